//! The WGS-84 earth model shared by the simulator and the estimator: radii of
//! curvature, normal gravity, earth rotation and transport rate in the NED frame.
//!
//! Formulas follow Groves, *Principles of GNSS, Inertial, and Multisensor Integrated
//! Navigation Systems*, 2nd ed. (2013), §2.4 and §2.4.7, in the forms used by KF-GINS
//! (`earth.h`). Angles in rad, lengths in m, rates in rad/s.

/// WGS-84 semi-major axis, m.
pub const WGS84_A: f64 = 6_378_137.0;
/// WGS-84 flattening.
pub const WGS84_F: f64 = 1.0 / 298.257_223_563;
/// WGS-84 first eccentricity squared, e² = f(2 − f).
pub const WGS84_E2: f64 = WGS84_F * (2.0 - WGS84_F);
/// Earth rotation rate ω_ie, rad/s.
pub const OMEGA_IE: f64 = 7.292_115_146_7e-5;

/// Meridian radius R_M and prime-vertical radius R_N at latitude `lat_rad`, m
/// (Groves eq. 2.105–2.106): R_N = a/√(1−e²sin²φ), R_M = a(1−e²)/(1−e²sin²φ)^{3/2}.
pub fn radii(lat_rad: f64) -> (f64, f64) {
    let s = lat_rad.sin();
    let w = 1.0 - WGS84_E2 * s * s;
    let rn = WGS84_A / w.sqrt();
    let rm = WGS84_A * (1.0 - WGS84_E2) / (w * w.sqrt());
    (rm, rn)
}

/// Normal gravity magnitude at latitude `lat_rad` and ellipsoidal height `h_m`, m/s²:
/// Somigliana's formula with the second-order free-air correction (as in KF-GINS
/// `Earth::gravity`).
pub fn normal_gravity(lat_rad: f64, h_m: f64) -> f64 {
    let s2 = lat_rad.sin().powi(2);
    let g0 = 9.780_326_771_5 * (1.0 + 0.005_279_041_4 * s2 + 0.000_023_271_8 * s2 * s2);
    g0 - (3.087_691_089e-6 - 4.397_731e-9 * s2) * h_m + 0.721e-12 * h_m * h_m
}

/// Earth rotation expressed in NED, ω_ie^n = [ω cosφ, 0, −ω sinφ] rad/s (Groves eq. 2.123).
pub fn omega_ie_n(lat_rad: f64) -> [f64; 3] {
    [OMEGA_IE * lat_rad.cos(), 0.0, -OMEGA_IE * lat_rad.sin()]
}

/// Transport rate ω_en^n = [v_E/(R_N+h), −v_N/(R_M+h), −v_E tanφ/(R_N+h)] rad/s
/// (Groves eq. 5.44) for NED velocity `v_ned` in m/s.
pub fn omega_en_n(lat_rad: f64, h_m: f64, v_ned: [f64; 3]) -> [f64; 3] {
    let (rm, rn) = radii(lat_rad);
    [
        v_ned[1] / (rn + h_m),
        -v_ned[0] / (rm + h_m),
        -v_ned[1] * lat_rad.tan() / (rn + h_m),
    ]
}

/// Geodetic → ECEF, m (Groves eq. 2.112).
pub fn geodetic_to_ecef(lat_rad: f64, lon_rad: f64, h_m: f64) -> [f64; 3] {
    let (_, rn) = radii(lat_rad);
    let (sl, cl) = lat_rad.sin_cos();
    let (so, co) = lon_rad.sin_cos();
    [
        (rn + h_m) * cl * co,
        (rn + h_m) * cl * so,
        ((1.0 - WGS84_E2) * rn + h_m) * sl,
    ]
}

/// NED offset of point 2 from point 1, m, through ECEF (exact for any distance; the NED
/// axes are those at point 1).
pub fn ned_between(lat1: f64, lon1: f64, h1: f64, lat2: f64, lon2: f64, h2: f64) -> [f64; 3] {
    let a = geodetic_to_ecef(lat1, lon1, h1);
    let b = geodetic_to_ecef(lat2, lon2, h2);
    let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let (sl, cl) = lat1.sin_cos();
    let (so, co) = lon1.sin_cos();
    [
        -sl * co * d[0] - sl * so * d[1] + cl * d[2],
        -so * d[0] + co * d[1],
        -cl * co * d[0] - cl * so * d[1] - sl * d[2],
    ]
}

