//! `navsync imu --source … --id ID`: IMU drivers, publishing `ImuSample` on
//! `navsync/imu/{id}/sample` and `Health` on `navsync/health/imu-{id}`.
//!
//! Sources:
//!
//! - `iio:DEVICE[+DEVICE]` — any MEMS IMU with a Linux Industrial I/O driver and a buffer
//!   (ADIS164xx, BMI160/BMI270, ICM-20xxx via inv_mpu6050, …; chips whose driver registers
//!   the gyroscope and the accelerometer as two devices, such as ICM-42xxx, LSM6DSx or
//!   BMI088, as `GYRO+ACCEL`): set up through sysfs, records from `/dev/iio:deviceN`, stamped
//!   with the kernel's per-sample timestamp ([`iio`]: the process shell, `device`, `scan`,
//!   `record`, `pair`).
//! - `xsens:PORT[:BAUD]` — an Xsens MTi sending MTData2 over a serial port (default
//!   115200 Bd), stamped on receipt and carrying the device's SampleTimeFine clock
//!   ([`xsens`]: the process shell, `frame`).
//! - `sim[:DIR]` — the simulator's IMU `ID` (`navsync sim --imu-output xsens`), which is an
//!   Xsens device on the pseudo-terminal `DIR/imu{ID}` (default navsync's runtime directory)
//!   ([`xsens::sim_device`]).
//!
//! Adding a source: a folder or file here with its pure decoder and its process shell, an
//! [`ImuSource`] variant with its text form (`kind:…`, the flag's and the file's) and its arms
//! in [`ImuSource`]'s `FromStr`, [`ImuSource::default_ranges`] and [`run`].
//!
//! Every source ends in [`output::SampleOutput`]: checks ([`sample_checks`]: NaN, range,
//! time going backwards, duplicates, sequence gaps and counter wraps), axis mapping to
//! forward-right-down ([`axes`]), stamping and publishing. Device errors never stop the
//! driver: it logs them (once per kind, then rate-limited), counts them in its health
//! report and reopens the device with exponential backoff.

pub mod axes;
pub mod iio;
pub mod output;
pub mod sample_checks;
pub mod xsens;

use std::path::PathBuf;
use std::str::FromStr;

use navsync_shared::imu_spec::G0;
use navsync_shared::ipc::{IpcError, IpcNode};
use tracing::{info, info_span};

use self::axes::AxisMap;
use self::iio::device::IioSetup;
use self::output::SampleOutput;
use self::sample_checks::Limits;

pub use iio::BUFFER_LENGTH as IIO_BUFFER_LENGTH;

/// Where the samples come from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ImuSource {
    /// A Linux IIO device (`iio:deviceN`, `N`, or its `name`), or the two devices of a split
    /// IMU (gyroscope and accelerometer), joined by `+`.
    Iio {
        /// The device(s).
        devices: Vec<String>,
    },
    /// An Xsens MTi on a serial port.
    Xsens {
        /// Serial device.
        port: String,
        /// Line rate.
        baud: u32,
    },
    /// The simulator's IMU of the same id, an Xsens device on `DIR/imu{id}`.
    Sim {
        /// Directory of the simulator's links.
        dir: PathBuf,
    },
}

deserialize_from_str!(ImuSource);

impl ImuSource {
    /// The source's full-scale ranges when none is configured: (gyroscope °/s,
    /// accelerometer g). Each source states its own.
    pub fn default_ranges(&self) -> (f64, f64) {
        match self {
            Self::Iio { .. } => iio::DEFAULT_RANGES,
            Self::Xsens { .. } | Self::Sim { .. } => (xsens::GYRO_RANGE_DPS, xsens::ACCEL_RANGE_G),
        }
    }
}

/// The source as written on the command line (`iio:adis16475`, `xsens:/dev/ttyUSB0:921600`).
impl std::fmt::Display for ImuSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Iio { devices } => write!(f, "iio:{}", devices.join("+")),
            Self::Xsens { port, baud } => write!(f, "xsens:{port}:{baud}"),
            Self::Sim { dir } => write!(f, "sim:{}", dir.display()),
        }
    }
}

