//! The pose at any instant on data navsync did not generate (issue 39): a drive of the
//! independent generator (`tests/python/independent_drive.py`, KF-GINS formats, exact
//! kinematics) imported and replayed (`navsync replay --estimate --fused --out`), its delayed filter's
//! states (`navsync/nav/fused`) and real-time states (`navsync/nav/state`) interpolated at
//! random instants with the history's own rule and formulas (`navsync_wire::interpolation`, as
//! `History::state_at` answers), each against the generator's truth at that instant
//! (`truth.nav`, 200 Hz, interpolated the same way).

use std::path::{Path, PathBuf};
use std::process::Command;

use navsync_recording::SampleReader;
use navsync_shared::earth;
use navsync_shared::history::{Interpolated, Record, Source, at_utc, bracket_index};
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::{AnySample, NavState, NavStatus};
use navsync_shared::services;
use navsync_shared::time::{NS_PER_S, SECONDS_PER_WEEK, gps_ns_from_utc_ns, utc_ns_from_gps_ns};
use navsync_tests::{TestEnv, python_with};

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Body→NED quaternion [w, x, y, z] of ZYX roll, pitch, yaw (rad).
fn quaternion(rpy: [f64; 3]) -> [f64; 4] {
    let [r, p, y] = rpy.map(|a| a / 2.0);
    let (sr, cr, sp, cp, sy, cy) = (r.sin(), r.cos(), p.sin(), p.cos(), y.sin(), y.cos());
    [
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ]
}

/// The truth file's rows (week, seconds of week, lat, lon, h, v NED, roll, pitch, yaw in
/// degrees) as records on the UTC axis of GPS week `week` (KF-GINS's IMU file has seconds of
/// week only: the import's week is the states'), host time = UTC (only their order and spacing
/// matter).
fn truth_records(path: &Path, week: i64) -> Vec<Record> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter_map(|l| {
            let v: Vec<f64> = l.split_whitespace().filter_map(|x| x.parse().ok()).collect();
            (v.len() >= 11).then(|| {
                let gps_ns = (week * SECONDS_PER_WEEK) * NS_PER_S + (v[1] * 1e9).round() as i64;
                let mut s = NavState::zeroed();
                s.utc_ns = utc_ns_from_gps_ns(gps_ns);
                s.host_ns = s.utc_ns;
                (s.lat_deg, s.lon_deg, s.height_m) = (v[2], v[3], v[4]);
                s.vel_ned_mps = [v[5], v[6], v[7]];
                s.q_nb = quaternion([v[8].to_radians(), v[9].to_radians(), v[10].to_radians()]);
                Record::of(&s, Source::Predicted)
            })
        })
        .collect()
}

/// The value at UTC `t` of a sequence of records in time order, as the history answers it.
fn at(records: &[Record], t: i64) -> Option<Interpolated> {
    let (a, b) = bracket_index(records.len(), |k| records[k].utc_ns, t)?;
    Some(at_utc(&records[a], &records[b], t))
}

/// NED error of `x` against `truth`, m.
fn error_ned(truth: &Interpolated, x: &Interpolated) -> [f64; 3] {
    earth::ned_between(
        truth.pose.lat_deg.to_radians(),
        truth.pose.lon_deg.to_radians(),
        truth.pose.height_m,
        x.pose.lat_deg.to_radians(),
        x.pose.lon_deg.to_radians(),
        x.pose.height_m,
    )
}

