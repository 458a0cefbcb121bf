//! Seed inputs for the fuzz targets, made with the project's own encoders and test data:
//!
//! - `nmea_epoch/`: bursts of the simulated receiver (`sim::nmea::write_burst`): with and
//!   without a fix, across midnight, 1 and 10 Hz, GP and GN talkers; every NMEA sentence
//!   quoted in the project's sources and tests;
//! - `xsens_frame/`: MTData2 messages (`encode_mtdata2`) in every real format, the
//!   simulator's Xsens messages for the IMU samples of `tests/data/record_drive.mcap`,
//!   streams with noise and other messages;
//! - `iio_record/`, `iio_scan/`: device descriptions (the layout of `tests/tests/imu_iio.rs`
//!   and the type forms of the unit tests) with records encoded for them;
//! - `mcap_reader/`: small recordings (`SampleRecorder`) of the first samples of
//!   `tests/data/record_drive.mcap`, closed and cut short.
//!
//! Usage: `navsync-fuzz-seeds REPO_ROOT OUT_DIR` (writes `OUT_DIR/<target>/<name>`).

use std::fs;
use std::io::Cursor;
use std::path::{Path, PathBuf};

use navsync_drivers::imu::iio::record::layout;
use navsync_drivers::imu::iio::scan::{Endian, Repr, ScanElement, ScanType};
use navsync_sim::xsens_imus::SimXsensImu;
use navsync_drivers::imu::xsens::frame::{MtData2, RealFormat, STATUS_CLIP_GYR, encode_mtdata2};
use navsync_sim::nmea::{EpochReport, FixReport, frame, write_burst};
use navsync_recording::{RecordingOptions, SampleReader, SampleRecorder};
use navsync_shared::samples::AnySample;

struct Out(PathBuf);

impl Out {
    fn put(&self, target: &str, name: &str, bytes: &[u8]) {
        let dir = self.0.join(target);
        fs::create_dir_all(&dir).expect("create the seed directory");
        fs::write(dir.join(name), bytes).expect("write a seed");
    }
}

fn nmea(out: &Out, repo: &Path) {
    let epoch0 = 1_700_000_000_000_000_000i64; // 2023-11-14T22:13:20Z
    let fix = |k: i64| FixReport {
        lat_deg: 48.137154 + k as f64 * 1e-5,
        lon_deg: -11.576124 - k as f64 * 2e-5,
        alt_msl_m: 519.25,
        geoid_sep_m: 47.75,
        vel_n_mps: 3.0,
        vel_e_mps: -4.0,
        vel_d_mps: 0.5,
    };
    let report = |utc_ns: i64, fix: Option<FixReport>| EpochReport {
        utc_ns,
        fix,
        sats_used: 9,
        hdop: 0.9,
        vdop: 1.4,
        sigma_lat_lon_alt_m: [1.5, 1.25, 3.0],
    };
    let mut cases: Vec<(&str, Vec<u8>)> = Vec::new();
    for (name, talker, period_ns, start, n, outage) in [
        ("sim_gp_1hz", "GP", 1_000_000_000, epoch0, 8, None),
        ("sim_gn_10hz", "GN", 100_000_000, epoch0, 12, None),
        ("sim_outage", "GN", 1_000_000_000, epoch0, 8, Some(3..6)),
        ("sim_midnight", "GP", 1_000_000_000, 1_704_067_196_000_000_000, 8, None),
        ("sim_no_fix", "GP", 1_000_000_000, epoch0, 4, Some(0..4)),
    ] {
        let mut bytes = Vec::new();
        for k in 0..n {
            let f = (!outage.as_ref().is_some_and(|o: &std::ops::Range<i64>| o.contains(&k))).then(|| fix(k));
            write_burst(talker, &report(start + k * period_ns, f), &mut bytes);
        }
        cases.push((name, bytes));
    }
    for (name, bytes) in &cases {
        out.put("nmea_epoch", name, bytes);
    }
    // The simulated u-blox receiver (NAV-PVT, NAV-EOE, TIM-TP), alone and with NMEA between
    // its epochs, as on a port configured for both.
    let extras = navsync_sim::ubx::UbxExtras {
        h_acc_m: 0.9,
        v_acc_m: 1.4,
        s_acc_mps: 0.08,
        next_pulse_q_err_ps: -4331,
    };
    let (mut ubx, mut mixed) = (Vec::new(), Vec::new());
    for k in 0..8 {
        let r = report(epoch0 + k * 1_000_000_000, (k != 4).then(|| fix(k)));
        navsync_sim::ubx::write_epoch(&r, &extras, &mut ubx);
        navsync_sim::ubx::write_epoch(&r, &extras, &mut mixed);
        write_burst("GN", &r, &mut mixed);
    }
    out.put("ubx_stream", "sim_ubx_1hz", &ubx);
    out.put("ubx_stream", "sim_ubx_and_nmea", &mixed);
    out.put("nmea_epoch", "repo_sentences", &quoted_sentences(repo));
}

