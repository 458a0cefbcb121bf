//! `navsync pps --source SOURCE --id ID`: the 1 PPS driver.
//!
//! read an edge from the source → validate ([`edge_validator`], pure: missing, duplicate,
//! early/late edges rejected and counted, stamp jitter measured) → publish `PpsEdge` on
//! `navsync/pps/{id}/edge`, Health on `navsync/health/pps-{id}`.
//!
//! Sources:
//! - `kernel:/dev/ppsN` ([`kernel`]): the Linux PPS API (RFC 2783), kernel interrupt stamps,
//!   ~1 µs;
//! - `serial-dcd:/dev/ttyX`, `serial-cts:/dev/ttyX` ([`serial_dcd`]): a modem-status line,
//!   stamped at user-space wake-up (tens of µs, measured);
//! - `sim` ([`sim_source`]): the simulator's raw edges from `navsync/sim/pps`.
//!
//! Published edges: `stamp.host_ns` the edge's `CLOCK_MONOTONIC` time, `stamp.seq` the number
//! of seconds since the first accepted edge (a gap is a missing edge), `source_seq` the
//! source's own counter, `jitter_ns` the 1-sigma stamp noise (measured once 8 one-second
//! intervals were seen, the source's typical value before). Which GNSS second an edge marks,
//! and whether a valid fix vouches for it, is decided by the estimator (`time_sync`).

pub mod edge_validator;
pub mod kernel;
pub mod serial_dcd;
pub mod sim_source;

use std::path::PathBuf;
use std::time::Duration;

use navsync_shared::health_reporter::HealthReporter;
use navsync_shared::ipc::{IpcError, IpcNode};
use navsync_shared::samples::{PpsEdge, Stamp, StampSource};
use navsync_shared::services;
use navsync_shared::time::monotonic_now_ns;
use tracing::{debug, info, info_span, warn};

use edge_validator::{EdgeValidator, RawEdge, ValidatorConfig, Verdict};
use serial_dcd::Line;

/// Errors of the PPS driver.
#[derive(Debug, thiserror::Error)]
pub enum PpsError {
    /// The device could not be opened.
    #[error("opening {path}: {source}")]
    Open {
        /// Device path.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// An ioctl failed.
    #[error("{what} on {path}: {source}")]
    Ioctl {
        /// The request.
        what: &'static str,
        /// Device path.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// The device cannot serve as a PPS source.
    #[error("{path}: {what}")]
    Unsupported {
        /// Device path.
        path: String,
        /// Why.
        what: String,
    },
    /// The device failed while in use.
    #[error("{path}: {what}")]
    Device {
        /// Device path.
        path: String,
        /// What failed.
        what: String,
    },
    /// A source specification that is not understood.
    #[error("unknown PPS source `{0}`: expected kernel:/dev/ppsN, serial-dcd:/dev/ttyX, serial-cts:/dev/ttyX or sim")]
    BadSource(String),
    /// IPC failure.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// A health counter could not be registered.
    #[error(transparent)]
    Health(#[from] navsync_shared::health_reporter::HealthError),
}

/// Where the edges come from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SourceSpec {
    /// A kernel PPS device.
    Kernel(PathBuf),
    /// A serial port's modem-status line.
    Serial(PathBuf, Line),
    /// The simulator.
    Sim,
}

deserialize_from_str!(SourceSpec);

impl std::str::FromStr for SourceSpec {
    type Err = PpsError;
    fn from_str(s: &str) -> Result<Self, PpsError> {
        let path = |p: &str| {
            if p.is_empty() {
                Err(PpsError::BadSource(s.to_string()))
            } else {
                Ok(PathBuf::from(p))
            }
        };
        if s == "sim" {
            Ok(Self::Sim)
        } else if let Some(p) = s.strip_prefix("kernel:") {
            Ok(Self::Kernel(path(p)?))
        } else if let Some(p) = s.strip_prefix("serial-dcd:") {
            Ok(Self::Serial(path(p)?, Line::Dcd))
        } else if let Some(p) = s.strip_prefix("serial-cts:") {
            Ok(Self::Serial(path(p)?, Line::Cts))
        } else {
            Err(PpsError::BadSource(s.to_string()))
        }
    }
}

impl std::fmt::Display for SourceSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Kernel(p) => write!(f, "kernel:{}", p.display()),
            Self::Serial(p, Line::Dcd) => write!(f, "serial-dcd:{}", p.display()),
            Self::Serial(p, Line::Cts) => write!(f, "serial-cts:{}", p.display()),
            Self::Sim => write!(f, "sim"),
        }
    }
}

