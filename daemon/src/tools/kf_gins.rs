//! Data exchange with KF-GINS (i2Nav-WHU/KF-GINS, the EKF GNSS/INS of Wuhan University's i2Nav
//! group) and the datasets in its format (awesome-gins-datasets).
//!
//! `navsync import kf-gins --imu IMU.txt --gnss GNSS.pos [--truth TRUTH.nav] -o REC.mcap` turns
//! its text files into a navsync recording that `navsync replay` publishes and
//! `navsync replay --estimate` processes; `navsync replay --estimate --format kf-gins --out DIR`
//! writes the navigation result in KF-GINS's result layout ([`ResultWriter`]), so its plotting
//! and evaluation scripts (`scripts/plot_navresult.py`) read it unchanged.
//!
//! # The formats (KF-GINS README §2.2, `src/fileio/*loader*.h`, `src/kf_gins.cpp`)
//!
//! Text, one record per line, columns split at any of `,`, space, tab
//! (`FileLoader::load_`: `absl::StrSplit(line, absl::ByAnyChar(", \t"), absl::SkipWhitespace())`).
//!
//! * IMU (`ImuFileLoader::next`): GNSS seconds of week; X-Y-Z angle increments (rad); X-Y-Z
//!   velocity increments (m/s); axes forward-right-down; the increments are over the interval
//!   that ends at the time tag (dt = difference of time tags, the nominal 1/rate when that is
//!   ≥ 0.1 s); an optional 8th column (odometer) is ignored here.
//! * GNSS (`GnssFileLoader::next`): seconds of week; latitude, longitude (deg); ellipsoidal
//!   height (m); position STD north-east-down (m). 7 columns, or 13 with the velocity (NED, m/s)
//!   in columns 5-7 and the STDs in 8-10 (velocity STDs in 11-13).
//! * Navigation result and truth (`writeNavResult` in `kf_gins.cpp`, README): GNSS week (KF-GINS
//!   writes 0); seconds of week; latitude, longitude (deg); ellipsoidal height (m); velocity
//!   north-east-down (m/s); roll, pitch, yaw (deg). 11 columns, each written with `%-15.9lf `
//!   (`FileSaver::dump_`).
//! * IMU error (`KF_GINS_IMU_ERR.txt`): seconds of week; gyroscope biases (deg/h);
//!   accelerometer biases (mGal); gyroscope and accelerometer scale factors (ppm).
//! * STD (`KF_GINS_STD.txt`, `writeSTD`): seconds of week; position, velocity STD (NED, m, m/s);
//!   attitude STD (deg); gyroscope bias STD (deg/h); accelerometer bias STD (mGal); scale factor
//!   STDs (ppm).
//!
//! # How the import maps them onto navsync samples
//!
//! Host time (`CLOCK_MONOTONIC` ns of the recording) is GPS time shifted so that the first
//! record is at [`HOST_BASE_NS`]; the GPS week comes from `--week` or the truth file. Each IMU
//! row is an `ImuSample` with rate = increment / dt and `dt_s` = dt (so increment = rate · dt
//! exactly); each GNSS row a `GnssFix` (ellipsoidal height as altitude with geoid separation 0,
//! the STDs as the receiver's σ, the velocity from a 13-column file or `--gnss-vel`, mode 3D)
//! received `--gnss-latency` (default [`FIX_LATENCY_S`]) after its epoch; one PPS edge at
//! every whole GPS second (unless `--no-pps`), so the estimator maps host time to GNSS time
//! exactly (hardware sync); each truth row a `SimTruth`, so `replay --estimate` reports the
//! accuracy against it.
//!
//! The GNSS file's tags are GNSS epochs by default (`--gnss-tags epoch`, KF-GINS's and NMEA's
//! meaning). `--gnss-tags receipt` says they are receipt times on the IMU's clock (a logging
//! computer's): each fix is stamped at its tag, no PPS edge is written, and the estimator finds
//! the delay (software sync). Either way the recording declares its exact time axis
//! (`navsync.time_axis`): the estimator labels each state with its IMU sample's own tag, so an
//! export lies on the input's time axis. `--kf-gins-config` stores KF-GINS's IMU noise, lever arm and initial
//! state as channel metadata, and keeps only its start/end time.
//!
//! A file without velocities gives fixes with speed and track from central differences of
//! the positions (for the alignment's heading) but no velocity: differences carry the
//! positions' noise, correlated from fix to fix, so the filter makes position-only updates,
//! as KF-GINS does.

use navsync_recording::output::{OutputFile, Overwrite};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::iter::Peekable;
use std::path::{Path, PathBuf};

use navsync_estimator::settings::{InitialState, TimeAxis};
use navsync_recording::{RecordingError, SampleRecorder, channels};

use super::kf_gins_config::KfGinsConfig;
use navsync_shared::reflect::{Reflect, fixed_str};
use navsync_shared::samples::*;
use navsync_shared::services;
use navsync_shared::time::{NS_PER_S, gps_ns_from_utc_ns, utc_ns_from_gps_ns};

/// Host time of the first record of an imported file, ns (any positive value would do).
pub const HOST_BASE_NS: i64 = 1_000 * NS_PER_S;
/// How long after its epoch an imported fix is "received" (its stamp), s.
pub const FIX_LATENCY_S: f64 = 0.05;
/// Nanoseconds in a GPS week.
pub const WEEK_NS: i64 = 604_800 * NS_PER_S;
/// The GPS week when neither `--week` nor the truth file gives one (2022-03-13, that of
/// KF-GINS's demo dataset's era; only the calendar date of the import depends on it).
pub const DEFAULT_WEEK: i64 = 2200;

