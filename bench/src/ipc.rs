//! `navsync-bench ipc`: publisher → subscriber latency between separate processes, iceoryx2
//! (navsync's services: shared-memory sample + futex wake-up; the subscriber asleep on the
//! service's event as a client is, on the one wake-up as the estimator is, or spinning)
//! against a Unix-domain socket carrying the same bytes (SOCK_SEQPACKET, the subscriber asleep
//! in a blocking `recv`), for `ImuSample` (112 B), `NavState` (640 B), `GnssRaw` (2608 B) and
//! a 64 KiB message, 1 to 16 subscriber processes, paced at a fixed rate and unpaced. The
//! iceoryx2 subscribers read the stamp in place in shared memory; the socket's receive the
//! whole message.
//!
//! Every case starts its own processes (`navsync-bench helper ipc-pub|ipc-sub`) under a
//! fresh iceoryx2 prefix: the subscribers first (they print `ready` once listening), then the
//! publisher. The publisher writes `CLOCK_MONOTONIC` into the payload (`stamp.host_ns`,
//! `host_ns`) right before publishing and a sequence number; each subscriber takes
//! `CLOCK_MONOTONIC` when it has the sample in hand and keeps every difference (exact
//! percentiles, nothing binned). Lost samples (iceoryx2's publisher never blocks: a full
//! subscriber buffer loses its oldest sample) are counted from the sequence numbers; the
//! socket's sender blocks instead.
//!
//! With `--rounds N` every case runs N times with a share of the samples, the transports
//! alternating round by round in a rotated order, and its figures pool the rounds: on a
//! shared VM whose host noise drifts over minutes, the transports then see the same host.

use std::io::BufReader;
use std::path::{Path, PathBuf};
use std::time::Duration;

use navsync_shared::ipc::{IpcError, IpcNode};
use navsync_shared::pacing;
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::{GnssRaw, ImuSample, NavState};
use navsync_shared::services;
use navsync_shared::time::monotonic_now_ns;
use serde::Serialize;

use crate::util::{self, BenchEnv, Machine, Percentiles};

pub mod floor;

/// How long a bench publisher stays after its last sample unless stopped earlier: longer than
/// the bench waits for its subscribers.
const PUBLISHER_LINGER: Duration = Duration::from_secs(30);

/// Which sample type a case carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    /// `ImuSample` (112 bytes) on `navsync/imu/bench/sample`.
    Imu,
    /// `NavState` on `navsync/nav/state`.
    Nav,
    /// `GnssRaw` (a raw-measurement epoch, 2608 B) on `navsync/gnss/bench/raw`.
    Raw,
    /// [`Blob64k`] (64 KiB, an image-sized message) on [`BLOB_SERVICE`].
    Blob,
}

/// A 64 KiB message for the IPC benchmark (where copying through the kernel costs most).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct Blob64k {
    /// Publish time, CLOCK_MONOTONIC ns.
    pub host_ns: i64,
    /// Sequence number.
    pub seq: u64,
    /// Filler, bytes.
    pub data: [u8; 65520],
}

impl Reflect for Blob64k {
    // Not recorded or bridged (a benchmark service): no field table needed.
    const FIELDS: &'static [navsync_shared::reflect::Field] = &[];
    const TYPE_NAME: &'static str = "navsync.bench.Blob64k.v1";
    const DOC: &'static str = "A 64 KiB message for the IPC benchmark.";
    fn zeroed() -> Self {
        Self {
            host_ns: 0,
            seq: 0,
            data: [0; 65520],
        }
    }
}

/// The service [`Blob64k`] travels on (a benchmark service, see `services::BENCH_PREFIX`).
pub const BLOB_SERVICE: &str = "navsync/bench/blob";

/// The transport of a case.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Transport {
    /// navsync's iceoryx2 services, the subscriber asleep on the service's own event
    /// (`Subscriber::wait_next`, as the clients and `navsync echo`).
    Iceoryx2,
    /// navsync's iceoryx2 services, the subscriber asleep on the one wake-up of a process
    /// with many inputs (`IpcNode::wait` on `navsync/wake` with a timeout, as the estimator;
    /// the timeout through the alarm thread, `ipc::futex`).
    Iceoryx2Wake,
    /// As `iceoryx2-wake`, but every timed wait arms the kernel's timer
    /// (`futex::timeouts_by_kernel`): what the alarm thread saves.
    Iceoryx2WakeTimer,
    /// navsync's iceoryx2 services, the subscriber spinning on its queue (`--busy-poll`:
    /// `Subscriber::set_busy_poll`); a core per subscriber.
    Iceoryx2Busy,
    /// A Unix-domain SOCK_SEQPACKET socket per subscriber.
    Socket,
    /// The floor of any shared-memory transport: a ring in `/dev/shm` and one futex word for
    /// all subscribers, woken by one `FUTEX_WAKE` (`ipc/floor.rs`; not a product transport).
    FutexFloor,
}

/// A publishing rate: Hz, or `max` (back to back, no pacing).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rate {
    /// Paced at this many samples per second.
    Hz(f64),
    /// Unpaced.
    Max,
}

impl std::str::FromStr for Rate {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "max" {
            return Ok(Self::Max);
        }
        match s.parse::<f64>() {
            Ok(r) if r.is_finite() && r > 0.0 && r <= 1e6 => Ok(Self::Hz(r)),
            _ => Err(format!("`{s}`: a rate is a number of Hz (0 < r ≤ 1e6) or `max`")),
        }
    }
}

