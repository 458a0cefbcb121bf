//! `navsync gpsd-server [--listen 127.0.0.1:2947]`: the fused navigation state in gpsd's JSON
//! protocol, so existing gpsd clients (`gpspipe -w`, `cgps`, libgps programs, gpsd's Python
//! client) work unchanged.
//!
//! The subset of the protocol (gpsd_json(5)) that clients use:
//!
//! * On connect the server sends `VERSION`.
//! * `?WATCH={"enable":true,"json":true};` answers `DEVICES` and `WATCH`, then streams `TPV`,
//!   `ATT`, `IMU` (and `SKY` when a GNSS fix was seen) once per report period, or with
//!   `--report fix` once per GNSS epoch, the moment the receiver's fix arrives (as gpsd does);
//!   `?WATCH={"enable":false};` stops it; `?WATCH;` reports the watch state.
//! * `?POLL;` answers one `POLL` with the latest `TPV` and `SKY`; `?VERSION;`, `?DEVICES;`,
//!   `?DEVICE;` as gpsd. Anything else gets an `ERROR` object, as from gpsd.
//!
//! What the objects carry: `TPV` is the estimator's `NavState` (time = its UTC, lat/lon,
//! `altHAE` = ellipsoidal height, `altMSL` with the receiver's geoid separation, velocities,
//! track, speed, climb; error estimates `epx`/`epy`/`epv`/`eph`/`eps`/`epc`/`epd`/`sep` as
//! 2σ (≈95 %, gpsd's convention) of the filter's covariance, `ept` the time mapping's 2σ);
//! mode 3 once the filter is aligned (status 6 "GNSS+DR", 5 "DR" while INS-only), mode 1 while
//! aligning without a fresh fix. `ATT` has roll, pitch, heading (= yaw) in degrees; `IMU` the bias-compensated
//! specific force (m/s²) and rate (°/s) in body FRD axes; `SKY` the receiver's DOPs and
//! satellites used.
//!
//! In both modes `TPV` is the fused state while the estimator's state is aligned and fresh
//! (under [`FRESH_NAV_NS`] old), otherwise the receiver's own fix ([`tpv_of_fix`]): with
//! `--report period`, while the state is still aligning and the fix is fresh, and once per
//! period of the fixes' time while no fused state is fresh. So a receiver alone serves gpsd
//! clients, and a standing vehicle with a 3D fix is not reported as mode 1; `ATT` and `IMU`
//! come with the fused state only.
//!
//! `?POLL` answers the fused state while it is fresh (under [`FRESH_NAV_NS`] old), else the
//! receiver's fix while that is fresh (under [`FRESH_FIX_NS`]), else no fix: a `TPV` of mode 1
//! and `active:0` (a dead estimator's last state is not a fix).
//!
//! One thread, one `poll(2)` loop over the listening socket, the clients and the fix
//! subscriber's wake-up descriptor (no async runtime). Every client is bounded, whatever it
//! sends or fails to read ([`ClientLimits`]): its pending output, replies to requests and
//! watch reports alike (a client that lets it pass [`MAX_PENDING_BYTES`] is dropped instead of
//! blocking the others or growing the server); its requests, by a token bucket
//! ([`REQUESTS_PER_S`], burst [`REQUEST_BURST`]: beyond it the server stops reading from that
//! socket until the bucket refills, so TCP pushes back on the client); a request line, at
//! [`MAX_REQUEST_BYTES`] (an `ERROR`, then closed; a line end always ends a request, so an
//! unbalanced `{` costs that request only); its silence, at `--idle-timeout` for a client that
//! does not watch (gpsd drops those after 3 minutes too). At most `--max-clients` clients at
//! once (one more gets an `ERROR` and is closed). Sockets are non-blocking. Listens on
//! localhost unless told otherwise. Counters in `navsync/health/gpsd-server`.

use std::collections::VecDeque;
use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::os::fd::AsRawFd;

use navsync_shared::health_reporter::HealthReporter;
use navsync_shared::ipc::{IpcError, IpcNode};
use navsync_shared::samples::{GnssFix, NavState, NavStatus, TimeState};
use navsync_shared::services;
use navsync_shared::time::{format_rfc3339_ms, monotonic_now_ns};
use serde_json::{Map, Value, json};
use tracing::{info, warn};

/// The gpsd protocol version spoken (gpsd 3.2x).
const PROTO_MAJOR: u32 = 3;
/// Minor protocol version.
const PROTO_MINOR: u32 = 14;
/// The device name in every report.
pub const DEVICE: &str = "navsync";
/// A client's pending output beyond this is a slow client: it is dropped.
pub const MAX_PENDING_BYTES: usize = 256 * 1024;
/// The kernel's send buffer of a client socket (bounded: autotuning could hold megabytes for a
/// client that does not read).
const SEND_BUFFER_BYTES: libc::c_int = 64 * 1024;
/// A request line longer than this (gpsd's own limit is 1536 characters) gets an `ERROR` and
/// closes the client.
pub const MAX_REQUEST_BYTES: usize = 4096;
/// Requests a client may make per second on average (a token bucket; gpsd clients send a
/// handful per connection, a polling client one per report).
pub const REQUESTS_PER_S: f64 = 20.0;
/// Requests a client may make at once (the bucket's depth).
pub const REQUEST_BURST: f64 = 40.0;
/// With `--report period` and in `?POLL`, the receiver's fix is reported while it is at most
/// this old (host `CLOCK_MONOTONIC`, ns): a 1 Hz receiver with one epoch missing.
pub const FRESH_FIX_NS: i64 = 2_500_000_000;

/// `navsync gpsd-server`: the fused state for gpsd clients (gpsd JSON protocol: VERSION,
/// DEVICES, WATCH, POLL, TPV, SKY, ATT, IMU).
#[derive(Debug, Clone, clap::Args)]
pub struct GpsdArgs {
    /// Address to listen on (localhost by default; port 0: any free port, printed on stderr).
    #[arg(long, default_value = "127.0.0.1:2947")]
    pub listen: SocketAddr,
    /// Most clients at once.
    #[arg(long, default_value_t = 32, value_parser = at_least_one)]
    pub max_clients: usize,
    /// Reports (TPV, ATT, IMU, SKY) per second, in (0, 1000] (with `--report period`).
    #[arg(long = "rate", default_value_t = 1.0, value_parser = report_rate)]
    pub rate_hz: f64,
    /// When reports go out.
    #[arg(long, value_enum, default_value_t = ReportOn::Period)]
    pub report: ReportOn,
    /// The receiver whose fixes give SKY, the geoid separation and, with `--report fix`, the
    /// report times (`navsync/gnss/{id}/fix`).
    #[arg(long, default_value = "0")]
    pub gnss_id: String,
    /// Seconds after which a client that does not watch and has sent nothing is closed
    /// (gpsd: 180), so idle connections cannot hold every `--max-clients` slot.
    #[arg(long = "idle-timeout", default_value_t = 180.0, value_parser = idle_timeout)]
    pub idle_timeout_s: f64,
}

fn idle_timeout(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(t) if t > 0.0 && t <= 86_400.0 => Ok(t),
        _ => Err(format!("`{s}`: expected seconds in (0, 86400]")),
    }
}

