//! GNSS signal-in-space models for tightly coupled fusion, pure functions documented against
//! IS-GPS-200: so far the GPS LNAV subframe decoder ([`lnav`]), the satellite position and
//! clock from the broadcast ephemeris or almanac ([`orbit`]) and single-point positioning
//! with the broadcast ionosphere and a standard troposphere ([`spp`]).

pub mod lnav;
pub mod orbit;
pub mod spp;
