//! The simulator's GPS side (`sim/src/gps.rs`) against the estimator's independent GPS models
//! (`estimator/src/gnss/`): the almanac of gpsd's `ublox-ned-m8t-sbfrx3` capture goes through
//! `navsync decode --yuma` into the simulator; its LNAV subframes must decode (parity, fields)
//! into ephemerides whose orbits and clocks equal the simulator's truth, its almanac
//! propagation must equal the estimator's almanac orbit years later, and a single-point
//! solution on its RXM-RAWX must land on the simulated antenna within the simulated errors.

use crate::gps_sky;

use navsync_drivers::gnss::{Decoder, GnssDecoder, GnssExtra, Protocol};
use navsync_estimator::gnss::lnav::{self, Subframe};
use navsync_estimator::gnss::orbit::Orbit;
use navsync_estimator::gnss::ranges::{EphemerisStore, RangeBuildCounts};
use navsync_estimator::gnss::spp::{self, C_M_S};
use navsync_shared::earth;
use navsync_shared::samples::{GnssNavData, GnssRaw};
use navsync_sim::gps::{self, Ephemeris, KlobucharRaw, Sky, SkyConfig};

/// `navsync decode --yuma` of the m8t capture, parsed by the simulator.
fn m8t_almanac() -> Vec<gps::AlmanacSat> {
    gps::parse_yuma(&navsync_tests::m8t_yuma()).expect("the YUMA navsync wrote")
}

/// The GPS raw measurements and navigation data of UBX bytes, through the driver's decoder.
fn decode(bytes: &[u8]) -> (Vec<GnssRaw>, Vec<GnssNavData>) {
    let (mut raws, mut navs) = (Vec::new(), Vec::new());
    let mut d = Decoder::new(Protocol::Ubx);
    d.push_extras(bytes, 0, 0, &mut |_| {}, &mut |x| match x {
        GnssExtra::Raw(r) => raws.push(*r),
        GnssExtra::NavData(n) => navs.push(*n),
        _ => {}
    });
    (raws, navs)
}

#[test]
fn the_simulated_almanac_orbits_and_subframes_match_the_estimators_models() {
    let almanac = m8t_almanac();
    assert!(almanac.len() >= 28, "{} satellites", almanac.len());
    // The same almanac pages as the estimator decodes them.
    let sky = gps_sky::RealSky::m8t();
    let iono = KlobucharRaw::from_si(
        SkyConfig::default().klobuchar_alpha,
        SkyConfig::default().klobuchar_beta,
    );
    // A week ≈ 6 years after the almanac's (full week from `navsync decode`'s modulo 1024).
    let (alm_week, later_week) = (
        2048 + i64::from(almanac[0].week),
        2048 + i64::from(almanac[0].week) + 320,
    );
    let mut worst_alm = 0f64;
    let mut worst_eph = (0f64, 0f64);
    for a in &almanac {
        // The estimator's sky holds the healthy satellites.
        let Some(est) = sky.almanac.get(&a.prn) else {
            assert_ne!(a.health, 0, "PRN {} is healthy but not in the estimator's sky", a.prn);
            continue;
        };
        // Years later: the simulator's issue carried forward vs the estimator's almanac orbit.
        let eph = Ephemeris::from_almanac(a, alm_week, later_week, 3600, 1);
        for t in [0.0, 3600.0, 7200.0] {
            let tk = (later_week - alm_week) as f64 * 604_800.0 + t - est.toe_s;
            let p_est = nalgebra::Vector3::from(est.position_ecef_m_tk(tk));
            worst_alm = worst_alm.max((eph.state(t).pos_m - p_est).norm());
        }
        // The subframes decode (parity, preamble) into an ephemeris with the same
        // orbit and clock as the simulator's truth.
        let mut store = EphemerisStore::default();
        for id in 1..=4 {
            let words = gps::subframe(&eph, id, 1234, &iono);
            let dec = lnav::decode(&words).unwrap_or_else(|e| panic!("PRN {} subframe {id}: {e}", a.prn));
            assert_eq!((dec.id, dec.tow_count), (id as u8, 1234));
            if let Subframe::Ephem1(s1) = dec.subframe {
                assert_eq!(i64::from(s1.wn), later_week % 1024);
                assert_eq!(s1.iodc, 1);
            }
            store.on_subframe(a.prn, &dec.subframe);
        }
        let orbit: Orbit = *store.orbit(a.prn, 3600.0).expect("an ephemeris from the subframes");
        for t in [0.0, 3600.0, 7200.0] {
            let truth = eph.state(t);
            let p = nalgebra::Vector3::from(orbit.position_ecef_m(t));
            worst_eph.0 = worst_eph.0.max((truth.pos_m - p).norm());
            worst_eph.1 = worst_eph.1.max((truth.clock_s - orbit.clock_offset_s(t)).abs() * C_M_S);
        }
    }
    println!(
        "{} satellites: sim issue vs estimator almanac 6 years on ≤ {worst_alm:.3} m; decoded ephemeris vs sim truth ≤ {:.2e} m, clock ≤ {:.2e} m",
        almanac.len(),
        worst_eph.0,
        worst_eph.1
    );
    // Quantisation to the ephemeris's LSBs (2⁻³¹ semicircles ≈ 4 cm at GPS radius).
    assert!(worst_alm < 0.5, "{worst_alm} m");
    assert!(worst_eph.0 < 1e-3 && worst_eph.1 < 1e-3, "{worst_eph:?}");
}

