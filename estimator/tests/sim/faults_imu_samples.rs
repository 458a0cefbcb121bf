//! An IMU delivering NaN, saturated and time-reversed samples (issue 8), offline and
//! deterministic on the simulated default drive: bursts of bad samples in the middle of a turn
//! and of an acceleration, plus single bad samples every few seconds, injected into the
//! reference IMU's stream. The estimator must reject and count every one by kind (array
//! counters `invalid`, `saturated`, `backwards`; Health `imu_rejected_*`), never let a NaN
//! into the navigation state, keep producing states, and stay within the clean run's error.
//!
//! The driver side (bytes → decoder → sample checks) is tested next to the code, in
//! `drivers/src/imu/xsens_driver.rs`.

use crate::fault_drive::{ErrorTrack, drive, estimator_args, scenario, t_s};
use navsync_wire::imu_spec::ImuPreset;
use navsync_wire::samples::{AnySample, IMU_FLAG_SATURATED, ImuSample};

/// What was done to a sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Fault {
    /// Values replaced by NaN or infinity.
    NotFinite,
    /// Every axis at ± full scale, flagged saturated (a sensor railing).
    Saturated,
    /// An extra sample stamped 30 ms before its predecessor, with wild values.
    ReversedExtra,
    /// The sample's own stamp set 1 s back, values wild.
    ReversedStamp,
}

/// The fault for a reference-IMU sample at scenario time `t` (s), if any. Bursts of 0.1 s
/// (20 samples) during the right turn (68–78 s) and the acceleration (93–103 s), then one
/// sample of each kind every 5 s.
fn fault_at(t: f64) -> Option<Fault> {
    let within = |from: f64, len: f64| t >= from && t < from + len;
    if within(70.0, 0.1) || within(96.0, 0.1) {
        return Some(Fault::NotFinite);
    }
    if within(72.0, 0.1) || within(98.0, 0.1) {
        return Some(Fault::Saturated);
    }
    if within(74.0, 0.1) {
        return Some(Fault::ReversedExtra);
    }
    if within(100.0, 0.05) {
        return Some(Fault::ReversedStamp);
    }
    if t >= 105.0 {
        // Single samples: the first sample at or after 105 + 5k s (+ 1 s, + 2 s, + 3 s).
        let phase = (t - 105.0).rem_euclid(5.0);
        let first = |at: f64| phase >= at && phase < at + 0.005;
        return [
            (0.0, Fault::NotFinite),
            (1.0, Fault::Saturated),
            (2.0, Fault::ReversedExtra),
            (3.0, Fault::ReversedStamp),
        ]
        .into_iter()
        .find(|(at, _)| first(*at))
        .map(|(_, f)| f);
    }
    None
}

#[derive(Debug, Default, Clone, Copy)]
struct Injected {
    not_finite: u64,
    saturated: u64,
    /// Extra samples stamped before their predecessor.
    reversed_extra: u64,
    /// Samples whose own stamp was moved back.
    reversed_stamp: u64,
    /// Samples the simulator itself flagged saturated (none expected on this drive).
    sim_saturated: u64,
    /// Runs of consecutive samples missing from the stream (rejected in place).
    gaps: u64,
}

fn run(end_s: f64, inject: bool) -> (ErrorTrack, Injected, navsync_estimator::pipeline::Pipeline) {
    let spec = ImuPreset::Industrial.spec();
    let (gyro_fs, accel_fs) = (spec.gyro.range, spec.accel.range);
    let mut n = Injected::default();
    let mut k = 0u64;
    let mut prev: Option<ImuSample> = None;
    let mut in_gap = false;
    let mut track = ErrorTrack::default();
    let edit = |s: AnySample, out: &mut Vec<AnySample>| {
        let AnySample::Imu(x) = s else {
            out.push(s);
            return;
        };
        n.sim_saturated += u64::from(x.flags & IMU_FLAG_SATURATED != 0);
        let fault = if inject { fault_at(t_s(x.stamp.host_ns)) } else { None };
        let mut bad = x;
        k += 1;
        match fault {
            None => out.push(s),
            Some(Fault::NotFinite) => {
                // Vary which axes and which non-finite value.
                let v = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY][(k % 3) as usize];
                bad.gyro_rps[(k % 3) as usize] = v;
                if k.is_multiple_of(2) {
                    bad.accel_mps2 = [f64::NAN; 3];
                }
                n.not_finite += 1;
                out.push(AnySample::Imu(bad));
            }
            Some(Fault::Saturated) => {
                let sign = if k.is_multiple_of(2) { 1.0 } else { -1.0 };
                bad.gyro_rps = [sign * gyro_fs, -sign * gyro_fs, sign * gyro_fs];
                bad.accel_mps2 = [sign * accel_fs, sign * accel_fs, -accel_fs];
                bad.flags |= IMU_FLAG_SATURATED;
                n.saturated += 1;
                out.push(AnySample::Imu(bad));
            }
            Some(Fault::ReversedExtra) => {
                out.push(s);
                bad.stamp.host_ns -= 30_000_000;
                bad.gyro_rps = [3.0, -2.0, 1.0];
                bad.accel_mps2 = [40.0, -30.0, 20.0];
                n.reversed_extra += 1;
                out.push(AnySample::Imu(bad));
            }
            Some(Fault::ReversedStamp) => {
                let before = prev.map_or(x.stamp.host_ns, |p| p.stamp.host_ns);
                bad.stamp.host_ns = before - 1_000_000_000;
                bad.gyro_rps = [-3.0, 2.0, -1.0];
                bad.accel_mps2 = [-40.0, 30.0, -20.0];
                n.reversed_stamp += 1;
                out.push(AnySample::Imu(bad));
            }
        }
        let missing = fault.is_some() && fault != Some(Fault::ReversedExtra);
        n.gaps += u64::from(missing && !in_gap);
        in_gap = missing;
        if !missing {
            prev = Some(x);
        }
    };
    let p = drive(&scenario(), &estimator_args(), end_s, edit, |_, e| track.on(&e));
    (track, n, p)
}

