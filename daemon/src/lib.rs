//! # navsync (daemon crate)
//!
//! The `navsync` executable is one multi-call binary: every role (`gps`, `pps`, `imu`,
//! `estimator`, `sim`, `demo`, `echo`, …) runs as its own OS process and talks to the others
//! only through iceoryx2 services (see `navsync_shared::services`).
//!
//! This library holds the [`estimator`] (functional core: mechanization, filters, clock
//! model) and the process shells in [`roles`] that wire the core to the services.

pub mod estimator;
pub mod evaluation;
pub mod input_order;
pub mod offline;
pub mod roles;
