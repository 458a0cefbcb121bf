//! The vehicle's motion on the WGS-84 ellipsoid.
//!
//! A car without sideslip: the body x axis is along the velocity, roll is 0, pitch is the
//! flight-path angle θ and yaw the heading ψ. Speed v, heading ψ and flight-path angle θ are
//! closed-form per segment (raised-cosine changes, [`smooth_step`]), so the velocity
//!
//! ```text
//! v^n = v·[cosθ cosψ, cosθ sinψ, −sinθ]          (NED)
//! ```
//!
//! its time derivative a^n = dv^n/dt, the attitude C_b^n = R_z(ψ) R_y(θ) and the body rate
//! ω_nb^b = [−ψ̇ sinθ, θ̇, ψ̇ cosθ] (the Euler-rate relation of a z-y-x rotation sequence,
//! Groves 2013 §2.2.2 / Titterton & Weston 2004 §3.6, with roll 0) and its derivative are
//! all exact at any instant. Position (φ, λ, h) follows from the curvilinear kinematics
//! (Groves 2013 §2.4.3, the differential form of the position update of §5.4.4):
//!
//! ```text
//! φ̇ = v_N/(R_M + h),   λ̇ = v_E/((R_N + h) cosφ),   ḣ = −v_D
//! ```
//!
//! integrated by classical RK4 with a step of at most 10 ms whose grid includes every segment
//! boundary (the integrand is analytic inside a segment), stored in a table and read back by
//! cubic Hermite interpolation using the exact derivative at the nodes. The resulting error is
//! below 1e-9 m (see the tests, which measure it).
//!
//! # Body vibration
//!
//! On top of this smooth path the body rolls, pitches and heaves ([`Vibration`], closed-form,
//! zero at standstill): roll φ_v, pitch θ + θ_v and a vertical displacement z_v (up), each with
//! exact first and second time derivatives. Then
//!
//! ```text
//! C_b^n   = R_z(ψ) R_y(θ + θ_v) R_x(φ_v)                  (Groves 2013 eq. 2.22)
//! ω_nb^b  = [ φ̇ − ψ̇ sinθ_b,                                (Euler-rate relation of the z-y-x
//!             θ̇_b cosφ + ψ̇ cosθ_b sinφ,                     sequence, the inverse of Groves
//!            −θ̇_b sinφ + ψ̇ cosθ_b cosφ ]                    eq. 2.58; θ_b = θ + θ_v, φ = φ_v)
//! v^n     = v·[cosθ cosψ, cosθ sinψ, −sinθ] − [0, 0, ż_v]
//! a^n     = dv^n/dt                     − [0, 0, z̈_v]
//! h       = h_path + z_v
//! ```
//!
//! The velocity keeps the direction of the path (the body pitches on its suspension, the car
//! does not fly). ω̇_nb^b is the time derivative of the expression above (see [`body_rate_rpy`]).
//! The heave is not integrated: the table integrates the path, and the height is
//! h_path(t) + z_v(t) analytically; the table's integrand takes the radii denominators at that
//! full height (R_M + h_path + z_v), so φ̇ and λ̇ are exactly those of the full motion (the
//! coupling is v·z_v/R ≈ 1e-8 m/s and integrated to < 1e-11 m by RK4).

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use navsync_shared::earth;

use super::scenario::{SegmentConfig, StartConfig, TrajectoryConfig};
use super::vibration::{Vibration, VibrationState};

/// Largest RK4 step of the position table, s.
pub const POSITION_STEP_S: f64 = 0.01;

/// The raised-cosine ("sin²-rate") transition on x ∈ [0, 1] and its first two derivatives
/// w.r.t. x: s(x) = x − sin(2πx)/(2π), s′ = 1 − cos 2πx = 2 sin²(πx), s″ = 2π sin 2πx.
/// s goes from 0 to 1 with s′ and s″ zero at both ends, so a quantity changed along it has
/// continuous first and second time derivatives across segment boundaries.
pub fn smooth_step(x: f64) -> [f64; 3] {
    use std::f64::consts::TAU;
    let x = x.clamp(0.0, 1.0);
    let (s2, c2) = (TAU * x).sin_cos();
    [x - s2 / TAU, 1.0 - c2, TAU * s2]
}

pub use super::jet::Jet;

/// One segment's closed-form motion, all angles in rad.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentMotion {
    /// Start, s of scenario time.
    pub t0: f64,
    /// Length, s.
    pub duration: f64,
    /// Speed at the start, m/s, and its change over the segment.
    pub speed: (f64, f64),
    /// Heading at the start, rad, and its change.
    pub heading: (f64, f64),
    /// Flight-path angle at the start, rad, and its change.
    pub pitch: (f64, f64),
}

impl SegmentMotion {
    /// End of the segment, s.
    pub fn t1(&self) -> f64 {
        self.t0 + self.duration
    }

    /// (speed, heading, pitch) jets at scenario time `t` (clamped to the segment).
    pub fn path(&self, t: f64) -> (Jet, Jet, Jet) {
        let d = self.duration;
        let [s, ds, dds] = smooth_step((t - self.t0) / d);
        let jet = |(q0, dq): (f64, f64)| [q0 + dq * s, dq * ds / d, dq * dds / (d * d)];
        (jet(self.speed), jet(self.heading), jet(self.pitch))
    }
}

