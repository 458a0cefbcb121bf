//! `navsync gnss`: the process shell around a receiver protocol's [`Decoder`].
//!
//! read (serialport, as little buffering as the API allows) → stamp (host time when the read
//! returned, back-dated by the line rate for bytes that were already waiting) → decode
//! ([`Decoder`], pure) → publish `GnssFix` on `navsync/gnss/{id}/fix`.
//!
//! Robustness:
//!
//! - Malformed input (binary noise, bad or missing checksums, truncated, over-long or
//!   non-ASCII sentences, unparsable fields) is dropped by the decoder and counted; every
//!   counter is in the health report, and each kind is logged when it first occurs and then
//!   at most every 10 s ([`RateLimitedLog`]).
//! - The port vanishing (USB unplug: the device node or its symlink disappears, reads fail or
//!   hang up) is survived: the epoch being assembled is emitted (its bytes all arrived), the
//!   driver logs once, reopens with exponential backoff (0.1 s → 5 s), and resumes when the
//!   port is back. A read of zero bytes (hang-up) counts as the port closing, so a dead line
//!   cannot spin the process.
//! - `--baud auto` hunts the common rates like gpsd does: at each rate it listens until
//!   [`HUNT_DWELL`] has passed with at least [`HUNT_MIN_BYTES`] received and no frame with
//!   a valid checksum (the decoder's [`GnssDecoder::valid_frames`]), then switches rate (the port stays open; only the line settings and
//!   the input queue are reset). A rate that yields valid sentences is kept (and tried first
//!   after a reconnection); if it later yields only garbage for [`HUNT_DWELL`], hunting
//!   resumes. A silent line is not hunted (silence says nothing about the rate). A fixed
//!   `--baud` never hunts: a wrong rate then shows as noise and checksum counters.
//!
//! Health counters besides the decoder's: `baud` (current rate), `baud_hunts`, `port_opens`,
//! `port_open_failures`, `port_reopens` (read failures and hang-ups), `publish_errors`,
//! `extra_publish_errors` (time pulses, time marks, raw data, subframes, IMU samples not
//! published), `events_unmapped` (time marks published without host times: the estimator's
//! time mapping was not usable yet), `configure_acked`, `configure_failed`.

use std::io::{ErrorKind, Read};
use std::time::{Duration, Instant};

use navsync_shared::health_reporter::{CounterId, HealthError, HealthReporter};
use navsync_shared::ipc::{IpcError, IpcNode, IpcSample, Publisher, Subscriber};
use navsync_shared::reflect::fixed_str;
use navsync_shared::samples::{GnssEvent, GnssFix, GnssNavData, GnssRaw, GnssSky, GnssTimePulse, ImuSample, TimeState};
use navsync_shared::services;
use navsync_shared::time::{monotonic_now_ns, utc_ns_from_gps_ns};
use serialport::{ClearBuffer, SerialPort, TTYPort};
use tracing::{info, info_span, warn};

use super::ubx::configure as ubx_configure;
use super::{Decoder, GnssDecoder, GnssExtra, Protocol};
use crate::rate_log::RateLimitedLog;

/// Baud rates tried by `--baud auto`, most common first (gpsd's hunt order differs; these
/// are the rates receivers ship with).
pub const HUNT_BAUDS: [u32; 7] = [9600, 4800, 38_400, 115_200, 19_200, 57_600, 230_400];

/// How long one baud rate is tried before hunting on, when bytes but no valid sentence arrive.
pub const HUNT_DWELL: Duration = Duration::from_millis(2500);

/// Bytes that must have arrived at a rate without a valid sentence before it is abandoned.
pub const HUNT_MIN_BYTES: u64 = 64;

/// Read timeout after a byte; after this much silence the epoch being assembled is emitted
/// (the fallback for receivers whose cycle is not learnt: a learnt cycle's epoch goes out with
/// its last message).
pub const IDLE_FLUSH: Duration = Duration::from_millis(50);

/// Read timeout once the line has been silent for [`IDLE_FLUSH`] and the epoch was flushed:
/// nothing is pending, so the driver sleeps until the next byte (a signal ends the wait at
/// once; this only bounds the health report's and the watchdog's period).
pub const IDLE_WAIT: Duration = Duration::from_millis(1000);

