//! Tightly coupled GNSS aiding: every satellite's pseudorange and Doppler fused one by one
//! (scalar updates, each gated on its own), with the receiver clock bias and drift as filter
//! states ([`crate::nav::error_state::CLK_BIAS`], `CLK_DRIFT`) and, for Galileo, BeiDou and
//! GLONASS, the inter-system bias of their clock ([`crate::nav::error_state::ISB`]); one
//! [`Measurement`] kind of
//! the navigator's queue, active when the filter estimates the clock
//! ([`crate::nav::error_state::ProcessNoise::clock`]). One satellite helps: with 1–3 in view
//! the filter still bounds the inertial drift along their lines of sight, where a loosely
//! coupled filter has no fix.
//!
//! Measurement model (Groves 2013, §14.3.3, eq. 14.127 and 14.128, in this filter's NED error
//! state). With u the unit line of sight from the antenna to the satellite (the satellite at
//! transmission rotated into the reception's ECEF frame, IS-GPS-200 §20.3.3.4.3.3.2) and the
//! antenna at the epoch t_f = t_stamp − Δ̂:
//!   ρ̂ = |r_sat − r_ant| + c·δt̂_r + b̂_sys + k·I + T   (Klobuchar I at L1 scaled by
//!        k = (f_L1/f)² of the signal's carrier, Saastamoinen T, from `gnss::spp`; b_sys the
//!        inter-system bias, 0 for GPS)
//!   ρ̇̂ = (v_sat − v_ant)·u + c·δṫ̂_r                 (one oscillator: one drift)
//! measured against the receiver's ρ + c·δt_sv and −λ·D + c·δṫ_sv ([`SatRange`]). Since
//! ∂ρ/∂r_ant = −uᵀ, the Jacobians are −u_nᵀ times the loosely coupled ones of
//! [`super::gnss`] (lever arm, attitude, gyro bias and Δ columns included) and −1 on the clock
//! state and the system's inter-system bias; innovation dz = computed − measured (KF-GINS sign).
//!
//! Time-differenced carrier phase (TDCP; Wendel, Meister, Schlaile & Trommer 2006; Groves
//! 2013, §9.2.7): of a satellite whose carrier the receiver kept locked since the previous
//! epoch, λ·(φ_k − φ_{k−1}) = r_k − r_{k−1} + c·(δt_r,k − δt_r,k−1) + mm-level noise, the
//! ambiguity gone. It is predicted from the previous epoch's corrected antenna and clock and
//! the present ones, so the strapdown's integrated motion over the interval is what is
//! measured; its error is, to first order, the velocity error times the interval:
//! H = Δt × the range rate's rows (the position errors common to both epochs cancel, as do the
//! corrections other measurements made in between, which are taken out of the prediction).
//! The epoch's differences are fused before its code and Doppler, sequentially with the
//! residuals kept linear (dz_j − H_j·Σdx), so that each is relative to the same prior.

use nalgebra::{Matrix1, Matrix3, SMatrix, Vector1, Vector3};
use navsync_wire::earth;
use navsync_wire::samples::RawMeasurement;

use super::Measurement;
use crate::gnss::broadcast::{GNSS_ID_BEIDOU, GNSS_ID_GALILEO, GNSS_ID_GLONASS};
use crate::gnss::ranges::{GNSS_ID_GPS, MAX_RANGE_SATS, RangeEpoch, SatRange};
use crate::gnss::spp::{C_M_S, atmosphere_var_m2, ned_from_ecef, rotate_for_flight, troposphere_delay_m};
use crate::nav::config::NavConfig;
use crate::nav::error_state::{ATT, BG, CLK_BIAS, CLK_DRIFT, DELAY, ISB, ISB_SYSTEMS, N, POS, StateVec, VEL};
use crate::nav::eskf::Update;
use crate::nav::filter::DelayedFilter;
use crate::nav::mechanization::skew;
use crate::time::clock_model::OscillatorNoise;

/// 1σ at zenith of a time-differenced carrier phase, m: the phase noise of both epochs
/// (u-blox reports 0.004–0.06 cycles, ≤ 1 cm at L1; the receiver's own σ·√2 when larger),
/// the change of multipath, and what the first-order model leaves over the interval (half the
/// acceleration error times Δt², a few mm for Δt = 0.25 s and 0.1 m/s²). Scaled with elevation
/// and C/N0 as the code.
const CARRIER_DELTA_STD_M: f64 = 0.01;
/// Carrier phases further apart than this are not differenced, s: the first-order model
/// (velocity error × Δt) holds over a receiver's measurement interval, not over gaps.
const CARRIER_DELTA_MAX_S: f64 = 1.5;

/// Settings of the pseudorange and Doppler updates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangingConfig {
    /// Satellites below this elevation are not used, rad (default 5°, a receiver's usual
    /// tracking mask; the σ grows towards the horizon, see [`Self::pseudorange_std_m`]).
    pub elevation_mask_rad: f64,
    /// Signals weaker than this are not used, dB-Hz (default 25).
    pub cno_mask_dbhz: f64,
    /// Pseudorange 1σ at zenith, m (default 3): code noise, multipath, the broadcast orbit
    /// and clock errors and what the atmosphere models leave; at elevation el it is
    /// σ·√((1 + 1/sin²el)/2) (RTKLIB's a² + b²/sin²el with a = b: 2.3 × at 20°, 8.1 × at
    /// 5°); the receiver's own σ when larger. Weak signals are weighted down further (see
    /// [`Self::reference_cno_dbhz`]).
    pub pseudorange_std_m: f64,
    /// Range-rate 1σ at zenith and at the reference C/N0, m/s (default 0.1), scaled likewise.
    pub range_rate_std_mps: f64,
    /// Below this C/N0 the σ above grow by √(10^((C/N0_ref − C/N0)/10)) (the code-tracking
    /// noise variance goes with 1/(C/N0)), dB-Hz (default 30: open sky gives a patch antenna
    /// 30–35 dB-Hz at 5–15° elevation, which the elevation model already carries; a signal
    /// weaker than that, under foliage or diffracted in a canyon, is weighted down more).
    pub reference_cno_dbhz: f64,
    /// Correlation time of the pseudorange errors that time averaging reduces, s (default 5):
    /// a moving antenna's code multipath and the code tracking error decorrelate over seconds
    /// (the broadcast orbit and clock errors and what the atmosphere models leave persist for
    /// hours and are not reduced by time at all: the published σ's floor carries them,
    /// [`crate::nav::filter::DelayedFilter::pos_floor_std_ned_m`]). As a first-order
    /// Gauss–Markov process of correlation time τ, samples Δt apart carry the information of
    /// independent ones 2τ apart (the variance of a mean over T ≫ τ is 2τσ²/T), so each
    /// pseudorange is fused with its variance × max(1, 2τ/Δt), Δt since the satellite's previous
    /// one (its first, or one after a gap of 2τ, at full weight; the gate keeps one sample's
    /// variance). Fused as if white, 4 Hz code pulled the walk0827 solution along the
    /// satellites' slowly varying errors.
    pub code_correlation_s: f64,
    /// 1σ given to the clock bias when it is (re)initialised from the residuals, m (default 30).
    pub clock_init_std_m: f64,
    /// 1σ given to the clock drift when it is initialised, m/s (default 2).
    pub drift_init_std_mps: f64,
    /// A median pseudorange residual beyond this re-initialises the clock bias, m (default
    /// 1000: a receiver's millisecond clock jump is 299.8 km, a drift model's error after a
    /// minute of holdover a few hundred metres at most).
    pub clock_reset_m: f64,
}

