//! Publishes a process's [`Health`] on `navsync/health/{process}` about once per second.
//!
//! Counters and rates are registered by name (at most 23 bytes, the [`Health`] name field)
//! into the report's fixed table ([`MAX_COUNTERS`] counters, [`MAX_RATES`] rates); a name too
//! long or a table full is a [`HealthError`], never a silently shared or truncated slot.

use crate::ipc::{IpcError, IpcNode, Publisher};
use crate::reflect::fixed_str;
use crate::samples::{Health, MAX_COUNTERS, MAX_RATES};
use crate::services;
use crate::time::{NS_PER_S, monotonic_now_ns};

/// Interval between reports, ns.
pub const HEALTH_INTERVAL_NS: i64 = NS_PER_S;

/// Collects counters and event rates and publishes them periodically.
pub struct HealthReporter {
    publisher: Publisher<Health>,
    health: Health,
    last_publish_ns: i64,
    /// Events counted since the last report, per rate slot.
    events: [u64; MAX_RATES],
}

/// Why a counter or rate could not be registered.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum HealthError {
    /// The table is full.
    #[error("health report of {process}: no room for `{name}` (all {capacity} {what} slots taken)")]
    Full {
        /// The process.
        process: String,
        /// The name that did not fit.
        name: String,
        /// `counter` or `rate`.
        what: &'static str,
        /// Slots in the table.
        capacity: usize,
    },
    /// The name is longer than the report's name field.
    #[error("health counter name `{name}` is longer than {max} bytes")]
    NameTooLong {
        /// The name.
        name: String,
        /// Longest name, bytes.
        max: usize,
    },
}

/// Longest counter or rate name, bytes (the field holds a NUL-terminated 24-byte string).
pub const MAX_NAME_LEN: usize = 23;

/// Index of a registered counter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CounterId(usize);

/// Index of a registered rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RateId(usize);

impl HealthReporter {
    /// A reporter for `process` (e.g. `gps-0`), publishing on `navsync/health/{process}`.
    pub fn new(node: &IpcNode, process: &str) -> Result<Self, IpcError> {
        let publisher = node.publisher::<Health>(&services::health(process))?;
        let mut health = Health::new(process);
        health.started_host_ns = monotonic_now_ns();
        Ok(Self {
            publisher,
            health,
            last_publish_ns: 0,
            events: [0; MAX_RATES],
        })
    }

    fn key(name: &str) -> Result<[u8; 24], HealthError> {
        if name.len() > MAX_NAME_LEN {
            return Err(HealthError::NameTooLong {
                name: name.to_string(),
                max: MAX_NAME_LEN,
            });
        }
        Ok(fixed_str::<24>(name))
    }

    fn full(&self, name: &str, what: &'static str, capacity: usize) -> HealthError {
        HealthError::Full {
            process: crate::reflect::str_of(&self.health.process).to_string(),
            name: name.to_string(),
            what,
            capacity,
        }
    }

    /// Registers (or finds) a counter slot.
    pub fn counter(&mut self, name: &str) -> Result<CounterId, HealthError> {
        let key = Self::key(name)?;
        let slots = &self.health.counters;
        if let Some(i) = slots.iter().position(|c| c.name == key) {
            return Ok(CounterId(i));
        }
        let Some(i) = slots.iter().position(|c| c.name[0] == 0) else {
            return Err(self.full(name, "counter", MAX_COUNTERS));
        };
        self.health.counters[i].name = key;
        Ok(CounterId(i))
    }

    /// Sets a counter's value.
    pub fn set(&mut self, id: CounterId, value: u64) {
        self.health.counters[id.0].value = value;
    }

    /// Adds to a counter.
    pub fn add(&mut self, id: CounterId, n: u64) {
        self.health.counters[id.0].value += n;
    }

    /// Sets a counter by name (registering it on first use).
    pub fn set_named(&mut self, name: &str, value: u64) -> Result<(), HealthError> {
        let id = self.counter(name)?;
        self.set(id, value);
        Ok(())
    }

    /// Registers (or finds) a rate slot, e.g. "samples_out".
    pub fn rate(&mut self, name: &str) -> Result<RateId, HealthError> {
        let key = Self::key(name)?;
        let slots = &self.health.rates;
        if let Some(i) = slots.iter().position(|r| r.name == key) {
            return Ok(RateId(i));
        }
        let Some(i) = slots.iter().position(|r| r.name[0] == 0) else {
            return Err(self.full(name, "rate", MAX_RATES));
        };
        self.health.rates[i].name = key;
        Ok(RateId(i))
    }

    /// Counts one event towards a rate.
    pub fn tick(&mut self, id: RateId) {
        self.events[id.0] += 1;
    }

    /// Publishes if the interval has passed. Returns true when it published.
    pub fn maybe_publish(&mut self, now_ns: i64) -> Result<bool, IpcError> {
        if self.last_publish_ns != 0 && now_ns - self.last_publish_ns < HEALTH_INTERVAL_NS {
            return Ok(false);
        }
        self.publish_at(now_ns)?;
        Ok(true)
    }

    fn publish_at(&mut self, now_ns: i64) -> Result<(), IpcError> {
        let dt = if self.last_publish_ns == 0 {
            (now_ns - self.health.started_host_ns).max(1) as f64 * 1e-9
        } else {
            (now_ns - self.last_publish_ns) as f64 * 1e-9
        };
        for (r, n) in self.health.rates.iter_mut().zip(self.events.iter_mut()) {
            r.hz = *n as f64 / dt;
            *n = 0;
        }
        self.health.host_ns = now_ns;
        self.health.seq += 1;
        self.last_publish_ns = now_ns;
        self.publisher.publish(&self.health)
    }

    /// Publishes now, whatever the interval (a state change subscribers must see at once, e.g.
    /// an input going stale); the next periodic report follows a full interval later.
    pub fn publish_now(&mut self, now_ns: i64) -> Result<(), IpcError> {
        self.publish_at(now_ns)
    }

    /// Publishes a last report with `alive = 0` (call before a clean exit).
    pub fn publish_final(&mut self) -> Result<(), IpcError> {
        self.health.alive = 0;
        self.publish_at(monotonic_now_ns())
    }

    /// The report as it stands.
    pub fn health(&self) -> &Health {
        &self.health
    }
}