/// Every NMEA sentence quoted in the project's Rust sources and tests, in source order:
/// complete ones (`$…*hh`) as they are, bodies (`GPGGA,…`, framed by the tests' helpers) with
/// their checksum added.
fn quoted_sentences(repo: &Path) -> Vec<u8> {
    fn walk(dir: &Path, files: &mut Vec<PathBuf>) {
        let Ok(entries) = fs::read_dir(dir) else { return };
        let mut entries: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
        entries.sort();
        for p in entries {
            if p.is_dir() {
                walk(&p, files);
            } else if p.extension().is_some_and(|e| e == "rs") {
                files.push(p);
            }
        }
    }
    let mut files = Vec::new();
    for d in ["drivers", "daemon", "shared", "tests"] {
        walk(&repo.join(d), &mut files);
    }
    let is_address = |a: &str| (5..=6).contains(&a.len()) && a.bytes().all(|b| b.is_ascii_uppercase());
    let mut out = Vec::new();
    for f in files {
        let Ok(text) = fs::read_to_string(&f) else { continue };
        for lit in text.split('"').skip(1).step_by(2) {
            let lit = lit.trim_end_matches("\\r\\n");
            if lit.contains(['{', '\\']) || !lit.bytes().all(|b| (0x20..=0x7e).contains(&b)) {
                continue;
            }
            let body = lit.trim_start_matches(['$', '!']);
            let Some((address, _)) = body.split_once(',') else {
                continue;
            };
            if !is_address(address) {
                continue;
            }
            if lit.starts_with(['$', '!']) && lit.contains('*') {
                out.extend_from_slice(lit.as_bytes());
                out.extend_from_slice(b"\r\n");
            } else if !lit.starts_with(['$', '!']) {
                frame(body, &mut out);
            }
        }
    }
    out
}

fn xsens(out: &Out, imu_samples: &[navsync_shared::samples::ImuSample]) {
    let full = MtData2 {
        sample_time_fine: Some(4_294_967_000),
        packet_counter: Some(65_535),
        acceleration: Some([0.25, -1.5, 9.80665]),
        rate_of_turn: Some([0.001, -0.5, 3.25]),
        temperature_c: Some(31.5),
        status_word: Some(STATUS_CLIP_GYR[2]),
        ..Default::default()
    };
    let increments = MtData2 {
        sample_time_fine: Some(1234),
        packet_counter: Some(7),
        delta_v: Some([0.0025, -0.015, 0.0980665]),
        delta_q: Some([0.999_999_5, 0.0005, -0.0002, 0.0001]),
        ..Default::default()
    };
    let mut msg = Vec::new();
    for (fname, format) in [
        ("f32", RealFormat::Float32),
        ("fp1220", RealFormat::Fp1220),
        ("fp1632", RealFormat::Fp1632),
        ("f64", RealFormat::Float64),
    ] {
        for (mname, m) in [("full", &full), ("increments", &increments)] {
            encode_mtdata2(m, format, &mut msg);
            out.put("xsens_frame", &format!("mtdata2_{mname}_{fname}"), &msg);
        }
    }
    // The simulator's messages for recorded IMU samples, as one stream.
    let mut imu = SimXsensImu::new(0, 0.0, 100.0);
    let mut stream = Vec::new();
    for s in imu_samples.iter().take(20) {
        stream.extend_from_slice(imu.message(s));
    }
    out.put("xsens_frame", "sim_record_drive_stream", &stream);
    // Noise, false starts, a GoToConfig, an extended-length message, then data.
    let mut noisy = vec![0x00, 0xFA, 0x12, 0x55, 0xFA, 0xFF, 0x36, 0xFA, 0xFF, 0x30, 0x00, 0xD1];
    let mut ext = vec![0xFA, 0xFF, 0x91, 0xFF, 0x01, 0x2C];
    ext.extend((0..300u32).map(|i| (i * 7) as u8));
    let sum = ext[1..].iter().fold(0u8, |s, &x| s.wrapping_add(x));
    ext.push(sum.wrapping_neg());
    noisy.extend_from_slice(&ext);
    encode_mtdata2(&full, RealFormat::Float32, &mut msg);
    noisy.extend_from_slice(&msg);
    noisy.extend_from_slice(&msg[..msg.len() / 2]);
    encode_mtdata2(&increments, RealFormat::Fp1632, &mut msg);
    noisy.extend_from_slice(&msg);
    out.put("xsens_frame", "noisy_stream", &noisy);
}

