//! Groups NMEA sentences into GNSS epochs.
//!
//! A receiver reports each navigation epoch as a burst of sentences (GGA, RMC, GSA, …), most
//! of which carry the epoch's UTC time of day. [`EpochAssembler`] checks each sentence,
//! decodes the ones that carry fix data, merges those of one time tag into one [`GnssFix`],
//! and emits the fix when the epoch is complete:
//!
//! - as soon as the receiver's **last data sentence of the cycle** arrives, once it has been
//!   learned from the stream: at every time-tag change the last sentence that carried fix
//!   data (formatter and occurrence, e.g. the 2nd GSA, whichever talker) is a candidate, trusted after two
//!   consecutive cycle boundaries agree. An epoch emitted on [`EpochAssembler::flush`] (the
//!   line went idle: the live driver's case when the receiver pauses between bursts) votes
//!   too, when the next epoch's first time tag differs from its own. Sentences without fix data (GSV, TXT, proprietary)
//!   never count, so trailing satellite views do not delay the fix. A sentence once seen
//!   followed by another data sentence of its epoch is never trusted
//!   ([`CycleEnder::followed`]). The learned ender is forgotten when a time-tagged sentence
//!   for the emitted epoch arrives after it — that sentence is counted late and dropped: every
//!   epoch is published exactly once — and when the receiver gains or loses its fix
//!   (receivers change their cycle then);
//! - otherwise when a fix sentence with a **new time tag** arrives, or a fix sentence
//!   repeats within the epoch with the same or no time (a new cycle: e.g. a receiver without
//!   fix sending `$GPGGA,,,,,,0,…` every second);
//! - or on [`EpochAssembler::flush`] (the live driver calls it after a read timeout: the
//!   line went idle, so the burst is over).
//!
//! Sentences without fix data in between epochs open no epoch; the stamp of an epoch is the
//! host time of the first byte of its first data sentence.
//!
//! Each sentence is checked and decoded by [`super::sentence`] (which fields of which
//! sentence, and what the `nmea` crate is used for); this module merges them.
//!
//! Decoding follows gpsd's `driver_nmea0183.c` where NMEA leaves room for interpretation, so
//! that the decoder can be checked against gpsd's regression captures
//! (`drivers/tests/conformance/gpsd_conformance.rs`): a position is taken only from a sentence that
//! flags it valid; DOPs ≥ 99 are "unknown" sentinels; two-digit RMC years 80–99 are 19xx,
//! 00–79 are 20xx; when two sentences of one epoch carry the same quantity, the later one
//! wins. ZDA and GST carry a time of their own that need not be the epoch's (several
//! receivers send ZDA for the next second), so they never close an epoch tagged by a fix
//! sentence: ZDA supplies the date for its own time of day, GST sigmas are used only when
//! GST's time matches the epoch. A ZDA tags an epoch only when it comes first (and a
//! ZDA-only receiver thus yields time-only epochs, mode 0).
//!
//! Fix mode: GSA states it and PGRMZ too; GGA/GNS imply it (3D with an altitude and ≥ 4
//! satellites; with an altitude from ≤ 3 satellites 3D if the previous epoch had a fix, else
//! 2D, as gpsd; 2D without an altitude; no fix when flagged invalid); RMC/GLL only say "valid
//! position", which is 3D if the epoch has an altitude or > 3 satellites, else the dimension
//! of the receiver's previous fix, else 2D. Within an epoch later claims win, except that a
//! 2D claim does not undo a 3D one. `mode` thus means what it means to gpsd clients; that an
//! altitude from ≤ 3 satellites is held, not measured, is in `sats_used`
//! ([`GnssFix::altitude_held`]), which the estimator uses.
//!
//! Dates: RMC and ZDA give a date together with their own time of day; that anchor is carried
//! forward to later epochs (across midnight: a time of day more than 12 h before the anchor's
//! is on the next day). An epoch before the first date has `utc_ns`/`gps_ns` unknown but
//! `tod_ns` known.

use navsync_shared::samples::{FixMode, GnssFix, Stamp, StampSource};
use navsync_shared::time::{NS_PER_S, gps_ns_from_utc_ns};

use super::sentence::{Kind, ModeHint, Reject, Update, check, decode};
use crate::gnss::cycle::CycleEnder;
use crate::gnss::order::{Admit, TimeOrder};

/// Nanoseconds per day.
const NS_PER_DAY: i64 = 86_400 * NS_PER_S;
/// Half a day, ns: a time of day further than this from the date anchor's is on another day.
const HALF_DAY_NS: i64 = NS_PER_DAY / 2;
/// Longest sentence address kept for cycle-ender keys (`GPGGA`, `PGRME`, `PMTK001`).
const ADDR_MAX: usize = 8;
/// Distinct sentence addresses and formatters tracked per epoch for occurrence numbering.
const SEEN_MAX: usize = 40;
/// Distinct (system, PRN) pairs tracked per epoch from GSA.
const PRN_MAX: usize = 64;

/// Counters of [`EpochAssembler`], since creation.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct EpochCounters {
    /// Sentences offered.
    pub sentences: u64,
    /// Sentences whose checksum did not match; dropped.
    pub bad_checksum: u64,
    /// Sentences without a `*hh` checksum, or not starting with `$`/`!`; dropped (gpsd
    /// drops them too).
    pub no_checksum: u64,
    /// Supported sentences rejected by the `nmea` crate from which the lenient decoder could
    /// read nothing either (or a GSA without a valid mode); dropped.
    pub unparsable: u64,
    /// Valid sentences of a type that carries no fix data for us (GSV, TXT, proprietary, AIS).
    pub unsupported: u64,
    /// Supported sentences the `nmea` crate rejected but the lenient field decoder accepted.
    pub lenient: u64,
    /// Fields that were present but malformed (time, number, date); ignored.
    pub bad_fields: u64,
    /// Well-formed values outside what NMEA 0183 allows (negative speed, track ≥ 360°, GGA
    /// quality above 8); the field, or for a quality the fix, dropped.
    pub out_of_range: u64,
    /// Epochs emitted.
    pub epochs: u64,
    /// Epochs emitted on the learned last sentence of the cycle (subset of `epochs`).
    pub ender_emits: u64,
    /// Epochs emitted by [`EpochAssembler::flush`] (subset of `epochs`).
    pub flush_emits: u64,
    /// Time-tagged sentences for an epoch already emitted on the learned ender (the ender
    /// was wrong; it is forgotten and never trusted again). Dropped: the epoch is not
    /// published twice.
    pub late_sentences: u64,
    /// Epochs held back because their time was not after the last one published (the same
    /// time tag again, time going back; `crate::gnss::order::TimeOrder`).
    pub not_after_last: u64,
    /// Times the receiver's time went back for good and the epoch order restarted.
    pub time_resets: u64,
    /// Epochs closed because a time-tagged sentence repeated with the same (or no) time.
    pub repeats: u64,
    /// ZDA/GST sentences for an epoch already emitted (date used, sigmas dropped).
    pub after_epoch: u64,
    /// Epochs whose receiver claimed a fix from 0 satellites; published as no fix.
    pub zero_satellite_fixes: u64,
}

