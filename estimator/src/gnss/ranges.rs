//! A receiver's raw measurements of one epoch made ready for tightly coupled fusion: the
//! broadcast ephemerides collected from the navigation data (GPS LNAV subframes 1–3 of one
//! issue, IS-GPS-200N §20.3.4.4 for IODE/IODC; the ionosphere page; Galileo I/NAV and BeiDou
//! D1/D2 through [`NavCollector`], keyed by (gnss id, sv id); GLONASS immediate data through a
//! [`GloStore`]), and per satellite the preferred signal's pseudorange and Doppler
//! ([`SPP_SIGNALS`]: GPS L1 C/A, Galileo E1, BeiDou B1I/B3I, GLONASS L1OF)
//! paired with its satellite's position, velocity and clock at the time of transmission. What
//! depends on the receiver's position (the Earth's rotation during the flight, elevation,
//! ionosphere, troposphere) is left to the filter, which knows it. The same signal choice
//! serves single-point positioning ([`EphemerisStore::system_observations`]).

use navsync_wire::samples::{GnssNavData, GnssRaw, RawMeasurement, SIG_GPS_L2_PY};

use super::broadcast::{
    BroadcastEphemeris, GNSS_ID_BEIDOU, GNSS_ID_GALILEO, GNSS_ID_GLONASS, L2_HZ, L5_HZ, NavCollector, NavEphemeris,
    SignalDelays, carries_lnav,
};
use super::cnav;
use super::glonass::{self, GloEphemeris, GloStore};
use super::lnav::{self, Ephem1, Ephem2, Ephem3, Subframe};
use super::orbit::Orbit;
use super::spp::{C_M_S, Klobuchar, Observation, SystemObservation};

/// Satellites one [`RangeEpoch`] holds (the weakest are dropped when a receiver tracks more).
pub const MAX_RANGE_SATS: usize = 32;
/// GPS L1 carrier frequency, Hz (IS-GPS-200 §3.3.1.1).
pub const L1_HZ: f64 = 1_575.42e6;
pub use super::broadcast::GNSS_ID_GPS;
/// Highest GPS PRN.
const MAX_PRN: usize = 32;
/// Highest Galileo SVID.
const MAX_GAL: usize = 36;
/// Highest BeiDou PRN.
const MAX_BDS: usize = 63;
/// BeiDou time is GPS time less this, s (BDS-SIS-ICD-B1I §4.2: BDT began 2006-01-01 00:00:00
/// UTC, when GPS time was 14 s ahead of UTC).
pub const BDT_MINUS_GPST_S: f64 = -14.0;

/// The signals single-point positioning uses, in order of preference per satellite: (u-blox
/// `gnssId`, `sigId`, carrier frequency in Hz, whether the broadcast group delay applies).
/// GPS L1 C/A; Galileo E1-C, E1-B (BGD(E1,E5b) of I/NAV); BeiDou B1I D1, D2 (T_GD1), B3I
/// D1, D2 (no group delay: B3I is the reference of BeiDou's clock parameters,
/// BDS-SIS-ICD-B1I §5.2.4.10); GLONASS L1OF (its frequency is channel 0's here, each
/// satellite's from its channel, [`glonass::l1of_hz`]; τ_n is L1's clock, no group delay).
pub const SPP_SIGNALS: [(u8, u8, f64, bool); 8] = [
    (GNSS_ID_GPS, 0, L1_HZ, true),
    (GNSS_ID_GALILEO, 0, L1_HZ, true),
    (GNSS_ID_GALILEO, 1, L1_HZ, true),
    (GNSS_ID_BEIDOU, 0, 1_561.098e6, true),
    (GNSS_ID_BEIDOU, 1, 1_561.098e6, true),
    (GNSS_ID_BEIDOU, 4, 1_268.52e6, false),
    (GNSS_ID_BEIDOU, 10, 1_268.52e6, false),
    (GNSS_ID_GLONASS, 0, 1_602.0e6, false),
];
/// The second signals of an ionosphere-free combination with [`SPP_SIGNALS`]' first: (u-blox
/// `gnssId`, the `sigId`s of one signal in order of preference, carrier frequency in Hz). GPS
/// L2C (CL, CM: one code, one inter-signal correction), L2 P(Y) (a geodetic receiver's, [`SIG_GPS_L2_PY`]); Galileo E5a-Q, E5a-I (u-blox
/// interface description, "GNSS signal identifiers"); each epoch uses one per system
/// ([`second_signals`]). No L5 or E5b: a receiver delays each band differently (metres between
/// L2 and L5 on the walk's u-blox X20), and L2C and E5a are what its satellites have most. BeiDou's B2a and B1C group delays are in B-CNAV messages, which are not
/// decoded: BeiDou and GLONASS stay on one frequency.
pub const DUAL_FREQUENCY_SIGNALS: [(u8, &[u8], f64); 3] = [
    (GNSS_ID_GPS, &[3, 4], L2_HZ),
    (GNSS_ID_GPS, &[SIG_GPS_L2_PY], L2_HZ),
    (GNSS_ID_GALILEO, &[4, 3], L5_HZ),
];
/// 1σ of each GPS inter-signal correction taken as 0 when no CNAV message type 30 came, s
/// (the broadcast values are a fraction of a nanosecond to about one).
const ISC_UNKNOWN_STD_S: f64 = 1e-9;
/// 1σ of a GLONASS pseudorange's inter-frequency bias, m: each channel's code delay in the
/// receiver differs from the others' by decimetres to metres, and one inter-system bias per
/// system leaves it. Added in quadrature to the broadcast accuracy F_T.
pub const GLONASS_IFB_STD_M: f64 = 1.0;
/// An ephemeris is used up to this far from its t_oe, s (the 4 h curve fit of IS-GPS-200
/// §20.3.4.4 is ±2 h; an hour of margin for a receiver that did not get the next issue yet).
pub const EPHEMERIS_VALID_S: f64 = 3.0 * 3600.0;

