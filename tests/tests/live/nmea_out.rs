//! `navsync nmea-out` on a pseudo-terminal, read as a LiDAR's NMEA input would: right after
//! each GNSS second of the published time mapping, `$GPRMC` then `$GPZDA` of that second, with
//! valid checksums, consecutive seconds, the fused position while the state is aligned; each
//! pair arrives after its second began and before the next one.

use std::time::{Duration, Instant};

use navsync_shared::reflect::Reflect;
use navsync_shared::samples::{NavState, NavStatus, TimeState, TimeStatus};
use navsync_shared::services;
use navsync_shared::time::{NS_PER_S, monotonic_now_ns, realtime_now_ns};
use navsync_tests::TestEnv;

/// GNSS time minus the system clock in this test's mapping, ns.
const OFFSET_NS: i64 = 375_000_000;

/// One locked mapping for a whole test (UTC = host time + (realtime − monotonic) + OFFSET) and
/// an aligned state at 48.137° N, `lon_deg`, moving at 5 m/s; with the realtime it was made at.
fn mapping_and_state(lon_deg: f64) -> (TimeState, NavState, i64) {
    let (h0, r0) = (monotonic_now_ns(), realtime_now_ns());
    let mut t = TimeState::unknown();
    t.status = TimeStatus::Locked as u8;
    t.ref_host_ns = h0;
    t.ref_utc_ns = r0 + OFFSET_NS;
    t.offset_std_ns = 500.0;
    t.rate_std = 1e-9;
    t.leap_s = 18;
    let mut n = NavState::zeroed();
    n.status = NavStatus::Aligned as u8;
    n.lat_deg = 48.137154;
    n.lon_deg = lon_deg;
    n.vel_ned_mps = [5.0, 0.0, 0.0];
    (t, n, r0)
}

/// Publishes the mapping and the state, stamped now.
fn publish_now(
    t: &mut TimeState,
    n: &mut NavState,
    time_pub: &mut navsync_shared::ipc::Publisher<TimeState>,
    nav_pub: &mut navsync_shared::ipc::Publisher<NavState>,
) {
    let now = monotonic_now_ns();
    t.computed_host_ns = now;
    n.host_ns = now;
    time_pub.publish(t).unwrap();
    nav_pub.publish(n).unwrap();
}

