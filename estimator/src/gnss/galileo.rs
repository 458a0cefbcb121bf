//! Galileo I/NAV (E1-B, E5b-I) navigation data: a nominal page pair → one 128-bit word,
//! CRC checked, and the word types of the ephemeris, clock, ionosphere and GST, after the
//! Galileo OS SIS ICD (issue 2.x): §4.3.2 (the nominal page: even part 120 bits = even/odd,
//! page type, data 112 bits, tail 6; odd part = even/odd, page type, data 16 bits, reserved 1
//! (40 bits, OSNMA), SAR 22, spare 2, CRC 24, reserved 2 (8), tail 6), §4.3.2.1 (CRC-24Q over
//! the even part's first 114 bits and the odd part's first 82 bits), §4.3.5 Table 40 (word
//! types 0–5: bit allocation) and §5.1 Tables 60, 63, 67, 68, 74, 75, 76, 77, 78 (parameters
//! and scale factors).
//!
//! Bytes in: the 8 words u-blox puts in a Galileo I/NAV UBX-RXM-SFRBX (u-blox interface
//! description, "Galileo I/NAV"): words 0–3 the even part from word 0's most significant bit
//! (120 bits and 8 bits of padding), words 4–7 the odd part the same way. Alert pages (page
//! type 1) and dummy words (type 63) carry no ephemeris.

use super::bits::{BitsWriter, OutOfRange};
use super::orbit::{GPS_PI, Orbit, OrbitFrame};

/// Why a page pair was not decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum InavError {
    /// Fewer than the 8 words of a page pair.
    #[error("a Galileo I/NAV page pair has 8 words, got {0}")]
    Words(usize),
    /// The even/odd bits are not 0 then 1.
    #[error("not an even/odd page pair")]
    EvenOdd,
    /// An alert page (page type 1).
    #[error("alert page")]
    Alert,
    /// The CRC-24Q over the pair does not match.
    #[error("CRC error")]
    Crc,
}

/// Word types 1–4 with one IODnav: the ephemeris and clock (Tables 60, 63), SI units.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct Word1 {
    /// IODnav.
    pub iod_nav: u16,
    /// t0e, s of the GST week.
    pub toe_s: f64,
    /// M0, rad.
    pub m0_rad: f64,
    /// Eccentricity.
    pub e: f64,
    /// √A, √m.
    pub sqrt_a: f64,
}

/// Word type 2.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct Word2 {
    /// IODnav.
    pub iod_nav: u16,
    /// Ω0, rad.
    pub omega0_rad: f64,
    /// i0, rad.
    pub i0_rad: f64,
    /// ω, rad.
    pub omega_rad: f64,
    /// i̇, rad/s.
    pub idot_rad_s: f64,
}

/// Word type 3.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct Word3 {
    /// IODnav.
    pub iod_nav: u16,
    /// Ω̇, rad/s.
    pub omega_dot_rad_s: f64,
    /// Δn, rad/s.
    pub delta_n_rad_s: f64,
    /// C_uc, rad.
    pub cuc_rad: f64,
    /// C_us, rad.
    pub cus_rad: f64,
    /// C_rc, m.
    pub crc_m: f64,
    /// C_rs, m.
    pub crs_m: f64,
    /// SISA index (Table 76; 255: no accuracy prediction, NAPA).
    pub sisa: u8,
}

/// Word type 4.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct Word4 {
    /// IODnav.
    pub iod_nav: u16,
    /// SVID of the transmitting satellite.
    pub svid: u8,
    /// C_ic, rad.
    pub cic_rad: f64,
    /// C_is, rad.
    pub cis_rad: f64,
    /// t0c, s of the GST week.
    pub toc_s: f64,
    /// af0, s.
    pub af0_s: f64,
    /// af1, s/s.
    pub af1: f64,
    /// af2, s/s².
    pub af2_per_s: f64,
}

