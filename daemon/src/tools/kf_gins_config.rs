//! KF-GINS's YAML configuration (`dataset/kf-gins.yaml` of i2Nav-WHU/KF-GINS, read by its
//! `kf_gins.cpp: loadConfig`), so a KF-GINS user's setup carries over to navsync
//! (`navsync import kf-gins --config FILE`): the IMU noise (`imunoise` and the initial σ of the
//! sensor errors), the antenna lever arm (`antlever`), the initial state (`initpos`, `initvel`,
//! `initatt`, `initgyrbias`, `initaccbias` and their σ) and the processing span (`starttime`,
//! `endtime`). Units as KF-GINS's: degrees, °/√h, m/s/√h, °/h, mGal, ppm, hours.
//!
//! Paths (`imupath`, `gnsspath`, `outputpath`) and the data layout (`imudatalen`,
//! `imudatarate`) are the import's own flags; keys navsync does not use (`odo*`, `cover*`, …)
//! are listed in [`KfGinsConfig::ignored`] and printed, not silently dropped.

use std::path::{Path, PathBuf};

use navsync_shared::imu_spec::{ImuNoise, PerAxis};
use yaml_rust2::{Yaml, YamlLoader};

/// A KF-GINS configuration, as far as navsync uses it.
#[derive(Debug, Clone, PartialEq)]
pub struct KfGinsConfig {
    /// The IMU noise model (`imunoise` with `initbgstd`, `initbastd`, `initsgstd`, `initsastd`).
    pub noise: Option<ImuNoise>,
    /// Antenna from the IMU in the body frame (FRD), m (`antlever`).
    pub lever_arm_m: Option<[f64; 3]>,
    /// The initial state at `starttime`, when `initpos` and `initatt` are given.
    pub initial: Option<KfGinsInitial>,
    /// First and last seconds of week to process (`starttime`, `endtime`; −1: to the end).
    pub span_sow: (Option<f64>, Option<f64>),
    /// Keys of the file navsync does not use.
    pub ignored: Vec<String>,
}

/// KF-GINS's initial state (its units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KfGinsInitial {
    /// Seconds of week (`starttime`).
    pub sow: f64,
    /// Latitude, longitude (deg), height (m) (`initpos`).
    pub pos: [f64; 3],
    /// Velocity NED, m/s (`initvel`).
    pub vel: [f64; 3],
    /// Roll, pitch, yaw, deg (`initatt`).
    pub att_deg: [f64; 3],
    /// Gyro bias, °/h (`initgyrbias`).
    pub gyro_bias_deg_per_h: [f64; 3],
    /// Accelerometer bias, mGal (`initaccbias`).
    pub accel_bias_mgal: [f64; 3],
    /// 1-sigma of position N, E, D (m), velocity (m/s), attitude (deg) (`initposstd`, …).
    pub pos_std: [f64; 3],
    /// See `pos_std`.
    pub vel_std: [f64; 3],
    /// See `pos_std`.
    pub att_std_deg: [f64; 3],
}

/// A problem with the file.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {problem}")]
pub struct KfGinsConfigError {
    /// The file.
    pub path: PathBuf,
    /// What is wrong (with the key).
    pub problem: String,
}

/// Keys navsync reads (top level), and those it takes from the import's flags instead.
const USED: [&str; 18] = [
    "imunoise",
    "antlever",
    "initpos",
    "initvel",
    "initatt",
    "initgyrbias",
    "initaccbias",
    "initposstd",
    "initvelstd",
    "initattstd",
    "initbgstd",
    "initbastd",
    "initsgstd",
    "initsastd",
    "starttime",
    "endtime",
    "initgyrscale",
    "initaccscale",
];
const PATHS: [&str; 5] = ["imupath", "gnsspath", "outputpath", "imudatalen", "imudatarate"];

impl KfGinsConfig {
    /// Reads and checks `path`.
    pub fn load(path: &Path) -> Result<Self, KfGinsConfigError> {
        let text = std::fs::read_to_string(path).map_err(|e| KfGinsConfigError {
            path: path.to_path_buf(),
            problem: format!("cannot read: {e}"),
        })?;
        Self::parse(&text, path)
    }

