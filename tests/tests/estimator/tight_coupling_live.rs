//! The live estimator tightly coupled (`navsync estimator --coupling tight`) over iceoryx2:
//! the simulator drives the IMU, the PPS and an NMEA receiver through `navsync gnss` as in
//! the other live tests; this test plays a u-blox receiver's raw side on the receiver's
//! services: the real RXM-SFRBX subframes of SV 3 (its broadcast ephemeris) and the
//! ionosphere page from gpsd's `ublox-ned-m8t-sbfrx3` capture on `navsync/gnss/0/nav-data`,
//! and one RXM-RAWX epoch per second on `navsync/gnss/0/raw` with SV 3's pseudorange and
//! Doppler computed from that ephemeris, the simulator's truth and a receiver clock (bias
//! 10 µs, drift 0.2 ppm). The simulated GNSS time is set (`--utc-offset`) to SV 3's t_oe
//! and the drive starts right under it. The estimator aligns on the receiver's fixes, then fuses
//! the one satellite: its `Health` counts the ranges and the clock's anchoring, its
//! `TimeState` carries the receiver clock.
//!
//! A second test runs the whole chain with the simulator's own GPS sky: `sim` with
//! `[gnss.sky]` (the m8t capture's almanac through `navsync decode --yuma`) writes RXM-RAWX,
//! RXM-SFRBX and NAV-PVT into a pseudo-terminal, `gnss --protocol ubx` decodes and publishes
//! them, the estimator fuses them tightly coupled.

use crate::gps_sky;

use std::time::{Duration, Instant};

use navsync_estimator::gnss::lnav::{self, Subframe};
use navsync_estimator::gnss::ranges::{EphemerisStore, L1_HZ};
use navsync_estimator::gnss::spp::{self, C_M_S};
use navsync_shared::earth;
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::{GnssNavData, GnssRaw, RawMeasurement, SimTruth, Stamp, StampSource, TimeState};
use navsync_shared::services;
use navsync_shared::time::{gps_ns_from_utc_ns, monotonic_now_ns, realtime_now_ns};
use navsync_tests::{HealthWatch, TestEnv, shared_material, write_drive_scenario};

const WEEK_NS: i64 = 604_800 * 1_000_000_000;
/// The scenario's start as `write_drive_scenario` writes it (replaced by SV 3's
/// sub-satellite point).
const START: (f64, f64) = (48.137154, 11.576124);
/// The receiver clock: bias at the first epoch (m) and drift (m/s).
const BIAS0_M: f64 = 2998.0;
const DRIFT_MPS: f64 = 60.0;

