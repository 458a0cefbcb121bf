//! Ground truth from the simulator, for evaluation only.

use super::MAX_IMUS;

crate::sample_struct! {
    /// What really happened at one instant of the simulated world.
    pub struct SimTruth = "navsync.SimTruth.v1" {
        /// Host time (`CLOCK_MONOTONIC` ns) of this instant.
        pub host_ns: i64,
        /// True UTC at `host_ns`, ns since 1970.
        pub utc_ns: i64,
        /// Sequence number.
        pub seq: u64,
        /// True fractional frequency error of the host clock, d(UTC)/d(host) − 1.
        pub rate_error: f64,
        /// Latitude of the body origin, degrees (WGS-84).
        pub lat_deg: f64,
        /// Longitude, degrees.
        pub lon_deg: f64,
        /// Height above the ellipsoid, m.
        pub height_m: f64,
        /// Velocity, NED, m/s.
        pub vel_ned_mps: [f64; 3],
        /// Acceleration (dv/dt of the NED velocity), m/s².
        pub acc_ned_mps2: [f64; 3],
        /// Roll, pitch, yaw of the body (FRD) frame w.r.t. NED, rad.
        pub rpy_rad: [f64; 3],
        /// True receiver output latency d0 (first NMEA byte after the epoch), s.
        pub gnss_latency_s: f64,
        /// True IMU stamp offsets relative to IMU 0, s (stamps late by this much).
        pub imu_offset_s: [f64; MAX_IMUS],
        /// Number of simulated IMUs.
        pub imu_count: u8,
        /// Reserved, zero.
        pub reserved: [u8; 7],
    }
}
