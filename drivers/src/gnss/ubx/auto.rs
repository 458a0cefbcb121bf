//! `--protocol auto`: one port, UBX navigation when the receiver sends it, else NMEA.
//!
//! A u-blox port carries UBX and NMEA side by side, in whatever mix the receiver was
//! configured for. [`AutoDecoder`] runs the [`UbxDecoder`] on the bytes; the NMEA sentences
//! its framer separates out go through the existing [`NmeaDecoder`]. The rule, decided from
//! the bytes alone:
//!
//! - UBX epochs are always emitted (they exist only when UBX NAV messages arrive);
//! - NMEA epochs are emitted until UBX navigates, and dropped while it does (counted,
//!   `auto_nmea_suppressed`), so each epoch is reported once, from UBX, the richer protocol.
//!   UBX navigates once it is a stable majority: of the last [`UBX_WINDOW`] NMEA epochs, at
//!   least [`UBX_MAJORITY`] had a UBX navigation solution message (NAV-PVT, NAV-SOL,
//!   NAV-POSLLH or HNR-PVT, within the bounds of [`super::plausible`]) within
//!   [`UBX_COVER_NS`] of them; it stops navigating when none of the last [`UBX_WINDOW`] had
//!   one (the receiver was reconfigured). A few stray or forged UBX frames never cover
//!   enough epochs to take over (three used to suppress the real NMEA fixes for ~13 s); an
//!   NMEA epoch that began before UBX took over is still reported, unless a UBX epoch of the
//!   same time of day was emitted already (the same receiver epoch: reported once). While UBX
//!   solutions are about but UBX does not navigate yet, an NMEA epoch is held until the next
//!   epoch of either protocol: a UBX epoch of the same time replaces it (the receiver sent
//!   its sentences first), else it is published then.
//!
//! The skies (`GnssExtra::Sky`): UBX's (NAV-SAT, NAV-SVINFO) always; the NMEA ones (GSV with
//! GSA) unless a UBX sky came within [`UBX_SKY_HOLD_NS`] before (left out, as expected of a
//! port that sends UBX skies; not a `Health` counter), numbered anew like the fixes.
//!
//! The fixes emitted are numbered anew (`stamp.seq` 0, 1, 2, … whichever protocol each came
//! from), so a gap in the sequence is a lost sample as everywhere else.

use navsync_shared::samples::{GnssFix, GnssSky};

use super::{Event, UbxDecoder};
use crate::gnss::nmea::NmeaDecoder;
use crate::gnss::order::{Admit, TimeOrder};
use crate::gnss::{GnssDecoder, GnssExtra};

/// The NMEA epochs over which UBX's share is judged.
pub const UBX_WINDOW: u32 = 8;
/// Of the last [`UBX_WINDOW`] NMEA epochs, how many must have a UBX navigation solution near
/// them for UBX to take over.
pub const UBX_MAJORITY: u32 = 6;
/// A UBX navigation solution this close (host time) to an NMEA epoch covers it: the same
/// receiver epoch, or one of a receiver sending NMEA at up to 10 × its UBX rate.
pub const UBX_COVER_NS: i64 = 1_500_000_000;
/// An NMEA sky is not published within this long (host time) after a UBX sky: the receiver
/// reports its satellites in UBX, the richer report.
pub const UBX_SKY_HOLD_NS: i64 = 5_000_000_000;

/// The skies of either protocol as one stream (see the module doc).
#[derive(Debug, Clone, Copy, Default)]
struct Skies {
    /// Receipt time of the last UBX sky, host ns.
    last_ubx_ns: Option<i64>,
    /// Skies published (their sequence numbers).
    emitted: u64,
    /// NMEA skies dropped because UBX reports the sky.
    suppressed: u64,
}

impl Skies {
    fn publish(&mut self, from_ubx: bool, sky: &GnssSky, extra: &mut impl FnMut(GnssExtra<'_>)) {
        if from_ubx {
            self.last_ubx_ns = Some(sky.stamp.host_ns);
        } else if self
            .last_ubx_ns
            .is_some_and(|t| sky.stamp.host_ns - t <= UBX_SKY_HOLD_NS)
        {
            self.suppressed += 1;
            return;
        }
        let mut k = *sky;
        k.stamp.seq = self.emitted;
        self.emitted += 1;
        extra(GnssExtra::Sky(&k));
    }
}

/// UBX with NMEA fallback as one [`GnssDecoder`] (see the module doc).
#[derive(Debug, Clone, Default)]
pub struct AutoDecoder {
    ubx: UbxDecoder,
    nmea: NmeaDecoder,
    /// UBX's navigation state (see the module doc).
    vote: UbxVote,
    /// NMEA epochs dropped because UBX navigates or reported the same epoch.
    suppressed: u64,
    /// An NMEA epoch held while UBX solutions are about but UBX does not navigate yet: the
    /// same receiver epoch's UBX messages may follow its sentences, and the richer report is
    /// the one published (once). Published when the next epoch of either protocol comes
    /// first, or at a flush.
    pending: Option<GnssFix>,
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
    /// The skies of both protocols.
    skies: Skies,
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

