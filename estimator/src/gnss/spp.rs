//! Single-point positioning from GPS L1 C/A pseudoranges: geometry (elevation, azimuth, the
//! Earth's rotation during the signal's flight), the broadcast Klobuchar ionosphere
//! (IS-GPS-200N §20.3.3.5.2.5), a standard-atmosphere Saastamoinen troposphere, and a
//! weighted least-squares solution of ECEF position and receiver clock bias (Gauss-Newton on
//! the normal equations, statically sized) with a chi-square residual check that excludes the
//! worst satellite once (RAIM-style fault detection and exclusion); velocity and clock drift
//! from Doppler by weighted least squares at a known position.

use nalgebra::{Matrix3, Matrix4, Vector4};

use super::lnav::IonoUtc;
use super::orbit::{GPS_PI, OMEGA_E_RAD_S};
use navsync_wire::earth::geodetic_from_ecef;

/// Speed of light, m/s (IS-GPS-200 §20.3.4.3).
pub const C_M_S: f64 = 299_792_458.0;

/// Elevation and azimuth (rad; azimuth clockwise from north) of `sat` seen from `rx`, both
/// ECEF, m.
pub fn elevation_azimuth(rx: [f64; 3], sat: [f64; 3]) -> (f64, f64) {
    let Some(g) = geodetic_from_ecef(rx[0], rx[1], rx[2]) else {
        return (std::f64::consts::FRAC_PI_2, 0.0);
    };
    let (sl, cl) = g.lat_deg.to_radians().sin_cos();
    let (so, co) = g.lon_deg.to_radians().sin_cos();
    let d = [sat[0] - rx[0], sat[1] - rx[1], sat[2] - rx[2]];
    let e = -so * d[0] + co * d[1];
    let n = -sl * co * d[0] - sl * so * d[1] + cl * d[2];
    let u = cl * co * d[0] + cl * so * d[1] + sl * d[2];
    let el = u.atan2(e.hypot(n));
    let az = e.atan2(n).rem_euclid(2.0 * std::f64::consts::PI);
    (el, az)
}

/// The rotation from ECEF to the local NED frame at geodetic latitude/longitude (rad), C_e^n
/// (Groves eq. 2.150): its rows are the north, east and down axes in ECEF.
pub fn ned_from_ecef(lat_rad: f64, lon_rad: f64) -> Matrix3<f64> {
    let (sl, cl) = lat_rad.sin_cos();
    let (so, co) = lon_rad.sin_cos();
    Matrix3::new(-sl * co, -sl * so, cl, -so, co, 0.0, -cl * co, -cl * so, -sl)
}

/// The satellite position at transmission (ECEF of that instant) expressed in the ECEF frame
/// of the reception `tau_s` later: rotated by ω_e·τ about z (the Sagnac correction).
pub fn rotate_for_flight(sat: [f64; 3], tau_s: f64) -> [f64; 3] {
    let (s, c) = (OMEGA_E_RAD_S * tau_s).sin_cos();
    [c * sat[0] + s * sat[1], -s * sat[0] + c * sat[1], sat[2]]
}

/// The broadcast ionosphere model (IS-GPS-200 §20.3.3.5.2.5, Figure 20-4).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Klobuchar {
    /// α_0..α_3: s, s/semicircle, s/semicircle², s/semicircle³.
    pub alpha: [f64; 4],
    /// β_0..β_3: s, s/semicircle, s/semicircle², s/semicircle³.
    pub beta: [f64; 4],
}

impl Klobuchar {
    /// The coefficients of subframe 4 page 18, scaled (IS-GPS-200 Table 20-X).
    pub fn from_page(p: &IonoUtc) -> Self {
        let a = |i: usize, e: i32| f64::from(p.alpha[i]) * 2f64.powi(e);
        let b = |i: usize, e: i32| f64::from(p.beta[i]) * 2f64.powi(e);
        Self {
            alpha: [a(0, -30), a(1, -27), a(2, -24), a(3, -24)],
            beta: [b(0, 11), b(1, 14), b(2, 16), b(3, 16)],
        }
    }

