//! Loosely coupled GNSS aiding: position and velocity of the antenna, with the lever arm and
//! the GNSS time-synchronisation error Δ; one [`Measurement`] kind of the navigator's queue
//! (PX4 EKF2 keeps each aiding source in its own file; this is the GNSS one).
//!
//! Measurement model. The receiver reports the antenna state at its epoch t_e; the filter fuses
//! the fix at t_f = t_stamp − Δ̂ (t_stamp: the epoch mapped to host time under hardware sync, the
//! receipt time of its first byte under software sync). With δΔ = Δ − Δ̂ the true epoch is
//! t_f − δΔ, so the fix measures p(t_f − δΔ) ≈ p(t_f) − v·δΔ and v(t_f − δΔ) ≈ v(t_f) − a·δΔ:
//! the measurement Jacobian w.r.t. Δ is −v for position and −a for velocity (Li et al.,
//! GPS/SINS time synchronisation). In KF-GINS's innovation form dz = INS − GNSS = H δx this
//! appears as +v and +a in the Δ column, with δΔ "true − estimated".
//!
//! Position innovation (KF-GINS `gnssUpdate`): dz_r = D_R (p_ant − p_gnss), p_ant = p + D_R⁻¹ C_b^n l,
//! D_R = diag(R_M+h, (R_N+h) cos φ, −1); H_r = [I₃, 0, [(C_b^n l)×], 0, …, v].
//! Velocity innovation: v_ant = v + C_b^n (ω_ib^b × l); dz_v = v_ant − v_gnss;
//! H_v = [0, I₃, [(C_b^n (ω×l))×], −C_b^n [l×], 0, …, a].

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use navsync_wire::earth;
use navsync_wire::samples::{
    FIX_FLAG_INVALID_LLH, FIX_FLAG_NOT_GNSS, FIX_FLAG_RECEIVER_INVALID, GNSS_PROTOCOL_FILE, GnssFix,
};

use super::Measurement;
use crate::declare::checks::{non_negative, positive};
use crate::nav::config::NavConfig;
use crate::nav::error_state::{ATT, BA, BG, DELAY, N, POS, VEL};
use crate::nav::eskf::Update;
use crate::nav::filter::DelayedFilter;
use crate::nav::mechanization::{Pva, skew};

/// A fix reduced to what the filter fuses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GnssObservation {
    /// Host time of the fix before the Δ correction, ns (see module docs).
    pub stamp_host_ns: i64,
    /// Latitude, rad.
    pub lat_rad: f64,
    /// Longitude, rad.
    pub lon_rad: f64,
    /// Ellipsoidal height of the antenna, m.
    pub h_m: f64,
    /// NED velocity, m/s; the down component may be NaN (NMEA carries none).
    pub vel_ned_mps: Vector3<f64>,
    /// 1-sigma position error N, E, D, m.
    pub pos_std_m: Vector3<f64>,
    /// 1-sigma velocity error per axis, m/s.
    pub vel_std_mps: f64,
    /// Speed over ground, m/s (NaN when unknown).
    pub speed_mps: f64,
    /// Track over ground, rad (NaN when unknown).
    pub track_rad: f64,
    /// 1-sigma N, E, D of the part of the fix's error that persists across epochs, m (zero:
    /// none). A single-point solution's errors (broadcast orbit and clock, atmosphere,
    /// multipath) change over minutes, not from one epoch to the next; the filter, which fuses
    /// each epoch as independent, would average them away. The published position σ is never
    /// below it ([`DelayedFilter::pos_floor_std_ned_m`]). A receiver's fix: its own accuracy
    /// (u-blox hAcc and vAcc are the "accuracy estimate" of the position it reports, NMEA GST
    /// the "standard deviation" of its errors; the interface descriptions), which no number
    /// of its fixes improves, their errors being correlated from one to the next; a file's
    /// ([`GNSS_PROTOCOL_FILE`]): none, its σ being the measurement noise KF-GINS takes it for.
    pub pos_floor_std_m: Vector3<f64>,
}

crate::settings_group! {
    /// How the fixes' accuracy becomes the measurement noise R: the receiver's own σ (NMEA GST,
    /// a KF-GINS file's std columns) where a fix carries it, else an HDOP model; then scaled and
    /// floored, so an RTK-fixed receiver is trusted at cm level and a model of the receiver's
    /// optimism can be stated.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct GnssAccuracy {
        /// User-equivalent range error for fixes without their own σ, m: σ_horizontal axis =
        /// HDOP·UERE/√2, σ_down = VDOP·UERE (default 2 m).
        pub uere_m: f64 = 2.0;
        /// 1-sigma of the receiver's velocity per axis where a fix carries none (NMEA), m/s.
        pub gnss_vel_std_mps: f64 = 0.1, file "estimator", flag "gnss-vel-std", check positive;
        /// Factor on every position σ (1: the receiver's σ as it is).
        pub gnss_pos_std_scale: f64 = 1.0, file "estimator", flag "gnss-std-scale", check positive;
        /// Smallest GNSS position σ per axis, m.
        pub gnss_pos_std_floor_m: f64 = 0.005, file "estimator", flag "gnss-std-floor", check non_negative;
    }
}