/// When `navsync gpsd-server` reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ReportOn {
    /// At `--rate`, on the first fused state of each period (UTC when known).
    Period,
    /// Once per epoch of the receiver `--gnss-id`, as its fix arrives (gpsd's cadence).
    Fix,
}

/// With `--report fix`, a fused state at most this old (host `CLOCK_MONOTONIC`, ns) is reported
/// instead of the receiver's fix.
pub const FRESH_NAV_NS: i64 = 500_000_000;

fn at_least_one(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if n > 0 => Ok(n),
        _ => Err(format!("`{s}`: expected at least 1")),
    }
}

fn report_rate(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(r) if r > 0.0 && r <= 1000.0 => Ok(r),
        _ => Err(format!("`{s}`: expected a rate in (0, 1000] reports per second")),
    }
}

/// Errors of `navsync gpsd-server`.
#[derive(Debug, thiserror::Error)]
pub enum GpsdError {
    /// IPC failure.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// Socket failure.
    #[error("{what}: {source}")]
    Io {
        /// What was done.
        what: String,
        /// Cause.
        source: std::io::Error,
    },
    /// A health counter could not be registered.
    #[error(transparent)]
    Health(#[from] navsync_shared::health_reporter::HealthError),
}

/// A watch request's settings.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Watch {
    enable: bool,
    json: bool,
}

/// The bounds every client is held to ([`MAX_PENDING_BYTES`], [`REQUESTS_PER_S`],
/// [`REQUEST_BURST`], [`MAX_REQUEST_BYTES`], `--idle-timeout`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClientLimits {
    /// Pending output beyond this drops the client.
    pub max_pending_bytes: usize,
    /// Requests per second on average.
    pub requests_per_s: f64,
    /// Requests at once.
    pub request_burst: f64,
    /// The longest request line.
    pub max_request_bytes: usize,
    /// A client that does not watch is closed after this long without a request, ns.
    pub idle_timeout_ns: i64,
}

impl ClientLimits {
    /// The defaults with `--idle-timeout`.
    pub fn with_idle_timeout_s(idle_timeout_s: f64) -> Self {
        Self {
            max_pending_bytes: MAX_PENDING_BYTES,
            requests_per_s: REQUESTS_PER_S,
            request_burst: REQUEST_BURST,
            max_request_bytes: MAX_REQUEST_BYTES,
            idle_timeout_ns: (idle_timeout_s * 1e9) as i64,
        }
    }
}

struct Client {
    stream: TcpStream,
    peer: SocketAddr,
    inbuf: Vec<u8>,
    out: VecDeque<u8>,
    watch: Watch,
    closing: bool,
    /// Requests received but not answered yet: the bucket was empty (at most one read's worth).
    backlog: VecDeque<Command>,
    /// The request bucket's tokens, and when it was last filled (host monotonic ns).
    tokens: f64,
    refilled_ns: i64,
    /// When the client last sent a request (or connected), host monotonic ns.
    last_request_ns: i64,
    /// Its requests are waiting for tokens.
    throttled: bool,
}

impl Client {
    /// A freshly accepted connection: non-blocking, no Nagle delay, a bounded send buffer.
    fn accepted(stream: TcpStream, peer: SocketAddr) -> Self {
        Self::accepted_at(stream, peer, monotonic_now_ns(), REQUEST_BURST)
    }

    fn accepted_at(stream: TcpStream, peer: SocketAddr, now_ns: i64, tokens: f64) -> Self {
        let _ = stream.set_nonblocking(true);
        let _ = stream.set_nodelay(true);
        set_send_buffer(&stream, SEND_BUFFER_BYTES);
        Self {
            stream,
            peer,
            inbuf: Vec::new(),
            out: VecDeque::new(),
            watch: Watch::default(),
            closing: false,
            backlog: VecDeque::new(),
            tokens,
            refilled_ns: now_ns,
            last_request_ns: now_ns,
            throttled: false,
        }
    }

    /// Refills the request bucket for the time since the last refill.
    fn refill(&mut self, now_ns: i64, limits: &ClientLimits) {
        let dt_s = now_ns.saturating_sub(self.refilled_ns).max(0) as f64 * 1e-9;
        self.tokens = (self.tokens + dt_s * limits.requests_per_s).min(limits.request_burst);
        self.refilled_ns = now_ns;
    }

    /// Whether the server reads from this client now: not while requests wait for tokens.
    fn wants_input(&self) -> bool {
        self.backlog.is_empty() && !self.closing
    }

    /// Idle: not watching and silent for longer than the limit.
    fn idle(&self, now_ns: i64, limits: &ClientLimits) -> bool {
        !self.watch.enable && now_ns - self.last_request_ns > limits.idle_timeout_ns
    }

    fn queue(&mut self, line: &str) {
        self.out.extend(line.as_bytes());
        self.out.push_back(b'\n');
    }

    /// Writes what the socket takes now; false when the peer is gone.
    fn flush(&mut self) -> bool {
        while !self.out.is_empty() {
            let (a, _) = self.out.as_slices();
            match self.stream.write(a) {
                Ok(0) => return false,
                Ok(n) => {
                    self.out.drain(..n);
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => return true,
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(_) => return false,
            }
        }
        true
    }
}

/// What became of a client after a report was queued to it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Delivery {
    /// Written, or queued within the bound.
    Kept,
    /// The peer closed or the socket failed.
    Gone,
    /// More than `max_pending_bytes` wait for a reader that does not read: drop it rather
    /// than buffer without bound or block the other clients.
    Slow,
}

/// Queues `lines` to `c`, writes what its socket takes now (never blocks) and applies the
/// slow-client bound.
fn deliver(c: &mut Client, lines: &[String], max_pending_bytes: usize) -> Delivery {
    for l in lines {
        c.queue(l);
    }
    if !c.flush() {
        Delivery::Gone
    } else if c.out.len() > max_pending_bytes {
        Delivery::Slow
    } else {
        Delivery::Kept
    }
}

/// Bounds the kernel's send buffer of a client socket to `bytes` (also `navsync web`'s).
pub(crate) fn set_send_buffer(s: &TcpStream, bytes: libc::c_int) {
    // SAFETY: setsockopt on a socket we own, with a pointer to a live int of the stated size.
    unsafe {
        libc::setsockopt(
            s.as_raw_fd(),
            libc::SOL_SOCKET,
            libc::SO_SNDBUF,
            (&bytes as *const libc::c_int).cast(),
            size_of::<libc::c_int>() as libc::socklen_t,
        );
    }
}

/// One command of a request line: name and JSON argument.
#[derive(Debug, Clone, PartialEq)]
pub struct Command {
    /// E.g. `WATCH`.
    pub name: String,
    /// The `=`-argument, if any.
    pub arg: Option<Value>,
}

