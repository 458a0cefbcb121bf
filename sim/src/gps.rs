//! The simulated receiver's GPS L1 C/A side (`[gnss.sky]`): a constellation propagated from a
//! YUMA almanac, one broadcast ephemeris issue per satellite every two hours, the receiver's
//! pseudoranges and Dopplers of the satellites in view, and the UBX messages that carry them
//! (UBX-RXM-RAWX, UBX-RXM-SFRBX with GPS LNAV subframes).
//!
//! Written from IS-GPS-200N (Table 20-IV: the user algorithm for satellite position, §20.3.3.3.3.1
//! satellite clock and relativistic term, Figure 20-1/Tables 20-I and 20-III: subframe layouts,
//! §20.3.5.2 and Table 20-XIV: parity, §20.3.3.5.2.5: the Klobuchar model), the YUMA almanac
//! format as the US Coast Guard's NAVCEN publishes it, and the u-blox 8 / M8 protocol
//! description (UBX-13003221: UBX-RXM-RAWX, UBX-RXM-SFRBX, "GPS L1C/A" data words);
//! independently of the estimator's decoders and orbit model, which `tests/tests/estimator/sim_gps.rs`
//! checks against.
//!
//! The physics of one measurement (true GPS time t of the epoch, receiver antenna r, v in ECEF):
//! - transmission time t − τ with τ = |R_z(ω_e τ) r_s(t − τ) − r| / c iterated (the satellite
//!   position rotated by the Earth's turn during the flight: Sagnac);
//! - ρ = |…| + c (b_r − δt_s) + I + T + e_s + m + ε: receiver clock bias b_r (its own
//!   oscillator: bias, drift, random-walk frequency), satellite clock δt_s from the broadcast
//!   polynomial plus the relativistic term, the ionosphere I (the broadcast Klobuchar model ×
//!   `ionosphere_scale`: what the broadcast model misses), the troposphere T (a zenith delay
//!   from height with the Black–Eisner mapping, a different model than the estimator's,
//!   × `troposphere_scale`), the
//!   broadcast orbit-and-clock error e_s (one draw per satellite and ephemeris issue), a
//!   multipath-like first-order Gauss–Markov error m and white noise ε, the last two scaled by
//!   1/sin(elevation);
//! - Doppler = −ρ̇/λ_L1 (u-blox: positive when approaching) with ρ̇ = (v_s − v)·u + c (ḃ_r − δṫ_s);
//! - the receiver reports its epoch at its own time: rcvTow = t + b_r.
//!
//! Shortcuts, on purpose: the broadcast ephemeris is the truth orbit's own Keplerian elements
//! (no harmonic terms, Δn = IDOT = 0) quantised to their LNAV scale factors, its error
//! modelled in the range (e_s); subframe 4 carries page 18 (ionosphere, UTC) in every frame, so
//! that an estimator has the Klobuchar parameters within 30 s (a real satellite sends it
//! once per 12.5 minutes); subframe 5 is not sent. The receiver's clock is never stepped
//! (u-blox receivers keep |b_r| < 1 ms by millisecond jumps).

use std::path::Path;

use nalgebra::Vector3;
use navsync_shared::earth;
use navsync_shared::time::{NS_PER_S, SECONDS_PER_WEEK, gps_ns_from_utc_ns};
use serde::Deserialize;

use super::oscillator::Oscillator;
use super::rng::{Rng, streams};
use super::ubx;

/// Speed of light, m/s (IS-GPS-200 §20.3.4.3).
pub const C_M_S: f64 = 299_792_458.0;
/// WGS-84 gravitational constant μ, m³/s² (IS-GPS-200 Table 20-IV).
const MU_M3_S2: f64 = 3.986_005e14;
/// WGS-84 Earth rotation rate, rad/s (Table 20-IV).
const OMEGA_E_RAD_S: f64 = 7.292_115_146_7e-5;
/// Relativistic constant F = −2√μ/c², s/√m (§20.3.3.3.3.1).
const F_S_SQRT_M: f64 = -4.442_807_633e-10;
/// π as GPS defines it for semicircles (§20.3.3.3.3.1; deliberately truncated).
#[allow(clippy::approx_constant)]
const GPS_PI: f64 = 3.141_592_653_589_8;
/// L1 carrier, Hz.
pub const L1_HZ: f64 = 1_575.42e6;
/// GPS week, s.
const WEEK_S: f64 = SECONDS_PER_WEEK as f64;
/// Life of one broadcast ephemeris issue, s (t_oe in its middle).
const ISSUE_S: i64 = 7200;
/// PRNs of the GPS constellation.
pub const MAX_PRN: usize = 32;
/// Satellites one RXM-RAWX reports at most (a receiver's GPS channels).
pub const MAX_CHANNELS: usize = 16;

fn p2(n: i32) -> f64 {
    2f64.powi(n)
}

// ---------------------------------------------------------------------------------------------
// The almanac (YUMA)

/// One satellite of a YUMA almanac, in the file's units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AlmanacSat {
    /// PRN, 1..=32.
    pub prn: u8,
    /// Health (0 = healthy).
    pub health: u32,
    /// Eccentricity.
    pub e: f64,
    /// Time of applicability t_oa, s of the almanac week.
    pub toa_s: f64,
    /// Inclination, rad.
    pub i_rad: f64,
    /// Rate of right ascension Ω̇, rad/s.
    pub omega_dot_rad_s: f64,
    /// √A, √m.
    pub sqrt_a: f64,
    /// Longitude of the ascending node at the week's start Ω₀, rad.
    pub omega0_rad: f64,
    /// Argument of perigee ω, rad.
    pub omega_rad: f64,
    /// Mean anomaly at t_oa M₀, rad.
    pub m0_rad: f64,
    /// Clock bias a_f0, s.
    pub af0_s: f64,
    /// Clock drift a_f1, s/s.
    pub af1: f64,
    /// GPS week of t_oa (YUMA files often give it modulo 1024).
    pub week: u32,
}

/// Why a YUMA almanac was not read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("line {line}: {message}")]
pub struct YumaError {
    /// 1-based line.
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

/// The fields of one YUMA record, by the label's start, in file order.
const YUMA_FIELDS: [&str; 13] = [
    "ID",
    "Health",
    "Eccentricity",
    "Time of Applicability",
    "Orbital Inclination",
    "Rate of Right Ascen",
    "SQRT(A)",
    "Right Ascen at Week",
    "Argument of Perigee",
    "Mean Anom",
    "Af0",
    "Af1",
    "week",
];

/// Parses a YUMA almanac: records of thirteen `Label: value` lines, each record opened by a
/// `****` line. Unknown labels, bad numbers and incomplete records are errors with their line.
pub fn parse_yuma(text: &str) -> Result<Vec<AlmanacSat>, YumaError> {
    let mut out = Vec::new();
    let mut rec: Option<(usize, [Option<f64>; 13])> = None;
    let close = |rec: Option<(usize, [Option<f64>; 13])>, out: &mut Vec<AlmanacSat>| -> Result<(), YumaError> {
        let Some((line, v)) = rec else { return Ok(()) };
        let mut f = [0.0; 13];
        for (k, x) in v.iter().enumerate() {
            f[k] = x.ok_or_else(|| YumaError {
                line,
                message: format!("the record has no `{}` line", YUMA_FIELDS[k]),
            })?;
        }
        if !(1.0..=MAX_PRN as f64).contains(&f[0]) || f[0].fract() != 0.0 {
            return Err(YumaError {
                line,
                message: format!("ID {} is not a GPS PRN 1..=32", f[0]),
            });
        }
        out.push(AlmanacSat {
            prn: f[0] as u8,
            health: f[1] as u32,
            e: f[2],
            toa_s: f[3],
            i_rad: f[4],
            omega_dot_rad_s: f[5],
            sqrt_a: f[6],
            omega0_rad: f[7],
            omega_rad: f[8],
            m0_rad: f[9],
            af0_s: f[10],
            af1: f[11],
            week: f[12] as u32,
        });
        Ok(())
    };
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if line.is_empty() {
            continue;
        }
        if line.starts_with('*') {
            close(rec.take(), &mut out)?;
            rec = Some((i + 1, [None; 13]));
            continue;
        }
        let err = |message: String| YumaError { line: i + 1, message };
        let (label, value) = line
            .split_once(':')
            .ok_or_else(|| err(format!("`{line}` is not `Label: value`")))?;
        let k = YUMA_FIELDS
            .iter()
            .position(|f| label.trim().starts_with(f))
            .ok_or_else(|| err(format!("unknown label `{}`", label.trim())))?;
        let Some((_, fields)) = rec.as_mut() else {
            return Err(err("a value before the first `****` record header".into()));
        };
        let v: f64 = value
            .trim()
            .parse()
            .map_err(|_| err(format!("`{}` is not a number", value.trim())))?;
        if !v.is_finite() {
            return Err(err(format!("`{}` is not finite", value.trim())));
        }
        fields[k] = Some(v);
    }
    close(rec, &mut out)?;
    if out.is_empty() {
        return Err(YumaError {
            line: 1,
            message: "no almanac record".into(),
        });
    }
    Ok(out)
}

