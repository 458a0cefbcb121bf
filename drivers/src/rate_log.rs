//! Logging of error counters without flooding the log: the first occurrence of each kind is
//! logged at once, later ones at most once per interval per kind, as a count.
//!
//! Drivers keep exact counters in their `Health` report; the log only tells a human that
//! something is happening and what kind of thing it is.

use std::time::{Duration, Instant};

use tracing::warn;

/// Default interval between two log lines of one kind.
pub const DEFAULT_INTERVAL: Duration = Duration::from_secs(10);

#[derive(Debug, Clone)]
struct Kind {
    name: &'static str,
    logged_value: u64,
    last_log: Option<Instant>,
}

/// Rate-limited, per-kind logging of monotonically growing counters.
#[derive(Debug, Clone)]
pub struct RateLimitedLog {
    interval: Duration,
    kinds: Vec<Kind>,
}

impl Default for RateLimitedLog {
    fn default() -> Self {
        Self::new(DEFAULT_INTERVAL)
    }
}

impl RateLimitedLog {
    /// Logs each kind at most once per `interval`.
    pub fn new(interval: Duration) -> Self {
        Self {
            interval,
            kinds: Vec::new(),
        }
    }

    /// Reports the current value of counter `name` (with `what` describing it for a human);
    /// logs if it grew and the kind's interval has passed. Returns true when it logged.
    pub fn update(&mut self, name: &'static str, value: u64, what: &str, now: Instant) -> bool {
        let i = match self.kinds.iter().position(|k| k.name == name) {
            Some(i) => i,
            None => {
                self.kinds.push(Kind {
                    name,
                    logged_value: 0,
                    last_log: None,
                });
                self.kinds.len() - 1
            }
        };
        let k = &mut self.kinds[i];
        if value <= k.logged_value {
            return false;
        }
        match k.last_log {
            None => warn!(
                kind = name,
                total = value,
                "{what} (first occurrence; further ones are counted in health and logged at most every {:?})",
                self.interval
            ),
            Some(t) if now.duration_since(t) >= self.interval => {
                warn!(kind = name, new = value - k.logged_value, total = value, "{what}")
            }
            Some(_) => return false,
        }
        k.logged_value = value;
        k.last_log = Some(now);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_at_once_then_once_per_interval() {
        let mut log = RateLimitedLog::new(Duration::from_secs(10));
        let t0 = Instant::now();
        assert!(!log.update("bad", 0, "bad things", t0));
        assert!(log.update("bad", 1, "bad things", t0));
        assert!(!log.update("bad", 50, "bad things", t0 + Duration::from_secs(3)));
        assert!(
            log.update("other", 2, "other things", t0 + Duration::from_secs(3)),
            "kinds are independent"
        );
        assert!(log.update("bad", 60, "bad things", t0 + Duration::from_secs(11)));
        assert!(
            !log.update("bad", 60, "bad things", t0 + Duration::from_secs(30)),
            "no growth, no line"
        );
    }
}