/// Serial line rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Baud {
    /// A fixed rate, e.g. 9600.
    Fixed(u32),
    /// Hunt through [`HUNT_BAUDS`] until sentences with valid checksums arrive.
    Auto,
}

/// The line rates a serial port takes: the standard rates of Linux termios (`B50` …
/// `B4000000`, termios(3)); GNSS receivers use 4800 to 921600.
pub const STANDARD_BAUDS: [u32; 30] = [
    50, 75, 110, 134, 150, 200, 300, 600, 1200, 1800, 2400, 4800, 9600, 19_200, 38_400, 57_600, 115_200, 230_400,
    460_800, 500_000, 576_000, 921_600, 1_000_000, 1_152_000, 1_500_000, 2_000_000, 2_500_000, 3_000_000, 3_500_000,
    4_000_000,
];

impl Baud {
    /// A fixed rate, when it is one of [`STANDARD_BAUDS`].
    pub fn standard(rate: u32) -> Option<Self> {
        STANDARD_BAUDS.contains(&rate).then_some(Self::Fixed(rate))
    }
}

/// What a baud rate must be, for messages.
const BAUD_EXPECTED: &str =
    "a standard baud rate (4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600, …) or \"auto\"";

impl std::str::FromStr for Baud {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "auto" {
            return Ok(Baud::Auto);
        }
        s.parse::<u32>()
            .ok()
            .and_then(Baud::standard)
            .ok_or_else(|| format!("`{s}` is not {BAUD_EXPECTED}"))
    }
}

impl std::fmt::Display for Baud {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Fixed(b) => write!(f, "{b}"),
            Self::Auto => f.write_str("auto"),
        }
    }
}

/// In a configuration file: a standard rate (`9600`) or `"auto"`.
impl<'de> serde::Deserialize<'de> for Baud {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl serde::de::Visitor<'_> for V {
            type Value = Baud;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(BAUD_EXPECTED)
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Baud, E> {
                u32::try_from(v)
                    .ok()
                    .and_then(Baud::standard)
                    .ok_or_else(|| E::invalid_value(serde::de::Unexpected::Signed(v), &self))
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Baud, E> {
                self.visit_i64(i64::try_from(v).unwrap_or(-1))
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Baud, E> {
                if v == "auto" {
                    Ok(Baud::Auto)
                } else {
                    Err(E::invalid_value(serde::de::Unexpected::Str(v), &self))
                }
            }
        }
        d.deserialize_any(V)
    }
}

/// Settings of the GNSS driver process.
#[derive(Debug, Clone)]
pub struct GnssArgs {
    /// Serial device, e.g. `/dev/ttyUSB0` or a pseudo-terminal.
    pub port: String,
    /// Line rate.
    pub baud: Baud,
    /// The receiver's protocol.
    pub protocol: Protocol,
    /// Receiver id (service `navsync/gnss/{id}/fix`, health `navsync/health/gnss-{id}`).
    pub id: String,
    /// Publish the receiver's own IMU readings (UBX ESF-MEAS) as this IMU id
    /// (`navsync/imu/{imu_id}/sample`); `None`: not published.
    pub imu_id: Option<String>,
    /// Set a u-blox receiver up for navsync once the port is open (RAM only; see
    /// [`super::ubx::configure`]). Off: the driver never writes to the receiver.
    pub configure: bool,
}

/// How long the receiver has to answer the MON-VER poll, and each configuration command.
/// Health counters the driver registers besides its decoder's: the port's six
/// (`PortCounters`), `extra_publish_errors`, `events_unmapped`, `configure_acked`,
/// `configure_failed`. A decoder's counters and these must fit one `Health` report
/// (`MAX_COUNTERS`): each decoder's test checks it.
pub const DRIVER_COUNTERS: usize = 10;
const CONFIGURE_ANSWER_TIMEOUT: Duration = Duration::from_millis(1500);

