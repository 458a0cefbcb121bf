//! `navsync decode FILE|-` (alias `nmea`): decodes a receiver capture offline with the live
//! driver's [`Decoder`](navsync_drivers::gnss::Decoder): one JSON object per epoch on stdout,
//! the decoder's counters on stderr; with `--subframes`, one JSON object per GPS LNAV
//! subframe of its RXM-SFRBX instead (`navsync_estimator::gnss::lnav`, unscaled fields); with
//! `--yuma`, the GPS almanac of those subframes as a YUMA file (what `[gnss.sky] almanac` of a
//! simulator scenario reads).

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
    #[arg(long, conflicts_with = "yuma")]
    pub subframes: bool,
    /// Print the GPS almanac of the capture's subframes (subframes 4 and 5; the latest page of
    /// each PRN) in the YUMA format, its week modulo 1024 from the capture's subframe 1.
    #[arg(long)]
    pub yuma: bool,
}

/// The GPS LNAV subframes of a capture's RXM-SFRBX, decoded, with the number rejected.
fn gps_subframes(
    bytes: &[u8],
) -> Vec<(
    u8,
    Result<navsync_estimator::gnss::lnav::Decoded, navsync_estimator::gnss::lnav::LnavError>,
)> {
    use navsync_drivers::gnss::capture::gpsd_header;
    use navsync_drivers::gnss::{Decoder, GnssDecoder, GnssExtra};
    use navsync_estimator::gnss::lnav;
    let (header, _) = gpsd_header(bytes);
    let mut d = Decoder::new(Protocol::Ubx);
    let mut out = Vec::new();
    d.push_extras(bytes.get(header..).unwrap_or(&[]), 0, 0, &mut |_| {}, &mut |x| {
        let GnssExtra::NavData(n) = x else { return };
        if n.gnss_id == 0 {
            let len = usize::from(n.num_words).min(n.words.len());
            out.push((n.sv_id, lnav::decode(&n.words[..len])));
        }
    });
    out
}

/// `--yuma`: the capture's almanac as a YUMA file (IS-GPS-200 Table 20-VI scale factors through
/// [`Orbit::from_almanac`](navsync_estimator::gnss::orbit::Orbit::from_almanac)). √A is
/// printed with 11 decimals (NAVCEN prints 6): exact for its 2⁻¹¹ √m scale, where 6 decimals
/// would shift the mean motion by up to 3·10⁻¹⁰ — 220 m of along-track position after six
/// years of propagation.
fn yuma(bytes: &[u8], file: &str) -> Result<()> {
    use navsync_estimator::gnss::lnav::Subframe;
    use navsync_estimator::gnss::orbit::Orbit;
    let subframes = gps_subframes(bytes);
    // The almanac's week: the week of the capture (subframe 1) moved to the half week around
    // t_oa (an almanac's t_oa lies within ±3.5 days of its transmission).
    let now = subframes.iter().find_map(|(_, d)| match d {
        Ok(d) => match d.subframe {
            Subframe::Ephem1(e) => Some((i64::from(e.wn), f64::from(d.tow_count) * 6.0)),
            _ => None,
        },
        Err(_) => None,
    });
    let (week, tow) = now.with_context(|| format!("{file}: no GPS subframe 1, so no week for the almanac"))?;
    let mut pages = std::collections::BTreeMap::new();
    for (_, d) in &subframes {
        if let Ok(navsync_estimator::gnss::lnav::Decoded {
            subframe: Subframe::Almanac(a),
            ..
        }) = d
            && a.sqrt_a > 0
        {
            pages.insert(a.sv, *a);
        }
    }
    anyhow::ensure!(!pages.is_empty(), "{file}: no GPS almanac page (subframes 4 and 5)");
    let mut out = std::io::stdout().lock();
    for (sv, a) in &pages {
        let o = Orbit::from_almanac(a);
        let shift = ((o.toe_s - tow) / 604_800.0).round() as i64;
        let w = (week + shift).rem_euclid(1024);
        writeln!(
            out,
            "******** Week {w} almanac for PRN-{sv:02} ********\n\
             ID:                         {sv:02}\n\
             Health:                     {:03}\n\
             Eccentricity:               {:.10E}\n\
             Time of Applicability(s):  {:.4}\n\
             Orbital Inclination(rad):   {:.10}\n\
             Rate of Right Ascen(r/s):  {:.10E}\n\
             SQRT(A)  (m 1/2):           {:.11}\n\
             Right Ascen at Week(rad):  {:.10E}\n\
             Argument of Perigee(rad):   {:.9}\n\
             Mean Anom(rad):            {:.10E}\n\
             Af0(s):                     {:.10E}\n\
             Af1(s/s):                  {:.10E}\n\
             week:                       {w}\n",
            a.health,
            o.e,
            o.toe_s,
            o.i0_rad,
            o.omega_dot_rad_s,
            o.sqrt_a,
            o.omega0_rad,
            o.omega_rad,
            o.m0_rad,
            o.af[0],
            o.af[1],
        )
        .context("writing stdout")?;
    }
    eprintln!("{} GPS almanac pages, week {} mod 1024", pages.len(), week);
    Ok(())
}

/// `--subframes`: every GPS subframe, decoded or with the reason it was not.
fn subframes(bytes: &[u8], file: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    let (mut ok, mut bad) = (0u64, 0u64);
    for (sv, d) in gps_subframes(bytes) {
        let line = match d {
            Ok(s) => {
                ok += 1;
                serde_json::json!({ "sv": sv, "decoded": s })
            }
            Err(e) => {
                bad += 1;
                serde_json::json!({ "sv": sv, "error": e.to_string() })
            }
        };
        writeln!(out, "{line}").context("writing stdout")?;
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
    if opts.yuma {
        return yuma(&bytes, &opts.file);
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
