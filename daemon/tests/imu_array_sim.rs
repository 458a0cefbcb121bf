//! IMU arrays on the simulator (offline, deterministic): offsets converge with an honest std,
//! the fused virtual IMU has the noise of four IMUs averaged, and an IMU that stops or
//! disagrees leaves the array with its reason and comes back when healthy.

use navsync::estimator::imu_array::{ImuArray, VirtualSample};
use navsync::estimator::pipeline::Pipeline;
use navsync::evaluation::{DelayTruth, Summary};
use navsync::offline;
use navsync::roles::estimator::EstimatorArgs;
use navsync_drivers::sim::imu_errors::ImuPreset;
use navsync_drivers::sim::published::PublishedStream;
use navsync_drivers::sim::scenario::{SegmentConfig, SegmentKind, SimConfig};
use navsync_drivers::sim::world::World;
use navsync_shared::samples::{AnySample, ImuSample, ImuSyncReason};

const HOST0: i64 = 3_000_000_000;

fn consumer_args() -> EstimatorArgs {
    EstimatorArgs {
        imu_ids: (0..4).map(|i| i.to_string()).collect(),
        imu_model: ImuPreset::Consumer,
        gnss_vel_std_mps: 0.05,
        ..Default::default()
    }
}

/// (time since start in s, per-IMU offset estimates in s, their stds in s).
type OffsetTrack = Vec<(f64, [f64; 4], [f64; 4])>;

fn drive(offsets_ms: [f64; 4]) -> (Summary, OffsetTrack) {
    let mut cfg = SimConfig::default_drive();
    cfg.set_imu_preset(ImuPreset::Consumer);
    cfg.set_imu_offsets_s(&offsets_ms.map(|o| o * 1e-3));
    let world = World::new(&cfg, HOST0, 1_790_000_000_000_000_000).expect("world");
    let mut p = Pipeline::new(consumer_args().pipeline_config());
    let mut track = Vec::new();
    let r = offline::run(
        &mut p,
        PublishedStream::new(world).map(|x| x.sample),
        DelayTruth::Zero,
        |s| {
            if s.seq % 200 == 0 {
                let t = (s.host_ns - HOST0) as f64 * 1e-9;
                track.push((
                    t,
                    [0, 1, 2, 3].map(|i| s.imu[i].offset_s),
                    [0, 1, 2, 3].map(|i| s.imu[i].offset_std_s),
                ));
            }
        },
    );
    (r.summary, track)
}

#[test]
fn offsets_converge_with_an_honest_std() {
    for offsets in [
        [0.0, 10.0, 15.0, 20.0],
        [0.0, 20.0, 25.0, 30.0],
        [0.0, 30.0, 50.0, 90.0],
    ] {
        let (summary, track) = drive(offsets);
        println!("offsets {offsets:?} ms:\n{}", summary.table());
        // The drive starts moving at 40 s; 30 s of motion later every offset is within 0.3 ms
        // (the README lists the measured figures), and from then on the error stays within
        // 3 sigma; at the end within 0.1 ms.
        for (t, est, std) in track.iter().filter(|(t, ..)| *t >= 70.0) {
            for i in 1..4 {
                let err = (est[i] - offsets[i] * 1e-3).abs();
                assert!(
                    err <= 3e-4,
                    "IMU {i}: Td {:.4} ms at {t:.0} s (true {})",
                    est[i] * 1e3,
                    offsets[i]
                );
                assert!(
                    err <= 3.0 * std[i] + 2e-5,
                    "IMU {i}: error {err} s, std {} s at {t:.0} s",
                    std[i]
                );
            }
        }
        if let Some((t, est, std)) = track.iter().find(|(t, ..)| *t >= 70.0) {
            let errs: Vec<String> = (1..4)
                .map(|i| format!("{:+.4}±{:.4} ms", (est[i] - offsets[i] * 1e-3) * 1e3, std[i] * 1e3))
                .collect();
            println!("offset errors after 30 s of motion (t = {t:.0} s): {}", errs.join(", "));
        }
        let (_, est, _) = track.last().expect("states");
        for i in 1..4 {
            assert!(
                (est[i] - offsets[i] * 1e-3).abs() <= 1e-4,
                "IMU {i}: final Td {} s",
                est[i]
            );
        }
        assert!(summary.pos_rms_m.unwrap() < 1.0, "position RMS {:?}", summary.pos_rms_m);
    }
}