/// Splits request text (`?WATCH={...};?POLL;`) into commands; returns the commands and how many
/// bytes were consumed (a command still being received stays in the buffer). Malformed JSON
/// arguments yield a command with a `Value::Null` argument, which is answered with an error; a
/// line end always ends a command (gpsd's requests are lines), so an argument whose braces do
/// not balance is malformed at its line's end instead of swallowing every later request.
pub fn parse_commands(buf: &[u8]) -> (Vec<Command>, usize) {
    let mut out = Vec::new();
    let mut i = 0;
    let mut consumed = 0;
    while i < buf.len() {
        match buf[i] {
            b'?' => {
                let start = i + 1;
                let mut j = start;
                while j < buf.len() && buf[j].is_ascii_alphanumeric() {
                    j += 1;
                }
                if j == buf.len() {
                    break; // incomplete
                }
                let name = String::from_utf8_lossy(&buf[start..j]).to_ascii_uppercase();
                let mut arg = None;
                if buf[j] == b'=' {
                    // A JSON object: up to its matching brace (gpsd's objects have no braces in strings).
                    let mut k = j + 1;
                    let mut depth = 0i32;
                    let mut end = None;
                    while k < buf.len() {
                        match buf[k] {
                            b'{' => depth += 1,
                            b'}' => {
                                depth -= 1;
                                if depth == 0 {
                                    end = Some(k + 1);
                                    break;
                                }
                            }
                            b'\n' => {
                                end = Some(k);
                                break;
                            }
                            _ => {}
                        }
                        k += 1;
                    }
                    let Some(end) = end else { break };
                    arg = Some(serde_json::from_slice::<Value>(&buf[j + 1..end]).unwrap_or(Value::Null));
                    j = end;
                }
                while j < buf.len() && matches!(buf[j], b';' | b'\r' | b'\n') {
                    j += 1;
                }
                out.push(Command { name, arg });
                i = j;
                consumed = j;
            }
            _ => {
                i += 1;
                // Anything outside a command up to a line end is ignored.
                if buf[i - 1] == b'\n' {
                    consumed = i;
                }
            }
        }
    }
    (out, consumed)
}

fn num(x: f64) -> Option<Value> {
    x.is_finite().then(|| json!(x))
}

fn put(m: &mut Map<String, Value>, k: &str, v: Option<Value>) {
    if let Some(v) = v {
        m.insert(k.to_string(), v);
    }
}

fn iso_time(utc_ns: i64) -> Option<Value> {
    (utc_ns != i64::MIN).then(|| json!(format_rfc3339_ms(utc_ns)))
}

/// Whether `n` navigates: past its alignment, with a position.
fn navigates(n: &NavState) -> bool {
    n.status != NavStatus::Aligning as u8 && n.lat_deg.is_finite() && n.lon_deg.is_finite()
}

/// The `TPV` object of a navigation state (with the latest fix for the geoid separation and
/// the latest time state for the time error).
pub fn tpv(n: &NavState, fix: Option<&GnssFix>, time: Option<&TimeState>) -> Value {
    let mut m = Map::new();
    m.insert("class".into(), json!("TPV"));
    m.insert("device".into(), json!(DEVICE));
    let aligned = navigates(n);
    m.insert("mode".into(), json!(if aligned { 3 } else { 1 }));
    if aligned {
        let dr = n.status == NavStatus::InsOnly as u8;
        m.insert("status".into(), json!(if dr { 5 } else { 6 }));
    }
    put(&mut m, "time", iso_time(n.utc_ns));
    if let Some(t) = time.filter(|t| t.is_valid()) {
        put(&mut m, "ept", num(2.0 * t.utc_std_ns_at(n.host_ns) * 1e-9));
        put(&mut m, "leapseconds", Some(json!(t.leap_s)));
    }
    if !aligned {
        return Value::Object(m);
    }
    let [sn, se, sd] = n.pos_std_ned_m;
    let [svn, sve, svd] = n.vel_std_ned_mps;
    let [vn, ve, vd] = n.vel_ned_mps;
    let speed = vn.hypot(ve);
    put(&mut m, "lat", num(n.lat_deg));
    put(&mut m, "lon", num(n.lon_deg));
    put(&mut m, "altHAE", num(n.height_m));
    if let Some(sep) = fix.map(|f| f.geoid_sep_m).filter(|s| s.is_finite()) {
        put(&mut m, "altMSL", num(n.height_m - sep));
        put(&mut m, "alt", num(n.height_m - sep));
        put(&mut m, "geoidSep", num(sep));
    }
    put(&mut m, "epx", num(2.0 * se));
    put(&mut m, "epy", num(2.0 * sn));
    put(&mut m, "epv", num(2.0 * sd));
    put(&mut m, "eph", num(2.0 * sn.hypot(se)));
    put(&mut m, "sep", num(2.0 * (sn * sn + se * se + sd * sd).sqrt()));
    put(&mut m, "track", num(ve.atan2(vn).to_degrees().rem_euclid(360.0)));
    put(&mut m, "speed", num(speed));
    put(&mut m, "climb", num(-vd));
    put(&mut m, "velN", num(vn));
    put(&mut m, "velE", num(ve));
    put(&mut m, "velD", num(vd));
    put(&mut m, "eps", num(2.0 * svn.hypot(sve)));
    put(&mut m, "epc", num(2.0 * svd));
    if speed > 0.1 {
        // Track error from the horizontal velocity error across the direction of travel.
        put(&mut m, "epd", num((2.0 * svn.hypot(sve) / speed).atan().to_degrees()));
    }
    Value::Object(m)
}

/// The `TPV` object of the receiver's own fix (no estimator, or its state not aligned or
/// stale): mode as the receiver's, status from its quality (gpsd_json(5): 2 DGPS, 3 RTK fixed,
/// 4 RTK float, 5 dead reckoning), `eph`/`epv`/`eps` the receiver's own accuracy estimates
/// (UBX hAcc/vAcc/sAcc, as gpsd reports them), or 2σ of NMEA GST.
pub fn tpv_of_fix(f: &GnssFix, time: Option<&TimeState>) -> Value {
    let mut m = Map::new();
    m.insert("class".into(), json!("TPV"));
    m.insert("device".into(), json!(DEVICE));
    let mode = if f.mode == 0 { 1 } else { f.mode.min(3) };
    m.insert("mode".into(), json!(mode));
    let status = match f.quality {
        2 => Some(2),
        4 => Some(3),
        5 => Some(4),
        6 => Some(5),
        1 => Some(1),
        _ => None,
    };
    put(&mut m, "status", status.filter(|_| mode >= 2).map(|s| json!(s)));
    put(&mut m, "time", iso_time(f.utc_ns));
    if let Some(t) = time.filter(|t| t.is_valid()) {
        put(&mut m, "leapseconds", Some(json!(t.leap_s)));
    }
    if mode < 2 {
        return Value::Object(m);
    }
    put(&mut m, "lat", num(f.lat_deg));
    put(&mut m, "lon", num(f.lon_deg));
    if mode == 3 {
        put(&mut m, "altMSL", num(f.alt_msl_m));
        put(&mut m, "alt", num(f.alt_msl_m));
        put(&mut m, "altHAE", num(f.alt_msl_m + f.geoid_sep_m));
        put(&mut m, "geoidSep", num(f.geoid_sep_m));
        put(&mut m, "climb", num(-f.vel_d_mps));
        put(&mut m, "velD", num(f.vel_d_mps));
    }
    put(&mut m, "speed", num(f.speed_mps));
    put(&mut m, "track", num(f.track_deg));
    put(&mut m, "velN", num(f.vel_n_mps));
    put(&mut m, "velE", num(f.vel_e_mps));
    let gst = |s: f64| num(2.0 * s);
    put(
        &mut m,
        "eph",
        num(f.h_acc_m).or_else(|| num(2.0 * f.std_lat_m.hypot(f.std_lon_m))),
    );
    put(&mut m, "epv", num(f.v_acc_m).or_else(|| gst(f.std_alt_m)));
    put(&mut m, "epx", gst(f.std_lon_m));
    put(&mut m, "epy", gst(f.std_lat_m));
    put(&mut m, "eps", num(f.s_acc_mps));
    Value::Object(m)
}

