//! Service names and per-service quality of service: the one place that spells them.
//!
//! | service | type | publisher |
//! |---|---|---|
//! | `navsync/gnss/{id}/fix` | [`GnssFix`] | `navsync gnss` |
//! | `navsync/gnss/{id}/hnr` | [`GnssFix`] | `navsync gnss` (UBX HNR-PVT: the receiver's high-rate fused solution) |
//! | `navsync/gnss/{id}/timepulse` | [`GnssTimePulse`] | `navsync gnss` (UBX TIM-TP) |
//! | `navsync/gnss/{id}/event` | [`GnssEvent`] | `navsync gnss` (UBX TIM-TM2) |
//! | `navsync/gnss/{id}/raw` | [`GnssRaw`] | `navsync gnss` (UBX RXM-RAWX) |
//! | `navsync/gnss/{id}/nav-data` | [`GnssNavData`] | `navsync gnss` (UBX RXM-SFRBX) |
//! | `navsync/trigger/{id}/event` | [`GnssEvent`] | `navsync trigger` (a host-stamped trigger input's edges: GPIO line events) |
//! | `navsync/event/{id}/pose` | [`EventPose`] | `navsync estimator` (each event receiver `id` marked, with the pose at its instant once fused) |
//! | `navsync/gnss/{id}/sky` | [`GnssSky`] | `navsync gnss` (the satellites of an epoch: NMEA GSV with GSA, UBX NAV-SAT or NAV-SVINFO) |
//! | `navsync/pps/{id}/edge` | [`PpsEdge`] | `navsync pps` (or the simulator) |
//! | `navsync/imu/{id}/sample` | [`ImuSample`] | `navsync imu` (or the simulator) |
//! | `navsync/time/state` | [`TimeState`] | `navsync estimator` |
//! | `navsync/time/network` | [`NetworkTime`] | `navsync estimator --time-source chrony\|system` (its readings of the network time service) |
//! | `navsync/nav/state` | [`NavState`] | `navsync estimator` |
//! | `navsync/nav/fused` | [`NavState`] | `navsync replay --estimate --fused --out` (the delayed filter's states; live they go into the history) |
//! | `navsync/health/{process}` | [`Health`] | every process |
//! | `navsync/estimator/settings` | [`EstimatorSettings`] | `navsync estimator` (its settings in force, about once per second) |
//! | `navsync/sim/truth` | [`SimTruth`] | `navsync sim` |
//! | `navsync/sim/pps` | [`PpsEdge`] | `navsync sim` (raw edges for `navsync pps --source sim`) |
//!
//! Each publish-subscribe service has an event service of the same name through which
//! publishers wake subscribers.

use crate::reflect::Reflect;
use crate::samples::{
    AnySample, EstimatorSettings, EventPose, GnssEvent, GnssFix, GnssNavData, GnssRaw, GnssSky, GnssTimePulse, Health,
    ImuSample, NavState, NetworkTime, PpsEdge, SimTruth, TimeState,
};

/// Environment variable with the iceoryx2 resource prefix (default [`DEFAULT_PREFIX`]).
/// Tests set a unique value so that parallel tests and a running demo never meet.
pub const PREFIX_ENV: &str = "NAVSYNC_IPC_PREFIX";
/// Default iceoryx2 resource prefix for shared-memory and lock files.
pub const DEFAULT_PREFIX: &str = "navsync_";

