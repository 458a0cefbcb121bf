//! The simulated sensor world.

pub mod error;
pub mod gnss_receiver;
pub mod imu_errors;
pub mod imu_stream;
pub mod inverse_mechanization;
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
pub mod vibration;
pub mod world;
