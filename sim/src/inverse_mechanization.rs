//! True IMU outputs by inverse strapdown mechanization in the local-level NED frame.
//!
//! Given the exact kinematics ([`Kinematics`]) the inertial angular rate and the specific
//! force of the body frame follow from inverting the NED mechanization equations of Groves
//! (2013) §5.4 (the same conventions as KF-GINS `insmech.cpp`):
//!
//! ```text
//! attitude (§5.4.1, Ċ_b^n = C_b^n Ω_ib^b − (Ω_ie^n + Ω_en^n) C_b^n), solved for ω_ib^b:
//!     ω_ib^b = ω_nb^b + C_n^b (ω_ie^n + ω_en^n)
//! velocity (eq. 5.54, v̇^n = C_b^n f_ib^b + g^n − (Ω_en^n + 2Ω_ie^n) v^n), solved for f_ib^b:
//!     f_ib^b = C_n^b ( v̇^n + (2ω_ie^n + ω_en^n) × v^n − g^n ),   g^n = [0, 0, γ(φ, h)]
//! ```
//!
//! with ω_ie^n (eq. 2.123), ω_en^n (eq. 5.44) and the normal gravity γ of
//! [`navsync_shared::earth`]. A sensor at lever arm r (body axes) from the body origin feels
//! f_ib^b + ω̇_ib^b × r + ω_ib^b × (ω_ib^b × r) (rigid-body kinematics, Groves §2.5.5; the gravity
//! gradient over r is neglected: < 2e-7 m/s² for r < 0.1 m), expressed in its own axes by the
//! mounting rotation C_b^s.
//!
//! An `ImuSample` reports averages over its interval [t − T, t]: ∫ω dt/T and ∫f dt/T of the
//! sensor-frame quantities (the increments an integrating IMU outputs, before coning and
//! sculling compensation), computed here by Gauss–Legendre quadrature on each smooth piece of
//! the interval (split at segment boundaries, and into pieces of at most [`MAX_PIECE_S`]).
//!
//! The body vibration ([`super::vibration`]) puts lines up to 18.5 Hz into ω and f, and the
//! lever-arm terms ω × (ω × r) their pairwise sums (up to 37 Hz, but with amplitudes of order
//! |ω|²|r| < 1e-5 m/s²). An n-point Gauss–Legendre rule on a piece of length T integrates
//! sin(ωt) with a relative error ≈ (n!)⁴/((2n+1)((2n)!)³)·(ωT)^{2n} (Abramowitz & Stegun
//! 25.4.30), for n = 5: 3.9e-13·(ωT)^10. With pieces of at most 5 ms, ωT ≤ 0.58 at 18.5 Hz and
//! the relative error ≤ 1.7e-15 (≤ 1e-12 at 37 Hz); the tests measure it against an 8-point
//! rule on 16 sub-pieces. Without the split, a 50 Hz IMU (20 ms) would see ωT = 2.3 and a
//! relative error of 1e-9, a 10 Hz IMU garbage.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use navsync_shared::earth;

use super::quadrature::{self, Rule};
use super::trajectory::{Kinematics, Trajectory, geodetic_rates};

/// Quadrature rule of the sample averages (see the tests for its measured error).
pub const SAMPLE_RULE: Rule = quadrature::GL5;

/// Longest piece one application of the quadrature rule covers, s (module docs): the
/// 200 Hz default samples are one piece each, slower IMUs' intervals are split evenly.
pub const MAX_PIECE_S: f64 = 0.005;

/// Inertial quantities of the body frame at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InertialState {
    /// Earth rate in NED, ω_ie^n, rad/s.
    pub omega_ie_n: Vector3<f64>,
    /// Transport rate, ω_en^n, rad/s.
    pub omega_en_n: Vector3<f64>,
    /// Normal gravity γ(φ, h), m/s² (g^n = [0, 0, γ]).
    pub gravity_mps2: f64,
    /// Angular rate of the body w.r.t. inertial space in body axes, ω_ib^b, rad/s.
    pub omega_ib_b: Vector3<f64>,
    /// Time derivative of ω_ib^b (body axes), rad/s².
    pub omega_ib_b_dot: Vector3<f64>,
    /// Specific force at the body origin, body axes, f_ib^b, m/s².
    pub f_ib_b: Vector3<f64>,
}

