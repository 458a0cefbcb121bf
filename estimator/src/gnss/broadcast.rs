//! The navigation data words of every system the decoders read, routed by u-blox `gnssId` and
//! `sigId` (UBX-RXM-SFRBX, as a [`GnssNavData`](navsync_wire::samples::GnssNavData) carries
//! them) to their decoders and assembled per satellite into ephemerides: Galileo I/NAV
//! ([`galileo`](super::galileo): E1-B sigId 1, E5b-I sigId 5; F/NAV [`fnav`](super::fnav):
//! E5a-I sigId 3), BeiDou ([`beidou`]: D1 of
//! the MEO/IGSO PRNs on B1I sigId 0, B2I sigId 2, B3I sigId 4; D2 of the GEO PRNs on sigId 1,
//! 3, 10) and GPS CNAV ([`cnav`](super::cnav): L2 CL/CM sigId 3, 4, L5 I/Q sigId 6, 7). GPS
//! LNAV (L1 C/A, sigId 0: [`carries_lnav`]) keeps its own path
//! ([`ranges::EphemerisStore`](super::ranges::EphemerisStore)).
//!
//! Every ephemeris yields a [`BroadcastEphemeris`]: the system-neutral part an ephemeris store
//! keyed by (gnss id, sv id) holds for GPS, Galileo and BeiDou alike: the [`Orbit`] (with its
//! [`OrbitFrame`](super::orbit::OrbitFrame)), issue, health and accuracy.

use super::beidou::{self, BdsAssembler, BdsEphemeris, BdsError, D2Assembler};
use super::cnav::{self, CnavAssembler, CnavEphemeris, CnavError};
use super::fnav::{self, FnavAssembler, FnavEphemeris, FnavError};
use super::galileo::{self, GalAssembler, GalEphemeris, InavError};
use super::orbit::Orbit;
use navsync_wire::samples::SIG_GPS_L2_PY;

/// u-blox `gnssId` of GPS.
pub const GNSS_ID_GPS: u8 = 0;
/// u-blox `gnssId` of Galileo.
pub const GNSS_ID_GALILEO: u8 = 2;
/// u-blox `gnssId` of BeiDou.
pub const GNSS_ID_BEIDOU: u8 = 3;
/// u-blox `gnssId` of GLONASS (its navigation data: [`glonass`](super::glonass)).
pub const GNSS_ID_GLONASS: u8 = 6;
/// Highest Galileo SVID.
const MAX_GAL: usize = 36;
/// Highest BeiDou PRN.
const MAX_BDS: usize = 63;
/// Highest GPS PRN.
const MAX_GPS: usize = 32;

/// Whether a message of system `gnss_id` on signal `sig_id` (u-blox numbers) carries GPS
/// LNAV subframes: GPS L1 C/A (sigId 0; a receiver before u-blox protocol 27 leaves the byte
/// reserved, 0). L2C and L5 carry CNAV ([`cnav`]).
pub fn carries_lnav(gnss_id: u8, sig_id: u8) -> bool {
    gnss_id == GNSS_ID_GPS && sig_id == 0
}

/// A completed ephemeris of one of the systems decoded here.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(tag = "system", rename_all = "snake_case")]
pub enum NavEphemeris {
    /// Galileo I/NAV.
    Galileo(GalEphemeris),
    /// Galileo F/NAV.
    GalileoFnav(FnavEphemeris),
    /// BeiDou D1 (MEO/IGSO) or D2 (GEO).
    Beidou(BdsEphemeris),
    /// GPS CNAV (L2C or L5).
    GpsCnav(CnavEphemeris),
}

