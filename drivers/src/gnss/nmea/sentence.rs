//! One NMEA 0183 sentence: its frame and checksum checked (`check`), and the fix data it
//! carries decoded into an `Update` in SI units (`decode`). The layer under
//! [`super::epoch::EpochAssembler`], which merges the updates of one time tag into a
//! `GnssFix` (and documents how: which sentence wins, fix mode, dates).
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
//! | PGRMZ | 1 altitude feet (Garmin; MSL as gpsd reads it), 3 fix dimension 1/2/3 |
//!
//! Sentences are checked and split with the `nmea` crate, whose typed output is used for
//! what it represents exactly (coordinates, fix quality, satellite counts, status and mode
//! flags, PRN lists, ZDA date). Quantities the crate stores as `f32` (altitudes, DOPs, speed,
//! track, sigmas) and the time of day (which the crate converts through a float) are read
//! from the checksummed sentence text as `f64` / integer nanoseconds. Sentences the crate
//! rejects although their checksum is right (non-standard field formats that gpsd accepts,
//! e.g. an empty GGA quality, a 24-PRN GSA, a four-letter GNS mode) are decoded from the text
//! alone and counted in [`super::epoch::EpochCounters::lenient`].

use navsync_shared::samples::{
    FixMode, SENTENCE_GGA, SENTENCE_GLL, SENTENCE_GNS, SENTENCE_GSA, SENTENCE_GST, SENTENCE_RMC, SENTENCE_VTG,
    SENTENCE_ZDA,
};
use navsync_shared::time::{NS_PER_S, civil_from_days, days_from_civil};
use nmea::ParseResult;
use nmea::sentences::gns::NavigationStatus;
use nmea::sentences::gsa::GsaMode2;
use nmea::sentences::rmc::RmcStatusOfFix;
use nmea::sentences::rmz::PgrmzFixType;
use nmea::sentences::{FaaMode, FixType};

/// Knots to m/s (1 kn = 1852 m/h).
const KNOTS_TO_MPS: f64 = 1852.0 / 3600.0;
/// km/h to m/s.
const KMH_TO_MPS: f64 = 1.0 / 3.6;
/// DOP values at or above this are receivers' "unknown" sentinels (99.9, 99.99).
const DOP_SENTINEL: f64 = 99.0;

/// The sentence types decoded into fixes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Kind {
    Gga,
    Rmc,
    Gns,
    Vtg,
    Gsa,
    Gst,
    Zda,
    Gll,
    /// Garmin proprietary `$PGRMZ`: altitude (feet) and fix dimension.
    Rmz,
}

impl Kind {
    /// The type of a 5-character address `TTSSS` (any two-character talker: GP, GN, GL, GA,
    /// GB, BD, GQ, QZ, GI, and Quectel's PQ).
    pub(super) fn of_address(addr: &[u8]) -> Option<Self> {
        if addr == b"PGRMZ" {
            return Some(Self::Rmz);
        }
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

    /// A sentence that reports a fix with the epoch's time tag (GGA, RMC, GNS, GLL).
    pub(super) fn is_fix(self) -> bool {
        matches!(self, Self::Gga | Self::Rmc | Self::Gns | Self::Gll)
    }

    /// The [`navsync_shared::samples::GnssFix::sentences`] bit.
    pub(super) fn bit(self) -> u32 {
        match self {
            Self::Gga => SENTENCE_GGA,
            Self::Rmc => SENTENCE_RMC,
            Self::Gns => SENTENCE_GNS,
            Self::Vtg => SENTENCE_VTG,
            Self::Gsa => SENTENCE_GSA,
            Self::Gst => SENTENCE_GST,
            Self::Zda => SENTENCE_ZDA,
            Self::Gll => SENTENCE_GLL,
            // No GnssFix::sentences bit is defined for PGRMZ.
            Self::Rmz => 0,
        }
    }
}

/// Why a sentence was dropped before decoding.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Reject {
    NoChecksum,
    BadChecksum,
}

/// A sentence whose checksum is right: its address (`GPGGA`) and data (between the first
/// comma and `*`).
#[derive(Debug, Clone, Copy)]
pub(super) struct Checked<'a> {
    pub(super) text: &'a str,
    pub(super) address: &'a [u8],
    pub(super) data: &'a str,
}