/// Errors of the KF-GINS import and export.
#[derive(Debug, thiserror::Error)]
pub enum KfGinsError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// A line that is not a record of the expected format.
    #[error("{path}:{line}: {problem}")]
    Format {
        /// File.
        path: String,
        /// Line number (1-based).
        line: usize,
        /// What is wrong.
        problem: String,
    },
    /// Writing the recording.
    #[error(transparent)]
    Recording(#[from] RecordingError),
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> KfGinsError + '_ {
    move |source| KfGinsError::Io {
        path: path.display().to_string(),
        source,
    }
}

/// The records of a KF-GINS text file, each a row of numbers (lines that are empty or start
/// with `#` or `%` are skipped).
pub struct Rows {
    path: PathBuf,
    lines: std::io::Lines<BufReader<File>>,
    line: usize,
    /// Accepted column counts.
    columns: &'static [usize],
}

impl Rows {
    /// Opens `path`, whose records must have one of `columns` columns.
    pub fn open(path: &Path, columns: &'static [usize]) -> Result<Self, KfGinsError> {
        let f = File::open(path).map_err(io_err(path))?;
        Ok(Self {
            path: path.to_path_buf(),
            lines: BufReader::new(f).lines(),
            line: 0,
            columns,
        })
    }
}

impl Iterator for Rows {
    type Item = Result<(usize, Vec<f64>), KfGinsError>;
    fn next(&mut self) -> Option<Self::Item> {
        loop {
            let text = match self.lines.next()? {
                Ok(t) => t,
                Err(e) => return Some(Err(io_err(&self.path)(e))),
            };
            self.line += 1;
            let t = text.trim();
            if t.is_empty() || t.starts_with('#') || t.starts_with('%') {
                continue;
            }
            let bad = |problem: String| KfGinsError::Format {
                path: self.path.display().to_string(),
                line: self.line,
                problem,
            };
            let mut row = Vec::with_capacity(13);
            for tok in t.split([',', ' ', '\t']).filter(|s| !s.is_empty()) {
                match tok.parse::<f64>() {
                    Ok(v) if v.is_finite() => row.push(v),
                    _ => return Some(Err(bad(format!("`{tok}` is not a number")))),
                }
            }
            if !self.columns.contains(&row.len()) {
                return Some(Err(bad(format!(
                    "{} columns, expected {}",
                    row.len(),
                    self.columns
                        .iter()
                        .map(|c| c.to_string())
                        .collect::<Vec<_>>()
                        .join(" or ")
                ))));
            }
            return Some(Ok((self.line, row)));
        }
    }
}

/// One point of a trajectory in KF-GINS's result/truth layout.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavRecord {
    /// GPS week (0 when the file did not say).
    pub week: i64,
    /// GPS seconds of week.
    pub sow: f64,
    /// Latitude, deg.
    pub lat_deg: f64,
    /// Longitude, deg.
    pub lon_deg: f64,
    /// Ellipsoidal height, m.
    pub height_m: f64,
    /// Velocity NED, m/s.
    pub vel_ned_mps: [f64; 3],
    /// Roll, pitch, yaw, deg.
    pub rpy_deg: [f64; 3],
}

impl NavRecord {
    /// From an 11-column row.
    pub fn from_row(r: &[f64]) -> Self {
        Self {
            week: r[0].round() as i64,
            sow: r[1],
            lat_deg: r[2],
            lon_deg: r[3],
            height_m: r[4],
            vel_ned_mps: [r[5], r[6], r[7]],
            rpy_deg: [r[8], r[9], r[10]],
        }
    }
}

/// Reads a navigation result or truth file (11 columns).
pub fn read_nav(path: &Path) -> Result<Vec<NavRecord>, KfGinsError> {
    Rows::open(path, &[11])?
        .map(|r| r.map(|(_, row)| NavRecord::from_row(&row)))
        .collect()
}

/// One line in KF-GINS's text layout: every value as `%-15.9lf ` (`FileSaver::dump_`).
pub fn format_row(values: &[f64]) -> String {
    let mut s = String::with_capacity(values.len() * 16 + 1);
    for v in values {
        let cell = format!("{v:.9}");
        s.push_str(&format!("{cell:<15} "));
    }
    s.push('\n');
    s
}

/// GPS week and seconds of week of a UTC instant.
pub fn week_sow(utc_ns: i64) -> (i64, f64) {
    let g = gps_ns_from_utc_ns(utc_ns);
    let week = g.div_euclid(WEEK_NS);
    (week, g.rem_euclid(WEEK_NS) as f64 * 1e-9)
}

/// Writes navigation states in KF-GINS's result layout: `KF_GINS_Navresult.nav`,
/// `KF_GINS_IMU_ERR.txt` and `KF_GINS_STD.txt` in a directory (as KF-GINS's `outputpath`), or
/// only the navigation result into a file. States while aligning or without UTC are left out.
pub struct ResultWriter {
    nav: BufWriter<OutputFile>,
    imu_err: Option<BufWriter<OutputFile>>,
    std: Option<BufWriter<OutputFile>>,
    path: PathBuf,
    rows: u64,
}

