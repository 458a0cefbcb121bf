//! The scenario: a TOML description of the simulated world (trajectory, IMUs, GNSS receiver,
//! host oscillator, seed), its validation, and the command-line style overrides the process
//! shell applies after loading.
//!
//! Units are SI throughout (s, m, m/s, Hz) except angles in configuration files, which are
//! in degrees (`*_deg`). The layout of a scenario file is documented in
//! `sim/scenarios/default_drive.toml`, which is also the embedded default
//! ([`SimConfig::default_drive`]).
//!
//! Errors name the file, the line and the dotted field (`trajectory.segment[3].to_speed_mps`)
//! and say what was expected: type errors and unknown fields through toml's spans and
//! `deny_unknown_fields`, semantic errors (e.g. a static segment entered at speed) through
//! [`navsync_shared::config::SourceMap`].

use std::path::Path;

use navsync_shared::samples::MAX_IMUS;
use serde::Deserialize;

pub use super::error::SimError;
use super::imu_errors::ImuPreset;
use navsync_shared::source_map::SourceMap;

/// Origin label of the embedded default scenario.
pub const DEFAULT_DRIVE_ORIGIN: &str = "sim/scenarios/default_drive.toml";

/// Origin reported for values set through the override setters.
pub const OVERRIDES_ORIGIN: &str = "overrides";

const DEFAULT_DRIVE_TOML: &str = include_str!("../scenarios/default_drive.toml");

/// The complete description of a simulated world. Same configuration and seed, same world.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimConfig {
    /// Seed of every random source of the world (sensor noise, jitter, oscillator).
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// The vehicle's motion.
    pub trajectory: TrajectoryConfig,
    /// The IMU array.
    #[serde(default)]
    pub imu: ImuArrayConfig,
    /// The GNSS receiver (fixes, NMEA output, outages).
    #[serde(default)]
    pub gnss: GnssConfig,
    /// The host oscillator and the PPS time stamps.
    #[serde(default)]
    pub clock: ClockConfig,
    /// Ground-truth output.
    #[serde(default)]
    pub truth: TruthConfig,
    /// Where the fields were in the text (for error messages).
    #[serde(skip)]
    source: Option<SourceMap>,
    /// Where the text came from (file path or a label such as `<embedded default_drive.toml>`).
    #[serde(skip)]
    origin: String,
    /// Dotted paths set through override setters (errors on them name [`OVERRIDES_ORIGIN`]).
    #[serde(skip)]
    overridden: Vec<&'static str>,
}

fn default_seed() -> u64 {
    1
}

/// Initial state and motion segments.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrajectoryConfig {
    /// Initial position, heading, pitch and speed.
    pub start: StartConfig,
    /// Motion segments, run in order (TOML `[[trajectory.segment]]`).
    #[serde(rename = "segment", default)]
    pub segments: Vec<SegmentConfig>,
    /// Body vibration superposed on the smooth path (TOML `[trajectory.vibration]`; on by
    /// default with the nominal figures of [`VibrationConfig::default`]).
    #[serde(default)]
    pub vibration: VibrationConfig,
}

/// Road- and engine-induced body vibration, superposed on the smooth segment motion
/// (model, spectra and sources in [`vibration`](super::vibration)).
///
/// Roll and pitch of the body and its vertical (heave) displacement are each a sum of
/// sinusoids in the 1–20 Hz band with seed-drawn phases, scaled by a smooth speed envelope
/// that is 0 at standstill, 1 at `reference_speed_mps` and grows like √(v/v_ref) above it
/// (the ISO 8608 road input at a fixed temporal frequency grows with speed). The RMS figures
/// are those of a steady drive at the reference speed.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VibrationConfig {
    /// Whether the body vibrates (default true).
    pub enabled: bool,
    /// Speed at which the RMS figures below apply, m/s (default 20 = 72 km/h).
    pub reference_speed_mps: f64,
    /// RMS of the body roll angle at the reference speed, degrees (default 0.065: with the
    /// built-in spectrum a roll rate of ≈ 0.9 °/s RMS).
    pub roll_rms_deg: f64,
    /// RMS of the body pitch angle at the reference speed, degrees (default 0.08: a pitch
    /// rate of ≈ 0.9 °/s RMS).
    pub pitch_rms_deg: f64,
    /// RMS of the vertical (heave) displacement of the body at the reference speed, m
    /// (default 0.003: a vertical acceleration of ≈ 0.25 m/s² RMS, a good road).
    pub heave_rms_m: f64,
}

impl Default for VibrationConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            reference_speed_mps: 20.0,
            roll_rms_deg: 0.065,
            pitch_rms_deg: 0.08,
            heave_rms_m: 0.003,
        }
    }
}

/// The vehicle's state at scenario time 0.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StartConfig {
    /// Geodetic latitude (WGS-84), degrees north, |φ| ≤ 85°.
    pub lat_deg: f64,
    /// Longitude, degrees east.
    pub lon_deg: f64,
    /// Height above the WGS-84 ellipsoid, m.
    pub height_m: f64,
    /// Heading (yaw of the body frame, clockwise from true north), degrees.
    pub heading_deg: f64,
    /// Flight-path angle = pitch, degrees, positive nose up (default 0).
    #[serde(default)]
    pub pitch_deg: f64,
    /// Speed along the body x axis, m/s (default 0).
    #[serde(default)]
    pub speed_mps: f64,
}

/// The kind of a motion segment; it decides which change fields are allowed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SegmentKind {
    /// Standing still: entered at speed 0, no change fields.
    Static,
    /// Speed increases to `to_speed_mps`.
    Accelerate,
    /// Speed decreases to `to_speed_mps` (0 to stop).
    Decelerate,
    /// Constant speed, heading and pitch; no change fields.
    Cruise,
    /// Heading changes by `heading_change_deg` (positive = right/clockwise) at constant speed > 0.
    Turn,
    /// Flight-path angle (pitch) changes to `to_pitch_deg` at constant speed > 0.
    Climb,
    /// Any combination of `to_speed_mps`, `heading_change_deg`, `to_pitch_deg` at once.
    Maneuver,
}

impl SegmentKind {
    /// Lower-case name as written in the scenario.
    pub fn name(self) -> &'static str {
        match self {
            Self::Static => "static",
            Self::Accelerate => "accelerate",
            Self::Decelerate => "decelerate",
            Self::Cruise => "cruise",
            Self::Turn => "turn",
            Self::Climb => "climb",
            Self::Maneuver => "maneuver",
        }
    }
}

/// One motion segment. Changes follow the raised-cosine profile of
/// [`smooth_step`](super::trajectory::smooth_step), so accelerations and angular rates are
/// continuous and zero at both ends of every segment.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SegmentConfig {
    /// What the segment does.
    pub kind: SegmentKind,
    /// Length, s (> 0).
    pub duration_s: f64,
    /// Speed at the end, m/s (accelerate, decelerate, maneuver).
    #[serde(default)]
    pub to_speed_mps: Option<f64>,
    /// Heading change, degrees, positive clockwise seen from above (turn, maneuver).
    #[serde(default)]
    pub heading_change_deg: Option<f64>,
    /// Flight-path angle (pitch) at the end, degrees, positive up (climb, maneuver).
    #[serde(default)]
    pub to_pitch_deg: Option<f64>,
}

/// The IMU array: common settings and per-IMU overrides.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ImuArrayConfig {
    /// Number of IMUs, 1..=[`MAX_IMUS`] (default 4).
    pub count: usize,
    /// Error model of every IMU without its own `preset` (default `consumer`).
    pub preset: ImuPreset,
    /// Sample rate, Hz (default 200).
    pub rate_hz: f64,
    /// 1-σ host time-stamp jitter of every IMU without its own value, s (default 20 µs).
    pub stamp_jitter_s: f64,
    /// Per-IMU settings; table `i` applies to IMU `i` (TOML `[[imu.unit]]`); IMUs beyond the
    /// list use the defaults, tables beyond `count` are ignored.
    #[serde(rename = "unit")]
    pub units: Vec<ImuUnitConfig>,
    /// Each IMU samples on its own crystal, [`imu_crystal_freq_error`] off true time (a
    /// device with its own clock, such as an Xsens MTi, whose SampleTimeFine counts that
    /// crystal); default false: every IMU samples on the exact grid of scenario time.
    /// `navsync sim --imu-output xsens` switches it on.
    pub device_clocks: bool,
}

/// Fractional frequency error of IMU `index`'s crystal when IMUs sample on their own clocks
/// (+25, −40, +60, −15 ppm, …): its nominal sample period T lasts T/(1 + y) of true time.
pub fn imu_crystal_freq_error(index: usize) -> f64 {
    [25e-6, -40e-6, 60e-6, -15e-6][index % 4]
}