    /// Parses `text` (the contents of `path`).
    pub fn parse(text: &str, path: &Path) -> Result<Self, KfGinsConfigError> {
        let err = |problem: String| KfGinsConfigError {
            path: path.to_path_buf(),
            problem,
        };
        let docs = YamlLoader::load_from_str(text).map_err(|e| err(format!("not YAML: {e}")))?;
        let doc = docs.first().cloned().unwrap_or(Yaml::Null);
        let Yaml::Hash(map) = &doc else {
            return Err(err("expected a mapping of KF-GINS settings".into()));
        };
        let mut ignored = Vec::new();
        for k in map.keys() {
            let key = k.as_str().unwrap_or("?");
            if !USED.contains(&key) && !PATHS.contains(&key) {
                ignored.push(key.to_string());
            }
        }
        let num = |y: &Yaml, key: &str| -> Result<f64, KfGinsConfigError> {
            match y {
                Yaml::Real(_) | Yaml::Integer(_) => y
                    .as_f64()
                    .or_else(|| y.as_i64().map(|i| i as f64))
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| err(format!("{key}: not a finite number"))),
                _ => Err(err(format!("{key}: expected a number, found {y:?}"))),
            }
        };
        let get = |key: &str| -> Option<&Yaml> {
            let y = &doc[key];
            (!y.is_badvalue()).then_some(y)
        };
        let vec3 = |y: &Yaml, key: &str| -> Result<[f64; 3], KfGinsConfigError> {
            let Yaml::Array(a) = y else {
                return Err(err(format!("{key}: expected [x, y, z]")));
            };
            if a.len() != 3 {
                return Err(err(format!("{key}: expected 3 numbers, found {}", a.len())));
            }
            Ok([num(&a[0], key)?, num(&a[1], key)?, num(&a[2], key)?])
        };
        let opt3 = |key: &str| get(key).map(|y| vec3(y, key)).transpose();
        let nonneg3 = |key: &str| -> Result<Option<PerAxis>, KfGinsConfigError> {
            match opt3(key)? {
                Some(v) if v.iter().any(|x| *x < 0.0) => Err(err(format!("{key}: expected values ≥ 0"))),
                v => Ok(v.map(PerAxis)),
            }
        };
        let noise = match get("imunoise") {
            None => None,
            Some(n @ Yaml::Hash(_)) => {
                let sub = |key: &str| -> Result<PerAxis, KfGinsConfigError> {
                    let full = format!("imunoise.{key}");
                    match &n[key] {
                        Yaml::BadValue => Err(err(format!("{full}: missing"))),
                        y => {
                            let v = vec3(y, &full)?;
                            if v.iter().any(|x| *x < 0.0) {
                                return Err(err(format!("{full}: expected values ≥ 0")));
                            }
                            Ok(PerAxis(v))
                        }
                    }
                };
                let corr = match &n["corrtime"] {
                    Yaml::BadValue => return Err(err("imunoise.corrtime: missing".into())),
                    y => num(y, "imunoise.corrtime")?,
                };
                let gsstd = sub("gsstd")?;
                let asstd = sub("asstd")?;
                let noise = ImuNoise {
                    arw_deg_per_sqrt_h: sub("arw")?,
                    vrw_mps_per_sqrt_h: sub("vrw")?,
                    gyro_bias_std_deg_per_h: sub("gbstd")?,
                    accel_bias_std_mgal: sub("abstd")?,
                    gyro_scale_std_ppm: gsstd,
                    accel_scale_std_ppm: asstd,
                    corr_time_h: corr,
                    // KF-GINS: the initial σ default to the instabilities when not given.
                    gyro_bias_init_std_deg_per_h: nonneg3("initbgstd")?.unwrap_or(sub("gbstd")?),
                    accel_bias_init_std_mgal: nonneg3("initbastd")?.unwrap_or(sub("abstd")?),
                    gyro_scale_init_std_ppm: nonneg3("initsgstd")?.unwrap_or(gsstd),
                    accel_scale_init_std_ppm: nonneg3("initsastd")?.unwrap_or(asstd),
                };
                noise.check().map_err(|m| err(format!("imunoise: {m}")))?;
                Some(noise)
            }
            Some(y) => return Err(err(format!("imunoise: expected a mapping, found {y:?}"))),
        };
        let start = get("starttime").map(|y| num(y, "starttime")).transpose()?;
        let end = get("endtime")
            .map(|y| num(y, "endtime"))
            .transpose()?
            .filter(|e| *e >= 0.0);
        let initial = match (opt3("initpos")?, opt3("initatt")?, start) {
            (Some(pos), Some(att_deg), Some(sow)) => Some(KfGinsInitial {
                sow,
                pos,
                vel: opt3("initvel")?.unwrap_or([0.0; 3]),
                att_deg,
                gyro_bias_deg_per_h: opt3("initgyrbias")?.unwrap_or([0.0; 3]),
                accel_bias_mgal: opt3("initaccbias")?.unwrap_or([0.0; 3]),
                pos_std: nonneg3("initposstd")?.map_or([0.1, 0.1, 0.2], |p| p.0),
                vel_std: nonneg3("initvelstd")?.map_or([0.05; 3], |p| p.0),
                att_std_deg: nonneg3("initattstd")?.map_or([0.5, 0.5, 1.0], |p| p.0),
            }),
            (Some(_), _, None) | (_, Some(_), None) => {
                return Err(err("initpos/initatt need starttime (the instant they are for)".into()));
            }
            _ => None,
        };
        for key in ["initgyrscale", "initaccscale"] {
            if opt3(key)?.is_some_and(|v| v.iter().any(|x| *x != 0.0)) {
                ignored.push(format!("{key} (navsync starts scale factors at zero)"));
            }
        }
        Ok(Self {
            noise,
            lever_arm_m: opt3("antlever")?,
            initial,
            span_sow: (start, end),
            ignored,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DEMO: &str = r#"
imupath: "dataset/Leador-A15.txt"
gnsspath: "dataset/GNSS-RTK.txt"
imudatalen: 7
imudatarate: 200
starttime: 456300
endtime: -1
initpos: [ 30.4447873701, 114.4718632047, 20.899 ]
initvel: [ 0.0, 0.0, 0.0 ]
initatt: [ 0.854, -2.0345, 185.696 ]
initgyrbias: [ 0, 0, 0 ]
initaccbias: [ 0, 0, 0 ]
initgyrscale: [ 0, 0, 0 ]
initaccscale: [ 0, 0, 0 ]
initposstd: [ 0.05, 0.05, 0.05 ]
initvelstd: [ 0.05, 0.05, 0.05 ]
initattstd: [ 0.1, 0.1, 0.5 ]
imunoise:
  arw: [0.003, 0.003, 0.003]
  vrw: [0.03, 0.03, 0.03]
  gbstd: [0.027, 0.027, 0.027]
  abstd: [15.0, 15.0, 15.0]
  gsstd: [300.0, 300.0, 300.0]
  asstd: [300.0, 300.0, 300.0]
  corrtime: 4.0
antlever: [ -0.073, 0.302, 0.080 ]
odometer: 1
"#;

    #[test]
    fn the_kf_gins_demo_configuration_is_read() {
        let c = KfGinsConfig::parse(DEMO, Path::new("kf-gins.yaml")).unwrap();
        let n = c.noise.unwrap();
        assert_eq!(n.arw_deg_per_sqrt_h, PerAxis::all(0.003));
        assert_eq!(n.accel_bias_std_mgal, PerAxis::all(15.0));
        assert_eq!(n.corr_time_h, 4.0);
        // No initbgstd: the turn-on σ defaults to the instability, as in KF-GINS.
        assert_eq!(n.gyro_bias_init_std_deg_per_h, PerAxis::all(0.027));
        assert_eq!(c.lever_arm_m, Some([-0.073, 0.302, 0.080]));
        let i = c.initial.unwrap();
        assert_eq!((i.sow, i.att_deg[2], i.att_std_deg[2]), (456300.0, 185.696, 0.5));
        assert_eq!(c.span_sow, (Some(456300.0), None));
        assert_eq!(c.ignored, vec!["odometer".to_string()]);
    }

    #[test]
    fn errors_name_the_key() {
        let e = KfGinsConfig::parse("antlever: [1, 2]\n", Path::new("k.yaml")).unwrap_err();
        assert!(e.to_string().contains("antlever: expected 3 numbers"), "{e}");
        let e = KfGinsConfig::parse("imunoise:\n  arw: [1, 1, 1]\n", Path::new("k.yaml")).unwrap_err();
        assert!(e.to_string().contains("imunoise.corrtime: missing"), "{e}");
        let bad = DEMO.replace("gbstd: [0.027, 0.027, 0.027]", "gbstd: [-1, 0, 0]");
        let e = KfGinsConfig::parse(&bad, Path::new("k.yaml")).unwrap_err();
        assert!(e.to_string().contains("imunoise.gbstd: expected values ≥ 0"), "{e}");
        let e = KfGinsConfig::parse("initpos: [1, 2, 3]\ninitatt: [0, 0, 0]\n", Path::new("k.yaml")).unwrap_err();
        assert!(e.to_string().contains("need starttime"), "{e}");
    }
}
