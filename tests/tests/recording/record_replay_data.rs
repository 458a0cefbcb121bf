//! The recording checked into `tests/data/record_drive.mcap` (made by
//! `navsync sim --scenario tests/data/record_drive.toml --fast --record …`) replayed through the
//! live processes: `navsync replay` → `navsync estimator` → `navsync/nav/state`, observed from
//! this test. The live estimator's states equal `navsync replay --estimate`'s bit for bit, the
//! replayed samples reach a recorder unchanged, and every message of the file (JSON, written by
//! navsync's own MCAP writer before the `mcap` crate and CDR) survives a JSON decode/encode
//! round trip byte for byte and a CDR one bit for bit.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Child, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use navsync_recording::Encoding;
use navsync_recording::channels::{self, Codec, sample_json};
use navsync_recording::mcap_reader::ScanEnd;
use navsync_recording::{McapReader, SampleReader};
use navsync_shared::samples::{AnySample, Health, NavState, NavStatus, TimeStatus};
use navsync_shared::services;
use navsync_tests::TestEnv;

fn data_file() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/record_drive.mcap")
}

fn start(env: &TestEnv, name: &str, args: &[&str]) -> Child {
    let log = File::create(env.dir.join(format!("{name}.log"))).expect("log file");
    env.command(args)
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .unwrap_or_else(|e| panic!("starting navsync {args:?}: {e}"))
}

