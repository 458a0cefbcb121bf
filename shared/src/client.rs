//! A small client API for programs that consume navsync's output: subscribe to the navigation
//! state (or any sensor or state service) in a few lines, wait for the next sample with a
//! timeout, and ask for the latest one no older than a given age.
//!
//! ```no_run
//! use std::time::Duration;
//! use navsync_shared::client::NavClient;
//!
//! # fn main() -> Result<(), navsync_shared::client::ClientError> {
//! let mut nav = NavClient::connect()?;
//! // Block until the next state arrives (at most 1 s).
//! if let Some(s) = nav.next(Duration::from_secs(1))? {
//!     println!("{:.7} {:.7} {:.2} m", s.lat_deg, s.lon_deg, s.height_m);
//! }
//! // The newest state, only if it is less than 50 ms old (host clock); None when stale.
//! match nav.latest(Duration::from_millis(50))? {
//!     Some(s) => println!("yaw {:.2}°", s.rpy_rad[2].to_degrees()),
//!     None => eprintln!("no fresh navigation state"),
//! }
//! # Ok(()) }
//! ```
//!
//! Any other service works the same way with [`Client`] and the service's sample type:
//!
//! ```no_run
//! use std::time::Duration;
//! use navsync_shared::{client::Client, samples::ImuSample, services};
//!
//! # fn main() -> Result<(), navsync_shared::client::ClientError> {
//! let mut imu = Client::<ImuSample>::connect_to(&services::imu_sample("0"))?;
//! while let Some(s) = imu.next(Duration::from_secs(1))? {
//!     println!("{} {:?}", s.stamp.host_ns, s.gyro_rps);
//! }
//! # Ok(()) }
//! ```
//!
//! The client joins the navsync instance named by `$NAVSYNC_IPC_PREFIX` (default `navsync_`),
//! like every navsync process. Ages are measured on the host's `CLOCK_MONOTONIC`, the clock
//! every navsync time stamp is on. Creating a client installs iceoryx2's SIGINT/SIGTERM
//! handler for the process ([`Client::termination_requested`] reports the signal; waits
//! return early).
//!
//! A complete program: `shared/examples/nav_subscriber.rs`
//! (`cargo run -p navsync-shared --example nav_subscriber`).

use core::fmt::Debug;
use core::time::Duration;

use crate::ipc::{IpcError, IpcNode, IpcSample, Subscriber};
use crate::samples::{GnssFix, Health, ImuSample, NavState, PpsEdge, SimTruth, TimeState};
use crate::services::{self, ServiceKind};
use crate::time::monotonic_now_ns;

/// What went wrong in a client.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The service name is not a navsync service, or carries another type.
    #[error("`{service}` does not carry {wanted} (expected e.g. navsync/nav/state, navsync/imu/0/sample)")]
    WrongService {
        /// The service asked for.
        service: String,
        /// The type name of the client.
        wanted: &'static str,
    },
    /// iceoryx2 failed.
    #[error(transparent)]
    Ipc(#[from] IpcError),
}

/// A sample type with a host time stamp (`CLOCK_MONOTONIC` ns), for staleness checks.
pub trait Stamped: IpcSample {
    /// The host time the sample is for, ns.
    fn host_ns(&self) -> i64;
}

impl Stamped for NavState {
    fn host_ns(&self) -> i64 {
        self.host_ns
    }
}
impl Stamped for TimeState {
    fn host_ns(&self) -> i64 {
        self.computed_host_ns
    }
}
impl Stamped for ImuSample {
    fn host_ns(&self) -> i64 {
        self.stamp.host_ns
    }
}
impl Stamped for GnssFix {
    fn host_ns(&self) -> i64 {
        self.stamp.host_ns
    }
}
impl Stamped for PpsEdge {
    fn host_ns(&self) -> i64 {
        self.stamp.host_ns
    }
}
impl Stamped for Health {
    fn host_ns(&self) -> i64 {
        self.host_ns
    }
}
impl Stamped for SimTruth {
    fn host_ns(&self) -> i64 {
        self.host_ns
    }
}

/// A subscription to one navsync service with its own iceoryx2 node.
pub struct Client<T: Stamped> {
    // Field order: the subscriber is dropped before its node.
    sub: Subscriber<T>,
    node: IpcNode,
    latest: Option<T>,
    received: u64,
}

/// A client of `navsync/nav/state`.
pub type NavClient = Client<NavState>;
/// A client of `navsync/time/state`.
pub type TimeClient = Client<TimeState>;

