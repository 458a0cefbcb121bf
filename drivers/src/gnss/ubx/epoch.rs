//! Groups decoded UBX messages into navigation epochs: one [`GnssFix`] per epoch.
//!
//! All NAV messages of one navigation epoch carry the same `iTOW` (GPS time of week, ms;
//! u-blox 8 / M8 Receiver Description UBX-13003221, "iTOW Timestamps"). The
//! [`EpochAssembler`] merges them, each quantity from the message of the highest precedence
//! whatever the order of arrival (the table at `Sources`; `docs/guide/receivers.md`), and
//! publishes the epoch **once**, when it is complete and has its time:
//!
//! - at **NAV-EOE** of its `iTOW` (protocol 18+ receivers send it after the epoch's last NAV
//!   message);
//! - else at the receiver's **last NAV message of the cycle**, once learned: whenever an
//!   epoch ends without NAV-EOE (a NAV message of another `iTOW` arrives, or the line went
//!   idle and the next epoch begins), its last NAV message is a candidate, trusted after
//!   [`ENDER_VOTES`](crate::gnss::cycle::ENDER_VOTES) consecutive epochs agree; a message
//!   ever seen followed by another NAV message of its epoch is never trusted
//!   ([`CycleEnder::followed`]);
//! - else when a NAV message with **another `iTOW`** arrives (the first of the next epoch);
//! - else on [`EpochAssembler::flush`] (the live driver calls it when the line goes idle).
//!
//! A NAV message for an epoch already published is late: counted (`late_messages`), never
//! published again (a late NAV-SAT still becomes the satellites of its epoch), and the message
//! it followed is no longer trusted as the cycle's last. Each output (the NAV epochs, the
//! HNR-PVT fixes) passes a [`TimeOrder`]: its times strictly increase (`not_after_last`,
//! `time_resets`). The stamp of an epoch is the receipt time of its first message's first
//! byte; `seq` counts the fixes of its output.
//!
//! Older receivers (u-blox 4 to 7) describe an epoch with NAV-SOL (ECEF position and
//! velocity, GPS week and time), NAV-TIMEGPS, NAV-POSLLH, NAV-VELNED, NAV-DOP, NAV-STATUS and
//! NAV-TIMEUTC; newer ones with NAV-PVT. Mapping to [`GnssFix`]:
//!
//! - **time**: the navigation epoch ([`epoch_ns`]: the precise time rounded to the
//!   millisecond). `utc_ns` from a valid UTC date and time (NAV-PVT `validDate` and
//!   `validTime`, NAV-TIMEUTC `validUTC`) plus `nano`; else from GPS week and `iTOW` + `fTOW` (NAV-SOL
//!   `WKNSET`/`TOWSET`, NAV-TIMEGPS `towValid`/`weekValid`) minus the leap seconds (the
//!   receiver's, NAV-TIMEGPS `leapSValid`, else the table of `navsync_shared::time`).
//!   `gps_ns` from week and time of week, else from `utc_ns` and the leap seconds.
//! - **mode** (gpsd's TPV mode, checked against gpsd's output in
//!   `drivers/tests/conformance/gpsd_ubx_conformance.rs`) from `fixType`/`gpsFix`: 0 no fix → 1;
//!   1 dead reckoning only → 2 (gpsd: "consider this too as 2D"); 2 → 2; 3 and 4 (GNSS +
//!   dead reckoning) → 3; 5 time only → 3 (a timing receiver's fixed, surveyed position, as
//!   gpsd reports it). NAV-STATUS with `gpsFixOk` clear says no fix (gpsd too); NAV-PVT's and
//!   NAV-SOL's fix type stand whatever `gnssFixOK` says (gpsd too): that flag is in `quality`
//!   and `fix_flags`.
//! - **quality** (NMEA GGA terms): `gnssFixOK`/`GPSfixOK` clear → 0; no fix → 0; carrier
//!   phase fixed → 4, float → 5; differential → 2; dead reckoning only → 6; else 1 (time only
//!   included).
//! - **position**: from NAV-PVT/NAV-POSLLH (1e-7°; `height` and `hMSL` → `alt_msl_m` and
//!   `geoid_sep_m` = height − hMSL); else from NAV-SOL's ECEF position ([`super::ecef`]).
//!   NAV-SOL gives no MSL altitude: `geoid_sep_m` is then EGM96's separation N at the
//!   position ([`crate::gnss::geoid`]) and `alt_msl_m` the ellipsoidal height less N, with
//!   the `sentences` bit `FIX_GEOID_MODEL` saying so; [`GnssFix::height_m`] is the receiver's
//!   ellipsoidal height either way.
//!   Nothing (position, height, velocity) is reported for an epoch without a fix (mode < 2),
//!   no position or height for one flagged `invalidLlh`, no position outside ±90°/±180°.
//!   DOPs of 99.99 (u-blox's "unknown") are NaN.
//! - **velocity**: NAV-PVT/NAV-VELNED north/east/down, ground speed and heading of motion;
//!   else NAV-SOL's ECEF velocity rotated to NED, speed and track from its north and east.
//! - **accuracies**: `hAcc`, `vAcc`, `sAcc`, `headAcc`/`cAcc` as reported (NAV-SOL's 3D
//!   `pAcc` is not a horizontal accuracy and is not used).
//! - **sats_used**: `numSV`, else the satellites NAV-SAT/NAV-SVINFO flag as used.
//!
//! HNR-PVT (the fused high-rate solution of ADR/UDR receivers) arrives between the NAV
//! epochs at its own rate: each one is a complete fix of its own, emitted at once (bit
//! `UBX_MSG_HNR_PVT`, `FIX_FLAG_NOT_GNSS`) with sequence numbers and time order of its own,
//! without disturbing the NAV epoch being assembled; the decoder hands it out as
//! `GnssExtra::Hnr` for `navsync/gnss/{id}/hnr`, never with the NAV epochs.
//!
//! The satellites of the last epoch that carried NAV-SAT/NAV-SVINFO
//! ([`EpochAssembler::satellites`]), the last TIM-TP ([`EpochAssembler::time_pulse`]) and
//! TIM-TM2 ([`EpochAssembler::time_mark`]) are kept for consumers.

use navsync_shared::samples::{
    FIX_FLAG_DIFFERENTIAL, FIX_FLAG_FULLY_RESOLVED, FIX_FLAG_INVALID_LLH, FIX_FLAG_NOT_GNSS, FIX_FLAG_OK,
    FIX_FLAG_RECEIVER_INVALID, FIX_FLAG_VALID_DATE, FIX_FLAG_VALID_TIME, FIX_GEOID_MODEL, FixMode, GNSS_PROTOCOL_UBX,
    GnssEvent, GnssFix, GnssTimePulse, Stamp, StampSource, UBX_MSG_HNR_PVT, UBX_MSG_NAV_DOP, UBX_MSG_NAV_EOE,
    UBX_MSG_NAV_POSLLH, UBX_MSG_NAV_PVT, UBX_MSG_NAV_SAT, UBX_MSG_NAV_SOL, UBX_MSG_NAV_STATUS, UBX_MSG_NAV_TIMEGPS,
    UBX_MSG_NAV_TIMEUTC, UBX_MSG_NAV_VELNED,
};
use navsync_shared::time::{
    Civil, GPS_EPOCH_UNIX_S, NS_PER_S, SECONDS_PER_WEEK, gps_ns_from_utc_ns, utc_ns_from_civil, utc_ns_from_gps_ns,
};

use super::ecef::{geodetic_from_ecef, ned_from_ecef_velocity};
use super::esf::HnrPvt;
use super::messages::{MAX_SATS, Message};
use super::nav::{NavPvt, NavSat, NavSol, NavStatus, NavSvinfo, NavTimegps, SatInfo};
use super::tim::{TimTm2, TimTp};
use crate::gnss::cycle::CycleEnder;
use crate::gnss::geoid::GeoidCache;
use crate::gnss::order::{Admit, TimeOrder};

/// Nanoseconds per day.
const NS_PER_DAY: i64 = 86_400 * NS_PER_S;
/// Nanoseconds per GPS week.
const NS_PER_WEEK: i64 = SECONDS_PER_WEEK * NS_PER_S;
/// Nanoseconds per millisecond.
const NS_PER_MS: i64 = 1_000_000;

/// Counters of [`EpochAssembler`], since creation.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct EpochCounters {
    /// NAV messages merged into epochs.
    pub nav_messages: u64,
    /// Fixes emitted (NAV epochs and HNR-PVT).
    pub epochs: u64,
    /// NAV epochs emitted at NAV-EOE (subset of `epochs`).
    pub eoe_emits: u64,
    /// NAV epochs emitted by [`EpochAssembler::flush`] (subset of `epochs`).
    pub flush_emits: u64,
    /// NAV epochs emitted at the learned last NAV message of the cycle (subset of `epochs`).
    pub ender_emits: u64,
    /// NAV messages for an epoch already published (or closed): dropped, never published
    /// again (a late NAV-SAT/NAV-SVINFO still becomes that epoch's satellites).
    pub late_messages: u64,
    /// Fixes emitted from HNR-PVT (subset of `epochs`).
    pub hnr_fixes: u64,
    /// Epochs emitted without a time (no valid date, week or time of week).
    pub no_time: u64,
    /// Epochs held back because their time was not after the last one published on their
    /// output (the same epoch again, time going back; [`TimeOrder`]).
    pub not_after_last: u64,
    /// Times the receiver's time went back for good and the order restarted.
    pub time_resets: u64,
    /// NAV-SAT/NAV-SVINFO satellites that did not fit (more than [`MAX_SATS`]).
    pub sats_dropped: u64,
    /// TIM-TP messages.
    pub time_pulses: u64,
    /// TIM-TM2 messages.
    pub time_marks: u64,
}

impl EpochCounters {
    /// The counters with short names for a `Health` report (names ≤ 23 bytes).
    pub fn named(&self) -> [(&'static str, u64); 13] {
        [
            ("ubx_nav_messages", self.nav_messages),
            ("ubx_epochs", self.epochs),
            ("ubx_eoe_emits", self.eoe_emits),
            ("ubx_flush_emits", self.flush_emits),
            ("ubx_ender_emits", self.ender_emits),
            ("ubx_late_messages", self.late_messages),
            ("ubx_hnr_fixes", self.hnr_fixes),
            ("ubx_no_time", self.no_time),
            ("ubx_not_after_last", self.not_after_last),
            ("ubx_time_resets", self.time_resets),
            ("ubx_sats_dropped", self.sats_dropped),
            ("ubx_time_pulses", self.time_pulses),
            ("ubx_time_marks", self.time_marks),
        ]
    }
}

/// The satellites reported with one epoch (NAV-SAT or NAV-SVINFO).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SatView {
    /// GPS time of week of the epoch, ms.
    pub itow_ms: u32,
    /// The epoch's UTC time, ns since 1970 (`i64::MIN` when it had none).
    pub utc_ns: i64,
    /// Receipt time of the first byte of the NAV-SAT/NAV-SVINFO message, host
    /// `CLOCK_MONOTONIC` ns (`i64::MIN` before any).
    pub host_ns: i64,
    /// They came from NAV-SVINFO (legacy satellite numbers converted) rather than NAV-SAT.
    pub from_svinfo: bool,
    /// `sats[..len]` are the satellites.
    pub sats: [SatInfo; MAX_SATS],
    /// Valid entries of `sats`.
    pub len: usize,
    /// Satellites the message had beyond [`MAX_SATS`].
    pub dropped: usize,
}