/// Configures a u-blox receiver on `port` (module [`super::ubx::configure`]); what each
/// command got as answer. An error when the receiver answers no UBX at all.
fn configure_receiver(port: &mut TTYPort, node: &IpcNode) -> Result<ubx_configure::Report, String> {
    use super::ubx::framer::{Frame, UbxFramer};
    use super::ubx::messages::{Message, decode};
    use std::io::Write;
    let mut framer = UbxFramer::new();
    let mut buf = [0u8; 512];
    // Reads until `done` says so or the timeout passes; `done` sees every decoded message.
    let mut wait = |port: &mut TTYPort, done: &mut dyn FnMut(&Message) -> bool| -> bool {
        let until = Instant::now() + CONFIGURE_ANSWER_TIMEOUT;
        while Instant::now() < until && !node.termination_requested() {
            let n = match port.read(&mut buf) {
                Ok(n) => n,
                Err(e) if e.kind() == ErrorKind::TimedOut || e.kind() == ErrorKind::Interrupted => continue,
                Err(_) => return false,
            };
            let mut finished = false;
            framer.push(&buf[..n], 0, 0, &mut |f| {
                if let Frame::Ubx { class, id, payload, .. } = f
                    && let Ok(m) = decode(class, id, payload)
                {
                    finished |= done(&m);
                }
            });
            if finished {
                return true;
            }
        }
        false
    };
    let write = |port: &mut TTYPort, frame: &[u8]| port.write_all(frame).and_then(|()| port.flush());
    write(port, &ubx_configure::poll_version()).map_err(|e| format!("writing the MON-VER poll: {e}"))?;
    let mut version = None;
    if !wait(port, &mut |m| match m {
        Message::MonVer(v) => {
            version = Some(*v);
            true
        }
        _ => false,
    }) {
        return Err(format!(
            "the receiver answered no UBX poll (MON-VER) within {CONFIGURE_ANSWER_TIMEOUT:?}: only a u-blox \
             receiver speaking UBX can be configured (an NMEA-only receiver cannot)"
        ));
    }
    let v = version.ok_or("no MON-VER")?;
    let mut report = ubx_configure::Report {
        version: ubx_configure::describe_version(&v),
        answers: Vec::new(),
    };
    for c in ubx_configure::commands(v.protocol_version_x100()) {
        write(port, &c.frame).map_err(|e| format!("writing {}: {e}", c.what))?;
        let mut answer = ubx_configure::Answer::TimedOut;
        wait(port, &mut |m| {
            let a = match m {
                Message::AckAck(a) => ubx_configure::answer_to(&c, a.cls_id, a.msg_id, true),
                Message::AckNak(a) => ubx_configure::answer_to(&c, a.cls_id, a.msg_id, false),
                _ => None,
            };
            if let Some(a) = a {
                answer = a;
            }
            a.is_some()
        });
        report.answers.push((c.what, c.optional, answer));
    }
    Ok(report)
}

/// Publishers of what a receiver reports besides fixes (time pulses, time marks, raw
/// measurements, subframes, its IMU, its high-rate fused solution, its sky), each created on its first sample, so a receiver that
/// sends none of them creates no service for them.
struct ExtraPublishers<'n> {
    node: &'n IpcNode,
    id: String,
    imu_id: Option<String>,
    time_pulse: Option<Publisher<GnssTimePulse>>,
    event: Option<Publisher<GnssEvent>>,
    raw: Option<Publisher<GnssRaw>>,
    nav_data: Option<Publisher<GnssNavData>>,
    imu: Option<Publisher<ImuSample>>,
    /// The receiver's high-rate fused solution (HNR-PVT), `navsync/gnss/{id}/hnr`.
    hnr: Option<Publisher<GnssFix>>,
    /// The satellites of each epoch, `navsync/gnss/{id}/sky`.
    sky: Option<Publisher<GnssSky>>,
    /// The estimator's host → GNSS time mapping (`navsync/time/state`), subscribed on the
    /// first time mark, and its latest state: a time mark's GNSS time is mapped back to the
    /// host clock with it ([`GnssEvent::rising_host_ns`]).
    time: Option<Subscriber<TimeState>>,
    time_state: Option<TimeState>,
    /// Time marks published without host times (no usable mapping yet).
    events_unmapped: u64,
    /// Samples that could not be published (publisher creation or publishing failed).
    errors: u64,
}

