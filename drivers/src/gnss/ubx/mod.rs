//! u-blox UBX: bytes → [`framer::UbxFramer`] (UBX frames, NMEA sentences and RTCM3 frames
//! separated, each stamped with the host time of its first byte) → [`messages::decode`]
//! (payloads into typed structs: [`nav`], [`tim`], [`rxm`], [`esf`], [`mon`]) →
//! [`epoch::EpochAssembler`] (the NAV messages of one `iTOW` merged into one `GnssFix`).
//! [`UbxDecoder`] is the three as one [`GnssDecoder`]; [`auto::AutoDecoder`] adds the NMEA
//! sentences of the same port for receivers that send no UBX navigation messages.
//!
//! References: u-blox 8 / M8 Receiver Description incl. Protocol Specification
//! (UBX-13003221); u-blox F9 HPG Interface Description (UBX-22008968); RTCM 10403.x for
//! RTCM3 framing. Checked against gpsd's output on real captures by
//! `drivers/tests/conformance/gpsd_ubx_conformance.rs`.

pub mod auto;
pub mod configure;
pub mod ecef;
pub mod epoch;
pub mod esf;
pub mod framer;
pub mod messages;
pub mod mon;
pub mod nav;
pub mod plausible;
pub mod rxm;
pub mod samples;
pub mod tim;

use navsync_shared::samples::{GnssFix, UBX_MSG_HNR_PVT};

use super::{GnssDecoder, GnssExtra};
use epoch::{EpochAssembler, EpochCounters, SatView, TimeMark, TimePulse};
use framer::{Frame, FramerCounters, UbxFramer};
use messages::Message;
use mon::MonVer;

/// What the decoder made of the UBX frames, besides epochs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MessageCounters {
    /// Frames whose payload could not be decoded (wrong length or version); dropped.
    pub decode_errors: u64,
    /// Frames of messages this front end does not decode (counted, ignored).
    pub unknown: u64,
    /// ACK-ACK messages.
    pub acks: u64,
    /// ACK-NAK messages (the receiver rejected a configuration message).
    pub naks: u64,
    /// Values outside what the message's interface description allows ([`plausible`]): the
    /// field, or the whole message, dropped.
    pub out_of_range: u64,
}

impl MessageCounters {
    /// The counters with short names for a `Health` report (names ≤ 23 bytes).
    pub fn named(&self) -> [(&'static str, u64); 5] {
        [
            ("ubx_decode_errors", self.decode_errors),
            ("ubx_unknown_msgs", self.unknown),
            ("ubx_acks", self.acks),
            ("ubx_naks", self.naks),
            ("ubx_out_of_range", self.out_of_range),
        ]
    }
}

/// The UBX decoder's counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct UbxCounters {
    /// Framing (UBX, NMEA, RTCM3, noise).
    pub framer: FramerCounters,
    /// Message decoding.
    pub messages: MessageCounters,
    /// Epochs.
    pub epochs: EpochCounters,
}