/// Word type 5: ionosphere, group delays, health, GST (Tables 67, 74, 77, 78).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct Word5 {
    /// NeQuick effective ionisation a_i0 (sfu), a_i1 (sfu/deg), a_i2 (sfu/deg²).
    pub ai: [f64; 3],
    /// Ionospheric disturbance flags of regions 1–5 (bit 4 = region 1).
    pub region_flags: u8,
    /// BGD(E1,E5a), s.
    pub bgd_e1_e5a_s: f64,
    /// BGD(E1,E5b), s.
    pub bgd_e1_e5b_s: f64,
    /// E5b signal health status (2 bits; 0 OK).
    pub e5b_hs: u8,
    /// E1-B signal health status (2 bits; 0 OK).
    pub e1b_hs: u8,
    /// E5b data validity status (0 valid, 1 working without guarantee).
    pub e5b_dvs: u8,
    /// E1-B data validity status.
    pub e1b_dvs: u8,
    /// GST week number (12 bits, weeks since 1999-08-22).
    pub wn: u16,
    /// GST time of week, s.
    pub tow_s: u32,
}

/// One decoded I/NAV word.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum InavWord {
    /// Word type 1.
    Ephem1(Word1),
    /// Word type 2.
    Ephem2(Word2),
    /// Word type 3.
    Ephem3(Word3),
    /// Word type 4.
    Ephem4(Word4),
    /// Word type 5.
    Iono5(Word5),
    /// Word type 0 with GST (time field 2): week and time of week.
    Gst {
        /// GST week number.
        wn: u16,
        /// GST time of week, s.
        tow_s: u32,
    },
    /// Any other word type (almanac, GST-UTC, GST-GPS, reduced CED, dummy …), not decoded here.
    Other(u8),
}

/// CRC-24Q (generator 0x1864CFB, Galileo OS SIS ICD §4.3.2.1 = RTCM's), over the bit source
/// `bit(i)` for `i` in `0..n`.
pub fn crc24q(n: u32, bit: impl Fn(u32) -> u32) -> u32 {
    let mut crc = 0u32;
    for i in 0..n {
        let top = ((crc >> 23) & 1) ^ bit(i);
        crc = (crc << 1) & 0xFF_FFFF;
        if top == 1 {
            crc ^= 0x86_4CFB;
        }
    }
    crc
}

/// The 128 bits of words `w[0..4]` (the first word's MSB first).
fn part(w: &[u32]) -> u128 {
    w.iter().take(4).fold(0u128, |a, &x| (a << 32) | u128::from(x))
}

/// Bit `i` (0 = MSB) of a 128-bit part.
fn bit(p: u128, i: u32) -> u32 {
    ((p >> (127 - i)) & 1) as u32
}

/// The 128-bit I/NAV word of a nominal page pair (even part's 112 data bits, then the odd
/// part's 16), its CRC checked.
pub fn page_pair_word(words: &[u32]) -> Result<u128, InavError> {
    if words.len() < 8 {
        return Err(InavError::Words(words.len()));
    }
    let (even, odd) = (part(&words[..4]), part(&words[4..8]));
    if bit(even, 0) != 0 || bit(odd, 0) != 1 {
        return Err(InavError::EvenOdd);
    }
    if bit(even, 1) == 1 || bit(odd, 1) == 1 {
        return Err(InavError::Alert);
    }
    let crc = crc24q(196, |i| if i < 114 { bit(even, i) } else { bit(odd, i - 114) });
    if crc != ((odd >> (128 - 106)) & 0xFF_FFFF) as u32 {
        return Err(InavError::Crc);
    }
    let data_even = (even >> (128 - 114)) & ((1u128 << 112) - 1);
    let data_odd = (odd >> (128 - 18)) & 0xFFFF;
    Ok((data_even << 16) | data_odd)
}

/// Bits `from..from+n` (0 = the word type's MSB) of a 128-bit I/NAV word, unsigned.
fn u(word: u128, from: u32, n: u32) -> u64 {
    ((word >> (128 - from - n)) & ((1u128 << n) - 1)) as u64
}

