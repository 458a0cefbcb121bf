//! A receiver's raw measurements of one epoch made ready for tightly coupled fusion: the
//! broadcast ephemerides collected from the navigation data (GPS LNAV subframes 1–3 of one
//! issue, IS-GPS-200N §20.3.4.4 for IODE/IODC; the ionosphere page), and each GPS L1 C/A
//! pseudorange and Doppler paired with its satellite's position, velocity and clock at the
//! time of transmission. What depends on the receiver's position (the Earth's rotation during
//! the flight, elevation, ionosphere, troposphere) is left to the filter, which knows it.

use navsync_wire::samples::{GnssNavData, GnssRaw};

use super::lnav::{self, Ephem1, Ephem2, Ephem3, Subframe};
use super::orbit::Orbit;
use super::spp::{C_M_S, Klobuchar};

/// Satellites one [`RangeEpoch`] holds (the strongest first when a receiver tracks more).
pub const MAX_RANGE_SATS: usize = 16;
/// GPS L1 carrier frequency, Hz (IS-GPS-200 §3.3.1.1).
pub const L1_HZ: f64 = 1_575.42e6;
/// u-blox `gnssId` of GPS.
pub const GNSS_ID_GPS: u8 = 0;
/// Highest GPS PRN.
const MAX_PRN: usize = 32;
/// An ephemeris is used up to this far from its t_oe, s (the 4 h curve fit of IS-GPS-200
/// §20.3.4.4 is ±2 h; an hour of margin for a receiver that did not get the next issue yet).
pub const EPHEMERIS_VALID_S: f64 = 3.0 * 3600.0;

/// One satellite's measurements with its broadcast state at transmission.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SatRange {
    /// PRN.
    pub sv: u8,
    /// Carrier-to-noise density, dB-Hz.
    pub cno_dbhz: u8,
    /// Pseudorange corrected for the satellite clock, ρ + c·δt_sv, m: it models
    /// r + c·δt_r + I + T (geometric range, receiver clock, ionosphere, troposphere).
    pub pseudorange_m: f64,
    /// Range rate corrected for the satellite clock drift, −λ_L1·D + c·δṫ_sv, m/s: it models
    /// the geometric range rate plus c·δṫ_r. NaN without a Doppler.
    pub range_rate_mps: f64,
    /// Satellite position at transmission, ECEF of that instant, m.
    pub sat_ecef_m: [f64; 3],
    /// Satellite velocity at transmission, ECEF, m/s.
    pub sat_vel_mps: [f64; 3],
    /// 1σ of the pseudorange the receiver reports (0 when it reports none), at least the
    /// ephemeris's user range accuracy, m.
    pub pseudorange_std_m: f64,
    /// 1σ of the range rate the receiver reports (0 when it reports none), m/s.
    pub range_rate_std_mps: f64,
}

/// The GPS measurements of one receiver epoch, ready for the filter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangeEpoch {
    /// Host time of the epoch before the Δ correction, ns (as a fix's stamp: the epoch mapped
    /// through the PPS clock model under hardware sync, the receipt time under software sync).
    pub stamp_host_ns: i64,
    /// GPS time of the measurements, s of week (the receiver's time minus its clock bias as
    /// estimated when the epoch was built).
    pub tow_s: f64,
    /// The broadcast ionosphere, when its page was received.
    pub iono: Option<Klobuchar>,
    /// Satellites in `sats`.
    pub count: u8,
    /// The satellites, `count` of them.
    pub sats: [SatRange; MAX_RANGE_SATS],
}

impl RangeEpoch {
    /// The satellites of this epoch.
    pub fn sats(&self) -> &[SatRange] {
        &self.sats[..usize::from(self.count).min(MAX_RANGE_SATS)]
    }
}

/// What [`EphemerisStore::range_epoch`] left out of an epoch, by reason.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RangeBuildCounts {
    /// Signals other than GPS L1 C/A (other constellations are not modelled yet).
    pub other_signals: u64,
    /// GPS signals whose pseudorange the receiver marks invalid.
    pub invalid: u64,
    /// GPS satellites without a complete, healthy, current ephemeris (URA index 15, no
    /// accuracy prediction, counts as unhealthy).
    pub no_ephemeris: u64,
    /// Satellites beyond [`MAX_RANGE_SATS`] (the weakest are dropped).
    pub over_capacity: u64,
}

/// The subframes 1–3 last received from one satellite and the ephemeris they made.
#[derive(Debug, Clone, Copy, Default)]
struct SatEphemeris {
    s1: Option<Ephem1>,
    s2: Option<Ephem2>,
    s3: Option<Ephem3>,
    orbit: Option<Orbit>,
    healthy: bool,
    /// The user range accuracy of the issue, m (0: not broadcast, an orbit from elsewhere).
    ura_m: f64,
}

