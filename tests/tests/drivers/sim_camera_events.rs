//! The simulated camera through the live chain: `navsync sim` (UBX at 4 Hz, a 4 Hz camera on the
//! receiver's EXTINT0: exposures 100 ms after triggers on the quarter seconds of UTC, 5 ms long,
//! no jitter; the receiver's latch clock 20.83 ns) writes TIM-TM2 into a pseudo-terminal,
//! `navsync gnss --protocol ubx` publishes each mark on `navsync/gnss/{id}/event`, and maps it to
//! host time with the time state on `navsync/time/state`, which this test publishes from the
//! simulator's truth (`navsync/sim/truth`: host and UTC of the same instant, the host clock's
//! rate) in place of the estimator. Each event's GPS times must be those of an exposure (the
//! quarter second + 100 ms, + 105 ms for the falling edge) to within the receiver's `accEst`,
//! late by up to one tick of its latch clock; consecutive events one trigger apart, counted;
//! and the host times the driver mapped those of the exposures on the simulated host clock
//! (the truth interpolated at the exposure), to within `accEst` and 10 ns.

use std::fmt::Write as _;
use std::time::{Duration, Instant};

use navsync_shared::samples::{GnssEvent, SimTruth, TimeState, TimeStatus};
use navsync_shared::services;
use navsync_shared::time::utc_ns_from_gps_ns;
use navsync_tests::{TestEnv, write_drive_scenario};

/// Trigger period of the camera, and its exposure's start and end after the trigger, ns.
const PERIOD_NS: i64 = 250_000_000;
const RISING_NS: i64 = 100_000_000;
const FALLING_NS: i64 = 105_000_000;

/// Events with mapped host times to collect.
const MAPPED: usize = 12;

/// How late a reported UTC is after the exposure edge `after_trigger_ns` past a trigger, ns.
fn late_ns(utc_ns: i64, after_trigger_ns: i64) -> i64 {
    let e = (utc_ns - after_trigger_ns).rem_euclid(PERIOD_NS);
    // Just before the edge (an error below 0) would show as almost a period late.
    if e > PERIOD_NS / 2 { e - PERIOD_NS } else { e }
}

/// The simulated host's time of UTC `utc_ns`, interpolated between the truth samples around it.
fn true_host_ns(truth: &[(i64, i64)], utc_ns: i64) -> Option<i64> {
    let i = truth.iter().position(|&(_, u)| u > utc_ns)?;
    let ((h0, u0), (h1, u1)) = (truth.get(i.checked_sub(1)?)?, truth[i]);
    Some(h0 + ((utc_ns - u0) as f64 * (h1 - h0) as f64 / (u1 - u0) as f64).round() as i64)
}