/// The `ATT` object: roll, pitch, heading in degrees.
pub fn att(n: &NavState) -> Value {
    let [r, p, y] = n.rpy_rad.map(f64::to_degrees);
    let mut m = Map::new();
    m.insert("class".into(), json!("ATT"));
    m.insert("device".into(), json!(DEVICE));
    put(&mut m, "time", iso_time(n.utc_ns));
    put(&mut m, "heading", num(y.rem_euclid(360.0)));
    put(&mut m, "pitch", num(p));
    put(&mut m, "roll", num(r));
    put(&mut m, "yaw", num(y.rem_euclid(360.0)));
    let [sr, sp, sy] = n.att_std_rad.map(f64::to_degrees);
    put(&mut m, "roll_st", num(sr));
    put(&mut m, "pitch_st", num(sp));
    put(&mut m, "yaw_st", num(sy));
    Value::Object(m)
}

/// The `IMU` object: body-frame specific force (m/s²) and angular rate (°/s).
pub fn imu(n: &NavState) -> Value {
    let mut m = Map::new();
    m.insert("class".into(), json!("IMU"));
    m.insert("device".into(), json!(DEVICE));
    put(&mut m, "time", iso_time(n.utc_ns));
    for (k, v) in ["acc_x", "acc_y", "acc_z"].iter().zip(n.accel_body_mps2) {
        put(&mut m, k, num(v));
    }
    for (k, v) in ["gyro_x", "gyro_y", "gyro_z"].iter().zip(n.gyro_body_rps) {
        put(&mut m, k, num(v.to_degrees()));
    }
    Value::Object(m)
}

/// The `SKY` object of a fix: dilutions of precision and satellites used.
pub fn sky(f: &GnssFix) -> Value {
    let mut m = Map::new();
    m.insert("class".into(), json!("SKY"));
    m.insert("device".into(), json!(DEVICE));
    put(&mut m, "time", iso_time(f.utc_ns));
    put(&mut m, "hdop", num(f.hdop));
    put(&mut m, "vdop", num(f.vdop));
    put(&mut m, "pdop", num(f.pdop));
    if f.sats_used != u16::MAX {
        m.insert("uSat".into(), json!(f.sats_used));
    }
    Value::Object(m)
}

fn version() -> Value {
    json!({
        "class": "VERSION",
        "release": format!("navsync {}", env!("CARGO_PKG_VERSION")),
        "rev": env!("CARGO_PKG_VERSION"),
        "proto_major": PROTO_MAJOR,
        "proto_minor": PROTO_MINOR,
    })
}

fn device(activated: &str) -> Value {
    json!({
        "class": "DEVICE",
        "path": DEVICE,
        "driver": "navsync GNSS/INS",
        "activated": activated,
        "flags": 1,
        "native": 0,
    })
}

fn watch_json(w: Watch) -> Value {
    json!({
        "class": "WATCH",
        "enable": w.enable,
        "json": w.json,
        "nmea": false,
        "raw": 0,
        "scaled": false,
        "timing": false,
        "split24": false,
        "pps": false,
    })
}

fn error(message: &str) -> Value {
    json!({ "class": "ERROR", "message": message })
}

/// The latest inputs.
#[derive(Default)]
struct Latest {
    nav: Option<NavState>,
    fix: Option<GnssFix>,
    time: Option<TimeState>,
}

impl Latest {
    /// The receiver's latest fix while it is under [`FRESH_FIX_NS`] old at `now_ns` (host
    /// monotonic).
    fn fresh_fix(&self, now_ns: i64) -> Option<GnssFix> {
        self.fix
            .filter(|f| now_ns.saturating_sub(f.stamp.host_ns).abs() < FRESH_FIX_NS)
    }

    fn activated(&self) -> String {
        self.nav
            .filter(|n| n.utc_ns != i64::MIN)
            .map(|n| format_rfc3339_ms(n.utc_ns))
            .unwrap_or_default()
    }
}

/// A period's report (`--report period`) on the fused state `n`: TPV, ATT, IMU, and SKY once a
/// fix was seen. While `n` is not aligned (the vehicle still standing before its alignment)
/// and the receiver's fix is under [`FRESH_FIX_NS`] old at `now_ns` (host monotonic), the
/// fix's own TPV instead (a receiver with a 3D fix is not reported as mode 1).
fn period_report(n: &NavState, latest: &Latest, now_ns: i64) -> Vec<String> {
    let mut lines = match latest.fresh_fix(now_ns) {
        Some(f) if !navigates(n) && f.mode >= 2 => vec![tpv_of_fix(&f, latest.time.as_ref()).to_string()],
        _ => vec![
            tpv(n, latest.fix.as_ref(), latest.time.as_ref()).to_string(),
            att(n).to_string(),
            imu(n).to_string(),
        ],
    };
    if let Some(f) = &latest.fix {
        lines.push(sky(f).to_string());
    }
    lines
}

/// A period's report (`--report period`) when no fused state is fresh (no estimator running,
/// or a dead one): the receiver's fix as its own TPV, then SKY, so a receiver alone serves
/// gpsd clients in the default mode too.
fn fix_period_report(fix: &GnssFix, latest: &Latest) -> Vec<String> {
    vec![tpv_of_fix(fix, latest.time.as_ref()).to_string(), sky(fix).to_string()]
}

/// The report of the latest fix's epoch (`--report fix`): the fused state's TPV, ATT and IMU
/// when it is aligned and under [`FRESH_NAV_NS`] old at `now_ns` (host monotonic), else the
/// fix's own TPV; then SKY.
fn fix_report(latest: &Latest, now_ns: i64) -> Option<Vec<String>> {
    let fix = latest.fix.as_ref()?;
    let fused = latest
        .nav
        .filter(|n| navigates(n) && now_ns.saturating_sub(n.host_ns).abs() < FRESH_NAV_NS);
    let mut lines = match fused {
        Some(n) => vec![
            tpv(&n, Some(fix), latest.time.as_ref()).to_string(),
            att(&n).to_string(),
            imu(&n).to_string(),
        ],
        None => vec![tpv_of_fix(fix, latest.time.as_ref()).to_string()],
    };
    lines.push(sky(fix).to_string());
    Some(lines)
}