#[test]
fn poses_between_states_on_an_independent_drive_against_its_truth() {
    let env = TestEnv::new("histgen");
    let (py, target) = python_with(&env.dir, &["numpy"])
        .unwrap_or_else(|why| panic!("cannot install numpy (needs python3, pip and PyPI or a wheel): {why}"));
    let drive = env.dir.join("drive");
    let mut cmd = Command::new(&py);
    cmd.arg(repo_root().join("tests/python/independent_drive.py"))
        .arg(&drive)
        .args(["--duration", "240", "--static", "60", "--seed", "7"]);
    if let Some(t) = &target {
        cmd.env("PYTHONPATH", t);
    }
    let o = cmd.output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rec = env.dir.join("drive.mcap");
    let o = env
        .command(&["import", "kf-gins", "--imu"])
        .arg(drive.join("imu.txt"))
        .arg("--gnss")
        .arg(drive.join("gnss.pos"))
        .arg("--kf-gins-config")
        .arg(drive.join("kf-gins.yaml"))
        .arg("--out")
        .arg(&rec)
        .output()
        .unwrap();
    assert!(o.status.success(), "import: {}", String::from_utf8_lossy(&o.stderr));
    let out = env.dir.join("out.mcap");
    let o = env
        .command(&["replay"])
        .arg(&rec)
        .args(["--estimate", "--fused", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "replay: {}", String::from_utf8_lossy(&o.stderr));

    let (mut fused, mut predicted) = (Vec::new(), Vec::new());
    let mut r = SampleReader::open(&out).unwrap();
    while let Some(m) = r.next_sample().unwrap() {
        let AnySample::Nav(n) = m.sample else { continue };
        if n.status != NavStatus::Aligned as u8 || n.utc_ns == i64::MIN {
            continue;
        }
        if m.service == services::NAV_FUSED {
            fused.push(Record::of(&n, Source::Fused));
        } else if m.service == services::NAV_STATE {
            predicted.push(Record::of(&n, Source::Predicted));
        }
    }
    let week = gps_ns_from_utc_ns(fused[0].utc_ns) / (SECONDS_PER_WEEK * NS_PER_S);
    let truth = truth_records(&drive.join("truth.nav"), week);
    println!(
        "{} fused and {} predicted aligned states, {} truth rows",
        fused.len(),
        predicted.len(),
        truth.len()
    );
    assert!(fused.len() > 20_000, "{} fused states", fused.len());
    // After the alignment has settled (20 s) until the end of the fused states, inside the
    // truth and the predicted states.
    println!(
        "UTC spans, s: fused {:.3}..{:.3}, predicted {:.3}..{:.3}, truth {:.3}..{:.3}",
        fused[0].utc_ns as f64 * 1e-9,
        fused.last().unwrap().utc_ns as f64 * 1e-9,
        predicted[0].utc_ns as f64 * 1e-9,
        predicted.last().unwrap().utc_ns as f64 * 1e-9,
        truth[0].utc_ns as f64 * 1e-9,
        truth.last().unwrap().utc_ns as f64 * 1e-9
    );
    let span = (
        fused[0].utc_ns.max(predicted[0].utc_ns).max(truth[0].utc_ns) + 20 * NS_PER_S,
        fused
            .last()
            .unwrap()
            .utc_ns
            .min(predicted.last().unwrap().utc_ns)
            .min(truth.last().unwrap().utc_ns),
    );
    assert!(span.1 - span.0 > 100 * NS_PER_S, "{span:?}");

    for (name, states) in [("fused", &fused), ("predicted", &predicted)] {
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        let n = 4000;
        let (mut within1, mut within2, mut within3) = (0usize, 0usize, 0usize);
        let (mut sq_interp, mut sq_nearest) = (0.0f64, 0.0f64);
        let mut worse = 0usize;
        for _ in 0..n {
            x = x
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            let t = span.0 + ((x >> 11) % (span.1 - span.0) as u64) as i64;
            let got = at(states, t).unwrap();
            let want = at(&truth, t).unwrap();
            let e = error_ned(&want, &got);
            let eh = e[0].hypot(e[1]);
            let sh = got.pose.pos_std_ned_m[0].hypot(got.pose.pos_std_ned_m[1]);
            within1 += usize::from(eh <= sh);
            within2 += usize::from(eh <= 2.0 * sh);
            within3 += usize::from(eh <= 3.0 * sh);
            let norm = |v: [f64; 3]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
            sq_interp += norm(e).powi(2);
            // The nearer of the two states, against the truth at its own instant.
            let (a, b) = bracket_index(states.len(), |k| states[k].utc_ns, t).unwrap();
            let near = if got.fraction <= 0.5 { &states[a] } else { &states[b] };
            let own = at(states, near.utc_ns).unwrap();
            let en = error_ned(&at(&truth, near.utc_ns).unwrap(), &own);
            sq_nearest += norm(en).powi(2);
            worse += usize::from(norm(e) > 1.05 * norm(en) + 1e-3);
        }
        let pct = |k: usize| 100.0 * k as f64 / n as f64;
        let (rms_i, rms_n) = ((sq_interp / n as f64).sqrt(), (sq_nearest / n as f64).sqrt());
        println!(
            "{name}: {n} instants over {:.0} s: horizontal error within σ {:.1} %, 2σ {:.1} %, 3σ {:.1} %; 3-D RMS interpolated {rms_i:.4} m, nearest state {rms_n:.4} m (ratio {:.4}); worse than 1.05 × the nearest state's own in {:.1} %",
            (span.1 - span.0) as f64 * 1e-9,
            pct(within1),
            pct(within2),
            pct(within3),
            rms_i / rms_n,
            pct(worse)
        );
        assert!(pct(within2) >= 95.0, "{name}: within 2σ in {:.1} %", pct(within2));
        assert!(
            rms_i <= 1.05 * rms_n,
            "{name}: {rms_i} m against the nearest state's {rms_n} m"
        );
    }
}
