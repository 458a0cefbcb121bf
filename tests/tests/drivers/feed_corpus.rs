//! Real receiver captures from the gpsd corpus (`navsync_tests::corpus_dir()`, or
//! `$NAVSYNC_CORPUS_DIR`) played by `navsync feed` into pseudo-terminals and read by live
//! `navsync gps` (the alias of `navsync gnss`) processes: what arrives on `navsync/gnss/{id}/fix` must be, field by field,
//! what the offline decoder (`gnss::capture::decode_capture`) makes of the same file, and the
//! driver's error counters must equal the offline ones. Most captures are played as fast as
//! the driver reads (`--speed max`), two at 5× their own pace (epoch by epoch, with idle line
//! time in between, as from the receiver).

use std::path::PathBuf;
use std::time::{Duration, Instant};

use navsync_drivers::gnss::Protocol;
use navsync_drivers::gnss::capture::decode_capture;
use navsync_shared::ipc::Subscriber;
use navsync_shared::samples::*;
use navsync_shared::services;
use navsync_tests::TestEnv;

/// Captures with a range of receivers, talkers, rates, and broken input.
const MAX_SPEED: [&str; 9] = [
    "bu353s4.log",
    "gps-360.log",
    "nmea-fuzzy-cases.log",
    "tcp-torture.log",
    "garmin48.log",
    "skytraq-fixB.log",
    "quectel-eg25-g-2.log",
    "ac12.log",
    "eXplorist210.log",
];
const PACED: [&str; 2] = ["ublox-lea-5q.log", "garmin15x.log"];
const PACED_SPEED: f64 = 5.0;