/// The exact motion of the body frame at one instant (no inertial terms).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kinematics {
    /// Scenario time, s.
    pub t_s: f64,
    /// Geodetic latitude, rad.
    pub lat_rad: f64,
    /// Longitude, rad (not wrapped: continuous along the trajectory).
    pub lon_rad: f64,
    /// Height above the ellipsoid, m.
    pub height_m: f64,
    /// Velocity w.r.t. the earth, NED, m/s.
    pub v_ned: Vector3<f64>,
    /// Time derivative of `v_ned`, m/s².
    pub a_ned: Vector3<f64>,
    /// Speed (v), heading (ψ, rad) and flight-path angle (θ, rad) with their first and second
    /// time derivatives.
    pub speed: Jet,
    /// Heading jet, rad, rad/s, rad/s².
    pub heading: Jet,
    /// Flight-path angle jet (the pitch of the smooth path, without vibration), rad, rad/s,
    /// rad/s².
    pub pitch: Jet,
    /// Body vibration at this instant: roll φ_v, pitch perturbation θ_v (rad) and heave z_v
    /// (m, up) jets; zero at standstill or with the vibration off. The attitude, body rate,
    /// velocity, acceleration and height above include it.
    pub vibration: VibrationState,
    /// Body-to-NED direction cosine matrix C_b^n = R_z(ψ) R_y(θ + θ_v) R_x(φ_v).
    pub c_b_n: Matrix3<f64>,
    /// Body rate w.r.t. NED in body axes, ω_nb^b, rad/s.
    pub omega_nb_b: Vector3<f64>,
    /// Time derivative of ω_nb^b, rad/s².
    pub omega_nb_b_dot: Vector3<f64>,
}

impl Kinematics {
    /// Roll, pitch, yaw of the body w.r.t. NED (vibration included), rad; yaw wrapped to
    /// (−π, π].
    pub fn rpy_rad(&self) -> [f64; 3] {
        [self.vibration.roll[0], self.body_pitch_rad(), wrap_pi(self.heading[0])]
    }

    /// Body pitch θ + θ_v, rad.
    pub fn body_pitch_rad(&self) -> f64 {
        self.pitch[0] + self.vibration.pitch[0]
    }

    /// Attitude quaternion q_b^n (rotates body vectors into NED).
    pub fn q_b_n(&self) -> UnitQuaternion<f64> {
        UnitQuaternion::from_euler_angles(self.vibration.roll[0], self.body_pitch_rad(), self.heading[0])
    }
}

/// Wraps an angle to (−π, π].
pub fn wrap_pi(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    let w = a.rem_euclid(TAU);
    if w > PI { w - TAU } else { w }
}

/// C_b^n for roll 0, pitch θ, yaw ψ (Groves eq. 2.22 with φ = 0).
pub fn dcm_from_pitch_yaw(theta: f64, psi: f64) -> Matrix3<f64> {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = psi.sin_cos();
    Matrix3::new(ct * cp, -sp, st * cp, ct * sp, cp, st * sp, -st, 0.0, ct)
}

/// C_b^n for roll φ, pitch θ, yaw ψ (Groves 2013 eq. 2.22: R_z(ψ) R_y(θ) R_x(φ)).
pub fn dcm_from_rpy(phi: f64, theta: f64, psi: f64) -> Matrix3<f64> {
    let (sf, cf) = phi.sin_cos();
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = psi.sin_cos();
    Matrix3::new(
        ct * cp,
        -cf * sp + sf * st * cp,
        sf * sp + cf * st * cp,
        ct * sp,
        cf * cp + sf * st * sp,
        -sf * cp + cf * st * sp,
        -st,
        sf * ct,
        cf * ct,
    )
}

/// ω_nb^b and its time derivative from roll φ, pitch θ and yaw ψ jets (Euler-rate relation of
/// the z-y-x sequence, the inverse of Groves 2013 eq. 2.58):
///
/// ```text
/// ω = [ φ̇ − ψ̇ sθ,  θ̇ cφ + ψ̇ cθ sφ,  −θ̇ sφ + ψ̇ cθ cφ ]
/// ω̇ = [ φ̈ − ψ̈ sθ − ψ̇ θ̇ cθ,
///       θ̈ cφ − θ̇ φ̇ sφ + ψ̈ cθ sφ − ψ̇ θ̇ sθ sφ + ψ̇ φ̇ cθ cφ,
///      −θ̈ sφ − θ̇ φ̇ cφ + ψ̈ cθ cφ − ψ̇ θ̇ sθ cφ − ψ̇ φ̇ cθ sφ ]
/// ```
///
/// With φ ≡ 0 it is [`body_rate`].
pub fn body_rate_rpy(phi: Jet, th: Jet, psi: Jet) -> (Vector3<f64>, Vector3<f64>) {
    let (sf, cf) = phi[0].sin_cos();
    let (st, ct) = th[0].sin_cos();
    let w = Vector3::new(
        phi[1] - psi[1] * st,
        th[1] * cf + psi[1] * ct * sf,
        -th[1] * sf + psi[1] * ct * cf,
    );
    let dw = Vector3::new(
        phi[2] - psi[2] * st - psi[1] * th[1] * ct,
        th[2] * cf - th[1] * phi[1] * sf + psi[2] * ct * sf - psi[1] * th[1] * st * sf + psi[1] * phi[1] * ct * cf,
        -th[2] * sf - th[1] * phi[1] * cf + psi[2] * ct * cf - psi[1] * th[1] * st * cf - psi[1] * phi[1] * ct * sf,
    );
    (w, dw)
}

