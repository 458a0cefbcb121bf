//! Groups NMEA sentences into GNSS epochs.
//!
//! A receiver reports each navigation epoch as a burst of sentences (GGA, RMC, GSA, …), most
//! of which carry the epoch's UTC time of day. [`EpochAssembler`] checks each sentence,
//! decodes the ones that carry fix data, merges those of one time tag into one [`GnssFix`],
//! and emits the fix when the epoch is complete:
//!
//! - as soon as the receiver's **last sentence of the cycle** arrives, once that sentence has
//!   been learned from the stream (the sentence just before a time-tag change, seen at two
//!   consecutive cycle boundaries);
//! - otherwise when a sentence with a **new time tag** arrives (or a time-tagged sentence
//!   repeats within the epoch: the receiver started a new cycle with the same time);
//! - or on [`EpochAssembler::flush`] (the live driver calls it after a read timeout: the
//!   line went idle, so the burst is over).
//!
//! # Sources of each field (NMEA 0183 v4.11 field numbers, 1 = first field after the address)
//!
//! | Sentence | Used fields |
//! |---|---|
//! | GGA | 1 UTC hhmmss.ss, 2–5 lat/lon ddmm.mm N/S dddmm.mm E/W, 6 quality (0 invalid), 7 satellites used, 8 HDOP, 9 MSL altitude m, 11 geoid separation m |
//! | RMC | 1 UTC, 2 status A/D valid V invalid, 3–6 lat/lon, 7 speed over ground knots, 8 track ° true, 9 date ddmmyy, 12 FAA mode |
//! | GNS | 1 UTC, 2–5 lat/lon, 6 mode per constellation (first char used, N invalid), 7 satellites, 8 HDOP, 9 MSL altitude m, 10 geoid separation m, 13 nav status (U/V unusable) |
//! | VTG | 1 track ° true, 5 speed knots (7 km/h when knots empty), 9 FAA mode (E/N: not used) |
//! | GSA | 2 mode 1 none/2 2D/3 3D, 3–14 PRNs used, 15 PDOP, 16 HDOP, 17 VDOP, 18 system ID (NMEA 4.11) |
//! | GST | 1 UTC of the fix it refers to, 6/7/8 1-σ latitude/longitude/altitude error m |
//! | ZDA | 1 UTC, 2 day, 3 month, 4 four-digit year |
//! | GLL | 1–4 lat/lon, 5 UTC, 6 status A/V, 7 FAA mode |
//!
//! Decoding follows gpsd's `driver_nmea0183.c` where NMEA leaves room for interpretation, so
//! that the decoder can be checked against gpsd's regression captures
//! (`drivers/tests/gpsd_conformance.rs`): a position is taken only from a sentence that
//! flags it valid; DOPs ≥ 99 are "unknown" sentinels; two-digit RMC years 80–99 are 19xx,
//! 00–79 are 20xx; when two sentences of one epoch carry the same quantity, the later one
//! wins. ZDA and GST carry a time of their own that need not be the epoch's (several
//! receivers send ZDA for the next second), so they never open or close an epoch: ZDA
//! supplies the date for its own time of day, GST sigmas are used only when GST's time
//! matches the epoch.
//!
//! Sentences are checked and split with the `nmea` crate, whose typed output is used for
//! what it represents exactly (coordinates, fix quality, satellite counts, status and mode
//! flags, PRN lists, ZDA date). Quantities the crate stores as `f32` (altitudes, DOPs, speed,
//! track, sigmas) and the time of day (which the crate converts through a float) are read
//! from the checksummed sentence text as `f64` / integer nanoseconds. Sentences the crate
//! rejects although their checksum is right (non-standard field formats that gpsd accepts,
//! e.g. an empty GGA quality, a 24-PRN GSA, a four-letter GNS mode) are decoded from the text
//! alone and counted in [`EpochCounters::lenient`].
//!
//! Dates: RMC and ZDA give a date together with their own time of day; that anchor is carried
//! forward to later epochs (across midnight: a time of day more than 12 h before the anchor's
//! is on the next day). An epoch before the first date has `utc_ns`/`gps_ns` unknown but
//! `tod_ns` known.

use navsync_shared::samples::{
    FixMode, GnssFix, SENTENCE_GGA, SENTENCE_GLL, SENTENCE_GNS, SENTENCE_GSA, SENTENCE_GST, SENTENCE_RMC,
    SENTENCE_VTG, SENTENCE_ZDA, Stamp, StampSource,
};
use navsync_shared::time::{NS_PER_S, civil_from_days, days_from_civil, gps_ns_from_utc_ns};
use nmea::ParseResult;
use nmea::sentences::gns::NavigationStatus;
use nmea::sentences::gsa::GsaMode2;
use nmea::sentences::rmc::RmcStatusOfFix;
use nmea::sentences::{FaaMode, FixType};

