//! Tightly against loosely coupled on a real pedestrian walk in "canyon windows": the
//! rtklibexplorer walk (`datasets/rtklibexplorer-walk0827`: a u-blox X20's UBX log of a 134 s
//! walk, 22–25 satellites of GPS, Galileo and BeiDou, the IMU on GPS time), imported with
//! `navsync import ubx` as `recording/ubx_import.rs` does, and rewritten into canyon variants
//! in which, for 15 s at a time, the receiver sees only K satellites.
//!
//! **Windows** (the rule): the first starts 30 s after the log's first raw epoch (408639.75 s
//! of week, so at 408669.75), each lasts 15 s (both ends included: 61 epochs at 4 Hz) and the
//! next starts 10 s of full sky after the previous one ends, four in all: [408669.75,
//! 408684.75], [408694.75, 408709.75], [408719.75, 408734.75], [408744.75, 408759.75]. A raw
//! epoch is in a window by its receiver time of week rounded to 50 ms (the receiver's clock is
//! 2 ms off the 0.25 s grid), a fix by its GPS time.
//!
//! **Satellites kept** (the rule, per window): among the satellites with a measurement in every
//! raw epoch of the window whose healthy broadcast ephemeris the log completed before the
//! window starts (GPS LNAV subframes 1–3 with health 0; Galileo I/NAV and BeiDou D1 as
//! `navsync_estimator::gnss::broadcast::NavCollector` assembles them, healthy with a finite
//! accuracy; completion timed by the raw epoch before the navigation data message), the K with
//! the highest mean C/N0 over all their measurements in the window (ties by system, then
//! satellite id); K = 0 is a blockage. Each K (0, 2, 3) and window is a recording of its own, the rest of the walk
//! under the full sky: a window then starts from the same full-sky state for both couplings,
//! and its cost is its own (with the four windows in one recording, 10 s apart, the tightly
//! coupled filter carried 0.4–0.8 m of one window into the next, and loose coupling's
//! coasting depended on the canyon before). In a window every `GnssRaw` keeps only
//! the measurements (all signals) of those K satellites, and every `GnssFix` is dropped: a
//! receiver with 2–3 satellites has no fix, so the loosely coupled filter coasts. Navigation
//! data, PPS edges and the IMU are kept unchanged, and every channel's metadata (the IMU's
//! `navsync.time_axis` among them) travels along; the full-sky variant is the unmodified copy
//! and must replay exactly as the imported recording.
//!
//! **Couplings**: `loose` (the receiver's own fixes: RTK, cm-level), `loose-spp` (navsync's
//! single-point solution of the same raw epochs as fixes: loose coupling on the measurements
//! the tight filter fuses) and `tight`.
//!
//! **Scores**: the horizontal error at the antenna (lever arm [0, −0.05, 0] m, the output
//! interpolated) against the receiver's RTK-fixed epochs (`gnss.pos` where `gnss_q.txt` says
//! Q 1: up to 408727.75; the rest of the walk is RTK float): the whole walk's RMS, and per
//! window the error at its last RTK-fixed epoch (printed; window 4 lies in the float part).
//! What a window costs each coupling is the horizontal distance, at the window's last epoch,
//! between its output on the canyon variant and its own output on the full sky: for loose
//! coupling the inertial drift while it coasts; for tight the drift its 2–3 satellites let
//! through. Measured so, the window's cost is apart from the error both share with the full sky
//! (code ranges against RTK: the tightly coupled filter's is 4–7 m here, the receiver's RTK
//! fixes' 1–7 cm), and every window counts, in the RTK-float part too.
//!
//! **Asserted**: over the full-sky walk the tightly coupled RMS is at most loose coupling's on
//! the same measurements (`loose-spp`) and at most [`MAX_TIGHT_RMS_M`]; in every variant the
//! tightly coupled filter fuses GPS, Galileo and BeiDou ranges and time-differenced carrier
//! phases, and both solutions from the raw measurements keep their north and east errors within
//! 2σ at ≥ 90 % of the RTK-fixed epochs (never confidently wrong, canyons included); with 3
//! satellites tight's window cost is at most a third of loose's in every window (issue 36's
//! bar: tight 0.46 / 0.15 / 1.09 / 0.09 m against loose's 4.31 / 3.25 / 3.71 / 6.24 m on
//! 2026-12-06, with every signal of the log kept); at the end of each blockage the tightly coupled receiver clock (`TimeState`,
//! a replay with `--out` of its own) is within 2σ of its full-sky run, σ being what the
//! holdover added (√(σ_b² − σ_f²): both runs share the error they had when it began; 24–72 ns
//! off, σ 42–157 ns; with the data sheet's TCXO alone 24–82 ns off, σ 10–22 ns); no replay
//! reports a problem.
//!
//! **Measured, not asserted** (issue 36's bars, which this walk does not allow everywhere):
//! tight ≤ loose on the receiver's RTK fixes cannot hold, those fixes being the reference.
//! With 2 satellites a third of loose's cost is met in windows 1, 2 and 4 (tight 1.19 / 0.75 /
//! 4.99 / 1.00 m): the carrier and the Doppler measure the velocity along their two lines of
//! sight only, and along the direction they leave (u₁ × u₂, printed, near the horizontal) the
//! tightly coupled filter coasts on its IMU: its error along it in window 3 (−4.19 m) is
//! about what its own blockage of the same window leaves there (−4.73 m; both printed), where
//! window 1, with the same two satellites and direction, coasted +0.52 m. Loose's own drift
//! along it, printed, is more than a third of loose's cost in windows 1 and 4, yet tight met
//! the bar there: that drift is one IMU's coasting,
//! not a bound on another's (`tests/python/walk0827_window_coast.py` measures KF-GINS's).

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::process::Command;

