//! The receiver's sky from NMEA: GSV (satellites in view: elevation, azimuth, SNR) with GSA
//! (the satellites used in the solution) → one [`GnssSky`] per cycle. Pure, no allocation.
//!
//! GSV (NMEA 0183 v4.11): 1 number of sentences of the group, 2 this sentence's number, 3
//! satellites in view, then per satellite (up to four a sentence) PRN, elevation (degrees,
//! 00–90), azimuth (degrees true, 000–359), SNR (C/N0, dB-Hz, 00–99, empty when not tracking);
//! NMEA 4.10 adds a signal ID after the last satellite. Each talker (`GP`, `GL`, `GA`, `GB`,
//! `GQ`, …) and signal sends a group of its own; a receiver sends the groups of one cycle
//! one after another, some with GSA or other sentences between the groups. The sky of a
//! cycle is the GSV sentences up to the next fix sentence (GGA, RMC, GNS, GLL): it is complete
//! when one arrives, when a group starts again (a receiver that sends nothing but GSV) or when
//! the line goes idle ([`SkyAssembler::flush`]), and stamped with the host time of its first
//! GSV's first byte. A satellite reported on several signals is one entry (the first
//! elevation and azimuth, the highest SNR).
//!
//! Used: the PRNs of the receiver's latest GSA group (the GSA sentences of one cycle, one per
//! system on multi-constellation receivers), matched by system and satellite, when the GSV
//! gives the satellite an SNR (a satellite without a signal is not used: a Quectel lists
//! satellites in GSA after it lost them; gpsd reads it so too). Satellites are
//! numbered as u-blox numbers them (`gnssId`/`svId`, see [`gnss_sat`]), as in
//! `GnssRaw`, so that a sky from NMEA and one from UBX read alike.

use navsync_shared::samples::{GNSS_PROTOCOL_NMEA, GnssSky, SkySatellite, Stamp, StampSource};

use super::sentence::{Kind, check, decode};

/// (GNSS id, satellite id) pairs used according to the latest GSA group.
const USED_MAX: usize = 64;
/// GSV groups (talker and signal) within one cycle.
const GROUPS_MAX: usize = 16;

/// The u-blox `gnssId`/`svId` of an NMEA satellite number `prn` reported by `talker` (the two
/// characters of the address, or for a GSA with an NMEA 4.11 system ID `b'0'` + that ID),
/// following the NMEA numbering (NMEA 0183 v4.11; u-blox's "Satellite numbering" appendix):
/// GPS 1–32, SBAS 33–64 (PRN − 87 … as 120–151), GLONASS 65–96 (slot + 64), QZSS 193–202,
/// Galileo 301–336 and BeiDou 401–437 in the extended numbering; with a constellation's own
/// talker (`GL`, `GA`, `GB`/`BD`, `GQ`/`QZ`) or system ID, 1–64 are that constellation's
/// satellites. `None` for numbers outside these ranges.
pub fn gnss_sat(talker: [u8; 2], prn: u16) -> Option<(u8, u8)> {
    /// u-blox GNSS ids.
    const GPS: u8 = 0;
    const SBAS: u8 = 1;
    const GALILEO: u8 = 2;
    const BEIDOU: u8 = 3;
    const QZSS: u8 = 5;
    const GLONASS: u8 = 6;
    let sv = |x: u16| u8::try_from(x).ok();
    let own = match talker {
        [b'G', b'L'] | [b'0', b'2'] => Some(GLONASS),
        [b'G', b'A'] | [b'0', b'3'] => Some(GALILEO),
        [b'G', b'B'] | [b'B', b'D'] | [b'0', b'4'] => Some(BEIDOU),
        [b'G', b'Q'] | [b'Q', b'Z'] | [b'0', b'5'] => Some(QZSS),
        _ => None,
    };
    Some(match (own, prn) {
        (Some(GLONASS), 65..=96) => (GLONASS, sv(prn - 64)?),
        (Some(QZSS), 193..=202) => (QZSS, sv(prn - 192)?),
        (Some(GALILEO), 301..=336) => (GALILEO, sv(prn - 300)?),
        (Some(BEIDOU), 401..=437) => (BEIDOU, sv(prn - 400)?),
        (Some(g), 1..=64) => (g, sv(prn)?),
        (_, 1..=32) => (GPS, sv(prn)?),
        (_, 33..=64) => (SBAS, sv(prn + 87)?),
        (_, 65..=96) => (GLONASS, sv(prn - 64)?),
        (_, 120..=158) => (SBAS, sv(prn)?),
        (_, 193..=202) => (QZSS, sv(prn - 192)?),
        (_, 301..=336) => (GALILEO, sv(prn - 300)?),
        (_, 401..=437) => (BEIDOU, sv(prn - 400)?),
        _ => return None,
    })
}

