//! The error state of the navigation filter, its continuous-time dynamics and process noise.
//!
//! Conventions follow KF-GINS (`gi_engine.cpp`; Shin 2005, *Estimation Techniques for Low-Cost
//! Inertial Navigation*, ch. 2): position and velocity errors are *computed − true* (NED, m and
//! m/s); the attitude error φ is the phi angle with C_b^n(true) = exp([φ×]) C_b^n(computed); the
//! sensor errors (biases, scale factors) and the GNSS delay are *true − estimated*, fed back by
//! addition. Error state (N = 27):
//!
//! | index | state | unit |
//! |---|---|---|
//! | 0–2 | δr: position error N, E, D | m |
//! | 3–5 | δv: velocity error N, E, D | m/s |
//! | 6–8 | φ: attitude error (NED axes) | rad |
//! | 9–11 | gyro bias b_g (body FRD) | rad/s |
//! | 12–14 | accelerometer bias b_a (body FRD) | m/s² |
//! | 15–17 | gyro scale factor s_g | — |
//! | 18–20 | accelerometer scale factor s_a | — |
//! | 21 | GNSS time-synchronisation error Δ | s |
//! | 22 | receiver clock bias c·δt_r (tightly coupled only) | m |
//! | 23 | receiver clock drift c·δṫ_r (tightly coupled only) | m/s |
//! | 24 | inter-system bias Galileo − GPS of the receiver's clock (tightly coupled only) | m |
//! | 25 | inter-system bias BeiDou − GPS (tightly coupled only) | m |
//! | 26 | inter-system bias GLONASS − GPS (tightly coupled only) | m |
//!
//! The clock states are frozen (zero covariance, no process noise) unless the filter is
//! tightly coupled ([`ProcessNoise::clock`]); loosely coupled, the receiver solved its clock.
//! One oscillator drives every system's clock: each system's bias is the GPS one plus its
//! inter-system bias (the receiver's signal delays of that system and the offset between the
//! systems' time scales, GGTO of Galileo OS SIS ICD §5.1.5; BDT − GPST beyond its 14 s is
//! kept to < 100 ns, BDS-SIS-ICD-B1I §5.2.4.19; GLONASS time's offset from GPS time, tens of
//! ns, with the receiver's GLONASS delays), nearly constant: a random walk of
//! [`ISB_RW_M_SQRT_S`] (RTKLIB instead keeps one free clock per system).

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use navsync_wire::earth::{self, OMEGA_IE};
use navsync_wire::imu_spec::{ImuErrorSpec, ImuNoise, PerAxis};

use crate::time::clock_model::OscillatorNoise;

use super::mechanization::{Pva, skew};

/// Error-state dimension.
pub const N: usize = 27;
/// Position error.
pub const POS: usize = 0;
/// Velocity error.
pub const VEL: usize = 3;
/// Attitude error (phi angle).
pub const ATT: usize = 6;
/// Gyro bias.
pub const BG: usize = 9;
/// Accelerometer bias.
pub const BA: usize = 12;
/// Gyro scale factor.
pub const SG: usize = 15;
/// Accelerometer scale factor.
pub const SA: usize = 18;
/// GNSS delay.
pub const DELAY: usize = 21;
/// Receiver clock bias, m.
pub const CLK_BIAS: usize = 22;
/// Receiver clock drift, m/s.
pub const CLK_DRIFT: usize = 23;
/// Inter-system biases of the receiver clock, m: Galileo's, BeiDou's, then GLONASS's, minus
/// GPS's.
pub const ISB: usize = 24;
/// Systems with an inter-system bias state.
pub const ISB_SYSTEMS: usize = 3;
/// Random walk of an inter-system bias, m/√s (1 cm/√s: 0.6 m in an hour, ample for a
/// hardware delay drifting with temperature and for GGTO's few ns a day).
pub const ISB_RW_M_SQRT_S: f64 = 0.01;

/// Error-state vector.
pub type StateVec = SVector<f64, N>;
/// Error-state covariance / transition matrix.
pub type StateMat = SMatrix<f64, N, N>;