impl Default for RangingConfig {
    fn default() -> Self {
        Self {
            elevation_mask_rad: 5f64.to_radians(),
            cno_mask_dbhz: 25.0,
            pseudorange_std_m: 3.0,
            range_rate_std_mps: 0.1,
            reference_cno_dbhz: 30.0,
            code_correlation_s: 5.0,
            clock_init_std_m: 30.0,
            drift_init_std_mps: 2.0,
            clock_reset_m: 1000.0,
        }
    }
}

/// One satellite's carrier phase at the previous epoch, with what the filter then predicted
/// of it.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct CarrierTrack {
    gnss_id: u8,
    sv: u8,
    sig_id: u8,
    trk_stat: u8,
    lock_time_ms: u16,
    /// [`SatRange::carrier_m`], m.
    carrier_m: f64,
    /// Geometric range from the corrected antenna, m.
    range_m: f64,
    /// The receiver clock bias of the satellite's system, corrected, m.
    clock_m: f64,
}

/// The previous epoch's carrier phases ([`CarrierTrack`]), for the time differences.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CarrierMemory {
    /// GPS time of the epoch, s of week.
    tow_s: f64,
    /// The position corrections fed back up to then ([`DelayedFilter::pos_corrections_ned_m`]).
    corrections_ned_m: Vector3<f64>,
    count: usize,
    sats: [CarrierTrack; MAX_RANGE_SATS],
}

/// When each satellite's pseudorange was last fused, for [`RangingConfig::code_correlation_s`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CodeMemory {
    /// GPS time of week, s, by system slot ([`system_slot`]) and satellite number; NaN: never.
    last_tow_s: [[f64; 64]; SLOTS],
}

impl Default for CodeMemory {
    fn default() -> Self {
        Self {
            last_tow_s: [[f64::NAN; 64]; SLOTS],
        }
    }
}

impl CodeMemory {
    /// The variance factor of satellite `s`'s pseudorange at `tow_s`: max(1, 2τ/Δt) with Δt
    /// since its previous one (1 for its first); remembers `tow_s`.
    fn inflation(&mut self, s: &SatRange, tow_s: f64, tau_s: f64) -> f64 {
        let Some(last) = system_slot(s.gnss_id).and_then(|k| self.last_tow_s[k].get_mut(usize::from(s.sv))) else {
            return 1.0;
        };
        let mut dt = tow_s - *last;
        dt -= (dt / 604_800.0).round() * 604_800.0;
        *last = tow_s;
        if dt.is_finite() && dt > 0.0 {
            (2.0 * tau_s / dt).max(1.0)
        } else {
            1.0
        }
    }
}

/// Satellites fused in an epoch for [`ClockWatch`] to use its clock drift (one more than the
/// velocity and the drift need: the drift is then set by the carrier phases, not the model).
pub const CLOCK_WATCH_MIN_SATS: u64 = 5;
/// Horizons over which [`ClockWatch`] compares the drift's change with the oscillator model,
/// s: octaves, as an Allan plot (a warming crystal's frequency ramp shows at the long ones).
const CLOCK_WATCH_HORIZONS_S: [f64; 4] = [1.0, 4.0, 16.0, 64.0];
/// [`ClockWatch`] averages the last this many ratios per horizon.
const CLOCK_WATCH_MEMORY: u32 = 8;

/// Checks the receiver oscillator's model against the clock itself (covariance matching,
/// Mehra 1972; Mohamed & Schwarz 1999): while the sky is redundant the carrier phases fix the
/// clock drift to mm/s, so the drift's change over a horizon τ, Δd, can be compared with what
/// the model's random-walk FM allows, q_d(τ) = q_f·c²·τ (Brown & Hwang eq. 9.3.11): the ratio
/// r = Δd² / (q_d(τ) + the two drifts' posterior variances) has mean 1 for a clock as stable as
/// its model. The random-walk FM is scaled by the largest mean ratio over the horizons (never
/// below 1), so that a clock whose frequency wanders or ramps more than the data sheet says
/// (the rtklibexplorer walk's u-blox X20: −63 → −81 m/s in 2 min after power-on, 20 m RMS of
/// bias prediction error over 15 s where the TCXO model allows 6.3 m) is not trusted to tell
/// a move along the one direction 3 satellites leave to the clock, and its holdover σ
/// ([`crate::nav::navigator::Navigator::receiver_clock`]) covers it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockWatch {
    /// Per horizon: (GPS time of week s, drift m/s, its variance m²/s²) at the horizon's
    /// start; NaN time: none.
    anchor: [(f64, f64, f64); CLOCK_WATCH_HORIZONS_S.len()],
    /// Per horizon: the mean ratio (1 before the first) and how many it averages.
    mean_ratio: [f64; CLOCK_WATCH_HORIZONS_S.len()],
    count: [u32; CLOCK_WATCH_HORIZONS_S.len()],
}