/// Reads and parses a YUMA almanac file.
pub fn read_yuma(path: &Path) -> Result<Vec<AlmanacSat>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    parse_yuma(&text).map_err(|e| format!("{}: {e}", path.display()))
}

// ---------------------------------------------------------------------------------------------
// One broadcast ephemeris issue

/// One satellite's broadcast ephemeris issue: Keplerian elements at t_oe as LNAV integers
/// (IS-GPS-200 Tables 20-I and 20-III scale factors); the truth orbit is the same elements.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ephemeris {
    /// PRN.
    pub prn: u8,
    /// Full GPS week of t_oe.
    pub week: i64,
    /// Issue of data (IODE = the 8 LSBs of IODC).
    pub iode: u8,
    /// t_oe = t_oc, s of week (a multiple of 16).
    pub toe_s: i64,
    /// √A, 2⁻¹⁹ √m.
    pub sqrt_a: u32,
    /// e, 2⁻³³.
    pub e: u32,
    /// i₀, 2⁻³¹ semicircles.
    pub i0: i32,
    /// Ω₀, 2⁻³¹ semicircles.
    pub omega0: i32,
    /// Ω̇ (24 bits), 2⁻⁴³ semicircles/s.
    pub omega_dot: i32,
    /// ω, 2⁻³¹ semicircles.
    pub omega: i32,
    /// M₀, 2⁻³¹ semicircles.
    pub m0: i32,
    /// a_f0 (22 bits), 2⁻³¹ s.
    pub af0: i32,
    /// a_f1, 2⁻⁴³ s/s.
    pub af1: i16,
}

/// A satellite's state at one instant (ECEF at that instant).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SatState {
    /// Position, ECEF m.
    pub pos_m: Vector3<f64>,
    /// Velocity in the rotating ECEF frame, m/s.
    pub vel_mps: Vector3<f64>,
    /// Clock offset δt_s (polynomial + relativistic term), s.
    pub clock_s: f64,
    /// Clock drift δṫ_s, s/s.
    pub clock_drift: f64,
}