/// Nanoseconds per day.
const NS_PER_DAY: i64 = 86_400 * NS_PER_S;
/// Half a day, ns: a time of day further than this from the date anchor's is on another day.
const HALF_DAY_NS: i64 = NS_PER_DAY / 2;
/// Knots to m/s (1 kn = 1852 m/h).
const KNOTS_TO_MPS: f64 = 1852.0 / 3600.0;
/// km/h to m/s.
const KMH_TO_MPS: f64 = 1.0 / 3.6;
/// DOP values at or above this are receivers' "unknown" sentinels (99.9, 99.99).
const DOP_SENTINEL: f64 = 99.0;
/// Cycle boundaries at which the same sentence must be last before it is trusted as the
/// receiver's cycle ender.
const ENDER_VOTES: u8 = 2;
/// Longest sentence address kept for cycle-ender keys (`GPGGA`, `PGRME`, `PMTK001`).
const ADDR_MAX: usize = 8;
/// Distinct sentence addresses tracked per epoch for occurrence numbering.
const SEEN_MAX: usize = 24;
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
    /// Supported sentences whose fields could not be decoded; dropped.
    pub unparsable: u64,
    /// Valid sentences of a type that carries no fix data for us (GSV, TXT, proprietary, AIS).
    pub unsupported: u64,
    /// Supported sentences the `nmea` crate rejected but the lenient field decoder accepted.
    pub lenient: u64,
    /// Fix fields that were present but invalid (bad date, out-of-range coordinate); ignored.
    pub bad_fields: u64,
    /// Epochs emitted.
    pub epochs: u64,
    /// Epochs emitted on the learned last sentence of the cycle (subset of `epochs`).
    pub ender_emits: u64,
    /// Epochs emitted by [`EpochAssembler::flush`] (subset of `epochs`).
    pub flush_emits: u64,
    /// Time-tagged sentences for an epoch already emitted on the learned ender (the ender
    /// was wrong; it is forgotten and relearned). The late data start a new epoch.
    pub late_sentences: u64,
    /// Epochs closed because a time-tagged sentence repeated with the same (or no) time.
    pub repeats: u64,
}

impl EpochCounters {
    /// The counters with short names for a `Health` report (names ≤ 24 bytes).
    pub fn named(&self) -> [(&'static str, u64); 12] {
        [
            ("nmea_sentences_in", self.sentences),
            ("nmea_bad_checksum", self.bad_checksum),
            ("nmea_no_checksum", self.no_checksum),
            ("nmea_unparsable", self.unparsable),
            ("nmea_unsupported", self.unsupported),
            ("nmea_lenient", self.lenient),
            ("nmea_bad_fields", self.bad_fields),
            ("nmea_epochs", self.epochs),
            ("nmea_ender_emits", self.ender_emits),
            ("nmea_flush_emits", self.flush_emits),
            ("nmea_late_sentences", self.late_sentences),
            ("nmea_repeats", self.repeats),
        ]
    }
}

/// The sentence types decoded into fixes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Gga,
    Rmc,
    Gns,
    Vtg,
    Gsa,
    Gst,
    Zda,
    Gll,
}

impl Kind {
    /// The type of a 5-character address `TTSSS` (any two-character talker: GP, GN, GL, GA,
    /// GB, BD, GQ, QZ, GI, and Quectel's PQ).
    fn of_address(addr: &[u8]) -> Option<Self> {
        if addr.len() != 5 || !addr[..2].iter().all(u8::is_ascii_alphanumeric) {
            return None;
        }
        Some(match &addr[2..] {
            b"GGA" => Self::Gga,
            b"RMC" => Self::Rmc,
            b"GNS" => Self::Gns,
            b"VTG" => Self::Vtg,
            b"GSA" => Self::Gsa,
            b"GST" => Self::Gst,
            b"ZDA" => Self::Zda,
            b"GLL" => Self::Gll,
            _ => return None,
        })
    }

    /// The [`GnssFix::sentences`] bit.
    fn bit(self) -> u32 {
        match self {
            Self::Gga => SENTENCE_GGA,
            Self::Rmc => SENTENCE_RMC,
            Self::Gns => SENTENCE_GNS,
            Self::Vtg => SENTENCE_VTG,
            Self::Gsa => SENTENCE_GSA,
            Self::Gst => SENTENCE_GST,
            Self::Zda => SENTENCE_ZDA,
            Self::Gll => SENTENCE_GLL,
        }
    }
}

/// Why a sentence was dropped before decoding.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Reject {
    NoChecksum,
    BadChecksum,
}

/// A sentence whose checksum is right: its address (`GPGGA`) and data (between the first
/// comma and `*`).
#[derive(Debug, Clone, Copy)]
struct Checked<'a> {
    text: &'a str,
    address: &'a [u8],
    data: &'a str,
}

