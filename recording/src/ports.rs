//! Publishers and subscribers for any navsync service, typed by the service's name: what a
//! recorder subscribes with and a replayer publishes with.

use super::channels::SampleType;
use navsync_shared::ipc::{IpcError, IpcNode, Publisher, Subscriber};
use navsync_shared::samples::AnySample;
use navsync_shared::services::ServiceKind;

/// A subscriber of whatever type the service carries.
pub enum AnySubscriber {
    /// `navsync/gnss/{id}/fix`
    GnssFix(Subscriber<navsync_shared::samples::GnssFix>),
    /// `navsync/pps/{id}/edge`, `navsync/sim/pps`
    PpsEdge(Subscriber<navsync_shared::samples::PpsEdge>),
    /// `navsync/imu/{id}/sample`
    Imu(Subscriber<navsync_shared::samples::ImuSample>),
    /// `navsync/time/state`
    Time(Subscriber<navsync_shared::samples::TimeState>),
    /// `navsync/nav/state`
    Nav(Subscriber<navsync_shared::samples::NavState>),
    /// `navsync/health/{process}`
    Health(Subscriber<navsync_shared::samples::Health>),
    /// `navsync/sim/truth`
    Truth(Subscriber<navsync_shared::samples::SimTruth>),
    /// `navsync/gnss/{id}/timepulse`
    TimePulse(Subscriber<navsync_shared::samples::GnssTimePulse>),
    /// `navsync/gnss/{id}/event`
    Event(Subscriber<navsync_shared::samples::GnssEvent>),
    /// `navsync/gnss/{id}/raw`
    Raw(Subscriber<navsync_shared::samples::GnssRaw>),
    /// `navsync/gnss/{id}/nav-data`
    NavData(Subscriber<navsync_shared::samples::GnssNavData>),
    /// `navsync/estimator/settings`
    Settings(Subscriber<navsync_shared::samples::EstimatorSettings>),
    /// `navsync/time/network`
    NetworkTime(Subscriber<navsync_shared::samples::NetworkTime>),
    /// `navsync/gnss/{id}/sky`
    Sky(Subscriber<navsync_shared::samples::GnssSky>),
    /// `navsync/event/{id}/pose`
    EventPose(Subscriber<navsync_shared::samples::EventPose>),
}

macro_rules! each_subscriber {
    ($self:expr, $s:ident => $body:expr) => {
        match $self {
            AnySubscriber::GnssFix($s) => $body,
            AnySubscriber::PpsEdge($s) => $body,
            AnySubscriber::Imu($s) => $body,
            AnySubscriber::Time($s) => $body,
            AnySubscriber::Nav($s) => $body,
            AnySubscriber::Health($s) => $body,
            AnySubscriber::Truth($s) => $body,
            AnySubscriber::TimePulse($s) => $body,
            AnySubscriber::Event($s) => $body,
            AnySubscriber::Raw($s) => $body,
            AnySubscriber::NavData($s) => $body,
            AnySubscriber::Settings($s) => $body,
            AnySubscriber::NetworkTime($s) => $body,
            AnySubscriber::Sky($s) => $body,
            AnySubscriber::EventPose($s) => $body,
        }
    };
}

fn unknown(service: &str) -> IpcError {
    IpcError::InvalidName(format!("{service} (not a navsync service)"))
}

impl AnySubscriber {
    /// Subscribes to `service` (creating it if it does not exist yet) as one of the inputs of
    /// a process that sleeps on its `ipc::Wake`.
    pub fn open(node: &IpcNode, service: &str) -> Result<Self, IpcError> {
        Ok(match ServiceKind::of(service).ok_or_else(|| unknown(service))? {
            ServiceKind::GnssFix => Self::GnssFix(node.input(service)?),
            ServiceKind::PpsEdge => Self::PpsEdge(node.input(service)?),
            ServiceKind::ImuSample => Self::Imu(node.input(service)?),
            ServiceKind::TimeState => Self::Time(node.input(service)?),
            ServiceKind::NavState => Self::Nav(node.input(service)?),
            ServiceKind::Health => Self::Health(node.input(service)?),
            ServiceKind::SimTruth => Self::Truth(node.input(service)?),
            ServiceKind::GnssTimePulse => Self::TimePulse(node.input(service)?),
            ServiceKind::GnssEvent => Self::Event(node.input(service)?),
            ServiceKind::GnssRaw => Self::Raw(node.input(service)?),
            ServiceKind::GnssNavData => Self::NavData(node.input(service)?),
            ServiceKind::EstimatorSettings => Self::Settings(node.input(service)?),
            ServiceKind::NetworkTime => Self::NetworkTime(node.input(service)?),
            ServiceKind::GnssSky => Self::Sky(node.input(service)?),
            ServiceKind::EventPose => Self::EventPose(node.input(service)?),
        })
    }

    /// The service name.
    pub fn service(&self) -> &str {
        each_subscriber!(self, s => s.service())
    }