/// `x` wrapped into [−π, π).
fn wrap_pi(x: f64) -> f64 {
    (x + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI
}

/// Rounds `x / lsb` to an integer that fits `bits` (two's complement), saturating.
fn quantise(x: f64, lsb: f64, bits: u32) -> i64 {
    let max = (1i64 << (bits - 1)) - 1;
    ((x / lsb).round() as i64).clamp(-max - 1, max)
}

impl Ephemeris {
    /// The issue of `a`'s satellite whose t_oe is `toe_s` of full week `week`: the almanac's
    /// elements carried from its t_oa to t_oe (M₀ by the mean motion, Ω₀ re-referenced to the
    /// week of t_oe, a_f0 by a_f1), quantised. `almanac_week` is `a`'s full week.
    pub fn from_almanac(a: &AlmanacSat, almanac_week: i64, week: i64, toe_s: i64, iode: u8) -> Self {
        let n = (MU_M3_S2 / a.sqrt_a.powi(6)).sqrt();
        let dweek_s = (week - almanac_week) as f64 * WEEK_S;
        let dt = dweek_s + toe_s as f64 - a.toa_s;
        // Ω(t) = Ω₀ + (Ω̇ − ω_e) t_k − ω_e t_ref with t_k from the reference (Table 20-IV): the
        // same node at any instant from either reference gives Ω₀' = Ω₀ + Ω̇ Δt_ref − ω_e·Δweek.
        let omega0 = a.omega0_rad + a.omega_dot_rad_s * dt - OMEGA_E_RAD_S * dweek_s;
        let m0 = a.m0_rad + n * dt;
        let semi = |x: f64, bits| quantise(wrap_pi(x) / GPS_PI, p2(-31), bits) as i32;
        Self {
            prn: a.prn,
            week,
            iode,
            toe_s,
            sqrt_a: (a.sqrt_a / p2(-19)).round() as u32,
            e: (a.e / p2(-33)).round() as u32,
            i0: semi(a.i_rad, 32),
            omega0: semi(omega0, 32),
            omega_dot: quantise(a.omega_dot_rad_s / GPS_PI, p2(-43), 24) as i32,
            omega: semi(a.omega_rad, 32),
            m0: semi(m0, 32),
            af0: quantise(a.af0_s + a.af1 * dt, p2(-31), 22) as i32,
            af1: quantise(a.af1, p2(-43), 16) as i16,
        }
    }

    /// Position, velocity and clock at GPS time `t_s` seconds from the start of week
    /// `self.week` (may be negative or beyond a week). IS-GPS-200 Table 20-IV with the
    /// harmonic corrections, Δn and IDOT zero; velocity by a central difference of ±0.5 s.
    pub fn state(&self, t_s: f64) -> SatState {
        let tk = t_s - self.toe_s as f64;
        let (p0, _) = self.position(tk - 0.5);
        let (p1, _) = self.position(tk + 0.5);
        let (pos_m, ek) = self.position(tk);
        let (sqrt_a, e) = (f64::from(self.sqrt_a) * p2(-19), f64::from(self.e) * p2(-33));
        let n = (MU_M3_S2 / sqrt_a.powi(6)).sqrt();
        let ek_dot = n / (1.0 - e * ek.cos());
        let (af0, af1) = (f64::from(self.af0) * p2(-31), f64::from(self.af1) * p2(-43));
        SatState {
            pos_m,
            vel_mps: p1 - p0,
            clock_s: af0 + af1 * tk + F_S_SQRT_M * e * sqrt_a * ek.sin(),
            clock_drift: af1 + F_S_SQRT_M * e * sqrt_a * ek.cos() * ek_dot,
        }
    }

    /// ECEF position at `tk` s from t_oe and the eccentric anomaly (rad).
    fn position(&self, tk: f64) -> (Vector3<f64>, f64) {
        let sqrt_a = f64::from(self.sqrt_a) * p2(-19);
        let a = sqrt_a * sqrt_a;
        let e = f64::from(self.e) * p2(-33);
        let semi = |v: i32| f64::from(v) * p2(-31) * GPS_PI;
        let n = (MU_M3_S2 / (a * a * a)).sqrt();
        let mk = semi(self.m0) + n * tk;
        // Kepler's equation M = E − e sin E by Newton's method.
        let mut ek = mk;
        for _ in 0..10 {
            ek -= (ek - e * ek.sin() - mk) / (1.0 - e * ek.cos());
        }
        let nu = ((1.0 - e * e).sqrt() * ek.sin()).atan2(ek.cos() - e);
        let u = nu + semi(self.omega);
        let r = a * (1.0 - e * ek.cos());
        let omega_dot = f64::from(self.omega_dot) * p2(-43) * GPS_PI;
        let node = semi(self.omega0) + (omega_dot - OMEGA_E_RAD_S) * tk - OMEGA_E_RAD_S * self.toe_s as f64;
        let (xp, yp) = (r * u.cos(), r * u.sin());
        let (so, co) = node.sin_cos();
        let (si, ci) = semi(self.i0).sin_cos();
        (
            Vector3::new(xp * co - yp * ci * so, xp * so + yp * ci * co, yp * si),
            ek,
        )
    }
}

// ---------------------------------------------------------------------------------------------
// LNAV subframes

/// Writes `value`'s `n` low bits at bits `from..from+n` of a subframe (1-based, IS-GPS-200
/// numbering: word k's data bits are 30(k−1)+1 ..= 30(k−1)+24).
fn put(d: &mut [u32; 10], from: u32, n: u32, value: i64) {
    for k in 0..n {
        let b = from + k;
        let (word, pos) = (((b - 1) / 30) as usize, (b - 1) % 30);
        debug_assert!(pos < 24, "bit {b} is a parity bit");
        let bit = ((value >> (n - 1 - k)) & 1) as u32;
        d[word] = (d[word] & !(1 << (23 - pos))) | (bit << (23 - pos));
    }
}

/// Parity bits D25..D30 of 24 source bits d1..d24 (d1 the MSB) after a word whose last two
/// transmitted bits were D29*, D30* (IS-GPS-200 Table 20-XIV).
fn lnav_parity(d: u32, d29: u32, d30: u32) -> u32 {
    let sum = |mask: &[u32]| mask.iter().fold(0, |acc, &n| acc ^ ((d >> (24 - n)) & 1));
    let p = [
        d29 ^ sum(&[1, 2, 3, 5, 6, 10, 11, 12, 13, 14, 17, 18, 20, 23]),
        d30 ^ sum(&[2, 3, 4, 6, 7, 11, 12, 13, 14, 15, 18, 19, 21, 24]),
        d29 ^ sum(&[1, 3, 4, 5, 7, 8, 12, 13, 14, 15, 16, 19, 20, 22]),
        d30 ^ sum(&[2, 4, 5, 6, 8, 9, 13, 14, 15, 16, 17, 20, 21, 23]),
        d30 ^ sum(&[1, 3, 5, 6, 7, 9, 10, 14, 15, 16, 17, 18, 21, 22, 24]),
        d29 ^ sum(&[3, 5, 6, 8, 9, 10, 11, 13, 15, 19, 22, 23, 24]),
    ];
    p.iter().fold(0, |acc, &b| (acc << 1) | b)
}

/// The ten words of a subframe as u-blox delivers them for GPS L1 C/A (UBX-RXM-SFRBX: the 30
/// transmitted bits right-aligned, D29*, D30* of the word before in bits 31 and 30): parity
/// added, data bits inverted after a word ending in D30 = 1, and the "t" bits of words 2 and
/// 10 (data bits 23–24) chosen so that their D29 = D30 = 0 (§20.3.5.2), which makes every
/// subframe start with D29* = D30* = 0.
fn lnav_words(mut d: [u32; 10]) -> [u32; 10] {
    let mut out = [0u32; 10];
    let (mut d29, mut d30) = (0u32, 0u32);
    for i in 0..10 {
        if i == 1 || i == 9 {
            let t = (0..4u32)
                .find(|t| lnav_parity((d[i] & !3) | t, d29, d30) & 3 == 0)
                .unwrap_or(0);
            d[i] = (d[i] & !3) | t;
        }
        let p = lnav_parity(d[i], d29, d30);
        let sent = if d30 == 1 { d[i] ^ 0xFF_FFFF } else { d[i] };
        out[i] = (d29 << 31) | (d30 << 30) | (sent << 6) | p;
        (d29, d30) = ((p >> 1) & 1, p & 1);
    }
    out
}

/// TLM and HOW: preamble, the TOW count of the next subframe's start (6 s units), the id.
fn lnav_header(d: &mut [u32; 10], tow_count: u32, id: u32) {
    put(d, 1, 8, 0x8B);
    put(d, 31, 17, i64::from(tow_count));
    put(d, 50, 3, i64::from(id));
}

/// Klobuchar coefficients as broadcast (subframe 4 page 18 integers).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KlobucharRaw {
    /// α₀..α₃, scale 2⁻³⁰, 2⁻²⁷, 2⁻²⁴, 2⁻²⁴.
    pub alpha: [i8; 4],
    /// β₀..β₃, scale 2¹¹, 2¹⁴, 2¹⁶, 2¹⁶.
    pub beta: [i8; 4],
}

const ALPHA_LSB: [i32; 4] = [-30, -27, -24, -24];
const BETA_LSB: [i32; 4] = [11, 14, 16, 16];

impl KlobucharRaw {
    /// From α (s, s/semicircle, …) and β (s, …), rounded to the broadcast scale.
    pub fn from_si(alpha: [f64; 4], beta: [f64; 4]) -> Self {
        let q = |x: f64, lsb: i32| quantise(x, p2(lsb), 8) as i8;
        Self {
            alpha: std::array::from_fn(|k| q(alpha[k], ALPHA_LSB[k])),
            beta: std::array::from_fn(|k| q(beta[k], BETA_LSB[k])),
        }
    }

    /// The L1 ionospheric delay, s, at a receiver (φ, λ rad) for a satellite at elevation and
    /// azimuth (rad) at GPS time `tow_s` (IS-GPS-200 §20.3.3.5.2.5, Figure 20-4).
    pub fn delay_s(&self, lat_rad: f64, lon_rad: f64, el_rad: f64, az_rad: f64, tow_s: f64) -> f64 {
        let semi = |x: f64| x / GPS_PI;
        let el = semi(el_rad);
        let psi = 0.0137 / (el + 0.11) - 0.022;
        let phi_i = (semi(lat_rad) + psi * az_rad.cos()).clamp(-0.416, 0.416);
        let lam_i = semi(lon_rad) + psi * az_rad.sin() / (phi_i * GPS_PI).cos();
        let phi_m = phi_i + 0.064 * ((lam_i - 1.617) * GPS_PI).cos();
        let t = (4.32e4 * lam_i + tow_s).rem_euclid(86_400.0);
        let f = 1.0 + 16.0 * (0.53 - el).powi(3);
        let poly = |c: [i8; 4], lsb: [i32; 4]| {
            (0..4)
                .map(|k| f64::from(c[k]) * p2(lsb[k]) * phi_m.powi(k as i32))
                .sum::<f64>()
        };
        let per = poly(self.beta, BETA_LSB).max(72_000.0);
        let amp = poly(self.alpha, ALPHA_LSB).max(0.0);
        let x = 2.0 * std::f64::consts::PI * (t - 50_400.0) / per;
        if x.abs() < 1.57 {
            f * (5e-9 + amp * (1.0 - x * x / 2.0 + x.powi(4) / 24.0))
        } else {
            f * 5e-9
        }
    }
}