impl EpochCounters {
    /// The counters with short names for a `Health` report (names ≤ 24 bytes).
    pub fn named(&self) -> [(&'static str, u64); 17] {
        [
            ("nmea_sentences_in", self.sentences),
            ("nmea_bad_checksum", self.bad_checksum),
            ("nmea_no_checksum", self.no_checksum),
            ("nmea_unparsable", self.unparsable),
            ("nmea_unsupported", self.unsupported),
            ("nmea_lenient", self.lenient),
            ("nmea_bad_fields", self.bad_fields),
            ("nmea_out_of_range", self.out_of_range),
            ("nmea_epochs", self.epochs),
            ("nmea_ender_emits", self.ender_emits),
            ("nmea_flush_emits", self.flush_emits),
            ("nmea_late_sentences", self.late_sentences),
            ("nmea_repeats", self.repeats),
            ("nmea_after_epoch", self.after_epoch),
            ("nmea_zero_sat_fixes", self.zero_satellite_fixes),
            ("nmea_not_after_last", self.not_after_last),
            ("nmea_time_resets", self.time_resets),
        ]
    }
}

/// Identity of a sentence within a cycle: its address and how many times that address has
/// occurred in the epoch so far (1 = first). Used to learn the receiver's cycle ender.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Key {
    addr: [u8; ADDR_MAX],
    occurrence: u8,
}

impl Key {
    fn addr_of(address: &[u8]) -> [u8; ADDR_MAX] {
        let mut a = [0u8; ADDR_MAX];
        for (o, &b) in a.iter_mut().zip(address) {
            *o = b;
        }
        a
    }
}

/// The epoch being assembled.
#[derive(Debug, Clone, Copy)]
struct Epoch {
    /// The epoch exists (some valid sentence has been seen since the last one was emitted).
    open: bool,
    /// Some decoded sentence has been merged.
    has_data: bool,
    /// The own time of the last ZDA/GST merged (which need not be the epoch's).
    aux_tod_ns: Option<i64>,
    fix: GnssFix,
    /// Time tag, ns since midnight.
    tod_ns: Option<i64>,
    /// The time tag came from a ZDA (no GGA/RMC/GNS/GLL has tagged the epoch yet).
    tod_from_zda: bool,
    /// `fix.mode` was determined by a sentence of this epoch (not implied by RMC/GLL).
    mode_determined: bool,
    /// Addresses seen in this epoch and their counts.
    seen: [([u8; ADDR_MAX], u8); SEEN_MAX],
    n_seen: usize,
    /// The last sentence that carried fix data.
    last_data_key: Option<Key>,
    /// (system, PRN) pairs used according to GSA.
    prns: [(u8, u16); PRN_MAX],
    n_prns: usize,
    /// Largest satellites-used count from GGA/GNS.
    sats_reported: Option<u16>,
}

impl Epoch {
    fn closed() -> Self {
        Self {
            open: false,
            has_data: false,
            aux_tod_ns: None,
            fix: GnssFix::empty(Stamp::host(0, 0, StampSource::Receipt)),
            tod_ns: None,
            tod_from_zda: false,
            mode_determined: false,
            seen: [([0; ADDR_MAX], 0); SEEN_MAX],
            n_seen: 0,
            last_data_key: None,
            prns: [(0, 0); PRN_MAX],
            n_prns: 0,
            sats_reported: None,
        }
    }

    fn start(host_ns: i64) -> Self {
        let mut e = Self::closed();
        e.open = true;
        e.fix.stamp.host_ns = host_ns;
        e
    }

    /// Times `address` has occurred in this epoch.
    fn count_of(&self, address: &[u8]) -> u8 {
        let addr = Key::addr_of(address);
        self.seen[..self.n_seen]
            .iter()
            .find(|(a, _)| *a == addr)
            .map_or(0, |s| s.1)
    }

    /// Records one more occurrence of `address`; returns its key for learning the cycle: the
    /// sentence formatter without the talker (`GSA`, `RMC`; proprietary addresses whole) and
    /// its occurrence among the epoch's sentences of that formatter, so that a receiver
    /// switching talkers with the constellations it uses (`$GNRMC` ↔ `$GPRMC`) keeps its cycle,
    /// while `$GPGSA`, `$GLGSA` are GSA #1 and #2.
    fn note(&mut self, address: &[u8]) -> Key {
        self.bump(Key::addr_of(address));
        let formatter = match address {
            [b'P', ..] => address,
            [_, _, rest @ ..] if address.len() == 5 => rest,
            _ => address,
        };
        // Formatter entries share the table, marked by a leading '*'.
        let mut addr = [0u8; ADDR_MAX];
        addr[0] = b'*';
        for (o, &b) in addr[1..].iter_mut().zip(formatter) {
            *o = b;
        }
        let occurrence = self.bump(addr);
        Key { addr, occurrence }
    }

    /// One more occurrence of `addr` in the table; returns its count.
    fn bump(&mut self, addr: [u8; ADDR_MAX]) -> u8 {
        let n = self.n_seen;
        match self.seen[..n].iter_mut().find(|(a, _)| *a == addr) {
            Some(slot) => {
                slot.1 = slot.1.saturating_add(1);
                slot.1
            }
            None if n < SEEN_MAX => {
                self.seen[n] = (addr, 1);
                self.n_seen += 1;
                1
            }
            None => 1,
        }
    }

    /// Satellites used: the larger of the GGA/GNS count and the GSA PRN count (both can
    /// fall short: GGA per constellation or capped at 12, GSA at 12 PRNs per sentence).
    fn sats_used(&self) -> Option<u16> {
        let gsa = (self.n_prns > 0).then_some(self.n_prns as u16);
        self.sats_reported.max(gsa)
    }

    fn add_prn(&mut self, entry: (u8, u16)) {
        if self.n_prns < PRN_MAX && !self.prns[..self.n_prns].contains(&entry) {
            self.prns[self.n_prns] = entry;
            self.n_prns += 1;
        }
    }

    /// Applies a mode claim (see [`ModeHint`]); `last_dim` is the dimension (2 or 3) of the
    /// receiver's last fix, 0 when unknown.
    fn apply_mode(&mut self, hint: ModeHint, last_dim: u8) {
        match hint {
            // A 2D claim does not downgrade a 3D one determined in the same epoch: GGA/GNS
            // report 3D for an altitude from ≥ 4 satellites, and some receivers (Quectel)
            // send GSA mode 2 alongside (gpsd keeps 3D too). A 3D only assumed from the
            // previous fix (RMC first) does give way.
            ModeHint::Mode(m)
                if m == FixMode::Fix2d as u8 && self.fix.mode == FixMode::Fix3d as u8 && self.mode_determined => {}
            ModeHint::Mode(m) => {
                self.fix.mode = m;
                self.mode_determined = true;
            }
            ModeHint::AltitudeFewSats => {
                let m = if last_dim != 0 { FixMode::Fix3d } else { FixMode::Fix2d };
                self.apply_mode(ModeHint::Mode(m as u8), last_dim);
            }
            ModeHint::Position if !self.mode_determined => {
                let three_d = self.fix.alt_msl_m.is_finite()
                    || self.sats_used().unwrap_or(0) > 3
                    || last_dim == FixMode::Fix3d as u8;
                self.fix.mode = if three_d {
                    FixMode::Fix3d as u8
                } else {
                    FixMode::Fix2d as u8
                };
            }
            // gpsd's "probably 3D": a valid position after a 2D claim in an epoch that has an
            // altitude is 3D (a u-blox sends GLL after its GSA mode 2).
            ModeHint::Position if self.fix.mode == FixMode::Fix2d as u8 && self.fix.alt_msl_m.is_finite() => {
                self.fix.mode = FixMode::Fix3d as u8;
            }
            ModeHint::Position => {}
        }
    }

