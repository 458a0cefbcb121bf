//! The delayed filter of the fusion horizon: strapdown mechanization at the IMU rate,
//! covariance propagation every ~20 ms, closed-loop feedback of the error-state estimates.

use nalgebra::{UnitQuaternion, Vector3};
use navsync_wire::earth;

use super::config::NavConfig;
use super::error_state::{
    self, ATT, BA, BG, CLK_BIAS, CLK_DRIFT, DELAY, ISB, ISB_SYSTEMS, POS, SA, SG, StateMat, StateVec, VEL,
};
use super::eskf::Eskf;
use super::imu_buffer::ImuRecord;
use super::mechanization::{ImuIncrement, Pva, propagate};

/// A horizontal speed estimate this many σ above zero makes the GNSS delay observable
/// ([`DelayedFilter::delay_observable`]).
pub const DELAY_SPEED_SIGMAS: f64 = 3.0;

/// What the doubt on Δ adds to the published variances (the covariance P itself unchanged):
/// Δ's own, and each state's share through P's regression on Δ, (P_iΔ / P_ΔΔ)² · doubt (a Δ
/// off by δΔ leaves position, velocity and attitude off by their regression on it: for the
/// position −v·δΔ, a fix taken for an instant δΔ away, [`super::measurements::gnss`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DelayDoubt {
    /// Added to Δ's variance, s².
    pub delay_s2: f64,
    /// Added to the position's variance N, E, D, m².
    pub pos_m2: Vector3<f64>,
    /// Added to the velocity's variance N, E, D, (m/s)².
    pub vel_m2ps2: Vector3<f64>,
    /// Added to the attitude error's variance (NED axes), rad².
    pub att_rad2: Vector3<f64>,
}

impl DelayDoubt {
    /// The doubt `delay_s2` (s²) on Δ carried to the states by covariance `p`.
    pub fn from_covariance(p: &StateMat, delay_s2: f64) -> Self {
        let p_dd = p[(DELAY, DELAY)];
        if !(delay_s2 > 0.0 && p_dd > 0.0) {
            return Self::default();
        }
        let share = |i: usize| Vector3::from_fn(|k, _| (p[(i + k, DELAY)] / p_dd).powi(2) * delay_s2);
        Self {
            delay_s2,
            pos_m2: share(POS),
            vel_m2ps2: share(VEL),
            att_rad2: share(ATT),
        }
    }

    /// σ's `std` with `add` (variances) added.
    pub fn widen(std: [f64; 3], add: &Vector3<f64>) -> [f64; 3] {
        std::array::from_fn(|i| (std[i] * std[i] + add[i]).sqrt())
    }

    /// Δ's σ `std_s` with the doubt added, s.
    pub fn delay_std_s(&self, std_s: f64) -> f64 {
        (std_s * std_s + self.delay_s2).sqrt()
    }
}

/// The published position σ per axis (NED, m) of a state whose covariance gives `std_m`: times
/// the filter's [`DelayedFilter::sigma_scale`], with Δ's doubt, and at least the floor
/// ([`DelayedFilter::pos_floor_std_ned_m`]).
pub fn published_pos_std_ned_m(
    std_m: [f64; 3],
    sigma_scale: f64,
    floor_m: &Vector3<f64>,
    doubt: &DelayDoubt,
) -> [f64; 3] {
    let widened = DelayDoubt::widen(std_m.map(|s| s * sigma_scale), &doubt.pos_m2);
    std::array::from_fn(|i| widened[i].max(floor_m[i]))
}

