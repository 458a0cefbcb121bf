//! `navsync bridge zenoh`: chosen iceoryx2 services out to Zenoh key expressions
//! ([`wire`](crate::wire)), and, with `import`, a remote instance's keys back into the local
//! iceoryx2 under the same service names (a local subscriber cannot tell the difference).
//!
//! Export: one subscriber per matching service (names, or patterns matched against the
//! existing services every [`DISCOVERY_INTERVAL`], so services that appear later, or come back
//! with a restarted process, are exported from then on), one wake-up (`ipc::Wake`), one Zenoh publisher per
//! key with congestion control `Drop`: a slow network or subscriber drops samples on the Zenoh
//! side and never blocks the local publishers. Per-service rate limits decimate by the samples'
//! host stamps (e.g. NavState to 50 Hz over a radio link).
//!
//! Import: a Zenoh subscriber on `navsync/<instance>/**` hands samples to a bounded queue
//! (full: dropped and counted, memory stays bounded), a thread of its own decodes them
//! (a sample of another layout version is refused with a message naming both) and publishes
//! them on the local service. Losses are counted from the exporter's sequence numbers.
//!
//! Counters go to the bridge's `Health` (`navsync/health/bridge-zenoh`).

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use navsync_recording::glob::{ServiceGlob, any_matches};
use navsync_recording::ports::{AnyPublisher, AnySubscriber};
use navsync_shared::health_reporter::HealthReporter;
use navsync_shared::ipc::{self, IpcError, IpcNode};
use navsync_shared::samples::AnySample;
use navsync_shared::services::ServiceKind;
use navsync_shared::time::monotonic_now_ns;
use tracing::{info, info_span, warn};
use zenoh::Wait;
use zenoh::qos::CongestionControl;

use crate::wire::{self, GapCounter};

/// How often export patterns are matched against the existing services.
pub const DISCOVERY_INTERVAL: Duration = Duration::from_millis(500);
/// Samples waiting between the Zenoh subscriber and the importing thread.
pub const IMPORT_QUEUE: usize = 4096;
/// The bridge's own health service (never imported over it).
pub const OWN_HEALTH: &str = "navsync/health/bridge-zenoh";
/// Default services exported.
pub const DEFAULT_EXPORT: [&str; 3] = ["navsync/nav/state", "navsync/time/state", "navsync/health/**"];

/// Zenoh's role.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Peer to peer (default).
    Peer,
    /// Client of a router or peer.
    Client,
    /// Router.
    Router,
}

/// How the Zenoh session is set up.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SessionSettings {
    /// A Zenoh configuration file (JSON5), passed through; the settings below override it.
    pub config_file: Option<std::path::PathBuf>,
    /// Mode (default: the file's, else peer).
    pub mode: Option<Mode>,
    /// Endpoints to connect to, e.g. `tcp/10.0.0.1:7447`.
    pub connect: Vec<String>,
    /// Endpoints to listen on.
    pub listen: Vec<String>,
}

/// A Zenoh error, with what was being done.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    /// Zenoh refused.
    #[error("zenoh: {what}: {detail}")]
    Zenoh {
        /// What was being done.
        what: &'static str,
        /// Zenoh's message.
        detail: String,
    },
    /// iceoryx2.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// A health counter.
    #[error(transparent)]
    Health(#[from] navsync_shared::health_reporter::HealthError),
    /// A setting.
    #[error("{0}")]
    Settings(String),
}

fn zerr(what: &'static str) -> impl Fn(zenoh::Error) -> BridgeError {
    move |e| BridgeError::Zenoh {
        what,
        detail: e.to_string(),
    }
}