impl SatView {
    const EMPTY: SatView = SatView {
        itow_ms: 0,
        utc_ns: i64::MIN,
        host_ns: i64::MIN,
        from_svinfo: false,
        sats: [SatInfo::EMPTY; MAX_SATS],
        len: 0,
        dropped: 0,
    };

    /// The satellites.
    pub fn satellites(&self) -> &[SatInfo] {
        self.sats.get(..self.len).unwrap_or(&[])
    }

    /// Satellites flagged as used in the solution.
    pub fn used(&self) -> usize {
        self.satellites().iter().filter(|s| s.used).count()
    }

    fn of_sat(m: &NavSat) -> Self {
        Self {
            itow_ms: m.itow_ms,
            utc_ns: i64::MIN,
            host_ns: i64::MIN,
            from_svinfo: false,
            sats: m.sats,
            len: m.len,
            dropped: m.dropped,
        }
    }

    fn of_svinfo(m: &NavSvinfo) -> Self {
        Self {
            itow_ms: m.itow_ms,
            utc_ns: i64::MIN,
            host_ns: i64::MIN,
            from_svinfo: true,
            sats: m.sats,
            len: m.len,
            dropped: m.dropped,
        }
    }
}

/// The last TIM-TP: the time of the next time pulse.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TimePulse {
    /// The message.
    pub tp: TimTp,
    /// Receipt time of its first byte, host `CLOCK_MONOTONIC` ns.
    pub host_ns: i64,
    /// The pulse's time, ns UTC since 1970: from a UTC time base directly, from a GPS time
    /// base with the receiver's leap seconds ([`EpochAssembler::leap_seconds`]); `i64::MIN`
    /// before the receiver has reported them, for other GNSS time bases (GLONASS, BeiDou,
    /// Galileo: not converted) and for impossible weeks.
    pub pulse_utc_ns: i64,
    /// The pulse's time, ns GPS time since 1980-01-06 (from a UTC time base with the leap
    /// seconds, the receiver's or the table's; `i64::MIN` when not known).
    pub pulse_gps_ns: i64,
}

impl TimePulse {
    /// As the sample published on `navsync/gnss/{id}/timepulse`, stamped at the message's
    /// receipt with sequence number `seq`.
    pub fn sample(&self, seq: u64) -> GnssTimePulse {
        GnssTimePulse {
            stamp: Stamp::host(self.host_ns, seq, StampSource::Receipt),
            pulse_gps_ns: self.pulse_gps_ns,
            pulse_utc_ns: self.pulse_utc_ns,
            q_err_ps: if self.tp.q_err_valid() {
                self.tp.q_err_ps
            } else {
                i32::MIN
            },
            time_base: u8::from(self.tp.utc_time_base()),
            utc_available: (self.tp.flags >> 1) & 1,
            reserved: [0; 2],
        }
    }
}

/// The last TIM-TM2 (time mark on an EXTINT input), with the receipt time of its first byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TimeMark {
    /// The message.
    pub tm2: TimTm2,
    /// Receipt time of its first byte, host `CLOCK_MONOTONIC` ns.
    pub host_ns: i64,
    /// GPS time of the last rising edge, ns since 1980-01-06 (`i64::MIN` when no new edge,
    /// the time is not valid, or the time base is the receiver's own).
    pub rising_gps_ns: i64,
    /// GPS time of the last falling edge, ns (`i64::MIN` as for `rising_gps_ns`).
    pub falling_gps_ns: i64,
}

impl TimeMark {
    /// As the sample published on `navsync/gnss/{id}/event` (host times of the edges not
    /// known here: `i64::MIN`; the driver maps them with the estimator's time state), stamped at the message's receipt with sequence number `seq`.
    pub fn sample(&self, seq: u64) -> GnssEvent {
        GnssEvent {
            stamp: Stamp::host(self.host_ns, seq, StampSource::Receipt),
            rising_gps_ns: self.rising_gps_ns,
            falling_gps_ns: self.falling_gps_ns,
            rising_host_ns: i64::MIN,
            falling_host_ns: i64::MIN,
            accuracy_ns: self.tm2.acc_est_ns,
            count: self.tm2.count,
            channel: self.tm2.ch,
            flags: self.tm2.flags,
        }
    }
}

/// The epoch being assembled.
#[derive(Debug, Clone, Copy)]
struct Epoch {
    open: bool,
    itow_ms: u32,
    fix: GnssFix,
    /// UTC from NAV-PVT / NAV-TIMEUTC, ns.
    utc_ns: Option<i64>,
    /// GPS time from NAV-SOL / NAV-TIMEGPS, ns since the GPS epoch.
    gps_ns: Option<i64>,
    /// GPS − UTC the receiver reported in this epoch (NAV-TIMEGPS `leapSValid`, or its
    /// `iTOW` against its valid UTC), s.
    leap_s: Option<i64>,
    /// Position and heights (ellipsoid, MSL; m) from NAV-PVT / NAV-POSLLH.
    geodetic: bool,
    height_m: f64,
    msl_m: f64,
    /// NAV-SOL's ECEF position (m) and velocity (m/s).
    ecef_m: Option<[f64; 3]>,
    ecef_vel_mps: Option<[f64; 3]>,
    /// Velocity from NAV-PVT / NAV-VELNED.
    ned_vel: bool,
    /// Satellites used (`numSV`).
    num_sv: Option<u16>,
    sats: Option<SatView>,
    /// The last NAV message merged other than NAV-EOE (its name), for learning the cycle.
    last_msg: Option<&'static str>,
    /// The precedence rank of the message that supplied each quantity ([`Sources`]).
    src: Sources,
}

/// Which message supplies each quantity of an epoch: the precedence rank of the message that
/// set it (0: none yet). A message sets a quantity only if its rank is at least the current
/// one, so the finest and most complete message wins whatever the order of arrival
/// (`docs/guide/receivers.md`, "One message per quantity"; u-blox 8 / M8 Receiver
/// Description UBX-13003221, "UBX-NAV-PVT": "This message combines position, velocity and
/// time solution, including accuracy figures", at 1 mm, 1 mm/s; NAV-VELNED and NAV-SOL carry
/// cm/s, NAV-SOL cm ECEF):
///
/// | quantity | NAV-PVT | NAV-POSLLH | NAV-VELNED | NAV-SOL | NAV-DOP | others |
/// |---|---|---|---|---|---|---|
/// | position, heights | 3 | 2 | | 1 (ECEF, cm) | | |
/// | hAcc, vAcc | 3 | 2 | | | | |
/// | velocity, speed, track | 3 (mm/s) | | 2 (cm/s) | 1 (ECEF cm/s) | | |
/// | sAcc | 3 (mm/s) | | 2 (cm/s) | 1 (cm/s) | | |
/// | headAcc | 3 | | 2 | | | |
/// | pDOP | 2 | | | 1 | 3 | |
/// | satellites used | 2 (`numSV`) | | | 1 (`numSV`) | | NAV-SAT/SVINFO flags when neither |
/// | satellites | | | | | | NAV-SAT 2 over NAV-SVINFO 1 |
/// | UTC | 2 | | | | | NAV-TIMEUTC 1 |
/// | GPS week/time | | | | 1 | | NAV-TIMEGPS 2 |
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Sources {
    pos: u8,
    acc: u8,
    vel: u8,
    s_acc: u8,
    head_acc: u8,
    pdop: u8,
    num_sv: u8,
    sats: u8,
    utc: u8,
    gps: u8,
}

/// Takes a quantity for a message of precedence `rank`: whether it may set it (its rank is
/// at least that of the message that set it so far); records the rank.
fn claim(slot: &mut u8, rank: u8) -> bool {
    if rank >= *slot {
        *slot = rank;
        true
    } else {
        false
    }
}

impl Epoch {
    fn closed() -> Self {
        let mut fix = GnssFix::empty(Stamp::host(0, 0, StampSource::Receipt));
        fix.protocol = GNSS_PROTOCOL_UBX;
        Self {
            open: false,
            itow_ms: 0,
            fix,
            utc_ns: None,
            gps_ns: None,
            leap_s: None,
            geodetic: false,
            height_m: f64::NAN,
            msl_m: f64::NAN,
            ecef_m: None,
            ecef_vel_mps: None,
            ned_vel: false,
            num_sv: None,
            sats: None,
            last_msg: None,
            src: Sources::default(),
        }
    }

    fn start(itow_ms: u32, host_ns: i64) -> Self {
        let mut e = Self::closed();
        e.open = true;
        e.itow_ms = itow_ms;
        e.fix.stamp.host_ns = host_ns;
        e
    }

    /// A UTC or GPS time is known.
    fn has_time(&self) -> bool {
        self.utc_ns.is_some() || self.gps_ns.is_some()
    }

    /// Data besides NAV-EOE.
    fn has_data(&self) -> bool {
        self.fix.sentences & !UBX_MSG_NAV_EOE != 0
    }

    /// Mode, quality and the fix-status bits of `fix_flags` from a fix type and its flags.
    fn set_status(&mut self, mode: u8, quality: u8, ok: bool, diff: bool) {
        let f = &mut self.fix;
        f.mode = mode;
        f.quality = quality;
        f.fix_flags &= !(FIX_FLAG_OK | FIX_FLAG_RECEIVER_INVALID | FIX_FLAG_DIFFERENTIAL);
        f.fix_flags |= if ok { FIX_FLAG_OK } else { FIX_FLAG_RECEIVER_INVALID };
        if diff {
            f.fix_flags |= FIX_FLAG_DIFFERENTIAL;
        }
    }

    /// A position from NAV-PVT/NAV-POSLLH/HNR-PVT; one outside the globe is garbage and
    /// leaves the epoch without a position.
    fn set_geodetic(&mut self, lat_deg: f64, lon_deg: f64, height_m: f64, msl_m: f64) {
        if !(lat_deg.abs() <= 90.0 && lon_deg.abs() <= 180.0) {
            self.geodetic = false;
            self.fix.lat_deg = f64::NAN;
            self.fix.lon_deg = f64::NAN;
            return;
        }
        self.geodetic = true;
        self.fix.lat_deg = lat_deg;
        self.fix.lon_deg = lon_deg;
        self.height_m = height_m;
        self.msl_m = msl_m;
    }

