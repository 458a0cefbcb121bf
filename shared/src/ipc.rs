//! iceoryx2 plumbing: one node per process, publishers that wake their subscribers,
//! subscribers that sleep until a sample arrives, one wake-up for a process with many inputs.
//!
//! Every navsync service is a pair: a publish-subscribe service carrying the samples and an
//! event service of the same name. [`Publisher::publish`] writes the sample straight into a
//! shared-memory slot loaned from iceoryx2, then notifies the event service (a subscriber
//! asleep in [`Subscriber::wait_next`] wakes) and the wake-up event [`services::WAKE`] with
//! the sample's kind: a process with many inputs (the estimator, the recorder, the bridge)
//! sleeps on that one event ([`Wake`], [`IpcNode::wait`]) and drains its inputs when it fires.
//! Events use navsync's own iceoryx2 service type, a futex in shared memory instead of a
//! Unix datagram ([`futex`]): a wake-up is one `FUTEX_WAKE`, and none while the listener is
//! awake.
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

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use iceoryx2_bb_posix::signal::SignalHandler;
use iceoryx2_cal::event::ListenerWaitError;

use crate::reflect::Reflect;
use crate::services::{self, MAX_NODES, MAX_PUBLISHERS, MAX_SUBSCRIBERS, ServiceKind};

pub mod futex;
pub mod pooled;

/// The iceoryx2 service type navsync uses: inter-process, shared memory, futex wake-ups
/// ([`futex::Service`]).
pub type Transport = futex::Service;

/// iceoryx2's stock inter-process service type (Unix-datagram events): the wake-up of programs
/// built on iceoryx2's own service types, which cannot load navsync's futex trigger (the
/// `iceoryx2` Python package). Publishers of [`services::has_stock_wake`] kinds also notify the
/// stock event [`services::stock_wake`] of their service; with no listener that costs no
/// system call.
pub type StockTransport = iceoryx2::service::ipc::Service;

/// The longest a timed wait sleeps before it looks at the termination latch again: a
/// SIGINT/SIGTERM reaches one thread of the process, not necessarily the waiting one, and
/// iceoryx2's handler only records it, so a termination request is noticed within this time.
/// (Waits registered as sleepers, untimed ones and those of at least [`futex::ALARM_MIN`]
/// where navsync's handler is chained in front, [`futex::termination_wakes_sleepers`], are
/// woken by it at once; the slice bounds the others.)
pub const WAIT_SLICE: Duration = Duration::from_millis(50);

/// How many polls a busy wait makes between looks at the clock and the termination latch.
const BUSY_CHECK_EVERY: u32 = 256;

/// Process-wide latch of a termination request, sticky: set by navsync's own SIGINT/SIGTERM
/// handler ([`futex::termination_wakes_sleepers`], installed in front of iceoryx2's when a node
/// is created) and never cleared. iceoryx2 0.10 keeps only the last signal it caught, SIGCONT
/// included, so a SIGCONT right after the SIGTERM (what `systemctl stop` and `timeout` send)
/// overwrote the request there: the waits had seen it and returned at once, the loops asked
/// iceoryx2, heard "no" and spun at 100 % CPU, never exiting.
pub(crate) static TERMINATED: AtomicBool = AtomicBool::new(false);

/// True once SIGINT or SIGTERM was received (latched, whatever signal came after; an atomic
/// load, no system call, once a node installed navsync's handler).
pub fn termination_requested() -> bool {
    if TERMINATED.load(Ordering::SeqCst) {
        return true;
    }
    // Before navsync's handler is installed (or if it could not be), iceoryx2's record.
    if !futex::handler_installed() && SignalHandler::termination_requested() {
        TERMINATED.store(true, Ordering::SeqCst);
    }
    TERMINATED.load(Ordering::SeqCst)
}

/// What a navsync service can carry: a reflected sample type (every type of
/// `crate::samples`: `#[repr(C)]`, plain numbers, no pointers).
pub trait IpcSample: Reflect + Copy + Debug {}
impl<T: Reflect + Copy + Debug> IpcSample for T {}

