//! `navsync web [--listen 127.0.0.1:8080] [--allow-remote]`: the running system in a browser
//! and for Prometheus, from one more subscriber (the other processes are untouched).
//!
//! * `/`: one self-contained page (`web/page.html`: inline CSS, JavaScript and SVG; no
//!   external script, font or tile, so it works on an offline vehicle) with the state at the
//!   time of the request inlined, then updated over Server-Sent Events from `/events`.
//! * `/events`: one JSON object per second (`text/event-stream`): what `navsync status --json`
//!   reports (processes, services, health, time, nav; gathered by the same code,
//!   [`super::status::Status`]) and what the page needs beside it ([`extras`]): the GNSS −
//!   host clock offset and σ now, the navigation σ, each receiver's fix quality and sky (its
//!   latest `GnssSky`: every satellite's azimuth, elevation, C/N0 and whether it is used, drawn
//!   as a polar plot), the IMUs' sample counts and the track in local ENU.
//! * `/metrics`: the same in Prometheus's text exposition format ([`metrics_text`]).
//! * `/state.json`: the latest of those objects.
//!
//! Read-only: GET and HEAD only (others 405), no request body (413). Loopback by default;
//! another address only with `--allow-remote`; on loopback a request must name a loopback host
//! (421 otherwise: a page elsewhere cannot read it through DNS rebinding). Bounded against
//! hostile clients, every bound counted in `navsync/health/web` and in `/metrics`: at most
//! `--max-connections` connections at once (one more is answered 503 and closed), at most
//! `--max-streams` of them event streams (503 beyond); a request head over [`MAX_HEAD_BYTES`]
//! is answered 431 (413 with a body), one not complete within [`REQUEST_TIMEOUT`] 408; a client
//! that does not take a write within `--write-timeout` (its socket's send buffer bounded to
//! [`SEND_BUFFER_BYTES`]) is dropped.
//!
//! Threads, all under `SCHED_IDLE` (they run on what the pipeline leaves of the CPU,
//! [`super::run_as_observer`]): the main thread gathers (iceoryx2) and publishes a snapshot once a second; one
//! thread accepts; one thread per connection (so at most `--max-connections`) reads the
//! request and answers it from the snapshot. No async runtime, no HTTP crate: the bounds sit
//! on the socket (the cap answered before a byte is parsed, the send buffer, the write
//! timeout), which the small synchronous HTTP crates keep inside their own thread pools.

use std::collections::{BTreeMap, VecDeque};
use std::fmt::Write as _;
use std::io::{ErrorKind, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use navsync_shared::earth::ned_between;
use navsync_shared::health_reporter::{CounterId, HealthReporter};
use navsync_shared::ipc::IpcError;
use navsync_shared::samples::{AnySample, GnssFix, GnssSky, NavState, NavStatus, TimeState};
use navsync_shared::time::{format_rfc3339_ms, monotonic_now_ns, realtime_now_ns};
use serde_json::{Value, json};
use tracing::{info, warn};

use super::status::{Status, StatusError};

/// The page, with `/*STATE*/null` where the state at the time of the request goes.
const PAGE: &str = include_str!("web/page.html");
/// Where the page takes the state inlined.
const PAGE_STATE_SLOT: &str = "/*STATE*/null";

/// The longest request head (request line and headers); beyond it: 431.
pub const MAX_HEAD_BYTES: usize = 8 * 1024;
/// A request head must be complete this long after the connection was accepted (else 408).
pub const REQUEST_TIMEOUT: Duration = Duration::from_secs(5);
/// The kernel's send buffer of a client socket: a client that does not read fills it soon, and
/// its next write times out (autotuning would hold megabytes for it).
pub const SEND_BUFFER_BYTES: libc::c_int = 64 * 1024;
/// The track kept for the page: this many points, one a second.
pub const TRACK_POINTS: usize = 600;
/// An event stream idle for this long gets a comment line (proxies and browsers keep it open).
const KEEPALIVE: Duration = Duration::from_secs(15);
/// After an error answer, what the client still sends is read and dropped for at most this
/// long (and [`LINGER_BYTES`]), so the answer is not lost to a reset.
const LINGER: Duration = Duration::from_millis(500);
/// See [`LINGER`].
const LINGER_BYTES: usize = 2 << 20;

/// Settings of `navsync web`.
#[derive(Debug, Clone, clap::Args)]
pub struct WebArgs {
    /// Address to listen on (loopback by default; port 0: any free port, printed on stderr).
    /// An address other than loopback needs --allow-remote.
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub listen: SocketAddr,
    /// Allow --listen on an address other than loopback (the page and the metrics are
    /// read-only, but anyone who reaches the address reads them: no authentication, no TLS).
    #[arg(long)]
    pub allow_remote: bool,
    /// Most connections at once; one more is answered 503 and closed.
    #[arg(long, default_value_t = 16, value_parser = at_least_one)]
    pub max_connections: usize,
    /// Most event streams (/events, the open pages) at once, fewer than --max-connections so
    /// open pages never lock out a Prometheus scrape; one more is answered 503.
    #[arg(long, default_value_t = 8, value_parser = at_least_one)]
    pub max_streams: usize,
    /// A client that does not take a write for this long is dropped, s.
    #[arg(long = "write-timeout", value_name = "S", default_value = "5", value_parser = super::echo::positive_seconds)]
    pub write_timeout: Duration,
    /// Also serve Foxglove's live protocol (the Foxglove WebSocket protocol, subprotocol
    /// `foxglove.websocket.v1`; Foxglove's and Lichtblick's "Foxglove WebSocket" connection, port
    /// 8765 by convention) on this address, every navsync service as a channel in the
    /// recordings' schemas and CDR; loopback unless --allow-remote; at most --max-connections
    /// clients.
    #[arg(long, value_name = "ADDR")]
    pub foxglove_listen: Option<SocketAddr>,
}

fn at_least_one(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if n > 0 => Ok(n),
        _ => Err(format!("`{s}`: expected at least 1")),
    }
}

/// Errors of `navsync web`.
#[derive(Debug, thiserror::Error)]
pub enum WebError {
    /// `--listen` on an address other than loopback without `--allow-remote`.
    #[error(
        "--listen {0}: not a loopback address; the page and the metrics would be readable from the \
         network (read-only, no authentication, no TLS): add --allow-remote to mean it"
    )]
    NotLoopback(SocketAddr),
    /// `--max-streams` not below `--max-connections`.
    #[error("--max-streams {streams} must be below --max-connections {connections} (room for a scrape)")]
    Streams {
        /// `--max-streams`.
        streams: usize,
        /// `--max-connections`.
        connections: usize,
    },
    /// Gathering failed.
    #[error(transparent)]
    Status(#[from] StatusError),
    /// IPC failure.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// A health counter could not be registered.
    #[error(transparent)]
    Health(#[from] navsync_shared::health_reporter::HealthError),
    /// Socket failure.
    #[error("{what}: {source}")]
    Io {
        /// What was done.
        what: String,
        /// Cause.
        source: std::io::Error,
    },
}

/// Refuses an address other than loopback unless `allow_remote`.
pub fn check_listen(addr: SocketAddr, allow_remote: bool) -> Result<(), WebError> {
    if addr.ip().is_loopback() || allow_remote {
        Ok(())
    } else {
        Err(WebError::NotLoopback(addr))
    }
}

// ---------------------------------------------------------------------------------------------
// HTTP: one request per connection, GET and HEAD.

/// A request the server answers.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Request {
    /// The path, without the query.
    pub path: String,
    /// HEAD: the headers only.
    pub head_only: bool,
    /// The `Host` header, when there is one.
    pub host: Option<String>,
}

/// Why a request head is refused, as its status.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reject {
    /// 400: not HTTP/1.x.
    BadRequest,
    /// 405: a method other than GET or HEAD.
    MethodNotAllowed,
    /// 413: a request with a body.
    PayloadTooLarge,
    /// 431: the head over [`MAX_HEAD_BYTES`].
    HeadTooLarge,
    /// 408: the head not complete within [`REQUEST_TIMEOUT`].
    Timeout,
    /// 421: a `Host` that is not a loopback name while listening on loopback only (a page
    /// elsewhere reaching this server through DNS rebinding).
    ForeignHost,
}