    /// Calls `f` with every buffered sample (copied out of shared memory); returns how many.
    pub fn drain(&self, mut f: impl FnMut(AnySample)) -> Result<usize, IpcError> {
        each_subscriber!(self, s => s.for_each(|x| f(SampleType::wrap(*x))))
    }
}

/// A publisher of whatever type the service carries.
pub enum AnyPublisher {
    /// `navsync/gnss/{id}/fix`
    GnssFix(Publisher<navsync_shared::samples::GnssFix>),
    /// `navsync/pps/{id}/edge`, `navsync/sim/pps`
    PpsEdge(Publisher<navsync_shared::samples::PpsEdge>),
    /// `navsync/imu/{id}/sample`
    Imu(Publisher<navsync_shared::samples::ImuSample>),
    /// `navsync/time/state`
    Time(Publisher<navsync_shared::samples::TimeState>),
    /// `navsync/nav/state`
    Nav(Publisher<navsync_shared::samples::NavState>),
    /// `navsync/health/{process}`
    Health(Publisher<navsync_shared::samples::Health>),
    /// `navsync/sim/truth`
    Truth(Publisher<navsync_shared::samples::SimTruth>),
    /// `navsync/gnss/{id}/timepulse`
    TimePulse(Publisher<navsync_shared::samples::GnssTimePulse>),
    /// `navsync/gnss/{id}/event`
    Event(Publisher<navsync_shared::samples::GnssEvent>),
    /// `navsync/gnss/{id}/raw`
    Raw(Publisher<navsync_shared::samples::GnssRaw>),
    /// `navsync/gnss/{id}/nav-data`
    NavData(Publisher<navsync_shared::samples::GnssNavData>),
    /// `navsync/estimator/settings`
    Settings(Publisher<navsync_shared::samples::EstimatorSettings>),
    /// `navsync/time/network`
    NetworkTime(Publisher<navsync_shared::samples::NetworkTime>),
    /// `navsync/gnss/{id}/sky`
    Sky(Publisher<navsync_shared::samples::GnssSky>),
    /// `navsync/event/{id}/pose`
    EventPose(Publisher<navsync_shared::samples::EventPose>),
}

impl AnyPublisher {
    /// A publisher on `service` (creating the service if it does not exist yet).
    pub fn open(node: &IpcNode, service: &str) -> Result<Self, IpcError> {
        Ok(match ServiceKind::of(service).ok_or_else(|| unknown(service))? {
            ServiceKind::GnssFix => Self::GnssFix(node.publisher(service)?),
            ServiceKind::PpsEdge => Self::PpsEdge(node.publisher(service)?),
            ServiceKind::ImuSample => Self::Imu(node.publisher(service)?),
            ServiceKind::TimeState => Self::Time(node.publisher(service)?),
            ServiceKind::NavState => Self::Nav(node.publisher(service)?),
            ServiceKind::Health => Self::Health(node.publisher(service)?),
            ServiceKind::SimTruth => Self::Truth(node.publisher(service)?),
            ServiceKind::GnssTimePulse => Self::TimePulse(node.publisher(service)?),
            ServiceKind::GnssEvent => Self::Event(node.publisher(service)?),
            ServiceKind::GnssRaw => Self::Raw(node.publisher(service)?),
            ServiceKind::GnssNavData => Self::NavData(node.publisher(service)?),
            ServiceKind::EstimatorSettings => Self::Settings(node.publisher(service)?),
            ServiceKind::NetworkTime => Self::NetworkTime(node.publisher(service)?),
            ServiceKind::GnssSky => Self::Sky(node.publisher(service)?),
            ServiceKind::EventPose => Self::EventPose(node.publisher(service)?),
        })
    }

    /// Publishes `sample`, which must be of the service's type.
    pub fn publish(&mut self, sample: &AnySample) -> Result<(), IpcError> {
        match self {
            Self::GnssFix(p) => pub_as(p, sample),
            Self::PpsEdge(p) => pub_as(p, sample),
            Self::Imu(p) => pub_as(p, sample),
            Self::Time(p) => pub_as(p, sample),
            Self::Nav(p) => pub_as(p, sample),
            Self::Health(p) => pub_as(p, sample),
            Self::Truth(p) => pub_as(p, sample),
            Self::TimePulse(p) => pub_as(p, sample),
            Self::Event(p) => pub_as(p, sample),
            Self::Raw(p) => pub_as(p, sample),
            Self::NavData(p) => pub_as(p, sample),
            Self::Settings(p) => pub_as(p, sample),
            Self::NetworkTime(p) => pub_as(p, sample),
            Self::Sky(p) => pub_as(p, sample),
            Self::EventPose(p) => pub_as(p, sample),
        }
    }
}

fn pub_as<T: SampleType>(p: &mut Publisher<T>, sample: &AnySample) -> Result<(), IpcError> {
    match T::unwrap(sample) {
        Some(x) => p.publish(x),
        None => Err(IpcError::Iceoryx {
            what: "publishing",
            service: p.service().to_string(),
            detail: format!(
                "a {:?} sample on a {:?} service",
                ServiceKind::of_sample(sample),
                T::KIND
            ),
        }),
    }
}
