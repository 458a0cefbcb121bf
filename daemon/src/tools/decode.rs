//! `navsync decode FILE|-` (alias `nmea`): decodes a receiver capture offline with the live
//! driver's [`Decoder`](navsync_drivers::gnss::Decoder): one JSON object per epoch on stdout,
//! the decoder's counters on stderr.

use std::io::{Read, Write};

use anyhow::{Context, Result};
use navsync_drivers::gnss::Protocol;
use navsync_drivers::gnss::capture::{decode_capture, epoch_json};

/// `navsync decode`: a capture file (gpsd log: `#` comments skipped) or `-` for stdin.
#[derive(clap::Args, Debug)]
pub struct Options {
    /// Capture file, or `-` for stdin.
    pub file: String,
    /// The receiver's protocol: nmea, ubx (u-blox binary, NMEA on the same port skipped) or auto (UBX when the capture has UBX navigation, else NMEA).
    #[arg(long, default_value = "nmea")]
    pub protocol: Protocol,
}

/// Decodes and prints.
pub fn run(opts: Options) -> Result<()> {
    let bytes = if opts.file == "-" {
        let mut b = Vec::new();
        std::io::stdin().read_to_end(&mut b).context("reading stdin")?;
        b
    } else {
        std::fs::read(&opts.file).with_context(|| format!("reading {}", opts.file))?
    };
    let cap = decode_capture(&bytes, opts.protocol);
    let mut out = std::io::stdout().lock();
    for f in &cap.fixes {
        writeln!(out, "{}", epoch_json(f))?;
    }
    let counters: Vec<String> = cap
        .counters()
        .iter()
        .filter(|(_, v)| *v > 0)
        .map(|(n, v)| format!("{n} {v}"))
        .collect();
    eprintln!("{} epochs; {}", cap.fixes.len(), counters.join(", "));
    anyhow::ensure!(
        !cap.fixes.is_empty() || bytes.is_empty(),
        "{}: no epoch decoded from {} bytes as {} (wrong protocol, or not receiver output?)",
        opts.file,
        bytes.len(),
        opts.protocol
    );
    Ok(())
}
