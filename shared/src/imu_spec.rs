//! IMU error specifications: the figures of an IMU class (noise densities, bias stability,
//! turn-on bias, scale factor, resolution, range) in SI units, and the presets navsync ships.
//! The simulator draws its sensor errors from them and the estimator derives its process noise
//! from them, so both sides describe the same device.
//!
//! Unit conversions used below: 1 °/√h = (π/180)/60 rad/√s; 1 °/s/√Hz = π/180 rad/s/√Hz;
//! 1 m/s/√h = 1/60 (m/s)/√s; 1 µg/√Hz = 9.80665e-6 (m/s²)/√Hz; 1 °/h = (π/180)/3600 rad/s.
//! The Allan deviation of a first-order Gauss–Markov process peaks at 0.6174 σ near
//! τ = 1.89 τ_c, so a datasheet's in-run bias stability (the floor of its Allan curve) gives
//! σ_GM = stability / 0.6174.

use serde::Deserialize;

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