/// Counters of [`SkyAssembler`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SkyCounters {
    /// GSV sentences decoded.
    pub gsv: u64,
    /// GSV sentences or satellite blocks that could not be read (malformed numbers, a
    /// satellite number outside every system's range); dropped.
    pub gsv_bad: u64,
    /// Skies completed.
    pub skies: u64,
}

impl SkyCounters {
    /// The counters a `Health` report carries: only what went wrong (the GSV sentences and the
    /// skies themselves show in the sentence count and the sky service's rate; a receiver's
    /// report has room for `MAX_COUNTERS` (96) counters in all, `DRIVER_COUNTERS` of them the driver's).
    pub fn named(&self) -> [(&'static str, u64); 1] {
        [("nmea_gsv_bad", self.gsv_bad)]
    }
}

/// GSV and GSA sentences → one [`GnssSky`] per cycle (see the module documentation).
#[derive(Debug, Clone)]
pub struct SkyAssembler {
    /// The sky being assembled (`num_sats` 0 and `stamp.host_ns` `i64::MIN`: none).
    sky: GnssSky,
    /// The run of GSV sentences is open.
    open: bool,
    /// The GSV groups (talker, signal ID) of the open run.
    groups: [([u8; 2], u8); GROUPS_MAX],
    n_groups: usize,
    /// The satellites used according to the latest GSA group, and whether the last sentence
    /// was a GSA (the next GSA then belongs to the same group).
    used: [(u8, u8); USED_MAX],
    n_used: usize,
    in_gsa: bool,
    seq: u64,
    counters: SkyCounters,
}

impl Default for SkyAssembler {
    fn default() -> Self {
        Self::new()
    }
}

impl SkyAssembler {
    /// An assembler that has seen nothing yet.
    pub fn new() -> Self {
        Self {
            sky: GnssSky::empty(Stamp::host(i64::MIN, 0, StampSource::Receipt)),
            open: false,
            groups: [([0; 2], 0); GROUPS_MAX],
            n_groups: 0,
            used: [(0, 0); USED_MAX],
            n_used: 0,
            in_gsa: false,
            seq: 0,
            counters: SkyCounters::default(),
        }
    }

    /// Counters since creation.
    pub fn counters(&self) -> &SkyCounters {
        &self.counters
    }

    /// Consumes one sentence (text from `$` to before CR/LF, `host_ns` the host time of its
    /// first byte); `epoch_utc_ns` is the UTC of the epoch the sentence falls into (`i64::MIN`
    /// when not known). A sky completed by this sentence goes to `out`.
    pub fn push(&mut self, text: &[u8], host_ns: i64, epoch_utc_ns: i64, out: &mut impl FnMut(&GnssSky)) {
        let Ok(s) = check(text) else {
            return;
        };
        let talker = match s.address {
            [a, b, ..] => [*a, *b],
            _ => [0; 2],
        };
        if s.address.get(2..) == Some(b"GSV".as_slice()) && s.address.len() == 5 {
            self.in_gsa = false;
            self.gsv(talker, s.data, host_ns, epoch_utc_ns, out);
            return;
        }
        let kind = Kind::of_address(s.address);
        if kind.is_some_and(Kind::is_fix) {
            self.finish(out);
        }
        if kind == Some(Kind::Gsa) {
            if !self.in_gsa {
                self.n_used = 0;
            }
            self.in_gsa = true;
            if let Some((u, _)) = decode(Kind::Gsa, &s) {
                let system = if u.gsa_system.is_ascii_digit() {
                    [b'0', u.gsa_system]
                } else {
                    talker
                };
                for &prn in u.gsa_prns.get(..u.gsa_prn_count).unwrap_or(&[]) {
                    if let Some(id) = gnss_sat(system, prn)
                        && self.n_used < USED_MAX
                        && !self.used[..self.n_used].contains(&id)
                    {
                        self.used[self.n_used] = id;
                        self.n_used += 1;
                    }
                }
            }
        } else {
            self.in_gsa = false;
        }
    }

    /// The line went idle: the open sky is complete.
    pub fn flush(&mut self, out: &mut impl FnMut(&GnssSky)) {
        self.finish(out);
    }

