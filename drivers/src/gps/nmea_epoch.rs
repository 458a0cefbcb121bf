//! Groups NMEA sentences into GNSS epochs.
