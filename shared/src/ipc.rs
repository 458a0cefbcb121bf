//! iceoryx2 plumbing: one node per process, publishers that wake their subscribers,
//! subscribers that can be attached to a `WaitSet`.
//!
//! Every navsync service is a pair: a publish-subscribe service carrying the samples and an
//! event service of the same name. [`Publisher::publish`] writes the sample straight into a
//! shared-memory slot loaned from iceoryx2 and then notifies the event service, so a
//! subscriber sleeping in a [`WaitSet`] wakes up without polling.
//!
//! ```no_run
//! use navsync_shared::{ipc::IpcNode, samples::NavState, services};
//! # fn main() -> Result<(), navsync_shared::ipc::IpcError> {
//! let node = IpcNode::new("my-client")?;
//! let nav = node.subscriber::<NavState>(services::NAV_STATE)?;
//! while let Some(state) = nav.wait_next(std::time::Duration::from_secs(1))? {
//!     println!("lat {} lon {}", state.lat_deg, state.lon_deg);
//! }
//! # Ok(()) }
//! ```

use core::fmt::Debug;
use core::time::Duration;

use core::sync::atomic::{AtomicBool, Ordering};

use iceoryx2::node::NodeWaitFailure;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;

use crate::reflect::Reflect;
use crate::services::{self, MAX_NODES, MAX_PUBLISHERS, MAX_SUBSCRIBERS, ServiceKind};

/// The iceoryx2 service variant navsync uses: inter-process, shared memory.
pub type Transport = ipc::Service;

/// What a navsync service can carry: a reflected, zero-copy sample type (every type of
/// `crate::samples`); for code generic over the sample type without naming iceoryx2.
pub trait IpcSample: Reflect + ZeroCopySend + Debug {}
impl<T: Reflect + ZeroCopySend + Debug> IpcSample for T {}

/// What went wrong in the IPC layer. iceoryx2's own error is kept as text with the
/// service it concerns.
#[derive(Debug, thiserror::Error)]
pub enum IpcError {
    /// An iceoryx2 operation failed.
    #[error("{what} `{service}`: {detail}")]
    Iceoryx {
        /// The operation.
        what: &'static str,
        /// The service or node concerned.
        service: String,
        /// iceoryx2's error.
        detail: String,
    },
    /// A name was not acceptable to iceoryx2.
    #[error("invalid name `{0}`")]
    InvalidName(String),
}

fn err(what: &'static str, service: &str, e: impl Debug) -> IpcError {
    IpcError::Iceoryx {
        what,
        service: service.to_string(),
        detail: format!("{e:?}"),
    }
}

/// The iceoryx2 resource prefix in use: `$NAVSYNC_IPC_PREFIX` or `navsync_`.
pub fn prefix() -> String {
    std::env::var(services::PREFIX_ENV).unwrap_or_else(|_| services::DEFAULT_PREFIX.to_string())
}

/// iceoryx2 configuration with navsync's resource prefix.
pub fn config() -> Result<Config, IpcError> {
    config_with_prefix(&prefix())
}

/// Environment variable naming a dedicated iceoryx2 root directory (default `/tmp/iceoryx2/`);
/// the systemd units use `/run/navsync/iceoryx2/` (README "## Running as a service").
pub const ROOT_ENV: &str = "NAVSYNC_IPC_ROOT";

/// iceoryx2 configuration with an explicit resource prefix.
pub fn config_with_prefix(prefix: &str) -> Result<Config, IpcError> {
    let mut config = Config::default();
    config.global.prefix = FileName::new(prefix.as_bytes()).map_err(|_| IpcError::InvalidName(prefix.to_string()))?;
    if let Ok(root) = std::env::var(ROOT_ENV)
        && !root.is_empty()
    {
        let root = if root.ends_with('/') { root } else { format!("{root}/") };
        config
            .global
            .set_root_path(&Path::new(root.as_bytes()).map_err(|_| IpcError::InvalidName(root.clone()))?);
    }
    Ok(config)
}