fn wait_exit(env: &TestEnv, child: &mut Child, name: &str, timeout: Duration) -> ExitStatus {
    let t0 = Instant::now();
    loop {
        if let Some(st) = child.try_wait().expect("waiting") {
            return st;
        }
        if t0.elapsed() > timeout {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{name} did not exit within {timeout:?}; log:\n{}", env.log(name));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn read_all(path: &Path) -> Vec<(String, AnySample)> {
    let mut r = SampleReader::open(path).unwrap_or_else(|e| panic!("{e}"));
    let mut out = Vec::new();
    while let Some(s) = r.next_sample().unwrap_or_else(|e| panic!("{e}")) {
        out.push((s.service.to_string(), s.sample));
    }
    assert_eq!(r.scan_end(), Some(&ScanEnd::Clean), "{}", path.display());
    out
}

fn bytes_of<T>(x: &T) -> &[u8] {
    // SAFETY: reading the bytes of a plain-data `#[repr(C)]` value.
    unsafe { std::slice::from_raw_parts((x as *const T).cast::<u8>(), size_of::<T>()) }
}

const INPUTS: [&str; 4] = [
    "navsync/imu/0/sample",
    "navsync/pps/0/edge",
    "navsync/gnss/0/fix",
    "navsync/sim/truth",
];

#[test]
fn the_checked_in_json_recording_survives_json_and_cdr_round_trips() {
    let path = data_file();
    let size = std::fs::metadata(&path).unwrap().len();
    assert!(size <= 2_000_000, "{} is {size} bytes; keep it small", path.display());
    let mut r = McapReader::open(&path).unwrap();
    let mut n = 0;
    let mut buf = Vec::new();
    let mut cdr = Vec::new();
    while let Some(m) = r.next_message().unwrap() {
        let ty = channels::channel_kind(m.channel, m.schema).unwrap();
        assert_eq!(ty.codec, Codec::Json, "{}: an older layout", m.channel.topic);
        let sample = channels::decode(ty, m.data).unwrap();
        Encoding::Json.encode(&sample, &mut buf);
        Encoding::Cdr.encode(&sample, &mut cdr);
        let cdr_type = channels::ChannelType {
            kind: ty.kind,
            codec: Codec::Cdr,
        };
        let back = channels::decode(cdr_type, &cdr).unwrap();
        assert_eq!(sample_json(&back), sample_json(&sample), "{} via CDR", m.channel.topic);
        // The shortest text of a float is unique, so equal text means equal bits.
        assert!(
            buf == m.data,
            "{} message {}: {} != {}",
            m.channel.topic,
            m.sequence,
            String::from_utf8_lossy(&buf),
            String::from_utf8_lossy(m.data)
        );
        n += 1;
    }
    assert!(n > 3000, "{n} messages");
    let stats = r.summary().unwrap().statistics.clone().unwrap();
    assert_eq!(stats.message_count, n);
}

#[test]
fn replaying_the_checked_in_recording_drives_a_live_estimator() {
    let mut env = TestEnv::new("recdata");
    let node = env.node("observer");
    let nav = node.subscriber::<NavState>(services::NAV_STATE).unwrap();
    let est_health = node.subscriber::<Health>(&services::health("estimator")).unwrap();
    let input = data_file().display().to_string();
    // A recorder of what the replay publishes.
    let rec = env.dir.join("replayed.mcap");
    let rec_s = rec.display().to_string();
    let mut args = vec!["record", rec_s.as_str(), "--services"];
    args.extend(INPUTS);
    let mut recorder = start(&env, "record", &args);
    env.wait_for_path(&rec, Duration::from_secs(20));
    // The live estimator gets the models the recording says it was made with, as
    // `replay --estimate` takes them from its channel metadata: the receiver's velocity σ and
    // the IMU's model (the industrial preset; no lever arm).
    let reader = SampleReader::open(&data_file()).unwrap();
    let meta = |service: &str, key: &str| {
        reader
            .channel_metadata(service)
            .into_iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v)
            .unwrap_or_else(|| panic!("{key} missing on {service}"))
    };
    let vel_std = meta(&services::gnss_fix("0"), channels::META_GNSS_VEL_STD);
    let noise: navsync_shared::imu_spec::ImuNoise =
        serde_json::from_str(&meta(&services::imu_sample("0"), channels::META_IMU_NOISE)).unwrap();
    assert_eq!(noise, navsync_shared::imu_spec::ImuPreset::Industrial.noise());
    assert_eq!(
        meta(&services::gnss_fix("0"), channels::META_LEVER_ARM),
        "[0.0,0.0,0.0]"
    );
    env.spawn(
        "estimator",
        &[
            "estimator",
            "--gnss",
            "0",
            "--pps",
            "0",
            "--imus",
            "0",
            "--gnss-vel-std",
            &vel_std,
            "--imu-model",
            "industrial",
        ],
    );
    assert!(
        est_health.wait_next(Duration::from_secs(20)).unwrap().is_some(),
        "the estimator did not start; log:\n{}",
        env.log("estimator")
    );
    // 28 s of recording at 4x.
    let mut args = vec!["replay", input.as_str(), "--speed", "4", "--services"];
    args.extend(INPUTS);
    let t0 = Instant::now();
    let mut replay = start(&env, "replay", &args);
    let mut live: Vec<NavState> = Vec::new();
    let st = loop {
        nav.for_each(|n| live.push(*n)).unwrap();
        if let Some(st) = replay.try_wait().unwrap() {
            break st;
        }
        assert!(t0.elapsed() < Duration::from_secs(60), "replay did not finish");
        env.assert_running();
        std::thread::sleep(Duration::from_millis(20));
    };
    let took = t0.elapsed().as_secs_f64();
    assert!(st.success(), "replay: {st}\n{}", env.log("replay"));
    let t1 = Instant::now();
    while t1.elapsed() < Duration::from_millis(1000) {
        nav.for_each(|n| live.push(*n)).unwrap();
        std::thread::sleep(Duration::from_millis(20));
    }
    // SAFETY: signalling our own child.
    unsafe { libc::kill(recorder.id() as libc::pid_t, libc::SIGTERM) };
    let st = wait_exit(&env, &mut recorder, "record", Duration::from_secs(20));
    assert!(st.success(), "record: {st}\n{}", env.log("record"));
    println!("replayed 28 s at x4 in {took:.1} s; {} nav states observed", live.len());

    // One state per IMU sample, the filter aligned and fusing.
    let original = read_all(&data_file());
    let imu = original.iter().filter(|(s, _)| s == INPUTS[0]).count();
    assert_eq!(live.len(), imu, "{} states for {imu} IMU samples", live.len());
    assert!(live.windows(2).all(|w| w[1].seq == w[0].seq + 1), "states missing");
    let last = live.last().unwrap();
    assert_eq!(last.status, NavStatus::Aligned as u8, "{last:?}");
    assert_eq!(last.time_status, TimeStatus::Locked as u8);
    assert!(last.fixes_used >= 8, "{} fixes used", last.fixes_used);

    // The live estimator computed exactly what the offline replay computes.
    let out = env.dir.join("nav.mcap");
    let o = env
        .command(&["replay", &input, "--estimate", "--out", &out.display().to_string()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let offline: Vec<NavState> = read_all(&out)
        .into_iter()
        .filter_map(|(_, s)| match s {
            AnySample::Nav(n) => Some(n),
            _ => None,
        })
        .collect();
    assert_eq!(offline.len(), live.len());
    for (a, b) in live.iter().zip(&offline) {
        assert!(
            bytes_of(a) == bytes_of(b),
            "live and offline states differ at seq {}:\n{}\n{}",
            a.seq,
            sample_json(&AnySample::Nav(*a)),
            sample_json(&AnySample::Nav(*b))
        );
    }

    // The replayed samples arrived unchanged, in order, on every service.
    let recorded = read_all(&rec);
    for service in INPUTS {
        let want: Vec<String> = original
            .iter()
            .filter(|(s, _)| s == service)
            .map(|(_, x)| sample_json(x).to_string())
            .collect();
        let got: Vec<String> = recorded
            .iter()
            .filter(|(s, _)| s == service)
            .map(|(_, x)| sample_json(x).to_string())
            .collect();
        assert_eq!(got.len(), want.len(), "{service}");
        assert!(got == want, "{service}: replayed samples differ");
    }
    drop((nav, est_health, node));
    env.finish();
}