    fn pvt(&mut self, m: &NavPvt) {
        let f = &mut self.fix;
        f.sentences |= UBX_MSG_NAV_PVT;
        f.fix_flags &= !(FIX_FLAG_VALID_DATE | FIX_FLAG_VALID_TIME | FIX_FLAG_FULLY_RESOLVED | FIX_FLAG_INVALID_LLH);
        for (bit, flag) in [
            (0x01, FIX_FLAG_VALID_DATE),
            (0x02, FIX_FLAG_VALID_TIME),
            (0x04, FIX_FLAG_FULLY_RESOLVED),
        ] {
            if m.valid & bit != 0 {
                f.fix_flags |= flag;
            }
        }
        if m.invalid_llh() {
            f.fix_flags |= FIX_FLAG_INVALID_LLH;
        }
        if m.valid_date_time() && claim(&mut self.src.utc, 2) {
            self.utc_ns = utc_of(m.year, m.month, m.day, m.hour, m.min, m.sec, m.nano_ns);
            if m.fully_resolved() {
                self.leap_s = self.utc_ns.and_then(|u| leap_of(m.itow_ms, u)).or(self.leap_s);
            }
        }
        let ok = m.gnss_fix_ok();
        self.set_status(
            mode_of(m.fix_type),
            quality_of(m.fix_type, ok, m.diff_soln(), m.carr_soln()),
            ok,
            m.diff_soln(),
        );
        if !m.invalid_llh() && claim(&mut self.src.pos, 3) {
            self.set_geodetic(m.lat_deg, m.lon_deg, m.height_m, m.h_msl_m);
        }
        if claim(&mut self.src.acc, 3) {
            self.fix.h_acc_m = m.h_acc_m;
            self.fix.v_acc_m = m.v_acc_m;
        }
        self.set_ned_velocity(
            3,
            [m.vel_n_mps, m.vel_e_mps, m.vel_d_mps],
            m.g_speed_mps,
            m.head_mot_deg,
        );
        if claim(&mut self.src.s_acc, 3) {
            self.fix.s_acc_mps = m.s_acc_mps;
        }
        if claim(&mut self.src.head_acc, 3) {
            self.fix.head_acc_deg = m.head_acc_deg;
        }
        if claim(&mut self.src.pdop, 2) {
            self.fix.pdop = dop(m.p_dop);
        }
        if claim(&mut self.src.num_sv, 2) {
            self.num_sv = Some(u16::from(m.num_sv));
        }
    }

    /// A NED velocity with ground speed and heading of motion (NAV-PVT rank 3, NAV-VELNED 2).
    fn set_ned_velocity(&mut self, rank: u8, [n, e, d]: [f64; 3], speed_mps: f64, heading_deg: f64) {
        if !claim(&mut self.src.vel, rank) {
            return;
        }
        let f = &mut self.fix;
        f.vel_n_mps = n;
        f.vel_e_mps = e;
        f.vel_d_mps = d;
        f.speed_mps = speed_mps;
        f.track_deg = heading_deg.rem_euclid(360.0);
        self.ned_vel = true;
    }

    fn sol(&mut self, m: &NavSol) {
        self.fix.sentences |= UBX_MSG_NAV_SOL;
        let ok = m.fix_ok();
        self.set_status(
            mode_of(m.gps_fix),
            quality_of(m.gps_fix, ok, m.diff_soln(), 0),
            ok,
            m.diff_soln(),
        );
        for (bit, flag) in [(0x04, FIX_FLAG_VALID_DATE), (0x08, FIX_FLAG_VALID_TIME)] {
            if m.flags & bit != 0 {
                self.fix.fix_flags |= flag;
            }
        }
        if m.time_valid() && claim(&mut self.src.gps, 1) {
            self.gps_ns = gps_of(i64::from(m.week), tow_ns(m.itow_ms, m.ftow_ns));
        }
        // The ECEF position and velocity are used at the end only where no message of higher
        // precedence gave a geodetic position or a NED velocity.
        if claim(&mut self.src.pos, 1) {
            self.ecef_m = Some([m.ecef_x_m, m.ecef_y_m, m.ecef_z_m]);
        }
        if claim(&mut self.src.vel, 1) {
            self.ecef_vel_mps = Some([m.ecef_vx_mps, m.ecef_vy_mps, m.ecef_vz_mps]);
        }
        if claim(&mut self.src.s_acc, 1) {
            self.fix.s_acc_mps = m.s_acc_mps;
        }
        if claim(&mut self.src.pdop, 1) {
            self.fix.pdop = dop(m.p_dop);
        }
        if claim(&mut self.src.num_sv, 1) {
            self.num_sv = Some(u16::from(m.num_sv));
        }
    }

    fn timegps(&mut self, m: &NavTimegps) {
        self.fix.sentences |= UBX_MSG_NAV_TIMEGPS;
        if m.time_valid() && claim(&mut self.src.gps, 2) {
            self.gps_ns = gps_of(i64::from(m.week), tow_ns(m.itow_ms, m.ftow_ns));
            self.fix.fix_flags |= FIX_FLAG_VALID_DATE | FIX_FLAG_VALID_TIME;
        }
        if m.leap_valid() {
            self.leap_s = Some(i64::from(m.leap_s));
        }
    }

    fn status(&mut self, m: &NavStatus) {
        self.fix.sentences |= UBX_MSG_NAV_STATUS;
        let ok = m.fix_ok();
        let (mode, quality) = if ok {
            (
                mode_of(m.gps_fix),
                quality_of(m.gps_fix, ok, m.diff_soln(), m.carr_soln()),
            )
        } else {
            (FixMode::NoFix as u8, 0)
        };
        self.set_status(mode, quality, ok, m.diff_soln());
    }

    fn merge(&mut self, msg: &Message) {
        match msg {
            Message::NavPvt(m) => self.pvt(m),
            Message::NavSol(m) => self.sol(m),
            Message::NavTimegps(m) => self.timegps(m),
            Message::NavStatus(m) => self.status(m),
            Message::NavPosllh(m) => {
                self.fix.sentences |= UBX_MSG_NAV_POSLLH;
                if claim(&mut self.src.pos, 2) {
                    self.set_geodetic(m.lat_deg, m.lon_deg, m.height_m, m.h_msl_m);
                }
                if claim(&mut self.src.acc, 2) {
                    self.fix.h_acc_m = m.h_acc_m;
                    self.fix.v_acc_m = m.v_acc_m;
                }
            }
            Message::NavVelned(m) => {
                self.fix.sentences |= UBX_MSG_NAV_VELNED;
                self.set_ned_velocity(2, [m.vel_n_mps, m.vel_e_mps, m.vel_d_mps], m.g_speed_mps, m.heading_deg);
                if claim(&mut self.src.s_acc, 2) {
                    self.fix.s_acc_mps = m.s_acc_mps;
                }
                if claim(&mut self.src.head_acc, 2) {
                    self.fix.head_acc_deg = m.c_acc_deg;
                }
            }
            Message::NavDop(m) => {
                let f = &mut self.fix;
                f.sentences |= UBX_MSG_NAV_DOP;
                f.hdop = dop(m.h_dop);
                f.vdop = dop(m.v_dop);
                if claim(&mut self.src.pdop, 3) {
                    self.fix.pdop = dop(m.p_dop);
                }
            }
            Message::NavTimeutc(m) => {
                self.fix.sentences |= UBX_MSG_NAV_TIMEUTC;
                if m.utc_valid() && claim(&mut self.src.utc, 1) {
                    self.utc_ns = utc_of(m.year, m.month, m.day, m.hour, m.min, m.sec, m.nano_ns);
                    self.leap_s = self.utc_ns.and_then(|u| leap_of(m.itow_ms, u)).or(self.leap_s);
                    self.fix.fix_flags |= FIX_FLAG_VALID_DATE | FIX_FLAG_VALID_TIME | FIX_FLAG_FULLY_RESOLVED;
                }
            }
            Message::NavSat(m) => {
                self.fix.sentences |= UBX_MSG_NAV_SAT;
                if claim(&mut self.src.sats, 2) {
                    self.sats = Some(SatView::of_sat(m));
                }
            }
            Message::NavSvinfo(m) => {
                self.fix.sentences |= UBX_MSG_NAV_SAT;
                if claim(&mut self.src.sats, 1) {
                    self.sats = Some(SatView::of_svinfo(m));
                }
            }
            Message::NavEoe(_) => self.fix.sentences |= UBX_MSG_NAV_EOE,
            _ => {}
        }
    }
}

/// A DOP, NaN for u-blox's "unknown" 99.99 (and anything above).
fn dop(v: f64) -> f64 {
    if v < 99.99 { v } else { f64::NAN }
}

/// gpsd's TPV mode of a UBX fix type (see the module doc).
fn mode_of(fix_type: u8) -> u8 {
    match fix_type {
        1 | 2 => FixMode::Fix2d as u8,
        3..=5 => FixMode::Fix3d as u8,
        _ => FixMode::NoFix as u8,
    }
}

/// NMEA GGA quality of a UBX fix (see the module doc).
fn quality_of(fix_type: u8, ok: bool, diff: bool, carr_soln: u8) -> u8 {
    match (fix_type, ok, carr_soln, diff) {
        (0 | 6.., _, _, _) | (_, false, _, _) => 0,
        (_, _, 2, _) => 4,
        (_, _, 1, _) => 5,
        (_, _, _, true) => 2,
        (1, _, _, _) => 6,
        _ => 1,
    }
}

/// Years accepted in a UBX date (u-blox documents 1999..=2099; an `i64` of ns reaches 2262).
const YEARS: core::ops::RangeInclusive<u16> = 1980..=2200;
/// GPS weeks accepted (to 2171).
const WEEKS: core::ops::RangeInclusive<i64> = 0..=9999;

/// The navigation epoch of a precise time: the time rounded to the nearest millisecond.
///
/// u-blox 8 / M8 Receiver Description (UBX-13003221), "Clocks and Time", "Navigation
/// Epochs": "Each navigation solution is triggered by the tick of the 1-kHz clock nearest to
/// the desired navigation solution time"; "iTOW Timestamps": iTOW, in ms, "indicates the GPS
/// time at which the navigation epoch occurred". The sub-millisecond rest of a precise time
/// (NAV-PVT/NAV-TIMEUTC/HNR-PVT `nano` beyond the whole ms, NAV-SOL/NAV-TIMEGPS `fTOW`) is
/// the receiver clock's offset from that tick as the solution measured it, not another
/// instant: an epoch whose UTC fields say 02:40:14 with `nano` −192 µs ("UTC
/// Representation": the fields are rounded and `nano` corrects them, so it is negative when
/// they were rounded up) is the epoch 02:40:14.000, as gpsd reports it. Every output path
/// (the fix's `utc_ns`/`gps_ns`, hence JSON, gpsd-server, recordings, the estimator) carries
/// the rounded time.
pub fn epoch_ns(precise_ns: i64) -> i64 {
    precise_ns.saturating_add(NS_PER_MS / 2).div_euclid(NS_PER_MS) * NS_PER_MS
}

/// UTC ns of a UBX date and time with its (possibly negative) nanoseconds, as the navigation
/// epoch ([`epoch_ns`]); `None` for an impossible date.
#[allow(clippy::too_many_arguments)]
fn utc_of(year: u16, month: u8, day: u8, hour: u8, min: u8, sec: u8, nano_ns: i32) -> Option<i64> {
    let ok = YEARS.contains(&year)
        && (1..=12).contains(&month)
        && (1..=31).contains(&day)
        && hour < 24
        && min < 60
        && sec <= 60;
    ok.then(|| {
        utc_ns_from_civil(&Civil {
            year: i64::from(year),
            month: u32::from(month),
            day: u32::from(day),
            hour: u32::from(hour),
            minute: u32::from(min),
            second: u32::from(sec),
            nanos: 0,
        }) + i64::from(nano_ns)
    })
    .map(epoch_ns)
}

/// GPS ns of a week, time of week (ms) and fraction (ns); `None` for a week outside
/// [`WEEKS`].
fn gps_of(week: i64, tow_ns: i64) -> Option<i64> {
    WEEKS.contains(&week).then(|| week * NS_PER_WEEK + tow_ns)
}

/// Time of week of `iTOW` (ms) + `fTOW` (ns) as the navigation epoch ([`epoch_ns`]), ns.
fn tow_ns(itow_ms: u32, ftow_ns: i32) -> i64 {
    epoch_ns(i64::from(itow_ms) * NS_PER_MS + i64::from(ftow_ns))
}