/// 1-sigma given to an altitude the receiver holds ([`GnssFix::altitude_held`]), m: large
/// enough that the update carries no vertical information.
pub const HELD_ALTITUDE_STD_M: f64 = 1.0e3;

/// Prepares a fix for fusion; `None` when it has no usable position (no 2D/3D fix, or the
/// receiver flags it invalid) or is not a GNSS solution: a u-blox HNR-PVT is the receiver's own
/// GNSS/INS blend at up to 30 Hz, correlated from one to the next and with the receiver's
/// IMU, and fusing it as an independent GNSS measurement would make the filter overconfident. Accuracy, in order: the receiver's per-axis σ (NMEA GST); its
/// accuracy estimates (UBX hAcc, vAcc: σ north = σ east = hAcc/√2, σ down = vAcc); else the
/// DOPs (VDOP unknown: 1.5·HDOP; HDOP unknown: 2). Velocity σ per axis: sAcc/√2 when reported,
/// else the configured value.
pub fn observation(fix: &GnssFix, stamp_host_ns: i64, acc: &GnssAccuracy) -> Option<GnssObservation> {
    if !fix.has_position() || !fix.alt_msl_m.is_finite() {
        return None;
    }
    if fix.fix_flags & (FIX_FLAG_INVALID_LLH | FIX_FLAG_RECEIVER_INVALID | FIX_FLAG_NOT_GNSS) != 0 {
        return None;
    }
    let hdop = if fix.hdop.is_finite() { fix.hdop } else { 2.0 };
    let vdop = if fix.vdop.is_finite() { fix.vdop } else { 1.5 * hdop };
    let gst = [fix.std_lat_m, fix.std_lon_m, fix.std_alt_m];
    let positive = |x: f64| x.is_finite() && x > 0.0;
    let mut pos_std = if gst.iter().all(|s| positive(*s)) {
        Vector3::from(gst)
    } else if positive(fix.h_acc_m) && positive(fix.v_acc_m) {
        let h = fix.h_acc_m / std::f64::consts::SQRT_2;
        Vector3::new(h, h, fix.v_acc_m)
    } else {
        let h = hdop * acc.uere_m / std::f64::consts::SQRT_2;
        Vector3::new(h, h, vdop * acc.uere_m)
    };
    let vel_std_mps = if positive(fix.s_acc_mps) {
        fix.s_acc_mps / std::f64::consts::SQRT_2
    } else {
        acc.gnss_vel_std_mps
    };
    pos_std = (pos_std * acc.gnss_pos_std_scale).map(|s| s.max(acc.gnss_pos_std_floor_m));
    if fix.altitude_held() {
        // From ≤ 3 satellites the altitude is the receiver's assumption: no vertical information.
        pos_std.z = pos_std.z.max(HELD_ALTITUDE_STD_M);
    }
    Some(GnssObservation {
        stamp_host_ns,
        lat_rad: fix.lat_deg.to_radians(),
        lon_rad: fix.lon_deg.to_radians(),
        h_m: fix.height_m(),
        vel_ned_mps: Vector3::new(fix.vel_n_mps, fix.vel_e_mps, fix.vel_d_mps),
        pos_std_m: pos_std,
        vel_std_mps,
        speed_mps: fix.speed_mps,
        track_rad: fix.track_deg.to_radians(),
        pos_floor_std_m: if fix.protocol == GNSS_PROTOCOL_FILE {
            Vector3::zeros()
        } else {
            // No vertical floor from an altitude the receiver held.
            Vector3::new(pos_std.x, pos_std.y, if fix.altitude_held() { 0.0 } else { pos_std.z })
        },
    })
}

