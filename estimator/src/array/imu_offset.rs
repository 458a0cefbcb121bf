//! Online estimation of one IMU's time offset Td relative to the reference IMU of an array,
//! from the rigid-body relation between their measurements.
//!
//! Model. IMU i's samples are stamped Td late: the sample stamped t measured the motion at
//! t − Td. A rigid body has one angular rate, so after the mounting rotation IMU i's gyro reads
//! ω_i(t) = ω_0(t − Td) + Δb_g (Δb_g = b_g,i − b_g,0, its bias relative to the reference), and
//! its accelerometer f_i(t) = f_0(t − Td) + ω̇×r + ω×(ω×r) + Δb_a (r = lever arm from the
//! reference to IMU i, body frame; the lever terms are removed before this filter sees f).
//! Interpolating IMU i at the reference instant τ shifted by the current estimate T̂d and
//! linearising x_0(τ − δ) ≈ x_0(τ) − ẋ_0(τ)·δ with δ = Td − T̂d gives the measurement
//!
//!   r = x_i(τ + T̂d) − x_0(τ) = −ẋ_0(τ)·δ + Δb + n,   H = [−ẋ_0, I₃]  (per sensor triad),
//!
//! fused in a 13-state Kalman filter x = [Td, Δb_g, Δb_a, Δs_g, Δs_a]: the IMUs' scale factors
//! differ too (Δs = s_i − s_0, per axis), which adds diag(ω_0)·Δs_g and diag(f_0)·Δs_a to the
//! residuals; left out, a scale difference in a turn correlates with ω̇ and biases Td. The published approach (difference
//! of two IMUs' navigation solutions, s(kT − Td) ≈ s_k − v_k·Td + a_k·Td²/2) observes Td only
//! through velocity and position, i.e. after two integrations of the sensor noise; comparing
//! the raw rates observes it through the rate derivatives directly, and needs no navigation
//! solution per IMU.
//!
//! Observability: Td is visible only while the motion changes (ω̇ ≠ 0 or ḟ ≠ 0). While the
//! smoothed information rate ‖ω̇‖²/σ_ω² + ‖ḟ‖²/σ_f² stays below a multiple of what the
//! differentiator's own noise produces (a parked or cruising vehicle without vibration), the Td
//! column of H is zeroed: Td is frozen (and flagged unobservable) while the relative biases keep
//! being estimated.

use nalgebra::{SMatrix, SVector, Vector3};

/// State dimension: Td, relative gyro and accelerometer biases and scale factors.
const M: usize = 13;
type Vec7 = SVector<f64, M>;
type Mat7 = SMatrix<f64, M, M>;

/// Settings of one offset filter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OffsetConfig {
    /// Prior of Td, s, and its 1-sigma.
    pub td_prior_s: f64,
    /// 1-sigma of the Td prior, s.
    pub td_prior_std_s: f64,
    /// Random walk of Td, s/√s (a nearly constant offset).
    pub td_rw: f64,
    /// Prior 1-sigma of the relative gyro bias, rad/s.
    pub gyro_bias_std: f64,
    /// Prior 1-sigma of the relative accelerometer bias, m/s².
    pub accel_bias_std: f64,
    /// Random walk of the relative gyro bias, rad/s/√s.
    pub gyro_bias_rw: f64,
    /// Random walk of the relative accelerometer bias, m/s²/√s.
    pub accel_bias_rw: f64,
    /// Prior 1-sigma of the relative gyro scale factor.
    pub gyro_scale_std: f64,
    /// Prior 1-sigma of the relative accelerometer scale factor.
    pub accel_scale_std: f64,
    /// Td is frozen while the smoothed information ‖ω̇‖²/σ_ω² + ‖ḟ‖²/σ_f² (1/s²) is below this
    /// many times what the differentiator's noise alone produces.
    pub min_information_ratio: f64,
}

/// The estimated error of the fractional-delay interpolation of one comparison, per component
/// (gyro, then accelerometer): its value (with the sample noise in it) and its variance without
/// the noise's share.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct InterpolationError {
    /// The error's estimate (rad/s, m/s²).
    pub value: SVector<f64, 6>,
    /// Its square without the sample noise's share.
    pub variance: SVector<f64, 6>,
}