/// The system-neutral part of a broadcast ephemeris.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BroadcastEphemeris {
    /// u-blox `gnssId` (0 GPS, 2 Galileo, 3 BeiDou).
    pub gnss_id: u8,
    /// Satellite within the system.
    pub sv_id: u8,
    /// Orbit and clock, in the system's time (GPST, GST, BDT seconds of week).
    pub orbit: Orbit,
    /// Issue of data (GPS IODE, Galileo IODnav, BeiDou AODE; GPS CNAV, which has none:
    /// t_oe / 300 s).
    pub iod: u16,
    /// Usable by the system's health and validity flags.
    pub healthy: bool,
    /// Signal-in-space accuracy, m (GPS URA, Galileo SISA, BeiDou URA); ∞ when not predicted.
    pub accuracy_m: f64,
    /// Each signal's group delay against the clock of `orbit` (Galileo; GPS's are the
    /// store's, [`SignalDelays::gps`]).
    pub delays: SignalDelays,
}

/// GPS L2 carrier frequency, Hz (IS-GPS-200 §3.3.1.1).
pub const L2_HZ: f64 = 1_227.60e6;
/// GPS L5 and Galileo E5a carrier frequency, Hz (IS-GPS-705 §3.3.1.1; OS SIS ICD §2.3.1).
pub const L5_HZ: f64 = 1_176.45e6;
/// Galileo E5b carrier frequency, Hz (OS SIS ICD §2.3.1).
pub const E5B_HZ: f64 = 1_207.14e6;
/// GPS L1 and Galileo E1 carrier frequency, Hz.
const L1_HZ: f64 = 1_575.42e6;

/// Each signal's group delay against the clock an ephemeris' a_f0..a_f2 describe, s: the
/// pseudorange on that signal is late by it (its single-frequency user's satellite clock is the
/// ephemeris' less this). `None`: not broadcast. Two signals' ionosphere-free combination keeps
/// f₁²B₁ − f₂²B₂ over f₁² − f₂² of them ([`combination_keeps`](Self::combination_keeps)).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SignalDelays {
    /// GPS L1 C/A, Galileo E1.
    pub l1_s: Option<f64>,
    /// GPS L2C, Galileo E5b.
    pub l2_s: Option<f64>,
    /// GPS L5, Galileo E5a.
    pub l5_s: Option<f64>,
    /// GPS L2 P(Y) ([`SIG_GPS_L2_PY`]): γ·T_GD, T_GD's definition (IS-GPS-200 §20.3.3.3.3.2).
    pub l2_py_s: Option<f64>,
    /// GPS: the inter-signal corrections (CNAV message type 30) were not received and are
    /// taken as 0 (they are ≲ 1 ns; the user adds their σ).
    pub isc_unknown: bool,
}

impl SignalDelays {
    /// GPS, from T_GD and the inter-signal corrections of CNAV message type 30 when received
    /// (`delays`; else taken as 0 and [`isc_unknown`](Self::isc_unknown) set). The clock of both
    /// LNAV and CNAV is the L1 P(Y)/L2 P(Y) ionosphere-free one; a single-frequency user's is
    /// Δt_SV − γ·T_GD + ISC, γ = (f_L1/f)² (IS-GPS-200 §30.3.3.3.1.1.1; IS-GPS-705
    /// §20.3.3.3.1.2.1): B = γ·T_GD − ISC. L5: ISC_L5Q5, else ISC_L5I5.
    pub fn gps(tgd_s: f64, delays: Option<&cnav::GroupDelays>) -> Self {
        let tgd_s = delays.and_then(|d| d.tgd_s).unwrap_or(tgd_s);
        let isc = |f: fn(&cnav::GroupDelays) -> Option<f64>| delays.and_then(f);
        let l1 = isc(|d| d.isc_l1ca_s);
        let l2 = isc(|d| d.isc_l2c_s);
        let l5 = isc(|d| d.isc_l5q5_s.or(d.isc_l5i5_s));
        let gamma = |f: f64| (L1_HZ / f).powi(2);
        Self {
            l1_s: Some(tgd_s - l1.unwrap_or(0.0)),
            l2_s: Some(gamma(L2_HZ) * tgd_s - l2.unwrap_or(0.0)),
            l5_s: Some(gamma(L5_HZ) * tgd_s - l5.unwrap_or(0.0)),
            l2_py_s: Some(gamma(L2_HZ) * tgd_s),
            isc_unknown: l1.is_none() || l2.is_none() || l5.is_none(),
        }
    }

