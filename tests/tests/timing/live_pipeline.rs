//! The demo's processes (sim, gnss, pps, estimator) as separate OS processes over real iceoryx2
//! services, observed from this test process: every service carries samples, and the time
//! mapping from the simulated PPS (0.5 ppm, 1 µs jitter) is within 5 µs of the truth after 30 s.

use std::time::{Duration, Instant};

use navsync_shared::samples::*;
use navsync_shared::services;
use navsync_tests::TestEnv;

#[test]
fn every_service_carries_samples_and_time_maps_within_5_us() {
    let _alone = navsync_tests::alone();
    let mut env = TestEnv::new("live");
    let node = env.node("observer");
    let imus: Vec<_> = (0..4)
        .map(|i| {
            node.subscriber::<ImuSample>(&services::imu_sample(&i.to_string()))
                .unwrap()
        })
        .collect();
    let pps = node.subscriber::<PpsEdge>(&services::pps_edge("0")).unwrap();
    let fix = node.subscriber::<GnssFix>(&services::gnss_fix("0")).unwrap();
    let time = node.subscriber::<TimeState>(services::TIME_STATE).unwrap();
    let nav = node.subscriber::<NavState>(services::NAV_STATE).unwrap();
    let truth = node.subscriber::<SimTruth>(services::SIM_TRUTH).unwrap();
    let healths: Vec<_> = ["sim", "gnss-0", "pps-0", "estimator"]
        .iter()
        .map(|p| node.subscriber::<Health>(&services::health(p)).unwrap())
        .collect();

    let link = env.dir.join("gnss0");
    let link_s = link.display().to_string();
    let dir_s = env.dir.display().to_string();
    // The IMUs take the real Xsens path: simulator → pseudo-terminal → `navsync imu`.
    env.spawn(
        "sim",
        &[
            "sim",
            "--pty-link",
            &link_s,
            "--imus",
            "4",
            "--duration",
            "60",
            "--imu-output",
            "xsens",
            "--imu-pty-dir",
            &dir_s,
        ],
    );
    env.wait_for_path(&link, Duration::from_secs(20));
    env.spawn("gnss", &["gnss", "--port", &link_s, "--baud", "115200", "--id", "0"]);
    for i in 0..4 {
        let port = env.dir.join(format!("imu{i}"));
        env.wait_for_path(&port, Duration::from_secs(20));
        let source = format!("xsens:{}:921600", port.display());
        env.spawn(
            &format!("imu{i}"),
            &["imu", "--source", &source, "--id", &i.to_string()],
        );
    }
    env.spawn("pps", &["pps", "--source", "sim", "--id", "0"]);
    env.spawn(
        "estimator",
        &["estimator", "--gnss", "0", "--pps", "0", "--imus", "0,1,2,3"],
    );

    let t0 = Instant::now();
    let mut counts = [0u64; 10];
    let (mut last_seq, mut last_dev) = ([0u64; 4], [i64::MIN; 4]);
    let mut latest_time: Option<TimeState> = None;
    let (mut first_truth_host, mut checked, mut worst) = (None::<i64>, 0u64, 0.0f64);
    while t0.elapsed() < Duration::from_secs(55) {
        std::thread::sleep(Duration::from_millis(50));
        env.assert_running();
        for (i, s) in imus.iter().enumerate() {
            counts[i] += s
                .for_each(|x| {
                    // Stamped on receipt, with the device's own clock, numbered by its counter.
                    assert_eq!(x.stamp.source(), StampSource::Receipt);
                    assert_eq!(x.stamp.has_device_time, 1);
                    assert!(
                        x.stamp.seq >= last_seq[i] && x.stamp.device_ns > last_dev[i],
                        "imu {i}: {x:?}"
                    );
                    (last_seq[i], last_dev[i]) = (x.stamp.seq + 1, x.stamp.device_ns);
                })
                .unwrap() as u64;
        }
        counts[4] += pps.for_each(|_| {}).unwrap() as u64;
        counts[5] += fix.for_each(|_| {}).unwrap() as u64;
        while let Some(t) = time.receive().unwrap() {
            counts[6] += 1;
            latest_time = Some(t);
        }
        counts[7] += nav.for_each(|_| {}).unwrap() as u64;
        while let Some(tr) = truth.receive().unwrap() {
            counts[8] += 1;
            let first = *first_truth_host.get_or_insert(tr.host_ns);
            if tr.host_ns - first > 30_000_000_000
                && let Some(ts) = &latest_time
            {
                assert_eq!(ts.status(), TimeStatus::Locked, "time not locked after 30 s");
                let err = (ts.utc_ns_at(tr.host_ns) - tr.utc_ns) as f64;
                worst = worst.max(err.abs());
                checked += 1;
            }
        }
        for h in &healths {
            counts[9] += h.for_each(|_| {}).unwrap() as u64;
        }
        if checked >= 500 && counts.iter().all(|&c| c > 0) {
            break;
        }
    }
    let names = [
        "imu0", "imu1", "imu2", "imu3", "pps", "fix", "time", "nav", "truth", "health",
    ];
    for (n, c) in names.iter().zip(counts.iter()) {
        assert!(
            *c > 0,
            "no samples on {n}; counts {counts:?}\nestimator log:\n{}",
            env.log("estimator")
        );
    }
    println!("counts {counts:?}; {checked} truth instants after 30 s, worst mapping error {worst:.0} ns");
    assert!(checked >= 500, "only {checked} truth instants checked");
    assert!(worst < 5_000.0, "time mapping error {worst} ns after 30 s");
    drop((imus, pps, fix, time, nav, truth, healths, node));
    env.finish();
}
