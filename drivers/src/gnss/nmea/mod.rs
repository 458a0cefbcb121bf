//! NMEA 0183: bytes → [`framer::LineFramer`] (sentences, each stamped with the host time of
//! its first byte) → [`sentence`] (checksum, fields decoded into an update in SI units) →
//! [`epoch::EpochAssembler`] (the updates of one time tag merged into one `GnssFix`).
//! [`NmeaDecoder`] is the three as one [`GnssDecoder`].

pub mod epoch;
pub mod framer;
pub mod sentence;

use navsync_shared::samples::GnssFix;

use super::GnssDecoder;
use epoch::{EpochAssembler, EpochCounters};
use framer::{FramerCounters, LineFramer};

/// The NMEA front end as a [`GnssDecoder`]: pure, no allocation per byte or fix.
#[derive(Debug, Clone, Default)]
pub struct NmeaDecoder {
    framer: LineFramer,
    assembler: EpochAssembler,
}

impl NmeaDecoder {
    /// A decoder at the start of a stream.
    pub fn new() -> Self {
        Self::default()
    }

    /// Everything counted so far.
    pub fn counters(&self) -> NmeaCounters {
        NmeaCounters {
            framer: *self.framer.counters(),
            epochs: *self.assembler.counters(),
        }
    }
}

/// The NMEA decoder's counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct NmeaCounters {
    /// Framing (noise, truncation, over-long lines).
    pub framer: FramerCounters,
    /// Sentence checks, decoding and epochs.
    pub epochs: EpochCounters,
}

impl GnssDecoder for NmeaDecoder {
    fn push(&mut self, bytes: &[u8], read_host_ns: i64, ns_per_byte: i64, out: &mut impl FnMut(&GnssFix)) {
        let Self { framer, assembler } = self;
        framer.push(bytes, read_host_ns, ns_per_byte, &mut |s| {
            assembler.push(s.text, s.host_ns, out)
        });
    }

    fn flush(&mut self, out: &mut impl FnMut(&GnssFix)) {
        self.assembler.flush(out);
    }

    fn reset(&mut self) {
        self.framer.reset();
    }

    fn bytes(&self) -> u64 {
        self.framer.counters().bytes
    }

    fn valid_frames(&self) -> u64 {
        let c = self.assembler.counters();
        c.sentences - c.bad_checksum - c.no_checksum
    }

    fn each_counter(&self, f: &mut impl FnMut(&'static str, u64)) {
        let framer = self.framer.counters().named();
        let assembler = self.assembler.counters().named();
        for (name, v) in framer.into_iter().chain(assembler) {
            f(name, v);
        }
    }

    fn describe(name: &str) -> Option<&'static str> {
        Some(match name {
            "nmea_noise_bytes" => "bytes outside NMEA sentences skipped (binary noise, wrong baud rate?)",
            "nmea_truncated" => "NMEA sentences cut short by the next one dropped",
            "nmea_overlong" => "over-long NMEA sentences dropped",
            "nmea_non_ascii" => "NMEA sentences with non-ASCII bytes dropped",
            "nmea_bad_checksum" => "NMEA sentences with a bad checksum dropped",
            "nmea_no_checksum" => "NMEA sentences without a checksum dropped",
            "nmea_unparsable" => "unparsable NMEA sentences dropped",
            "nmea_bad_fields" => "malformed NMEA fields ignored",
            "nmea_out_of_range" => "NMEA values outside the standard's range dropped",
            "nmea_zero_sat_fixes" => "fixes claimed from 0 satellites published as no fix",
            "nmea_late_sentences" => "NMEA fix sentences for an epoch already published dropped (not published twice)",
            "nmea_not_after_last" => "NMEA epochs held back: their time was not after the last one published",
            "nmea_time_resets" => "the receiver's time went back for good; the epoch order restarted",
            _ => return None,
        })
    }
}