/// IMU and filter process-noise figures (KF-GINS `ImuNoise`), SI units, per IMU axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProcessNoise {
    /// Angle random walk, rad/√s.
    pub arw: Vector3<f64>,
    /// Velocity random walk, m/s/√s.
    pub vrw: Vector3<f64>,
    /// Gyro bias Gauss–Markov standard deviation, rad/s.
    pub gyro_bias_std: Vector3<f64>,
    /// Accelerometer bias Gauss–Markov standard deviation, m/s².
    pub accel_bias_std: Vector3<f64>,
    /// Gyro scale-factor Gauss–Markov standard deviation.
    pub gyro_scale_std: Vector3<f64>,
    /// Accelerometer scale-factor Gauss–Markov standard deviation.
    pub accel_scale_std: Vector3<f64>,
    /// Correlation time of the bias and scale Gauss–Markov processes, s.
    pub corr_time_s: f64,
    /// Initial 1-sigma of the gyro bias (turn-on bias), rad/s.
    pub gyro_bias_init_std: Vector3<f64>,
    /// Initial 1-sigma of the accelerometer bias (turn-on bias), m/s².
    pub accel_bias_init_std: Vector3<f64>,
    /// Initial 1-sigma of the gyro scale factor.
    pub gyro_scale_init_std: Vector3<f64>,
    /// Initial 1-sigma of the accelerometer scale factor.
    pub accel_scale_init_std: Vector3<f64>,
    /// Random walk of the GNSS delay, s/√s (lets Δ follow slow changes of the receiver).
    pub delay_rw: f64,
    /// Estimate scale factors (else their states are frozen at zero).
    pub estimate_scale: bool,
    /// The GNSS delay Δ is a live state (else frozen; from [`super::config::NavConfig::estimate_delay`]).
    pub delay_state: bool,
    /// The receiver's oscillator when its clock bias and drift are estimated (tightly
    /// coupled); `None`: the clock states are frozen (loosely coupled, the default).
    pub clock: Option<OscillatorNoise>,
}

impl ProcessNoise {
    /// Process noise of an IMU as its model states it (KF-GINS units, converted to SI): white
    /// noise from the random walks, the bias and scale Gauss–Markov processes from their
    /// instabilities, the initial uncertainties from the turn-on errors. Scale factors are
    /// estimated when a turn-on spread is given. Δ is a constant per session that may wander
    /// by 0.1 ms/√s (a receiver firmware changing its output schedule).
    pub fn from_imu_noise(n: &ImuNoise) -> Self {
        const DEG_H: f64 = std::f64::consts::PI / 180.0 / 3600.0;
        let v = |p: PerAxis, k: f64| Vector3::from(p.0) * k;
        Self {
            arw: v(n.arw_deg_per_sqrt_h, std::f64::consts::PI / 180.0 / 60.0),
            vrw: v(n.vrw_mps_per_sqrt_h, 1.0 / 60.0),
            gyro_bias_std: v(n.gyro_bias_std_deg_per_h, DEG_H),
            accel_bias_std: v(n.accel_bias_std_mgal, 1e-5),
            gyro_scale_std: v(n.gyro_scale_std_ppm, 1e-6),
            accel_scale_std: v(n.accel_scale_std_ppm, 1e-6),
            corr_time_s: n.corr_time_h * 3600.0,
            gyro_bias_init_std: v(n.gyro_bias_init_std_deg_per_h, DEG_H),
            accel_bias_init_std: v(n.accel_bias_init_std_mgal, 1e-5),
            gyro_scale_init_std: v(n.gyro_scale_init_std_ppm, 1e-6),
            accel_scale_init_std: v(n.accel_scale_init_std_ppm, 1e-6),
            delay_rw: 1e-4,
            estimate_scale: n.gyro_scale_init_std_ppm.0.iter().any(|x| *x > 0.0)
                || n.accel_scale_init_std_ppm.0.iter().any(|x| *x > 0.0),
            delay_state: true,
            clock: None,
        }
    }