/// Subframe `id` (1–4) of `eph`'s issue, transmitted just before TOW count `tow_count` (the
/// HOW's count: the next subframe's start, 6 s units); subframe 4 is page 18.
pub fn subframe(eph: &Ephemeris, id: u32, tow_count: u32, iono: &KlobucharRaw) -> [u32; 10] {
    let mut d = [0u32; 10];
    lnav_header(&mut d, tow_count, id);
    let iodc = i64::from(eph.iode);
    match id {
        1 => {
            put(&mut d, 61, 10, eph.week.rem_euclid(1024));
            put(&mut d, 71, 2, 0b01); // P code on L2
            put(&mut d, 73, 4, 0); // URA index 0: 2.4 m
            put(&mut d, 77, 6, 0); // healthy
            put(&mut d, 83, 2, iodc >> 8);
            put(&mut d, 211, 8, iodc & 0xFF);
            put(&mut d, 197, 8, 0); // T_GD
            put(&mut d, 219, 16, eph.toe_s / 16);
            put(&mut d, 241, 8, 0); // a_f2
            put(&mut d, 249, 16, i64::from(eph.af1));
            put(&mut d, 271, 22, i64::from(eph.af0));
        }
        2 => {
            put(&mut d, 61, 8, i64::from(eph.iode));
            put(&mut d, 107, 8, i64::from(eph.m0) >> 24);
            put(&mut d, 121, 24, i64::from(eph.m0));
            put(&mut d, 167, 8, i64::from(eph.e) >> 24);
            put(&mut d, 181, 24, i64::from(eph.e));
            put(&mut d, 227, 8, i64::from(eph.sqrt_a) >> 24);
            put(&mut d, 241, 24, i64::from(eph.sqrt_a));
            put(&mut d, 271, 16, eph.toe_s / 16);
        }
        3 => {
            put(&mut d, 77, 8, i64::from(eph.omega0) >> 24);
            put(&mut d, 91, 24, i64::from(eph.omega0));
            put(&mut d, 137, 8, i64::from(eph.i0) >> 24);
            put(&mut d, 151, 24, i64::from(eph.i0));
            put(&mut d, 197, 8, i64::from(eph.omega) >> 24);
            put(&mut d, 211, 24, i64::from(eph.omega));
            put(&mut d, 241, 24, i64::from(eph.omega_dot));
            put(&mut d, 271, 8, i64::from(eph.iode));
        }
        _ => {
            // Page 18: data id 01, SV id 56; α, β; UTC A1 = A0 = 0, ΔtLS = ΔtLSF = 18 s.
            put(&mut d, 61, 2, 0b01);
            put(&mut d, 63, 6, 56);
            for (k, at) in [69, 77, 91, 99].into_iter().enumerate() {
                put(&mut d, at, 8, i64::from(iono.alpha[k]));
            }
            for (k, at) in [107, 121, 129, 137].into_iter().enumerate() {
                put(&mut d, at, 8, i64::from(iono.beta[k]));
            }
            put(&mut d, 219, 8, (eph.toe_s / 4096) & 0xFF);
            put(&mut d, 227, 8, eph.week & 0xFF);
            put(&mut d, 241, 8, 18);
            put(&mut d, 249, 8, eph.week & 0xFF);
            put(&mut d, 257, 8, 7);
            put(&mut d, 271, 8, 18);
        }
    }
    lnav_words(d)
}

/// A UBX-RXM-SFRBX frame (class 0x02, id 0x13, version 2) of GPS L1 C/A words.
pub fn write_sfrbx(prn: u8, channel: u8, words: &[u32; 10], out: &mut Vec<u8>) {
    let mut p = [0u8; 8 + 40];
    p[0] = 0; // gnssId GPS
    p[1] = prn;
    p[4] = 10; // numWords
    p[5] = channel;
    p[6] = 2; // version
    for (k, w) in words.iter().enumerate() {
        p[8 + 4 * k..12 + 4 * k].copy_from_slice(&w.to_le_bytes());
    }
    ubx::frame(0x02, 0x13, &p, out);
}

// ---------------------------------------------------------------------------------------------
// The sky and the receiver's measurements

/// `[gnss.sky]`: the receiver's GPS signals (needs `gnss.protocol = "ubx"`).
#[derive(Debug, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SkyConfig {
    /// YUMA almanac of the constellation (relative to the scenario file's folder); none: the
    /// receiver writes no raw measurements (default none). `navsync decode --yuma CAPTURE`
    /// writes one from a u-blox capture's subframes.
    pub almanac: Option<String>,
    /// The almanac's satellites, read from `almanac` when the scenario is loaded.
    #[serde(skip)]
    pub constellation: Vec<AlmanacSat>,
    /// Elevation below which the receiver tracks nothing, deg (default 5).
    pub elevation_mask_deg: f64,
    /// White pseudorange noise at zenith, 1 σ, m (default 0.5; × 1/sin(elevation)).
    pub pseudorange_sigma_m: f64,
    /// Multipath-like pseudorange error at zenith, 1 σ, m (default 1; × 1/sin(elevation)).
    pub multipath_sigma_m: f64,
    /// Its correlation time (first-order Gauss–Markov), s (default 30).
    pub multipath_correlation_s: f64,
    /// White range-rate noise at zenith, 1 σ, m/s (default 0.03; × 1/sin(elevation)).
    pub range_rate_sigma_mps: f64,
    /// Broadcast orbit-and-clock error along the line of sight, 1 σ, m: one draw per
    /// satellite and ephemeris issue (default 1).
    pub broadcast_error_m: f64,
    /// True ionosphere = the broadcast Klobuchar delay × this (default 1.3).
    pub ionosphere_scale: f64,
    /// True troposphere = this simulator's zenith-delay-and-mapping model × this (default
    /// 1.05: the receiver, which corrects with that model, keeps 5 %).
    pub troposphere_scale: f64,
    /// Broadcast Klobuchar α₀..α₃, s, s/semicircle, s/semicircle², s/semicircle³.
    pub klobuchar_alpha: [f64; 4],
    /// Broadcast Klobuchar β₀..β₃, s, s/semicircle, …
    pub klobuchar_beta: [f64; 4],
    /// Receiver clock bias at the start, s (default 50 µs).
    pub clock_bias_s: f64,
    /// Receiver clock drift (fractional frequency error) at the start (default 2e-7).
    pub clock_drift: f64,
    /// Random-walk of that frequency error, 1/√s (default 1e-10: a TCXO).
    pub clock_drift_random_walk: f64,
    /// Canyons and blockages (TOML `[[gnss.sky.window]]`).
    #[serde(rename = "window")]
    pub windows: Vec<SkyWindow>,
}

impl Default for SkyConfig {
    fn default() -> Self {
        Self {
            almanac: None,
            constellation: Vec::new(),
            elevation_mask_deg: 5.0,
            pseudorange_sigma_m: 0.5,
            multipath_sigma_m: 1.0,
            multipath_correlation_s: 30.0,
            range_rate_sigma_mps: 0.03,
            broadcast_error_m: 1.0,
            ionosphere_scale: 1.3,
            troposphere_scale: 1.05,
            klobuchar_alpha: [1.1176e-8, 7.4506e-9, -5.9605e-8, -5.9605e-8],
            klobuchar_beta: [90_112.0, 0.0, -196_608.0, -65_536.0],
            clock_bias_s: 50e-6,
            clock_drift: 2e-7,
            clock_drift_random_walk: 1e-10,
            windows: Vec::new(),
        }
    }
}

