//! `navsync sim --fast --estimate`: the simulated world's published samples fed straight into
//! the estimator library as fast as the CPU allows, and the accuracy report printed.

use std::path::Path;

use navsync_drivers::sim::process::{SimArgs, load_config};
use navsync_drivers::sim::published::PublishedStream;
use navsync_drivers::sim::world::World;

use crate::estimator::pipeline::Pipeline;
use crate::evaluation::DelayTruth;
use crate::offline;
use crate::roles::estimator::EstimatorArgs;

/// Errors of the offline simulation.
#[derive(Debug, thiserror::Error)]
pub enum SimEstimateError {
    /// Bad scenario.
    #[error(transparent)]
    Scenario(#[from] navsync_drivers::sim::error::SimError),
    /// Writing the summary.
    #[error("writing {path}: {source}")]
    Io {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
}

/// Runs the world through the estimator and prints the summary (and writes it as JSON).
/// `model_from_sim`: tell the filter the simulated IMU preset and receiver velocity noise.
pub fn run(
    sim: &SimArgs,
    est: &EstimatorArgs,
    model_from_sim: bool,
    summary_json: Option<&Path>,
) -> Result<(), SimEstimateError> {
    let cfg = load_config(sim)?;
    let mut est = est.clone();
    if model_from_sim {
        // The filter is told what the simulated devices are: IMU class and receiver velocity noise.
        est.imu_model = cfg.imu.preset;
        est.gnss_vel_std_mps = cfg.gnss.velocity_sigma_mps.max(0.01);
    }
    let start_utc = navsync_shared::time::realtime_now_ns() / 1_000_000_000 * 1_000_000_000;
    let world = World::new(&cfg, 1_000_000_000_000, start_utc)?;
    let stream = PublishedStream::new(world).map(|p| p.sample);
    let mut pipeline = Pipeline::new(est.pipeline_config());
    let truth = if est.software_sync {
        DelayTruth::ReceiverLatency
    } else {
        DelayTruth::Zero
    };
    let run = offline::run(&mut pipeline, stream, truth, |_| {});
    println!("{}", run.summary.table());
    if let Some(p) = summary_json {
        let text = serde_json::to_string_pretty(&run.summary).unwrap_or_default();
        std::fs::write(p, text).map_err(|source| SimEstimateError::Io {
            path: p.display().to_string(),
            source,
        })?;
    }
    Ok(())
}
