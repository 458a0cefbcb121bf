//! WGS-84 Earth-centred, Earth-fixed (ECEF) coordinates to geodetic ones, for receivers that
//! report their solution in ECEF only (UBX-NAV-SOL): the conversion lives in
//! `navsync_shared::earth` (the GNSS models use it too); its tests are here.

pub use navsync_shared::earth::{Geodetic, geodetic_from_ecef, ned_from_ecef_velocity};

#[cfg(test)]
mod tests {
    use super::*;

    /// Geodetic → ECEF (closed form), to check the inverse.
    fn ecef(lat_deg: f64, lon_deg: f64, h: f64) -> (f64, f64, f64) {
        let [x, y, z] = navsync_shared::earth::geodetic_to_ecef(lat_deg.to_radians(), lon_deg.to_radians(), h);
        (x, y, z)
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
