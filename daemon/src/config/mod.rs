//! The configuration file (`/etc/navsync/navsync.toml`, `--config FILE` to choose another):
//! one TOML document that describes every device, the IMU mountings and lever arms, the noise
//! preset, the timing sources and the outputs. Every role reads its part; command-line flags
//! override the file.
//!
//! ```toml
//! [logging]
//! level = "info"                      # tracing filter; $RUST_LOG overrides
//!
//! [gnss.0]                            # navsync gnss --id 0 (`[gps.0]` is read the same)
//! port = "/dev/ttyACM0"
//! baud = "auto"                       # or a rate: 9600
//! protocol = "nmea"
//! lever_arm_m = [0.10, 0.0, -1.20]    # antenna in the body frame (FRD), m
//!
//! [pps.0]
//! source = "kernel:/dev/pps0"
//!
//! [imu.0]
//! source = "iio:adis16475"
//! rate_hz = 400
//! mounting = { rotation_deg = [0, 0, 90], lever_arm_m = [0.2, 0, 0] }
//!
//! [estimator]
//! imus = ["0"]                        # default: every [imu.*] in the file
//! imu_model = "industrial"
//! ```
//!
//! Sections deserialise straight into the types the roles use (the drivers' `Baud`,
//! `Protocol`, `ImuSource`, PPS `SourceSpec`, `AxisMap`, the IMU preset), with the same text
//! as on the command line. Errors name the file, the line, the column and the field, and say
//! what was expected in the user's words, not Rust's ([`user_wording`]: `navsync.toml:12:11:
//! imu.0.rate_hz: expected a number, found "fast" (text)`); keys the file does not know are
//! errors, not silently ignored.
//! [`Loaded::load`] checks what the types cannot (ranges, ids, cross references).
//!
//! Precedence, per field, is explicit in each role's options: a flag given on the command
//! line, else the file, else the documented default (`Option::or`, no string ids).
//!
//! The annotated example is `systemd/navsync.toml.example`.

pub mod bridge;
pub mod estimator;
pub mod recording;

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

use navsync_drivers::gnss::Protocol;
use navsync_drivers::gnss::driver::Baud;
use navsync_drivers::imu::ImuSource;
use navsync_drivers::imu::axes::AxisMap;
use navsync_drivers::pps::SourceSpec;
use navsync_shared::source_map::SourceMap;
use serde::Deserialize;

/// The default configuration file.
pub const DEFAULT_PATH: &str = "/etc/navsync/navsync.toml";

/// The largest configuration file read (the annotated example is ~10 KiB): a bigger one is
/// refused instead of read into memory (`--config /dev/zero` grew to 8 GB).
pub const MAX_FILE_BYTES: u64 = 1 << 20;

/// The most characters of a field path or message an error shows (a 10 MB value was echoed
/// whole to stderr); the rest is summarised by its length.
pub const MAX_SHOWN_CHARS: usize = 200;

/// `s`, cut to [`MAX_SHOWN_CHARS`] characters with a note of how many more there were.
pub fn cut(s: &str) -> std::borrow::Cow<'_, str> {
    match s.char_indices().nth(MAX_SHOWN_CHARS) {
        None => std::borrow::Cow::Borrowed(s),
        Some((at, _)) => {
            let more = s[at..].chars().count();
            std::borrow::Cow::Owned(format!("{}… ({more} more characters)", &s[..at]))
        }
    }
}

/// A configuration error, located in its file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConfigError {
    /// The file.
    pub file: PathBuf,
    /// 1-based line and column, when known.
    pub line: Option<(usize, usize)>,
    /// Dotted field path (`imu.0.rate_hz`), when known.
    pub field: Option<String>,
    /// What is wrong and what was expected.
    pub message: String,
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some((l, c)) = self.line {
            write!(f, ":{l}:{c}")?;
        }
        write!(f, ": ")?;
        if let Some(field) = &self.field {
            write!(f, "{}: ", cut(field))?;
        }
        write!(f, "{}", cut(&self.message))
    }
}

impl std::error::Error for ConfigError {}

