//! `navsync`: one multi-call binary; each subcommand is one role and runs as its own process.

use std::io::{Read, Write};
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result};
use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use navsync::roles;
use navsync_drivers::feed::{FeedArgs, Speed};
use navsync_drivers::gps::driver::Baud;
use navsync_drivers::imu::axes::AxisMap;
use navsync_drivers::imu::{ImuArgs, ImuSource};
use navsync_shared::imu_spec::ImuPreset;
use navsync_sim::process::SimArgs;
use navsync_sim::xsens_imus::SimImuOutput;
use tracing::Level;
use tracing_subscriber::filter::Targets;
use tracing_subscriber::prelude::*;

#[derive(Parser)]
#[command(name = "navsync", version, about = "GNSS/INS time-synchronisation daemon")]
struct Cli {
    /// Configuration file (default /etc/navsync/navsync.toml when it exists); flags override it.
    #[arg(long, global = true, value_name = "FILE")]
    config: Option<PathBuf>,
    #[command(subcommand)]
    cmd: Cmd,
}

/// Two numbers `A:B` (seconds).
fn parse_pair(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = s
        .split_once(':')
        .ok_or_else(|| format!("`{s}`: expected A:B, two numbers of seconds"))?;
    let start: f64 = a
        .trim()
        .parse()
        .map_err(|_| format!("`{a}` is not a number of seconds"))?;
    let dur: f64 = b
        .trim()
        .parse()
        .map_err(|_| format!("`{b}` is not a number of seconds"))?;
    Ok((start, dur))
}

/// A device id as used in service names: letters, digits, `-` and `_`.
fn parse_id(s: &str) -> Result<String, String> {
    if !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_') {
        Ok(s.to_string())
    } else {
        Err(format!("`{s}`: an id is letters, digits, `-` and `_`"))
    }
}

#[derive(Subcommand)]
enum AnalyzeCmd {
    /// The GNSS delay by least squares per segment (ΔV = ΔV₀ + a·Δ, east and north) beside the
    /// online estimate, like Table 1 of the GPS/SINS time-synchronisation literature.
    GnssDelay {
        /// The recording (MCAP).
        recording: PathBuf,
        /// Segments START:END in seconds since the first sample, comma-separated (default: all).
        #[arg(long, value_delimiter = ',', value_parser = parse_pair)]
        segments: Vec<(f64, f64)>,
        /// IMU ids (the first is the reference).
        #[arg(long, default_value = "0", value_delimiter = ',', value_parser = parse_id)]
        imus: Vec<String>,
        /// IMU class for the filter's process noise.
        #[arg(long, default_value = "industrial")]
        imu_model: ImuPreset,
        /// 1-sigma of the receiver's velocity per axis, m/s.
        #[arg(long, default_value_t = 0.1)]
        gnss_vel_std: f64,
    },
}

#[derive(Subcommand)]
enum ImportCmd {
    /// KF-GINS text files (IMU increments, GNSS positions, optional reference trajectory).
    KfGins {
        /// IMU file: seconds of week, 3 angle increments (rad), 3 velocity increments (m/s), FRD.
        #[arg(long)]
        imu: PathBuf,
        /// GNSS file: seconds of week, lat, lon (deg), height (m), STD north/east/down (m).
        #[arg(long)]
        gnss: PathBuf,
        /// Reference trajectory: week, seconds of week, lat, lon, h, vN, vE, vD, roll, pitch, yaw (deg).
        #[arg(long)]
        truth: Option<PathBuf>,
        /// IMU rate, Hz (default: from the time tags).
        #[arg(long)]
        imu_rate: Option<f64>,
        /// GPS week of the data (default: the truth file's, else 2200).
        #[arg(long)]
        week: Option<i64>,
        /// The output recording (MCAP).
        #[arg(short, long)]
        out: PathBuf,
    },
}

/// Output format of `replay --estimate --out`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum EstimateFormat {
    /// NavState and TimeState in an MCAP file.
    Mcap,
    /// KF-GINS's navigation result (11 columns; a directory gets its IMU_ERR and STD files too).
    KfGins,
}

