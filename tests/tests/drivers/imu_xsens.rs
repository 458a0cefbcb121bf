//! `navsync imu --source xsens:PORT` as a real process on a pseudo-terminal fed by
//! `navsync feed` with hand-built Xbus bytes (encoded here, independently of the driver's
//! encoder): values and axes (sensor frame z up → forward-right-down), the device clock
//! unwrapped across its 2³² wrap, PacketCounter wrap and gaps, every kind of corruption
//! (garbage, bad checksum, truncated message, NaN, out of range, device time backwards)
//! rejected and counted, float32 / fixed 16.32 / float64 formats, an extended-length
//! message, clipping flags, and the port vanishing and returning (feeder exits, a new one
//! takes the same link).

use std::time::{Duration, Instant};

use navsync_shared::samples::*;
use navsync_shared::services;
use navsync_tests::TestEnv;

/// Sum of BID..DATA, negated.
fn checksum(body: &[u8]) -> u8 {
    body.iter().fold(0u8, |s, &b| s.wrapping_add(b)).wrapping_neg()
}

/// One Xbus message FA FF MID LEN DATA CS (standard or extended length).
fn message(mid: u8, data: &[u8]) -> Vec<u8> {
    let mut body = vec![0xFF, mid];
    if data.len() < 255 {
        body.push(data.len() as u8);
    } else {
        body.push(0xFF);
        body.extend_from_slice(&(data.len() as u16).to_be_bytes());
    }
    body.extend_from_slice(data);
    let cs = checksum(&body);
    let mut m = vec![0xFA];
    m.extend_from_slice(&body);
    m.push(cs);
    m
}

#[derive(Clone, Copy)]
enum Fmt {
    F32,
    Fp1632,
    F64,
}

fn put_reals(d: &mut Vec<u8>, id: u16, fmt: Fmt, v: &[f64]) {
    let (bits, size) = match fmt {
        Fmt::F32 => (0, 4),
        Fmt::Fp1632 => (2, 6),
        Fmt::F64 => (3, 8),
    };
    d.extend_from_slice(&(id | bits).to_be_bytes());
    d.push((v.len() * size) as u8);
    for &x in v {
        match fmt {
            Fmt::F32 => d.extend_from_slice(&(x as f32).to_be_bytes()),
            Fmt::F64 => d.extend_from_slice(&x.to_be_bytes()),
            Fmt::Fp1632 => {
                let i = (x * 4_294_967_296.0).round() as i64;
                d.extend_from_slice(&(i as u32).to_be_bytes());
                d.extend_from_slice(&((i >> 32) as i16).to_be_bytes());
            }
        }
    }
}

/// What one frame says, in the Xsens sensor frame (z up).
#[derive(Clone, Copy)]
struct Frame {
    pc: u16,
    stf: u32,
    gyro: [f64; 3],
    accel: [f64; 3],
    temp: f64,
    status: u32,
    fmt: Fmt,
}

fn mtdata2(f: &Frame) -> Vec<u8> {
    let mut d = Vec::new();
    d.extend_from_slice(&[0x10, 0x20, 2]);
    d.extend_from_slice(&f.pc.to_be_bytes());
    d.extend_from_slice(&[0x10, 0x60, 4]);
    d.extend_from_slice(&f.stf.to_be_bytes());
    d.extend_from_slice(&[0xE0, 0x20, 4]);
    d.extend_from_slice(&f.status.to_be_bytes());
    put_reals(&mut d, 0x0810, f.fmt, &[f.temp]);
    put_reals(&mut d, 0x4020, f.fmt, &f.accel);
    put_reals(&mut d, 0x8020, f.fmt, &f.gyro);
    message(0x36, &d)
}

fn frame(k: u32, pc: u16, stf: u32) -> Frame {
    let x = f64::from(k);
    Frame {
        pc,
        stf,
        gyro: [0.01 * x, -0.02 * x, 0.5 + 0.001 * x],
        accel: [0.1 * x, 0.2, 9.80665 - 0.01 * x],
        temp: 30.0 + 0.25 * x,
        status: 0,
        fmt: Fmt::F32,
    }
}

/// The sample the driver must publish for `f` (sensor z up → FRD: x, −y, −z).
struct Expect {
    seq: u64,
    device_ns: i64,
    gyro: [f64; 3],
    accel: [f64; 3],
    temp: f64,
    saturated: bool,
}

fn expect(f: &Frame, seq: u64, unwrapped_ticks: i64) -> Expect {
    let q = |v: f64| match f.fmt {
        Fmt::F32 => f64::from(v as f32),
        Fmt::Fp1632 => (v * 4_294_967_296.0).round() / 4_294_967_296.0,
        Fmt::F64 => v,
    };
    Expect {
        seq,
        device_ns: unwrapped_ticks * 100_000,
        gyro: [q(f.gyro[0]), -q(f.gyro[1]), -q(f.gyro[2])],
        accel: [q(f.accel[0]), -q(f.accel[1]), -q(f.accel[2])],
        temp: q(f.temp),
        saturated: f.status != 0,
    }
}

