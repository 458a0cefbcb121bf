//! `navsync replay REC.mcap`: publishes a recording into the live services, and
//! `navsync replay REC.mcap --estimate`: runs the estimator library over it offline.
//!
//! Live replay publishes every recorded sample, unchanged, on the service it was recorded
//! from, with the recorded spacing of `publish_time` (host `CLOCK_MONOTONIC` at receipt for
//! `navsync record`, the delivery instant for `navsync sim --fast --record`) divided by
//! `--speed`. Waits are absolute `clock_nanosleep`s on `CLOCK_MONOTONIC`, so the schedule does
//! not drift over a long file; `--speed max` publishes as fast as it can (subscribers with
//! full buffers then lose samples, as they would with a fast driver). A running estimator or
//! any other subscriber sees the same service names, types and samples as from the drivers;
//! the samples keep their recorded stamps (with `--loop`, every lap repeats them).
//!
//! `--estimate` feeds the samples the live estimator subscribes to (`--gnss`, `--pps`,
//! `--imus` ids) in recorded order through [`offline::run_ordered`] with the pipeline the live
//! process builds from the same flags (`Settings::pipeline_config`), as fast as the CPU
//! allows. Both go through [`navsync_estimator::input_order`], so the `NavState`s are bit-identical to the
//! live process's for the same samples, and bit-identical from run to run.

use std::collections::HashSet;
use std::io::Write;
use std::path::PathBuf;
use std::str::FromStr;

use navsync_recording::glob::{ServiceGlob, any_matches};
use navsync_recording::mcap_reader::ScanEnd;
use navsync_recording::ports::AnyPublisher;
use navsync_recording::{RecordingError, SampleReader, SampleRecorder};
use navsync_shared::ipc::{IpcError, IpcNode};
use navsync_shared::pacing::sleep_until;
use navsync_shared::samples::AnySample;
use navsync_shared::services::{self, ServiceKind};
use navsync_shared::time::{NS_PER_S, monotonic_now_ns};
use tracing::{info, info_span, warn};

use navsync_estimator::evaluation::{DelayTruth, Summary};
use navsync_estimator::offline::{self, Output};
use navsync_estimator::pipeline::Pipeline;
use navsync_estimator::settings::Settings;

/// Replay speed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Speed {
    /// Recorded spacing divided by this factor (1: real time).
    Factor(f64),
    /// As fast as possible.
    Max,
}

impl FromStr for Speed {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "max" {
            return Ok(Self::Max);
        }
        match s.parse::<f64>() {
            Ok(f) if f.is_finite() && f > 0.0 => Ok(Self::Factor(f)),
            _ => Err(format!("`{s}`: a speed is a factor > 0 (1 = real time) or `max`")),
        }
    }
}

/// Settings of a live replay.
#[derive(Debug, Clone)]
pub struct ReplayArgs {
    /// The recording.
    pub input: PathBuf,
    /// Speed.
    pub speed: Speed,
    /// Start over at the end until stopped.
    pub looped: bool,
    /// Service patterns to publish (empty: every recorded service).
    pub services: Vec<String>,
    /// Progress bar on stderr.
    pub progress: bool,
}

