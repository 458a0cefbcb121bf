//! The systemd notification protocol (`sd_notify(3)`) without libsystemd: `READY=1`,
//! `WATCHDOG=1`, `STATUS=…` and `STOPPING=1` as datagrams to the `AF_UNIX` socket named by
//! `$NOTIFY_SOCKET` (a path, or an abstract name written with a leading `@`).
//!
//! Outside systemd (`$NOTIFY_SOCKET` unset) every call is a no-op, so roles call these
//! unconditionally:
//!
//! * [`ready`] once the process really serves (its services exist and its loop runs); later
//!   calls do nothing;
//! * [`watchdog`] from every turn of the main loop: it sends `WATCHDOG=1` when half of
//!   `$WATCHDOG_USEC` has passed since the last one, so a loop that stops turning stops
//!   feeding the watchdog and systemd restarts the unit (`WatchdogSec=`);
//! * [`stopping`] when the loop ends, before cleaning up.
//!
//! `$WATCHDOG_PID`, when set, must name this process (as in `sd_watchdog_enabled(3)`), so a
//! child that inherited the environment does not feed its parent's watchdog.

use std::io;
use std::os::linux::net::SocketAddrExt;
use std::os::unix::net::{SocketAddr, UnixDatagram};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Where and how often to notify, as read from the environment.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NotifyEnv {
    /// `$NOTIFY_SOCKET`: a path, or `@name` for an abstract socket.
    pub socket: Option<String>,
    /// `$WATCHDOG_USEC` as a duration, if the watchdog is enabled for this process.
    pub watchdog: Option<Duration>,
}

impl NotifyEnv {
    /// Reads `$NOTIFY_SOCKET`, `$WATCHDOG_USEC` and `$WATCHDOG_PID`.
    pub fn from_env() -> Self {
        let var = |k: &str| std::env::var(k).ok().filter(|v| !v.is_empty());
        Self::from_vars(
            var("NOTIFY_SOCKET"),
            var("WATCHDOG_USEC"),
            var("WATCHDOG_PID"),
            std::process::id(),
        )
    }

    /// The same from given values (pure, for tests).
    pub fn from_vars(socket: Option<String>, usec: Option<String>, pid: Option<String>, my_pid: u32) -> Self {
        let for_me = pid.is_none_or(|p| p.trim().parse::<u32>().ok() == Some(my_pid));
        let watchdog = usec
            .and_then(|u| u.trim().parse::<u64>().ok())
            .filter(|u| *u > 0 && for_me)
            .map(Duration::from_micros);
        Self { socket, watchdog }
    }
}

/// A connection to the service manager's notification socket.
#[derive(Debug)]
pub struct Notifier {
    socket: Option<(UnixDatagram, SocketAddr)>,
    watchdog_every: Option<Duration>,
    last_watchdog: Option<Instant>,
    ready_sent: bool,
}

impl Notifier {
    /// A notifier for `env`; without a socket every call is a no-op.
    pub fn new(env: &NotifyEnv) -> io::Result<Self> {
        let socket = match &env.socket {
            Some(s) => Some((UnixDatagram::unbound()?, address(s)?)),
            None => None,
        };
        Ok(Self {
            socket,
            watchdog_every: env.watchdog.map(|w| w / 2),
            last_watchdog: None,
            ready_sent: false,
        })
    }

    /// Whether a service manager listens.
    pub fn enabled(&self) -> bool {
        self.socket.is_some()
    }

    /// The interval at which [`watchdog`](Self::watchdog) sends: half of `$WATCHDOG_USEC`.
    pub fn watchdog_interval(&self) -> Option<Duration> {
        self.watchdog_every
    }

    /// Sends one datagram of `KEY=VALUE` lines.
    pub fn send(&self, state: &str) -> io::Result<()> {
        if let Some((sock, addr)) = &self.socket {
            sock.send_to_addr(state.as_bytes(), addr)?;
        }
        Ok(())
    }

    /// `READY=1` (with a `STATUS=` line when given), once; returns whether it was sent now.
    pub fn ready(&mut self, status: Option<&str>) -> io::Result<bool> {
        if self.ready_sent || self.socket.is_none() {
            self.ready_sent = true;
            return Ok(false);
        }
        let msg = match status {
            Some(s) => format!("READY=1\nSTATUS={}", one_line(s)),
            None => "READY=1".to_string(),
        };
        self.send(&msg)?;
        self.ready_sent = true;
        Ok(true)
    }

    /// `WATCHDOG=1` if half the watchdog interval has passed since the last one (or none was
    /// sent yet); returns whether it was sent.
    pub fn watchdog(&mut self, now: Instant) -> io::Result<bool> {
        let Some(every) = self.watchdog_every else {
            return Ok(false);
        };
        if self.last_watchdog.is_some_and(|t| now.duration_since(t) < every) {
            return Ok(false);
        }
        self.send("WATCHDOG=1")?;
        self.last_watchdog = Some(now);
        Ok(true)
    }

    /// `STATUS=text`.
    pub fn status(&self, text: &str) -> io::Result<()> {
        self.send(&format!("STATUS={}", one_line(text)))
    }

    /// `STOPPING=1`.
    pub fn stopping(&self) -> io::Result<()> {
        self.send("STOPPING=1")
    }
}

fn one_line(s: &str) -> String {
    s.replace('\n', " ")
}

