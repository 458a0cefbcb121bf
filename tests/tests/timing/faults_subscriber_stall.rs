//! A stalled subscriber (issue 8): two `navsync echo` processes, one on `navsync/nav/state`
//! (the estimator's publisher) and one on `navsync/imu/0/sample` (an IMU driver's), are
//! stopped with SIGSTOP for 10 s while the live pipeline runs (two industrial IMUs at 100 Hz
//! through the Xsens path, gps, pps, estimator). This test process subscribes to the same two
//! services and measures, per 10 s window before, during and after the stop:
//!
//! * the latency of each sample at this subscriber (receipt on `CLOCK_MONOTONIC` minus the
//!   sample's host stamp: the IMU driver's receipt of the Xsens message, or for a NavState the
//!   host time of its IMU epoch), p50 / p99 / max;
//! * the estimator's own output latency as it reports it in Health (`nav_latency_p99_us`);
//! * how many samples arrived, and sequence gaps.
//!
//! The bound is relative: a window's p99 may not exceed max(baseline p99 × [`P99_FACTOR`],
//! [`P99_FLOOR_MS`]), the baseline measured over [`BASELINE`] just before the stop. Factor and
//! floor absorb the scheduling noise of a shared 2-core machine: with nothing stopped, the
//! p99 of a 10 s window (1000 samples) moved between 0.4 and 10.4 ms in our runs; a publisher
//! that waited for the stopped subscriber would show seconds (and fewer samples). Publishing must go on: every window receives at least 90 % of the
//! baseline's rate, with no sequence gaps. After SIGCONT the echo processes print again (the
//! stop must not end them) and the latencies stay within the same bound.

use std::time::{Duration, Instant};

use navsync_shared::ipc::Subscriber;
use navsync_shared::samples::*;
use navsync_shared::services;
use navsync_shared::time::monotonic_now_ns;
use navsync_tests::{HealthWatch, TestEnv, process_state, quantile, write_drive_scenario};

/// A window's latency p99 may be this many times the baseline's …
const P99_FACTOR: f64 = 3.0;
/// … or this much, whichever is larger, ms: a publisher that waited for the stopped
/// subscriber would show seconds; windows with nothing stopped reached 10.4 ms at p99 on this
/// shared 2-core machine (2026-12-01, the window after SIGCONT: the estimator's own p99 rose
/// to 1.9 ms as the echo processes printed again), so 10 ms failed on noise.
const P99_FLOOR_MS: f64 = 50.0;
/// Length of the stop and of the windows during and after it.
const WINDOW: Duration = Duration::from_secs(10);
/// Length of the baseline window before the stop.
const BASELINE: Duration = Duration::from_secs(20);

/// What one window saw.
#[derive(Debug, Default)]
struct Window {
    nav_latency_ms: Vec<f64>,
    imu_latency_ms: Vec<f64>,
    nav_gaps: u64,
    imu_gaps: u64,
    /// `nav_latency_p99_us` of the estimator's Health reports in the window, µs.
    est_p99_us: Vec<u64>,
}

impl Window {
    fn summary(&mut self, name: &str) -> (f64, f64) {
        let n = self.nav_latency_ms.len();
        let i = self.imu_latency_ms.len();
        let (n50, n99, nmax) = (
            quantile(&mut self.nav_latency_ms, 0.5),
            quantile(&mut self.nav_latency_ms, 0.99),
            quantile(&mut self.nav_latency_ms, 1.0),
        );
        let (i50, i99, imax) = (
            quantile(&mut self.imu_latency_ms, 0.5),
            quantile(&mut self.imu_latency_ms, 0.99),
            quantile(&mut self.imu_latency_ms, 1.0),
        );
        println!(
            "{name:<9} NavState: {n} received, {} gaps, latency p50 {n50:.3} / p99 {n99:.3} / max {nmax:.3} ms; \
             ImuSample 0: {i} received, {} gaps, latency p50 {i50:.3} / p99 {i99:.3} / max {imax:.3} ms; \
             estimator nav_latency_p99_us per report {:?}",
            self.nav_gaps, self.imu_gaps, self.est_p99_us
        );
        (n99, i99)
    }
}

