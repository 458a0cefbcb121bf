//! `navsync export rinex` on the GEONET stations (`rinex_spp.rs`'s data): import the RINEX 2.10
//! files, export the recording as RINEX 3.05, import the export again, and the single-point
//! solutions are the original import's epoch by epoch; RTKLIB's `rnx2rtkp` reads the export
//! and solves it as it solves the original files (skipped without its binary). And on the
//! walk's u-blox log (`spp_walk.rs`'s data), with its Galileo and BeiDou navigation data: the
//! export's records are RTKLIB's `convbin` records of the same log, and `rnx2rtkp` solves both
//! alike.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use navsync_tests::{TestEnv, shared_material};

use super::rinex_spp::{MASK_DEG, STATIONS, files, rtklib, rtklib_spp, rtklib_spp_systems, run_ok};
use super::spp_walk::{convbin_walk, navsync_spp, rtk_fixed, rtklib_spp as rtklib_walk_spp, rtklib_tools, score};

fn p(x: &Path) -> String {
    x.display().to_string()
}

/// Imports a station and exports the recording: (recording, exported OBS, exported NAV).
fn import_and_export(env: &TestEnv, station: &str) -> (PathBuf, PathBuf, PathBuf) {
    let (obs, nav) = files(station);
    let rec = env.dir.join(format!("{station}.mcap"));
    let (xo, xn) = (
        env.dir.join(format!("{station}.obs")),
        env.dir.join(format!("{station}.nav")),
    );
    run_ok(env, &["import", "rinex", &p(&obs), &p(&nav), "--out", &p(&rec)]);
    run_ok(env, &["export", "rinex", &p(&rec), "--obs", &p(&xo), "--nav", &p(&xn)]);
    (rec, xo, xn)
}

/// `navsync spp` of a recording: per solved epoch, (week, seconds of week, ECEF m).
fn spp(env: &TestEnv, rec: &Path) -> Vec<(u32, f64, [f64; 3])> {
    let csv = rec.with_extension("csv");
    run_ok(
        env,
        &[
            "spp",
            &p(rec),
            "--out",
            &p(&csv),
            "--elevation-mask-deg",
            MASK_DEG,
            "--force",
        ],
    );
    std::fs::read_to_string(&csv)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let x = |k: usize| f[k].parse::<f64>().unwrap();
            (f[0].parse().unwrap(), x(1), [x(2), x(3), x(4)])
        })
        .collect()
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

#[test]
fn geonet_export_imports_back_to_the_same_solutions() {
    let env = TestEnv::new("rinexexp");
    for (station, _) in STATIONS {
        let (rec, xo, xn) = import_and_export(&env, station);
        let text = std::fs::read_to_string(&xo).unwrap();
        assert!(
            text.starts_with("     3.05           OBSERVATION DATA    G"),
            "{station}"
        );
        assert!(
            text.contains("G    4 C1C L1C C2W L2W"),
            "{station}: GPS L1 C/A and L2 P(Y) code and phase"
        );
        let nav = std::fs::read_to_string(&xn).unwrap();
        assert!(
            nav.starts_with("     3.05           N: GNSS NAV DATA    G"),
            "{station}"
        );
        assert!(
            nav.contains("GPSA ") && nav.contains("GPSB "),
            "{station}: no ionosphere"
        );

        let again = env.dir.join(format!("{station}-again.mcap"));
        run_ok(&env, &["import", "rinex", &p(&xo), &p(&xn), "--out", &p(&again)]);
        let (first, second) = (spp(&env, &rec), spp(&env, &again));
        assert!(first.len() > 100, "{station}: {} solutions", first.len());
        assert_eq!(first.len(), second.len(), "{station}: solved epochs differ");
        let mut worst = 0.0f64;
        for (a, b) in first.iter().zip(&second) {
            assert_eq!((a.0, a.1), (b.0, b.1), "{station}: epochs differ");
            worst = worst.max(distance(a.2, b.2));
        }
        eprintln!(
            "{station}: import → export → import: {} epochs, largest SPP difference {worst:.2e} m",
            first.len()
        );
        assert!(worst <= 1e-3, "{station}: {worst} m");

        // An existing file is replaced only with --force.
        let o = env
            .command(&["export", "rinex", &p(&rec), "--obs", &p(&xo), "--nav", &p(&xn)])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains("--force"), "{err}");
        run_ok(
            &env,
            &[
                "export",
                "rinex",
                &p(&rec),
                "--obs",
                &p(&xo),
                "--nav",
                &p(&xn),
                "--force",
            ],
        );
    }
}

