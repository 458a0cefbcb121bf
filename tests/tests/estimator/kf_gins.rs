//! Data exchange with KF-GINS: the checked-in simulator recording is written out in KF-GINS's
//! text formats by this test (IMU increments, GNSS positions, reference trajectory), imported
//! with `navsync import kf-gins`, processed by `navsync replay --estimate --format kf-gins`
//! into KF-GINS's result files, and evaluated with `navsync eval` against the truth file and
//! against the recording itself.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use navsync_recording::SampleReader;
use navsync_shared::samples::{AnySample, GnssFix, ImuSample, SimTruth};
use navsync_shared::time::gps_ns_from_utc_ns;
use navsync_tests::TestEnv;
use serde_json::Value;

const WEEK_NS: i64 = 604_800_000_000_000;

fn data_file() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/record_drive.mcap")
}

fn read(path: &Path) -> Vec<(String, AnySample)> {
    let mut r = SampleReader::open(path).unwrap();
    let mut out = Vec::new();
    while let Some(s) = r.next_sample().unwrap() {
        out.push((s.service.to_string(), s.sample));
    }
    out
}

/// Host time → UTC by the truth (linear between truth samples).
fn utc_of(truth: &[SimTruth], host_ns: i64) -> i64 {
    let i = truth
        .partition_point(|t| t.host_ns <= host_ns)
        .clamp(1, truth.len() - 1);
    let (a, b) = (&truth[i - 1], &truth[i]);
    let w = (host_ns - a.host_ns) as f64 / (b.host_ns - a.host_ns) as f64;
    a.utc_ns + ((b.utc_ns - a.utc_ns) as f64 * w).round() as i64
}

fn sow(utc_ns: i64) -> (i64, f64) {
    let g = gps_ns_from_utc_ns(utc_ns);
    (g.div_euclid(WEEK_NS), g.rem_euclid(WEEK_NS) as f64 * 1e-9)
}

fn run_ok(env: &TestEnv, args: &[&str]) -> (String, String) {
    let o = env.command(args).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(o.status.success(), "navsync {args:?}: {}\n{err}", o.status);
    (String::from_utf8_lossy(&o.stdout).to_string(), err)
}

fn columns(path: &Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| l.split_whitespace().map(|x| x.parse().unwrap()).collect())
        .collect()
}