/// iceoryx2 creates its per-prefix node counter (`/dev/shm/<prefix>…global_mgmt`) world-
/// writable (0666) on purpose; every other resource is owner-only. Tighten ours to 0660 so
/// that only the owner's group can create nodes under this prefix.
fn restrict_global_segment(prefix: &str) {
    use std::os::unix::fs::{MetadataExt, PermissionsExt};
    let Ok(dir) = std::fs::read_dir("/dev/shm") else { return };
    // SAFETY: geteuid has no preconditions.
    let me = unsafe { libc::geteuid() };
    for e in dir.flatten() {
        let name = e.file_name();
        let name = name.to_string_lossy();
        if name.starts_with(prefix)
            && name.ends_with(".global_mgmt")
            && let Ok(m) = e.metadata()
            && m.uid() == me
            && m.mode() & 0o007 != 0
        {
            let _ = std::fs::set_permissions(e.path(), std::fs::Permissions::from_mode(0o660));
        }
    }
}

/// One process's iceoryx2 node.
pub struct IpcNode {
    node: Node<Transport>,
    /// Latched termination request: iceoryx2 reports (and clears) the signal once, to whichever
    /// wait sees it first; the latch keeps it for every later check.
    terminated: AtomicBool,
}

impl IpcNode {
    /// Creates the node, named after the process role (e.g. `gps-0`). SIGINT and SIGTERM are
    /// turned into a termination request that [`termination_requested`](Self::termination_requested)
    /// and every wait reports.
    pub fn new(process: &str) -> Result<Self, IpcError> {
        Self::with_prefix(process, &prefix())
    }

    /// Like [`new`](Self::new) with an explicit resource prefix instead of `$NAVSYNC_IPC_PREFIX`
    /// (tests that talk to several isolated navsync instances from one process).
    pub fn with_prefix(process: &str, prefix: &str) -> Result<Self, IpcError> {
        let config = config_with_prefix(prefix)?;
        let name = NodeName::new(process).map_err(|_| IpcError::InvalidName(process.to_string()))?;
        let node = NodeBuilder::new()
            .name(&name)
            .config(&config)
            .create::<Transport>()
            .map_err(|e| err("creating node", process, e))?;
        let node = Self {
            node,
            terminated: AtomicBool::new(false),
        };
        // iceoryx2 installs its SIGINT/SIGTERM handler on the first wait; do it now, so a
        // termination request that arrives before the first wait is latched, not fatal.
        node.termination_requested();
        // Reclaim what processes that died without cleaning up (kill -9) left behind.
        node.reclaim_dead_nodes();
        restrict_global_segment(prefix);
        Ok(node)
    }

    /// Removes the resources of every dead node under this prefix (a process that died without
    /// cleaning up, e.g. `kill -9`): its shared memory and files go, and its ports leave every
    /// service, so [`Subscriber::publisher_count`] no longer counts them. Returns how many dead
    /// nodes were reclaimed. Every node does it once when created; it lists every node of the
    /// prefix (directory scans and file reads: a few hundred µs on the 2-core benchmark
    /// machine), so a latency-critical loop leaves it to another thread (the estimator's
    /// reclaimer).
    pub fn reclaim_dead_nodes(&self) -> u64 {
        self.node.try_cleanup_dead_nodes().cleanups
    }

    /// The iceoryx2 node.
    pub fn node(&self) -> &Node<Transport> {
        &self.node
    }

    /// True once SIGINT or SIGTERM was received (latched).
    pub fn termination_requested(&self) -> bool {
        if let Err(NodeWaitFailure::TerminationRequest) = self.node.wait(Duration::ZERO) {
            self.terminated.store(true, Ordering::Relaxed);
        }
        self.terminated.load(Ordering::Relaxed)
    }

