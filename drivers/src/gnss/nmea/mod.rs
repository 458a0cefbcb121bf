//! NMEA 0183: bytes → [`framer::LineFramer`] (sentences, each stamped with the host time of
//! its first byte) → [`sentence`] (checksum, fields decoded into an update in SI units) →
//! [`epoch::EpochAssembler`] (the updates of one time tag merged into one `GnssFix`); beside
//! it [`sky::SkyAssembler`] (GSV with GSA → one `GnssSky` per cycle).
//! [`NmeaDecoder`] is these as one [`GnssDecoder`].

pub mod epoch;
pub mod framer;
pub mod sentence;
pub mod sky;

use navsync_shared::samples::GnssFix;

use super::{GnssDecoder, GnssExtra};
use epoch::{EpochAssembler, EpochCounters};
use framer::{FramerCounters, LineFramer};
use sky::{SkyAssembler, SkyCounters};

/// The NMEA front end as a [`GnssDecoder`]: pure, no allocation per byte or fix.
#[derive(Debug, Clone, Default)]
pub struct NmeaDecoder {
    framer: LineFramer,
    assembler: EpochAssembler,
    sky: SkyAssembler,
}

impl NmeaDecoder {
    /// A decoder at the start of a stream.
    pub fn new() -> Self {
        Self::default()
    }

    /// Hands over the sky still being assembled (its GSV sentences were the last of the
    /// stream, or of the burst before the line went idle), as [`GnssExtra::Sky`].
    pub fn flush_sky(&mut self, extra: &mut impl FnMut(GnssExtra<'_>)) {
        self.sky.flush(&mut |k| extra(GnssExtra::Sky(k)));
    }

    /// Everything counted so far.
    pub fn counters(&self) -> NmeaCounters {
        NmeaCounters {
            framer: *self.framer.counters(),
            epochs: *self.assembler.counters(),
            sky: *self.sky.counters(),
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
    /// GSV sentences and skies.
    pub sky: SkyCounters,
}

impl GnssDecoder for NmeaDecoder {
    fn push(&mut self, bytes: &[u8], read_host_ns: i64, ns_per_byte: i64, out: &mut impl FnMut(&GnssFix)) {
        let Self { framer, assembler, .. } = self;
        framer.push(bytes, read_host_ns, ns_per_byte, &mut |s| {
            assembler.push(s.text, s.host_ns, out)
        });
    }

    /// As `push`, with the sky of each cycle (GSV with GSA) as [`GnssExtra::Sky`], handed over
    /// when the sentence after the cycle's GSV sentences arrives (after that sentence's fix,
    /// if it completes one).
    fn push_extras(
        &mut self,
        bytes: &[u8],
        read_host_ns: i64,
        ns_per_byte: i64,
        out: &mut impl FnMut(&GnssFix),
        extra: &mut impl FnMut(GnssExtra<'_>),
    ) {
        let Self { framer, assembler, sky } = self;
        framer.push(bytes, read_host_ns, ns_per_byte, &mut |s| {
            // The epoch a GSV falls into is known before the sentence is merged (a sentence
            // that completes a sky is merged first: its fix goes out before the sky).
            let utc = assembler.epoch_utc_ns();
            let mut done = None;
            sky.push(s.text, s.host_ns, utc, &mut |k| done = Some(*k));
            assembler.push(s.text, s.host_ns, out);
            if let Some(k) = done {
                extra(GnssExtra::Sky(&k));
            }
        });
    }

    fn flush(&mut self, out: &mut impl FnMut(&GnssFix)) {
        self.assembler.flush(out);
    }

    fn flush_extras(&mut self, out: &mut impl FnMut(&GnssFix), extra: &mut impl FnMut(GnssExtra<'_>)) {
        self.assembler.flush(out);
        self.flush_sky(extra);
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
        let sky = self.sky.counters().named();
        for (name, v) in framer.into_iter().chain(assembler).chain(sky) {
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
            "nmea_gsv_bad" => "malformed NMEA GSV sentences or satellites dropped",
            _ => return None,
        })
    }
}