/// The delayed filter: the navigation state at the delayed time (the fusion horizon behind
/// the present), its error covariance and the sensor-error and GNSS-delay estimates. The
/// measurements ([`super::measurements`]) fuse into it at their epochs.
#[derive(Debug, Clone)]
pub struct DelayedFilter {
    /// Position, velocity, attitude at [`t_ns`](Self::t_ns).
    pub pva: Pva,
    /// The last IMU increment (coning/sculling of the next step).
    pub pre: ImuIncrement,
    /// Host time of the state, ns.
    pub t_ns: i64,
    /// The error-state covariance.
    pub eskf: Eskf,
    /// Gyro bias estimate (body FRD), rad/s.
    pub bias_g: Vector3<f64>,
    /// Accelerometer bias estimate (body FRD), m/s².
    pub bias_a: Vector3<f64>,
    /// Gyro scale-factor estimate.
    pub scale_g: Vector3<f64>,
    /// Accelerometer scale-factor estimate.
    pub scale_a: Vector3<f64>,
    /// GNSS delay estimate Δ̂, s.
    pub delay_s: f64,
    /// Receiver clock bias estimate c·δt_r at [`t_ns`](Self::t_ns), m (tightly coupled; the
    /// receiver's time minus GPS time, times c).
    pub clock_bias_m: f64,
    /// Receiver clock drift estimate c·δṫ_r, m/s.
    pub clock_drift_mps: f64,
    /// The clock states hold an estimate (set by the first tightly coupled measurement).
    pub clock_valid: bool,
    /// Inter-system bias estimates of the receiver clock (Galileo, BeiDou) minus GPS's, m
    /// ([`error_state::ISB`]).
    pub isb_m: [f64; ISB_SYSTEMS],
    /// Which inter-system biases hold an estimate (set by their system's first measurement).
    pub isb_valid: [bool; ISB_SYSTEMS],
    /// The published position σ's floor N, E, D, m: the σ of the last single-point solution
    /// from the satellites the filter fuses (tightly coupled, or loosely on navsync's own
    /// solution), zero on a receiver's fixes. Errors that persist across epochs (broadcast
    /// orbit and clock, the atmosphere the models leave, multipath) are fused as if
    /// independent, so the covariance P shrinks below what they allow; the floor is their
    /// consider covariance (Schmidt 1966) taken as one epoch's snapshot. P itself is not
    /// changed (the gates and gains stay the filter's).
    pub pos_floor_std_ned_m: Vector3<f64>,
    /// The published receiver-clock σ's floor, m: the σ of the same solution's clock, for
    /// the same reason.
    pub clock_floor_std_m: f64,
    /// The factor on the published position, velocity and attitude σ, ≥ 1: √ of the running
    /// NIS per component of the GNSS updates when above 1 (set by the navigator's monitor).
    /// Innovations k² times larger than the filter predicts show its covariance k times too
    /// small (the innovation-based consistency test, Bar-Shalom, Li & Kirubarajan 2001, §5.4;
    /// Mehra 1972's covariance matching): what the data say of the σ is published even where
    /// the filter's gains keep the model (its own adaptation, `GnssFusion::adapt_process_noise`,
    /// is off by default). Kept with the state, so the smoothed output gets it too.
    pub sigma_scale: f64,
    /// What the published σ's add for the doubt on Δ: what the estimate's dependence on its
    /// prior shows P_ΔΔ to claim beyond the data (the navigator's prior-shifted shadow,
    /// [`super::navigator::SHADOW_MIN_PRIOR_STD_S`]). P itself is not changed.
    pub delay_doubt: DelayDoubt,
    /// Sum of the position corrections fed back so far, NED, m (the change of the position
    /// estimate that is not motion: time-differenced carrier phases take it out).
    pub pos_corrections_ned_m: Vector3<f64>,
    /// NED acceleration over the last step, m/s².
    pub acc_ned: Vector3<f64>,
    /// Compensated angular rate of the last step (body FRD), rad/s.
    pub last_w: Vector3<f64>,
    /// Factor on the IMU's process noise, ≥ 1: raised when the GNSS innovations show the
    /// configured model too optimistic ([`super::measurements::gnss::GnssFusion`]).
    pub q_scale: f64,
    /// Factor on the receiver oscillator's random-walk FM, ≥ 1: raised when the clock drift
    /// the ranges show changes more than the oscillator model allows
    /// ([`super::measurements::ranges::ClockWatch`]).
    pub clock_q_scale: f64,
    /// Covariance propagations so far.
    pub propagations: u64,
    /// The transition Φ of the last propagation (for the offline smoother).
    pub last_phi: StateMat,
    cov_dt: f64,
    cov_f: Vector3<f64>,
    cov_w: Vector3<f64>,
}

