//! Pulse outputs: a line that a sensor (LiDAR, camera, logger) takes as its PPS or trigger
//! input, driven on navsync's GNSS seconds (`navsync pps-out`, `daemon/src/live/pps_out.rs`).
//!
//! Two kinds, because who times the edge differs:
//!
//! - **Software-timed lines** ([`PulseOutput`]): the process changes the line's level itself
//!   at the host time the time mapping gives for the whole GNSS second; the edge is as exact
//!   as user space is (tens of µs). [`GpioLine`] (a GPIO line through the Linux GPIO
//!   character device) and [`Simulated`] (a file, one line per edge: what the tests read).
//! - **Hardware-timed** ([`PhcPeriodic`]): a PTP hardware clock's periodic output, programmed
//!   once to start on a whole second of the PHC's time with a 1 s period; the NIC's counter
//!   times every edge (ns-level), so it is only as right as the PHC's time, which phc2sys
//!   keeps on the disciplined system clock. It has no per-edge call and so is not a
//!   [`PulseOutput`].
//!
//! The output is named by an [`OutputSpec`] (`gpio:/dev/gpiochip0:17`, `phc:/dev/ptp0:0`,
//! `sim:FILE`); [`OutputSpec::open`] gives the matching [`Output`].
//!
//! Times are host `CLOCK_MONOTONIC` ns, navsync's host time (the frame of `Stamp::host_ns`
//! and of `TimeState`), unless a name says otherwise (`phc_ns`: the PHC's own time).

pub mod gpio;
pub mod phc;
pub mod sim;

use std::path::{Path, PathBuf};

pub use gpio::GpioLine;
pub use phc::PhcPeriodic;
pub use sim::Simulated;

/// A line whose level the caller changes at the instant an edge is due (software-timed).
pub trait PulseOutput: Send {
    /// Drives the line high (`true`, the pulse's leading edge: "active" for a GPIO line) or
    /// low; returns the edge's host time (`CLOCK_MONOTONIC` ns) as navsync knows it: read
    /// right after the device took the new level (the simulated output: the time it records).
    fn set(&mut self, high: bool) -> Result<i64, PulseOutError>;

    /// The output in words, for logs (`GPIO /dev/gpiochip0 line 17`).
    fn describe(&self) -> String;
}

/// Errors of the pulse outputs.
#[derive(Debug, thiserror::Error)]
pub enum PulseOutError {
    /// An output specification that is not understood.
    #[error(
        "`{0}` is not a pulse output: expected gpio:/dev/gpiochipN:LINE, phc:/dev/ptpN:CHANNEL[:PIN] or sim:FILE \
         (a device without a `/` is under /dev: gpio:gpiochip0:17)"
    )]
    BadSpec(String),
    /// The device is not there.
    #[error("{path}: no such device ({what})")]
    Missing {
        /// Device path.
        path: String,
        /// What was expected there.
        what: &'static str,
    },
    /// The GPIO line could not be requested or driven.
    #[error("GPIO {chip} line {line}: {source}")]
    Gpio {
        /// The chip's character device.
        chip: String,
        /// Line offset on the chip.
        line: u32,
        /// Cause.
        source: gpiocdev::Error,
    },
    /// A device could not be opened.
    #[error("opening {path}: {source}")]
    Open {
        /// Device or file path.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// An ioctl or read on the PTP hardware clock failed.
    #[error("{what} on {path}: {source}")]
    Ioctl {
        /// The request.
        what: &'static str,
        /// Device path.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// The PHC cannot do what was asked.
    #[error("{path}: {what}")]
    Unsupported {
        /// Device path.
        path: String,
        /// Why.
        what: String,
    },
    /// Writing the simulated output's file failed.
    #[error("writing {path}: {source}")]
    Write {
        /// File path.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
}

/// Where the pulses go.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum OutputSpec {
    /// A GPIO line: the chip's character device and the line's offset on it.
    Gpio {
        /// `/dev/gpiochipN`.
        chip: PathBuf,
        /// Line offset (as `gpioinfo` lists it).
        line: u32,
    },
    /// A PTP hardware clock's periodic output.
    Phc {
        /// `/dev/ptpN`.
        device: PathBuf,
        /// Periodic output channel (`index` of `PTP_PEROUT_REQUEST2`, below the clock's
        /// `n_per_out`).
        channel: u32,
        /// A programmable pin to route the channel to first (`PTP_PIN_SETFUNC2`), for NICs
        /// whose pins have no fixed function; `None` leaves the pins as they are.
        pin: Option<u32>,
    },
    /// A file with one line per edge.
    Sim(PathBuf),
}

deserialize_from_str!(OutputSpec);

impl std::str::FromStr for OutputSpec {
    type Err = PulseOutError;
    fn from_str(s: &str) -> Result<Self, PulseOutError> {
        let bad = || PulseOutError::BadSpec(s.to_string());
        let number = |t: &str| t.parse::<u32>().map_err(|_| bad());
        if let Some(file) = s.strip_prefix("sim:") {
            return if file.is_empty() {
                Err(bad())
            } else {
                Ok(Self::Sim(file.into()))
            };
        }
        let (kind, rest) = s.split_once(':').ok_or_else(bad)?;
        let fields: Vec<&str> = rest.split(':').collect();
        let device = || device_path(fields[0]).ok_or_else(bad);
        match (kind, fields.len()) {
            ("gpio", 2) => Ok(Self::Gpio {
                chip: device()?,
                line: number(fields[1])?,
            }),
            ("phc", 2 | 3) => Ok(Self::Phc {
                device: device()?,
                channel: number(fields[1])?,
                pin: fields.get(2).map(|p| number(p)).transpose()?,
            }),
            _ => Err(bad()),
        }
    }
}

/// A device named in a specification: a path, or a name under /dev (`gpiochip0`).
fn device_path(s: &str) -> Option<PathBuf> {
    match s {
        "" => None,
        s if s.contains('/') => Some(s.into()),
        s => Some(Path::new("/dev").join(s)),
    }
}

impl std::fmt::Display for OutputSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Gpio { chip, line } => write!(f, "gpio:{}:{line}", chip.display()),
            Self::Phc { device, channel, pin } => {
                write!(f, "phc:{}:{channel}", device.display())?;
                match pin {
                    Some(p) => write!(f, ":{p}"),
                    None => Ok(()),
                }
            }
            Self::Sim(p) => write!(f, "sim:{}", p.display()),
        }
    }
}

