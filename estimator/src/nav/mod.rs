//! The navigation filter.
//!
//! - [`mechanization`]: strapdown INS in NED on WGS-84 (increments, coning/sculling).
//! - [`error_state`], [`eskf`]: the 22-state error model (KF-GINS conventions + GNSS delay Δ)
//!   and the Kalman filter engine with chi-square gating.
//! - [`gnss_fusion`]: GNSS position/velocity observations with lever arm and the Δ Jacobians.
//! - [`alignment`]: levelling and GNSS-course heading.
//! - [`imu_buffer`], [`navigator`]: the fusion horizon (delayed filter + output predictor).

pub mod alignment;
pub mod error_state;
pub mod eskf;
pub mod gnss_fusion;
pub mod imu_buffer;
pub mod mechanization;
pub mod navigator;
