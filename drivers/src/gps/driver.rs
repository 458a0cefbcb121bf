//! `navsync gps`: the process shell around the NMEA front end.
//!
//! read (serialport, as little buffering as the API allows) → stamp (host time when the read
//! returned, back-dated by the line rate for bytes that were already waiting) → decode
//! ([`LineFramer`] → [`EpochAssembler`], pure) → publish `GnssFix` on `navsync/gnss/{id}/fix`.
//!
//! The port vanishing (USB unplug) is survived: the driver logs it once, reopens with
//! exponential backoff (0.1 s → 5 s) and resumes; a wrong baud rate shows as noise and
//! checksum counters, and `--baud auto` hunts the common rates like gpsd does.

use std::io::{ErrorKind, Read};
use std::time::{Duration, Instant};

use navsync_shared::health_reporter::HealthReporter;
use navsync_shared::ipc::{IpcError, IpcNode, Publisher};
use navsync_shared::samples::GnssFix;
use navsync_shared::services;
use navsync_shared::time::monotonic_now_ns;
use serialport::{ClearBuffer, SerialPort, TTYPort};
use tracing::{info, info_span, warn};

use super::nmea_epoch::EpochAssembler;
use super::nmea_framer::LineFramer;

/// Baud rates tried by `--baud auto`, most common first (gpsd's hunt order differs; these
/// are the rates NMEA receivers ship with).
pub const HUNT_BAUDS: [u32; 7] = [9600, 4800, 38_400, 115_200, 19_200, 57_600, 230_400];

/// How long one baud rate is tried before hunting on, when no valid sentence arrives.
const HUNT_DWELL: Duration = Duration::from_millis(2500);

/// Read timeout; after this much silence the epoch being assembled is emitted.
pub const IDLE_FLUSH: Duration = Duration::from_millis(50);

/// Serial line rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Baud {
    /// A fixed rate, e.g. 9600.
    Fixed(u32),
    /// Hunt through [`HUNT_BAUDS`] until sentences with valid checksums arrive.
    Auto,
}

impl std::str::FromStr for Baud {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "auto" {
            return Ok(Baud::Auto);
        }
        s.parse::<u32>()
            .ok()
            .filter(|b| *b > 0)
            .map(Baud::Fixed)
            .ok_or_else(|| format!("`{s}` is not a baud rate (a positive integer or `auto`)"))
    }
}

/// Settings of the GPS driver process.
#[derive(Debug, Clone)]
pub struct GpsArgs {
    /// Serial device, e.g. `/dev/ttyUSB0` or a pseudo-terminal.
    pub port: String,
    /// Line rate.
    pub baud: Baud,
    /// Receiver id (service `navsync/gnss/{id}/fix`).
    pub id: String,
}

