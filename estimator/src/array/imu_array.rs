//! An inertial sensor array: several IMUs with unknown, nearly constant stamp offsets relative
//! to a reference IMU, aligned onto the reference's time grid and fused into one virtual IMU.
//!
//! Per sample of the reference IMU (instant τ, the centre of its averaging interval):
//! 1. every other IMU in the array is interpolated at τ + T̂d_i by an order-N Lagrange
//!    fractional-delay filter ([`fractional_delay`](super::fractional_delay)) over its own samples (any rate: this is
//!    also the resampling to the reference rate);
//! 2. the aligned rates are compared with the reference's: the residuals drive each IMU's
//!    [`OffsetFilter`] (Td, relative biases), and a persistent disagreement beyond the gate drops
//!    the IMU from the array;
//! 3. the aligned, mounting-rotated, lever-arm- and relative-bias-corrected rates are averaged
//!    with weights 1/σ² (each IMU's white-noise variance per sample): the virtual IMU, which
//!    has the reference IMU's biases, position and time grid and less noise (σ/√n for n equal
//!    IMUs).
//!
//! Acquisition. The offset filter linearises x_0(τ − δ) ≈ x_0(τ) − ẋ_0(τ)·δ, which holds only
//! for δ well inside a quarter period of the fastest motion (6 ms for a 40 Hz vibration), while
//! Td's prior spans ±0.3 s: started outside that range the filter can lock onto a wrong lobe with
//! a tight σ. So Td is frozen until an acquisition, as a GNSS receiver acquires a code phase
//! before it tracks it: over the last [`ACQ_WINDOW`] reference samples, the cost
//! J(L) = Σ_c Σ_n (d_nc − d̄_c)²/σ_c² of the de-meaned differences d = x_i(τ + L·T) − x_0(τ)
//! (gyro and accelerometer, σ_c both IMUs' sample noise) is computed for every lag L within
//! 3σ of the prior; the smallest J gives Td = (L + parabolic refinement)·T. It is taken only
//! when unambiguous: every lag two or more samples away costs at least [`ACQ_MARGIN`] more (a
//! likelihood ratio of e^(margin/2)) and twice as much (the best lag explains most of the
//! difference, whatever the residual model leaves). The filter then tracks from there with
//! 1-sigma max(T/2, √(2/J''))·T. An IMU that comes to disagree is acquired again, and moved
//! when the acquisition disagrees with its filter by more than 3σ.
//!
//! Stamps are smoothed per IMU by an α–β tracker of stamp = t₀ + k·T (sample counter k), which
//! removes the stamp jitter without assuming the nominal rate. An IMU whose samples stop (stale),
//! saturate, are invalid, disagree or whose offset has not converged is out of the array, with
//! its reason in the per-IMU table; it is re-admitted when healthy again.
//!
//! Reference handover. When the reference IMU goes stale (its driver died) while another IMU
//! is live, the live IMU with the best-known offset (in the array first, then the smallest Td
//! 1-sigma) becomes the reference, so the array and the `NavState`s it drives go on. Its own
//! offset filter is frozen at that moment and its samples are put into the terms of the IMU it
//! replaces: stamps moved by −T̂d, and x₀ = (x_i − Δb̂) ⊘ (1 + Δŝ) per sensor triad (the inverse
//! of the residual model of [`OffsetFilter`], r = Δb + diag(x₀)·Δs). So the virtual IMU keeps
//! the time base, biases and scale factors the navigation filter has estimated, and the other
//! IMUs' offset filters stay valid. What changes is its position (the new reference's): the
//! pipeline moves the GNSS lever arm by the difference. The old reference, when it returns,
//! joins as an ordinary member; its offset filter starts where it stands relative to those
//! terms (zero: it defined them) with the frozen filter's covariance added. The reference does
//! not move back.
//! The choice depends only on the samples, so a replay makes the same handover.
//!
//! Fixed memory: every ring buffer is allocated at construction; nothing per sample.

use nalgebra::{Matrix3, SVector, Vector3};
use navsync_wire::reflect::{fixed_str, str_of};
use navsync_wire::samples::{IMU_FLAG_SATURATED, ImuSample, ImuSync, ImuSyncReason, MAX_IMUS};

use super::fractional_delay::{MAX_ORDER, lagrange_coefficients};
use super::imu_offset::{InterpolationError, OffsetConfig, OffsetFilter, OffsetUpdate};

/// Samples kept per IMU (1.28 s at 200 Hz): more than the largest offset plus the filter span.
pub const RING: usize = 256;

/// Reference samples an acquisition compares (0.5 s at 200 Hz).
pub const ACQ_WINDOW: usize = 100;

/// The largest lag an acquisition searches, reference samples (±0.32 s at 200 Hz): with the
/// window and the interpolation span it fits the ring.
pub const ACQ_MAX_LAG: usize = 64;

/// How much more (χ²) every other lag must cost than the acquired one.
pub const ACQ_MARGIN: f64 = 50.0;

/// One IMU of the array as configured.
#[derive(Debug, Clone, PartialEq)]
pub struct UnitConfig {
    /// IMU id (as in `navsync/imu/{id}/sample`).
    pub id: String,
    /// Rotation sensor → body (FRD): x_body = C_b^s · x_sensor.
    pub c_b_s: Matrix3<f64>,
    /// Position of the IMU in the body frame, m.
    pub lever_b_m: Vector3<f64>,
    /// Gyro white-noise density, rad/s/√Hz (= ARW in rad/√s).
    pub gyro_noise_density: f64,
    /// Accelerometer white-noise density, m/s²/√Hz.
    pub accel_noise_density: f64,
}

