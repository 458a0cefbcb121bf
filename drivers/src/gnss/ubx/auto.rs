//! `--protocol auto`: one port, UBX navigation when the receiver sends it, else NMEA.
//!
//! A u-blox port carries UBX and NMEA side by side, in whatever mix the receiver was
//! configured for. [`AutoDecoder`] runs the [`UbxDecoder`] on the bytes; the NMEA sentences
//! its framer separates out go through the existing [`NmeaDecoder`]. The rule, decided from
//! the bytes alone:
//!
//! - UBX epochs are always emitted (they exist only when UBX NAV messages arrive);
//! - an NMEA epoch is emitted when the port carried no UBX navigation as it began (its
//!   first sentence arrived before the first UBX navigation solution message, NAV-PVT,
//!   NAV-SOL, NAV-POSLLH or HNR-PVT), or once [`NMEA_TAKEOVER_EPOCHS`] NMEA epochs in a row
//!   have been completed without such a message (the receiver was reconfigured). Otherwise
//!   it is counted (`auto_nmea_suppressed`) and dropped, so each epoch is reported once,
//!   from UBX, the richer protocol.
//!
//! The fixes emitted are numbered anew (`stamp.seq` 0, 1, 2, … whichever protocol each came
//! from), so a gap in the sequence is a lost sample as everywhere else.

use navsync_shared::samples::GnssFix;

use super::{Event, UbxDecoder};
use crate::gnss::nmea::NmeaDecoder;
use crate::gnss::order::{Admit, TimeOrder};
use crate::gnss::{GnssDecoder, GnssExtra};

/// NMEA epochs in a row without a UBX navigation solution message after which NMEA takes over
/// again (more than a receiver sending NMEA at up to 10 × its UBX rate produces between two
/// UBX solutions).
pub const NMEA_TAKEOVER_EPOCHS: u32 = 10;

/// UBX with NMEA fallback as one [`GnssDecoder`] (see the module doc).
#[derive(Debug, Clone, Default)]
pub struct AutoDecoder {
    ubx: UbxDecoder,
    nmea: NmeaDecoder,
    /// A UBX navigation solution has been seen and NMEA has not taken over since.
    ubx_navigates: bool,
    /// Receipt time of the UBX navigation solution that made UBX navigate, host ns.
    ubx_since_ns: i64,
    /// NMEA epochs completed since the last UBX navigation solution.
    nmea_since_ubx: u32,
    /// NMEA epochs dropped because UBX navigates.
    suppressed: u64,
    /// Fixes emitted: their sequence numbers, one count for both protocols (the two decoders
    /// number their own epochs, and suppressed NMEA epochs would leave gaps that subscribers
    /// take for losses).
    emitted: u64,
    /// The order of the merged output: an epoch of one protocol whose time is not after the
    /// last one published (of either) is held back ([`TimeOrder`]), counted in `held_back`.
    order: TimeOrder,
    held_back: u64,
    /// Resets of the merged output's time line ([`Admit::Reset`]).
    resets: u64,
}

impl AutoDecoder {
    /// A decoder at the start of a stream.
    pub fn new() -> Self {
        Self::default()
    }

    /// The UBX decoder (counters, satellites, time pulse).
    pub fn ubx(&self) -> &UbxDecoder {
        &self.ubx
    }

    /// The NMEA decoder fed with the port's NMEA sentences.
    pub fn nmea(&self) -> &NmeaDecoder {
        &self.nmea
    }

    /// True while UBX epochs are the ones emitted (a UBX navigation solution was seen and
    /// NMEA has not taken over since).
    pub fn ubx_navigates(&self) -> bool {
        self.ubx_navigates
    }

    /// NMEA epochs dropped because UBX navigates.
    pub fn nmea_suppressed(&self) -> u64 {
        self.suppressed
    }

    /// Emits `fix` with the next sequence number, if its time is after the last one emitted.
    fn renumbered(
        (emitted, order, held_back, resets): (&mut u64, &mut TimeOrder, &mut u64, &mut u64),
        fix: &GnssFix,
        out: &mut impl FnMut(&GnssFix),
    ) {
        match order.admit(fix.utc_ns) {
            Admit::HeldBack => {
                *held_back += 1;
                return;
            }
            Admit::Reset => *resets += 1,
            Admit::Publish => {}
        }
        let mut f = *fix;
        f.stamp.seq = *emitted;
        *emitted += 1;
        out(&f);
    }

