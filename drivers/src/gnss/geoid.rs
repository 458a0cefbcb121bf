//! The geoid: the separation N between the WGS-84 ellipsoid and mean sea level (EGM96), for
//! receivers that report no height above sea level (u-blox NAV-SOL: an ECEF position only).
//!
//! **Model.** EGM96 (NIMA TR8350.2, 3rd ed., 1997, with the Rapp height-anomaly-to-undulation
//! correction term), evaluated from its spherical-harmonic coefficients to degree and order 360
//! by the `egm96` crate (a port of NGA's reference program F477; zlib licence): the model
//! itself, not an interpolated grid. gpsd instead interpolates bilinearly in a 5° grid of
//! EGM2008, which is off by metres in rugged terrain: a grid that coarse does not meet 1 m.
//!
//! **Cache.** The full expansion costs about a millisecond, so [`GeoidCache`] evaluates it at
//! the centre of the 0.001° cell (≤ 79 m from any point of it) the position falls in and
//! reuses it while the receiver stays in that cell. The geoid's slope (the deflection of the
//! vertical) is below 1′ ≈ 0.3 mm/m almost everywhere, so the cache adds at most ~0.03 m;
//! `cached_value_stays_within_5_cm_of_the_model` measures it on random points. Total error
//! against EGM96: ≤ 0.05 m; EGM96 itself describes mean sea level to about 1 m (NIMA's
//! stated global accuracy), which is the limit of any MSL height navsync derives.
//!
//! The first evaluation on a thread allocates the expansion's scratch arrays (once, kept);
//! nothing is allocated afterwards.

/// Edge of the cache cell, degrees.
pub const CELL_DEG: f64 = 1e-3;

/// EGM96 geoid undulation N at geodetic `lat_deg`, `lon_deg` (WGS-84), m: ellipsoidal height
/// = height above mean sea level + N. `None` for a position that is not finite or not on the
/// globe.
pub fn egm96_separation_m(lat_deg: f64, lon_deg: f64) -> Option<f64> {
    if !(lat_deg.abs() <= 90.0 && lon_deg.abs() <= 360.0) {
        return None;
    }
    let n = egm96::egm96_compute_altitude_offset(lat_deg, lon_deg);
    // EGM96 undulations lie within −107 m … +86 m.
    (n.abs() < 200.0).then_some(n)
}

/// [`egm96_separation_m`] with the value of the last 0.001° cell kept (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GeoidCache {
    /// The cell (latitude, longitude in units of [`CELL_DEG`]) and its undulation, m.
    last: Option<((i64, i64), f64)>,
    /// Full evaluations of the model so far.
    evaluations: u64,
}

impl GeoidCache {
    /// The undulation at the centre of the cell of (`lat_deg`, `lon_deg`), m.
    pub fn separation_m(&mut self, lat_deg: f64, lon_deg: f64) -> Option<f64> {
        if !(lat_deg.abs() <= 90.0 && lon_deg.abs() <= 360.0) {
            return None;
        }
        // Both within ±360 000 cells: the casts are exact.
        let key = ((lat_deg / CELL_DEG).round() as i64, (lon_deg / CELL_DEG).round() as i64);
        if let Some((k, n)) = self.last
            && k == key
        {
            return Some(n);
        }
        let n = egm96_separation_m(key.0 as f64 * CELL_DEG, key.1 as f64 * CELL_DEG)?;
        self.evaluations += 1;
        self.last = Some((key, n));
        Some(n)
    }

    /// Full evaluations of the model so far.
    pub fn evaluations(&self) -> u64 {
        self.evaluations
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn agrees_with_nga_reference_values() {
        // NGA's EGM96 test points for F477 (INPUT.DAT → OUTF477.DAT: latitude, longitude,
        // undulation to the millimetre), within 5 mm (the published values are NGA's; the
        // crate's arithmetic differs from F477's in the last digits).
        for (lat, lon, n) in [
            (38.628_155, 269.779_155, -31.628),
            (-14.621_217, 305.021_114, -2.969),
            (46.874_319, 102.448_729, -43.575),
            (-23.617_446, 133.874_712, 15.871),
            (38.625_473, 359.999_500, 50.066),
            (-0.466_744, 0.002_300, 17.329),
        ] {
            let ours = egm96_separation_m(lat, lon).unwrap();
            assert!((ours - n).abs() < 0.005, "{lat} {lon}: NGA {n} ours {ours}");
        }
        assert_eq!(egm96_separation_m(f64::NAN, 0.0), None);
        assert_eq!(egm96_separation_m(91.0, 0.0), None);
    }

    #[test]
    fn cached_value_stays_within_5_cm_of_the_model() {
        // Random points, each with a neighbour in the same cell: the cached value against the
        // model evaluated at the point itself.
        let mut x = 0x9E37_79B9_7F4A_7C15_u64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut cache = GeoidCache::default();
        let mut worst = 0.0f64;
        for _ in 0..60 {
            let lat = next() * 170.0 - 85.0;
            let lon = next() * 360.0 - 180.0;
            for (dlat, dlon) in [(0.0, 0.0), (0.000_49, -0.000_49)] {
                let (la, lo) = (lat + dlat, lon + dlon);
                let cached = cache.separation_m(la, lo).unwrap();
                let exact = egm96_separation_m(la, lo).unwrap();
                worst = worst.max((cached - exact).abs());
            }
        }
        assert!(worst < 0.05, "cache error {worst} m");
        assert!(cache.evaluations() <= 120);
        // Same cell: no new evaluation.
        let before = cache.evaluations();
        cache.separation_m(46.404_6, -117.020_4);
        cache.separation_m(46.404_62, -117.020_41);
        assert_eq!(cache.evaluations(), before + 1);
    }
}