/// Checks the frame and checksum of `$aaaaa,d,d,…*hh`: XOR of every character between `$`
/// and `*`, as two hex digits (NMEA 0183 §5.2.1). Trailing blanks after the checksum are
/// tolerated.
fn check(text: &[u8]) -> Result<Checked<'_>, Reject> {
    let text = text.trim_ascii_end();
    if !matches!(text.first(), Some(b'$' | b'!')) || !text.is_ascii() {
        return Err(Reject::NoChecksum);
    }
    let star = text.iter().rposition(|&b| b == b'*').ok_or(Reject::NoChecksum)?;
    let hex = &text[star + 1..];
    if hex.len() != 2 {
        return Err(Reject::NoChecksum);
    }
    let want = hex_digit(hex[0]).zip(hex_digit(hex[1])).map(|(h, l)| h << 4 | l).ok_or(Reject::NoChecksum)?;
    let body = &text[1..star];
    if body.iter().fold(0u8, |c, &b| c ^ b) != want {
        return Err(Reject::BadChecksum);
    }
    let comma = body.iter().position(|&b| b == b',').unwrap_or(body.len());
    let data = body.get(comma + 1..).unwrap_or(&[]);
    // The text is ASCII (checked above), hence UTF-8.
    let as_str = |b| core::str::from_utf8(b).map_err(|_| Reject::NoChecksum);
    Ok(Checked { text: as_str(text)?, address: &body[..comma], data: as_str(data)? })
}

fn hex_digit(b: u8) -> Option<u8> {
    match b {
        b'0'..=b'9' => Some(b - b'0'),
        b'A'..=b'F' => Some(b - b'A' + 10),
        b'a'..=b'f' => Some(b - b'a' + 10),
        _ => None,
    }
}

/// Field `i` (1-based, as numbered in NMEA documentation) of a sentence's data; empty when
/// absent. Allocation-free.
fn field(data: &str, i: usize) -> &str {
    i.checked_sub(1).and_then(|n| data.split(',').nth(n)).unwrap_or("")
}

/// Number of fields in a sentence's data.
fn field_count(data: &str) -> usize {
    data.split(',').count()
}

/// Two ASCII digits as a number.
fn two_digits(b: &[u8]) -> Option<u32> {
    match b {
        [h @ b'0'..=b'9', l @ b'0'..=b'9'] => Some(u32::from(h - b'0') * 10 + u32::from(l - b'0')),
        _ => None,
    }
}

/// UTC time of day `hhmmss[.s…]` → ns since midnight. Seconds up to 60 (leap second);
/// fraction digits beyond nanoseconds are ignored.
fn parse_tod(s: &str) -> Option<i64> {
    let b = s.as_bytes();
    let (hh, mm, ss) = (two_digits(b.get(0..2)?)?, two_digits(b.get(2..4)?)?, two_digits(b.get(4..6)?)?);
    if hh > 23 || mm > 59 || ss > 60 {
        return None;
    }
    let mut nanos: i64 = 0;
    if b.len() > 6 {
        let frac = match &b[6..] {
            [b'.', frac @ ..] if frac.iter().all(u8::is_ascii_digit) => frac,
            _ => return None,
        };
        let mut scale = NS_PER_S / 10;
        for &d in frac.iter().take(9) {
            nanos += i64::from(d - b'0') * scale;
            scale /= 10;
        }
    }
    Some((i64::from(hh) * 3600 + i64::from(mm) * 60 + i64::from(ss)) * NS_PER_S + nanos)
}

/// Days since 1970 of a valid proleptic Gregorian date (rejects e.g. 31 February).
fn valid_days(year: i64, month: u32, day: u32) -> Option<i64> {
    if !(1..=12).contains(&month) || !(1..=31).contains(&day) {
        return None;
    }
    let days = days_from_civil(year, month, day);
    (civil_from_days(days) == (year, month, day)).then_some(days)
}

/// RMC date `ddmmyy` → days since 1970. Two-digit years 80–99 are 1980–1999 and 00–79 are
/// 2000–2079 (gpsd's rule: GNSS dates start in 1980).
fn parse_ddmmyy(s: &str) -> Option<i64> {
    let b = s.as_bytes();
    if b.len() != 6 {
        return None;
    }
    let (dd, mm, yy) = (two_digits(&b[0..2])?, two_digits(&b[2..4])?, two_digits(&b[4..6])?);
    let year = i64::from(yy) + if yy >= 80 { 1900 } else { 2000 };
    valid_days(year, mm, dd)
}

/// ZDA year range accepted (a four-digit year; GNSS time starts in 1980).
const ZDA_YEARS: core::ops::RangeInclusive<u32> = 1980..=2200;

/// A decimal number field; `None` when empty, malformed or not finite.
fn num(s: &str) -> Option<f64> {
    let s = s.trim();
    if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit() || matches!(b, b'.' | b'-' | b'+')) {
        return None;
    }
    s.parse::<f64>().ok().filter(|v| v.is_finite())
}

/// An unsigned integer field; `None` when empty or malformed.
fn int(s: &str) -> Option<u32> {
    let s = s.trim();
    if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    s.parse().ok()
}

/// A DOP field; `None` when empty, malformed or a ≥ 99 "unknown" sentinel.
fn dop(s: &str) -> Option<f64> {
    num(s).filter(|&d| (0.0..DOP_SENTINEL).contains(&d))
}