/// A time window in which fewer satellites are visible (scenario time).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SkyWindow {
    /// Start, s of scenario time.
    pub start_s: f64,
    /// Length, s.
    pub duration_s: f64,
    /// At most this many satellites, the highest first (0: full blockage).
    pub max_sats: Option<usize>,
    /// A street canyon: only satellites within ± this many degrees of the vehicle's heading
    /// or its reverse (along the street) are visible.
    pub corridor_half_width_deg: Option<f64>,
    /// Elevation mask inside the window, deg (buildings; default the sky's mask).
    pub elevation_mask_deg: Option<f64>,
}

/// What the receiver's GPS side wrote for one epoch.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SkyEpoch {
    /// Satellites measured (in RXM-RAWX).
    pub tracked: usize,
    /// Subframes sent (RXM-SFRBX).
    pub subframes: usize,
    /// The receiver's own solution from these measurements (≥ 4 satellites).
    pub fix: Option<SkyFix>,
}

/// The error of the receiver's own position/velocity solution: the weighted least-squares
/// solution (position + clock, velocity + drift) of the measurement errors it does not
/// correct (broadcast error, unmodelled ionosphere, multipath, noise), linearised at the
/// truth — ranges of 20 000 km make the metre-level errors linear to ~10⁻⁷. Its accuracy
/// estimates cover the whole error budget, the persistent errors too (as a receiver's UERE
/// budget does), not the noise it weights by alone.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SkyFix {
    /// Position error, NED m.
    pub pos_err_ned_m: [f64; 3],
    /// Velocity error, NED m/s.
    pub vel_err_ned_mps: [f64; 3],
    /// 1σ horizontal (RSS of north and east), m, from the solution's covariance under the
    /// whole error budget.
    pub h_acc_m: f64,
    /// 1σ vertical, m.
    pub v_acc_m: f64,
    /// √2 × the mean 1σ per velocity axis, m/s (u-blox sAcc as the estimator reads it).
    pub s_acc_mps: f64,
}

/// Weighted least squares of errors `e` with rows (line of sight u in ECEF, σ):
/// ((HᵀWH)⁻¹HᵀW e, (HᵀWH)⁻¹) for the states (δr ECEF, δ clock), H = [−uᵀ 1].
fn wls_error(rows: &[(Vector3<f64>, f64, f64)]) -> Option<(nalgebra::Vector4<f64>, nalgebra::Matrix4<f64>)> {
    let mut n = nalgebra::Matrix4::zeros();
    let mut b = nalgebra::Vector4::zeros();
    for (u, sigma, e) in rows {
        let h = nalgebra::Vector4::new(-u[0], -u[1], -u[2], 1.0);
        let w = 1.0 / (sigma * sigma).max(1e-12);
        n += h * h.transpose() * w;
        b += h * (w * e);
    }
    let p = n.try_inverse()?;
    Some((p * b, p))
}

/// The receiver's oscillator: what its clock reads against GPS time. The receiver's time is
/// t_r = t_GPS + b(τ) with the clock bias b(τ) = b₀ + ∫₀^τ y ds, its fractional frequency error
/// y (the clock drift) starting at `clock_drift` and wandering as a random walk of
/// `clock_drift_random_walk`/√s — the host clock's model ([`Oscillator`], RWFM with Allan
/// deviation σ_y(1 s) = q/√3 for a random-walk step q·√Δ). A deterministic function of
/// scenario time τ, so the GPS side and an IMU sampling on the same crystal
/// (`imu.unit[i].receiver_clock`) see one clock.
#[derive(Debug, Clone)]
pub struct ReceiverClock {
    bias0_s: f64,
    start_gps_ns: i64,
    osc: Oscillator,
}

impl ReceiverClock {
    /// The clock of `cfg` for a scenario starting at UTC `start_utc_ns` and lasting
    /// `duration_s`, drawn over it and 10 s more (beyond, the frequency stays constant) from
    /// the seed's GPS-clock stream: the same arguments give the same clock.
    pub fn new(cfg: &SkyConfig, seed: u64, start_utc_ns: i64, duration_s: f64) -> Self {
        let osc = Oscillator::new(
            0,
            0,
            cfg.clock_drift,
            cfg.clock_drift_random_walk / 3f64.sqrt(),
            duration_s + 10.0,
            &mut Rng::stream(seed, streams::GPS_CLOCK),
        );
        Self {
            bias0_s: cfg.clock_bias_s,
            start_gps_ns: gps_ns_from_utc_ns(start_utc_ns),
            osc,
        }
    }

    /// Clock bias b at scenario time `tau`, s (receiver time − GPS time).
    pub fn bias_s(&self, tau: f64) -> f64 {
        self.bias0_s + self.osc.offset_s(tau)
    }

    /// Clock drift ḃ (fractional frequency error) at scenario time `tau`.
    pub fn drift(&self, tau: f64) -> f64 {
        self.osc.freq_error(tau)
    }

    /// What the receiver's clock reads at scenario time `tau`: GPS time + b, ns since the
    /// GPS epoch (rounded to the ns).
    pub fn reading_ns(&self, tau: f64) -> i64 {
        self.start_gps_ns + ((tau + self.bias_s(tau)) * 1e9).round() as i64
    }

    /// The scenario time at which the receiver's clock reads `reading_ns` (ns since the GPS
    /// epoch), s: Newton's iteration on τ + b(τ) = reading, exact to < 1 ps in 3 steps since
    /// |ḃ| ≪ 1.
    pub fn tau_at_reading(&self, reading_ns: i64) -> f64 {
        let target = (reading_ns - self.start_gps_ns) as f64 * 1e-9;
        let mut tau = target - self.bias_s(target);
        for _ in 0..3 {
            tau -= (tau + self.bias_s(tau) - target) / (1.0 + self.drift(tau));
        }
        tau
    }
}

/// The receiver's GPS side: constellation, clock and error processes.
#[derive(Debug, Clone)]
pub struct Sky {
    cfg: SkyConfig,
    almanac_weeks: Vec<i64>,
    iono: KlobucharRaw,
    seed: u64,
    noise: Rng,
    clock: ReceiverClock,
    /// GPS time of the last epoch written, ns.
    last_epoch_gps_ns: Option<i64>,
    /// Scenario time of the last epoch written, s.
    last_epoch_tau: f64,
    multipath: [f64; MAX_PRN],
    last_subframe_tow: Option<i64>,
}

impl Sky {
    /// The sky of `cfg` for a scenario starting at `start_utc_ns` and lasting `duration_s`
    /// (its receiver clock: [`ReceiverClock::new`]); `None` without an almanac.
    pub fn new(cfg: &SkyConfig, seed: u64, start_utc_ns: i64, duration_s: f64) -> Option<Self> {
        if cfg.constellation.is_empty() {
            return None;
        }
        let now_week = gps_ns_from_utc_ns(start_utc_ns).div_euclid(SECONDS_PER_WEEK * NS_PER_S);
        // A week given modulo 1024: the roll-over period nearest the scenario's week.
        let almanac_weeks = cfg
            .constellation
            .iter()
            .map(|a| {
                let w = i64::from(a.week);
                if w >= 1024 {
                    w
                } else {
                    w + ((now_week - w) as f64 / 1024.0).round() as i64 * 1024
                }
            })
            .collect();
        let mut noise = Rng::stream(seed, streams::GPS_NOISE);
        let multipath = std::array::from_fn(|_| noise.normal());
        Some(Self {
            cfg: cfg.clone(),
            almanac_weeks,
            iono: KlobucharRaw::from_si(cfg.klobuchar_alpha, cfg.klobuchar_beta),
            seed,
            noise,
            clock: ReceiverClock::new(cfg, seed, start_utc_ns, duration_s),
            last_epoch_gps_ns: None,
            last_epoch_tau: 0.0,
            multipath,
            last_subframe_tow: None,
        })
    }

