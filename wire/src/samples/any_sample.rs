//! Any navsync sample, tagged with its type: what a recording holds and a replay publishes.

use super::{
    EstimatorSettings, EventPose, GnssEvent, GnssFix, GnssNavData, GnssRaw, GnssSky, GnssTimePulse, Health, ImuSample,
    NavState, NetworkTime, PpsEdge, SimTruth, TimeState,
};

/// A sample of any navsync type. Variants differ in size (a `Health` report is ~2.4 kB); the
/// enum stays unboxed because boxing would allocate per sample on replay paths.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AnySample {
    /// `navsync/gnss/{id}/fix`
    GnssFix(GnssFix),
    /// `navsync/pps/{id}/edge`
    PpsEdge(PpsEdge),
    /// `navsync/imu/{id}/sample`
    Imu(ImuSample),
    /// `navsync/time/state`
    Time(TimeState),
    /// `navsync/nav/state`
    Nav(NavState),
    /// `navsync/health/{process}`
    Health(Health),
    /// `navsync/sim/truth`
    Truth(SimTruth),
    /// `navsync/gnss/{id}/timepulse`
    TimePulse(GnssTimePulse),
    /// `navsync/gnss/{id}/event`
    Event(GnssEvent),
    /// `navsync/gnss/{id}/raw`
    Raw(GnssRaw),
    /// `navsync/gnss/{id}/nav-data`
    NavData(GnssNavData),
    /// `navsync/estimator/settings`
    Settings(EstimatorSettings),
    /// `navsync/time/network`
    NetworkTime(NetworkTime),
    /// `navsync/gnss/{id}/sky`
    Sky(GnssSky),
    /// `navsync/event/{id}/pose`
    EventPose(EventPose),
}

impl AnySample {
    /// The publisher's sequence number of the sample (consecutive samples of one publisher
    /// differ by 1; a gap is samples the reader did not see).
    pub fn seq(&self) -> u64 {
        match self {
            Self::GnssFix(f) => f.stamp.seq,
            Self::PpsEdge(e) => e.stamp.seq,
            Self::Imu(s) => s.stamp.seq,
            Self::Time(t) => t.seq,
            Self::Nav(n) => n.seq,
            Self::Health(h) => h.seq,
            Self::Truth(t) => t.seq,
            Self::TimePulse(t) => t.stamp.seq,
            Self::Event(e) => e.stamp.seq,
            Self::Raw(r) => r.stamp.seq,
            Self::NavData(d) => d.stamp.seq,
            Self::Settings(s) => s.seq,
            Self::NetworkTime(t) => t.seq,
            Self::Sky(s) => s.stamp.seq,
            Self::EventPose(e) => e.seq,
        }
    }

    /// The host time the sample is stamped with, ns (`CLOCK_MONOTONIC`). An event that got
    /// no pose has no host time of its own (`i64::MIN`): its report's host time stands in.
    pub fn host_ns(&self) -> i64 {
        match self {
            Self::GnssFix(f) => f.stamp.host_ns,
            Self::PpsEdge(e) => e.stamp.host_ns,
            Self::Imu(s) => s.stamp.host_ns,
            Self::Time(t) => t.computed_host_ns,
            Self::Nav(n) => n.host_ns,
            Self::Health(h) => h.host_ns,
            Self::Truth(t) => t.host_ns,
            Self::TimePulse(t) => t.stamp.host_ns,
            Self::Event(e) => e.stamp.host_ns,
            Self::Raw(r) => r.stamp.host_ns,
            Self::NavData(d) => d.stamp.host_ns,
            Self::Settings(s) => s.host_ns,
            Self::NetworkTime(t) => t.host_ns,
            Self::Sky(s) => s.stamp.host_ns,
            Self::EventPose(e) if e.host_ns == i64::MIN => e.report_host_ns,
            Self::EventPose(e) => e.host_ns,
        }
    }
}
