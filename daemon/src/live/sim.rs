//! `navsync sim`: the simulated sensor world in real time (`navsync_sim::process`), or as
//! fast as the CPU allows into the estimator and/or a recording (`--fast`,
//! [`crate::tools::sim_fast`]).

use std::path::PathBuf;

use anyhow::{Context, Result};
use navsync_sim::process::SimArgs;

use crate::config::Loaded;
use crate::config::estimator::ModelFlags;
use crate::tools::sim_fast;

/// `navsync sim`: IMUs and PPS to their services, NMEA into a pseudo-terminal.
#[derive(clap::Args, Debug)]
pub struct Options {
    /// The simulated world.
    #[command(flatten)]
    pub world: SimArgs,
    /// Do not wait for real time: produce the samples as fast as the CPU allows (with
    /// --estimate and/or --record).
    #[arg(long)]
    pub fast: bool,
    /// Run the estimator offline over the simulated samples and print the accuracy report.
    #[arg(long, requires = "fast")]
    pub estimate: bool,
    /// Write the accuracy report as JSON to this file.
    #[arg(long, requires = "estimate")]
    pub summary_json: Option<PathBuf>,
    /// Write the samples the drivers would publish, and the truth, into this MCAP file.
    #[arg(long, requires = "fast")]
    pub record: Option<PathBuf>,
    /// With --record: encoding and standard messages.
    #[command(flatten)]
    pub format: crate::config::recording::RecordingFlags,
    /// Replace an existing recording at --record or --summary-json (never the scenario).
    #[arg(long, requires = "fast")]
    pub force: bool,
    /// The estimator's models (with --estimate; every simulated IMU is fused, the first as
    /// the reference; unless --imu-model is given the filter is told the simulated IMU class
    /// and receiver velocity noise).
    #[command(flatten)]
    pub est: ModelFlags,
}

/// Runs the simulator as the options say.
pub fn run(opts: Options, cfg: &Loaded) -> Result<()> {
    if opts.fast {
        anyhow::ensure!(
            opts.estimate || opts.record.is_some(),
            "--fast needs --estimate and/or --record OUT.mcap"
        );
        let outputs = sim_fast::Outputs {
            estimate: opts.estimate,
            summary_json: opts.summary_json.as_deref(),
            record: opts.record.as_deref(),
            record_options: opts.format.options(&cfg.config.recording),
            force: opts.force,
        };
        return sim_fast::run(&opts.world, &opts.est, cfg, outputs).context("offline simulation");
    }
    navsync_sim::process::run(&opts.world).context("simulator")
}