    /// An NMEA epoch: emitted unless UBX navigated when it began.
    fn nmea_fix(
        ubx_navigates: &mut bool,
        ubx_since_ns: i64,
        nmea_since_ubx: &mut u32,
        suppressed: &mut u64,
        fix: &GnssFix,
        out: &mut impl FnMut(&GnssFix),
    ) {
        if *ubx_navigates {
            *nmea_since_ubx = nmea_since_ubx.saturating_add(1);
            if *nmea_since_ubx >= NMEA_TAKEOVER_EPOCHS {
                *ubx_navigates = false;
            }
        }
        if *ubx_navigates && fix.stamp.host_ns >= ubx_since_ns {
            *suppressed += 1;
        } else {
            out(fix);
        }
    }
}

impl GnssDecoder for AutoDecoder {
    fn push(&mut self, bytes: &[u8], read_host_ns: i64, ns_per_byte: i64, out: &mut impl FnMut(&GnssFix)) {
        self.push_extras(bytes, read_host_ns, ns_per_byte, out, &mut |_| {});
    }

    fn push_extras(
        &mut self,
        bytes: &[u8],
        read_host_ns: i64,
        ns_per_byte: i64,
        out: &mut impl FnMut(&GnssFix),
        extra: &mut impl FnMut(GnssExtra<'_>),
    ) {
        let Self {
            ubx,
            nmea,
            ubx_navigates,
            ubx_since_ns,
            nmea_since_ubx,
            suppressed,
            emitted,
            order,
            held_back,
            resets,
        } = self;
        let out = &mut |fix: &GnssFix| Self::renumbered((emitted, order, held_back, resets), fix, out);
        ubx.push_events(bytes, read_host_ns, ns_per_byte, &mut |ev| match ev {
            Event::Fix(fix) => out(fix),
            Event::Extra(x) => extra(x),
            Event::NavSolution { host_ns } => {
                if !*ubx_navigates {
                    *ubx_navigates = true;
                    *ubx_since_ns = host_ns;
                }
                *nmea_since_ubx = 0;
            }
            Event::Nmea { text, host_ns } => {
                // The sentence, then its terminator, at the time of its `$` (rate 0: no
                // back-dating within these pushes).
                let since = *ubx_since_ns;
                let mut emit =
                    |fix: &GnssFix| Self::nmea_fix(ubx_navigates, since, nmea_since_ubx, suppressed, fix, out);
                nmea.push(text, host_ns, 0, &mut emit);
                nmea.push(b"\r\n", host_ns, 0, &mut emit);
            }
        });
    }

    fn flush(&mut self, out: &mut impl FnMut(&GnssFix)) {
        let Self {
            ubx,
            nmea,
            ubx_navigates,
            ubx_since_ns,
            nmea_since_ubx,
            suppressed,
            emitted,
            order,
            held_back,
            resets,
        } = self;
        let out = &mut |fix: &GnssFix| Self::renumbered((emitted, order, held_back, resets), fix, out);
        ubx.flush(out);
        let since = *ubx_since_ns;
        nmea.flush(&mut |fix| Self::nmea_fix(ubx_navigates, since, nmea_since_ubx, suppressed, fix, out));
    }

    fn reset(&mut self) {
        self.ubx.reset();
        self.nmea.reset();
    }

    fn bytes(&self) -> u64 {
        self.ubx.bytes()
    }

    fn valid_frames(&self) -> u64 {
        self.ubx.valid_frames()
    }

    fn each_counter(&self, f: &mut impl FnMut(&'static str, u64)) {
        self.ubx.each_counter(f);
        self.nmea.each_counter(f);
        f("auto_nmea_suppressed", self.suppressed);
        f("auto_not_after_last", self.held_back);
        f("auto_time_resets", self.resets);
    }

    fn describe(name: &str) -> Option<&'static str> {
        UbxDecoder::describe_ubx(name)
            .or_else(|| NmeaDecoder::describe(name))
            .or_else(|| {
                Some(match name {
                    "auto_not_after_last" => {
                        "epochs held back: their time was not after the last one published (UBX or NMEA)"
                    }
                    "auto_time_resets" => "the receiver's time went back for good; the epoch order restarted",
                    _ => return None,
                })
            })
    }
}

#[cfg(test)]
mod tests {
    use super::super::framer::ubx_frame;
    use super::super::nav::tests::pvt_at as pvt;
    use super::*;
    use navsync_shared::health_reporter::MAX_NAME_LEN;
    use navsync_shared::samples::{GNSS_PROTOCOL_NMEA, GNSS_PROTOCOL_UBX, MAX_COUNTERS};