/// Settings of the array.
#[derive(Debug, Clone, PartialEq)]
pub struct ArrayConfig {
    /// The IMUs; the one at `reference` defines the time grid.
    pub units: Vec<UnitConfig>,
    /// Index of the reference IMU in `units`.
    pub reference: usize,
    /// Lagrange filter order N (default 3).
    pub order: usize,
    /// Offset filter settings (priors, random walks, observability threshold).
    pub offset: OffsetConfig,
    /// An IMU is in the array only once its offset 1-sigma is below this, s.
    pub admit_td_std_s: f64,
    /// No sample for this long (plus its own offset) makes an IMU stale, s.
    pub stale_after_s: f64,
    /// Consecutive gated comparisons that drop an IMU as disagreeing.
    pub disagree_after: u32,
    /// Consecutive accepted comparisons that re-admit a disagreeing IMU.
    pub agree_after: u32,
    /// Half-width K of the Savitzky–Golay differentiator of the reference's rates (samples):
    /// the low-noise one, used unless the fast one is clearly above its noise.
    pub derivative_half_width: usize,
    /// Half-width of the fast (wide-band) differentiator, used per sensor triad while its
    /// output exceeds its own noise by a signal-to-noise power ratio of 25.
    pub derivative_half_width_fast: usize,
}

/// One sample of the fused virtual IMU (body frame FRD, reference IMU's position and biases).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VirtualSample {
    /// Host time of the end of the interval (the reference sample's stamp), ns.
    pub host_ns: i64,
    /// Interval length, s.
    pub dt_s: f64,
    /// Average angular rate, rad/s.
    pub gyro_rps: Vector3<f64>,
    /// Average specific force, m/s².
    pub accel_mps2: Vector3<f64>,
    /// IMUs that contributed.
    pub contributors: u8,
}

#[derive(Debug, Clone, Copy, Default)]
struct Entry {
    seq: u64,
    /// Smoothed centre time of the averaging interval, ns since the array's epoch.
    center: f64,
    end_host_ns: i64,
    dt_s: f64,
    gyro: Vector3<f64>,
    accel: Vector3<f64>,
}

/// The samples of one interpolation (see `Unit::span`).
#[derive(Debug, Clone, Copy)]
struct Span {
    /// Ring index of the first sample.
    i0: usize,
    /// Its sequence number.
    first_seq: u64,
    /// The interpolation instant's position from the first sample, in samples.
    d: f64,
}

/// α–β tracker of stamp = t₀ + k·T.
#[derive(Debug, Clone, Copy, Default)]
struct Grid {
    t: f64,
    period: f64,
    seq: u64,
    init: bool,
}

impl Grid {
    const ALPHA: f64 = 0.02;
    const BETA: f64 = 2e-4;

    /// Smoothed stamp (ns since epoch) of sample `seq` stamped at `stamp`.
    fn update(&mut self, seq: u64, stamp: f64, nominal_period: f64) -> f64 {
        if !self.init || seq <= self.seq || seq - self.seq > 1000 {
            *self = Grid {
                t: stamp,
                period: nominal_period,
                seq,
                init: true,
            };
            return stamp;
        }
        let steps = (seq - self.seq) as f64;
        let predicted = self.t + steps * self.period;
        let e = stamp - predicted;
        // Residuals beyond 1/4 period mean a jump (reset), not jitter.
        if e.abs() > 0.25 * self.period * steps {
            *self = Grid {
                t: stamp,
                period: self.period,
                seq,
                init: true,
            };
            return stamp;
        }
        self.t = predicted + Self::ALPHA * e;
        self.period += Self::BETA * e / steps;
        self.seq = seq;
        self.t
    }
}

#[derive(Debug, Clone)]
struct Unit {
    cfg: UnitConfig,
    ring: Box<[Entry]>,
    head: usize,
    len: usize,
    /// Samples pushed so far: entry `i` of the ring is push number `pushed − len + i`
    /// (contiguous whatever the driver's sequence numbers do, e.g. restart from 0).
    pushed: u64,
    grid: Grid,
    filter: Option<OffsetFilter>,
    last_host_ns: Option<i64>,
    in_array: bool,
    reason: ImuSyncReason,
    disagree_run: u32,
    agree_run: u32,
    sigma_gyro: f64,
    sigma_accel: f64,
    /// Td acquired (see the module docs): the filter tracks it.
    acquired: bool,
    /// Push count at which the next acquisition is tried.
    next_acquisition: u64,
}

impl Unit {
    fn entry(&self, i: usize) -> &Entry {
        &self.ring[(self.head + i) % RING]
    }

    fn entry_mut(&mut self, i: usize) -> &mut Entry {
        &mut self.ring[(self.head + i) % RING]
    }

    /// A promoted reference (one whose offset filter was frozen at the handover; the
    /// configured reference has none) puts `e` into the terms of the reference it replaced.
    fn correct_if_promoted(&self, is_reference: bool, e: &mut Entry) {
        if is_reference && let Some(f) = &self.filter {
            into_reference_terms(f, e);
        }
    }

    fn push(&mut self, e: Entry) {
        if self.len == RING {
            self.head = (self.head + 1) % RING;
            self.len -= 1;
        }
        self.ring[(self.head + self.len) % RING] = e;
        self.len += 1;
        self.pushed += 1;
    }

