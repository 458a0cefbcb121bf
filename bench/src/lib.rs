//! # navsync-bench
//!
//! The benchmarks behind the tables of docs/benchmarks/, as a crate of their own
//! so the production `navsync` binary does not carry them. Each is one subcommand of the
//! `navsync-bench` binary with one options struct, prints a table and writes JSON with
//! `--json FILE`; `--quick` is the smoke-test size CI runs (`tests/tests/timing/bench_smoke.rs`).
//!
//! - [`ipc`]: publisher → subscriber latency between processes, iceoryx2 against a Unix socket.
//! - [`e2e`]: IMU driver → estimator → subscriber latency of the live pipeline, CPU and memory.
//! - [`gnss_latency`]: a receiver's epoch → fix at a subscriber, navsync against gpsd.
//! - [`throughput`]: IMU samples per second through the estimator library.
//! - [`timing`]: the time synchronisation against the simulated host oscillator (offline).
//! - [`zenoh`]: a NavState across two network namespaces through two Zenoh bridges.
//! - [`history`]: a `state_at` query of the history of states from another process.
//! - [`host`]: the machine's own wake-up lateness and stalls, no navsync code involved.
//! - [`netns`]: two "hosts" on one machine (network namespaces and a veth pair).
//! - [`util`]: percentiles, the machine's state, child processes, JSON.
//!
//! The processes the live benchmarks start are `navsync` roles (found beside this executable,
//! or `$NAVSYNC_BIN`) and `navsync-bench helper …` (publishers and subscribers of the IPC
//! benchmark, the end-to-end subscriber).

pub mod e2e;
pub mod gnss_latency;
pub mod history;
pub mod host;
pub mod ipc;
pub mod netns;
pub mod throughput;
pub mod timing;
pub mod util;
pub mod zenoh;
