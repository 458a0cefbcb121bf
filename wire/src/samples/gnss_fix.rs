//! One GNSS epoch: a receiver's navigation solution for one measurement instant, whatever its
//! protocol (the GNSS driver's decoder merges the messages that carry the epoch's time tag).

use super::Stamp;

crate::sample_struct! {
    /// A GNSS receiver's solution for one epoch (all messages of one time tag merged; for
    /// NMEA the sentences of one time tag).
    ///
    /// `stamp.host_ns` is the host time at which the epoch's first byte was received
    /// (`StampSource::Receipt`); the epoch itself happened earlier, at `utc_ns`.
    pub struct GnssFix = "navsync.GnssFix.v2" {
        /// Receipt stamp of the epoch's first byte and the driver's epoch counter.
        pub stamp: Stamp,
        /// Epoch time, ns UTC since 1970-01-01 (`i64::MIN` when the receiver gave no time).
        pub utc_ns: i64,
        /// Epoch time, ns GPS time since 1980-01-06 (`i64::MIN` when not known: no date or no time).
        pub gps_ns: i64,
        /// UTC time of day of the epoch's time tag, ns since midnight (−1 when the epoch had no
        /// time tag); known even when the date is not.
        pub tod_ns: i64,
        /// Latitude, degrees north (WGS-84), NaN when not known.
        pub lat_deg: f64,
        /// Longitude, degrees east (WGS-84), NaN when not known.
        pub lon_deg: f64,
        /// Altitude above mean sea level, m, NaN when not known.
        pub alt_msl_m: f64,
        /// Geoid separation (ellipsoid height minus MSL altitude), m, NaN when not known.
        pub geoid_sep_m: f64,
        /// Velocity north, m/s (NED), NaN when not known.
        pub vel_n_mps: f64,
        /// Velocity east, m/s (NED), NaN when not known.
        pub vel_e_mps: f64,
        /// Velocity down, m/s (NED), NaN when not known (NMEA carries none).
        pub vel_d_mps: f64,
        /// Speed over ground, m/s, NaN when not known.
        pub speed_mps: f64,
        /// Track over ground, degrees clockwise from true north, NaN when not known.
        pub track_deg: f64,
        /// Horizontal dilution of precision, NaN when not known.
        pub hdop: f64,
        /// Vertical dilution of precision, NaN when not known.
        pub vdop: f64,
        /// Position dilution of precision, NaN when not known.
        pub pdop: f64,
        /// 1-sigma latitude error as the receiver reports it (NMEA GST), m, NaN when not known.
        pub std_lat_m: f64,
        /// 1-sigma longitude error as the receiver reports it (NMEA GST), m, NaN when not known.
        pub std_lon_m: f64,
        /// 1-sigma altitude error as the receiver reports it (NMEA GST), m, NaN when not known.
        pub std_alt_m: f64,
        /// Horizontal accuracy estimate as the receiver reports it (UBX `hAcc`), m, NaN when
        /// not reported.
        pub h_acc_m: f64,
        /// Vertical accuracy estimate (UBX `vAcc`), m, NaN when not reported.
        pub v_acc_m: f64,
        /// Speed accuracy estimate (UBX `sAcc`), m/s, NaN when not reported.
        pub s_acc_mps: f64,
        /// Heading (track) accuracy estimate (UBX `headAcc`), degrees, NaN when not reported.
        pub head_acc_deg: f64,
        /// The set of source messages merged into this epoch, one bit per message type of the
        /// receiver's protocol (`protocol`): NMEA the `SENTENCE_*` bits (GGA, RMC, GNS, VTG,
        /// GSA, GST, ZDA, GLL in bit order), UBX the `UBX_MSG_*` bits.
        pub sentences: u32,
        /// Satellites used in the solution, `u16::MAX` when not known.
        pub sats_used: u16,
        /// Fix mode: 0 unknown, 1 no fix, 2 2D, 3 3D (as gpsd's TPV `mode`).
        pub mode: u8,
        /// Fix quality in NMEA GGA's terms, whatever the protocol (0 invalid, 1 GPS, 2 DGPS,
        /// 4 RTK fixed, 5 RTK float, 6 dead reckoning), 255 unknown.
        pub quality: u8,
        /// The receiver's validity flags, `FIX_FLAG_*` bits (0 when the protocol has none).
        pub fix_flags: u8,
        /// The receiver protocol the epoch came from, a `GNSS_PROTOCOL_*` value.
        pub protocol: u8,
        /// Reserved, zero.
        pub reserved: [u8; 6],
    }
}