/// The estimator's settings on the command line, shared by `estimator`, `replay --estimate`
/// and `report --estimate`.
#[derive(clap::Args, Debug)]
struct EstimatorFlags {
    /// GNSS receiver ids.
    #[arg(long, default_value = "0", value_delimiter = ',', value_parser = parse_id)]
    gnss: Vec<String>,
    /// PPS source ids (empty: none).
    #[arg(long, default_value = "0", value_delimiter = ',', value_parser = parse_id)]
    pps: Vec<String>,
    /// IMU ids (the first drives the filter).
    #[arg(long, default_value = "0", value_delimiter = ',', value_parser = parse_id)]
    imus: Vec<String>,
    /// Ignore PPS: stamp fixes by receipt time (software sync, ms-level time).
    #[arg(long)]
    software_sync: bool,
    /// IMU class for the filter's process noise: consumer, industrial.
    #[arg(long, default_value = "industrial")]
    imu_model: ImuPreset,
    /// Do not estimate the GNSS delay Δ (for comparison runs).
    #[arg(long)]
    no_delay_state: bool,
    /// 1-sigma of the receiver's velocity per axis, m/s.
    #[arg(long, default_value_t = 0.1)]
    gnss_vel_std: f64,
}

impl EstimatorFlags {
    /// The estimator's arguments (defaults for what the command line does not set).
    fn args(self) -> navsync_estimator::settings::Settings {
        navsync_estimator::settings::Settings {
            gnss_ids: self.gnss,
            pps_ids: self.pps,
            imu_ids: self.imus,
            software_sync: self.software_sync,
            imu_model: self.imu_model,
            estimate_delay: !self.no_delay_state,
            gnss_vel_std_mps: self.gnss_vel_std,
            ..Default::default()
        }
    }
}

