//! Initial alignment: roll and pitch by levelling the averaged accelerometers while static,
//! the gyro bias from the static average minus the earth rate, position and velocity from the
//! fix; the heading is left to the bank of heading hypotheses
//! ([`super::heading_bank`]), which starts on this alignment: at once after a levelling, else
//! once a fix shows motion (its hypotheses then start on the course).
//!
//! Levelling (Groves 2013 eq. 5.101): at rest f^b = C_n^b [0, 0, −g], so
//! θ = atan2(f_x, √(f_y² + f_z²)) and φ = atan2(−f_y, −f_z).

use nalgebra::{UnitQuaternion, Vector3};
use navsync_wire::earth;

use super::config::AlignConfig;
use super::imu_buffer::ImuRecord;
use super::measurements::gnss::GnssObservation;
use super::mechanization::Pva;

/// Result of the alignment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Alignment {
    /// Initial position, velocity and attitude at the fix's time.
    pub pva: Pva,
    /// Gyro bias from the static average, rad/s (zero without a static period).
    pub gyro_bias: Vector3<f64>,
    /// Whether roll and pitch came from a static levelling (else assumed level).
    pub levelled: bool,
    /// Static time averaged, s.
    pub static_s: f64,
    /// NED acceleration at the fix, from the velocities of the last two fixes, m/s² (zero
    /// when unknown); it couples the initial velocity error to the GNSS delay.
    pub acc_ned: Vector3<f64>,
    /// 1-sigma of the velocity as the fix gave it, m/s (∞ when unknown): a velocity
    /// differenced from noisy positions carries their noise.
    pub vel_std_mps: f64,
    /// Started standing after a levelling (the IMU static): the velocity is zero to within the
    /// configured initial σ, which the fix's velocity refines by its own σ.
    pub standing: bool,
    /// The fix's stamp minus the instant the accelerometer-integrated speed reached the fix's
    /// speed, and its 1-sigma, s: a first estimate of the GNSS delay (None without a static
    /// start; see [`Aligner::delay_from_onset`]).
    pub delay_from_onset_s: Option<(f64, f64)>,
}

/// Accumulates the static period and produces the [`Alignment`].
#[derive(Debug, Clone, Default)]
pub struct Aligner {
    cfg: AlignConfig,
    sum_f: Vector3<f64>,
    sum_w: Vector3<f64>,
    time_s: f64,
    in_static: bool,
    /// Stamp (ns) and horizontal velocity of the previous fix.
    prev_fix: Option<(i64, Vector3<f64>)>,
    /// Forward speed integrated from the accelerometers since the vehicle started moving.
    onset: Option<Onset>,
}

/// Smallest 1-sigma of the motion-onset estimate of the GNSS delay, s (the speed noise of a fix,
/// ~0.05 m/s, over a drive-off acceleration of ~1 m/s²).
pub const ONSET_DELAY_FLOOR_S: f64 = 0.05;

/// Points kept of the speed profile after motion onset (10 s at 50 Hz).
const ONSET_POINTS: usize = 500;
/// Spacing of the speed-profile points, ns.
const ONSET_STEP_NS: i64 = 20_000_000;

/// The speed profile after motion onset, from the accelerometers alone.
///
/// While a car stands still its forward specific force is f̄_x = g·sin θ + b_x; when it drives off
/// with the same pitch, f_x − f̄_x is its forward acceleration with the bias cancelled, so
/// v(t) = ∫ (f_x − f̄_x) dt needs no alignment. Comparing v(t) with the speed of the first moving
/// fix tells when that fix's epoch was: the GNSS delay before the filter has any estimate.
#[derive(Debug, Clone)]
struct Onset {
    /// Mean specific force of the static period before the motion, m/s² (body axes).
    f_ref: Vector3<f64>,
    speed: f64,
    last_point_ns: i64,
    points: Box<[(i64, f64)]>,
    len: usize,
}

impl Aligner {
    /// An aligner with thresholds `cfg`.
    pub fn new(cfg: AlignConfig) -> Self {
        Self {
            cfg,
            ..Default::default()
        }
    }

    /// Adds one IMU interval. A new static period after motion restarts the average.
    pub fn on_imu(&mut self, r: &ImuRecord) {
        self.track_onset(r);
        // Static: small rates, and |f| ≈ g (first second) or f close to the static mean so far
        // (|f| alone changes only to second order with a horizontal acceleration). Normal
        // gravity at 45° latitude: the |f| tolerance covers 9.78–9.83 m/s².
        let g = earth::normal_gravity(std::f64::consts::FRAC_PI_4, 0.0);
        let accel_still = match self.onset.as_ref() {
            Some(o) => (r.accel_mps2 - o.f_ref).norm() < self.cfg.static_accel_dev_mps2,
            None => (r.accel_mps2.norm() - g).abs() < self.cfg.static_accel_mps2,
        };
        let still = r.gyro_rps.norm() < self.cfg.static_gyro_rps && accel_still;
        if still {
            if !self.in_static {
                // A new static period: restart the averages (the onset profile is re-armed once
                // the new period has lasted a second).
                self.sum_f = Vector3::zeros();
                self.sum_w = Vector3::zeros();
                self.time_s = 0.0;
                self.in_static = true;
            }
            self.sum_f += r.accel_mps2 * r.dt_s;
            self.sum_w += r.gyro_rps * r.dt_s;
            self.time_s += r.dt_s;
        } else {
            self.in_static = false;
        }
    }

