//! `navsync record` beside a live run, and `navsync replay --estimate` over that recording:
//! the replayed navigation states equal the live estimator's bit for bit (matched by IMU host
//! time) with the live estimator's own settings (not the defaults: they come from the
//! recording, no flag is given to the replay), and two replays write byte-identical files. A recorder killed with SIGKILL leaves a
//! readable file that lacks at most the last second.

use std::collections::HashMap;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Child, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use navsync_recording::SampleReader;
use navsync_recording::channels::sample_json;
use navsync_recording::mcap_reader::ScanEnd;
use navsync_shared::samples::{
    AnySample, EventPose, GNSS_PROTOCOL_UBX, GnssFix, Health, NavState, NavStatus, TimeStatus,
};
use navsync_shared::services;
use navsync_shared::time::monotonic_now_ns;
use navsync_tests::TestEnv;

fn scenario() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/record_drive.toml")
}

/// Starts a navsync child that the test stops itself (stderr to `<dir>/<name>.log`).
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

/// Every sample of a recording: (service, sample, log_time, publish_time), and how it ended.
fn read_all(path: &Path) -> (Vec<(String, AnySample, u64, u64)>, ScanEnd) {
    let mut r = SampleReader::open(path).unwrap_or_else(|e| panic!("{e}"));
    let mut out = Vec::new();
    while let Some(s) = r.next_sample().unwrap_or_else(|e| panic!("{e}")) {
        out.push((s.service.to_string(), s.sample, s.log_time, s.publish_time));
    }
    (out, r.scan_end().cloned().expect("scan end"))
}

fn nav_states(samples: &[(String, AnySample, u64, u64)]) -> Vec<NavState> {
    samples
        .iter()
        .filter_map(|(_, s, _, _)| match s {
            AnySample::Nav(n) => Some(*n),
            _ => None,
        })
        .collect()
}

/// The bytes of a sample struct (both sides come out of the JSON decoder, which starts from
/// all-zero bytes, so padding and reserved fields compare equal too).
fn bytes_of<T>(x: &T) -> &[u8] {
    // SAFETY: reading the bytes of a plain-data `#[repr(C)]` value.
    unsafe { std::slice::from_raw_parts((x as *const T).cast::<u8>(), size_of::<T>()) }
}

fn counter(h: &Health, name: &str) -> Option<u64> {
    h.counter(name)
}

#[test]
fn a_live_run_and_its_replay_agree_bit_for_bit() {
    live_run_and_replay("recreplay", "nmea");
}

/// The same with the simulated receiver writing u-blox UBX (NAV-PVT, NAV-EOE, TIM-TP) and the
/// GNSS driver reading it (`--protocol ubx`): the fixes carry the receiver's accuracy
/// estimates, the edges are labelled by TIM-TP, and the replay is still bit-exact.
#[test]
fn a_live_ubx_run_and_its_replay_agree_bit_for_bit() {
    live_run_and_replay("recreplayubx", "ubx");
}

