//! The host-clock ↔ GNSS-time mapping and the other time-synchronisation estimates.

use super::MAX_IMUS;

crate::sample_struct! {
    /// Synchronisation state of one IMU of the array, relative to the reference IMU.
    pub struct ImuSync = "navsync.ImuSync.v1" {
        /// IMU id (NUL-padded ASCII); empty for an unused slot.
        pub imu_id: [u8; 8],
        /// Estimated time offset Td, s: the IMU's stamps are late by Td relative to the reference IMU.
        pub offset_s: f64,
        /// 1-sigma of `offset_s`, s.
        pub offset_std_s: f64,
        /// 1 when the IMU contributes to the fused virtual IMU.
        pub in_array: u8,
        /// Why not, an [`ImuSyncReason`] as `u8` (0 when it is in the array).
        pub reason: u8,
        /// 1 while there is enough motion to observe the offset; 0 means the estimate is frozen.
        pub observable: u8,
        /// Reserved, zero.
        pub reserved: [u8; 5],
    }
}

/// Why an IMU is not in the array.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum ImuSyncReason {
    /// It is in the array.
    InArray = 0,
    /// No samples received yet.
    Absent = 1,
    /// Samples stopped arriving.
    Stale = 2,
    /// An axis is saturated.
    Saturated = 3,
    /// Disagrees with the others beyond the gate.
    Disagrees = 4,
    /// Non-finite or time-reversed samples.
    Invalid = 5,
    /// Offset not converged yet.
    Converging = 6,
}

impl ImuSyncReason {
    /// Lower-case name for logs and JSON.
    pub fn name(v: u8) -> &'static str {
        match v {
            0 => "in-array",
            1 => "absent",
            2 => "stale",
            3 => "saturated",
            4 => "disagrees",
            5 => "invalid",
            6 => "converging",
            _ => "unknown",
        }
    }
}

crate::sample_struct! {
    /// Host time → GNSS time mapping with its uncertainty, and what is known of the receiver's latency.
    ///
    /// Mapping (a first-order clock model, linear in host time):
    /// `utc_ns(h) = ref_utc_ns + (h − ref_host_ns) · (1 + rate_error)`; see [`TimeState::utc_ns_at`].
    pub struct TimeState = "navsync.TimeState.v2" {
        /// Host time (`CLOCK_MONOTONIC` ns) of the reference point of the mapping.
        pub ref_host_ns: i64,
        /// Estimated UTC (ns since 1970) at `ref_host_ns`.
        pub ref_utc_ns: i64,
        /// Host time when this state was computed, ns.
        pub computed_host_ns: i64,
        /// Host time of the last PPS edge used, ns (0 when none).
        pub last_pps_host_ns: i64,
        /// Sequence number of this state.
        pub seq: u64,
        /// Fractional frequency error of the host clock: d(UTC)/d(host) − 1 (−5e−7: host runs 0.5 ppm fast).
        pub rate_error: f64,
        /// 1-sigma of the mapped time at `ref_host_ns`, ns.
        pub offset_std_ns: f64,
        /// 1-sigma of `rate_error`.
        pub rate_std: f64,
        /// Covariance of offset (ns) and rate error, ns.
        pub offset_rate_cov_ns: f64,
        /// Phase random-walk intensity of the oscillator model, ns²/s (grows the variance in holdover).
        pub q_offset_ns2_per_s: f64,
        /// Frequency random-walk intensity of the oscillator model, 1/s.
        pub q_rate_per_s: f64,
        /// Receiver output latency d0 (first NMEA byte minus its PPS edge): minimum, s (NaN when not measured).
        pub latency_min_s: f64,
        /// Receiver output latency d0: median, s.
        pub latency_median_s: f64,
        /// Receiver output latency d0: 99th percentile, s.
        pub latency_p99_s: f64,
        /// Receiver output latency d0: maximum, s.
        pub latency_max_s: f64,
        /// Estimated GNSS time-synchronisation error Δ of the fixes fused by the filter, s.
        pub gnss_delay_s: f64,
        /// 1-sigma of `gnss_delay_s`, s.
        pub gnss_delay_std_s: f64,
        /// The GNSS receiver's clock bias at `computed_host_ns` (receiver time − GPS time) from
        /// the tightly coupled filter, ns: extrapolated with its drift while no satellite is
        /// fused (holdover; see `rx_clock_last_fused_host_ns`). NaN when loosely coupled or
        /// before the clock is anchored.
        pub rx_clock_bias_ns: f64,
        /// 1-sigma of `rx_clock_bias_ns` (grows in holdover), ns.
        pub rx_clock_bias_std_ns: f64,
        /// The receiver clock's drift (fractional frequency offset, s/s); NaN as the bias.
        pub rx_clock_drift: f64,
        /// 1-sigma of `rx_clock_drift`.
        pub rx_clock_drift_std: f64,
        /// Host time of the last receiver epoch with a satellite fused, ns (0: none).
        pub rx_clock_last_fused_host_ns: i64,
        /// Number of epochs in the latency statistics.
        pub latency_count: u64,
        /// PPS edges accepted.
        pub pps_used: u64,
        /// PPS edges rejected (missing label, duplicate, early, late, no valid fix).
        pub pps_rejected: u64,
        /// Per-IMU offsets relative to the reference IMU.
        pub imu: [ImuSync; MAX_IMUS],
        /// A [`TimeStatus`] as `u8`.
        pub status: u8,
        /// Number of used slots in `imu`.
        pub imu_count: u8,
        /// GPS − UTC, s (leap seconds).
        pub leap_s: i16,
        /// Reserved, zero.
        pub reserved: [u8; 4],
    }
}

