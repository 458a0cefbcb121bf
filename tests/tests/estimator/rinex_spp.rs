//! Real receiver data through RINEX: two GEONET stations (RINEX 2.10, 1 h at 30 s, GPS;
//! `../shared/datasets/rtklib-geonet-0759-3040/`) imported with `navsync import rinex`, solved
//! with `navsync spp` against the stations' marker coordinates, and side by side with RTKLIB's
//! single-point solution (`rnx2rtkp -p 0`, same elevation mask, broadcast ionosphere,
//! Saastamoinen troposphere) when its binary is there; the same station as RINEX 3.05
//! (RTKLIB's `convbin`) against its RINEX 2.10 files.

use std::path::{Path, PathBuf};

use navsync_estimator::gnss::ranges::EphemerisStore;
use navsync_estimator::gnss::spp::ned_from_ecef;
use navsync_recording::SampleReader;
use navsync_shared::earth::geodetic_from_ecef;
use navsync_shared::samples::AnySample;
use navsync_tests::{TestEnv, shared_material};
use serde_json::Value;

/// The stations and their marker positions (GEONET coordinates, the files' headers), ECEF m.
pub(crate) const STATIONS: [(&str, [f64; 3]); 2] = [
    ("0759", [-3976219.5082, 3382372.5671, 3652512.9849]),
    ("3040", [-3978242.4348, 3382841.1715, 3649902.7667]),
];
/// The elevation mask both solutions use, degrees.
pub(crate) const MASK_DEG: &str = "10";

pub(crate) fn files(station: &str) -> (PathBuf, PathBuf) {
    let d = shared_material("datasets/rtklib-geonet-0759-3040");
    (
        d.join(format!("{station}0920.05o")),
        d.join(format!("{station}0920.05n")),
    )
}

pub(crate) fn run_ok(env: &TestEnv, args: &[&str]) -> String {
    let o = env.command(args).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "navsync {args:?}: {}\n{err}", o.status);
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Horizontal and 3-D RMS of ECEF positions against `reference`, m (east/north/up at the
/// reference; computed here, independently of `navsync spp`'s own summary).
fn rms(positions: &[[f64; 3]], reference: [f64; 3]) -> (f64, f64) {
    let g = geodetic_from_ecef(reference[0], reference[1], reference[2]).unwrap();
    let c = ned_from_ecef(g.lat_deg.to_radians(), g.lon_deg.to_radians());
    let (mut h, mut v) = (0.0, 0.0);
    for p in positions {
        let d = nalgebra::Vector3::new(p[0] - reference[0], p[1] - reference[1], p[2] - reference[2]);
        let ned = c * d;
        h += ned.x * ned.x + ned.y * ned.y;
        v += ned.z * ned.z;
    }
    let n = positions.len().max(1) as f64;
    ((h / n).sqrt(), ((h + v) / n).sqrt())
}

/// Imports one station and solves it: (navsync's positions, its JSON summary, the recording).
fn navsync_spp(env: &TestEnv, station: &str, reference: [f64; 3]) -> (Vec<[f64; 3]>, Value, PathBuf) {
    let (obs, nav) = files(station);
    let rec = env.dir.join(format!("{station}.mcap"));
    let csv = env.dir.join(format!("{station}.csv"));
    let p = |x: &Path| x.display().to_string();
    run_ok(env, &["import", "rinex", &p(&obs), &p(&nav), "--out", &p(&rec)]);
    let r = format!("{},{},{}", reference[0], reference[1], reference[2]);
    let json = run_ok(
        env,
        &[
            "spp",
            &p(&rec),
            "--out",
            &p(&csv),
            &format!("--reference={r}"),
            "--elevation-mask-deg",
            MASK_DEG,
            "--json",
        ],
    );
    let summary: Value = serde_json::from_str(json.trim()).unwrap_or_else(|e| panic!("{e}: {json}"));
    let text = std::fs::read_to_string(&csv).unwrap();
    let positions = text
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<f64> = l.split(',').take(5).map(|x| x.parse().unwrap()).collect();
            [f[2], f[3], f[4]]
        })
        .collect();
    (positions, summary, rec)
}

/// Observation epochs of a RINEX 2 file, counted from its text: epoch lines with flag 0/1.
fn epoch_lines(obs: &Path) -> usize {
    let text = std::fs::read_to_string(obs).unwrap();
    let body = text.split("END OF HEADER").nth(1).unwrap();
    body.lines()
        .filter(|l| {
            l.len() >= 32
                && matches!(&l[26..29], "  0" | "  1")
                && l[..26].split_whitespace().filter(|x| x.parse::<f64>().is_ok()).count() == 6
        })
        .count()
}

