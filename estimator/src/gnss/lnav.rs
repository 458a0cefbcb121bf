//! GPS LNAV (L1 C/A) subframe decoding: ten 30-bit words → the broadcast fields as the
//! unscaled integers of IS-GPS-200 (IS-GPS-200N §20.3.2–20.3.3, Figures 20-1 and 20-2,
//! Tables 20-I, 20-III, 20-V, 20-VI), parity checked (§20.3.5.2, Table 20-XIV).
//!
//! Input: the words as a receiver hands them over, 30 bits right-justified per `u32`, with
//! D29* and D30* (the last two parity bits of the word before) copied into bits 31 and 30
//! (u-blox UBX-RXM-SFRBX for GPS L1 C/A; gpsd's convention). Data bits are sent inverted when
//! D30* is 1 (§20.3.5.2); the decoder undoes that per word and accepts a subframe only when
//! all ten words pass the parity check. Scaling to physical
//! units (powers of two, semicircles) is the user's: these are the raw fields, which is what
//! gpsd prints with `"scaled":false` and what `tests/tests/estimator/lnav_gpsd.rs` compares against.

/// Why a subframe was not decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum LnavError {
    /// Fewer than ten words.
    #[error("a GPS LNAV subframe has 10 words, got {0}")]
    Words(usize),
    /// A word failed the parity check (index 0..10).
    #[error("parity error in word {0}")]
    Parity(usize),
    /// The TLM word does not start with the preamble 0x8B.
    #[error("no TLM preamble (0x{0:02X})")]
    Preamble(u8),
    /// The HOW's subframe id is not 1..=5.
    #[error("subframe id {0} is not 1..=5")]
    SubframeId(u8),
}

/// Subframe 1: clock, week, health (IS-GPS-200 §20.3.3.3, Table 20-I).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct Ephem1 {
    /// GPS week number mod 1024.
    pub wn: u16,
    /// Codes on L2 (2 bits).
    pub l2: u8,
    /// URA index (4 bits).
    pub ura: u8,
    /// SV health (6 bits).
    pub health: u8,
    /// Issue of data, clock (10 bits).
    pub iodc: u16,
    /// L2 P data flag.
    pub l2p: u8,
    /// T_GD, 2⁻³¹ s.
    pub tgd: i8,
    /// t_oc, 2⁴ s.
    pub toc: u16,
    /// a_f2, 2⁻⁵⁵ s/s².
    pub af2: i8,
    /// a_f1, 2⁻⁴³ s/s.
    pub af1: i16,
    /// a_f0 (22 bits), 2⁻³¹ s.
    pub af0: i32,
}

/// Subframe 2: ephemeris part 1 (Table 20-III).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct Ephem2 {
    /// Issue of data, ephemeris.
    pub iode: u8,
    /// C_rs, 2⁻⁵ m.
    pub crs: i16,
    /// Δn, 2⁻⁴³ semicircles/s.
    pub delta_n: i16,
    /// M_0, 2⁻³¹ semicircles.
    pub m0: i32,
    /// C_uc, 2⁻²⁹ rad.
    pub cuc: i16,
    /// e, 2⁻³³.
    pub e: u32,
    /// C_us, 2⁻²⁹ rad.
    pub cus: i16,
    /// √A, 2⁻¹⁹ √m.
    pub sqrt_a: u32,
    /// t_oe, 2⁴ s.
    pub toe: u16,
    /// Fit interval flag.
    pub fit: u8,
    /// Age of data offset (5 bits), 900 s.
    pub aodo: u8,
}

/// Subframe 3: ephemeris part 2 (Table 20-III).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct Ephem3 {
    /// C_ic, 2⁻²⁹ rad.
    pub cic: i16,
    /// Ω_0, 2⁻³¹ semicircles.
    pub omega0: i32,
    /// C_is, 2⁻²⁹ rad.
    pub cis: i16,
    /// i_0, 2⁻³¹ semicircles.
    pub i0: i32,
    /// C_rc, 2⁻⁵ m.
    pub crc: i16,
    /// ω, 2⁻³¹ semicircles.
    pub omega: i32,
    /// Ω̇ (24 bits), 2⁻⁴³ semicircles/s.
    pub omega_dot: i32,
    /// Issue of data, ephemeris.
    pub iode: u8,
    /// IDOT (14 bits), 2⁻⁴³ semicircles/s.
    pub idot: i16,
}