    /// Merges a decoded sentence (later values replace earlier ones, as in gpsd).
    fn merge(&mut self, u: &Update, last_dim: u8) {
        self.has_data = true;
        if u.aux_tod_ns.is_some() {
            self.aux_tod_ns = u.aux_tod_ns;
        }
        let f = &mut self.fix;
        f.sentences |= u.kind.bit();
        match (u.tod_ns, u.aux_tod_ns) {
            (Some(t), _) => {
                // A coarser tag just before the epoch's finer one is the same epoch
                // ([`same_epoch_coarser_tag`]): the epoch keeps the tag it has.
                if !self.tod_ns.is_some_and(|c| same_epoch_coarser_tag(c, t)) {
                    self.tod_ns = Some(t);
                }
                self.tod_from_zda = false;
            }
            (None, Some(z)) if u.kind == Kind::Zda && self.tod_ns.is_none() => {
                self.tod_ns = Some(z);
                self.tod_from_zda = true;
            }
            _ => {}
        }
        if let Some((lat, lon)) = u.lat_lon {
            f.lat_deg = lat;
            f.lon_deg = lon;
        }
        set(&mut f.alt_msl_m, u.alt_msl_m);
        set(&mut f.geoid_sep_m, u.geoid_sep_m);
        set(&mut f.speed_mps, u.speed_mps);
        set(&mut f.track_deg, u.track_deg);
        set(&mut f.hdop, u.hdop);
        set(&mut f.vdop, u.vdop);
        set(&mut f.pdop, u.pdop);
        // GST refers to the fix at its own time: use it only for that epoch.
        if u.kind != Kind::Gst || u.aux_tod_ns.is_none() || u.aux_tod_ns == self.tod_ns {
            set(&mut f.std_lat_m, u.std_m[0]);
            set(&mut f.std_lon_m, u.std_m[1]);
            set(&mut f.std_alt_m, u.std_m[2]);
        }
        if let Some(q) = u.quality {
            f.quality = q;
        }
        if let Some(n) = u.sats_used {
            self.sats_reported = self.sats_reported.max(Some(n));
        }
        for &prn in &u.gsa_prns[..u.gsa_prn_count] {
            self.add_prn((u.gsa_system, prn));
        }
        if let Some(hint) = u.mode {
            self.apply_mode(hint, last_dim);
        }
    }
}

fn set(dst: &mut f64, v: Option<f64>) {
    if let Some(v) = v {
        *dst = v;
    }
}

/// A known date: `days` since 1970 is the UTC date at time of day `tod_ns`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct DateAnchor {
    days: i64,
    tod_ns: i64,
}

impl DateAnchor {
    /// The date of a time of day near this anchor: a time more than 12 h before the
    /// anchor's is on the next day (midnight rollover), more than 12 h after on the previous.
    fn days_at(&self, tod_ns: i64) -> i64 {
        let delta = tod_ns - self.tod_ns;
        if delta < -HALF_DAY_NS {
            self.days + 1
        } else if delta > HALF_DAY_NS {
            self.days - 1
        } else {
            self.days
        }
    }
}

/// How an epoch came to be emitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Close {
    /// A sentence with another time tag (or a repeated one) started the next epoch.
    NextEpoch,
    /// The learned last sentence of the cycle arrived.
    Ender,
    /// [`EpochAssembler::flush`].
    Flush,
}

/// Sentences → [`GnssFix`] epochs. Pure state machine: no I/O, no clock, no allocation.
#[derive(Debug, Clone)]
pub struct EpochAssembler {
    cur: Epoch,
    /// The last epoch emitted on the learned ender, kept in case late data for it arrive.
    prev: Option<Epoch>,
    date: Option<DateAnchor>,
    /// Dimension (2 or 3) of the last emitted fix, 0 after a no-fix epoch or none yet.
    last_dim: u8,
    /// Time tag of the last emitted epoch.
    last_emitted_tod: Option<i64>,
    /// Own time of the last ZDA/GST merged into the last emitted epoch.
    last_emitted_aux: Option<i64>,
    /// Mode of the last emitted epoch.
    last_mode: u8,
    /// The learned last data sentence of the cycle.
    cycle: CycleEnder<Key>,
    /// The last data sentence and time tag of an epoch emitted on flush: a vote for the cycle
    /// ender once the next epoch's time tag is seen to differ.
    flushed: Option<(Key, i64)>,
    /// The order of the epochs published.
    order: TimeOrder,
    seq: u64,
    counters: EpochCounters,
}

impl Default for EpochAssembler {
    fn default() -> Self {
        Self::new()
    }
}

impl EpochAssembler {
    /// An assembler that knows nothing about the receiver yet.
    pub fn new() -> Self {
        Self {
            cur: Epoch::closed(),
            prev: None,
            date: None,
            last_dim: 0,
            last_emitted_tod: None,
            last_emitted_aux: None,
            last_mode: FixMode::Unknown as u8,
            cycle: CycleEnder::default(),
            flushed: None,
            order: TimeOrder::default(),
            seq: 0,
            counters: EpochCounters::default(),
        }
    }

    /// Counters since creation.
    pub fn counters(&self) -> &EpochCounters {
        &self.counters
    }

    /// The learned last data-carrying sentence of the receiver's cycle (its formatter) and its
    /// occurrence within the cycle, e.g. `("GSA", 2)`; `None` while not (or no longer) known.
    pub fn cycle_ender(&self) -> Option<(&str, u8)> {
        let k = self.cycle.ender()?;
        let len = k.addr.iter().position(|&b| b == 0).unwrap_or(ADDR_MAX);
        Some((core::str::from_utf8(&k.addr[1..len]).unwrap_or("?"), k.occurrence))
    }

    /// The UTC of the epoch being assembled (the last one emitted when none is open or it has
    /// no time tag yet), ns since 1970; `i64::MIN` before a time tag and a date are known.
    pub fn epoch_utc_ns(&self) -> i64 {
        let tod = if self.cur.open { self.cur.tod_ns } else { None }.or(self.last_emitted_tod);
        match (tod, self.date) {
            (Some(t), Some(a)) => a.days_at(t) * NS_PER_DAY + t,
            _ => i64::MIN,
        }
    }

