//! `navsync-bench zenoh`: a NavState published on host A's iceoryx2 → `navsync bridge zenoh`
//! (namespace A) → TCP over a veth link → `navsync bridge zenoh --import` (namespace B) → a
//! subscriber on host B's iceoryx2; latency from the publish (`host_ns`, the machine's one
//! `CLOCK_MONOTONIC`) to the receipt, at each rate, and the bridges' CPU time per message.
//! Needs root (network namespaces) and a navsync built with its default feature `zenoh`.

use std::time::{Duration, Instant};

use navsync_shared::ipc::IpcNode;
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::NavState;
use navsync_shared::services::{NAV_STATE, PREFIX_ENV};
use navsync_shared::time::monotonic_now_ns;
use serde::Serialize;

use crate::netns::{NetnsPair, StopOnDrop as Child};
use crate::util::{BenchEnv, Machine, Percentiles, cpu_time_s, navsync_exe, write_json};

/// `navsync-bench zenoh`.
#[derive(Debug, Clone, clap::Args)]
pub struct ZenohBenchArgs {
    /// Publish rates, Hz.
    #[arg(long, value_delimiter = ',', default_value = "100,1000")]
    pub rates: Vec<f64>,
    /// Seconds measured per rate.
    #[arg(long, default_value = "10")]
    pub duration: f64,
    /// The smoke-test size (1 s per rate).
    #[arg(long)]
    pub quick: bool,
    /// Write the report as JSON.
    #[arg(long)]
    pub json: Option<std::path::PathBuf>,
}

/// One rate's result.
#[derive(Debug, Clone, Serialize)]
pub struct ZenohCase {
    /// Publish rate, Hz.
    pub rate_hz: f64,
    /// NavStates published on host A.
    pub sent: u64,
    /// NavStates received on host B.
    pub received: u64,
    /// Publish → receipt latency.
    pub latency: Percentiles,
    /// CPU time per message of host A's bridge, µs.
    pub bridge_a_cpu_us_per_msg: f64,
    /// CPU time per message of host B's bridge, µs.
    pub bridge_b_cpu_us_per_msg: f64,
}

/// The report.
#[derive(Debug, Clone, Serialize)]
pub struct ZenohReport {
    /// The machine during the run.
    pub machine: Machine,
    /// One per rate.
    pub cases: Vec<ZenohCase>,
}

/// Errors of the benchmark.
#[derive(Debug, thiserror::Error)]
pub enum ZenohBenchError {
    /// Setting up.
    #[error("{0}")]
    Setup(String),
}

fn setup<E: std::fmt::Display>(what: &str) -> impl Fn(E) -> ZenohBenchError + '_ {
    move |e| ZenohBenchError::Setup(format!("{what}: {e}"))
}

/// Runs every rate; prints the table.
pub fn run(args: &ZenohBenchArgs) -> Result<ZenohReport, ZenohBenchError> {
    let mut machine = Machine::now();
    let link =
        NetnsPair::new("nzb").map_err(|e| ZenohBenchError::Setup(format!("network namespaces (root needed): {e}")))?;
    let mut cases = Vec::new();
    for &rate in &args.rates {
        let secs = if args.quick { 1.0 } else { args.duration };
        cases.push(run_case(&link, rate, secs)?);
    }
    machine.finish();
    let r = ZenohReport { machine, cases };
    println!("{}", table(&r));
    if let Some(p) = &args.json {
        write_json(p, &r).map_err(setup("writing the JSON"))?;
    }
    if r.cases.iter().any(|c| c.received == 0) {
        return Err(ZenohBenchError::Setup("a rate delivered nothing to host B".into()));
    }
    Ok(r)
}