    /// Galileo, with the clock of I/NAV (E1,E5b) or F/NAV (E1,E5a) and the BGDs the message
    /// carries (OS SIS ICD §5.1.5: a single-frequency user's clock on E1 is the pair's less
    /// BGD, on the pair's other signal less (f_E1/f)²·BGD). I/NAV's E5a delay goes through E1,
    /// which both clocks share: BGD(E1,E5b) − BGD(E1,E5a) + (f_E1/f_E5a)²·BGD(E1,E5a).
    pub fn galileo(bgd_e1_e5a_s: f64, bgd_e1_e5b_s: Option<f64>) -> Self {
        let gamma = |f: f64| (L1_HZ / f).powi(2);
        let a = bgd_e1_e5a_s;
        match bgd_e1_e5b_s {
            Some(b) => Self {
                l1_s: Some(b),
                l2_s: Some(gamma(E5B_HZ) * b),
                l5_s: Some(b - a + gamma(L5_HZ) * a),
                l2_py_s: None,
                isc_unknown: false,
            },
            None => Self {
                l1_s: Some(a),
                l2_s: None,
                l5_s: Some(gamma(L5_HZ) * a),
                l2_py_s: None,
                isc_unknown: false,
            },
        }
    }

    /// The delay of signal `sig_id` (u-blox numbering, [`SIG_GPS_L2_PY`] beyond it) of system
    /// `gnss_id` on carrier `freq_hz`, s.
    pub fn of_signal(&self, gnss_id: u8, sig_id: u8, freq_hz: f64) -> Option<f64> {
        if (gnss_id, sig_id) == (GNSS_ID_GPS, SIG_GPS_L2_PY) {
            return self.l2_py_s;
        }
        self.at(freq_hz)
    }

    /// The delay of the signal on carrier `freq_hz` (L1/E1, L2/E5b, L5/E5a), s.
    pub fn at(&self, freq_hz: f64) -> Option<f64> {
        [
            (L1_HZ, self.l1_s),
            (L2_HZ, self.l2_s),
            (E5B_HZ, self.l2_s),
            (L5_HZ, self.l5_s),
        ]
        .into_iter()
        .find(|(f, _)| (f - freq_hz).abs() < 1e3)
        .and_then(|(_, d)| d)
    }

    /// (f₁²B₁ − f₂²B₂) / (f₁² − f₂²), s: what the ionosphere-free combination of a signal on
    /// `f1_hz` delayed by `b1_s` and one on `f2_hz` delayed by `b2_s` keeps of the delays (0 for
    /// GPS L1/L2 P(Y): T_GD's definition, IS-GPS-200 §20.3.3.3.3.2).
    pub fn combination_keeps(f1_hz: f64, b1_s: f64, f2_hz: f64, b2_s: f64) -> f64 {
        let (g1, g2) = (f1_hz * f1_hz, f2_hz * f2_hz);
        (g1 * b1_s - g2 * b2_s) / (g1 - g2)
    }
}

