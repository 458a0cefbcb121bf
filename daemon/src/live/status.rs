//! `navsync status`: every navsync process and service on the host, what flows where, and the
//! time-synchronisation and navigation state in one view.
//!
//! Discovery is iceoryx2's own: [`Node::list`] finds the processes (nodes) under the navsync
//! resource prefix (`$NAVSYNC_IPC_PREFIX` or `navsync_`), `Service::list` the services. Every
//! navsync publish-subscribe service is opened (never created) and subscribed to for the
//! measurement window: the rate is the number of intervals between the samples that arrived
//! in it over the time their own stamps span (so a 1 Hz service over a 2 s window is 1 Hz,
//! whether 2 or 3 of its samples fell in the window), the last-sample age is the host clock
//! minus the newest sample's own stamp (`CLOCK_MONOTONIC`), and publisher/subscriber counts
//! come from the service's dynamic configuration (this process's own subscriber not counted).
//! The latest `Health` of each process gives its counters; the latest `TimeState` and
//! `NavState` give the time-sync state, the receiver latency d0, the GNSS delay Δ and the
//! per-IMU offsets; a u-blox receiver's latest TIM-TP gives the qErr of its next pulse, its
//! latest TIM-TM2 the last time mark.
//!
//! A process's state is iceoryx2's, refined ([`refine_state`]): `alive`; `stalled` when it is
//! stopped (SIGSTOP: `/proc/PID/stat` says `T`) or its `Health` heartbeat is older than
//! [`HEARTBEAT_STALE_S`] (a listed node is not a working process); `gone` when it died
//! without cleaning up (`kill -9`: listed before this process's own node reclaims it) or
//! vanished between two refreshes of `--watch`, so a killed process is reported, not silently
//! missing.
//!
//! A process is one row even when it holds two iceoryx2 nodes (a publisher of `NavState` or
//! `TimeState` has a second one, on iceoryx2's stock service type, for the Python clients).
//! With nothing running under the prefix (no process, no service), a single report says so
//! and exits non-zero.
//!
//! `--json` prints one JSON document (one line per refresh with `--watch`); `--watch S`
//! refreshes every S seconds until Ctrl-C (`--count N` refreshes, then exits).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::Write;
use std::time::{Duration, Instant};

use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;
use iceoryx2::service::static_config::messaging_pattern::MessagingPattern;
use navsync_shared::ipc::Wire;
use navsync_shared::ipc::{self, IpcError, IpcNode, Transport};
use navsync_shared::reflect::str_of;
use navsync_shared::samples::*;
use navsync_shared::services::ServiceKind;
use navsync_shared::time::monotonic_now_ns;
use serde_json::{Map, Value, json};

/// Settings of `navsync status`.
#[derive(Debug, Clone, clap::Args)]
pub struct StatusArgs {
    /// One JSON document (one line per refresh with --watch).
    #[arg(long)]
    pub json: bool,
    /// Refresh every S seconds until Ctrl-C.
    #[arg(long, value_name = "S", num_args = 0..=1, default_missing_value = "1", value_parser = super::echo::positive_seconds)]
    pub watch: Option<Duration>,
    /// Measurement window of a single report, s.
    #[arg(long, value_name = "S", default_value = "2", value_parser = super::echo::positive_seconds)]
    pub window: Duration,
    /// With --watch: stop after N refreshes.
    #[arg(long)]
    pub count: Option<u64>,
    /// The instances and services heard through Zenoh at this endpoint (e.g.
    /// tcp/192.168.1.10:7447) during --window, instead of the local ones (needs the `zenoh`
    /// feature).
    #[arg(long, value_name = "ENDPOINT", conflicts_with = "watch")]
    pub zenoh: Option<String>,
}

/// Errors of `navsync status`.
#[derive(Debug, thiserror::Error)]
pub enum StatusError {
    /// IPC failure.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// Listing nodes or services failed.
    #[error("{0}")]
    Discovery(String),
    /// No navsync process or service under the prefix.
    #[error(
        "nothing is running under the iceoryx2 prefix `{0}`: no navsync process, no service \
         (the services' prefix and root are set by [ipc].prefix, $NAVSYNC_IPC_PREFIX and $NAVSYNC_IPC_ROOT)"
    )]
    NothingRunning(String),
    /// stdout closed.
    #[error("writing output: {0}")]
    Io(#[from] std::io::Error),
}

/// One observed service, type-erased.
trait Monitor {
    /// Takes what arrived (the subscriber keeps only the newest sample: a reader that wakes
    /// once a second costs a 1 kHz publisher nothing per sample) and counts, by the samples'
    /// sequence numbers, what was published since the previous newest.
    fn poll(&mut self) -> Arrivals;
    /// (publishers, subscribers) on the service, including this process's subscriber.
    fn ports(&self) -> (usize, usize);
    /// Host stamp of the newest sample ever received.
    fn last_host_ns(&self) -> Option<i64>;
    /// The newest sample.
    fn latest(&self) -> Option<AnySample>;
}

