//! Time synchronisation: the host clock mapped to GNSS time.
//!
//! - [`clock_model`]: Kalman filter of host-clock offset and drift against GNSS time.
//! - [`time_sync`]: PPS labelling, holdover, software-sync fallback, receiver latency.
//! - [`latency_stats`]: order statistics of the receiver output latency d0.
//! - [`device_clock`]: a device's own counter (e.g. Xsens SampleTimeFine) mapped to GNSS or
//!   host time.
//! - [`device_timing`]: each IMU's samples timed by its device clock once converged.

pub mod clock_model;
pub mod device_clock;
pub mod device_timing;
pub mod latency_stats;
pub mod time_sync;