#[test]
fn geonet_stations_import_and_solve_within_a_metre_horizontally() {
    let env = TestEnv::new("rinexspp");
    for (station, reference) in STATIONS {
        let (positions, summary, rec) = navsync_spp(&env, station, reference);
        // Every epoch of the file is in the recording and nearly every one is solved.
        let epochs = epoch_lines(&files(station).0);
        assert!(epochs > 100, "{station}: {epochs} epochs in the file");
        assert_eq!(summary["epochs"].as_u64(), Some(epochs as u64), "{station}: {summary}");
        assert!(
            positions.len() * 100 >= epochs * 95,
            "{station}: {} of {epochs} solved",
            positions.len()
        );
        // The navigation data decode as LNAV (parity) into complete ephemerides.
        let mut store = EphemerisStore::default();
        let mut reader = SampleReader::open(&rec).unwrap();
        while let Some(s) = reader.next_sample().unwrap() {
            if let AnySample::NavData(d) = s.sample {
                store.on_nav_data(&d);
            }
        }
        assert_eq!(store.bad_subframes, 0, "{station}");
        assert!(store.ephemerides >= 8, "{station}: {} ephemerides", store.ephemerides);
        let (h, d3) = rms(&positions, reference);
        eprintln!("{station}: navsync SPP horizontal RMS {h:.3} m, 3-D RMS {d3:.3} m");
        assert!(h <= 1.0, "{station}: horizontal RMS {h:.3} m");
        let reported = summary["horizontal_rms_m"].as_f64().unwrap();
        assert!((reported - h).abs() < 1e-3, "{station}: summary {reported} vs {h}");
    }
}

/// An RTKLIB program: `$env_var`, else its build beside the checkout
/// (`../rtklib/app/consapp/NAME/gcc/NAME`); `None`, saying the test is skipped, without it.
pub(crate) fn rtklib(name: &str, env_var: &str) -> Option<PathBuf> {
    let built = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../../rtklib/app/consapp/{name}/gcc/{name}"));
    let p = std::env::var_os(env_var).map_or(built, PathBuf::from);
    if !p.is_file() {
        eprintln!("skipped: RTKLIB's {name} not found (set {env_var} or build it in ../rtklib)");
        return None;
    }
    Some(p)
}

/// RTKLIB's single-point solution of an OBS/NAV pair, per epoch (its time as printed, ECEF
/// m): single point (-p 0), ECEF output (-e), GPS only, the same mask; broadcast ionosphere
/// and Saastamoinen troposphere are rnx2rtkp's defaults.
pub(crate) fn rtklib_spp(rnx2rtkp: &Path, obs: &Path, nav: &Path, out: &Path) -> Vec<(String, [f64; 3])> {
    rtklib_spp_systems(rnx2rtkp, obs, nav, out, "G")
}

/// [`rtklib_spp`] with the systems `systems` (rnx2rtkp's `-sys`, e.g. `G,E,C`).
pub(crate) fn rtklib_spp_systems(
    rnx2rtkp: &Path,
    obs: &Path,
    nav: &Path,
    out: &Path,
    systems: &str,
) -> Vec<(String, [f64; 3])> {
    rtklib_spp_with(rnx2rtkp, obs, nav, out, systems, None)
}

/// RTKLIB's ionosphere-free single-point solution (`pos1-ionoopt=dual-freq`,
/// `pos1-frequency=l1+l2`) of `obs`/`nav` with `systems`, as [`rtklib_spp_systems`].
pub(crate) fn rtklib_dual_frequency(
    rnx2rtkp: &Path,
    obs: &Path,
    nav: &Path,
    out: &Path,
    systems: &str,
) -> Vec<(String, [f64; 3])> {
    let options = "pos1-frequency     =l1+l2\npos1-ionoopt       =dual-freq\nout-timeform       =tow\n";
    rtklib_spp_with(rnx2rtkp, obs, nav, out, systems, Some(options))
}

