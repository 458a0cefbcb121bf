//! Galileo I/NAV and BeiDou D1 ephemerides of a real receiver's log (u-blox X20, the
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
//! equal convbin's F/NAV records of the same IODnav.

use std::collections::BTreeSet;

use crate::gps_sky::nav_data;
use navsync_estimator::gnss::broadcast::{NavCollector, NavEphemeris};
use navsync_tests::shared_material;

#[test]
fn walk_log_galileo_and_beidou_ephemerides() {
    let path = shared_material("datasets/rtklibexplorer-walk0827/source/gnss_1730.ubx");
    let bytes = std::fs::read(&path).expect("the walk's UBX log");
    let mut nav = NavCollector::default();
    let (mut gal, mut bds) = (BTreeSet::new(), BTreeSet::new());
    let mut usable = 0;
    for n in nav_data(&bytes) {
        let len = usize::from(n.num_words).min(n.words.len());
        let Ok(Some(e)) = nav.on_words(n.gnss_id, n.sv_id, n.sig_id, &n.words[..len]) else {
            continue;
        };
        let b = e.broadcast();
        match e {
            NavEphemeris::Galileo(g) => gal.insert((g.sv, g.iod_nav())),
            NavEphemeris::Beidou(c) => bds.insert((c.sv, b.iod)),
        };
        // Every ephemeris's satellite at t_oe is at a MEO/IGSO radius (20–45 Mm).
        let p = b.orbit.position_ecef_m(b.orbit.toe_s);
        let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        assert!((2.0e7..4.5e7).contains(&r), "{e:?}: r = {r} m");
        usable += usize::from(b.healthy && b.accuracy_m.is_finite());
    }
    let c = nav.counts;
    // Every I/NAV page pair (396) and every D1 subframe (153) of the log passes its CRC/BCH.
    assert_eq!(
        (c.galileo_words, c.beidou_subframes, c.rejected),
        (396, 153, 0),
        "{c:?}"
    );
    let sats = |s: &BTreeSet<(u8, u16)>| s.iter().map(|x| x.0).collect::<BTreeSet<u8>>();
    let convbin_gal = BTreeSet::from([7, 13, 26, 29, 33]);
    let convbin_bds = BTreeSet::from([11, 21, 22, 34, 42, 43, 44, 50]);
    assert!(sats(&gal).is_superset(&convbin_gal), "Galileo {gal:?}");
    assert_eq!(sats(&gal).len(), 7, "Galileo {gal:?}");
    assert_eq!(sats(&bds), convbin_bds, "BeiDou {bds:?}");
    assert_eq!((gal.len(), bds.len()), (7, 8));
    // C50 broadcasts SatH1 = 1 (as in convbin's record) and E14 (in its eccentric orbit)
    // E1-B signal health 1, out of service: the other 13 are usable.
    assert_eq!(usable, 13);
}

/// `navsync decode --subframes` prints, after the GPS subframes, one JSON object per Galileo
/// and BeiDou ephemeris with its system named (7 and 8 on the walk's log), SI units.
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
    assert_eq!((count("galileo"), count("beidou"), eph.len()), (7, 8, 15));
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
