//! A navigation state between two states: the interpolation the history of states
//! (`navsync_shared::history`) answers `state_at` queries with, and the estimator its event
//! poses, so both give the same answer for the same two states.
//!
//! Between the records `a` and `b` around the instant, `τ = (t − t_a)/h`, `h = t_b − t_a`:
//!
//! - position: cubic Hermite (the basis `h00 = 2τ³ − 3τ² + 1`, `h10 = τ³ − 2τ² + τ`,
//!   `h01 = −2τ³ + 3τ²`, `h11 = τ³ − τ²`; e.g. Kincaid & Cheney, *Numerical Analysis*, §6.3)
//!   on `a`'s and `b`'s positions with their NED velocities as the end slopes, in a local NED
//!   frame at `a` (north = Δφ·(R_M + h_a), east = Δλ·(R_N + h_a)·cos φ_a, down = −Δh, undone
//!   the same way): exact for a constant acceleration (a quadratic is a cubic);
//! - velocity: linear, i.e. a constant acceleration `(v_b − v_a)/h` over the interval (the
//!   derivative of the position polynomial would add the position's noise to the velocity);
//! - attitude: slerp of the quaternions (Shoemake, "Animating rotation with quaternion
//!   curves", SIGGRAPH 1985) along the shorter arc, roll/pitch/yaw from the result;
//! - σ's and UTC: linear; the answer carries the [`Source`] and status of both records.

use crate::earth;
use crate::samples::NavState;

/// Where a record's state comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Source {
    /// The real-time predictor's state, as published on `navsync/nav/state`.
    Predicted = 1,
    /// The delayed filter's state once it fused that instant (all the measurements up to it).
    Fused = 2,
}

impl Source {
    /// The source of byte `v` (`None`: not a source).
    pub fn from_u8(v: u8) -> Option<Self> {
        match v {
            1 => Some(Self::Predicted),
            2 => Some(Self::Fused),
            _ => None,
        }
    }
}

/// Where the body is and how it moves at one instant, with the σ's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Latitude, degrees.
    pub lat_deg: f64,
    /// Longitude, degrees.
    pub lon_deg: f64,
    /// Height above the ellipsoid, m.
    pub height_m: f64,
    /// NED velocity, m/s.
    pub vel_ned_mps: [f64; 3],
    /// Attitude quaternion body→NED, [w, x, y, z].
    pub q_nb: [f64; 4],
    /// Roll, pitch, yaw (ZYX) of `q_nb`, rad.
    pub rpy_rad: [f64; 3],
    /// 1-σ position, NED, m.
    pub pos_std_ned_m: [f64; 3],
    /// 1-σ velocity, NED, m/s.
    pub vel_std_ned_mps: [f64; 3],
    /// 1-σ attitude, rad.
    pub att_std_rad: [f64; 3],
}

/// One state of the history (a copy out of shared memory).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Record {
    /// The record's index (records written before it).
    pub index: u64,
    /// Host time (`CLOCK_MONOTONIC` ns) of the state.
    pub host_ns: i64,
    /// UTC, ns since 1970 (`i64::MIN` while time is not known).
    pub utc_ns: i64,
    /// Position, velocity, attitude and their σ.
    pub pose: Pose,
    /// Angular rate, body FRD, rad/s.
    pub gyro_body_rps: [f64; 3],
    /// Where the state comes from (`None`: an unknown source byte).
    pub source: Option<Source>,
    /// The state's `NavStatus` as `u8`.
    pub status: u8,
    /// The state's `TimeStatus` as `u8`.
    pub time_status: u8,
    /// The state's integrity flags.
    pub integrity: u8,
}

impl Record {
    /// The record of `s` from `source`.
    pub fn of(s: &NavState, source: Source) -> Self {
        Self {
            index: 0,
            host_ns: s.host_ns,
            utc_ns: s.utc_ns,
            pose: Pose {
                lat_deg: s.lat_deg,
                lon_deg: s.lon_deg,
                height_m: s.height_m,
                vel_ned_mps: s.vel_ned_mps,
                q_nb: s.q_nb,
                rpy_rad: s.rpy_rad,
                pos_std_ned_m: s.pos_std_ned_m,
                vel_std_ned_mps: s.vel_std_ned_mps,
                att_std_rad: s.att_std_rad,
            },
            gyro_body_rps: s.gyro_body_rps,
            source: Some(source),
            status: s.status,
            time_status: s.time_status,
            integrity: s.integrity,
        }
    }
}

/// A state interpolated between two records of the history.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interpolated {
    /// The host instant, ns.
    pub host_ns: i64,
    /// Its UTC, ns since 1970 (`i64::MIN` when a record around it has none).
    pub utc_ns: i64,
    /// Position, velocity, attitude and their σ, interpolated.
    pub pose: Pose,
    /// Where the records before and after the instant come from.
    pub sources: [Option<Source>; 2],
    /// Their `NavStatus`es.
    pub status: [u8; 2],
    /// Their host times, ns.
    pub bracket_host_ns: [i64; 2],
    /// `τ = (t − t_a)/(t_b − t_a)`.
    pub fraction: f64,
}

fn lerp(a: f64, b: f64, t: f64) -> f64 {
    a + (b - a) * t
}

fn lerp3(a: [f64; 3], b: [f64; 3], t: f64) -> [f64; 3] {
    std::array::from_fn(|i| lerp(a[i], b[i], t))
}

