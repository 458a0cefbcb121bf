//! # navsync (daemon crate)
//!
//! The `navsync` executable is one multi-call binary: every role (`gps`, `pps`, `imu`,
//! `estimator`, `sim`, `demo`, `echo`, …) runs as its own OS process and talks to the others
//! only through iceoryx2 services (see `navsync_shared::services`).
//!
//! The functional core is the crate `navsync-estimator`; this crate holds the process shells
//! in [`roles`] that wire it (and the drivers) to the services.

pub mod roles;