/// The `POLL` object at `now_ns` (host monotonic): the fused state while fresh, else the
/// receiver's fix while fresh, else no fix (a `TPV` of mode 1, `active:0`).
fn poll_reply(latest: &Latest, now_ns: i64) -> Value {
    let fresh_nav = latest
        .nav
        .filter(|n| now_ns.saturating_sub(n.host_ns).abs() < FRESH_NAV_NS && n.status != NavStatus::Aligning as u8);
    let fresh_fix = latest.fresh_fix(now_ns);
    let (tpv, active) = match (&fresh_nav, &fresh_fix) {
        (Some(n), fix) => (tpv(n, fix.as_ref().or(latest.fix.as_ref()), latest.time.as_ref()), 1),
        (None, Some(f)) => (tpv_of_fix(f, latest.time.as_ref()), 1),
        (None, None) => (json!({"class": "TPV", "device": DEVICE, "mode": 1}), 0),
    };
    let skies: Vec<Value> = fresh_fix.iter().map(sky).collect();
    let time = fresh_nav
        .and_then(|n| iso_time(n.utc_ns))
        .unwrap_or_else(|| json!(format_rfc3339_ms(navsync_shared::time::realtime_now_ns())));
    json!({
        "class": "POLL",
        "time": time,
        "active": active,
        "tpv": [tpv],
        "gst": [],
        "sky": skies,
    })
}

/// A command name as echoed in an `ERROR`: at most 32 characters (a name can be as long as
/// the request line).
fn shown(name: &str) -> &str {
    name.get(..32).unwrap_or(name)
}

/// Answers the commands of one client.
fn handle(c: &mut Client, cmds: impl IntoIterator<Item = Command>, latest: &Latest, now_ns: i64) {
    for cmd in cmds {
        match (cmd.name.as_str(), &cmd.arg) {
            (_, Some(Value::Null)) => c.queue(&error(&format!("Invalid {} argument", shown(&cmd.name))).to_string()),
            ("VERSION", _) => c.queue(&version().to_string()),
            ("DEVICES", _) => {
                c.queue(&json!({"class": "DEVICES", "devices": [device(&latest.activated())]}).to_string())
            }
            ("DEVICE", _) => c.queue(&device(&latest.activated()).to_string()),
            ("WATCH", arg) => {
                if let Some(a) = arg {
                    let enable = a.get("enable").and_then(Value::as_bool).unwrap_or(true);
                    let json = a.get("json").and_then(Value::as_bool).unwrap_or(c.watch.json || enable);
                    c.watch = Watch { enable, json };
                    if enable {
                        c.queue(&json!({"class": "DEVICES", "devices": [device(&latest.activated())]}).to_string());
                    }
                }
                c.queue(&watch_json(c.watch).to_string());
            }
            ("POLL", _) => c.queue(&poll_reply(latest, now_ns).to_string()),
            (other, _) => c.queue(&error(&format!("Unrecognized request '{}'", shown(other))).to_string()),
        }
    }
}

