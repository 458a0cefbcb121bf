//! `navsync import rinex OBS NAV [NAV…] --out REC.mcap`: a RINEX observation file and its
//! navigation files (GPS, GLONASS, Galileo, BeiDou) as a recording of a receiver's raw data
//! (RINEX 2.11 / 3.05; the parser is `navsync_drivers::gnss::rinex`).
//!
//! Each observation epoch is a `GnssRaw` on `navsync/gnss/0/raw` (its GNSS time in `week` and
//! `rcv_tow_s`). The navigation file reaches the estimator the way a receiver's does, as GPS
//! LNAV subframes on `navsync/gnss/0/nav-data`: each ephemeris is quantised back into the
//! integers of subframes 1–3 (IS-GPS-200 Tables 20-I and 20-III: RINEX holds those integers
//! times their scale factors, so rounding value / scale recovers them) and the header's α/β into
//! subframe 4 page 18, encoded with parity by `lnav::encode`: one decoder and one ephemeris store
//! (`gnss::ranges::EphemerisStore`) for live and imported data. A GLONASS record becomes strings
//! 1–4 of one frame (`glonass::encode_strings`, GLONASS ICD Table 4.5; t_b and t_k moved from
//! RINEX's UTC to Moscow time, F_T from RINEX 3.05's URAI, else index 4, 5 m), and its channel
//! gives the observations' GLONASS `freqId` when the observation header has none. A Galileo
//! I/NAV record becomes word types 1–5 as E1-B page pairs (`galileo::encode_word`, OS SIS ICD
//! Table 40, CRC-24Q), a BeiDou MEO/IGSO record D1 subframes 1–3 (`beidou::encode_d1`,
//! BDS-SIS-ICD-B1I §5.2, BCH parity), a GEO one D2 subframe 1 pages 1–10 (`beidou::encode_d2`,
//! §5.3), a Galileo F/NAV record page types 1–4 on E5a-I (`fnav::encode_page`). An issue is
//! delivered when its t_oe (GLONASS: t_b) becomes the nearest to the epoch (RTKLIB's choice
//! among a file's ephemerides; the first issue of each satellite before the first epoch).
//!
//! Host time: GPS time shifted so that the first epoch is at `kf_gins::HOST_BASE_NS`, the same
//! synthetic axis as `import kf-gins` (declared as `navsync.time_axis` on the raw channel).

use std::path::{Path, PathBuf};

use navsync_drivers::gnss::rinex::{self, GloRecord, GpsEphemeris, KeplerRecord, NavFile, ObsFile, RinexError};
use navsync_estimator::gnss::beidou::{self, BdsEphemeris, Sub1, Sub2, Sub3};
use navsync_estimator::gnss::bits::OutOfRange;
use navsync_estimator::gnss::fnav::{self, FnavEphemeris};
use navsync_estimator::gnss::galileo::{self, GalEphemeris, Word1, Word2, Word3, Word4, Word5};
use navsync_estimator::gnss::glonass::{self, GloEphemeris};
use navsync_estimator::gnss::lnav::{self, Ephem1, Ephem2, Ephem3, IonoUtc, Subframe};
use navsync_estimator::gnss::orbit::GPS_PI;
use navsync_recording::{RecordingError, SampleRecorder};
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::{AnySample, GnssNavData, Stamp, StampSource};
use navsync_shared::services;
use navsync_shared::time::{NS_PER_S, utc_ns_from_gps_ns};

use super::kf_gins::{HOST_BASE_NS, WEEK_NS};

/// Seconds in a GPS week.
const WEEK_S: f64 = 604_800.0;

/// `navsync import rinex`.
#[derive(Debug, Clone, clap::Args)]
pub struct RinexArgs {
    /// RINEX observation file (2.10/2.11 or 3.0x).
    pub obs: PathBuf,
    /// RINEX navigation files (2.10/2.11 GPS `N` or GLONASS `G`, or 3.0x GPS, GLONASS,
    /// Galileo, BeiDou or mixed): their GPS, GLONASS, Galileo and BeiDou records.
    #[arg(required = true, num_args = 1..)]
    pub nav: Vec<PathBuf>,
    /// The output recording (MCAP).
    #[arg(short, long)]
    pub out: PathBuf,
    /// Receiver id in the recording (`navsync/gnss/ID/raw`, `…/nav-data`).
    #[arg(long, default_value = "0", value_parser = crate::config::estimator::parse_id)]
    pub gnss_id: String,
    /// Replace an existing recording at --out (never one of the inputs).
    #[arg(long)]
    pub force: bool,
}