impl SourceSpec {
    /// How the source's stamps are taken.
    pub fn stamp_source(&self) -> StampSource {
        match self {
            Self::Kernel(_) => StampSource::KernelPps,
            Self::Serial(..) => StampSource::SerialLine,
            Self::Sim => StampSource::Simulated,
        }
    }

    /// Typical 1-sigma stamp jitter before it is measured, and the smallest value published
    /// once measured, ns.
    pub fn jitter_prior_and_floor_ns(&self) -> (f64, f64) {
        match self {
            Self::Kernel(_) | Self::Sim => (1_000.0, 1_000.0),
            Self::Serial(..) => (30_000.0, 5_000.0),
        }
    }
}

/// Settings of the PPS driver process.
#[derive(Debug, Clone)]
pub struct PpsArgs {
    /// The source.
    pub source: SourceSpec,
    /// PPS id (service `navsync/pps/{id}/edge`).
    pub id: String,
}

/// The edge to publish for an accepted raw edge. Pure.
pub fn published_edge(raw: &RawEdge, index: u64, jitter_ns: f64, source: StampSource) -> PpsEdge {
    PpsEdge {
        stamp: Stamp::host(raw.host_ns, index, source),
        source_seq: raw.source_seq,
        jitter_ns,
        assert_edge: 1,
        reserved: [0; 7],
    }
}

/// The 1-sigma jitter to publish: the measured one (not below the floor) once known, else
/// what the source states, else the prior.
pub fn jitter_to_publish(spec: &SourceSpec, measured: Option<f64>, stated: Option<f64>) -> f64 {
    let (prior, floor) = spec.jitter_prior_and_floor_ns();
    match (stated, measured) {
        (Some(s), _) => s,
        (None, Some(m)) => m.max(floor),
        (None, None) => prior,
    }
}

enum Source {
    Kernel(kernel::KernelPps),
    Serial(serial_dcd::SerialDcd),
    Sim(Box<sim_source::SimSource>),
}

impl Source {
    fn open(spec: &SourceSpec, node: &IpcNode) -> Result<Self, PpsError> {
        Ok(match spec {
            SourceSpec::Kernel(p) => Self::Kernel(kernel::KernelPps::open(p)?),
            SourceSpec::Serial(p, line) => Self::Serial(serial_dcd::SerialDcd::open(p, *line)?),
            SourceSpec::Sim => Self::Sim(Box::new(sim_source::SimSource::open(node)?)),
        })
    }

    fn next_edge(&mut self, timeout: Duration) -> Result<Option<RawEdge>, PpsError> {
        match self {
            Self::Kernel(k) => k.next_edge(timeout),
            Self::Serial(s) => s.next_edge(timeout),
            Self::Sim(s) => s.next_edge(timeout),
        }
    }

    fn stated_jitter_ns(&self) -> Option<f64> {
        match self {
            Self::Sim(s) => s.stated_jitter_ns(),
            _ => None,
        }
    }