/// Outcome of one comparison.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OffsetUpdate {
    /// Fused; normalised innovation squared.
    Accepted(f64),
    /// Innovation beyond the 99.9 % gate (6 dof): the IMUs disagree.
    Rejected(f64),
}

/// 99.9 % chi-square quantile, 6 degrees of freedom.
const GATE_6: f64 = 22.46;

/// The per-IMU offset and relative-bias filter.
#[derive(Debug, Clone)]
pub struct OffsetFilter {
    cfg: OffsetConfig,
    x: Vec7,
    p: Mat7,
    info_ema: f64,
    noise_info: f64,
    updates: u64,
    /// Smoothed Σ(e·ẋ/σ²) of the interpolation error and Σ(ẋ/σ)² of the regressor (Td's bias).
    interp_num_ema: f64,
    interp_den_ema: f64,
}

impl OffsetFilter {
    /// A filter at its prior.
    pub fn new(cfg: OffsetConfig) -> Self {
        let mut p = Mat7::zeros();
        p[(0, 0)] = cfg.td_prior_std_s.powi(2);
        for i in 1..4 {
            p[(i, i)] = cfg.gyro_bias_std.powi(2);
            p[(i + 3, i + 3)] = cfg.accel_bias_std.powi(2);
            p[(i + 6, i + 6)] = cfg.gyro_scale_std.powi(2);
            p[(i + 9, i + 9)] = cfg.accel_scale_std.powi(2);
        }
        let mut x = Vec7::zeros();
        x[0] = cfg.td_prior_s;
        Self {
            cfg,
            x,
            p,
            info_ema: 0.0,
            noise_info: f64::INFINITY,
            updates: 0,
            interp_num_ema: 0.0,
            interp_den_ema: 0.0,
        }
    }

    /// The filter of a reference that was replaced by this filter's IMU (array handover). The
    /// promoted IMU's samples are put into the array's reference terms with this filter's
    /// estimates, so the replaced IMU relative to them has the state it has relative to the
    /// terms: zero when it defined them (`own` = None), else its own frozen estimates `own`;
    /// uncertain by its own covariance plus this filter's (the correction's error).
    pub fn for_replaced_reference(&self, own: Option<&Self>) -> Self {
        match own {
            Some(o) => Self {
                p: o.p + self.p,
                ..o.clone()
            },
            None => Self {
                x: Vec7::zeros(),
                ..self.clone()
            },
        }
    }

    /// Puts Td at an acquisition's value with its 1-sigma (inside the linearisation's capture
    /// range, see [`ImuArray`](super::imu_array::ImuArray)); Td's correlations with the other
    /// states are dropped, which leaves P positive definite.
    pub fn reacquire(&mut self, td_s: f64, td_std_s: f64) {
        self.x[0] = td_s;
        for k in 1..M {
            self.p[(0, k)] = 0.0;
            self.p[(k, 0)] = 0.0;
        }
        self.p[(0, 0)] = td_std_s * td_std_s;
        self.interp_num_ema = 0.0;
        self.interp_den_ema = 0.0;
    }

    /// Estimated offset Td, s.
    pub fn td_s(&self) -> f64 {
        self.x[0]
    }

    /// 1-sigma of Td, s: the filter's, with the bias the interpolation's error can put on Td
    /// (see [`update`](Self::update)) added in quadrature.
    pub fn td_std_s(&self) -> f64 {
        let bias = if self.interp_den_ema > 0.0 {
            self.interp_num_ema / self.interp_den_ema
        } else {
            0.0
        };
        (self.p[(0, 0)].max(0.0) + bias * bias).sqrt()
    }

    /// Estimated relative gyro bias (IMU − reference), body axes, rad/s.
    pub fn gyro_bias(&self) -> Vector3<f64> {
        Vector3::new(self.x[1], self.x[2], self.x[3])
    }