    /// L1 ionospheric delay, s, for a user at geodetic latitude/longitude (rad), a satellite
    /// at elevation/azimuth (rad), at GPS time `t_s` (s of week).
    pub fn delay_s(&self, lat_rad: f64, lon_rad: f64, el_rad: f64, az_rad: f64, t_s: f64) -> f64 {
        let e = el_rad / GPS_PI; // semicircles
        let (phi_u, lam_u) = (lat_rad / GPS_PI, lon_rad / GPS_PI);
        let psi = 0.0137 / (e + 0.11) - 0.022;
        let phi_i = (phi_u + psi * az_rad.cos()).clamp(-0.416, 0.416);
        let lam_i = lam_u + psi * az_rad.sin() / (phi_i * GPS_PI).cos();
        let phi_m = phi_i + 0.064 * ((lam_i - 1.617) * GPS_PI).cos();
        let t = (4.32e4 * lam_i + t_s).rem_euclid(86_400.0);
        let f = 1.0 + 16.0 * (0.53 - e).powi(3);
        let poly = |c: &[f64; 4]| c[0] + c[1] * phi_m + c[2] * phi_m.powi(2) + c[3] * phi_m.powi(3);
        let amp = poly(&self.alpha).max(0.0);
        let per = poly(&self.beta).max(72_000.0);
        let x = 2.0 * GPS_PI * (t - 50_400.0) / per;
        if x.abs() < 1.57 {
            f * (5e-9 + amp * (1.0 - x * x / 2.0 + x.powi(4) / 24.0))
        } else {
            f * 5e-9
        }
    }
}

/// Tropospheric delay, m: Saastamoinen's zenith delays with the standard atmosphere at
/// height `h_m` (1013.25 hPa, 15 °C and 50 % humidity at sea level), as RTKLIB's `tropmodel`,
/// mapped by 1.001/√(0.002001 + sin²el) (Black & Eisner 1984, RTCA DO-229 A.4.2.4) rather than
/// RTKLIB's 1/sin(el), which overstates the delay by 12 % at 5° (the ranging mask);
/// 0 below the horizon or for heights outside −100 m..10 km.
pub fn troposphere_delay_m(lat_rad: f64, h_m: f64, el_rad: f64) -> f64 {
    if el_rad <= 0.0 || !(-100.0..=1e4).contains(&h_m) {
        return 0.0;
    }
    let hgt = h_m.max(0.0);
    let pres = 1013.25 * (1.0 - 2.2557e-5 * hgt).powf(5.2568);
    let temp = 15.0 - 6.5e-3 * hgt + 273.16;
    let e = 6.108 * 0.5 * ((17.15 * temp - 4684.0) / (temp - 38.45)).exp();
    let zenith_h = 0.0022768 * pres / (1.0 - 0.00266 * (2.0 * lat_rad).cos() - 0.00028 * hgt / 1e3);
    let zenith_w = 0.002277 * (1255.0 / temp + 0.05) * e;
    let mapping = 1.001 / (0.002_001 + el_rad.sin().powi(2)).sqrt();
    (zenith_h + zenith_w) * mapping
}

/// One satellite's measurement for [`solve`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// Satellite (PRN).
    pub sv: u8,
    /// Pseudorange, m.
    pub pseudorange_m: f64,
    /// Satellite position at transmission, ECEF of that instant, m.
    pub sat_ecef_m: [f64; 3],
    /// Satellite clock offset at transmission (s), already including relativity and T_GD.
    pub sat_clock_s: f64,
    /// Pseudorange noise at zenith, 1σ, m (scaled by 1/sin(elevation)).
    pub sigma_zenith_m: f64,
}

/// A position and clock solution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Solution {
    /// Receiver position, ECEF, m.
    pub ecef_m: [f64; 3],
    /// Receiver clock bias, m (c·δt).
    pub clock_bias_m: f64,
    /// Covariance of (x, y, z, c·δt), m².
    pub cov: Matrix4<f64>,
    /// Satellites used.
    pub used: usize,
    /// Weighted sum of squared residuals (χ² with `used − 4` degrees of freedom).
    pub chi2: f64,
    /// The satellite excluded by the residual check, if any.
    pub excluded: Option<u8>,
}

/// Why no solution.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SppError {
    /// Fewer than four usable satellites.
    #[error("{0} satellites above the mask: 4 needed")]
    TooFew(usize),
    /// The normal equations were singular (degenerate geometry) or did not converge.
    #[error("no convergence (geometry or outliers)")]
    NoConvergence,
}

/// Settings of [`solve`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SppSettings {
    /// Elevation mask, rad (default 10°).
    pub elevation_mask_rad: f64,
    /// False-alarm probability of the residual check (default 1e-3): a χ² above its quantile
    /// excludes the satellite with the largest normalised residual, once, when ≥ 6 are used.
    pub p_false_alarm: f64,
}

impl Default for SppSettings {
    fn default() -> Self {
        Self {
            elevation_mask_rad: 10f64.to_radians(),
            p_false_alarm: 1e-3,
        }
    }
}