#[test]
fn bad_imu_samples_are_rejected_counted_and_harmless() {
    let end_s = 240.0;
    let (clean, _, clean_p) = run(end_s, false);
    let (faulty, n, p) = run(end_s, true);
    let ac = *p.array().counters();
    let pc = *p.counters();
    let nc = p.nav().counters();
    let windows = [
        ("turn with bursts, 68–80 s", 68.0, 80.0),
        ("acceleration with bursts, 93–105 s", 93.0, 105.0),
        ("single bad samples, 105 s–end", 105.0, end_s),
        ("whole drive after alignment", 40.0, end_s),
    ];
    println!("injected: {n:?}");
    println!("array counters: {ac:?}");
    println!(
        "pipeline: {} samples used, {} rejected; navigator: {} gaps bridged, {} backwards; clean run: {} states, faulty run: {} states",
        pc.imu_used, pc.imu_invalid, nc.imu_gaps, nc.imu_backwards, clean.states, faulty.states
    );
    let mut rows = Vec::new();
    for (name, from, to) in windows {
        let (c, f) = (clean.stats(from, to), faulty.stats(from, to));
        println!("{name}:\n  clean  {c}\n  faults {f}");
        rows.push((name, c, f));
    }

    // Every bad sample rejected and counted by kind; nothing else rejected.
    assert_eq!(n.sim_saturated, 0, "the simulator saturated on its own");
    let reversed = n.reversed_extra + n.reversed_stamp;
    assert!(
        n.not_finite >= 40 && n.saturated >= 40 && n.reversed_extra >= 20 && n.reversed_stamp >= 10,
        "{n:?}"
    );
    assert_eq!(ac.invalid, n.not_finite, "non-finite samples counted");
    assert_eq!(ac.saturated, n.saturated, "saturated samples counted");
    assert_eq!(ac.backwards, reversed, "time-reversed samples counted");
    assert_eq!(pc.imu_invalid, n.not_finite + n.saturated + reversed);
    let clean_ac = *clean_p.array().counters();
    assert_eq!((clean_ac.invalid, clean_ac.saturated, clean_ac.backwards), (0, 0, 0));
    // The interval of a rejected sample is bridged by the next good one (time-reversed extras
    // sit between good samples and leave no gap), in the filter and the output stream.
    assert_eq!(nc.imu_gaps, 2 * n.gaps, "gaps bridged");
    // It continues: one state per accepted reference sample, no NaN anywhere.
    assert_eq!(
        faulty.states + n.not_finite + n.saturated + n.reversed_stamp,
        clean.states,
        "states"
    );
    assert!(
        faulty.non_finite.is_none(),
        "non-finite NavState field {:?}",
        faulty.non_finite
    );
    // And stays within the normal error (the bounds of the hardware-sync accuracy test), close
    // to the clean run's: a rejected sample's interval is bridged with its successor's rates,
    // which misses 0.1 s of vibration in a burst.
    for (name, c, f) in rows {
        assert!(
            f.h_rms_m <= c.h_rms_m + 0.15 && f.h_max_m <= c.h_max_m + 0.3,
            "{name}: position {f} vs clean {c}"
        );
        assert!(
            f.vel_rms_mps <= c.vel_rms_mps + 0.02,
            "{name}: velocity {f} vs clean {c}"
        );
        assert!(f.yaw_max_deg <= c.yaw_max_deg + 0.2, "{name}: yaw {f} vs clean {c}");
    }
    let whole = faulty.stats(40.0, end_s);
    assert!(whole.h_rms_m < 1.0 && whole.vel_rms_mps < 0.15, "{whole}");
}
