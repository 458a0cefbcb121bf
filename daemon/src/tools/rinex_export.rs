//! `navsync export rinex REC.mcap --obs OUT.obs --nav OUT.nav`: a recording's raw
//! measurements as a RINEX 3.05 observation file and the GPS, GLONASS, Galileo and BeiDou
//! ephemerides of its navigation data as a RINEX 3.05 navigation file, the inverse of `navsync
//! import rinex` (the text is written by `navsync_drivers::gnss::rinex_write`, RINEX 3.05 Tables
//! A2/A3 and A5/A8/A10 and the Galileo and BDS record tables).
//!
//! The raw epochs (`GnssRaw` on `navsync/gnss/{id}/raw`, from `import rinex` or a u-blox
//! receiver's RXM-RAWX) are written at their receiver time, GPS time. The navigation data
//! (`GnssNavData` on `…/nav-data`, RXM-SFRBX) are decoded by the estimator's LNAV decoder
//! (`gnss::lnav`, parity checked); every issue of subframes 1–3 whose IODC and IODEs agree is one
//! ephemeris (the same issue repeated every 30 s is written once), scaled back to RINEX units by
//! `rinex::ephemeris_of`, and the last subframe 4 page 18 gives the header's Klobuchar α/β.
//! GLONASS strings 1–4 of one frame (`gnss::glonass`) are one ephemeris (written once per
//! t_b), its UTC date the one nearest the epochs around it, its channel the observations'.
//! Galileo I/NAV and F/NAV and BeiDou D1/D2 words go through the estimator's
//! [`NavCollector`]: each ephemeris it completes is one record ([`kepler_record_of`]); GPS
//! CNAV's are counted and left out (RINEX 3.05 has no CNAV record). The
//! header's `APPROX POSITION XYZ` is the first epoch's single-point solution (`navsync spp`'s),
//! zeros when no epoch has one.

use std::io::Write;
use std::path::PathBuf;

use navsync_drivers::gnss::rinex::{self, GloRecord, GpsEphemeris, KeplerRecord};
use navsync_drivers::gnss::rinex_write::{self, NavRecords, ObsHeader, RinexWriteError};
use navsync_estimator::gnss::broadcast::{GNSS_ID_GLONASS, NavCollector, NavEphemeris, carries_lnav};
use navsync_estimator::gnss::galileo;
use navsync_estimator::gnss::glonass::{GloEphemeris, GloStore};
use navsync_estimator::gnss::lnav::{self, Ephem1, Ephem2, Ephem3, Subframe};
use navsync_estimator::gnss::ranges::{EphemerisStore, RangeBuildCounts};
use navsync_estimator::gnss::spp::SppSettings;
use navsync_recording::output::{OutputFile, Overwrite};
use navsync_recording::{RecordingError, SampleReader};
use navsync_shared::samples::{AnySample, GnssRaw};
use navsync_shared::services;
use navsync_shared::time::{civil_from_utc_ns, realtime_now_ns};

use super::rinex::{ephemeris_of, glonass_record_of, iono_of_page};

/// `navsync export …`.
#[derive(Debug, Clone, clap::Subcommand)]
pub enum ExportCommand {
    /// A recording's raw measurements and navigation data as RINEX 3.05 observation and
    /// navigation files.
    Rinex(RinexExportArgs),
}

/// `navsync export rinex`.
#[derive(Debug, Clone, clap::Args)]
pub struct RinexExportArgs {
    /// The recording: a receiver's raw data and navigation data (`navsync import rinex`, or
    /// recorded from a u-blox receiver's RXM-RAWX and RXM-SFRBX).
    pub recording: PathBuf,
    /// The observation file to write (RINEX 3.05).
    #[arg(long)]
    pub obs: PathBuf,
    /// The navigation file to write (RINEX 3.05): GPS, GLONASS, Galileo and BeiDou records.
    #[arg(long)]
    pub nav: PathBuf,
    /// The receiver's id in the recording (`navsync/gnss/ID/raw`, `…/nav-data`).
    #[arg(long, default_value = "0", value_parser = crate::config::estimator::parse_id)]
    pub gnss_id: String,
    /// The header's MARKER NAME (default: the recording's file name without its extension).
    #[arg(long)]
    pub marker: Option<String>,
    /// Replace existing files at --obs and --nav.
    #[arg(long)]
    pub force: bool,
}