impl ExtraPublishers<'_> {
    fn publish(&mut self, x: GnssExtra<'_>) {
        let mapped;
        let x = match x {
            GnssExtra::Event(e) => {
                mapped = self.map_to_host(e);
                GnssExtra::Event(&mapped)
            }
            x => x,
        };
        let id = self.id.as_str();
        let node = self.node;
        let r = match x {
            GnssExtra::TimePulse(s) => publish_lazily(node, &mut self.time_pulse, || services::gnss_time_pulse(id), s),
            GnssExtra::Event(s) => publish_lazily(node, &mut self.event, || services::gnss_event(id), s),
            GnssExtra::Raw(s) => publish_lazily(node, &mut self.raw, || services::gnss_raw(id), s),
            GnssExtra::NavData(s) => publish_lazily(node, &mut self.nav_data, || services::gnss_nav_data(id), s),
            GnssExtra::Hnr(s) => publish_lazily(node, &mut self.hnr, || services::gnss_hnr(id), s),
            GnssExtra::Sky(s) => publish_lazily(node, &mut self.sky, || services::gnss_sky(id), s),
            GnssExtra::Imu(s) => match &self.imu_id {
                Some(imu_id) => {
                    let mut s = *s;
                    s.imu_id = fixed_str::<8>(imu_id);
                    publish_lazily(node, &mut self.imu, || services::imu_sample(imu_id), &s)
                }
                None => Ok(()),
            },
        };
        if let Err(e) = r {
            if self.errors == 0 {
                warn!("publishing a receiver product: {e}");
            }
            self.errors += 1;
        }
    }
}

impl ExtraPublishers<'_> {
    /// The time mark with the host times of its edges, from the latest host → GNSS time
    /// mapping the estimator published (GPS → UTC by the leap-second table, then
    /// [`TimeState::host_ns_at`]); left at `i64::MIN` (and counted) while there is none.
    fn map_to_host(&mut self, e: &GnssEvent) -> GnssEvent {
        if self.time.is_none() {
            match self.node.subscriber::<TimeState>(services::TIME_STATE) {
                Ok(sub) => self.time = Some(sub),
                Err(e) => {
                    warn!("time marks get no host times: {e}");
                    self.errors += 1;
                }
            }
        }
        if let Some(sub) = &self.time {
            let latest = &mut self.time_state;
            if sub.for_each(|t| *latest = Some(*t)).is_err() {
                self.errors += 1;
            }
        }
        let mut e = *e;
        match self.time_state.filter(TimeState::is_valid) {
            Some(t) => {
                for (gps, host) in [
                    (e.rising_gps_ns, &mut e.rising_host_ns),
                    (e.falling_gps_ns, &mut e.falling_host_ns),
                ] {
                    if gps != i64::MIN {
                        *host = t.host_ns_at(utc_ns_from_gps_ns(gps));
                    }
                }
            }
            None => self.events_unmapped += 1,
        }
        e
    }
}

/// Publishes `sample` on the publisher in `slot`, creating it on `service()` first if needed.
fn publish_lazily<T: IpcSample>(
    node: &IpcNode,
    slot: &mut Option<Publisher<T>>,
    service: impl FnOnce() -> String,
    sample: &T,
) -> Result<(), IpcError> {
    if slot.is_none() {
        *slot = Some(node.publisher::<T>(&service())?);
    }
    match slot {
        Some(p) => p.publish(sample),
        None => Ok(()),
    }
}

/// Errors that stop the GNSS driver (device errors never do: it reopens).
#[derive(Debug, thiserror::Error)]
pub enum GnssError {
    /// IPC failure.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// A health counter could not be registered.
    #[error(transparent)]
    Health(#[from] navsync_shared::health_reporter::HealthError),
    /// `--configure` could not configure the receiver.
    #[error("--configure on {port}: {why}")]
    Configure {
        /// The port.
        port: String,
        /// Why.
        why: String,
    },
}

/// The baud-rate hunt of `--baud auto` (a pure state machine on counters and time).
#[derive(Debug, Clone)]
pub struct BaudHunt {
    index: usize,
    locked: Option<u32>,
    /// When the current rate was set, with the byte and valid-sentence counts at that moment
    /// or at the last valid sentence.
    since: Instant,
    bytes_at: u64,
    valid_at: u64,
    hunts: u64,
}

/// What the hunt decided after looking at the counters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HuntStep {
    /// Keep listening at the current rate.
    Stay,
    /// Valid sentences arrive at this rate for the first time: it is now locked.
    Locked(u32),
    /// Switch to this rate.
    Switch(u32),
}

