//! Foxglove's live protocol in `navsync web --foxglove-listen ADDR`: the Foxglove WebSocket
//! protocol v1 (subprotocol `foxglove.websocket.v1`, github.com/foxglove/ws-protocol,
//! `docs/spec.md`), so Foxglove and Lichtblick attach to a running vehicle with the same
//! schemas and CDR they read in navsync's recordings ([`navsync_recording::channels`]).
//!
//! - On connect the server sends `serverInfo`, then `advertise` with one channel per navsync
//!   service (topic `/navsync/…`, encoding `cdr`, schema encoding `ros2msg`, schema name
//!   `navsync_msgs/msg/…`, the full `.msg` definition); services that appear later are
//!   advertised as they appear (discovery once a second).
//! - A client `subscribe`s to channel ids with its own subscription ids (`unsubscribe` ends
//!   them); the server subscribes to a service only while a client does (a channel nobody
//!   watches costs its publisher nothing), and every sample from then on goes to the
//!   client as a binary `MessageData` frame:
//!   opcode 0x01, subscription id (u32 LE), receive time (u64 LE, ns since 1970), the CDR bytes.
//! - Read-only: client `advertise`/`publish` and other operations are ignored (counted as
//!   `foxglove_ignored`). Bounded: at most `max_clients` at once (one more is closed after the
//!   handshake with a close frame, counted), a client whose unsent data exceed
//!   [`MAX_PENDING_BYTES`] (a slow reader; its socket's send buffer is kept at 64 KiB) is dropped
//!   and counted.

use std::collections::HashMap;
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use navsync_recording::channels::{Encoding, topic_of};
use navsync_recording::ports::AnySubscriber;
use navsync_shared::ipc::{self, IpcNode};
use navsync_shared::services::ServiceKind;
use serde_json::{Value, json};
use tracing::{info, warn};
use tungstenite::handshake::server::{ErrorResponse, Request, Response};
use tungstenite::protocol::WebSocketConfig;
use tungstenite::{Message, WebSocket};

/// The WebSocket subprotocol of the Foxglove protocol, version 1.
pub const SUBPROTOCOL: &str = "foxglove.websocket.v1";
/// Unsent bytes after which a client is a slow reader and is dropped (about a second of every
/// service of four IMUs at 1 kHz).
pub const MAX_PENDING_BYTES: usize = 1 << 20;
/// The kernel's send buffer of a client's socket, bytes: what a slow reader holds beyond
/// [`MAX_PENDING_BYTES`] (the default grows to megabytes).
const SOCKET_SEND_BUFFER: libc::c_int = 64 << 10;
/// Opcode of a server `MessageData` binary frame.
const OP_MESSAGE_DATA: u8 = 0x01;

/// Counters of the Foxglove server, shown in `navsync/health/web`.
#[derive(Debug, Default)]
pub struct FoxgloveCounts {
    /// Clients accepted.
    pub clients: AtomicU64,
    /// Clients refused (over the cap, or a failed handshake).
    pub refused: AtomicU64,
    /// Clients dropped as slow readers or on a write error.
    pub dropped: AtomicU64,
    /// Messages sent.
    pub messages: AtomicU64,
    /// Client operations ignored (the server is read-only) or not understood.
    pub ignored: AtomicU64,
}

/// One connected client.
struct Client {
    ws: WebSocket<TcpStream>,
    /// subscription id → channel id.
    subs: HashMap<u32, u32>,
    peer: SocketAddr,
    /// False once a write failed: dropped after this round.
    alive: bool,
}

/// A channel offered to the clients: a navsync service.
struct Channel {
    service: String,
    kind: ServiceKind,
    /// Open while a client subscribes to the channel.
    sub: Option<AnySubscriber>,
}

/// `MessageData`: opcode, subscription id, receive time, payload.
pub fn message_data(subscription: u32, receive_ns: u64, payload: &[u8], out: &mut Vec<u8>) {
    out.clear();
    out.push(OP_MESSAGE_DATA);
    out.extend_from_slice(&subscription.to_le_bytes());
    out.extend_from_slice(&receive_ns.to_le_bytes());
    out.extend_from_slice(payload);
}

