//! The integrity monitor catches each kind of fault injected into the simulated default drive
//! and says so (counters, `NavState::integrity`), and no aligned state carries a non-finite
//! number: NaN IMU values, absurd fixes, a wrong IMU model, a gyro bias that steps.

use crate::fault_drive::{ErrorTrack, Event, drive, estimator_args, scenario, t_s};
use navsync_estimator::pipeline::Pipeline;
use navsync_estimator::settings::Settings;
use navsync_sim::imu_errors::ImuPreset;
use navsync_wire::samples::{AnySample, INTEGRITY_INCONSISTENT, INTEGRITY_RECOVERING, NavStatus};

/// End of every drive, s of scenario time.
const END_S: f64 = 240.0;

/// What a faulty run produced.
struct Outcome {
    track: ErrorTrack,
    /// (scenario time, integrity flags) of every state that had any.
    flagged: Vec<(f64, u8)>,
    /// Share of the truth instants after `settle_s` whose horizontal error is within 3 σ.
    covered: f64,
    pipeline: Pipeline,
}

fn run(
    args: &Settings,
    cfg_edit: impl FnOnce(&mut navsync_sim::scenario::SimConfig),
    settle_s: f64,
    edit: impl FnMut(AnySample, &mut Vec<AnySample>),
) -> Outcome {
    let mut cfg = scenario();
    cfg_edit(&mut cfg);
    let mut track = ErrorTrack::default();
    let mut flagged = Vec::new();
    let (mut n, mut inside) = (0u64, 0u64);
    let mut sigma_h = f64::NAN;
    let pipeline = drive(&cfg, args, END_S, edit, |_, e| {
        if let Event::Nav(s) = &e {
            if s.integrity != 0 {
                flagged.push((t_s(s.host_ns), s.integrity));
            }
            sigma_h = if s.status == NavStatus::Aligning as u8 {
                f64::NAN
            } else {
                s.pos_std_ned_m[0].hypot(s.pos_std_ned_m[1])
            };
        }
        let before = track.errors.len();
        track.on(&e);
        if let (Some(err), true) = (track.errors.get(before), sigma_h.is_finite())
            && err.t_s >= settle_s
        {
            n += 1;
            inside += u64::from(err.h_m <= 3.0 * sigma_h);
        }
    });
    Outcome {
        track,
        flagged,
        covered: inside as f64 / n.max(1) as f64,
        pipeline,
    }
}

fn counter(p: &Pipeline, name: &str) -> u64 {
    let mut v = 0;
    p.nav().integrity().each(&mut |n, c| {
        if n == name {
            v = c;
        }
    });
    v
}

#[test]
fn nan_imu_values_never_reach_an_output() {
    let o = run(
        &estimator_args(),
        |_| {},
        60.0,
        |s, out| match s {
            AnySample::Imu(mut x) if (150.0..151.0).contains(&t_s(x.stamp.host_ns)) => {
                x.gyro_rps[2] = f64::NAN;
                x.accel_mps2[0] = f64::NAN;
                out.push(AnySample::Imu(x));
            }
            s => out.push(s),
        },
    );
    assert!(o.track.non_finite.is_none(), "{:?}", o.track.non_finite);
    assert!(
        o.pipeline.array().counters().invalid > 0,
        "the NaN samples were rejected and counted"
    );
    let after = o.track.stats(152.0, END_S);
    println!("NaN second: after {after}, 3σ coverage {:.3}", o.covered);
    assert!(after.n > 500, "navigation goes on: {after}");
    assert!(
        o.covered >= 0.9,
        "σ covers the error in {:.1} % of the instants",
        100.0 * o.covered
    );
}

#[test]
fn absurd_fixes_are_rejected_and_counted() {
    let o = run(
        &estimator_args(),
        |_| {},
        60.0,
        |s, out| match s {
            AnySample::GnssFix(mut f) if (150.0..152.0).contains(&t_s(f.stamp.host_ns)) => {
                f.lat_deg += 10.0;
                f.speed_mps = 900.0;
                f.vel_n_mps = 900.0;
                out.push(AnySample::GnssFix(f));
            }
            s => out.push(s),
        },
    );
    assert!(o.track.non_finite.is_none());
    assert!(
        o.pipeline.nav().counters().fixes_rejected >= 2,
        "the absurd fixes were rejected"
    );
    let around = o.track.stats(148.0, 160.0);
    assert!(around.h_max_m < 2.0, "the state did not follow them: {around}");
}

#[test]
fn a_wrong_imu_model_is_caught_and_its_sigma_widened() {
    // Consumer-grade data, an estimator told the IMU is perfect: its σ would be far too small.
    let mut args = estimator_args();
    args.imu.imu_model = ImuPreset::Perfect;
    // σ is judged once the monitor has had the drive's first minute of fixes to see it.
    let o = run(
        &args,
        |c| c.set_imu_preset(ImuPreset::Consumer),
        120.0,
        crate::fault_drive::unchanged,
    );
    assert!(o.track.non_finite.is_none());
    let inconsistent = counter(&o.pipeline, "integrity_inconsistent") + counter(&o.pipeline, "integrity_resets");
    assert!(inconsistent > 0, "the monitor saw nothing");
    assert!(
        o.flagged
            .iter()
            .any(|(_, f)| f & (INTEGRITY_INCONSISTENT | INTEGRITY_RECOVERING) != 0),
        "no state was flagged"
    );
    println!("wrong model: {inconsistent} episodes, 3σ coverage {:.3}", o.covered);
    assert!(
        o.covered >= 0.9,
        "σ covers the error in {:.1} % of the instants",
        100.0 * o.covered
    );
}

#[test]
fn a_gyro_bias_step_is_caught_and_sigma_covers_the_error() {
    const STEP_RPS: f64 = 0.01; // 0.57 °/s: 11 σ of the industrial model's turn-on bias
    let o = run(
        &estimator_args(),
        |_| {},
        60.0,
        |s, out| match s {
            AnySample::Imu(mut x) if t_s(x.stamp.host_ns) >= 150.0 => {
                x.gyro_rps[2] += STEP_RPS;
                out.push(AnySample::Imu(x));
            }
            s => out.push(s),
        },
    );
    assert!(o.track.non_finite.is_none());
    let caught = counter(&o.pipeline, "integrity_inconsistent")
        + counter(&o.pipeline, "integrity_implausible")
        + counter(&o.pipeline, "integrity_resets");
    assert!(caught > 0, "the monitor saw nothing");
    assert!(
        o.flagged
            .iter()
            .any(|(t, f)| *t >= 150.0 && f & (INTEGRITY_INCONSISTENT | INTEGRITY_RECOVERING) != 0),
        "no state after the step was flagged"
    );
    let late = o.track.stats(200.0, END_S);
    // An 11 σ step of an industrial gyro's bias is beyond what its model lets the filter
    // learn within the drive: what it must do is say so, with a σ that covers its error.
    println!("bias step: caught {caught}, late {late}, 3σ coverage {:.3}", o.covered);
    assert!(
        o.covered >= 0.9,
        "σ covers the error in {:.1} % of the instants",
        100.0 * o.covered
    );
}