impl DelayedFilter {
    /// A filter at `pva` and host time `t_ns` with covariance `eskf`, gyro bias `bias_g`
    /// (rad/s), GNSS delay `delay_s` (s), the other sensor errors zero.
    pub fn new(pva: Pva, t_ns: i64, eskf: Eskf, bias_g: Vector3<f64>, delay_s: f64) -> Self {
        Self {
            pva,
            pre: ImuIncrement::zero(),
            t_ns,
            eskf,
            bias_g,
            bias_a: Vector3::zeros(),
            scale_g: Vector3::zeros(),
            scale_a: Vector3::zeros(),
            delay_s,
            clock_bias_m: 0.0,
            clock_drift_mps: 0.0,
            clock_valid: false,
            isb_m: [0.0; ISB_SYSTEMS],
            isb_valid: [false; ISB_SYSTEMS],
            pos_floor_std_ned_m: Vector3::zeros(),
            clock_floor_std_m: 0.0,
            sigma_scale: 1.0,
            delay_doubt: DelayDoubt::default(),
            pos_corrections_ned_m: Vector3::zeros(),
            acc_ned: Vector3::zeros(),
            last_w: Vector3::zeros(),
            q_scale: 1.0,
            clock_q_scale: 1.0,
            propagations: 0,
            last_phi: StateMat::identity(),
            cov_dt: 0.0,
            cov_f: Vector3::zeros(),
            cov_w: Vector3::zeros(),
        }
    }

    /// Bias- and scale-compensated rates of a record (KF-GINS `imuCompensate`).
    pub fn compensate(&self, r: &ImuRecord) -> (Vector3<f64>, Vector3<f64>) {
        let w = (r.gyro_rps - self.bias_g).component_div(&(Vector3::repeat(1.0) + self.scale_g));
        let f = (r.accel_mps2 - self.bias_a).component_div(&(Vector3::repeat(1.0) + self.scale_a));
        (w, f)
    }

    pub(crate) fn step(&mut self, r: &ImuRecord, cfg: &NavConfig) {
        let (w, f) = self.compensate(r);
        let inc = ImuIncrement::from_rates(r.dt_s, w, f);
        let v0 = self.pva.vel_ned_mps;
        self.pva = propagate(&self.pva, &self.pre, &inc);
        self.pre = inc;
        if self.clock_valid {
            self.clock_bias_m += self.clock_drift_mps * (r.host_ns - self.t_ns) as f64 * 1e-9;
        }
        self.t_ns = r.host_ns;
        if r.dt_s > 0.0 {
            self.acc_ned = (self.pva.vel_ned_mps - v0) / r.dt_s;
        }
        self.last_w = w;
        self.cov_dt += r.dt_s;
        self.cov_f += f * r.dt_s;
        self.cov_w += w * r.dt_s;
        if self.cov_dt >= cfg.cov_step_s {
            self.propagate_covariance(cfg);
        }
    }

    /// P ← Φ P Φᵀ + Q over the accumulated interval, Φ = I + F·Δt with F at the current state
    /// and the interval-mean rates (KF-GINS propagates per IMU sample; grouping ~20 ms keeps the
    /// cost per sample low and changes Φ by O((F·Δt)²)).
    pub fn propagate_covariance(&mut self, cfg: &NavConfig) {
        if self.cov_dt <= 0.0 {
            return;
        }
        let f_b = self.cov_f / self.cov_dt;
        let w_b = self.cov_w / self.cov_dt;
        let f = error_state::system_matrix(&self.pva, &f_b, &w_b, &cfg.noise);
        let phi = StateMat::identity() + f * self.cov_dt;
        let c_bn = self.pva.q_nb.to_rotation_matrix().into_inner();
        let mut noise = cfg.noise;
        noise.clock = noise.clock.map(|o| o.with_random_walk_fm_scaled(self.clock_q_scale));
        let q = error_state::process_noise(&noise, &c_bn, self.cov_dt, self.q_scale);
        self.eskf.predict(&phi, &q);
        self.propagations += 1;
        self.last_phi = phi;
        self.cov_dt = 0.0;
        self.cov_f = Vector3::zeros();
        self.cov_w = Vector3::zeros();
    }

