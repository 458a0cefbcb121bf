//! `navsync-bench host`: what the machine itself does to a periodic sleeper, with no navsync
//! code in the way. One thread per online CPU, pinned to it, sleeps to absolute
//! CLOCK_MONOTONIC instants at a fixed rate and records how late each wake-up is. Read beside
//! the other benchmarks: a transport's p99.9 cannot be better than the stalls measured here.
//!
//! A host that stops the VM now and then (CPU quota, other tenants) shows as wake-ups late by
//! milliseconds; when those stalls keep one phase of a 100 ms cycle (the default period of
//! Linux's CFS bandwidth control, `cpu.max`), the phase concentration is high: the share of
//! stalls in the busiest 10 ms of the cycle, 10 % for stalls unrelated to such a period.
//! The median lateness is the cost of a timer wake-up; with `--idle-polling` beside a run
//! without, the part of it that is waking a halted CPU.

use std::path::PathBuf;

use serde::Serialize;

use navsync_shared::pacing;
use navsync_shared::time::monotonic_now_ns;

use crate::util::{self, Machine, Percentiles};

/// The cycle whose phase the stalls are binned in, ns.
const CYCLE_NS: i64 = 100_000_000;
/// Phase bins of the cycle (10 ms each).
const PHASE_BINS: usize = 10;