/// The nominal user range accuracy of URA index `n`, m (IS-GPS-200 §20.3.3.3.1.3:
/// X = 2^(1 + N/2) for N ≤ 6, 2^(N − 2) for 6 < N < 15); `None` for N = 15, "no accuracy
/// prediction available", which the store treats as an unusable satellite.
pub fn ura_m(n: u8) -> Option<f64> {
    match n {
        0..=6 => Some(2f64.powf(1.0 + f64::from(n) / 2.0)),
        7..=14 => Some(2f64.powi(i32::from(n) - 2)),
        _ => None,
    }
}

/// The broadcast ephemerides and ionosphere collected from a receiver's navigation data.
#[derive(Debug, Clone)]
pub struct EphemerisStore {
    sats: [SatEphemeris; MAX_PRN],
    iono: Option<Klobuchar>,
    /// Subframes that failed the parity or preamble check.
    pub bad_subframes: u64,
    /// Ephemerides completed (a new issue of subframes 1–3).
    pub ephemerides: u64,
}

impl Default for EphemerisStore {
    fn default() -> Self {
        Self {
            sats: [SatEphemeris::default(); MAX_PRN],
            iono: None,
            bad_subframes: 0,
            ephemerides: 0,
        }
    }
}

impl EphemerisStore {
    /// Takes one navigation-data message: GPS LNAV subframes are decoded (parity checked) and
    /// subframes 1–3 of one issue make an ephemeris (IODC's 8 LSBs = IODE of subframes 2 and
    /// 3); subframe 4 page 18 sets the ionosphere. Others are ignored.
    pub fn on_nav_data(&mut self, d: &GnssNavData) {
        if d.gnss_id != GNSS_ID_GPS || usize::from(d.num_words) < 10 {
            return;
        }
        match lnav::decode(&d.words[..10]) {
            Ok(dec) => self.on_subframe(d.sv_id, &dec.subframe),
            Err(_) => self.bad_subframes += 1,
        }
    }

    /// Takes one decoded subframe of satellite `prn`.
    pub fn on_subframe(&mut self, prn: u8, sf: &Subframe) {
        let Some(e) = usize::from(prn).checked_sub(1).and_then(|i| self.sats.get_mut(i)) else {
            return;
        };
        match sf {
            Subframe::Ephem1(s) => e.s1 = Some(*s),
            Subframe::Ephem2(s) => e.s2 = Some(*s),
            Subframe::Ephem3(s) => e.s3 = Some(*s),
            Subframe::IonoUtc(p) => {
                self.iono = Some(Klobuchar::from_page(p));
                return;
            }
            _ => return,
        }
        if let (Some(s1), Some(s2), Some(s3)) = (e.s1, e.s2, e.s3)
            && (s1.iodc & 0xFF) as u8 == s2.iode
            && s2.iode == s3.iode
        {
            let orbit = Orbit::from_ephemeris(&s1, &s2, &s3);
            if e.orbit != Some(orbit) {
                self.ephemerides += 1;
            }
            e.orbit = Some(orbit);
            // IS-GPS-200 §20.3.3.3.1.4: the six-bit health's MSB summarises the navigation data.
            let ura = ura_m(s1.ura);
            e.healthy = s1.health & 0x20 == 0 && ura.is_some();
            e.ura_m = ura.unwrap_or(f64::INFINITY);
        }
    }

    /// Sets satellite `prn`'s orbit directly (an ephemeris from elsewhere, or a simulation's).
    pub fn insert_orbit(&mut self, prn: u8, orbit: Orbit) {
        if let Some(e) = usize::from(prn).checked_sub(1).and_then(|i| self.sats.get_mut(i)) {
            e.orbit = Some(orbit);
            e.healthy = true;
            e.ura_m = 0.0;
        }
    }

    /// Sets the broadcast ionosphere directly.
    pub fn set_iono(&mut self, iono: Klobuchar) {
        self.iono = Some(iono);
    }

    /// The usable orbit of satellite `prn` at GPS time `tow_s`.
    pub fn orbit(&self, prn: u8, tow_s: f64) -> Option<&Orbit> {
        self.usable_ephemeris(prn, tow_s).map(|(o, _)| o)
    }

    /// The usable orbit of satellite `prn` at GPS time `tow_s` (healthy, with an accuracy
    /// prediction, within its validity) and its user range accuracy, m.
    fn usable_ephemeris(&self, prn: u8, tow_s: f64) -> Option<(&Orbit, f64)> {
        let e = self.sats.get(usize::from(prn).checked_sub(1)?)?;
        let o = e.orbit.as_ref().filter(|_| e.healthy)?;
        let mut dt = tow_s - o.toe_s;
        dt -= (dt / 604_800.0).round() * 604_800.0;
        (dt.abs() <= EPHEMERIS_VALID_S).then_some((o, e.ura_m))
    }

    /// Satellites with a usable ephemeris at `tow_s`.
    pub fn usable(&self, tow_s: f64) -> usize {
        (1..=MAX_PRN as u8).filter(|p| self.orbit(*p, tow_s).is_some()).count()
    }

