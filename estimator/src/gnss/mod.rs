//! GNSS signal-in-space models for tightly coupled fusion, pure functions documented against
//! IS-GPS-200: so far the GPS LNAV subframe decoder ([`lnav`]) and the satellite position
//! and clock from the broadcast ephemeris or almanac ([`orbit`]).

pub mod lnav;
pub mod orbit;
