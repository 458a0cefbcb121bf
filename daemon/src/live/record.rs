//! `navsync record OUT.mcap [--services GLOB …] [--duration S]`: records navsync services into
//! an MCAP file (see `navsync_recording` for the format and conventions).
//!
//! One subscriber per service and one wake-up for all ([`navsync_shared::ipc::Wake`]): the
//! recorder sleeps until a publisher wakes it (no polling per sample). Services are found by
//! name: patterns without wildcards are subscribed at start (so nothing published after the recorder started is
//! missed), wildcard patterns (default `navsync/**`: every sensor sample, time state, nav
//! state, health, sim truth) are matched against `list_services()` every
//! [`DISCOVERY_INTERVAL`], so services that appear later are recorded from then on.
//!
//! Each wake-up drains every subscriber and writes what it found in stamp order (by the
//! sample's host time, ties in drain order: within one wake-up that is the order the
//! publishers stamped, hence published, them), all with the same times: `log_time` =
//! `CLOCK_REALTIME` and `publish_time` = `CLOCK_MONOTONIC` at the wake-up. With the default CDR
//! encoding the loop allocates nothing per message in steady state (JSON, `--encoding json`,
//! allocates while encoding).
//!
//! The open chunk is closed and handed to the operating system at least every
//! [`CHUNK_INTERVAL`], so `kill -9` loses at most that much; SIGINT/SIGTERM or the end of
//! `--duration` close the file with its summary and footer. Progress (elapsed time, file size,
//! messages per service) goes to stderr. An existing file at OUT is refused (it used to be
//! truncated silently) unless `--force`.

use std::collections::HashSet;
use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

use navsync_recording::glob::{ServiceGlob, any_matches};
use navsync_recording::ports::AnySubscriber;
use navsync_recording::{RecordingError, SampleRecorder};
use navsync_shared::health_reporter::HealthReporter;
use navsync_shared::ipc::{self, IpcError, IpcNode};
use navsync_shared::samples::AnySample;
use navsync_shared::services::ServiceKind;
use navsync_shared::time::{NS_PER_S, monotonic_now_ns, realtime_now_ns};
use tracing::{info, info_span, warn};

/// How often wildcard patterns are matched against the existing services.
pub const DISCOVERY_INTERVAL: Duration = Duration::from_millis(500);
/// Longest time a message waits in the open chunk before it reaches the operating system.
pub const CHUNK_INTERVAL: Duration = Duration::from_secs(1);
/// Default patterns: every navsync service.
pub const DEFAULT_SERVICES: &str = "navsync/**";

/// `navsync record`: navsync services into an MCAP file until Ctrl-C/SIGTERM or --duration.
#[derive(Debug, Clone, clap::Args)]
pub struct Options {
    /// Output file (MCAP) [default: [outputs.record].path]; `{start}` in it becomes the UTC
    /// start time (`20261204T170525Z`), so every run gets a file of its own.
    pub out: Option<PathBuf>,
    /// Services to record: names or patterns (`*` within a segment, `**` across)
    /// [default: [outputs.record].services, else navsync/**].
    #[arg(long, num_args = 1..)]
    pub services: Vec<String>,
    /// Stop after this many seconds.
    #[arg(long = "duration")]
    pub duration_s: Option<f64>,
    /// Encoding and standard messages.
    #[command(flatten)]
    pub format: crate::config::recording::RecordingFlags,
    /// Replace an existing file at OUT (without it, an existing file is refused).
    #[arg(long)]
    pub force: bool,
}

/// Runs `navsync record`: flags, else `[outputs.record]`.
pub fn main(opts: Options, cfg: &crate::config::Loaded) -> anyhow::Result<()> {
    use anyhow::Context;
    let r = cfg.config.outputs.record.as_ref();
    let Some(out) = opts.out.or_else(|| r.map(|r| r.path.clone())) else {
        anyhow::bail!("no output file, and no [outputs.record] in {}", cfg.shown());
    };
    let out = with_start_time(&out, realtime_now_ns());
    let services = if opts.services.is_empty() {
        r.map(|r| r.services.clone()).unwrap_or_default()
    } else {
        opts.services
    };
    let metadata = crate::config::estimator::recording_metadata(cfg)?;
    run(&RecordArgs {
        out: out.clone(),
        services,
        duration_s: opts.duration_s,
        progress: true,
        metadata,
        options: opts.format.options(&cfg.config.recording),
        force: opts.force,
    })
    .with_context(|| format!("recording {}", out.display()))?;
    Ok(())
}