impl Reject {
    /// The status line's code and reason.
    pub fn status(self) -> (u16, &'static str) {
        match self {
            Self::BadRequest => (400, "Bad Request"),
            Self::MethodNotAllowed => (405, "Method Not Allowed"),
            Self::PayloadTooLarge => (413, "Content Too Large"),
            Self::HeadTooLarge => (431, "Request Header Fields Too Large"),
            Self::Timeout => (408, "Request Timeout"),
            Self::ForeignHost => (421, "Misdirected Request"),
        }
    }

    fn counter(self) -> Count {
        match self {
            Self::BadRequest => Count::BadRequests,
            Self::MethodNotAllowed => Count::MethodNotAllowed,
            Self::PayloadTooLarge | Self::HeadTooLarge => Count::TooLarge,
            Self::Timeout => Count::Timeouts,
            Self::ForeignHost => Count::ForeignHosts,
        }
    }
}

/// The end of a request head (`\r\n\r\n`, or `\n\n` from a sloppy client) in `buf`: the
/// head's length.
fn head_end(buf: &[u8]) -> Option<usize> {
    let crlf = buf.windows(4).position(|w| w == b"\r\n\r\n").map(|i| i + 4);
    let lf = buf.windows(2).position(|w| w == b"\n\n").map(|i| i + 2);
    match (crlf, lf) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

/// Parses a complete request head. Pure.
pub fn parse_head(head: &[u8]) -> Result<Request, Reject> {
    let text = std::str::from_utf8(head).map_err(|_| Reject::BadRequest)?;
    let mut lines = text.split('\n').map(|l| l.strip_suffix('\r').unwrap_or(l));
    let line = lines.next().ok_or(Reject::BadRequest)?;
    let mut parts = line.split(' ');
    let (Some(method), Some(target), Some(version), None) = (parts.next(), parts.next(), parts.next(), parts.next())
    else {
        return Err(Reject::BadRequest);
    };
    if !matches!(version, "HTTP/1.0" | "HTTP/1.1") || !target.starts_with('/') {
        return Err(Reject::BadRequest);
    }
    if method.is_empty() || !method.bytes().all(|b| b.is_ascii_uppercase()) {
        return Err(Reject::BadRequest);
    }
    let head_only = match method {
        "GET" => false,
        "HEAD" => true,
        _ => return Err(Reject::MethodNotAllowed),
    };
    let mut host = None;
    for h in lines.take_while(|l| !l.is_empty()) {
        let Some((name, value)) = h.split_once(':') else {
            return Err(Reject::BadRequest);
        };
        let value = value.trim();
        if name.eq_ignore_ascii_case("host") {
            host = Some(value.to_string());
        }
        if name.eq_ignore_ascii_case("transfer-encoding")
            || (name.eq_ignore_ascii_case("content-length") && value != "0")
        {
            return Err(Reject::PayloadTooLarge);
        }
    }
    let path = target.split(['?', '#']).next().unwrap_or("/").to_string();
    Ok(Request { path, head_only, host })
}

/// True for a `Host` header naming the loopback interface: `localhost`, a loopback address,
/// with or without a port.
pub fn is_loopback_host(host: &str) -> bool {
    let name = match host.strip_prefix('[') {
        Some(rest) => rest.split(']').next().unwrap_or(""),
        None => match host.rsplit_once(':') {
            Some((name, port)) if port.bytes().all(|b| b.is_ascii_digit()) => name,
            _ => host,
        },
    };
    name.eq_ignore_ascii_case("localhost") || name.parse::<std::net::IpAddr>().is_ok_and(|ip| ip.is_loopback())
}

/// Reads a request head: up to [`MAX_HEAD_BYTES`], until `deadline`.
fn read_head(stream: &mut TcpStream, deadline: Instant) -> Result<Vec<u8>, Option<Reject>> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 2048];
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(Some(Reject::Timeout));
        }
        let _ = stream.set_read_timeout(Some(left));
        let room = (MAX_HEAD_BYTES + 1 - buf.len()).min(chunk.len());
        match stream.read(&mut chunk[..room]) {
            Ok(0) => return Err(None),
            Ok(n) => {
                buf.extend_from_slice(&chunk[..n]);
                if let Some(end) = head_end(&buf) {
                    buf.truncate(end);
                    return Ok(buf);
                }
                if buf.len() > MAX_HEAD_BYTES {
                    return Err(Some(Reject::HeadTooLarge));
                }
            }
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                return Err(Some(Reject::Timeout));
            }
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(_) => return Err(None),
        }
    }
}

/// A whole response: status line, headers, body.
fn response(code: u16, reason: &str, content_type: &str, extra: &str, body: &[u8], head_only: bool) -> Vec<u8> {
    let mut r = format!(
        "HTTP/1.1 {code} {reason}\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\n\
         Cache-Control: no-store\r\nConnection: close\r\nX-Content-Type-Options: nosniff\r\n{extra}\r\n",
        body.len()
    )
    .into_bytes();
    if !head_only {
        r.extend_from_slice(body);
    }
    r
}

fn error_response(code: u16, reason: &str, extra: &str) -> Vec<u8> {
    response(
        code,
        reason,
        "text/plain; charset=utf-8",
        extra,
        format!("{code} {reason}\n").as_bytes(),
        false,
    )
}

/// What the page's Content-Security-Policy allows: its own inline script and style, its own
/// origin for the event stream, nothing from anywhere else.
const PAGE_CSP: &str = "Content-Security-Policy: default-src 'none'; script-src 'unsafe-inline'; \
     style-src 'unsafe-inline'; img-src data:; connect-src 'self'; base-uri 'none'; form-action 'none'; \
     frame-ancestors 'none'\r\nReferrer-Policy: no-referrer\r\n";

// ---------------------------------------------------------------------------------------------
// What the threads share.

/// The web process's own counters (health `navsync/health/web`, `/metrics`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Count {
    ConnectionsAccepted,
    RefusedConnections,
    RefusedStreams,
    Requests,
    BadRequests,
    MethodNotAllowed,
    NotFound,
    TooLarge,
    Timeouts,
    ForeignHosts,
    SlowDropped,
    EventsSent,
    ConnectionsActive,
    StreamsActive,
}

/// Every counter: its name (health and `navsync_web_{name}[_total]`), whether it is a gauge,
/// and its help text.
const COUNTS: [(Count, &str, bool, &str); 14] = [
    (
        Count::ConnectionsAccepted,
        "connections_accepted",
        false,
        "Connections accepted and served.",
    ),
    (
        Count::RefusedConnections,
        "refused_connections",
        false,
        "Connections answered 503: --max-connections already open.",
    ),
    (
        Count::RefusedStreams,
        "refused_streams",
        false,
        "Event streams answered 503: --max-streams already open.",
    ),
    (Count::Requests, "requests", false, "Requests answered (any status)."),
    (
        Count::BadRequests,
        "bad_requests",
        false,
        "Requests answered 400: not HTTP/1.x.",
    ),
    (
        Count::MethodNotAllowed,
        "method_not_allowed",
        false,
        "Requests answered 405: a method other than GET or HEAD (read-only).",
    ),
    (Count::NotFound, "not_found", false, "Requests answered 404."),
    (
        Count::TooLarge,
        "too_large",
        false,
        "Requests answered 431 (a head over 8 KiB) or 413 (a body).",
    ),
    (
        Count::Timeouts,
        "request_timeouts",
        false,
        "Connections answered 408: no complete request head within 5 s.",
    ),
    (
        Count::ForeignHosts,
        "foreign_hosts",
        false,
        "Requests answered 421: a Host other than loopback's while listening on loopback only.",
    ),
    (
        Count::SlowDropped,
        "slow_clients_dropped",
        false,
        "Clients dropped because they did not take a write within --write-timeout.",
    ),
    (
        Count::EventsSent,
        "events_sent",
        false,
        "Server-Sent Events written to the event streams.",
    ),
    (
        Count::ConnectionsActive,
        "connections_active",
        true,
        "Connections open now.",
    ),
    (Count::StreamsActive, "streams_active", true, "Event streams open now."),
];

