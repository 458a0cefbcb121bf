//! Strapdown inertial mechanization in the local-level NED frame on WGS-84.
//!
//! Increment-based, as in KF-GINS (`insmech.cpp`, Wuhan University) after Savage,
//! *Strapdown Analytics* (2000) and Shin & El-Sheimy (2004): the IMU delivers angle increments
//! Δθ = ∫ω_ib^b dt and velocity increments Δv = ∫f^b dt over each sample interval, and the
//! update uses the current and the previous increment pair for the two-sample coning and
//! sculling corrections. Order: velocity, then position, then attitude, each with mid-interval
//! earth quantities (KF-GINS does the same).
//!
//! Notation: C_b^n body(FRD)→NED, ω_ie^n earth rate, ω_en^n transport rate, g^n = [0, 0, γ].

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use navsync_wire::earth;

/// One IMU interval as increments in the body frame (FRD).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuIncrement {
    /// Interval length, s.
    pub dt_s: f64,
    /// Angle increment ∫ω_ib^b dt, rad.
    pub dtheta_rad: Vector3<f64>,
    /// Velocity increment ∫f^b dt, m/s.
    pub dvel_mps: Vector3<f64>,
}

impl ImuIncrement {
    /// Increments from interval-average rate (rad/s) and specific force (m/s²).
    pub fn from_rates(dt_s: f64, gyro_rps: Vector3<f64>, accel_mps2: Vector3<f64>) -> Self {
        Self {
            dt_s,
            dtheta_rad: gyro_rps * dt_s,
            dvel_mps: accel_mps2 * dt_s,
        }
    }

    /// A zero-length interval (used as the "previous" increment before the first sample).
    pub fn zero() -> Self {
        Self {
            dt_s: 0.0,
            dtheta_rad: Vector3::zeros(),
            dvel_mps: Vector3::zeros(),
        }
    }
}

/// Position, velocity and attitude of the body frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pva {
    /// Geodetic latitude, rad.
    pub lat_rad: f64,
    /// Longitude, rad.
    pub lon_rad: f64,
    /// Height above the WGS-84 ellipsoid, m.
    pub h_m: f64,
    /// Velocity in NED, m/s.
    pub vel_ned_mps: Vector3<f64>,
    /// Attitude: rotation body(FRD) → NED (v^n = q_nb · v^b).
    pub q_nb: UnitQuaternion<f64>,
}

impl Pva {
    /// Roll, pitch, yaw (ZYX Euler angles of C_b^n), rad.
    pub fn rpy_rad(&self) -> Vector3<f64> {
        let (r, p, y) = self.q_nb.euler_angles();
        Vector3::new(r, p, y)
    }
}

/// Earth quantities at one position/velocity.
struct EarthAt {
    rm: f64,
    rn: f64,
    w_ie: Vector3<f64>,
    w_en: Vector3<f64>,
    g: Vector3<f64>,
}

/// The position-dependent earth quantities of one step, evaluated once at the step's start.
/// Within a step (≤ 10 ms) latitude and height change by < 1e−7 rad and a few cm, which moves
/// radii, earth rate and gravity by < 1e−9 relative; only the velocity-dependent transport rate
/// is re-evaluated at the mid-points the algorithm asks for.
struct EarthCache {
    h: f64,
    tan_lat: f64,
    rm: f64,
    rn: f64,
    w_ie: Vector3<f64>,
    g: Vector3<f64>,
}

impl EarthCache {
    fn new(lat: f64, h: f64) -> Self {
        let (rm, rn) = earth::radii(lat);
        let (sl, cl) = lat.sin_cos();
        Self {
            h,
            tan_lat: sl / cl,
            rm,
            rn,
            w_ie: Vector3::new(earth::OMEGA_IE * cl, 0.0, -earth::OMEGA_IE * sl),
            g: Vector3::new(0.0, 0.0, earth::normal_gravity(lat, h)),
        }
    }

