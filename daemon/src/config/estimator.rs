//! The estimator's settings on the command line and in the file, resolved into one
//! [`Settings`]: per field a flag given on the command line, else `[estimator]`/`[timing]`
//! (and each IMU's `mounting`, the first receiver's `lever_arm_m`), else the default of
//! [`Settings`]. The live `navsync estimator` and every offline tool (`replay --estimate`,
//! `sim --fast --estimate`, `report`, `analyze`) take the same flags ([`EstimatorFlags`]).

use navsync_estimator::settings::{Coupling, ImuMounting, ReceiverOscillator, Settings};
use navsync_shared::imu_spec::{ImuNoise, ImuPreset, PerAxis};

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
    /// Adapt the IMU's process noise when the GNSS innovations show it too optimistic
    /// [default: [estimator].adapt_process_noise, else off].
    #[arg(long = "adapt-noise")]
    pub adapt_process_noise: bool,
    /// Fuse IMU samples at their receipt stamps even where they carry a device clock
    /// [default: [estimator].device_clocks, else the device clocks are used].
    #[arg(long)]
    pub no_device_clocks: bool,
    /// 1-sigma of the receiver's velocity per axis, m/s [default: [estimator].gnss_vel_std_mps,
    /// else 0.1].
    #[arg(long = "gnss-vel-std")]
    pub gnss_vel_std_mps: Option<f64>,
    /// Factor on the receiver's position σ [default: [estimator].gnss_pos_std_scale, else 1].
    #[arg(long = "gnss-std-scale")]
    pub gnss_pos_std_scale: Option<f64>,
    /// Smallest GNSS position σ, m [default: [estimator].gnss_pos_std_floor_m, else 0.005].
    #[arg(long = "gnss-std-floor")]
    pub gnss_pos_std_floor_m: Option<f64>,
    /// GNSS antenna in the body frame (FRD) from the IMU, m, `x,y,z` [default: the first
    /// receiver's [gnss.ID].lever_arm_m, else the recording's, else 0].
    #[arg(long = "lever-arm", value_parser = parse_vector, allow_hyphen_values = true)]
    pub lever_arm_m: Option<[f64; 3]>,
    /// Scale of the 99.9 % innovation gate [default: [estimator].gate_scale, else 1].
    #[arg(long)]
    pub gate_scale: Option<f64>,
    /// GNSS speed above which the course gives the initial heading, m/s
    /// [default: [estimator].align_min_speed_mps, else 3].
    #[arg(long = "align-speed")]
    pub align_min_speed_mps: Option<f64>,
    /// 1-sigma of the prior of Δ under hardware sync (the IMU-to-GNSS time offset left after
    /// the PPS mapping), s [default: [estimator].delay_prior_std_s, else 0.02; IMU time tags
    /// from another clock than the PPS's may need 0.2].
    #[arg(long = "delay-prior-std")]
    pub delay_prior_std_s: Option<f64>,
    /// Fusion horizon, s: how far the filter runs behind the present to fuse late
    /// measurements at their epoch (≥ the largest receiver latency + 0.25 s) [default 1.5].
    #[arg(long = "horizon")]
    pub fusion_horizon_s: Option<f64>,
    /// How GNSS aids the filter: loose (the receiver's fixes) or tight (each satellite's
    /// pseudorange and Doppler from UBX RXM-RAWX/RXM-SFRBX, the receiver clock in the filter)
    /// [default: [estimator].coupling, else loose].
    #[arg(long)]
    pub coupling: Option<Coupling>,
    /// The receiver's oscillator for the clock states when tightly coupled: tcxo or crystal
    /// [default: [estimator].receiver_oscillator, else tcxo].
    #[arg(long)]
    pub receiver_oscillator: Option<ReceiverOscillator>,
    /// The IMU's noise (KF-GINS units; each a number or x,y,z; over [estimator.imu_noise],
    /// the recording's, else --imu-model's).
    #[command(flatten)]
    pub noise: NoiseFlags,
}

