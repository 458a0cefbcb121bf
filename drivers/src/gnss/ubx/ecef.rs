//! WGS-84 Earth-centred, Earth-fixed (ECEF) coordinates to geodetic ones, for receivers that
//! report their solution in ECEF only (UBX-NAV-SOL).
//!
//! The conversion iterates the geodetic latitude to convergence (NIMA TR8350.2 ellipsoid; the
//! height formula `p·cos φ + z·sin φ − a·√(1 − e²·sin² φ)` holds at the poles too), exact to
//! well below the centimetre resolution of the input.

/// WGS-84 semi-major axis, m.
const A_M: f64 = 6_378_137.0;
/// WGS-84 flattening.
const F: f64 = 1.0 / 298.257_223_563;
/// First eccentricity squared.
const E2: f64 = F * (2.0 - F);

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
/// 1 km of the Earth's centre (a receiver's "no solution" zeros) or a non-finite one.
pub fn geodetic_from_ecef(x_m: f64, y_m: f64, z_m: f64) -> Option<Geodetic> {
    if !(x_m.is_finite() && y_m.is_finite() && z_m.is_finite()) || x_m.hypot(y_m).hypot(z_m) < 1_000.0 {
        return None;
    }
    let p = x_m.hypot(y_m);
    let lon = y_m.atan2(x_m);
    let mut lat = z_m.atan2(p * (1.0 - E2));
    for _ in 0..8 {
        let (s, c) = lat.sin_cos();
        let n = A_M / (1.0 - E2 * s * s).sqrt();
        let height = p * c + z_m * s - A_M * (1.0 - E2 * s * s).sqrt();
        let next = z_m.atan2(p * (1.0 - E2 * n / (n + height)));
        let done = (next - lat).abs() < 1e-15;
        lat = next;
        if done {
            break;
        }
    }
    let (s, c) = lat.sin_cos();
    let height = p * c + z_m * s - A_M * (1.0 - E2 * s * s).sqrt();
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

    /// Geodetic → ECEF (closed form), to check the inverse.
    fn ecef(lat_deg: f64, lon_deg: f64, h: f64) -> (f64, f64, f64) {
        let (s, c) = lat_deg.to_radians().sin_cos();
        let (sl, cl) = lon_deg.to_radians().sin_cos();
        let n = A_M / (1.0 - E2 * s * s).sqrt();
        ((n + h) * c * cl, (n + h) * c * sl, (n * (1.0 - E2) + h) * s)
    }

    #[test]
    fn round_trips_everywhere() {
        for lat in [-90.0, -89.9999, -45.877, 0.0, 20.6293, 44.0688, 89.99999, 90.0] {
            for lon in [-180.0, -117.02, 0.0, 5.8, 138.6, 179.9] {
                for h in [-420.0, 0.0, 1_110.23, 35_786_000.0] {
                    let (x, y, z) = ecef(lat, lon, h);
                    let g = geodetic_from_ecef(x, y, z).unwrap();
                    assert!((g.lat_deg - lat).abs() < 1e-11, "{lat} {lon} {h}: {g:?}");
                    if lat.abs() < 90.0 {
                        let dl = (g.lon_deg - lon + 540.0).rem_euclid(360.0) - 180.0;
                        assert!(dl.abs() < 1e-11, "{lat} {lon} {h}: {g:?}");
                    }
                    assert!((g.height_m - h).abs() < 1e-6, "{lat} {lon} {h}: {g:?}");
                }
            }
        }
    }

    #[test]
    fn reference_point() {
        // A NAV-SOL of the navisys-gr701w capture (Lewiston, ID).
        let g = geodetic_from_ecef(-2_001_691.83, -3_925_074.28, 4_596_546.16).unwrap();
        assert!((g.lat_deg - 46.404_642_08).abs() < 1e-8, "{g:?}");
        assert!((g.lon_deg + 117.020_468_876).abs() < 1e-8, "{g:?}");
        assert!((g.height_m - 232.9593).abs() < 1e-3, "{g:?}");
        assert_eq!(geodetic_from_ecef(0.0, 0.0, 0.0), None);
        assert_eq!(geodetic_from_ecef(f64::NAN, 0.0, 7e6), None);
    }

    #[test]
    fn velocity_rotation() {
        // Straight up at the equator / prime meridian is +X.
        let [n, e, d] = ned_from_ecef_velocity(0.0, 0.0, 1.0, 0.0, 0.0);
        assert!(n.abs() < 1e-15 && e.abs() < 1e-15 && (d + 1.0).abs() < 1e-15);
        // East at longitude 90° is −X; north at the equator is +Z.
        let [n, e, _] = ned_from_ecef_velocity(0.0, 90.0, -2.0, 0.0, 3.0);
        assert!((n - 3.0).abs() < 1e-12 && (e - 2.0).abs() < 1e-12);
    }
}
