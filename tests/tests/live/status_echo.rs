//! `navsync status` and `navsync echo --fields/--rate/--hz` against a live set of processes
//! (sim with a u-blox receiver, gnss, pps, estimator with two IMUs): every process and service
//! is found, rates, ages and subscriber counts are measured, the health counters, the
//! time-sync state, d0, Δ, the receiver's time pulse with its qErr and the per-IMU table are
//! there, in JSON, as text and refreshing with `--watch`.

use std::time::Duration;

use crate::clients_common::{run_ok, start_live_speaking, wait_ready};
use navsync_shared::samples::{ImuSample, NavState};
use navsync_shared::services;
use navsync_tests::TestEnv;
use serde_json::Value;

fn service<'a>(report: &'a Value, name: &str) -> &'a Value {
    report["services"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["name"] == name)
        .unwrap_or_else(|| panic!("{name} not in the status report: {report:#}"))
}

#[test]
fn status_and_echo_see_the_live_processes() {
    let mut env = TestEnv::new("status");
    start_live_speaking(&mut env, "ubx");
    let node = env.node("observer");
    // This test's own subscribers: status must count them.
    let _nav_sub = node.subscriber::<NavState>(services::NAV_STATE).unwrap();
    let _imu_sub = node.subscriber::<ImuSample>(&services::imu_sample("1")).unwrap();
    let (time, _) = wait_ready(&mut env, &node, true, Duration::from_secs(60));
    println!("time locked: {:?}", time.status());

    // One JSON report over a 2 s window.
    let out = run_ok(&env, &["status", "--json", "--window", "2"]);
    let r: Value = serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}"));
    assert_eq!(r["prefix"], env.prefix.as_str());
    let procs: Vec<&str> = r["processes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    for p in ["sim", "gnss-0", "pps-0", "estimator", "observer"] {
        assert!(procs.contains(&p), "process {p} missing: {procs:?}");
    }
    let est = r["processes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"] == "estimator")
        .unwrap();
    assert_eq!(est["state"], "alive");
    assert!(est["pid"].as_i64().unwrap() > 0);
    assert!(est["uptime_s"].as_f64().unwrap() > 1.0, "{est}");

    let imu0 = service(&r, "navsync/imu/0/sample");
    assert_eq!(imu0["type"], "navsync.ImuSample.v1");
    assert_eq!(imu0["publishers"], 1);
    // The estimator subscribes; status does not count itself.
    assert_eq!(imu0["subscribers"], 1, "{imu0}");
    let rate = imu0["rate_hz"].as_f64().unwrap();
    assert!((60.0..140.0).contains(&rate), "IMU rate {rate} Hz: {imu0}");
    let age = imu0["last_sample_age_s"].as_f64().unwrap();
    assert!((0.0..1.0).contains(&age), "IMU sample age {age} s");
    assert!(imu0["nodes"].as_array().unwrap().iter().any(|n| n == "sim"), "{imu0}");
    // The estimator and this test subscribe to IMU 1.
    assert_eq!(service(&r, "navsync/imu/1/sample")["subscribers"], 2);
    let nav = service(&r, "navsync/nav/state");
    assert_eq!(nav["publishers"], 1);
    assert_eq!(nav["subscribers"], 1, "only this test subscribes: {nav}");
    assert!(nav["rate_hz"].as_f64().unwrap() > 50.0, "{nav}");
    let fix = service(&r, "navsync/gnss/0/fix");
    assert!(fix["rate_hz"].as_f64().unwrap() > 0.0, "{fix}");
    for s in [
        "navsync/pps/0/edge",
        "navsync/time/state",
        "navsync/sim/truth",
        "navsync/health/estimator",
    ] {
        service(&r, s);
    }

    // Health: counters of every process.
    let health = r["health"].as_array().unwrap();
    let gps = health.iter().find(|h| h["process"] == "gnss-0").expect("gps health");
    assert_eq!(gps["alive"], true);
    assert!(gps["counters"].as_object().unwrap().len() >= 3, "{gps}");
    let pps = health.iter().find(|h| h["process"] == "pps-0").expect("pps health");
    assert!(pps["counters"]["pps_accepted"].as_u64().unwrap() > 2, "{pps}");

    // Time sync, receiver latency, Δ, IMU table.
    let t = &r["time"];
    assert_eq!(t["status"], "locked", "{t}");
    let d0 = t["receiver_latency_d0_s"]["median"].as_f64().unwrap();
    assert!((0.0..1.0).contains(&d0), "d0 {d0}");
    assert!(t["receiver_latency_d0_s"]["epochs"].as_u64().unwrap() > 0);
    assert!(t["drift_ppm"].as_f64().is_some());
    // The receiver's next time pulse (TIM-TP) and its quantisation error.
    let pulses = r["time_pulses"].as_array().unwrap();
    assert_eq!(pulses.len(), 1, "{pulses:?}");
    assert_eq!(pulses[0]["service"], "navsync/gnss/0/timepulse");
    assert!(pulses[0]["q_err_ns"].is_number(), "{pulses:?}");
    assert!(
        pulses[0]["pulse_utc_ns"]
            .as_i64()
            .is_some_and(|t| t > 1_600_000_000_000_000_000)
    );
    let n = &r["nav"];
    assert!(n["lat_deg"].as_f64().is_some_and(|x| (x - 48.137).abs() < 0.01), "{n}");
    let imus = n["imu"].as_array().unwrap();
    assert_eq!(imus.len(), 2, "{n}");
    assert_eq!(imus[1]["id"], "1");
    assert!(n["gnss_delay_s"].is_number() || n["gnss_delay_s"].is_null());

    // The text view says the same (over the default 2 s window: in 1 s a 1 Hz service such as
    // the time state may publish nothing, when its sample falls just outside).
    let text = run_ok(&env, &["status"]);
    println!("{text}");
    for needle in [
        "navsync/imu/0/sample",
        "estimator",
        "TIME  locked",
        "receiver latency d0",
        "GNSS delay",
        "time pulse (navsync/gnss/0/timepulse): qErr ",
        "NAV ",
    ] {
        assert!(text.contains(needle), "`{needle}` missing:\n{text}");
    }

    // --watch: one JSON line per refresh.
    let out = run_ok(&env, &["status", "--json", "--watch", "0.5", "--count", "3"]);
    let lines: Vec<Value> = out.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len(), 3, "{out}");
    assert!(lines.iter().all(|l| l["services"].as_array().unwrap().len() >= 8));
    assert!(lines[2]["host_ns"].as_i64() > lines[0]["host_ns"].as_i64());

    // echo --fields: only those fields, nested and indexed paths included.
    let out = run_ok(
        &env,
        &[
            "echo",
            "navsync/nav/state",
            "--json",
            "--count",
            "3",
            "--fields",
            "lat_deg,lon_deg,vel_ned_mps[2],imu[1].imu_id,seq",
        ],
    );
    let rows: Vec<Value> = out.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(rows.len(), 3);
    for row in &rows {
        let keys: Vec<&String> = row.as_object().unwrap().keys().collect();
        assert_eq!(
            keys,
            ["lat_deg", "lon_deg", "vel_ned_mps[2]", "imu[1].imu_id", "seq"],
            "{row}"
        );
        assert_eq!(row["imu[1].imu_id"], "1");
    }
    let text = run_ok(
        &env,
        &[
            "echo",
            "navsync/imu/0/sample",
            "--count",
            "2",
            "--fields",
            "stamp.host_ns,stamp.seq",
        ],
    );
    assert!(
        text.lines()
            .all(|l| l.starts_with("stamp.host_ns=") && l.contains(" stamp.seq=")),
        "{text}"
    );
    let o = env
        .command(&["echo", "navsync/nav/state", "--fields", "no_such_field"])
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("has no field `no_such_field`"));

    // echo --rate 5: at most 5 lines per second, i.e. printed samples ≥ ~200 ms apart in
    // their own stamps (the IMU's 100 Hz stamps are 10 ms apart).
    let out = run_ok(
        &env,
        &[
            "echo",
            "navsync/imu/0/sample",
            "--json",
            "--count",
            "5",
            "--rate",
            "5",
            "--fields",
            "stamp.host_ns",
        ],
    );
    let stamps: Vec<i64> = out
        .lines()
        .map(|l| {
            serde_json::from_str::<Value>(l).unwrap()["stamp.host_ns"]
                .as_i64()
                .unwrap()
        })
        .collect();
    assert_eq!(stamps.len(), 5);
    for w in stamps.windows(2) {
        assert!(
            w[1] - w[0] >= 100_000_000,
            "lines closer than the rate allows: {stamps:?}"
        );
    }

    // echo --hz: the measured rate instead of the samples.
    let out = run_ok(
        &env,
        &["echo", "navsync/imu/0/sample", "--hz", "--json", "--count", "2"],
    );
    let last: Value = serde_json::from_str(out.lines().last().unwrap()).unwrap();
    let stamp_rate = last["stamp_rate_hz"].as_f64().unwrap();
    assert!((95.0..105.0).contains(&stamp_rate), "{last}");
    assert!(last["samples"].as_u64().unwrap() > 30, "{last}");
    assert_eq!(last["seq_gaps"], 0, "{last}");
    println!("echo --hz: {last}");

    drop((_nav_sub, _imu_sub, node));
    env.finish();
}

