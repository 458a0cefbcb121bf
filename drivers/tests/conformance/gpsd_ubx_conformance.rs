//! Conformance of the u-blox front end (framer, message decoders, epoch assembler) with gpsd,
//! on gpsd's u-blox regression captures (`shared/corpora/gpsd-ubx`, outside the repository).
//!
//! Every capture is decoded with `Protocol::Auto`, the setting for a u-blox port: the
//! captures are what such a port sends (UBX interleaved with NMEA and RTCM3), `auto` decodes
//! their UBX navigation and falls back to the NMEA sentences only on a port without it, and
//! the table shows which protocol every epoch came from (`nmea` column), so a capture
//! decoded from NMEA would be visible. (`ubx` would give the same epochs on this corpus, where
//! every capture with fixes carries UBX NAV messages; `auto` also runs the NMEA path.)
//!
//! **TPV.** For every capture `NAME.log`, gpsd's output `NAME.log.chk` holds TPV reports;
//! gpsd refines a TPV as more messages of one epoch arrive, so for every distinct TPV `time`
//! the LAST TPV carrying it is gpsd's view of that epoch. The decoder's fix with the same time
//! (gpsd prints times rounded to the millisecond; the last fix, should there be several) is
//! compared with it:
//!
//! - `time`: equal to gpsd's millisecond; `mode`: equal;
//! - `lat`/`lon`: within 1e-7°; `altHAE` ([`GnssFix::height_m`]) and `altMSL`: within
//!   1 mm; `speed`: within 1 mm/s; `track`: within 0.01°; `climb` (−velD): within 1 mm/s;
//! - the accuracies gpsd takes from the receiver: `eph` = hAcc, `epv` = vAcc (within 1 mm),
//!   `eps` = sAcc (within 5 mm/s: gpsd prints it to the centimetre).
//!
//! A field is compared only where gpsd reports it (gpsd omits what it does not know and
//! hides position and velocity below a 2D fix). The decoder reports what the receiver sent;
//! gpsd also computes quantities of its own and merges every protocol of the port. Values of
//! gpsd's that are recognisably its own are not compared but counted per field in the
//! table's last column:
//!
//! - `geoid:altMSL` where the receiver sent no MSL height (NAV-SOL only): gpsd's geoid model
//!   against navsync's (`FIX_GEOID_MODEL`), within [`GEOID_MODELS_TOL_M`];
//! - `altMSL`, `speed`, `track`, `climb` where we have no value: no velocity (gpsd differences positions), no vertical velocity
//!   (gpsd takes no velD from NAV-PVT/HNR-PVT and differences successive heights: `climb`
//!   is compared where gpsd's TPV carries the receiver's `velD`);
//! - `eph`/`epv` equal to one of the DOPs gpsd printed for the epoch × its UERE (19/23 m,
//!   4.75/5.75 m with DGPS), and `eps` equal to its error model's
//!   `(max(epx', epy') + max(epx, epy)) / Δt`, which replaces the receiver's sAcc whenever a
//!   message of the epoch arrives after the one that carried it (recognised by the formula
//!   with the previous epoch's TPV, or, for gpsd's first epoch, whose predecessor it did not
//!   print, with this epoch's epx/epy and the receiver's epoch interval; or by an earlier TPV
//!   of the same time that still showed the receiver's value);
//! - `nmea:field`: a value gpsd took from the NMEA sentences the receiver sent for the same
//!   epoch besides the UBX messages (`auto` reports the UBX solution): equal to the
//!   sentence's value (the same capture decoded as NMEA), which agrees with ours to the
//!   sentence's resolution (0.1 m altitudes, 1e-5′ latitude/longitude);
//! - `velned:field` (speed, track, climb, eps): gpsd's NAV-VELNED value (cm/s) where the
//!   receiver also sent NAV-PVT, whose finer value (mm/s) the decoder reports (precedence
//!   table in `docs/guide/receivers.md`); agreeing to NAV-VELNED's resolution;
//! - `ecef:climb`: gpsd's climb from NAV-SOL's ECEF velocity (cm/s, printed in the TPV,
//!   rotated here) where the receiver also sent NAV-PVT, whose velD (mm/s) the decoder
//!   reports; agreeing to the ECEF resolution.
//!
//! A value of ours that is unknown where gpsd has the receiver's (position, ellipsoidal
//! height, a climb from velD, an accuracy not recognised as gpsd's model) is a difference.
//!
//! Every other difference is a named [`EXCEPTIONS`] entry (a condition on gpsd's TPV and our
//! fix, limited to the captures and fields it names) with its reason, or a [`TIME_SHIFTS`]
//! entry for captures whose dates gpsd moved by whole GPS week rollovers. The test fails on
//! any difference that no exception explains, on an exception that no longer applies, and
//! when fewer than 99 % of all of gpsd's timed epochs match (excepted epochs count as not
//! matching).
//!
//! **SKY.** Where NAV-SAT or NAV-SVINFO is present, the `GnssSky` samples the decoder
//! publishes (`navsync/gnss/{id}/sky`, the first per epoch time) are compared with gpsd's first
//! SKY with satellites at that time (gpsd prints it on NAV-SAT/NAV-SVINFO; later SKYs of the
//! same time come from NAV-SIG, which this front end does not decode): `uSat` with the
//! satellites flagged used, and for every satellite gpsd lists (matched by `gnssid`/`svid`) its
//! elevation and azimuth (whole degrees), where gpsd gives them, its C/N0 (`ss`, dB-Hz) and
//! whether it is used.
//!
//! **PPS.** gpsd prints PPS and TOFF objects only for a PPS source, which `gpsfake` (that
//! produced the `.chk` files) does not have: the corpus holds none. What corresponds to them
//! is checked instead: every TIM-TP announces the next pulse, and its time (converted to
//! UTC) must be one second after the NAV epoch that follows it (rounded to the second), and
//! the time of an epoch gpsd reports, to 1 ms (the pulse marks that epoch's second; Antaris
//! receivers measure 1 ms before the second).
//!
//! Run with `-- --nocapture` for the per-capture table. Diagnostics: `UBX_ALL=1` prints every
//! unexplained mismatch, `UBX_COUNTERS=1` the decoder's non-zero counters per capture,
//! `UBX_DUMP=NAME.log` the decoder's epochs and gpsd's for one capture.