impl FromStr for ImuSource {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let expected =
            || format!("`{s}` is not an IMU source: expected `iio:DEVICE`, `xsens:PORT[:BAUD]` or `sim[:DIR]`");
        let (kind, rest) = s.split_once(':').unwrap_or((s, ""));
        match kind {
            "iio" if !rest.is_empty() => {
                let devices: Vec<String> = rest.split('+').map(str::to_string).collect();
                if devices.len() > 2 || devices.iter().any(String::is_empty) {
                    return Err(expected());
                }
                Ok(Self::Iio { devices })
            }
            "xsens" if !rest.is_empty() => {
                let (port, baud) = match rest.rsplit_once(':') {
                    Some((p, b)) if !p.is_empty() && b.chars().all(|c| c.is_ascii_digit()) => {
                        let baud = b
                            .parse::<u32>()
                            .ok()
                            .filter(|b| crate::gnss::driver::STANDARD_BAUDS.contains(b))
                            .ok_or_else(|| {
                                format!(
                                    "`{b}` in `{s}` is not a standard baud rate (115200, 230400, 460800, 921600, …)"
                                )
                            })?;
                        (p, baud)
                    }
                    _ => (rest, xsens::DEFAULT_BAUD),
                };
                Ok(Self::Xsens {
                    port: port.to_string(),
                    baud,
                })
            }
            "sim" => Ok(Self::Sim {
                dir: if rest.is_empty() {
                    xsens::sim_device::default_sim_dir()
                } else {
                    PathBuf::from(rest)
                },
            }),
            _ => Err(expected()),
        }
    }
}

/// Settings of `navsync imu`.
#[derive(Debug, Clone)]
pub struct ImuArgs {
    /// The source.
    pub source: ImuSource,
    /// IMU id (service `navsync/imu/{id}/sample`).
    pub id: String,
    /// sysfs directory of IIO devices (default `/sys/bus/iio/devices`).
    pub sysfs_root: PathBuf,
    /// Directory of device nodes (default `/dev`).
    pub dev_root: PathBuf,
    /// Sampling frequency: requested from an IIO device; the nominal output rate of an Xsens
    /// device (otherwise learnt from its SampleTimeFine).
    pub rate_hz: Option<f64>,
    /// Device axes → published forward-right-down axes (default `x,-y,-z`: device z up).
    pub axes: AxisMap,
    /// Gyroscope full-scale range, °/s (default: 2000 for Xsens and the simulator, none for
    /// IIO, whose integer outputs cannot exceed their range and are flagged at full scale).
    pub gyro_range_dps: Option<f64>,
    /// Accelerometer full-scale range, g (default: 16 for Xsens and the simulator, none for IIO).
    pub accel_range_g: Option<f64>,
    /// IIO buffer length, records.
    pub buffer_length: u32,
}

