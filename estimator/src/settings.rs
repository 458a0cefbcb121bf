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
use navsync_wire::imu_spec::{ImuNoise, ImuPreset};
use navsync_wire::services;

use crate::array::imu_array::{ArrayConfig, UnitConfig};
use crate::array::imu_offset::OffsetConfig;
use crate::declare::checks::{count_within, ids, positive, within};
use crate::declare::{Group, Invalid, Spec};
use crate::evaluation::DelayTruth;
use crate::nav::error_state::ProcessNoise;
use crate::nav::measurements::MeasurementConfig;
use crate::nav::measurements::gnss::GnssAccuracy;
use crate::nav::navigator::NavConfig;
use crate::pipeline::PipelineConfig;
use crate::time::device_timing::DeviceTimingConfig;
use crate::time::time_sync::TimeSyncConfig;

pub use crate::nav::config::{Coupling, InitialState, ReceiverOscillator};
pub use crate::time::time_sync::TimeAxis;

/// Where one IMU sits in the body frame.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ImuMounting {
    /// Rotation IMU axes → body (FRD): x_body = C_b^s · x_imu.
    pub c_b_s: [[f64; 3]; 3],
    /// Position of the IMU in the body frame (FRD), m.
    pub lever_b_m: [f64; 3],
}

crate::settings_group! {
    /// Which services the estimator fuses, by device id.
    #[derive(Debug, Clone, PartialEq)]
    pub struct Inputs {
        /// GNSS receiver ids (`navsync/gnss/{id}/fix`; in the file, every `[gnss.*]` when not
        /// given).
        pub gnss: Vec<String> = vec!["0".into()], file "estimator", flag "gnss", check ids(0, 8);
        /// PPS source ids (`navsync/pps/{id}/edge`; in the file, every `[pps.*]` when not given).
        pub pps: Vec<String> = vec!["0".into()], file "estimator", flag "pps", check ids(0, 8);
        /// IMU ids (`navsync/imu/{id}/sample`), the reference (which paces the output) first
        /// (in the file, every `[imu.*]` in id order when not given).
        pub imus: Vec<String> = vec!["0".into()], file "estimator", flag "imus", check ids(1, 8);
        /// Trigger input ids (`navsync/trigger/{id}/event`, `navsync trigger`): each edge gets
        /// its pose on `navsync/event/{id}/pose`, as a receiver's TIM-TM2 marks do.
        pub triggers: Vec<String> = Vec::new(), file "estimator", flag "triggers", check ids(0, 8);
        /// Where the host clock's GNSS time comes from: gnss (the receivers' PPS and fixes),
        /// chrony (a host without a receiver on a master's time base: chronyd's tracking report,
        /// `chronyc tracking`) or system (the kernel's NTP state of a clock a time
        /// daemon disciplines). With chrony or system the PPS inputs are not read.
        pub time_source: TimeSource = TimeSource::Gnss, file "estimator", flag "time-source";
        /// Where chronyd answers `chronyc tracking` with `time_source = "chrony"` (chronyc's
        /// `-h`): an address (chronyd's command port 323, open to local users for monitoring) or
        /// the path of its Unix command socket (root and chronyd's user only).
        pub chrony_address: String = "127.0.0.1".into(), file "estimator", flag "chrony-address";
        /// Seconds of navigation states kept in shared memory for `state_at` queries (the
        /// client API's `History`): 1000 records of 256 bytes a second, enough for a reference
        /// IMU at up to 1 kHz (10 s: 2.56 MB).
        pub history_s: f64 = 10.0, file "estimator", flag "history-s", check within(1.0, 300.0);
    }
}

/// Where the host clock's GNSS time comes from ([`Inputs::time_source`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TimeSource {
    /// The receivers' PPS edges and fixes (the default).
    #[default]
    Gnss,
    /// chronyd's tracking report (`chronyc tracking` through the command socket).
    Chrony,
    /// The kernel's NTP state (`adjtimex(2)`): a clock chronyd or ntpd disciplines.
    System,
}

impl TimeSource {
    /// True for the sources that are a network time service.
    pub fn is_network(self) -> bool {
        !matches!(self, Self::Gnss)
    }
}

crate::enum_setting!(TimeSource);