/// GPS − UTC (s) from a NAV message's `iTOW` (GPS time of week, ms) and the UTC of the same
/// epoch: the difference of the two times of week, rounded to the second; `None` unless it is
/// a plausible leap-second count (0..=60) within 0.1 s.
fn leap_of(itow_ms: u32, utc_ns: i64) -> Option<i64> {
    let utc_tow = (utc_ns - GPS_EPOCH_UNIX_S * NS_PER_S).rem_euclid(NS_PER_WEEK);
    let mut d = (i64::from(itow_ms) * NS_PER_MS - utc_tow).rem_euclid(NS_PER_WEEK);
    if d > NS_PER_WEEK / 2 {
        d -= NS_PER_WEEK;
    }
    let leap = (d + NS_PER_S / 2).div_euclid(NS_PER_S);
    ((0..=60).contains(&leap) && (d - leap * NS_PER_S).abs() < NS_PER_S / 10).then_some(leap)
}

/// UTC of a GPS time, with the receiver's leap seconds when known.
fn utc_from_gps(gps_ns: i64, leap_s: Option<i64>) -> i64 {
    match leap_s {
        Some(l) => gps_ns + (GPS_EPOCH_UNIX_S - l) * NS_PER_S,
        None => utc_ns_from_gps_ns(gps_ns),
    }
}

/// GPS time of a UTC time, with the receiver's leap seconds when known.
fn gps_from_utc(utc_ns: i64, leap_s: Option<i64>) -> i64 {
    match leap_s {
        Some(l) => utc_ns - (GPS_EPOCH_UNIX_S - l) * NS_PER_S,
        None => gps_ns_from_utc_ns(utc_ns),
    }
}

/// How an epoch came to be emitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Close {
    NextEpoch,
    Eoe,
    Ender,
    Flush,
}

/// Decoded UBX messages → [`GnssFix`] epochs. Pure state machine: no I/O, no clock, no
/// allocation.
#[derive(Debug, Clone)]
pub struct EpochAssembler {
    cur: Epoch,
    /// `iTOW` of the last epoch closed (ms), the last data message merged into it and its
    /// UTC time: a NAV message of that `iTOW` arriving later is late.
    last_itow_ms: Option<u32>,
    last_closed_msg: Option<&'static str>,
    last_closed_utc_ns: i64,
    /// The order of the NAV epochs and of the HNR-PVT fixes published ([`TimeOrder`]).
    nav_order: TimeOrder,
    hnr_order: TimeOrder,
    /// The geoid model for receivers without an MSL height (NAV-SOL).
    geoid: GeoidCache,
    /// Receiver's GPS − UTC, s (see [`EpochAssembler::leap_seconds`]), carried across epochs.
    leap_s: Option<i64>,
    sats: SatView,
    /// Times [`EpochAssembler::satellites`] took a new view.
    sat_views: u64,
    time_pulse: Option<TimePulse>,
    time_mark: Option<TimeMark>,
    /// The learned last NAV message of the cycle (by name).
    cycle: CycleEnder<&'static str>,
    /// The last message and `iTOW` of an epoch emitted on flush: a vote once the next epoch
    /// begins.
    flushed: Option<(&'static str, u32)>,
    /// Sequence numbers of the NAV epochs and of the HNR-PVT fixes (two outputs).
    seq: u64,
    hnr_seq: u64,
    counters: EpochCounters,
}

impl Default for EpochAssembler {
    fn default() -> Self {
        Self::new()
    }
}

impl EpochAssembler {
    /// An assembler that has seen nothing yet.
    pub fn new() -> Self {
        Self {
            cur: Epoch::closed(),
            last_itow_ms: None,
            last_closed_msg: None,
            last_closed_utc_ns: i64::MIN,
            nav_order: TimeOrder::default(),
            hnr_order: TimeOrder::default(),
            geoid: GeoidCache::default(),
            leap_s: None,
            sats: SatView::EMPTY,
            sat_views: 0,
            time_pulse: None,
            time_mark: None,
            cycle: CycleEnder::default(),
            flushed: None,
            seq: 0,
            hnr_seq: 0,
            counters: EpochCounters::default(),
        }
    }

    /// The learned last NAV message of the receiver's cycle (e.g. `"NAV-DOP"`); `None` while
    /// not (or no longer) known, and for receivers that send NAV-EOE.
    pub fn cycle_ender(&self) -> Option<&'static str> {
        self.cycle.ender().copied()
    }

    /// Counters since creation.
    pub fn counters(&self) -> &EpochCounters {
        &self.counters
    }

    /// The satellites of the last emitted epoch that carried NAV-SAT or NAV-SVINFO (empty
    /// before the first).
    pub fn satellites(&self) -> &SatView {
        &self.sats
    }

    /// How many views [`EpochAssembler::satellites`] has taken so far: a new value means a new
    /// view (an epoch with NAV-SAT/NAV-SVINFO emitted, or a late one for the epoch emitted).
    pub fn satellite_views(&self) -> u64 {
        self.sat_views
    }

    /// The last TIM-TP (time of the next pulse, its quantisation error).
    pub fn time_pulse(&self) -> Option<&TimePulse> {
        self.time_pulse.as_ref()
    }

    /// The last TIM-TM2 (time mark).
    pub fn time_mark(&self) -> Option<&TimeMark> {
        self.time_mark.as_ref()
    }

    /// The receiver's GPS − UTC leap seconds, s: from NAV-TIMEGPS with `leapSValid`, or from
    /// the `iTOW` of a NAV-PVT (`fullyResolved`) or NAV-TIMEUTC (`validUTC`) against its UTC.
    pub fn leap_seconds(&self) -> Option<i64> {
        self.leap_s
    }

    /// Consumes one decoded message whose frame's first byte arrived at `host_ns` and calls
    /// `out` for every fix it completes (the previous epoch when this message starts a new
    /// one, this epoch at its NAV-EOE, an HNR-PVT fix). Messages other than NAV, HNR-PVT,
    /// TIM-TP and TIM-TM2 are ignored.
    pub fn push(&mut self, msg: &Message, host_ns: i64, out: &mut impl FnMut(&GnssFix)) {
        match msg {
            Message::HnrPvt(m) => return self.hnr(m, host_ns, out),
            Message::TimTp(m) => return self.tim_tp(m, host_ns),
            Message::TimTm2(m) => return self.tim_tm2(m, host_ns),
            _ => {}
        }
        let Some(itow_ms) = nav_itow(msg) else {
            return;
        };
        self.counters.nav_messages += 1;
        if self.cur.open && self.cur.itow_ms != itow_ms {
            if self.last_itow_ms == Some(itow_ms) {
                // For the epoch before the one being assembled.
                return self.late(msg, host_ns);
            }
            self.emit(Close::NextEpoch, out);
        }
        if !self.cur.open {
            if self.last_itow_ms == Some(itow_ms) {
                // For the epoch just emitted (at NAV-EOE, the learned last message, on flush).
                return self.late(msg, host_ns);
            }
            if let Some((name, flushed_itow)) = self.flushed.take()
                && flushed_itow != itow_ms
            {
                self.cycle.vote(name);
            }
            self.cur = Epoch::start(itow_ms, host_ns);
        }
        self.cur.merge(msg);
        if let Some(v) = self.cur.sats.as_mut()
            && match msg {
                Message::NavSat(_) => !v.from_svinfo,
                Message::NavSvinfo(_) => v.from_svinfo,
                _ => false,
            }
        {
            v.host_ns = host_ns;
        }
        if self.cur.leap_s.is_some() {
            self.leap_s = self.cur.leap_s;
        }
        if matches!(msg, Message::NavEoe(_)) {
            // NAV-EOE ends the epoch ("output after all enabled NAV class messages", u-blox
            // M8 UBX-13003221 "UBX-NAV-EOE"); one before the message carrying the epoch's
            // time (out of order) leaves it open until the next epoch begins or the line
            // goes idle, so that the epoch is published with its time.
            if self.cur.has_time() {
                self.emit(Close::Eoe, out);
            }
        } else {
            let name = msg.name();
            if let Some(before) = self.cur.last_msg
                && before != name
            {
                // `before` is not the last message of every epoch: never the cycle's ender.
                self.cycle.followed(before);
            }
            self.cur.last_msg = Some(name);
            // Not before the epoch has its time: a message reordered ahead of the one that
            // carries it would otherwise publish an epoch without its time.
            if self.cycle.is_ender(name) && self.cur.has_time() {
                self.emit(Close::Ender, out);
            }
        }
    }

    /// A NAV message for an epoch already closed: it is not published again (every epoch is
    /// published once). Counted; the message it followed is no cycle ender; a satellite view
    /// still replaces that epoch's in [`EpochAssembler::satellites`].
    fn late(&mut self, msg: &Message, host_ns: i64) {
        self.counters.late_messages += 1;
        if matches!(msg, Message::NavEoe(_)) {
            return;
        }
        if let Some(before) = self.last_closed_msg
            && before != msg.name()
        {
            self.cycle.followed(before);
        }
        self.last_closed_msg = Some(msg.name());
        let view = match msg {
            Message::NavSat(m) => Some(SatView::of_sat(m)),
            Message::NavSvinfo(m) if self.sats.itow_ms != m.itow_ms || self.sats.from_svinfo => {
                Some(SatView::of_svinfo(m))
            }
            _ => None,
        };
        if let Some(mut v) = view {
            v.utc_ns = self.last_closed_utc_ns;
            v.host_ns = host_ns;
            self.counters.sats_dropped += v.dropped as u64;
            self.sats = v;
            self.sat_views += 1;
        }
    }

    /// Emits the epoch being assembled, if any (the line went idle: its messages are all in).
    pub fn flush(&mut self, out: &mut impl FnMut(&GnssFix)) {
        if self.cur.open {
            self.emit(Close::Flush, out);
        }
    }

    fn tim_tp(&mut self, m: &TimTp, host_ns: i64) {
        self.counters.time_pulses += 1;
        // A UTC time base counts weeks and time of week like GPS time, from the GPS epoch.
        let (utc, gps) = match gps_of(i64::from(m.week), m.tow_ns()) {
            Some(t) if m.utc_time_base() => {
                let utc = t + GPS_EPOCH_UNIX_S * NS_PER_S;
                (utc, gps_from_utc(utc, self.leap_s))
            }
            Some(t) if m.ref_info & 0x0F == 0 => (self.leap_s.map_or(i64::MIN, |l| utc_from_gps(t, Some(l))), t),
            _ => (i64::MIN, i64::MIN),
        };
        self.time_pulse = Some(TimePulse {
            tp: *m,
            host_ns,
            pulse_utc_ns: utc,
            pulse_gps_ns: gps,
        });
    }

    fn tim_tm2(&mut self, m: &TimTm2, host_ns: i64) {
        self.counters.time_marks += 1;
        // Edge times in GPS time: GNSS time base (1) as is, UTC (2) with the leap seconds.
        let edge = |new: bool, week: u16, tow_ns: i64| {
            let t = gps_of(i64::from(week), tow_ns).filter(|_| new && m.time_valid())?;
            match m.time_base() {
                1 => Some(t),
                2 => Some(gps_from_utc(t + GPS_EPOCH_UNIX_S * NS_PER_S, self.leap_s)),
                _ => None,
            }
        };
        self.time_mark = Some(TimeMark {
            tm2: *m,
            host_ns,
            rising_gps_ns: edge(m.flags & 0x80 != 0, m.week_rising, m.rising_tow_ns()).unwrap_or(i64::MIN),
            falling_gps_ns: edge(m.flags & 0x04 != 0, m.week_falling, m.falling_tow_ns()).unwrap_or(i64::MIN),
        });
    }