#[derive(Subcommand)]
enum Cmd {
    /// GNSS receiver driver: NMEA 0183 from a serial port to `navsync/gnss/{id}/fix`.
    Gps {
        /// Serial device (e.g. /dev/ttyUSB0, or a pseudo-terminal); default `[gps.ID].port`.
        #[arg(long)]
        port: Option<String>,
        /// Line rate, or `auto` to hunt the common rates.
        #[arg(long, default_value = "9600")]
        baud: Baud,
        /// Receiver id.
        #[arg(long, default_value = "0")]
        id: String,
    },
    /// IMU driver: samples from an IIO device, an Xsens MTi or the simulator to `navsync/imu/{id}/sample`.
    Imu {
        /// `iio:DEVICE` (iio:deviceN, N or the device name; `GYRO+ACCEL` for a split IMU), `xsens:PORT[:BAUD]` or `sim[:DIR]`.
        #[arg(long)]
        source: Option<ImuSource>,
        /// IMU id.
        #[arg(long, default_value = "0", value_parser = parse_id)]
        id: String,
        /// sysfs directory of IIO devices.
        #[arg(long, default_value = navsync_drivers::imu::iio_device::SYSFS_ROOT)]
        sysfs_root: PathBuf,
        /// Directory of the IIO character devices.
        #[arg(long, default_value = navsync_drivers::imu::iio_device::DEV_ROOT)]
        dev_root: PathBuf,
        /// Sampling frequency, Hz: set on an IIO device; the nominal rate of an Xsens device.
        #[arg(long)]
        rate: Option<f64>,
        /// Device axes to forward-right-down, e.g. `x,-y,-z` (device z up) or `x,y,z`.
        #[arg(long, default_value = "x,-y,-z")]
        axes: AxisMap,
        /// Gyroscope range, °/s (samples beyond it are rejected; default 2000 for Xsens/sim).
        #[arg(long)]
        gyro_range_dps: Option<f64>,
        /// Accelerometer range, g (default 16 for Xsens/sim).
        #[arg(long)]
        accel_range_g: Option<f64>,
        /// IIO buffer length, records.
        #[arg(long, default_value_t = navsync_drivers::imu::IIO_BUFFER_LENGTH)]
        buffer_length: u32,
    },
    /// Plays a capture (NMEA log or raw bytes) into a pseudo-terminal, as the device would send it.
    Feed {
        /// Capture file: a gpsd-style NMEA log (`#` comments skipped) or raw bytes.
        capture: PathBuf,
        /// Create a pseudo-terminal (the only output there is; required).
        #[arg(long, required = true)]
        pty: bool,
        /// Symlink to create to the pseudo-terminal.
        #[arg(long)]
        link: Option<PathBuf>,
        /// `realtime`, a factor such as 10, or `max`.
        #[arg(long, default_value = "realtime")]
        speed: Speed,
        /// Start over at the end, until stopped.
        #[arg(long = "loop")]
        looped: bool,
        /// Line rate of the emulated device: paces raw captures; a reader at another rate gets garbage.
        #[arg(long)]
        baud: Option<u32>,
        /// Wait until a reader has opened the port (and flushed it) before sending.
        #[arg(long)]
        wait_reader: bool,
        /// Seconds to keep the port open after the end.
        #[arg(long, default_value_t = 1.0)]
        hold: f64,
    },
    /// The estimator: time mapping (and navigation filter) from the sensor services.
    Estimator {
        #[command(flatten)]
        est: EstimatorFlags,
        /// Hold the CPU wake-up latency at 0 µs while running (`/dev/cpu_dma_latency`, as
        /// cyclictest does): idle CPUs poll, so waking the estimator costs no exit from a
        /// halted CPU. For low-latency deployments, with SCHED_FIFO; costs an idle core's power.
        #[arg(long)]
        idle_polling: bool,
    },
    /// The simulated sensor world: IMUs and PPS to their services, NMEA into a pseudo-terminal.
    Sim {
        /// Scenario file (TOML); default: the embedded ~10 minute drive.
        #[arg(long)]
        scenario: Option<PathBuf>,
        /// Number of IMUs (overrides the scenario).
        #[arg(long)]
        imus: Option<usize>,
        /// IMU error preset for all IMUs: consumer, industrial, perfect.
        #[arg(long)]
        imu_preset: Option<ImuPreset>,
        /// Stamp offsets of the IMUs relative to the first, ms, comma-separated (e.g. 0,10,15,20).
        #[arg(long, value_delimiter = ',')]
        imu_offsets_ms: Option<Vec<f64>>,
        /// GNSS rate, Hz (1 or 10).
        #[arg(long)]
        gnss_rate: Option<u32>,
        /// NMEA output latency after the PPS edge, s.
        #[arg(long)]
        gnss_latency: Option<f64>,
        /// Host oscillator frequency error, ppm.
        #[arg(long)]
        clock_ppm: Option<f64>,
        /// PPS time-stamp jitter (1-sigma), ns.
        #[arg(long)]
        pps_jitter_ns: Option<f64>,
        /// Random seed.
        #[arg(long)]
        seed: Option<u64>,
        /// Create this symlink to the NMEA pseudo-terminal.
        #[arg(long)]
        pty_link: Option<PathBuf>,
        /// IMU samples: `direct` into the services, or `xsens` MTData2 into one pseudo-terminal per IMU.
        #[arg(long, default_value = "direct")]
        imu_output: SimImuOutput,
        /// Directory of the IMU pseudo-terminal links (`imu0`, `imu1`, …) with `--imu-output xsens`.
        #[arg(long)]
        imu_pty_dir: Option<PathBuf>,
        /// Stop after this many seconds.
        #[arg(long)]
        duration: Option<f64>,
        /// Simulated GNSS time minus the system clock, s.
        #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
        utc_offset: f64,
        /// A GNSS outage START:DURATION in seconds of scenario time (repeatable).
        #[arg(long, value_parser = parse_pair)]
        gnss_outage: Vec<(f64, f64)>,
        /// Switch the simulated body vibration off (a perfectly smooth drive).
        #[arg(long)]
        no_vibration: bool,
        /// Do not wait for real time: produce the samples as fast as the CPU allows (with --estimate and/or --record).
        #[arg(long)]
        fast: bool,
        /// Run the estimator offline over the simulated samples and print the accuracy report.
        #[arg(long, requires = "fast")]
        estimate: bool,
        /// Write the accuracy report as JSON to this file.
        #[arg(long, requires = "estimate")]
        summary_json: Option<PathBuf>,
        /// Write the samples the drivers would publish, and the truth, into this MCAP file (with --fast).
        #[arg(long, requires = "fast")]
        record: Option<PathBuf>,
        /// Estimator: ignore PPS (software sync).
        #[arg(long)]
        software_sync: bool,
        /// Estimator: do not estimate the GNSS delay Δ.
        #[arg(long)]
        no_delay_state: bool,
        /// Estimator: IMU class for the process noise (default: the simulated preset).
        #[arg(long)]
        imu_model: Option<ImuPreset>,
        /// Estimator: fuse the IMUs without estimating their time offsets (for comparison runs).
        #[arg(long)]
        no_imu_offsets: bool,
    },
    /// Runs sim, gps and estimator as child processes with a live status line.
    Demo {
        /// Stop after this many seconds (default: at the end of the scenario or Ctrl-C).
        #[arg(long)]
        duration: Option<f64>,
        /// Number of simulated IMUs.
        #[arg(long, default_value_t = 4)]
        imus: usize,
        /// Scenario file (TOML); default: the embedded ~10 minute drive.
        #[arg(long)]
        scenario: Option<PathBuf>,
        /// IMU path: `xsens` (simulator → pseudo-terminals → `navsync imu` drivers) or `direct`.
        #[arg(long, default_value = "xsens")]
        imu_output: SimImuOutput,
    },
    /// Prints the samples of any navsync service, one per line.
    Echo {
        /// Service, e.g. navsync/imu/0/sample, navsync/time/state.
        service: String,
        /// Stop after N samples.
        #[arg(long)]
        count: Option<u64>,
        /// JSON lines instead of text.
        #[arg(long)]
        json: bool,
        /// Fail if no sample arrives for this many seconds.
        #[arg(long)]
        timeout: Option<f64>,
        /// Print at most N lines per second (the newest sample when a line is due).
        #[arg(long, value_name = "N")]
        rate: Option<f64>,
        /// Print the measured rate (once per second) instead of the samples.
        #[arg(long, conflicts_with_all = ["rate", "fields"])]
        hz: bool,
        /// Print only these fields, e.g. `lat_deg,lon_deg,stamp.host_ns,vel_ned_mps[2]`.
        #[arg(long, value_delimiter = ',')]
        fields: Vec<String>,
    },
    /// 1 PPS driver: edges from a kernel PPS device, a serial modem line or the simulator,
    /// validated (missing/duplicate/early/late counted), to `navsync/pps/{id}/edge`.
    Pps {
        /// kernel:/dev/ppsN, serial-dcd:/dev/ttyX, serial-cts:/dev/ttyX, or sim; default `[pps.ID].source`.
        #[arg(long)]
        source: Option<navsync_drivers::pps::SourceSpec>,
        /// PPS id.
        #[arg(long, default_value = "0", value_parser = parse_id)]
        id: String,
    },
    /// Exports GNSS time (`navsync/time/state`) to chrony/ntpd as an NTP shared-memory refclock.
    Ntpshm {
        /// SHM unit: segment key 0x4e545030 + unit (chrony: `refclock SHM <unit>`).
        #[arg(long, default_value_t = 0)]
        unit: u32,
    },
    /// Records navsync services into an MCAP file until Ctrl-C/SIGTERM or --duration.
    Record {
        /// Output file (MCAP); default `[outputs.record].path`.
        out: Option<PathBuf>,
        /// Services to record: names or patterns (`*` within a segment, `**` across); default `navsync/**`.
        #[arg(long, num_args = 1..)]
        services: Vec<String>,
        /// Stop after this many seconds.
        #[arg(long)]
        duration: Option<f64>,
    },
    /// Publishes a recording into the live services with its original timing, or runs the
    /// estimator over it offline (--estimate).
    Replay {
        /// The recording (MCAP).
        input: PathBuf,
        /// `1` (real time), a factor such as 10, or `max`.
        #[arg(long, default_value = "1")]
        speed: roles::replay::Speed,
        /// Start over at the end, until stopped.
        #[arg(long = "loop")]
        looped: bool,
        /// Publish only these services: names or patterns (`*` within a segment, `**` across).
        #[arg(long, num_args = 1..)]
        services: Vec<String>,
        /// Run the estimator over the recording as fast as the CPU allows instead of publishing.
        #[arg(long)]
        estimate: bool,
        /// Write the estimator's NavState and TimeState into this MCAP file (with --estimate).
        #[arg(long, requires = "estimate")]
        out: Option<PathBuf>,
        /// Format of --out: `mcap`, or `kf-gins` (KF-GINS's result layout; a directory gets
        /// KF_GINS_Navresult.nav, KF_GINS_IMU_ERR.txt and KF_GINS_STD.txt).
        #[arg(long, default_value = "mcap", requires = "out")]
        format: EstimateFormat,
        /// Write the accuracy summary as JSON to this file (with --estimate).
        #[arg(long, requires = "estimate")]
        summary_json: Option<PathBuf>,
        /// The estimator's settings (with --estimate).
        #[command(flatten)]
        est: EstimatorFlags,
    },
    /// Offline analyses of a recording.
    Analyze {
        #[command(subcommand)]
        what: AnalyzeCmd,
    },
    /// Every navsync process and service on this host: rates, last-sample ages, subscribers,
    /// health counters, time-sync state, receiver latency d0, GNSS delay and IMU offsets.
    Status {
        /// One JSON document (one line per refresh with --watch).
        #[arg(long)]
        json: bool,
        /// Refresh every S seconds until Ctrl-C.
        #[arg(long, value_name = "S", num_args = 0..=1, default_missing_value = "1")]
        watch: Option<f64>,
        /// Measurement window of a single report, s.
        #[arg(long, default_value_t = 2.0)]
        window: f64,
        /// With --watch: stop after N refreshes.
        #[arg(long)]
        count: Option<u64>,
    },
    /// Prints the sample layouts as Python ctypes structures (shared/python/navsync_types.py).
    PythonTypes,
    /// Serves the fused state to gpsd clients (gpsd JSON protocol: VERSION, DEVICES, WATCH,
    /// POLL, TPV, SKY, ATT, IMU).
    GpsdServer {
        /// Address to listen on (localhost by default; port 0: any free port, printed on stderr).
        #[arg(long, default_value = "127.0.0.1:2947")]
        listen: std::net::SocketAddr,
        /// Most clients at once.
        #[arg(long, default_value_t = 32)]
        max_clients: usize,
        /// Reports (TPV, ATT, IMU, SKY) per second.
        #[arg(long, default_value_t = 1.0)]
        rate: f64,
    },
    /// One self-contained HTML page with SVG plots of a recording: trajectory, errors against
    /// the truth, GNSS delay and IMU offsets with ±2σ, clock offset and drift, receiver latency.
    Report {
        /// The recording (MCAP).
        input: PathBuf,
        /// The HTML file (default: the recording's name with .html).
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// Run the estimator over the recording even when it has navigation states.
        #[arg(long)]
        estimate: bool,
        /// The estimator's settings (when it runs).
        #[command(flatten)]
        est: EstimatorFlags,
    },
    /// Imports another system's data files into a navsync recording.
    Import {
        #[command(subcommand)]
        what: ImportCmd,
    },
    /// Position, velocity and attitude error statistics of a trajectory against a reference
    /// (KF-GINS result/truth files or navsync recordings).
    Eval {
        /// Reference trajectory.
        #[arg(long)]
        truth: PathBuf,
        /// Trajectory to evaluate.
        #[arg(long)]
        solution: PathBuf,
        /// Leave out the solution's first S seconds.
        #[arg(long, default_value_t = 0.0)]
        skip: f64,
        /// JSON instead of the table.
        #[arg(long)]
        json: bool,
    },
    /// Decodes an NMEA capture offline (same code as the live driver): one JSON object per epoch.
    Nmea {
        /// Capture file, or `-` for stdin.
        file: String,
    },
    /// Checks the configuration file (--config, default /etc/navsync/navsync.toml) without
    /// starting anything: errors name the file, line, field and what was expected.
    CheckConfig,
    /// Installs the binary, the systemd units, sysusers/tmpfiles/udev files and the example
    /// configuration (README "## Running as a service").
    Install {
        /// Installation prefix: the binary goes to PREFIX/bin/navsync, which the units run.
        #[arg(long, default_value = "/usr/local")]
        prefix: PathBuf,
        /// Staging root (an image or package tree): every file goes below it.
        #[arg(long, default_value = "/")]
        root: PathBuf,
    },
}

