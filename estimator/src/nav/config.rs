//! The navigation filter's settings ([`NavConfig`], one declaration per setting:
//! [`crate::declare`]) and the types they are made of: how GNSS aids the filter
//! ([`Coupling`]), the receiver's oscillator ([`ReceiverOscillator`]) and a known initial state
//! ([`InitialState`]), the alignment's thresholds ([`AlignConfig`]) and the integrity monitor's
//! bounds ([`IntegrityConfig`]). A leaf of the filter:
//! it imports only the noise models (the IMU's, the oscillators'); each kind of measurement
//! declares its own settings ([`super::measurements::MeasurementConfig`]).
//!
//! Units: SI unless the name says otherwise; frames: body forward-right-down (FRD),
//! navigation north-east-down (NED).

use navsync_wire::imu_spec::ImuPreset;

use super::error_state::ProcessNoise;
use crate::declare::checks::{finite3, positive, within};
use crate::time::clock_model::OscillatorNoise;

/// How GNSS aids the filter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Coupling {
    /// The receiver's position and velocity fixes (the default).
    #[default]
    Loose,
    /// Each satellite's pseudorange and Doppler (UBX RXM-RAWX with the ephemerides of
    /// RXM-SFRBX), with the receiver's clock bias and drift as filter states
    /// ([`super::measurements::ranges`]).
    Tight,
    /// navsync's own single-point solution of each raw epoch (the satellites and signals the
    /// tightly coupled filter would use, one receiver clock per system; velocity from the
    /// Doppler) fused as a fix; the receiver's fixes are not used. Loose coupling on the same
    /// measurements as tight, for comparison, or where the receiver's own fix is not wanted.
    LooseSpp,
}

impl Coupling {
    /// True when the estimator takes the receivers' raw measurements and navigation data.
    pub fn uses_raw(self) -> bool {
        matches!(self, Self::Tight | Self::LooseSpp)
    }
}

impl std::str::FromStr for Coupling {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "loose" => Ok(Self::Loose),
            "tight" => Ok(Self::Tight),
            "loose-spp" => Ok(Self::LooseSpp),
            _ => Err(format!("unknown coupling `{s}`, expected loose, tight or loose-spp")),
        }
    }
}

/// The receiver's oscillator: the process noise of its clock states when tightly coupled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ReceiverOscillator {
    /// A TCXO ([`OscillatorNoise::tcxo`]; the default: what GNSS receivers carry).
    #[default]
    Tcxo,
    /// A plain 0.5 ppm crystal ([`OscillatorNoise::crystal`]).
    Crystal,
}

impl ReceiverOscillator {
    /// The oscillator's noise.
    pub fn noise(self) -> OscillatorNoise {
        match self {
            Self::Tcxo => OscillatorNoise::tcxo(),
            Self::Crystal => OscillatorNoise::crystal(),
        }
    }
}

impl std::str::FromStr for ReceiverOscillator {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "tcxo" => Ok(Self::Tcxo),
            "crystal" => Ok(Self::Crystal),
            _ => Err(format!("unknown receiver oscillator `{s}`, expected tcxo or crystal")),
        }
    }
}

crate::enum_setting!(Coupling, ReceiverOscillator);

/// A known initial state (KF-GINS's `initpos`, `initvel`, `initatt`, `initgyrbias`,
/// `initaccbias` and their σ): the filter starts from it at `utc_ns` instead of aligning
/// itself (levelling and the GNSS course). Position of the IMU (navigation point), not the
/// antenna.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InitialState {
    /// The instant, ns UTC since 1970 (GNSS time; KF-GINS `starttime` in seconds of week is
    /// converted by the import).
    pub utc_ns: i64,
    /// Latitude, deg.
    pub lat_deg: f64,
    /// Longitude, deg.
    pub lon_deg: f64,
    /// Ellipsoidal height, m.
    pub height_m: f64,
    /// Velocity NED, m/s.
    pub vel_ned_mps: [f64; 3],
    /// Roll, pitch, yaw of the body frame (FRD) in NED, deg.
    pub rpy_deg: [f64; 3],
    /// Gyro bias (body FRD), °/h.
    #[serde(default)]
    pub gyro_bias_deg_per_h: [f64; 3],
    /// Accelerometer bias (body FRD), mGal.
    #[serde(default)]
    pub accel_bias_mgal: [f64; 3],
    /// 1-sigma of the position N, E, D, m.
    pub pos_std_m: [f64; 3],
    /// 1-sigma of the velocity N, E, D, m/s.
    pub vel_std_mps: [f64; 3],
    /// 1-sigma of roll, pitch, yaw, deg.
    pub att_std_deg: [f64; 3],
}

/// An initial state is given in the configuration file (or a recording), not as a flag.
impl crate::declare::SettingValue for InitialState {
    fn parse_text(text: &str) -> Result<Self, String> {
        Err(format!("`{text}`: an initial state is given in the configuration file"))
    }
    fn show(&self) -> String {
        format!("{self:?}")
    }
}

