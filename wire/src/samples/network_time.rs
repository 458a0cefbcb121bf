//! The host clock against UTC as a network time service (chronyd, or the kernel's NTP state)
//! sees it: what `navsync estimator --time-source chrony|system` maps its host clock with when
//! the host has no receiver of its own.

crate::sample_struct! {
    /// One reading of the network-disciplined clock, taken by the estimator's shell and fused
    /// by its time synchronisation (status `network`). Published on `navsync/time/network`, so
    /// a recording replays the same mapping.
    pub struct NetworkTime = "navsync.NetworkTime.v1" {
        /// Host time of the reading (`CLOCK_MONOTONIC` ns, the middle of the query).
        pub host_ns: i64,
        /// UTC at `host_ns` as the source has it, ns since 1970: the system clock
        /// (`CLOCK_REALTIME`) read beside `host_ns` plus the source's pending correction.
        pub utc_ns: i64,
        /// Reading sequence number.
        pub seq: u64,
        /// 1-sigma of `utc_ns`, ns (see [`NetworkTime::max_error_ns`] for how it is derived).
        pub std_ns: f64,
        /// The source's bound on the error of `utc_ns`, ns: chrony's root dispersion plus half
        /// its root delay (chronyc(1), "tracking"), or the kernel's `maxerror` (adjtimex(2)).
        pub max_error_ns: f64,
        /// Fractional frequency error of the host clock the source sees, d(UTC)/d(host) − 1
        /// (NaN when it does not say).
        pub rate_error: f64,
        /// The source's stratum (1: its server has a reference clock; 0 when not known).
        pub stratum: u8,
        /// A [`NetworkSource`] as `u8`.
        pub source: u8,
        /// 1 when the source says it is synchronised (chrony's leap status not "not
        /// synchronised"; the kernel's `STA_UNSYNC` clear).
        pub synchronised: u8,
        /// Reserved, zero.
        pub reserved: [u8; 5],
    }
}

/// Where a [`NetworkTime`] reading comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum NetworkSource {
    /// Not known.
    Unknown = 0,
    /// chronyd's tracking report through its command socket.
    Chrony = 1,
    /// The kernel's NTP state (`adjtimex(2)`) of a clock some daemon disciplines.
    System = 2,
}

impl NetworkSource {
    /// Decodes [`NetworkTime::source`].
    pub fn from_u8(v: u8) -> Self {
        match v {
            1 => Self::Chrony,
            2 => Self::System,
            _ => Self::Unknown,
        }
    }

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Unknown => "unknown",
            Self::Chrony => "chrony",
            Self::System => "system",
        }
    }
}
