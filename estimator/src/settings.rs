//! The estimator's settings: which inputs it fuses, the sensor models, and every tuning value,
//! each with its documented default. The live `navsync estimator`, `replay --estimate`,
//! `sim --fast --estimate`, the report, the analyses, the benchmarks and the tests all build
//! their [`Pipeline`](crate::pipeline::Pipeline) from a [`Settings`] through
//! [`Settings::pipeline_config`], so one set of settings gives one estimator everywhere.
//!
//! Units: SI unless the name says otherwise (`_s`, `_m`, `_mps`, `_deg`, `_ns`); frames:
//! body forward-right-down (FRD), navigation north-east-down (NED).

use std::collections::BTreeMap;

use nalgebra::{Matrix3, Vector3};
use navsync_shared::imu_spec::{ImuNoise, ImuPreset};
use navsync_shared::services;

use crate::array::imu_array::{ArrayConfig, UnitConfig};
use crate::array::imu_offset::OffsetConfig;
use crate::evaluation::DelayTruth;
use crate::nav::error_state::ProcessNoise;
use crate::nav::measurements::gnss::GnssAccuracy;
use crate::nav::navigator::NavConfig;
use crate::pipeline::PipelineConfig;
use crate::time::clock_model::OscillatorNoise;
use crate::time::device_timing::DeviceTimingConfig;
use crate::time::time_sync::TimeSyncConfig;

/// How GNSS aids the filter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Coupling {
    /// The receiver's position and velocity fixes (the default).
    #[default]
    Loose,
    /// Each satellite's pseudorange and Doppler (UBX RXM-RAWX with the ephemerides of
    /// RXM-SFRBX), with the receiver's clock bias and drift as filter states
    /// ([`crate::nav::measurements::ranges`]).
    Tight,
}

impl std::str::FromStr for Coupling {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "loose" => Ok(Self::Loose),
            "tight" => Ok(Self::Tight),
            _ => Err(format!("unknown coupling `{s}`, expected loose or tight")),
        }
    }
}

/// The receiver's oscillator: the process noise of its clock states when tightly coupled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize)]
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

/// Where one IMU sits in the body frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuMounting {
    /// Rotation IMU axes → body (FRD): x_body = C_b^s · x_imu.
    pub c_b_s: [[f64; 3]; 3],
    /// Position of the IMU in the body frame (FRD), m.
    pub lever_b_m: [f64; 3],
}

/// Tuning of the IMU array (offset estimation, alignment and fusion of several IMUs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArrayTuning {
    /// Order N of the Lagrange fractional-delay filter (default 3: cubic, 4 taps).
    pub lagrange_order: usize,
    /// 1-sigma of the prior of each IMU's time offset Td, s (default 0.1 s).
    pub td_prior_std_s: f64,
    /// Random walk of Td, s/√s (default 1e-6: a crystal's drift between two IMUs' stamps).
    pub td_rw: f64,
    /// An offset is observable (and updated) only while the information of the current
    /// window exceeds this many times the prior's (default 4).
    pub min_information_ratio: f64,
    /// An IMU joins the fused array once σ(Td) is below this, s (default 0.3 ms).
    pub admit_td_std_s: f64,
    /// No sample for this long (plus its own offset) makes an IMU stale, s (default 50 ms).
    pub stale_after_s: f64,
    /// Consecutive gated comparisons that drop an IMU as disagreeing (default 20).
    pub disagree_after: u32,
    /// Consecutive accepted comparisons that re-admit it (default 400).
    pub agree_after: u32,
    /// Half-width of the low-noise Savitzky–Golay differentiator of the reference's rates,
    /// samples (default 20).
    pub derivative_half_width: usize,
    /// Half-width of the fast (wide-band) differentiator, samples (default 3).
    pub derivative_half_width_fast: usize,
}

impl Default for ArrayTuning {
    fn default() -> Self {
        Self {
            lagrange_order: 3,
            td_prior_std_s: 0.1,
            td_rw: 1e-6,
            min_information_ratio: 4.0,
            admit_td_std_s: 3e-4,
            stale_after_s: 0.05,
            disagree_after: 20,
            agree_after: 400,
            derivative_half_width: 20,
            derivative_half_width_fast: 3,
        }
    }
}

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

