//! The simulator's GPS side (`sim/src/gps.rs`) against the estimator's independent GPS models
//! (`estimator/src/gnss/`): the almanac of gpsd's `ublox-ned-m8t-sbfrx3` capture goes through
//! `navsync decode --yuma` into the simulator; its LNAV subframes must decode (parity, fields)
//! into ephemerides whose orbits and clocks equal the simulator's truth, its almanac
//! propagation must equal the estimator's almanac orbit years later, and a single-point
//! solution on its RXM-RAWX must land on the simulated antenna within the simulated errors.

mod gps_sky;

use std::process::Command;

use navsync_drivers::gnss::{Decoder, GnssDecoder, GnssExtra, Protocol};
use navsync_estimator::gnss::lnav::{self, Subframe};
use navsync_estimator::gnss::orbit::Orbit;
use navsync_estimator::gnss::ranges::{EphemerisStore, RangeBuildCounts};
use navsync_estimator::gnss::spp::{self, C_M_S};
use navsync_shared::earth;
use navsync_shared::samples::{GnssNavData, GnssRaw};
use navsync_sim::gps::{self, Ephemeris, KlobucharRaw, Sky, SkyConfig};
use navsync_tests::{navsync_bin, shared_material};

/// `navsync decode --yuma` of the m8t capture, parsed by the simulator.
fn m8t_almanac() -> Vec<gps::AlmanacSat> {
    let capture = shared_material("corpora/gpsd-ubx").join("ublox-ned-m8t-sbfrx3.log");
    let out = Command::new(navsync_bin())
        .args(["decode", "--yuma"])
        .arg(&capture)
        .output()
        .expect("navsync decode");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).unwrap();
    gps::parse_yuma(&text).expect("the YUMA navsync wrote")
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
    let mut sky = Sky::new(&cfg, 7, start_utc).unwrap();
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
    let mut bias_err = Vec::new();
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
        n += 1;
    }
    assert!(n >= 250, "{n} solutions of 300");
    let (hr, vr) = ((sum_h2 / n as f64).sqrt(), (sum_v2 / n as f64).sqrt());
    let clock = (bias_err.iter().map(|b| b * b).sum::<f64>() / n as f64).sqrt();
    println!(
        "SPP on the simulator's RAWX: {n} epochs, {:.1} satellites, horizontal RMS {hr:.2} m, vertical {vr:.2} m, clock {clock:.2} m RMS",
        sats as f64 / n as f64
    );
    // Errors per satellite: 1 m broadcast, 1 m multipath, 0.5 m noise at zenith, ~30 % of
    // the ionosphere unmodelled; with HDOP ~1–2 a few metres.
    assert!(hr < 8.0 && vr < 15.0 && clock < 15.0, "{hr} {vr} {clock}");
}