    /// Sleeps up to `d` (less when a signal arrives); returns false once termination was requested.
    pub fn sleep(&self, d: Duration) -> bool {
        if let Err(NodeWaitFailure::TerminationRequest) = self.node.wait(d) {
            self.terminated.store(true, Ordering::Relaxed);
        }
        !self.terminated.load(Ordering::Relaxed)
    }

    /// Waits on `waitset` until an attachment fires or `timeout` passes; returns false once
    /// termination was requested.
    pub fn wait_on(&self, waitset: &WaitSet<Transport>, timeout: Duration) -> Result<bool, IpcError> {
        match waitset.wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, timeout) {
            Ok(WaitSetRunResult::TerminationRequest) => self.terminated.store(true, Ordering::Relaxed),
            Ok(_) => {}
            Err(e) => return Err(err("waiting on waitset", "-", e)),
        }
        Ok(!self.termination_requested())
    }

    fn event_service(
        &self,
        service: &str,
    ) -> Result<iceoryx2::service::port_factory::event::PortFactory<Transport>, IpcError> {
        let name: ServiceName = service
            .try_into()
            .map_err(|_| IpcError::InvalidName(service.to_string()))?;
        self.node
            .service_builder(&name)
            .event()
            .max_nodes(MAX_NODES)
            .max_listeners(MAX_SUBSCRIBERS)
            .max_notifiers(MAX_PUBLISHERS)
            .open_or_create()
            .map_err(|e| err("opening event service", service, e))
    }

    fn pubsub_service<T: Reflect + ZeroCopySend + Debug>(
        &self,
        service: &str,
    ) -> Result<iceoryx2::service::port_factory::publish_subscribe::PortFactory<Transport, T, ()>, IpcError> {
        let kind = ServiceKind::of(service).ok_or_else(|| IpcError::InvalidName(service.to_string()))?;
        if kind.type_name() != T::TYPE_NAME {
            return Err(err(
                "opening",
                service,
                format!("carries {}, not {}", kind.type_name(), T::TYPE_NAME),
            ));
        }
        let qos = kind.qos();
        let name: ServiceName = service
            .try_into()
            .map_err(|_| IpcError::InvalidName(service.to_string()))?;
        self.node
            .service_builder(&name)
            .publish_subscribe::<T>()
            .enable_safe_overflow(true)
            .history_size(qos.history)
            .subscriber_max_buffer_size(qos.buffer)
            .subscriber_max_borrowed_samples(4)
            .max_subscribers(MAX_SUBSCRIBERS)
            .max_publishers(MAX_PUBLISHERS)
            .max_nodes(MAX_NODES)
            .open_or_create()
            .map_err(|e| err("opening service", service, e))
    }

    /// A publisher on `service`; the service is created if it does not exist yet.
    pub fn publisher<T: Reflect + ZeroCopySend + Debug>(&self, service: &str) -> Result<Publisher<T>, IpcError> {
        let ps = self.pubsub_service::<T>(service)?;
        let publisher = ps
            .publisher_builder()
            .backpressure_strategy(BackpressureStrategy::DiscardData)
            .create()
            .map_err(|e| err("creating publisher", service, e))?;
        let notifier = self
            .event_service(service)?
            .notifier_builder()
            .create()
            .map_err(|e| err("creating notifier", service, e))?;
        Ok(Publisher {
            publisher,
            notifier,
            service: service.to_string(),
            sent: 0,
        })
    }

    /// A subscriber on `service`; the service is created if it does not exist yet.
    pub fn subscriber<T: Reflect + ZeroCopySend + Debug>(&self, service: &str) -> Result<Subscriber<T>, IpcError> {
        let ps = self.pubsub_service::<T>(service)?;
        let subscriber = ps
            .subscriber_builder()
            .create()
            .map_err(|e| err("creating subscriber", service, e))?;
        let listener = self
            .event_service(service)?
            .listener_builder()
            .create()
            .map_err(|e| err("creating listener", service, e))?;
        Ok(Subscriber {
            subscriber,
            listener,
            service: service.to_string(),
            port_factory: ps,
        })
    }

    /// A WaitSet that returns on SIGINT/SIGTERM.
    pub fn waitset(&self) -> Result<WaitSet<Transport>, IpcError> {
        WaitSetBuilder::new()
            .create::<Transport>()
            .map_err(|e| err("creating waitset", "-", e))
    }
}