/// Errors of `navsync replay`.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// IPC failure.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// Reading the recording or writing the output.
    #[error(transparent)]
    Recording(#[from] RecordingError),
    /// Writing the KF-GINS result.
    #[error(transparent)]
    KfGins(#[from] crate::roles::kf_gins::KfGinsError),
    /// Writing the summary.
    #[error("writing {path}: {source}")]
    Io {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
}

/// What a live replay published.
#[derive(Debug, Clone, Default)]
pub struct ReplayStats {
    /// Samples published.
    pub published: u64,
    /// Laps completed.
    pub laps: u64,
}

/// Publishes the recording into the live services until its end (every lap with `--loop`) or
/// SIGINT/SIGTERM.
pub fn run(args: &ReplayArgs) -> Result<ReplayStats, ReplayError> {
    let _span = info_span!("replay").entered();
    // Wake-ups within µs of the requested time (the default timer slack is 50 µs).
    // SAFETY: prctl with an integer argument.
    unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1u64) };
    let globs: Vec<ServiceGlob> = args.services.iter().map(|s| ServiceGlob::new(s)).collect();
    let node = IpcNode::new("replay")?;
    let mut pubs: Vec<Option<AnyPublisher>> = Vec::new();
    let mut stats = ReplayStats::default();
    let tty = args.progress && is_tty();
    'laps: loop {
        let mut reader = SampleReader::open(&args.input)?;
        // Create the publishers before the clock starts when the summary lists the channels.
        if let Some(summary) = reader.summary() {
            for ch in &summary.channels {
                if ServiceKind::of(&ch.topic).is_some() && any_matches(&globs, &ch.topic) {
                    publisher(&node, &mut pubs, ch.id, &ch.topic)?;
                }
            }
        }
        let file_len = reader.mcap().file_len().max(1);
        let start = monotonic_now_ns() + 20_000_000;
        let mut t0: Option<u64> = None;
        let mut last_progress = 0i64;
        let mut lap_published = 0u64;
        while let Some(m) = reader.next_sample()? {
            if !any_matches(&globs, m.service) {
                continue;
            }
            let rel_ns = m.publish_time.saturating_sub(*t0.get_or_insert(m.publish_time));
            if let Speed::Factor(f) = args.speed {
                let target = start + (rel_ns as f64 / f) as i64;
                loop {
                    let now = monotonic_now_ns();
                    if now >= target {
                        break;
                    }
                    if node.termination_requested() {
                        break 'laps;
                    }
                    sleep_until(target.min(now + 100_000_000), 0);
                }
            } else if lap_published.is_multiple_of(4096) && node.termination_requested() {
                break 'laps;
            }
            let p = publisher(&node, &mut pubs, m.channel_id, m.service)?;
            if let Err(e) = p.publish(&m.sample) {
                warn!("publishing on {}: {e}", m.service);
            }
            lap_published += 1;
            stats.published += 1;
            let now = monotonic_now_ns();
            if args.progress && now - last_progress >= if tty { NS_PER_S / 5 } else { 5 * NS_PER_S } {
                let done = reader.mcap().position() as f64 / file_len as f64;
                progress(tty, done, rel_ns, stats.published, args.speed, stats.laps);
                last_progress = now;
            }
        }
        if let Some(ScanEnd::Truncated { offset, record }) = reader.scan_end() {
            warn!(
                "{}: the recording stops at byte {offset} ({record}): it was not closed properly; replayed what precedes",
                args.input.display()
            );
        }
        stats.laps += 1;
        if args.progress {
            progress(tty, 1.0, 0, stats.published, args.speed, stats.laps);
        }
        if !args.looped || lap_published == 0 || node.termination_requested() {
            break;
        }
    }
    if args.progress {
        eprintln!();
    }
    info!(published = stats.published, laps = stats.laps, "replay finished");
    Ok(stats)
}

fn publisher<'a>(
    node: &IpcNode,
    pubs: &'a mut Vec<Option<AnyPublisher>>,
    channel: u16,
    service: &str,
) -> Result<&'a mut AnyPublisher, IpcError> {
    let i = usize::from(channel);
    if pubs.len() <= i {
        pubs.resize_with(i + 1, || None);
    }
    if pubs[i].is_none() {
        pubs[i] = Some(AnyPublisher::open(node, service)?);
    }
    Ok(pubs[i].as_mut().expect("just created"))
}

fn is_tty() -> bool {
    // SAFETY: isatty only inspects the descriptor.
    unsafe { libc::isatty(2) == 1 }
}

fn progress(tty: bool, done: f64, rel_ns: u64, published: u64, speed: Speed, laps: u64) {
    const WIDTH: usize = 30;
    let filled = ((done.clamp(0.0, 1.0) * WIDTH as f64) as usize).min(WIDTH);
    let speed = match speed {
        Speed::Factor(f) => format!("x{f}"),
        Speed::Max => "max".into(),
    };
    let line = format!(
        "replay [{}{}] {:3.0}%  t+{:.1} s  {published} samples  {speed}{}",
        "#".repeat(filled),
        "-".repeat(WIDTH - filled),
        done * 100.0,
        rel_ns as f64 * 1e-9,
        if laps > 0 {
            format!("  lap {}", laps + 1)
        } else {
            String::new()
        }
    );
    let mut err = std::io::stderr().lock();
    if tty {
        let _ = write!(err, "\r\x1b[2K{line}");
    } else {
        let _ = writeln!(err, "{line}");
    }
    let _ = err.flush();
}