/// The socket address of `$NOTIFY_SOCKET`: `@name` is abstract, anything else a path.
fn address(s: &str) -> io::Result<SocketAddr> {
    match s.strip_prefix('@') {
        Some(name) => SocketAddr::from_abstract_name(name.as_bytes()),
        None if s.starts_with('/') => SocketAddr::from_pathname(s),
        None => Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("NOTIFY_SOCKET `{s}` is neither an absolute path nor an abstract name (@…)"),
        )),
    }
}

static GLOBAL: Mutex<Option<Notifier>> = Mutex::new(None);

fn with_global<R>(f: impl FnOnce(&mut Notifier) -> io::Result<R>) -> Option<R> {
    let mut g = GLOBAL.lock().unwrap_or_else(|e| e.into_inner());
    if g.is_none() {
        match Notifier::new(&NotifyEnv::from_env()) {
            Ok(n) => *g = Some(n),
            Err(e) => {
                // Not fatal: the process runs, systemd's start timeout or watchdog tells.
                eprintln!("navsync: systemd notification socket unusable: {e}");
                *g = Some(
                    Notifier::new(&NotifyEnv {
                        socket: None,
                        watchdog: None,
                    })
                    .ok()?,
                );
            }
        }
    }
    let n = g.as_mut()?;
    f(n).ok()
}

/// The process-wide notifier: `READY=1` (once), with a status line; true when sent now.
pub fn ready(status: &str) -> bool {
    with_global(|n| n.ready(Some(status))) == Some(true)
}

/// The process-wide notifier: `WATCHDOG=1` when half of `$WATCHDOG_USEC` has passed.
pub fn watchdog() {
    with_global(|n| n.watchdog(Instant::now()));
}

/// The process-wide notifier: `STATUS=text`.
pub fn status(text: &str) {
    with_global(|n| n.status(text));
}

/// The process-wide notifier: `STOPPING=1`.
pub fn stopping() {
    with_global(|n| n.stopping());
}

#[cfg(test)]
mod tests {
    use super::*;

    fn recv(s: &UnixDatagram) -> String {
        let mut buf = [0u8; 512];
        let n = s.recv(&mut buf).expect("datagram");
        String::from_utf8_lossy(&buf[..n]).into_owned()
    }

    #[test]
    fn env_parsing() {
        let e = NotifyEnv::from_vars(Some("/run/x".into()), Some("3000000".into()), None, 7);
        assert_eq!(e.watchdog, Some(Duration::from_secs(3)));
        let e = NotifyEnv::from_vars(None, Some("3000000".into()), Some("8".into()), 7);
        assert_eq!(e.watchdog, None, "another process's watchdog");
        let e = NotifyEnv::from_vars(None, Some("3000000".into()), Some("7".into()), 7);
        assert_eq!(e.watchdog, Some(Duration::from_secs(3)));
        assert_eq!(NotifyEnv::from_vars(None, Some("x".into()), None, 7).watchdog, None);
        assert_eq!(NotifyEnv::from_vars(None, Some("0".into()), None, 7).watchdog, None);
        assert!(Notifier::new(&NotifyEnv::from_vars(Some("relative".into()), None, None, 1)).is_err());
    }

    #[test]
    fn path_socket_gets_ready_watchdog_at_half_interval_and_stopping() {
        let dir = std::env::temp_dir().join(format!("navsync-sdnotify-{}", std::process::id()));
        let _ = std::fs::create_dir_all(&dir);
        let path = dir.join("notify.sock");
        let _ = std::fs::remove_file(&path);
        let server = UnixDatagram::bind(&path).expect("bind");
        server.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
        let env = NotifyEnv {
            socket: Some(path.display().to_string()),
            watchdog: Some(Duration::from_millis(200)),
        };
        let mut n = Notifier::new(&env).unwrap();
        assert!(n.enabled());
        assert_eq!(n.watchdog_interval(), Some(Duration::from_millis(100)));
        assert!(n.ready(Some("serving\n3 services")).unwrap());
        assert!(!n.ready(None).unwrap(), "READY only once");
        assert_eq!(recv(&server), "READY=1\nSTATUS=serving 3 services");
        let t0 = Instant::now();
        assert!(n.watchdog(t0).unwrap());
        assert!(!n.watchdog(t0 + Duration::from_millis(99)).unwrap());
        assert!(n.watchdog(t0 + Duration::from_millis(100)).unwrap());
        assert_eq!(recv(&server), "WATCHDOG=1");
        assert_eq!(recv(&server), "WATCHDOG=1");
        n.stopping().unwrap();
        assert_eq!(recv(&server), "STOPPING=1");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn abstract_socket() {
        let name = format!("navsync-sdnotify-test-{}", std::process::id());
        let server = UnixDatagram::bind_addr(&SocketAddr::from_abstract_name(name.as_bytes()).unwrap()).unwrap();
        server.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
        let mut n = Notifier::new(&NotifyEnv {
            socket: Some(format!("@{name}")),
            watchdog: None,
        })
        .unwrap();
        assert!(n.ready(None).unwrap());
        assert_eq!(recv(&server), "READY=1");
        assert!(!n.watchdog(Instant::now()).unwrap(), "no watchdog configured");
        n.status("x").unwrap();
        assert_eq!(recv(&server), "STATUS=x");
    }

    #[test]
    fn no_socket_is_a_no_op() {
        let mut n = Notifier::new(&NotifyEnv {
            socket: None,
            watchdog: Some(Duration::from_secs(1)),
        })
        .unwrap();
        assert!(!n.enabled());
        assert!(!n.ready(None).unwrap());
        n.stopping().unwrap();
    }
}