impl NavEphemeris {
    /// The system-neutral part.
    pub fn broadcast(&self) -> BroadcastEphemeris {
        match self {
            Self::Galileo(e) => BroadcastEphemeris {
                gnss_id: GNSS_ID_GALILEO,
                sv_id: e.sv,
                orbit: e.orbit(),
                iod: e.iod_nav(),
                healthy: e.healthy(),
                accuracy_m: e.sisa_m().unwrap_or(f64::INFINITY),
                delays: SignalDelays::galileo(e.w5.bgd_e1_e5a_s, Some(e.w5.bgd_e1_e5b_s)),
            },
            Self::GalileoFnav(e) => BroadcastEphemeris {
                gnss_id: GNSS_ID_GALILEO,
                sv_id: e.sv,
                orbit: e.orbit(),
                iod: e.p1.iod_nav,
                healthy: e.healthy(),
                accuracy_m: e.sisa_m().unwrap_or(f64::INFINITY),
                delays: SignalDelays::galileo(e.p1.bgd_e1_e5a_s, None),
            },
            Self::Beidou(e) => BroadcastEphemeris {
                gnss_id: GNSS_ID_BEIDOU,
                sv_id: e.sv,
                orbit: e.orbit(),
                iod: u16::from(e.s1.aode),
                healthy: e.healthy(),
                // BDS-SIS-ICD-B1I §5.2.4.5: URA as GPS's URA index (IS-GPS-200).
                accuracy_m: super::ranges::ura_m(e.s1.urai).unwrap_or(f64::INFINITY),
                delays: SignalDelays::default(),
            },
            Self::GpsCnav(e) => BroadcastEphemeris {
                gnss_id: GNSS_ID_GPS,
                sv_id: e.sv,
                orbit: e.orbit(),
                iod: (e.e10.toe_s / 300.0) as u16,
                healthy: e.healthy(),
                accuracy_m: e.accuracy_m().unwrap_or(f64::INFINITY),
                delays: SignalDelays::gps(0.0, Some(&e.delays)),
            },
        }
    }
}