/// Runs the server until SIGINT/SIGTERM.
pub fn run(args: &GpsdArgs) -> Result<(), GpsdError> {
    let io = |what: &str| {
        let what = what.to_string();
        move |source| GpsdError::Io { what, source }
    };
    let node = IpcNode::new("gpsd-server")?;
    let nav_sub = node.input::<NavState>(services::NAV_STATE)?;
    let fix_service = services::gnss_fix(&args.gnss_id);
    let fix_sub = node.input::<GnssFix>(&fix_service)?;
    // The fix's wake-up as a descriptor for the poll(2) set below.
    let fix_wake = navsync_shared::ipc::WakeFd::new("gpsd-server", &fix_service)?;
    let time_sub = node.input::<TimeState>(services::TIME_STATE)?;
    let mut health = HealthReporter::new(&node, "gpsd-server")?;
    let c_accepted = health.counter("clients_accepted")?;
    let c_rejected = health.counter("clients_rejected")?;
    let c_slow = health.counter("clients_dropped_slow")?;
    let c_active = health.counter("clients_active")?;
    let c_reports = health.counter("reports_sent")?;
    let c_bad = health.counter("bad_requests")?;
    let c_idle = health.counter("clients_dropped_idle")?;
    let c_throttled = health.counter("clients_throttled")?;
    let limits = ClientLimits::with_idle_timeout_s(args.idle_timeout_s);
    let r_tpv = health.rate("tpv_out")?;

    let listener = TcpListener::bind(args.listen).map_err(io(&format!("listening on {}", args.listen)))?;
    listener.set_nonblocking(true).map_err(io("listener"))?;
    let local = listener.local_addr().map_err(io("listener address"))?;
    // The bound address on stderr (with --listen …:0 the port the system chose).
    eprintln!("navsync gpsd-server: listening on {local}");
    info!(%local, max_clients = args.max_clients, "gpsd server");
    navsync_shared::sd_notify::ready(&format!("gpsd-server on {local}"));

    let period_ns = (1e9 / args.rate_hz.clamp(0.01, 1000.0)) as i64;
    // Period reports go out within 10 ms of their state; fix reports are woken by the fix
    // itself, and the wait only paces the draining of the fused state (its buffer holds more).
    let poll_ms = match args.report {
        ReportOn::Period => 10,
        ReportOn::Fix => 100,
    };
    let mut clients: Vec<Client> = Vec::new();
    let mut latest = Latest::default();
    let mut last_slot: Option<i64> = None;
    let mut last_fix_slot: Option<i64> = None;
    let mut rx = [0u8; 2048];
    while !node.termination_requested() {
        // poll(2): the listener, the fix subscriber's wake-up (a fix is reported the moment
        // it arrives with `--report fix`) and every client (writable only while output is
        // pending). The timeout paces the period reports and the fused state's draining.
        let mut fds: Vec<libc::pollfd> = Vec::with_capacity(2 + clients.len());
        fds.push(libc::pollfd {
            fd: listener.as_raw_fd(),
            events: libc::POLLIN,
            revents: 0,
        });
        fds.push(libc::pollfd {
            fd: fix_wake.fd(),
            events: libc::POLLIN,
            revents: 0,
        });
        for c in &clients {
            // A client whose requests wait for tokens is not read (TCP pushes back on it).
            let mut events = if c.wants_input() { libc::POLLIN } else { 0 };
            if !c.out.is_empty() {
                events |= libc::POLLOUT;
            }
            fds.push(libc::pollfd {
                fd: c.stream.as_raw_fd(),
                events,
                revents: 0,
            });
        }
        // A client held back by its bucket is looked at again within 50 ms.
        let timeout_ms = if clients.iter().any(|c| !c.backlog.is_empty()) {
            poll_ms.min(50)
        } else {
            poll_ms
        };
        // SAFETY: fds is a valid array of pollfd for the call's duration.
        let n = unsafe { libc::poll(fds.as_mut_ptr(), fds.len() as libc::nfds_t, timeout_ms) };
        if n < 0 {
            let e = std::io::Error::last_os_error();
            if e.kind() != ErrorKind::Interrupted {
                return Err(GpsdError::Io {
                    what: "poll".into(),
                    source: e,
                });
            }
        }
        // New clients.
        if fds[0].revents & libc::POLLIN != 0 {
            loop {
                match listener.accept() {
                    Ok((stream, peer)) => {
                        let mut c = Client::accepted(stream, peer);
                        if clients.len() >= args.max_clients {
                            health.add(c_rejected, 1);
                            c.queue(&error("too many clients").to_string());
                            let _ = c.flush();
                            warn!(%peer, "client rejected: {} clients already", clients.len());
                            continue;
                        }
                        health.add(c_accepted, 1);
                        c.queue(&version().to_string());
                        c.flush();
                        info!(%peer, "client connected");
                        clients.push(c);
                    }
                    Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                    Err(e) if e.kind() == ErrorKind::Interrupted => {}
                    Err(e) => {
                        warn!("accept: {e}");
                        break;
                    }
                }
            }
        }
        // Requests and writable sockets.
        let now = monotonic_now_ns();
        for (c, pfd) in clients.iter_mut().zip(fds.iter().skip(2)) {
            if pfd.revents & (libc::POLLIN | libc::POLLHUP | libc::POLLERR) != 0 && c.wants_input() {
                match read_requests(c, &mut rx, &limits, now) {
                    Ok(bad) => health.add(c_bad, bad),
                    Err(RequestError::LineTooLong) => {
                        health.add(c_bad, 1);
                        c.queue(&error("request line too long").to_string());
                        let _ = c.flush();
                        c.closing = true;
                    }
                }
            }
            if pfd.revents & (libc::POLLHUP | libc::POLLERR) != 0 && !c.wants_input() {
                // Gone while its requests waited: nobody to answer.
                c.closing = true;
            }
            if !c.backlog.is_empty() && answer_backlog(c, &latest, &limits, now) {
                health.add(c_throttled, 1);
            }
            if !c.out.is_empty() && !c.flush() {
                c.closing = true;
            } else if c.out.len() > limits.max_pending_bytes {
                // Replies to requests count against the same bound as watch reports.
                warn!(peer = %c.peer, pending = c.out.len(), "dropping a client that does not read its replies");
                health.add(c_slow, 1);
                c.closing = true;
            } else if c.idle(now, &limits) {
                info!(peer = %c.peer, "closing an idle client");
                health.add(c_idle, 1);
                c.closing = true;
            }
        }
        // Inputs: the fused state before the fixes, so a fix's report has the newest state.
        while let Some(t) = time_sub.receive()? {
            latest.time = Some(t);
        }
        let mut due = None;
        while let Some(n) = nav_sub.receive()? {
            // Report on the first state of each period (UTC when known, else host time).
            let t = if n.utc_ns != i64::MIN { n.utc_ns } else { n.host_ns };
            let slot = t.div_euclid(period_ns);
            if last_slot != Some(slot) {
                last_slot = Some(slot);
                due = Some(n);
            }
            latest.nav = Some(n);
        }
        let mut new_fixes = 0usize;
        fix_wake.clear();
        fix_sub.drain(|f| {
            latest.fix = Some(f);
            new_fixes += 1;
            true
        })?;
        let now_ns = monotonic_now_ns();
        // Without a fresh fused state, the period's first fix (by its UTC, else host time).
        let nav_fresh = latest
            .nav
            .is_some_and(|n| now_ns.saturating_sub(n.host_ns).abs() < FRESH_NAV_NS);
        let due_fix = latest.fix.filter(|f| {
            let t = if f.utc_ns != i64::MIN {
                f.utc_ns
            } else {
                f.stamp.host_ns
            };
            let slot = t.div_euclid(period_ns);
            let due = new_fixes > 0 && !nav_fresh && due.is_none() && last_fix_slot != Some(slot);
            if due {
                last_fix_slot = Some(slot);
            }
            due
        });
        let lines = match args.report {
            ReportOn::Period => due
                .map(|n| period_report(&n, &latest, now_ns))
                .or_else(|| due_fix.map(|f| fix_period_report(&f, &latest))),
            ReportOn::Fix if new_fixes > 0 => fix_report(&latest, now_ns),
            ReportOn::Fix => None,
        };
        if let Some(lines) = lines {
            health.tick(r_tpv);
            for c in clients
                .iter_mut()
                .filter(|c| c.watch.enable && c.watch.json && !c.closing)
            {
                health.add(c_reports, 1);
                match deliver(c, &lines, MAX_PENDING_BYTES) {
                    Delivery::Kept => {}
                    Delivery::Gone => c.closing = true,
                    Delivery::Slow => {
                        warn!(peer = %c.peer, pending = c.out.len(), "dropping a slow client");
                        health.add(c_slow, 1);
                        c.closing = true;
                    }
                }
            }
        }
        clients.retain(|c| {
            if c.closing {
                info!(peer = %c.peer, "client gone");
            }
            !c.closing
        });
        health.set(c_active, clients.len() as u64);
        health.maybe_publish(monotonic_now_ns())?;
        navsync_shared::sd_notify::watchdog();
    }
    navsync_shared::sd_notify::stopping();
    health.publish_final()?;
    Ok(())
}

/// A request that closes its client.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum RequestError {
    /// A line longer than [`ClientLimits::max_request_bytes`].
    LineTooLong,
}

/// Reads what the client sent (at most one line's bound at a time, so the buffer stays
/// bounded whatever it sends) into its backlog of requests; the number of malformed ones.
fn read_requests(c: &mut Client, rx: &mut [u8], limits: &ClientLimits, now_ns: i64) -> Result<u64, RequestError> {
    loop {
        let room = limits
            .max_request_bytes
            .saturating_sub(c.inbuf.len())
            .clamp(1, rx.len());
        match c.stream.read(&mut rx[..room]) {
            Ok(0) => {
                c.closing = true;
                break;
            }
            Ok(k) => c.inbuf.extend_from_slice(&rx[..k]),
            Err(e) if e.kind() == ErrorKind::WouldBlock => break,
            Err(e) if e.kind() == ErrorKind::Interrupted => continue,
            Err(_) => {
                c.closing = true;
                break;
            }
        }
        let (cmds, used) = parse_commands(&c.inbuf);
        c.inbuf.drain(..used);
        if !cmds.is_empty() {
            c.last_request_ns = now_ns;
        }
        c.backlog.extend(cmds);
        if c.inbuf.len() >= limits.max_request_bytes {
            return Err(RequestError::LineTooLong);
        }
        if !c.backlog.is_empty() {
            // Answer these first; the rest waits in the socket.
            break;
        }
    }
    Ok(c.backlog.iter().filter(|k| k.arg == Some(Value::Null)).count() as u64)
}

/// Answers as many waiting requests as the client's bucket allows; true when the client has
/// just started to wait for tokens (counted once per episode).
fn answer_backlog(c: &mut Client, latest: &Latest, limits: &ClientLimits, now_ns: i64) -> bool {
    c.refill(now_ns, limits);
    let n = (c.tokens.floor().max(0.0) as usize).min(c.backlog.len());
    c.tokens -= n as f64;
    let cmds: Vec<Command> = c.backlog.drain(..n).collect();
    handle(c, cmds, latest, now_ns);
    let started = !c.backlog.is_empty() && !c.throttled;
    c.throttled = !c.backlog.is_empty();
    started
}

