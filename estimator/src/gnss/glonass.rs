//! GLONASS L1OF immediate data (the satellite's own ephemeris) and its orbit, after the
//! GLONASS Interface Control Document, Edition 5.1 (2008): strings 1–4 of each 30 s frame
//! (§4.4, Table 4.5: fields, sign-magnitude numbers, scale factors) and the numerical
//! integration of the satellite's motion in PZ-90 (Appendix A.3.1.2: Runge–Kutta 4 of the
//! equations of motion with the Earth's J₂⁰ and rotation, the broadcast lunisolar
//! acceleration held constant). PZ-90.11 and WGS-84 differ by centimetres; this module does
//! not transform between them.
//!
//! Bytes in: the four 32-bit words u-blox puts in a GLONASS RXM-SFRBX (u-blox 8/M8 Receiver
//! Description, "GLONASS"): the 85-bit string from word 0's most significant bit (string bit
//! 85, the idle bit) onwards, and in word 3 the superframe and frame numbers. The string's
//! Hamming check bits are not verified; a string is used only with the three others of the
//! same frame and string 4's slot number equal to the satellite's.

use thiserror::Error;

/// Earth's gravitational constant in PZ-90, m³/s² (ICD Table 3.2).
const GM_M3_S2: f64 = 398_600.441_8e9;
/// PZ-90 semi-major axis, m.
const AE_M: f64 = 6_378_136.0;
/// Second zonal harmonic J₂⁰ (ICD Table 3.2: 1082625.75·10⁻⁹).
const J2: f64 = 1_082_625.75e-9;
/// Earth's rotation rate, rad/s.
const OMEGA_E_RAD_S: f64 = 7.292_115e-5;
/// Runge–Kutta step, s (the ICD's example integrates with steps of a few minutes; 60 s keeps
/// the truncation error below a millimetre over the ±15 min an ephemeris is used).
const STEP_S: f64 = 60.0;
/// GLONASS time is UTC(SU) + 3 h.
pub const MOSCOW_OFFSET_S: i64 = 3 * 3600;
/// An ephemeris is used up to this far from its t_b, s: new immediate data come every
/// 30 min with t_b in the middle of their interval (ICD §4.4); 15 min more of margin for a
/// receiver that has not yet received the next.
pub const EPHEMERIS_VALID_S: f64 = 1800.0;

/// The carrier frequency of GLONASS L1OF on channel `k` (−7…+6), Hz (the ICD's nominal
/// carrier frequencies: 1602 MHz + k·562.5 kHz).
pub fn l1of_hz(k: i8) -> f64 {
    1_602.0e6 + f64::from(k) * 562.5e3
}

/// Seconds from t_b to the instant of GPS time `gps_tow_s` (s of week) with GPS − UTC =
/// `leap_s`, within ±12 h (GLONASS time is UTC(SU) + 3 h; UTC(SU) is taken as UTC).
pub fn seconds_since_tb_gps(tb_s: f64, gps_tow_s: f64, leap_s: f64) -> f64 {
    let sod = (gps_tow_s - leap_s + MOSCOW_OFFSET_S as f64).rem_euclid(86_400.0);
    (sod - tb_s + 43_200.0).rem_euclid(86_400.0) - 43_200.0
}

/// Why a GLONASS string was not decoded.
#[derive(Debug, Error, Clone, Copy, PartialEq, Eq)]
pub enum GloError {
    /// Fewer than the 3 words that hold a string (u-blox sends 4).
    #[error("a GLONASS string needs 3 words, got {0}")]
    TooShort(usize),
    /// The idle bit (string bit 85) is not 0: not a string.
    #[error("idle bit set")]
    IdleBit,
}