/// NED velocity and its time derivative from the speed, heading and pitch jets.
pub fn velocity_and_acceleration(v: Jet, psi: Jet, th: Jet) -> (Vector3<f64>, Vector3<f64>) {
    let (st, ct) = th[0].sin_cos();
    let (sp, cp) = psi[0].sin_cos();
    let u = Vector3::new(ct * cp, ct * sp, -st);
    let du = Vector3::new(
        -st * th[1] * cp - ct * sp * psi[1],
        -st * th[1] * sp + ct * cp * psi[1],
        -ct * th[1],
    );
    (u * v[0], u * v[1] + du * v[0])
}

/// ω_nb^b and its derivative for roll 0 (Euler-rate relation of the z-y-x sequence).
pub fn body_rate(psi: Jet, th: Jet) -> (Vector3<f64>, Vector3<f64>) {
    let (st, ct) = th[0].sin_cos();
    let w = Vector3::new(-psi[1] * st, th[1], psi[1] * ct);
    let dw = Vector3::new(
        -psi[2] * st - psi[1] * th[1] * ct,
        th[2],
        psi[2] * ct - psi[1] * th[1] * st,
    );
    (w, dw)
}

/// Geodetic rates (φ̇, λ̇, ḣ) for NED velocity `v` at (φ, h) (Groves 2013 §2.4.3).
pub fn geodetic_rates(lat: f64, h: f64, v: &Vector3<f64>) -> [f64; 3] {
    let (rm, rn) = earth::radii(lat);
    [v[0] / (rm + h), v[1] / ((rn + h) * lat.cos()), -v[2]]
}

/// One node of the position table.
#[derive(Debug, Clone, Copy)]
struct Node {
    /// Offsets from the start position: Δφ rad, Δλ rad, Δh m (small numbers, so that the
    /// accumulation over 10⁵ steps keeps ~1e-19 rad resolution instead of the ~1e-16 rad of
    /// an absolute latitude).
    p: [f64; 3],
    /// φ̇, λ̇, ḣ.
    dp: [f64; 3],
}

/// Nodes of one segment: `steps` equal steps of `step` s from node `first`.
#[derive(Debug, Clone, Copy)]
struct SegmentGrid {
    first: usize,
    steps: usize,
    step: f64,
}

/// The whole trajectory: closed-form path per segment, the body vibration and the integrated
/// position table.
#[derive(Debug, Clone)]
pub struct Trajectory {
    segments: Vec<SegmentMotion>,
    grids: Vec<SegmentGrid>,
    nodes: Vec<Node>,
    vibration: Vibration,
    /// Start position φ₀ rad, λ₀ rad, h₀ m.
    origin: [f64; 3],
    duration: f64,
}

impl Trajectory {
    /// Builds the trajectory of a validated scenario's `[trajectory]` (segments and vibration,
    /// whose phases come from `seed`) with the default step.
    pub fn from_config(cfg: &TrajectoryConfig, seed: u64) -> Self {
        Self::with_vibration(
            &cfg.start,
            &cfg.segments,
            Vibration::new(&cfg.vibration, seed),
            POSITION_STEP_S,
        )
    }

    /// Builds the smooth trajectory (no vibration) of validated segments
    /// ([`SimConfig::validate`](super::scenario::SimConfig::validate)) with the default step.
    /// (An empty segment list gives 1 s of constant motion.)
    pub fn new(start: &StartConfig, segments: &[SegmentConfig]) -> Self {
        Self::with_step(start, segments, POSITION_STEP_S)
    }

    /// Builds the smooth trajectory with RK4 steps of at most `max_step_s` (for accuracy tests).
    pub fn with_step(start: &StartConfig, segments: &[SegmentConfig], max_step_s: f64) -> Self {
        Self::with_vibration(start, segments, Vibration::none(), max_step_s)
    }

    /// Builds the trajectory with body vibration `vibration` and RK4 steps of at most
    /// `max_step_s`.
    pub fn with_vibration(
        start: &StartConfig,
        segments: &[SegmentConfig],
        vibration: Vibration,
        max_step_s: f64,
    ) -> Self {
        let motions = segment_motions(start, segments);
        let duration = motions.last().map_or(0.0, SegmentMotion::t1);
        let origin = [start.lat_deg.to_radians(), start.lon_deg.to_radians(), start.height_m];
        let mut traj = Self {
            segments: motions,
            grids: Vec::new(),
            nodes: Vec::new(),
            vibration,
            origin,
            duration,
        };
        traj.integrate(max_step_s);
        traj
    }