    /// Earth quantities with the transport rate for velocity `v` (Groves eq. 5.44).
    fn at(&self, v: &Vector3<f64>) -> EarthAt {
        let (rmh, rnh) = (self.rm + self.h, self.rn + self.h);
        EarthAt {
            rm: self.rm,
            rn: self.rn,
            w_ie: self.w_ie,
            w_en: Vector3::new(v.y / rnh, -v.x / rmh, -v.y * self.tan_lat / rnh),
            g: self.g,
        }
    }
}

/// Skew-symmetric (cross-product) matrix, [a×] b = a × b.
pub fn skew(a: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -a.z, a.y, a.z, 0.0, -a.x, -a.y, a.x, 0.0)
}

/// Velocity change in NED over one interval with earth quantities `e` and mid-interval
/// velocity `v_mid` (Savage 2000 eq. 7.2.2.2-…; KF-GINS `velUpdate`):
/// Δv^n = [I − ½ζ×] C_b^n(k−1) Δv_sf + [g^n − (2ω_ie^n + ω_en^n) × v^n] Δt, ζ = (ω_ie^n + ω_en^n) Δt,
/// where Δv_sf = Δv + ½ Δθ × Δv + (Δθ_{k−1} × Δv + Δv_{k−1} × Δθ)/12 (rotation and two-sample sculling).
fn velocity_change(
    c_bn: &Matrix3<f64>,
    dv_sf: &Vector3<f64>,
    e: &EarthAt,
    v_mid: &Vector3<f64>,
    dt: f64,
) -> Vector3<f64> {
    let zeta = (e.w_ie + e.w_en) * dt;
    let dv_f = (Matrix3::identity() - skew(&zeta) * 0.5) * c_bn * dv_sf;
    let dv_g = (e.g - (2.0 * e.w_ie + e.w_en).cross(v_mid)) * dt;
    dv_f + dv_g
}

/// Advances `prev` over the interval of `cur` (whose previous interval was `pre`).
pub fn propagate(prev: &Pva, pre: &ImuIncrement, cur: &ImuIncrement) -> Pva {
    let dt = cur.dt_s;
    let c_bn = prev.q_nb.to_rotation_matrix().into_inner();

    // Specific-force velocity increment with rotation and sculling compensation.
    let dv_sf = cur.dvel_mps
        + cur.dtheta_rad.cross(&cur.dvel_mps) * 0.5
        + (pre.dtheta_rad.cross(&cur.dvel_mps) + pre.dvel_mps.cross(&cur.dtheta_rad)) / 12.0;

    // --- velocity: predict with k−1 earth quantities, then redo with the mid-point velocity.
    let earth = EarthCache::new(prev.lat_rad, prev.h_m);
    let e0 = earth.at(&prev.vel_ned_mps);
    let v_mid0 = prev.vel_ned_mps + velocity_change(&c_bn, &dv_sf, &e0, &prev.vel_ned_mps, dt) * 0.5;
    let e_mid = earth.at(&v_mid0);
    let vel = prev.vel_ned_mps + velocity_change(&c_bn, &dv_sf, &e_mid, &v_mid0, dt);

    // --- position: trapezoidal velocity (KF-GINS `posUpdate`).
    // (A velocity that moves the position far in one step is a diverged filter: the integrity
    // monitor's to catch, not a reason to stop.)
    let (lat, lon, h) = advance_position(prev, &prev.vel_ned_mps, &vel, dt, &e0);

    // --- attitude: q_nb(k) = q_nn · q_nb(k−1) · q_bb (KF-GINS `attUpdate`), with the two-sample
    // coning correction φ = Δθ + (Δθ_{k−1} × Δθ)/12 and the navigation-frame rotation
    // ζ = (ω_ie^n + ω_en^n) Δt with the mid-point velocity.
    let v_half = (prev.vel_ned_mps + vel) * 0.5;
    let e_att = earth.at(&v_half);
    let phi = cur.dtheta_rad + pre.dtheta_rad.cross(&cur.dtheta_rad) / 12.0;
    let q_bb = UnitQuaternion::from_scaled_axis(phi);
    let q_nn = UnitQuaternion::from_scaled_axis(-(e_att.w_ie + e_att.w_en) * dt);
    let q_nb = UnitQuaternion::new_normalize((q_nn * prev.q_nb * q_bb).into_inner());

    Pva {
        lat_rad: lat,
        lon_rad: lon,
        h_m: h,
        vel_ned_mps: vel,
        q_nb,
    }
}

