//! Setting up a Linux IIO device for buffered capture through sysfs, and finding its
//! character device.
//!
//! Sequence (kernel `Documentation/iio/iio_devbuf.rst`, `Documentation/ABI/testing/sysfs-bus-iio`):
//!
//! 1. `buffer/enable` ← 0 (scan elements cannot change while the buffer runs);
//! 2. `sampling_frequency` (or `in_anglvel_sampling_frequency` / `in_accel_sampling_frequency`
//!    on devices with per-sensor rates) ← the requested rate, read back;
//! 3. `current_timestamp_clock` ← `monotonic`, read back (the default is `realtime`, which
//!    would not be the host's `CLOCK_MONOTONIC`);
//! 4. every `scan_elements/in_*_en` ← 1 for angular rate, acceleration, temperature and the
//!    timestamp, 0 for everything else; read back (drivers may refuse);
//! 5. the enabled channels' `_index` and `_type` give the record layout; `in_<ch>_scale` /
//!    `in_<type>_scale` and `_offset` the conversion to SI units;
//! 6. `buffer/length` ← the buffer size in records; `buffer/enable` ← 1;
//! 7. records are read from `<dev-root>/iio:deviceN`.
//!
//! Since Linux 5.11 the same attributes also live under `buffer0/`; the legacy `buffer/` and
//! `scan_elements/` directories are used when present, `buffer0/` otherwise. The sysfs and
//! /dev roots are parameters, so tests run this on a fake tree of plain files.

use std::io::ErrorKind;
use std::path::{Path, PathBuf};

use super::record::{Conversion, MissingChannel, RecordDecoder, layout};
use super::scan::{ChannelRole, ScanElement, ScanType, ScanTypeError};

/// Default sysfs directory of IIO devices.
pub const SYSFS_ROOT: &str = "/sys/bus/iio/devices";
/// Default directory of device nodes.
pub const DEV_ROOT: &str = "/dev";

/// Why a device could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum IioError {
    /// No such device.
    #[error("no IIO device `{device}` under {root} (expected `iio:deviceN`, `N`, or a name read from `*/name`)")]
    NotFound {
        /// What was asked for.
        device: String,
        /// Where it was looked for.
        root: PathBuf,
    },
    /// Reading or writing an attribute failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The attribute.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// An attribute did not hold a number.
    #[error("{}: `{text}` is not a number", path.display())]
    NotANumber {
        /// The attribute.
        path: PathBuf,
        /// Its contents.
        text: String,
    },
    /// A scan element type could not be parsed.
    #[error("{}: {source}", path.display())]
    ScanType {
        /// The `_type` attribute.
        path: PathBuf,
        /// The parse error.
        source: ScanTypeError,
    },
    /// A required channel is not in the scan.
    #[error("{}: {source}", dir.display())]
    Missing {
        /// The device directory.
        dir: PathBuf,
        /// Which channel.
        source: MissingChannel,
    },
    /// The devices' channels do not make one IMU.
    #[error("{}: {what}", dir.display())]
    Layout {
        /// The (first) device directory.
        dir: PathBuf,
        /// What is wrong.
        what: String,
    },
    /// The kernel kept another time-stamp clock.
    #[error("{}: the kernel time stamps use `{clock}`, not `monotonic` (writing it failed); they would not be CLOCK_MONOTONIC", path.display())]
    Clock {
        /// `current_timestamp_clock`.
        path: PathBuf,
        /// What it reads.
        clock: String,
    },
}

/// How to set the device up.
#[derive(Debug, Clone, PartialEq)]
pub struct IioSetup {
    /// Sampling frequency to request, Hz (`None`: keep the device's).
    pub rate_hz: Option<f64>,
    /// Buffer length, records.
    pub buffer_length: u32,
}

