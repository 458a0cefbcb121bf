//! Single-point positioning from pseudoranges of GPS, Galileo, BeiDou and GLONASS: geometry
//! (elevation, azimuth, the Earth's rotation during the signal's flight), the broadcast
//! Klobuchar ionosphere (IS-GPS-200N §20.3.3.5.2.5) scaled by (f_L1/f)² to each signal's
//! carrier (§20.3.3.3.3.2), a standard-atmosphere Saastamoinen troposphere, and a weighted
//! least-squares solution of ECEF position and one receiver clock bias per system (the
//! inter-system time offsets and biases go into those clocks, as RTKLIB's `pntpos` does;
//! Gauss-Newton on the normal equations, statically sized) with a chi-square residual check
//! on `used − unknowns` degrees of freedom that excludes the worst satellite once (RAIM-style
//! fault detection and exclusion); velocity and clock drift from Doppler by weighted least
//! squares at a known position.

use nalgebra::{Matrix3, Matrix4, SMatrix, SVector, Vector4};

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

/// The L1 ionospheric delay at zenith taken as error where no broadcast model is known, m
/// (≈ 10 m by day at mid-latitudes; RTKLIB's `ERR_ION` is 5 m).
pub const UNMODELLED_IONO_ZENITH_M: f64 = 10.0;

/// Variance of what the atmosphere models leave in a pseudorange, m²: half the broadcast
/// ionosphere's delay `iono_m` (the Klobuchar model corrects about half of the delay,
/// IS-GPS-200 §20.3.3.5.2.5) and 0.3 m of the troposphere's at zenith, mapped with
/// 1/(sin el + 0.1) — RTKLIB's `ERR_BRDCI` and `ERR_SAAS` (T. Takasu, RTKLIB 2.4.2 manual,
/// Appendix E.6; `pntpos.c`). Both change over minutes and across the sky, not per epoch.
/// Without a broadcast model (`iono_m` `None`) the whole delay is error:
/// [`UNMODELLED_IONO_ZENITH_M`] × `iono_scale` (f_L1/f)² / sin el.
pub fn atmosphere_var_m2(iono_m: Option<f64>, iono_scale: f64, el_rad: f64) -> f64 {
    const IONO_RESIDUAL: f64 = 0.5;
    const TROPO_ZENITH_M: f64 = 0.3;
    let iono_var = match iono_m {
        Some(d) => (IONO_RESIDUAL * d).powi(2),
        None => (iono_scale * UNMODELLED_IONO_ZENITH_M / el_rad.sin().max(0.1)).powi(2),
    };
    iono_var + (TROPO_ZENITH_M / (el_rad.max(0.0).sin() + 0.1)).powi(2)
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

/// The systems [`solve`] keeps a receiver clock for, in this order (u-blox `gnssId`):
/// GPS, Galileo, BeiDou, GLONASS.
pub const SYSTEMS: [u8; 4] = [0, 2, 3, 6];
/// Systems, hence receiver clocks, of one solution at most.
pub const MAX_SYSTEMS: usize = SYSTEMS.len();
/// Unknowns at most: position and one clock per system.
const NX: usize = 3 + MAX_SYSTEMS;
type MatX = SMatrix<f64, NX, NX>;
type VecX = SVector<f64, NX>;

/// The index of system `gnss_id` (u-blox numbering) in [`SYSTEMS`].
pub fn system_index(gnss_id: u8) -> Option<usize> {
    SYSTEMS.iter().position(|&g| g == gnss_id)
}

/// One satellite's measurement of any system, for [`solve`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SystemObservation {
    /// The measurement (satellite clock and group delay of the signal used included).
    pub obs: Observation,
    /// The system, u-blox `gnssId` (one of [`SYSTEMS`]).
    pub gnss_id: u8,
    /// (f_L1 / f)² of the signal's carrier: the L1 ionospheric delay times this is the
    /// signal's (IS-GPS-200 §20.3.3.3.3.2); 0 for an ionosphere-free combination.
    pub iono_scale: f64,
    /// What the measurement multiplies each signal's noise by: 1 for one signal,
    /// √(α₁² + α₂²) for an ionosphere-free combination α₁P₁ − α₂P₂ (≈ 3.0 for L1/L2, 2.6 for
    /// L1/L5).
    pub noise_gain: f64,
}