/// Position update terms at the filter state `pva` with body rate `w_b` (rad/s, bias
/// compensated), fused `eps_s` after the observation's (Δ-corrected) time: the GNSS position
/// is extrapolated by v_ant·ε. The Δ column only when `delay_observable`
/// ([`DelayedFilter::delay_observable`]). Both use the antenna's velocity
/// v_ant = v + C_b^n (ω × l): the antenna at the epoch t − Δ is r(t − Δ) + C_b^n(t − Δ)·l, whose
/// derivative in Δ is −v_ant (a slow robot turning 60° in 8 s with its antenna 0.47 m off the
/// IMU: a lever-arm velocity of 0.06 m/s beside 0.5 m/s).
pub fn position_terms(
    pva: &Pva,
    lever_b: &Vector3<f64>,
    w_b: &Vector3<f64>,
    obs: &GnssObservation,
    eps_s: f64,
    delay_observable: bool,
) -> (SVector<f64, 3>, SMatrix<f64, 3, N>, Matrix3<f64>) {
    let c_bn = pva.q_nb.to_rotation_matrix().into_inner();
    let (rm, rn) = earth::radii(pva.lat_rad);
    let d_r = Vector3::new(rm + pva.h_m, (rn + pva.h_m) * pva.lat_rad.cos(), -1.0);
    let lever_n = c_bn * lever_b;
    let v = pva.vel_ned_mps + c_bn * w_b.cross(lever_b);
    let dz = Vector3::new(
        (pva.lat_rad - obs.lat_rad) * d_r.x,
        (pva.lon_rad - obs.lon_rad) * d_r.y,
        (pva.h_m - obs.h_m) * d_r.z,
    ) + lever_n
        - v * eps_s;
    let mut h = SMatrix::<f64, 3, N>::zeros();
    h.fixed_view_mut::<3, 3>(0, POS).copy_from(&Matrix3::identity());
    h.fixed_view_mut::<3, 3>(0, ATT).copy_from(&skew(&lever_n));
    if delay_observable {
        h.fixed_view_mut::<3, 1>(0, DELAY).copy_from(&v);
    }
    let r = Matrix3::from_diagonal(&obs.pos_std_m.component_mul(&obs.pos_std_m));
    (dz, h, r)
}

/// Horizontal velocity update terms (NMEA has no vertical velocity), with body rate `w_b`
/// (rad/s, bias compensated) and NED acceleration `acc_ned` for the Δ column (only when
/// `delay_observable`).
pub fn velocity_terms(
    pva: &Pva,
    lever_b: &Vector3<f64>,
    w_b: &Vector3<f64>,
    acc_ned: &Vector3<f64>,
    obs: &GnssObservation,
    eps_s: f64,
    delay_observable: bool,
) -> (SVector<f64, 2>, SMatrix<f64, 2, N>, nalgebra::Matrix2<f64>) {
    let c_bn = pva.q_nb.to_rotation_matrix().into_inner();
    let rot = c_bn * w_b.cross(lever_b);
    let v_ant = pva.vel_ned_mps + rot;
    let dz3 = v_ant - obs.vel_ned_mps - acc_ned * eps_s;
    let mut h3 = SMatrix::<f64, 3, N>::zeros();
    h3.fixed_view_mut::<3, 3>(0, VEL).copy_from(&Matrix3::identity());
    h3.fixed_view_mut::<3, 3>(0, ATT).copy_from(&skew(&rot));
    h3.fixed_view_mut::<3, 3>(0, BG).copy_from(&(-c_bn * skew(lever_b)));
    if delay_observable {
        h3.fixed_view_mut::<3, 1>(0, DELAY).copy_from(acc_ned);
    }
    let dz = SVector::<f64, 2>::new(dz3.x, dz3.y);
    let h = h3.fixed_rows::<2>(0).into_owned();
    let r = nalgebra::Matrix2::identity() * (obs.vel_std_mps * obs.vel_std_mps);
    (dz, h, r)
}

/// Fuses the fix into one hypothesis of the heading bank ([`crate::nav::heading_bank`]),
/// ungated: position, then horizontal velocity where the fix has one. Returns the
/// log-likelihood of the innovations (their sum) and the heading correction they applied
/// (rad, about the navigation frame's down axis); `None` when an update failed (the
/// hypothesis is then dropped).
pub fn fuse_weighed(obs: &GnssObservation, f: &mut DelayedFilter, eps: f64, cfg: &NavConfig) -> Option<(f64, f64)> {
    let lever = Vector3::from(cfg.gnss_lever_arm_m);
    f.with_unobservable_delay_held(|f| {
        let (dz, h, r) = position_terms(&f.pva, &lever, &f.last_w, obs, eps, f.delay_observable());
        let (dx, mut ll) = f.eskf.update_with_likelihood(&dz, &h, &r)?;
        f.feedback(&dx, cfg.fusion_horizon_s);
        let mut dyaw = dx[ATT + 2];
        if obs.vel_ned_mps.x.is_finite() && obs.vel_ned_mps.y.is_finite() {
            let (dz, h, r) = velocity_terms(&f.pva, &lever, &f.last_w, &f.acc_ned, obs, eps, f.delay_observable());
            let (dx, l) = f.eskf.update_with_likelihood(&dz, &h, &r)?;
            f.feedback(&dx, cfg.fusion_horizon_s);
            ll += l;
            dyaw += dx[ATT + 2];
        }
        Some((ll, dyaw))
    })
}