impl SessionSettings {
    /// The Zenoh configuration: the file (or Zenoh's defaults), then navsync's link settings
    /// for a link that may go away (lease 1 s with 4 keep-alives, reconnect every 250–1000 ms:
    /// a link back after an outage carries samples again within about a second), then mode and
    /// endpoints. Multicast scouting is off when endpoints are given.
    pub fn zenoh_config(&self) -> Result<zenoh::Config, BridgeError> {
        let mut c = match &self.config_file {
            Some(p) => {
                zenoh::Config::from_file(p).map_err(|e| BridgeError::Settings(format!("{}: {e}", p.display())))?
            }
            None => {
                let mut c = zenoh::Config::default();
                let set = |c: &mut zenoh::Config, k: &str, v: &str| {
                    c.insert_json5(k, v)
                        .map_err(|e| BridgeError::Settings(format!("zenoh setting {k} = {v}: {e}")))
                };
                set(&mut c, "transport/link/tx/lease", "1000")?;
                set(&mut c, "transport/link/tx/keep_alive", "4")?;
                set(
                    &mut c,
                    "connect/retry",
                    "{ period_init_ms: 250, period_max_ms: 1000, period_increase_factor: 2 }",
                )?;
                c
            }
        };
        let set = |c: &mut zenoh::Config, k: &str, v: String| {
            c.insert_json5(k, &v)
                .map_err(|e| BridgeError::Settings(format!("zenoh setting {k} = {v}: {e}")))
        };
        if let Some(m) = self.mode {
            let m = match m {
                Mode::Peer => "peer",
                Mode::Client => "client",
                Mode::Router => "router",
            };
            set(&mut c, "mode", format!("\"{m}\""))?;
        }
        let list = |v: &[String]| serde_json::to_string(v).unwrap_or_default();
        if !self.connect.is_empty() {
            set(&mut c, "connect/endpoints", list(&self.connect))?;
        }
        if !self.listen.is_empty() {
            set(&mut c, "listen/endpoints", list(&self.listen))?;
        }
        if !self.connect.is_empty() || !self.listen.is_empty() {
            set(&mut c, "scouting/multicast/enabled", "false".into())?;
        }
        Ok(c)
    }

    /// Opens a session.
    pub fn open(&self) -> Result<zenoh::Session, BridgeError> {
        zenoh::open(self.zenoh_config()?)
            .wait()
            .map_err(zerr("opening the session"))
    }
}

/// A per-service rate limit: services matching `pattern` at most `max_hz` samples/s.
#[derive(Debug, Clone, PartialEq)]
pub struct RateLimit {
    /// Service name or pattern.
    pub pattern: String,
    /// Samples per second.
    pub max_hz: f64,
}

/// What the bridge does.
#[derive(Debug, Clone, PartialEq)]
pub struct BridgeSettings {
    /// This host's instance name in the keys.
    pub instance: String,
    /// Services (names or patterns) to export; empty: none.
    pub export: Vec<String>,
    /// Rate limits of exported services (first match wins).
    pub rates: Vec<RateLimit>,
    /// Import the services of this remote instance (`*`: every other instance).
    pub import: Option<String>,
    /// Which services to import (patterns; default every navsync service).
    pub import_services: Vec<String>,
    /// The Zenoh session.
    pub session: SessionSettings,
    /// Stop after this long (tests, benchmarks).
    pub duration: Option<Duration>,
}

struct Exported {
    service: String,
    publisher: zenoh::pubsub::Publisher<'static>,
    kind: ServiceKind,
    min_interval_ns: i64,
    last_sent_ns: Option<i64>,
    seq: u64,
}

/// Counters shared with the import thread.
#[derive(Default)]
struct ImportStats {
    received: AtomicU64,
    published: AtomicU64,
    lost: AtomicU64,
    refused: AtomicU64,
    dropped_queue: AtomicU64,
}