impl Default for ClockWatch {
    fn default() -> Self {
        Self {
            anchor: [(f64::NAN, 0.0, 0.0); CLOCK_WATCH_HORIZONS_S.len()],
            mean_ratio: [1.0; CLOCK_WATCH_HORIZONS_S.len()],
            count: [0; CLOCK_WATCH_HORIZONS_S.len()],
        }
    }
}

impl ClockWatch {
    /// The factor on the oscillator's random-walk FM, ≥ 1.
    pub fn scale(&self) -> f64 {
        self.mean_ratio.iter().fold(1.0, |s, r| s.max(*r))
    }

    /// Forgets the drifts seen (the clock was re-initialised); keeps what was learnt.
    fn restart(&mut self) {
        for a in &mut self.anchor {
            a.0 = f64::NAN;
        }
    }

    /// Takes the drift `drift_mps` ± √`var` at `tow_s` of a clock modelled by `osc`.
    fn observe(&mut self, tow_s: f64, drift_mps: f64, var: f64, osc: &OscillatorNoise) {
        for (k, horizon) in CLOCK_WATCH_HORIZONS_S.iter().enumerate() {
            let (t0, d0, v0) = self.anchor[k];
            let mut dt = tow_s - t0;
            dt -= (dt / 604_800.0).round() * 604_800.0;
            if !(dt > 0.0 && dt < 2.0 * horizon) {
                // None yet, or a gap: this horizon starts again from here.
                self.anchor[k] = (tow_s, drift_mps, var);
                continue;
            }
            if dt < *horizon {
                continue;
            }
            let r = (drift_mps - d0).powi(2) / (osc.process_noise_m(dt)[(1, 1)] + var + v0);
            self.count[k] = (self.count[k] + 1).min(CLOCK_WATCH_MEMORY);
            self.mean_ratio[k] += (r - self.mean_ratio[k]) / f64::from(self.count[k]);
            self.anchor[k] = (tow_s, drift_mps, var);
        }
    }
}

/// What the ranging updates count.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RangingState {
    /// Epochs fused (at least one satellite accepted).
    pub epochs_used: u64,
    /// Epochs that reached the filter while it did not estimate the clock (loosely coupled).
    pub epochs_not_tight: u64,
    /// Pseudoranges fused.
    pub ranges_used: u64,
    /// Pseudoranges fused per system: GPS, Galileo, BeiDou.
    pub ranges_used_by_system: [u64; SLOTS],
    /// Pseudoranges that failed the innovation gate.
    pub ranges_rejected: u64,
    /// Range rates fused.
    pub rates_used: u64,
    /// Range rates that failed the innovation gate.
    pub rates_rejected: u64,
    /// Time-differenced carrier phases fused.
    pub carrier_deltas_used: u64,
    /// Time-differenced carrier phases that failed the innovation gate (an undetected slip).
    pub carrier_deltas_rejected: u64,
    /// Carrier phases not differenced for a cycle slip the receiver reported (lock time or
    /// half-cycle flag).
    pub carrier_slips: u64,
    /// The previous epoch's carrier phases.
    pub carrier: CarrierMemory,
    /// When each satellite's pseudorange was last fused.
    pub code_memory: CodeMemory,
    /// The receiver clock against its oscillator model.
    pub clock_watch: ClockWatch,
    /// Satellites below the elevation mask.
    pub below_mask: u64,
    /// Satellites below the C/N0 mask.
    pub weak_signal: u64,
    /// Clock initialisations from the residuals.
    pub clock_inits: u64,
    /// Clock bias re-initialisations after a jump of the receiver's clock.
    pub clock_resets: u64,
    /// Inter-system bias initialisations from the residuals (a system's first satellites).
    pub isb_inits: u64,
    /// Fixes fused loosely while tightly coupled because no raw epoch came
    /// ([`crate::nav::navigator::Navigator::on_gnss`]).
    pub fallback_fixes: u64,
    /// Satellites fused in the last epoch.
    pub last_sats: u64,
    /// Host time of the last epoch with a fused satellite, ns (0: none yet).
    pub last_fused_ns: i64,
}

/// The antenna at the measurement epoch.
struct Antenna {
    ecef_m: [f64; 3],
    vel_ecef_mps: Vector3<f64>,
    lat_rad: f64,
    lon_rad: f64,
    h_m: f64,
    /// Columns: the N, E, D axes in ECEF (C_n^e).
    c_ne: Matrix3<f64>,
    /// Lever arm in NED, m.
    lever_n: Vector3<f64>,
    /// Lever-arm velocity C_b^n (ω × l) in NED, m/s.
    lever_vel_n: Vector3<f64>,
    c_bn: Matrix3<f64>,
}

impl Antenna {
    /// The antenna of filter `f` `eps_s` before its time.
    fn of(f: &DelayedFilter, lever_b: &Vector3<f64>, eps_s: f64) -> Self {
        let c_bn = f.pva.q_nb.to_rotation_matrix().into_inner();
        let lever_n = c_bn * lever_b;
        let (rm, rn) = earth::radii(f.pva.lat_rad);
        let d = lever_n - f.pva.vel_ned_mps * eps_s;
        let lat = f.pva.lat_rad + d.x / (rm + f.pva.h_m);
        let lon = f.pva.lon_rad + d.y / ((rn + f.pva.h_m) * f.pva.lat_rad.cos());
        let h = f.pva.h_m - d.z;
        let c_ne = ned_from_ecef(lat, lon).transpose();
        let lever_vel_n = c_bn * f.last_w.cross(lever_b);
        let v_ned = f.pva.vel_ned_mps - f.acc_ned * eps_s + lever_vel_n;
        Self {
            ecef_m: earth::geodetic_to_ecef(lat, lon, h),
            vel_ecef_mps: c_ne * v_ned,
            lat_rad: lat,
            lon_rad: lon,
            h_m: h,
            c_ne,
            lever_n,
            lever_vel_n,
            c_bn,
        }
    }
}

