//! The navigation filter with a fusion horizon: a delayed error-state filter plus an output
//! predictor (the structure of PX4's EKF2).
//!
//! - Every IMU interval enters the [`ImuBuffer`]. The *delayed* filter consumes intervals once
//!   they are older than the horizon (default 2 s, adaptive): strapdown mechanization at the IMU rate,
//!   covariance propagation every ~20 ms. Measurements wait in one queue
//!   ([`super::measurements`]) until the delayed filter reaches their epoch, and are fused
//!   *there*: a GNSS fix at t_f = t_stamp − Δ̂, its measurement time, so neither the receiver's
//!   output latency nor the serial transfer biases it.
//! - The *output* state is the delayed state carried to the present through the buffered
//!   intervals. It advances one mechanization step per new IMU interval; after a correction
//!   of the delayed state it is recomputed by replaying the buffer. A `NavState` is therefore
//!   available for every IMU sample the moment it arrives, with no added latency.
//!
//! Pure and deterministic: the output depends only on the samples and their order.

use nalgebra::Vector3;
use navsync_wire::imu_spec::ImuPreset;
use navsync_wire::samples::{ImuSync, MAX_IMUS, NavState, NavStatus};

use super::alignment::{Aligner, ONSET_DELAY_FLOOR_S};
pub use super::config::NavConfig;
use super::config::{Coupling, InitialState};
use super::error_state::{ATT, BA, BG, CLK_BIAS, CLK_DRIFT, DELAY, POS, ProcessNoise, SA, SG, StateMat, VEL};
use super::eskf::Eskf;
use super::filter::{DelayDoubt, DelayedFilter, published_pos_std_ned_m};
use super::heading_bank::{BankStep, HeadingBank, with_heading};
use super::imu_buffer::{ImuBuffer, ImuRecord};
use super::integrity::{
    self, Fault, INTEGRITY_HEADING_UNKNOWN, INTEGRITY_INCONSISTENT, INTEGRITY_RECOVERING, IntegrityCounters,
};
use super::measurements::gnss::GnssObservation;
use super::measurements::{Measurement, MeasurementConfig, MeasurementQueue, MeasurementStates};
use super::mechanization::{ImuIncrement, Pva, propagate};
use super::noise_meter::{MeasuredNoise, NoiseMeter};
use super::smoother::SmootherLog;
use crate::gnss::ranges::RangeEpoch;

/// Shortest adaptive fusion horizon, s.
pub const MIN_HORIZON_S: f64 = 0.25;
/// Margin of the adaptive horizon over the fixes' delay, s.
const HORIZON_MARGIN_S: f64 = 0.02;
/// How fast the adaptive horizon's memory of a long delay fades, per fix, s.
const HORIZON_DECAY_S: f64 = 0.01;

/// Gives the bias states at least `model`'s turn-on σ (a widened model: the estimates kept).
fn reopen_bias_std(f: &mut DelayedFilter, model: &ProcessNoise) {
    for i in 0..3 {
        let (g, a) = (BG + i, BA + i);
        f.eskf.p[(g, g)] = f.eskf.p[(g, g)].max(model.gyro_bias_init_std[i].powi(2));
        f.eskf.p[(a, a)] = f.eskf.p[(a, a)].max(model.accel_bias_init_std[i].powi(2));
    }
}

/// Clears the sensor-error estimates of `f` (biases, scale factors) and re-opens their
/// covariance to the model's turn-on σ, decorrelated from the other states.
fn reset_sensor_errors(f: &mut DelayedFilter, noise: &ProcessNoise) {
    f.bias_g = Vector3::zeros();
    f.bias_a = Vector3::zeros();
    f.scale_g = Vector3::zeros();
    f.scale_a = Vector3::zeros();
    let scale = |std: f64| if noise.estimate_scale { std * std } else { 0.0 };
    for i in 0..3 {
        f.eskf.reopen(BG + i, noise.gyro_bias_init_std[i].powi(2));
        f.eskf.reopen(BA + i, noise.accel_bias_init_std[i].powi(2));
        f.eskf.reopen(SG + i, scale(noise.gyro_scale_init_std[i]));
        f.eskf.reopen(SA + i, scale(noise.accel_scale_init_std[i]));
    }
}

/// Below this fraction of the generic model's no measured white noise is taken (ARW
/// 0.02 °/√h: beyond a navigation-grade IMU's; keeps the process noise positive).
const MIN_NOISE_SCALE: f64 = 0.01;

/// `generic` (the model of an IMU of unknown class) scaled to what the IMU's signal shows
/// ([`super::noise_meter`]): each white noise at most its measured bound (vibration comes and
/// goes), never above the generic model; the bias instabilities, a property of the IMU in use
/// rather than of the moment, by `k_bias` (the largest of the white-noise ratios the signal has
/// shown so far: an IMU's Allan curve moves as a whole from class to class, and the generic
/// model's ARW and instabilities are those of one IMU in use); the turn-on errors and the
/// states' switches as in `current`. Returns the noise and the ratio the instabilities took.
fn scaled_to_signal(
    generic: &ProcessNoise,
    m: &MeasuredNoise,
    k_bias: f64,
    current: &ProcessNoise,
) -> (ProcessNoise, f64) {
    let kg = (m.arw_rad_sqrt_s / generic.arw.mean()).clamp(MIN_NOISE_SCALE, 1.0);
    let ka = (m.vrw_mps_sqrt_s / generic.vrw.mean()).clamp(MIN_NOISE_SCALE, 1.0);
    let k = kg.max(ka).max(k_bias);
    let noise = ProcessNoise {
        arw: generic.arw * kg,
        vrw: generic.vrw * ka,
        gyro_bias_std: generic.gyro_bias_std * k,
        accel_bias_std: generic.accel_bias_std * k,
        ..*current
    };
    (noise, k)
}

/// `noise` with every term at least that of an IMU of unknown class (the generic preset): what
/// the filter assumes once the data have contradicted the configured model.
fn widened(noise: &ProcessNoise) -> ProcessNoise {
    let g = ProcessNoise::from_imu_noise(&ImuPreset::Generic.noise());
    let max = |a: Vector3<f64>, b: Vector3<f64>| a.zip_map(&b, f64::max);
    ProcessNoise {
        arw: max(noise.arw, g.arw),
        vrw: max(noise.vrw, g.vrw),
        gyro_bias_std: max(noise.gyro_bias_std, g.gyro_bias_std),
        accel_bias_std: max(noise.accel_bias_std, g.accel_bias_std),
        gyro_scale_std: max(noise.gyro_scale_std, g.gyro_scale_std),
        accel_scale_std: max(noise.accel_scale_std, g.accel_scale_std),
        corr_time_s: noise.corr_time_s.min(g.corr_time_s),
        gyro_bias_init_std: max(noise.gyro_bias_init_std, g.gyro_bias_init_std),
        accel_bias_init_std: max(noise.accel_bias_init_std, g.accel_bias_init_std),
        ..*noise
    }
}

/// Counters of the navigation filter: its own, and the GNSS fixes' (kept by their
/// measurement kind, [`super::measurements::gnss::GnssState`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct NavCounters {
    /// Fixes fused (position accepted).
    pub fixes_used: u64,
    /// Fixes whose position failed the innovation gate.
    pub fixes_rejected: u64,
    /// Velocity updates that failed the gate.
    pub vel_rejected: u64,
    /// Fixes (and raw epochs) whose epoch was already behind the delayed filter (horizon too
    /// short).
    pub fixes_too_old: u64,
    /// IMU intervals longer than 1.5 nominal periods (dropped samples bridged).
    pub imu_gaps: u64,
    /// IMU samples going back in time (ignored).
    pub imu_backwards: u64,
    /// Output replays after a correction.
    pub replays: u64,
    /// Resets to GNSS after [`RESET_AFTER_REJECTS`] consecutive rejected fixes.
    pub gnss_resets: u64,
    /// Of those, full resets (see [`super::measurements::gnss::GnssState::gnss_resets_full`]).
    pub gnss_resets_full: u64,
    /// Heading banks started ([`HeadingBank`]: the alignment of the heading).
    pub heading_banks: u64,
    /// Heading banks whose every hypothesis failed (the alignment started again).
    pub heading_banks_failed: u64,
}

pub use super::measurements::gnss::RESET_AFTER_REJECTS;

/// Fixes remembered for the motion test on positions ([`Navigator::displaced`]).
const RECENT_FIXES: usize = 16;
/// The longest baseline of that test, s.
const MOTION_BASELINE_S: f64 = 3.0;

/// The receiver clock as the tightly coupled filter knows it ([`Navigator::receiver_clock`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReceiverClock {
    /// Clock bias c·δt_r (receiver time minus GPS time, times c), m.
    pub bias_m: f64,
    /// Clock drift c·δṫ_r, m/s.
    pub drift_mps: f64,
    /// 1σ of the bias, m.
    pub bias_std_m: f64,
    /// 1σ of the drift, m/s.
    pub drift_std_mps: f64,
    /// Host time of the last epoch with a satellite fused, ns (0: none yet).
    pub last_fused_ns: i64,
}

/// The least GNSS delay Δ the filter holds, s (its lower clamp, [`DelayedFilter::feedback`]).
pub const MIN_DELAY_S: f64 = -0.5;
/// Δ stays this far below the fusion horizon, s (its upper clamp).
pub const DELAY_HORIZON_MARGIN_S: f64 = 0.05;
/// A prior of Δ at least this loose (s, 1σ) runs a shadow navigator ([`Navigator::reset_delay`]):
/// software sync's (0.5 s), not hardware sync's (0.02 s by default).
pub const SHADOW_MIN_PRIOR_STD_S: f64 = 0.1;

/// Intervals between fixes kept for the receiver's own ([`Navigator::fix_interval_ns`]).
const FIX_INTERVALS: usize = 9;

/// Sets filter `f`'s Δ to `prior_s` with 1σ `prior_std_s` (0 when Δ is not `live`), its
/// correlations with the other states forgotten.
fn reopen_delay(f: &mut DelayedFilter, prior_s: f64, prior_std_s: f64, live: bool) {
    f.delay_s = prior_s;
    f.eskf.reopen(DELAY, if live { prior_std_s * prior_std_s } else { 0.0 });
}

/// Output re-propagation after a correction: the state, last increment, host time (ns) and
/// last compensated rates of the records integrated so far.
#[derive(Debug, Clone, Copy)]
struct CatchUp {
    pva: Pva,
    pre: ImuIncrement,
    t: i64,
    w: Vector3<f64>,
    f: Vector3<f64>,
}

