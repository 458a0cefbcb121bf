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

use serde::Deserialize;

use super::rng::Rng;

/// Standard gravity used by datasheets to express accelerations in g, m/s².
pub const G0: f64 = 9.806_65;
/// Ratio of the peak Allan deviation of a first-order Gauss–Markov process to its
/// stationary standard deviation (max over τ of the ADEV, reached at τ ≈ 1.89 τ_c).
pub const GM_ADEV_PEAK_RATIO: f64 = 0.617_364;

/// °/√h → rad/√s (angle random walk).
pub fn arw_deg_per_sqrt_h(x: f64) -> f64 {
    x.to_radians() / 60.0
}
/// °/s/√Hz → rad/s/√Hz (rate-noise density, numerically the ARW in rad/√s).
pub fn dps_per_sqrt_hz(x: f64) -> f64 {
    x.to_radians()
}
/// m/s/√h → (m/s)/√s (velocity random walk).
pub fn vrw_mps_per_sqrt_h(x: f64) -> f64 {
    x / 60.0
}
/// µg/√Hz → (m/s²)/√Hz (acceleration-noise density, numerically the VRW in (m/s)/√s).
pub fn ug_per_sqrt_hz(x: f64) -> f64 {
    x * 1e-6 * G0
}
/// °/h → rad/s.
pub fn deg_per_h(x: f64) -> f64 {
    x.to_radians() / 3600.0
}
/// °/s → rad/s.
pub fn deg_per_s(x: f64) -> f64 {
    x.to_radians()
}
/// mg → m/s².
pub fn milli_g(x: f64) -> f64 {
    x * 1e-3 * G0
}
/// µg → m/s².
pub fn micro_g(x: f64) -> f64 {
    x * 1e-6 * G0
}

/// Which IMU error model to simulate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ImuPreset {
    /// TDK InvenSense ICM-20602 class consumer MEMS IMU ([`ImuErrorSpec::consumer`]).
    Consumer,
    /// Analog Devices ADIS16465-1 class industrial MEMS IMU ([`ImuErrorSpec::industrial`]).
    Industrial,
    /// No errors at all: outputs are the exact averaged truth.
    Perfect,
}

impl ImuPreset {
    /// The error figures of this preset.
    pub fn spec(self) -> ImuErrorSpec {
        match self {
            Self::Consumer => ImuErrorSpec::consumer(),
            Self::Industrial => ImuErrorSpec::industrial(),
            Self::Perfect => ImuErrorSpec::perfect(),
        }
    }

    /// Lower-case name as written in scenarios and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::Consumer => "consumer",
            Self::Industrial => "industrial",
            Self::Perfect => "perfect",
        }
    }
}

impl std::str::FromStr for ImuPreset {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "consumer" => Ok(Self::Consumer),
            "industrial" => Ok(Self::Industrial),
            "perfect" => Ok(Self::Perfect),
            _ => Err(format!(
                "unknown IMU preset `{s}`, expected consumer, industrial or perfect"
            )),
        }
    }
}

/// Error figures of one triad (gyroscope or accelerometer), SI units; the same on each axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorErrorSpec {
    /// White-noise density, rad/s/√Hz (gyro, = ARW in rad/√s) or (m/s²)/√Hz (accel, = VRW in (m/s)/√s).
    pub noise_density: f64,
    /// 1-σ spread of the constant (turn-on) bias, rad/s or m/s².
    pub bias_sigma: f64,
    /// Stationary 1-σ of the Gauss–Markov bias instability, rad/s or m/s².
    pub bias_instability_sigma: f64,
    /// Correlation time of the bias instability, s.
    pub bias_correlation_s: f64,
    /// 1-σ spread of the constant scale-factor error, fraction (0.01 = 1 %).
    pub scale_factor_sigma: f64,
    /// Output resolution (LSB), rad/s or m/s²; 0 = not quantized.
    pub quantum: f64,
    /// Full-scale range (outputs are clamped to ±range and flagged), rad/s or m/s²; ∞ = none.
    pub range: f64,
}

impl SensorErrorSpec {
    /// A triad without errors.
    pub const PERFECT: Self = Self {
        noise_density: 0.0,
        bias_sigma: 0.0,
        bias_instability_sigma: 0.0,
        bias_correlation_s: 1.0,
        scale_factor_sigma: 0.0,
        quantum: 0.0,
        range: f64::INFINITY,
    };

    /// 1-σ of the white noise on one sample averaged over `period_s`: N/√T.
    pub fn white_sigma(&self, period_s: f64) -> f64 {
        self.noise_density / period_s.sqrt()
    }
}

/// Error figures of one IMU.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuErrorSpec {
    /// Gyroscope triad.
    pub gyro: SensorErrorSpec,
    /// Accelerometer triad.
    pub accel: SensorErrorSpec,
    /// Temperature reported in every sample, °C.
    pub temperature_c: f64,
}