impl ResultWriter {
    /// Creates the file(s): `out` is a directory (existing, or given with a trailing `/`) or a
    /// file. Each is written beside its name and renamed into place by
    /// [`finish`](Self::finish) (`navsync_recording::output`: never over an input, nor over
    /// a recording without `rules.force`).
    pub fn create(out: &Path, rules: &Overwrite<'_>) -> Result<Self, KfGinsError> {
        let is_dir = out.is_dir() || out.as_os_str().to_string_lossy().ends_with('/');
        let create = |p: &Path| -> Result<BufWriter<OutputFile>, KfGinsError> {
            Ok(BufWriter::new(OutputFile::create(p, rules)?))
        };
        if is_dir {
            std::fs::create_dir_all(out).map_err(io_err(out))?;
            let nav_path = out.join("KF_GINS_Navresult.nav");
            Ok(Self {
                nav: create(&nav_path)?,
                imu_err: Some(create(&out.join("KF_GINS_IMU_ERR.txt"))?),
                std: Some(create(&out.join("KF_GINS_STD.txt"))?),
                path: nav_path,
                rows: 0,
            })
        } else {
            Ok(Self {
                nav: create(out)?,
                imu_err: None,
                std: None,
                path: out.to_path_buf(),
                rows: 0,
            })
        }
    }

    /// Writes one state.
    pub fn write(&mut self, n: &NavState) -> Result<(), KfGinsError> {
        if n.status == NavStatus::Aligning as u8 || n.utc_ns == i64::MIN {
            return Ok(());
        }
        let (week, sow) = week_sow(n.utc_ns);
        let [r, p, y] = n.rpy_rad.map(f64::to_degrees);
        let line = format_row(&[
            week as f64,
            sow,
            n.lat_deg,
            n.lon_deg,
            n.height_m,
            n.vel_ned_mps[0],
            n.vel_ned_mps[1],
            n.vel_ned_mps[2],
            r,
            p,
            y,
        ]);
        let e = io_err(&self.path);
        self.nav.write_all(line.as_bytes()).map_err(e)?;
        const DEG_H: f64 = 180.0 / std::f64::consts::PI * 3600.0;
        const MGAL: f64 = 1e5;
        if let Some(w) = &mut self.imu_err {
            let mut v = vec![sow];
            v.extend(n.gyro_bias_rps.map(|x| x * DEG_H));
            v.extend(n.accel_bias_mps2.map(|x| x * MGAL));
            // navsync estimates no scale factors.
            v.extend([0.0; 6]);
            w.write_all(format_row(&v).as_bytes()).map_err(io_err(&self.path))?;
        }
        if let Some(w) = &mut self.std {
            let mut v = vec![sow];
            v.extend(n.pos_std_ned_m);
            v.extend(n.vel_std_ned_mps);
            v.extend(n.att_std_rad.map(f64::to_degrees));
            v.extend(n.gyro_bias_std_rps.map(|x| x * DEG_H));
            v.extend(n.accel_bias_std_mps2.map(|x| x * MGAL));
            v.extend([0.0; 6]);
            w.write_all(format_row(&v).as_bytes()).map_err(io_err(&self.path))?;
        }
        self.rows += 1;
        Ok(())
    }

    /// Flushes everything and renames the files into place; returns the rows written.
    pub fn finish(self) -> Result<u64, KfGinsError> {
        let p = self.path.clone();
        for w in [Some(self.nav), self.imu_err, self.std].into_iter().flatten() {
            let f = w.into_inner().map_err(|e| io_err(&p)(e.into_error()))?;
            f.commit()?;
        }
        Ok(self.rows)
    }
}

/// `navsync import`: another system's data files into a navsync recording.
#[derive(Debug, clap::Subcommand)]
pub enum ImportCommand {
    /// KF-GINS text files (IMU increments, GNSS positions, optional reference trajectory).
    KfGins(ImportArgs),
    /// A RINEX observation file and its GPS navigation file (2.10/2.11, 3.0x): a receiver's
    /// raw measurements and LNAV subframes.
    Rinex(super::rinex::RinexArgs),
    /// A u-blox receiver's own log (UBX: NAV-PVT, RXM-RAWX, RXM-SFRBX …), optionally with
    /// RTKLIB's time-tag file of it, and an IMU file in KF-GINS's format.
    Ubx(super::ubx_import::UbxArgs),
}

/// Runs `navsync import …` and prints what it wrote.
pub fn main(cmd: ImportCommand) -> anyhow::Result<()> {
    use anyhow::Context;
    let args = match cmd {
        ImportCommand::KfGins(args) => args,
        ImportCommand::Rinex(args) => return super::rinex::main(&args),
        ImportCommand::Ubx(args) => return super::ubx_import::main(&args),
    };
    let stats = import(&args).with_context(|| format!("importing into {}", args.out.display()))?;
    eprintln!(
        "{}: {} IMU samples ({:.1} Hz), {} GNSS fixes, {} PPS edges, {} truth samples (GPS week {})",
        args.out.display(),
        stats.imu,
        stats.imu_rate_hz,
        stats.fixes,
        stats.pps,
        stats.truth,
        stats.week
    );
    for m in &stats.metadata {
        eprintln!("  stored: {m}");
    }
    for k in &stats.ignored {
        eprintln!("  not used from the KF-GINS configuration: {k}");
    }
    anyhow::ensure!(stats.imu > 0, "no IMU sample in the span imported");
    anyhow::ensure!(stats.fixes > 0, "no GNSS fix in the span imported");
    Ok(())
}

