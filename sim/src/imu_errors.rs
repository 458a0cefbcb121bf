//! IMU sensor error models and the presets of the two IMU classes the project targets.
//!
//! Per IMU and per axis (sensor frame), the output is
//!
//! ```text
//! y = Q( sat( (1 + s)·x + b0 + b_GM(t) + w ) )
//! ```
//!
//! with x the true average rate (or specific force) over the sample interval, s a constant
//! scale-factor error, b0 a constant (turn-on) bias, b_GM a first-order Gauss–Markov bias
//! instability, w white noise, sat the full-scale clamp and Q the output quantization.
//!
//! - White noise: a rate-noise density N (°/s/√Hz ≡ ARW in °/√s; µg/√Hz ≡ VRW in (m/s)/√s)
//!   gives on the average over T = 1/rate the standard deviation σ = N/√T = N·√rate
//!   (IEEE Std 952-1997 Annex C; Groves 2013 §4.4.3, eq. 4.20).
//! - Bias instability: b_k = φ b_{k−1} + σ_GM √(1 − φ²) ξ_k, φ = exp(−T/τ_c) (Groves §14.2.7,
//!   eq. 14.83 in discrete form), started in its stationary distribution. The Allan deviation
//!   of such a process peaks at 0.6174 σ_GM near τ = 1.89 τ_c, so σ_GM is chosen as the
//!   datasheet's in-run bias stability (the minimum of the Allan deviation curve) divided by
//!   0.6174: the model's ADEV then touches the datasheet floor.
//!
//! Unit conversions used below: 1 °/√h = (π/180)/60 rad/√s; 1 °/s/√Hz = π/180 rad/s/√Hz;
//! 1 m/s/√h = 1/60 (m/s)/√s; 1 µg/√Hz = 9.80665e-6 (m/s²)/√Hz; 1 °/h = (π/180)/3600 rad/s.

use super::rng::Rng;

pub use navsync_shared::imu_spec::{
    G0, GM_ADEV_PEAK_RATIO, ImuErrorSpec, ImuPreset, SensorErrorSpec, arw_deg_per_sqrt_h, deg_per_h, deg_per_s,
    dps_per_sqrt_hz, micro_g, milli_g, ug_per_sqrt_hz, vrw_mps_per_sqrt_h,
};

/// The error state of one triad of one IMU (constant draws and the Gauss–Markov state).
#[derive(Debug, Clone)]
pub struct SensorErrorState {
    spec: SensorErrorSpec,
    /// Constant bias per axis, rad/s or m/s².
    pub bias: [f64; 3],
    /// Scale-factor error per axis, fraction.
    pub scale_factor: [f64; 3],
    /// Current Gauss–Markov bias per axis, rad/s or m/s².
    pub gm_bias: [f64; 3],
    phi: f64,
    gm_drive: f64,
    white: f64,
}

impl SensorErrorState {
    /// Draws the constant errors and the initial (stationary) Gauss–Markov bias for a triad
    /// sampled every `period_s`.
    pub fn new(spec: SensorErrorSpec, period_s: f64, rng: &mut Rng) -> Self {
        let bias = rng.gaussian3([spec.bias_sigma; 3]);
        let scale_factor = rng.gaussian3([spec.scale_factor_sigma; 3]);
        let gm_bias = rng.gaussian3([spec.bias_instability_sigma; 3]);
        let phi = (-period_s / spec.bias_correlation_s).exp();
        let gm_drive = spec.bias_instability_sigma * (1.0 - phi * phi).sqrt();
        Self {
            spec,
            bias,
            scale_factor,
            gm_bias,
            phi,
            gm_drive,
            white: spec.white_sigma(period_s),
        }
    }

    /// The triad's output for true averaged input `x`; true when an axis saturated.
    /// Advances the bias instability by one sample.
    pub fn apply(&mut self, x: [f64; 3], rng: &mut Rng) -> ([f64; 3], bool) {
        let mut out = [0.0; 3];
        let mut saturated = false;
        for k in 0..3 {
            let w = rng.gaussian(self.white);
            self.gm_bias[k] = self.phi * self.gm_bias[k] + rng.gaussian(self.gm_drive);
            let y = (1.0 + self.scale_factor[k]) * x[k] + self.bias[k] + self.gm_bias[k] + w;
            let (y, sat) = clamp(y, self.spec.range);
            saturated |= sat;
            out[k] = quantize(y, self.spec.quantum);
        }
        (out, saturated)
    }
}

fn clamp(y: f64, range: f64) -> (f64, bool) {
    if y > range {
        (range, true)
    } else if y < -range {
        (-range, true)
    } else {
        (y, false)
    }
}

fn quantize(y: f64, q: f64) -> f64 {
    if q > 0.0 { (y / q).round() * q } else { y }
}

/// The error state of one IMU.
#[derive(Debug, Clone)]
pub struct ImuErrorState {
    /// Gyroscope triad.
    pub gyro: SensorErrorState,
    /// Accelerometer triad.
    pub accel: SensorErrorState,
    /// Reported temperature, °C.
    pub temperature_c: f64,
}

