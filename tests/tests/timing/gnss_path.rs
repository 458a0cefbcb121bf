//! sim → pseudo-terminal → `navsync gnss` (serialport) → `navsync/gnss/{id}/fix`, checked fix by
//! fix against the simulator's truth: with a noise-free receiver every fix must carry its
//! epoch's exact UTC second and the true position to the precision of its NMEA fields
//! (lat/lon 1e−7 arc-minutes ≈ 0.2 mm, altitude 1 mm), and arrive d0 = 0.6 s after its epoch.

use std::time::{Duration, Instant};

use navsync_shared::earth;
use navsync_shared::samples::*;
use navsync_shared::services;
use navsync_shared::time::NS_PER_S;
use navsync_tests::TestEnv;

#[test]
fn fixes_reproduce_the_truth_epoch_by_epoch() {
    let _alone = navsync_tests::alone();
    let mut env = TestEnv::new("gpspath");
    let node = env.node("observer");
    let fix_sub = node.subscriber::<GnssFix>(&services::gnss_fix("0")).unwrap();
    let truth_sub = node.subscriber::<SimTruth>(services::SIM_TRUTH).unwrap();
    let scenario = concat!(env!("CARGO_MANIFEST_DIR"), "/data/gnss_exact.toml");
    let link = env.dir.join("gnss0");
    let link_s = link.display().to_string();
    env.spawn(
        "sim",
        &["sim", "--scenario", scenario, "--pty-link", &link_s, "--duration", "30"],
    );
    env.wait_for_path(&link, Duration::from_secs(20));
    env.spawn("gnss", &["gnss", "--port", &link_s, "--baud", "115200", "--id", "0"]);

    let (mut truth, mut fixes) = (Vec::new(), Vec::new());
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(28) && fixes.len() < 15 {
        std::thread::sleep(Duration::from_millis(100));
        env.assert_running();
        while let Some(t) = truth_sub.receive().unwrap() {
            truth.push(t);
        }
        while let Some(f) = fix_sub.receive().unwrap() {
            fixes.push(f);
        }
    }
    while let Some(t) = truth_sub.receive().unwrap() {
        truth.push(t);
    }
    assert!(fixes.len() >= 15, "only {} fixes\n{}", fixes.len(), env.log("gnss"));

    let mut compared = 0;
    for pair in fixes.windows(2) {
        assert_eq!(
            pair[1].utc_ns - pair[0].utc_ns,
            NS_PER_S,
            "consecutive epochs one second apart"
        );
    }
    for f in &fixes {
        assert_eq!(f.utc_ns.rem_euclid(NS_PER_S), 0, "epoch on a whole second");
        assert_eq!(f.mode, FixMode::Fix3d as u8);
        // Truth samples bracketing the epoch in UTC.
        let Some(i) = truth.iter().position(|t| t.utc_ns >= f.utc_ns) else {
            continue;
        };
        if i == 0 {
            continue;
        }
        let (a, b) = (&truth[i - 1], &truth[i]);
        let w = (f.utc_ns - a.utc_ns) as f64 / (b.utc_ns - a.utc_ns) as f64;
        let lerp = |x: f64, y: f64| x + (y - x) * w;
        let lat = lerp(a.lat_deg, b.lat_deg);
        let lon = lerp(a.lon_deg, b.lon_deg);
        let h = lerp(a.height_m, b.height_m);
        let d = earth::ned_between(
            lat.to_radians(),
            lon.to_radians(),
            h,
            f.lat_deg.to_radians(),
            f.lon_deg.to_radians(),
            f.height_m(),
        );
        assert!(
            d[0].abs() < 0.002 && d[1].abs() < 0.002,
            "fix at {} off by {d:?} m",
            f.utc_ns
        );
        assert!(d[2].abs() < 0.002, "altitude off by {} m", d[2]);
        // Receipt of the first byte: host time of the epoch (from the truth's host↔UTC pairs) + d0.
        let epoch_host = a.host_ns
            + ((f.utc_ns - a.utc_ns) as f64 * (b.host_ns - a.host_ns) as f64 / (b.utc_ns - a.utc_ns) as f64) as i64;
        let d0 = (f.stamp.host_ns - epoch_host) as f64 * 1e-9;
        assert!(
            (0.6..0.65).contains(&d0),
            "receipt {d0} s after the epoch (simulated 0.6 s)"
        );
        compared += 1;
    }
    println!("{} fixes, {compared} compared with the truth", fixes.len());
    assert!(compared >= 12, "only {compared} fixes compared");
    drop((fix_sub, truth_sub, node));
    env.finish();
}