impl std::str::FromStr for TimeSource {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "gnss" => Ok(Self::Gnss),
            "chrony" => Ok(Self::Chrony),
            "system" => Ok(Self::System),
            _ => Err(format!("unknown time source `{s}`, expected gnss, chrony or system")),
        }
    }
}

crate::settings_group! {
    /// The IMU's error model: the filter's process noise and the array's noise.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct ImuModel {
        /// IMU class for the filter's process noise when `imu_noise` is not given: generic (an
        /// IMU of unknown class as it behaves in use), consumer, industrial, perfect (on the
        /// command line it replaces a model from the file or the recording).
        pub imu_model: ImuPreset = ImuPreset::Generic, file "estimator", flag "imu-model";
        /// The IMU's noise model in KF-GINS's units (`[estimator.imu_noise]`), overriding
        /// `imu_model`'s; refined field by field by `--arw`, `--vrw`, … .
        pub imu_noise: Option<ImuNoise> = None, file "estimator";
    }
}

crate::settings_group! {
    /// Tuning of the IMU array (offset estimation, alignment and fusion of several IMUs).
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct ArrayTuning {
        /// Estimate the IMUs' time offsets (off: held at zero, an uncompensated array, for
        /// comparison runs).
        pub estimate_imu_offsets: bool = true, file "estimator", switch "no-imu-offsets" => false;
        /// Order N of the Lagrange fractional-delay filter (5: 6 taps; the cubic's phase
        /// error under a car's vibration biased Td by 12–23 µs at 0.9 of a sample).
        pub lagrange_order: usize = 5, check count_within(1, 7);
        /// 1-sigma of the prior of each IMU's time offset Td, s.
        pub td_prior_std_s: f64 = 0.1, check positive;
        /// Random walk of Td, s/√s (a crystal's drift between two IMUs' stamps).
        pub td_rw: f64 = 1e-6;
        /// An offset is observable (and updated) only while the information of the current
        /// window exceeds this many times the prior's.
        pub min_information_ratio: f64 = 4.0;
        /// An IMU joins the fused array once σ(Td) is below this, s (0.3 ms).
        pub admit_td_std_s: f64 = 3e-4;
        /// No sample for this long (plus its own offset) makes an IMU stale, s.
        pub stale_after_s: f64 = 0.05;
        /// Consecutive gated comparisons that drop an IMU as disagreeing.
        pub disagree_after: u32 = 20;
        /// Consecutive accepted comparisons that re-admit it.
        pub agree_after: u32 = 400;
        /// Half-width of the low-noise Savitzky–Golay differentiator of the reference's rates,
        /// samples.
        pub derivative_half_width: usize = 20;
        /// Half-width of the fast (wide-band) differentiator, samples.
        pub derivative_half_width_fast: usize = 3;
    }
}

/// Everything the estimator needs to be built: the groups of settings, each declared where it
/// acts ([`crate::declare`]), and the IMUs' mountings. `Default`: one receiver, PPS source and
/// IMU with id "0"; hardware sync; industrial IMU; Δ estimated.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Settings {
    /// Which services it fuses.
    pub inputs: Inputs,
    /// The IMU's error model.
    pub imu: ImuModel,
    /// The IMU array's tuning.
    pub array: ArrayTuning,
    /// Mountings by IMU id (from each `[imu.ID] mounting`); an IMU without one is mounted as
    /// the body frame at its origin.
    pub imu_mountings: BTreeMap<String, ImuMounting>,
    /// Time synchronisation.
    pub time: TimeSyncConfig,
    /// The IMUs' device clocks.
    pub device_timing: DeviceTimingConfig,
    /// The navigation filter (its `noise` is made from [`Self::imu`] by
    /// [`Self::pipeline_config`]).
    pub nav: NavConfig,
    /// How the fixes' accuracy becomes the measurement noise.
    pub gnss: GnssAccuracy,
    /// Each kind of measurement's settings.
    pub measurements: MeasurementConfig,
}

