//! # navsync-shared
//!
//! What every navsync process agrees on, and nothing else: no driver and no estimator logic
//! lives here. Read the modules in this order:
//!
//! 1. [`samples`]: the `#[repr(C)]` sample types that travel through shared memory
//!    ([`samples::GnssFix`], [`samples::PpsEdge`], [`samples::ImuSample`],
//!    [`samples::TimeState`], [`samples::NavState`], [`samples::Health`], [`samples::SimTruth`]),
//!    with units and frames on every field.
//! 2. [`services`]: the service names (`navsync/imu/{id}/sample`, …) and their QoS.
//! 3. [`ipc`]: the iceoryx2 plumbing on navsync's own service type (futex wake-ups):
//!    [`ipc::IpcNode`], [`ipc::Publisher`] (zero-copy publish with wake-up),
//!    [`ipc::Subscriber`] (blocking wait with timeout), [`ipc::Wake`] (one wake-up for many
//!    inputs).
//! 4. [`time`]: host monotonic time, UTC, GPS time, leap seconds.
//! 5. [`earth`]: the WGS-84 model (radii, normal gravity, earth rate, transport rate).
//! 6. [`reflect`] and [`json`]: the field tables behind the layout contract and the JSON codec.
//! 7. [`client`]: subscribing from other programs (`NavClient::connect()?.next(timeout)`).
//! 8. [`history`]: the pose at any recent instant, from the estimator's states in shared
//!    memory (`History::open()?.state_at_host(t)`).
//!
//! Frames: navigation frame NED (north-east-down), body frame FRD (forward-right-down).
//! Times: integer nanoseconds; `host_ns` is `CLOCK_MONOTONIC`.

pub use navsync_wire::{cdr, earth, imu_spec, interpolation, json, reflect, ros2msg, samples, services, time};

pub mod client;
pub mod cpu_wakeup;
pub mod health_reporter;
pub mod history;
pub mod ipc;
pub mod latency_histogram;
pub mod pacing;
pub mod runtime_dir;
pub mod sd_notify;
pub mod source_map;