/// One satellite's measurements with its broadcast state at transmission.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SatRange {
    /// System, u-blox `gnssId` (GPS 0, Galileo 2, BeiDou 3, GLONASS 6).
    pub gnss_id: u8,
    /// Satellite number in its system (GPS PRN, Galileo SVID, BeiDou PRN, GLONASS slot).
    pub sv: u8,
    /// (f_L1 / f)² of the signal's carrier: the L1 ionospheric delay times this is the
    /// signal's (IS-GPS-200 §20.3.3.3.3.2).
    pub iono_scale: f64,
    /// Carrier-to-noise density, dB-Hz.
    pub cno_dbhz: u8,
    /// Pseudorange corrected for the satellite clock, ρ + c·δt_sv, m: it models
    /// r + c·δt_r + I + T (geometric range, receiver clock, ionosphere, troposphere).
    pub pseudorange_m: f64,
    /// Range rate corrected for the satellite clock drift, −λ·D + c·δṫ_sv (λ of the signal's
    /// carrier), m/s: it models
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
    /// Signal, u-blox `sigId` (a carrier phase is differenced with the same signal's only).
    pub sig_id: u8,
    /// Carrier phase in metres corrected for the satellite clock, λ·φ + c·δt_sv (u-blox
    /// `cpMes` has the pseudorange's sign, its ambiguity set near it): it models
    /// r + c·δt_r − k·I + T + λ·N with N constant while the receiver keeps lock. NaN when the
    /// receiver marks it invalid (`trkStat` bit 1) or reports none.
    pub carrier_m: f64,
    /// 1σ of the carrier phase the receiver reports, m.
    pub carrier_std_m: f64,
    /// How long the receiver has kept lock on the carrier, ms (u-blox `locktime`, at most
    /// 64 500): a count that fell or that is shorter than the time since the previous epoch
    /// marks a cycle slip between them.
    pub lock_time_ms: u16,
    /// u-blox `trkStat`: bit 3 (half a cycle subtracted from the phase) must not change
    /// between two epochs whose phases are differenced.
    pub trk_stat: u8,
}

/// The measurements of one receiver epoch, ready for the filter.
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
    /// 1σ N, E, D of the epoch's own single-point solution, m (zero: none, fewer satellites
    /// than unknowns): the floor of the published position σ
    /// ([`crate::nav::filter::DelayedFilter::pos_floor_std_ned_m`]).
    pub pos_floor_std_ned_m: [f64; 3],
    /// 1σ of that solution's receiver clock, m (zero: none): the floor of the published
    /// clock σ.
    pub clock_floor_std_m: f64,
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

/// Whether the receiver marks `m`'s pseudorange valid (u-blox `trkStat` bit 0) and it is a
/// positive number.
fn pseudorange_valid(m: &RawMeasurement) -> bool {
    m.trk_stat & 1 != 0 && m.pseudorange_m.is_finite() && m.pseudorange_m > 0.0
}

/// Per system of [`DUAL_FREQUENCY_SIGNALS`] the second signal of an epoch's combinations: the
/// one with a valid pseudorange from most satellites (the table's order among equals), `None`
/// for a system with none. GPS first, then Galileo.
fn second_signals(meas: &[RawMeasurement]) -> [Option<(u8, &'static [u8], f64)>; 2] {
    let mut out = [None; 2];
    for (slot, system) in out.iter_mut().zip([GNSS_ID_GPS, GNSS_ID_GALILEO]) {
        let mut best = (0, None);
        for e in DUAL_FREQUENCY_SIGNALS.iter().filter(|e| e.0 == system) {
            let n = meas
                .iter()
                .filter(|m| m.gnss_id == e.0 && e.1.contains(&m.sig_id) && pseudorange_valid(m))
                .count();
            if n > best.0 {
                best = (n, Some(*e));
            }
        }
        *slot = best.1;
    }
    out
}

/// The second signal of an ionosphere-free combination ([`EphemerisStore::second_signal`]).
struct SecondSignal {
    pseudorange_m: f64,
    /// The receiver's 1σ, m.
    pseudorange_std_m: f32,
    freq_hz: f64,
    /// What the combination keeps of the two signals' group delays, s.
    combined_delay_s: f64,
    isc_unknown: bool,
}

/// The signal [`EphemerisStore::each_signal`] chose for a satellite, with its ephemeris.
struct Signal {
    model: SatModel,
    accuracy_m: f64,
    freq_hz: f64,
    t0_s: f64,
}

/// One satellite's broadcast motion and clock: a Keplerian orbit (GPS, Galileo, BeiDou; times
/// in the system's own time, s of week) or GLONASS immediate data (times in GPS time, s of
/// week; the state integrated from t_b, [`GloEphemeris::state_at`]). Positions and velocities
/// are in the ECEF of the instant asked for (PZ-90 taken as WGS 84: centimetres apart).
#[derive(Debug, Clone, Copy)]
enum SatModel {
    Kepler(Orbit),
    Glonass {
        eph: GloEphemeris,
        /// t_b as a GPS time of week, s (the one nearest the epoch).
        tb_tow_s: f64,
    },
}

impl SatModel {
    /// Seconds from t_b to GPS time `t_s` (s of week), across a week's end.
    fn since_tb(tb_tow_s: f64, t_s: f64) -> f64 {
        let dt = t_s - tb_tow_s;
        dt - (dt / 604_800.0).round() * 604_800.0
    }

    /// The satellite clock's offset at `t_s`, s (GPS, Galileo, BeiDou: with relativity and
    /// the group delay the orbit carries).
    fn clock_offset_s(&self, t_s: f64) -> f64 {
        match self {
            Self::Kepler(o) => o.clock_offset_s(t_s),
            Self::Glonass { eph, tb_tow_s } => eph.clock_offset_s(Self::since_tb(*tb_tow_s, t_s)),
        }
    }

    /// The satellite clock's drift at `t_s`, s/s.
    fn clock_drift(&self, t_s: f64) -> f64 {
        match self {
            Self::Kepler(o) => o.clock_drift(t_s),
            Self::Glonass { eph, .. } => eph.gamma,
        }
    }

    /// Position (m) and velocity (m/s) at `t_s`.
    fn state(&self, t_s: f64) -> ([f64; 3], [f64; 3]) {
        match self {
            Self::Kepler(o) => (o.position_ecef_m(t_s), o.velocity_ecef_mps(t_s)),
            Self::Glonass { eph, tb_tow_s } => eph.state_at(Self::since_tb(*tb_tow_s, t_s)),
        }
    }
}

/// The systems the tightly coupled filter fuses (u-blox `gnssId`s): GPS, Galileo, BeiDou,
/// GLONASS.
pub const RANGE_SYSTEMS: [u8; 4] = [GNSS_ID_GPS, GNSS_ID_GALILEO, GNSS_ID_BEIDOU, GNSS_ID_GLONASS];

/// What [`EphemerisStore::range_epoch`] left out of an epoch, by reason.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RangeBuildCounts {
    /// Signals not in [`SPP_SIGNALS`] (L2/L5/E5…, GLONASS on an unknown channel), of systems
    /// not asked for, or with a preferred signal of the same satellite in the epoch.
    pub other_signals: u64,
    /// Signals whose pseudorange the receiver marks invalid.
    pub invalid: u64,
    /// Satellites without a complete, healthy, current ephemeris (GPS URA index 15, no
    /// accuracy prediction, counts as unhealthy).
    pub no_ephemeris: u64,
    /// Satellites beyond [`MAX_RANGE_SATS`] (the weakest are dropped).
    pub over_capacity: u64,
    /// Dual-frequency single-point positioning: GPS and Galileo satellites without their
    /// second signal ([`EphemerisStore::system_observations`]).
    pub no_second_signal: u64,
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
    /// T_GD and the inter-signal corrections of the latest CNAV message type 30.
    cnav_delays: Option<cnav::GroupDelays>,
}

