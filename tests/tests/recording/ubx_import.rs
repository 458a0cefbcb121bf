//! `navsync import ubx` on a real receiver's own log (`../shared/datasets/rtklibexplorer-walk0827`:
//! a u-blox X20's UBX log of a 134 s walk, RTKLIB's time-tag file of it, the IMU already on GPS
//! time in KF-GINS's format): the recording holds what the live driver's decoder finds in the
//! log, every channel's host times increase, the fixes lie on the IMU's axis (at their epoch
//! plus the nominal latency, or at the logging PC's time of their chunk with `--tag`), and
//! `replay --estimate` follows the receiver's RTK-fixed epochs, but not when the IMU is 1 s off.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use navsync_drivers::gnss::{Decoder, GnssDecoder, GnssExtra, Protocol};
use navsync_recording::SampleReader;
use navsync_shared::samples::{AnySample, GnssFix};
use navsync_tests::{TestEnv, shared_material, walk0827_antenna_error, walk0827_reference};
use serde_json::Value;

const WEEK_NS: i64 = 604_800_000_000_000;
const WEEK: i64 = 2381;
/// The bound on the horizontal RMS at the RTK-fixed epochs, m (measured 0.042 m; the IMU 1 s
/// late gives 0.99 m).
const RMS_BOUND_M: f64 = 0.15;
/// The same for the tightly coupled filter on the log's raw epochs (its whole log: 0.150 m,
/// `tests/tests/estimator/tight_walk.rs`).
const TIGHT_RMS_BOUND_M: f64 = 0.5;
/// The same for a filter aligned on navsync's single-point solutions of the log's raw epochs
/// (those are 8.26 m from the track, RTKLIB's 8.29 m: `tests/tests/estimator/spp_walk.rs`).
const SPP_RMS_BOUND_M: f64 = 9.0;

fn data() -> PathBuf {
    shared_material("datasets/rtklibexplorer-walk0827")
}

fn log() -> PathBuf {
    data().join("source/gnss_1730.ubx")
}