/// Consecutive rejected fixes after which the filter resets to GNSS (a GNSS jump, or a filter
/// that has lost consistency, must not keep it in dead reckoning forever; PX4's EKF2 does the
/// same after its GPS rejection timeout). When the fix's velocity passes the gate the inertial
/// solution is sound and the position jumped (a receiver reset, a spoofer): only the position
/// is reset. Otherwise position and velocity are, and the attitude and sensor-error
/// uncertainty reopened.
pub const RESET_AFTER_REJECTS: u32 = 5;

crate::settings_group! {
    /// How GNSS fixes that fail the gate are treated, and how the filter checks its own model.
    ///
    /// **Covariance inflation.** A fix whose position fails the 99.9 % gate by at most
    /// `max_inflation` (NIS ≤ gate × `max_inflation`) after the filter has coasted without a
    /// position for `coast_s`, while it is still recovering from such a fix (within `coast_s` of
    /// it), right after a rejected fix, or while the recent innovations are too large on average
    /// (NIS per component above `inflate_above_nis`), is evidence that the filter's covariance is
    /// too small (process noise below what the IMU really does: vibration, a wrong IMU model, a
    /// long outage), not that the fix is wrong: the whole covariance is scaled by NIS / gate, which
    /// keeps its correlations (fading memory, Sorenson & Sacks 1971; Groves 2013 §17.3.2), and the
    /// fix is fused. A single fix far off after fixes that agreed (multipath) is still rejected,
    /// and so is any fix beyond the bound (a 10 km jump), which [`RESET_AFTER_REJECTS`] in a row
    /// turn into a reset.
    ///
    /// **Process-noise adaptation** (innovation-based adaptive estimation, Mehra 1970; Mohamed &
    /// Schwarz 1999; off by default). The NIS per component of every position and velocity update
    /// while fixes flow is averaged over about `adapt_fixes` updates (1 for a consistent filter);
    /// with `adapt_process_noise`, an average above 1.5 multiplies the IMU's process noise by the
    /// average (at most 4× per update, at most `max_q_scale` in all) and one below 0.7 divides it
    /// back towards the configured model, never below it. It rescues a model far too optimistic
    /// (on the simulated drive with every noise term 10× too small: 0.37 m instead of 0.99 m
    /// horizontal RMS), but on a real drive whose innovations come from vibration and timing
    /// rather than from the IMU's noise (drive0708) it raises the noise for nothing and the
    /// dead reckoning through outages gets worse (outage-end mean 4.8 → 10.5 m): hence opt-in.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct GnssFusion {
        /// Largest covariance scale one fix may apply (default 10⁴: an innovation up to 100× the
        /// gate's radius); 1 switches the inflation off.
        pub max_inflation: f64 = 1.0e4;
        /// Coasting without a fused position for at least this long makes the next fix eligible
        /// for inflation, s (default 2).
        pub coast_s: f64 = 2.0;
        /// Average NIS per component above which any gated fix is inflated (default 1.5).
        pub inflate_above_nis: f64 = 1.5;
        /// Length of the NIS average, updates (default 10).
        pub adapt_fixes: f64 = 10.0;
        /// Adapt the IMU's process noise when the GNSS innovations show it too optimistic.
        pub adapt_process_noise: bool = false, file "estimator", switch "adapt-noise" => true;
        /// Largest factor on the IMU's process noise (default 100: 10× its σ).
        pub max_q_scale: f64 = 100.0;
    }
}

/// A single update's NIS per component counts at most this much in the average (one outlier
/// must not move it by itself).
const NIS_AVERAGE_CAP: f64 = 10.0;

/// Feeds one update's NIS (`m` components) into the average and, when enabled, adapts the
/// IMU's process noise ([`GnssFusion`]).
fn adapt_process_noise(f: &mut DelayedFilter, fusion: &GnssFusion, state: &mut GnssState, nis: f64, m: usize) {
    if !nis.is_finite() {
        return;
    }
    state.nis_average += ((nis / m as f64).min(NIS_AVERAGE_CAP) - state.nis_average) / fusion.adapt_fixes.max(1.0);
    if !fusion.adapt_process_noise {
        return;
    }
    let avg = state.nis_average;
    if !((avg > 1.5 && f.q_scale < fusion.max_q_scale) || (avg < 0.7 && f.q_scale > 1.0)) {
        return;
    }
    let q = (f.q_scale * avg.clamp(0.5, 4.0)).clamp(1.0, fusion.max_q_scale.max(1.0));
    // The predicted innovations grow with the process noise: expect the average to follow.
    state.nis_average /= q / f.q_scale;
    f.q_scale = q;
}

