//! `navsync demo`: the whole pipeline on one machine with no sensors.
//!
//! Starts `navsync sim` (simulated world: IMUs published directly, raw PPS edges on
//! `navsync/sim/pps`, NMEA written into a pseudo-terminal), `navsync gnss` (reads that
//! pseudo-terminal through the serial API), `navsync pps --source sim` (validates the edges as
//! it would a kernel PPS device's) and `navsync estimator` as child processes; shows a live status line with per-service rates
//! and the time-mapping error against the simulated truth; stops them all on Ctrl-C/SIGTERM
//! or at the end of `--duration`, and prints a summary.
//!
//! With `--imu-output xsens` (the default) the simulator does not publish IMU samples: it
//! writes each IMU's samples as Xsens MTData2 messages into a pseudo-terminal of its own, and
//! one `navsync imu --source xsens:…` driver per IMU reads them through the serial API and
//! publishes them, as it would a real MTi. `--imu-output direct` keeps the shortcut.

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, IsTerminal, Write};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{Receiver, Sender};
use std::time::{Duration, Instant};

use navsync_drivers::imu::xsens::sim_device::{SIM_BAUD, sim_port};
use navsync_shared::ipc::{IpcError, IpcNode, Subscriber};
use navsync_shared::reflect::str_of;
use navsync_shared::samples::*;
use navsync_shared::services;
use navsync_sim::process::{SimArgs, load_config};
use navsync_sim::scenario::OutputProtocol;
use navsync_sim::xsens_imus::SimImuOutput;
use tracing::info;

use navsync_estimator::evaluation::{DelayTruth, Evaluator};

/// Settings of `navsync demo`.
#[derive(Debug, Clone, clap::Args)]
pub struct DemoArgs {
    /// Stop after this many seconds (default: at the end of the scenario or Ctrl-C).
    #[arg(long = "duration")]
    pub duration_s: Option<f64>,
    /// Number of simulated IMUs.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(usize))]
    pub imus: usize,
    /// Scenario file (TOML); default: the embedded ~10 minute drive.
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// IMU path: `xsens` (simulator → pseudo-terminals → `navsync imu` drivers) or `direct`.
    #[arg(long, default_value = "xsens")]
    pub imu_output: SimImuOutput,
    /// What the simulated receiver writes and the GNSS driver reads: `nmea` or `ubx`.
    #[arg(long, default_value = "nmea")]
    pub gnss_protocol: OutputProtocol,
    /// Extra arguments passed to `navsync sim`.
    #[arg(skip)]
    pub sim_args: Vec<String>,
}

/// Child names of the IMU drivers (one per IMU, at most `MAX_IMUS`).
const IMU_PROCS: [&str; MAX_IMUS] = ["imu0", "imu1", "imu2", "imu3", "imu4", "imu5", "imu6", "imu7"];

/// Errors of `navsync demo`.
#[derive(Debug, thiserror::Error)]
pub enum DemoError {
    /// IPC failure.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// A child process could not be started or failed.
    #[error("{0}")]
    Child(String),
    /// I/O.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// The runtime directory is not safe to use.
    #[error(transparent)]
    RuntimeDir(#[from] navsync_shared::runtime_dir::RuntimeDirError),
}

struct Proc {
    name: &'static str,
    child: Child,
}

/// Starts `navsync ARGS` as the child `name`; its log lines (`name: line`) go to `logs`,
/// forwarded by a reader thread of its own, so the demo prints them above its status line
/// instead of through it.
fn spawn(name: &'static str, args: &[String], logs: &Sender<String>) -> Result<Proc, DemoError> {
    let exe = std::env::current_exe()?;
    // The children are the demo's, not the service manager's: they neither report readiness
    // nor feed a watchdog of their own.
    let mut cmd = Command::new(exe);
    cmd.args(args)
        .env_remove("NOTIFY_SOCKET")
        .env_remove("WATCHDOG_USEC")
        .env_remove("WATCHDOG_PID")
        .stderr(Stdio::piped())
        // A group of its own: the terminal's Ctrl-C reaches the demo only, which then stops the
        // children in order (see `stop_all`).
        .process_group(0);
    // SAFETY: prctl(2) is async-signal-safe; the child asks for SIGTERM should the demo die
    // without stopping it (it is no longer in the terminal's process group).
    unsafe {
        cmd.pre_exec(|| {
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
            Ok(())
        });
    }
    let mut child = cmd
        .spawn()
        .map_err(|e| DemoError::Child(format!("starting `navsync {}`: {e}", args.join(" "))))?;
    if let Some(stderr) = child.stderr.take() {
        let tx = logs.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                if tx.send(format!("{name}: {line}")).is_err() {
                    break;
                }
            }
        });
    }
    info!(name, pid = child.id(), "started");
    Ok(Proc { name, child })
}

