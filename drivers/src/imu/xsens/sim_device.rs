//! Where the simulator's IMUs appear as Xsens MTi devices: `navsync sim --imu-output xsens`
//! writes one pseudo-terminal per IMU at [`sim_port`] (the writer is `navsync_sim::xsens_imus`),
//! and `navsync imu --source sim[:DIR] --id I` reads IMU `I` there with the Xsens driver.

use std::path::{Path, PathBuf};

/// Line rate the simulated devices nominally use (a pseudo-terminal has none; the driver
/// uses it to back-date messages that arrive together).
pub const SIM_BAUD: u32 = 921_600;
/// Directory of the simulated devices' links when none is given: navsync's runtime
/// directory ([`navsync_shared::runtime_dir::base`]: `$RUNTIME_DIRECTORY`,
/// `$XDG_RUNTIME_DIR/navsync`, `/run/navsync` for root, else `/tmp/navsync-<uid>`), checked
/// before use by both sides.
pub fn default_sim_dir() -> PathBuf {
    navsync_shared::runtime_dir::base()
}

/// The link to simulated IMU `index`'s pseudo-terminal in `dir`: `dir/imu{index}`.
pub fn sim_port(dir: &Path, index: usize) -> PathBuf {
    dir.join(format!("imu{index}"))
}