impl Default for ImuArrayConfig {
    fn default() -> Self {
        Self {
            count: 4,
            preset: ImuPreset::Consumer,
            rate_hz: 200.0,
            stamp_jitter_s: 20e-6,
            units: Vec::new(),
            device_clocks: false,
        }
    }
}

/// Settings of one IMU; every field is optional.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ImuUnitConfig {
    /// Stamp delay Td, s: the sample whose data ends at true time t is stamped at host(t + Td)
    /// (default [`default_imu_offset_s`]: 0, 10, 15, 20, 25, … ms).
    pub offset_s: Option<f64>,
    /// Sample rate, Hz (default: the array's).
    pub rate_hz: Option<f64>,
    /// Sample-grid phase, s in [0, 1/rate): sample k covers [phase + k/rate, phase + (k+1)/rate]
    /// of scenario time (default i × 1.1 ms modulo the period).
    pub phase_s: Option<f64>,
    /// 1-σ stamp jitter, s (default: the array's).
    pub stamp_jitter_s: Option<f64>,
    /// Error model (default: the array's).
    pub preset: Option<ImuPreset>,
    /// Mounting: roll, pitch, yaw of the sensor axes w.r.t. the body (FRD) axes, degrees
    /// (C_s^b = R_z(yaw) R_y(pitch) R_x(roll)); default 0, 0, 0.
    pub mount_rpy_deg: [f64; 3],
    /// Lever arm from the body origin to the sensor, body (FRD) axes, m; default 0.
    pub lever_arm_m: [f64; 3],
    /// The IMU samples on the GNSS receiver's oscillator (one crystal: an IMU in the
    /// receiver's chip, or one triggered by its time pulse): sample k ends when the receiver's
    /// clock reads a multiple of the period (plus `phase_s`), and its stamp carries that
    /// reading as device time with [`IMU_FLAG_RECEIVER_CLOCK`](navsync_shared::samples::IMU_FLAG_RECEIVER_CLOCK).
    /// Needs `[gnss.sky]` (the receiver's clock lives there); default false.
    pub receiver_clock: bool,
}

/// Default stamp delay of IMU `index` relative to true time, s: 0, 10, 15, 20 ms for the
/// first four, then 5 ms more per IMU.
pub fn default_imu_offset_s(index: usize) -> f64 {
    match index {
        0 => 0.0,
        1 => 0.010,
        2 => 0.015,
        _ => 0.020 + 0.005 * (index as f64 - 3.0),
    }
}

/// The fully resolved settings of one IMU.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResolvedImu {
    /// Stamp delay Td, s.
    pub offset_s: f64,
    /// Sample rate, Hz.
    pub rate_hz: f64,
    /// Sample-grid phase, s.
    pub phase_s: f64,
    /// 1-σ stamp jitter, s.
    pub stamp_jitter_s: f64,
    /// Error model.
    pub preset: ImuPreset,
    /// Mounting roll, pitch, yaw, rad.
    pub mount_rpy_rad: [f64; 3],
    /// Lever arm, body axes, m.
    pub lever_arm_m: [f64; 3],
    /// Fractional frequency error of the crystal the IMU samples on (0: the exact grid).
    pub clock_freq_error: f64,
    /// Samples on the GNSS receiver's oscillator ([`ImuUnitConfig::receiver_clock`]; then
    /// `clock_freq_error` is unused).
    pub receiver_clock: bool,
}

/// The simulated receiver's output protocol.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum OutputProtocol {
    /// NMEA 0183 sentences.
    #[default]
    Nmea,
    /// u-blox UBX messages.
    Ubx,
}

impl std::str::FromStr for OutputProtocol {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "nmea" => Ok(Self::Nmea),
            "ubx" => Ok(Self::Ubx),
            _ => Err(format!("`{s}` is not a simulated receiver protocol (nmea, ubx)")),
        }
    }
}

/// NMEA talker identifier.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
pub enum Talker {
    /// Multi-constellation receiver (`$GN…`).
    #[serde(rename = "GN")]
    Gn,
    /// GPS-only receiver (`$GP…`).
    #[serde(rename = "GP")]
    Gp,
}

impl Talker {
    /// The two talker characters.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Gn => "GN",
            Self::Gp => "GP",
        }
    }
}

impl std::str::FromStr for Talker {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_uppercase().as_str() {
            "GN" => Ok(Self::Gn),
            "GP" => Ok(Self::Gp),
            _ => Err(format!("unknown talker `{s}`, expected GN or GP")),
        }
    }
}

/// The GNSS receiver.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GnssConfig {
    /// Epoch rate, Hz: 1, 2, 4, 5, 10 or 20 (default 1).
    pub rate_hz: u32,
    /// What the receiver writes: `nmea` (RMC, VTG, GGA, GSA, GST, ZDA) or `ubx` (NAV-PVT,
    /// NAV-EOE, TIM-TP, and TIM-TM2 of the camera; `crate::ubx`) (default `nmea`).
    pub protocol: OutputProtocol,
    /// NMEA talker, `GN` or `GP` (default `GN`).
    pub talker: Talker,
    /// Output latency d0: the epoch's first NMEA byte leaves the receiver d0 after the epoch
    /// (the PPS edge for whole seconds), s (default 0.6; may exceed 1 s).
    pub latency_s: f64,
    /// 1-σ per-epoch jitter of the latency, s (default 0).
    pub latency_jitter_s: f64,
    /// Serial baud rate the shell paces the bytes at (default 115200).
    pub baud: u32,
    /// Horizontal position error, RMS over north and east, m (default 1.5: σ_N = σ_E = 1.5/√2).
    pub horizontal_rms_m: f64,
    /// Vertical position error, 1 σ, m (default 3).
    pub vertical_sigma_m: f64,
    /// Velocity error, 1 σ per NED axis, m/s (default 0.05).
    pub velocity_sigma_mps: f64,
    /// Correlation time of the position error (first-order Gauss–Markov), s; 0 = white (default).
    pub position_correlation_s: f64,
    /// Geoid separation N (ellipsoidal height − MSL altitude), m (default 0).
    pub geoid_separation_m: f64,
    /// Antenna position w.r.t. the body origin, body (FRD) axes, m (default 0).
    pub antenna_lever_arm_m: [f64; 3],
    /// Satellites used, reported in GGA and GSA (default 12).
    pub sats_used: u8,
    /// HDOP reported (default 0.8).
    pub hdop: f64,
    /// VDOP reported (default 1.2).
    pub vdop: f64,
    /// Period of the receiver's time-pulse clock, ns: each PPS edge comes out on that grid, up
    /// to half a period off the ideal second (a sawtooth over the seconds), and UBX output
    /// reports the error in TIM-TP `qErr` (default 0: ideal edges; a u-blox M8T's 48 MHz:
    /// 20.83).
    pub timepulse_quantization_ns: f64,
    /// Outages (TOML `[[gnss.outage]]`).
    #[serde(rename = "outage")]
    pub outages: Vec<OutageConfig>,
    /// The receiver's GPS signals: raw measurements and navigation data from a real almanac
    /// (TOML `[gnss.sky]`; [`crate::gps`]). With an almanac the receiver has no fix while it
    /// sees fewer than four satellites.
    pub sky: crate::gps::SkyConfig,
    /// A camera whose exposure pulse is wired into the receiver's EXTINT0 input, reported as
    /// UBX-TIM-TM2 time marks (TOML `[gnss.camera]`; [`crate::camera`]).
    pub camera: CameraConfig,
}

impl GnssConfig {
    /// The camera's trigger rate in force, Hz (0: no camera): `camera.rate_hz`, by default 1
    /// for a UBX receiver and 0 for NMEA, which has no time-mark message.
    pub fn camera_rate_hz(&self) -> f64 {
        self.camera.rate_hz.unwrap_or(match self.protocol {
            OutputProtocol::Ubx => DEFAULT_CAMERA_RATE_HZ,
            OutputProtocol::Nmea => 0.0,
        })
    }
}

/// Trigger rate of the camera of a UBX receiver without `gnss.camera.rate_hz`, Hz.
pub const DEFAULT_CAMERA_RATE_HZ: f64 = 1.0;