/// One decoded string of the immediate data (ICD Table 4.5), SI units, PZ-90 axes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GloString {
    /// String 1: x, ẋ, ẍ and t_k.
    One {
        /// t_k: start of the frame, s of the Moscow day.
        tk_s: f64,
        /// x, ẋ, ẍ (m, m/s, m/s²).
        axis: Axis,
    },
    /// String 2: y, ẏ, ÿ, B_n and t_b.
    Two {
        /// B_n, the health word (its most significant bit set: unhealthy).
        health: u8,
        /// t_b: the instant the ephemeris refers to, s of the Moscow day (15 min steps).
        tb_s: f64,
        /// y, ẏ, ÿ.
        axis: Axis,
    },
    /// String 3: z, ż, z̈ and γ_n.
    Three {
        /// γ_n: relative frequency deviation of the satellite's carrier.
        gamma: f64,
        /// z, ż, z̈.
        axis: Axis,
    },
    /// String 4: τ_n, F_T, N_T and the slot number n.
    Four {
        /// τ_n: the satellite clock's offset from GLONASS time, s.
        tau_s: f64,
        /// F_T: the index of the predicted user range accuracy (ICD Table 4.4).
        accuracy_index: u8,
        /// E_n: age of the immediate data, days.
        age_days: u8,
        /// N_T: day within the four-year interval (1 = 1 January of the leap year).
        day_in_interval: u16,
        /// n: the transmitting satellite's slot (1–24).
        slot: u8,
    },
    /// Strings 5–15 (almanac, time scales), not decoded here.
    Other(u8),
}

/// One coordinate of the state vector, SI units.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Axis {
    /// Position, m.
    pub pos_m: f64,
    /// Velocity, m/s.
    pub vel_mps: f64,
    /// Lunisolar acceleration, m/s².
    pub acc_mps2: f64,
}

/// Bit `b` … `b − n + 1` of the string (ICD numbering, 85 = the idle bit, first sent) as an
/// unsigned number.
fn bits(words: &[u32], b: u32, n: u32) -> u64 {
    let mut v = 0u64;
    for k in 0..n {
        let offset = (85 - (b - k)) as usize;
        let bit = (words[offset / 32] >> (31 - offset % 32)) & 1;
        v = (v << 1) | u64::from(bit);
    }
    v
}

/// Sign-magnitude (ICD §4.4: the most significant bit is the sign, 1 = negative).
fn signed(words: &[u32], b: u32, n: u32) -> f64 {
    let v = bits(words, b, n);
    let magnitude = (v & ((1 << (n - 1)) - 1)) as f64;
    if v >> (n - 1) == 1 { -magnitude } else { magnitude }
}

/// x, ẋ, ẍ of strings 1–3: ẋ bits 64–41 (2⁻²⁰ km/s), ẍ 40–36 (2⁻³⁰ km/s²), x 35–9 (2⁻¹¹ km).
fn axis(w: &[u32]) -> Axis {
    Axis {
        vel_mps: signed(w, 64, 24) * 2f64.powi(-20) * 1e3,
        acc_mps2: signed(w, 40, 5) * 2f64.powi(-30) * 1e3,
        pos_m: signed(w, 35, 27) * 2f64.powi(-11) * 1e3,
    }
}

/// Decodes one string from the words of a u-blox RXM-SFRBX (string number m in bits 84–81).
pub fn decode_string(words: &[u32]) -> Result<GloString, GloError> {
    if words.len() < 3 {
        return Err(GloError::TooShort(words.len()));
    }
    if bits(words, 85, 1) != 0 {
        return Err(GloError::IdleBit);
    }
    Ok(match bits(words, 84, 4) {
        1 => GloString::One {
            // t_k: hours (5 bits), minutes (6), 30 s (1), bits 76–65.
            tk_s: (bits(words, 76, 5) * 3600 + bits(words, 71, 6) * 60 + bits(words, 65, 1) * 30) as f64,
            axis: axis(words),
        },
        2 => GloString::Two {
            health: bits(words, 80, 3) as u8,
            tb_s: (bits(words, 76, 7) * 900) as f64,
            axis: axis(words),
        },
        3 => GloString::Three {
            gamma: signed(words, 79, 11) * 2f64.powi(-40),
            axis: axis(words),
        },
        4 => GloString::Four {
            tau_s: signed(words, 80, 22) * 2f64.powi(-30),
            accuracy_index: bits(words, 33, 4) as u8,
            age_days: bits(words, 53, 5) as u8,
            day_in_interval: bits(words, 26, 11) as u16,
            slot: bits(words, 15, 5) as u8,
        },
        m => GloString::Other(m as u8),
    })
}