impl std::fmt::Display for Rate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Hz(r) => write!(f, "{r}"),
            Self::Max => f.write_str("max"),
        }
    }
}

impl Serialize for Rate {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.to_string())
    }
}

/// A sample type the benchmark can carry: where its time stamp and sequence number live.
trait Payload: navsync_shared::ipc::IpcSample {
    fn service() -> String;
    fn make(host_ns: i64, seq: u64) -> Self;
    fn stamp(&self) -> (i64, u64);
}

impl Payload for ImuSample {
    fn service() -> String {
        services::imu_sample("bench")
    }
    fn make(host_ns: i64, seq: u64) -> Self {
        let mut s = Self::zeroed();
        s.stamp.host_ns = host_ns;
        s.stamp.seq = seq;
        s.gyro_rps = [0.01, -0.02, 0.03];
        s.accel_mps2 = [0.1, 0.2, -9.8];
        s.dt_s = 1e-3;
        s.imu_id = *b"bench\0\0\0";
        s
    }
    fn stamp(&self) -> (i64, u64) {
        (self.stamp.host_ns, self.stamp.seq)
    }
}

impl Payload for GnssRaw {
    fn service() -> String {
        services::gnss_raw("bench")
    }
    fn make(host_ns: i64, seq: u64) -> Self {
        let mut s = Self::zeroed();
        s.stamp.host_ns = host_ns;
        s.stamp.seq = seq;
        s.num_meas = s.meas.len() as u8;
        for (i, m) in s.meas.iter_mut().enumerate() {
            m.pseudorange_m = 2.2e7 + i as f64;
            m.cno_dbhz = 40;
        }
        s
    }
    fn stamp(&self) -> (i64, u64) {
        (self.stamp.host_ns, self.stamp.seq)
    }
}

impl Payload for Blob64k {
    fn service() -> String {
        BLOB_SERVICE.to_string()
    }
    fn make(host_ns: i64, seq: u64) -> Self {
        let mut s = Self::zeroed();
        s.host_ns = host_ns;
        s.seq = seq;
        s.data[0] = seq as u8;
        s
    }
    fn stamp(&self) -> (i64, u64) {
        (self.host_ns, self.seq)
    }
}

impl Payload for NavState {
    fn service() -> String {
        services::NAV_STATE.to_string()
    }
    fn make(host_ns: i64, seq: u64) -> Self {
        let mut s = Self::zeroed();
        s.host_ns = host_ns;
        s.seq = seq;
        s.lat_deg = 48.137154;
        s.lon_deg = 11.576124;
        s.q_nb = [1.0, 0.0, 0.0, 0.0];
        s
    }
    fn stamp(&self) -> (i64, u64) {
        (self.host_ns, self.seq)
    }
}

/// The payload's bytes, as the socket sends them.
fn bytes_of<T: Payload>(v: &T) -> &[u8] {
    // SAFETY: every navsync sample is #[repr(C)] of integers and floats without padding
    // (shared/src/samples/layout_contract.rs), so all its bytes are initialised.
    unsafe { std::slice::from_raw_parts((v as *const T).cast::<u8>(), size_of::<T>()) }
}

