//! `navsync echo SERVICE`: prints every sample of any navsync service, one line each,
//! human-readable by default or as JSON (`--json`, the same encoding as the recordings).

use std::io::Write;
use std::time::{Duration, Instant};

use iceoryx2::prelude::ZeroCopySend;
use navsync_shared::ipc::{IpcError, IpcNode};
use navsync_shared::json::to_json;
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::*;
use navsync_shared::services::ServiceKind;
use serde_json::Value;

/// Settings of `navsync echo`.
#[derive(Debug, Clone)]
pub struct EchoArgs {
    /// Service name, e.g. `navsync/imu/0/sample`.
    pub service: String,
    /// Stop after this many samples.
    pub count: Option<u64>,
    /// Print JSON instead of text.
    pub json: bool,
    /// Give up after this long without a sample.
    pub timeout: Option<Duration>,
}

/// Errors of `navsync echo`.
#[derive(Debug, thiserror::Error)]
pub enum EchoError {
    /// Not a navsync service name.
    #[error("`{0}` is not a navsync service (expected e.g. navsync/imu/0/sample, navsync/nav/state)")]
    UnknownService(String),
    /// IPC failure.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// No sample within the timeout.
    #[error("no sample on `{0}` within the timeout")]
    Timeout(String),
    /// stdout closed.
    #[error("writing output: {0}")]
    Io(#[from] std::io::Error),
}

/// Runs `navsync echo`.
pub fn run(args: &EchoArgs) -> Result<(), EchoError> {
    let kind = ServiceKind::of(&args.service).ok_or_else(|| EchoError::UnknownService(args.service.clone()))?;
    match kind {
        ServiceKind::GnssFix => echo::<GnssFix>(args),
        ServiceKind::PpsEdge => echo::<PpsEdge>(args),
        ServiceKind::ImuSample => echo::<ImuSample>(args),
        ServiceKind::TimeState => echo::<TimeState>(args),
        ServiceKind::NavState => echo::<NavState>(args),
        ServiceKind::Health => echo::<Health>(args),
        ServiceKind::SimTruth => echo::<SimTruth>(args),
    }
}

fn echo<T: Reflect + ZeroCopySend + core::fmt::Debug>(args: &EchoArgs) -> Result<(), EchoError> {
    let node = IpcNode::new(&format!("echo-{}", std::process::id()))?;
    let sub = node.subscriber::<T>(&args.service)?;
    let mut out = std::io::stdout().lock();
    let mut n = 0u64;
    let mut last = Instant::now();
    while args.count.is_none_or(|c| n < c) && !node.termination_requested() {
        match sub.wait_next(Duration::from_millis(200))? {
            Some(sample) => {
                let v = to_json(&sample);
                if args.json {
                    writeln!(out, "{v}")?;
                } else {
                    writeln!(out, "{}", human(&v))?;
                }
                n += 1;
                last = Instant::now();
            }
            None => {
                if args.timeout.is_some_and(|t| last.elapsed() > t) {
                    return Err(EchoError::Timeout(args.service.clone()));
                }
            }
        }
    }
    Ok(())
}

/// One line of `key=value` pairs, nested keys dotted, unknown (null) values and empty
/// table slots left out; floats with up to 9 decimals (scientific notation below 1e−3).
pub fn human(v: &Value) -> String {
    let mut parts = Vec::new();
    flatten("", v, &mut parts);
    parts.join(" ")
}

fn is_empty_slot(v: &Value) -> bool {
    match v {
        Value::Object(m) => m.values().all(is_empty_slot),
        Value::String(s) => s.is_empty(),
        Value::Number(n) => n.as_f64() == Some(0.0),
        Value::Null => true,
        Value::Array(a) => a.iter().all(is_empty_slot),
        Value::Bool(b) => !b,
    }
}

fn flatten(prefix: &str, v: &Value, out: &mut Vec<String>) {
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                flatten(&key, x, out);
            }
        }
        Value::Array(a) if a.iter().all(|x| x.is_number() || x.is_null()) => {
            let items: Vec<String> = a.iter().map(scalar).collect();
            out.push(format!("{prefix}=[{}]", items.join(",")));
        }
        Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                if !is_empty_slot(x) {
                    flatten(&format!("{prefix}[{i}]"), x, out);
                }
            }
        }
        Value::Null => {}
        Value::String(s) if s.is_empty() => {}
        _ => out.push(format!("{prefix}={}", scalar(v))),
    }
}

fn scalar(v: &Value) -> String {
    match v {
        Value::Number(n) if n.is_f64() => {
            let x = n.as_f64().unwrap_or(f64::NAN);
            if x != 0.0 && (x.abs() < 1e-3 || x.abs() >= 1e9) {
                format!("{x:.6e}")
            } else {
                format!("{x:.9}")
                    .trim_end_matches('0')
                    .trim_end_matches('.')
                    .to_string()
            }
        }
        Value::Null => "null".into(),
        Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn human_line_skips_unknowns_and_empty_slots() {
        let mut h = Health::new("gps-0");
        h.counters[0].name = navsync_shared::reflect::fixed_str("bad_checksum");
        h.counters[0].value = 3;
        let line = human(&to_json(&h));
        assert!(
            line.contains("counters[0].name=bad_checksum counters[0].value=3"),
            "{line}"
        );
        assert!(!line.contains("counters[1]"), "{line}");
        let fix = GnssFix::empty(Stamp::host(5, 1, StampSource::Receipt));
        let line = human(&to_json(&fix));
        assert!(line.starts_with("stamp.host_ns=5"), "{line}");
        assert!(!line.contains("lat_deg"), "{line}");
    }
}