/// Whether a newly completed ephemeris replaces the one a satellite holds: unless the held one
/// has a later reference time. A satellite's navigation messages (GPS LNAV and CNAV, Galileo
/// I/NAV and F/NAV) are decoded separately and may carry different issues: the newer t_oe
/// wins, a tie goes to the newest arrival.
fn replaces(held: Option<&Orbit>, new: &Orbit) -> bool {
    held.is_none_or(|o| {
        let mut dt = o.toe_s - new.toe_s;
        dt -= (dt / 604_800.0).round() * 604_800.0;
        dt <= 0.0
    })
}

impl SatEphemeris {
    /// Takes a completed GPS ephemeris (LNAV or CNAV) when it [`replaces`] the held one;
    /// returns whether the orbit changed.
    fn keep(&mut self, orbit: Orbit, healthy: bool, ura_m: f64) -> bool {
        if !replaces(self.orbit.as_ref(), &orbit) {
            return false;
        }
        let changed = self.orbit != Some(orbit);
        (self.orbit, self.healthy, self.ura_m) = (Some(orbit), healthy, ura_m);
        changed
    }
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
    /// Galileo, BeiDou and GLONASS (on the heap: ~130 kB, allocated once with the store).
    others: Box<OtherSystems>,
    /// Galileo, BeiDou and GLONASS ephemerides completed.
    pub other_ephemerides: u64,
}

/// The Galileo, BeiDou and GLONASS part of an [`EphemerisStore`].
#[derive(Debug, Clone)]
struct OtherSystems {
    /// Navigation data assembled per satellite.
    collector: NavCollector,
    /// The latest Galileo ephemeris of each SVID.
    gal: [Option<BroadcastEphemeris>; MAX_GAL],
    /// The latest BeiDou ephemeris of each PRN.
    bds: [Option<BroadcastEphemeris>; MAX_BDS],
    /// BeiDou's broadcast Klobuchar coefficients (D1/D2 subframe 1), the ionosphere when no
    /// GPS page 18 came.
    bds_iono: Option<Klobuchar>,
    /// GLONASS immediate data per slot.
    glo: GloStore,
}

impl Default for EphemerisStore {
    fn default() -> Self {
        Self {
            sats: [SatEphemeris::default(); MAX_PRN],
            iono: None,
            bad_subframes: 0,
            ephemerides: 0,
            others: Box::new(OtherSystems {
                collector: NavCollector::default(),
                gal: [None; MAX_GAL],
                bds: [None; MAX_BDS],
                bds_iono: None,
                glo: GloStore::default(),
            }),
            other_ephemerides: 0,
        }
    }
}

impl EphemerisStore {
    /// Takes one navigation-data message: GPS LNAV subframes are decoded (parity checked) and
    /// subframes 1–3 of one issue make an ephemeris (IODC's 8 LSBs = IODE of subframes 2 and
    /// 3); subframe 4 page 18 sets the ionosphere. GPS CNAV, Galileo and BeiDou words go to
    /// the [`NavCollector`], whose ephemerides are kept per satellite; GLONASS strings to a
    /// [`GloStore`]. Others are ignored.
    pub fn on_nav_data(&mut self, d: &GnssNavData) {
        if d.gnss_id == GNSS_ID_GLONASS {
            let n = usize::from(d.num_words).min(d.words.len());
            let before = self.others.glo.counters.ephemerides;
            self.others.glo.on_words(d.sv_id, &d.words[..n]);
            self.other_ephemerides += self.others.glo.counters.ephemerides - before;
            return;
        }
        if !carries_lnav(d.gnss_id, d.sig_id) {
            let n = usize::from(d.num_words).min(d.words.len());
            if let Ok(Some(e)) = self
                .others
                .collector
                .on_words(d.gnss_id, d.sv_id, d.sig_id, &d.words[..n])
            {
                self.on_broadcast(&e);
            }
            return;
        }
        if usize::from(d.num_words) < 10 {
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
            // IS-GPS-200 §20.3.3.3.1.4: the six-bit health's MSB summarises the navigation data.
            let ura = ura_m(s1.ura);
            if e.keep(
                orbit,
                s1.health & 0x20 == 0 && ura.is_some(),
                ura.unwrap_or(f64::INFINITY),
            ) {
                self.ephemerides += 1;
            }
        }
    }

    /// Keeps a Galileo (I/NAV, F/NAV), BeiDou or GPS CNAV ephemeris ([`insert_broadcast`]), and
    /// BeiDou's ionosphere coefficients.
    ///
    /// [`insert_broadcast`]: Self::insert_broadcast
    pub fn on_broadcast(&mut self, e: &NavEphemeris) {
        if let NavEphemeris::GpsCnav(c) = e
            && let Some(sat) = usize::from(c.sv).checked_sub(1).and_then(|i| self.sats.get_mut(i))
        {
            sat.cnav_delays = Some(c.delays);
        }
        if let NavEphemeris::Beidou(d) = e
            && d.s1.alpha.iter().any(|a| *a != 0.0)
        {
            self.others.bds_iono = Some(Klobuchar {
                alpha: d.s1.alpha,
                beta: d.s1.beta,
            });
        }
        self.insert_broadcast(e.broadcast());
    }