impl BaudHunt {
    /// A hunt starting at the first of [`HUNT_BAUDS`].
    pub fn new(now: Instant) -> Self {
        Self {
            index: 0,
            locked: None,
            since: now,
            bytes_at: 0,
            valid_at: 0,
            hunts: 0,
        }
    }

    /// The rate to use now.
    pub fn baud(&self) -> u32 {
        HUNT_BAUDS[self.index % HUNT_BAUDS.len()]
    }

    /// Rate changes so far.
    pub fn hunts(&self) -> u64 {
        self.hunts
    }

    /// The rate that yielded valid sentences, if any.
    pub fn locked(&self) -> Option<u32> {
        self.locked
    }

    /// Restarts the dwell at the current rate (after the port was (re)opened).
    pub fn restart(&mut self, now: Instant, bytes: u64, valid: u64) {
        self.since = now;
        self.bytes_at = bytes;
        self.valid_at = valid;
    }

    /// Looks at the byte and valid-sentence counters at time `now`.
    pub fn step(&mut self, now: Instant, bytes: u64, valid: u64) -> HuntStep {
        if valid > self.valid_at {
            self.restart(now, bytes, valid);
            let b = self.baud();
            if self.locked != Some(b) {
                self.locked = Some(b);
                return HuntStep::Locked(b);
            }
            return HuntStep::Stay;
        }
        if now.duration_since(self.since) < HUNT_DWELL || bytes - self.bytes_at < HUNT_MIN_BYTES {
            return HuntStep::Stay;
        }
        self.locked = None;
        self.index = (self.index + 1) % HUNT_BAUDS.len();
        self.hunts += 1;
        self.restart(now, bytes, valid);
        HuntStep::Switch(self.baud())
    }
}

/// Health counter ids of the port.
struct PortCounters {
    baud: CounterId,
    hunts: CounterId,
    opens: CounterId,
    open_failures: CounterId,
    reopens: CounterId,
    publish_errors: CounterId,
}