impl Client<NavState> {
    /// Subscribes to the navigation state, `navsync/nav/state`.
    pub fn connect() -> Result<Self, ClientError> {
        Self::connect_to(services::NAV_STATE)
    }
}

impl Client<TimeState> {
    /// Subscribes to the time mapping, `navsync/time/state`.
    pub fn connect_time() -> Result<Self, ClientError> {
        Self::connect_to(services::TIME_STATE)
    }
}

impl<T: Stamped> Client<T> {
    /// Subscribes to `service`, which must carry `T` (e.g. `navsync/imu/0/sample` for
    /// [`ImuSample`]). The service need not exist yet: samples flow once its publisher starts.
    pub fn connect_to(service: &str) -> Result<Self, ClientError> {
        let node = IpcNode::new(&format!("client-{}", std::process::id()))?;
        Self::with_node(node, service)
    }

    /// Like [`connect_to`](Self::connect_to) with a node of the caller's (its own name or
    /// resource prefix, e.g. [`IpcNode::with_prefix`]).
    pub fn with_node(node: IpcNode, service: &str) -> Result<Self, ClientError> {
        if ServiceKind::of(service).is_none_or(|k| k.type_name() != T::TYPE_NAME) {
            return Err(ClientError::WrongService {
                service: service.to_string(),
                wanted: T::TYPE_NAME,
            });
        }
        let sub = node.subscriber::<T>(service)?;
        Ok(Self {
            sub,
            node,
            latest: None,
            received: 0,
        })
    }

    fn take(&mut self, s: T) -> T {
        self.latest = Some(s);
        self.received += 1;
        s
    }

    /// Busy polling: [`next`](Self::next) spins instead of sleeping (lowest latency, a whole
    /// core; for a subscriber on an isolated core). Off by default.
    pub fn set_busy_poll(&self, on: bool) {
        self.sub.set_busy_poll(on);
    }

    /// The next sample in arrival order, waiting up to `timeout`; `None` on timeout or when
    /// SIGINT/SIGTERM arrived. Samples are buffered between calls (up to the service's buffer,
    /// oldest lost first), so a loop over `next` sees every sample of a steady stream.
    pub fn next(&mut self, timeout: Duration) -> Result<Option<T>, ClientError> {
        if self.node.termination_requested() {
            return Ok(None);
        }
        Ok(self.sub.wait_next(timeout)?.map(|s| self.take(s)))
    }

    /// The next buffered sample without waiting.
    pub fn try_next(&mut self) -> Result<Option<T>, ClientError> {
        Ok(self.sub.receive()?.map(|s| self.take(s)))
    }

    /// Drains the buffer and returns the newest sample received so far with its age on the
    /// host clock (negative when stamped in the future, e.g. replayed), or `None` before the
    /// first one.
    pub fn latest_with_age(&mut self) -> Result<Option<(T, Duration)>, ClientError> {
        while self.try_next()?.is_some() {}
        Ok(self.latest.map(|s| {
            let age_ns = monotonic_now_ns().saturating_sub(s.host_ns()).max(0);
            (s, Duration::from_nanos(age_ns as u64))
        }))
    }

    /// The newest sample if it is at most `max_age` old (by its host time stamp); `None` when
    /// there is none or it is stale.
    pub fn latest(&mut self, max_age: Duration) -> Result<Option<T>, ClientError> {
        Ok(self
            .latest_with_age()?
            .and_then(|(s, age)| (age <= max_age).then_some(s)))
    }

    /// Waits up to `timeout` for a sample at most `max_age` old: the latest one if it is fresh,
    /// else the next to arrive that is.
    pub fn wait_fresh(&mut self, max_age: Duration, timeout: Duration) -> Result<Option<T>, ClientError> {
        let deadline = std::time::Instant::now() + timeout;
        if let Some(s) = self.latest(max_age)? {
            return Ok(Some(s));
        }
        loop {
            let now = std::time::Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            match self.next(deadline - now)? {
                Some(s) if monotonic_now_ns().saturating_sub(s.host_ns()) <= max_age.as_nanos() as i64 => {
                    return Ok(Some(s));
                }
                Some(_) => {}
                None => return Ok(None),
            }
        }
    }

    /// Samples received so far.
    pub fn received(&self) -> u64 {
        self.received
    }

    /// The service name.
    pub fn service(&self) -> &str {
        self.sub.service()
    }

    /// True once SIGINT or SIGTERM was received.
    pub fn termination_requested(&self) -> bool {
        self.node.termination_requested()
    }

    /// The underlying node (to open further subscribers on it).
    pub fn node(&self) -> &IpcNode {
        &self.node
    }
}
