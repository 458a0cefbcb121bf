//! RINEX observation and GPS and GLONASS navigation files, parsed from text (pure: no I/O).
//!
//! Formats: RINEX 2.11 (IGS/RTCM-SC104, "RINEX: The Receiver Independent Exchange Format
//! Version 2.11", 2012 update: Tables A1–A4, A11 GLONASS navigation; 2.10 is the same layout)
//! and RINEX 3.05 (IGS/RTCM 2020: Tables A1–A7 observation, A8 GPS navigation, A10 GLONASS
//! navigation; 3.00–3.04 share it). Observation epochs become [`GnssRaw`] samples with u-blox
//! `gnssId`/`sigId` (UBX-RXM-RAWX's convention, GPS L1 C/A first; a GLONASS signal's `freqId`
//! from the header's `GLONASS SLOT / FRQ #`, else [`GLONASS_CHANNEL_UNKNOWN`]); a GPS navigation
//! record becomes a [`GpsEphemeris`] in RINEX's units (s, m, rad), a GLONASS one a
//! [`GloRecord`] (SI units), and the header's Klobuchar α/β. Errors name the file, the line
//! (1-based) and the field.

use navsync_shared::reflect::Reflect;
use navsync_shared::samples::{GnssRaw, LOCK_TIME_MAX_MS, MAX_RAW_MEASUREMENTS, RawMeasurement, SIG_GPS_L2_PY};
use navsync_shared::time::{GPS_EPOCH_UNIX_S, days_from_civil, gps_minus_utc_s};

/// `freqId` of a GLONASS measurement whose channel the file does not give (u-blox's are
/// 0–13, channel + 7): the estimator leaves it out rather than guess its carrier.
pub const GLONASS_CHANNEL_UNKNOWN: u8 = 255;

/// Seconds in a GPS week.
const WEEK_S: f64 = 604_800.0;

/// Bad RINEX input: where and what.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}:{line}: {field}: {problem}")]
pub struct RinexError {
    /// The file's name as given.
    pub file: String,
    /// Line, 1-based.
    pub line: usize,
    /// The field (header label or record field).
    pub field: String,
    /// What is wrong.
    pub problem: String,
}

/// A GPS time: full week and seconds of week.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GpsTime {
    /// Weeks since 1980-01-06.
    pub week: u32,
    /// Seconds of week.
    pub tow_s: f64,
}

/// Weeks from the GPS epoch (1980-01-06) to the BDT epoch (2006-01-01, a Sunday): BDT week w
/// starts on the calendar day of GPS week w + 1356 (BDS-SIS-ICD-B1I §4.3: BDT counts from
/// 2006-01-01 00:00:00 UTC, 14 s behind GPS time).
pub const BDT_WEEK_OFFSET: u32 = 1356;

/// A Galileo or a BeiDou navigation record (RINEX 3.05's Galileo and BDS navigation data record
/// tables: the layout of GPS's Table A8 with other meanings in some fields), in the system's own time: GST, written as GPS
/// time (the same weeks and seconds), or BDT.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KeplerRecord {
    /// Line of the record in the file (0 when made, not read).
    pub line: usize,
    /// `'E'` Galileo or `'C'` BeiDou.
    pub system: char,
    /// Satellite (Galileo SVID, BeiDou PRN).
    pub sv: u8,
    /// The week of t_oc: Galileo's as RINEX counts it (continuous, aligned with GPS weeks),
    /// BeiDou's BDT week (weeks since 2006-01-01).
    pub toc_week: u32,
    /// t_oc, s of that week.
    pub toc_s: f64,
    /// Clock bias (s), drift (s/s), drift rate (s/s²).
    pub af: [f64; 3],
    /// BROADCAST ORBIT 1–7 in the table's order and units. Galileo: IODnav, C_rs, Δn, M_0 /
    /// C_uc, e, C_us, √A / t_oe, C_ic, Ω_0, C_is / i_0, C_rc, ω, Ω̇ / IDOT, data sources, GAL
    /// week, spare / SISA (m), SV health, BGD E5a/E1, BGD E5b/E1 / transmission time, spare.
    /// BeiDou: AODE … / IDOT, spare, BDT week, spare / URA (m), SatH1, T_GD1 B1/B3, T_GD2
    /// B2/B3 / transmission time, AODC. Of ORBIT 7 the first two are written and read.
    pub orbit: [[f64; 4]; 7],
}

/// An observation file.
#[derive(Debug, Clone)]
pub struct ObsFile {
    /// Format version (2.10, 2.11, 3.05 …).
    pub version: f64,
    /// Header `APPROX POSITION XYZ`, ECEF m.
    pub approx_ecef_m: Option<[f64; 3]>,
    /// Header `LEAP SECONDS` (GPS − UTC, s).
    pub leap_s: Option<i16>,
    /// One sample per epoch (flags 0 and 1), `stamp` zero (the caller stamps).
    pub epochs: Vec<GnssRaw>,
    /// Observations without a signal id ([`SIGNALS`]: L1 P(Y) …), not kept.
    pub unmapped: u64,
    /// GLONASS channel of each slot (index 1–24) from `GLONASS SLOT / FRQ #`, if given.
    pub glonass_channels: [Option<i8>; 25],
}

impl ObsFile {
    /// Gives the GLONASS measurements without a channel the one of `channels` (by slot, e.g.
    /// a navigation file's); returns how many are still without one.
    pub fn fill_glonass_channels(&mut self, channels: &[Option<i8>; 25]) -> u64 {
        let mut left = 0;
        for e in &mut self.epochs {
            let n = usize::from(e.num_meas);
            for m in e.meas[..n]
                .iter_mut()
                .filter(|m| m.gnss_id == 6 && m.freq_id == GLONASS_CHANNEL_UNKNOWN)
            {
                match channels.get(usize::from(m.sv_id)).copied().flatten() {
                    Some(k) => m.freq_id = (k + 7) as u8,
                    None => left += 1,
                }
            }
        }
        left
    }
}

/// A GLONASS broadcast ephemeris (RINEX 2.11 Table A11, RINEX 3.05 Table A10) in SI units.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GloRecord {
    /// Slot number n (RINEX `Rnn`).
    pub slot: u8,
    /// Line of the record in the file.
    pub line: usize,
    /// t_b (the record's epoch, UTC in the file) as a GPS time.
    pub toc: GpsTime,
    /// t_b as a UTC time of day, s (0–86 400).
    pub toc_utc_sod_s: f64,
    /// Days since 1970-01-01 of t_b's UTC date.
    pub toc_utc_day: i64,
    /// τ_n, s (RINEX gives −τ_n, the "SV clock bias").
    pub tau_s: f64,
    /// γ_n (relative frequency bias).
    pub gamma: f64,
    /// t_k, the message frame time, s of the UTC day.
    pub tk_s: f64,
    /// Position at t_b, PZ-90, m (RINEX: km).
    pub pos_m: [f64; 3],
    /// Velocity, m/s.
    pub vel_mps: [f64; 3],
    /// Lunisolar acceleration, m/s².
    pub acc_mps2: [f64; 3],
    /// Health: 0 healthy (the most significant bit of B_n).
    pub health: f64,
    /// Frequency channel k, −7…+6.
    pub channel: i8,
    /// Age of the operational information E_n, days.
    pub age_days: f64,
    /// F_T, the accuracy index (RINEX 3.05 line 5, URAI), when given.
    pub accuracy_index: Option<u8>,
}

/// A GPS broadcast ephemeris in RINEX units (RINEX 2.11 Table A4, RINEX 3.05 Table A8).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GpsEphemeris {
    /// PRN.
    pub prn: u8,
    /// Line of the record in the file.
    pub line: usize,
    /// t_oc as a GPS time.
    pub toc_week: u32,
    /// t_oc, s of week.
    pub toc_s: f64,
    /// Clock bias a_f0 (s), drift a_f1 (s/s), drift rate a_f2 (s/s²).
    pub af: [f64; 3],
    /// IODE.
    pub iode: f64,
    /// C_rs, m.
    pub crs: f64,
    /// Δn, rad/s.
    pub delta_n: f64,
    /// M_0, rad.
    pub m0: f64,
    /// C_uc, rad.
    pub cuc: f64,
    /// Eccentricity.
    pub e: f64,
    /// C_us, rad.
    pub cus: f64,
    /// √A, √m.
    pub sqrt_a: f64,
    /// t_oe, s of GPS week.
    pub toe_s: f64,
    /// C_ic, rad.
    pub cic: f64,
    /// Ω_0, rad.
    pub omega0: f64,
    /// C_is, rad.
    pub cis: f64,
    /// i_0, rad.
    pub i0: f64,
    /// C_rc, m.
    pub crc: f64,
    /// ω, rad.
    pub omega: f64,
    /// Ω̇, rad/s.
    pub omega_dot: f64,
    /// IDOT, rad/s.
    pub idot: f64,
    /// Codes on L2.
    pub l2_codes: f64,
    /// GPS week of t_oe (continuous, not mod 1024).
    pub week: f64,
    /// L2 P data flag.
    pub l2p: f64,
    /// SV accuracy (URA), m.
    pub accuracy_m: f64,
    /// SV health.
    pub health: f64,
    /// T_GD, s.
    pub tgd_s: f64,
    /// IODC.
    pub iodc: f64,
    /// Transmission time of message, s of week.
    pub tx_time_s: f64,
    /// Fit interval, h (0 when not given).
    pub fit_h: f64,
}