/// Runs `$body` with `$g` bound to each settings group of `$s` in turn (`mut` for a mutable
/// borrow): the one list of the groups [`Settings`] is made of.
macro_rules! each_group {
    ($s:expr, mut $g:ident => $body:block) => {
        each_group!(@ $s, (mut), $g, $body)
    };
    ($s:expr, $g:ident => $body:block) => {
        each_group!(@ $s, (), $g, $body)
    };
    (@ $s:expr, ($($m:tt)?), $g:ident, $body:block) => {{
        { let $g = & $($m)? $s.inputs; $body }
        { let $g = & $($m)? $s.imu; $body }
        { let $g = & $($m)? $s.array; $body }
        { let $g = & $($m)? $s.time; $body }
        { let $g = & $($m)? $s.device_timing; $body }
        { let $g = & $($m)? $s.nav; $body }
        { let $g = & $($m)? $s.nav.align; $body }
        { let $g = & $($m)? $s.nav.integrity; $body }
        { let $g = & $($m)? $s.measurements.gnss; $body }
        { let $g = & $($m)? $s.measurements.zupt; $body }
        { let $g = & $($m)? $s.gnss; $body }
    }};
}

/// The [`Spec`]s of `g`'s group.
fn specs_of<G: Group>(_: &G) -> &'static [Spec] {
    G::SPECS
}

/// Whether `g`'s group declares `name` in file section `section`.
fn declares<G: Group>(_: &G, section: &str, name: &str) -> bool {
    G::SPECS.iter().any(|s| s.name == name && s.section == Some(section))
}