/// What one poll of a service saw.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Arrivals {
    /// Samples published since the previous poll, by their sequence numbers (a sample with no
    /// predecessor seen, or whose publisher restarted, counts 1).
    published: u64,
    /// Of those, the ones whose predecessor's host stamp is known: the intervals in `span`.
    intervals: u64,
    /// Host stamps (ns) of the newest sample before them and of the newest now.
    span: Option<(i64, i64)>,
}

impl Arrivals {
    /// Counts `seq` at host time `host_ns` after `prev` (sequence number, host ns).
    fn count(&mut self, prev: Option<(u64, i64)>, seq: u64, host_ns: i64) {
        match prev {
            Some((p, p_host)) if seq > p => {
                self.published += seq - p;
                self.intervals += seq - p;
                self.span = Some((self.span.map_or(p_host, |(f, _)| f), host_ns));
            }
            _ => self.published += 1,
        }
    }

    /// This poll's arrivals after `earlier`'s, as one.
    fn merge(&mut self, later: Arrivals) {
        self.published += later.published;
        self.intervals += later.intervals;
        if let Some((f, l)) = later.span {
            self.span = Some((self.span.map_or(f, |(f0, _)| f0), l));
        }
    }
}

struct Typed<T: navsync_shared::ipc::IpcSample> {
    factory: iceoryx2::service::port_factory::publish_subscribe::PortFactory<Transport, Wire<T>, ()>,
    sub: iceoryx2::port::subscriber::Subscriber<Transport, Wire<T>, ()>,
    latest: Option<T>,
    wrap: fn(T) -> AnySample,
}

impl<T: navsync_shared::ipc::IpcSample> Monitor for Typed<T> {
    fn poll(&mut self) -> Arrivals {
        let mut a = Arrivals::default();
        while let Ok(Some(s)) = self.sub.receive() {
            let sample = s.payload().0;
            let any = (self.wrap)(sample);
            let prev = self.latest.map(|p| {
                let p = (self.wrap)(p);
                (p.seq(), p.host_ns())
            });
            a.count(prev, any.seq(), any.host_ns());
            self.latest = Some(sample);
        }
        a
    }
    fn ports(&self) -> (usize, usize) {
        let d = self.factory.dynamic_config();
        (d.number_of_publishers(), d.number_of_subscribers())
    }
    fn last_host_ns(&self) -> Option<i64> {
        self.latest.map(|s| (self.wrap)(s).host_ns())
    }
    fn latest(&self) -> Option<AnySample> {
        self.latest.map(self.wrap)
    }
}

fn open_typed<T: navsync_shared::ipc::IpcSample>(
    node: &IpcNode,
    service: &str,
    wrap: fn(T) -> AnySample,
) -> Result<Box<dyn Monitor>, String> {
    let name: ServiceName = service.try_into().map_err(|e| format!("{e:?}"))?;
    // Open only: status must never create a service that is not there.
    let factory = node
        .node()
        .service_builder(&name)
        .publish_subscribe::<Wire<T>>()
        .open()
        .map_err(|e| format!("{e:?}"))?;
    // Only the newest sample is kept: the publisher overwrites it (safe overflow), so a reader
    // that polls seldom neither falls behind nor holds the publisher's samples.
    let sub = factory
        .subscriber_builder()
        .buffer_size(1)
        .create()
        .map_err(|e| format!("{e:?}"))?;
    Ok(Box::new(Typed {
        factory,
        sub,
        latest: None,
        wrap,
    }))
}

fn open_monitor(node: &IpcNode, service: &str, kind: ServiceKind) -> Result<Box<dyn Monitor>, String> {
    match kind {
        ServiceKind::GnssFix => open_typed::<GnssFix>(node, service, AnySample::GnssFix),
        ServiceKind::PpsEdge => open_typed::<PpsEdge>(node, service, AnySample::PpsEdge),
        ServiceKind::ImuSample => open_typed::<ImuSample>(node, service, AnySample::Imu),
        ServiceKind::TimeState => open_typed::<TimeState>(node, service, AnySample::Time),
        ServiceKind::NavState => open_typed::<NavState>(node, service, AnySample::Nav),
        ServiceKind::Health => open_typed::<Health>(node, service, AnySample::Health),
        ServiceKind::SimTruth => open_typed::<SimTruth>(node, service, AnySample::Truth),
        ServiceKind::GnssTimePulse => open_typed::<GnssTimePulse>(node, service, AnySample::TimePulse),
        ServiceKind::GnssEvent => open_typed::<GnssEvent>(node, service, AnySample::Event),
        ServiceKind::GnssRaw => open_typed::<GnssRaw>(node, service, AnySample::Raw),
        ServiceKind::GnssNavData => open_typed::<GnssNavData>(node, service, AnySample::NavData),
        ServiceKind::EstimatorSettings => open_typed::<EstimatorSettings>(node, service, AnySample::Settings),
        ServiceKind::NetworkTime => open_typed::<NetworkTime>(node, service, AnySample::NetworkTime),
        ServiceKind::GnssSky => open_typed::<GnssSky>(node, service, AnySample::Sky),
        ServiceKind::EventPose => open_typed::<EventPose>(node, service, AnySample::EventPose),
    }
}