    fn hnr(&mut self, m: &HnrPvt, host_ns: i64, out: &mut impl FnMut(&GnssFix)) {
        let mut e = Epoch::start(m.itow_ms, host_ns);
        e.fix.sentences = UBX_MSG_HNR_PVT;
        e.fix.fix_flags |= FIX_FLAG_NOT_GNSS;
        let ok = m.fix_ok();
        e.set_status(
            mode_of(m.gps_fix),
            quality_of(m.gps_fix, ok, m.diff_soln(), 0),
            ok,
            m.diff_soln(),
        );
        if m.valid_date_time() {
            e.utc_ns = utc_of(m.year, m.month, m.day, m.hour, m.min, m.sec, m.nano_ns);
            e.fix.fix_flags |= FIX_FLAG_VALID_DATE | FIX_FLAG_VALID_TIME;
        }
        if m.valid & 0x04 != 0 {
            e.fix.fix_flags |= FIX_FLAG_FULLY_RESOLVED;
        }
        e.set_geodetic(m.lat_deg, m.lon_deg, m.height_m, m.h_msl_m);
        let f = &mut e.fix;
        f.speed_mps = m.g_speed_mps;
        f.track_deg = m.head_mot_deg.rem_euclid(360.0);
        let (s, c) = f.track_deg.to_radians().sin_cos();
        f.vel_n_mps = m.g_speed_mps * c;
        f.vel_e_mps = m.g_speed_mps * s;
        f.h_acc_m = m.h_acc_m;
        f.v_acc_m = m.v_acc_m;
        f.s_acc_mps = m.s_acc_mps;
        f.head_acc_deg = m.head_acc_deg;
        e.ned_vel = true;
        if let Some(fix) = self.finish(e, true) {
            self.counters.hnr_fixes += 1;
            out(&fix);
        }
    }

    /// Completes the open epoch and hands it to `out` (epochs with nothing but NAV-EOE are
    /// dropped).
    fn emit(&mut self, how: Close, out: &mut impl FnMut(&GnssFix)) {
        let e = core::mem::replace(&mut self.cur, Epoch::closed());
        self.last_itow_ms = Some(e.itow_ms);
        self.last_closed_msg = e.last_msg;
        self.last_closed_utc_ns = i64::MIN;
        // An epoch that ended without NAV-EOE teaches the cycle: at once when the next epoch's
        // first message closed it, when the next epoch begins if the line went idle.
        self.flushed = None;
        match (how, e.last_msg) {
            (Close::NextEpoch, Some(name)) => self.cycle.vote(name),
            (Close::Flush, Some(name)) => self.flushed = Some((name, e.itow_ms)),
            _ => {}
        }
        if !e.has_data() {
            return;
        }
        let Some(fix) = self.finish(e, false) else {
            return;
        };
        match how {
            Close::Eoe => self.counters.eoe_emits += 1,
            Close::Ender => self.counters.ender_emits += 1,
            Close::Flush => self.counters.flush_emits += 1,
            Close::NextEpoch => {}
        }
        self.last_closed_utc_ns = fix.utc_ns;
        if let Some(mut sats) = e.sats {
            sats.utc_ns = fix.utc_ns;
            self.counters.sats_dropped += sats.dropped as u64;
            self.sats = sats;
            self.sat_views += 1;
        }
        out(&fix);
    }

    /// The fix of a complete epoch (time, position, velocity derived; stamped and counted), of
    /// the HNR-PVT output when `hnr`; `None` when its time is not after the last one published
    /// on that output ([`TimeOrder`]: held back, counted).
    fn finish(&mut self, e: Epoch, hnr: bool) -> Option<GnssFix> {
        let mut fix = e.fix;
        // A solution no message vouched for (gnssFixOK, GPSfixOK) is not one the receiver
        // calls valid.
        if fix.fix_flags & FIX_FLAG_OK == 0 {
            fix.fix_flags |= FIX_FLAG_RECEIVER_INVALID;
        }
        let leap = e.leap_s.or(self.leap_s);
        let (utc, gps) = match (e.utc_ns, e.gps_ns) {
            (Some(u), Some(g)) => (Some(u), Some(g)),
            (Some(u), None) => (Some(u), Some(gps_from_utc(u, leap))),
            (None, Some(g)) => (Some(utc_from_gps(g, leap)), Some(g)),
            (None, None) => (None, None),
        };
        match (utc, gps) {
            (Some(u), Some(g)) => {
                fix.utc_ns = u;
                fix.gps_ns = g;
                fix.tod_ns = u.rem_euclid(NS_PER_DAY);
            }
            _ => self.counters.no_time += 1,
        }
        let has_fix = fix.mode >= FixMode::Fix2d as u8;
        if has_fix && e.geodetic {
            fix.alt_msl_m = e.msl_m;
            fix.geoid_sep_m = e.height_m - e.msl_m;
        } else if let (true, Some([x, y, z])) = (has_fix, e.ecef_m)
            && let Some(g) = geodetic_from_ecef(x, y, z)
        {
            fix.lat_deg = g.lat_deg;
            fix.lon_deg = g.lon_deg;
            // No MSL altitude from the receiver: the geoid model's, said so (module doc).
            match self.geoid.separation_m(g.lat_deg, g.lon_deg) {
                Some(n) => {
                    fix.alt_msl_m = g.height_m - n;
                    fix.geoid_sep_m = n;
                    fix.sentences |= FIX_GEOID_MODEL;
                }
                None => fix.alt_msl_m = g.height_m,
            }
        }
        if let (true, false, true, Some([vx, vy, vz])) = (has_fix, e.ned_vel, fix.lat_deg.is_finite(), e.ecef_vel_mps) {
            let [n, east, d] = ned_from_ecef_velocity(fix.lat_deg, fix.lon_deg, vx, vy, vz);
            fix.vel_n_mps = n;
            fix.vel_e_mps = east;
            fix.vel_d_mps = d;
            fix.speed_mps = n.hypot(east);
            // No direction of motion at rest: 0, as gpsd reports it.
            fix.track_deg = if n == 0.0 && east == 0.0 {
                0.0
            } else {
                east.atan2(n).to_degrees().rem_euclid(360.0)
            };
        }
        let invalid_llh = fix.fix_flags & FIX_FLAG_INVALID_LLH != 0;
        let position = [
            &mut fix.lat_deg,
            &mut fix.lon_deg,
            &mut fix.alt_msl_m,
            &mut fix.geoid_sep_m,
        ];
        if !has_fix || invalid_llh {
            position.into_iter().for_each(|v| *v = f64::NAN);
        }
        if !has_fix {
            for v in [
                &mut fix.vel_n_mps,
                &mut fix.vel_e_mps,
                &mut fix.vel_d_mps,
                &mut fix.speed_mps,
                &mut fix.track_deg,
            ] {
                *v = f64::NAN;
            }
        }
        fix.sats_used = match (e.num_sv, e.sats) {
            (Some(n), _) => n,
            (None, Some(s)) => u16::try_from(s.used()).unwrap_or(u16::MAX),
            (None, None) => u16::MAX,
        };
        let order = if hnr { &mut self.hnr_order } else { &mut self.nav_order };
        match order.admit(fix.utc_ns) {
            Admit::Publish => {}
            Admit::Reset => self.counters.time_resets += 1,
            Admit::HeldBack => {
                self.counters.not_after_last += 1;
                return None;
            }
        }
        let seq = if hnr { &mut self.hnr_seq } else { &mut self.seq };
        fix.stamp = Stamp::host(fix.stamp.host_ns, *seq, StampSource::Receipt);
        *seq += 1;
        self.counters.epochs += 1;
        Some(fix)
    }
}