/// Logs to stderr: the level from `$RUST_LOG`, else the configuration's `[logging].level`,
/// else info. Under systemd (`$JOURNAL_STREAM` set: stderr is the journal) without colours and
/// time stamps (the journal stamps every line); on a terminal with colours.
fn init_logging(config_level: Option<&str>) {
    let filter: Targets = std::env::var("RUST_LOG")
        .ok()
        .and_then(|s| s.parse().ok())
        .or_else(|| config_level.and_then(|s| s.parse().ok()))
        .unwrap_or_else(|| Targets::new().with_default(Level::INFO));
    let journal = std::env::var_os("JOURNAL_STREAM").is_some();
    let tty = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let layer = tracing_subscriber::fmt::layer()
        .with_writer(std::io::stderr)
        .with_target(false)
        .with_ansi(tty && !journal);
    let registry = tracing_subscriber::registry().with(filter);
    let _ = if journal {
        registry.with(layer.without_time()).try_init()
    } else {
        registry.with(layer).try_init()
    };
}

fn main() -> Result<()> {
    let matches = Cli::command().get_matches();
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    // The subcommand's flags, to tell flags given on the command line from defaults.
    let sub = matches.subcommand().map(|(_, m)| m);
    if matches!(cli.cmd, Cmd::CheckConfig) {
        return roles::service::check_config(cli.config.as_deref());
    }
    let cfg = roles::service::load(cli.config.as_deref())?;
    init_logging(cfg.config.logging.level.as_deref());
    match cli.cmd {
        Cmd::CheckConfig => {}
        Cmd::Install { prefix, root } => {
            let done = roles::service::install(&prefix, &root)?;
            for f in &done.files {
                println!("{}", f.display());
            }
            eprintln!(
                "then: systemd-sysusers; systemd-tmpfiles --create; udevadm control --reload; systemctl daemon-reload; \
                 edit /etc/navsync/navsync.toml; navsync check-config; systemctl enable --now navsync.target"
            );
        }
        Cmd::Gps { port, baud, id } => {
            let args = roles::service::gps_args(&cfg, sub, port, baud, id)?;
            navsync_drivers::gps::driver::run(&args).with_context(|| format!("gps driver on {}", args.port))?;
        }
        Cmd::Imu {
            source,
            id,
            sysfs_root,
            dev_root,
            rate,
            axes,
            gyro_range_dps,
            accel_range_g,
            buffer_length,
        } => {
            let args = roles::service::imu_args(&cfg, sub, &id.clone(), source, |source| ImuArgs {
                source,
                id,
                sysfs_root,
                dev_root,
                rate_hz: rate,
                axes,
                gyro_range_dps,
                accel_range_g,
                buffer_length,
            })?;
            navsync_drivers::imu::run(&args).with_context(|| format!("imu driver on {:?}", args.source))?;
        }
        Cmd::Feed {
            capture,
            pty: _,
            link,
            speed,
            looped,
            baud,
            wait_reader,
            hold,
        } => {
            let stats = navsync_drivers::feed::run(&FeedArgs {
                capture: capture.clone(),
                link,
                speed,
                looped,
                baud,
                wait_reader,
                hold_s: hold,
            })
            .with_context(|| format!("feeding {}", capture.display()))?;
            eprintln!(
                "navsync feed: {} bytes in {} chunks, {} lap(s), {} chunk(s) garbled by a wrong reader rate",
                stats.bytes, stats.chunks, stats.laps, stats.garbled_chunks
            );
        }
        Cmd::Estimator { est, idle_polling } => {
            let args = roles::service::estimator_args(&cfg, sub, est.args())?;
            let _hold = idle_polling
                .then(navsync_shared::cpu_wakeup::CpuWakeupHold::take)
                .transpose()
                .context("--idle-polling: holding /dev/cpu_dma_latency at 0")?;
            roles::estimator::run(&args).context("estimator")?;
        }
        Cmd::Sim {
            scenario,
            imus,
            imu_preset,
            imu_offsets_ms,
            gnss_rate,
            gnss_latency,
            clock_ppm,
            pps_jitter_ns,
            seed,
            pty_link,
            imu_output,
            imu_pty_dir,
            duration,
            utc_offset,
            gnss_outage,
            no_vibration,
            fast,
            estimate,
            summary_json,
            record,
            software_sync,
            no_delay_state,
            imu_model,
            no_imu_offsets,
        } => {
            let args = SimArgs {
                scenario,
                imus,
                preset: imu_preset,
                imu_offsets_ms,
                gnss_rate_hz: gnss_rate,
                gnss_latency_s: gnss_latency,
                clock_ppm,
                pps_jitter_ns,
                seed,
                pty_link,
                imu_output,
                imu_pty_dir,
                duration_s: duration,
                utc_offset_s: utc_offset,
                gnss_outages: gnss_outage,
                no_vibration,
            };
            if fast {
                let est = navsync_estimator::settings::Settings {
                    gnss_ids: vec!["0".into()],
                    pps_ids: vec!["0".into()],
                    imu_ids: vec!["0".into()],
                    software_sync,
                    imu_model: imu_model.unwrap_or(ImuPreset::Industrial),
                    estimate_delay: !no_delay_state,
                    estimate_imu_offsets: !no_imu_offsets,
                    ..Default::default()
                };
                anyhow::ensure!(
                    estimate || record.is_some(),
                    "--fast needs --estimate and/or --record OUT.mcap"
                );
                let outputs = roles::sim_estimate::FastOutputs {
                    estimate,
                    summary_json: summary_json.as_deref(),
                    record: record.as_deref(),
                };
                roles::sim_estimate::run_fast(&args, &est, imu_model.is_none(), outputs)
                    .context("offline simulation")?;
            } else {
                navsync_sim::process::run(&args).context("simulator")?;
            }
        }
        Cmd::Demo {
            duration,
            imus,
            scenario,
            imu_output,
        } => {
            roles::demo::run(&roles::demo::DemoArgs {
                duration_s: duration,
                imus,
                scenario,
                imu_output,
                sim_args: Vec::new(),
            })
            .context("demo")?;
        }
        Cmd::Echo {
            service,
            count,
            json,
            timeout,
            rate,
            hz,
            fields,
        } => {
            roles::echo::run(&roles::echo::EchoArgs {
                service: service.clone(),
                count,
                json,
                timeout: timeout.map(Duration::from_secs_f64),
                max_rate_hz: rate,
                measure_rate: hz,
                fields,
            })
            .with_context(|| format!("echo {service}"))?;
        }
        Cmd::Pps { source, id } => {
            let args = roles::service::pps_args(&cfg, source, id)?;
            let shown = args.source.to_string();
            navsync_drivers::pps::run(&args).with_context(|| format!("pps driver on {shown}"))?;
        }
        Cmd::Ntpshm { unit } => {
            let unit = roles::service::ntpshm_unit(&cfg, sub, unit);
            roles::ntpshm::run(&roles::ntpshm::NtpShmArgs { unit }).context("ntpshm")?;
        }
        Cmd::Record {
            out,
            services,
            duration,
        } => {
            let (out, services) = roles::service::record_target(&cfg, out, services)?;
            roles::record::run(&roles::record::RecordArgs {
                out: out.clone(),
                services,
                duration_s: duration,
                progress: true,
            })
            .with_context(|| format!("recording {}", out.display()))?;
        }
        Cmd::Replay {
            input,
            speed,
            looped,
            services,
            estimate,
            out,
            format,
            summary_json,
            est,
        } => {
            if estimate {
                roles::replay::run_estimate(&roles::replay::EstimateArgs {
                    input: input.clone(),
                    est: est.args(),
                    out,
                    kf_gins_format: format == EstimateFormat::KfGins,
                    summary_json,
                })
                .with_context(|| format!("estimating over {}", input.display()))?;
            } else {
                roles::replay::run(&roles::replay::ReplayArgs {
                    input: input.clone(),
                    speed,
                    looped,
                    services,
                    progress: true,
                })
                .with_context(|| format!("replaying {}", input.display()))?;
            }
        }
        Cmd::Analyze {
            what:
                AnalyzeCmd::GnssDelay {
                    recording,
                    segments,
                    imus,
                    imu_model,
                    gnss_vel_std,
                },
        } => {
            let args = roles::analyze::GnssDelayArgs {
                recording: recording.clone(),
                segments,
                est: navsync_estimator::settings::Settings {
                    imu_ids: imus,
                    imu_model,
                    gnss_vel_std_mps: gnss_vel_std,
                    ..Default::default()
                },
            };
            let rows =
                roles::analyze::gnss_delay(&args).with_context(|| format!("analysing {}", recording.display()))?;
            print!("{}", roles::analyze::table(&rows));
        }
        Cmd::Status {
            json,
            watch,
            window,
            count,
        } => {
            anyhow::ensure!(
                window > 0.0 && watch.is_none_or(|w| w > 0.0),
                "--window and --watch take a positive number of seconds"
            );
            roles::status::run(&roles::status::StatusArgs {
                json,
                watch: watch.map(Duration::from_secs_f64),
                window: Duration::from_secs_f64(window),
                count,
            })
            .context("status")?;
        }
        Cmd::PythonTypes => roles::python_types::run().context("writing stdout")?,
        Cmd::GpsdServer {
            listen,
            max_clients,
            rate,
        } => {
            anyhow::ensure!(max_clients > 0, "--max-clients must be at least 1");
            anyhow::ensure!(
                rate > 0.0 && rate <= 1000.0,
                "--rate must be in (0, 1000] reports per second"
            );
            roles::gpsd_server::run(&roles::gpsd_server::GpsdArgs {
                listen,
                max_clients,
                rate_hz: rate,
            })
            .context("gpsd-server")?;
        }
        Cmd::Import {
            what:
                ImportCmd::KfGins {
                    imu,
                    gnss,
                    truth,
                    imu_rate,
                    week,
                    out,
                },
        } => {
            let stats = roles::kf_gins::import(&roles::kf_gins::ImportArgs {
                imu,
                gnss,
                truth,
                imu_rate_hz: imu_rate,
                week,
                imu_id: "0".into(),
                out: out.clone(),
            })
            .with_context(|| format!("importing into {}", out.display()))?;
            eprintln!(
                "{}: {} IMU samples ({:.1} Hz), {} GNSS fixes, {} PPS edges, {} truth samples (GPS week {})",
                out.display(),
                stats.imu,
                stats.imu_rate_hz,
                stats.fixes,
                stats.pps,
                stats.truth,
                stats.week
            );
        }
        Cmd::Report {
            input,
            out,
            estimate,
            est,
        } => {
            let out = out.unwrap_or_else(|| roles::report::default_out(&input));
            let plots = roles::report::run(&roles::report::ReportArgs {
                input: input.clone(),
                out: out.clone(),
                estimate,
                est: est.args(),
            })
            .with_context(|| format!("report of {}", input.display()))?;
            eprintln!("{}: {plots} plots", out.display());
        }
        Cmd::Eval {
            truth,
            solution,
            skip,
            json,
        } => {
            roles::eval::run(&roles::eval::EvalArgs {
                truth,
                solution,
                skip_s: skip,
                json,
            })
            .context("eval")?;
        }
        Cmd::Nmea { file } => {
            let bytes = if file == "-" {
                let mut b = Vec::new();
                std::io::stdin().read_to_end(&mut b).context("reading stdin")?;
                b
            } else {
                std::fs::read(&file).with_context(|| format!("reading {file}"))?
            };
            let (fixes, counters) = navsync_drivers::gps::offline::decode_capture(&bytes);
            let mut out = std::io::stdout().lock();
            for f in &fixes {
                writeln!(out, "{}", navsync_drivers::gps::offline::epoch_json(f))?;
            }
            eprintln!("{} epochs; {counters:?}", fixes.len());
        }
    }
    Ok(())
}
