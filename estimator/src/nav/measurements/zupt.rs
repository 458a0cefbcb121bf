//! Zero-velocity update (ZUPT) with zero angular rate (ZARU): while the vehicle stands still,
//! its velocity is zero and its body turns only with the Earth, so the gyros measure their
//! own bias. A [`Measurement`] the IMU data itself produces.
//!
//! Detection, on the delayed filter's IMU stream (so a stop is fused where it happened): the
//! stream is cut into windows of `window_s`; a window is *still* when the standard deviation of
//! the specific force (root of the trace of its covariance) is below `accel_std_mps2` (a moving
//! car vibrates, a parked one hardly), the mean bias-compensated angular rate is below
//! `gyro_rps`, the mean specific force is the previous window's within `accel_change_mps2`
//! (no acceleration building up: a car moving off or coming to a stop changes it, however
//! smoothly), and the filter's own speed is below `speed_mps` (a car cruising on a smooth road
//! can look still to an IMU; the filter knows it is moving). After `still_windows` still
//! windows in a row, every further still window yields one update at its end (Groves 2013,
//! §15.3: ZUPT and ZARU as Kalman filter measurements):
//!
//! - velocity: dz = v̂ − 0 = δv, H = [0, I₃, 0, …], R = σ_v² I (the body sways by mm/s);
//! - angular rate: dz = ω̄ − C_n^b ω_ie^n with ω̄ the window's mean compensated rate; since
//!   ω̄ = ω_true + (b − b̂) and ω_true = C_n^b ω_ie^n at rest, dz = δb_g (true − estimated, as
//!   the filter's bias states): H = [0, …, I₃ (gyro bias), …], R = max(σ̂/√n, floor)² I with σ̂
//!   the window's per-sample rate scatter (vibration included).
//!
//! Both are gated like every measurement (99.9 % chi-square) and counted (`zupt_used`,
//! `zupt_rejected`).

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use navsync_wire::earth;

use super::Measurement;
use crate::nav::error_state::{ATT, BG, N, VEL};
use crate::nav::mechanization::skew;
use crate::nav::eskf::Update;
use crate::nav::filter::DelayedFilter;
use crate::nav::imu_buffer::ImuRecord;
use crate::nav::config::NavConfig;

crate::settings_group! {
    /// Settings of the standstill updates.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct ZuptConfig {
        /// Zero-velocity and zero-angular-rate updates while the vehicle stands still.
        pub zupt: bool = true, file "estimator", switch "no-zupt" => false;
        /// Length of a detection window, s (default 0.5).
        pub window_s: f64 = 0.5;
        /// Largest specific-force scatter of a still window, m/s² (default 0.25: above a parked
        /// car's engine vibration, below a moving car's).
        pub accel_std_mps2: f64 = 0.25;
        /// Largest mean compensated angular rate of a still window, rad/s (default 1°/s).
        pub gyro_rps: f64 = 1f64.to_radians();
        /// Largest change of the mean specific force from the previous window, m/s² (default
        /// 0.03: a standing vehicle's mean is constant; an acceleration building up moves it).
        pub accel_change_mps2: f64 = 0.03;
        /// Largest filter speed at which a window may count as still, m/s (default 0.15).
        pub speed_mps: f64 = 0.15;
        /// Still windows in a row before the first update (default 2: one second).
        pub still_windows: u32 = 2;
        /// 1-sigma of the zero velocity, m/s (default 0.02).
        pub vel_std_mps: f64 = 0.02;
        /// Smallest 1-sigma of the window's mean angular rate, rad/s (default 2e-4, 41°/h).
        pub rate_std_floor_rps: f64 = 2e-4;
    }
}


/// Sums of the current detection window.
#[derive(Debug, Clone, Copy, Default)]
struct Window {
    n: u32,
    t_s: f64,
    sum_f: Vector3<f64>,
    sum_ff: Vector3<f64>,
    sum_w: Vector3<f64>,
    sum_ww: Vector3<f64>,
    max_speed: f64,
}

/// The detector's state and counters.
#[derive(Debug, Clone, Copy, Default)]
pub struct ZuptState {
    window: Window,
    /// Mean specific force of the previous window (body FRD), m/s².
    previous_mean_f: Option<Vector3<f64>>,
    still_in_a_row: u32,
    /// Updates fused.
    pub used: u64,
    /// Updates the gate rejected.
    pub rejected: u64,
}