    /// The samples an order-`order` interpolation at centre time `t` (ns since epoch) uses:
    /// ring index and sequence number of the first, and t's position within them, in samples;
    /// `None` when the span is not available or not contiguous (a gap of dropped or rejected
    /// samples).
    fn span(&self, order: usize, t: f64) -> Option<Span> {
        if self.len < order + 1 || self.grid.period <= 0.0 {
            return None;
        }
        // Position of t in sample counts, from the newest sample (robust to older gaps).
        let newest = self.entry(self.len - 1);
        let x = newest.seq as f64 + (t - newest.center) / self.grid.period;
        let first_seq = (x - (order as f64 - 1.0) / 2.0).floor();
        if first_seq < 0.0 || first_seq as u64 + order as u64 > newest.seq {
            return None;
        }
        let first_seq = first_seq as u64;
        let back = (newest.seq - first_seq) as usize;
        if back >= self.len {
            return None;
        }
        let i0 = self.len - 1 - back;
        let e0 = self.entry(i0);
        if e0.seq != first_seq || self.entry(i0 + order).seq != first_seq + order as u64 {
            return None; // a gap inside the span
        }
        // Delay within the span from the span's own spacing.
        let local = (self.entry(i0 + order).center - e0.center) / order as f64;
        if local <= 0.0 {
            return None;
        }
        Some(Span {
            i0,
            first_seq,
            d: (t - e0.center) / local,
        })
    }

    /// Lagrange interpolation of gyro and accel at centre time `t` (ns since epoch); `None`
    /// when the span is not available or not contiguous (a gap of dropped or rejected samples).
    fn interpolate(&self, order: usize, t: f64) -> Option<(Vector3<f64>, Vector3<f64>)> {
        Some(self.interpolate_span(order, &self.span(order, t)?))
    }

    /// Lagrange interpolation of gyro and accel over `span`.
    fn interpolate_span(&self, order: usize, span: &Span) -> (Vector3<f64>, Vector3<f64>) {
        let mut h = [0.0; MAX_ORDER + 1];
        lagrange_coefficients(order, span.d, &mut h);
        let (mut g, mut a) = (Vector3::zeros(), Vector3::zeros());
        for (n, hn) in h.iter().enumerate().take(order + 1) {
            let e = self.entry(span.i0 + n);
            g += e.gyro * *hn;
            a += e.accel * *hn;
        }
        (g, a)
    }

    /// The error of [`interpolate_span`](Self::interpolate_span) per component (gyro, then
    /// accelerometer): the next term of Newton's series, Δ^(N+1) x / (N+1)! · Π_{i=0..N}(d − i)
    /// (the Lagrange remainder with the (N+1)-th derivative taken from the samples' own
    /// (N+1)-th difference), and its variance without the sample noise's share of that
    /// difference, C(2N+2, N+1)·σ² (what is left is the motion's); zero where no further
    /// contiguous sample is available.
    fn interpolation_error(&self, order: usize, span: &Span) -> InterpolationError {
        let mut err = InterpolationError::default();
        let Span { i0, first_seq, d } = *span;
        // The (N+1)-th difference over N + 2 contiguous samples: the span and the next one,
        // else the one before.
        let m = order + 1;
        let start = if i0 + m < self.len && self.entry(i0 + m).seq == first_seq + m as u64 {
            i0
        } else if i0 >= 1 && self.entry(i0 - 1).seq + 1 == first_seq {
            i0 - 1
        } else {
            return err;
        };
        let (mut binom, mut fact, mut poly) = (1.0, 1.0, 1.0);
        for i in 0..=order {
            fact *= (i + 1) as f64;
            poly *= d - i as f64;
        }
        for k in 0..=m {
            // (−1)^(m−k) C(m, k)
            let c = if (m - k).is_multiple_of(2) { binom } else { -binom };
            let e = self.entry(start + k);
            for c3 in 0..3 {
                err.value[c3] += c * e.gyro[c3];
                err.value[c3 + 3] += c * e.accel[c3];
            }
            binom = binom * (m - k) as f64 / (k + 1) as f64;
        }
        // C(2m, m): the variance of the m-th difference of white noise, in σ².
        let noise: f64 = (1..=m).map(|i| (m + i) as f64 / i as f64).product();
        let scale = poly / fact;
        for c in 0..6 {
            let sigma = if c < 3 { self.sigma_gyro } else { self.sigma_accel };
            err.variance[c] = (err.value[c].powi(2) - noise * sigma * sigma).max(0.0) * scale * scale;
            err.value[c] *= scale;
        }
        err
    }

    /// Newest centre time, ns since epoch.
    fn newest_center(&self) -> Option<f64> {
        (self.len > 0).then(|| self.entry(self.len - 1).center)
    }
}

/// First derivative of the reference's rates at ring index `j` by the least-squares slope over
/// the 2K + 1 samples j−K … j+K (Savitzky & Golay 1964): ẋ_j = Σ m·x_{j+m} / (T·Σ m²),
/// Σ m² = K(K+1)(2K+1)/3.
///
/// Choice of K: a noisy regressor attenuates the offset estimate towards its prior (errors in
/// variables: the update scales by Σẋ²/(Σẋ² + Σσ_ẋ²)), so the differentiator must keep its
/// noise well below the signal's rate changes. A band-limited derivative stays unbiased: it
/// correlates only with the band it passes, and what lies above it merely adds noise to the
/// residual. K = 20 at 200 Hz (a 0.2 s window, response down by half near 3 Hz) keeps a
/// consumer gyro's derivative noise near 2e−3 rad/s² and passes manoeuvres and the body modes
/// of a car; with strong vibration above that band a smaller K extracts more.
fn savitzky_golay_slope(u: &Unit, j: usize, k: usize) -> (Vector3<f64>, Vector3<f64>) {
    let (mut sg, mut sa) = (Vector3::zeros(), Vector3::zeros());
    for m in 1..=k {
        let (a, b) = (u.entry(j + m), u.entry(j - m));
        sg += (a.gyro - b.gyro) * m as f64;
        sa += (a.accel - b.accel) * m as f64;
    }
    let kf = k as f64;
    let t = (u.entry(j + k).center - u.entry(j - k).center) * 1e-9 / (2.0 * kf);
    let denom = t * kf * (kf + 1.0) * (2.0 * kf + 1.0) / 3.0;
    (sg / denom, sa / denom)
}