struct Probe {
    nav: Subscriber<NavState>,
    imu: Subscriber<ImuSample>,
    health: HealthWatch,
    last_nav: Option<NavState>,
    last_imu_seq: Option<u64>,
    last_health_seq: Option<u64>,
}

impl Probe {
    /// Collects for `d`; wakes on the one wake-up of every publisher.
    fn collect(&mut self, env: &mut TestEnv, node: &navsync_shared::ipc::IpcNode, d: Duration) -> Window {
        let wake = node.wake().unwrap();
        let mut w = Window::default();
        let t0 = Instant::now();
        let mut checked = Instant::now();
        while t0.elapsed() < d {
            node.wait(&wake, Duration::from_millis(10)).unwrap();
            let now = monotonic_now_ns();
            while let Some(n) = self.nav.receive().unwrap() {
                w.nav_latency_ms.push((now - n.host_ns) as f64 * 1e-6);
                if let Some(p) = &self.last_nav
                    && n.seq > p.seq + 1
                {
                    w.nav_gaps += n.seq - p.seq - 1;
                }
                self.last_nav = Some(n);
            }
            while let Some(s) = self.imu.receive().unwrap() {
                w.imu_latency_ms.push((now - s.stamp.host_ns) as f64 * 1e-6);
                if let Some(p) = self.last_imu_seq
                    && s.stamp.seq > p + 1
                {
                    w.imu_gaps += s.stamp.seq - p - 1;
                }
                self.last_imu_seq = Some(s.stamp.seq);
            }
            if checked.elapsed() > Duration::from_millis(200) {
                checked = Instant::now();
                self.health.poll();
                if let Some(h) = self.health.latest("estimator")
                    && self.last_health_seq != Some(h.seq)
                {
                    self.last_health_seq = Some(h.seq);
                    w.est_p99_us.push(h.counter("nav_latency_p99_us").unwrap_or(0));
                }
                env.assert_running();
            }
        }
        w
    }
}