#[test]
fn simulated_camera_marks_arrive_as_events_at_their_exposures() {
    let mut env = TestEnv::new("simcamera");
    let scenario = env.dir.join("camera.toml");
    write_drive_scenario(&scenario, 20.0, 1, 100.0);
    let mut text = std::fs::read_to_string(&scenario).unwrap();
    let _ = write!(
        text,
        "\n[gnss]\nprotocol = \"ubx\"\nrate_hz = 4\ntimepulse_quantization_ns = 20.83\n\n\
         [gnss.camera]\nrate_hz = 4.0\nexposure_offset_s = 0.1\nexposure_jitter_s = 0.0\nexposure_s = 0.005\n"
    );
    std::fs::write(&scenario, text).unwrap();

    let node = env.node("observer");
    let events = node.subscriber::<GnssEvent>(&services::gnss_event("cam")).unwrap();
    let truth_sub = node.subscriber::<SimTruth>(services::SIM_TRUTH).unwrap();
    let mut time_pub = node.publisher::<TimeState>(services::TIME_STATE).unwrap();
    let link = env.dir.join("rx");
    let (link_s, scen_s) = (link.display().to_string(), scenario.display().to_string());
    env.spawn(
        "sim",
        &[
            "sim",
            "--scenario",
            &scen_s,
            "--imus",
            "1",
            "--pty-link",
            &link_s,
            "--duration",
            "30",
        ],
    );
    env.wait_for_path(&link, Duration::from_secs(20));
    env.spawn(
        "gnss",
        &[
            "gnss",
            "--port",
            &link_s,
            "--baud",
            "115200",
            "--protocol",
            "ubx",
            "--id",
            "cam",
        ],
    );

    // (host, UTC) of every truth sample; the events as they arrive.
    let mut truth: Vec<(i64, i64)> = Vec::new();
    let mut got: Vec<GnssEvent> = Vec::new();
    let t0 = Instant::now();
    while got.iter().filter(|e| e.rising_host_ns != i64::MIN).count() < MAPPED {
        env.assert_running();
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "{} events, {} mapped; sim:\n{}\ngnss:\n{}",
            got.len(),
            got.iter().filter(|e| e.rising_host_ns != i64::MIN).count(),
            env.log("sim"),
            env.log("gnss")
        );
        let mut latest = None;
        truth_sub
            .for_each(|t| {
                truth.push((t.host_ns, t.utc_ns));
                latest = Some(*t);
            })
            .unwrap();
        // The estimator's part: the host → UTC mapping, here the simulator's own.
        if let Some(t) = latest {
            let mut ts = TimeState::unknown();
            ts.status = TimeStatus::Locked as u8;
            ts.ref_host_ns = t.host_ns;
            ts.ref_utc_ns = t.utc_ns;
            ts.rate_error = t.rate_error;
            ts.leap_s = 18;
            time_pub.publish(&ts).unwrap();
        }
        events.for_each(|e| got.push(*e)).unwrap();
        std::thread::sleep(Duration::from_millis(20));
    }
    // The truth a little past the last event, to interpolate at it.
    std::thread::sleep(Duration::from_millis(300));
    truth_sub.for_each(|t| truth.push((t.host_ns, t.utc_ns))).unwrap();

    let mut report = String::new();
    for (i, e) in got.iter().enumerate() {
        assert_eq!((e.channel, e.accuracy_ns), (0, 21), "event {i}");
        // New rising and falling edges, time valid, UTC available, GNSS time base, armed,
        // running.
        assert_eq!(
            e.flags,
            0x80 | 0x40 | 0x20 | 0x08 | 0x04 | 0x01,
            "event {i}: flags {:#04x}",
            e.flags
        );
        let acc = i64::from(e.accuracy_ns);
        let (rising, falling) = (
            utc_ns_from_gps_ns(e.rising_gps_ns),
            utc_ns_from_gps_ns(e.falling_gps_ns),
        );
        let (late_r, late_f) = (late_ns(rising, RISING_NS), late_ns(falling, FALLING_NS));
        assert!(
            (0..=acc).contains(&late_r) && (0..=acc).contains(&late_f),
            "event {i}: edges {late_r} and {late_f} ns after the exposure's (accEst {acc} ns)"
        );
        if let Some(prev) = i.checked_sub(1).map(|j| got[j]) {
            let triggers = (e.rising_gps_ns - prev.rising_gps_ns + PERIOD_NS / 2).div_euclid(PERIOD_NS);
            assert_eq!(
                i64::from(e.count.wrapping_sub(prev.count)),
                triggers,
                "event {i}: count against the triggers between"
            );
            assert_eq!(triggers, 1, "event {i}: one trigger per 4 Hz epoch");
        }
        if e.rising_host_ns == i64::MIN {
            continue;
        }
        let (true_r, true_f) = (rising - late_r, falling - late_f);
        for (mapped, utc) in [(e.rising_host_ns, true_r), (e.falling_host_ns, true_f)] {
            let host = true_host_ns(&truth, utc).unwrap_or_else(|| panic!("event {i}: no truth around {utc}"));
            assert!(
                (mapped - host).abs() <= acc + 10,
                "event {i}: mapped host time {} ns off the exposure's",
                mapped - host
            );
        }
        let _ = writeln!(
            report,
            "event {i}: count {}, edges late by {late_r}/{late_f} ns, host {} ns off",
            e.count,
            e.rising_host_ns - true_host_ns(&truth, true_r).unwrap_or(0)
        );
    }
    println!("{report}");
    drop((events, truth_sub, time_pub, node));
    env.finish();
}