/// `navsync import kf-gins`: KF-GINS's text formats into a recording.
#[derive(Debug, Clone, clap::Args)]
pub struct ImportArgs {
    /// IMU file: seconds of week, 3 angle increments (rad), 3 velocity increments (m/s), FRD.
    #[arg(long)]
    pub imu: PathBuf,
    /// GNSS file: seconds of week, lat, lon (deg), height (m), STD north/east/down (m).
    #[arg(long)]
    pub gnss: PathBuf,
    /// Reference trajectory: week, seconds of week, lat, lon, h, vN, vE, vD, roll, pitch, yaw (deg).
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// IMU rate, Hz (default: from the median spacing of the time tags).
    #[arg(long = "imu-rate")]
    pub imu_rate_hz: Option<f64>,
    /// GPS week of the data (default: the truth file's, else 2200).
    #[arg(long)]
    pub week: Option<i64>,
    /// IMU id in the recording.
    #[arg(long, default_value = "0", value_parser = crate::config::estimator::parse_id)]
    pub imu_id: String,
    /// One more IMU of an array, `ID=FILE` (repeatable): a file in `--imu`'s format and rate on
    /// the same time tags, recorded as IMU `ID` (`replay --estimate --imus 0,ID,…` estimates its
    /// time offset and fuses the array).
    #[arg(long = "array-imu", value_name = "ID=FILE", value_parser = parse_array_imu)]
    pub array_imu: Vec<(String, PathBuf)>,
    /// KF-GINS's YAML configuration: its IMU noise, antenna lever arm, initial state and
    /// start/end time go into the recording (channel metadata), so `replay --estimate` uses them.
    /// (`--config` is navsync's own configuration file.)
    #[arg(long = "kf-gins-config", value_name = "YAML")]
    pub kf_gins_config: Option<PathBuf>,
    /// Column order of a 13-column GNSS file: `kf-gins` (KF-GINS C++: position, velocity,
    /// position STD, velocity STD) or `matlab` (KF-GINS-Matlab GNSS-POSVEL: position, position
    /// STD, velocity, velocity STD).
    #[arg(long, default_value = "kf-gins")]
    pub gnss_layout: GnssLayout,
    /// The receiver's velocity: `sow vN vE vD [σN σE σD]` (m/s), matched to the GNSS file's
    /// epochs by time (instead of central differences of the positions).
    #[arg(long)]
    pub gnss_vel: Option<PathBuf>,
    /// What the GNSS file's time tags are: `epoch` (the GNSS epoch of each fix, in the IMU's
    /// time scale, as KF-GINS and NMEA write them) or `receipt` (when a logging computer received
    /// each fix, on the IMU's clock: the delay is unknown and the estimator finds it).
    #[arg(long, value_enum, default_value_t = GnssTags::Epoch)]
    pub gnss_tags: GnssTags,
    /// Epoch tags: how long after its epoch each fix is received (its stamp), s
    /// (default 0.05).
    #[arg(long)]
    pub gnss_latency: Option<f64>,
    /// Epoch tags: no PPS edges, the recording has only fixes received `--gnss-latency` after
    /// their epoch, for the estimator's software sync (it must find the latency itself).
    #[arg(long)]
    pub no_pps: bool,
    /// The output recording (MCAP).
    #[arg(short, long)]
    pub out: PathBuf,
    /// Replace an existing recording at --out (never one of the inputs).
    #[arg(long)]
    pub force: bool,
}

/// `ID=FILE` of `--array-imu`.
fn parse_array_imu(s: &str) -> Result<(String, PathBuf), String> {
    let (id, path) = s
        .split_once('=')
        .ok_or_else(|| format!("`{s}`: expected ID=FILE (e.g. 1=imu1.txt)"))?;
    if path.is_empty() {
        return Err(format!("`{s}`: no file after `=`"));
    }
    Ok((crate::config::estimator::parse_id(id)?, PathBuf::from(path)))
}

/// What the time tags of a GNSS file are.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum GnssTags {
    /// The GNSS epoch of each fix, on the IMU file's time scale (KF-GINS's and NMEA's meaning):
    /// the import adds PPS edges on whole seconds (hardware sync).
    Epoch,
    /// When each fix was received, on the IMU's clock (a logging computer's stamps): no PPS,
    /// the estimator finds the delay itself (software sync).
    Receipt,
}

/// Column order of a 13-column GNSS file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum GnssLayout {
    /// KF-GINS (C++): `sow lat lon h vN vE vD σN σE σD σvN σvE σvD`.
    KfGins,
    /// KF-GINS-Matlab `GNSS-POSVEL`: `sow lat lon h σN σE σD vN vE vD σvN σvE σvD`.
    Matlab,
}

/// What an import wrote.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ImportStats {
    /// IMU samples.
    pub imu: u64,
    /// GNSS fixes.
    pub fixes: u64,
    /// PPS edges.
    pub pps: u64,
    /// Truth samples.
    pub truth: u64,
    /// The GPS week used.
    pub week: i64,
    /// The IMU rate used, Hz.
    pub imu_rate_hz: f64,
    /// What the recording stores about its models (channel metadata keys and values).
    pub metadata: Vec<String>,
    /// Keys of the KF-GINS configuration not used.
    pub ignored: Vec<String>,
}

/// A sample on its way into the recording, ordered by its delivery (publish) time.
pub(crate) struct Item {
    pub(crate) publish_ns: i64,
    pub(crate) service: String,
    pub(crate) sample: AnySample,
}

/// Maps GPS seconds of week to host and UTC time.
#[derive(Clone, Copy)]
pub(crate) struct Timeline {
    pub(crate) week: i64,
    /// Seconds of week of the first record (host time HOST_BASE_NS).
    pub(crate) sow0: f64,
}