    fn nmea(body: &str) -> Vec<u8> {
        let sum = body.bytes().fold(0u8, |c, b| c ^ b);
        format!("${body}*{sum:02X}\r\n").into_bytes()
    }

    fn gga(t: &str) -> Vec<u8> {
        nmea(&format!("GPGGA,{t},4807.0381,N,01131.0004,E,1,08,0.9,545.4,M,46.9,M,,"))
    }

    fn run(d: &mut AutoDecoder, bytes: &[u8]) -> Vec<GnssFix> {
        let mut v = Vec::new();
        d.push(bytes, 0, 0, &mut |f| v.push(*f));
        d.flush(&mut |f| v.push(*f));
        v
    }

    #[test]
    fn nmea_only_port_gives_nmea_epochs() {
        let mut d = AutoDecoder::new();
        let mut s = gga("120000");
        s.extend(gga("120001"));
        let fixes = run(&mut d, &s);
        assert_eq!(fixes.len(), 2);
        assert!(fixes.iter().all(|f| f.protocol == GNSS_PROTOCOL_NMEA));
        assert!(!d.ubx_navigates());
        assert_eq!(d.nmea().counters().epochs.epochs, 2);
    }

    #[test]
    fn ubx_navigation_wins_over_nmea_and_nmea_takes_over_when_it_stops() {
        let mut d = AutoDecoder::new();
        let mut fixes = Vec::new();
        // Each frame in a read of its own, 1 ms apart.
        let frames: Vec<Vec<u8>> = vec![
            gga("120000"),
            ubx_frame(1, 7, &pvt(1000, 3, 1)),
            gga("120001"),
            ubx_frame(1, 7, &pvt(2000, 3, 1)),
            gga("120002"),
        ];
        for (i, f) in frames.iter().enumerate() {
            d.push(f, i as i64 * 1_000_000, 0, &mut |f| fixes.push(*f));
        }
        d.flush(&mut |f| fixes.push(*f));
        let protocols: Vec<u8> = fixes.iter().map(|f| f.protocol).collect();
        // The NMEA epoch of 12:00:00 began before the first NAV-PVT: reported (when the next
        // GGA completes it); the later ones are not.
        assert_eq!(
            protocols,
            vec![GNSS_PROTOCOL_NMEA, GNSS_PROTOCOL_UBX, GNSS_PROTOCOL_UBX]
        );
        assert_eq!(d.nmea_suppressed(), 2);
        let seqs: Vec<u64> = fixes.iter().map(|f| f.stamp.seq).collect();
        assert_eq!(
            seqs,
            [0, 1, 2],
            "one numbering for both protocols, no gap for suppressed epochs"
        );
        // UBX stops: after NMEA_TAKEOVER_EPOCHS NMEA epochs NMEA is reported again.
        let mut s = Vec::new();
        for i in 0..15 {
            s.extend(gga(&format!("1201{i:02}")));
        }
        let mut fixes = Vec::new();
        d.push(&s, 10_000_000, 0, &mut |f| fixes.push(*f));
        d.flush(&mut |f| fixes.push(*f));
        // The 2 NMEA epochs after the last NAV-PVT count towards the takeover: 7 more are
        // dropped, the 10th in a row is reported.
        let dropped = NMEA_TAKEOVER_EPOCHS as usize - 1 - 2;
        assert_eq!(fixes.len(), 15 - dropped);
        assert!(fixes.iter().enumerate().all(|(i, f)| f.stamp.seq == 3 + i as u64));
        assert_eq!(d.nmea_suppressed(), 2 + dropped as u64);
        assert!(!d.ubx_navigates());
    }

    #[test]
    fn counters_fit_one_health_report() {
        let d = AutoDecoder::new();
        let mut n = 0;
        d.each_counter(&mut |name, _| {
            n += 1;
            assert!(name.len() <= MAX_NAME_LEN, "{name}");
        });
        // The GNSS driver adds 6 port counters.
        assert!(n + 6 <= MAX_COUNTERS, "{n}");
        assert!(AutoDecoder::describe("nmea_bad_checksum").is_some());
        assert!(AutoDecoder::describe("ubx_bad_checksum").is_some());
    }
}