/// Inverse mechanization at one instant (see the module documentation for the equations).
pub fn inertial_state(k: &Kinematics) -> InertialState {
    let (lat, h) = (k.lat_rad, k.height_m);
    let v = &k.v_ned;
    let omega_ie_n = Vector3::from(earth::omega_ie_n(lat));
    let omega_en_n = Vector3::from(earth::omega_en_n(lat, h, [v[0], v[1], v[2]]));
    let gravity = earth::normal_gravity(lat, h);
    let c_n_b = k.c_b_n.transpose();
    let w_in_n = omega_ie_n + omega_en_n;
    let omega_ib_b = k.omega_nb_b + c_n_b * w_in_n;
    // d/dt (C_n^b w) = −ω_nb^b × (C_n^b w) + C_n^b ẇ, since Ċ_n^b = −[ω_nb^b ×] C_n^b.
    let w_dot = earth_rates_dot(k);
    let omega_ib_b_dot = k.omega_nb_b_dot - k.omega_nb_b.cross(&(c_n_b * w_in_n)) + c_n_b * w_dot;
    let coriolis = (2.0 * omega_ie_n + omega_en_n).cross(v);
    let f_n = k.a_ned + coriolis - Vector3::new(0.0, 0.0, gravity);
    InertialState {
        omega_ie_n,
        omega_en_n,
        gravity_mps2: gravity,
        omega_ib_b,
        omega_ib_b_dot,
        f_ib_b: c_n_b * f_n,
    }
}

/// Time derivative of ω_ie^n + ω_en^n along the trajectory, rad/s², from the analytic
/// derivatives of Groves eq. 2.123 and 5.44 with dR_N/dφ = R_N e² sinφ cosφ / (1 − e² sin²φ) and
/// dR_M/dφ = 3 R_M e² sinφ cosφ / (1 − e² sin²φ) (from eq. 2.105–2.106).
pub fn earth_rates_dot(k: &Kinematics) -> Vector3<f64> {
    let (lat, h) = (k.lat_rad, k.height_m);
    let (v, a) = (&k.v_ned, &k.a_ned);
    let [lat_dot, _, h_dot] = geodetic_rates(lat, h, v);
    let (s, c) = lat.sin_cos();
    let (rm, rn) = earth::radii(lat);
    let w2 = 1.0 - earth::WGS84_E2 * s * s;
    let drn = rn * earth::WGS84_E2 * s * c / w2;
    let drm = 3.0 * rm * earth::WGS84_E2 * s * c / w2;
    let (an, bm) = (rn + h, rm + h);
    let (an_dot, bm_dot) = (drn * lat_dot + h_dot, drm * lat_dot + h_dot);
    let ie_dot = Vector3::new(-s, 0.0, -c) * (earth::OMEGA_IE * lat_dot);
    let tan = s / c;
    let en_dot = Vector3::new(
        a[1] / an - v[1] * an_dot / (an * an),
        -a[0] / bm + v[0] * bm_dot / (bm * bm),
        -(a[1] * tan / an + v[1] * lat_dot / (c * c * an) - v[1] * tan * an_dot / (an * an)),
    );
    ie_dot + en_dot
}

/// How one IMU is attached to the body.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuMount {
    /// Body-to-sensor rotation C_b^s (transpose of the mounting C_s^b).
    pub c_b_s: Matrix3<f64>,
    /// Lever arm from the body origin to the sensor, body axes, m.
    pub lever_arm_b: Vector3<f64>,
}

impl ImuMount {
    /// Sensor aligned with the body axes at the body origin.
    pub fn identity() -> Self {
        Self {
            c_b_s: Matrix3::identity(),
            lever_arm_b: Vector3::zeros(),
        }
    }

    /// Mount from the sensor's roll, pitch, yaw w.r.t. the body (C_s^b = R_z R_y R_x), rad,
    /// and its lever arm, m.
    pub fn new(rpy_rad: [f64; 3], lever_arm_m: [f64; 3]) -> Self {
        let c_s_b = UnitQuaternion::from_euler_angles(rpy_rad[0], rpy_rad[1], rpy_rad[2]).to_rotation_matrix();
        Self {
            c_b_s: c_s_b.matrix().transpose(),
            lever_arm_b: Vector3::from(lever_arm_m),
        }
    }

    /// Instantaneous true sensor outputs (ω_is^s rad/s, f^s m/s²).
    pub fn sensor_outputs(&self, s: &InertialState) -> (Vector3<f64>, Vector3<f64>) {
        let w = &s.omega_ib_b;
        let r = &self.lever_arm_b;
        let f = s.f_ib_b + s.omega_ib_b_dot.cross(r) + w.cross(&w.cross(r));
        (self.c_b_s * w, self.c_b_s * f)
    }
}