/// Checks the frame and checksum of `$aaaaa,d,d,…*hh`: XOR of every character between `$`
/// and `*`, as two hex digits (NMEA 0183 §5.2.1). Trailing blanks after the checksum are
/// tolerated.
pub(super) fn check(text: &[u8]) -> Result<Checked<'_>, Reject> {
    let text = text.trim_ascii_end();
    if !matches!(text.first(), Some(b'$' | b'!')) || !text.is_ascii() {
        return Err(Reject::NoChecksum);
    }
    let star = text.iter().rposition(|&b| b == b'*').ok_or(Reject::NoChecksum)?;
    let hex = &text[star + 1..];
    if hex.len() != 2 {
        return Err(Reject::NoChecksum);
    }
    let want = hex_digit(hex[0])
        .zip(hex_digit(hex[1]))
        .map(|(h, l)| h << 4 | l)
        .ok_or(Reject::NoChecksum)?;
    let body = &text[1..star];
    if body.iter().fold(0u8, |c, &b| c ^ b) != want {
        return Err(Reject::BadChecksum);
    }
    let comma = body.iter().position(|&b| b == b',').unwrap_or(body.len());
    let data = body.get(comma + 1..).unwrap_or(&[]);
    // The text is ASCII (checked above), hence UTF-8.
    let as_str = |b| core::str::from_utf8(b).map_err(|_| Reject::NoChecksum);
    Ok(Checked {
        text: as_str(text)?,
        address: &body[..comma],
        data: as_str(data)?,
    })
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
    let (hh, mm, ss) = (
        two_digits(b.get(0..2)?)?,
        two_digits(b.get(2..4)?)?,
        two_digits(b.get(4..6)?)?,
    );
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

/// A coordinate pair from the `nmea` crate, which does not range-check: `None` unless
/// |lat| ≤ 90° and |lon| ≤ 180°.
/// The highest GGA quality NMEA 0183 defines (8: simulator).
const MAX_GGA_QUALITY: u32 = 8;

fn plausible(lat_lon: Option<(f64, f64)>) -> Option<(f64, f64)> {
    lat_lon.filter(|(lat, lon)| lat.abs() <= 90.0 && lon.abs() <= 180.0)
}

/// What a sentence says about the fix mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum ModeHint {
    /// A mode the sentence determines: GSA and PGRMZ state it, GGA/GNS imply it (altitude
    /// with ≥ 4 satellites: 3D), and any sentence flagging its fix invalid means no fix.
    Mode(u8),
    /// A valid position with an altitude from at most 3 satellites (GGA, GNS): too few to
    /// solve altitude, which the receiver holds. gpsd's convention, followed here so that
    /// `mode` means what it means to gpsd clients: 3D when the receiver's previous epoch had a
    /// fix (its no-downgrade rule), 2D on the first epoch of a fix. The fix's `sats_used` tells
    /// a navigation filter that the altitude is not measured ([`navsync_shared::samples::GnssFix::altitude_held`]).
    AltitudeFewSats,
    /// A valid position from a sentence that says nothing about the dimension (RMC, GLL).
    /// It does not override a mode determined in the same epoch; otherwise it is 3D when the
    /// epoch has an altitude or more than 3 satellites used, else the dimension of the
    /// receiver's last fix (its dimension does not change because a sentence was left out),
    /// else 2D. (gpsd: RMC/GLL "probably 3D" rules and its no-downgrade rule.)
    Position,
}