    /// The GPS L1 C/A measurements of `raw` with their satellites' states (IS-GPS-200
    /// §20.3.3.3.3.1: transmission time t = t_rx − ρ/c − δt_sv, whichever the receiver's clock
    /// error, since the pseudorange carries the same error), stamped `stamp_host_ns`;
    /// `rx_clock_bias_m` (c·δt_r, the filter's estimate, 0 when none) turns the receiver's time
    /// into GPS time. The strongest [`MAX_RANGE_SATS`] are kept.
    pub fn range_epoch(
        &self,
        raw: &GnssRaw,
        stamp_host_ns: i64,
        rx_clock_bias_m: f64,
        counts: &mut RangeBuildCounts,
    ) -> RangeEpoch {
        let mut out = RangeEpoch {
            stamp_host_ns,
            tow_s: raw.rcv_tow_s - rx_clock_bias_m / C_M_S,
            iono: self.iono,
            count: 0,
            sats: [SatRange::default(); MAX_RANGE_SATS],
        };
        let lambda = C_M_S / L1_HZ;
        let n = usize::from(raw.num_meas).min(raw.meas.len());
        for m in &raw.meas[..n] {
            if m.gnss_id != GNSS_ID_GPS || m.sig_id != 0 {
                counts.other_signals += 1;
                continue;
            }
            if m.trk_stat & 1 == 0 || !m.pseudorange_m.is_finite() || m.pseudorange_m <= 0.0 {
                counts.invalid += 1;
                continue;
            }
            let t0 = raw.rcv_tow_s - m.pseudorange_m / C_M_S;
            let Some((orbit, ura)) = self.usable_ephemeris(m.sv_id, t0) else {
                counts.no_ephemeris += 1;
                continue;
            };
            let dt_sv = orbit.clock_offset_s(t0);
            let t_tx = t0 - dt_sv;
            let doppler = f64::from(m.doppler_hz);
            let sat = SatRange {
                sv: m.sv_id,
                cno_dbhz: m.cno_dbhz,
                pseudorange_m: m.pseudorange_m + C_M_S * dt_sv,
                range_rate_mps: if doppler.is_finite() {
                    -lambda * doppler + C_M_S * orbit.clock_drift(t_tx)
                } else {
                    f64::NAN
                },
                sat_ecef_m: orbit.position_ecef_m(t_tx),
                sat_vel_mps: orbit.velocity_ecef_mps(t_tx),
                // The receiver's σ, at least the broadcast user range accuracy.
                pseudorange_std_m: f64::from(m.pseudorange_std_m).max(ura),
                range_rate_std_mps: (f64::from(m.doppler_std_hz) * lambda).max(0.0),
            };
            let count = usize::from(out.count);
            if count < MAX_RANGE_SATS {
                out.sats[count] = sat;
                out.count += 1;
                continue;
            }
            counts.over_capacity += 1;
            // Full: replace the weakest if this one is stronger.
            if let Some(weakest) = out.sats.iter_mut().min_by_key(|s| s.cno_dbhz)
                && weakest.cno_dbhz < sat.cno_dbhz
            {
                *weakest = sat;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gnss::lnav::{Ephem1, Ephem2, Ephem3};

    #[test]
    fn user_range_accuracy_follows_is_gps_200() {
        let x: Vec<Option<f64>> = [0u8, 1, 2, 6, 7, 14, 15].iter().map(|&n| ura_m(n)).collect();
        assert_eq!(x[0], Some(2.0));
        assert!((x[1].unwrap() - 2.828).abs() < 1e-3 && (x[2].unwrap() - 4.0).abs() < 1e-12);
        assert_eq!((x[3], x[4], x[5], x[6]), (Some(16.0), Some(32.0), Some(4096.0), None));
    }

    /// An ephemeris of one issue with URA index `ura`: usable (its accuracy as the σ floor)
    /// unless the index is 15.
    #[test]
    fn an_ephemeris_without_accuracy_prediction_is_not_used() {
        for (ura, usable) in [(0u8, true), (9, true), (15, false)] {
            let mut st = EphemerisStore::default();
            let s1 = Ephem1 {
                iodc: 7,
                ura,
                ..Ephem1::default()
            };
            st.on_subframe(5, &Subframe::Ephem1(s1));
            st.on_subframe(
                5,
                &Subframe::Ephem2(Ephem2 {
                    iode: 7,
                    ..Ephem2::default()
                }),
            );
            st.on_subframe(
                5,
                &Subframe::Ephem3(Ephem3 {
                    iode: 7,
                    ..Ephem3::default()
                }),
            );
            assert_eq!(st.ephemerides, 1);
            assert_eq!(st.orbit(5, 0.0).is_some(), usable, "URA index {ura}");
            if usable {
                assert_eq!(st.usable_ephemeris(5, 0.0).unwrap().1, ura_m(ura).unwrap());
            }
        }
    }
}
