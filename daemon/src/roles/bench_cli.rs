//! The command line of `navsync bench …` (and of the hidden `navsync bench-helper …` processes
//! the benchmarks start), and the dispatch to the benchmarks.

use std::path::PathBuf;

use super::bench_ipc::{self, Kind, Rate, Transport};

/// `navsync bench WHAT`.
#[derive(Debug, clap::Subcommand)]
pub enum BenchCmd {
    /// Offline timing benchmark: clock model, holdover, d0 (the table in the README's "## Timing").
    Timing,
    /// IPC latency between processes: iceoryx2 services against a Unix-domain socket.
    Ipc {
        /// Samples per case.
        #[arg(long, default_value_t = 100_000)]
        samples: u64,
        /// Sample types, comma-separated: imu, nav.
        #[arg(long, value_delimiter = ',', default_value = "imu,nav")]
        kinds: Vec<Kind>,
        /// Publishing rates, Hz or `max` (back to back), comma-separated.
        #[arg(long, value_delimiter = ',', default_value = "1000,max")]
        rates: Vec<Rate>,
        /// Subscriber process counts, comma-separated (at most 16).
        #[arg(long, value_delimiter = ',', default_value = "1")]
        subscribers: Vec<usize>,
        /// Transports, comma-separated: iceoryx2, socket.
        #[arg(long, value_delimiter = ',', default_value = "iceoryx2,socket")]
        transports: Vec<Transport>,
        /// Run publisher (PRIO) and subscribers (PRIO − 1) under SCHED_FIFO (needs CAP_SYS_NICE).
        #[arg(long, value_name = "PRIO", value_parser = clap::value_parser!(u8).range(1..=99))]
        realtime: Option<u8>,
        /// A short run (2000 samples per case) for smoke tests.
        #[arg(long)]
        quick: bool,
        /// Write the results as JSON to this file.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// End-to-end latency (IMU driver → estimator → subscriber), CPU and memory of every process
    /// under IMUs at 1 kHz and GNSS at 10 Hz.
    E2e {
        /// IMU counts, comma-separated (one run each, at most 8).
        #[arg(long, value_delimiter = ',', default_value = "4")]
        imus: Vec<usize>,
        /// Measured window, s.
        #[arg(long, default_value_t = 60.0)]
        duration: f64,
        /// Warm-up after the first NavState, s.
        #[arg(long, default_value_t = 10.0)]
        warmup: f64,
        /// How the IMU samples reach the services: xsens (simulator → pseudo-terminal → driver) or direct.
        #[arg(long, default_value = "xsens")]
        imu_path: super::bench_e2e::ImuPath,
        /// Run the latency chain (IMU drivers, estimator, subscriber) under SCHED_FIFO with this
        /// priority (1–99; needs CAP_SYS_NICE), as a deployment would with
        /// `CPUSchedulingPolicy=fifo`; the simulator (the "hardware") stays SCHED_OTHER.
        #[arg(long, value_name = "PRIO", value_parser = clap::value_parser!(u8).range(1..=99))]
        realtime: Option<u8>,
        /// A short run (2 IMUs, 3 s warm-up, 5 s measured) for smoke tests.
        #[arg(long)]
        quick: bool,
        /// Write the results as JSON to this file.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Estimator throughput (IMU samples/s, one core) for several IMU counts; `--hour`: the
    /// cost per sample per 10 minutes of a one-hour drive.
    Throughput {
        /// IMU counts, comma-separated.
        #[arg(long, value_delimiter = ',', default_value = "1,4,8")]
        imus: Vec<usize>,
        /// Scenario file (default: the embedded 10-minute drive).
        #[arg(long)]
        scenario: Option<PathBuf>,
        /// Seconds of scenario to run (default: all of it).
        #[arg(long)]
        duration: Option<f64>,
        /// The one-hour drive (sim/scenarios/long_drive_1h.toml, embedded), one IMU, cost per 10 minutes.
        #[arg(long, conflicts_with_all = ["scenario", "imus"])]
        hour: bool,
        /// A short run (60 s of scenario, 1 and 4 IMUs) for smoke tests.
        #[arg(long)]
        quick: bool,
        /// Write the results as JSON to this file.
        #[arg(long)]
        json: Option<PathBuf>,
    },
}

/// `navsync bench-helper WHAT` (hidden): the processes the benchmarks start.
#[derive(Debug, clap::Subcommand)]
pub enum HelperCmd {
    /// Publishes COUNT samples with CLOCK_MONOTONIC and a sequence number in the payload.
    IpcPub {
        /// Transport.
        #[arg(long)]
        transport: Transport,
        /// Sample type.
        #[arg(long)]
        kind: Kind,
        /// Samples to publish.
        #[arg(long)]
        count: u64,
        /// Hz or `max`.
        #[arg(long)]
        rate: Rate,
        /// Subscriber socket paths (socket transport), comma-separated.
        #[arg(long, value_delimiter = ',')]
        sockets: Vec<PathBuf>,
    },
    /// Receives the samples of `ipc-pub` and writes their latencies.
    IpcSub {
        /// Transport.
        #[arg(long)]
        transport: Transport,
        /// Sample type.
        #[arg(long)]
        kind: Kind,
        /// Samples the publisher sends.
        #[arg(long)]
        count: u64,
        /// Subscriber index.
        #[arg(long, default_value_t = 0)]
        index: usize,
        /// Latency file (little-endian i64 ns).
        #[arg(long)]
        out: PathBuf,
        /// Socket path to listen on (socket transport).
        #[arg(long)]
        socket: Option<PathBuf>,
    },
    /// Subscribes to the NavStates and the reference IMU's samples and measures their latency.
    E2eSub {
        /// Seconds to wait after the first NavState.
        #[arg(long)]
        warmup_s: f64,
        /// Seconds to measure.
        #[arg(long)]
        duration_s: f64,
    },
}

/// Errors of `navsync bench`.
#[derive(Debug, thiserror::Error)]
pub enum BenchCliError {
    /// The timing benchmark.
    #[error(transparent)]
    Timing(#[from] super::bench_timing::BenchError),
    /// The IPC benchmark.
    #[error(transparent)]
    Ipc(#[from] bench_ipc::IpcBenchError),
    /// The end-to-end benchmark.
    #[error(transparent)]
    E2e(#[from] super::bench_e2e::E2eError),
    /// The throughput benchmark.
    #[error(transparent)]
    Throughput(#[from] super::bench_throughput::ThroughputError),
    /// Writing a scenario file.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// Bad arguments.
    #[error("{0}")]
    Args(String),
}

/// Runs `navsync bench WHAT`.
pub fn run(cmd: BenchCmd) -> Result<(), BenchCliError> {
    match cmd {
        BenchCmd::Timing => super::bench_timing::run("timing")?,
        BenchCmd::Ipc {
            samples,
            kinds,
            rates,
            subscribers,
            transports,
            realtime,
            quick,
            json,
        } => {
            if let Some(&n) = subscribers
                .iter()
                .find(|&&n| n == 0 || n > navsync_shared::services::MAX_SUBSCRIBERS)
            {
                return Err(BenchCliError::Args(format!(
                    "--subscribers {n}: 1 to {}",
                    navsync_shared::services::MAX_SUBSCRIBERS
                )));
            }
            bench_ipc::run(&bench_ipc::IpcBenchArgs {
                samples: if quick { 2000 } else { samples.max(1) },
                kinds,
                rates,
                subscribers,
                transports,
                realtime,
                json,
            })?;
        }
        BenchCmd::E2e {
            imus,
            duration,
            warmup,
            imu_path,
            realtime,
            quick,
            json,
        } => {
            if let Some(&n) = imus.iter().find(|&&n| n == 0 || n > navsync_shared::samples::MAX_IMUS) {
                return Err(BenchCliError::Args(format!(
                    "--imus {n}: 1 to {}",
                    navsync_shared::samples::MAX_IMUS
                )));
            }
            super::bench_e2e::run(&super::bench_e2e::E2eArgs {
                imus: if quick { vec![2] } else { imus },
                duration_s: if quick { 5.0 } else { duration },
                warmup_s: if quick { 3.0 } else { warmup },
                imu_path,
                realtime,
                json,
            })?;
        }
        BenchCmd::Throughput {
            imus,
            scenario,
            duration,
            hour,
            quick,
            json,
        } => {
            // The hour-long drive is embedded, so the command runs from any directory.
            let hour_file = if hour {
                let p = std::env::temp_dir().join(format!("navsync-long-drive-{}.toml", std::process::id()));
                std::fs::write(&p, LONG_DRIVE_1H)?;
                Some(p)
            } else {
                None
            };
            let args = super::bench_throughput::ThroughputArgs {
                imus: if hour {
                    vec![1]
                } else if quick {
                    vec![1, 4]
                } else {
                    imus
                },
                scenario: hour_file.clone().or(scenario),
                duration_s: if quick { Some(60.0) } else { duration },
                block_s: if quick { 20.0 } else { super::bench_throughput::BLOCK_S },
                json,
            };
            if let Some(&n) = args
                .imus
                .iter()
                .find(|&&n| n == 0 || n > navsync_shared::samples::MAX_IMUS)
            {
                return Err(BenchCliError::Args(format!(
                    "--imus {n}: 1 to {}",
                    navsync_shared::samples::MAX_IMUS
                )));
            }
            let r = super::bench_throughput::run(&args);
            if let Some(p) = hour_file {
                let _ = std::fs::remove_file(p);
            }
            r?;
        }
    }
    Ok(())
}

/// The one-hour drive of `navsync bench throughput --hour`.
pub const LONG_DRIVE_1H: &str = include_str!("../../../sim/scenarios/long_drive_1h.toml");

/// Runs `navsync bench-helper WHAT`.
pub fn run_helper(cmd: HelperCmd) -> Result<(), BenchCliError> {
    match cmd {
        HelperCmd::IpcPub {
            transport,
            kind,
            count,
            rate,
            sockets,
        } => bench_ipc::helper_pub(&bench_ipc::PubArgs {
            transport,
            kind,
            count,
            rate,
            sockets,
        })?,
        HelperCmd::IpcSub {
            transport,
            kind,
            count,
            index,
            out,
            socket,
        } => bench_ipc::helper_sub(&bench_ipc::SubArgs {
            transport,
            kind,
            count,
            index,
            out,
            socket,
        })?,
        HelperCmd::E2eSub { warmup_s, duration_s } => super::bench_e2e::helper_sub(warmup_s, duration_s)?,
    }
    Ok(())
}
