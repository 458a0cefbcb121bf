//! `navsync estimator --idle-polling` (low-latency deployments, README "## Performance"): while
//! the estimator runs the kernel's CPU wake-up latency request is 0 µs, and it is released
//! when the estimator exits. Read back from `/dev/cpu_dma_latency` (the current aggregate
//! request, an i32 in µs).
//!
//! Taking the request needs write access to the file (root, or the udev rule in
//! `systemd/99-navsync.rules`): otherwise the test says why it is skipped.

use std::io::Read;
use std::time::{Duration, Instant};

use navsync_tests::{HealthWatch, TestEnv};

const PATH: &str = "/dev/cpu_dma_latency";

/// The current CPU latency request, µs.
fn current_request_us() -> i32 {
    let mut b = [0u8; 4];
    std::fs::File::open(PATH)
        .and_then(|mut f| f.read_exact(&mut b))
        .expect("reading /dev/cpu_dma_latency");
    i32::from_ne_bytes(b)
}

#[test]
fn idle_polling_holds_the_wakeup_latency_at_zero_while_the_estimator_runs() {
    let _alone = navsync_tests::alone();
    if std::fs::OpenOptions::new().write(true).open(PATH).is_err() {
        println!("skipped: {PATH} is missing or not writable here (root or the navsync udev rule needed)");
        return;
    }
    let before = current_request_us();
    if before == 0 {
        println!("skipped: another process already holds the CPU wake-up latency at 0");
        return;
    }
    let mut env = TestEnv::new("idlepoll");
    let node = env.node("observer");
    let mut health = HealthWatch::new(&node, &["estimator"]);
    env.spawn("estimator", &["estimator", "--idle-polling"]);
    let t0 = Instant::now();
    // Serving (its first Health report) and holding the request.
    while current_request_us() != 0 || health.latest("estimator").is_none() {
        health.poll();
        env.assert_running();
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "the request stayed at {} µs\n{}",
            current_request_us(),
            env.log("estimator")
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    println!("request {before} µs before, 0 µs while the estimator runs");
    drop((health, node));
    env.finish();
    let after = current_request_us();
    println!("{after} µs after it exited");
    assert_eq!(after, before, "the request was not released");
}