    /// Process noise of an IMU class ([`ImuNoise::from_spec`]).
    pub fn from_spec(spec: &ImuErrorSpec) -> Self {
        Self::from_imu_noise(&ImuNoise::from_spec(spec))
    }
}

/// Builds F (continuous-time error dynamics) at `pva` with bias-compensated specific force
/// `f_b` (m/s²) and angular rate `w_b` (rad/s) in the body frame: the blocks of KF-GINS
/// `insPropagation` (Shin 2005 eq. 2.41–2.49 in NED position metres).
pub fn system_matrix(pva: &Pva, f_b: &Vector3<f64>, w_b: &Vector3<f64>, noise: &ProcessNoise) -> StateMat {
    let mut f = StateMat::zeros();
    let (lat, h) = (pva.lat_rad, pva.h_m);
    let v = pva.vel_ned_mps;
    let (rm, rn) = earth::radii(lat);
    let (rmh, rnh) = (rm + h, rn + h);
    let (sl, cl) = lat.sin_cos();
    let tl = sl / cl;
    let g = earth::normal_gravity(lat, h);
    let c_bn = pva.q_nb.to_rotation_matrix().into_inner();
    let w_ie = Vector3::from(earth::omega_ie_n(lat));
    let w_en = Vector3::from(earth::omega_en_n(lat, h, [v.x, v.y, v.z]));

    // Position error.
    let frr = Matrix3::new(
        -v.z / rmh,
        0.0,
        v.x / rmh,
        v.y * tl / rnh,
        -(v.z + v.x * tl) / rnh,
        v.y / rnh,
        0.0,
        0.0,
        0.0,
    );
    f.fixed_view_mut::<3, 3>(POS, POS).copy_from(&frr);
    f.fixed_view_mut::<3, 3>(POS, VEL).copy_from(&Matrix3::identity());

    // Velocity error.
    let fvr = Matrix3::new(
        -2.0 * v.y * OMEGA_IE * cl / rmh - v.y * v.y / (rmh * rnh * cl * cl),
        0.0,
        v.x * v.z / (rmh * rmh) - v.y * v.y * tl / (rnh * rnh),
        2.0 * OMEGA_IE * (v.x * cl - v.z * sl) / rmh + v.x * v.y / (rmh * rnh * cl * cl),
        0.0,
        (v.y * v.z + v.x * v.y * tl) / (rnh * rnh),
        2.0 * OMEGA_IE * v.y * sl / rmh,
        0.0,
        -v.y * v.y / (rnh * rnh) - v.x * v.x / (rmh * rmh) + 2.0 * g / ((rm * rn).sqrt() + h),
    );
    let fvv = Matrix3::new(
        v.z / rmh,
        -2.0 * (OMEGA_IE * sl + v.y * tl / rnh),
        v.x / rmh,
        2.0 * OMEGA_IE * sl + v.y * tl / rnh,
        (v.z + v.x * tl) / rnh,
        2.0 * OMEGA_IE * cl + v.y / rnh,
        -2.0 * v.x / rmh,
        -2.0 * (OMEGA_IE * cl + v.y / rnh),
        0.0,
    );
    f.fixed_view_mut::<3, 3>(VEL, POS).copy_from(&fvr);
    f.fixed_view_mut::<3, 3>(VEL, VEL).copy_from(&fvv);
    f.fixed_view_mut::<3, 3>(VEL, ATT).copy_from(&skew(&(c_bn * f_b)));
    f.fixed_view_mut::<3, 3>(VEL, BA).copy_from(&c_bn);
    if noise.estimate_scale {
        f.fixed_view_mut::<3, 3>(VEL, SA)
            .copy_from(&(c_bn * Matrix3::from_diagonal(f_b)));
    }

    // Attitude error.
    let fpr = Matrix3::new(
        -OMEGA_IE * sl / rmh,
        0.0,
        v.y / (rnh * rnh),
        0.0,
        0.0,
        -v.x / (rmh * rmh),
        -OMEGA_IE * cl / rmh - v.y / (rmh * rnh * cl * cl),
        0.0,
        -v.y * tl / (rnh * rnh),
    );
    let fpv = Matrix3::new(0.0, 1.0 / rnh, 0.0, -1.0 / rmh, 0.0, 0.0, 0.0, -tl / rnh, 0.0);
    f.fixed_view_mut::<3, 3>(ATT, POS).copy_from(&fpr);
    f.fixed_view_mut::<3, 3>(ATT, VEL).copy_from(&fpv);
    f.fixed_view_mut::<3, 3>(ATT, ATT).copy_from(&(-skew(&(w_ie + w_en))));
    f.fixed_view_mut::<3, 3>(ATT, BG).copy_from(&(-c_bn));
    if noise.estimate_scale {
        f.fixed_view_mut::<3, 3>(ATT, SG)
            .copy_from(&(-c_bn * Matrix3::from_diagonal(w_b)));
    }

    // Sensor errors: first-order Gauss–Markov, ẋ = −x/T + w.
    let decay = -1.0 / noise.corr_time_s;
    for i in BG..SG {
        f[(i, i)] = decay;
    }
    if noise.estimate_scale {
        for i in SG..DELAY {
            f[(i, i)] = decay;
        }
    }

    // Receiver clock: the bias integrates the drift (Brown & Hwang eq. 9.3.10).
    if noise.clock.is_some() {
        f[(CLK_BIAS, CLK_DRIFT)] = 1.0;
    }
    // The inter-system biases are random walks (F = 0).
    f
}