    /// Keeps a Galileo, BeiDou or GPS (CNAV, beside LNAV's) ephemeris for its satellite when it
    /// [`replaces`] the one held (others are ignored).
    pub fn insert_broadcast(&mut self, b: BroadcastEphemeris) {
        if b.gnss_id == GNSS_ID_GPS {
            let slot = usize::from(b.sv_id).checked_sub(1).and_then(|i| self.sats.get_mut(i));
            if let Some(e) = slot
                && e.keep(b.orbit, b.healthy, b.accuracy_m)
            {
                self.ephemerides += 1;
            }
            return;
        }
        let slot = usize::from(b.sv_id).checked_sub(1).and_then(|i| match b.gnss_id {
            GNSS_ID_GALILEO => self.others.gal.get_mut(i),
            GNSS_ID_BEIDOU => self.others.bds.get_mut(i),
            _ => None,
        });
        if let Some(s) = slot
            && replaces(s.as_ref().map(|o| &o.orbit), &b.orbit)
        {
            if s.map(|o| o.orbit) != Some(b.orbit) {
                self.other_ephemerides += 1;
            }
            *s = Some(b);
        }
    }

    /// The broadcast ionosphere: GPS's (LNAV subframe 4 page 18, else CNAV message type 30),
    /// else BeiDou's coefficients.
    pub fn iono(&self) -> Option<Klobuchar> {
        let cnav = self
            .others
            .collector
            .gps_cnav_iono
            .map(|(alpha, beta)| Klobuchar { alpha, beta });
        self.iono.or(cnav).or(self.others.bds_iono)
    }

    /// The usable ephemeris of satellite `sv_id` of system `gnss_id` at `t_s` (s of week in the
    /// system's own time; GLONASS: GPS time, with GPS − UTC = `leap_s`): its model and
    /// accuracy, m.
    fn usable_any(&self, gnss_id: u8, sv_id: u8, t_s: f64, leap_s: f64) -> Option<(SatModel, f64)> {
        if gnss_id == GNSS_ID_GPS {
            return self
                .usable_ephemeris(sv_id, t_s)
                .map(|(o, a)| (SatModel::Kepler(*o), a));
        }
        if gnss_id == GNSS_ID_GLONASS {
            let eph = *self.others.glo.ephemeris(sv_id).filter(|e| e.healthy())?;
            let accuracy_m = eph.accuracy_m()?.hypot(GLONASS_IFB_STD_M);
            let dt = glonass::seconds_since_tb_gps(eph.tb_s, t_s, leap_s);
            return (dt.abs() <= glonass::EPHEMERIS_VALID_S).then_some((
                SatModel::Glonass {
                    eph,
                    tb_tow_s: t_s - dt,
                },
                accuracy_m,
            ));
        }
        let i = usize::from(sv_id).checked_sub(1)?;
        let e = match gnss_id {
            GNSS_ID_GALILEO => self.others.gal.get(i),
            GNSS_ID_BEIDOU => self.others.bds.get(i),
            _ => None,
        }?
        .as_ref()
        .filter(|e| e.healthy && e.accuracy_m.is_finite())?;
        let mut dt = t_s - e.orbit.toe_s;
        dt -= (dt / 604_800.0).round() * 604_800.0;
        (dt.abs() <= EPHEMERIS_VALID_S).then_some((SatModel::Kepler(e.orbit), e.accuracy_m))
    }

    /// Per satellite of the systems `systems` (u-blox `gnssId`s) the first signal of
    /// [`SPP_SIGNALS`] the receiver tracked with a valid pseudorange, given to `each` with its
    /// satellite's ephemeris: the orbit (its group delay zeroed for a signal that is the
    /// clock's reference), the broadcast accuracy, m, the carrier frequency, Hz, and the
    /// reception time less the flight time, t_rx − ρ/c, in the system's own time, s of week
    /// (BeiDou: BDT = GPST − 14 s; Galileo: GST taken as GPST, the GGTO of a few ns left in the
    /// receiver's Galileo clock; GLONASS: GPS time, its offset from GLONASS time left in the
    /// receiver's GLONASS clock). A GLONASS signal's carrier is its channel's (u-blox
    /// `freqId` − 7); one without a channel (`freqId` > 13) counts as another signal. GPS −
    /// UTC: [`GnssRaw::gps_minus_utc_s`]. What is left out is counted in `counts`.
    fn each_signal(
        &self,
        raw: &GnssRaw,
        systems: &[u8],
        counts: &mut RangeBuildCounts,
        mut each: impl FnMut(&RawMeasurement, Signal),
    ) {
        let n = usize::from(raw.num_meas).min(raw.meas.len());
        let meas = &raw.meas[..n];
        let leap_s = f64::from(raw.gps_minus_utc_s());
        let rank = |g: u8, s: u8| SPP_SIGNALS.iter().position(|&(sg, ss, _, _)| sg == g && ss == s);
        for (k, m) in meas.iter().enumerate() {
            let channel = (m.gnss_id == GNSS_ID_GLONASS).then_some(m.freq_id);
            let Some(r) =
                rank(m.gnss_id, m.sig_id).filter(|_| systems.contains(&m.gnss_id) && channel.is_none_or(|c| c <= 13))
            else {
                counts.other_signals += 1;
                continue;
            };
            if !pseudorange_valid(m) {
                counts.invalid += 1;
                continue;
            }
            // A more preferred valid signal of the same satellite wins.
            let better = meas.iter().enumerate().any(|(j, o)| {
                j != k
                    && o.gnss_id == m.gnss_id
                    && o.sv_id == m.sv_id
                    && pseudorange_valid(o)
                    && rank(o.gnss_id, o.sig_id).is_some_and(|ro| ro < r || (ro == r && j < k))
            });
            if better {
                counts.other_signals += 1;
                continue;
            }
            let (_, _, freq_hz, group_delay) = SPP_SIGNALS[r];
            let freq_hz = channel.map_or(freq_hz, |c| glonass::l1of_hz(c as i8 - 7));
            let offset = if m.gnss_id == GNSS_ID_BEIDOU {
                BDT_MINUS_GPST_S
            } else {
                0.0
            };
            let t0_s = raw.rcv_tow_s + offset - m.pseudorange_m / C_M_S;
            let Some((mut model, accuracy_m)) = self.usable_any(m.gnss_id, m.sv_id, t0_s, leap_s) else {
                counts.no_ephemeris += 1;
                continue;
            };
            if let SatModel::Kepler(orbit) = &mut model
                && !group_delay
            {
                orbit.tgd_s = 0.0;
            }
            each(
                m,
                Signal {
                    model,
                    accuracy_m,
                    freq_hz,
                    t0_s,
                },
            );
        }
    }