/// The decoded content of one sentence, in SI units.
#[derive(Debug, Clone, Copy)]
pub(super) struct Update {
    pub(super) kind: Kind,
    /// Epoch time tag (GGA, RMC, GNS, GLL), ns since midnight.
    pub(super) tod_ns: Option<i64>,
    /// Time of day of a ZDA or GST, which may differ from the epoch's.
    pub(super) aux_tod_ns: Option<i64>,
    /// Date (days since 1970) valid at `aux_tod_ns` (ZDA) or `tod_ns` (RMC).
    pub(super) date_days: Option<i64>,
    pub(super) lat_lon: Option<(f64, f64)>,
    pub(super) alt_msl_m: Option<f64>,
    pub(super) geoid_sep_m: Option<f64>,
    pub(super) speed_mps: Option<f64>,
    pub(super) track_deg: Option<f64>,
    pub(super) hdop: Option<f64>,
    pub(super) vdop: Option<f64>,
    pub(super) pdop: Option<f64>,
    pub(super) sats_used: Option<u16>,
    pub(super) quality: Option<u8>,
    pub(super) std_m: [Option<f64>; 3],
    pub(super) mode: Option<ModeHint>,
    /// GSA: satellite system of the PRNs (talker letter or NMEA 4.11 system ID).
    pub(super) gsa_system: u8,
    pub(super) gsa_prns: [u16; 24],
    pub(super) gsa_prn_count: usize,
    /// Fields present but invalid.
    pub(super) bad_fields: u32,
    /// Well-formed values outside what NMEA 0183 allows (a negative speed, a track of 360° or
    /// more, a GGA quality above 8); the field, or for a quality the fix, is dropped.
    pub(super) out_of_range: u32,
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
            out_of_range: 0,
        }
    }

    /// A speed over ground, m/s: NMEA 0183 has no negative speed; one is counted and dropped.
    fn speed(&mut self, v: Option<f64>) -> Option<f64> {
        let bad = v.is_some_and(|v| v < 0.0);
        self.out_of_range += u32::from(bad);
        v.filter(|_| !bad)
    }

    /// A track, ° true: NMEA 0183's is in [0, 360); another is counted and dropped.
    fn track(&mut self, v: Option<f64>) -> Option<f64> {
        let bad = v.is_some_and(|v| !(0.0..360.0).contains(&v));
        self.out_of_range += u32::from(bad);
        v.filter(|_| !bad)
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
/// mode: no fix for quality 0 or no position, else 3D with an altitude and ≥ 4 satellites,
/// else 2D. (gpsd also calls < 3 satellites "no fix"; multi-constellation receivers send one
/// GGA per system whose count covers that system only, so that rule is not applied.) A
/// quality NMEA 0183 does not define (above 8) is counted and the fix dropped: nothing says
/// what the position is worth.
fn decode_gga(d: &str, parsed: Option<&nmea::sentences::GgaData>) -> Update {
    let mut u = Update::new(Kind::Gga);
    u.tod_ns = u.tod(field(d, 1));
    if int(field(d, 6)).is_some_and(|q| q > MAX_GGA_QUALITY) {
        u.out_of_range += 1;
        u.mode = Some(ModeHint::Mode(FixMode::NoFix as u8));
        return u;
    }
    let (quality, lat_lon, sats) = match parsed {
        Some(p) => (
            p.fix_type.map(quality_digit),
            plausible(p.latitude.zip(p.longitude)),
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
    u.with_position(d, lat_lon, 11, sats)
}

impl Update {
    /// The position part GGA and GNS share: no fix without a valid position, else the
    /// position, the MSL altitude (field 9), the geoid separation (field `geoid_field`: 11 in
    /// GGA, 10 in GNS) and the mode they imply.
    fn with_position(mut self, d: &str, lat_lon: Option<(f64, f64)>, geoid_field: usize, sats: Option<u16>) -> Self {
        let Some(lat_lon) = lat_lon else {
            self.mode = Some(ModeHint::Mode(FixMode::NoFix as u8));
            return self;
        };
        self.lat_lon = Some(lat_lon);
        self.alt_msl_m = self.opt_num(field(d, 9), num);
        self.geoid_sep_m = self.opt_num(field(d, geoid_field), num);
        self.mode = Some(altitude_mode(self.alt_msl_m.is_some(), sats));
        self
    }
}

/// The mode a GGA/GNS position implies: 3D with an altitude from ≥ 4 satellites, gpsd's
/// rule for an altitude from fewer ([`ModeHint::AltitudeFewSats`]), 2D without an altitude.
fn altitude_mode(has_altitude: bool, sats: Option<u16>) -> ModeHint {
    match (has_altitude, sats.unwrap_or(0)) {
        (false, _) => ModeHint::Mode(FixMode::Fix2d as u8),
        (true, n) if n >= 4 => ModeHint::Mode(FixMode::Fix3d as u8),
        (true, _) => ModeHint::AltitudeFewSats,
    }
}

/// RMC. Time, date, position, speed and track are used only when the status is A or D
/// (gpsd: some receivers send bogus times while the warning flag V is set).
fn decode_rmc(d: &str, parsed: Option<&nmea::sentences::RmcData>) -> Update {
    let mut u = Update::new(Kind::Rmc);
    let tod = u.tod(field(d, 1));
    let (valid, lat_lon, faa_invalid) = match parsed {
        Some(p) => (
            p.status_of_fix != RmcStatusOfFix::Invalid,
            plausible(p.lat.zip(p.lon)),
            p.faa_mode == Some(FaaMode::DataNotValid),
        ),
        None => (
            matches!(field(d, 2), "A" | "D"),
            parse_lat_lon(d, 3),
            field(d, 12) == "N",
        ),
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
    let speed = u.opt_num(field(d, 7), num).map(|kn| kn * KNOTS_TO_MPS);
    u.speed_mps = u.speed(speed);
    let track = u.opt_num(field(d, 8), num);
    u.track_deg = u.track(track);
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
            plausible(p.lat.zip(p.lon)),
            Some(p.nsattelites),
            matches!(
                p.nav_status,
                Some(NavigationStatus::Unsafe | NavigationStatus::NotValidForNavigation)
            ),
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
    u.with_position(d, lat_lon, 10, sats)
}

/// VTG. Speed and track are used unless the FAA mode says estimated or not valid.
fn decode_vtg(d: &str) -> Update {
    let mut u = Update::new(Kind::Vtg);
    if matches!(field(d, 9), "E" | "N") {
        return u;
    }
    let track = u.opt_num(field(d, 1), num);
    u.track_deg = u.track(track);
    let knots = u.opt_num(field(d, 5), num);
    let speed = match knots {
        Some(kn) => Some(kn * KNOTS_TO_MPS),
        None => u.opt_num(field(d, 7), num).map(|kmh| kmh * KMH_TO_MPS),
    };
    u.speed_mps = u.speed(speed);
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
        None => int(field(d, 2))
            .and_then(|m| u8::try_from(m).ok())
            .filter(|m| (1..=3).contains(m)),
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
    u.gsa_system = if n == 18 {
        int(field(d, 18)).map_or(talker, |s| b'0' + (s % 10) as u8)
    } else {
        talker
    };
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
    if u.gsa_prn_count == 0 && u.mode != Some(ModeHint::Mode(FixMode::NoFix as u8)) {
        // A 2D/3D claim without a single satellite used is not credible (i.Trek sends
        // "A,2" with no PRNs and DOPs of 50 while losing lock; per-system NMEA 4.11 GSAs
        // of unused systems look alike): keep its DOPs, not its mode.
        u.mode = None;
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
        None => (
            int(field(d, 2)),
            int(field(d, 3)),
            int(field(d, 4)).filter(|_| field(d, 4).len() == 4),
        ),
    };
    if let (Some(day), Some(month), Some(year)) = (day, month, year) {
        u.date_days = ZDA_YEARS
            .contains(&year)
            .then(|| valid_days(i64::from(year), month, day))
            .flatten();
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
        Some(p) => (
            p.valid,
            plausible(p.latitude.zip(p.longitude)),
            p.faa_mode == Some(FaaMode::DataNotValid),
        ),
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

/// PGRMZ (Garmin proprietary): 1 altitude in feet (MSL, as gpsd reads it; integer), 2 `f`,
/// 3 fix dimension 1 none / 2 2D / 3 3D.
fn decode_rmz(d: &str, parsed: Option<&nmea::sentences::PgrmzData>) -> Update {
    /// International foot, m.
    const FOOT_M: f64 = 0.3048;
    let mut u = Update::new(Kind::Rmz);
    let (alt_ft, mode) = match parsed {
        Some(p) => (
            Some(f64::from(p.altitude)),
            Some(match p.fix_type {
                PgrmzFixType::NoFix => 1,
                PgrmzFixType::TwoDimensional => 2,
                PgrmzFixType::ThreeDimensional => 3,
            }),
        ),
        None => {
            let alt = if field(d, 2) == "f" {
                field(d, 1).trim().parse::<i32>().ok().map(f64::from)
            } else {
                None
            };
            let mode = int(field(d, 3))
                .and_then(|m| u8::try_from(m).ok())
                .filter(|m| (1..=3).contains(m));
            (alt, mode)
        }
    };
    u.alt_msl_m = alt_ft.map(|ft| ft * FOOT_M);
    u.mode = mode.map(ModeHint::Mode);
    u
}

/// Decodes a checked sentence of a supported kind. Returns the update (possibly empty, e.g.
/// a VTG whose fields are all blank) and whether the lenient decoder had to be used; `None`
/// when the sentence is malformed (the crate rejects it and no field could be read).
pub(super) fn decode(kind: Kind, s: &Checked<'_>) -> Option<(Update, bool)> {
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
        (Kind::Rmz, Some(ParseResult::PGRMZ(p))) => decode_rmz(d, Some(p)),
        (Kind::Rmz, _) => decode_rmz(d, None),
    };
    let nothing = u.tod_ns.is_none()
        && u.aux_tod_ns.is_none()
        && u.mode.is_none()
        && u.speed_mps.is_none()
        && u.track_deg.is_none()
        && u.alt_msl_m.is_none()
        && u.std_m.iter().all(Option::is_none);
    // Unparsable: neither the crate nor the lenient decoder could read anything from it.
    (!(nothing && lenient)).then_some((u, lenient))
}