/// The latest snapshot and everything the connection threads share.
struct Shared {
    /// (generation, the snapshot's JSON, the metrics of the state, in the exposition format).
    latest: Mutex<(u64, Arc<String>, Arc<String>)>,
    changed: Condvar,
    stop: AtomicBool,
    counts: [AtomicU64; COUNTS.len()],
    connections: AtomicUsize,
    streams: AtomicUsize,
    max_connections: usize,
    max_streams: usize,
    write_timeout: Duration,
    /// Listening on loopback only: a request must name a loopback host.
    loopback_only: bool,
}

impl Shared {
    fn add(&self, c: Count) {
        self.counts[c as usize].fetch_add(1, Ordering::Relaxed);
    }

    fn value(&self, c: Count) -> u64 {
        match c {
            Count::ConnectionsActive => self.connections.load(Ordering::Relaxed) as u64,
            Count::StreamsActive => self.streams.load(Ordering::Relaxed) as u64,
            c => self.counts[c as usize].load(Ordering::Relaxed),
        }
    }

    fn latest(&self) -> (u64, Arc<String>, Arc<String>) {
        let l = self.latest.lock().unwrap_or_else(|e| e.into_inner());
        (l.0, l.1.clone(), l.2.clone())
    }

    fn publish(&self, snapshot: String, metrics: String) {
        let mut l = self.latest.lock().unwrap_or_else(|e| e.into_inner());
        *l = (l.0 + 1, Arc::new(snapshot), Arc::new(metrics));
        self.changed.notify_all();
    }

    /// The web process's own metrics, read now.
    fn own_metrics(&self, out: &mut String) {
        for (c, name, gauge, help) in COUNTS {
            let v = self.value(c) as f64;
            if gauge {
                family(out, &format!("navsync_web_{name}"), "gauge", help, [(String::new(), v)]);
            } else {
                family(
                    out,
                    &format!("navsync_web_{name}_total"),
                    "counter",
                    help,
                    [(String::new(), v)],
                );
            }
        }
    }
}

/// Decrements a count when the connection or stream it stands for ends.
struct Slot<'a>(&'a AtomicUsize);

impl Drop for Slot<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::Relaxed);
    }
}

/// Takes one of `max` slots of `count`, or none when all are taken.
fn take_slot(count: &AtomicUsize, max: usize) -> Option<Slot<'_>> {
    count
        .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |n| (n < max).then_some(n + 1))
        .ok()
        .map(|_| Slot(count))
}

/// Writes all of `bytes`; false when the client is gone or too slow (counted).
fn send(stream: &mut TcpStream, bytes: &[u8], sh: &Shared) -> bool {
    match stream.write_all(bytes) {
        Ok(()) => true,
        Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
            sh.add(Count::SlowDropped);
            warn!("dropping a client that does not read");
            false
        }
        Err(_) => false,
    }
}

/// Sends an error answer and reads (and drops) what the client still sends for a while, so
/// the answer is not lost to the reset a close with unread data causes.
fn refuse(stream: &mut TcpStream, bytes: &[u8]) {
    let _ = stream.set_write_timeout(Some(Duration::from_secs(1)));
    let _ = stream.write_all(bytes);
    let _ = stream.shutdown(Shutdown::Write);
    let until = Instant::now() + LINGER;
    let mut chunk = [0u8; 4096];
    let mut read = 0;
    while read < LINGER_BYTES {
        let left = until.saturating_duration_since(Instant::now());
        if left.is_zero() {
            break;
        }
        let _ = stream.set_read_timeout(Some(left));
        match stream.read(&mut chunk) {
            Ok(0) => break,
            Ok(n) => read += n,
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(_) => break,
        }
    }
}

/// Accepts connections until stopped; each in a thread of its own, at most `max_connections`.
fn accept_loop(listener: TcpListener, sh: Arc<Shared>) {
    for stream in listener.incoming() {
        if sh.stop.load(Ordering::Relaxed) {
            return;
        }
        let mut stream = match stream {
            Ok(s) => s,
            Err(e) => {
                // Out of descriptors or memory: wait instead of spinning.
                warn!("accept: {e}");
                std::thread::sleep(Duration::from_millis(100));
                continue;
            }
        };
        let Some(slot) = take_slot(&sh.connections, sh.max_connections) else {
            sh.add(Count::RefusedConnections);
            refuse_busy(&mut stream, "too many connections");
            continue;
        };
        // The slot moves into the thread; a failed spawn drops it again.
        std::mem::forget(slot);
        let sh2 = sh.clone();
        let spawned = std::thread::Builder::new().name("web-client".into()).spawn(move || {
            let _slot = Slot(&sh2.connections);
            sh2.add(Count::ConnectionsAccepted);
            serve(stream, &sh2);
        });
        if let Err(e) = spawned {
            sh.connections.fetch_sub(1, Ordering::Relaxed);
            sh.add(Count::RefusedConnections);
            warn!("no thread for a client: {e}");
        }
    }
}

/// 503 to a client over a cap: without a thread of its own, bounded in time (the accept
/// thread waits at most [`LINGER`] plus a second for it).
fn refuse_busy(stream: &mut TcpStream, why: &str) {
    warn!("refusing a client: {why}");
    refuse(
        stream,
        &error_response(503, "Service Unavailable", "Retry-After: 5\r\n"),
    );
}

/// Serves one connection: one request, one answer (an event stream until the client leaves).
fn serve(mut stream: TcpStream, sh: &Shared) {
    super::gpsd_server::set_send_buffer(&stream, SEND_BUFFER_BYTES);
    let _ = stream.set_nodelay(true);
    let _ = stream.set_write_timeout(Some(sh.write_timeout));
    let req = match read_head(&mut stream, Instant::now() + REQUEST_TIMEOUT)
        .and_then(|h| parse_head(&h).map_err(Some))
        .and_then(|r| {
            let foreign = sh.loopback_only && r.host.as_deref().is_some_and(|h| !is_loopback_host(h));
            if foreign { Err(Some(Reject::ForeignHost)) } else { Ok(r) }
        }) {
        Ok(r) => r,
        Err(None) => return,
        Err(Some(reject)) => {
            sh.add(reject.counter());
            sh.add(Count::Requests);
            let (code, reason) = reject.status();
            let extra = if reject == Reject::MethodNotAllowed {
                "Allow: GET, HEAD\r\n"
            } else {
                ""
            };
            refuse(&mut stream, &error_response(code, reason, extra));
            return;
        }
    };
    sh.add(Count::Requests);
    let (_, snapshot, metrics) = sh.latest();
    let bytes = match req.path.as_str() {
        "/" | "/index.html" => response(
            200,
            "OK",
            "text/html; charset=utf-8",
            PAGE_CSP,
            page(&snapshot).as_bytes(),
            req.head_only,
        ),
        "/metrics" => {
            let mut body = String::with_capacity(metrics.len() + 4096);
            body.push_str(&metrics);
            sh.own_metrics(&mut body);
            response(
                200,
                "OK",
                "text/plain; version=0.0.4; charset=utf-8",
                "",
                body.as_bytes(),
                req.head_only,
            )
        }
        "/state.json" => response(200, "OK", "application/json", "", snapshot.as_bytes(), req.head_only),
        "/events" if req.head_only => response(200, "OK", "text/event-stream", "", b"", true),
        "/events" => {
            let Some(_stream_slot) = take_slot(&sh.streams, sh.max_streams) else {
                sh.add(Count::RefusedStreams);
                refuse_busy(&mut stream, "too many event streams");
                return;
            };
            stream_events(&mut stream, sh);
            return;
        }
        _ => {
            sh.add(Count::NotFound);
            error_response(404, "Not Found", "")
        }
    };
    if send(&mut stream, &bytes, sh) {
        let _ = stream.shutdown(Shutdown::Write);
    }
}