/// A camera on the receiver's EXTINT0 input ([`crate::camera`]). It is triggered on a grid of
/// true time: trigger k at the first whole UTC second of the scenario + k/`rate_hz`. Its
/// exposure starts `exposure_offset_s` (+ a seeded Gaussian jitter) after the trigger and
/// lasts `exposure_s`; its exposure-active output, high during the exposure, drives EXTINT0,
/// so the rising edge is the start of the exposure and the falling edge its end. The receiver
/// time-stamps both edges on its own clock and reports the latest of each in the TIM-TM2 of
/// the next navigation epoch (a camera faster than the epoch rate loses marks, as on a real
/// receiver: `count` still counts every rising edge).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraConfig {
    /// Trigger rate, Hz, 0 ≤ rate ≤ 100; 0 = no camera (default: 1 with `gnss.protocol =
    /// "ubx"`, none with `nmea`, where a rate > 0 is an error).
    pub rate_hz: Option<f64>,
    /// Start of the exposure after the trigger, s, 0 ≤ offset ≤ 1 (default 0.005).
    pub exposure_offset_s: f64,
    /// 1-σ jitter of that offset, s, drawn per trigger from the seed (default 10e-6).
    pub exposure_jitter_s: f64,
    /// Exposure time (the pulse's width), s, 1 µs ≤ width ≤ half the trigger period
    /// (default 0.002).
    pub exposure_s: f64,
}

impl Default for CameraConfig {
    fn default() -> Self {
        Self {
            rate_hz: None,
            exposure_offset_s: 0.005,
            exposure_jitter_s: 10e-6,
            exposure_s: 0.002,
        }
    }
}

impl Default for GnssConfig {
    fn default() -> Self {
        Self {
            rate_hz: 1,
            timepulse_quantization_ns: 0.0,
            protocol: OutputProtocol::Nmea,
            talker: Talker::Gn,
            latency_s: 0.6,
            latency_jitter_s: 0.0,
            baud: 115_200,
            horizontal_rms_m: 1.5,
            vertical_sigma_m: 3.0,
            velocity_sigma_mps: 0.05,
            position_correlation_s: 0.0,
            geoid_separation_m: 0.0,
            antenna_lever_arm_m: [0.0; 3],
            sats_used: 12,
            hdop: 0.8,
            vdop: 1.2,
            outages: Vec::new(),
            sky: crate::gps::SkyConfig::default(),
            camera: CameraConfig::default(),
        }
    }
}

/// A GNSS outage: the receiver keeps talking but has no fix.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutageConfig {
    /// Start, s of scenario time.
    pub start_s: f64,
    /// Length, s (> 0). Epochs in [start, start + duration) have no fix.
    pub duration_s: f64,
    /// Whether PPS edges continue during the outage (default true).
    #[serde(default = "default_true")]
    pub pps_continues: bool,
}

fn default_true() -> bool {
    true
}

/// The host oscillator (CLOCK_MONOTONIC) against true (GNSS/UTC) time, and PPS stamping.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ClockConfig {
    /// Fractional frequency error y of the host clock at the start, ppm: host time advances
    /// (1 + y) s per true second (default +0.5: the host gains 0.5 µs per second).
    pub freq_error_ppm: f64,
    /// Random-walk frequency noise, expressed as its Allan deviation at τ = 1 s (default 1e-10,
    /// a TCXO-class wander; 0 disables it). See [`Oscillator`](super::oscillator::Oscillator).
    pub freq_rw_adev_1s: f64,
    /// 1-σ jitter of the PPS edge's host time stamp, s (default 1 µs, kernel PPS).
    pub pps_jitter_s: f64,
    /// PPS outages (TOML `[[clock.pps_outage]]`): no edges while the fixes go on (a cut PPS
    /// line, a receiver that stops its time pulse). Default none.
    #[serde(rename = "pps_outage")]
    pub pps_outages: Vec<PpsOutageConfig>,
}

impl Default for ClockConfig {
    fn default() -> Self {
        Self {
            freq_error_ppm: 0.5,
            freq_rw_adev_1s: 1e-10,
            pps_jitter_s: 1e-6,
            pps_outages: Vec::new(),
        }
    }
}

/// A PPS outage: the receiver's PPS output is silent, its NMEA and fixes are not.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PpsOutageConfig {
    /// Start, s of scenario time.
    pub start_s: f64,
    /// Length, s (> 0). Edges of true seconds in [start, start + duration) are not emitted.
    pub duration_s: f64,
}

/// Ground-truth events.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TruthConfig {
    /// Rate of `SimTruth` events on a true-time grid from the start, Hz (default 100).
    pub rate_hz: f64,
}

impl Default for TruthConfig {
    fn default() -> Self {
        Self { rate_hz: 100.0 }
    }
}

impl SimConfig {
    /// Parses and validates a scenario. `origin` (usually the file path) is named in errors.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, SimError> {
        let source = SourceMap::build(text);
        let mut cfg: SimConfig = toml::from_str(text).map_err(|e| parse_error(&e, &source, origin))?;
        cfg.source = Some(source);
        cfg.origin = origin.to_owned();
        cfg.load_almanac()?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Reads `gnss.sky.almanac` (a path relative to the scenario file's folder when the
    /// origin is a file) into `gnss.sky.constellation`.
    fn load_almanac(&mut self) -> Result<(), SimError> {
        let Some(name) = self.gnss.sky.almanac.clone() else {
            return Ok(());
        };
        let path = Path::new(&name);
        let path = match Path::new(&self.origin).parent() {
            Some(dir) if path.is_relative() && !self.origin.starts_with('<') => dir.join(path),
            _ => path.to_path_buf(),
        };
        match crate::gps::read_yuma(&path) {
            Ok(c) => {
                self.gnss.sky.constellation = c;
                Ok(())
            }
            Err(e) => Err(self.invalid("gnss.sky.almanac", format!("the YUMA almanac: {e}"))),
        }
    }

    /// Reads, parses and validates a scenario file.
    pub fn from_file(path: &Path) -> Result<Self, SimError> {
        let origin = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| SimError::Io {
            origin: origin.clone(),
            source,
        })?;
        Self::from_toml_str(&text, &origin)
    }

    /// The embedded default scenario (`sim/scenarios/default_drive.toml`): a ~10 minute
    /// car drive with a static start, stops, turns both ways, speed changes and a gentle
    /// climb and descent.
    ///
    /// # Panics
    /// Never at run time: the embedded file is checked by the unit tests.
    pub fn default_drive() -> Self {
        match Self::from_toml_str(DEFAULT_DRIVE_TOML, DEFAULT_DRIVE_ORIGIN) {
            Ok(cfg) => cfg,
            Err(e) => panic!("embedded default scenario is invalid: {e}"),
        }
    }

    /// The resolved settings of IMU `index` (< `imu.count`).
    pub fn imu_unit(&self, index: usize) -> ResolvedImu {
        let unit = self.imu.units.get(index).cloned().unwrap_or_default();
        let rate_hz = unit.rate_hz.unwrap_or(self.imu.rate_hz);
        let period = 1.0 / rate_hz;
        let phase_s = unit.phase_s.unwrap_or_else(|| (index as f64 * 1.1e-3) % period);
        ResolvedImu {
            offset_s: unit.offset_s.unwrap_or_else(|| default_imu_offset_s(index)),
            rate_hz,
            phase_s,
            stamp_jitter_s: unit.stamp_jitter_s.unwrap_or(self.imu.stamp_jitter_s),
            preset: unit.preset.unwrap_or(self.imu.preset),
            mount_rpy_rad: unit.mount_rpy_deg.map(f64::to_radians),
            lever_arm_m: unit.lever_arm_m,
            clock_freq_error: if self.imu.device_clocks {
                imu_crystal_freq_error(index)
            } else {
                0.0
            },
            receiver_clock: unit.receiver_clock,
        }
    }

    /// Total scenario length, s (sum of the segment durations).
    pub fn duration_s(&self) -> f64 {
        self.trajectory.segments.iter().map(|s| s.duration_s).sum()
    }

    // ----- overrides (the process shell's command-line options) -----

    fn mark(&mut self, path: &'static str) {
        if !self.overridden.contains(&path) {
            self.overridden.push(path);
        }
    }

    /// Sets the seed of every random source.
    pub fn set_seed(&mut self, seed: u64) {
        self.seed = seed;
        self.mark("seed");
    }

    /// Sets the number of IMUs (validated by [`SimConfig::validate`]: 1..=MAX_IMUS).
    pub fn set_imu_count(&mut self, count: usize) {
        self.imu.count = count;
        self.mark("imu.count");
    }

    /// Sets the error model of every IMU (per-IMU presets from the file are dropped).
    pub fn set_imu_preset(&mut self, preset: ImuPreset) {
        self.imu.preset = preset;
        for unit in &mut self.imu.units {
            unit.preset = None;
        }
        self.mark("imu.preset");
    }

    /// Sets the sample rate of every IMU, Hz (per-IMU rates and phases from the file are dropped).
    pub fn set_imu_rate_hz(&mut self, rate_hz: f64) {
        self.imu.rate_hz = rate_hz;
        for unit in &mut self.imu.units {
            unit.rate_hz = None;
            unit.phase_s = None;
        }
        self.mark("imu.rate_hz");
    }

