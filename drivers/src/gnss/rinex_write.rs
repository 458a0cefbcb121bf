//! RINEX 3.05 observation and navigation files written as text (pure: no I/O), the inverse of
//! [`super::rinex`]: a receiver's [`GnssRaw`] epochs and its GPS, GLONASS, Galileo and BeiDou
//! ephemerides out.
//!
//! Format: RINEX 3.05 (IGS/RTCM-SC104, "RINEX The Receiver Independent Exchange Format Version
//! 3.05", 2020): observation header Table A2, records Table A3 (§5.4 half-cycle ambiguities,
//! §5.7 signal strength), observation codes §5.1 (the u-blox signal ids mapped back by
//! [`super::rinex::rinex_signal`]); navigation header Table A5 (`IONOSPHERIC CORR` GPSA/GPSB),
//! GPS records Table A8, GLONASS records Table A10, and the appendix's "GALILEO" and "BDS
//! NAVIGATION MESSAGE FILE – DATA RECORD DESCRIPTION" tables.

use std::fmt::Write;

use navsync_shared::samples::{GnssRaw, RawMeasurement};
use navsync_shared::time::{civil_from_days, days_from_civil};

use super::rinex::{GloRecord, GpsEphemeris, KeplerRecord, rinex_signal};

/// Seconds in a GPS week.
const WEEK_S: f64 = 604_800.0;

/// Why a file could not be written.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RinexWriteError {
    /// No epoch: an observation file needs `TIME OF FIRST OBS`.
    #[error("no observation epoch to write")]
    NoEpochs,
    /// An epoch whose time is not a GPS time (seconds of week outside 0..604800).
    #[error("epoch {index}: time of week {tow_s} s is not in 0..604800")]
    BadEpochTime {
        /// The epoch's index.
        index: usize,
        /// Its seconds of week.
        tow_s: f64,
    },
}

/// What an observation file's header says beside its observations.
#[derive(Debug, Clone, PartialEq)]
pub struct ObsHeader {
    /// `PGM / RUN BY / DATE`: program (20 characters at most).
    pub program: String,
    /// `PGM / RUN BY / DATE`: the date of creation, `yyyymmdd hhmmss UTC` (§5.8).
    pub date: String,
    /// `MARKER NAME` (60 characters at most).
    pub marker: String,
    /// `APPROX POSITION XYZ`, ECEF m.
    pub approx_ecef_m: [f64; 3],
}

/// An observation file and what it left out.
#[derive(Debug, Clone, PartialEq)]
pub struct ObsText {
    /// The file.
    pub text: String,
    /// Measurements of signals without a RINEX code in [`super::rinex::SIGNALS`] (or
    /// satellites without a RINEX number), not written.
    pub unmapped: u64,
}

/// The system letters in the order their records are written (u-blox gnssId order).
const SYSTEMS: [char; 6] = ['G', 'S', 'E', 'C', 'J', 'R'];

/// RINEX satellite number of a u-blox svId (SBAS 120–158 → S20–S58; others as they are).
fn rinex_prn(system: char, sv_id: u8) -> Option<u8> {
    let prn = if system == 'S' { sv_id.checked_sub(100)? } else { sv_id };
    (1..=99).contains(&prn).then_some(prn)
}

/// The four observation kinds (§5.1: code, phase, Doppler, signal strength) of a measurement,
/// `None` where it has none.
fn values(m: &RawMeasurement) -> [Option<f64>; 4] {
    let ok = |v: f64| v.is_finite() && v.abs() < 1e9;
    let c = (m.trk_stat & 1 != 0 && ok(m.pseudorange_m)).then_some(m.pseudorange_m);
    let l = (m.trk_stat & 2 != 0 && ok(m.carrier_phase_cycles) && m.carrier_phase_cycles != 0.0)
        .then_some(m.carrier_phase_cycles);
    let d = ok(f64::from(m.doppler_hz)).then_some(f64::from(m.doppler_hz));
    let s = (m.cno_dbhz > 0).then_some(f64::from(m.cno_dbhz));
    [c, l, d, s]
}

/// A signal's RINEX code and which kinds (in [`KINDS`] order) have a value in the file.
type SignalKinds = ([char; 3], [bool; 4]);

/// An observation column: its signal's index in the system's list, the code, the kind.
type Column = (usize, [char; 3], usize);

/// The observation kinds' letters, in the order of [`values`].
const KINDS: [char; 4] = ['C', 'L', 'D', 'S'];

