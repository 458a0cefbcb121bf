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
            },
            Self::GalileoFnav(e) => BroadcastEphemeris {
                gnss_id: GNSS_ID_GALILEO,
                sv_id: e.sv,
                orbit: e.orbit(),
                iod: e.p1.iod_nav,
                healthy: e.healthy(),
                accuracy_m: e.sisa_m().unwrap_or(f64::INFINITY),
            },
            Self::Beidou(e) => BroadcastEphemeris {
                gnss_id: GNSS_ID_BEIDOU,
                sv_id: e.sv,
                orbit: e.orbit(),
                iod: u16::from(e.s1.aode),
                healthy: e.healthy(),
                // BDS-SIS-ICD-B1I §5.2.4.5: URA as GPS's URA index (IS-GPS-200).
                accuracy_m: super::ranges::ura_m(e.s1.urai).unwrap_or(f64::INFINITY),
            },
            Self::GpsCnav(e) => BroadcastEphemeris {
                gnss_id: GNSS_ID_GPS,
                sv_id: e.sv,
                orbit: e.orbit(),
                iod: (e.e10.toe_s / 300.0) as u16,
                healthy: e.healthy(),
                accuracy_m: e.accuracy_m().unwrap_or(f64::INFINITY),
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