/// Errors that stop the driver (device errors never do: it reopens).
#[derive(Debug, thiserror::Error)]
pub enum ImuError {
    /// IPC failure.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// A setting is out of range.
    #[error("{0}")]
    Config(String),
    /// A health counter could not be registered.
    #[error(transparent)]
    Health(#[from] navsync_shared::health_reporter::HealthError),
    /// The simulated devices' directory is not safe to use.
    #[error("the simulated IMUs' directory")]
    SimDir(#[from] navsync_shared::runtime_dir::RuntimeDirError),
}

/// Runs the driver until SIGINT/SIGTERM.
pub fn run(args: &ImuArgs) -> Result<(), ImuError> {
    let process = format!("imu-{}", args.id);
    let _span = info_span!("imu", id = %args.id).entered();
    if let Some(r) = args.rate_hz
        && !(r.is_finite() && r > 1.0 && r <= 100_000.0)
    {
        return Err(ImuError::Config(format!(
            "--rate {r}: expected a sampling frequency in Hz, 1 < rate ≤ 100000"
        )));
    }
    let default_ranges = args.source.default_ranges();
    let limits = Limits {
        gyro_rps: args.gyro_range_dps.unwrap_or(default_ranges.0).to_radians(),
        accel_mps2: args.accel_range_g.unwrap_or(default_ranges.1) * G0,
    };
    let node = IpcNode::new(&process)?;
    let mut out = SampleOutput::new(&node, &args.id, &process, limits, args.rate_hz.map(|f| 1.0 / f))?;
    info!(source = ?args.source, axes = %args.axes, "imu driver running");
    // Serving: the services exist; the device is read (or waited for, with backoff) from here.
    navsync_shared::sd_notify::ready(&format!("imu {}: {:?}", args.id, args.source));
    match &args.source {
        ImuSource::Iio { devices } => iio::run(
            &node,
            &iio::IioArgs {
                devices: devices.clone(),
                sysfs_root: args.sysfs_root.clone(),
                dev_root: args.dev_root.clone(),
                setup: IioSetup {
                    rate_hz: args.rate_hz,
                    buffer_length: args.buffer_length,
                },
                axes: args.axes,
            },
            &mut out,
        ),
        ImuSource::Xsens { port, baud } => xsens::run(
            &node,
            &xsens::XsensArgs {
                port: port.clone(),
                baud: *baud,
                axes: args.axes,
                rate_hz: args.rate_hz,
            },
            &mut out,
        ),
        ImuSource::Sim { dir } => {
            // A link in a directory another user controls could lead anywhere.
            navsync_shared::runtime_dir::check(dir, navsync_shared::runtime_dir::HINT)?;
            let index: usize = args.id.parse().map_err(|_| {
                ImuError::Config(format!(
                    "--source sim needs a numeric --id (the simulator's IMU index), not `{}`",
                    args.id
                ))
            })?;
            xsens::run(
                &node,
                &xsens::XsensArgs {
                    port: xsens::sim_device::sim_port(dir, index).display().to_string(),
                    baud: xsens::sim_device::SIM_BAUD,
                    axes: args.axes,
                    rate_hz: args.rate_hz,
                },
                &mut out,
            )
        }
    }
    navsync_shared::sd_notify::stopping();
    out.finish();
    info!(published = out.published(), "imu driver stopped");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sources() {
        assert_eq!(
            "iio:iio:device3".parse::<ImuSource>(),
            Ok(ImuSource::Iio {
                devices: vec!["iio:device3".into()]
            })
        );
        assert_eq!(
            "iio:icm42600-gyro+icm42600-accel".parse::<ImuSource>(),
            Ok(ImuSource::Iio {
                devices: vec!["icm42600-gyro".into(), "icm42600-accel".into()]
            })
        );
        assert_eq!(
            "xsens:/dev/ttyUSB0".parse::<ImuSource>(),
            Ok(ImuSource::Xsens {
                port: "/dev/ttyUSB0".into(),
                baud: 115_200
            })
        );
        assert_eq!(
            "xsens:/dev/ttyUSB0:921600".parse::<ImuSource>(),
            Ok(ImuSource::Xsens {
                port: "/dev/ttyUSB0".into(),
                baud: 921_600
            })
        );
        assert_eq!(
            "sim".parse::<ImuSource>(),
            Ok(ImuSource::Sim {
                dir: navsync_shared::runtime_dir::base()
            })
        );
        assert_eq!("sim:/x".parse::<ImuSource>(), Ok(ImuSource::Sim { dir: "/x".into() }));
        for bad in ["", "iio", "iio:", "xsens:", "spi:0", "/dev/ttyUSB0"] {
            let e = bad.parse::<ImuSource>().unwrap_err();
            assert!(
                e.contains("expected `iio:DEVICE`, `xsens:PORT[:BAUD]` or `sim[:DIR]`"),
                "{e}"
            );
        }
        for bad in ["xsens:/dev/x:0", "xsens:/dev/x:12345"] {
            let e = bad.parse::<ImuSource>().unwrap_err();
            assert!(e.contains("not a standard baud rate"), "{bad}: {e}");
        }
    }
}