/// The calendar date and time of a GPS time: (year, month, day, hour, minute, seconds).
pub fn calendar(week: u32, tow_s: f64) -> (i64, u32, u32, u32, u32, f64) {
    // Rounded to the 0.1 µs RINEX prints, so that 59.99999999 s is not written as 60.
    let s = (tow_s * 1e7).round() / 1e7;
    let day = (s / 86_400.0).floor();
    let (y, mo, d) = civil_from_days(days_from_civil(1980, 1, 6) + i64::from(week) * 7 + day as i64);
    let in_day = s - day * 86_400.0;
    let whole = in_day.floor() as u32;
    (
        y,
        mo,
        d,
        whole / 3600,
        whole / 60 % 60,
        in_day - f64::from(whole - whole % 60),
    )
}

/// A header line: the content in columns 1–60, the label in 61–80.
fn header(out: &mut String, content: &str, label: &str) {
    let _ = writeln!(out, "{content:<60.60}{label}");
}

/// A Fortran `Dw.d`-style number as RINEX 3 writes it: one digit before the point, `d`
/// decimals, an `E` and a signed two-digit exponent, right-justified in `w` columns.
pub fn fortran_e(x: f64, w: usize, d: usize) -> String {
    let s = format!("{x:.d$E}");
    let (mantissa, exp) = s.split_once('E').unwrap_or((&s, "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    let sign = if exp < 0 { '-' } else { '+' };
    format!("{:>w$}", format!("{mantissa}E{sign}{:02}", exp.abs()))
}

/// An observation file (RINEX 3.05, Tables A2 and A3) of `epochs`, each at its receiver time
/// (`week`, `rcv_tow_s`, GPS time). Per system present, its `SYS / # / OBS TYPES` lists every
/// signal observed, each with the kinds (C, L, D, S) it has a value of anywhere in the file.
/// Values are F14.3; the phase's loss-of-lock indicator (LLI) has bit 0 set when the signal's
/// lock time says it was not kept since its previous epoch ([`RawMeasurement::kept_lock`]: a
/// possible cycle slip) and bit 1 when the
/// half-cycle ambiguity is not resolved (§5.4; u-blox `trkStat` bit 2 clear); every value's
/// signal strength indicator (SSI) is C/N0 in 6 dB-Hz steps, 1–9 (§5.7, Table 12).
pub fn write_obs(h: &ObsHeader, epochs: &[GnssRaw]) -> Result<ObsText, RinexWriteError> {
    let (first, last) = match (epochs.first(), epochs.last()) {
        (Some(a), Some(b)) => (a, b),
        _ => return Err(RinexWriteError::NoEpochs),
    };
    for (index, e) in epochs.iter().enumerate() {
        if !(0.0..WEEK_S).contains(&e.rcv_tow_s) {
            return Err(RinexWriteError::BadEpochTime {
                index,
                tow_s: e.rcv_tow_s,
            });
        }
    }
    // Per system, the codes present (band, attribute) with which kinds have values.
    let mut types: Vec<(char, Vec<SignalKinds>)> = SYSTEMS.iter().map(|&s| (s, Vec::new())).collect();
    let mut glonass: Vec<(u8, i8)> = Vec::new();
    let mut unmapped = 0u64;
    let mut leap = None;
    for e in epochs {
        if e.rec_stat & 1 != 0 {
            leap = Some(e.leap_s);
        }
        for m in e.meas.iter().take(usize::from(e.num_meas)) {
            let Some((sys, band, attr)) = rinex_signal(m.gnss_id, m.sig_id) else {
                unmapped += 1;
                continue;
            };
            if rinex_prn(sys, m.sv_id).is_none() {
                unmapped += 1;
                continue;
            }
            if sys == 'R' && !glonass.iter().any(|(p, _)| *p == m.sv_id) && m.freq_id <= 13 {
                glonass.push((m.sv_id, m.freq_id as i8 - 7));
            }
            let list = &mut types.iter_mut().find(|(s, _)| *s == sys).expect("SYSTEMS holds it").1;
            let code = [sys, band, attr];
            let at = match list.iter().position(|(c, _)| *c == code) {
                Some(i) => i,
                None => {
                    list.push((code, [false; 4]));
                    list.len() - 1
                }
            };
            for (k, v) in values(m).iter().enumerate() {
                list[at].1[k] |= v.is_some();
            }
        }
    }
    // Signals in the table's order within a system; systems without a value left out.
    for (_, list) in &mut types {
        list.retain(|(_, has)| has.iter().any(|&b| b));
        list.sort_by_key(|(c, _)| super::rinex::SIGNALS.iter().position(|s| [s.0, s.1, s.2] == *c));
    }
    types.retain(|(_, list)| !list.is_empty());
    glonass.sort_unstable();

    let mut out = String::new();
    let system = match types.as_slice() {
        [(s, _)] => *s,
        _ => 'M',
    };
    header(
        &mut out,
        &format!("{:9.2}{:11}{:<20}{:<20}", 3.05, "", "OBSERVATION DATA", system),
        "RINEX VERSION / TYPE",
    );
    header(
        &mut out,
        &format!("{:<20.20}{:<20}{:<20.20}", h.program, "", h.date),
        "PGM / RUN BY / DATE",
    );
    header(&mut out, &h.marker, "MARKER NAME");
    header(&mut out, "", "OBSERVER / AGENCY");
    header(&mut out, "", "REC # / TYPE / VERS");
    header(&mut out, "", "ANT # / TYPE");
    let p = h.approx_ecef_m;
    header(
        &mut out,
        &format!("{:14.4}{:14.4}{:14.4}", p[0], p[1], p[2]),
        "APPROX POSITION XYZ",
    );
    header(
        &mut out,
        &format!("{:14.4}{:14.4}{:14.4}", 0.0, 0.0, 0.0),
        "ANTENNA: DELTA H/E/N",
    );
    // Each system's types (A1, 2X, I3, 13(1X, A3); continuation lines 6X, 13(1X, A3)).
    let mut columns: Vec<(char, Vec<Column>)> = Vec::new();
    for (sys, list) in &types {
        let mut codes = Vec::new();
        let mut cols = Vec::new();
        for (k, (code, has)) in list.iter().enumerate() {
            for (j, kind) in KINDS.iter().enumerate() {
                if has[j] {
                    cols.push((k, *code, j));
                    codes.push(format!("{kind}{}{}", code[1], code[2]));
                }
            }
        }
        for (n, chunk) in codes.chunks(13).enumerate() {
            let lead = if n == 0 {
                format!("{sys}  {:3}", codes.len())
            } else {
                " ".repeat(6)
            };
            header(&mut out, &format!("{lead} {}", chunk.join(" ")), "SYS / # / OBS TYPES");
        }
        columns.push((*sys, cols));
    }
    header(&mut out, "DBHZ", "SIGNAL STRENGTH UNIT");
    let time_line = |e: &GnssRaw| {
        let (y, mo, d, hh, mm, ss) = calendar(u32::from(e.week), e.rcv_tow_s);
        format!("  {y:4}    {mo:02}    {d:02}    {hh:02}    {mm:02}   {ss:10.7}     GPS")
    };
    header(&mut out, &time_line(first), "TIME OF FIRST OBS");
    header(&mut out, &time_line(last), "TIME OF LAST OBS");
    if let Some(leap) = leap {
        header(&mut out, &format!("{leap:6}"), "LEAP SECONDS");
    }
    // Phase shifts (required since 3.01): the system alone, no correction applied.
    for (sys, _) in &types {
        header(&mut out, &sys.to_string(), "SYS / PHASE SHIFT");
    }
    if types.iter().any(|(s, _)| *s == 'R') {
        for (n, chunk) in glonass.chunks(8).enumerate() {
            let lead = if n == 0 {
                format!("{:3} ", glonass.len())
            } else {
                " ".repeat(4)
            };
            let list: String = chunk.iter().map(|(p, f)| format!("R{p:02} {f:2} ")).collect();
            header(&mut out, &format!("{lead}{list}"), "GLONASS SLOT / FRQ #");
        }
        header(
            &mut out,
            " C1C    0.000 C1P    0.000 C2C    0.000 C2P    0.000",
            "GLONASS COD/PHS/BIS",
        );
    }
    header(&mut out, "", "END OF HEADER");

    // Records (Table A3): the epoch line, then one line per satellite.
    let mut lock = super::rinex::LockTimes::new();
    for e in epochs {
        let meas = &e.meas[..usize::from(e.num_meas).min(e.meas.len())];
        let mut sats: Vec<(usize, u8, u8)> = Vec::new(); // (system index, RINEX prn, svId)
        for m in meas {
            let Some((sys, _, _)) = rinex_signal(m.gnss_id, m.sig_id) else {
                continue;
            };
            let Some(prn) = rinex_prn(sys, m.sv_id) else { continue };
            let Some(si) = columns.iter().position(|(s, _)| *s == sys) else {
                continue;
            };
            if !sats.contains(&(si, prn, m.sv_id)) {
                sats.push((si, prn, m.sv_id));
            }
        }
        sats.sort_unstable();
        let (y, mo, d, hh, mm, ss) = calendar(u32::from(e.week), e.rcv_tow_s);
        let _ = writeln!(
            out,
            "> {y:4} {mo:02} {d:02} {hh:02} {mm:02}{ss:11.7}  0{:3}",
            sats.len()
        );
        for (si, prn, sv) in sats {
            let (sys, cols) = &columns[si];
            let mut line = format!("{sys}{prn:02}");
            let signal = |code: [char; 3]| {
                meas.iter()
                    .find(|m| m.sv_id == sv && rinex_signal(m.gnss_id, m.sig_id) == Some((code[0], code[1], code[2])))
            };
            for (_, code, kind) in cols {
                let Some(m) = signal(*code) else {
                    line += &" ".repeat(16);
                    continue;
                };
                let Some(v) = values(m)[*kind] else {
                    line += &" ".repeat(16);
                    continue;
                };
                let mut lli = 0u8;
                if *kind == 1 {
                    let key = (m.gnss_id, m.sv_id, m.sig_id);
                    let now_s = f64::from(e.week) * 604_800.0 + e.rcv_tow_s;
                    if let Some(&(then_s, prev)) = lock.get(&key)
                        && !RawMeasurement::kept_lock(prev, m.lock_time_ms, now_s - then_s)
                    {
                        lli |= 1;
                    }
                    lock.insert(key, (now_s, m.lock_time_ms));
                    if m.trk_stat & 4 == 0 {
                        lli |= 2;
                    }
                }
                let ssi = if m.cno_dbhz > 0 {
                    char::from(b'0' + (m.cno_dbhz / 6).clamp(1, 9))
                } else {
                    ' '
                };
                let lli = if lli > 0 { char::from(b'0' + lli) } else { ' ' };
                let _ = write!(line, "{v:14.3}{lli}{ssi}");
            }
            let _ = writeln!(out, "{}", line.trim_end());
        }
    }
    Ok(ObsText { text: out, unmapped })
}

/// The records of a navigation file.
#[derive(Debug, Clone, Copy, Default)]
pub struct NavRecords<'a> {
    /// GPS's Klobuchar α/β (`IONOSPHERIC CORR` GPSA/GPSB).
    pub iono: Option<([f64; 4], [f64; 4])>,
    /// BeiDou's Klobuchar α/β (`IONOSPHERIC CORR` BDSA/BDSB).
    pub bds_iono: Option<([f64; 4], [f64; 4])>,
    /// GPS LNAV ephemerides.
    pub gps: &'a [GpsEphemeris],
    /// GLONASS ephemerides.
    pub glonass: &'a [GloRecord],
    /// Galileo and BeiDou ephemerides.
    pub kepler: &'a [KeplerRecord],
}

/// A navigation file (RINEX 3.05, Tables A5, A8, A10 and the Galileo and BDS record tables):
/// the header with the Klobuchar
/// α/β as `IONOSPHERIC CORR` GPSA/GPSB when given, then each GPS ephemeris (t_oc as a calendar
/// epoch, values as D19.12, the fit interval in hours), each GLONASS one (t_b as a UTC
/// calendar epoch, −τ_n, γ_n, t_k as s of the UTC day; km, km/s, km/s²; health, channel, age;
/// 3.05's fourth orbit line with status flags and the L1/L2 delay difference unknown, 0, the
/// accuracy index F_T as URAI (4, 5 m, when unknown), health flags 0) and each Galileo and
/// BeiDou one (t_oc as a calendar epoch of GST, of BDT). The system is `G`, `R`, `E`, `C` or
/// `M` (mixed) after what it holds.
pub fn write_nav(program: &str, date: &str, records: &NavRecords) -> String {
    let NavRecords {
        iono,
        bds_iono,
        gps: ephemerides,
        glonass,
        kepler,
    } = *records;
    let mut systems: Vec<char> = kepler.iter().map(|k| k.system).collect();
    systems.extend(ephemerides.first().map(|_| 'G'));
    systems.extend(glonass.first().map(|_| 'R'));
    systems.sort_unstable();
    systems.dedup();
    let mut out = String::new();
    let system = match systems.as_slice() {
        ['R'] => "R: GLONASS",
        ['E'] => "E: GALILEO",
        ['C'] => "C: BEIDOU",
        [] | ['G'] => "G: GPS",
        _ => "M: MIXED",
    };
    header(
        &mut out,
        &format!("{:9.2}{:11}{:<20}{:<20}", 3.05, "", "N: GNSS NAV DATA", system),
        "RINEX VERSION / TYPE",
    );
    header(
        &mut out,
        &format!("{program:<20.20}{:<20}{date:<20.20}", ""),
        "PGM / RUN BY / DATE",
    );
    for (names, coefficients) in [(["GPSA", "GPSB"], iono), (["BDSA", "BDSB"], bds_iono)] {
        let Some((a, b)) = coefficients else { continue };
        for (name, v) in names.into_iter().zip([a, b]) {
            let coefficients: String = v.iter().map(|x| fortran_e(*x, 12, 4)).collect();
            header(&mut out, &format!("{name} {coefficients}"), "IONOSPHERIC CORR");
        }
    }
    header(&mut out, "", "END OF HEADER");
    for e in ephemerides {
        let (y, mo, d, hh, mm, ss) = calendar(e.toc_week, e.toc_s);
        let f = |x: f64| fortran_e(x, 19, 12);
        let _ = writeln!(
            out,
            "G{:02} {y:4} {mo:02} {d:02} {hh:02} {mm:02} {:02}{}{}{}",
            e.prn,
            ss.round() as u32,
            f(e.af[0]),
            f(e.af[1]),
            f(e.af[2])
        );
        let rows: [&[f64]; 7] = [
            &[e.iode, e.crs, e.delta_n, e.m0],
            &[e.cuc, e.e, e.cus, e.sqrt_a],
            &[e.toe_s, e.cic, e.omega0, e.cis],
            &[e.i0, e.crc, e.omega, e.omega_dot],
            &[e.idot, e.l2_codes, e.week, e.l2p],
            &[e.accuracy_m, e.health, e.tgd_s, e.iodc],
            &[e.tx_time_s, e.fit_h],
        ];
        for row in rows {
            let _ = writeln!(out, "    {}", row.iter().map(|x| f(*x)).collect::<String>());
        }
    }
    for r in glonass {
        let f = |x: f64| fortran_e(x, 19, 12);
        let (y, mo, d) = civil_from_days(r.toc_utc_day);
        let sod = r.toc_utc_sod_s.round() as u32;
        let _ = writeln!(
            out,
            "R{:02} {y:4} {mo:02} {d:02} {:02} {:02} {:02}{}{}{}",
            r.slot,
            sod / 3600,
            sod / 60 % 60,
            sod % 60,
            f(-r.tau_s),
            f(r.gamma),
            f(r.tk_s)
        );
        let extra = [r.health, f64::from(r.channel), r.age_days];
        for (i, last) in extra.into_iter().enumerate() {
            let _ = writeln!(
                out,
                "    {}{}{}{}",
                f(r.pos_m[i] / 1e3),
                f(r.vel_mps[i] / 1e3),
                f(r.acc_mps2[i] / 1e3),
                f(last)
            );
        }
        let urai = f64::from(r.accuracy_index.unwrap_or(4));
        let _ = writeln!(out, "    {}{}{}{}", f(0.0), f(0.0), f(urai), f(0.0));
    }
    for k in kepler {
        let f = |x: f64| fortran_e(x, 19, 12);
        // BDT's calendar is GPS's shifted by whole weeks (no leap second between the epochs'
        // days matters: each scale's own calendar is written).
        let week = k.toc_week
            + if k.system == 'C' {
                super::rinex::BDT_WEEK_OFFSET
            } else {
                0
            };
        let (y, mo, d, hh, mm, ss) = calendar(week, k.toc_s);
        let _ = writeln!(
            out,
            "{}{:02} {y:4} {mo:02} {d:02} {hh:02} {mm:02} {:02}{}{}{}",
            k.system,
            k.sv,
            ss.round() as u32,
            f(k.af[0]),
            f(k.af[1]),
            f(k.af[2])
        );
        for (i, row) in k.orbit.iter().enumerate() {
            let row = if i == 6 { &row[..2] } else { &row[..] };
            let _ = writeln!(out, "    {}", row.iter().map(|x| f(*x)).collect::<String>());
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::rinex::{gps_time, parse_nav, parse_obs};
    use super::*;
    use navsync_shared::reflect::Reflect;

    fn meas(gnss_id: u8, sv_id: u8, sig_id: u8, pr: f64, cp: f64, cno: u8) -> RawMeasurement {
        let mut m = RawMeasurement::zeroed();
        (m.gnss_id, m.sv_id, m.sig_id, m.cno_dbhz) = (gnss_id, sv_id, sig_id, cno);
        (m.pseudorange_m, m.carrier_phase_cycles, m.doppler_hz) = (pr, cp, -1234.5);
        m.trk_stat = 0b111;
        m.lock_time_ms = 5000;
        m
    }

    fn epoch(tow_s: f64, meas_list: &[RawMeasurement]) -> GnssRaw {
        let mut e = GnssRaw::zeroed();
        (e.week, e.rcv_tow_s, e.leap_s, e.rec_stat) = (2110, tow_s, 18, 1);
        e.meas[..meas_list.len()].copy_from_slice(meas_list);
        e.num_meas = meas_list.len() as u8;
        e
    }

    const HEADER: fn() -> ObsHeader = || ObsHeader {
        program: "navsync 0.1".into(),
        date: "20261205 061500 UTC".into(),
        marker: "TEST".into(),
        approx_ecef_m: [-3976219.5082, 3382372.5671, 3652512.9849],
    };

    #[test]
    fn observations_are_written_as_rinex_305_and_read_back() {
        let t = gps_time(2020, 6, 14, 12, 0, 1.5);
        let mut a = meas(0, 5, 0, 21000000.125, 110356000.25, 45);
        let b = meas(2, 11, 0, 23000000.5, 0.0, 0);
        let c = meas(3, 7, 0, 24000000.75, 124000000.5, 40);
        a.trk_stat = 0b011; // half cycle not resolved
        let mut a2 = a;
        a2.lock_time_ms = 100; // lock time went down: a possible slip
        let mut glo = meas(6, 3, 0, 20000000.0, 1e8, 30);
        glo.freq_id = 7 - 4;
        let unknown = meas(0, 9, 1, 1.0, 1.0, 1); // GPS sigId 1: no RINEX code in the table
        let epochs = [
            epoch(t.tow_s, &[a, b, c, glo, unknown]),
            epoch(t.tow_s + 59.999_999_999_99, &[a2]),
        ];
        let w = write_obs(&HEADER(), &epochs).unwrap();
        assert_eq!(w.unmapped, 1);
        let lines: Vec<&str> = w.text.lines().collect();
        assert_eq!(
            lines[0],
            "     3.05           OBSERVATION DATA    M                   RINEX VERSION / TYPE"
        );
        assert!(lines.iter().all(|l| l.len() <= 80), "{}", w.text);
        let find = |label: &str| lines.iter().filter(|l| l.ends_with(label)).copied().collect::<Vec<_>>();
        assert_eq!(
            find("SYS / # / OBS TYPES"),
            [
                "G    4 C1C L1C D1C S1C                                      SYS / # / OBS TYPES",
                "E    2 C1C D1C                                              SYS / # / OBS TYPES",
                "C    4 C2I L2I D2I S2I                                      SYS / # / OBS TYPES",
                "R    4 C1C L1C D1C S1C                                      SYS / # / OBS TYPES",
            ]
        );
        assert_eq!(
            find("TIME OF FIRST OBS")[0],
            "  2020    06    14    12    00    1.5000000     GPS         TIME OF FIRST OBS"
        );
        assert_eq!(
            find("GLONASS SLOT / FRQ #")[0].trim_end(),
            format!("{:<60}GLONASS SLOT / FRQ #", "  1 R03 -4")
        );
        let body = w.text.split("END OF HEADER\n").nth(1).unwrap();
        let body: Vec<&str> = body.lines().collect();
        assert_eq!(body[0], "> 2020 06 14 12 00  1.5000000  0  4");
        // C1C, L1C with LLI 2 (half cycle), D1C, S1C; SSI 7 (45 dB-Hz) on each.
        assert_eq!(
            body[1],
            "G05  21000000.125 7 110356000.25027     -1234.500 7        45.000 7"
        );
        // 59.99999999999 s after 12:00:01.5 is 12:01:01.5, not 12:00:61.5.
        assert_eq!(body[5], "> 2020 06 14 12 01  1.5000000  0  1");
        assert!(body[6].contains("110356000.25037"), "slip and half cycle: {}", body[6]);

        let back = parse_obs("x.obs", &w.text).unwrap();
        assert_eq!(back.approx_ecef_m, Some(HEADER().approx_ecef_m));
        assert_eq!(back.leap_s, Some(18));
        assert_eq!(back.epochs.len(), 2);
        let e = back.epochs[0];
        assert_eq!((e.week, e.rcv_tow_s, e.num_meas), (2110, t.tow_s, 4));
        let ids: Vec<_> = e.meas[..4].iter().map(|m| (m.gnss_id, m.sv_id, m.sig_id)).collect();
        assert_eq!(ids, [(0, 5, 0), (2, 11, 0), (3, 7, 0), (6, 3, 0)]);
        for (got, want) in e.meas[..4].iter().zip([a, b, c, glo]) {
            assert_eq!(got.pseudorange_m, want.pseudorange_m);
            assert_eq!(got.doppler_hz, want.doppler_hz);
            assert_eq!(got.cno_dbhz, want.cno_dbhz);
        }
        assert_eq!(
            (e.meas[0].carrier_phase_cycles, e.meas[0].trk_stat),
            (110356000.25, 0b011)
        );
        assert!(e.meas[1].carrier_phase_cycles.is_nan());
    }

    #[test]
    fn nothing_to_write_is_an_error() {
        assert_eq!(write_obs(&HEADER(), &[]), Err(RinexWriteError::NoEpochs));
        let e = epoch(WEEK_S, &[]);
        assert!(matches!(
            write_obs(&HEADER(), &[e]),
            Err(RinexWriteError::BadEpochTime { index: 0, .. })
        ));
    }

    /// A GLONASS record written (with 3.05's fourth orbit line) reads back the same, beside
    /// a GPS one in a mixed file and alone in a GLONASS file.
    #[test]
    fn glonass_records_are_written_and_read_back() {
        let r = GloRecord {
            slot: 12,
            line: 0,
            toc: super::super::rinex::GpsTime {
                week: 2268,
                tow_s: 312_318.0,
            },
            toc_utc_sod_s: 53_100.0,
            toc_utc_day: 19_536,
            tau_s: -2.856153326e-5,
            gamma: 9.094947017729e-13,
            tk_s: 53_820.0,
            pos_m: [-8_905_342.7, 14_087_869.1, 19_335_698.6],
            vel_mps: [-2_294.995307922, 1_309.631347656, -1_966.602325439],
            acc_mps2: [9.313225746155e-7, 0.0, -2.793967723846e-6],
            health: 0.0,
            channel: -5,
            age_days: 1.0,
            accuracy_index: Some(3),
        };
        for mixed in [false, true] {
            let text = write_nav(
                "navsync",
                "20261205 061500 UTC",
                &NavRecords {
                    glonass: &[r],
                    ..NavRecords::default()
                },
            );
            let text = if mixed {
                text.replace("R: GLONASS", "M: MIXED  ")
            } else {
                text
            };
            assert!(
                text.lines()
                    .next()
                    .unwrap()
                    .contains(if mixed { "M: MIXED" } else { "R: GLONASS" })
            );
            let back = parse_nav("g.nav", &text).unwrap();
            assert_eq!(back.glonass.len(), 1);
            let b = back.glonass[0];
            assert_eq!(
                (b.slot, b.toc, b.toc_utc_sod_s, b.toc_utc_day),
                (12, r.toc, 53_100.0, 19_536)
            );
            assert_eq!(
                (b.channel, b.age_days, b.accuracy_index, b.tk_s),
                (-5, 1.0, Some(3), 53_820.0)
            );
            for i in 0..3 {
                assert!(
                    (b.pos_m[i] - r.pos_m[i]).abs() < 1e-6,
                    "{i}: {}",
                    b.pos_m[i] - r.pos_m[i]
                );
                assert!((b.vel_mps[i] - r.vel_mps[i]).abs() < 1e-9 && (b.acc_mps2[i] - r.acc_mps2[i]).abs() < 1e-15);
            }
            assert!((b.tau_s - r.tau_s).abs() < 1e-17 && (b.gamma - r.gamma).abs() < 1e-24);
        }
    }

    #[test]
    fn ephemerides_are_written_as_rinex_305_and_read_back() {
        assert_eq!(fortran_e(-3.25962901115e-9, 19, 12), "-3.259629011150E-09");
        assert_eq!(fortran_e(525_600.0, 19, 12), " 5.256000000000E+05");
        assert_eq!(fortran_e(0.0, 12, 4), "  0.0000E+00");
        let e = GpsEphemeris {
            prn: 7,
            toc_week: 1316,
            toc_s: 525_600.0,
            af: [3.966595977540e-4, 1.705302565820e-12, 0.0],
            iode: 140.0,
            crs: -52.1875,
            delta_n: 4.02659638965e-9,
            m0: 2.87153499034,
            cuc: -2.67662107944e-6,
            e: 5.95761800651e-3,
            cus: 4.17418777943e-6,
            sqrt_a: 5153.63647842,
            toe_s: 525_600.0,
            cic: 1.06170773506e-7,
            omega0: -2.49318481774,
            cis: -9.31322574615e-8,
            i0: 0.983391914449,
            crc: 309.375,
            omega: -1.65049681327,
            omega_dot: -7.88997134293e-9,
            idot: -8.5717856424e-12,
            l2_codes: 1.0,
            week: 1316.0,
            l2p: 0.0,
            accuracy_m: 2.0,
            health: 0.0,
            tgd_s: -3.25962901115e-9,
            iodc: 396.0,
            tx_time_s: 519_576.0,
            fit_h: 4.0,
            line: 0,
        };
        let alpha = [1.118e-8, 1.49e-8, -5.96e-8, -5.96e-8];
        let beta = [88_060.0, 16_380.0, -196_600.0, -131_100.0];
        let text = write_nav(
            "navsync",
            "20261205 061500 UTC",
            &NavRecords {
                iono: Some((alpha, beta)),
                gps: &[e],
                ..NavRecords::default()
            },
        );
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(
            lines[2],
            "GPSA   1.1180E-08  1.4900E-08 -5.9600E-08 -5.9600E-08       IONOSPHERIC CORR"
        );
        assert_eq!(
            lines[5],
            "G07 2005 04 02 02 00 00 3.966595977540E-04 1.705302565820E-12 0.000000000000E+00"
        );
        assert_eq!(lines.len(), 5 + 8);
        let back = parse_nav("x.nav", &text).unwrap();
        assert_eq!(back.version, 3.05);
        assert_eq!((back.iono_alpha, back.iono_beta), (Some(alpha), Some(beta)));
        assert_eq!(back.ephemerides, [GpsEphemeris { line: 6, ..e }]);
    }

    /// Galileo records are dated in GST (GPS's weeks and calendar), BeiDou's in BDT (its week
    /// 0 began on 2006-01-01): the walk's C21 of BDT week 1025, t_oc 406800 s, and E07 of week
    /// 2381, t_oc 407400 s, as RTKLIB's `convbin` dates them (2025-08-28 17:00:00 and 17:10:00);
    /// eight lines each, ORBIT 7 with two values, the file `M` when mixed, `E` when Galileo alone.
    #[test]
    fn galileo_and_beidou_records_are_dated_in_their_own_time() {
        let mut orbit = [[0.0; 4]; 7];
        orbit[6] = [408_630.0, 1.0, 0.0, 0.0];
        let c21 = KeplerRecord {
            line: 0,
            system: 'C',
            sv: 21,
            toc_week: 1025,
            toc_s: 406_800.0,
            af: [-9.634450543672e-4, -6.846967437468e-12, 0.0],
            orbit,
        };
        let e07 = KeplerRecord {
            system: 'E',
            sv: 7,
            toc_week: 2381,
            toc_s: 407_400.0,
            ..c21
        };
        let text = write_nav(
            "navsync",
            "20261206 000000 UTC",
            &NavRecords {
                kepler: &[c21, e07],
                ..NavRecords::default()
            },
        );
        let lines: Vec<&str> = text.lines().collect();
        assert!(lines[0].contains("M: MIXED"), "{}", lines[0]);
        assert_eq!(lines.len(), 3 + 2 * 8);
        assert_eq!(
            lines[3],
            "C21 2025 08 28 17 00 00-9.634450543672E-04-6.846967437468E-12 0.000000000000E+00"
        );
        assert_eq!(lines[10], "     4.086300000000E+05 1.000000000000E+00");
        assert!(lines[11].starts_with("E07 2025 08 28 17 10 00"), "{}", lines[11]);
        let alone = write_nav(
            "navsync",
            "20261206 000000 UTC",
            &NavRecords {
                kepler: &[e07],
                ..NavRecords::default()
            },
        );
        assert!(alone.lines().next().unwrap().contains("E: GALILEO"));
    }
}