/// What [`solve`] needs of a measurement: [`Observation`] is GPS L1 C/A.
pub trait Measured {
    /// The measurement.
    fn observation(&self) -> &Observation;
    /// Its system's index in [`SYSTEMS`] (≥ [`MAX_SYSTEMS`]: not solved for).
    fn system(&self) -> usize;
    /// (f_L1 / f)² of its carrier.
    fn iono_scale(&self) -> f64;
}

impl Measured for Observation {
    fn observation(&self) -> &Observation {
        self
    }
    fn system(&self) -> usize {
        0
    }
    fn iono_scale(&self) -> f64 {
        1.0
    }
}

impl Measured for SystemObservation {
    fn observation(&self) -> &Observation {
        &self.obs
    }
    fn system(&self) -> usize {
        system_index(self.gnss_id).unwrap_or(MAX_SYSTEMS)
    }
    fn iono_scale(&self) -> f64 {
        self.iono_scale
    }
}

/// A position and clock solution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Solution {
    /// Receiver position, ECEF, m.
    pub ecef_m: [f64; 3],
    /// Receiver clock bias, m (c·δt): of the first system used in the order of [`SYSTEMS`]
    /// (GPS time when GPS is used).
    pub clock_bias_m: f64,
    /// Covariance of (x, y, z, c·δt), m² (the clock of `clock_bias_m`).
    pub cov: Matrix4<f64>,
    /// Satellites used.
    pub used: usize,
    /// Weighted sum of squared residuals (χ² with `used − 3 − systems` degrees of freedom).
    pub chi2: f64,
    /// The satellite excluded by the residual check, if any.
    pub excluded: Option<u8>,
    /// The system of the excluded satellite (u-blox `gnssId`; 0 when none was excluded).
    pub excluded_gnss_id: u8,
    /// Receiver clock bias of each system of [`SYSTEMS`], m (0 for a system not used).
    pub clock_biases_m: [f64; MAX_SYSTEMS],
    /// Satellites used of each system of [`SYSTEMS`].
    pub used_per_system: [usize; MAX_SYSTEMS],
}

impl Solution {
    /// Receiver clocks estimated (systems with a satellite used).
    pub fn systems(&self) -> usize {
        self.used_per_system.iter().filter(|&&n| n > 0).count()
    }

    /// Degrees of freedom of [`chi2`](Self::chi2): satellites used less the unknowns.
    pub fn dof(&self) -> usize {
        self.used.saturating_sub(3 + self.systems())
    }
}

/// Why no solution.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SppError {
    /// Fewer usable satellites than unknowns (position and one clock per system).
    #[error("{0} satellites above the mask: 3 + one per system needed")]
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

/// Solves position and one receiver clock per system from `obs` at GPS reception time
/// `t_rx_s` (s of week), starting at `init` (ECEF, m; the Earth's centre converges too):
/// [`Observation`]s are GPS L1 C/A (one clock), [`SystemObservation`]s of any of [`SYSTEMS`]
/// (others are ignored). `iono`: the broadcast model (L1 delays), if known, scaled by each
/// observation's `iono_scale`.
pub fn solve<O: Measured>(
    obs: &[O],
    iono: Option<&Klobuchar>,
    t_rx_s: f64,
    init: [f64; 3],
    settings: &SppSettings,
) -> Result<Solution, SppError> {
    let first = solve_excluding(obs, iono, t_rx_s, init, settings, None)?;
    let unknowns = 3 + first.systems();
    if first.used >= unknowns + 2 && first.chi2 > chi2_quantile(first.dof(), settings.p_false_alarm) {
        // Exclude the satellite whose removal lowers χ² the most.
        let best = (0..obs.len())
            .filter_map(|k| solve_excluding(obs, iono, t_rx_s, first.ecef_m, settings, Some(k)).ok())
            .min_by(|a, b| a.chi2.total_cmp(&b.chi2));
        if let Some(s) = best {
            return Ok(s);
        }
    }
    Ok(first)
}

