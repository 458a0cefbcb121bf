//! The real GPS sky of the tests that need satellites: the navigation data of gpsd's u-blox
//! captures as navsync's driver publishes it, the almanac and ionosphere of
//! `ublox-ned-m8t-sbfrx3` (a complete 12.5-minute almanac cycle), and the tests' own noise.
//! Nothing here comes from navsync's simulator.

#![allow(dead_code)]

use std::collections::BTreeMap;

use navsync_drivers::gnss::capture::gpsd_header;
use navsync_drivers::gnss::{Decoder, GnssDecoder, GnssExtra, Protocol};
use navsync_estimator::gnss::lnav::{self, Subframe};
use navsync_estimator::gnss::orbit::Orbit;
use navsync_estimator::gnss::spp::Klobuchar;
use navsync_shared::samples::GnssNavData;
use navsync_tests::shared_material;

/// The RXM-SFRBX of a capture, as the GNSS driver publishes them.
pub fn nav_data(bytes: &[u8]) -> Vec<GnssNavData> {
    let (header, _) = gpsd_header(bytes);
    let mut d = Decoder::new(Protocol::Auto);
    let mut out = Vec::new();
    d.push_extras(bytes.get(header..).unwrap_or(&[]), 0, 0, &mut |_| {}, &mut |x| {
        if let GnssExtra::NavData(n) = x {
            out.push(*n);
        }
    });
    out
}

/// The constellation of the m8t capture: every healthy satellite's almanac orbit by PRN and
/// the broadcast ionosphere.
pub struct RealSky {
    /// Almanac orbits by PRN.
    pub almanac: BTreeMap<u8, Orbit>,
    /// The ionosphere page's Klobuchar model.
    pub iono: Klobuchar,
}

impl RealSky {
    /// Decodes the almanac and the ionosphere of `ublox-ned-m8t-sbfrx3`.
    pub fn m8t() -> Self {
        let dir = shared_material("corpora/gpsd-ubx");
        let bytes = std::fs::read(dir.join("ublox-ned-m8t-sbfrx3.log")).expect("the m8t capture");
        let mut almanac = BTreeMap::new();
        let mut iono = None;
        for n in nav_data(&bytes).iter().filter(|n| n.gnss_id == 0) {
            let len = usize::from(n.num_words).min(n.words.len());
            match lnav::decode(&n.words[..len]).map(|d| d.subframe) {
                Ok(Subframe::Almanac(a)) if a.health == 0 && a.sqrt_a > 0 => {
                    almanac.insert(a.sv, Orbit::from_almanac(&a));
                }
                Ok(Subframe::IonoUtc(u)) => iono = Some(Klobuchar::from_page(&u)),
                _ => {}
            }
        }
        assert!(almanac.len() >= 28, "{} healthy almanac pages", almanac.len());
        Self {
            almanac,
            iono: iono.expect("the ionosphere page"),
        }
    }
}

/// Deterministic standard normal numbers (xorshift64*, Box–Muller): the tests' own noise.
pub struct Normal(pub u64);

impl Normal {
    /// Uniform in (0, 1).
    pub fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        ((self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    /// Standard normal.
    pub fn next(&mut self) -> f64 {
        let (u1, u2) = (self.uniform(), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

/// A satellite seen from a receiver at GPS time `t` (s of week): what the tests' receivers
/// measure before their errors.
pub struct Sight {
    /// Signal travel time, s (iterated on the geometric range, Sagnac included).
    pub tau_s: f64,
    /// Satellite position at transmission in the reception's ECEF frame, m.
    pub sat_ecef_m: [f64; 3],
    /// Elevation and azimuth, rad.
    pub el_rad: f64,
    /// See `el_rad`.
    pub az_rad: f64,
    /// Geometric range rate (satellite minus receiver velocity along the line of sight), m/s.
    pub range_rate_mps: f64,
}

/// Satellite `orbit` seen at GPS time `t_s` from a receiver at `rx` (ECEF, m) moving at
/// `vel` (ECEF, m/s).
pub fn sight(orbit: &Orbit, rx: [f64; 3], vel: [f64; 3], t_s: f64) -> Sight {
    use navsync_estimator::gnss::spp::{C_M_S, elevation_azimuth, rotate_for_flight};
    let dist = |a: [f64; 3]| ((a[0] - rx[0]).powi(2) + (a[1] - rx[1]).powi(2) + (a[2] - rx[2]).powi(2)).sqrt();
    let mut tau = 0.075;
    let mut rot = [0.0; 3];
    for _ in 0..4 {
        rot = rotate_for_flight(orbit.position_ecef_m(t_s - tau), tau);
        tau = dist(rot) / C_M_S;
    }
    let (el_rad, az_rad) = elevation_azimuth(rx, rot);
    let vs = rotate_for_flight(orbit.velocity_ecef_mps(t_s - tau), tau);
    let r = dist(rot);
    Sight {
        tau_s: tau,
        sat_ecef_m: rot,
        el_rad,
        az_rad,
        range_rate_mps: (0..3).map(|j| (vs[j] - vel[j]) * (rot[j] - rx[j]) / r).sum(),
    }
}