#[test]
fn a_single_point_solution_on_the_simulated_raw_data_finds_the_antenna() {
    let mut cfg = SkyConfig {
        constellation: m8t_almanac(),
        ..SkyConfig::default()
    };
    cfg.almanac = Some("m8t".into());
    let start_utc = 1_790_000_000_000_000_000i64;
    let mut sky = Sky::new(&cfg, 7, start_utc, 300.0).unwrap();
    // A static antenna in Munich, 300 epochs.
    let (lat, lon, h) = (48.137f64.to_radians(), 11.576f64.to_radians(), 567.0);
    let mut bytes = Vec::new();
    let mut clocks = Vec::new();
    for k in 0..300i64 {
        let utc = start_utc + k * 1_000_000_000;
        sky.write_epoch(
            utc,
            k as f64,
            [lat, lon, h],
            nalgebra::Vector3::zeros(),
            0.0,
            &mut bytes,
        );
        clocks.push(sky.receiver_clock().0 * C_M_S);
    }
    let (raws, navs) = decode(&bytes);
    assert_eq!(raws.len(), 300);
    let mut store = EphemerisStore::default();
    for n in &navs {
        store.on_nav_data(n);
    }
    assert_eq!(store.bad_subframes, 0);
    let (mut n, mut sum_h2, mut sum_v2, mut sats) = (0usize, 0.0, 0.0, 0usize);
    let (mut bias_err, mut nees) = (Vec::new(), 0.0);
    let truth_ecef = nalgebra::Vector3::from(earth::geodetic_to_ecef(lat, lon, h));
    for (raw, true_bias_m) in raws.iter().zip(&clocks) {
        let mut counts = RangeBuildCounts::default();
        let epoch = store.range_epoch(raw, 0, 0.0, &mut counts);
        if epoch.sats().len() < 4 {
            continue;
        }
        sats += epoch.sats().len();
        let settings = spp::SppSettings::default();
        let obs: Vec<spp::Observation> = epoch
            .sats()
            .iter()
            .map(|s| spp::Observation {
                sv: s.sv,
                pseudorange_m: s.pseudorange_m,
                sat_ecef_m: s.sat_ecef_m,
                sat_clock_s: 0.0,
                sigma_zenith_m: 2.0,
            })
            .collect();
        let Ok(sol) = spp::solve(&obs, epoch.iono.as_ref(), epoch.tow_s, [0.0; 3], &settings) else {
            continue;
        };
        let g = earth::geodetic_from_ecef(sol.ecef_m[0], sol.ecef_m[1], sol.ecef_m[2]).unwrap();
        let d = earth::ned_between(lat, lon, h, g.lat_deg.to_radians(), g.lon_deg.to_radians(), g.height_m);
        sum_h2 += d[0] * d[0] + d[1] * d[1];
        sum_v2 += d[2] * d[2];
        bias_err.push(sol.clock_bias_m - true_bias_m);
        // Covariance consistency: the position error (ECEF) normalised by the solution's own
        // covariance; 3 on average for a σ model that matches the errors.
        let e = nalgebra::Vector3::from(sol.ecef_m) - truth_ecef;
        let cov = sol.cov.fixed_view::<3, 3>(0, 0).into_owned();
        nees += cov
            .try_inverse()
            .map_or(f64::NAN, |inv| (e.transpose() * inv * e)[(0, 0)]);
        n += 1;
    }
    let nees = nees / n as f64;
    assert!(n >= 250, "{n} solutions of 300");
    let (hr, vr) = ((sum_h2 / n as f64).sqrt(), (sum_v2 / n as f64).sqrt());
    let clock = (bias_err.iter().map(|b| b * b).sum::<f64>() / n as f64).sqrt();
    println!(
        "SPP on the simulator's RAWX: {n} epochs, {:.1} satellites, horizontal RMS {hr:.2} m, vertical {vr:.2} m, clock {clock:.2} m RMS; mean NEES {nees:.2} (3 expected)",
        sats as f64 / n as f64
    );
    // Errors per satellite: 1 m broadcast, 1 m multipath, 0.5 m noise at zenith, ~30 % of
    // the ionosphere unmodelled; with HDOP ~1–2 a few metres.
    assert!(hr < 8.0 && vr < 15.0 && clock < 15.0, "{hr} {vr} {clock}");
    // The σ model (2 m at zenith over sin(elevation)) against the simulated errors: neither
    // far too optimistic nor far too pessimistic.
    assert!((0.3..10.0).contains(&nees), "mean NEES {nees}");
}

