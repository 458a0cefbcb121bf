//! The estimator's settings on the command line and in the file, resolved into one
//! [`Settings`]: per field a flag given on the command line, else `[estimator]`/`[timing]`
//! (and each IMU's `mounting`, the first receiver's `lever_arm_m`), else the default of
//! [`Settings`]. The live `navsync estimator` and every offline tool (`replay --estimate`,
//! `sim --fast --estimate`, `report`, `analyze`) take the same flags ([`EstimatorFlags`]).

use navsync_estimator::settings::{ImuMounting, Settings};
use navsync_shared::imu_spec::ImuPreset;

use super::{ConfigError, Loaded};

/// A device id as used in service names: letters, digits, `-` and `_`.
pub fn parse_id(s: &str) -> Result<String, String> {
    if super::valid_id(s) {
        Ok(s.to_string())
    } else {
        Err(format!("`{s}`: an id is 1 to 16 letters, digits, `-` and `_`"))
    }
}

/// The estimator's flags (each overrides the file; absent flags leave the file's value).
#[derive(clap::Args, Debug, Clone, Default)]
pub struct EstimatorFlags {
    /// Which services it fuses.
    #[command(flatten)]
    pub inputs: InputFlags,
    /// How it models and fuses them.
    #[command(flatten)]
    pub model: ModelFlags,
}

/// The estimator's inputs by id.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct InputFlags {
    /// GNSS receiver ids [default: every [gnss.*] of the file, else 0].
    #[arg(long, value_delimiter = ',', value_parser = parse_id)]
    pub gnss: Option<Vec<String>>,
    /// PPS source ids [default: every [pps.*] of the file, else 0].
    #[arg(long, value_delimiter = ',', value_parser = parse_id)]
    pub pps: Option<Vec<String>>,
    /// IMU ids, the reference (which paces the output) first [default: every [imu.*], else 0].
    #[arg(long, value_delimiter = ',', value_parser = parse_id)]
    pub imus: Option<Vec<String>>,
}

/// The estimator's models and switches.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct ModelFlags {
    /// Ignore PPS: stamp fixes by receipt time (software sync, ms-level time)
    /// [default: [timing].software_sync, else off].
    #[arg(long)]
    pub software_sync: bool,
    /// IMU class for the filter's process noise: consumer, industrial, perfect
    /// [default: [estimator].imu_model, else industrial].
    #[arg(long)]
    pub imu_model: Option<ImuPreset>,
    /// Do not estimate the GNSS delay Δ (for comparison runs) [default: estimated].
    #[arg(long)]
    pub no_delay_state: bool,
    /// Fuse the IMUs without estimating their time offsets (for comparison runs)
    /// [default: estimated].
    #[arg(long)]
    pub no_imu_offsets: bool,
    /// No zero-velocity updates while standing still [default: [estimator].zupt, else on].
    #[arg(long)]
    pub no_zupt: bool,
    /// 1-sigma of the receiver's velocity per axis, m/s [default: [estimator].gnss_vel_std_mps,
    /// else 0.1].
    #[arg(long = "gnss-vel-std")]
    pub gnss_vel_std_mps: Option<f64>,
}

impl EstimatorFlags {
    /// The settings: `defaults`, then the file, then the flags given.
    pub fn settings_over(&self, cfg: &Loaded, defaults: Settings) -> Result<Settings, ConfigError> {
        let mut s = defaults;
        apply_file(&mut s, cfg)?;
        let i = &self.inputs;
        if let Some(ids) = &i.gnss {
            s.gnss_ids = ids.clone();
        }
        if let Some(ids) = &i.pps {
            s.pps_ids = ids.clone();
        }
        if let Some(ids) = &i.imus {
            s.imu_ids = ids.clone();
        }
        self.model.apply(&mut s);
        if s.imu_ids.is_empty() {
            return Err(cfg.error_at("estimator.imus", "no IMU: the estimator needs at least one"));
        }
        Ok(s)
    }

    /// The settings over [`Settings::default`].
    pub fn settings(&self, cfg: &Loaded) -> Result<Settings, ConfigError> {
        self.settings_over(cfg, Settings::default())
    }
}