/// Publishes samples of one type on one service and wakes its subscribers.
pub struct Publisher<T: Reflect + ZeroCopySend + Debug> {
    publisher: iceoryx2::port::publisher::Publisher<Transport, T, ()>,
    notifier: Notifier<Transport>,
    service: String,
    sent: u64,
}

impl<T: Reflect + ZeroCopySend + Debug> Publisher<T> {
    /// Writes `value` into a loaned shared-memory slot, sends it and notifies listeners.
    /// Never blocks: a subscriber with a full buffer loses its oldest sample.
    pub fn publish(&mut self, value: &T) -> Result<(), IpcError> {
        self.publish_with(|| *value)
    }

    /// Loans a slot in shared memory, then writes `make()` into it and publishes it: what
    /// `make` stamps (e.g. the publish time of a latency probe) is taken with the slot already
    /// in hand, as a zero-copy publisher that fills a loaned slot would.
    pub fn publish_with(&mut self, make: impl FnOnce() -> T) -> Result<(), IpcError> {
        let slot = self
            .publisher
            .loan_uninit()
            .map_err(|e| err("loaning sample on", &self.service, e))?;
        slot.write_payload(make())
            .send()
            .map_err(|e| err("sending on", &self.service, e))?;
        self.notifier
            .notify()
            .map_err(|e| err("notifying on", &self.service, e))?;
        self.sent += 1;
        Ok(())
    }

    /// Samples published so far.
    pub fn sent(&self) -> u64 {
        self.sent
    }

    /// The service name.
    pub fn service(&self) -> &str {
        &self.service
    }
}

/// Receives samples of one type from one service.
pub struct Subscriber<T: Reflect + ZeroCopySend + Debug> {
    subscriber: iceoryx2::port::subscriber::Subscriber<Transport, T, ()>,
    listener: Listener<Transport>,
    service: String,
    port_factory: iceoryx2::service::port_factory::publish_subscribe::PortFactory<Transport, T, ()>,
}

impl<T: Reflect + ZeroCopySend + Debug> Subscriber<T> {
    /// The next buffered sample (copied out of shared memory), if any.
    pub fn receive(&self) -> Result<Option<T>, IpcError> {
        match self.subscriber.receive() {
            Ok(Some(sample)) => Ok(Some(*sample.payload())),
            Ok(None) => Ok(None),
            Err(e) => Err(err("receiving from", &self.service, e)),
        }
    }

    /// Calls `f` with a reference into shared memory for every buffered sample (zero copy).
    pub fn for_each(&self, mut f: impl FnMut(&T)) -> Result<usize, IpcError> {
        let mut n = 0;
        while let Some(sample) = self
            .subscriber
            .receive()
            .map_err(|e| err("receiving from", &self.service, e))?
        {
            f(sample.payload());
            n += 1;
        }
        Ok(n)
    }

    /// After a wake-up: hands every buffered sample to `f` (by value), consumes the wake-up
    /// events, then hands over what arrived meanwhile. Samples before events, so the first
    /// sample is in hand right after the wake-up, with no event syscalls in between; a sample
    /// published while the events were consumed is not left waiting for the next wake-up.
    /// `f` returns false to stop early (the events are then left for the next wait).
    pub fn drain(&self, mut f: impl FnMut(T) -> bool) -> Result<usize, IpcError> {
        let mut n = 0;
        for clear in [true, false] {
            while let Some(s) = self.receive()? {
                n += 1;
                if !f(s) {
                    return Ok(n);
                }
            }
            if clear {
                self.clear_events();
            }
        }
        Ok(n)
    }