impl Settings {
    /// Every declared setting, group by group (names are unique across groups).
    pub fn specs() -> Vec<&'static Spec> {
        let s = Self::default();
        let mut out = Vec::new();
        each_group!(s, g => {
            out.extend(specs_of(g));
        });
        out
    }

    /// Sets setting `name` from a command-line flag's text.
    pub fn set_text(&mut self, name: &str, text: &str) -> Result<(), String> {
        each_group!(self, mut g => {
            if let Some(r) = g.set_text(name, text) {
                return r;
            }
        });
        Err(format!("no setting `{name}` has a command-line form"))
    }

    /// Sets setting `name` of the file's section `section` from its value; `None` when no
    /// setting is read from there.
    pub fn set_value<'de, D: serde::Deserializer<'de>>(
        &mut self,
        section: &str,
        name: &str,
        value: D,
    ) -> Option<Result<(), D::Error>> {
        each_group!(self, mut g => {
            if declares(g, section, name) {
                return g.set_value(section, name, value);
            }
        });
        None
    }

    /// The settings in force as JSON, for a recording of the live run: every setting of the
    /// file's sections (`{"file": {section: {name: value}}}`), the antenna lever arm and the
    /// IMUs' mountings. [`Self::apply_in_force`] reads it back.
    pub fn in_force_json(&self) -> String {
        let mut file = serde_json::Map::new();
        each_group!(self, g => {
            for (section, name, value) in g.file_values() {
                let sec = file
                    .entry(section.to_string())
                    .or_insert_with(|| serde_json::Value::Object(serde_json::Map::new()));
                if let serde_json::Value::Object(m) = sec {
                    m.insert(name.to_string(), value);
                }
            }
        });
        serde_json::json!({
            "file": file,
            "gnss_lever_arm_m": self.nav.gnss_lever_arm_m,
            "imu_mountings": self.imu_mountings,
        })
        .to_string()
    }

    /// Sets what [`Self::in_force_json`] wrote; an error names the setting that does not read
    /// (a recording of another version).
    pub fn apply_in_force(&mut self, json: &str) -> Result<(), String> {
        let v: serde_json::Value = serde_json::from_str(json).map_err(|e| format!("not JSON: {e}"))?;
        if let Some(file) = v["file"].as_object() {
            for (section, values) in file {
                for (name, value) in values.as_object().into_iter().flatten() {
                    match self.set_value(section, name, value.clone()) {
                        Some(Ok(())) => {}
                        Some(Err(e)) => return Err(format!("{section}.{name}: {e}")),
                        None => return Err(format!("{section}.{name}: no such setting")),
                    }
                }
            }
        }
        if !v["gnss_lever_arm_m"].is_null() {
            self.nav.gnss_lever_arm_m =
                serde_json::from_value(v["gnss_lever_arm_m"].clone()).map_err(|e| format!("gnss_lever_arm_m: {e}"))?;
        }
        if !v["imu_mountings"].is_null() {
            self.imu_mountings =
                serde_json::from_value(v["imu_mountings"].clone()).map_err(|e| format!("imu_mountings: {e}"))?;
        }
        Ok(())
    }

    /// The first setting whose value fails its check.
    pub fn check(&self) -> Result<(), Invalid> {
        each_group!(self, g => {
            g.check()?;
        });
        Ok(())
    }

    /// Setting `name`'s value as text (the file's and the command line's settings).
    pub fn show(&self, name: &str) -> Option<String> {
        each_group!(self, g => {
            if let Some(v) = g.show(name) {
                return Some(v);
            }
        });
        None
    }

    /// The services these settings subscribe to (PPS, GNSS fixes and time pulses, IMUs; the
    /// raw measurements and navigation data when tightly coupled).
    pub fn input_services(&self) -> Vec<String> {
        let pps = self.inputs.pps.iter().map(|id| services::pps_edge(id));
        let gnss = self.inputs.gnss.iter().map(|id| services::gnss_fix(id));
        let pulses = self.inputs.gnss.iter().map(|id| services::gnss_time_pulse(id));
        let imus = self.inputs.imus.iter().map(|id| services::imu_sample(id));
        let tight = self.nav.coupling.uses_raw();
        let raw = self
            .inputs
            .gnss
            .iter()
            .filter(|_| tight)
            .flat_map(|id| [services::gnss_raw(id), services::gnss_nav_data(id)]);
        // A receiver's event marks (TIM-TM2): each gets its pose ([`crate::events`]).
        let events = self.inputs.gnss.iter().map(|id| services::gnss_event(id));
        let triggers = self.inputs.triggers.iter().map(|id| services::trigger_event(id));
        pps.chain(gnss)
            .chain(pulses)
            .chain(events)
            .chain(triggers)
            .chain(imus)
            .chain(raw)
            .collect()
    }

    /// Which Δ the filter should find (for the accuracy report against a simulated truth).
    pub fn delay_truth(&self) -> DelayTruth {
        if self.time.software_sync {
            DelayTruth::ReceiverLatency
        } else {
            DelayTruth::Zero
        }
    }

    /// The IMU noise model in force: `imu_noise`, else the preset's.
    pub fn noise(&self) -> ImuNoise {
        self.imu.imu_noise.unwrap_or_else(|| self.imu.imu_model.noise())
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
                .inputs
                .imus
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
                td_prior_std_s: if t.estimate_imu_offsets {
                    t.td_prior_std_s
                } else {
                    1e-12
                },
                td_rw: if t.estimate_imu_offsets { t.td_rw } else { 0.0 },
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
        PipelineConfig {
            time: self.time,
            nav: NavConfig {
                noise: ProcessNoise::from_imu_noise(&self.noise()),
                ..self.nav
            },
            gnss: self.gnss,
            measurements: self.measurements,
            reference_imu: self.inputs.imus.first().cloned().unwrap_or_else(|| "0".into()),
            array: self.array_config(),
            device_timing: self.device_timing,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_settings_in_force_read_back_exactly() {
        let mut s = Settings::default();
        s.set_text("imu_model", "consumer").unwrap();
        s.set_text("gnss_vel_std_mps", "0.05").unwrap();
        s.set_text("imus", "0,1,2,3").unwrap();
        s.nav.gnss_lever_arm_m = [0.1, -0.2, 0.3];
        s.imu.imu_noise = Some(ImuPreset::Industrial.noise());
        s.imu_mountings.insert(
            "1".into(),
            ImuMounting {
                c_b_s: [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]],
                lever_b_m: [0.01, 0.02, 0.03],
            },
        );
        let json = s.in_force_json();
        println!("{} bytes: {json}", json.len());
        // Room to grow in the sample that carries it.
        assert!(
            json.len() <= navsync_wire::samples::SETTINGS_JSON_BYTES / 2,
            "{} bytes",
            json.len()
        );
        let mut back = Settings::default();
        back.apply_in_force(&json).unwrap();
        assert_eq!(back, s);
        let e = back
            .apply_in_force(r#"{"file": {"estimator": {"no_such": 1}}}"#)
            .unwrap_err();
        assert!(e.contains("estimator.no_such"), "{e}");
    }
}
