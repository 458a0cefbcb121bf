//! The sample types that travel through shared memory.
//!
//! Conventions for every type here:
//! - `#[repr(C)]`, fixed size, no pointers (the IPC layer sends them zero-copy:
//!   `navsync_shared::ipc`); the layout version is part of the type name
//!   (`navsync.ImuSample.v1`), so a process built against another layout cannot open the
//!   service.
//! - Time stamps are integer nanoseconds. `host_ns` is the host's `CLOCK_MONOTONIC`;
//!   `utc_ns` is UTC since the Unix epoch; `gps_ns` is GPS time since 1980-01-06.
//! - Navigation frame: local-level NED (north, east, down). Body frame: forward, right, down (FRD).
//! - A float that is not known is NaN (written as JSON `null`).

mod any_sample;
mod estimator_settings;
mod event_pose;
mod gnss_event;
mod gnss_fix;
mod gnss_nav_data;
mod gnss_raw;
mod gnss_sky;
mod gnss_time_pulse;
mod health;
mod imu_sample;
#[cfg(test)]
mod layout_contract;
mod nav_state;
mod network_time;
mod pps_edge;
mod sim_truth;
mod stamp;
mod time_state;

pub use any_sample::AnySample;
pub use estimator_settings::{EstimatorSettings, SETTINGS_JSON_BYTES};
pub use event_pose::{EVENT_EDGE_FALLING, EVENT_EDGE_RISING, EventPose};
pub use gnss_event::GnssEvent;
pub use gnss_fix::*;
pub use gnss_nav_data::{GnssNavData, MAX_NAV_WORDS};
pub use gnss_raw::{GnssRaw, LOCK_TIME_MAX_MS, MAX_RAW_MEASUREMENTS, RawMeasurement, SIG_GPS_L2_PY};
pub use gnss_sky::{GnssSky, MAX_SKY_SATELLITES, SkySatellite};
pub use gnss_time_pulse::GnssTimePulse;
pub use health::{Counter, Health, MAX_COUNTERS, MAX_RATES, RateEntry};
pub use imu_sample::{IMU_FLAG_RECEIVER_CLOCK, IMU_FLAG_SATURATED, ImuSample};
pub use nav_state::{INTEGRITY_HEADING_UNKNOWN, INTEGRITY_INCONSISTENT, INTEGRITY_RECOVERING, NavState, NavStatus};
pub use network_time::{NetworkSource, NetworkTime};
pub use pps_edge::PpsEdge;
pub use sim_truth::SimTruth;
pub use stamp::{Stamp, StampSource};
pub use time_state::{ImuSync, ImuSyncReason, TimeState, TimeStatus};

/// Largest number of IMUs in one array (per-IMU tables in [`TimeState`] and [`NavState`]).
pub const MAX_IMUS: usize = 8;