crate::settings_group! {
    /// The navigation filter's settings.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct NavConfig {
        /// IMU and state process noise (from the IMU model: `imu_model`, `imu_noise`).
        pub noise: ProcessNoise = ProcessNoise::from_imu_noise(&ImuPreset::Generic.noise());
        /// With the generic IMU model (an IMU of unknown class): its process noise scaled down to
        /// what the IMU's own signal shows, each white noise at most the density its 20 ms
        /// second differences hold over the last 10 s, the bias instabilities by the largest
        /// such ratio seen since the start, never above the generic model (off: the generic
        /// model as it is).
        pub imu_noise_from_signal: bool = true, file "estimator", switch "no-imu-noise-from-signal" => false;
        /// GNSS antenna in the body frame (FRD) from the IMU, m, `x,y,z` (in the file: the
        /// first receiver's `[gnss.ID] lever_arm_m`; else the recording's).
        pub gnss_lever_arm_m: [f64; 3] = [0.0; 3], flag "lever-arm", check finite3;
        /// Fusion horizon, s: how far the delayed filter runs behind the present to fuse late
        /// measurements at their epoch (≥ the largest receiver latency + 0.25 s, the input
        /// order's hold and Δ's doubt included: 2 s takes a receipt latency of 1.5 s); with
        /// `adaptive_horizon` its largest value.
        pub fusion_horizon_s: f64 = 2.0, file "estimator", flag "horizon", check within(0.3, 10.0);
        /// Shorten the horizon to what the fixes need (their delay from epoch to release, with
        /// Δ̂ + 3σ_Δ and a 20 ms margin, the largest of the recent ones), at least
        /// [`super::navigator::MIN_HORIZON_S`]: the output then carries less dead reckoning
        /// after the last fix.
        pub adaptive_horizon: bool = true;
        /// Covariance propagation step, s.
        pub cov_step_s: f64 = 0.02;
        /// Initial 1-sigma of roll and pitch after levelling, rad.
        pub init_level_std_rad: f64 = 0.5f64.to_radians();
        /// Initial 1-sigma of the heading from the GNSS course, rad.
        pub init_yaw_std_rad: f64 = 5f64.to_radians();
        /// Initial 1-sigma of the velocity, m/s.
        pub init_vel_std_mps: f64 = 0.3;
        /// Scale of the 99.9 % chi-square innovation gate.
        pub gate_scale: f64 = 1.0, file "estimator", flag "gate-scale", check positive;
        /// No fix for this long: INS-only, s.
        pub outage_after_s: f64 = 2.5;
        /// Estimate the GNSS delay Δ as a filter state (off: Δ frozen at its prior, for
        /// comparison runs).
        pub estimate_delay: bool = true, file "estimator", switch "no-delay-state" => false;
        /// 1-sigma of the prior of Δ under hardware sync (the IMU-to-GNSS time offset left after
        /// the PPS mapping), s (IMU time tags from another clock than the PPS's may need 0.2).
        pub delay_prior_std_s: f64 = 0.02, file "estimator", flag "delay-prior-std", check positive;
        /// How GNSS aids the filter: loose (the receiver's fixes), tight (each satellite's
        /// pseudorange, Doppler and carrier-phase change from UBX RXM-RAWX/RXM-SFRBX, the
        /// receiver clock in the filter) or loose-spp (navsync's single-point solution of the same raw measurements
        /// as fixes).
        pub coupling: Coupling = Coupling::Loose, file "estimator", flag "coupling";
        /// The receiver's oscillator for the clock states when tightly coupled: tcxo or crystal.
        pub receiver_oscillator: ReceiverOscillator = ReceiverOscillator::Tcxo, file "estimator", flag "receiver-oscillator";
        /// A known initial state instead of the alignment.
        pub initial_state: Option<InitialState> = None, file "estimator";
        /// Alignment thresholds.
        pub align: AlignConfig = AlignConfig::default();
        /// Bounds of the integrity monitor ([`super::integrity`]).
        pub integrity: IntegrityConfig = IntegrityConfig::default();
    }
}

crate::settings_group! {
    /// Thresholds of the alignment.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct AlignConfig {
        /// GNSS speed from which a fix counts as moving, m/s: without a static levelling the
        /// alignment starts on the first moving fix, its heading hypotheses on the course.
        pub align_min_speed_mps: f64 = 0.3, file "estimator", flag "align-speed", check positive;
        /// Largest angular rate still counted as static, rad/s.
        pub static_gyro_rps: f64 = 0.05;
        /// Largest deviation of |f| from 1 g still counted as static, m/s².
        pub static_accel_mps2: f64 = 0.3;
        /// Largest deviation of f from the static mean still counted as static, m/s².
        pub static_accel_dev_mps2: f64 = 0.15;
    }
}

crate::settings_group! {
    /// Bounds of the integrity monitor.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct IntegrityConfig {
        /// A bias estimate beyond this many times its turn-on σ (and instability σ) is not one
        /// the IMU model allows: the filter is reset.
        pub bias_sigmas: f64 = 6.0, file "estimator", check positive;
        /// Largest plausible scale-factor estimate (fraction; 0.2 = 20 %: a filter on a
        /// vibrating mount has been seen carrying ten percent to stand for what its model lacks;
        /// beyond that the estimate no longer stands for any IMU).
        pub max_scale: f64 = 0.1;
        /// Running NIS per component of the GNSS updates above which the filter is
        /// inconsistent (the 99.9 % χ² quantile of a 10-update average of 2–3 components is
        /// about 2.3; 3 leaves margin for the average's correlation).
        pub max_nis_average: f64 = 3.0, file "estimator", check positive;
        /// Seconds after a reset during which states are flagged as recovering.
        pub recovering_s: f64 = 10.0;
    }
}

impl NavConfig {
    /// The defaults with the given IMU process noise.
    pub fn with_noise(noise: ProcessNoise) -> Self {
        Self {
            noise,
            ..Self::default()
        }
    }
}
