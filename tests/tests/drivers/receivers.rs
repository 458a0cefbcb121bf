//! Receivers through the live driver as a user runs them (`navsync gnss` without
//! `--protocol`: `auto`, the bytes say which protocol they are), fed real u-blox captures
//! (`../shared/corpora/gpsd-ubx`) by `navsync feed` through pseudo-terminals:
//!
//! - **ublox-neo-m8l** (NAV-PVT epochs at 1 Hz, HNR-PVT at 10 Hz): the GNSS epochs on
//!   `navsync/gnss/{id}/fix` and the HNR-PVT fixes on `navsync/gnss/{id}/hnr`, never mixed:
//!   each service's times strictly increase and its sequence numbers count from 0 without a
//!   gap; no fix on `…/fix` is an HNR-PVT one (`sats_used` known on every GNSS fix), every
//!   fix on `…/hnr` is (`FIX_FLAG_NOT_GNSS`); as many of each as the offline decoder makes;
//! - **ublox-8-time** (NAV-SOL only: ECEF, no height above sea level): every fix's `alt_msl_m`
//!   is the ellipsoidal height less the EGM96 separation at its position, with the source
//!   stated (`FIX_GEOID_MODEL`); the ellipsoidal height is the receiver's.

use std::time::{Duration, Instant};

use navsync_drivers::gnss::capture::decode_capture;
use navsync_drivers::gnss::geoid::egm96_separation_m;
use navsync_drivers::gnss::{GnssDecoder, Protocol};
use navsync_shared::ipc::Subscriber;
use navsync_shared::samples::{FIX_FLAG_NOT_GNSS, FIX_GEOID_MODEL, GnssFix, UBX_MSG_HNR_PVT};
use navsync_shared::services;
use navsync_tests::{TestEnv, shared_material};