/// Cubic Hermite: the value at `τ` of the cubic through `p0`, `p1` with slopes `m0`, `m1`
/// (per unit of τ).
pub fn hermite(p0: f64, m0: f64, p1: f64, m1: f64, tau: f64) -> f64 {
    let (t2, t3) = (tau * tau, tau * tau * tau);
    (2.0 * t3 - 3.0 * t2 + 1.0) * p0 + (t3 - 2.0 * t2 + tau) * m0 + (-2.0 * t3 + 3.0 * t2) * p1 + (t3 - t2) * m1
}

/// Spherical linear interpolation of unit quaternions [w, x, y, z] along the shorter arc
/// (Shoemake 1985); normalised.
pub fn slerp(a: [f64; 4], b: [f64; 4], t: f64) -> [f64; 4] {
    let mut dot: f64 = a.iter().zip(b.iter()).map(|(x, y)| x * y).sum();
    let b = if dot < 0.0 {
        dot = -dot;
        b.map(|x| -x)
    } else {
        b
    };
    let (wa, wb) = if dot > 0.9995 {
        (1.0 - t, t)
    } else {
        let th = dot.clamp(-1.0, 1.0).acos();
        let s = th.sin();
        (((1.0 - t) * th).sin() / s, (t * th).sin() / s)
    };
    let q: [f64; 4] = std::array::from_fn(|i| wa * a[i] + wb * b[i]);
    let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    if n > 0.0 { q.map(|x| x / n) } else { a }
}

/// Roll, pitch, yaw (ZYX Euler) of the body→NED quaternion [w, x, y, z], rad.
pub fn rpy_of(q: [f64; 4]) -> [f64; 3] {
    let [w, x, y, z] = q;
    [
        (2.0 * (w * x + y * z)).atan2(1.0 - 2.0 * (x * x + y * y)),
        (2.0 * (w * y - z * x)).clamp(-1.0, 1.0).asin(),
        (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z)),
    ]
}

/// The state at `host_ns` between records `a` and `b` (`a` before `b`): see the
/// [module](self) documentation for the formulas. Outside `[a, b]` it extrapolates.
pub fn interpolate(a: &Record, b: &Record, host_ns: i64) -> Interpolated {
    let h = (b.host_ns - a.host_ns) as f64 * 1e-9;
    let tau = if h > 0.0 {
        (host_ns - a.host_ns) as f64 * 1e-9 / h
    } else {
        0.0
    };
    let (pa, pb) = (&a.pose, &b.pose);
    // Local NED at a.
    let lat_a = pa.lat_deg.to_radians();
    let (rm, rn) = earth::radii(lat_a);
    let (kn, ke) = (rm + pa.height_m, (rn + pa.height_m) * lat_a.cos());
    let d1 = [
        (pb.lat_deg - pa.lat_deg).to_radians() * kn,
        (pb.lon_deg - pa.lon_deg).to_radians() * ke,
        -(pb.height_m - pa.height_m),
    ];
    let p: [f64; 3] = std::array::from_fn(|i| hermite(0.0, pa.vel_ned_mps[i] * h, d1[i], pb.vel_ned_mps[i] * h, tau));
    let q_nb = slerp(pa.q_nb, pb.q_nb, tau);
    let utc_ns = if a.utc_ns == i64::MIN || b.utc_ns == i64::MIN {
        i64::MIN
    } else {
        a.utc_ns + ((b.utc_ns - a.utc_ns) as f64 * tau).round() as i64
    };
    Interpolated {
        host_ns,
        utc_ns,
        pose: Pose {
            lat_deg: pa.lat_deg + (p[0] / kn).to_degrees(),
            lon_deg: pa.lon_deg + (p[1] / ke).to_degrees(),
            height_m: pa.height_m - p[2],
            vel_ned_mps: lerp3(pa.vel_ned_mps, pb.vel_ned_mps, tau),
            q_nb,
            rpy_rad: rpy_of(q_nb),
            pos_std_ned_m: lerp3(pa.pos_std_ned_m, pb.pos_std_ned_m, tau),
            vel_std_ned_mps: lerp3(pa.vel_std_ned_mps, pb.vel_std_ned_mps, tau),
            att_std_rad: lerp3(pa.att_std_rad, pb.att_std_rad, tau),
        },
        sources: [a.source, b.source],
        status: [a.status, b.status],
        bracket_host_ns: [a.host_ns, b.host_ns],
        fraction: tau,
    }
}

/// The consecutive positions `(a, a + 1)` of a sequence of `len` records, in increasing order
/// of `key`, with `key(a) ≤ t ≤ key(a + 1)` (bisection; `None` when `t` is outside or there
/// are fewer than two). The rule the history's queries follow, so any holder of the same
/// records finds the same two.
pub fn bracket_index(len: usize, key: impl Fn(usize) -> i64, t: i64) -> Option<(usize, usize)> {
    if len < 2 {
        return None;
    }
    let (mut lo, mut hi) = (0, len - 1);
    if t > key(hi) || t < key(lo) {
        return None;
    }
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if key(mid) <= t {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some((lo, hi))
}

/// The state at UTC `utc_ns` between records `a` and `b` (both with a UTC): the host instant
/// mapped linearly between theirs, then [`interpolate`]d; the answer carries `utc_ns`.
pub fn at_utc(a: &Record, b: &Record, utc_ns: i64) -> Interpolated {
    let host_ns = if b.utc_ns == a.utc_ns {
        a.host_ns
    } else {
        let f = (utc_ns - a.utc_ns) as f64 / (b.utc_ns - a.utc_ns) as f64;
        a.host_ns + ((b.host_ns - a.host_ns) as f64 * f).round() as i64
    };
    let mut out = interpolate(a, b, host_ns);
    out.utc_ns = utc_ns;
    out
}
