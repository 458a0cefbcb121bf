//! Several IMUs as one: each IMU's time offset against the reference estimated online
//! ([`imu_offset`]), each stream shifted onto the reference's time grid by a Lagrange
//! fractional-delay filter ([`fractional_delay`]), the array fused by minimum variance into one
//! virtual IMU ([`imu_array`]).

pub mod fractional_delay;
pub mod imu_array;
pub mod imu_offset;