/// Average sensor outputs over [t_end − period, t_end] of scenario time: (∫ω_is^s dt/T rad/s,
/// ∫f^s dt/T m/s²), by [`SAMPLE_RULE`] on each piece between segment boundaries.
pub fn averaged_outputs(traj: &Trajectory, mount: &ImuMount, t_end: f64, period: f64) -> ([f64; 3], [f64; 3]) {
    let (dth, dv) = increments(traj, mount, t_end - period, t_end, SAMPLE_RULE);
    (dth.map(|x| x / period), dv.map(|x| x / period))
}

/// [`averaged_outputs`] with an explicit quadrature rule (for accuracy tests).
pub fn averaged_outputs_with(
    traj: &Trajectory,
    mount: &ImuMount,
    t_end: f64,
    period: f64,
    rule: Rule,
) -> ([f64; 3], [f64; 3]) {
    let (dth, dv) = increments(traj, mount, t_end - period, t_end, rule);
    (dth.map(|x| x / period), dv.map(|x| x / period))
}

/// Sensor-frame increments over [t_start, t_end] of scenario time: (Δθ = ∫ω_is^s dt rad,
/// Δv = ∫f^s dt m/s), by `rule` on each piece between segment boundaries, pieces longer than
/// [`MAX_PIECE_S`] split evenly. Consecutive samples pass the same instant as one's end and
/// the next one's start, so the intervals tile time exactly and the increments add up to the
/// integral over any span.
pub fn increments(traj: &Trajectory, mount: &ImuMount, t_start: f64, t_end: f64, rule: Rule) -> ([f64; 3], [f64; 3]) {
    increments_split(traj, mount, t_start, t_end, rule, MAX_PIECE_S)
}

