//! Satellite position and clock from a broadcast Keplerian ephemeris or almanac: GPS
//! (IS-GPS-200N §20.3.3.4.3, Table 20-IV "Elements of Coordinate Systems"; §20.3.3.5.2.1,
//! Table 20-VI for the almanac; §20.3.3.3.3.1 for the clock with the relativistic term and
//! T_GD), and with their own constants (an [`OrbitFrame`]) Galileo (OS SIS ICD issue 2.x
//! §5.1.1, Table 59) and BeiDou (BDS-SIS-ICD-B1I v3.0 §5.2.4.12, Table 5-11, CGCS2000, with the
//! GEO satellites' extra rotation). Positions are ECEF in m at the given time of transmission,
//! seconds of week in the system's own time (GPST, GST, BDT = GPST − 14 s); the Earth's
//! rotation during the signal's travel (Sagnac) is the user's, who knows the receiver.

use super::lnav::{Almanac, Ephem1, Ephem2, Ephem3};

/// WGS-84 value of the Earth's gravitational constant for GPS, m³/s² (IS-GPS-200 Table 20-IV).
pub const MU_M3_S2: f64 = 3.986005e14;
/// WGS-84 Earth rotation rate, rad/s (IS-GPS-200 Table 20-IV).
pub const OMEGA_E_RAD_S: f64 = 7.292_115_146_7e-5;
/// π as IS-GPS-200 defines it for the semicircle conversions (deliberately this truncated
/// value, which the control segment's fit uses, not `core::f64::consts::PI`).
#[allow(clippy::approx_constant)]
pub const GPS_PI: f64 = 3.141_592_653_589_8;
/// Relativistic constant F = −2√μ/c², s/√m (IS-GPS-200 §20.3.3.3.3.1).
pub const F_S_SQRT_M: f64 = -4.442_807_633e-10;
/// Speed of light, m/s (the relativistic constant of the other systems is computed from it).
const C_M_S: f64 = 299_792_458.0;
/// Galileo's and BeiDou's (CGCS2000) gravitational constant, m³/s² (Galileo OS SIS ICD
/// Table 59; BDS-SIS-ICD-B1I Table 5-11).
pub const MU_GAL_BDS_M3_S2: f64 = 3.986_004_418e14;
/// CGCS2000 Earth rotation rate, rad/s (BDS-SIS-ICD-B1I Table 5-11); Galileo uses GPS's value.
pub const OMEGA_E_BDS_RAD_S: f64 = 7.292_115_0e-5;

/// Which system's constants and formulas an [`Orbit`] follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum OrbitFrame {
    /// GPS (WGS-84, IS-GPS-200).
    #[default]
    Gps,
    /// Galileo (GTRF; μ = 3.986004418e14 m³/s², Ω̇e as GPS).
    Galileo,
    /// BeiDou MEO/IGSO (CGCS2000: μ = 3.986004418e14 m³/s², Ω̇e = 7.2921150e-5 rad/s).
    BeiDou,
    /// BeiDou GEO: CGCS2000, the orbit computed in an inertial-like frame and rotated by −5°
    /// about x and Ω̇e·t_k about z (BDS-SIS-ICD-B1I §5.2.4.12).
    BeiDouGeo,
}

impl OrbitFrame {
    /// Gravitational constant, m³/s².
    pub fn mu_m3_s2(self) -> f64 {
        match self {
            Self::Gps => MU_M3_S2,
            _ => MU_GAL_BDS_M3_S2,
        }
    }

    /// Earth rotation rate, rad/s.
    pub fn omega_e_rad_s(self) -> f64 {
        match self {
            Self::Gps | Self::Galileo => OMEGA_E_RAD_S,
            Self::BeiDou | Self::BeiDouGeo => OMEGA_E_BDS_RAD_S,
        }
    }