/// Errors of the RINEX import.
#[derive(Debug, thiserror::Error)]
pub enum RinexImportError {
    /// A file could not be read (the cause follows in the error's chain).
    #[error("reading {path}")]
    Io {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// Bad RINEX input (file, line, field).
    #[error(transparent)]
    Rinex(#[from] RinexError),
    /// Writing the recording.
    #[error(transparent)]
    Recording(#[from] RecordingError),
}

/// What an import wrote.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RinexStats {
    /// Observation epochs (`GnssRaw` samples).
    pub epochs: u64,
    /// Measurements in them.
    pub measurements: u64,
    /// Observations of signals without a signal id (`navsync_drivers::gnss::rinex::SIGNALS`) (not imported).
    pub unmapped: u64,
    /// GPS ephemerides (each as subframes 1–3).
    pub ephemerides: u64,
    /// Subframes written (including page 18).
    pub subframes: u64,
    /// GLONASS ephemerides (each as strings 1–4).
    pub glonass_ephemerides: u64,
    /// GLONASS measurements without a channel in any file (left out by the estimator).
    pub glonass_without_channel: u64,
    /// Galileo ephemerides (each as I/NAV word types 1–5 on E1-B, or F/NAV page types 1–4
    /// on E5a-I).
    pub galileo_ephemerides: u64,
    /// BeiDou ephemerides (each as D1 subframes 1–3, a GEO's as D2 subframe 1 pages 1–10).
    pub beidou_ephemerides: u64,
    /// BeiDou records whose AODE did not fit its 5 bits (RTKLIB writes its own issue number
    /// there): its 5 low bits were kept.
    pub beidou_aode_wrapped: u64,
    /// The header's approximate position, ECEF m.
    pub approx_ecef_m: Option<[f64; 3]>,
    /// The largest |value / scale − integer| over the quantised fields: near 0 for broadcast
    /// values (RINEX's 12 significant digits), up to 0.5 for values that were not.
    pub worst_quantisation: f64,
}

/// Runs `navsync import rinex` and prints what it wrote.
pub fn main(args: &RinexArgs) -> anyhow::Result<()> {
    use anyhow::Context;
    let s = import(args).with_context(|| format!("importing into {}", args.out.display()))?;
    eprintln!(
        "{}: {} epochs, {} measurements ({} observations of signals without a signal id left out), \
         {} GPS ephemerides as {} LNAV subframes, {} GLONASS ephemerides as strings 1–4 (largest \
         rounding {:.1e} LSB)",
        args.out.display(),
        s.epochs,
        s.measurements,
        s.unmapped,
        s.ephemerides,
        s.subframes,
        s.glonass_ephemerides,
        s.worst_quantisation
    );
    if s.galileo_ephemerides + s.beidou_ephemerides > 0 {
        eprintln!(
            "  {} Galileo ephemerides as I/NAV words 1–5 or F/NAV pages 1–4, {} BeiDou ones as D1 \
             subframes (GEO: D2 pages) ({} BeiDou AODE beyond 5 bits kept mod 32)",
            s.galileo_ephemerides, s.beidou_ephemerides, s.beidou_aode_wrapped
        );
    }
    if s.glonass_without_channel > 0 {
        eprintln!(
            "  {} GLONASS measurements without a frequency channel (no GLONASS SLOT / FRQ # header, \
             no navigation record of their slot): left out of the solutions",
            s.glonass_without_channel
        );
    }
    if let Some(p) = s.approx_ecef_m {
        eprintln!("  header position (ECEF m): {:.4},{:.4},{:.4}", p[0], p[1], p[2]);
    }
    anyhow::ensure!(s.epochs > 0, "no observation epoch in {}", args.obs.display());
    anyhow::ensure!(
        s.ephemerides + s.glonass_ephemerides + s.galileo_ephemerides + s.beidou_ephemerides > 0,
        "no GPS, GLONASS, Galileo or BeiDou ephemeris in {}",
        args.nav
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(())
}

fn read(path: &Path) -> Result<String, RinexImportError> {
    // RINEX is ASCII; a stray byte is replaced rather than refused (it lands in a field).
    std::fs::read(path)
        .map(|b| String::from_utf8_lossy(&b).into_owned())
        .map_err(|source| RinexImportError::Io {
            path: path.display().to_string(),
            source,
        })
}

/// Reads and parses the files: the observations, and each navigation file with its name.
pub fn parse_files(obs: &Path, navs: &[PathBuf]) -> Result<(ObsFile, Vec<(String, NavFile)>), RinexImportError> {
    let o = rinex::parse_obs(&obs.display().to_string(), &read(obs)?)?;
    let mut n = Vec::with_capacity(navs.len());
    for nav in navs {
        let name = nav.display().to_string();
        let parsed = rinex::parse_nav(&name, &read(nav)?)?;
        n.push((name, parsed));
    }
    Ok((o, n))
}

/// One navigation record of any file.
#[derive(Debug, Clone, Copy)]
enum Record {
    Gps(GpsEphemeris),
    Glonass(GloRecord),
    /// Galileo (I/NAV or F/NAV) or BeiDou.
    Kepler(KeplerRecord),
}

impl Record {
    /// (u-blox gnssId, with bit 7 set for Galileo F/NAV; satellite) and the reference time
    /// (t_oe, t_b), GPS ns.
    fn key(&self) -> ((u8, u8), i64) {
        let gps_ns = |week: f64, tow_s: f64| week as i64 * WEEK_NS + (tow_s * 1e9).round() as i64;
        match self {
            Self::Gps(e) => ((0, e.prn), gps_ns(e.week, e.toe_s)),
            Self::Glonass(r) => ((6, r.slot), gps_ns(f64::from(r.toc.week), r.toc.tow_s)),
            // t_oe of GST (GPS's weeks) or of BDT (GPS − 14 s, weeks from GPS week 1356).
            Self::Kepler(k) if k.system == 'C' => (
                (3, k.sv),
                gps_ns(k.orbit[4][2] + f64::from(rinex::BDT_WEEK_OFFSET), k.orbit[2][0] + 14.0),
            ),
            // F/NAV records keyed apart from I/NAV ones (both are delivered, as a receiver does).
            Self::Kepler(k) => (
                (if is_fnav(k) { 0x82 } else { 2 }, k.sv),
                gps_ns(k.orbit[4][2], k.orbit[2][0]),
            ),
        }
    }
}

/// The RINEX record of GLONASS immediate data `e` received near the epoch `near` (its t_b the
/// instant of that Moscow time of day nearest the epoch; GPS − UTC the receiver's when valid,
/// else the table's), on channel `channel`: the inverse of [`glonass_strings`].
pub fn glonass_record_of(e: &GloEphemeris, near: &navsync_shared::samples::GnssRaw, channel: i8) -> GloRecord {
    let gps_s = f64::from(near.week) * WEEK_S + near.rcv_tow_s;
    let leap = f64::from(near.gps_minus_utc_s());
    let moscow = glonass::MOSCOW_OFFSET_S as f64;
    let utc_s = gps_s - leap;
    let dt = (e.tb_s - (utc_s + moscow).rem_euclid(86_400.0) + 43_200.0).rem_euclid(86_400.0) - 43_200.0;
    let toc_utc_s = (utc_s + dt).round();
    let toc_gps_s = toc_utc_s + leap;
    let week = (toc_gps_s / WEEK_S).floor();
    // Seconds since 1970 of the UTC instant, for its date.
    let unix_s = toc_utc_s + navsync_shared::time::GPS_EPOCH_UNIX_S as f64;
    let day = (unix_s / 86_400.0).floor();
    GloRecord {
        slot: e.slot,
        line: 0,
        toc: rinex::GpsTime {
            week: week as u32,
            tow_s: toc_gps_s - week * WEEK_S,
        },
        toc_utc_sod_s: unix_s - day * 86_400.0,
        toc_utc_day: day as i64,
        tau_s: e.tau_s,
        gamma: e.gamma,
        tk_s: (e.tk_s - moscow).rem_euclid(86_400.0),
        pos_m: e.pos_m,
        vel_mps: e.vel_mps,
        acc_mps2: e.acc_mps2,
        health: if e.healthy() { 0.0 } else { 1.0 },
        channel,
        age_days: f64::from(e.age_days),
        accuracy_index: Some(e.accuracy_index),
    }
}

/// Strings 1–4 of a GLONASS record: t_b and t_k in Moscow time (UTC + 3 h), N_T the day of the
/// four-year interval (1 = 1 January of the leap year), F_T `URAI` else index 4 (5 m); the
/// largest rounding of its values to their scale factors goes to `worst`.
fn glonass_strings(r: &GloRecord, file: &str, frame: u32, worst: &mut f64) -> Result<[[u32; 4]; 4], RinexError> {
    let err = |field: &str, problem: String| RinexError {
        file: file.to_string(),
        line: r.line,
        field: field.to_string(),
        problem,
    };
    let moscow = glonass::MOSCOW_OFFSET_S as f64;
    let tb_s = (r.toc_utc_sod_s + moscow).rem_euclid(86_400.0);
    if (tb_s / 900.0).fract() != 0.0 {
        return Err(err(
            "toc",
            format!("t_b {tb_s} s of the Moscow day is not a quarter hour"),
        ));
    }
    let day = r.toc_utc_day + ((r.toc_utc_sod_s + moscow) / 86_400.0).floor() as i64;
    let (year, _, _) = navsync_shared::time::civil_from_days(day);
    let leap_year = year - year.rem_euclid(4);
    let n_t = day - navsync_shared::time::days_from_civil(leap_year, 1, 1) + 1;
    let e = GloEphemeris {
        slot: r.slot,
        tb_s,
        pos_m: r.pos_m,
        vel_mps: r.vel_mps,
        acc_mps2: r.acc_mps2,
        gamma: r.gamma,
        tau_s: r.tau_s,
        health: if r.health != 0.0 { 0b100 } else { 0 },
        day_in_interval: n_t as u16,
        accuracy_index: r.accuracy_index.unwrap_or(4),
        age_days: r.age_days.clamp(0.0, 31.0) as u8,
        tk_s: (r.tk_s + moscow).rem_euclid(86_400.0),
    };
    let scaled = (0..3)
        .flat_map(|i| {
            [
                e.pos_m[i] / (2f64.powi(-11) * 1e3),
                e.vel_mps[i] / (2f64.powi(-20) * 1e3),
                e.acc_mps2[i] / (2f64.powi(-30) * 1e3),
            ]
        })
        .chain([e.gamma / 2f64.powi(-40), e.tau_s / 2f64.powi(-30)]);
    for v in scaled {
        *worst = worst.max((v - v.round()).abs());
    }
    glonass::encode_strings(&e, frame)
        .ok_or_else(|| err("GLONASS broadcast orbit", "a value beyond its field in the ICD".into()))
}

/// Quantises RINEX values to LNAV integers, checking each fits its bits.
struct Quantiser<'a> {
    file: &'a str,
    line: usize,
    worst: f64,
}

impl Quantiser<'_> {
    /// `value / 2^lsb` rounded, as a two's-complement (`signed`) or unsigned field of `bits`.
    fn q(&mut self, field: &str, value: f64, lsb: i32, bits: u32, signed: bool) -> Result<i64, RinexError> {
        let x = value / 2f64.powi(lsb);
        let r = x.round();
        let (lo, hi) = if signed {
            (-(1i64 << (bits - 1)), (1i64 << (bits - 1)) - 1)
        } else {
            (0, (1i64 << bits) - 1)
        };
        if !r.is_finite() || r < lo as f64 || r > hi as f64 {
            return Err(RinexError {
                file: self.file.to_string(),
                line: self.line,
                field: field.to_string(),
                problem: format!("{value:e} is outside the LNAV field ({bits} bits of 2^{lsb})"),
            });
        }
        self.worst = self.worst.max((x - r).abs());
        Ok(r as i64)
    }
    /// An angle (rad or rad/s) in semicircles.
    fn semi(&mut self, field: &str, rad: f64, lsb: i32, bits: u32) -> Result<i64, RinexError> {
        self.q(field, rad / GPS_PI, lsb, bits, true)
    }
}

/// The URA index of an accuracy in m (IS-GPS-200 §20.3.3.3.1.3: the smallest N whose range's
/// upper bound 2.4, 3.4, 4.85, 6.85, 9.65, 13.65, 24, 48, … 6144 m holds it; 15 above).
pub fn ura_index(accuracy_m: f64) -> u8 {
    const UPPER: [f64; 7] = [2.4, 3.4, 4.85, 6.85, 9.65, 13.65, 24.0];
    (0..15u8)
        .find(|&n| {
            let upper = UPPER
                .get(usize::from(n))
                .copied()
                .unwrap_or(24.0 * 2f64.powi(i32::from(n) - 6));
            accuracy_m <= upper
        })
        .unwrap_or(15)
}

/// One ephemeris as LNAV subframes 1–3 (IS-GPS-200 Tables 20-I and 20-III scale factors).
pub fn subframes_of(e: &GpsEphemeris, file: &str, worst: &mut f64) -> Result<[Subframe; 3], RinexError> {
    let mut q = Quantiser {
        file,
        line: e.line,
        worst: *worst,
    };
    let iodc = q.q("IODC", e.iodc, 0, 10, false)?;
    let iode = q.q("IODE", e.iode, 0, 8, false)?;
    let s1 = Ephem1 {
        wn: (q.q("GPS week", e.week, 0, 16, false)? % 1024) as u16,
        l2: q.q("L2 codes", e.l2_codes, 0, 2, false)? as u8,
        ura: ura_index(e.accuracy_m),
        health: q.q("SV health", e.health, 0, 6, false)? as u8,
        iodc: iodc as u16,
        l2p: q.q("L2 P flag", e.l2p, 0, 1, false)? as u8,
        tgd: q.q("TGD", e.tgd_s, -31, 8, true)? as i8,
        toc: q.q("toc", e.toc_s, 4, 16, false)? as u16,
        af2: q.q("af2", e.af[2], -55, 8, true)? as i8,
        af1: q.q("af1", e.af[1], -43, 16, true)? as i16,
        af0: q.q("af0", e.af[0], -31, 22, true)? as i32,
    };
    let s2 = Ephem2 {
        iode: iode as u8,
        crs: q.q("Crs", e.crs, -5, 16, true)? as i16,
        delta_n: q.semi("Delta n", e.delta_n, -43, 16)? as i16,
        m0: q.semi("M0", e.m0, -31, 32)? as i32,
        cuc: q.q("Cuc", e.cuc, -29, 16, true)? as i16,
        e: q.q("e", e.e, -33, 32, false)? as u32,
        cus: q.q("Cus", e.cus, -29, 16, true)? as i16,
        sqrt_a: q.q("sqrt(A)", e.sqrt_a, -19, 32, false)? as u32,
        toe: q.q("Toe", e.toe_s, 4, 16, false)? as u16,
        // IS-GPS-200 §20.3.3.4.3.1: 0 for the 4 h curve fit, 1 for longer.
        fit: u8::from(e.fit_h > 4.0),
        aodo: 0,
    };
    let s3 = Ephem3 {
        cic: q.q("Cic", e.cic, -29, 16, true)? as i16,
        omega0: q.semi("OMEGA0", e.omega0, -31, 32)? as i32,
        cis: q.q("Cis", e.cis, -29, 16, true)? as i16,
        i0: q.semi("i0", e.i0, -31, 32)? as i32,
        crc: q.q("Crc", e.crc, -5, 16, true)? as i16,
        omega: q.semi("omega", e.omega, -31, 32)? as i32,
        omega_dot: q.semi("OMEGA DOT", e.omega_dot, -43, 24)? as i32,
        iode: iode as u8,
        idot: q.semi("IDOT", e.idot, -43, 14)? as i16,
    };
    *worst = q.worst;
    Ok([Subframe::Ephem1(s1), Subframe::Ephem2(s2), Subframe::Ephem3(s3)])
}

/// An ephemeris from LNAV subframes 1–3 in RINEX units, the inverse of [`subframes_of`]
/// (IS-GPS-200 Tables 20-I and 20-III scale factors; RINEX 3.05 Table A8 fields). `near_week`
/// (a full GPS week, e.g. of the receiver's epochs) resolves the broadcast week number mod
/// 1024; t_oc's week is t_oe's, or the one next to it when t_oc is half a week away (a
/// crossing of the week's end). The URA index becomes its nominal accuracy (§20.3.3.3.1.3;
/// index 15 above 6144 m), the fit interval flag 4 h or, set, the interval its IODC says
/// (Table 20-XII); the transmission time is subframe 1's start (its HOW's count − 6 s).
pub fn ephemeris_of(
    prn: u8,
    how_tow_count: u32,
    s1: &Ephem1,
    s2: &Ephem2,
    s3: &Ephem3,
    near_week: u32,
) -> GpsEphemeris {
    let p2 = |lsb: i32| 2f64.powi(lsb);
    let semi = |v: f64, lsb: i32| v * p2(lsb) * GPS_PI;
    // The full week ≡ wn (mod 1024) nearest to near_week.
    let wn = i64::from(s1.wn % 1024);
    let k = ((i64::from(near_week) - wn) as f64 / 1024.0).round() as i64;
    let week = (wn + 1024 * k).max(0) as u32;
    let (toc_s, toe_s) = (f64::from(s1.toc) * 16.0, f64::from(s2.toe) * 16.0);
    let toc_week = match toc_s - toe_s {
        d if d > WEEK_S / 2.0 => week.saturating_sub(1),
        d if d < -WEEK_S / 2.0 => week + 1,
        _ => week,
    };
    let accuracy_m = navsync_estimator::gnss::ranges::ura_m(s1.ura).unwrap_or(2.0 * 6144.0);
    let fit_h = match (s2.fit, s1.iodc) {
        (0, _) => 4.0,
        (_, 240..=247) => 8.0,
        (_, 248..=255 | 496) => 14.0,
        (_, 497..=503 | 1021..=1023) => 26.0,
        _ => 6.0,
    };
    GpsEphemeris {
        prn,
        line: 0,
        toc_week,
        toc_s,
        af: [
            f64::from(s1.af0) * p2(-31),
            f64::from(s1.af1) * p2(-43),
            f64::from(s1.af2) * p2(-55),
        ],
        iode: f64::from(s2.iode),
        crs: f64::from(s2.crs) * p2(-5),
        delta_n: semi(f64::from(s2.delta_n), -43),
        m0: semi(f64::from(s2.m0), -31),
        cuc: f64::from(s2.cuc) * p2(-29),
        e: f64::from(s2.e) * p2(-33),
        cus: f64::from(s2.cus) * p2(-29),
        sqrt_a: f64::from(s2.sqrt_a) * p2(-19),
        toe_s,
        cic: f64::from(s3.cic) * p2(-29),
        omega0: semi(f64::from(s3.omega0), -31),
        cis: f64::from(s3.cis) * p2(-29),
        i0: semi(f64::from(s3.i0), -31),
        crc: f64::from(s3.crc) * p2(-5),
        omega: semi(f64::from(s3.omega), -31),
        omega_dot: semi(f64::from(s3.omega_dot), -43),
        idot: semi(f64::from(s3.idot), -43),
        l2_codes: f64::from(s1.l2),
        week: f64::from(week),
        l2p: f64::from(s1.l2p),
        accuracy_m,
        health: f64::from(s1.health),
        tgd_s: f64::from(s1.tgd) * p2(-31),
        iodc: f64::from(s1.iodc),
        tx_time_s: (f64::from(how_tow_count) * 6.0 - 6.0).rem_euclid(WEEK_S),
        fit_h,
    }
}

/// Subframe 4 page 18's Klobuchar α/β in RINEX units (s, s/semicircle, …), the inverse of
/// [`iono_page`].
pub fn iono_of_page(page: &IonoUtc) -> ([f64; 4], [f64; 4]) {
    let mut alpha = [0.0; 4];
    let mut beta = [0.0; 4];
    for (k, lsb) in [-30, -27, -24, -24].into_iter().enumerate() {
        alpha[k] = f64::from(page.alpha[k]) * 2f64.powi(lsb);
    }
    for (k, lsb) in [11, 14, 16, 16].into_iter().enumerate() {
        beta[k] = f64::from(page.beta[k]) * 2f64.powi(lsb);
    }
    (alpha, beta)
}

/// The header's α/β as subframe 4 page 18 (Table 20-X scale factors; UTC parameters zero).
pub fn iono_page(alpha: [f64; 4], beta: [f64; 4], file: &str) -> Result<IonoUtc, RinexError> {
    let mut q = Quantiser {
        file,
        line: 1,
        worst: 0.0,
    };
    let mut page = IonoUtc::default();
    for (k, lsb) in [-30, -27, -24, -24].into_iter().enumerate() {
        page.alpha[k] = q.q("ION ALPHA", alpha[k], lsb, 8, true)? as i8;
    }
    for (k, lsb) in [11, 14, 16, 16].into_iter().enumerate() {
        page.beta[k] = q.q("ION BETA", beta[k], lsb, 8, true)? as i8;
    }
    Ok(page)
}

/// A subframe as the sample a receiver's driver publishes (UBX-RXM-SFRBX's content).
fn nav_sample(prn: u8, sf: &Subframe, tow_s: f64) -> Option<GnssNavData> {
    // The HOW's TOW count: the next subframe's start, 6 s units.
    let tow_count = ((tow_s / 6.0).floor() as i64 + 1).rem_euclid(100_800) as u32;
    let words = lnav::encode(tow_count, sf)?;
    let mut d = GnssNavData::zeroed();
    d.words[..10].copy_from_slice(&words);
    (d.gnss_id, d.sv_id, d.sig_id, d.num_words, d.version) = (0, prn, 0, 10, 2);
    Some(d)
}

/// Words of a u-blox RXM-SFRBX (`gnss_id`, `sv_id`, `sig_id` as u-blox numbers them) as a
/// navigation-data sample (GLONASS: the string, then the frame in word 3).
fn nav_words(gnss_id: u8, sv_id: u8, sig_id: u8, words: &[u32]) -> GnssNavData {
    let mut d = GnssNavData::zeroed();
    let n = words.len().min(d.words.len());
    d.words[..n].copy_from_slice(&words[..n]);
    (d.gnss_id, d.sv_id, d.sig_id, d.num_words, d.version) = (gnss_id, sv_id, sig_id, n as u8, 2);
    d
}

/// A field that does not fit as the RINEX error of record `k`.
fn field_error<'a>(k: &KeplerRecord, file: &'a str) -> impl Fn(OutOfRange) -> RinexError + 'a {
    let line = k.line;
    move |e| RinexError {
        file: file.to_string(),
        line,
        field: e.field.to_string(),
        problem: e.to_string(),
    }
}