    /// True while UBX epochs are the ones emitted (UBX is a stable majority; see the module
    /// doc).
    pub fn ubx_navigates(&self) -> bool {
        self.vote.navigates
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
}

/// Whether UBX navigates: which of the last NMEA epochs had a UBX navigation solution near
/// them.
#[derive(Debug, Clone, Copy, Default)]
struct UbxVote {
    /// Receipt time of the last UBX navigation solution, host ns.
    last_ubx_ns: Option<i64>,
    /// One bit per recent NMEA epoch, newest in bit 0: covered by a UBX solution.
    covered: u8,
    /// UBX is the majority (NMEA epochs are dropped).
    navigates: bool,
    /// Since when, host ns (an NMEA epoch that began before is still reported).
    since_ns: i64,
    /// Times of day (ns) of the last UBX epochs emitted, newest first.
    ubx_tods: [Option<i64>; 4],
}

impl UbxVote {
    fn ubx_solution(&mut self, host_ns: i64) {
        self.last_ubx_ns = Some(host_ns);
    }

    /// A UBX epoch was emitted.
    fn ubx_epoch(&mut self, tod_ns: i64) {
        if tod_ns >= 0 {
            self.ubx_tods.rotate_right(1);
            self.ubx_tods[0] = Some(tod_ns);
        }
    }

    /// True if a UBX navigation solution arrived within [`UBX_COVER_NS`] of `host_ns`.
    fn ubx_about(&self, host_ns: i64) -> bool {
        self.last_ubx_ns.is_some_and(|t| (host_ns - t).abs() <= UBX_COVER_NS)
    }

    /// True if a UBX epoch of this time of day was emitted lately.
    fn reported_by_ubx(&self, tod_ns: i64) -> bool {
        tod_ns >= 0 && self.ubx_tods.iter().flatten().any(|&t| (t - tod_ns).abs() < 1_000_000)
    }

    /// An NMEA epoch began at `host_ns`: its vote; true if it is to be dropped.
    fn nmea_epoch(&mut self, host_ns: i64) -> bool {
        let covered = self.ubx_about(host_ns);
        self.covered = (self.covered << 1) | u8::from(covered);
        let window = self.covered & ((1u16 << UBX_WINDOW) - 1) as u8;
        if !self.navigates && window.count_ones() >= UBX_MAJORITY {
            self.navigates = true;
            self.since_ns = host_ns;
        } else if self.navigates && window == 0 {
            self.navigates = false;
        }
        self.navigates && host_ns >= self.since_ns
    }
}

impl AutoDecoder {
    /// An NMEA epoch: dropped while UBX navigates or when UBX reported its epoch already; held
    /// in `pending` while UBX solutions are about (its UBX report may follow); else emitted.
    fn nmea_fix(
        vote: &mut UbxVote,
        suppressed: &mut u64,
        pending: &mut Option<GnssFix>,
        fix: &GnssFix,
        out: &mut impl FnMut(&GnssFix),
    ) {
        let navigates = vote.nmea_epoch(fix.stamp.host_ns);
        if navigates || vote.reported_by_ubx(fix.tod_ns) {
            *suppressed += 1;
            return;
        }
        if let Some(p) = pending.take() {
            out(&p);
        }
        if vote.ubx_about(fix.stamp.host_ns) {
            *pending = Some(*fix);
        } else {
            out(fix);
        }
    }

