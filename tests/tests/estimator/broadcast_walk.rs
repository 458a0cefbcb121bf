//! Galileo I/NAV and F/NAV, BeiDou D1 and GPS CNAV ephemerides of a real receiver's log (u-blox X20, the
//! rtklibexplorer walk of 2025-08-28: `datasets/rtklibexplorer-walk0827/source/gnss_1730.ubx`)
//! decoded through the path the driver takes (the UBX decoder's `GnssNavData` per
//! RXM-SFRBX, as published on `…/nav-data`) into `navsync_estimator::gnss::broadcast`.
//!
//! The counts against RTKLIB (rtklibexplorer demo5, `convbin -r ubx -v 3.04 -n nav.rnx -o
//! obs.rnx gnss_1730.ubx`): its navigation file has I/NAV (data source 513) ephemerides of
//! E07, E13, E26, E29, E33 and D1 ephemerides of C11, C21, C22, C34, C42, C43, C44, C50. navsync
//! completes those and two more I/NAV ones (E08 and E14, IODnav 45): RTKLIB completes an
//! I/NAV ephemeris only when word type 5 arrives after words 1–4 and 6 (the GST-UTC word),
//! and those two satellites' word 6 came after their last word 5 or not at all. Their orbits
//! equal convbin's F/NAV records of the same IODnav. F/NAV (E5a-I, sigId 3): the 11
//! ephemerides of convbin's records with data source 258, the same satellites and t0e.
//!
//! GPS CNAV (L2C sigId 4, L5 sigId 6; convbin does not decode it): the ephemerides of G08,
//! G10, G18, G23, G24, G27, G32, the satellites cssrlib 1.2.1's `RawNav.decode_gps_cnav`
//! completes from the same messages (its fields are compared in `gnss::cnav`'s unit tests);
//! where the satellite also sent a complete LNAV ephemeris, the two uploads put it within a few
//! metres of each other.

use std::collections::BTreeSet;

use crate::gps_sky::nav_data;
use navsync_estimator::gnss::broadcast::{NavCollector, NavEphemeris, carries_lnav};
use navsync_estimator::gnss::lnav::{self, Subframe};
use navsync_estimator::gnss::orbit::Orbit;
use navsync_tests::shared_material;