#[test]
fn kf_gins_files_round_trip_through_import_estimate_and_eval() {
    let env = TestEnv::new("kfgins");
    let samples = read(&data_file());
    let truth: Vec<SimTruth> = samples
        .iter()
        .filter_map(|(_, s)| if let AnySample::Truth(t) = s { Some(*t) } else { None })
        .collect();
    let imu: Vec<ImuSample> = samples
        .iter()
        .filter_map(|(_, s)| if let AnySample::Imu(x) = s { Some(*x) } else { None })
        .collect();
    let fixes: Vec<GnssFix> = samples
        .iter()
        .filter_map(|(_, s)| match s {
            AnySample::GnssFix(f) if f.has_position() => Some(*f),
            _ => None,
        })
        .collect();

    // KF-GINS files, written by this test.
    let (mut imu_txt, mut gnss_txt, mut truth_txt) = (String::new(), String::new(), String::new());
    let mut tags = Vec::with_capacity(imu.len());
    for s in &imu {
        let (_, t) = sow(utc_of(&truth, s.stamp.host_ns));
        tags.push(format!("{t:.6}").parse::<f64>().unwrap());
        let d = s.dt_s;
        let _ = writeln!(
            imu_txt,
            "{t:.6} {} {} {} {} {} {}",
            s.gyro_rps[0] * d,
            s.gyro_rps[1] * d,
            s.gyro_rps[2] * d,
            s.accel_mps2[0] * d,
            s.accel_mps2[1] * d,
            s.accel_mps2[2] * d
        );
    }
    for f in &fixes {
        let t = f.gps_ns.rem_euclid(WEEK_NS) as f64 * 1e-9;
        let std = |x: f64| if x.is_finite() { x } else { 1.5 };
        let _ = writeln!(
            gnss_txt,
            "{t:.3}, {:.10}, {:.10}, {:.4}, {:.3}, {:.3}, {:.3}",
            f.lat_deg,
            f.lon_deg,
            f.height_m(),
            std(f.std_lat_m),
            std(f.std_lon_m),
            std(f.std_alt_m)
        );
    }
    let mut week = 0;
    for t in &truth {
        let (w, s) = sow(t.utc_ns);
        week = w;
        let [r, p, y] = t.rpy_rad.map(f64::to_degrees);
        let _ = writeln!(
            truth_txt,
            "{w} {s:.6} {:.12} {:.12} {:.6} {} {} {} {r} {p} {y}",
            t.lat_deg, t.lon_deg, t.height_m, t.vel_ned_mps[0], t.vel_ned_mps[1], t.vel_ned_mps[2]
        );
    }
    let dir = &env.dir;
    let (imu_p, gnss_p, truth_p) = (dir.join("IMU.txt"), dir.join("GNSS.pos"), dir.join("truth.nav"));
    std::fs::write(&imu_p, imu_txt).unwrap();
    std::fs::write(&gnss_p, gnss_txt).unwrap();
    std::fs::write(&truth_p, truth_txt).unwrap();
    let s = |p: &Path| p.display().to_string();

    // Import.
    let rec = dir.join("imported.mcap");
    let (_, err) = run_ok(
        &env,
        &[
            "import",
            "kf-gins",
            "--imu",
            &s(&imu_p),
            "--gnss",
            &s(&gnss_p),
            "--truth",
            &s(&truth_p),
            "--imu-rate",
            "100",
            "-o",
            &s(&rec),
        ],
    );
    println!("{err}");
    let imported = read(&rec);
    let mut counts: BTreeMap<&str, usize> = BTreeMap::new();
    for (svc, _) in &imported {
        *counts.entry(svc.as_str()).or_default() += 1;
    }
    assert_eq!(counts["navsync/imu/0/sample"], imu.len(), "{counts:?}");
    assert_eq!(counts["navsync/gnss/0/fix"], fixes.len());
    assert_eq!(counts["navsync/sim/truth"], truth.len());
    let pps = counts["navsync/pps/0/edge"];
    assert!((25..=30).contains(&pps), "{pps} PPS edges for a 28 s file");
    assert!(err.contains(&format!("GPS week {week}")), "{err}");
    // The increments survive: rate · dt = the file's increment.
    let back: Vec<ImuSample> = imported
        .iter()
        .filter_map(|(_, s)| if let AnySample::Imu(x) = s { Some(*x) } else { None })
        .collect();
    for (i, (a, b)) in imu.iter().zip(&back).enumerate().skip(1) {
        for k in 0..3 {
            let (x, y) = (a.gyro_rps[k] * a.dt_s, b.gyro_rps[k] * b.dt_s);
            assert!((x - y).abs() <= 1e-15 + 1e-12 * x.abs(), "dθ {x} → {y}");
            let (x, y) = (a.accel_mps2[k] * a.dt_s, b.accel_mps2[k] * b.dt_s);
            assert!((x - y).abs() <= 1e-15 + 1e-12 * x.abs(), "dv {x} → {y}");
        }
        // dt is the difference of the time tags (the recording's host stamps carry the
        // simulated stamp jitter, so it is not exactly 1/rate).
        let tag_dt = tags[i] - tags[i - 1];
        assert!((b.dt_s - tag_dt).abs() < 1e-9, "dt {} vs tags {tag_dt}", b.dt_s);
    }
    // Fixes keep position and time, and get a velocity from the positions.
    let fix_back: Vec<GnssFix> = imported
        .iter()
        .filter_map(|(_, s)| if let AnySample::GnssFix(f) = s { Some(*f) } else { None })
        .collect();
    let mut speed_err = Vec::new();
    for (a, b) in fixes.iter().zip(&fix_back) {
        assert_eq!(a.gps_ns, b.gps_ns);
        assert!((a.lat_deg - b.lat_deg).abs() < 1e-9 && (a.lon_deg - b.lon_deg).abs() < 1e-9);
        assert!((a.height_m() - b.height_m()).abs() < 1e-3);
        if a.speed_mps.is_finite() && a.speed_mps > 3.0 {
            // Central differences of noisy positions (σ ≈ 0.5 m over 2 s: ≈ 0.35 m/s per axis).
            assert!(
                (a.speed_mps - b.speed_mps).abs() < 2.0,
                "speed {} vs {}",
                a.speed_mps,
                b.speed_mps
            );
            speed_err.push(a.speed_mps - b.speed_mps);
        }
    }
    let rms = (speed_err.iter().map(|e| e * e).sum::<f64>() / speed_err.len() as f64).sqrt();
    println!(
        "speed from central differences vs the receiver's: RMS {rms:.3} m/s over {} fixes",
        speed_err.len()
    );
    assert!(speed_err.len() > 10 && rms < 0.7, "RMS {rms} m/s");

    // The estimator over the import, written in KF-GINS's result layout.
    let out = dir.join("result/");
    let summary = dir.join("summary.json");
    let (table, _) = run_ok(
        &env,
        &[
            "replay",
            &s(&rec),
            "--estimate",
            "--format",
            "kf-gins",
            "--out",
            &s(&out),
            "--summary-json",
            &s(&summary),
            // The velocities are central differences of the positions (measured above).
            "--gnss-vel-std",
            "0.6",
            // The simulator's IMU (a MEMS one would need more of the short drive's motion
            // before its heading is known).
            "--imu-model",
            "industrial",
        ],
    );
    println!("replay --estimate over the import:\n{table}");
    let sum: Value = serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    let rms_import = sum["pos_rms_m"].as_f64().expect("compared against the imported truth");
    assert!(rms_import < 3.0, "{sum}");
    let nav = columns(&out.join("KF_GINS_Navresult.nav"));
    assert!(nav.len() > 1000, "{} rows", nav.len());
    assert!(nav.iter().all(|r| r.len() == 11));
    assert!(nav.windows(2).all(|w| w[1][1] > w[0][1]), "seconds of week increase");
    assert_eq!(nav[0][0], week as f64);
    assert!(columns(&out.join("KF_GINS_IMU_ERR.txt")).iter().all(|r| r.len() == 13));
    assert!(columns(&out.join("KF_GINS_STD.txt")).iter().all(|r| r.len() == 22));
    let first_line = std::fs::read_to_string(out.join("KF_GINS_Navresult.nav")).unwrap();
    let first_line = first_line.lines().next().unwrap();
    assert!(first_line.ends_with(' '), "%-15.9lf columns end with a space");
    assert!(
        first_line
            .split_whitespace()
            .all(|c| c.split('.').nth(1).is_some_and(|d| d.len() == 9))
    );

    // eval: the result against the truth file.
    let (js, _) = run_ok(
        &env,
        &[
            "eval",
            "--truth",
            &s(&truth_p),
            "--solution",
            &s(&out.join("KF_GINS_Navresult.nav")),
            "--json",
        ],
    );
    let ev: Value = serde_json::from_str(&js).unwrap();
    let h = ev["horizontal_m"]["rms"].as_f64().unwrap();
    println!(
        "eval (KF-GINS files): horizontal RMS {h:.3} m over {} points",
        ev["compared"]
    );
    assert!(ev["compared"].as_u64().unwrap() > 1000, "{ev}");
    // The summary compares each state with the truth at its IMU sample's time, eval at the
    // state's label, which carries the Δ correction (the IMU stamps' offset from GNSS time):
    // they differ by at most |Δ̂| times the speed.
    let v_max = columns(&truth_p).iter().map(|r| r[5].hypot(r[6])).fold(0.0, f64::max);
    let shift_m = sum["gnss_delay_est_s"].as_f64().unwrap_or(0.0).abs() * v_max;
    assert!(
        (h - rms_import).abs() < 0.05 + 0.1 * rms_import + shift_m,
        "eval {h} vs replay summary {rms_import} (labels shifted by Δ: up to {shift_m:.3} m)"
    );
    // Heading is initialised from the course of position-differenced velocities (σ ≈ 0.6 m/s at
    // ~10 m/s: ≈ 3.5° 1σ) and has 17 s of driving to settle in this short file.
    assert!(ev["att_deg"][2]["rms"].as_f64().unwrap() < 10.0, "{ev}");
    // KF-GINS writes week 0: seconds of week alone line the files up.
    let week0: String = std::fs::read_to_string(out.join("KF_GINS_Navresult.nav"))
        .unwrap()
        .lines()
        .map(|l| format!("0 {}\n", l.split_once(' ').unwrap().1))
        .collect();
    let week0_p = dir.join("week0.nav");
    std::fs::write(&week0_p, week0).unwrap();
    let (js0, _) = run_ok(
        &env,
        &["eval", "--truth", &s(&truth_p), "--solution", &s(&week0_p), "--json"],
    );
    let ev0: Value = serde_json::from_str(&js0).unwrap();
    assert_eq!(ev0["compared"], ev["compared"]);

    // eval on navsync recordings: the original recording's truth against `replay --estimate --out`.
    let nav_mcap = dir.join("nav.mcap");
    let summary2 = dir.join("summary2.json");
    run_ok(
        &env,
        &[
            "replay",
            &s(&data_file()),
            "--estimate",
            "--out",
            &s(&nav_mcap),
            "--summary-json",
            &s(&summary2),
        ],
    );
    let sum2: Value = serde_json::from_str(&std::fs::read_to_string(&summary2).unwrap()).unwrap();
    let (text, _) = run_ok(
        &env,
        &["eval", "--truth", &s(&data_file()), "--solution", &s(&nav_mcap)],
    );
    println!("{text}");
    let (js2, _) = run_ok(
        &env,
        &[
            "eval",
            "--truth",
            &s(&data_file()),
            "--solution",
            &s(&nav_mcap),
            "--json",
        ],
    );
    let ev2: Value = serde_json::from_str(&js2).unwrap();
    let (a, b) = (
        ev2["horizontal_m"]["rms"].as_f64().unwrap(),
        sum2["pos_rms_m"].as_f64().unwrap(),
    );
    assert!(
        (a - b).abs() < 0.02 + 0.05 * b,
        "eval {a} vs the estimator's own evaluation {b}"
    );
    // Mixed: the KF-GINS truth file against the navsync recording.
    let (js3, _) = run_ok(
        &env,
        &["eval", "--truth", &s(&truth_p), "--solution", &s(&nav_mcap), "--json"],
    );
    let ev3: Value = serde_json::from_str(&js3).unwrap();
    assert!((ev3["horizontal_m"]["rms"].as_f64().unwrap() - a).abs() < 0.01, "{ev3}");

    // Known errors come out exactly: the truth shifted 2 m north, 0.3 m/s east, 0.5° in yaw.
    let rm = 6_366_000.0; // metres per radian of latitude near 48° N (±0.2 %)
    let shifted: String = std::fs::read_to_string(&truth_p)
        .unwrap()
        .lines()
        .map(|l| {
            let mut v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            v[2] += (2.0f64 / rm).to_degrees();
            v[6] += 0.3;
            v[10] += 0.5;
            v.iter().map(|x| format!("{x:.12}")).collect::<Vec<_>>().join(" ") + "\n"
        })
        .collect();
    let shifted_p = dir.join("shifted.nav");
    std::fs::write(&shifted_p, shifted).unwrap();
    let (js4, _) = run_ok(
        &env,
        &["eval", "--truth", &s(&truth_p), "--solution", &s(&shifted_p), "--json"],
    );
    let ev4: Value = serde_json::from_str(&js4).unwrap();
    assert!(
        (ev4["pos_ned_m"][0]["mean"].as_f64().unwrap() - 2.0).abs() < 0.01,
        "{ev4}"
    );
    assert!(ev4["pos_ned_m"][1]["rms"].as_f64().unwrap() < 1e-3, "{ev4}");
    assert!(
        (ev4["vel_ned_mps"][1]["mean"].as_f64().unwrap() - 0.3).abs() < 1e-6,
        "{ev4}"
    );
    assert!(
        (ev4["att_deg"][2]["mean"].as_f64().unwrap() - 0.5).abs() < 1e-6,
        "{ev4}"
    );

    // A malformed file is reported with its line.
    std::fs::write(dir.join("bad.pos"), "456250.0 30.1 114.2 21.0 0.01 0.01\n").unwrap();
    let o = env
        .command(&[
            "import",
            "kf-gins",
            "--imu",
            &s(&imu_p),
            "--gnss",
            &s(&dir.join("bad.pos")),
            "-o",
            &s(&dir.join("x.mcap")),
        ])
        .output()
        .unwrap();
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("bad.pos:1: 6 columns, expected 7 or 13"), "{e}");
    env.finish();
}
