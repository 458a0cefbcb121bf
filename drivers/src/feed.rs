//! `navsync feed CAPTURE --pty [--link PATH] [--speed realtime|N|max] [--loop] [--baud N]
//! [--wait-reader] [--hold S]`: plays a recorded capture into a pseudo-terminal, as the
//! device that produced it would, so that a driver (`navsync gps`, `navsync imu
//! --source xsens:…`) reads it through its real serial code.
//!
//! - The capture is cut into timed chunks by [`capture`]: an NMEA log epoch by epoch (paced
//!   by the sentences' time tags), anything else (UBX, Xbus) by the line rate, a gpsd
//!   capture's leading `#` comment lines skipped.
//! - `--speed realtime` (default) keeps the capture's timing, `--speed N` plays N times
//!   faster, `--speed max` writes as fast as the reader takes the bytes (nothing is dropped:
//!   the feeder waits while the line discipline's buffer is full).
//! - `--baud N` is the rate of the emulated device: raw captures are paced by it, and when
//!   the reader opens the port at another rate, it receives what a UART at that rate would
//!   make of the bytes ([`uart`]), so wrong-rate handling and baud hunting can be tested on a
//!   pseudo-terminal.
//! - `--wait-reader` holds the capture back until a reader has opened the port and flushed
//!   its input: the feeder writes a `\r\n` probe (ignored between NMEA sentences, counted as
//!   noise by binary framers) and starts when the line's input queue has been emptied.
//!   Without it, the first bytes may be discarded by a driver that flushes stale input when
//!   it opens the port.
//! - `--loop` starts over at the end (until SIGINT/SIGTERM); otherwise the feeder waits until
//!   the reader has taken everything, holds the port open `--hold` seconds more (default 1),
//!   and exits, which removes the pseudo-terminal and its link like an unplugged device.

pub mod capture;
pub mod uart;

use std::fs::File;
use std::io::Write;
use std::os::fd::AsRawFd;
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use navsync_shared::time::{NS_PER_S, monotonic_now_ns};
use tracing::info;

use self::capture::{CaptureKind, Chunk};
use crate::pty::Pty;

/// Line rate for pacing raw captures when `--baud` is not given.
pub const DEFAULT_RAW_BAUD: u32 = 115_200;

pub use navsync_shared::pacing::Speed;

/// Settings of `navsync feed`.
#[derive(Debug, Clone)]
pub struct FeedArgs {
    /// The capture file.
    pub capture: PathBuf,
    /// Symlink to create to the pseudo-terminal.
    pub link: Option<PathBuf>,
    /// Playback speed.
    pub speed: Speed,
    /// Start over at the end.
    pub looped: bool,
    /// Line rate of the emulated device.
    pub baud: Option<u32>,
    /// Wait for a reader before sending.
    pub wait_reader: bool,
    /// Seconds to keep the port open after the end.
    pub hold_s: f64,
}

/// Errors of the feeder.
#[derive(Debug, thiserror::Error)]
pub enum FeedError {
    /// The capture could not be read.
    #[error("reading {}: {source}", path.display())]
    Read {
        /// The capture.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// The capture holds nothing to send.
    #[error("{}: nothing to send (only comments?)", .0.display())]
    Empty(PathBuf),
    /// The pseudo-terminal could not be created or written.
    #[error("pseudo-terminal: {0}")]
    Pty(std::io::Error),
}

/// What was sent.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FeedStats {
    /// Bytes written.
    pub bytes: u64,
    /// Chunks written.
    pub chunks: u64,
    /// Times the capture was played.
    pub laps: u64,
    /// Chunks delivered garbled because the reader used another rate.
    pub garbled_chunks: u64,
}

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    STOP.store(true, Ordering::Relaxed);
}

fn stopping() -> bool {
    STOP.load(Ordering::Relaxed)
}

/// Sleeps until host time `target_ns` in slices of at most 20 ms; false if asked to stop.
fn sleep_until(target_ns: i64) -> bool {
    loop {
        if stopping() {
            return false;
        }
        let left = target_ns - monotonic_now_ns();
        if left <= 0 {
            return true;
        }
        std::thread::sleep(Duration::from_nanos(left.min(20_000_000) as u64));
    }
}

/// The reader's side of the line: its termios (rate) and input queue.
struct Line {
    slave: File,
}

impl Line {
    fn open(path: &Path) -> std::io::Result<Self> {
        let slave = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .custom_flags(libc::O_NOCTTY | libc::O_NONBLOCK | libc::O_CLOEXEC)
            .open(path)?;
        Ok(Self { slave })
    }

    /// The rate the reader set, 0 if not known.
    fn reader_baud(&self) -> u32 {
        // SAFETY: TCGETS2 fills a termios2 we own.
        unsafe {
            let mut t: libc::termios2 = std::mem::zeroed();
            if libc::ioctl(self.slave.as_raw_fd(), libc::TCGETS2, &mut t) == 0 {
                t.c_ospeed
            } else {
                0
            }
        }
    }

    /// Bytes waiting in the reader's input queue.
    fn queued(&self) -> i64 {
        let mut n: libc::c_int = 0;
        // SAFETY: FIONREAD writes one int.
        let rc = unsafe { libc::ioctl(self.slave.as_raw_fd(), libc::FIONREAD, &mut n) };
        if rc == 0 { i64::from(n) } else { 0 }
    }
}