/// The `advertise` entry of a channel (pure).
pub fn channel_json(id: u32, service: &str, kind: ServiceKind) -> Value {
    let enc = Encoding::Cdr;
    json!({
        "id": id,
        "topic": topic_of(service),
        "encoding": enc.message_encoding(),
        "schemaName": enc.schema_name(kind),
        "schema": String::from_utf8_lossy(&enc.schema_data(kind)),
        "schemaEncoding": enc.schema_encoding(),
    })
}

/// What a client's text message asks.
#[derive(Debug, Default, PartialEq, Eq)]
pub struct ClientOp {
    /// New subscriptions: (subscription id, channel id).
    pub subscribe: Vec<(u32, u32)>,
    /// Subscription ids that end.
    pub unsubscribe: Vec<u32>,
}

/// Parses a client's text message (pure); `None` for an operation the server does not serve.
pub fn parse_client_op(text: &str) -> Option<ClientOp> {
    let v: Value = serde_json::from_str(text).ok()?;
    let u32_of = |v: &Value| v.as_u64().and_then(|x| u32::try_from(x).ok());
    match v.get("op")?.as_str()? {
        "subscribe" => Some(ClientOp {
            subscribe: v
                .get("subscriptions")?
                .as_array()?
                .iter()
                .filter_map(|s| Some((u32_of(s.get("id")?)?, u32_of(s.get("channelId")?)?)))
                .collect(),
            ..Default::default()
        }),
        "unsubscribe" => Some(ClientOp {
            unsubscribe: v
                .get("subscriptionIds")?
                .as_array()?
                .iter()
                .filter_map(u32_of)
                .collect(),
            ..Default::default()
        }),
        _ => None,
    }
}

/// Accepts clients on `listener`: the WebSocket handshake with the Foxglove subprotocol (a
/// client that does not offer it is refused), then hands them to the sender.
fn accept_loop(
    listener: TcpListener,
    pending: Arc<Mutex<Vec<Client>>>,
    counts: Arc<FoxgloveCounts>,
    stop: Arc<AtomicBool>,
) {
    for stream in listener.incoming() {
        if stop.load(Ordering::Relaxed) {
            return;
        }
        let Ok(stream) = stream else { continue };
        let peer = stream
            .peer_addr()
            .unwrap_or_else(|_| SocketAddr::from(([0, 0, 0, 0], 0)));
        // The handshake must not hang the accept loop.
        let _ = stream.set_read_timeout(Some(Duration::from_secs(5)));
        {
            use std::os::fd::AsRawFd;
            // SAFETY: setting an int socket option on a socket this thread owns.
            unsafe {
                libc::setsockopt(
                    stream.as_raw_fd(),
                    libc::SOL_SOCKET,
                    libc::SO_SNDBUF,
                    (&SOCKET_SEND_BUFFER as *const libc::c_int).cast(),
                    std::mem::size_of::<libc::c_int>() as libc::socklen_t,
                );
            }
        }
        let _ = stream.set_write_timeout(Some(Duration::from_secs(5)));
        // The signature is tungstenite's handshake callback's.
        #[allow(clippy::result_large_err)]
        let choose = |req: &Request, mut resp: Response| -> Result<Response, ErrorResponse> {
            let offered = req
                .headers()
                .get_all("Sec-WebSocket-Protocol")
                .iter()
                .filter_map(|h| h.to_str().ok())
                .flat_map(|h| h.split(','))
                .any(|p| p.trim() == SUBPROTOCOL);
            if !offered {
                let mut e = ErrorResponse::new(Some(format!("subprotocol {SUBPROTOCOL} required")));
                *e.status_mut() = tungstenite::http::StatusCode::BAD_REQUEST;
                return Err(e);
            }
            if let Ok(v) = SUBPROTOCOL.parse() {
                resp.headers_mut().insert("Sec-WebSocket-Protocol", v);
            }
            Ok(resp)
        };
        let config = WebSocketConfig {
            max_write_buffer_size: MAX_PENDING_BYTES,
            max_message_size: Some(64 << 10),
            max_frame_size: Some(64 << 10),
            ..Default::default()
        };
        match tungstenite::accept_hdr_with_config(stream, choose, Some(config)) {
            Ok(ws) => {
                if ws.get_ref().set_nonblocking(true).is_err() {
                    counts.refused.fetch_add(1, Ordering::Relaxed);
                    continue;
                }
                if let Ok(mut p) = pending.lock() {
                    p.push(Client {
                        ws,
                        subs: HashMap::new(),
                        peer,
                        alive: true,
                    });
                }
            }
            Err(e) => {
                counts.refused.fetch_add(1, Ordering::Relaxed);
                info!(%peer, "foxglove handshake refused: {e}");
            }
        }
    }
}

