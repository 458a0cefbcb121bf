//! `navsync pps-out --output sim:FILE` against a time mapping this test publishes (locked, GNSS
//! time 217.5 ms ahead of the system clock, the host clock 200 ppm slow against GNSS time):
//! every rising edge is at a whole UTC second through that mapping, for consecutive seconds,
//! each pulse as wide as asked; once the mapping's σ exceeds the bound no edge comes and the
//! process counts the seconds without one.
//!
//! The bound on an edge's error. The simulated output records `CLOCK_MONOTONIC` when the
//! process raises its line, so an edge's error is user-space timing alone: the wake-up 2 ms
//! before the second (a timed sleep, which may be late), the spin to the second, and the
//! process not being descheduled between the spin's last clock reading and the edge's. The
//! process runs `SCHED_FIFO` 50 as its unit runs it (where the test may set it: root in CI).
//! Measured on the 2-core development machine, 7-8 edges a run: p50 1.6-2.1 µs, max 2-28 µs,
//! also with two CPU-bound processes beside it. The bound, p99 ≤ 500 µs and every edge ≤ 2 ms
//! (an edge later than 1 ms is not raised at all and is counted as `pulses_late`), leaves room
//! for a loaded CI machine running this binary's other tests side by side, while an output that
//! ignored the mapping's rate (1.2 ms off after 6 s at 200 ppm) or its offset (hundreds of ms)
//! fails. What it does not show: a GPIO line's or a PHC's own edge (no such hardware here; the
//! GPIO edge is the same code path with the ioctl in the place of the file write).

use std::time::{Duration, Instant};

use navsync_drivers::pulse_out::sim::parse_edge_line;
use navsync_shared::samples::{TimeState, TimeStatus};
use navsync_shared::services;
use navsync_shared::time::{NS_PER_S, monotonic_now_ns, realtime_now_ns};
use navsync_tests::{HealthWatch, TestEnv, quantile};

/// GNSS time minus the system clock in this test's mapping, ns.
const OFFSET_NS: i64 = 217_500_000;
/// d(UTC)/d(host) − 1 of the mapping: the host clock 200 ppm slow.
const RATE_ERROR: f64 = 2e-4;
/// `--width-ms`.
const WIDTH_MS: i64 = 100;

/// The edges in the output's file so far, `(host_ns, high)`.
fn edges(path: &std::path::Path) -> Vec<(i64, bool)> {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    // A line being written has no newline yet: only whole lines.
    let whole = &text[..text.rfind('\n').map_or(0, |i| i + 1)];
    whole
        .lines()
        .map(|l| parse_edge_line(l).unwrap_or_else(|| panic!("not an edge: {l:?}")))
        .collect()
}