/// One IIO device description: (name, index, type, scale, offset).
type Device = &'static [(&'static str, u32, &'static str, &'static str, &'static str)];

const DEVICES: &[(&str, Device)] = &[
    (
        // tests/tests/imu_iio.rs: mixed byte orders, a 12-bit shifted accelerometer, a
        // channel the driver ignores, the timestamp.
        "imu_iio_test",
        &[
            ("temp", 0, "le:s16/16>>0", "1000", "-500"),
            ("anglvel_x", 1, "be:s32/32>>0", "0.0000010652", "0"),
            ("anglvel_y", 2, "be:s32/32>>0", "0.0000010652", "0"),
            ("anglvel_z", 3, "be:s32/32>>0", "0.0000010652", "0"),
            ("accel_x", 4, "le:s12/16>>4", "0.0023942", "0"),
            ("accel_y", 5, "le:s12/16>>4", "0.0023942", "0"),
            ("accel_z", 6, "le:s12/16>>4", "0.0023942", "0"),
            ("magn_x", 7, "le:s16/16>>0", "0.1", "0"),
            ("timestamp", 8, "le:s64/64>>0", "1", "0"),
        ],
    ),
    (
        "adis_like",
        &[
            ("anglvel_x", 0, "be:s32/32>>0", "0.000000006658", "0"),
            ("anglvel_y", 1, "be:s32/32>>0", "0.000000006658", "0"),
            ("anglvel_z", 2, "be:s32/32>>0", "0.000000006658", "0"),
            ("accel_x", 3, "be:s32/32>>0", "0.000000036", "0"),
            ("accel_y", 4, "be:s32/32>>0", "0.000000036", "0"),
            ("accel_z", 5, "be:s32/32>>0", "0.000000036", "0"),
            ("temp0", 6, "be:s16/16>>0", "100", "0"),
            ("timestamp", 7, "le:s64/64>>0", "1", "0"),
        ],
    ),
    (
        "gyro_only_u16",
        &[
            ("anglvel_x", 2, "le:u16/16>>0", "0.001", "-32768"),
            ("anglvel_y", 0, "le:u16/16>>0", "0.001", "-32768"),
            ("anglvel_z", 1, "le:u16/16>>0", "0.001", "-32768"),
        ],
    ),
    (
        "floats_and_repeat",
        &[
            ("accel_x", 0, "le:f32/32>>0", "1", "0"),
            ("accel_y", 1, "le:f32/32>>0", "1", "0"),
            ("accel_z", 2, "be:f64/64>>0", "1", "0"),
            ("deltaangl", 3, "le:u10/16X3>>2", "1", "0"),
            ("timestamp", 4, "be:s48/64", "1", "0"),
        ],
    ),
    (
        "bytes_8bit",
        &[
            ("accel_x", 0, "le:s8/8>>0", "0.15", "0"),
            ("accel_y", 1, "be:u7/8>>1", "0.15", "0"),
            ("accel_z", 2, "le:s4/8>>4", "0.15", "0"),
            ("temp", 3, "le:u8/8", "1", "0"),
        ],
    ),
];

/// Writes `v` into element 0 of the slot (integers: shifted into place, truncated to `bits`).
fn put_value(record: &mut [u8], offset: usize, ty: &ScanType, v: f64) {
    let n = ty.element_bytes();
    let word: u64 = match ty.repr {
        Repr::Float if n == 4 => u64::from((v as f32).to_bits()),
        Repr::Float => v.to_bits(),
        _ => {
            let bits = u32::from(ty.bits);
            let mask = if bits >= 64 { u64::MAX } else { (1u64 << bits) - 1 };
            ((v as i64 as u64) & mask) << ty.shift
        }
    };
    let bytes = word.to_be_bytes();
    let be = &bytes[8 - n..];
    let slot = &mut record[offset..offset + n];
    match ty.endian {
        Endian::Big => slot.copy_from_slice(be),
        Endian::Little => slot.iter_mut().zip(be.iter().rev()).for_each(|(d, s)| *d = *s),
    }
}