/// Queues `msg`; false (and the client marked to go) when it cannot take it: a slow reader
/// whose unsent data exceed [`MAX_PENDING_BYTES`], a closed connection, an error.
fn send(c: &mut Client, msg: Message) -> bool {
    if !c.alive {
        return false;
    }
    c.alive = match c.ws.write(msg) {
        Ok(()) => true,
        Err(tungstenite::Error::Io(e)) if e.kind() == std::io::ErrorKind::WouldBlock => true,
        Err(_) => false,
    };
    c.alive
}

/// The Foxglove server: its own node and subscribers, a thread that accepts and one that sends.
pub struct FoxgloveServer {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
    /// Its counters.
    pub counts: Arc<FoxgloveCounts>,
}

impl FoxgloveServer {
    /// Listens on `listener` (already bound and checked by the caller) and serves up to
    /// `max_clients` clients.
    pub fn start(listener: TcpListener, max_clients: usize) -> std::io::Result<Self> {
        let stop = Arc::new(AtomicBool::new(false));
        let counts = Arc::new(FoxgloveCounts::default());
        let pending = Arc::new(Mutex::new(Vec::new()));
        {
            let (p, c, s) = (pending.clone(), counts.clone(), stop.clone());
            std::thread::Builder::new()
                .name("foxglove-accept".into())
                .spawn(move || accept_loop(listener, p, c, s))?;
        }
        let (c, s) = (counts.clone(), stop.clone());
        let thread = std::thread::Builder::new().name("foxglove".into()).spawn(move || {
            if let Err(e) = serve(&pending, &c, &s, max_clients) {
                warn!("foxglove server stopped: {e}");
            }
        })?;
        Ok(Self {
            stop,
            thread: Some(thread),
            counts,
        })
    }
}