    /// Estimated relative accelerometer bias, body axes, m/s².
    pub fn accel_bias(&self) -> Vector3<f64> {
        Vector3::new(self.x[4], self.x[5], self.x[6])
    }

    /// Estimated relative gyro scale factor (IMU − reference), per body axis.
    pub fn gyro_scale(&self) -> Vector3<f64> {
        Vector3::new(self.x[7], self.x[8], self.x[9])
    }

    /// Estimated relative accelerometer scale factor, per body axis.
    pub fn accel_scale(&self) -> Vector3<f64> {
        Vector3::new(self.x[10], self.x[11], self.x[12])
    }

    /// The filter's prediction of r = x_i(τ + T̂d) − x_0(τ) at a reference instant with rates
    /// `w`, `f` and derivatives `w_dot`, `f_dot`, and the variance of that prediction per
    /// component (from P: bias, scale and the offset's alignment error ẋ·δTd). Subtracting the
    /// prediction turns IMU i's aligned sample into the reference IMU's terms.
    pub fn predicted_residual(
        &self,
        w: &Vector3<f64>,
        f: &Vector3<f64>,
        w_dot: &Vector3<f64>,
        f_dot: &Vector3<f64>,
    ) -> (SVector<f64, 6>, SVector<f64, 6>) {
        let mut h = SMatrix::<f64, 6, M>::zeros();
        for k in 0..3 {
            h[(k, 0)] = -w_dot[k];
            h[(k + 3, 0)] = -f_dot[k];
            h[(k, 1 + k)] = 1.0;
            h[(k + 3, 4 + k)] = 1.0;
            h[(k, 7 + k)] = w[k];
            h[(k + 3, 10 + k)] = f[k];
        }
        let mut r_hat = h * self.x;
        for k in 0..6 {
            r_hat[k] -= h[(k, 0)] * self.x[0];
        }
        let hp = h * self.p;
        let var = SVector::<f64, 6>::from_fn(|k, _| (hp.row(k) * h.row(k).transpose())[(0, 0)].max(0.0));
        (r_hat, var)
    }

    /// True while the motion makes Td observable (see the module docs).
    pub fn observable(&self) -> bool {
        self.info_ema >= self.cfg.min_information_ratio * self.noise_info
    }

    /// Comparisons fused so far.
    pub fn updates(&self) -> u64 {
        self.updates
    }

    /// Propagates over `dt_s` (random walks).
    pub fn predict(&mut self, dt_s: f64) {
        self.p[(0, 0)] += self.cfg.td_rw.powi(2) * dt_s;
        for i in 1..4 {
            self.p[(i, i)] += self.cfg.gyro_bias_rw.powi(2) * dt_s;
            self.p[(i + 3, i + 3)] += self.cfg.accel_bias_rw.powi(2) * dt_s;
        }
    }

