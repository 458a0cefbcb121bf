//! Recording and replay: `navsync record` beside a live run, `replay --estimate` bit for bit,
//! the checked-in recording, the recordings as ROS 2 bags in Python's `mcap` and `rosbags`, and
//! `navsync report`, `navsync geotag`. One test binary; its tests run concurrently, each in its own `TestEnv`.

mod geotag;
mod record_replay;
mod record_replay_data;
mod record_replay_python;
mod report;
mod ubx_import;