/// Writes the pose of `pva` (rates `w`, specific force `f`, body FRD), the σ's and the sensor
/// errors of `filt` into `s`; the position, velocity and attitude σ times
/// [`DelayedFilter::sigma_scale`], the position's with Δ's doubt and at least its floor
/// ([`published_pos_std_ned_m`]).
fn write_pose(s: &mut NavState, pva: &Pva, w: Vector3<f64>, f: Vector3<f64>, filt: &DelayedFilter) {
    let sigma_scale = filt.sigma_scale;
    let q = pva.q_nb.quaternion();
    s.lat_deg = pva.lat_rad.to_degrees();
    s.lon_deg = pva.lon_rad.to_degrees();
    s.height_m = pva.h_m;
    s.vel_ned_mps = pva.vel_ned_mps.into();
    s.rpy_rad = pva.rpy_rad().into();
    s.q_nb = [q.w, q.i, q.j, q.k];
    s.gyro_body_rps = w.into();
    s.accel_body_mps2 = f.into();
    let std3 = |i: usize| [filt.eskf.std(i), filt.eskf.std(i + 1), filt.eskf.std(i + 2)];
    let scaled = |i: usize| std3(i).map(|x| x * sigma_scale);
    let doubt = &filt.delay_doubt;
    s.pos_std_ned_m = published_pos_std_ned_m(std3(POS), sigma_scale, &filt.pos_floor_std_ned_m, doubt);
    s.vel_std_ned_mps = DelayDoubt::widen(scaled(VEL), &doubt.vel_m2ps2);
    s.att_std_rad = DelayDoubt::widen(scaled(ATT), &doubt.att_rad2);
    s.gyro_bias_rps = filt.bias_g.into();
    s.accel_bias_mps2 = filt.bias_a.into();
    s.gyro_bias_std_rps = std3(BG);
    s.accel_bias_std_mps2 = std3(BA);
}

/// States the delayed filter makes in one call at most, kept without reallocating: a whole
/// fusion horizon (2 s by default, with the input order's hold) of a 1 kHz IMU, which it steps
/// over at once when the heading is decided, with the fine alignment's last half batch.
pub const MAX_FUSED_BATCH: usize = 4096;

/// The navigation filter.
#[derive(Debug, Clone)]
pub struct Navigator {
    cfg: NavConfig,
    /// Each kind of measurement's settings.
    kinds: MeasurementConfig,
    buf: ImuBuffer,
    aligner: Aligner,
    /// The heading hypotheses while the heading is being decided ([`HeadingBank`]).
    bank: Option<HeadingBank>,
    filt: Option<DelayedFilter>,
    /// The present-time state, the last increment and the host time it is for.
    out: Option<(Pva, ImuIncrement, i64)>,
    /// Output-stream intervals newer than the newest filter-stream interval.
    out_tail: ImuBuffer,
    last_output_ns: Option<i64>,
    out_w: Vector3<f64>,
    out_f: Vector3<f64>,
    /// The output re-propagated from a corrected delayed state, in progress (see
    /// [`Navigator::catch_up`]).
    catchup: Option<CatchUp>,
    /// Measurements waiting for their epochs.
    queue: MeasurementQueue,
    /// What each kind of measurement keeps between measurements.
    states: MeasurementStates,
    counters: NavCounters,
    last_imu_ns: Option<i64>,
    last_fix_rx_ns: Option<i64>,
    /// A fix has shown the platform moving (speed ≥ the alignment's minimum and 5.3 σ, or a
    /// displacement that large over a few seconds: [`Navigator::displaced`]).
    motion_seen: bool,
    /// Epoch of the previous fix, host ns (for the noise of a speed from positions).
    prev_fix_ns: Option<i64>,
    /// The last intervals between two fixes, ns (0: none yet), whose median is the receiver's
    /// own interval ([`Navigator::fix_interval_ns`]).
    fix_intervals_ns: [i64; FIX_INTERVALS],
    /// The latest fixes' stamps (host ns), positions (rad) and horizontal σ (m): motion shown
    /// by a displacement over a few seconds where the fixes carry no velocity.
    recent_fixes: [(i64, f64, f64, f64); RECENT_FIXES],
    recent_len: usize,
    /// Receipt of the last raw epoch (tightly coupled), host ns.
    last_ranges_rx_ns: Option<i64>,
    /// The fusion horizon in force, ns.
    horizon_ns: i64,
    /// The longest recent delay of a fix from its epoch to its release, ns (fading).
    fix_delay_ns: i64,
    /// What the integrity monitor found, by kind.
    integrity: IntegrityCounters,
    /// The offline smoother's log, when smoothing is on ([`Self::enable_smoothing`]).
    smoother: Option<SmootherLog>,
    /// The filter is flagged inconsistent (its covariance was inflated).
    inconsistent: bool,
    /// The IMU model was widened after an inconsistency ([`widened`]).
    widened: bool,
    /// An IMU of unknown class: the generic model its process noise is scaled from, the meter
    /// of its signal and the largest ratio to the generic model it has shown
    /// ([`NavConfig::imu_noise_from_signal`]); `None` for a model given.
    noise_from_signal: Option<(ProcessNoise, Option<NoiseMeter>, f64)>,
    /// Host time until which states are flagged as recovering from a reset, ns.
    recovering_until_ns: i64,
    /// The same navigator with Δ's prior shifted by one σ, fed the same inputs, while that
    /// prior is loose ([`SHADOW_MIN_PRIOR_STD_S`]): how far its Δ estimate stays from this
    /// one's is the information the data really hold on Δ ([`Self::update_delay_doubt`]).
    shadow: Option<Box<Navigator>>,
    /// This navigator's shift of every prior of Δ it is given, in σ of that prior: 0, or ±1
    /// for a shadow.
    prior_shift_sigmas: f64,
    /// The prior of the GNSS delay Δ in force and its 1-sigma, s (set by
    /// [`Navigator::reset_delay`] when the time base of the fix stamps changes; the motion
    /// onset may narrow it at alignment).
    delay_prior: (f64, f64),
    /// The prior of Δ of the time base in force (as set by [`Navigator::reset_delay`], before
    /// any narrowing) and the least Δ that is physical, s ([`Navigator::set_delay_floor`]).
    delay_base: (f64, f64, f64),
    /// The delayed filter's states since [`Navigator::drain_fused`] last took them: each
    /// instant it stepped over, with every measurement up to it fused (its capacity is kept);
    /// `None` unless [`Navigator::keep_fused`] asked for them.
    fused: Option<Vec<NavState>>,
    /// The last covariance the integrity monitor found positive definite.
    pd_memo: integrity::PdMemo,
}

impl Navigator {
    /// A filter that waits for alignment, with the default settings of every kind of
    /// measurement.
    pub fn new(cfg: NavConfig) -> Self {
        Self::with_measurements(cfg, MeasurementConfig::default())
    }

    /// A filter that waits for alignment, with `kinds` the settings of each kind of
    /// measurement.
    pub fn with_measurements(mut cfg: NavConfig, kinds: MeasurementConfig) -> Self {
        let generic = ProcessNoise::from_imu_noise(&ImuPreset::Generic.noise());
        let noise_from_signal = (cfg.imu_noise_from_signal && cfg.noise == generic).then_some((generic, None, 0.0));
        // The states the settings make live: Δ, and the receiver clock when tightly coupled.
        cfg.noise.delay_state = cfg.estimate_delay;
        cfg.noise.clock = (cfg.coupling == Coupling::Tight).then(|| cfg.receiver_oscillator.noise());
        Self {
            cfg,
            kinds,
            buf: ImuBuffer::default(),
            aligner: Aligner::new(cfg.align),
            bank: None,
            filt: None,
            out: None,
            out_tail: ImuBuffer::default(),
            last_output_ns: None,
            out_w: Vector3::zeros(),
            out_f: Vector3::zeros(),
            catchup: None,
            queue: MeasurementQueue::default(),
            states: MeasurementStates::default(),
            counters: NavCounters::default(),
            last_imu_ns: None,
            last_fix_rx_ns: None,
            motion_seen: false,
            prev_fix_ns: None,
            fix_intervals_ns: [0; FIX_INTERVALS],
            recent_fixes: [(0, 0.0, 0.0, 0.0); RECENT_FIXES],
            recent_len: 0,
            last_ranges_rx_ns: None,
            horizon_ns: (cfg.fusion_horizon_s * 1e9) as i64,
            fix_delay_ns: 0,
            delay_prior: (0.0, cfg.delay_prior_std_s),
            delay_base: (0.0, cfg.delay_prior_std_s, MIN_DELAY_S),
            fused: None,
            pd_memo: integrity::PdMemo::default(),
            integrity: IntegrityCounters::default(),
            smoother: None,
            inconsistent: false,
            widened: false,
            noise_from_signal,
            recovering_until_ns: i64::MIN,
            shadow: None,
            prior_shift_sigmas: 0.0,
        }
    }

    /// Counters so far.
    pub fn counters(&self) -> NavCounters {
        let g = &self.states.gnss;
        NavCounters {
            fixes_used: g.fixes_used,
            fixes_rejected: g.fixes_rejected,
            vel_rejected: g.vel_rejected,
            gnss_resets: g.gnss_resets,
            gnss_resets_full: g.gnss_resets_full,
            ..self.counters
        }
    }

    /// What each kind of measurement keeps (its counters: [`MeasurementStates::each_counter`]).
    pub fn measurement_states(&self) -> &MeasurementStates {
        &self.states
    }

    /// Configuration in use.
    pub fn config(&self) -> &NavConfig {
        &self.cfg
    }

    /// The fusion horizon in force, s (adaptive: see [`NavConfig::adaptive_horizon`]).
    pub fn horizon_s(&self) -> f64 {
        self.horizon_ns as f64 * 1e-9
    }

    /// True once a fix has shown the platform moving (speed ≥ the alignment's minimum and 5.3 σ
    /// of the speed, or a displacement over a few seconds that large: [`Self::displaced`]):
    /// before that, a heading may not be observable at all.
    pub fn motion_seen(&self) -> bool {
        self.motion_seen
    }

    /// True once aligned.
    pub fn is_aligned(&self) -> bool {
        self.filt.is_some()
    }

    /// Estimated GNSS delay Δ and its published 1-sigma (with its doubt,
    /// [`DelayedFilter::delay_doubt`]), s (NaN before alignment or when switched off).
    pub fn gnss_delay(&self) -> (f64, f64) {
        match &self.filt {
            Some(f) if self.cfg.estimate_delay => (f.delay_s, f.delay_doubt.delay_std_s(f.eskf.std(DELAY))),
            _ => (f64::NAN, f64::NAN),
        }
    }

    /// Forgets the delay estimate (the time base of the fix stamps changed), and what was
    /// learnt from fixes stamped on the old base: their stamps ([`Self::displaced`], the
    /// speed's noise, the aligner's accelerations) and a heading bank still deciding (its
    /// hypotheses carry the old prior, its fixes the old stamps: the sweep's seed 21 run 5, a
    /// PPS acquired while it decided, left Δ at 0.33 ± 0.11 s for −0.008 s). The alignment
    /// starts again from the next fix.
    pub fn reset_delay(&mut self, prior_s: f64, prior_std_s: f64) {
        self.prev_fix_ns = None;
        self.recent_len = 0;
        self.aligner.forget_fixes();
        let shifted_s = prior_s + self.prior_shift_sigmas * prior_std_s;
        self.delay_prior = (shifted_s, prior_std_s);
        self.delay_base.0 = shifted_s;
        self.delay_base.1 = prior_std_s;
        if let Some(f) = &mut self.filt {
            reopen_delay(f, shifted_s, prior_std_s, self.cfg.estimate_delay);
        }
        self.bank = None;
        self.reset_shadow(prior_s, prior_std_s);
    }