/// Upper quantile of χ² with `dof` degrees of freedom for probability `p` (Wilson–Hilferty).
fn chi2_quantile(dof: usize, p: f64) -> f64 {
    // Standard normal quantile (Acklam's rational approximation is overkill here: the three
    // values navsync uses are tabulated, others interpolate logarithmically).
    let z = if p <= 1e-4 {
        3.719
    } else if p <= 1e-3 {
        3.090 + (3.719 - 3.090) * (1e-3f64.ln() - p.ln()) / (1e-3f64.ln() - 1e-4f64.ln())
    } else {
        2.326 + (3.090 - 2.326) * (1e-2f64.ln() - p.ln().min(1e-2f64.ln())) / (1e-2f64.ln() - 1e-3f64.ln())
    };
    let k = dof as f64;
    k * (1.0 - 2.0 / (9.0 * k) + z * (2.0 / (9.0 * k)).sqrt()).powi(3)
}

/// Solves position and clock from `obs` at GPS reception time `t_rx_s` (s of week), starting
/// at `init` (ECEF, m; the Earth's centre converges too). `iono`: the broadcast model, if
/// known.
pub fn solve(
    obs: &[Observation],
    iono: Option<&Klobuchar>,
    t_rx_s: f64,
    init: [f64; 3],
    settings: &SppSettings,
) -> Result<Solution, SppError> {
    let first = solve_excluding(obs, iono, t_rx_s, init, settings, None)?;
    if first.used >= 6 && first.chi2 > chi2_quantile(first.used - 4, settings.p_false_alarm) {
        // Exclude the satellite whose removal lowers χ² the most.
        let best = obs
            .iter()
            .filter_map(|o| solve_excluding(obs, iono, t_rx_s, first.ecef_m, settings, Some(o.sv)).ok())
            .min_by(|a, b| a.chi2.total_cmp(&b.chi2));
        if let Some(s) = best {
            return Ok(s);
        }
    }
    Ok(first)
}

fn solve_excluding(
    obs: &[Observation],
    iono: Option<&Klobuchar>,
    t_rx_s: f64,
    init: [f64; 3],
    settings: &SppSettings,
    exclude: Option<u8>,
) -> Result<Solution, SppError> {
    let mut x = Vector4::new(init[0], init[1], init[2], 0.0);
    for iter in 0..15 {
        let rx = [x[0], x[1], x[2]];
        let geo = geodetic_from_ecef(rx[0], rx[1], rx[2]);
        let (mut n, mut b, mut used, mut chi2) = (Matrix4::zeros(), Vector4::zeros(), 0usize, 0.0);
        for o in obs.iter().filter(|o| Some(o.sv) != exclude) {
            let r0 = dist(o.sat_ecef_m, rx);
            let sat = rotate_for_flight(o.sat_ecef_m, r0 / C_M_S);
            let r = dist(sat, rx);
            // Away from the solution (first iterations from the Earth's centre) every
            // satellite counts, without atmosphere or mask.
            let (mut model, mut sin_el) = (r + x[3] - C_M_S * o.sat_clock_s, 1.0);
            if let Some(g) = geo.filter(|g| g.height_m > -1e4 && iter > 0) {
                let (el, az) = elevation_azimuth(rx, sat);
                if el < settings.elevation_mask_rad {
                    continue;
                }
                sin_el = el.sin();
                let (lat, lon) = (g.lat_deg.to_radians(), g.lon_deg.to_radians());
                if let Some(k) = iono {
                    model += C_M_S * k.delay_s(lat, lon, el, az, t_rx_s);
                }
                model += troposphere_delay_m(lat, g.height_m, el);
            }
            let w = (sin_el / o.sigma_zenith_m).powi(2);
            let h = Vector4::new((rx[0] - sat[0]) / r, (rx[1] - sat[1]) / r, (rx[2] - sat[2]) / r, 1.0);
            let v = o.pseudorange_m - model;
            n += h * h.transpose() * w;
            b += h * (w * v);
            chi2 += w * v * v;
            used += 1;
        }
        if used < 4 {
            return Err(SppError::TooFew(used));
        }
        let Some(cov) = n.try_inverse() else {
            return Err(SppError::NoConvergence);
        };
        let dx = cov * b;
        x += dx;
        if dx.norm() < 1e-4 && iter > 0 {
            return Ok(Solution {
                ecef_m: [x[0], x[1], x[2]],
                clock_bias_m: x[3],
                cov,
                used,
                // The residuals after this last (tiny) step equal those before it.
                chi2,
                excluded: exclude,
            });
        }
    }
    Err(SppError::NoConvergence)
}

