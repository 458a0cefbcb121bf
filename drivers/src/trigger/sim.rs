//! `sim:RATE_HZ`: rising edges at a fixed rate on the host clock (`CLOCK_MONOTONIC`), on the
//! grid of whole multiples of the period, so two processes with the same rate see the same
//! instants. For tests and the demo on a machine without GPIO; an edge the process wakes up
//! late for keeps its scheduled time (a real line's kernel stamp does not depend on the reader
//! either).

use std::time::Duration;

use navsync_shared::pacing::sleep_until;
use navsync_shared::time::monotonic_now_ns;

use super::{TriggerEdge, TriggerError, TriggerInput};

/// A simulated trigger input.
pub struct SimTrigger {
    period_ns: i64,
    next_ns: i64,
    count: u32,
}

impl SimTrigger {
    /// Edges at `hz` from the next multiple of the period on.
    pub fn new(hz: f64) -> Self {
        let period_ns = (1e9 / hz).round().max(1.0) as i64;
        let now = monotonic_now_ns();
        Self {
            period_ns,
            next_ns: (now / period_ns + 1) * period_ns,
            count: 0,
        }
    }
}

impl TriggerInput for SimTrigger {
    fn next_edge(&mut self, timeout: Duration) -> Result<Option<TriggerEdge>, TriggerError> {
        let deadline = monotonic_now_ns().saturating_add(timeout.as_nanos().min(i64::MAX as u128) as i64);
        if self.next_ns > deadline {
            sleep_until(deadline, 0);
            return Ok(None);
        }
        sleep_until(self.next_ns, 0);
        let edge = TriggerEdge {
            host_ns: self.next_ns,
            rising: true,
            count: self.count,
        };
        self.count = self.count.wrapping_add(1);
        self.next_ns += self.period_ns;
        Ok(Some(edge))
    }

    fn describe(&self) -> String {
        format!("simulated trigger every {} ms", self.period_ns as f64 * 1e-6)
    }

    fn channel(&self) -> u8 {
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edges_on_the_rate_grid() {
        let mut t = SimTrigger::new(100.0);
        let a = t.next_edge(Duration::from_secs(1)).unwrap().unwrap();
        let b = t.next_edge(Duration::from_secs(1)).unwrap().unwrap();
        assert_eq!(a.host_ns % 10_000_000, 0);
        assert_eq!(b.host_ns - a.host_ns, 10_000_000);
        assert_eq!((a.count, b.count, a.rising), (0, 1, true));
        assert!(monotonic_now_ns() >= b.host_ns);
    }
}