    /// Starts, re-primes or ends the shadow for a new prior of Δ (`prior_s` ± `prior_std_s`):
    /// one while the prior is loose (software sync's receipt latency), Δ a state and the
    /// coupling loose; its prior one σ above (below, where the horizon leaves no room).
    fn reset_shadow(&mut self, prior_s: f64, prior_std_s: f64) {
        if self.prior_shift_sigmas != 0.0 {
            return;
        }
        if !(self.cfg.estimate_delay && !self.is_tight() && prior_std_s >= SHADOW_MIN_PRIOR_STD_S) {
            self.shadow = None;
            return;
        }
        let room_s = self.cfg.fusion_horizon_s - DELAY_HORIZON_MARGIN_S - (prior_s + prior_std_s);
        let shift = if room_s >= prior_std_s { 1.0 } else { -1.0 };
        if self.shadow.is_none() {
            let mut sh = Box::new(self.clone());
            sh.fused = None;
            sh.smoother = None;
            self.shadow = Some(sh);
        }
        let Some(sh) = &mut self.shadow else { return };
        sh.prior_shift_sigmas = shift;
        sh.reset_delay(prior_s, prior_std_s);
    }

    /// Sets the doubt on Δ ([`DelayedFilter::delay_doubt`]) from the shadow. In a
    /// linear Gaussian filter the posterior mean depends on the prior mean through
    /// ∂Δ̂/∂Δ̂₀ = P_ΔΔ / P₀ (the information form: x̂ = P (P₀⁻¹ x̂₀ + Hᵀ R⁻¹ z)), so a prior
    /// shifted by σ₀ moves the estimate by P_ΔΔ/σ₀. The shadow's estimate, |δΔ̂| away, shows
    /// P_eff = |δΔ̂|·σ₀ to be what the data leave of the prior; where that exceeds the filter's
    /// P_ΔΔ (a slow mover's Δ read from the noise of its velocity: the EKF's spurious
    /// information, Huang, Mourikis & Roumeliotis 2010), the difference is the doubt, at most
    /// the prior's variance (and all of it while the shadow is not aligned yet).
    fn update_delay_doubt(&mut self) {
        let Some(f) = &mut self.filt else { return };
        let Some(sh) = &self.shadow else {
            f.delay_doubt = DelayDoubt::default();
            return;
        };
        let sigma0 = self.delay_prior.1;
        let prior_var = sigma0 * sigma0;
        let p_eff = match &sh.filt {
            Some(g) => ((g.delay_s - f.delay_s).abs() * sigma0).min(prior_var),
            None => prior_var,
        };
        f.delay_doubt = DelayDoubt::from_covariance(&f.eskf.p, (p_eff - f.eskf.p[(DELAY, DELAY)]).max(0.0));
    }

    /// The least GNSS delay Δ that is physical for the fix stamps in force, s: under software
    /// sync a fix cannot be received before its epoch, so Δ (the receipt's lag behind the
    /// epoch, less the IMU samples' own) is at least minus the IMU's receipt latency; under
    /// hardware sync the filter's bound [`MIN_DELAY_S`]. An estimate below it, or at a bound of
    /// the filter, is reset to the prior ([`Self::monitor`]).
    pub fn set_delay_floor(&mut self, floor_s: f64) {
        self.delay_base.2 = floor_s.max(MIN_DELAY_S);
        if let Some(sh) = &mut self.shadow {
            sh.set_delay_floor(floor_s);
        }
    }

    /// The present output state, if aligned.
    pub fn output(&self) -> Option<&Pva> {
        self.out.as_ref().map(|(p, _, _)| p)
    }

    /// Queues a fix for fusion at its epoch (receipt host time `rx_ns` only marks GNSS as alive).
    /// Tightly coupled ([`Self::is_tight`]), fixes align the filter, and afterwards are fused
    /// only while no raw epoch has come for [`NavConfig::outage_after_s`] (a receiver that does
    /// not send its raw measurements: counted as `ranges_fallback_fixes`); otherwise the
    /// satellites' own measurements ([`Self::on_ranges`]) carry the same information.
    pub fn on_gnss(&mut self, obs: GnssObservation, rx_ns: i64) {
        if let Some(sh) = &mut self.shadow {
            sh.on_gnss(obs, rx_ns);
        }
        self.last_fix_rx_ns = Some(rx_ns);
        // Moving: faster than the alignment's minimum and than the speed's own noise. Without
        // a measured velocity the speed is a difference of positions (σ_h each, dt apart):
        // √2·σ_h/dt per axis, whatever velocity σ the settings assume. The horizontal speed of
        // a standing receiver with σ per axis is Rayleigh: above kσ with probability exp(−k²/2),
        // 1e-6 per fix at k = 5.3.
        const MOTION_SIGMAS: f64 = 5.3;
        let measured = obs.vel_ned_mps.x.is_finite() && obs.vel_ned_mps.y.is_finite();
        let prev = self.prev_fix_ns.replace(obs.stamp_host_ns);
        let interval_ns = self.fix_interval_ns();
        if let Some(prev) = prev.filter(|&p| obs.stamp_host_ns > p) {
            self.fix_intervals_ns.copy_within(1.., 0);
            self.fix_intervals_ns[FIX_INTERVALS - 1] = obs.stamp_host_ns - prev;
        }
        let speed_std = match prev {
            _ if measured => obs.vel_std_mps,
            // Over the receiver's interval, not over a gap of fixes missed here (the sweep's
            // seed 21 run 5: 1.85 s of fixes waiting for the PPS made 1.8 m/s of a standing
            // robot's 2.8 m/s speed noise look like motion at 12 σ, and a heading 12° off
            // was decided with σ 1.6°).
            Some(prev) if obs.stamp_host_ns > prev => {
                let dt_s = interval_ns.unwrap_or(obs.stamp_host_ns - prev) as f64 * 1e-9;
                let sigma_h = obs.pos_std_m.x.max(obs.pos_std_m.y);
                obs.vel_std_mps.max(std::f64::consts::SQRT_2 * sigma_h / dt_s)
            }
            // The first fix without a measured velocity: its noise is not known yet.
            _ => f64::INFINITY,
        };
        let displaced = !measured && self.displaced(&obs, MOTION_SIGMAS);
        let moving = displaced || obs.speed_mps >= self.cfg.align.align_min_speed_mps.max(MOTION_SIGMAS * speed_std);
        self.motion_seen |= moving;
        if self.filt.is_none() {
            self.adapt_horizon(obs.stamp_host_ns);
            match &mut self.bank {
                Some(bank) => {
                    // Started while standing: the motion onset gives the first estimate of Δ,
                    // once a fix shows the motion above its speed's noise.
                    if self.cfg.estimate_delay
                        && moving
                        && let Some((d, sd)) = self
                            .aligner
                            .delay_from_onset(&obs, speed_std, ONSET_DELAY_FLOOR_S)
                            .filter(|(d, sd)| {
                                *sd < self.delay_prior.1 && (-0.2..self.cfg.fusion_horizon_s - 0.1).contains(d)
                            })
                    {
                        let d = d + self.prior_shift_sigmas * sd;
                        self.delay_prior = (d, sd);
                        bank.reset_delay(d, sd);
                    }
                    bank.queue(obs);
                }
                None => self.try_align(&obs, speed_std, moving),
            }
            return;
        }
        if self.is_tight() {
            let raw_recent = self
                .last_ranges_rx_ns
                .is_some_and(|t| (rx_ns - t) as f64 * 1e-9 <= self.cfg.outage_after_s);
            if raw_recent {
                return;
            }
            self.states.ranges.fallback_fixes += 1;
        }
        self.adapt_horizon(obs.stamp_host_ns);
        self.enqueue(obs);
    }

    /// The receiver's interval between fixes, ns: the median of the last [`FIX_INTERVALS`]
    /// (a gap of missed fixes or a receipt's jitter moves it little); `None` before any.
    fn fix_interval_ns(&self) -> Option<i64> {
        let mut sorted = self.fix_intervals_ns;
        sorted.sort_unstable();
        let seen = &sorted[sorted.partition_point(|&i| i == 0)..];
        (!seen.is_empty()).then(|| seen[seen.len() / 2])
    }

    /// Queues a GNSS measurement, unless its epoch is behind the delayed filter by more than
    /// one covariance step (the horizon was too short: counted).
    fn enqueue<M: Measurement>(&mut self, m: M) {
        let Some(f) = &self.filt else { return };
        if f.t_ns - m.epoch_ns(f.delay_s) > (self.cfg.cov_step_s * 1e9) as i64 {
            self.counters.fixes_too_old += 1;
            return;
        }
        self.states.queue(&mut self.queue, m.into());
    }

    /// Queues a receiver epoch's pseudoranges and Doppler for fusion at its epoch (tightly
    /// coupled; receipt host time `rx_ns` marks GNSS as alive when a satellite is in it).
    /// Before alignment, or loosely coupled, the epoch is counted and dropped.
    pub fn on_ranges(&mut self, epoch: RangeEpoch, rx_ns: i64) {
        if !self.is_tight() || self.filt.is_none() {
            self.states.ranges.epochs_not_tight += 1;
            return;
        }
        self.last_ranges_rx_ns = Some(rx_ns);
        if epoch.count > 0 {
            self.last_fix_rx_ns = Some(rx_ns);
        }
        self.adapt_horizon(epoch.stamp_host_ns);
        self.enqueue(epoch);
    }

    /// The adaptive horizon after a GNSS epoch stamped `stamp_host_ns` (before Δ) arrived.
    /// Before the alignment (the heading bank) the time base's prior of Δ stands for the
    /// filter's estimate under hardware sync (0 ± 0.02 s: the horizon shrinks to what the
    /// fixes need, and the output starts that much earlier); under software sync (0.5 ± 0.5 s)
    /// the horizon is left at its largest until the filter estimates Δ.
    fn adapt_horizon(&mut self, stamp_host_ns: i64) {
        let Some(now) = self.last_imu_ns else {
            return;
        };
        if !self.cfg.adaptive_horizon {
            return;
        }
        // The delay this epoch needed from its epoch (with Δ's doubt) to its release now.
        let (d, sd) = match &self.filt {
            Some(f) => (f.delay_s, f.eskf.std(DELAY)),
            None if self.delay_base.1 <= self.cfg.delay_prior_std_s => (self.delay_base.0, self.delay_base.1),
            None => return,
        };
        let doubt = if self.cfg.estimate_delay { d + 3.0 * sd } else { d };
        let needed = now - stamp_host_ns + (doubt.max(0.0) * 1e9) as i64;
        self.fix_delay_ns = needed.max(self.fix_delay_ns - (HORIZON_DECAY_S * 1e9) as i64);
        let max = (self.cfg.fusion_horizon_s * 1e9) as i64;
        let min = (MIN_HORIZON_S * 1e9) as i64;
        self.horizon_ns = (self.fix_delay_ns + (HORIZON_MARGIN_S * 1e9) as i64).clamp(min, max);
    }