/// `navsync/gnss/{id}/fix`
pub fn gnss_fix(id: &str) -> String {
    format!("navsync/gnss/{id}/fix")
}
/// `navsync/gnss/{id}/hnr`: the receiver's high-rate blend of GNSS and its own sensors (UBX
/// HNR-PVT), a stream of its own beside the GNSS epochs on [`gnss_fix`] (its fixes carry
/// `FIX_FLAG_NOT_GNSS`).
pub fn gnss_hnr(id: &str) -> String {
    format!("navsync/gnss/{id}/hnr")
}
/// `navsync/gnss/{id}/timepulse`
pub fn gnss_time_pulse(id: &str) -> String {
    format!("navsync/gnss/{id}/timepulse")
}
/// `navsync/gnss/{id}/event`
pub fn gnss_event(id: &str) -> String {
    format!("navsync/gnss/{id}/event")
}
/// `navsync/gnss/{id}/raw`
pub fn gnss_raw(id: &str) -> String {
    format!("navsync/gnss/{id}/raw")
}
/// `navsync/gnss/{id}/nav-data`
pub fn gnss_nav_data(id: &str) -> String {
    format!("navsync/gnss/{id}/nav-data")
}
/// `navsync/gnss/{id}/sky`: the satellites the receiver reports with an epoch (elevation,
/// azimuth, C/N0, used in the solution).
pub fn gnss_sky(id: &str) -> String {
    format!("navsync/gnss/{id}/sky")
}
/// `navsync/trigger/{id}/event`: a host-stamped trigger input's edges (`navsync trigger`), as
/// [`GnssEvent`]s with host times only.
pub fn trigger_event(id: &str) -> String {
    format!("navsync/trigger/{id}/event")
}
/// `navsync/event/{id}/pose`: the events device `id` marked (a receiver's TIM-TM2), each
/// with the pose at its instant.
pub fn event_pose(id: &str) -> String {
    format!("navsync/event/{id}/pose")
}
/// `navsync/pps/{id}/edge`
pub fn pps_edge(id: &str) -> String {
    format!("navsync/pps/{id}/edge")
}
/// `navsync/imu/{id}/sample`
pub fn imu_sample(id: &str) -> String {
    format!("navsync/imu/{id}/sample")
}
/// `navsync/health/{process}`
pub fn health(process: &str) -> String {
    format!("navsync/health/{process}")
}
/// The time mapping.
pub const TIME_STATE: &str = "navsync/time/state";
/// The readings of the network time service an estimator without a receiver maps its host
/// clock with.
pub const NETWORK_TIME: &str = "navsync/time/network";
/// The navigation solution.
pub const NAV_STATE: &str = "navsync/nav/state";
/// The delayed filter's states (its state at each instant it stepped over, every measurement
/// up to it fused): written by `navsync replay --estimate --fused --out`; the live estimator keeps
/// them in the history of states (`navsync_shared::history`) rather than publishing them.
pub const NAV_FUSED: &str = "navsync/nav/fused";
/// The estimator's settings in force.
pub const ESTIMATOR_SETTINGS: &str = "navsync/estimator/settings";
/// Simulator ground truth.
pub const SIM_TRUTH: &str = "navsync/sim/truth";
/// Raw simulated PPS edges (simulator-private; `navsync pps --source sim` validates them and
/// republishes on [`pps_edge`]).
pub const SIM_PPS: &str = "navsync/sim/pps";

/// The sample type carried by a service.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ServiceKind {
    /// [`GnssFix`]
    GnssFix,
    /// [`PpsEdge`]
    PpsEdge,
    /// [`ImuSample`]
    ImuSample,
    /// [`TimeState`]
    TimeState,
    /// [`NavState`]
    NavState,
    /// [`Health`]
    Health,
    /// [`SimTruth`]
    SimTruth,
    /// [`GnssTimePulse`]
    GnssTimePulse,
    /// [`GnssEvent`]
    GnssEvent,
    /// [`GnssRaw`]
    GnssRaw,
    /// [`GnssNavData`]
    GnssNavData,
    /// [`EstimatorSettings`]
    EstimatorSettings,
    /// [`NetworkTime`]
    NetworkTime,
    /// [`GnssSky`]
    GnssSky,
    /// [`EventPose`]
    EventPose,
}

impl ServiceKind {
    /// The kind of service that carries `sample`.
    pub fn of_sample(sample: &AnySample) -> Self {
        match sample {
            AnySample::GnssFix(_) => Self::GnssFix,
            AnySample::PpsEdge(_) => Self::PpsEdge,
            AnySample::Imu(_) => Self::ImuSample,
            AnySample::Time(_) => Self::TimeState,
            AnySample::Nav(_) => Self::NavState,
            AnySample::Health(_) => Self::Health,
            AnySample::Truth(_) => Self::SimTruth,
            AnySample::TimePulse(_) => Self::GnssTimePulse,
            AnySample::Event(_) => Self::GnssEvent,
            AnySample::Raw(_) => Self::GnssRaw,
            AnySample::NavData(_) => Self::GnssNavData,
            AnySample::Settings(_) => Self::EstimatorSettings,
            AnySample::NetworkTime(_) => Self::NetworkTime,
            AnySample::Sky(_) => Self::GnssSky,
            AnySample::EventPose(_) => Self::EventPose,
        }
    }

