//! Tests that must have the machine to themselves: they assert latency, jitter, scatter or
//! deadlines of live processes (the receiver latency d0, device-clock timing, the time mapping,
//! stale inputs after `kill -9`, a stalled subscriber, the soak, the benchmarks, the Zenoh link,
//! chrony's offset, linuxptp's offset over veth), or change machine-wide state
//! (`/dev/cpu_dma_latency`). Each takes `navsync_tests::alone()` first, so they run one at a
//! time; cargo runs one test binary at a time.

mod bench_smoke;
mod chrony_shm;
mod faults_kill;
mod faults_subscriber_stall;
mod gnss_path;
mod idle_polling;
mod imu_device_clock;
mod live_pipeline;
mod network_time;
mod ptp;
mod receiver_latency;
mod soak;
mod zenoh_bridge;
