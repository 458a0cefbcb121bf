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
//! Every deliberate difference is a named [`EXCEPTIONS`] entry (a condition on gpsd's TPV
//! and our fix, limited to the captures and fields it names) with its reason, or a
//! [`TIME_SHIFTS`] entry for captures whose dates gpsd moved by whole GPS week rollovers.
//! The test fails on any difference that no exception explains, on an exception that no
//! longer applies, and when fewer than 99 % of all of gpsd's timed epochs match (an epoch of
//! a date-shifted capture matches when every field, the time after the listed shift, is
//! equal; the exceptions count as not matching). The table prints raw figures (matched / excepted / unexplained) for
//! every capture, so the share of deliberate differences is visible too.

use crate::gpsd_common;

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use navsync_drivers::gnss::Protocol;
use navsync_drivers::gnss::capture::{decode_capture, epoch_json};
use navsync_drivers::gnss::nmea::NmeaCounters;
use navsync_shared::samples::{GnssFix, SENTENCE_RMC, SENTENCE_VTG};
use navsync_shared::time::{Civil, NS_PER_S, format_rfc3339_ms, utc_ns_from_civil};
use serde_json::Value;

/// Tolerances.
const LATLON_TOL_DEG: f64 = 1e-7;
const ALT_TOL_M: f64 = 1e-3;
const SPEED_TOL_MPS: f64 = 1e-3;
const TRACK_TOL_DEG: f64 = 0.01;
/// Share of all of gpsd's timed epochs that must match.
const MIN_MATCH_RATIO: f64 = 0.99;
/// Captures expected in the corpus (a smaller number means it is incomplete).
const EXPECTED_CAPTURES: usize = 76;

/// A deliberate difference from gpsd.
struct Exception {
    /// Short name for the report.
    name: &'static str,
    /// Captures it applies to.
    captures: &'static [&'static str],
    /// gpsd TPV times it applies to; empty: wherever `applies` holds in those captures.
    times: &'static [&'static str],
    /// Compared fields it explains (`time`: no decoded epoch at gpsd's time).
    fields: &'static [&'static str],
    /// The condition (gpsd's TPV, our fix at that time) that identifies the difference.
    applies: fn(&Value, Option<&GnssFix>) -> bool,
    /// Why the decoder deliberately differs.
    reason: &'static str,
}

fn gpsd_mode(tpv: &Value) -> u64 {
    tpv.get("mode").and_then(Value::as_u64).unwrap_or(0)
}

/// A gpsd TPV that holds nothing but a time and a mode (no position, no velocity).
fn time_only(tpv: &Value) -> bool {
    tpv.as_object().is_some_and(|o| {
        o.keys()
            .all(|k| matches!(k.as_str(), "class" | "mode" | "time" | "ept" | "status"))
    })
}