/// A service being watched and its counts since the last report.
struct Watched {
    kind: ServiceKind,
    monitor: Box<dyn Monitor>,
    /// What was published since the interval started.
    interval: Arrivals,
    total: u64,
    last_arrival: Option<Instant>,
    /// Names of the nodes attached to the service, from discovery.
    nodes: Vec<String>,
}

/// A process whose latest `Health` is older than this (three of its 1 s reports missed) has
/// stopped reporting: `stalled`.
pub const HEARTBEAT_STALE_S: f64 = 3.0;

/// The state shown for a process: iceoryx2's node state (`alive`, `dead`, …), refined by its
/// `/proc` state letter and the age of its latest `Health` (None: it has none); and why, for a
/// stalled one.
pub fn refine_state(
    node_state: &'static str,
    proc_state: Option<char>,
    heartbeat_age_s: Option<f64>,
) -> (&'static str, Option<String>) {
    match node_state {
        "alive" => {}
        "dead" => return ("gone", Some("died without cleaning up (killed?)".into())),
        other => return (other, None),
    }
    if matches!(proc_state, Some('T' | 't')) {
        return ("stalled", Some("stopped (SIGSTOP or a debugger)".into()));
    }
    match heartbeat_age_s {
        Some(age) if age > HEARTBEAT_STALE_S => ("stalled", Some(format!("no heartbeat for {age:.1} s"))),
        _ => ("alive", None),
    }
}

/// The state letter of process `pid` in `/proc` (`R`, `S`, `T` when stopped, …).
fn proc_state(pid: i32) -> Option<char> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    s.rsplit_once(')')
        .and_then(|(_, rest)| rest.trim_start().chars().next())
}

/// A discovered process (iceoryx2 node).
#[derive(Debug, Clone)]
struct Process {
    name: String,
    pid: Option<i32>,
    executable: String,
    state: &'static str,
}

/// What `navsync status` gathers, for any process that shows it (`status`, `web`): the
/// processes and services under the prefix ([`Status::discover`]), their samples
/// ([`Status::poll`]) and one report over the interval since the last ([`Status::report`]).
pub struct Status {
    node: IpcNode,
    services: BTreeMap<String, Watched>,
    processes: Vec<Process>,
    /// Processes that died or vanished: reported as `gone`.
    gone: Vec<Process>,
    foreign_services: Vec<String>,
    interval_start: Instant,
}

impl Status {
    fn new() -> Result<Self, StatusError> {
        Self::named(&format!("status-{}", std::process::id()))
    }

    /// Gathering through an iceoryx2 node named `name` (the process's name as others see it).
    pub fn named(name: &str) -> Result<Self, StatusError> {
        // The dead nodes first: creating our node reclaims them, and they would vanish.
        let gone = list_processes(&ipc::config()?, None)?
            .into_iter()
            .filter(|p| p.state == "dead")
            .map(|p| Process { state: "gone", ..p })
            .collect();
        let node = IpcNode::new(name)?;
        Ok(Self {
            node,
            services: BTreeMap::new(),
            processes: Vec::new(),
            gone,
            foreign_services: Vec::new(),
            interval_start: Instant::now(),
        })
    }

    /// The iceoryx2 node it gathers through.
    pub fn node(&self) -> &IpcNode {
        &self.node
    }