/// Samples of a simulated standstill.
fn static_samples(seconds: f64) -> Vec<ImuSample> {
    let mut cfg = SimConfig::default_drive();
    cfg.set_imu_preset(ImuPreset::Consumer);
    cfg.trajectory.segments = vec![SegmentConfig {
        kind: SegmentKind::Static,
        duration_s: seconds,
        to_speed_mps: None,
        heading_change_deg: None,
        to_pitch_deg: None,
    }];
    let world = World::new(&cfg, HOST0, 1_790_000_000_000_000_000).expect("world");
    PublishedStream::new(world)
        .filter_map(|p| match p.sample {
            AnySample::Imu(s) => Some(s),
            _ => None,
        })
        .collect()
}

fn std_dev(v: &[f64]) -> f64 {
    let m = v.iter().sum::<f64>() / v.len() as f64;
    (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
}

#[test]
fn fused_array_has_the_angle_random_walk_of_four_imus() {
    let samples = static_samples(100.0);
    let mut array = ImuArray::new(consumer_args().pipeline_config().array);
    let mut fused: Vec<VirtualSample> = Vec::new();
    for s in &samples {
        let i = array
            .index_of(navsync_shared::reflect::str_of(&s.imu_id))
            .expect("known IMU");
        array.push(i, s, &mut |v| fused.push(*v));
    }
    let single: Vec<&ImuSample> = samples.iter().filter(|s| s.imu_id[0] == b'0').skip(1000).collect();
    let fused = &fused[1000..];
    for axis in 0..3 {
        let s1 = std_dev(&single.iter().map(|s| s.gyro_rps[axis]).collect::<Vec<_>>());
        let s4 = std_dev(&fused.iter().map(|v| v.gyro_rps[axis]).collect::<Vec<_>>());
        let ratio = s4 / s1;
        println!("gyro axis {axis}: single {s1:.3e} rad/s, fused {s4:.3e} rad/s, ratio {ratio:.3} (ideal 0.5)");
        assert!(
            (0.45..=0.55).contains(&ratio),
            "ARW ratio {ratio} is not within 10 % of 1/√4"
        );
    }
}

#[test]
fn a_stopped_imu_leaves_the_array_and_returns() {
    let samples = static_samples(30.0);
    let mut array = ImuArray::new(consumer_args().pipeline_config().array);
    let mut reasons = Vec::new();
    for s in &samples {
        let t = (s.stamp.host_ns - HOST0) as f64 * 1e-9;
        let i = array
            .index_of(navsync_shared::reflect::str_of(&s.imu_id))
            .expect("known IMU");
        // IMU 2 is silent from 10 s to 12 s; IMU 3 reports a 0.2 rad/s gyro fault from 20 s on.
        if i == 2 && (10.0..12.0).contains(&t) {
            continue;
        }
        let mut s = *s;
        if i == 3 && t >= 20.0 {
            s.gyro_rps[2] += 0.2;
        }
        array.push(i, &s, &mut |_| {});
        if i == 0 && s.stamp.seq % 100 == 0 {
            let (table, _) = array.table();
            reasons.push((
                t,
                table[2].reason,
                table[2].in_array,
                table[3].reason,
                table[3].in_array,
            ));
        }
    }
    let at = |t0: f64| reasons.iter().find(|r| r.0 >= t0).copied().expect("time");
    assert_eq!(at(9.0).1, ImuSyncReason::Converging as u8, "IMU 2 before the gap");
    assert_eq!(at(9.0).2, 1, "IMU 2 contributes at rest");
    assert_eq!(at(11.0).1, ImuSyncReason::Stale as u8, "IMU 2 during the gap");
    assert_eq!(at(11.0).2, 0);
    assert_eq!(at(14.0).2, 1, "IMU 2 back after the gap");
    assert_eq!(at(19.0).4, 1, "IMU 3 before its fault");
    assert_eq!(at(21.0).3, ImuSyncReason::Disagrees as u8, "IMU 3 after its fault");
    assert_eq!(at(21.0).4, 0);
}
