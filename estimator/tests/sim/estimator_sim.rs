//! The estimator on the simulated default drive (offline, deterministic): accuracy under
//! hardware sync, the GNSS delay Δ under software sync with a 1.1 s receiver latency, what the
//! Δ state is worth, a 30 s GNSS outage in a turn, and bit-identical reruns. The bounds are
//! looser than the README's benchmark figures but still fail on a real regression.

use navsync_estimator::evaluation::{DelayTruth, Summary};
use navsync_estimator::offline;
use navsync_estimator::pipeline::Pipeline;
use navsync_estimator::settings::Settings;
use navsync_sim::imu_errors::ImuPreset;
use navsync_sim::published::PublishedStream;
use navsync_sim::scenario::{OutageConfig, SimConfig};
use navsync_sim::trajectory::Trajectory;
use navsync_sim::world::World;
use navsync_wire::samples::NavState;

struct Run {
    summary: Summary,
    states: Vec<NavState>,
}

fn run(latency_s: f64, software_sync: bool, delay_state: bool, outage: Option<(f64, f64)>) -> Run {
    run_with(ImuPreset::Industrial, latency_s, software_sync, delay_state, outage)
}

fn run_with(
    preset: ImuPreset,
    latency_s: f64,
    software_sync: bool,
    delay_state: bool,
    outage: Option<(f64, f64)>,
) -> Run {
    let mut cfg = SimConfig::default_drive();
    cfg.set_imu_count(1);
    cfg.set_imu_preset(preset);
    cfg.set_nmea_latency_s(latency_s);
    if let Some((start_s, duration_s)) = outage {
        cfg.gnss.outages.push(OutageConfig {
            start_s,
            duration_s,
            pps_continues: true,
        });
    }
    let world = World::new(&cfg, 3_000_000_000, 1_790_000_000_000_000_000).expect("world");
    let args = {
        let mut s = Settings::default();
        s.inputs.gnss = vec!["0".into()];
        s.inputs.pps = vec!["0".into()];
        s.inputs.imus = vec!["0".into()];
        s.time.software_sync = software_sync;
        s.imu.imu_model = preset;
        s.nav.estimate_delay = delay_state;
        s.gnss.gnss_vel_std_mps = 0.05;
        s
    };
    let mut pipeline = Pipeline::new(args.pipeline_config());
    let truth = if software_sync {
        DelayTruth::ReceiverLatency
    } else {
        DelayTruth::Zero
    };
    let mut states = Vec::new();
    let r = offline::run(
        &mut pipeline,
        PublishedStream::new(world).map(|p| p.sample),
        truth,
        |s| states.push(*s),
    );
    Run {
        summary: r.summary,
        states,
    }
}

/// The Cramér–Rao bound of the GNSS delay Δ for a perfect IMU, s, at every whole second of
/// the drive: the best σ_Δ any estimator can reach from the fixes (white position and
/// velocity noise as the simulated receiver's), since a real IMU's attitude, bias and noise
/// errors only add unknowns. Per horizontal axis j ∈ {N, E} the fix at t_k (1 Hz) measures
///   p: δp0_j + δv0_j·t_k + v_j(t_k)·Δ + n_p,   v: δv0_j + a_j(t_k)·Δ + n_v
/// (the INS minus the GNSS at its true epoch, the Jacobians of `nav/measurements/gnss.rs` with a
/// perfect INS whose only errors are its initial position and velocity), and the bound is
/// √[(Σ Hᵀ R⁻¹ H)⁻¹]_ΔΔ (Fisher information of the linear-Gaussian model, no prior).
fn ideal_delay_bound_s(cfg: &SimConfig) -> Vec<f64> {
    let traj = Trajectory::from_config(&cfg.trajectory, cfg.seed);
    let var_p = (cfg.gnss.horizontal_rms_m / std::f64::consts::SQRT_2).powi(2);
    let var_v = cfg.gnss.velocity_sigma_mps.powi(2);
    let mut info = nalgebra::Matrix5::<f64>::zeros();
    let mut out = Vec::new();
    for k in 0..traj.duration_s() as usize {
        let t = k as f64;
        let kin = traj.kinematics(t);
        for j in 0..2 {
            // States: δp0_N, δp0_E, δv0_N, δv0_E, Δ.
            let mut hp = nalgebra::RowVector5::zeros();
            hp[j] = 1.0;
            hp[2 + j] = t;
            hp[4] = kin.v_ned[j];
            let mut hv = nalgebra::RowVector5::zeros();
            hv[2 + j] = 1.0;
            hv[4] = kin.a_ned[j];
            info += hp.transpose() * hp / var_p + hv.transpose() * hv / var_v;
        }
        out.push(info.try_inverse().map_or(f64::INFINITY, |c| c[(4, 4)].max(0.0).sqrt()));
    }
    out
}

#[test]
fn hardware_sync_accuracy() {
    let s = run(0.6, false, true, None).summary;
    println!("{}", s.table());
    assert!(s.pos_rms_m.unwrap() < 1.0, "horizontal RMS {:?}", s.pos_rms_m);
    assert!(s.vel_rms_mps.unwrap() < 0.15, "velocity RMS {:?}", s.vel_rms_mps);
    assert!(s.att_rms_deg.unwrap()[2] < 1.0, "yaw RMS {:?}", s.att_rms_deg);
    let (d, sd) = (s.gnss_delay_est_s.unwrap(), s.gnss_delay_std_s.unwrap());
    assert!(d.abs() < 3.0 * sd && sd < 0.05, "Δ = {d} ± {sd} s under hardware sync");
}

