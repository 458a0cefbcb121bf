//! # navsync-wire
//!
//! The wire contract every navsync process and every subscriber agrees on, and nothing that
//! moves it: no IPC, no threads. The IPC plumbing on iceoryx2 is beside it in
//! `navsync-shared`, so the estimator (a pure state machine) builds without iceoryx2.
//!
//! 1. [`samples`]: the `#[repr(C)]` sample types, with units and frames on every field.
//! 2. [`services`]: the service names (`navsync/imu/{id}/sample`, …) and their QoS.
//! 3. [`time`]: host monotonic time, UTC, GPS time, leap seconds.
//! 4. [`earth`]: the WGS-84 model (radii, normal gravity, earth rate, transport rate).
//! 5. [`imu_spec`]: the IMU error description shared by the simulator and the estimator;
//!    [`interpolation`]: a navigation state between two states (the history's and the event poses').
//! 6. [`reflect`], [`json`], [`cdr`], [`ros2msg`]: the field tables behind the layout contract
//!    and the codecs driven by them.
//!
//! Frames: navigation frame NED (north-east-down), body frame FRD (forward-right-down).
//! Times: integer nanoseconds; `host_ns` is `CLOCK_MONOTONIC`.

pub mod cdr;
pub mod earth;
pub mod imu_spec;
pub mod interpolation;
pub mod json;
pub mod reflect;
pub mod ros2msg;
pub mod samples;
pub mod services;
pub mod time;