/// The IMU's noise model on the command line, field by field (KF-GINS's units).
#[derive(clap::Args, Debug, Clone, Default)]
pub struct NoiseFlags {
    /// Angle random walk, °/√h.
    #[arg(long = "arw")]
    pub arw_deg_per_sqrt_h: Option<PerAxis>,
    /// Velocity random walk, m/s/√h.
    #[arg(long = "vrw")]
    pub vrw_mps_per_sqrt_h: Option<PerAxis>,
    /// Gyro bias instability (Gauss–Markov σ), °/h.
    #[arg(long = "gyro-bias-std")]
    pub gyro_bias_std_deg_per_h: Option<PerAxis>,
    /// Accelerometer bias instability (Gauss–Markov σ), mGal.
    #[arg(long = "accel-bias-std")]
    pub accel_bias_std_mgal: Option<PerAxis>,
    /// Turn-on gyro bias σ, °/h.
    #[arg(long = "gyro-bias-init-std")]
    pub gyro_bias_init_std_deg_per_h: Option<PerAxis>,
    /// Turn-on accelerometer bias σ, mGal.
    #[arg(long = "accel-bias-init-std")]
    pub accel_bias_init_std_mgal: Option<PerAxis>,
    /// Gyro scale-factor σ (turn-on; instability a tenth), ppm; 0 switches scale factors off.
    #[arg(long = "gyro-scale-std")]
    pub gyro_scale_std_ppm: Option<PerAxis>,
    /// Accelerometer scale-factor σ (turn-on; instability a tenth), ppm.
    #[arg(long = "accel-scale-std")]
    pub accel_scale_std_ppm: Option<PerAxis>,
    /// Correlation time of the bias and scale-factor processes, h.
    #[arg(long = "corr-time")]
    pub corr_time_h: Option<f64>,
}

impl NoiseFlags {
    /// The flags given, over `n`.
    pub fn apply(&self, n: &mut ImuNoise) {
        let set = |dst: &mut PerAxis, v: Option<PerAxis>| {
            if let Some(v) = v {
                *dst = v;
            }
        };
        set(&mut n.arw_deg_per_sqrt_h, self.arw_deg_per_sqrt_h);
        set(&mut n.vrw_mps_per_sqrt_h, self.vrw_mps_per_sqrt_h);
        set(&mut n.gyro_bias_std_deg_per_h, self.gyro_bias_std_deg_per_h);
        set(&mut n.accel_bias_std_mgal, self.accel_bias_std_mgal);
        set(&mut n.gyro_bias_init_std_deg_per_h, self.gyro_bias_init_std_deg_per_h);
        set(&mut n.accel_bias_init_std_mgal, self.accel_bias_init_std_mgal);
        if let Some(v) = self.gyro_scale_std_ppm {
            n.gyro_scale_init_std_ppm = v;
            n.gyro_scale_std_ppm = v.scaled(0.1);
        }
        if let Some(v) = self.accel_scale_std_ppm {
            n.accel_scale_init_std_ppm = v;
            n.accel_scale_std_ppm = v.scaled(0.1);
        }
        if let Some(t) = self.corr_time_h {
            n.corr_time_h = t;
        }
    }

    /// Whether any flag was given.
    fn any(&self) -> bool {
        self.arw_deg_per_sqrt_h.is_some()
            || self.vrw_mps_per_sqrt_h.is_some()
            || self.gyro_bias_std_deg_per_h.is_some()
            || self.accel_bias_std_mgal.is_some()
            || self.gyro_bias_init_std_deg_per_h.is_some()
            || self.accel_bias_init_std_mgal.is_some()
            || self.gyro_scale_std_ppm.is_some()
            || self.accel_scale_std_ppm.is_some()
            || self.corr_time_h.is_some()
    }
}