#[test]
fn software_sync_finds_a_1_1_s_delay_and_reports_an_honest_std() {
    let s = run(1.1, true, true, None).summary;
    println!("{}", s.table());
    // The drive starts moving at 40 s of scenario time. With 1 Hz fixes of 0.05 m/s velocity
    // noise, this drive carries 6 ms (1σ, perfect IMU: `ideal_delay_bound_s`) of delay
    // information after 120 s of driving, 9 ms for the filter with the industrial IMU (the
    // README lists the spread over seeds); the estimate must be consistent with its std from
    // then on and within 10 ms once the drive has turned a few more corners (300 s).
    let bound = ideal_delay_bound_s(&SimConfig::default_drive());
    println!(
        "ideal-IMU bound on σ_Δ: {:.1} ms at 120 s of driving (t = 160 s), {:.1} ms at t = 220 s, {:.1} ms at the end",
        bound[160] * 1e3,
        bound[220] * 1e3,
        bound.last().unwrap() * 1e3
    );
    // The reported σ is an honest one: never below what the fixes can tell (5 % for the
    // linearisation and the fix times' offset from whole seconds).
    for p in s.series.iter().filter(|p| p.t_s >= 60.0) {
        let b = bound[(p.t_s as usize).min(bound.len() - 1)];
        assert!(
            p.delay_std_s >= 0.95 * b,
            "σ_Δ = {} s at {:.0} s below the ideal-IMU bound {b} s",
            p.delay_std_s,
            p.t_s
        );
    }
    let late: Vec<_> = s.series.iter().filter(|p| p.t_s >= 160.0).collect();
    assert!(late.len() > 400);
    for p in &late {
        let err = (p.delay_s - 1.1).abs();
        assert!(
            err <= 3.0 * p.delay_std_s,
            "Δ̂ = {} ± {} s at {:.0} s",
            p.delay_s,
            p.delay_std_s,
            p.t_s
        );
        assert!(p.delay_std_s < 0.012, "σ_Δ = {} s at {:.0} s", p.delay_std_s, p.t_s);
        if p.t_s >= 300.0 {
            assert!(err <= 0.010, "Δ̂ = {} s at {:.0} s", p.delay_s, p.t_s);
        }
    }
    let (d, sd) = (s.gnss_delay_est_s.unwrap(), s.gnss_delay_std_s.unwrap());
    assert!(
        (d - 1.1).abs() <= 2.0 * sd,
        "final Δ̂ = {d} ± {sd} s does not cover 1.1 s"
    );
}

#[test]
fn with_a_perfect_imu_the_delay_estimate_reaches_the_information_bound() {
    // With an IMU without errors, what is left between the filter and the bound is the
    // filter's own modelling: Δ may wander (0.1 ms/√s random walk, which discounts old fixes),
    // and the fixes before alignment enter only as the 50 ms motion-onset prior. Measured
    // 1.17–1.27 × the bound from t = 120 s on; a Δ Jacobian off by a factor would show here.
    let s = run_with(ImuPreset::Perfect, 1.1, true, true, None).summary;
    let bound = ideal_delay_bound_s(&SimConfig::default_drive());
    eprintln!("{}", s.table());
    let mut worst: f64 = 0.0;
    for p in s.series.iter().filter(|p| (p.t_s as i64) % 20 == 0) {
        eprintln!("t {:.0} d {:.4} sd {:.4}", p.t_s, p.delay_s, p.delay_std_s);
    }
    for p in s.series.iter().filter(|p| p.t_s >= 120.0) {
        let b = bound[(p.t_s as usize).min(bound.len() - 1)];
        worst = worst.max(p.delay_std_s / b);
        assert!(
            (p.delay_s - 1.1).abs() <= 3.0 * p.delay_std_s,
            "Δ̂ = {} ± {} s at {:.0} s",
            p.delay_s,
            p.delay_std_s,
            p.t_s
        );
    }
    println!("perfect IMU: σ_Δ / ideal bound ≤ {worst:.2} from t = 120 s on");
    assert!(worst < 1.35, "σ_Δ up to {worst:.2} × the ideal-IMU bound");
}

#[test]
fn the_delay_state_pays_for_itself() {
    let with = run(1.1, true, true, None).summary.pos_rms_m.unwrap();
    let zero_latency = run(0.0, true, true, None).summary.pos_rms_m.unwrap();
    let without = run(1.1, true, false, None).summary.pos_rms_m.unwrap();
    println!("horizontal RMS: Δ estimated {with:.3} m, zero latency {zero_latency:.3} m, Δ off {without:.3} m");
    assert!(with <= 1.1 * zero_latency, "{with} vs {zero_latency}");
    assert!(
        without > 3.0 * with,
        "Δ off {without} m is not visibly worse than {with} m"
    );
}

#[test]
fn thirty_second_outage_in_a_turn_stays_within_10_m() {
    // The 120° right turn runs from 439 s to 457 s.
    let s = run(0.6, false, true, Some((433.0, 30.0))).summary;
    println!("{}", s.table());
    assert_eq!(s.outage_end_h_err_m.len(), 1, "{:?}", s.outage_end_h_err_m);
    assert!(
        s.outage_end_h_err_m[0] < 10.0,
        "error at the end of the outage {:?}",
        s.outage_end_h_err_m
    );
}

#[test]
fn reruns_are_bit_identical() {
    let a = run(1.1, true, true, None).states;
    let b = run(1.1, true, true, None).states;
    assert_eq!(a.len(), b.len());
    assert!(a.len() > 100_000);
    for (x, y) in a.iter().zip(&b) {
        let json_x = navsync_wire::json::to_json(x).to_string();
        let json_y = navsync_wire::json::to_json(y).to_string();
        assert_eq!(json_x, json_y, "states differ at host time {}", x.host_ns);
    }
}