/// An opened output.
pub enum Output {
    /// Software-timed: the caller drives every edge.
    Line(Box<dyn PulseOutput>),
    /// Hardware-timed: programmed once, the PHC times the edges.
    Periodic(PhcPeriodic),
}

impl OutputSpec {
    /// Opens the output (requests the GPIO line, opens the PHC, creates the file). A GPIO
    /// line starts low; a PHC is not programmed yet ([`PhcPeriodic::program`]).
    pub fn open(&self) -> Result<Output, PulseOutError> {
        Ok(match self {
            Self::Gpio { chip, line } => Output::Line(Box::new(GpioLine::open(chip, *line)?)),
            Self::Phc { device, channel, pin } => Output::Periodic(PhcPeriodic::open(device, *channel, *pin)?),
            Self::Sim(path) => Output::Line(Box::new(Simulated::create(path)?)),
        })
    }
}

/// `Missing` when `path` does not exist, so that a machine without the device says so rather
/// than the library's or the kernel's bare "No such file or directory".
fn require_device(path: &Path, what: &'static str) -> Result<(), PulseOutError> {
    if path.exists() {
        Ok(())
    } else {
        Err(PulseOutError::Missing {
            path: path.display().to_string(),
            what,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn output_specs_parse_and_print_back() {
        for (text, spec) in [
            (
                "gpio:/dev/gpiochip0:17",
                OutputSpec::Gpio {
                    chip: "/dev/gpiochip0".into(),
                    line: 17,
                },
            ),
            (
                "phc:/dev/ptp1:0",
                OutputSpec::Phc {
                    device: "/dev/ptp1".into(),
                    channel: 0,
                    pin: None,
                },
            ),
            (
                "phc:/dev/ptp0:1:2",
                OutputSpec::Phc {
                    device: "/dev/ptp0".into(),
                    channel: 1,
                    pin: Some(2),
                },
            ),
            ("sim:/tmp/edges.txt", OutputSpec::Sim("/tmp/edges.txt".into())),
            ("sim:edges:1.txt", OutputSpec::Sim("edges:1.txt".into())),
        ] {
            assert_eq!(text.parse::<OutputSpec>().unwrap(), spec, "{text}");
            assert_eq!(spec.to_string(), text);
        }
        // A name without a slash is under /dev (the systemd instance `gpio:gpiochip0:17`).
        assert_eq!(
            "gpio:gpiochip0:17".parse::<OutputSpec>().unwrap().to_string(),
            "gpio:/dev/gpiochip0:17"
        );
        assert_eq!(
            "phc:ptp0:0".parse::<OutputSpec>().unwrap().to_string(),
            "phc:/dev/ptp0:0"
        );
        for bad in [
            "",
            "gpio",
            "gpio:/dev/gpiochip0",
            "gpio:/dev/gpiochip0:x",
            "gpio::17",
            "gpio:/dev/gpiochip0:-1",
            "gpio:/dev/gpiochip0:17:1",
            "phc:/dev/ptp0",
            "phc:/dev/ptp0:0:1:2",
            "sim:",
            "kernel:/dev/pps0",
        ] {
            let e = bad.parse::<OutputSpec>().unwrap_err();
            assert!(matches!(e, PulseOutError::BadSpec(_)), "{bad}: {e}");
            assert!(e.to_string().contains("gpio:/dev/gpiochipN:LINE"), "{e}");
        }
    }

    #[test]
    fn a_missing_device_says_so() {
        for spec in ["gpio:/dev/navsync-no-gpiochip:17", "phc:/dev/navsync-no-ptp:0"] {
            let Err(e) = spec.parse::<OutputSpec>().unwrap().open() else {
                panic!("{spec} opened");
            };
            let text = e.to_string();
            assert!(matches!(e, PulseOutError::Missing { .. }), "{spec}: {text}");
            assert!(text.contains("no such device"), "{text}");
        }
    }
}