/// What GNSS fusion keeps between fixes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GnssState {
    /// Fixes rejected in a row (reset after [`RESET_AFTER_REJECTS`]).
    pub consecutive_rejects: u32,
    /// Sum of the position innovations (filter minus fix, NED, m) of the fixes rejected in a
    /// row: a position reset moves by their mean.
    pub rejected_dz_sum_m: Vector3<f64>,
    /// Sum of the rejected fixes' position variances (NED, m²).
    pub rejected_var_sum_m2: Vector3<f64>,
    /// Host time of the last fix fused (or reset to), ns.
    pub last_fused_ns: i64,
    /// Fixes fused after scaling the covariance ([`GnssFusion`]).
    pub inflations: u64,
    /// Host time of the last such fix, ns.
    pub last_inflated_ns: i64,
    /// Running average of the NIS per component of the updates fused while fixes flow (1
    /// when the filter is consistent).
    pub nis_average: f64,
    /// Fixes fused (position accepted).
    pub fixes_used: u64,
    /// Fixes whose position failed the innovation gate.
    pub fixes_rejected: u64,
    /// Velocity updates that failed the gate.
    pub vel_rejected: u64,
    /// Resets to GNSS after [`RESET_AFTER_REJECTS`] consecutive rejected fixes.
    pub gnss_resets: u64,
    /// Of those, full resets: the fix's velocity disagreed with the filter too (the filter had
    /// lost consistency), so velocity was reset as well and the attitude and sensor-error
    /// uncertainty reopened. The others moved only the position (the GNSS position jumped).
    pub gnss_resets_full: u64,
}

impl Default for GnssState {
    fn default() -> Self {
        Self {
            consecutive_rejects: 0,
            rejected_dz_sum_m: Vector3::zeros(),
            rejected_var_sum_m2: Vector3::zeros(),
            last_fused_ns: 0,
            inflations: 0,
            last_inflated_ns: 0,
            nis_average: 1.0,
            fixes_used: 0,
            fixes_rejected: 0,
            vel_rejected: 0,
            gnss_resets: 0,
            gnss_resets_full: 0,
        }
    }
}

impl Measurement for GnssObservation {
    type Config = GnssFusion;
    type State = GnssState;

    /// The fix's epoch: its stamp minus the GNSS delay estimate (module docs).
    fn epoch_ns(&self, delay_s: f64) -> i64 {
        self.stamp_host_ns - (delay_s * 1e9) as i64
    }