impl ImuErrorSpec {
    /// ICM-20602 class (TDK InvenSense DS-000176 rev. 1.0), configured ±500 °/s and ±4 g.
    ///
    /// Gyroscope:
    /// - rate-noise spectral density 0.004 °/s/√Hz (datasheet; = ARW 0.24 °/√h);
    /// - turn-on bias: initial ZRO tolerance ±1 °/s (datasheet), taken as 3 σ → σ = 0.333 °/s;
    /// - bias instability: not specified by the datasheet; 8 °/h (typical Allan floor of this
    ///   class), τ_c = 100 s;
    /// - scale factor: sensitivity tolerance ±1 % (datasheet), 3 σ → σ = 0.333 %;
    /// - resolution 1/65.5 °/s per LSB at ±500 °/s (datasheet sensitivity 65.5 LSB/(°/s)).
    ///
    /// Accelerometer:
    /// - noise power spectral density 100 µg/√Hz (datasheet; = VRW 0.059 m/s/√h);
    /// - turn-on bias: zero-g initial tolerance ±25 mg (datasheet, component level), 3 σ →
    ///   σ = 8.33 mg;
    /// - bias instability: not specified; 60 µg (typical of the class), τ_c = 100 s;
    /// - scale factor: ±1 % assumed like the gyro's, 3 σ → σ = 0.333 %;
    /// - resolution 1/8192 g per LSB at ±4 g (datasheet sensitivity 8192 LSB/g).
    pub fn consumer() -> Self {
        Self {
            gyro: SensorErrorSpec {
                noise_density: dps_per_sqrt_hz(0.004),
                bias_sigma: deg_per_s(1.0 / 3.0),
                bias_instability_sigma: deg_per_h(8.0) / GM_ADEV_PEAK_RATIO,
                bias_correlation_s: 100.0,
                scale_factor_sigma: 0.01 / 3.0,
                quantum: deg_per_s(1.0 / 65.5),
                range: deg_per_s(500.0),
            },
            accel: SensorErrorSpec {
                noise_density: ug_per_sqrt_hz(100.0),
                bias_sigma: milli_g(25.0 / 3.0),
                bias_instability_sigma: micro_g(60.0) / GM_ADEV_PEAK_RATIO,
                bias_correlation_s: 100.0,
                scale_factor_sigma: 0.01 / 3.0,
                quantum: G0 / 8192.0,
                range: 4.0 * G0,
            },
            temperature_c: 30.0,
        }
    }

    /// ADIS16465-1 class (Analog Devices ADIS16465 data sheet rev. B), ±125 °/s and ±8 g,
    /// 32-bit outputs.
    ///
    /// Gyroscope:
    /// - angle random walk 0.15 °/√h (datasheet);
    /// - in-run bias stability 2 °/h (datasheet), τ_c = 200 s;
    /// - turn-on bias: factory calibrated; σ = 0.05 °/s assumed (bias repeatability class);
    /// - scale factor: factory calibrated; σ = 0.1 % assumed;
    /// - resolution 1/(160·2¹⁶) °/s per LSB (160 LSB/(°/s) in the 16-bit word, 32-bit output).
    ///
    /// Accelerometer:
    /// - velocity random walk 0.012 m/s/√h (datasheet);
    /// - in-run bias stability 3.6 µg (datasheet), τ_c = 200 s;
    /// - turn-on bias: σ = 1.5 mg assumed; scale factor σ = 0.1 % assumed;
    /// - resolution 1/(4000·2¹⁶) g per LSB (4000 LSB/g in the 16-bit word, 32-bit output).
    pub fn industrial() -> Self {
        Self {
            gyro: SensorErrorSpec {
                noise_density: arw_deg_per_sqrt_h(0.15),
                bias_sigma: deg_per_s(0.05),
                bias_instability_sigma: deg_per_h(2.0) / GM_ADEV_PEAK_RATIO,
                bias_correlation_s: 200.0,
                scale_factor_sigma: 0.001,
                quantum: deg_per_s(1.0 / (160.0 * 65536.0)),
                range: deg_per_s(125.0),
            },
            accel: SensorErrorSpec {
                noise_density: vrw_mps_per_sqrt_h(0.012),
                bias_sigma: milli_g(1.5),
                bias_instability_sigma: micro_g(3.6) / GM_ADEV_PEAK_RATIO,
                bias_correlation_s: 200.0,
                scale_factor_sigma: 0.001,
                quantum: G0 / (4000.0 * 65536.0),
                range: 8.0 * G0,
            },
            temperature_c: 35.0,
        }
    }

    /// No errors: the exact averaged truth, NaN-free, never saturated.
    pub fn perfect() -> Self {
        Self {
            gyro: SensorErrorSpec::PERFECT,
            accel: SensorErrorSpec::PERFECT,
            temperature_c: 25.0,
        }
    }
}

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