    /// Sets the stamp delays Td of IMUs 0, 1, …, s (IMUs beyond the slice keep theirs).
    pub fn set_imu_offsets_s(&mut self, offsets_s: &[f64]) {
        if self.imu.units.len() < offsets_s.len() {
            self.imu.units.resize_with(offsets_s.len(), ImuUnitConfig::default);
        }
        for (unit, &off) in self.imu.units.iter_mut().zip(offsets_s) {
            unit.offset_s = Some(off);
        }
        self.mark("imu.unit");
    }

    /// Lets every IMU sample on its own crystal ([`ImuArrayConfig::device_clocks`]).
    pub fn set_imu_device_clocks(&mut self, on: bool) {
        self.imu.device_clocks = on;
        self.mark("imu.device_clocks");
    }

    /// Sets the 1-σ stamp jitter of every IMU, s (per-IMU values from the file are dropped).
    pub fn set_imu_stamp_jitter_s(&mut self, jitter_s: f64) {
        self.imu.stamp_jitter_s = jitter_s;
        for unit in &mut self.imu.units {
            unit.stamp_jitter_s = None;
        }
        self.mark("imu.stamp_jitter_s");
    }

    /// Sets the GNSS epoch rate, Hz (1, 2, 4, 5, 10 or 20).
    pub fn set_gnss_rate_hz(&mut self, rate_hz: u32) {
        self.gnss.rate_hz = rate_hz;
        self.mark("gnss.rate_hz");
    }

    /// Sets the NMEA output latency d0 after the epoch, s.
    pub fn set_nmea_latency_s(&mut self, latency_s: f64) {
        self.gnss.latency_s = latency_s;
        self.mark("gnss.latency_s");
    }

    /// Sets the receiver's output protocol.
    pub fn set_gnss_protocol(&mut self, protocol: OutputProtocol) {
        self.gnss.protocol = protocol;
        self.mark("gnss.protocol");
    }

    /// Sets the NMEA talker.
    pub fn set_talker(&mut self, talker: Talker) {
        self.gnss.talker = talker;
        self.mark("gnss.talker");
    }

    /// Sets the serial baud rate.
    pub fn set_baud(&mut self, baud: u32) {
        self.gnss.baud = baud;
        self.mark("gnss.baud");
    }

    /// Sets the camera's trigger rate, Hz (0: no camera).
    pub fn set_camera_rate_hz(&mut self, rate_hz: f64) {
        self.gnss.camera.rate_hz = Some(rate_hz);
        self.mark("gnss.camera.rate_hz");
    }

    /// Sets the start of the camera's exposure after its trigger, s.
    pub fn set_camera_exposure_offset_s(&mut self, offset_s: f64) {
        self.gnss.camera.exposure_offset_s = offset_s;
        self.mark("gnss.camera.exposure_offset_s");
    }

    /// Sets the host clock's fractional frequency error, ppm.
    pub fn set_clock_ppm(&mut self, ppm: f64) {
        self.clock.freq_error_ppm = ppm;
        self.mark("clock.freq_error_ppm");
    }

    /// Sets the host clock's random-walk frequency noise (Allan deviation at 1 s; 0 = none).
    pub fn set_clock_rw_adev_1s(&mut self, adev: f64) {
        self.clock.freq_rw_adev_1s = adev;
        self.mark("clock.freq_rw_adev_1s");
    }

    /// Sets the 1-σ PPS stamp jitter, s.
    pub fn set_pps_jitter_s(&mut self, jitter_s: f64) {
        self.clock.pps_jitter_s = jitter_s;
        self.mark("clock.pps_jitter_s");
    }

    /// Removes all GNSS outages.
    pub fn clear_gnss_outages(&mut self) {
        self.gnss.outages.clear();
        self.mark("gnss.outage");
    }

    /// Switches the body vibration on or off (`[trajectory.vibration] enabled`).
    pub fn set_vibration(&mut self, enabled: bool) {
        self.trajectory.vibration.enabled = enabled;
        self.mark("trajectory.vibration.enabled");
    }

    /// Makes the world noise-free and exactly synchronous: `perfect` IMUs, zero stamp offsets
    /// and jitter, zero PPS and latency jitter, zero GNSS noise, no frequency wander
    /// (the constant frequency error is kept).
    pub fn set_noise_free(&mut self) {
        self.set_imu_preset(ImuPreset::Perfect);
        self.set_imu_stamp_jitter_s(0.0);
        let n = self.imu.count.max(self.imu.units.len());
        self.set_imu_offsets_s(&vec![0.0; n]);
        self.set_pps_jitter_s(0.0);
        self.set_clock_rw_adev_1s(0.0);
        self.gnss.latency_jitter_s = 0.0;
        self.gnss.horizontal_rms_m = 0.0;
        self.gnss.vertical_sigma_m = 0.0;
        self.gnss.velocity_sigma_mps = 0.0;
        self.gnss.camera.exposure_jitter_s = 0.0;
        self.mark("gnss");
    }

    // ----- validation -----

    /// Checks every value; the error names the origin, line and field.
    pub fn validate(&self) -> Result<(), SimError> {
        self.validate_trajectory()?;
        self.validate_vibration()?;
        self.validate_imus()?;
        self.validate_gnss()?;
        self.validate_clock()
    }

    /// An [`SimError::Invalid`] for field `path`, located through the source map.
    fn invalid(&self, path: &str, message: impl Into<String>) -> SimError {
        let overridden = self
            .overridden
            .iter()
            .any(|p| path == *p || path.starts_with(&format!("{p}.")));
        let overridden = overridden || self.overridden.iter().any(|p| path.starts_with(&format!("{p}[")));
        let (origin, line) = match (&self.source, overridden) {
            (Some(src), false) => (self.origin.clone(), src.locate(path).map(|(line, _)| line)),
            (Some(_), true) => (OVERRIDES_ORIGIN.to_owned(), None),
            (None, _) => ("<config>".to_owned(), None),
        };
        SimError::Invalid {
            origin,
            line,
            field: path.to_owned(),
            message: message.into(),
        }
    }

    fn check_range(&self, path: &str, value: f64, lo: f64, hi: f64, unit: &str) -> Result<(), SimError> {
        if value.is_finite() && value >= lo && value <= hi {
            Ok(())
        } else {
            Err(self.invalid(
                path,
                format!("{value} is out of range, expected {lo} ≤ value ≤ {hi} {unit}"),
            ))
        }
    }

    fn validate_trajectory(&self) -> Result<(), SimError> {
        let s = &self.trajectory.start;
        self.check_range("trajectory.start.lat_deg", s.lat_deg, -85.0, 85.0, "deg")?;
        self.check_range("trajectory.start.lon_deg", s.lon_deg, -180.0, 180.0, "deg")?;
        self.check_range("trajectory.start.height_m", s.height_m, -1000.0, 50_000.0, "m")?;
        self.check_range("trajectory.start.heading_deg", s.heading_deg, -360.0, 360.0, "deg")?;
        self.check_range(
            "trajectory.start.pitch_deg",
            s.pitch_deg,
            -MAX_PITCH_DEG,
            MAX_PITCH_DEG,
            "deg",
        )?;
        self.check_range("trajectory.start.speed_mps", s.speed_mps, 0.0, MAX_SPEED_MPS, "m/s")?;
        if self.trajectory.segments.is_empty() {
            return Err(self.invalid(
                "trajectory.segment",
                "the scenario has no motion segments, expected at least one",
            ));
        }
        let mut state = (s.speed_mps, s.pitch_deg);
        for (i, seg) in self.trajectory.segments.iter().enumerate() {
            state = self.validate_segment(i, seg, state)?;
        }
        let total = self.duration_s();
        if total > MAX_DURATION_S {
            return Err(self.invalid(
                "trajectory.segment",
                format!("total duration {total} s exceeds {MAX_DURATION_S} s"),
            ));
        }
        Ok(())
    }

