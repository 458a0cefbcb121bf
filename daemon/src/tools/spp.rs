//! `navsync spp REC.mcap [--out FILE.csv] [--reference X,Y,Z] [--systems G,E,C,R]
//! [--dual-frequency]`: the single-point solution of each raw epoch of a recording from GPS L1
//! C/A, Galileo E1, BeiDou B1I/B3I and GLONASS L1OF (with `--dual-frequency` GPS L1 C/A + L2C
//! and Galileo E1 + E5a ionosphere-free) with one receiver clock per system (the estimator's `gnss::spp`, with the
//! navigation data collected by `gnss::ranges::EphemerisStore` as the tightly coupled filter
//! does), as a CSV, and its errors against a reference position (east/north/up, horizontal,
//! vertical and 3-D RMS, m), with the satellites used per system.

use std::io::Write;
use std::path::PathBuf;

use navsync_estimator::gnss::ranges::{EphemerisStore, RangeBuildCounts};
use navsync_estimator::gnss::spp::{self, MAX_SYSTEMS, SppError, SppSettings};
use navsync_recording::SampleReader;
use navsync_recording::output::{OutputFile, Overwrite};
use navsync_shared::earth::geodetic_from_ecef;
use navsync_shared::samples::{AnySample, GnssRaw};
use navsync_shared::services;

/// `navsync spp`.
#[derive(Debug, Clone, clap::Args)]
pub struct SppArgs {
    /// The recording: a receiver's raw data and navigation data (`navsync import rinex`, or
    /// recorded from a u-blox receiver's RXM-RAWX and RXM-SFRBX).
    pub recording: PathBuf,
    /// The receiver's id in the recording.
    #[arg(long, default_value = "0", value_parser = crate::config::estimator::parse_id)]
    pub gnss_id: String,
    /// Per-epoch solutions as CSV (GPS week, seconds of week, ECEF and geodetic position,
    /// clock bias, satellites, east/north/up error against --reference).
    #[arg(short, long)]
    pub out: Option<PathBuf>,
    /// The reference position the errors are taken against, ECEF m: `X,Y,Z`.
    #[arg(long, value_parser = parse_xyz, allow_hyphen_values = true)]
    pub reference: Option<[f64; 3]>,
    /// Elevation mask, degrees.
    #[arg(long, default_value_t = 10.0)]
    pub elevation_mask_deg: f64,
    /// Pseudorange 1σ at zenith, m (each satellite's broadcast URA when larger); the σ grows
    /// as 1/sin(elevation).
    #[arg(long, default_value_t = 3.0)]
    pub pseudorange_std_m: f64,
    /// The systems used, by their RINEX letters: G GPS (L1 C/A), E Galileo (E1-C, else E1-B),
    /// C BeiDou (B1I, else B3I), R GLONASS (L1OF, each satellite on its channel's
    /// frequency); one receiver clock each.
    #[arg(long, default_value = "G,E,C,R", value_parser = parse_systems)]
    pub systems: Systems,
    /// GPS and Galileo as the ionosphere-free combination of two signals (GPS L1 C/A with L2C,
    /// or L2 P(Y) from a geodetic receiver's RINEX; Galileo E1 with E5a) instead of one signal
    /// with the broadcast ionosphere model: no ionospheric error, about 3× the noise. One
    /// second signal per system and epoch, the one most satellites have; a satellite without it
    /// is left out. BeiDou and GLONASS stay on one frequency.
    #[arg(long)]
    pub dual_frequency: bool,
    /// The summary as one JSON object on stdout.
    #[arg(long)]
    pub json: bool,
    /// Replace an existing file at --out.
    #[arg(long)]
    pub force: bool,
}

/// The systems of `--systems`: u-blox `gnssId`s.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Systems(pub Vec<u8>);

/// The RINEX letter of each system of [`spp::SYSTEMS`].
const LETTERS: [char; MAX_SYSTEMS] = ['G', 'E', 'C', 'R'];

fn parse_systems(s: &str) -> Result<Systems, String> {
    let mut out = Vec::new();
    for part in s.split(',').map(str::trim) {
        let g = match part {
            "G" => 0,
            "E" => 2,
            "C" => 3,
            "R" => 6,
            _ => {
                return Err(format!(
                    "unknown system '{part}': G (GPS), E (Galileo), C (BeiDou), R (GLONASS)"
                ));
            }
        };
        if !out.contains(&g) {
            out.push(g);
        }
    }
    Ok(Systems(out))
}