    /// The newest sample of every service watched, by service name.
    pub fn latest_samples(&self) -> impl Iterator<Item = (&str, AnySample)> + '_ {
        self.services
            .iter()
            .filter_map(|(name, w)| w.monitor.latest().map(|s| (name.as_str(), s)))
    }

    /// Finds processes and services; subscribes to new services, forgets vanished ones.
    pub fn discover(&mut self) -> Result<(), StatusError> {
        let config = ipc::config()?;
        let own = *self.node.node().id();
        let processes = list_processes(&config, Some(own))?;
        // What was there at the last discovery and is not now has gone.
        for p in &self.processes {
            let same = |q: &Process| q.name == p.name && q.pid == p.pid;
            if p.state != "gone" && !processes.iter().any(same) && !self.gone.iter().any(same) {
                self.gone.push(Process {
                    state: "gone",
                    ..p.clone()
                });
            }
        }
        self.processes = processes;

        let mut found: BTreeMap<String, Vec<String>> = BTreeMap::new();
        let mut foreign = Vec::new();
        Transport::list(&config, |s| {
            if matches!(
                s.static_details.messaging_pattern(),
                MessagingPattern::PublishSubscribe(_)
            ) {
                let name = s.static_details.name().as_str().to_string();
                let mut nodes = Vec::new();
                if let Some(d) = &s.dynamic_details {
                    for n in &d.nodes {
                        if *n.node_id() == own {
                            continue;
                        }
                        if let NodeState::Alive(v) = n
                            && let Some(det) = v.details()
                        {
                            nodes.push(det.name().as_str().to_string());
                        }
                    }
                }
                nodes.sort();
                nodes.dedup();
                if ServiceKind::of(&name).is_some() {
                    found.insert(name, nodes);
                } else {
                    foreign.push(name);
                }
            }
            CallbackProgression::Continue
        })
        .map_err(|e| StatusError::Discovery(format!("listing services: {e:?}")))?;
        foreign.sort();
        self.foreign_services = foreign;
        self.services.retain(|name, _| found.contains_key(name));
        for (name, nodes) in found {
            if let Some(w) = self.services.get_mut(&name) {
                w.nodes = nodes;
                continue;
            }
            let kind = ServiceKind::of(&name).expect("filtered above");
            match open_monitor(&self.node, &name, kind) {
                Ok(mut monitor) => {
                    // What arrives at once is history (the newest sample before we came), not rate.
                    monitor.poll();
                    self.services.insert(
                        name,
                        Watched {
                            kind,
                            monitor,
                            interval: Arrivals::default(),
                            total: 0,
                            last_arrival: None,
                            nodes,
                        },
                    );
                }
                Err(e) => tracing::debug!("cannot open {name}: {e}"),
            }
        }
        Ok(())
    }

    /// Takes what arrived on every service watched.
    pub fn poll(&mut self) {
        for w in self.services.values_mut() {
            let a = w.monitor.poll();
            if a.published > 0 {
                w.interval.merge(a);
                w.total += a.published;
                w.last_arrival = Some(Instant::now());
            }
        }
    }

    /// The report over the interval since the last one, as JSON; starts the next interval.
    pub fn report(&mut self) -> Value {
        let now_ns = monotonic_now_ns();
        let now = Instant::now();
        let span = now.duration_since(self.interval_start).as_secs_f64().max(1e-3);
        let age = |h: i64| now_ns.saturating_sub(h) as f64 * 1e-9;
        let mut services = Vec::new();
        let (mut health, mut time, mut nav) = (Vec::new(), None, None);
        let (mut pulses, mut marks) = (Vec::new(), Vec::new());
        for (name, w) in &mut self.services {
            let (publishers, subscribers) = w.monitor.ports();
            services.push(json!({
                "name": name,
                "type": w.kind.type_name(),
                "publishers": publishers,
                "subscribers": subscribers.saturating_sub(1),
                "nodes": w.nodes,
                "rate_hz": rate_hz(w.interval, span),
                "samples": w.interval.published,
                "received_total": w.total,
                "last_sample_age_s": w.monitor.last_host_ns().map(age),
                "last_received_s": w.last_arrival.map(|t| now.duration_since(t).as_secs_f64()),
            }));
            w.interval = Arrivals::default();
            match w.monitor.latest() {
                Some(AnySample::Health(h)) => health.push(health_json(&h, now_ns)),
                Some(AnySample::Time(t)) => time = Some(time_json(&t, now_ns)),
                Some(AnySample::Nav(n)) => nav = Some(nav_json(&n, now_ns)),
                Some(AnySample::TimePulse(t)) => pulses.push(time_pulse_json(name, &t, now_ns)),
                Some(AnySample::Event(e)) => marks.push(time_mark_json(name, &e, now_ns)),
                _ => {}
            }
        }
        self.interval_start = now;
        let processes: Vec<Value> = self
            .processes
            .iter()
            .chain(&self.gone)
            .map(|p| {
                let h = health
                    .iter()
                    .find(|h| h["process"] == p.name.as_str() && h["pid"].as_i64() == p.pid.map(i64::from));
                let (state, why) = refine_state(
                    p.state,
                    p.pid.and_then(proc_state),
                    h.and_then(|h| h["report_age_s"].as_f64()),
                );
                json!({
                    "name": p.name,
                    "pid": p.pid,
                    "executable": p.executable,
                    "state": state,
                    "why": why,
                    "uptime_s": h.and_then(|h| h["uptime_s"].as_f64()),
                })
            })
            .collect();
        json!({
            "prefix": ipc::prefix(),
            "host_ns": now_ns,
            "interval_s": span,
            "processes": processes,
            "services": services,
            "other_services": self.foreign_services,
            "health": health,
            "time": time,
            "time_pulses": pulses,
            "time_marks": marks,
            "nav": nav,
        })
    }
}

/// The rate of what was published in a window of `span_s` seconds: the intervals between
/// samples over the host time they span (a count over the window would show 1 Hz as 1.5 Hz
/// when 3 samples of a 1 Hz service fall in a 2 s window). Without an interval (or stamps
/// that do not advance, or a stamp that means "no host time"), the count over the window.
fn rate_hz(a: Arrivals, span_s: f64) -> f64 {
    match a.span {
        Some((first, last)) if a.intervals >= 1 && last > first && first != i64::MIN => {
            a.intervals as f64 / (last.saturating_sub(first) as f64 * 1e-9)
        }
        _ => a.published as f64 / span_s.max(1e-3),
    }
}

fn f(x: f64) -> Value {
    if x.is_finite() { json!(x) } else { Value::Null }
}

fn imu_table(t: &[ImuSync]) -> Vec<Value> {
    t.iter()
        .map(|e| {
            json!({
                "id": str_of(&e.imu_id),
                "offset_s": f(e.offset_s),
                "offset_std_s": f(e.offset_std_s),
                "in_array": e.in_array == 1,
                "reason": ImuSyncReason::name(e.reason),
                "observable": e.observable == 1,
            })
        })
        .collect()
}