    /// Checks segment `i` entered at (speed m/s, pitch deg); returns the state at its end.
    fn validate_segment(&self, i: usize, seg: &SegmentConfig, (v0, p0): (f64, f64)) -> Result<(f64, f64), SimError> {
        let kind = seg.kind.name();
        let at = |f: &str| format!("trajectory.segment[{i}].{f}");
        let ctx = format!("segment {i} ({kind})");
        if !(seg.duration_s.is_finite() && seg.duration_s >= MIN_SEGMENT_S && seg.duration_s <= MAX_DURATION_S) {
            return Err(self.invalid(
                &at("duration_s"),
                format!(
                    "{ctx}: duration {} s, expected {MIN_SEGMENT_S} s ≤ duration ≤ {MAX_DURATION_S} s",
                    seg.duration_s
                ),
            ));
        }
        let (allow_speed, allow_heading, allow_pitch) = match seg.kind {
            SegmentKind::Static | SegmentKind::Cruise => (false, false, false),
            SegmentKind::Accelerate | SegmentKind::Decelerate => (true, false, false),
            SegmentKind::Turn => (false, true, false),
            SegmentKind::Climb => (false, false, true),
            SegmentKind::Maneuver => (true, true, true),
        };
        for (present, allowed, field) in [
            (seg.to_speed_mps.is_some(), allow_speed, "to_speed_mps"),
            (seg.heading_change_deg.is_some(), allow_heading, "heading_change_deg"),
            (seg.to_pitch_deg.is_some(), allow_pitch, "to_pitch_deg"),
        ] {
            if present && !allowed {
                return Err(self.invalid(
                    &at(field),
                    format!("{ctx}: `{field}` is not allowed in a {kind} segment"),
                ));
            }
        }
        let v1 = seg.to_speed_mps.unwrap_or(v0);
        let p1 = seg.to_pitch_deg.unwrap_or(p0);
        let dpsi = seg.heading_change_deg.unwrap_or(0.0);
        self.check_range(&at("to_speed_mps"), v1, 0.0, MAX_SPEED_MPS, "m/s")
            .map_err(|e| self.with_context(e, &ctx))?;
        self.check_range(&at("to_pitch_deg"), p1, -MAX_PITCH_DEG, MAX_PITCH_DEG, "deg")
            .map_err(|e| self.with_context(e, &ctx))?;
        self.check_range(&at("heading_change_deg"), dpsi, -3600.0, 3600.0, "deg")
            .map_err(|e| self.with_context(e, &ctx))?;
        self.check_segment_kind(i, seg, &ctx, (v0, v1), (p0, p1), dpsi)?;
        Ok((v1, p1))
    }

    fn with_context(&self, e: SimError, ctx: &str) -> SimError {
        match e {
            SimError::Invalid {
                origin,
                line,
                field,
                message,
            } => SimError::Invalid {
                origin,
                line,
                field,
                message: format!("{ctx}: {message}"),
            },
            other => other,
        }
    }

    fn check_segment_kind(
        &self,
        i: usize,
        seg: &SegmentConfig,
        ctx: &str,
        (v0, v1): (f64, f64),
        (p0, p1): (f64, f64),
        dpsi: f64,
    ) -> Result<(), SimError> {
        let at = |f: &str| format!("trajectory.segment[{i}].{f}");
        let need = |field: &str, present: bool| -> Result<(), SimError> {
            if present {
                Ok(())
            } else {
                Err(self.invalid(&at(field), format!("{ctx}: missing `{field}`")))
            }
        };
        match seg.kind {
            SegmentKind::Static if v0 != 0.0 => Err(self.invalid(
                &at("kind"),
                format!("{ctx}: the vehicle moves at {v0} m/s when this static segment starts; expected speed 0 (decelerate to 0 first)"),
            )),
            SegmentKind::Accelerate => {
                need("to_speed_mps", seg.to_speed_mps.is_some())?;
                if v1 > v0 { Ok(()) } else {
                    Err(self.invalid(&at("to_speed_mps"), format!("{ctx}: to_speed_mps {v1} m/s, expected more than the entry speed {v0} m/s")))
                }
            }
            SegmentKind::Decelerate => {
                need("to_speed_mps", seg.to_speed_mps.is_some())?;
                if v1 < v0 { Ok(()) } else {
                    Err(self.invalid(&at("to_speed_mps"), format!("{ctx}: to_speed_mps {v1} m/s, expected less than the entry speed {v0} m/s")))
                }
            }
            SegmentKind::Turn | SegmentKind::Climb if v0 <= 0.0 => Err(self.invalid(
                &at("kind"),
                format!("{ctx}: a car cannot turn or change pitch while standing still; expected a speed > 0 at the segment start"),
            )),
            SegmentKind::Turn => {
                need("heading_change_deg", seg.heading_change_deg.is_some())?;
                if dpsi != 0.0 { Ok(()) } else { Err(self.invalid(&at("heading_change_deg"), format!("{ctx}: expected a non-zero heading change"))) }
            }
            SegmentKind::Climb => need("to_pitch_deg", seg.to_pitch_deg.is_some()),
            SegmentKind::Maneuver => {
                if seg.to_speed_mps.is_none() && seg.heading_change_deg.is_none() && seg.to_pitch_deg.is_none() {
                    return Err(self.invalid(&at("kind"), format!("{ctx}: expected at least one of to_speed_mps, heading_change_deg, to_pitch_deg")));
                }
                if (dpsi != 0.0 || p1 != p0) && v0 <= 0.0 && v1 <= 0.0 {
                    return Err(self.invalid(&at("kind"), format!("{ctx}: heading or pitch changes while standing still")));
                }
                Ok(())
            }
            _ => Ok(()),
        }
    }

    fn validate_vibration(&self) -> Result<(), SimError> {
        let v = &self.trajectory.vibration;
        self.check_range(
            "trajectory.vibration.reference_speed_mps",
            v.reference_speed_mps,
            0.5,
            MAX_SPEED_MPS,
            "m/s",
        )?;
        self.check_range("trajectory.vibration.roll_rms_deg", v.roll_rms_deg, 0.0, 2.0, "deg")?;
        self.check_range("trajectory.vibration.pitch_rms_deg", v.pitch_rms_deg, 0.0, 2.0, "deg")?;
        self.check_range("trajectory.vibration.heave_rms_m", v.heave_rms_m, 0.0, 0.05, "m")
    }

    fn validate_imus(&self) -> Result<(), SimError> {
        let imu = &self.imu;
        if imu.count == 0 || imu.count > MAX_IMUS {
            return Err(self.invalid(
                "imu.count",
                format!("{} IMUs, expected 1 ≤ count ≤ {MAX_IMUS}", imu.count),
            ));
        }
        self.check_range("imu.rate_hz", imu.rate_hz, 1.0, 4000.0, "Hz")?;
        self.check_range("imu.stamp_jitter_s", imu.stamp_jitter_s, 0.0, 0.1, "s")?;
        for i in 0..imu.count {
            self.validate_imu_unit(i)?;
        }
        Ok(())
    }

    fn validate_imu_unit(&self, i: usize) -> Result<(), SimError> {
        let at = |f: &str| format!("imu.unit[{i}].{f}");
        let unit = self.imu.units.get(i).cloned().unwrap_or_default();
        if let Some(rate) = unit.rate_hz {
            self.check_range(&at("rate_hz"), rate, 1.0, 4000.0, "Hz")?;
        }
        let r = self.imu_unit(i);
        let period = 1.0 / r.rate_hz;
        if !(r.phase_s.is_finite() && r.phase_s >= 0.0 && r.phase_s < period) {
            return Err(self.invalid(
                &at("phase_s"),
                format!(
                    "IMU {i}: phase {} s, expected 0 ≤ phase < {period} s (one period)",
                    r.phase_s
                ),
            ));
        }
        self.check_range(&at("offset_s"), r.offset_s, -1.0, 1.0, "s")?;
        if !(r.stamp_jitter_s.is_finite() && r.stamp_jitter_s >= 0.0 && r.stamp_jitter_s <= period / 10.0) {
            return Err(self.invalid(
                &at("stamp_jitter_s"),
                format!(
                    "IMU {i}: stamp jitter {} s, expected 0 ≤ jitter ≤ {} s (a tenth of the sample period)",
                    r.stamp_jitter_s,
                    period / 10.0
                ),
            ));
        }
        for (k, a) in unit.mount_rpy_deg.iter().enumerate() {
            self.check_range(&format!("{}[{k}]", at("mount_rpy_deg")), *a, -360.0, 360.0, "deg")?;
        }
        for (k, l) in unit.lever_arm_m.iter().enumerate() {
            self.check_range(&format!("{}[{k}]", at("lever_arm_m")), *l, -10.0, 10.0, "m")?;
        }
        if unit.receiver_clock && self.gnss.sky.almanac.is_none() {
            return Err(self.invalid(
                &at("receiver_clock"),
                format!("IMU {i} samples on the GNSS receiver's clock, which needs [gnss.sky] with an almanac"),
            ));
        }
        Ok(())
    }