use navsync_estimator::gnss::broadcast::NavCollector;
use navsync_estimator::gnss::lnav::{self, Subframe};
use navsync_recording::channels::{META_LAYOUT, META_QOS};
use navsync_recording::output::Overwrite;
use navsync_recording::ros_std::META_ORIGIN;
use navsync_recording::{RecordingOptions, SampleReader, SampleRecorder};
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::{AnySample, GnssRaw, RawMeasurement};
use navsync_tests::{TestEnv, shared_material, walk0827_antenna_error, walk0827_reference};
use serde_json::Value;

const WEEK_NS: i64 = 604_800_000_000_000;
const WEEK: i64 = 2381;
/// The first window starts this long after the first raw epoch, s.
const FIRST_WINDOW_AFTER_S: f64 = 30.0;
/// A window's length, s.
const WINDOW_S: f64 = 15.0;
/// Full sky between two windows, s.
const GAP_S: f64 = 10.0;
/// Windows.
const WINDOWS: usize = 4;
/// Satellites kept in a window, one recording each (0: a blockage, the receiver clock in
/// holdover).
const KS: [usize; 3] = [0, 2, 3];
/// The fraction of RTK-fixed epochs at which a solution from the raw measurements (tight,
/// loose-spp) must have its north and east errors within 2σ (issue 34's lower bound).
const MIN_COVERAGE: f64 = 0.9;
/// Full sky: the tightly coupled horizontal RMS against the RTK-fixed epochs at most this, m
/// (0.61–0.75 m measured 2026-12-05 as the filter changed, twice the most as the bound).
const MAX_TIGHT_RMS_M: f64 = 1.5;
/// The couplings compared: the receiver's fixes, navsync's solution of the raw epochs, tight.
const COUPLINGS: [&str; 3] = ["loose", "loose-spp", "tight"];

fn data() -> PathBuf {
    shared_material("datasets/rtklibexplorer-walk0827")
}

fn p(x: &Path) -> String {
    x.display().to_string()
}

/// Runs navsync; its stderr.
fn run_ok(env: &TestEnv, args: &[&str]) -> String {
    let o = env.command(args).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "navsync {args:?}: {}\n{err}", o.status);
    err
}

/// A raw epoch's nominal time of week, s: the receiver's time rounded to 50 ms.
fn epoch_sow(r: &GnssRaw) -> f64 {
    (r.rcv_tow_s * 20.0).round() / 20.0
}

/// A satellite: (u-blox gnssId, svId).
type Sat = (u8, u8);

/// A window's start and the satellites kept in it with their mean C/N0, dB-Hz.
type Kept = (f64, Vec<(Sat, f64)>);

/// One sample of a recording as read.
struct Recorded {
    service: String,
    sample: AnySample,
    log_time: u64,
    publish_time: u64,
}

/// A recording's samples in file order and each channel's metadata (without what the writer
/// adds itself).
struct Recording {
    samples: Vec<Recorded>,
    metadata: HashMap<String, Vec<(String, String)>>,
}

fn read(rec: &Path) -> Recording {
    let mut r = SampleReader::open(rec).unwrap();
    let mut out = Recording {
        samples: Vec::new(),
        metadata: HashMap::new(),
    };
    while let Some(s) = r.next_sample().unwrap() {
        out.samples.push(Recorded {
            service: s.service.to_string(),
            sample: s.sample,
            log_time: s.log_time,
            publish_time: s.publish_time,
        });
    }
    assert!(r.skipped_chunks().is_empty() && r.skipped_channels().is_empty());
    for s in &out.samples {
        if !out.metadata.contains_key(&s.service) {
            let m = r
                .channel_metadata(&s.service)
                .into_iter()
                .filter(|(k, _)| k != META_LAYOUT && k != META_QOS && k != META_ORIGIN)
                .collect();
            out.metadata.insert(s.service.clone(), m);
        }
    }
    out
}

/// When each satellite's healthy broadcast ephemeris was first complete: the time of week of
/// the raw epoch before the navigation data message that completed it.
fn ephemerides_complete(rec: &Recording) -> BTreeMap<Sat, f64> {
    let mut nav = NavCollector::default();
    // GPS: subframes 1 (healthy), 2 and 3 seen.
    let mut gps: HashMap<u8, [bool; 3]> = HashMap::new();
    let mut out = BTreeMap::new();
    let mut now = f64::NAN;
    for s in &rec.samples {
        match &s.sample {
            AnySample::Raw(r) => now = epoch_sow(r),
            AnySample::NavData(n) => {
                let words = &n.words[..usize::from(n.num_words).min(n.words.len())];
                if n.gnss_id == 0 && n.sig_id == 0 {
                    let Ok(d) = lnav::decode(words) else { continue };
                    let e = gps.entry(n.sv_id).or_default();
                    match d.subframe {
                        Subframe::Ephem1(x) => e[0] = x.health == 0,
                        Subframe::Ephem2(_) => e[1] = true,
                        Subframe::Ephem3(_) => e[2] = true,
                        _ => {}
                    }
                    if e.iter().all(|x| *x) && now.is_finite() {
                        out.entry((0, n.sv_id)).or_insert(now);
                    }
                } else if let Ok(Some(e)) = nav.on_words(n.gnss_id, n.sv_id, n.sig_id, words) {
                    let b = e.broadcast();
                    if b.healthy && b.accuracy_m.is_finite() && now.is_finite() {
                        out.entry((b.gnss_id, b.sv_id)).or_insert(now);
                    }
                }
            }
            _ => {}
        }
    }
    out
}

/// The windows' starts, s of week.
fn windows(rec: &Recording) -> Vec<f64> {
    let first = rec
        .samples
        .iter()
        .find_map(|s| match &s.sample {
            AnySample::Raw(r) => Some(epoch_sow(r)),
            _ => None,
        })
        .expect("a raw epoch");
    (0..WINDOWS)
        .map(|i| first + FIRST_WINDOW_AFTER_S + i as f64 * (WINDOW_S + GAP_S))
        .collect()
}

