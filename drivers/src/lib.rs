//! # navsync-drivers
//!
//! The driver processes: thin shells that read a device, decode the bytes with a pure
//! function, stamp and publish. Each driver's process entry point is a `run` function that
//! the `navsync` binary calls.
//!
//! - [`gps`]: NMEA 0183 over a serial port → `navsync/gnss/{id}/fix`.
//! - [`pps`]: 1 PPS from a kernel PPS device, a serial modem line or the simulator, validated,
//!   → `navsync/pps/{id}/edge`.
//! - [`imu`]: IMUs (Linux IIO devices, Xsens MTi over serial, the simulator's IMUs) →
//!   `navsync/imu/{id}/sample`.
//! - [`feed`]: replays a capture into a pseudo-terminal, as a device would send it.
//! - [`pty`]: pseudo-terminals, through which the simulator (crate `navsync-sim`) and the
//!   feeder talk to the GPS driver exactly as a receiver would.

pub mod feed;
pub mod gps;
pub mod imu;
pub mod pps;
pub mod pty;
pub mod rate_log;
