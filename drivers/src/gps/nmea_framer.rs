//! Splits a serial byte stream into NMEA sentences.
