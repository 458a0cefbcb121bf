//! GNSS receiver driver: NMEA 0183 from a serial port to `GnssFix` samples.
//!
//! Pipeline (each stage a pure state machine, testable on bytes):
//! bytes → [`nmea_framer::LineFramer`] (sentences, each stamped with the host time of its
//! first byte) → [`nmea_epoch::EpochAssembler`] (sentences of one time tag merged into one
//! `GnssFix`) → publish.

pub mod driver;
pub mod nmea_epoch;
pub mod nmea_framer;
pub mod offline;