/// A satellite's immediate data: its state at t_b in PZ-90 and its clock.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GloEphemeris {
    /// Slot n, 1–24.
    pub slot: u8,
    /// t_b, s of the Moscow day.
    pub tb_s: f64,
    /// Position at t_b, PZ-90 (ECEF), m.
    pub pos_m: [f64; 3],
    /// Velocity at t_b, PZ-90, m/s.
    pub vel_mps: [f64; 3],
    /// Lunisolar acceleration, PZ-90, m/s² (held constant).
    pub acc_mps2: [f64; 3],
    /// γ_n.
    pub gamma: f64,
    /// τ_n, s.
    pub tau_s: f64,
    /// B_n (most significant bit set: unhealthy).
    pub health: u8,
    /// N_T: day within the four-year interval.
    pub day_in_interval: u16,
    /// F_T: index of the predicted user range accuracy (ICD Table 4.4).
    pub accuracy_index: u8,
    /// E_n: age of the immediate data, days.
    pub age_days: u8,
    /// t_k: start of the frame that carried it, s of the Moscow day.
    pub tk_s: f64,
}

impl GloEphemeris {
    /// Whether the satellite is usable: B_n's most significant bit, the only one the user
    /// checks (ICD §4.4, Table 4.5), is 0.
    pub fn healthy(&self) -> bool {
        self.health & 0b100 == 0
    }

    /// The predicted user range accuracy F_T, 1σ, m (ICD Table 4.4; `None` for index 15,
    /// not used).
    pub fn accuracy_m(&self) -> Option<f64> {
        const F_T_M: [f64; 15] = [
            1.0, 2.0, 2.5, 4.0, 5.0, 7.0, 10.0, 12.0, 14.0, 16.0, 32.0, 64.0, 128.0, 256.0, 512.0,
        ];
        F_T_M.get(usize::from(self.accuracy_index)).copied()
    }

    /// The satellite clock's offset from GLONASS time `dt_s` seconds after t_b, s: the
    /// satellite's time runs ahead by −τ_n + γ_n·(t − t_b) (ICD §4.4, τ_n and γ_n:
    /// t = t_k + τ_n(t_b) − γ_n(t_b)·(t_k − t_b)); relativity is in τ_n and γ_n, and no
    /// group delay applies to L1 (τ_n is L1's).
    pub fn clock_offset_s(&self, dt_s: f64) -> f64 {
        -self.tau_s + self.gamma * dt_s
    }