/// Position after `dt` with the mean of `v0` and `v1` and the radii in `e`
/// (φ̇ = v_N/(R_M+h), λ̇ = v_E/((R_N+h) cos φ), ḣ = −v_D; Groves eq. 5.56).
fn advance_position(p: &Pva, v0: &Vector3<f64>, v1: &Vector3<f64>, dt: f64, e: &EarthAt) -> (f64, f64, f64) {
    let v = (v0 + v1) * 0.5;
    let h = p.h_m - v.z * dt;
    let h_mid = 0.5 * (p.h_m + h);
    let lat = p.lat_rad + v.x / (e.rm + h_mid) * dt;
    let lat_mid = 0.5 * (p.lat_rad + lat);
    let lon = p.lon_rad + v.y / ((e.rn + h_mid) * lat_mid.cos()) * dt;
    (lat, lon, h)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A body at rest, level, heading north, senses −g on the down axis and the earth rate:
    /// integrating exactly those increments must keep it at rest.
    #[test]
    fn stationary_stays_put() {
        let lat = 30.5f64.to_radians();
        let mut p = Pva {
            lat_rad: lat,
            lon_rad: 114.3f64.to_radians(),
            h_m: 20.0,
            vel_ned_mps: Vector3::zeros(),
            q_nb: UnitQuaternion::identity(),
        };
        let g = earth::normal_gravity(lat, 20.0);
        let w = Vector3::from(earth::omega_ie_n(lat));
        let inc = ImuIncrement::from_rates(0.005, w, Vector3::new(0.0, 0.0, -g));
        let mut pre = inc;
        for _ in 0..(200 * 600) {
            p = propagate(&p, &pre, &inc);
            pre = inc;
        }
        let (rm, _) = earth::radii(lat);
        assert!(
            (p.lat_rad - lat).abs() * rm < 0.05,
            "north drift {}",
            (p.lat_rad - lat) * rm
        );
        assert!((p.h_m - 20.0).abs() < 0.05, "height {}", p.h_m);
        assert!(p.vel_ned_mps.norm() < 1e-3, "velocity {:?}", p.vel_ned_mps);
        assert!(p.rpy_rad().norm() < 1e-6, "attitude {:?}", p.rpy_rad());
    }

    /// Constant yaw rate at rest about the down axis: the yaw must advance by rate × time.
    #[test]
    fn yaw_rotation_integrates() {
        let lat = 0.0;
        let mut p = Pva {
            lat_rad: lat,
            lon_rad: 0.0,
            h_m: 0.0,
            vel_ned_mps: Vector3::zeros(),
            q_nb: UnitQuaternion::identity(),
        };
        let g = earth::normal_gravity(lat, 0.0);
        let rate = 10f64.to_radians();
        let w_ie = Vector3::from(earth::omega_ie_n(lat));
        let mut pre = ImuIncrement::zero();
        for _ in 0..400 {
            // Earth rate in body axes rotates with the body; at the equator it is along north.
            let yaw = p.rpy_rad().z;
            let w_b = Vector3::new(w_ie.x * yaw.cos(), -w_ie.x * yaw.sin(), rate);
            let inc = ImuIncrement::from_rates(0.005, w_b, Vector3::new(0.0, 0.0, -g));
            p = propagate(&p, &pre, &inc);
            pre = inc;
        }
        assert!(
            (p.rpy_rad().z - 20f64.to_radians()).abs() < 1e-4,
            "yaw {}",
            p.rpy_rad().z.to_degrees()
        );
    }
}
