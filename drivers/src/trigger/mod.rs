//! Trigger inputs: a line on which a camera or another sensor signals its exposure (or any
//! event whose pose is wanted), time-stamped on the host (`navsync trigger`,
//! `daemon/src/live/trigger.rs`). The edge's host time (`CLOCK_MONOTONIC` ns) becomes a
//! [`GnssEvent`](navsync_shared::samples::GnssEvent) with host times only on
//! `navsync/trigger/{id}/event`, which the estimator turns into a pose as it does a receiver's
//! TIM-TM2 mark (`navsync/event/{id}/pose`).
//!
//! Sources, named by a [`TriggerSpec`]:
//! - `gpio:/dev/gpiochipN:LINE` ([`gpio::GpioTrigger`]): a GPIO line's edge events through
//!   the Linux GPIO character device (uAPI v2, through `gpiocdev`): the kernel stamps each edge
//!   in its interrupt handler with `CLOCK_MONOTONIC` (the line's default event clock), so
//!   the stamp does not depend on when this process is scheduled.
//! - `sim:RATE_HZ` ([`sim::SimTrigger`]): edges at a fixed rate on the host clock, for tests
//!   and the demo on a machine without GPIO.

pub mod gpio;
pub mod sim;

use std::path::PathBuf;
use std::time::Duration;

pub use gpio::GpioTrigger;
pub use sim::SimTrigger;

/// One edge on a trigger input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TriggerEdge {
    /// Host time of the edge (`CLOCK_MONOTONIC` ns).
    pub host_ns: i64,
    /// A rising edge (inactive → active); else falling.
    pub rising: bool,
    /// The input's own count of its edges (the kernel's line sequence number for a GPIO line).
    pub count: u32,
}

/// Which edges are events.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Edges {
    /// Rising edges (inactive → active: a camera's exposure start on most strobe outputs).
    #[default]
    Rising,
    /// Falling edges.
    Falling,
    /// Both.
    Both,
}

impl std::str::FromStr for Edges {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "rising" => Ok(Self::Rising),
            "falling" => Ok(Self::Falling),
            "both" => Ok(Self::Both),
            _ => Err(format!("`{s}`: expected rising, falling or both")),
        }
    }
}

/// A trigger input.
pub trait TriggerInput: Send {
    /// The next edge, waiting at most `timeout`; `None` when none came.
    fn next_edge(&mut self, timeout: Duration) -> Result<Option<TriggerEdge>, TriggerError>;

    /// The input in words, for logs (`GPIO /dev/gpiochip0 line 17`).
    fn describe(&self) -> String;

    /// The line number reported as the event's channel (0 for a simulated input).
    fn channel(&self) -> u8;
}

/// Errors of the trigger inputs.
#[derive(Debug, thiserror::Error)]
pub enum TriggerError {
    /// A specification that is not understood.
    #[error(
        "`{0}` is not a trigger input: expected gpio:/dev/gpiochipN:LINE or sim:RATE_HZ (a device without a `/` is under /dev: gpio:gpiochip0:17)"
    )]
    BadSpec(String),
    /// The device is not there.
    #[error("{0}: no such device (a GPIO character device, /dev/gpiochipN)")]
    Missing(String),
    /// The GPIO line could not be requested or read.
    #[error("GPIO {chip} line {line}: {source}")]
    Gpio {
        /// The chip's character device.
        chip: String,
        /// Line offset on the chip.
        line: u32,
        /// Cause.
        source: gpiocdev::Error,
    },
}

/// Where the edges come from.
#[derive(Debug, Clone, PartialEq)]
pub enum TriggerSpec {
    /// A GPIO line: the chip's character device and the line's offset on it.
    Gpio {
        /// `/dev/gpiochipN`.
        chip: PathBuf,
        /// Line offset (as `gpioinfo` lists it).
        line: u32,
    },
    /// Edges at a fixed rate on the host clock, Hz (0.01 to 1000).
    Sim(f64),
}

impl std::str::FromStr for TriggerSpec {
    type Err = TriggerError;
    fn from_str(s: &str) -> Result<Self, TriggerError> {
        let bad = || TriggerError::BadSpec(s.to_string());
        if let Some(rate) = s.strip_prefix("sim:") {
            let hz: f64 = rate.parse().map_err(|_| bad())?;
            return if (0.01..=1000.0).contains(&hz) {
                Ok(Self::Sim(hz))
            } else {
                Err(bad())
            };
        }
        let rest = s.strip_prefix("gpio:").ok_or_else(bad)?;
        let (chip, line) = rest.rsplit_once(':').ok_or_else(bad)?;
        let line: u32 = line.parse().map_err(|_| bad())?;
        if chip.is_empty() {
            return Err(bad());
        }
        let chip = if chip.contains('/') {
            PathBuf::from(chip)
        } else {
            PathBuf::from("/dev").join(chip)
        };
        Ok(Self::Gpio { chip, line })
    }
}

impl TriggerSpec {
    /// Opens the input, reporting the edges `edges`.
    pub fn open(&self, edges: Edges) -> Result<Box<dyn TriggerInput>, TriggerError> {
        Ok(match self {
            Self::Gpio { chip, line } => Box::new(GpioTrigger::open(chip, *line, edges)?),
            Self::Sim(hz) => Box::new(SimTrigger::new(*hz)),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse_and_bad_ones_say_what_is_expected() {
        assert_eq!(
            "gpio:gpiochip0:17".parse::<TriggerSpec>().unwrap(),
            TriggerSpec::Gpio {
                chip: "/dev/gpiochip0".into(),
                line: 17
            }
        );
        assert_eq!(
            "gpio:/dev/gpiochip2:3".parse::<TriggerSpec>().unwrap(),
            TriggerSpec::Gpio {
                chip: "/dev/gpiochip2".into(),
                line: 3
            }
        );
        assert_eq!("sim:5".parse::<TriggerSpec>().unwrap(), TriggerSpec::Sim(5.0));
        for bad in ["sim:0", "sim:x", "gpio:17", "gpio::3", "gpio:chip:x", "usb:1"] {
            let e = bad.parse::<TriggerSpec>().unwrap_err().to_string();
            assert!(e.contains("gpio:/dev/gpiochipN:LINE"), "{bad}: {e}");
        }
    }

    #[test]
    fn a_missing_chip_is_named() {
        let e = "gpio:/dev/gpiochip-none:1"
            .parse::<TriggerSpec>()
            .unwrap()
            .open(Edges::Rising)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("/dev/gpiochip-none") && e.contains("no such device"), "{e}");
    }
}