fn iio(out: &Out) {
    for (name, device) in DEVICES {
        let mut text = format!("# {name}\n");
        let mut elements = Vec::new();
        for (ch, index, ty, scale, offset) in device.iter() {
            text.push_str(&format!("{ch} {index} {ty} {scale} {offset}\n"));
            elements.push(ScanElement {
                name: ch.to_string(),
                index: *index,
                ty: ty.parse().expect("a valid type"),
            });
        }
        out.put("iio_scan", name, text.as_bytes());
        let lay = layout(&elements);
        let mut bytes = text.into_bytes();
        bytes.push(b'\n');
        for k in 0..4i64 {
            let mut record = vec![0u8; lay.record_bytes];
            for (i, (ch, slot)) in lay.slots.iter().enumerate() {
                let v = match ch.as_str() {
                    "timestamp" => 1_000_000_000.0 + k as f64 * 2_500_000.0,
                    // Near full scale in the last record.
                    _ if k == 3 => f64::from(i32::MAX),
                    _ => (k * 100 - 150 + i as i64 * 17) as f64,
                };
                put_value(&mut record, slot.offset, &slot.ty, v);
            }
            bytes.extend_from_slice(&record);
        }
        out.put("iio_record", name, &bytes);
    }
    // The type forms of the unit tests, one per line (valid and rejected).
    let forms = "le:s16/16>>0\nbe:s12/16>>4\nle:u10/16X3>>2\nbe:s48/64\nle:f32/32>>0\ns16/16>>0\n\
                 me:s16/16>>0\nle:x16/16>>0\nle:s16/12>>0\nle:s16/16>>4\nle:s0/16\nle:f16/16\nle:s16-16\n";
    out.put("iio_scan", "unit_test_types", forms.as_bytes());
}

fn mcap(out: &Out, samples: &[(String, AnySample, u64, u64)], drive: &[u8]) {
    let record = |n: usize, chunk: usize, flush_each: bool| -> Vec<u8> {
        let options = RecordingOptions {
            chunk_size: chunk,
            ..RecordingOptions::default()
        };
        let mut r = SampleRecorder::new(Cursor::new(Vec::new()), Path::new("seed.mcap"), options).expect("a recorder");
        for (service, s, log, publish) in samples.iter().take(n) {
            r.write(service, s, *log, *publish).expect("write a sample");
            if flush_each {
                r.flush_chunk().expect("flush a chunk");
            }
        }
        r.finish().expect("close the recording").into_inner()
    };
    let small = record(24, 2048, false);
    out.put("mcap_reader", "drive_24_samples", &small);
    out.put("mcap_reader", "drive_24_samples_cut", &small[..small.len() * 3 / 5]);
    let per_message = record(6, 1 << 20, true);
    out.put("mcap_reader", "drive_6_samples_chunk_each", &per_message);
    out.put("mcap_reader", "empty_recording", &record(0, 2048, false));
    // The same samples as JSON with uncompressed chunks (what navsync wrote before CDR).
    let mut r = SampleRecorder::new(
        Cursor::new(Vec::new()),
        Path::new("seed.mcap"),
        RecordingOptions {
            encoding: navsync_recording::Encoding::Json,
            compression: navsync_recording::ChunkCompression::None,
            chunk_size: 2048,
            ros_std: None,
        },
    )
    .expect("a recorder");
    for (service, s, log, publish) in samples.iter().take(24) {
        r.write(service, s, *log, *publish).expect("write a sample");
    }
    out.put("mcap_reader", "drive_24_samples_json", &r.finish().expect("close").into_inner());
    // The head of the recording the tests use: a file whose writer died.
    out.put("mcap_reader", "record_drive_head", &drive[..drive.len().min(6000)]);
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let [_, repo, dir] = &args[..] else {
        eprintln!("usage: navsync-fuzz-seeds REPO_ROOT OUT_DIR");
        std::process::exit(2);
    };
    let out = Out(PathBuf::from(dir));
    let drive_path = Path::new(repo).join("tests/data/record_drive.mcap");
    let drive = fs::read(&drive_path).expect("tests/data/record_drive.mcap");
    let mut reader = SampleReader::open(&drive_path).expect("open the test recording");
    let mut samples = Vec::new();
    let mut imu_samples = Vec::new();
    let mut services = std::collections::BTreeSet::new();
    while let Some(s) = reader.next_sample().expect("read the test recording") {
        if let AnySample::Imu(i) = s.sample {
            imu_samples.push(i);
        }
        // The first samples of every service, so that small files hold every channel type.
        if services.insert(s.service.to_string()) || samples.len() < 16 {
            samples.push((s.service.to_string(), s.sample, s.log_time, s.publish_time));
        }
    }
    nmea(&out, Path::new(repo));
    xsens(&out, &imu_samples);
    iio(&out);
    mcap(&out, &samples, &drive);
}