/// `navsync-bench ipc`: IPC latency between processes, iceoryx2 services against a
/// Unix-domain socket.
#[derive(Debug, Clone, clap::Args)]
pub struct IpcBenchArgs {
    /// Samples per case.
    #[arg(long, default_value_t = 100_000, value_parser = clap::value_parser!(u64).range(1..))]
    pub samples: u64,
    /// Sample types, comma-separated: imu (112 B), nav (640 B), raw (GnssRaw, 2.6 KiB), blob (64 KiB).
    #[arg(long, value_delimiter = ',', default_value = "imu,nav")]
    pub kinds: Vec<Kind>,
    /// Publishing rates, Hz or `max` (back to back), comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "1000,max")]
    pub rates: Vec<Rate>,
    /// Subscriber process counts, comma-separated (at most 16).
    #[arg(long, value_delimiter = ',', default_value = "1", value_parser = crate::util::subscriber_count)]
    pub subscribers: Vec<usize>,
    /// Transports, comma-separated: iceoryx2 (the service's event), iceoryx2-wake (the one wake-up),
    /// iceoryx2-wake-timer (the same, timeouts on kernel timers), iceoryx2-busy, socket,
    /// futex-floor (the floor of any shared-memory transport).
    #[arg(long, value_delimiter = ',', default_value = "iceoryx2,socket")]
    pub transports: Vec<Transport>,
    /// Run publisher (PRIO) and subscribers (PRIO − 1) under SCHED_FIFO (needs CAP_SYS_NICE).
    #[arg(long, value_name = "PRIO", value_parser = clap::value_parser!(u8).range(1..=99))]
    pub realtime: Option<u8>,
    /// Split every case's samples into this many rounds and run the transports round by
    /// round, each round in another order (round r starts with the r-th transport), fresh
    /// processes each time; a case's figures pool its rounds. On a shared host whose noise
    /// drifts over minutes, this puts the transports under the same conditions.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=1000))]
    pub rounds: u64,
    /// A short run (2000 samples per case) for smoke tests.
    #[arg(long)]
    pub quick: bool,
    /// Write the results as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// One case's figures.
#[derive(Debug, Clone, Serialize)]
pub struct IpcCase {
    /// Transport.
    pub transport: Transport,
    /// Sample type.
    pub kind: Kind,
    /// Payload size, bytes.
    pub payload_bytes: usize,
    /// Requested rate.
    pub rate: Rate,
    /// Subscriber processes.
    pub subscribers: usize,
    /// SCHED_FIFO priority of publisher and subscribers, if they ran under it.
    pub realtime: Option<u8>,
    /// Samples published.
    pub sent: u64,
    /// Samples received, summed over the subscribers.
    pub received: u64,
    /// Samples lost (sent × subscribers − received).
    pub lost: u64,
    /// Publish errors.
    pub publish_errors: u64,
    /// Achieved publishing rate, samples/s.
    pub achieved_rate_hz: f64,
    /// Latency over every received sample of every subscriber.
    pub latency: Percentiles,
    /// Publisher CPU per sample, µs.
    pub publisher_cpu_us_per_sample: f64,
    /// Subscriber CPU per received sample, µs (mean over the subscribers).
    pub subscriber_cpu_us_per_sample: f64,
}

/// Everything `navsync-bench ipc` measured.
#[derive(Debug, Clone, Serialize)]
pub struct IpcReport {
    /// The machine and its load.
    pub machine: Machine,
    /// The cases in the order they ran.
    pub cases: Vec<IpcCase>,
    /// With `--rounds` ≥ 2: the first transport against each other one, round by round.
    pub paired: Vec<Paired>,
}

/// Which metrics [`Paired`] compares, in its arrays' order.
pub const PAIRED_METRICS: [&str; 4] = ["p50", "p99", "p99.9", "subscriber CPU"];

/// The first transport of a run against another, round by round. Both ran in every round,
/// back to back, so a round's pair saw the same host; a pooled percentile can be decided by
/// a few rounds the host disturbed, the per-round comparison shows whether a difference is
/// systematic. Arrays follow [`PAIRED_METRICS`].
#[derive(Debug, Clone, Serialize)]
pub struct Paired {
    /// Sample type.
    pub kind: Kind,
    /// Requested rate.
    pub rate: Rate,
    /// Subscriber processes.
    pub subscribers: usize,
    /// The transport compared (the run's first).
    pub transport: Transport,
    /// The transport it is compared against.
    pub against: Transport,
    /// Rounds compared.
    pub rounds: u64,
    /// Rounds in which `transport`'s figure was at or below `against`'s.
    pub at_or_below: [u64; 4],
    /// Median over the rounds of `transport`'s figure / `against`'s.
    pub median_ratio: [f64; 4],
    /// One-sided sign test of "`transport` is worse": the probability of at least as many
    /// rounds above `against` if either were equally likely to be above (ties left out).
    pub p_worse: [f64; 4],
}

/// One round's figures of one transport: p50, p99, p99.9 latency (µs) and subscriber CPU
/// per received sample (µs).
fn round_figures(run: &mut CaseRun) -> [f64; 4] {
    let p = Percentiles::from_ns(&mut run.latencies_ns);
    [
        p.p50_us,
        p.p99_us,
        p.p999_us,
        run.subscriber_cpu_s / run.received.max(1) as f64 * 1e6,
    ]
}

/// P(X ≥ k) for X ~ Binomial(n, ½): the one-sided sign test.
pub fn sign_test_p(k: u64, n: u64) -> f64 {
    if k == 0 {
        return 1.0;
    }
    if k > n {
        return 0.0;
    }
    // pmf(i + 1) = pmf(i) · (n − i)/(i + 1), from pmf(0) = 2⁻ⁿ (n ≤ 1000: no underflow).
    let mut pmf = 0.5f64.powi(n.min(1000) as i32);
    let mut tail = 0.0;
    for i in 0..=n {
        if i >= k {
            tail += pmf;
        }
        pmf *= (n - i) as f64 / (i + 1) as f64;
    }
    tail.min(1.0)
}

impl Paired {
    fn of(
        (kind, rate, subscribers): (Kind, Rate, usize),
        (transport, against): (Transport, Transport),
        a: &[[f64; 4]],
        b: &[[f64; 4]],
    ) -> Self {
        let mut at_or_below = [0u64; 4];
        let mut median_ratio = [f64::NAN; 4];
        let mut p_worse = [1.0; 4];
        for m in 0..4 {
            let (mut above, mut below) = (0u64, 0u64);
            let mut ratios: Vec<f64> = Vec::with_capacity(a.len());
            for (x, y) in a.iter().zip(b) {
                let (x, y) = (x[m], y[m]);
                if x <= y {
                    at_or_below[m] += 1;
                }
                above += u64::from(x > y);
                below += u64::from(x < y);
                if y > 0.0 {
                    ratios.push(x / y);
                }
            }
            ratios.sort_by(f64::total_cmp);
            if !ratios.is_empty() {
                let h = ratios.len() / 2;
                median_ratio[m] = if ratios.len() % 2 == 1 {
                    ratios[h]
                } else {
                    0.5 * (ratios[h - 1] + ratios[h])
                };
            }
            p_worse[m] = sign_test_p(above, above + below);
        }
        Self {
            kind,
            rate,
            subscribers,
            transport,
            against,
            rounds: a.len().min(b.len()) as u64,
            at_or_below,
            median_ratio,
            p_worse,
        }
    }
}

/// Errors of the benchmark.
#[derive(Debug, thiserror::Error)]
pub enum IpcBenchError {
    /// Starting or talking to a child failed.
    #[error("{0}")]
    Child(String),
    /// I/O.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// IPC.
    #[error(transparent)]
    Ipc(#[from] IpcError),
}

fn child_err(e: impl std::fmt::Display) -> IpcBenchError {
    IpcBenchError::Child(e.to_string())
}

/// Runs every case of `args` and prints the table; returns the report.
pub fn run(args: &IpcBenchArgs) -> Result<IpcReport, IpcBenchError> {
    let mut args = args.clone();
    if args.quick {
        args.samples = 2000;
    }
    let args = &args;
    let mut report = IpcReport {
        machine: Machine::now(),
        cases: Vec::new(),
        paired: Vec::new(),
    };
    let _wakeup = util::wakeup_hold(args.realtime.is_some(), &mut report.machine);
    let rounds = args.rounds.min(args.samples);
    let n_t = args.transports.len();
    for &kind in &args.kinds {
        for &rate in &args.rates {
            for &subs in &args.subscribers {
                // Transports alternate case by case (and round by round, each round in a
                // rotated order), so that all see the same load.
                let mut runs: Vec<Vec<CaseRun>> = vec![Vec::new(); n_t];
                for r in 0..rounds {
                    let samples = args.samples / rounds + u64::from(r < args.samples % rounds);
                    for k in 0..n_t {
                        let i = (k + r as usize) % n_t;
                        let run = run_case(args.transports[i], kind, rate, subs, samples, args.realtime)?;
                        runs[i].push(run);
                    }
                }
                if rounds >= 2 {
                    let figures: Vec<Vec<[f64; 4]>> = runs
                        .iter_mut()
                        .map(|rs| rs.iter_mut().map(round_figures).collect())
                        .collect();
                    for i in 1..n_t {
                        report.paired.push(Paired::of(
                            (kind, rate, subs),
                            (args.transports[0], args.transports[i]),
                            &figures[0],
                            &figures[i],
                        ));
                    }
                }
                for (&transport, runs) in args.transports.iter().zip(&mut runs) {
                    let case = pool(transport, kind, rate, subs, args.realtime, runs);
                    eprintln!("{}", row(&case));
                    report.cases.push(case);
                }
            }
        }
    }
    report.machine.finish();
    println!("{}", table(&report));
    if let Some(p) = &args.json {
        util::write_json(p, &report)?;
    }
    Ok(report)
}

fn arg<T: ToString>(v: T) -> String {
    v.to_string()
}

fn kind_name(k: Kind) -> &'static str {
    match k {
        Kind::Imu => "imu",
        Kind::Nav => "nav",
        Kind::Raw => "raw",
        Kind::Blob => "blob",
    }
}

fn transport_name(t: Transport) -> &'static str {
    match t {
        Transport::Iceoryx2 => "iceoryx2",
        Transport::Iceoryx2Wake => "iceoryx2-wake",
        Transport::Iceoryx2WakeTimer => "iceoryx2-wake-timer",
        Transport::Iceoryx2Busy => "iceoryx2-busy",
        Transport::Socket => "socket",
        Transport::FutexFloor => "futex-floor",
    }
}