    /// The ephemeris issue of almanac entry `k` in force at GPS time `gps_ns`.
    pub fn ephemeris(&self, k: usize, gps_ns: i64) -> Ephemeris {
        let a = &self.cfg.constellation[k];
        let t_s = gps_ns.div_euclid(NS_PER_S);
        let issue = t_s.div_euclid(ISSUE_S);
        let toe_abs = issue * ISSUE_S + ISSUE_S / 2;
        let (week, toe_s) = (
            toe_abs.div_euclid(SECONDS_PER_WEEK),
            toe_abs.rem_euclid(SECONDS_PER_WEEK),
        );
        let iode = (issue + i64::from(a.prn) * 7).rem_euclid(256) as u8;
        Ephemeris::from_almanac(a, self.almanac_weeks[k], week, toe_s, iode)
    }

    /// The receiver clock at the last epoch written: bias (s) and drift (s/s), the truth its
    /// pseudoranges carry.
    pub fn receiver_clock(&self) -> (f64, f64) {
        (
            self.clock.bias_s(self.last_epoch_tau),
            self.clock.drift(self.last_epoch_tau),
        )
    }

    /// The receiver's oscillator.
    pub fn clock(&self) -> &ReceiverClock {
        &self.clock
    }

    /// The window in force at scenario time `tau`, if any.
    fn window(&self, tau: f64) -> Option<&SkyWindow> {
        self.cfg
            .windows
            .iter()
            .find(|w| tau >= w.start_s && tau < w.start_s + w.duration_s)
    }

    /// Writes the epoch at UTC `utc_ns` (scenario time `tau`) for an antenna at (φ, λ rad, h m)
    /// moving at `v_ned` (m/s) with the vehicle heading `heading_rad`: RXM-RAWX of the
    /// satellites in view and RXM-SFRBX of the subframes completed since the last epoch.
    pub fn write_epoch(
        &mut self,
        utc_ns: i64,
        tau: f64,
        antenna: [f64; 3],
        v_ned: Vector3<f64>,
        heading_rad: f64,
        out: &mut Vec<u8>,
    ) -> SkyEpoch {
        let gps_ns = gps_ns_from_utc_ns(utc_ns);
        let week_ns = SECONDS_PER_WEEK * NS_PER_S;
        let (week, tow_ns) = (gps_ns.div_euclid(week_ns), gps_ns.rem_euclid(week_ns));
        let tow_s = tow_ns as f64 * 1e-9;
        let dt = self
            .last_epoch_gps_ns
            .replace(gps_ns)
            .map_or(1.0, |last| ((gps_ns - last) as f64 * 1e-9).max(0.0));
        self.last_epoch_tau = tau;
        let (bias_s, drift) = (self.clock.bias_s(tau), self.clock.drift(tau));
        let (lat, lon, h) = (antenna[0], antenna[1], antenna[2]);
        let rx = Vector3::from(earth::geodetic_to_ecef(lat, lon, h));
        let c_e_n = ned_from_ecef(lat, lon);
        let v_rx = c_e_n.transpose() * v_ned;
        // Every PRN draws its noise every epoch, visible or not: visibility never shifts the
        // noise sequence of another satellite or epoch.
        let phi = (-dt / self.cfg.multipath_correlation_s.max(1e-3)).exp();
        let mut white = [(0.0, 0.0); MAX_PRN];
        for (m, w) in self.multipath.iter_mut().zip(white.iter_mut()) {
            *m = phi * *m + (1.0 - phi * phi).sqrt() * self.noise.normal();
            *w = (self.noise.normal(), self.noise.normal());
        }
        let window = self.window(tau).cloned();
        let mask = window
            .as_ref()
            .and_then(|w| w.elevation_mask_deg)
            .unwrap_or(self.cfg.elevation_mask_deg)
            .to_radians();
        let mut seen: Vec<Seen> = Vec::with_capacity(MAX_PRN);
        for k in 0..self.cfg.constellation.len() {
            let a = self.cfg.constellation[k];
            if a.health != 0 {
                continue;
            }
            let eph = self.ephemeris(k, gps_ns);
            let t_week = ((week - eph.week) as f64) * WEEK_S + tow_s;
            // Signal flight: τ from the geometric range with the satellite rotated by ω_e τ.
            let mut tau_s = 0.075;
            let mut sat = eph.state(t_week - tau_s);
            let mut rot = sat.pos_m;
            for _ in 0..5 {
                sat = eph.state(t_week - tau_s);
                rot = rotate_z(&sat.pos_m, OMEGA_E_RAD_S * tau_s);
                tau_s = (rot - rx).norm() / C_M_S;
            }
            let los = rot - rx;
            let range = los.norm();
            let u = los / range;
            let u_ned = c_e_n * u;
            let el = (-u_ned[2]).asin();
            let az = u_ned[1].atan2(u_ned[0]);
            if el < mask {
                continue;
            }
            if let Some(half) = window.as_ref().and_then(|w| w.corridor_half_width_deg) {
                let off = wrap_pi(az - heading_rad).abs();
                if off.min(std::f64::consts::PI - off) > half.to_radians() {
                    continue;
                }
            }
            let sin_el = el.sin().max(0.1);
            let i = usize::from(a.prn) - 1;
            let iono_m = self.cfg.ionosphere_scale * C_M_S * self.iono.delay_s(lat, lon, el, az, tow_s);
            let tropo_model_m = (2.3 * (-1.16e-4 * h).exp() + 0.1) * 1.001 / (0.002_001 + sin_el * sin_el).sqrt();
            let tropo_m = self.cfg.troposphere_scale * tropo_model_m;
            let sisre_m = Rng::stream(
                self.seed,
                streams::GPS_BROADCAST ^ (u64::from(a.prn) << 32) ^ u64::from(eph.iode),
            )
            .gaussian(self.cfg.broadcast_error_m);
            // What the receiver's own solution does not correct: all but the broadcast
            // ionosphere (iono_m / scale) and the troposphere model.
            // What the receiver's ionosphere and troposphere models leave, m.
            let iono_left_m = (self.cfg.ionosphere_scale - 1.0) / self.cfg.ionosphere_scale.max(1e-9) * iono_m;
            let tropo_left_m = tropo_m - tropo_model_m;
            let pr_err = iono_left_m
                + tropo_left_m
                + sisre_m
                + self.cfg.multipath_sigma_m / sin_el * self.multipath[i]
                + self.cfg.pseudorange_sigma_m / sin_el * white[i].0;
            let pr = range
                + C_M_S * (bias_s - sat.clock_s)
                + iono_m / self.cfg.ionosphere_scale.max(1e-9)
                + tropo_model_m
                + pr_err;
            let v_sat = rotate_z(&sat.vel_mps, OMEGA_E_RAD_S * tau_s);
            let rr_err = self.cfg.range_rate_sigma_mps / sin_el * white[i].1;
            let rr = (v_sat - v_rx).dot(&u) + C_M_S * (drift - sat.clock_drift) + rr_err;
            let pr_sigma = self.cfg.pseudorange_sigma_m.hypot(self.cfg.multipath_sigma_m) / sin_el;
            let rr_sigma = self.cfg.range_rate_sigma_mps / sin_el;
            // What the receiver's error budget adds for the errors its corrections leave, which
            // persist from epoch to epoch: the broadcast orbit and clock, the ionosphere and
            // troposphere its models miss (their size here).
            let persistent_sigma = self.cfg.broadcast_error_m.hypot(iono_left_m).hypot(tropo_left_m);
            seen.push(Seen {
                el,
                meas: Measured {
                    prn: a.prn,
                    pr_m: pr,
                    doppler_hz: -rr * L1_HZ / C_M_S,
                    cno_dbhz: (30.0 + 20.0 * el.sin()).round() as u8,
                    pr_sigma_m: pr_sigma,
                    doppler_sigma_hz: rr_sigma * L1_HZ / C_M_S,
                },
                u,
                pr_err,
                rr_err,
                persistent_sigma,
            });
        }
        seen.sort_by(|a, b| b.el.total_cmp(&a.el));
        let max = window.as_ref().and_then(|w| w.max_sats).unwrap_or(MAX_CHANNELS);
        seen.truncate(max.min(MAX_CHANNELS));
        let fix = self.solution(&seen, &c_e_n);
        let meas: Vec<Measured> = seen.into_iter().map(|x| x.meas).collect();
        write_rawx(tow_s + bias_s, week, &meas, out);
        // Subframes whose transmission ended since the last epoch (at multiples of 6 s).
        let now_s = gps_ns.div_euclid(NS_PER_S);
        let mut subframes = 0;
        let last = self.last_subframe_tow.replace(now_s.div_euclid(6) * 6);
        let first = last.map_or(now_s.div_euclid(6) * 6, |l| l + 6);
        let mut end = first;
        while end <= now_s {
            // The subframe sent in [end − 6, end): id from its position in the 30 s frame.
            let id = ((end - 6).div_euclid(6).rem_euclid(5) + 1) as u32;
            if id <= 4 {
                let tow_count = (end.rem_euclid(SECONDS_PER_WEEK) / 6) as u32;
                for (ch, m) in meas.iter().enumerate() {
                    let k = self.cfg.constellation.iter().position(|a| a.prn == m.prn).unwrap_or(0);
                    let eph = self.ephemeris(k, (end - 6) * NS_PER_S);
                    write_sfrbx(m.prn, ch as u8, &subframe(&eph, id, tow_count, &self.iono), out);
                    subframes += 1;
                }
            }
            end += 6;
        }
        SkyEpoch {
            tracked: meas.len(),
            subframes,
            fix,
        }
    }