/// The event stream: the latest snapshot at once, then every new one, until the client leaves,
/// is too slow, or the process stops.
fn stream_events(stream: &mut TcpStream, sh: &Shared) {
    let head = "HTTP/1.1 200 OK\r\nContent-Type: text/event-stream\r\nCache-Control: no-store\r\n\
                Connection: close\r\nX-Content-Type-Options: nosniff\r\n\r\nretry: 2000\n\n";
    if !send(stream, head.as_bytes(), sh) {
        return;
    }
    let mut seen = 0u64;
    loop {
        let (generation, snapshot) = {
            let mut l = sh.latest.lock().unwrap_or_else(|e| e.into_inner());
            let deadline = Instant::now() + KEEPALIVE;
            while l.0 == seen && !sh.stop.load(Ordering::Relaxed) {
                let left = deadline.saturating_duration_since(Instant::now());
                if left.is_zero() {
                    break;
                }
                l = sh.changed.wait_timeout(l, left).unwrap_or_else(|e| e.into_inner()).0;
            }
            (l.0, l.1.clone())
        };
        if sh.stop.load(Ordering::Relaxed) {
            return;
        }
        let ok = if generation == seen {
            send(stream, b": keep-alive\n\n", sh)
        } else {
            seen = generation;
            let mut event = String::with_capacity(snapshot.len() + 16);
            event.push_str("data: ");
            event.push_str(&snapshot);
            event.push_str("\n\n");
            let ok = send(stream, event.as_bytes(), sh);
            if ok {
                sh.add(Count::EventsSent);
            }
            ok
        };
        if !ok {
            return;
        }
    }
}

/// The page with `snapshot` inlined (a `<` escaped, so no string in it ends the script).
pub fn page(snapshot: &str) -> String {
    PAGE.replacen(PAGE_STATE_SLOT, &snapshot.replace('<', "\\u003c"), 1)
}

// ---------------------------------------------------------------------------------------------
// The snapshot beside the status report.

/// The track of the fused position, in local ENU around its first point.
#[derive(Debug, Default)]
pub struct Track {
    origin: Option<(f64, f64, f64)>,
    points: VecDeque<[f64; 2]>,
}

impl Track {
    /// Adds the state's position (one a second); a point over 100 km from the origin starts
    /// a new track there.
    pub fn push(&mut self, n: &NavState) {
        if !(n.lat_deg.is_finite() && n.lon_deg.is_finite() && n.height_m.is_finite()) {
            return;
        }
        let (lat, lon, h) = (n.lat_deg.to_radians(), n.lon_deg.to_radians(), n.height_m);
        let (olat, olon, oh) = *self.origin.get_or_insert((lat, lon, h));
        let ned = ned_between(olat, olon, oh, lat, lon, h);
        if ned[0].hypot(ned[1]) > 100e3 {
            self.origin = None;
            self.points.clear();
            return self.push(n);
        }
        if self.points.len() == TRACK_POINTS {
            self.points.pop_front();
        }
        self.points.push_back([ned[1], ned[0]]);
    }

    fn json(&self) -> Value {
        let round = |x: f64| (x * 1000.0).round() / 1000.0;
        json!({
            "origin_deg": self.origin.map(|(a, b, h)| [a.to_degrees(), b.to_degrees(), h]),
            "en_m": self.points.iter().map(|p| [round(p[0]), round(p[1])]).collect::<Vec<_>>(),
        })
    }
}

fn finite(x: f64) -> Value {
    if x.is_finite() { json!(x) } else { Value::Null }
}

/// The id in a service name `navsync/{kind}/{id}/…`.
fn service_id(service: &str) -> &str {
    service.split('/').nth(2).unwrap_or("")
}

/// GGA's fix quality by name.
pub fn quality_name(q: u8) -> &'static str {
    match q {
        0 => "invalid",
        1 => "gps",
        2 => "dgps",
        3 => "pps",
        4 => "rtk-fixed",
        5 => "rtk-float",
        6 => "dead-reckoning",
        7 => "manual",
        8 => "simulation",
        _ => "unknown",
    }
}

fn fix_json(service: &str, f: &GnssFix, now_ns: i64) -> Value {
    json!({
        "id": service_id(service),
        "mode": match f.mode { 1 => "no fix", 2 => "2D", 3 => "3D", _ => "unknown" },
        "mode_code": f.mode,
        "quality": quality_name(f.quality),
        "sats_used": (f.sats_used != u16::MAX).then_some(f.sats_used),
        "hdop": finite(f.hdop),
        "vdop": finite(f.vdop),
        "pdop": finite(f.pdop),
        "h_acc_m": finite(if f.h_acc_m.is_finite() { f.h_acc_m } else { f.std_lat_m.hypot(f.std_lon_m) }),
        "v_acc_m": finite(if f.v_acc_m.is_finite() { f.v_acc_m } else { f.std_alt_m }),
        "utc": (f.utc_ns != i64::MIN).then(|| format_rfc3339_ms(f.utc_ns)),
        "age_s": now_ns.saturating_sub(f.stamp.host_ns) as f64 * 1e-9,
    })
}

/// The one-letter prefix of a GNSS id in satellite labels (RINEX's: G GPS, S SBAS, E Galileo,
/// C BeiDou, J QZSS, R GLONASS; I for IMES) and the system's name.
pub fn gnss_system(gnss_id: u8) -> (&'static str, &'static str) {
    match gnss_id {
        0 => ("G", "GPS"),
        1 => ("S", "SBAS"),
        2 => ("E", "Galileo"),
        3 => ("C", "BeiDou"),
        4 => ("I", "IMES"),
        5 => ("J", "QZSS"),
        6 => ("R", "GLONASS"),
        _ => ("?", "other"),
    }
}

/// A receiver's latest sky for the page: every satellite with its label (`G05`), elevation
/// and azimuth (degrees, `null` when not known), C/N0 (dB-Hz, `null` when 0) and `used`.
pub fn sky_json(service: &str, s: &GnssSky, now_ns: i64) -> Value {
    let sats: Vec<Value> = s
        .satellites()
        .iter()
        .map(|x| {
            let (letter, system) = gnss_system(x.gnss_id);
            json!({
                "label": format!("{letter}{:02}", x.sv_id),
                "system": system,
                "gnss_id": x.gnss_id,
                "sv_id": x.sv_id,
                "el_deg": finite(f64::from(x.elevation_deg)),
                "az_deg": finite(f64::from(x.azimuth_deg)),
                "cno_dbhz": (x.cno_dbhz > 0).then_some(x.cno_dbhz),
                "used": x.used != 0,
            })
        })
        .collect();
    json!({
        "id": service_id(service),
        "in_view": s.num_sats,
        "used": s.used(),
        "dropped": s.dropped,
        "utc": (s.utc_ns != i64::MIN).then(|| format_rfc3339_ms(s.utc_ns)),
        "age_s": now_ns.saturating_sub(s.stamp.host_ns) as f64 * 1e-9,
        "satellites": sats,
    })
}

/// The host's `CLOCK_MONOTONIC` and `CLOCK_REALTIME` at one instant (the realtime reading
/// between two monotonic ones, paired with their midpoint).
fn clocks_now() -> (i64, i64) {
    let a = monotonic_now_ns();
    let real = realtime_now_ns();
    let b = monotonic_now_ns();
    (a + (b - a) / 2, real)
}

/// What the page and the metrics show beside the status report, from the latest samples.
pub fn extras<'a>(latest: impl Iterator<Item = (&'a str, AnySample)>, track: &mut Track) -> Value {
    let (mono, real) = clocks_now();
    let mut fixes = Vec::new();
    let mut skies = Vec::new();
    let mut imu_samples = BTreeMap::new();
    let (mut time, mut nav) = (None, None);
    for (service, sample) in latest {
        match sample {
            AnySample::GnssFix(f) => fixes.push(fix_json(service, &f, mono)),
            AnySample::Sky(s) => skies.push(sky_json(service, &s, mono)),
            AnySample::Imu(s) => {
                imu_samples.insert(service_id(service).to_string(), s.stamp.seq + 1);
            }
            AnySample::Time(t) => time = Some(t),
            AnySample::Nav(n) => nav = Some(n),
            _ => {}
        }
    }
    let clock = time.filter(TimeState::is_valid).map(|t: TimeState| {
        json!({
            // GNSS time (UTC through the mapping) minus the host's system clock, now.
            "offset_s": (t.utc_ns_at(mono) - real) as f64 / 1e9,
            "sigma_s": finite(t.utc_std_ns_at(mono) * 1e-9),
            "utc": format_rfc3339_ms(t.utc_ns_at(mono)),
        })
    });
    if let Some(n) = &nav {
        track.push(n);
    }
    let nav_sigma = nav.map(|n| {
        json!({
            "vel_std_ned_mps": n.vel_std_ned_mps.map(finite),
            "att_std_deg": n.att_std_rad.map(|r| finite(r.to_degrees())),
            "utc": (n.utc_ns != i64::MIN).then(|| format_rfc3339_ms(n.utc_ns)),
            "seq": n.seq,
        })
    });
    json!({
        "clock": clock,
        "nav_sigma": nav_sigma,
        "fixes": fixes,
        "skies": skies,
        "imu_samples": imu_samples,
        "track": track.json(),
        "time_seq": time.map(|t| t.seq),
    })
}