fn corpus() -> PathBuf {
    let dir = std::env::var_os("NAVSYNC_CORPUS_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(navsync_tests::corpus_dir);
    assert!(
        dir.join("ac12.log").exists(),
        "the gpsd NMEA corpus is not at {} (put shared/corpora/gpsd-nmea beside the checkout or set NAVSYNC_CORPUS_DIR)",
        dir.display()
    );
    dir
}

fn same(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

/// Field-by-field equality of two fixes, everything but the receipt time and sequence number.
fn diff(live: &GnssFix, off: &GnssFix) -> Vec<String> {
    let mut d = Vec::new();
    let ints = [
        ("utc_ns", live.utc_ns, off.utc_ns),
        ("gps_ns", live.gps_ns, off.gps_ns),
        ("tod_ns", live.tod_ns, off.tod_ns),
        ("sentences", i64::from(live.sentences), i64::from(off.sentences)),
        ("sats_used", i64::from(live.sats_used), i64::from(off.sats_used)),
        ("mode", i64::from(live.mode), i64::from(off.mode)),
        ("quality", i64::from(live.quality), i64::from(off.quality)),
        (
            "stamp.source",
            i64::from(live.stamp.source),
            i64::from(off.stamp.source),
        ),
    ];
    for (n, a, b) in ints {
        if a != b {
            d.push(format!("{n}: live {a} offline {b}"));
        }
    }
    let floats = [
        ("lat_deg", live.lat_deg, off.lat_deg),
        ("lon_deg", live.lon_deg, off.lon_deg),
        ("alt_msl_m", live.alt_msl_m, off.alt_msl_m),
        ("geoid_sep_m", live.geoid_sep_m, off.geoid_sep_m),
        ("vel_n_mps", live.vel_n_mps, off.vel_n_mps),
        ("vel_e_mps", live.vel_e_mps, off.vel_e_mps),
        ("vel_d_mps", live.vel_d_mps, off.vel_d_mps),
        ("speed_mps", live.speed_mps, off.speed_mps),
        ("track_deg", live.track_deg, off.track_deg),
        ("hdop", live.hdop, off.hdop),
        ("vdop", live.vdop, off.vdop),
        ("pdop", live.pdop, off.pdop),
        ("std_lat_m", live.std_lat_m, off.std_lat_m),
        ("std_lon_m", live.std_lon_m, off.std_lon_m),
        ("std_alt_m", live.std_alt_m, off.std_alt_m),
    ];
    for (n, a, b) in floats {
        if !same(a, b) {
            d.push(format!("{n}: live {a} offline {b}"));
        }
    }
    d
}

/// Consecutive fixes of the same epoch collapsed to the last one (an epoch re-emitted with
/// late data replaces the earlier emission, as consumers are told to do).
fn collapse(fixes: &[GnssFix]) -> Vec<GnssFix> {
    let mut out: Vec<GnssFix> = Vec::new();
    for f in fixes {
        match out.last_mut() {
            Some(l) if l.utc_ns == f.utc_ns && l.tod_ns == f.tod_ns => *l = *f,
            _ => out.push(*f),
        }
    }
    out
}

struct Run {
    name: &'static str,
    id: String,
    offline: Vec<GnssFix>,
    counters: navsync_drivers::gnss::nmea::NmeaCounters,
    fixes: Sub,
    health: Subscriber<Health>,
    live: Vec<GnssFix>,
    latest: Option<Health>,
    paced: bool,
}

type Sub = Subscriber<GnssFix>;

#[test]
fn corpus_captures_through_feed_and_gps_match_the_offline_decoder() {
    let dir = corpus();
    let mut env = TestEnv::new("feedcorpus");
    let node = env.node("observer");
    let mut runs = Vec::new();
    for (k, name) in MAX_SPEED.iter().chain(PACED.iter()).enumerate() {
        let bytes = std::fs::read(dir.join(name)).unwrap();
        let decoded = decode_capture(&bytes, Protocol::Nmea);
        let (offline, counters) = (decoded.fixes.clone(), decoded.nmea().expect("NMEA").counters());
        assert!(!offline.is_empty(), "{name}: no fixes offline");
        let id = format!("c{k}");
        runs.push(Run {
            name,
            offline,
            counters,
            fixes: node.subscriber::<GnssFix>(&services::gnss_fix(&id)).unwrap(),
            health: node
                .subscriber::<Health>(&services::health(&format!("gnss-{id}")))
                .unwrap(),
            id,
            live: Vec::new(),
            latest: None,
            paced: PACED.contains(name),
        });
    }
    for r in &runs {
        let link = env.dir.join(&r.id);
        let speed = if r.paced { PACED_SPEED.to_string() } else { "max".into() };
        env.spawn(
            &format!("feed-{}", r.id),
            &[
                "feed",
                &dir.join(r.name).display().to_string(),
                "--pty",
                "--link",
                &link.display().to_string(),
                "--speed",
                &speed,
                "--wait-reader",
                "--hold",
                "120",
            ],
        );
        env.wait_for_path(&link, Duration::from_secs(20));
        env.spawn(
            &format!("gps-{}", r.id),
            &[
                "gps",
                "--port",
                &link.display().to_string(),
                "--baud",
                "115200",
                // The NMEA decoder's counters are compared with the offline NMEA decode
                // (the default, auto, counts the same bytes in its u-blox framer).
                "--protocol",
                "nmea",
                "--id",
                &r.id,
            ],
        );
    }

    // Everything decoded offline must arrive; then a little more time for any re-emission.
    let t0 = Instant::now();
    let done = |r: &Run| {
        let sentences = r
            .latest
            .as_ref()
            .and_then(|h| h.counter("nmea_sentences_in"))
            .unwrap_or(0);
        collapse(&r.live).len() >= collapse(&r.offline).len() && sentences >= r.counters.epochs.sentences
    };
    while t0.elapsed() < Duration::from_secs(90) {
        env.assert_running();
        for r in runs.iter_mut() {
            while let Some(f) = r.fixes.receive().unwrap() {
                r.live.push(f);
            }
            while let Some(h) = r.health.receive().unwrap() {
                r.latest = Some(h);
            }
        }
        if runs.iter().all(done) {
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_millis(300));

    let mut report = String::new();
    let mut failures = 0;
    for r in runs.iter_mut() {
        while let Some(f) = r.fixes.receive().unwrap() {
            r.live.push(f);
        }
        let (live, off) = (collapse(&r.live), collapse(&r.offline));
        let mut bad = Vec::new();
        if live.len() != off.len() {
            bad.push(format!("{} epochs live, {} offline", live.len(), off.len()));
        }
        for (i, (a, b)) in live.iter().zip(&off).enumerate() {
            let d = diff(a, b);
            if !d.is_empty() {
                bad.push(format!("epoch {i}: {}", d.join(", ")));
            }
        }
        // The decoder's error counters do not depend on how the bytes were cut into reads.
        let h = r.latest.expect("health");
        let c = &r.counters;
        for (name, want) in [
            ("nmea_noise_bytes", c.framer.noise_bytes),
            ("nmea_truncated", c.framer.truncated),
            ("nmea_overlong", c.framer.overlong),
            ("nmea_non_ascii", c.framer.non_ascii),
            ("nmea_bad_checksum", c.epochs.bad_checksum),
            ("nmea_no_checksum", c.epochs.no_checksum),
            ("nmea_unparsable", c.epochs.unparsable),
            ("nmea_sentences_in", c.epochs.sentences),
        ] {
            if h.counter(name) != Some(want) {
                bad.push(format!("{name}: live {:?} offline {want}", h.counter(name)));
            }
        }
        if r.paced {
            // Paced by the time tags: the receipts spread over at least 80 % of the capture's
            // span at this speed (a lower bound: a slow machine only spreads them more).
            let span_live = (r.live.last().unwrap().stamp.host_ns - r.live[0].stamp.host_ns) as f64 * 1e-9;
            let tods: Vec<i64> = off.iter().map(|f| f.tod_ns).filter(|t| *t >= 0).collect();
            let span_cap = (tods.iter().max().unwrap() - tods.iter().min().unwrap()) as f64 * 1e-9;
            if span_live < 0.8 * span_cap / PACED_SPEED {
                bad.push(format!(
                    "not paced: {span_live:.2} s live for {span_cap:.1} s of capture"
                ));
            }
        }
        report.push_str(&format!(
            "{:<28} {:>4} epochs offline, {:>4} fixes live ({} after collapsing){}\n",
            r.name,
            off.len(),
            r.live.len(),
            live.len(),
            if bad.is_empty() {
                String::new()
            } else {
                format!("  MISMATCH: {}", bad.join("; "))
            }
        ));
        failures += usize::from(!bad.is_empty());
    }
    println!("{report}");
    assert_eq!(failures, 0, "\n{report}");
    drop(runs);
    drop(node);
    env.finish();
}