/// Publishes `t` (fresh) every 100 ms for `d`, checking that the processes keep running.
fn publish_for(
    env: &mut TestEnv,
    publisher: &mut navsync_shared::ipc::Publisher<TimeState>,
    t: &mut TimeState,
    d: Duration,
) {
    let t0 = Instant::now();
    while t0.elapsed() < d {
        t.computed_host_ns = monotonic_now_ns();
        publisher.publish(t).unwrap();
        env.assert_running();
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn pps_out_raises_an_edge_at_each_gnss_second_of_the_mapping() {
    let mut env = TestEnv::new("ppsout");
    let node = env.node("mapping");
    let mut time_pub = node.publisher::<TimeState>(services::TIME_STATE).unwrap();
    let mut health = HealthWatch::new(&node, &["pps-out"]);
    let file = env.dir.join("edges.txt");
    let (h0, r0) = (monotonic_now_ns(), realtime_now_ns());
    let mut t = TimeState::unknown();
    t.status = TimeStatus::Locked as u8;
    t.ref_host_ns = h0;
    t.ref_utc_ns = r0 + OFFSET_NS;
    t.rate_error = RATE_ERROR;
    t.offset_std_ns = 500.0;
    t.rate_std = 1e-9;
    let pid = env.spawn(
        "pps-out",
        &[
            "pps-out",
            "--output",
            &format!("sim:{}", file.display()),
            "--width-ms",
            &WIDTH_MS.to_string(),
        ],
    );
    // As its unit runs it (CPUSchedulingPolicy=fifo, CPUSchedulingPriority=50), where this test
    // may (root, or CAP_SYS_NICE): a software-timed edge is as good as the process's scheduling.
    let scheduling = match navsync_bench::util::set_fifo(pid, 50) {
        Ok(()) => "SCHED_FIFO 50".to_string(),
        Err(e) => format!("not real-time ({e})"),
    };
    publish_for(&mut env, &mut time_pub, &mut t, Duration::from_millis(7500));

    // The mapping's σ over the bound (5 ms > 1000 µs): no more edges.
    let over_from = monotonic_now_ns();
    t.offset_std_ns = 5e6;
    publish_for(&mut env, &mut time_pub, &mut t, Duration::from_secs(3));
    let all = edges(&file);
    let rss_kib = navsync_tests::rss_kib(pid).unwrap_or(0);
    // Health is published once a second: wait for a report that shows the unusable seconds.
    let t_wait = Instant::now();
    while health.counter("pps-out", "pulses_not_written").unwrap_or(0) < 2 && t_wait.elapsed() < Duration::from_secs(5)
    {
        health.wait(Duration::from_millis(500));
    }
    let counter = |name: &str| health.counter("pps-out", name).unwrap_or(0);

    // Each rising edge and the falling edge after it.
    let mut pulses = Vec::new();
    for (i, &(at, high)) in all.iter().enumerate() {
        if high {
            let fall = all.get(i + 1).filter(|e| !e.1).map(|e| e.0);
            pulses.push((at, fall));
        }
    }
    // The edge's error: its UTC by the mapping minus the nearest whole second.
    let mut seconds = Vec::new();
    let mut errors_us = Vec::new();
    for &(rise, _) in &pulses {
        let utc = t.utc_ns_at(rise);
        let second = (utc + NS_PER_S / 2).div_euclid(NS_PER_S) * NS_PER_S;
        seconds.push(second);
        errors_us.push((utc - second) as f64 * 1e-3);
    }
    let mut abs: Vec<f64> = errors_us.iter().map(|e| e.abs()).collect();
    let (p50, p99, max) = (
        quantile(&mut abs, 0.5),
        quantile(&mut abs, 0.99),
        quantile(&mut abs, 1.0),
    );
    let widths_ms: Vec<f64> = pulses
        .iter()
        .filter_map(|&(r, f)| f.map(|f| (f - r) as f64 * 1e-6))
        .collect();
    println!(
        "{scheduling}, {} edges: error p50 {p50:.1} µs, p99 {p99:.1} µs, max {max:.1} µs (signed, µs: {errors_us:.1?}); \
         widths {widths_ms:.3?} ms; health: pulses {}, pulses_late {}, edge_late_p99_us {}, pulses_not_written {}; \
         resident {rss_kib} KiB",
        pulses.len(),
        counter("pulses"),
        counter("pulses_late"),
        counter("edge_late_p99_us"),
        counter("pulses_not_written"),
    );
    let log = env.log("pps-out");
    assert!(pulses.len() >= 5, "{} pulses in 7.5 s: {all:?}\n{log}", pulses.len());
    assert!(p99 <= 500.0 && max <= 2000.0, "edge errors (µs) {errors_us:?}\n{log}");
    assert!(
        errors_us.iter().all(|&e| e >= -0.01),
        "an edge before its second: {errors_us:?}"
    );
    // Consecutive seconds, but for edges the process could not raise in time and counted (the
    // counter covers the process's life, the capture a window of it: a late second before the
    // first edge captured or after the last is counted and leaves no gap).
    let gaps: i64 = seconds.windows(2).map(|w| (w[1] - w[0]) / NS_PER_S - 1).sum();
    assert!(
        seconds.windows(2).all(|w| w[1] > w[0]) && gaps <= counter("pulses_late") as i64,
        "seconds {seconds:?}, {gaps} missing, pulses_late {}",
        counter("pulses_late")
    );
    // The falling edge: a plain timed sleep (a sensor triggers on the rising edge), so late by
    // a wake-up's latency at most.
    assert_eq!(
        widths_ms.len(),
        pulses.len(),
        "a pulse without its falling edge: {all:?}"
    );
    assert!(
        widths_ms
            .iter()
            .all(|&w| (WIDTH_MS as f64..WIDTH_MS as f64 + 10.0).contains(&w)),
        "widths (ms) {widths_ms:?}"
    );
    // The σ over the bound: no edge after the process saw it (within one 200 ms wait and a
    // pulse), and the seconds without one counted.
    let after: Vec<_> = pulses.iter().filter(|p| p.0 > over_from + 300_000_000).collect();
    assert!(after.is_empty(), "edges with the σ over the bound: {after:?}");
    assert!(counter("pulses_not_written") >= 2, "{:?}", health.latest("pps-out"));
    assert_eq!(
        counter("pulses") as usize,
        pulses.len(),
        "{:?}",
        health.latest("pps-out")
    );
    drop((time_pub, health, node));
    env.finish();
}