use crate::gpsd_common;

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use navsync_drivers::gnss::capture::{REPLAY_NS_PER_BYTE, decode_capture, epoch_json};
use navsync_drivers::gnss::ubx::auto::AutoDecoder;
use navsync_drivers::gnss::ubx::ecef::ned_from_ecef_velocity;
use navsync_drivers::gnss::{GnssDecoder, GnssExtra, Protocol};
use navsync_shared::samples::{
    FIX_GEOID_MODEL, GNSS_PROTOCOL_NMEA, GnssFix, GnssSky, UBX_MSG_HNR_PVT, UBX_MSG_NAV_PVT, UBX_MSG_NAV_VELNED,
};
use navsync_shared::time::{Civil, NS_PER_S, format_rfc3339_ms, gps_minus_utc_s, utc_ns_from_civil};
use serde_json::Value;

/// Tolerances.
const LATLON_TOL_DEG: f64 = 1e-7;
const ALT_TOL_M: f64 = 1e-3;
const SPEED_TOL_MPS: f64 = 1e-3;
const TRACK_TOL_DEG: f64 = 0.01;
const CLIMB_TOL_MPS: f64 = 1e-3;
/// eph/epv: mm values, printed by gpsd with 3 decimals.
const ACC_TOL_M: f64 = 1e-3;
/// eps: printed by gpsd with 2 decimals, so half a centimetre per second.
const EPS_TOL_MPS: f64 = 0.005 + 1e-9;
/// gpsd's geoid (EGM2008 bilinear in a 5° grid) against navsync's (EGM96 from its
/// coefficients), m: the coarse grid is off by metres in places.
const GEOID_MODELS_TOL_M: f64 = 5.0;
/// Share of all of gpsd's timed epochs that must match.
const MIN_MATCH_RATIO: f64 = 0.99;
/// Captures expected in the corpus (a smaller number means it is incomplete).
const EXPECTED_CAPTURES: usize = 21;

/// A deliberate difference from gpsd.
struct Exception {
    /// Short name for the report.
    name: &'static str,
    /// Captures it applies to (empty: any capture, the condition alone identifies it).
    captures: &'static [&'static str],
    /// gpsd TPV times it applies to; empty: wherever `applies` holds in those captures.
    times: &'static [&'static str],
    /// Compared fields it explains (`time`: no decoded epoch at gpsd's time; SKY: `sky_time`,
    /// `sky_used`, `sky_sat`, `sky_el`, `sky_az`; PPS: `pps`).
    fields: &'static [&'static str],
    /// The condition (gpsd's object, our fix at that time …) that identifies the difference.
    applies: fn(&Ctx) -> bool,
    /// Why the decoder deliberately differs.
    reason: &'static str,
}

/// gpsd's leap-second count before the receiver has told it (its compiled-in default), s.
const GPSD_DEFAULT_LEAP_S: i64 = 18;

/// Our NAV fix at `t` (UTC ns, to the millisecond).
fn nav_fix_at(fixes: &[GnssFix], t: i64) -> Option<&GnssFix> {
    let key = gpsd_time(t);
    fixes
        .iter()
        .filter(|f| f.sentences & UBX_MSG_HNR_PVT == 0)
        .find(|f| f.utc_ns != i64::MIN && gpsd_time(f.utc_ns) == key)
}

const EXCEPTIONS: &[Exception] = &[
    Exception {
        name: "gpsd-default-leap-seconds",
        captures: &[],
        times: &[],
        fields: &["time"],
        applies: |c| {
            // No "leapseconds" yet, and our epoch is where gpsd's default leap count puts it.
            let Some(t) = c.tpv.get("time").and_then(Value::as_str).and_then(parse_gpsd_time) else {
                return false;
            };
            let shift = GPSD_DEFAULT_LEAP_S - i64::from(gps_minus_utc_s(t));
            c.tpv.get("leapseconds").is_none() && c.fix.is_none() && nav_fix_at(c.fixes, t + shift * NS_PER_S).is_some()
        },
        reason: "the capture starts with a NAV-SOL before the receiver's first NAV-TIMEGPS: gpsd converts its GPS \
                 time with its compiled-in 18 leap seconds (the 2007/2009 count was 14/15) and reports the epoch \
                 4/3 s early; the decoder uses the leap-second table until the receiver reports the count",
    },
    Exception {
        name: "gpsd-hnr-merged-into-nav-epoch",
        captures: &[],
        times: &[],
        fields: &["lat", "lon", "altHAE", "altMSL", "speed", "track", "eph", "epv", "eps"],
        applies: |c| {
            // gpsd's position is that of one of our HNR-PVT fixes: of this time, or received
            // during this NAV epoch (before the next one began).
            let (Some(fix), Some(lat), Some(lon)) = (c.fix, get(c.tpv, "lat"), get(c.tpv, "lon")) else {
                return false;
            };
            let end = c
                .fixes
                .iter()
                .filter(|f| f.sentences & UBX_MSG_HNR_PVT == 0 && f.stamp.host_ns > fix.stamp.host_ns)
                .map(|f| f.stamp.host_ns)
                .min()
                .unwrap_or(i64::MAX);
            c.fixes.iter().any(|h| {
                let same_time = gpsd_time(h.utc_ns) == gpsd_time(fix.utc_ns);
                let during = h.stamp.host_ns > fix.stamp.host_ns && h.stamp.host_ns < end;
                h.sentences & UBX_MSG_HNR_PVT != 0
                    && (same_time || during)
                    && (h.lat_deg - lat).abs() <= LATLON_TOL_DEG
                    && (h.lon_deg - lon).abs() <= LATLON_TOL_DEG
            })
        },
        reason: "gpsd merges HNR-PVT (the high-rate fused solution) into the NAV epoch it arrives in, as HNR-PVT \
                 does not start a cycle in gpsd: an HNR-PVT received between the epoch's NAV-PVT and NAV-TIMEGPS \
                 puts its position and velocity under the NAV epoch's time (neo-m8l), and for the capture's first \
                 NAV epoch, which gpsd does not report (it has not yet learned the receiver's cycle), the TPV of \
                 that time is the HNR-PVT's (neo-m8u-hnr); the decoder reports each HNR-PVT as a fix of its own \
                 and the NAV epoch, later, as the receiver sent it",
    },
];

