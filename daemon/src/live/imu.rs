//! `navsync imu`: the IMU driver process (`navsync_drivers::imu`) with its settings: flag,
//! else `[imu.ID]`, else default.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use navsync_drivers::imu::axes::AxisMap;
use navsync_drivers::imu::{IIO_BUFFER_LENGTH, ImuArgs, ImuSource};

use crate::config::Loaded;
use crate::config::estimator::parse_id;

/// `navsync imu`: samples from an IIO device, an Xsens MTi or the simulator to
/// `navsync/imu/{id}/sample`.
#[derive(clap::Args, Debug)]
pub struct Options {
    /// `iio:DEVICE` (iio:deviceN, N or the device name; `GYRO+ACCEL` for a split IMU),
    /// `xsens:PORT[:BAUD]` or `sim[:DIR]` [default: [imu.ID].source].
    #[arg(long)]
    pub source: Option<ImuSource>,
    /// IMU id.
    #[arg(long, default_value = "0", value_parser = parse_id)]
    pub id: String,
    /// sysfs directory of IIO devices [default: [imu.ID].sysfs_root, else /sys/bus/iio/devices].
    #[arg(long)]
    pub sysfs_root: Option<PathBuf>,
    /// Directory of the IIO character devices [default: [imu.ID].dev_root, else /dev].
    #[arg(long)]
    pub dev_root: Option<PathBuf>,
    /// Sampling frequency, Hz: set on an IIO device; the nominal rate of an Xsens device
    /// [default: [imu.ID].rate_hz, else the device's].
    #[arg(long)]
    pub rate: Option<f64>,
    /// Device axes to forward-right-down, e.g. `x,-y,-z` (device z up) or `x,y,z`
    /// [default: [imu.ID].axes, else x,-y,-z].
    #[arg(long)]
    pub axes: Option<AxisMap>,
    /// Gyroscope range, °/s: samples beyond it are rejected [default: [imu.ID], else 2000 for
    /// Xsens/sim].
    #[arg(long)]
    pub gyro_range_dps: Option<f64>,
    /// Accelerometer range, g [default: [imu.ID], else 16 for Xsens/sim].
    #[arg(long)]
    pub accel_range_g: Option<f64>,
    /// IIO buffer length, records [default: [imu.ID].buffer_length, else 512].
    #[arg(long)]
    pub buffer_length: Option<u32>,
}

impl Options {
    /// The driver's settings.
    pub fn resolve(self, cfg: &Loaded) -> Result<ImuArgs> {
        let s = cfg.config.imu.get(&self.id);
        let Some(source) = self.source.or_else(|| s.map(|s| s.source.clone())) else {
            bail!("no --source, and no [imu.{}] in {}", self.id, cfg.shown());
        };
        Ok(ImuArgs {
            source,
            sysfs_root: self
                .sysfs_root
                .or_else(|| s.and_then(|s| s.sysfs_root.clone()))
                .unwrap_or_else(|| navsync_drivers::imu::iio::device::SYSFS_ROOT.into()),
            dev_root: self
                .dev_root
                .or_else(|| s.and_then(|s| s.dev_root.clone()))
                .unwrap_or_else(|| navsync_drivers::imu::iio::device::DEV_ROOT.into()),
            rate_hz: self.rate.or(s.and_then(|s| s.rate_hz)),
            axes: self.axes.or(s.and_then(|s| s.axes)).unwrap_or(AxisMap::Z_UP_TO_FRD),
            gyro_range_dps: self.gyro_range_dps.or(s.and_then(|s| s.gyro_range_dps)),
            accel_range_g: self.accel_range_g.or(s.and_then(|s| s.accel_range_g)),
            buffer_length: self
                .buffer_length
                .or(s.and_then(|s| s.buffer_length))
                .unwrap_or(IIO_BUFFER_LENGTH),
            id: self.id,
        })
    }
}

/// Runs the driver until SIGINT/SIGTERM.
pub fn run(opts: Options, cfg: &Loaded) -> Result<()> {
    let args = opts.resolve(cfg)?;
    navsync_drivers::imu::run(&args).with_context(|| format!("imu driver on {:?}", args.source))
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;

    #[test]
    fn flags_win_over_the_file_and_the_file_over_defaults() {
        let cfg = Loaded::parse(
            "[imu.0]\nsource = \"sim\"\nrate_hz = 100\naxes = \"x,y,z\"\n",
            Path::new("t.toml"),
        )
        .unwrap();
        let opts = |id: &str, rate: Option<f64>| Options {
            source: None,
            id: id.into(),
            sysfs_root: None,
            dev_root: None,
            rate,
            axes: None,
            gyro_range_dps: None,
            accel_range_g: None,
            buffer_length: None,
        };
        let a = opts("0", None).resolve(&cfg).unwrap();
        assert_eq!((a.rate_hz, a.axes.to_string().as_str()), (Some(100.0), "x,y,z"));
        assert_eq!(a.buffer_length, IIO_BUFFER_LENGTH);
        assert_eq!(opts("0", Some(400.0)).resolve(&cfg).unwrap().rate_hz, Some(400.0));
        let e = opts("1", None).resolve(&cfg).unwrap_err().to_string();
        assert!(e.contains("no --source, and no [imu.1] in t.toml"), "{e}");
    }
}