/// `rnx2rtkp -p 0 -e -sys SYSTEMS -m MASK` (with `options` as a `-k` file beside `out`):
/// ("week tow", ECEF m) per epoch.
fn rtklib_spp_with(
    rnx2rtkp: &Path,
    obs: &Path,
    nav: &Path,
    out: &Path,
    systems: &str,
    options: Option<&str>,
) -> Vec<(String, [f64; 3])> {
    let mut cmd = std::process::Command::new(rnx2rtkp);
    if let Some(text) = options {
        let conf = out.with_extension("conf");
        std::fs::write(&conf, text).unwrap();
        cmd.arg("-k").arg(conf);
    }
    let o = cmd
        .args(["-p", "0", "-e", "-sys", systems, "-m", MASK_DEG, "-o"])
        .arg(out)
        .arg(obs)
        .arg(nav)
        .output()
        .unwrap();
    assert!(o.status.success(), "rnx2rtkp: {}", String::from_utf8_lossy(&o.stderr));
    std::fs::read_to_string(out)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('%'))
        .map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            let x = |k: usize| f[k].parse::<f64>().unwrap();
            (format!("{} {}", f[0], f[1]), [x(2), x(3), x(4)])
        })
        .collect()
}

#[test]
fn geonet_spp_is_no_worse_than_rtklib() {
    let Some(rnx2rtkp) = rtklib("rnx2rtkp", "NAVSYNC_RNX2RTKP") else {
        return;
    };
    let env = TestEnv::new("rinexrtk");
    for (station, reference) in STATIONS {
        let (obs, nav) = files(station);
        let pos = env.dir.join(format!("{station}.pos"));
        let theirs: Vec<[f64; 3]> = rtklib_spp(&rnx2rtkp, &obs, &nav, &pos)
            .into_iter()
            .map(|(_, p)| p)
            .collect();
        assert!(theirs.len() > 100, "{station}: RTKLIB solved {} epochs", theirs.len());
        let (ours, _, _) = navsync_spp(&env, station, reference);
        let ((h, d3), (rh, rd3)) = (rms(&ours, reference), rms(&theirs, reference));
        eprintln!(
            "{station}: horizontal / 3-D RMS: navsync {h:.3} / {d3:.3} m ({} epochs), RTKLIB {rh:.3} / {rd3:.3} m ({} epochs)",
            ours.len(),
            theirs.len()
        );
        assert!(ours.len() >= theirs.len(), "{station}: navsync solved fewer epochs");
        assert!(
            h <= rh,
            "{station}: navsync horizontal RMS {h:.3} m > RTKLIB's {rh:.3} m"
        );
    }
}

/// A RINEX 2 GPS navigation file rewritten as RINEX 3.05 (Table A8: `Gnn yyyy mm dd hh mm ss`
/// first lines, orbit lines indented by 4; the header's α/β as `IONOSPHERIC CORR` GPSA/GPSB).
fn nav_as_rinex3(v2: &str) -> String {
    let mut out = format!(
        "{:<20}{:<20}{:<20}RINEX VERSION / TYPE\n",
        "     3.05", "N: GNSS NAV DATA", "G: GPS"
    );
    let (header, body) = v2.split_once("END OF HEADER").unwrap();
    for l in header.lines() {
        let label = l.get(60..).unwrap_or("").trim();
        let which = match label {
            "ION ALPHA" => "GPSA",
            "ION BETA" => "GPSB",
            _ => continue,
        };
        out += &format!("{:<60}IONOSPHERIC CORR\n", format!("{which} {}", &l[2..50]));
    }
    out += &format!("{:60}END OF HEADER\n", "");
    for l in body.lines().skip(1).filter(|l| !l.trim().is_empty()) {
        if l.starts_with("   ") || l.starts_with("    ") {
            out += &format!(" {l}\n");
        } else {
            let prn: u32 = l[0..2].trim().parse().unwrap();
            let t: Vec<f64> = l[3..22].split_whitespace().map(|x| x.parse().unwrap()).collect();
            out += &format!(
                "G{prn:02} {} {:02} {:02} {:02} {:02} {:02}{}\n",
                2000 + t[0] as u32,
                t[1],
                t[2],
                t[3],
                t[4],
                t[5].round(),
                &l[22..]
            );
        }
    }
    out
}