    /// Relativistic constant F = −2√μ/c², s/√m (GPS: IS-GPS-200's rounded value).
    pub fn f_s_sqrt_m(self) -> f64 {
        match self {
            Self::Gps => F_S_SQRT_M,
            _ => -2.0 * self.mu_m3_s2().sqrt() / (C_M_S * C_M_S),
        }
    }
}

/// Half a GPS week, s: time differences are wrapped into ±this.
const HALF_WEEK_S: f64 = 302_400.0;

/// A satellite's broadcast orbit and clock in physical units (angles in rad).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Orbit {
    /// Reference time of the orbit (t_oe, or t_oa for an almanac), s of week.
    pub toe_s: f64,
    /// √A, √m.
    pub sqrt_a: f64,
    /// Eccentricity.
    pub e: f64,
    /// Inclination at t_oe, rad.
    pub i0_rad: f64,
    /// Rate of inclination, rad/s.
    pub idot_rad_s: f64,
    /// Longitude of the ascending node at the week's start, rad.
    pub omega0_rad: f64,
    /// Rate of right ascension, rad/s.
    pub omega_dot_rad_s: f64,
    /// Argument of perigee, rad.
    pub omega_rad: f64,
    /// Mean anomaly at t_oe, rad.
    pub m0_rad: f64,
    /// Mean motion correction, rad/s.
    pub delta_n_rad_s: f64,
    /// Rate of the semi-major axis, m/s (GPS CNAV's Ȧ, IS-GPS-200 Table 30-II: A_k = A_0 +
    /// Ȧ·t_k, with A_0 = `sqrt_a`²; 0 for the other ephemerides).
    pub a_dot_m_s: f64,
    /// Rate of the mean motion correction, rad/s² (GPS CNAV's Δṅ_0: Δn_A = Δn_0 + ½Δṅ_0·t_k;
    /// 0 for the other ephemerides).
    pub delta_n_dot_rad_s2: f64,
    /// Harmonic corrections: C_uc, C_us (rad), C_rc, C_rs (m), C_ic, C_is (rad).
    pub cuc: f64,
    /// See `cuc`.
    pub cus: f64,
    /// See `cuc`.
    pub crc: f64,
    /// See `cuc`.
    pub crs: f64,
    /// See `cuc`.
    pub cic: f64,
    /// See `cuc`.
    pub cis: f64,
    /// Clock reference time t_oc, s of week.
    pub toc_s: f64,
    /// Clock polynomial a_f0 (s), a_f1 (s/s), a_f2 (s/s²).
    pub af: [f64; 3],
    /// Group delay subtracted from the clock for the signal used, s (GPS: T_GD for L1 C/A;
    /// Galileo I/NAV: BGD(E1,E5b) for E1; BeiDou: T_GD1 for B1I; 0 for an almanac).
    pub tgd_s: f64,
    /// The system's constants and formulas.
    pub frame: OrbitFrame,
}

fn p2(n: i32) -> f64 {
    2f64.powi(n)
}

impl Orbit {
    /// The ephemeris of subframes 1–3 (scale factors of IS-GPS-200 Tables 20-I and 20-III).
    /// The caller pairs subframes of one issue (IODC's 8 LSBs = IODE of 2 and 3).
    pub fn from_ephemeris(s1: &Ephem1, s2: &Ephem2, s3: &Ephem3) -> Self {
        let sc = GPS_PI;
        Self {
            toe_s: f64::from(s2.toe) * 16.0,
            sqrt_a: f64::from(s2.sqrt_a) * p2(-19),
            e: f64::from(s2.e) * p2(-33),
            i0_rad: f64::from(s3.i0) * p2(-31) * sc,
            idot_rad_s: f64::from(s3.idot) * p2(-43) * sc,
            omega0_rad: f64::from(s3.omega0) * p2(-31) * sc,
            omega_dot_rad_s: f64::from(s3.omega_dot) * p2(-43) * sc,
            omega_rad: f64::from(s3.omega) * p2(-31) * sc,
            m0_rad: f64::from(s2.m0) * p2(-31) * sc,
            delta_n_rad_s: f64::from(s2.delta_n) * p2(-43) * sc,
            a_dot_m_s: 0.0,
            delta_n_dot_rad_s2: 0.0,
            cuc: f64::from(s2.cuc) * p2(-29),
            cus: f64::from(s2.cus) * p2(-29),
            crc: f64::from(s3.crc) * p2(-5),
            crs: f64::from(s2.crs) * p2(-5),
            cic: f64::from(s3.cic) * p2(-29),
            cis: f64::from(s3.cis) * p2(-29),
            toc_s: f64::from(s1.toc) * 16.0,
            af: [
                f64::from(s1.af0) * p2(-31),
                f64::from(s1.af1) * p2(-43),
                f64::from(s1.af2) * p2(-55),
            ],
            tgd_s: f64::from(s1.tgd) * p2(-31),
            frame: OrbitFrame::Gps,
        }
    }

