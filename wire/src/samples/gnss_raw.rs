//! A receiver's raw measurements of one epoch (u-blox UBX-RXM-RAWX): pseudorange, carrier
//! phase and Doppler of every tracked signal, for tightly coupled fusion.

use super::Stamp;

/// Measurements one [`GnssRaw`] holds.
pub const MAX_RAW_MEASUREMENTS: usize = 64;
/// `sig_id` of GPS L2 P(Y), a signal u-blox receivers do not report and so number (their
/// ids end at 15): a geodetic receiver's semi-codeless L2 (RINEX 3 `C2W`, RINEX 2 `P2`).
pub const SIG_GPS_L2_PY: u8 = 32;

crate::sample_struct! {
    /// One signal's raw measurements.
    pub struct RawMeasurement = "navsync.RawMeasurement.v1" {
        /// Pseudorange, m.
        pub pseudorange_m: f64,
        /// Carrier phase, cycles.
        pub carrier_phase_cycles: f64,
        /// Doppler, Hz (positive: approaching).
        pub doppler_hz: f32,
        /// Pseudorange 1-sigma, m.
        pub pseudorange_std_m: f32,
        /// Carrier phase 1-sigma, cycles.
        pub carrier_phase_std_cycles: f32,
        /// Doppler 1-sigma, Hz.
        pub doppler_std_hz: f32,
        /// Carrier phase lock time, ms.
        pub lock_time_ms: u16,
        /// GNSS id (u-blox: 0 GPS, 1 SBAS, 2 Galileo, 3 BeiDou, 5 QZSS, 6 GLONASS).
        pub gnss_id: u8,
        /// Satellite id within the system.
        pub sv_id: u8,
        /// Signal id (u-blox `sigId`; [`SIG_GPS_L2_PY`] for GPS L2 P(Y)).
        pub sig_id: u8,
        /// GLONASS frequency slot + 7 (0..=13), else 0.
        pub freq_id: u8,
        /// Carrier-to-noise density, dB-Hz.
        pub cno_dbhz: u8,
        /// Tracking status bits (u-blox `trkStat`: pseudorange valid, carrier valid, half
        /// cycle valid, half cycle subtracted).
        pub trk_stat: u8,
    }
}

crate::sample_struct! {
    /// The raw measurements of one receiver epoch.
    pub struct GnssRaw = "navsync.GnssRaw.v1" {
        /// Receipt stamp of the message's first byte and the driver's epoch counter.
        pub stamp: Stamp,
        /// Receiver time of week of the measurements, s (GPS time scale).
        pub rcv_tow_s: f64,
        /// GPS week number of the receiver time.
        pub week: u16,
        /// GPS − UTC leap seconds (when `rec_stat` says they are valid).
        pub leap_s: i16,
        /// Measurements in `meas`.
        pub num_meas: u8,
        /// Receiver status bits (u-blox `recStat`: leap seconds valid, clock reset).
        pub rec_stat: u8,
        /// Measurements the message held beyond [`MAX_RAW_MEASUREMENTS`] (dropped).
        pub dropped: u8,
        /// Reserved, zero.
        pub reserved: u8,
        /// The measurements, `num_meas` of them.
        pub meas: [RawMeasurement; MAX_RAW_MEASUREMENTS],
    }
}

/// u-blox `locktime` saturates here, ms (the u-blox interface description, UBX-RXM-RAWX).
pub const LOCK_TIME_MAX_MS: u16 = 64_500;

impl GnssRaw {
    /// GPS − UTC at the epoch, s: the receiver's when it marks it valid (`recStat` bit 0),
    /// else the leap-second table's ([`crate::time::gps_minus_utc_s`]) at the epoch's time.
    pub fn gps_minus_utc_s(&self) -> i16 {
        if self.rec_stat & 1 != 0 {
            return self.leap_s;
        }
        let gps_ns = i64::from(self.week) * 604_800_000_000_000 + (self.rcv_tow_s * 1e9) as i64;
        crate::time::gps_minus_utc_s(crate::time::utc_ns_from_gps_ns(gps_ns))
    }
}

impl RawMeasurement {
    /// Which measurements an epoch with more than [`MAX_RAW_MEASUREMENTS`] keeps first (lower
    /// first, receiver order within a rank; u-blox `gnssId`/`sigId`): 0, the signals
    /// single-point positioning and the tightly coupled filter use (GPS, SBAS and QZSS L1 C/A,
    /// Galileo E1, BeiDou B1I and B3I, GLONASS L1OF); 1, the second signals of an
    /// ionosphere-free combination (GPS L2C or L2 P(Y), Galileo E5a); 2, the others. An all-band receiver
    /// reports 70 and more signals per epoch (the walk0827 u-blox X20: 22–25 satellites on
    /// 2–3 bands each).
    pub fn keep_rank(&self) -> u8 {
        match (self.gnss_id, self.sig_id) {
            (0 | 1 | 5 | 6, 0) | (5, 1) | (2, 0 | 1) | (3, 0 | 1 | 4 | 10) => 0,
            (0, 3 | 4 | SIG_GPS_L2_PY) | (2, 3 | 4) => 1,
            _ => 2,
        }
    }

    /// Whether the receiver kept lock on a carrier between a measurement with lock time
    /// `prev_ms` and this one `dt_s` later with `lock_time_ms`: the count did not fall (unless
    /// both saturated) and covers at least half the interval (a count shorter than that
    /// restarted in between). Phases across a `false` may differ by a cycle slip.
    pub fn kept_lock(prev_ms: u16, lock_ms: u16, dt_s: f64) -> bool {
        lock_ms >= prev_ms.min(LOCK_TIME_MAX_MS - 1) && f64::from(lock_ms) >= 500.0 * dt_s
    }
}