/// Discrete process noise over `dt` at attitude `c_bn` (C_b^n): Q_d = G Q_c Gᵀ·dt with the
/// white-noise intensities of the random walks (ARW², VRW² per IMU axis, rotated into the
/// navigation frame: C diag(σ²) Cᵀ) and of the Gauss–Markov drivers (2σ²/T). KF-GINS uses the
/// trapezoid ½(Φ Q Φᵀ + Q)·dt; the difference is O(F·dt) relative, below 2 % of the
/// off-diagonal terms at the 20 ms covariance step. `imu_scale` multiplies the IMU's share
/// (every term but the GNSS delay's): the filter's adaptation of a model that proved too
/// optimistic (1 = the model as configured).
pub fn process_noise(noise: &ProcessNoise, c_bn: &Matrix3<f64>, dt: f64, imu_scale: f64) -> StateMat {
    let mut q = StateMat::zeros();
    let dt_imu = dt * imu_scale;
    let rotated = |s: &Vector3<f64>| c_bn * Matrix3::from_diagonal(&s.component_mul(s)) * c_bn.transpose() * dt_imu;
    q.fixed_view_mut::<3, 3>(VEL, VEL).copy_from(&rotated(&noise.vrw));
    q.fixed_view_mut::<3, 3>(ATT, ATT).copy_from(&rotated(&noise.arw));
    let gm = |std: f64| 2.0 * std * std / noise.corr_time_s * dt_imu;
    for i in 0..3 {
        q[(BG + i, BG + i)] = gm(noise.gyro_bias_std[i]);
        q[(BA + i, BA + i)] = gm(noise.accel_bias_std[i]);
        if noise.estimate_scale {
            q[(SG + i, SG + i)] = gm(noise.gyro_scale_std[i]);
            q[(SA + i, SA + i)] = gm(noise.accel_scale_std[i]);
        }
    }
    if noise.delay_state {
        q[(DELAY, DELAY)] = noise.delay_rw * noise.delay_rw * dt;
    }
    if let Some(osc) = noise.clock {
        q.fixed_view_mut::<2, 2>(CLK_BIAS, CLK_BIAS)
            .copy_from(&osc.process_noise_m(dt));
        for i in ISB..ISB + ISB_SYSTEMS {
            q[(i, i)] = ISB_RW_M_SQRT_S * ISB_RW_M_SQRT_S * dt;
        }
    }
    q
}
