//! `navsync gnss` as a real process on pseudo-terminals fed by `navsync feed`, under the
//! faults of a real serial line: malformed input (bad checksums, truncated, over-long and
//! non-ASCII sentences, binary noise) counted exactly and logged once per kind; a wrong line
//! rate (the feeder delivers what a UART at the reader's rate would receive) showing as noise,
//! and `--baud auto` hunting its way to the right rate (also for a u-blox receiver in UBX with
//! `--protocol auto`); the port vanishing (feeder killed:
//! pseudo-terminal and link gone) and returning on the same link.

use std::path::Path;
use std::time::{Duration, Instant};

use navsync_drivers::gnss::Protocol;
use navsync_drivers::gnss::capture::decode_capture;
use navsync_shared::ipc::Subscriber;
use navsync_shared::samples::*;
use navsync_shared::services;
use navsync_tests::TestEnv;

/// `$body*hh\r\n` with the right checksum.
fn sentence(body: &str) -> String {
    let cs = body.bytes().fold(0u8, |a, b| a ^ b);
    format!("${body}*{cs:02X}\r\n")
}

fn hms(t: u32) -> String {
    format!("{:02}{:02}{:02}.00", 12 + t / 3600, (t / 60) % 60, t % 60)
}

/// One clean epoch: GGA, GSA, RMC at second `t`.
fn epoch(t: u32) -> String {
    let lat = format!("4807.{:06}", 38_000 + t * 7);
    [
        sentence(&format!(
            "GPGGA,{},{lat},N,01131.000000,E,1,08,0.9,545.4,M,46.9,M,,",
            hms(t)
        )),
        sentence("GPGSA,A,3,04,05,,09,12,,,24,,,,,2.5,1.3,2.1"),
        sentence(&format!(
            "GPRMC,{},A,{lat},N,01131.000000,E,022.4,084.4,230394,003.1,W",
            hms(t)
        )),
    ]
    .concat()
}

fn clean_capture(epochs: u32) -> String {
    let mut s = String::from("# synthetic receiver\n");
    for t in 0..epochs {
        s.push_str(&epoch(t));
    }
    s
}

fn spawn_feed(env: &mut TestEnv, name: &str, capture: &Path, link: &Path, extra: &[&str]) {
    let mut args = vec![
        "feed".to_string(),
        capture.display().to_string(),
        "--pty".into(),
        "--link".into(),
        link.display().to_string(),
        "--wait-reader".into(),
    ];
    args.extend(extra.iter().map(|s| s.to_string()));
    let a: Vec<&str> = args.iter().map(String::as_str).collect();
    env.spawn(name, &a);
    env.wait_for_path(link, Duration::from_secs(20));
}

struct Watch {
    fixes: Subscriber<GnssFix>,
    health: Subscriber<Health>,
    got: Vec<GnssFix>,
    latest: Option<Health>,
}

impl Watch {
    fn new(env: &TestEnv, node: &navsync_shared::ipc::IpcNode, id: &str) -> Self {
        let _ = env;
        Self {
            fixes: node.subscriber(&services::gnss_fix(id)).unwrap(),
            health: node.subscriber(&services::health(&format!("gnss-{id}"))).unwrap(),
            got: Vec::new(),
            latest: None,
        }
    }

    fn poll(&mut self) {
        while let Some(f) = self.fixes.receive().unwrap() {
            self.got.push(f);
        }
        while let Some(h) = self.health.receive().unwrap() {
            self.latest = Some(h);
        }
    }

    fn counter(&self, name: &str) -> u64 {
        self.latest.as_ref().and_then(|h| h.counter(name)).unwrap_or(0)
    }

