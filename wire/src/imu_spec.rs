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
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ImuPreset {
    /// An IMU of unknown class as it behaves in use ([`ImuErrorSpec::generic`]): the
    /// estimator's default.
    Generic,
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
            Self::Generic => ImuErrorSpec::generic(),
            Self::Consumer => ImuErrorSpec::consumer(),
            Self::Industrial => ImuErrorSpec::industrial(),
            Self::Perfect => ImuErrorSpec::perfect(),
        }
    }

    /// Lower-case name as written in scenarios and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::Generic => "generic",
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
            "generic" => Ok(Self::Generic),
            "consumer" => Ok(Self::Consumer),
            "industrial" => Ok(Self::Industrial),
            "perfect" => Ok(Self::Perfect),
            _ => Err(format!(
                "unknown IMU preset `{s}`, expected generic, consumer, industrial or perfect"
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
        // Its (zero) bias is a random constant, not a process forgotten within a second: a
        // filter given this model keeps what it learns about its bias.
        bias_correlation_s: 3600.0,
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
    /// An IMU of unknown class, as it behaves in use: a consumer MEMS IMU on a vehicle or in a
    /// hand, where vibration and handling, not the datasheet's noise, make the effective noise
    /// (Groves 2013 §4.4: vibration raises a MEMS IMU's apparent noise by an order of
    /// magnitude). The figures are the effective noise measured on a real drive (TDK ICM-45686
    /// on a car roof, rtklibexplorer drive0708, its README's suggested settings at the
    /// midpoints of their ranges): ARW 2 °/√h, VRW 0.75 m/s/√h, bias instability 30 °/h and
    /// 0.15 m/s² (15 000 mGal) with a 0.75 h correlation time, turn-on bias 0.35 °/s and
    /// 0.15 m/s², scale factors 0.1 %. The estimator's default: its σ stays honest for the
    /// IMUs navsync meets in practice, and a better IMU gains accuracy by stating its model
    /// (`imu_model`, `[estimator.imu_noise]`). Not quantized; ±2000 °/s, ±16 g.
    pub fn generic() -> Self {
        Self {
            gyro: SensorErrorSpec {
                noise_density: arw_deg_per_sqrt_h(2.0),
                bias_sigma: deg_per_s(0.35),
                bias_instability_sigma: deg_per_h(30.0),
                bias_correlation_s: 2700.0,
                scale_factor_sigma: 0.001,
                quantum: 0.0,
                range: deg_per_s(2000.0),
            },
            accel: SensorErrorSpec {
                noise_density: vrw_mps_per_sqrt_h(0.75),
                bias_sigma: 0.15,
                bias_instability_sigma: 0.15,
                bias_correlation_s: 2700.0,
                scale_factor_sigma: 0.001,
                quantum: 0.0,
                range: 16.0 * G0,
            },
            temperature_c: 30.0,
        }
    }

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

/// A value per axis (x, y, z of the IMU): in a configuration file a number (the same on
/// every axis) or an array of three.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(transparent)]
pub struct PerAxis(pub [f64; 3]);

impl PerAxis {
    /// The same value on every axis.
    pub const fn all(x: f64) -> Self {
        Self([x; 3])
    }

    /// Each value times `k`.
    pub fn scaled(self, k: f64) -> Self {
        Self(self.0.map(|x| x * k))
    }
}

/// `2` (every axis) or `3,3,0.3` (x, y, z), as on the command line.
impl std::str::FromStr for PerAxis {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let v: Vec<f64> = s
            .split(',')
            .map(|x| x.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| format!("`{s}`: expected a number or three numbers x,y,z"))?;
        match v.as_slice() {
            [x] => Ok(Self::all(*x)),
            [x, y, z] => Ok(Self([*x, *y, *z])),
            _ => Err(format!("`{s}`: expected a number or three numbers x,y,z")),
        }
    }
}

impl<'de> Deserialize<'de> for PerAxis {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Repr {
            One(f64),
            Three([f64; 3]),
        }
        match Repr::deserialize(d) {
            Ok(Repr::One(x)) => Ok(Self::all(x)),
            Ok(Repr::Three(v)) => Ok(Self(v)),
            Err(_) => Err(serde::de::Error::custom(
                "expected a number or an array of three numbers",
            )),
        }
    }
}