    fn gsv(&mut self, talker: [u8; 2], data: &str, host_ns: i64, epoch_utc_ns: i64, out: &mut impl FnMut(&GnssSky)) {
        let fields: [&str; 24] = {
            let mut f = [""; 24];
            let mut it = data.split(',');
            for slot in &mut f {
                *slot = it.next().unwrap_or("");
            }
            f
        };
        let n = data.split(',').count();
        let num = |s: &str| -> Option<u16> {
            let s = s.trim();
            (!s.is_empty() && s.bytes().all(|b| b.is_ascii_digit()))
                .then(|| s.parse().ok())
                .flatten()
        };
        let (Some(_total), Some(part)) = (num(fields[0]), num(fields[1])) else {
            self.counters.gsv_bad += 1;
            return;
        };
        self.counters.gsv += 1;
        // NMEA 4.10: a signal ID after the satellites (the field count is then 4k + 4).
        let signal = if n > 3 && (n - 3) % 4 == 1 {
            fields
                .get(n - 1)
                .and_then(|f| num(f))
                .and_then(|x| u8::try_from(x).ok())
                .unwrap_or(0)
        } else {
            0
        };
        let group = (talker, signal);
        let seen = self.groups[..self.n_groups].contains(&group);
        if part == 1 && seen {
            // The same group again: a new cycle without another sentence in between.
            self.finish(out);
        }
        if !self.open {
            self.open = true;
            self.n_groups = 0;
            self.sky = GnssSky::empty(Stamp::host(host_ns, self.seq, StampSource::Receipt));
            self.sky.protocol = GNSS_PROTOCOL_NMEA;
        }
        self.sky.utc_ns = epoch_utc_ns;
        if !self.groups[..self.n_groups].contains(&group) && self.n_groups < GROUPS_MAX {
            self.groups[self.n_groups] = group;
            self.n_groups += 1;
        }
        let blocks = (n.saturating_sub(3) / 4).min(4);
        for b in 0..blocks {
            let f = |k: usize| fields.get(3 + 4 * b + k).copied().unwrap_or("");
            if f(0).trim().is_empty() {
                continue;
            }
            let Some((gnss_id, sv_id)) = num(f(0)).and_then(|prn| gnss_sat(talker, prn)) else {
                self.counters.gsv_bad += 1;
                continue;
            };
            let el = num(f(1)).filter(|&e| e <= 90);
            let az = num(f(2)).filter(|&a| a <= 360).map(|a| a % 360);
            let cno = num(f(3)).filter(|&c| c <= 99).map_or(0, |c| c as u8);
            let sat = SkySatellite {
                elevation_deg: el.map_or(f32::NAN, f32::from),
                azimuth_deg: az.map_or(f32::NAN, f32::from),
                gnss_id,
                sv_id,
                cno_dbhz: cno,
                used: 0,
            };
            let len = usize::from(self.sky.num_sats);
            match self.sky.sats[..len]
                .iter_mut()
                .find(|x| x.gnss_id == gnss_id && x.sv_id == sv_id)
            {
                Some(x) => {
                    x.cno_dbhz = x.cno_dbhz.max(cno);
                    if x.elevation_deg.is_nan() {
                        x.elevation_deg = sat.elevation_deg;
                        x.azimuth_deg = sat.azimuth_deg;
                    }
                }
                None => {
                    self.sky.push(sat);
                }
            }
        }
    }