/// One coordinate `[d]ddmm.mmmm` with hemisphere → signed degrees; `max_deg` 90 or 180.
/// As in gpsd, a decimal point is required.
fn parse_coord(value: &str, hemi: &str, positive: u8, negative: u8, max_deg: f64) -> Option<f64> {
    let dot = value.find('.')?;
    let (whole, frac) = value.split_at(dot);
    if whole.is_empty() || !whole.bytes().all(|b| b.is_ascii_digit()) || whole.len() > 5 {
        return None;
    }
    let whole: u32 = whole.parse().ok()?;
    let frac_min = if frac.len() > 1 { num(frac)? } else { 0.0 };
    let minutes = f64::from(whole % 100) + frac_min;
    if minutes >= 60.0 {
        return None;
    }
    let deg = f64::from(whole / 100) + minutes / 60.0;
    let sign = match hemi.as_bytes() {
        [h] if *h == positive => 1.0,
        [h] if *h == negative => -1.0,
        _ => return None,
    };
    (deg <= max_deg).then_some(sign * deg)
}

/// Latitude and longitude from four consecutive fields starting at `first` (lat, N/S, lon,
/// E/W); `None` when any is empty or invalid.
fn parse_lat_lon(data: &str, first: usize) -> Option<(f64, f64)> {
    let lat = parse_coord(field(data, first), field(data, first + 1), b'N', b'S', 90.0)?;
    let lon = parse_coord(field(data, first + 2), field(data, first + 3), b'E', b'W', 180.0)?;
    Some((lat, lon))
}

/// What a sentence says about the fix mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ModeHint {
    /// An explicit mode (GSA, or a sentence flagging the fix invalid).
    Mode(u8),
    /// A valid position without dimension information (RMC, GLL): 3D when the epoch has an
    /// altitude or more than 3 satellites, 2D otherwise.
    Position,
}

/// The decoded content of one sentence, in SI units.
#[derive(Debug, Clone, Copy)]
struct Update {
    kind: Kind,
    /// Epoch time tag (GGA, RMC, GNS, GLL), ns since midnight.
    tod_ns: Option<i64>,
    /// Time of day of a ZDA or GST, which may differ from the epoch's.
    aux_tod_ns: Option<i64>,
    /// Date (days since 1970) valid at `aux_tod_ns` (ZDA) or `tod_ns` (RMC).
    date_days: Option<i64>,
    lat_lon: Option<(f64, f64)>,
    alt_msl_m: Option<f64>,
    geoid_sep_m: Option<f64>,
    speed_mps: Option<f64>,
    track_deg: Option<f64>,
    hdop: Option<f64>,
    vdop: Option<f64>,
    pdop: Option<f64>,
    sats_used: Option<u16>,
    quality: Option<u8>,
    std_m: [Option<f64>; 3],
    mode: Option<ModeHint>,
    /// GSA: satellite system of the PRNs (talker letter or NMEA 4.11 system ID).
    gsa_system: u8,
    gsa_prns: [u16; 24],
    gsa_prn_count: usize,
    /// Fields present but invalid.
    bad_fields: u32,
}

impl Update {
    fn new(kind: Kind) -> Self {
        Self {
            kind,
            tod_ns: None,
            aux_tod_ns: None,
            date_days: None,
            lat_lon: None,
            alt_msl_m: None,
            geoid_sep_m: None,
            speed_mps: None,
            track_deg: None,
            hdop: None,
            vdop: None,
            pdop: None,
            sats_used: None,
            quality: None,
            std_m: [None; 3],
            mode: None,
            gsa_system: 0,
            gsa_prns: [0; 24],
            gsa_prn_count: 0,
            bad_fields: 0,
        }
    }

    /// A time-of-day field: empty is "absent", malformed counts as a bad field.
    fn tod(&mut self, s: &str) -> Option<i64> {
        let t = parse_tod(s);
        self.bad_fields += u32::from(t.is_none() && !s.is_empty());
        t
    }

    /// An optional numeric field: empty is "absent", malformed counts as a bad field.
    fn opt_num(&mut self, s: &str, parse: fn(&str) -> Option<f64>) -> Option<f64> {
        let v = parse(s);
        self.bad_fields += u32::from(v.is_none() && num(s).is_none() && !s.trim().is_empty());
        v
    }
}

/// GGA fix quality digit of the crate's [`FixType`].
fn quality_digit(t: FixType) -> u8 {
    match t {
        FixType::Invalid => 0,
        FixType::Gps => 1,
        FixType::DGps => 2,
        FixType::Pps => 3,
        FixType::Rtk => 4,
        FixType::FloatRtk => 5,
        FixType::Estimated => 6,
        FixType::Manual => 7,
        FixType::Simulation => 8,
    }
}