    /// True when the filter estimates the receiver clock and fuses satellites' measurements
    /// (tightly coupled: [`ProcessNoise::clock`] set).
    pub fn is_tight(&self) -> bool {
        self.cfg.coupling == Coupling::Tight
    }

    /// The receiver clock at host time `now_ns` from the tightly coupled filter: the delayed
    /// filter's bias extrapolated with its drift, σ grown by the covariance over the interval
    /// and the oscillator's process noise (holdover while no satellite is fused), never below
    /// the last single-point solution's clock σ ([`DelayedFilter::clock_floor_std_m`]). `None` when
    /// loosely coupled or before the clock was anchored.
    pub fn receiver_clock(&self, now_ns: i64) -> Option<ReceiverClock> {
        let (f, osc) = (self.filt.as_ref()?, self.cfg.noise.clock?);
        if !f.clock_valid {
            return None;
        }
        let dt = ((now_ns - f.t_ns) as f64 * 1e-9).max(0.0);
        let p = &f.eskf.p;
        let q = osc.with_random_walk_fm_scaled(f.clock_q_scale).process_noise_m(dt);
        let var_b = p[(CLK_BIAS, CLK_BIAS)]
            + 2.0 * dt * p[(CLK_BIAS, CLK_DRIFT)]
            + dt * dt * p[(CLK_DRIFT, CLK_DRIFT)]
            + q[(0, 0)];
        let var_d = p[(CLK_DRIFT, CLK_DRIFT)] + q[(1, 1)];
        Some(ReceiverClock {
            bias_m: f.clock_bias_m + f.clock_drift_mps * dt,
            drift_mps: f.clock_drift_mps,
            bias_std_m: var_b.max(0.0).sqrt().max(f.clock_floor_std_m),
            drift_std_mps: var_d.max(0.0).sqrt(),
            last_fused_ns: self.states.ranges.last_fused_ns,
        })
    }

    /// Starts the filter from a known state (instead of [`Self::on_gnss`]'s alignment) at host
    /// time `host_ns` (the state's instant), with the gyro and accelerometer biases and their
    /// and the state's 1-sigma as given; the other sensor errors start at zero with their
    /// turn-on σ. Does nothing once the filter runs.
    pub fn initialize(&mut self, init: &InitialState, host_ns: i64) {
        if let Some(sh) = &mut self.shadow {
            sh.initialize(init, host_ns);
        }
        if self.filt.is_some() {
            return;
        }
        self.bank = None;
        let cfg = &self.cfg;
        let [r, p_, y] = init.rpy_deg.map(f64::to_radians);
        let pva = Pva {
            lat_rad: init.lat_deg.to_radians(),
            lon_rad: init.lon_deg.to_radians(),
            h_m: init.height_m,
            vel_ned_mps: Vector3::from(init.vel_ned_mps),
            q_nb: nalgebra::UnitQuaternion::from_euler_angles(r, p_, y),
        };
        const DEG_H: f64 = std::f64::consts::PI / 180.0 / 3600.0;
        let mut p = StateMat::zeros();
        for i in 0..3 {
            p[(POS + i, POS + i)] = init.pos_std_m[i].powi(2);
            p[(VEL + i, VEL + i)] = init.vel_std_mps[i].powi(2);
            p[(ATT + i, ATT + i)] = init.att_std_deg[i].to_radians().powi(2);
            p[(BG + i, BG + i)] = cfg.noise.gyro_bias_init_std[i].powi(2);
            p[(BA + i, BA + i)] = cfg.noise.accel_bias_init_std[i].powi(2);
            if cfg.noise.estimate_scale {
                p[(SG + i, SG + i)] = cfg.noise.gyro_scale_init_std[i].powi(2);
                p[(SA + i, SA + i)] = cfg.noise.accel_scale_init_std[i].powi(2);
            }
        }
        if cfg.estimate_delay {
            p[(DELAY, DELAY)] = self.delay_prior.1.powi(2);
        }
        while self.buf.front().is_some_and(|r| r.host_ns <= host_ns) {
            self.buf.pop();
        }
        let mut f = DelayedFilter::new(
            pva,
            host_ns,
            Eskf::new(p),
            Vector3::from(init.gyro_bias_deg_per_h) * DEG_H,
            self.delay_prior.0,
        );
        f.bias_a = Vector3::from(init.accel_bias_mgal) * 1e-5;
        if let Some(log) = &mut self.smoother {
            log.start(&f);
        }
        self.filt = Some(f);
        self.states.gnss.last_fused_ns = host_ns;
        self.replay();
    }

    /// Whether `obs` lies farther from one of the fixes of the last [`MOTION_BASELINE_S`] than
    /// `k` σ of the difference of their horizontal positions, and as far as the alignment's
    /// minimum speed covers in that time: motion shown by positions alone, where a speed from
    /// two neighbouring fixes is too noisy (metre-level fixes at 4 Hz: a difference σ of 5 m/s,
    /// a car never reaches 5.3 σ of it). Remembers `obs`.
    fn displaced(&mut self, obs: &GnssObservation, k: f64) -> bool {
        let (rm, rn) = navsync_wire::earth::radii(obs.lat_rad);
        let sigma_h = obs.pos_std_m.x.max(obs.pos_std_m.y);
        let shown = self.recent_fixes[..self.recent_len].iter().any(|&(t, lat, lon, s)| {
            let dt_s = (obs.stamp_host_ns - t) as f64 * 1e-9;
            let north_m = (obs.lat_rad - lat) * (rm + obs.h_m);
            let east_m = (obs.lon_rad - lon) * (rn + obs.h_m) * obs.lat_rad.cos();
            let d = north_m.hypot(east_m);
            dt_s > 0.0
                && dt_s <= MOTION_BASELINE_S
                && d >= k * sigma_h.hypot(s)
                && d >= self.cfg.align.align_min_speed_mps * dt_s
        });
        if self.recent_len == RECENT_FIXES {
            self.recent_fixes.copy_within(1.., 0);
            self.recent_len -= 1;
        }
        self.recent_fixes[self.recent_len] = (obs.stamp_host_ns, obs.lat_rad, obs.lon_rad, sigma_h);
        self.recent_len += 1;
        shown
    }

    /// Aligns on `obs` when the aligner can (`speed_std_mps`: the σ of its speed; `moving`: it
    /// shows motion above that noise).
    fn try_align(&mut self, obs: &GnssObservation, speed_std_mps: f64, moving: bool) {
        let Some(mut a) = self.aligner.try_align(obs, speed_std_mps, moving) else {
            return;
        };
        // The initial velocity. Standing (the IMU static after its levelling): zero to within
        // the configured σ0, refined by the fix's velocity with its own σ (the product of the
        // two Gaussians: a Doppler velocity of 0.1 m/s counts, a speed differenced from 1.8 m
        // positions 0.1 s apart, 25 m/s of noise, does not). Moving: the fix's velocity, with
        // at least its own σ.
        let sigma0 = self.cfg.init_vel_std_mps;
        let vel_std = if a.standing {
            // A σ of zero is a velocity's σ not given (no receiver knows its velocity exactly).
            let k = if a.vel_std_mps.is_finite() && a.vel_std_mps > 0.0 {
                sigma0 * sigma0 / (sigma0 * sigma0 + a.vel_std_mps * a.vel_std_mps)
            } else {
                0.0
            };
            a.pva.vel_ned_mps *= k;
            a.acc_ned *= k;
            sigma0 * (1.0 - k).sqrt()
        } else if a.vel_std_mps.is_finite() {
            sigma0.max(a.vel_std_mps)
        } else {
            sigma0
        };
        // A loose delay prior (software sync) is replaced by the motion-onset estimate: the
        // speed noise of a fix (~0.05 m/s) over a drive-off acceleration of ~1 m/s² puts it
        // within ~50 ms. Only on a fix that shows motion: a standing fix's speed is its noise,
        // which the accelerometers' integrated noise reaches at any time.
        if self.cfg.estimate_delay
            && moving
            && let Some((d, sd)) = a
                .delay_from_onset_s
                .filter(|(d, sd)| *sd < self.delay_prior.1 && (-0.2..self.cfg.fusion_horizon_s - 0.1).contains(d))
        {
            self.delay_prior = (d + self.prior_shift_sigmas * sd, sd);
        }
        let cfg = &self.cfg;
        let mut p = StateMat::zeros();
        for i in 0..3 {
            p[(POS + i, POS + i)] = obs.pos_std_m[i].powi(2);
            p[(VEL + i, VEL + i)] = vel_std.powi(2);
            p[(BG + i, BG + i)] = if a.levelled {
                // Static average: white noise over the static time plus the bias instability.
                cfg.noise.arw[i] * cfg.noise.arw[i] / a.static_s.max(1.0) + cfg.noise.gyro_bias_std[i].powi(2)
            } else {
                cfg.noise.gyro_bias_init_std[i].powi(2)
            };
            p[(BA + i, BA + i)] = cfg.noise.accel_bias_init_std[i].powi(2);
            if cfg.noise.estimate_scale {
                p[(SG + i, SG + i)] = cfg.noise.gyro_scale_init_std[i].powi(2);
                p[(SA + i, SA + i)] = cfg.noise.accel_scale_init_std[i].powi(2);
            }
        }
        let level_std = if a.levelled {
            cfg.init_level_std_rad
        } else {
            5f64.to_radians()
        };
        p[(ATT, ATT)] = level_std.powi(2);
        p[(ATT + 1, ATT + 1)] = level_std.powi(2);
        p[(ATT + 2, ATT + 2)] = cfg.init_yaw_std_rad.powi(2);
        if cfg.estimate_delay {
            // The initial position and velocity come from a fix whose epoch is only known to
            // σ_Δ: δr = −v·δΔ and δv = −a·δΔ (see measurements::gnss), so they share that uncertainty.
            let var_d = self.delay_prior.1.powi(2);
            let v = a.pva.vel_ned_mps;
            let acc = a.acc_ned;
            p[(DELAY, DELAY)] = var_d;
            for i in 0..3 {
                p[(POS + i, DELAY)] = -v[i] * var_d;
                p[(DELAY, POS + i)] = -v[i] * var_d;
                p[(VEL + i, DELAY)] = -acc[i] * var_d;
                p[(DELAY, VEL + i)] = -acc[i] * var_d;
                for j in 0..3 {
                    p[(POS + i, POS + j)] += v[i] * v[j] * var_d;
                    p[(VEL + i, VEL + j)] += acc[i] * acc[j] * var_d;
                    p[(POS + i, VEL + j)] += v[i] * acc[j] * var_d;
                    p[(VEL + j, POS + i)] += v[i] * acc[j] * var_d;
                }
            }
        }
        let t_f = obs.stamp_host_ns - (self.delay_prior.0 * 1e9) as i64;
        while self.buf.front().is_some_and(|r| r.host_ns <= t_f) {
            self.buf.pop();
        }
        let base = DelayedFilter::new(a.pva, t_f, Eskf::new(p), a.gyro_bias, self.delay_prior.0);
        self.bank = Some(HeadingBank::new(&base, &Vector3::from(self.cfg.gnss_lever_arm_m)));
        self.counters.heading_banks += 1;
    }