    /// Consumes one sentence (text from `$` to before CR/LF; `host_ns` the host time of its
    /// first byte) and calls `out` for every epoch it completes (0, 1 or 2: the previous
    /// epoch when this sentence starts a new one, this one if it is the cycle ender).
    ///
    /// Emitted fixes have `stamp = Stamp::host(first_byte_host_ns, seq, Receipt)` with `seq`
    /// counting emissions from 0. Every epoch is emitted once: a time-tagged sentence for an
    /// epoch already emitted on a wrongly learned cycle ender is counted late and dropped, and
    /// an epoch whose time is not after the last one emitted is held back.
    pub fn push(&mut self, text: &[u8], host_ns: i64, out: &mut impl FnMut(&GnssFix)) {
        self.counters.sentences += 1;
        let s = match check(text) {
            Ok(s) => s,
            Err(Reject::NoChecksum) => return self.counters.no_checksum += 1,
            Err(Reject::BadChecksum) => return self.counters.bad_checksum += 1,
        };
        let update = match Kind::of_address(s.address) {
            Some(kind) => match decode(kind, &s) {
                Some((u, lenient)) => {
                    self.counters.lenient += u64::from(lenient);
                    self.counters.bad_fields += u64::from(u.bad_fields);
                    self.counters.out_of_range += u64::from(u.out_of_range);
                    Some(u)
                }
                None => {
                    self.counters.unparsable += 1;
                    return;
                }
            },
            None => {
                self.counters.unsupported += 1;
                None
            }
        };
        let Some(u) = update else {
            // A sentence without fix data (GSV, TXT, proprietary) is only counted in the open
            // epoch; it neither opens an epoch nor can become the learned cycle ender, so an
            // epoch is emitted on its last data sentence without waiting for trailing ones.
            if self.cur.open {
                self.cur.note(s.address);
            }
            return;
        };
        if self.route(&u, s.address, out) {
            return;
        }
        if let (Some(days), Some(tod)) = (u.date_days, u.tod_ns.or(u.aux_tod_ns)) {
            self.date = Some(DateAnchor { days, tod_ns: tod });
        }
        if !self.cur.open {
            if u.tod_ns.is_none()
                && u.aux_tod_ns.is_some()
                && (u.aux_tod_ns == self.last_emitted_tod || u.aux_tod_ns == self.last_emitted_aux)
            {
                // A ZDA or GST for the epoch just emitted (sent after the cycle's usual last
                // sentence), or the same ZDA/GST again as the one merged into it: its date is
                // taken, but it does not start an epoch of its own.
                self.counters.after_epoch += 1;
                return;
            }
            self.cur = Epoch::start(host_ns);
        }
        self.cur.merge(&u, self.last_dim);
        let key = self.cur.note(s.address);
        if let Some(before) = self.cur.last_data_key
            && before != key
        {
            // `before` is not the last data sentence of every epoch: never the cycle's ender.
            self.cycle.followed(before);
        }
        self.cur.last_data_key = Some(key);
        // Not before the epoch has its time tag (a sentence reordered ahead of the tagged ones).
        if self.cycle.is_ender(key) && self.cur.tod_ns.is_some() {
            if has_fix(self.cur.fix.mode) == has_fix(self.last_mode) {
                self.emit(Close::Ender, out);
            } else {
                // Receivers change their cycle when they gain or lose the fix (other
                // sentences, another order): the learned ender no longer applies.
                self.forget_ender();
            }
        }
    }

    /// Emits the epoch being assembled, if any. The live driver calls this when the line has
    /// been idle for longer than the gap between sentences of one burst (a read timeout).
    pub fn flush(&mut self, out: &mut impl FnMut(&GnssFix)) {
        if self.cur.open {
            self.emit(Close::Flush, out);
        }
    }

    /// Decides, before a decoded sentence is merged, whether it closes the open epoch; true
    /// when it is late (for the epoch already emitted on the learned ender) and is dropped.
    fn route(&mut self, u: &Update, address: &[u8], out: &mut impl FnMut(&GnssFix)) -> bool {
        if u.kind.is_fix() {
            return self.route_fix(u.tod_ns, address, out);
        } else if let (Kind::Zda, Some(z)) = (u.kind, u.aux_tod_ns) {
            // A ZDA with another time closes an epoch that only a ZDA has tagged.
            if self.cur.open && self.cur.tod_from_zda && self.cur.tod_ns != Some(z) {
                self.emit(Close::NextEpoch, out);
            }
        }
        false
    }

    /// Routing of a fix sentence (GGA, RMC, GNS, GLL) with time tag `t` (if any); true when
    /// it is late.
    fn route_fix(&mut self, t: Option<i64>, address: &[u8], out: &mut impl FnMut(&GnssFix)) -> bool {
        if let (Some((key, flushed_tod)), Some(t)) = (self.flushed, t) {
            self.flushed = None;
            if flushed_tod != t {
                self.cycle.vote(key);
            }
        }
        if self.cur.open {
            match (self.cur.tod_ns, t) {
                (Some(c), Some(t)) if c != t && !same_epoch_coarser_tag(c, t) => {
                    if let (false, Some(k)) = (self.cur.tod_from_zda, self.cur.last_data_key) {
                        self.cycle.vote(k);
                    }
                    self.emit(Close::NextEpoch, out);
                }
                // The same fix sentence again without a new time: the receiver started a new
                // cycle with the same (or no) time tag.
                _ if self.cur.count_of(address) > 0 => {
                    self.counters.repeats += 1;
                    self.emit(Close::NextEpoch, out);
                }
                _ => {}
            }
        }
        let untagged = !self.cur.open || self.cur.tod_ns.is_none();
        if t.is_some() && untagged && self.prev.as_ref().and_then(|p| p.tod_ns) == t {
            self.late();
            return true;
        }
        false
    }

    /// A fix sentence for the epoch last emitted on the learned ender: that sentence was not
    /// the cycle's last after all. It is never trusted again; the late sentence is dropped
    /// (the epoch was published and is not published twice).
    fn late(&mut self) {
        self.counters.late_sentences += 1;
        if let Some(k) = self.prev.as_ref().and_then(|p| p.last_data_key) {
            self.cycle.followed(k);
        }
        self.forget_ender();
    }

    fn forget_ender(&mut self) {
        self.cycle.forget();
        self.flushed = None;
    }

    /// Completes the open epoch and hands it to `out` (epochs without fix data are dropped).
    fn emit(&mut self, how: Close, out: &mut impl FnMut(&GnssFix)) {
        let e = core::mem::replace(&mut self.cur, Epoch::closed());
        self.flushed = match (how, e.last_data_key, e.tod_ns) {
            (Close::Flush, Some(k), Some(tod)) if !e.tod_from_zda => Some((k, tod)),
            _ => None,
        };
        if !e.has_data {
            return;
        }
        self.prev = (how == Close::Ender).then_some(e);
        let mut fix = e.fix;
        if let Some(n) = e.sats_used() {
            fix.sats_used = n;
            if n == 0 && has_fix(fix.mode) {
                // A position computed from no satellite (a receiver's GGA with fix quality 1
                // and 0 satellites used) is not a fix; gpsd reports no fix too.
                fix.mode = FixMode::NoFix as u8;
                self.counters.zero_satellite_fixes += 1;
            }
        }
        if let Some(tod) = e.tod_ns {
            fix.tod_ns = tod;
            if let Some(anchor) = self.date {
                let days = anchor.days_at(tod);
                fix.utc_ns = days * NS_PER_DAY + tod;
                fix.gps_ns = gps_ns_from_utc_ns(fix.utc_ns);
                // Carry the date forward from this epoch (keeps rollovers monotonic).
                self.date = Some(DateAnchor { days, tod_ns: tod });
            }
        }
        velocity(&mut fix);
        self.last_emitted_tod = e.tod_ns;
        self.last_emitted_aux = e.aux_tod_ns;
        self.last_mode = fix.mode;
        self.last_dim = match fix.mode {
            m if m == FixMode::Fix2d as u8 || m == FixMode::Fix3d as u8 => m,
            m if m == FixMode::NoFix as u8 => 0,
            _ => self.last_dim,
        };
        match self.order.admit(fix.utc_ns) {
            Admit::Publish => {}
            Admit::Reset => self.counters.time_resets += 1,
            Admit::HeldBack => {
                self.counters.not_after_last += 1;
                return;
            }
        }
        fix.stamp = Stamp::host(fix.stamp.host_ns, self.seq, StampSource::Receipt);
        self.seq += 1;
        self.counters.epochs += 1;
        match how {
            Close::Ender => self.counters.ender_emits += 1,
            Close::Flush => self.counters.flush_emits += 1,
            Close::NextEpoch => {}
        }
        out(&fix);
    }
}