/// One satellite's Doppler for [`solve_velocity`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangeRate {
    /// Satellite (PRN).
    pub sv: u8,
    /// Measured range rate, m/s: −λ_L1 × Doppler (Hz), λ_L1 = c / 1575.42 MHz.
    pub range_rate_mps: f64,
    /// Satellite position and velocity at transmission, ECEF, m and m/s.
    pub sat_ecef_m: [f64; 3],
    /// See `sat_ecef_m`.
    pub sat_vel_mps: [f64; 3],
    /// Satellite clock drift, s/s.
    pub sat_clock_drift: f64,
    /// Range-rate noise, 1σ, m/s.
    pub sigma_mps: f64,
}

/// A velocity and clock-drift solution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VelocitySolution {
    /// Receiver velocity, ECEF, m/s.
    pub vel_ecef_mps: [f64; 3],
    /// Receiver clock drift, m/s (c·δṫ).
    pub clock_drift_mps: f64,
    /// Covariance of (v_x, v_y, v_z, c·δṫ), m²/s².
    pub cov: Matrix4<f64>,
    /// Satellites used.
    pub used: usize,
}

/// Receiver velocity and clock drift from range rates, at the receiver position `rx` (ECEF, m):
/// ρ̇ = (v_sat − v_rx)·u + c·(δṫ_rx − δṫ_sat), u the unit vector receiver → satellite, solved
/// by weighted least squares (linear: one step).
pub fn solve_velocity(obs: &[RangeRate], rx: [f64; 3], settings: &SppSettings) -> Result<VelocitySolution, SppError> {
    let (mut n, mut b, mut used) = (Matrix4::zeros(), Vector4::zeros(), 0usize);
    for o in obs {
        let r0 = dist(o.sat_ecef_m, rx);
        let sat = rotate_for_flight(o.sat_ecef_m, r0 / C_M_S);
        let (el, _) = elevation_azimuth(rx, sat);
        if el < settings.elevation_mask_rad {
            continue;
        }
        let r = dist(sat, rx);
        let u = [(sat[0] - rx[0]) / r, (sat[1] - rx[1]) / r, (sat[2] - rx[2]) / r];
        let vs = rotate_for_flight(o.sat_vel_mps, r0 / C_M_S);
        let known = vs[0] * u[0] + vs[1] * u[1] + vs[2] * u[2] - C_M_S * o.sat_clock_drift;
        let h = Vector4::new(-u[0], -u[1], -u[2], 1.0);
        let w = (el.sin() / o.sigma_mps).powi(2);
        n += h * h.transpose() * w;
        b += h * (w * (o.range_rate_mps - known));
        used += 1;
    }
    if used < 4 {
        return Err(SppError::TooFew(used));
    }
    let cov = n.try_inverse().ok_or(SppError::NoConvergence)?;
    let x = cov * b;
    Ok(VelocitySolution {
        vel_ecef_mps: [x[0], x[1], x[2]],
        clock_drift_mps: x[3],
        cov,
        used,
    })
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn geometry_and_atmosphere_are_sane() {
        let rx = navsync_wire::earth::geodetic_to_ecef(0.0, 0.0, 0.0);
        // Straight up.
        let (el, _) = elevation_azimuth(rx, [rx[0] + 2e7, 0.0, 0.0]);
        assert!((el - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
        // Due north on the horizon-ish.
        let (el, az) = elevation_azimuth(rx, [rx[0], 0.0, 2e7]);
        assert!(el.abs() < 0.8 && az.abs() < 1e-9, "el {el} az {az}");
        // Zenith troposphere at sea level ≈ 2.4 m, more at low elevation.
        let z = troposphere_delay_m(0.7, 0.0, std::f64::consts::FRAC_PI_2);
        assert!((2.2..2.6).contains(&z), "zenith {z} m");
        assert!(troposphere_delay_m(0.7, 0.0, 10f64.to_radians()) > 5.0 * z);
        // Night-time Klobuchar is the 5 ns floor times the obliquity F = 1 + 16(0.53 − E)³.
        let k = Klobuchar {
            alpha: [1e-8, 0.0, 0.0, 0.0],
            beta: [1e5, 0.0, 0.0, 0.0],
        };
        let night = k.delay_s(0.0, 0.0, std::f64::consts::FRAC_PI_2, 0.0, 0.0);
        assert!((night - 5e-9 * (1.0 + 16.0 * 0.03f64.powi(3))).abs() < 1e-15, "{night}");
        assert!(k.delay_s(0.0, 0.0, std::f64::consts::FRAC_PI_2, 0.0, 50_400.0) > 1e-8);
        assert!((chi2_quantile(4, 1e-3) - 18.47).abs() < 0.3);
    }
}