    /// Completes the open sky: marks the used satellites and hands it to `out`.
    fn finish(&mut self, out: &mut impl FnMut(&GnssSky)) {
        if !self.open {
            return;
        }
        self.open = false;
        let used = &self.used[..self.n_used];
        let len = usize::from(self.sky.num_sats);
        for x in &mut self.sky.sats[..len] {
            x.used = u8::from(x.cno_dbhz > 0 && used.contains(&(x.gnss_id, x.sv_id)));
        }
        self.seq += 1;
        self.counters.skies += 1;
        out(&self.sky);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn nmea(body: &str) -> Vec<u8> {
        let sum = body.bytes().fold(0u8, |a, b| a ^ b);
        format!("${body}*{sum:02X}").into_bytes()
    }

    fn run(sentences: &[&str]) -> Vec<GnssSky> {
        let mut a = SkyAssembler::new();
        let mut out = Vec::new();
        for (i, s) in sentences.iter().enumerate() {
            a.push(&nmea(s), i as i64 * 1000, 7, &mut |k| out.push(*k));
        }
        a.flush(&mut |k| out.push(*k));
        out
    }

    #[test]
    fn a_gsv_group_with_its_gsa() {
        // Garmin GPSmap 76S (gpsd's corpus): GSA, then three GSV.
        let skies = run(&[
            "GPGSA,A,3,03,07,08,11,13,16,19,23,24,28,,,3.6,2.0,3.0",
            "GPGSV,3,1,10,03,41,050,46,07,60,317,49,08,34,315,45,11,35,148,45",
            "GPGSV,3,2,10,13,38,213,45,16,27,068,43,19,72,076,50,23,09,182,37",
            "GPGSV,3,3,10,24,06,166,35,28,09,271,36",
            "GPGLL,3854.5087,N,07726.4523,W,125106,V,S",
        ]);
        assert_eq!(skies.len(), 1);
        let k = &skies[0];
        assert_eq!((k.num_sats, k.used(), k.stamp.host_ns, k.utc_ns), (10, 10, 1000, 7));
        let s = k.satellites()[0];
        assert_eq!(
            (s.gnss_id, s.sv_id, s.elevation_deg, s.azimuth_deg, s.cno_dbhz, s.used),
            (0, 3, 41.0, 50.0, 46, 1)
        );
        assert_eq!(k.protocol, GNSS_PROTOCOL_NMEA);
    }

    #[test]
    fn several_talkers_and_signals_make_one_sky() {
        let skies = run(&[
            "GNGSA,A,3,05,13,,,,,,,,,,,1.6,1.3,0.9,1",
            "GNGSA,A,3,67,68,,,,,,,,,,,1.6,1.3,0.9,2",
            "GPGSV,1,1,03,05,40,083,46,13,,,30,40,10,200,,1",
            "GPGSV,1,1,01,05,40,083,48,7",
            "GLGSV,1,1,02,67,55,120,40,68,12,300,",
            "GNRMC,120000.00,A,4807.038,N,01131.000,E,0.0,,010124,,,A",
            "GPGSV,1,1,01,05,41,084,47",
        ]);
        assert_eq!(skies.len(), 2, "{skies:?}");
        let k = &skies[0];
        assert_eq!(k.num_sats, 5);
        let find = |g: u8, sv: u8| *k.satellites().iter().find(|s| s.gnss_id == g && s.sv_id == sv).unwrap();
        // G05 on two signals: one entry, the higher C/N0.
        assert_eq!((find(0, 5).cno_dbhz, find(0, 5).used), (48, 1));
        // No elevation or azimuth: unknown.
        assert!(find(0, 13).elevation_deg.is_nan() && find(0, 13).azimuth_deg.is_nan());
        assert_eq!((find(0, 13).cno_dbhz, find(0, 13).used), (30, 1));
        // PRN 40 is SBAS 127; no SNR: 0.
        assert_eq!((find(1, 127).cno_dbhz, find(1, 127).used), (0, 0));
        // GLONASS 65–96 are slots 1–32; the GSA with system ID 2 marks slot 3 used.
        assert_eq!((find(6, 3).elevation_deg, find(6, 3).used), (55.0, 1));
        // Slot 4 is in the GSA but has no SNR: not used (as gpsd reads it).
        assert_eq!((find(6, 4).cno_dbhz, find(6, 4).used), (0, 0));
        // The second cycle, completed by the flush.
        assert_eq!((skies[1].num_sats, skies[1].stamp.seq), (1, 1));
    }

    #[test]
    fn a_receiver_that_sends_only_gsv() {
        let skies = run(&[
            "GPGSV,2,1,05,01,10,010,20,02,20,020,21,03,30,030,22,04,40,040,23",
            "GPGSV,2,2,05,05,50,050,24",
            "GPGSV,2,1,05,01,10,010,20,02,20,020,21,03,30,030,22,04,40,040,23",
            "GPGSV,2,2,05,05,50,050,24",
        ]);
        assert_eq!(skies.iter().map(|k| k.num_sats).collect::<Vec<_>>(), [5, 5]);
        assert_eq!(skies[1].stamp.host_ns, 2000);
    }

    #[test]
    fn satellite_numbers() {
        assert_eq!(gnss_sat(*b"GP", 33), Some((1, 120)));
        assert_eq!(gnss_sat(*b"GN", 70), Some((6, 6)));
        assert_eq!(gnss_sat(*b"GL", 70), Some((6, 6)));
        assert_eq!(gnss_sat(*b"GL", 7), Some((6, 7)));
        assert_eq!(gnss_sat(*b"GA", 11), Some((2, 11)));
        assert_eq!(gnss_sat(*b"GB", 40), Some((3, 40)));
        assert_eq!(gnss_sat(*b"GP", 195), Some((5, 3)));
        assert_eq!(gnss_sat(*b"GN", 305), Some((2, 5)));
        assert_eq!(gnss_sat(*b"GN", 410), Some((3, 10)));
        assert_eq!(gnss_sat(*b"GP", 0), None);
        assert_eq!(gnss_sat(*b"GP", 250), None);
    }
}