/// Settings of a recording.
#[derive(Debug, Clone)]
pub struct RecordArgs {
    /// Output file.
    pub out: PathBuf,
    /// Service patterns (empty: [`DEFAULT_SERVICES`]).
    pub services: Vec<String>,
    /// Stop after this many seconds.
    pub duration_s: Option<f64>,
    /// Print progress to stderr.
    pub progress: bool,
    /// Channel metadata (service, key, value): what the devices are
    /// ([`crate::config::estimator::recording_metadata`]).
    pub metadata: Vec<(String, &'static str, String)>,
    /// Encoding, compression, standard messages.
    pub options: navsync_recording::RecordingOptions,
    /// Replace an existing file at `out` (else it is refused).
    pub force: bool,
}

/// Errors of `navsync record`.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// IPC failure.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// Writing the file.
    #[error(transparent)]
    Recording(#[from] RecordingError),
    /// A pattern names something that is not a navsync service.
    #[error(
        "`{0}` is not a navsync service name or pattern (expected e.g. navsync/imu/0/sample, navsync/imu/*/sample)"
    )]
    BadPattern(String),
    /// A health counter could not be registered.
    #[error(transparent)]
    Health(#[from] navsync_shared::health_reporter::HealthError),
}

/// What a recording run wrote.
#[derive(Debug, Clone, Default)]
pub struct RecordStats {
    /// Messages per service.
    pub per_service: Vec<(String, u64)>,
    /// Bytes of the file.
    pub bytes: u64,
}

/// Records until SIGINT/SIGTERM or the duration.
pub fn run(args: &RecordArgs) -> Result<RecordStats, RecordError> {
    let _span = info_span!("record").entered();
    let patterns: Vec<ServiceGlob> = if args.services.is_empty() {
        vec![ServiceGlob::new(DEFAULT_SERVICES)]
    } else {
        args.services.iter().map(|s| ServiceGlob::new(s)).collect()
    };
    for p in &patterns {
        if p.is_literal() && ServiceKind::of(p.as_str()).is_none() || !p.as_str().starts_with("navsync/") {
            return Err(RecordError::BadPattern(p.as_str().to_string()));
        }
    }
    let node = IpcNode::new("record")?;
    let mut subs: Vec<AnySubscriber> = Vec::new();
    let mut refused: HashSet<String> = HashSet::new();
    for p in patterns.iter().filter(|p| p.is_literal()) {
        subscribe(&node, &mut subs, p.as_str())?;
    }
    let found = new_services(&patterns, &subs, &refused)?;
    subscribe_all(&node, &mut subs, &mut refused, found);
    // Messages per subscriber.
    let mut counts: Vec<u64> = vec![0; subs.len()];
    let mut health = HealthReporter::new(&node, "record")?;
    let c_msgs = health.counter("messages")?;
    let c_bytes = health.counter("bytes")?;
    let c_services = health.counter("services")?;
    let r_msgs = health.rate("messages")?;

    // The file appears once the initial subscriptions exist: from then on nothing is missed.
    // It is created exclusively (an existing file is refused unless --force): a recording
    // grows at its own name, readable while it is written.
    let mut rec = SampleRecorder::create_live(&args.out, args.force, args.options.clone())?;
    for (service, key, value) in &args.metadata {
        rec.set_channel_metadata(service, key, value)?;
    }
    for s in &subs {
        rec.channel(s.service())?;
    }
    info!(file = %args.out.display(), services = subs.len(), "recording");
    navsync_shared::sd_notify::ready(&format!("recording to {}", args.out.display()));

    let t0 = monotonic_now_ns();
    let end = args.duration_s.map(|d| t0 + (d * 1e9) as i64);
    let mut last_flush = t0;
    let mut last_discovery = t0;
    let mut last_progress = 0i64;
    let tty = args.progress && is_tty();
    let mut batch: Vec<(usize, AnySample)> = Vec::with_capacity(1024);
    let mut order: Vec<(i64, usize)> = Vec::with_capacity(1024);
    // One wake-up for every service: each navsync publisher notifies it after publishing.
    let wake = node.wake()?;
    let mut running = true;
    while running {
        loop {
            let now = monotonic_now_ns();
            let next_due = [last_flush + ns(CHUNK_INTERVAL), last_discovery + ns(DISCOVERY_INTERVAL)]
                .into_iter()
                .chain(end)
                .min()
                .unwrap_or(now);
            let timeout = Duration::from_nanos((next_due - now).clamp(1_000_000, 200_000_000) as u64);
            let alive = node.wait(&wake, timeout)?;
            let rx_mono = monotonic_now_ns();
            let rx_real = realtime_now_ns();
            batch.clear();
            for (i, s) in subs.iter().enumerate() {
                s.drain(|x| batch.push((i, x)))?;
            }
            // Stamp order, ties in drain order; an index sort (no allocation, no large moves).
            order.clear();
            order.extend(batch.iter().enumerate().map(|(k, (_, x))| (x.host_ns(), k)));
            order.sort_unstable();
            for &(_, k) in &order {
                let (i, x) = &batch[k];
                rec.write(subs[*i].service(), x, rx_real.max(0) as u64, rx_mono.max(0) as u64)?;
                counts[*i] += 1;
                health.tick(r_msgs);
            }
            health.add(c_msgs, batch.len() as u64);
            let now = monotonic_now_ns();
            if now - last_flush >= ns(CHUNK_INTERVAL) {
                rec.flush_chunk()?;
                last_flush = now;
            }
            health.set(c_bytes, rec.bytes_written());
            health.set(c_services, subs.len() as u64);
            health.maybe_publish(now)?;
            navsync_shared::sd_notify::watchdog();
            if args.progress && now - last_progress >= if tty { NS_PER_S / 5 } else { 5 * NS_PER_S } {
                progress(tty, now - t0, rec.bytes_written(), &subs, &counts);
                last_progress = now;
            }
            if !alive || end.is_some_and(|e| now >= e) {
                running = false;
                break;
            }
            if now - last_discovery >= ns(DISCOVERY_INTERVAL) {
                last_discovery = now;
                let found = new_services(&patterns, &subs, &refused)?;
                if !found.is_empty() {
                    let before = subs.len();
                    subscribe_all(&node, &mut subs, &mut refused, found);
                    for s in &subs[before..] {
                        rec.channel(s.service())?;
                    }
                    counts.resize(subs.len(), 0);
                    break; // restart the wait loop with the new subscribers
                }
            }
        }
    }
    navsync_shared::sd_notify::stopping();
    let _ = health.publish_final();
    let bytes = rec.bytes_written();
    let stats = RecordStats {
        per_service: subs
            .iter()
            .zip(&counts)
            .map(|(s, &n)| (s.service().to_string(), n))
            .collect(),
        bytes,
    };
    rec.close()?;
    if args.progress {
        let size = std::fs::metadata(&args.out).map(|m| m.len()).unwrap_or(bytes);
        progress(tty, monotonic_now_ns() - t0, size, &subs, &counts);
        eprintln!();
    }
    info!(file = %args.out.display(), "recording closed");
    Ok(stats)
}