impl Drop for FoxgloveServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn serve(
    pending: &Mutex<Vec<Client>>,
    counts: &FoxgloveCounts,
    stop: &AtomicBool,
    max_clients: usize,
) -> Result<(), ipc::IpcError> {
    let node = IpcNode::new("web-foxglove")?;
    // Channel id = index + 1 in `channels`: each service with its kind and, while a client
    // subscribes to it, a subscriber (none otherwise: a channel nobody watches costs its
    // publisher nothing).
    let mut channels: Vec<Channel> = Vec::new();
    let mut clients: Vec<Client> = Vec::new();
    let mut next_discovery = Instant::now();
    let mut payload = Vec::with_capacity(4096);
    let mut frame = Vec::with_capacity(4096);
    let session = format!("{}", navsync_shared::time::realtime_now_ns());
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(5));
        let mut new_channels = Vec::new();
        if Instant::now() >= next_discovery {
            next_discovery = Instant::now() + Duration::from_secs(1);
            for name in ipc::list_services()? {
                let Some(kind) = ServiceKind::of(&name) else { continue };
                if channels.iter().any(|c| c.service == name) {
                    continue;
                }
                channels.push(Channel {
                    service: name.clone(),
                    kind,
                    sub: None,
                });
                new_channels.push(channel_json(channels.len() as u32, &name, kind));
            }
        }
        // New clients: serverInfo and every channel.
        let arrived: Vec<Client> = pending.lock().map(|mut p| p.drain(..).collect()).unwrap_or_default();
        for mut c in arrived {
            if clients.len() >= max_clients {
                counts.refused.fetch_add(1, Ordering::Relaxed);
                let _ = c.ws.close(None);
                let _ = c.ws.flush();
                continue;
            }
            counts.clients.fetch_add(1, Ordering::Relaxed);
            let info = json!({"op": "serverInfo", "name": "navsync", "capabilities": [],
                "supportedEncodings": [], "metadata": {}, "sessionId": session});
            let all: Vec<Value> = channels
                .iter()
                .enumerate()
                .map(|(i, c)| channel_json(i as u32 + 1, &c.service, c.kind))
                .collect();
            let ok = send(&mut c, Message::text(info.to_string()))
                && send(
                    &mut c,
                    Message::text(json!({"op": "advertise", "channels": all}).to_string()),
                );
            if ok {
                info!(peer = %c.peer, "foxglove client");
                clients.push(c);
            } else {
                counts.dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
        if !new_channels.is_empty() {
            let msg = json!({"op": "advertise", "channels": new_channels}).to_string();
            clients.retain_mut(|c| send(c, Message::text(msg.clone())));
        }
        // Client operations.
        for c in &mut clients {
            loop {
                match c.ws.read() {
                    Ok(Message::Text(t)) => match parse_client_op(t.as_str()) {
                        Some(op) => {
                            c.subs.extend(op.subscribe);
                            for id in op.unsubscribe {
                                c.subs.remove(&id);
                            }
                        }
                        None => {
                            counts.ignored.fetch_add(1, Ordering::Relaxed);
                        }
                    },
                    Ok(Message::Binary(_)) => {
                        counts.ignored.fetch_add(1, Ordering::Relaxed);
                    }
                    Ok(_) => {}
                    Err(tungstenite::Error::Io(e)) if e.kind() == std::io::ErrorKind::WouldBlock => break,
                    Err(_) => {
                        c.alive = false;
                        break;
                    }
                }
            }
        }
        // Samples to the clients subscribed to their channel.
        let now_ns = navsync_shared::time::realtime_now_ns().max(0) as u64;
        for (i, channel) in channels.iter_mut().enumerate() {
            let ch = i as u32 + 1;
            let wanted = clients.iter().any(|c| c.subs.values().any(|&x| x == ch));
            if !wanted {
                // Nobody watches it (any more): no subscriber.
                channel.sub = None;
                continue;
            }
            if channel.sub.is_none() {
                // The first subscription: samples from now on.
                match AnySubscriber::open(&node, &channel.service) {
                    Ok(sub) => channel.sub = Some(sub),
                    Err(e) => {
                        warn!("foxglove: cannot subscribe to {}: {e}", channel.service);
                        continue;
                    }
                }
            }
            let Some(s) = &channel.sub else { continue };
            let _ = s.drain(|sample| {
                Encoding::Cdr.encode(&sample, &mut payload);
                for c in &mut clients {
                    let ids: Vec<u32> = c.subs.iter().filter(|&(_, &x)| x == ch).map(|(&id, _)| id).collect();
                    for id in ids {
                        message_data(id, now_ns, &payload, &mut frame);
                        if send(c, Message::binary(frame.clone())) {
                            counts.messages.fetch_add(1, Ordering::Relaxed);
                        }
                    }
                }
            });
        }
        // Flush; a client that cannot take its data (or is gone) is dropped.
        let before = clients.len();
        clients.retain_mut(|c| {
            c.alive
                && match c.ws.flush() {
                    Ok(()) => true,
                    Err(tungstenite::Error::Io(e)) if e.kind() == std::io::ErrorKind::WouldBlock => true,
                    Err(_) => false,
                }
        });
        counts
            .dropped
            .fetch_add((before - clients.len()) as u64, Ordering::Relaxed);
    }
    for c in &mut clients {
        let _ = c.ws.close(None);
        let _ = c.ws.flush();
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn message_data_frames_and_client_operations() {
        let mut out = Vec::new();
        message_data(7, 0x0102_0304_0506_0708, &[0xAA, 0xBB], &mut out);
        assert_eq!(out, [1, 7, 0, 0, 0, 8, 7, 6, 5, 4, 3, 2, 1, 0xAA, 0xBB]);
        let op =
            parse_client_op(r#"{"op":"subscribe","subscriptions":[{"id":0,"channelId":3},{"id":1,"channelId":4}]}"#)
                .unwrap();
        assert_eq!(op.subscribe, vec![(0, 3), (1, 4)]);
        let op = parse_client_op(r#"{"op":"unsubscribe","subscriptionIds":[1]}"#).unwrap();
        assert_eq!((op.subscribe, op.unsubscribe), (vec![], vec![1]));
        assert!(parse_client_op(r#"{"op":"advertise","channels":[]}"#).is_none());
        assert!(parse_client_op("not json").is_none());
    }

    #[test]
    fn channels_carry_the_recordings_schema() {
        let c = channel_json(2, "navsync/nav/state", ServiceKind::NavState);
        assert_eq!(c["topic"], "/navsync/nav/state");
        assert_eq!(c["encoding"], "cdr");
        assert_eq!(c["schemaEncoding"], "ros2msg");
        assert_eq!(c["schemaName"], "navsync_msgs/msg/NavState");
        assert!(c["schema"].as_str().unwrap().contains("float64"));
    }
}