fn parse_xyz(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("expected X,Y,Z in metres, got '{s}'"))?;
    <[f64; 3]>::try_from(v).map_err(|_| format!("expected three numbers X,Y,Z, got '{s}'"))
}

/// One epoch's solution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EpochSolution {
    /// GPS week of the epoch.
    pub week: u16,
    /// Receiver time of the epoch, s of week.
    pub tow_s: f64,
    /// The solution.
    pub sol: spp::Solution,
}

/// What [`solve_recording`] found.
#[derive(Debug, Clone, Default)]
pub struct SppRun {
    /// The solved epochs.
    pub solutions: Vec<EpochSolution>,
    /// Raw epochs of the receiver.
    pub epochs: u64,
    /// Epochs without a solution: fewer than four satellites.
    pub too_few: u64,
    /// Epochs without a solution: no convergence.
    pub no_convergence: u64,
    /// Measurements left out while building the epochs.
    pub counts: RangeBuildCounts,
    /// Epochs solved with at least one satellite of each system of [`spp::SYSTEMS`].
    pub epochs_with_system: [u64; MAX_SYSTEMS],
    /// Satellites used, summed over the solved epochs, per system of [`spp::SYSTEMS`].
    pub used_per_system: [u64; MAX_SYSTEMS],
}

/// Solves every raw epoch of the recording.
pub fn solve_recording(args: &SppArgs) -> anyhow::Result<SppRun> {
    let (raw_service, nav_service) = (
        services::gnss_raw(&args.gnss_id),
        services::gnss_nav_data(&args.gnss_id),
    );
    let settings = SppSettings {
        elevation_mask_rad: args.elevation_mask_deg.to_radians(),
        ..SppSettings::default()
    };
    let mut reader = SampleReader::open(&args.recording)?;
    let mut store = EphemerisStore::default();
    let mut run = SppRun::default();
    let mut init = [0.0; 3];
    while let Some(s) = reader.next_sample()? {
        match s.sample {
            AnySample::NavData(d) if s.service == nav_service => store.on_nav_data(&d),
            AnySample::Raw(raw) if s.service == raw_service => {
                run.epochs += 1;
                let (std, systems) = (args.pseudorange_std_m, &args.systems.0);
                let signals = Signals {
                    systems,
                    dual_frequency: args.dual_frequency,
                };
                match solve_epoch_systems(&store, &raw, signals, init, &settings, std, &mut run.counts) {
                    Ok(sol) => {
                        init = sol.ecef_m;
                        for (k, &n) in sol.used_per_system.iter().enumerate() {
                            run.epochs_with_system[k] += u64::from(n > 0);
                            run.used_per_system[k] += n as u64;
                        }
                        run.solutions.push(EpochSolution {
                            week: raw.week,
                            tow_s: raw.rcv_tow_s,
                            sol,
                        });
                    }
                    Err(SppError::TooFew(_)) => run.too_few += 1,
                    Err(SppError::NoConvergence) => run.no_convergence += 1,
                }
            }
            _ => {}
        }
    }
    Ok(run)
}

/// The GPS L1 C/A single-point solution of one raw epoch with the ephemerides `store` holds,
/// iterated from `init` (ECEF m); each satellite's σ at zenith is the larger of
/// `pseudorange_std_m` and its broadcast URA.
pub fn solve_epoch(
    store: &EphemerisStore,
    raw: &GnssRaw,
    init: [f64; 3],
    settings: &SppSettings,
    pseudorange_std_m: f64,
    counts: &mut RangeBuildCounts,
) -> Result<spp::Solution, SppError> {
    let signals = Signals {
        systems: &[0],
        dual_frequency: false,
    };
    solve_epoch_systems(store, raw, signals, init, settings, pseudorange_std_m, counts)
}

/// What [`solve_epoch_systems`] takes of an epoch.
#[derive(Debug, Clone, Copy)]
pub struct Signals<'a> {
    /// The systems (u-blox `gnssId`s), one receiver clock each.
    pub systems: &'a [u8],
    /// Ionosphere-free combinations where a second signal was tracked (`--dual-frequency`).
    pub dual_frequency: bool,
}

