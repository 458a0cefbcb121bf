//! Live sets of processes and the ways in for other programs: `navsync demo`, `status`, `echo`,
//! the Rust client API, Python over iceoryx2 and `ctypes`, `gpsd-server`, `web`, the health table, the
//! futex wake-ups, a PPS source going silent, the systemd units, `navsync install`, the
//! shared memory's permissions and how user errors are reported. One test binary; its tests run concurrently, each in its own `TestEnv`.

mod clients_common;

mod client_api;
mod demo;
mod event_poses;
mod faults_pps_silence_live;
mod foxglove;
mod gpsd_server;
mod health_table;
mod history;
mod install;
mod ipc_wake;
mod nmea_out;
mod pps_out;
mod python_iceoryx2;
mod python_types;
mod reliability;
mod shm_permissions;
mod status_echo;
mod systemd_units;
mod user_errors;
mod web;