/// The same, two's complement.
fn s(word: u128, from: u32, n: u32) -> i64 {
    ((u(word, from, n) << (64 - n)) as i64) >> (64 - n)
}

fn p2(n: i32) -> f64 {
    2f64.powi(n)
}

/// Decodes one I/NAV page pair (8 u-blox words) into its word.
pub fn decode(words: &[u32]) -> Result<InavWord, InavError> {
    let w = page_pair_word(words)?;
    Ok(decode_word(w))
}

/// Decodes a 128-bit I/NAV word (Table 40 bit allocation; Tables 60, 63, 67, 68, 74 scales).
pub fn decode_word(w: u128) -> InavWord {
    let sc = GPS_PI;
    let iod_nav = u(w, 6, 10) as u16;
    let (uf, sf) = (|a, n| u(w, a, n) as f64, |a, n| s(w, a, n) as f64);
    match u(w, 0, 6) as u8 {
        1 => InavWord::Ephem1(Word1 {
            iod_nav,
            toe_s: uf(16, 14) * 60.0,
            m0_rad: sf(30, 32) * p2(-31) * sc,
            e: uf(62, 32) * p2(-33),
            sqrt_a: uf(94, 32) * p2(-19),
        }),
        2 => InavWord::Ephem2(Word2 {
            iod_nav,
            omega0_rad: sf(16, 32) * p2(-31) * sc,
            i0_rad: sf(48, 32) * p2(-31) * sc,
            omega_rad: sf(80, 32) * p2(-31) * sc,
            idot_rad_s: sf(112, 14) * p2(-43) * sc,
        }),
        3 => InavWord::Ephem3(Word3 {
            iod_nav,
            omega_dot_rad_s: sf(16, 24) * p2(-43) * sc,
            delta_n_rad_s: sf(40, 16) * p2(-43) * sc,
            cuc_rad: sf(56, 16) * p2(-29),
            cus_rad: sf(72, 16) * p2(-29),
            crc_m: sf(88, 16) * p2(-5),
            crs_m: sf(104, 16) * p2(-5),
            sisa: u(w, 120, 8) as u8,
        }),
        4 => InavWord::Ephem4(Word4 {
            iod_nav,
            svid: u(w, 16, 6) as u8,
            cic_rad: sf(22, 16) * p2(-29),
            cis_rad: sf(38, 16) * p2(-29),
            toc_s: uf(54, 14) * 60.0,
            af0_s: sf(68, 31) * p2(-34),
            af1: sf(99, 21) * p2(-46),
            af2_per_s: sf(120, 6) * p2(-59),
        }),
        5 => InavWord::Iono5(Word5 {
            ai: [uf(6, 11) * p2(-2), sf(17, 11) * p2(-8), sf(28, 14) * p2(-15)],
            region_flags: u(w, 42, 5) as u8,
            bgd_e1_e5a_s: sf(47, 10) * p2(-32),
            bgd_e1_e5b_s: sf(57, 10) * p2(-32),
            e5b_hs: u(w, 67, 2) as u8,
            e1b_hs: u(w, 69, 2) as u8,
            e5b_dvs: u(w, 71, 1) as u8,
            e1b_dvs: u(w, 72, 1) as u8,
            wn: u(w, 73, 12) as u16,
            tow_s: u(w, 85, 20) as u32,
        }),
        0 if u(w, 6, 2) == 2 => InavWord::Gst {
            wn: u(w, 96, 12) as u16,
            tow_s: u(w, 108, 20) as u32,
        },
        other => InavWord::Other(other),
    }
}