    fn track_onset(&mut self, r: &ImuRecord) {
        if self.in_static && self.time_s > 1.0 {
            // Still (or just starting): (re)arm the profile with the latest static mean.
            self.onset = Some(Onset {
                f_ref: self.sum_f / self.time_s,
                speed: 0.0,
                last_point_ns: r.host_ns,
                points: self
                    .onset
                    .take()
                    .map_or_else(|| vec![(0, 0.0); ONSET_POINTS].into_boxed_slice(), |o| o.points),
                len: 0,
            });
        }
        if let Some(o) = &mut self.onset {
            o.speed += (r.accel_mps2.x - o.f_ref.x) * r.dt_s;
            if r.host_ns - o.last_point_ns >= ONSET_STEP_NS && o.len < ONSET_POINTS {
                o.points[o.len] = (r.host_ns, o.speed);
                o.len += 1;
                o.last_point_ns = r.host_ns;
            }
        }
    }

    /// Host time (ns) at which the accelerometer-integrated speed first reached `speed_mps`.
    /// Host time (ns) at which the accelerometer-integrated speed first reached `speed_mps`,
    /// and the acceleration there (m/s², over ±0.1 s).
    fn onset_time_of(&self, speed_mps: f64) -> Option<(i64, f64)> {
        let o = self.onset.as_ref()?;
        let pts = &o.points[..o.len];
        let i = pts.iter().position(|p| p.1 >= speed_mps)?;
        if i == 0 {
            return None;
        }
        let ((t0, v0), (t1, v1)) = (pts[i - 1], pts[i]);
        let t = t0 + ((speed_mps - v0) / (v1 - v0) * (t1 - t0) as f64) as i64;
        let (a, b) = (pts[i.saturating_sub(5)], pts[(i + 5).min(pts.len() - 1)]);
        let accel = (b.1 - a.1) / ((b.0 - a.0) as f64 * 1e-9).max(1e-3);
        Some((t, accel))
    }

    /// The fix's stamp minus the instant the accelerometer-integrated speed reached the fix's
    /// speed, s: a first estimate of the GNSS delay once the vehicle moves, with its 1-sigma:
    /// the σ of the fix's speed (`speed_std_mps`: its measured velocity's, or that of a
    /// difference of noisy positions) over the acceleration there, at least `floor_s` (`None`
    /// without a static start, before the speed is reached, or without an acceleration).
    pub fn delay_from_onset(&self, obs: &GnssObservation, speed_std_mps: f64, floor_s: f64) -> Option<(f64, f64)> {
        let (t, accel) = self.onset_time_of(obs.speed_mps)?;
        (accel > 0.0).then(|| {
            let sigma_v = if speed_std_mps.is_nan() { 0.1 } else { speed_std_mps };
            ((obs.stamp_host_ns - t) as f64 * 1e-9, (sigma_v / accel).max(floor_s))
        })
    }

    /// Seconds of static data averaged so far.
    pub fn static_s(&self) -> f64 {
        self.time_s
    }

    /// Forgets the previous fix (its stamp is on a time base no longer in force).
    pub fn forget_fixes(&mut self) {
        self.prev_fix = None;
    }

    /// Roll and pitch from the static average, rad, if there is one.
    pub fn level(&self) -> Option<(f64, f64)> {
        (self.time_s > 0.5).then(|| {
            let f = self.sum_f / self.time_s;
            ((-f.y).atan2(-f.z), f.x.atan2((f.y * f.y + f.z * f.z).sqrt()))
        })
    }