#[test]
fn rtklib_solves_the_export_as_the_original_files() {
    let Some(rnx2rtkp) = rtklib("rnx2rtkp", "NAVSYNC_RNX2RTKP") else {
        return;
    };
    let env = TestEnv::new("rinexexprtk");
    for (station, _) in STATIONS {
        let (obs, nav) = files(station);
        let (_, xo, xn) = import_and_export(&env, station);
        let original = rtklib_spp(&rnx2rtkp, &obs, &nav, &env.dir.join(format!("{station}-orig.pos")));
        let exported = rtklib_spp(&rnx2rtkp, &xo, &xn, &env.dir.join(format!("{station}-export.pos")));
        assert!(
            original.len() > 100,
            "{station}: RTKLIB solved {} epochs",
            original.len()
        );
        assert_eq!(
            original.len(),
            exported.len(),
            "{station}: RTKLIB solved different epochs"
        );
        let mut worst = 0.0f64;
        for (a, b) in original.iter().zip(&exported) {
            assert_eq!(a.0, b.0, "{station}: epochs differ");
            worst = worst.max(distance(a.1, b.1));
        }
        eprintln!(
            "{station}: RTKLIB on the export vs the RINEX 2.10 files: {} epochs, largest difference {worst:.4} m",
            original.len()
        );
        assert!(worst <= 0.1, "{station}: {worst} m");
    }
}

/// The Galileo and BeiDou records of a RINEX 3 navigation file by (satellite, t_oe, the
/// fifth orbit line's second field: Galileo's data sources): the clock line's three values and
/// the orbit lines' values, in order.
fn kepler_records(text: &str) -> HashMap<(String, u64, u64), Vec<f64>> {
    let body = text.split_once("END OF HEADER").unwrap().1;
    let lines: Vec<&str> = body.lines().skip(1).collect();
    let value = |l: &str, k: usize| -> Option<f64> {
        let f = l.get(k..(k + 19).min(l.len()))?.trim().replace('D', "E");
        (!f.is_empty()).then(|| f.parse().unwrap())
    };
    let mut out = HashMap::new();
    let mut i = 0;
    while i < lines.len() {
        let l = lines[i];
        // GLONASS and SBAS records have 3 orbit lines (GLONASS in 3.05: 4), the others 7.
        let n = match l.chars().next() {
            Some('R') if lines.get(i + 4).is_some_and(|x| x.starts_with(' ')) => 5,
            Some('R' | 'S') => 4,
            _ => 8,
        };
        if l.starts_with('E') || l.starts_with('C') {
            let mut v: Vec<f64> = (0..3).filter_map(|k| value(l, 23 + 19 * k)).collect();
            for o in &lines[i + 1..i + n] {
                v.extend((0..4).filter_map(|k| value(o, 4 + 19 * k)));
            }
            out.insert((l[..3].to_string(), v[11] as u64, v[20] as u64), v);
        }
        i += n;
    }
    out
}