/// An IMU's noise and error model as a datasheet or an Allan-variance plot states it, in
/// KF-GINS's units (its `imunoise` and initial-σ blocks), per axis: what the estimator's
/// process noise and initial uncertainty are made of, what `[imu.ID.noise]` or
/// `[estimator.imu_noise]` and `navsync import kf-gins --config` set, and what recordings store.
///
/// The bias and scale-factor errors are first-order Gauss–Markov processes with stationary
/// standard deviation `*_std` and correlation time `corr_time_h` (driving noise 2σ²/τ), starting
/// from a turn-on error of standard deviation `*_init_std`. An Allan plot's bias-instability
/// floor B corresponds to σ = B / 0.6174 ([`GM_ADEV_PEAK_RATIO`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImuNoise {
    /// Angle random walk, °/√h (KF-GINS `arw`; a rate-noise density in °/s/√Hz × 60).
    pub arw_deg_per_sqrt_h: PerAxis,
    /// Velocity random walk, m/s/√h (KF-GINS `vrw`; an acceleration-noise density in
    /// m/s²/√Hz × 60).
    pub vrw_mps_per_sqrt_h: PerAxis,
    /// Gyro bias instability: Gauss–Markov σ, °/h (KF-GINS `gbstd`).
    pub gyro_bias_std_deg_per_h: PerAxis,
    /// Accelerometer bias instability: Gauss–Markov σ, mGal = 1e-5 m/s² (KF-GINS `abstd`).
    pub accel_bias_std_mgal: PerAxis,
    /// Gyro scale-factor instability: Gauss–Markov σ, ppm (KF-GINS `gsstd`).
    pub gyro_scale_std_ppm: PerAxis,
    /// Accelerometer scale-factor instability: Gauss–Markov σ, ppm (KF-GINS `asstd`).
    pub accel_scale_std_ppm: PerAxis,
    /// Correlation time of the bias and scale-factor processes, h (KF-GINS `corrtime`).
    pub corr_time_h: f64,
    /// Turn-on gyro bias σ, °/h (KF-GINS `initbgstd`).
    pub gyro_bias_init_std_deg_per_h: PerAxis,
    /// Turn-on accelerometer bias σ, mGal (KF-GINS `initbastd`).
    pub accel_bias_init_std_mgal: PerAxis,
    /// Turn-on gyro scale-factor σ, ppm (KF-GINS `initsgstd`); 0 on every axis: scale factors
    /// are not estimated.
    pub gyro_scale_init_std_ppm: PerAxis,
    /// Turn-on accelerometer scale-factor σ, ppm (KF-GINS `initsastd`).
    pub accel_scale_init_std_ppm: PerAxis,
}

/// rad/s → °/h.
const RAD_S_TO_DEG_H: f64 = 180.0 / std::f64::consts::PI * 3600.0;
/// m/s² → mGal.
const MPS2_TO_MGAL: f64 = 1e5;

impl ImuNoise {
    /// The model of an IMU class: its noise densities, bias instability and correlation time,
    /// turn-on bias and scale-factor spread (scale-factor instability a tenth of the spread).
    pub fn from_spec(spec: &ImuErrorSpec) -> Self {
        let (g, a) = (&spec.gyro, &spec.accel);
        Self {
            arw_deg_per_sqrt_h: PerAxis::all(g.noise_density.to_degrees() * 60.0),
            vrw_mps_per_sqrt_h: PerAxis::all(a.noise_density * 60.0),
            gyro_bias_std_deg_per_h: PerAxis::all(g.bias_instability_sigma * RAD_S_TO_DEG_H),
            accel_bias_std_mgal: PerAxis::all(a.bias_instability_sigma * MPS2_TO_MGAL),
            gyro_scale_std_ppm: PerAxis::all(0.1 * g.scale_factor_sigma * 1e6),
            accel_scale_std_ppm: PerAxis::all(0.1 * a.scale_factor_sigma * 1e6),
            corr_time_h: g.bias_correlation_s / 3600.0,
            gyro_bias_init_std_deg_per_h: PerAxis::all(g.bias_sigma.max(g.bias_instability_sigma) * RAD_S_TO_DEG_H),
            accel_bias_init_std_mgal: PerAxis::all(a.bias_sigma.max(a.bias_instability_sigma) * MPS2_TO_MGAL),
            gyro_scale_init_std_ppm: PerAxis::all(g.scale_factor_sigma * 1e6),
            accel_scale_init_std_ppm: PerAxis::all(a.scale_factor_sigma * 1e6),
        }
    }

    /// Every value finite and ≥ 0, the correlation time > 0; else what is wrong (a field name
    /// and the value).
    pub fn check(&self) -> Result<(), String> {
        let fields = [
            ("arw_deg_per_sqrt_h", self.arw_deg_per_sqrt_h),
            ("vrw_mps_per_sqrt_h", self.vrw_mps_per_sqrt_h),
            ("gyro_bias_std_deg_per_h", self.gyro_bias_std_deg_per_h),
            ("accel_bias_std_mgal", self.accel_bias_std_mgal),
            ("gyro_scale_std_ppm", self.gyro_scale_std_ppm),
            ("accel_scale_std_ppm", self.accel_scale_std_ppm),
            ("gyro_bias_init_std_deg_per_h", self.gyro_bias_init_std_deg_per_h),
            ("accel_bias_init_std_mgal", self.accel_bias_init_std_mgal),
            ("gyro_scale_init_std_ppm", self.gyro_scale_init_std_ppm),
            ("accel_scale_init_std_ppm", self.accel_scale_init_std_ppm),
        ];
        for (name, v) in fields {
            if let Some(x) = v.0.iter().find(|x| !(x.is_finite() && **x >= 0.0)) {
                return Err(format!("{name}: {x} (expected a finite value ≥ 0)"));
            }
        }
        if !(self.corr_time_h.is_finite() && self.corr_time_h > 0.0) {
            return Err(format!(
                "corr_time_h: {} (expected a time > 0 in hours)",
                self.corr_time_h
            ));
        }
        Ok(())
    }
}

impl ImuPreset {
    /// The noise model of this preset.
    pub fn noise(self) -> ImuNoise {
        ImuNoise::from_spec(&self.spec())
    }
}