    /// A UBX epoch: a held NMEA epoch of the same time of day is dropped (the same receiver
    /// epoch, reported by UBX), an older one published first.
    fn ubx_fix(
        vote: &mut UbxVote,
        suppressed: &mut u64,
        pending: &mut Option<GnssFix>,
        fix: &GnssFix,
        out: &mut impl FnMut(&GnssFix),
    ) {
        vote.ubx_epoch(fix.tod_ns);
        if let Some(p) = pending.take() {
            if vote.reported_by_ubx(p.tod_ns) {
                *suppressed += 1;
            } else if p.utc_ns < fix.utc_ns {
                out(&p);
            } else {
                *pending = Some(p);
            }
        }
        out(fix);
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
            vote,
            suppressed,
            pending,
            emitted,
            order,
            held_back,
            resets,
            skies,
        } = self;
        let out = &mut |fix: &GnssFix| Self::renumbered((emitted, order, held_back, resets), fix, out);
        ubx.push_events(bytes, read_host_ns, ns_per_byte, &mut |ev| match ev {
            Event::Fix(fix) => Self::ubx_fix(vote, suppressed, pending, fix, out),
            Event::Extra(GnssExtra::Sky(k)) => skies.publish(true, k, extra),
            Event::Extra(x) => extra(x),
            Event::NavSolution { host_ns } => vote.ubx_solution(host_ns),
            Event::Nmea { text, host_ns } => {
                // The sentence, then its terminator, at the time of its `$` (rate 0: no
                // back-dating within these pushes).
                let mut emit = |fix: &GnssFix| Self::nmea_fix(vote, suppressed, pending, fix, out);
                let mut sky = |x: GnssExtra<'_>| {
                    if let GnssExtra::Sky(k) = x {
                        skies.publish(false, k, extra);
                    }
                };
                nmea.push_extras(text, host_ns, 0, &mut emit, &mut sky);
                nmea.push_extras(b"\r\n", host_ns, 0, &mut emit, &mut sky);
            }
        });
    }

    fn flush(&mut self, out: &mut impl FnMut(&GnssFix)) {
        self.flush_extras(out, &mut |_| {});
    }

