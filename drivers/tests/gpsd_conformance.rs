//! Conformance of the NMEA front end (framer + epoch assembler) with gpsd, on gpsd's own
//! regression captures (`shared/corpora/gpsd-nmea`, outside the repository).
//!
//! For every capture `NAME.log`, gpsd's output `NAME.log.chk` holds TPV reports; gpsd
//! refines a TPV as more sentences of one epoch arrive, so for every distinct TPV `time` the
//! LAST TPV carrying it is gpsd's view of that epoch. The decoder's fix with the same time
//! (the last one, should it emit several) is compared with it:
//!
//! - `time`: exact (to gpsd's millisecond);
//! - `mode`: equal;
//! - `lat`/`lon`: within 1e-7°; `altMSL`: within 1 mm; `speed`: within 1 mm/s; `track`:
//!   within 0.01°.
//!
//! A field is compared only where gpsd reports it (gpsd omits what it does not know, and
//! hides lat/lon below a 2D fix and altitude below 3D). Fields we report and gpsd does not
//! are not compared. Where gpsd reports a speed or track although the epoch contained no
//! sentence carrying one (no RMC, VTG), gpsd computed it from successive positions; the
//! decoder reports only what the receiver sent, so those are not compared either (counted
//! as "derived" in the table).
//!
//! Every deliberate difference is a named [`EXCEPTIONS`] entry with its reason; any other
//! difference fails the test, and at least 99 % of gpsd's timed epochs (summed over all
//! captures) must match outright (excepted epochs do not count as matched).

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use navsync_drivers::gps::offline::decode_capture;
use navsync_shared::samples::{GnssFix, SENTENCE_RMC, SENTENCE_VTG};
use navsync_shared::time::format_rfc3339_ms;
use serde_json::Value;

/// Tolerances.
const LATLON_TOL_DEG: f64 = 1e-7;
const ALT_TOL_M: f64 = 1e-3;
const SPEED_TOL_MPS: f64 = 1e-3;
const TRACK_TOL_DEG: f64 = 0.01;
/// Share of gpsd's timed epochs that must match.
const MIN_MATCH_RATIO: f64 = 0.99;
/// Captures expected in the corpus (a smaller number means it is incomplete).
const EXPECTED_CAPTURES: usize = 76;

/// A deliberate difference from gpsd: in `capture`, at gpsd TPV `time` (`None`: every
/// epoch of the capture), the compared `field` differs for `reason`.
struct Exception {
    capture: &'static str,
    time: Option<&'static str>,
    field: &'static str,
    reason: &'static str,
}

const EXCEPTIONS: &[Exception] = &[];

fn corpus_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/corpora/gpsd-nmea")
}

/// gpsd's last TPV per distinct `time`, in order of first appearance.
fn gpsd_epochs(chk: &str) -> Vec<(String, Value)> {
    let mut order: Vec<String> = Vec::new();
    let mut last: HashMap<String, Value> = HashMap::new();
    for line in chk.lines() {
        let line = line.trim();
        if !line.starts_with('{') {
            continue;
        }
        let Ok(v) = serde_json::from_str::<Value>(line) else { continue };
        if v.get("class").and_then(Value::as_str) != Some("TPV") {
            continue;
        }
        let Some(time) = v.get("time").and_then(Value::as_str).map(str::to_owned) else { continue };
        if !last.contains_key(&time) {
            order.push(time.clone());
        }
        last.insert(time, v);
    }
    order.into_iter().filter_map(|t| last.remove(&t).map(|v| (t, v))).collect()
}

/// One field difference.
struct Diff {
    field: &'static str,
    detail: String,
}

/// Compares one epoch; returns the differences and whether a gpsd-derived speed/track was
/// skipped.
fn compare(gpsd: &Value, fix: &GnssFix) -> (Vec<Diff>, bool) {
    let mut diffs = Vec::new();
    let mut derived = false;
    let g = |k: &str| gpsd.get(k).and_then(Value::as_f64);
    let mode = gpsd.get("mode").and_then(Value::as_u64).unwrap_or(0);
    if mode != u64::from(fix.mode) {
        diffs.push(Diff { field: "mode", detail: format!("gpsd {mode} ours {}", fix.mode) });
    }
    let mut num = |field: &'static str, key: &str, ours: f64, tol: f64, circular: bool| {
        let Some(theirs) = g(key) else { return };
        let mut d = (theirs - ours).abs();
        if circular {
            d = d.min(360.0 - d);
        }
        if !(d <= tol) {
            diffs.push(Diff { field, detail: format!("gpsd {theirs} ours {ours}") });
        }
    };
    num("lat", "lat", fix.lat_deg, LATLON_TOL_DEG, false);
    num("lon", "lon", fix.lon_deg, LATLON_TOL_DEG, false);
    num("altMSL", "altMSL", fix.alt_msl_m, ALT_TOL_M, false);
    let sent_velocity = fix.sentences & (SENTENCE_RMC | SENTENCE_VTG) != 0;
    if sent_velocity || (fix.speed_mps.is_finite() || fix.track_deg.is_finite()) {
        num("speed", "speed", fix.speed_mps, SPEED_TOL_MPS, false);
        num("track", "track", fix.track_deg, TRACK_TOL_DEG, true);
    } else if g("speed").is_some() || g("track").is_some() {
        derived = true;
    }
    (diffs, derived)
}