fn run_case(link: &NetnsPair, rate: f64, secs: f64) -> Result<ZenohCase, ZenohBenchError> {
    let (a, b) = (
        BenchEnv::new("zna").map_err(setup("scratch"))?,
        BenchEnv::new("znb").map_err(setup("scratch"))?,
    );
    let exe = navsync_exe().map_err(setup("the navsync binary"))?;
    let endpoint = format!("tcp/{}:7447", link.addr[0]);
    let spawn = |i: usize, env: &BenchEnv, args: &[&str], name: &str| -> Result<Child, ZenohBenchError> {
        let log = std::fs::File::create(env.dir.join(format!("{name}.log"))).map_err(setup("log"))?;
        link.command(i, &exe, args)
            .env(PREFIX_ENV, &env.prefix)
            .env("RUST_LOG", "warn")
            .stdout(std::process::Stdio::null())
            .stderr(log)
            .spawn()
            .map(Child)
            .map_err(setup("starting a bridge"))
    };
    let bridge_a = spawn(
        0,
        &a,
        &[
            "bridge",
            "zenoh",
            "--instance",
            "benchA",
            "--export",
            NAV_STATE,
            "--listen",
            &endpoint,
        ],
        "bridge",
    )?;
    let bridge_b = spawn(
        1,
        &b,
        &[
            "bridge",
            "zenoh",
            "--instance",
            "benchB",
            "--no-export",
            "--import",
            "benchA",
            "--connect",
            &endpoint,
        ],
        "bridge",
    )?;
    // Host B's subscriber on its own thread (and node), measuring receipt - host_ns.
    let (tx, rx) = std::sync::mpsc::channel::<Vec<(u64, i64)>>();
    let prefix_b = b.prefix.clone();
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let stop2 = stop.clone();
    let heard = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
    let heard2 = heard.clone();
    let sub_thread = std::thread::spawn(move || {
        let mut got = Vec::new();
        let Ok(node) = IpcNode::with_prefix("bench-sub", &prefix_b) else {
            let _ = tx.send(got);
            return;
        };
        let Ok(sub) = node.subscriber::<NavState>(NAV_STATE) else {
            let _ = tx.send(got);
            return;
        };
        while !stop2.load(std::sync::atomic::Ordering::Relaxed) {
            if let Ok(Some(n)) = sub.wait_next(Duration::from_millis(50)) {
                got.push((n.seq, monotonic_now_ns() - n.host_ns));
                heard2.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            }
        }
        let _ = tx.send(got);
    });
    let node = IpcNode::with_prefix("bench-pub", &a.prefix).map_err(setup("host A's node"))?;
    let mut publisher = node
        .publisher::<NavState>(NAV_STATE)
        .map_err(setup("host A's publisher"))?;
    let period = Duration::from_secs_f64(1.0 / rate);
    let mut seq = 0u64;
    let mut publish = |seq: &mut u64| {
        let mut n = NavState::zeroed();
        *seq += 1;
        n.seq = *seq;
        n.host_ns = monotonic_now_ns();
        let _ = publisher.publish(&n);
    };
    // Warm-up at 100 Hz: until host B hears (at most 15 s), then 1 s more.
    let t0 = Instant::now();
    let mut heard_at: Option<Instant> = None;
    loop {
        publish(&mut seq);
        std::thread::sleep(Duration::from_millis(10));
        if heard_at.is_none() && heard.load(std::sync::atomic::Ordering::Relaxed) > 0 {
            heard_at = Some(Instant::now());
        }
        if heard_at.is_some_and(|t| t.elapsed() > Duration::from_secs(1)) {
            break;
        }
        if t0.elapsed() > Duration::from_secs(15) {
            return Err(ZenohBenchError::Setup(format!(
                "nothing reached host B in 15 s; bridge A: {}; bridge B: {}",
                a.log("bridge"),
                b.log("bridge")
            )));
        }
    }
    let first_measured = seq + 1;
    let cpu = |c: &Child| cpu_time_s(c.0.id()).unwrap_or(f64::NAN);
    let (cpu_a0, cpu_b0) = (cpu(&bridge_a), cpu(&bridge_b));
    let n = (rate * secs).round() as u64;
    let start = Instant::now();
    for k in 0..n {
        let due = start + period.mul_f64(k as f64);
        let now = Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
        publish(&mut seq);
    }
    std::thread::sleep(Duration::from_millis(500));
    let (cpu_a1, cpu_b1) = (cpu(&bridge_a), cpu(&bridge_b));
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let got = rx.recv().unwrap_or_default();
    let _ = sub_thread.join();
    drop((bridge_a, bridge_b));
    let mut lat: Vec<i64> = got
        .iter()
        .filter(|(s, _)| *s >= first_measured)
        .map(|(_, l)| *l)
        .collect();
    let received = lat.len() as u64;
    let per = |c: f64| c * 1e6 / received.max(1) as f64;
    Ok(ZenohCase {
        rate_hz: rate,
        sent: n,
        received,
        latency: Percentiles::from_ns(&mut lat),
        bridge_a_cpu_us_per_msg: per(cpu_a1 - cpu_a0),
        bridge_b_cpu_us_per_msg: per(cpu_b1 - cpu_b0),
    })
}

/// The table of docs/benchmarks/performance.md ("Zenoh bridge latency").
pub fn table(r: &ZenohReport) -> String {
    let mut s = String::from(
        "| rate | sent | received | p50 µs | p99 µs | p99.9 µs | max µs | bridge A CPU µs/msg | bridge B CPU µs/msg |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    for c in &r.cases {
        s.push_str(&format!(
            "| {:.0} Hz | {} | {} | {:.0} | {:.0} | {:.0} | {:.0} | {:.1} | {:.1} |\n",
            c.rate_hz,
            c.sent,
            c.received,
            c.latency.p50_us,
            c.latency.p99_us,
            c.latency.p999_us,
            c.latency.max_us,
            c.bridge_a_cpu_us_per_msg,
            c.bridge_b_cpu_us_per_msg
        ));
    }
    s.push_str(&r.machine.line());
    s
}