#[cfg(test)]
mod tests {
    use super::*;
    use navsync_shared::reflect::Reflect;

    /// A real loopback TCP connection: the server side as the run loop accepts it, and the
    /// peer's socket.
    fn connected_pair() -> (Client, TcpStream) {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let peer = TcpStream::connect(listener.local_addr().unwrap()).unwrap();
        let (stream, addr) = listener.accept().unwrap();
        (Client::accepted(stream, addr), peer)
    }

    /// One report's worth of lines, about 1.5 KiB like TPV + ATT + IMU + SKY.
    fn report() -> Vec<String> {
        (0..4)
            .map(|i| format!("{{\"class\":\"X{i}\",\"pad\":\"{}\"}}", "x".repeat(370)))
            .collect()
    }

    #[test]
    fn a_client_that_stops_reading_is_dropped_once_its_queue_passes_the_bound() {
        let (mut c, peer) = connected_pair();
        let lines = report();
        let per_report: usize = lines.iter().map(|l| l.len() + 1).sum();
        // The peer never reads: the kernel's buffers fill (a few MiB at most on loopback), then
        // the queue grows until the bound is passed. Never blocks: each call returns at once.
        let mut reports = 0usize;
        let verdict = loop {
            match deliver(&mut c, &lines, MAX_PENDING_BYTES) {
                Delivery::Kept => reports += 1,
                other => break other,
            }
            assert!(
                reports < 100_000,
                "never dropped after {} MiB",
                (reports * per_report) >> 20
            );
        };
        assert_eq!(verdict, Delivery::Slow);
        assert!(c.out.len() > MAX_PENDING_BYTES);
        assert!(
            c.out.len() <= MAX_PENDING_BYTES + per_report,
            "the bound is checked per report"
        );
        println!(
            "dropped after {reports} reports ({} KiB sent, {} KiB in the kernel's buffers)",
            (reports * per_report) >> 10,
            (reports * per_report - c.out.len()) >> 10
        );
        drop(peer);
    }

    #[test]
    fn a_client_that_reads_is_kept_and_gets_every_byte() {
        let (mut c, mut peer) = connected_pair();
        let lines = report();
        let per_report: usize = lines.iter().map(|l| l.len() + 1).sum();
        let mut buf = vec![0u8; per_report];
        // Twice the volume that drops a silent client, read as it comes.
        let n = 2 * (MAX_PENDING_BYTES + (8 << 20)) / per_report;
        for _ in 0..n {
            assert_eq!(deliver(&mut c, &lines, MAX_PENDING_BYTES), Delivery::Kept);
            // Drain what was queued (the socket may hold part of it back until read).
            let mut got = 0;
            while got < per_report {
                got += peer.read(&mut buf[got..]).unwrap();
                assert!(c.flush());
            }
            assert_eq!(&buf[..lines[0].len()], lines[0].as_bytes());
        }
        assert!(c.out.is_empty());
    }

    #[test]
    fn a_client_that_closed_is_gone() {
        let (mut c, peer) = connected_pair();
        drop(peer);
        let lines = report();
        // The first write may still succeed (the peer's RST arrives after it); the next fail.
        let verdicts: Vec<Delivery> = (0..50).map(|_| deliver(&mut c, &lines, MAX_PENDING_BYTES)).collect();
        assert!(verdicts.contains(&Delivery::Gone), "{verdicts:?}");
    }

    #[test]
    fn commands_are_split_and_incomplete_ones_kept() {
        let (c, used) = parse_commands(b"?WATCH={\"enable\":true,\"json\":true};?POLL;\n?VERS");
        assert_eq!(c.len(), 2);
        assert_eq!(c[0].name, "WATCH");
        assert_eq!(c[0].arg, Some(json!({"enable": true, "json": true})));
        assert_eq!(
            c[1],
            Command {
                name: "POLL".into(),
                arg: None
            }
        );
        assert_eq!(used, 42);
        let (c, used) = parse_commands(b"?WATCH={\"enable\":tr");
        assert!(c.is_empty());
        assert_eq!(used, 0);
        let (c, _) = parse_commands(b"?WATCH={bad};\r\n");
        assert_eq!(c[0].arg, Some(Value::Null));
        let (c, used) = parse_commands(b"garbage\n?version;");
        assert_eq!(c[0].name, "VERSION");
        assert_eq!(used, 17);
    }

    #[test]
    fn an_unbalanced_brace_costs_its_own_line_only() {
        // Before: the brace search ran past the line end and swallowed every later request.
        let text = b"?WATCH={\"enable\":true\n?VERSION;\n?POLL;\n";
        let (c, used) = parse_commands(text);
        let names: Vec<&str> = c.iter().map(|k| k.name.as_str()).collect();
        assert_eq!(names, ["WATCH", "VERSION", "POLL"]);
        assert_eq!(c[0].arg, Some(Value::Null), "malformed, answered with an ERROR");
        assert_eq!(used, text.len());
        let (c, _) = parse_commands(b"?WATCH=}}{\n?DEVICES;");
        assert_eq!(c.len(), 2);
        assert_eq!(c[1].name, "DEVICES");
    }

    /// A client flooding `?POLL;` without ever reading, served as the run loop does.
    #[test]
    fn a_client_that_floods_requests_and_never_reads_stays_bounded_and_is_dropped() {
        let (mut c, mut peer) = connected_pair();
        peer.set_nonblocking(true).unwrap();
        let limits = ClientLimits::with_idle_timeout_s(180.0);
        let mut n = NavState::zeroed();
        n.status = NavStatus::Aligned as u8;
        n.lat_deg = 48.0;
        n.lon_deg = 11.0;
        let mut latest = Latest {
            nav: Some(n),
            fix: None,
            time: None,
        };
        let mut rx = [0u8; 2048];
        let flood = b"?POLL;".repeat(100);
        let (mut now, mut answered, mut max_backlog) = (0i64, 0usize, 0usize);
        let dropped = loop {
            let _ = peer.write(&flood);
            latest.nav.as_mut().unwrap().host_ns = now;
            if c.wants_input() {
                assert_eq!(read_requests(&mut c, &mut rx, &limits, now), Ok(0));
            }
            max_backlog = max_backlog.max(c.backlog.len());
            let before = c.backlog.len();
            answer_backlog(&mut c, &latest, &limits, now);
            answered += before - c.backlog.len();
            assert!(c.flush(), "the peer is there");
            if c.out.len() > limits.max_pending_bytes {
                break true;
            }
            now += 10_000_000;
            if now > 3_600 * 1_000_000_000 {
                break false;
            }
        };
        assert!(dropped, "never passed the output bound");
        let seconds = now as f64 * 1e-9;
        // The bucket held it to its rate: at most the burst plus the rate over the time.
        assert!(
            answered as f64 <= REQUEST_BURST + REQUESTS_PER_S * seconds + 1.0,
            "{answered} answers in {seconds} s"
        );
        // One read's worth of requests at most waits (2048 bytes of 6-byte requests).
        assert!(max_backlog <= 2048 / 6 + 1, "{max_backlog}");
        assert!(c.inbuf.len() < limits.max_request_bytes);
        println!("dropped after {seconds:.0} s of flooding, {answered} requests answered");
    }

