//! `navsync feed`: plays a capture into a pseudo-terminal as the device would send it
//! (`navsync_drivers::feed`), a receiver stand-in for tests and benchmarks.

use std::path::PathBuf;

use anyhow::{Context, Result};
use navsync_drivers::feed::{FeedArgs, Speed};

/// `navsync feed`: a capture (NMEA log or raw bytes) into a pseudo-terminal.
#[derive(clap::Args, Debug)]
pub struct Options {
    /// Capture file: a gpsd-style log (`#` comments skipped) or raw bytes.
    pub capture: PathBuf,
    /// Create a pseudo-terminal (the only output there is; required).
    #[arg(long, required = true)]
    pub pty: bool,
    /// Symlink to create to the pseudo-terminal.
    #[arg(long)]
    pub link: Option<PathBuf>,
    /// `realtime`, a factor such as 10, or `max`.
    #[arg(long, default_value = "realtime")]
    pub speed: Speed,
    /// Start over at the end, until stopped.
    #[arg(long = "loop")]
    pub looped: bool,
    /// Line rate of the emulated device: paces raw captures; a reader at another rate gets garbage.
    #[arg(long, value_parser = standard_baud)]
    pub baud: Option<u32>,
    /// Wait until a reader has opened the port (and flushed it) before sending.
    #[arg(long)]
    pub wait_reader: bool,
    /// Seconds to keep the port open after the end.
    #[arg(long, default_value_t = 1.0)]
    pub hold: f64,
}

/// A standard line rate (termios's, as a serial device takes: 9600, 115200, …).
fn standard_baud(s: &str) -> Result<u32, String> {
    match s.parse::<navsync_drivers::gnss::driver::Baud>()? {
        navsync_drivers::gnss::driver::Baud::Fixed(b) => Ok(b),
        navsync_drivers::gnss::driver::Baud::Auto => {
            Err("`auto`: expected a standard baud rate (9600, 115200, …)".into())
        }
    }
}

/// Plays the capture; prints what was sent.
pub fn run(opts: Options) -> Result<()> {
    let stats = navsync_drivers::feed::run(&FeedArgs {
        capture: opts.capture.clone(),
        link: opts.link,
        speed: opts.speed,
        looped: opts.looped,
        baud: opts.baud,
        wait_reader: opts.wait_reader,
        hold_s: opts.hold,
    })
    .with_context(|| format!("feeding {}", opts.capture.display()))?;
    eprintln!(
        "navsync feed: {} bytes in {} chunks, {} lap(s), {} chunk(s) garbled by a wrong reader rate",
        stats.bytes, stats.chunks, stats.laps, stats.garbled_chunks
    );
    Ok(())
}