    /// The body vibration.
    pub fn vibration(&self) -> &Vibration {
        &self.vibration
    }

    /// Scenario length, s.
    pub fn duration_s(&self) -> f64 {
        self.duration
    }

    /// The segments' closed-form motions.
    pub fn segments(&self) -> &[SegmentMotion] {
        &self.segments
    }

    /// Index of the segment containing `t` (clamped to the scenario).
    pub fn segment_index(&self, t: f64) -> usize {
        self.segments
            .partition_point(|s| s.t1() < t)
            .min(self.segments.len().saturating_sub(1))
    }

    /// Integrates the smooth path's position; the node heights are h_path (without heave),
    /// the radii denominators use the full height h_path + z_v (module docs).
    fn integrate(&mut self, max_step: f64) {
        let o = self.origin;
        let mut p = [0.0; 3];
        let vib = &self.vibration;
        for (i, seg) in self.segments.iter().enumerate() {
            let steps = (seg.duration / max_step).ceil().max(1.0) as usize;
            let step = seg.duration / steps as f64;
            let first = self.nodes.len();
            self.grids.push(SegmentGrid { first, steps, step });
            let f = |t: f64, d: &[f64; 3]| -> [f64; 3] {
                let (v, psi, th) = seg.path(t);
                let heave = vib.heave(t, v)[0];
                geodetic_rates(
                    o[0] + d[0],
                    o[2] + d[2] + heave,
                    &velocity_and_acceleration(v, psi, th).0,
                )
            };
            for k in 0..steps {
                let t = seg.t0 + k as f64 * step;
                self.nodes.push(Node { p, dp: f(t, &p) });
                p = rk4_step(&f, t, &p, step);
            }
            if i + 1 == self.segments.len() {
                let t = seg.t1();
                self.nodes.push(Node { p, dp: f(t, &p) });
            }
        }
    }

    /// Position (φ rad, λ rad, h m) at scenario time `t` by cubic Hermite interpolation of
    /// the RK4 table (t clamped to [0, duration]).
    pub fn position(&self, t: f64) -> [f64; 3] {
        let d = self.position_offset(t);
        [self.origin[0] + d[0], self.origin[1] + d[1], self.origin[2] + d[2]]
    }

    /// Position relative to the start (Δφ rad, Δλ rad, Δh m; heave included) at scenario
    /// time `t`.
    pub fn position_offset(&self, t: f64) -> [f64; 3] {
        let t = t.clamp(0.0, self.duration);
        let mut d = self.table_offset(t);
        if let Some(seg) = self.segments.get(self.segment_index(t)) {
            d[2] += self.vibration.heave(t, seg.path(t).0)[0];
        }
        d
    }

    /// The position table's offset at `t` (Δφ, Δλ, Δh of the smooth path, without heave).
    fn table_offset(&self, t: f64) -> [f64; 3] {
        let i = self.segment_index(t);
        let (Some(seg), Some(grid)) = (self.segments.get(i), self.grids.get(i)) else {
            return [0.0; 3];
        };
        let tau = (t - seg.t0).clamp(0.0, seg.duration);
        let k = ((tau / grid.step).floor() as usize).min(grid.steps - 1);
        let (Some(a), Some(b)) = (self.nodes.get(grid.first + k), self.nodes.get(grid.first + k + 1)) else {
            return [0.0; 3];
        };
        let h = grid.step;
        let u = (tau - k as f64 * h) / h;
        hermite(a, b, h, u)
    }

    /// The exact kinematic state at scenario time `t` (clamped to [0, duration]), vibration
    /// included (module docs).
    pub fn kinematics(&self, t: f64) -> Kinematics {
        let t = t.clamp(0.0, self.duration);
        let seg = self.segments[self.segment_index(t)];
        let (speed, heading, pitch) = seg.path(t);
        let vib = self.vibration.state(t, speed);
        let (mut v_ned, mut a_ned) = velocity_and_acceleration(speed, heading, pitch);
        v_ned[2] -= vib.heave[1];
        a_ned[2] -= vib.heave[2];
        let body_pitch = [
            pitch[0] + vib.pitch[0],
            pitch[1] + vib.pitch[1],
            pitch[2] + vib.pitch[2],
        ];
        let (omega_nb_b, omega_nb_b_dot) = body_rate_rpy(vib.roll, body_pitch, heading);
        let d = self.table_offset(t);
        Kinematics {
            t_s: t,
            lat_rad: self.origin[0] + d[0],
            lon_rad: self.origin[1] + d[1],
            height_m: self.origin[2] + (d[2] + vib.heave[0]),
            v_ned,
            a_ned,
            speed,
            heading,
            pitch,
            vibration: vib,
            c_b_n: dcm_from_rpy(vib.roll[0], body_pitch[0], heading[0]),
            omega_nb_b,
            omega_nb_b_dot,
        }
    }