/// What one run of a case (fresh processes) measured, before pooling into an [`IpcCase`].
#[derive(Debug, Clone)]
struct CaseRun {
    sent: u64,
    received: u64,
    publish_errors: u64,
    /// The publisher's time from first to last sample, s.
    wall_s: f64,
    /// CPU time, s.
    publisher_cpu_s: f64,
    /// CPU time summed over the subscribers, s.
    subscriber_cpu_s: f64,
    /// Every received sample's latency at every subscriber, ns.
    latencies_ns: Vec<i64>,
}

fn payload_bytes(kind: Kind) -> usize {
    match kind {
        Kind::Imu => size_of::<ImuSample>(),
        Kind::Nav => size_of::<NavState>(),
        Kind::Raw => size_of::<GnssRaw>(),
        Kind::Blob => size_of::<Blob64k>(),
    }
}

/// A case's figures over its runs (rounds).
fn pool(
    transport: Transport,
    kind: Kind,
    rate: Rate,
    subscribers: usize,
    realtime: Option<u8>,
    runs: &mut [CaseRun],
) -> IpcCase {
    let sum = |f: fn(&CaseRun) -> u64| runs.iter().map(f).sum::<u64>();
    let sumf = |f: fn(&CaseRun) -> f64| runs.iter().map(f).sum::<f64>();
    let (sent, received, errors) = (sum(|r| r.sent), sum(|r| r.received), sum(|r| r.publish_errors));
    let (wall, pub_cpu, sub_cpu) = (
        sumf(|r| r.wall_s),
        sumf(|r| r.publisher_cpu_s),
        sumf(|r| r.subscriber_cpu_s),
    );
    let mut all: Vec<i64> = runs
        .iter_mut()
        .flat_map(|r| std::mem::take(&mut r.latencies_ns))
        .collect();
    IpcCase {
        transport,
        kind,
        payload_bytes: payload_bytes(kind),
        rate,
        subscribers,
        realtime,
        sent,
        received,
        lost: (sent * subscribers as u64).saturating_sub(received),
        publish_errors: errors,
        achieved_rate_hz: sent as f64 / wall,
        latency: Percentiles::from_ns(&mut all),
        publisher_cpu_us_per_sample: pub_cpu / sent.max(1) as f64 * 1e6,
        subscriber_cpu_us_per_sample: sub_cpu / received.max(1) as f64 * 1e6,
    }
}