fn collect(sub: &navsync_shared::ipc::Subscriber<ImuSample>, n: usize, got: &mut Vec<ImuSample>) {
    let t0 = Instant::now();
    while got.len() < n && t0.elapsed() < Duration::from_secs(30) {
        while let Some(s) = sub.receive().unwrap() {
            got.push(s);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn health(sub: &navsync_shared::ipc::Subscriber<Health>, latest: &mut Option<Health>) {
    while let Some(h) = sub.receive().unwrap() {
        *latest = Some(h);
    }
}

fn wait_counter(
    sub: &navsync_shared::ipc::Subscriber<Health>,
    latest: &mut Option<Health>,
    name: &str,
    min: u64,
) -> u64 {
    let t0 = Instant::now();
    loop {
        health(sub, latest);
        let v = latest.as_ref().and_then(|h| h.counter(name)).unwrap_or(0);
        if v >= min || t0.elapsed() > Duration::from_secs(20) {
            return v;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn xsens_driver_decodes_checks_and_survives_unplug() {
    let mut env = TestEnv::new("xsens");
    let node = env.node("observer");
    let sub = node.subscriber::<ImuSample>(&services::imu_sample("7")).unwrap();
    let hsub = node.subscriber::<Health>(&services::health("imu-7")).unwrap();
    let link = env.dir.join("mti");
    let link_s = link.display().to_string();

    // --- capture 1 ---------------------------------------------------------------------
    let mut bytes = vec![0x00, 0xFA, 0x12, 0x55, 0xFA, 0xFF, 0x36]; // garbage with fake starts
    let mut expected = Vec::new();
    let stf0: u32 = u32::MAX - 120; // wraps after a few samples
    let mut pc: u16 = 65_531;
    let mut stf = stf0;
    let mut unwrapped = i64::from(stf0);
    let mut seq = 0u64;
    let push = |bytes: &mut Vec<u8>, expected: &mut Vec<Expect>, f: Frame, seq: u64, unwrapped: i64| {
        bytes.extend_from_slice(&mtdata2(&f));
        expected.push(expect(&f, seq, unwrapped));
    };
    for k in 0..6 {
        let mut f = frame(k, pc, stf);
        f.fmt = [Fmt::F32, Fmt::Fp1632, Fmt::F64][k as usize % 3];
        push(&mut bytes, &mut expected, f, seq, unwrapped);
        pc = pc.wrapping_add(1);
        stf = stf.wrapping_add(50);
        unwrapped += 50;
        seq += 1;
    }
    // Two messages lost (counter and clock move on by three steps).
    pc = pc.wrapping_add(2);
    stf = stf.wrapping_add(100);
    unwrapped += 100;
    seq += 2;
    // A bad checksum, a truncated message, then a good one.
    let mut bad = mtdata2(&frame(90, pc, stf));
    let n = bad.len();
    bad[n - 3] ^= 0x40;
    bytes.extend_from_slice(&bad);
    let cut = mtdata2(&frame(91, pc, stf));
    bytes.extend_from_slice(&cut[..cut.len() / 2]);
    let mut clipped = frame(6, pc, stf);
    clipped.status = 0x0800; // ClipGyrX
    push(&mut bytes, &mut expected, clipped, seq, unwrapped);
    // NaN, out of range (20 g), device time backwards: rejected, nothing advances.
    let mut nan = frame(92, pc.wrapping_add(1), stf.wrapping_add(50));
    nan.gyro[1] = f64::NAN;
    bytes.extend_from_slice(&mtdata2(&nan));
    let mut big = frame(93, pc.wrapping_add(1), stf.wrapping_add(50));
    big.accel[0] = 20.0 * 9.80665;
    bytes.extend_from_slice(&mtdata2(&big));
    bytes.extend_from_slice(&mtdata2(&frame(94, pc.wrapping_add(1), stf.wrapping_sub(500))));
    pc = pc.wrapping_add(1);
    stf = stf.wrapping_add(50);
    unwrapped += 50;
    seq += 1;
    // An extended-length message: a 300-byte item the driver does not know, then the data.
    let mut d = vec![0x70, 0x10, 255];
    d.extend(std::iter::repeat_n(0xAB, 255));
    let f = frame(7, pc, stf);
    let m = mtdata2(&f);
    d.extend_from_slice(&m[4..m.len() - 1]);
    bytes.extend_from_slice(&message(0x36, &d));
    expected.push(expect(&f, seq, unwrapped));
    // A device error report and a final good message.
    bytes.extend_from_slice(&message(0x42, &[0x04]));
    pc = pc.wrapping_add(1);
    stf = stf.wrapping_add(50);
    unwrapped += 50;
    seq += 1;
    push(&mut bytes, &mut expected, frame(8, pc, stf), seq, unwrapped);
    let cap1 = env.dir.join("cap1.bin");
    std::fs::write(&cap1, &bytes).unwrap();

    env.spawn(
        "feed1",
        &[
            "feed",
            &cap1.display().to_string(),
            "--pty",
            "--link",
            &link_s,
            "--baud",
            "115200",
            "--wait-reader",
            "--hold",
            "0.5",
        ],
    );
    env.wait_for_path(&link, Duration::from_secs(20));
    env.spawn(
        "imu",
        &["imu", "--source", &format!("xsens:{link_s}:115200"), "--id", "7"],
    );

    let mut got = Vec::new();
    collect(&sub, expected.len(), &mut got);
    assert_eq!(got.len(), expected.len(), "published {got:?}\n{}", env.log("imu"));
    let mut last_host = i64::MIN;
    for (s, e) in got.iter().zip(&expected) {
        assert_eq!(s.stamp.seq, e.seq);
        assert_eq!(s.stamp.source(), StampSource::Receipt);
        assert_eq!(s.stamp.has_device_time, 1);
        assert_eq!(s.stamp.device_ns, e.device_ns, "seq {}", e.seq);
        assert!(s.stamp.host_ns >= last_host, "receipt stamps never go back");
        last_host = s.stamp.host_ns;
        for k in 0..3 {
            assert!(
                (s.gyro_rps[k] - e.gyro[k]).abs() < 1e-12,
                "seq {} gyro {:?} vs {:?}",
                e.seq,
                s.gyro_rps,
                e.gyro
            );
            assert!(
                (s.accel_mps2[k] - e.accel[k]).abs() < 1e-12,
                "seq {} accel {:?} vs {:?}",
                e.seq,
                s.accel_mps2,
                e.accel
            );
        }
        assert!((s.temperature_c - e.temp).abs() < 1e-12);
        assert_eq!(s.flags & IMU_FLAG_SATURATED != 0, e.saturated, "seq {}", e.seq);
        assert_eq!(navsync_shared::reflect::str_of(&s.imu_id), "7");
        // 50 ticks of the 10 kHz clock per sample.
        assert!((s.dt_s - 0.005).abs() < 1e-12, "seq {} dt {}", e.seq, s.dt_s);
    }

    let mut latest = None;
    assert_eq!(
        wait_counter(&hsub, &mut latest, "samples_accepted", expected.len() as u64),
        expected.len() as u64
    );
    let h = latest.unwrap();
    let c = |n: &str| h.counter(n).unwrap_or(u64::MAX);
    assert_eq!(c("samples_dropped"), 2);
    assert_eq!(c("rejected_not_finite"), 1);
    assert_eq!(c("rejected_range"), 1);
    assert_eq!(c("rejected_device_back"), 1);
    // The fake start FA FF 36 in the garbage (its length byte is the next preamble), the
    // corrupted message and the truncated one.
    assert_eq!(c("xbus_bad_checksum"), 3);
    assert_eq!(c("xbus_device_errors"), 1);
    assert_eq!(c("samples_at_range"), 0);

    // --- the port vanishes: the feeder exits (hold ends) and removes the link ------------
    let t0 = Instant::now();
    while link.exists() && t0.elapsed() < Duration::from_secs(20) {
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(!link.exists(), "feeder did not exit");
    assert!(wait_counter(&hsub, &mut latest, "device_reopens", 1) >= 1);
    assert!(wait_counter(&hsub, &mut latest, "device_open_failures", 1) >= 1);

    // --- and comes back on the same link with the counters 100 samples later ------------
    let mut bytes = Vec::new();
    let mut expected2 = Vec::new();
    pc = pc.wrapping_add(100);
    stf = stf.wrapping_add(5000);
    unwrapped += 5000;
    seq += 100;
    for k in 0..4 {
        push(&mut bytes, &mut expected2, frame(20 + k, pc, stf), seq, unwrapped);
        pc = pc.wrapping_add(1);
        stf = stf.wrapping_add(50);
        unwrapped += 50;
        seq += 1;
    }
    let cap2 = env.dir.join("cap2.bin");
    std::fs::write(&cap2, &bytes).unwrap();
    env.spawn(
        "feed2",
        &[
            "feed",
            &cap2.display().to_string(),
            "--pty",
            "--link",
            &link_s,
            "--wait-reader",
            "--hold",
            "30",
        ],
    );
    let mut got2 = Vec::new();
    collect(&sub, expected2.len(), &mut got2);
    assert_eq!(
        got2.len(),
        expected2.len(),
        "after the port returned: {got2:?}\n{}",
        env.log("imu")
    );
    for (s, e) in got2.iter().zip(&expected2) {
        assert_eq!(s.stamp.seq, e.seq);
        assert_eq!(s.stamp.device_ns, e.device_ns);
    }
    let h = latest.unwrap();
    assert!(wait_counter(&hsub, &mut latest, "samples_dropped", 101) >= 101, "{h:?}");
    // Logged once per kind, not once per occurrence.
    let log = env.log("imu");
    let firsts = log.matches("first occurrence").count();
    assert!((3..=12).contains(&firsts), "{firsts} first-occurrence lines:\n{log}");
    assert!(log.lines().count() < 60, "log flood:\n{log}");
    drop((sub, hsub, node));
    env.finish();
}