    /// The receiver's own solution error from the tracked satellites (≥ 4), see [`SkyFix`].
    fn solution(&self, seen: &[Seen], c_e_n: &nalgebra::Matrix3<f64>) -> Option<SkyFix> {
        if seen.len() < 4 {
            return None;
        }
        let rr_sigma = |el: f64| self.cfg.range_rate_sigma_mps.max(1e-3) / el.sin().max(0.1);
        let pr_rows: Vec<_> = seen
            .iter()
            .map(|x| (x.u, x.meas.pr_sigma_m.max(0.01), x.pr_err))
            .collect();
        let rr_rows: Vec<_> = seen.iter().map(|x| (x.u, rr_sigma(x.el), x.rr_err)).collect();
        let (dx, p) = wls_error(&pr_rows)?;
        let (dv, pv) = wls_error(&rr_rows)?;
        let pos = c_e_n * dx.fixed_rows::<3>(0);
        let vel = c_e_n * dv.fixed_rows::<3>(0);
        // The accuracy it reports is its solution's covariance under the whole error budget,
        // the persistent errors too (weighted as the noise alone: P + P·Σ h hᵀ σ_p²/σ⁴·P, the
        // covariance of the weighted solution when each range's variance is σ² + σ_p²).
        let mut extra = nalgebra::Matrix4::zeros();
        for ((u, sigma, _), x) in pr_rows.iter().zip(seen) {
            let h = nalgebra::Vector4::new(-u[0], -u[1], -u[2], 1.0);
            extra += h * h.transpose() * (x.persistent_sigma / (sigma * sigma)).powi(2);
        }
        let p = p + p * extra * p;
        let p_ned = c_e_n * p.fixed_view::<3, 3>(0, 0) * c_e_n.transpose();
        let trace_v = pv.fixed_view::<3, 3>(0, 0).trace();
        Some(SkyFix {
            pos_err_ned_m: pos.into(),
            vel_err_ned_mps: vel.into(),
            h_acc_m: (p_ned[(0, 0)] + p_ned[(1, 1)]).sqrt(),
            v_acc_m: p_ned[(2, 2)].sqrt(),
            s_acc_mps: std::f64::consts::SQRT_2 * (trace_v / 3.0).sqrt(),
        })
    }
}

/// A satellite the receiver tracks in an epoch.
struct Seen {
    /// Elevation, rad.
    el: f64,
    meas: Measured,
    /// Line of sight, ECEF unit vector.
    u: Vector3<f64>,
    /// The pseudorange's error the receiver does not correct, m.
    pr_err: f64,
    /// The range rate's error, m/s.
    rr_err: f64,
    /// 1σ of the errors in `pr_err` that persist from epoch to epoch (the broadcast orbit and
    /// clock, what the atmosphere models leave), m: the receiver's error budget beyond
    /// `meas.pr_sigma_m`.
    persistent_sigma: f64,
}

/// One satellite's measurement as RXM-RAWX reports it.
#[derive(Debug, Clone, Copy)]
struct Measured {
    prn: u8,
    pr_m: f64,
    doppler_hz: f64,
    cno_dbhz: u8,
    pr_sigma_m: f64,
    doppler_sigma_hz: f64,
}

/// The smallest n (0..=15) with base·2ⁿ ≥ σ: the RAWX standard-deviation code.
fn stdev_code(sigma: f64, base: f64) -> u8 {
    (0..15u8).find(|n| base * p2(i32::from(*n)) >= sigma).unwrap_or(15)
}

/// A UBX-RXM-RAWX frame (class 0x02, id 0x15, version 1): receiver time of week `rcv_tow_s`.
fn write_rawx(rcv_tow_s: f64, week: i64, meas: &[Measured], out: &mut Vec<u8>) {
    let (mut tow, mut week) = (rcv_tow_s, week);
    if tow >= WEEK_S {
        tow -= WEEK_S;
        week += 1;
    }
    let mut p = vec![0u8; 16 + 32 * meas.len()];
    p[0..8].copy_from_slice(&tow.to_le_bytes());
    p[8..10].copy_from_slice(&(week as u16).to_le_bytes());
    p[10] = 18; // leapS
    p[11] = meas.len() as u8;
    p[12] = 0b01; // recStat: leap seconds determined
    p[13] = 1; // version
    for (k, m) in meas.iter().enumerate() {
        let o = 16 + 32 * k;
        p[o..o + 8].copy_from_slice(&m.pr_m.to_le_bytes());
        p[o + 16..o + 20].copy_from_slice(&(m.doppler_hz as f32).to_le_bytes());
        p[o + 20] = 0; // gnssId GPS
        p[o + 21] = m.prn;
        p[o + 22] = 0; // sigId L1 C/A
        p[o + 26] = m.cno_dbhz;
        p[o + 27] = stdev_code(m.pr_sigma_m, 0.01);
        p[o + 29] = stdev_code(m.doppler_sigma_hz, 0.002);
        p[o + 30] = 0b0001; // trkStat: pseudorange valid (no carrier phase)
    }
    ubx::frame(0x02, 0x15, &p, out);
}

/// `v` rotated about the z axis by `angle` (rad): an ECEF vector of an earlier instant
/// expressed in the ECEF frame `angle / ω_e` seconds later.
fn rotate_z(v: &Vector3<f64>, angle: f64) -> Vector3<f64> {
    let (s, c) = angle.sin_cos();
    Vector3::new(c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2])
}