impl Timeline {
    pub(crate) fn host_ns(&self, sow: f64) -> i64 {
        HOST_BASE_NS + ((sow - self.sow0) * 1e9).round() as i64
    }
    pub(crate) fn gps_ns(&self, sow: f64) -> i64 {
        self.week * WEEK_NS + (sow * 1e9).round() as i64
    }
    pub(crate) fn utc_ns(&self, sow: f64) -> i64 {
        utc_ns_from_gps_ns(self.gps_ns(sow))
    }
}

/// A new recording at `out` for an import of `inputs` (refused if it is one of them; an existing
/// recording replaced only with `force`) whose time axis (host `HOST_BASE_NS` at GPS time
/// `gps0_ns`, ns) is declared on `axis_service`: every import's one start. Also the axis's
/// metadata value, for a report of what was written.
pub fn imported_recording(
    out: &Path,
    inputs: &[&Path],
    force: bool,
    axis_service: &str,
    gps0_ns: i64,
) -> Result<(SampleRecorder<BufWriter<OutputFile>>, String), RecordingError> {
    let mut rec = SampleRecorder::create(
        out,
        &Overwrite::new(inputs, force),
        navsync_recording::RecordingOptions::default(),
    )?;
    let axis = channels::metadata_value(&TimeAxis {
        host_ns: HOST_BASE_NS,
        gps_ns: gps0_ns,
    });
    rec.set_channel_metadata(axis_service, channels::META_TIME_AXIS, &axis)?;
    Ok((rec, axis))
}

/// Seconds of week as integer milliseconds (to match epochs of two files).
fn ms_of(sow: f64) -> i64 {
    (sow * 1e3).round() as i64
}

/// NED velocities, m/s, by epoch (seconds of week in ms).
type VelocitiesByEpoch = BTreeMap<i64, [f64; 3]>;

/// A velocity file: `sow vN vE vD [σN σE σD]` by epoch (ms), and the median σ when given.
fn read_velocities(path: &Path) -> Result<(VelocitiesByEpoch, Option<f64>), KfGinsError> {
    let mut v = BTreeMap::new();
    let mut sigmas = Vec::new();
    for r in Rows::open(path, &[4, 7])? {
        let (_, row) = r?;
        v.insert(ms_of(row[0]), [row[1], row[2], row[3]]);
        if row.len() == 7 {
            sigmas.extend_from_slice(&row[4..7]);
        }
    }
    sigmas.sort_by(f64::total_cmp);
    Ok((v, sigmas.get(sigmas.len() / 2).copied()))
}

/// The median velocity σ of a 13-column GNSS file (its last three columns).
fn median_vel_std(path: &Path) -> Result<Option<f64>, KfGinsError> {
    let mut sigmas = Vec::new();
    for r in Rows::open(path, &[7, 13])? {
        let (_, row) = r?;
        if row.len() == 13 {
            sigmas.extend_from_slice(&row[10..13]);
        }
    }
    sigmas.sort_by(f64::total_cmp);
    Ok(sigmas.get(sigmas.len() / 2).copied())
}

/// Median spacing of the first time tags of an IMU file, s.
pub(crate) fn median_spacing(path: &Path) -> Result<f64, KfGinsError> {
    let mut ts = Vec::new();
    for r in Rows::open(path, &[7, 8])?.take(2001) {
        ts.push(r?.1[0]);
    }
    let mut d: Vec<f64> = ts.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
    d.sort_by(f64::total_cmp);
    d.get(d.len() / 2).copied().ok_or_else(|| KfGinsError::Format {
        path: path.display().to_string(),
        line: 1,
        problem: "fewer than two IMU records with increasing time".into(),
    })
}

pub(crate) fn imu_items(
    rows: impl Iterator<Item = Result<(usize, Vec<f64>), KfGinsError>>,
    tl: Timeline,
    nominal_dt: f64,
    service: String,
    id: [u8; 8],
) -> impl Iterator<Item = Result<Item, KfGinsError>> {
    let mut prev: Option<f64> = None;
    let mut seq = 0u64;
    rows.map(move |r| {
        let (_, row) = r?;
        let t = row[0];
        let dt = match prev {
            Some(p) if t - p > 0.0 && t - p < 0.1 => t - p,
            _ => nominal_dt,
        };
        prev = Some(t);
        let host = tl.host_ns(t);
        let s = ImuSample {
            stamp: Stamp::host(host, seq, StampSource::Simulated),
            gyro_rps: [row[1] / dt, row[2] / dt, row[3] / dt],
            accel_mps2: [row[4] / dt, row[5] / dt, row[6] / dt],
            dt_s: dt,
            temperature_c: f64::NAN,
            imu_id: id,
            flags: 0,
            reserved: 0,
        };
        seq += 1;
        Ok(Item {
            publish_ns: host,
            service: service.clone(),
            sample: AnySample::Imu(s),
        })
    })
}

/// A GNSS file row's position STD north, east, down, m.
fn row_std(row: &[f64], layout: GnssLayout) -> [f64; 3] {
    match (row.len(), layout) {
        (13, GnssLayout::KfGins) => [row[7], row[8], row[9]],
        _ => [row[4], row[5], row[6]],
    }
}