fn solve_excluding<O: Measured>(
    obs: &[O],
    iono: Option<&Klobuchar>,
    t_rx_s: f64,
    init: [f64; 3],
    settings: &SppSettings,
    exclude: Option<usize>,
) -> Result<Solution, SppError> {
    let mut x = VecX::zeros();
    x.fixed_rows_mut::<3>(0).copy_from_slice(&init);
    // The previous step, m: the mask and the atmosphere apply once the position is within a
    // kilometre (elevations then within a hundredth of a degree). From the Earth's centre
    // with a receiver clock tens of km off, the first step can land hundreds of km away,
    // where a satellite low in the sky would be masked wrongly (with exactly four, no
    // solution at all).
    let mut last_step_m = f64::INFINITY;
    for _ in 0..15 {
        let rx = [x[0], x[1], x[2]];
        let geo = geodetic_from_ecef(rx[0], rx[1], rx[2]);
        let (mut n, mut b, mut used, mut chi2) = (MatX::zeros(), VecX::zeros(), 0usize, 0.0);
        let mut per_system = [0usize; MAX_SYSTEMS];
        for (k, m) in obs.iter().enumerate() {
            let (o, sys) = (m.observation(), m.system());
            if Some(k) == exclude || sys >= MAX_SYSTEMS {
                continue;
            }
            let r0 = dist(o.sat_ecef_m, rx);
            let sat = rotate_for_flight(o.sat_ecef_m, r0 / C_M_S);
            let r = dist(sat, rx);
            // Away from the solution (first iterations from the Earth's centre) every
            // satellite counts, without atmosphere or mask.
            let (mut model, mut sin_el) = (r + x[3 + sys] - C_M_S * o.sat_clock_s, 1.0);
            let mut atmosphere_var = 0.0;
            if let Some(g) = geo.filter(|g| g.height_m > -1e4 && last_step_m < 1e3) {
                let (el, az) = elevation_azimuth(rx, sat);
                if el < settings.elevation_mask_rad {
                    continue;
                }
                sin_el = el.sin();
                let (lat, lon) = (g.lat_deg.to_radians(), g.lon_deg.to_radians());
                let iono_m = iono.map(|k| C_M_S * k.delay_s(lat, lon, el, az, t_rx_s) * m.iono_scale());
                model += iono_m.unwrap_or(0.0) + troposphere_delay_m(lat, g.height_m, el);
                atmosphere_var = atmosphere_var_m2(iono_m, m.iono_scale(), el);
            }
            let w = 1.0 / ((o.sigma_zenith_m / sin_el).powi(2) + atmosphere_var);
            let mut h = VecX::zeros();
            h[0] = (rx[0] - sat[0]) / r;
            h[1] = (rx[1] - sat[1]) / r;
            h[2] = (rx[2] - sat[2]) / r;
            h[3 + sys] = 1.0;
            let v = o.pseudorange_m - model;
            n += h * h.transpose() * w;
            b += h * (w * v);
            chi2 += w * v * v;
            used += 1;
            per_system[sys] += 1;
        }
        let systems = per_system.iter().filter(|&&c| c > 0).count();
        if used < 3 + systems.max(1) {
            return Err(SppError::TooFew(used));
        }
        // A system without a satellite keeps its clock (a unit pseudo-observation of no
        // change, as RTKLIB's `pntpos` constrains it), which leaves the others' solution as is.
        for (s, _) in per_system.iter().enumerate().filter(|(_, c)| **c == 0) {
            n[(3 + s, 3 + s)] = 1.0;
        }
        let Some(cov) = n.try_inverse() else {
            return Err(SppError::NoConvergence);
        };
        let dx = cov * b;
        x += dx;
        let near = last_step_m < 1e3;
        last_step_m = dx.fixed_rows::<3>(0).norm();
        if dx.norm() < 1e-4 && near {
            let reference = per_system.iter().position(|&c| c > 0).unwrap_or(0);
            let keep = [0, 1, 2, 3 + reference];
            let cov4 = Matrix4::from_fn(|i, j| cov[(keep[i], keep[j])]);
            let mut clock_biases_m = [0.0; MAX_SYSTEMS];
            for (s, c) in clock_biases_m.iter_mut().enumerate() {
                *c = if per_system[s] > 0 { x[3 + s] } else { 0.0 };
            }
            let excluded = exclude.and_then(|k| obs.get(k));
            return Ok(Solution {
                ecef_m: [x[0], x[1], x[2]],
                clock_bias_m: x[3 + reference],
                cov: cov4,
                used,
                // The residuals after this last (tiny) step equal those before it.
                chi2,
                excluded: excluded.map(|m| m.observation().sv),
                excluded_gnss_id: excluded.map_or(0, |m| SYSTEMS.get(m.system()).copied().unwrap_or(0)),
                clock_biases_m,
                used_per_system: per_system,
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

    /// A receiver 1 km up at 40° N 105° W seeing `n` satellites spread in azimuth and
    /// elevation, each of system `systems[k % len]`, with exact pseudoranges for receiver
    /// clocks `clocks_m` (by [`SYSTEMS`] index) and the troposphere the solver models; free of
    /// the ionosphere (`iono_scale` 0, as an ionosphere-free combination would be), so that
    /// without a broadcast model the solver adds no σ for it.
    fn synthetic(n: usize, systems: &[u8], clocks_m: [f64; MAX_SYSTEMS]) -> ([f64; 3], Vec<SystemObservation>) {
        let rx = navsync_wire::earth::geodetic_to_ecef(40f64.to_radians(), (-105f64).to_radians(), 1000.0);
        let c_en = ned_from_ecef(40f64.to_radians(), (-105f64).to_radians());
        let g = geodetic_from_ecef(rx[0], rx[1], rx[2]).unwrap();
        let obs = (0..n)
            .map(|k| {
                let az = (k as f64 * 137.5f64).to_radians();
                let el = (15.0 + (k as f64 * 29.0) % 70.0).to_radians();
                let ned = [el.cos() * az.cos(), el.cos() * az.sin(), -el.sin()];
                // ECEF direction = C_e^nᵀ · NED.
                let d: Vec<f64> = (0..3).map(|j| (0..3).map(|i| c_en[(i, j)] * ned[i]).sum()).collect();
                let sat = [rx[0] + 2.2e7 * d[0], rx[1] + 2.2e7 * d[1], rx[2] + 2.2e7 * d[2]];
                let gnss_id = systems[k % systems.len()];
                let rot = rotate_for_flight(sat, dist(sat, rx) / C_M_S);
                let (e, _) = elevation_azimuth(rx, rot);
                let pr = dist(rot, rx)
                    + clocks_m[system_index(gnss_id).unwrap()]
                    + troposphere_delay_m(g.lat_deg.to_radians(), g.height_m, e);
                SystemObservation {
                    obs: Observation {
                        sv: k as u8 + 1,
                        pseudorange_m: pr,
                        sat_ecef_m: sat,
                        sat_clock_s: 0.0,
                        sigma_zenith_m: 1.0,
                    },
                    gnss_id,
                    noise_gain: 1.0,
                    iono_scale: 0.0,
                }
            })
            .collect();
        (rx, obs)
    }

    /// One receiver clock per system: GPS, Galileo and BeiDou clocks kilometres apart are each
    /// recovered, the position exactly, χ² ≈ 0 on `used − 3 − 3` degrees of freedom; the
    /// same satellites as one system (one clock) cannot fit them.
    #[test]
    fn each_system_has_its_own_receiver_clock() {
        let clocks = [150.0, -2_500.0, 7_000.0, 0.0];
        let (rx, obs) = synthetic(10, &[0, 2, 3], clocks);
        let s = solve(&obs, None, 0.0, [0.0; 3], &SppSettings::default()).unwrap();
        assert!(dist(s.ecef_m, rx) < 1e-3, "{:?} vs {rx:?}", s.ecef_m);
        for (est, truth) in s.clock_biases_m.iter().zip(&clocks).take(3) {
            assert!((est - truth).abs() < 1e-3, "{:?}", s.clock_biases_m);
        }
        assert_eq!(
            (s.used, s.systems(), s.dof(), s.used_per_system),
            (10, 3, 4, [4, 3, 3, 0])
        );
        assert_eq!(s.clock_bias_m, s.clock_biases_m[0]);
        assert!(s.chi2 < 1e-6 && s.excluded.is_none(), "χ² {}", s.chi2);
        // Without GPS the reported clock is Galileo's.
        let no_gps: Vec<_> = obs.iter().copied().filter(|o| o.gnss_id != 0).collect();
        let s = solve(&no_gps, None, 0.0, [0.0; 3], &SppSettings::default()).unwrap();
        assert!((s.clock_bias_m - clocks[1]).abs() < 1e-3 && dist(s.ecef_m, rx) < 1e-3);
        assert_eq!((s.used, s.dof()), (6, 1));
        // Five satellites of two systems: 3 + 2 unknowns, solved with 0 degrees of freedom.
        let two: Vec<_> = obs.iter().copied().filter(|o| o.gnss_id != 3).collect();
        let s = solve(&two[..5], None, 0.0, [0.0; 3], &SppSettings::default()).unwrap();
        assert!(dist(s.ecef_m, rx) < 1e-3 && s.dof() == 0);
        // Four satellites of two systems are too few.
        let r = solve(&two[..4], None, 0.0, [0.0; 3], &SppSettings::default());
        assert!(matches!(r, Err(SppError::TooFew(4))), "{r:?}");
        // Labelled as one system the clocks disagree: the fit is kilometres off.
        let one: Vec<_> = obs.iter().map(|o| SystemObservation { gnss_id: 0, ..*o }).collect();
        let s = solve(&one, None, 0.0, [0.0; 3], &SppSettings::default());
        assert!(s.is_err() || s.unwrap().chi2 > 1e4);
    }

    /// The residual check's threshold has the degrees of freedom of the unknowns: a 40 m
    /// fault on one satellite of three systems is found and excluded, the position
    /// recovered; GPS satellites as `Observation`s or as `SystemObservation`s give the same solution.
    #[test]
    fn the_residual_check_excludes_a_faulty_satellite_of_any_system() {
        let clocks = [150.0, -2_500.0, 7_000.0, 0.0];
        let (rx, mut obs) = synthetic(12, &[0, 2, 3], clocks);
        obs[7].obs.pseudorange_m += 40.0;
        let s = solve(&obs, None, 0.0, [0.0; 3], &SppSettings::default()).unwrap();
        assert_eq!((s.excluded, s.excluded_gnss_id), (Some(8), obs[7].gnss_id));
        assert!(dist(s.ecef_m, rx) < 1e-3 && s.chi2 < 1e-6 && s.used == 11);
        // 7 satellites of 3 systems: 6 unknowns, one degree of freedom: detection needs 2.
        let (_, mut few) = synthetic(7, &[0, 2, 3], clocks);
        few[1].obs.pseudorange_m += 40.0;
        let s = solve(&few, None, 0.0, [0.0; 3], &SppSettings::default()).unwrap();
        assert!(s.excluded.is_none() && s.dof() == 1 && s.chi2 > 1.0);
        // (An `Observation` is an L1 range: `iono_scale` 1.)
        let (_, gps) = synthetic(8, &[0], clocks);
        let gps: Vec<_> = gps
            .iter()
            .map(|o| SystemObservation { iono_scale: 1.0, ..*o })
            .collect();
        let plain: Vec<Observation> = gps.iter().map(|o| o.obs).collect();
        let a = solve(&plain, None, 0.0, [0.0; 3], &SppSettings::default()).unwrap();
        let b = solve(&gps, None, 0.0, [0.0; 3], &SppSettings::default()).unwrap();
        assert_eq!(a, b);
    }

    /// The ionosphere of a signal off L1 is the L1 delay times (f_L1/f)²: B3I's pseudorange
    /// carrying 1.54 × the L1 delay solves exactly when its scale says so.
    #[test]
    fn ionosphere_is_scaled_to_the_carrier() {
        let k = Klobuchar {
            alpha: [2e-8, 0.0, 0.0, 0.0],
            beta: [1e5, 0.0, 0.0, 0.0],
        };
        let (rx, mut obs) = synthetic(10, &[0, 3], [0.0, 0.0, 300.0, 0.0]);
        let g = geodetic_from_ecef(rx[0], rx[1], rx[2]).unwrap();
        let t = 50_400.0 + 105.0 / 180.0 * 43_200.0; // local afternoon at the IPP
        for o in &mut obs {
            let scale = if o.gnss_id == 3 {
                (1575.42f64 / 1268.52).powi(2)
            } else {
                1.0
            };
            let rot = rotate_for_flight(o.obs.sat_ecef_m, dist(o.obs.sat_ecef_m, rx) / C_M_S);
            let (el, az) = elevation_azimuth(rx, rot);
            let d = k.delay_s(g.lat_deg.to_radians(), g.lon_deg.to_radians(), el, az, t) * C_M_S;
            o.obs.pseudorange_m += scale * d;
            o.iono_scale = scale;
        }
        let s = solve(&obs, Some(&k), t, [0.0; 3], &SppSettings::default()).unwrap();
        assert!(dist(s.ecef_m, rx) < 1e-3, "{} m", dist(s.ecef_m, rx));
        for o in &mut obs {
            o.iono_scale = 1.0;
        }
        let s = solve(&obs, Some(&k), t, [0.0; 3], &SppSettings::default()).unwrap();
        assert!(dist(s.ecef_m, rx) > 0.05, "{} m", dist(s.ecef_m, rx));
    }
}