fn tag() -> PathBuf {
    data().join("source/gnss_1730.ubx.tag")
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

/// `import ubx` of the walk's log with `imu` and `extra` flags into `name`.mcap; the
/// recording and the import's stderr.
fn import(env: &TestEnv, name: &str, imu: &Path, extra: &[&str]) -> (PathBuf, String) {
    let rec = env.dir.join(format!("{name}.mcap"));
    let mut args = vec!["import", "ubx"];
    let (l, i, r) = (p(&log()), p(imu), p(&rec));
    args.extend([l.as_str(), "--imu", i.as_str(), "--out", r.as_str()]);
    args.extend(extra);
    let err = run_ok(env, &args);
    (rec, err)
}

/// The GPS seconds of week of the IMU file's rows.
fn imu_sows(imu: &Path) -> Vec<f64> {
    std::fs::read_to_string(imu)
        .unwrap()
        .lines()
        .filter_map(|l| l.split_whitespace().next()?.parse().ok())
        .collect()
}

/// What a recording holds.
#[derive(Default)]
struct Recorded {
    fixes: Vec<GnssFix>,
    raw: usize,
    nav_data: usize,
    imu_hosts: Vec<i64>,
    pps_hosts: Vec<i64>,
    /// `navsync.time_axis`: (host ns, GPS ns).
    axis: (i64, i64),
}

impl Recorded {
    /// GPS ns of a host time on the recording's axis.
    fn gps_ns(&self, host_ns: i64) -> i64 {
        self.axis.1 + (host_ns - self.axis.0)
    }
    /// Host ns of a GPS time.
    fn host_ns(&self, gps_ns: i64) -> i64 {
        self.axis.0 + (gps_ns - self.axis.1)
    }
}

/// Reads a recording, checking every channel's stamps strictly increase.
fn read(rec: &Path) -> Recorded {
    let mut r = SampleReader::open(rec).unwrap();
    let axis = r
        .channel_metadata("navsync/imu/0/sample")
        .into_iter()
        .find(|(k, _)| k == "navsync.time_axis")
        .map(|(_, v)| serde_json::from_str::<Value>(&v).unwrap())
        .expect("navsync.time_axis on the IMU's channel");
    let mut out = Recorded {
        axis: (axis["host_ns"].as_i64().unwrap(), axis["gps_ns"].as_i64().unwrap()),
        ..Recorded::default()
    };
    let mut last: HashMap<String, i64> = HashMap::new();
    while let Some(s) = r.next_sample().unwrap() {
        let host = match &s.sample {
            AnySample::GnssFix(f) => f.stamp.host_ns,
            AnySample::Raw(x) => x.stamp.host_ns,
            AnySample::NavData(x) => x.stamp.host_ns,
            AnySample::Imu(x) => x.stamp.host_ns,
            AnySample::PpsEdge(x) => x.stamp.host_ns,
            other => panic!("unexpected sample {other:?} on {}", s.service),
        };
        let prev = last.entry(s.service.to_string()).or_insert(i64::MIN);
        assert!(host > *prev, "{}: host time {host} after {prev}", s.service);
        *prev = host;
        match s.sample {
            AnySample::GnssFix(f) => out.fixes.push(f),
            AnySample::Raw(_) => out.raw += 1,
            AnySample::NavData(_) => out.nav_data += 1,
            AnySample::Imu(_) => out.imu_hosts.push(host),
            AnySample::PpsEdge(_) => out.pps_hosts.push(host),
            _ => {}
        }
    }
    out
}

/// What the live driver's decoder finds in the log: (fixes, raw epochs, navigation data).
fn decoded_counts() -> (usize, usize, usize) {
    let bytes = std::fs::read(log()).unwrap();
    let (mut fixes, mut raw, mut nav) = (0, 0, 0);
    let mut d = Decoder::new(Protocol::Ubx);
    for chunk in bytes.chunks(4096) {
        d.push_extras(chunk, 0, 0, &mut |_| fixes += 1, &mut |x| match x {
            GnssExtra::Raw(_) => raw += 1,
            GnssExtra::NavData(_) => nav += 1,
            _ => {}
        });
    }
    d.flush(&mut |_| fixes += 1);
    (fixes, raw, nav)
}

/// Counts as the log's (the decoder's, `navsync decode`'s and the dataset README's figures),
/// the IMU file's rows, and each IMU sample at its row's GPS time on the recording's axis.
fn check_counts_and_imu_axis(r: &Recorded, imu: &[f64]) {
    let (fixes, raw, nav) = decoded_counts();
    assert_eq!(
        (fixes, raw, nav),
        (536, 536, 2328),
        "the decoder on the log (README: 536, 536, 2328)"
    );
    assert_eq!((r.fixes.len(), r.raw, r.nav_data), (fixes, raw, nav));
    assert_eq!(r.imu_hosts.len(), imu.len());
    for (h, sow) in r.imu_hosts.iter().zip(imu) {
        let g = WEEK * WEEK_NS + (sow * 1e9).round() as i64;
        assert!((r.gps_ns(*h) - g).abs() <= 1_000, "IMU row {sow}: host {h}");
    }
    // PPS edges on whole GPS seconds, one a second over the span.
    assert!(r.pps_hosts.len() >= 134, "{} PPS edges", r.pps_hosts.len());
    for h in &r.pps_hosts {
        assert_eq!(r.gps_ns(*h).rem_euclid(1_000_000_000), 0, "PPS edge at host {h}");
    }
}

/// Each fix's epoch between the IMU samples around its GPS time (by the IMU file's rows), and
/// its receipt after the epoch; the receipt latencies, s.
fn check_fixes_on_the_imu_axis(r: &Recorded, imu: &[f64]) -> Vec<f64> {
    let mut latencies = Vec::new();
    let mut bracketed = 0;
    for f in &r.fixes {
        let s = (f.gps_ns - WEEK * WEEK_NS) as f64 * 1e-9;
        let epoch_host = r.host_ns(f.gps_ns);
        let k = imu.partition_point(|t| *t <= s);
        if k > 0 && k < imu.len() {
            assert!(
                r.imu_hosts[k - 1] <= epoch_host && epoch_host < r.imu_hosts[k],
                "fix at {s}: epoch host {epoch_host} not between the IMU rows {} and {}",
                imu[k - 1],
                imu[k]
            );
            bracketed += 1;
        }
        let latency = (f.stamp.host_ns - epoch_host) as f64 * 1e-9;
        assert!(
            latency > 0.0 && latency < 0.2,
            "fix at {s} received {latency} s after its epoch"
        );
        latencies.push(latency);
    }
    assert!(bracketed >= 530, "{bracketed} fixes within the IMU's span");
    latencies
}

#[test]
fn the_walks_ubx_log_imports_with_its_counts_on_the_imus_time_axis() {
    let env = TestEnv::new("ubximport");
    let imu_path = data().join("imu.txt");
    let imu = imu_sows(&imu_path);
    let decode = run_ok(&env, &["decode", &p(&log())]);
    assert!(decode.starts_with("536 epochs;"), "navsync decode: {decode}");
    let (rec, err) = import(&env, "epochs", &imu_path, &[]);
    assert!(
        err.contains("536 fixes, 536 raw epochs, 2328 navigation data messages"),
        "{err}"
    );
    let r = read(&rec);
    check_counts_and_imu_axis(&r, &imu);
    // Without tags: each fix the nominal 50 ms after its epoch.
    for l in check_fixes_on_the_imu_axis(&r, &imu) {
        assert!((l - 0.05).abs() < 1e-6, "latency {l}");
    }
}

#[test]
fn the_walks_ubx_log_with_its_time_tags_lies_at_the_logging_pcs_times() {
    let env = TestEnv::new("ubxtag");
    let imu_path = data().join("imu.txt");
    let imu = imu_sows(&imu_path);
    let (rec, err) = import(&env, "tags", &imu_path, &["--tag", &p(&tag())]);
    // The tag file: 76-byte header, 1715 records of 8 bytes, the last at the log's end.
    assert!(err.contains("1715 time tags, 0 bytes after the last"), "{err}");
    let r = read(&rec);
    check_counts_and_imu_axis(&r, &imu);
    let mut lat = check_fixes_on_the_imu_axis(&r, &imu);
    lat.sort_by(f64::total_cmp);
    let (lo, med, hi) = (lat[0], lat[lat.len() / 2], lat[lat.len() - 1]);
    eprintln!("fixes received {lo:.3} / {med:.3} / {hi:.3} s after their epoch (min / median / max)");
    assert!(hi - lo > 0.01, "receipt latencies {lo}..{hi} s: not the PC's times");
    // Read here independently of the import: the open time (GPS seconds since 1970 and a
    // fraction at bytes 64 and 68); every fix stamped a whole millisecond tick after it.
    let t = std::fs::read(tag()).unwrap();
    let secs = i64::from(u32::from_le_bytes(t[64..68].try_into().unwrap()));
    let frac = f64::from_le_bytes(t[68..76].try_into().unwrap());
    let open_gps_ns = (secs - 315_964_800) * 1_000_000_000 + (frac * 1e9).round() as i64;
    assert_eq!(open_gps_ns, WEEK * WEEK_NS + 408_639_657_000_000);
    for f in &r.fixes {
        let since_open = r.gps_ns(f.stamp.host_ns) - open_gps_ns;
        assert_eq!(
            since_open.rem_euclid(1_000_000),
            0,
            "fix stamp {since_open} ns after the open"
        );
    }
}

/// The receiver's RTK-fixed epochs: (sow, lat, lon).
fn rtk_fixed() -> Vec<(f64, f64, f64)> {
    walk0827_reference()
        .into_iter()
        .filter(|r| r.3 == 1.0)
        .map(|r| (r.0, r.1, r.2))
        .collect()
}

/// `replay --estimate` of a recording: the horizontal RMS and largest error at the antenna
/// against the RTK-fixed epochs (m, the output interpolated to each), epochs compared, Δ and
/// its σ (s), and how often the monitor reset Δ.
fn estimate(env: &TestEnv, rec: &Path, name: &str) -> (f64, f64, usize, f64, f64, u64) {
    estimate_with(env, rec, name, &[])
}

/// As [`estimate`], with `extra` flags for the replay.
fn estimate_with(env: &TestEnv, rec: &Path, name: &str, extra: &[&str]) -> (f64, f64, usize, f64, f64, u64) {
    let nav = env.dir.join(format!("{name}.nav"));
    let summary = env.dir.join(format!("{name}.json"));
    let (r, s, n) = (p(rec), p(&summary), p(&nav));
    let mut args = vec![
        "replay",
        r.as_str(),
        "--estimate",
        "--lever-arm",
        "0,-0.05,0",
        "--summary-json",
        s.as_str(),
        "--out",
        n.as_str(),
        "--format",
        "kf-gins",
    ];
    args.extend(extra);
    run_ok(env, &args);
    let s: Value = serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    assert!(s["problem"].is_null(), "{name}: {}", s["problem"]);
    let rows: Vec<Vec<f64>> = std::fs::read_to_string(&nav)
        .unwrap()
        .lines()
        .map(|l| l.split_whitespace().map(|x| x.parse().unwrap()).collect())
        .collect();
    assert!(
        rows.iter().flatten().all(|x: &f64| x.is_finite()),
        "{name}: a value that is not finite in the output"
    );
    let (mut sum, mut max, mut n) = (0.0, 0.0f64, 0usize);
    for (sow, lat, lon) in rtk_fixed() {
        let Some((north, east)) = walk0827_antenna_error(&rows, sow, lat, lon) else {
            continue;
        };
        let d2 = north * north + east * east;
        sum += d2;
        max = max.max(d2.sqrt());
        n += 1;
    }
    let rms = (sum / n.max(1) as f64).sqrt();
    let (d, sd) = (
        s["gnss_delay_est_s"].as_f64().unwrap(),
        s["gnss_delay_std_s"].as_f64().unwrap(),
    );
    let delay_resets = s["measurement_counters"]["integrity_delay_resets"]
        .as_u64()
        .unwrap_or(0);
    eprintln!(
        "{name}: {n} RTK-fixed epochs, horizontal RMS {rms:.3} m, max {max:.3} m; Δ {d:+.4} ± {sd:.4} s, {delay_resets} resets of Δ"
    );
    (rms, max, n, d, sd, delay_resets)
}

#[test]
fn the_walk_imported_from_ubx_is_estimated_within_its_rtk_fixes_and_a_shifted_imu_is_not() {
    let env = TestEnv::new("ubxestimate");
    let imu_path = data().join("imu.txt");
    let tag = p(&tag());
    for (name, extra) in [
        ("epochs", vec![]),
        ("tags", vec!["--tag", tag.as_str()]),
        ("tags-no-pps", vec!["--tag", tag.as_str(), "--no-pps"]),
    ] {
        let (rec, _) = import(&env, name, &imu_path, &extra);
        let (rms, _, n, d, _, _) = estimate(&env, &rec, name);
        // Output from 1.8 s after the motion starts (408652 s): the walk's fixed epochs after it.
        assert!(n >= 290, "{name}: {n} epochs compared");
        assert!(rms <= RMS_BOUND_M, "{name}: horizontal RMS {rms:.3} m");
        if extra.contains(&"--no-pps") {
            // Software sync: Δ is the receipt delay, the tags' 24–74 ms (median 42 ms).
            assert!((0.0..0.1).contains(&d), "{name}: Δ {d} s");
        } else {
            // Hardware sync: Δ is what is left after the PPS mapping (the README: ±0.03 s).
            assert!(d.abs() <= 0.05, "{name}: Δ {d} s");
        }
    }
    // The IMU's tags 1 s late (a broken axis): Δ saturates near −0.5 s and the RMS more than
    // doubles the bound.
    let shifted: String = std::fs::read_to_string(&imu_path)
        .unwrap()
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let (t, rest) = l.trim().split_once(char::is_whitespace).unwrap();
            format!("{:.5} {rest}\n", t.parse::<f64>().unwrap() + 1.0)
        })
        .collect();
    let shifted_path = env.dir.join("imu_late.txt");
    std::fs::write(&shifted_path, shifted).unwrap();
    let (rec, _) = import(&env, "imu-late", &shifted_path, &[]);
    let (rms, _, _, d, _, delay_resets) = estimate(&env, &rec, "imu-late");
    assert!(
        rms > RMS_BOUND_M,
        "the IMU 1 s late: horizontal RMS {rms:.3} m within the bound"
    );
    // 1 s is beyond what Δ may be under PPS (−0.5 s … the horizon): the filter drives Δ to its
    // bound, and the monitor starts it again from its prior each time, counted (before that
    // rule it published Δ −0.5 s with a σ of milliseconds).
    assert!(delay_resets > 0, "the IMU 1 s late: Δ {d} s and no reset of Δ counted");
}