/// An almanac page (subframe 4 pages 2–5, 7–10; subframe 5 pages 1–24; Table 20-VI).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct Almanac {
    /// SV (PRN) the almanac is for (the page's SV ID, 1..=32).
    pub sv: u8,
    /// e, 2⁻²¹.
    pub e: u16,
    /// t_oa, 2¹² s.
    pub toa: u8,
    /// δ_i, 2⁻¹⁹ semicircles (relative to 0.30 semicircles).
    pub delta_i: i16,
    /// Ω̇, 2⁻³⁸ semicircles/s.
    pub omega_dot: i16,
    /// SV health (8 bits).
    pub health: u8,
    /// √A (24 bits), 2⁻¹¹ √m.
    pub sqrt_a: u32,
    /// Ω_0 (24 bits), 2⁻²³ semicircles.
    pub omega0: i32,
    /// ω (24 bits), 2⁻²³ semicircles.
    pub omega: i32,
    /// M_0 (24 bits), 2⁻²³ semicircles.
    pub m0: i32,
    /// a_f0 (11 bits), 2⁻²⁰ s.
    pub af0: i16,
    /// a_f1 (11 bits), 2⁻³⁸ s/s.
    pub af1: i16,
}

/// Subframe 4 page 18 (SV ID 56): ionosphere and UTC (§20.3.3.5.1.6–7, Table 20-X).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct IonoUtc {
    /// Klobuchar α_0..α_3 (2⁻³⁰ s, 2⁻²⁷ s/semicircle, 2⁻²⁴ s/semicircle², 2⁻²⁴ s/semicircle³).
    pub alpha: [i8; 4],
    /// Klobuchar β_0..β_3 (2¹¹ s, 2¹⁴ s/semicircle, 2¹⁶ s/semicircle², 2¹⁶ s/semicircle³).
    pub beta: [i8; 4],
    /// A_1, 2⁻⁵⁰ s/s.
    pub a1: i32,
    /// A_0, 2⁻³⁰ s.
    pub a0: i32,
    /// t_ot, 2¹² s.
    pub tot: u8,
    /// WN_t, weeks mod 256.
    pub wnt: u8,
    /// Δt_LS, s.
    pub dt_ls: i8,
    /// WN_LSF, weeks mod 256.
    pub wn_lsf: u8,
    /// DN, days (1..=7).
    pub dn: u8,
    /// Δt_LSF, s.
    pub dt_lsf: i8,
}

/// A decoded subframe.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Subframe {
    /// Subframe 1.
    Ephem1(Ephem1),
    /// Subframe 2.
    Ephem2(Ephem2),
    /// Subframe 3.
    Ephem3(Ephem3),
    /// An almanac page of subframe 4 or 5.
    Almanac(Almanac),
    /// Subframe 4 page 18.
    IonoUtc(IonoUtc),
    /// Another page of subframe 4 or 5 (health, NMCT, special message, reserved): its
    /// SV ID (data ID in bits 1–2 of word 3 not kept).
    OtherPage {
        /// Subframe (4 or 5).
        subframe: u8,
        /// The page's SV ID (IS-GPS-200 Table 20-V).
        sv_id: u8,
    },
}

/// A subframe with its HOW.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Decoded {
    /// Subframe id (1..=5).
    pub id: u8,
    /// The HOW's time-of-week count (17 bits, 6 s units: the start of the next subframe).
    pub tow_count: u32,
    /// The fields.
    pub subframe: Subframe,
}

/// The 24 data bits of every word, inversion undone, after the parity check.
fn data_words(words: &[u32]) -> Result<[u32; 10], LnavError> {
    if words.len() < 10 {
        return Err(LnavError::Words(words.len()));
    }
    let mut out = [0u32; 10];
    for (i, &raw) in words.iter().take(10).enumerate() {
        // D29*, D30* of the word before, as the receiver copies them into bits 31 and 30
        // (u-blox; gpsd's convention): the data bits are sent inverted when D30* is 1.
        let (d29s, d30s) = ((raw >> 31) & 1, (raw >> 30) & 1);
        let w = raw & 0x3FFF_FFFF;
        let data = if d30s == 1 { (w >> 6) ^ 0xFF_FFFF } else { w >> 6 };
        if parity(data, d29s, d30s) != w & 0x3F {
            return Err(LnavError::Parity(i));
        }
        out[i] = data;
    }
    Ok(out)
}