/// Time tags within this much of each other may be one epoch's, reported at two
/// resolutions: NMEA's usual time field has centiseconds, some receivers stamp one sentence
/// to the millisecond (eXplorist 210: GLL `200620.303`, then GGA and RMC `200620.30`).
const TAG_RESOLUTION_NS: i64 = 10_000_000;

/// Whether a fix sentence tagged `t` belongs to the open epoch tagged `c` although the tags
/// differ: `t` is before `c` by less than [`TAG_RESOLUTION_NS`], i.e. the same instant at a
/// coarser resolution. An epoch of its own there would step time back by a few ms after `c`
/// was published. (A coarser tag just *after* a finer one, `200621.297` then `200621.30`,
/// still opens an epoch, as gpsd reports it: time goes forward.)
fn same_epoch_coarser_tag(c: i64, t: i64) -> bool {
    t < c && c - t < TAG_RESOLUTION_NS
}

/// A 2D or 3D fix.
fn has_fix(mode: u8) -> bool {
    mode == FixMode::Fix2d as u8 || mode == FixMode::Fix3d as u8
}

/// North and east velocity from speed over ground and track (0 when the speed is 0, even if
/// the receiver left the track empty, as receivers do when stationary).
fn velocity(f: &mut GnssFix) {
    if f.speed_mps == 0.0 {
        f.vel_n_mps = 0.0;
        f.vel_e_mps = 0.0;
    } else if f.speed_mps.is_finite() && f.track_deg.is_finite() {
        let (s, c) = f.track_deg.to_radians().sin_cos();
        f.vel_n_mps = f.speed_mps * c;
        f.vel_e_mps = f.speed_mps * s;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use navsync_shared::samples::{SENTENCE_GGA, SENTENCE_GSA, SENTENCE_RMC, SENTENCE_ZDA};
    use navsync_shared::time::{Civil, format_rfc3339_ms, utc_ns_from_civil};

    /// `$<body>*hh` with the right checksum.
    fn nmea(body: &str) -> String {
        let sum = body.bytes().fold(0u8, |c, b| c ^ b);
        format!("${body}*{sum:02X}")
    }

    /// Feeds sentences (host time = index × 1 ms) and returns the fixes, each with the index
    /// of the sentence whose push emitted it.
    fn run(asm: &mut EpochAssembler, sentences: &[String]) -> Vec<(usize, GnssFix)> {
        let mut out = Vec::new();
        for (i, s) in sentences.iter().enumerate() {
            asm.push(s.as_bytes(), i as i64 * 1_000_000, &mut |f| out.push((i, *f)));
        }
        out
    }

    fn flush(asm: &mut EpochAssembler) -> Vec<GnssFix> {
        let mut out = Vec::new();
        asm.flush(&mut |f| out.push(*f));
        out
    }

    fn gga(hhmmss: &str) -> String {
        nmea(&format!(
            "GPGGA,{hhmmss},4807.0381,N,01131.0004,E,1,08,0.9,545.437,M,46.9,M,,"
        ))
    }

    fn rmc(hhmmss: &str, ddmmyy: &str) -> String {
        nmea(&format!(
            "GPRMC,{hhmmss},A,4807.0381,N,01131.0004,E,010.0,090.0,{ddmmyy},,,A"
        ))
    }

    fn gsa() -> String {
        nmea("GPGSA,A,3,04,05,,09,12,,,24,,,,,2.5,1.3,2.1")
    }

    fn utc(year: i64, month: u32, day: u32, hour: u32, minute: u32, second: u32, ms: u32) -> i64 {
        utc_ns_from_civil(&Civil {
            year,
            month,
            day,
            hour,
            minute,
            second,
            nanos: ms * 1_000_000,
        })
    }

    /// Checksum-valid values outside NMEA 0183's ranges (seen from a misbehaving receiver:
    /// speed -11.5 m/s, track 999.4°, GGA quality 9) were published as they came.
    #[test]
    fn values_outside_the_standard_are_counted_and_dropped() {
        let mut asm = EpochAssembler::new();
        let sentences = [
            nmea("GPGGA,123519,4807.0381,N,01131.0004,E,1,08,0.9,545.437,M,46.9,M,,"),
            nmea("GPRMC,123519,A,4807.0381,N,01131.0004,E,-22.35,999.4,230394,,,A"),
            nmea("GPGGA,123520,4807.0381,N,01131.0004,E,9,08,0.9,545.437,M,46.9,M,,"),
            nmea("GPRMC,123520,A,4807.0381,N,01131.0004,E,010.0,360.0,230394,,,A"),
            nmea("GPVTG,-5.0,T,,M,-3.0,N,,K,A"),
            gga("123521"),
            rmc("123521", "230394"),
        ];
        let mut fixes: Vec<GnssFix> = run(&mut asm, &sentences).into_iter().map(|(_, f)| f).collect();
        fixes.extend(flush(&mut asm));
        assert_eq!(asm.counters().out_of_range, 6, "{:?}", asm.counters());
        let by_time = |hhmmss: u32| {
            fixes
                .iter()
                .find(|f| f.utc_ns.rem_euclid(86_400_000_000_000) / 1_000_000_000 == i64::from(hhmmss))
                .copied()
        };
        // 12:35:19: the position stands, speed and track are dropped.
        let f = by_time(12 * 3600 + 35 * 60 + 19).expect("the 12:35:19 fix");
        assert!(f.mode >= 2 && f.lat_deg.is_finite());
        assert!(f.speed_mps.is_nan() && f.track_deg.is_nan(), "{f:?}");
        // 12:35:20: quality 9 is no fix; the 360° track is dropped, the speed kept.
        let f = by_time(12 * 3600 + 35 * 60 + 20).expect("the 12:35:20 epoch");
        assert!(f.track_deg.is_nan(), "{f:?}");
        assert_eq!(
            (f.mode, f.quality),
            (1, u8::MAX),
            "quality 9 is no fix, not published: {f:?}"
        );
        // 12:35:21: all in range, all used.
        let f = by_time(12 * 3600 + 35 * 60 + 21).expect("the 12:35:21 fix");
        assert_eq!(f.quality, 1);
        assert!(
            (f.track_deg - 90.0).abs() < 1e-9 && (f.speed_mps - 10.0 * 0.514444).abs() < 1e-3,
            "{f:?}"
        );
    }

    #[test]
    fn checksums_are_verified() {
        let mut asm = EpochAssembler::new();
        let good = gga("123519");
        let mut bad = good.clone();
        bad.replace_range(8..9, "9");
        let lower = good
            .to_lowercase()
            .replace("$gpgga", "$GPGGA")
            .replace("n,", "N,")
            .replace("e,", "E,");
        let missing = good[..good.len() - 3].to_string();
        let out = run(&mut asm, &[bad, missing, "$".into(), "garbage".into(), lower]);
        assert!(out.is_empty());
        let c = *asm.counters();
        assert_eq!(c.bad_checksum, 1);
        assert_eq!(c.no_checksum, 3);
        assert_eq!(flush(&mut asm).len(), 1, "lower-case hex checksum is accepted");
    }

    #[test]
    fn gga_rmc_fields_and_units() {
        let mut asm = EpochAssembler::new();
        run(&mut asm, &[gga("123519.25"), rmc("123519.25", "230394"), gsa()]);
        let f = flush(&mut asm);
        assert_eq!(f.len(), 1);
        let f = f[0];
        assert!((f.lat_deg - (48.0 + 7.0381 / 60.0)).abs() < 1e-12);
        assert!((f.lon_deg - (11.0 + 31.0004 / 60.0)).abs() < 1e-12);
        assert_eq!(f.alt_msl_m, 545.437, "altitude kept to the mm (the crate has f32)");
        assert_eq!(f.geoid_sep_m, 46.9);
        assert_eq!(f.speed_mps, 10.0 * 1852.0 / 3600.0);
        assert_eq!(f.track_deg, 90.0);
        assert!((f.vel_e_mps - f.speed_mps).abs() < 1e-12 && f.vel_n_mps.abs() < 1e-12);
        assert_eq!(
            (f.hdop, f.pdop, f.vdop),
            (1.3, 2.5, 2.1),
            "GSA DOPs win over GGA's (later)"
        );
        assert_eq!(f.sats_used, 8, "GGA count (8) over GSA PRNs (5)");
        assert_eq!((f.mode, f.quality), (3, 1));
        assert_eq!(f.sentences, SENTENCE_GGA | SENTENCE_RMC | SENTENCE_GSA);
        assert_eq!(f.tod_ns, (12 * 3600 + 35 * 60 + 19) * NS_PER_S + 250_000_000);
        assert_eq!(f.utc_ns, utc(1994, 3, 23, 12, 35, 19, 250));
        assert_eq!(format_rfc3339_ms(f.utc_ns), "1994-03-23T12:35:19.250Z");
        assert_eq!(f.gps_ns, gps_ns_from_utc_ns(f.utc_ns));
        assert_eq!(
            f.gps_ns - f.utc_ns,
            (9 - 315_964_800) * NS_PER_S,
            "9 leap seconds in March 1994"
        );
        assert_eq!(f.stamp.source(), StampSource::Receipt);
    }

    #[test]
    fn epoch_closes_on_new_time_and_stamps_its_first_byte() {
        let mut asm = EpochAssembler::new();
        let out = run(
            &mut asm,
            &[
                rmc("000001", "010125"),
                gga("000001"),
                rmc("000002", "010125"),
                gga("000002"),
            ],
        );
        assert_eq!(out.len(), 1);
        let (emitted_at, f) = out[0];
        assert_eq!(emitted_at, 2, "emitted when the next time tag arrives");
        assert_eq!(f.stamp.host_ns, 0, "host time of the epoch's first sentence");
        assert_eq!(f.stamp.seq, 0);
        let last = flush(&mut asm);
        assert_eq!(last[0].stamp.host_ns, 2_000_000);
        assert_eq!(last[0].stamp.seq, 1);
        assert_eq!(asm.counters().flush_emits, 1);
    }

    #[test]
    fn last_sentence_of_cycle_is_learned() {
        let mut asm = EpochAssembler::new();
        let mut sentences = Vec::new();
        for s in 10..16 {
            let t = format!("1200{s}");
            sentences.extend([rmc(&t, "150326"), nmea("GPGSV,1,1,01,01,40,083,46"), gga(&t), gsa()]);
            sentences.push(nmea("GPGSV,1,1,01,01,40,083,46"));
        }
        let out = run(&mut asm, &sentences);
        // Cycles 1 and 2 close on the next RMC; both vote GSA #1 (the last sentence with fix
        // data; GSV carries none), so from cycle 3 on each epoch is emitted on its own GSA.
        let emitted_at: Vec<usize> = out.iter().map(|o| o.0).collect();
        assert_eq!(emitted_at, vec![5, 10, 13, 18, 23, 28]);
        assert_eq!(asm.cycle_ender(), Some(("GSA", 1)));
        assert_eq!(asm.counters().ender_emits, 4);
        assert!(flush(&mut asm).is_empty(), "nothing left over");
        let times: Vec<i64> = out.iter().map(|o| o.1.utc_ns).collect();
        assert!(times.windows(2).all(|w| w[1] - w[0] == NS_PER_S));
    }

    #[test]
    fn the_cycle_is_learned_from_bursts_flushed_by_the_idle_line() {
        // The live driver's case: each burst is followed by silence, so every epoch is emitted
        // on flush until the ender is known; then on its last data sentence.
        let mut asm = EpochAssembler::new();
        let mut emitted = Vec::new();
        for s in 10..16 {
            let t = format!("1200{s}");
            let burst = [rmc(&t, "150326"), gga(&t), gsa(), nmea("GPGSV,1,1,01,01,40,083,46")];
            let mut in_burst = 0;
            for b in &burst {
                asm.push(b.as_bytes(), 0, &mut |_| in_burst += 1);
            }
            let mut flushed = 0;
            asm.flush(&mut |_| flushed += 1);
            emitted.push((in_burst, flushed));
        }
        // Bursts 1 and 2 are flushed; the first time tags of bursts 2 and 3 vote GSA #1, so
        // burst 3 on is emitted on its GSA.
        assert_eq!(emitted, [(0, 1), (0, 1), (1, 0), (1, 0), (1, 0), (1, 0)]);
        assert_eq!(asm.cycle_ender(), Some(("GSA", 1)));
        assert_eq!((asm.counters().ender_emits, asm.counters().flush_emits), (4, 2));
    }

    #[test]
    fn late_data_never_publish_an_epoch_twice() {
        let mut asm = EpochAssembler::new();
        let mut sentences = Vec::new();
        for s in 10..14 {
            let t = format!("1200{s}");
            sentences.extend([rmc(&t, "150326"), gga(&t)]);
        }
        // The ender (GGA) is learned; now the receiver adds a GLL after it.
        sentences.extend([rmc("120014", "150326"), gga("120014")]);
        sentences.push(nmea("GPGLL,4807.0382,N,01131.0005,E,120014,A,A"));
        let out = run(&mut asm, &sentences);
        let rest = flush(&mut asm);
        let last_early = out
            .last()
            .map(|o| o.1)
            .unwrap_or_else(|| GnssFix::empty(Stamp::host(0, 0, StampSource::Unknown)));
        assert_eq!(last_early.sentences, SENTENCE_RMC | SENTENCE_GGA);
        assert_eq!(asm.counters().late_sentences, 1);
        assert_eq!(asm.cycle_ender(), None, "forgotten");
        assert!(rest.is_empty(), "the epoch of 12:00:14 was published once: {rest:?}");
        // GGA was followed once: the next epochs close when the next one begins.
        let mut more = Vec::new();
        for s in 15..19 {
            let t = format!("1200{s}");
            more.extend([
                rmc(&t, "150326"),
                gga(&t),
                nmea(&format!("GPGLL,4807.0382,N,01131.0005,E,{t},A,A")),
            ]);
        }
        let out = run(&mut asm, &more);
        assert_eq!(asm.cycle_ender(), Some(("GLL", 1)), "GLL, never followed, is learned");
        let times: Vec<i64> = out.iter().map(|o| o.1.utc_ns).collect();
        assert!(times.windows(2).all(|w| w[0] < w[1]), "{times:?}");
    }

    #[test]
    fn date_rolls_over_at_midnight() {
        let mut asm = EpochAssembler::new();
        let mut out = run(
            &mut asm,
            &[
                rmc("235959.50", "311224"),
                gga("235959.50"),
                gga("000000.50"),
                gga("000001.50"),
            ],
        );
        out.extend(flush(&mut asm).into_iter().map(|f| (0, f)));
        let times: Vec<String> = out.iter().map(|o| format_rfc3339_ms(o.1.utc_ns)).collect();
        assert_eq!(
            times,
            [
                "2024-12-31T23:59:59.500Z",
                "2025-01-01T00:00:00.500Z",
                "2025-01-01T00:00:01.500Z"
            ]
        );
        assert_eq!(out[1].1.tod_ns, NS_PER_S / 2);
    }

    #[test]
    fn zda_ahead_of_the_fix_dates_it_across_midnight() {
        // mr-350p style: the ZDA for the next second closes each cycle.
        let mut asm = EpochAssembler::new();
        let out = run(
            &mut asm,
            &[gga("235959"), nmea("GPZDA,000000.000,01,01,2025,,"), gga("000000")],
        );
        assert_eq!(out.len(), 1);
        assert_eq!(format_rfc3339_ms(out[0].1.utc_ns), "2024-12-31T23:59:59.000Z");
        assert_eq!(format_rfc3339_ms(flush(&mut asm)[0].utc_ns), "2025-01-01T00:00:00.000Z");
    }

    #[test]
    fn epochs_before_the_first_date_have_time_of_day_only() {
        let mut asm = EpochAssembler::new();
        run(&mut asm, &[gga("101010")]);
        let f = flush(&mut asm)[0];
        assert_eq!((f.utc_ns, f.gps_ns), (i64::MIN, i64::MIN));
        assert_eq!(f.tod_ns, 36_610 * NS_PER_S);
    }

    #[test]
    fn zda_only_receiver_gives_time_only_epochs() {
        let mut asm = EpochAssembler::new();
        let out = run(
            &mut asm,
            &[
                nmea("GPZDA,160012.71,11,03,2004,-1,00"),
                nmea("GPZDA,160013.71,11,03,2004,-1,00"),
            ],
        );
        assert_eq!(out.len(), 1);
        let f = out[0].1;
        assert_eq!(format_rfc3339_ms(f.utc_ns), "2004-03-11T16:00:12.710Z");
        assert_eq!((f.mode, f.sentences), (FixMode::Unknown as u8, SENTENCE_ZDA));
        assert!(f.lat_deg.is_nan());
    }

    #[test]
    fn invalid_fixes_give_no_position() {
        let mut asm = EpochAssembler::new();
        run(
            &mut asm,
            &[
                nmea("GPRMC,001902.00,V,4807.0381,N,01131.0004,E,,,020211,,,N"),
                nmea("GPGGA,001902.00,4807.0381,N,01131.0004,E,0,00,99.99,,,,,,"),
                nmea("GPGSA,A,1,,,,,,,,,,,,,99.99,99.99,99.99"),
            ],
        );
        let f = flush(&mut asm)[0];
        assert_eq!(f.mode, FixMode::NoFix as u8);
        assert!(f.lat_deg.is_nan() && f.hdop.is_nan() && f.pdop.is_nan());
        assert_eq!(f.utc_ns, i64::MIN, "RMC with status V gives no date");
        assert_eq!(f.quality, 0);
    }

    #[test]
    fn a_fix_from_no_satellite_is_no_fix() {
        // A Hemisphere receiver's GGA: fix quality 1, 0 satellites used.
        let mut asm = EpochAssembler::new();
        run(
            &mut asm,
            &[nmea("GPGGA,120000,4807.0381,N,01131.0004,E,1,00,2.0,545.4,M,46.9,M,,")],
        );
        let f = flush(&mut asm)[0];
        assert_eq!((f.mode, f.sats_used), (FixMode::NoFix as u8, 0));
        assert!(!f.has_position());
        assert_eq!(asm.counters().zero_satellite_fixes, 1);
    }

    #[test]
    fn mode_rules() {
        // 3 satellites: altitude held, 2D even though GGA has one.
        let mut asm = EpochAssembler::new();
        run(
            &mut asm,
            &[nmea("GPGGA,120000,4807.0381,N,01131.0004,E,1,03,2.0,545.4,M,46.9,M,,")],
        );
        assert_eq!(flush(&mut asm)[0].mode, 2);
        // RMC alone after a 3D epoch keeps the dimension; a GSA claiming 2D with no
        // satellite is ignored.
        let mut asm = EpochAssembler::new();
        run(
            &mut asm,
            &[
                gga("120000"),
                rmc("120001", "010125"),
                nmea("GPGSA,A,2,,,,,,,,,,,,,50.0,50.0,50.0"),
            ],
        );
        let f = flush(&mut asm)[0];
        assert_eq!((f.mode, f.pdop), (3, 50.0));
        // GGA 3D then GSA mode 2 with 7 satellites and a VDOP (Quectel): stays 3D.
        let mut asm = EpochAssembler::new();
        run(
            &mut asm,
            &[gga("120000"), nmea("GPGSA,A,2,06,07,11,19,22,28,30,,,,,,1.4,1.1,0.8,1")],
        );
        let f = flush(&mut asm)[0];
        assert_eq!((f.mode, f.sats_used), (3, 8));
        // An altitude from 3 satellites after a fix: 3D as gpsd says, the altitude held.
        let mut asm = EpochAssembler::new();
        let three_sats = |t: &str| nmea(&format!("GPGGA,{t},4807.0381,N,01131.0004,E,1,03,2.0,545.4,M,46.9,M,,"));
        run(
            &mut asm,
            &[gga("120000"), rmc("120001", "010125"), three_sats("120001")],
        );
        let f = flush(&mut asm)[0];
        assert_eq!((f.mode, f.sats_used, f.altitude_held()), (3, 3, true));
        // ... and on the first epoch of a fix (after no fix) 2D, then 3D (gpsd's no-downgrade).
        let mut asm = EpochAssembler::new();
        let no_fix = nmea("GPGGA,120000,4807.0381,N,01131.0004,E,0,00,,,M,,M,,");
        let out = run(
            &mut asm,
            &[no_fix, three_sats("120001"), three_sats("120002"), gga("120003")],
        );
        let modes: Vec<u8> = out
            .iter()
            .map(|o| o.1.mode)
            .chain(flush(&mut asm).iter().map(|f| f.mode))
            .collect();
        assert_eq!(modes, vec![1, 2, 3, 3]);
        // PGRMZ: altitude in feet and explicit dimension.
        let mut asm = EpochAssembler::new();
        run(
            &mut asm,
            &[nmea("GPGLL,4807.0381,N,01131.0004,E,120000,A"), nmea("PGRMZ,48,f,3")],
        );
        let f = flush(&mut asm)[0];
        assert_eq!((f.mode, f.alt_msl_m), (3, 48.0 * 0.3048));
    }

    #[test]
    fn gsa_counts_distinct_satellites_over_systems() {
        let mut asm = EpochAssembler::new();
        run(
            &mut asm,
            &[
                nmea("GNGNS,043539.00,4333.190206,N,00127.618380,E,AAAAN,,1.3,250.8,50.0,,,S"),
                nmea("GNGSA,A,3,02,08,10,23,27,,,,,,,,1.6,1.3,0.9,1"),
                nmea("GNGSA,A,3,65,66,73,81,82,,,,,,,,1.6,1.3,0.9,2"),
                nmea("GNGSA,A,3,02,08,,,,,,,,,,,1.6,1.3,0.9,4"),
                nmea("GNGSA,A,3,02,08,10,23,27,,,,,,,,1.6,1.3,0.9,1"),
            ],
        );
        let f = flush(&mut asm)[0];
        assert_eq!(f.sats_used, 12, "5 GPS + 5 GLONASS + 2 BeiDou, repeats not counted");
        assert_eq!(f.mode, 3);
        // A 24-PRN GSA (Navior CH-4701) would panic the nmea crate: decoded leniently.
        let mut asm = EpochAssembler::new();
        run(
            &mut asm,
            &[nmea("GPGSA,A,3,27,23,13,07,25,,,,,,,,,,,,,,,,,,,,07.9,06.0,05.2")],
        );
        assert_eq!(asm.counters().lenient, 1);
        let f = flush(&mut asm)[0];
        assert_eq!((f.mode, f.sats_used, f.pdop, f.hdop, f.vdop), (3, 5, 7.9, 6.0, 5.2));
    }

    #[test]
    fn vtg_gst_and_lenient_gga() {
        let mut asm = EpochAssembler::new();
        run(
            &mut asm,
            &[
                // Empty fix quality: the crate rejects it, gpsd reads the position anyway.
                nmea("GPGGA,120000.00,4807.0381,N,01131.0004,E,,05,1.1,100.0,M,,M,,"),
                nmea("GPVTG,,T,,M,,N,36.0,K,A"),
                nmea("GPGST,120000.00,1.0,2.0,1.5,30.0,1.8,1.6,3.2"),
                nmea("GPGST,115959.00,9.0,9.0,9.0,9.0,9.0,9.0,9.0"),
            ],
        );
        let f = flush(&mut asm)[0];
        assert_eq!(asm.counters().lenient, 1);
        assert_eq!((f.lat_deg.is_finite(), f.quality), (true, u8::MAX));
        assert_eq!(f.speed_mps, 10.0, "km/h used when knots are empty");
        assert!(f.track_deg.is_nan() && f.vel_n_mps.is_nan());
        assert_eq!(
            (f.std_lat_m, f.std_lon_m, f.std_alt_m),
            (1.8, 1.6, 3.2),
            "GST of another time ignored"
        );
        let mut asm = EpochAssembler::new();
        run(
            &mut asm,
            &[gga("120000"), nmea("GPVTG,054.7,T,034.4,M,005.5,N,010.2,K,N")],
        );
        assert!(flush(&mut asm)[0].speed_mps.is_nan(), "VTG mode N not used");
    }

    #[test]
    fn repeated_untimed_cycles_are_separate_epochs() {
        // Quectel losing the fix: no time at all, one epoch per cycle.
        let mut asm = EpochAssembler::new();
        let cycle = [nmea("GPGGA,,,,,,0,,,,,,,,"), nmea("GPRMC,,V,,,,,,,,,,N")];
        let out = run(
            &mut asm,
            &[cycle[0].clone(), cycle[1].clone(), cycle[0].clone(), cycle[1].clone()],
        );
        assert_eq!(out.len(), 1);
        assert_eq!((out[0].1.mode, out[0].1.tod_ns), (FixMode::NoFix as u8, -1));
        assert_eq!(asm.counters().repeats, 1);
    }

    #[test]
    fn counter_names_fit_health_slots() {
        for (name, _) in EpochCounters::default().named() {
            assert!(name.len() <= 24, "{name}");
        }
    }

    /// xorshift64 for reproducible pseudo-random input.
    fn next(x: &mut u64) -> u64 {
        *x ^= *x << 13;
        *x ^= *x >> 7;
        *x ^= *x << 17;
        *x
    }

    #[test]
    fn random_bytes_never_panic() {
        let mut asm = EpochAssembler::new();
        let mut x = 0x2545_F491_4F6C_DD1D_u64;
        let alphabet = b"$!*,.0123456789ABCDEFGNPRSTVWZ-\x00\xff";
        let mut buf = Vec::with_capacity(128);
        for _ in 0..20_000 {
            buf.clear();
            let len = (next(&mut x) % 120) as usize;
            for _ in 0..len {
                let r = next(&mut x);
                buf.push(if r.is_multiple_of(3) {
                    (r >> 8) as u8
                } else {
                    alphabet[(r >> 8) as usize % alphabet.len()]
                });
            }
            asm.push(&buf, 0, &mut |_| {});
        }
        assert_eq!(asm.counters().sentences, 20_000);
    }

    #[test]
    fn mutated_sentences_with_valid_checksums_never_panic() {
        // Valid checksums so that mutations reach the nmea crate and the field decoders.
        let seeds = [
            "GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
            "GPRMC,225446.33,A,4916.45,N,12311.12,W,000.5,054.7,191194,020.3,E,A",
            "GNGNS,224749.00,3333.4268304,N,11153.3538273,W,D,19,0.6,406.110,-26.294,6.0,0138,S,",
            "GPVTG,054.7,T,034.4,M,005.5,N,010.2,K,A",
            "GNGSA,A,3,13,12,22,19,08,21,,,,,,,1.05,0.64,0.83,4",
            "GPGST,172814.0,0.006,0.023,0.020,273.6,0.023,0.020,0.031",
            "GPZDA,160012.71,11,03,2004,-1,00",
            "GPGLL,4916.45,N,12311.12,W,225444,A,A",
            "PGRMZ,246,f,3",
        ];
        let junk = b",,,.-9AZNSEW*$0123456789";
        let mut asm = EpochAssembler::new();
        let mut x = 0x9E37_79B9_7F4A_7C15_u64;
        let mut emitted = 0u64;
        for round in 0..30_000 {
            let mut body = seeds[round % seeds.len()].as_bytes().to_vec();
            for _ in 0..=(next(&mut x) % 4) {
                let r = next(&mut x);
                let at = (r as usize >> 8) % (body.len() + 1);
                let b = junk[(r >> 32) as usize % junk.len()];
                match r % 4 {
                    0 if at < body.len() => body[at] = b,
                    1 => body.insert(at, b),
                    2 if at < body.len() => {
                        body.remove(at);
                    }
                    _ => body.extend(std::iter::repeat_n(b',', (r % 16) as usize)),
                }
            }
            let body = String::from_utf8_lossy(&body).into_owned();
            let s = nmea(&body);
            asm.push(s.as_bytes(), round as i64, &mut |f| {
                emitted += 1;
                assert!(f.mode <= 3);
                assert!(f.lat_deg.is_nan() || f.lat_deg.abs() <= 90.0);
                assert!(f.lon_deg.is_nan() || f.lon_deg.abs() <= 180.0);
            });
        }
        assert!(emitted > 0);
        assert_eq!(asm.counters().bad_checksum, 0);
    }
}