/// Variance of one component of a Savitzky–Golay slope over 2K + 1 samples of noise `sigma`
/// spaced `t` s: σ² / (t² Σm²).
fn slope_variance(sigma: f64, t: f64, k: usize) -> f64 {
    let sum_m2 = (k * (k + 1) * (2 * k + 1)) as f64 / 3.0;
    sigma * sigma / (t * t * sum_m2)
}

/// The reference's rate derivatives at ring index `j` and their noise variances per component,
/// per sensor triad: from the fast differentiator when its output stands well above its noise
/// (vibration, sharp manoeuvres: more information), else from the low-noise one; and from the
/// central difference (K = 1) when that stands above its own noise and holds more than four
/// times the chosen one's power (the chosen one sees less than half the motion's amplitude:
/// the motion is faster than its band). A narrow
/// differentiator is blind to fast motion: the K = 3 slope of a 37 Hz vibration sampled at
/// 200 Hz is 8.5 % of its derivative (Σ m·sin(mωT) / (ωT·Σ m²)), the central difference's 79 %
/// (sin ωT / ωT), and a regressor that small makes the offset filter's Td wrong by
/// milliseconds, not only less certain.
fn choose_derivative(u: &Unit, j: usize, k: usize, k_fast: usize) -> (Vector3<f64>, Vector3<f64>, f64, f64) {
    const SNR: f64 = 25.0;
    let t = u.entry(j).dt_s;
    let pick = |(narrow, v_narrow): (Vector3<f64>, f64),
                (fast, v_fast): (Vector3<f64>, f64),
                (wide, v_wide): (Vector3<f64>, f64)| {
        let chosen = if fast.norm_squared() >= SNR * 3.0 * v_fast {
            (fast, v_fast)
        } else {
            (narrow, v_narrow)
        };
        if wide.norm_squared() >= SNR * 3.0 * v_wide && wide.norm_squared() > 4.0 * chosen.0.norm_squared() {
            (wide, v_wide)
        } else {
            chosen
        }
    };
    let kf = k_fast.min(k);
    let (wl, fl) = savitzky_golay_slope(u, j, k);
    let (ws, fs) = savitzky_golay_slope(u, j, kf);
    let (w1, f1) = savitzky_golay_slope(u, j, 1);
    let var = |sigma: f64, kk: usize| slope_variance(sigma, t, kk);
    let (w_dot, wd_var) = pick(
        (wl, var(u.sigma_gyro, k)),
        (ws, var(u.sigma_gyro, kf)),
        (w1, var(u.sigma_gyro, 1)),
    );
    let (f_dot, fd_var) = pick(
        (fl, var(u.sigma_accel, k)),
        (fs, var(u.sigma_accel, kf)),
        (f1, var(u.sigma_accel, 1)),
    );
    (w_dot, f_dot, wd_var, fd_var)
}

/// Counters of the array.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ArrayCounters {
    /// Samples accepted.
    pub samples: u64,
    /// Samples with non-finite values or a non-positive interval (rejected).
    pub invalid: u64,
    /// Samples older than the previous one of the same IMU (rejected).
    pub backwards: u64,
    /// Samples flagged saturated ([`IMU_FLAG_SATURATED`]: an axis at the sensor's full-scale
    /// range, so the true value is unknown), rejected: the interval is bridged by the next
    /// sample like a dropped one.
    pub saturated: u64,
    /// Samples from an id not in the configuration (ignored).
    pub unknown_id: u64,
    /// Virtual samples produced.
    pub virtual_samples: u64,
    /// Offset comparisons rejected by the gate.
    pub disagreements: u64,
    /// Times the reference moved to another IMU because it went stale.
    pub handovers: u64,
    /// Offsets acquired (see the module docs).
    pub acquisitions: u64,
    /// Of those, the ones that set an offset filter's Td: the first of each IMU, and any that
    /// disagreed with the filter by more than 3σ.
    pub reacquisitions: u64,
}

/// The IMU array.
#[derive(Debug, Clone)]
pub struct ImuArray {
    cfg: ArrayConfig,
    units: Vec<Unit>,
    epoch_ns: Option<i64>,
    /// Push number (see `Unit::pushed`) of the reference's next instant to fuse.
    next_ref_index: Option<u64>,
    latest_host_ns: i64,
    /// End time of the last virtual sample (handover: the new reference continues after it).
    last_virtual_ns: i64,
    counters: ArrayCounters,
}

