//! `navsync-bench e2e`: end-to-end latency of the live pipeline, CPU and memory of every
//! process, under a 1 kHz load.
//!
//! Processes, as `navsync demo` runs them (each under the benchmark's own iceoryx2 prefix):
//! `navsync sim` (the embedded `sim/scenarios/bench_1khz.toml`: every IMU at 1 kHz, GNSS at
//! 10 Hz at 460800 Bd) writing each IMU's Xsens MTData2 messages into a pseudo-terminal and
//! NMEA into another, one `navsync imu --source xsens:…` driver per IMU, `navsync gps`,
//! `navsync pps --source sim`, `navsync estimator` over all IMUs, and an independent
//! subscriber (`navsync-bench helper e2e-sub`) on `navsync/nav/state` and the reference
//! IMU's `navsync/imu/0/sample`.
//!
//! What is measured: an IMU driver stamps each sample with the `CLOCK_MONOTONIC` instant its
//! read returned with the message's last byte (`stamp.host_ns`), then decodes, checks and
//! publishes it; the estimator (run with `--no-device-clocks`, so that it fuses each sample at
//! that stamp) gives the `NavState` for that sample the same `host_ns`. The
//! subscriber takes `CLOCK_MONOTONIC` when it has the `NavState` in hand: **end-to-end =
//! receipt of the NavState − host_ns**, i.e. driver decode + publish, IPC, the estimator's
//! wake-up, input ordering and filter, its publish, IPC and the subscriber's wake-up. The
//! subscriber also receives the IMU sample itself and splits the figure into driver → subscriber
//! (receipt of the IMU sample − host_ns) and the rest (NavState − IMU sample receipt).
//! With `--imu-path direct` the simulator publishes the IMU samples itself (no drivers, no
//! pseudo-terminals) right after waking at the sample's stamp, so the figure then also holds
//! the simulator's wake-up lateness.
//!
//! CPU is `utime + stime` from `/proc/PID/stat` over the measured window; memory is each
//! process's peak RSS (`VmHWM`) at the end.
//!
//! `--compare-web` runs each case five times, side by side: as above, then with a watched
//! vehicle's extra load ([`web_load`]): `navsync web` with its Foxglove server, an open page and
//! a scrape of `/metrics` every second, then also a Foxglove client subscribed to the NavState,
//! then to every channel, and last unwatched again (the run-to-run spread). Their cost to the
//! estimator is the difference of the rows.

mod web_load;

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use navsync_shared::ipc::{IpcError, IpcNode};
use navsync_shared::samples::{ImuSample, NavState};
use navsync_shared::services;
use navsync_shared::time::{NS_PER_S, monotonic_now_ns};
use serde::Serialize;

use crate::util::{self, BenchEnv, Machine, Percentiles};

/// The scenario of the benchmark (IMUs at 1 kHz, GNSS at 10 Hz).
pub const BENCH_SCENARIO: &str = include_str!("../../sim/scenarios/bench_1khz.toml");
/// Line rate of the simulated GNSS receiver in [`BENCH_SCENARIO`].
const GNSS_BAUD: &str = "460800";

/// How IMU samples reach the services.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum ImuPath {
    /// Simulator → pseudo-terminal (Xsens MTData2) → `navsync imu` driver → service.
    Xsens,
    /// The simulator publishes the samples itself.
    Direct,
}

