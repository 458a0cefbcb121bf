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
//! Protocols: [`nmea`] (NMEA 0183), [`ubx`] (u-blox UBX, with the NMEA sentences and RTCM3
//! frames of the same port separated out), and `auto` ([`ubx::auto`]: UBX navigation when the
//! port carries it, else NMEA). Adding one: a module with its framer and decoders (pure
//! functions on bytes), a type implementing [`GnssDecoder`] that fills the protocol-neutral
//! fields of [`GnssFix`], and its line in the `gnss_protocols!` registry below.

pub mod capture;
pub mod cycle;
pub mod driver;
pub mod geoid;
pub mod nmea;
pub mod order;
pub mod rinex;
pub mod rinex_write;
pub mod ubx;

use std::str::FromStr;

use navsync_shared::samples::{GnssEvent, GnssFix, GnssNavData, GnssRaw, GnssSky, GnssTimePulse, ImuSample};

use nmea::NmeaDecoder;
use ubx::UbxDecoder;
use ubx::auto::AutoDecoder;

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
    /// As [`push`](Self::push), also handing the receiver's other products to `extra` in
    /// stream order (time pulses, time marks, raw measurements, navigation data subframes,
    /// the receiver's own IMU readings, the satellites of an epoch). Default: none.
    fn push_extras(
        &mut self,
        bytes: &[u8],
        read_host_ns: i64,
        ns_per_byte: i64,
        out: &mut impl FnMut(&GnssFix),
        extra: &mut impl FnMut(GnssExtra<'_>),
    ) {
        let _ = extra;
        self.push(bytes, read_host_ns, ns_per_byte, out);
    }
    /// As [`flush`](Self::flush), also handing over the products the idle line completes (the
    /// sky of the epoch or cycle just ended). Default: [`flush`](Self::flush) alone.
    fn flush_extras(&mut self, out: &mut impl FnMut(&GnssFix), extra: &mut impl FnMut(GnssExtra<'_>)) {
        let _ = extra;
        self.flush(out);
    }
}

/// A receiver's product other than a fix, as the sample published for it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GnssExtra<'a> {
    /// The next time pulse (UBX TIM-TP), for `navsync/gnss/{id}/timepulse`.
    TimePulse(&'a GnssTimePulse),
    /// A time mark of an input pin (UBX TIM-TM2), for `navsync/gnss/{id}/event`.
    Event(&'a GnssEvent),
    /// Raw measurements of an epoch (UBX RXM-RAWX), for `navsync/gnss/{id}/raw`.
    Raw(&'a GnssRaw),
    /// A navigation data subframe (UBX RXM-SFRBX), for `navsync/gnss/{id}/nav-data`.
    NavData(&'a GnssNavData),
    /// A reading of the receiver's own IMU (UBX ESF-MEAS), for `navsync/imu/{id}/sample`
    /// (`imu_id` still empty: the driver names it).
    Imu(&'a ImuSample),
    /// The receiver's high-rate blend of GNSS and its sensors (UBX HNR-PVT, `FIX_FLAG_NOT_GNSS`),
    /// for `navsync/gnss/{id}/hnr`: a stream of its own, with its own sequence numbers and
    /// times, never mixed into the GNSS epochs of `navsync/gnss/{id}/fix`.
    Hnr(&'a GnssFix),
    /// The satellites the receiver reported with an epoch (NMEA GSV with GSA, UBX NAV-SAT or
    /// NAV-SVINFO), for `navsync/gnss/{id}/sky`.
    Sky(&'a GnssSky),
}

/// The registry of receiver protocols: for each line `Variant = "name" => DecoderType` (with
/// `[boxed]` for a decoder kept on the heap), the [`Protocol`] variant with its name on the
/// command line and in the file, and the [`Decoder`] variant with every arm of its
/// [`GnssDecoder`] implementation. A new protocol is one line here.
macro_rules! gnss_protocols {
    (
        default $default:ident;
        $( $(#[doc = $doc:literal])+ $variant:ident = $name:literal => $dec:ident $([$boxed:ident])?, )*
    ) => {
        /// The receiver protocol of a port (`navsync gnss --protocol`, `[gnss.ID] protocol`).
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        pub enum Protocol {
            $( $(#[doc = $doc])+ $variant, )*
        }

        impl Default for Protocol {
            fn default() -> Self {
                Self::$default
            }
        }

        impl Protocol {
            /// Every protocol.
            pub const ALL: &'static [Protocol] = &[$(Self::$variant),*];

            /// The name on the command line and in the configuration file.
            pub fn name(self) -> &'static str {
                match self {
                    $(Self::$variant => $name,)*
                }
            }
        }

        /// The decoder of one [`Protocol`]. Decoders with a large window (UBX's framer holds one
        /// maximal frame, 8 kB) are boxed, allocated once with the decoder; the NMEA decoder
        /// stays inline, so that the NMEA path allocates nothing at all.
        #[allow(clippy::large_enum_variant)]
        #[derive(Debug, Clone)]
        pub enum Decoder {
            $( $(#[doc = $doc])+ $variant(gnss_protocols!(@store $dec $($boxed)?)), )*
        }

        impl Decoder {
            /// A decoder for `protocol` at the start of a stream.
            pub fn new(protocol: Protocol) -> Self {
                match protocol {
                    $(Protocol::$variant => Self::$variant(Default::default()),)*
                }
            }

            /// What a growing error counter of any protocol means.
            pub fn describe_counter(name: &str) -> Option<&'static str> {
                None$(.or_else(|| <$dec as GnssDecoder>::describe(name)))*
            }
        }

        impl GnssDecoder for Decoder {
            fn push(&mut self, bytes: &[u8], read_host_ns: i64, ns_per_byte: i64, out: &mut impl FnMut(&GnssFix)) {
                match self {
                    $(Self::$variant(d) => d.push(bytes, read_host_ns, ns_per_byte, out),)*
                }
            }

            fn push_extras(
                &mut self,
                bytes: &[u8],
                read_host_ns: i64,
                ns_per_byte: i64,
                out: &mut impl FnMut(&GnssFix),
                extra: &mut impl FnMut(GnssExtra<'_>),
            ) {
                match self {
                    $(Self::$variant(d) => d.push_extras(bytes, read_host_ns, ns_per_byte, out, extra),)*
                }
            }

            fn flush(&mut self, out: &mut impl FnMut(&GnssFix)) {
                match self {
                    $(Self::$variant(d) => d.flush(out),)*
                }
            }

            fn flush_extras(&mut self, out: &mut impl FnMut(&GnssFix), extra: &mut impl FnMut(GnssExtra<'_>)) {
                match self {
                    $(Self::$variant(d) => d.flush_extras(out, extra),)*
                }
            }

            fn reset(&mut self) {
                match self {
                    $(Self::$variant(d) => d.reset(),)*
                }
            }

            fn bytes(&self) -> u64 {
                match self {
                    $(Self::$variant(d) => d.bytes(),)*
                }
            }

            fn valid_frames(&self) -> u64 {
                match self {
                    $(Self::$variant(d) => d.valid_frames(),)*
                }
            }

            fn each_counter(&self, f: &mut impl FnMut(&'static str, u64)) {
                match self {
                    $(Self::$variant(d) => d.each_counter(f),)*
                }
            }

            fn describe(name: &str) -> Option<&'static str> {
                Self::describe_counter(name)
            }
        }
    };
    (@store $dec:ident) => { $dec };
    (@store $dec:ident boxed) => { Box<$dec> };
}

gnss_protocols! {
    default Auto;
    /// NMEA 0183 sentences.
    Nmea = "nmea" => NmeaDecoder,
    /// u-blox UBX binary messages (NMEA and RTCM3 on the same port are skipped).
    Ubx = "ubx" => UbxDecoder [boxed],
    /// UBX navigation when the port carries UBX NAV messages, else its NMEA sentences,
    /// decided from the bytes ([`ubx::auto`]).
    Auto = "auto" => AutoDecoder [boxed],
}

impl FromStr for Protocol {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL.iter().copied().find(|p| p.name() == s).ok_or_else(|| {
            let known: Vec<_> = Self::ALL.iter().map(|p| p.name()).collect();
            format!("`{s}` is not a GNSS protocol (known: {})", known.join(", "))
        })
    }
}

impl std::fmt::Display for Protocol {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// In a configuration file: the protocol's name.
impl<'de> serde::Deserialize<'de> for Protocol {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn protocol_names_round_trip() {
        for p in [Protocol::Nmea, Protocol::Ubx, Protocol::Auto] {
            assert_eq!(p.name().parse::<Protocol>(), Ok(p));
            let json = format!("\"{}\"", p.name());
            assert_eq!(serde_json::from_str::<Protocol>(&json).ok(), Some(p));
        }
        assert!("sirf".parse::<Protocol>().is_err());
        assert_eq!(
            Protocol::default(),
            Protocol::Auto,
            "the bytes say which protocol they are"
        );
    }
}