    /// All kinds.
    pub const ALL: [ServiceKind; 15] = [
        Self::GnssFix,
        Self::PpsEdge,
        Self::ImuSample,
        Self::TimeState,
        Self::NavState,
        Self::Health,
        Self::SimTruth,
        Self::GnssTimePulse,
        Self::GnssEvent,
        Self::GnssRaw,
        Self::GnssNavData,
        Self::EstimatorSettings,
        Self::NetworkTime,
        Self::GnssSky,
        Self::EventPose,
    ];

    /// The kind's position in [`ALL`](Self::ALL): its event id on [`WAKE`].
    pub fn index(self) -> usize {
        Self::ALL.iter().position(|&k| k == self).unwrap_or(Self::ALL.len())
    }

    /// The kind of a service from its name, or `None` for a name navsync does not use.
    pub fn of(service: &str) -> Option<Self> {
        let parts: Vec<&str> = service.split('/').collect();
        match parts.as_slice() {
            ["navsync", "gnss", id, "fix" | "hnr"] if !id.is_empty() => Some(Self::GnssFix),
            ["navsync", "gnss", id, "timepulse"] if !id.is_empty() => Some(Self::GnssTimePulse),
            ["navsync", "gnss", id, "event"] if !id.is_empty() => Some(Self::GnssEvent),
            ["navsync", "gnss", id, "raw"] if !id.is_empty() => Some(Self::GnssRaw),
            ["navsync", "gnss", id, "nav-data"] if !id.is_empty() => Some(Self::GnssNavData),
            ["navsync", "gnss", id, "sky"] if !id.is_empty() => Some(Self::GnssSky),
            ["navsync", "event", id, "pose"] if !id.is_empty() => Some(Self::EventPose),
            ["navsync", "trigger", id, "event"] if !id.is_empty() => Some(Self::GnssEvent),
            ["navsync", "pps", id, "edge"] if !id.is_empty() => Some(Self::PpsEdge),
            ["navsync", "imu", id, "sample"] if !id.is_empty() => Some(Self::ImuSample),
            ["navsync", "time", "state"] => Some(Self::TimeState),
            ["navsync", "time", "network"] => Some(Self::NetworkTime),
            ["navsync", "nav", "state" | "fused"] => Some(Self::NavState),
            ["navsync", "health", p] if !p.is_empty() => Some(Self::Health),
            ["navsync", "estimator", "settings"] => Some(Self::EstimatorSettings),
            ["navsync", "sim", "truth"] => Some(Self::SimTruth),
            ["navsync", "sim", "pps"] => Some(Self::PpsEdge),
            _ => None,
        }
    }

    /// iceoryx2 type name, which includes the layout version.
    pub fn type_name(self) -> &'static str {
        match self {
            Self::GnssFix => GnssFix::TYPE_NAME,
            Self::PpsEdge => PpsEdge::TYPE_NAME,
            Self::ImuSample => ImuSample::TYPE_NAME,
            Self::TimeState => TimeState::TYPE_NAME,
            Self::NavState => NavState::TYPE_NAME,
            Self::Health => Health::TYPE_NAME,
            Self::SimTruth => SimTruth::TYPE_NAME,
            Self::GnssTimePulse => GnssTimePulse::TYPE_NAME,
            Self::GnssEvent => GnssEvent::TYPE_NAME,
            Self::GnssRaw => GnssRaw::TYPE_NAME,
            Self::GnssNavData => GnssNavData::TYPE_NAME,
            Self::EstimatorSettings => EstimatorSettings::TYPE_NAME,
            Self::NetworkTime => NetworkTime::TYPE_NAME,
            Self::GnssSky => GnssSky::TYPE_NAME,
            Self::EventPose => EventPose::TYPE_NAME,
        }
    }

    /// Quality of service of this kind of service.
    pub fn qos(self) -> Qos {
        match self {
            // Up to 1 kHz per IMU: a 0.5 s buffer rides out a scheduling hiccup of the estimator.
            Self::ImuSample => Qos {
                history: 0,
                buffer: 512,
            },
            Self::SimTruth => Qos {
                history: 1,
                buffer: 512,
            },
            Self::NavState => Qos {
                history: 1,
                buffer: 512,
            },
            Self::GnssFix | Self::PpsEdge | Self::GnssTimePulse | Self::GnssEvent | Self::GnssRaw | Self::EventPose => {
                Qos { history: 1, buffer: 64 }
            }
            // Up to ~40 subframes per second over all tracked satellites.
            Self::GnssNavData => Qos {
                history: 0,
                buffer: 256,
            },
            // About once per second per receiver; a late subscriber (the web page) gets the last.
            Self::TimeState | Self::Health | Self::NetworkTime | Self::GnssSky => Qos { history: 1, buffer: 16 },
            // About once per second; a recorder started later gets the last one.
            Self::EstimatorSettings => Qos { history: 1, buffer: 4 },
        }
    }
}