/// `navsync-bench e2e`: end-to-end latency (IMU driver → estimator → subscriber), CPU and
/// memory of every process under IMUs at 1 kHz and GNSS at 10 Hz.
#[derive(Debug, Clone, clap::Args)]
pub struct E2eArgs {
    /// IMU counts, comma-separated (one run each, at most 8).
    #[arg(long, value_delimiter = ',', default_value = "4", value_parser = crate::util::imu_count)]
    pub imus: Vec<usize>,
    /// Measured window, s.
    #[arg(long = "duration", default_value_t = 60.0)]
    pub duration_s: f64,
    /// Warm-up after the first NavState, s.
    #[arg(long = "warmup", default_value_t = 10.0)]
    pub warmup_s: f64,
    /// How the IMU samples reach the services: xsens (simulator → pseudo-terminal → driver) or direct.
    #[arg(long, default_value = "xsens")]
    pub imu_path: ImuPath,
    /// Run the latency chain (IMU drivers, estimator, subscriber) under SCHED_FIFO with this
    /// priority (1–99; needs CAP_SYS_NICE), as a deployment would with
    /// `CPUSchedulingPolicy=fifo`; the simulator (the "hardware") stays SCHED_OTHER.
    #[arg(long, value_name = "PRIO", value_parser = clap::value_parser!(u8).range(1..=99))]
    pub realtime: Option<u8>,
    /// Hold the CPU wake-up latency at 0 µs (idle CPUs poll instead of halting) without
    /// SCHED_FIFO: separates the wake-up of halted CPUs from scheduling (`--realtime` holds
    /// it too). The product's equivalent is `navsync estimator --idle-polling`.
    #[arg(long)]
    pub idle_polling: bool,
    /// Pin the latency chain (drivers, estimator, subscriber) to this CPU and the simulator
    /// to the others, as a deployment would with `CPUAffinity=` (no privileges needed): the
    /// chain's wake-ups then stay on one CPU instead of waking a halted one.
    #[arg(long, value_name = "CPU")]
    pub pin_chain: Option<usize>,
    /// A short run (2 IMUs, 3 s warm-up, 5 s measured) for smoke tests.
    #[arg(long)]
    pub quick: bool,
    /// Run each case five times: without `navsync web`; with it, an open page and a Prometheus
    /// scrape every second; also a Foxglove client on the navigation state; on every channel;
    /// without web again (the run-to-run spread), to show what watching costs the estimator.
    #[arg(long)]
    pub compare_web: bool,
    /// Write the results as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

impl E2eArgs {
    /// The settings with `--quick` applied.
    fn effective(&self) -> Self {
        let mut a = self.clone();
        if a.quick {
            (a.imus, a.duration_s, a.warmup_s) = (vec![2], 5.0, 3.0);
        }
        a
    }
}

/// CPU and memory of one process.
#[derive(Debug, Clone, Serialize)]
pub struct ProcFigures {
    /// Process name (`sim`, `imu-0`, `gps`, `pps`, `estimator`, `subscriber`).
    pub name: String,
    /// CPU over the window, % of one core.
    pub cpu_percent: f64,
    /// Peak RSS, MiB.
    pub peak_rss_mib: f64,
}

/// One run's figures.
#[derive(Debug, Clone, Serialize)]
pub struct E2eCase {
    /// IMUs.
    pub imus: usize,
    /// IMU path.
    pub imu_path: ImuPath,
    /// SCHED_FIFO priority of the latency chain, if it ran under it.
    pub realtime: Option<u8>,
    /// The CPU the latency chain was pinned to, if it was.
    pub pin_chain: Option<usize>,
    /// Run with `navsync web`, its Foxglove server and their clients (`--compare-web`).
    pub web: bool,
    /// What was watched (empty without web).
    pub web_watch: String,
    /// Foxglove messages the watching client received in the run (0 without web).
    pub foxglove_messages: u64,
    /// Bytes the page's event stream and the scrapes received (0 without web).
    pub web_http_bytes: u64,
    /// Measured window, s.
    pub window_s: f64,
    /// NavStates received in the window.
    pub nav_states: u64,
    /// NavStates whose IMU sample the subscriber had received too.
    pub matched: u64,
    /// Gaps in the NavState sequence numbers in the window.
    pub nav_gaps: u64,
    /// NavState receipt − IMU sample stamp (driver's receipt of its last byte).
    pub end_to_end: Percentiles,
    /// IMU sample receipt by the subscriber − its stamp.
    pub driver_to_subscriber: Percentiles,
    /// NavState receipt − IMU sample receipt (estimator and its IPC).
    pub imu_to_nav: Percentiles,
    /// Every process.
    pub processes: Vec<ProcFigures>,
}

/// Everything `navsync-bench e2e` measured.
#[derive(Debug, Clone, Serialize)]
pub struct E2eReport {
    /// The machine and its load.
    pub machine: Machine,
    /// One entry per IMU count.
    pub cases: Vec<E2eCase>,
}

/// Errors of the benchmark.
#[derive(Debug, thiserror::Error)]
pub enum E2eError {
    /// A child failed or did not answer.
    #[error("{0}")]
    Child(String),
    /// I/O.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// IPC.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// An option that cannot be applied on this machine.
    #[error("{0}")]
    Option(String),
}

fn s<T: ToString>(v: T) -> String {
    v.to_string()
}

/// Lines of a child's stdout, read by a thread (so that waits can time out).
fn line_reader(out: std::process::ChildStdout) -> Receiver<String> {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines() {
            let Ok(line) = line else { break };
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    rx
}

fn wait_line(
    rx: &Receiver<String>,
    env: &mut BenchEnv,
    pred: impl Fn(&str) -> bool,
    timeout: Duration,
) -> Result<String, E2eError> {
    let t0 = Instant::now();
    loop {
        match rx.recv_timeout(Duration::from_millis(200)) {
            Ok(l) if pred(&l) => return Ok(l),
            Ok(_) => {}
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => {
                return Err(E2eError::Child(format!(
                    "the subscriber stopped:\n{}",
                    env.log("subscriber")
                )));
            }
        }
        env.check_running().map_err(E2eError::Child)?;
        if t0.elapsed() > timeout {
            return Err(E2eError::Child(format!(
                "no answer from the subscriber within {timeout:?}"
            )));
        }
    }
}

fn wait_path(env: &mut BenchEnv, p: &std::path::Path) -> Result<(), E2eError> {
    let t0 = Instant::now();
    while !p.exists() {
        env.check_running().map_err(E2eError::Child)?;
        if t0.elapsed() > Duration::from_secs(20) {
            return Err(E2eError::Child(format!("{} did not appear", p.display())));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok(())
}

/// Runs one IMU count.
pub fn run_case(args: &E2eArgs, imus: usize, web: Option<web_load::Watch>) -> Result<E2eCase, E2eError> {
    let mut env = BenchEnv::new("e2e")?;
    let scenario = env.dir.join("bench_1khz.toml");
    std::fs::write(&scenario, BENCH_SCENARIO)?;
    let dir = env.dir.display().to_string();
    let link = env.dir.join("gnss0");
    let mut pids: Vec<(String, u32)> = Vec::new();

    let (pid, out) = env.spawn(
        "subscriber",
        &[
            s("helper"),
            s("e2e-sub"),
            s("--warmup-s"),
            s(args.warmup_s),
            s("--duration-s"),
            s(args.duration_s),
        ],
        true,
    )?;
    let lines = line_reader(out.ok_or_else(|| E2eError::Child("no stdout".into()))?);
    wait_line(&lines, &mut env, |l| l == "ready", Duration::from_secs(20))?;
    pids.push(("subscriber".into(), pid));

    let mut sim = vec![
        s("sim"),
        s("--scenario"),
        scenario.display().to_string(),
        s("--imus"),
        s(imus),
        s("--pty-link"),
        link.display().to_string(),
    ];
    if args.imu_path == ImuPath::Xsens {
        sim.extend([s("--imu-output"), s("xsens"), s("--imu-pty-dir"), dir.clone()]);
    }
    let (pid, _) = env.spawn("sim", &sim, false)?;
    pids.push(("sim".into(), pid));
    wait_path(&mut env, &link)?;
    let (pid, _) = env.spawn(
        "gps",
        &[
            s("gps"),
            s("--port"),
            link.display().to_string(),
            s("--baud"),
            s(GNSS_BAUD),
            s("--id"),
            s("0"),
        ],
        false,
    )?;
    pids.push(("gps".into(), pid));
    if args.imu_path == ImuPath::Xsens {
        for i in 0..imus {
            let port = navsync_drivers::imu::xsens::sim_device::sim_port(&env.dir, i);
            wait_path(&mut env, &port)?;
            let source = format!(
                "xsens:{}:{}",
                port.display(),
                navsync_drivers::imu::xsens::sim_device::SIM_BAUD
            );
            let name = format!("imu-{i}");
            let (pid, _) = env.spawn(
                &name,
                &[s("imu"), s("--source"), source, s("--id"), s(i), s("--rate"), s("1000")],
                false,
            )?;
            pids.push((name, pid));
        }
    }
    let (pid, _) = env.spawn("pps", &[s("pps"), s("--source"), s("sim"), s("--id"), s("0")], false)?;
    pids.push(("pps".into(), pid));
    let imu_list = (0..imus).map(|i| i.to_string()).collect::<Vec<_>>().join(",");
    let (pid, _) = env.spawn(
        "estimator",
        &[
            s("estimator"),
            s("--gnss"),
            s("0"),
            s("--pps"),
            s("0"),
            s("--imus"),
            imu_list,
            s("--imu-model"),
            s("consumer"),
            // The latency is measured from the driver's receipt stamp, which a NavState
            // carries when samples are fused at it; with device clocks it would carry the
            // sample's device time mapped to host time instead.
            s("--no-device-clocks"),
            s("--gnss-vel-std"),
            s("0.05"),
        ],
        false,
    )?;
    pids.push(("estimator".into(), pid));
    let watchers = if let Some(watch) = web {
        let port = || {
            std::net::TcpListener::bind("127.0.0.1:0")
                .and_then(|l| l.local_addr())
                .map(|a| a.to_string())
        };
        let (http, fox) = (port()?, port()?);
        let (pid, _) = env.spawn(
            "web",
            &[
                s("web"),
                s("--listen"),
                http.clone(),
                s("--foxglove-listen"),
                fox.clone(),
            ],
            false,
        )?;
        pids.push(("web".into(), pid));
        // The web process discovers the services once a second.
        std::thread::sleep(Duration::from_secs(2));
        Some(web_load::WebLoad::start(&http, &fox, watch))
    } else {
        None
    };
    if let Some(prio) = args.realtime {
        // The latency chain on top, each stage above the next: the reference IMU's driver,
        // the estimator, the subscriber; below them the other drivers, whose samples the
        // array uses tens of ms later anyway (derivative window), so their wake-ups do not
        // preempt the chain.
        for (name, pid) in &pids {
            let p = match name.as_str() {
                "imu-0" => prio,
                "estimator" => prio.saturating_sub(1).max(1),
                "subscriber" => prio.saturating_sub(2).max(1),
                n if n.starts_with("imu-") || n == "gps" || n == "pps" => prio.saturating_sub(3).max(1),
                _ => continue,
            };
            util::set_fifo(*pid, p).map_err(|e| E2eError::Child(format!("SCHED_FIFO {p} for {name}: {e}")))?;
        }
    }

    if let Some(cpu) = args.pin_chain {
        let others: Vec<usize> = (0..util::online_cpus()).filter(|&c| c != cpu).collect();
        for (name, pid) in &pids {
            let cpus = if name == "sim" {
                others.as_slice()
            } else {
                std::slice::from_ref(&cpu)
            };
            if !cpus.is_empty() {
                util::set_affinity(*pid, cpus)
                    .map_err(|e| E2eError::Child(format!("CPU affinity {cpus:?} for {name}: {e}")))?;
            }
        }
    }

    wait_line(
        &lines,
        &mut env,
        |l| l == "measuring",
        Duration::from_secs_f64(args.warmup_s + 60.0),
    )?;
    let t0 = Instant::now();
    let cpu0: Vec<f64> = pids
        .iter()
        .map(|(_, p)| util::cpu_time_s(*p).unwrap_or(f64::NAN))
        .collect();
    let result = wait_line(
        &lines,
        &mut env,
        |l| l.starts_with('{'),
        Duration::from_secs_f64(args.duration_s + 30.0),
    )?;
    let window = t0.elapsed().as_secs_f64();
    let (foxglove_messages, web_http_bytes) = watchers.as_ref().map_or((0, 0), |w| {
        (
            w.foxglove_messages.load(std::sync::atomic::Ordering::Relaxed),
            w.http_bytes.load(std::sync::atomic::Ordering::Relaxed),
        )
    });
    drop(watchers);
    let processes: Vec<ProcFigures> = pids
        .iter()
        .zip(&cpu0)
        .map(|((name, p), c0)| ProcFigures {
            name: name.clone(),
            cpu_percent: (util::cpu_time_s(*p).unwrap_or(f64::NAN) - c0) / window * 100.0,
            peak_rss_mib: util::peak_rss_kib(*p).map_or(f64::NAN, |k| k as f64 / 1024.0),
        })
        .collect();
    let bad = env.stop_all();
    if !bad.is_empty() {
        return Err(E2eError::Child(format!("did not exit cleanly: {bad:?}")));
    }
    let v: serde_json::Value = serde_json::from_str(&result).map_err(|e| E2eError::Child(format!("{e}: {result}")))?;
    let pct = |k: &str| -> Percentiles { serde_json::from_value(v[k].clone()).unwrap_or_default() };
    Ok(E2eCase {
        imus,
        imu_path: args.imu_path,
        realtime: args.realtime,
        pin_chain: args.pin_chain,
        web: web.is_some(),
        web_watch: web.map_or(String::new(), |w| w.label().to_string()),
        foxglove_messages,
        web_http_bytes,
        window_s: v["window_s"].as_f64().unwrap_or(f64::NAN),
        nav_states: v["nav_states"].as_u64().unwrap_or(0),
        matched: v["matched"].as_u64().unwrap_or(0),
        nav_gaps: v["nav_gaps"].as_u64().unwrap_or(0),
        end_to_end: pct("end_to_end"),
        driver_to_subscriber: pct("driver_to_subscriber"),
        imu_to_nav: pct("imu_to_nav"),
        processes,
    })
}

/// Runs every IMU count, prints the tables, writes the JSON.
pub fn run(args: &E2eArgs) -> Result<E2eReport, E2eError> {
    let args = &args.effective();
    if let Some(cpu) = args.pin_chain
        && cpu >= util::online_cpus()
    {
        return Err(E2eError::Option(format!(
            "--pin-chain {cpu}: this machine has CPUs 0–{}",
            util::online_cpus() - 1
        )));
    }
    let mut report = E2eReport {
        machine: Machine::now(),
        cases: Vec::new(),
    };
    let _wakeup = util::wakeup_hold(args.realtime.is_some() || args.idle_polling, &mut report.machine);
    let web_modes: &[Option<web_load::Watch>] = if args.compare_web {
        // The unwatched row again at the end: the run-to-run spread the others compare with.
        &[
            None,
            Some(web_load::Watch::Page),
            Some(web_load::Watch::NavState),
            Some(web_load::Watch::AllChannels),
            None,
        ]
    } else {
        &[None]
    };
    for &n in &args.imus {
        for &web in web_modes {
            let c = run_case(args, n, web)?;
            eprintln!("{}", latency_row(&c));
            report.cases.push(c);
        }
    }
    report.machine.finish();
    println!("{}", table(&report));
    if let Some(p) = &args.json {
        util::write_json(p, &report)?;
    }
    Ok(report)
}

fn latency_row(c: &E2eCase) -> String {
    let cpu = |n: &str| {
        c.processes
            .iter()
            .find(|p| p.name == n)
            .map_or(f64::NAN, |p| p.cpu_percent)
    };
    let drivers: f64 = c
        .processes
        .iter()
        .filter(|p| p.name.starts_with("imu-"))
        .map(|p| p.cpu_percent)
        .sum();
    format!(
        "| {} × 1 kHz ({}) | {} | {:.0} / {:.0} / {:.0} | {:.0} / {:.0} / {:.0} | {:.0} / {:.0} / {:.0} | {:.1} % | {:.1} % | {:.1} % |",
        c.imus,
        {
            let mut label = match c.imu_path {
                ImuPath::Xsens => "xsens".to_string(),
                ImuPath::Direct => "direct".to_string(),
            };
            if let Some(p) = c.realtime {
                label += &format!(", FIFO {p}");
            }
            if let Some(cpu) = c.pin_chain {
                label += &format!(", chain on CPU {cpu}");
            }
            if c.web {
                label += &format!(
                    ", watched: {}, {} Foxglove messages, {} kB",
                    c.web_watch,
                    c.foxglove_messages,
                    c.web_http_bytes / 1000
                );
            }
            label
        },
        c.nav_states,
        c.end_to_end.p50_us,
        c.end_to_end.p99_us,
        c.end_to_end.max_us,
        c.driver_to_subscriber.p50_us,
        c.driver_to_subscriber.p99_us,
        c.driver_to_subscriber.max_us,
        c.imu_to_nav.p50_us,
        c.imu_to_nav.p99_us,
        c.imu_to_nav.max_us,
        cpu("estimator"),
        drivers,
        cpu("sim"),
    )
}

/// The Markdown tables of a report: latency and CPU per IMU count, then every process's CPU
/// and peak RSS.
pub fn table(r: &E2eReport) -> String {
    let mut s = String::from(
        "| IMUs (path) | NavStates | end-to-end p50 / p99 / max µs | driver → subscriber p50 / p99 / max µs | IMU sample → NavState p50 / p99 / max µs | estimator CPU | IMU drivers CPU (sum) | sim CPU |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    for c in &r.cases {
        s.push_str(&latency_row(c));
        s.push('\n');
    }
    for c in &r.cases {
        s.push_str(&format!(
            "\n{} IMU(s){}: per process\n\n| process | CPU (% of one core) | peak RSS MiB |\n|---|---|---|\n",
            c.imus,
            if c.web { ", watched" } else { "" }
        ));
        for p in &c.processes {
            s.push_str(&format!(
                "| {} | {:.1} | {:.1} |\n",
                p.name, p.cpu_percent, p.peak_rss_mib
            ));
        }
    }
    s.push('\n');
    s.push_str(&r.machine.line());
    s
}

// ---------------------------------------------------------------- helper process

/// Receipts of the reference IMU's samples by sequence number (ring).
const RING: usize = 1024;

/// `navsync-bench helper e2e-sub`: waits for the first NavState, lets `warmup_s` pass, prints
/// `measuring`, measures for `duration_s` and prints one JSON line with the percentiles.
pub fn helper_sub(warmup_s: f64, duration_s: f64) -> Result<(), E2eError> {
    use std::io::Write;
    let node = IpcNode::new("bench-e2e-sub")?;
    let nav = node.input::<NavState>(services::NAV_STATE)?;
    let imu = node.input::<ImuSample>(&services::imu_sample("0"))?;
    let wake = node.wake()?;
    let say = |l: &str| {
        let mut o = std::io::stdout().lock();
        let _ = writeln!(o, "{l}");
        let _ = o.flush();
    };
    say("ready");
    let mut ring = vec![(i64::MIN, 0i64); RING];
    let cap = (duration_s * 1200.0) as usize + 1000;
    let (mut e2e, mut hop, mut rest) = (
        Vec::with_capacity(cap),
        Vec::with_capacity(cap),
        Vec::with_capacity(cap),
    );
    let (mut start, mut end): (Option<i64>, Option<i64>) = (None, None);
    let (mut navs, mut gaps, mut last_seq) = (0u64, 0u64, None::<u64>);
    let mut measuring_since = 0i64;
    while node.wait(&wake, Duration::from_millis(100))? {
        imu.drain(|x| {
            let now = monotonic_now_ns();
            ring[x.stamp.seq as usize % RING] = (x.stamp.host_ns, now);
            true
        })?;
        nav.drain(|n| {
            let now = monotonic_now_ns();
            if start.is_none() {
                start = Some(now + (warmup_s * 1e9) as i64);
            }
            if now < start.unwrap_or(i64::MAX) {
                return true;
            }
            if end.is_none() {
                end = Some(now + (duration_s * 1e9) as i64);
                measuring_since = now;
                say("measuring");
            }
            if let Some(prev) = last_seq
                && n.seq > prev + 1
            {
                gaps += n.seq - prev - 1;
            }
            last_seq = Some(n.seq);
            navs += 1;
            e2e.push(now - n.host_ns);
            // The reference IMU's receipt: the newest entries of the ring first.
            if let Some(&(h, t)) = ring.iter().find(|(h, _)| *h == n.host_ns) {
                hop.push(t - h);
                rest.push(now - t);
            }
            true
        })?;
        if end.is_some_and(|e| monotonic_now_ns() >= e) {
            break;
        }
    }
    let window = (monotonic_now_ns() - measuring_since) as f64 / NS_PER_S as f64;
    let matched = hop.len();
    say(&serde_json::json!({
        "window_s": window,
        "nav_states": navs,
        "matched": matched,
        "nav_gaps": gaps,
        "end_to_end": Percentiles::from_ns(&mut e2e),
        "driver_to_subscriber": Percentiles::from_ns(&mut hop),
        "imu_to_nav": Percentiles::from_ns(&mut rest),
    })
    .to_string());
    Ok(())
}