/// A sample as iceoryx2 carries it: the sample itself, under the type name of its field table
/// ([`Reflect::TYPE_NAME`], the layout version included), which is how iceoryx2 and the
/// other languages' bindings identify a service's type.
#[derive(Debug, Clone, Copy)]
#[repr(transparent)]
pub struct Wire<T>(pub T);

// SAFETY: every `Reflect` type is a `#[repr(C)]` struct of integers, floats and arrays of them
// (`sample_struct!`, checked field by field by `Reflect::FIELDS` and the layout test): it holds
// no pointer and is valid in any process that maps it. `Wire` is `repr(transparent)`, so its
// layout is the sample's; the type name carries the layout version.
unsafe impl<T: IpcSample> ZeroCopySend for Wire<T> {
    unsafe fn type_name() -> &'static str {
        T::TYPE_NAME
    }
}

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
    /// iceoryx2's root directory is not safe to use ([`root_dir`]); the error names it.
    #[error(transparent)]
    RuntimeDir(#[from] crate::runtime_dir::RuntimeDirError),
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

/// Environment variable naming a dedicated iceoryx2 root directory; the systemd units use
/// `/run/navsync/iceoryx2/` (README "## Running as a service"). See [`root_dir`].
pub const ROOT_ENV: &str = "NAVSYNC_IPC_ROOT";

/// iceoryx2's root directory (its service and node files; the shared memory itself is in
/// `/dev/shm`): `$NAVSYNC_IPC_ROOT`, else `iceoryx2` in systemd's `$RUNTIME_DIRECTORY`, else
/// `navsync/iceoryx2` in `$XDG_RUNTIME_DIR`, else iceoryx2's own default `/tmp/iceoryx2`
/// (where programs on stock iceoryx2 settings, such as the Python package, meet navsync).
/// Whichever it is, it is created owner-only or checked before use
/// ([`crate::runtime_dir::ensure`]): one that another user owns or may write into is refused.
pub fn root_dir() -> std::path::PathBuf {
    use std::path::PathBuf;
    let var = |k: &str| std::env::var_os(k).filter(|v| !v.is_empty()).map(PathBuf::from);
    if let Some(root) = var(ROOT_ENV) {
        return root;
    }
    if let Some(d) = var("RUNTIME_DIRECTORY") {
        return crate::runtime_dir::base_from(Some(d), None, 0).join("iceoryx2");
    }
    if let Some(x) = var("XDG_RUNTIME_DIR").filter(|x| x.is_absolute()) {
        return x.join("navsync").join("iceoryx2");
    }
    PathBuf::from("/tmp/iceoryx2")
}

/// Where [`root_dir`] comes from, for its errors.
const ROOT_HINT: &str = "set $NAVSYNC_IPC_ROOT, $XDG_RUNTIME_DIR or $RUNTIME_DIRECTORY to a directory of your own";

/// iceoryx2 configuration with an explicit resource prefix, in the checked [`root_dir`].
pub fn config_with_prefix(prefix: &str) -> Result<Config, IpcError> {
    let mut config = Config::default();
    config.global.prefix = FileName::new(prefix.as_bytes()).map_err(|_| IpcError::InvalidName(prefix.to_string()))?;
    let root = crate::runtime_dir::ensure(&root_dir(), ROOT_HINT)?;
    let mut root = root.display().to_string();
    if !root.ends_with('/') {
        root.push('/');
    }
    config
        .global
        .set_root_path(&Path::new(root.as_bytes()).map_err(|_| IpcError::InvalidName(root.clone()))?);
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
    config: Config,
    name: String,
    /// A node of [`StockTransport`], made with the first publisher that needs one.
    stock: core::cell::OnceCell<Node<StockTransport>>,
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
        // iceoryx2's SIGINT/SIGTERM handler (installed on its first look) and navsync's in
        // front of it, before the node exists: a termination request from here on is latched,
        // neither fatal (a process killed by the signal would leave its node's files to the
        // dead-node reclaim) nor undone by a later signal.
        futex::termination_wakes_sleepers();
        let config = config_with_prefix(prefix)?;
        let name = NodeName::new(process).map_err(|_| IpcError::InvalidName(process.to_string()))?;
        let node = NodeBuilder::new()
            .name(&name)
            .config(&config)
            .create::<Transport>()
            .map_err(|e| err("creating node", process, e))?;
        let node = Self {
            node,
            config,
            name: process.to_string(),
            stock: core::cell::OnceCell::new(),
        };
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

    /// True once SIGINT or SIGTERM was received (latched; see [`termination_requested`]).
    pub fn termination_requested(&self) -> bool {
        termination_requested()
    }

    /// Sleeps up to `d` (less when a signal arrives); returns false once termination was requested.
    pub fn sleep(&self, d: Duration) -> bool {
        // iceoryx2 reports (and clears) the signal to this wait: latch it.
        if let Err(iceoryx2::node::NodeWaitFailure::TerminationRequest) = self.node.wait(d) {
            TERMINATED.store(true, Ordering::Relaxed);
        }
        !termination_requested()
    }

    /// Sleeps on `wake` until a sample of any kind is published under this prefix or `timeout`
    /// passes; returns false once termination was requested. What fired is in
    /// [`Wake::fired`]; the caller drains its inputs (a wake-up can stand for several samples,
    /// and samples published while the caller was awake wake it at once next time).
    pub fn wait(&self, wake: &Wake, timeout: Duration) -> Result<bool, IpcError> {
        let deadline = std::time::Instant::now() + timeout;
        let mut fired = 0u32;
        if wake.busy.get() {
            let mut spins = 0u32;
            loop {
                match wake.listener.try_wait(|a| fired |= 1 << a.id.as_value().min(31)) {
                    Ok(_) | Err(ListenerWaitError::InterruptSignal) => {}
                    Err(e) => return Err(err("polling", services::WAKE, e)),
                }
                if fired != 0 {
                    wake.fired.set(fired);
                    return Ok(true);
                }
                spins = spins.wrapping_add(1);
                if spins.is_multiple_of(BUSY_CHECK_EVERY) {
                    if termination_requested() {
                        return Ok(false);
                    }
                    if std::time::Instant::now() >= deadline {
                        wake.fired.set(0);
                        return Ok(true);
                    }
                }
                core::hint::spin_loop();
            }
        }
        loop {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            match wake
                .listener
                .timed_wait(|a| fired |= 1 << a.id.as_value().min(31), left.min(WAIT_SLICE))
            {
                Ok(_) | Err(ListenerWaitError::InterruptSignal) => {}
                Err(e) => return Err(err("waiting on", services::WAKE, e)),
            }
            if termination_requested() {
                return Ok(false);
            }
            if fired != 0 || left <= WAIT_SLICE {
                wake.fired.set(fired);
                return Ok(true);
            }
        }
    }

    /// The wake-up of a process with many inputs: a listener on [`services::WAKE`], which every
    /// navsync publisher notifies after publishing, with its kind as the event id. Subscribe
    /// to the inputs with [`input`](Self::input), wait with [`wait`](Self::wait).
    pub fn wake(&self) -> Result<Wake, IpcError> {
        let listener = self
            .wake_service()?
            .listener_builder()
            .create()
            .map_err(|e| err("creating listener", services::WAKE, e))?;
        Ok(Wake {
            listener,
            fired: core::cell::Cell::new(0),
            busy: core::cell::Cell::new(false),
        })
    }

    fn wake_service(&self) -> Result<iceoryx2::service::port_factory::event::PortFactory<Transport>, IpcError> {
        let name: ServiceName = services::WAKE
            .try_into()
            .map_err(|_| IpcError::InvalidName(services::WAKE.to_string()))?;
        self.node
            .service_builder(&name)
            .event()
            .max_nodes(services::MAX_WAKE_NODES)
            .max_listeners(MAX_SUBSCRIBERS)
            .max_notifiers(services::MAX_WAKE_NOTIFIERS)
            .event_id_max_value(ServiceKind::ALL.len())
            .open_or_create()
            .map_err(|e| err("opening event service", services::WAKE, e))
    }

    fn stock_notifier(&self, service: &str) -> Result<Notifier<StockTransport>, IpcError> {
        if self.stock.get().is_none() {
            let name = NodeName::new(&self.name).map_err(|_| IpcError::InvalidName(self.name.clone()))?;
            let node = NodeBuilder::new()
                .name(&name)
                .config(&self.config)
                .create::<StockTransport>()
                .map_err(|e| err("creating node", &self.name, e))?;
            let _ = self.stock.set(node);
        }
        let Some(node) = self.stock.get() else {
            return Err(err("creating node", &self.name, "stock node missing"));
        };
        let event = services::stock_wake(service);
        let name: ServiceName = event
            .as_str()
            .try_into()
            .map_err(|_| IpcError::InvalidName(event.clone()))?;
        node.service_builder(&name)
            .event()
            .max_nodes(MAX_NODES)
            .max_listeners(MAX_SUBSCRIBERS)
            .max_notifiers(MAX_PUBLISHERS)
            .open_or_create()
            .map_err(|e| err("opening event service", &event, e))?
            .notifier_builder()
            .create()
            .map_err(|e| err("creating notifier", &event, e))
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
            // One event: "a sample was published".
            .event_id_max_value(0)
            .open_or_create()
            .map_err(|e| err("opening event service", service, e))
    }

    fn pubsub_service<T: IpcSample>(
        &self,
        service: &str,
    ) -> Result<iceoryx2::service::port_factory::publish_subscribe::PortFactory<Transport, Wire<T>, ()>, IpcError> {
        let qos = match ServiceKind::of(service) {
            Some(kind) if kind.type_name() != T::TYPE_NAME => {
                return Err(err(
                    "opening",
                    service,
                    format!("carries {}, not {}", kind.type_name(), T::TYPE_NAME),
                ));
            }
            Some(kind) => kind.qos(),
            None if service.starts_with(services::BENCH_PREFIX) => services::BENCH_QOS,
            None => return Err(IpcError::InvalidName(service.to_string())),
        };
        let name: ServiceName = service
            .try_into()
            .map_err(|_| IpcError::InvalidName(service.to_string()))?;
        self.node
            .service_builder(&name)
            .publish_subscribe::<Wire<T>>()
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
    pub fn publisher<T: IpcSample>(&self, service: &str) -> Result<Publisher<T>, IpcError> {
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
        let kind = ServiceKind::of(service).map_or(ServiceKind::ALL.len(), ServiceKind::index);
        let wake = self
            .wake_service()?
            .notifier_builder()
            .default_event_id(EventId::new(kind))
            .create()
            .map_err(|e| err("creating notifier", services::WAKE, e))?;
        let stock = match ServiceKind::of(service) {
            Some(k) if services::has_stock_wake(k) => Some(self.stock_notifier(service)?),
            _ => None,
        };
        Ok(Publisher {
            publisher,
            notifier,
            wake,
            stock,
            service: service.to_string(),
            sent: 0,
        })
    }

    /// A subscriber on `service` that can sleep until its next sample
    /// ([`Subscriber::wait_next`]); the service is created if it does not exist yet.
    pub fn subscriber<T: IpcSample>(&self, service: &str) -> Result<Subscriber<T>, IpcError> {
        let mut s = self.input(service)?;
        s.listener = Some(
            self.event_service(service)?
                .listener_builder()
                .create()
                .map_err(|e| err("creating listener", service, e))?,
        );
        Ok(s)
    }

    /// A subscriber on `service` without a wake-up of its own: one of the inputs of a process
    /// that sleeps on its [`Wake`].
    pub fn input<T: IpcSample>(&self, service: &str) -> Result<Subscriber<T>, IpcError> {
        let ps = self.pubsub_service::<T>(service)?;
        let subscriber = ps
            .subscriber_builder()
            .create()
            .map_err(|e| err("creating subscriber", service, e))?;
        Ok(Subscriber {
            subscriber,
            busy: core::cell::Cell::new(false),
            listener: None,
            service: service.to_string(),
            port_factory: ps,
        })
    }
}

/// The one wake-up of a process with many inputs (see [`IpcNode::wake`]).
pub struct Wake {
    listener: Listener<Transport>,
    fired: core::cell::Cell<u32>,
    busy: core::cell::Cell<bool>,
}

impl Wake {
    /// Busy polling: [`IpcNode::wait`] spins on the event in user space instead of sleeping
    /// (no wake-up latency, no `FUTEX_WAKE` for the publishers; a whole core). For a process
    /// on an isolated core; off by default.
    pub fn set_busy_poll(&self, on: bool) {
        self.busy.set(on);
    }

    /// The kinds of sample published before the last [`IpcNode::wait`] returned, as a bit
    /// set over [`ServiceKind::index`] (bit 31: services of no navsync kind); 0 after a
    /// timeout.
    pub fn fired(&self) -> u32 {
        self.fired.get()
    }

    /// True if a sample of `kind` was among what woke the last wait.
    pub fn fired_kind(&self, kind: ServiceKind) -> bool {
        self.fired.get() & (1 << kind.index()) != 0
    }
}

/// Publishes samples of one type on one service and wakes its subscribers.
pub struct Publisher<T: IpcSample> {
    publisher: iceoryx2::port::publisher::Publisher<Transport, Wire<T>, ()>,
    notifier: Notifier<Transport>,
    /// On [`services::WAKE`], with this service's kind as the event id.
    wake: Notifier<Transport>,
    /// On [`services::stock_wake`] for the kinds that have one.
    stock: Option<Notifier<StockTransport>>,
    service: String,
    sent: u64,
}

impl<T: IpcSample> Publisher<T> {
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
        slot.write_payload(Wire(make()))
            .send()
            .map_err(|e| err("sending on", &self.service, e))?;
        self.notifier
            .notify()
            .map_err(|e| err("notifying on", &self.service, e))?;
        self.wake.notify().map_err(|e| err("notifying on", services::WAKE, e))?;
        if let Some(n) = &self.stock {
            n.notify()
                .map_err(|e| err("notifying the stock event of", &self.service, e))?;
        }
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
pub struct Subscriber<T: IpcSample> {
    subscriber: iceoryx2::port::subscriber::Subscriber<Transport, Wire<T>, ()>,
    /// The service's event, for [`wait_next`](Self::wait_next); none for an input of a
    /// process that sleeps on its [`Wake`].
    listener: Option<Listener<Transport>>,
    /// [`wait_next`](Subscriber::wait_next) spins instead of sleeping.
    busy: core::cell::Cell<bool>,
    service: String,
    port_factory: iceoryx2::service::port_factory::publish_subscribe::PortFactory<Transport, Wire<T>, ()>,
}

impl<T: IpcSample> Subscriber<T> {
    /// The next buffered sample (copied out of shared memory), if any.
    pub fn receive(&self) -> Result<Option<T>, IpcError> {
        match self.subscriber.receive() {
            Ok(Some(sample)) => Ok(Some(sample.payload().0)),
            Ok(None) => Ok(None),
            Err(e) => Err(err("receiving from", &self.service, e)),
        }
    }

    /// Hands the next buffered sample, if any, to `f` where it lies in shared memory.
    pub fn receive_with<R>(&self, f: impl FnOnce(&T) -> R) -> Result<Option<R>, IpcError> {
        match self.subscriber.receive() {
            Ok(Some(sample)) => Ok(Some(f(&sample.payload().0))),
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
            f(&sample.payload().0);
            n += 1;
        }
        Ok(n)
    }

    /// Hands every buffered sample to `f` (by value) until it returns false; returns how
    /// many it was given.
    pub fn drain(&self, mut f: impl FnMut(T) -> bool) -> Result<usize, IpcError> {
        let mut n = 0;
        while let Some(s) = self.receive()? {
            n += 1;
            if !f(s) {
                break;
            }
        }
        Ok(n)
    }

    /// Blocks until a sample is available or `timeout` passes; `Ok(None)` on timeout, or
    /// earlier on a termination request (the caller checks [`termination_requested`]).
    /// `Duration::MAX` waits without a timeout and without arming a kernel timer per wait
    /// (cheaper per sample); it returns `Ok(None)` only on SIGINT/SIGTERM.
    /// Sleeps in `FUTEX_WAIT` on the service's event; a publisher's `FUTEX_WAKE` puts the
    /// sample in hand with no other system call. Needs a subscriber made by
    /// [`IpcNode::subscriber`] (an [`IpcNode::input`] has no wake-up of its own).
    pub fn wait_next(&self, timeout: Duration) -> Result<Option<T>, IpcError> {
        self.wait_with(timeout, |s| *s)
    }

    /// Like [`wait_next`](Self::wait_next), but hands the sample to `f` where it lies in shared
    /// memory (zero copy) and returns what `f` returns.
    pub fn wait_with<R>(&self, timeout: Duration, mut f: impl FnMut(&T) -> R) -> Result<Option<R>, IpcError> {
        if let Some(s) = self.receive_with(&mut f)? {
            return Ok(Some(s));
        }
        if self.busy.get() {
            // None: no deadline (`Duration::MAX`).
            let deadline = std::time::Instant::now().checked_add(timeout);
            let mut spins = 0u32;
            loop {
                if let Some(s) = self.receive_with(&mut f)? {
                    return Ok(Some(s));
                }
                spins = spins.wrapping_add(1);
                if spins.is_multiple_of(BUSY_CHECK_EVERY)
                    && (termination_requested() || deadline.is_some_and(|d| std::time::Instant::now() >= d))
                {
                    return Ok(None);
                }
                core::hint::spin_loop();
            }
        }
        let Some(listener) = &self.listener else {
            return Err(err(
                "waiting on",
                &self.service,
                "an input of a Wake has no wake-up of its own",
            ));
        };
        if timeout == Duration::MAX {
            // No timeout: no kernel timer per wait; a termination signal wakes the wait.
            loop {
                match listener.blocking_wait(|_| {}) {
                    Ok(_) | Err(ListenerWaitError::InterruptSignal) => {}
                    Err(e) => return Err(err("waiting on", &self.service, e)),
                }
                if let Some(s) = self.receive_with(&mut f)? {
                    return Ok(Some(s));
                }
                if termination_requested() {
                    return Ok(None);
                }
            }
        }
        // The clock is read only once a wait has come back empty: a sample that wakes the
        // first wait is in hand without it.
        let mut deadline: Option<std::time::Instant> = None;
        loop {
            let left = deadline.map_or(timeout, |d| d.saturating_duration_since(std::time::Instant::now()));
            let woken = match listener.timed_wait(|_| {}, left.min(WAIT_SLICE)) {
                Ok(n) => n > 0,
                Err(ListenerWaitError::InterruptSignal) => true,
                Err(e) => return Err(err("waiting on", &self.service, e)),
            };
            if let Some(s) = self.receive_with(&mut f)? {
                return Ok(Some(s));
            }
            if left <= WAIT_SLICE || termination_requested() {
                return Ok(None);
            }
            if deadline.is_none() {
                // A slice that ended without an event took all of it; one woken took ~0.
                let used = if woken { Duration::ZERO } else { WAIT_SLICE };
                deadline = Some(std::time::Instant::now() + (timeout - used));
            }
        }
    }

    /// Busy polling: [`wait_next`](Self::wait_next) spins on the subscriber in user space
    /// instead of sleeping (no wake-up latency, no `FUTEX_WAKE` for the publisher; a whole
    /// core). For a subscriber on an isolated core; off by default.
    pub fn set_busy_poll(&self, on: bool) {
        self.busy.set(on);
    }

    /// Publishers on the service now. A publisher whose process was killed is counted until
    /// some node reclaims the dead node ([`IpcNode::reclaim_dead_nodes`]).
    pub fn publisher_count(&self) -> usize {
        self.port_factory.dynamic_config().number_of_publishers()
    }

    /// The service name.
    pub fn service(&self) -> &str {
        &self.service
    }
}

/// A file descriptor that becomes readable when a sample is published on a service, for a
/// `poll(2)` loop that also waits on sockets (navsync's events are futexes, without a
/// descriptor): a thread with a node of its own sleeps on the service's event and counts an
/// `eventfd` up on every wake-up. One hop more than [`Subscriber::wait_next`] (a thread
/// wake-up, some µs); the samples are taken by the caller's own subscriber
/// ([`IpcNode::input`]) once the descriptor fired, after [`clear`](Self::clear).
pub struct WakeFd {
    fd: std::os::fd::OwnedFd,
    stop: std::sync::Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl WakeFd {
    /// Starts the thread, whose node is named `{process}-wake`, on `service`'s event.
    pub fn new(process: &str, service: &str) -> Result<Self, IpcError> {
        use std::os::fd::{AsRawFd, FromRawFd};
        // SAFETY: eventfd has no preconditions; the descriptor is owned below.
        let raw = unsafe { libc::eventfd(0, libc::EFD_CLOEXEC | libc::EFD_NONBLOCK) };
        if raw < 0 {
            return Err(err("creating eventfd for", service, std::io::Error::last_os_error()));
        }
        // SAFETY: a fresh descriptor that nothing else owns.
        let fd = unsafe { std::os::fd::OwnedFd::from_raw_fd(raw) };
        let stop = std::sync::Arc::new(AtomicBool::new(false));
        let (tx, rx) = std::sync::mpsc::channel();
        let (name, service_name, prefix, stop2) =
            (format!("{process}-wake"), service.to_string(), prefix(), stop.clone());
        let efd = fd.as_raw_fd();
        let thread = std::thread::Builder::new()
            .name(name.clone())
            .spawn(move || {
                let listener = IpcNode::with_prefix(&name, &prefix).and_then(|node| {
                    let l = node
                        .event_service(&service_name)?
                        .listener_builder()
                        .create()
                        .map_err(|e| err("creating listener", &service_name, e))?;
                    Ok((node, l))
                });
                let (_node, listener) = match listener {
                    Ok(x) => {
                        let _ = tx.send(Ok(()));
                        x
                    }
                    Err(e) => {
                        let _ = tx.send(Err(e));
                        return;
                    }
                };
                while !stop2.load(Ordering::Relaxed) {
                    if let Ok(n) = listener.timed_wait(|_| {}, WAIT_SLICE)
                        && n > 0
                    {
                        let one = 1u64;
                        // SAFETY: writing 8 bytes from a live u64 to our eventfd, which outlives
                        // this thread (joined before it is closed).
                        unsafe { libc::write(efd, (&one as *const u64).cast(), 8) };
                    }
                }
            })
            .map_err(|e| err("starting wake-up thread for", service, e))?;
        match rx.recv() {
            Ok(Ok(())) => Ok(Self {
                fd,
                stop,
                thread: Some(thread),
            }),
            Ok(Err(e)) => Err(e),
            Err(_) => Err(err("starting wake-up thread for", service, "the thread ended")),
        }
    }

    /// The descriptor to poll for `POLLIN`.
    pub fn fd(&self) -> std::os::fd::RawFd {
        use std::os::fd::AsRawFd;
        self.fd.as_raw_fd()
    }

    /// Consumes the wake-ups counted so far (before draining the subscriber).
    pub fn clear(&self) {
        let mut v = 0u64;
        // SAFETY: reading 8 bytes into a live u64 from our non-blocking eventfd.
        unsafe { libc::read(self.fd(), (&mut v as *mut u64).cast(), 8) };
    }
}

impl Drop for WakeFd {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
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