/// A deserialiser's message in the words of a configuration file's reader: serde's
/// `invalid type: string "fast", expected f64` becomes `expected a number, found "fast"
/// (text)`, Rust's type names (`f64`, `u32`, `a sequence`, …) what one writes in TOML.
/// Other messages are kept as they are.
pub fn user_wording(message: &str) -> String {
    let message = message.trim();
    for head in ["invalid type: ", "invalid value: ", "invalid length "] {
        if let Some((found, expected)) = message
            .strip_prefix(head)
            .and_then(|rest| rest.rsplit_once(", expected "))
        {
            return format!("expected {}, found {}", expected_words(expected), found_words(found));
        }
    }
    message.to_string()
}

/// What serde says was expected, as a reader of TOML says it.
fn expected_words(e: &str) -> String {
    let e = e.trim();
    match e {
        "f64" | "f32" => "a number".into(),
        "u8" | "u16" | "u32" | "u64" | "u128" | "usize" => "a whole number ≥ 0".into(),
        "i8" | "i16" | "i32" | "i64" | "i128" | "isize" => "a whole number".into(),
        "a boolean" => "true or false".into(),
        "a string" | "a borrowed string" => "text in quotes".into(),
        "a sequence" => "a list [...]".into(),
        "a map" => "a table".into(),
        _ => {
            if let Some(n) = e
                .strip_prefix("an array of length ")
                .or_else(|| e.strip_prefix("a tuple of size "))
            {
                format!("a list of {n} values [...]")
            } else if let Some(name) = e.strip_prefix("struct ") {
                format!("a table ({name})")
            } else {
                e.to_string()
            }
        }
    }
}

/// What serde says it found, as written in the file.
fn found_words(f: &str) -> String {
    let f = f.trim();
    let quoted = |s: &str| s.trim_matches('`').to_string();
    if let Some(s) = f.strip_prefix("string ") {
        format!("{s} (text)")
    } else if let Some(s) = f
        .strip_prefix("integer ")
        .or_else(|| f.strip_prefix("floating point "))
        .or_else(|| f.strip_prefix("boolean "))
    {
        quoted(s)
    } else {
        match f {
            "sequence" => "a list".into(),
            "map" => "a table".into(),
            other => other.to_string(),
        }
    }
}

/// `[logging]`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Logging {
    /// A `tracing` filter: a level (`info`) or `level,target=level,…`. `$RUST_LOG` overrides it.
    pub level: Option<String>,
}

/// `[ipc]`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ipc {
    /// iceoryx2 resource prefix (default `navsync_`); `$NAVSYNC_IPC_PREFIX` overrides it.
    pub prefix: Option<String>,
}

/// `[gnss.ID]` (or `[gps.ID]`): one GNSS receiver.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GnssConfig {
    /// Serial device, e.g. `/dev/ttyACM0` or a stable `/dev/serial/by-id/…` link.
    pub port: String,
    /// Line rate or `"auto"` (default 9600).
    #[serde(default)]
    pub baud: Option<Baud>,
    /// The receiver's protocol: `auto`, `nmea` or `ubx` (default `auto`: the bytes say which).
    #[serde(default)]
    pub protocol: Option<Protocol>,
    /// Antenna position in the body frame (forward-right-down), m (the filter's GNSS lever arm).
    #[serde(default)]
    pub lever_arm_m: [f64; 3],
    /// Publish the receiver's own IMU (UBX ESF-MEAS: NEO-M8L/M8U, ZED-F9R) as this IMU id
    /// (default: not published).
    #[serde(default)]
    pub imu_id: Option<String>,
    /// Set a u-blox receiver up for navsync at start (RAM only; default false: navsync never
    /// writes to a receiver unless told).
    #[serde(default)]
    pub configure: Option<bool>,
}

/// `[pps.ID]`: one 1 PPS source.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PpsConfig {
    /// `kernel:/dev/ppsN`, `serial-dcd:/dev/ttyX`, `serial-cts:/dev/ttyX` or `sim`.
    pub source: SourceSpec,
}

/// How an IMU sits in the body frame.
#[derive(Debug, Clone, Copy, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Mounting {
    /// Rotation of the IMU's published axes relative to the body frame as roll, pitch, yaw
    /// (Z-Y-X Euler angles, degrees): x_body = C_b^s · x_imu with
    /// C_b^s = Rz(yaw)·Ry(pitch)·Rx(roll). Zero: the IMU's axes are the body axes.
    #[serde(default)]
    pub rotation_deg: [f64; 3],
    /// Position of the IMU in the body frame (forward-right-down), m.
    #[serde(default)]
    pub lever_arm_m: [f64; 3],
}