/// Runs one case in fresh processes.
fn run_case(
    transport: Transport,
    kind: Kind,
    rate: Rate,
    subscribers: usize,
    samples: u64,
    realtime: Option<u8>,
) -> Result<CaseRun, IpcBenchError> {
    let mut env = BenchEnv::new("ipc")?;
    let payload_bytes = payload_bytes(kind);
    // The futex floor's ring, in /dev/shm (tmpfs) as iceoryx2's segments; removed on return.
    let ring = match transport {
        Transport::FutexFloor => {
            let path = PathBuf::from(format!(
                "/dev/shm/navsync-bench-floor-{}-{}",
                std::process::id(),
                monotonic_now_ns()
            ));
            floor::create(&path, payload_bytes)?;
            Some(RemoveOnDrop(path))
        }
        _ => None,
    };
    let mut outs = Vec::new();
    let mut sockets = Vec::new();
    for i in 0..subscribers {
        let lat = env.dir.join(format!("lat-{i}.bin"));
        let sock = env.dir.join(format!("sock-{i}"));
        let mut a = vec![
            arg("helper"),
            arg("ipc-sub"),
            arg("--transport"),
            arg(transport_name(transport)),
            arg("--kind"),
            arg(kind_name(kind)),
            arg("--count"),
            arg(samples),
            arg("--index"),
            arg(i),
            arg("--out"),
            lat.display().to_string(),
        ];
        if transport == Transport::Socket {
            a.extend([arg("--socket"), sock.display().to_string()]);
        }
        if let Some(r) = &ring {
            a.extend([arg("--shm"), r.0.display().to_string()]);
        }
        let name = format!("sub-{i}");
        let (pid, out) = env.spawn(&name, &a, true)?;
        if let Some(p) = realtime {
            util::set_fifo(pid, p.saturating_sub(1).max(1)).map_err(child_err)?;
        }
        let mut out = BufReader::new(out.ok_or_else(|| child_err("no stdout"))?);
        if !util::wait_for_line(&mut out, "ready", Duration::from_secs(20)) {
            return Err(child_err(format!("{name} did not get ready:\n{}", env.log(&name))));
        }
        outs.push((name, lat, out));
        sockets.push(sock.display().to_string());
    }
    let mut a = vec![
        arg("helper"),
        arg("ipc-pub"),
        arg("--transport"),
        arg(transport_name(transport)),
        arg("--kind"),
        arg(kind_name(kind)),
        arg("--count"),
        arg(samples),
        arg("--rate"),
        arg(rate),
    ];
    if transport == Transport::Socket {
        a.push(arg("--sockets"));
        a.push(sockets.join(","));
    }
    if let Some(r) = &ring {
        a.extend([arg("--shm"), r.0.display().to_string()]);
    }
    let (pid, pub_out) = env.spawn("pub", &a, true)?;
    if let Some(p) = realtime {
        // The publisher above its subscribers, as a driver above the estimator.
        util::set_fifo(pid, p).map_err(child_err)?;
    }
    let mut pub_out = BufReader::new(pub_out.ok_or_else(|| child_err("no stdout"))?);
    // The publisher prints its summary after the last sample and stays until stopped (below).
    let Some(pub_summary) = util::next_json_line(&mut pub_out) else {
        let st = env.wait_exit("pub", Duration::from_secs(5));
        return Err(child_err(format!(
            "publisher ended without a summary ({st:?}):\n{}",
            env.log("pub")
        )));
    };
    if matches!(transport, Transport::Socket | Transport::FutexFloor) {
        // Nothing to stay for: it closes its connections (ending the subscribers) or leaves
        // the ring file (the bench's), and exits.
        let st = env.wait_exit("pub", Duration::from_secs(10));
        if !st.is_some_and(|st| st.success()) {
            return Err(child_err(format!("publisher failed ({st:?}):\n{}", env.log("pub"))));
        }
    }
    // Subscribers stop at the last sequence number; one that lost it is told to stop.
    let mut all = Vec::new();
    let mut sub_cpu = 0.0;
    let mut received = 0u64;
    for (name, lat, out) in &mut outs {
        if env.wait_exit(name, Duration::from_millis(1000)).is_none() {
            env.terminate(name);
        }
        let st = env
            .wait_exit(name, Duration::from_secs(10))
            .ok_or_else(|| child_err(format!("{name} did not stop")))?;
        if !st.success() {
            return Err(child_err(format!("{name} failed ({st}):\n{}", env.log(name))));
        }
        let s = util::last_json_line(out).unwrap_or_default();
        sub_cpu += s["cpu_s"].as_f64().unwrap_or(f64::NAN);
        let v = util::read_latencies(lat)?;
        received += v.len() as u64;
        all.extend(v);
    }
    let case = CaseRun {
        sent: pub_summary["sent"].as_u64().unwrap_or(0),
        received,
        publish_errors: pub_summary["errors"].as_u64().unwrap_or(0),
        wall_s: pub_summary["wall_s"].as_f64().unwrap_or(f64::NAN),
        publisher_cpu_s: pub_summary["cpu_s"].as_f64().unwrap_or(f64::NAN),
        subscriber_cpu_s: sub_cpu,
        latencies_ns: all,
    };
    let bad = env.stop_all();
    if !bad.is_empty() {
        return Err(child_err(format!("did not exit cleanly: {bad:?}")));
    }
    Ok(case)
}

fn row(c: &IpcCase) -> String {
    let rate = match c.rate {
        Rate::Hz(r) => format!("{r} Hz"),
        Rate::Max => format!("max ({:.0}/s)", c.achieved_rate_hz),
    };
    format!(
        "| {} | {} ({} B) | {} | {} | {}/{} | {:.1} | {:.1} | {:.1} | {:.1} | {:.2} / {:.2} |",
        match c.realtime {
            Some(p) => format!("{}, FIFO {p}", transport_name(c.transport)),
            None => transport_name(c.transport).to_string(),
        },
        match c.kind {
            Kind::Imu => "ImuSample",
            Kind::Nav => "NavState",
            Kind::Raw => "GnssRaw",
            Kind::Blob => "Blob64k",
        },
        c.payload_bytes,
        rate,
        c.subscribers,
        c.received,
        c.sent * c.subscribers as u64,
        c.latency.p50_us,
        c.latency.p99_us,
        c.latency.p999_us,
        c.latency.max_us,
        c.publisher_cpu_us_per_sample,
        c.subscriber_cpu_us_per_sample,
    )
}

