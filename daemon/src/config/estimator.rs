//! The estimator's settings on the command line and in the file, resolved into one
//! [`Settings`]: per setting a flag given on the command line, else the file (`[estimator]`,
//! `[timing]`, each IMU's `mounting`, the first receiver's `lever_arm_m`), else the base (the
//! defaults, or what a recording or the simulator says its devices are). The flags are made
//! from the settings' declarations ([`Settings::specs`]), so a setting's flag, file key,
//! default, documentation and check are written once; the check runs on the merged value.
//! The live `navsync estimator` and every offline tool (`replay --estimate`,
//! `sim --fast --estimate`, `report`, `analyze`) take the same flags ([`EstimatorFlags`]).

use clap::{Arg, ArgAction, ArgMatches, Command};
use navsync_estimator::declare::{Group, Spec};
use navsync_estimator::settings::{ImuMounting, Inputs, Settings};
use navsync_shared::imu_spec::{ImuNoise, PerAxis};

use super::{ConfigError, Loaded};

/// A device id as used in service names: letters, digits, `-` and `_` (a flag's parser).
pub fn parse_id(s: &str) -> Result<String, String> {
    if super::valid_id(s) {
        Ok(s.to_string())
    } else {
        Err(format!("`{s}`: an id is 1 to 16 letters, digits, `-` and `_`"))
    }
}

/// The estimator's flags with its inputs (`--gnss`, `--pps`, `--imus`): every process and tool
/// that picks its inputs by id.
pub type EstimatorFlags = SettingFlags<true>;
/// The estimator's flags without its inputs (the simulator's own IMUs are the inputs).
pub type ModelFlags = SettingFlags<false>;

/// The estimator's settings given on the command line (each over the file's value), and the
/// IMU noise model's refinements field by field.
#[derive(Debug, Clone, Default)]
pub struct SettingFlags<const INPUTS: bool> {
    /// Settings given, by name, with their text as typed (already checked by clap).
    pub given: Vec<(&'static str, String)>,
    /// The IMU's noise (KF-GINS units; each a number or x,y,z; over `[estimator.imu_noise]`,
    /// the recording's, else `--imu-model`'s).
    pub noise: NoiseFlags,
}

/// The settings that have a flag: every one with `INPUTS`, else all but the inputs.
fn flagged(inputs: bool) -> impl Iterator<Item = &'static Spec> {
    Settings::specs()
        .into_iter()
        .filter(move |s| s.flag.is_some() && (inputs || !Inputs::SPECS.contains(s)))
}

/// A flag's help: its doc comment, its default and where the file sets it (a switch says
/// which way it turns the setting).
fn help(spec: &Spec) -> String {
    let doc = spec
        .doc
        .split('\n')
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join(" ");
    let (doc, default) = match spec.switch {
        Some(true) => (format!("Turns on: {doc}"), " [default: off]".to_string()),
        Some(false) => (format!("Turns off: {doc}"), " [default: on]".to_string()),
        None => (
            doc,
            format!(
                " [default: {}]",
                Settings::default().show(spec.name).unwrap_or_default()
            ),
        ),
    };
    match spec.section {
        Some(section) => format!("{doc}{default} [file: [{section}] {}]", spec.name),
        None => format!("{doc}{default}"),
    }
}

/// Checks a flag's text: it parses, and the setting's check holds.
fn check_flag(name: &'static str, text: &str) -> Result<String, String> {
    let mut s = Settings::default();
    s.set_text(name, text)?;
    s.check().map_err(|e| e.message)?;
    Ok(text.to_string())
}

impl<const INPUTS: bool> clap::Args for SettingFlags<INPUTS> {
    fn augment_args(mut cmd: Command) -> Command {
        for spec in flagged(INPUTS) {
            let (name, flag) = (spec.name, spec.flag.unwrap_or_default());
            let arg = Arg::new(name).long(flag).help(help(spec));
            cmd = cmd.arg(match spec.switch {
                Some(_) => arg.action(ArgAction::SetTrue),
                None => arg
                    // Once per flag per command: the value's name lives as long as the parser.
                    .value_name(&*Box::leak(name.to_ascii_uppercase().into_boxed_str()))
                    .allow_hyphen_values(true)
                    .value_parser(move |t: &str| check_flag(name, t)),
            });
        }
        NoiseFlags::augment_args(cmd)
    }

    fn augment_args_for_update(cmd: Command) -> Command {
        Self::augment_args(cmd)
    }
}

impl<const INPUTS: bool> clap::FromArgMatches for SettingFlags<INPUTS> {
    fn from_arg_matches(m: &ArgMatches) -> Result<Self, clap::Error> {
        let mut given = Vec::new();
        for spec in flagged(INPUTS) {
            match spec.switch {
                Some(on) if m.get_flag(spec.name) => given.push((spec.name, on.to_string())),
                Some(_) => {}
                None => {
                    if let Some(t) = m.get_one::<String>(spec.name) {
                        given.push((spec.name, t.clone()));
                    }
                }
            }
        }
        Ok(Self {
            given,
            noise: NoiseFlags::from_arg_matches(m)?,
        })
    }