/// Publishes `make(k)` every `period` until `child` exits; its output.
fn publish_until_exit<T: navsync_shared::ipc::IpcSample>(
    publisher: &mut navsync_shared::ipc::Publisher<T>,
    child: std::process::Child,
    period: Duration,
    make: impl Fn(u64) -> T,
) -> std::process::Output {
    let mut child = child;
    let t0 = std::time::Instant::now();
    for k in 0u64.. {
        if child.try_wait().unwrap().is_some() || t0.elapsed() > Duration::from_secs(30) {
            break;
        }
        publisher.publish(&make(k)).unwrap();
        let next = period * u32::try_from(k + 1).unwrap();
        std::thread::sleep(next.saturating_sub(t0.elapsed()));
    }
    let _ = child.kill();
    child.wait_with_output().unwrap()
}

/// `status`: a 1 Hz service is 1 Hz over a window that holds 2 or 3 of its samples (the
/// intervals between them are counted, not the samples); a process with two iceoryx2 nodes
/// (a `TimeState` publisher has one more for the Python clients' wake-up) is one row; with
/// nothing running it says so and fails, without a backtrace even with RUST_BACKTRACE=1.
#[test]
fn status_rates_count_intervals_a_process_is_one_row_and_nothing_running_fails() {
    use navsync_shared::samples::TimeState;
    use navsync_shared::time::monotonic_now_ns;
    use std::process::Stdio;

    let env = TestEnv::new("statusrate");
    let o = env
        .command(&["status", "--window", "0.5"])
        .env("RUST_BACKTRACE", "1")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "nothing running, yet: {err}");
    assert!(err.contains("nothing is running under the iceoryx2 prefix"), "{err}");
    assert!(!err.contains("acktrace"), "{err}");

    let node = env.node("timekeeper");
    let mut publisher = node.publisher::<TimeState>(services::TIME_STATE).unwrap();
    let child = env
        .command(&["status", "--json", "--window", "2.5"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let base = monotonic_now_ns();
    let o = publish_until_exit(&mut publisher, child, Duration::from_secs(1), |k| {
        let mut t = TimeState::unknown();
        t.computed_host_ns = base + i64::try_from(k).unwrap() * 1_000_000_000;
        t.seq = k;
        t
    });
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: Value = serde_json::from_slice(&o.stdout).unwrap();
    let time = service(&r, services::TIME_STATE);
    let samples = time["samples"].as_u64().unwrap();
    let rate = time["rate_hz"].as_f64().unwrap();
    println!("{samples} samples of a 1 Hz service in 2.5 s: {rate} Hz");
    assert!((2..=3).contains(&samples), "{time}");
    assert!((rate - 1.0).abs() < 0.01, "1 Hz shown as {rate} Hz: {time}");
    let rows: Vec<&Value> = r["processes"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|p| p["name"] == "timekeeper")
        .collect();
    assert_eq!(rows.len(), 1, "{:#}", r["processes"]);
    drop((publisher, node));
    env.finish();
}

/// `echo`: enumerations by name (`status=aligned`), `--raw` for their numbers, and a field
/// asked for by `--fields` printed as `null` when it has no value.
#[test]
fn echo_names_enums_and_prints_asked_for_nulls() {
    use navsync_shared::reflect::Reflect;
    use navsync_shared::samples::{ImuSyncReason, NavStatus, TimeStatus};
    use std::process::Stdio;

    let env = TestEnv::new("echoenum");
    let node = env.node("navigator");
    let mut publisher = node.publisher::<NavState>(services::NAV_STATE).unwrap();
    let make = |k: u64| {
        let mut n = NavState::zeroed();
        n.seq = k;
        n.status = NavStatus::Aligned as u8;
        n.time_status = TimeStatus::Locked as u8;
        n.imu_count = 1;
        n.imu[0].reason = ImuSyncReason::Converging as u8;
        n.gnss_delay_s = f64::NAN;
        n.lat_deg = 48.5;
        n
    };
    let mut echo = |args: &[&str]| {
        let child = env
            .command(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let o = publish_until_exit(&mut publisher, child, Duration::from_millis(50), make);
        assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8(o.stdout).unwrap()
    };
    let fields = "status,time_status,gnss_delay_s,lat_deg,imu[0].reason";
    let out = echo(&["echo", services::NAV_STATE, "--count", "1", "--fields", fields]);
    assert_eq!(
        out.trim(),
        "status=aligned time_status=locked gnss_delay_s=null lat_deg=48.5 imu[0].reason=converging"
    );
    let out = echo(&["echo", services::NAV_STATE, "--count", "1", "--raw", "--fields", fields]);
    assert_eq!(
        out.trim(),
        "status=1 time_status=1 gnss_delay_s=null lat_deg=48.5 imu[0].reason=6"
    );
    let out = echo(&["echo", services::NAV_STATE, "--count", "1"]);
    assert!(
        out.contains(" status=aligned ") && out.contains("time_status=locked"),
        "{out}"
    );
    let out = echo(&[
        "echo",
        services::NAV_STATE,
        "--count",
        "1",
        "--json",
        "--fields",
        fields,
    ]);
    let v: Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(v["status"], 1, "JSON keeps the recordings' numbers: {v}");
    assert!(v["gnss_delay_s"].is_null(), "{v}");
    drop((publisher, node));
    env.finish();
}
