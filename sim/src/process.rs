//! `navsync sim`: the process shell around the simulated [`World`].
//!
//! It paces the world's time-ordered events against the host's `CLOCK_MONOTONIC`: IMU samples
//! and the truth are published straight into their services, PPS edges raw on the
//! simulator-private `navsync/sim/pps` (which `navsync pps --source sim` validates and
//! republishes on `navsync/pps/{id}/edge`, as it would a kernel PPS device); their time stamps
//! come from the world's oscillator model, not from when they are published. Each NMEA burst is
//! written into a pseudo-terminal at the serial line rate, its first byte at the instant the
//! world says it leaves the receiver, so the GPS driver reads it exactly as from a receiver.
//!
//! With `--imu-output xsens` the IMU samples are not published: each becomes an Xsens MTData2
//! message written into that IMU's pseudo-terminal at the sample's stamp time
//! ([`crate::xsens_imus`]), and `navsync imu --source xsens:…` drivers publish them.

use std::collections::VecDeque;
use std::path::PathBuf;

use navsync_shared::health_reporter::HealthReporter;
use navsync_shared::ipc::{IpcError, IpcNode};
use navsync_shared::pacing;
use navsync_shared::samples::{PpsEdge, SimTruth};
use navsync_shared::services;
use navsync_shared::time::{NS_PER_S, monotonic_now_ns, realtime_now_ns};
use tracing::{info, info_span, warn};

use super::error::SimError;
use super::imu_errors::ImuPreset;
use super::scenario::SimConfig;
use super::world::{SimEvent, World};
use crate::xsens_imus::{SimImuOutput, SimImuSink, SimImuSinkError};
use navsync_drivers::pty::Pty;

/// `navsync sim`: the simulated world's settings, overriding the scenario's.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct SimArgs {
    /// Scenario file (TOML); default: the embedded ~10 minute drive.
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Number of IMUs (overrides the scenario).
    #[arg(long)]
    pub imus: Option<usize>,
    /// IMU error preset for all IMUs: consumer, industrial, perfect.
    #[arg(long = "imu-preset")]
    pub preset: Option<ImuPreset>,
    /// Stamp offsets of the IMUs relative to the first, ms, comma-separated (e.g. 0,10,15,20).
    #[arg(long, value_delimiter = ',')]
    pub imu_offsets_ms: Option<Vec<f64>>,
    /// GNSS rate, Hz (1 or 10).
    #[arg(long = "gnss-rate")]
    pub gnss_rate_hz: Option<u32>,
    /// What the simulated receiver writes: nmea, or ubx (NAV-PVT, NAV-EOE, TIM-TP, and TIM-TM2
    /// time marks of the camera).
    #[arg(long = "gnss-protocol")]
    pub gnss_protocol: Option<crate::scenario::OutputProtocol>,
    /// Trigger rate of the camera on the receiver's EXTINT0, Hz; 0 = no camera (scenario
    /// `gnss.camera.rate_hz`; default 1 with ubx, none with nmea).
    #[arg(long = "camera-rate")]
    pub camera_rate_hz: Option<f64>,
    /// Start of the camera's exposure after its trigger, ms (scenario
    /// `gnss.camera.exposure_offset_s`; default 5).
    #[arg(long = "camera-offset-ms")]
    pub camera_offset_ms: Option<f64>,
    /// NMEA output latency after the PPS edge, s.
    #[arg(long = "gnss-latency")]
    pub gnss_latency_s: Option<f64>,
    /// Host oscillator frequency error, ppm.
    #[arg(long, allow_hyphen_values = true)]
    pub clock_ppm: Option<f64>,
    /// PPS time-stamp jitter (1-sigma), ns.
    #[arg(long)]
    pub pps_jitter_ns: Option<f64>,
    /// Random seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Create this symlink to the NMEA pseudo-terminal.
    #[arg(long)]
    pub pty_link: Option<PathBuf>,
    /// IMU samples: `direct` into the services, or `xsens` MTData2 into one pseudo-terminal
    /// per IMU for `navsync imu` drivers.
    #[arg(long, default_value = "direct")]
    pub imu_output: SimImuOutput,
    /// Directory of the IMU pseudo-terminal links (`imu0`, `imu1`, …) with `--imu-output xsens`
    /// (default navsync's runtime directory: `$XDG_RUNTIME_DIR/navsync`, `/run/navsync` for root, else `/tmp/navsync-<uid>`).
    #[arg(long)]
    pub imu_pty_dir: Option<PathBuf>,
    /// Stop after this many seconds of scenario.
    #[arg(long = "duration")]
    pub duration_s: Option<f64>,
    /// Simulated GNSS time minus the system clock, s (default 0: GNSS time ≈ system time).
    #[arg(long = "utc-offset", default_value_t = 0.0, allow_hyphen_values = true)]
    pub utc_offset_s: f64,
    /// With `--fast`: the scenario's start, UTC seconds since 1970 (default: now, rounded to
    /// the second, plus `--utc-offset`); fixes the GPS sky of `[gnss.sky]` for reproducible
    /// runs.
    #[arg(long = "start-utc")]
    pub start_utc_s: Option<i64>,
    /// A GNSS outage START:DURATION in seconds of scenario time (repeatable), added to the
    /// scenario's.
    #[arg(long = "gnss-outage", value_parser = parse_outage)]
    pub gnss_outages: Vec<(f64, f64)>,
    /// Switch the simulated body vibration off (a perfectly smooth drive;
    /// `[trajectory.vibration] enabled = false`).
    #[arg(long)]
    pub no_vibration: bool,
}