/// Errors that stop the GPS driver (device errors never do: it reopens).
#[derive(Debug, thiserror::Error)]
pub enum GpsError {
    /// IPC failure.
    #[error(transparent)]
    Ipc(#[from] IpcError),
}

struct Decoder {
    framer: LineFramer,
    assembler: EpochAssembler,
}

/// Runs the driver until SIGINT/SIGTERM.
pub fn run(args: &GpsArgs) -> Result<(), GpsError> {
    let process = format!("gps-{}", args.id);
    let _span = info_span!("gps", id = %args.id, port = %args.port).entered();
    let node = IpcNode::new(&process)?;
    let mut publisher = node.publisher::<GnssFix>(&services::gnss_fix(&args.id))?;
    let mut health = HealthReporter::new(&node, &process)?;
    let r_fix = health.rate("fixes_out");
    let c_reopen = health.counter("port_reopens");
    let c_publish_err = health.counter("publish_errors");
    let mut dec = Decoder {
        framer: LineFramer::new(),
        assembler: EpochAssembler::new(),
    };
    let mut backoff = Duration::from_millis(100);
    let mut hunt_index = 0usize;
    let mut warned_open = false;
    let mut last_errors = 0u64;
    let mut last_warn = Instant::now() - Duration::from_secs(60);

    info!("gps driver running");
    while !node.termination_requested() {
        let baud = match args.baud {
            Baud::Fixed(b) => b,
            Baud::Auto => HUNT_BAUDS[hunt_index % HUNT_BAUDS.len()],
        };
        let mut port = match open(&args.port, baud) {
            Ok(p) => {
                if warned_open {
                    info!(baud, "port is back");
                }
                warned_open = false;
                backoff = Duration::from_millis(100);
                p
            }
            Err(e) => {
                if !warned_open {
                    warn!("cannot open {}: {e}; retrying with backoff", args.port);
                    warned_open = true;
                }
                publish_health(&mut health, &dec, monotonic_now_ns());
                if !node.sleep(backoff) {
                    break;
                }
                backoff = (backoff * 2).min(Duration::from_secs(5));
                continue;
            }
        };
        info!(baud, "port open");
        let ns_per_byte = 10_000_000_000 / baud as i64;
        let valid_before = valid_sentences(&dec);
        let opened = Instant::now();
        let mut buf = [0u8; 512];
        loop {
            if node.termination_requested() {
                break;
            }
            match port.read(&mut buf) {
                Ok(0) => {}
                Ok(n) => {
                    let t = monotonic_now_ns();
                    let Decoder { framer, assembler } = &mut dec;
                    framer.push(&buf[..n], t, ns_per_byte, &mut |s| {
                        assembler.push(s.text, s.host_ns, &mut |fix| {
                            if publisher_publish(&mut publisher, fix) {
                                health.tick(r_fix);
                            } else {
                                health.add(c_publish_err, 1);
                            }
                        });
                    });
                }
                Err(e) if e.kind() == ErrorKind::TimedOut || e.kind() == ErrorKind::Interrupted => {
                    let Decoder { assembler, .. } = &mut dec;
                    assembler.flush(&mut |fix| {
                        if publisher_publish(&mut publisher, fix) {
                            health.tick(r_fix);
                        }
                    });
                }
                Err(e) => {
                    warn!("read from {} failed: {e}; reopening", args.port);
                    health.add(c_reopen, 1);
                    dec.framer.reset();
                    break;
                }
            }
            let now = monotonic_now_ns();
            publish_health(&mut health, &dec, now);
            let errors = error_count(&dec);
            if errors > last_errors && last_warn.elapsed() > Duration::from_secs(10) {
                warn!(
                    new_errors = errors - last_errors,
                    "malformed input skipped (see health counters)"
                );
                last_warn = Instant::now();
                last_errors = errors;
            }
            if args.baud == Baud::Auto && valid_sentences(&dec) == valid_before && opened.elapsed() > HUNT_DWELL {
                hunt_index += 1;
                info!(baud, "no valid NMEA at this rate; hunting on");
                break;
            }
        }
    }
    let _ = health.publish_final();
    info!("gps driver stopped");
    Ok(())
}

fn publisher_publish(p: &mut Publisher<GnssFix>, fix: &GnssFix) -> bool {
    match p.publish(fix) {
        Ok(()) => true,
        Err(e) => {
            warn!("publishing fix: {e}");
            false
        }
    }
}

/// Opens the port raw, with a short read timeout, and discards stale input.
fn open(path: &str, baud: u32) -> Result<TTYPort, serialport::Error> {
    let mut port = serialport::new(path, baud).timeout(IDLE_FLUSH).open_native()?;
    // Exclusive access is advisory; a pseudo-terminal's creator may hold it open too.
    let _ = port.set_exclusive(false);
    port.clear(ClearBuffer::Input)?;
    Ok(port)
}

/// Sentences that passed the checksum so far.
fn valid_sentences(d: &Decoder) -> u64 {
    let c = d.assembler.counters();
    c.sentences - c.bad_checksum - c.no_checksum
}

/// Malformed-input counters summed (for rate-limited logging).
fn error_count(d: &Decoder) -> u64 {
    let f = d.framer.counters();
    let a = d.assembler.counters();
    f.noise_bytes + f.truncated + f.overlong + f.non_ascii + a.bad_checksum + a.no_checksum + a.unparsable
}

fn publish_health(h: &mut HealthReporter, d: &Decoder, now: i64) {
    for (name, v) in d.framer.counters().named() {
        h.set_named(name, v);
    }
    for (name, v) in d.assembler.counters().named() {
        h.set_named(name, v);
    }
    if let Err(e) = h.maybe_publish(now) {
        warn!("publishing health: {e}");
    }
}