/// GGA. A position is used when quality is not 0 (an empty quality is "unknown", as gpsd);
/// mode: 3D with altitude and ≥ 4 satellites, 2D otherwise, no fix with < 3 satellites
/// (gpsd's rule) or quality 0.
fn decode_gga(d: &str, parsed: Option<&nmea::sentences::GgaData>) -> Update {
    let mut u = Update::new(Kind::Gga);
    u.tod_ns = u.tod(field(d, 1));
    let (quality, lat_lon, sats) = match parsed {
        Some(p) => (
            p.fix_type.map(quality_digit),
            p.latitude.zip(p.longitude),
            p.fix_satellites.map(|n| n.min(u32::from(u16::MAX - 1)) as u16),
        ),
        None => (
            int(field(d, 6)).and_then(|q| u8::try_from(q).ok()),
            parse_lat_lon(d, 2),
            int(field(d, 7)).map(|n| n.min(u32::from(u16::MAX - 1)) as u16),
        ),
    };
    u.quality = quality;
    u.sats_used = sats;
    u.hdop = u.opt_num(field(d, 8), dop);
    if quality == Some(0) {
        u.mode = Some(ModeHint::Mode(FixMode::NoFix as u8));
        return u;
    }
    let Some(lat_lon) = lat_lon else {
        u.mode = Some(ModeHint::Mode(FixMode::NoFix as u8));
        return u;
    };
    u.lat_lon = Some(lat_lon);
    u.alt_msl_m = u.opt_num(field(d, 9), num);
    u.geoid_sep_m = u.opt_num(field(d, 11), num);
    let n = sats.unwrap_or(0);
    let mode = if n < 3 {
        FixMode::NoFix
    } else if u.alt_msl_m.is_some() && n >= 4 {
        FixMode::Fix3d
    } else {
        FixMode::Fix2d
    };
    u.mode = Some(ModeHint::Mode(mode as u8));
    u
}

/// RMC. Time, date, position, speed and track are used only when the status is A or D
/// (gpsd: some receivers send bogus times while the warning flag V is set).
fn decode_rmc(d: &str, parsed: Option<&nmea::sentences::RmcData>) -> Update {
    let mut u = Update::new(Kind::Rmc);
    let tod = u.tod(field(d, 1));
    let (valid, lat_lon, faa_invalid) = match parsed {
        Some(p) => (
            p.status_of_fix != RmcStatusOfFix::Invalid,
            p.lat.zip(p.lon),
            p.faa_mode == Some(FaaMode::DataNotValid),
        ),
        None => (matches!(field(d, 2), "A" | "D"), parse_lat_lon(d, 3), field(d, 12) == "N"),
    };
    u.tod_ns = tod;
    if !valid {
        u.mode = Some(ModeHint::Mode(FixMode::NoFix as u8));
        return u;
    }
    let date = field(d, 9);
    u.date_days = parse_ddmmyy(date);
    u.bad_fields += u32::from(u.date_days.is_none() && !date.is_empty());
    match lat_lon {
        Some(ll) if !faa_invalid => {
            u.lat_lon = Some(ll);
            u.mode = Some(ModeHint::Position);
        }
        _ => u.mode = Some(ModeHint::Mode(FixMode::NoFix as u8)),
    }
    u.speed_mps = u.opt_num(field(d, 7), num).map(|kn| kn * KNOTS_TO_MPS);
    u.track_deg = u.opt_num(field(d, 8), num);
    u
}

/// GNS. The first mode character decides validity (as gpsd); a U/V navigation status makes
/// the sentence unusable for position.
fn decode_gns(d: &str, parsed: Option<&nmea::sentences::GnsData>) -> Update {
    let mut u = Update::new(Kind::Gns);
    u.tod_ns = u.tod(field(d, 1));
    let mode_char = field(d, 6).bytes().next();
    if matches!(mode_char, None | Some(b'N')) {
        u.mode = Some(ModeHint::Mode(FixMode::NoFix as u8));
        return u;
    }
    let (lat_lon, sats, unusable) = match parsed {
        Some(p) => (
            p.lat.zip(p.lon),
            Some(p.nsattelites),
            matches!(p.nav_status, Some(NavigationStatus::Unsafe | NavigationStatus::NotValidForNavigation)),
        ),
        None => (
            parse_lat_lon(d, 2),
            int(field(d, 7)).map(|n| n.min(u32::from(u16::MAX - 1)) as u16),
            matches!(field(d, 13), "U" | "V"),
        ),
    };
    if unusable {
        return u;
    }
    u.sats_used = sats;
    u.hdop = u.opt_num(field(d, 8), dop);
    let Some(lat_lon) = lat_lon else {
        u.mode = Some(ModeHint::Mode(FixMode::NoFix as u8));
        return u;
    };
    u.lat_lon = Some(lat_lon);
    u.alt_msl_m = u.opt_num(field(d, 9), num);
    u.geoid_sep_m = u.opt_num(field(d, 10), num);
    let mode = if u.alt_msl_m.is_some() && sats.unwrap_or(0) > 3 { FixMode::Fix3d } else { FixMode::Fix2d };
    u.mode = Some(ModeHint::Mode(mode as u8));
    u
}

/// VTG. Speed and track are used unless the FAA mode says estimated or not valid.
fn decode_vtg(d: &str) -> Update {
    let mut u = Update::new(Kind::Vtg);
    if matches!(field(d, 9), "E" | "N") {
        return u;
    }
    u.track_deg = u.opt_num(field(d, 1), num);
    let knots = u.opt_num(field(d, 5), num);
    u.speed_mps = match knots {
        Some(kn) => Some(kn * KNOTS_TO_MPS),
        None => u.opt_num(field(d, 7), num).map(|kmh| kmh * KMH_TO_MPS),
    };
    u
}