    /// Steps the heading bank over the buffered records older than `until_ns`; once it decides,
    /// the fine alignment runs ([`Self::fine_align`]).
    fn step_bank(&mut self, until_ns: i64) {
        let Some(bank) = &mut self.bank else { return };
        while let Some(r) = self.buf.front().copied() {
            if r.host_ns > until_ns {
                break;
            }
            self.buf.pop();
            match bank.step(&r, &self.cfg) {
                BankStep::Pending => {}
                BankStep::Failed => {
                    self.bank = None;
                    self.counters.heading_banks_failed += 1;
                    return;
                }
                BankStep::Decided { yaw0, yaw_std } => {
                    if let Some(mut bank) = self.bank.take() {
                        self.fine_align(&mut bank, yaw0, yaw_std);
                    }
                    return;
                }
            }
        }
    }

    /// The fine alignment after the bank decided: one filter from the bank's start with the
    /// decided initial heading `yaw0` ± `yaw_std` (rad) runs over the records and fixes the
    /// bank went through, with every kind of measurement, and becomes the delayed filter; the
    /// fixes still waiting are queued for it.
    fn fine_align(&mut self, bank: &mut HeadingBank, yaw0: f64, yaw_std: f64) {
        let start = with_heading(bank.base(), yaw0, yaw_std, &Vector3::from(self.cfg.gnss_lever_arm_m));
        self.states.gnss.last_fused_ns = start.t_ns;
        if let Some(log) = &mut self.smoother {
            log.start(&start);
        }
        self.filt = Some(start);
        let (records, fused, pending) = bank.log();
        // The states of the re-run are fused states like any later one (events marked while
        // the bank decided get their pose from them): the last half batch of them, so the
        // batch keeps its capacity (10 s at 200 Hz; the events waiting reach back ~9 s).
        let emit_from = records.len().saturating_sub(MAX_FUSED_BATCH / 2);
        let mut next = 0;
        for (k, r) in records.iter().enumerate() {
            while let (Some(obs), Some(f)) = (fused.get(next), &self.filt)
                && obs.epoch_ns(f.delay_s) <= r.host_ns
            {
                self.enqueue(*obs);
                next += 1;
            }
            self.filter_step(r);
            if k >= emit_from {
                self.push_fused(r);
            }
        }
        for obs in fused[next..].iter().copied().chain(pending) {
            self.enqueue(obs);
        }
    }

    /// Feeds one IMU interval (host time of its end, ns; nominal length, s; average rate and
    /// specific force in the body frame) to both the filter and the output predictor (single
    /// IMU). Returns true when a present-time state is available.
    pub fn on_imu(
        &mut self,
        host_ns: i64,
        nominal_dt_s: f64,
        gyro_rps: Vector3<f64>,
        accel_mps2: Vector3<f64>,
    ) -> bool {
        self.on_filter_imu(host_ns, nominal_dt_s, gyro_rps, accel_mps2);
        // A correction reaches the output at once here (no deferred catch-up).
        self.catch_up(usize::MAX);
        self.on_output_imu(host_ns, nominal_dt_s, gyro_rps, accel_mps2)
    }

    /// Makes a record of one stream's interval: rejects time going backwards and bridges gaps
    /// of dropped samples (up to 0.1 s, assuming constant rates).
    fn record(
        last: &mut Option<i64>,
        counters: &mut NavCounters,
        host_ns: i64,
        nominal_dt_s: f64,
        gyro_rps: Vector3<f64>,
        accel_mps2: Vector3<f64>,
    ) -> Option<ImuRecord> {
        let dt_s = match *last {
            Some(prev) if host_ns <= prev => {
                counters.imu_backwards += 1;
                return None;
            }
            Some(prev) => {
                let gap = (host_ns - prev) as f64 * 1e-9;
                if gap > 1.5 * nominal_dt_s {
                    counters.imu_gaps += 1;
                    gap.min(0.1)
                } else {
                    nominal_dt_s
                }
            }
            None => nominal_dt_s,
        };
        *last = Some(host_ns);
        Some(ImuRecord {
            host_ns,
            dt_s,
            gyro_rps,
            accel_mps2,
        })
    }

    /// Moves the GNSS antenna lever arm (body frame FRD, m, antenna − navigation point): the
    /// IMU that defines the navigation point changed (array reference handover).
    pub fn set_lever_arm(&mut self, lever_arm_b_m: Vector3<f64>) {
        self.cfg.gnss_lever_arm_m = lever_arm_b_m.into();
        if let Some(sh) = &mut self.shadow {
            sh.set_lever_arm(lever_arm_b_m);
        }
    }

    /// Feeds one interval of the filter stream (the fused virtual IMU, or the single IMU): it
    /// enters the fusion horizon and the delayed filter consumes what is older than the horizon
    /// (the shadow's too, and Δ's doubt follows).
    pub fn on_filter_imu(&mut self, host_ns: i64, nominal_dt_s: f64, gyro_rps: Vector3<f64>, accel_mps2: Vector3<f64>) {
        if let Some(sh) = &mut self.shadow {
            sh.on_filter_imu(host_ns, nominal_dt_s, gyro_rps, accel_mps2);
        }
        self.step_filter_stream(host_ns, nominal_dt_s, gyro_rps, accel_mps2);
        self.update_delay_doubt();
    }

    /// An IMU of unknown class: its signal's white-noise bound, and at the end of each block
    /// the process noise scaled to it (until the data contradicted the model: [`widened`]).
    fn measure_noise(&mut self, nominal_dt_s: f64, gyro_rps: &Vector3<f64>, accel_mps2: &Vector3<f64>) {
        let Some((generic, meter, k_bias)) = &mut self.noise_from_signal else {
            return;
        };
        if self.widened {
            return;
        }
        let meter = meter.get_or_insert_with(|| NoiseMeter::new(nominal_dt_s));
        if let Some(m) = meter.push(nominal_dt_s, gyro_rps, accel_mps2) {
            (self.cfg.noise, *k_bias) = scaled_to_signal(generic, &m, *k_bias, &self.cfg.noise);
        }
    }

    /// [`Self::on_filter_imu`] for this navigator alone.
    fn step_filter_stream(
        &mut self,
        host_ns: i64,
        nominal_dt_s: f64,
        gyro_rps: Vector3<f64>,
        accel_mps2: Vector3<f64>,
    ) {
        let Some(rec) = Self::record(
            &mut self.last_imu_ns,
            &mut self.counters,
            host_ns,
            nominal_dt_s,
            gyro_rps,
            accel_mps2,
        ) else {
            return;
        };
        self.measure_noise(nominal_dt_s, &gyro_rps, &accel_mps2);
        if self.filt.is_none() {
            self.aligner.on_imu(&rec);
        }
        self.buf.push(rec);
        while self.out_tail.front().is_some_and(|r| r.host_ns <= host_ns) {
            self.out_tail.pop();
        }
        let horizon_ns = self.horizon_ns;
        let mut corrected = false;
        let mut decided = false;
        if self.filt.is_none() && self.bank.is_some() {
            self.step_bank(host_ns - horizon_ns);
            decided = self.filt.is_some();
        }
        let Some(filt) = &mut self.filt else {
            while self.buf.front().is_some_and(|r| r.host_ns < host_ns - horizon_ns) {
                self.buf.pop();
            }
            return;
        };
        let mut t = filt.t_ns;
        while let Some(r) = self.buf.front().copied() {
            if r.host_ns > host_ns - horizon_ns {
                break;
            }
            self.buf.pop();
            if r.host_ns <= t {
                // Before a known initial state's instant (the filter stream lags the output's).
                continue;
            }
            corrected |= self.filter_step(&r);
            t = r.host_ns;
            self.push_fused(&r);
        }
        if !self.monitor() {
            return;
        }
        if decided {
            // The heading was just decided: the output starts from the new filter at once.
            self.replay();
        } else if corrected {
            self.counters.replays += 1;
            self.start_catch_up();
        }
    }

    /// One step of the delayed filter over record `r`: mechanization (and the covariance
    /// propagation when due), the measurements the IMU data make, and every measurement due.
    /// With smoothing on, the step and its updates go into the log. True when a measurement
    /// corrected the state.
    fn filter_step(&mut self, r: &ImuRecord) -> bool {
        let Some(filt) = &mut self.filt else { return false };
        let before = filt.propagations;
        filt.step(r, &self.cfg);
        self.states.on_step(r, filt, &self.cfg, &self.kinds, &mut self.queue);
        let Some(log) = &mut self.smoother else {
            return self.queue.fuse_due(filt, &self.cfg, &self.kinds, &mut self.states);
        };
        if filt.propagations != before {
            log.on_propagation(&filt.last_phi);
        }
        log.on_step(filt);
        if self.queue.has_due(filt) {
            // What fuse_due does first anyway: the covariance propagated to now.
            let flushed = filt.propagations;
            filt.propagate_covariance(&self.cfg);
            if filt.propagations != flushed {
                log.on_propagation(&filt.last_phi);
            }
            log.before_updates(filt);
        }
        let corrected = self.queue.fuse_due(filt, &self.cfg, &self.kinds, &mut self.states);
        log.after_updates(filt, filt.propagations != before);
        corrected
    }

    /// Keeps what the offline smoother needs from here on ([`SmootherLog`]).
    pub fn enable_smoothing(&mut self) {
        let mut log = SmootherLog::new();
        if let Some(f) = &self.filt {
            log.start(f);
        }
        self.smoother = Some(log);
    }

    /// The smoother's log, when smoothing is on.
    pub fn smoother(&self) -> Option<&SmootherLog> {
        self.smoother.as_ref()
    }

