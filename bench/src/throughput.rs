//! `navsync-bench throughput`: how many IMU samples per second the estimator library takes on
//! one core, for 1, 4 and 8 IMUs, and whether its cost per sample stays flat over an hour.
//!
//! The simulated world's published samples (what the drivers would publish: IMU samples, PPS
//! edges, fixes decoded from NMEA; [`PublishedStream`]) are produced in batches of at most
//! 10 s of scenario time, outside the measurement; each batch then goes through the input
//! order and the estimator pipeline exactly as in `navsync estimator` and `replay --estimate`,
//! timed as a whole (no clock reads per sample). The cost of each 10-minute block of scenario
//! time is reported separately, so that growth over a long run shows.

use std::path::PathBuf;
use std::time::Instant;

use navsync_shared::samples::AnySample;
use navsync_shared::time::NS_PER_S;
use navsync_sim::error::SimError;
use navsync_sim::process::{SimArgs, load_config};
use navsync_sim::published::PublishedStream;
use navsync_sim::world::World;
use serde::Serialize;

use crate::util::{self, Machine};
use navsync_estimator::input_order::{Input, InputOrder};
use navsync_estimator::pipeline::Pipeline;
use navsync_estimator::settings::Settings;

/// Default length of a cost block, s of scenario time.
pub const BLOCK_S: f64 = 600.0;
/// Longest batch produced before it is estimated, s of scenario time.
const BATCH_S: i64 = 10;