/// Captures whose gpsd dates are later than the receiver's by whole GPS week rollovers: the
/// decoder's epoch for gpsd time `t` is looked up at `t − shift_s`; all fields are compared.
struct TimeShift {
    captures: &'static [&'static str],
    shift_s: i64,
    reason: &'static str,
}

const TIME_SHIFTS: &[TimeShift] = &[];

/// UTC ns of gpsd's `YYYY-MM-DDTHH:MM:SS.sssZ`.
fn parse_gpsd_time(s: &str) -> Option<i64> {
    let b = s.as_bytes();
    let n = |r: std::ops::Range<usize>| s.get(r).and_then(|t| t.parse::<u32>().ok());
    if b.len() != 24 || b[4] != b'-' || b[10] != b'T' || b[19] != b'.' || b[23] != b'Z' {
        return None;
    }
    let c = Civil {
        year: i64::from(n(0..4)?),
        month: n(5..7)?,
        day: n(8..10)?,
        hour: n(11..13)?,
        minute: n(14..16)?,
        second: n(17..19)?,
        nanos: n(20..23)? * 1_000_000,
    };
    Some(utc_ns_from_civil(&c))
}

/// gpsd's time text of a UTC instant: rounded to the nearest millisecond, as gpsd prints.
fn gpsd_time(utc_ns: i64) -> String {
    format_rfc3339_ms((utc_ns + 500_000).div_euclid(1_000_000) * 1_000_000)
}

fn corpus_dir() -> Result<PathBuf, String> {
    let beside = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/corpora/gpsd-ubx");
    if beside.is_dir() {
        return Ok(beside);
    }
    let env = std::env::var_os("NAVSYNC_SHARED_DIR").map(|d| PathBuf::from(d).join("corpora/gpsd-ubx"));
    match env {
        Some(d) if d.is_dir() => Ok(d),
        _ => Err(format!(
            "gpsd u-blox corpus not found: looked at {} and $NAVSYNC_SHARED_DIR/corpora/gpsd-ubx ({})",
            beside.display(),
            env.map_or("NAVSYNC_SHARED_DIR not set".to_owned(), |d| d.display().to_string())
        )),
    }
}

/// gpsd's JSON objects of one class, in order.
fn objects<'a>(chk: &'a str, class: &'a str) -> impl Iterator<Item = Value> + 'a {
    chk.lines().filter_map(move |line| {
        let line = line.trim();
        if !line.starts_with('{') {
            return None;
        }
        let v: Value = serde_json::from_str(line).ok()?;
        (v.get("class").and_then(Value::as_str) == Some(class)).then_some(v)
    })
}

/// gpsd's TPVs per distinct `time` in order of first appearance: (time, last TPV, the TPV
/// before the last one's time, i.e. gpsd's previous epoch's last TPV).
fn gpsd_epochs(chk: &str) -> Vec<(String, Value)> {
    let mut order: Vec<String> = Vec::new();
    let mut last: HashMap<String, Value> = HashMap::new();
    for v in objects(chk, "TPV") {
        let Some(time) = v.get("time").and_then(Value::as_str).map(str::to_owned) else {
            continue;
        };
        if !last.contains_key(&time) {
            order.push(time.clone());
        }
        last.insert(time, v);
    }
    order
        .into_iter()
        .filter_map(|t| last.remove(&t).map(|v| (t, v)))
        .collect()
}

/// One field difference.
struct Diff {
    field: &'static str,
    detail: String,
}

fn get(v: &Value, k: &str) -> Option<f64> {
    v.get(k).and_then(Value::as_f64)
}

/// What gpsd's TPV of one epoch is compared with, and what identifies the values gpsd
/// computed itself.
struct Ctx<'a> {
    /// gpsd's last TPV of the epoch.
    tpv: &'a Value,
    /// gpsd's earlier TPVs of the same time.
    earlier: &'a [Value],
    /// gpsd's last TPV of the previous epoch.
    prev: Option<&'a Value>,
    /// The DOPs gpsd printed (SKY objects, in file order) from the previous epoch's last TPV
    /// up to this epoch's last TPV: (hdop, vdop), the candidates for its error model's input.
    dops: &'a [Dops],
    /// Our fix at gpsd's time.
    fix: Option<&'a GnssFix>,
    /// The same capture's NMEA sentences decoded as NMEA: the epoch at gpsd's time.
    nmea: Option<&'a GnssFix>,
    /// All our fixes (for exceptions that look at neighbouring epochs).
    fixes: &'a [GnssFix],
}

/// The vertical speed of gpsd's printed ECEF velocity (`ecefvx`…, cm/s) at its position.
fn ecef_climb(tpv: &Value) -> Option<f64> {
    let [_, _, down] = ned_from_ecef_velocity(
        get(tpv, "lat")?,
        get(tpv, "lon")?,
        get(tpv, "ecefvx")?,
        get(tpv, "ecefvy")?,
        get(tpv, "ecefvz")?,
    );
    Some(-down)
}

/// gpsd's error-model speed error: `(max(epx', epy') + max(epx, epy)) / Δt`.
fn gpsd_model_eps(tpv: &Value, prev: Option<&Value>) -> Option<f64> {
    let prev = prev?;
    let dt = (parse_gpsd_time(tpv.get("time")?.as_str()?)? - parse_gpsd_time(prev.get("time")?.as_str()?)?) as f64
        / NS_PER_S as f64;
    let m = |v: &Value| Some(get(v, "epx")?.max(get(v, "epy")?));
    (dt > 0.0).then_some((m(prev)? + m(tpv)?) / dt)
}

/// gpsd's error-model speed error at its first reported epoch, whose predecessor gpsd did not
/// print: with the predecessor's epx/epy taken equal to this epoch's (DOPs change little
/// from one epoch to the next) and Δt the receiver's epoch interval (our previous NAV fix).
fn first_epoch_model_eps(c: &Ctx, fix: &GnssFix) -> Option<f64> {
    if c.prev.is_some() {
        return None;
    }
    let m = get(c.tpv, "epx")?.max(get(c.tpv, "epy")?);
    let before = c
        .fixes
        .iter()
        .filter(|f| f.sentences & UBX_MSG_HNR_PVT == 0 && f.utc_ns < fix.utc_ns)
        .map(|f| f.utc_ns)
        .max()?;
    let dt = (fix.utc_ns - before) as f64 / NS_PER_S as f64;
    (dt > 0.0).then_some(2.0 * m / dt)
}

