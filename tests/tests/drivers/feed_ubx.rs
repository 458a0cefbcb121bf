//! Real u-blox captures (`../shared/corpora/gpsd-ubx`) played by `navsync feed` into
//! pseudo-terminals (gpsd's `#` header skipped, paced by the line rate) and read by live
//! `navsync gnss --protocol auto` processes: the fixes on `navsync/gnss/{id}/fix` are, field by
//! field, what the offline decoder makes of the same bytes, and the receiver's other products
//! arrive on their services, as many as offline: TIM-TP on `…/timepulse` (u-blox-m8t-time),
//! RXM-SFRBX subframes on `…/nav-data` (ublox-glo), the NEO-M8L's own IMU (ESF-MEAS) as
//! `navsync/imu/{imu_id}/sample` with `--imu-id`, and the skies of NAV-SAT/NAV-SVINFO on
//! `…/sky` (every capture).

use std::time::{Duration, Instant};

use navsync_drivers::gnss::capture::gpsd_header;
use navsync_drivers::gnss::{Decoder, GnssDecoder, GnssExtra, Protocol};
use navsync_shared::ipc::Subscriber;
use navsync_shared::samples::{GnssFix, GnssNavData, GnssSky, GnssTimePulse, ImuSample};
use navsync_shared::services;
use navsync_tests::{TestEnv, shared_material};

/// What the offline decoder makes of a capture: fixes, time pulses, subframes, IMU samples,
/// skies.
fn offline(bytes: &[u8]) -> (Vec<GnssFix>, usize, usize, usize, usize) {
    let (header, _) = gpsd_header(bytes);
    let mut d = Decoder::new(Protocol::Auto);
    let (mut fixes, mut pulses, mut subframes, mut imu, mut skies) = (Vec::new(), 0, 0, 0, 0);
    let mut count = |x: GnssExtra<'_>| match x {
        GnssExtra::TimePulse(_) => pulses += 1,
        GnssExtra::NavData(_) => subframes += 1,
        GnssExtra::Imu(_) => imu += 1,
        GnssExtra::Sky(_) => skies += 1,
        _ => {}
    };
    d.push_extras(
        bytes.get(header..).unwrap_or(&[]),
        0,
        0,
        &mut |f| fixes.push(*f),
        &mut count,
    );
    d.flush_extras(&mut |f| fixes.push(*f), &mut count);
    (fixes, pulses, subframes, imu, skies)
}

fn same(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

#[test]
fn ubx_captures_through_feed_and_gnss_match_the_offline_decoder() {
    let dir = shared_material("corpora/gpsd-ubx");
    let mut env = TestEnv::new("feedubx");
    let node = env.node("observer");
    let captures = ["ublox-neo-m8l.log", "u-blox-m8t-time.log", "ublox-glo.log"];
    struct Run {
        fixes: Subscriber<GnssFix>,
        pulses: Subscriber<GnssTimePulse>,
        nav: Subscriber<GnssNavData>,
        imu: Subscriber<ImuSample>,
        sky: Subscriber<GnssSky>,
        got: (Vec<GnssFix>, usize, usize, usize, usize),
        want: (Vec<GnssFix>, usize, usize, usize, usize),
    }
    let mut runs = Vec::new();
    // One capture at a time, paced by the line rate and drained while it plays (a subscriber
    // buffers 64 fixes; unpaced, a capture's 200 fixes would overflow it).
    for (k, name) in captures.iter().enumerate() {
        let path = dir.join(name);
        let want = offline(&std::fs::read(&path).unwrap());
        assert!(!want.0.is_empty(), "{name}: no fixes offline");
        let (id, imu_id) = (format!("u{k}"), format!("r{k}"));
        let mut r = Run {
            fixes: node.subscriber(&services::gnss_fix(&id)).unwrap(),
            pulses: node.subscriber(&services::gnss_time_pulse(&id)).unwrap(),
            nav: node.subscriber(&services::gnss_nav_data(&id)).unwrap(),
            imu: node.subscriber(&services::imu_sample(&imu_id)).unwrap(),
            sky: node.subscriber(&services::gnss_sky(&id)).unwrap(),
            got: (Vec::new(), 0, 0, 0, 0),
            want,
        };
        let link = env.dir.join(&id);
        let link_s = link.display().to_string();
        env.spawn(
            &format!("feed-{id}"),
            &[
                "feed",
                &path.display().to_string(),
                "--pty",
                "--link",
                &link_s,
                "--baud",
                "115200",
                "--wait-reader",
                "--hold",
                "120",
            ],
        );
        env.wait_for_path(&link, Duration::from_secs(20));
        env.spawn(
            &format!("gnss-{id}"),
            &[
                "gnss",
                "--port",
                &link_s,
                "--baud",
                "115200",
                "--protocol",
                "auto",
                "--id",
                &id,
                "--imu-id",
                &imu_id,
            ],
        );
        let t0 = Instant::now();
        loop {
            env.assert_running();
            r.fixes.for_each(|f| r.got.0.push(*f)).unwrap();
            r.got.1 += r.pulses.for_each(|_| {}).unwrap();
            r.got.2 += r.nav.for_each(|_| {}).unwrap();
            r.got.3 += r.imu.for_each(|_| {}).unwrap();
            r.got.4 += r.sky.for_each(|_| {}).unwrap();
            let complete = r.got.0.len() >= r.want.0.len()
                && (r.got.1, r.got.2, r.got.3, r.got.4) >= (r.want.1, r.want.2, r.want.3, r.want.4);
            if complete || t0.elapsed() > Duration::from_secs(60) {
                break;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        println!("{name}: played in {:.1} s", t0.elapsed().as_secs_f64());
        env.kill9(&format!("gnss-{id}"));
        env.kill9(&format!("feed-{id}"));
        runs.push(r);
    }
    for (r, name) in runs.iter().zip(captures) {
        let (got, want) = (&r.got, &r.want);
        println!(
            "{name}: fixes {}/{}, time pulses {}/{}, subframes {}/{}, IMU samples {}/{}, skies {}/{} (live/offline)",
            got.0.len(),
            want.0.len(),
            got.1,
            want.1,
            got.2,
            want.2,
            got.3,
            want.3,
            got.4,
            want.4
        );
        assert_eq!(
            (got.0.len(), got.1, got.2, got.3, got.4),
            (want.0.len(), want.1, want.2, want.3, want.4),
            "{name}"
        );
        for (a, b) in got.0.iter().zip(&want.0) {
            let floats = [
                (a.lat_deg, b.lat_deg),
                (a.lon_deg, b.lon_deg),
                (a.alt_msl_m, b.alt_msl_m),
                (a.vel_n_mps, b.vel_n_mps),
                (a.h_acc_m, b.h_acc_m),
                (a.s_acc_mps, b.s_acc_mps),
            ];
            assert!(
                a.utc_ns == b.utc_ns && a.mode == b.mode && floats.iter().all(|(x, y)| same(*x, *y)),
                "{name}: live {a:?}\noffline {b:?}"
            );
        }
    }
    // The captures hold what the README says they do.
    assert!(runs[0].want.3 > 100, "neo-m8l: {} IMU samples", runs[0].want.3);
    assert!(runs[1].want.1 > 100, "m8t-time: {} time pulses", runs[1].want.1);
    assert!(runs[2].want.2 > 500, "glo: {} subframes", runs[2].want.2);
    assert!(
        runs.iter().all(|r| r.want.4 > 10),
        "skies: {:?}",
        runs.iter().map(|r| r.want.4).collect::<Vec<_>>()
    );
    drop((runs, node));
    env.finish();
}