/// A RINEX 3 Galileo I/NAV record as the page pairs of word types 1–5 on E1-B (Galileo OS SIS
/// ICD Table 40 and the scale factors of Tables 60, 63, 68: `galileo::encode_word`): the SISA
/// in m as its index (Table 76), SV health bits 0–2 and 6–8 as E1-B's and E5b's DVS and HS,
/// GST's week as RINEX's Galileo week − 1024 (mod 4096), word 5's time of week the record's
/// transmission time; the ionosphere (a_i) zero. The largest rounding goes to `worst`.
fn galileo_pages(k: &KeplerRecord, file: &str, worst: &mut f64) -> Result<[[u32; 8]; 5], RinexError> {
    let o = &k.orbit;
    let iod_nav = o[0][0].round().clamp(0.0, f64::from(u16::MAX)) as u16;
    let health = o[5][1].round().clamp(0.0, 511.0) as u16;
    let bit = |b: u16, n: u16| ((health >> b) & ((1 << n) - 1)) as u8;
    let e = GalEphemeris {
        sv: k.sv,
        w1: Word1 {
            iod_nav,
            toe_s: o[2][0],
            m0_rad: o[0][3],
            e: o[1][1],
            sqrt_a: o[1][3],
        },
        w2: Word2 {
            iod_nav,
            omega0_rad: o[2][2],
            i0_rad: o[3][0],
            omega_rad: o[3][2],
            idot_rad_s: o[4][0],
        },
        w3: Word3 {
            iod_nav,
            omega_dot_rad_s: o[3][3],
            delta_n_rad_s: o[0][2],
            cuc_rad: o[1][0],
            cus_rad: o[1][2],
            crc_m: o[3][1],
            crs_m: o[0][1],
            sisa: galileo::sisa_index(o[5][0]),
        },
        w4: Word4 {
            iod_nav,
            svid: k.sv,
            cic_rad: o[2][1],
            cis_rad: o[2][3],
            toc_s: k.toc_s,
            af0_s: k.af[0],
            af1: k.af[1],
            af2_per_s: k.af[2],
        },
        w5: Word5 {
            ai: [0.0; 3],
            region_flags: 0,
            bgd_e1_e5a_s: o[5][2],
            bgd_e1_e5b_s: o[5][3],
            e5b_hs: bit(7, 2),
            e1b_hs: bit(1, 2),
            e5b_dvs: bit(6, 1),
            e1b_dvs: bit(0, 1),
            wn: gst_week(o[4][2]),
            tow_s: o[6][0].clamp(0.0, WEEK_S - 1.0) as u32,
        },
    };
    let mut out = [[0u32; 8]; 5];
    for (slot, w) in out.iter_mut().zip(galileo::words_of(&e)) {
        *slot = galileo::page_pair(galileo::encode_word(&w, worst).map_err(field_error(k, file))?);
    }
    Ok(out)
}