/// The `iTOW` of a NAV message that belongs to an epoch (`None` for other messages).
fn nav_itow(msg: &Message) -> Option<u32> {
    Some(match msg {
        Message::NavPvt(m) => m.itow_ms,
        Message::NavSol(m) => m.itow_ms,
        Message::NavTimegps(m) => m.itow_ms,
        Message::NavPosllh(m) => m.itow_ms,
        Message::NavVelned(m) => m.itow_ms,
        Message::NavDop(m) => m.itow_ms,
        Message::NavStatus(m) => m.itow_ms,
        Message::NavTimeutc(m) => m.itow_ms,
        Message::NavSat(m) => m.itow_ms,
        Message::NavSvinfo(m) => m.itow_ms,
        Message::NavEoe(m) => m.itow_ms,
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::super::esf::decode_hnr_pvt;
    use super::super::messages::decode;
    use super::super::nav::tests::{P, pvt, pvt_at};
    use super::*;
    use navsync_shared::time::format_rfc3339_ms;

    /// A NAV-PVT message (see `nav::tests::pvt`) with a valid position.
    fn pvt_msg(itow_ms: u32, fix_type: u8, flags: u8) -> Message {
        let mut p = pvt_at(itow_ms, fix_type, flags);
        p[78] = 0;
        decode(1, 7, &p).unwrap()
    }

    fn eoe(itow_ms: u32) -> Message {
        decode(1, 0x61, &itow_ms.to_le_bytes()).unwrap()
    }

    fn dop(itow_ms: u32) -> Message {
        decode(
            1,
            4,
            &P::default()
                .u4(itow_ms)
                .u2(250)
                .u2(200)
                .u2(120)
                .u2(150)
                .u2(130)
                .u2(90)
                .u2(91)
                .0,
        )
        .unwrap()
    }

    fn timegps(itow_ms: u32, ftow_ns: i32, week: i16, leap: i8, valid: u8) -> Message {
        decode(
            1,
            0x20,
            &P::default()
                .u4(itow_ms)
                .i4(ftow_ns)
                .i2(week)
                .i1(leap)
                .u1(valid)
                .u4(20)
                .0,
        )
        .unwrap()
    }

    fn sol(itow_ms: u32, gps_fix: u8, flags: u8) -> Message {
        let p = P::default()
            .u4(itow_ms)
            .i4(-112_313)
            .i2(1977)
            .u1(gps_fix)
            .u1(flags)
            .i4(447_748_713) // ECEF of 45.2185 N 5.8072 E, 278.88 m
            .i4(45_537_503)
            .i4(450_468_408)
            .u4(990)
            .i4(100)
            .i4(-50)
            .i4(30)
            .u4(7)
            .u2(167)
            .u1(0)
            .u1(6)
            .u4(0)
            .0;
        decode(1, 6, &p).unwrap()
    }

    fn status(itow_ms: u32, gps_fix: u8, flags: u8, flags2: u8) -> Message {
        decode(
            1,
            3,
            &P::default()
                .u4(itow_ms)
                .u1(gps_fix)
                .u1(flags)
                .u1(0)
                .u1(flags2)
                .u4(0)
                .u4(0)
                .0,
        )
        .unwrap()
    }

    /// Pushes messages (host time = index × 1 ms) and returns (index of the push, fix).
    fn run(asm: &mut EpochAssembler, msgs: &[Message]) -> Vec<(usize, GnssFix)> {
        let mut out = Vec::new();
        for (i, m) in msgs.iter().enumerate() {
            asm.push(m, i as i64 * 1_000_000, &mut |f| out.push((i, *f)));
        }
        out
    }

    fn flush(asm: &mut EpochAssembler) -> Vec<GnssFix> {
        let mut out = Vec::new();
        asm.flush(&mut |f| out.push(*f));
        out
    }

    #[test]
    fn nav_pvt_epoch_closes_at_eoe_and_maps_every_field() {
        let mut asm = EpochAssembler::new();
        let out = run(
            &mut asm,
            &[pvt_msg(237_537_000, 3, 0x01), dop(237_537_000), eoe(237_537_000)],
        );
        assert_eq!(out.len(), 1);
        let (at, f) = out[0];
        assert_eq!(at, 2, "emitted at NAV-EOE");
        assert_eq!(
            (f.stamp.host_ns, f.stamp.seq, f.stamp.source()),
            (0, 0, StampSource::Receipt)
        );
        assert_eq!(
            format_rfc3339_ms(f.utc_ns),
            "2021-06-10T18:18:57.000Z",
            "18:18:57 with nano −123456 ns is the epoch 18:18:57.000"
        );
        assert_eq!(f.utc_ns % NS_PER_S, 0, "rounded to the navigation epoch's millisecond");
        assert_eq!(f.gps_ns, gps_ns_from_utc_ns(f.utc_ns));
        assert_eq!(f.tod_ns, f.utc_ns.rem_euclid(NS_PER_DAY));
        assert_eq!((f.lat_deg, f.lon_deg), (50.135_084_5, 14.429_946_9));
        assert_eq!(f.alt_msl_m, 304.671);
        assert!((f.geoid_sep_m - (348.941 - 304.671)).abs() < 1e-9 && (f.height_m() - 348.941).abs() < 1e-9);
        assert_eq!(
            (f.vel_n_mps, f.vel_e_mps, f.vel_d_mps, f.speed_mps),
            (-0.01, 0.02, -0.03, 0.024)
        );
        assert!((f.track_deg - 123.456_78).abs() < 1e-9);
        assert_eq!(
            (f.h_acc_m, f.v_acc_m, f.s_acc_mps, f.head_acc_deg),
            (2.513, 4.894, 0.35, 90.0)
        );
        assert_eq!(
            (f.hdop, f.vdop, f.pdop),
            (1.3, 1.5, 2.0),
            "NAV-DOP after NAV-PVT's pDOP"
        );
        assert!(f.std_lat_m.is_nan(), "GST only");
        assert_eq!(
            (f.sats_used, f.mode, f.quality, f.protocol),
            (12, 3, 1, GNSS_PROTOCOL_UBX)
        );
        assert_eq!(f.sentences, UBX_MSG_NAV_PVT | UBX_MSG_NAV_DOP | UBX_MSG_NAV_EOE);
        assert_eq!(
            f.fix_flags,
            FIX_FLAG_OK | FIX_FLAG_VALID_DATE | FIX_FLAG_VALID_TIME | FIX_FLAG_FULLY_RESOLVED
        );
        assert!(flush(&mut asm).is_empty());
        assert_eq!(asm.counters().eoe_emits, 1);
    }

    #[test]
    fn nav_sol_epoch_from_ecef_closes_at_the_next_itow() {
        let mut asm = EpochAssembler::new();
        let out = run(
            &mut asm,
            &[
                sol(494_575_000, 2, 0xDF),
                dop(494_575_000),
                timegps(494_575_000, -112_313, 1977, 18, 0x07),
                sol(494_576_000, 2, 0xDF),
            ],
        );
        assert_eq!(out.len(), 1);
        let (at, f) = out[0];
        assert_eq!(at, 3, "emitted when the next epoch's first message arrives");
        // iTOW + fTOW (−112 µs) is the navigation epoch iTOW.
        let gps = 1977 * NS_PER_WEEK + 494_575_000 * NS_PER_MS;
        assert_eq!(f.gps_ns, gps);
        assert_eq!(f.utc_ns, gps + (GPS_EPOCH_UNIX_S - 18) * NS_PER_S);
        assert_eq!(format_rfc3339_ms(f.utc_ns), "2017-12-01T17:22:37.000Z");
        assert!(
            (f.lat_deg - 45.2185).abs() < 1e-7 && (f.lon_deg - 5.8072).abs() < 1e-7,
            "{f:?}"
        );
        // No MSL height from the receiver: EGM96's separation, said so.
        assert_ne!(f.sentences & FIX_GEOID_MODEL, 0);
        let n = crate::gnss::geoid::egm96_separation_m(f.lat_deg, f.lon_deg).unwrap();
        assert!((f.geoid_sep_m - n).abs() < 0.05, "{} {n}", f.geoid_sep_m);
        assert!((f.alt_msl_m - (278.88 - n)).abs() < 0.06, "{}", f.alt_msl_m);
        assert!(
            (f.height_m() - 278.88).abs() < 0.01,
            "the ellipsoidal height: {}",
            f.height_m()
        );
        let [n, e, d] = ned_from_ecef_velocity(f.lat_deg, f.lon_deg, 1.0, -0.5, 0.3);
        assert_eq!((f.vel_n_mps, f.vel_e_mps, f.vel_d_mps), (n, e, d));
        assert_eq!(f.speed_mps, n.hypot(e));
        assert!((f.track_deg - e.atan2(n).to_degrees().rem_euclid(360.0)).abs() < 1e-12);
        assert_eq!((f.s_acc_mps, f.pdop, f.hdop, f.sats_used), (0.07, 2.0, 1.3, 6));
        assert!(f.h_acc_m.is_nan(), "NAV-SOL's pAcc is 3D");
        assert_eq!((f.mode, f.quality), (2, 2), "2D, differential");
        assert_eq!(asm.leap_seconds(), Some(18));
        let last = flush(&mut asm);
        assert_eq!(
            (last.len(), last[0].stamp.host_ns, last[0].stamp.seq),
            (1, 3_000_000, 1)
        );
        assert_eq!(last[0].utc_ns - f.utc_ns, NS_PER_S, "the leap seconds carried over");
        assert_eq!(asm.counters().flush_emits, 1);
    }

    #[test]
    fn the_last_nav_message_of_the_cycle_is_learned() {
        // A receiver without NAV-EOE: NAV-PVT, NAV-DOP per epoch, each epoch one burst
        // followed by silence (flush), as on a live port.
        let mut asm = EpochAssembler::new();
        let mut emitted = Vec::new();
        for k in 1..=6u32 {
            let itow = k * 1000;
            let mut in_burst = 0;
            for m in [pvt_msg(itow, 3, 1), dop(itow)] {
                asm.push(&m, 0, &mut |_| in_burst += 1);
            }
            let mut flushed = 0;
            asm.flush(&mut |_| flushed += 1);
            emitted.push((in_burst, flushed));
        }
        // Epochs 1 and 2 are flushed and vote NAV-DOP when the next epoch begins.
        assert_eq!(emitted, [(0, 1), (0, 1), (1, 0), (1, 0), (1, 0), (1, 0)]);
        assert_eq!(asm.cycle_ender(), Some("NAV-DOP"));
        assert_eq!(asm.counters().ender_emits, 4);
        // The receiver adds NAV-SAT after NAV-DOP: the epoch was published at NAV-DOP and is
        // not published again; NAV-SAT still gives the satellites of that epoch, and NAV-DOP
        // is never trusted again.
        let mut out = Vec::new();
        for m in [pvt_msg(7000, 3, 1), dop(7000), sat(7000)] {
            asm.push(&m, 0, &mut |f| out.push(*f));
        }
        asm.flush(&mut |f| out.push(*f));
        assert_eq!(out.len(), 1, "published once, at NAV-DOP");
        assert_eq!(asm.counters().late_messages, 1);
        assert_eq!(
            (asm.satellites().itow_ms, asm.satellites().utc_ns),
            (7000, out[0].utc_ns)
        );
        assert_eq!(asm.cycle_ender(), None);
        for k in 8..=12u32 {
            for m in [pvt_msg(k * 1000, 3, 1), dop(k * 1000)] {
                asm.push(&m, 0, &mut |f| out.push(*f));
            }
            asm.flush(&mut |f| out.push(*f));
        }
        assert_eq!(
            asm.cycle_ender(),
            None,
            "NAV-DOP was followed once: never the ender again"
        );
        assert_eq!(out.len(), 6);
        // Without NAV-EOE but with the next epoch arriving at once (no idle line), it is
        // learned from the epoch boundaries.
        let mut asm = EpochAssembler::new();
        let msgs: Vec<Message> = (1..=5u32)
            .flat_map(|k| [pvt_msg(k * 1000, 3, 1), dop(k * 1000)])
            .collect();
        let out = run(&mut asm, &msgs);
        let at: Vec<usize> = out.iter().map(|o| o.0).collect();
        assert_eq!(at, [2, 4, 5, 7, 9], "next-epoch closes, then at NAV-DOP");
    }

    #[test]
    fn late_messages_are_counted_and_never_publish_an_epoch_twice() {
        let mut asm = EpochAssembler::new();
        let mut out = run(&mut asm, &[pvt_msg(1000, 3, 1), eoe(1000), dop(1000)]);
        out.extend(flush(&mut asm).into_iter().map(|f| (9, f)));
        assert_eq!(out.len(), 1, "published once, at NAV-EOE");
        assert!(out[0].1.hdop.is_nan());
        assert_eq!(asm.counters().late_messages, 1);
        // A message for the previous epoch while the next one is assembled: dropped.
        let mut asm = EpochAssembler::new();
        let out = run(&mut asm, &[pvt_msg(1000, 3, 1), pvt_msg(2000, 3, 1), dop(1000)]);
        assert_eq!(out.len(), 1);
        assert_eq!(asm.counters().late_messages, 1);
        assert_eq!(flush(&mut asm)[0].sentences, UBX_MSG_NAV_PVT);
    }

    #[test]
    fn fix_type_mode_and_quality() {
        assert_eq!([0, 1, 2, 3, 4, 5, 6].map(mode_of), [1, 2, 2, 3, 3, 3, 1]);
        assert_eq!(quality_of(3, true, false, 0), 1);
        assert_eq!(quality_of(3, false, false, 0), 0, "gnssFixOK clear");
        assert_eq!(quality_of(0, true, false, 0), 0);
        assert_eq!(quality_of(3, true, true, 0), 2);
        assert_eq!(quality_of(3, true, true, 1), 5);
        assert_eq!(quality_of(3, true, true, 2), 4);
        assert_eq!(quality_of(1, true, false, 0), 6);
        assert_eq!(quality_of(5, true, false, 0), 1);
        // NAV-STATUS without gpsFixOk after a 3D NAV-PVT: no fix, nothing reported.
        let mut asm = EpochAssembler::new();
        run(&mut asm, &[pvt_msg(1000, 3, 1), status(1000, 3, 0x0C, 0)]);
        let f = flush(&mut asm)[0];
        assert_eq!((f.mode, f.quality, f.fix_flags & FIX_FLAG_OK), (1, 0, 0));
        assert!(f.lat_deg.is_nan() && f.speed_mps.is_nan() && f.alt_msl_m.is_nan());
        assert!(f.utc_ns != i64::MIN, "the time stays");
        // NAV-STATUS with carrier phase fixed (flags2 carrSoln 2).
        let mut asm = EpochAssembler::new();
        run(&mut asm, &[pvt_msg(1000, 3, 0x03), status(1000, 3, 0x0F, 0x80)]);
        assert_eq!(flush(&mut asm)[0].quality, 4);
        // invalidLlh: no position, the flag set.
        let mut asm = EpochAssembler::new();
        asm.push(&decode(1, 7, &pvt(1000, 3, 1)).unwrap(), 0, &mut |_| {});
        let f = flush(&mut asm)[0];
        assert!(f.lat_deg.is_nan() && f.fix_flags & FIX_FLAG_INVALID_LLH != 0);
    }

    #[test]
    fn hnr_pvt_is_a_fix_of_its_own() {
        let hnr = P::default()
            .u4(1_500)
            .u2(2021)
            .u1(6)
            .u1(16)
            .u1(23)
            .u1(46)
            .u1(5)
            .u1(0x37)
            .i4(100_000_000)
            .u1(1)
            .u1(0x1D)
            .zeros(2)
            .i4(-1_213_140_876)
            .i4(440_688_578)
            .i4(1_111_800)
            .i4(1_133_150)
            .i4(1_000)
            .i4(1_001)
            .i4(9_000_000)
            .i4(0)
            .u4(3_024)
            .u4(6_053)
            .u4(290)
            .u4(3_334_190)
            .zeros(4)
            .0;
        let hnr = Message::HnrPvt(decode_hnr_pvt(&hnr).unwrap());
        let mut asm = EpochAssembler::new();
        let out = run(&mut asm, &[pvt_msg(1000, 3, 1), hnr, eoe(1000)]);
        assert_eq!(out.len(), 2);
        let (at, h) = out[0];
        assert_eq!(
            (at, h.stamp.host_ns, h.stamp.seq, h.sentences),
            (1, 1_000_000, 0, UBX_MSG_HNR_PVT)
        );
        assert_eq!(format_rfc3339_ms(h.utc_ns), "2021-06-16T23:46:05.100Z");
        assert_eq!(
            (h.mode, h.quality, h.lat_deg, h.lon_deg),
            (2, 6, 44.068_857_8, -121.314_087_6)
        );
        assert!((h.vel_e_mps - 1.0).abs() < 1e-12 && h.vel_n_mps.abs() < 1e-12 && h.vel_d_mps.is_nan());
        assert_eq!(
            (h.h_acc_m, h.v_acc_m, h.s_acc_mps, h.sats_used),
            (3.024, 6.053, 0.29, u16::MAX)
        );
        let (at, nav) = out[1];
        assert_eq!(
            (at, nav.stamp.seq, nav.sentences & UBX_MSG_HNR_PVT),
            (2, 0, 0),
            "the NAV epoch is intact, numbered on its own output"
        );
        assert_eq!(asm.counters().hnr_fixes, 1);
    }

    #[test]
    fn time_pulse_and_time_mark() {
        let mut asm = EpochAssembler::new();
        let tp_utc = P::default()
            .u4(237_870_000)
            .u4(0)
            .i4(-4331)
            .u2(2146)
            .u1(0x0B)
            .u1(0x0F)
            .0;
        asm.push(&decode(0x0D, 1, &tp_utc).unwrap(), 5, &mut |_| {});
        let t = *asm.time_pulse().unwrap();
        assert_eq!((t.host_ns, t.tp.q_err_ps), (5, -4331));
        assert_eq!(format_rfc3339_ms(t.pulse_utc_ns), "2021-02-23T18:04:30.000Z");
        assert_eq!(t.pulse_gps_ns, gps_ns_from_utc_ns(t.pulse_utc_ns), "table leap seconds");
        let s = t.sample(7);
        assert_eq!(
            (s.stamp.host_ns, s.stamp.seq, s.q_err_ps, s.time_base, s.utc_available),
            (5, 7, -4331, 1, 1)
        );
        assert_eq!((s.pulse_utc_ns, s.pulse_gps_ns), (t.pulse_utc_ns, t.pulse_gps_ns));
        // GPS time base: UTC only once the receiver has told its leap seconds.
        let tp_gps = P::default().u4(237_888_000).u4(0).i4(10).u2(2146).u1(0x12).u1(0x00).0;
        asm.push(&decode(0x0D, 1, &tp_gps).unwrap(), 6, &mut |_| {});
        let t = *asm.time_pulse().unwrap();
        assert_eq!(
            (t.pulse_utc_ns, t.pulse_gps_ns),
            (i64::MIN, 2146 * NS_PER_WEEK + 237_888 * NS_PER_S)
        );
        assert_eq!(t.sample(0).q_err_ps, i32::MIN, "qErrInvalid");
        asm.push(&timegps(1, 0, 2146, 18, 7), 6, &mut |_| {});
        asm.push(&decode(0x0D, 1, &tp_gps).unwrap(), 7, &mut |_| {});
        let t = *asm.time_pulse().unwrap();
        assert_eq!(format_rfc3339_ms(t.pulse_utc_ns), "2021-02-23T18:04:30.000Z");
        assert_eq!(t.pulse_gps_ns, 2146 * NS_PER_WEEK + 237_888 * NS_PER_S);
        // GLONASS time base: not converted.
        let tp_glo = P::default().u4(1).u4(0).i4(10).u2(2146).u1(0x00).u1(0x01).0;
        asm.push(&decode(0x0D, 1, &tp_glo).unwrap(), 8, &mut |_| {});
        assert_eq!(asm.time_pulse().unwrap().pulse_utc_ns, i64::MIN);
        // Time mark, GNSS time base, a new rising edge, no new falling one.
        let tm2 = P::default()
            .u1(0)
            .u1(0xC8)
            .u2(17)
            .u2(2146)
            .u2(2146)
            .u4(1000)
            .u4(250)
            .u4(1500)
            .u4(1)
            .u4(20)
            .0;
        asm.push(&decode(0x0D, 3, &tm2).unwrap(), 9, &mut |_| {});
        let m = *asm.time_mark().unwrap();
        assert_eq!((m.host_ns, m.tm2.count), (9, 17));
        assert_eq!(
            (m.rising_gps_ns, m.falling_gps_ns),
            (2146 * NS_PER_WEEK + NS_PER_S + 250, i64::MIN)
        );
        let e = m.sample(3);
        assert_eq!(
            (e.stamp.seq, e.rising_gps_ns, e.rising_host_ns, e.count, e.accuracy_ns),
            (3, m.rising_gps_ns, i64::MIN, 17, 20)
        );
        assert_eq!((asm.counters().time_pulses, asm.counters().time_marks), (4, 1));
    }

    #[test]
    fn satellites_of_the_last_epoch() {
        let mut asm = EpochAssembler::new();
        assert_eq!(asm.satellites().len, 0);
        // NAV-SAT alone: sats_used from its flags, no time: NAV-EOE does not publish an epoch
        // without its time (the message carrying it may come out of order); the next epoch
        // or an idle line does.
        assert!(run(&mut asm, &[sat(1000), eoe(1000)]).is_empty());
        let out = flush(&mut asm);
        assert_eq!((out[0].sats_used, out[0].mode), (1, 0));
        let v = asm.satellites();
        assert_eq!(
            (v.itow_ms, v.len, v.used(), v.from_svinfo, v.utc_ns),
            (1000, 2, 1, false, i64::MIN)
        );
        // With NAV-PVT: the epoch's time; an epoch without satellites keeps them.
        run(
            &mut asm,
            &[
                pvt_msg(2000, 3, 1),
                sat(2000),
                eoe(2000),
                pvt_msg(3000, 3, 1),
                eoe(3000),
            ],
        );
        let v = asm.satellites();
        assert_eq!(v.itow_ms, 2000);
        assert_ne!(v.utc_ns, i64::MIN, "the epoch's time");
    }

    /// NAV-SAT with satellite 5 used and 7 not.
    fn sat(itow_ms: u32) -> Message {
        let mut p = P::default().u4(itow_ms).u1(1).u1(2).zeros(2).0;
        for (sv, used) in [(5u8, true), (7, false)] {
            p.extend(
                P::default()
                    .u1(0)
                    .u1(sv)
                    .u1(40)
                    .i1(30)
                    .i2(120)
                    .i2(0)
                    .u4(if used { 0x0F } else { 0x04 })
                    .0,
            );
        }
        decode(1, 0x35, &p).unwrap()
    }

    #[test]
    fn leap_seconds_from_itow_against_utc() {
        // 2021-06-10 18:18:57 − 123456 ns UTC; GPS is 18 s ahead: iTOW 4 d 18:19:15 − 0.123 ms.
        let itow = ((4 * 86_400 + 18 * 3600 + 19 * 60 + 15) * 1000) as u32;
        let mut asm = EpochAssembler::new();
        run(&mut asm, &[pvt_msg(itow, 3, 1)]);
        assert_eq!(asm.leap_seconds(), Some(18));
        assert_eq!(leap_of(itow, 0), None, "not a plausible count");
        // Across the week boundary: GPS already in the next week, UTC not yet.
        let sunday = utc_ns_from_civil(&Civil {
            year: 2021,
            month: 6,
            day: 12,
            hour: 23,
            minute: 59,
            second: 50,
            nanos: 0,
        });
        assert_eq!(leap_of(8_000, sunday), Some(18));
    }

    #[test]
    fn impossible_dates_and_weeks_give_no_time() {
        let mut p = pvt(1000, 3, 1);
        p[4..6].copy_from_slice(&60_000u16.to_le_bytes());
        let mut asm = EpochAssembler::new();
        asm.push(&decode(1, 7, &p).unwrap(), 0, &mut |_| {});
        asm.push(&timegps(1000, 0, i16::MAX, 18, 7), 0, &mut |_| {});
        let f = flush(&mut asm)[0];
        assert_eq!((f.utc_ns, f.gps_ns, f.tod_ns), (i64::MIN, i64::MIN, -1));
        assert_eq!(asm.counters().no_time, 1);
        let tp = P::default().u4(u32::MAX).u4(u32::MAX).i4(0).u2(u16::MAX).u1(1).u1(0).0;
        asm.push(&decode(0x0D, 1, &tp).unwrap(), 0, &mut |_| {});
        assert_eq!(asm.time_pulse().map(|t| t.pulse_utc_ns), Some(i64::MIN));
    }
    // ---- Issue 35: each defect as a test on bytes written from the interface description
    // (u-blox 8 / M8 Receiver Description, UBX-13003221: UBX-NAV-PVT, UBX-NAV-VELNED,
    // UBX-NAV-SOL, UBX-NAV-SAT, UBX-HNR-PVT payload layouts).

    /// A NAV-PVT payload (3D fix, gnssFixOK, valid date and time) at `hh:mm:ss` + `nano` ns on
    /// 2021-06-10, with velocity north `vel_n_mm_s`, ground speed and sAcc in mm/s.
    fn pvt_time(itow_ms: u32, (hh, mm, ss): (u8, u8, u8), nano: i32, vel_n_mm_s: i32, s_acc_mm_s: u32) -> Message {
        let mut p = pvt(itow_ms, 3, 0x01);
        p[8] = hh;
        p[9] = mm;
        p[10] = ss;
        p[16..20].copy_from_slice(&nano.to_le_bytes());
        p[48..52].copy_from_slice(&vel_n_mm_s.to_le_bytes());
        p[52..56].copy_from_slice(&0i32.to_le_bytes());
        p[60..64].copy_from_slice(&vel_n_mm_s.unsigned_abs().to_le_bytes());
        p[68..72].copy_from_slice(&s_acc_mm_s.to_le_bytes());
        p[78] = 0;
        decode(1, 7, &p).unwrap()
    }

    #[test]
    fn issue35_negative_nano_is_the_epoch_of_the_rounded_second() {
        // UTC fields 02:40:14 with nano −192 µs and −78 µs (the fields are rounded, nano
        // corrects them): the navigation epochs 02:40:14.000 and 02:40:15.000, not …13.999.
        let mut asm = EpochAssembler::new();
        let out = run(
            &mut asm,
            &[
                pvt_time(1_000, (2, 40, 14), -192_000, 0, 100),
                eoe(1_000),
                pvt_time(2_000, (2, 40, 15), -78_000, 0, 100),
                eoe(2_000),
                pvt_time(3_000, (2, 40, 15), 999_600_000, 0, 100),
                eoe(3_000),
            ],
        );
        let times: Vec<String> = out.iter().map(|(_, f)| format_rfc3339_ms(f.utc_ns)).collect();
        assert_eq!(
            times,
            [
                "2021-06-10T02:40:14.000Z",
                "2021-06-10T02:40:15.000Z",
                "2021-06-10T02:40:16.000Z"
            ]
        );
        for (_, f) in &out {
            assert_eq!(f.utc_ns % NS_PER_MS, 0, "on the millisecond in the sample itself");
            assert_eq!(f.gps_ns % NS_PER_MS, 0);
        }
        // The same in the JSON of `navsync decode`.
        let j = crate::gnss::capture::epoch_json(&out[0].1);
        assert_eq!(j["time"], "2021-06-10T02:40:14.000Z");
        // And for HNR-PVT and NAV-TIMEUTC, whose nano is the same field.
        assert_eq!(epoch_ns(14 * NS_PER_S - 192_000), 14 * NS_PER_S);
        assert_eq!(epoch_ns(14 * NS_PER_S + 499_999), 14 * NS_PER_S);
        assert_eq!(epoch_ns(14 * NS_PER_S + 500_000), 14 * NS_PER_S + NS_PER_MS);
        assert_eq!(epoch_ns(-1), 0);
    }

    #[test]
    fn issue35_nav_sol_only_gives_msl_from_the_geoid_model_and_keeps_the_ellipsoidal_height() {
        // A receiver sending NAV-SOL (ECEF, no MSL height) and NAV-TIMEGPS only.
        let mut asm = EpochAssembler::new();
        run(
            &mut asm,
            &[
                sol(494_575_000, 3, 0xDF),
                timegps(494_575_000, 0, 1977, 18, 0x07),
                sol(494_576_000, 3, 0xDF),
            ],
        );
        let f = flush(&mut asm)[0];
        let g = geodetic_from_ecef(4_477_487.13, 455_375.03, 4_504_684.08).unwrap();
        let n = crate::gnss::geoid::egm96_separation_m(g.lat_deg, g.lon_deg).unwrap();
        assert!(n.abs() > 10.0, "the separation matters here: {n}");
        assert!(
            (f.height_m() - g.height_m).abs() < 1e-6,
            "ellipsoidal height is the receiver's"
        );
        assert!(
            (f.alt_msl_m - (g.height_m - n)).abs() < 0.05,
            "MSL = h − N, not h: {} vs {}",
            f.alt_msl_m,
            g.height_m
        );
        assert_ne!(f.sentences & FIX_GEOID_MODEL, 0, "the source is stated");
        let j = crate::gnss::capture::epoch_json(&f);
        assert_eq!(j["alt_msl_source"], "egm96");
        assert!((j["alt_hae"].as_f64().unwrap() - g.height_m).abs() < 1e-6);
        // With NAV-PVT (hMSL from the receiver): the receiver's, no model.
        let mut asm = EpochAssembler::new();
        run(&mut asm, &[pvt_msg(1000, 3, 1), sol(1000, 3, 0xDF), eoe(1000)]);
        let asm_out = asm.counters().epochs;
        assert_eq!(asm_out, 1);
    }

    /// A NAV-VELNED payload: velocity north `vel_n_cm_s`, ground speed, sAcc in cm/s.
    fn velned(itow_ms: u32, vel_n_cm_s: i32, s_acc_cm_s: u32) -> Message {
        let p = P::default()
            .u4(itow_ms)
            .i4(vel_n_cm_s)
            .i4(0)
            .i4(7)
            .u4(vel_n_cm_s.unsigned_abs())
            .u4(vel_n_cm_s.unsigned_abs())
            .i4(0)
            .u4(s_acc_cm_s)
            .u4(900_000)
            .0;
        decode(1, 0x12, &p).unwrap()
    }

    #[test]
    fn issue35_the_finer_message_wins_whatever_the_order() {
        // NAV-PVT says 1.234 m/s north, sAcc 0.081 m/s (mm/s); NAV-VELNED of the same epoch
        // 1.23 m/s, sAcc 0.09 m/s (cm/s): NAV-PVT's stand, before or after NAV-VELNED.
        for order in [0, 1] {
            let (a, b) = (pvt_time(1_000, (2, 40, 14), 0, 1_234, 81), velned(1_000, 123, 9));
            let msgs = if order == 0 {
                [a, b, eoe(1_000)]
            } else {
                [b, a, eoe(1_000)]
            };
            let mut asm = EpochAssembler::new();
            let f = run(&mut asm, &msgs)[0].1;
            assert_eq!(
                (f.vel_n_mps, f.speed_mps, f.s_acc_mps),
                (1.234, 1.234, 0.081),
                "order {order}"
            );
            assert_eq!(f.vel_d_mps, -0.03, "NAV-PVT's velD");
            assert_ne!(f.sentences & UBX_MSG_NAV_VELNED, 0, "both merged");
        }
        // NAV-VELNED alone still gives the velocity.
        let mut asm = EpochAssembler::new();
        let f = run(&mut asm, &[sol(1_000, 3, 0xDF), velned(1_000, 123, 9), eoe(1_000)])[0].1;
        assert_eq!((f.vel_n_mps, f.s_acc_mps), (1.23, 0.09), "VELNED over NAV-SOL's ECEF");
        // NAV-SOL's pDOP and sAcc do not overwrite NAV-PVT's, in either order.
        let mut asm = EpochAssembler::new();
        let f = run(
            &mut asm,
            &[pvt_time(1_000, (2, 40, 14), 0, 0, 81), sol(1_000, 3, 0xDF), eoe(1_000)],
        )[0]
        .1;
        assert_eq!((f.s_acc_mps, f.pdop, f.sats_used), (0.081, 1.56, 12));
    }

    #[test]
    fn issue35_alternating_epoch_content_is_published_once() {
        // Epochs of NAV-PVT alone and NAV-PVT + NAV-SAT every fifth second, each burst
        // followed by an idle line (flush) or not; the capture starting with either kind.
        for start_with_sat in [false, true] {
            for idle in [false, true] {
                let mut asm = EpochAssembler::new();
                let mut out = Vec::new();
                let mut with_sat = Vec::new();
                for k in 1..=30u32 {
                    let itow = k * 1000;
                    let sat_epoch = (k + u32::from(!start_with_sat) * 3) % 5 == 1;
                    let mut msgs = vec![pvt_msg(itow, 3, 1)];
                    if sat_epoch {
                        msgs.push(sat(itow));
                        with_sat.push(itow);
                    }
                    for m in &msgs {
                        asm.push(m, i64::from(itow), &mut |f| out.push(*f));
                    }
                    if idle {
                        asm.flush(&mut |f| out.push(*f));
                    }
                }
                asm.flush(&mut |f| out.push(*f));
                let times: Vec<i64> = out.iter().map(|f| f.utc_ns).collect();
                assert_eq!(times.len(), 30, "sat first {start_with_sat} idle {idle}: {times:?}");
                assert!(times.windows(2).all(|w| w[0] < w[1]), "strictly increasing");
                let seqs: Vec<u64> = out.iter().map(|f| f.stamp.seq).collect();
                assert_eq!(seqs, (0..30).collect::<Vec<_>>());
                assert!(asm.counters().late_messages <= 1, "at most the first NAV-SAT");
            }
        }
    }

    #[test]
    fn issue35_hnr_pvt_is_an_output_of_its_own() {
        // HNR-PVT at 10 Hz (the .4, .0, .5 of the issue) between NAV epochs at 1 Hz, through
        // the whole decoder: the fixes carry NAV epochs only, the HNR output its own
        // strictly increasing times and sequence numbers.
        use crate::gnss::ubx::UbxDecoder;
        use crate::gnss::ubx::framer::ubx_frame;
        use crate::gnss::{GnssDecoder, GnssExtra};
        let mut bytes = Vec::new();
        let itow0 = (3 * 86_400 + 23 * 3600 + 46 * 60 + 23) * 1000;
        for s in 5..10u8 {
            let nav_itow = itow0 + u32::from(s) * 1000;
            for tenth in 0..10u32 {
                // nano 40 µs before each tenth: rounded to it.
                let p = hnr_payload(nav_itow + tenth * 100, s, (tenth * 100_000_000) as i32 - 40_000);
                bytes.extend(ubx_frame(0x28, 0, &p));
            }
            let mut pvt_p = pvt(nav_itow, 3, 1);
            pvt_p[4..6].copy_from_slice(&2021u16.to_le_bytes());
            (pvt_p[6], pvt_p[7], pvt_p[8], pvt_p[9], pvt_p[10]) = (6, 16, 23, 46, s);
            pvt_p[16..20].copy_from_slice(&0i32.to_le_bytes());
            pvt_p[78] = 0;
            bytes.extend(ubx_frame(1, 7, &pvt_p));
            bytes.extend(ubx_frame(1, 0x61, &nav_itow.to_le_bytes()));
        }
        let mut d = UbxDecoder::new();
        let (mut nav, mut hnr) = (Vec::new(), Vec::new());
        d.push_extras(&bytes, 0, 1, &mut |f| nav.push(*f), &mut |x| {
            if let GnssExtra::Hnr(h) = x {
                hnr.push(*h);
            }
        });
        assert_eq!((nav.len(), hnr.len()), (5, 50));
        assert!(
            nav.iter()
                .all(|f| f.sentences & UBX_MSG_HNR_PVT == 0 && f.sats_used == 12)
        );
        assert!(hnr.iter().all(|f| f.fix_flags & FIX_FLAG_NOT_GNSS != 0));
        for out in [&nav, &hnr] {
            assert!(out.windows(2).all(|w| w[0].utc_ns < w[1].utc_ns));
            assert!(out.iter().enumerate().all(|(i, f)| f.stamp.seq == i as u64));
        }
        assert_eq!(format_rfc3339_ms(hnr[1].utc_ns), "2021-06-16T23:46:05.100Z", "rounded");
    }

    /// An HNR-PVT payload at 2021-06-16 23:46:`sec` + `nano` ns, a dead-reckoning fix.
    fn hnr_payload(itow_ms: u32, sec: u8, nano: i32) -> Vec<u8> {
        let mut p = P::default()
            .u4(itow_ms)
            .u2(2021)
            .u1(6)
            .u1(16)
            .u1(23)
            .u1(46)
            .u1(sec)
            .u1(0x37)
            .i4(nano)
            .0;
        p.extend(
            P::default()
                .u1(1)
                .u1(0x1D)
                .zeros(2)
                .i4(-1_213_140_876)
                .i4(440_688_578)
                .i4(1_111_800)
                .i4(1_133_150)
                .i4(1_000)
                .i4(1_001)
                .i4(9_000_000)
                .i4(0)
                .u4(3_024)
                .u4(6_053)
                .u4(290)
                .u4(3_334_190)
                .zeros(4)
                .0,
        );
        p
    }
}