/// `v` is one of the `dops` × one of gpsd's UEREs (without, with DGPS), to gpsd's printed
/// precision of `v` (DOPs from the receiver are exact hundredths). `dop_rounded`: also allow
/// for the rounding of a DOP gpsd computed itself (from the satellites, printed to 0.01);
/// used only where we have no value of our own to compare.
fn dop_model(v: Option<f64>, dops: impl Iterator<Item = Option<f64>>, ueres: [f64; 2], dop_rounded: bool) -> bool {
    let Some(v) = v else { return false };
    let slack = |u: f64| if dop_rounded { 0.005 * u } else { 0.0 };
    dops.flatten()
        .any(|d| ueres.iter().any(|u| (v - d * u).abs() <= 0.0005 + 1e-9 + slack(*u)))
}

/// (hdop, vdop) of one SKY object of gpsd's.
type Dops = (Option<f64>, Option<f64>);

/// For every TPV time, the DOPs of the SKY objects gpsd printed since the last TPV of the
/// previous time (in file order) up to the last TPV of this time.
fn dops_before_tpvs(chk: &str) -> HashMap<String, Vec<Dops>> {
    let mut out: HashMap<String, Vec<Dops>> = HashMap::new();
    let mut pending: Vec<Dops> = Vec::new();
    let mut last_time = String::new();
    for line in chk.lines().filter(|l| l.trim_start().starts_with('{')) {
        let Ok(v) = serde_json::from_str::<Value>(line.trim()) else {
            continue;
        };
        match v.get("class").and_then(Value::as_str) {
            Some("SKY") if v.get("hdop").is_some() || v.get("vdop").is_some() => {
                pending.push((get(&v, "hdop"), get(&v, "vdop")));
            }
            Some("TPV") => {
                let Some(t) = v.get("time").and_then(Value::as_str) else {
                    continue;
                };
                if t != last_time {
                    // A new epoch: the DOPs printed since the previous epoch's last TPV and
                    // the last DOPs of that epoch (still in force).
                    let carried = out.get(&last_time).and_then(|d| d.last().copied());
                    out.insert(t.to_owned(), carried.into_iter().collect());
                    last_time = t.to_owned();
                }
                out.entry(t.to_owned()).or_default().append(&mut pending);
            }
            _ => {}
        }
    }
    out
}

/// Resolution of an NMEA rendering of a quantity (half a unit of its last digit): latitude
/// and longitude to 1e-5 arc minutes, altitudes to 0.1 m (a height above the ellipsoid is a
/// sum of two such), speed to 0.001 kn, standard deviations to 0.1 m.
fn nmea_quantum(field: &str) -> f64 {
    match field {
        "lat" | "lon" => 0.5e-5 / 60.0,
        "altMSL" | "epv" => 0.05,
        "altHAE" => 0.1,
        "speed" => 0.0005 * 1852.0 / 3600.0,
        _ => 0.0,
    }
}

/// Where a TPV field of gpsd's may come from besides the receiver's message.
#[derive(Clone, Copy)]
enum Source {
    /// Only the receiver (lat, lon, altHAE, a climb from the receiver's velD): ours must be
    /// known and equal.
    Receiver,
    /// gpsd computes it when the receiver does not send it (altMSL from its geoid model, speed
    /// and track from successive positions, climb from successive heights): not compared when
    /// ours is unknown.
    Computed,
    /// gpsd's error model (eph, epv from DOP × UERE; eps): not compared when gpsd's value is
    /// recognised as the model's (`true`).
    Model(bool),
}