    /// An almanac page (IS-GPS-200 Table 20-VI): a Keplerian orbit without harmonic
    /// corrections, inclination 0.30 semicircles + δ_i.
    pub fn from_almanac(a: &Almanac) -> Self {
        let sc = GPS_PI;
        let toa = f64::from(a.toa) * 4096.0;
        Self {
            toe_s: toa,
            sqrt_a: f64::from(a.sqrt_a) * p2(-11),
            e: f64::from(a.e) * p2(-21),
            i0_rad: (0.30 + f64::from(a.delta_i) * p2(-19)) * sc,
            omega0_rad: f64::from(a.omega0) * p2(-23) * sc,
            omega_dot_rad_s: f64::from(a.omega_dot) * p2(-38) * sc,
            omega_rad: f64::from(a.omega) * p2(-23) * sc,
            m0_rad: f64::from(a.m0) * p2(-23) * sc,
            toc_s: toa,
            af: [f64::from(a.af0) * p2(-20), f64::from(a.af1) * p2(-38), 0.0],
            ..Self::default()
        }
    }

    /// Eccentric anomaly (rad) at GPS time `t_s` (s of week), by fixed-point iteration of
    /// Kepler's equation M = E − e·sin E.
    fn eccentric_anomaly(&self, t_s: f64) -> (f64, f64) {
        self.eccentric_anomaly_tk(wrap(t_s - self.toe_s))
    }

    fn eccentric_anomaly_tk(&self, tk: f64) -> (f64, f64) {
        let a = self.sqrt_a * self.sqrt_a;
        let delta_n = self.delta_n_rad_s + 0.5 * self.delta_n_dot_rad_s2 * tk;
        let n = (self.frame.mu_m3_s2() / (a * a * a)).sqrt() + delta_n;
        let m = self.m0_rad + n * tk;
        let mut e_anom = m;
        for _ in 0..30 {
            let next = m + self.e * e_anom.sin();
            if (next - e_anom).abs() < 1e-15 {
                e_anom = next;
                break;
            }
            e_anom = next;
        }
        (e_anom, tk)
    }

    /// Satellite position, ECEF at the time of transmission `t_s` (s of week in the system's
    /// time), m (IS-GPS-200 Table 20-IV; BDS-SIS-ICD-B1I §5.2.4.12 for a GEO).
    pub fn position_ecef_m(&self, t_s: f64) -> [f64; 3] {
        self.position_ecef_m_tk(wrap(t_s - self.toe_s))
    }

