//! The estimator library: plain synchronous state machines fed with timestamped samples.
//! No IPC, clocks or threads in here; the `navsync estimator` process is the shell around it.
//!
//! - [`mechanization`]: strapdown INS in NED on WGS-84 (increments, coning/sculling).
//! - [`clock_model`]: Kalman filter of host-clock offset and drift against GNSS time.
//! - [`time_sync`]: PPS labelling, holdover, software-sync fallback, receiver latency.
//! - [`latency_stats`]: order statistics of the receiver output latency d0.
//! - [`error_state`], [`eskf`]: the 22-state error model (KF-GINS conventions + GNSS delay Δ)
//!   and the Kalman filter engine with chi-square gating.
//! - [`gnss_fusion`]: GNSS position/velocity aiding with lever arm and the Δ Jacobians.
//! - [`alignment`]: levelling and GNSS-course heading.
//! - [`imu_buffer`], [`navigator`]: the fusion horizon (delayed filter + output predictor).
//! - [`imu_array`], [`imu_offset`], [`fractional_delay`]: several IMUs: online offset estimation,
//!   Lagrange fractional-delay alignment and fusion into one virtual IMU.

pub mod alignment;
pub mod clock_model;
pub mod device_clock;
pub mod error_state;
pub mod eskf;
pub mod fractional_delay;
pub mod gnss_fusion;
pub mod imu_array;
pub mod imu_buffer;
pub mod imu_offset;
pub mod latency_stats;
pub mod mechanization;
pub mod navigator;
pub mod pipeline;
pub mod time_sync;