    #[test]
    fn a_request_line_longer_than_the_bound_is_refused() {
        let (mut c, mut peer) = connected_pair();
        let limits = ClientLimits::with_idle_timeout_s(180.0);
        peer.write_all(&[b'x'; MAX_REQUEST_BYTES + 10]).unwrap();
        let mut rx = [0u8; 2048];
        let mut r = Ok(0);
        for _ in 0..100 {
            r = read_requests(&mut c, &mut rx, &limits, 0);
            if r.is_err() {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        assert_eq!(r, Err(RequestError::LineTooLong));
        assert!(c.inbuf.len() <= MAX_REQUEST_BYTES);
    }

    #[test]
    fn an_idle_client_that_does_not_watch_times_out() {
        let (mut c, _peer) = connected_pair();
        let limits = ClientLimits::with_idle_timeout_s(180.0);
        let t0 = c.last_request_ns;
        assert!(!c.idle(t0 + 179_000_000_000, &limits));
        assert!(c.idle(t0 + 181_000_000_000, &limits));
        c.watch.enable = true;
        assert!(!c.idle(t0 + 3_600_000_000_000, &limits), "a watcher is never idle");
    }

    #[test]
    fn poll_reports_no_fix_once_the_state_and_the_fix_are_stale() {
        let mut n = NavState::zeroed();
        n.status = NavStatus::Aligned as u8;
        n.lat_deg = 48.0;
        n.lon_deg = 11.0;
        n.utc_ns = 1_700_000_000_000_000_000;
        n.host_ns = 100_000_000_000;
        let mut f = GnssFix::empty(navsync_shared::samples::Stamp::host(
            n.host_ns,
            0,
            navsync_shared::samples::StampSource::Receipt,
        ));
        f.mode = 3;
        f.lat_deg = 48.0;
        f.lon_deg = 11.0;
        let latest = Latest {
            nav: Some(n),
            fix: Some(f),
            time: None,
        };
        let fresh = poll_reply(&latest, n.host_ns + 100_000_000);
        assert_eq!(
            (fresh["active"].as_u64(), fresh["tpv"][0]["mode"].as_u64()),
            (Some(1), Some(3))
        );
        assert_eq!(fresh["tpv"][0]["status"], 6, "{fresh}");
        // The estimator stopped; the receiver goes on: its fix.
        let fix_only = poll_reply(&latest, n.host_ns + FRESH_NAV_NS + 1);
        assert_eq!(fix_only["active"], 1);
        assert!(fix_only["tpv"][0].get("status").is_none(), "{fix_only}");
        // Both stale (the estimator died 23 s ago, as in the report): no fix at all.
        let dead = poll_reply(&latest, n.host_ns + 23_000_000_000);
        assert_eq!(dead["active"], 0, "{dead}");
        assert_eq!(dead["tpv"][0]["mode"], 1, "{dead}");
        assert!(dead["tpv"][0].get("lat").is_none() && dead["tpv"][0].get("ept").is_none());
        assert_eq!(dead["sky"].as_array().map(Vec::len), Some(0));
    }

    #[test]
    fn a_receivers_fix_becomes_a_tpv_and_a_stale_state_is_not_reported() {
        let mut f = GnssFix::empty(navsync_shared::samples::Stamp::host(
            0,
            0,
            navsync_shared::samples::StampSource::Receipt,
        ));
        f.mode = 3;
        f.quality = 4;
        f.utc_ns = 1_700_000_000_000_000_000;
        f.lat_deg = 48.1;
        f.lon_deg = 11.5;
        f.alt_msl_m = 500.0;
        f.geoid_sep_m = 47.0;
        f.vel_d_mps = -0.25;
        f.h_acc_m = 0.02;
        let v = tpv_of_fix(&f, None);
        assert_eq!((v["mode"].as_u64(), v["status"].as_u64()), (Some(3), Some(3)), "{v}");
        assert_eq!(v["altHAE"], 547.0);
        assert_eq!(v["climb"], 0.25);
        assert_eq!(v["eph"], 0.02);
        assert!(v.get("epx").is_none(), "no GST: no epx");
        f.mode = 1;
        let v = tpv_of_fix(&f, None);
        assert!(v.get("lat").is_none() && v.get("status").is_none(), "{v}");
        f.mode = 3;

        // A fused state is reported only while aligned and fresh.
        let mut n = NavState::zeroed();
        n.status = NavStatus::Aligned as u8;
        n.lat_deg = 1.0;
        n.lon_deg = 2.0;
        n.host_ns = 10_000_000_000;
        let latest = Latest {
            nav: Some(n),
            fix: Some(f),
            time: None,
        };
        let fused = fix_report(&latest, n.host_ns + 1_000_000).unwrap();
        assert_eq!(fused.len(), 4, "TPV ATT IMU SKY");
        assert!(fused[0].contains("\"lat\":1.0"), "{}", fused[0]);
        let stale = fix_report(&latest, n.host_ns + FRESH_NAV_NS + 1).unwrap();
        assert_eq!(stale.len(), 2, "TPV SKY");
        assert!(stale[0].contains("\"lat\":48.1"), "{}", stale[0]);
        assert!(fix_report(&Latest::default(), 0).is_none());
    }

    #[test]
    fn tpv_carries_position_velocity_and_2_sigma_errors() {
        let mut n = NavState::zeroed();
        n.status = NavStatus::Aligned as u8;
        n.utc_ns = 1_700_000_000_123_000_000;
        n.lat_deg = 48.1;
        n.lon_deg = 11.5;
        n.height_m = 600.0;
        n.vel_ned_mps = [3.0, 4.0, -0.5];
        n.pos_std_ned_m = [0.3, 0.4, 0.6];
        n.vel_std_ned_mps = [0.03, 0.04, 0.05];
        let mut fix = GnssFix::empty(navsync_shared::samples::Stamp::host(
            0,
            0,
            navsync_shared::samples::StampSource::Receipt,
        ));
        fix.geoid_sep_m = 47.0;
        let v = tpv(&n, Some(&fix), None);
        assert_eq!(v["mode"], 3);
        assert_eq!(v["status"], 6);
        assert_eq!(v["time"], "2023-11-14T22:13:20.123Z");
        assert_eq!(v["altMSL"], 553.0);
        assert!((v["speed"].as_f64().unwrap() - 5.0).abs() < 1e-12);
        assert!((v["track"].as_f64().unwrap() - 53.130102354).abs() < 1e-6);
        assert!((v["climb"].as_f64().unwrap() - 0.5).abs() < 1e-12);
        assert!((v["epx"].as_f64().unwrap() - 0.8).abs() < 1e-12);
        assert!((v["epy"].as_f64().unwrap() - 0.6).abs() < 1e-12);
        assert!((v["eph"].as_f64().unwrap() - 1.0).abs() < 1e-12);
        n.status = NavStatus::Aligning as u8;
        let v = tpv(&n, None, None);
        assert_eq!(v["mode"], 1);
        assert!(v.get("lat").is_none());
    }
}