    /// The integrity monitor ([`integrity`]) over the delayed filter: a breakdown or an
    /// implausible state resets the filter (it aligns again); an inconsistency inflates its
    /// covariance by the running NIS and flags the states until the innovations agree again.
    /// Returns false when the filter was reset.
    fn monitor(&mut self) -> bool {
        let Some(f) = &mut self.filt else { return true };
        f.sigma_scale = self.states.gnss.nis_average.max(1.0).sqrt();
        let (prior_s, prior_std_s, floor_s) = self.delay_base;
        let max_delay_s = self.cfg.fusion_horizon_s - DELAY_HORIZON_MARGIN_S;
        if self.cfg.estimate_delay && (f.delay_s < floor_s || f.delay_s <= MIN_DELAY_S || f.delay_s >= max_delay_s) {
            // Not an estimate: what the filter wants lies outside what is physical or beyond
            // its bound, and its σ says nothing of that. Δ starts again from the time base's
            // prior, the states flagged as recovering.
            self.integrity.delay_resets += 1;
            self.recovering_until_ns = f.t_ns + (self.cfg.integrity.recovering_s * 1e9) as i64;
            self.delay_prior = (prior_s, prior_std_s);
            reopen_delay(f, prior_s, prior_std_s, true);
            self.start_catch_up();
            return true;
        }
        let nis = self.states.gnss.nis_average;
        match integrity::check(f, &self.cfg.noise, nis, &self.cfg.integrity, &mut self.pd_memo) {
            Some(fault @ (Fault::NonFinite | Fault::NotPositiveDefinite)) => {
                self.integrity.count(fault);
                self.integrity.resets += 1;
                let t = f.t_ns;
                self.recovering_until_ns = t + (self.cfg.integrity.recovering_s * 1e9) as i64;
                self.reset();
                false
            }
            Some(Fault::Implausible) => {
                self.integrity.count(Fault::Implausible);
                self.recovering_until_ns = f.t_ns + (self.cfg.integrity.recovering_s * 1e9) as i64;
                let wider = widened(&self.cfg.noise);
                if !self.widened && wider != self.cfg.noise && integrity::plausible(f, &wider, &self.cfg.integrity) {
                    // Sensor errors an IMU of unknown class may have: the configured model
                    // was too narrow for this IMU. It is widened (once, as on an inconsistency),
                    // the estimates are kept and their σ reopened to the wider turn-on σ.
                    self.widened = true;
                    self.cfg.noise = wider;
                    reopen_bias_std(f, &wider);
                } else {
                    // Beyond any IMU's: the navigation states are sound; the sensor errors are
                    // re-learnt from their turn-on σ, decorrelated from the rest.
                    reset_sensor_errors(f, &self.cfg.noise);
                }
                if let Some(log) = &mut self.smoother {
                    log.start(f);
                }
                self.start_catch_up();
                true
            }
            Some(Fault::Inconsistent) => {
                if !self.inconsistent {
                    // A new episode, flagged. An IMU model the data contradict is widened to the
                    // conservative one of an IMU of unknown class (each term at least the
                    // generic preset's), once; a filter whose model is already that wide has its
                    // covariance inflated on the rejected fixes ([`GnssFusion`]).
                    self.integrity.count(Fault::Inconsistent);
                    self.inconsistent = true;
                    if !self.widened {
                        self.widened = true;
                        let wider = widened(&self.cfg.noise);
                        if wider != self.cfg.noise {
                            // The model was narrower than any real IMU's: what it made the
                            // covariance is scaled to the innovations, once, and the sensor
                            // errors get at least the wider model's turn-on σ.
                            self.cfg.noise = wider;
                            f.eskf.p *= nis;
                            reopen_bias_std(f, &wider);
                        }
                    }
                }
                true
            }
            None => {
                // Flagged until the running NIS is back below half the bound.
                if self.inconsistent && nis < 0.5 * self.cfg.integrity.max_nis_average {
                    self.inconsistent = false;
                }
                true
            }
        }
    }

    /// Drops the filter and its output: it aligns again from the next fix (the levelling and
    /// the IMU buffer are kept; the measurement counters go on).
    fn reset(&mut self) {
        self.filt = None;
        self.bank = None;
        self.out = None;
        self.catchup = None;
        self.queue = MeasurementQueue::default();
        self.inconsistent = false;
        self.states.gnss.nis_average = 1.0;
        self.states.gnss.consecutive_rejects = 0;
    }

    /// What the integrity monitor found, by kind.
    pub fn integrity(&self) -> &IntegrityCounters {
        &self.integrity
    }

    /// Feeds one interval of the output stream (the reference IMU at the present): advances the
    /// present-time state by one mechanization step. Returns true when a state is available.
    pub fn on_output_imu(
        &mut self,
        host_ns: i64,
        nominal_dt_s: f64,
        gyro_rps: Vector3<f64>,
        accel_mps2: Vector3<f64>,
    ) -> bool {
        let Some(rec) = Self::record(
            &mut self.last_output_ns,
            &mut self.counters,
            host_ns,
            nominal_dt_s,
            gyro_rps,
            accel_mps2,
        ) else {
            return self.out.is_some();
        };
        if self.last_imu_ns.is_none_or(|f| rec.host_ns > f) {
            // Newer than the filter stream: the replay after a correction needs it.
            self.out_tail.push(rec);
        }
        let (Some(filt), Some((pva, pre, t))) = (&self.filt, &mut self.out) else {
            return false;
        };
        if rec.host_ns > *t {
            let (w, f) = filt.compensate(&rec);
            let inc = ImuIncrement::from_rates(rec.dt_s, w, f);
            *pva = propagate(pva, pre, &inc);
            *pre = inc;
            *t = rec.host_ns;
            self.out_w = w;
            self.out_f = f;
        }
        true
    }

    /// Starts re-propagating the output from the (corrected) delayed state; see
    /// [`catch_up`](Self::catch_up).
    fn start_catch_up(&mut self) {
        self.catchup = self.filt.as_ref().map(|filt| CatchUp {
            pva: filt.pva,
            pre: filt.pre,
            t: filt.t_ns,
            w: filt.last_w,
            f: Vector3::zeros(),
        });
    }

    /// Brings a correction of the delayed state forward to the present by at most `max_steps`
    /// mechanization steps: the output is re-propagated from the corrected delayed state
    /// through the buffered filter-stream intervals (all newer than the delayed state), then
    /// the output-stream intervals newer still, and replaces the present-time state once it
    /// has reached it. Meanwhile the output goes on from the uncorrected state. So no single
    /// IMU sample pays for the whole fusion horizon (1.5 s: 1500 steps at 1 kHz, ~0.6 ms); with
    /// `max_steps` per output sample a correction reaches the output
    /// horizon / (max_steps − 1) samples later. Returns true while a catch-up is in progress.
    pub fn catch_up(&mut self, max_steps: usize) -> bool {
        let (Some(c), Some(filt)) = (&mut self.catchup, &self.filt) else {
            return false;
        };
        let newest_filter = self.buf.iter().last().map_or(filt.t_ns, |r| r.host_ns);
        let from_ns = c.t;
        let mut records = self
            .buf
            .iter()
            .chain(self.out_tail.iter().filter(|r| r.host_ns > newest_filter))
            .filter(|r| r.host_ns > from_ns);
        for r in records.by_ref().take(max_steps) {
            (c.w, c.f) = filt.compensate(r);
            let inc = ImuIncrement::from_rates(r.dt_s, c.w, c.f);
            c.pva = propagate(&c.pva, &c.pre, &inc);
            c.pre = inc;
            c.t = r.host_ns;
        }
        if records.next().is_some() {
            return true;
        }
        let c = *c;
        self.out = Some((c.pva, c.pre, c.t));
        self.out_w = c.w;
        self.out_f = c.f;
        self.catchup = None;
        false
    }

    /// Recomputes the output state from the delayed state at once (the whole catch-up).
    fn replay(&mut self) {
        self.start_catch_up();
        self.catch_up(usize::MAX);
    }

    /// Filter status at host time `now_ns`.
    pub fn status(&self, now_ns: i64) -> NavStatus {
        if self.filt.is_none() || self.out.is_none() {
            return NavStatus::Aligning;
        }
        let outage = self
            .last_fix_rx_ns
            .is_none_or(|t| (now_ns - t) as f64 * 1e-9 > self.cfg.outage_after_s);
        if outage {
            NavStatus::InsOnly
        } else if self.states.gnss.consecutive_rejects >= 3 {
            NavStatus::Degraded
        } else {
            NavStatus::Aligned
        }
    }

    /// Fills the navigation part of a [`NavState`] for the present (host time `now_ns`).
    pub fn fill(&self, s: &mut NavState, now_ns: i64) {
        s.host_ns = now_ns;
        s.status = self.status(now_ns) as u8;
        s.integrity = self.integrity_flags();
        s.fixes_used = self.states.gnss.fixes_used as u32;
        s.fixes_rejected = self.states.gnss.fixes_rejected as u32;
        s.last_fix_host_ns = self.states.gnss.last_fused_ns;
        let (Some((pva, _, _)), Some(filt)) = (&self.out, &self.filt) else {
            for v in [
                &mut s.lat_deg,
                &mut s.lon_deg,
                &mut s.height_m,
                &mut s.gnss_delay_s,
                &mut s.gnss_delay_std_s,
            ] {
                *v = f64::NAN;
            }
            if let Some((r, p)) = self.aligner.level() {
                s.rpy_rad = [r, p, f64::NAN];
            } else {
                s.rpy_rad = [f64::NAN; 3];
            }
            s.vel_ned_mps = [f64::NAN; 3];
            s.q_nb = [f64::NAN; 4];
            return;
        };
        let q = pva.q_nb.quaternion();
        let finite = [pva.lat_rad, pva.lon_rad, pva.h_m, q.w, q.i, q.j, q.k]
            .iter()
            .chain(pva.vel_ned_mps.iter())
            .all(|x| x.is_finite());
        if !finite {
            // The output predictor broke down before the monitor saw the filter do so: no
            // number is claimed (the next check resets the filter).
            s.status = NavStatus::Aligning as u8;
            s.integrity |= INTEGRITY_RECOVERING;
            s.lat_deg = f64::NAN;
            s.lon_deg = f64::NAN;
            s.height_m = f64::NAN;
            s.vel_ned_mps = [f64::NAN; 3];
            s.rpy_rad = [f64::NAN; 3];
            s.q_nb = [f64::NAN; 4];
            return;
        }
        write_pose(s, pva, self.out_w, self.out_f, filt);
        let (d, ds) = self.gnss_delay();
        s.gnss_delay_s = d;
        s.gnss_delay_std_s = ds;
    }

    /// Keeps the delayed filter's state at the end of record `r` (see [`Self::drain_fused`]).
    fn push_fused(&mut self, r: &ImuRecord) {
        if self.fused.is_none() {
            return;
        }
        self.update_delay_doubt();
        let Some(filt) = &self.filt else {
            return;
        };
        let mut s = <NavState as navsync_wire::reflect::Reflect>::zeroed();
        s.host_ns = r.host_ns;
        s.status = self.status(r.host_ns) as u8;
        s.integrity = self.integrity_flags();
        s.fixes_used = self.states.gnss.fixes_used as u32;
        s.fixes_rejected = self.states.gnss.fixes_rejected as u32;
        s.last_fix_host_ns = self.states.gnss.last_fused_ns;
        let (w, f) = filt.compensate(r);
        write_pose(&mut s, &filt.pva, w, f, filt);
        let (d, ds) = self.gnss_delay();
        s.gnss_delay_s = d;
        s.gnss_delay_std_s = ds;
        if let Some(v) = &mut self.fused {
            v.push(s);
        }
    }

    /// Keeps the delayed filter's states for [`Self::drain_fused`] from now on (the caller
    /// must drain them).
    pub fn keep_fused(&mut self) {
        self.fused.get_or_insert_with(|| Vec::with_capacity(MAX_FUSED_BATCH));
    }

    /// Hands each state the delayed filter made since the last call to `f`, oldest first: the
    /// state at an instant once every measurement up to it is fused (better than the
    /// prediction made for that instant, which had only the measurements then received).
    /// Navigation fields only, as [`Self::fill`]; a state may be non-finite when the filter
    /// broke down (the monitor resets it after the step).
    pub fn drain_fused(&mut self, f: &mut dyn FnMut(&NavState)) {
        for s in self.fused.iter_mut().flatten() {
            f(s);
        }
        if let Some(v) = &mut self.fused {
            v.clear();
        }
    }

