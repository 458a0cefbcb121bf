//! `navsync trigger --source SPEC --id ID [--edges rising|falling|both]`: a trigger input
//! stamped on the host (a camera's strobe or exposure output on a GPIO line; a simulated one),
//! each edge published as a [`GnssEvent`] with host times only on `navsync/trigger/{id}/event`.
//! The estimator (`navsync estimator --triggers ID`) gives each its pose once its delayed filter
//! has fused past the edge (`navsync/event/{id}/pose`), as it does a receiver's TIM-TM2 mark.
//!
//! The edge's time is the kernel's stamp of the line event (`CLOCK_MONOTONIC`, taken when the
//! interrupt is handled; `navsync_drivers::trigger`), so the process's own scheduling does not
//! enter it. Counters in `navsync/health/trigger-{id}`: edges, edges lost (gaps in the
//! kernel's line sequence number: its event queue overflowed).

use navsync_drivers::trigger::{Edges, TriggerError, TriggerSpec};
use navsync_shared::health_reporter::HealthReporter;
use navsync_shared::ipc::IpcNode;
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::{GnssEvent, StampSource};
use navsync_shared::services;
use navsync_shared::time::monotonic_now_ns;
use std::time::Duration;
use tracing::{info, info_span, warn};

/// `navsync trigger`.
#[derive(Debug, Clone, clap::Args)]
pub struct TriggerArgs {
    /// The input: gpio:/dev/gpiochipN:LINE (a GPIO line's edges, stamped by the kernel) or
    /// sim:RATE_HZ (edges at a fixed rate on the host clock, for tests). A device without a
    /// `/` is under /dev (gpio:gpiochip0:17).
    #[arg(long, value_name = "SPEC")]
    pub source: TriggerSpec,
    /// The trigger's id: its events go to navsync/trigger/{id}/event, their poses to
    /// navsync/event/{id}/pose (ids share that namespace with the receivers': choose one no
    /// receiver has, e.g. cam0).
    #[arg(long, value_name = "ID")]
    pub id: String,
    /// Which edges are events: rising, falling or both.
    #[arg(long, default_value = "rising", value_name = "EDGES")]
    pub edges: Edges,
}

/// Errors of `navsync trigger`.
#[derive(Debug, thiserror::Error)]
pub enum TriggerRunError {
    /// The input could not be opened or read.
    #[error(transparent)]
    Input(#[from] TriggerError),
    /// IPC failure.
    #[error(transparent)]
    Ipc(#[from] navsync_shared::ipc::IpcError),
    /// A health counter could not be registered.
    #[error(transparent)]
    Health(#[from] navsync_shared::health_reporter::HealthError),
}

/// The event of one edge: host times only (no GNSS time: the estimator maps it).
pub fn event_of(edge: &navsync_drivers::trigger::TriggerEdge, seq: u64, channel: u8) -> GnssEvent {
    let mut e = GnssEvent::zeroed();
    e.stamp.host_ns = edge.host_ns;
    e.stamp.device_ns = edge.host_ns;
    e.stamp.seq = seq;
    e.stamp.source = StampSource::KernelEvent as u8;
    e.rising_gps_ns = i64::MIN;
    e.falling_gps_ns = i64::MIN;
    (e.rising_host_ns, e.falling_host_ns) = if edge.rising {
        (edge.host_ns, i64::MIN)
    } else {
        (i64::MIN, edge.host_ns)
    };
    e.count = edge.count as u16;
    e.channel = channel;
    e
}

/// Runs the trigger input until SIGINT/SIGTERM.
pub fn run(args: &TriggerArgs) -> Result<(), TriggerRunError> {
    let _span = info_span!("trigger", id = %args.id).entered();
    // The device first: a machine without it fails before anything else is set up.
    let mut input = args.source.open(args.edges)?;
    let name = format!("trigger-{}", args.id);
    let node = IpcNode::new(&name)?;
    let mut health = HealthReporter::new(&node, &name)?;
    let c_edges = health.counter("edges")?;
    let c_lost = health.counter("edges_lost")?;
    let r_edges = health.rate("edges")?;
    let mut publisher = node.publisher::<GnssEvent>(&services::trigger_event(&args.id))?;
    info!(input = %input.describe(), "trigger running");
    navsync_shared::sd_notify::ready(&format!("trigger {}: {}", args.id, input.describe()));
    let (mut seq, mut last_count) = (0u64, None::<u32>);
    while !node.termination_requested() {
        navsync_shared::sd_notify::watchdog();
        if let Some(edge) = input.next_edge(Duration::from_millis(200))? {
            if let Some(prev) = last_count {
                health.add(c_lost, u64::from(edge.count.wrapping_sub(prev).saturating_sub(1)));
            }
            last_count = Some(edge.count);
            let e = event_of(&edge, seq, input.channel());
            seq += 1;
            if let Err(err) = publisher.publish(&e) {
                warn!("publishing an event: {err}");
            }
            health.add(c_edges, 1);
            health.tick(r_edges);
        }
        health.maybe_publish(monotonic_now_ns())?;
    }
    navsync_shared::sd_notify::stopping();
    let _ = health.publish_final();
    info!("trigger stopped");
    Ok(())
}
