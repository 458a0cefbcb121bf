//! The navigation filter.
//!
//! - [`mechanization`]: strapdown INS in NED on WGS-84 (increments, coning/sculling).
//! - [`error_state`], [`eskf`]: the 27-state error model (KF-GINS conventions + GNSS delay Δ + receiver clock)
//!   and the Kalman filter engine with chi-square gating.
//! - [`config`]: the filter's settings (a leaf: one declaration per setting).
//! - [`alignment`]: levelling and GNSS-course heading.
//! - [`noise_meter`]: the white noise an IMU of unknown class can have, from its own signal.
//! - [`imu_buffer`], [`filter`], [`navigator`]: the fusion horizon (delayed filter + output
//!   predictor).
//! - [`measurements`]: the one measurement queue and its kinds (GNSS position/velocity with
//!   lever arm and the Δ Jacobians, …), each fused at its own epoch.

pub mod alignment;
pub mod config;
pub mod error_state;
pub mod eskf;
pub mod filter;
pub mod heading_bank;
pub mod imu_buffer;
pub mod integrity;
pub mod measurements;
pub mod mechanization;
pub mod navigator;
pub mod noise_meter;
pub mod smoother;