/// A navigation file's GPS content.
#[derive(Debug, Clone, Default)]
pub struct NavFile {
    /// Format version.
    pub version: f64,
    /// Klobuchar α_0..α_3 (s, s/semicircle, s/semicircle², s/semicircle³), if in the header.
    pub iono_alpha: Option<[f64; 4]>,
    /// Klobuchar β_0..β_3 (s, s/semicircle, …), if in the header.
    pub iono_beta: Option<[f64; 4]>,
    /// GPS ephemerides in file order.
    pub ephemerides: Vec<GpsEphemeris>,
    /// GLONASS ephemerides in file order.
    pub glonass: Vec<GloRecord>,
    /// Galileo and BeiDou ephemerides in file order (RINEX 3).
    pub kepler: Vec<KeplerRecord>,
    /// BeiDou's Klobuchar α and β (`IONOSPHERIC CORR` BDSA/BDSB), if in the header.
    pub bds_iono: Option<([f64; 4], [f64; 4])>,
    /// Records of other systems (SBAS, QZSS, NavIC), skipped.
    pub other_systems: u64,
}

impl NavFile {
    /// The GLONASS channel of each slot (index 1–24) its records give.
    pub fn glonass_channels(&self) -> [Option<i8>; 25] {
        let mut out = [None; 25];
        for r in &self.glonass {
            if let Some(c) = out.get_mut(usize::from(r.slot)) {
                *c = Some(r.channel);
            }
        }
        out
    }
}

/// Lines of one file with their numbers, for errors.
struct Lines<'a> {
    file: &'a str,
    lines: Vec<&'a str>,
    next: usize,
}

impl<'a> Lines<'a> {
    fn new(file: &'a str, text: &'a str) -> Self {
        Self {
            file,
            lines: text.lines().map(|l| l.trim_end_matches('\r')).collect(),
            next: 0,
        }
    }
    /// The next line and its number (1-based).
    fn next(&mut self) -> Option<(usize, &'a str)> {
        let l = self.lines.get(self.next)?;
        self.next += 1;
        Some((self.next, l))
    }
    fn err(&self, line: usize, field: &str, problem: impl Into<String>) -> RinexError {
        RinexError {
            file: self.file.to_string(),
            line,
            field: field.to_string(),
            problem: problem.into(),
        }
    }
    /// The next line, or an error saying the file ended inside `what`.
    fn need(&mut self, what: &str) -> Result<(usize, &'a str), RinexError> {
        let n = self.lines.len();
        self.next()
            .ok_or_else(|| self.err(n, what, "the file ends inside the record"))
    }
}

/// Columns `a..b` (0-based, clipped to the line).
fn col(line: &str, a: usize, b: usize) -> &str {
    let b = b.min(line.len());
    line.get(a.min(b)..b).unwrap_or("")
}

/// A Fortran number (`D` exponents allowed); blank is `None`.
fn number(s: &str) -> Result<Option<f64>, String> {
    let t = s.trim();
    if t.is_empty() {
        return Ok(None);
    }
    t.replace(['D', 'd'], "E")
        .parse::<f64>()
        .map(Some)
        .map_err(|_| format!("'{t}' is not a number"))
}

/// The GPS time of a calendar date and time of day (GPS time scale).
pub fn gps_time(year: i64, month: u32, day: u32, hour: u32, min: u32, sec: f64) -> GpsTime {
    let days = days_from_civil(year, month, day) - days_from_civil(1980, 1, 6);
    let s = days as f64 * 86_400.0 + f64::from(hour * 3600 + min * 60) + sec;
    let week = (s / WEEK_S).floor();
    GpsTime {
        week: week as u32,
        tow_s: s - week * WEEK_S,
    }
}

/// A two-digit RINEX 2 year (80–99: 19xx, else 20xx).
fn full_year(y: i64) -> i64 {
    match y {
        0..=79 => 2000 + y,
        80..=99 => 1900 + y,
        _ => y,
    }
}

/// Parses a date and time from whitespace-separated fields `y m d h min s`.
fn epoch_fields(lines: &Lines<'_>, n: usize, field: &str, text: &str) -> Result<GpsTime, RinexError> {
    let v: Vec<&str> = text.split_whitespace().collect();
    let bad = || {
        lines.err(
            n,
            field,
            format!("'{}' is not 'year month day hour minute second'", text.trim()),
        )
    };
    if v.len() != 6 {
        return Err(bad());
    }
    let i = |k: usize| v[k].parse::<i64>().map_err(|_| bad());
    let (y, mo, d, h, mi) = (i(0)?, i(1)?, i(2)?, i(3)?, i(4)?);
    let s = v[5].parse::<f64>().map_err(|_| bad())?;
    let ok = (1980..=2100).contains(&full_year(y))
        && (1..=12).contains(&mo)
        && (1..=31).contains(&d)
        && (0..24).contains(&h)
        && (0..60).contains(&mi);
    if !ok || !(0.0..61.0).contains(&s) {
        return Err(bad());
    }
    Ok(gps_time(full_year(y), mo as u32, d as u32, h as u32, mi as u32, s))
}

/// The header's version and file type (`RINEX VERSION / TYPE`), checked to be `want`.
fn version_line(lines: &mut Lines<'_>, want: char) -> Result<(f64, char), RinexError> {
    let Some((n, l)) = lines.next() else {
        return Err(lines.err(1, "RINEX VERSION / TYPE", "empty file"));
    };
    if col(l, 60, 80).trim() != "RINEX VERSION / TYPE" {
        return Err(lines.err(n, "RINEX VERSION / TYPE", "the first line is not the version line"));
    }
    let version = number(col(l, 0, 9))
        .ok()
        .flatten()
        .ok_or_else(|| lines.err(n, "RINEX VERSION / TYPE", "no version number"))?;
    let kind = col(l, 20, 21).chars().next().unwrap_or(' ');
    if kind != want {
        return Err(lines.err(
            n,
            "RINEX VERSION / TYPE",
            format!("file type '{kind}', expected '{want}'"),
        ));
    }
    if !(2.0..4.0).contains(&version) {
        return Err(lines.err(
            n,
            "RINEX VERSION / TYPE",
            format!("version {version}: 2.xx or 3.xx supported"),
        ));
    }
    // The satellite system (col 41): RINEX 2 nav files have none (GPS), 3.xx 'G', 'M', …
    let system = col(l, 40, 41).chars().next().unwrap_or(' ');
    Ok((version, system))
}

/// RINEX 3 signals (system letter, band digit, attribute; RINEX 3.05 §5.1, Tables 4–10) and
/// their u-blox (gnssId, sigId) (u-blox interface description, "Signal identifiers"): the one
/// table both directions use, [`ublox_signal`] (import) and [`rinex_signal`] (export). Where two
/// RINEX codes name one u-blox signal (BeiDou B1I: C2I since RINEX 3.02, C1I before) the first
/// is the one written; where one RINEX code names two u-blox signals (BeiDou's D1 and D2 of one
/// band: the code is the band's, D2 the GEO satellites' message; the `X` codes of two
/// components tracked together, RINEX 3.05 §5.1, as RTKLIB writes a u-blox receiver's
/// signals: read as the band's first u-blox signal) the first is the one read. GPS L2 P(Y)
/// (`C2W`, RINEX 2 `P2`), which u-blox receivers do not report, has navsync's own id
/// [`SIG_GPS_L2_PY`].
pub const SIGNALS: [(char, char, char, u8, u8); 31] = [
    ('G', '1', 'C', 0, 0),
    ('G', '2', 'L', 0, 3),
    ('G', '2', 'S', 0, 4),
    ('G', '5', 'I', 0, 6),
    ('G', '5', 'Q', 0, 7),
    ('S', '1', 'C', 1, 0),
    ('E', '1', 'C', 2, 0),
    ('E', '1', 'B', 2, 1),
    ('E', '5', 'I', 2, 3),
    ('E', '5', 'Q', 2, 4),
    ('E', '7', 'I', 2, 5),
    ('E', '7', 'Q', 2, 6),
    ('C', '2', 'I', 3, 0),
    ('C', '1', 'I', 3, 0),
    ('C', '7', 'I', 3, 2),
    ('C', '6', 'I', 3, 4),
    ('C', '2', 'I', 3, 1),
    ('C', '7', 'I', 3, 3),
    ('C', '6', 'I', 3, 10),
    ('G', '2', 'X', 0, 3),
    ('G', '5', 'X', 0, 6),
    ('E', '1', 'X', 2, 0),
    ('E', '5', 'X', 2, 3),
    ('E', '7', 'X', 2, 5),
    ('J', '2', 'X', 5, 4),
    ('J', '1', 'C', 5, 0),
    ('J', '2', 'S', 5, 4),
    ('J', '2', 'L', 5, 5),
    ('R', '1', 'C', 6, 0),
    ('R', '2', 'C', 6, 2),
    ('G', '2', 'W', 0, SIG_GPS_L2_PY),
];

