//! `sim`: raw edges from the simulator (`navsync sim` publishes them on the simulator-private
//! `navsync/sim/pps`). Their stamps come from the simulated host oscillator plus the
//! configured stamp jitter (`navsync sim --clock-ppm P --pps-jitter-ns N`, or the scenario's
//! `[clock]` table); this source only carries them into the same validation as a device.

use std::time::Duration;

use navsync_shared::ipc::{IpcNode, Subscriber};
use navsync_shared::samples::PpsEdge;
use navsync_shared::services;

use super::PpsError;
use super::edge_validator::RawEdge;

/// A subscriber to the simulator's raw edges.
pub struct SimSource {
    sub: Subscriber<PpsEdge>,
    stated_jitter_ns: Option<f64>,
}

impl SimSource {
    /// Subscribes to `navsync/sim/pps`.
    pub fn open(node: &IpcNode) -> Result<Self, PpsError> {
        Ok(Self {
            sub: node.subscriber(services::SIM_PPS)?,
            stated_jitter_ns: None,
        })
    }

    /// The next raw edge within `timeout`, if any.
    pub fn next_edge(&mut self, timeout: Duration) -> Result<Option<RawEdge>, PpsError> {
        let Some(e) = self.sub.wait_next(timeout)? else {
            return Ok(None);
        };
        if e.jitter_ns.is_finite() && e.jitter_ns > 0.0 {
            self.stated_jitter_ns = Some(e.jitter_ns);
        }
        Ok(Some(raw_of(&e)))
    }

    /// The jitter the simulator states for its stamps, ns (its configuration).
    pub fn stated_jitter_ns(&self) -> Option<f64> {
        self.stated_jitter_ns
    }
}

/// The raw edge carried by a simulated `PpsEdge`.
pub fn raw_of(e: &PpsEdge) -> RawEdge {
    RawEdge {
        host_ns: e.stamp.host_ns,
        source_seq: e.source_seq,
        assert: e.assert_edge != 0,
    }
}
