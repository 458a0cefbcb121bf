//! `gpio:/dev/gpiochipN:LINE`: a GPIO line's edges as events, through the Linux GPIO character
//! device (uAPI v2 line request with edge detection, `GPIO_V2_LINE_FLAG_EDGE_*`, through the
//! `gpiocdev` crate; consumer `navsync-trigger`). The kernel stamps each edge when its
//! interrupt is handled, on `CLOCK_MONOTONIC` (the default event clock of uAPI v2), navsync's
//! host clock; edges queue in the kernel until read (its buffer: 16 per line by default), and
//! the line's sequence number shows an overrun as a gap.
//!
//! Not exercised on the development machine: it has no GPIO chip and no `gpio-sim` (which
//! needs configfs); opening a chip that is not there is [`TriggerError::Missing`].

use std::path::Path;
use std::time::Duration;

use gpiocdev::line::{EdgeDetection, EdgeKind, EventClock};

use super::{Edges, TriggerEdge, TriggerError, TriggerInput};

/// The consumer name the kernel shows for the requested line.
pub const CONSUMER: &str = "navsync-trigger";

/// A GPIO line requested for its edge events.
pub struct GpioTrigger {
    request: gpiocdev::Request,
    chip: String,
    line: u32,
}

impl GpioTrigger {
    /// Requests line `line` of chip `chip` (`/dev/gpiochipN`) as an input reporting `edges`.
    pub fn open(chip: &Path, line: u32, edges: Edges) -> Result<Self, TriggerError> {
        let name = chip.display().to_string();
        if !chip.exists() {
            return Err(TriggerError::Missing(name));
        }
        let detection = match edges {
            Edges::Rising => EdgeDetection::RisingEdge,
            Edges::Falling => EdgeDetection::FallingEdge,
            Edges::Both => EdgeDetection::BothEdges,
        };
        let request = gpiocdev::Request::builder()
            .on_chip(chip)
            .with_consumer(CONSUMER)
            .with_line(line)
            .as_input()
            .with_edge_detection(detection)
            .with_event_clock(EventClock::Monotonic)
            .request()
            .map_err(|source| TriggerError::Gpio {
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

    fn error(&self, source: gpiocdev::Error) -> TriggerError {
        TriggerError::Gpio {
            chip: self.chip.clone(),
            line: self.line,
            source,
        }
    }
}

impl TriggerInput for GpioTrigger {
    fn next_edge(&mut self, timeout: Duration) -> Result<Option<TriggerEdge>, TriggerError> {
        if !self.request.wait_edge_event(timeout).map_err(|e| self.error(e))? {
            return Ok(None);
        }
        let e = self.request.read_edge_event().map_err(|e| self.error(e))?;
        Ok(Some(TriggerEdge {
            host_ns: e.timestamp_ns as i64,
            rising: e.kind == EdgeKind::Rising,
            count: e.line_seqno,
        }))
    }

    fn describe(&self) -> String {
        format!("GPIO {} line {}", self.chip, self.line)
    }

    fn channel(&self) -> u8 {
        self.line.min(255) as u8
    }
}