/// Compares one epoch: the differences; the fields gpsd derived go to `derived` (not
/// compared), as `field`, `nmea:field` or `ecef:field`.
fn compare(c: &Ctx, fix: &GnssFix, derived: &mut Vec<String>) -> Vec<Diff> {
    let gpsd = c.tpv;
    let mut diffs = Vec::new();
    let mode = gpsd.get("mode").and_then(Value::as_u64).unwrap_or(0);
    if mode != u64::from(fix.mode) {
        diffs.push(Diff {
            field: "mode",
            detail: format!("gpsd {mode} ours {}", fix.mode),
        });
    }
    let nmea_value = |field: &str, n: &GnssFix| match field {
        "lat" => n.lat_deg,
        "lon" => n.lon_deg,
        "altHAE" => n.height_m(),
        "altMSL" => n.alt_msl_m,
        "speed" => n.speed_mps,
        "epv" => n.std_alt_m,
        _ => f64::NAN,
    };
    // When the receiver sends both NAV-SOL and NAV-PVT, gpsd takes the climb from NAV-SOL's
    // ECEF velocity (cm/s, printed in the TPV) and the decoder NAV-PVT's velD (mm/s):
    // recognised by rotating gpsd's printed ECEF velocity, compared at the ECEF resolution.
    let climb_from_ecef = match (get(gpsd, "climb"), ecef_climb(gpsd)) {
        (Some(g), Some(e)) => {
            fix.sentences & UBX_MSG_NAV_PVT != 0
                && (g - e).abs() <= 0.0005 + 1e-9
                && (g + fix.vel_d_mps).abs() > CLIMB_TOL_MPS
                && (e + fix.vel_d_mps).abs() <= 0.005 * 3f64.sqrt()
        }
        _ => false,
    };
    if climb_from_ecef {
        derived.push("ecef:climb".to_owned());
    }
    // No MSL height from the receiver (NAV-SOL): both sides' geoid models (navsync EGM96 from
    // its coefficients, gpsd EGM2008 from a 5° grid), which agree to GEOID_MODELS_TOL_M.
    let geoid_model = fix.sentences & FIX_GEOID_MODEL != 0;
    if geoid_model && let Some(g) = get(gpsd, "altMSL") {
        if (g - fix.alt_msl_m).abs() <= GEOID_MODELS_TOL_M {
            derived.push("geoid:altMSL".into());
        } else {
            diffs.push(Diff {
                field: "altMSL",
                detail: format!("gpsd {g} ours {} (both geoid models)", fix.alt_msl_m),
            });
        }
    }
    // Compares `field` where gpsd has it (see [`Source`] for what gpsd may compute itself).
    let mut cmp = |field: &'static str, ours: f64, tol: f64, circular: bool, source: Source| {
        let Some(theirs) = get(gpsd, field) else { return };
        let dist = |a: f64, b: f64| {
            let d = (a - b).abs();
            if circular { d.min(360.0 - d) } else { d }
        };
        if dist(theirs, ours) <= tol {
            return;
        }
        match (source, ours.is_finite()) {
            (Source::Model(true), _) | (Source::Computed, false) => {
                derived.push(field.to_owned());
                return;
            }
            _ => {}
        }
        // gpsd takes the velocity of NAV-VELNED (cm/s) when it follows NAV-PVT in the epoch;
        // the decoder keeps NAV-PVT's (mm/s; docs/guide/receivers.md): equal to VELNED's
        // resolution (track: that resolution across the speed).
        let velned = fix.sentences & UBX_MSG_NAV_VELNED != 0 && fix.sentences & UBX_MSG_NAV_PVT != 0;
        let cm = 0.01 * 3f64.sqrt() + 1e-9;
        let velned_tol = match field {
            "speed" | "climb" | "eps" => cm,
            "track" => (cm / fix.speed_mps.max(cm)).to_degrees(),
            _ => -1.0,
        };
        if velned && dist(theirs, ours) <= velned_tol {
            derived.push(format!("velned:{field}"));
            return;
        }
        // gpsd merged the NMEA sentence of this epoch over the UBX value: its value is the
        // sentence's, which agrees with ours to the sentence's resolution.
        if let Some(n) = c.nmea.map(|n| nmea_value(field, n))
            && dist(theirs, n) <= tol
            && dist(ours, n) <= nmea_quantum(field) + tol
        {
            derived.push(format!("nmea:{field}"));
            return;
        }
        diffs.push(Diff {
            field,
            detail: format!("gpsd {theirs} ours {ours}"),
        });
    };
    cmp("lat", fix.lat_deg, LATLON_TOL_DEG, false, Source::Receiver);
    cmp("lon", fix.lon_deg, LATLON_TOL_DEG, false, Source::Receiver);
    cmp("altHAE", fix.height_m(), ALT_TOL_M, false, Source::Receiver);
    if !geoid_model {
        let msl = if fix.geoid_sep_m.is_finite() {
            fix.alt_msl_m
        } else {
            f64::NAN
        };
        cmp("altMSL", msl, ALT_TOL_M, false, Source::Computed);
    }
    cmp("speed", fix.speed_mps, SPEED_TOL_MPS, false, Source::Computed);
    cmp("track", fix.track_deg, TRACK_TOL_DEG, true, Source::Computed);
    // gpsd's climb is the receiver's only when it had a NED velocity (velD in the TPV), else
    // gpsd differences successive heights.
    if !climb_from_ecef {
        let (climb, source) = if gpsd.get("velD").is_some() {
            (-fix.vel_d_mps, Source::Receiver)
        } else {
            (f64::NAN, Source::Computed)
        };
        cmp("climb", climb, CLIMB_TOL_MPS, false, source);
    }
    let eph_model = dop_model(
        get(gpsd, "eph"),
        c.dops.iter().map(|d| d.0),
        [19.0, 4.75],
        fix.h_acc_m.is_nan(),
    );
    cmp("eph", fix.h_acc_m, ACC_TOL_M, false, Source::Model(eph_model));
    let epv_model = dop_model(
        get(gpsd, "epv"),
        c.dops.iter().map(|d| d.1),
        [23.0, 5.75],
        fix.v_acc_m.is_nan(),
    );
    cmp("epv", fix.v_acc_m, ACC_TOL_M, false, Source::Model(epv_model));
    // gpsd's error model replaces the receiver's sAcc: by its formula, or (where the previous
    // epoch's epx/epy are not known from its TPVs) as seen from an earlier TPV of this epoch
    // that still showed the receiver's value while this one has the model's inputs.
    let eps = get(gpsd, "eps");
    let model = gpsd_model_eps(gpsd, c.prev).or_else(|| first_epoch_model_eps(c, fix));
    let by_formula = matches!((model, eps), (Some(m), Some(e)) if (m - e).abs() <= EPS_TOL_MPS + 0.001);
    let shown_before = gpsd.get("epx").is_some()
        && c.earlier
            .iter()
            .any(|t| get(t, "eps").is_some_and(|e| (e - fix.s_acc_mps).abs() <= EPS_TOL_MPS));
    cmp(
        "eps",
        fix.s_acc_mps,
        EPS_TOL_MPS,
        false,
        Source::Model(by_formula || shown_before),
    );
    diffs
}

/// Our decode of one capture, fed one byte per read so that the satellites and time pulse
/// can be read after every fix.
struct Decoded {
    fixes: Vec<GnssFix>,
    /// The HNR-PVT fixes (`navsync/gnss/{id}/hnr`, an output of its own), then the NAV epochs
    /// (which win where both have a time).
    all: Vec<GnssFix>,
    /// The skies published (`GnssExtra::Sky`), the first per epoch time: (its time text, the
    /// sample).
    sats: Vec<(String, GnssSky)>,
    /// Every TIM-TP: (pulse UTC ns, the UTC of the NAV epoch that follows it: the first whose
    /// first byte arrived after the TIM-TP's).
    pulses: Vec<(i64, Option<i64>)>,
    decoder: AutoDecoder,
}