/// The walk's u-blox log through `import ubx` and `export rinex`, against RTKLIB's `convbin` of
/// the same log: every Galileo (I/NAV, F/NAV) and BeiDou record `convbin` writes is in the
/// export with the same clock and orbit to the 12 digits `convbin` prints (the decoders are
/// independent: navsync's `gnss::{galileo, fnav, beidou}` and RTKLIB's `rcvraw.c`), and
/// `rnx2rtkp` solves both file pairs to the same positions with G,E,C (measured ≤ 1 mm on all
/// 536 epochs; the export's ionosphere header, which `convbin` has none of, left out for it).
/// Two fields differ by convention and are not compared: BeiDou's AODE (RTKLIB writes its own
/// issue number from t_oe) and the transmission time.
#[test]
fn walk_export_has_convbins_galileo_and_beidou_records() {
    let Some((convbin, rnx2rtkp)) = rtklib_tools() else {
        return;
    };
    let env = TestEnv::new("rinexexpwalk");
    let walk = shared_material("datasets/rtklibexplorer-walk0827");
    let log = walk.join("source/gnss_1730.ubx");
    let rec = env.dir.join("walk.mcap");
    let (xo, xn) = (env.dir.join("export.obs"), env.dir.join("export.nav"));
    let (co, cn) = (env.dir.join("convbin.obs"), env.dir.join("convbin.nav"));
    run_ok(
        &env,
        &[
            "import",
            "ubx",
            &p(&log),
            "--imu",
            &p(&walk.join("imu.txt")),
            "--out",
            &p(&rec),
        ],
    );
    run_ok(&env, &["export", "rinex", &p(&rec), "--obs", &p(&xo), "--nav", &p(&xn)]);
    convbin_walk(&convbin, "3.05", &co, &cn);
    let ours = kepler_records(&std::fs::read_to_string(&xn).unwrap());
    let theirs = kepler_records(&std::fs::read_to_string(&cn).unwrap());
    let count = |m: &HashMap<(String, u64, u64), Vec<f64>>, c: char| m.keys().filter(|k| k.0.starts_with(c)).count();
    eprintln!(
        "walk: export {} Galileo and {} BeiDou records, convbin {} and {}",
        count(&ours, 'E'),
        count(&ours, 'C'),
        count(&theirs, 'E'),
        count(&theirs, 'C')
    );
    assert!(count(&theirs, 'E') >= 10 && count(&theirs, 'C') >= 5);
    for (key, want) in &theirs {
        let got = ours.get(key).unwrap_or_else(|| panic!("{key:?} not in the export"));
        assert_eq!(got.len(), want.len(), "{key:?}");
        let aode = key.0.starts_with('C').then_some(3);
        for (k, (a, b)) in got.iter().zip(want).enumerate() {
            if Some(k) == aode || k == 27 {
                continue;
            }
            assert!(
                (a - b).abs() <= 5e-12 * b.abs().max(1e-30),
                "{key:?} field {k}: {a:e} vs convbin's {b:e}"
            );
        }
    }
    // The export's header has the log's Klobuchar α/β (GPS CNAV's, BeiDou D1's), which
    // `convbin` does not write: left out here, so that RTKLIB gets the same inputs.
    let text = std::fs::read_to_string(&xn).unwrap();
    let iono: Vec<&str> = text.lines().filter(|l| l.ends_with("IONOSPHERIC CORR")).collect();
    assert_eq!(
        iono.iter().map(|l| &l[..4]).collect::<Vec<_>>(),
        ["GPSA", "GPSB", "BDSA", "BDSB"]
    );
    let xn_plain = env.dir.join("export-no-iono.nav");
    let plain: Vec<&str> = text.lines().filter(|l| !l.ends_with("IONOSPHERIC CORR")).collect();
    std::fs::write(&xn_plain, plain.join("\n") + "\n").unwrap();
    for systems in ["G,E,C", "E"] {
        let tag = systems.replace(',', "");
        let a = rtklib_spp_systems(&rnx2rtkp, &co, &cn, &env.dir.join(format!("c{tag}.pos")), systems);
        let b = rtklib_spp_systems(&rnx2rtkp, &xo, &xn_plain, &env.dir.join(format!("x{tag}.pos")), systems);
        assert!(a.len() > 500, "{systems}: RTKLIB solved {} epochs", a.len());
        assert_eq!(a.len(), b.len(), "{systems}: RTKLIB solved different epochs");
        let worst = a
            .iter()
            .zip(&b)
            .map(|(x, y)| {
                assert_eq!(x.0, y.0, "{systems}: epochs differ");
                distance(x.1, y.1)
            })
            .fold(0.0, f64::max);
        eprintln!(
            "walk -sys {systems}: RTKLIB on the export vs on convbin's files: {} epochs, largest difference {worst:.4} m",
            a.len()
        );
        assert!(worst <= 0.01, "{systems}: {worst} m");
    }
}