/// Why a message's words were not decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum NavWordsError {
    /// A Galileo I/NAV page pair was rejected.
    #[error("Galileo I/NAV: {0}")]
    Galileo(#[from] InavError),
    /// A Galileo F/NAV page was rejected.
    #[error("Galileo F/NAV: {0}")]
    GalileoFnav(#[from] FnavError),
    /// A BeiDou D1 or D2 subframe was rejected.
    #[error("BeiDou: {0}")]
    Beidou(#[from] BdsError),
    /// A GPS CNAV message was rejected.
    #[error("GPS CNAV: {0}")]
    GpsCnav(#[from] CnavError),
}

/// Counters of a [`NavCollector`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct NavCounts {
    /// Galileo I/NAV page pairs decoded.
    pub galileo_words: u64,
    /// Galileo F/NAV pages decoded.
    pub galileo_fnav_pages: u64,
    /// BeiDou D1 and D2 subframes decoded.
    pub beidou_subframes: u64,
    /// GPS CNAV messages decoded.
    pub gps_cnav_messages: u64,
    /// Messages rejected (CRC, parity, preamble, page layout).
    pub rejected: u64,
    /// Messages of other systems and signals, or of satellites out of range.
    pub ignored: u64,
}

/// Per-satellite assemblers of Galileo, BeiDou and GPS CNAV ephemerides. Fixed size, no
/// allocation.
#[derive(Debug, Clone)]
pub struct NavCollector {
    gal: [GalAssembler; MAX_GAL],
    fnav: [FnavAssembler; MAX_GAL],
    gps: [CnavAssembler; MAX_GPS],
    /// GPS CNAV's ionosphere (message type 30's Klobuchar α/β), the latest.
    pub gps_cnav_iono: Option<([f64; 4], [f64; 4])>,
    bds: [BdsAssembler; MAX_BDS],
    geo: [D2Assembler; MAX_BDS],
    /// What came in.
    pub counts: NavCounts,
}

impl Default for NavCollector {
    fn default() -> Self {
        Self {
            gal: [GalAssembler::default(); MAX_GAL],
            fnav: [FnavAssembler::default(); MAX_GAL],
            gps: [CnavAssembler::default(); MAX_GPS],
            gps_cnav_iono: None,
            bds: [BdsAssembler::default(); MAX_BDS],
            geo: [D2Assembler::default(); MAX_BDS],
            counts: NavCounts::default(),
        }
    }
}

impl NavCollector {
    /// Takes one RXM-SFRBX's words (`gnss_id`, `sv_id`, `sig_id` as u-blox numbers them);
    /// returns the ephemeris they completed, if any. Rejected words are counted and returned
    /// as the error; messages this collector does not read give `Ok(None)`.
    pub fn on_words(
        &mut self,
        gnss_id: u8,
        sv_id: u8,
        sig_id: u8,
        words: &[u32],
    ) -> Result<Option<NavEphemeris>, NavWordsError> {
        let slot = usize::from(sv_id).checked_sub(1);
        match (gnss_id, sig_id) {
            (GNSS_ID_GALILEO, 1 | 5) if slot.is_some_and(|i| i < MAX_GAL) => {
                let w = galileo::decode(words).inspect_err(|_| self.counts.rejected += 1)?;
                self.counts.galileo_words += 1;
                let a = &mut self.gal[slot.unwrap_or(0)];
                Ok(a.on_word(sv_id, &w).map(NavEphemeris::Galileo))
            }
            (GNSS_ID_GALILEO, 3) if slot.is_some_and(|i| i < MAX_GAL) => {
                let p = fnav::decode(words).inspect_err(|_| self.counts.rejected += 1)?;
                self.counts.galileo_fnav_pages += 1;
                let a = &mut self.fnav[slot.unwrap_or(0)];
                Ok(a.on_page(sv_id, &p).map(NavEphemeris::GalileoFnav))
            }
            (GNSS_ID_BEIDOU, 0 | 2 | 4) if slot.is_some_and(|i| i < MAX_BDS) && !beidou::is_geo(sv_id) => {
                let sf = beidou::decode_d1(words).inspect_err(|_| self.counts.rejected += 1)?;
                self.counts.beidou_subframes += 1;
                let a = &mut self.bds[slot.unwrap_or(0)];
                Ok(a.on_subframe(sv_id, &sf).map(NavEphemeris::Beidou))
            }
            (GNSS_ID_BEIDOU, 1 | 3 | 10) if slot.is_some_and(|i| i < MAX_BDS) && beidou::is_geo(sv_id) => {
                let page = beidou::decode_d2(words).inspect_err(|_| self.counts.rejected += 1)?;
                self.counts.beidou_subframes += 1;
                let a = &mut self.geo[slot.unwrap_or(0)];
                Ok(page.and_then(|p| a.on_page(sv_id, &p)).map(NavEphemeris::Beidou))
            }
            (GNSS_ID_GPS, 3 | 4 | 6 | 7) if slot.is_some_and(|i| i < MAX_GPS) => {
                let m = cnav::decode(words).inspect_err(|_| self.counts.rejected += 1)?;
                self.counts.gps_cnav_messages += 1;
                if let cnav::CnavMessage::Clock { delays: Some(d), .. } = m.message {
                    self.gps_cnav_iono = Some((d.alpha, d.beta));
                }
                let a = &mut self.gps[slot.unwrap_or(0)];
                Ok(a.on_message(sv_id, &m.message).map(NavEphemeris::GpsCnav))
            }
            _ => {
                self.counts.ignored += 1;
                Ok(None)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// GPS: without inter-signal corrections L1/L2 keeps nothing of T_GD (its definition);
    /// with them the combination keeps what IS-GPS-200 §30.3.3.3.1.1.1 adds to it, c·(ISC_L2C
    /// − γ·ISC_L1C/A)/(1 − γ) with the opposite sign (here a delay, there a correction), and
    /// each single frequency's delay is γ·T_GD − ISC.
    /// What the combination of the signals on `f1_hz` and `f2_hz` keeps of `d`'s delays.
    fn keeps(d: &SignalDelays, f1_hz: f64, f2_hz: f64) -> Option<f64> {
        Some(SignalDelays::combination_keeps(
            f1_hz,
            d.at(f1_hz)?,
            f2_hz,
            d.at(f2_hz)?,
        ))
    }

    #[test]
    fn gps_delays_follow_the_interface_specification() {
        let tgd = -8.3e-9;
        let none = SignalDelays::gps(tgd, None);
        assert!(none.isc_unknown);
        assert!(keeps(&none, L1_HZ, L2_HZ).unwrap().abs() < 1e-20);
        let d = cnav::GroupDelays {
            tgd_s: Some(tgd),
            isc_l1ca_s: Some(0.4e-9),
            isc_l2c_s: Some(-1.1e-9),
            isc_l5i5_s: Some(2.0e-9),
            isc_l5q5_s: Some(2.2e-9),
            ..cnav::GroupDelays::default()
        };
        let g = SignalDelays::gps(0.0, Some(&d));
        assert!(!g.isc_unknown);
        let gamma12 = (L1_HZ / L2_HZ).powi(2);
        let correction = (-1.1e-9 - gamma12 * 0.4e-9) / (1.0 - gamma12);
        assert!((keeps(&g, L1_HZ, L2_HZ).unwrap() + correction).abs() < 1e-20);
        assert!((g.at(L1_HZ).unwrap() - (tgd - 0.4e-9)).abs() < 1e-20);
        let gamma15 = (L1_HZ / L5_HZ).powi(2);
        assert!((g.at(L5_HZ).unwrap() - (gamma15 * tgd - 2.2e-9)).abs() < 1e-20);
        assert_eq!(g.at(1_561.098e6), None);
        // L2 P(Y): γ·T_GD, whatever the L2C correction; with L1 P(Y) (T_GD) nothing is kept.
        assert_eq!(g.of_signal(GNSS_ID_GPS, SIG_GPS_L2_PY, L2_HZ), Some(gamma12 * tgd));
        assert_eq!(g.of_signal(GNSS_ID_GPS, 3, L2_HZ), g.l2_s);
        let py = SignalDelays::combination_keeps(L1_HZ, tgd, L2_HZ, g.l2_py_s.unwrap());
        assert!(py.abs() < 1e-20);
    }

    /// Galileo: I/NAV's clock (E1,E5b) and F/NAV's (E1,E5a) of the same instant differ by
    /// BGD(E1,E5b) − BGD(E1,E5a) (both give E1's single-frequency clock); less what their
    /// E1/E5a combination keeps, both give the same clock, and E1's delay is each message's own
    /// BGD. F/NAV has no E5b delay.
    #[test]
    fn galileo_inav_and_fnav_give_one_dual_frequency_clock() {
        let (a, b) = (-3.96e-9, -4.42e-9);
        let clock_fnav = 1.234e-4;
        let clock_inav = clock_fnav - a + b;
        let (inav, fnav) = (SignalDelays::galileo(a, Some(b)), SignalDelays::galileo(a, None));
        let e1_e5a = |d: &SignalDelays| keeps(d, L1_HZ, L5_HZ).unwrap();
        assert!(((clock_inav - e1_e5a(&inav)) - (clock_fnav - e1_e5a(&fnav))).abs() < 1e-20);
        assert!(((clock_inav - inav.at(L1_HZ).unwrap()) - (clock_fnav - fnav.at(L1_HZ).unwrap())).abs() < 1e-20);
        assert!(keeps(&inav, L1_HZ, E5B_HZ).unwrap().abs() < 1e-20);
        assert_eq!(fnav.at(E5B_HZ), None);
    }

    /// Any words, satellite and signal numbers: decoded, rejected or ignored, never a panic.
    #[test]
    fn arbitrary_words_never_panic() {
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        let mut c = NavCollector::default();
        for _ in 0..100_000 {
            let r = next();
            let mut words = [0u32; 16];
            for w in &mut words {
                *w = next() as u32;
            }
            let n = (r % 17) as usize;
            let gnss = [GNSS_ID_GALILEO, GNSS_ID_BEIDOU, GNSS_ID_GPS][(r >> 8) as usize % 3];
            let sig = [0u8, 1, 2, 3, 4, 5, 6, 7, 10, 200][(r >> 16) as usize % 10];
            let sv = (r >> 24) as u8;
            let _ = c.on_words(gnss, sv, sig, &words[..n]);
        }
        let k = c.counts;
        let decoded = k.galileo_words + k.galileo_fnav_pages + k.beidou_subframes + k.gps_cnav_messages;
        assert_eq!(decoded + k.rejected + k.ignored, 100_000);
        assert!(k.rejected > 0 && k.ignored > 0);
    }
}