/// The byte ranges and (class, id) of the UBX frames in `bytes` (NMEA, RTCM3 and every other
/// byte between them skipped).
fn ubx_frames(bytes: &[u8]) -> Vec<(std::ops::Range<usize>, (u8, u8))> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i..].starts_with(&[0xb5, 0x62]) && i + 6 <= bytes.len() {
            let len = usize::from(u16::from_le_bytes([bytes[i + 4], bytes[i + 5]]));
            let end = (i + 8 + len).min(bytes.len());
            out.push((i..end, (bytes[i + 2], bytes[i + 3])));
            i = end;
        } else {
            i += 1;
        }
    }
    out
}

/// The walk's log damaged as a serial line or a disk damages one: `flips` single bits flipped
/// at places drawn from `seed` (the simulator's generator), and the last `cut` bytes gone (the
/// last frame cut short). Also returns how many of the log's NAV-PVT, RXM-RAWX and RXM-SFRBX
/// frames the damage touched (a flipped bit anywhere in the frame, its sync bytes included, or
/// a byte of it cut).
fn damaged_log(seed: u64, flips: usize, cut: usize) -> (Vec<u8>, usize) {
    let original = std::fs::read(log()).unwrap();
    let mut bytes = original.clone();
    let mut rng = navsync_sim::rng::Rng::new(seed);
    let mut flipped = Vec::with_capacity(flips);
    for _ in 0..flips {
        let at = (rng.next_u64() % bytes.len() as u64) as usize;
        flipped.push(at);
        bytes[at] ^= 1 << (rng.next_u64() % 8);
    }
    let kept = bytes.len() - cut;
    let touched = ubx_frames(&original)
        .into_iter()
        .filter(|(r, id)| {
            [(0x01, 0x07), (0x02, 0x15), (0x02, 0x13)].contains(id)
                && (r.end > kept || flipped.iter().any(|at| r.contains(at)))
        })
        .count();
    bytes.truncate(kept);
    (bytes, touched)
}

