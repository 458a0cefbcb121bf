//! `navsync decode FILE|-` (alias `nmea`): decodes a receiver capture offline with the live
//! driver's [`Decoder`](navsync_drivers::gnss::Decoder): one JSON object per epoch on stdout,
//! the decoder's counters on stderr; with `--subframes`, one JSON object per GPS LNAV
//! subframe of its RXM-SFRBX instead (`navsync_estimator::gnss::lnav`, unscaled fields), then
//! one per Galileo I/NAV and BeiDou D1/D2 ephemeris (`navsync_estimator::gnss::broadcast`); with
//! `--yuma`, the GPS almanac of those subframes as a YUMA file (what `[gnss.sky] almanac` of a
//! simulator scenario reads); with `--sky`, each GPS and GLONASS satellite of the receiver's NAV-SAT with
//! the elevation and azimuth computed from broadcast orbits next to the receiver's own.

use std::io::{Read, Write};

use anyhow::{Context, Result};
use navsync_drivers::gnss::Protocol;
use navsync_drivers::gnss::capture::{Seen, decode_capture, epoch_json};
use navsync_estimator::gnss::broadcast::carries_lnav;

/// `navsync decode`: a capture file (gpsd log: `#` comments skipped) or `-` for stdin.
#[derive(clap::Args, Debug)]
pub struct Options {
    /// Capture file, or `-` for stdin.
    pub file: String,
    /// The receiver's protocol: auto (UBX navigation when the capture has it, else its NMEA:
    /// the bytes say which), nmea, or ubx (u-blox binary, NMEA on the same port skipped).
    #[arg(long, default_value = "auto")]
    pub protocol: Protocol,
    /// Print the GPS LNAV subframes of the capture's UBX-RXM-SFRBX (ephemerides, almanac,
    /// ionosphere/UTC; IS-GPS-200 unscaled fields), then each Galileo I/NAV and F/NAV, BeiDou
    /// D1/D2 and GPS CNAV (L2C, L5) ephemeris completed from its words (SI units, the system named),
    /// instead of the epochs.
    #[arg(long, conflicts_with = "yuma")]
    pub subframes: bool,
    /// Print the GPS almanac of the capture's subframes (subframes 4 and 5; the latest page of
    /// each PRN) in the YUMA format, its week modulo 1024 from the capture's subframe 1.
    #[arg(long, conflicts_with = "sky")]
    pub yuma: bool,
    /// Print, for every GPS and GLONASS satellite in the capture's UBX-NAV-SAT, its elevation
    /// and azimuth computed from an orbit (GPS: the capture's own ephemeris, else its almanac
    /// page, else `--almanac`; GLONASS: the capture's immediate data, strings 1–4, integrated)
    /// at the receiver's NAV-PVT position, next to the receiver's own: one JSON object per
    /// satellite and epoch; the largest differences on stderr.
    #[arg(long)]
    pub sky: bool,
    /// With `--sky`: a YUMA almanac for the satellites the capture has no orbit of.
    #[arg(long, requires = "sky")]
    pub almanac: Option<String>,
}

