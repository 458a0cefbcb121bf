//! The watchers of `navsync-bench e2e --compare-web`: what a watched vehicle runs besides the
//! pipeline. `navsync web` with its Foxglove server, an open page (the `/events` stream read to
//! the end), a Prometheus scrape of `/metrics` once a second, and a Foxglove client subscribed
//! to every channel (the WebSocket protocol, as Foxglove does it: tungstenite's client).

use std::io::{Read, Write};
use std::net::TcpStream;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use tungstenite::Message;
use tungstenite::client::IntoClientRequest;

/// The clients' threads and what they received; stopped on drop.
pub struct WebLoad {
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
    /// Bytes the page's event stream and the scrapes received.
    pub http_bytes: Arc<AtomicU64>,
    /// Foxglove messages received.
    pub foxglove_messages: Arc<AtomicU64>,
}

fn get(addr: &str, path: &str, stop: &AtomicBool, bytes: &AtomicU64) {
    let Ok(mut s) = TcpStream::connect(addr) else { return };
    let _ = s.set_read_timeout(Some(Duration::from_millis(500)));
    let _ = write!(s, "GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n");
    let mut buf = [0u8; 16384];
    while !stop.load(Ordering::Relaxed) {
        match s.read(&mut buf) {
            Ok(0) => return,
            Ok(n) => {
                bytes.fetch_add(n as u64, Ordering::Relaxed);
            }
            Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {}
            Err(_) => return,
        }
    }
}

/// What the Foxglove client subscribes to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Watch {
    /// The page and the scrapes only: no Foxglove client.
    Page,
    /// `/navsync/nav/state` only (watching the vehicle move).
    NavState,
    /// Every channel advertised (the IMUs' samples at 1 kHz each among them).
    AllChannels,
}

fn foxglove(addr: &str, stop: &AtomicBool, messages: &AtomicU64, watch: Watch) -> Result<(), String> {
    let stream = TcpStream::connect(addr).map_err(|e| e.to_string())?;
    let mut req = format!("ws://{addr}/")
        .into_client_request()
        .map_err(|e| e.to_string())?;
    let proto = "foxglove.websocket.v1".parse().map_err(|_| "header".to_string())?;
    req.headers_mut().insert("Sec-WebSocket-Protocol", proto);
    let (mut ws, _) = tungstenite::client(req, stream).map_err(|e| e.to_string())?;
    let _ = ws.get_ref().set_read_timeout(Some(Duration::from_millis(500)));
    let mut next_sub = 0u32;
    while !stop.load(Ordering::Relaxed) {
        match ws.read() {
            Ok(Message::Text(t)) => {
                // Subscribe to every channel advertised.
                let v: serde_json::Value = serde_json::from_str(t.as_str()).unwrap_or_default();
                if v["op"] == "advertise" {
                    let subs: Vec<serde_json::Value> = v["channels"]
                        .as_array()
                        .into_iter()
                        .flatten()
                        .filter(|c| watch == Watch::AllChannels || c["topic"].as_str() == Some("/navsync/nav/state"))
                        .filter_map(|c| c["id"].as_u64())
                        .map(|id| {
                            next_sub += 1;
                            serde_json::json!({"id": next_sub, "channelId": id})
                        })
                        .collect();
                    let op = serde_json::json!({"op": "subscribe", "subscriptions": subs});
                    ws.send(Message::text(op.to_string())).map_err(|e| e.to_string())?;
                }
            }
            Ok(Message::Binary(_)) => {
                messages.fetch_add(1, Ordering::Relaxed);
            }
            Ok(_) => {}
            Err(tungstenite::Error::Io(e))
                if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {}
            Err(e) => return Err(e.to_string()),
        }
    }
    Ok(())
}

/// The watchers stand for programs on other machines (an operator's browser and Foxglove app,
/// the fleet's Prometheus): on the measured machine their threads run under `SCHED_IDLE`, so
/// what the comparison measures is the vehicle's side (the `navsync web` process, itself under
/// `SCHED_IDLE`, and the loopback traffic), not a browser sharing the vehicle's two cores.
fn as_remote_watcher() {
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: sched_setscheduler on the calling thread with a valid sched_param.
    if unsafe { libc::sched_setscheduler(0, libc::SCHED_IDLE, &param) } != 0 {
        eprintln!("watcher: SCHED_IDLE refused: {}", std::io::Error::last_os_error());
    }
}

impl Watch {
    /// What the row watches, for the table.
    pub fn label(self) -> &'static str {
        match self {
            Self::Page => "the page and /metrics, no Foxglove client",
            Self::NavState => "the page, /metrics, Foxglove on the NavState",
            Self::AllChannels => "the page, /metrics, Foxglove on every channel",
        }
    }
}

impl WebLoad {
    /// Connects the watchers to `navsync web` at `http` (page and metrics) and `foxglove`.
    pub fn start(http: &str, foxglove_addr: &str, watch: Watch) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let http_bytes = Arc::new(AtomicU64::new(0));
        let foxglove_messages = Arc::new(AtomicU64::new(0));
        let mut threads = Vec::new();
        {
            let (stop, bytes, addr) = (stop.clone(), http_bytes.clone(), http.to_string());
            threads.push(std::thread::spawn(move || {
                as_remote_watcher();
                get(&addr, "/events", &stop, &bytes)
            }));
        }
        {
            let (stop, bytes, addr) = (stop.clone(), http_bytes.clone(), http.to_string());
            threads.push(std::thread::spawn(move || {
                as_remote_watcher();
                while !stop.load(Ordering::Relaxed) {
                    get(&addr, "/metrics", &AtomicBool::new(false), &bytes);
                    std::thread::sleep(Duration::from_secs(1));
                }
            }));
        }
        if watch != Watch::Page {
            let (stop, n, addr) = (stop.clone(), foxglove_messages.clone(), foxglove_addr.to_string());
            threads.push(std::thread::spawn(move || {
                as_remote_watcher();
                if let Err(e) = foxglove(&addr, &stop, &n, watch) {
                    eprintln!("foxglove watcher: {e}");
                }
            }));
        }
        Self {
            stop,
            threads,
            http_bytes,
            foxglove_messages,
        }
    }
}

impl Drop for WebLoad {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}