/// A damaged copy of the log: the import keeps every frame that survived, says on stderr how
/// many were skipped and why (the decoder's error counters, by name), and the recording is
/// estimated both ways as the whole log is, with nothing that is not finite in the output.
#[test]
fn a_damaged_log_keeps_what_survived_and_says_what_was_skipped() {
    let env = TestEnv::new("ubxdamaged");
    let imu = data().join("imu.txt");
    let (_, raw_whole, nav_whole) = decoded_counts();
    let damaged = env.dir.join("damaged.ubx");
    let (bytes, touched) = damaged_log(0x9e37_79b9_7f4a_7c15, 100, 1000);
    std::fs::write(&damaged, bytes).unwrap();
    let rec = env.dir.join("damaged.mcap");
    let err = run_ok(
        &env,
        &["import", "ubx", &p(&damaged), "--imu", &p(&imu), "--out", &p(&rec)],
    );
    eprintln!("{err}");
    // The frames dropped whole, by the counters the import names (a bad checksum or length).
    let counted = |name: &str| -> Option<u64> {
        err.lines()
            .find_map(|l| l.split(&format!(": {name} ")).nth(1)?.split(':').next()?.parse().ok())
    };
    let skipped = counted("ubx_bad_checksum")
        .unwrap_or_else(|| panic!("the import does not count the damaged frames:\n{err}"))
        + counted("ubx_bad_length").unwrap_or(0);
    let r = read(&rec);
    // Only damaged frames are lost: a frame with a bad checksum or length is counted, one whose
    // sync bytes were hit is not a frame any more (its bytes are counted as noise), and the
    // last one is cut short.
    let lost = (536 - r.fixes.len()) + (raw_whole - r.raw) + (nav_whole - r.nav_data);
    eprintln!("{lost} messages lost, {touched} frames damaged, {skipped} dropped for a bad checksum or length");
    assert!(r.raw > 0 && !r.fixes.is_empty(), "nothing survived");
    assert!(
        lost <= touched && skipped as usize <= touched,
        "{lost} messages lost and {skipped} frames dropped for a bad checksum or length, {touched} frames damaged"
    );
    // The fixes lost are at most the damaged ones: loosely coupled as the whole log is.
    let (rms, _, n, _, _, _) = estimate(&env, &rec, "damaged-loose");
    assert!(n >= 280 && rms <= RMS_BOUND_M, "loose: {n} epochs, RMS {rms:.3} m");
    // Tightly coupled on the raw epochs that survived.
    let (rms, _, n, _, _, _) = estimate_with(&env, &rec, "damaged-tight", &["--coupling", "tight"]);
    assert!(
        n >= 280 && rms <= TIGHT_RMS_BOUND_M,
        "tight: {n} epochs, RMS {rms:.3} m"
    );
}