const EXCEPTIONS: &[Exception] = &[
    Exception {
        name: "no-fix-under-stale-time",
        captures: &["gp-320fw-2019-04-07-coldboot.log", "quectel.log", "ublox-lea-4h.log"],
        times: &[],
        fields: &["mode"],
        applies: |tpv, fix| gpsd_mode(tpv) == 1 && time_only(tpv) && fix.is_some_and(|f| f.mode != 1),
        reason: "gpsd ignores the time of an RMC with status V and of sentences with an empty time \
                 field, so it reports the receiver's next (no-fix) state under the last time it had; \
                 the decoder gives those sentences an epoch of their own and keeps this epoch as it was",
    },
    Exception {
        name: "zda-time-report",
        captures: &["ac12.log"],
        times: &["2007-12-23T19:32:28.000Z"],
        fields: &["time"],
        applies: |tpv, fix| gpsd_mode(tpv) == 0 && time_only(tpv) && fix.is_none(),
        reason: "this receiver's ZDA runs 2 s ahead of its fixes; gpsd reports the capture's trailing \
                 ZDA as a time-only TPV, the decoder takes ZDA as date information for the epoch in \
                 progress (a ZDA starts an epoch only when no fix sentence tags one)",
    },
    Exception {
        name: "zda-date-after-cold-boot",
        captures: &["gp-320fw-2019-04-07-coldboot.log"],
        times: &["2019-04-07T00:04:27.000Z"],
        fields: &["time"],
        applies: |_, fix| fix.is_none(),
        reason: "after its cold boot the receiver's ZDA in this epoch says 1999-08-22 (GPS week \
                 rollover); gpsd reported the epoch before that ZDA arrived, with the date carried \
                 from before the reboot, the decoder uses the epoch's own ZDA (1999-08-22T00:04:27)",
    },
    Exception {
        name: "gpsd-pmgnst-field-bug",
        captures: &["eXplorist210.log"],
        times: &["2006-05-20T20:06:20.300Z", "2006-05-20T20:06:22.310Z"],
        fields: &["mode"],
        applies: |tpv, fix| gpsd_mode(tpv) == 1 && fix.is_some_and(|f| f.mode == 3),
        reason: "gpsd reads Magellan's $PMGNST one field off (the mode from the 'T' flag, the flag \
                 from the battery level) and sets no fix after a valid 3D epoch (GGA 5 satellites, \
                 GSA mode 3); the decoder does not decode $PMGNST",
    },
    Exception {
        name: "one-epoch-two-tag-resolutions",
        captures: &["eXplorist210.log"],
        times: &["2006-05-20T20:06:20.300Z"],
        fields: &["time"],
        applies: |_, fix| fix.is_none(),
        reason: "this receiver stamps GLL to the millisecond (200620.303) and then GGA/RMC of the same \
                 epoch to the centisecond (200620.30): gpsd reports two TPVs, the second 3 ms before the \
                 first; the decoder keeps them one epoch (20.303) so that its times never step back",
    },
    Exception {
        name: "gpsd-perc-average-position",
        captures: &["ericsson-gru04-02-70sec.log"],
        times: &["2026-02-12T21:37:13.000Z", "2026-02-12T21:38:13.000Z"],
        fields: &["lat", "lon"],
        applies: |tpv, fix| tpv.get("status").and_then(Value::as_u64) == Some(7) && fix.is_some(),
        reason: "once a minute this timing receiver sends $PERC,GPavp, its averaged (survey) \
                 position; gpsd replaces the epoch's position by it, the decoder keeps the epoch's \
                 own GNS/GLL position (7 m away)",
    },
];

/// Captures whose gpsd dates are later than the receiver's by whole GPS week rollovers: the
/// decoder's epoch for gpsd time `t` is looked up at `t − shift_s`; all fields are compared.
struct TimeShift {
    captures: &'static [&'static str],
    shift_s: i64,
    reason: &'static str,
}

/// 1024 GPS weeks, s.
const GPS_ROLLOVER_S: i64 = 1024 * 7 * 86_400;

const TIME_SHIFTS: &[TimeShift] = &[TimeShift {
    captures: &["rst39.log", "tcp-torture.log"],
    shift_s: GPS_ROLLOVER_S,
    reason: "gpsd's week-rollover heuristic (a date before 2017 while it believes 18 leap seconds \
             are in force) moved these correct 2014 and 2007 dates (RMC and ZDA agree) forward by \
             1024 weeks; the decoder reports the receiver's date",
}];

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

fn corpus_dir() -> PathBuf {
    // `$NAVSYNC_CORPUS_DIR` overrides the location beside the checkout.
    std::env::var_os("NAVSYNC_CORPUS_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/corpora/gpsd-nmea"))
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
        let Ok(v) = serde_json::from_str::<Value>(line) else {
            continue;
        };
        if v.get("class").and_then(Value::as_str) != Some("TPV") {
            continue;
        }
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