/// Runs the bridge until SIGINT/SIGTERM or the duration.
pub fn run(s: &BridgeSettings) -> Result<(), BridgeError> {
    let _span = info_span!("bridge-zenoh", instance = %s.instance).entered();
    if !wire::valid_instance(&s.instance) {
        return Err(BridgeError::Settings(format!(
            "instance `{}`: letters, digits, `-`, `_` and `.` only",
            s.instance
        )));
    }
    let session = s.session.open()?;
    info!(zid = %session.zid(), "zenoh session open");
    let node = IpcNode::new("bridge-zenoh")?;
    let mut health = HealthReporter::new(&node, "bridge-zenoh")?;
    let c_exported = health.counter("exported")?;
    let c_rate_limited = health.counter("rate_limited")?;
    let c_put_errors = health.counter("put_errors")?;
    let c_services = health.counter("services_exported")?;
    let c_peers = health.counter("zenoh_peers")?;
    let c_imported = health.counter("imported")?;
    let c_import_lost = health.counter("import_lost")?;
    let c_import_refused = health.counter("import_refused")?;
    let c_import_dropped = health.counter("import_dropped")?;
    let r_exported = health.rate("exported")?;

    // Import: Zenoh callback → bounded queue → a thread publishing into iceoryx2.
    let stats = Arc::new(ImportStats::default());
    let stop = Arc::new(AtomicBool::new(false));
    let mut import_thread = None;
    let mut _import_sub = None;
    if let Some(remote) = &s.import {
        let (tx, rx) = std::sync::mpsc::sync_channel::<(String, Vec<u8>, Option<Vec<u8>>)>(IMPORT_QUEUE);
        let key = if remote == "*" {
            "navsync/*/**".to_string()
        } else {
            format!("navsync/{remote}/**")
        };
        let st = stats.clone();
        let own = s.instance.clone();
        let sub = session
            .declare_subscriber(key.clone())
            .callback(move |sample| {
                let k = sample.key_expr().as_str();
                if wire::parse_key(k).is_some_and(|(inst, _)| inst == own) {
                    return; // our own exports
                }
                let item = (
                    k.to_string(),
                    sample.payload().to_bytes().into_owned(),
                    sample.attachment().map(|a| a.to_bytes().into_owned()),
                );
                if tx.try_send(item).is_err() {
                    st.dropped_queue.fetch_add(1, Ordering::Relaxed);
                }
            })
            .wait()
            .map_err(zerr("subscribing"))?;
        _import_sub = Some(sub);
        let globs: Vec<ServiceGlob> = if s.import_services.is_empty() {
            vec![ServiceGlob::new("navsync/**")]
        } else {
            s.import_services.iter().map(|p| ServiceGlob::new(p)).collect()
        };
        let (st, stop2) = (stats.clone(), stop.clone());
        info!(key = %key, "importing");
        import_thread = Some(
            std::thread::Builder::new()
                .name("import".into())
                .spawn(move || import_loop(rx, &globs, &st, &stop2))
                .map_err(|e| BridgeError::Settings(format!("starting the import thread: {e}")))?,
        );
    }

    // Export.
    let globs: Vec<ServiceGlob> = s.export.iter().map(|p| ServiceGlob::new(p)).collect();
    // One wake-up for every exported service: each navsync publisher notifies it.
    let wake = node.wake()?;
    let mut subs: Vec<AnySubscriber> = Vec::new();
    let mut exported: Vec<Exported> = Vec::new();
    let mut refused: std::collections::HashSet<String> = Default::default();
    let (mut payload, mut att) = (Vec::with_capacity(4096), Vec::with_capacity(64));
    let t0 = monotonic_now_ns();
    let end = s.duration.map(|d| t0 + d.as_nanos() as i64);
    let mut last_discovery = i64::MIN;
    navsync_shared::sd_notify::ready("bridging");
    'outer: loop {
        let now = monotonic_now_ns();
        if now.saturating_sub(last_discovery) >= DISCOVERY_INTERVAL.as_nanos() as i64 {
            last_discovery = now;
            for name in to_export(&globs, &exported, &refused)? {
                match export(&node, &session, &s.instance, &name, &s.rates) {
                    Ok((sub, e)) => {
                        info!(service = %name, key = %wire::key_of(&s.instance, &name), "exporting");
                        subs.push(sub);
                        exported.push(e);
                    }
                    Err(e) => {
                        warn!("not exporting {name}: {e}");
                        refused.insert(name);
                    }
                }
            }
        }
        // Wait for samples (or the next discovery / health report).
        loop {
            let alive = node.wait(&wake, Duration::from_millis(100))?;
            for (sub, e) in subs.iter().zip(exported.iter_mut()) {
                let (mut sent, mut limited, mut errors) = (0u64, 0u64, 0u64);
                sub.drain(|x| match e.offer(&x, &mut payload, &mut att) {
                    Offer::Sent => sent += 1,
                    Offer::Limited => limited += 1,
                    Offer::Failed => errors += 1,
                })?;
                health.add(c_exported, sent);
                health.add(c_rate_limited, limited);
                health.add(c_put_errors, errors);
                for _ in 0..sent {
                    health.tick(r_exported);
                }
            }
            let now = monotonic_now_ns();
            health.set(c_services, exported.len() as u64);
            health.set(c_imported, stats.published.load(Ordering::Relaxed));
            health.set(c_import_lost, stats.lost.load(Ordering::Relaxed));
            health.set(c_import_refused, stats.refused.load(Ordering::Relaxed));
            health.set(c_import_dropped, stats.dropped_queue.load(Ordering::Relaxed));
            if health.maybe_publish(now)? {
                let peers = session.info().peers_zid().wait().count() + session.info().routers_zid().wait().count();
                health.set(c_peers, peers as u64);
            }
            navsync_shared::sd_notify::watchdog();
            if !alive || end.is_some_and(|e| now >= e) {
                break 'outer;
            }
            if now.saturating_sub(last_discovery) >= DISCOVERY_INTERVAL.as_nanos() as i64 {
                break; // discover again
            }
        }
    }
    navsync_shared::sd_notify::stopping();
    stop.store(true, Ordering::Relaxed);
    drop(_import_sub);
    if let Some(t) = import_thread {
        let _ = t.join();
    }
    let _ = health.publish_final();
    let _ = session.close().wait();
    info!(
        exported = exported.len(),
        imported = stats.published.load(Ordering::Relaxed),
        "bridge stopped"
    );
    Ok(())
}