/// The six parity bits D25..D30 of 24 source data bits d1..d24 (d1 = MSB) given D29*, D30*
/// of the previous word (IS-GPS-200 Table 20-XIV).
fn parity(d: u32, d29s: u32, d30s: u32) -> u32 {
    let bit = |n: u32| (d >> (24 - n)) & 1;
    let x = |ns: &[u32]| ns.iter().fold(0, |a, &n| a ^ bit(n));
    let p25 = d29s ^ x(&[1, 2, 3, 5, 6, 10, 11, 12, 13, 14, 17, 18, 20, 23]);
    let p26 = d30s ^ x(&[2, 3, 4, 6, 7, 11, 12, 13, 14, 15, 18, 19, 21, 24]);
    let p27 = d29s ^ x(&[1, 3, 4, 5, 7, 8, 12, 13, 14, 15, 16, 19, 20, 22]);
    let p28 = d30s ^ x(&[2, 4, 5, 6, 8, 9, 13, 14, 15, 16, 17, 20, 21, 23]);
    let p29 = d30s ^ x(&[1, 3, 5, 6, 7, 9, 10, 14, 15, 16, 17, 18, 21, 22, 24]);
    let p30 = d29s ^ x(&[3, 5, 6, 8, 9, 10, 11, 13, 15, 19, 22, 23, 24]);
    (p25 << 5) | (p26 << 4) | (p27 << 3) | (p28 << 2) | (p29 << 1) | p30
}

/// Bits `from..from+n` (1-based within the subframe's 300 bits, word k's data bits being
/// 30(k−1)+1 ..= 30(k−1)+24) as an unsigned number; fields may span words.
fn bits(d: &[u32; 10], from: u32, n: u32) -> u32 {
    let mut v = 0u32;
    for b in from..from + n {
        let word = ((b - 1) / 30) as usize;
        let pos = (b - 1) % 30; // 0..24 are data bits
        v = (v << 1) | ((d[word] >> (23 - pos)) & 1);
    }
    v
}

/// A two's-complement field of `n` bits.
fn signed(v: u32, n: u32) -> i32 {
    ((v << (32 - n)) as i32) >> (32 - n)
}

/// Decodes one GPS LNAV subframe from its ten words.
pub fn decode(words: &[u32]) -> Result<Decoded, LnavError> {
    let d = data_words(words)?;
    let preamble = (d[0] >> 16) as u8;
    if preamble != 0x8B {
        return Err(LnavError::Preamble(preamble));
    }
    let b = |from, n| bits(&d, from, n);
    let s = |from, n| signed(bits(&d, from, n), n);
    let tow_count = b(31, 17);
    let id = b(50, 3) as u8;
    let subframe = match id {
        1 => Subframe::Ephem1(Ephem1 {
            wn: b(61, 10) as u16,
            l2: b(71, 2) as u8,
            ura: b(73, 4) as u8,
            health: b(77, 6) as u8,
            iodc: ((b(83, 2) << 8) | b(211, 8)) as u16,
            l2p: b(91, 1) as u8,
            tgd: s(197, 8) as i8,
            toc: b(219, 16) as u16,
            af2: s(241, 8) as i8,
            af1: s(249, 16) as i16,
            af0: s(271, 22),
        }),
        2 => Subframe::Ephem2(Ephem2 {
            iode: b(61, 8) as u8,
            crs: s(69, 16) as i16,
            delta_n: s(91, 16) as i16,
            m0: ((b(107, 8) << 24) | b(121, 24)) as i32,
            cuc: s(151, 16) as i16,
            e: (b(167, 8) << 24) | b(181, 24),
            cus: s(211, 16) as i16,
            sqrt_a: (b(227, 8) << 24) | b(241, 24),
            toe: b(271, 16) as u16,
            fit: b(287, 1) as u8,
            aodo: b(288, 5) as u8,
        }),
        3 => Subframe::Ephem3(Ephem3 {
            cic: s(61, 16) as i16,
            omega0: ((b(77, 8) << 24) | b(91, 24)) as i32,
            cis: s(121, 16) as i16,
            i0: ((b(137, 8) << 24) | b(151, 24)) as i32,
            crc: s(181, 16) as i16,
            omega: ((b(197, 8) << 24) | b(211, 24)) as i32,
            omega_dot: s(241, 24),
            iode: b(271, 8) as u8,
            idot: s(279, 14) as i16,
        }),
        4 | 5 => {
            let sv_id = b(63, 6) as u8;
            if (1..=32).contains(&sv_id) {
                Subframe::Almanac(Almanac {
                    sv: sv_id,
                    e: b(69, 16) as u16,
                    toa: b(91, 8) as u8,
                    delta_i: s(99, 16) as i16,
                    omega_dot: s(121, 16) as i16,
                    health: b(137, 8) as u8,
                    sqrt_a: b(151, 24),
                    omega0: s(181, 24),
                    omega: s(211, 24),
                    m0: s(241, 24),
                    af0: signed((b(271, 8) << 3) | b(290, 3), 11) as i16,
                    af1: s(279, 11) as i16,
                })
            } else if id == 4 && sv_id == 56 {
                Subframe::IonoUtc(IonoUtc {
                    alpha: [s(69, 8) as i8, s(77, 8) as i8, s(91, 8) as i8, s(99, 8) as i8],
                    beta: [s(107, 8) as i8, s(121, 8) as i8, s(129, 8) as i8, s(137, 8) as i8],
                    a1: s(151, 24),
                    a0: ((b(181, 24) << 8) | b(211, 8)) as i32,
                    tot: b(219, 8) as u8,
                    wnt: b(227, 8) as u8,
                    dt_ls: s(241, 8) as i8,
                    wn_lsf: b(249, 8) as u8,
                    dn: b(257, 8) as u8,
                    dt_lsf: s(271, 8) as i8,
                })
            } else {
                Subframe::OtherPage { subframe: id, sv_id }
            }
        }
        other => return Err(LnavError::SubframeId(other)),
    };
    Ok(Decoded {
        id,
        tow_count,
        subframe,
    })
}

