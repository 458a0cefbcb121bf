//! Per-process health: alive, rates, error counters.

crate::sample_struct! {
    /// One named counter.
    pub struct Counter = "navsync.Counter.v1" {
        /// Counter name (NUL-padded ASCII), empty for an unused slot.
        pub name: [u8; 24],
        /// Value since the process started.
        pub value: u64,
    }
}

crate::sample_struct! {
    /// One named rate.
    pub struct RateEntry = "navsync.RateEntry.v1" {
        /// Rate name (NUL-padded ASCII), empty for an unused slot.
        pub name: [u8; 24],
        /// Rate over the last reporting interval, Hz.
        pub hz: f64,
    }
}

/// Counter slots in [`Health`].
pub const MAX_COUNTERS: usize = 96;
/// Rate slots in [`Health`].
pub const MAX_RATES: usize = 8;

crate::sample_struct! {
    /// Heartbeat of one process, published about once per second on `navsync/health/{process}`.
    pub struct Health = "navsync.Health.v3" {
        /// Host time of this report, ns (`CLOCK_MONOTONIC`).
        pub host_ns: i64,
        /// Host time the process started, ns.
        pub started_host_ns: i64,
        /// Report sequence number.
        pub seq: u64,
        /// Error and event counters.
        pub counters: [Counter; MAX_COUNTERS],
        /// Rates.
        pub rates: [RateEntry; MAX_RATES],
        /// Process name, e.g. "gps-0" (NUL-padded ASCII).
        pub process: [u8; 32],
        /// Operating-system process id.
        pub pid: u32,
        /// 1 while the process is serving; 0 in its last report before exiting.
        pub alive: u8,
        /// Reserved, zero.
        pub reserved: [u8; 3],
    }
}

impl Health {
    /// A report for `process` with no counters.
    pub fn new(process: &str) -> Self {
        let mut h = <Self as crate::reflect::Reflect>::zeroed();
        h.process = crate::reflect::fixed_str(process);
        h.pid = std::process::id();
        h.alive = 1;
        h
    }

    /// Value of a counter by name.
    pub fn counter(&self, name: &str) -> Option<u64> {
        self.counters
            .iter()
            .find(|c| crate::reflect::str_of(&c.name) == name)
            .map(|c| c.value)
    }

    /// Value of a rate by name, Hz.
    pub fn rate(&self, name: &str) -> Option<f64> {
        self.rates
            .iter()
            .find(|r| crate::reflect::str_of(&r.name) == name)
            .map(|r| r.hz)
    }
}