/// GSA. Field layout: mode1, mode2, PRN fields, PDOP, HDOP, VDOP[, system ID]; receivers
/// send 12 PRN fields (NMEA) or more (the Navior CH-4701 sends 24), so the DOPs are located
/// from the end.
fn decode_gsa(d: &str, talker: u8, parsed: Option<&nmea::sentences::GsaData>) -> Option<Update> {
    let mut u = Update::new(Kind::Gsa);
    let n = field_count(d);
    let mode = match parsed {
        Some(p) => Some(match p.mode2 {
            GsaMode2::NoFix => 1,
            GsaMode2::Fix2D => 2,
            GsaMode2::Fix3D => 3,
        }),
        None => int(field(d, 2)).and_then(|m| u8::try_from(m).ok()).filter(|m| (1..=3).contains(m)),
    };
    if n < 17 {
        // Runt (e.g. i.Trek's "$GPGSA,A,1,,,,*32"): only the mode, if any.
        u.mode = mode.map(ModeHint::Mode);
        return mode.map(|_| u);
    }
    u.mode = Some(ModeHint::Mode(mode?));
    // NMEA 4.11 adds a system ID after VDOP when there are exactly 12 PRN fields.
    let dops_at = if n == 18 { 15 } else { n - 2 };
    u.pdop = u.opt_num(field(d, dops_at), dop);
    u.hdop = u.opt_num(field(d, dops_at + 1), dop);
    u.vdop = u.opt_num(field(d, dops_at + 2), dop);
    u.gsa_system = if n == 18 { int(field(d, 18)).map_or(talker, |s| b'0' + (s % 10) as u8) } else { talker };
    match parsed {
        Some(p) => {
            for &prn in p.fix_sats_prn.iter() {
                u.push_prn(prn);
            }
        }
        None => {
            for i in 3..dops_at {
                if let Some(prn) = int(field(d, i)).filter(|&p| p > 0) {
                    u.push_prn(prn);
                }
            }
        }
    }
    Some(u)
}

impl Update {
    fn push_prn(&mut self, prn: u32) {
        if let (Some(slot), Ok(prn)) = (self.gsa_prns.get_mut(self.gsa_prn_count), u16::try_from(prn)) {
            *slot = prn;
            self.gsa_prn_count += 1;
        }
    }
}

/// GST: 1-σ latitude, longitude and altitude errors, m, for the fix at its time.
fn decode_gst(d: &str) -> Update {
    let mut u = Update::new(Kind::Gst);
    u.aux_tod_ns = u.tod(field(d, 1));
    for (k, i) in [6, 7, 8].into_iter().enumerate() {
        u.std_m[k] = u.opt_num(field(d, i), num).filter(|&s| s >= 0.0);
    }
    u
}

/// ZDA: the date at the ZDA's own time of day.
fn decode_zda(d: &str, parsed: Option<&nmea::sentences::ZdaData>) -> Update {
    let mut u = Update::new(Kind::Zda);
    u.aux_tod_ns = u.tod(field(d, 1));
    let (day, month, year) = match parsed {
        Some(p) => (p.day.map(u32::from), p.month.map(u32::from), p.year.map(u32::from)),
        None => (int(field(d, 2)), int(field(d, 3)), int(field(d, 4)).filter(|_| field(d, 4).len() == 4)),
    };
    if let (Some(day), Some(month), Some(year)) = (day, month, year) {
        u.date_days = ZDA_YEARS.contains(&year).then(|| valid_days(i64::from(year), month, day)).flatten();
        u.bad_fields += u32::from(u.date_days.is_none());
    }
    if u.aux_tod_ns.is_none() {
        u.date_days = None;
    }
    u
}

/// GLL. Position used when the status is A and the FAA mode (if any) is not N.
fn decode_gll(d: &str, parsed: Option<&nmea::sentences::GllData>) -> Update {
    let mut u = Update::new(Kind::Gll);
    u.tod_ns = u.tod(field(d, 5));
    let (valid, lat_lon, faa_invalid) = match parsed {
        Some(p) => (p.valid, p.latitude.zip(p.longitude), p.faa_mode == Some(FaaMode::DataNotValid)),
        None => (field(d, 6) == "A", parse_lat_lon(d, 1), field(d, 7) == "N"),
    };
    match lat_lon {
        Some(ll) if valid && !faa_invalid => {
            u.lat_lon = Some(ll);
            u.mode = Some(ModeHint::Position);
        }
        _ => u.mode = Some(ModeHint::Mode(FixMode::NoFix as u8)),
    }
    u
}