/// The Markdown table of a report.
pub fn table(r: &IpcReport) -> String {
    let mut s = String::from(
        "| transport | payload | rate | subscribers | received | p50 µs | p99 µs | p99.9 µs | max µs | CPU µs/sample pub / sub |\n\
         |---|---|---|---|---|---|---|---|---|---|\n",
    );
    for c in &r.cases {
        s.push_str(&row(c));
        s.push('\n');
    }
    if !r.paired.is_empty() {
        s.push_str(&paired_table(&r.paired));
    }
    s.push_str(&r.machine.line());
    s
}

/// The round-by-round comparison: per metric, rounds at or below, the median ratio and the
/// sign test's p of "worse".
fn paired_table(paired: &[Paired]) -> String {
    let mut s = format!(
        "\nround by round (cell: rounds at or below / rounds, median ratio, sign-test p of worse):\n\n\
         | payload | rate | subscribers | transport vs | {} |\n|---|---|---|---|---|---|---|---|\n",
        PAIRED_METRICS.join(" | ")
    );
    for p in paired {
        let cells: Vec<String> = (0..4)
            .map(|m| {
                format!(
                    "{}/{}, ×{:.3}, p {:.3}",
                    p.at_or_below[m], p.rounds, p.median_ratio[m], p.p_worse[m]
                )
            })
            .collect();
        s.push_str(&format!(
            "| {} | {} | {} | {} vs {} | {} |\n",
            kind_name(p.kind),
            match p.rate {
                Rate::Hz(r) => format!("{r} Hz"),
                Rate::Max => "max".to_string(),
            },
            p.subscribers,
            transport_name(p.transport),
            transport_name(p.against),
            cells.join(" | ")
        ));
    }
    s.push('\n');
    s
}

// ---------------------------------------------------------------- helper processes

/// `navsync-bench helper ipc-pub`: publishes COUNT samples with CLOCK_MONOTONIC and a
/// sequence number in the payload.
#[derive(Debug, Clone, clap::Args)]
pub struct PubArgs {
    /// Transport.
    #[arg(long)]
    pub transport: Transport,
    /// Sample type.
    #[arg(long)]
    pub kind: Kind,
    /// Samples to send (sequence numbers 0..count).
    #[arg(long)]
    pub count: u64,
    /// Hz or `max`.
    #[arg(long)]
    pub rate: Rate,
    /// Socket paths of the subscribers (socket transport), comma-separated.
    #[arg(long, value_delimiter = ',')]
    pub sockets: Vec<PathBuf>,
    /// The ring file (futex-floor transport).
    #[arg(long)]
    pub shm: Option<PathBuf>,
}

/// `navsync-bench helper ipc-sub`: receives the samples of `ipc-pub` and writes their
/// latencies.
#[derive(Debug, Clone, clap::Args)]
pub struct SubArgs {
    /// Transport.
    #[arg(long)]
    pub transport: Transport,
    /// Sample type.
    #[arg(long)]
    pub kind: Kind,
    /// Samples the publisher sends.
    #[arg(long)]
    pub count: u64,
    /// Subscriber index (node name).
    #[arg(long, default_value_t = 0)]
    pub index: usize,
    /// Latency file (little-endian i64 ns).
    #[arg(long)]
    pub out: PathBuf,
    /// Socket path to listen on (socket transport).
    #[arg(long)]
    pub socket: Option<PathBuf>,
    /// The ring file (futex-floor transport).
    #[arg(long)]
    pub shm: Option<PathBuf>,
}

/// Publishes `count` samples and prints a JSON summary.
pub fn helper_pub(a: &PubArgs) -> Result<(), IpcBenchError> {
    match a.kind {
        Kind::Imu => publish::<ImuSample>(a),
        Kind::Nav => publish::<NavState>(a),
        Kind::Raw => publish::<GnssRaw>(a),
        Kind::Blob => publish::<Blob64k>(a),
    }
}

/// `navsync-bench helper ipc-sub`: receives until the last sequence number (or SIGTERM),
/// writes the latencies and prints a JSON summary.
pub fn helper_sub(a: &SubArgs) -> Result<(), IpcBenchError> {
    match a.kind {
        Kind::Imu => subscribe::<ImuSample>(a),
        Kind::Nav => subscribe::<NavState>(a),
        Kind::Raw => subscribe::<GnssRaw>(a),
        Kind::Blob => subscribe::<Blob64k>(a),
    }
}