/// [`GnssFix::protocol`]: NMEA 0183.
pub const GNSS_PROTOCOL_NMEA: u8 = 0;
/// [`GnssFix::protocol`]: u-blox UBX.
pub const GNSS_PROTOCOL_UBX: u8 = 1;
/// [`GnssFix::protocol`]: no receiver's messages but a file of positions with the noise σ of
/// each (KF-GINS's GNSS file, `navsync import kf-gins`); `sentences` 0.
pub const GNSS_PROTOCOL_FILE: u8 = 2;

/// [`GnssFix::fix_flags`]: the receiver says the fix is valid (UBX NAV-PVT `gnssFixOK`,
/// NAV-SOL `GPSfixOK`).
pub const FIX_FLAG_OK: u8 = 1 << 0;
/// [`GnssFix::fix_flags`]: differential corrections applied (UBX `diffSoln`).
pub const FIX_FLAG_DIFFERENTIAL: u8 = 1 << 1;
/// [`GnssFix::fix_flags`]: the receiver marks latitude, longitude and height invalid (UBX
/// NAV-PVT `invalidLlh`).
pub const FIX_FLAG_INVALID_LLH: u8 = 1 << 2;
/// [`GnssFix::fix_flags`]: the date is valid (UBX `validDate`).
pub const FIX_FLAG_VALID_DATE: u8 = 1 << 3;
/// [`GnssFix::fix_flags`]: the time of day is valid (UBX `validTime`).
pub const FIX_FLAG_VALID_TIME: u8 = 1 << 4;
/// [`GnssFix::fix_flags`]: date and time are fully resolved (UBX `fullyResolved`).
pub const FIX_FLAG_FULLY_RESOLVED: u8 = 1 << 5;
/// [`GnssFix::fix_flags`]: the receiver says its solution is not valid (UBX NAV-PVT
/// `gnssFixOK`, NAV-SOL `GPSfixOK` clear); a protocol without such a flag leaves it clear. Not
/// fused.
pub const FIX_FLAG_RECEIVER_INVALID: u8 = 1 << 6;
/// [`GnssFix::fix_flags`]: not a GNSS solution but the receiver's own blend of GNSS and its
/// sensors (UBX HNR-PVT), correlated with them from one output to the next. Not fused as a
/// GNSS measurement.
pub const FIX_FLAG_NOT_GNSS: u8 = 1 << 7;

/// [`GnssFix::sentences`] bit of a UBX NAV-PVT message.
pub const UBX_MSG_NAV_PVT: u32 = 1 << 0;
/// [`GnssFix::sentences`] bit of a UBX NAV-SOL message.
pub const UBX_MSG_NAV_SOL: u32 = 1 << 1;
/// [`GnssFix::sentences`] bit of a UBX NAV-TIMEGPS message.
pub const UBX_MSG_NAV_TIMEGPS: u32 = 1 << 2;
/// [`GnssFix::sentences`] bit of a UBX NAV-POSLLH message.
pub const UBX_MSG_NAV_POSLLH: u32 = 1 << 3;
/// [`GnssFix::sentences`] bit of a UBX NAV-VELNED message.
pub const UBX_MSG_NAV_VELNED: u32 = 1 << 4;
/// [`GnssFix::sentences`] bit of a UBX NAV-DOP message.
pub const UBX_MSG_NAV_DOP: u32 = 1 << 5;
/// [`GnssFix::sentences`] bit of a UBX NAV-STATUS message.
pub const UBX_MSG_NAV_STATUS: u32 = 1 << 6;
/// [`GnssFix::sentences`] bit of a UBX NAV-TIMEUTC message.
pub const UBX_MSG_NAV_TIMEUTC: u32 = 1 << 7;
/// [`GnssFix::sentences`] bit of a UBX NAV-SAT or NAV-SVINFO message.
pub const UBX_MSG_NAV_SAT: u32 = 1 << 8;
/// [`GnssFix::sentences`] bit of a UBX NAV-EOE message (the epoch is complete).
pub const UBX_MSG_NAV_EOE: u32 = 1 << 9;
/// [`GnssFix::sentences`] bit of a UBX HNR-PVT message (high-rate dead-reckoning output).
pub const UBX_MSG_HNR_PVT: u32 = 1 << 10;