// ---------------------------------------------------------------------------------------------
// Prometheus's text exposition format.

/// A label value escaped for the exposition format (`\`, `"` and line feeds).
pub fn escape_label(v: &str) -> String {
    let mut s = String::with_capacity(v.len());
    for c in v.chars() {
        match c {
            '\\' => s.push_str("\\\\"),
            '"' => s.push_str("\\\""),
            '\n' => s.push_str("\\n"),
            c => s.push(c),
        }
    }
    s
}

/// `{name="value",…}` from pairs (values escaped); empty without pairs.
pub fn labels(pairs: &[(&str, &str)]) -> String {
    if pairs.is_empty() {
        return String::new();
    }
    let inner: Vec<String> = pairs
        .iter()
        .map(|(k, v)| format!("{k}=\"{}\"", escape_label(v)))
        .collect();
    format!("{{{}}}", inner.join(","))
}

/// One metric family: HELP, TYPE and its samples (label set, value); samples that are not
/// finite are left out (an unknown value is no sample), and so is a family without samples.
fn family(out: &mut String, name: &str, kind: &str, help: &str, samples: impl IntoIterator<Item = (String, f64)>) {
    let samples: Vec<(String, f64)> = samples.into_iter().filter(|(_, v)| v.is_finite()).collect();
    if samples.is_empty() {
        return;
    }
    let _ = writeln!(out, "# HELP {name} {help}");
    let _ = writeln!(out, "# TYPE {name} {kind}");
    for (l, v) in samples {
        let _ = writeln!(out, "{name}{l} {v}");
    }
}

fn gauge(out: &mut String, name: &str, help: &str, v: Option<f64>) {
    family(out, name, "gauge", help, v.map(|v| (String::new(), v)));
}

/// A sample per row of `rows` with a number at `field`, labelled `label` = the row's `key`.
fn per_row<'a>(
    rows: &'a [Value],
    label: &'a str,
    key: &'a str,
    field: &'a str,
) -> impl Iterator<Item = (String, f64)> + 'a {
    rows.iter().filter_map(move |r| {
        r[field]
            .as_f64()
            .map(|v| (labels(&[(label, r[key].as_str().unwrap_or(""))]), v))
    })
}

/// A sample per number in each row's object `field` (a process's counters, its rates),
/// labelled `key` = the row's `key` and `entry` = the number's name.
fn per_entry<'a>(
    rows: &'a [Value],
    key: &'a str,
    field: &'a str,
    entry: &'a str,
) -> impl Iterator<Item = (String, f64)> + 'a {
    rows.iter().flat_map(move |r| {
        let k = r[key].as_str().unwrap_or("");
        r[field]
            .as_object()
            .into_iter()
            .flatten()
            .filter_map(move |(name, v)| v.as_f64().map(|v| (labels(&[(key, k), (entry, name)]), v)))
    })
}