/// [`increments`] with pieces of at most `max_piece_s` (for accuracy tests; `f64::INFINITY`
/// splits at segment boundaries only).
pub fn increments_split(
    traj: &Trajectory,
    mount: &ImuMount,
    t_start: f64,
    t_end: f64,
    rule: Rule,
    max_piece_s: f64,
) -> ([f64; 3], [f64; 3]) {
    let mut cuts = [0.0; 8];
    let n = traj.boundaries_in(t_start, t_end, &mut cuts);
    let mut acc = [0.0; 6];
    let mut a = t_start;
    for b in cuts[..n].iter().copied().chain(std::iter::once(t_end)) {
        // The slack keeps an interval of exactly max_piece_s (up to rounding) in one piece.
        let pieces = ((b - a) / max_piece_s - 1e-9).ceil().max(1.0) as usize;
        let mut pa = a;
        for j in 1..=pieces {
            let pb = if j == pieces {
                b
            } else {
                a + (b - a) * j as f64 / pieces as f64
            };
            let piece = quadrature::integrate(rule, pa, pb, |t| {
                let (w, f) = mount.sensor_outputs(&inertial_state(&traj.kinematics(t)));
                [w[0], w[1], w[2], f[0], f[1], f[2]]
            });
            for (s, p) in acc.iter_mut().zip(piece) {
                *s += p;
            }
            pa = pb;
        }
        a = b;
    }
    // More boundaries than `cuts` holds (segments shorter than T/8) fall inside one piece;
    // validation keeps segments ≥ 0.1 s, so this happens only for IMU rates below 80 Hz.
    ([acc[0], acc[1], acc[2]], [acc[3], acc[4], acc[5]])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quadrature::GL8;
    use crate::scenario::VibrationConfig;
    use crate::scenario::{SegmentConfig, SegmentKind, StartConfig};
    use crate::trajectory::tests::vibrating_traj as default_traj;
    use crate::vibration::Vibration;

    /// 4th-order central difference (error h⁴ f⁽⁵⁾/30).
    fn fd4<T>(f: impl Fn(f64) -> T, t: f64, h: f64) -> T
    where
        T: std::ops::Sub<Output = T> + std::ops::Add<Output = T> + std::ops::Mul<f64, Output = T>,
    {
        (f(t - 2.0 * h) - f(t + 2.0 * h) + (f(t + h) - f(t - h)) * 8.0) * (1.0 / (12.0 * h))
    }

    /// 5 s of cruise at 20 m/s from t = 0 with the default vibration (vibrating from the
    /// start, at small t where the node times carry ≤ 2e-16 s of rounding).
    fn vibrating_cruise() -> Trajectory {
        let start = StartConfig {
            lat_deg: 48.0,
            lon_deg: 11.0,
            height_m: 500.0,
            heading_deg: 40.0,
            pitch_deg: 0.0,
            speed_mps: 20.0,
        };
        let seg = SegmentConfig {
            kind: SegmentKind::Cruise,
            duration_s: 5.0,
            to_speed_mps: None,
            heading_change_deg: None,
            to_pitch_deg: None,
        };
        Trajectory::with_vibration(
            &start,
            &[seg],
            Vibration::new(&VibrationConfig::default(), 3),
            crate::trajectory::POSITION_STEP_S,
        )
    }

    fn static_traj(lat_deg: f64, h: f64) -> Trajectory {
        let start = StartConfig {
            lat_deg,
            lon_deg: 10.0,
            height_m: h,
            heading_deg: 30.0,
            pitch_deg: 0.0,
            speed_mps: 0.0,
        };
        let seg = SegmentConfig {
            kind: SegmentKind::Static,
            duration_s: 10.0,
            to_speed_mps: None,
            heading_change_deg: None,
            to_pitch_deg: None,
        };
        Trajectory::new(&start, &[seg])
    }

    #[test]
    fn at_rest_reads_minus_gravity_and_earth_rate() {
        let lat = 48.0f64;
        let traj = static_traj(lat, 500.0);
        let (w, f) = averaged_outputs(&traj, &ImuMount::identity(), 5.0, 0.005);
        let g = earth::normal_gravity(lat.to_radians(), 500.0);
        // (t_end − period) carries a rounding of ~1e-16·t, i.e. a relative 2e-14 on T.
        assert!(f[0].abs() < 1e-12 && f[1].abs() < 1e-12, "{f:?}");
        assert!((f[2] + g).abs() < 1e-12, "{f:?}");
        // Earth rate magnitude and vertical component: −Ω sinφ on the down axis.
        let norm = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
        let tol = 1e-13 * earth::OMEGA_IE;
        assert!((norm - earth::OMEGA_IE).abs() < tol, "{norm}");
        assert!((w[2] + earth::OMEGA_IE * lat.to_radians().sin()).abs() < tol);
        // Heading 30°: the horizontal earth rate Ω cosφ points north, i.e. at −30° in body axes.
        let hz = earth::OMEGA_IE * lat.to_radians().cos();
        assert!((w[0] - hz * 30f64.to_radians().cos()).abs() < tol);
        assert!((w[1] + hz * 30f64.to_radians().sin()).abs() < tol);
    }

    /// Along the vibrating drive (4th-order differences at 0.1 ms: the vibration lines need the
    /// short step, see the trajectory tests).
    #[test]
    fn earth_rates_dot_matches_finite_difference() {
        let traj = default_traj();
        let h = 1e-4;
        for i in 1..600 {
            let t = i as f64 + 0.37;
            if t + 2.0 * h > traj.duration_s() {
                break;
            }
            let w = |t: f64| {
                let s = inertial_state(&traj.kinematics(t));
                s.omega_ie_n + s.omega_en_n
            };
            let fd = (-w(t + 2.0 * h) + 8.0 * w(t + h) - 8.0 * w(t - h) + w(t - 2.0 * h)) / (12.0 * h);
            let an = earth_rates_dot(&traj.kinematics(t));
            assert!((fd - an).norm() < 1e-14, "t={t}: {fd} vs {an}");
            let s = |t: f64| inertial_state(&traj.kinematics(t)).omega_ib_b;
            let fd = (-s(t + 2.0 * h) + 8.0 * s(t + h) - 8.0 * s(t - h) + s(t - 2.0 * h)) / (12.0 * h);
            let an = inertial_state(&traj.kinematics(t)).omega_ib_b_dot;
            assert!((fd - an).norm() < 1e-8, "t={t}: {fd} vs {an}");
        }
    }

    /// Forward mechanization of the truth: v̇ = C_b^n f + g − (2ω_ie + ω_en) × v and
    /// Ċ_b^n = C_b^n Ω_ib − Ω_in C_b^n must reproduce the trajectory's own derivatives, along
    /// the vibrating drive.
    #[test]
    fn forward_mechanization_closes() {
        let traj = default_traj();
        let h = 1e-4;
        for i in 0..300 {
            let t = 2.0 * i as f64 + 0.5;
            if t + 2.0 * h > traj.duration_s() {
                break;
            }
            let k = traj.kinematics(t);
            let s = inertial_state(&k);
            let vdot = k.c_b_n * s.f_ib_b + Vector3::new(0.0, 0.0, s.gravity_mps2)
                - (2.0 * s.omega_ie_n + s.omega_en_n).cross(&k.v_ned);
            let v_fd = fd4(|x| traj.kinematics(x).v_ned, t, h);
            assert!((vdot - v_fd).norm() < 1e-8, "t={t}");
            let cdot = k.c_b_n * s.omega_ib_b.cross_matrix() - (s.omega_ie_n + s.omega_en_n).cross_matrix() * k.c_b_n;
            let c_fd = fd4(|x| traj.kinematics(x).c_b_n, t, h);
            assert!((cdot - c_fd).norm() < 1e-9, "t={t}");
        }
    }

    /// Truncation error of the sample averages with vibration lines up to 18.5 Hz:
    /// [`SAMPLE_RULE`] on one 5 ms piece against an 8-point rule on 16 sub-pieces, with lever
    /// arm and mounting rotation, at t < 5 s where the node times carry ≤ 4.4e-16 s of
    /// rounding. The predicted truncation (3.9e-13·(ωT)^10 relative, 1.7e-15 at ωT = 0.58)
    /// is below that rounding floor (≈ ω̇·δt ≲ 1e-15 rad/s, jerk·δt ≲ 2e-14 m/s²), which
    /// is what the measured differences show. Then slower IMUs: the split into ≤ 5 ms pieces
    /// keeps that accuracy where one rule over the whole interval would not.
    #[test]
    fn vibration_quadrature_truncation_error() {
        let traj = vibrating_cruise();
        let mount = ImuMount::new([0.01, -0.02, 1.5], [0.05, -0.03, 0.02]);
        let composite = |a: f64, b: f64| -> [f64; 6] {
            let mut acc = [0.0; 6];
            for j in 0..16 {
                let (pa, pb) = (a + (b - a) * j as f64 / 16.0, a + (b - a) * (j + 1) as f64 / 16.0);
                let p = quadrature::integrate(GL8, pa, pb, |t| {
                    let (w, f) = mount.sensor_outputs(&inertial_state(&traj.kinematics(t)));
                    [w[0], w[1], w[2], f[0], f[1], f[2]]
                });
                for (s, v) in acc.iter_mut().zip(p) {
                    *s += v / (b - a);
                }
            }
            acc
        };
        let worst = |period: f64, max_piece: f64| -> (f64, f64) {
            let (mut ww, mut wf): (f64, f64) = (0.0, 0.0);
            let mut t = period;
            while t <= 4.9 {
                // Average over the interval as rounded (t − period is not exactly period long).
                let a = t - period;
                let (dth, dv) = increments_split(&traj, &mount, a, t, SAMPLE_RULE, max_piece);
                let r = composite(a, t);
                for k in 0..3 {
                    ww = ww.max((dth[k] / (t - a) - r[k]).abs());
                    wf = wf.max((dv[k] / (t - a) - r[k + 3]).abs());
                }
                t += period * 1.37;
            }
            (ww, wf)
        };
        let (w200, f200) = worst(0.005, MAX_PIECE_S);
        println!("200 Hz, GL5 on one 5 ms piece: gyro {w200:.2e} rad/s, accel {f200:.2e} m/s²");
        assert!(w200 < 2e-15 && f200 < 5e-14, "{w200} {f200}");
        for rate in [50.0, 10.0] {
            let period = 1.0 / rate;
            let (ws, fs) = worst(period, MAX_PIECE_S);
            let (wu, fu) = worst(period, f64::INFINITY);
            println!(
                "{rate} Hz: split into 5 ms pieces gyro {ws:.2e} rad/s, accel {fs:.2e} m/s²; \
                 one GL5 over {:.0} ms gyro {wu:.2e} rad/s, accel {fu:.2e} m/s²",
                period * 1e3
            );
            assert!(ws < 2e-15 && fs < 5e-14, "{rate} Hz split: {ws} {fs}");
            assert!(
                fu > 100.0 * fs.max(1e-16),
                "{rate} Hz: the split must matter ({fu} vs {fs})"
            );
        }
    }

    /// The sample averages by [`SAMPLE_RULE`] against the 8-point rule and against an
    /// 8-point rule on 16 sub-intervals, over the whole vibrating default drive at 200 Hz.
    /// Late in the drive the differences are set by the rounding of the node times, not by the
    /// rules (ulp(600 s) = 1.1e-13 s against the vibration's ω̇ ≲ 2 rad/s² and jerk ≲ 30 m/s³:
    /// ~1e-13 rad/s and ~3e-12 m/s²); the truncation error alone is measured by
    /// `vibration_quadrature_truncation_error`.
    #[test]
    fn averaged_outputs_quadrature_error() {
        let traj = default_traj();
        let mount = ImuMount::new([0.01, -0.02, 1.5], [0.05, -0.03, 0.02]);
        let period = 0.005;
        let (mut worst_w, mut worst_f): (f64, f64) = (0.0, 0.0);
        let mut t = period;
        while t <= traj.duration_s() {
            let (w5, f5) = averaged_outputs(&traj, &mount, t, period);
            let (w8, f8) = averaged_outputs_with(&traj, &mount, t, period, GL8);
            for k in 0..3 {
                worst_w = worst_w.max((w5[k] - w8[k]).abs());
                worst_f = worst_f.max((f5[k] - f8[k]).abs());
            }
            t += 0.0371;
        }
        println!("GL5 vs GL8 sample averages: gyro {worst_w:.3e} rad/s, accel {worst_f:.3e} m/s²");
        assert!(worst_w < 2e-13 && worst_f < 5e-12, "{worst_w} {worst_f}");
        // Composite reference (8 × GL8 on each side of the boundary) on intervals straddling
        // segment boundaries.
        for seg in &traj.segments()[1..12] {
            let t_end = seg.t0 + 0.0021;
            let (w5, f5) = averaged_outputs(&traj, &mount, t_end, period);
            let mut acc = [0.0; 6];
            for (a0, b0) in [(t_end - period, seg.t0), (seg.t0, t_end)] {
                for j in 0..8 {
                    let a = a0 + j as f64 * (b0 - a0) / 8.0;
                    let b = a0 + (j + 1) as f64 * (b0 - a0) / 8.0;
                    let p = quadrature::integrate(GL8, a, b, |t| {
                        let (w, f) = mount.sensor_outputs(&inertial_state(&traj.kinematics(t)));
                        [w[0], w[1], w[2], f[0], f[1], f[2]]
                    });
                    for (s, v) in acc.iter_mut().zip(p) {
                        *s += v / period;
                    }
                }
            }
            for k in 0..3 {
                assert!((w5[k] - acc[k]).abs() < 2e-13, "gyro {k}: {} vs {}", w5[k], acc[k]);
                assert!(
                    (f5[k] - acc[k + 3]).abs() < 5e-12,
                    "accel {k}: {} vs {}",
                    f5[k],
                    acc[k + 3]
                );
            }
        }
    }

    #[test]
    fn lever_arm_centripetal_in_a_turn() {
        // In a steady turn the lever-arm term ω × (ω × r) for r along body y is −ω_z² r.
        let traj = default_traj();
        let turn = traj
            .segments()
            .iter()
            .find(|s| s.heading.1.abs() > 1.0)
            .expect("a turn");
        let t = turn.t0 + turn.duration / 2.0;
        let k = traj.kinematics(t);
        let s = inertial_state(&k);
        let r = 0.5;
        let (_, f0) = ImuMount::identity().sensor_outputs(&s);
        let (_, f1) = ImuMount::new([0.0; 3], [0.0, r, 0.0]).sensor_outputs(&s);
        let w = s.omega_ib_b;
        let expected =
            s.omega_ib_b_dot.cross(&Vector3::new(0.0, r, 0.0)) + w.cross(&w.cross(&Vector3::new(0.0, r, 0.0)));
        assert!(((f1 - f0) - expected).norm() < 1e-15);
        assert!((f1 - f0)[1] < -0.5 * w[2] * w[2] * r, "centripetal towards the centre");
    }

    #[test]
    fn mounting_rotation_rotates_outputs() {
        let traj = default_traj();
        let s = inertial_state(&traj.kinematics(123.4));
        // Sensor yawed +90°: sensor x = body y, so f^s_x = f^b_y and f^s_y = −f^b_x.
        let (w, f) = ImuMount::new([0.0, 0.0, std::f64::consts::FRAC_PI_2], [0.0; 3]).sensor_outputs(&s);
        assert!((f[0] - s.f_ib_b[1]).abs() < 1e-12 && (f[1] + s.f_ib_b[0]).abs() < 1e-12);
        assert!((w[2] - s.omega_ib_b[2]).abs() < 1e-18);
    }
}