/// The u-blox (gnssId, sigId) of a RINEX 3 signal: system letter, band digit, attribute
/// ([`SIGNALS`]); `None` for signals without an id there (GPS L1 P(Y) …).
pub fn ublox_signal(system: char, band: char, attribute: char) -> Option<(u8, u8)> {
    SIGNALS
        .iter()
        .find(|s| (s.0, s.1, s.2) == (system, band, attribute))
        .map(|s| (s.3, s.4))
}

/// The RINEX 3 signal (system letter, band digit, attribute) of a u-blox (gnssId, sigId)
/// ([`SIGNALS`], the inverse of [`ublox_signal`]); `None` for one the table does not hold.
pub fn rinex_signal(gnss_id: u8, sig_id: u8) -> Option<(char, char, char)> {
    SIGNALS
        .iter()
        .find(|s| (s.3, s.4) == (gnss_id, sig_id))
        .map(|s| (s.0, s.1, s.2))
}

/// A RINEX 2 observation type as the RINEX 3 code it means (RINEX 3.05 §5.1 and Table A2 of
/// 2.11: C1 is C/A code, P1/P2 are P(Y), L1/L2/D1/D2/S1/S2 follow the code tracked: C/A on
/// L1, P(Y) on L2; C2 is L2C, C5/L5 are L5).
fn v3_code_of_v2(t: &str) -> Option<[char; 3]> {
    let mut c = t.chars();
    let (kind, band) = (c.next()?, c.next()?);
    let attribute = match (kind, band) {
        ('P', '1' | '2') => 'W',
        ('C', '1') => 'C',
        ('C', '2' | '5' | '7' | '8' | '6') => 'X',
        (_, '1') => 'C',
        (_, '2') => 'W',
        _ => 'X',
    };
    let kind = if kind == 'P' { 'C' } else { kind };
    Some([kind, band, attribute])
}

/// The observation types of a system: each as its RINEX 3 code and as the header wrote it.
type ObsTypes = Vec<([char; 3], String)>;

/// Per system letter, its observation types (RINEX 2: one list for all systems).
#[derive(Default)]
struct TypeTable {
    v2: ObsTypes,
    v3: Vec<(char, ObsTypes)>,
}

impl TypeTable {
    fn of(&self, system: char) -> Option<&ObsTypes> {
        if self.v3.is_empty() {
            Some(&self.v2)
        } else {
            self.v3.iter().find(|(s, _)| *s == system).map(|(_, t)| t)
        }
    }
}

/// Parses an observation file (`file` names it in errors).
pub fn parse_obs(file: &str, text: &str) -> Result<ObsFile, RinexError> {
    let mut lines = Lines::new(file, text);
    let (version, _) = version_line(&mut lines, 'O')?;
    let mut out = ObsFile {
        version,
        approx_ecef_m: None,
        leap_s: None,
        epochs: Vec::new(),
        unmapped: 0,
        glonass_channels: [None; 25],
    };
    let mut types = TypeTable::default();
    let (mut v2_count, mut v3_pending): (usize, Option<(char, usize)>) = (0, None);
    loop {
        let Some((n, l)) = lines.next() else {
            return Err(lines.err(lines.lines.len(), "END OF HEADER", "no end of header"));
        };
        let label = col(l, 60, 80).trim();
        let num = |a, b, field: &str| -> Result<f64, RinexError> {
            number(col(l, a, b))
                .map_err(|p| lines.err(n, field, p))?
                .ok_or_else(|| lines.err(n, field, "blank"))
        };
        match label {
            "END OF HEADER" => break,
            "APPROX POSITION XYZ" => {
                out.approx_ecef_m = Some([
                    num(0, 14, "APPROX POSITION XYZ")?,
                    num(14, 28, "APPROX POSITION XYZ")?,
                    num(28, 42, "APPROX POSITION XYZ")?,
                ]);
            }
            "LEAP SECONDS" => out.leap_s = Some(num(0, 6, label)? as i16),
            // RINEX 3.05 Table A2: up to 8 of `Rnn k` per line after the count (columns 1–3).
            "GLONASS SLOT / FRQ #" => {
                for j in 0..8 {
                    let sat = col(l, 4 + 7 * j, 7 + 7 * j).trim();
                    if sat.is_empty() {
                        break;
                    }
                    let (sys, slot) = sat_id(&lines, n, sat)?;
                    let k = col(l, 7 + 7 * j, 10 + 7 * j)
                        .trim()
                        .parse::<i8>()
                        .ok()
                        .filter(|k| (-7..=6).contains(k));
                    let Some(k) = k.filter(|_| sys == 'R') else {
                        return Err(lines.err(
                            n,
                            label,
                            format!(
                                "'{}' is not a GLONASS slot and channel −7…+6",
                                col(l, 4 + 7 * j, 10 + 7 * j)
                            ),
                        ));
                    };
                    if let Some(c) = out.glonass_channels.get_mut(usize::from(slot)) {
                        *c = Some(k);
                    }
                }
            }
            "TIME OF FIRST OBS" => {
                let sys = col(l, 48, 51).trim();
                if !sys.is_empty() && sys != "GPS" {
                    return Err(lines.err(n, label, format!("time system {sys}: only GPS time is supported")));
                }
            }
            "# / TYPES OF OBSERV" => {
                if !col(l, 0, 6).trim().is_empty() {
                    v2_count = num(0, 6, label)? as usize;
                }
                for k in 0..9 {
                    let t = col(l, 10 + 6 * k, 12 + 6 * k).trim();
                    if types.v2.len() < v2_count && !t.is_empty() {
                        let code = v3_code_of_v2(t).ok_or_else(|| lines.err(n, label, format!("type '{t}'")))?;
                        types.v2.push((code, t.to_string()));
                    }
                }
            }
            "SYS / # / OBS TYPES" => {
                let sys = col(l, 0, 1).chars().next().unwrap_or(' ');
                if sys != ' ' {
                    let count = num(3, 6, label)? as usize;
                    types.v3.push((sys, Vec::with_capacity(count)));
                    v3_pending = Some((sys, count));
                }
                let Some((_, count)) = v3_pending else {
                    return Err(lines.err(n, label, "a continuation line without a system"));
                };
                let list = &mut types.v3.last_mut().expect("pushed above").1;
                for k in 0..13 {
                    let t: Vec<char> = col(l, 7 + 4 * k, 10 + 4 * k).chars().collect();
                    if list.len() < count && t.len() == 3 {
                        list.push(([t[0], t[1], t[2]], t.iter().collect()));
                    }
                }
            }
            _ => {}
        }
    }
    if types.v2.is_empty() && types.v3.is_empty() {
        return Err(lines.err(lines.next, "# / TYPES OF OBSERV", "no observation types in the header"));
    }
    let v3 = version >= 3.0;
    let mut locks = LockTimes::new();
    while let Some((n, l)) = lines.next() {
        if l.trim().is_empty() {
            continue;
        }
        let (time_text, flag_col, count_cols, sats_at) = if v3 {
            if !l.starts_with('>') {
                return Err(lines.err(n, "EPOCH", "an epoch record starts with '>'"));
            }
            (col(l, 1, 29), 31, (32, 35), None)
        } else {
            (col(l, 0, 26), 28, (29, 32), Some(32))
        };
        let flag = col(l, flag_col, flag_col + 1).trim();
        let count = col(l, count_cols.0, count_cols.1)
            .trim()
            .parse::<usize>()
            .map_err(|_| {
                lines.err(
                    n,
                    "number of satellites",
                    format!("'{}'", col(l, count_cols.0, count_cols.1)),
                )
            })?;
        if !matches!(flag, "" | "0" | "1") {
            // An event (2–5: header records follow) or a cycle-slip record (6): skip `count` lines.
            for _ in 0..count {
                lines.need("event record")?;
            }
            continue;
        }
        let t = epoch_fields(&lines, n, "epoch", time_text)?;
        // RINEX 2: satellite list on the epoch line (12 per line, continued from column 33).
        let mut sats: Vec<(char, u8)> = Vec::with_capacity(count);
        if let Some(at) = sats_at {
            let mut line = (n, l);
            for k in 0..count {
                if k > 0 && k % 12 == 0 {
                    line = lines.need("satellite list")?;
                }
                let s = col(line.1, at + 3 * (k % 12), at + 3 * (k % 12) + 3);
                sats.push(sat_id(&lines, line.0, s)?);
            }
        }
        let mut raw = GnssRaw::zeroed();
        raw.rcv_tow_s = t.tow_s;
        raw.week = t.week as u16;
        if let Some(leap) = out.leap_s {
            raw.leap_s = leap;
            raw.rec_stat |= 1;
        }
        let mut meas: Vec<RawMeasurement> = Vec::new();
        let mut listed = sats.iter();
        for _ in 0..count {
            // RINEX 3: one line per satellite, its id first.
            let (sat, first) = if v3 {
                let (m, line) = lines.need("observation record")?;
                (sat_id(&lines, m, col(line, 0, 3))?, Some((m, line)))
            } else {
                (*listed.next().expect("count satellites listed"), None)
            };
            let Some(list) = types.of(sat.0) else {
                return Err(lines.err(n, "satellite", format!("system '{}' has no observation types", sat.0)));
            };
            // The values, 16 columns each: RINEX 3 after the id on one line, RINEX 2 five per line.
            let mut values: Vec<(Option<f64>, u8)> = Vec::with_capacity(list.len());
            let mut current = first;
            for (j, (_, name)) in list.iter().enumerate() {
                let (m, line, at) = if let Some((m, line)) = first {
                    (m, line, 3 + 16 * j)
                } else {
                    if j % 5 == 0 {
                        current = Some(lines.need("observation record")?);
                    }
                    let (m, line) = current.expect("set above");
                    (m, line, 16 * (j % 5))
                };
                let v = number(col(line, at, at + 14)).map_err(|p| lines.err(m, name, p))?;
                let lli = col(line, at + 14, at + 15).trim().parse::<u8>().unwrap_or(0);
                values.push((v, lli));
            }
            let now_s = f64::from(t.week) * 604_800.0 + t.tow_s;
            signals(sat, list, &values, (now_s, &mut locks), &mut meas, &mut out.unmapped);
        }
        // By `keep_rank` (what a full epoch keeps first), GPS L1 C/A first, then by system,
        // signal and satellite.
        meas.sort_by_key(|m| {
            (
                m.keep_rank(),
                m.gnss_id != 0 || m.sig_id != 0,
                m.gnss_id,
                m.sig_id,
                m.sv_id,
            )
        });
        raw.dropped = meas.len().saturating_sub(MAX_RAW_MEASUREMENTS).min(255) as u8;
        for (slot, m) in raw.meas.iter_mut().zip(&meas) {
            *slot = *m;
        }
        raw.num_meas = meas.len().min(MAX_RAW_MEASUREMENTS) as u8;
        out.epochs.push(raw);
    }
    let channels = out.glonass_channels;
    out.fill_glonass_channels(&channels);
    Ok(out)
}