/// The 128-bit I/NAV word of word types 0 (GST), 1–5 (the inverse of [`decode_word`], same
/// Table 40 bit allocation and scale factors); other words give their type's 6 bits and zeros.
/// `worst` receives the largest |value / scale − round(value / scale)| over the fields, in
/// LSBs (0 for values that came from a broadcast); a value beyond its field's range is an
/// error naming the field.
pub fn encode_word(word: &InavWord, worst: &mut f64) -> Result<u128, OutOfRange> {
    let sc = GPS_PI;
    let mut x = BitsWriter::<4>::new(worst);
    let (uns, sig) = (|a, n| (a, n, false), |a, n| (a, n, true));
    let head = |x: &mut BitsWriter<4>, t: i64, iod: u16| {
        x.raw("word type", uns(0, 6), t)?;
        x.raw("IODnav", uns(6, 10), i64::from(iod))
    };
    match *word {
        InavWord::Ephem1(a) => {
            head(&mut x, 1, a.iod_nav)?;
            x.put("t0e", uns(16, 14), a.toe_s, 60.0)?;
            x.put("M0", sig(30, 32), a.m0_rad, p2(-31) * sc)?;
            x.put("e", uns(62, 32), a.e, p2(-33))?;
            x.put("sqrt(A)", uns(94, 32), a.sqrt_a, p2(-19))?;
        }
        InavWord::Ephem2(a) => {
            head(&mut x, 2, a.iod_nav)?;
            x.put("OMEGA0", sig(16, 32), a.omega0_rad, p2(-31) * sc)?;
            x.put("i0", sig(48, 32), a.i0_rad, p2(-31) * sc)?;
            x.put("omega", sig(80, 32), a.omega_rad, p2(-31) * sc)?;
            x.put("IDOT", sig(112, 14), a.idot_rad_s, p2(-43) * sc)?;
        }
        InavWord::Ephem3(a) => {
            head(&mut x, 3, a.iod_nav)?;
            x.put("OMEGA DOT", sig(16, 24), a.omega_dot_rad_s, p2(-43) * sc)?;
            x.put("Delta n", sig(40, 16), a.delta_n_rad_s, p2(-43) * sc)?;
            x.put("Cuc", sig(56, 16), a.cuc_rad, p2(-29))?;
            x.put("Cus", sig(72, 16), a.cus_rad, p2(-29))?;
            x.put("Crc", sig(88, 16), a.crc_m, p2(-5))?;
            x.put("Crs", sig(104, 16), a.crs_m, p2(-5))?;
            x.raw("SISA", uns(120, 8), i64::from(a.sisa))?;
        }
        InavWord::Ephem4(a) => {
            head(&mut x, 4, a.iod_nav)?;
            x.raw("SVID", uns(16, 6), i64::from(a.svid))?;
            x.put("Cic", sig(22, 16), a.cic_rad, p2(-29))?;
            x.put("Cis", sig(38, 16), a.cis_rad, p2(-29))?;
            x.put("t0c", uns(54, 14), a.toc_s, 60.0)?;
            x.put("af0", sig(68, 31), a.af0_s, p2(-34))?;
            x.put("af1", sig(99, 21), a.af1, p2(-46))?;
            x.put("af2", sig(120, 6), a.af2_per_s, p2(-59))?;
        }
        InavWord::Iono5(a) => {
            x.raw("word type", uns(0, 6), 5)?;
            x.put("ai0", uns(6, 11), a.ai[0], p2(-2))?;
            x.put("ai1", sig(17, 11), a.ai[1], p2(-8))?;
            x.put("ai2", sig(28, 14), a.ai[2], p2(-15))?;
            x.raw("region flags", uns(42, 5), i64::from(a.region_flags))?;
            x.put("BGD(E1,E5a)", sig(47, 10), a.bgd_e1_e5a_s, p2(-32))?;
            x.put("BGD(E1,E5b)", sig(57, 10), a.bgd_e1_e5b_s, p2(-32))?;
            x.raw("E5b HS", uns(67, 2), i64::from(a.e5b_hs))?;
            x.raw("E1-B HS", uns(69, 2), i64::from(a.e1b_hs))?;
            x.raw("E5b DVS", uns(71, 1), i64::from(a.e5b_dvs))?;
            x.raw("E1-B DVS", uns(72, 1), i64::from(a.e1b_dvs))?;
            x.raw("WN", uns(73, 12), i64::from(a.wn))?;
            x.raw("TOW", uns(85, 20), i64::from(a.tow_s))?;
        }
        InavWord::Gst { wn, tow_s } => {
            x.raw("time", uns(6, 2), 2)?;
            x.raw("WN", uns(96, 12), i64::from(wn))?;
            x.raw("TOW", uns(108, 20), i64::from(tow_s))?;
        }
        InavWord::Other(t) => x.raw("word type", uns(0, 6), i64::from(t))?,
    }
    Ok(x.w.iter().fold(0u128, |a, &w| (a << 32) | u128::from(w)))
}