    /// Fuses one comparison at a reference instant: gyro and accelerometer residuals
    /// r = x_i(τ + T̂d) − x_0(τ) (body axes), the reference's rates x_0(τ) (`w`, `f`) and their
    /// derivatives ẋ_0(τ), the
    /// 1-sigma of one residual component (both IMUs' sample noise), the variances of one
    /// component of the derivative estimates (their noise), and whether Td has been acquired
    /// (before, Td is frozen: it learns nothing from a linearisation that may not hold).
    ///
    /// `interp_err` is the fractional-delay interpolation's error. Its variance is added to R;
    /// and where it is systematic (a phase error of the interpolator at the frequency of a
    /// narrow-band vibration, which does not average out) it biases Td by its projection on
    /// the regressor, b = Σ(e·ẋ/σ²) / Σ(ẋ²/σ²), smoothed, whose square is added to Td's
    /// reported variance (a consider term, as for an unestimated bias; sample noise in e does
    /// not correlate with the reference's ẋ and averages out).
    ///
    /// The derivatives are measured, not known: a noisy regressor −ẋ would make the filter
    /// count noise as information. Their noise enters the residual multiplied by the offset
    /// error δ, so R is inflated by P_TdTd·σ_ẋ² (the errors-in-variables term), and Td is
    /// frozen while the signal's information does not exceed what that noise alone would give.
    #[allow(clippy::too_many_arguments)]
    pub fn update(
        &mut self,
        r_gyro: &Vector3<f64>,
        w: &Vector3<f64>,
        w_dot: &Vector3<f64>,
        sigma_gyro: f64,
        r_accel: &Vector3<f64>,
        f: &Vector3<f64>,
        f_dot: &Vector3<f64>,
        sigma_accel: f64,
        w_dot_var: f64,
        f_dot_var: f64,
        interp_err: &InterpolationError,
        acquired: bool,
    ) -> OffsetUpdate {
        // Smoothed information rate over ~0.5 s (EMA at the sample rate, α = 0.01).
        let info = w_dot.norm_squared() / sigma_gyro.powi(2) + f_dot.norm_squared() / sigma_accel.powi(2);
        self.info_ema += 0.01 * (info - self.info_ema);
        self.noise_info = 3.0 * (w_dot_var / sigma_gyro.powi(2) + f_dot_var / sigma_accel.powi(2));
        // Before an acquisition the linearisation may be outside its capture range.
        let use_td = acquired && self.observable();
        let mut h = SMatrix::<f64, 6, M>::zeros();
        for k in 0..3 {
            if use_td {
                h[(k, 0)] = -w_dot[k];
                h[(k + 3, 0)] = -f_dot[k];
            }
            h[(k, 1 + k)] = 1.0;
            h[(k + 3, 4 + k)] = 1.0;
            h[(k, 7 + k)] = w[k];
            h[(k + 3, 10 + k)] = f[k];
        }
        let r = SVector::<f64, 6>::new(r_gyro.x, r_gyro.y, r_gyro.z, r_accel.x, r_accel.y, r_accel.z);
        // Predicted residual at the current estimate (the offset error is zero-mean):
        // r̂ = Δb̂ + diag(x_0)·Δŝ, i.e. H x̂ without the Td column.
        let mut r_hat = h * self.x;
        for k in 0..6 {
            r_hat[k] -= h[(k, 0)] * self.x[0];
        }
        let nu = r - r_hat;
        let mut rn = SMatrix::<f64, 6, 6>::zeros();
        let p_td = if use_td { self.p[(0, 0)] } else { 0.0 };
        for k in 0..3 {
            rn[(k, k)] = sigma_gyro.powi(2) + p_td * w_dot_var + interp_err.variance[k];
            rn[(k + 3, k + 3)] = sigma_accel.powi(2) + p_td * f_dot_var + interp_err.variance[k + 3];
        }
        if use_td {
            let num: f64 = (0..3)
                .map(|k| {
                    interp_err.value[k] * w_dot[k] / sigma_gyro.powi(2)
                        + interp_err.value[k + 3] * f_dot[k] / sigma_accel.powi(2)
                })
                .sum();
            let den = (w_dot / sigma_gyro).norm_squared() + (f_dot / sigma_accel).norm_squared();
            self.interp_num_ema += 0.001 * (num - self.interp_num_ema);
            self.interp_den_ema += 0.001 * (den - self.interp_den_ema);
        }
        let pht = self.p * h.transpose();
        let s = h * pht + rn;
        let Some(s_inv) = s.try_inverse() else {
            return OffsetUpdate::Rejected(f64::INFINITY);
        };
        let nis = (nu.transpose() * s_inv * nu)[(0, 0)];
        if !nis.is_finite() || nis > GATE_6 {
            return OffsetUpdate::Rejected(nis);
        }
        let mut k = pht * s_inv;
        if !use_td {
            // Frozen: Td gets no gain, not even through its correlation with the biases (the
            // Joseph form below keeps P consistent for any gain).
            k.row_mut(0).fill(0.0);
        }
        self.x += k * nu;
        let i_kh = Mat7::identity() - k * h;
        let p = i_kh * self.p * i_kh.transpose() + k * rn * k.transpose();
        self.p = (p + p.transpose()) * 0.5;
        self.updates += 1;
        OffsetUpdate::Accepted(nis)
    }
}
