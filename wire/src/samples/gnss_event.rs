//! A time mark of an external event on a receiver's input pin (u-blox UBX-TIM-TM2: a camera's
//! exposure pulse on EXTINT), in GNSS time and, where the time mapping is known, host time.

use super::Stamp;

crate::sample_struct! {
    /// One time-mark report: the latest rising and falling edges on one input channel.
    pub struct GnssEvent = "navsync.GnssEvent.v1" {
        /// Receipt stamp of the message's first byte and the driver's message counter.
        pub stamp: Stamp,
        /// GPS time of the last rising edge, ns since 1980-01-06 (`i64::MIN` when none is new).
        pub rising_gps_ns: i64,
        /// GPS time of the last falling edge, ns since 1980-01-06 (`i64::MIN` when none is new).
        pub falling_gps_ns: i64,
        /// Host time (`CLOCK_MONOTONIC`) of the rising edge through the estimator's time
        /// mapping, ns (`i64::MIN` when the mapping was not known).
        pub rising_host_ns: i64,
        /// Host time of the falling edge, ns (`i64::MIN` when not known).
        pub falling_host_ns: i64,
        /// The receiver's accuracy estimate of the time marks, ns.
        pub accuracy_ns: u32,
        /// Edge counter of the channel (rising edges, as the receiver counts them).
        pub count: u16,
        /// Input channel (u-blox: 0 EXTINT0, 1 EXTINT1).
        pub channel: u8,
        /// The receiver's flags byte (u-blox TIM-TM2 `flags`: mode, run, new edges, time base, UTC, valid).
        pub flags: u8,
    }
}