#[test]
fn nmea_out_writes_rmc_and_zda_after_each_gnss_second() {
    let mut env = TestEnv::new("nmeaout");
    let node = env.node("mapping");
    let mut time_pub = node.publisher::<TimeState>(services::TIME_STATE).unwrap();
    let mut nav_pub = node.publisher::<NavState>(services::NAV_STATE).unwrap();
    let pty = navsync_drivers::pty::Pty::open(None).expect("a pseudo-terminal");
    let port = pty.path().display().to_string();
    let (mut t, mut n, r0) = mapping_and_state(-11.576124);
    env.spawn("nmea-out", &["nmea-out", "--port", &port, "--baud", "9600"]);

    let mut pty = pty;
    let mut chunks: Vec<(i64, Vec<u8>)> = Vec::new();
    let mut buf = [0u8; 512];
    let t0 = Instant::now();
    let mut last_pub = Instant::now() - Duration::from_secs(1);
    while t0.elapsed() < Duration::from_millis(4500) {
        if last_pub.elapsed() > Duration::from_millis(100) {
            publish_now(&mut t, &mut n, &mut time_pub, &mut nav_pub);
            last_pub = Instant::now();
        }
        while let Ok(k) = pty.read(&mut buf) {
            if k == 0 {
                break;
            }
            chunks.push((monotonic_now_ns(), buf[..k].to_vec()));
        }
        env.assert_running();
        std::thread::sleep(Duration::from_millis(2));
    }

    // Sentences, each with the host time its first byte was read.
    let mut lines: Vec<(i64, String)> = Vec::new();
    let mut cur = String::new();
    let mut cur_at = 0;
    for (at, bytes) in &chunks {
        for &b in bytes {
            if cur.is_empty() {
                cur_at = *at;
            }
            if b == b'\n' {
                lines.push((cur_at, cur.trim_end().to_string()));
                cur.clear();
            } else {
                cur.push(b as char);
            }
        }
    }
    assert!(
        lines.len() >= 6,
        "{} sentences: {lines:?}\n{}",
        lines.len(),
        env.log("nmea-out")
    );
    let mut seconds = Vec::new();
    for pair in lines.chunks(2).filter(|p| p.len() == 2) {
        let (rmc_at, rmc) = &pair[0];
        let (_, zda) = &pair[1];
        for s in [rmc, zda] {
            let (body, cs) = s[1..].split_once('*').unwrap_or_else(|| panic!("no checksum: {s}"));
            let sum = body.bytes().fold(0u8, |a, b| a ^ b);
            assert_eq!(u8::from_str_radix(cs, 16).ok(), Some(sum), "checksum of {s}");
        }
        assert!(
            rmc.starts_with("$GPRMC,") && zda.starts_with("$GPZDA,"),
            "{rmc} / {zda}"
        );
        let f: Vec<&str> = rmc.split(',').collect();
        assert_eq!((f[2], f[4], f[6]), ("A", "N", "W"), "{rmc}");
        assert_eq!(f[1], zda.split(',').nth(1).unwrap(), "RMC and ZDA of one second");
        // The second the pair names, as UTC ns, and the host time it began at by the mapping.
        let z: Vec<&str> = zda.split(',').collect();
        let hms = z[1];
        let (hh, mm, ss): (i64, i64, i64) = (
            hms[0..2].parse().unwrap(),
            hms[2..4].parse().unwrap(),
            hms[4..6].parse().unwrap(),
        );
        let day_ns = (r0 + OFFSET_NS).div_euclid(86_400 * NS_PER_S) * 86_400 * NS_PER_S;
        let mut utc = day_ns + ((hh * 60 + mm) * 60 + ss) * NS_PER_S;
        if utc < r0 + OFFSET_NS - 3600 * NS_PER_S {
            utc += 86_400 * NS_PER_S; // the test crossed midnight UTC
        }
        let begins = t.host_ns_at(utc);
        let after = (rmc_at - begins) as f64 * 1e-9;
        assert!(
            (0.0..1.0).contains(&after),
            "{rmc} read {after:.3} s after its second began (must be within that second)"
        );
        seconds.push(utc);
    }
    assert!(seconds.len() >= 3, "{seconds:?}");
    assert!(
        seconds.windows(2).all(|w| w[1] - w[0] == NS_PER_S),
        "not consecutive seconds: {seconds:?}"
    );
    drop((time_pub, nav_pub, node));
    env.finish();
}

/// The gpsd binary, or why the test cannot run.
fn gpsd_bin() -> Result<std::path::PathBuf, String> {
    let bin = ["/usr/sbin/gpsd", "/usr/bin/gpsd", "/usr/local/sbin/gpsd"]
        .iter()
        .map(std::path::PathBuf::from)
        .find(|p| p.exists())
        .ok_or("gpsd is not installed (Debian package `gpsd`; .ci/run installs it as root)")?;
    Ok(bin)
}