    fn update_from_arg_matches(&mut self, m: &ArgMatches) -> Result<(), clap::Error> {
        *self = Self::from_arg_matches(m)?;
        Ok(())
    }
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

impl<const INPUTS: bool> SettingFlags<INPUTS> {
    /// Whether setting `name` was given.
    pub fn gives(&self, name: &str) -> bool {
        self.given.iter().any(|(n, _)| *n == name)
    }

    /// The settings: `base`, then the file, then the flags given; checked.
    pub fn settings_over(&self, cfg: &Loaded, base: Settings) -> Result<Settings, ConfigError> {
        let mut s = base;
        apply_file(&mut s, cfg)?;
        self.apply(&mut s)?;
        check(&s, cfg)?;
        Ok(s)
    }

    /// The settings over [`Settings::default`].
    pub fn settings(&self, cfg: &Loaded) -> Result<Settings, ConfigError> {
        self.settings_over(cfg, Settings::default())
    }

    /// The flags given, over `s`. A preset (`--imu-model`) replaces an explicit model from
    /// the file or the recording; the noise flags refine the model in force.
    pub fn apply(&self, s: &mut Settings) -> Result<(), ConfigError> {
        for (name, text) in &self.given {
            s.set_text(name, text).map_err(|message| ConfigError {
                file: "command line".into(),
                line: None,
                field: Some(format!("--{}", flag_of(name))),
                message,
            })?;
            if *name == "imu_model" {
                s.imu.imu_noise = None;
            }
        }
        if self.noise.any() {
            let mut n = s.noise();
            self.noise.apply(&mut n);
            s.imu.imu_noise = Some(n);
        }
        Ok(())
    }
}

/// The flag of setting `name`.
fn flag_of(name: &str) -> &'static str {
    Settings::specs()
        .into_iter()
        .find(|s| s.name == name)
        .and_then(|s| s.flag)
        .unwrap_or_default()
}

/// The merged settings' check, its error located where the failing value came from: the
/// file's line when the file set it, else the setting's name.
pub fn check(s: &Settings, cfg: &Loaded) -> Result<(), ConfigError> {
    let Err(e) = s.check() else { return Ok(()) };
    let section = Settings::specs()
        .into_iter()
        .find(|x| x.name == e.name)
        .and_then(|x| x.section);
    let index = e.index.map(|i| format!("[{i}]")).unwrap_or_default();
    match section {
        Some(section) if cfg.section(section).is_some_and(|t| t.contains_key(e.name)) => {
            Err(cfg.error_at(&format!("{section}.{}{index}", e.name), e.message))
        }
        _ => Err(ConfigError {
            file: cfg.file.clone(),
            line: None,
            field: Some(format!("{}{index}", e.name)),
            message: e.message,
        }),
    }
}