    fn validate_gnss(&self) -> Result<(), SimError> {
        let g = &self.gnss;
        if !GNSS_RATES_HZ.contains(&g.rate_hz) {
            return Err(self.invalid(
                "gnss.rate_hz",
                format!("{} Hz, expected one of {GNSS_RATES_HZ:?}", g.rate_hz),
            ));
        }
        self.check_range("gnss.latency_s", g.latency_s, 0.0, 10.0, "s")?;
        self.check_range("gnss.latency_jitter_s", g.latency_jitter_s, 0.0, 0.1, "s")?;
        self.check_range("gnss.horizontal_rms_m", g.horizontal_rms_m, 0.0, 1000.0, "m")?;
        self.check_range("gnss.vertical_sigma_m", g.vertical_sigma_m, 0.0, 1000.0, "m")?;
        self.check_range("gnss.velocity_sigma_mps", g.velocity_sigma_mps, 0.0, 100.0, "m/s")?;
        self.check_range(
            "gnss.timepulse_quantization_ns",
            g.timepulse_quantization_ns,
            0.0,
            1000.0,
            "ns",
        )?;
        self.check_range("gnss.position_correlation_s", g.position_correlation_s, 0.0, 1e5, "s")?;
        self.check_range("gnss.geoid_separation_m", g.geoid_separation_m, -150.0, 150.0, "m")?;
        self.check_range("gnss.hdop", g.hdop, 0.0, 99.0, "")?;
        self.check_range("gnss.vdop", g.vdop, 0.0, 99.0, "")?;
        for (k, l) in g.antenna_lever_arm_m.iter().enumerate() {
            self.check_range(&format!("gnss.antenna_lever_arm_m[{k}]"), *l, -50.0, 50.0, "m")?;
        }
        // A burst of the six sentences is at most ~560 bytes of 10 bits each (8N1).
        let burst_s = MAX_BURST_BYTES as f64 * 10.0 / f64::from(g.baud.max(1));
        if g.baud < 1200 || burst_s >= 1.0 / f64::from(g.rate_hz) {
            return Err(self.invalid(
                "gnss.baud",
                format!("{} baud cannot carry one ~{MAX_BURST_BYTES}-byte NMEA burst per {} s epoch, expected a faster baud", g.baud, 1.0 / f64::from(g.rate_hz)),
            ));
        }
        for (i, o) in g.outages.iter().enumerate() {
            self.check_window(&format!("gnss.outage[{i}]"), o.start_s, o.duration_s)?;
        }
        self.validate_camera()?;
        self.validate_sky()
    }

    fn validate_camera(&self) -> Result<(), SimError> {
        let (g, c) = (&self.gnss, &self.gnss.camera);
        let rate = g.camera_rate_hz();
        self.check_range("gnss.camera.rate_hz", rate, 0.0, MAX_CAMERA_RATE_HZ, "Hz")?;
        if rate > 0.0 && g.protocol != OutputProtocol::Ubx {
            return Err(self.invalid(
                "gnss.camera.rate_hz",
                format!(
                    "a {rate} Hz camera: its time marks are written as UBX-TIM-TM2 (NMEA has none), expected gnss.protocol = \"ubx\" or rate_hz = 0"
                ),
            ));
        }
        self.check_range("gnss.camera.exposure_offset_s", c.exposure_offset_s, 0.0, 1.0, "s")?;
        if rate == 0.0 {
            return Ok(());
        }
        let period = 1.0 / rate;
        self.check_range(
            "gnss.camera.exposure_s",
            c.exposure_s,
            1e-6,
            period / 2.0,
            "s (half the trigger period)",
        )?;
        self.check_range(
            "gnss.camera.exposure_jitter_s",
            c.exposure_jitter_s,
            0.0,
            (period / 20.0).min(1e-3),
            "s (a twentieth of the trigger period, at most 1 ms)",
        )
    }

    fn validate_sky(&self) -> Result<(), SimError> {
        let (g, s) = (&self.gnss, &self.gnss.sky);
        if s.almanac.is_some() && g.protocol != OutputProtocol::Ubx {
            return Err(self.invalid(
                "gnss.sky.almanac",
                "raw measurements are written as UBX-RXM-RAWX and RXM-SFRBX, expected gnss.protocol = \"ubx\"",
            ));
        }
        self.check_range("gnss.sky.elevation_mask_deg", s.elevation_mask_deg, -5.0, 60.0, "deg")?;
        self.check_range("gnss.sky.pseudorange_sigma_m", s.pseudorange_sigma_m, 0.0, 100.0, "m")?;
        self.check_range("gnss.sky.multipath_sigma_m", s.multipath_sigma_m, 0.0, 100.0, "m")?;
        self.check_range(
            "gnss.sky.multipath_correlation_s",
            s.multipath_correlation_s,
            0.001,
            1e5,
            "s",
        )?;
        self.check_range(
            "gnss.sky.range_rate_sigma_mps",
            s.range_rate_sigma_mps,
            0.0,
            10.0,
            "m/s",
        )?;
        self.check_range("gnss.sky.broadcast_error_m", s.broadcast_error_m, 0.0, 100.0, "m")?;
        self.check_range("gnss.sky.ionosphere_scale", s.ionosphere_scale, 0.01, 10.0, "")?;
        self.check_range("gnss.sky.troposphere_scale", s.troposphere_scale, 0.5, 2.0, "")?;
        self.check_range("gnss.sky.clock_bias_s", s.clock_bias_s, -1e-3, 1e-3, "s")?;
        self.check_range("gnss.sky.clock_drift", s.clock_drift, -1e-5, 1e-5, "")?;
        self.check_range(
            "gnss.sky.clock_drift_random_walk",
            s.clock_drift_random_walk,
            0.0,
            1e-7,
            "1/√s",
        )?;
        for (i, w) in s.windows.iter().enumerate() {
            let at = format!("gnss.sky.window[{i}]");
            self.check_window(&at, w.start_s, w.duration_s)?;
            if let Some(half) = w.corridor_half_width_deg {
                self.check_range(&format!("{at}.corridor_half_width_deg"), half, 0.0, 90.0, "deg")?;
            }
            if let Some(m) = w.elevation_mask_deg {
                self.check_range(&format!("{at}.elevation_mask_deg"), m, -5.0, 90.0, "deg")?;
            }
        }
        // RXM-RAWX of 16 satellites and 16 RXM-SFRBX: ~1.4 kB more per epoch.
        let burst_s = (MAX_BURST_BYTES + 1400) as f64 * 10.0 / f64::from(g.baud.max(1));
        if s.almanac.is_some() && burst_s >= 1.0 / f64::from(g.rate_hz) {
            return Err(self.invalid(
                "gnss.baud",
                format!(
                    "{} baud cannot carry an epoch with raw measurements (~{} bytes) per {} s, expected a faster baud",
                    g.baud,
                    MAX_BURST_BYTES + 1400,
                    1.0 / f64::from(g.rate_hz)
                ),
            ));
        }
        Ok(())
    }

    /// An outage window `key` (`start_s`, `duration_s`): within the longest scenario, at least
    /// 1 ms long.
    fn check_window(&self, key: &str, start_s: f64, duration_s: f64) -> Result<(), SimError> {
        self.check_range(&format!("{key}.start_s"), start_s, 0.0, MAX_DURATION_S, "s")?;
        self.check_range(&format!("{key}.duration_s"), duration_s, 1e-3, MAX_DURATION_S, "s")
    }

    fn validate_clock(&self) -> Result<(), SimError> {
        let c = &self.clock;
        self.check_range("clock.freq_error_ppm", c.freq_error_ppm, -1000.0, 1000.0, "ppm")?;
        self.check_range("clock.freq_rw_adev_1s", c.freq_rw_adev_1s, 0.0, 1e-6, "")?;
        self.check_range("clock.pps_jitter_s", c.pps_jitter_s, 0.0, 0.01, "s")?;
        for (i, o) in c.pps_outages.iter().enumerate() {
            self.check_window(&format!("clock.pps_outage[{i}]"), o.start_s, o.duration_s)?;
        }
        self.check_range("truth.rate_hz", self.truth.rate_hz, 1.0, 1000.0, "Hz")
    }
}

/// GNSS epoch rates that divide one second into whole nanoseconds and centiseconds, Hz.
pub const GNSS_RATES_HZ: [u32; 6] = [1, 2, 4, 5, 10, 20];
/// Fastest camera trigger accepted, Hz.
pub const MAX_CAMERA_RATE_HZ: f64 = 100.0;
/// Largest |flight-path angle| accepted, degrees (keeps the Euler angles far from ±90°).
pub const MAX_PITCH_DEG: f64 = 45.0;
/// Largest speed accepted, m/s.
pub const MAX_SPEED_MPS: f64 = 300.0;
/// Shortest segment accepted, s.
pub const MIN_SEGMENT_S: f64 = 0.1;
/// Longest scenario accepted, s (6 h; the position table holds 100 nodes per second).
pub const MAX_DURATION_S: f64 = 6.0 * 3600.0;
/// Upper bound on the size of one NMEA burst, bytes (used to check the baud rate).
pub const MAX_BURST_BYTES: usize = 560;