/// One crystal (issue 17): the default drive's IMU samples on the simulated receiver's
/// oscillator (`imu.unit[0].receiver_clock`: sample k ends when the receiver's clock reads a
/// multiple of 5 ms, that reading is its device time) and reaches the host 4 ms late with a
/// 0.4 ms scatter, as through the receiver's serial port. The tightly coupled estimator times
/// it by its receiver clock estimate and the PPS clock model; the device-clock regression,
/// which is all a loosely coupled estimator has, keeps the least transport delay of its
/// windows. Against the simulator's truth (the host time of each sample's instant), with a
/// 60 s blockage (300–360 s) and then one satellite for 60 s; the receiver clock itself in
/// `TimeState` against the simulated oscillator through the blockage (holdover) and its
/// recovery on one satellite.
#[test]
fn an_imu_on_the_receivers_crystal_is_timed_by_the_tightly_coupled_clock() {
    use navsync_estimator::offline::{self, Output};
    use navsync_estimator::pipeline::Pipeline;
    use navsync_estimator::settings::{Coupling, Settings};
    use navsync_estimator::time::device_timing::{DeviceTiming, DeviceTimingConfig};
    use navsync_shared::samples::{AnySample, IMU_FLAG_RECEIVER_CLOCK};
    use navsync_sim::gps::{ReceiverClock, SkyWindow};
    use navsync_sim::published::PublishedStream;
    use navsync_sim::scenario::{ImuUnitConfig, OutputProtocol, SimConfig};
    use navsync_sim::world::World;

    const BLOCKAGE: (f64, f64) = (300.0, 360.0);
    const ONE_SAT_END: f64 = 420.0;
    let mut cfg = SimConfig::default_drive();
    cfg.set_imu_count(1);
    cfg.imu.units = vec![ImuUnitConfig {
        offset_s: Some(4e-3),
        stamp_jitter_s: Some(0.4e-3),
        receiver_clock: true,
        ..ImuUnitConfig::default()
    }];
    cfg.gnss.protocol = OutputProtocol::Ubx;
    cfg.gnss.sky.almanac = Some("m8t".into());
    cfg.gnss.sky.constellation = m8t_almanac();
    let window = |start_s: f64, end_s: f64, n: usize| SkyWindow {
        start_s,
        duration_s: end_s - start_s,
        max_sats: Some(n),
        corridor_half_width_deg: None,
        elevation_mask_deg: None,
    };
    cfg.gnss.sky.windows = vec![window(BLOCKAGE.0, BLOCKAGE.1, 0), window(BLOCKAGE.1, ONE_SAT_END, 1)];
    // 2026-12-01 00:00 UTC, the start of the sim_sky benchmark.
    let (start_host, start_utc) = (1_000_000_000_000i64, 1_796_083_200_000_000_000i64);
    let truth = World::new(&cfg, start_host, start_utc).expect("scenario");
    let stream = PublishedStream::new(World::new(&cfg, start_host, start_utc).unwrap());
    let settings = {
        let mut s = Settings::default();
        s.nav.coupling = Coupling::Tight;
        s.imu.imu_model = cfg.imu.preset;
        s.nav.gnss_lever_arm_m = cfg.gnss.antenna_lever_arm_m;
        s
    };
    let mut pipeline = Pipeline::new(settings.pipeline_config());
    // The device-clock regression alone, on the same samples.
    let mut regression = DeviceTiming::new(DeviceTimingConfig::default());
    let imu = truth.imu(0).unwrap();
    let true_host = |seq: u64| truth.oscillator().host_ns_at_tau(imu.sample_time_s(seq));
    let tau_of = |host_ns: i64| truth.oscillator().tau_at_host(host_ns);
    // (scenario time, estimator error ns, regression error ns, receipt error ns)
    let mut rows: Vec<(f64, f64, f64, f64)> = Vec::new();
    // (scenario time, estimated receiver clock bias ns, its σ ns, true bias ns)
    let true_clock = ReceiverClock::new(&cfg.gnss.sky, cfg.seed, start_utc, truth.duration_s());
    let mut clocks: Vec<(f64, f64, f64, f64)> = Vec::new();
    let mut flagged = 0u64;
    let samples = stream.map(|p| {
        let mut tag = None;
        if let AnySample::Imu(s) = &p.sample {
            flagged += u64::from(s.flags & IMU_FLAG_RECEIVER_CLOCK != 0);
            let mapped = regression.retime(0, s);
            tag = Some((s.stamp.seq, mapped.stamp.host_ns, s.stamp.host_ns));
        }
        (p.sample, tag)
    });
    offline::run_ordered(
        &mut pipeline,
        Some("0"),
        samples,
        settings.delay_truth(),
        true,
        |o, tag| {
            if let Output::Time(t) = o
                && t.rx_clock_bias_ns.is_finite()
            {
                let tau = tau_of(t.computed_host_ns);
                clocks.push((
                    tau,
                    t.rx_clock_bias_ns,
                    t.rx_clock_bias_std_ns,
                    true_clock.bias_s(tau) * 1e9,
                ));
            }
            if let (Output::Nav(n), Some((seq, regressed, receipt))) = (o, tag) {
                let t = true_host(*seq);
                rows.push((
                    tau_of(t),
                    (n.host_ns - t) as f64,
                    (regressed - t) as f64,
                    (receipt - t) as f64,
                ));
            }
        },
    );
    let c = *pipeline.device_timing().counters();
    eprintln!("counters {c:?}, flagged samples {flagged}, states {}", rows.len());
    assert!(rows.len() > 100_000, "{} states", rows.len());
    let stats = |from: f64, to: f64, col: fn(&(f64, f64, f64, f64)) -> f64| {
        let v: Vec<f64> = rows.iter().filter(|r| r.0 >= from && r.0 < to).map(col).collect();
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let rms = (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        let max = v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        (mean, rms, max)
    };
    let spans = [
        ("tracking 100–300 s", 100.0, BLOCKAGE.0),
        ("blockage 300–360 s", BLOCKAGE.0, BLOCKAGE.1),
        ("one satellite 360–420 s", BLOCKAGE.1, ONE_SAT_END),
        ("tracking 420 s–end", ONE_SAT_END, 1e9),
    ];
    for (name, from, to) in spans {
        let (e, r, d) = (
            stats(from, to, |r| r.1),
            stats(from, to, |r| r.2),
            stats(from, to, |r| r.3),
        );
        eprintln!(
            "{name}: receiver clock mean {:.0} rms {:.0} max {:.0} ns; device-clock regression mean {:.0} rms {:.0} ns; receipt mean {:.0} rms {:.0} ns",
            e.0, e.1, e.2, r.0, r.1, d.0, d.1
        );
    }
    // The clock in TimeState: the last state before scenario time `t`.
    let clock_at = |t: f64| *clocks.iter().rfind(|c| c.0 < t).expect("a clock state");
    let (before, held) = (clock_at(BLOCKAGE.0), clock_at(BLOCKAGE.1));
    eprintln!(
        "receiver clock before the blockage: error {:.1} ns σ {:.1} ns; after 60 s of holdover: error {:.1} ns σ {:.1} ns",
        before.1 - before.3,
        before.2,
        held.1 - held.3,
        held.2
    );
    for after in [1.0, 5.0, 10.0, 30.0, 59.0] {
        let c = clock_at(BLOCKAGE.1 + after);
        eprintln!(
            "  one satellite for {after:>2} s: clock error {:.1} ns σ {:.1} ns",
            c.1 - c.3,
            c.2
        );
    }
    // Holdover: the error stays within its grown σ; one satellite brings σ down again.
    assert!((held.1 - held.3).abs() < 3.0 * held.2, "{held:?}");
    assert!(held.2 > before.2, "σ grows in holdover: {before:?} {held:?}");
    assert!(
        clock_at(BLOCKAGE.1 + 10.0).2 < held.2,
        "one satellite re-anchors the clock"
    );
    assert_eq!(flagged, pipeline.counters().imu_used + pipeline.counters().imu_invalid);
    // Every sample once the clock is anchored, through the blockage too (a TCXO's σ stays
    // far below the 1 µs limit for 60 s).
    assert!(c.receiver_clock as f64 > 0.9 * flagged as f64, "{c:?}");
    assert_eq!(c.receiver_clock_outliers, 0, "{c:?}");
    for (name, from, to) in spans {
        let (e, r) = (stats(from, to, |r| r.1), stats(from, to, |r| r.2));
        assert!(e.1 < 1_000.0, "{name}: receiver-clock timing {e:?} ns");
        assert!(e.1 * 100.0 < r.1, "{name}: receiver clock {e:?} vs regression {r:?} ns");
    }
}