/// The 8 u-blox words of a nominal page pair carrying `word` (the inverse of
/// [`page_pair_word`]: even part = even 0, page type 0, the word's first 112 bits, tail; odd
/// part = odd 1, page type 0, its last 16 bits, OSNMA, SAR and spare bits 0, the CRC-24Q of
/// §4.3.2.1, reserved and tail 0).
pub fn page_pair(word: u128) -> [u32; 8] {
    let even = (word >> 16) << (128 - 114);
    let mut odd = (1u128 << 127) | ((word & 0xFFFF) << (128 - 18));
    let bit = |p: u128, i: u32| ((p >> (127 - i)) & 1) as u32;
    let crc = crc24q(196, |i| if i < 114 { bit(even, i) } else { bit(odd, i - 114) });
    odd |= u128::from(crc) << (128 - 106);
    let mut out = [0u32; 8];
    for k in 0..4 {
        out[k] = (even >> (96 - 32 * k)) as u32;
        out[4 + k] = (odd >> (96 - 32 * k)) as u32;
    }
    out
}

/// Word types 1–5 of an ephemeris, in that order (the inverse of [`GalAssembler`]).
pub fn words_of(e: &GalEphemeris) -> [InavWord; 5] {
    [
        InavWord::Ephem1(e.w1),
        InavWord::Ephem2(e.w2),
        InavWord::Ephem3(e.w3),
        InavWord::Ephem4(e.w4),
        InavWord::Iono5(e.w5),
    ]
}

/// The SISA index of an accuracy `m` metres (the smallest index of [`sisa_m`] at least `m`;
/// 255, NAPA, for a negative value or one beyond 6 m).
pub fn sisa_index(m: f64) -> u8 {
    (0..=125u8)
        .find(|&i| sisa_m(i).is_some_and(|a| a >= m - 1e-9))
        .filter(|_| m >= 0.0)
        .unwrap_or(255)
}

/// A complete Galileo I/NAV ephemeris: word types 1–4 of one IODnav and the latest word 5.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct GalEphemeris {
    /// Satellite (SVID 1–36).
    pub sv: u8,
    /// Word type 1.
    pub w1: Word1,
    /// Word type 2.
    pub w2: Word2,
    /// Word type 3.
    pub w3: Word3,
    /// Word type 4.
    pub w4: Word4,
    /// Word type 5.
    pub w5: Word5,
}

impl GalEphemeris {
    /// IODnav.
    pub fn iod_nav(&self) -> u16 {
        self.w1.iod_nav
    }

    /// The orbit and E1 clock (af0–af2 of I/NAV, −BGD(E1,E5b): OS SIS ICD §5.1.5), s of the
    /// GST week.
    pub fn orbit(&self) -> Orbit {
        Orbit {
            toe_s: self.w1.toe_s,
            sqrt_a: self.w1.sqrt_a,
            e: self.w1.e,
            i0_rad: self.w2.i0_rad,
            idot_rad_s: self.w2.idot_rad_s,
            omega0_rad: self.w2.omega0_rad,
            omega_dot_rad_s: self.w3.omega_dot_rad_s,
            omega_rad: self.w2.omega_rad,
            m0_rad: self.w1.m0_rad,
            delta_n_rad_s: self.w3.delta_n_rad_s,
            a_dot_m_s: 0.0,
            delta_n_dot_rad_s2: 0.0,
            cuc: self.w3.cuc_rad,
            cus: self.w3.cus_rad,
            crc: self.w3.crc_m,
            crs: self.w3.crs_m,
            cic: self.w4.cic_rad,
            cis: self.w4.cis_rad,
            toc_s: self.w4.toc_s,
            af: [self.w4.af0_s, self.w4.af1, self.w4.af2_per_s],
            tgd_s: self.w5.bgd_e1_e5b_s,
            frame: OrbitFrame::Galileo,
        }
    }