/// A toml deserialization error as a [`SimError::Parse`] naming file, line, column and field.
fn parse_error(e: &toml::de::Error, source: &SourceMap, origin: &str) -> SimError {
    let pos = e.span().map_or(0, |s| s.start);
    let (line, column) = source.line_col(pos);
    let field = e
        .span()
        .and_then(|s| source.field_at(s.start))
        .unwrap_or("(document)")
        .to_owned();
    SimError::Parse {
        origin: origin.to_owned(),
        line,
        column,
        field,
        message: e.message().trim().to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn minimal(extra_segments: &str) -> String {
        format!(
            "[trajectory.start]\nlat_deg = 47.0\nlon_deg = 8.0\nheight_m = 400.0\nheading_deg = 0.0\n\n\
             [[trajectory.segment]]\nkind = \"static\"\nduration_s = 10.0\n{extra_segments}"
        )
    }

    #[test]
    fn default_drive_is_valid_and_about_ten_minutes() {
        let cfg = SimConfig::default_drive();
        let d = cfg.duration_s();
        assert!((540.0..=720.0).contains(&d), "duration {d}");
        assert!(
            cfg.trajectory.segments[0].kind == SegmentKind::Static && cfg.trajectory.segments[0].duration_s >= 30.0
        );
        assert_eq!(cfg.imu.count, 4);
        let offs: Vec<f64> = (0..4).map(|i| cfg.imu_unit(i).offset_s).collect();
        assert_eq!(offs, vec![0.0, 0.010, 0.015, 0.020]);
        let kinds: Vec<SegmentKind> = cfg.trajectory.segments.iter().map(|s| s.kind).collect();
        for k in [
            SegmentKind::Turn,
            SegmentKind::Climb,
            SegmentKind::Accelerate,
            SegmentKind::Decelerate,
        ] {
            assert!(kinds.contains(&k), "default drive lacks {k:?}");
        }
        let turns: Vec<f64> = cfg
            .trajectory
            .segments
            .iter()
            .filter_map(|s| s.heading_change_deg)
            .collect();
        assert!(
            turns.iter().any(|&t| t > 0.0) && turns.iter().any(|&t| t < 0.0),
            "turns both ways"
        );
        let stops = cfg
            .trajectory
            .segments
            .iter()
            .skip(1)
            .filter(|s| s.kind == SegmentKind::Static)
            .count();
        assert!(stops >= 1, "at least one stop");
    }

    #[test]
    fn minimal_scenario_gets_defaults() {
        let cfg = SimConfig::from_toml_str(&minimal(""), "m.toml").expect("valid");
        assert_eq!(cfg.gnss.rate_hz, 1);
        assert_eq!(cfg.gnss.baud, 115_200);
        assert!((cfg.clock.freq_error_ppm - 0.5).abs() < 1e-12);
        assert!((cfg.clock.pps_jitter_s - 1e-6).abs() < 1e-18);
        assert!((cfg.gnss.latency_s - 0.6).abs() < 1e-12);
        let u3 = cfg.imu_unit(3);
        assert!((u3.offset_s - 0.020).abs() < 1e-15);
        assert!((u3.phase_s - 3.3e-3).abs() < 1e-12);
    }

    #[test]
    fn pps_outages_are_read_and_validated() {
        let text = format!(
            "{}\n[[clock.pps_outage]]\nstart_s = 4.0\nduration_s = 3.0\n",
            minimal("")
        );
        let cfg = SimConfig::from_toml_str(&text, "p.toml").expect("valid");
        assert_eq!(cfg.clock.pps_outages.len(), 1);
        assert_eq!(
            (cfg.clock.pps_outages[0].start_s, cfg.clock.pps_outages[0].duration_s),
            (4.0, 3.0)
        );
        assert!(SimConfig::default_drive().clock.pps_outages.is_empty());
        let msg = SimConfig::from_toml_str(&text.replace("duration_s = 3.0", "duration_s = 0.0"), "p.toml")
            .expect_err("empty outage")
            .to_string();
        assert!(msg.contains("clock.pps_outage[0].duration_s"), "{msg}");
    }

    #[test]
    fn unknown_field_names_file_line_and_field() {
        let text = minimal("").replace("heading_deg = 0.0", "heading_deg = 0.0\nheadin_deg = 3.0");
        let err = SimConfig::from_toml_str(&text, "bad.toml").expect_err("unknown field");
        let msg = err.to_string();
        assert!(msg.starts_with("bad.toml:6:"), "{msg}");
        assert!(msg.contains("headin_deg"), "{msg}");
        assert!(msg.contains("expected"), "{msg}");
    }

    #[test]
    fn wrong_type_names_line_and_field() {
        let text = minimal("").replace("duration_s = 10.0", "duration_s = \"ten\"");
        let err = SimConfig::from_toml_str(&text, "bad.toml").expect_err("type error");
        match &err {
            SimError::Parse {
                origin,
                line,
                field,
                message,
                ..
            } => {
                assert_eq!(origin, "bad.toml");
                assert_eq!(*line, 9, "{err}");
                assert_eq!(field, "trajectory.segment[0].duration_s", "{err}");
                assert!(message.contains("expected"), "{message}");
            }
            other => panic!("unexpected {other}"),
        }
    }

    #[test]
    fn unknown_kind_missing_field_and_io_errors() {
        let text = minimal("").replace("kind = \"static\"", "kind = \"hover\"");
        let err = SimConfig::from_toml_str(&text, "k.toml").expect_err("bad kind");
        let msg = err.to_string();
        println!("{msg}");
        assert!(
            msg.starts_with("k.toml:8:") && msg.contains("hover") && msg.contains("static"),
            "{msg}"
        );
        let text = minimal("\n[[trajectory.segment]]\nkind = \"cruise\"\n");
        let msg = SimConfig::from_toml_str(&text, "m.toml")
            .expect_err("missing")
            .to_string();
        println!("{msg}");
        assert!(
            msg.starts_with("m.toml:11:") && msg.contains("segment[1]") && msg.contains("duration_s"),
            "{msg}"
        );
        let text = minimal("").replace("[trajectory.start]", "[imu]\nrate = 100\n\n[trajectory.start]");
        let msg = SimConfig::from_toml_str(&text, "u.toml")
            .expect_err("unknown")
            .to_string();
        println!("{msg}");
        assert!(msg.starts_with("u.toml:2:") && msg.contains("rate"), "{msg}");
        let err = SimConfig::from_file(Path::new("/nonexistent/scenario.toml")).expect_err("io");
        assert!(matches!(err, SimError::Io { .. }) && err.to_string().starts_with("/nonexistent/scenario.toml"));
    }

    #[test]
    fn sky_errors_name_the_field_and_the_almanac_line() {
        let dir = std::env::temp_dir().join(format!("navsync-sky-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("bad.yuma"), "**** Week 1 almanac ****\nID: 03\nHealth: x\n").unwrap();
        let origin = dir.join("s.toml").display().to_string();
        let text = minimal("\n[gnss]\nprotocol = \"ubx\"\n\n[gnss.sky]\nalmanac = \"bad.yuma\"\n");
        let msg = SimConfig::from_toml_str(&text, &origin)
            .expect_err("bad almanac")
            .to_string();
        println!("{msg}");
        assert!(
            msg.contains("gnss.sky.almanac") && msg.contains("bad.yuma: line 3"),
            "{msg}"
        );
        let text = minimal("\n[gnss.sky]\nalmanac = \"bad.yuma\"\n");
        let msg = SimConfig::from_toml_str(&text, "<text>")
            .expect_err("no file")
            .to_string();
        assert!(msg.contains("gnss.sky.almanac"), "{msg}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn syntax_error_has_line() {
        let err = SimConfig::from_toml_str("seed = 1\n[x", "s.toml").expect_err("syntax");
        assert!(err.to_string().starts_with("s.toml:2:"), "{err}");
    }

    #[test]
    fn static_segment_at_speed_names_segment_index_and_line() {
        let text = minimal(
            "\n[[trajectory.segment]]\nkind = \"accelerate\"\nduration_s = 5.0\nto_speed_mps = 10.0\n\n\
             [[trajectory.segment]]\nkind = \"static\"\nduration_s = 5.0\n",
        );
        let err = SimConfig::from_toml_str(&text, "s.toml").expect_err("static at speed");
        let msg = err.to_string();
        assert!(msg.contains("segment 2 (static)"), "{msg}");
        assert!(msg.contains("trajectory.segment[2].kind"), "{msg}");
        assert!(msg.starts_with("s.toml:17:"), "{msg}");
    }

    #[test]
    fn static_segment_with_speed_field_and_negative_duration() {
        let text = minimal("").replace("duration_s = 10.0", "duration_s = 10.0\nto_speed_mps = 3.0");
        let msg = SimConfig::from_toml_str(&text, "s.toml")
            .expect_err("field")
            .to_string();
        assert!(
            msg.contains("segment 0 (static)") && msg.contains("to_speed_mps") && msg.starts_with("s.toml:10:"),
            "{msg}"
        );
        let text = minimal("").replace("duration_s = 10.0", "duration_s = -1.0");
        let msg = SimConfig::from_toml_str(&text, "s.toml")
            .expect_err("negative")
            .to_string();
        assert!(
            msg.contains("segment 0 (static)") && msg.contains("duration") && msg.starts_with("s.toml:9:"),
            "{msg}"
        );
    }

    #[test]
    fn turn_while_standing_is_rejected() {
        let text = minimal("\n[[trajectory.segment]]\nkind = \"turn\"\nduration_s = 5.0\nheading_change_deg = 90.0\n");
        let msg = SimConfig::from_toml_str(&text, "s.toml")
            .expect_err("turn at rest")
            .to_string();
        assert!(msg.contains("segment 1 (turn)"), "{msg}");
    }

    #[test]
    fn overrides_are_validated_and_named() {
        let mut cfg = SimConfig::default_drive();
        cfg.set_imu_count(9);
        let msg = cfg.validate().expect_err("too many").to_string();
        assert!(msg.starts_with("overrides: imu.count"), "{msg}");
        cfg.set_imu_count(6);
        cfg.set_imu_offsets_s(&[0.0, 0.001]);
        cfg.set_gnss_rate_hz(10);
        cfg.set_talker("gp".parse().expect("talker"));
        cfg.set_imu_preset("industrial".parse().expect("preset"));
        cfg.validate().expect("valid overrides");
        assert!((cfg.imu_unit(1).offset_s - 0.001).abs() < 1e-15);
        assert!((cfg.imu_unit(5).offset_s - 0.030).abs() < 1e-15);
        assert_eq!(cfg.imu_unit(4).preset, ImuPreset::Industrial);
        cfg.set_gnss_rate_hz(3);
        assert!(cfg.validate().is_err());
    }

    #[test]
    fn camera_settings_defaults_and_errors() {
        // Default: a 1 Hz camera on a UBX receiver, none on an NMEA one.
        let mut cfg = SimConfig::from_toml_str(&minimal(""), "c.toml").expect("valid");
        assert_eq!(cfg.gnss.camera_rate_hz(), 0.0);
        cfg.set_gnss_protocol(OutputProtocol::Ubx);
        assert_eq!(cfg.gnss.camera_rate_hz(), DEFAULT_CAMERA_RATE_HZ);
        let c = &cfg.gnss.camera;
        assert_eq!(
            (c.exposure_offset_s, c.exposure_jitter_s, c.exposure_s),
            (0.005, 10e-6, 0.002)
        );
        // The file's table (lines 11-17 after the minimal scenario's ten).
        let base = minimal(
            "\n[gnss]\nprotocol = \"ubx\"\n\n[gnss.camera]\nrate_hz = 10.0\nexposure_offset_s = 0.02\nexposure_jitter_s = 1e-4\nexposure_s = 0.004\n",
        );
        let cfg = SimConfig::from_toml_str(&base, "c.toml").expect("valid");
        let c = &cfg.gnss.camera;
        assert_eq!(cfg.gnss.camera_rate_hz(), 10.0);
        assert_eq!(
            (c.exposure_offset_s, c.exposure_jitter_s, c.exposure_s),
            (0.02, 1e-4, 0.004)
        );
        for (from, to, field, line) in [
            ("rate_hz = 10.0", "rate_hz = 200.0", "rate_hz", 15),
            ("exposure_s = 0.004", "exposure_s = 0.06", "exposure_s", 18),
            (
                "exposure_jitter_s = 1e-4",
                "exposure_jitter_s = 6e-3",
                "exposure_jitter_s",
                17,
            ),
            (
                "exposure_offset_s = 0.02",
                "exposure_offset_s = -0.1",
                "exposure_offset_s",
                16,
            ),
            ("protocol = \"ubx\"", "protocol = \"nmea\"", "rate_hz", 15),
        ] {
            let msg = SimConfig::from_toml_str(&base.replace(from, to), "c.toml")
                .expect_err("invalid")
                .to_string();
            println!("{msg}");
            assert!(
                msg.starts_with(&format!("c.toml:{line}:")) && msg.contains(&format!("gnss.camera.{field}")),
                "{msg}"
            );
        }
        // Overrides: a camera on an NMEA receiver is named as such; rate 0 switches it off.
        let mut cfg = SimConfig::default_drive();
        cfg.set_camera_rate_hz(1.0);
        let msg = cfg.validate().expect_err("NMEA").to_string();
        assert!(
            msg.starts_with("overrides: gnss.camera.rate_hz") && msg.contains("TIM-TM2"),
            "{msg}"
        );
        cfg.set_camera_rate_hz(0.0);
        cfg.validate().expect("no camera");
    }

    #[test]
    fn vibration_defaults_and_switch() {
        let cfg = SimConfig::default_drive();
        let v = &cfg.trajectory.vibration;
        assert!(v.enabled && v.heave_rms_m > 0.0 && v.roll_rms_deg > 0.0 && v.pitch_rms_deg > 0.0);
        // A scenario without the table vibrates with the defaults.
        let m = SimConfig::from_toml_str(&minimal(""), "m.toml").expect("valid");
        let d = VibrationConfig::default();
        assert!(m.trajectory.vibration.enabled);
        assert_eq!(
            (m.trajectory.vibration.roll_rms_deg, m.trajectory.vibration.heave_rms_m),
            (d.roll_rms_deg, d.heave_rms_m)
        );
        // The embedded file writes the defaults.
        assert_eq!(
            (v.reference_speed_mps, v.roll_rms_deg, v.pitch_rms_deg, v.heave_rms_m),
            (d.reference_speed_mps, d.roll_rms_deg, d.pitch_rms_deg, d.heave_rms_m)
        );
        let mut off = cfg.clone();
        off.set_vibration(false);
        off.validate().expect("valid");
        assert!(!off.trajectory.vibration.enabled);
        let text = minimal("\n[trajectory.vibration]\nenabled = false\n");
        let cfg = SimConfig::from_toml_str(&text, "v.toml").expect("valid");
        assert!(!cfg.trajectory.vibration.enabled && cfg.trajectory.vibration.heave_rms_m == d.heave_rms_m);
    }

    #[test]
    fn vibration_errors_name_file_line_and_field() {
        let base = minimal("\n[trajectory.vibration]\nroll_rms_deg = 0.1\nheave_rms_m = 0.004\n");
        SimConfig::from_toml_str(&base, "v.toml").expect("valid");
        // Unknown field (line 13).
        let text = base.replace("heave_rms_m = 0.004", "heave_rms = 0.004");
        let msg = SimConfig::from_toml_str(&text, "v.toml")
            .expect_err("unknown")
            .to_string();
        assert!(msg.starts_with("v.toml:13:") && msg.contains("heave_rms"), "{msg}");
        // Wrong type.
        let text = base.replace("roll_rms_deg = 0.1", "roll_rms_deg = \"big\"");
        match SimConfig::from_toml_str(&text, "v.toml").expect_err("type") {
            SimError::Parse { line, field, .. } => {
                assert_eq!((line, field.as_str()), (12, "trajectory.vibration.roll_rms_deg"));
            }
            other => panic!("unexpected {other}"),
        }
        // Out of range: negative, too large, not finite.
        for (from, to, field, line) in [
            ("roll_rms_deg = 0.1", "roll_rms_deg = -0.1", "roll_rms_deg", 12),
            ("heave_rms_m = 0.004", "heave_rms_m = 0.5", "heave_rms_m", 13),
            ("heave_rms_m = 0.004", "heave_rms_m = nan", "heave_rms_m", 13),
            (
                "heave_rms_m = 0.004",
                "heave_rms_m = 0.004\npitch_rms_deg = 9.0",
                "pitch_rms_deg",
                14,
            ),
            (
                "heave_rms_m = 0.004",
                "heave_rms_m = 0.004\nreference_speed_mps = 0.0",
                "reference_speed_mps",
                14,
            ),
        ] {
            let text = base.replace(from, to);
            let err = SimConfig::from_toml_str(&text, "v.toml").expect_err("range");
            let msg = err.to_string();
            println!("{msg}");
            assert!(msg.starts_with(&format!("v.toml:{line}:")), "{msg}");
            assert!(
                msg.contains(&format!("trajectory.vibration.{field}")) && msg.contains("expected"),
                "{msg}"
            );
        }
    }
}