/// [`solve_epoch`] with the systems and signals of `signals`; the σ floor `pseudorange_std_m`
/// is one signal's (scaled by a combination's noise gain).
pub fn solve_epoch_systems(
    store: &EphemerisStore,
    raw: &GnssRaw,
    signals: Signals,
    init: [f64; 3],
    settings: &SppSettings,
    pseudorange_std_m: f64,
    counts: &mut RangeBuildCounts,
) -> Result<spp::Solution, SppError> {
    let mut obs = store.system_observations(raw, signals.systems, signals.dual_frequency, counts);
    for o in &mut obs {
        o.obs.sigma_zenith_m = o.obs.sigma_zenith_m.max(pseudorange_std_m * o.noise_gain);
    }
    spp::solve(&obs, store.iono().as_ref(), raw.rcv_tow_s, init, settings)
}

/// `G:n E:n C:n` of the systems with a count.
fn per_system(counts: &[u64; MAX_SYSTEMS]) -> String {
    let parts: Vec<String> = LETTERS
        .iter()
        .zip(counts)
        .filter(|(_, n)| **n > 0)
        .map(|(l, n)| format!("{l} {n}"))
        .collect();
    parts.join(", ")
}

/// East, north, up of `p − reference`, m.
pub fn enu_error(p: [f64; 3], reference: [f64; 3]) -> Option<[f64; 3]> {
    let g = geodetic_from_ecef(reference[0], reference[1], reference[2])?;
    let c = spp::ned_from_ecef(g.lat_deg.to_radians(), g.lon_deg.to_radians());
    let d = [p[0] - reference[0], p[1] - reference[1], p[2] - reference[2]];
    let ned = |row: usize| (0..3).map(|k| c[(row, k)] * d[k]).sum::<f64>();
    Some([ned(1), ned(0), -ned(2)])
}

/// Horizontal, vertical and 3-D RMS of east/north/up errors, m.
pub fn rms(errors: &[[f64; 3]]) -> [f64; 3] {
    let n = errors.len().max(1) as f64;
    let h = errors.iter().map(|e| e[0] * e[0] + e[1] * e[1]).sum::<f64>() / n;
    let v = errors.iter().map(|e| e[2] * e[2]).sum::<f64>() / n;
    [h.sqrt(), v.sqrt(), (h + v).sqrt()]
}