#[test]
fn the_live_estimator_fuses_one_real_satellite() {
    let bytes = std::fs::read(shared_material("corpora/gpsd-ubx").join("ublox-ned-m8t-sbfrx3.log")).unwrap();
    let nav: Vec<GnssNavData> = gps_sky::nav_data(&bytes)
        .into_iter()
        .filter(|n| n.gnss_id == 0)
        .collect();
    // SV 3's subframes 1–3 and the ionosphere page: what the estimator will be sent.
    let mut sent = Vec::new();
    let mut toe_s = None;
    for n in &nav {
        let len = usize::from(n.num_words).min(n.words.len());
        match lnav::decode(&n.words[..len]).map(|d| d.subframe) {
            Ok(Subframe::Ephem1(_) | Subframe::Ephem3(_)) if n.sv_id == 3 => sent.push(*n),
            Ok(Subframe::Ephem2(e)) if n.sv_id == 3 => {
                toe_s = Some(f64::from(e.toe) * 16.0);
                sent.push(*n);
            }
            Ok(Subframe::IonoUtc(_)) => sent.push(*n),
            _ => {}
        }
    }
    let toe_s = toe_s.expect("SV 3's subframe 2");
    let mut store = EphemerisStore::default();
    for n in &sent {
        store.on_nav_data(n);
    }
    let orbit = *store.orbit(3, toe_s).expect("SV 3's ephemeris");
    // The drive starts under SV 3 at its t_oe (the scenario's start moved there).
    let best_tow = toe_s;
    let sat = orbit.position_ecef_m(toe_s);
    let under = earth::geodetic_from_ecef(sat[0], sat[1], sat[2]).expect("a sub-satellite point");
    // The simulated GNSS time starts 10 s before that (the same week as now).
    let now_gps = gps_ns_from_utc_ns(realtime_now_ns());
    let target_gps = now_gps.div_euclid(WEEK_NS) * WEEK_NS + ((best_tow - 10.0) * 1e9) as i64;
    let offset_s = (target_gps - now_gps) as f64 * 1e-9;

    let mut env = TestEnv::new("tightlive");
    let scenario = env.dir.join("drive.toml");
    write_drive_scenario(&scenario, 60.0, 1, 100.0);
    let text = std::fs::read_to_string(&scenario).unwrap();
    let moved = text.replace(
        &format!("lat_deg = {}\nlon_deg = {}", START.0, START.1),
        &format!("lat_deg = {:.6}\nlon_deg = {:.6}", under.lat_deg, under.lon_deg),
    );
    assert_ne!(moved, text, "the scenario's start was not found");
    std::fs::write(&scenario, moved).unwrap();
    let node = env.node("rawrx");
    let mut raw_pub = node.publisher::<GnssRaw>(&services::gnss_raw("0")).unwrap();
    let mut nav_pub = node.publisher::<GnssNavData>(&services::gnss_nav_data("0")).unwrap();
    let truth = node.subscriber::<SimTruth>(services::SIM_TRUTH).unwrap();
    let time = node.subscriber::<TimeState>(services::TIME_STATE).unwrap();
    let mut health = HealthWatch::new(&node, &["estimator"]);
    let offset = format!("{offset_s:.3}");
    spawn_tight_chain(&mut env, &scenario, &["--utc-offset", &offset], &[]);

    let lambda = C_M_S / L1_HZ;
    let iono = store_iono(&sent);
    let (mut seq, mut first_tow) = (0u64, None::<f64>);
    let mut last_nav = None::<Instant>;
    let mut latest_time = None::<TimeState>;
    let mut last_second = None::<i64>;
    let t0 = Instant::now();
    let done = loop {
        env.assert_running();
        if last_nav.is_none_or(|t| t.elapsed() > Duration::from_secs(2)) {
            for n in &sent {
                let mut m = *n;
                m.stamp = Stamp::host(monotonic_now_ns(), seq, StampSource::Receipt);
                nav_pub.publish(&m).unwrap();
            }
            last_nav = Some(Instant::now());
        }
        while let Some(tr) = truth.receive().unwrap() {
            // One raw epoch a second, at the first truth sample of each second.
            let second = tr.utc_ns.div_euclid(1_000_000_000);
            if last_second.replace(second) == Some(second) {
                continue;
            }
            let gps_ns = gps_ns_from_utc_ns(tr.utc_ns);
            let t = gps_ns.rem_euclid(WEEK_NS) as f64 * 1e-9;
            let since = t - *first_tow.get_or_insert(t);
            let bias = BIAS0_M + DRIFT_MPS * since;
            let (lat, lon) = (tr.lat_deg.to_radians(), tr.lon_deg.to_radians());
            let rx = earth::geodetic_to_ecef(lat, lon, tr.height_m);
            let v = nalgebra::Vector3::from(tr.vel_ned_mps);
            let vel: [f64; 3] = (spp::ned_from_ecef(lat, lon).transpose() * v).into();
            let g = gps_sky::sight(&orbit, rx, vel, t);
            let (tau, el, az) = (g.tau_s, g.el_rad, g.az_rad);
            let pr = tau * C_M_S + bias - C_M_S * orbit.clock_offset_s(t - tau)
                + C_M_S * iono.delay_s(lat, lon, el, az, t)
                + spp::troposphere_delay_m(lat, tr.height_m, el);
            let rr = g.range_rate_mps + DRIFT_MPS - C_M_S * orbit.clock_drift(t - tau);
            let mut raw = GnssRaw::zeroed();
            seq += 1;
            raw.stamp = Stamp::host(monotonic_now_ns(), seq, StampSource::Receipt);
            raw.rcv_tow_s = t + bias / C_M_S;
            raw.week = (gps_ns.div_euclid(WEEK_NS)) as u16;
            raw.leap_s = 18;
            let mut m = RawMeasurement::zeroed();
            m.pseudorange_m = pr;
            m.doppler_hz = (-rr / lambda) as f32;
            m.sv_id = 3;
            m.cno_dbhz = 45;
            m.trk_stat = 1;
            raw.meas[0] = m;
            raw.num_meas = 1;
            raw_pub.publish(&raw).unwrap();
        }
        while let Some(ts) = time.receive().unwrap() {
            latest_time = Some(ts);
        }
        health.poll();
        let used = health.counter("estimator", "ranges_used").unwrap_or(0);
        if used >= 10 && latest_time.is_some_and(|t| t.rx_clock_bias_ns.is_finite()) {
            break true;
        }
        if t0.elapsed() > Duration::from_secs(75) {
            break false;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let h = health.latest("estimator").cloned();
    let counter = |name: &str| h.as_ref().and_then(|h| h.counter(name)).unwrap_or(0);
    assert!(
        done,
        "ranges_used {}, clock_inits {}, epochs_not_tight {}, time state {:?}\nestimator log:\n{}",
        counter("ranges_used"),
        counter("clock_inits"),
        counter("ranges_epochs_not_tight"),
        latest_time.map(|t| t.rx_clock_bias_ns),
        env.log("estimator")
    );
    let ts = latest_time.unwrap();
    // The true bias at the time state's instant (its own host → GNSS time mapping).
    let at_gps = gps_ns_from_utc_ns(ts.utc_ns_at(ts.computed_host_ns));
    let since = at_gps.rem_euclid(WEEK_NS) as f64 * 1e-9 - first_tow.unwrap();
    let truth_bias_ns = (BIAS0_M + DRIFT_MPS * since) / C_M_S * 1e9;
    println!(
        "live, one satellite: ranges_used {}, range_rates_used {}, clock_inits {}; receiver clock {:.0} ns ± {:.0} (truth {truth_bias_ns:.0} ns), drift {:.3} ppm",
        counter("ranges_used"),
        counter("range_rates_used"),
        counter("clock_inits"),
        ts.rx_clock_bias_ns,
        ts.rx_clock_bias_std_ns,
        ts.rx_clock_drift * 1e6
    );
    assert_eq!(counter("clock_inits"), 1);
    assert_eq!(counter("ephemerides"), 1, "SV 3's ephemeris");
    assert!(counter("raw_epochs") >= 10 && counter("nav_data") >= 4);
    assert_eq!(counter("nav_data_bad"), 0);
    // One satellite: the bias is known to the INS's position along its line of sight.
    assert!(
        (ts.rx_clock_bias_ns - truth_bias_ns).abs() < 3.0 * ts.rx_clock_bias_std_ns + 50.0,
        "clock {} ns ± {} vs {truth_bias_ns} ns",
        ts.rx_clock_bias_ns,
        ts.rx_clock_bias_std_ns
    );
    assert!(
        (ts.rx_clock_drift * C_M_S - DRIFT_MPS).abs() < 5.0,
        "drift {}",
        ts.rx_clock_drift
    );
    drop((raw_pub, nav_pub, truth, time, health, node));
    env.finish();
}

/// Spawns `estimator --coupling tight` (GNSS 0, PPS 0, IMU 0), `pps --source sim`, `sim` on
/// `scenario` (one IMU straight into its service, the receiver on a pseudo-terminal, plus
/// `sim_args`) and `gnss` on that pseudo-terminal (plus `gnss_args`).
fn spawn_tight_chain(env: &mut TestEnv, scenario: &std::path::Path, sim_args: &[&str], gnss_args: &[&str]) {
    env.spawn(
        "estimator",
        &[
            "estimator",
            "--gnss",
            "0",
            "--pps",
            "0",
            "--imus",
            "0",
            "--coupling",
            "tight",
        ],
    );
    env.spawn("pps", &["pps", "--source", "sim", "--id", "0"]);
    let link = env.dir.join("gnss0");
    let (link_s, scen) = (link.display().to_string(), scenario.display().to_string());
    let mut sim = vec![
        "sim",
        "--scenario",
        &scen,
        "--imus",
        "1",
        "--pty-link",
        &link_s,
        "--imu-output",
        "direct",
    ];
    sim.extend_from_slice(sim_args);
    env.spawn("sim", &sim);
    env.wait_for_path(&link, Duration::from_secs(30));
    let mut gnss = vec!["gnss", "--port", &link_s, "--baud", "115200", "--id", "0"];
    gnss.extend_from_slice(gnss_args);
    env.spawn("gnss", &gnss);
}

/// The ionosphere of the subframes sent.
fn store_iono(sent: &[GnssNavData]) -> spp::Klobuchar {
    sent.iter()
        .find_map(|n| match lnav::decode(&n.words[..10]).map(|d| d.subframe) {
            Ok(Subframe::IonoUtc(p)) => Some(spp::Klobuchar::from_page(&p)),
            _ => None,
        })
        .expect("the ionosphere page")
}

#[test]
fn sim_to_ubx_driver_to_tight_estimator() {
    let mut env = TestEnv::new("tightchain");
    let capture = shared_material("corpora/gpsd-ubx").join("ublox-ned-m8t-sbfrx3.log");
    let out = env
        .command(&["decode", "--yuma", capture.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let almanac = env.dir.join("m8t.yuma");
    std::fs::write(&almanac, &out.stdout).unwrap();
    let scenario = env.dir.join("drive.toml");
    write_drive_scenario(&scenario, 60.0, 1, 100.0);
    let mut text = std::fs::read_to_string(&scenario).unwrap();
    // The IMU samples on the receiver's crystal and arrives 4 ms late (one crystal: the
    // estimator times it by the receiver clock it estimates).
    text.push_str(&format!(
        "\n[gnss]\nprotocol = \"ubx\"\n\n[gnss.sky]\nalmanac = \"{}\"\n\n[[imu.unit]]\nreceiver_clock = true\noffset_s = 0.004\n",
        almanac.display()
    ));
    std::fs::write(&scenario, text).unwrap();
    let node = env.node("chain");
    let time = node.subscriber::<TimeState>(services::TIME_STATE).unwrap();
    let mut health = HealthWatch::new(&node, &["estimator", "gnss-0"]);
    spawn_tight_chain(&mut env, &scenario, &[], &["--protocol", "ubx"]);
    let mut latest = None::<TimeState>;
    let t0 = Instant::now();
    let done = loop {
        env.assert_running();
        while let Some(ts) = time.receive().unwrap() {
            latest = Some(ts);
        }
        health.poll();
        let epochs = health.counter("estimator", "ranges_epochs_used").unwrap_or(0);
        let imu_timed = health.counter("estimator", "rx_clock_imu").unwrap_or(0);
        if epochs >= 15 && imu_timed > 0 && latest.is_some_and(|t| t.rx_clock_bias_ns.is_finite()) {
            break true;
        }
        if t0.elapsed() > Duration::from_secs(75) {
            break false;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let h = health.latest("estimator").cloned();
    let counter = |name: &str| h.as_ref().and_then(|h| h.counter(name)).unwrap_or(0);
    assert!(
        done,
        "raw_epochs {}, nav_data {}, ephemerides {}, ranges_epochs_used {}, clock_inits {}, rx_clock_imu {}\nestimator log:\n{}\ngnss log:\n{}",
        counter("raw_epochs"),
        counter("nav_data"),
        counter("ephemerides"),
        counter("ranges_epochs_used"),
        counter("clock_inits"),
        counter("rx_clock_imu"),
        env.log("estimator"),
        env.log("gnss")
    );
    let ts = latest.unwrap();
    println!(
        "sim → gnss --protocol ubx → estimator --coupling tight: raw epochs {}, subframes {}, ephemerides {}, ranges used {} in {} epochs, rejected {}; receiver clock {:.0} ± {:.0} ns, drift {:.3} ppm; IMU samples timed by it {} (waiting {}, outliers {})",
        counter("raw_epochs"),
        counter("nav_data"),
        counter("ephemerides"),
        counter("ranges_used"),
        counter("ranges_epochs_used"),
        counter("ranges_rejected"),
        ts.rx_clock_bias_ns,
        ts.rx_clock_bias_std_ns,
        ts.rx_clock_drift * 1e6,
        counter("rx_clock_imu"),
        counter("rx_clock_imu_waiting"),
        counter("rx_clock_imu_outliers")
    );
    assert_eq!(counter("nav_data_bad"), 0);
    assert_eq!(counter("rx_clock_imu_outliers"), 0);
    assert!(counter("ephemerides") >= 4, "ephemerides from the simulated subframes");
    assert!(counter("ranges_used") >= 4 * counter("ranges_epochs_used"));
    // The simulated receiver clock: 50 µs at the simulator's start, then 0.2 ppm (and a TCXO's
    // random walk): between 50 µs and 50 µs + 0.2 ppm × the time since the sim was spawned.
    let most_ns = 50_000.0 + 0.2e-6 * (t0.elapsed().as_secs_f64() + 2.0) * 1e9;
    assert!(
        (49_700.0..most_ns + 300.0).contains(&ts.rx_clock_bias_ns),
        "clock {} ns, expected 50 000 to {most_ns:.0} ns",
        ts.rx_clock_bias_ns
    );
    assert!(
        (ts.rx_clock_drift - 2e-7).abs() < 0.05e-6,
        "drift {}",
        ts.rx_clock_drift
    );
    drop((time, health, node));
    env.finish();
}