/// Publish-subscribe settings of a service. Publishers never block: a subscriber whose
/// buffer is full loses its oldest sample (iceoryx2 safe overflow), which shows as a gap
/// in the sequence numbers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Qos {
    /// Samples a late subscriber receives on connecting.
    pub history: usize,
    /// Samples buffered per subscriber.
    pub buffer: usize,
}

/// Services under this prefix carry benchmark payloads of any type (`navsync-bench ipc`), with
/// [`BENCH_QOS`]; they are no [`ServiceKind`], so recorders and bridges leave them alone.
pub const BENCH_PREFIX: &str = "navsync/bench/";
/// Publish-subscribe settings of the benchmark services.
pub const BENCH_QOS: Qos = Qos { history: 0, buffer: 16 };

/// The event every navsync publisher notifies after publishing, with its service's
/// [`ServiceKind::index`] as the event id: the one wake-up of a process with many inputs
/// (`ipc::Wake`).
pub const WAKE: &str = "navsync/wake";
/// Maximum notifiers on [`WAKE`]: one per publisher of every process under a prefix.
pub const MAX_WAKE_NOTIFIERS: usize = 128;
/// Maximum nodes on [`WAKE`]: every process under a prefix.
pub const MAX_WAKE_NODES: usize = 64;

/// The stock iceoryx2 event (Unix-datagram trigger, `iceoryx2::service::ipc::Service`) that
/// publishers of `service` also notify, for subscribers built on iceoryx2's own service types
/// (the `iceoryx2` Python package), which cannot wait on navsync's futex events: `{service}/wake`.
pub fn stock_wake(service: &str) -> String {
    format!("{service}/wake")
}

/// Kinds whose publishers notify a [`stock_wake`] event too: the outputs other programs read.
pub fn has_stock_wake(kind: ServiceKind) -> bool {
    matches!(kind, ServiceKind::NavState | ServiceKind::TimeState)
}

/// Maximum subscribers per service.
pub const MAX_SUBSCRIBERS: usize = 16;
/// Maximum publishers per service (a replay and a driver may overlap briefly).
pub const MAX_PUBLISHERS: usize = 4;
/// Maximum nodes (processes) attached to one service.
pub const MAX_NODES: usize = 24;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds_from_names() {
        assert_eq!(ServiceKind::of(&gnss_fix("0")), Some(ServiceKind::GnssFix));
        assert_eq!(ServiceKind::of(&gnss_hnr("0")), Some(ServiceKind::GnssFix));
        assert_eq!(ServiceKind::of(&gnss_sky("0")), Some(ServiceKind::GnssSky));
        assert_eq!(ServiceKind::of(&event_pose("0")), Some(ServiceKind::EventPose));
        assert_eq!(ServiceKind::of(&trigger_event("cam0")), Some(ServiceKind::GnssEvent));
        assert_eq!(ServiceKind::of(&imu_sample("3")), Some(ServiceKind::ImuSample));
        assert_eq!(ServiceKind::of(&health("gps-0")), Some(ServiceKind::Health));
        assert_eq!(ServiceKind::of(NAV_STATE), Some(ServiceKind::NavState));
        assert_eq!(ServiceKind::of(NAV_FUSED), Some(ServiceKind::NavState));
        assert_eq!(ServiceKind::of(SIM_PPS), Some(ServiceKind::PpsEdge));
        assert_eq!(ServiceKind::of("navsync/imu//sample"), None);
        assert_eq!(ServiceKind::of("other/thing"), None);
    }
}
