//! `navsync-bench`: the benchmarks (docs/benchmarks/); one options
//! struct per subcommand, passed whole to its module.

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use navsync_bench::{e2e, gnss_latency, history, host, ipc, throughput, timing, zenoh};

#[derive(Parser)]
#[command(name = "navsync-bench", version, about = "navsync's benchmarks")]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Offline timing benchmark: clock model, holdover, d0 (the table in docs/benchmarks/timing.md).
    Timing,
    /// IPC latency between processes: iceoryx2 services against a Unix-domain socket.
    Ipc(ipc::IpcBenchArgs),
    /// End-to-end latency (IMU driver → estimator → subscriber), CPU and memory of every
    /// process under IMUs at 1 kHz and GNSS at 10 Hz.
    E2e(e2e::E2eArgs),
    /// Estimator throughput (IMU samples/s, one core) for several IMU counts; `--hour`: the
    /// cost per sample per 10 minutes of a one-hour drive.
    Throughput(throughput::ThroughputArgs),
    /// A receiver's epoch → the fix at a subscriber (Rust client, navsync echo), against gpsd
    /// → gpspipe in the same run, on real captures written epoch by epoch into pseudo-terminals.
    GnssLatency(gnss_latency::GnssLatencyArgs),
    /// A NavState from host A's iceoryx2 to host B's through two Zenoh bridges over a veth
    /// link between network namespaces (root; a navsync built with its default feature `zenoh`).
    Zenoh(zenoh::ZenohBenchArgs),
    /// A `state_at` query of the history of states from another process than its writer's
    /// (p50/p99 per query, a writer at 1 kHz).
    History(history::HistoryArgs),
    /// The machine's own wake-up stalls: a sleeper per CPU at a fixed rate, no navsync code
    /// (read beside the latency benchmarks; finds stalls that keep the phase of a 100 ms cycle).
    Host(host::HostArgs),
    /// The processes the benchmarks start (publishers and subscribers).
    #[command(subcommand, hide = true)]
    Helper(Helper),
}

#[derive(Subcommand)]
enum Helper {
    /// Publishes COUNT samples with CLOCK_MONOTONIC and a sequence number in the payload.
    IpcPub(ipc::PubArgs),
    /// Receives the samples of `ipc-pub` and writes their latencies.
    IpcSub(ipc::SubArgs),
    /// Subscribes to the NavStates and the reference IMU's samples and measures their latency.
    E2eSub {
        /// Seconds to wait after the first NavState.
        #[arg(long)]
        warmup_s: f64,
        /// Seconds to measure.
        #[arg(long)]
        duration_s: f64,
    },
    /// Prints the receipt time of every fix on a GNSS fix service (`gnss-latency`).
    GnssSub {
        /// The service, e.g. navsync/gnss/0/fix.
        #[arg(long)]
        service: String,
    },
    /// Writes a history of states at 1 kHz (`history`).
    HistoryWriter(history::WriterArgs),
    /// Prints the time and size of every read on a terminal (`gnss-latency`'s floor).
    PtyRead {
        /// The terminal, e.g. /dev/pts/7.
        #[arg(long)]
        port: std::path::PathBuf,
    },
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_target(false)
        .init();
    match cli.cmd {
        Cmd::Timing => timing::run().context("timing benchmark")?,
        Cmd::Ipc(a) => drop(ipc::run(&a).context("IPC benchmark")?),
        Cmd::E2e(a) => drop(e2e::run(&a).context("end-to-end benchmark")?),
        Cmd::Throughput(a) => drop(throughput::run(&a).context("throughput benchmark")?),
        Cmd::GnssLatency(a) => drop(gnss_latency::run(&a).context("GNSS latency benchmark")?),
        Cmd::Zenoh(a) => drop(zenoh::run(&a).context("Zenoh benchmark")?),
        Cmd::Host(a) => drop(host::run(&a).context("host benchmark")?),
        Cmd::History(a) => drop(history::run(&a).context("history benchmark")?),
        Cmd::Helper(Helper::HistoryWriter(a)) => history::helper_writer(&a).context("history-writer")?,
        Cmd::Helper(Helper::GnssSub { service }) => gnss_latency::helper_sub(&service).context("gnss-sub")?,
        Cmd::Helper(Helper::PtyRead { port }) => gnss_latency::helper_pty_read(&port).context("pty-read")?,
        Cmd::Helper(Helper::IpcPub(a)) => ipc::helper_pub(&a).context("ipc-pub")?,
        Cmd::Helper(Helper::IpcSub(a)) => ipc::helper_sub(&a).context("ipc-sub")?,
        Cmd::Helper(Helper::E2eSub { warmup_s, duration_s }) => {
            e2e::helper_sub(warmup_s, duration_s).context("e2e-sub")?
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    /// clap's consistency checks of every subcommand.
    #[test]
    fn the_command_line_is_consistent() {
        super::Cli::command().debug_assert();
    }
}
