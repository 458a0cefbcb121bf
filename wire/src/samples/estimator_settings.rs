//! The estimator's settings in force, so that a recording of a live run replays like it.

/// Bytes of [`EstimatorSettings::json`].
pub const SETTINGS_JSON_BYTES: usize = 4096;

crate::sample_struct! {
    /// The settings a running estimator uses (its flags over its configuration file over the
    /// defaults), published about once per second on `navsync/estimator/settings`; a recording
    /// keeps them and `replay --estimate` starts from them.
    pub struct EstimatorSettings = "navsync.EstimatorSettings.v1" {
        /// Host time of this report, ns (`CLOCK_MONOTONIC`).
        pub host_ns: i64,
        /// Report sequence number.
        pub seq: u64,
        /// The settings as JSON (`Settings::in_force_json` of the estimator crate), NUL-padded
        /// UTF-8.
        pub json: [u8; SETTINGS_JSON_BYTES],
    }
}

impl EstimatorSettings {
    /// A report of `json` at `host_ns`; `None` when it does not fit.
    pub fn new(host_ns: i64, seq: u64, json: &str) -> Option<Self> {
        let bytes = json.as_bytes();
        if bytes.len() > SETTINGS_JSON_BYTES || bytes.contains(&0) {
            return None;
        }
        let mut s = <Self as crate::reflect::Reflect>::zeroed();
        s.host_ns = host_ns;
        s.seq = seq;
        s.json[..bytes.len()].copy_from_slice(bytes);
        Some(s)
    }

    /// The JSON text (up to the first NUL); `None` when it is not UTF-8.
    pub fn text(&self) -> Option<&str> {
        let n = self.json.iter().position(|&b| b == 0).unwrap_or(self.json.len());
        core::str::from_utf8(&self.json[..n]).ok()
    }
}