/// A device set up for capture.
#[derive(Debug, Clone)]
pub struct IioDevice {
    /// Its sysfs directory.
    pub dir: PathBuf,
    /// Its character device.
    pub dev_node: PathBuf,
    /// The `name` attribute (empty if absent).
    pub name: String,
    /// The sampling frequency read back, Hz.
    pub sampling_hz: Option<f64>,
    /// Record decoder of the enabled channels.
    pub decoder: RecordDecoder,
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> IioError + '_ {
    move |source| IioError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Reads an attribute, trimmed.
pub fn read_attr(path: &Path) -> Result<String, IioError> {
    std::fs::read_to_string(path)
        .map(|s| s.trim().to_string())
        .map_err(io_err(path))
}

/// Writes an attribute (the file must exist: sysfs attributes are never created).
pub fn write_attr(path: &Path, value: &str) -> Result<(), IioError> {
    use std::io::Write;
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .truncate(true)
        .open(path)
        .map_err(io_err(path))?;
    f.write_all(format!("{value}\n").as_bytes()).map_err(io_err(path))
}

fn read_number(path: &Path) -> Result<f64, IioError> {
    let text = read_attr(path)?;
    text.parse::<f64>().map_err(|_| IioError::NotANumber {
        path: path.to_path_buf(),
        text,
    })
}

fn exists(p: &Path) -> bool {
    p.exists()
}

/// The sysfs directory of `device` under `root`: `iio:deviceN`, a bare `N`, or the device
/// whose `name` attribute equals `device`.
pub fn resolve(root: &Path, device: &str) -> Result<PathBuf, IioError> {
    if !device.is_empty() && !device.contains('/') {
        let direct = root.join(device);
        if direct.join("scan_elements").exists() || direct.join("buffer0").exists() {
            return Ok(direct);
        }
    }
    if device.chars().all(|c| c.is_ascii_digit()) && !device.is_empty() {
        let d = root.join(format!("iio:device{device}"));
        if d.exists() {
            return Ok(d);
        }
    }
    if let Ok(rd) = std::fs::read_dir(root) {
        let mut dirs: Vec<PathBuf> = rd.flatten().map(|e| e.path()).collect();
        dirs.sort();
        for d in dirs {
            if read_attr(&d.join("name")).is_ok_and(|n| n == device) {
                return Ok(d);
            }
        }
    }
    Err(IioError::NotFound {
        device: device.to_string(),
        root: root.to_path_buf(),
    })
}

/// The directories holding the scan elements and the buffer attributes.
fn buffer_dirs(dir: &Path) -> (PathBuf, PathBuf) {
    let legacy_scan = dir.join("scan_elements");
    let legacy_buf = dir.join("buffer");
    let b0 = dir.join("buffer0");
    let scan = if exists(&legacy_scan) { legacy_scan } else { b0.clone() };
    let buf = if exists(&legacy_buf) { legacy_buf } else { b0 };
    (scan, buf)
}

/// Stops capture (`buffer/enable` ← 0); errors are ignored (the device may be gone).
pub fn disable(dir: &Path) {
    let (_, buf) = buffer_dirs(dir);
    let _ = write_attr(&buf.join("enable"), "0");
}

/// The scan element names (without `in_` and `_en`) of a device.
fn scan_names(scan_dir: &Path) -> Result<Vec<String>, IioError> {
    let rd = std::fs::read_dir(scan_dir).map_err(io_err(scan_dir))?;
    let mut names: Vec<String> = rd
        .flatten()
        .filter_map(|e| {
            let n = e.file_name().to_string_lossy().into_owned();
            n.strip_prefix("in_")?.strip_suffix("_en").map(str::to_string)
        })
        .collect();
    names.sort();
    Ok(names)
}

/// Sets the device in `dir` up for capture and returns what is needed to read it.
pub fn configure(dir: &Path, dev_root: &Path, setup: &IioSetup) -> Result<IioDevice, IioError> {
    let name = read_attr(&dir.join("name")).unwrap_or_default();
    let (scan_dir, buf_dir) = buffer_dirs(dir);
    write_attr(&buf_dir.join("enable"), "0")?;

    let freq_attrs = [
        "sampling_frequency",
        "in_anglvel_sampling_frequency",
        "in_accel_sampling_frequency",
    ]
    .map(|a| dir.join(a));
    if let Some(hz) = setup.rate_hz {
        for a in freq_attrs.iter().filter(|a| exists(a)) {
            write_attr(a, &format!("{hz}"))?;
        }
    }
    let sampling_hz = match freq_attrs.iter().find(|a| exists(a)) {
        Some(a) => Some(read_number(a)?).filter(|f| *f > 0.0),
        None => None,
    };

    let clock = dir.join("current_timestamp_clock");
    // Writing fails on kernels where it is fixed; what counts is what it reads afterwards.
    let written = write_attr(&clock, "monotonic");
    match read_attr(&clock) {
        Ok(c) if c == "monotonic" => {}
        Ok(c) => return Err(IioError::Clock { path: clock, clock: c }),
        Err(e) => return Err(written.err().unwrap_or(e)),
    }

    let mut enabled = Vec::new();
    for n in scan_names(&scan_dir)? {
        let en = scan_dir.join(format!("in_{n}_en"));
        let want = ChannelRole::of(&n).is_some();
        // Some channels cannot be switched (always on, or not allowed together); the
        // read-back decides what the records hold.
        let _ = write_attr(&en, if want { "1" } else { "0" });
        if read_attr(&en)? != "1" {
            continue;
        }
        let ty_path = scan_dir.join(format!("in_{n}_type"));
        let ty: ScanType = read_attr(&ty_path)?.parse().map_err(|source| IioError::ScanType {
            path: ty_path.clone(),
            source,
        })?;
        let index_path = scan_dir.join(format!("in_{n}_index"));
        let index = read_number(&index_path)?;
        if !(0.0..=f64::from(u32::MAX)).contains(&index) || index.fract() != 0.0 {
            return Err(IioError::NotANumber {
                path: index_path,
                text: index.to_string(),
            });
        }
        enabled.push(ScanElement {
            name: n,
            index: index as u32,
            ty,
        });
    }
    let lay = layout(&enabled);

    // Scale and offset: the channel's own attribute, else the type's shared one.
    let mut conv_err = None;
    let decoder = RecordDecoder::new(&lay, |ch, role| {
        let attr = |suffix: &str| -> Option<PathBuf> {
            [format!("in_{ch}_{suffix}"), format!("in_{}_{suffix}", role.type_name())]
                .into_iter()
                .map(|f| dir.join(f))
                .find(|p| exists(p))
        };
        let mut number = |suffix: &str, default: Option<f64>| -> f64 {
            match attr(suffix) {
                Some(p) => read_number(&p).unwrap_or_else(|e| {
                    conv_err.get_or_insert(e);
                    f64::NAN
                }),
                None => default.unwrap_or_else(|| {
                    conv_err.get_or_insert(IioError::Io {
                        path: dir.join(format!("in_{}_{suffix}", role.type_name())),
                        source: ErrorKind::NotFound.into(),
                    });
                    f64::NAN
                }),
            }
        };
        let (scale, offset) = match role {
            // Temperatures are milli-°C after scaling; a missing scale means 1 m°C per LSB.
            ChannelRole::Temp => (number("scale", Some(1.0)) * 1e-3, number("offset", Some(0.0))),
            _ => (number("scale", None), number("offset", Some(0.0))),
        };
        Conversion { scale, offset }
    })
    .map_err(|source| IioError::Missing {
        dir: dir.to_path_buf(),
        source,
    })?;
    if let Some(e) = conv_err {
        return Err(e);
    }

    write_attr(&buf_dir.join("length"), &setup.buffer_length.to_string())?;
    let watermark = buf_dir.join("watermark");
    if exists(&watermark) {
        // Wake the reader for every record (lowest latency).
        let _ = write_attr(&watermark, "1");
    }
    write_attr(&buf_dir.join("enable"), "1")?;

    let dev_name = dir.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    Ok(IioDevice {
        dir: dir.to_path_buf(),
        dev_node: dev_root.join(dev_name),
        name,
        sampling_hz,
        decoder,
    })
}