fn decode(log: &[u8]) -> Decoded {
    let mut d = AutoDecoder::new();
    let mut fixes = Vec::new();
    let mut hnr = Vec::new();
    let mut sats = Vec::new();
    let mut tp_host: Vec<(i64, i64)> = Vec::new();
    let mut sky_times = std::collections::HashSet::new();
    let mut pulses_seen = 0;
    let header = header_len(log);
    let mut on_sky = |s: &GnssSky| {
        // The UBX skies (an NMEA sky of the port's sentences, published while no UBX one is
        // about, is not what this test compares).
        if s.protocol != GNSS_PROTOCOL_NMEA && s.num_sats > 0 && s.utc_ns != i64::MIN && sky_times.insert(s.utc_ns) {
            sats.push((gpsd_time(s.utc_ns), *s));
        }
    };
    for (i, b) in log.iter().enumerate().skip(header) {
        let read_ns = (i as i64 + 1) * REPLAY_NS_PER_BYTE;
        let mut new = Vec::new();
        d.push_extras(
            core::slice::from_ref(b),
            read_ns,
            REPLAY_NS_PER_BYTE,
            &mut |f| new.push(*f),
            &mut |x| match x {
                GnssExtra::Hnr(h) => hnr.push(*h),
                GnssExtra::Sky(s) => on_sky(s),
                _ => {}
            },
        );
        fixes.extend(new);
        let c = d.ubx().counters().epochs.time_pulses;
        if c != pulses_seen {
            pulses_seen = c;
            if let Some(tp) = d.ubx().time_pulse() {
                tp_host.push((tp.pulse_utc_ns, tp.host_ns));
            }
        }
    }
    let mut new = Vec::new();
    d.flush(&mut |f| new.push(*f));
    fixes.extend(new);
    let nav = |f: &&GnssFix| f.protocol != GNSS_PROTOCOL_NMEA && f.sentences & UBX_MSG_HNR_PVT == 0;
    let pulses = tp_host
        .iter()
        .map(|&(pulse, host)| {
            let next = fixes
                .iter()
                .filter(nav)
                .filter(|f| f.stamp.host_ns > host)
                .min_by_key(|f| f.stamp.host_ns);
            (pulse, next.map(|f| f.utc_ns))
        })
        .collect();
    Decoded {
        all: hnr.iter().chain(&fixes).copied().collect(),
        fixes,
        sats,
        pulses,
        decoder: d,
    }
}

/// Length of gpsd's leading `#` comment lines.
fn header_len(log: &[u8]) -> usize {
    let mut at = 0;
    while log.get(at) == Some(&b'#') {
        at += log[at..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(log.len() - at, |i| i + 1);
    }
    at
}

fn dump(dec: &Decoded, chk: &str) {
    for f in &dec.fixes {
        println!(
            "ours {} {} hae={} sep={} vd={} hacc={} vacc={} sacc={} bits={:#06x} proto={} host={}",
            gpsd_time(f.utc_ns),
            epoch_json(f),
            f.height_m(),
            f.geoid_sep_m,
            f.vel_d_mps,
            f.h_acc_m,
            f.v_acc_m,
            f.s_acc_mps,
            f.sentences,
            f.protocol,
            f.stamp.host_ns
        );
    }
    println!("counters {:?}", dec.decoder.ubx().counters());
    for (t, v) in gpsd_epochs(chk) {
        println!("gpsd {t} {v}");
    }
}

#[derive(Default)]
struct Row {
    name: String,
    fixes: usize,
    nmea_fixes: usize,
    epochs: usize,
    matched: usize,
    shifted: usize,
    excepted: usize,
    unexplained: usize,
    derived: HashMap<String, usize>,
    sky: usize,
    sky_matched: usize,
    sky_excepted: usize,
    sky_unexplained: usize,
    sky_missing: usize,
    /// Satellites in our skies compared, and of them those gpsd lists (compared field by field).
    sky_sats: usize,
    sky_sats_compared: usize,
    pulses: usize,
    pulses_matched: usize,
    pulses_unexplained: usize,
    first_mismatch: String,
}

/// Looks a difference up in [`EXCEPTIONS`]; counts the hit.
fn excepted(name: &str, time: &str, field: &str, ctx: &Ctx, used: &mut [usize]) -> bool {
    let hit = EXCEPTIONS.iter().position(|e| {
        (e.captures.is_empty() || e.captures.contains(&name))
            && e.fields.contains(&field)
            && (e.times.is_empty() || e.times.contains(&time))
            && (e.applies)(ctx)
    });
    if let Some(i) = hit {
        used[i] += 1;
    }
    hit.is_some()
}

fn note(row: &mut Row, s: String) {
    if std::env::var_os("UBX_ALL").is_some() {
        println!("mismatch {} {s}", row.name);
    }
    if row.first_mismatch.is_empty() {
        row.first_mismatch = s;
    }
}

fn check_tpv(row: &mut Row, dec: &Decoded, nmea: &[GnssFix], chk: &str, used: &mut [usize]) {
    let name = row.name.clone();
    let by_time = |fixes: &'_ [GnssFix]| -> HashMap<String, GnssFix> {
        fixes
            .iter()
            .filter(|f| f.utc_ns != i64::MIN)
            .map(|f| (gpsd_time(f.utc_ns), *f))
            .collect()
    };
    let (ours, nmea) = (by_time(&dec.all), by_time(nmea));
    let mut all_tpvs: HashMap<String, Vec<Value>> = HashMap::new();
    for v in objects(chk, "TPV") {
        if let Some(t) = v.get("time").and_then(Value::as_str) {
            all_tpvs.entry(t.to_owned()).or_default().push(v.clone());
        }
    }
    let dops = dops_before_tpvs(chk);
    let shift_s = TIME_SHIFTS
        .iter()
        .find(|s| s.captures.contains(&name.as_str()))
        .map_or(0, |s| s.shift_s);
    let mut prev: Option<Value> = None;
    for (time, tpv) in gpsd_epochs(chk) {
        row.epochs += 1;
        let ours_time = match shift_s {
            0 => time.clone(),
            s => parse_gpsd_time(&time).map_or_else(|| time.clone(), |t| format_rfc3339_ms(t - s * NS_PER_S)),
        };
        let earlier = all_tpvs.get(&time).map_or(&[][..], |v| &v[..v.len().saturating_sub(1)]);
        let ctx = Ctx {
            tpv: &tpv,
            earlier,
            prev: prev.as_ref(),
            dops: dops.get(&time).map_or(&[][..], Vec::as_slice),
            fix: ours.get(&ours_time),
            nmea: nmea.get(&ours_time),
            fixes: &dec.all,
        };
        let mut derived = Vec::new();
        let diffs = match ctx.fix {
            Some(fix) => compare(&ctx, fix, &mut derived),
            None => vec![Diff {
                field: "time",
                detail: "no decoded epoch at this time".into(),
            }],
        };
        for d in derived {
            *row.derived.entry(d).or_default() += 1;
        }
        if diffs.is_empty() {
            row.matched += 1;
            row.shifted += usize::from(shift_s != 0);
        } else {
            let mut hits = vec![0usize; EXCEPTIONS.len()];
            let unexplained: Vec<&Diff> = diffs
                .iter()
                .filter(|d| !excepted(&name, &time, d.field, &ctx, &mut hits))
                .collect();
            if unexplained.is_empty() {
                row.excepted += 1;
                for (u, h) in used.iter_mut().zip(&hits) {
                    *u += usize::from(*h > 0);
                }
            } else {
                row.unexplained += 1;
                let mut s = format!("{time}:");
                for d in unexplained {
                    let _ = write!(s, " {} ({})", d.field, d.detail);
                }
                note(row, s);
            }
        }
        prev = Some(tpv);
    }
}