/// `--sky`: computed against reported satellite geometry (IS-GPS-200 Table 20-IV orbits, the
/// GLONASS ICD's integrated orbits; elevation/azimuth at the receiver's position for a signal
/// sent 75 ms before the epoch).
fn sky(bytes: &[u8], file: &str, almanac: Option<&str>) -> Result<()> {
    use navsync_drivers::gnss::capture::gpsd_header;
    use navsync_drivers::gnss::ubx::framer::{Frame, UbxFramer};
    use navsync_drivers::gnss::ubx::messages::{self, Message};
    use navsync_estimator::gnss::glonass::{self, GloStore};
    use navsync_estimator::gnss::lnav::{self, Subframe};
    use navsync_estimator::gnss::orbit::Orbit;
    use navsync_estimator::gnss::ranges::EphemerisStore;
    use navsync_estimator::gnss::spp;
    use navsync_shared::time::gps_ns_from_utc_ns;
    const WEEK_S: i64 = 604_800;
    let (header, _) = gpsd_header(bytes);
    let mut store = EphemerisStore::default();
    let mut glo = GloStore::default();
    let mut pages = std::collections::BTreeMap::new();
    // (NAV-SAT, the latest NAV-PVT with a fix before it: position and GPS week)
    let mut epochs = Vec::new();
    let mut pvt: Option<([f64; 3], i64)> = None;
    UbxFramer::new().push(bytes.get(header..).unwrap_or(&[]), 0, 0, &mut |f| {
        let Frame::Ubx { class, id, payload, .. } = f else {
            return;
        };
        match messages::decode(class, id, payload) {
            Ok(Message::NavPvt(p)) if p.fix_type >= 2 => {
                let week = gps_ns_from_utc_ns(p.utc_second_ns()).div_euclid(WEEK_S * 1_000_000_000);
                let rx =
                    navsync_shared::earth::geodetic_to_ecef(p.lat_deg.to_radians(), p.lon_deg.to_radians(), p.height_m);
                pvt = Some((rx, week));
            }
            Ok(Message::NavSat(s)) => {
                if let Some(p) = pvt {
                    epochs.push((s, p));
                }
            }
            Ok(Message::RxmSfrbx(x)) if x.gnss_id == 6 => glo.on_words(x.sv_id, x.data_words()),
            Ok(Message::RxmSfrbx(x)) if carries_lnav(x.gnss_id, x.sig_id) => {
                if let Ok(d) = lnav::decode(x.data_words()) {
                    match d.subframe {
                        Subframe::Almanac(a) if a.sqrt_a > 0 => {
                            pages.insert(a.sv, Orbit::from_almanac(&a));
                        }
                        other => store.on_subframe(x.sv_id, &other),
                    }
                }
            }
            _ => {}
        }
    });
    anyhow::ensure!(!epochs.is_empty(), "{file}: no UBX-NAV-SAT after a NAV-PVT with a fix");
    // A YUMA almanac: orbits with their full week (a week modulo 1024 resolved near the capture).
    let yuma: std::collections::BTreeMap<u8, (Orbit, i64)> = match almanac {
        None => Default::default(),
        Some(path) => {
            let capture_week = epochs[0].1.1;
            navsync_sim::gps::read_yuma(std::path::Path::new(path))
                .map_err(anyhow::Error::msg)?
                .iter()
                .map(|a| {
                    let w = i64::from(a.week);
                    let week = if w >= 1024 {
                        w
                    } else {
                        w + ((capture_week - w) as f64 / 1024.0).round() as i64 * 1024
                    };
                    let orbit = Orbit {
                        toe_s: a.toa_s,
                        sqrt_a: a.sqrt_a,
                        e: a.e,
                        i0_rad: a.i_rad,
                        omega0_rad: a.omega0_rad,
                        omega_dot_rad_s: a.omega_dot_rad_s,
                        omega_rad: a.omega_rad,
                        m0_rad: a.m0_rad,
                        toc_s: a.toa_s,
                        af: [a.af0_s, a.af1, 0.0],
                        ..Orbit::default()
                    };
                    (a.prn, (orbit, week))
                })
                .collect()
        }
    };
    let mut out = std::io::stdout().lock();
    // Per source: (satellites compared, largest |Δel|, largest |Δaz|·cos el), degrees.
    let mut worst: std::collections::BTreeMap<&str, (u64, f64, f64)> = Default::default();
    for (nav_sat, (rx, week)) in &epochs {
        let tow = f64::from(nav_sat.itow_ms) * 1e-3;
        let t_tx = tow - 0.075;
        let utc_tx_ns = navsync_shared::time::utc_ns_from_gps_ns(
            week * WEEK_S * 1_000_000_000 + i64::from(nav_sat.itow_ms) * 1_000_000 - 75_000_000,
        );
        for sat in nav_sat.satellites().iter().filter(|x| x.gnss_id == 0 || x.gnss_id == 6) {
            let pos = if sat.gnss_id == 6 {
                // GLONASS: the slot's immediate data integrated from t_b (PZ-90 taken as WGS-84).
                glo.ephemeris(sat.sv_id).map(|e| {
                    let dt = glonass::seconds_since_tb(e.tb_s, utc_tx_ns);
                    ("glonass-ephemeris", e.state_at(dt).0)
                })
            } else if let Some(o) = store.orbit(sat.sv_id, tow) {
                Some(("ephemeris", o.position_ecef_m(t_tx)))
            } else if let Some(o) = pages.get(&sat.sv_id) {
                Some(("almanac", o.position_ecef_m(t_tx)))
            } else {
                yuma.get(&sat.sv_id).map(|(o, w)| {
                    let tk = (week - w) as f64 * WEEK_S as f64 + t_tx - o.toe_s;
                    ("yuma", o.position_ecef_m_tk(tk))
                })
            };
            let Some((source, pos)) = pos else { continue };
            let (el, az) = spp::elevation_azimuth(*rx, spp::rotate_for_flight(pos, 0.075));
            let (el, az) = (el.to_degrees(), az.to_degrees().rem_euclid(360.0));
            let d_el = el - f64::from(sat.elev_deg);
            let d_az = (az - f64::from(sat.azim_deg) + 540.0).rem_euclid(360.0) - 180.0;
            let w = worst.entry(source).or_default();
            *w = (
                w.0 + 1,
                w.1.max(d_el.abs()),
                w.2.max(d_az.abs() * el.to_radians().cos()),
            );
            let line = serde_json::json!({
                "tow_s": tow, "gnss_id": sat.gnss_id, "sv": sat.sv_id, "source": source,
                "el_deg": el, "az_deg": az,
                "receiver_el_deg": sat.elev_deg, "receiver_az_deg": sat.azim_deg,
                "d_el_deg": d_el, "d_az_deg": d_az,
            });
            writeln!(out, "{line}").context("writing stdout")?;
        }
    }
    for (source, (n, el, az)) in &worst {
        eprintln!("{source}: {n} satellite sightings, largest |Δel| {el:.2}°, largest |Δaz|·cos(el) {az:.2}°");
    }
    anyhow::ensure!(
        !worst.is_empty(),
        "{file}: no GPS or GLONASS satellite of NAV-SAT has an orbit (no ephemeris or almanac page in the capture; give --almanac)"
    );
    Ok(())
}