    /// Position and velocity (PZ-90, m and m/s) at `dt_s` seconds after t_b: Runge–Kutta 4
    /// of ICD Appendix A.3.1.2 in steps of at most 60 s.
    pub fn state_at(&self, dt_s: f64) -> ([f64; 3], [f64; 3]) {
        let mut s = [
            self.pos_m[0],
            self.pos_m[1],
            self.pos_m[2],
            self.vel_mps[0],
            self.vel_mps[1],
            self.vel_mps[2],
        ];
        let steps = (dt_s.abs() / STEP_S).ceil().max(1.0);
        let h = dt_s / steps;
        for _ in 0..steps as usize {
            let k1 = self.derivative(&s);
            let k2 = self.derivative(&add(&s, &k1, h / 2.0));
            let k3 = self.derivative(&add(&s, &k2, h / 2.0));
            let k4 = self.derivative(&add(&s, &k3, h));
            for i in 0..6 {
                s[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
        ([s[0], s[1], s[2]], [s[3], s[4], s[5]])
    }

    /// ICD A.3.1.2: ẍ = −GM x/r³ − 3/2 J₂ GM a_e² x/r⁵ (1 − 5z²/r²) + ω² x + 2ω ẏ + ẍ_ls,
    /// ÿ likewise with −2ω ẋ, z̈ = −GM z/r³ − 3/2 J₂ GM a_e² z/r⁵ (3 − 5z²/r²) + z̈_ls.
    fn derivative(&self, s: &[f64; 6]) -> [f64; 6] {
        let (x, y, z) = (s[0], s[1], s[2]);
        let r2 = x * x + y * y + z * z;
        let r = r2.sqrt();
        let gm_r3 = GM_M3_S2 / (r2 * r);
        let j = 1.5 * J2 * GM_M3_S2 * AE_M * AE_M / (r2 * r2 * r);
        let z2 = 5.0 * z * z / r2;
        let w2 = OMEGA_E_RAD_S * OMEGA_E_RAD_S;
        [
            s[3],
            s[4],
            s[5],
            -gm_r3 * x - j * x * (1.0 - z2) + w2 * x + 2.0 * OMEGA_E_RAD_S * s[4] + self.acc_mps2[0],
            -gm_r3 * y - j * y * (1.0 - z2) + w2 * y - 2.0 * OMEGA_E_RAD_S * s[3] + self.acc_mps2[1],
            -gm_r3 * z - j * z * (3.0 - z2) + self.acc_mps2[2],
        ]
    }
}

fn add(s: &[f64; 6], k: &[f64; 6], h: f64) -> [f64; 6] {
    std::array::from_fn(|i| s[i] + h * k[i])
}

/// Strings 1–4 of a frame carrying `e` (the inverse of [`decode_string`]: each field rounded
/// to its scale factor, sign-magnitude, ICD Table 4.5; t_k to its 30 s) with `frame` in word
/// 3, as u-blox delivers them (unused bits and Hamming bits zero). `None` when a value does
/// not fit its field.
pub fn encode_strings(e: &GloEphemeris, frame: u32) -> Option<[[u32; 4]; 4]> {
    fn put(w: &mut [u32; 4], b: u32, n: u32, v: u64) {
        for k in 0..n {
            if (v >> (n - 1 - k)) & 1 == 1 {
                let offset = (85 - (b - k)) as usize;
                w[offset / 32] |= 1 << (31 - offset % 32);
            }
        }
    }
    fn unsigned(value: f64, n: u32) -> Option<u64> {
        let v = value.round();
        (v >= 0.0 && v < 2f64.powi(n as i32)).then_some(v as u64)
    }
    fn signed(value: f64, lsb: f64, n: u32) -> Option<u64> {
        let v = (value / lsb).round();
        let magnitude = unsigned(v.abs(), n - 1)?;
        Some(if v < 0.0 { (1 << (n - 1)) | magnitude } else { magnitude })
    }
    let mut s = [[0u32; 4]; 4];
    for (i, w) in s.iter_mut().enumerate() {
        put(w, 84, 4, i as u64 + 1);
        w[3] = frame;
    }
    for (i, w) in s.iter_mut().take(3).enumerate() {
        put(w, 64, 24, signed(e.vel_mps[i], 2f64.powi(-20) * 1e3, 24)?);
        put(w, 40, 5, signed(e.acc_mps2[i], 2f64.powi(-30) * 1e3, 5)?);
        put(w, 35, 27, signed(e.pos_m[i], 2f64.powi(-11) * 1e3, 27)?);
    }
    let tk = unsigned((e.tk_s / 30.0).floor(), 12)?;
    put(&mut s[0], 76, 5, (tk / 120) % 24);
    put(&mut s[0], 71, 6, (tk / 2) % 60);
    put(&mut s[0], 65, 1, tk % 2);
    put(&mut s[1], 80, 3, u64::from(e.health & 7));
    put(&mut s[1], 76, 7, unsigned(e.tb_s / 900.0, 7)?);
    put(&mut s[2], 79, 11, signed(e.gamma, 2f64.powi(-40), 11)?);
    put(&mut s[3], 80, 22, signed(e.tau_s, 2f64.powi(-30), 22)?);
    put(&mut s[3], 53, 5, u64::from(e.age_days & 31));
    put(&mut s[3], 33, 4, u64::from(e.accuracy_index & 15));
    put(&mut s[3], 26, 11, u64::from(e.day_in_interval & 0x7FF));
    put(&mut s[3], 15, 5, u64::from(e.slot & 31));
    Some(s)
}

/// Seconds from t_b to the instant at UTC `utc_ns`, within ±12 h (t_b is a time of the
/// Moscow day).
pub fn seconds_since_tb(tb_s: f64, utc_ns: i64) -> f64 {
    let sod = (utc_ns.div_euclid(1_000_000_000) + MOSCOW_OFFSET_S).rem_euclid(86_400) as f64
        + utc_ns.rem_euclid(1_000_000_000) as f64 * 1e-9;
    (sod - tb_s + 43_200.0).rem_euclid(86_400.0) - 43_200.0
}

/// Counters of the assembly.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct GloCounters {
    /// Strings that did not decode.
    pub bad_strings: u64,
    /// Sets of strings 1–4 dropped: a string of another frame, out of order, or string 4
    /// naming another slot.
    pub inconsistent: u64,
    /// Ephemerides completed.
    pub ephemerides: u64,
}

/// The latest complete immediate data per slot, from strings 1–4 of one frame.
#[derive(Debug, Clone, Default)]
pub struct GloStore {
    partial: [Option<(u32, u8, GloEphemeris)>; 25],
    latest: [Option<GloEphemeris>; 25],
    /// What went in and what was dropped.
    pub counters: GloCounters,
}

impl GloStore {
    /// Feeds one RXM-SFRBX of slot `slot` (u-blox svId; its words, word 3 the frame id).
    pub fn on_words(&mut self, slot: u8, words: &[u32]) {
        let idx = usize::from(slot);
        if !(1..=24).contains(&idx) {
            self.counters.bad_strings += 1;
            return;
        }
        let frame = words.get(3).copied().unwrap_or(0);
        let s = match decode_string(words) {
            Ok(s) => s,
            Err(_) => {
                self.counters.bad_strings += 1;
                return;
            }
        };
        let next = match (s, self.partial[idx].take()) {
            (GloString::One { axis, tk_s }, _) => {
                let mut e = GloEphemeris {
                    slot,
                    tk_s,
                    ..GloEphemeris::default()
                };
                set_axis(&mut e, 0, &axis);
                Some((frame, 1, e))
            }
            (GloString::Two { health, tb_s, axis }, Some((f, 1, mut e))) if f == frame => {
                e.health = health;
                e.tb_s = tb_s;
                set_axis(&mut e, 1, &axis);
                Some((f, 2, e))
            }
            (GloString::Three { gamma, axis }, Some((f, 2, mut e))) if f == frame => {
                e.gamma = gamma;
                set_axis(&mut e, 2, &axis);
                Some((f, 3, e))
            }
            (
                GloString::Four {
                    tau_s,
                    accuracy_index,
                    age_days,
                    day_in_interval,
                    slot: n,
                },
                Some((f, 3, mut e)),
            ) if f == frame && n == slot => {
                e.tau_s = tau_s;
                e.day_in_interval = day_in_interval;
                e.accuracy_index = accuracy_index;
                e.age_days = age_days;
                self.latest[idx] = Some(e);
                self.counters.ephemerides += 1;
                None
            }
            (GloString::Other(_), p) => p,
            (_, Some(_)) | (GloString::Two { .. } | GloString::Three { .. } | GloString::Four { .. }, None) => {
                self.counters.inconsistent += 1;
                None
            }
        };
        self.partial[idx] = next;
    }

    /// The latest complete immediate data of `slot`.
    pub fn ephemeris(&self, slot: u8) -> Option<&GloEphemeris> {
        self.latest.get(usize::from(slot))?.as_ref()
    }
}

fn set_axis(e: &mut GloEphemeris, i: usize, a: &Axis) {
    e.pos_m[i] = a.pos_m;
    e.vel_mps[i] = a.vel_mps;
    e.acc_mps2[i] = a.acc_mps2;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Words carrying `fields` (string bit, width, value) in a string numbered `m`.
    fn words(m: u64, fields: &[(u32, u32, u64)]) -> [u32; 4] {
        let mut w = [0u32; 4];
        let mut put = |b: u32, n: u32, v: u64| {
            for k in 0..n {
                if (v >> (n - 1 - k)) & 1 == 1 {
                    let offset = (85 - (b - k)) as usize;
                    w[offset / 32] |= 1 << (31 - offset % 32);
                }
            }
        };
        put(84, 4, m);
        for &(b, n, v) in fields {
            put(b, n, v);
        }
        w[3] = 0x086d_0001;
        w
    }

    #[test]
    fn fields_are_sign_magnitude_at_their_bits() {
        // x = −(2¹⁰ + 5)·2⁻¹¹ km, ẋ = 3·2⁻²⁰ km/s, ẍ = −1·2⁻³⁰ km/s², t_k = 17 h 57 min 30 s.
        let w = words(
            1,
            &[
                (76, 5, 17),
                (71, 6, 57),
                (65, 1, 1),
                (64, 24, 3),
                (40, 5, 0b10001),
                (35, 27, (1 << 26) | 1029),
            ],
        );
        let GloString::One { tk_s, axis } = decode_string(&w).unwrap() else {
            panic!()
        };
        assert_eq!(tk_s, 17.0 * 3600.0 + 57.0 * 60.0 + 30.0);
        assert_eq!(axis.pos_m, -1029.0 * 2f64.powi(-11) * 1e3);
        assert_eq!(axis.vel_mps, 3.0 * 2f64.powi(-20) * 1e3);
        assert_eq!(axis.acc_mps2, -(2f64.powi(-30)) * 1e3);
        let w = words(4, &[(80, 22, (1 << 21) | 7), (33, 4, 6), (26, 11, 1275), (15, 5, 3)]);
        assert_eq!(
            decode_string(&w).unwrap(),
            GloString::Four {
                tau_s: -7.0 * 2f64.powi(-30),
                accuracy_index: 6,
                age_days: 0,
                day_in_interval: 1275,
                slot: 3
            }
        );
        let mut bad = w;
        bad[0] |= 1 << 31;
        assert_eq!(decode_string(&bad), Err(GloError::IdleBit));
        assert_eq!(decode_string(&w[..2]), Err(GloError::TooShort(2)));
    }

    #[test]
    fn strings_one_to_four_of_one_frame_make_an_ephemeris() {
        let mut st = GloStore::default();
        let s = [
            words(1, &[(35, 27, 1000)]),
            words(2, &[(76, 7, 71), (35, 27, 2000)]),
            words(3, &[(35, 27, 3000)]),
            words(4, &[(15, 5, 3)]),
        ];
        for w in &s {
            st.on_words(3, w);
        }
        let e = st.ephemeris(3).unwrap();
        assert_eq!(e.tb_s, 71.0 * 900.0);
        assert_eq!(e.pos_m[1], 2000.0 * 2f64.powi(-11) * 1e3);
        // String 4 naming another slot, or a string of another frame: dropped.
        let mut st = GloStore::default();
        for w in &s {
            st.on_words(5, w);
        }
        assert!(st.ephemeris(5).is_none());
        let mut other = s[2];
        other[3] += 1;
        let mut st2 = GloStore::default();
        for w in [&s[0], &s[1], &other, &s[3]] {
            st2.on_words(3, w);
        }
        assert!(st2.ephemeris(3).is_none());
        assert_eq!(st.counters.inconsistent + st2.counters.inconsistent, 3);
        // Slot 0 or 25: counted, no panic.
        st.on_words(0, &s[0]);
        st.on_words(25, &s[0]);
        assert_eq!(st.counters.bad_strings, 2);
    }

    /// Encoded strings decode to the same immediate data (values on their scale factors).
    #[test]
    fn encoded_strings_decode_to_the_same_ephemeris() {
        let e = GloEphemeris {
            slot: 11,
            tb_s: 71.0 * 900.0,
            pos_m: [-1029.0 * 2f64.powi(-11) * 1e3, 12_345_678.0 * 2f64.powi(-11) * 1e3, 0.0],
            vel_mps: [3.0 * 2f64.powi(-20) * 1e3, -2_000_000.0 * 2f64.powi(-20) * 1e3, 0.0],
            acc_mps2: [-(2f64.powi(-30)) * 1e3, 0.0, 9.0 * 2f64.powi(-30) * 1e3],
            gamma: -3.0 * 2f64.powi(-40),
            tau_s: 12_345.0 * 2f64.powi(-30),
            health: 0,
            day_in_interval: 1275,
            accuracy_index: 6,
            age_days: 3,
            tk_s: 17.0 * 3600.0 + 57.0 * 60.0 + 30.0,
        };
        let s = encode_strings(&e, 0x086d_0001).unwrap();
        let mut st = GloStore::default();
        for w in &s {
            st.on_words(11, w);
        }
        assert_eq!(st.ephemeris(11), Some(&e));
        let GloString::One { tk_s, .. } = decode_string(&s[0]).unwrap() else {
            panic!()
        };
        assert_eq!(tk_s, 17.0 * 3600.0 + 57.0 * 60.0 + 30.0);
        // A position beyond 27 bits of 2⁻¹¹ km does not fit.
        let far = GloEphemeris {
            pos_m: [7.0e7, 0.0, 0.0],
            ..e
        };
        assert!(encode_strings(&far, 0).is_none());
    }

    #[test]
    fn the_integration_keeps_a_circular_orbit_and_returns_to_its_start() {
        // A GLONASS-like orbit: radius 25 510 km, inclined 64.8°, circular speed in the
        // rotating frame (inertial velocity minus ω × r).
        let r = 25_510e3;
        let v = (GM_M3_S2 / r).sqrt();
        let inc = 64.8f64.to_radians();
        let e = GloEphemeris {
            pos_m: [r, 0.0, 0.0],
            vel_mps: [0.0, v * inc.cos() - OMEGA_E_RAD_S * r, v * inc.sin()],
            ..GloEphemeris::default()
        };
        let (p, _) = e.state_at(900.0);
        let radius = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        // J₂ perturbs the radius by a few km at most in 15 min.
        assert!((radius - r).abs() < 5e3, "{}", radius - r);
        let (p2, v2) = e.state_at(900.0);
        let back = GloEphemeris {
            pos_m: p2,
            vel_mps: v2,
            ..e
        };
        let (p0, _) = back.state_at(-900.0);
        for (i, (a, b)) in p0.iter().zip(e.pos_m).enumerate() {
            assert!((a - b).abs() < 1e-3, "{i}: {}", a - b);
        }
    }

    #[test]
    fn time_since_tb_wraps_around_the_moscow_day() {
        // 2023-06-28 14:57:10 UTC = 17:57:10 Moscow; t_b = 71·15 min = 17:45.
        let utc = 1_687_964_230_000_000_000;
        assert_eq!(seconds_since_tb(71.0 * 900.0, utc), 730.0);
        // 23:50 Moscow with t_b = 00:00 of the next day: −600 s.
        let utc = 1_687_964_230_000_000_000 + (5 * 3600 + 52 * 60 + 50) * 1_000_000_000;
        assert_eq!(seconds_since_tb(0.0, utc), -600.0);
    }
}