/// gpsd's first SKY with satellites per time.
fn gpsd_skies(chk: &str) -> HashMap<String, Value> {
    let mut m = HashMap::new();
    for v in objects(chk, "SKY") {
        let (Some(t), Some(_)) = (v.get("time").and_then(Value::as_str), v.get("satellites")) else {
            continue;
        };
        m.entry(t.to_owned()).or_insert(v);
    }
    m
}

fn check_sky(row: &mut Row, dec: &Decoded, chk: &str, used: &mut [usize]) {
    let name = row.name.clone();
    let skies = gpsd_skies(chk);
    let fix_at: HashMap<String, &GnssFix> = dec.fixes.iter().map(|f| (gpsd_time(f.utc_ns), f)).collect();
    for (time, view) in &dec.sats {
        let Some(sky) = skies.get(time) else {
            // gpsd printed no SKY at this time (its first epochs, before it knew the GPS week,
            // carry another date); counted in the table.
            row.sky_missing += 1;
            continue;
        };
        row.sky += 1;
        let fix = fix_at.get(time).copied();
        let mut diffs = Vec::new();
        let u_sat = sky.get("uSat").and_then(Value::as_u64).unwrap_or(0);
        row.sky_sats += view.num_sats as usize;
        if u_sat != view.used() as u64 {
            diffs.push(Diff {
                field: "sky_used",
                detail: format!("gpsd uSat {u_sat} ours {}", view.used()),
            });
        }
        for s in sky.get("satellites").and_then(Value::as_array).into_iter().flatten() {
            let id = |k: &str| s.get(k).and_then(Value::as_u64);
            let (Some(g), Some(sv)) = (id("gnssid"), id("svid")) else {
                continue;
            };
            let ours = view
                .satellites()
                .iter()
                .find(|o| u64::from(o.gnss_id) == g && u64::from(o.sv_id) == sv);
            let Some(o) = ours else {
                diffs.push(Diff {
                    field: "sky_sat",
                    detail: format!("gpsd lists {g}/{sv}, ours not"),
                });
                continue;
            };
            if let Some(el) = get(s, "el")
                && f64::from(o.elevation_deg) != el
            {
                diffs.push(Diff {
                    field: "sky_el",
                    detail: format!("{g}/{sv} gpsd {el} ours {}", o.elevation_deg),
                });
            }
            if let Some(az) = get(s, "az")
                && f64::from(o.azimuth_deg) != az
            {
                diffs.push(Diff {
                    field: "sky_az",
                    detail: format!("{g}/{sv} gpsd {az} ours {}", o.azimuth_deg),
                });
            }
            if let Some(ss) = get(s, "ss")
                && f64::from(o.cno_dbhz) != ss
            {
                diffs.push(Diff {
                    field: "sky_ss",
                    detail: format!("{g}/{sv} gpsd {ss} ours {}", o.cno_dbhz),
                });
            }
            if let Some(u) = s.get("used").and_then(Value::as_bool)
                && u != (o.used != 0)
            {
                diffs.push(Diff {
                    field: "sky_sat_used",
                    detail: format!("{g}/{sv} gpsd {u} ours {}", o.used),
                });
            }
            row.sky_sats_compared += 1;
        }
        if diffs.is_empty() {
            row.sky_matched += 1;
        } else if diffs.iter().all(|d| {
            let ctx = Ctx {
                tpv: sky,
                earlier: &[],
                prev: None,
                dops: &[],
                fix,
                nmea: None,
                fixes: &dec.all,
            };
            excepted(&name, time, d.field, &ctx, used)
        }) {
            row.sky_excepted += 1;
        } else {
            row.sky_unexplained += 1;
            let mut s = format!("SKY {time}:");
            for d in &diffs {
                let _ = write!(s, " {} ({})", d.field, d.detail);
            }
            note(row, s);
        }
    }
}

fn check_pps(row: &mut Row, dec: &Decoded, chk: &str) {
    let gpsd_times: Vec<i64> = gpsd_epochs(chk)
        .iter()
        .filter_map(|(t, _)| parse_gpsd_time(t))
        .collect();
    let last = gpsd_times.iter().copied().max().unwrap_or(i64::MIN);
    for &(pulse, next_epoch) in &dec.pulses {
        if pulse > last {
            // Announces a pulse after gpsd's last epoch (end of the capture).
            continue;
        }
        row.pulses += 1;
        // The pulse after the epoch that follows the TIM-TP: 1 s after its time rounded to
        // the second (Antaris receivers measure 1 ms before the second).
        let one_after = next_epoch.map(|e| (e + NS_PER_S / 2).div_euclid(NS_PER_S) * NS_PER_S + NS_PER_S);
        let on_gpsd_epoch = gpsd_times.iter().any(|t| (t - pulse).abs() <= 1_000_000);
        if one_after == Some(pulse) && on_gpsd_epoch {
            row.pulses_matched += 1;
        } else {
            row.pulses_unexplained += 1;
            note(
                row,
                format!(
                    "PPS {}: next epoch {:?}, gpsd epoch at the pulse {on_gpsd_epoch}",
                    format_rfc3339_ms(pulse),
                    next_epoch.map(format_rfc3339_ms)
                ),
            );
        }
    }
}