    fn flush_extras(&mut self, out: &mut impl FnMut(&GnssFix), extra: &mut impl FnMut(GnssExtra<'_>)) {
        let Self {
            ubx,
            nmea,
            vote,
            suppressed,
            pending,
            emitted,
            order,
            held_back,
            resets,
            skies,
        } = self;
        let out = &mut |fix: &GnssFix| Self::renumbered((emitted, order, held_back, resets), fix, out);
        ubx.flush_events(&mut |ev| match ev {
            Event::Fix(fix) => Self::ubx_fix(vote, suppressed, pending, fix, out),
            Event::Extra(GnssExtra::Sky(k)) => skies.publish(true, k, extra),
            _ => {}
        });
        nmea.flush_extras(
            &mut |fix| Self::nmea_fix(vote, suppressed, pending, fix, out),
            &mut |x| {
                if let GnssExtra::Sky(k) = x {
                    skies.publish(false, k, extra);
                }
            },
        );
        if let Some(p) = pending.take() {
            out(&p);
        }
    }

    fn reset(&mut self) {
        self.ubx.reset();
        self.nmea.reset();
        self.pending = None;
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

    const S: i64 = 1_000_000_000;

    /// NMEA epoch `t` (a GGA at `t` s past 12:00:00) and, with `ubx`, its NAV-PVT 100 ms
    /// later, each in a read of its own; the fixes.
    fn second(d: &mut AutoDecoder, t: i64, ubx: bool, fixes: &mut Vec<GnssFix>) {
        d.push(&gga(&format!("12{:02}{:02}", t / 60, t % 60)), t * S, 0, &mut |f| {
            fixes.push(*f)
        });
        if ubx {
            let frame = ubx_frame(1, 7, &pvt(1000 * t as u32, 3, 1));
            d.push(&frame, t * S + S / 10, 0, &mut |f| fixes.push(*f));
        }
    }

    #[test]
    fn ubx_takes_over_once_it_is_a_stable_majority_and_gives_way_when_it_stops() {
        let mut d = AutoDecoder::new();
        let mut fixes = Vec::new();
        let mut navigated_at = None;
        for t in 0..20 {
            second(&mut d, t, true, &mut fixes);
            if navigated_at.is_none() && d.ubx_navigates() {
                navigated_at = Some(t);
            }
        }
        // The first NMEA epochs are reported (UBX is not yet a stable majority), then UBX
        // alone: every epoch once from then on.
        let at = navigated_at.expect("UBX never took over") as usize;
        // The UBX_MAJORITY-th covered NMEA epoch (epoch 5, or 6 when the NMEA decoder has not
        // learned its cycle's last sentence yet) makes UBX navigate.
        assert!(
            (UBX_MAJORITY as usize - 1..=UBX_MAJORITY as usize).contains(&at),
            "took over at {at} s"
        );
        let nmea_before = fixes.iter().filter(|f| f.protocol == GNSS_PROTOCOL_NMEA).count();
        assert!(nmea_before < UBX_MAJORITY as usize + 1, "{nmea_before} NMEA fixes");
        let after: Vec<u8> = fixes
            .iter()
            .filter(|f| f.stamp.host_ns > (at as i64 + 1) * S)
            .map(|f| f.protocol)
            .collect();
        assert!(after.iter().all(|&p| p == GNSS_PROTOCOL_UBX), "{after:?}");
        assert!(after.len() >= 10);
        // UBX stops: NMEA is reported again once none of the last UBX_WINDOW epochs had UBX.
        let mut more = Vec::new();
        for t in 20..40 {
            second(&mut d, t, false, &mut more);
        }
        d.flush(&mut |f| more.push(*f));
        assert!(!d.ubx_navigates());
        assert!(more.iter().all(|f| f.protocol == GNSS_PROTOCOL_NMEA));
        let first_back = (more[0].stamp.host_ns / S) as u32;
        assert!(first_back <= 20 + UBX_WINDOW + 1, "NMEA back at {first_back} s");
        let seqs: Vec<u64> = fixes.iter().chain(&more).map(|f| f.stamp.seq).collect();
        assert!(
            seqs.windows(2).all(|w| w[1] == w[0] + 1),
            "one numbering for both protocols, no gap for suppressed epochs: {seqs:?}"
        );
    }

    /// Three stray NAV-PVT frames on an NMEA port used to suppress the real NMEA fixes for
    /// ~13 s (each one made UBX "navigate" for the next 10 NMEA epochs).
    #[test]
    fn a_few_stray_ubx_frames_do_not_suppress_nmea() {
        let mut d = AutoDecoder::new();
        let mut fixes = Vec::new();
        for t in 0..20 {
            second(&mut d, t, matches!(t, 3 | 7 | 11), &mut fixes);
            assert!(!d.ubx_navigates(), "UBX took over at {t} s");
        }
        d.flush(&mut |f| fixes.push(*f));
        let nmea = fixes.iter().filter(|f| f.protocol == GNSS_PROTOCOL_NMEA).count();
        assert_eq!(nmea, 20, "every NMEA epoch reported");
        assert_eq!(d.nmea_suppressed(), 0);
    }

    #[test]
    fn an_nmea_port_reports_its_sky_unless_ubx_does() {
        use navsync_shared::time::NS_PER_S;
        let mut d = AutoDecoder::new();
        let mut skies = Vec::new();
        for (i, t) in ["120000.00", "120001.00"].iter().enumerate() {
            let mut bytes = gga(t);
            bytes.extend(nmea("GPGSA,A,3,05,13,,,,,,,,,,,1.6,1.3,0.9"));
            bytes.extend(nmea("GPGSV,1,1,02,05,40,083,46,13,20,200,30"));
            d.push_extras(&bytes, i as i64 * NS_PER_S, 0, &mut |_| {}, &mut |x| {
                if let GnssExtra::Sky(k) = x {
                    skies.push(*k);
                }
            });
        }
        // The first cycle's sky, completed by the second GGA.
        assert_eq!(skies.len(), 1);
        assert_eq!((skies[0].num_sats, skies[0].used(), skies[0].stamp.seq), (2, 2, 0));
        // A UBX sky holds the NMEA ones back for a while; numbered as one stream.
        let mut s = Skies::default();
        let mut out = Vec::new();
        for (from_ubx, host_ns) in [
            (false, 0),
            (true, 10 * NS_PER_S),
            (false, 11 * NS_PER_S),
            (false, 10 * NS_PER_S + UBX_SKY_HOLD_NS + 1),
        ] {
            let mut k = skies[0];
            k.stamp.host_ns = host_ns;
            s.publish(from_ubx, &k, &mut |x| {
                if let GnssExtra::Sky(k) = x {
                    out.push(*k);
                }
            });
        }
        assert_eq!(out.iter().map(|k| k.stamp.seq).collect::<Vec<_>>(), [0, 1, 2]);
        assert_eq!(s.suppressed, 1);
    }

    #[test]
    fn counters_fit_one_health_report() {
        let d = AutoDecoder::new();
        let mut n = 0;
        d.each_counter(&mut |name, _| {
            n += 1;
            assert!(name.len() <= MAX_NAME_LEN, "{name}");
        });
        // The GNSS driver adds its own.
        let total = n + crate::gnss::driver::DRIVER_COUNTERS;
        assert!(
            total <= MAX_COUNTERS,
            "{n} of the decoder and the driver's: {total} > {MAX_COUNTERS}"
        );
        assert!(AutoDecoder::describe("nmea_bad_checksum").is_some());
        assert!(AutoDecoder::describe("ubx_bad_checksum").is_some());
    }
}