/// The GPS LNAV subframes of a capture's RXM-SFRBX, decoded, with the number rejected.
fn gps_subframes(
    bytes: &[u8],
) -> Vec<(
    u8,
    Result<navsync_estimator::gnss::lnav::Decoded, navsync_estimator::gnss::lnav::LnavError>,
)> {
    let mut out = Vec::new();
    nav_data(bytes, &mut |n| {
        if carries_lnav(n.gnss_id, n.sig_id) {
            let len = usize::from(n.num_words).min(n.words.len());
            out.push((n.sv_id, navsync_estimator::gnss::lnav::decode(&n.words[..len])));
        }
    });
    out
}

/// Every RXM-SFRBX of a capture as the driver publishes it (`GnssNavData`).
fn nav_data(bytes: &[u8], on: &mut dyn FnMut(&navsync_shared::samples::GnssNavData)) {
    use navsync_drivers::gnss::capture::gpsd_header;
    use navsync_drivers::gnss::{Decoder, GnssDecoder, GnssExtra};
    let (header, _) = gpsd_header(bytes);
    let mut d = Decoder::new(Protocol::Ubx);
    d.push_extras(bytes.get(header..).unwrap_or(&[]), 0, 0, &mut |_| {}, &mut |x| {
        if let GnssExtra::NavData(n) = x {
            on(n);
        }
    });
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

/// `--subframes`: every GPS LNAV subframe, decoded or with the reason it was not, then each
/// Galileo I/NAV and F/NAV, BeiDou D1/D2 and GPS CNAV ephemeris completed from the capture's words (SI
/// units).
fn subframes(bytes: &[u8], file: &str) -> Result<()> {
    use navsync_estimator::gnss::broadcast::NavCollector;
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
    let mut nav = NavCollector::default();
    let mut lines = Vec::new();
    nav_data(bytes, &mut |n| {
        let len = usize::from(n.num_words).min(n.words.len());
        if let Ok(Some(e)) = nav.on_words(n.gnss_id, n.sv_id, n.sig_id, &n.words[..len]) {
            lines.push(serde_json::json!({ "ephemeris": e }));
        }
    });
    for line in &lines {
        writeln!(out, "{line}").context("writing stdout")?;
    }
    let c = nav.counts;
    eprintln!(
        "{ok} GPS LNAV subframes decoded, {bad} rejected; {} Galileo I/NAV words, {} Galileo F/NAV pages, {} BeiDou subframes and {} GPS CNAV messages decoded, {} rejected: {} Galileo/BeiDou/GPS CNAV ephemerides",
        c.galileo_words,
        c.galileo_fnav_pages,
        c.beidou_subframes,
        c.gps_cnav_messages,
        c.rejected,
        lines.len()
    );
    anyhow::ensure!(
        ok > 0 || !lines.is_empty() || bytes.is_empty(),
        "{file}: no GPS LNAV subframe nor Galileo/BeiDou/GPS CNAV ephemeris (UBX-RXM-SFRBX) decoded"
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
    if opts.sky {
        return sky(&bytes, &opts.file, opts.almanac.as_deref());
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
    let hnr = if cap.hnr.is_empty() {
        String::new()
    } else {
        format!(
            " (and {} HNR-PVT fixes, navsync/gnss/ID/hnr, not printed)",
            cap.hnr.len()
        )
    };
    eprintln!("{} epochs{hnr}; {}", cap.fixes.len(), counters.join(", "));
    anyhow::ensure!(
        !cap.fixes.is_empty() || bytes.is_empty(),
        "{}: no epoch decoded from {} bytes as {}: {}",
        opts.file,
        bytes.len(),
        opts.protocol,
        Seen::of(&bytes).explain(opts.protocol)
    );
    Ok(())
}
