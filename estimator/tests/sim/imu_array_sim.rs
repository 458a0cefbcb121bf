//! IMU arrays on the simulator (offline, deterministic): offsets converge with an honest std,
//! the fused virtual IMU has the noise of four IMUs averaged, and an IMU that stops or
//! disagrees leaves the array with its reason and comes back when healthy.

use navsync_estimator::array::imu_array::{ImuArray, VirtualSample};
use navsync_estimator::evaluation::{DelayTruth, Summary};
use navsync_estimator::offline;
use navsync_estimator::pipeline::Pipeline;
use navsync_estimator::settings::Settings;
use navsync_sim::imu_errors::ImuPreset;
use navsync_sim::published::PublishedStream;
use navsync_sim::scenario::{SegmentConfig, SegmentKind, SimConfig};
use navsync_sim::world::World;
use navsync_wire::reflect::Reflect;
use navsync_wire::samples::{AnySample, ImuSample, ImuSyncReason};

const HOST0: i64 = 3_000_000_000;

fn consumer_args() -> Settings {
    let mut s = Settings::default();
    s.inputs.imus = (0..4).map(|i| i.to_string()).collect();
    s.imu.imu_model = ImuPreset::Consumer;
    s.gnss.gnss_vel_std_mps = 0.05;
    s
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
            .index_of(navsync_wire::reflect::str_of(&s.imu_id))
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
            .index_of(navsync_wire::reflect::str_of(&s.imu_id))
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

/// Runs the default drive for `end_s` with 4 consumer IMUs (offsets 0, 10, 15, 20 ms), in the
/// live process's input order (released by IMU "0"), leaving out the samples of IMU `id` in
/// each `(id, gap)` (its driver dead); a restarted driver numbers its samples from 0 again.
/// Returns the summary, the NavStates' host times and, per NavState, the time and IMU 0's
/// table row (reason, in array).
fn drive_with_gaps(end_s: f64, gaps: &[(u8, std::ops::Range<f64>)]) -> (Summary, Vec<i64>, Vec<(f64, u8, u8)>) {
    let mut cfg = SimConfig::default_drive();
    cfg.set_imu_preset(ImuPreset::Consumer);
    cfg.set_imu_offsets_s(&[0.0, 0.010, 0.015, 0.020]);
    let world = World::new(&cfg, HOST0, 1_790_000_000_000_000_000).expect("world");
    let mut p = Pipeline::new(consumer_args().pipeline_config());
    let t_of = |host_ns: i64| (host_ns - HOST0) as f64 * 1e-9;
    let mut restarted_at: [Option<u64>; 4] = [None; 4];
    let samples = PublishedStream::new(world)
        .map(|x| x.sample)
        .take_while(|s| match s {
            AnySample::Imu(x) => t_of(x.stamp.host_ns) < end_s,
            _ => true,
        })
        .filter_map(move |mut s| {
            if let AnySample::Imu(x) = &mut s {
                let (id, t) = (x.imu_id[0] - b'0', t_of(x.stamp.host_ns));
                for (g_id, gap) in gaps {
                    if *g_id == id && gap.contains(&t) {
                        return None;
                    }
                    if *g_id == id && t >= gap.end {
                        let first = *restarted_at[usize::from(id)].get_or_insert(x.stamp.seq);
                        x.stamp.seq -= first;
                    }
                }
            }
            Some(s)
        });
    let (mut stamps, mut imu0) = (Vec::new(), Vec::new());
    let r = offline::run_ordered(
        &mut p,
        Some("0"),
        samples.map(|s| (s, ())),
        DelayTruth::Zero,
        false,
        |o, _| {
            if let offline::Output::Nav(n) = o {
                stamps.push(n.host_ns);
                imu0.push((t_of(n.host_ns), n.imu[0].reason, n.imu[0].in_array));
            }
        },
    );
    let handovers = gaps.iter().filter(|(id, _)| *id == 0).count() as u64;
    assert_eq!(p.array().counters().handovers, handovers, "handovers");
    // The fused stream that drives the filter goes on too (one virtual sample per reference
    // sample at 200 Hz).
    let virtual_samples = p.array().counters().virtual_samples;
    assert!(
        virtual_samples as f64 > 0.98 * end_s * 200.0,
        "{virtual_samples} virtual samples in {end_s} s"
    );
    (r.summary, stamps, imu0)
}

#[test]
fn the_reference_imu_stopping_hands_the_array_over_and_navigation_goes_on() {
    let (base, _, _) = drive_with_gaps(200.0, &[]);
    // The drivers of IMUs 1–3 restart at 99.5 s (their samples numbered from 0 again, their
    // rings still holding samples from before); IMU 0 (the configured reference) is dead from
    // 100 s to 130 s of the drive (moving): one of the others takes over.
    let (run, stamps, imu0) = drive_with_gaps(
        200.0,
        &[(1, 97.0..99.5), (2, 97.0..99.5), (3, 97.0..99.5), (0, 100.0..130.0)],
    );
    println!(
        "without the gap:\n{}\nIMU 0 dead 100–130 s:\n{}",
        base.table(),
        run.table()
    );
    // NavStates go on: the longest pause is the order's reference-silent lag plus the stale
    // time (100 + 50 ms), and they come at the IMU rate otherwise.
    let gaps: Vec<i64> = stamps.windows(2).map(|w| w[1] - w[0]).collect();
    let longest_ms = *gaps.iter().max().unwrap() as f64 * 1e-6;
    println!(
        "longest pause between NavStates {longest_ms:.1} ms; {} NavStates",
        stamps.len()
    );
    assert!(longest_ms < 200.0, "NavStates paused {longest_ms} ms");
    assert!(
        gaps.iter().all(|&g| g > 0),
        "NavState host times go backwards across the handover"
    );
    let n_expected = (200.0 - 0.2) * 200.0;
    assert!(stamps.len() as f64 > 0.98 * n_expected, "{} NavStates", stamps.len());
    // IMU 0 is shown stale while dead and joins the array again as a member after it returns.
    let at = |t0: f64| imu0.iter().find(|r| r.0 >= t0).copied().expect("time");
    assert_eq!(at(101.0).1, ImuSyncReason::Stale as u8, "IMU 0 while dead");
    assert_eq!(at(101.0).2, 0);
    let back = imu0.iter().find(|r| r.0 >= 130.0 && r.2 == 1).map(|r| r.0 - 130.0);
    println!("IMU 0 back in the array {back:?} s after it returned");
    assert!(back.is_some_and(|s| s < 10.0), "IMU 0 not back in the array: {back:?}");
    // The handover does not hurt the solution: the same accuracy as without the gap.
    let (p0, p1) = (base.pos_rms_m.unwrap(), run.pos_rms_m.unwrap());
    let (a0, a1) = (base.att_rms_deg.unwrap(), run.att_rms_deg.unwrap());
    assert!(p1 <= 1.2 * p0 + 0.05, "position RMS {p1} m vs {p0} m without the gap");
    assert!(a1[2] <= 1.2 * a0[2] + 0.05, "yaw RMS {} deg vs {} deg", a1[2], a0[2]);
}

/// A vibrating body (three tones per axis of 11–37 Hz, ~1 m/s² and ~3°/s) seen by two IMUs,
/// the second stamped 9 ms late: beyond a quarter period of the fastest tone, where the offset
/// filter's linearisation no longer holds and, started from its prior of 0, it locked onto a
/// wrong lobe (57 ms ± 0.1 ms on an independent drive). The acquisition (the lag of least
/// residual over a 0.5 s window) puts the filter within its capture range first.
#[test]
fn an_offset_beyond_the_linear_capture_range_is_acquired_not_locked_on_a_wrong_lobe() {
    const DT: f64 = 0.005;
    const TD: f64 = 0.009;
    // Tones (amplitude of the rate in rad/s or of the specific force in m/s², rad/s, phase).
    let tone = |k: usize| {
        let f = [11.3, 23.9, 36.7][k % 3] + k as f64 * 0.37;
        (
            0.02 + 0.01 * (k % 3) as f64,
            2.0 * std::f64::consts::PI * f,
            0.7 * k as f64,
        )
    };
    // Mean of Σ A sin(ωt + φ) over (a, b] for the 3 tones of component c.
    let mean = |c: usize, scale: f64, a: f64, b: f64| -> f64 {
        (0..3)
            .map(|j| {
                let (amp, w, ph) = tone(3 * c + j);
                scale * amp * ((w * a + ph).cos() - (w * b + ph).cos()) / (w * (b - a))
            })
            .sum()
    };
    // Deterministic white noise at the consumer model's density (xorshift, Box–Muller).
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut gauss = move || {
        let mut u = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let (u1, u2) = (u(), u());
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    };
    let mut cfg = consumer_args().pipeline_config().array;
    cfg.units.truncate(2);
    let (sg, sa) = (
        cfg.units[0].gyro_noise_density / DT.sqrt(),
        cfg.units[0].accel_noise_density / DT.sqrt(),
    );
    let mut array = ImuArray::new(cfg);
    for k in 1..=6000u64 {
        let t = k as f64 * DT;
        for i in 0..2 {
            let lag = if i == 1 { TD } else { 0.0 };
            let (a, b) = (t - DT - lag, t - lag);
            let mut s = ImuSample::zeroed();
            s.stamp.host_ns = HOST0 + (t * 1e9).round() as i64;
            s.stamp.seq = k;
            s.dt_s = DT;
            s.imu_id[0] = b'0' + i as u8;
            for c in 0..3 {
                s.gyro_rps[c] = mean(c, 3.0, a, b) + sg * gauss();
                s.accel_mps2[c] = mean(c + 3, 30.0, a, b) + if c == 2 { -9.8 } else { 0.0 } + sa * gauss();
            }
            array.push(i, &s, &mut |_| {});
        }
    }
    let (td, sd) = array.offset(1);
    println!(
        "Td {:.4} ± {:.4} ms (true {} ms), acquisitions {}",
        td * 1e3,
        sd * 1e3,
        TD * 1e3,
        array.counters().acquisitions
    );
    assert!(array.counters().acquisitions >= 1, "never acquired");
    assert!(sd < 2e-4, "Td 1-sigma {sd} s: not converged");
    assert!(
        (td - TD).abs() <= 2.0 * sd + 1e-6,
        "Td {td} s for {TD} s (1-sigma {sd} s)"
    );
}
