//! The GNSS time of a receiver's next time pulse (u-blox UBX-TIM-TP): labels the PPS edge
//! directly, with the pulse's quantisation error for the sawtooth correction.

use super::Stamp;

crate::sample_struct! {
    /// What the receiver says about its next time pulse (the PPS edge), sent before it.
    ///
    /// The receiver's pulse comes out on its local oscillator's grid, up to a few ns away from
    /// the ideal instant: that error is `q_err_ps` (u-blox: the pulse happens `q_err_ps` after
    /// the ideal time), so the ideal GNSS second's host time is the edge's stamp minus it.
    pub struct GnssTimePulse = "navsync.GnssTimePulse.v1" {
        /// Receipt stamp of the message's first byte and the driver's message counter.
        pub stamp: Stamp,
        /// GPS time of the next pulse, ns since 1980-01-06 (`i64::MIN` when not known).
        pub pulse_gps_ns: i64,
        /// UTC of the next pulse, ns since 1970 (`i64::MIN` when the leap seconds are not known).
        pub pulse_utc_ns: i64,
        /// Quantisation error of the next pulse, ps (`i32::MIN` when the receiver marks it invalid).
        pub q_err_ps: i32,
        /// The pulse's time base: 0 GNSS (GPS) time, 1 UTC.
        pub time_base: u8,
        /// 1 when the receiver has UTC (leap seconds) information.
        pub utc_available: u8,
        /// Reserved, zero.
        pub reserved: [u8; 2],
    }
}