impl Mounting {
    /// C_b^s as a row-major 3×3 matrix.
    pub fn c_b_s(&self) -> [[f64; 3]; 3] {
        let [r, p, y] = self.rotation_deg.map(f64::to_radians);
        let (sr, cr) = r.sin_cos();
        let (sp, cp) = p.sin_cos();
        let (sy, cy) = y.sin_cos();
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    }
}

/// `[imu.ID]`: one IMU.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImuConfig {
    /// `iio:DEVICE[+DEVICE]`, `xsens:PORT[:BAUD]` or `sim[:DIR]`.
    pub source: ImuSource,
    /// Sampling frequency, Hz.
    pub rate_hz: Option<f64>,
    /// Device axes → forward-right-down, e.g. `"x,-y,-z"`.
    pub axes: Option<AxisMap>,
    /// Gyroscope range, °/s.
    pub gyro_range_dps: Option<f64>,
    /// Accelerometer range, g.
    pub accel_range_g: Option<f64>,
    /// IIO buffer length, records.
    pub buffer_length: Option<u32>,
    /// sysfs directory of the IIO devices (default `/sys/bus/iio/devices`).
    pub sysfs_root: Option<PathBuf>,
    /// Directory of the IIO device nodes (default `/dev`).
    pub dev_root: Option<PathBuf>,
    /// Where the IMU sits in the body frame.
    #[serde(default)]
    pub mounting: Mounting,
}

/// `[outputs.ntpshm]`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NtpShmOutput {
    /// SHM unit (key 0x4e545030 + unit).
    #[serde(default)]
    pub unit: u32,
    /// chrony's SOCK refclock socket to send each sample to as well (`refclock SOCK PATH`).
    #[serde(default)]
    pub sock: Option<PathBuf>,
    /// Withhold a sample whose mapping 1σ exceeds this many µs (default 1000).
    #[serde(default)]
    pub max_std_us: Option<f64>,
}

/// `[outputs.record]`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordOutput {
    /// Output file (MCAP); `{start}` becomes the UTC start time, so a restarted service writes
    /// a new file (an existing file is never overwritten).
    pub path: PathBuf,
    /// Services or patterns (default `navsync/**`).
    #[serde(default)]
    pub services: Vec<String>,
}

/// `[outputs]`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Outputs {
    /// NTP shared-memory export for chrony/ntpd.
    pub ntpshm: Option<NtpShmOutput>,
    /// Recording of the services.
    pub record: Option<RecordOutput>,
}

/// The whole file.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Logging.
    #[serde(default)]
    pub logging: Logging,
    /// iceoryx2.
    #[serde(default)]
    pub ipc: Ipc,
    /// GNSS receivers by id (`[gnss.ID]`; `[gps.ID]` is the same).
    #[serde(default, alias = "gps")]
    pub gnss: BTreeMap<String, GnssConfig>,
    /// PPS sources by id.
    #[serde(default)]
    pub pps: BTreeMap<String, PpsConfig>,
    /// IMUs by id.
    #[serde(default)]
    pub imu: BTreeMap<String, ImuConfig>,
    /// Timing (`[timing]`: the estimator's time synchronisation settings, read by their
    /// declarations: [`estimator::apply_file`]).
    #[serde(default)]
    pub timing: toml::Table,
    /// The estimator (`[estimator]`, read by the settings' declarations: [`estimator::apply_file`]).
    #[serde(default)]
    pub estimator: toml::Table,
    /// Outputs.
    #[serde(default)]
    pub outputs: Outputs,
    /// How recordings are written.
    #[serde(default)]
    pub recording: recording::RecordingConfig,
    /// Bridges to other hosts (`[bridge.zenoh]`).
    #[serde(default)]
    pub bridge: bridge::Bridges,
}

/// Loads `--config FILE`, else `/etc/navsync/navsync.toml` when it exists, else nothing; and
/// applies `[ipc].prefix` when `$NAVSYNC_IPC_PREFIX` is not set (every process of an
/// installation then meets under the same prefix).
pub fn load(explicit: Option<&Path>) -> Result<Loaded, ConfigError> {
    let loaded = Loaded::load_or_default(explicit)?;
    if let Some(p) = &loaded.config.ipc.prefix
        && std::env::var_os(navsync_shared::services::PREFIX_ENV).is_none()
    {
        // SAFETY: called at the start of main, before any thread exists.
        unsafe { std::env::set_var(navsync_shared::services::PREFIX_ENV, p) };
    }
    Ok(loaded)
}