/// A geodetic position on the WGS-84 ellipsoid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geodetic {
    /// Latitude, degrees north.
    pub lat_deg: f64,
    /// Longitude, degrees east.
    pub lon_deg: f64,
    /// Height above the ellipsoid, m.
    pub height_m: f64,
}

/// The geodetic position of the ECEF point (`x_m`, `y_m`, `z_m`); `None` for a point within
/// 1 km of the Earth's centre (a receiver's "no solution" zeros) or a non-finite one. Iterates
/// the geodetic latitude to convergence (NIMA TR8350.2 ellipsoid; the height formula
/// `p·cos φ + z·sin φ − a·√(1 − e²·sin² φ)` holds at the poles too), exact to well below a
/// centimetre.
pub fn geodetic_from_ecef(x_m: f64, y_m: f64, z_m: f64) -> Option<Geodetic> {
    if !(x_m.is_finite() && y_m.is_finite() && z_m.is_finite()) || x_m.hypot(y_m).hypot(z_m) < 1_000.0 {
        return None;
    }
    let p = x_m.hypot(y_m);
    let lon = y_m.atan2(x_m);
    let mut lat = z_m.atan2(p * (1.0 - WGS84_E2));
    for _ in 0..8 {
        let (s, c) = lat.sin_cos();
        let n = WGS84_A / (1.0 - WGS84_E2 * s * s).sqrt();
        let height = p * c + z_m * s - WGS84_A * (1.0 - WGS84_E2 * s * s).sqrt();
        let next = z_m.atan2(p * (1.0 - WGS84_E2 * n / (n + height)));
        let done = (next - lat).abs() < 1e-15;
        lat = next;
        if done {
            break;
        }
    }
    let (s, c) = lat.sin_cos();
    let height = p * c + z_m * s - WGS84_A * (1.0 - WGS84_E2 * s * s).sqrt();
    Some(Geodetic {
        lat_deg: lat.to_degrees(),
        lon_deg: lon.to_degrees(),
        height_m: height,
    })
}

/// The ECEF velocity (`vx`, `vy`, `vz`, m/s) in the local north-east-down frame at
/// (`lat_deg`, `lon_deg`): `[north, east, down]`, m/s.
pub fn ned_from_ecef_velocity(lat_deg: f64, lon_deg: f64, vx: f64, vy: f64, vz: f64) -> [f64; 3] {
    let (sin_lat, cos_lat) = lat_deg.to_radians().sin_cos();
    let (sin_lon, cos_lon) = lon_deg.to_radians().sin_cos();
    let north = -vx * sin_lat * cos_lon - vy * sin_lat * sin_lon + vz * cos_lat;
    let east = -vx * sin_lon + vy * cos_lon;
    let up = vx * cos_lat * cos_lon + vy * cos_lat * sin_lon + vz * sin_lat;
    [north, east, -up]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gravity_and_radii_reference_values() {
        // Equator and pole normal gravity (WGS-84 γ_e = 9.7803253359, γ_p = 9.8321849378).
        assert!((normal_gravity(0.0, 0.0) - 9.780_325).abs() < 1e-5);
        assert!((normal_gravity(std::f64::consts::FRAC_PI_2, 0.0) - 9.832_185).abs() < 1e-4);
        let (rm, rn) = radii(0.0);
        assert!((rn - WGS84_A).abs() < 1e-6);
        assert!((rm - 6_335_439.327).abs() < 1e-2);
    }

    #[test]
    fn ned_between_small_offsets() {
        let lat = 30f64.to_radians();
        let (rm, rn) = radii(lat);
        let d = ned_between(lat, 0.5, 10.0, lat + 100.0 / rm, 0.5 + 50.0 / (rn * lat.cos()), 7.0);
        assert!((d[0] - 100.0).abs() < 0.01 && (d[1] - 50.0).abs() < 0.01 && (d[2] - 3.0).abs() < 0.01);
    }
}