    /// The alignment on a fix after a levelling or while `moving` (the caller's test: the fix's
    /// speed at least `align_min_speed_mps` and clear of its noise, or a displacement), or
    /// `None` (the fix is remembered for the acceleration); `speed_std_mps` is the σ of the
    /// fix's speed (its velocity's σ, and for the motion-onset estimate of the delay).
    pub fn try_align(&mut self, obs: &GnssObservation, speed_std_mps: f64, moving: bool) -> Option<Alignment> {
        // A fix with speed and track but no velocity (a receiver or file without one): the
        // horizontal velocity along the track.
        let mut v = obs.vel_ned_mps;
        if !(v.x.is_finite() && v.y.is_finite()) && obs.speed_mps.is_finite() && obs.track_rad.is_finite() {
            v.x = obs.speed_mps * obs.track_rad.cos();
            v.y = obs.speed_mps * obs.track_rad.sin();
        }
        let prev = self.prev_fix.replace((obs.stamp_host_ns, Vector3::new(v.x, v.y, 0.0)));
        let acc_ned = match prev {
            Some((t, pv)) if obs.stamp_host_ns > t && obs.stamp_host_ns - t <= 2_000_000_000 && v.x.is_finite() => {
                (Vector3::new(v.x, v.y, 0.0) - pv) / ((obs.stamp_host_ns - t) as f64 * 1e-9)
            }
            _ => Vector3::zeros(),
        };
        // Moving: the heading hypotheses start on the course. Standing after a levelling: they
        // start now (their heading is decided once the motion shows it), so the static
        // period already estimates the sensor errors.
        let moving = moving && obs.track_rad.is_finite();
        let standing = self.in_static && self.level().is_some() && !moving;
        if !((moving || standing) && v.x.is_finite() && v.y.is_finite()) {
            return None;
        }
        let vel_std_mps = if speed_std_mps.is_nan() {
            f64::INFINITY
        } else {
            speed_std_mps
        };
        let (roll, pitch, levelled) = match self.level() {
            Some((r, p)) => (r, p, true),
            None => (0.0, 0.0, false),
        };
        let course = if moving { obs.track_rad } else { 0.0 };
        let q_nb = UnitQuaternion::from_euler_angles(roll, pitch, course);
        let gyro_bias = if levelled {
            let w_ie_b = q_nb.inverse() * Vector3::from(earth::omega_ie_n(obs.lat_rad));
            self.sum_w / self.time_s - w_ie_b
        } else {
            Vector3::zeros()
        };
        let vd = if v.z.is_finite() { v.z } else { 0.0 };
        Some(Alignment {
            pva: Pva {
                lat_rad: obs.lat_rad,
                lon_rad: obs.lon_rad,
                h_m: obs.h_m,
                vel_ned_mps: Vector3::new(v.x, v.y, vd),
                q_nb,
            },
            gyro_bias,
            levelled,
            static_s: self.time_s,
            acc_ned: if acc_ned.iter().all(|a| a.is_finite()) {
                acc_ned
            } else {
                Vector3::zeros()
            },
            vel_std_mps,
            standing: !moving,
            delay_from_onset_s: self.delay_from_onset(obs, speed_std_mps, ONSET_DELAY_FLOOR_S),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_a_tilted_body() {
        let (roll, pitch) = (3f64.to_radians(), -2f64.to_radians());
        let q = UnitQuaternion::from_euler_angles(roll, pitch, 1.0);
        let g = earth::normal_gravity(0.78, 0.0);
        let f_b = q.inverse() * Vector3::new(0.0, 0.0, -g);
        let mut a = Aligner::new(AlignConfig::default());
        for _ in 0..400 {
            a.on_imu(&ImuRecord {
                host_ns: 0,
                dt_s: 0.005,
                gyro_rps: Vector3::zeros(),
                accel_mps2: f_b,
            });
        }
        let (r, p) = a.level().unwrap();
        assert!((r - roll).abs() < 1e-9 && (p - pitch).abs() < 1e-9, "{r} {p}");
    }

    /// After a levelling, a fix the caller does not find moving starts standing (its speed and
    /// σ handed on for the navigator's static prior), one it finds moving on its course.
    #[test]
    fn a_standing_start_and_a_moving_one() {
        let g = earth::normal_gravity(0.78, 0.0);
        let mut a = Aligner::new(AlignConfig::default());
        for k in 0..1000 {
            a.on_imu(&ImuRecord {
                host_ns: k * 5_000_000,
                dt_s: 0.005,
                gyro_rps: Vector3::zeros(),
                accel_mps2: Vector3::new(0.0, 0.0, -g),
            });
        }
        let obs = GnssObservation {
            stamp_host_ns: 5_000_000_000,
            lat_rad: 0.78,
            lon_rad: 0.1,
            h_m: 50.0,
            vel_ned_mps: Vector3::repeat(f64::NAN),
            pos_std_m: Vector3::new(1.8, 1.8, 3.6),
            vel_std_mps: f64::NAN,
            speed_mps: 17.9,
            track_rad: 1.0,
            pos_floor_std_m: Vector3::zeros(),
        };
        let standing = a.try_align(&obs, 25.0, false).expect("a levelled start");
        assert!(standing.standing && standing.vel_std_mps == 25.0);
        assert_eq!(standing.pva.q_nb.euler_angles().2, 0.0);
        let moving = a.try_align(&obs, 0.05, true).expect("a moving start");
        assert!(!moving.standing && moving.vel_std_mps == 0.05);
        assert!((moving.pva.vel_ned_mps.xy().norm() - 17.9).abs() < 1e-9);
        assert!((moving.pva.q_nb.euler_angles().2 - 1.0).abs() < 1e-9);
    }
}