/// A real gpsd takes `nmea-out` as its time source: nmea-out → pseudo-terminal → (this test
/// relays the bytes) → a second pseudo-terminal → `gpsd -N -n -b` → its JSON socket: every
/// TPV's `time` is the GNSS second of the published mapping whose sentences just came, for
/// consecutive seconds.
#[test]
fn gpsd_takes_nmea_out_as_its_time_source() {
    use std::io::{BufRead, BufReader, Write};
    let bin = match gpsd_bin() {
        Ok(b) => b,
        Err(why) => {
            println!("SKIPPED: {why}");
            return;
        }
    };
    let mut env = TestEnv::new("nmeagpsd");
    let node = env.node("mapping");
    let mut time_pub = node.publisher::<TimeState>(services::TIME_STATE).unwrap();
    let mut nav_pub = node.publisher::<NavState>(services::NAV_STATE).unwrap();
    let mut out = navsync_drivers::pty::Pty::open(None).expect("a pseudo-terminal");
    let port = out.path().display().to_string();
    let gpsd_link = env.dir.join("gpsd-tty");
    let mut into_gpsd = navsync_drivers::pty::Pty::open(Some(&gpsd_link)).expect("a pseudo-terminal");
    let (mut t, mut n, r0) = mapping_and_state(11.576124);
    env.spawn("nmea-out", &["nmea-out", "--port", &port, "--baud", "9600"]);
    let tcp = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
        .to_string();
    let gpsd = std::process::Command::new(&bin)
        .args(["-N", "-n", "-b", "-S", &tcp, "-F"])
        .arg(env.dir.join("gpsd.sock"))
        .arg(&gpsd_link)
        .stdout(std::process::Stdio::null())
        .stderr(std::fs::File::create(env.dir.join("gpsd.log")).expect("log"))
        .spawn()
        .expect("starting gpsd");
    let _gpsd = navsync_bench::netns::StopOnDrop(gpsd);

    // gpsd's JSON stream, read on a thread; TPV lines with the host time they came.
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    let tcp_port = tcp.clone();
    std::thread::spawn(move || {
        let t0 = Instant::now();
        let stream = loop {
            match std::net::TcpStream::connect(format!("127.0.0.1:{tcp_port}")) {
                Ok(s) => break s,
                Err(_) if t0.elapsed() < Duration::from_secs(10) => std::thread::sleep(Duration::from_millis(50)),
                Err(_) => return,
            }
        };
        let mut w = stream.try_clone().expect("clone");
        let _ = w.write_all(b"?WATCH={\"enable\":true,\"json\":true}\n");
        for line in BufReader::new(stream).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                return;
            }
        }
    });

    let mut tpv_times: Vec<String> = Vec::new();
    let mut zda_seconds: Vec<String> = Vec::new();
    let mut pending = String::new();
    let mut buf = [0u8; 512];
    let t0 = Instant::now();
    let mut last_pub = Instant::now() - Duration::from_secs(1);
    while t0.elapsed() < Duration::from_secs(12) && tpv_times.len() < 6 {
        if last_pub.elapsed() > Duration::from_millis(100) {
            publish_now(&mut t, &mut n, &mut time_pub, &mut nav_pub);
            last_pub = Instant::now();
        }
        // The relay: what nmea-out wrote, into gpsd's terminal.
        while let Ok(k) = out.read(&mut buf) {
            if k == 0 {
                break;
            }
            into_gpsd.write(&buf[..k]).expect("relaying to gpsd");
            pending.push_str(&String::from_utf8_lossy(&buf[..k]));
        }
        while let Some(i) = pending.find('\n') {
            let line: String = pending.drain(..=i).collect();
            if let Some(hms) = line.strip_prefix("$GPZDA,").and_then(|r| r.get(..6)) {
                zda_seconds.push(hms.to_string());
            }
        }
        while let Ok(line) = rx.try_recv() {
            if line.contains("\"class\":\"TPV\"")
                && let Some(time) = line.split("\"time\":\"").nth(1).and_then(|r| r.split('"').next())
            {
                tpv_times.push(time.to_string());
            }
        }
        env.assert_running();
        std::thread::sleep(Duration::from_millis(5));
    }
    let log = std::fs::read_to_string(env.dir.join("gpsd.log")).unwrap_or_default();
    println!("gpsd TPV times: {tpv_times:?}\nnmea-out ZDA seconds: {zda_seconds:?}");
    assert!(
        tpv_times.len() >= 4,
        "gpsd reported {} TPVs with a time\n{log}",
        tpv_times.len()
    );
    // Each TPV time is a whole second the mapping named (a ZDA of nmea-out), consecutive.
    let mut secs = Vec::new();
    for time in &tpv_times {
        // 2026-12-05T00:25:03.000Z
        let hms: String = time.get(11..19).unwrap_or("").replace(':', "");
        assert!(time.ends_with(".000Z"), "TPV time {time} is not a whole second");
        assert!(
            zda_seconds.contains(&hms),
            "TPV time {time} is not a second nmea-out named: {zda_seconds:?}"
        );
        let civil = navsync_shared::time::civil_from_utc_ns(r0 + OFFSET_NS);
        let day = format!("{:04}-{:02}-{:02}", civil.year, civil.month, civil.day);
        if !time.starts_with(&day) {
            println!("the test crossed midnight UTC: {time} vs {day}");
        }
        let s: i64 = hms
            .parse::<i64>()
            .map(|v| (v / 10000) * 3600 + (v / 100 % 100) * 60 + v % 100)
            .unwrap();
        secs.push(s);
    }
    // gpsd may report one cycle in more than one TPV (RMC, then ZDA): one second each.
    secs.dedup();
    assert!(
        secs.len() >= 3 && secs.windows(2).all(|w| (w[1] - w[0]).rem_euclid(86_400) == 1),
        "TPV times not one per second: {tpv_times:?}"
    );
    drop((time_pub, nav_pub, node));
    env.finish();
}