    fn device_counters(&self) -> [(&'static str, u64); 2] {
        match self {
            Self::Kernel(k) => [
                ("kernel_skipped_asserts", k.decoder().skipped),
                ("kernel_bad_times", k.decoder().bad_times),
            ],
            Self::Serial(s) => [("missed_transitions", s.missed_transitions()), ("", 0)],
            Self::Sim(_) => [("", 0), ("", 0)],
        }
    }
}

/// Consecutive IPC failures (other than for a termination signal) before giving up.
const MAX_IPC_ERRORS: u32 = 100;
/// How long one wait for an edge lasts before termination is checked again.
const WAIT: Duration = Duration::from_millis(250);

/// Runs the driver until SIGINT/SIGTERM. A device that cannot be opened (or fails) is
/// reopened with exponential backoff (0.1 s → 5 s); a bad source specification, the sim's
/// IPC failing, or a device that can never be a PPS source stop the driver with an error.
pub fn run(args: &PpsArgs) -> Result<(), PpsError> {
    let process = format!("pps-{}", args.id);
    let _span = info_span!("pps", id = %args.id, source = %args.source).entered();
    let node = IpcNode::new(&process)?;
    let mut publisher = node.publisher::<PpsEdge>(&services::pps_edge(&args.id))?;
    let mut health = HealthReporter::new(&node, &process)?;
    let r_edges = health.rate("edges_out")?;
    let c_reopen = health.counter("device_reopens")?;
    let c_jitter = health.counter("jitter_ns")?;
    let c_publish_err = health.counter("publish_errors")?;
    let mut validator = EdgeValidator::new(ValidatorConfig::default());
    let stamp_source = args.source.stamp_source();
    let mut backoff = Duration::from_millis(100);
    let mut warned = false;
    let mut ipc_errors = 0u32;
    info!("pps driver running");
    navsync_shared::sd_notify::ready(&format!("pps {}: {}", args.id, args.source));

    'outer: while !node.termination_requested() {
        navsync_shared::sd_notify::watchdog();
        let mut source = match Source::open(&args.source, &node) {
            Ok(s) => {
                if warned {
                    info!("source is back");
                }
                warned = false;
                backoff = Duration::from_millis(100);
                s
            }
            Err(e @ (PpsError::Unsupported { .. } | PpsError::Ipc(_) | PpsError::BadSource(_))) => return Err(e),
            Err(e) => {
                if !warned {
                    warn!("{e}; retrying with backoff");
                    warned = true;
                }
                if let Err(e) = health.maybe_publish(monotonic_now_ns()) {
                    warn!("publishing health: {e}");
                }
                if !node.sleep(backoff) {
                    break;
                }
                backoff = (backoff * 2).min(Duration::from_secs(5));
                continue;
            }
        };
        loop {
            if node.termination_requested() {
                break 'outer;
            }
            match source.next_edge(WAIT) {
                Ok(Some(raw)) => {
                    ipc_errors = 0;
                    let verdict = validator.push(&raw);
                    let index = match verdict {
                        Verdict::Accepted { index, .. } | Verdict::Resynced { index } => Some(index),
                        _ => None,
                    };
                    if !matches!(verdict, Verdict::Accepted { missing: 0, .. } | Verdict::Clear) {
                        debug!(?verdict, host_ns = raw.host_ns, "edge");
                    }
                    if let Some(index) = index {
                        let jitter =
                            jitter_to_publish(&args.source, validator.measured_jitter_ns(), source.stated_jitter_ns());
                        let edge = published_edge(&raw, index, jitter, stamp_source);
                        match publisher.publish(&edge) {
                            Ok(()) => health.tick(r_edges),
                            Err(e) => {
                                warn!("publishing edge: {e}");
                                health.add(c_publish_err, 1);
                            }
                        }
                    }
                }
                Ok(None) => {}
                // A signal interrupts the sim source's wait: SIGTERM/SIGINT end the loop at the
                // top; other interruptions are retried, a persistent failure is an error.
                Err(e @ PpsError::Ipc(_)) => {
                    ipc_errors += 1;
                    if ipc_errors > MAX_IPC_ERRORS && !node.termination_requested() {
                        return Err(e);
                    }
                    continue;
                }
                Err(e) => {
                    warn!("{e}; reopening");
                    health.add(c_reopen, 1);
                    break;
                }
            }
            for (name, v) in validator.counters().named() {
                health.set_named(name, v)?;
            }
            for (name, v) in source.device_counters() {
                if !name.is_empty() {
                    health.set_named(name, v)?;
                }
            }
            health.set(
                c_jitter,
                validator.measured_jitter_ns().map_or(0, |j| j.round().max(0.0) as u64),
            );
            if let Err(e) = health.maybe_publish(monotonic_now_ns()) {
                warn!("publishing health: {e}");
            }
            navsync_shared::sd_notify::watchdog();
        }
    }
    navsync_shared::sd_notify::stopping();
    let _ = health.publish_final();
    info!("pps driver stopped");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn source_specs_parse_and_print() {
        for s in [
            "kernel:/dev/pps0",
            "serial-dcd:/dev/ttyS0",
            "serial-cts:/dev/ttyUSB1",
            "sim",
        ] {
            let spec: SourceSpec = s.parse().expect(s);
            assert_eq!(spec.to_string(), s);
        }
        assert_eq!(
            "kernel:/dev/pps0".parse::<SourceSpec>().unwrap().stamp_source(),
            StampSource::KernelPps
        );
        for bad in ["", "kernel:", "usb:/dev/x", "serial-dcd:", "SIM"] {
            assert!(bad.parse::<SourceSpec>().is_err(), "{bad}");
        }
    }

    #[test]
    fn published_jitter_prefers_stated_then_measured() {
        let serial = SourceSpec::Serial("/dev/ttyS0".into(), Line::Dcd);
        assert_eq!(jitter_to_publish(&serial, None, None), 30_000.0);
        assert_eq!(jitter_to_publish(&serial, Some(12_000.0), None), 12_000.0);
        assert_eq!(jitter_to_publish(&serial, Some(100.0), None), 5_000.0);
        assert_eq!(
            jitter_to_publish(&SourceSpec::Sim, Some(900.0), Some(30_000.0)),
            30_000.0
        );
        let e = published_edge(
            &RawEdge {
                host_ns: 5,
                source_seq: 9,
                assert: true,
            },
            3,
            1e3,
            StampSource::KernelPps,
        );
        assert_eq!(
            (e.stamp.host_ns, e.stamp.seq, e.source_seq, e.assert_edge),
            (5, 3, 9, 1)
        );
    }
}