#[test]
fn walk_log_galileo_beidou_and_gps_cnav_ephemerides() {
    let path = shared_material("datasets/rtklibexplorer-walk0827/source/gnss_1730.ubx");
    let bytes = std::fs::read(&path).expect("the walk's UBX log");
    let mut nav = NavCollector::default();
    let (mut gal, mut bds, mut gps) = (BTreeSet::new(), BTreeSet::new(), BTreeSet::new());
    let mut fnav = BTreeSet::new();
    let mut usable = 0;
    // LNAV subframes 1–3 per PRN, and the CNAV orbits, to compare the two.
    let mut lnav_sf = std::collections::BTreeMap::<u8, [Option<Subframe>; 3]>::new();
    let mut cnav_orbits = Vec::new();
    for n in nav_data(&bytes) {
        let len = usize::from(n.num_words).min(n.words.len());
        if carries_lnav(n.gnss_id, n.sig_id) {
            let sf = lnav::decode(&n.words[..len]).expect("every L1 C/A subframe passes its parity");
            let k = match sf.subframe {
                Subframe::Ephem1(_) => 0,
                Subframe::Ephem2(_) => 1,
                Subframe::Ephem3(_) => 2,
                _ => continue,
            };
            lnav_sf.entry(n.sv_id).or_default()[k] = Some(sf.subframe);
            continue;
        }
        let Ok(Some(e)) = nav.on_words(n.gnss_id, n.sv_id, n.sig_id, &n.words[..len]) else {
            continue;
        };
        let b = e.broadcast();
        match e {
            NavEphemeris::Galileo(g) => gal.insert((g.sv, g.iod_nav())),
            NavEphemeris::GalileoFnav(g) => fnav.insert((g.sv, b.orbit.toe_s as u32)),
            NavEphemeris::Beidou(c) => bds.insert((c.sv, b.iod)),
            NavEphemeris::GpsCnav(g) => {
                cnav_orbits.push((g.sv, b.orbit));
                gps.insert((g.sv, b.iod))
            }
        };
        // Every ephemeris's satellite at t_oe is at a MEO/IGSO radius (20–45 Mm).
        let p = b.orbit.position_ecef_m(b.orbit.toe_s);
        let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        assert!((2.0e7..4.5e7).contains(&r), "{e:?}: r = {r} m");
        usable += usize::from(b.healthy && b.accuracy_m.is_finite());
    }
    let c = nav.counts;
    // Every I/NAV page pair (396), F/NAV page (98), D1 subframe (153) and CNAV message (148)
    // of the log passes its CRC/BCH.
    assert_eq!(
        (
            c.galileo_words,
            c.galileo_fnav_pages,
            c.beidou_subframes,
            c.gps_cnav_messages,
            c.rejected
        ),
        (396, 98, 153, 148, 0),
        "{c:?}"
    );
    // convbin's F/NAV records (data source 258): satellite and t0e (17:10 = 407400 s, …).
    let convbin_fnav = BTreeSet::from([
        (7, 407_400),
        (8, 407_400),
        (8, 408_000),
        (13, 406_800),
        (14, 407_400),
        (14, 408_000),
        (26, 407_400),
        (26, 408_000),
        (29, 405_000),
        (33, 407_400),
        (33, 408_000),
    ]);
    assert_eq!(fnav, convbin_fnav, "Galileo F/NAV");
    let sats = |s: &BTreeSet<(u8, u16)>| s.iter().map(|x| x.0).collect::<BTreeSet<u8>>();
    let convbin_gal = BTreeSet::from([7, 13, 26, 29, 33]);
    let convbin_bds = BTreeSet::from([11, 21, 22, 34, 42, 43, 44, 50]);
    assert!(sats(&gal).is_superset(&convbin_gal), "Galileo {gal:?}");
    assert_eq!(sats(&gal).len(), 7, "Galileo {gal:?}");
    assert_eq!(sats(&bds), convbin_bds, "BeiDou {bds:?}");
    assert_eq!((gal.len(), bds.len()), (7, 8));
    assert_eq!(
        sats(&gps),
        BTreeSet::from([8, 10, 18, 23, 24, 27, 32]),
        "GPS CNAV {gps:?}"
    );
    // C50 broadcasts SatH1 = 1 (as in convbin's record) and E14 (in its eccentric orbit)
    // E1-B and E5a signal health 1, out of service: the other 13 I/NAV and D1, 9 F/NAV and the
    // 7 GPS are usable.
    assert_eq!(usable, 13 + 9 + 7);
    // LNAV and CNAV of one satellite: separate uploads of one orbit, a few metres apart.
    let mut compared = 0;
    for (prn, sf) in &lnav_sf {
        let [
            Some(Subframe::Ephem1(s1)),
            Some(Subframe::Ephem2(s2)),
            Some(Subframe::Ephem3(s3)),
        ] = sf
        else {
            continue;
        };
        let lnav = Orbit::from_ephemeris(s1, s2, s3);
        for (_, cnav) in cnav_orbits.iter().filter(|(sv, _)| sv == prn) {
            let t = cnav.toe_s + 120.0;
            let (a, b) = (lnav.position_ecef_m(t), cnav.position_ecef_m(t));
            let d = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
            let dclk = (lnav.clock_offset_s(t) - cnav.clock_offset_s(t)) * 299_792_458.0;
            println!(
                "G{prn:02}: LNAV t_oe {} vs CNAV t_oe {}: {d:.2} m, clock {dclk:.2} m",
                lnav.toe_s, cnav.toe_s
            );
            assert!(d < 5.0 && dclk.abs() < 5.0, "G{prn:02}: {d} m, clock {dclk} m");
            compared += 1;
        }
    }
    assert!(compared >= 3, "{compared} satellites with both LNAV and CNAV");
}

/// `navsync decode --subframes` prints, after the GPS subframes, one JSON object per Galileo
/// I/NAV and F/NAV, BeiDou and GPS CNAV ephemeris with its system named (7, 11, 8 and 7 on the
/// walk's log), SI units.
#[test]
fn navsync_decode_prints_galileo_and_beidou_ephemerides() {
    let path = shared_material("datasets/rtklibexplorer-walk0827/source/gnss_1730.ubx");
    let out = std::process::Command::new(navsync_tests::navsync_bin())
        .args(["decode", "--subframes"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let eph: Vec<serde_json::Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter_map(|l| l.get("ephemeris").cloned())
        .collect();
    let count = |s: &str| eph.iter().filter(|e| e["system"] == s).count();
    assert_eq!(
        (
            count("galileo"),
            count("galileo_fnav"),
            count("beidou"),
            count("gps_cnav"),
            eph.len()
        ),
        (7, 11, 8, 7, 33)
    );
    let e07 = eph
        .iter()
        .find(|e| e["system"] == "galileo" && e["sv"] == 7)
        .expect("E07");
    assert_eq!(e07["w1"]["iod_nav"], 44);
    assert_eq!(e07["w1"]["toe_s"], 407_400.0);
    let c21 = eph
        .iter()
        .find(|e| e["system"] == "beidou" && e["sv"] == 21)
        .expect("C21");
    assert_eq!(c21["s1"]["toc_s"], 406_800.0);
}