    /// The [`NavState::integrity`] flags of the filter now.
    fn integrity_flags(&self) -> u8 {
        let mut flags = 0;
        if self.filt.is_none() {
            flags |= INTEGRITY_HEADING_UNKNOWN;
        }
        if self.inconsistent {
            flags |= INTEGRITY_INCONSISTENT;
        }
        if self.filt.as_ref().is_some_and(|f| f.t_ns < self.recovering_until_ns)
            || (self.filt.is_none() && self.integrity.resets > 0)
        {
            flags |= INTEGRITY_RECOVERING;
        }
        flags
    }

    /// An empty per-IMU table.
    pub fn empty_imu_table() -> [ImuSync; MAX_IMUS] {
        [<ImuSync as navsync_wire::reflect::Reflect>::zeroed(); MAX_IMUS]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nav::config::InitialState;
    use navsync_wire::earth;

    /// A navigator initialised at 45° N, 7° E, 300 m, level and heading north, at 1 s, moving
    /// north at `north_mps`, its position known to `pos_std_m` per axis.
    fn aligned_with(north_mps: f64, pos_std_m: f64) -> Navigator {
        let mut nav = Navigator::new(NavConfig::default());
        let init = InitialState {
            utc_ns: 0,
            lat_deg: 45.0,
            lon_deg: 7.0,
            height_m: 300.0,
            vel_ned_mps: [north_mps, 0.0, 0.0],
            rpy_deg: [0.0, 0.0, 0.0],
            gyro_bias_deg_per_h: [0.0; 3],
            accel_bias_mgal: [0.0; 3],
            pos_std_m: [pos_std_m; 3],
            vel_std_mps: [0.05; 3],
            att_std_deg: [0.5, 0.5, 2.0],
        };
        nav.initialize(&init, 1_000_000_000);
        nav
    }

    fn aligned() -> Navigator {
        aligned_with(1.0, 0.1)
    }

    /// An IMU of unknown class (the generic model) gets the process noise its signal shows: a
    /// quiet one's white noise and instabilities scaled down, a vibrating one's never above the
    /// generic model; a model given, or the switch off, stays as configured.
    #[test]
    fn an_unknown_imus_noise_follows_its_signal_and_a_given_model_stays() {
        use crate::test_noise::gauss;
        let g = earth::normal_gravity(45f64.to_radians(), 300.0);
        let generic = ProcessNoise::from_imu_noise(&ImuPreset::Generic.noise());
        let consumer = ProcessNoise::from_imu_noise(&ImuPreset::Consumer.noise());
        let mut navs = [
            Navigator::new(NavConfig::default()),
            Navigator::new(NavConfig::with_noise(consumer)),
            Navigator::new(NavConfig {
                imu_noise_from_signal: false,
                ..NavConfig::default()
            }),
        ];
        let dt: f64 = 0.005;
        let mut rng = 11u64;
        // 15 s each: beyond the meter's first window.
        let mut feed = |navs: &mut [Navigator; 3], from: i64, scale_g: f64, scale_a: f64| {
            for k in from..from + 3000 {
                let w = Vector3::from_fn(|_, _| gauss(&mut rng)) * (scale_g * generic.arw.mean() / dt.sqrt());
                let a = Vector3::from_fn(|_, _| gauss(&mut rng)) * (scale_a * generic.vrw.mean() / dt.sqrt());
                for nav in navs.iter_mut() {
                    nav.on_imu(1_000_000_000 + k * 5_000_000, dt, w, a + Vector3::new(0.0, 0.0, -g));
                }
            }
        };
        // Quiet: a tenth of the generic gyro noise, a fifth of its accelerometer's.
        feed(&mut navs, 0, 0.1, 0.2);
        let n = navs[0].config().noise;
        let ratio = |x: &Vector3<f64>, y: &Vector3<f64>| x.mean() / y.mean();
        assert!((0.09..0.13).contains(&ratio(&n.arw, &generic.arw)), "{:?}", n.arw);
        assert!((0.18..0.26).contains(&ratio(&n.vrw, &generic.vrw)), "{:?}", n.vrw);
        let k = ratio(&n.vrw, &generic.vrw);
        assert!((ratio(&n.gyro_bias_std, &generic.gyro_bias_std) - k).abs() < 1e-12);
        assert!((ratio(&n.accel_bias_std, &generic.accel_bias_std) - k).abs() < 1e-12);
        assert_eq!(n.gyro_bias_init_std, generic.gyro_bias_init_std);
        assert_eq!(navs[1].config().noise.arw, consumer.arw);
        assert_eq!(navs[2].config().noise.arw, generic.arw);
        // Vibrating: five times the generic model's noise; it keeps the generic model.
        feed(&mut navs, 3000, 5.0, 5.0);
        assert_eq!(navs[0].config().noise.arw, generic.arw);
        assert_eq!(navs[0].config().noise.accel_bias_std, generic.accel_bias_std);
        assert_eq!(navs[1].config().noise.vrw, consumer.vrw);
        // Quiet again (a vehicle stopped): the white noise follows, the instabilities stay.
        feed(&mut navs, 6000, 0.1, 0.2);
        let n = navs[0].config().noise;
        assert!(ratio(&n.arw, &generic.arw) < 0.13, "{:?}", n.arw);
        assert_eq!(n.gyro_bias_std, generic.gyro_bias_std);
    }

    /// A loose prior of Δ (software sync) runs a shadow with the prior one σ above, fed the
    /// same inputs; a tight one (hardware sync) none.
    #[test]
    fn a_loose_delay_prior_runs_a_shadow_one_sigma_above() {
        let mut nav = aligned();
        nav.reset_delay(0.0, 0.02);
        assert!(nav.shadow.is_none());
        nav.reset_delay(0.5, 0.5);
        let sh = nav.shadow.as_ref().expect("a shadow");
        assert_eq!(sh.delay_prior, (1.0, 0.5));
        assert_eq!(sh.filt.as_ref().map(|f| f.delay_s), Some(1.0));
        assert_eq!(nav.filt.as_ref().map(|f| f.delay_s), Some(0.5));
        let g = earth::normal_gravity(45f64.to_radians(), 300.0);
        for k in 1..=1000 {
            nav.on_imu(
                1_000_000_000 + k * 5_000_000,
                0.005,
                Vector3::zeros(),
                Vector3::new(0.0, 0.0, -g),
            );
        }
        let (main_t, shadow_t) = (
            nav.filt.as_ref().map(|f| f.t_ns),
            nav.shadow.as_ref().and_then(|s| s.filt.as_ref().map(|f| f.t_ns)),
        );
        assert!(main_t.is_some() && main_t == shadow_t, "{main_t:?} {shadow_t:?}");
        // A prior near the horizon: the shadow's goes one σ below.
        nav.reset_delay(1.6, 0.3);
        assert_eq!(nav.shadow.as_ref().map(|s| s.delay_prior), Some((1.3, 0.3)));
        nav.reset_delay(0.0, 0.02);
        assert!(nav.shadow.is_none());
    }

    /// The shadow's estimate |δΔ̂| from the filter's shows P_eff = |δΔ̂|·σ₀ (the linear filter's
    /// ∂Δ̂/∂Δ̂₀ = P_ΔΔ/P₀): a P_ΔΔ below it is published widened to it, and so are the states
    /// through their regression on Δ (the position by −v·δΔ); a P_ΔΔ at or above it unchanged.
    #[test]
    fn the_published_delay_sigma_is_what_the_shadow_shows_the_data_to_hold() {
        let mut nav = aligned();
        nav.reset_delay(0.5, 0.5);
        let v = 2.0;
        {
            let f = nav.filt.as_mut().unwrap();
            f.eskf.p[(DELAY, DELAY)] = 0.01;
            f.eskf.p[(POS, DELAY)] = -v * 0.01;
            f.eskf.p[(DELAY, POS)] = -v * 0.01;
            f.eskf.p[(POS, POS)] = v * v * 0.01 + 1e-4;
            nav.shadow.as_mut().unwrap().filt.as_mut().unwrap().delay_s = 0.9;
        }
        nav.update_delay_doubt();
        let (d, sd) = nav.gnss_delay();
        assert_eq!(d, 0.5);
        // P_eff = 0.4 · 0.5 = 0.2 s².
        assert!((sd - 0.2_f64.sqrt()).abs() < 1e-12, "{sd}");
        let mut s = <NavState as navsync_wire::reflect::Reflect>::zeroed();
        nav.fill(&mut s, 1_000_000_000);
        let expected = (v * v * 0.01 + 1e-4 + v * v * 0.19_f64).sqrt();
        assert!(
            (s.pos_std_ned_m[0] - expected).abs() < 1e-9,
            "{:?} vs {expected}",
            s.pos_std_ned_m
        );
        // A filter that already claims no more than that: nothing added.
        nav.filt.as_mut().unwrap().eskf.p[(DELAY, DELAY)] = 0.25;
        nav.update_delay_doubt();
        assert_eq!(nav.gnss_delay().1, 0.5);
        // A shadow not aligned yet: no more than the prior is claimed.
        nav.filt.as_mut().unwrap().eskf.p[(DELAY, DELAY)] = 0.01;
        nav.shadow.as_mut().unwrap().filt = None;
        nav.update_delay_doubt();
        assert!((nav.gnss_delay().1 - 0.5).abs() < 1e-12);
    }

    /// The fine alignment's re-run over the bank's data makes fused states like any later
    /// step (the last half batch of them): the instants the bank spent deciding get the delayed
    /// filter's state, not only those after the decision (events marked there get a pose).
    #[test]
    fn the_fine_alignment_hands_on_its_states() {
        let mut nav = Navigator::new(NavConfig::default());
        nav.reset_delay(0.0, 0.02);
        nav.keep_fused();
        let (lat0, lon0, h0) = (0.75_f64, 0.2_f64, 100.0);
        let g = earth::normal_gravity(lat0, h0);
        let (rm, rn) = earth::radii(lat0);
        let yaw = 30f64.to_radians();
        // Standing 3 s, then 1 m/s² forward along 30°, level; 200 Hz IMU, exact fixes at 10 Hz.
        let (t0, t_go) = (1_000_000_000_000_i64, 3.0);
        let mut decided_ns = None;
        let mut first_fused_ns = None;
        for k in 1..=5000 {
            let t_s = k as f64 * 0.005;
            let t_ns = t0 + k * 5_000_000;
            let a = if t_s > t_go { 1.0 } else { 0.0 };
            nav.on_imu(t_ns, 0.005, Vector3::zeros(), Vector3::new(a, 0.0, -g));
            if k % 20 == 0 {
                let tm = (t_s - t_go).max(0.0);
                let (d, v) = (0.5 * tm * tm, tm);
                let obs = GnssObservation {
                    stamp_host_ns: t_ns,
                    lat_rad: lat0 + d * yaw.cos() / (rm + h0),
                    lon_rad: lon0 + d * yaw.sin() / ((rn + h0) * lat0.cos()),
                    h_m: h0,
                    vel_ned_mps: Vector3::new(v * yaw.cos(), v * yaw.sin(), 0.0),
                    pos_std_m: Vector3::new(0.05, 0.05, 0.1),
                    vel_std_mps: 0.05,
                    speed_mps: v,
                    track_rad: yaw,
                    pos_floor_std_m: Vector3::zeros(),
                };
                nav.on_gnss(obs, t_ns);
            }
            if nav.is_aligned() && decided_ns.is_none() {
                decided_ns = Some(t_ns);
            }
            nav.drain_fused(&mut |s| {
                first_fused_ns.get_or_insert(s.host_ns);
            });
        }
        let decided_ns = decided_ns.expect("the heading decided");
        let first = first_fused_ns.expect("fused states");
        let horizon_ns = (nav.horizon_s() * 1e9) as i64;
        assert!(
            first < decided_ns - horizon_ns - 1_000_000_000,
            "the first fused state {} s before the decision, the horizon {} s",
            (decided_ns - first) as f64 * 1e-9,
            nav.horizon_s()
        );
        let yaw_est = nav.output().unwrap().q_nb.euler_angles().2;
        assert!(
            (yaw_est - yaw).abs() < 2f64.to_radians(),
            "yaw {}",
            yaw_est.to_degrees()
        );
    }

    /// A car standing with 1 cm fixes at 10 Hz and no velocity (speed and track differenced
    /// from the positions, as an import without velocities has them), software sync (Δ's prior
    /// 0.5 ± 0.5 s): the alignment correlates position with Δ through the standing velocity,
    /// which is the fixes' noise. Δ is held while not observable, so the standing fixes leave
    /// it and its σ alone, and the heading bank, which cannot see a heading in them, decides
    /// none (the sweep's seed 15 run 3: Δ went 0.5 → 1.95 s with σ 1 ms while standing, and a
    /// heading 149° off was decided with σ 1°).
    #[test]
    fn a_standing_start_learns_neither_delay_nor_heading_from_the_noise() {
        let mut nav = Navigator::new(NavConfig {
            gnss_lever_arm_m: [-0.01, 0.774, -0.8],
            ..NavConfig::default()
        });
        nav.reset_delay(0.5, 0.5);
        let (lat0, lon0, h0) = (0.746_f64, 2.162_f64, 300.0);
        let g = earth::normal_gravity(lat0, h0);
        let (rm, rn) = earth::radii(lat0);
        let yaw = 221f64.to_radians();
        let lever_n = nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, yaw) * Vector3::new(-0.01, 0.774, -0.8);
        // Gaussian noise, σ 1 cm (xorshift64 and Box–Muller: deterministic).
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        let mut gauss = move || {
            let mut u = || {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state >> 11) as f64 / (1u64 << 53) as f64
            };
            let (u1, u2) = (u().max(1e-300), u());
            (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
        };
        let fixes: Vec<(f64, f64)> = (0..=301).map(|_| (0.01 * gauss(), 0.01 * gauss())).collect();
        let t0 = 1_000_000_000_000_i64;
        let mut moved = 0.0_f64;
        for k in 1..=6000 {
            let t_ns = t0 + k * 5_000_000;
            nav.on_imu(t_ns, 0.005, Vector3::zeros(), Vector3::new(0.0, 0.0, -g));
            if k % 20 == 0 && k / 20 < 300 {
                let i = (k / 20) as usize;
                let (n, e) = (lever_n.x + fixes[i].0, lever_n.y + fixes[i].1);
                let v = Vector3::new(fixes[i + 1].0 - fixes[i - 1].0, fixes[i + 1].1 - fixes[i - 1].1, 0.0) / 0.2;
                let obs = GnssObservation {
                    stamp_host_ns: t_ns,
                    lat_rad: lat0 + n / (rm + h0),
                    lon_rad: lon0 + e / ((rn + h0) * lat0.cos()),
                    h_m: h0 - lever_n.z,
                    vel_ned_mps: Vector3::new(f64::NAN, f64::NAN, f64::NAN),
                    pos_std_m: Vector3::new(0.011, 0.011, 0.02),
                    vel_std_mps: f64::NAN,
                    speed_mps: v.norm(),
                    track_rad: v.y.atan2(v.x),
                    pos_floor_std_m: Vector3::zeros(),
                };
                nav.on_gnss(obs, t_ns);
            }
            for (d, sd) in nav.bank.iter().flat_map(|b| b.delays()) {
                moved = moved.max((d - 0.5).abs()).max((sd - 0.5).abs());
            }
        }
        assert!(
            !nav.is_aligned(),
            "a heading decided while standing: {:?}",
            nav.output()
        );
        assert!(nav.bank.is_some(), "the heading bank waits");
        assert!(moved < 1e-3, "Δ or its σ moved by {moved} s");
        // The fixes' time base changes (PPS acquired) while it waits: it starts again.
        nav.reset_delay(0.0, 0.02);
        assert!(nav.bank.is_none(), "a bank on the old prior and stamps kept");
        assert_eq!(nav.delay_prior, (0.0, 0.02));
        assert_eq!(
            (nav.prev_fix_ns, nav.recent_len),
            (None, 0),
            "fixes on the old stamps kept"
        );
    }