/// Decodes a checked sentence of a supported kind. Returns the update and whether the
/// lenient decoder had to be used; `None` when nothing usable could be decoded.
fn decode(kind: Kind, s: &Checked<'_>) -> Option<(Update, bool)> {
    let d = s.data;
    // The crate's GSA parser panics on more than 18 PRN fields: never hand it one.
    let crate_ok = !(kind == Kind::Gsa && field_count(d) > 18);
    let parsed = if crate_ok { nmea::parse_str(s.text).ok() } else { None };
    let talker = s.address.get(1).copied().unwrap_or(b'?');
    let lenient = parsed.is_none();
    let u = match (kind, parsed.as_ref()) {
        (Kind::Gga, Some(ParseResult::GGA(p))) => decode_gga(d, Some(p)),
        (Kind::Gga, _) => decode_gga(d, None),
        (Kind::Rmc, Some(ParseResult::RMC(p))) => decode_rmc(d, Some(p)),
        (Kind::Rmc, _) => decode_rmc(d, None),
        (Kind::Gns, Some(ParseResult::GNS(p))) => decode_gns(d, Some(p)),
        (Kind::Gns, _) => decode_gns(d, None),
        (Kind::Vtg, _) => decode_vtg(d),
        (Kind::Gsa, Some(ParseResult::GSA(p))) => decode_gsa(d, talker, Some(p))?,
        (Kind::Gsa, _) => decode_gsa(d, talker, None)?,
        (Kind::Gst, _) => decode_gst(d),
        (Kind::Zda, Some(ParseResult::ZDA(p))) => decode_zda(d, Some(p)),
        (Kind::Zda, _) => decode_zda(d, None),
        (Kind::Gll, Some(ParseResult::GLL(p))) => decode_gll(d, Some(p)),
        (Kind::Gll, _) => decode_gll(d, None),
    };
    let nothing = u.tod_ns.is_none()
        && u.aux_tod_ns.is_none()
        && u.mode.is_none()
        && u.speed_mps.is_none()
        && u.track_deg.is_none()
        && u.std_m.iter().all(Option::is_none);
    (!nothing).then_some((u, lenient))
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
    /// Some sentence has been merged (the epoch exists).
    open: bool,
    fix: GnssFix,
    tod_ns: Option<i64>,
    /// Addresses seen in this epoch and their counts.
    seen: [([u8; ADDR_MAX], u8); SEEN_MAX],
    n_seen: usize,
    last_key: Option<Key>,
    /// (system, PRN) pairs used according to GSA.
    prns: [(u8, u16); PRN_MAX],
    n_prns: usize,
    /// Satellites used from GGA/GNS (preferred over the GSA count).
    sats_reported: Option<u16>,
}