/// The fixes of a GNSS file (small: read whole), with velocities by central differences when
/// the file has none.
fn read_fixes(
    path: &Path,
    tl: Timeline,
    layout: GnssLayout,
    latency_s: f64,
    velocities: &BTreeMap<i64, [f64; 3]>,
    span: (f64, f64),
) -> Result<Vec<GnssFix>, KfGinsError> {
    let rows: Vec<Vec<f64>> = Rows::open(path, &[7, 13])?
        .map(|r| r.map(|(_, row)| row))
        .filter(|r| r.as_ref().map_or(true, |row| row[0] >= span.0 && row[0] <= span.1))
        .collect::<Result<_, _>>()?;
    let ned = |a: &[f64], b: &[f64]| {
        navsync_shared::earth::ned_between(
            a[1].to_radians(),
            a[2].to_radians(),
            a[3],
            b[1].to_radians(),
            b[2].to_radians(),
            b[3],
        )
    };
    let mut out = Vec::with_capacity(rows.len());
    for (i, row) in rows.iter().enumerate() {
        let t = row[0];
        let mut f = GnssFix::empty(Stamp::host(
            tl.host_ns(t) + (latency_s * 1e9) as i64,
            i as u64,
            StampSource::Receipt,
        ));
        f.utc_ns = tl.utc_ns(t);
        f.gps_ns = tl.gps_ns(t);
        f.tod_ns = f.utc_ns.rem_euclid(86_400 * NS_PER_S);
        f.lat_deg = row[1];
        f.lon_deg = row[2];
        f.alt_msl_m = row[3];
        f.geoid_sep_m = 0.0;
        let vel = match (row.len(), layout) {
            (13, GnssLayout::KfGins) => Some([row[4], row[5], row[6]]),
            (13, GnssLayout::Matlab) => Some([row[7], row[8], row[9]]),
            _ => None,
        };
        [f.std_lat_m, f.std_lon_m, f.std_alt_m] = row_std(row, layout);
        let vel = vel.or_else(|| velocities.get(&ms_of(t)).copied());
        // Without a velocity from the receiver: speed and track from central differences
        // (the alignment's heading), but no velocity: they carry the positions' noise,
        // correlated from fix to fix, so the filter makes position-only updates (as KF-GINS).
        let from_receiver = vel.is_some();
        let vel = vel.or_else(|| {
            // Central difference of the neighbours within 2.5 s (one-sided at the ends).
            let a = if i > 0 && t - rows[i - 1][0] <= 2.5 {
                &rows[i - 1]
            } else {
                row
            };
            let b = if i + 1 < rows.len() && rows[i + 1][0] - t <= 2.5 {
                &rows[i + 1]
            } else {
                row
            };
            let dt = b[0] - a[0];
            (dt > 0.0).then(|| ned(a, b).map(|d| d / dt))
        });
        if let Some(v) = vel {
            f.speed_mps = v[0].hypot(v[1]);
            f.track_deg = v[1].atan2(v[0]).to_degrees().rem_euclid(360.0);
            if from_receiver {
                [f.vel_n_mps, f.vel_e_mps, f.vel_d_mps] = v;
            }
        }
        // Positions with the noise σ KF-GINS takes them with, not a receiver's accuracy.
        f.protocol = GNSS_PROTOCOL_FILE;
        f.mode = FixMode::Fix3d as u8;
        f.quality = 1;
        out.push(f);
    }
    Ok(out)
}

fn truth_items(
    rows: impl Iterator<Item = Result<(usize, Vec<f64>), KfGinsError>>,
    tl: Timeline,
    gnss_latency_s: f64,
) -> impl Iterator<Item = Result<Item, KfGinsError>> {
    let mut seq = 0u64;
    rows.map(move |r| {
        let (_, row) = r?;
        let n = NavRecord::from_row(&row);
        let host = tl.host_ns(n.sow);
        let mut t = SimTruth::zeroed();
        t.host_ns = host;
        t.utc_ns = tl.utc_ns(n.sow);
        t.seq = seq;
        t.lat_deg = n.lat_deg;
        t.lon_deg = n.lon_deg;
        t.height_m = n.height_m;
        t.vel_ned_mps = n.vel_ned_mps;
        t.rpy_rad = n.rpy_deg.map(f64::to_radians);
        t.gnss_latency_s = gnss_latency_s;
        t.imu_count = 1;
        seq += 1;
        Ok(Item {
            publish_ns: host,
            service: services::SIM_TRUTH.to_string(),
            sample: AnySample::Truth(t),
        })
    })
}

/// `count` PPS edges at the whole GPS seconds of week from `first_sow` on (each delivered 1 ms
/// after its edge, on `navsync/pps/0/edge`).
pub(crate) fn pps_items(tl: Timeline, first_sow: i64, count: i64) -> impl Iterator<Item = Result<Item, KfGinsError>> {
    (first_sow..first_sow + count.max(0)).enumerate().map(move |(i, s)| {
        let host = tl.host_ns(s as f64);
        let mut e = PpsEdge::zeroed();
        e.stamp = Stamp::host(host, i as u64, StampSource::Simulated);
        e.jitter_ns = 1_000.0;
        e.assert_edge = 1;
        Ok(Item {
            publish_ns: host + 1_000_000,
            service: services::pps_edge("0"),
            sample: AnySample::PpsEdge(e),
        })
    })
}

/// Takes the earliest of several time-ordered streams.
pub(crate) type Stream = Peekable<Box<dyn Iterator<Item = Result<Item, KfGinsError>>>>;