/// Prints the children's log lines that arrived; on a terminal each above the status line
/// `status` (cleared, then drawn again below them).
fn print_child_logs(logs: &Receiver<String>, tty: bool, status: Option<&str>) {
    let mut err = std::io::stderr().lock();
    let mut any = false;
    while let Ok(line) = logs.try_recv() {
        if tty && !any {
            let _ = write!(err, "\r\x1b[2K");
        }
        any = true;
        let _ = writeln!(err, "{line}");
    }
    if any
        && tty
        && let Some(s) = status
    {
        let _ = write!(err, "{s}");
    }
    let _ = err.flush();
}

fn wait_for_path(p: &Path, procs: &mut [Proc], timeout: Duration) -> Result<(), DemoError> {
    let t0 = Instant::now();
    while !p.exists() {
        for pr in procs.iter_mut() {
            if let Some(st) = pr.child.try_wait()? {
                return Err(DemoError::Child(format!("{} exited early ({st})", pr.name)));
            }
        }
        if t0.elapsed() > timeout {
            return Err(DemoError::Child(format!(
                "{} did not appear within {timeout:?}",
                p.display()
            )));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok(())
}

/// Stops the children one after the other, last started first (the estimator, then the
/// drivers, the simulator last, so no driver sees its pseudo-terminal vanish under it): SIGTERM,
/// then SIGKILL after 5 s.
fn stop_all(procs: &mut Vec<Proc>) -> Vec<(String, String)> {
    let mut report = Vec::new();
    for p in procs.iter_mut().rev() {
        // SAFETY: signalling our own child by pid.
        unsafe { libc::kill(p.child.id() as libc::pid_t, libc::SIGTERM) };
        let t0 = Instant::now();
        let status = loop {
            match p.child.try_wait() {
                Ok(Some(st)) => break st.to_string(),
                Ok(None) if t0.elapsed() < Duration::from_secs(5) => std::thread::sleep(Duration::from_millis(10)),
                Ok(None) => {
                    let _ = p.child.kill();
                    let _ = p.child.wait();
                    break "killed after 5 s".to_string();
                }
                Err(e) => break format!("wait failed: {e}"),
            }
        };
        report.push((p.name.to_string(), status));
    }
    procs.clear();
    report
}

/// Per-service counters kept by the monitor.
#[derive(Default)]
struct Count {
    total: u64,
    window: u64,
}

/// Time-mapping error statistics against the truth, ns.
#[derive(Default)]
struct ErrStats {
    n: u64,
    sum_sq: f64,
    max_abs: f64,
    last: f64,
}

impl ErrStats {
    fn push(&mut self, e: f64) {
        self.n += 1;
        self.sum_sq += e * e;
        self.max_abs = self.max_abs.max(e.abs());
        self.last = e;
    }
    fn rms(&self) -> f64 {
        if self.n == 0 {
            f64::NAN
        } else {
            (self.sum_sq / self.n as f64).sqrt()
        }
    }
}

struct Monitor {
    imus: Vec<Subscriber<ImuSample>>,
    pps: Subscriber<PpsEdge>,
    fix: Subscriber<GnssFix>,
    time: Subscriber<TimeState>,
    truth: Subscriber<SimTruth>,
    healths: Vec<(String, Subscriber<Health>)>,
    counts: BTreeMap<String, Count>,
    latest_time: Option<TimeState>,
    latest_health: BTreeMap<String, Health>,
    err_locked: ErrStats,
    last_fix: Option<GnssFix>,
    nav: Subscriber<NavState>,
    latest_nav: Option<NavState>,
    eval: Evaluator,
    started: Instant,
}

impl Monitor {
    fn new(node: &IpcNode, imus: usize) -> Result<Self, IpcError> {
        let imus = (0..imus)
            .map(|i| node.subscriber(&services::imu_sample(&i.to_string())))
            .collect::<Result<_, _>>()?;
        let healths = ["sim", "gnss-0", "pps-0", "estimator"]
            .iter()
            .map(|p| Ok((p.to_string(), node.subscriber(&services::health(p))?)))
            .collect::<Result<_, IpcError>>()?;
        Ok(Self {
            imus,
            pps: node.subscriber(&services::pps_edge("0"))?,
            fix: node.subscriber(&services::gnss_fix("0"))?,
            time: node.subscriber(services::TIME_STATE)?,
            truth: node.subscriber(services::SIM_TRUTH)?,
            healths,
            counts: BTreeMap::new(),
            latest_time: None,
            latest_health: BTreeMap::new(),
            err_locked: ErrStats::default(),
            last_fix: None,
            nav: node.subscriber(services::NAV_STATE)?,
            latest_nav: None,
            eval: Evaluator::default(),
            started: Instant::now(),
        })
    }

    fn count(&mut self, service: &str, n: usize) {
        let c = self.counts.entry(service.to_string()).or_default();
        c.total += n as u64;
        c.window += n as u64;
    }

    fn drain(&mut self) -> Result<(), IpcError> {
        let mut navs = 0;
        while let Some(n) = self.nav.receive()? {
            self.eval.add_nav(&n);
            self.latest_nav = Some(n);
            navs += 1;
        }
        self.count(services::NAV_STATE, navs);
        for i in 0..self.imus.len() {
            let n = self.imus[i].for_each(|_| {})?;
            let name = self.imus[i].service().to_string();
            self.count(&name, n);
        }
        let n = self.pps.for_each(|_| {})?;
        self.count(&services::pps_edge("0"), n);
        let mut fixes = 0;
        while let Some(f) = self.fix.receive()? {
            self.last_fix = Some(f);
            fixes += 1;
        }
        self.count(&services::gnss_fix("0"), fixes);
        let mut states = 0;
        while let Some(t) = self.time.receive()? {
            self.latest_time = Some(t);
            states += 1;
        }
        self.count(services::TIME_STATE, states);
        let mut truths = 0;
        while let Some(tr) = self.truth.receive()? {
            truths += 1;
            self.eval.add_truth(&tr);
            if let Some(ts) = &self.latest_time
                && ts.status() == TimeStatus::Locked
            {
                self.err_locked.push((ts.utc_ns_at(tr.host_ns) - tr.utc_ns) as f64);
            }
        }
        self.count(services::SIM_TRUTH, truths);
        for i in 0..self.healths.len() {
            let mut n = 0;
            while let Some(h) = self.healths[i].1.receive()? {
                self.latest_health.insert(self.healths[i].0.clone(), h);
                n += 1;
            }
            let name = services::health(&self.healths[i].0);
            self.count(&name, n);
        }
        Ok(())
    }

    fn status_line(&mut self, elapsed_s: f64, window_s: f64) -> String {
        let imu_hz: u64 = self
            .counts
            .iter()
            .filter(|(k, _)| k.starts_with("navsync/imu/"))
            .map(|(_, c)| c.window)
            .sum();
        let get = |m: &BTreeMap<String, Count>, k: &str| m.get(k).map_or(0, |c| c.window);
        let fix_hz = get(&self.counts, &services::gnss_fix("0")) as f64 / window_s;
        let pps_hz = get(&self.counts, &services::pps_edge("0")) as f64 / window_s;
        let time = match &self.latest_time {
            Some(t) if !t.offset_std_ns.is_finite() => format!("time {}", t.status().name()),
            Some(t) => format!(
                "time {} ±{:.2} µs, err {:+.2} µs, d0 {}",
                t.status().name(),
                t.offset_std_ns * 1e-3,
                self.err_locked.last * 1e-3,
                if t.latency_median_s.is_finite() {
                    format!("{:.4} s", t.latency_median_s)
                } else {
                    "-".into()
                }
            ),
            None => "time -".into(),
        };
        for c in self.counts.values_mut() {
            c.window = 0;
        }
        format!(
            "[{elapsed_s:6.1} s] imu {:.0} Hz  pps {pps_hz:.1} Hz  gnss {fix_hz:.1} Hz  {time}  {}",
            imu_hz as f64 / window_s,
            nav_status(self.latest_nav.as_ref())
        )
    }
}

/// The navigation part of the status line: the filter's status, and once it navigates, where
/// the vehicle is (latitude, longitude in degrees) with the horizontal 1σ (m).
fn nav_status(n: Option<&NavState>) -> String {
    match n {
        None => "nav -".into(),
        Some(n) if n.status == NavStatus::Aligning as u8 || !n.lat_deg.is_finite() => {
            format!("nav {}", NavStatus::name(n.status))
        }
        Some(n) => format!(
            "nav {} {:.6},{:.6} ±{:.2} m",
            NavStatus::name(n.status),
            n.lat_deg,
            n.lon_deg,
            n.pos_std_ned_m[0].hypot(n.pos_std_ned_m[1])
        ),
    }
}

/// Runs the demo.
pub fn run(args: &DemoArgs) -> Result<(), DemoError> {
    let node = IpcNode::new(&format!("demo-{}", std::process::id()))?;
    // The pseudo-terminal links, in a directory of this process's own under navsync's runtime
    // directory (created exclusively, owner-only: a predictable path in /tmp could be another
    // user's).
    let dir = navsync_shared::runtime_dir::private(&format!("demo-{}", std::process::id()))?;
    let link = dir.join("gnss0");
    let mut monitor = Monitor::new(&node, args.imus)?;

    let mut sim_args: Vec<String> = vec![
        "sim".into(),
        "--pty-link".into(),
        link.display().to_string(),
        "--imus".into(),
        args.imus.to_string(),
    ];
    if let Some(s) = &args.scenario {
        sim_args.extend(["--scenario".into(), s.display().to_string()]);
    }
    let gnss_protocol = match args.gnss_protocol {
        OutputProtocol::Nmea => "nmea",
        OutputProtocol::Ubx => "ubx",
    };
    sim_args.extend(["--gnss-protocol".into(), gnss_protocol.into()]);
    let xsens = args.imu_output == SimImuOutput::Xsens;
    if xsens {
        sim_args.extend([
            "--imu-output".into(),
            "xsens".into(),
            "--imu-pty-dir".into(),
            dir.display().to_string(),
        ]);
        for i in 0..args.imus.min(MAX_IMUS) {
            let p = format!("imu-{i}");
            monitor
                .healths
                .push((p.clone(), node.subscriber(&services::health(&p))?));
        }
    }
    // The simulator runs as long as the demo (it would otherwise log the scenario's length).
    if let Some(d) = args.duration_s
        && !args.sim_args.iter().any(|a| a == "--duration")
    {
        sim_args.extend(["--duration".into(), format!("{}", d + 2.0)]);
    }
    sim_args.extend(args.sim_args.iter().cloned());
    let imu_list = (0..args.imus).map(|i| i.to_string()).collect::<Vec<_>>().join(",");

    let (log_tx, log_rx) = std::sync::mpsc::channel::<String>();
    let tty = std::io::stderr().is_terminal();
    let mut procs = vec![spawn("sim", &sim_args, &log_tx)?];
    let result = (|| -> Result<(), DemoError> {
        wait_for_path(&link, &mut procs, Duration::from_secs(10))?;
        procs.push(spawn(
            "gnss",
            &[
                "gnss",
                "--port",
                &link.display().to_string(),
                "--baud",
                "115200",
                "--protocol",
                gnss_protocol,
                "--id",
                "0",
            ]
            .map(String::from),
            &log_tx,
        )?);
        if xsens {
            for (i, name) in IMU_PROCS.iter().enumerate().take(args.imus) {
                let port = sim_port(&dir, i);
                wait_for_path(&port, &mut procs, Duration::from_secs(10))?;
                let source = format!("xsens:{}:{SIM_BAUD}", port.display());
                procs.push(spawn(
                    name,
                    &["imu", "--source", &source, "--id", &i.to_string()].map(String::from),
                    &log_tx,
                )?);
            }
        }
        procs.push(spawn(
            "pps",
            &["pps", "--source", "sim", "--id", "0"].map(String::from),
            &log_tx,
        )?);
        // Tell the filter what the simulated devices are (IMU class, receiver velocity noise).
        let sim_cfg = load_config(&SimArgs {
            scenario: args.scenario.clone(),
            ..Default::default()
        })
        .map_err(|e| DemoError::Child(format!("scenario: {e}")))?;
        let imu_model = sim_cfg.imu.preset.name().to_string();
        let vel_std = sim_cfg.gnss.velocity_sigma_mps.max(0.01).to_string();
        // Stated where users see them (a recording of the demo keeps them too:
        // navsync/estimator/settings).
        eprintln!(
            "demo: estimator --imus {imu_list} --imu-model {imu_model} --gnss-vel-std {vel_std} (the simulated \
             devices' IMU class and receiver velocity noise)"
        );
        procs.push(spawn(
            "estimator",
            &[
                "estimator",
                "--gnss",
                "0",
                "--pps",
                "0",
                "--imus",
                &imu_list,
                "--imu-model",
                &imu_model,
                "--gnss-vel-std",
                &vel_std,
            ]
            .map(String::from),
            &log_tx,
        )?);
        navsync_shared::sd_notify::ready("demo running");
        monitor_loop(&node, &mut monitor, &mut procs, args.duration_s, &log_rx)
    })();
    if tty {
        eprintln!();
    }
    let exits = stop_all(&mut procs);
    // Every child has exited: its reader thread ends at the end of its output.
    drop(log_tx);
    while let Ok(line) = log_rx.recv_timeout(Duration::from_millis(500)) {
        eprintln!("{line}");
    }
    let _ = monitor.drain();
    let _ = std::fs::remove_dir_all(&dir);
    print_summary(&mut monitor, &exits);
    result
}

fn monitor_loop(
    node: &IpcNode,
    monitor: &mut Monitor,
    procs: &mut [Proc],
    duration_s: Option<f64>,
    logs: &Receiver<String>,
) -> Result<(), DemoError> {
    let t0 = Instant::now();
    let mut last_line = Instant::now();
    let tty = std::io::stderr().is_terminal();
    let mut status: Option<String> = None;
    loop {
        print_child_logs(logs, tty, status.as_deref());
        // The monitor is a display: it wakes every 100 ms and drains what arrived (every service
        // buffers far more than 100 ms of samples) instead of waking for each of ~5000 samples/s.
        if !node.sleep(Duration::from_millis(100)) {
            break;
        }
        monitor.drain()?;
        for p in procs.iter_mut() {
            if let Some(st) = p.child.try_wait()? {
                if p.name == "sim" && st.success() {
                    info!("the scenario ended");
                    return Ok(());
                }
                return Err(DemoError::Child(format!("{} exited unexpectedly ({st})", p.name)));
            }
        }
        let elapsed = t0.elapsed().as_secs_f64();
        let period = if tty { 1.0 } else { 5.0 };
        if last_line.elapsed().as_secs_f64() >= period {
            let line = monitor.status_line(elapsed, last_line.elapsed().as_secs_f64());
            let mut err = std::io::stderr().lock();
            if tty {
                let _ = write!(err, "\r\x1b[2K{line}");
            } else {
                let _ = writeln!(err, "{line}");
            }
            let _ = err.flush();
            status = Some(line);
            last_line = Instant::now();
        }
        if duration_s.is_some_and(|d| elapsed >= d) {
            break;
        }
    }
    Ok(())
}

fn print_summary(m: &mut Monitor, exits: &[(String, String)]) {
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "\n=== navsync demo summary ===");
    let _ = writeln!(out, "{:<32} {:>10}", "service", "samples");
    for (k, c) in &m.counts {
        let _ = writeln!(out, "{k:<32} {:>10}", c.total);
    }
    if let Some(t) = &m.latest_time {
        let _ = writeln!(
            out,
            "time mapping: {} (PPS used {}, rejected {}), host clock rate error {:+.4} ppm ± {:.4}",
            t.status().name(),
            t.pps_used,
            t.pps_rejected,
            t.rate_error * 1e6,
            t.rate_std * 1e6
        );
        let _ = writeln!(
            out,
            "mapped-time error vs truth while locked: RMS {:.3} µs, max {:.3} µs over {} truth samples",
            m.err_locked.rms() * 1e-3,
            m.err_locked.max_abs * 1e-3,
            m.err_locked.n
        );
        if t.latency_count > 0 {
            let _ = writeln!(
                out,
                "receiver latency d0 over {} epochs: min {:.6} s, median {:.6} s, p99 {:.6} s, max {:.6} s",
                t.latency_count, t.latency_min_s, t.latency_median_s, t.latency_p99_s, t.latency_max_s
            );
        }
    }
    if let Some(f) = &m.last_fix {
        let _ = writeln!(
            out,
            "last fix: lat {:.7} lon {:.7} alt {:.2} m, mode {}",
            f.lat_deg, f.lon_deg, f.alt_msl_m, f.mode
        );
    }
    // The counters that moved (every one is in `navsync echo navsync/health/…`).
    for (p, h) in &m.latest_health {
        let counters: Vec<String> = h
            .counters
            .iter()
            .filter(|c| c.name[0] != 0 && c.value != 0)
            .map(|c| format!("{}={}", str_of(&c.name), c.value))
            .collect();
        if !counters.is_empty() {
            let _ = writeln!(out, "health {p}: {}", counters.join(" "));
        }
    }
    // The accuracy report of the run against the simulated truth (the same as
    // `navsync replay --estimate` prints).
    let imu0 = m.counts.get(&services::imu_sample("0")).map_or(0, |c| c.total);
    let fixes = m.counts.get(&services::gnss_fix("0")).map_or(0, |c| c.total);
    let rejected = m.latest_nav.as_ref().map_or(0, |n| n.fixes_rejected as u64);
    let mut summary = m.eval.summary(
        (imu0, fixes, rejected),
        m.started.elapsed().as_secs_f64(),
        0.0,
        DelayTruth::Zero,
    );
    if summary.pos_rms_m.is_none() && summary.problem.is_none() {
        let status = m
            .latest_nav
            .as_ref()
            .map_or("no navigation state", |n| NavStatus::name(n.status));
        summary.problem = Some(format!(
            "no accuracy yet: the filter never navigated ({status}); it aligns once the vehicle moves \
             (a simulated drive starts by standing still): run the demo longer"
        ));
    }
    let _ = writeln!(
        out,
        "\n--- accuracy against the simulated truth ---\n{}",
        summary.table()
    );
    for (name, st) in exits {
        let _ = writeln!(out, "{name}: {st}");
    }
}