/// The walk's log without its UBX frames of (class, id) in `drop` (NMEA, RTCM3 and every other
/// byte kept).
fn log_without(drop: &[(u8, u8)]) -> Vec<u8> {
    let bytes = std::fs::read(log()).unwrap();
    let mut out = Vec::with_capacity(bytes.len());
    let mut at = 0;
    for (r, id) in ubx_frames(&bytes) {
        out.extend_from_slice(&bytes[at..r.start]);
        if !drop.contains(&id) {
            out.extend_from_slice(&bytes[r.clone()]);
        }
        at = r.end;
    }
    out.extend_from_slice(&bytes[at..]);
    out
}

/// A logger's log of raw measurements only (RXM-RAWX and RXM-SFRBX, no NAV-PVT, as RTKLIB's
/// users log a u-blox): its raw epochs label the PPS edges, the tightly coupled filter aligns
/// on its own single-point solutions and stays on them (8.26 m from the RTK track, as navsync's
/// and RTKLIB's single-point solutions of the log are: the track's base, see
/// docs/benchmarks/accuracy.md); loose coupling, which has no fix, says so.
/// A log without navigation data (no RXM-SFRBX): tightly coupled, no satellite can be fused,
/// and the run says so and fails instead of coasting silently.
#[test]
fn a_log_of_raw_measurements_alone_or_without_navigation_data_is_estimated() {
    let env = TestEnv::new("ubxrawonly");
    let imu = data().join("imu.txt");
    let import_log = |name: &str, bytes: Vec<u8>| -> PathBuf {
        let path = env.dir.join(format!("{name}.ubx"));
        std::fs::write(&path, bytes).unwrap();
        let rec = env.dir.join(format!("{name}.mcap"));
        run_ok(
            &env,
            &["import", "ubx", &p(&path), "--imu", &p(&imu), "--out", &p(&rec)],
        );
        rec
    };
    let counters = |name: &str| -> Value {
        let s: Value =
            serde_json::from_str(&std::fs::read_to_string(env.dir.join(format!("{name}.json"))).unwrap()).unwrap();
        s["measurement_counters"].clone()
    };

    // Raw measurements alone (NAV-PVT is class 0x01, id 0x07).
    let raw_only = import_log("raw-only", log_without(&[(0x01, 0x07)]));
    let r = read(&raw_only);
    assert!(
        r.fixes.is_empty() && r.raw == 536,
        "{} fixes, {} raw epochs",
        r.fixes.len(),
        r.raw
    );
    let (rms, _, n, _, _, _) = estimate_with(&env, &raw_only, "raw-only-tight", &["--coupling", "tight"]);
    let c = counters("raw-only-tight");
    eprintln!(
        "raw-only tight: {} ranges in {} epochs",
        c["ranges_used"], c["ranges_epochs_used"]
    );
    assert!(
        n >= 250 && rms <= SPP_RMS_BOUND_M,
        "raw only, tight: {n} epochs, RMS {rms:.3} m"
    );
    let o = env.command(&["replay", &p(&raw_only), "--estimate"]).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("no GNSS fix"),
        "raw only, loose: {}\n{err}",
        o.status
    );

    // No navigation data (RXM-SFRBX is class 0x02, id 0x13).
    let no_nav = import_log("no-nav", log_without(&[(0x02, 0x13)]));
    let o = env
        .command(&["replay", &p(&no_nav), "--estimate", "--coupling", "tight"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("no satellite was fused") && err.contains("no ephemeris"),
        "no navigation data, tight: {}\n{err}",
        o.status
    );
    // Loosely coupled it is the whole log's run.
    let (rms, _, n, _, _, _) = estimate(&env, &no_nav, "no-nav-loose");
    assert!(
        n >= 280 && rms <= RMS_BOUND_M,
        "no navigation data, loose: {n} epochs, RMS {rms:.3} m"
    );
}