    /// Healthy for E1-B: signal health 0, data valid, and a SISA with an accuracy prediction.
    pub fn healthy(&self) -> bool {
        self.w5.e1b_hs == 0 && self.w5.e1b_dvs == 0 && self.w3.sisa != 255
    }

    /// The signal-in-space accuracy of the SISA index, m ([`sisa_m`]).
    pub fn sisa_m(&self) -> Option<f64> {
        sisa_m(self.w3.sisa)
    }
}

/// The signal-in-space accuracy of SISA index `sisa`, m (OS SIS ICD Table 76: 0–49 in 1 cm
/// steps, 50–74 2 cm, 75–99 4 cm, 100–125 16 cm); `None` for spare values and 255 (NAPA).
pub fn sisa_m(sisa: u8) -> Option<f64> {
    let n = f64::from(sisa);
    match sisa {
        0..=49 => Some(n * 0.01),
        50..=74 => Some(0.5 + (n - 50.0) * 0.02),
        75..=99 => Some(1.0 + (n - 75.0) * 0.04),
        100..=125 => Some(2.0 + (n - 100.0) * 0.16),
        _ => None,
    }
}

/// One satellite's words as they arrive, completed into an ephemeris when words 1–4 share an
/// IODnav and a word 5 has been seen (OS SIS ICD §5.1.9.2: a new IODnav for every batch).
#[derive(Debug, Clone, Copy, Default)]
pub struct GalAssembler {
    w1: Option<Word1>,
    w2: Option<Word2>,
    w3: Option<Word3>,
    w4: Option<Word4>,
    w5: Option<Word5>,
    last: Option<GalEphemeris>,
}

