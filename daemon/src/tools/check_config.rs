//! `navsync check-config`: parses and checks the whole configuration file (every section is
//! typed: device strings are parsed as the roles parse them) and prints what every role would
//! run. Starts nothing.

use std::path::Path;

use anyhow::Result;
use navsync_drivers::gnss::driver::Baud;

use crate::config::estimator::EstimatorFlags;
use crate::config::{DEFAULT_PATH, Loaded};

/// Checks `--config FILE` (default `/etc/navsync/navsync.toml`).
pub fn run(explicit: Option<&Path>) -> Result<()> {
    let path = explicit.unwrap_or(Path::new(DEFAULT_PATH));
    let cfg = Loaded::load(path)?;
    let c = &cfg.config;
    let est = EstimatorFlags::default().settings(&cfg)?;
    let mut warnings = Vec::new();
    for (kind, ids, known) in [
        ("gnss", &est.inputs.gnss, c.gnss.keys().collect::<Vec<_>>()),
        ("pps", &est.inputs.pps, c.pps.keys().collect()),
        ("imus", &est.inputs.imus, c.imu.keys().collect()),
    ] {
        for id in ids {
            if !known.contains(&id) {
                warnings.push(format!(
                    "estimator.{kind} names `{id}`, which has no section in this file (its driver must get its device on the command line)"
                ));
            }
        }
    }
    println!("{}: OK", cfg.file.display());
    for (id, g) in &c.gnss {
        println!(
            "  navsync gnss --id {id}: {} at {} Bd, {}",
            g.port,
            g.baud.unwrap_or(Baud::Fixed(9600)),
            g.protocol.unwrap_or_default()
        );
    }
    for (id, p) in &c.pps {
        println!("  navsync pps --id {id}: {}", p.source);
    }
    for (id, i) in &c.imu {
        println!(
            "  navsync imu --id {id}: {} (rotation {:?}°, lever arm {:?} m)",
            i.source, i.mounting.rotation_deg, i.mounting.lever_arm_m
        );
    }
    let noise = if est.imu.imu_noise.is_some() {
        let n = est.noise();
        format!(
            "IMU noise ARW {:?} °/√h, VRW {:?} m/s/√h ([estimator.imu_noise])",
            n.arw_deg_per_sqrt_h.0, n.vrw_mps_per_sqrt_h.0
        )
    } else {
        format!("{} IMU noise", est.imu.imu_model.name())
    };
    println!(
        "  navsync estimator: gnss {:?}, pps {:?}, imus {:?}, {} sync, {noise}{}",
        est.inputs.gnss,
        est.inputs.pps,
        est.inputs.imus,
        if est.time.software_sync { "software" } else { "PPS" },
        if est.nav.initial_state.is_some() {
            ", initial state given"
        } else {
            ""
        }
    );
    if let Some(n) = &c.outputs.ntpshm {
        println!("  navsync ntpshm: unit {}", n.unit);
    }
    if let Some(r) = &c.outputs.record {
        println!("  navsync record: {}", r.path.display());
    }
    println!(
        "  recordings: {}{}",
        match c.recording.encoding {
            navsync_recording::Encoding::Cdr => "CDR (a ROS 2 bag)",
            navsync_recording::Encoding::Json => "JSON",
        },
        if c.recording.ros_std {
            " with the standard ROS 2 messages"
        } else {
            ""
        }
    );
    if let Some(z) = &c.bridge.zenoh {
        println!(
            "  navsync bridge zenoh: instance {}, export {:?}, import {}, listen {:?}, connect {:?}",
            z.instance.as_deref().unwrap_or("(host name)"),
            z.export.clone().unwrap_or_else(|| vec!["(default)".into()]),
            z.import.as_deref().unwrap_or("none"),
            z.listen,
            z.connect
        );
    }
    for w in warnings {
        println!("warning: {w}");
    }
    Ok(())
}
