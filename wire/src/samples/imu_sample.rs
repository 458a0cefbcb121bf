//! One IMU measurement.

use super::Stamp;

crate::sample_struct! {
    /// One IMU sample in the IMU's own sensor frame (forward-right-down when mounted as the
    /// body frame; the mounting rotation comes from the configuration).
    ///
    /// Rates and specific forces are averages over the sample interval that ends at
    /// `stamp.host_ns` (increment divided by `dt_s`), the way integrating IMUs report them.
    pub struct ImuSample = "navsync.ImuSample.v1" {
        /// Host time of the end of the sample interval and how it was taken.
        pub stamp: Stamp,
        /// Angular rate of the sensor frame w.r.t. inertial space, rad/s, sensor axes x, y, z.
        pub gyro_rps: [f64; 3],
        /// Specific force, m/s², sensor axes x, y, z (reads −g on the down axis at rest: [0, 0, −9.8]).
        pub accel_mps2: [f64; 3],
        /// Nominal length of the sample interval, s.
        pub dt_s: f64,
        /// Sensor temperature, °C, NaN when not known.
        pub temperature_c: f64,
        /// IMU id (NUL-padded ASCII, e.g. "0").
        pub imu_id: [u8; 8],
        /// Flags: bit 0 saturated, bit 1 sampled on the GNSS receiver's clock.
        pub flags: u32,
        /// Reserved, zero.
        pub reserved: u32,
    }
}

/// [`ImuSample::flags`] bit: at least one axis reached the sensor's range.
pub const IMU_FLAG_SATURATED: u32 = 1;

/// [`ImuSample::flags`] bit: the IMU samples on the GNSS receiver's oscillator (one crystal),
/// and `stamp.device_ns` is what the receiver's clock read at the sample: GPS time plus the
/// receiver clock bias, ns since the GPS epoch (1980-01-06). The tightly coupled estimator
/// removes the bias it estimates and maps the GPS time to host time.
pub const IMU_FLAG_RECEIVER_CLOCK: u32 = 2;
