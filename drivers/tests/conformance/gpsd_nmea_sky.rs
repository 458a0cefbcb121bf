//! The NMEA sky (GSV with GSA → `GnssSky`, `navsync_drivers::gnss::nmea::sky`) against gpsd's
//! SKY objects over gpsd's NMEA corpus.
//!
//! gpsd's NMEA SKY objects carry no time of their own, so the skies are compared in order:
//! gpsd prints a SKY with satellites when it has read a cycle's GSV groups, and the decoder
//! publishes one `GnssSky` per cycle. For every capture with GSV where both count the same
//! skies, each of gpsd's satellites (matched by `gnssid`/`svid`) is compared with ours:
//! elevation and azimuth (whole degrees, where gpsd gives them), `ss` (C/N0, dB-Hz; gpsd's 0
//! is our 0, not tracking; a satellite gpsd lists once per signal is compared by its best) and
//! `used` (from GSA). Captures where the counts differ (gpsd prints partial skies while it
//! learns which talker ends a receiver's GSV cycle, or merges cycles) are listed, not compared.
//! At most 3 % of the satellites compared may differ (the in-order pairing can be a cycle off).

use crate::gpsd_common;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use navsync_drivers::gnss::capture::{REPLAY_NS_PER_BYTE, gpsd_header};
use navsync_drivers::gnss::nmea::NmeaDecoder;
use navsync_drivers::gnss::{GnssDecoder, GnssExtra};
use navsync_shared::samples::GnssSky;
use serde_json::Value;

fn corpus_dir() -> PathBuf {
    std::env::var_os("NAVSYNC_CORPUS_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/corpora/gpsd-nmea"))
}

/// Our skies of a capture, in order.
fn skies(bytes: &[u8]) -> Vec<GnssSky> {
    let (header, _) = gpsd_header(bytes);
    let mut d = NmeaDecoder::new();
    let mut out = Vec::new();
    d.push_extras(
        bytes.get(header..).unwrap_or(&[]),
        bytes.len() as i64 * REPLAY_NS_PER_BYTE,
        REPLAY_NS_PER_BYTE,
        &mut |_| {},
        &mut |x| {
            if let GnssExtra::Sky(s) = x {
                out.push(*s);
            }
        },
    );
    d.flush_sky(&mut |x| {
        if let GnssExtra::Sky(s) = x {
            out.push(*s);
        }
    });
    out
}

/// gpsd's SKY objects with satellites, in order.
fn gpsd_skies(chk: &str) -> Vec<Value> {
    chk.lines()
        .filter(|l| l.contains("\"class\":\"SKY\"") && l.contains("\"satellites\""))
        .filter_map(|l| serde_json::from_str(l.trim()).ok())
        .collect()
}

#[derive(Default)]
struct Tally {
    skies: usize,
    sats: usize,
    differ: Vec<String>,
}

fn compare(ours: &GnssSky, gpsd: &Value, t: &mut Tally, at: &str) {
    t.skies += 1;
    for s in gpsd["satellites"].as_array().into_iter().flatten() {
        let (Some(g), Some(sv)) = (s["gnssid"].as_u64(), s["svid"].as_u64()) else {
            continue;
        };
        t.sats += 1;
        let Some(o) = ours
            .satellites()
            .iter()
            .find(|o| u64::from(o.gnss_id) == g && u64::from(o.sv_id) == sv)
        else {
            t.differ.push(format!("{at}: gpsd lists {g}/{sv}, ours not"));
            continue;
        };
        let mut d = String::new();
        if let Some(el) = s["el"].as_f64()
            && f64::from(o.elevation_deg) != el
        {
            let _ = write!(d, " el gpsd {el} ours {}", o.elevation_deg);
        }
        if let Some(az) = s["az"].as_f64()
            && f64::from(o.azimuth_deg) != az
        {
            let _ = write!(d, " az gpsd {az} ours {}", o.azimuth_deg);
        }
        // A satellite gpsd lists once per signal is one entry of ours, with its best C/N0.
        let ss = gpsd["satellites"]
            .as_array()
            .into_iter()
            .flatten()
            .filter(|x| x["gnssid"].as_u64() == Some(g) && x["svid"].as_u64() == Some(sv))
            .filter_map(|x| x["ss"].as_f64())
            .reduce(f64::max);
        if let Some(ss) = ss
            && f64::from(o.cno_dbhz) != ss
        {
            let _ = write!(d, " ss gpsd {ss} ours {}", o.cno_dbhz);
        }
        if let Some(u) = s["used"].as_bool()
            && u != (o.used != 0)
        {
            let _ = write!(d, " used gpsd {u} ours {}", o.used);
        }
        if !d.is_empty() {
            t.differ.push(format!("{at} {g}/{sv}:{d}"));
        }
    }
}

#[test]
fn nmea_skies_match_gpsd() {
    let mut total = Tally::default();
    let (mut compared, mut uncounted) = (Vec::new(), Vec::new());
    for c in gpsd_common::captures(&corpus_dir(), 76) {
        let ours = skies(&c.bytes);
        let theirs = gpsd_skies(&c.chk);
        if ours.is_empty() && theirs.is_empty() {
            continue;
        }
        if ours.len() != theirs.len() {
            uncounted.push(format!("{} (ours {}, gpsd {})", c.name, ours.len(), theirs.len()));
            continue;
        }
        let mut t = Tally::default();
        for (i, (o, g)) in ours.iter().zip(&theirs).enumerate() {
            compare(o, g, &mut t, &format!("{} sky {i}", c.name));
        }
        println!(
            "{:<34} {:>4} skies {:>5} satellites {:>4} differ",
            c.name,
            t.skies,
            t.sats,
            t.differ.len()
        );
        for d in t.differ.iter().take(3) {
            println!("    {d}");
        }
        compared.push(c.name.clone());
        total.skies += t.skies;
        total.sats += t.sats;
        total.differ.extend(t.differ);
    }
    println!(
        "TOTAL {} captures compared: {} skies, {} satellites of gpsd's, {} differ; {} captures with another \
         number of skies: {}",
        compared.len(),
        total.skies,
        total.sats,
        total.differ.len(),
        uncounted.len(),
        uncounted.join(", ")
    );
    // Measured when written: 37 captures, 300 skies, 3320 satellites, 71 differ, all in two
    // captures (isync, ublox-f9p-hpnmea) where the values differ by one unit, a cycle apart:
    // the in-order pairing is one cycle off there (gpsd printed a partial sky first).
    assert!(total.skies >= 290 && total.sats >= 3000, "too few skies compared");
    assert!(
        total.differ.len() * 100 <= total.sats * 3,
        "{} of {} satellites differ from gpsd's SKY",
        total.differ.len(),
        total.sats
    );
}