/// Writes `value`'s `n` low bits at bits `from..from+n` (numbered as in [`bits`]).
fn put(d: &mut [u32; 10], from: u32, n: u32, value: i64) {
    for k in 0..n {
        let b = from + k;
        let (word, pos) = (((b - 1) / 30) as usize, (b - 1) % 30);
        let bit = ((value >> (n - 1 - k)) & 1) as u32;
        d[word] = (d[word] & !(1 << (23 - pos))) | (bit << (23 - pos));
    }
}

/// Ten 24-bit data words as sent (parity added, data inverted after a word ending in D30 = 1),
/// with D29*, D30* of the word before in bits 31 and 30 (u-blox, gpsd): the inverse of the
/// decoder's word handling. The subframe starts after D29* = D30* = 0.
pub fn words_from_data(data: [u32; 10]) -> [u32; 10] {
    let mut out = [0u32; 10];
    let mut prev = 0u32;
    for (i, &d) in data.iter().enumerate() {
        let (d29s, d30s) = ((prev >> 1) & 1, prev & 1);
        let p = parity(d, d29s, d30s);
        let sent = if d30s == 1 { d ^ 0xFF_FFFF } else { d };
        out[i] = (d29s << 31) | (d30s << 30) | (sent << 6) | p;
        prev = out[i];
    }
    out
}