/// The error function, to 1.5e-7 (Abramowitz & Stegun 7.1.26).
fn erf(x: f64) -> f64 {
    let t = 1.0 / (1.0 + 0.327_591_1 * x.abs());
    let poly =
        t * (0.254_829_592 + t * (-0.284_496_736 + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    (1.0 - poly * (-x * x).exp()).copysign(x)
}

fn in_window(sow: f64, t0: f64) -> bool {
    sow >= t0 - 1e-6 && sow <= t0 + WINDOW_S + 1e-6
}

/// The `k` satellites kept in the window from `t0` (the rule in the module docs), with their
/// mean C/N0, dB-Hz.
fn kept(rec: &Recording, eph: &BTreeMap<Sat, f64>, t0: f64, k: usize) -> Vec<(Sat, f64)> {
    let mut epochs = 0usize;
    // Per satellite: epochs present, C/N0 sum, measurements.
    let mut stats: BTreeMap<Sat, (usize, f64, usize)> = BTreeMap::new();
    for s in &rec.samples {
        let AnySample::Raw(r) = &s.sample else { continue };
        if !in_window(epoch_sow(r), t0) {
            continue;
        }
        epochs += 1;
        let mut seen = BTreeSet::new();
        for m in &r.meas[..usize::from(r.num_meas)] {
            let e = stats.entry((m.gnss_id, m.sv_id)).or_default();
            if seen.insert((m.gnss_id, m.sv_id)) {
                e.0 += 1;
            }
            e.1 += f64::from(m.cno_dbhz);
            e.2 += 1;
        }
    }
    assert_eq!(epochs, 61, "raw epochs in the window from {t0}");
    let mut c: Vec<(Sat, f64)> = stats
        .into_iter()
        .filter(|(sat, (n, _, _))| *n == epochs && eph.get(sat).is_some_and(|t| *t < t0))
        .map(|(sat, (_, sum, n))| (sat, sum / n as f64))
        .collect();
    // Stable: equal means stay in (system, satellite) order.
    c.sort_by(|a, b| b.1.total_cmp(&a.1));
    assert!(c.len() >= k, "window from {t0}: only {} candidates", c.len());
    c.truncate(k);
    c
}

/// The code error of each satellite in `sats` over the window from `t0`, against the antenna
/// positions `position` (sow → lat°, lon°, ellipsoidal height m): per epoch its pseudorange
/// less the geometric range, the broadcast ionosphere and the troposphere, less the median of
/// the same over its system's satellites (which the receiver clock and the inter-system bias
/// take), averaged over the window, m. Against the full-sky tightly coupled track, what stays
/// is how far each satellite's persisting error (residual ionosphere, multipath, broadcast
/// orbit and clock) departs from the consensus of the whole sky: with only these satellites
/// left, the tightly coupled position moves by about as much along their lines of sight,
/// whatever the inertial drift.
fn code_errors(rec: &Recording, t0: f64, sats: &[Sat], position: &dyn Fn(f64) -> Option<[f64; 3]>) -> Vec<(Sat, f64)> {
    use navsync_estimator::gnss::ranges::{EphemerisStore, RangeBuildCounts};
    use navsync_estimator::gnss::spp::{C_M_S, elevation_azimuth, rotate_for_flight, troposphere_delay_m};
    use navsync_shared::earth::geodetic_to_ecef;
    let mut store = EphemerisStore::default();
    let mut counts = RangeBuildCounts::default();
    let mut sums: BTreeMap<Sat, (f64, usize)> = BTreeMap::new();
    for s in &rec.samples {
        match &s.sample {
            AnySample::NavData(n) => store.on_nav_data(n),
            AnySample::Raw(r) if in_window(epoch_sow(r), t0) => {
                let Some([lat, lon, h]) = position(epoch_sow(r)) else {
                    continue;
                };
                let (lat, lon) = (lat.to_radians(), lon.to_radians());
                let rx = geodetic_to_ecef(lat, lon, h);
                let mut residuals = |clock_m: f64| -> Vec<(Sat, f64)> {
                    let e = store.range_epoch(r, 0, clock_m, &mut counts);
                    e.sats()
                        .iter()
                        .map(|x| {
                            let d0 = dist(x.sat_ecef_m, rx);
                            let sat = rotate_for_flight(x.sat_ecef_m, d0 / C_M_S);
                            let (el, az) = elevation_azimuth(rx, sat);
                            let iono = e.iono.map_or(0.0, |k| C_M_S * k.delay_s(lat, lon, el, az, e.tow_s));
                            let model = dist(sat, rx) + x.iono_scale * iono + troposphere_delay_m(lat, h, el);
                            ((x.gnss_id, x.sv), x.pseudorange_m - model)
                        })
                        .collect()
                };
                // The satellites' positions at the receiver's clock's GPS time (two passes).
                let first = residuals(0.0);
                let Some(clock) = median(first.iter().map(|x| x.1).collect()) else {
                    continue;
                };
                let res = residuals(clock);
                for sat in sats {
                    let Some(&(_, mine)) = res.iter().find(|x| x.0 == *sat) else {
                        continue;
                    };
                    let system: Vec<f64> = res.iter().filter(|x| x.0.0 == sat.0).map(|x| x.1).collect();
                    if let Some(m) = median(system) {
                        let e = sums.entry(*sat).or_default();
                        e.0 += mine - m;
                        e.1 += 1;
                    }
                }
            }
            _ => {}
        }
    }
    sums.into_iter().map(|(sat, (sum, n))| (sat, sum / n as f64)).collect()
}

/// The direction (NED unit vector) the satellites `sats` leave unmeasured at the window's last
/// raw epoch, seen from `position`, and for three satellites the clock's share of it. Two: u₁ ×
/// u₂, along which neither range changes (the carrier and the Doppler give the velocity along
/// u₁ and u₂ only). Three: w = U⁻¹·1 (U's rows the lines of sight), along which every range
/// changes alike: a move β·w/|w| is a receiver clock change of β/|w| (the returned |w|), so only
/// the clock's stability tells it from the clock. Along it the tightly coupled filter coasts
/// on its IMU (and its clock model) as loose coupling does everywhere.
fn unobserved_direction(
    rec: &Recording,
    t0: f64,
    sats: &[Sat],
    position: &dyn Fn(f64) -> Option<[f64; 3]>,
) -> Option<([f64; 3], Option<f64>)> {
    use navsync_estimator::gnss::ranges::{EphemerisStore, RangeBuildCounts};
    use navsync_estimator::gnss::spp::{C_M_S, elevation_azimuth, rotate_for_flight};
    use navsync_shared::earth::geodetic_to_ecef;
    let (mut store, mut counts) = (EphemerisStore::default(), RangeBuildCounts::default());
    let mut last = None;
    for s in &rec.samples {
        match &s.sample {
            AnySample::NavData(n) => store.on_nav_data(n),
            AnySample::Raw(r) if in_window(epoch_sow(r), t0) => {
                let [lat, lon, h] = position(epoch_sow(r))?;
                let rx = geodetic_to_ecef(lat.to_radians(), lon.to_radians(), h);
                let e = store.range_epoch(r, 0, 0.0, &mut counts);
                let u: Vec<[f64; 3]> = sats
                    .iter()
                    .filter_map(|sat| e.sats().iter().find(|x| (x.gnss_id, x.sv) == *sat))
                    .map(|x| {
                        let (el, az) =
                            elevation_azimuth(rx, rotate_for_flight(x.sat_ecef_m, dist(x.sat_ecef_m, rx) / C_M_S));
                        [el.cos() * az.cos(), el.cos() * az.sin(), -el.sin()]
                    })
                    .collect();
                match u[..] {
                    [a, b] => {
                        let c = [
                            a[1] * b[2] - a[2] * b[1],
                            a[2] * b[0] - a[0] * b[2],
                            a[0] * b[1] - a[1] * b[0],
                        ];
                        let n = dist(c, [0.0; 3]);
                        last = Some((c.map(|x| x / n), None));
                    }
                    [a, b, c] => {
                        let m = nalgebra::Matrix3::from_rows(
                            &[a.into(), b.into(), c.into()].map(|r: nalgebra::Vector3<f64>| r.transpose()),
                        );
                        if let Some(w) = m.try_inverse().map(|i| i * nalgebra::Vector3::repeat(1.0)) {
                            let n = w.norm();
                            last = Some(([w[0] / n, w[1] / n, w[2] / n], Some(n)));
                        }
                    }
                    _ => {}
                }
            }
            _ => {}
        }
    }
    last
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    (n > 0).then(|| {
        if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        }
    })
}

/// A canyon variant's name: `k` satellites in window `w` (from 0).
fn variant_name(k: usize, w: usize) -> String {
    format!("{k} satellites, W{}", w + 1)
}

/// Writes `rec` to `out` with, in each window (start, satellites kept), only the kept
/// satellites' measurements and no fixes; everything else, times and metadata as read. The
/// raw epochs thinned and the fixes dropped.
fn write_variant(rec: &Recording, input: &Path, out: &Path, windows: &[(f64, Vec<Sat>)]) -> (usize, usize) {
    let (mut thinned, mut dropped) = (0, 0);
    let inputs = [input];
    let mut w = SampleRecorder::create(out, &Overwrite::new(&inputs, false), RecordingOptions::default()).unwrap();
    for (service, meta) in &rec.metadata {
        for (k, v) in meta {
            w.set_channel_metadata(service, k, v).unwrap();
        }
    }
    let window_of = |sow: f64| windows.iter().find(|(t0, _)| in_window(sow, *t0));
    for s in &rec.samples {
        let sample = match &s.sample {
            AnySample::Raw(r) => match window_of(epoch_sow(r)) {
                Some((_, sats)) => {
                    let mut r2 = *r;
                    let mut n = 0;
                    for m in &r.meas[..usize::from(r.num_meas)] {
                        if sats.contains(&(m.gnss_id, m.sv_id)) {
                            r2.meas[n] = *m;
                            n += 1;
                        }
                    }
                    for m in &mut r2.meas[n..] {
                        *m = RawMeasurement::zeroed();
                    }
                    r2.num_meas = n as u8;
                    thinned += 1;
                    AnySample::Raw(r2)
                }
                None => s.sample,
            },
            AnySample::GnssFix(f) => {
                let sow = (f.gps_ns - WEEK * WEEK_NS) as f64 * 1e-9;
                if window_of(sow).is_some() {
                    dropped += 1;
                    continue;
                }
                s.sample
            }
            _ => s.sample,
        };
        w.write(&s.service, &sample, s.log_time, s.publish_time).unwrap();
    }
    w.close().unwrap();
    (thinned, dropped)
}

/// The arguments of `replay --estimate` of `rec` with `coupling` and the walk's lever arm,
/// then `extra`.
fn replay_args(rec: &Path, coupling: &str, extra: &[&str]) -> Vec<String> {
    let mut args: Vec<String> = [
        "replay",
        &p(rec),
        "--estimate",
        "--lever-arm",
        "0,-0.05,0",
        "--coupling",
        coupling,
    ]
    .map(String::from)
    .into();
    args.extend(extra.iter().map(|x| x.to_string()));
    args
}

/// `replay --estimate` of `rec` with `coupling`, as a command; the output directory (KF-GINS's
/// result files) and the summary's path.
fn replay_command(env: &TestEnv, rec: &Path, name: &str, coupling: &str) -> (Command, PathBuf, PathBuf) {
    let nav = env.dir.join(name);
    std::fs::create_dir_all(&nav).unwrap();
    let summary = env.dir.join(format!("{name}.json"));
    let args = replay_args(
        rec,
        coupling,
        &["--summary-json", &p(&summary), "--out", &p(&nav), "--format", "kf-gins"],
    );
    let c = env.command(&args.iter().map(String::as_str).collect::<Vec<_>>());
    (c, nav, summary)
}

/// The receiver clock of one `TimeState`.
#[derive(Debug, Clone, Copy)]
struct ClockState {
    /// Host time it was computed at, ns.
    host_ns: i64,
    /// Receiver clock bias and its σ, ns.
    bias_ns: f64,
    std_ns: f64,
    /// Host time of the last epoch with a fused satellite, ns.
    last_fused_ns: i64,
}

/// The tightly coupled replay of `rec`'s `TimeState`s that carry the receiver clock.
fn clock_states(env: &TestEnv, rec: &Path, name: &str) -> Vec<ClockState> {
    let out = env.dir.join(format!("{name}.mcap"));
    let args = replay_args(rec, "tight", &["--out", &p(&out)]);
    run_ok(env, &args.iter().map(String::as_str).collect::<Vec<_>>());
    let mut r = SampleReader::open(&out).unwrap();
    let mut states = Vec::new();
    while let Some(s) = r.next_sample().unwrap() {
        if let AnySample::Time(t) = s.sample
            && t.rx_clock_bias_ns.is_finite()
        {
            states.push(ClockState {
                host_ns: t.computed_host_ns,
                bias_ns: t.rx_clock_bias_ns,
                std_ns: t.rx_clock_bias_std_ns,
                last_fused_ns: t.rx_clock_last_fused_host_ns,
            });
        }
    }
    states
}

/// One replay's result.
struct Replay {
    /// The output file's text.
    nav: String,
    /// The output's (sow, lat°, lon°, height m) rows.
    track: Vec<(f64, f64, f64, f64)>,
    summary: Value,
    /// `KF_GINS_STD.txt`'s rows: sow, then the position σ N, E, D, m, …
    std: Vec<Vec<f64>>,
    /// (sow, Q, horizontal error at the antenna, m, whether N and E are both within 2σ) at each
    /// reference epoch within the output.
    errors: Vec<(f64, f64, f64, bool)>,
}

impl Replay {
    fn load(name: &str, dir: &Path, summary_path: &Path) -> Self {
        let summary: Value = serde_json::from_str(&std::fs::read_to_string(summary_path).unwrap()).unwrap();
        let nav = std::fs::read_to_string(dir.join("KF_GINS_Navresult.nav")).unwrap();
        let table = |text: &str| -> Vec<Vec<f64>> {
            text.lines()
                .map(|l| l.split_whitespace().map(|x| x.parse().unwrap()).collect())
                .collect()
        };
        let rows = table(&nav);
        // KF_GINS_STD.txt: sow, then the position σ N, E, D, m.
        let std = table(&std::fs::read_to_string(dir.join("KF_GINS_STD.txt")).unwrap());
        assert!(!rows.is_empty(), "{name}: no output");
        let mut errors = Vec::new();
        for (sow, lat, lon, q) in walk0827_reference() {
            let Some((north, east)) = walk0827_antenna_error(&rows, sow, lat, lon) else {
                continue;
            };
            let s = &std[std.partition_point(|r| r[0] < sow).min(std.len() - 1)];
            let within = north.abs() <= 2.0 * s[1] && east.abs() <= 2.0 * s[2];
            errors.push((sow, q, north.hypot(east), within));
        }
        let track = rows.iter().map(|r| (r[1], r[2], r[3], r[4])).collect();
        Self {
            nav,
            track,
            summary,
            std,
            errors,
        }
    }

    /// The output's position (lat°, lon°, height m) at `sow`, interpolated.
    fn at(&self, sow: f64) -> Option<[f64; 3]> {
        let k = self.track.partition_point(|r| r.0 <= sow);
        let (a, b) = (self.track.get(k.checked_sub(1)?)?, self.track.get(k)?);
        let w = (sow - a.0) / (b.0 - a.0);
        Some([a.1 + w * (b.1 - a.1), a.2 + w * (b.2 - a.2), a.3 + w * (b.3 - a.3)])
    }

    /// What the window from `t0` cost this run against `full` (the same coupling on the full
    /// sky): the horizontal distance between their positions at the window's end, m.
    fn window_cost(&self, full: &Replay, t0: f64) -> f64 {
        let [north, east, _] = self.window_offset(full, t0);
        north.hypot(east)
    }

    /// This run's position minus `full`'s at the end of the window from `t0`, N, E, D, m.
    fn window_offset(&self, full: &Replay, t0: f64) -> [f64; 3] {
        let end = t0 + WINDOW_S;
        let (Some(a), Some(b)) = (self.at(end), full.at(end)) else {
            panic!("no output at the window's end {end}");
        };
        const R: f64 = 6_378_137.0;
        [
            (a[0] - b[0]).to_radians() * R,
            (a[1] - b[1]).to_radians() * R * a[0].to_radians().cos(),
            b[2] - a[2],
        ]
    }

    /// The position σ along the unit vector `d` (NED) at `sow`, m, from the N, E and D σ (their
    /// correlations left out).
    fn std_along(&self, sow: f64, d: [f64; 3]) -> f64 {
        let row = &self.std[self.std.partition_point(|r| r[0] < sow).min(self.std.len() - 1)];
        (0..3).map(|i| (d[i] * row[i + 1]).powi(2)).sum::<f64>().sqrt()
    }

    /// Horizontal RMS at the RTK-fixed epochs, m, and their number.
    fn rms(&self) -> (f64, usize) {
        let e: Vec<f64> = self.errors.iter().filter(|x| x.1 == 1.0).map(|x| x.2).collect();
        (
            (e.iter().map(|x| x * x).sum::<f64>() / e.len().max(1) as f64).sqrt(),
            e.len(),
        )
    }

    /// The fraction of the RTK-fixed epochs whose north and east errors are both within 2σ.
    fn coverage(&self) -> f64 {
        let fixed = || self.errors.iter().filter(|x| x.1 == 1.0);
        fixed().filter(|x| x.3).count() as f64 / fixed().count().max(1) as f64
    }

    /// The error at the window's last RTK-fixed epoch: (sow, m); else at its last epoch
    /// against the float position, `None` for the first.
    fn window_end(&self, t0: f64) -> (Option<f64>, f64) {
        let inside = || self.errors.iter().filter(|x| in_window(x.0, t0));
        match inside().rfind(|x| x.1 == 1.0) {
            Some(x) => (Some(x.0), x.2),
            None => (None, inside().next_back().expect("reference epochs in the window").2),
        }
    }

    /// Every summary entry whose key path contains "range".
    fn range_counters(&self) -> Vec<(String, Value)> {
        fn walk(v: &Value, path: &str, out: &mut Vec<(String, Value)>) {
            let Value::Object(m) = v else { return };
            for (k, x) in m {
                let path = if path.is_empty() {
                    k.clone()
                } else {
                    format!("{path}.{k}")
                };
                match x {
                    Value::Object(_) => walk(x, &path, out),
                    _ if k.contains("range") || k.contains("carrier") => out.push((path, x.clone())),
                    _ => {}
                }
            }
        }
        let mut out = Vec::new();
        walk(&self.summary, "", &mut out);
        out
    }
}

#[test]
fn tight_and_loose_on_the_walk_with_canyon_windows() {
    let started = std::time::Instant::now();
    let env = TestEnv::new("tightwalk");
    let original = env.dir.join("walk.mcap");
    run_ok(
        &env,
        &[
            "import",
            "ubx",
            &p(&data().join("source/gnss_1730.ubx")),
            "--imu",
            &p(&data().join("imu.txt")),
            "--out",
            &p(&original),
        ],
    );
    let rec = read(&original);
    let eph = ephemerides_complete(&rec);
    let starts = windows(&rec);

    // The variants: the unmodified copy (full sky), then one per K and window.
    let mut variants: Vec<(String, PathBuf, Vec<Kept>)> = Vec::new();
    let copy = env.dir.join("full.mcap");
    assert_eq!(write_variant(&rec, &original, &copy, &[]), (0, 0));
    variants.push(("full sky".into(), copy, Vec::new()));
    for k in KS {
        for (w, t0) in starts.iter().enumerate() {
            let chosen = vec![(*t0, kept(&rec, &eph, *t0, k))];
            let sats: Vec<(f64, Vec<Sat>)> = chosen
                .iter()
                .map(|(t0, c)| (*t0, c.iter().map(|x| x.0).collect()))
                .collect();
            let path = env.dir.join(format!("k{k}w{}.mcap", w + 1));
            // The window's 61 epochs (4 Hz, both ends) thinned, and their fixes dropped.
            assert_eq!(write_variant(&rec, &original, &path, &sats), (61, 61));
            variants.push((variant_name(k, w), path, chosen));
        }
    }
    let variant = |k: usize, w: usize| {
        variants
            .iter()
            .position(|v| v.0 == variant_name(k, w))
            .expect("the variant")
    };

    // Every replay at once (each a process of its own): the original with both couplings (the
    // copy must give the same outputs), then every variant with both.
    let mut jobs: Vec<(String, Command, PathBuf, PathBuf)> = Vec::new();
    for coupling in ["loose", "tight"] {
        let name = format!("original-{coupling}");
        let (c, n, s) = replay_command(&env, &original, &name, coupling);
        jobs.push((name, c, n, s));
    }
    for (i, (_, path, _)) in variants.iter().enumerate() {
        for coupling in COUPLINGS {
            let name = format!("v{i}-{coupling}");
            let (c, n, s) = replay_command(&env, path, &name, coupling);
            jobs.push((name, c, n, s));
        }
    }
    let replay_started = std::time::Instant::now();
    let results: Vec<Replay> = std::thread::scope(|scope| {
        let handles: Vec<_> = jobs
            .into_iter()
            .map(|(name, mut c, nav, summary)| {
                scope.spawn(move || {
                    let o = c.output().unwrap();
                    assert!(
                        o.status.success(),
                        "{name}: {}\n{}",
                        o.status,
                        String::from_utf8_lossy(&o.stderr)
                    );
                    Replay::load(&name, &nav, &summary)
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let replay_s = replay_started.elapsed().as_secs_f64();
    let (original_runs, runs) = results.split_at(2);

    // The receiver clock through each blockage: the tightly coupled TimeStates of the blockage
    // variant against the full sky's at the blockage's last epoch.
    let clock_runs: Vec<Vec<ClockState>> = std::thread::scope(|scope| {
        let handles: Vec<_> = std::iter::once(0)
            .chain((0..WINDOWS).map(|w| variant(0, w)))
            .map(|v| {
                let (env, path) = (&env, &variants[v].1);
                scope.spawn(move || clock_states(env, path, &format!("clock-{v}")))
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });

    // The copy replays exactly as the import.
    for (o, c) in original_runs.iter().zip([&runs[0], &runs[2]]) {
        assert!(
            o.nav == c.nav,
            "the unmodified copy's output differs from the original's"
        );
        assert_eq!(o.rms(), c.rms());
    }

    // The satellites kept.
    for (name, _, chosen) in &variants[1..] {
        for (t0, c) in chosen {
            let list: Vec<String> = c
                .iter()
                .map(|((g, sv), cno)| {
                    let sys = match g {
                        0 => "G",
                        2 => "E",
                        3 => "C",
                        _ => "?",
                    };
                    format!("{sys}{sv:02} ({cno:.1} dB-Hz)")
                })
                .collect();
            let sats: Vec<Sat> = c.iter().map(|x| x.0).collect();
            let full_sky_tight = |sow: f64| runs[2].at(sow);
            let errs: Vec<String> = code_errors(&rec, *t0, &sats, &full_sky_tight)
                .iter()
                .map(|((g, sv), e)| format!("{g}:{sv} {e:+.2} m"))
                .collect();
            eprintln!(
                "{name} [{t0:.2}, {:.2}]: {}; their code error against the full-sky tightly coupled track: {}",
                t0 + WINDOW_S,
                list.join(", "),
                errs.join(", ")
            );
        }
    }

    // The table.
    eprintln!();
    let mut header = format!("{:<16} {:<9} {:>9}", "variant", "coupl.", "RMS [m]");
    for (i, t0) in starts.iter().enumerate() {
        header += &format!(" {:>14}", format!("W{} {:.2}", i + 1, t0));
    }
    eprintln!("{header}");
    let nc = COUPLINGS.len();
    for (i, (name, _, chosen)) in variants.iter().enumerate() {
        for (j, coupling) in COUPLINGS.iter().enumerate() {
            let r = &runs[nc * i + j];
            let (rms, n) = r.rms();
            let mut line = format!("{name:<16} {coupling:<9} {rms:>9.3}");
            for t0 in &starts {
                // A window variant: its own window's column only.
                if !chosen.is_empty() && !chosen.iter().any(|c| c.0 == *t0) {
                    line += &format!(" {:>14}", "–");
                    continue;
                }
                line += &match r.window_end(*t0) {
                    (Some(sow), err) => format!(" {:>14}", format!("{err:.2}@{:.2}", sow - 408_000.0)),
                    (None, err) => format!(" {:>14}", format!("({err:.2})")),
                };
            }
            eprintln!(
                "{line}   ({n} RTK-fixed epochs, N and E within 2σ at {:.3})",
                r.coverage()
            );
        }
    }
    eprintln!(
        "window columns: horizontal error, m, at the window's last RTK-fixed epoch (@ its sow − 408000); \
         (…): at its last epoch against the RTK float position, not scored"
    );
    // What each window cost each coupling.
    eprintln!(
        "\nwhat each window cost (m): the distance at its end between the window's canyon run and the same coupling's full-sky run"
    );
    // By K (as in KS) and coupling: the cost of each window.
    let mut costs: Vec<Vec<f64>> = Vec::new();
    for k in KS {
        for (j, coupling) in COUPLINGS.iter().enumerate() {
            let c: Vec<f64> = (0..WINDOWS)
                .map(|w| runs[nc * variant(k, w) + j].window_cost(&runs[j], starts[w]))
                .collect();
            let list: Vec<String> = c.iter().map(|x| format!("{x:>8.2}")).collect();
            eprintln!("{:<16} {coupling:<9} {}", format!("{k} satellites"), list.join(" "));
            costs.push(c);
        }
    }
    // Where the satellites leave the tightly coupled filter to its IMU: loose's inertial drift
    // over the window along the direction they leave unmeasured, put back into the horizontal
    // plane (an IMU drifting as loose's does leaves this much there alone). With 3 satellites
    // it is the clock's direction: the receiver's clock would have to hold to (a third of
    // loose's cost) / |w| over the window to tell a move along it, where a data sheet's TCXO
    // lets it wander by σ_b and this receiver's clock, warming up, by more (the filter's
    // `clock_noise_scale_pct`, printed).
    let tcxo = navsync_estimator::nav::config::ReceiverOscillator::Tcxo.noise();
    let sigma_b = tcxo.process_noise_m(WINDOW_S)[(0, 0)].sqrt();
    let clock_scale = runs[2].summary["measurement_counters"]["clock_noise_scale_pct"]
        .as_u64()
        .unwrap_or(0);
    eprintln!(
        "\nthe receiver clock: the full-sky tightly coupled filter scaled the TCXO's random-walk FM by {:.2} (ClockWatch)",
        clock_scale as f64 / 100.0
    );
    // With 2 satellites, what an INS on this IMU gives along d: loose's σ along d at the
    // window's end (it starts at the RTK fixes' cm, so its growth is the IMU's coasting under
    // the filter's IMU model), the chance that a coasting of that σ stays within the bar, and
    // whether the coastings measured lie within 3 of those σ (the bound's premise).
    let mut coasting_misses = Vec::new();
    let mut all_four = 1.0;
    for k in KS.into_iter().filter(|k| *k >= 2) {
        let name = format!("{k} satellites");
        eprintln!(
            "\n{name}: the direction they leave unmeasured (NED; 2: u1 x u2, 3: w = U^-1 1, a clock change of 1/|w| per metre) and loose's drift along it, horizontal, vs a third of loose's cost"
        );
        for w in 0..WINDOWS {
            let v = variant(k, w);
            let (t0, chosen) = &variants[v].2[0];
            let sats: Vec<Sat> = chosen.iter().map(|x| x.0).collect();
            let full_sky_tight = |sow: f64| runs[2].at(sow);
            let Some((d, scale)) = unobserved_direction(&rec, *t0, &sats, &full_sky_tight) else {
                eprintln!("  window {}: the satellites' directions not found", w + 1);
                continue;
            };
            let c = runs[nc * v].window_offset(&runs[0], *t0);
            let along = c[0] * d[0] + c[1] * d[1] + c[2] * d[2];
            let floor = along.abs() * d[0].hypot(d[1]);
            let loose = c[0].hypot(c[1]);
            // Tight's own inertial coasting along d (its blockage run, the same state at the
            // window's start) against its error there with the K satellites.
            let dot = |x: [f64; 3]| x[0] * d[0] + x[1] * d[1] + x[2] * d[2];
            let coast = dot(runs[nc * variant(0, w) + 2].window_offset(&runs[2], *t0));
            let mine = dot(runs[nc * v + 2].window_offset(&runs[2], *t0));
            let clock = scale.map_or(String::new(), |n| {
                format!(
                    "; |w| {n:.2}: the clock would have to hold to {:.2} m over the window, a data sheet's TCXO lets it wander {sigma_b:.1} m",
                    loose / 3.0 / n
                )
            });
            eprintln!(
                "  window {}: d = ({:+.2}, {:+.2}, {:+.2}), loose's drift along d {along:+.2} m, horizontal {floor:.2} m {} a third of loose's cost {:.2} m{clock}; tight along d: blockage {coast:+.2} m, {k} satellites {mine:+.2} m",
                w + 1,
                d[0],
                d[1],
                d[2],
                if floor > loose / 3.0 { ">" } else { "<=" },
                loose / 3.0
            );
            if k == 2 {
                let loose_run = &runs[nc * v];
                let sigma = (loose_run.std_along(*t0 + WINDOW_S, d).powi(2) - loose_run.std_along(*t0, d).powi(2))
                    .max(0.0)
                    .sqrt();
                // Meeting the bar needs at least |e_d|·|d_h| ≤ a third of loose's cost.
                let p = erf(loose / 3.0 / d[0].hypot(d[1]) / (sigma * std::f64::consts::SQRT_2));
                all_four *= p;
                eprintln!(
                    "    an INS's coasting along d over the window, σ {sigma:.2} m (loose's model of this IMU): within the bar with probability {p:.2}; tight blockage {:.1} σ, loose {:.1} σ",
                    coast.abs() / sigma,
                    along.abs() / sigma
                );
                for (who, e) in [("tight's blockage", coast), ("loose", along)] {
                    if e.abs() > 3.0 * sigma {
                        coasting_misses.push(format!(
                            "W{}: {who} coasted {e:+.2} m along d, beyond 3σ of the IMU model's {sigma:.2} m",
                            w + 1
                        ));
                    }
                }
            }
        }
    }
    eprintln!(
        "2 satellites: the chance that an INS coasting as the filter's IMU model says stays within the bar along d in all {WINDOWS} windows: {all_four:.4}"
    );
    eprintln!(
        "\nthe receiver clock at each blockage's end (host time of its last raw epoch), tightly coupled, against the full sky's:"
    );
    let mut clock_misses = Vec::new();
    for w in 0..WINDOWS {
        let end = rec
            .samples
            .iter()
            .find_map(|s| match &s.sample {
                AnySample::Raw(r) if (epoch_sow(r) - starts[w] - WINDOW_S).abs() < 1e-6 => Some(r.stamp.host_ns),
                _ => None,
            })
            .expect("the window's last raw epoch");
        let at = |states: &[ClockState]| states.iter().rfind(|c| c.host_ns <= end).copied();
        let (Some(b), Some(f)) = (at(&clock_runs[w + 1]), at(&clock_runs[0])) else {
            clock_misses.push(format!("W{}: no TimeState with the receiver clock", w + 1));
            continue;
        };
        let held_s = (b.host_ns - b.last_fused_ns) as f64 * 1e-9;
        // Both runs share the error they had when the blockage began (the full sky's clock σ,
        // mostly the code's common error); their difference is what the holdover added, whose
        // σ is the growth of the blockage run's: √(σ_b² − σ_f²).
        let e = b.bias_ns - f.bias_ns;
        let added = (b.std_ns.powi(2) - f.std_ns.powi(2)).max(0.0).sqrt();
        eprintln!(
            "  W{}: {held_s:.1} s of holdover: {e:+.1} ns, σ {:.1} ns (full sky σ {:.1} ns: the holdover's {added:.1} ns)",
            w + 1,
            b.std_ns,
            f.std_ns
        );
        if held_s < WINDOW_S - 1.0 || e.abs() > 2.0 * added {
            clock_misses.push(format!(
                "W{}: the receiver clock after {held_s:.1} s of holdover {e:+.1} ns off the full sky's, beyond 2σ of what the holdover added ({added:.1} ns)",
                w + 1
            ));
        }
    }

    eprintln!("\ntightly coupled summaries' range counters:");
    for (i, (name, _, _)) in variants.iter().enumerate() {
        let r = &runs[nc * i + 2];
        let list: Vec<String> = r.range_counters().iter().map(|(k, v)| format!("{k} {v}")).collect();
        eprintln!("  {name}: {}", list.join(", "));
    }
    eprintln!(
        "\n{} replays in {replay_s:.1} s (in parallel); the test {:.1} s",
        nc * variants.len() + 2,
        started.elapsed().as_secs_f64()
    );

    // The criteria.
    let mut failures = clock_misses;
    failures.extend(coasting_misses);
    for r in original_runs.iter().chain(runs) {
        if !r.summary["problem"].is_null() {
            failures.push(format!("a replay's problem: {}", r.summary["problem"]));
        }
    }
    let (spp_rms, _) = runs[1].rms();
    let (tc_rms, _) = runs[2].rms();
    if tc_rms > spp_rms {
        failures.push(format!(
            "full sky: tightly coupled RMS {tc_rms:.3} m > loosely coupled on the same measurements {spp_rms:.3} m"
        ));
    }
    // The carrier's time differences and the code's correlation model keep the solution within
    // a metre of the RTK track (0.71 m measured; 4.97 m fusing 4 Hz code as white noise alone).
    if tc_rms > MAX_TIGHT_RMS_M {
        failures.push(format!(
            "full sky: tightly coupled RMS {tc_rms:.3} m > {MAX_TIGHT_RMS_M} m"
        ));
    }
    // With 3 satellites every window costs tight at most a third of loose's coasting (issue 36).
    let three = KS.iter().position(|k| *k == 3).expect("the 3-satellite variants");
    let row = |j: usize| &costs[three * nc + j];
    let met = row(0).iter().zip(row(2)).filter(|(l, t)| **t <= **l / 3.0).count();
    if met < WINDOWS {
        failures.push(format!(
            "3 satellites: tight's window costs {:?} at most a third of loose's {:?} in {met} of {WINDOWS} windows",
            row(2),
            row(0)
        ));
    }
    for (i, (name, _, _)) in variants.iter().enumerate() {
        let tc = &runs[nc * i + 2];
        let counter = |k: &str| tc.summary["measurement_counters"][k].as_u64().unwrap_or(0);
        if counter("carrier_deltas_used") == 0 {
            failures.push(format!("{name}: no carrier phase difference fused"));
        }
        for system in ["gps", "galileo", "beidou"] {
            if counter(&format!("ranges_used_{system}")) == 0 {
                failures.push(format!("{name}: tightly coupled fused no {system} range"));
            }
        }
        for j in [1, 2] {
            let cov = runs[nc * i + j].coverage();
            if cov < MIN_COVERAGE {
                failures.push(format!(
                    "{name}, {}: N and E within 2σ at {cov:.3} of the RTK-fixed epochs (< {MIN_COVERAGE})",
                    COUPLINGS[j]
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
