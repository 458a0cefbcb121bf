//! The estimator library: plain synchronous state machines fed with timestamped samples.
//! No IPC, clocks or threads in here; the `navsync estimator` process is the shell around it.
//!
//! - [`mechanization`]: strapdown INS in NED on WGS-84 (increments, coning/sculling).
//! - [`clock_model`]: Kalman filter of host-clock offset and drift against GNSS time.
//! - [`time_sync`]: PPS labelling, holdover, software-sync fallback, receiver latency.
//! - [`latency_stats`]: order statistics of the receiver output latency d0.

pub mod clock_model;
pub mod latency_stats;
pub mod mechanization;
pub mod time_sync;