enum Offer {
    Sent,
    Limited,
    Failed,
}

impl Exported {
    fn offer(&mut self, x: &AnySample, payload: &mut Vec<u8>, att: &mut Vec<u8>) -> Offer {
        let t = x.host_ns();
        if self.min_interval_ns > 0
            && let Some(last) = self.last_sent_ns
            && t.saturating_sub(last) < self.min_interval_ns
        {
            return Offer::Limited;
        }
        wire::encode(x, payload);
        wire::attachment(self.kind, self.seq, att);
        match self.publisher.put(payload.as_slice()).attachment(att.as_slice()).wait() {
            Ok(()) => {
                self.seq += 1;
                self.last_sent_ns = Some(t);
                Offer::Sent
            }
            Err(e) => {
                warn!(service = %self.service, "zenoh put: {e}");
                Offer::Failed
            }
        }
    }
}

/// Existing services to export that are not exported yet (nor refused).
fn to_export(
    globs: &[ServiceGlob],
    exported: &[Exported],
    refused: &std::collections::HashSet<String>,
) -> Result<Vec<String>, IpcError> {
    if globs.is_empty() {
        return Ok(Vec::new());
    }
    let mut names: Vec<String> = globs
        .iter()
        .filter(|g| g.is_literal())
        .map(|g| g.as_str().to_string())
        .collect();
    names.extend(ipc::list_services()?.into_iter().filter(|n| any_matches(globs, n)));
    names.sort();
    names.dedup();
    Ok(names
        .into_iter()
        .filter(|n| ServiceKind::of(n).is_some() && !refused.contains(n) && !exported.iter().any(|e| e.service == *n))
        .collect())
}

fn export(
    node: &IpcNode,
    session: &zenoh::Session,
    instance: &str,
    service: &str,
    rates: &[RateLimit],
) -> Result<(AnySubscriber, Exported), BridgeError> {
    let kind = ServiceKind::of(service)
        .ok_or_else(|| BridgeError::Settings(format!("`{service}` is not a navsync service")))?;
    let sub = AnySubscriber::open(node, service)?;
    let publisher = session
        .declare_publisher(wire::key_of(instance, service))
        .congestion_control(CongestionControl::Drop)
        .wait()
        .map_err(zerr("declaring a publisher"))?;
    let min_interval_ns = rates
        .iter()
        .find(|r| ServiceGlob::new(&r.pattern).matches(service))
        .map_or(0, |r| (1e9 / r.max_hz) as i64);
    Ok((
        sub,
        Exported {
            service: service.to_string(),
            publisher,
            kind,
            min_interval_ns,
            last_sent_ns: None,
            seq: 0,
        },
    ))
}

fn import_loop(
    rx: std::sync::mpsc::Receiver<(String, Vec<u8>, Option<Vec<u8>>)>,
    globs: &[ServiceGlob],
    stats: &ImportStats,
    stop: &AtomicBool,
) {
    let node = match IpcNode::new("bridge-zenoh-import") {
        Ok(n) => n,
        Err(e) => {
            warn!("import: {e}");
            return;
        }
    };
    let mut pubs: HashMap<String, AnyPublisher> = HashMap::new();
    let mut gaps = GapCounter::default();
    let mut warned: std::collections::HashSet<String> = Default::default();
    while !stop.load(Ordering::Relaxed) && !node.termination_requested() {
        let Ok((key, payload, att)) = rx.recv_timeout(Duration::from_millis(100)) else {
            continue;
        };
        stats.received.fetch_add(1, Ordering::Relaxed);
        let (r, service) = match wire::decode(&key, &payload, att.as_deref()) {
            Ok(x) => x,
            Err(e) => {
                stats.refused.fetch_add(1, Ordering::Relaxed);
                if warned.insert(key.clone()) {
                    warn!("refused: {e}");
                }
                continue;
            }
        };
        stats.lost.fetch_add(gaps.note(&key, r.seq), Ordering::Relaxed);
        // The local bridge publishes its own health under this name.
        if !any_matches(globs, &service) || service == OWN_HEALTH {
            continue;
        }
        let p = match pubs.get_mut(&service) {
            Some(p) => p,
            None => match AnyPublisher::open(&node, &service) {
                Ok(p) => pubs.entry(service.clone()).or_insert(p),
                Err(e) => {
                    if warned.insert(service.clone()) {
                        warn!("not importing {service}: {e}");
                    }
                    continue;
                }
            },
        };
        match p.publish(&r.sample) {
            Ok(()) => {
                stats.published.fetch_add(1, Ordering::Relaxed);
            }
            Err(e) => warn!("publishing {service}: {e}"),
        }
    }
}