    /// Segment boundaries strictly inside (a, b), in increasing order, written to `out`;
    /// returns how many (at most `out.len()`).
    pub fn boundaries_in(&self, a: f64, b: f64, out: &mut [f64]) -> usize {
        let mut n = 0;
        let first = self.segment_index(a);
        for seg in self.segments.iter().skip(first) {
            let t = seg.t1();
            if t >= b || n == out.len() {
                break;
            }
            if t > a {
                out[n] = t;
                n += 1;
            }
        }
        n
    }
}

/// Converts validated segment configs into closed-form motions.
fn segment_motions(start: &StartConfig, segments: &[SegmentConfig]) -> Vec<SegmentMotion> {
    let mut t0 = 0.0;
    let mut v = start.speed_mps;
    let mut psi = start.heading_deg.to_radians();
    let mut th = start.pitch_deg.to_radians();
    let mut out = Vec::with_capacity(segments.len());
    for s in segments {
        let dv = s.to_speed_mps.map_or(0.0, |v1| v1 - v);
        let dpsi = s.heading_change_deg.map_or(0.0, f64::to_radians);
        let dth = s.to_pitch_deg.map_or(0.0, |p| p.to_radians() - th);
        out.push(SegmentMotion {
            t0,
            duration: s.duration_s,
            speed: (v, dv),
            heading: (psi, dpsi),
            pitch: (th, dth),
        });
        t0 += s.duration_s;
        v += dv;
        psi += dpsi;
        th += dth;
    }
    if out.is_empty() {
        // Not reachable from a validated scenario; keeps the trajectory well defined.
        out.push(SegmentMotion {
            t0: 0.0,
            duration: 1.0,
            speed: (v, 0.0),
            heading: (psi, 0.0),
            pitch: (th, 0.0),
        });
    }
    out
}

fn rk4_step(f: &impl Fn(f64, &[f64; 3]) -> [f64; 3], t: f64, y: &[f64; 3], h: f64) -> [f64; 3] {
    let add = |y: &[f64; 3], k: &[f64; 3], s: f64| [y[0] + s * k[0], y[1] + s * k[1], y[2] + s * k[2]];
    let k1 = f(t, y);
    let k2 = f(t + h / 2.0, &add(y, &k1, h / 2.0));
    let k3 = f(t + h / 2.0, &add(y, &k2, h / 2.0));
    let k4 = f(t + h, &add(y, &k3, h));
    std::array::from_fn(|i| y[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]))
}

