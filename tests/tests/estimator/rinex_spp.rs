//! Real receiver data through RINEX: two GEONET stations (RINEX 2.10, 1 h at 30 s, GPS;
//! `../shared/datasets/rtklib-geonet-0759-3040/`) imported with `navsync import rinex`, solved
//! with `navsync spp` against the stations' marker coordinates, and side by side with RTKLIB's
//! single-point solution (`rnx2rtkp -p 0`, same elevation mask, broadcast ionosphere,
//! Saastamoinen troposphere) when its binary is there.

use std::path::{Path, PathBuf};

use navsync_estimator::gnss::ranges::EphemerisStore;
use navsync_estimator::gnss::spp::ned_from_ecef;
use navsync_recording::SampleReader;
use navsync_shared::earth::geodetic_from_ecef;
use navsync_shared::samples::AnySample;
use navsync_tests::{TestEnv, shared_material};
use serde_json::Value;

/// The stations and their marker positions (GEONET coordinates, the files' headers), ECEF m.
const STATIONS: [(&str, [f64; 3]); 2] = [
    ("0759", [-3976219.5082, 3382372.5671, 3652512.9849]),
    ("3040", [-3978242.4348, 3382841.1715, 3649902.7667]),
];
/// The elevation mask both solutions use, degrees.
const MASK_DEG: &str = "10";

fn files(station: &str) -> (PathBuf, PathBuf) {
    let d = shared_material("datasets/rtklib-geonet-0759-3040");
    (
        d.join(format!("{station}0920.05o")),
        d.join(format!("{station}0920.05n")),
    )
}

fn run_ok(env: &TestEnv, args: &[&str]) -> String {
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

/// RTKLIB's `rnx2rtkp`: `$NAVSYNC_RNX2RTKP`, else the build beside the checkout.
fn rnx2rtkp() -> Option<PathBuf> {
    let p = std::env::var_os("NAVSYNC_RNX2RTKP")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../rtklib/app/consapp/rnx2rtkp/gcc/rnx2rtkp")
        });
    p.is_file().then_some(p)
}

#[test]
fn geonet_spp_is_no_worse_than_rtklib() {
    let Some(rtklib) = rnx2rtkp() else {
        eprintln!("skipped: RTKLIB's rnx2rtkp not found (set NAVSYNC_RNX2RTKP or build it in ../rtklib)");
        return;
    };
    let env = TestEnv::new("rinexrtk");
    for (station, reference) in STATIONS {
        let (obs, nav) = files(station);
        let pos = env.dir.join(format!("{station}.pos"));
        // Single point (-p 0), ECEF output (-e), GPS only, the same mask; broadcast
        // ionosphere and Saastamoinen troposphere are rnx2rtkp's defaults.
        let o = std::process::Command::new(&rtklib)
            .args(["-p", "0", "-e", "-sys", "G", "-m", MASK_DEG, "-o"])
            .arg(&pos)
            .arg(&obs)
            .arg(&nav)
            .output()
            .unwrap();
        assert!(o.status.success(), "rnx2rtkp: {}", String::from_utf8_lossy(&o.stderr));
        let theirs: Vec<[f64; 3]> = std::fs::read_to_string(&pos)
            .unwrap()
            .lines()
            .filter(|l| !l.starts_with('%'))
            .map(|l| {
                let f: Vec<f64> = l.split_whitespace().take(5).map(|x| x.parse().unwrap()).collect();
                [f[2], f[3], f[4]]
            })
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