#[test]
fn bad_inputs_are_errors_that_name_the_file() {
    let env = TestEnv::new("ubxbad");
    let imu = data().join("imu.txt");
    let fail = |args: &[&str]| -> String {
        let o = env.command(args).output().unwrap();
        assert!(!o.status.success(), "navsync {args:?} succeeded");
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(!err.contains("panicked"), "{err}");
        err
    };
    let out = p(&env.dir.join("bad.mcap"));
    // A log without a UBX epoch.
    let text = env.dir.join("text.ubx");
    std::fs::write(&text, "not a receiver's log\n").unwrap();
    let err = fail(&["import", "ubx", &p(&text), "--imu", &p(&imu), "--out", &out]);
    assert!(err.contains("text.ubx: no UBX epoch"), "{err}");
    // A tag file that is not RTKLIB's.
    let err = fail(&[
        "import",
        "ubx",
        &p(&log()),
        "--imu",
        &p(&imu),
        "--tag",
        &p(&text),
        "--out",
        &out,
    ]);
    assert!(err.contains("text.ubx: byte 0: not an RTKLIB time-tag file"), "{err}");
    // An IMU file with a bad line: its file and line.
    let bad_imu = env.dir.join("imu_bad.txt");
    std::fs::write(&bad_imu, "408640.97345 0 0 0 0 0 -0.098\n408640.98339 0 0 0 0 0 x\n").unwrap();
    let err = fail(&["import", "ubx", &p(&log()), "--imu", &p(&bad_imu), "--out", &out]);
    assert!(err.contains("imu_bad.txt:2: `x` is not a number"), "{err}");
    assert!(!env.dir.join("bad.mcap").exists(), "a recording left behind");
}