fn health_json(h: &Health, now_ns: i64) -> Value {
    let counters: Map<String, Value> = h
        .counters
        .iter()
        .filter(|c| c.name[0] != 0)
        .map(|c| (str_of(&c.name).to_string(), json!(c.value)))
        .collect();
    let rates: Map<String, Value> = h
        .rates
        .iter()
        .filter(|r| r.name[0] != 0)
        .map(|r| (str_of(&r.name).to_string(), f(r.hz)))
        .collect();
    json!({
        "process": str_of(&h.process),
        "pid": h.pid,
        "alive": h.alive == 1,
        "uptime_s": (h.host_ns - h.started_host_ns) as f64 * 1e-9,
        "report_age_s": now_ns.saturating_sub(h.host_ns) as f64 * 1e-9,
        "reports": h.seq,
        "counters": counters,
        "rates": rates,
    })
}

fn time_json(t: &TimeState, now_ns: i64) -> Value {
    json!({
        "status": t.status().name(),
        "state_age_s": now_ns.saturating_sub(t.computed_host_ns) as f64 * 1e-9,
        "utc_now_ns": t.is_valid().then(|| t.utc_ns_at(now_ns)),
        "utc_std_ns": if t.is_valid() { f(t.utc_std_ns_at(now_ns)) } else { Value::Null },
        "offset_std_ns": f(t.offset_std_ns),
        "drift_ppm": f(t.rate_error * 1e6),
        "drift_std_ppm": f(t.rate_std * 1e6),
        "last_pps_age_s": (t.last_pps_host_ns != 0).then(|| now_ns.saturating_sub(t.last_pps_host_ns) as f64 * 1e-9),
        "pps_used": t.pps_used,
        "pps_rejected": t.pps_rejected,
        "receiver_latency_d0_s": {
            "min": f(t.latency_min_s),
            "median": f(t.latency_median_s),
            "p99": f(t.latency_p99_s),
            "max": f(t.latency_max_s),
            "epochs": t.latency_count,
        },
        "gnss_delay_s": f(t.gnss_delay_s),
        "gnss_delay_std_s": f(t.gnss_delay_std_s),
        "leap_s": t.leap_s,
        "imu": imu_table(&t.imu[..usize::from(t.imu_count).min(MAX_IMUS)]),
    })
}

/// A receiver's latest report of its next time pulse (UBX TIM-TP): the quantisation error
/// (qErr, the sawtooth correction the estimator applies to that PPS edge), ns.
fn time_pulse_json(service: &str, t: &GnssTimePulse, now_ns: i64) -> Value {
    json!({
        "service": service,
        "q_err_ns": (t.q_err_ps != i32::MIN).then(|| f64::from(t.q_err_ps) * 1e-3),
        "pulse_utc_ns": (t.pulse_utc_ns != i64::MIN).then_some(t.pulse_utc_ns),
        "time_base": match t.time_base { 0 => "gnss", _ => "utc" },
        "age_s": now_ns.saturating_sub(t.stamp.host_ns) as f64 * 1e-9,
    })
}

/// A receiver's latest time mark (UBX TIM-TM2): channel, count, accuracy, edges in GPS and host time.
fn time_mark_json(service: &str, e: &GnssEvent, now_ns: i64) -> Value {
    let known = |v: i64| (v != i64::MIN).then_some(v);
    json!({
        "service": service,
        "channel": e.channel,
        "count": e.count,
        "accuracy_ns": e.accuracy_ns,
        "rising_gps_ns": known(e.rising_gps_ns),
        "rising_host_ns": known(e.rising_host_ns),
        "falling_gps_ns": known(e.falling_gps_ns),
        "falling_host_ns": known(e.falling_host_ns),
        "age_s": now_ns.saturating_sub(e.stamp.host_ns) as f64 * 1e-9,
    })
}

fn nav_json(n: &NavState, now_ns: i64) -> Value {
    json!({
        "status": NavStatus::name(n.status),
        "time_status": TimeStatus::from_u8(n.time_status).name(),
        "state_age_s": now_ns.saturating_sub(n.host_ns) as f64 * 1e-9,
        "utc_ns": (n.utc_ns != i64::MIN).then_some(n.utc_ns),
        "lat_deg": f(n.lat_deg),
        "lon_deg": f(n.lon_deg),
        "height_m": f(n.height_m),
        "vel_ned_mps": n.vel_ned_mps.map(f),
        "rpy_deg": n.rpy_rad.map(|r| f(r.to_degrees())),
        "pos_std_ned_m": n.pos_std_ned_m.map(f),
        "fixes_used": n.fixes_used,
        "fixes_rejected": n.fixes_rejected,
        "last_fix_age_s": (n.last_fix_host_ns != 0).then(|| now_ns.saturating_sub(n.last_fix_host_ns) as f64 * 1e-9),
        "gnss_delay_s": f(n.gnss_delay_s),
        "gnss_delay_std_s": f(n.gnss_delay_std_s),
        "imu": imu_table(&n.imu[..usize::from(n.imu_count).min(MAX_IMUS)]),
    })
}

fn num(v: &Value, digits: usize) -> String {
    v.as_f64().map_or("-".into(), |x| format!("{x:.digits$}"))
}

fn seconds(v: &Value) -> String {
    match v.as_f64() {
        None => "-".into(),
        Some(x) if x.abs() < 1.0 => format!("{:.1} ms", x * 1e3),
        Some(x) if x.abs() < 120.0 => format!("{x:.2} s"),
        Some(x) => format!("{:.0} s", x),
    }
}