/// Everything the estimator needs to be built.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// GNSS receiver ids (`navsync/gnss/{id}/fix`); default `["0"]`.
    pub gnss_ids: Vec<String>,
    /// PPS source ids (`navsync/pps/{id}/edge`); default `["0"]`.
    pub pps_ids: Vec<String>,
    /// IMU ids (`navsync/imu/{id}/sample`), the reference first; default `["0"]`.
    pub imu_ids: Vec<String>,
    /// Ignore PPS: stamp fixes by the receipt of their first byte (software sync, ms-level
    /// time); default false.
    pub software_sync: bool,
    /// IMU class: the filter's process noise when `imu_noise` is not given; default industrial.
    pub imu_model: ImuPreset,
    /// The IMU's noise model (KF-GINS units), overriding `imu_model`'s.
    pub imu_noise: Option<ImuNoise>,
    /// Estimate the GNSS delay Δ as a filter state; default true.
    pub estimate_delay: bool,
    /// 1-sigma of the receiver's velocity per axis, m/s (NMEA reports none); default 0.1.
    pub gnss_vel_std_mps: f64,
    /// Factor on the receiver's position σ (default 1).
    pub gnss_pos_std_scale: f64,
    /// Smallest position σ per axis, m (default 0.005).
    pub gnss_pos_std_floor_m: f64,
    /// Scale of the 99.9 % chi-square innovation gate (default 1).
    pub gate_scale: f64,
    /// GNSS speed above which the course gives the heading at alignment, m/s (default 3).
    pub align_min_speed_mps: f64,
    /// A known initial state instead of the alignment (default none).
    pub initial_state: Option<InitialState>,
    /// Fusion horizon: how far the delayed filter runs behind the present, s (default 1.5:
    /// covers a receiver latency up to ~1.25 s plus the input hold).
    pub fusion_horizon_s: f64,
    /// Estimate the IMUs' time offsets (else they are held at zero: an uncompensated array);
    /// default true.
    pub estimate_imu_offsets: bool,
    /// Mountings by IMU id; an IMU without one is mounted as the body frame at its origin.
    pub imu_mountings: BTreeMap<String, ImuMounting>,
    /// GNSS antenna position in the body frame (FRD), m; default zero.
    pub gnss_lever_arm_m: [f64; 3],
    /// Host oscillator Allan deviations at 1 s (white FM, random-walk FM); default a TCXO
    /// ([`OscillatorNoise::default`]).
    pub oscillator_adev_1s: Option<(f64, f64)>,
    /// Zero-velocity and zero-angular-rate updates while the vehicle stands still
    /// ([`crate::nav::measurements::zupt`]); default on.
    pub zupt: bool,
    /// Time IMU samples by their device clocks where they carry one (Xsens SampleTimeFine;
    /// [`crate::time::device_timing`]); default on.
    pub device_clocks: bool,
    /// Adapt the IMU's process noise to the GNSS innovations
    /// ([`crate::nav::measurements::gnss::GnssFusion`]); default off.
    pub adapt_process_noise: bool,
    /// Prior of Δ under software sync and its 1-sigma, s (default 0.5 ± 0.5 s: any receiver
    /// latency below the fusion horizon).
    pub software_delay_prior_s: (f64, f64),
    /// Prior of Δ under hardware sync and its 1-sigma, s (default 0 ± 20 ms: the remaining
    /// IMU-to-GNSS offset once fixes are stamped at their epoch).
    pub hardware_delay_prior_s: (f64, f64),
    /// The IMU array's tuning.
    pub array: ArrayTuning,
    /// How GNSS aids the filter (default loosely coupled).
    pub coupling: Coupling,
    /// The receiver's oscillator, for the clock states when tightly coupled (default TCXO).
    pub receiver_oscillator: ReceiverOscillator,
}

impl Default for Settings {
    /// One receiver, PPS source and IMU with id "0"; hardware sync; industrial IMU; Δ estimated.
    fn default() -> Self {
        Self {
            gnss_ids: vec!["0".into()],
            pps_ids: vec!["0".into()],
            imu_ids: vec!["0".into()],
            software_sync: false,
            imu_model: ImuPreset::Industrial,
            estimate_delay: true,
            gnss_vel_std_mps: GnssAccuracy::default().vel_std_mps,
            gnss_pos_std_scale: GnssAccuracy::default().pos_std_scale,
            gnss_pos_std_floor_m: GnssAccuracy::default().pos_std_floor_m,
            gate_scale: 1.0,
            align_min_speed_mps: 3.0,
            initial_state: None,
            fusion_horizon_s: 1.5,
            estimate_imu_offsets: true,
            imu_noise: None,
            imu_mountings: BTreeMap::new(),
            gnss_lever_arm_m: [0.0; 3],
            oscillator_adev_1s: None,
            zupt: true,
            adapt_process_noise: false,
            device_clocks: true,
            software_delay_prior_s: (0.5, 0.5),
            hardware_delay_prior_s: (0.0, 0.02),
            array: ArrayTuning::default(),
            coupling: Coupling::Loose,
            receiver_oscillator: ReceiverOscillator::Tcxo,
        }
    }
}

impl Settings {
    /// The services these settings subscribe to (PPS, GNSS fixes and time pulses, IMUs; the
    /// raw measurements and navigation data when tightly coupled).
    pub fn input_services(&self) -> Vec<String> {
        let pps = self.pps_ids.iter().map(|id| services::pps_edge(id));
        let gnss = self.gnss_ids.iter().map(|id| services::gnss_fix(id));
        let pulses = self.gnss_ids.iter().map(|id| services::gnss_time_pulse(id));
        let imus = self.imu_ids.iter().map(|id| services::imu_sample(id));
        let tight = self.coupling == Coupling::Tight;
        let raw = self
            .gnss_ids
            .iter()
            .filter(|_| tight)
            .flat_map(|id| [services::gnss_raw(id), services::gnss_nav_data(id)]);
        pps.chain(gnss).chain(pulses).chain(imus).chain(raw).collect()
    }

