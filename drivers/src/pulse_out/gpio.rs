//! `gpio:/dev/gpiochipN:LINE`: a GPIO line as an output through the Linux GPIO character
//! device (uAPI v2, `GPIO_V2_GET_LINE_IOCTL` and `GPIO_V2_LINE_SET_VALUES_IOCTL`, through the
//! `gpiocdev` crate). The line is requested for this process alone (consumer
//! `navsync-pps-out`, as `gpioinfo` shows it), starts inactive (low) and is released, and so
//! returned to the kernel's default, when the process ends.
//!
//! The edge is software-timed: the process sets the level at the host time the mapping gives,
//! and the level changes when the ioctl reaches the GPIO controller's register (a few µs on a
//! memory-mapped SoC GPIO, longer behind I²C/SPI expanders or USB adapters, which this module
//! cannot see). The time returned by [`set`](super::PulseOutput::set) is read right after the
//! ioctl returns, so it is the edge's time plus that ioctl's return path.
//!
//! Not exercised on the development machine: it has no GPIO chip and no `gpio-sim` (which
//! needs configfs); opening a chip that is not there is [`PulseOutError::Missing`].

use std::path::Path;

use gpiocdev::line::Value;
use navsync_shared::time::monotonic_now_ns;

use super::{PulseOutError, PulseOutput, require_device};

/// The consumer name the kernel shows for the requested line.
pub const CONSUMER: &str = "navsync-pps-out";

/// A requested GPIO output line.
pub struct GpioLine {
    request: gpiocdev::Request,
    chip: String,
    line: u32,
}

impl GpioLine {
    /// Requests line `line` of the chip `chip` (`/dev/gpiochipN`) as an output, inactive.
    pub fn open(chip: &Path, line: u32) -> Result<Self, PulseOutError> {
        require_device(chip, "a GPIO character device, /dev/gpiochipN")?;
        let name = chip.display().to_string();
        let request = gpiocdev::Request::builder()
            .on_chip(chip)
            .with_consumer(CONSUMER)
            .with_line(line)
            .as_output(Value::Inactive)
            .request()
            .map_err(|source| PulseOutError::Gpio {
                chip: name.clone(),
                line,
                source,
            })?;
        Ok(Self {
            request,
            chip: name,
            line,
        })
    }
}

impl PulseOutput for GpioLine {
    fn set(&mut self, high: bool) -> Result<i64, PulseOutError> {
        let value = if high { Value::Active } else { Value::Inactive };
        self.request
            .set_lone_value(value)
            .map_err(|source| PulseOutError::Gpio {
                chip: self.chip.clone(),
                line: self.line,
                source,
            })?;
        Ok(monotonic_now_ns())
    }

    fn describe(&self) -> String {
        format!("GPIO {} line {}", self.chip, self.line)
    }
}
