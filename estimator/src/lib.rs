//! # navsync-estimator
//!
//! The functional core of navsync: plain synchronous state machines fed with time-stamped
//! samples, with no IPC, clocks, threads or files. The `navsync estimator` process, the
//! offline tools (`replay --estimate`, `sim --fast --estimate`, `report`, `analyze`), the
//! benchmarks and the tests all drive the same [`pipeline::Pipeline`], built from
//! [`settings::Settings`], in the same [`input_order`]; so the output depends only on the
//! samples and their order, and a replay is bit-identical.
//!
//! - [`time`]: the host clock against GNSS time (PPS labelling, clock Kalman filter, holdover,
//!   software-sync fallback, receiver latency, device clocks).
//! - [`nav`]: the navigation filter: strapdown mechanization in NED on WGS-84, the 22-state
//!   error model (KF-GINS conventions + GNSS delay Δ), the Kalman engine, alignment and the
//!   fusion horizon with its measurement queue ([`nav::measurement`]).
//! - [`array`]: several IMUs: online offset estimation, Lagrange fractional-delay alignment,
//!   fusion into one virtual IMU.
//! - [`pipeline`]: time sync + array + navigator as one state machine.
//! - [`input_order`]: the canonical order in which samples of many services enter it.
//! - [`feed`]: the one input path (order, dispatch, what comes back) of the live process and
//!   the offline runs.
//! - [`offline`]: the pipeline over a stream of samples as fast as the CPU allows.
//! - [`evaluation`]: accuracy against a truth (the simulator's, or another trajectory).
//! - [`settings`]: every setting, composed of the groups declared where they act
//!   ([`declare`]: one declaration per setting).
//! - [`gnss`]: GNSS signal-in-space models (GPS LNAV subframe decoding, checked against gpsd),
//!   the first pieces of tightly coupled fusion; not used by the pipeline yet.

#![forbid(unsafe_code)]

pub mod array;
pub mod declare;
pub mod evaluation;
pub mod events;
pub mod feed;
pub mod gnss;
pub mod input_order;
pub mod nav;
pub mod offline;
pub mod output_check;
pub mod pipeline;
pub mod settings;
pub mod time;

#[cfg(test)]
pub(crate) mod test_noise;