fn check_capture(name: &str, log: &[u8], chk: &str, used: &mut [usize]) -> Row {
    let dec = decode(log);
    // Reads of any size give the same fixes, stamps included.
    let whole = decode_capture(log, Protocol::Auto);
    assert_eq!(
        whole.fixes.len(),
        dec.fixes.len(),
        "{name}: byte-wise and capture decoding differ"
    );
    for (a, b) in whole.fixes.iter().zip(&dec.fixes) {
        assert_eq!(format!("{a:?}"), format!("{b:?}"), "{name}");
    }
    if std::env::var("UBX_DUMP").is_ok_and(|d| d == name) {
        dump(&dec, chk);
    }
    if std::env::var_os("UBX_COUNTERS").is_some() {
        let mut c = Vec::new();
        dec.decoder.each_counter(&mut |n, v| {
            if v != 0 {
                c.push(format!("{n}={v}"));
            }
        });
        println!("counters {name} {}", c.join(" "));
    }
    let mut row = Row {
        name: name.to_owned(),
        fixes: dec.fixes.len(),
        nmea_fixes: dec.fixes.iter().filter(|f| f.protocol == GNSS_PROTOCOL_NMEA).count(),
        ..Row::default()
    };
    let nmea = decode_capture(log, Protocol::Nmea).fixes;
    check_tpv(&mut row, &dec, &nmea, chk, used);
    check_sky(&mut row, &dec, chk, used);
    check_pps(&mut row, &dec, chk);
    row
}

#[test]
fn gpsd_ubx_conformance() {
    let dir = corpus_dir().unwrap_or_else(|e| panic!("{e}"));
    let mut used = vec![0usize; EXCEPTIONS.len()];
    let rows: Vec<Row> = gpsd_common::captures(&dir, EXPECTED_CAPTURES)
        .iter()
        .map(|c| check_capture(&c.name, &c.bytes, &c.chk, &mut used))
        .collect();

    let sum = |f: fn(&Row) -> usize| rows.iter().map(f).sum::<usize>();
    let (total, matched, shifted) = (sum(|r| r.epochs), sum(|r| r.matched), sum(|r| r.shifted));
    let (excepted, unexplained) = (sum(|r| r.excepted), sum(|r| r.unexplained));
    let (sky, sky_matched, sky_excepted, sky_unexplained) = (
        sum(|r| r.sky),
        sum(|r| r.sky_matched),
        sum(|r| r.sky_excepted),
        sum(|r| r.sky_unexplained),
    );
    let (pulses, pulses_matched, pulses_unexplained) = (
        sum(|r| r.pulses),
        sum(|r| r.pulses_matched),
        sum(|r| r.pulses_unexplained),
    );
    let sky_missing = sum(|r| r.sky_missing);
    let (sky_sats, sky_sats_compared) = (sum(|r| r.sky_sats), sum(|r| r.sky_sats_compared));
    println!(
        "{:<30} {:>5} {:>4} {:>5} {:>7} {:>6} {:>4} | {:>4} {:>5} {:>6} {:>4} {:>5} | {:>4} {:>5} {:>4} | fields gpsd derived; \
         first unexplained difference",
        "capture",
        "fixes",
        "nmea",
        "gpsd",
        "matched",
        "except",
        "diff",
        "sky",
        "match",
        "except",
        "diff",
        "nosky",
        "pps",
        "match",
        "diff"
    );
    let mut derived_total: HashMap<String, usize> = HashMap::new();
    for r in &rows {
        let mut derived: Vec<_> = r.derived.iter().collect();
        derived.sort();
        let derived: Vec<String> = derived.iter().map(|(k, v)| format!("{k}:{v}")).collect();
        for (k, v) in &r.derived {
            *derived_total.entry(k.clone()).or_default() += v;
        }
        println!(
            "{:<30} {:>5} {:>4} {:>5} {:>7} {:>6} {:>4} | {:>4} {:>5} {:>6} {:>4} {:>5} | {:>4} {:>5} {:>4} | {} {}",
            r.name,
            r.fixes,
            r.nmea_fixes,
            r.epochs,
            r.matched,
            r.excepted,
            r.unexplained,
            r.sky,
            r.sky_matched,
            r.sky_excepted,
            r.sky_unexplained,
            r.sky_missing,
            r.pulses,
            r.pulses_matched,
            r.pulses_unexplained,
            derived.join(","),
            r.first_mismatch
        );
    }
    let mut derived_total: Vec<_> = derived_total.into_iter().collect();
    derived_total.sort();
    println!(
        "TOTAL {} captures, {total} gpsd timed epochs: {matched} match ({:.2} %; {shifted} after a listed date \
         shift), {excepted} deliberate differences, {unexplained} unexplained. SKY: {sky} epochs, {sky_matched} \
         match, {sky_excepted} deliberate differences, {sky_unexplained} unexplained ({sky_missing} epochs with \
         satellites but no gpsd SKY at their time; {sky_sats} satellites, {sky_sats_compared} of them in gpsd's SKY: \
         elevation, azimuth, ss, used compared). PPS: {pulses} TIM-TP pulses, \
         {pulses_matched} match, {pulses_unexplained} unexplained. Fields gpsd derived (not compared): {derived_total:?}",
        rows.len(),
        100.0 * matched as f64 / total.max(1) as f64,
    );
    for (e, n) in EXCEPTIONS.iter().zip(&used) {
        let captures = if e.captures.is_empty() {
            "any capture".to_owned()
        } else {
            e.captures.join(", ")
        };
        println!("exception {} ({n} in {captures}): {}", e.name, e.reason);
    }
    for s in TIME_SHIFTS {
        println!("date shift {} s ({}): {}", s.shift_s, s.captures.join(", "), s.reason);
    }

    assert!(total > 0, "no timed gpsd epochs found in {}", dir.display());
    assert_eq!(
        unexplained + sky_unexplained + pulses_unexplained,
        0,
        "{unexplained} TPV epochs, {sky_unexplained} SKY epochs and {pulses_unexplained} pulses differ from gpsd \
         without a listed exception (see table)"
    );
    let unused: Vec<_> = EXCEPTIONS
        .iter()
        .zip(&used)
        .filter(|(_, n)| **n == 0)
        .map(|(e, _)| e.name)
        .collect();
    assert!(unused.is_empty(), "exceptions that no longer apply: {unused:?}");
    assert!(pulses > 0 && sky > 0, "no TIM-TP pulses or satellites compared");
    let ratio_all = matched as f64 / total as f64;
    assert!(
        ratio_all >= MIN_MATCH_RATIO,
        "only {matched}/{total} epochs match gpsd ({:.2} %)",
        100.0 * ratio_all
    );
}