/// The text of a regular file of at most [`MAX_FILE_BYTES`]. Opened without blocking (a FIFO
/// with no writer would wait forever) and checked on the open descriptor, so what is read is
/// what was checked.
fn read_bounded(file: &Path) -> std::io::Result<String> {
    use std::io::Read;
    use std::os::unix::fs::OpenOptionsExt;
    let invalid = |m: String| std::io::Error::new(std::io::ErrorKind::InvalidInput, m);
    let f = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(file)?;
    let meta = f.metadata()?;
    if !meta.is_file() {
        return Err(invalid(
            "not a regular file (a FIFO, a device or a directory): refused".to_string(),
        ));
    }
    if meta.len() > MAX_FILE_BYTES {
        return Err(invalid(format!(
            "{} bytes, more than the {MAX_FILE_BYTES} a configuration file may have: refused",
            meta.len()
        )));
    }
    let mut bytes = Vec::new();
    f.take(MAX_FILE_BYTES + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > MAX_FILE_BYTES {
        return Err(invalid(format!(
            "more than the {MAX_FILE_BYTES} bytes a configuration file may have: refused"
        )));
    }
    String::from_utf8(bytes).map_err(|e| invalid(format!("not UTF-8 text (at byte {})", e.utf8_error().valid_up_to())))
}

/// A loaded configuration with where it came from, to locate errors found later.
#[derive(Debug, Clone, Default)]
pub struct Loaded {
    /// The settings.
    pub config: Config,
    /// The file (empty when no file was read).
    pub file: PathBuf,
    map: SourceMap,
}

pub use navsync_estimator::declare::checks::valid_id;

fn valid_level(s: &str) -> bool {
    const LEVELS: [&str; 6] = ["trace", "debug", "info", "warn", "error", "off"];
    s.split(',').all(|d| {
        let d = d.trim();
        let level = d.rsplit_once('=').map_or(d, |(_, l)| l);
        let target_ok = d
            .rsplit_once('=')
            .is_none_or(|(t, _)| !t.is_empty() && t.chars().all(|c| c.is_ascii_alphanumeric() || "_:-".contains(c)));
        target_ok && LEVELS.contains(&level.to_ascii_lowercase().as_str())
    })
}

impl Loaded {
    /// No file: every setting at its default (command-line flags only).
    pub fn none() -> Self {
        Self::default()
    }

    /// Parses and checks `text` as the contents of `file`.
    pub fn parse(text: &str, file: &Path) -> Result<Self, ConfigError> {
        let map = SourceMap::build(text);
        let config: Config = toml::from_str(text).map_err(|e| {
            let span = e.span();
            ConfigError {
                file: file.to_path_buf(),
                line: span.as_ref().map(|s| map.line_col(s.start)),
                field: span.and_then(|s| map.field_at(s.start)).map(str::to_string),
                message: user_wording(e.message()),
            }
        })?;
        let loaded = Self {
            config,
            file: file.to_path_buf(),
            map,
        };
        loaded.check()?;
        Ok(loaded)
    }

    /// Reads, parses and checks `file`: a regular file of at most [`MAX_FILE_BYTES`] (a
    /// FIFO, a device or a directory is refused without waiting on it or reading it).
    pub fn load(file: &Path) -> Result<Self, ConfigError> {
        let fail = |message: String| ConfigError {
            file: file.to_path_buf(),
            line: None,
            field: None,
            message,
        };
        let text = read_bounded(file).map_err(|e| fail(format!("cannot read the configuration file: {e}")))?;
        Self::parse(&text, file)
    }

    /// `--config FILE` when given (it must exist), else the default file when it exists, else
    /// no file.
    pub fn load_or_default(explicit: Option<&Path>) -> Result<Self, ConfigError> {
        match explicit {
            Some(p) => Self::load(p),
            None if Path::new(DEFAULT_PATH).exists() => Self::load(Path::new(DEFAULT_PATH)),
            None => Ok(Self::none()),
        }
    }

    /// Whether a file was read.
    pub fn from_file(&self) -> bool {
        !self.file.as_os_str().is_empty()
    }

    /// The file for messages ("a configuration file (none at …)" when none was read).
    pub fn shown(&self) -> String {
        if self.from_file() {
            self.file.display().to_string()
        } else {
            format!("a configuration file (none at {DEFAULT_PATH})")
        }
    }

    /// An error about field `path` (dotted, e.g. `imu.0.source`) of this file.
    pub fn error_at(&self, path: &str, message: impl Into<String>) -> ConfigError {
        ConfigError {
            file: self.file.clone(),
            line: self.map.locate(path),
            field: Some(path.to_string()),
            message: message.into(),
        }
    }

    fn check(&self) -> Result<(), ConfigError> {
        let c = &self.config;
        let positive = |path: String, v: Option<f64>, what: &str| match v {
            Some(x) if !(x.is_finite() && x > 0.0) => Err(self.error_at(&path, format!("{x}: expected {what}"))),
            _ => Ok(()),
        };
        let finite3 = |path: String, v: &[f64; 3], what: &str| match v.iter().position(|x| !x.is_finite()) {
            Some(i) => Err(self.error_at(&format!("{path}[{i}]"), format!("{}: expected {what}", v[i]))),
            None => Ok(()),
        };
        if let Some(n) = &c.outputs.ntpshm {
            positive(
                "outputs.ntpshm.max_std_us".into(),
                n.max_std_us,
                "a number of µs above 0",
            )?;
        }
        if let Some(l) = &c.logging.level
            && !valid_level(l)
        {
            return Err(self.error_at(
                "logging.level",
                format!("`{l}`: expected a level (trace, debug, info, warn, error, off) or `level,target=level,…`"),
            ));
        }
        if let Some(p) = &c.ipc.prefix
            && (p.is_empty() || p.len() > 32 || !p.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-'))
        {
            return Err(self.error_at(
                "ipc.prefix",
                format!("`{p}`: expected 1 to 32 letters, digits, `_` or `-`"),
            ));
        }
        for (section, ids) in [
            ("gnss", c.gnss.keys().collect::<Vec<_>>()),
            ("pps", c.pps.keys().collect()),
            ("imu", c.imu.keys().collect()),
        ] {
            for id in ids {
                if !valid_id(id) {
                    return Err(self.error_at(
                        &format!("{section}.{id}"),
                        format!("`{id}` is not an id: expected 1 to 16 letters, digits, `-` or `_`"),
                    ));
                }
            }
        }
        for (id, g) in &c.gnss {
            if g.port.is_empty() {
                return Err(self.error_at(&format!("gnss.{id}.port"), "empty: expected a serial device path"));
            }
            finite3(
                format!("gnss.{id}.lever_arm_m"),
                &g.lever_arm_m,
                "a finite distance in m",
            )?;
        }
        for (id, i) in &c.imu {
            if let Some(r) = i.rate_hz
                && !(r.is_finite() && r > 1.0 && r <= 100_000.0)
            {
                return Err(self.error_at(
                    &format!("imu.{id}.rate_hz"),
                    format!("{r}: expected a sampling frequency in Hz, 1 < rate ≤ 100000"),
                ));
            }
            positive(
                format!("imu.{id}.gyro_range_dps"),
                i.gyro_range_dps,
                "a range > 0 in °/s",
            )?;
            positive(format!("imu.{id}.accel_range_g"), i.accel_range_g, "a range > 0 in g")?;
            if i.buffer_length == Some(0) {
                return Err(self.error_at(&format!("imu.{id}.buffer_length"), "0: expected at least 1 record"));
            }
            finite3(
                format!("imu.{id}.mounting.rotation_deg"),
                &i.mounting.rotation_deg,
                "an angle in degrees",
            )?;
            finite3(
                format!("imu.{id}.mounting.lever_arm_m"),
                &i.mounting.lever_arm_m,
                "a finite distance in m",
            )?;
        }
        let mut settings = navsync_estimator::settings::Settings::default();
        estimator::apply_file(&mut settings, self)?;
        estimator::check(&settings, self)?;
        if let Some(r) = &c.outputs.record
            && r.path.as_os_str().is_empty()
        {
            return Err(self.error_at("outputs.record.path", "empty: expected a file path"));
        }
        Ok(())
    }

    /// A section of the file read as a table (`estimator`, `timing`); `None` when absent.
    pub fn section(&self, name: &str) -> Option<&toml::Table> {
        match name {
            "estimator" => Some(&self.config.estimator),
            "timing" => Some(&self.config.timing),
            _ => None,
        }
        .filter(|t| !t.is_empty())
    }
}

#[cfg(test)]
mod tests;
