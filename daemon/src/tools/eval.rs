//! `navsync eval --truth FILE --solution FILE`: position, velocity and attitude error
//! statistics of one trajectory against another.
//!
//! Either file is a KF-GINS navigation result or truth (11 text columns, see
//! [`super::kf_gins`]) or a navsync recording (MCAP: the solution's `NavState`s, the truth's
//! `SimTruth` or, without it, its `NavState`s). Both are put on GPS time (KF-GINS: week and
//! seconds of week; navsync: UTC plus leap seconds); when a KF-GINS file has week 0 (KF-GINS
//! writes 0), only the seconds of week are compared. The truth is interpolated linearly to every
//! solution epoch inside its span (yaw unwrapped); the errors are solution minus truth: position
//! in metres north/east/down at the truth point (through ECEF), velocity NED, roll/pitch/yaw
//! wrapped to ±180°. Solution states while aligning are not compared; `--skip S` leaves out the
//! first S seconds.

use std::path::{Path, PathBuf};

use navsync_estimator::evaluation::track::{EvalReport, Track, TrackPoint, errors, statistics};
use navsync_recording::SampleReader;
use navsync_shared::samples::{AnySample, NavStatus};
use navsync_shared::time::gps_ns_from_utc_ns;

use super::kf_gins;

/// Errors of `navsync eval`.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// Reading a KF-GINS file.
    #[error(transparent)]
    KfGins(#[from] kf_gins::KfGinsError),
    /// Reading a recording.
    #[error(transparent)]
    Recording(#[from] navsync_recording::RecordingError),
    /// Reading a file.
    #[error("{0}: {1}")]
    Io(String, std::io::Error),
    /// Nothing to compare.
    #[error("{0}")]
    Empty(String),
}

fn is_mcap(path: &Path) -> Result<bool, EvalError> {
    use std::io::Read;
    let mut f = std::fs::File::open(path).map_err(|e| EvalError::Io(path.display().to_string(), e))?;
    let mut magic = [0u8; 5];
    let n = f
        .read(&mut magic)
        .map_err(|e| EvalError::Io(path.display().to_string(), e))?;
    Ok(n == 5 && &magic == b"\x89MCAP")
}

/// Which samples of a recording make the trajectory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrackRole {
    /// `SimTruth`, else `NavState`.
    Truth,
    /// `NavState` (not while aligning).
    Solution,
}

/// Reads a trajectory from a KF-GINS file or a recording.
pub fn read_trajectory(path: &Path, role: TrackRole) -> Result<Track, EvalError> {
    let source = path.display().to_string();
    if !is_mcap(path)? {
        let recs = kf_gins::read_nav(path)?;
        let week_known = recs.iter().all(|r| r.week > 0);
        let points = recs
            .iter()
            .map(|r| TrackPoint {
                t_s: if week_known {
                    r.week as f64 * 604_800.0 + r.sow
                } else {
                    r.sow
                },
                lat_deg: r.lat_deg,
                lon_deg: r.lon_deg,
                height_m: r.height_m,
                vel_ned_mps: r.vel_ned_mps,
                rpy_deg: r.rpy_deg,
            })
            .collect();
        return Ok(Track {
            points,
            week_known,
            source,
        });
    }
    let mut reader = SampleReader::open(path)?;
    let (mut truth, mut nav) = (Vec::new(), Vec::new());
    let t_of = |utc_ns: i64| gps_ns_from_utc_ns(utc_ns) as f64 * 1e-9;
    while let Some(s) = reader.next_sample()? {
        match s.sample {
            AnySample::Truth(t) if role == TrackRole::Truth && t.utc_ns != i64::MIN => truth.push(TrackPoint {
                t_s: t_of(t.utc_ns),
                lat_deg: t.lat_deg,
                lon_deg: t.lon_deg,
                height_m: t.height_m,
                vel_ned_mps: t.vel_ned_mps,
                rpy_deg: t.rpy_rad.map(f64::to_degrees),
            }),
            AnySample::Nav(n) if n.utc_ns != i64::MIN && n.status != NavStatus::Aligning as u8 => {
                nav.push(TrackPoint {
                    t_s: t_of(n.utc_ns),
                    lat_deg: n.lat_deg,
                    lon_deg: n.lon_deg,
                    height_m: n.height_m,
                    vel_ned_mps: n.vel_ned_mps,
                    rpy_deg: n.rpy_rad.map(f64::to_degrees),
                })
            }
            _ => {}
        }
    }
    let mut points = if role == TrackRole::Truth && !truth.is_empty() {
        truth
    } else {
        nav
    };
    points.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    Ok(Track {
        points,
        week_known: true,
        source,
    })
}

/// `navsync eval`: position, velocity and attitude error statistics of a trajectory against
/// a reference (KF-GINS result/truth files or navsync recordings).
#[derive(Debug, Clone, clap::Args)]
pub struct EvalArgs {
    /// Reference trajectory.
    #[arg(long)]
    pub truth: PathBuf,
    /// Trajectory to evaluate.
    #[arg(long)]
    pub solution: PathBuf,
    /// Leave out the solution's first S seconds.
    #[arg(long = "skip", default_value_t = 0.0)]
    pub skip_s: f64,
    /// JSON instead of the table.
    #[arg(long)]
    pub json: bool,
}

/// Runs `navsync eval`; prints the table (or JSON) and returns the report.
pub fn run(args: &EvalArgs) -> Result<EvalReport, EvalError> {
    let truth = read_trajectory(&args.truth, TrackRole::Truth)?;
    let mut solution = read_trajectory(&args.solution, TrackRole::Solution)?;
    if truth.points.len() < 2 {
        return Err(EvalError::Empty(format!(
            "{}: fewer than two truth points",
            truth.source
        )));
    }
    let total = solution.points.len();
    if let Some(t0) = solution.points.first().map(|p| p.t_s) {
        solution.points.retain(|p| p.t_s >= t0 + args.skip_s);
    }
    let errs = errors(&truth, &solution, 2.0);
    if errs.is_empty() {
        return Err(EvalError::Empty(format!(
            "no solution point of {} lies within the truth's time span ({})",
            solution.source, truth.source
        )));
    }
    let report = statistics(&truth.source, &solution.source, &errs, total);
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report).unwrap_or_default());
    } else {
        print!("{}", report.table());
    }
    Ok(report)
}