/// GST's 12-bit week number of RINEX's Galileo week (continuous, aligned with GPS's: GST
/// week 0 is GPS week 1024, OS SIS ICD §5.1.2).
fn gst_week(gal_week: f64) -> u16 {
    ((gal_week.clamp(0.0, 1e6) as i64 - 1024).rem_euclid(4096)) as u16
}

/// Whether a record is Galileo F/NAV: data sources (RINEX 3.05, ORBIT 5) with bit 1 (E5a-I)
/// and neither I/NAV bit (0 E1-B, 2 E5b-I).
fn is_fnav(k: &KeplerRecord) -> bool {
    let sources = k.orbit[4][1].clamp(0.0, 1023.0) as u32;
    k.system == 'E' && sources & 0b010 != 0 && sources & 0b101 == 0
}

/// A RINEX 3 Galileo F/NAV record as page types 1–4 on E5a-I (OS SIS ICD §4.2.2,
/// `fnav::encode_page`): its (E1,E5a) clock, SISA(E1,E5a) as the index, health bits 3–5 as
/// E5a's DVS and HS, BGD(E1,E5a), GST's week and the transmission time in page 1.
fn fnav_pages(k: &KeplerRecord, file: &str, worst: &mut f64) -> Result<[[u32; 8]; 4], RinexError> {
    let o = &k.orbit;
    let iod_nav = o[0][0].round().clamp(0.0, f64::from(u16::MAX)) as u16;
    let health = o[5][1].round().clamp(0.0, 511.0) as u16;
    let e = FnavEphemeris {
        sv: k.sv,
        p1: fnav::Page1 {
            svid: k.sv,
            iod_nav,
            toc_s: k.toc_s,
            af: k.af,
            sisa: galileo::sisa_index(o[5][0]),
            ai: [0.0; 3],
            bgd_e1_e5a_s: o[5][2],
            e5a_hs: ((health >> 4) & 3) as u8,
            wn: gst_week(o[4][2]),
            tow_s: o[6][0].clamp(0.0, WEEK_S - 1.0) as u32,
            e5a_dvs: ((health >> 3) & 1) as u8,
        },
        p2: fnav::Page2 {
            iod_nav,
            m0_rad: o[0][3],
            omega_dot_rad_s: o[3][3],
            e: o[1][1],
            sqrt_a: o[1][3],
            omega0_rad: o[2][2],
            idot_rad_s: o[4][0],
        },
        p3: fnav::Page3 {
            iod_nav,
            i0_rad: o[3][0],
            omega_rad: o[3][2],
            delta_n_rad_s: o[0][2],
            cuc_rad: o[1][0],
            cus_rad: o[1][2],
            crc_m: o[3][1],
            crs_m: o[0][1],
            toe_s: o[2][0],
        },
        p4: fnav::Page4 {
            iod_nav,
            cic_rad: o[2][1],
            cis_rad: o[2][3],
        },
    };
    let mut out = [[0u32; 8]; 4];
    for (slot, page) in out.iter_mut().zip(fnav::pages_of(&e)) {
        *slot = fnav::encode_page(&page, worst).map_err(field_error(k, file))?;
    }
    Ok(out)
}