/// One thing the decoder found in the byte stream, in stream order ([`UbxDecoder::push_events`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event<'a> {
    /// A completed NAV epoch (HNR-PVT fixes are [`GnssExtra::Hnr`]).
    Fix(&'a GnssFix),
    /// An NMEA sentence with a valid checksum (`$` … `*hh`, without CR/LF) and the host time
    /// of its `$`, ns.
    Nmea {
        /// The sentence text.
        text: &'a [u8],
        /// Receipt time of its first byte, host `CLOCK_MONOTONIC` ns.
        host_ns: i64,
    },
    /// A UBX navigation solution message arrived (NAV-PVT, NAV-SOL, NAV-POSLLH or HNR-PVT):
    /// the port carries UBX navigation.
    NavSolution {
        /// Receipt time of the message's first byte, host `CLOCK_MONOTONIC` ns.
        host_ns: i64,
    },
    /// A product other than a fix (time pulse, time mark, raw measurements, a subframe, a
    /// reading of the receiver's IMU), as its sample.
    Extra(GnssExtra<'a>),
}

/// The UBX front end as a [`GnssDecoder`]: pure, no allocation per byte or fix.
#[derive(Debug, Clone, Default)]
pub struct UbxDecoder {
    framer: UbxFramer,
    assembler: EpochAssembler,
    messages: MessageCounters,
    version: Option<MonVer>,
    /// The receiver's IMU readings being assembled into samples.
    esf: samples::EsfImu,
    /// Sequence numbers of the extra samples: time pulses, time marks, raw, subframes, skies.
    extra_seq: [u64; 5],
    /// The assembler's satellite views already published as skies.
    sky_views: u64,
}

impl UbxDecoder {
    /// A decoder at the start of a stream.
    pub fn new() -> Self {
        Self::default()
    }

    /// Everything counted so far.
    pub fn counters(&self) -> UbxCounters {
        UbxCounters {
            framer: *self.framer.counters(),
            messages: self.messages,
            epochs: *self.assembler.counters(),
        }
    }

    /// The satellites of the last emitted epoch that carried NAV-SAT or NAV-SVINFO.
    pub fn satellites(&self) -> &SatView {
        self.assembler.satellites()
    }

    /// The last TIM-TP: the time of the next time pulse and its quantisation error.
    pub fn time_pulse(&self) -> Option<&TimePulse> {
        self.assembler.time_pulse()
    }

    /// The last TIM-TM2 (time mark).
    pub fn time_mark(&self) -> Option<&TimeMark> {
        self.assembler.time_mark()
    }

    /// The receiver's last MON-VER (software, hardware and protocol versions).
    pub fn version(&self) -> Option<&MonVer> {
        self.version.as_ref()
    }

    /// The receiver's GPS − UTC leap seconds (NAV-TIMEGPS with `leapSValid`), s.
    pub fn leap_seconds(&self) -> Option<i64> {
        self.assembler.leap_seconds()
    }

    /// Feeds the bytes of one read (as [`GnssDecoder::push`]) and reports, in stream order,
    /// every fix completed, every valid NMEA sentence and every UBX navigation solution
    /// message to `on`.
    pub fn push_events(&mut self, bytes: &[u8], read_host_ns: i64, ns_per_byte: i64, on: &mut impl FnMut(Event<'_>)) {
        let Self {
            framer,
            assembler,
            messages,
            version,
            esf,
            extra_seq,
            sky_views,
        } = self;
        framer.push(bytes, read_host_ns, ns_per_byte, &mut |frame| match frame {
            Frame::Ubx {
                class,
                id,
                payload,
                host_ns,
            } => match messages::decode(class, id, payload) {
                Ok(mut msg) => {
                    let checked = plausible::check(&mut msg);
                    messages.out_of_range += checked.out_of_range();
                    if checked.dropped {
                        return;
                    }
                    match &msg {
                        Message::Other { .. } => messages.unknown += 1,
                        Message::AckAck(_) => messages.acks += 1,
                        Message::AckNak(_) => messages.naks += 1,
                        Message::MonVer(v) => *version = Some(*v),
                        Message::NavPvt(_) | Message::NavSol(_) | Message::NavPosllh(_) | Message::HnrPvt(_) => {
                            on(Event::NavSolution { host_ns })
                        }
                        _ => {}
                    }
                    // HNR-PVT fixes are an output of their own (`GnssExtra::Hnr`).
                    assembler.push(&msg, host_ns, &mut |fix| {
                        if fix.sentences & UBX_MSG_HNR_PVT != 0 {
                            on(Event::Extra(GnssExtra::Hnr(fix)))
                        } else {
                            on(Event::Fix(fix))
                        }
                    });
                    let mut next = |i: usize| {
                        extra_seq[i] += 1;
                        extra_seq[i] - 1
                    };
                    match &msg {
                        Message::TimTp(_) => {
                            if let Some(tp) = assembler.time_pulse() {
                                on(Event::Extra(GnssExtra::TimePulse(&tp.sample(next(0)))));
                            }
                        }
                        Message::TimTm2(_) => {
                            if let Some(tm) = assembler.time_mark() {
                                on(Event::Extra(GnssExtra::Event(&tm.sample(next(1)))));
                            }
                        }
                        Message::RxmRawx(m) => {
                            on(Event::Extra(GnssExtra::Raw(&samples::raw_sample(m, host_ns, next(2)))))
                        }
                        Message::RxmSfrbx(m) => on(Event::Extra(GnssExtra::NavData(&samples::nav_data_sample(
                            m,
                            host_ns,
                            next(3),
                        )))),
                        Message::EsfMeas(m) => {
                            if let Some(s) = esf.push(m, host_ns) {
                                on(Event::Extra(GnssExtra::Imu(&s)));
                            }
                        }
                        _ => {}
                    }
                    // A new satellite view (its epoch emitted, or a late NAV-SAT for it).
                    if let Some(sky) = new_sky(assembler, sky_views, &mut extra_seq[4]) {
                        on(Event::Extra(GnssExtra::Sky(&sky)));
                    }
                }
                Err(_) => messages.decode_errors += 1,
            },
            Frame::Nmea { text, host_ns } => on(Event::Nmea { text, host_ns }),
            Frame::Rtcm3 { .. } => {}
        });
    }

    /// As [`GnssDecoder::flush`], with the sky of the epoch it completes as [`Event::Extra`].
    pub fn flush_events(&mut self, on: &mut impl FnMut(Event<'_>)) {
        self.assembler.flush(&mut |fix| on(Event::Fix(fix)));
        if let Some(sky) = new_sky(&self.assembler, &mut self.sky_views, &mut self.extra_seq[4]) {
            on(Event::Extra(GnssExtra::Sky(&sky)));
        }
    }

    /// What a growing UBX error counter means (shared with [`auto::AutoDecoder`]).
    pub(crate) fn describe_ubx(name: &str) -> Option<&'static str> {
        Some(match name {
            "ubx_noise_bytes" => "bytes outside UBX/NMEA/RTCM3 frames skipped (line noise, wrong baud rate?)",
            "ubx_bad_checksum" => "UBX frames with a bad checksum dropped",
            "ubx_bad_length" => "UBX frames with an implausible length dropped",
            "ubx_nmea_bad_checksum" => "NMEA sentences with a bad or missing checksum dropped (UBX port)",
            "ubx_rtcm3_bad_crc" => "RTCM3 frames with a bad CRC dropped",
            "ubx_decode_errors" => "UBX messages of a wrong length or version dropped",
            "ubx_out_of_range" => "UBX values outside the interface description dropped",
            "ubx_naks" => "UBX configuration messages rejected by the receiver (ACK-NAK)",
            "ubx_late_messages" => {
                "UBX NAV messages that arrived after their epoch was published (not published again)"
            }
            "ubx_not_after_last" => "UBX epochs held back: their time was not after the last one published",
            "ubx_time_resets" => "the receiver's time went back for good; the epoch order restarted",
            "ubx_sats_dropped" => "satellites beyond the capacity of a NAV-SAT/NAV-SVINFO view dropped",
            _ => return None,
        })
    }
}

/// The assembler's satellite view as a sky, when it is one not yet published (`published`:
/// the views published so far; `seq`: the skies' sequence counter).
fn new_sky(assembler: &EpochAssembler, published: &mut u64, seq: &mut u64) -> Option<navsync_shared::samples::GnssSky> {
    if assembler.satellite_views() == *published {
        return None;
    }
    *published = assembler.satellite_views();
    *seq += 1;
    Some(samples::sky_sample(assembler.satellites(), *seq - 1))
}

impl GnssDecoder for UbxDecoder {
    fn push(&mut self, bytes: &[u8], read_host_ns: i64, ns_per_byte: i64, out: &mut impl FnMut(&GnssFix)) {
        self.push_events(bytes, read_host_ns, ns_per_byte, &mut |ev| {
            if let Event::Fix(fix) = ev {
                out(fix);
            }
        });
    }

    fn push_extras(
        &mut self,
        bytes: &[u8],
        read_host_ns: i64,
        ns_per_byte: i64,
        out: &mut impl FnMut(&GnssFix),
        extra: &mut impl FnMut(GnssExtra<'_>),
    ) {
        self.push_events(bytes, read_host_ns, ns_per_byte, &mut |ev| match ev {
            Event::Fix(fix) => out(fix),
            Event::Extra(x) => extra(x),
            Event::Nmea { .. } | Event::NavSolution { .. } => {}
        });
    }

    fn flush(&mut self, out: &mut impl FnMut(&GnssFix)) {
        self.assembler.flush(out);
    }

    fn flush_extras(&mut self, out: &mut impl FnMut(&GnssFix), extra: &mut impl FnMut(GnssExtra<'_>)) {
        self.flush_events(&mut |ev| match ev {
            Event::Fix(fix) => out(fix),
            Event::Extra(x) => extra(x),
            Event::Nmea { .. } | Event::NavSolution { .. } => {}
        });
    }

    fn reset(&mut self) {
        self.framer.reset();
    }

    fn bytes(&self) -> u64 {
        self.framer.counters().bytes
    }

    fn valid_frames(&self) -> u64 {
        self.framer.counters().valid_frames()
    }

    fn each_counter(&self, f: &mut impl FnMut(&'static str, u64)) {
        let c = self.counters();
        for (name, v) in c
            .framer
            .named()
            .into_iter()
            .chain(c.messages.named())
            .chain(c.epochs.named())
        {
            f(name, v);
        }
    }

    fn describe(name: &str) -> Option<&'static str> {
        Self::describe_ubx(name)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::framer::ubx_frame;
    use super::nav::tests::pvt_at as pvt;
    use super::*;
    use navsync_shared::health_reporter::MAX_NAME_LEN;

    #[test]
    fn decodes_a_stream_into_epochs() {
        let mut d = UbxDecoder::new();
        let mut bytes = ubx_frame(1, 7, &pvt(1000, 3, 0x01));
        bytes.extend(ubx_frame(1, 0x61, &1000u32.to_le_bytes()));
        bytes.extend(ubx_frame(1, 7, &pvt(2000, 3, 0x01)));
        bytes.extend(ubx_frame(1, 7, &[0; 10]));
        bytes.extend(ubx_frame(0x27, 3, &[0; 10]));
        bytes.extend(ubx_frame(5, 0, &[6, 1]));
        let mut fixes = Vec::new();
        d.push(&bytes, 1_000_000, 0, &mut |f| fixes.push(*f));
        assert_eq!(fixes.len(), 1, "the first at its NAV-EOE");
        d.flush(&mut |f| fixes.push(*f));
        assert_eq!(fixes.len(), 2);
        let c = d.counters();
        assert_eq!(
            (c.messages.decode_errors, c.messages.unknown, c.messages.naks),
            (1, 1, 1)
        );
        assert_eq!((c.epochs.eoe_emits, c.epochs.flush_emits), (1, 1));
        assert_eq!(d.valid_frames(), 6);
    }

    /// xorshift64 for reproducible pseudo-random input.
    fn next(x: &mut u64) -> u64 {
        *x ^= *x << 13;
        *x ^= *x >> 7;
        *x ^= *x << 17;
        *x
    }

    #[test]
    fn random_frames_with_valid_checksums_never_panic() {
        // Every decoded message, with payloads of random content and of lengths around the
        // valid ones (so that the decoders and the epoch assembler see garbage that passed
        // the checksum), mixed with the decoder's own PVT epochs.
        let ids = [
            (1, 7, 92),
            (1, 6, 52),
            (1, 0x20, 16),
            (1, 2, 28),
            (1, 0x12, 36),
            (1, 4, 18),
            (1, 3, 16),
            (1, 0x21, 20),
            (1, 0x35, 8 + 12 * 3),
            (1, 0x30, 8 + 12 * 3),
            (1, 0x61, 4),
            (0x0D, 1, 16),
            (0x0D, 3, 28),
            (2, 0x15, 16 + 32 * 2),
            (2, 0x13, 8 + 4 * 10),
            (0x10, 2, 8 + 4 * 3 + 4),
            (0x10, 3, 4 + 8 * 3),
            (0x28, 0, 72),
            (0x0A, 4, 100),
            (5, 1, 2),
        ];
        let mut d = UbxDecoder::new();
        let mut x = 0x2545_F491_4F6C_DD1D_u64;
        let mut fixes = 0u64;
        for round in 0..40_000u32 {
            let r = next(&mut x);
            let (class, id, len) = ids[(r % ids.len() as u64) as usize];
            let len = match (r >> 8) % 4 {
                0 => len,
                1 => (len + (r >> 16) as usize % 5).saturating_sub(2),
                _ => len,
            };
            let mut payload: Vec<u8> = (0..len).map(|_| (next(&mut x) >> 24) as u8).collect();
            if (r >> 20).is_multiple_of(3) {
                // Plausible counts and versions, so that the variable-length bodies decode.
                match (class, id) {
                    (1, 0x35) if len > 5 => (payload[4], payload[5]) = (1, 3),
                    (1, 0x30) if len > 4 => payload[4] = 3,
                    (2, 0x15) if len > 11 => payload[11] = 2,
                    (2, 0x13) if len > 4 => payload[4] = 10,
                    _ => {}
                }
            }
            let mut bytes = ubx_frame(class, id, &payload);
            if round % 7 == 0 {
                bytes.extend(ubx_frame(1, 7, &pvt(round, 3, 1)));
            }
            let check = |f: &GnssFix| {
                assert!(f.mode <= 3);
                assert!(f.lat_deg.is_nan() || f.lat_deg.abs() <= 90.0);
                assert!(f.utc_ns == i64::MIN || f.gps_ns != i64::MIN);
            };
            let mut hnr = 0;
            d.push_extras(
                &bytes,
                i64::from(round),
                1,
                &mut |f| {
                    fixes += 1;
                    check(f);
                },
                &mut |x| {
                    if let GnssExtra::Hnr(f) = x {
                        hnr += 1;
                        check(f);
                    }
                },
            );
            fixes += hnr;
        }
        d.flush(&mut |_| fixes += 1);
        assert!(fixes > 1000);
        let c = d.counters();
        assert!(c.messages.decode_errors > 0 && c.epochs.epochs == fixes);
    }

    #[test]
    fn counter_names_fit_health_slots() {
        let d = UbxDecoder::new();
        let mut n = 0;
        d.each_counter(&mut |name, _| {
            n += 1;
            assert!(name.len() <= MAX_NAME_LEN, "{name}");
        });
        assert_eq!(n, 27);
    }
}