/// Runs `navsync spp`.
pub fn run(args: &SppArgs) -> anyhow::Result<()> {
    use anyhow::Context;
    let r = solve_recording(args).with_context(|| format!("reading {}", args.recording.display()))?;
    let errors: Vec<[f64; 3]> = match args.reference {
        Some(p) => r
            .solutions
            .iter()
            .map(|s| enu_error(s.sol.ecef_m, p).context("--reference is not a position on the Earth"))
            .collect::<anyhow::Result<_>>()?,
        None => Vec::new(),
    };
    if let Some(out) = &args.out {
        let inputs = [args.recording.as_path()];
        let f = OutputFile::create(out, &Overwrite::new(&inputs, args.force))?;
        let mut w = std::io::BufWriter::new(f);
        writeln!(
            w,
            "week,tow_s,x_m,y_m,z_m,lat_deg,lon_deg,height_m,clock_bias_m,sats,excluded_prn,east_m,north_m,up_m,gps,galileo,beidou,glonass,excluded"
        )?;
        for (k, s) in r.solutions.iter().enumerate() {
            let p = s.sol.ecef_m;
            // A value that does not exist (no geodetic form, no --reference) is an empty field.
            let opt = |v: Option<f64>, decimals: usize| v.map_or(String::new(), |x| format!("{x:.decimals$}"));
            let g = geodetic_from_ecef(p[0], p[1], p[2]);
            let e = errors.get(k).copied();
            writeln!(
                w,
                "{},{:.3},{:.4},{:.4},{:.4},{},{},{},{:.3},{},{},{},{},{},{},{},{},{},{}",
                s.week,
                s.tow_s,
                p[0],
                p[1],
                p[2],
                opt(g.map(|g| g.lat_deg), 9),
                opt(g.map(|g| g.lon_deg), 9),
                opt(g.map(|g| g.height_m), 4),
                s.sol.clock_bias_m,
                s.sol.used,
                s.sol.excluded.map_or(String::new(), |x| x.to_string()),
                opt(e.map(|e| e[0]), 4),
                opt(e.map(|e| e[1]), 4),
                opt(e.map(|e| e[2]), 4),
                s.sol.used_per_system[0],
                s.sol.used_per_system[1],
                s.sol.used_per_system[2],
                s.sol.used_per_system[3],
                excluded_name(&s.sol),
            )?;
        }
        w.into_inner().map_err(|e| e.into_error())?.commit()?;
    }
    let [h, v, d3] = rms(&errors);
    if args.json {
        let mut j = serde_json::json!({
            "epochs": r.epochs,
            "solved": r.solutions.len(),
            "too_few_satellites": r.too_few,
            "no_convergence": r.no_convergence,
            "no_ephemeris": r.counts.no_ephemeris,
            "other_signals": r.counts.other_signals,
            "dual_frequency": args.dual_frequency,
            "no_second_signal": r.counts.no_second_signal,
            "systems": args.systems.0.iter().filter_map(|g| spp::system_index(*g)).map(|k| LETTERS[k].to_string()).collect::<Vec<_>>(),
            "epochs_with_system": system_map(&r.epochs_with_system),
            "satellites_used_per_system": system_map(&r.used_per_system),
        });
        if args.reference.is_some() {
            j["horizontal_rms_m"] = h.into();
            j["vertical_rms_m"] = v.into();
            j["rms_3d_m"] = d3.into();
        }
        println!("{j}");
    } else {
        println!(
            "{} epochs, {} solved ({} with fewer than 4 satellites, {} without convergence)",
            r.epochs,
            r.solutions.len(),
            r.too_few,
            r.no_convergence
        );
        let mean: Vec<String> = LETTERS
            .iter()
            .zip(&r.used_per_system)
            .filter(|(_, n)| **n > 0)
            .map(|(l, n)| format!("{l} {:.1}", *n as f64 / r.solutions.len().max(1) as f64))
            .collect();
        println!(
            "epochs using each system: {}; satellites used per solved epoch: {}",
            per_system(&r.epochs_with_system),
            mean.join(", ")
        );
        if args.dual_frequency {
            println!(
                "ionosphere-free (GPS L1/L2, Galileo E1/E5a); {} GPS and Galileo measurements left out without their system's second signal",
                r.counts.no_second_signal
            );
        }
        if args.reference.is_some() {
            println!("against the reference: horizontal RMS {h:.3} m, vertical RMS {v:.3} m, 3-D RMS {d3:.3} m");
        }
    }
    anyhow::ensure!(!r.solutions.is_empty(), "no epoch solved");
    Ok(())
}

/// `{"G": n, "E": n, …}` of every system of [`spp::SYSTEMS`].
fn system_map(counts: &[u64; MAX_SYSTEMS]) -> serde_json::Value {
    let m: serde_json::Map<String, serde_json::Value> = LETTERS
        .iter()
        .zip(counts)
        .map(|(l, n)| (l.to_string(), (*n).into()))
        .collect();
    m.into()
}

/// The excluded satellite as RINEX names it (`E11`), empty when none.
fn excluded_name(s: &spp::Solution) -> String {
    let letter = spp::system_index(s.excluded_gnss_id).map_or('?', |k| LETTERS[k]);
    s.excluded.map_or(String::new(), |sv| format!("{letter}{sv:02}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_are_east_north_up() {
        // On the equator at 0° E: ECEF x is up, y east, z north.
        let r = [6_378_137.0, 0.0, 0.0];
        let e = enu_error([r[0] + 3.0, 2.0, 1.0], r).unwrap();
        assert!(
            (e[0] - 2.0).abs() < 1e-6 && (e[1] - 1.0).abs() < 1e-6 && (e[2] - 3.0).abs() < 1e-6,
            "{e:?}"
        );
        let [h, v, d] = rms(&[[3.0, 4.0, 0.0], [0.0, 0.0, 2.0]]);
        assert!((h - 12.5f64.sqrt()).abs() < 1e-12 && (v - 2f64.sqrt()).abs() < 1e-12);
        assert!((d - 14.5f64.sqrt()).abs() < 1e-12);
        assert_eq!(parse_xyz("-1,2.5,3"), Ok([-1.0, 2.5, 3.0]));
        assert!(parse_xyz("1,2").is_err() && parse_xyz("a,b,c").is_err());
        assert_eq!(parse_systems("G, E,C,G"), Ok(Systems(vec![0, 2, 3])));
        assert_eq!(parse_systems("R,G"), Ok(Systems(vec![6, 0])));
        assert!(parse_systems("G,X").is_err());
    }
}