/// Writes all of `bytes`, waiting while the line is full; false if asked to stop.
fn write_all(pty: &mut Pty, bytes: &[u8]) -> Result<bool, FeedError> {
    let mut done = 0;
    while done < bytes.len() {
        done += pty.write(&bytes[done..]).map_err(FeedError::Pty)?;
        if done < bytes.len() {
            if stopping() {
                return Ok(false);
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    Ok(true)
}

/// Plays the capture; returns what was sent (also on SIGINT/SIGTERM).
pub fn run(args: &FeedArgs) -> Result<FeedStats, FeedError> {
    // SAFETY: installing an async-signal-safe handler that only stores an atomic.
    unsafe {
        libc::signal(libc::SIGINT, on_signal as *const () as libc::sighandler_t);
        libc::signal(libc::SIGTERM, on_signal as *const () as libc::sighandler_t);
    }
    let bytes = std::fs::read(&args.capture).map_err(|source| FeedError::Read {
        path: args.capture.clone(),
        source,
    })?;
    let kind = capture::detect(&bytes);
    let line_baud = args.baud.unwrap_or(DEFAULT_RAW_BAUD);
    let chunks: Vec<Chunk> = match kind {
        CaptureKind::Nmea => capture::nmea_chunks(&bytes),
        // A binary capture from gpsd's regression suite starts with `#` comment lines.
        CaptureKind::Raw => {
            let (header, _) = crate::gnss::capture::gpsd_header(&bytes);
            capture::raw_chunks(bytes.get(header..).unwrap_or(&[]), line_baud)
        }
    };
    if chunks.is_empty() {
        return Err(FeedError::Empty(args.capture.clone()));
    }
    // One more epoch between laps of an NMEA log.
    let lap_s = capture::duration_s(&chunks, line_baud) + if kind == CaptureKind::Nmea { 1.0 } else { 0.0 };

    let mut pty = Pty::open(args.link.as_deref()).map_err(FeedError::Pty)?;
    let line = Line::open(pty.path()).map_err(FeedError::Pty)?;
    {
        let mut out = std::io::stdout().lock();
        let _ = writeln!(
            out,
            "navsync feed: {} on {}{}",
            args.capture.display(),
            pty.path().display(),
            pty.link()
                .map(|l| format!(" (link {})", l.display()))
                .unwrap_or_default()
        );
        let _ = out.flush();
    }
    info!(kind = ?kind, chunks = chunks.len(), lap_s, "feeding");
    navsync_shared::sd_notify::ready(&format!("feeding {}", pty.path().display()));

    let mut stats = FeedStats::default();
    if args.wait_reader {
        write_all(&mut pty, b"\r\n")?;
        // The probe reaches the reader's queue asynchronously (the tty flip buffer): see it
        // arrive first, unless a reader that was already reading takes it at once.
        let arrive_by = monotonic_now_ns() + NS_PER_S / 2;
        while line.queued() == 0 && monotonic_now_ns() < arrive_by {
            std::thread::sleep(Duration::from_millis(1));
        }
        while line.queued() > 0 {
            if stopping() {
                return Ok(stats);
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        info!("a reader took the probe; starting");
    }

    let start = monotonic_now_ns();
    let mut scratch = Vec::new();
    'laps: loop {
        for c in &chunks {
            if let Speed::Factor(f) = args.speed {
                let due = (stats.laps as f64 * lap_s + c.due_s) / f;
                if !sleep_until(start + (due * NS_PER_S as f64) as i64) {
                    break 'laps;
                }
            } else if stopping() {
                break 'laps;
            }
            let out: &[u8] = match args.baud {
                Some(tx) => {
                    scratch.clear();
                    let rx = line.reader_baud();
                    uart::receive(&c.bytes, tx, if rx == 0 { tx } else { rx }, &mut scratch);
                    if scratch != c.bytes {
                        stats.garbled_chunks += 1;
                    }
                    &scratch
                }
                None => &c.bytes,
            };
            if !write_all(&mut pty, out)? {
                break 'laps;
            }
            stats.bytes += out.len() as u64;
            stats.chunks += 1;
        }
        stats.laps += 1;
        if !args.looped {
            break;
        }
    }
    // Let the reader take what is queued, then keep the port a little longer.
    let drain_until = monotonic_now_ns() + 5 * NS_PER_S;
    while line.queued() > 0 && monotonic_now_ns() < drain_until && !stopping() {
        std::thread::sleep(Duration::from_millis(5));
    }
    sleep_until(monotonic_now_ns() + (args.hold_s.max(0.0) * 1e9) as i64);
    info!(?stats, "feed done");
    drop(pty);
    Ok(stats)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn speeds() {
        assert_eq!("realtime".parse::<Speed>(), Ok(Speed::Factor(1.0)));
        assert_eq!("max".parse::<Speed>(), Ok(Speed::Max));
        assert_eq!("12.5".parse::<Speed>(), Ok(Speed::Factor(12.5)));
        for bad in ["0", "-2", "fast", "inf"] {
            assert!(
                bad.parse::<Speed>()
                    .unwrap_err()
                    .contains("expected `realtime` (= 1), `max`"),
                "{bad}"
            );
        }
    }
}
