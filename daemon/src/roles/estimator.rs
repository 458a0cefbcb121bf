//! `navsync estimator`: subscribes to the timing and sensor services, runs the estimator
//! library and publishes `navsync/time/state` (and, with the navigation filter,
//! `navsync/nav/state`).
//!
//! The loop sleeps in a WaitSet on the subscribers' events; on every wake-up it drains the
//! services in a fixed order (PPS, GNSS, IMUs), so the result depends only on the samples and
//! the order in which they were received.

use std::time::Duration;

use iceoryx2::prelude::*;
use navsync_shared::health_reporter::HealthReporter;
use navsync_shared::ipc::{IpcError, IpcNode, Subscriber};
use navsync_shared::samples::{GnssFix, ImuSample, PpsEdge, TimeState};
use navsync_shared::services;
use navsync_shared::time::{NS_PER_S, monotonic_now_ns};
use tracing::{info, info_span, warn};

use crate::estimator::time_sync::{TimeSync, TimeSyncConfig};

/// Command-line settings of the estimator process.
#[derive(Debug, Clone)]
pub struct EstimatorArgs {
    /// GNSS receiver ids to subscribe to.
    pub gnss_ids: Vec<String>,
    /// PPS source ids.
    pub pps_ids: Vec<String>,
    /// IMU ids.
    pub imu_ids: Vec<String>,
    /// Ignore PPS: software synchronisation from NMEA receipt times.
    pub software_sync: bool,
}

/// Errors of the estimator process.
#[derive(Debug, thiserror::Error)]
pub enum EstimatorError {
    /// IPC failure.
    #[error(transparent)]
    Ipc(#[from] IpcError),
}

/// Runs the estimator until SIGINT/SIGTERM.
pub fn run(args: &EstimatorArgs) -> Result<(), EstimatorError> {
    let _span = info_span!("estimator").entered();
    let node = IpcNode::new("estimator")?;
    let pps: Vec<Subscriber<PpsEdge>> = args
        .pps_ids
        .iter()
        .map(|id| node.subscriber(&services::pps_edge(id)))
        .collect::<Result<_, _>>()?;
    let gnss: Vec<Subscriber<GnssFix>> = args
        .gnss_ids
        .iter()
        .map(|id| node.subscriber(&services::gnss_fix(id)))
        .collect::<Result<_, _>>()?;
    let imus: Vec<Subscriber<ImuSample>> = args
        .imu_ids
        .iter()
        .map(|id| node.subscriber(&services::imu_sample(id)))
        .collect::<Result<_, _>>()?;
    let mut time_pub = node.publisher::<TimeState>(services::TIME_STATE)?;
    let mut health = HealthReporter::new(&node, "estimator")?;
    let c_pps = health.counter("pps_used");
    let c_pps_rej = health.counter("pps_rejected");
    let c_fixes = health.counter("gnss_fixes");
    let c_imu = health.counter("imu_samples");
    let c_imu_gap = health.counter("imu_seq_gaps");
    let r_imu = health.rate("imu_samples");
    let r_fix = health.rate("gnss_fixes");

    let waitset = node.waitset()?;
    let mut guards = Vec::new();
    for l in pps
        .iter()
        .map(|s| s.listener())
        .chain(gnss.iter().map(|s| s.listener()))
        .chain(imus.iter().map(|s| s.listener()))
    {
        guards.push(waitset.attach_notification(l).map_err(|e| IpcError::Iceoryx {
            what: "attaching to waitset",
            service: "-".into(),
            detail: format!("{e:?}"),
        })?);
    }

    let mut sync = TimeSync::new(TimeSyncConfig {
        software_sync: args.software_sync,
        ..Default::default()
    });
    let mut last_imu_seq: Vec<Option<u64>> = vec![None; imus.len()];
    let mut last_state_ns = 0i64;
    let mut last_status = sync.status();
    info!(pps = ?args.pps_ids, gnss = ?args.gnss_ids, imus = ?args.imu_ids, "estimator running");

    loop {
        let res =
            waitset.wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, Duration::from_millis(100));
        if res.is_err() || node.termination_requested() {
            break;
        }
        let mut updated = false;
        for s in &pps {
            s.clear_events();
            while let Some(edge) = s.receive()? {
                updated |= sync.on_pps(&edge);
            }
        }
        for s in &gnss {
            s.clear_events();
            while let Some(fix) = s.receive()? {
                health.add(c_fixes, 1);
                health.tick(r_fix);
                updated |= sync.on_fix(&fix);
            }
        }
        for (s, last) in imus.iter().zip(last_imu_seq.iter_mut()) {
            s.clear_events();
            s.for_each(|sample| {
                if let Some(prev) = *last
                    && sample.stamp.seq > prev + 1
                {
                    health.add(c_imu_gap, sample.stamp.seq - prev - 1);
                }
                *last = Some(sample.stamp.seq);
                health.add(c_imu, 1);
                health.tick(r_imu);
            })?;
        }
        let now = monotonic_now_ns();
        sync.tick(now);
        if sync.status() != last_status {
            info!(from = last_status.name(), to = sync.status().name(), "time status");
            last_status = sync.status();
        }
        if updated || now - last_state_ns >= NS_PER_S {
            let state = sync.time_state(now);
            if let Err(e) = time_pub.publish(&state) {
                warn!("publishing time state: {e}");
            }
            last_state_ns = now;
        }
        health.set(c_pps, sync.counters().pps_used);
        health.set(c_pps_rej, sync.counters().rejected());
        health.maybe_publish(now)?;
    }
    drop(guards);
    health.publish_final()?;
    info!("estimator stopped");
    Ok(())
}
