//! Pacing a process on GNSS seconds: the outputs that hand GNSS time to sensors (`nmea-out`,
//! `pps-out`) act once per whole UTC second, at the host time navsync's time mapping
//! (`navsync/time/state`) gives for it, and only while the mapping may be handed on
//! ([`exportable_std_ns`]: locked, holdover or software, fresh, σ within the bound).

use std::time::Duration;

use crate::live::ntpshm::exportable_std_ns;
use navsync_shared::ipc::{IpcError, IpcNode, Subscriber};
use navsync_shared::pacing::sleep_until;
use navsync_shared::samples::TimeState;
use navsync_shared::services;
use navsync_shared::time::{NS_PER_S, monotonic_now_ns};

/// Longest single wait, so that a stop request or a new mapping is seen: ns.
const STEP_NS: i64 = 200_000_000;
/// The wait while the mapping may not be used.
const UNUSABLE_WAIT: Duration = Duration::from_millis(200);

/// The GNSS second to act on next and the host time (`CLOCK_MONOTONIC` ns) it begins at, from
/// the mapping `t` at host time `now_ns`; `None` when the mapping must not be used. Pure.
pub fn next_second(t: &TimeState, now_ns: i64, max_std_ns: f64) -> Option<(i64, i64)> {
    exportable_std_ns(t, now_ns, max_std_ns)?;
    let second = (t.utc_ns_at(now_ns).div_euclid(NS_PER_S) + 1) * NS_PER_S;
    Some((second, t.host_ns_at(second)))
}

/// What [`SecondPacer::next`] came back with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tick {
    /// The GNSS second `second` (UTC ns, whole) began at host time `at` by the latest mapping;
    /// it is now `at` or just after. Each second is handed out once.
    Second {
        /// UTC, ns since 1970, a whole second.
        second: i64,
        /// Its host time, `CLOCK_MONOTONIC` ns.
        at: i64,
    },
    /// No mapping may be used (none, acquiring, stale, σ over the bound); waited 200 ms.
    Unusable,
    /// Woke before the next second (a step of the wait, a signal, or that second was already
    /// handed out): call again.
    Pending,
}

/// Waits for the GNSS seconds of the latest `TimeState`.
pub struct SecondPacer {
    time: Subscriber<TimeState>,
    latest: Option<TimeState>,
    max_std_ns: f64,
    spin_ns: i64,
    done: Option<i64>,
}

impl SecondPacer {
    /// Subscribes to `navsync/time/state`. Seconds are handed out while the mapping's 1σ is at
    /// most `max_std_ns`; the last `spin_ns` before a second are spun rather than slept
    /// (0: sleep to it; a timed sleep wakes tens of µs late, more on a loaded machine).
    pub fn new(node: &IpcNode, max_std_ns: f64, spin_ns: i64) -> Result<Self, IpcError> {
        Ok(Self {
            time: node.subscriber::<TimeState>(services::TIME_STATE)?,
            latest: None,
            max_std_ns,
            spin_ns,
            done: None,
        })
    }

    /// The latest mapping received.
    pub fn mapping(&self) -> Option<&TimeState> {
        self.latest.as_ref()
    }

    /// Takes the new mappings and waits toward the next GNSS second, at most 200 ms.
    pub fn next(&mut self, node: &IpcNode) -> Result<Tick, IpcError> {
        while let Some(t) = self.time.receive()? {
            self.latest = Some(t);
        }
        let now = monotonic_now_ns();
        let Some((second, at)) = self.latest.as_ref().and_then(|t| next_second(t, now, self.max_std_ns)) else {
            node.sleep(UNUSABLE_WAIT);
            return Ok(Tick::Unusable);
        };
        if self.done == Some(second) {
            node.sleep(Duration::from_millis(20));
            return Ok(Tick::Pending);
        }
        if at > now {
            if at - now > STEP_NS {
                sleep_until(now + STEP_NS, 0);
            } else {
                sleep_until(at, self.spin_ns);
            }
            if at > monotonic_now_ns() {
                return Ok(Tick::Pending);
            }
        }
        self.done = Some(second);
        Ok(Tick::Second { second, at })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::live::ntpshm::STALE_AFTER_NS;
    use navsync_shared::samples::TimeStatus;

    #[test]
    fn the_next_second_by_the_mapping() {
        let mut t = TimeState::unknown();
        t.status = TimeStatus::Locked as u8;
        t.ref_host_ns = 10 * NS_PER_S;
        t.ref_utc_ns = 1_796_419_805 * NS_PER_S + 250_000_000;
        t.computed_host_ns = t.ref_host_ns;
        t.offset_std_ns = 500.0;
        t.rate_std = 1e-9;
        let (s, at) = next_second(&t, t.ref_host_ns, 1e6).unwrap();
        assert_eq!(s, 1_796_419_806 * NS_PER_S);
        assert_eq!(at, t.ref_host_ns + 750_000_000);
        // A host clock 100 ppm slow: the second comes 75 µs earlier on it.
        t.rate_error = 1e-4;
        let (s, at) = next_second(&t, t.ref_host_ns, 1e6).unwrap();
        assert_eq!(s, 1_796_419_806 * NS_PER_S);
        assert_eq!(at, t.ref_host_ns + 749_925_007);
        t.rate_error = 0.0;
        assert_eq!(next_second(&t, t.ref_host_ns, 100.0), None, "σ over the bound");
        assert_eq!(next_second(&t, t.ref_host_ns + STALE_AFTER_NS + 1, 1e6), None, "stale");
        t.status = TimeStatus::Acquiring as u8;
        assert_eq!(next_second(&t, t.ref_host_ns, 1e6), None);
        t.status = TimeStatus::Locked as u8;
        t.rate_std = f64::NAN;
        assert_eq!(
            next_second(&t, t.ref_host_ns, 1e6),
            None,
            "an unknown σ is over any bound"
        );
    }
}
