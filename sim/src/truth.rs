//! The exact state of the simulated world at one instant, for tests and evaluation.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use navsync_shared::samples::{MAX_IMUS, SimTruth};

use super::inverse_mechanization::{InertialState, inertial_state};
use super::trajectory::{Kinematics, Trajectory, wrap_pi};

/// Kinematic and inertial truth of the body frame at one UTC instant. Frames: NED navigation
/// frame, FRD body frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthState {
    /// The instant, UTC ns since 1970.
    pub utc_ns: i64,
    /// Scenario time, s since the start.
    pub t_s: f64,
    /// Geodetic latitude (WGS-84), rad.
    pub lat_rad: f64,
    /// Longitude, rad, wrapped to (−π, π].
    pub lon_rad: f64,
    /// Height above the ellipsoid, m.
    pub height_m: f64,
    /// Velocity w.r.t. the earth, NED, m/s.
    pub v_ned: Vector3<f64>,
    /// dv_ned/dt, m/s².
    pub a_ned: Vector3<f64>,
    /// Roll, pitch, yaw, rad (yaw in (−π, π]).
    pub rpy_rad: [f64; 3],
    /// Body-to-NED DCM C_b^n.
    pub c_b_n: Matrix3<f64>,
    /// Body-to-NED attitude quaternion q_b^n.
    pub q_b_n: UnitQuaternion<f64>,
    /// Body rate w.r.t. NED, body axes, rad/s.
    pub omega_nb_b: Vector3<f64>,
    /// Body rate w.r.t. inertial space, body axes, rad/s (what a body-aligned gyro reads).
    pub omega_ib_b: Vector3<f64>,
    /// Specific force at the body origin, body axes, m/s² (what a body-aligned accelerometer
    /// at the origin reads).
    pub f_ib_b: Vector3<f64>,
    /// Earth rate in NED, rad/s.
    pub omega_ie_n: Vector3<f64>,
    /// Transport rate in NED, rad/s.
    pub omega_en_n: Vector3<f64>,
    /// Normal gravity γ(φ, h), m/s².
    pub gravity_mps2: f64,
}

impl TruthState {
    /// The truth at UTC `utc_ns`, scenario time `t_s` (clamped to the scenario).
    pub fn at(traj: &Trajectory, utc_ns: i64, t_s: f64) -> Self {
        let k = traj.kinematics(t_s);
        Self::from_parts(utc_ns, &k, &inertial_state(&k))
    }

    fn from_parts(utc_ns: i64, k: &Kinematics, s: &InertialState) -> Self {
        Self {
            utc_ns,
            t_s: k.t_s,
            lat_rad: k.lat_rad,
            lon_rad: wrap_pi(k.lon_rad),
            height_m: k.height_m,
            v_ned: k.v_ned,
            a_ned: k.a_ned,
            rpy_rad: k.rpy_rad(),
            c_b_n: k.c_b_n,
            q_b_n: k.q_b_n(),
            omega_nb_b: k.omega_nb_b,
            omega_ib_b: s.omega_ib_b,
            f_ib_b: s.f_ib_b,
            omega_ie_n: s.omega_ie_n,
            omega_en_n: s.omega_en_n,
            gravity_mps2: s.gravity_mps2,
        }
    }
}

/// Fields of [`SimTruth`] that do not depend on the instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthConstants {
    /// Nominal NMEA output latency d0, s.
    pub gnss_latency_s: f64,
    /// IMU stamp offsets relative to IMU 0, s.
    pub imu_offset_s: [f64; MAX_IMUS],
    /// Number of IMUs.
    pub imu_count: u8,
}

/// Builds a [`SimTruth`] record; `rate_error` is d(UTC)/d(host) − 1 = 1/(1 + y) − 1.
pub fn sim_truth(state: &TruthState, host_ns: i64, seq: u64, freq_error_y: f64, c: &TruthConstants) -> SimTruth {
    SimTruth {
        host_ns,
        utc_ns: state.utc_ns,
        seq,
        rate_error: 1.0 / (1.0 + freq_error_y) - 1.0,
        lat_deg: state.lat_rad.to_degrees(),
        lon_deg: state.lon_rad.to_degrees(),
        height_m: state.height_m,
        vel_ned_mps: [state.v_ned[0], state.v_ned[1], state.v_ned[2]],
        acc_ned_mps2: [state.a_ned[0], state.a_ned[1], state.a_ned[2]],
        rpy_rad: state.rpy_rad,
        gnss_latency_s: c.gnss_latency_s,
        imu_offset_s: c.imu_offset_s,
        imu_count: c.imu_count,
        reserved: [0; 7],
    }
}
