//! Recordings: navsync samples in MCAP files (<https://mcap.dev/spec>), what `navsync record`,
//! `navsync replay`, `navsync sim --fast --record`, clients and tests agree on.
//!
//! Read in this order:
//! 1. [`channels`]: the conventions (a ROS 2 bag: topic = `/` + service name, `cdr` messages,
//!    one `ros2msg` schema per sample type named `navsync_msgs/msg/ImuSample`, …; `json` too).
//! 2. [`sample_file`]: [`SampleRecorder`] and [`SampleReader`], samples in and out by service.
//! 3. [`mcap_writer`], [`mcap_reader`]: the container, through the `mcap` crate.
//! 4. [`ros_std`]: the standard ROS 2 messages written next to navsync's own (`--ros-std`).
//! 5. [`ports`], [`glob`]: what the record and replay processes need besides (pacing: `navsync_shared::pacing`).
//! 6. [`output`]: how every command writes a file (a temporary file renamed into place, inputs
//!    compared by device and inode, an existing recording replaced only with `--force`).
//!
//! # Time stamps of the messages
//!
//! MCAP gives every message a `log_time` and a `publish_time` (ns, epoch chosen by the
//! writer). navsync fills them so that `log_time` is always UTC-like (ns since 1970, what
//! Foxglove puts on its time axis) and `publish_time` is always host `CLOCK_MONOTONIC`
//! (what the samples themselves are stamped with, and what replay paces by):
//!
//! | writer | `log_time` | `publish_time` |
//! |---|---|---|
//! | `navsync record` (live) | `CLOCK_REALTIME` at receipt | `CLOCK_MONOTONIC` at receipt |
//! | `navsync sim --fast --record` | simulated UTC of the delivery instant | simulated host time of the delivery instant |
//! | `navsync replay --estimate --out` | `log_time` of the IMU sample the state is for | the state's `host_ns` |
//!
//! So in a simulated recording `publish_time` is exactly when the driver would have published
//! the sample, and in a live one when the recorder received it. Samples keep their own
//! stamps untouched; neither time replaces them.
//!
//! # Durability
//!
//! Recordings are chunked (zstd); the recorder closes a chunk at least every second and hands it to
//! the operating system, so a crash or `kill -9` loses at most the last second. A clean stop
//! writes the summary (schemas, channels, statistics, chunk indexes) and the footer.

#![forbid(unsafe_code)]

pub mod channels;
mod error;
pub mod glob;
pub mod mcap_reader;
pub mod mcap_writer;
pub mod output;
pub mod ports;
pub mod ros_std;
pub mod sample_file;

pub use channels::Encoding;
pub use error::RecordingError;
pub use mcap_reader::McapReader;
pub use mcap_writer::ChunkCompression;
pub use mcap_writer::McapWriter;
pub use sample_file::{RecordedSample, RecordingOptions, SampleReader, SampleRecorder};

#[cfg(test)]
mod tests;