/// One standstill update: at host time `t_ns` the window's mean compensated angular rate
/// (body FRD, rad/s) and its 1-sigma.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Zupt {
    /// End of the still window, host ns.
    pub t_ns: i64,
    /// Mean compensated angular rate over the window (body FRD), rad/s.
    pub mean_rate_rps: Vector3<f64>,
    /// 1-sigma of that mean per axis, rad/s.
    pub rate_std_rps: f64,
}

impl Measurement for Zupt {
    type Config = ZuptConfig;
    type State = ZuptState;

    fn epoch_ns(&self, _delay_s: f64) -> i64 {
        self.t_ns
    }

    fn fuse(&self, f: &mut DelayedFilter, _eps_s: f64, cfg: &NavConfig, z: &ZuptConfig, state: &mut ZuptState) -> bool {
        let c_nb = f.pva.q_nb.inverse().to_rotation_matrix().into_inner();
        let w_ie_n = Vector3::from(earth::omega_ie_n(f.pva.lat_rad));
        let w_ie_b = c_nb * w_ie_n;
        let mut dz = SVector::<f64, 6>::zeros();
        dz.fixed_rows_mut::<3>(0).copy_from(&f.pva.vel_ned_mps);
        dz.fixed_rows_mut::<3>(3).copy_from(&(self.mean_rate_rps - w_ie_b));
        let mut h = SMatrix::<f64, 6, N>::zeros();
        h.fixed_view_mut::<3, 3>(0, VEL).copy_from(&Matrix3::identity());
        h.fixed_view_mut::<3, 3>(3, BG).copy_from(&Matrix3::identity());
        // The earth rate the body sees depends on the attitude: with C_b^n = (I + [φ×]) Ĉ_b^n,
        // ω_ie^b = Ĉ_n^b ω_ie^n + Ĉ_n^b [ω_ie^n×] φ (the gyrocompassing term, Groves 2013
        // §5.6.2). Leaving it out would let a standstill pin the gyro bias to a wrong heading.
        h.fixed_view_mut::<3, 3>(3, ATT).copy_from(&(c_nb * skew(&w_ie_n)));
        let mut r = SMatrix::<f64, 6, 6>::zeros();
        for i in 0..3 {
            r[(i, i)] = z.vel_std_mps.powi(2);
            r[(3 + i, 3 + i)] = self.rate_std_rps.powi(2);
        }
        match f.eskf.update(&dz, &h, &r, cfg.gate_scale) {
            Update::Accepted { dx, .. } => {
                f.feedback(&dx, cfg.fusion_horizon_s);
                state.used += 1;
                true
            }
            Update::Rejected { .. } => {
                state.rejected += 1;
                false
            }
        }
    }

    fn on_step(rec: &ImuRecord, f: &DelayedFilter, _cfg: &NavConfig, z: &ZuptConfig, state: &mut ZuptState) -> Option<Self> {
        if !z.zupt {
            return None;
        }
        let (w, acc) = f.compensate(rec);
        let win = &mut state.window;
        win.n += 1;
        win.t_s += rec.dt_s;
        win.sum_f += acc;
        win.sum_ff += acc.component_mul(&acc);
        win.sum_w += w;
        win.sum_ww += w.component_mul(&w);
        win.max_speed = win.max_speed.max(f.pva.vel_ned_mps.norm());
        if win.t_s < z.window_s {
            return None;
        }
        let win = std::mem::take(&mut state.window);
        let n = f64::from(win.n);
        let var = |sum: Vector3<f64>, sum_sq: Vector3<f64>| (sum_sq / n - (sum / n).component_mul(&(sum / n))).sum().max(0.0);
        let mean_w = win.sum_w / n;
        let mean_f = win.sum_f / n;
        let steady = state
            .previous_mean_f
            .replace(mean_f)
            .is_some_and(|p| (mean_f - p).norm() < z.accel_change_mps2);
        let still = var(win.sum_f, win.sum_ff).sqrt() < z.accel_std_mps2
            && mean_w.norm() < z.gyro_rps
            && steady
            && win.max_speed < z.speed_mps;
        if !still {
            state.still_in_a_row = 0;
            return None;
        }
        state.still_in_a_row += 1;
        if state.still_in_a_row < z.still_windows {
            return None;
        }
        let rate_scatter = (var(win.sum_w, win.sum_ww) / 3.0).sqrt();
        Some(Zupt {
            t_ns: f.t_ns,
            mean_rate_rps: mean_w,
            rate_std_rps: (rate_scatter / n.sqrt()).max(z.rate_std_floor_rps),
        })
    }

    fn counters(state: &ZuptState, out: &mut dyn FnMut(&'static str, u64)) {
        out("zupt_used", state.used);
        out("zupt_rejected", state.rejected);
    }
}