/// Cubic Hermite interpolation between nodes `a` and `b` a step `h` apart, at u ∈ [0, 1].
fn hermite(a: &Node, b: &Node, h: f64, u: f64) -> [f64; 3] {
    let u2 = u * u;
    let u3 = u2 * u;
    let h01 = -2.0 * u3 + 3.0 * u2;
    let h10 = u3 - 2.0 * u2 + u;
    let h11 = u3 - u2;
    std::array::from_fn(|i| a.p[i] + (b.p[i] - a.p[i]) * h01 + h * (a.dp[i] * h10 + b.dp[i] * h11))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::scenario::{SegmentKind, SimConfig};

    /// The default drive's smooth path (no vibration).
    pub(crate) fn default_traj() -> Trajectory {
        let cfg = SimConfig::default_drive();
        Trajectory::new(&cfg.trajectory.start, &cfg.trajectory.segments)
    }

    /// The default drive as the world builds it: with its (default-on) vibration.
    pub(crate) fn vibrating_traj() -> Trajectory {
        let cfg = SimConfig::default_drive();
        assert!(cfg.trajectory.vibration.enabled);
        Trajectory::from_config(&cfg.trajectory, cfg.seed)
    }

    /// 4th-order central difference (error h⁴ f⁽⁵⁾/30).
    fn fd4<T>(f: impl Fn(f64) -> T, t: f64, h: f64) -> T
    where
        T: std::ops::Sub<Output = T> + std::ops::Add<Output = T> + std::ops::Mul<f64, Output = T>,
    {
        (f(t - 2.0 * h) - f(t + 2.0 * h) + (f(t + h) - f(t - h)) * 8.0) * (1.0 / (12.0 * h))
    }

    /// Distance in m between two position offsets (small-offset metric at the origin).
    fn dist(origin: [f64; 3], a: [f64; 3], b: [f64; 3]) -> f64 {
        let (rm, rn) = earth::radii(origin[0]);
        let dn = (a[0] - b[0]) * (rm + origin[2]);
        let de = (a[1] - b[1]) * (rn + origin[2]) * origin[0].cos();
        let dd = a[2] - b[2];
        (dn * dn + de * de + dd * dd).sqrt()
    }

    #[test]
    fn smooth_step_ends_and_derivatives() {
        assert_eq!(smooth_step(0.0), [0.0, 0.0, 0.0]);
        let e = smooth_step(1.0);
        assert!((e[0] - 1.0).abs() < 1e-15 && e[1].abs() < 1e-15 && e[2].abs() < 1e-13);
        let h = 1e-5;
        for x in [0.1, 0.37, 0.5, 0.81] {
            let d1 = (smooth_step(x + h)[0] - smooth_step(x - h)[0]) / (2.0 * h);
            let d2 = (smooth_step(x + h)[1] - smooth_step(x - h)[1]) / (2.0 * h);
            assert!((d1 - smooth_step(x)[1]).abs() < 1e-9);
            assert!((d2 - smooth_step(x)[2]).abs() < 1e-8);
        }
    }

    /// With the vibration on: a^n = dv^n/dt, Ċ_b^n = C_b^n [ω_nb^b ×], dω_nb^b/dt and the
    /// position rates against 4th-order central differences every 0.1 s of the drive. The
    /// vibration lines (≤ 18.5 Hz) need the 4th-order stencil: at h = 0.1 ms its truncation is
    /// h⁴ω⁶A/30 < 3e-10 for ω̇, where the 2nd-order one would leave h²ω⁴A/6 ≈ 1e-7.
    #[test]
    fn analytic_derivatives_match_finite_differences() {
        let traj = vibrating_traj();
        let h = 1e-4;
        let mut checked = 0;
        let mut moving = 0;
        for i in 0..6000 {
            let t = 0.1 * i as f64 + 0.0123;
            if t + 2.0 * h > traj.duration_s() {
                break;
            }
            let k0 = traj.kinematics(t);
            if k0.vibration.roll[0] != 0.0 {
                moving += 1;
            }
            // a = dv/dt
            let a_fd = fd4(|x| traj.kinematics(x).v_ned, t, h);
            assert!((a_fd - k0.a_ned).norm() < 1e-8, "t={t} a {a_fd} vs {}", k0.a_ned);
            // Ċ_b^n = C_b^n [ω_nb^b ×]
            let cdot = fd4(|x| traj.kinematics(x).c_b_n, t, h);
            let expected = k0.c_b_n * k0.omega_nb_b.cross_matrix();
            assert!((cdot - expected).norm() < 1e-9, "t={t}");
            let wdot = fd4(|x| traj.kinematics(x).omega_nb_b, t, h);
            assert!(
                (wdot - k0.omega_nb_b_dot).norm() < 1e-8,
                "t={t}: {wdot} vs {}",
                k0.omega_nb_b_dot
            );
            // Height rate including the heave: dh/dt = −v_D (short step: heave lines).
            let dh = fd4(|x| traj.position_offset(x)[2], t, h);
            assert!((dh + k0.v_ned[2]).abs() < 1e-8, "t={t}: ḣ {dh} vs {}", -k0.v_ned[2]);
            // Position derivative = velocity: 4th-order central differences of the table part
            // (the offsets less the analytic heave) at the table's step, plus ż_v.
            let hp = 1e-2;
            let p = |dt: f64| {
                let mut d = traj.position_offset(t + dt);
                d[2] -= traj.kinematics(t + dt).vibration.heave[0];
                d
            };
            let (p2, p1, m1, m2) = (p(2.0 * hp), p(hp), p(-hp), p(-2.0 * hp));
            let mut rate: [f64; 3] =
                std::array::from_fn(|i| (-p2[i] + 8.0 * p1[i] - 8.0 * m1[i] + m2[i]) / (12.0 * hp));
            rate[2] += k0.vibration.heave[1];
            let expected = geodetic_rates(k0.lat_rad, k0.height_m, &k0.v_ned);
            let (rm, rn) = earth::radii(k0.lat_rad);
            let scale = [rm + k0.height_m, (rn + k0.height_m) * k0.lat_rad.cos(), 1.0];
            for i in 0..3 {
                let err_mps = (rate[i] - expected[i]) * scale[i];
                assert!(err_mps.abs() < 1e-8, "t={t} axis {i}: {err_mps} m/s");
            }
            checked += 1;
        }
        assert!(checked > 5000 && moving > 4000, "{checked} {moving}");
    }

    /// ω_nb^b and ω̇ of [`body_rate_rpy`] against the derivative of the DCM for arbitrary
    /// (large) angle jets, i.e. independently of the vibration's small angles.
    #[test]
    fn general_euler_rates_match_the_dcm() {
        let ang = |t: f64| {
            [
                [0.3 * (1.1 * t).sin(), 0.33 * (1.1 * t).cos(), -0.363 * (1.1 * t).sin()],
                [
                    0.2 + 0.1 * (0.7 * t).cos(),
                    -0.07 * (0.7 * t).sin(),
                    -0.049 * (0.7 * t).cos(),
                ],
                [0.5 * t + 0.1 * t * t, 0.5 + 0.2 * t, 0.2],
            ]
        };
        let h = 1e-4;
        for i in 0..50 {
            let t = 0.37 * i as f64;
            let [phi, th, psi] = ang(t);
            let c = dcm_from_rpy(phi[0], th[0], psi[0]);
            let q = UnitQuaternion::from_euler_angles(phi[0], th[0], psi[0]);
            assert!((q.to_rotation_matrix().matrix() - c).norm() < 1e-15);
            let (w, dw) = body_rate_rpy(phi, th, psi);
            let cdot = fd4(
                |x| {
                    let [a, b, y] = ang(x);
                    dcm_from_rpy(a[0], b[0], y[0])
                },
                t,
                h,
            );
            assert!(
                (cdot - c * w.cross_matrix()).norm() < 1e-10,
                "t={t}: {}",
                (cdot - c * w.cross_matrix()).norm()
            );
            let wdot = fd4(
                |x| {
                    let [a, b, y] = ang(x);
                    body_rate_rpy(a, b, y).0
                },
                t,
                h,
            );
            assert!((wdot - dw).norm() < 1e-10, "t={t}: {wdot} vs {dw}");
            // Roll 0: the general relation reduces to the roll-free one.
            let (a, b) = (body_rate_rpy([0.0; 3], th, psi), body_rate(psi, th));
            assert!((a.0 - b.0).norm() == 0.0 && (a.1 - b.1).norm() == 0.0);
            assert!((dcm_from_rpy(0.0, th[0], psi[0]) - dcm_from_pitch_yaw(th[0], psi[0])).norm() == 0.0);
        }
    }

    /// Standing still there is no vibration: the static segments' kinematics equal those of the
    /// smooth trajectory bit for bit; with the vibration off the whole drive does.
    #[test]
    fn no_vibration_at_standstill_and_when_off() {
        let (vib, smooth) = (vibrating_traj(), default_traj());
        let mut cfg = SimConfig::default_drive();
        cfg.set_vibration(false);
        let off = Trajectory::from_config(&cfg.trajectory, cfg.seed);
        assert!(vib.vibration().is_enabled() && !off.vibration().is_enabled());
        let mut statics = 0;
        for i in 0..60_000 {
            let t = 0.01 * i as f64 + 0.003;
            let k = vib.kinematics(t);
            assert_eq!(off.kinematics(t), smooth.kinematics(t), "t={t}");
            if k.speed == [0.0; 3] {
                statics += 1;
                assert_eq!(k.vibration, VibrationState::default(), "t={t}");
                let s = smooth.kinematics(t);
                assert_eq!(
                    (k.c_b_n, k.omega_nb_b, k.omega_nb_b_dot),
                    (s.c_b_n, s.omega_nb_b, s.omega_nb_b_dot)
                );
                assert_eq!((k.v_ned, k.a_ned), (s.v_ned, s.a_ned));
                assert_eq!(k.rpy_rad(), s.rpy_rad());
            } else if k.speed[0] > 5.0 {
                assert!(k.vibration.roll[0] != 0.0 && k.vibration.heave[0] != 0.0, "t={t}");
            }
        }
        // The drive stands still 40 + 20 + 34 s (minus the segments' ends).
        assert!(statics > 9000, "{statics}");
    }

    /// The 60 s cruise at 22 m/s (t = 344…404 s): the RMS of the simulated roll, pitch and
    /// heave and of their rates and accelerations (as they appear in ω_nb^b and a^n) equal the
    /// stationary figures of the configured model at that speed within 5 % (beat terms of a
    /// finite record).
    #[test]
    fn cruise_rms_matches_the_configured_figures() {
        let cfg = SimConfig::default_drive();
        let traj = vibrating_traj();
        let seg = traj
            .segments()
            .iter()
            .find(|s| s.speed.1 == 0.0 && s.heading.1 == 0.0 && s.pitch.1 == 0.0 && s.speed.0 > 21.0)
            .copied()
            .expect("fast cruise");
        let v = seg.speed.0;
        let n = 60_000;
        let mut ms = [0.0; 9];
        for i in 0..n {
            let t = seg.t0 + seg.duration * (i as f64 + 0.5) / n as f64;
            let k = traj.kinematics(t);
            let x = [
                k.rpy_rad()[0],
                k.omega_nb_b[0],
                k.omega_nb_b_dot[0],
                k.rpy_rad()[1],
                k.omega_nb_b[1],
                k.omega_nb_b_dot[1],
                k.vibration.heave[0],
                -k.v_ned[2],
                -k.a_ned[2],
            ];
            for (m, x) in ms.iter_mut().zip(x) {
                *m += x * x / n as f64;
            }
        }
        let r = traj.vibration().rms_at_speed(v);
        let model = [
            r.roll.value,
            r.roll.rate,
            r.roll.acceleration,
            r.pitch.value,
            r.pitch.rate,
            r.pitch.acceleration,
            r.heave.value,
            r.heave.rate,
            r.heave.acceleration,
        ];
        let names = [
            "roll",
            "roll rate",
            "roll acc",
            "pitch",
            "pitch rate",
            "pitch acc",
            "heave",
            "heave rate",
            "heave acc",
        ];
        for ((name, m), want) in names.iter().zip(ms).zip(model) {
            let got = m.sqrt();
            println!("{name:>10}: simulated RMS {got:.4e}, model {want:.4e}");
            assert!((got / want - 1.0).abs() < 0.05, "{name}: {got} vs {want}");
        }
        // The model figures are the configured ones scaled by the envelope at 22 m/s.
        let e = traj.vibration().envelope([v, 0.0, 0.0])[0];
        let vc = &cfg.trajectory.vibration;
        assert!((r.roll.value - e * vc.roll_rms_deg.to_radians()).abs() < 1e-15);
        assert!((r.pitch.value - e * vc.pitch_rms_deg.to_radians()).abs() < 1e-15);
        assert!((r.heave.value - e * vc.heave_rms_m).abs() < 1e-15);
        assert!((1.0..1.1).contains(&e), "envelope at {v} m/s: {e}");
    }

    /// Same configuration and seed, same trajectory; another seed, other phases.
    #[test]
    fn vibration_is_deterministic_in_the_seed() {
        let cfg = SimConfig::default_drive();
        let a = Trajectory::from_config(&cfg.trajectory, cfg.seed);
        let b = Trajectory::from_config(&cfg.trajectory, cfg.seed);
        let c = Trajectory::from_config(&cfg.trajectory, cfg.seed + 1);
        for t in [0.5, 100.0, 250.25, 399.9] {
            assert_eq!(a.kinematics(t), b.kinematics(t));
            assert_eq!(a.position(t), b.position(t));
        }
        assert_ne!(a.kinematics(100.0).c_b_n, c.kinematics(100.0).c_b_n);
    }

    #[test]
    fn quaternion_and_dcm_agree() {
        let traj = vibrating_traj();
        for t in [0.0, 100.0, 222.2, 400.0] {
            let k = traj.kinematics(t);
            let r = k.q_b_n().to_rotation_matrix();
            assert!((r.matrix() - k.c_b_n).norm() < 1e-14);
        }
    }

    #[test]
    fn continuity_across_segment_boundaries() {
        let traj = vibrating_traj();
        for seg in &traj.segments()[..traj.segments().len() - 1] {
            let t = seg.t1();
            let a = traj.kinematics(t - 1e-9);
            let b = traj.kinematics(t + 1e-9);
            assert!((a.a_ned - b.a_ned).norm() < 1e-6);
            assert!((a.omega_nb_b - b.omega_nb_b).norm() < 1e-8);
            assert!((a.omega_nb_b_dot - b.omega_nb_b_dot).norm() < 1e-6);
        }
    }

    /// Numerical error of the position table: the default step (10 ms) against an 8× finer
    /// table, at the nodes and between them. RK4 + Hermite errors scale with h⁴, so the
    /// difference is the default table's error to within 1/4096.
    #[test]
    fn position_table_error_below_a_nanometre() {
        let cfg = SimConfig::default_drive();
        let vib = || Vibration::new(&cfg.trajectory.vibration, cfg.seed);
        let (start, segs) = (&cfg.trajectory.start, &cfg.trajectory.segments);
        let coarse = Trajectory::with_vibration(start, segs, vib(), POSITION_STEP_S);
        let fine = Trajectory::with_vibration(start, segs, vib(), POSITION_STEP_S / 8.0);
        assert!(coarse.vibration().is_enabled());
        let mut worst: f64 = 0.0;
        let n = 200_000;
        for i in 0..=n {
            // Irrational-ish sampling so most points fall between the nodes.
            let t = coarse.duration_s() * (i as f64 + 0.382) / (n as f64 + 1.0);
            worst = worst.max(dist(coarse.origin, coarse.position_offset(t), fine.position_offset(t)));
        }
        println!("position table error (10 ms RK4 + Hermite vs 1.25 ms): {worst:.3e} m");
        assert!(worst < 1e-9, "worst position error {worst} m");
    }

    #[test]
    fn straight_north_run_matches_meridian_arc() {
        // 100 s due north at 20 m/s from 45°: the arc length ∫ R_M dφ must be 2000 m.
        let start = StartConfig {
            lat_deg: 45.0,
            lon_deg: 7.0,
            height_m: 0.0,
            heading_deg: 0.0,
            pitch_deg: 0.0,
            speed_mps: 20.0,
        };
        let segs = [SegmentConfig {
            kind: SegmentKind::Cruise,
            duration_s: 100.0,
            to_speed_mps: None,
            heading_change_deg: None,
            to_pitch_deg: None,
        }];
        let traj = Trajectory::new(&start, &segs);
        let p = traj.position(100.0);
        // Simpson integration of R_M over the latitude interval.
        let (a, b) = (45f64.to_radians(), p[0]);
        let n = 100;
        let hh = (b - a) / n as f64;
        let mut s = earth::radii(a).0 + earth::radii(b).0;
        for i in 1..n {
            s += if i % 2 == 1 { 4.0 } else { 2.0 } * earth::radii(a + i as f64 * hh).0;
        }
        let arc = s * hh / 3.0;
        assert!((arc - 2000.0).abs() < 1e-8, "arc {arc}");
        assert!((p[1] - 7f64.to_radians()).abs() < 1e-15 && p[2].abs() < 1e-12);
    }

    #[test]
    fn boundaries_in_interval() {
        let traj = vibrating_traj();
        let t1 = traj.segments()[0].t1();
        let mut buf = [0.0; 4];
        assert_eq!(traj.boundaries_in(t1 - 0.001, t1 + 0.001, &mut buf), 1);
        assert_eq!(buf[0], t1);
        assert_eq!(traj.boundaries_in(t1, t1 + 0.001, &mut buf), 0);
    }
}