fn live_run_and_replay(name: &str, protocol: &str) {
    let mut env = TestEnv::new(name);
    let node = env.node("observer");
    let est_health = node.subscriber::<Health>(&services::health("estimator")).unwrap();
    let rec = env.dir.join("live.mcap");
    let rec_s = rec.display().to_string();
    // The recorder first: it subscribes to the named services before it creates the file, so
    // it sees everything the estimator sees.
    let mut recorder = start(
        &env,
        "record",
        &[
            "record",
            &rec_s,
            "--services",
            "navsync/imu/0/sample",
            "navsync/pps/0/edge",
            "navsync/gnss/0/fix",
            "navsync/gnss/0/timepulse",
            "navsync/gnss/0/event",
            "navsync/event/0/pose",
            "navsync/nav/state",
            "navsync/time/state",
            "navsync/sim/truth",
            "navsync/health/*",
            "navsync/estimator/settings",
        ],
    );
    env.wait_for_path(&rec, Duration::from_secs(20));
    // Settings other than the defaults (as `navsync demo` runs it): the recording holds them
    // and the replay, given no flag, uses them.
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
            "--imu-model",
            "consumer",
            "--gnss-vel-std",
            "0.05",
        ],
    );
    assert!(
        est_health.wait_next(Duration::from_secs(20)).unwrap().is_some(),
        "the estimator did not start; log:\n{}",
        env.log("estimator")
    );
    env.spawn("pps", &["pps", "--source", "sim", "--id", "0"]);
    let link = env.dir.join("gnss0");
    let link_s = link.display().to_string();
    let scen = scenario().display().to_string();
    let mut sim = start(
        &env,
        "sim",
        &[
            "sim",
            "--scenario",
            &scen,
            "--pty-link",
            &link_s,
            "--gnss-protocol",
            protocol,
        ],
    );
    env.wait_for_path(&link, Duration::from_secs(20));
    env.spawn(
        "gps",
        &[
            "gps",
            "--port",
            &link_s,
            "--baud",
            "115200",
            "--protocol",
            protocol,
            "--id",
            "0",
        ],
    );
    // The scenario lasts 28 s of real time.
    let st = wait_exit(&env, &mut sim, "sim", Duration::from_secs(120));
    assert!(st.success(), "sim: {st}\n{}", env.log("sim"));
    env.assert_running();
    // Let the last states reach the recorder, then close the file properly.
    std::thread::sleep(Duration::from_millis(1500));
    // SAFETY: signalling our own child.
    unsafe { libc::kill(recorder.id() as libc::pid_t, libc::SIGTERM) };
    let st = wait_exit(&env, &mut recorder, "record", Duration::from_secs(20));
    assert!(st.success(), "record: {st}\n{}", env.log("record"));

    let (live, end) = read_all(&rec);
    assert_eq!(end, ScanEnd::Clean);
    let imu_samples = live.iter().filter(|(s, ..)| s == "navsync/imu/0/sample").count();
    let live_nav = nav_states(&live);
    let size = std::fs::metadata(&rec).unwrap().len();
    println!(
        "live recording: {} messages, {imu_samples} IMU samples, {} nav states, {size} bytes",
        live.len(),
        live_nav.len()
    );
    assert!(imu_samples >= 2700, "only {imu_samples} IMU samples recorded");
    let fixes: Vec<GnssFix> = live
        .iter()
        .filter_map(|(_, s, ..)| match s {
            AnySample::GnssFix(f) => Some(*f),
            _ => None,
        })
        .collect();
    assert!(fixes.len() >= 25, "{} fixes", fixes.len());
    let pulses = live
        .iter()
        .filter(|(_, s, ..)| matches!(s, AnySample::TimePulse(_)))
        .count();
    if protocol == "ubx" {
        // The receiver's own accuracy estimates, and its TIM-TP for every second.
        assert!(fixes.iter().all(|f| f.protocol == GNSS_PROTOCOL_UBX), "not UBX fixes");
        let f = fixes.last().unwrap();
        assert!(f.h_acc_m > 0.0 && f.v_acc_m > 0.0 && f.s_acc_mps > 0.0, "{f:?}");
        assert!(pulses >= 25, "{pulses} time pulse reports");
    } else {
        assert_eq!(pulses, 0);
    }
    assert_eq!(live_nav.len(), imu_samples, "one live NavState per IMU sample");
    let last_health = live
        .iter()
        .rev()
        .find_map(|(s, x, ..)| match x {
            AnySample::Health(h) if s == "navsync/health/estimator" => Some(*h),
            _ => None,
        })
        .expect("estimator health recorded");
    let late = counter(&last_health, "inputs_late");
    let by_receiver = counter(&last_health, "pps_labelled_by_rx").unwrap_or(0);
    if protocol == "ubx" {
        assert!(by_receiver >= 20, "{by_receiver} edges labelled by TIM-TP");
    } else {
        assert_eq!(by_receiver, 0);
    }
    println!(
        "estimator: inputs_late {late:?}, imu_seq_gaps {:?}",
        counter(&last_health, "imu_seq_gaps")
    );

    // Two replays through the estimator library.
    let mut outs = Vec::new();
    for i in 0..2 {
        let out = env.dir.join(format!("nav{i}.mcap"));
        let summary = env.dir.join(format!("summary{i}.json"));
        let t0 = Instant::now();
        let o = env
            .command(&[
                "replay",
                &rec_s,
                "--estimate",
                "--out",
                &out.display().to_string(),
                "--summary-json",
                &summary.display().to_string(),
            ])
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "replay --estimate: {}\n{}",
            o.status,
            String::from_utf8_lossy(&o.stderr)
        );
        println!("replay --estimate {i}: {:.2} s", t0.elapsed().as_secs_f64());
        let s: serde_json::Value = serde_json::from_slice(&std::fs::read(&summary).unwrap()).unwrap();
        assert_eq!(s["imu_samples"], imu_samples as u64);
        outs.push(out);
    }
    let (a, b) = (std::fs::read(&outs[0]).unwrap(), std::fs::read(&outs[1]).unwrap());
    assert!(a == b, "two replays wrote different files");

    let (replayed, end) = read_all(&outs[0]);
    assert_eq!(end, ScanEnd::Clean);
    let replay_nav: HashMap<i64, NavState> = nav_states(&replayed).into_iter().map(|n| (n.host_ns, n)).collect();
    assert_eq!(replay_nav.len(), live_nav.len());
    let mut first_diff = None;
    let mut differing = 0;
    for n in &live_nav {
        let r = replay_nav
            .get(&n.host_ns)
            .unwrap_or_else(|| panic!("no replayed state for IMU host time {}", n.host_ns));
        if bytes_of(n) != bytes_of(r) {
            differing += 1;
            first_diff.get_or_insert((*n, *r));
        }
    }
    if let Some((n, r)) = first_diff {
        let (jn, jr) = (sample_json(&AnySample::Nav(n)), sample_json(&AnySample::Nav(r)));
        let fields: Vec<String> = jn
            .as_object()
            .unwrap()
            .iter()
            .filter(|(k, v)| jr[k.as_str()] != **v)
            .map(|(k, v)| format!("{k}: live {v} replay {}", jr[k.as_str()]))
            .collect();
        panic!(
            "{differing} of {} states differ (estimator inputs_late {late:?}); first at seq {}: {fields:?}",
            live_nav.len(),
            n.seq
        );
    }
    // The event poses (UBX: the simulated camera's TIM-TM2 marks) as the live estimator
    // published them, bit for bit in the replay (which also poses those the live run still
    // held when it stopped).
    let poses = |v: &[(String, AnySample, u64, u64)]| -> Vec<EventPose> {
        v.iter()
            .filter_map(|(_, s, ..)| match s {
                AnySample::EventPose(p) => Some(*p),
                _ => None,
            })
            .collect()
    };
    let (live_poses, replay_poses) = (poses(&live), poses(&replayed));
    if protocol == "ubx" {
        let posed = live_poses.iter().filter(|p| p.source != 0).count();
        assert!(posed >= 10, "{posed} live event poses");
        for p in &live_poses {
            let r = replay_poses
                .iter()
                .find(|r| r.seq == p.seq)
                .unwrap_or_else(|| panic!("no replayed event pose {}", p.seq));
            assert!(
                bytes_of(p) == bytes_of(r),
                "event pose {}: live {p:?}, replay {r:?}",
                p.seq
            );
        }
        println!(
            "{} live event poses ({posed} posed) equal the replayed ones",
            live_poses.len()
        );
    } else {
        assert!(live_poses.is_empty() && replay_poses.is_empty());
    }
    // The comparison covers a working filter: aligned, locked, fusing fixes.
    let last = live_nav.last().unwrap();
    assert_eq!(last.status, NavStatus::Aligned as u8, "{last:?}");
    assert_eq!(last.time_status, TimeStatus::Locked as u8, "{last:?}");
    assert!(last.fixes_used >= 8, "{} fixes used", last.fixes_used);
    println!(
        "{} live states equal the replayed ones bit for bit; {} fixes used",
        live_nav.len(),
        last.fixes_used
    );
    drop((est_health, node));
    env.finish();
}