impl ModelFlags {
    /// The flags given, over `s`.
    pub fn apply(&self, s: &mut Settings) {
        if self.software_sync {
            s.software_sync = true;
        }
        if let Some(m) = self.imu_model {
            s.imu_model = m;
        }
        if self.no_delay_state {
            s.estimate_delay = false;
        }
        if self.no_imu_offsets {
            s.estimate_imu_offsets = false;
        }
        if self.no_zupt {
            s.zupt = false;
        }
        if let Some(v) = self.gnss_vel_std_mps {
            s.gnss_vel_std_mps = v;
        }
    }
}

/// Applies what the file says about the estimator to `s`.
pub fn apply_file(s: &mut Settings, cfg: &Loaded) -> Result<(), ConfigError> {
    let c = &cfg.config;
    let e = &c.estimator;
    if let Some(ids) = cfg.estimator_gnss() {
        s.gnss_ids = ids;
    }
    if let Some(ids) = cfg.estimator_pps() {
        s.pps_ids = ids;
    }
    if let Some(ids) = cfg.estimator_imus() {
        s.imu_ids = ids;
    }
    if let Some(v) = c.timing.software_sync {
        s.software_sync = v;
    }
    if let Some(m) = e.imu_model {
        s.imu_model = m;
    }
    if let Some(v) = e.estimate_delay {
        s.estimate_delay = v;
    }
    if let Some(v) = e.gnss_vel_std_mps {
        s.gnss_vel_std_mps = v;
    }
    if let Some(v) = e.estimate_imu_offsets {
        s.estimate_imu_offsets = v;
    }
    if let Some(v) = e.zupt {
        s.zupt = v;
    }
    for (id, i) in &c.imu {
        s.imu_mountings.insert(
            id.clone(),
            ImuMounting {
                c_b_s: i.mounting.c_b_s(),
                lever_b_m: i.mounting.lever_arm_m,
            },
        );
    }
    if let Some(g) = s.gnss_ids.first().and_then(|id| c.gnss.get(id)) {
        s.gnss_lever_arm_m = g.lever_arm_m;
    }
    let t = &c.timing;
    if t.oscillator_white_fm_adev_1s.is_some() || t.oscillator_random_walk_fm_adev_1s.is_some() {
        s.oscillator_adev_1s = Some((
            t.oscillator_white_fm_adev_1s.unwrap_or(1e-10),
            t.oscillator_random_walk_fm_adev_1s.unwrap_or(1e-10),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;

    #[test]
    fn flags_win_over_the_file_and_the_file_over_defaults() {
        let cfg = Loaded::parse(
            "[gnss.0]\nport = \"/dev/a\"\nlever_arm_m = [1, 2, 3]\n[imu.0]\nsource = \"sim\"\nmounting = { lever_arm_m = [0.5, 0, 0] }\n[estimator]\nimu_model = \"consumer\"\ngnss_vel_std_mps = 0.3\n[timing]\nsoftware_sync = true\n",
            Path::new("t.toml"),
        )
        .unwrap();
        let e = EstimatorFlags::default().settings(&cfg).unwrap();
        assert_eq!(e.imu_model, ImuPreset::Consumer);
        assert_eq!(e.gnss_vel_std_mps, 0.3);
        assert!(e.software_sync);
        assert_eq!(e.gnss_lever_arm_m, [1.0, 2.0, 3.0]);
        assert_eq!(e.imu_mountings["0"].lever_b_m, [0.5, 0.0, 0.0]);
        let pc = e.pipeline_config();
        assert_eq!(pc.nav.lever_arm_b_m.x, 1.0);
        assert_eq!(pc.array.units[0].lever_b_m.x, 0.5);
        let flags = EstimatorFlags {
            model: ModelFlags {
                imu_model: Some(ImuPreset::Industrial),
                gnss_vel_std_mps: Some(0.05),
                no_imu_offsets: true,
                ..Default::default()
            },
            ..Default::default()
        };
        let e = flags.settings(&cfg).unwrap();
        assert_eq!((e.imu_model, e.gnss_vel_std_mps), (ImuPreset::Industrial, 0.05));
        assert!(!e.estimate_imu_offsets);
        // No file: the defaults.
        assert_eq!(
            EstimatorFlags::default().settings(&Loaded::none()).unwrap(),
            Settings::default()
        );
    }
}