fn publish<T: Payload>(a: &PubArgs) -> Result<(), IpcBenchError> {
    // The event wake-ups are what is measured; the pacing sleep must not add timer slack.
    navsync_shared::pacing::minimal_timer_slack();
    let period_ns = match a.rate {
        Rate::Hz(r) => Some(1e9 / r),
        Rate::Max => None,
    };
    // Sends samples 0..count with `send` (returning its errors) at the paced instants and
    // prints the summary as soon as the last one is sent; the iceoryx2 publisher then stays
    // until the bench stops it, as a driver does: a subscriber woken only after the burst (at
    // `max` rate) still finds the publisher's data segment to connect to. A publisher that
    // left first would take its unread samples with it.
    let paced = |send: &mut dyn FnMut(u64) -> u64| {
        let cpu0 = util::own_cpu_time_s();
        let t0 = monotonic_now_ns();
        let mut errors = 0;
        for i in 0..a.count {
            if let Some(p) = period_ns {
                pacing::sleep_until(t0 + (i as f64 * p) as i64, 0);
            }
            errors += send(i);
        }
        let wall = (monotonic_now_ns() - t0) as f64 * 1e-9;
        let cpu = util::own_cpu_time_s() - cpu0;
        println!(
            "{}",
            serde_json::json!({ "sent": a.count, "errors": errors, "wall_s": wall, "cpu_s": cpu })
        );
    };
    match a.transport {
        Transport::Iceoryx2 | Transport::Iceoryx2Wake | Transport::Iceoryx2WakeTimer | Transport::Iceoryx2Busy => {
            let node = IpcNode::new("bench-pub")?;
            let mut p = node.publisher::<T>(&T::service())?;
            // Let the subscribers' ports settle before the first sample.
            std::thread::sleep(Duration::from_millis(100));
            paced(&mut |i| u64::from(p.publish_with(|| T::make(monotonic_now_ns(), i)).is_err()));
            let t_end = std::time::Instant::now();
            while t_end.elapsed() < PUBLISHER_LINGER && node.sleep(Duration::from_millis(50)) {}
        }
        Transport::Socket => {
            // The sent bytes stay in the subscribers' socket buffers: closing ends their loops.
            let fds: Vec<Fd> = a.sockets.iter().map(|p| connect(p)).collect::<Result<_, _>>()?;
            std::thread::sleep(Duration::from_millis(100));
            paced(&mut |i| {
                let v = T::make(monotonic_now_ns(), i);
                let b = bytes_of(&v);
                let mut errors = 0;
                for fd in &fds {
                    // SAFETY: sending our buffer on our socket.
                    let n = unsafe { libc::send(fd.0, b.as_ptr().cast(), b.len(), libc::MSG_NOSIGNAL) };
                    errors += u64::from(n != b.len() as isize);
                }
                errors
            });
        }
        Transport::FutexFloor => {
            let path = a.shm.as_deref().ok_or_else(|| child_err("--shm needed"))?;
            let ring = floor::Ring::open(path, size_of::<T>())?;
            std::thread::sleep(Duration::from_millis(100));
            paced(&mut |i| {
                ring.publish(i, || T::make(monotonic_now_ns(), i));
                0
            });
        }
    }
    Ok(())
}

fn subscribe<T: Payload>(a: &SubArgs) -> Result<(), IpcBenchError> {
    let mut lat: Vec<i64> = Vec::with_capacity(a.count as usize);
    let last = a.count.saturating_sub(1);
    let cpu0;
    match a.transport {
        Transport::Iceoryx2 | Transport::Iceoryx2Busy => {
            let node = IpcNode::new(&format!("bench-sub-{}", a.index))?;
            let sub = node.subscriber::<T>(&T::service())?;
            sub.set_busy_poll(a.transport == Transport::Iceoryx2Busy);
            ready();
            cpu0 = util::own_cpu_time_s();
            loop {
                // In place in shared memory: the stamp is read where the publisher wrote it.
                // No timeout, as the socket's blocking `recv`: ends on the last sample or SIGTERM.
                let Some((host_ns, seq)) = sub.wait_with(Duration::MAX, |s| s.stamp())? else {
                    if node.termination_requested() {
                        break;
                    }
                    continue;
                };
                let now = monotonic_now_ns();
                lat.push(now - host_ns);
                if seq >= last {
                    break;
                }
            }
        }
        Transport::Iceoryx2Wake | Transport::Iceoryx2WakeTimer => {
            navsync_shared::ipc::futex::timeouts_by_kernel(a.transport == Transport::Iceoryx2WakeTimer);
            let node = IpcNode::new(&format!("bench-sub-{}", a.index))?;
            let sub = node.input::<T>(&T::service())?;
            let wake = node.wake()?;
            ready();
            cpu0 = util::own_cpu_time_s();
            let mut done = false;
            while !done && node.wait(&wake, Duration::from_secs(1))? {
                sub.for_each(|s| {
                    let now = monotonic_now_ns();
                    let (host_ns, seq) = s.stamp();
                    lat.push(now - host_ns);
                    done |= seq >= last;
                })?;
            }
        }
        Transport::Socket => {
            let path = a.socket.as_deref().ok_or_else(|| child_err("--socket needed"))?;
            let listener = listen(path)?;
            ready();
            // SAFETY: accepting on our listening socket.
            let conn = Fd(unsafe { libc::accept(listener.0, std::ptr::null_mut(), std::ptr::null_mut()) });
            if conn.0 < 0 {
                return Err(std::io::Error::last_os_error().into());
            }
            cpu0 = util::own_cpu_time_s();
            let mut v = T::zeroed();
            loop {
                // SAFETY: receiving at most size_of::<T>() bytes into a T (any bytes are valid).
                let n = unsafe { libc::recv(conn.0, (&mut v as *mut T).cast(), size_of::<T>(), 0) };
                let now = monotonic_now_ns();
                if n <= 0 {
                    if n < 0 && std::io::Error::last_os_error().kind() == std::io::ErrorKind::Interrupted {
                        continue;
                    }
                    break; // the publisher closed the connection
                }
                let (host_ns, seq) = v.stamp();
                lat.push(now - host_ns);
                if seq >= last {
                    break;
                }
            }
        }
        Transport::FutexFloor => {
            let path = a.shm.as_deref().ok_or_else(|| child_err("--shm needed"))?;
            let ring = floor::Ring::open(path, size_of::<T>())?;
            let stop = floor::stop_flag();
            ready();
            cpu0 = util::own_cpu_time_s();
            let mut next = 0;
            // In place in shared memory, as the iceoryx2 subscriber reads it.
            while let Some((seq, host_ns)) = ring.wait_with(next, stop, |s: &T| s.stamp().0) {
                lat.push(monotonic_now_ns() - host_ns);
                next = seq + 1;
                if seq >= last {
                    break;
                }
            }
        }
    }
    let cpu = util::own_cpu_time_s() - cpu0;
    util::write_latencies(&a.out, &lat)?;
    println!("{}", serde_json::json!({ "received": lat.len(), "cpu_s": cpu }));
    Ok(())
}