impl Epoch {
    fn closed() -> Self {
        Self {
            open: false,
            fix: GnssFix::empty(Stamp::host(0, 0, StampSource::Receipt)),
            tod_ns: None,
            seen: [([0; ADDR_MAX], 0); SEEN_MAX],
            n_seen: 0,
            last_key: None,
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
    fn count_of(&self, addr: &[u8; ADDR_MAX]) -> u8 {
        self.seen[..self.n_seen].iter().find(|(a, _)| a == addr).map_or(0, |s| s.1)
    }

    /// Records one more occurrence of `address`; returns its key.
    fn note(&mut self, address: &[u8]) -> Key {
        let addr = Key::addr_of(address);
        let n = self.n_seen;
        let occurrence = match self.seen[..n].iter_mut().find(|(a, _)| *a == addr) {
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
        };
        let key = Key { addr, occurrence };
        self.last_key = Some(key);
        key
    }

    /// Applies a mode claim: later sentences win, except that a 2D claim does not downgrade
    /// a 3D fix of the same epoch (RMC/GLL after a 3D GGA).
    fn apply_mode(&mut self, mode: u8) {
        if !(mode == FixMode::Fix2d as u8 && self.fix.mode == FixMode::Fix3d as u8) {
            self.fix.mode = mode;
        }
    }

    fn sats_used(&self) -> Option<u16> {
        self.sats_reported.or((self.n_prns > 0).then_some(self.n_prns as u16))
    }

    /// Merges a decoded sentence (later values replace earlier ones).
    fn merge(&mut self, u: &Update) {
        let f = &mut self.fix;
        f.sentences |= u.kind.bit();
        if let Some(t) = u.tod_ns {
            self.tod_ns = Some(t);
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
        if u.kind != Kind::Gst || u.aux_tod_ns.is_none() || u.aux_tod_ns == self.tod_ns {
            set(&mut f.std_lat_m, u.std_m[0]);
            set(&mut f.std_lon_m, u.std_m[1]);
            set(&mut f.std_alt_m, u.std_m[2]);
        }
        if let Some(q) = u.quality {
            f.quality = q;
        }
        if let Some(n) = u.sats_used {
            self.sats_reported = Some(n);
        }
        for &prn in &u.gsa_prns[..u.gsa_prn_count] {
            let entry = (u.gsa_system, prn);
            if self.n_prns < PRN_MAX && !self.prns[..self.n_prns].contains(&entry) {
                self.prns[self.n_prns] = entry;
                self.n_prns += 1;
            }
        }
        match u.mode {
            Some(ModeHint::Mode(m)) => self.apply_mode(m),
            Some(ModeHint::Position) => {
                let three_d = self.fix.alt_msl_m.is_finite() || self.sats_used().unwrap_or(0) > 3;
                self.apply_mode(if three_d { FixMode::Fix3d as u8 } else { FixMode::Fix2d as u8 });
            }
            None => {}
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

/// Sentences → [`GnssFix`] epochs. Pure state machine: no I/O, no clock, no allocation.
#[derive(Debug, Clone)]
pub struct EpochAssembler {
    cur: Epoch,
    /// Time tag of the last epoch emitted on the learned ender.
    ender_emitted_tod: Option<i64>,
    date: Option<DateAnchor>,
    ender: Option<Key>,
    candidate: Option<Key>,
    votes: u8,
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
            ender_emitted_tod: None,
            date: None,
            ender: None,
            candidate: None,
            votes: 0,
            seq: 0,
            counters: EpochCounters::default(),
        }
    }

    /// Counters since creation.
    pub fn counters(&self) -> &EpochCounters {
        &self.counters
    }

    /// The learned last sentence of the receiver's cycle, e.g. `("GPGSV", 3)` for the third
    /// GPGSV of a cycle; `None` while not (or no longer) known.
    pub fn cycle_ender(&self) -> Option<(&str, u8)> {
        let k = self.ender.as_ref()?;
        let len = k.addr.iter().position(|&b| b == 0).unwrap_or(ADDR_MAX);
        Some((core::str::from_utf8(&k.addr[..len]).unwrap_or("?"), k.occurrence))
    }

    /// Consumes one sentence (text from `$` to before CR/LF; `host_ns` the host time of its
    /// first byte) and calls `out` for every epoch it completes (0, 1 or 2: the previous
    /// epoch on a new time tag, this one if the sentence is the learned cycle ender).
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
        if let Some(u) = &update {
            self.route(u, s.address, out);
            if let (Some(days), Some(tod)) = (u.date_days, u.tod_ns.or(u.aux_tod_ns)) {
                self.date = Some(DateAnchor { days, tod_ns: tod });
            }
        }
        if !self.cur.open {
            if update.is_none() {
                // Data-less sentences between epochs do not start one.
                return;
            }
            self.cur = Epoch::start(host_ns);
        }
        if let Some(u) = &update {
            self.cur.merge(u);
        }
        let key = self.cur.note(s.address);
        if self.ender == Some(key) {
            self.counters.ender_emits += 1;
            self.ender_emitted_tod = self.cur.tod_ns;
            self.emit(out);
        }
    }

    /// Emits the epoch being assembled, if any (call when the line has been idle for longer
    /// than the gap between sentences of one burst).
    pub fn flush(&mut self, out: &mut impl FnMut(&GnssFix)) {
        if self.cur.open && self.emit(out) {
            self.counters.flush_emits += 1;
        }
    }

    /// Decides, before a decoded sentence is merged, whether it closes the open epoch.
    fn route(&mut self, u: &Update, address: &[u8], out: &mut impl FnMut(&GnssFix)) {
        let Some(t) = u.tod_ns else { return };
        if !self.cur.open || self.cur.tod_ns.is_none() {
            if self.ender_emitted_tod == Some(t) {
                // Data for the epoch just emitted on the ender: the ender was wrong.
                self.counters.late_sentences += 1;
                self.forget_ender();
            }
            return;
        }
        if self.cur.tod_ns != Some(t) {
            if let Some(last) = self.cur.last_key {
                self.learn(last);
            }
            self.emit(out);
        } else if self.cur.count_of(&Key::addr_of(address)) > 0 {
            self.counters.repeats += 1;
            self.emit(out);
        }
    }

    /// One vote for `key` as the cycle ender (it was last before a time-tag change).
    fn learn(&mut self, key: Key) {
        if self.candidate == Some(key) {
            self.votes = self.votes.saturating_add(1);
        } else {
            self.candidate = Some(key);
            self.votes = 1;
        }
        if self.votes >= ENDER_VOTES {
            self.ender = Some(key);
        }
    }

    fn forget_ender(&mut self) {
        self.ender = None;
        self.candidate = None;
        self.votes = 0;
        self.ender_emitted_tod = None;
    }

    /// Completes the open epoch and hands it to `out` (skipped when it holds no fix data).
    /// Returns whether a fix was emitted.
    fn emit(&mut self, out: &mut impl FnMut(&GnssFix)) -> bool {
        let mut e = core::mem::replace(&mut self.cur, Epoch::closed());
        if e.fix.sentences == 0 {
            return false;
        }
        if let Some(n) = e.sats_used() {
            e.fix.sats_used = n;
        }
        if let Some(tod) = e.tod_ns {
            e.fix.tod_ns = tod;
            if let Some(anchor) = self.date {
                let days = anchor.days_at(tod);
                e.fix.utc_ns = days * NS_PER_DAY + tod;
                e.fix.gps_ns = gps_ns_from_utc_ns(e.fix.utc_ns);
                // Carry the date forward from this epoch (keeps rollovers monotonic).
                self.date = Some(DateAnchor { days, tod_ns: tod });
            }
        }
        velocity(&mut e.fix);
        e.fix.stamp = Stamp::host(e.fix.stamp.host_ns, self.seq, StampSource::Receipt);
        self.seq += 1;
        self.counters.epochs += 1;
        out(&e.fix);
        true
    }
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