    /// A receiver's fixes whose error persists (the same 3 m north and 1 m west every second,
    /// hAcc 2.83 m: 2 m per axis) keep the published horizontal σ at the receiver's own,
    /// covering that error however many are fused; the same positions from a file, whose σ is
    /// a measurement noise, let it shrink as the filter averages them.
    #[test]
    fn a_receivers_accuracy_is_a_floor_of_the_published_sigma_and_a_files_noise_is_not() {
        use crate::nav::measurements::gnss::{GnssAccuracy, observation};
        use navsync_wire::samples::{FixMode, GNSS_PROTOCOL_FILE, GNSS_PROTOCOL_UBX, GnssFix, Stamp, StampSource};
        const SIGMA_M: f64 = 2.0;
        let g = earth::normal_gravity(45f64.to_radians(), 300.0);
        let run = |protocol: u8| {
            let mut nav = aligned_with(0.0, SIGMA_M);
            let (lat0, r) = (45f64.to_radians(), 6_378_137.0_f64);
            let mut t_ns = 1_000_000_000;
            // 120 s at 100 Hz, a fix every second.
            for k in 1..=12_000 {
                t_ns = 1_000_000_000 + k * 10_000_000;
                nav.on_imu(t_ns, 0.01, Vector3::zeros(), Vector3::new(0.0, 0.0, -g));
                if k % 100 == 0 {
                    let mut fix = GnssFix::empty(Stamp::host(t_ns, 0, StampSource::Receipt));
                    fix.lat_deg = 45.0 + (3.0 / r).to_degrees();
                    fix.lon_deg = 7.0 - (1.0 / (r * lat0.cos())).to_degrees();
                    (fix.alt_msl_m, fix.geoid_sep_m) = (300.0, 0.0);
                    (fix.vel_n_mps, fix.vel_e_mps, fix.vel_d_mps) = (0.0, 0.0, 0.0);
                    (fix.mode, fix.sats_used, fix.protocol) = (FixMode::Fix3d as u8, 9, protocol);
                    if protocol == GNSS_PROTOCOL_FILE {
                        [fix.std_lat_m, fix.std_lon_m, fix.std_alt_m] = [SIGMA_M, SIGMA_M, 3.0];
                    } else {
                        (fix.h_acc_m, fix.v_acc_m) = (SIGMA_M * std::f64::consts::SQRT_2, 3.0);
                    }
                    fix.s_acc_mps = 0.07;
                    let obs = observation(&fix, t_ns, &GnssAccuracy::default()).expect("usable");
                    nav.on_gnss(obs, t_ns);
                }
            }
            let mut s = <NavState as navsync_wire::reflect::Reflect>::zeroed();
            nav.fill(&mut s, t_ns);
            let north_m = (s.lat_deg.to_radians() - lat0) * r;
            (s.pos_std_ned_m, north_m)
        };
        let (std, north_m) = run(GNSS_PROTOCOL_UBX);
        assert!((north_m - 3.0).abs() < 0.5, "the filter follows the fixes: {north_m} m");
        assert!(
            std[0] >= SIGMA_M - 1e-9 && std[1] >= SIGMA_M - 1e-9 && std[2] >= 3.0 - 1e-9,
            "a receiver's fixes: published σ {std:?} below theirs"
        );
        let (std, north_m) = run(GNSS_PROTOCOL_FILE);
        assert!((north_m - 3.0).abs() < 0.5, "{north_m} m");
        assert!(std[0] < 1.0 && std[1] < 1.0, "a file's fixes: published σ {std:?}");
    }

    /// A speed differenced from positions has the noise of the receiver's interval, not of a
    /// gap between the fixes the navigator got: standing fixes at 10 Hz (σ 0.2 m, a speed noise
    /// of 2.8 m/s) with 2 s missed never show motion.
    #[test]
    fn a_gap_in_the_fixes_does_not_make_speed_noise_motion() {
        let mut nav = Navigator::new(NavConfig::default());
        let fix = |t_ns: i64| GnssObservation {
            stamp_host_ns: t_ns,
            lat_rad: 0.7,
            lon_rad: 0.1,
            h_m: 100.0,
            vel_ned_mps: Vector3::new(f64::NAN, f64::NAN, f64::NAN),
            pos_std_m: Vector3::new(0.2, 0.2, 0.4),
            vel_std_mps: f64::NAN,
            speed_mps: 1.8,
            track_rad: 0.3,
            pos_floor_std_m: Vector3::zeros(),
        };
        for t_ns in [0, 100_000_000, 2_100_000_000] {
            nav.on_gnss(fix(t_ns), t_ns);
        }
        assert!(
            !nav.motion_seen,
            "1.8 m/s of 2.8 m/s noise taken for motion after a gap"
        );
        assert_eq!(nav.fix_interval_ns(), Some(2_000_000_000), "two intervals: the later");
        for t_ns in [2_200_000_000, 2_300_000_000] {
            nav.on_gnss(fix(t_ns), t_ns);
        }
        assert_eq!(
            nav.fix_interval_ns(),
            Some(100_000_000),
            "the median of 0.1, 2, 0.1, 0.1 s"
        );
    }

    /// Under software sync a Δ below what is physical (a fix received before its epoch) is
    /// not an estimate: it starts again from the prior, counted, the states recovering; the
    /// same Δ under hardware sync is left to the filter.
    #[test]
    fn a_delay_beyond_what_is_physical_starts_again_from_its_prior() {
        let mut nav = aligned();
        nav.reset_delay(0.5, 0.5);
        nav.set_delay_floor(-0.1);
        nav.filt.as_mut().unwrap().delay_s = -0.3;
        nav.monitor();
        let (d, sd) = nav.gnss_delay();
        assert_eq!((d, sd), (0.5, 0.5));
        assert_eq!(nav.integrity().delay_resets, 1);
        assert!(nav.recovering_until_ns > 1_000_000_000);
        let mut nav = aligned();
        nav.reset_delay(0.0, 0.02);
        nav.set_delay_floor(f64::NEG_INFINITY);
        nav.filt.as_mut().unwrap().delay_s = -0.3;
        nav.monitor();
        assert_eq!(nav.gnss_delay().0, -0.3);
        assert_eq!(nav.integrity().delay_resets, 0);
        // At the filter's bound, whatever the sync: reset.
        nav.filt.as_mut().unwrap().delay_s = MIN_DELAY_S;
        nav.monitor();
        assert_eq!(nav.integrity().delay_resets, 1);
    }
}