/// C_e^n: ECEF → NED at (φ, λ).
fn ned_from_ecef(lat: f64, lon: f64) -> nalgebra::Matrix3<f64> {
    let (sp, cp) = lat.sin_cos();
    let (sl, cl) = lon.sin_cos();
    nalgebra::Matrix3::new(-sp * cl, -sp * sl, cp, -sl, cl, 0.0, -cp * cl, -cp * sl, -sp)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_receiver_clock_is_one_invertible_function_of_time() {
        let cfg = SkyConfig::default();
        let start = 1_796_083_200_000_000_000;
        let (a, b) = (
            ReceiverClock::new(&cfg, 3, start, 600.0),
            ReceiverClock::new(&cfg, 3, start, 600.0),
        );
        let gps0 = gps_ns_from_utc_ns(start);
        for k in 0..600 {
            let tau = k as f64 * 1.0137;
            assert_eq!(a.bias_s(tau), b.bias_s(tau), "same arguments, same clock");
            // Reading = GPS time + bias; its inverse within a ns (the reading's rounding).
            let r = a.reading_ns(tau);
            assert!((r - gps0 - (tau * 1e9).round() as i64 - (a.bias_s(tau) * 1e9).round() as i64).abs() <= 1);
            assert!((a.tau_at_reading(r) - tau).abs() < 1.1e-9, "{k}");
        }
        // Bias 50 µs + 0.2 ppm drift; the random walk (1e-10/√s) moves the frequency by
        // 2.4e-9 and the time by 0.85 µs (1σ) over 10 min.
        let predicted = cfg.clock_bias_s + cfg.clock_drift * 600.0;
        assert!(
            (a.bias_s(600.0) - predicted).abs() < 5e-6,
            "{}",
            a.bias_s(600.0) - predicted
        );
        assert!((a.drift(600.0) - cfg.clock_drift).abs() < 1e-8);
        assert!((a.bias_s(600.0) - predicted).abs() > 0.0, "it wanders");
    }

    const YUMA: &str = "******** Week 1015 almanac for PRN-03 ********
ID:                         03
Health:                     000
Eccentricity:               0.1540565491E-001
Time of Applicability(s):  589824.0000
Orbital Inclination(rad):   0.9667646885
Rate of Right Ascen(r/s):  -0.7497455496E-008
SQRT(A)  (m 1/2):           5153.632324
Right Ascen at Week(rad):   0.1080935121E+001
Argument of Perigee(rad):   0.867064476
Mean Anom(rad):            -0.2049810290E+001
Af0(s):                     0.4386901855E-003
Af1(s/s):                  -0.1091393642E-010
week:                       1015
";

    #[test]
    fn yuma_records_and_their_errors() {
        let a = parse_yuma(YUMA).unwrap();
        assert_eq!(a.len(), 1);
        assert_eq!((a[0].prn, a[0].week), (3, 1015));
        assert!((a[0].sqrt_a - 5153.632324).abs() < 1e-9);
        let bad = YUMA.replace("0.867064476", "x");
        assert_eq!(parse_yuma(&bad).unwrap_err().line, 10);
        let missing = YUMA.replace("Af1(s/s):                  -0.1091393642E-010\n", "");
        let e = parse_yuma(&missing).unwrap_err();
        assert_eq!(e.line, 1);
        assert!(e.message.contains("Af1"), "{e}");
        assert!(parse_yuma("").is_err());
    }

    #[test]
    fn orbit_radius_speed_and_period() {
        let a = parse_yuma(YUMA).unwrap()[0];
        let eph = Ephemeris::from_almanac(&a, 2039, 2039, 7200, 1);
        let s = eph.state(7200.0);
        let r = s.pos_m.norm();
        let sma = a.sqrt_a * a.sqrt_a;
        assert!((r - sma).abs() < sma * a.e * 1.01, "radius {r}");
        // Inertial speed √(μ(2/r − 1/a)) (vis-viva); the ECEF velocity differs by ω_e × r, and
        // the node's regression Ω̇ moves the orbit by up to |Ω̇| r.
        let w = Vector3::new(0.0, 0.0, OMEGA_E_RAD_S);
        let v_i = (s.vel_mps + w.cross(&s.pos_m)).norm();
        let vis = (MU_M3_S2 * (2.0 / r - 1.0 / sma)).sqrt();
        assert!((v_i - vis).abs() < a.omega_dot_rad_s.abs() * r, "{v_i} vs {vis}");
        // Relativistic clock term within |F e √A| of the polynomial.
        assert!((s.clock_s - f64::from(eph.af0) * p2(-31)).abs() <= F_S_SQRT_M.abs() * a.e * a.sqrt_a + 1e-12);
    }

    #[test]
    fn an_issue_is_the_almanac_carried_forward() {
        // The same instant from the almanac's reference and from an issue a week later.
        let a = parse_yuma(YUMA).unwrap()[0];
        let at_toa = Ephemeris::from_almanac(&a, 2039, 2039, 589_824, 1);
        let later = Ephemeris::from_almanac(&a, 2039, 2040, 3600, 2);
        let t_in_2040 = 5000.0;
        let p1 = at_toa.state(WEEK_S + t_in_2040).pos_m;
        let p2 = later.state(t_in_2040).pos_m;
        // Only the quantisation of the carried elements differs (2⁻³¹ semicircles ≈ 4 cm).
        assert!((p1 - p2).norm() < 1.0, "{}", (p1 - p2).norm());
    }

    #[test]
    fn subframe_words_have_valid_parity_and_clean_ends() {
        let a = parse_yuma(YUMA).unwrap()[0];
        let eph = Ephemeris::from_almanac(&a, 2039, 2039, 7200, 9);
        let iono = KlobucharRaw::from_si(
            SkyConfig::default().klobuchar_alpha,
            SkyConfig::default().klobuchar_beta,
        );
        for id in 1..=4 {
            let w = subframe(&eph, id, 1234, &iono);
            let (mut d29, mut d30) = (0, 0);
            for (k, word) in w.iter().enumerate() {
                assert_eq!(((word >> 31) & 1, (word >> 30) & 1), (d29, d30), "word {k}");
                let data = ((word >> 6) & 0xFF_FFFF) ^ if d30 == 1 { 0xFF_FFFF } else { 0 };
                assert_eq!(lnav_parity(data, d29, d30), word & 0x3F);
                (d29, d30) = ((word >> 1) & 1, word & 1);
            }
            assert_eq!(w[9] & 3, 0, "D29 = D30 = 0 after word 10");
            assert_eq!(((w[0] >> 22) & 0xFF), 0x8B);
        }
    }

    #[test]
    fn klobuchar_is_a_few_metres_by_day() {
        let iono = KlobucharRaw::from_si(
            SkyConfig::default().klobuchar_alpha,
            SkyConfig::default().klobuchar_beta,
        );
        let (lat, lon) = (48f64.to_radians(), 11f64.to_radians());
        // 14:00 local ≈ 50 400 s at λ = 0; night is the 5 ns floor × obliquity.
        let day = iono.delay_s(lat, lon, 90f64.to_radians(), 0.0, 50_400.0 - 11.0 / 15.0 * 3600.0) * C_M_S;
        let night = iono.delay_s(lat, lon, 90f64.to_radians(), 0.0, 0.0) * C_M_S;
        assert!((2.0..20.0).contains(&day), "{day}");
        assert!((night - 1.5).abs() < 0.1, "{night}");
        let low = iono.delay_s(lat, lon, 10f64.to_radians(), 0.0, 0.0) * C_M_S;
        assert!(low > 2.5 * night, "{low}");
    }
}