/// The nodes under this prefix (but `own`), by name and pid, with iceoryx2's state.
fn list_processes(
    config: &Config,
    own: Option<iceoryx2::identifiers::UniqueNodeId>,
) -> Result<Vec<Process>, StatusError> {
    let mut processes = Vec::new();
    Node::<Transport>::list(config, |state| {
        let (view, st) = match &state {
            NodeState::Alive(v) => (Some(v.details().clone()), "alive"),
            NodeState::Dead(v) => (Some(v.details().clone()), "dead"),
            NodeState::Inaccessible(_) => (None, "inaccessible"),
            NodeState::Undefined(_) => (None, "undefined"),
        };
        if Some(*state.node_id()) == own {
            return CallbackProgression::Continue;
        }
        let details = view.flatten();
        processes.push(Process {
            name: details
                .as_ref()
                .map_or(String::new(), |d| d.name().as_str().to_string()),
            pid: details.as_ref().map(|d| d.process_id().value()),
            executable: details.as_ref().map_or(String::new(), |d| d.executable().to_string()),
            state: st,
        });
        CallbackProgression::Continue
    })
    .map_err(|e| StatusError::Discovery(format!("listing nodes: {e:?}")))?;
    processes.sort_by(|a, b| (&a.name, a.pid).cmp(&(&b.name, b.pid)));
    // One process, one row: a process may hold two nodes of the same name (the stock
    // transport's beside navsync's, for a `NavState`/`TimeState` publisher's Python wake-up).
    processes.dedup_by(|later, kept| {
        let same = later.pid.is_some() && later.name == kept.name && later.pid == kept.pid;
        if same && kept.state != "alive" {
            kept.state = later.state;
        }
        same
    });
    Ok(processes)
}