    /// Like [`position_ecef_m`](Self::position_ecef_m) at `tk_s` seconds from the orbit's
    /// reference time, not wrapped to a week (an almanac used weeks away from its t_oa).
    pub fn position_ecef_m_tk(&self, tk_s: f64) -> [f64; 3] {
        let (ek, tk) = self.eccentric_anomaly_tk(tk_s);
        let a = self.sqrt_a * self.sqrt_a + self.a_dot_m_s * tk;
        let nu = ((1.0 - self.e * self.e).sqrt() * ek.sin()).atan2(ek.cos() - self.e);
        let phi = nu + self.omega_rad;
        let (s2, c2) = (2.0 * phi).sin_cos();
        let u = phi + self.cus * s2 + self.cuc * c2;
        let r = a * (1.0 - self.e * ek.cos()) + self.crs * s2 + self.crc * c2;
        let i = self.i0_rad + self.cis * s2 + self.cic * c2 + self.idot_rad_s * tk;
        let (xp, yp) = (r * u.cos(), r * u.sin());
        let we = self.frame.omega_e_rad_s();
        // A GEO's node has no Earth-rotation term over t_k: that rotation comes after.
        let geo = self.frame == OrbitFrame::BeiDouGeo;
        let node_rate = if geo {
            self.omega_dot_rad_s
        } else {
            self.omega_dot_rad_s - we
        };
        let om = self.omega0_rad + node_rate * tk - we * self.toe_s;
        let (so, co) = om.sin_cos();
        let (si, ci) = i.sin_cos();
        let p = [xp * co - yp * ci * so, xp * so + yp * ci * co, yp * si];
        if !geo {
            return p;
        }
        // BDS-SIS-ICD-B1I §5.2.4.12: R_Z(Ω̇e·t_k)·R_X(−5°)·p, with
        // R_X(φ) = [1 0 0; 0 cos φ sin φ; 0 −sin φ cos φ] and
        // R_Z(φ) = [cos φ sin φ 0; −sin φ cos φ 0; 0 0 1].
        let (sx, cx) = (-5f64).to_radians().sin_cos();
        let q = [p[0], cx * p[1] + sx * p[2], -sx * p[1] + cx * p[2]];
        let (sz, cz) = (we * tk).sin_cos();
        [cz * q[0] + sz * q[1], -sz * q[0] + cz * q[1], q[2]]
    }