fn ready() {
    use std::io::Write;
    let mut o = std::io::stdout().lock();
    let _ = writeln!(o, "ready");
    let _ = o.flush();
}

/// A file removed on drop.
struct RemoveOnDrop(PathBuf);

impl Drop for RemoveOnDrop {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// An owned file descriptor, closed on drop.
struct Fd(i32);

impl Drop for Fd {
    fn drop(&mut self) {
        if self.0 >= 0 {
            // SAFETY: closing our own descriptor once.
            unsafe { libc::close(self.0) };
        }
    }
}

fn sockaddr(path: &Path) -> Result<(libc::sockaddr_un, libc::socklen_t), IpcBenchError> {
    use std::os::unix::ffi::OsStrExt;
    // SAFETY: an all-zero sockaddr_un is valid.
    let mut addr: libc::sockaddr_un = unsafe { std::mem::zeroed() };
    addr.sun_family = libc::AF_UNIX as libc::sa_family_t;
    let b = path.as_os_str().as_bytes();
    if b.len() >= addr.sun_path.len() {
        return Err(child_err(format!("socket path too long: {}", path.display())));
    }
    for (d, s) in addr.sun_path.iter_mut().zip(b) {
        *d = *s as libc::c_char;
    }
    Ok((addr, size_of::<libc::sockaddr_un>() as libc::socklen_t))
}

fn seqpacket() -> Result<Fd, IpcBenchError> {
    // SAFETY: plain socket creation.
    let fd = unsafe { libc::socket(libc::AF_UNIX, libc::SOCK_SEQPACKET | libc::SOCK_CLOEXEC, 0) };
    if fd < 0 {
        return Err(std::io::Error::last_os_error().into());
    }
    Ok(Fd(fd))
}

fn listen(path: &Path) -> Result<Fd, IpcBenchError> {
    let fd = seqpacket()?;
    let (addr, len) = sockaddr(path)?;
    let _ = std::fs::remove_file(path);
    // SAFETY: binding our socket to a valid address.
    if unsafe { libc::bind(fd.0, (&addr as *const libc::sockaddr_un).cast(), len) } != 0
        // SAFETY: listening on our bound socket.
        || unsafe { libc::listen(fd.0, 4) } != 0
    {
        return Err(std::io::Error::last_os_error().into());
    }
    Ok(fd)
}

fn connect(path: &Path) -> Result<Fd, IpcBenchError> {
    let fd = seqpacket()?;
    let (addr, len) = sockaddr(path)?;
    // SAFETY: connecting our socket to a valid address.
    if unsafe { libc::connect(fd.0, (&addr as *const libc::sockaddr_un).cast(), len) } != 0 {
        return Err(std::io::Error::last_os_error().into());
    }
    Ok(fd)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sign_test_tails() {
        assert_eq!(sign_test_p(0, 10), 1.0);
        assert!((sign_test_p(10, 10) - 1.0 / 1024.0).abs() < 1e-15);
        // P(X ≥ 8), n = 10: (45 + 10 + 1) / 1024.
        assert!((sign_test_p(8, 10) - 56.0 / 1024.0).abs() < 1e-12);
        assert!((sign_test_p(5, 10) - 638.0 / 1024.0).abs() < 1e-12);
        assert_eq!(sign_test_p(3, 2), 0.0);
        assert!(sign_test_p(1000, 1000) > 0.0);
    }

    #[test]
    fn paired_counts_rounds_and_medians() {
        // Transport a is lower in p50 every round, higher in p99 in two of three, tied in CPU.
        let a = [[1.0, 5.0, 9.0, 2.0], [1.0, 5.0, 9.0, 2.0], [1.0, 3.0, 9.0, 2.0]];
        let b = [[2.0, 4.0, 9.0, 2.0], [4.0, 4.0, 9.0, 2.0], [2.0, 4.0, 9.0, 2.0]];
        let p = Paired::of(
            (Kind::Imu, Rate::Hz(1000.0), 1),
            (Transport::Iceoryx2, Transport::Socket),
            &a,
            &b,
        );
        assert_eq!(p.rounds, 3);
        assert_eq!(p.at_or_below, [3, 1, 3, 3]);
        assert_eq!(p.median_ratio[0], 0.5);
        assert_eq!(p.median_ratio[1], 1.25);
        assert_eq!(p.p_worse[0], 1.0);
        assert_eq!(p.p_worse[1], 0.5);
        // Ties count as neither.
        assert_eq!(p.p_worse[3], 1.0);
        assert!(paired_table(&[p]).contains("| imu | 1000 Hz | 1 | iceoryx2 vs socket | 3/3, ×0.500"));
    }
}