impl GalAssembler {
    /// Takes one decoded word of satellite `sv`; returns the ephemeris when this word
    /// completed a new one (a different issue or content than the last returned).
    pub fn on_word(&mut self, sv: u8, w: &InavWord) -> Option<GalEphemeris> {
        match *w {
            InavWord::Ephem1(x) => self.w1 = Some(x),
            InavWord::Ephem2(x) => self.w2 = Some(x),
            InavWord::Ephem3(x) => self.w3 = Some(x),
            InavWord::Ephem4(x) => self.w4 = Some(x),
            InavWord::Iono5(x) => self.w5 = Some(x),
            _ => return None,
        }
        let (w1, w2, w3, w4, w5) = (self.w1?, self.w2?, self.w3?, self.w4?, self.w5?);
        let iod = w1.iod_nav;
        if w2.iod_nav != iod || w3.iod_nav != iod || w4.iod_nav != iod {
            return None;
        }
        let eph = GalEphemeris { sv, w1, w2, w3, w4, w5 };
        // A new word 5 (its GST advances) alone does not make a new ephemeris.
        let same = self.last.is_some_and(|l| GalEphemeris { w5: l.w5, ..eph } == l);
        self.last = Some(eph);
        (!same).then_some(eph)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gnss::orbit::rinex_check::{assert_orbit_equals_record, assert_positions, assert_rinex_eq};

    /// E07's I/NAV page pairs on E1-B (sigId 1) of word types 1, 3, 5, 2, 4 (IODnav 44), as the
    /// receiver's RXM-SFRBX delivered them in the walk's log
    /// (`shared/datasets/rtklibexplorer-walk0827/source/gnss_1730.ubx`, u-blox X20,
    /// 2025-08-28, the RXM-RAWX rcvTow before each: 408652.998, 408654.998, 408656.998,
    /// 408662.998, 408664.998 s GPS).
    const E07_IOD44: [[u32; 8]; 5] = [
        [
            0x010B1A86, 0x18FAAC77, 0x00289F24, 0xAA04C000, 0xA122C000, 0x0000002A, 0xAAAA4BE8, 0xC08AC000,
        ],
        [
            0x030B3FF0, 0x2BC9CB7F, 0x38828007, 0x77FEC000, 0xA5DAC000, 0x0000002A, 0xAAAA5330, 0x10CBC000,
        ],
        [
            0x054FBFD0, 0x26D00280, 0xA80A9AC7, 0x89EA8000, 0xAAAA8000, 0x0000002A, 0xAAAA61CC, 0x29010000,
        ],
        [
            0x020B184F, 0xB6D649D5, 0x837FC35D, 0x00FF8000, 0x80914000, 0x0000002A, 0xAAAA5662, 0xCD410000,
        ],
        [
            0x040B0700, 0x3000006A, 0x1BFE5666, 0xDFFFC000, 0x9BC04000, 0x0000002A, 0xAAAA5C7A, 0x5E0AC000,
        ],
    ];

    fn e07() -> GalEphemeris {
        let mut a = GalAssembler::default();
        let mut out = None;
        for (k, w) in E07_IOD44.iter().enumerate() {
            let word = decode(w).unwrap();
            let eph = a.on_word(7, &word);
            // Complete only with the last of words 1–5.
            assert_eq!(eph.is_some(), k == 4, "word {k}: {word:?}");
            out = out.or(eph);
        }
        out.unwrap()
    }

    /// The fields equal RTKLIB's (rtklibexplorer demo5) decoding of the same words:
    /// `convbin -r ubx -v 3.04 -n nav.rnx -o obs.rnx gnss_1730.ubx`, record
    /// `E07 2025 08 28 17 10 00` with data source 513 (I/NAV E1-B).
    #[test]
    fn e07_iod44_equals_convbin() {
        let e = e07();
        let o = e.orbit();
        assert_orbit_equals_record(
            &o,
            [
                -0.202941067982e-03,
                -0.206057393370e-11,
                0.0,
                -0.352812500000e+02,
                0.358193491625e-08,
                0.613081661655e+00,
                -0.148639082909e-05,
                0.309918541461e-03,
                0.476837158203e-05,
                0.544060992813e+04,
                0.407400000000e+06,
                0.894069671631e-07,
                0.238676450559e+01,
                0.0,
                0.965454400011e+00,
                0.238968750000e+03,
                0.330190859695e+00,
                -0.578916971358e-08,
                0.517878714584e-10,
            ],
        );
        assert_rinex_eq(&[
            ("IODnav", f64::from(e.iod_nav()), 44.0),
            ("GAL week", f64::from(e.w5.wn) + 1024.0, 0.238100000000e+04),
            ("SISA m", e.sisa_m().unwrap_or(f64::NAN), 0.312000000000e+01),
            ("BGD E5a/E1", e.w5.bgd_e1_e5a_s, 0.465661287308e-08),
            ("BGD E5b/E1", e.w5.bgd_e1_e5b_s, 0.488944351673e-08),
            ("t0c (the record's epoch)", o.toc_s, 407_400.0),
        ]);
        assert!(e.healthy() && e.w4.svid == 7 && e.w5.tow_s == 408_655);
        assert_eq!(o.frame, OrbitFrame::Galileo);
    }

    /// The position from the decoded ephemeris equals the one computed by an independent
    /// implementation of OS SIS ICD §5.1.1 (Python, double precision) from convbin's RINEX
    /// values of the same record: within 1 mm at t0e and t0e + 1800 s.
    #[test]
    fn e07_position_equals_the_rinex_records() {
        assert_positions(
            &e07().orbit(),
            &[
                (407_400.0, [1_055_702.283_3, -22_054_190.839_6, 19_703_342.399_4]),
                (409_200.0, [3_420_628.508_7, -19_062_053.226_5, 22_377_137.008_4]),
            ],
        );
    }

    /// A flipped bit fails the CRC; the even/odd order, an alert page and a short message are
    /// refused; a word of another IODnav does not complete the ephemeris.
    #[test]
    fn corrupted_pages_are_rejected() {
        for k in 0..8 {
            let mut w = E07_IOD44[0];
            // A data bit of the even part, of the odd part's bits under the CRC (0..82), or
            // of the CRC itself (odd bits 82..106: word 7's first ten).
            w[k] ^= match k {
                0..=3 => 1 << 20,
                4..=6 => 1 << 19,
                _ => 1 << 26,
            };
            let e = decode(&w).unwrap_err();
            assert!(matches!(e, InavError::Crc | InavError::EvenOdd), "word {k}: {e:?}");
        }
        let mut swapped = [0u32; 8];
        swapped[..4].copy_from_slice(&E07_IOD44[0][4..]);
        swapped[4..].copy_from_slice(&E07_IOD44[0][..4]);
        assert_eq!(decode(&swapped), Err(InavError::EvenOdd));
        let mut alert = E07_IOD44[0];
        alert[0] |= 1 << 30;
        assert_eq!(decode(&alert), Err(InavError::Alert));
        assert_eq!(decode(&E07_IOD44[0][..7]), Err(InavError::Words(7)));
        // Words 1–3 and 5 of IODnav 44 with a word 4 of another issue: no ephemeris.
        let mut a = GalAssembler::default();
        for w in &E07_IOD44[..4] {
            assert_eq!(a.on_word(7, &decode(w).unwrap()), None);
        }
        let InavWord::Ephem4(mut w4) = decode(&E07_IOD44[4]).unwrap() else {
            panic!("not word 4")
        };
        w4.iod_nav = 45;
        assert_eq!(a.on_word(7, &InavWord::Ephem4(w4)), None);
    }

    /// Encoding is the inverse of decoding: E07's five real page pairs decode, encode and decode
    /// to the same words with no rounding (broadcast values lie on the grid), the pairs pass the
    /// CRC, and one flipped bit in an encoded pair is caught.
    #[test]
    fn encoded_page_pairs_decode_to_the_same_words() {
        for pair in E07_IOD44 {
            let word = decode(&pair).unwrap();
            let mut worst = 0.0;
            let again = page_pair(encode_word(&word, &mut worst).unwrap());
            assert_eq!(decode(&again).unwrap(), word);
            assert!(worst < 1e-6, "{worst}");
            for b in [3, 40, 100] {
                let mut bad = again;
                bad[b / 32] ^= 1 << (31 - b % 32);
                assert_eq!(decode(&bad), Err(InavError::Crc));
            }
        }
        let e = e07();
        let mut a = GalAssembler::default();
        let mut worst = 0.0;
        let back = words_of(&e)
            .iter()
            .filter_map(|w| a.on_word(e.sv, &decode(&page_pair(encode_word(w, &mut worst).unwrap())).unwrap()))
            .last();
        assert_eq!(back, Some(e));
        let mut off = e.w4;
        off.af0_s += 0.25 * p2(-34);
        encode_word(&InavWord::Ephem4(off), &mut worst).unwrap();
        assert!((worst - 0.25).abs() < 1e-6, "{worst}");
        off.af0_s = 1.0;
        let err = encode_word(&InavWord::Ephem4(off), &mut worst).unwrap_err();
        assert_eq!((err.field, err.value, err.bits), ("af0", 1.0, 31));
        let mut w1 = e.w1;
        w1.e = -0.1;
        assert_eq!(encode_word(&InavWord::Ephem1(w1), &mut worst).unwrap_err().field, "e");
        assert_eq!((sisa_index(3.12), sisa_index(0.0), sisa_index(-1.0)), (107, 0, 255));
        assert!((sisa_m(sisa_index(3.12)).unwrap() - 3.12).abs() < 1e-12);
    }

    #[test]
    fn crc24q_of_a_known_vector() {
        // RTCM 3's CRC-24Q of the bytes "123456789" is 0xCDE703.
        let msg = b"123456789";
        let crc = crc24q(72, |i| u32::from((msg[(i / 8) as usize] >> (7 - i % 8)) & 1));
        assert_eq!(crc, 0xCD_E703);
    }
}