/// Puts a sample of a promoted reference IMU (one whose offset filter was frozen at the
/// handover) into the terms of the reference it replaced: stamp − T̂d and
/// x₀ = (x_i − Δb̂) ⊘ (1 + Δŝ) per triad (see the module docs).
fn into_reference_terms(f: &OffsetFilter, e: &mut Entry) {
    let td_ns = f.td_s() * 1e9;
    e.center -= td_ns;
    e.end_host_ns -= td_ns.round() as i64;
    e.gyro = (e.gyro - f.gyro_bias()).component_div(&(Vector3::repeat(1.0) + f.gyro_scale()));
    e.accel = (e.accel - f.accel_bias()).component_div(&(Vector3::repeat(1.0) + f.accel_scale()));
}

impl ImuArray {
    /// An array with nothing received yet.
    pub fn new(cfg: ArrayConfig) -> Self {
        let units = cfg
            .units
            .iter()
            .enumerate()
            .map(|(i, u)| Unit {
                cfg: u.clone(),
                ring: vec![Entry::default(); RING].into_boxed_slice(),
                head: 0,
                len: 0,
                pushed: 0,
                grid: Grid::default(),
                filter: (i != cfg.reference).then(|| OffsetFilter::new(cfg.offset)),
                last_host_ns: None,
                in_array: i == cfg.reference,
                reason: if i == cfg.reference {
                    ImuSyncReason::InArray
                } else {
                    ImuSyncReason::Absent
                },
                disagree_run: 0,
                agree_run: 0,
                sigma_gyro: 0.0,
                sigma_accel: 0.0,
                acquired: false,
                next_acquisition: 0,
            })
            .collect();
        Self {
            cfg,
            units,
            epoch_ns: None,
            next_ref_index: None,
            latest_host_ns: 0,
            last_virtual_ns: i64::MIN,
            counters: ArrayCounters::default(),
        }
    }

    /// Index of the IMU with this id.
    pub fn index_of(&self, id: &str) -> Option<usize> {
        self.units.iter().position(|u| u.cfg.id == id)
    }

    /// Index of the reference IMU.
    pub fn reference(&self) -> usize {
        self.cfg.reference
    }

    /// Counters so far.
    pub fn counters(&self) -> &ArrayCounters {
        &self.counters
    }

    /// Id of the reference IMU as stored in samples.
    pub fn reference_id(&self) -> [u8; 8] {
        fixed_str(&self.units[self.cfg.reference].cfg.id)
    }

    /// Position of IMU `index` in the body frame (FRD), m.
    pub fn lever_b_m(&self, index: usize) -> Vector3<f64> {
        self.units[index].cfg.lever_b_m
    }

    /// Sample `s` of IMU `index` in the body frame (FRD) for the present-time output: host time
    /// (ns), angular rate (rad/s) and specific force (m/s²), mounting-rotated and, for a
    /// promoted reference, in the terms of the reference it replaced.
    pub fn output_sample(&self, index: usize, s: &ImuSample) -> (i64, Vector3<f64>, Vector3<f64>) {
        let u = &self.units[index];
        let mut e = Entry {
            end_host_ns: s.stamp.host_ns,
            gyro: u.cfg.c_b_s * Vector3::from(s.gyro_rps),
            accel: u.cfg.c_b_s * Vector3::from(s.accel_mps2),
            ..Entry::default()
        };
        u.correct_if_promoted(index == self.cfg.reference, &mut e);
        (e.end_host_ns, e.gyro, e.accel)
    }

    /// Estimated offset and its 1-sigma of IMU `index`, s (the configured reference: 0 ± 0; a
    /// promoted one: its offset frozen at the handover).
    pub fn offset(&self, index: usize) -> (f64, f64) {
        self.units[index]
            .filter
            .as_ref()
            .map_or((0.0, 0.0), |f| (f.td_s(), f.td_std_s()))
    }

    /// The per-IMU table for `NavState`/`TimeState`.
    pub fn table(&self) -> ([ImuSync; MAX_IMUS], u8) {
        let mut t = [<ImuSync as navsync_wire::reflect::Reflect>::zeroed(); MAX_IMUS];
        for (slot, u) in t.iter_mut().zip(&self.units) {
            slot.imu_id = fixed_str(&u.cfg.id);
            let (td, sd) = u.filter.as_ref().map_or((0.0, 0.0), |f| (f.td_s(), f.td_std_s()));
            slot.offset_s = td;
            slot.offset_std_s = sd;
            slot.in_array = u8::from(u.in_array);
            slot.reason = u.reason as u8;
            slot.observable = u.filter.as_ref().map_or(1, |f| u8::from(f.observable()));
        }
        (t, self.units.len().min(MAX_IMUS) as u8)
    }

    /// Feeds one sample (sensor frame) of the IMU with index `index`; calls `out` for every
    /// virtual sample that becomes complete. Returns false when the sample was rejected.
    pub fn push(&mut self, index: usize, s: &ImuSample, out: &mut impl FnMut(&VirtualSample)) -> bool {
        let accepted = self.accept(index, s);
        if accepted {
            self.emit(out);
        }
        accepted
    }