/// A RINEX 3 BeiDou record as the ephemeris its broadcast carries (BDS-SIS-ICD-B1I §5.2.4):
/// the URA in m as its index (IS-GPS-200's table, §5.2.4.5), the Klobuchar α/β of the file's
/// `BDSA`/`BDSB` header (else zero; a GEO's D2 pages do not carry them), subframe 1's SOW the
/// record's t_oe; with whether its AODE had to be cut to 5 bits (RTKLIB writes its own issue
/// number there).
fn beidou_ephemeris(
    k: &KeplerRecord,
    iono: Option<([f64; 4], [f64; 4])>,
    file: &str,
) -> Result<(BdsEphemeris, bool), RinexError> {
    let o = &k.orbit;
    let toe_s = o[2][0];
    if toe_s.rem_euclid(8.0) != 0.0 {
        return Err(RinexError {
            file: file.to_string(),
            line: k.line,
            field: "Toe".to_string(),
            problem: format!("{toe_s} s is not a multiple of 8 s"),
        });
    }
    let toe8 = (toe_s / 8.0) as u32;
    let aode = o[0][0].round().max(0.0) as u64;
    let (alpha, beta) = iono.unwrap_or_default();
    let small = |x: f64| x.round().clamp(0.0, 255.0) as u8;
    let e = BdsEphemeris {
        sv: k.sv,
        sow_s: toe_s as u32,
        s1: Sub1 {
            sat_h1: small(o[5][1]),
            aodc: small(o[6][1]),
            urai: ura_index(o[5][0]),
            week: o[4][2].clamp(0.0, f64::from(u16::MAX)) as u16,
            toc_s: k.toc_s,
            tgd1_s: o[5][2],
            tgd2_s: o[5][3],
            alpha,
            beta,
            a0_s: k.af[0],
            a1: k.af[1],
            a2_per_s: k.af[2],
            aode: (aode % 32) as u8,
        },
        s2: Sub2 {
            delta_n_rad_s: o[0][2],
            cuc_rad: o[1][0],
            m0_rad: o[0][3],
            e: o[1][1],
            cus_rad: o[1][2],
            crc_m: o[3][1],
            crs_m: o[0][1],
            sqrt_a: o[1][3],
            toe_msb: (toe8 >> 15) as u8,
        },
        s3: Sub3 {
            toe_lsb: (toe8 & 0x7FFF) as u16,
            i0_rad: o[3][0],
            cic_rad: o[2][1],
            omega_dot_rad_s: o[3][3],
            cis_rad: o[2][3],
            idot_rad_s: o[4][0],
            omega0_rad: o[2][2],
            omega_rad: o[3][2],
        },
    };
    Ok((e, aode > 31))
}