/// Applies what the file says about the estimator to `s`: `[estimator]` and `[timing]` by
/// the settings' declarations, the inputs from the devices' sections where `[estimator]`
/// names none, each IMU's mounting and the first receiver's lever arm. Unknown keys and
/// values of the wrong type are errors naming the file, line and field.
pub fn apply_file(s: &mut Settings, cfg: &Loaded) -> Result<(), ConfigError> {
    let c = &cfg.config;
    for section in ["timing", "estimator"] {
        for (key, value) in cfg.section(section).into_iter().flatten() {
            let at = format!("{section}.{key}");
            match s.set_value(section, key, value.clone()) {
                Some(Ok(())) => {}
                Some(Err(e)) => return Err(cfg.error_at(&at, super::user_wording(e.message()))),
                None => {
                    let known: Vec<_> = Settings::specs()
                        .into_iter()
                        .filter(|x| x.section == Some(section))
                        .map(|x| format!("`{}`", x.name))
                        .collect();
                    return Err(cfg.error_at(
                        &at,
                        format!("unknown field `{key}`, expected one of {}", known.join(", ")),
                    ));
                }
            }
        }
    }
    let estimator = cfg.section("estimator");
    let given = |key: &str| estimator.is_some_and(|t| t.contains_key(key));
    if !given("gnss") && !c.gnss.is_empty() {
        s.inputs.gnss = c.gnss.keys().cloned().collect();
    }
    if !given("pps") && !c.pps.is_empty() {
        s.inputs.pps = c.pps.keys().cloned().collect();
    }
    if !given("imus") && !c.imu.is_empty() {
        s.inputs.imus = c.imu.keys().cloned().collect();
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
    if let Some(g) = s.inputs.gnss.first().and_then(|id| c.gnss.get(id)) {
        s.nav.gnss_lever_arm_m = g.lever_arm_m;
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
    let c = &cfg.config;
    let states = |key: &str| cfg.section("estimator").is_some_and(|t| t.contains_key(key));
    let mut out = Vec::new();
    if states("imu_model") || states("imu_noise") {
        let noise = metadata_value(&s.noise());
        for id in &s.inputs.imus {
            out.push((services::imu_sample(id), channels::META_IMU_NOISE, noise.clone()));
        }
    }
    if let (Some(i), Some(id)) = (&s.nav.initial_state, s.inputs.imus.first()) {
        out.push((
            services::imu_sample(id),
            channels::META_INITIAL_STATE,
            metadata_value(i),
        ));
    }
    for id in &s.inputs.gnss {
        if let Some(g) = c.gnss.get(id) {
            out.push((
                services::gnss_fix(id),
                channels::META_LEVER_ARM,
                metadata_value(&g.lever_arm_m),
            ));
        }
        if states("gnss_vel_std_mps") {
            out.push((
                services::gnss_fix(id),
                channels::META_GNSS_VEL_STD,
                metadata_value(&s.gnss.gnss_vel_std_mps),
            ));
        }
    }
    Ok(out)
}

/// The configuration reference of every declared setting (`navsync config-reference`, kept in
/// `docs/guide/configuration.md`): per file section a table of key, flag, default and what it
/// does, all from the settings' declarations (`settings_group!`).
pub fn reference() -> String {
    let defaults = Settings::default();
    let one_line = |doc: &str| {
        doc.split('\n')
            .map(str::trim)
            .filter(|l| !l.is_empty())
            .collect::<Vec<_>>()
            .join(" ")
            .replace('|', "\\|")
    };
    let mut out = String::from(
        "# Configuration reference: the estimator's settings\n\n\
         Generated by `navsync config-reference` from the settings' declarations (one\n\
         `settings_group!` per group, where the settings act); a test keeps this file equal to its\n\
         output. Each setting is read from its section of the configuration file\n\
         (`/etc/navsync/navsync.toml`, or `--config FILE`) and, where it has one, from its flag\n\
         (flag over file over default); its check runs on the merged value and an error names\n\
         the file, line and field, or the flag. The devices' sections (`[gnss.ID]`, `[pps.ID]`,\n\
         `[imu.ID]`), `[outputs.*]` and `[logging]` are described in\n\
         `systemd/navsync.toml.example`; `navsync check-config` checks a whole file.\n",
    );
    let specs = Settings::specs();
    // The file's sections in declaration order, then "" for the flags without a file key.
    let mut sections: Vec<&str> = Vec::new();
    for section in specs.iter().filter_map(|s| s.section).chain([""]) {
        if !sections.contains(&section) {
            sections.push(section);
        }
    }
    for section in sections {
        let rows: Vec<&&Spec> = specs
            .iter()
            .filter(|s| s.section.unwrap_or("") == section && (s.section.is_some() || s.flag.is_some()))
            .collect();
        if rows.is_empty() {
            continue;
        }
        if section.is_empty() {
            out.push_str("\n## Command line only\n\n| flag | default | what |\n|---|---|---|\n");
        } else {
            out.push_str(&format!(
                "\n## `[{section}]`\n\n| key | flag | default | what |\n|---|---|---|---|\n"
            ));
        }
        for s in rows {
            let flag = s.flag.map_or(String::new(), |f| format!("`--{f}`"));
            let default = match s.switch {
                Some(true) => "off".to_string(),
                Some(false) => "on".to_string(),
                None => defaults
                    .show(s.name)
                    .map_or(String::new(), |v| format!("`{}`", v.replace('|', "\\|"))),
            };
            if section.is_empty() {
                out.push_str(&format!("| {flag} | {default} | {} |\n", one_line(s.doc)));
            } else {
                out.push_str(&format!(
                    "| `{}` | {flag} | {default} | {} |\n",
                    s.name,
                    one_line(s.doc)
                ));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use navsync_shared::imu_spec::ImuPreset;

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
        assert_eq!(e.imu.imu_model, ImuPreset::Consumer);
        assert_eq!(e.gnss.gnss_vel_std_mps, 0.3);
        assert!(e.time.software_sync);
        assert_eq!(e.nav.gnss_lever_arm_m, [1.0, 2.0, 3.0]);
        assert_eq!(e.imu_mountings["0"].lever_b_m, [0.5, 0.0, 0.0]);
        let pc = e.pipeline_config();
        assert_eq!(pc.nav.gnss_lever_arm_m[0], 1.0);
        assert_eq!(pc.array.units[0].lever_b_m.x, 0.5);
        let flags = EstimatorFlags {
            given: vec![
                ("imu_model", "industrial".into()),
                ("gnss_vel_std_mps", "0.05".into()),
                ("estimate_imu_offsets", "false".into()),
            ],
            ..Default::default()
        };
        let e = flags.settings(&cfg).unwrap();
        assert_eq!(
            (e.imu.imu_model, e.gnss.gnss_vel_std_mps),
            (ImuPreset::Industrial, 0.05)
        );
        assert!(!e.array.estimate_imu_offsets);
        // No file: the defaults.
        assert_eq!(
            EstimatorFlags::default().settings(&Loaded::none()).unwrap(),
            Settings::default()
        );
    }
}