    /// Takes one sample (sensor frame) of the IMU with index `index` into its ring and updates
    /// the membership (stale IMUs, reference handover), without fusing: [`emit`](Self::emit)
    /// does that. Returns false when the sample was rejected.
    pub fn accept(&mut self, index: usize, s: &ImuSample) -> bool {
        let Some(unit) = self.units.get_mut(index) else {
            self.counters.unknown_id += 1;
            return false;
        };
        let g = Vector3::from(s.gyro_rps);
        let a = Vector3::from(s.accel_mps2);
        if !(g.iter().chain(a.iter()).all(|v| v.is_finite()) && s.dt_s > 0.0 && s.dt_s < 1.0) {
            self.counters.invalid += 1;
            return false;
        }
        if unit.last_host_ns.is_some_and(|t| s.stamp.host_ns <= t) {
            self.counters.backwards += 1;
            return false;
        }
        if s.flags & IMU_FLAG_SATURATED != 0 {
            self.counters.saturated += 1;
            return false;
        }
        let epoch = *self.epoch_ns.get_or_insert(s.stamp.host_ns);
        let period_ns = s.dt_s * 1e9;
        let end = unit
            .grid
            .update(s.stamp.seq, (s.stamp.host_ns - epoch) as f64, period_ns);
        unit.sigma_gyro = unit.cfg.gyro_noise_density / s.dt_s.sqrt();
        unit.sigma_accel = unit.cfg.accel_noise_density / s.dt_s.sqrt();
        let mut e = Entry {
            seq: s.stamp.seq,
            center: end - period_ns / 2.0,
            end_host_ns: s.stamp.host_ns,
            dt_s: s.dt_s,
            gyro: unit.cfg.c_b_s * g,
            accel: unit.cfg.c_b_s * a,
        };
        unit.correct_if_promoted(index == self.cfg.reference, &mut e);
        unit.push(e);
        unit.last_host_ns = Some(s.stamp.host_ns);
        if unit.reason == ImuSyncReason::Absent || unit.reason == ImuSyncReason::Stale {
            unit.reason = if index == self.cfg.reference {
                ImuSyncReason::InArray
            } else {
                ImuSyncReason::Converging
            };
            unit.in_array = index == self.cfg.reference;
        }
        self.latest_host_ns = self.latest_host_ns.max(s.stamp.host_ns);
        self.counters.samples += 1;
        self.mark_stale();
        true
    }

    fn mark_stale(&mut self) {
        let stale_ns = (self.cfg.stale_after_s * 1e9) as i64;
        for u in &mut self.units {
            let td_ns = u.filter.as_ref().map_or(0.0, |f| f.td_s().max(0.0) * 1e9) as i64;
            if u.last_host_ns
                .is_some_and(|t| self.latest_host_ns - t > stale_ns + td_ns)
            {
                u.in_array = false;
                u.reason = ImuSyncReason::Stale;
            }
        }
        if self.units[self.cfg.reference].reason == ImuSyncReason::Stale {
            self.hand_over();
        }
    }

    /// Makes the best live IMU the reference (see the module docs): in the array before
    /// converging, then the smallest offset 1-sigma; none live: nothing changes.
    fn hand_over(&mut self) {
        let r = self.cfg.reference;
        let td_std = |u: &Unit| u.filter.as_ref().map_or(f64::INFINITY, OffsetFilter::td_std_s);
        let Some(n) = self
            .units
            .iter()
            .enumerate()
            .filter(|(i, u)| {
                *i != r && u.len > 0 && matches!(u.reason, ImuSyncReason::InArray | ImuSyncReason::Converging)
            })
            .min_by(|(_, a), (_, b)| (!a.in_array).cmp(&!b.in_array).then(td_std(a).total_cmp(&td_std(b))))
            .map(|(i, _)| i)
        else {
            return;
        };
        let new = &mut self.units[n];
        let frozen = new.filter.clone().unwrap_or_else(|| OffsetFilter::new(self.cfg.offset));
        for i in 0..new.len {
            into_reference_terms(&frozen, new.entry_mut(i));
        }
        new.reason = ImuSyncReason::InArray;
        new.in_array = true;
        (new.disagree_run, new.agree_run) = (0, 0);
        // The replaced reference's offset is known as well as the promoted one's was.
        let acquired = new.acquired;
        let old = &mut self.units[r];
        old.filter = Some(frozen.for_replaced_reference(old.filter.as_ref()));
        old.acquired = acquired;
        (old.disagree_run, old.agree_run) = (0, 0);
        self.cfg.reference = n;
        self.next_ref_index = None;
        self.counters.handovers += 1;
    }

