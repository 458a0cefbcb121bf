//! `navsync imu --source iio:…` as a real process on a fake Linux IIO device built here: a
//! sysfs tree of plain files (`scan_elements`, scales, `buffer/`, `sampling_frequency`,
//! `current_timestamp_clock`) and a FIFO standing in for `/dev/iio:device0`. The test writes
//! binary records the way the kernel lays them out and checks what is published: SI units
//! from the scales and offsets, the axis map, the kernel time stamps, sequence gaps inferred
//! from the stamps, rejections, the sysfs setup the driver did, and the device vanishing
//! (node deleted, reads end) and coming back.

use std::fs::File;
use std::io::Write;
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use navsync_shared::ipc::Subscriber;
use navsync_shared::samples::*;
use navsync_shared::services;
use navsync_tests::TestEnv;

const GYRO_SCALE: f64 = 0.000_001_065_264; // rad/s per LSB
const ACCEL_SCALE: f64 = 0.019_154; // m/s² per LSB of the 12-bit value
const TEMP_SCALE: f64 = 125.0; // m°C per LSB
const TEMP_OFFSET: f64 = 2_000.0; // LSB
const PERIOD_NS: i64 = 5_000_000; // 200 Hz

fn write(path: &Path, text: &str) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, format!("{text}\n")).unwrap();
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_default().trim().to_string()
}

fn mkfifo(path: &Path) {
    let c = std::ffi::CString::new(path.as_os_str().as_bytes()).unwrap();
    // SAFETY: valid NUL-terminated path.
    assert_eq!(
        unsafe { libc::mkfifo(c.as_ptr(), 0o600) },
        0,
        "mkfifo {}",
        path.display()
    );
}

/// The fake device: temperature, 3 × 32-bit big-endian gyro, 3 × 12-bit accel (shifted by 4
/// in 16 bits), a magnetometer the driver must switch off, and the timestamp.
fn build_device(root: &Path) -> (PathBuf, PathBuf) {
    let dev = root.join("sys/iio:device0");
    write(&dev.join("name"), "fake-imu");
    write(&dev.join("sampling_frequency"), "100");
    write(&dev.join("current_timestamp_clock"), "realtime");
    write(&dev.join("in_anglvel_scale"), &format!("{GYRO_SCALE}"));
    write(&dev.join("in_accel_scale"), &format!("{ACCEL_SCALE}"));
    write(&dev.join("in_temp_scale"), &format!("{TEMP_SCALE}"));
    write(&dev.join("in_temp_offset"), &format!("{TEMP_OFFSET}"));
    write(&dev.join("in_magn_scale"), "0.1");
    write(&dev.join("buffer/enable"), "0");
    write(&dev.join("buffer/length"), "2");
    write(&dev.join("buffer/watermark"), "16");
    let se = dev.join("scan_elements");
    let chans: [(&str, u32, &str, &str); 9] = [
        ("temp", 0, "le:s16/16>>0", "0"),
        ("anglvel_x", 1, "be:s32/32>>0", "0"),
        ("anglvel_y", 2, "be:s32/32>>0", "0"),
        ("anglvel_z", 3, "be:s32/32>>0", "0"),
        ("accel_x", 4, "le:s12/16>>4", "0"),
        ("accel_y", 5, "le:s12/16>>4", "0"),
        ("accel_z", 6, "le:s12/16>>4", "0"),
        ("magn_x", 7, "le:s16/16>>0", "1"),
        ("timestamp", 8, "le:s64/64>>0", "0"),
    ];
    for (name, index, ty, en) in chans {
        write(&se.join(format!("in_{name}_en")), en);
        write(&se.join(format!("in_{name}_index")), &index.to_string());
        write(&se.join(format!("in_{name}_type")), ty);
    }
    let dev_root = root.join("dev");
    std::fs::create_dir_all(&dev_root).unwrap();
    mkfifo(&dev_root.join("iio:device0"));
    (root.join("sys"), dev_root)
}

