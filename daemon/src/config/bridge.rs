//! `[bridge.zenoh]`: what `navsync bridge zenoh` exports and imports (flags override it).

use std::collections::BTreeMap;
use std::path::PathBuf;

use serde::Deserialize;

/// `[bridge]`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Bridges {
    /// `[bridge.zenoh]`.
    pub zenoh: Option<ZenohBridgeConfig>,
}

/// Zenoh's role, as the file names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ZenohMode {
    /// Peer to peer.
    Peer,
    /// Client.
    Client,
    /// Router.
    Router,
}

/// `[bridge.zenoh]`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ZenohBridgeConfig {
    /// This host's name in the keys (`navsync/<instance>/nav/state`); default the host name.
    pub instance: Option<String>,
    /// Services (names or patterns) to export; default `navsync/nav/state`,
    /// `navsync/time/state`, `navsync/health/**`; `[]` exports nothing.
    pub export: Option<Vec<String>>,
    /// Rate limits, service name or pattern → samples per second (e.g.
    /// `"navsync/nav/state" = 50`).
    pub rates: BTreeMap<String, f64>,
    /// Import the services of this remote instance (`"*"`: every other one) into the local
    /// iceoryx2, under the same names.
    pub import: Option<String>,
    /// Which services to import (patterns; default every navsync service).
    pub import_services: Vec<String>,
    /// A Zenoh configuration file (JSON5), passed through.
    pub zenoh_config: Option<PathBuf>,
    /// peer (default), client or router.
    pub mode: Option<ZenohMode>,
    /// Endpoints to connect to, e.g. `["tcp/192.168.1.10:7447"]`.
    pub connect: Vec<String>,
    /// Endpoints to listen on, e.g. `["tcp/0.0.0.0:7447"]`.
    pub listen: Vec<String>,
}