/// A satellite id `Gnn` (RINEX 2: a blank system is GPS).
fn sat_id(lines: &Lines<'_>, n: usize, s: &str) -> Result<(char, u8), RinexError> {
    let mut c = s.chars();
    let system = match c.next() {
        Some(' ') | None => 'G',
        Some(x) => x,
    };
    let prn = c
        .as_str()
        .trim()
        .parse::<u8>()
        .map_err(|_| lines.err(n, "satellite", format!("'{s}' is not a satellite id")))?;
    Ok((system, prn))
}

/// Per signal (u-blox gnss, sv, sig): the time of its last carrier phase (GPS weeks × 604 800
/// + seconds of week, s) and its lock time then, ms.
pub(crate) type LockTimes = std::collections::HashMap<(u8, u8, u8), (f64, u16)>;

/// The measurements of one satellite: one per signal (band and attribute) with a u-blox id.
/// A carrier phase's lock time (u-blox `locktime`, which RINEX does not carry) is the time
/// since the signal's first phase or the last one whose loss-of-lock indicator had bit 0 set
/// (RINEX 3.05 §5.7: lost lock since the previous observation, a cycle slip possible); `now`
/// is the epoch's time and the signals' lock history.
fn signals(
    sat: (char, u8),
    types: &ObsTypes,
    values: &[(Option<f64>, u8)],
    now: (f64, &mut LockTimes),
    out: &mut Vec<RawMeasurement>,
    unmapped: &mut u64,
) {
    let (now_s, locks) = now;
    let mut seen: Vec<(char, char)> = Vec::new();
    for ((t, _), (v, _)) in types.iter().zip(values) {
        if v.is_some() && !seen.contains(&(t[1], t[2])) {
            seen.push((t[1], t[2]));
        }
    }
    for (band, attribute) in seen {
        let Some((gnss_id, sig_id)) = ublox_signal(sat.0, band, attribute) else {
            *unmapped += 1;
            continue;
        };
        let get = |kind: char| {
            types
                .iter()
                .zip(values)
                .find(|((t, _), _)| t[0] == kind && t[1] == band && t[2] == attribute)
                .and_then(|(_, (v, lli))| v.map(|v| (v, *lli)))
        };
        let mut m = RawMeasurement::zeroed();
        (m.gnss_id, m.sv_id, m.sig_id) = (gnss_id, sat.1, sig_id);
        if gnss_id == 6 {
            m.freq_id = GLONASS_CHANNEL_UNKNOWN;
        }
        m.pseudorange_m = f64::NAN;
        m.carrier_phase_cycles = f64::NAN;
        m.doppler_hz = f32::NAN;
        if let Some((pr, _)) = get('C').filter(|(pr, _)| *pr > 0.0) {
            m.pseudorange_m = pr;
            m.trk_stat |= 1;
        }
        if let Some((cp, lli)) = get('L').filter(|(cp, _)| *cp != 0.0) {
            m.carrier_phase_cycles = cp;
            // Carrier valid; half cycle resolved unless the LLI's bit 1 says otherwise.
            m.trk_stat |= if lli & 2 == 0 { 0b110 } else { 0b010 };
            let key = (gnss_id, sat.1, sig_id);
            let lock_ms = match locks.get(&key) {
                Some(&(then_s, lock)) if lli & 1 == 0 && now_s > then_s => {
                    (f64::from(lock) + 1000.0 * (now_s - then_s)).min(f64::from(LOCK_TIME_MAX_MS))
                }
                _ => 0.0,
            };
            m.lock_time_ms = lock_ms as u16;
            locks.insert(key, (now_s, m.lock_time_ms));
        }
        if let Some((d, _)) = get('D') {
            m.doppler_hz = d as f32;
        }
        if let Some((s, _)) = get('S') {
            m.cno_dbhz = s.round().clamp(0.0, 255.0) as u8;
        }
        out.push(m);
    }
}

