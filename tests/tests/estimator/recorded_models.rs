//! A recording says which IMU and receiver it holds, and the estimator survives a wrong IMU
//! model (issue 15, item 3 and "robust to a wrong model"), through the commands a user types:
//! `navsync sim --fast --record` (the simulator's default IMU is the consumer preset) then
//! `navsync replay --estimate` with the filter's defaults (industrial) and with IMU noise
//! models 10× off.

use std::path::Path;

use navsync_recording::{SampleReader, channels};
use navsync_shared::imu_spec::{ImuNoise, ImuPreset};
use navsync_shared::services;
use navsync_tests::TestEnv;
use serde_json::Value;

fn run_ok(env: &TestEnv, args: &[&str]) -> String {
    let o = env.command(args).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(o.status.success(), "navsync {args:?}: {}\n{err}", o.status);
    String::from_utf8_lossy(&o.stdout).to_string()
}

/// `replay --estimate` with `flags`: (horizontal RMS m, yaw RMS deg, rejected fixes).
fn estimate(env: &TestEnv, rec: &Path, name: &str, flags: &[&str]) -> (f64, f64, u64) {
    let json = env.dir.join(format!("{name}.json"));
    let mut args = vec!["replay", rec.to_str().unwrap(), "--estimate", "--summary-json"];
    args.push(json.to_str().unwrap());
    args.extend_from_slice(flags);
    run_ok(env, &args);
    let s: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert!(s["problem"].is_null(), "{name}: {}", s["problem"]);
    let r = (
        s["pos_rms_m"].as_f64().unwrap(),
        s["att_rms_deg"][2].as_f64().unwrap(),
        s["rejected_fixes"].as_u64().unwrap(),
    );
    println!(
        "{name:40} horizontal RMS {:.3} m, yaw RMS {:.3}°, {} fixes rejected",
        r.0, r.1, r.2
    );
    r
}

/// The consumer preset's noise with the process-noise terms (random walks, bias and scale
/// instabilities) multiplied by `k`, as flags; the turn-on uncertainties are left as they are.
fn scaled_noise_flags(k: f64, only_random_walks: bool) -> Vec<String> {
    let n = ImuPreset::Consumer.noise();
    let mut v = vec![
        format!("--arw={}", n.arw_deg_per_sqrt_h.0[0] * k),
        format!("--vrw={}", n.vrw_mps_per_sqrt_h.0[0] * k),
    ];
    if !only_random_walks {
        v.extend([
            format!("--gyro-bias-std={}", n.gyro_bias_std_deg_per_h.0[0] * k),
            format!("--accel-bias-std={}", n.accel_bias_std_mgal.0[0] * k),
            format!("--gyro-scale-std={}", n.gyro_scale_std_ppm.0[0] * k),
            format!("--accel-scale-std={}", n.accel_scale_std_ppm.0[0] * k),
        ]);
    }
    v
}

#[test]
fn a_simulator_recording_carries_its_imu_model_and_a_wrong_one_does_not_diverge() {
    let env = TestEnv::new("recmodels");
    let rec = env.dir.join("rec.mcap");
    run_ok(&env, &["sim", "--fast", "--record", rec.to_str().unwrap()]);

    // The recording says what it holds: the consumer preset's noise on every IMU channel,
    // the antenna lever arm and the receiver's velocity σ on the fix channel.
    let reader = SampleReader::open(&rec).unwrap();
    let meta = reader.channel_metadata(&services::imu_sample("0"));
    let noise = meta
        .iter()
        .find(|(k, _)| k == channels::META_IMU_NOISE)
        .map(|(_, v)| serde_json::from_str::<ImuNoise>(v).unwrap())
        .expect("IMU noise in the recording");
    assert_eq!(noise, ImuPreset::Consumer.noise());
    let fix_meta = reader.channel_metadata(&services::gnss_fix("0"));
    for key in [channels::META_LEVER_ARM, channels::META_GNSS_VEL_STD] {
        assert!(fix_meta.iter().any(|(k, _)| k == key), "{key} missing: {fix_meta:?}");
    }

    // Replayed with the filter's defaults (industrial), the recording's model is used: the
    // same result as naming it.
    let recorded = estimate(&env, &rec, "recorded model", &[]);
    let named = estimate(&env, &rec, "--imu-model consumer", &["--imu-model", "consumer"]);
    assert_eq!(recorded, named);
    assert!(recorded.0 < 0.6 && recorded.2 <= 3, "{recorded:?}");

    // A wrong model: named explicitly (industrial: 7× smaller turn-on gyro bias), or every
    // process-noise term 10× too large or too small. No divergence; within 2× of the matched
    // run where the model's error is in the noise densities, or with --adapt-noise.
    let (h0, y0, _) = recorded;
    let large = scaled_noise_flags(10.0, false);
    let small_rw = scaled_noise_flags(0.1, true);
    let small = scaled_noise_flags(0.1, false);
    let mut small_adapt = small.clone();
    small_adapt.push("--adapt-noise".into());
    let industrial = vec!["--imu-model".to_string(), "industrial".into()];
    // Where the model's turn-on bias σ is too small (the named industrial model: 7× smaller
    // gyro bias; every term 10× too small) the consumer IMU's biases leave its 6 σ and the
    // integrity monitor widens the model; the error made before that is what these runs cost:
    // measured 0.88° and 5.54° yaw RMS against the matched 0.21° (bounded here at 16× and 30×:
    // no divergence; a tighter detection is open work of issue 34). The second is a 100 s coast
    // of a filter whose every noise term is 10× too small: its heading drifts with the gyro bias
    // it learnt before, 3.06° RMS before the GNSS delay stopped learning from a standing
    // vehicle's velocity noise, 5.54° after (its yaw error within 2σ of the published σ, 15° there).
    // Where only the noise densities are wrong: within 2× (2.5× adapted, measured 0.48°).
    for (name, flags, h_factor, y_factor) in [
        ("--imu-model industrial", &industrial, 2.0, 16.0),
        ("all process noise 10x too large", &large, 2.0, 2.0),
        ("ARW and VRW 10x too small", &small_rw, 2.0, 2.0),
        ("all process noise 10x too small, adapted", &small_adapt, 2.0, 2.5),
        ("all process noise 10x too small", &small, 3.0, 30.0),
    ] {
        let flags: Vec<&str> = flags.iter().map(String::as_str).collect();
        let (h, y, _) = estimate(&env, &rec, name, &flags);
        assert!(
            h <= h_factor * h0,
            "{name}: horizontal RMS {h:.3} m vs matched {h0:.3} m"
        );
        assert!(y <= y_factor * y0, "{name}: yaw RMS {y:.3}° vs matched {y0:.3}°");
    }
}

#[test]
fn a_run_without_usable_states_says_why_and_fails() {
    // The checked-in simulator recording, estimated with a receiver it does not hold: the
    // filter cannot align (a static start levels it, but no fix gives a position).
    let env = TestEnv::new("silentrun");
    let rec = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/record_drive.mcap");
    let json = env.dir.join("s.json");
    let o = env
        .command(&[
            "replay",
            rec.to_str().unwrap(),
            "--estimate",
            "--gnss",
            "9",
            "--summary-json",
            json.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let (out, err) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(!o.status.success(), "exit 0 without a usable state:\n{out}\n{err}");
    assert!(err.contains("not aligned") && err.contains("no GNSS fix"), "{err}");
    assert!(out.contains("WARNING"), "{out}");
    let s: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(s["usable_states"].as_u64(), Some(0));
    assert!(s["nav_states"].as_u64().unwrap() > 1000);
    assert!(s["problem"].as_str().unwrap().contains("not aligned"));
}
