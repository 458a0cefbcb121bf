//! GNSS signal-in-space models for tightly coupled fusion, pure functions documented against
//! IS-GPS-200: the GPS LNAV subframe decoder ([`lnav`]), the satellite position and clock from
//! the broadcast ephemeris or almanac ([`orbit`]), single-point positioning with the broadcast
//! ionosphere and a standard troposphere ([`spp`]), and a receiver's raw measurements paired
//! with the broadcast ephemerides for the filter ([`ranges`]); GLONASS immediate data and
//! its numerically integrated orbit and clock after the GLONASS ICD ([`glonass`], through
//! [`ranges`] like the others); Galileo I/NAV ([`galileo`]) and F/NAV ([`fnav`]), BeiDou D1/D2 ([`beidou`]) and GPS CNAV ([`cnav`],
//! L2C and L5) ephemerides, assembled per satellite from the receiver's navigation data words
//! ([`broadcast`]), their orbits through [`orbit`] with each system's constants.

pub mod beidou;
pub mod bits;
pub mod broadcast;
pub mod cnav;
pub mod fnav;
pub mod galileo;
pub mod glonass;
pub mod lnav;
pub mod orbit;
pub mod ranges;
pub mod spp;