    /// Position (gated; five rejections in a row reset to the fix), then horizontal velocity;
    /// Δ held while not observable ([`DelayedFilter::with_unobservable_delay_held`]).
    fn fuse(
        &self,
        f: &mut DelayedFilter,
        eps: f64,
        cfg: &NavConfig,
        fusion: &GnssFusion,
        state: &mut GnssState,
    ) -> bool {
        let obs = self;
        f.with_unobservable_delay_held(|f| {
            f.pos_floor_std_ned_m = obs.pos_floor_std_m;
            let t_f = obs.epoch_ns(f.delay_s);
            let (dz, h, r) = position_terms(
                &f.pva,
                &Vector3::from(cfg.gnss_lever_arm_m),
                &f.last_w,
                obs,
                eps,
                f.delay_observable(),
            );
            let mut outcome = f.eskf.update(&dz, &h, &r, cfg.gate_scale);
            let since = |t: i64| (t_f - t) as f64 * 1e-9;
            let coasted = state.last_fused_ns == 0 || since(state.last_fused_ns) >= fusion.coast_s;
            if !coasted {
                let nis = match outcome {
                    Update::Accepted { nis, .. } | Update::Rejected { nis } => nis,
                };
                adapt_process_noise(f, fusion, state, nis, 3);
            }
            if let Update::Rejected { nis } = outcome {
                let gate = crate::nav::eskf::gate_of::<3>(cfg.gate_scale);
                let recovering = state.inflations > 0 && since(state.last_inflated_ns) < fusion.coast_s
                    || state.nis_average > fusion.inflate_above_nis;
                if (coasted || recovering || state.consecutive_rejects > 0) && nis <= gate * fusion.max_inflation {
                    f.eskf.p *= nis / gate;
                    state.inflations += 1;
                    state.last_inflated_ns = t_f;
                    // Now within the gate up to R's share: fused without gating again.
                    outcome = f.eskf.update(&dz, &h, &r, f64::INFINITY);
                }
            }
            match outcome {
                Update::Accepted { dx, .. } => {
                    f.feedback(&dx, cfg.fusion_horizon_s);
                    state.fixes_used += 1;
                    state.consecutive_rejects = 0;
                    state.last_fused_ns = t_f;
                }
                Update::Rejected { .. } => {
                    state.fixes_rejected += 1;
                    if state.consecutive_rejects == 0 {
                        state.rejected_dz_sum_m = Vector3::zeros();
                        state.rejected_var_sum_m2 = Vector3::zeros();
                    }
                    state.consecutive_rejects += 1;
                    state.rejected_dz_sum_m += dz;
                    state.rejected_var_sum_m2 += obs.pos_std_m.component_mul(&obs.pos_std_m);
                    if state.consecutive_rejects < RESET_AFTER_REJECTS {
                        // A position that jumped leaves the Doppler velocity valid: it is fused on
                        // its own gate, so the dead reckoning until the reset keeps its velocity.
                        return fuse_velocity(f, obs, eps, cfg, fusion, state, coasted);
                    }
                    // Persistently rejected: did the GNSS position jump, or has the filter lost
                    // consistency? The fix's velocity against the filter's tells.
                    let vel_agrees = obs.vel_ned_mps.x.is_finite() && obs.vel_ned_mps.y.is_finite() && {
                        let (dz, h, r) = velocity_terms_of(f, cfg, obs, eps);
                        f.eskf.gate(&dz, &h, &r, cfg.gate_scale).0
                    };
                    state.gnss_resets += 1;
                    let k = f64::from(state.consecutive_rejects);
                    let (mean_dz, mean_var) = (state.rejected_dz_sum_m / k, state.rejected_var_sum_m2 / k);
                    state.consecutive_rejects = 0;
                    state.last_fused_ns = t_f;
                    if !vel_agrees {
                        reset_to(f, obs, cfg, eps);
                        state.gnss_resets_full += 1;
                        return true;
                    }
                    // The fixes rejected in a row agree on one jump (their velocities were fused, so
                    // the filter kept its velocity meanwhile): the position moves by their mean
                    // offset, known to their σ over √K.
                    shift_position(f, &mean_dz, &(mean_var / k));
                }
            }
            fuse_velocity(f, obs, eps, cfg, fusion, state, coasted);
            true
        })
    }