/// `path` with every `{start}` replaced by the UTC time `utc_ns` as `YYYYMMDDTHHMMSSZ` (a
/// service restarted after a crash then writes a new file instead of meeting its last one).
pub fn with_start_time(path: &std::path::Path, utc_ns: i64) -> PathBuf {
    let text = path.to_string_lossy();
    if !text.contains("{start}") {
        return path.to_path_buf();
    }
    let stamp: String = navsync_shared::time::format_rfc3339_ms(utc_ns)
        .chars()
        .take(19)
        .filter(|c| !matches!(c, '-' | ':'))
        .chain(['Z'])
        .collect();
    PathBuf::from(text.replace("{start}", &stamp))
}

fn ns(d: Duration) -> i64 {
    d.as_nanos() as i64
}

fn subscribe(node: &IpcNode, subs: &mut Vec<AnySubscriber>, service: &str) -> Result<(), IpcError> {
    if subs.iter().any(|s| s.service() == service) {
        return Ok(());
    }
    subs.push(AnySubscriber::open(node, service)?);
    Ok(())
}

/// Existing services that match a wildcard pattern and are not subscribed yet (nor refused).
fn new_services(
    patterns: &[ServiceGlob],
    subs: &[AnySubscriber],
    refused: &HashSet<String>,
) -> Result<Vec<String>, IpcError> {
    let wild: Vec<ServiceGlob> = patterns.iter().filter(|p| !p.is_literal()).cloned().collect();
    if wild.is_empty() {
        return Ok(Vec::new());
    }
    Ok(ipc::list_services()?
        .into_iter()
        .filter(|name| {
            ServiceKind::of(name).is_some()
                && any_matches(&wild, name)
                && !refused.contains(name)
                && !subs.iter().any(|s| s.service() == name)
        })
        .collect())
}

/// Subscribes to `names`; a service that refuses (another layout version, or at its subscriber
/// limit) is logged once and not tried again.
fn subscribe_all(node: &IpcNode, subs: &mut Vec<AnySubscriber>, refused: &mut HashSet<String>, names: Vec<String>) {
    for name in names {
        if let Err(e) = subscribe(node, subs, &name) {
            warn!("not recording {name}: {e}");
            refused.insert(name);
        }
    }
}

fn is_tty() -> bool {
    std::io::IsTerminal::is_terminal(&std::io::stderr())
}

fn progress(tty: bool, elapsed_ns: i64, bytes: u64, subs: &[AnySubscriber], counts: &[u64]) {
    let total: u64 = counts.iter().sum();
    let mut line = format!(
        "recording {:.1} s, {:.2} MB, {total} messages",
        elapsed_ns as f64 * 1e-9,
        bytes as f64 / 1e6
    );
    for (s, n) in subs.iter().zip(counts) {
        let short = s.service().strip_prefix("navsync/").unwrap_or(s.service());
        line.push_str(&format!(" | {short} {n}"));
    }
    let mut err = std::io::stderr().lock();
    if tty {
        let _ = write!(err, "\r\x1b[2K{line}");
    } else {
        let _ = writeln!(err, "{line}");
    }
    let _ = err.flush();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn start_in_the_path_becomes_the_utc_start_time() {
        let t = 1_796_403_925_562_000_000; // 2026-12-04T17:05:25.562Z
        let p = with_start_time(std::path::Path::new("/var/lib/navsync/navsync-{start}.mcap"), t);
        assert_eq!(p, PathBuf::from("/var/lib/navsync/navsync-20261204T170525Z.mcap"));
        let plain = std::path::Path::new("/tmp/x.mcap");
        assert_eq!(with_start_time(plain, t), plain);
    }
}
