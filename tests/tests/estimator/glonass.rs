//! GLONASS through the path a receiver's raw data takes (`EphemerisStore`: navigation data in,
//! observations for single-point positioning and the tightly coupled filter out), on real
//! immediate data: `ublox-glo` (GLONASS only, 2023-06-28 in Moscow) carries strings 1–4 of
//! four satellites and the receiver's NAV-PVT, but no RXM-RAWX, and no raw GLONASS data exists
//! in the shared material. The pseudoranges are therefore made here, at the receiver's
//! position, from the decoded ephemerides by a path of their own: GLONASS time from the
//! NAV-PVT's UTC date (`glonass::seconds_since_tb`), not from a GPS time of week and a leap
//! second count as the store does. What they prove: the GPS ↔ GLONASS time handling, each
//! satellite's channel frequency, the ephemeris validity and the fourth receiver clock. What
//! they cannot: the receiver's GLONASS inter-frequency biases (given a σ, not measured here).

use navsync_drivers::gnss::capture::gpsd_header;
use navsync_drivers::gnss::ubx::framer::{Frame, UbxFramer};
use navsync_drivers::gnss::ubx::messages::{self, Message};
use navsync_estimator::gnss::glonass::{self, GloStore};
use navsync_estimator::gnss::ranges::{EphemerisStore, L1_HZ, RangeBuildCounts};
use navsync_estimator::gnss::spp::{self, C_M_S, SppSettings};
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::{GnssRaw, RawMeasurement};
use navsync_shared::time::gps_ns_from_utc_ns;
use navsync_tests::shared_material;

use crate::gps_sky::nav_data;

/// The receiver's clock bias in the made epochs, s.
const CLOCK_S: f64 = 3.1e-4;
const WEEK_NS: i64 = 604_800_000_000_000;

/// The capture's NAV-PVT fixes: (UTC ns, ECEF m).
fn fixes(bytes: &[u8]) -> Vec<(i64, [f64; 3])> {
    let (header, _) = gpsd_header(bytes);
    let mut out = Vec::new();
    UbxFramer::new().push(&bytes[header..], 0, 0, &mut |f| {
        if let Frame::Ubx { class, id, payload, .. } = f
            && let Ok(Message::NavPvt(p)) = messages::decode(class, id, payload)
            && p.fix_type >= 3
        {
            let utc = p.utc_second_ns();
            let rx =
                navsync_shared::earth::geodetic_to_ecef(p.lat_deg.to_radians(), p.lon_deg.to_radians(), p.height_m);
            out.push((utc, rx));
        }
    });
    out
}

/// The raw epoch a receiver at `rx` with clock bias [`CLOCK_S`] would report at UTC `utc_ns`:
/// each healthy satellite of `glo` above 10° on channel k = slot mod 14 − 7, its range with
/// the flight time (Earth rotation included), the satellite clock and the troposphere; no
/// ionosphere (GLONASS broadcasts none). GPS − UTC 18 s; `leap_s`/`rec_stat` as the receiver
/// would report them.
fn epoch(glo: &GloStore, rx: [f64; 3], utc_ns: i64, leap_s: i16, rec_stat: u8) -> GnssRaw {
    let g = navsync_shared::earth::geodetic_from_ecef(rx[0], rx[1], rx[2]).unwrap();
    let gps_ns = gps_ns_from_utc_ns(utc_ns);
    let mut raw = GnssRaw::zeroed();
    raw.rcv_tow_s = gps_ns.rem_euclid(WEEK_NS) as f64 * 1e-9 + CLOCK_S;
    raw.week = gps_ns.div_euclid(WEEK_NS) as u16;
    (raw.leap_s, raw.rec_stat) = (leap_s, rec_stat);
    for slot in 1..=24u8 {
        let Some(e) = glo.ephemeris(slot).filter(|e| e.healthy()) else {
            continue;
        };
        let (mut tau, mut sat, mut dt_sv) = (0.075f64, [0.0; 3], 0.0f64);
        for _ in 0..5 {
            // Sent at GLONASS time t_rx − τ; the satellite's clock then read dt_sv more.
            let dt = glonass::seconds_since_tb(e.tb_s, utc_ns - (tau * 1e9).round() as i64);
            dt_sv = e.clock_offset_s(dt);
            sat = spp::rotate_for_flight(e.state_at(dt).0, tau);
            tau = (0..3).map(|i| (sat[i] - rx[i]).powi(2)).sum::<f64>().sqrt() / C_M_S;
        }
        let (el, _) = spp::elevation_azimuth(rx, sat);
        if el < 10f64.to_radians() {
            continue;
        }
        let k = usize::from(raw.num_meas);
        raw.meas[k] = RawMeasurement {
            pseudorange_m: C_M_S * (tau + CLOCK_S - dt_sv)
                + spp::troposphere_delay_m(g.lat_deg.to_radians(), g.height_m, el),
            doppler_hz: f32::NAN,
            pseudorange_std_m: 0.5,
            gnss_id: 6,
            sv_id: slot,
            freq_id: slot % 14,
            cno_dbhz: 42,
            trk_stat: 1,
            ..RawMeasurement::zeroed()
        };
        raw.num_meas += 1;
    }
    raw
}

