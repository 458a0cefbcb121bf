//! GNSS receivers: bytes from a serial port (or a capture) to `GnssFix` samples on
//! `navsync/gnss/{id}/fix`.
//!
//! The seam for receiver protocols is [`GnssDecoder`]: a pure state machine that takes the
//! bytes of each read with their receipt time and emits one [`GnssFix`] per navigation epoch,
//! stamped at the receipt of the epoch's first byte. [`Decoder`] holds the decoder of the
//! chosen [`Protocol`]; the serial driver ([`driver`]), the offline capture decoder
//! ([`capture`], `navsync decode`), the simulator's fast path and the fuzz targets all go
//! through it, and baud hunting asks it whether the bytes are valid frames.
//!
//! Protocols: [`nmea`] (NMEA 0183). Adding one: a module with its framer and decoders
//! (pure functions on bytes), a type implementing [`GnssDecoder`], a [`Protocol`] variant and
//! its arm in [`Decoder`].

pub mod capture;
pub mod driver;
pub mod nmea;

use std::str::FromStr;

use navsync_shared::samples::GnssFix;

use nmea::NmeaDecoder;

/// A GNSS receiver protocol front end: bytes in, one fix per navigation epoch out. Pure: no
/// I/O, no clock, no allocation per byte or fix.
pub trait GnssDecoder {
    /// Feeds the bytes of one read, which returned at host time `read_host_ns` (ns,
    /// `CLOCK_MONOTONIC`); bytes that were already waiting are back-dated by `ns_per_byte`
    /// each (the line rate). Every epoch completed by these bytes goes to `out`.
    fn push(&mut self, bytes: &[u8], read_host_ns: i64, ns_per_byte: i64, out: &mut impl FnMut(&GnssFix));
    /// The line went idle (or closed): the epoch being assembled is complete; emits it.
    fn flush(&mut self, out: &mut impl FnMut(&GnssFix));
    /// Drops a partly received frame (the port was reopened or its rate changed).
    fn reset(&mut self);
    /// Bytes received so far.
    fn bytes(&self) -> u64;
    /// Frames whose checksum passed so far: bytes at the right line rate (baud hunting).
    fn valid_frames(&self) -> u64;
    /// Every counter (framing, checks, epochs) by its health-report name.
    fn each_counter(&self, f: &mut impl FnMut(&'static str, u64));
    /// What a growing error counter means, for the log; `None` for counters that are not errors.
    fn describe(name: &str) -> Option<&'static str>;
}

/// The receiver protocol of a port (`navsync gnss --protocol`, `[gnss.ID] protocol`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Protocol {
    /// NMEA 0183 sentences.
    #[default]
    Nmea,
}

impl Protocol {
    /// The name on the command line and in the configuration file.
    pub fn name(self) -> &'static str {
        match self {
            Self::Nmea => "nmea",
        }
    }
}

impl FromStr for Protocol {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "nmea" => Ok(Self::Nmea),
            _ => Err(format!("`{s}` is not a GNSS protocol (known: nmea)")),
        }
    }
}

impl std::fmt::Display for Protocol {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The decoder of one [`Protocol`].
#[derive(Debug, Clone)]
pub enum Decoder {
    /// NMEA 0183.
    Nmea(NmeaDecoder),
}

impl Decoder {
    /// A decoder for `protocol` at the start of a stream.
    pub fn new(protocol: Protocol) -> Self {
        match protocol {
            Protocol::Nmea => Self::Nmea(NmeaDecoder::new()),
        }
    }

    /// What a growing error counter of any protocol means.
    pub fn describe_counter(name: &str) -> Option<&'static str> {
        NmeaDecoder::describe(name)
    }
}

impl GnssDecoder for Decoder {
    fn push(&mut self, bytes: &[u8], read_host_ns: i64, ns_per_byte: i64, out: &mut impl FnMut(&GnssFix)) {
        match self {
            Self::Nmea(d) => d.push(bytes, read_host_ns, ns_per_byte, out),
        }
    }

    fn flush(&mut self, out: &mut impl FnMut(&GnssFix)) {
        match self {
            Self::Nmea(d) => d.flush(out),
        }
    }

    fn reset(&mut self) {
        match self {
            Self::Nmea(d) => d.reset(),
        }
    }

    fn bytes(&self) -> u64 {
        match self {
            Self::Nmea(d) => d.bytes(),
        }
    }

    fn valid_frames(&self) -> u64 {
        match self {
            Self::Nmea(d) => d.valid_frames(),
        }
    }

    fn each_counter(&self, f: &mut impl FnMut(&'static str, u64)) {
        match self {
            Self::Nmea(d) => d.each_counter(f),
        }
    }

    fn describe(name: &str) -> Option<&'static str> {
        Self::describe_counter(name)
    }
}