/// `navsync-bench throughput`: estimator throughput (IMU samples/s, one core) for several IMU
/// counts; `--hour`: the cost per sample per 10 minutes of a one-hour drive.
#[derive(Debug, Clone, clap::Args)]
pub struct ThroughputArgs {
    /// IMU counts, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "1,4,8", value_parser = crate::util::imu_count)]
    pub imus: Vec<usize>,
    /// Scenario file (default: the embedded 10-minute drive).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Seconds of scenario to run (default: all of it).
    #[arg(long = "duration")]
    pub duration_s: Option<f64>,
    /// Block length for the cost table, s.
    #[arg(skip = BLOCK_S)]
    pub block_s: f64,
    /// The one-hour drive (sim/scenarios/long_drive_1h.toml, embedded), one IMU, cost per 10 minutes.
    #[arg(long, conflicts_with_all = ["scenario", "imus"])]
    pub hour: bool,
    /// A short run (60 s of scenario, 1 and 4 IMUs) for smoke tests.
    #[arg(long)]
    pub quick: bool,
    /// Write the results as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// The one-hour drive of `navsync-bench throughput --hour`.
pub const LONG_DRIVE_1H: &str = include_str!("../../sim/scenarios/long_drive_1h.toml");

/// The cost of one block of scenario time.
#[derive(Debug, Clone, Serialize)]
pub struct Block {
    /// Start of the block, s of scenario time.
    pub start_s: f64,
    /// End of the block, s of scenario time.
    pub end_s: f64,
    /// IMU samples in it.
    pub imu_samples: u64,
    /// Estimator time, s.
    pub estimator_s: f64,
    /// Estimator time per IMU sample, ns.
    pub ns_per_sample: f64,
}

/// One IMU count's figures.
#[derive(Debug, Clone, Serialize)]
pub struct ThroughputCase {
    /// IMUs fused.
    pub imus: usize,
    /// IMU rate, Hz (of the first IMU).
    pub imu_rate_hz: f64,
    /// Scenario seconds.
    pub scenario_s: f64,
    /// IMU samples (all IMUs).
    pub imu_samples: u64,
    /// NavStates produced.
    pub nav_states: u64,
    /// Time spent in the estimator (input order + pipeline), s.
    pub estimator_s: f64,
    /// IMU samples per second of estimator time.
    pub imu_samples_per_s: f64,
    /// Estimator time per IMU sample, ns.
    pub ns_per_sample: f64,
    /// Time spent producing the samples (simulator; not part of the figure above), s.
    pub simulator_s: f64,
    /// Cost per block of scenario time.
    pub blocks: Vec<Block>,
    /// Peak resident set size of the benchmark process after this case, KiB.
    pub peak_rss_kib: u64,
}

/// Everything `navsync-bench throughput` measured.
#[derive(Debug, Clone, Serialize)]
pub struct ThroughputReport {
    /// The machine and its load.
    pub machine: Machine,
    /// One entry per IMU count.
    pub cases: Vec<ThroughputCase>,
}

/// Runs one IMU count.
pub fn run_case(args: &ThroughputArgs, imus: usize) -> Result<ThroughputCase, SimError> {
    let cfg = load_config(&SimArgs {
        scenario: args.scenario.clone(),
        imus: Some(imus),
        ..Default::default()
    })?;
    let est = {
        let mut s = Settings::default();
        s.inputs.imus = (0..cfg.imu.count).map(|i| i.to_string()).collect();
        s.imu.imu_model = cfg.imu.preset;
        s.gnss.gnss_vel_std_mps = cfg.gnss.velocity_sigma_mps.max(0.01);
        s
    };
    let start_host = 1_000_000_000_000i64;
    let start_utc = 1_790_000_000 * NS_PER_S;
    let world = World::new(&cfg, start_host, start_utc)?;
    let scenario_s = args.duration_s.unwrap_or(f64::INFINITY).min(world.duration_s());
    let end_host = start_host + (scenario_s * 1e9) as i64;
    let pcfg = est.pipeline_config();
    let mut order: InputOrder<()> = InputOrder::new(Some(&pcfg.reference_imu));
    let mut pipeline = Pipeline::new(pcfg);
    let mut stream = PublishedStream::new(world)
        .take_while(|p| p.delivered_ns <= end_host)
        .map(|p| p.sample)
        .filter(|s| !matches!(s, AnySample::Truth(_)))
        .peekable();
    let block_ns = (args.block_s * 1e9) as i64;
    let n_blocks = ((scenario_s / args.block_s).ceil() as usize).max(1);
    let mut blocks: Vec<Block> = (0..n_blocks)
        .map(|i| Block {
            start_s: i as f64 * args.block_s,
            end_s: ((i + 1) as f64 * args.block_s).min(scenario_s),
            imu_samples: 0,
            estimator_s: 0.0,
            ns_per_sample: f64::NAN,
        })
        .collect();
    let mut batch: Vec<AnySample> = Vec::with_capacity(200_000);
    let (mut sim_s, mut nav_states) = (0.0, 0u64);
    loop {
        // Produce one batch: up to BATCH_S of scenario time, never across a block boundary.
        let t = Instant::now();
        batch.clear();
        let Some(first) = stream.peek() else { break };
        let rel = first.host_ns() - start_host;
        let block = ((rel.max(0) / block_ns) as usize).min(n_blocks - 1);
        let batch_end = (rel + BATCH_S * NS_PER_S).min((block as i64 + 1) * block_ns) + start_host;
        while let Some(s) = stream.next_if(|s| s.host_ns() < batch_end || batch.is_empty()) {
            batch.push(s);
        }
        sim_s += t.elapsed().as_secs_f64();
        let imu_in_batch = batch.iter().filter(|s| matches!(s, AnySample::Imu(_))).count() as u64;
        // Estimate it.
        let t = Instant::now();
        for s in batch.drain(..) {
            order.push(s, ());
            while let Some((s, ())) = order.pop() {
                nav_states += u64::from(feed(&mut pipeline, &s));
            }
        }
        let dt = t.elapsed().as_secs_f64();
        blocks[block].imu_samples += imu_in_batch;
        blocks[block].estimator_s += dt;
    }
    let t = Instant::now();
    while let Some((s, ())) = order.pop_any() {
        nav_states += u64::from(feed(&mut pipeline, &s));
    }
    if let Some(last) = blocks.last_mut() {
        last.estimator_s += t.elapsed().as_secs_f64();
    }
    for b in &mut blocks {
        b.ns_per_sample = b.estimator_s / b.imu_samples.max(1) as f64 * 1e9;
    }
    blocks.retain(|b| b.imu_samples > 0);
    let imu_samples: u64 = blocks.iter().map(|b| b.imu_samples).sum();
    let estimator_s: f64 = blocks.iter().map(|b| b.estimator_s).sum();
    Ok(ThroughputCase {
        imus,
        imu_rate_hz: cfg.imu_unit(0).rate_hz,
        scenario_s,
        imu_samples,
        nav_states,
        estimator_s,
        imu_samples_per_s: imu_samples as f64 / estimator_s,
        ns_per_sample: estimator_s / imu_samples.max(1) as f64 * 1e9,
        simulator_s: sim_s,
        blocks,
        peak_rss_kib: util::peak_rss_kib(std::process::id()).unwrap_or(0),
    })
}

/// One sample into the pipeline; true when it produced a NavState.
fn feed(p: &mut Pipeline, s: &Input) -> bool {
    match s {
        Input::Imu(x) => p.on_imu(x).is_some(),
        Input::GnssFix(f) => {
            p.on_fix(f);
            false
        }
        Input::PpsEdge(e) => {
            p.on_pps(e);
            false
        }
        _ => false,
    }
}

/// Runs every IMU count, prints the tables, writes the JSON.
pub fn run(args: &ThroughputArgs) -> Result<ThroughputReport, ThroughputError> {
    let mut args = args.clone();
    // The hour-long drive is embedded, so the command runs from any directory.
    let hour_file = args
        .hour
        .then(|| std::env::temp_dir().join(format!("navsync-long-drive-{}.toml", std::process::id())));
    if let Some(p) = &hour_file {
        std::fs::write(p, LONG_DRIVE_1H).map_err(ThroughputError::Io)?;
        (args.imus, args.scenario) = (vec![1], Some(p.clone()));
    } else if args.quick {
        (args.imus, args.duration_s, args.block_s) = (vec![1, 4], Some(60.0), 20.0);
    }
    let r = run_cases(&args);
    if let Some(p) = hour_file {
        let _ = std::fs::remove_file(p);
    }
    r
}

fn run_cases(args: &ThroughputArgs) -> Result<ThroughputReport, ThroughputError> {
    let mut report = ThroughputReport {
        machine: Machine::now(),
        cases: Vec::new(),
    };
    for &n in &args.imus {
        let c = run_case(args, n)?;
        eprintln!(
            "{} IMU(s): {:.0} samples/s ({:.0} ns/sample) over {} samples",
            c.imus, c.imu_samples_per_s, c.ns_per_sample, c.imu_samples
        );
        report.cases.push(c);
    }
    report.machine.finish();
    println!("{}", table(&report));
    if let Some(p) = &args.json {
        util::write_json(p, &report).map_err(ThroughputError::Io)?;
    }
    Ok(report)
}

/// The Markdown tables of a report: one row per IMU count, then the cost per block of each.
pub fn table(r: &ThroughputReport) -> String {
    let mut s = String::from(
        "| IMUs | IMU rate | scenario | IMU samples | estimator time | IMU samples/s | ns/sample | NavStates | simulator time |\n\
         |---|---|---|---|---|---|---|---|---|\n",
    );
    for c in &r.cases {
        s.push_str(&format!(
            "| {} | {} Hz | {:.0} s | {} | {:.2} s | {:.0} | {:.0} | {} | {:.2} s |\n",
            c.imus,
            c.imu_rate_hz,
            c.scenario_s,
            c.imu_samples,
            c.estimator_s,
            c.imu_samples_per_s,
            c.ns_per_sample,
            c.nav_states,
            c.simulator_s
        ));
    }
    for c in r.cases.iter().filter(|c| c.blocks.len() > 1) {
        s.push_str(&format!(
            "\n{} IMU(s), cost per block of scenario time:\n\n| block | IMU samples | ns/sample |\n|---|---|---|\n",
            c.imus
        ));
        for b in &c.blocks {
            s.push_str(&format!(
                "| {:.0}–{:.0} s | {} | {:.0} |\n",
                b.start_s, b.end_s, b.imu_samples, b.ns_per_sample
            ));
        }
    }
    s.push('\n');
    s.push_str(&r.machine.line());
    s
}

/// Errors of the throughput benchmark.
#[derive(Debug, thiserror::Error)]
pub enum ThroughputError {
    /// Bad scenario.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// Writing the JSON.
    #[error(transparent)]
    Io(std::io::Error),
}