    /// Satellite velocity, ECEF, m/s: the central difference of [`position_ecef_m`] over
    /// ±0.5 s (the orbit's curvature makes that exact to ~0.1 mm/s).
    ///
    /// [`position_ecef_m`]: Self::position_ecef_m
    pub fn velocity_ecef_mps(&self, t_s: f64) -> [f64; 3] {
        let (a, b) = (self.position_ecef_m(t_s + 0.5), self.position_ecef_m(t_s - 0.5));
        [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
    }

    /// Satellite clock drift at `t_s`, s/s (the derivative of the polynomial).
    pub fn clock_drift(&self, t_s: f64) -> f64 {
        self.af[1] + 2.0 * self.af[2] * wrap(t_s - self.toc_s)
    }

    /// Satellite clock offset at `t_s` (s of week in the system's time), s: the polynomial,
    /// the relativistic term F·e·√A·sin E_k and −[`tgd_s`](Self::tgd_s) (IS-GPS-200
    /// §20.3.3.3.3.1–2; Galileo OS SIS ICD §5.1.4–5.1.5; BDS-SIS-ICD-B1I §5.2.4.9–10).
    pub fn clock_offset_s(&self, t_s: f64) -> f64 {
        let dt = wrap(t_s - self.toc_s);
        let (ek, _) = self.eccentric_anomaly(t_s);
        let rel = self.frame.f_s_sqrt_m() * self.e * self.sqrt_a * ek.sin();
        self.af[0] + self.af[1] * dt + self.af[2] * dt * dt + rel - self.tgd_s
    }
}

/// A time difference wrapped into ±half a week (IS-GPS-200 Table 20-IV, t_k).
fn wrap(dt: f64) -> f64 {
    if dt > HALF_WEEK_S {
        dt - 2.0 * HALF_WEEK_S
    } else if dt < -HALF_WEEK_S {
        dt + 2.0 * HALF_WEEK_S
    } else {
        dt
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_circular_orbit_keeps_its_radius_and_period() {
        // e = 0, no corrections: |r| = A at any time, and the satellite returns after 2π/n.
        let o = Orbit {
            sqrt_a: 5153.7,
            i0_rad: 0.3 * GPS_PI,
            ..Orbit::default()
        };
        let a = 5153.7f64 * 5153.7;
        let period = 2.0 * std::f64::consts::PI / (MU_M3_S2 / (a * a * a)).sqrt();
        for t in [0.0, 1000.0, 20_000.0] {
            let p = o.position_ecef_m(t);
            let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            assert!((r - a).abs() < 1e-6, "r {r} vs A {a}");
        }
        // In the orbital plane the angle advances by 2π per period; ECEF adds the Earth's
        // rotation over the period, which the node's term −Ω̇e·t_k undoes.
        let (p0, p1) = (o.position_ecef_m(100.0), o.position_ecef_m(100.0 + period));
        let z_diff = (p0[2] - p1[2]).abs();
        assert!(z_diff < 1e-3, "z after one period differs by {z_diff} m");
        assert_eq!(wrap(400_000.0), 400_000.0 - 604_800.0);
    }
}

/// Checks shared by the decoders' tests against RTKLIB's RINEX navigation records.
#[cfg(test)]
pub(crate) mod rinex_check {
    use super::Orbit;

    /// `a` equals `b` as RINEX prints it: within half a unit of its 12th significant digit.
    pub fn rinex_eq(a: f64, b: f64) -> bool {
        if b == 0.0 {
            return a == 0.0;
        }
        (a - b).abs() <= 0.5 * 10f64.powf(b.abs().log10().floor() + 1.0 - 12.0)
    }

    /// Asserts every `(name, ours, rinex)` with [`rinex_eq`].
    pub fn assert_rinex_eq(fields: &[(&str, f64, f64)]) {
        for &(name, ours, rinex) in fields {
            assert!(rinex_eq(ours, rinex), "{name}: {ours:e} vs RINEX {rinex:e}");
        }
    }

    /// The orbit's values in the order of a RINEX 3 Galileo/BeiDou record (lines 0–4 and
    /// IDOT): af0, af1, af2, (issue: left out), Crs, Δn, M0, Cuc, e, Cus, √A, toe, Cic, Ω0,
    /// Cis, i0, Crc, ω, Ω̇, IDOT; asserted equal to `rinex`.
    pub fn assert_orbit_equals_record(o: &Orbit, rinex: [f64; 19]) {
        let ours = [
            ("af0", o.af[0]),
            ("af1", o.af[1]),
            ("af2", o.af[2]),
            ("Crs", o.crs),
            ("Δn", o.delta_n_rad_s),
            ("M0", o.m0_rad),
            ("Cuc", o.cuc),
            ("e", o.e),
            ("Cus", o.cus),
            ("√A", o.sqrt_a),
            ("toe", o.toe_s),
            ("Cic", o.cic),
            ("Ω0", o.omega0_rad),
            ("Cis", o.cis),
            ("i0", o.i0_rad),
            ("Crc", o.crc),
            ("ω", o.omega_rad),
            ("Ω̇", o.omega_dot_rad_s),
            ("IDOT", o.idot_rad_s),
        ];
        for ((name, v), r) in ours.into_iter().zip(rinex) {
            assert!(rinex_eq(v, r), "{name}: {v:e} vs RINEX {r:e}");
        }
    }

    /// Asserts the orbit's position at each `(t, ecef)` within 1 mm.
    pub fn assert_positions(o: &Orbit, want: &[(f64, [f64; 3])]) {
        for &(t, w) in want {
            let p = o.position_ecef_m(t);
            let d = ((p[0] - w[0]).powi(2) + (p[1] - w[1]).powi(2) + (p[2] - w[2]).powi(2)).sqrt();
            assert!(d < 1e-3, "t {t}: {p:?} vs {w:?}: {d} m");
        }
    }
}