/// The report as text.
pub fn render_text(r: &Value) -> String {
    let mut s = String::new();
    let procs = r["processes"].as_array().map_or(&[][..], |v| v);
    let services = r["services"].as_array().map_or(&[][..], |v| v);
    let _ = writeln!(
        s,
        "navsync status: prefix {}, {} processes, {} services (measured over {:.1} s)",
        r["prefix"].as_str().unwrap_or(""),
        procs.len(),
        services.len(),
        r["interval_s"].as_f64().unwrap_or(0.0)
    );
    let _ = writeln!(s, "\n{:<24} {:>8} {:<13} {:>10}", "PROCESS", "PID", "STATE", "UPTIME");
    for p in procs {
        let _ = writeln!(
            s,
            "{:<24} {:>8} {:<13} {:>10}{}",
            p["name"].as_str().unwrap_or(""),
            p["pid"].as_i64().map_or("-".into(), |x| x.to_string()),
            p["state"].as_str().unwrap_or(""),
            seconds(&p["uptime_s"]),
            p["why"].as_str().map_or(String::new(), |w| format!("  {w}"))
        );
    }
    // The columns as wide as their longest entry (a type name such as
    // navsync.GnssTimePulse.v1 overflowed a fixed width and shifted the row).
    let width = |key: &str, header: &str| {
        services
            .iter()
            .filter_map(|v| v[key].as_str())
            .map(|x| x.chars().count())
            .chain([header.len()])
            .max()
            .unwrap_or(0)
    };
    let (nw, tw) = (width("name", "SERVICE"), width("type", "TYPE"));
    let _ = writeln!(
        s,
        "\n{:<nw$} {:<tw$} {:>3} {:>3} {:>9} {:>10}  NODES",
        "SERVICE", "TYPE", "PUB", "SUB", "RATE Hz", "LAST AGE"
    );
    for v in services {
        let nodes: Vec<&str> = v["nodes"]
            .as_array()
            .map(|a| a.iter().filter_map(Value::as_str).collect())
            .unwrap_or_default();
        let _ = writeln!(
            s,
            "{:<nw$} {:<tw$} {:>3} {:>3} {:>9} {:>10}  {}",
            v["name"].as_str().unwrap_or(""),
            v["type"].as_str().unwrap_or(""),
            v["publishers"].to_string(),
            v["subscribers"].to_string(),
            num(&v["rate_hz"], 1),
            seconds(&v["last_sample_age_s"]),
            nodes.join(",")
        );
    }
    if let Some(other) = r["other_services"].as_array().filter(|a| !a.is_empty()) {
        let names: Vec<&str> = other.iter().filter_map(Value::as_str).collect();
        let _ = writeln!(s, "(other services under this prefix: {})", names.join(", "));
    }
    let t = &r["time"];
    if t.is_object() {
        let d0 = &t["receiver_latency_d0_s"];
        let _ = writeln!(
            s,
            "\nTIME  {}  σ {} ns  drift {} ppm  last PPS {} ago  PPS used {} rejected {}",
            t["status"].as_str().unwrap_or(""),
            num(&t["utc_std_ns"], 1),
            num(&t["drift_ppm"], 4),
            seconds(&t["last_pps_age_s"]),
            t["pps_used"],
            t["pps_rejected"]
        );
        let _ = writeln!(
            s,
            "      receiver latency d0: min {} s  median {} s  p99 {} s  max {} s  ({} epochs)",
            num(&d0["min"], 6),
            num(&d0["median"], 6),
            num(&d0["p99"], 6),
            num(&d0["max"], 6),
            d0["epochs"]
        );
        if !r["nav"].is_object() {
            // Else it is on the NAV line (the same estimate).
            let _ = writeln!(
                s,
                "      GNSS delay Δ {} ± {} s",
                num(&t["gnss_delay_s"], 4),
                num(&t["gnss_delay_std_s"], 4)
            );
        }
    } else {
        let _ = writeln!(s, "\nTIME  no time state");
    }
    for p in r["time_pulses"].as_array().map_or(&[][..], |v| v) {
        let _ = writeln!(
            s,
            "      time pulse ({}): qErr {} ns, {} time base, reported {} ago",
            p["service"].as_str().unwrap_or(""),
            num(&p["q_err_ns"], 3),
            p["time_base"].as_str().unwrap_or(""),
            seconds(&p["age_s"])
        );
    }
    for m in r["time_marks"].as_array().map_or(&[][..], |v| v) {
        let _ = writeln!(
            s,
            "      time mark ({}): channel {} count {} ±{} ns, host time {}, reported {} ago",
            m["service"].as_str().unwrap_or(""),
            m["channel"],
            m["count"],
            m["accuracy_ns"],
            if m["rising_host_ns"].is_null() {
                "unknown"
            } else {
                "mapped"
            },
            seconds(&m["age_s"])
        );
    }
    let n = &r["nav"];
    if n.is_object() {
        let p = &n["pos_std_ned_m"];
        let hstd = p[0].as_f64().zip(p[1].as_f64()).map(|(a, b)| a.hypot(b));
        let v = &n["vel_ned_mps"];
        let speed = v[0].as_f64().zip(v[1].as_f64()).map(|(a, b)| a.hypot(b));
        let _ = writeln!(
            s,
            "NAV   {} ({} time)  {} {} {} m  ±{} m  speed {} m/s  yaw {}°  fixes {} ({} rejected), last {} ago  state age {}",
            n["status"].as_str().unwrap_or(""),
            n["time_status"].as_str().unwrap_or(""),
            num(&n["lat_deg"], 7),
            num(&n["lon_deg"], 7),
            num(&n["height_m"], 2),
            hstd.map_or("-".into(), |x| format!("{x:.2}")),
            speed.map_or("-".into(), |x| format!("{x:.2}")),
            num(&n["rpy_deg"][2], 1),
            n["fixes_used"],
            n["fixes_rejected"],
            seconds(&n["last_fix_age_s"]),
            seconds(&n["state_age_s"])
        );
        let _ = writeln!(
            s,
            "      GNSS delay Δ {} ± {} s",
            num(&n["gnss_delay_s"], 4),
            num(&n["gnss_delay_std_s"], 4)
        );
        if let Some(imus) = n["imu"].as_array().filter(|a| !a.is_empty()) {
            let _ = writeln!(s, "      IMU  offset Td         ±2σ        array      observable");
            for e in imus {
                let _ = writeln!(
                    s,
                    "      {:<4} {:>9} ms  {:>9} ms  {:<10} {}",
                    e["id"].as_str().unwrap_or(""),
                    e["offset_s"].as_f64().map_or("-".into(), |x| format!("{:.4}", x * 1e3)),
                    e["offset_std_s"]
                        .as_f64()
                        .map_or("-".into(), |x| format!("{:.4}", 2.0 * x * 1e3)),
                    if e["in_array"] == true {
                        "in"
                    } else {
                        e["reason"].as_str().unwrap_or("")
                    },
                    if e["observable"] == true { "yes" } else { "frozen" }
                );
            }
        }
    } else {
        let _ = writeln!(s, "NAV   no navigation state");
    }
    let mut errors = String::new();
    for h in r["health"].as_array().map_or(&[][..], |v| v) {
        let nonzero: Vec<String> = h["counters"]
            .as_object()
            .map(|m| {
                m.iter()
                    .filter(|(_, v)| v.as_u64().is_some_and(|x| x > 0))
                    .map(|(k, v)| format!("{k}={v}"))
                    .collect()
            })
            .unwrap_or_default();
        let _ = writeln!(
            errors,
            "  {:<14} report {} ago{}  {}",
            h["process"].as_str().unwrap_or(""),
            seconds(&h["report_age_s"]),
            if h["alive"] == true { "" } else { " (exiting)" },
            if nonzero.is_empty() {
                "no counts".to_string()
            } else {
                nonzero.join(" ")
            }
        );
    }
    if !errors.is_empty() {
        let _ = writeln!(s, "\nHEALTH (counters that are not zero)\n{errors}");
    }
    s
}

