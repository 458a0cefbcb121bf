//! # navsync-sim
//!
//! The simulated sensor world that stands in for the hardware: a drive on WGS-84
//! ([`trajectory`], [`scenario`]), its exact IMU increments by inverse mechanization
//! ([`inverse_mechanization`], [`vibration`], [`quadrature`]), IMU errors ([`imu_errors`],
//! [`imu_stream`]), a GNSS receiver writing NMEA or UBX ([`gnss_receiver`], [`nmea`], [`ubx`]) with GPS raw
//! measurements and navigation data from a real almanac ([`gps`]) and the time marks of a
//! camera on its EXTINT0 input ([`camera`]), a drifting host
//! oscillator and its PPS edges ([`oscillator`], [`pps`]) and the truth ([`truth`]), all
//! advanced together by [`world::World`].
//!
//! Two shells use the world: [`process`] (`navsync sim`: real time, IMUs and PPS into their
//! services or, through [`xsens_imus`], into pseudo-terminals as Xsens devices; NMEA into a
//! pseudo-terminal) and [`published::PublishedStream`] (the samples the drivers would publish,
//! as fast as the CPU allows, for `navsync sim --fast` and the estimator's tests).
//!
//! The simulator depends on the drivers' encoders and decoders (it writes what a device
//! writes); the drivers know nothing of it.

pub mod camera;
pub mod error;
pub mod gnss_receiver;
pub mod gps;
pub mod imu_errors;
pub mod imu_stream;
pub mod inverse_mechanization;
pub mod jet;
pub mod nmea;
pub mod oscillator;
pub mod pps;
pub mod process;
pub mod published;
pub mod quadrature;
pub mod rng;
pub mod scenario;
pub mod trajectory;
pub mod truth;
pub mod ubx;
pub mod vibration;
pub mod world;
pub mod xsens_imus;