/// Settings of `navsync replay --estimate`.
#[derive(Debug, Clone)]
pub struct EstimateArgs {
    /// The recording.
    pub input: PathBuf,
    /// The estimator's settings, as for the live process.
    pub est: Settings,
    /// Write NavState and TimeState here.
    pub out: Option<PathBuf>,
    /// Write `out` in KF-GINS's result layout instead of MCAP ([`crate::roles::kf_gins::ResultWriter`]).
    pub kf_gins_format: bool,
    /// Write the accuracy summary here as JSON.
    pub summary_json: Option<PathBuf>,
}

/// Runs the estimator over a recording as fast as the CPU allows; prints the summary table
/// (to stdout) and returns it.
pub fn run_estimate(args: &EstimateArgs) -> Result<Summary, ReplayError> {
    let _span = info_span!("replay-estimate").entered();
    let mut reader = SampleReader::open(&args.input)?;
    // Exactly what the live estimator subscribes to, and the truth for the evaluation.
    let mut wanted: HashSet<String> = HashSet::new();
    wanted.extend(args.est.pps_ids.iter().map(|id| services::pps_edge(id)));
    wanted.extend(args.est.gnss_ids.iter().map(|id| services::gnss_fix(id)));
    wanted.extend(args.est.imu_ids.iter().map(|id| services::imu_sample(id)));
    wanted.insert(services::SIM_TRUTH.to_string());
    let mut read_err: Option<RecordingError> = None;
    let samples = std::iter::from_fn(|| {
        loop {
            match reader.next_sample() {
                Ok(Some(m)) if wanted.contains(m.service) => return Some((m.sample, m.log_time)),
                Ok(Some(_)) => {}
                Ok(None) => return None,
                Err(e) => {
                    read_err = Some(e);
                    return None;
                }
            }
        }
    });
    let mut out = match &args.out {
        Some(p) if !args.kf_gins_format => Some(SampleRecorder::create(p)?),
        _ => None,
    };
    let mut kf_gins = match &args.out {
        Some(p) if args.kf_gins_format => Some(crate::roles::kf_gins::ResultWriter::create(p)?),
        _ => None,
    };
    let mut kf_gins_err: Option<crate::roles::kf_gins::KfGinsError> = None;
    let mut write_err: Option<RecordingError> = None;
    let cfg = args.est.pipeline_config();
    let reference = cfg.reference_imu.clone();
    let mut pipeline = Pipeline::new(cfg);
    let truth = if args.est.software_sync {
        DelayTruth::ReceiverLatency
    } else {
        DelayTruth::Zero
    };
    let run = offline::run_ordered(
        &mut pipeline,
        Some(&reference),
        samples,
        truth,
        out.is_some(),
        |o, &log_time| {
            if kf_gins_err.is_none()
                && let (Some(w), Output::Nav(n)) = (kf_gins.as_mut(), o)
            {
                kf_gins_err = w.write(n).err();
            }
            let Some(rec) = out.as_mut() else { return };
            if write_err.is_some() {
                return;
            }
            let r = match o {
                Output::Nav(n) => rec.write(
                    services::NAV_STATE,
                    &AnySample::Nav(*n),
                    log_time,
                    n.host_ns.max(0) as u64,
                ),
                Output::Time(t) => rec.write(
                    services::TIME_STATE,
                    &AnySample::Time(*t),
                    log_time,
                    t.computed_host_ns.max(0) as u64,
                ),
            };
            if let Err(e) = r {
                write_err = Some(e);
            }
        },
    );
    if let Some(e) = read_err.or(write_err) {
        return Err(e.into());
    }
    if let Some(ScanEnd::Truncated { offset, record }) = reader.scan_end() {
        warn!(
            "{}: the recording stops at byte {offset} ({record}): it was not closed properly; estimated over what precedes",
            args.input.display()
        );
    }
    if let Some(rec) = out {
        rec.close()?;
    }
    if let Some(e) = kf_gins_err {
        return Err(e.into());
    }
    if let Some(w) = kf_gins {
        w.finish()?;
    }
    println!("{}", run.summary.table());
    if let Some(p) = &args.summary_json {
        let text = serde_json::to_string_pretty(&run.summary).unwrap_or_default();
        std::fs::write(p, text).map_err(|source| ReplayError::Io {
            path: p.display().to_string(),
            source,
        })?;
    }
    Ok(run.summary)
}