    /// Which Δ the filter should find (for the accuracy report against a simulated truth).
    pub fn delay_truth(&self) -> DelayTruth {
        if self.software_sync {
            DelayTruth::ReceiverLatency
        } else {
            DelayTruth::Zero
        }
    }

    /// The IMU noise model in force: `imu_noise`, else the preset's.
    pub fn noise(&self) -> ImuNoise {
        self.imu_noise.unwrap_or_else(|| self.imu_model.noise())
    }

    /// The IMU array: every IMU of `imu_ids` with the IMU class's noise and its mounting.
    pub fn array_config(&self) -> ArrayConfig {
        let noise = ProcessNoise::from_imu_noise(&self.noise());
        let t = &self.array;
        let (bg, ba) = (
            noise.gyro_bias_init_std.mean().max(1e-6),
            noise.accel_bias_init_std.mean().max(1e-5),
        );
        let gm_rw = |sigma: f64, tau: f64| (2.0 * 2.0 * sigma * sigma / tau).sqrt();
        ArrayConfig {
            units: self
                .imu_ids
                .iter()
                .map(|id| {
                    let m = self.imu_mountings.get(id);
                    UnitConfig {
                        id: id.clone(),
                        c_b_s: m.map_or_else(Matrix3::identity, |m| Matrix3::from_fn(|r, c| m.c_b_s[r][c])),
                        lever_b_m: m.map_or_else(Vector3::zeros, |m| Vector3::from(m.lever_b_m)),
                        gyro_noise_density: noise.arw.mean().max(1e-7),
                        accel_noise_density: noise.vrw.mean().max(1e-6),
                    }
                })
                .collect(),
            reference: 0,
            order: t.lagrange_order,
            offset: OffsetConfig {
                td_prior_s: 0.0,
                // Uncompensated: the offsets are held at zero (a vanishing prior, no random walk).
                td_prior_std_s: if self.estimate_imu_offsets {
                    t.td_prior_std_s
                } else {
                    1e-12
                },
                td_rw: if self.estimate_imu_offsets { t.td_rw } else { 0.0 },
                // Relative biases of two IMUs: √2 times one IMU's spread.
                gyro_bias_std: std::f64::consts::SQRT_2 * bg,
                accel_bias_std: std::f64::consts::SQRT_2 * ba,
                gyro_bias_rw: gm_rw(noise.gyro_bias_std.mean(), noise.corr_time_s).max(1e-9),
                accel_bias_rw: gm_rw(noise.accel_bias_std.mean(), noise.corr_time_s).max(1e-8),
                gyro_scale_std: std::f64::consts::SQRT_2 * noise.gyro_scale_init_std.mean().max(1e-5),
                accel_scale_std: std::f64::consts::SQRT_2 * noise.accel_scale_init_std.mean().max(1e-5),
                min_information_ratio: t.min_information_ratio,
            },
            admit_td_std_s: t.admit_td_std_s,
            stale_after_s: t.stale_after_s,
            disagree_after: t.disagree_after,
            agree_after: t.agree_after,
            derivative_half_width: t.derivative_half_width,
            derivative_half_width_fast: t.derivative_half_width_fast,
        }
    }

    /// The estimator configuration these settings describe.
    pub fn pipeline_config(&self) -> PipelineConfig {
        let mut noise = ProcessNoise::from_imu_noise(&self.noise());
        noise.estimate_delay = self.estimate_delay;
        noise.clock = (self.coupling == Coupling::Tight).then(|| self.receiver_oscillator.noise());
        let mut nav = NavConfig {
            lever_arm_b_m: Vector3::from(self.gnss_lever_arm_m),
            gate_scale: self.gate_scale,
            horizon_s: self.fusion_horizon_s,
            ..NavConfig::with_noise(noise)
        };
        nav.align.min_speed_mps = self.align_min_speed_mps;
        nav.measurements.zupt.enabled = self.zupt;
        nav.measurements.gnss.adapt_process_noise = self.adapt_process_noise;
        PipelineConfig {
            time: TimeSyncConfig {
                software_sync: self.software_sync,
                noise: self
                    .oscillator_adev_1s
                    .map_or_else(Default::default, |(w, r)| OscillatorNoise::from_allan(w, r)),
                ..Default::default()
            },
            nav,
            gnss: GnssAccuracy {
                vel_std_mps: self.gnss_vel_std_mps,
                pos_std_scale: self.gnss_pos_std_scale,
                pos_std_floor_m: self.gnss_pos_std_floor_m,
                ..GnssAccuracy::default()
            },
            initial_state: self.initial_state,
            reference_imu: self.imu_ids.first().cloned().unwrap_or_else(|| "0".into()),
            array: self.array_config(),
            software_delay_prior: self.software_delay_prior_s,
            hardware_delay_prior: self.hardware_delay_prior_s,
            device_timing: DeviceTimingConfig {
                enabled: self.device_clocks,
                ..DeviceTimingConfig::default()
            },
        }
    }
}