/// Parses a navigation file's GPS and GLONASS records and its ionosphere (`file` names it in
/// errors): RINEX 3 GPS, GLONASS or mixed files, RINEX 2 GPS (`N`) or GLONASS (`G`) files.
pub fn parse_nav(file: &str, text: &str) -> Result<NavFile, RinexError> {
    let mut lines = Lines::new(file, text);
    let glonass_v2 = lines.lines.first().is_some_and(|l| col(l, 20, 21) == "G");
    let (version, system) = version_line(&mut lines, if glonass_v2 { 'G' } else { 'N' })?;
    let v3 = version >= 3.0;
    if v3 && !matches!(system, 'G' | 'M' | 'R' | 'E' | 'C') {
        return Err(lines.err(
            1,
            "RINEX VERSION / TYPE",
            format!("system '{system}': GPS, GLONASS, Galileo, BeiDou or mixed expected"),
        ));
    }
    let (mut bds_alpha, mut bds_beta) = (None, None);
    let mut out = NavFile {
        version,
        ..NavFile::default()
    };
    loop {
        let Some((n, l)) = lines.next() else {
            return Err(lines.err(lines.lines.len(), "END OF HEADER", "no end of header"));
        };
        let label = col(l, 60, 80).trim();
        let four = |at: usize, field: &str| -> Result<[f64; 4], RinexError> {
            let mut v = [0.0; 4];
            for (k, x) in v.iter_mut().enumerate() {
                *x = number(col(l, at + 12 * k, at + 12 * (k + 1)))
                    .map_err(|p| lines.err(n, field, p))?
                    .ok_or_else(|| lines.err(n, field, format!("coefficient {k} blank")))?;
            }
            Ok(v)
        };
        match label {
            "END OF HEADER" => {
                out.bds_iono = bds_alpha.zip(bds_beta);
                break;
            }
            "ION ALPHA" => out.iono_alpha = Some(four(2, label)?),
            "ION BETA" => out.iono_beta = Some(four(2, label)?),
            "IONOSPHERIC CORR" => match col(l, 0, 4) {
                "GPSA" => out.iono_alpha = Some(four(5, "IONOSPHERIC CORR GPSA")?),
                "GPSB" => out.iono_beta = Some(four(5, "IONOSPHERIC CORR GPSB")?),
                "BDSA" => bds_alpha = Some(four(5, "IONOSPHERIC CORR BDSA")?),
                "BDSB" => bds_beta = Some(four(5, "IONOSPHERIC CORR BDSB")?),
                _ => {}
            },
            _ => {}
        }
    }
    while let Some((n, l)) = lines.next() {
        if l.trim().is_empty() {
            continue;
        }
        // RINEX 3: 'Gnn yyyy mm dd hh mm ss' then 3 × D19.12 from column 24; other systems'
        // records have 4 lines (SBAS) or 8 (GLONASS: `glonass_record`). RINEX 2: 'nn yy mm dd hh mm ss.s' to 22.
        if (v3 && col(l, 0, 1) == "R") || (!v3 && glonass_v2) {
            out.glonass.push(glonass_record(&mut lines, n, l, v3)?);
            continue;
        }
        let (prn_text, time_text, first) = if v3 {
            let sys = col(l, 0, 1);
            if sys == "E" || sys == "C" {
                out.kepler.push(kepler_record(&mut lines, n, l)?);
                continue;
            }
            if sys != "G" {
                let more = if sys == "S" { 3 } else { 7 };
                for _ in 0..more {
                    lines.need("navigation record")?;
                }
                out.other_systems += 1;
                continue;
            }
            (col(l, 1, 3), col(l, 4, 23), 23)
        } else {
            (col(l, 0, 2), col(l, 3, 22), 22)
        };
        let prn = prn_text
            .trim()
            .parse::<u8>()
            .ok()
            .filter(|p| (1..=32).contains(p))
            .ok_or_else(|| lines.err(n, "PRN", format!("'{prn_text}' is not a GPS PRN")))?;
        let toc = epoch_fields(&lines, n, "toc", time_text)?;
        // 3 values on the first line, 4 on each of the 7 orbit lines (the last may be short).
        let names = record_names(
            ["af0", "af1", "af2", "IODE"],
            [
                "L2 codes",
                "GPS week",
                "L2 P flag",
                "SV accuracy",
                "SV health",
                "TGD",
                "IODC",
                "transmission time",
                "fit interval",
                "spare",
                "spare",
            ],
        );
        let indent = if v3 { 4 } else { 3 };
        let v = record_values(&mut lines, (n, l, first), indent, &names, "broadcast orbit")?;
        let e = GpsEphemeris {
            prn,
            line: n,
            toc_week: toc.week,
            toc_s: toc.tow_s,
            af: [v[0], v[1], v[2]],
            iode: v[3],
            crs: v[4],
            delta_n: v[5],
            m0: v[6],
            cuc: v[7],
            e: v[8],
            cus: v[9],
            sqrt_a: v[10],
            toe_s: v[11],
            cic: v[12],
            omega0: v[13],
            cis: v[14],
            i0: v[15],
            crc: v[16],
            omega: v[17],
            omega_dot: v[18],
            idot: v[19],
            l2_codes: v[20],
            week: v[21],
            l2p: v[22],
            accuracy_m: v[23],
            health: v[24],
            tgd_s: v[25],
            iodc: v[26],
            tx_time_s: v[27],
            fit_h: v[28],
        };
        if e.sqrt_a <= 0.0 || !(0.0..1.0).contains(&e.e) || !(0.0..WEEK_S).contains(&e.toe_s) {
            return Err(lines.err(n, "broadcast orbit", "sqrt(A), e or Toe out of range"));
        }
        if !(0.0..=6000.0).contains(&e.week) {
            return Err(lines.err(n, "GPS week", format!("{} is not a GPS week", e.week)));
        }
        out.ephemerides.push(e);
    }
    Ok(out)
}

/// The names of a GPS, Galileo or BeiDou record's 31 values (for errors): the clock and issue
/// `head`, the Keplerian orbit the three share (ORBIT 1–4 after the issue, and IDOT), then the
/// system's own `tail`.
fn record_names(head: [&'static str; 4], tail: [&'static str; 11]) -> [&'static str; 31] {
    const ORBIT: [&str; 16] = [
        "Crs",
        "Delta n",
        "M0",
        "Cuc",
        "e",
        "Cus",
        "sqrt(A)",
        "Toe",
        "Cic",
        "OMEGA0",
        "Cis",
        "i0",
        "Crc",
        "omega",
        "OMEGA DOT",
        "IDOT",
    ];
    let mut out = [""; 31];
    for (o, n) in out.iter_mut().zip(head.iter().chain(&ORBIT).chain(&tail)) {
        *o = n;
    }
    out
}

/// One Galileo or BeiDou record (RINEX 3) from its first line `l` (line `n`): `Ennn`/`Cnn`,
/// t_oc as a calendar epoch of GST (GPS's calendar) or BDT, the clock, then seven orbit lines
/// ([`KeplerRecord`]).
fn kepler_record(lines: &mut Lines<'_>, n: usize, l: &str) -> Result<KeplerRecord, RinexError> {
    let system = col(l, 0, 1).chars().next().unwrap_or(' ');
    let (max, what) = if system == 'E' {
        (36, "Galileo SVID")
    } else {
        (63, "BeiDou PRN")
    };
    let sv_text = col(l, 1, 3);
    let sv = sv_text
        .trim()
        .parse::<u8>()
        .ok()
        .filter(|p| (1..=max).contains(p))
        .ok_or_else(|| lines.err(n, "PRN", format!("'{sv_text}' is not a {what}")))?;
    // The epoch in the system's own calendar: BDT's weeks count from GPS week 1356.
    let toc = epoch_fields(lines, n, "toc", col(l, 4, 23))?;
    let offset = if system == 'C' { BDT_WEEK_OFFSET } else { 0 };
    let toc_week = toc
        .week
        .checked_sub(offset)
        .ok_or_else(|| lines.err(n, "toc", "before the BDT epoch (2006-01-01)"))?;
    let names = if system == 'E' {
        record_names(
            ["af0", "af1", "af2", "IODnav"],
            [
                "data sources",
                "GAL week",
                "spare",
                "SISA",
                "SV health",
                "BGD E5a/E1",
                "BGD E5b/E1",
                "transmission time",
                "spare",
                "spare",
                "spare",
            ],
        )
    } else {
        record_names(
            ["a0", "a1", "a2", "AODE"],
            [
                "spare",
                "BDT week",
                "spare",
                "SV accuracy",
                "SatH1",
                "TGD1",
                "TGD2",
                "transmission time",
                "AODC",
                "spare",
                "spare",
            ],
        )
    };
    let v = record_values(lines, (n, l, 23), 4, &names, "broadcast orbit")?;
    let mut orbit = [[0.0; 4]; 7];
    for (k, x) in v[3..].iter().enumerate() {
        orbit[k / 4][k % 4] = *x;
    }
    if v[10] <= 0.0 || !(0.0..1.0).contains(&v[8]) || !(0.0..WEEK_S).contains(&v[11]) {
        return Err(lines.err(n, "broadcast orbit", "sqrt(A), e or Toe out of range"));
    }
    if !(0.0..=6000.0).contains(&v[21]) || v[21].fract() != 0.0 {
        return Err(lines.err(n, names[21], format!("{} is not a week", v[21])));
    }
    Ok(KeplerRecord {
        line: n,
        system,
        sv,
        toc_week,
        toc_s: toc.tow_s,
        af: [v[0], v[1], v[2]],
        orbit,
    })
}

/// The `K` values of a navigation record (blank: 0): 3 on its first line `(n, l)` from column
/// `first`, then 4 per orbit line from column `indent` (the last may be short), each D19.12,
/// named by `names` in errors.
fn record_values<const K: usize>(
    lines: &mut Lines<'_>,
    (n, l, first): (usize, &str, usize),
    indent: usize,
    names: &[&str; K],
    what: &str,
) -> Result<[f64; K], RinexError> {
    let mut v = [0.0f64; K];
    let (mut m, mut line, mut at, mut per_line) = (n, l, first, 3);
    let mut k = 0;
    while k < K {
        for j in 0..per_line.min(K - k) {
            let a = at + 19 * j;
            v[k + j] = number(col(line, a, a + 19))
                .map_err(|p| lines.err(m, names[k + j], p))?
                .unwrap_or(0.0);
        }
        k += per_line;
        if k < K {
            (m, line) = lines.need(what)?;
            (at, per_line) = (indent, 4);
        }
    }
    Ok(v)
}

