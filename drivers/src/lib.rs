//! # navsync-drivers
//!
//! The driver processes: thin shells that read a device, decode the bytes with a pure
//! function, stamp and publish. Each driver's process entry point is a `run` function that
//! the `navsync` binary calls.
//!
//! - [`gnss`]: GNSS receivers (NMEA 0183) over a serial port → `navsync/gnss/{id}/fix`.
//! - [`pps`]: 1 PPS from a kernel PPS device, a serial modem line or the simulator, validated,
//!   → `navsync/pps/{id}/edge`.
//! - [`imu`]: IMUs (Linux IIO devices, Xsens MTi over serial, the simulator's IMUs) →
//!   `navsync/imu/{id}/sample`.
//! - [`pulse_out`]: pulse outputs for sensors (a GPIO line, a PTP hardware clock's periodic
//!   output, a file for tests), driven by `navsync pps-out`.
//! - [`feed`]: replays a capture into a pseudo-terminal, as a device would send it.
//! - [`pty`]: pseudo-terminals, through which the simulator (crate `navsync-sim`) and the
//!   feeder talk to the GNSS driver exactly as a receiver would.

/// Implements `serde::Deserialize` for a type through its `FromStr`, so a configuration file
/// takes the same text as the command line (`source = "iio:adis16475"`) and its errors are
/// the parser's own message, located by the configuration loader.
macro_rules! deserialize_from_str {
    ($t:ty) => {
        impl<'de> serde::Deserialize<'de> for $t {
            fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                let s = <String as serde::Deserialize>::deserialize(d)?;
                s.parse().map_err(serde::de::Error::custom)
            }
        }
    };
}

pub mod feed;
pub mod gnss;
pub mod imu;
pub mod pps;
pub mod pty;
pub mod pulse_out;
pub mod rate_log;
pub mod trigger;
