//! `navsync sim --fast`: the simulated world's published samples, produced as fast as the CPU
//! allows, fed straight into the estimator library (`--estimate`, prints the accuracy report)
//! and/or written into an MCAP recording (`--record OUT.mcap`).
//!
//! The samples are exactly those the drivers would publish ([`PublishedStream`]: IMU samples
//! and PPS edges as the simulator publishes them, fixes decoded from the world's NMEA by the
//! GNSS driver's own decoder, the truth), in delivery order. In the recording each message has
//! `log_time` = the simulated UTC of its delivery instant and `publish_time` = its delivery
//! host time (`World::utc_ns_at_host`), so `navsync replay` paces it as the drivers would have.

use navsync_recording::output::{Overwrite, check_target, write_file};
use std::path::Path;

use navsync_recording::{RecordingError, SampleRecorder, channels};
use navsync_shared::services;
use navsync_sim::process::{SimArgs, load_config};
use navsync_sim::published::PublishedStream;
use navsync_sim::world::World;

use navsync_estimator::offline;
use navsync_estimator::settings::Settings;
use navsync_sim::scenario::SimConfig;

use crate::config::estimator::ModelFlags;
use crate::config::{ConfigError, Loaded};

/// Errors of the offline simulation.
#[derive(Debug, thiserror::Error)]
pub enum SimEstimateError {
    /// Bad scenario.
    #[error(transparent)]
    Scenario(#[from] navsync_sim::error::SimError),
    /// Writing the summary.
    #[error("writing {path}: {source}")]
    Io {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// Writing the recording.
    #[error(transparent)]
    Recording(#[from] RecordingError),
    /// The estimator's settings.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The estimator produced no usable states or far fewer than expected.
    #[error("{0}")]
    Unusable(String),
}

/// What `navsync sim --fast` does with the samples.
#[derive(Debug, Clone, Default)]
pub struct Outputs<'a> {
    /// Run the estimator and print the accuracy report.
    pub estimate: bool,
    /// Write the accuracy report as JSON here (with `estimate`).
    pub summary_json: Option<&'a Path>,
    /// Write the samples into this MCAP file.
    pub record: Option<&'a Path>,
    /// How the recording is written.
    pub record_options: navsync_recording::RecordingOptions,
    /// Replace an existing recording (`--force`).
    pub force: bool,
}

/// The estimator's settings for the simulated world: every simulated IMU (ids "0", "1", …;
/// the first is the reference), the configuration file, then `flags`. Unless the flags name
/// an IMU model, the filter is told what the simulated devices are: the IMU class and the
/// receiver's velocity noise.
pub fn settings(cfg: &SimConfig, flags: &ModelFlags, file: &Loaded) -> Result<Settings, ConfigError> {
    let mut s = Settings::default();
    crate::config::estimator::apply_file(&mut s, file)?;
    s.inputs.imus = (0..cfg.imu.count).map(|i| i.to_string()).collect();
    if !flags.gives("imu_model") {
        s.imu.imu_model = cfg.imu.preset;
        s.gnss.gnss_vel_std_mps = sim_gnss_vel_std(cfg);
    }
    s.nav.gnss_lever_arm_m = cfg.gnss.antenna_lever_arm_m;
    flags.apply(&mut s)?;
    crate::config::estimator::check(&s, file)?;
    Ok(s)
}

/// The velocity σ the filter is given for the simulated receiver, m/s (its noise, at least 1 cm/s).
fn sim_gnss_vel_std(cfg: &SimConfig) -> f64 {
    cfg.gnss.velocity_sigma_mps.max(0.01)
}

/// Stores in the recording what the simulated devices are (each IMU's noise model, the
/// antenna lever arm, the receiver's velocity σ), so `replay --estimate` uses the right models.
fn describe_devices<W: std::io::Write + std::io::Seek>(
    mut rec: SampleRecorder<W>,
    cfg: &SimConfig,
) -> Result<SampleRecorder<W>, RecordingError> {
    for i in 0..cfg.imu.count {
        let noise = cfg.imu_unit(i).preset.noise();
        rec.set_channel_metadata(
            &services::imu_sample(&i.to_string()),
            channels::META_IMU_NOISE,
            &channels::metadata_value(&noise),
        )?;
    }
    let fix = services::gnss_fix("0");
    rec.set_channel_metadata(
        &fix,
        channels::META_LEVER_ARM,
        &channels::metadata_value(&cfg.gnss.antenna_lever_arm_m),
    )?;
    rec.set_channel_metadata(
        &fix,
        channels::META_GNSS_VEL_STD,
        &channels::metadata_value(&sim_gnss_vel_std(cfg)),
    )?;
    Ok(rec)
}

/// Produces the world's samples as fast as the CPU allows (up to `--duration` of scenario
/// time when given) and estimates and/or records them.
pub fn run(sim: &SimArgs, flags: &ModelFlags, file: &Loaded, outputs: Outputs<'_>) -> Result<(), SimEstimateError> {
    let cfg = load_config(sim)?;
    let est = settings(&cfg, flags, file)?;
    let start_host = 1_000_000_000_000;
    let start_utc = match sim.start_utc_s {
        Some(s) => s * 1_000_000_000,
        None => {
            (navsync_shared::time::realtime_now_ns() + (sim.utc_offset_s * 1e9) as i64) / 1_000_000_000 * 1_000_000_000
        }
    };
    let world = World::new(&cfg, start_host, start_utc)?;
    // The world's clock, for the UTC of each delivery instant (a pure function of the world).
    let clock = world.clone();
    let end_host = sim.duration_s.map(|d| start_host + (d * 1e9) as i64);
    // Written beside their names and renamed into place at the end (never over the scenario
    // file, nor over a recording without --force).
    let inputs: Vec<&Path> = sim.scenario.as_deref().into_iter().collect();
    let rules = Overwrite::new(&inputs, outputs.force);
    if let Some(p) = outputs.summary_json {
        check_target(p, &rules)?;
    }
    let mut recorder = match outputs.record {
        Some(p) => Some(describe_devices(
            SampleRecorder::create(p, &rules, outputs.record_options.clone())?,
            &cfg,
        )?),
        None => None,
    };
    let mut write_err: Option<RecordingError> = None;
    let mut unusable = None;
    let stream = PublishedStream::new(world)
        .take_while(|p| end_host.is_none_or(|end| p.delivered_ns <= end))
        .inspect(|p| {
            if let Some(r) = recorder.as_mut()
                && write_err.is_none()
            {
                let log_time = clock.utc_ns_at_host(p.delivered_ns).max(0) as u64;
                if let Err(e) = r.write(&p.service, &p.sample, log_time, p.delivered_ns.max(0) as u64) {
                    write_err = Some(e);
                }
            }
        })
        .map(|p| p.sample);
    if outputs.estimate {
        let run = offline::estimate(&est, stream.map(|s| (s, ())), false, |_, _| {});
        println!("{}", run.summary.table());
        if let Some(p) = outputs.summary_json {
            let text = serde_json::to_string_pretty(&run.summary).unwrap_or_default();
            write_file(p, &rules, text.as_bytes())?;
        }
        if let Some(p) = run.summary.problem {
            unusable = Some(p);
        }
    } else {
        stream.for_each(drop);
    }
    if let Some(e) = write_err {
        return Err(e.into());
    }
    if let Some(r) = recorder {
        let messages = r.message_count();
        r.close()?;
        if let Some(p) = outputs.record {
            eprintln!("navsync sim: {messages} samples recorded to {}", p.display());
        }
    }
    match unusable {
        Some(p) => Err(SimEstimateError::Unusable(p)),
        None => Ok(()),
    }
}