/// A BeiDou ephemeris as the words a receiver would deliver: a MEO/IGSO satellite's D1
/// subframes 1–3 on B1I (`beidou::encode_d1`, u-blox sigId 0), a GEO's D2 subframe 1 pages
/// 1–10 (`beidou::encode_d2`, sigId 1); each of ten words with BCH parity.
fn beidou_words(
    e: &BdsEphemeris,
    k: &KeplerRecord,
    file: &str,
    worst: &mut f64,
) -> Result<(u8, Vec<[u32; 10]>), RinexError> {
    if beidou::is_geo(e.sv) {
        let pages = beidou::encode_d2(e, worst).map_err(field_error(k, file))?;
        return Ok((1, pages.to_vec()));
    }
    let mut out = Vec::with_capacity(3);
    for sf in beidou::d1_subframes(e) {
        out.push(beidou::encode_d1(&sf, worst).map_err(field_error(k, file))?);
    }
    Ok((0, out))
}

/// Runs `navsync import rinex`.
pub fn import(args: &RinexArgs) -> Result<RinexStats, RinexImportError> {
    let (mut obs, navs) = parse_files(&args.obs, &args.nav)?;
    let mut channels = [None; 25];
    for (_, n) in &navs {
        for (c, k) in channels.iter_mut().zip(n.glonass_channels()) {
            *c = c.or(k);
        }
    }
    let mut stats = RinexStats {
        approx_ecef_m: obs.approx_ecef_m,
        unmapped: obs.unmapped,
        glonass_without_channel: obs.fill_glonass_channels(&channels),
        ..RinexStats::default()
    };
    // GPS ns of an epoch; the first epoch is the host axis's origin.
    let gps_ns = |week: i64, tow_s: f64| week * WEEK_NS + (tow_s * 1e9).round() as i64;
    let t0 = obs.epochs.first().map_or(0, |e| gps_ns(i64::from(e.week), e.rcv_tow_s));
    let host_of = |g: i64| HOST_BASE_NS + (g - t0);
    // Each issue's delivery: before the first epoch for a satellite's first issue, else when
    // its t_oe (t_b) becomes the nearer one (the midpoint between the two).
    let mut recs: Vec<(usize, Record)> = Vec::new();
    for (f, (_, n)) in navs.iter().enumerate() {
        recs.extend(n.ephemerides.iter().map(|e| (f, Record::Gps(*e))));
        recs.extend(n.glonass.iter().map(|r| (f, Record::Glonass(*r))));
        recs.extend(n.kepler.iter().map(|k| (f, Record::Kepler(*k))));
    }
    recs.sort_by_key(|(_, r)| r.key());
    recs.dedup_by_key(|(_, r)| r.key());
    let mut deliveries: Vec<(i64, usize, Record)> = Vec::with_capacity(recs.len());
    for (k, (f, r)) in recs.iter().enumerate() {
        let (sat, t) = r.key();
        let at = match k.checked_sub(1).map(|j| recs[j].1.key()) {
            Some((prev_sat, prev)) if prev_sat == sat => (prev + t) / 2,
            _ => i64::MIN,
        };
        deliveries.push((at.max(t0 - NS_PER_S), *f, *r));
    }
    deliveries.sort_by_key(|(at, _, r)| (*at, r.key().0));

    let raw_service = services::gnss_raw(&args.gnss_id);
    let nav_service = services::gnss_nav_data(&args.gnss_id);
    let inputs: Vec<&Path> = std::iter::once(args.obs.as_path())
        .chain(args.nav.iter().map(PathBuf::as_path))
        .collect();
    let (mut rec, _) = super::kf_gins::imported_recording(&args.out, &inputs, args.force, &raw_service, t0)?;
    let log_time = |host: i64| utc_ns_from_gps_ns(t0 + (host - HOST_BASE_NS)).max(0) as u64;
    let mut nav_seq = 0u64;
    let mut write_nav =
        |rec: &mut SampleRecorder<_>, d: Option<GnssNavData>, at: i64| -> Result<(), RinexImportError> {
            let host = host_of(at);
            if let Some(mut d) = d {
                d.stamp = Stamp::host(host, nav_seq, StampSource::Simulated);
                rec.write(&nav_service, &AnySample::NavData(d), log_time(host), host.max(0) as u64)?;
                nav_seq += 1;
            }
            Ok(())
        };
    let tow = |at: i64| at.rem_euclid(WEEK_NS) as f64 / 1e9;
    let iono = navs
        .iter()
        .find_map(|(name, n)| Some((name, n.iono_alpha?, n.iono_beta?)));
    let first_gps = deliveries.iter().find_map(|(_, _, r)| match r {
        Record::Gps(e) => Some(e.prn),
        _ => None,
    });
    if let (Some((name, a, b)), Some(prn)) = (iono, first_gps) {
        let page = iono_page(a, b, name)?;
        let at = t0 - NS_PER_S;
        write_nav(&mut rec, nav_sample(prn, &Subframe::IonoUtc(page), tow(at)), at)?;
        stats.subframes += 1;
    }
    let mut next = deliveries.iter().peekable();
    for (i, raw) in obs.epochs.iter().enumerate() {
        let g = gps_ns(i64::from(raw.week), raw.rcv_tow_s);
        while let Some((at, f, r)) = next.next_if(|(at, _, _)| *at <= g) {
            let name = &navs[*f].0;
            match r {
                Record::Gps(e) => {
                    for sf in subframes_of(e, name, &mut stats.worst_quantisation)? {
                        write_nav(&mut rec, nav_sample(e.prn, &sf, tow(*at)), *at)?;
                        stats.subframes += 1;
                    }
                    stats.ephemerides += 1;
                }
                Record::Glonass(r) => {
                    let frame = stats.glonass_ephemerides as u32;
                    for words in glonass_strings(r, name, frame, &mut stats.worst_quantisation)? {
                        write_nav(&mut rec, Some(nav_words(6, r.slot, 0, &words)), *at)?;
                    }
                    stats.glonass_ephemerides += 1;
                }
                Record::Kepler(k) if is_fnav(k) => {
                    for words in fnav_pages(k, name, &mut stats.worst_quantisation)? {
                        write_nav(&mut rec, Some(nav_words(2, k.sv, 3, &words)), *at)?;
                    }
                    stats.galileo_ephemerides += 1;
                }
                Record::Kepler(k) if k.system == 'E' => {
                    for words in galileo_pages(k, name, &mut stats.worst_quantisation)? {
                        write_nav(&mut rec, Some(nav_words(2, k.sv, 1, &words)), *at)?;
                    }
                    stats.galileo_ephemerides += 1;
                }
                Record::Kepler(k) => {
                    let (e, wrapped) = beidou_ephemeris(k, navs[*f].1.bds_iono, name)?;
                    let (sig, words) = beidou_words(&e, k, name, &mut stats.worst_quantisation)?;
                    for w in words {
                        write_nav(&mut rec, Some(nav_words(3, k.sv, sig, &w)), *at)?;
                    }
                    stats.beidou_ephemerides += 1;
                    stats.beidou_aode_wrapped += u64::from(wrapped);
                }
            }
        }
        let mut r = *raw;
        let host = host_of(g);
        r.stamp = Stamp::host(host, i as u64, StampSource::Simulated);
        rec.write(&raw_service, &AnySample::Raw(r), log_time(host), host.max(0) as u64)?;
        stats.epochs += 1;
        stats.measurements += u64::from(r.num_meas);
    }
    rec.close()?;
    Ok(stats)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ura_index_takes_nominal_values_and_upper_bounds() {
        for (m, n) in [
            (1.0, 0),
            (2.0, 0),
            (2.4, 0),
            (2.8, 1),
            (3.4, 1),
            (4.0, 2),
            (24.0, 6),
            (32.0, 7),
            (6144.0, 14),
        ] {
            assert_eq!(ura_index(m), n, "{m} m");
        }
        assert_eq!(ura_index(1e4), 15);
    }

    /// A RINEX ephemeris made from LNAV integers comes back as those integers, and a value
    /// outside a field's range is an error at the record's line.
    #[test]
    fn ephemeris_values_quantise_back_to_their_integers() {
        let e = GpsEphemeris {
            prn: 3,
            line: 42,
            toc_s: 7200.0,
            af: [-1234.0 * 2f64.powi(-31), 17.0 * 2f64.powi(-43), 0.0],
            iode: 77.0,
            iodc: 77.0,
            crs: -52.1875,
            delta_n: 937.0 * 2f64.powi(-43) * GPS_PI,
            m0: -1_234_567_890.0 * 2f64.powi(-31) * GPS_PI,
            e: 51_234_567.0 * 2f64.powi(-33),
            sqrt_a: 2_702_000_123.0 * 2f64.powi(-19),
            toe_s: 7200.0,
            omega_dot: -2000.0 * 2f64.powi(-43) * GPS_PI,
            idot: -1000.0 * 2f64.powi(-43) * GPS_PI,
            week: 1316.0,
            accuracy_m: 2.0,
            tgd_s: -7.0 * 2f64.powi(-31),
            ..GpsEphemeris::default()
        };
        let mut worst = 0.0;
        let [Subframe::Ephem1(s1), Subframe::Ephem2(s2), Subframe::Ephem3(s3)] =
            subframes_of(&e, "x.05n", &mut worst).unwrap()
        else {
            panic!("not subframes 1-3")
        };
        assert_eq!(
            (s1.af0, s1.af1, s1.tgd, s1.toc, s1.wn, s1.iodc),
            (-1234, 17, -7, 450, 292, 77)
        );
        assert_eq!(
            (s2.crs, s2.delta_n, s2.m0, s2.e, s2.sqrt_a, s2.toe),
            (-1670, 937, -1_234_567_890, 51_234_567, 2_702_000_123, 450)
        );
        assert_eq!((s3.omega_dot, s3.idot, s3.iode), (-2000, -1000, 77));
        assert!(worst < 1e-3, "{worst}");
        // And back: the subframes' ephemeris quantises to the same subframes.
        let back = ephemeris_of(3, 1201, &s1, &s2, &s3, 1300);
        assert_eq!((back.week, back.toc_week, back.tx_time_s), (1316.0, 1316, 7200.0));
        assert_eq!((back.crs, back.delta_n, back.sqrt_a), (e.crs, e.delta_n, e.sqrt_a));
        let again = subframes_of(&back, "x", &mut worst).unwrap();
        assert_eq!(
            again,
            [Subframe::Ephem1(s1), Subframe::Ephem2(s2), Subframe::Ephem3(s3)]
        );
        assert!(worst < 1e-3, "{worst}");
        let page = iono_page(
            [1.118e-8, 1.49e-8, -5.96e-8, -5.96e-8],
            [88_060.0, 16_380.0, -196_600.0, -131_100.0],
            "x",
        )
        .unwrap();
        let (a, b) = iono_of_page(&page);
        assert_eq!(iono_page(a, b, "x").unwrap(), page);
        assert!((a[0] - 1.118e-8).abs() < 2f64.powi(-31) && (b[2] + 196_600.0).abs() <= 2f64.powi(15));
        let bad = GpsEphemeris { crs: 2000.0, ..e };
        let err = subframes_of(&bad, "x.05n", &mut worst).unwrap_err();
        assert_eq!((err.file.as_str(), err.line, err.field.as_str()), ("x.05n", 42, "Crs"));
    }

    /// The walk's E07 and C21 records as `convbin` writes them become words that the
    /// estimator's decoders complete into ephemerides with the records' values (on the ICD's
    /// grid: no rounding); a value beyond its field, or a t_oe off BeiDou's 8 s grid, is an
    /// error at the record's line naming the field.
    #[test]
    fn galileo_and_beidou_records_become_words_the_decoders_read() {
        use navsync_estimator::gnss::beidou::{BdsAssembler, D2Assembler, decode_d1, decode_d2};
        use navsync_estimator::gnss::galileo::GalAssembler;
        use navsync_estimator::gnss::orbit::OrbitFrame;
        let e07 = KeplerRecord {
            line: 12,
            system: 'E',
            sv: 7,
            toc_week: 2381,
            toc_s: 407_400.0,
            af: [-2.029410679825e-4, -2.060573933704e-12, 0.0],
            orbit: [
                [44.0, -35.28125, 3.581934916253e-9, 0.6130816616549],
                [-1.486390829086e-6, 3.099185414612e-4, 4.768371582031e-6, 5440.609928131],
                [407_400.0, 8.940696716309e-8, 2.38676450559, 0.0],
                [0.965454400011, 238.96875, 0.3301908596947, -5.789169713584e-9],
                [5.178787145843e-11, 513.0, 2381.0, 0.0],
                [3.12, 0.0, 4.656612873077e-9, 4.889443516731e-9],
                [408_655.0, 0.0, 0.0, 0.0],
            ],
        };
        let mut worst = 0.0;
        let mut a = GalAssembler::default();
        let gal = galileo_pages(&e07, "w.nav", &mut worst)
            .unwrap()
            .iter()
            .filter_map(|w| a.on_word(7, &galileo::decode(w).unwrap()))
            .last()
            .unwrap();
        let o = gal.orbit();
        assert!(worst < 1e-3, "{worst}");
        assert_eq!(
            (o.toe_s, o.toc_s, gal.iod_nav(), gal.w5.wn, gal.sisa_m()),
            (407_400.0, 407_400.0, 44, 1357, Some(3.12))
        );
        assert!((o.sqrt_a - 5440.609928131).abs() < 1e-9 && (o.tgd_s - 4.889443516731e-9).abs() < 1e-18);
        assert!(gal.healthy());
        let bad = KeplerRecord {
            af: [1.0, 0.0, 0.0],
            ..e07
        };
        let err = galileo_pages(&bad, "w.nav", &mut worst).unwrap_err();
        assert_eq!(
            (err.file.as_str(), err.line, err.field.as_str()),
            ("w.nav", 12, "af0"),
            "{err}"
        );
        // The same satellite's F/NAV record (data sources 258, the (E1,E5a) clock): page types
        // 1–4 on E5a-I, with BGD(E1,E5a) as its group delay.
        let mut orbit = e07.orbit;
        (orbit[4][1], orbit[5][3]) = (258.0, 0.0);
        let f07 = KeplerRecord {
            af: [-2.029420575127e-4, -2.074784788419e-12, 0.0],
            orbit,
            ..e07
        };
        assert!(is_fnav(&f07) && !is_fnav(&e07));
        let mut a = navsync_estimator::gnss::fnav::FnavAssembler::default();
        let f = fnav_pages(&f07, "w.nav", &mut worst)
            .unwrap()
            .iter()
            .filter_map(|w| a.on_page(7, &fnav::decode(w).unwrap()))
            .last()
            .unwrap();
        let o = f.orbit();
        assert!(worst < 1e-3, "{worst}");
        assert_eq!((o.toe_s, o.tgd_s, f.p1.wn), (407_400.0, 4.6566128730773926e-9, 1357));
        assert!((o.af[0] + 2.029420575127e-4).abs() < 2f64.powi(-34));
        assert!(f.healthy());

        let c21 = KeplerRecord {
            line: 40,
            system: 'C',
            sv: 21,
            toc_week: 1025,
            toc_s: 406_800.0,
            af: [-9.634450543672e-4, -6.846967437468e-12, 0.0],
            orbit: [
                [85.0, -3.5, 3.659438144573e-9, 0.8863045281069],
                [-1.336447894573e-7, 5.563498707488e-4, 6.671529263258e-6, 5282.626552582],
                [406_800.0, 4.516914486885e-8, 1.750643840109, -5.215406417847e-8],
                [0.9838546573813, 238.25, 5.962172078684e-2, -6.660634585023e-9],
                [3.675153084878e-10, 0.0, 1025.0, 0.0],
                [2.0, 0.0, 1.33e-8, 1.33e-8],
                [408_630.0, 1.0, 0.0, 0.0],
            ],
        };
        let mut worst = 0.0;
        let (e, wrapped) = beidou_ephemeris(&c21, None, "w.nav").unwrap();
        let (sig, words) = beidou_words(&e, &c21, "w.nav", &mut worst).unwrap();
        let mut a = BdsAssembler::default();
        let bds = words
            .iter()
            .filter_map(|w| a.on_subframe(21, &decode_d1(w).unwrap()))
            .last()
            .unwrap();
        assert!(sig == 0 && wrapped && worst < 1e-3, "{worst}");
        // The same orbit as a GEO's (PRN 3): D2 pages on B1I D2, the same ephemeris.
        let geo = KeplerRecord { sv: 3, ..c21 };
        let (e3, _) = beidou_ephemeris(&geo, None, "w.nav").unwrap();
        let (sig, pages) = beidou_words(&e3, &geo, "w.nav", &mut worst).unwrap();
        let mut d2 = D2Assembler::default();
        let back = pages
            .iter()
            .filter_map(|w| d2.on_page(3, &decode_d2(w).unwrap()?))
            .last()
            .unwrap();
        assert_eq!((sig, pages.len(), back.orbit().frame), (1, 10, OrbitFrame::BeiDouGeo));
        assert_eq!(BdsEphemeris { sv: 21, ..back }, bds);
        let o = bds.orbit();
        assert_eq!(
            (o.toe_s, bds.s1.aode, bds.s1.aodc, bds.s1.week, bds.s1.urai),
            (406_800.0, 85 % 32, 1, 1025, 0)
        );
        assert!((o.sqrt_a - 5282.626552582).abs() < 1e-9 && (bds.s1.tgd1_s - 1.33e-8).abs() < 1e-18);
        let off = KeplerRecord {
            orbit: [
                c21.orbit[0],
                c21.orbit[1],
                [406_804.0, 0.0, 0.0, 0.0],
                c21.orbit[3],
                c21.orbit[4],
                c21.orbit[5],
                c21.orbit[6],
            ],
            ..c21
        };
        let err = beidou_ephemeris(&off, None, "w.nav").unwrap_err();
        assert_eq!((err.line, err.field.as_str()), (40, "Toe"), "{err}");
        let bad = KeplerRecord {
            af: [0.0, 1.0, 0.0],
            ..c21
        };
        let (e, _) = beidou_ephemeris(&bad, None, "w.nav").unwrap();
        let err = beidou_words(&e, &bad, "w.nav", &mut worst).unwrap_err();
        assert_eq!((err.line, err.field.as_str()), (40, "a1"), "{err}");
    }

    /// Any record a file may hold (NaN, infinities, huge, negative, fractional values in any
    /// field; any satellite number) is words or an error naming a field, never a panic.
    #[test]
    fn arbitrary_galileo_and_beidou_records_never_panic() {
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        let specials = [
            f64::NAN,
            f64::INFINITY,
            -1e300,
            -1.0,
            0.0,
            0.5,
            1.0,
            1e9,
            604_800.0,
            406_800.0,
        ];
        let (mut ok, mut errors) = (0, 0);
        for _ in 0..20_000 {
            let value = |r: u64| {
                if r.is_multiple_of(4) {
                    specials[(r >> 8) as usize % specials.len()]
                } else {
                    f64::from_bits(r >> 2) % 1e6
                }
            };
            let mut orbit = [[0.0; 4]; 7];
            for v in orbit.iter_mut().flatten() {
                *v = value(next());
            }
            let k = KeplerRecord {
                line: 7,
                system: if next() % 2 == 0 { 'E' } else { 'C' },
                sv: (next() % 70) as u8,
                toc_week: (next() % 5000) as u32,
                toc_s: value(next()),
                af: [value(next()), value(next()), value(next())],
                orbit,
            };
            let mut worst = 0.0;
            let r = if k.system == 'E' {
                let fnav = fnav_pages(&k, "x", &mut worst).map(|_| ());
                galileo_pages(&k, "x", &mut worst).map(|_| ()).and(fnav)
            } else {
                beidou_ephemeris(&k, None, "x").and_then(|(e, _)| beidou_words(&e, &k, "x", &mut worst).map(|_| ()))
            };
            match r {
                Ok(()) => ok += 1,
                Err(e) => {
                    assert_eq!((e.line, e.file.as_str()), (7, "x"));
                    assert!(!e.field.is_empty());
                    errors += 1;
                }
            }
        }
        assert!(errors > 1000, "{ok} encoded, {errors} errors");
    }
}