/// The same station as RINEX 3.05 (observations converted by RTKLIB's `convbin`, navigation
/// rewritten by this test) gives the same solution, epoch by epoch, as its RINEX 2.10 files.
#[test]
fn geonet_rinex3_gives_the_rinex2_solutions() {
    let Some(convbin) = rtklib("convbin", "NAVSYNC_CONVBIN") else {
        return;
    };
    let env = TestEnv::new("rinex3");
    let (station, reference) = STATIONS[1];
    let (obs, nav) = files(station);
    let (obs3, nav3) = (env.dir.join("r3.obs"), env.dir.join("r3.nav"));
    let o = std::process::Command::new(&convbin)
        .args(["-r", "rinex", "-v", "3.05", "-o"])
        .arg(&obs3)
        .arg(&obs)
        .output()
        .unwrap();
    assert!(
        o.status.success() && obs3.is_file(),
        "convbin: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(std::fs::read_to_string(&obs3).unwrap().starts_with("     3.05"));
    std::fs::write(&nav3, nav_as_rinex3(&std::fs::read_to_string(&nav).unwrap())).unwrap();
    let p = |x: &Path| x.display().to_string();
    let r = format!("--reference={},{},{}", reference[0], reference[1], reference[2]);
    let mut csvs = Vec::new();
    for (name, o, n) in [("v2", &obs, &nav), ("v3", &obs3, &nav3)] {
        let rec = env.dir.join(format!("{name}.mcap"));
        let csv = env.dir.join(format!("{name}.csv"));
        run_ok(&env, &["import", "rinex", &p(o), &p(n), "--out", &p(&rec)]);
        run_ok(&env, &["spp", &p(&rec), "--out", &p(&csv), &r]);
        csvs.push(std::fs::read_to_string(&csv).unwrap());
    }
    assert!(csvs[0].lines().count() > 100, "{}", csvs[0]);
    assert_eq!(csvs[0], csvs[1], "RINEX 3 and RINEX 2 solutions differ");
}

/// Dual frequency on a geodetic receiver's RINEX 2 (`C1` and `P2`: GPS L1 C/A and the
/// semi-codeless L2 P(Y), navsync's `SIG_GPS_L2_PY`): `navsync spp --dual-frequency` solves
/// every epoch with the ionosphere-free combination (the L2 delay γ·T_GD, the L1 C/A one T_GD
/// with its unknown ISC as σ), within 1.5 m horizontally of each marker (measured 1.15 and
/// 1.08 m; RTKLIB's `pos1-ionoopt=dual-freq` on the same files, printed when built, 1.04 and
/// 1.15 m). On these files one frequency with the broadcast model is better (0.48 and 0.56 m):
/// the combination triples the code noise, and C1's satellite biases against P1 (no DCB file
/// here, as for RTKLIB) go into it 2.5-fold.
#[test]
fn geonet_dual_frequency_uses_l2_p_y() {
    let env = TestEnv::new("rinexdual");
    let p = |x: &Path| x.display().to_string();
    for (station, reference) in STATIONS {
        let (obs, nav) = files(station);
        let rec = env.dir.join(format!("{station}.mcap"));
        run_ok(&env, &["import", "rinex", &p(&obs), &p(&nav), "--out", &p(&rec)]);
        let r = format!("--reference={},{},{}", reference[0], reference[1], reference[2]);
        let json = run_ok(
            &env,
            &[
                "spp",
                &p(&rec),
                &r,
                "--elevation-mask-deg",
                MASK_DEG,
                "--dual-frequency",
                "--json",
            ],
        );
        let s: Value = serde_json::from_str(json.trim()).unwrap();
        let (h, solved) = (s["horizontal_rms_m"].as_f64().unwrap(), s["solved"].as_u64().unwrap());
        let used = s["satellites_used_per_system"]["G"].as_u64().unwrap() as f64 / solved.max(1) as f64;
        let theirs = rtklib("rnx2rtkp", "NAVSYNC_RNX2RTKP").map(|rnx2rtkp| {
            let out = env.dir.join(format!("{station}-dual.pos"));
            let positions: Vec<[f64; 3]> = rtklib_dual_frequency(&rnx2rtkp, &obs, &nav, &out, "G")
                .into_iter()
                .map(|(_, p)| p)
                .collect();
            rms(&positions, reference).0
        });
        eprintln!(
            "{station} dual frequency (L1 C/A + L2 P(Y)): navsync horizontal RMS {h:.3} m ({solved} epochs, {used:.1} \
             satellites, {} without P2), RTKLIB {theirs:.3?} m",
            s["no_second_signal"]
        );
        assert!(solved >= 114 && used >= 5.0, "{station}: {s}");
        assert!(h <= 1.5, "{station}: {h:.3} m");
    }
}