    /// The pseudoranges of `raw` for single-point positioning with the systems `systems`
    /// (u-blox `gnssId`s), the signal of each satellite chosen as for the filter
    /// ([`each_signal`](Self::each_signal)): its satellite's position at transmission (in the
    /// ECEF of that instant), its clock offset including the signal's group delay, the
    /// ionosphere scale (f_L1/f)² of its carrier, and a σ at zenith of the larger of the
    /// receiver's σ and the broadcast accuracy.
    ///
    /// `dual_frequency`: each satellite of a system of [`DUAL_FREQUENCY_SIGNALS`] (GPS,
    /// Galileo) with its first signal and its second signal's ionosphere-free combination P =
    /// (f₁²P₁ − f₂²P₂)/(f₁² − f₂²) (IS-GPS-200 §20.3.3.3.3.3, §30.3.3.3.1.1.1; OS SIS ICD
    /// §5.1.5), the clock less what that keeps of the group delays
    /// ([`SignalDelays::combination_keeps`]), an ionosphere scale of 0, and each signal's σ
    /// scaled by its coefficient. One second signal per system and epoch, the one most of its
    /// satellites have ([`second_signals`]): a receiver delays each signal differently, and one
    /// combination for all of a system's satellites leaves that in the system's clock. A
    /// satellite without it is left out ([`RangeBuildCounts::no_second_signal`]): on one
    /// frequency, or another pair, it would carry the receiver's bias between the signals into
    /// its system's clock. BeiDou and GLONASS stay on one frequency.
    pub fn system_observations(
        &self,
        raw: &GnssRaw,
        systems: &[u8],
        dual_frequency: bool,
        counts: &mut RangeBuildCounts,
    ) -> Vec<SystemObservation> {
        let (mut out, mut no_second) = (Vec::new(), 0);
        let n = usize::from(raw.num_meas).min(raw.meas.len());
        let meas = &raw.meas[..n];
        let chosen = second_signals(meas);
        self.each_signal(raw, systems, counts, |m, sig| {
            let paired = dual_frequency && DUAL_FREQUENCY_SIGNALS.iter().any(|(g, _, _)| *g == m.gnss_id);
            let second = paired
                .then(|| self.second_signal(meas, m, sig.freq_hz, &chosen))
                .flatten();
            if paired && second.is_none() {
                no_second += 1;
                return;
            }
            let mut model = sig.model;
            if let (true, SatModel::Kepler(o)) = (second.is_some(), &mut model) {
                o.tgd_s = 0.0;
            }
            let dt_sv = model.clock_offset_s(sig.t0_s);
            let t_tx = sig.t0_s - dt_sv;
            let receiver_std_m = f64::from(m.pseudorange_std_m);
            let mut o = SystemObservation {
                obs: Observation {
                    sv: m.sv_id,
                    pseudorange_m: m.pseudorange_m,
                    sat_ecef_m: model.state(t_tx).0,
                    sat_clock_s: dt_sv,
                    sigma_zenith_m: receiver_std_m.max(sig.accuracy_m),
                },
                gnss_id: m.gnss_id,
                iono_scale: (L1_HZ / sig.freq_hz).powi(2),
                noise_gain: 1.0,
            };
            if let Some(p) = second {
                let (g1, g2) = (sig.freq_hz.powi(2), p.freq_hz.powi(2));
                let (a1, a2) = (g1 / (g1 - g2), g2 / (g1 - g2));
                o.obs.pseudorange_m = a1 * m.pseudorange_m - a2 * p.pseudorange_m;
                o.obs.sat_clock_s = dt_sv - p.combined_delay_s;
                o.iono_scale = 0.0;
                o.noise_gain = a1.hypot(a2);
                let std_m = (a1 * receiver_std_m).hypot(a2 * f64::from(p.pseudorange_std_m));
                let isc_m = if p.isc_unknown {
                    o.noise_gain * C_M_S * ISC_UNKNOWN_STD_S
                } else {
                    0.0
                };
                o.obs.sigma_zenith_m = std_m.max(sig.accuracy_m).hypot(isc_m);
            }
            out.push(o);
        });
        counts.no_second_signal += no_second;
        out
    }

    /// The second signal of `first`'s satellite (carrier `f1_hz`) for an ionosphere-free
    /// combination: its system's signal of `chosen` ([`second_signals`]) with a valid
    /// pseudorange, when the satellite's ephemeris gives its group delay and `first`'s.
    fn second_signal(
        &self,
        meas: &[RawMeasurement],
        first: &RawMeasurement,
        f1_hz: f64,
        chosen: &[Option<(u8, &[u8], f64)>],
    ) -> Option<SecondSignal> {
        let &(_, sigs, f2_hz) = chosen.iter().flatten().find(|(g, _, _)| *g == first.gnss_id)?;
        let m = sigs.iter().find_map(|&sig| {
            meas.iter()
                .find(|o| (o.gnss_id, o.sv_id, o.sig_id) == (first.gnss_id, first.sv_id, sig) && pseudorange_valid(o))
        })?;
        let delays = self.signal_delays(first.gnss_id, first.sv_id)?;
        Some(SecondSignal {
            pseudorange_m: m.pseudorange_m,
            pseudorange_std_m: m.pseudorange_std_m,
            freq_hz: f2_hz,
            combined_delay_s: SignalDelays::combination_keeps(
                f1_hz,
                delays.of_signal(first.gnss_id, first.sig_id, f1_hz)?,
                f2_hz,
                delays.of_signal(m.gnss_id, m.sig_id, f2_hz)?,
            ),
            isc_unknown: delays.isc_unknown,
        })
    }