/// One record: temp at 0, gyro at 4/8/12, accel at 16/18/20, (magn disabled), pad, ts at 24.
fn record(temp: i16, gyro: [i32; 3], accel: [i16; 3], ts: i64) -> [u8; 32] {
    let mut r = [0u8; 32];
    r[0..2].copy_from_slice(&temp.to_le_bytes());
    for (k, g) in gyro.iter().enumerate() {
        r[4 + 4 * k..8 + 4 * k].copy_from_slice(&g.to_be_bytes());
    }
    for (k, a) in accel.iter().enumerate() {
        // 12 bits in the top of 16, junk in the low nibble.
        let w = ((*a as u16) << 4) | 0x9;
        r[16 + 2 * k..18 + 2 * k].copy_from_slice(&w.to_le_bytes());
    }
    r[24..32].copy_from_slice(&ts.to_le_bytes());
    r
}

/// Opens the FIFO for writing once the driver holds it open for reading.
fn open_writer(path: &Path) -> File {
    let t0 = Instant::now();
    loop {
        match std::fs::OpenOptions::new()
            .write(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(path)
        {
            Ok(f) => {
                // Blocking writes from here on.
                // SAFETY: clearing O_NONBLOCK on our own descriptor.
                unsafe { libc::fcntl(std::os::fd::AsRawFd::as_raw_fd(&f), libc::F_SETFL, 0) };
                return f;
            }
            Err(e) => {
                assert!(
                    t0.elapsed() < Duration::from_secs(30),
                    "no reader on {}: {e}",
                    path.display()
                );
                std::thread::sleep(Duration::from_millis(20));
            }
        }
    }
}

fn collect(sub: &Subscriber<ImuSample>, n: usize, got: &mut Vec<ImuSample>) {
    let t0 = Instant::now();
    while got.len() < n && t0.elapsed() < Duration::from_secs(30) {
        while let Some(s) = sub.receive().unwrap() {
            got.push(s);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn counter(sub: &Subscriber<Health>, latest: &mut Option<Health>, name: &str, min: u64) -> u64 {
    let t0 = Instant::now();
    loop {
        while let Some(h) = sub.receive().unwrap() {
            *latest = Some(h);
        }
        let v = latest.as_ref().and_then(|h| h.counter(name)).unwrap_or(0);
        if v >= min || t0.elapsed() > Duration::from_secs(20) {
            return v;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

struct Rec {
    raw: [u8; 32],
    temp: i16,
    gyro: [i32; 3],
    accel: [i16; 3],
    ts: i64,
}

fn rec(k: i64, ts: i64) -> Rec {
    let temp = (100 + k) as i16;
    let gyro = [1000 * k as i32, -20_000, 300_000 - k as i32];
    let mut accel = [(k % 50) as i16, -7, -512];
    if k == 17 {
        accel[0] = 2047; // full scale of 12 bits: flagged saturated
    }
    Rec {
        raw: record(temp, gyro, accel, ts),
        temp,
        gyro,
        accel,
        ts,
    }
}

fn check(s: &ImuSample, r: &Rec, seq: u64) {
    assert_eq!(s.stamp.seq, seq, "ts {}", r.ts);
    assert_eq!(s.stamp.host_ns, r.ts, "the kernel time stamp is the host stamp");
    assert_eq!(s.stamp.source(), StampSource::KernelEvent);
    assert_eq!(s.stamp.has_device_time, 0);
    // Default axis map x,-y,-z.
    let g = r.gyro.map(|v| f64::from(v) * GYRO_SCALE);
    let a = r.accel.map(|v| f64::from(v) * ACCEL_SCALE);
    let want_g = [g[0], -g[1], -g[2]];
    let want_a = [a[0], -a[1], -a[2]];
    for k in 0..3 {
        assert!(
            (s.gyro_rps[k] - want_g[k]).abs() < 1e-15,
            "{:?} vs {want_g:?}",
            s.gyro_rps
        );
        assert!(
            (s.accel_mps2[k] - want_a[k]).abs() < 1e-12,
            "{:?} vs {want_a:?}",
            s.accel_mps2
        );
    }
    let t = (f64::from(r.temp) + TEMP_OFFSET) * TEMP_SCALE / 1000.0;
    assert!((s.temperature_c - t).abs() < 1e-12, "{} vs {t}", s.temperature_c);
    assert_eq!(s.flags & IMU_FLAG_SATURATED != 0, r.accel[0] == 2047);
    assert!((s.dt_s - 0.005).abs() < 1e-12);
}

#[test]
fn iio_driver_on_a_fake_device_tree() {
    let mut env = TestEnv::new("iio");
    let (sys, dev_root) = build_device(&env.dir);
    let devdir = sys.join("iio:device0");
    let fifo = dev_root.join("iio:device0");
    let node = env.node("observer");
    let sub = node.subscriber::<ImuSample>(&services::imu_sample("3")).unwrap();
    let hsub = node.subscriber::<Health>(&services::health("imu-3")).unwrap();
    env.spawn(
        "imu",
        &[
            "imu",
            "--source",
            "iio:fake-imu",
            "--id",
            "3",
            "--sysfs-root",
            &sys.display().to_string(),
            "--dev-root",
            &dev_root.display().to_string(),
            "--rate",
            "200",
            "--buffer-length",
            "256",
        ],
    );

    // Batch 1: records 0..30 with records 10, 11, 12 lost (overflow), one stamp going back,
    // written in pieces that split records.
    let mut w = open_writer(&fifo);
    // The driver set the device up before opening the node.
    assert_eq!(read(&devdir.join("current_timestamp_clock")), "monotonic");
    assert_eq!(
        read(&devdir.join("sampling_frequency")).parse::<f64>().ok(),
        Some(200.0)
    );
    assert_eq!(read(&devdir.join("buffer/length")), "256");
    assert_eq!(read(&devdir.join("buffer/watermark")), "1");
    assert_eq!(read(&devdir.join("buffer/enable")), "1");
    assert_eq!(
        read(&devdir.join("scan_elements/in_magn_x_en")),
        "0",
        "unused channels off"
    );
    for ch in [
        "temp",
        "anglvel_x",
        "anglvel_y",
        "anglvel_z",
        "accel_x",
        "accel_y",
        "accel_z",
        "timestamp",
    ] {
        assert_eq!(read(&devdir.join(format!("scan_elements/in_{ch}_en"))), "1", "{ch}");
    }
    // Kernel stamps are CLOCK_MONOTONIC and lie before the read that returns them.
    let t0_ns = navsync_shared::time::monotonic_now_ns() - 5_000_000_000;
    let mut expected: Vec<(Rec, u64)> = Vec::new();
    let mut bytes = Vec::new();
    for k in 0..30i64 {
        if (10..13).contains(&k) {
            continue;
        }
        let r = rec(k, t0_ns + k * PERIOD_NS + (k % 3) * 40_000);
        bytes.extend_from_slice(&r.raw);
        expected.push((r, k as u64));
        if k == 20 {
            // A record stamped before its predecessor: rejected.
            bytes.extend_from_slice(&rec(99, t0_ns + 15 * PERIOD_NS).raw);
        }
        if k == 25 {
            // A corrupt stamp far in the future: dropped before the checks.
            bytes.extend_from_slice(&rec(98, t0_ns + 1_000_000 * PERIOD_NS).raw);
        }
    }
    for piece in bytes.chunks(50) {
        w.write_all(piece).unwrap();
        w.flush().unwrap();
        std::thread::sleep(Duration::from_millis(2));
    }
    let mut got = Vec::new();
    collect(&sub, expected.len(), &mut got);
    assert_eq!(got.len(), expected.len(), "{}", env.log("imu"));
    for (s, (r, seq)) in got.iter().zip(&expected) {
        check(s, r, *seq);
    }
    let mut latest = None;
    assert_eq!(
        counter(&hsub, &mut latest, "samples_accepted", expected.len() as u64),
        expected.len() as u64
    );
    let h = latest.unwrap();
    assert_eq!(h.counter("samples_dropped"), Some(3));
    assert_eq!(h.counter("rejected_host_back"), Some(1));
    assert_eq!(h.counter("iio_bad_stamps"), Some(1));
    assert_eq!(h.counter("samples_at_range"), Some(0), "no range set for IIO");
    assert!(
        h.counter("iio_short_reads").unwrap_or(0) >= 1,
        "pieces split records: {h:?}"
    );

    // The device vanishes: its node is deleted and the stream ends.
    std::fs::remove_file(&fifo).unwrap();
    drop(w);
    assert!(
        counter(&hsub, &mut latest, "device_open_failures", 1) >= 1,
        "{}",
        env.log("imu")
    );
    assert!(latest.as_ref().and_then(|h| h.counter("device_reopens")).unwrap_or(0) >= 1);
    // It comes back one second later in its own time.
    mkfifo(&fifo);
    let mut w = open_writer(&fifo);
    assert_eq!(read(&devdir.join("buffer/enable")), "1", "set up again");
    let mut expected2 = Vec::new();
    for k in 230..240i64 {
        let r = rec(k, t0_ns + k * PERIOD_NS);
        w.write_all(&r.raw).unwrap();
        expected2.push((r, k as u64));
    }
    w.flush().unwrap();
    let mut got2 = Vec::new();
    collect(&sub, expected2.len(), &mut got2);
    assert_eq!(got2.len(), expected2.len(), "{}", env.log("imu"));
    for (s, (r, seq)) in got2.iter().zip(&expected2) {
        check(s, r, *seq);
    }
    assert_eq!(
        counter(&hsub, &mut latest, "samples_dropped", 203),
        203,
        "200 records missed while away"
    );

    // Stopping the driver stops the capture.
    env.signal("imu", libc::SIGTERM);
    let t0 = Instant::now();
    while read(&devdir.join("buffer/enable")) != "0" && t0.elapsed() < Duration::from_secs(20) {
        std::thread::sleep(Duration::from_millis(20));
    }
    assert_eq!(read(&devdir.join("buffer/enable")), "0", "buffer disabled on exit");
    drop(w);
    drop((sub, hsub, node));
    env.finish();
}

/// A split IMU: the gyroscope and the accelerometer as two devices with a buffer each (as
/// `inv_icm42600` and `st_lsm6dsx` register them), joined by the driver by kernel stamp.
#[test]
fn a_split_imu_is_joined_by_stamp() {
    let mut env = TestEnv::new("iiosplit");
    let sys = env.dir.join("sys");
    let dev_root = env.dir.join("dev");
    std::fs::create_dir_all(&dev_root).unwrap();
    for (n, name, kind) in [(1, "fake-gyro", "anglvel"), (2, "fake-accel", "accel")] {
        let dev = sys.join(format!("iio:device{n}"));
        write(&dev.join("name"), name);
        write(&dev.join("sampling_frequency"), "200");
        write(&dev.join("current_timestamp_clock"), "realtime");
        write(
            &dev.join(format!("in_{kind}_scale")),
            if kind == "accel" { "0.01" } else { "0.001" },
        );
        write(&dev.join("in_temp_scale"), "1000");
        write(&dev.join("buffer/enable"), "0");
        write(&dev.join("buffer/length"), "1");
        let se = dev.join("scan_elements");
        let chans = [
            (format!("{kind}_x"), 0),
            (format!("{kind}_y"), 1),
            (format!("{kind}_z"), 2),
            ("temp".to_string(), 3),
            ("timestamp".to_string(), 4),
        ];
        for (ch, index) in chans {
            let ty = if ch == "timestamp" {
                "le:s64/64>>0"
            } else {
                "le:s16/16>>0"
            };
            write(&se.join(format!("in_{ch}_en")), "0");
            write(&se.join(format!("in_{ch}_index")), &index.to_string());
            write(&se.join(format!("in_{ch}_type")), ty);
        }
        mkfifo(&dev_root.join(format!("iio:device{n}")));
    }
    let node = env.node("observer");
    let sub = node.subscriber::<ImuSample>(&services::imu_sample("5")).unwrap();
    let hsub = node.subscriber::<Health>(&services::health("imu-5")).unwrap();
    env.spawn(
        "imu",
        &[
            "imu",
            "--source",
            "iio:fake-gyro+fake-accel",
            "--id",
            "5",
            "--sysfs-root",
            &sys.display().to_string(),
            "--dev-root",
            &dev_root.display().to_string(),
            "--axes",
            "x,y,z",
        ],
    );
    let mut wg = open_writer(&dev_root.join("iio:device1"));
    let mut wa = open_writer(&dev_root.join("iio:device2"));
    // Records: three s16 values, s16 temperature, padding to 8, s64 stamp.
    let rec = |v: [i16; 3], temp: i16, ts: i64| {
        let mut r = [0u8; 16];
        for (k, x) in v.iter().enumerate() {
            r[2 * k..2 * k + 2].copy_from_slice(&x.to_le_bytes());
        }
        r[6..8].copy_from_slice(&temp.to_le_bytes());
        r[8..16].copy_from_slice(&ts.to_le_bytes());
        r
    };
    let t0_ns = navsync_shared::time::monotonic_now_ns() - 5_000_000_000;
    let mut gyro_bytes = Vec::new();
    let mut accel_bytes = Vec::new();
    for k in 0..20i64 {
        let ts = t0_ns + k * PERIOD_NS;
        gyro_bytes.extend_from_slice(&rec([k as i16, 2, 3], 25, ts));
        // The accelerometer's record 7 is lost; its stamps lag the gyroscope's by 30 µs.
        if k != 7 {
            accel_bytes.extend_from_slice(&rec([100 + k as i16, -200, -981], 26, ts + 30_000));
        }
    }
    wg.write_all(&gyro_bytes).unwrap();
    wa.write_all(&accel_bytes).unwrap();
    let mut got = Vec::new();
    collect(&sub, 19, &mut got);
    assert_eq!(got.len(), 19, "{}", env.log("imu"));
    let ks: Vec<i64> = (0..20).filter(|k| *k != 7).collect();
    for (s, k) in got.iter().zip(ks) {
        assert_eq!(s.stamp.host_ns, t0_ns + k * PERIOD_NS, "the gyroscope's stamp");
        assert_eq!(s.stamp.seq, k as u64);
        assert_eq!(s.stamp.source(), StampSource::KernelEvent);
        assert!((s.gyro_rps[0] - 0.001 * k as f64).abs() < 1e-12);
        assert!((s.accel_mps2[0] - 0.01 * (100 + k) as f64).abs() < 1e-12);
        assert!((s.accel_mps2[2] + 9.81).abs() < 1e-12);
        assert_eq!(s.temperature_c, 25.0, "the gyroscope's temperature");
    }
    let mut latest = None;
    assert_eq!(counter(&hsub, &mut latest, "iio_pairs", 19), 19);
    assert_eq!(counter(&hsub, &mut latest, "samples_dropped", 1), 1);
    assert!(counter(&hsub, &mut latest, "iio_unpaired", 1) >= 1);
    for n in [1, 2] {
        assert_eq!(read(&sys.join(format!("iio:device{n}/buffer/enable"))), "1");
    }
    drop((wg, wa, sub, hsub, node));
    env.finish();
}