/// Errors of the RINEX export.
#[derive(Debug, thiserror::Error)]
pub enum RinexExportError {
    /// Reading the recording or writing a file.
    #[error(transparent)]
    Recording(#[from] RecordingError),
    /// The observations could not be written (no epoch …).
    #[error(transparent)]
    Write(#[from] RinexWriteError),
    /// An output exists and --force was not given.
    #[error("{0} exists: --force replaces it")]
    Exists(PathBuf),
    /// --obs and --nav name one file.
    #[error("--obs and --nav are the same file ({0})")]
    SameOutput(PathBuf),
    /// Writing a temporary output.
    #[error("writing {path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
}

/// What an export wrote.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ExportStats {
    /// Observation epochs.
    pub epochs: u64,
    /// Measurements in them.
    pub measurements: u64,
    /// Measurements without a RINEX code (not written).
    pub unmapped: u64,
    /// GPS ephemerides written.
    pub ephemerides: u64,
    /// GLONASS ephemerides written.
    pub glonass_ephemerides: u64,
    /// GLONASS ephemerides not written: no observation gives their slot's channel.
    pub glonass_without_channel: u64,
    /// Galileo ephemerides written (I/NAV and F/NAV, each issue once).
    pub galileo_ephemerides: u64,
    /// BeiDou ephemerides written (D1 and D2).
    pub beidou_ephemerides: u64,
    /// GPS CNAV ephemerides not written: RINEX 3.05 has no record for them (RINEX 4's `CNAV`).
    pub gps_cnav_left_out: u64,
    /// Navigation messages that failed the LNAV parity or preamble check.
    pub bad_subframes: u64,
    /// The header's GPS Klobuchar α/β were written (subframe 4 page 18, else CNAV message
    /// type 30, seen).
    pub iono: bool,
    /// The header's BeiDou Klobuchar α/β were written (a D1 subframe 1 with them seen).
    pub bds_iono: bool,
    /// The header's approximate position (first single-point solution), if any epoch solved.
    pub approx_ecef_m: Option<[f64; 3]>,
}

/// Subframes 1–3 of one satellite as last received, with subframe 1's HOW count.
#[derive(Default, Clone, Copy)]
struct Issue {
    s1: Option<(Ephem1, u32)>,
    s2: Option<Ephem2>,
    s3: Option<Ephem3>,
}

/// Runs `navsync export rinex` and prints what it wrote.
pub fn main(cmd: ExportCommand) -> anyhow::Result<()> {
    use anyhow::Context;
    let ExportCommand::Rinex(args) = cmd;
    let s = export(&args).with_context(|| format!("exporting {}", args.recording.display()))?;
    eprintln!(
        "{}: {} epochs, {} measurements ({} of signals without a RINEX code left out); {}: {} GPS \
         ephemerides{}, {} GLONASS, {} Galileo, {} BeiDou ephemerides ({} navigation messages failed the \
         parity check; {} GLONASS ephemerides without a channel and {} GPS CNAV ones, which RINEX 3.05 \
         has no record for, left out)",
        args.obs.display(),
        s.epochs,
        s.measurements,
        s.unmapped,
        args.nav.display(),
        s.ephemerides,
        match (s.iono, s.bds_iono) {
            (true, true) => " and GPS's and BeiDou's Klobuchar α/β",
            (true, false) => " and GPS's Klobuchar α/β",
            (false, true) => " and BeiDou's Klobuchar α/β",
            (false, false) => "",
        },
        s.glonass_ephemerides,
        s.galileo_ephemerides,
        s.beidou_ephemerides,
        s.bad_subframes,
        s.glonass_without_channel,
        s.gps_cnav_left_out
    );
    match s.approx_ecef_m {
        Some(p) => eprintln!(
            "  approximate position (first SPP solution, ECEF m): {:.4},{:.4},{:.4}",
            p[0], p[1], p[2]
        ),
        None => eprintln!("  no epoch solved: approximate position written as zeros"),
    }
    anyhow::ensure!(
        s.ephemerides + s.glonass_ephemerides + s.galileo_ephemerides + s.beidou_ephemerides > 0,
        "no GPS, GLONASS, Galileo or BeiDou ephemeris in {}",
        args.recording.display()
    );
    Ok(())
}

/// Runs `navsync export rinex`.
pub fn export(args: &RinexExportArgs) -> Result<ExportStats, RinexExportError> {
    if navsync_recording::output::same_file(&args.obs, &args.nav) || args.obs == args.nav {
        return Err(RinexExportError::SameOutput(args.obs.clone()));
    }
    for p in [&args.obs, &args.nav] {
        if !args.force && p.exists() {
            return Err(RinexExportError::Exists(p.clone()));
        }
    }
    let (raw_service, nav_service) = (
        services::gnss_raw(&args.gnss_id),
        services::gnss_nav_data(&args.gnss_id),
    );
    let mut reader = SampleReader::open(&args.recording)?;
    let mut stats = ExportStats::default();
    let mut epochs: Vec<GnssRaw> = Vec::new();
    // Ephemerides in the order their issues completed, and when (index of the next epoch).
    let mut issues = [Issue::default(); 32];
    let mut complete: Vec<(u8, u32, Ephem1, Ephem2, Ephem3)> = Vec::new();
    let mut iono = None;
    // GLONASS: each ephemeris once (t_k aside), with the number of epochs read before it.
    let mut glo = GloStore::default();
    let mut glo_done: Vec<(usize, GloEphemeris)> = Vec::new();
    // Galileo, BeiDou (and GPS CNAV) ephemerides, each once, with the epochs read before it.
    let mut others = NavCollector::default();
    let mut others_done: Vec<(usize, NavEphemeris)> = Vec::new();
    // The first single-point solution, with the ephemerides received up to its epoch.
    let mut store = EphemerisStore::default();
    let settings = SppSettings::default();
    let mut counts = RangeBuildCounts::default();
    while let Some(s) = reader.next_sample()? {
        match s.sample {
            AnySample::Raw(raw) if s.service == raw_service => {
                if stats.approx_ecef_m.is_none() {
                    stats.approx_ecef_m = super::spp::solve_epoch(&store, &raw, [0.0; 3], &settings, 3.0, &mut counts)
                        .ok()
                        .map(|sol| sol.ecef_m);
                }
                stats.measurements += u64::from(raw.num_meas);
                epochs.push(raw);
            }
            AnySample::NavData(d) if s.service == nav_service => {
                store.on_nav_data(&d);
                if d.gnss_id == GNSS_ID_GLONASS {
                    let before = glo.counters.ephemerides;
                    glo.on_words(d.sv_id, &d.words[..usize::from(d.num_words).min(d.words.len())]);
                    let same = |a: &GloEphemeris, b: &GloEphemeris| {
                        GloEphemeris { tk_s: 0.0, ..*a } == GloEphemeris { tk_s: 0.0, ..*b }
                    };
                    if glo.counters.ephemerides > before
                        && let Some(e) = glo.ephemeris(d.sv_id)
                        && !glo_done.iter().any(|(_, x)| same(x, e))
                    {
                        glo_done.push((epochs.len(), *e));
                    }
                    continue;
                }
                if !carries_lnav(d.gnss_id, d.sig_id) {
                    let n = usize::from(d.num_words).min(d.words.len());
                    if let Ok(Some(e)) = others.on_words(d.gnss_id, d.sv_id, d.sig_id, &d.words[..n])
                        && !others_done.iter().any(|(_, x)| *x == e)
                    {
                        others_done.push((epochs.len(), e));
                    }
                    continue;
                }
                if d.num_words < 10 {
                    continue;
                }
                let Ok(dec) = lnav::decode(&d.words[..10]) else {
                    stats.bad_subframes += 1;
                    continue;
                };
                let Some(issue) = usize::from(d.sv_id).checked_sub(1).and_then(|i| issues.get_mut(i)) else {
                    continue;
                };
                match dec.subframe {
                    Subframe::Ephem1(s1) => issue.s1 = Some((s1, dec.tow_count)),
                    Subframe::Ephem2(s2) => issue.s2 = Some(s2),
                    Subframe::Ephem3(s3) => issue.s3 = Some(s3),
                    Subframe::IonoUtc(page) => iono = Some(iono_of_page(&page)),
                    _ => continue,
                }
                if let (Some((s1, how)), Some(s2), Some(s3)) = (issue.s1, issue.s2, issue.s3) {
                    let same_issue = (s1.iodc & 0xFF) as u8 == s2.iode && s2.iode == s3.iode;
                    let seen = complete
                        .iter()
                        .any(|(prn, _, a, b, c)| *prn == d.sv_id && (*a, *b, *c) == (s1, s2, s3));
                    if same_issue && !seen {
                        complete.push((d.sv_id, how, s1, s2, s3));
                    }
                }
            }
            _ => {}
        }
    }
    stats.epochs = epochs.len() as u64;
    let near_week = epochs.first().map_or(0, |e| u32::from(e.week));
    let ephemerides: Vec<GpsEphemeris> = complete
        .iter()
        .map(|(prn, how, s1, s2, s3)| ephemeris_of(*prn, *how, s1, s2, s3, near_week))
        .collect();
    stats.ephemerides = ephemerides.len() as u64;
    // GPS's Klobuchar: LNAV page 18's, else CNAV message type 30's (the same parameters,
    // IS-GPS-200 §30.3.3.3); BeiDou's: the last D1 subframe 1's.
    let iono = iono.or(others.gps_cnav_iono);
    let bds_iono = others_done.iter().rev().find_map(|(_, e)| match e {
        NavEphemeris::Beidou(b) if b.s1.alpha.iter().any(|a| *a != 0.0) => Some((b.s1.alpha, b.s1.beta)),
        _ => None,
    });
    stats.iono = iono.is_some();
    stats.bds_iono = bds_iono.is_some();
    let mut glonass: Vec<GloRecord> = Vec::new();
    for (at, e) in &glo_done {
        let channel = epochs.iter().find_map(|raw| {
            raw.meas[..usize::from(raw.num_meas).min(raw.meas.len())]
                .iter()
                .find(|m| m.gnss_id == GNSS_ID_GLONASS && m.sv_id == e.slot && m.freq_id <= 13)
                .map(|m| m.freq_id as i8 - 7)
        });
        match (channel, epochs.get(*at).or(epochs.last())) {
            (Some(k), Some(near)) => glonass.push(glonass_record_of(e, near, k)),
            _ => stats.glonass_without_channel += 1,
        }
    }
    stats.glonass_ephemerides = glonass.len() as u64;
    let mut kepler: Vec<KeplerRecord> = Vec::new();
    for (at, e) in &others_done {
        match (kepler_record_of(e, epochs.get(*at).or(epochs.last())), e) {
            (Some(k), _) => kepler.push(k),
            (None, NavEphemeris::GpsCnav(_)) => stats.gps_cnav_left_out += 1,
            (None, _) => {}
        }
    }
    stats.galileo_ephemerides = kepler.iter().filter(|k| k.system == 'E').count() as u64;
    stats.beidou_ephemerides = kepler.iter().filter(|k| k.system == 'C').count() as u64;

    let program = format!("navsync {}", env!("CARGO_PKG_VERSION"));
    let c = civil_from_utc_ns(realtime_now_ns());
    let date = format!(
        "{:04}{:02}{:02} {:02}{:02}{:02} UTC",
        c.year, c.month, c.day, c.hour, c.minute, c.second
    );
    let marker = args.marker.clone().unwrap_or_else(|| {
        args.recording
            .file_stem()
            .map_or_else(String::new, |s| s.to_string_lossy().into_owned())
    });
    let header = ObsHeader {
        program: program.clone(),
        date: date.clone(),
        marker,
        approx_ecef_m: stats.approx_ecef_m.unwrap_or([0.0; 3]),
    };
    let obs = rinex_write::write_obs(&header, &epochs)?;
    stats.unmapped = obs.unmapped;
    let nav = rinex_write::write_nav(
        &program,
        &date,
        &NavRecords {
            iono,
            bds_iono,
            gps: &ephemerides,
            glonass: &glonass,
            kepler: &kepler,
        },
    );

    // Both files complete before either is renamed into place.
    let inputs = [args.recording.as_path()];
    let rules = Overwrite::new(&inputs, args.force);
    let mut files = Vec::new();
    for (path, text) in [(&args.obs, &obs.text), (&args.nav, &nav)] {
        let mut f = OutputFile::create(path, &rules)?;
        f.write_all(text.as_bytes()).map_err(|source| RinexExportError::Io {
            path: path.clone(),
            source,
        })?;
        files.push(f);
    }
    for f in files {
        f.commit()?;
    }
    Ok(stats)
}

/// The week of seconds-of-week `t_s` nearest the instant `near_week`, `near_s` of the same time
/// scale.
fn week_near(t_s: f64, near_week: i64, near_s: f64) -> u32 {
    (near_week - ((t_s - near_s) / 604_800.0).round() as i64).max(0) as u32
}

/// The RINEX record of a Galileo (I/NAV, F/NAV) or BeiDou (D1, D2) ephemeris received near the
/// epoch `near` (which resolves the weeks of t_oc and t_oe; Galileo's 12-bit and BeiDou's 13-bit
/// week numbers are not used); `None` for GPS CNAV, which RINEX 3.05 has no record for, and
/// without an epoch. Galileo's data sources (RINEX 3.05 Galileo record, ORBIT 5): I/NAV
/// 513 (bits 0 and 9: E1-B, clock for E5b,E1), F/NAV 258 (bits 1 and 8: E5a-I, clock for
/// E5a,E1), as RTKLIB's `convbin` writes them; SV health bits 0–2 E1-B DVS/HS, 3–5 E5a, 6–8
/// E5b (OS SIS ICD §5.1.9.3). BeiDou's times are BDT (GPS − 14 s, BDS-SIS-ICD-B1I §4.3).
pub fn kepler_record_of(e: &NavEphemeris, near: Option<&GnssRaw>) -> Option<KeplerRecord> {
    let near = near?;
    let (gps_week, gps_s) = (i64::from(near.week), near.rcv_tow_s);
    let o = e.broadcast().orbit;
    let sisa = |index: u8| galileo::sisa_m(index).unwrap_or(-1.0);
    let (system, sv, week, iod, sources, accuracy, health, delays, tx, last) = match e {
        NavEphemeris::Galileo(g) => {
            let w5 = &g.w5;
            let health = u16::from(w5.e1b_dvs)
                | (u16::from(w5.e1b_hs) << 1)
                | (u16::from(w5.e5b_dvs) << 6)
                | (u16::from(w5.e5b_hs) << 7);
            (
                'E',
                g.sv,
                week_near(o.toe_s, gps_week, gps_s),
                g.w1.iod_nav,
                513.0,
                sisa(g.w3.sisa),
                f64::from(health),
                [w5.bgd_e1_e5a_s, w5.bgd_e1_e5b_s],
                f64::from(w5.tow_s),
                0.0,
            )
        }
        NavEphemeris::GalileoFnav(f) => (
            'E',
            f.sv,
            week_near(o.toe_s, gps_week, gps_s),
            f.p1.iod_nav,
            258.0,
            sisa(f.p1.sisa),
            f64::from((f.p1.e5a_dvs << 3) | (f.p1.e5a_hs << 4)),
            [f.p1.bgd_e1_e5a_s, 0.0],
            f64::from(f.p1.tow_s),
            0.0,
        ),
        NavEphemeris::Beidou(b) => {
            let bdt_s = gps_s + navsync_estimator::gnss::ranges::BDT_MINUS_GPST_S;
            let bdt_week = gps_week - i64::from(rinex::BDT_WEEK_OFFSET);
            (
                'C',
                b.sv,
                week_near(o.toe_s, bdt_week, bdt_s),
                u16::from(b.s1.aode),
                0.0,
                navsync_estimator::gnss::ranges::ura_m(b.s1.urai).unwrap_or(-1.0),
                f64::from(b.s1.sat_h1),
                [b.s1.tgd1_s, b.s1.tgd2_s],
                f64::from(b.sow_s),
                f64::from(b.s1.aodc),
            )
        }
        NavEphemeris::GpsCnav(_) => return None,
    };
    let toc_week = (i64::from(week) - ((o.toc_s - o.toe_s) / 604_800.0).round() as i64).max(0) as u32;
    Some(KeplerRecord {
        line: 0,
        system,
        sv,
        toc_week,
        toc_s: o.toc_s,
        af: o.af,
        orbit: [
            [f64::from(iod), o.crs, o.delta_n_rad_s, o.m0_rad],
            [o.cuc, o.e, o.cus, o.sqrt_a],
            [o.toe_s, o.cic, o.omega0_rad, o.cis],
            [o.i0_rad, o.crc, o.omega_rad, o.omega_dot_rad_s],
            [o.idot_rad_s, sources, f64::from(week), 0.0],
            [accuracy, health, delays[0], delays[1]],
            [tx, last, 0.0, 0.0],
        ],
    })
}