/// Runs the driver until SIGINT/SIGTERM.
pub fn run(args: &GnssArgs) -> Result<(), GnssError> {
    let process = format!("gnss-{}", args.id);
    let _span = info_span!("gnss", id = %args.id, port = %args.port, protocol = %args.protocol).entered();
    let node = IpcNode::new(&process)?;
    let mut publisher = node.publisher::<GnssFix>(&services::gnss_fix(&args.id))?;
    let mut health = HealthReporter::new(&node, &process)?;
    let r_fix = health.rate("fixes_out")?;
    // DRIVER_COUNTERS counts these and the four below.
    let pc = PortCounters {
        baud: health.counter("baud")?,
        hunts: health.counter("baud_hunts")?,
        opens: health.counter("port_opens")?,
        open_failures: health.counter("port_open_failures")?,
        reopens: health.counter("port_reopens")?,
        publish_errors: health.counter("publish_errors")?,
    };
    let mut dec = Decoder::new(args.protocol);
    let mut extras = ExtraPublishers {
        node: &node,
        id: args.id.clone(),
        imu_id: args.imu_id.clone(),
        time_pulse: None,
        event: None,
        raw: None,
        nav_data: None,
        imu: None,
        hnr: None,
        sky: None,
        time: None,
        time_state: None,
        events_unmapped: 0,
        errors: 0,
    };
    let c_extra_errors = health.counter("extra_publish_errors")?;
    let c_events_unmapped = health.counter("events_unmapped")?;
    let c_cfg_acked = health.counter("configure_acked")?;
    let c_cfg_failed = health.counter("configure_failed")?;
    let mut configured = false;
    let mut log = RateLimitedLog::default();
    let mut hunt = BaudHunt::new(Instant::now());
    let mut backoff = Duration::from_millis(100);
    let mut warned_open = false;

    info!("gnss driver running");
    while !node.termination_requested() {
        // Serving: the services exist and the device is being read (or waited for, with backoff).
        navsync_shared::sd_notify::ready(&format!("gnss {}: reading {}", args.id, args.port));
        // The line rate now (the hunt changes it while the port stays open).
        let mut baud = match args.baud {
            Baud::Fixed(b) => b,
            Baud::Auto => hunt.baud(),
        };
        let mut port = match open(&args.port, baud) {
            Ok(p) => {
                if warned_open {
                    info!(baud, "port is back");
                }
                warned_open = false;
                p
            }
            Err(e) => {
                if !warned_open {
                    warn!("cannot open {}: {e}; retrying with backoff", args.port);
                    warned_open = true;
                }
                health.add(pc.open_failures, 1);
                publish_health(&mut health, &dec, &mut log)?;
                if !node.sleep(backoff) {
                    break;
                }
                backoff = (backoff * 2).min(Duration::from_secs(5));
                continue;
            }
        };
        health.add(pc.opens, 1);
        health.set(pc.baud, u64::from(baud));
        info!(baud, "port open");
        if args.configure && !configured {
            let report = configure_receiver(&mut port, &node).map_err(|why| GnssError::Configure {
                port: args.port.clone(),
                why,
            })?;
            info!(receiver = %report.version, "configuring the receiver (RAM layer)");
            for (what, optional, answer) in &report.answers {
                match answer {
                    ubx_configure::Answer::Acked => health.add(c_cfg_acked, 1),
                    _ if *optional => info!("{what}: {answer:?} (optional: the receiver may not have it)"),
                    _ => health.add(c_cfg_failed, 1),
                }
            }
            let failed = report.failed();
            if failed.is_empty() {
                info!("receiver configured");
            } else {
                warn!(?failed, "the receiver did not acknowledge these settings");
            }
            configured = true;
        }
        let mut ns_per_byte = 10_000_000_000 / i64::from(baud);
        hunt.restart(Instant::now(), dec.bytes(), dec.valid_frames());
        // One read takes a whole burst (an epoch of NMEA with GSV is 1–2 KiB): the epoch's end
        // is seen on the first wake-up.
        let mut buf = [0u8; 4096];
        // Silent since the last idle flush: nothing pending, wait long.
        let mut idle = false;
        let mut emit = |fix: &GnssFix, health: &mut HealthReporter| match publisher.publish(fix) {
            Ok(()) => health.tick(r_fix),
            Err(e) => {
                health.add(pc.publish_errors, 1);
                warn!("publishing fix: {e}");
            }
        };
        loop {
            if node.termination_requested() {
                break;
            }
            let closed = match port.read(&mut buf) {
                Ok(0) => Some("the port hung up".to_string()),
                Ok(n) => {
                    backoff = Duration::from_millis(100);
                    let t = monotonic_now_ns();
                    if idle {
                        idle = false;
                        let _ = port.set_timeout(IDLE_FLUSH);
                    }
                    dec.push_extras(&buf[..n], t, ns_per_byte, &mut |fix| emit(fix, &mut health), &mut |x| {
                        extras.publish(x)
                    });
                    health.set(c_extra_errors, extras.errors);
                    health.set(c_events_unmapped, extras.events_unmapped);
                    None
                }
                Err(e) if e.kind() == ErrorKind::TimedOut => {
                    dec.flush_extras(&mut |fix| emit(fix, &mut health), &mut |x| extras.publish(x));
                    if !idle {
                        idle = true;
                        let _ = port.set_timeout(IDLE_WAIT);
                    }
                    None
                }
                Err(e) if e.kind() == ErrorKind::Interrupted => None,
                Err(e) => Some(format!("read failed: {e}")),
            };
            if let Some(why) = closed {
                // Everything of the epoch in progress has arrived: emit it, then reopen.
                dec.flush_extras(&mut |fix| emit(fix, &mut health), &mut |x| extras.publish(x));
                dec.reset();
                warn!("{}: {why}; reopening with backoff", args.port);
                health.add(pc.reopens, 1);
                break;
            }
            if args.baud == Baud::Auto {
                match hunt.step(Instant::now(), dec.bytes(), dec.valid_frames()) {
                    HuntStep::Stay => {}
                    HuntStep::Locked(b) => info!(baud = b, "valid frames at this rate; keeping it"),
                    HuntStep::Switch(b) => {
                        info!(from = baud, to = b, "no valid frames at this rate; hunting on");
                        health.set(pc.hunts, hunt.hunts());
                        if port
                            .set_baud_rate(b)
                            .and_then(|()| port.clear(ClearBuffer::Input))
                            .is_err()
                        {
                            break;
                        }
                        dec.reset();
                        health.set(pc.baud, u64::from(b));
                        baud = b;
                        ns_per_byte = 10_000_000_000 / i64::from(b);
                    }
                }
            }
            publish_health(&mut health, &dec, &mut log)?;
        }
        drop(port);
        if node.termination_requested() {
            break;
        }
        publish_health(&mut health, &dec, &mut log)?;
        if !node.sleep(backoff) {
            break;
        }
        backoff = (backoff * 2).min(Duration::from_secs(5));
    }
    navsync_shared::sd_notify::stopping();
    publish_health(&mut health, &dec, &mut log)?;
    let _ = health.publish_final();
    info!("gnss driver stopped");
    Ok(())
}