/// Encodes subframes 1–3 and subframe 4 page 18 (the inverse of [`decode`], same bit table):
/// the words of a subframe whose HOW carries `tow_count`; `None` for the other kinds.
pub fn encode(tow_count: u32, sf: &Subframe) -> Option<[u32; 10]> {
    let mut d = [0u32; 10];
    put(&mut d, 1, 8, 0x8B);
    put(&mut d, 31, 17, i64::from(tow_count));
    let mut p = |from, n, v: i64| put(&mut d, from, n, v);
    match sf {
        Subframe::Ephem1(e) => {
            p(50, 3, 1);
            p(61, 10, e.wn.into());
            p(71, 2, e.l2.into());
            p(73, 4, e.ura.into());
            p(77, 6, e.health.into());
            p(83, 2, i64::from(e.iodc) >> 8);
            p(91, 1, e.l2p.into());
            p(197, 8, e.tgd.into());
            p(211, 8, i64::from(e.iodc));
            p(219, 16, e.toc.into());
            p(241, 8, e.af2.into());
            p(249, 16, e.af1.into());
            p(271, 22, e.af0.into());
        }
        Subframe::Ephem2(e) => {
            p(50, 3, 2);
            p(61, 8, e.iode.into());
            p(69, 16, e.crs.into());
            p(91, 16, e.delta_n.into());
            p(107, 8, i64::from(e.m0) >> 24);
            p(121, 24, e.m0.into());
            p(151, 16, e.cuc.into());
            p(167, 8, i64::from(e.e) >> 24);
            p(181, 24, e.e.into());
            p(211, 16, e.cus.into());
            p(227, 8, i64::from(e.sqrt_a) >> 24);
            p(241, 24, e.sqrt_a.into());
            p(271, 16, e.toe.into());
            p(287, 1, e.fit.into());
            p(288, 5, e.aodo.into());
        }
        Subframe::Ephem3(e) => {
            p(50, 3, 3);
            p(61, 16, e.cic.into());
            p(77, 8, i64::from(e.omega0) >> 24);
            p(91, 24, e.omega0.into());
            p(121, 16, e.cis.into());
            p(137, 8, i64::from(e.i0) >> 24);
            p(151, 24, e.i0.into());
            p(181, 16, e.crc.into());
            p(197, 8, i64::from(e.omega) >> 24);
            p(211, 24, e.omega.into());
            p(241, 24, e.omega_dot.into());
            p(271, 8, e.iode.into());
            p(279, 14, e.idot.into());
        }
        Subframe::IonoUtc(u) => {
            p(50, 3, 4);
            p(61, 2, 0b01);
            p(63, 6, 56);
            for (k, at) in [69, 77, 91, 99].into_iter().enumerate() {
                p(at, 8, u.alpha[k].into());
            }
            for (k, at) in [107, 121, 129, 137].into_iter().enumerate() {
                p(at, 8, u.beta[k].into());
            }
            p(151, 24, u.a1.into());
            p(181, 24, i64::from(u.a0) >> 8);
            p(211, 8, u.a0.into());
            p(219, 8, u.tot.into());
            p(227, 8, u.wnt.into());
            p(241, 8, u.dt_ls.into());
            p(249, 8, u.wn_lsf.into());
            p(257, 8, u.dn.into());
            p(271, 8, u.dt_lsf.into());
        }
        Subframe::Almanac(_) | Subframe::OtherPage { .. } => return None,
    }
    Some(words_from_data(d))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parity_inversion_and_fields_round_trip() {
        // TLM: preamble; HOW: TOW count 73 768, subframe 1; WN 69 in word 3.
        let mut data = [0u32; 10];
        data[0] = 0x8B << 16;
        data[1] = (73_768 << 7) | (1 << 2);
        data[2] = 69 << 14;
        data[9] = 0xAB_CDEF & !0x3; // a_f0 bits and the two "t" bits
        let words = words_from_data(data);
        let d = decode(&words).unwrap();
        // Some words were sent inverted (D30* = 1 after a word ending in 1).
        assert!(words.iter().any(|w| (w >> 30) & 1 == 1));
        assert_eq!((d.id, d.tow_count), (1, 73_768));
        let Subframe::Ephem1(e) = d.subframe else {
            panic!("{d:?}")
        };
        assert_eq!(e.wn, 69);
        // One flipped bit anywhere fails the parity of its word.
        for i in 0..10 {
            let mut bad = words;
            bad[i] ^= 1 << 17;
            assert_eq!(decode(&bad), Err(LnavError::Parity(i)));
        }
        assert_eq!(decode(&words[..9]), Err(LnavError::Words(9)));
    }

    /// Every field of subframes 1–3 and page 18 survives encode → decode, extremes included.
    #[test]
    fn encode_is_the_inverse_of_decode() {
        let e1 = Ephem1 {
            wn: 1023,
            l2: 2,
            ura: 15,
            health: 0x21,
            iodc: 0x3A5,
            l2p: 1,
            tgd: -128,
            toc: 0xFFFF,
            af2: -3,
            af1: -32_768,
            af0: -(1 << 21),
        };
        let e2 = Ephem2 {
            iode: 0xA5,
            crs: -5,
            delta_n: 32_767,
            m0: i32::MIN + 7,
            cuc: -1,
            e: u32::MAX - 3,
            cus: 1234,
            sqrt_a: 0xA1B2_C3D4,
            toe: 37_800 / 16,
            fit: 1,
            aodo: 31,
        };
        let e3 = Ephem3 {
            cic: -2,
            omega0: -123_456_789,
            cis: 77,
            i0: 654_321_987,
            crc: -32_768,
            omega: i32::MAX,
            omega_dot: -(1 << 23),
            iode: 0xA5,
            idot: -(1 << 13),
        };
        let page = IonoUtc {
            alpha: [11, -2, 127, -128],
            beta: [90, 16, -3, -64],
            a1: -(1 << 23),
            a0: i32::MIN + 1,
            tot: 144,
            wnt: 255,
            dt_ls: 13,
            wn_lsf: 137,
            dn: 7,
            dt_lsf: 14,
        };
        for (id, sf) in [
            (1, Subframe::Ephem1(e1)),
            (2, Subframe::Ephem2(e2)),
            (3, Subframe::Ephem3(e3)),
            (4, Subframe::IonoUtc(page)),
        ] {
            let words = encode(100_799, &sf).unwrap();
            let d = decode(&words).unwrap();
            assert_eq!((d.id, d.tow_count, d.subframe), (id, 100_799, sf));
        }
        assert_eq!(encode(1, &Subframe::OtherPage { subframe: 4, sv_id: 57 }), None);
    }
}
