//! The fused, synchronised navigation state.

use super::{ImuSync, MAX_IMUS};

crate::sample_struct! {
    /// The estimator's navigation solution at one IMU epoch.
    pub struct NavState = "navsync.NavState.v2" {
        /// Host time (`CLOCK_MONOTONIC` ns) of the IMU epoch this state is for.
        pub host_ns: i64,
        /// UTC of that epoch, ns since 1970 (`i64::MIN` while time is not known).
        pub utc_ns: i64,
        /// Sequence number.
        pub seq: u64,
        /// Host time of the last GNSS fix fused, ns (0 when none).
        pub last_fix_host_ns: i64,
        /// Latitude of the body-frame origin, degrees (WGS-84).
        pub lat_deg: f64,
        /// Longitude, degrees (WGS-84).
        pub lon_deg: f64,
        /// Height above the WGS-84 ellipsoid, m.
        pub height_m: f64,
        /// Velocity in the NED navigation frame, m/s.
        pub vel_ned_mps: [f64; 3],
        /// Attitude of the body (FRD) frame w.r.t. NED: roll, pitch, yaw, rad (ZYX Euler).
        pub rpy_rad: [f64; 3],
        /// Attitude quaternion body→NED, [w, x, y, z].
        pub q_nb: [f64; 4],
        /// Angular rate of the body w.r.t. inertial space, body FRD axes, rad/s (bias compensated).
        pub gyro_body_rps: [f64; 3],
        /// Specific force, body FRD axes, m/s² (bias compensated).
        pub accel_body_mps2: [f64; 3],
        /// 1-sigma position error, north/east/down, m.
        pub pos_std_ned_m: [f64; 3],
        /// 1-sigma velocity error, NED, m/s.
        pub vel_std_ned_mps: [f64; 3],
        /// 1-sigma attitude error (phi angle, NED axes), rad.
        pub att_std_rad: [f64; 3],
        /// Estimated gyro bias, body FRD axes, rad/s.
        pub gyro_bias_rps: [f64; 3],
        /// Estimated accelerometer bias, body FRD axes, m/s².
        pub accel_bias_mps2: [f64; 3],
        /// 1-sigma gyro bias, rad/s.
        pub gyro_bias_std_rps: [f64; 3],
        /// 1-sigma accelerometer bias, m/s².
        pub accel_bias_std_mps2: [f64; 3],
        /// Estimated GNSS time-synchronisation error Δ, s (NaN when the state is off).
        pub gnss_delay_s: f64,
        /// 1-sigma of `gnss_delay_s`, s.
        pub gnss_delay_std_s: f64,
        /// Per-IMU offsets and array membership.
        pub imu: [ImuSync; MAX_IMUS],
        /// GNSS fixes fused so far.
        pub fixes_used: u32,
        /// GNSS fixes rejected by the innovation gate so far.
        pub fixes_rejected: u32,
        /// A [`NavStatus`] as `u8`.
        pub status: u8,
        /// Number of used slots in `imu`.
        pub imu_count: u8,
        /// A `TimeStatus` as `u8`: how the time stamps of this solution are referenced.
        pub time_status: u8,
        /// The integrity monitor's flags, `INTEGRITY_*` bits (0: nothing to report; this byte
        /// was reserved before, so older writers leave it 0).
        pub integrity: u8,
        /// Reserved, zero.
        pub reserved: [u8; 4],
    }
}

/// [`NavState::integrity`]: the heading is not observed yet; `rpy_rad[2]` is not a heading
/// (its σ says π).
pub const INTEGRITY_HEADING_UNKNOWN: u8 = 1 << 0;
/// [`NavState::integrity`]: the GNSS innovations are larger than the covariance predicts; the
/// covariance was inflated so that σ covers the error, and the solution is flagged until they
/// agree again.
pub const INTEGRITY_INCONSISTENT: u8 = 1 << 1;
/// [`NavState::integrity`]: the filter was reset by the integrity monitor (a non-finite or
/// implausible state) within the last seconds and is recovering.
pub const INTEGRITY_RECOVERING: u8 = 1 << 2;

/// Filter status.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum NavStatus {
    /// Levelling from the accelerometers / waiting for heading.
    Aligning = 0,
    /// Aligned and aided by GNSS.
    Aligned = 1,
    /// GNSS lost: inertial only, covariance growing.
    InsOnly = 2,
    /// Running with reduced sensors (IMUs dropped from the array, fixes rejected).
    Degraded = 3,
}

impl NavStatus {
    /// Lower-case name.
    pub fn name(v: u8) -> &'static str {
        match v {
            0 => "aligning",
            1 => "aligned",
            2 => "ins-only",
            3 => "degraded",
            _ => "unknown",
        }
    }
}
