//! # navsync (daemon crate)
//!
//! The `navsync` executable is one multi-call binary: every role (`gnss`, `pps`, `imu`,
//! `estimator`, `sim`, `demo`, `echo`, …) runs as its own OS process and talks to the others
//! only through iceoryx2 services (see `navsync_shared::services`).
//!
//! - [`live`]: the process shells that wire a functional core (the estimator crate
//!   `navsync-estimator`, the drivers, the simulator) to the services, and the clients of the
//!   live services (`echo`, `status`, `record`, `gpsd-server`, `ntpshm`, `demo`).
//! - [`tools`]: offline tools over files (`replay --estimate`, `sim --fast`, `report`, `eval`,
//!   `analyze`, `import`, `decode`) and the installation helpers.
//! - [`config`]: the configuration file, deserialised into the roles' own types.
//!
//! Every subcommand has one options struct (clap) in its module, passed whole to it; a setting
//! is the flag when given, else the file's, else the documented default.

pub mod config;
pub mod live;
pub mod logging;
pub mod tools;
