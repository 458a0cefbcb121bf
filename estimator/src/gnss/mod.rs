//! GNSS signal-in-space models for tightly coupled fusion, pure functions documented against
//! IS-GPS-200: the GPS LNAV subframe decoder ([`lnav`]), the satellite position and clock from
//! the broadcast ephemeris or almanac ([`orbit`]), single-point positioning with the broadcast
//! ionosphere and a standard troposphere ([`spp`]), and a receiver's raw measurements paired
//! with the broadcast ephemerides for the filter ([`ranges`]); GLONASS immediate data and
//! its numerically integrated orbit after the GLONASS ICD ([`glonass`]: geometry only, not
//! fused yet).

pub mod glonass;
pub mod lnav;
pub mod orbit;
pub mod ranges;
pub mod spp;