    fn counters(state: &GnssState, out: &mut dyn FnMut(&'static str, u64)) {
        out("gnss_inflations", state.inflations);
    }
}


/// [`velocity_terms`] of filter `f` at its last rates, with the configured lever arm.
fn velocity_terms_of(
    f: &DelayedFilter,
    cfg: &NavConfig,
    obs: &GnssObservation,
    eps: f64,
) -> (SVector<f64, 2>, SMatrix<f64, 2, N>, nalgebra::Matrix2<f64>) {
    velocity_terms(
        &f.pva,
        &Vector3::from(cfg.gnss_lever_arm_m),
        &f.last_w,
        &f.acc_ned,
        obs,
        eps,
        f.delay_observable(),
    )
}

/// Fuses the fix's horizontal velocity, gated (when it has one); true when it was fused.
fn fuse_velocity(
    f: &mut DelayedFilter,
    obs: &GnssObservation,
    eps: f64,
    cfg: &NavConfig,
    fusion: &GnssFusion,
    state: &mut GnssState,
    coasted: bool,
) -> bool {
    if !(obs.vel_ned_mps.x.is_finite() && obs.vel_ned_mps.y.is_finite()) {
        return false;
    }
    let (dz, h, r) = velocity_terms_of(f, cfg, obs, eps);
    let outcome = f.eskf.update(&dz, &h, &r, cfg.gate_scale);
    if !coasted {
        let nis = match outcome {
            Update::Accepted { nis, .. } | Update::Rejected { nis } => nis,
        };
        adapt_process_noise(f, fusion, state, nis, 2);
    }
    match outcome {
        Update::Accepted { dx, .. } => {
            f.feedback(&dx, cfg.fusion_horizon_s);
            true
        }
        Update::Rejected { .. } => {
            state.vel_rejected += 1;
            false
        }
    }
}

/// Moves the position by −`dz_ned_m` (the mean offset of the filter from the fixes rejected
/// in a row, NED, m) and sets its covariance to `var_ned_m2`, decorrelated from the other
/// states; velocity, attitude and sensor errors are kept: for a GNSS position that jumped while
/// its velocity still agrees with the inertial solution.
fn shift_position(f: &mut DelayedFilter, dz_ned_m: &Vector3<f64>, var_ned_m2: &Vector3<f64>) {
    // The innovations were formed at the filter's latitude and height: invert them there.
    let (rm, rn) = earth::radii(f.pva.lat_rad);
    let (lat, h) = (f.pva.lat_rad, f.pva.h_m);
    f.pva.lat_rad -= dz_ned_m.x / (rm + h);
    f.pva.lon_rad -= dz_ned_m.y / ((rn + h) * lat.cos());
    f.pva.h_m += dz_ned_m.z;
    for i in POS..POS + 3 {
        for j in 0..N {
            f.eskf.p[(i, j)] = 0.0;
            f.eskf.p[(j, i)] = 0.0;
        }
    }
    for i in 0..3 {
        f.eskf.p[(POS + i, POS + i)] = var_ned_m2[i];
    }
}

/// Resets position and velocity to a fix (extrapolated by ε to the filter time; vertical
/// velocity 0 ± 2 m/s when the fix has none) and their covariance to the fix's accuracy,
/// decorrelated from the other states.
fn reset_to(f: &mut DelayedFilter, obs: &GnssObservation, cfg: &NavConfig, eps: f64) {
    let c_bn = f.pva.q_nb.to_rotation_matrix().into_inner();
    let lever_n = c_bn * Vector3::from(cfg.gnss_lever_arm_m);
    let (rm, rn) = earth::radii(obs.lat_rad);
    // NMEA carries no vertical velocity: a land vehicle's is ~0, with 2 m/s of doubt.
    let v_d = if obs.vel_ned_mps.z.is_finite() {
        obs.vel_ned_mps.z
    } else {
        0.0
    };
    let v = if obs.vel_ned_mps.x.is_finite() && obs.vel_ned_mps.y.is_finite() {
        Vector3::new(obs.vel_ned_mps.x, obs.vel_ned_mps.y, v_d)
    } else {
        Vector3::new(f.pva.vel_ned_mps.x, f.pva.vel_ned_mps.y, v_d)
    };
    let p_ned = v * eps - lever_n;
    f.pva.lat_rad = obs.lat_rad + p_ned.x / (rm + obs.h_m);
    f.pva.lon_rad = obs.lon_rad + p_ned.y / ((rn + obs.h_m) * obs.lat_rad.cos());
    f.pva.h_m = obs.h_m - p_ned.z;
    f.pva.vel_ned_mps = v;
    for i in POS..ATT {
        for j in 0..N {
            f.eskf.p[(i, j)] = 0.0;
            f.eskf.p[(j, i)] = 0.0;
        }
    }
    for i in 0..3 {
        f.eskf.p[(POS + i, POS + i)] = obs.pos_std_m[i].powi(2);
        f.eskf.p[(VEL + i, VEL + i)] = obs.vel_std_mps.powi(2) + cfg.init_vel_std_mps.powi(2);
    }
    if !obs.vel_ned_mps.z.is_finite() {
        f.eskf.p[(VEL + 2, VEL + 2)] = 4.0;
    }
    // Persistent rejection means the filter was overconfident somewhere: reopen the
    // attitude and sensor-error uncertainty to their initial values so it can re-converge.
    let reopen = [
        (ATT, cfg.init_level_std_rad),
        (ATT + 1, cfg.init_level_std_rad),
        (ATT + 2, cfg.init_yaw_std_rad),
    ];
    for (i, sd) in reopen {
        f.eskf.p[(i, i)] = f.eskf.p[(i, i)].max(sd * sd);
    }
    for i in 0..3 {
        let bg = cfg.noise.gyro_bias_init_std[i].powi(2);
        let ba = cfg.noise.accel_bias_init_std[i].powi(2);
        f.eskf.p[(BG + i, BG + i)] = f.eskf.p[(BG + i, BG + i)].max(bg);
        f.eskf.p[(BA + i, BA + i)] = f.eskf.p[(BA + i, BA + i)].max(ba);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use navsync_wire::samples::{FixMode, Stamp, StampSource};

    fn fix(sats_used: u16) -> GnssFix {
        let mut f = GnssFix::empty(Stamp::host(0, 0, StampSource::Receipt));
        f.lat_deg = 48.1;
        f.lon_deg = 11.5;
        f.alt_msl_m = 520.0;
        f.hdop = 1.0;
        f.vdop = 1.5;
        f.sats_used = sats_used;
        f.mode = FixMode::Fix3d as u8;
        f
    }

    #[test]
    fn a_held_altitude_carries_no_vertical_weight() {
        let acc = GnssAccuracy::default();
        let measured = observation(&fix(7), 0, &acc).expect("usable");
        assert!((measured.pos_std_m.z - 1.5 * acc.uere_m).abs() < 1e-12);
        let held = observation(&fix(3), 0, &acc).expect("usable");
        assert_eq!(held.pos_std_m.z, HELD_ALTITUDE_STD_M);
        assert_eq!(held.pos_std_m.x, measured.pos_std_m.x, "horizontal unchanged");
        // Unknown satellite count: the altitude counts as measured.
        assert!(observation(&fix(u16::MAX), 0, &acc).unwrap().pos_std_m.z < 10.0);
    }

    /// A receiver's σ is also the floor of what persists of its error (none vertically for an
    /// altitude it held); a file's σ is a noise only.
    #[test]
    fn a_receivers_accuracy_persists_and_a_files_noise_does_not() {
        let acc = GnssAccuracy::default();
        let mut f = fix(7);
        (f.h_acc_m, f.v_acc_m, f.protocol) = (2.0, 3.0, navsync_wire::samples::GNSS_PROTOCOL_UBX);
        let o = observation(&f, 0, &acc).expect("usable");
        assert_eq!(o.pos_floor_std_m, o.pos_std_m);
        let held = observation(&fix(3), 0, &acc).expect("usable");
        assert_eq!(held.pos_floor_std_m, Vector3::new(held.pos_std_m.x, held.pos_std_m.y, 0.0));
        f.protocol = GNSS_PROTOCOL_FILE;
        assert_eq!(observation(&f, 0, &acc).unwrap().pos_floor_std_m, Vector3::zeros());
    }

    #[test]
    fn the_receivers_accuracy_estimates_are_its_noise_and_its_flags_are_honoured() {
        let acc = GnssAccuracy::default();
        let mut f = fix(20);
        (f.h_acc_m, f.v_acc_m, f.s_acc_mps) = (0.014, 0.010, 0.028);
        let o = observation(&f, 0, &acc).expect("usable");
        assert!((o.pos_std_m.x - 0.014 / std::f64::consts::SQRT_2).abs() < 1e-12 && o.pos_std_m.z == 0.010);
        assert!((o.vel_std_mps - 0.028 / std::f64::consts::SQRT_2).abs() < 1e-12);
        f.fix_flags = FIX_FLAG_RECEIVER_INVALID;
        assert!(
            observation(&f, 0, &acc).is_none(),
            "the receiver's own validity (gnssFixOK)"
        );
        f.fix_flags = FIX_FLAG_INVALID_LLH;
        assert!(observation(&f, 0, &acc).is_none(), "invalidLlh");
        f.fix_flags = FIX_FLAG_NOT_GNSS;
        assert!(observation(&f, 0, &acc).is_none(), "HNR-PVT is the receiver's blend");
    }

    /// The Δ column and the ε extrapolation are the antenna's velocity, lever-arm rotation
    /// included: the antenna of a robot at 0.5 m/s turning 7.5°/s with its antenna 0.47 m off
    /// the IMU, moved by the body's own motion over ε (its position after ε, by a rotation of
    /// the body, not linearised) is what the terms predict.
    #[test]
    fn the_delay_column_is_the_antennas_velocity() {
        let pva = Pva {
            lat_rad: 0.6,
            lon_rad: 2.0,
            h_m: 100.0,
            vel_ned_mps: Vector3::new(-0.14, -0.46, 0.0),
            q_nb: nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, 253f64.to_radians()),
        };
        let lever = Vector3::new(-0.325, -0.342, -0.896);
        let w_b = Vector3::new(0.0, 0.0, 7.5f64.to_radians());
        let mut obs = observation(&fix(9), 0, &GnssAccuracy::default()).expect("usable");
        (obs.lat_rad, obs.lon_rad, obs.h_m) = (pva.lat_rad, pva.lon_rad, pva.h_m);
        let (_, h, _) = position_terms(&pva, &lever, &w_b, &obs, 0.0, true);
        let c_bn = pva.q_nb.to_rotation_matrix().into_inner();
        let v_ant = pva.vel_ned_mps + c_bn * w_b.cross(&lever);
        assert!((h.fixed_view::<3, 1>(0, DELAY) - v_ant).norm() < 1e-12);
        assert!(c_bn * w_b.cross(&lever) != Vector3::zeros());
        // The antenna ε later: the body turned by ω·ε, the IMU moved by v·ε.
        let eps = 0.01;
        let turned = c_bn * nalgebra::Rotation3::from_scaled_axis(w_b * eps).into_inner() * lever;
        let moved = pva.vel_ned_mps * eps + turned - c_bn * lever;
        let (dz0, _, _) = position_terms(&pva, &lever, &w_b, &obs, 0.0, true);
        let (dz1, _, _) = position_terms(&pva, &lever, &w_b, &obs, eps, true);
        assert!(((dz0 - dz1) - moved).norm() < 1e-6, "{} vs {}", dz0 - dz1, moved);
    }
}