/// The state's metrics from the status report and its [`extras`] (the web process's own are
/// added at each scrape). Pure.
pub fn metrics_text(report: &Value, extra: &Value) -> String {
    let mut out = String::with_capacity(8192);
    let num = |v: &Value| v.as_f64();
    let t = &report["time"];
    let n = &report["nav"];
    let status = t["status"].as_str();
    family(
        &mut out,
        "navsync_time_status",
        "gauge",
        "The time mapping's status: 1 for the current one (locked: PPS, holdover, software, network, acquiring, none).",
        ["none", "locked", "holdover", "software", "acquiring", "network"]
            .into_iter()
            .filter(|_| status.is_some())
            .map(|s| (labels(&[("status", s)]), f64::from(u8::from(status == Some(s))))),
    );
    let clock = &extra["clock"];
    gauge(
        &mut out,
        "navsync_time_offset_seconds",
        "GNSS time (UTC through the estimator's mapping) minus the host's system clock (CLOCK_REALTIME), s.",
        num(&clock["offset_s"]),
    );
    gauge(
        &mut out,
        "navsync_time_sigma_seconds",
        "1-sigma of the GNSS time the mapping gives now, s.",
        num(&clock["sigma_s"]),
    );
    gauge(
        &mut out,
        "navsync_time_drift_ratio",
        "The host clock's fractional frequency error d(UTC)/d(host) - 1.",
        num(&t["drift_ppm"]).map(|x| x * 1e-6),
    );
    gauge(
        &mut out,
        "navsync_time_drift_sigma_ratio",
        "1-sigma of the host clock's fractional frequency error.",
        num(&t["drift_std_ppm"]).map(|x| x * 1e-6),
    );
    gauge(
        &mut out,
        "navsync_time_state_age_seconds",
        "Age of the latest time state, s.",
        num(&t["state_age_s"]),
    );
    gauge(
        &mut out,
        "navsync_time_last_pps_age_seconds",
        "Time since the last PPS edge used, s.",
        num(&t["last_pps_age_s"]),
    );
    family(
        &mut out,
        "navsync_time_pps_used_total",
        "counter",
        "PPS edges the estimator used (since it started).",
        num(&t["pps_used"]).map(|v| (String::new(), v)),
    );
    family(
        &mut out,
        "navsync_time_pps_rejected_total",
        "counter",
        "PPS edges the estimator rejected (since it started).",
        num(&t["pps_rejected"]).map(|v| (String::new(), v)),
    );
    let d0 = &t["receiver_latency_d0_s"];
    family(
        &mut out,
        "navsync_receiver_latency_seconds",
        "gauge",
        "The receiver's output latency d0 (first byte of an epoch minus its PPS edge), s, by statistic.",
        ["min", "median", "p99", "max"]
            .into_iter()
            .filter_map(|s| num(&d0[s]).map(|v| (labels(&[("stat", s)]), v))),
    );
    // Δ from the fused state when there is one (the same estimate), else the time state.
    let src = if n.is_object() { n } else { t };
    gauge(
        &mut out,
        "navsync_gnss_delay_seconds",
        "Estimated time-synchronisation error of the GNSS fixes, delta, s.",
        num(&src["gnss_delay_s"]),
    );
    gauge(
        &mut out,
        "navsync_gnss_delay_sigma_seconds",
        "1-sigma of delta, s.",
        num(&src["gnss_delay_std_s"]),
    );
    let imus = src["imu"].as_array().map_or(&[][..], |v| v);
    family(
        &mut out,
        "navsync_imu_offset_seconds",
        "gauge",
        "Each IMU's time offset relative to the reference IMU, s.",
        per_row(imus, "imu", "id", "offset_s"),
    );
    family(
        &mut out,
        "navsync_imu_offset_sigma_seconds",
        "gauge",
        "1-sigma of each IMU's time offset, s.",
        per_row(imus, "imu", "id", "offset_std_s"),
    );
    family(
        &mut out,
        "navsync_imu_in_array",
        "gauge",
        "1 when the IMU is fused into the virtual IMU.",
        imus.iter().map(|e| {
            (
                labels(&[("imu", e["id"].as_str().unwrap_or(""))]),
                f64::from(u8::from(e["in_array"] == true)),
            )
        }),
    );
    family(
        &mut out,
        "navsync_imu_samples_total",
        "counter",
        "Samples each IMU's source produced since it started (its latest sequence number + 1).",
        extra["imu_samples"]
            .as_object()
            .into_iter()
            .flatten()
            .filter_map(|(id, v)| num(v).map(|v| (labels(&[("imu", id)]), v))),
    );
    let nav_status = n["status"].as_str();
    family(
        &mut out,
        "navsync_nav_status",
        "gauge",
        "The navigation filter's status: 1 for the current one.",
        [0u8, 1, 2, 3]
            .into_iter()
            .map(NavStatus::name)
            .filter(|_| nav_status.is_some())
            .map(|s| (labels(&[("status", s)]), f64::from(u8::from(nav_status == Some(s))))),
    );
    gauge(
        &mut out,
        "navsync_nav_latitude_degrees",
        "Fused latitude, degrees north (WGS-84).",
        num(&n["lat_deg"]),
    );
    gauge(
        &mut out,
        "navsync_nav_longitude_degrees",
        "Fused longitude, degrees east (WGS-84).",
        num(&n["lon_deg"]),
    );
    gauge(
        &mut out,
        "navsync_nav_height_meters",
        "Fused height above the WGS-84 ellipsoid, m.",
        num(&n["height_m"]),
    );
    let axes = |v: &Value, names: [&str; 3]| -> Vec<(String, f64)> {
        names
            .iter()
            .enumerate()
            .filter_map(|(i, a)| num(&v[i]).map(|x| (labels(&[("axis", a)]), x)))
            .collect()
    };
    const NED: [&str; 3] = ["north", "east", "down"];
    family(
        &mut out,
        "navsync_nav_position_sigma_meters",
        "gauge",
        "1-sigma of the fused position, m, by NED axis.",
        axes(&n["pos_std_ned_m"], NED),
    );
    family(
        &mut out,
        "navsync_nav_velocity_meters_per_second",
        "gauge",
        "Fused velocity, m/s, by NED axis.",
        axes(&n["vel_ned_mps"], NED),
    );
    let ns = &extra["nav_sigma"];
    family(
        &mut out,
        "navsync_nav_velocity_sigma_meters_per_second",
        "gauge",
        "1-sigma of the fused velocity, m/s, by NED axis.",
        axes(&ns["vel_std_ned_mps"], NED),
    );
    const RPY: [&str; 3] = ["roll", "pitch", "yaw"];
    family(
        &mut out,
        "navsync_nav_attitude_degrees",
        "gauge",
        "Fused attitude, degrees.",
        axes(&n["rpy_deg"], RPY),
    );
    family(
        &mut out,
        "navsync_nav_attitude_sigma_degrees",
        "gauge",
        "1-sigma of the fused attitude, degrees.",
        axes(&ns["att_std_deg"], RPY),
    );
    gauge(
        &mut out,
        "navsync_nav_state_age_seconds",
        "Age of the latest navigation state, s.",
        num(&n["state_age_s"]),
    );
    family(
        &mut out,
        "navsync_nav_fixes_used_total",
        "counter",
        "GNSS fixes the filter fused (since the estimator started).",
        num(&n["fixes_used"]).map(|v| (String::new(), v)),
    );
    family(
        &mut out,
        "navsync_nav_fixes_rejected_total",
        "counter",
        "GNSS fixes the filter rejected (since the estimator started).",
        num(&n["fixes_rejected"]).map(|v| (String::new(), v)),
    );
    let fixes = extra["fixes"].as_array().map_or(&[][..], |v| v);
    family(
        &mut out,
        "navsync_gnss_fix_mode",
        "gauge",
        "The receiver's fix mode: 0 unknown, 1 no fix, 2 2D, 3 3D.",
        per_row(fixes, "gnss", "id", "mode_code"),
    );
    family(
        &mut out,
        "navsync_gnss_satellites_used",
        "gauge",
        "Satellites the receiver used in its solution.",
        per_row(fixes, "gnss", "id", "sats_used"),
    );
    let skies = extra["skies"].as_array().map_or(&[][..], |v| v);
    family(
        &mut out,
        "navsync_gnss_satellites",
        "gauge",
        "Satellites in the receiver's latest sky (navsync/gnss/{id}/sky), used in its solution or not.",
        skies.iter().flat_map(|s| {
            let id = s["id"].as_str().unwrap_or("");
            let (n, used) = (num(&s["in_view"]), num(&s["used"]));
            [
                (labels(&[("receiver", id), ("used", "true")]), used.unwrap_or(f64::NAN)),
                (
                    labels(&[("receiver", id), ("used", "false")]),
                    n.zip(used).map_or(f64::NAN, |(n, u)| n - u),
                ),
            ]
        }),
    );
    family(
        &mut out,
        "navsync_gnss_hdop",
        "gauge",
        "The receiver's horizontal dilution of precision.",
        per_row(fixes, "gnss", "id", "hdop"),
    );
    family(
        &mut out,
        "navsync_gnss_fix_age_seconds",
        "gauge",
        "Age of the receiver's latest fix, s.",
        per_row(fixes, "gnss", "id", "age_s"),
    );
    let services = report["services"].as_array().map_or(&[][..], |v| v);
    family(
        &mut out,
        "navsync_service_rate_hertz",
        "gauge",
        "Samples per second on each service over the last second.",
        per_row(services, "service", "name", "rate_hz"),
    );
    family(
        &mut out,
        "navsync_service_last_sample_age_seconds",
        "gauge",
        "Host clock minus the stamp of each service's newest sample, s.",
        per_row(services, "service", "name", "last_sample_age_s"),
    );
    family(
        &mut out,
        "navsync_service_publishers",
        "gauge",
        "Publishers on each service.",
        per_row(services, "service", "name", "publishers"),
    );
    family(
        &mut out,
        "navsync_service_subscribers",
        "gauge",
        "Subscribers on each service (the web process's own not counted).",
        per_row(services, "service", "name", "subscribers"),
    );
    let procs = report["processes"].as_array().map_or(&[][..], |v| v);
    family(
        &mut out,
        "navsync_process_up",
        "gauge",
        "1 for a process that is alive, 0 for one stalled or gone.",
        procs.iter().map(|p| {
            (
                labels(&[("process", p["name"].as_str().unwrap_or(""))]),
                f64::from(u8::from(p["state"] == "alive")),
            )
        }),
    );
    let health = report["health"].as_array().map_or(&[][..], |v| v);
    family(
        &mut out,
        "navsync_process_uptime_seconds",
        "gauge",
        "Each process's uptime by its latest health report, s.",
        per_row(health, "process", "process", "uptime_s"),
    );
    family(
        &mut out,
        "navsync_health_report_age_seconds",
        "gauge",
        "Age of each process's latest health report, s.",
        per_row(health, "process", "process", "report_age_s"),
    );
    // Not `navsync_health_counter`: promtool rejects a type's name in a metric's name.
    family(
        &mut out,
        "navsync_health_value",
        "gauge",
        "Each process's health counters by name (most count events since it started, some are levels).",
        per_entry(health, "process", "counters", "counter"),
    );
    family(
        &mut out,
        "navsync_health_rate_hertz",
        "gauge",
        "Each process's event rates over its last health interval, per second.",
        per_entry(health, "process", "rates", "rate"),
    );
    out
}

// ---------------------------------------------------------------------------------------------