#[test]
fn a_killed_recorder_loses_at_most_the_last_second() {
    let mut env = TestEnv::new("reckill");
    let rec = env.dir.join("killed.mcap");
    let rec_s = rec.display().to_string();
    let mut recorder = start(
        &env,
        "record",
        &[
            "record",
            &rec_s,
            "--services",
            "navsync/imu/0/sample",
            "navsync/sim/truth",
        ],
    );
    env.wait_for_path(&rec, Duration::from_secs(20));
    let link = env.dir.join("gnss0");
    let link_s = link.display().to_string();
    let scen = scenario().display().to_string();
    env.spawn(
        "sim",
        &["sim", "--scenario", &scen, "--pty-link", &link_s, "--duration", "8"],
    );
    env.wait_for_path(&link, Duration::from_secs(20));
    std::thread::sleep(Duration::from_millis(5500));
    let killed_at = monotonic_now_ns();
    recorder.kill().unwrap();
    let st = recorder.wait().unwrap();
    assert!(!st.success());
    // A node of this prefix reclaims what the killed recorder left in shared memory.
    let cleaner = env.node("cleaner");

    let (samples, end) = read_all(&rec);
    assert!(matches!(end, ScanEnd::Truncated { .. }), "{end:?}");
    let last_receipt = samples.iter().map(|s| s.3).max().expect("samples survive") as i64;
    let lost_s = (killed_at - last_receipt) as f64 * 1e-9;
    let imu = samples.iter().filter(|s| s.0 == "navsync/imu/0/sample").count();
    println!(
        "{} samples survived ({imu} IMU); the last received {lost_s:.2} s before the kill",
        samples.len()
    );
    assert!(imu >= 300, "only {imu} IMU samples survived");
    assert!(lost_s < 1.5, "lost the last {lost_s:.2} s");
    drop(cleaner);
    env.finish();
}