    /// Consumes pending wake-up events. After a wake-up, [`drain`](Self::drain) calls it
    /// between taking the samples, which keeps it off the wake-up path.
    pub fn clear_events(&self) {
        let _ = self.listener.try_wait(|_| {});
    }

    /// Blocks until a sample is available or `timeout` passes; `Ok(None)` on timeout, or
    /// earlier when a signal interrupts the wait: a termination request (the caller checks
    /// [`IpcNode::termination_requested`]) or SIGCONT after the process was stopped, which must
    /// not end a subscriber.
    ///
    /// Waits with `poll(2)` on the listener's descriptor and takes the sample as soon as it
    /// returns; the wake-up events are consumed on the next call, before looking again, so
    /// the path from the publisher's signal to the sample in hand has no syscall besides the
    /// wait itself (iceoryx2's own `timed_wait` consumes them first: `fcntl`, `recvfrom`,
    /// `fcntl`). A sample published after that look signals after the events were consumed,
    /// so none is left waiting.
    pub fn wait_next(&self, timeout: Duration) -> Result<Option<T>, IpcError> {
        if let Some(s) = self.receive()? {
            return Ok(Some(s));
        }
        let deadline = std::time::Instant::now() + timeout;
        loop {
            self.clear_events();
            if let Some(s) = self.receive()? {
                return Ok(Some(s));
            }
            let now = std::time::Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            let ms = (deadline - now).as_micros().div_ceil(1000).min(i32::MAX as u128) as i32;
            let mut pfd = libc::pollfd {
                fd: self.wake_fd(),
                events: libc::POLLIN,
                revents: 0,
            };
            // SAFETY: one valid pollfd for the call's duration.
            if unsafe { libc::poll(&mut pfd, 1, ms) } < 0 {
                let e = std::io::Error::last_os_error();
                if e.kind() == std::io::ErrorKind::Interrupted {
                    return self.receive();
                }
                return Err(err("waiting on", &self.service, e));
            }
            if let Some(s) = self.receive()? {
                return Ok(Some(s));
            }
        }
    }

    /// Publishers on the service now. A publisher whose process was killed is counted until
    /// some node reclaims the dead node ([`IpcNode::reclaim_dead_nodes`]).
    pub fn publisher_count(&self) -> usize {
        self.port_factory.dynamic_config().number_of_publishers()
    }

    /// The file descriptor that becomes readable when a publisher signals a new sample, for a
    /// `poll(2)` loop that also waits on sockets; after it fired, [`drain`](Self::drain) (or
    /// [`clear_events`](Self::clear_events)) consumes the signal.
    pub fn wake_fd(&self) -> std::os::fd::RawFd {
        // SAFETY: the descriptor is only read (polled), never closed; it lives as long as the
        // listener, which `self` owns.
        unsafe { self.listener.file_descriptor().native_handle() }
    }

    /// The listener to attach to a WaitSet.
    pub fn listener(&self) -> &Listener<Transport> {
        &self.listener
    }

    /// The service name.
    pub fn service(&self) -> &str {
        &self.service
    }
}

/// Names of the navsync services that currently exist under this prefix (pub-sub only).
pub fn list_services() -> Result<Vec<String>, IpcError> {
    let config = config()?;
    let mut names = Vec::new();
    Transport::list(&config, |s| {
        if matches!(
            s.static_details.messaging_pattern(),
            iceoryx2::service::static_config::messaging_pattern::MessagingPattern::PublishSubscribe(_)
        ) {
            names.push(s.static_details.name().as_str().to_string());
        }
        CallbackProgression::Continue
    })
    .map_err(|e| err("listing services", "-", e))?;
    names.sort();
    names.dedup();
    Ok(names)
}