/// RTKLIB's `convbin` RINEX of the walk through `import rinex`: its Galileo I/NAV and F/NAV
/// and BeiDou records become navigation words (`galileo::encode_word`, `fnav::encode_page`,
/// `beidou::encode_d1`) that the estimator's decoders read back; `export rinex` of the import
/// writes every one of them again with the same clock and orbit to the 12 digits `convbin`
/// prints (BeiDou's AODE mod 32, as its 5-bit field holds it; RTKLIB writes its own issue
/// number there; the transmission time aside), and `navsync spp` of the import uses GPS,
/// Galileo and BeiDou at every epoch, its horizontal RMS at the RTK-fixed epochs no worse than
/// RTKLIB's `rnx2rtkp -sys G,E,C` on the same files (measured 8.24 against 8.29 m).
#[test]
fn walk_rinex_import_reads_convbins_galileo_and_beidou_records() {
    let Some((convbin, rnx2rtkp)) = rtklib_tools() else {
        return;
    };
    let env = TestEnv::new("rinexwalkimp");
    let (co, cn) = (env.dir.join("convbin.obs"), env.dir.join("convbin.nav"));
    convbin_walk(&convbin, "3.05", &co, &cn);
    let rec = env.dir.join("imported.mcap");
    let (xo, xn) = (env.dir.join("again.obs"), env.dir.join("again.nav"));
    run_ok(&env, &["import", "rinex", &p(&co), &p(&cn), "--out", &p(&rec)]);
    run_ok(&env, &["export", "rinex", &p(&rec), "--obs", &p(&xo), "--nav", &p(&xn)]);
    let theirs = kepler_records(&std::fs::read_to_string(&cn).unwrap());
    let again = kepler_records(&std::fs::read_to_string(&xn).unwrap());
    let mut compared = 0;
    for (key, want) in &theirs {
        let got = again.get(key).unwrap_or_else(|| panic!("{key:?} not read back"));
        for (k, (a, b)) in got.iter().zip(want).enumerate() {
            match (key.0.starts_with('C'), k) {
                (_, 27) => {}
                (true, 3) => assert_eq!(*a as u64, *b as u64 % 32, "{key:?} AODE"),
                _ => assert!(
                    (a - b).abs() <= 5e-12 * b.abs().max(1e-30),
                    "{key:?} field {k}: {a:e} vs convbin's {b:e}"
                ),
            }
        }
        compared += 1;
    }
    eprintln!(
        "walk: {compared} of convbin's Galileo (I/NAV, F/NAV) and BeiDou records read back through import and export"
    );
    assert!(
        compared >= 10 && again.len() == compared,
        "{compared} compared, {} exported",
        again.len()
    );
    let (ours, used, summary) = navsync_spp(&env, &rec, "G,E,C");
    assert!(
        used.iter().all(|u| u.iter().all(|&n| n > 0)),
        "an epoch without one of the systems"
    );
    assert_eq!(summary["solved"].as_u64(), Some(536), "{summary}");
    let fixed = rtk_fixed();
    let theirs = rtklib_walk_spp(&rnx2rtkp, &co, &cn, &env.dir.join("rtk.pos"), "G,E,C");
    let ((h, n), (rh, rn)) = (score(&ours, &fixed, None), score(&theirs, &fixed, None));
    eprintln!("walk through convbin's RINEX: navsync {h:.3} m ({n}), RTKLIB {rh:.3} m ({rn}) at the RTK-fixed epochs");
    assert!(
        n == rn && h <= rh,
        "navsync {h:.3} m ({n}) against RTKLIB's {rh:.3} m ({rn})"
    );
}

/// Bad requests are errors that say what is wrong, with nothing written: a file that is not a
/// recording, an output that is the input, one file for both outputs, a receiver id without raw
/// data.
#[test]
fn export_refusals_say_why_and_write_nothing() {
    let env = TestEnv::new("rinexexperr");
    let (rec, xo, _) = import_and_export(&env, STATIONS[0].0);
    let (o2, n2) = (env.dir.join("2.obs"), env.dir.join("2.nav"));
    for (args, says) in [
        (
            vec![p(&xo), "--obs".into(), p(&o2), "--nav".into(), p(&n2)],
            "not an MCAP file",
        ),
        (
            vec![
                p(&rec),
                "--obs".into(),
                p(&rec),
                "--nav".into(),
                p(&n2),
                "--force".into(),
            ],
            "same file as the input",
        ),
        (
            vec![p(&rec), "--obs".into(), p(&o2), "--nav".into(), p(&o2)],
            "the same file",
        ),
        (
            vec![
                p(&rec),
                "--obs".into(),
                p(&o2),
                "--nav".into(),
                p(&n2),
                "--gnss-id".into(),
                "7".into(),
            ],
            "no observation epoch",
        ),
    ] {
        let mut all = vec!["export", "rinex"];
        all.extend(args.iter().map(String::as_str));
        let o = env.command(&all).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{all:?}: {err}");
        assert!(err.contains(says) && !err.contains("panicked"), "{all:?}: {err}");
        assert!(!o2.exists() && !n2.exists(), "{all:?} wrote a file");
    }
    assert!(navsync_recording::output::is_recording(&rec), "the input was kept");
}
