//! `[recording]`: how every navsync writer of recordings (`record`, `sim --fast --record`,
//! `replay --estimate --out`, `convert`) encodes them, and the flags that override it
//! (flag, else file, else default).

use serde::Deserialize;

use navsync_recording::ros_std::RosFrames;
use navsync_recording::{Encoding, RecordingOptions};

/// `[recording]`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RecordingConfig {
    /// Message encoding: `cdr` (a ROS 2 bag; default) or `json` (text).
    pub encoding: Encoding,
    /// Also write the standard ROS 2 messages (`sensor_msgs/Imu`, `NavSatFix`,
    /// `nav_msgs/Odometry`, `sensor_msgs/TimeReference`); default false.
    pub ros_std: bool,
    /// Frame ids of the standard messages (`[recording.ros_frames]`).
    pub ros_frames: RosFrames,
}

/// Flags of every command that writes a recording.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct RecordingFlags {
    /// Message encoding of the recording: cdr (a ROS 2 bag) or json (text)
    /// [default: [recording].encoding, else cdr].
    #[arg(long, value_parser = parse_encoding)]
    pub encoding: Option<Encoding>,
    /// Also write the standard ROS 2 messages (sensor_msgs/Imu per IMU, NavSatFix per
    /// receiver, nav_msgs/Odometry, sensor_msgs/TimeReference) [default: [recording].ros_std].
    #[arg(long)]
    pub ros_std: bool,
}

fn parse_encoding(s: &str) -> Result<Encoding, String> {
    match s {
        "cdr" => Ok(Encoding::Cdr),
        "json" => Ok(Encoding::Json),
        _ => Err(format!("`{s}`: expected cdr or json")),
    }
}

impl RecordingFlags {
    /// The options of a recording: these flags, else `[recording]`, else the defaults.
    pub fn options(&self, cfg: &RecordingConfig) -> RecordingOptions {
        let ros_std = self.ros_std || cfg.ros_std;
        RecordingOptions {
            encoding: self.encoding.unwrap_or(cfg.encoding),
            ros_std: ros_std.then(|| cfg.ros_frames.clone()),
            ..RecordingOptions::default()
        }
    }
}