/// Runs `navsync status`.
pub fn run(args: &StatusArgs) -> Result<(), StatusError> {
    let mut st = Status::new()?;
    st.discover()?;
    if args.watch.is_none() && st.processes.is_empty() && st.gone.is_empty() && st.services.is_empty() {
        return Err(StatusError::NothingRunning(ipc::prefix()));
    }
    let mut out = std::io::stdout().lock();
    let tty = std::io::IsTerminal::is_terminal(&std::io::stdout());
    let interval = args.watch.unwrap_or(args.window);
    let mut reports = 0u64;
    let mut last_discovery = Instant::now();
    navsync_shared::sd_notify::ready("status");
    loop {
        let until = st.interval_start + interval;
        while Instant::now() < until {
            if !st
                .node
                .sleep(Duration::from_millis(50).min(until.saturating_duration_since(Instant::now())))
            {
                return Ok(());
            }
            st.poll();
            if args.watch.is_some() && last_discovery.elapsed() >= Duration::from_secs(1) {
                st.discover()?;
                last_discovery = Instant::now();
            }
        }
        st.poll();
        let report = st.report();
        if args.json {
            writeln!(out, "{report}")?;
        } else {
            if args.watch.is_some() && tty {
                write!(out, "\x1b[H\x1b[2J")?;
            }
            write!(out, "{}", render_text(&report))?;
        }
        out.flush()?;
        reports += 1;
        if args.watch.is_none() || args.count.is_some_and(|c| reports >= c) {
            return Ok(());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stopped_or_silent_process_is_stalled_and_a_dead_one_gone() {
        assert_eq!(refine_state("alive", Some('S'), Some(0.4)), ("alive", None));
        assert_eq!(refine_state("alive", Some('R'), None), ("alive", None));
        let (s, why) = refine_state("alive", Some('T'), Some(0.4));
        assert_eq!(s, "stalled");
        assert!(why.unwrap().contains("stopped"));
        let (s, why) = refine_state("alive", Some('S'), Some(HEARTBEAT_STALE_S + 1.0));
        assert_eq!(s, "stalled");
        assert!(why.unwrap().contains("no heartbeat for 4.0 s"));
        assert_eq!(refine_state("dead", None, None).0, "gone");
        assert_eq!(refine_state("gone", None, None), ("gone", None));
        assert_eq!(refine_state("inaccessible", None, None), ("inaccessible", None));
    }

    #[test]
    fn service_columns_line_up_whatever_the_type_name() {
        let service = |name: &str, ty: &str| {
            json!({"name": name, "type": ty, "publishers": 1, "subscribers": 0, "rate_hz": 1.0,
                   "last_sample_age_s": 0.1, "nodes": ["gnss-0"]})
        };
        let r = json!({
            "prefix": "p_", "interval_s": 2.0, "processes": [],
            "services": [
                service("navsync/gnss/0/timepulse", "navsync.GnssTimePulse.v1"),
                service("navsync/nav/state", "navsync.NavState.v2"),
            ],
        });
        let text = render_text(&r);
        let rows: Vec<&str> = text
            .lines()
            .filter(|l| l.starts_with("SERVICE") || l.starts_with("navsync/"))
            .collect();
        assert_eq!(rows.len(), 3, "{text}");
        // The header's PUB and SUB columns hold each row's 1 and 0.
        let at = rows[0].find("PUB").expect("header");
        for row in &rows[1..] {
            assert_eq!(&row[at + 2..at + 3], "1", "{text}");
            assert_eq!(&row[at + 6..at + 7], "0", "{text}");
        }
    }

    #[test]
    fn the_rate_counts_intervals_between_samples() {
        let arrivals = |samples: &[(u64, i64)], prev: Option<(u64, i64)>| {
            let mut a = Arrivals::default();
            let mut p = prev;
            for &(seq, h) in samples {
                a.count(p, seq, h);
                p = Some((seq, h));
            }
            a
        };
        // 1 Hz: three samples 1 s apart fell in a 2.1 s window (a count said 1.43 Hz).
        let s = 1_000_000_000;
        let a = arrivals(&[(1, s), (2, 2 * s), (3, 3 * s)], Some((0, 0)));
        assert_eq!((a.published, a.intervals), (3, 3));
        assert!((rate_hz(a, 2.1) - 1.0).abs() < 1e-12);
        // Only the newest seen (a 1 kHz publisher polled once a second): counted by sequence.
        let a = arrivals(&[(1000, s)], Some((0, 0)));
        assert_eq!(a.published, 1000);
        assert!((rate_hz(a, 1.0) - 1000.0).abs() < 1e-9);
        // The first sample ever, or a restarted publisher: one, the count over the window.
        let a = arrivals(&[(7, 7)], None);
        assert!((rate_hz(a, 2.0) - 0.5).abs() < 1e-12);
        let a = arrivals(&[(0, s)], Some((5000, 0)));
        assert_eq!(a.published, 1);
        assert_eq!(rate_hz(Arrivals::default(), 2.0), 0.0);
        // Merged polls keep the first poll's start.
        let mut m = arrivals(&[(2, 2 * s)], Some((1, s)));
        m.merge(arrivals(&[(4, 4 * s)], Some((2, 2 * s))));
        assert_eq!((m.published, m.intervals, m.span), (3, 3, Some((s, 4 * s))));
        // A stamp that means "no host time" (an event without a pose) spans nothing.
        let a = arrivals(&[(2, 1_000)], Some((1, i64::MIN)));
        assert!((rate_hz(a, 2.0) - 0.5).abs() < 1e-12);
    }
}