/// State of the host ↔ GNSS time mapping.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum TimeStatus {
    /// No mapping yet.
    None = 0,
    /// Driven by labelled PPS edges (hardware sync, µs level).
    Locked = 1,
    /// PPS or GNSS lost: extrapolating with the estimated drift.
    Holdover = 2,
    /// No PPS: NMEA receipt time minus the estimated receiver latency (ms level).
    Software = 3,
    /// PPS seen but not yet labelled or converged.
    Acquiring = 4,
    /// No receiver: the host clock mapped through a network time service (chrony, or the
    /// kernel's NTP state; `--time-source chrony|system`), σ from that service's error bound.
    Network = 5,
}

impl TimeStatus {
    /// Decodes [`TimeState::status`].
    pub fn from_u8(v: u8) -> Self {
        match v {
            1 => Self::Locked,
            2 => Self::Holdover,
            3 => Self::Software,
            4 => Self::Acquiring,
            5 => Self::Network,
            _ => Self::None,
        }
    }

    /// True when the host clock is mapped to GNSS time by a clock model (PPS locked, in
    /// holdover, or through a network time service), rather than by software sync or not at all.
    pub fn is_clock_mapped(self) -> bool {
        matches!(self, Self::Locked | Self::Holdover | Self::Network)
    }

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Locked => "locked",
            Self::Holdover => "holdover",
            Self::Software => "software",
            Self::Acquiring => "acquiring",
            Self::Network => "network",
        }
    }
}

impl TimeState {
    /// Nothing known.
    pub fn unknown() -> Self {
        let mut s = <Self as crate::reflect::Reflect>::zeroed();
        for v in [
            &mut s.latency_min_s,
            &mut s.latency_median_s,
            &mut s.latency_p99_s,
            &mut s.latency_max_s,
            &mut s.gnss_delay_s,
            &mut s.gnss_delay_std_s,
            &mut s.rx_clock_bias_ns,
            &mut s.rx_clock_bias_std_ns,
            &mut s.rx_clock_drift,
            &mut s.rx_clock_drift_std,
            &mut s.offset_std_ns,
            &mut s.rate_std,
        ] {
            *v = f64::NAN;
        }
        s
    }

    /// The decoded status.
    pub fn status(&self) -> TimeStatus {
        TimeStatus::from_u8(self.status)
    }

    /// Maps a host time (`CLOCK_MONOTONIC` ns) to UTC ns with the linear model
    /// `utc = ref_utc + Δh + round(Δh · rate_error)`, Δh = h − ref_host.
    pub fn utc_ns_at(&self, host_ns: i64) -> i64 {
        let dh = host_ns - self.ref_host_ns;
        self.ref_utc_ns + dh + (dh as f64 * self.rate_error).round() as i64
    }

    /// 1-sigma of [`utc_ns_at`](Self::utc_ns_at), ns: the covariance propagated over Δh plus the
    /// oscillator's random walks, σ² = P00 + 2Δt·P01 + Δt²·P11 + q_φ·Δt + q_f·Δt³/3 (Δt in s).
    pub fn utc_std_ns_at(&self, host_ns: i64) -> f64 {
        let dt = ((host_ns - self.ref_host_ns) as f64 * 1e-9).abs();
        let p00 = self.offset_std_ns * self.offset_std_ns;
        let p11 = (self.rate_std * 1e9) * (self.rate_std * 1e9);
        let p01 = self.offset_rate_cov_ns * 1e9;
        let var = p00
            + 2.0 * dt * p01
            + dt * dt * p11
            + self.q_offset_ns2_per_s * dt
            + self.q_rate_per_s * 1e18 * dt * dt * dt / 3.0;
        // A term that is not known (NaN) leaves the σ unknown, never 0 (`f64::max` drops NaN).
        if var.is_nan() { f64::NAN } else { var.max(0.0).sqrt() }
    }

    /// Inverse mapping: the host time at which UTC reads `utc_ns`.
    pub fn host_ns_at(&self, utc_ns: i64) -> i64 {
        let du = utc_ns - self.ref_utc_ns;
        self.ref_host_ns + (du as f64 / (1.0 + self.rate_error)).round() as i64
    }

    /// True when the mapping can be used at all.
    pub fn is_valid(&self) -> bool {
        !matches!(self.status(), TimeStatus::None | TimeStatus::Acquiring)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn host_ns_at_inverts_utc_ns_at() {
        let mut s = TimeState::unknown();
        s.ref_host_ns = 5_000_000_000_000;
        s.ref_utc_ns = 1_790_000_000_000_000_000;
        s.rate_error = -3.7e-6;
        for dh in [
            -86_400_000_000_000i64,
            -1_000_000_007,
            0,
            999_999_937,
            3_600_000_000_000,
        ] {
            let host = s.ref_host_ns + dh;
            let back = s.host_ns_at(s.utc_ns_at(host));
            assert!((back - host).abs() <= 1, "{dh}: {back} vs {host}");
        }
        // A 3.7 ppm fast host clock: one UTC hour is 3.7e-6 h less on the host.
        let hour = 3_600_000_000_000i64;
        assert_eq!(s.host_ns_at(s.ref_utc_ns + hour) - s.ref_host_ns, hour + 13_320_049);
    }
}