    /// The group delays of satellite `sv_id` of system `gnss_id` against its ephemeris' clock:
    /// GPS from T_GD and CNAV's inter-signal corrections ([`SignalDelays::gps`]), Galileo from
    /// the BGDs of the ephemeris held; `None` for the other systems.
    fn signal_delays(&self, gnss_id: u8, sv_id: u8) -> Option<SignalDelays> {
        let i = usize::from(sv_id).checked_sub(1)?;
        match gnss_id {
            GNSS_ID_GPS => {
                let e = self.sats.get(i)?;
                Some(SignalDelays::gps(e.orbit?.tgd_s, e.cnav_delays.as_ref()))
            }
            GNSS_ID_GALILEO => self.others.gal.get(i)?.map(|e| e.delays),
            _ => None,
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

    /// The measurements of `raw` of every system of [`RANGE_SYSTEMS`] (per satellite the
    /// signal [`each_signal`](Self::each_signal) chooses) with their satellites' states
    /// (IS-GPS-200 §20.3.3.3.3.1: transmission time t = t_rx − ρ/c − δt_sv, whichever the
    /// receiver's clock error, since the pseudorange carries the same error), stamped
    /// `stamp_host_ns`; `rx_clock_bias_m` (c·δt_r, the filter's estimate, 0 when none) turns
    /// the receiver's time into GPS time. The strongest [`MAX_RANGE_SATS`] are kept.
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
            iono: self.iono(),
            pos_floor_std_ned_m: [0.0; 3],
            clock_floor_std_m: 0.0,
            count: 0,
            sats: [SatRange::default(); MAX_RANGE_SATS],
        };
        let mut over = 0;
        self.each_signal(raw, &RANGE_SYSTEMS, counts, |m, sig| {
            let lambda = C_M_S / sig.freq_hz;
            let dt_sv = sig.model.clock_offset_s(sig.t0_s);
            let t_tx = sig.t0_s - dt_sv;
            let (sat_ecef_m, sat_vel_mps) = sig.model.state(t_tx);
            let doppler = f64::from(m.doppler_hz);
            let sat = SatRange {
                gnss_id: m.gnss_id,
                sv: m.sv_id,
                iono_scale: (L1_HZ / sig.freq_hz).powi(2),
                cno_dbhz: m.cno_dbhz,
                pseudorange_m: m.pseudorange_m + C_M_S * dt_sv,
                range_rate_mps: if doppler.is_finite() {
                    -lambda * doppler + C_M_S * sig.model.clock_drift(t_tx)
                } else {
                    f64::NAN
                },
                sat_ecef_m,
                sat_vel_mps,
                // The receiver's σ, at least the broadcast accuracy.
                pseudorange_std_m: f64::from(m.pseudorange_std_m).max(sig.accuracy_m),
                range_rate_std_mps: (f64::from(m.doppler_std_hz) * lambda).max(0.0),
                sig_id: m.sig_id,
                carrier_m: if m.trk_stat & 2 != 0 && m.carrier_phase_cycles.is_finite() && m.carrier_phase_cycles != 0.0
                {
                    lambda * m.carrier_phase_cycles + C_M_S * dt_sv
                } else {
                    f64::NAN
                },
                carrier_std_m: lambda * f64::from(m.carrier_phase_std_cycles).max(0.0),
                lock_time_ms: m.lock_time_ms,
                trk_stat: m.trk_stat,
            };
            let count = usize::from(out.count);
            if count < MAX_RANGE_SATS {
                out.sats[count] = sat;
                out.count += 1;
                return;
            }
            over += 1;
            // Full: replace the weakest if this one is stronger.
            if let Some(weakest) = out.sats.iter_mut().min_by_key(|s| s.cno_dbhz)
                && weakest.cno_dbhz < sat.cno_dbhz
            {
                *weakest = sat;
            }
        });
        counts.over_capacity += over;
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

    /// A GPS satellite's LNAV and CNAV ephemerides share its slot: the later t_oe is kept
    /// whichever arrives last, a tie goes to the newest arrival.
    #[test]
    fn lnav_and_cnav_of_a_satellite_keep_the_later_reference_time() {
        let orbit = |toe_s: f64, e: f64| Orbit {
            toe_s,
            e,
            sqrt_a: 5153.7,
            ..Orbit::default()
        };
        let cnav = |toe_s, e| BroadcastEphemeris {
            gnss_id: GNSS_ID_GPS,
            sv_id: 10,
            orbit: orbit(toe_s, e),
            iod: 0,
            healthy: true,
            accuracy_m: 1.4,
            delays: SignalDelays::default(),
        };
        let mut st = EphemerisStore::default();
        st.insert_broadcast(cnav(408_600.0, 0.01));
        assert_eq!(
            st.usable_ephemeris(10, 408_700.0).map(|(o, a)| (o.e, a)),
            Some((0.01, 1.4))
        );
        // An LNAV issue with a later t_oe (LNAV's t_oe leads its transmission) replaces it.
        let lnav = |toe16: u16, iode: u8| {
            [
                Subframe::Ephem1(Ephem1 {
                    iodc: u16::from(iode),
                    ..Ephem1::default()
                }),
                Subframe::Ephem2(Ephem2 {
                    iode,
                    toe: toe16,
                    sqrt_a: (5153.7f64 * 2f64.powi(19)) as u32,
                    ..Ephem2::default()
                }),
                Subframe::Ephem3(Ephem3 {
                    iode,
                    ..Ephem3::default()
                }),
            ]
        };
        for sf in &lnav((410_400 / 16) as u16, 3) {
            st.on_subframe(10, sf);
        }
        let toe = |st: &EphemerisStore| st.orbit(10, 409_000.0).map(|o| o.toe_s);
        assert_eq!(toe(&st), Some(410_400.0));
        // A CNAV of an earlier t_oe does not; one of the same t_oe does (the newest arrival).
        st.insert_broadcast(cnav(409_500.0, 0.02));
        assert_eq!(toe(&st), Some(410_400.0));
        st.insert_broadcast(cnav(410_400.0, 0.03));
        assert_eq!(st.orbit(10, 409_000.0).map(|o| o.e), Some(0.03));
        // An LNAV of an earlier t_oe after it: kept out.
        for sf in &lnav((403_200 / 16) as u16, 4) {
            st.on_subframe(10, sf);
        }
        assert_eq!(st.orbit(10, 409_000.0).map(|o| o.e), Some(0.03));
        assert_eq!(st.ephemerides, 3);
    }

    /// Every signal the filter and single-point positioning use is one a full epoch keeps
    /// first, every second signal of a combination next ([`RawMeasurement::keep_rank`]).
    #[test]
    fn the_signals_used_are_the_ones_kept() {
        use navsync_wire::reflect::Reflect;
        let rank = |gnss_id, sig_id| {
            let mut m = RawMeasurement::zeroed();
            (m.gnss_id, m.sig_id) = (gnss_id, sig_id);
            m.keep_rank()
        };
        for (g, sig, _, _) in SPP_SIGNALS {
            assert_eq!(rank(g, sig), 0, "gnssId {g} sigId {sig}");
        }
        for (g, sigs, _) in DUAL_FREQUENCY_SIGNALS {
            for &sig in sigs {
                assert_eq!(rank(g, sig), 1, "gnssId {g} sigId {sig}");
            }
        }
        assert_eq!(rank(GNSS_ID_GPS, 7), 2);
    }

    /// Dual frequency: a GPS satellite's L1 C/A and L2 CL and a Galileo satellite's E1-C and
    /// E5a-Q, each delayed by the ionosphere as (f_L1/f)², combine to the range without it and
    /// with each clock less what the combination keeps of the group delays (GPS: nothing
    /// without CNAV's corrections, whose σ is added; Galileo I/NAV: BGD(E1,E5b) −
    /// BGD(E1,E5a)); a GPS satellite without the epoch's GPS second signal (L2C, which two
    /// satellites have, against one with L2 P(Y)) is left out and counted; BeiDou stays on one
    /// frequency.
    #[test]
    fn dual_frequency_observations_cancel_the_ionosphere() {
        use crate::gnss::orbit::OrbitFrame;
        use navsync_wire::reflect::Reflect;
        let t_rx = 300_000.0;
        let orbit = |frame, af0: f64, tgd_s| Orbit {
            sqrt_a: 5_300.0,
            i0_rad: 0.95,
            toe_s: t_rx,
            toc_s: t_rx,
            af: [af0, 0.0, 0.0],
            tgd_s,
            frame,
            ..Orbit::default()
        };
        let (bgd_a, bgd_b) = (-3.9e-9, -4.4e-9);
        let mut st = EphemerisStore::default();
        for prn in [3, 4, 6, 7] {
            st.insert_orbit(prn, orbit(OrbitFrame::Gps, 1e-4, 5e-9));
        }
        st.insert_broadcast(BroadcastEphemeris {
            gnss_id: GNSS_ID_GALILEO,
            sv_id: 5,
            orbit: orbit(OrbitFrame::Galileo, 1e-3, bgd_b),
            iod: 1,
            healthy: true,
            accuracy_m: 2.0,
            delays: SignalDelays::galileo(bgd_a, Some(bgd_b)),
        });
        st.insert_broadcast(BroadcastEphemeris {
            gnss_id: GNSS_ID_BEIDOU,
            sv_id: 20,
            orbit: orbit(OrbitFrame::BeiDou, 2e-3, 0.0),
            iod: 1,
            healthy: true,
            accuracy_m: 2.0,
            delays: SignalDelays::default(),
        });
        let iono_l1_m = 6.0;
        let meas = |gnss_id, sv_id, sig_id, freq_hz: f64| {
            let mut m = RawMeasurement::zeroed();
            let pr = 2.2e7 + iono_l1_m * (L1_HZ / freq_hz).powi(2);
            (m.gnss_id, m.sv_id, m.sig_id, m.pseudorange_m, m.trk_stat) = (gnss_id, sv_id, sig_id, pr, 1);
            m.pseudorange_std_m = 0.5;
            m
        };
        let list = [
            meas(GNSS_ID_GPS, 3, 0, L1_HZ),
            meas(GNSS_ID_GPS, 3, 3, L2_HZ),
            meas(GNSS_ID_GPS, 3, 7, L5_HZ), // L5: not GPS's second band
            meas(GNSS_ID_GPS, 4, 0, L1_HZ),
            // L2 P(Y) on one satellite, L2C on two: the epoch's GPS pairs are L1/L2C.
            meas(GNSS_ID_GPS, 6, 0, L1_HZ),
            meas(GNSS_ID_GPS, 6, SIG_GPS_L2_PY, L2_HZ),
            meas(GNSS_ID_GPS, 7, 0, L1_HZ),
            meas(GNSS_ID_GPS, 7, 4, L2_HZ),
            meas(GNSS_ID_GALILEO, 5, 0, L1_HZ),
            meas(GNSS_ID_GALILEO, 5, 4, L5_HZ),
            meas(GNSS_ID_BEIDOU, 20, 4, 1_268.52e6),
        ];
        let mut raw = GnssRaw::zeroed();
        raw.rcv_tow_s = t_rx;
        raw.meas[..list.len()].copy_from_slice(&list);
        raw.num_meas = list.len() as u8;
        let mut counts = RangeBuildCounts::default();
        let obs = st.system_observations(&raw, &[0, 2, 3], true, &mut counts);
        assert_eq!(counts.no_second_signal, 2);
        assert_eq!(obs.len(), 4, "{obs:?}");
        let gps: Vec<u8> = obs
            .iter()
            .filter(|o| o.gnss_id == GNSS_ID_GPS)
            .map(|o| o.obs.sv)
            .collect();
        assert_eq!(gps, [3, 7]);
        let find = |g: u8| obs.iter().find(|o| o.gnss_id == g).unwrap();
        let (g, e, c) = (find(GNSS_ID_GPS), find(GNSS_ID_GALILEO), find(GNSS_ID_BEIDOU));
        assert_eq!(g.obs.sv, 3);
        for o in [g, e] {
            assert!((o.obs.pseudorange_m - 2.2e7).abs() < 1e-6, "{o:?}");
            assert_eq!(o.iono_scale, 0.0);
        }
        assert!((g.obs.sat_clock_s - 1e-4).abs() < 1e-15, "{}", g.obs.sat_clock_s);
        assert!((e.obs.sat_clock_s - (1e-3 - (bgd_b - bgd_a))).abs() < 1e-15);
        let gain = |f2: f64| {
            let (g1, g2) = (L1_HZ * L1_HZ, f2 * f2);
            (g1 / (g1 - g2)).hypot(g2 / (g1 - g2))
        };
        assert!((g.noise_gain - gain(L2_HZ)).abs() < 1e-12 && (g.noise_gain - 2.98).abs() < 0.01);
        assert!((e.noise_gain - gain(L5_HZ)).abs() < 1e-12);
        // GPS: 0.5 m per signal through the combination and 1 ns per unknown correction.
        let want = (0.5 * gain(L2_HZ)).hypot(gain(L2_HZ) * C_M_S * 1e-9);
        assert!(
            (g.obs.sigma_zenith_m - want).abs() < 1e-9,
            "{} vs {want}",
            g.obs.sigma_zenith_m
        );
        assert_eq!((e.obs.sigma_zenith_m, c.noise_gain), (2.0, 1.0));
        assert!(c.iono_scale > 1.0);
        // One frequency: GPS 4 and 6 are back, each pseudorange as measured.
        let single = st.system_observations(&raw, &[0, 2, 3], false, &mut counts);
        assert_eq!(single.len(), 6);
        assert!(single.iter().all(|o| o.noise_gain == 1.0 && o.iono_scale >= 1.0));
    }

    /// Per satellite the preferred signal (E1-C before E1-B whatever the order), only the
    /// systems asked for, BeiDou's clock at BDT = GPST − 14 s without a group delay on B3I,
    /// Galileo's with its BGD, the ionosphere scale of each carrier; unhealthy satellites and
    /// signals not in the table left out and counted.
    #[test]
    fn system_observations_pick_the_signal_and_its_clock() {
        use crate::gnss::orbit::OrbitFrame;
        use navsync_wire::reflect::Reflect;
        let t_rx = 300_000.0;
        let orbit = |frame, af: [f64; 3], tgd_s, toc_s| Orbit {
            sqrt_a: 5_300.0,
            i0_rad: 0.95,
            toe_s: t_rx,
            toc_s,
            af,
            tgd_s,
            frame,
            ..Orbit::default()
        };
        let broadcast = |gnss_id, sv_id, orbit, healthy| BroadcastEphemeris {
            gnss_id,
            sv_id,
            orbit,
            iod: 1,
            healthy,
            accuracy_m: 2.0,
            delays: SignalDelays::default(),
        };
        let mut st = EphemerisStore::default();
        st.insert_orbit(3, orbit(OrbitFrame::Gps, [1e-4, 0.0, 0.0], 5e-9, t_rx));
        let gal = orbit(OrbitFrame::Galileo, [1e-3, 0.0, 0.0], 1e-8, t_rx);
        st.insert_broadcast(broadcast(GNSS_ID_GALILEO, 5, gal, true));
        // BeiDou's clock reference 14 s before the GPS time of the epoch: with a drift of
        // 1e-6 the offset is af0 + 1e-6·(−ρ/c) in BDT, 14e-6 s more if read in GPS time.
        let bds = orbit(OrbitFrame::BeiDou, [2e-3, 1e-6, 0.0], 5e-9, t_rx - 14.0);
        st.insert_broadcast(broadcast(GNSS_ID_BEIDOU, 20, bds, true));
        st.insert_broadcast(broadcast(GNSS_ID_BEIDOU, 21, bds, false));
        let meas = |gnss_id, sv_id, sig_id, pr| {
            let mut m = RawMeasurement::zeroed();
            (m.gnss_id, m.sv_id, m.sig_id, m.pseudorange_m, m.trk_stat) = (gnss_id, sv_id, sig_id, pr, 1);
            m
        };
        let list = [
            meas(GNSS_ID_GALILEO, 5, 1, 2.4e7 + 5.0), // E1-B
            meas(GNSS_ID_GPS, 3, 0, 2.1e7),
            meas(GNSS_ID_GALILEO, 5, 0, 2.4e7), // E1-C: preferred
            meas(GNSS_ID_GALILEO, 5, 4, 2.4e7), // E5a: not used
            meas(GNSS_ID_BEIDOU, 20, 4, 2.2e7), // B3I
            meas(GNSS_ID_BEIDOU, 21, 4, 2.2e7), // unhealthy
            meas(6, 1, 0, 2.0e7),               // GLONASS: not solved
        ];
        let mut raw = GnssRaw::zeroed();
        raw.rcv_tow_s = t_rx;
        raw.meas[..list.len()].copy_from_slice(&list);
        raw.num_meas = list.len() as u8;
        let mut counts = RangeBuildCounts::default();
        let obs = st.system_observations(&raw, &[0, 2, 3], false, &mut counts);
        assert_eq!(obs.len(), 3, "{obs:?}");
        assert_eq!((counts.other_signals, counts.no_ephemeris, counts.invalid), (3, 1, 0));
        let find = |g: u8| obs.iter().find(|o| o.gnss_id == g).unwrap();
        let (g, e, c) = (find(GNSS_ID_GPS), find(GNSS_ID_GALILEO), find(GNSS_ID_BEIDOU));
        assert_eq!(e.obs.pseudorange_m, 2.4e7);
        assert!((g.obs.sat_clock_s - (1e-4 - 5e-9)).abs() < 1e-15);
        assert!((e.obs.sat_clock_s - (1e-3 - 1e-8)).abs() < 1e-15);
        let want = 2e-3 + 1e-6 * (-2.2e7 / C_M_S);
        assert!(
            (c.obs.sat_clock_s - want).abs() < 1e-12,
            "{} vs {want}",
            c.obs.sat_clock_s
        );
        assert_eq!((g.iono_scale, e.iono_scale), (1.0, 1.0));
        assert!((c.iono_scale - (1575.42f64 / 1268.52).powi(2)).abs() < 1e-12);
        assert_eq!(e.obs.sigma_zenith_m, 2.0);
        // Galileo only.
        let only = st.system_observations(&raw, &[GNSS_ID_GALILEO], false, &mut counts);
        assert_eq!((only.len(), only[0].gnss_id), (1, GNSS_ID_GALILEO));
    }
}