/// Opens the port raw, with a short read timeout, and discards stale input.
fn open(path: &str, baud: u32) -> Result<TTYPort, serialport::Error> {
    let mut port = serialport::new(path, baud).timeout(IDLE_FLUSH).open_native()?;
    // Exclusive access is advisory; a pseudo-terminal's creator may hold it open too.
    let _ = port.set_exclusive(false);
    port.clear(ClearBuffer::Input)?;
    Ok(port)
}

/// Copies the decoder's counters into the report, logs growing error counters (once per
/// kind, then rate-limited) and publishes the report when due.
fn publish_health(h: &mut HealthReporter, d: &Decoder, log: &mut RateLimitedLog) -> Result<(), HealthError> {
    // Called on every turn of the read loop and of the reopen backoff: the systemd watchdog.
    navsync_shared::sd_notify::watchdog();
    let now = Instant::now();
    let mut result = Ok(());
    d.each_counter(&mut |name, v| {
        if let Err(e) = h.set_named(name, v) {
            result = Err(e);
        }
        if let Some(what) = Decoder::describe(name) {
            log.update(name, v, what, now);
        }
    });
    if let Err(e) = h.maybe_publish(monotonic_now_ns()) {
        warn!("publishing health: {e}");
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_baud_rate_is_a_standard_one() {
        assert_eq!("115200".parse::<Baud>(), Ok(Baud::Fixed(115_200)));
        assert_eq!("auto".parse::<Baud>(), Ok(Baud::Auto));
        for bad in ["12345", "0", "-9600", "fast", "9600.0"] {
            let e = bad.parse::<Baud>().expect_err(bad);
            assert!(e.contains("standard baud rate"), "{bad}: {e}");
        }
    }

    #[test]
    fn hunt_moves_on_only_after_garbage_for_the_dwell() {
        let t0 = Instant::now();
        let mut h = BaudHunt::new(t0);
        assert_eq!(h.baud(), 9600);
        // Silence: no hunting however long.
        assert_eq!(h.step(t0 + HUNT_DWELL * 3, 0, 0), HuntStep::Stay);
        // Garbage, but not yet for the dwell.
        assert_eq!(h.step(t0 + HUNT_DWELL / 2, 1000, 0), HuntStep::Stay);
        assert_eq!(h.step(t0 + HUNT_DWELL, 1000, 0), HuntStep::Switch(4800));
        let t1 = t0 + HUNT_DWELL;
        assert_eq!(h.step(t1 + HUNT_DWELL, 1010, 0), HuntStep::Stay, "too few bytes");
        assert_eq!(h.step(t1 + HUNT_DWELL, 2000, 0), HuntStep::Switch(38_400));
        let t2 = t1 + HUNT_DWELL;
        assert_eq!(
            h.step(t2 + Duration::from_millis(300), 2500, 3),
            HuntStep::Locked(38_400)
        );
        assert_eq!(h.step(t2 + Duration::from_millis(600), 2600, 5), HuntStep::Stay);
        assert_eq!(h.locked(), Some(38_400));
        assert_eq!(h.hunts(), 2);
        // Valid sentences keep the rate however much noise comes with them.
        assert_eq!(h.step(t2 + HUNT_DWELL * 2, 90_000, 6), HuntStep::Stay);
        // Only garbage for a whole dwell: the lock is lost and hunting resumes.
        let t3 = t2 + HUNT_DWELL * 2;
        assert_eq!(h.step(t3 + HUNT_DWELL, 99_000, 6), HuntStep::Switch(115_200));
        assert_eq!(h.locked(), None);
    }
}
