//! GNSS receiver driver: NMEA 0183 from a serial port to `GnssFix` samples.
//!
//! Pipeline (each stage a pure state machine, testable on bytes):
//! bytes → [`nmea_framer::LineFramer`] (sentences, each stamped with the host time of its
//! first byte) → [`nmea_sentence`] (checksum, fields decoded into an update in SI units) →
//! [`nmea_epoch::EpochAssembler`] (the updates of one time tag merged into one `GnssFix`) →
//! publish.

pub mod driver;
pub mod nmea_epoch;
pub mod nmea_framer;
pub mod nmea_sentence;
pub mod offline;