/// One satellite's geometry from the antenna.
struct Sight {
    /// Geometric range, m.
    range_m: f64,
    /// Unit line of sight, ECEF and NED.
    u_ecef: Vector3<f64>,
    u_ned: Vector3<f64>,
    /// Satellite velocity in the reception's ECEF frame, m/s.
    sat_vel: Vector3<f64>,
    el_rad: f64,
    /// Ionosphere plus troposphere, m.
    atmosphere_m: f64,
    /// Variance of what the atmosphere models leave ([`atmosphere_var_m2`]), or of the whole
    /// ionosphere when no model corrects it, m².
    atmosphere_var_m2: f64,
}

fn sight(a: &Antenna, s: &SatRange, e: &RangeEpoch) -> Sight {
    let d0 = Vector3::from(s.sat_ecef_m) - Vector3::from(a.ecef_m);
    let tau = d0.norm() / C_M_S;
    let sat = Vector3::from(rotate_for_flight(s.sat_ecef_m, tau));
    let d = sat - Vector3::from(a.ecef_m);
    let range_m = d.norm();
    let u_ecef = d / range_m;
    let u_ned = a.c_ne.transpose() * u_ecef;
    let el_rad = (-u_ned.z).clamp(-1.0, 1.0).asin();
    let az_rad = u_ned.y.atan2(u_ned.x).rem_euclid(2.0 * std::f64::consts::PI);
    let iono = e
        .iono
        .map(|k| s.iono_scale * C_M_S * k.delay_s(a.lat_rad, a.lon_rad, el_rad, az_rad, e.tow_s));
    let tropo = if el_rad > 0.0 {
        troposphere_delay_m(a.lat_rad, a.h_m, el_rad)
    } else {
        0.0
    };
    // Without the broadcast ionosphere the whole delay is error (`atmosphere_var_m2`).
    let atmosphere_var_m2 = atmosphere_var_m2(iono, s.iono_scale, el_rad);
    Sight {
        range_m,
        u_ecef,
        u_ned,
        sat_vel: Vector3::from(rotate_for_flight(s.sat_vel_mps, tau)),
        el_rad,
        atmosphere_m: iono.unwrap_or(0.0) + tropo,
        atmosphere_var_m2,
    }
}

/// The σ of a measurement with zenith value `zenith` at elevation `el_rad` and C/N0 `cno`:
/// σ² = σ_z²·(1 + 1/sin²el)/2, the a² + b²/sin²(el) model of RTKLIB (T. Takasu, RTKLIB 2.4.2
/// manual, Appendix E) with a = b — part of the error (the broadcast orbit and clock) does not
/// grow towards the horizon — times the weak-signal factor.
fn sigma(zenith: f64, reported: f64, el_rad: f64, cno: f64, rc: &RangingConfig) -> f64 {
    let weak = 10f64.powf(((rc.reference_cno_dbhz - cno) / 10.0).max(0.0));
    let sin_el = el_rad.sin().max(0.05);
    (zenith * ((1.0 + 1.0 / (sin_el * sin_el)) / 2.0).sqrt() * weak.sqrt()).max(reported)
}