/// [`GnssFix::sentences`] bit, any protocol: the geoid separation (`geoid_sep_m`), and so
/// `alt_msl_m`, is navsync's geoid model (EGM96, `navsync_drivers::gnss::geoid`) at the fix's
/// position, not the receiver's: it reported only an ellipsoidal height (u-blox NAV-SOL). The
/// ellipsoidal height ([`GnssFix::height_m`]) is the receiver's either way.
pub const FIX_GEOID_MODEL: u32 = 1 << 31;

/// [`GnssFix::sentences`] bit of a GGA sentence.
pub const SENTENCE_GGA: u32 = 1 << 0;
/// [`GnssFix::sentences`] bit of an RMC sentence.
pub const SENTENCE_RMC: u32 = 1 << 1;
/// [`GnssFix::sentences`] bit of a GNS sentence.
pub const SENTENCE_GNS: u32 = 1 << 2;
/// [`GnssFix::sentences`] bit of a VTG sentence.
pub const SENTENCE_VTG: u32 = 1 << 3;
/// [`GnssFix::sentences`] bit of a GSA sentence.
pub const SENTENCE_GSA: u32 = 1 << 4;
/// [`GnssFix::sentences`] bit of a GST sentence.
pub const SENTENCE_GST: u32 = 1 << 5;
/// [`GnssFix::sentences`] bit of a ZDA sentence.
pub const SENTENCE_ZDA: u32 = 1 << 6;
/// [`GnssFix::sentences`] bit of a GLL sentence.
pub const SENTENCE_GLL: u32 = 1 << 7;

/// Fix mode as in gpsd's TPV `mode`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
#[repr(u8)]
pub enum FixMode {
    /// Not known.
    Unknown = 0,
    /// No fix.
    NoFix = 1,
    /// 2D fix.
    Fix2d = 2,
    /// 3D fix.
    Fix3d = 3,
}

impl GnssFix {
    /// An epoch with nothing known yet.
    pub fn empty(stamp: Stamp) -> Self {
        Self {
            stamp,
            utc_ns: i64::MIN,
            gps_ns: i64::MIN,
            tod_ns: -1,
            lat_deg: f64::NAN,
            lon_deg: f64::NAN,
            alt_msl_m: f64::NAN,
            geoid_sep_m: f64::NAN,
            vel_n_mps: f64::NAN,
            vel_e_mps: f64::NAN,
            vel_d_mps: f64::NAN,
            speed_mps: f64::NAN,
            track_deg: f64::NAN,
            hdop: f64::NAN,
            vdop: f64::NAN,
            pdop: f64::NAN,
            std_lat_m: f64::NAN,
            std_lon_m: f64::NAN,
            std_alt_m: f64::NAN,
            h_acc_m: f64::NAN,
            v_acc_m: f64::NAN,
            s_acc_mps: f64::NAN,
            head_acc_deg: f64::NAN,
            sentences: 0,
            sats_used: u16::MAX,
            mode: FixMode::Unknown as u8,
            quality: u8::MAX,
            fix_flags: 0,
            protocol: GNSS_PROTOCOL_NMEA,
            reserved: [0; 6],
        }
    }

    /// True when the receiver reported a 2D or 3D position.
    pub fn has_position(&self) -> bool {
        self.mode >= FixMode::Fix2d as u8 && self.lat_deg.is_finite() && self.lon_deg.is_finite()
    }

    /// The altitude is held by the receiver, not measured: a position from at most 3
    /// satellites (4 unknowns with the receiver clock) solves latitude and longitude only.
    /// gpsd, and `mode`, may still call such a fix 3D.
    pub fn altitude_held(&self) -> bool {
        (1..=3).contains(&self.sats_used)
    }

    /// Ellipsoidal height (WGS-84), m: MSL altitude plus geoid separation (separation 0 when unknown).
    pub fn height_m(&self) -> f64 {
        let sep = if self.geoid_sep_m.is_finite() {
            self.geoid_sep_m
        } else {
            0.0
        };
        self.alt_msl_m + sep
    }
}
