//! The drivers as real processes (`navsync gnss`, `imu`, `feed`) on pseudo-terminals, FIFOs and
//! real receiver captures, and navsync's UBX decoders against pyubx2. One test binary; its tests
//! run concurrently, each in its own `TestEnv`.

mod feed_corpus;
mod feed_ubx;
mod gnss_configure;
mod gnss_event_host_time;
mod gnss_robustness;
mod imu_iio;
mod imu_xsens;
mod receivers;
mod sim_camera_events;
mod ubx_pyubx2;