impl ImuErrorState {
    /// Draws one IMU's constant errors.
    pub fn new(spec: &ImuErrorSpec, period_s: f64, rng: &mut Rng) -> Self {
        Self {
            gyro: SensorErrorState::new(spec.gyro, period_s, rng),
            accel: SensorErrorState::new(spec.accel, period_s, rng),
            temperature_c: spec.temperature_c,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample_stats(spec: SensorErrorSpec, period: f64, n: usize, seed: u64) -> (f64, f64) {
        // Only white noise: remove bias, GM and scale factor from the spec.
        let spec = SensorErrorSpec {
            bias_sigma: 0.0,
            bias_instability_sigma: 0.0,
            scale_factor_sigma: 0.0,
            ..spec
        };
        let mut rng = Rng::new(seed);
        let mut st = SensorErrorState::new(spec, period, &mut rng);
        let (mut s1, mut s2) = (0.0, 0.0);
        for _ in 0..n {
            let (y, _) = st.apply([0.0; 3], &mut rng);
            s1 += y[0];
            s2 += y[0] * y[0];
        }
        let mean = s1 / n as f64;
        (mean, (s2 / n as f64 - mean * mean).sqrt())
    }

    #[test]
    fn unit_conversions() {
        // 0.15 °/√h = 0.0025 °/s/√Hz.
        assert!((arw_deg_per_sqrt_h(0.15) - dps_per_sqrt_hz(0.0025)).abs() < 1e-15);
        // 100 µg/√Hz = 0.0588 m/s/√h.
        assert!((ug_per_sqrt_hz(100.0) * 60.0 - 0.058_84).abs() < 1e-5);
        assert!((deg_per_h(3600.0) - 1f64.to_radians()).abs() < 1e-15);
    }

    #[test]
    fn white_noise_matches_arw_and_vrw() {
        // σ of the averaged rate = N·√rate; checked within 2 % over 200k samples (the
        // standard error of a σ estimate is σ/√(2n) = 0.16 %).
        for (spec, rate) in [
            (ImuErrorSpec::industrial().gyro, 200.0),
            (ImuErrorSpec::industrial().accel, 200.0),
            (
                ImuErrorSpec {
                    ..ImuErrorSpec::consumer()
                }
                .gyro,
                1000.0,
            ),
        ] {
            let spec = SensorErrorSpec { quantum: 0.0, ..spec };
            let (mean, sigma) = sample_stats(spec, 1.0 / rate, 200_000, 11);
            let expected = spec.noise_density * f64::sqrt(rate);
            assert!((sigma / expected - 1.0).abs() < 0.02, "σ {sigma} vs {expected}");
            assert!(mean.abs() < 5.0 * expected / (200_000f64).sqrt());
        }
        // Consumer accel including its quantization (q/σ ≈ 0.1: adds q²/12, < 0.1 % of σ²).
        let spec = ImuErrorSpec::consumer().accel;
        let (_, sigma) = sample_stats(spec, 0.005, 200_000, 12);
        let expected = ug_per_sqrt_hz(100.0) * 200f64.sqrt();
        assert!((sigma / expected - 1.0).abs() < 0.02, "σ {sigma} vs {expected}");
    }

    #[test]
    fn integrated_noise_is_a_random_walk_with_the_arw() {
        // The angle from integrating the averaged rate for 1 s has σ = ARW·√1 s.
        let spec = SensorErrorSpec {
            quantum: 0.0,
            bias_sigma: 0.0,
            bias_instability_sigma: 0.0,
            ..ImuErrorSpec::industrial().gyro
        };
        let mut rng = Rng::new(5);
        let period = 0.005;
        let mut st = SensorErrorState::new(spec, period, &mut rng);
        let trials = 4000;
        let mut s2 = 0.0;
        for _ in 0..trials {
            let mut angle = 0.0;
            for _ in 0..200 {
                angle += st.apply([0.0; 3], &mut rng).0[2] * period;
            }
            s2 += angle * angle;
        }
        let sigma = (s2 / trials as f64).sqrt();
        let arw = arw_deg_per_sqrt_h(0.15);
        assert!((sigma / arw - 1.0).abs() < 0.05, "{sigma} vs {arw}");
    }

    #[test]
    fn gauss_markov_is_stationary_with_configured_sigma() {
        let spec = SensorErrorSpec {
            noise_density: 0.0,
            bias_sigma: 0.0,
            scale_factor_sigma: 0.0,
            quantum: 0.0,
            bias_correlation_s: 1.0,
            ..ImuErrorSpec::consumer().gyro
        };
        let mut rng = Rng::new(9);
        let (mut s2, mut n) = (0.0, 0usize);
        for _ in 0..200 {
            let mut st = SensorErrorState::new(spec, 0.01, &mut rng);
            for k in 0..500 {
                let (y, _) = st.apply([0.0; 3], &mut rng);
                if k % 100 == 0 {
                    s2 += y[1] * y[1];
                    n += 1;
                }
            }
        }
        let sigma = (s2 / n as f64).sqrt();
        assert!((sigma / spec.bias_instability_sigma - 1.0).abs() < 0.08, "{sigma}");
    }

    #[test]
    fn perfect_is_exact_and_consumes_no_randomness() {
        let mut rng = Rng::new(3);
        let mut st = ImuErrorState::new(&ImuErrorSpec::perfect(), 0.005, &mut rng);
        let x = [0.123_456_789, -1e-9, 9.81];
        assert_eq!(st.gyro.apply(x, &mut rng), (x, false));
        assert_eq!(st.accel.apply(x, &mut rng), (x, false));
        let mut fresh = Rng::new(3);
        assert_eq!(rng.next_u64(), fresh.next_u64());
    }

    #[test]
    fn saturation_and_quantization() {
        let mut rng = Rng::new(1);
        let spec = SensorErrorSpec {
            quantum: 0.5,
            range: 2.0,
            ..SensorErrorSpec::PERFECT
        };
        let mut st = SensorErrorState::new(spec, 0.01, &mut rng);
        let (y, sat) = st.apply([0.26, -0.74, 3.0], &mut rng);
        assert_eq!(y, [0.5, -0.5, 2.0]);
        assert!(sat);
    }
}