/// `START:DURATION`, two numbers of seconds.
fn parse_outage(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = s
        .split_once(':')
        .ok_or_else(|| format!("`{s}`: expected START:DURATION, two numbers of seconds"))?;
    let num = |x: &str| {
        x.trim()
            .parse::<f64>()
            .map_err(|_| format!("`{x}` is not a number of seconds"))
    };
    Ok((num(a)?, num(b)?))
}

/// Errors of the simulator process.
#[derive(Debug, thiserror::Error)]
pub enum SimProcessError {
    /// Bad scenario or override.
    #[error(transparent)]
    Scenario(#[from] SimError),
    /// IPC failure.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// The pseudo-terminal could not be created.
    #[error("creating the NMEA pseudo-terminal: {0}")]
    Pty(std::io::Error),
    /// The IMU outputs could not be set up.
    #[error(transparent)]
    ImuOutput(#[from] SimImuSinkError),
    /// A health counter could not be registered.
    #[error(transparent)]
    Health(#[from] navsync_shared::health_reporter::HealthError),
}

/// Loads the scenario and applies the command-line overrides.
pub fn load_config(args: &SimArgs) -> Result<SimConfig, SimError> {
    let mut cfg = match &args.scenario {
        Some(p) => SimConfig::from_file(p)?,
        None => SimConfig::default_drive(),
    };
    if let Some(n) = args.imus {
        cfg.set_imu_count(n);
    }
    if let Some(p) = args.preset {
        cfg.set_imu_preset(p);
    }
    if args.imu_output == SimImuOutput::Xsens {
        // An MTi samples on its own crystal, which SampleTimeFine counts.
        cfg.set_imu_device_clocks(true);
    }
    if let Some(offsets) = &args.imu_offsets_ms {
        let s: Vec<f64> = offsets.iter().map(|ms| ms * 1e-3).collect();
        cfg.set_imu_offsets_s(&s);
    }
    if let Some(p) = args.gnss_protocol {
        cfg.set_gnss_protocol(p);
    }
    if let Some(r) = args.gnss_rate_hz {
        cfg.set_gnss_rate_hz(r);
    }
    if let Some(r) = args.camera_rate_hz {
        cfg.set_camera_rate_hz(r);
    }
    if let Some(ms) = args.camera_offset_ms {
        cfg.set_camera_exposure_offset_s(ms * 1e-3);
    }
    if let Some(l) = args.gnss_latency_s {
        cfg.set_nmea_latency_s(l);
    }
    if let Some(p) = args.clock_ppm {
        cfg.set_clock_ppm(p);
    }
    if let Some(j) = args.pps_jitter_ns {
        cfg.set_pps_jitter_s(j * 1e-9);
    }
    if let Some(s) = args.seed {
        cfg.set_seed(s);
    }
    for &(start_s, duration_s) in &args.gnss_outages {
        cfg.gnss.outages.push(super::scenario::OutageConfig {
            start_s,
            duration_s,
            pps_continues: true,
        });
    }
    if args.no_vibration {
        cfg.set_vibration(false);
    }
    cfg.validate()?;
    Ok(cfg)
}

/// One NMEA burst being written at the line rate.
struct Burst {
    start_ns: i64,
    bytes: Vec<u8>,
    pos: usize,
}

/// Writes bursts into the pseudo-terminal at the serial line rate: byte j of a burst completes
/// at `start + j·t_char`; the first byte is written alone at `start`, then chunks of up to 16
/// bytes at the completion time of their last byte (what a UART delivers).
struct LineWriter {
    pty: Pty,
    char_ns: i64,
    queue: VecDeque<Burst>,
    line_free_ns: i64,
    shifted_bursts: u64,
}

const CHUNK: usize = 16;

impl LineWriter {
    fn push(&mut self, start_ns: i64, bytes: Vec<u8>) {
        let start = if start_ns < self.line_free_ns {
            // The previous burst still occupies the line (too many bytes for the baud rate).
            self.shifted_bursts += 1;
            self.line_free_ns
        } else {
            start_ns
        };
        self.line_free_ns = start + bytes.len() as i64 * self.char_ns;
        self.queue.push_back(Burst {
            start_ns: start,
            bytes,
            pos: 0,
        });
    }

    fn chunk_len(b: &Burst) -> usize {
        if b.pos == 0 {
            1
        } else {
            CHUNK.min(b.bytes.len() - b.pos)
        }
    }

    /// Host time at which the next chunk is due.
    fn next_due(&self) -> Option<i64> {
        let b = self.queue.front()?;
        let last = b.pos + Self::chunk_len(b) - 1;
        Some(b.start_ns + last as i64 * self.char_ns)
    }

    fn write_next(&mut self) {
        let Some(b) = self.queue.front_mut() else { return };
        let n = Self::chunk_len(b);
        if let Err(e) = self.pty.write(&b.bytes[b.pos..b.pos + n]) {
            warn!("writing NMEA: {e}");
        }
        b.pos += n;
        if b.pos >= b.bytes.len() {
            self.queue.pop_front();
        }
    }
}

/// Sleeps until `target` host ns (absolute, [`pacing::sleep_until`]); with `spin`, sleeps to
/// 200 µs before and spins the rest (used for the first byte of an NMEA burst, whose timing
/// the GPS driver measures). A signal ends the sleep early; the caller's loop checks.
fn sleep_until(target: i64, spin: bool) {
    pacing::sleep_until(target, if spin { 200_000 } else { 0 });
}

/// Runs the simulator in real time until the scenario (or `--duration`) ends or SIGINT/SIGTERM.
pub fn run(args: &SimArgs) -> Result<(), SimProcessError> {
    let _span = info_span!("sim").entered();
    let cfg = load_config(args)?;
    // Wake-ups within µs of the requested time (the default timer slack is 50 µs).
    navsync_shared::pacing::minimal_timer_slack();

    let node = IpcNode::new("sim")?;
    let mut imus = SimImuSink::open(&node, &cfg, args.imu_output, args.imu_pty_dir.as_deref())?;
    let mut pps_pub = node.publisher::<PpsEdge>(services::SIM_PPS)?;
    let mut truth_pub = node.publisher::<SimTruth>(services::SIM_TRUTH)?;
    let mut health = HealthReporter::new(&node, "sim")?;
    let c_late = health.counter("late_wakeups")?;
    let c_shifted = health.counter("nmea_bursts_shifted")?;
    let c_dropped = health.counter("nmea_bytes_dropped")?;
    let r_imu = health.rate("imu_samples")?;
    let c_imu_dropped = health.counter("imu_bytes_dropped")?;

    let pty = Pty::open(args.pty_link.as_deref()).map_err(SimProcessError::Pty)?;
    println!(
        "navsync sim: NMEA on {}{}",
        pty.path().display(),
        pty.link()
            .map(|l| format!(" (link {})", l.display()))
            .unwrap_or_default()
    );
    let mut line = LineWriter {
        pty,
        char_ns: 10 * NS_PER_S / cfg.gnss.baud as i64,
        queue: VecDeque::new(),
        line_free_ns: 0,
        shifted_bursts: 0,
    };

    // The pseudo-terminal delivers a byte to a reader that sleeps in poll() some tens of µs
    // after it is written (flip-buffer work item, wake-up); a UART's byte is there when the
    // line says. Measure that latency's minimum at start and write every NMEA burst that much
    // early, so that its first byte reaches the GPS driver at the instant the world says it
    // leaves the receiver, never before (residual: the latency above its minimum; README
    // "## Timing"). Watching every burst's delivery instead would compete with the very work
    // item that delivers it.
    let pty_lead_ns = pty_wakeup_latency_ns(41).unwrap_or(0);
    info!(
        pty_lead_ns,
        "pseudo-terminal wake-up latency measured; NMEA written that much early"
    );
    let start_host = monotonic_now_ns() + 300_000_000;
    let start_utc = realtime_now_ns() + (args.utc_offset_s * 1e9) as i64 + 300_000_000;
    let mut world = World::new(&cfg, start_host, start_utc)?;
    let end_host = args.duration_s.map(|d| start_host + (d * 1e9) as i64);
    // How long this run lasts: the scenario, or `--duration` when that ends it sooner.
    let run_s = args
        .duration_s
        .map_or(world.duration_s(), |d| d.min(world.duration_s()));
    info!(imus = cfg.imu.count, duration_s = run_s, "simulation running");

    let mut next = world.next_event();
    navsync_shared::sd_notify::ready("simulation running");
    loop {
        if node.termination_requested() {
            break;
        }
        let ev_time = next.as_ref().map(|e| match e {
            // Queued 1 ms ahead, so that the first byte is written by the spinning wait.
            SimEvent::Nmea { host_ns, .. } => host_ns - pty_lead_ns - 1_000_000,
            other => event_host_ns(other),
        });
        let due = match (ev_time, line.next_due()) {
            (Some(e), Some(l)) => e.min(l),
            (Some(e), None) => e,
            (None, Some(l)) => l,
            (None, None) => break,
        };
        if end_host.is_some_and(|end| due > end) {
            break;
        }
        let first_byte = line.next_due() == Some(due) && line.queue.front().is_some_and(|b| b.pos == 0);
        sleep_until(due.min(monotonic_now_ns() + 20_000_000), first_byte);
        let now = monotonic_now_ns();
        if now < due {
            continue; // woke early to check for termination
        }
        if now - due > 2_000_000 {
            health.add(c_late, 1);
        }
        if line.next_due() == Some(due) {
            line.write_next();
        } else if let Some(ev) = next.take() {
            match ev {
                SimEvent::Imu { index, sample } => {
                    imus.deliver(index, &sample)?;
                    health.tick(r_imu);
                }
                SimEvent::Pps(edge) => pps_pub.publish(&edge)?,
                SimEvent::Nmea { host_ns, bytes, .. } => line.push(host_ns - pty_lead_ns, bytes),
                SimEvent::Truth(t) => truth_pub.publish(&t)?,
            }
            next = world.next_event();
        }
        health.set(c_shifted, line.shifted_bursts);
        health.set(c_dropped, line.pty.dropped_bytes());
        health.set(c_imu_dropped, imus.dropped_bytes());
        health.maybe_publish(now)?;
    }
    let _ = health.publish_final();
    info!("simulation stopped");
    Ok(())
}

/// Smallest latency from writing one byte into a fresh pseudo-terminal to a reader sleeping in
/// `poll()` on its slave side waking up, ns, over `samples` bytes (5 ms apart); `None` if the
/// measurement could not be made. Clamped to [0, 2 ms].
pub fn pty_wakeup_latency_ns(samples: usize) -> Option<i64> {
    use std::os::fd::AsRawFd;
    use std::os::unix::fs::OpenOptionsExt;
    let mut pty = Pty::open(None).ok()?;
    let reader = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOCTTY)
        .open(pty.path())
        .ok()?;
    let (tx, rx) = std::sync::mpsc::channel::<i64>();
    let handle = std::thread::spawn(move || {
        let fd = reader.as_raw_fd();
        let mut buf = [0u8; 64];
        loop {
            let mut p = libc::pollfd {
                fd,
                events: libc::POLLIN,
                revents: 0,
            };
            // SAFETY: one valid pollfd.
            let rc = unsafe { libc::poll(&mut p, 1, 200) };
            if rc == 0 {
                return; // the writer is done
            }
            let t = monotonic_now_ns();
            // SAFETY: reading into a local buffer from our descriptor.
            let n = unsafe { libc::read(fd, buf.as_mut_ptr().cast(), buf.len()) };
            if rc < 0 || n <= 0 || tx.send(t).is_err() {
                return;
            }
        }
    });
    let mut lat = Vec::with_capacity(samples);
    for _ in 0..samples {
        std::thread::sleep(std::time::Duration::from_millis(5));
        let t = monotonic_now_ns();
        if pty.write(b"x").ok()? != 1 {
            break;
        }
        match rx.recv_timeout(std::time::Duration::from_millis(100)) {
            Ok(r) => lat.push(r - t),
            Err(_) => break,
        }
    }
    drop(pty);
    let _ = handle.join();
    if lat.len() < samples / 2 {
        return None;
    }
    lat.iter().copied().min().map(|m| m.clamp(0, 2_000_000))
}

fn event_host_ns(ev: &SimEvent) -> i64 {
    match ev {
        SimEvent::Imu { sample, .. } => sample.stamp.host_ns,
        SimEvent::Pps(e) => e.stamp.host_ns,
        SimEvent::Nmea { host_ns, .. } => *host_ns,
        SimEvent::Truth(t) => t.host_ns,
    }
}