pub(crate) fn pop_earliest(streams: &mut [Stream]) -> Option<Result<Item, KfGinsError>> {
    let mut best: Option<(usize, i64)> = None;
    for (i, s) in streams.iter_mut().enumerate() {
        match s.peek() {
            Some(Err(_)) => return s.next(),
            Some(Ok(it)) if best.is_none_or(|(_, t)| it.publish_ns < t) => best = Some((i, it.publish_ns)),
            _ => {}
        }
    }
    best.and_then(|(i, _)| streams[i].next())
}

/// Runs `navsync import kf-gins`.
pub fn import(args: &ImportArgs) -> Result<ImportStats, KfGinsError> {
    let config = match &args.kf_gins_config {
        Some(p) => Some(KfGinsConfig::load(p).map_err(|e| KfGinsError::Format {
            path: e.path.display().to_string(),
            line: 0,
            problem: e.problem,
        })?),
        None => None,
    };
    let span = config.as_ref().map_or((None, None), |c| c.span_sow);
    let span = (span.0.unwrap_or(f64::NEG_INFINITY), span.1.unwrap_or(f64::INFINITY));
    let in_span = move |r: &Result<(usize, Vec<f64>), KfGinsError>| {
        r.as_ref().map_or(true, |(_, row)| row[0] >= span.0 && row[0] <= span.1)
    };
    let imu_rows = || -> Result<_, KfGinsError> { Ok(Rows::open(&args.imu, &[7, 8])?.filter(in_span)) };
    if let Some((id, _)) = args.array_imu.iter().find(|(id, _)| *id == args.imu_id) {
        return Err(KfGinsError::Format {
            path: "--array-imu".into(),
            line: 0,
            problem: format!("IMU id `{id}` is --imu-id's: each IMU of the array needs its own id"),
        });
    }
    let dt = match args.imu_rate_hz {
        Some(r) if r > 0.0 => 1.0 / r,
        _ => median_spacing(&args.imu)?,
    };
    // The week: given, else the truth file's first record's (when it is not 0).
    let truth_week = match &args.truth {
        Some(p) => match Rows::open(p, &[11])?.next() {
            Some(r) => Some(r?.1[0].round() as i64).filter(|w| *w > 0),
            None => None,
        },
        None => None,
    };
    let week = args.week.or(truth_week).unwrap_or(DEFAULT_WEEK);
    let (first_imu, last_imu) = {
        let (mut first, mut last) = (None, f64::NAN);
        for r in imu_rows()? {
            let t = r?.1[0];
            first.get_or_insert(t);
            last = t;
        }
        match first {
            Some(f) => (f, last),
            None => {
                return Err(KfGinsError::Format {
                    path: args.imu.display().to_string(),
                    line: 1,
                    problem: "no IMU records (in the configuration's start/end time)".into(),
                });
            }
        }
    };
    // The first IMU record's interval starts dt before its tag.
    let tl = Timeline {
        week,
        sow0: first_imu - dt,
    };
    let (velocities, vel_file_std) = match &args.gnss_vel {
        Some(p) => read_velocities(p)?,
        None => (BTreeMap::new(), None),
    };
    let (latency, no_pps) = match (args.gnss_tags, args.gnss_latency) {
        (GnssTags::Epoch, l) => (l.unwrap_or(FIX_LATENCY_S), args.no_pps),
        (GnssTags::Receipt, None) => (0.0, true),
        (GnssTags::Receipt, Some(_)) => {
            return Err(KfGinsError::Format {
                path: args.gnss.display().to_string(),
                line: 0,
                problem: "--gnss-latency describes epoch tags; with --gnss-tags receipt the tags are the receipt times"
                    .into(),
            });
        }
    };
    let fixes = read_fixes(&args.gnss, tl, args.gnss_layout, latency, &velocities, span)?;
    let vel_std = vel_file_std.or(median_vel_std(&args.gnss)?);
    let imu_service = services::imu_sample(&args.imu_id);
    let id = fixed_str::<8>(&args.imu_id);

    // PPS edges at every whole GPS second of the IMU span (delivered 1 ms after the edge).
    let first_edge = (first_imu - dt).ceil() as i64;
    let last_edge = last_imu.floor() as i64;
    let edges = if no_pps { 0 } else { last_edge - first_edge + 1 };
    let pps = pps_items(tl, first_edge, edges);
    let fix_service = services::gnss_fix("0");
    let fix_items = fixes.into_iter().map(move |f| {
        Ok(Item {
            publish_ns: f.stamp.host_ns,
            service: fix_service.clone(),
            sample: AnySample::GnssFix(f),
        })
    });
    let mut streams: Vec<Stream> = vec![
        (Box::new(imu_items(imu_rows()?, tl, dt, imu_service.clone(), id)) as Box<dyn Iterator<Item = _>>).peekable(),
        (Box::new(pps) as Box<dyn Iterator<Item = _>>).peekable(),
        (Box::new(fix_items) as Box<dyn Iterator<Item = _>>).peekable(),
    ];
    for (array_id, path) in &args.array_imu {
        let rows = Rows::open(path, &[7, 8])?.filter(in_span);
        let items = imu_items(rows, tl, dt, services::imu_sample(array_id), fixed_str::<8>(array_id));
        streams.push((Box::new(items) as Box<dyn Iterator<Item = _>>).peekable());
    }
    if let Some(p) = &args.truth {
        // Truth rows: week, seconds of week, …
        let rows = Rows::open(p, &[11])?
            .filter(move |r| r.as_ref().map_or(true, |(_, row)| row[1] >= span.0 && row[1] <= span.1));
        // Receipt tags: the true delay is not known to the import.
        let true_latency = if args.gnss_tags == GnssTags::Receipt {
            f64::NAN
        } else {
            latency
        };
        streams.push((Box::new(truth_items(rows, tl, true_latency)) as Box<dyn Iterator<Item = _>>).peekable());
    }
    let inputs: Vec<&Path> = [Some(args.imu.as_path()), Some(args.gnss.as_path())]
        .into_iter()
        .chain([
            args.truth.as_deref(),
            args.kf_gins_config.as_deref(),
            args.gnss_vel.as_deref(),
        ])
        .flatten()
        .chain(args.array_imu.iter().map(|(_, p)| p.as_path()))
        .collect();
    // The files' time axis: the host clock of every sample is GPS time shifted; outputs keep it.
    let (mut rec, axis) = imported_recording(&args.out, &inputs, args.force, &imu_service, tl.gps_ns(tl.sow0))?;
    let mut stats = ImportStats {
        week,
        imu_rate_hz: 1.0 / dt,
        ..Default::default()
    };
    stats
        .metadata
        .push(format!("{imu_service} {} = {axis}", channels::META_TIME_AXIS));
    // What the data were made with, for `replay --estimate`.
    let mut meta = |service: &str, key: &str, value: String| -> Result<(), KfGinsError> {
        rec.set_channel_metadata(service, key, &value)?;
        stats.metadata.push(format!("{service} {key} = {value}"));
        Ok(())
    };
    let fix_channel = services::gnss_fix("0");
    if let Some(v) = vel_std {
        meta(&fix_channel, channels::META_GNSS_VEL_STD, format!("{v}"))?;
    }
    if let Some(c) = &config {
        if let Some(n) = &c.noise {
            meta(&imu_service, channels::META_IMU_NOISE, channels::metadata_value(n))?;
        }
        if let Some(l) = c.lever_arm_m {
            meta(&fix_channel, channels::META_LEVER_ARM, channels::metadata_value(&l))?;
        }
        if let Some(i) = &c.initial {
            let state = InitialState {
                utc_ns: tl.utc_ns(i.sow),
                lat_deg: i.pos[0],
                lon_deg: i.pos[1],
                height_m: i.pos[2],
                vel_ned_mps: i.vel,
                rpy_deg: i.att_deg,
                gyro_bias_deg_per_h: i.gyro_bias_deg_per_h,
                accel_bias_mgal: i.accel_bias_mgal,
                pos_std_m: i.pos_std,
                vel_std_mps: i.vel_std,
                att_std_deg: i.att_std_deg,
            };
            meta(
                &imu_service,
                channels::META_INITIAL_STATE,
                channels::metadata_value(&state),
            )?;
        }
        stats.ignored.clone_from(&c.ignored);
    }
    write_streams(rec, &mut streams, tl.gps_ns(tl.sow0), &mut |s| match s {
        AnySample::Imu(_) => stats.imu += 1,
        AnySample::GnssFix(_) => stats.fixes += 1,
        AnySample::PpsEdge(_) => stats.pps += 1,
        AnySample::Truth(_) => stats.truth += 1,
        _ => {}
    })?;
    Ok(stats)
}