    /// Fuses every reference instant whose samples are complete, in time order, and calls
    /// `out` with each virtual sample (single IMU: its newest sample, once).
    pub fn emit(&mut self, out: &mut impl FnMut(&VirtualSample)) {
        let r = self.cfg.reference;
        for i in 0..self.units.len() {
            let u = &self.units[i];
            if i == r
                || u.filter.is_none()
                || (u.acquired && u.reason != ImuSyncReason::Disagrees)
                || u.pushed < u.next_acquisition
            {
                continue;
            }
            let found = self.acquire(i);
            let u = &mut self.units[i];
            u.next_acquisition = u.pushed + (ACQ_WINDOW / 2) as u64;
            let (Some((td, sd)), Some(f)) = (found, u.filter.as_mut()) else {
                continue;
            };
            self.counters.acquisitions += 1;
            // The first acquisition starts the tracking; a later one moves it only when the two
            // disagree.
            let first = !u.acquired;
            u.acquired = true;
            if first || (td - f.td_s()).abs() > 3.0 * (sd.powi(2) + f.td_std_s().powi(2)).sqrt() {
                f.reacquire(td, sd);
                u.disagree_run = 0;
                self.counters.reacquisitions += 1;
            }
        }
        if self.units.len() == 1 {
            let u = &self.units[r];
            if u.len == 0 || u.entry(u.len - 1).end_host_ns <= self.last_virtual_ns {
                return;
            }
            let e = *u.entry(u.len - 1);
            self.last_virtual_ns = e.end_host_ns;
            self.counters.virtual_samples += 1;
            out(&VirtualSample {
                host_ns: e.end_host_ns,
                dt_s: e.dt_s,
                gyro_rps: e.gyro,
                accel_mps2: e.accel,
                contributors: 1,
            });
            return;
        }
        loop {
            let reference = &self.units[r];
            if reference.len < 3 {
                return;
            }
            let k = self.cfg.derivative_half_width;
            let first = reference.pushed - reference.len as u64;
            let next = *self.next_ref_index.get_or_insert(first + k as u64);
            // Position of instant j in the reference ring; the derivative needs j−K … j+K.
            if next < first + k as u64 {
                self.next_ref_index = Some(first + k as u64);
                continue;
            }
            let j = (next - first) as usize;
            if j + k >= reference.len {
                return;
            }
            let cur = *reference.entry(j);
            if cur.end_host_ns <= self.last_virtual_ns {
                // After a handover: the new reference continues where the old one ended.
                self.next_ref_index = Some(next + 1);
                continue;
            }
            if reference.entry(j - k).seq + k as u64 != cur.seq || cur.seq + k as u64 != reference.entry(j + k).seq {
                self.next_ref_index = Some(next + 1);
                continue;
            }
            let (w_dot, f_dot, wd_var, fd_var) =
                choose_derivative(reference, j, k, self.cfg.derivative_half_width_fast);
            // Wait until every live IMU has the samples its interpolation at τ + T̂d needs.
            let half_span = (self.cfg.order as f64 / 2.0 + 1.0) * cur.dt_s * 1e9;
            let waiting = self.units.iter().enumerate().any(|(i, u)| {
                i != r
                    && u.reason != ImuSyncReason::Stale
                    && u.reason != ImuSyncReason::Absent
                    && u.filter.as_ref().is_some_and(|f| {
                        u.newest_center()
                            .is_some_and(|c| c < cur.center + f.td_s() * 1e9 + half_span)
                    })
            });
            if waiting {
                return;
            }
            self.fuse_instant(&cur, &w_dot, &f_dot, (wd_var, fd_var), out);
            self.next_ref_index = Some(next + 1);
        }
    }

    /// Acquisition of IMU `i`'s offset (see the module docs): Td and its 1-sigma, s, or `None`
    /// when the rings do not yet hold the span or the best lag is not unambiguous.
    fn acquire(&self, i: usize) -> Option<(f64, f64)> {
        let (rf, u) = (&self.units[self.cfg.reference], &self.units[i]);
        let period = rf.grid.period;
        if period <= 0.0 || u.grid.period <= 0.0 || rf.len < ACQ_WINDOW || u.len < RING / 2 {
            return None;
        }
        let max_lag = ((3.0 * self.cfg.offset.td_prior_std_s * 1e9 / period).ceil() as usize).clamp(2, ACQ_MAX_LAG);
        let span = (max_lag as f64 + self.cfg.order as f64 + 2.0) * u.grid.period.max(period);
        let (u_first, u_last) = (u.entry(0).center, u.entry(u.len - 1).center);
        // The newest ACQ_WINDOW reference samples whose every lag lies inside IMU i's ring.
        let end = (0..rf.len).rev().find(|&j| rf.entry(j).center + span <= u_last)?;
        let start = (end + 1).checked_sub(ACQ_WINDOW)?;
        if rf.entry(start).center - span < u_first {
            return None;
        }
        let var = [
            u.sigma_gyro.powi(2) + rf.sigma_gyro.powi(2),
            u.sigma_accel.powi(2) + rf.sigma_accel.powi(2),
        ];
        if !(var[0] > 0.0 && var[1] > 0.0) {
            return None;
        }
        let mut cost = [0.0; 2 * ACQ_MAX_LAG + 1];
        let lags = 2 * max_lag + 1;
        for (l, c) in cost.iter_mut().enumerate().take(lags) {
            let lag_ns = (l as f64 - max_lag as f64) * period;
            let (mut sum, mut sum2) = ([0.0; 6], [0.0; 6]);
            for j in start..=end {
                let e = rf.entry(j);
                let (g, a) = u.interpolate(self.cfg.order, e.center + lag_ns)?;
                for k in 0..3 {
                    for (m, d) in [(k, g[k] - e.gyro[k]), (k + 3, a[k] - e.accel[k])] {
                        sum[m] += d;
                        sum2[m] += d * d;
                    }
                }
            }
            let n = ACQ_WINDOW as f64;
            *c = (0..6).map(|m| (sum2[m] - sum[m] * sum[m] / n) / var[m / 3]).sum();
        }
        let cost = &cost[..lags];
        let best = (0..lags).min_by(|&a, &b| cost[a].total_cmp(&cost[b]))?;
        if best == 0 || best + 1 == lags {
            return None; // at the edge of the search: the minimum may lie beyond it
        }
        let second = (0..lags)
            .filter(|&l| l.abs_diff(best) >= 2)
            .map(|l| cost[l])
            .fold(f64::INFINITY, f64::min);
        let jb = cost[best];
        if !(second - jb >= ACQ_MARGIN && second >= 2.0 * jb) {
            return None;
        }
        let (jm, jp) = (cost[best - 1], cost[best + 1]);
        let curvature = jm - 2.0 * jb + jp;
        if curvature.is_nan() || curvature <= 0.0 {
            return None;
        }
        let frac = (0.5 * (jm - jp) / curvature).clamp(-0.5, 0.5);
        let td = (best as f64 - max_lag as f64 + frac) * period * 1e-9;
        let sd = (2.0 / curvature).sqrt().max(0.5) * period * 1e-9;
        Some((td, sd))
    }