#[derive(Default)]
struct Row {
    name: String,
    epochs: usize,
    matched: usize,
    excepted: usize,
    mismatched: usize,
    derived: usize,
    fixes: usize,
    first_mismatch: String,
}

fn check_capture(name: &str, log: &[u8], chk: &str, used: &mut [bool]) -> Row {
    let (fixes, _counters) = decode_capture(log);
    let mut by_time: HashMap<String, &GnssFix> = HashMap::new();
    for f in &fixes {
        if f.utc_ns != i64::MIN {
            by_time.insert(format_rfc3339_ms(f.utc_ns), f);
        }
    }
    let mut row = Row { name: name.to_owned(), fixes: fixes.len(), ..Row::default() };
    for (time, tpv) in gpsd_epochs(chk) {
        row.epochs += 1;
        let diffs = match by_time.get(&time) {
            Some(fix) => {
                let (diffs, derived) = compare(&tpv, fix);
                row.derived += usize::from(derived);
                diffs
            }
            None => vec![Diff { field: "time", detail: "no decoded epoch at this time".into() }],
        };
        if diffs.is_empty() {
            row.matched += 1;
            continue;
        }
        let unexplained: Vec<&Diff> = diffs
            .iter()
            .filter(|d| {
                let hit = EXCEPTIONS.iter().position(|e| {
                    e.capture == name && e.field == d.field && e.time.is_none_or(|t| t == time)
                });
                if let Some(i) = hit {
                    used[i] = true;
                }
                hit.is_none()
            })
            .collect();
        if unexplained.is_empty() {
            row.excepted += 1;
        } else {
            row.mismatched += 1;
            if row.first_mismatch.is_empty() {
                let mut s = format!("{time}:");
                for d in unexplained {
                    let _ = write!(s, " {} ({})", d.field, d.detail);
                }
                row.first_mismatch = s;
            }
        }
    }
    row
}

#[test]
fn gpsd_conformance() {
    let dir = corpus_dir();
    let entries = std::fs::read_dir(&dir).unwrap_or_else(|e| {
        panic!("gpsd NMEA corpus not found at {} ({e}); it lives outside the repository", dir.display())
    });
    let mut logs: Vec<PathBuf> =
        entries.filter_map(Result::ok).map(|e| e.path()).filter(|p| p.extension().is_some_and(|x| x == "log")).collect();
    logs.sort();
    assert!(
        logs.len() >= EXPECTED_CAPTURES,
        "expected {EXPECTED_CAPTURES} captures in {}, found {}",
        dir.display(),
        logs.len()
    );

    let mut used = vec![false; EXCEPTIONS.len()];
    let mut rows = Vec::new();
    for log in &logs {
        let name = log.file_name().and_then(|n| n.to_str()).unwrap_or("?").to_owned();
        let bytes = std::fs::read(log).unwrap_or_else(|e| panic!("reading {}: {e}", log.display()));
        let chk_path = log.with_extension("log.chk");
        let chk = std::fs::read(&chk_path).unwrap_or_else(|e| panic!("reading {}: {e}", chk_path.display()));
        rows.push(check_capture(&name, &bytes, &String::from_utf8_lossy(&chk), &mut used));
    }

    let (mut total, mut matched, mut excepted, mut mismatched, mut derived) = (0, 0, 0, 0, 0);
    println!(
        "{:<36} {:>6} {:>6} {:>7} {:>6} {:>6} {:>6}  first mismatch",
        "capture", "fixes", "gpsd", "matched", "except", "diff", "deriv"
    );
    for r in &rows {
        println!(
            "{:<36} {:>6} {:>6} {:>7} {:>6} {:>6} {:>6}  {}",
            r.name, r.fixes, r.epochs, r.matched, r.excepted, r.mismatched, r.derived, r.first_mismatch
        );
        total += r.epochs;
        matched += r.matched;
        excepted += r.excepted;
        mismatched += r.mismatched;
        derived += r.derived;
    }
    println!(
        "TOTAL {} captures: {matched}/{total} gpsd timed epochs matched ({:.2} %), {excepted} excepted, \
         {mismatched} unexplained, {derived} with gpsd-derived speed/track not compared",
        rows.len(),
        100.0 * matched as f64 / total.max(1) as f64
    );
    for (e, u) in EXCEPTIONS.iter().zip(&used) {
        println!("exception {} {} {}: {}{}", e.capture, e.time.unwrap_or("*"), e.field, e.reason, if *u { "" } else { " (UNUSED)" });
    }

    assert!(total > 0, "no timed gpsd epochs found in {}", dir.display());
    assert_eq!(mismatched, 0, "{mismatched} epochs differ from gpsd without a listed exception (see table)");
    let unused: Vec<_> = EXCEPTIONS.iter().zip(&used).filter(|(_, u)| !**u).map(|(e, _)| e.capture).collect();
    assert!(unused.is_empty(), "exceptions that no longer apply: {unused:?}");
    let ratio = matched as f64 / total as f64;
    assert!(ratio >= MIN_MATCH_RATIO, "only {matched}/{total} epochs match gpsd ({:.2} %)", 100.0 * ratio);
}