/// Compares one epoch; returns the differences and whether a gpsd-derived speed/track was
/// skipped.
fn compare(gpsd: &Value, fix: &GnssFix) -> (Vec<Diff>, bool) {
    let mut diffs = Vec::new();
    let mut derived = false;
    let g = |k: &str| gpsd.get(k).and_then(Value::as_f64);
    let mode = gpsd.get("mode").and_then(Value::as_u64).unwrap_or(0);
    if mode != u64::from(fix.mode) {
        diffs.push(Diff {
            field: "mode",
            detail: format!("gpsd {mode} ours {}", fix.mode),
        });
    }
    let mut num = |field: &'static str, key: &str, ours: f64, tol: f64, circular: bool| {
        let Some(theirs) = g(key) else { return };
        let mut d = (theirs - ours).abs();
        if circular {
            d = d.min(360.0 - d);
        }
        if d.is_nan() || d > tol {
            diffs.push(Diff {
                field,
                detail: format!("gpsd {theirs} ours {ours}"),
            });
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

/// Diagnostics (`cargo test -p navsync-drivers --test conformance gpsd_conformance --
/// --nocapture` with): `NMEA_ALL=1` prints every unexplained mismatch, `NMEA_COUNTERS=1` the
/// decoder's counters per capture,
/// `NMEA_DUMP=NAME.log` the decoder's epochs, its counters and gpsd's epochs for one capture.
fn dump(fixes: &[GnssFix], counters: &NmeaCounters, chk: &str) {
    for f in fixes {
        println!(
            "ours {} tod={} bits={:#04x} host={}",
            epoch_json(f),
            f.tod_ns,
            f.sentences,
            f.stamp.host_ns
        );
    }
    println!("counters {counters:?}");
    for (t, v) in gpsd_epochs(chk) {
        println!("gpsd {t} {v}");
    }
}

#[derive(Default)]
struct Row {
    name: String,
    epochs: usize,
    matched: usize,
    shifted: usize,
    excepted: usize,
    unexplained: usize,
    derived: usize,
    fixes: usize,
    first_mismatch: String,
}

fn check_capture(name: &str, log: &[u8], chk: &str, used: &mut [usize]) -> Row {
    let decoded = decode_capture(log, Protocol::Nmea);
    let (fixes, counters) = (decoded.fixes.clone(), decoded.nmea().expect("NMEA").counters());
    if std::env::var("NMEA_DUMP").is_ok_and(|d| d == name) {
        dump(&fixes, &counters, chk);
    }
    if std::env::var_os("NMEA_COUNTERS").is_some() {
        println!("counters {name} {counters:?}");
    }
    // The last fix per time (the decoder emits an epoch again if late data complete it).
    let mut by_time: HashMap<String, &GnssFix> = HashMap::new();
    for f in &fixes {
        if f.utc_ns != i64::MIN {
            by_time.insert(format_rfc3339_ms(f.utc_ns), f);
        }
    }
    let shift_s = TIME_SHIFTS
        .iter()
        .find(|s| s.captures.contains(&name))
        .map_or(0, |s| s.shift_s);
    let mut row = Row {
        name: name.to_owned(),
        fixes: fixes.len(),
        ..Row::default()
    };
    for (time, tpv) in gpsd_epochs(chk) {
        row.epochs += 1;
        let ours_time = match shift_s {
            0 => time.clone(),
            s => parse_gpsd_time(&time).map_or_else(|| time.clone(), |t| format_rfc3339_ms(t - s * NS_PER_S)),
        };
        let fix = by_time.get(&ours_time).copied();
        let diffs = match fix {
            Some(fix) => {
                let (diffs, derived) = compare(&tpv, fix);
                row.derived += usize::from(derived);
                diffs
            }
            None => vec![Diff {
                field: "time",
                detail: "no decoded epoch at this time".into(),
            }],
        };
        if diffs.is_empty() {
            row.matched += 1;
            row.shifted += usize::from(shift_s != 0);
            continue;
        }
        let mut unexplained = Vec::new();
        let mut hits = Vec::new();
        for d in &diffs {
            let hit = EXCEPTIONS.iter().position(|e| {
                e.captures.contains(&name)
                    && e.fields.contains(&d.field)
                    && (e.times.is_empty() || e.times.contains(&time.as_str()))
                    && (e.applies)(&tpv, fix)
            });
            match hit {
                Some(i) => hits.push(i),
                None => unexplained.push(d),
            }
        }
        if unexplained.is_empty() {
            row.excepted += 1;
            hits.dedup();
            for i in hits {
                used[i] += 1;
            }
            continue;
        }
        row.unexplained += 1;
        let mut s = format!("{time}:");
        for d in unexplained {
            let _ = write!(s, " {} ({})", d.field, d.detail);
        }
        if std::env::var_os("NMEA_ALL").is_some() {
            println!("mismatch {name} {s}");
        }
        if row.first_mismatch.is_empty() {
            row.first_mismatch = s;
        }
    }
    row
}

#[test]
fn gpsd_conformance() {
    let dir = corpus_dir();
    let mut used = vec![0usize; EXCEPTIONS.len()];
    let rows: Vec<Row> = gpsd_common::captures(&dir, EXPECTED_CAPTURES)
        .iter()
        .map(|c| check_capture(&c.name, &c.bytes, &c.chk, &mut used))
        .collect();

    let sum = |f: fn(&Row) -> usize| rows.iter().map(f).sum::<usize>();
    let (total, matched, shifted) = (sum(|r| r.epochs), sum(|r| r.matched), sum(|r| r.shifted));
    let (excepted, unexplained, derived) = (sum(|r| r.excepted), sum(|r| r.unexplained), sum(|r| r.derived));
    println!(
        "{:<34} {:>5} {:>5} {:>7} {:>6} {:>5} {:>5}  first unexplained mismatch",
        "capture", "fixes", "gpsd", "matched", "except", "diff", "deriv"
    );
    for r in &rows {
        println!(
            "{:<34} {:>5} {:>5} {:>7} {:>6} {:>5} {:>5}  {}",
            r.name, r.fixes, r.epochs, r.matched, r.excepted, r.unexplained, r.derived, r.first_mismatch
        );
    }
    let comparable = total - excepted;
    let ratio = matched as f64 / comparable.max(1) as f64;
    println!(
        "TOTAL {} captures, {total} gpsd timed epochs: {matched} match ({:.2} % of all; {shifted} of them \
         after a listed date shift), {excepted} deliberate differences, {unexplained} unexplained; \
         {matched}/{comparable} = {:.2} % of the epochs that are not deliberate differences; \
         {derived} epochs with a gpsd-derived speed/track not compared",
        rows.len(),
        100.0 * matched as f64 / total.max(1) as f64,
        100.0 * ratio
    );
    for (e, n) in EXCEPTIONS.iter().zip(&used) {
        println!(
            "exception {} ({n} epochs in {}): {}",
            e.name,
            e.captures.join(", "),
            e.reason
        );
    }
    for s in TIME_SHIFTS {
        println!("date shift {} s ({}): {}", s.shift_s, s.captures.join(", "), s.reason);
    }

    assert!(total > 0, "no timed gpsd epochs found in {}", dir.display());
    assert_eq!(
        unexplained, 0,
        "{unexplained} epochs differ from gpsd without a listed exception (see table)"
    );
    let unused: Vec<_> = EXCEPTIONS
        .iter()
        .zip(&used)
        .filter(|(_, n)| **n == 0)
        .map(|(e, _)| e.name)
        .collect();
    assert!(unused.is_empty(), "exceptions that no longer apply: {unused:?}");
    let ratio_all = matched as f64 / total as f64;
    assert!(
        ratio_all >= MIN_MATCH_RATIO,
        "only {matched}/{total} epochs match gpsd ({:.2} %)",
        100.0 * ratio_all
    );
}