/// `navsync-bench host`.
#[derive(Debug, Clone, clap::Args)]
pub struct HostArgs {
    /// Measured time, s.
    #[arg(long = "duration", default_value_t = 30.0)]
    pub duration_s: f64,
    /// Wake-ups per second per CPU.
    #[arg(long, default_value_t = 1000.0)]
    pub rate: f64,
    /// A wake-up later than this is a stall, µs.
    #[arg(long = "stall", default_value_t = 1000.0)]
    pub stall_us: f64,
    /// Hold the CPU wake-up latency at 0 µs (idle CPUs poll instead of halting), as
    /// `navsync-bench e2e --idle-polling`: the difference is what waking a halted CPU costs.
    #[arg(long)]
    pub idle_polling: bool,
    /// A short run (3 s) for smoke tests.
    #[arg(long)]
    pub quick: bool,
    /// Write the results as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// One CPU's figures.
#[derive(Debug, Clone, Serialize)]
pub struct CpuFigures {
    /// The CPU the sleeper was pinned to.
    pub cpu: usize,
    /// Wake-up lateness (after the requested instant).
    pub lateness: Percentiles,
    /// Wake-ups late by more than the stall threshold.
    pub stalls: u64,
    /// Stalls per 10 ms phase bin of a 100 ms cycle from the start.
    pub stall_phase_bins: [u64; PHASE_BINS],
}

/// The report.
#[derive(Debug, Clone, Serialize)]
pub struct HostReport {
    /// Machine facts.
    pub machine: Machine,
    /// Requested wake-ups per CPU.
    pub expected_per_cpu: u64,
    /// Stall threshold, µs.
    pub stall_us: f64,
    /// Per CPU.
    pub cpus: Vec<CpuFigures>,
    /// All CPUs' stalls in the busiest phase bin, % of all stalls (10 % if unrelated to a
    /// 100 ms cycle; none without stalls).
    pub phase_concentration_percent: Option<f64>,
}

/// Errors.
#[derive(Debug, thiserror::Error)]
pub enum HostError {
    /// Bad option.
    #[error("{0}")]
    Option(String),
    /// A sleeper could not run or ran short.
    #[error("{0}")]
    Sleeper(String),
    /// I/O.
    #[error(transparent)]
    Io(#[from] std::io::Error),
}

/// Sleeps `n` times at `period_ns` from a common start on `cpu`; the lateness of each, ns.
fn sleeper(cpu: usize, t0: i64, period_ns: i64, n: u64) -> Result<Vec<i64>, HostError> {
    util::pin_this_thread(&[cpu]).map_err(|e| HostError::Sleeper(format!("CPU {cpu}: {e}")))?;
    // Timer slack 1 ns (default 50 µs): the lateness is then the wake-up path's alone.
    navsync_shared::pacing::minimal_timer_slack();
    let mut late = Vec::with_capacity(n as usize);
    for i in 1..=n as i64 {
        let target = t0 + i * period_ns;
        // No spin: the sleep's own wake-up is what is measured.
        while monotonic_now_ns() < target {
            pacing::sleep_until(target, 0);
        }
        late.push(monotonic_now_ns() - target);
    }
    Ok(late)
}

/// Runs the sleepers, prints the table, writes the JSON.
pub fn run(args: &HostArgs) -> Result<HostReport, HostError> {
    let duration_s = if args.quick { 3.0 } else { args.duration_s };
    if !(args.rate.is_finite() && args.rate > 0.0 && args.rate <= 100_000.0) {
        return Err(HostError::Option(format!("--rate {}: 0 < rate ≤ 100000 Hz", args.rate)));
    }
    for (name, v) in [("--duration", duration_s), ("--stall", args.stall_us)] {
        if !(v.is_finite() && v > 0.0) {
            return Err(HostError::Option(format!("{name} {v}: must be a positive number")));
        }
    }
    let period_ns = (1e9 / args.rate).round() as i64;
    let n = (duration_s * args.rate).round().max(1.0) as u64;
    let mut machine = Machine::now();
    let _wakeup = util::wakeup_hold(args.idle_polling, &mut machine);
    // A common start a little ahead, so every sleeper's cycle has the same phase.
    let t0 = monotonic_now_ns() + 50_000_000;
    let threads: Vec<_> = (0..util::online_cpus())
        .map(|cpu| (cpu, std::thread::spawn(move || sleeper(cpu, t0, period_ns, n))))
        .collect();
    let stall_ns = (args.stall_us * 1e3) as i64;
    let mut cpus = Vec::new();
    let mut all_bins = [0u64; PHASE_BINS];
    for (cpu, t) in threads {
        let mut late = t
            .join()
            .map_err(|_| HostError::Sleeper(format!("CPU {cpu}: the sleeper panicked")))??;
        if late.len() as u64 != n {
            return Err(HostError::Sleeper(format!("CPU {cpu}: {} of {n} wake-ups", late.len())));
        }
        let mut bins = [0u64; PHASE_BINS];
        for (i, &l) in late.iter().enumerate() {
            if l > stall_ns {
                let phase = ((i as i64 + 1) * period_ns).rem_euclid(CYCLE_NS);
                bins[(phase * PHASE_BINS as i64 / CYCLE_NS) as usize] += 1;
            }
        }
        for (a, b) in all_bins.iter_mut().zip(bins) {
            *a += b;
        }
        cpus.push(CpuFigures {
            cpu,
            lateness: Percentiles::from_ns(&mut late),
            stalls: bins.iter().sum(),
            stall_phase_bins: bins,
        });
    }
    machine.finish();
    let total: u64 = all_bins.iter().sum();
    let report = HostReport {
        machine,
        expected_per_cpu: n,
        stall_us: args.stall_us,
        cpus,
        phase_concentration_percent: (total > 0)
            .then(|| 100.0 * all_bins.iter().copied().max().unwrap_or(0) as f64 / total as f64),
    };
    println!("{}", table(&report));
    if let Some(p) = &args.json {
        util::write_json(p, &report)?;
    }
    Ok(report)
}

fn table(r: &HostReport) -> String {
    let mut s = format!(
        "| CPU | wake-ups | lateness p50 / p99 / p99.9 / max µs | stalls > {} µs | stalls per 10 ms of a 100 ms cycle |\n|---|---|---|---|---|\n",
        r.stall_us
    );
    for c in &r.cpus {
        s += &format!(
            "| {} | {} | {:.0} / {:.0} / {:.0} / {:.0} | {} | {:?} |\n",
            c.cpu,
            c.lateness.count,
            c.lateness.p50_us,
            c.lateness.p99_us,
            c.lateness.p999_us,
            c.lateness.max_us,
            c.stalls,
            c.stall_phase_bins
        );
    }
    s += &match r.phase_concentration_percent {
        Some(p) => format!("stalls in the busiest 10 ms of a 100 ms cycle: {p:.0} % (10 % if unrelated to it)\n"),
        None => "no stalls\n".to_string(),
    };
    s += &r.machine.line();
    s
}