/// Median of the first `n` values (n ≥ 1), without allocating.
fn median(v: &mut [f64; MAX_RANGE_SATS], n: usize) -> f64 {
    let s = &mut v[..n];
    s.sort_by(f64::total_cmp);
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

impl RangeEpoch {
    fn usable(&self, a: &Antenna, s: &SatRange, rc: &RangingConfig) -> Option<Sight> {
        let g = sight(a, s, self);
        (g.el_rad >= rc.elevation_mask_rad && f64::from(s.cno_dbhz) >= rc.cno_mask_dbhz).then_some(g)
    }

    /// Sets the clock from the median residuals of the satellites in view (≥ 1) the first
    /// time (GPS's when any is in view, else the first system's), re-anchors the bias after a
    /// jump, and sets each system's inter-system bias from its satellites' median residual the
    /// first time it is seen. Returns false while the clock has never been anchored (no usable
    /// satellite yet).
    fn anchor_clock(
        &self,
        f: &mut DelayedFilter,
        cfg: &NavConfig,
        rc: &RangingConfig,
        eps: f64,
        st: &mut RangingState,
    ) -> bool {
        let a = Antenna::of(f, &Vector3::from(cfg.gnss_lever_arm_m), eps);
        // Residuals without any receiver clock, by system slot ([`system_slot`]).
        let mut res = [[0.0; MAX_RANGE_SATS]; SLOTS];
        let mut n = [0usize; SLOTS];
        let mut rates = [0.0; MAX_RANGE_SATS];
        let mut m = 0;
        for s in self.sats() {
            let Some(k) = system_slot(s.gnss_id) else { continue };
            let Some(g) = self.usable(&a, s, rc) else { continue };
            res[k][n[k]] = s.pseudorange_m - g.range_m - g.atmosphere_m;
            n[k] += 1;
            if s.range_rate_mps.is_finite() {
                rates[m] = s.range_rate_mps - (g.sat_vel - a.vel_ecef_mps).dot(&g.u_ecef);
                m += 1;
            }
        }
        if n.iter().all(|&c| c == 0) {
            return f.clock_valid;
        }
        let pos_var: f64 = (0..3).map(|i| f.eskf.p[(POS + i, POS + i)]).sum();
        let isb_now = |f: &DelayedFilter, k: usize| if k == 0 { 0.0 } else { f.isb_m[k - 1] };
        let anchored = |f: &DelayedFilter, k: usize| k == 0 || f.isb_valid[k - 1];
        if f.clock_valid {
            // A jump of the receiver's clock shows in every anchored system's residuals.
            let mut all = [0.0; MAX_RANGE_SATS];
            let mut c = 0;
            for k in (0..SLOTS).filter(|&k| anchored(f, k)) {
                for r in &res[k][..n[k]] {
                    all[c] = r - isb_now(f, k);
                    c += 1;
                }
            }
            let bias_now = f.clock_bias_m - f.clock_drift_mps * eps;
            let bias = if c > 0 { median(&mut all, c) } else { bias_now };
            if (bias - bias_now).abs() > rc.clock_reset_m {
                f.clock_bias_m = bias + f.clock_drift_mps * eps;
                f.eskf.reopen(CLK_BIAS, rc.clock_init_std_m.powi(2) + pos_var);
                st.clock_resets += 1;
            }
        } else {
            let k = (0..SLOTS).find(|&k| n[k] > 0).unwrap_or(0);
            f.clock_drift_mps = if m > 0 { median(&mut rates, m) } else { 0.0 };
            f.clock_bias_m = median(&mut res[k], n[k]) + f.clock_drift_mps * eps;
            f.eskf.reopen(CLK_BIAS, rc.clock_init_std_m.powi(2) + pos_var);
            f.eskf.reopen(CLK_DRIFT, rc.drift_init_std_mps.powi(2));
            f.clock_valid = true;
            st.clock_inits += 1;
        }
        for k in 1..SLOTS {
            if n[k] == 0 || f.isb_valid[k - 1] {
                continue;
            }
            // Relative to the clock just used: its doubt and the system's median both count.
            let bias_now = f.clock_bias_m - f.clock_drift_mps * eps;
            f.isb_m[k - 1] = median(&mut res[k], n[k]) - bias_now;
            let var = rc.clock_init_std_m.powi(2) + f.eskf.p[(CLK_BIAS, CLK_BIAS)];
            f.eskf.reopen(ISB + k - 1, var);
            f.isb_valid[k - 1] = true;
            st.isb_inits += 1;
        }
        true
    }
}

impl RangeEpoch {
    /// The receiver clock bias of system `slot` at the epoch, m.
    fn clock_m(f: &DelayedFilter, slot: usize, eps: f64) -> f64 {
        let bias = f.clock_bias_m - f.clock_drift_mps * eps;
        if slot > 0 { bias + f.isb_m[slot - 1] } else { bias }
    }

    /// Fuses the time differences of the carrier phases against the previous epoch's
    /// ([`CarrierMemory`]; the model in the module header).
    fn fuse_carrier_deltas(
        &self,
        f: &mut DelayedFilter,
        eps: f64,
        cfg: &NavConfig,
        rc: &RangingConfig,
        st: &mut RangingState,
    ) {
        let prev = st.carrier;
        let mut dt = self.tow_s - prev.tow_s;
        dt -= (dt / 604_800.0).round() * 604_800.0;
        if prev.count == 0 || !(dt > 0.0 && dt <= CARRIER_DELTA_MAX_S) {
            return;
        }
        let lever_b = Vector3::from(cfg.gnss_lever_arm_m);
        let a = Antenna::of(f, &lever_b, eps);
        // The corrections other measurements fed back since: not motion.
        let moved_by_corrections = f.pos_corrections_ned_m - prev.corrections_ned_m;
        let mut rows = [(0.0, SMatrix::<f64, 1, N>::zeros(), 0.0); MAX_RANGE_SATS];
        let mut n = 0;
        for s in self.sats().iter().filter(|s| s.carrier_m.is_finite()) {
            let Some(slot) = fused_slot(f, s.gnss_id) else {
                continue;
            };
            let Some(e) = prev.sats[..prev.count]
                .iter()
                .find(|e| (e.gnss_id, e.sv, e.sig_id) == (s.gnss_id, s.sv, s.sig_id))
            else {
                continue;
            };
            let kept_lock = RawMeasurement::kept_lock(e.lock_time_ms, s.lock_time_ms, dt)
                && (s.trk_stat ^ e.trk_stat) & 8 == 0;
            if !kept_lock {
                st.carrier_slips += 1;
                continue;
            }
            let Some(g) = self.usable(&a, s, rc) else { continue };
            let h = range_rate_row(f, &a, &g, &lever_b) * dt;
            let predicted = g.range_m + g.u_ned.dot(&moved_by_corrections) - e.range_m
                + Self::clock_m(f, slot, eps)
                - e.clock_m;
            let reported = std::f64::consts::SQRT_2 * s.carrier_std_m.max(0.0);
            let sd = sigma(CARRIER_DELTA_STD_M, reported, g.el_rad, f64::from(s.cno_dbhz), rc);
            rows[n] = (predicted - (s.carrier_m - e.carrier_m), h, sd * sd);
            n += 1;
        }
        // Sequentially, each residual moved by what the epoch's earlier ones corrected.
        let mut applied = StateVec::zeros();
        for (dz0, h, var) in &rows[..n] {
            let dz = Vector1::new(dz0 - (h * applied)[0]);
            match f.eskf.update(&dz, h, &Matrix1::new(*var), cfg.gate_scale) {
                Update::Accepted { dx, .. } => {
                    f.feedback(&dx, cfg.fusion_horizon_s);
                    applied += dx;
                    st.carrier_deltas_used += 1;
                }
                Update::Rejected { .. } => st.carrier_deltas_rejected += 1,
            }
        }
    }

    /// Keeps this epoch's carrier phases with the corrected antenna's ranges and clock, for
    /// the next epoch's differences.
    fn remember_carriers(
        &self,
        f: &DelayedFilter,
        eps: f64,
        cfg: &NavConfig,
        rc: &RangingConfig,
        st: &mut RangingState,
    ) {
        let a = Antenna::of(f, &Vector3::from(cfg.gnss_lever_arm_m), eps);
        let m = &mut st.carrier;
        m.tow_s = self.tow_s;
        m.corrections_ned_m = f.pos_corrections_ned_m;
        m.count = 0;
        for s in self.sats().iter().filter(|s| s.carrier_m.is_finite()) {
            let Some(slot) = fused_slot(f, s.gnss_id) else {
                continue;
            };
            let Some(g) = self.usable(&a, s, rc) else { continue };
            m.sats[m.count] = CarrierTrack {
                gnss_id: s.gnss_id,
                sv: s.sv,
                sig_id: s.sig_id,
                trk_stat: s.trk_stat,
                lock_time_ms: s.lock_time_ms,
                carrier_m: s.carrier_m,
                range_m: g.range_m,
                clock_m: Self::clock_m(f, slot, eps),
            };
            m.count += 1;
        }
    }
}

/// [`system_slot`] of a system whose clock the filter holds (GPS, or an anchored inter-system
/// bias); `None` otherwise.
fn fused_slot(f: &DelayedFilter, gnss_id: u8) -> Option<usize> {
    system_slot(gnss_id).filter(|&k| k == 0 || f.isb_valid[k - 1])
}

/// The Jacobian row of a range rate along `g`'s line of sight (the module header's model):
/// velocity, the lever arm's rotation through attitude and gyro bias, Δ (when observable)
/// and the clock drift. Times Δt it is a carrier-phase difference's.
fn range_rate_row(f: &DelayedFilter, a: &Antenna, g: &Sight, lever_b: &Vector3<f64>) -> SMatrix<f64, 1, N> {
    let un = g.u_ned.transpose();
    let mut h = SMatrix::<f64, 1, N>::zeros();
    h.fixed_view_mut::<1, 3>(0, VEL).copy_from(&(-un));
    h.fixed_view_mut::<1, 3>(0, ATT)
        .copy_from(&(-un * skew(&a.lever_vel_n)));
    h.fixed_view_mut::<1, 3>(0, BG)
        .copy_from(&(un * a.c_bn * skew(lever_b)));
    if f.delay_observable() {
        h[(0, DELAY)] = -g.u_ned.dot(&f.acc_ned);
    }
    h[(0, CLK_DRIFT)] = -1.0;
    h
}

/// Clocks of the filter: GPS's and one per inter-system bias.
const SLOTS: usize = 1 + ISB_SYSTEMS;

/// The slot of system `gnss_id` among the filter's clocks: 0 GPS, 1 Galileo, 2 BeiDou, 3 GLONASS
/// (1 + the index of its inter-system bias state); `None` for systems not fused.
fn system_slot(gnss_id: u8) -> Option<usize> {
    match gnss_id {
        GNSS_ID_GPS => Some(0),
        GNSS_ID_GALILEO => Some(1),
        GNSS_ID_BEIDOU => Some(2),
        GNSS_ID_GLONASS => Some(3),
        _ => None,
    }
}

impl Measurement for RangeEpoch {
    type Config = RangingConfig;
    type State = RangingState;

    fn epoch_ns(&self, delay_s: f64) -> i64 {
        self.stamp_host_ns - (delay_s * 1e9) as i64
    }

    fn fuse(
        &self,
        f: &mut DelayedFilter,
        eps: f64,
        cfg: &NavConfig,
        rc: &RangingConfig,
        st: &mut RangingState,
    ) -> bool {
        if cfg.noise.clock.is_none() {
            st.epochs_not_tight += 1;
            return false;
        }
        let clock_events = (st.clock_inits, st.clock_resets);
        if !self.anchor_clock(f, cfg, rc, eps, st) {
            return false;
        }
        if (st.clock_inits, st.clock_resets) != clock_events {
            // A clock (re)set: nothing to difference against.
            st.carrier.count = 0;
            st.clock_watch.restart();
        }
        f.clock_q_scale = st.clock_watch.scale();
        if self.pos_floor_std_ned_m != [0.0; 3] {
            f.pos_floor_std_ned_m = Vector3::from(self.pos_floor_std_ned_m);
            f.clock_floor_std_m = self.clock_floor_std_m;
        }
        let lever_b = Vector3::from(cfg.gnss_lever_arm_m);
        self.fuse_carrier_deltas(f, eps, cfg, rc, st);
        let mut used = 0u64;
        for s in self.sats() {
            let Some(slot) = fused_slot(f, s.gnss_id) else {
                continue;
            };
            let a = Antenna::of(f, &lever_b, eps);
            let Some(g) = self.usable(&a, s, rc) else {
                if sight(&a, s, self).el_rad < rc.elevation_mask_rad {
                    st.below_mask += 1;
                } else {
                    st.weak_signal += 1;
                }
                continue;
            };
            let cno = f64::from(s.cno_dbhz);
            let un = g.u_ned.transpose();

            // Pseudorange.
            let mut h = SMatrix::<f64, 1, N>::zeros();
            h.fixed_view_mut::<1, 3>(0, POS).copy_from(&(-un));
            h.fixed_view_mut::<1, 3>(0, ATT).copy_from(&(-un * skew(&a.lever_n)));
            if f.delay_observable() {
                h[(0, DELAY)] = -g.u_ned.dot(&f.pva.vel_ned_mps);
            }
            h[(0, CLK_BIAS)] = -1.0;
            if slot > 0 {
                h[(0, ISB + slot - 1)] = -1.0;
            }
            let bias = Self::clock_m(f, slot, eps);
            let dz = Vector1::new(g.range_m + bias + g.atmosphere_m - s.pseudorange_m);
            let sd = sigma(rc.pseudorange_std_m, s.pseudorange_std_m, g.el_rad, cno, rc);
            // Gated on one sample's variance (an outlier stands out of that), fused with the
            // correlated error's.
            let var = sd * sd + g.atmosphere_var_m2;
            let inflation = st.code_memory.inflation(s, self.tow_s, rc.code_correlation_s);
            let update = match f.eskf.gate(&dz, &h, &Matrix1::new(var), cfg.gate_scale) {
                (true, _) => f.eskf.update(&dz, &h, &Matrix1::new(var * inflation), f64::INFINITY),
                (false, nis) => Update::Rejected { nis },
            };
            match update {
                Update::Accepted { dx, .. } => {
                    f.feedback(&dx, cfg.fusion_horizon_s);
                    st.ranges_used += 1;
                    st.ranges_used_by_system[slot] += 1;
                    used += 1;
                }
                Update::Rejected { .. } => st.ranges_rejected += 1,
            }

            // Range rate.
            if !s.range_rate_mps.is_finite() {
                continue;
            }
            let a = Antenna::of(f, &lever_b, eps);
            let g = sight(&a, s, self);
            let h = range_rate_row(f, &a, &g, &lever_b);
            let rate = (g.sat_vel - a.vel_ecef_mps).dot(&g.u_ecef) + f.clock_drift_mps;
            let dz = Vector1::new(rate - s.range_rate_mps);
            let sd = sigma(rc.range_rate_std_mps, s.range_rate_std_mps, g.el_rad, cno, rc);
            match f.eskf.update(&dz, &h, &Matrix1::new(sd * sd), cfg.gate_scale) {
                Update::Accepted { dx, .. } => {
                    f.feedback(&dx, cfg.fusion_horizon_s);
                    st.rates_used += 1;
                }
                Update::Rejected { .. } => st.rates_rejected += 1,
            }
        }
        self.remember_carriers(f, eps, cfg, rc, st);
        if let Some(osc) = cfg.noise.clock.filter(|_| used >= CLOCK_WATCH_MIN_SATS) {
            let var = f.eskf.p[(CLK_DRIFT, CLK_DRIFT)];
            st.clock_watch.observe(self.tow_s, f.clock_drift_mps, var, &osc);
            f.clock_q_scale = st.clock_watch.scale();
        }
        st.last_sats = used;
        if used > 0 {
            st.epochs_used += 1;
            st.last_fused_ns = self.epoch_ns(f.delay_s);
        }
        used > 0
    }

    fn counters(st: &RangingState, out: &mut dyn FnMut(&'static str, u64)) {
        out("ranges_epochs_used", st.epochs_used);
        out("ranges_epochs_not_tight", st.epochs_not_tight);
        out("ranges_used", st.ranges_used);
        out("ranges_used_gps", st.ranges_used_by_system[0]);
        out("ranges_used_galileo", st.ranges_used_by_system[1]);
        out("ranges_used_beidou", st.ranges_used_by_system[2]);
        out("ranges_used_glonass", st.ranges_used_by_system[3]);
        out("ranges_rejected", st.ranges_rejected);
        out("range_rates_used", st.rates_used);
        out("range_rates_rejected", st.rates_rejected);
        out("carrier_deltas_used", st.carrier_deltas_used);
        out("carrier_deltas_rejected", st.carrier_deltas_rejected);
        out("carrier_slips", st.carrier_slips);
        out("ranges_below_mask", st.below_mask);
        out("ranges_weak_signal", st.weak_signal);
        out("clock_inits", st.clock_inits);
        out("clock_resets", st.clock_resets);
        out("isb_inits", st.isb_inits);
        out("ranges_fallback_fixes", st.fallback_fixes);
        out("clock_noise_scale_pct", (st.clock_watch.scale() * 100.0).round() as u64);
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::UnitQuaternion;

    use super::*;
    use crate::nav::config::ReceiverOscillator;
    use crate::nav::error_state::StateMat;
    use crate::nav::eskf::Eskf;
    use crate::nav::mechanization::Pva;

    /// (azimuth, elevation) of the test's satellites, deg.
    const SKY: [(f64, f64); 6] = [(0.0, 60.0), (70.0, 35.0), (140.0, 50.0), (200.0, 25.0), (260.0, 40.0), (320.0, 70.0)];
    const CLOCK_M: f64 = 100.0;
    const DT_S: f64 = 0.25;

    fn cfg() -> NavConfig {
        let mut c = NavConfig::default();
        c.noise.clock = Some(ReceiverOscillator::Tcxo.noise());
        c
    }

    /// A filter at rest at 34° N 137° E moving north at `v_n` m/s, its clock anchored.
    fn filter(v_n: f64) -> DelayedFilter {
        let pva = Pva {
            lat_rad: 34f64.to_radians(),
            lon_rad: 137f64.to_radians(),
            h_m: 50.0,
            vel_ned_mps: Vector3::new(v_n, 0.0, 0.0),
            q_nb: UnitQuaternion::identity(),
        };
        let mut p = StateMat::identity() * 1e-8;
        for i in 0..3 {
            p[(POS + i, POS + i)] = 0.01;
            p[(VEL + i, VEL + i)] = 0.25;
        }
        (p[(CLK_BIAS, CLK_BIAS)], p[(CLK_DRIFT, CLK_DRIFT)]) = (1.0, 1e-4);
        let mut f = DelayedFilter::new(pva, 0, Eskf::new(p), Vector3::zeros(), 0.0);
        (f.clock_bias_m, f.clock_valid) = (CLOCK_M, true);
        f
    }

    /// Moves a filter north by `d_m` as its strapdown would.
    fn move_north(f: &mut DelayedFilter, d_m: f64) {
        f.pva.lat_rad += d_m / earth::radii(f.pva.lat_rad).0;
    }

    /// The epoch `truth` would measure at `tow_s`: the satellites of [`SKY`] (seen from
    /// `origin`, fixed in ECEF), code and carrier exact, carrier ambiguities of k cycles.
    fn epoch(truth: &DelayedFilter, origin: &DelayedFilter, tow_s: f64) -> RangeEpoch {
        let lever = Vector3::zeros();
        let (a0, a) = (Antenna::of(origin, &lever, 0.0), Antenna::of(truth, &lever, 0.0));
        let mut e = RangeEpoch {
            stamp_host_ns: (tow_s * 1e9) as i64,
            tow_s,
            iono: None,
            pos_floor_std_ned_m: [0.0; 3],
            clock_floor_std_m: 0.0,
            count: SKY.len() as u8,
            sats: [SatRange::default(); MAX_RANGE_SATS],
        };
        for (k, &(az, el)) in SKY.iter().enumerate() {
            let (az, el) = (az.to_radians(), el.to_radians());
            let u = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), -el.sin());
            let sat = Vector3::from(a0.ecef_m) + a0.c_ne * u * 2.2e7;
            e.sats[k] = SatRange {
                gnss_id: GNSS_ID_GPS,
                sv: k as u8 + 1,
                iono_scale: 1.0,
                cno_dbhz: 45,
                sat_ecef_m: sat.into(),
                range_rate_mps: f64::NAN,
                carrier_std_m: 0.001,
                lock_time_ms: (tow_s * 1000.0) as u16,
                trk_stat: 0b0111,
                ..SatRange::default()
            };
            let g = sight(&a, &e.sats[k], &e);
            e.sats[k].pseudorange_m = g.range_m + g.atmosphere_m + CLOCK_M;
            e.sats[k].carrier_m = g.range_m + g.atmosphere_m + CLOCK_M + 0.19 * (1000 + k) as f64;
        }
        e
    }

    /// GLONASS ranges get their own clock: their first epoch sets its inter-system bias (30 m
    /// here, GLONASS time's offset and the receiver's delays) from their median, then they are
    /// fused beside GPS's without moving the position.
    #[test]
    fn glonass_ranges_have_their_own_inter_system_bias() {
        let (cfg, rc) = (cfg(), RangingConfig::default());
        let origin = filter(0.0);
        let mut f = filter(0.0);
        let mut st = RangingState::default();
        for k in 0..8 {
            let mut e = epoch(&origin, &origin, 100.0 + k as f64 * DT_S);
            for s in &mut e.sats[4..6] {
                (s.gnss_id, s.sv) = (GNSS_ID_GLONASS, s.sv + 10);
                s.pseudorange_m += 30.0;
                s.carrier_m += 30.0;
            }
            assert!(e.fuse(&mut f, 0.0, &cfg, &rc, &mut st));
        }
        assert_eq!((st.isb_inits, st.ranges_used_by_system), (1, [32, 0, 0, 16]));
        assert!(f.isb_valid[2] && !f.isb_valid[0] && !f.isb_valid[1]);
        assert!((f.isb_m[2] - 30.0).abs() < 0.01, "GLONASS − GPS {} m", f.isb_m[2]);
        let d = Antenna::of(&f, &Vector3::zeros(), 0.0).ecef_m;
        let o = Antenna::of(&origin, &Vector3::zeros(), 0.0).ecef_m;
        let moved = (0..3).map(|i| (d[i] - o[i]).powi(2)).sum::<f64>().sqrt();
        assert!(moved < 0.01, "moved {moved} m");
    }

    /// The carrier's change over an epoch corrects a velocity 0.3 m/s off; a slip the receiver
    /// reports (lock time restarted, half-cycle flag changed) is not differenced, one it does not
    /// report (a cycle) fails the gate.
    #[test]
    fn the_carrier_phase_difference_measures_the_motion_and_slips_are_not_fused() {
        let (cfg, rc) = (cfg(), RangingConfig::default());
        let origin = filter(1.0);
        let (mut truth, mut f) = (filter(1.0), filter(1.3));
        let mut st = RangingState::default();
        let mut tow = 100.0;
        assert!(epoch(&truth, &origin, tow).fuse(&mut f, 0.0, &cfg, &rc, &mut st));
        assert_eq!(st.carrier_deltas_used, 0, "nothing to difference yet");
        let step = |truth: &mut DelayedFilter, f: &mut DelayedFilter, tow: &mut f64| {
            move_north(truth, 1.0 * DT_S);
            let v = f.pva.vel_ned_mps.x;
            move_north(f, v * DT_S);
            *tow += DT_S;
        };
        step(&mut truth, &mut f, &mut tow);
        epoch(&truth, &origin, tow).fuse(&mut f, 0.0, &cfg, &rc, &mut st);
        assert_eq!((st.carrier_deltas_used, st.carrier_deltas_rejected), (6, 0));
        let v = f.pva.vel_ned_mps;
        assert!((v.x - 1.0).abs() < 0.03 && v.y.abs() < 0.03, "velocity {v:?}");
        // The receiver restarts satellite 1's lock and flips satellite 2's half-cycle flag.
        step(&mut truth, &mut f, &mut tow);
        let mut e = epoch(&truth, &origin, tow);
        e.sats[0].lock_time_ms = 20;
        e.sats[1].trk_stat |= 8;
        e.fuse(&mut f, 0.0, &cfg, &rc, &mut st);
        assert_eq!((st.carrier_deltas_used, st.carrier_slips), (10, 2));
        // Satellite 3 slips a cycle unannounced.
        step(&mut truth, &mut f, &mut tow);
        let mut e = epoch(&truth, &origin, tow);
        e.sats[1].trk_stat |= 8;
        e.sats[2].carrier_m += 0.19;
        e.fuse(&mut f, 0.0, &cfg, &rc, &mut st);
        assert_eq!((st.carrier_deltas_used, st.carrier_deltas_rejected), (15, 1));
        assert!((f.pva.vel_ned_mps.x - 1.0).abs() < 0.03);
    }

    /// A clock as stable as its TCXO model keeps the model (the scale within the χ² spread of
    /// 8 ratios); one whose frequency ramps as the walk0827 receiver's does (−0.16 m/s², on
    /// top of the model's noise) raises it at the long horizons; a clock reset starts the
    /// drifts again without forgetting what was learnt.
    #[test]
    fn the_clock_watch_scales_the_oscillator_to_what_the_clock_shows() {
        let osc = ReceiverOscillator::Tcxo.noise();
        let mut rng = 0x2545_f491_4f6c_dd1du64;
        let mut gauss = move || crate::test_noise::gauss(&mut rng);
        let q_per_step = osc.process_noise_m(DT_S)[(1, 1)];
        let run = |ramp_mps2: f64, gauss: &mut dyn FnMut() -> f64| {
            let mut w = ClockWatch::default();
            let mut drift = -60.0;
            for k in 0..2400 {
                drift += ramp_mps2 * DT_S + q_per_step.sqrt() * gauss();
                w.observe(1000.0 + k as f64 * DT_S, drift, 1e-6, &osc);
            }
            w
        };
        let steady = run(0.0, &mut gauss);
        assert!(steady.scale() < 2.5, "a clock as its model: scale {}", steady.scale());
        let mut ramping = run(-0.16, &mut gauss);
        let s = ramping.scale();
        assert!(s > 20.0, "a ramping clock: scale {s}");
        ramping.restart();
        assert_eq!(ramping.scale(), s);
        ramping.observe(5000.0, 0.0, 1e-6, &osc);
        assert_eq!(ramping.scale(), s, "a restart's first drift is no change");
    }

    /// A satellite's pseudoranges Δt apart count as one per 2τ: the first at full weight, the
    /// next ones with their variance × 2τ/Δt, and again in full after a gap of 2τ.
    #[test]
    fn repeated_pseudoranges_of_a_satellite_are_weighted_by_their_correlation() {
        let mut m = CodeMemory::default();
        let s = SatRange {
            gnss_id: GNSS_ID_GPS,
            sv: 5,
            ..SatRange::default()
        };
        assert_eq!(m.inflation(&s, 10.0, 5.0), 1.0);
        assert_eq!(m.inflation(&s, 10.25, 5.0), 40.0);
        assert_eq!(m.inflation(&s, 11.25, 5.0), 10.0);
        assert_eq!(m.inflation(&s, 31.25, 5.0), 1.0);
        // Another satellite has its own history; a system not fused is not weighted.
        assert_eq!(m.inflation(&SatRange { sv: 6, ..s }, 31.5, 5.0), 1.0);
        assert_eq!(m.inflation(&SatRange { gnss_id: 1, ..s }, 31.5, 5.0), 1.0);
    }
}
