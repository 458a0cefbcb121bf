//! `navsync replay REC.mcap`: publishes a recording into the live services
//! (`navsync replay REC.mcap --estimate` runs the estimator over it offline instead:
//! [`crate::tools::estimate`]).
//!
//! Live replay publishes every recorded sample, unchanged, on the service it was recorded
//! from, with the recorded spacing of `publish_time` (host `CLOCK_MONOTONIC` at receipt for
//! `navsync record`, the delivery instant for `navsync sim --fast --record`) divided by
//! `--speed`. Waits are absolute `clock_nanosleep`s on `CLOCK_MONOTONIC`, so the schedule does
//! not drift over a long file; `--speed max` publishes as fast as it can (subscribers with
//! full buffers then lose samples, as they would with a fast driver). A running estimator or
//! any other subscriber sees the same service names, types and samples as from the drivers;
//! the samples keep their recorded stamps (with `--loop`, every lap repeats them).

use std::io::Write;
use std::path::PathBuf;

use navsync_recording::glob::{ServiceGlob, any_matches};
use navsync_recording::mcap_reader::ScanEnd;
use navsync_recording::ports::AnyPublisher;
use navsync_recording::{RecordingError, SampleReader};
use navsync_shared::ipc::{IpcError, IpcNode};
use navsync_shared::pacing::{Speed, sleep_until};
use navsync_shared::services::ServiceKind;
use navsync_shared::time::{NS_PER_S, monotonic_now_ns};
use tracing::{info, info_span, warn};

use crate::config::Loaded;
use crate::tools::estimate;

/// `navsync replay`: publishes a recording into the live services with its original timing,
/// or runs the estimator over it offline (`--estimate`).
#[derive(clap::Args, Debug)]
pub struct Options {
    /// The recording (MCAP).
    pub input: PathBuf,
    /// `1` (real time), a factor such as 10, or `max`.
    #[arg(long, default_value = "1")]
    pub speed: Speed,
    /// Start over at the end, until stopped.
    #[arg(long = "loop")]
    pub looped: bool,
    /// Publish only these services: names or patterns (`*` within a segment, `**` across).
    #[arg(long, num_args = 1..)]
    pub services: Vec<String>,
    /// Run the estimator over the recording as fast as the CPU allows instead of publishing.
    #[arg(long)]
    pub estimate: bool,
    /// With --estimate: its outputs and settings.
    #[command(flatten)]
    pub estimate_opts: estimate::EstimateOptions,
}

/// Runs `navsync replay` as the options say.
pub fn main(opts: Options, cfg: &Loaded) -> anyhow::Result<()> {
    use anyhow::Context;
    if opts.estimate {
        estimate::run(&opts.input, &opts.estimate_opts, cfg)
            .with_context(|| format!("estimating over {}", opts.input.display()))?;
        return Ok(());
    }
    run(&ReplayArgs {
        input: opts.input.clone(),
        speed: opts.speed,
        looped: opts.looped,
        services: opts.services,
        progress: true,
    })
    .with_context(|| format!("replaying {}", opts.input.display()))?;
    Ok(())
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
    /// Reading the recording.
    #[error(transparent)]
    Recording(#[from] RecordingError),
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
    navsync_shared::pacing::minimal_timer_slack();
    let globs: Vec<ServiceGlob> = args.services.iter().map(|s| ServiceGlob::new(s)).collect();
    let node = IpcNode::new("replay")?;
    navsync_shared::sd_notify::ready(&format!("replaying {}", args.input.display()));
    let mut pubs: Vec<Option<AnyPublisher>> = Vec::new();
    let mut stats = ReplayStats::default();
    let tty = args.progress && is_tty();
    let started = monotonic_now_ns();
    'laps: loop {
        let mut reader = SampleReader::open(&args.input)?;
        // Create the publishers before the clock starts when the summary lists the channels.
        if let Some(summary) = reader.summary() {
            for ch in &summary.channels {
                let service = navsync_recording::channels::service_of(&ch.topic);
                if ServiceKind::of(service).is_some() && any_matches(&globs, service) {
                    publisher(&node, &mut pubs, ch.id, service)?;
                }
            }
        }
        let file_len = reader.mcap().file_len().max(1);
        let start = monotonic_now_ns() + 20_000_000;
        let mut t0: Option<u64> = None;
        let mut last_progress = 0i64;
        let mut lap_published = 0u64;
        // Recording time of the last sample published (ns since the lap's first).
        let mut last_rel_ns = 0u64;
        while let Some(m) = reader.next_sample()? {
            if !any_matches(&globs, m.service) {
                continue;
            }
            let rel_ns = m.publish_time.saturating_sub(*t0.get_or_insert(m.publish_time));
            last_rel_ns = rel_ns;
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
        for c in reader.skipped_chunks() {
            warn!("{}: {c}; replayed the rest", args.input.display());
        }
        if args.progress {
            progress(tty, 1.0, last_rel_ns, stats.published, args.speed, stats.laps);
        }
        stats.laps += 1;
        if !args.looped || lap_published == 0 || node.termination_requested() {
            break;
        }
    }
    if args.progress {
        let s = (monotonic_now_ns() - started) as f64 / 1e9;
        eprintln!(
            "\nreplay: {} samples in {s:.2} s ({:.0} samples/s)",
            stats.published,
            stats.published as f64 / s.max(1e-9)
        );
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
    std::io::IsTerminal::is_terminal(&std::io::stderr())
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
