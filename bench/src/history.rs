//! `navsync-bench history`: the cost of a `state_at` query of the history of states
//! (`navsync_shared::history`) from another process than the writer's, while it writes.
//!
//! A helper process (`navsync-bench helper history-writer`) writes a state every millisecond
//! (a reference IMU at 1 kHz, the rate the capacity is made for) into a history of 10 s; this
//! process opens it and times each query (`CLOCK_MONOTONIC` around one call) at random
//! instants of the last 9 s, by host time (`state_at_host`) and by UTC (`state_at`).
//! docs/benchmarks/performance.md has the figures.

use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use navsync_shared::history::{self, History, HistoryWriter, Source};
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::NavState;
use navsync_shared::time::monotonic_now_ns;
use serde::Serialize;

use crate::util::{self, BenchEnv, Machine, Percentiles};

/// Options of `navsync-bench history`.
#[derive(clap::Args, Debug)]
pub struct HistoryArgs {
    /// Queries of each kind.
    #[arg(long, default_value_t = 200_000)]
    pub queries: usize,
    /// The smoke-test size (10 000 queries).
    #[arg(long)]
    pub quick: bool,
    /// Write the report as JSON to this file.
    #[arg(long)]
    pub json: Option<std::path::PathBuf>,
}

/// Options of the writer helper.
#[derive(clap::Args, Debug)]
pub struct WriterArgs {
    /// Seconds to write for.
    #[arg(long)]
    pub seconds: f64,
}

/// The report.
#[derive(Debug, Serialize)]
pub struct HistoryReport {
    /// `state_at_host` per query.
    pub state_at_host: Percentiles,
    /// `state_at` (UTC) per query.
    pub state_at: Percentiles,
    /// Queries that failed (none expected).
    pub failed: u64,
    /// Records the writer wrote during the queries.
    pub written: u64,
    /// The machine.
    pub machine: Machine,
}

const UTC0_NS: i64 = 1_700_000_000_000_000_000;

static STOP: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

extern "C" fn on_sigterm(_: libc::c_int) {
    STOP.store(true, std::sync::atomic::Ordering::Relaxed);
}

/// The writer: one state a millisecond, on a circle at 20 m/s, until `seconds` pass or SIGTERM.
pub fn helper_writer(a: &WriterArgs) -> Result<()> {
    let mut w = HistoryWriter::create(&navsync_shared::ipc::prefix(), history::capacity_for(10.0))?;
    // SAFETY: the handler only stores to an atomic.
    unsafe { libc::signal(libc::SIGTERM, on_sigterm as *const () as libc::sighandler_t) };
    println!("ready");
    let t0 = Instant::now();
    let mut s = NavState::zeroed();
    let mut next = monotonic_now_ns();
    while t0.elapsed().as_secs_f64() < a.seconds && !STOP.load(std::sync::atomic::Ordering::Relaxed) {
        let now = monotonic_now_ns();
        let t = now as f64 * 1e-9;
        let (sn, cn) = (t * 0.2).sin_cos();
        s.host_ns = now;
        s.utc_ns = UTC0_NS + now;
        s.lat_deg = 48.0 + sn * 1e-3;
        s.lon_deg = 11.0 + cn * 1.5e-3;
        s.height_m = 500.0;
        s.vel_ned_mps = [20.0 * cn, -20.0 * sn, 0.0];
        let y = t * 0.1;
        s.q_nb = [y.cos(), 0.0, 0.0, y.sin()];
        s.pos_std_ned_m = [0.5; 3];
        w.append(&s, Source::Predicted);
        next += 1_000_000;
        let wait = next - monotonic_now_ns();
        if wait > 0 {
            std::thread::sleep(Duration::from_nanos(wait as u64));
        }
    }
    Ok(())
}

/// Runs the benchmark.
pub fn run(a: &HistoryArgs) -> Result<HistoryReport> {
    let n = if a.quick { 10_000 } else { a.queries };
    let mut machine = Machine::now();
    let mut env = BenchEnv::new("hist")?;
    let secs = if a.quick { 15.0 } else { 60.0 };
    let (_, out) = env.spawn(
        "writer",
        &[
            "helper".into(),
            "history-writer".into(),
            "--seconds".into(),
            secs.to_string(),
        ],
        true,
    )?;
    let mut out = std::io::BufReader::new(out.context("writer stdout")?);
    if !util::wait_for_line(&mut out, "ready", Duration::from_secs(10)) {
        bail!("the writer did not start: {}", env.log("writer"));
    }
    let h = History::open_prefix(&env.prefix)?;
    // A full ring first (10 s at 1 kHz), or 2 s for the smoke test.
    let fill = if a.quick { 2_000 } else { 9_990 };
    let t0 = Instant::now();
    while h.write_index() < fill {
        if t0.elapsed() > Duration::from_secs(20) {
            bail!("the writer wrote {} records", h.write_index());
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let (mut by_host, mut by_utc) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let mut failed = 0u64;
    let w0 = h.write_index();
    let mut x = 0x9e37_79b9_7f4a_7c15u64;
    let back_ns = (fill as i64 - 10) * 1_000_000;
    for _ in 0..n {
        x = x
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        let t = monotonic_now_ns() - 2_000_000 - ((x >> 11) % back_ns as u64) as i64;
        let s = Instant::now();
        let r = h.state_at_host(t);
        by_host.push(s.elapsed().as_nanos() as i64);
        failed += u64::from(r.is_err());
        let s = Instant::now();
        let r = h.state_at(UTC0_NS + t);
        by_utc.push(s.elapsed().as_nanos() as i64);
        failed += u64::from(r.is_err());
    }
    let written = h.write_index() - w0;
    drop(h);
    let bad = env.stop_all();
    machine.finish();
    let report = HistoryReport {
        state_at_host: Percentiles::from_ns(&mut by_host),
        state_at: Percentiles::from_ns(&mut by_utc),
        failed,
        written,
        machine,
    };
    let p = |name: &str, q: &Percentiles| {
        println!(
            "{name:<14} {:>8} queries  p50 {:.2} µs  p99 {:.2} µs  p99.9 {:.2} µs  max {:.1} µs",
            q.count, q.p50_us, q.p99_us, q.p999_us, q.max_us
        )
    };
    p("state_at_host", &report.state_at_host);
    p("state_at", &report.state_at);
    println!(
        "failed {failed}; the writer wrote {written} records meanwhile (1 kHz)\n{}",
        report.machine.line()
    );
    if let Some(path) = &a.json {
        util::write_json(path, &report)?;
    }
    if !bad.is_empty() {
        bail!("the writer did not exit cleanly: {}", env.log("writer"));
    }
    if failed > 0 {
        bail!("{failed} queries failed");
    }
    Ok(report)
}