/// Every satellite of the capture's last minutes solved: the receiver's position within 1 cm
/// and its GLONASS clock within 1 cm, with the receiver's leap seconds and with the table's
/// (the receiver not yet knowing them). A leap second count one off puts the solution
/// kilometres away; an epoch an hour after the ephemerides' t_b (valid ±30 min) has none.
#[test]
fn glonass_pseudoranges_solve_with_real_immediate_data() {
    let bytes = std::fs::read(shared_material("corpora/gpsd-ubx").join("ublox-glo.log")).unwrap();
    let (mut store, mut glo) = (EphemerisStore::default(), GloStore::default());
    for n in nav_data(&bytes).iter().filter(|n| n.gnss_id == 6) {
        store.on_nav_data(n);
        glo.on_words(n.sv_id, &n.words[..usize::from(n.num_words).min(n.words.len())]);
    }
    assert!(store.other_ephemerides >= 4, "{} ephemerides", store.other_ephemerides);
    let fixes = fixes(&bytes);
    println!("{} NAV-PVT fixes", fixes.len());
    let settings = SppSettings::default();
    let solve = |raw: &GnssRaw, counts: &mut RangeBuildCounts| {
        let obs = store.system_observations(raw, &[6], counts);
        spp::solve(&obs, None, raw.rcv_tow_s, [0.0; 3], &settings)
    };
    let (mut worst, mut worst_clock, mut solved) = (0f64, 0f64, 0);
    for &(utc, rx) in fixes.iter().rev().step_by(12).take(10) {
        for (leap, stat) in [(18, 1), (0, 0)] {
            let raw = epoch(&glo, rx, utc, leap, stat);
            let mut counts = RangeBuildCounts::default();
            let s =
                solve(&raw, &mut counts).unwrap_or_else(|e| panic!("{e:?}: {} satellites, {counts:?}", raw.num_meas));
            assert_eq!(s.used_per_system[3], usize::from(raw.num_meas));
            let e = (0..3).map(|i| (s.ecef_m[i] - rx[i]).powi(2)).sum::<f64>().sqrt();
            worst = worst.max(e);
            worst_clock = worst_clock.max((s.clock_biases_m[3] - C_M_S * CLOCK_S).abs());
            solved += 1;
            // The filter's epoch: every satellite, its carrier on its own channel.
            let r = store.range_epoch(&raw, 0, 0.0, &mut RangeBuildCounts::default());
            assert_eq!(r.sats().len(), usize::from(raw.num_meas));
            for (sat, m) in r.sats().iter().zip(&raw.meas) {
                let f = 1_602.0e6 + (f64::from(m.freq_id) - 7.0) * 562.5e3;
                assert_eq!((sat.gnss_id, sat.sv), (6, m.sv_id));
                assert!(
                    (sat.iono_scale - (L1_HZ / f).powi(2)).abs() < 1e-12,
                    "{}",
                    sat.iono_scale
                );
            }
        }
    }
    println!("GLONASS SPP at {solved} epochs: worst position error {worst:.4} m, clock {worst_clock:.4} m");
    assert!(
        solved == 20 && worst < 0.01 && worst_clock < 0.01,
        "{worst} m, {worst_clock} m"
    );

    let (utc, rx) = *fixes.last().unwrap();
    let mut counts = RangeBuildCounts::default();
    let off = solve(&epoch(&glo, rx, utc, 17, 1), &mut counts)
        .map(|s| (0..3).map(|i| (s.ecef_m[i] - rx[i]).powi(2)).sum::<f64>().sqrt());
    println!("with GPS − UTC given as 17 s: {off:?}");
    assert!(off.is_err() || off.is_ok_and(|e| e > 100.0), "{off:?}");
    let late = epoch(&glo, rx, utc + 3_600_000_000_000, 18, 1);
    let mut counts = RangeBuildCounts::default();
    assert!(store.system_observations(&late, &[6], &mut counts).is_empty());
    assert_eq!(counts.no_ephemeris, u64::from(late.num_meas));
    assert!(late.num_meas >= 1, "{} satellites an hour later", late.num_meas);
}