/// Plays `name` into a live `navsync gnss --id {id}` (default protocol) and collects its
/// fixes and HNR-PVT fixes until as many as offline arrived (or 60 s).
fn play(env: &mut TestEnv, name: &str, id: &str) -> (Vec<GnssFix>, Vec<GnssFix>, Vec<GnssFix>, Vec<GnssFix>) {
    let path = shared_material("corpora/gpsd-ubx").join(name);
    let offline = decode_capture(&std::fs::read(&path).unwrap(), Protocol::default());
    assert!(
        matches!(offline.decoder, navsync_drivers::gnss::Decoder::Auto(_)),
        "the default protocol is auto"
    );
    let node = env.node(&format!("observer-{id}"));
    let fix: Subscriber<GnssFix> = node.subscriber(&services::gnss_fix(id)).unwrap();
    let hnr: Subscriber<GnssFix> = node.subscriber(&services::gnss_hnr(id)).unwrap();
    let link = env.dir.join(id);
    let link_s = link.display().to_string();
    env.spawn(
        &format!("feed-{id}"),
        &[
            "feed",
            &path.display().to_string(),
            "--pty",
            "--link",
            &link_s,
            "--baud",
            "115200",
            "--wait-reader",
            "--hold",
            "120",
        ],
    );
    env.wait_for_path(&link, Duration::from_secs(20));
    env.spawn(
        &format!("gnss-{id}"),
        &["gnss", "--port", &link_s, "--baud", "115200", "--id", id],
    );
    let (mut got_fix, mut got_hnr) = (Vec::new(), Vec::new());
    let t0 = Instant::now();
    loop {
        env.assert_running();
        fix.for_each(|f| got_fix.push(*f)).unwrap();
        hnr.for_each(|f| got_hnr.push(*f)).unwrap();
        let complete = got_fix.len() >= offline.fixes.len() && got_hnr.len() >= offline.hnr.len();
        if complete || t0.elapsed() > Duration::from_secs(60) {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    // Nothing more arrives (no epoch published twice, late).
    std::thread::sleep(Duration::from_millis(300));
    fix.for_each(|f| got_fix.push(*f)).unwrap();
    hnr.for_each(|f| got_hnr.push(*f)).unwrap();
    println!(
        "{name}: fixes {}/{}, HNR-PVT {}/{} (live/offline) in {:.1} s",
        got_fix.len(),
        offline.fixes.len(),
        got_hnr.len(),
        offline.hnr.len(),
        t0.elapsed().as_secs_f64()
    );
    let mut counters = Vec::new();
    offline.decoder.each_counter(&mut |n, v| {
        if v > 0 && (n.contains("late") || n.contains("not_after") || n.contains("resets")) {
            counters.push(format!("{n}={v}"));
        }
    });
    println!("{name}: offline {}", counters.join(" "));
    env.kill9(&format!("gnss-{id}"));
    env.kill9(&format!("feed-{id}"));
    drop((fix, hnr, node));
    (got_fix, got_hnr, offline.fixes, offline.hnr)
}

/// Times strictly increase and sequence numbers count from 0.
fn in_order(what: &str, fixes: &[GnssFix]) {
    for w in fixes.windows(2) {
        assert!(
            w[0].utc_ns < w[1].utc_ns,
            "{what}: time {} then {}",
            w[0].utc_ns,
            w[1].utc_ns
        );
    }
    for (i, f) in fixes.iter().enumerate() {
        assert_eq!(f.stamp.seq, i as u64, "{what}: sequence numbers");
    }
}

#[test]
fn hnr_pvt_and_gnss_epochs_on_services_of_their_own_and_geoid_heights() {
    let mut env = TestEnv::new("receivers");

    let (fix, hnr, want_fix, want_hnr) = play(&mut env, "ublox-neo-m8l.log", "m8l");
    assert!(
        want_hnr.len() > 100 && want_fix.len() > 10,
        "the capture is what it was"
    );
    assert_eq!((fix.len(), hnr.len()), (want_fix.len(), want_hnr.len()));
    in_order("fix", &fix);
    in_order("hnr", &hnr);
    for f in &fix {
        assert_eq!(f.sentences & UBX_MSG_HNR_PVT, 0, "an HNR-PVT fix on …/fix: {f:?}");
        assert_eq!(f.fix_flags & FIX_FLAG_NOT_GNSS, 0);
        assert!(
            f.mode < 2 || f.sats_used != u16::MAX,
            "GNSS epoch without sats_used: {f:?}"
        );
    }
    for (h, w) in hnr.iter().zip(&want_hnr) {
        assert_ne!(h.sentences & UBX_MSG_HNR_PVT, 0);
        assert_ne!(h.fix_flags & FIX_FLAG_NOT_GNSS, 0);
        assert_eq!(
            (h.utc_ns, h.lat_deg.to_bits()),
            (w.utc_ns, w.lat_deg.to_bits()),
            "as offline"
        );
    }

    let (fix, hnr, want_fix, _) = play(&mut env, "ublox-8-time.log", "sol");
    assert!(hnr.is_empty());
    assert_eq!(fix.len(), want_fix.len());
    in_order("fix", &fix);
    let mut with_position = 0;
    for f in fix.iter().filter(|f| f.has_position()) {
        with_position += 1;
        assert_ne!(f.sentences & FIX_GEOID_MODEL, 0, "source stated: {f:?}");
        let n = egm96_separation_m(f.lat_deg, f.lon_deg).unwrap();
        assert!((f.geoid_sep_m - n).abs() < 0.05, "{} vs EGM96 {n}", f.geoid_sep_m);
        assert!(
            (f.height_m() - f.alt_msl_m - n).abs() < 0.05,
            "MSL = ellipsoidal − N: {f:?}"
        );
    }
    assert!(with_position > 50, "{with_position} fixes with a position");
    env.finish();
}

#[test]
fn navsync_decode_finds_the_protocol_and_says_what_it_saw() {
    let env = TestEnv::new("decodeauto");
    let path = shared_material("corpora/gpsd-ubx").join("ublox-neo-m8n.log");
    let file = path.display().to_string();
    // No --protocol: auto, as for a u-blox capture a user decodes.
    let out = env.command(&["decode", &file]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let lines: Vec<serde_json::Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let offline = decode_capture(&std::fs::read(&path).unwrap(), Protocol::Auto);
    assert_eq!(lines.len(), offline.fixes.len());
    assert!(lines.len() > 10);
    for (l, f) in lines.iter().zip(&offline.fixes) {
        assert_eq!(f.utc_ns % 1_000_000, 0, "NAV-PVT epochs on their millisecond");
        assert_eq!(l["time"], navsync_shared::time::format_rfc3339_ms(f.utc_ns).as_str());
        assert_eq!(l["alt_msl_source"], "receiver");
    }
    // Forced to NMEA, it fails and says what the bytes are.
    let out = env.command(&["decode", "--protocol", "nmea", &file]).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("UBX frames") && err.contains("--protocol auto"),
        "the failure names what was seen: {err}"
    );
    env.finish();
}