/// One GLONASS record from its first line `l` (line `n`): RINEX 3 `Rnn yyyy mm dd hh mm ss`
/// or RINEX 2 `nn yy mm dd hh mm ss.s`, −τ_n, γ_n, t_k; three orbit lines of x, ẋ, ẍ (km,
/// km/s, km/s²) with health, channel and age; in RINEX 3.05 a fourth (status, L1/L2 delay,
/// URAI, health flags) when the next line is a continuation.
fn glonass_record(lines: &mut Lines<'_>, n: usize, l: &str, v3: bool) -> Result<GloRecord, RinexError> {
    let (slot_text, time_text, first, indent) = if v3 {
        (col(l, 1, 3), col(l, 4, 23), 23, 4)
    } else {
        (col(l, 0, 2), col(l, 3, 22), 22, 3)
    };
    let slot = slot_text
        .trim()
        .parse::<u8>()
        .ok()
        .filter(|s| (1..=24).contains(s))
        .ok_or_else(|| lines.err(n, "slot", format!("'{slot_text}' is not a GLONASS slot 1–24")))?;
    // t_b is UTC in the file (RINEX 3.05 Table A10): its GPS time adds GPS − UTC.
    let utc = epoch_fields(lines, n, "toc", time_text)?;
    let utc_s = f64::from(utc.week) * WEEK_S + utc.tow_s + GPS_EPOCH_UNIX_S as f64;
    let leap = f64::from(gps_minus_utc_s((utc_s * 1e9) as i64));
    let gps_s = f64::from(utc.week) * WEEK_S + utc.tow_s + leap;
    let week = (gps_s / WEEK_S).floor();
    let day = (utc_s / 86_400.0).floor();
    const NAMES: [&str; 15] = [
        "SV clock bias (-TauN)",
        "SV relative frequency bias (GammaN)",
        "message frame time (tk)",
        "X",
        "X velocity",
        "X acceleration",
        "health",
        "Y",
        "Y velocity",
        "Y acceleration",
        "frequency number",
        "Z",
        "Z velocity",
        "Z acceleration",
        "age of operation",
    ];
    let v = record_values(lines, (n, l, first), indent, &NAMES, "GLONASS broadcast orbit")?;
    let mut accuracy_index = None;
    let continued = lines
        .lines
        .get(lines.next)
        .is_some_and(|c| v3 && c.starts_with("    ") && !c.trim().is_empty());
    if continued {
        let (m, line) = lines.need("GLONASS broadcast orbit 4")?;
        let a = indent + 19 * 2;
        accuracy_index = number(col(line, a, a + 19))
            .map_err(|p| lines.err(m, "URAI", p))?
            .filter(|u| (0.0..15.0).contains(u))
            .map(|u| u as u8);
    }
    let pos_m = [v[3] * 1e3, v[7] * 1e3, v[11] * 1e3];
    let radius = pos_m.iter().map(|x| x * x).sum::<f64>().sqrt();
    if !(19.0e6..30.0e6).contains(&radius) {
        return Err(lines.err(
            n,
            "X, Y, Z",
            format!("a radius of {:.0} km is not a GLONASS orbit", radius / 1e3),
        ));
    }
    if !(-7.0..=13.0).contains(&v[10]) || v[10].fract() != 0.0 {
        return Err(lines.err(n + 2, "frequency number", format!("{} is not a channel −7…+13", v[10])));
    }
    Ok(GloRecord {
        slot,
        line: n,
        toc: GpsTime {
            week: week as u32,
            tow_s: gps_s - week * WEEK_S,
        },
        toc_utc_sod_s: utc_s - day * 86_400.0,
        toc_utc_day: day as i64,
        tau_s: -v[0],
        gamma: v[1],
        tk_s: v[2].rem_euclid(86_400.0),
        pos_m,
        vel_mps: [v[4] * 1e3, v[8] * 1e3, v[12] * 1e3],
        acc_mps2: [v[5] * 1e3, v[9] * 1e3, v[13] * 1e3],
        health: v[6],
        channel: v[10] as i8,
        age_days: v[14],
        accuracy_index,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const OBS2: &str = "     2.10           OBSERVATION DATA    G (GPS)             RINEX VERSION / TYPE
 -3976219.5082  3382372.5671  3652512.9849                  APPROX POSITION XYZ
     4    L1    C1    L2    P2                              # / TYPES OF OBSERV
  2005     4     2     0     0    0.0000000     GPS         TIME OF FIRST OBS
                                                            END OF HEADER
 05  4  2  0  0 30.0000000  0  2G 3G 7
  55923622.160    24767686.375    43647388.2424   24767684.8224
   -691177.8982   24361933.475     -537007.1404
";

    #[test]
    fn rinex2_observations_become_gps_l1_ca_measurements() {
        let f = parse_obs("a.05o", OBS2).unwrap();
        assert_eq!(f.approx_ecef_m, Some([-3976219.5082, 3382372.5671, 3652512.9849]));
        assert_eq!(f.epochs.len(), 1);
        let e = &f.epochs[0];
        // 2005-04-02 is a Saturday of GPS week 1316.
        assert_eq!((e.week, e.rcv_tow_s), (1316, 6.0 * 86_400.0 + 30.0));
        assert_eq!(e.num_meas, 4);
        let (a, b) = (e.meas[0], e.meas[1]);
        assert_eq!((a.gnss_id, a.sv_id, a.sig_id, a.trk_stat), (0, 3, 0, 0b111));
        assert_eq!((a.pseudorange_m, a.carrier_phase_cycles), (24767686.375, 55923622.160));
        // LLI 2: half-cycle ambiguity.
        assert_eq!((b.sv_id, b.trk_stat, b.carrier_phase_cycles), (7, 0b011, -691177.898));
        // L2/P2 as GPS L2 P(Y), after the L1 signals: G07 has no P2, so no valid pseudorange.
        let (c, d) = (e.meas[2], e.meas[3]);
        assert_eq!((c.sv_id, c.sig_id, c.pseudorange_m), (3, SIG_GPS_L2_PY, 24767684.822));
        assert_eq!((d.sv_id, d.sig_id, d.trk_stat & 1), (7, SIG_GPS_L2_PY, 0));
        assert_eq!(f.unmapped, 0);
    }

    const OBS3: &str = "     3.05           OBSERVATION DATA    M                   RINEX VERSION / TYPE
G    4 C1C L1C D1C S1C                                      SYS / # / OBS TYPES
E    2 C1C C5Q                                              SYS / # / OBS TYPES
    18                                                      LEAP SECONDS
                                                            END OF HEADER
> 2020 06 14 12 00  1.5000000  0  2
G05  21000000.125   110356000.250        -1234.500          45.250
E11  23000000.500    23000005.000
";

    #[test]
    fn rinex3_observations_map_to_ublox_signals() {
        let f = parse_obs("b.rnx", OBS3).unwrap();
        let e = &f.epochs[0];
        assert_eq!((e.leap_s, e.rec_stat & 1, e.num_meas), (18, 1, 3));
        let g = e.meas[0];
        assert_eq!((g.gnss_id, g.sv_id, g.sig_id, g.cno_dbhz), (0, 5, 0, 45));
        assert_eq!((g.pseudorange_m, g.doppler_hz), (21000000.125, -1234.5));
        // Galileo E1C (sigId 0) and E5a Q (sigId 4).
        let ids: Vec<_> = e.meas[1..3].iter().map(|m| (m.gnss_id, m.sv_id, m.sig_id)).collect();
        assert_eq!(ids, [(2, 11, 0), (2, 11, 4)]);
        let t = gps_time(2020, 6, 14, 12, 0, 1.5);
        assert_eq!((e.week, e.rcv_tow_s), (t.week as u16, t.tow_s));
        assert_eq!(t.week, 2110); // 2020-06-14, a Sunday, starts week 2110.
    }

    /// RINEX has no lock time: it counts from a signal's first phase and restarts where the
    /// loss-of-lock indicator's bit 0 is set (RINEX 3.05 §5.7); a phase differenced across such
    /// an epoch would span a cycle slip.
    #[test]
    fn the_lock_time_restarts_at_a_loss_of_lock() {
        let mut text =
            String::from("     3.05           OBSERVATION DATA    M                   RINEX VERSION / TYPE\n");
        text += &format!("{:<60}SYS / # / OBS TYPES\n", "G    2 C1C L1C");
        text += &format!("{:<60}END OF HEADER\n", "");
        for (sec, lli) in [(1.0, ' '), (2.0, ' '), (2.5, ' '), (3.5, '1'), (4.5, ' ')] {
            text += &format!("> 2020 06 14 12 00 {sec:10.7}  0  1\n");
            text += &format!("G05{:14.3}  {:14.3}{lli}\n", 21_000_000.125, 110_356_000.25 + sec);
        }
        let f = parse_obs("c.rnx", &text).unwrap();
        let locks: Vec<u16> = f.epochs.iter().map(|e| e.meas[0].lock_time_ms).collect();
        assert_eq!(locks, [0, 1000, 1500, 0, 1000]);
        assert!(f.epochs.iter().all(|e| e.meas[0].trk_stat & 2 != 0));
    }

    const NAV2: &str = "     2.10           N: GPS NAV DATA                         RINEX VERSION / TYPE
    1.1180D-08  1.4900D-08 -5.9600D-08 -5.9600D-08          ION ALPHA
    8.8060D+04  1.6380D+04 -1.9660D+05 -1.3110D+05          ION BETA
                                                            END OF HEADER
 1 05  4  2  2  0  0.0 3.966595977540D-04 1.705302565820D-12 0.000000000000D+00
    1.400000000000D+02-5.218750000000D+01 4.026596389650D-09 2.871534990340D+00
   -2.676621079440D-06 5.957618006510D-03 4.174187779430D-06 5.153636478420D+03
    5.256000000000D+05 1.061707735060D-07-2.493184817740D+00-9.313225746150D-08
    9.833919144490D-01 3.093750000000D+02-1.650496813270D+00-7.889971342930D-09
   -8.571785642400D-12 1.000000000000D+00 1.316000000000D+03 0.000000000000D+00
    1.000000000000D+00 0.000000000000D+00-3.259629011150D-09 3.960000000000D+02
    5.195760000000D+05
";

    #[test]
    fn rinex2_navigation_gives_ephemerides_and_klobuchar() {
        let f = parse_nav("a.05n", NAV2).unwrap();
        assert_eq!(f.iono_alpha, Some([1.118e-8, 1.49e-8, -5.96e-8, -5.96e-8]));
        assert_eq!(f.iono_beta.unwrap()[0], 88_060.0);
        let e = f.ephemerides[0];
        assert_eq!((e.prn, e.line, e.toc_week, e.toc_s), (1, 5, 1316, 525_600.0));
        assert_eq!(
            (e.iode, e.toe_s, e.week, e.iodc, e.fit_h),
            (140.0, 525_600.0, 1316.0, 396.0, 0.0)
        );
        assert_eq!(
            (e.sqrt_a, e.tgd_s, e.tx_time_s),
            (5153.63647842, -3.25962901115e-9, 519_576.0)
        );
    }

    /// A mixed RINEX 3.05 navigation file: GLONASS (with 3.05's fourth orbit line), Galileo,
    /// BeiDou, SBAS and GPS records, the GPS header α/β.
    fn mixed_nav3() -> String {
        // Fixed columns: 4X then 4 × D19.12 per orbit line (RINEX 3.05 Table A8).
        let orbit = |v: [f64; 4]| format!("    {}\n", v.map(|x| format!("{x:19.12E}")).concat());
        let mut nav3 = String::from(concat!(
            "     3.05           N: GNSS NAV DATA    M: Mixed            RINEX VERSION / TYPE\n",
            "GPSA   1.1180D-08  1.4900D-08 -5.9600D-08 -5.9600D-08       IONOSPHERIC CORR\n",
            "GPSB   8.8060D+04  1.6380D+04 -1.9660D+05 -1.3110D+05       IONOSPHERIC CORR\n",
            "                                                            END OF HEADER\n",
            "R05 2020 06 14 12 15 00-1.000000000000D-05 9.094947017729D-13 4.356000000000D+04\n",
        ));
        nav3 += &orbit([-8215.504394531, -2.294995307922, 9.313225746155e-10, 0.0]);
        nav3 += &orbit([14491.53320312, 1.309631347656, 0.0, -4.0]);
        nav3 += &orbit([19337.97607422, -1.966602325439, -2.793967723846e-9, 2.0]);
        nav3 += &orbit([0.0, 0.0, 6.0, 0.0]);
        nav3 += "E11 2020 06 14 12 10 00 1.000000000000D-05 0.000000000000D+00 0.000000000000D+00\n";
        let kepler = |week: f64| {
            [
                [44.0, -35.28, 3.58e-9, 0.61],
                [-1.48e-6, 3.1e-4, 4.77e-6, 5440.6],
                [43_800.0, 8.9e-8, 2.38, 0.0],
                [0.965, 238.9, 0.33, -5.8e-9],
                [5.2e-11, 513.0, week, 0.0],
                [3.12, 0.0, 4.66e-9, 4.89e-9],
                [43_000.0, 1.0, 0.0, 0.0],
            ]
        };
        for v in kepler(2110.0) {
            nav3 += &orbit(v);
        }
        // BeiDou: the epoch in BDT's calendar (week 754 = GPS week 2110's days).
        nav3 += "C21 2020 06 14 12 00 00 1.000000000000D-05 0.000000000000D+00 0.000000000000D+00\n";
        for v in kepler(754.0) {
            nav3 += &orbit(v);
        }
        // SBAS: 3 orbit lines, skipped.
        nav3 += "S33 2020 06 14 12 00 00 1.000000000000D-05 0.000000000000D+00 0.000000000000D+00\n";
        for _ in 0..3 {
            nav3 += &orbit([1.0, 2.0, 3.0, 4.0]);
        }
        nav3 += "G07 2020 06 14 12 00 00 1.000000000000D-05 2.000000000000D-12 0.000000000000D+00\n";
        for v in [
            [40.0, 10.0, 4e-9, 1.0],
            [1e-6, 1e-2, 2e-6, 5153.6],
            [216_000.0, 1e-7, 1.0, 1e-7],
            [0.96, 200.0, 0.5, -8e-9],
            [1e-10, 1.0, 2109.0, 0.0],
            [2.0, 0.0, 1e-9, 40.0],
        ] {
            nav3 += &orbit(v);
        }
        nav3 += &format!("    {:19.12E}{:19.12E}\n", 210_000.0, 4.0);
        nav3
    }

    /// A mixed RINEX 3.05 file: a GLONASS record (with 3.05's fourth orbit line) read, in SI
    /// units with t_b moved from UTC to GPS time; a Galileo and a BeiDou record read, each
    /// dated in its own time; an SBAS record skipped; a GPS one read.
    #[test]
    fn rinex3_navigation_reads_every_system_but_sbas() {
        let nav3 = mixed_nav3();
        let f = parse_nav("b.rnx", &nav3).unwrap();
        assert_eq!((f.other_systems, f.ephemerides.len(), f.glonass.len()), (1, 1, 1));
        let e = f.ephemerides[0];
        assert_eq!(
            (e.prn, e.line, e.toe_s, e.week, e.iodc, e.fit_h),
            (7, 30, 216_000.0, 2109.0, 40.0, 4.0)
        );
        let [gal, bds] = [f.kepler[0], f.kepler[1]];
        assert_eq!(
            (gal.system, gal.sv, gal.line, gal.toc_week, gal.toc_s),
            ('E', 11, 10, 2110, 43_800.0)
        );
        assert_eq!(
            (bds.system, bds.sv, bds.line, bds.toc_week, bds.toc_s),
            ('C', 21, 18, 754, 43_200.0)
        );
        assert_eq!(
            (gal.af[0], gal.orbit[1][3], gal.orbit[4][1], gal.orbit[6]),
            (1e-5, 5440.6, 513.0, [43_000.0, 1.0, 0.0, 0.0])
        );
        // A Galileo SVID beyond 36 and a week that is not one name their line and field.
        let err = parse_nav("b.rnx", &nav3.replacen("E11 ", "E41 ", 1)).unwrap_err();
        assert_eq!((err.line, err.field.as_str()), (10, "PRN"), "{err}");
        let err = parse_nav("b.rnx", &nav3.replacen("7.540000000000E2", "7.545000000000E2", 1)).unwrap_err();
        assert_eq!((err.line, err.field.as_str()), (18, "BDT week"), "{err}");
        assert_eq!(f.iono_beta.unwrap()[3], -1.311e5);
        let r = f.glonass[0];
        // 2020-06-14 is a Sunday: 12:15 UTC is 12:15:18 GPS of week 2110.
        assert_eq!((r.slot, r.line, r.toc.week, r.toc.tow_s), (5, 5, 2110, 44_118.0));
        assert_eq!((r.toc_utc_sod_s, r.tau_s, r.tk_s), (44_100.0, 1e-5, 43_560.0));
        assert_eq!(
            (r.channel, r.age_days, r.accuracy_index, r.health),
            (-4, 2.0, Some(6), 0.0)
        );
        assert!((r.pos_m[0] + 8_215_504.394531).abs() < 1e-6 && (r.vel_mps[2] + 1966.602325439).abs() < 1e-9);
        assert_eq!(f.glonass_channels()[5], Some(-4));
        // A position off any GLONASS orbit names its line.
        let bad = nav3.replacen("-8.215504394531E3", "-8.215504394531E5", 1);
        assert_ne!(bad, nav3);
        let err = parse_nav("b.rnx", &bad).unwrap_err();
        assert_eq!((err.line, err.field.as_str()), (5, "X, Y, Z"), "{err}");
    }

    /// A RINEX 2 GLONASS navigation file (type `G`, RINEX 2.11 Table A11): 4 lines per record.
    #[test]
    fn rinex2_glonass_navigation_is_read() {
        let orbit = |v: [f64; 4]| format!("   {}\n", v.map(|x| format!("{x:19.12E}")).concat());
        let mut nav2 = String::from(concat!(
            "     2.11           G: GLONASS NAV DATA                     RINEX VERSION / TYPE\n",
            "                                                            END OF HEADER\n",
            " 5 20  6 14 12 15  0.0-1.000000000000D-05 9.094947017729D-13 4.356000000000D+04\n",
        ));
        nav2 += &orbit([-8215.504394531, -2.294995307922, 0.0, 0.0]);
        nav2 += &orbit([14491.53320312, 1.309631347656, 0.0, 3.0]);
        nav2 += &orbit([19337.97607422, -1.966602325439, 0.0, 0.0]);
        let f = parse_nav("a.20g", &nav2).unwrap();
        assert_eq!((f.glonass.len(), f.ephemerides.len()), (1, 0));
        assert_eq!(
            (f.glonass[0].slot, f.glonass[0].channel, f.glonass[0].accuracy_index),
            (5, 3, None)
        );
    }

    /// `GLONASS SLOT / FRQ #` gives the observations their channel; a slot it does not list
    /// stays unknown until a navigation file gives it.
    #[test]
    fn glonass_observations_take_their_channel_from_the_header() {
        let obs = concat!(
            "     3.05           OBSERVATION DATA    M                   RINEX VERSION / TYPE\n",
            "R    1 C1C                                                  SYS / # / OBS TYPES\n",
            "  1 R03 -4                                                  GLONASS SLOT / FRQ #\n",
            "                                                            END OF HEADER\n",
            "> 2020 06 14 12 15  0.0000000  0  2\n",
            "R03  22114715.901\n",
            "R07  21114715.901\n",
        );
        let mut f = parse_obs("c.obs", obs).unwrap();
        let m = f.epochs[0].meas;
        assert_eq!(
            (m[0].sv_id, m[0].freq_id, m[1].sv_id, m[1].freq_id),
            (3, 3, 7, GLONASS_CHANNEL_UNKNOWN)
        );
        let mut channels = [None; 25];
        channels[7] = Some(6);
        assert_eq!(f.fill_glonass_channels(&channels), 0);
        assert_eq!(f.epochs[0].meas[1].freq_id, 13);
        let bad = obs.replace("R03 -4", "R03 -9");
        let err = parse_obs("c.obs", &bad).unwrap_err();
        assert_eq!((err.line, err.field.as_str()), (3, "GLONASS SLOT / FRQ #"), "{err}");
    }

    #[test]
    fn the_signal_table_maps_both_ways() {
        for (k, (sys, band, attr, g, sig)) in SIGNALS.into_iter().enumerate() {
            // A code read as the first u-blox signal it names: the same system and band.
            let first = SIGNALS
                .iter()
                .position(|s| (s.0, s.1, s.2) == (sys, band, attr))
                .unwrap();
            let read = ublox_signal(sys, band, attr).unwrap();
            assert_eq!(read, (SIGNALS[first].3, SIGNALS[first].4));
            assert!(first == k || (read.0 == g && sys == 'C'), "{sys}{band}{attr}");
            // An `X` code reads as a signal whose own code is of the same system and band.
            if attr == 'X' {
                let own = rinex_signal(read.0, read.1).unwrap();
                assert_eq!((own.0, own.1), (sys, band));
            }
            // A u-blox signal written as its first code, which reads back to it or, for
            // BeiDou's D2, to the D1 signal of its band.
            let back = rinex_signal(g, sig).unwrap();
            let again = ublox_signal(back.0, back.1, back.2).unwrap();
            assert!(again == (g, sig) || (g == 3 && [(1, 0), (3, 2), (10, 4)].contains(&(sig, again.1))));
        }
        assert_eq!(rinex_signal(3, 0), Some(('C', '2', 'I')));
        // BeiDou's D2 (GEO) signals are written with their band's code and read as D1's.
        assert_eq!(rinex_signal(3, 10), Some(('C', '6', 'I')));
        assert_eq!(ublox_signal('C', '6', 'I'), Some((3, 4)));
        assert_eq!(rinex_signal(0, 0), Some(('G', '1', 'C')));
        assert_eq!((rinex_signal(0, 1), ublox_signal('G', '2', 'P')), (None, None));
        assert_eq!(ublox_signal('G', '2', 'W'), Some((0, SIG_GPS_L2_PY)));
    }

    #[test]
    fn bad_input_names_file_line_and_field() {
        let bad = OBS2.replace("24767686.375", "24767x86.375");
        let e = parse_obs("a.05o", &bad).unwrap_err();
        assert_eq!((e.file.as_str(), e.line, e.field.as_str()), ("a.05o", 7, "C1"));
        assert!(e.to_string().starts_with("a.05o:7: C1: "), "{e}");
        let e = parse_obs("b.rnx", &OBS3.replace("23000005.000", "23000005.0.0")).unwrap_err();
        assert_eq!((e.line, e.field.as_str()), (8, "C5Q"));
        let e = parse_obs("b.rnx", &OBS3.replace("G05  2", "G0x  2")).unwrap_err();
        assert_eq!((e.line, e.field.as_str()), (7, "satellite"));
        let bad = NAV2.replace("5.153636478420D+03", "5.15363647842XD+0");
        let e = parse_nav("a.05n", &bad).unwrap_err();
        assert_eq!((e.line, e.field.as_str()), (7, "sqrt(A)"));
        let e = parse_nav("a.05n", &NAV2[..NAV2.len() - 60]).unwrap_err();
        assert_eq!(e.field, "broadcast orbit");
        let e = parse_obs("a.05o", "garbage\n").unwrap_err();
        assert_eq!((e.line, e.field.as_str()), (1, "RINEX VERSION / TYPE"));
        let e = parse_obs("a.05o", &OBS2.replace("  0  2G 3G 7", "  0  xG 3G 7")).unwrap_err();
        assert_eq!((e.line, e.field.as_str()), (6, "number of satellites"));
    }

    /// Bad input is an error, never a panic: 30 000 mutations (bytes changed, lines cut,
    /// duplicated or dropped, the file truncated) of the observation and navigation fixtures
    /// each parse to a file or to an error naming a line of the file.
    #[test]
    fn mutated_files_are_errors_not_panics() {
        let mut x = 0x2545_F491_4F6C_DD1Du64;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        let nav3 = mixed_nav3();
        let inputs: [(&str, &str, bool); 3] = [("a.05o", OBS2, true), ("b.rnx", OBS3, true), ("c.rnx", &nav3, false)];
        let (mut ok, mut errors) = (0, 0);
        for _ in 0..10_000 {
            for (name, text, obs) in inputs {
                let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
                for _ in 0..1 + next() % 3 {
                    if lines.is_empty() {
                        break;
                    }
                    let r = next();
                    let i = (r >> 8) as usize % lines.len();
                    match r % 6 {
                        0 => {
                            lines.remove(i);
                        }
                        1 => lines.insert(i, lines[i].clone()),
                        2 => {
                            let l = &mut lines[i];
                            let cut = (r >> 20) as usize % (l.len() + 1);
                            l.truncate(cut);
                        }
                        3 => lines.truncate(i),
                        _ => {
                            let l = &mut lines[i];
                            if !l.is_empty() {
                                let at = (r >> 20) as usize % l.len();
                                let c = b" 0123456789.-+DEeGRECSnaN\t"[(r >> 40) as usize % 26] as char;
                                let mut b: Vec<char> = l.chars().collect();
                                let k = at.min(b.len() - 1);
                                b[k] = c;
                                *l = b.into_iter().collect();
                            }
                        }
                    }
                }
                let text = lines.join("\n");
                let n = lines.len().max(1);
                let line = if obs {
                    parse_obs(name, &text).map(|_| ()).map_err(|e| e.line)
                } else {
                    parse_nav(name, &text).map(|_| ()).map_err(|e| e.line)
                };
                match line {
                    Ok(()) => ok += 1,
                    Err(l) => {
                        assert!(l <= n + 1, "{name}: error at line {l} of {n}");
                        errors += 1;
                    }
                }
            }
        }
        assert!(ok > 1000 && errors > 1000, "{ok} parsed, {errors} errors");
    }
}