    fn fuse_instant(
        &mut self,
        cur: &Entry,
        w_dot: &Vector3<f64>,
        f_dot: &Vector3<f64>,
        (wd_var, fd_var): (f64, f64),
        out: &mut impl FnMut(&VirtualSample),
    ) {
        let r = self.cfg.reference;
        let (w_dot, f_dot) = (*w_dot, *f_dot);
        let w = cur.gyro;
        let ref_lever = self.units[r].cfg.lever_b_m;
        let ref_sigma = (self.units[r].sigma_gyro, self.units[r].sigma_accel);
        // Minimum-variance combination per axis: the reference with its sample variance, every
        // other IMU converted into the reference's terms by subtracting the predicted residual
        // (relative bias and scale, alignment error), with its sample variance plus the
        // variance of that prediction. An IMU whose offset, bias or scale is still uncertain for
        // the current motion weighs little, so membership changes do not step the output.
        let inv = |v: f64| 1.0 / v.max(1e-30);
        let mut wsum = SVector::<f64, 6>::from_fn(|k, _| inv(if k < 3 { ref_sigma.0 } else { ref_sigma.1 }.powi(2)));
        let mut acc = SVector::<f64, 6>::new(
            cur.gyro.x,
            cur.gyro.y,
            cur.gyro.z,
            cur.accel.x,
            cur.accel.y,
            cur.accel.z,
        )
        .component_mul(&wsum);
        let w_ref = wsum;
        let mut contributors = 1u8;
        let order = self.cfg.order;
        let (admit_std, disagree_after, agree_after) =
            (self.cfg.admit_td_std_s, self.cfg.disagree_after, self.cfg.agree_after);
        for (i, u) in self.units.iter_mut().enumerate() {
            if i == r || matches!(u.reason, ImuSyncReason::Stale | ImuSyncReason::Absent) {
                continue;
            }
            let Some(td) = u.filter.as_ref().map(OffsetFilter::td_s) else {
                continue;
            };
            let Some(span) = u.span(order, cur.center + td * 1e9) else {
                u.in_array = false;
                continue;
            };
            let (g_u, a_u) = u.interpolate_span(order, &span);
            let interp_err = u.interpolation_error(order, &span);
            let Some(f) = u.filter.as_mut() else { continue };
            // Rigid body: remove the lever-arm specific force, ω̇ × ρ + ω × (ω × ρ), ρ = r_i − r_0.
            let rho = u.cfg.lever_b_m - ref_lever;
            let a_u = a_u - (w_dot.cross(&rho) + w.cross(&w.cross(&rho)));
            f.predict(cur.dt_s);
            let sg = (u.sigma_gyro.powi(2) + ref_sigma.0.powi(2)).sqrt();
            let sa = (u.sigma_accel.powi(2) + ref_sigma.1.powi(2)).sqrt();
            match f.update(
                &(g_u - cur.gyro),
                &w,
                &w_dot,
                sg,
                &(a_u - cur.accel),
                &cur.accel,
                &f_dot,
                sa,
                wd_var,
                fd_var,
                &interp_err,
                u.acquired,
            ) {
                OffsetUpdate::Accepted(_) => {
                    u.disagree_run = 0;
                    u.agree_run += 1;
                }
                OffsetUpdate::Rejected(_) => {
                    u.agree_run = 0;
                    u.disagree_run += 1;
                    self.counters.disagreements += 1;
                }
            }
            // Membership: a disagreeing IMU stays out until it agrees again for a while.
            if u.disagree_run >= disagree_after {
                u.reason = ImuSyncReason::Disagrees;
            } else if u.reason != ImuSyncReason::Disagrees || u.agree_run >= agree_after {
                u.reason = if f.td_std_s() < admit_std {
                    ImuSyncReason::InArray
                } else {
                    ImuSyncReason::Converging
                };
            }
            if u.reason == ImuSyncReason::Disagrees || u.disagree_run > 0 {
                u.in_array = false;
                continue;
            }
            let (r_hat, var) = f.predicted_residual(&w, &cur.accel, &w_dot, &f_dot);
            let x_u = SVector::<f64, 6>::new(g_u.x, g_u.y, g_u.z, a_u.x, a_u.y, a_u.z) - r_hat;
            let wt = SVector::<f64, 6>::from_fn(|c, _| {
                inv(if c < 3 { u.sigma_gyro } else { u.sigma_accel }.powi(2) + var[c])
            });
            acc += x_u.component_mul(&wt);
            wsum += wt;
            // In the array when it carries at least a tenth of the reference's weight.
            u.in_array = (0..6).all(|c| wt[c] >= 0.1 * w_ref[c]);
            contributors += u8::from(u.in_array);
        }
        let fused = acc.component_div(&wsum);
        self.last_virtual_ns = cur.end_host_ns;
        self.counters.virtual_samples += 1;
        out(&VirtualSample {
            host_ns: cur.end_host_ns,
            dt_s: cur.dt_s,
            gyro_rps: Vector3::new(fused[0], fused[1], fused[2]),
            accel_mps2: Vector3::new(fused[3], fused[4], fused[5]),
            contributors,
        });
    }

    /// Ids of the configured IMUs.
    pub fn ids(&self) -> impl Iterator<Item = &str> {
        self.units.iter().map(|u| u.cfg.id.as_str())
    }

    /// Id of IMU `index` as stored in samples.
    pub fn id_matches(&self, index: usize, raw: &[u8]) -> bool {
        self.units.get(index).is_some_and(|u| u.cfg.id == str_of(raw))
    }
}