/// `x,y,z`: three numbers.
fn parse_vector(s: &str) -> Result<[f64; 3], String> {
    match s.parse::<PerAxis>() {
        Ok(p) if s.contains(',') => Ok(p.0),
        _ => Err(format!("`{s}`: expected three numbers x,y,z")),
    }
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
            // A preset on the command line replaces an explicit model from the file or the
            // recording.
            s.imu_model = m;
            s.imu_noise = None;
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
        if self.adapt_process_noise {
            s.adapt_process_noise = true;
        }
        if self.no_device_clocks {
            s.device_clocks = false;
        }
        if let Some(v) = self.gnss_vel_std_mps {
            s.gnss_vel_std_mps = v;
        }
        if let Some(v) = self.gnss_pos_std_scale {
            s.gnss_pos_std_scale = v;
        }
        if let Some(v) = self.gnss_pos_std_floor_m {
            s.gnss_pos_std_floor_m = v;
        }
        if let Some(v) = self.lever_arm_m {
            s.gnss_lever_arm_m = v;
        }
        if let Some(v) = self.gate_scale {
            s.gate_scale = v;
        }
        if let Some(v) = self.align_min_speed_mps {
            s.align_min_speed_mps = v;
        }
        if let Some(v) = self.fusion_horizon_s {
            s.fusion_horizon_s = v;
        }
        if let Some(v) = self.delay_prior_std_s {
            s.hardware_delay_prior_s.1 = v;
        }
        if let Some(v) = self.coupling {
            s.coupling = v;
        }
        if let Some(v) = self.receiver_oscillator {
            s.receiver_oscillator = v;
        }
        if self.noise.any() {
            // Flags refine the model in force: the file's or the recording's, else the preset's
            // (after --imu-model).
            let mut n = s.noise();
            self.noise.apply(&mut n);
            s.imu_noise = Some(n);
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
    if let Some(v) = e.adapt_process_noise {
        s.adapt_process_noise = v;
    }
    if let Some(v) = e.device_clocks {
        s.device_clocks = v;
    }
    if let Some(v) = e.gnss_pos_std_scale {
        s.gnss_pos_std_scale = v;
    }
    if let Some(v) = e.gnss_pos_std_floor_m {
        s.gnss_pos_std_floor_m = v;
    }
    if let Some(v) = e.gate_scale {
        s.gate_scale = v;
    }
    if let Some(v) = e.align_min_speed_mps {
        s.align_min_speed_mps = v;
    }
    if let Some(n) = e.imu_noise {
        s.imu_noise = Some(n);
    }
    if let Some(i) = e.initial_state {
        s.initial_state = Some(i);
    }
    if let Some(v) = e.delay_prior_std_s {
        s.hardware_delay_prior_s.1 = v;
    }
    if let Some(v) = e.coupling {
        s.coupling = v;
    }
    if let Some(v) = e.receiver_oscillator {
        s.receiver_oscillator = v;
    }
    if let Some(v) = e.fusion_horizon_s {
        s.fusion_horizon_s = v;
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

/// What a live recording says about its devices, from the configuration file: the IMU noise
/// model on every IMU channel when the file names one (`[estimator] imu_model` or
/// `imu_noise`), the antenna lever arm (`[gnss.ID] lever_arm_m`) and the receiver's velocity σ
/// (`[estimator] gnss_vel_std_mps`) on the fix channels, a configured initial state on the
/// reference IMU's. Nothing the file does not state is claimed. Items: (service, key, value).
pub fn recording_metadata(cfg: &Loaded) -> Result<Vec<(String, &'static str, String)>, ConfigError> {
    use navsync_recording::channels::{self, metadata_value};
    use navsync_shared::services;
    let mut s = Settings::default();
    apply_file(&mut s, cfg)?;
    let (c, e) = (&cfg.config, &cfg.config.estimator);
    let mut out = Vec::new();
    if e.imu_model.is_some() || e.imu_noise.is_some() {
        let noise = metadata_value(&s.noise());
        for id in &s.imu_ids {
            out.push((services::imu_sample(id), channels::META_IMU_NOISE, noise.clone()));
        }
    }
    if let (Some(i), Some(id)) = (&s.initial_state, s.imu_ids.first()) {
        out.push((
            services::imu_sample(id),
            channels::META_INITIAL_STATE,
            metadata_value(i),
        ));
    }
    for id in &s.gnss_ids {
        if let Some(g) = c.gnss.get(id) {
            out.push((
                services::gnss_fix(id),
                channels::META_LEVER_ARM,
                metadata_value(&g.lever_arm_m),
            ));
        }
        if let Some(v) = e.gnss_vel_std_mps {
            out.push((services::gnss_fix(id), channels::META_GNSS_VEL_STD, metadata_value(&v)));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;

    #[test]
    fn a_live_recording_claims_only_what_the_file_states() {
        let none = Loaded::parse("[gnss.0]\nport = \"/dev/a\"\n", Path::new("t.toml")).unwrap();
        let m = recording_metadata(&none).unwrap();
        assert!(
            m.iter()
                .all(|(_, k, _)| *k != navsync_recording::channels::META_IMU_NOISE),
            "{m:?}"
        );
        let cfg = Loaded::parse(
            "[gnss.0]\nport = \"/dev/a\"\nlever_arm_m = [1, 2, 3]\n[estimator]\nimu_model = \"consumer\"\n",
            Path::new("t.toml"),
        )
        .unwrap();
        let m = recording_metadata(&cfg).unwrap();
        let noise = &m
            .iter()
            .find(|(s, k, _)| s == "navsync/imu/0/sample" && *k == navsync_recording::channels::META_IMU_NOISE)
            .unwrap()
            .2;
        let n: navsync_shared::imu_spec::ImuNoise = serde_json::from_str(noise).unwrap();
        assert_eq!(n, ImuPreset::Consumer.noise());
        assert!(m.contains(&(
            "navsync/gnss/0/fix".into(),
            navsync_recording::channels::META_LEVER_ARM,
            "[1.0,2.0,3.0]".into()
        )));
    }

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
