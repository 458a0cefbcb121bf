//! `navsync decode FILE|-` (alias `nmea`): decodes a receiver capture offline with the live
//! driver's [`Decoder`](navsync_drivers::gnss::Decoder): one JSON object per epoch on stdout,
//! the decoder's counters on stderr; with `--subframes`, one JSON object per GPS LNAV
//! subframe of its RXM-SFRBX instead (`navsync_estimator::gnss::lnav`, unscaled fields).

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
    /// Print the GPS LNAV subframes of the capture's UBX-RXM-SFRBX (ephemerides, almanac,
    /// ionosphere/UTC; IS-GPS-200 unscaled fields) instead of the epochs.
    #[arg(long)]
    pub subframes: bool,
}

/// `--subframes`: every GPS subframe, decoded or with the reason it was not.
fn subframes(bytes: &[u8], file: &str) -> Result<()> {
    use navsync_drivers::gnss::capture::gpsd_header;
    use navsync_drivers::gnss::{Decoder, GnssDecoder, GnssExtra};
    use navsync_estimator::gnss::lnav;
    let (header, _) = gpsd_header(bytes);
    let mut d = Decoder::new(Protocol::Ubx);
    let mut out = std::io::stdout().lock();
    let (mut ok, mut bad, mut write_err) = (0u64, 0u64, None);
    d.push_extras(bytes.get(header..).unwrap_or(&[]), 0, 0, &mut |_| {}, &mut |x| {
        let GnssExtra::NavData(n) = x else { return };
        if n.gnss_id != 0 {
            return;
        }
        let len = usize::from(n.num_words).min(n.words.len());
        let line = match lnav::decode(&n.words[..len]) {
            Ok(s) => {
                ok += 1;
                serde_json::json!({ "sv": n.sv_id, "decoded": s })
            }
            Err(e) => {
                bad += 1;
                serde_json::json!({ "sv": n.sv_id, "error": e.to_string() })
            }
        };
        if let Err(e) = writeln!(out, "{line}") {
            write_err = Some(e);
        }
    });
    if let Some(e) = write_err {
        return Err(e).context("writing stdout");
    }
    eprintln!("{ok} GPS subframes decoded, {bad} rejected");
    anyhow::ensure!(
        ok > 0 || bytes.is_empty(),
        "{file}: no GPS LNAV subframe (UBX-RXM-SFRBX) decoded"
    );
    Ok(())
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
    if opts.subframes {
        return subframes(&bytes, &opts.file);
    }
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