    /// Polls until `cond` holds (or 60 s pass); returns whether it held. Every child must
    /// keep running unless `env` is `None` (a child was stopped on purpose).
    fn wait(&mut self, mut env: Option<&mut TestEnv>, cond: impl Fn(&Self) -> bool) -> bool {
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(60) {
            if let Some(e) = env.as_deref_mut() {
                e.assert_running();
            }
            self.poll();
            if cond(self) {
                return true;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        false
    }
}

#[test]
fn malformed_input_is_dropped_counted_and_logged_once_per_kind() {
    let mut env = TestEnv::new("gpsbad");
    let node = env.node("observer");
    let mut w = Watch::new(&env, &node, "0");
    let mut cap: Vec<u8> = b"# synthetic receiver with a bad line\n".to_vec();
    for t in 0..40u32 {
        cap.extend_from_slice(epoch(t).as_bytes());
        // A bad checksum every epoch.
        cap.extend_from_slice(b"$GPGSV,3,1,11,03,03,111,00,04,15,270,00*00\r\n");
        if t % 3 == 0 {
            // Truncated: the next sentence starts before this one ended.
            cap.extend_from_slice(b"$GPGGA,12351");
        }
        if t % 4 == 0 {
            // Binary noise between sentences (no `$`, `!`, CR or LF).
            cap.extend((0..40u8).map(|i| 0x80 | i.wrapping_mul(37)));
            cap.extend_from_slice(b"\r\n");
        }
        if t % 5 == 0 {
            let mut long = b"$GPTXT,01,01,02,".to_vec();
            long.extend(std::iter::repeat_n(b'A', 300));
            long.extend_from_slice(b"*00\r\n");
            cap.extend_from_slice(&long);
        }
        if t % 7 == 0 {
            cap.extend_from_slice(b"$GPZDA,120000.00,23,03,1994,\x01\x02,00*00\r\n");
        }
        if t % 8 == 0 {
            cap.extend_from_slice(b"$GPVTG,084.4,T,077.8,M,022.4,N,041.5,K\r\n");
        }
    }
    let path = env.dir.join("bad.log");
    std::fs::write(&path, &cap).unwrap();
    let decoded = decode_capture(&cap, Protocol::Nmea);
    let (offline, oc) = (decoded.fixes.clone(), decoded.nmea().expect("NMEA").counters());
    assert_eq!(offline.len(), 40);
    assert!(oc.framer.noise_bytes > 0 && oc.framer.truncated > 0 && oc.framer.overlong > 0 && oc.framer.non_ascii > 0);
    assert!(oc.epochs.bad_checksum > 0 && oc.epochs.no_checksum > 0);

    let link = env.dir.join("gnss0");
    spawn_feed(&mut env, "feed", &path, &link, &["--speed", "max", "--hold", "60"]);
    env.spawn(
        "gnss",
        &[
            "gnss",
            "--port",
            &link.display().to_string(),
            "--baud",
            "115200",
            // The NMEA decoder's own counters are the subject (auto, the default, counts the
            // sentences it hands to it under ubx_* names too).
            "--protocol",
            "nmea",
            "--id",
            "0",
        ],
    );
    assert!(
        w.wait(Some(&mut env), |w| w.got.len() >= 40
            && w.counter("nmea_sentences_in") >= oc.epochs.sentences),
        "{} fixes\n{}",
        w.got.len(),
        env.log("gnss")
    );
    assert_eq!(w.got.len(), 40);
    for (a, b) in w.got.iter().zip(&offline) {
        assert_eq!(
            (a.utc_ns, a.tod_ns, a.mode, a.sats_used),
            (b.utc_ns, b.tod_ns, b.mode, b.sats_used)
        );
        assert_eq!(a.lat_deg.to_bits(), b.lat_deg.to_bits());
        assert_eq!(a.speed_mps.to_bits(), b.speed_mps.to_bits());
    }
    let kinds = [
        ("nmea_noise_bytes", oc.framer.noise_bytes),
        ("nmea_truncated", oc.framer.truncated),
        ("nmea_overlong", oc.framer.overlong),
        ("nmea_non_ascii", oc.framer.non_ascii),
        ("nmea_bad_checksum", oc.epochs.bad_checksum),
        ("nmea_no_checksum", oc.epochs.no_checksum),
    ];
    for (name, want) in kinds {
        assert_eq!(w.counter(name), want, "{name}");
    }
    // One log line per kind: the first occurrence; nothing per occurrence.
    let log = env.log("gnss");
    for (name, _) in kinds {
        assert_eq!(
            log.matches(name).count(),
            1,
            "{name} logged {} times:\n{log}",
            log.matches(name).count()
        );
    }
    assert!(log.lines().count() <= kinds.len() + 2, "log flood:\n{log}");
    drop((w, node));
    env.finish();
}

#[test]
fn wrong_baud_is_noise_and_auto_hunts_to_the_right_rate() {
    let mut env = TestEnv::new("gpsbaud");
    let node = env.node("observer");
    let path = env.dir.join("clean.log");
    std::fs::write(&path, clean_capture(20)).unwrap();
    let mut fixed = Watch::new(&env, &node, "fixed");
    let mut auto = Watch::new(&env, &node, "auto");
    let (la, lb) = (env.dir.join("a"), env.dir.join("b"));
    let feed = ["--baud", "38400", "--speed", "4", "--loop"];
    spawn_feed(&mut env, "feed-a", &path, &la, &feed);
    spawn_feed(&mut env, "feed-b", &path, &lb, &feed);
    env.spawn(
        "gnss-fixed",
        &[
            "gnss",
            "--port",
            &la.display().to_string(),
            "--baud",
            "9600",
            "--protocol",
            "nmea",
            "--id",
            "fixed",
        ],
    );
    env.spawn(
        "gnss-auto",
        &[
            "gnss",
            "--port",
            &lb.display().to_string(),
            "--baud",
            "auto",
            "--id",
            "auto",
        ],
    );
    assert!(
        auto.wait(Some(&mut env), |w| w.got.len() >= 8 && w.counter("baud") == 38_400),
        "auto: {} fixes, baud {}\n{}",
        auto.got.len(),
        auto.counter("baud"),
        env.log("gnss-auto")
    );
    // 9600 → 4800 → 38400.
    assert!(auto.counter("baud_hunts") >= 2, "hunts {}", auto.counter("baud_hunts"));
    assert_eq!(
        auto.counter("port_opens"),
        1,
        "hunting changes the rate without reopening"
    );
    assert!(auto.got.iter().all(|f| f.mode == FixMode::Fix3d as u8));
    // Meanwhile the fixed-rate driver at the wrong rate got only garbage, and says so.
    fixed.poll();
    assert!(fixed.got.is_empty(), "{} fixes at the wrong rate", fixed.got.len());
    assert!(fixed.wait(Some(&mut env), |w| w.counter("nmea_noise_bytes")
        + w.counter("nmea_bad_checksum")
        > 100));
    assert_eq!(fixed.counter("baud"), 9600);
    assert_eq!(fixed.counter("baud_hunts"), 0);
    let log = env.log("gnss-fixed");
    assert!(log.lines().count() < 10, "log flood:\n{log}");
    drop((fixed, auto, node));
    env.finish();
}

/// A u-blox receiver sending UBX and NMEA at 38400 Bd (a real capture, looped) is found by
/// `--baud auto --protocol auto`: valid UBX frames count as the right rate like NMEA
/// sentences, and the epochs come from UBX.
#[test]
fn auto_baud_and_protocol_find_a_ublox_receiver() {
    let mut env = TestEnv::new("gpsbaudubx");
    let node = env.node("observer");
    let capture = navsync_tests::shared_material("corpora/gpsd-ubx/ublox-neo-m8l.log");
    let mut w = Watch::new(&env, &node, "ubx");
    let link = env.dir.join("u");
    spawn_feed(&mut env, "feed", &capture, &link, &["--baud", "38400", "--loop"]);
    env.spawn(
        "gnss",
        &[
            "gnss",
            "--port",
            &link.display().to_string(),
            "--baud",
            "auto",
            "--protocol",
            "auto",
            "--id",
            "ubx",
        ],
    );
    assert!(
        // The health report comes once a second and the looped capture can deliver 8 epochs
        // sooner, so the counters are waited for too (the report that first shows 38400 Bd may
        // predate the first frame decoded at that rate).
        w.wait(Some(&mut env), |w| w.got.len() >= 8
            && w.counter("baud") == 38_400
            && w.counter("ubx_frames") > 0),
        "{} fixes, baud {}, UBX frames counted {}\n{}",
        w.got.len(),
        w.counter("baud"),
        w.counter("ubx_frames"),
        env.log("gnss")
    );
    assert!(w.counter("baud_hunts") >= 2, "hunts {}", w.counter("baud_hunts"));
    assert!(w.got.iter().all(|f| f.protocol == GNSS_PROTOCOL_UBX), "epochs from UBX");
    drop((w, node));
    env.finish();
}

#[test]
fn the_port_vanishing_and_returning_is_survived() {
    let mut env = TestEnv::new("gpsunplug");
    let node = env.node("observer");
    let path = env.dir.join("clean.log");
    std::fs::write(&path, clean_capture(30)).unwrap();
    let mut w = Watch::new(&env, &node, "0");
    let link = env.dir.join("ttyUSB0");
    spawn_feed(&mut env, "feed1", &path, &link, &["--speed", "5", "--loop"]);
    env.spawn(
        "gnss",
        &[
            "gnss",
            "--port",
            &link.display().to_string(),
            "--baud",
            "4800",
            "--id",
            "0",
        ],
    );
    assert!(w.wait(Some(&mut env), |w| w.got.len() >= 3), "{}", env.log("gnss"));

    // Unplug: the feeder goes, taking the pseudo-terminal and the link with it.
    env.signal("feed1", libc::SIGTERM);
    let t0 = Instant::now();
    while link.exists() && t0.elapsed() < Duration::from_secs(20) {
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(!link.exists());
    assert!(w.wait(None, |w| w.counter("port_reopens") >= 1
        && w.counter("port_open_failures") >= 2));
    // Detection is what the once-per-second health report shows.
    let detected_s = t0.elapsed().as_secs_f64();
    let before = w.got.len();

    // Plug back in on the same link.
    let t1 = Instant::now();
    spawn_feed(&mut env, "feed2", &path, &link, &["--speed", "5", "--loop"]);
    assert!(w.wait(None, |w| w.got.len() > before), "{}", env.log("gnss"));
    let first_fix_s = t1.elapsed().as_secs_f64();
    assert!(w.wait(None, |w| w.got.len() >= before + 3), "{}", env.log("gnss"));
    println!(
        "unplug: reopen and {} failed opens in health after {detected_s:.2} s; replug: first fix after {first_fix_s:.2} s (reopen backoff 0.1 s → 5 s)",
        w.counter("port_open_failures")
    );
    assert_eq!(w.counter("port_opens"), 2);
    // The backoff never exceeds 5 s; with the feeder's start-up this bounds the recovery.
    assert!(
        first_fix_s < 15.0,
        "first fix {first_fix_s} s after the device returned"
    );
    let log = env.log("gnss");
    assert_eq!(log.matches("cannot open").count(), 1, "one line per outage:\n{log}");
    assert!(log.lines().count() < 10, "log flood:\n{log}");
    drop((w, node));
    env.finish();
}