#[test]
fn stopped_subscriber_delays_no_publisher_and_blocks_nothing() {
    let _alone = navsync_tests::alone();
    let mut env = TestEnv::new("stall");
    let scen = env.dir.join("drive.toml");
    write_drive_scenario(&scen, 240.0, 2, 100.0);
    let node = env.node("observer");
    let mut probe = Probe {
        nav: node.input(services::NAV_STATE).unwrap(),
        imu: node.input(&services::imu_sample("0")).unwrap(),
        health: HealthWatch::new(&node, &["estimator", "imu-0"]),
        last_nav: None,
        last_imu_seq: None,
        last_health_seq: None,
    };
    env.spawn_pipeline(&scen, 2);
    env.spawn_capturing("echo-nav", &["echo", services::NAV_STATE]);
    env.spawn_capturing("echo-imu", &["echo", &services::imu_sample("0")]);

    // Steady state: aligned, locked, both echo processes printing.
    let t0 = Instant::now();
    loop {
        probe.collect(&mut env, &node, Duration::from_millis(500));
        let ready = probe
            .last_nav
            .is_some_and(|n| n.status == NavStatus::Aligned as u8 && n.time_status == TimeStatus::Locked as u8);
        if ready && env.stdout_len("echo-nav") > 0 && env.stdout_len("echo-imu") > 0 {
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "not aligned and locked within 120 s\n{}",
            env.log("estimator")
        );
    }
    // Settle (and keep this subscriber's queues drained: a backlog would be counted as latency).
    probe.collect(&mut env, &node, Duration::from_secs(2));

    let mut base = probe.collect(&mut env, &node, BASELINE);
    env.signal("echo-nav", libc::SIGSTOP);
    env.signal("echo-imu", libc::SIGSTOP);
    let mut stopped = probe.collect(&mut env, &node, WINDOW);
    let states: Vec<Option<char>> = ["echo-nav", "echo-imu"]
        .iter()
        .map(|n| env.pid(n).and_then(process_state))
        .collect();
    assert_eq!(states, [Some('T'), Some('T')], "the echo processes are not stopped");
    let printed_during_stop = (env.stdout_len("echo-nav"), env.stdout_len("echo-imu"));
    env.signal("echo-nav", libc::SIGCONT);
    env.signal("echo-imu", libc::SIGCONT);
    let mut resumed = probe.collect(&mut env, &node, WINDOW);
    let printed_after = (env.stdout_len("echo-nav"), env.stdout_len("echo-imu"));
    probe.health.poll();
    let imu_publish_errors = probe.health.counter("imu-0", "publish_errors");

    let (b_nav, b_imu) = base.summary("baseline");
    let (s_nav, s_imu) = stopped.summary("stopped");
    let (r_nav, r_imu) = resumed.summary("resumed");
    let nav_bound = (b_nav * P99_FACTOR).max(P99_FLOOR_MS);
    let imu_bound = (b_imu * P99_FACTOR).max(P99_FLOOR_MS);
    let est_base = base.est_p99_us.iter().copied().max().unwrap_or(0) as f64 * 1e-3;
    let est_bound = (est_base * P99_FACTOR).max(P99_FLOOR_MS);
    let est_stopped = stopped.est_p99_us.iter().copied().max().unwrap_or(0) as f64 * 1e-3;
    println!(
        "bounds (max(baseline p99 × {P99_FACTOR}, {P99_FLOOR_MS} ms)): NavState {nav_bound:.3} ms, ImuSample \
         {imu_bound:.3} ms, estimator's own p99 {est_bound:.3} ms (stopped: worst report {est_stopped:.3} ms); \
         echo output bytes after 10 s stopped {printed_during_stop:?}, 10 s after SIGCONT {printed_after:?}; imu-0 publish_errors {imu_publish_errors:?}"
    );

    let per_window = |n: usize| (n as f64 * WINDOW.as_secs_f64() / BASELINE.as_secs_f64()) as usize;
    for (name, w) in [("stopped", &stopped), ("resumed", &resumed)] {
        for (what, n, nb) in [
            (
                "NavState",
                w.nav_latency_ms.len(),
                per_window(base.nav_latency_ms.len()),
            ),
            (
                "ImuSample",
                w.imu_latency_ms.len(),
                per_window(base.imu_latency_ms.len()),
            ),
        ] {
            assert!(
                n * 10 >= nb * 9,
                "{name}: {n} {what}s against {nb} per 10 s in the baseline: publishing slowed"
            );
        }
        assert_eq!(
            (w.nav_gaps, w.imu_gaps),
            (0, 0),
            "{name}: samples lost at a subscriber that keeps up"
        );
    }
    assert!(
        s_nav <= nav_bound,
        "NavState latency p99 {s_nav:.3} ms while stopped > {nav_bound:.3} ms"
    );
    assert!(
        s_imu <= imu_bound,
        "ImuSample latency p99 {s_imu:.3} ms while stopped > {imu_bound:.3} ms"
    );
    assert!(
        est_stopped <= est_bound,
        "estimator output latency p99 {est_stopped:.3} ms while stopped > {est_bound:.3} ms"
    );
    assert!(
        r_nav <= nav_bound,
        "NavState latency p99 {r_nav:.3} ms after SIGCONT > {nav_bound:.3} ms"
    );
    assert!(
        r_imu <= imu_bound,
        "ImuSample latency p99 {r_imu:.3} ms after SIGCONT > {imu_bound:.3} ms"
    );
    assert_eq!(imu_publish_errors, Some(0), "the IMU driver failed to publish");
    // The stopped processes print again.
    assert!(
        printed_after.0 > printed_during_stop.0 && printed_after.1 > printed_during_stop.1,
        "the echo processes did not resume: {printed_after:?}"
    );
    for name in ["echo-nav", "echo-imu"] {
        assert!(env.is_running(name), "{name} exited:\n{}", env.log(name));
    }
    drop((probe, node));
    env.finish();
}
