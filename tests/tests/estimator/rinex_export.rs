//! `navsync export rinex` on the GEONET stations (`rinex_spp.rs`'s data): import the RINEX 2.10
//! files, export the recording as RINEX 3.05, import the export again, and the single-point
//! solutions are the original import's epoch by epoch; RTKLIB's `rnx2rtkp` reads the export
//! and solves it as it solves the original files (skipped without its binary).

use std::path::{Path, PathBuf};

use navsync_tests::TestEnv;

use super::rinex_spp::{MASK_DEG, STATIONS, files, rtklib, rtklib_spp, run_ok};

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
        assert!(text.contains("G    2 C1C L1C"), "{station}: GPS L1 C/A code and phase");
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