/// Writes the earliest sample of `streams` until all are empty, each shown to `count` first,
/// and closes the recording. Log time: the UTC of the delivery instant (as `navsync sim --fast
/// --record` writes it) on the axis where host time `HOST_BASE_NS` is GPS time `gps0_ns`.
pub(crate) fn write_streams(
    mut rec: SampleRecorder<BufWriter<OutputFile>>,
    streams: &mut [Stream],
    gps0_ns: i64,
    count: &mut dyn FnMut(&AnySample),
) -> Result<(), KfGinsError> {
    while let Some(item) = pop_earliest(streams) {
        let item = item?;
        count(&item.sample);
        let utc = utc_ns_from_gps_ns(gps0_ns + (item.publish_ns - HOST_BASE_NS));
        rec.write(
            &item.service,
            &item.sample,
            utc.max(0) as u64,
            item.publish_ns.max(0) as u64,
        )?;
    }
    rec.close()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_are_in_kf_gins_format() {
        assert_eq!(
            format_row(&[0.0, 456250.0, 30.4447858054, -1.5]),
            "0.000000000     456250.000000000 30.444785805    -1.500000000    \n"
        );
        let (week, sow) = week_sow(utc_ns_from_gps_ns(2200 * WEEK_NS + 456_250_500_000_000));
        assert_eq!(week, 2200);
        assert!((sow - 456_250.5).abs() < 1e-9);
    }

    #[test]
    fn rows_reject_bad_lines_with_their_line_number() {
        let dir = std::env::temp_dir().join(format!("kfgins-rows-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("gnss.pos");
        std::fs::write(&p, "# header\n1,2,3,4,5,6,7\n\n1 2\t3 4 5 6 x\n").unwrap();
        let mut rows = Rows::open(&p, &[7, 13]).unwrap();
        assert_eq!(
            rows.next().unwrap().unwrap(),
            (2, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0])
        );
        let e = rows.next().unwrap().unwrap_err().to_string();
        assert!(e.ends_with("gnss.pos:4: `x` is not a number"), "{e}");
        std::fs::write(&p, "1 2 3\n").unwrap();
        let e = Rows::open(&p, &[7, 13])
            .unwrap()
            .next()
            .unwrap()
            .unwrap_err()
            .to_string();
        assert!(e.ends_with("gnss.pos:1: 3 columns, expected 7 or 13"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