/// Runs `navsync web`.
pub fn run(args: &WebArgs) -> Result<(), WebError> {
    check_listen(args.listen, args.allow_remote)?;
    // A watcher, not part of the pipeline: every thread of this process (they inherit it)
    // runs on CPU time the drivers and the estimator leave, so watching costs them nothing
    // but the subscriptions (`navsync-bench e2e --compare-web`).
    super::run_as_observer("web");
    if args.max_streams >= args.max_connections {
        return Err(WebError::Streams {
            streams: args.max_streams,
            connections: args.max_connections,
        });
    }
    let mut st = Status::named("web")?;
    let mut health = HealthReporter::new(st.node(), "web")?;
    let ids: Vec<(Count, CounterId)> = COUNTS
        .iter()
        .map(|(c, name, _, _)| health.counter(name).map(|id| (*c, id)))
        .collect::<Result<_, _>>()?;
    let listener = TcpListener::bind(args.listen).map_err(|source| WebError::Io {
        what: format!("listening on {}", args.listen),
        source,
    })?;
    let local = listener.local_addr().map_err(|source| WebError::Io {
        what: "listener address".into(),
        source,
    })?;
    let shared = Arc::new(Shared {
        latest: Mutex::new((0, Arc::new("null".into()), Arc::new(String::new()))),
        changed: Condvar::new(),
        stop: AtomicBool::new(false),
        counts: Default::default(),
        connections: AtomicUsize::new(0),
        streams: AtomicUsize::new(0),
        max_connections: args.max_connections,
        max_streams: args.max_streams,
        write_timeout: args.write_timeout,
        loopback_only: local.ip().is_loopback(),
    });
    let foxglove = match args.foxglove_listen {
        Some(addr) => {
            check_listen(addr, args.allow_remote)?;
            let l = TcpListener::bind(addr).map_err(|source| WebError::Io {
                what: format!("listening on {addr} (--foxglove-listen)"),
                source,
            })?;
            if let Ok(a) = l.local_addr() {
                eprintln!("navsync web: Foxglove WebSocket on ws://{a}/");
            }
            let server =
                super::foxglove::FoxgloveServer::start(l, args.max_connections).map_err(|source| WebError::Io {
                    what: "starting the Foxglove server".into(),
                    source,
                })?;
            let names = [
                "foxglove_clients",
                "foxglove_refused",
                "foxglove_dropped",
                "foxglove_messages",
                "foxglove_ignored",
            ];
            let ids = names.iter().map(|n| health.counter(n)).collect::<Result<Vec<_>, _>>()?;
            Some((server, ids))
        }
        None => None,
    };
    let mut track = Track::default();
    st.discover()?;
    st.poll();
    let publish = |st: &mut Status, track: &mut Track, seq: u64| {
        let report = st.report();
        let extra = extras(st.latest_samples(), track);
        let metrics = metrics_text(&report, &extra);
        let mut snapshot = report;
        if let (Some(s), Value::Object(e)) = (snapshot.as_object_mut(), extra) {
            s.extend(e);
            s.insert("seq".into(), json!(seq));
        }
        shared.publish(snapshot.to_string(), metrics);
    };
    publish(&mut st, &mut track, 0);
    {
        let sh = shared.clone();
        std::thread::Builder::new()
            .name("web-accept".into())
            .spawn(move || accept_loop(listener, sh))
            .map_err(|source| WebError::Io {
                what: "starting the accept thread".into(),
                source,
            })?;
    }
    // The bound address on stderr (with --listen …:0 the port the system chose).
    eprintln!("navsync web: listening on http://{local}/");
    info!(%local, max_connections = args.max_connections, max_streams = args.max_streams, "web");
    navsync_shared::sd_notify::ready(&format!("web on http://{local}/"));
    // Once a second: the status subscriptions keep only each service's newest sample and count
    // the rest by sequence number, so nothing needs draining in between (a reader waking 20
    // times a second beside four 1 kHz IMUs showed in the pipeline's latency tail).
    let mut next = Instant::now() + Duration::from_secs(1);
    let mut seq = 0u64;
    while st.node().sleep(
        next.saturating_duration_since(Instant::now())
            .max(Duration::from_millis(10)),
    ) {
        if Instant::now() >= next {
            next += Duration::from_secs(1);
            if next < Instant::now() {
                next = Instant::now() + Duration::from_secs(1);
            }
            st.discover()?;
            st.poll();
            seq += 1;
            publish(&mut st, &mut track, seq);
        }
        for (c, id) in &ids {
            health.set(*id, shared.value(*c));
        }
        if let Some((server, fids)) = &foxglove {
            let c = &server.counts;
            let values = [&c.clients, &c.refused, &c.dropped, &c.messages, &c.ignored];
            for (id, v) in fids.iter().zip(values) {
                health.set(*id, v.load(Ordering::Relaxed));
            }
        }
        health.maybe_publish(monotonic_now_ns())?;
        navsync_shared::sd_notify::watchdog();
    }
    navsync_shared::sd_notify::stopping();
    shared.stop.store(true, Ordering::Relaxed);
    shared.changed.notify_all();
    health.publish_final()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_loopback_without_allow_remote() {
        assert!(check_listen("127.0.0.1:8080".parse().unwrap(), false).is_ok());
        assert!(check_listen("[::1]:8080".parse().unwrap(), false).is_ok());
        let e = check_listen("0.0.0.0:8080".parse().unwrap(), false).unwrap_err();
        assert!(e.to_string().contains("--allow-remote"), "{e}");
        assert!(check_listen("0.0.0.0:8080".parse().unwrap(), true).is_ok());
    }

    #[test]
    fn request_heads_are_read_only_gets() {
        let ok = parse_head(b"GET /metrics?x=1 HTTP/1.1\r\nHost: a\r\n\r\n").unwrap();
        assert_eq!(ok.path, "/metrics");
        assert!(!ok.head_only);
        assert!(parse_head(b"HEAD / HTTP/1.0\n\n").unwrap().head_only);
        assert_eq!(parse_head(b"POST / HTTP/1.1\r\n\r\n"), Err(Reject::MethodNotAllowed));
        assert_eq!(parse_head(b"DELETE / HTTP/1.1\r\n\r\n"), Err(Reject::MethodNotAllowed));
        assert_eq!(
            parse_head(b"GET / HTTP/1.1\r\nContent-Length: 5\r\n\r\n"),
            Err(Reject::PayloadTooLarge)
        );
        assert_eq!(
            parse_head(b"GET / HTTP/1.1\r\ntransfer-encoding: chunked\r\n\r\n"),
            Err(Reject::PayloadTooLarge)
        );
        assert!(parse_head(b"GET / HTTP/1.1\r\nContent-Length: 0\r\n\r\n").is_ok());
        for bad in [
            &b"GET /\r\n\r\n"[..],
            b"GET / HTTP/2\r\n\r\n",
            b"GET x HTTP/1.1\r\n\r\n",
            b"get / HTTP/1.1\r\n\r\n",
            b"GET / HTTP/1.1\r\nno colon\r\n\r\n",
            b"\xff\xfe",
        ] {
            assert_eq!(parse_head(bad), Err(Reject::BadRequest), "{bad:?}");
        }
        assert_eq!(head_end(b"GET / HTTP/1.1\r\n\r\nrest"), Some(18));
        assert_eq!(head_end(b"GET / HTTP/1.1\n\n"), Some(16));
        assert_eq!(head_end(b"GET / HTTP/1.1\r\n"), None);
    }

    #[test]
    fn only_loopback_hosts_on_loopback() {
        for h in [
            "localhost",
            "localhost:8080",
            "127.0.0.1:8080",
            "127.1.2.3",
            "[::1]:80",
            "[::1]",
            "LOCALHOST",
        ] {
            assert!(is_loopback_host(h), "{h}");
        }
        for h in [
            "evil.example",
            "evil.example:8080",
            "10.0.0.1:8080",
            "[fe80::1]:80",
            "localhost.evil.example",
            "",
        ] {
            assert!(!is_loopback_host(h), "{h}");
        }
        let r = parse_head(b"GET / HTTP/1.1\r\nHost: evil.example:8080\r\n\r\n").unwrap();
        assert_eq!(r.host.as_deref(), Some("evil.example:8080"));
    }

    #[test]
    fn slots_are_capped_and_given_back() {
        let n = AtomicUsize::new(0);
        let a = take_slot(&n, 2).unwrap();
        let b = take_slot(&n, 2).unwrap();
        assert!(take_slot(&n, 2).is_none());
        drop(a);
        assert!(take_slot(&n, 2).is_some());
        drop(b);
        assert_eq!(n.load(Ordering::Relaxed), 0);
    }

    #[test]
    fn the_page_inlines_the_state_without_ending_its_script() {
        let p = page(r#"{"name":"</script><b>"}"#);
        assert!(!p.contains(PAGE_STATE_SLOT));
        assert!(p.contains(r#"{"name":"\u003c/script>\u003cb>"}"#));
        assert_eq!(p.matches("</script>").count(), PAGE.matches("</script>").count());
        // Self-contained: nothing fetched from elsewhere.
        let page = PAGE.replace("\"http://www.w3.org/2000/svg\"", "");
        for needle in ["http://", "https://", "src=", "href=", "@import", "url("] {
            assert!(!page.contains(needle), "the page refers to `{needle}`");
        }
    }

    /// Every line is a comment (HELP/TYPE) or `name{labels} value`; names follow the rules;
    /// each family's samples follow its TYPE; counters end in `_total`.
    fn check_exposition(text: &str) {
        let mut kinds: BTreeMap<String, String> = BTreeMap::new();
        let mut current = String::new();
        for line in text.lines() {
            if let Some(rest) = line.strip_prefix("# HELP ") {
                let name = rest.split(' ').next().unwrap();
                assert!(!kinds.contains_key(name), "{name} twice");
                continue;
            }
            if let Some(rest) = line.strip_prefix("# TYPE ") {
                let (name, kind) = rest.split_once(' ').unwrap();
                assert!(["gauge", "counter"].contains(&kind), "{line}");
                assert_eq!(kind == "counter", name.ends_with("_total"), "{line}");
                kinds.insert(name.to_string(), kind.to_string());
                current = name.to_string();
                continue;
            }
            let name_end = line.find(['{', ' ']).unwrap();
            let name = &line[..name_end];
            assert_eq!(name, current, "a sample outside its family: {line}");
            assert!(
                name.starts_with("navsync_")
                    && name
                        .bytes()
                        .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_'),
                "{line}"
            );
            let value = line.rsplit(' ').next().unwrap();
            assert!(value.parse::<f64>().is_ok_and(f64::is_finite), "{line}");
        }
    }

    #[test]
    fn metrics_follow_the_exposition_format() {
        let report = json!({
            "time": {"status": "locked", "drift_ppm": 1.5, "drift_std_ppm": 0.01, "state_age_s": 0.2,
                     "pps_used": 10, "pps_rejected": 0, "last_pps_age_s": 0.3,
                     "receiver_latency_d0_s": {"min": 0.1, "median": 0.12, "p99": null, "max": 0.2},
                     "gnss_delay_s": 0.01, "gnss_delay_std_s": 0.001, "imu": []},
            "nav": {"status": "aligned", "lat_deg": 48.1, "lon_deg": 11.5, "height_m": 500.0,
                    "vel_ned_mps": [1.0, 2.0, null], "rpy_deg": [0.1, 0.2, 90.0],
                    "pos_std_ned_m": [0.1, 0.1, 0.2], "fixes_used": 7, "fixes_rejected": 1,
                    "gnss_delay_s": 0.01, "gnss_delay_std_s": 0.001, "state_age_s": 0.01,
                    "imu": [{"id": "0", "offset_s": 0.0, "offset_std_s": 0.0, "in_array": true},
                            {"id": "1", "offset_s": 0.002, "offset_std_s": 1e-5, "in_array": false}]},
            "services": [{"name": "navsync/imu/0/sample", "rate_hz": 100.0, "last_sample_age_s": 0.01,
                          "publishers": 1, "subscribers": 1}],
            "processes": [{"name": "est\"imator\\x\ny", "state": "alive"}],
            "health": [{"process": "gnss-0", "uptime_s": 5.0, "report_age_s": 0.5,
                        "counters": {"fixes": 5, "bad": 0}, "rates": {"fix_out": 1.0}}],
        });
        let extra = json!({
            "clock": {"offset_s": -1.5e-6, "sigma_s": 2e-7},
            "imu_samples": {"0": 1000, "1": 998},
            "fixes": [{"id": "0", "mode": "3D", "sats_used": 9, "hdop": 0.9, "age_s": 0.3}],
            "skies": [{"id": "0", "in_view": 12, "used": 9}],
            "nav_sigma": {"vel_std_ned_mps": [0.01, 0.01, 0.02], "att_std_deg": [0.1, 0.1, 0.5]},
        });
        let text = metrics_text(&report, &extra);
        check_exposition(&text);
        for needle in [
            "navsync_time_offset_seconds -0.0000015\n",
            "navsync_time_status{status=\"locked\"} 1\n",
            "navsync_time_status{status=\"holdover\"} 0\n",
            "navsync_imu_samples_total{imu=\"1\"} 998\n",
            "navsync_health_value{process=\"gnss-0\",counter=\"fixes\"} 5\n",
            "navsync_nav_status{status=\"aligned\"} 1\n",
            "navsync_gnss_delay_seconds 0.01\n",
            "navsync_imu_offset_seconds{imu=\"1\"} 0.002\n",
            "navsync_process_up{process=\"est\\\"imator\\\\x\\ny\"} 1\n",
            "navsync_receiver_latency_seconds{stat=\"median\"} 0.12\n",
            "navsync_gnss_satellites{receiver=\"0\",used=\"true\"} 9\n",
            "navsync_gnss_satellites{receiver=\"0\",used=\"false\"} 3\n",
        ] {
            assert!(text.contains(needle), "{needle} missing:\n{text}");
        }
        // An unknown value is no sample: velocity down and d0's p99.
        assert!(
            !text.contains("axis=\"down\"} NaN") && !text.contains("stat=\"p99\""),
            "{text}"
        );
        // Nothing known, nothing but well-formed text.
        check_exposition(&metrics_text(&json!({}), &json!({})));
        let sh = Shared {
            latest: Mutex::new((0, Arc::new(String::new()), Arc::new(String::new()))),
            changed: Condvar::new(),
            stop: AtomicBool::new(false),
            counts: Default::default(),
            connections: AtomicUsize::new(3),
            streams: AtomicUsize::new(1),
            max_connections: 4,
            max_streams: 2,
            write_timeout: Duration::from_secs(1),
            loopback_only: true,
        };
        sh.add(Count::TooLarge);
        let mut own = String::new();
        sh.own_metrics(&mut own);
        check_exposition(&own);
        assert!(own.contains("navsync_web_too_large_total 1\n"), "{own}");
        assert!(own.contains("navsync_web_connections_active 3\n"), "{own}");
    }

    #[test]
    fn the_track_is_local_enu_and_bounded() {
        let mut t = Track::default();
        let mut n = <NavState as navsync_shared::reflect::Reflect>::zeroed();
        for i in 0..(TRACK_POINTS + 5) {
            n.lat_deg = 48.0 + i as f64 * 1e-5;
            n.lon_deg = 11.0;
            n.height_m = 500.0;
            t.push(&n);
        }
        assert_eq!(t.points.len(), TRACK_POINTS);
        let last = t.points.back().unwrap();
        // 1e-5° of latitude ≈ 1.11 m north a step.
        assert!((last[1] - (TRACK_POINTS + 4) as f64 * 1.112).abs() < 1.0, "{last:?}");
        assert!(last[0].abs() < 1e-6);
        n.lat_deg = f64::NAN;
        t.push(&n);
        assert_eq!(t.points.len(), TRACK_POINTS);
    }

    #[test]
    fn a_sky_for_the_page() {
        use navsync_shared::samples::{SkySatellite, Stamp, StampSource};
        let mut s = GnssSky::empty(Stamp::host(1_000_000_000, 3, StampSource::Receipt));
        s.push(SkySatellite {
            elevation_deg: 45.0,
            azimuth_deg: 270.0,
            gnss_id: 0,
            sv_id: 5,
            cno_dbhz: 42,
            used: 1,
        });
        s.push(SkySatellite {
            gnss_id: 6,
            sv_id: 12,
            ..SkySatellite::EMPTY
        });
        let v = sky_json("navsync/gnss/rx1/sky", &s, 1_500_000_000);
        assert_eq!(v["id"], "rx1");
        assert_eq!((v["in_view"].as_u64(), v["used"].as_u64()), (Some(2), Some(1)));
        assert!((v["age_s"].as_f64().unwrap() - 0.5).abs() < 1e-9);
        let sats = v["satellites"].as_array().unwrap();
        assert_eq!(sats[0]["label"], "G05");
        assert_eq!(
            (sats[0]["el_deg"].as_f64(), sats[0]["az_deg"].as_f64()),
            (Some(45.0), Some(270.0))
        );
        assert_eq!(
            (sats[0]["cno_dbhz"].as_u64(), sats[0]["used"].as_bool()),
            (Some(42), Some(true))
        );
        // Unknown elevation, azimuth and C/N0 are null (the page leaves the satellite off the plot).
        assert_eq!(sats[1]["label"], "R12");
        assert!(sats[1]["el_deg"].is_null() && sats[1]["az_deg"].is_null() && sats[1]["cno_dbhz"].is_null());
        assert_eq!(sats[1]["used"], false);
        // The page draws it.
        assert!(PAGE.contains("function renderSky(") && PAGE.contains("id=\"skies\""));
    }

    #[test]
    fn fix_quality_and_status_names() {
        assert_eq!(quality_name(4), "rtk-fixed");
        assert_eq!(quality_name(200), "unknown");
        assert_eq!(navsync_shared::samples::TimeStatus::from_u8(1).name(), "locked");
    }
}