    /// Whether a GNSS measurement tells anything of the delay Δ: Δ enters it only as v·Δ (a
    /// position) or a·Δ (a velocity), so only while the horizontal speed estimate stands out of
    /// its own uncertainty (more than [`DELAY_SPEED_SIGMAS`] σ). Below, the Jacobian would be
    /// made of the velocity estimate's noise, and the filter would read information on Δ into
    /// a standing vehicle's fixes (the EKF's spurious observability: Huang, Mourikis &
    /// Roumeliotis 2010) and move Δ on it with a shrinking σ.
    pub fn delay_observable(&self) -> bool {
        let v = self.pva.vel_ned_mps;
        let var_h = self.eskf.p[(VEL, VEL)] + self.eskf.p[(VEL + 1, VEL + 1)];
        v.x * v.x + v.y * v.y > DELAY_SPEED_SIGMAS * DELAY_SPEED_SIGMAS * var_h
    }

    /// Runs `update` (one measurement's updates) with Δ held as a consider state
    /// ([`Eskf::held`]) while it is not [`delay_observable`](Self::delay_observable): a
    /// standing start's position and velocity are correlated with Δ through a velocity that is
    /// the fixes' noise, and each standing fix would otherwise move Δ through that correlation
    /// and shrink its σ (a car standing 30 s with 1 cm fixes at 10 Hz: Δ from 0.5 to 1.95 s
    /// with σ 1 ms, and the heading bank, linearised there, decided a heading 149° off with σ
    /// 1°). For the fixes only: a zero-velocity update informs Δ through those correlations
    /// rightly (the instant a vehicle stops is the IMU's, and the fixes see it Δ later).
    pub fn with_unobservable_delay_held<T>(&mut self, update: impl FnOnce(&mut Self) -> T) -> T {
        self.eskf.held = (!self.delay_observable()).then_some(DELAY);
        let out = update(self);
        self.eskf.held = None;
        out
    }

    /// Closed-loop feedback of an error-state estimate (KF-GINS `stateFeedback`).
    pub fn feedback(&mut self, dx: &StateVec, horizon_s: f64) {
        let (rm, rn) = earth::radii(self.pva.lat_rad);
        self.pva.lat_rad -= dx[POS] / (rm + self.pva.h_m);
        self.pva.lon_rad -= dx[POS + 1] / ((rn + self.pva.h_m) * self.pva.lat_rad.cos());
        self.pva.h_m += dx[POS + 2];
        self.pos_corrections_ned_m -= dx.fixed_rows::<3>(POS);
        self.pva.vel_ned_mps -= dx.fixed_rows::<3>(VEL);
        let q_pn = UnitQuaternion::from_scaled_axis(dx.fixed_rows::<3>(ATT).into_owned());
        self.pva.q_nb = UnitQuaternion::new_normalize((q_pn * self.pva.q_nb).into_inner());
        self.bias_g += dx.fixed_rows::<3>(BG);
        self.bias_a += dx.fixed_rows::<3>(BA);
        self.scale_g += dx.fixed_rows::<3>(SG);
        self.scale_a += dx.fixed_rows::<3>(SA);
        self.delay_s = (self.delay_s + dx[DELAY]).clamp(
            super::navigator::MIN_DELAY_S,
            horizon_s - super::navigator::DELAY_HORIZON_MARGIN_S,
        );
        self.clock_bias_m += dx[CLK_BIAS];
        self.clock_drift_mps += dx[CLK_DRIFT];
        for (k, b) in self.isb_m.iter_mut().enumerate() {
            *b += dx[ISB + k];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::UnitQuaternion;

    fn filter(speed_mps: f64, vel_std_mps: f64) -> DelayedFilter {
        let pva = Pva {
            lat_rad: 0.8,
            lon_rad: 0.2,
            h_m: 100.0,
            vel_ned_mps: Vector3::new(speed_mps, 0.0, 0.0),
            q_nb: UnitQuaternion::identity(),
        };
        let mut p = StateMat::identity() * 1e-4;
        for i in VEL..VEL + 3 {
            p[(i, i)] = vel_std_mps * vel_std_mps;
        }
        DelayedFilter::new(pva, 0, Eskf::new(p), Vector3::zeros(), 0.5)
    }

    /// A standing vehicle's velocity estimate is its own noise: no Δ column from it; a moving
    /// one's speed well out of its σ makes Δ observable.
    #[test]
    fn the_delay_is_observable_only_when_the_speed_stands_out_of_its_sigma() {
        assert!(!filter(0.02, 0.03).delay_observable());
        assert!(!filter(0.1, 0.03).delay_observable());
        assert!(filter(0.2, 0.03).delay_observable());
        assert!(filter(1.2, 0.05).delay_observable());
    }
}
