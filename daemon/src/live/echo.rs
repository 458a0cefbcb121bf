//! `navsync echo SERVICE`: prints every sample of any navsync service, one line each,
//! human-readable by default or as JSON (`--json`, the same encoding as the recordings).
//!
//! * `--fields lat_deg,lon_deg,stamp.host_ns` prints only those fields (dotted paths into
//!   nested structs, `[i]` into arrays: `vel_ned_mps[2]`, `imu[1].offset_s`); unknown paths
//!   are rejected before anything is received.
//! * `--rate N` prints at most N lines per second (the newest sample when a line is due;
//!   the others are skipped).
//!   A field asked for is always printed, `null` when it has no value (a NaN, an unknown time).
//! * Enumerations print as their names (`status=aligned time_status=locked
//!   stamp.source=kernel-pps`); `--raw` prints their numbers. `--json` is the recordings'
//!   encoding and keeps the numbers.
//! * `--hz` prints, once per second, the measured rate instead of the samples: samples per
//!   second of wall time, the mean/min/max spacing of their host stamps, and sequence gaps.

use std::io::Write;
use std::time::{Duration, Instant};

use navsync_shared::ipc::{IpcError, IpcNode};
use navsync_shared::json::to_json;
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::*;
use navsync_shared::services::ServiceKind;
use serde_json::{Map, Value};

/// Settings of `navsync echo`.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct EchoArgs {
    /// Service, e.g. navsync/imu/0/sample, navsync/time/state.
    pub service: String,
    /// Stop after N samples.
    #[arg(long)]
    pub count: Option<u64>,
    /// JSON lines instead of text.
    #[arg(long)]
    pub json: bool,
    /// Fail if no sample arrives for this many seconds.
    #[arg(long = "timeout", value_name = "S", value_parser = positive_seconds)]
    pub timeout: Option<Duration>,
    /// Print at most N lines per second (the newest sample when a line is due).
    #[arg(long = "rate", value_name = "N")]
    pub max_rate_hz: Option<f64>,
    /// Print the measured rate (once per second) instead of the samples.
    #[arg(long = "hz", conflicts_with_all = ["max_rate_hz", "fields"])]
    pub measure_rate: bool,
    /// Print only these fields, e.g. `lat_deg,lon_deg,stamp.host_ns,vel_ned_mps[2]`.
    #[arg(long, value_delimiter = ',')]
    pub fields: Vec<String>,
    /// Enumerations as their numbers (status=1) instead of their names (status=aligned).
    /// `--json` always gives the numbers.
    #[arg(long)]
    pub raw: bool,
    /// Receive through Zenoh from this endpoint (e.g. tcp/192.168.1.10:7447) instead of the
    /// local iceoryx2: one JSON line per sample with its instance and sequence number (needs
    /// the `zenoh` feature).
    #[arg(long, value_name = "ENDPOINT", conflicts_with_all = ["measure_rate", "fields", "max_rate_hz"])]
    pub zenoh: Option<String>,
    /// With --zenoh: only this instance's samples [default: any].
    #[arg(long, requires = "zenoh")]
    pub instance: Option<String>,
    /// Spin on the service instead of sleeping between samples (lowest latency, a whole core:
    /// for a subscriber on an isolated core). Off by default.
    #[arg(long, conflicts_with = "zenoh")]
    pub busy_poll: bool,
}

/// A positive number of seconds.
pub fn positive_seconds(s: &str) -> Result<Duration, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(Duration::from_secs_f64(v)),
        _ => Err(format!("`{s}`: expected a positive number of seconds")),
    }
}

/// Errors of `navsync echo`.
#[derive(Debug, thiserror::Error)]
pub enum EchoError {
    /// Not a navsync service name.
    #[error("`{0}` is not a navsync service (expected e.g. navsync/imu/0/sample, navsync/nav/state)")]
    UnknownService(String),
    /// A `--fields` path that the service's type does not have.
    #[error("{type_name} has no field `{path}` (fields: {known})")]
    UnknownField {
        /// The type.
        type_name: &'static str,
        /// The path asked for.
        path: String,
        /// The top-level fields.
        known: String,
    },
    /// A `--rate` that is not a positive number.
    #[error("--rate must be a positive number of lines per second")]
    BadRate,
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
        ServiceKind::GnssFix => echo::<GnssFix>(args, |s| (s.stamp.host_ns, Some(s.stamp.seq))),
        ServiceKind::PpsEdge => echo::<PpsEdge>(args, |s| (s.stamp.host_ns, Some(s.stamp.seq))),
        ServiceKind::ImuSample => echo::<ImuSample>(args, |s| (s.stamp.host_ns, Some(s.stamp.seq))),
        ServiceKind::TimeState => echo::<TimeState>(args, |s| (s.computed_host_ns, Some(s.seq))),
        ServiceKind::NavState => echo::<NavState>(args, |s| (s.host_ns, Some(s.seq))),
        ServiceKind::Health => echo::<Health>(args, |s| (s.host_ns, Some(s.seq))),
        ServiceKind::SimTruth => echo::<SimTruth>(args, |s| (s.host_ns, Some(s.seq))),
        ServiceKind::GnssTimePulse => echo::<GnssTimePulse>(args, |s| (s.stamp.host_ns, Some(s.stamp.seq))),
        ServiceKind::GnssEvent => echo::<GnssEvent>(args, |s| (s.stamp.host_ns, Some(s.stamp.seq))),
        ServiceKind::GnssRaw => echo::<GnssRaw>(args, |s| (s.stamp.host_ns, Some(s.stamp.seq))),
        ServiceKind::GnssNavData => echo::<GnssNavData>(args, |s| (s.stamp.host_ns, Some(s.stamp.seq))),
        ServiceKind::EstimatorSettings => echo::<EstimatorSettings>(args, |s| (s.host_ns, Some(s.seq))),
        ServiceKind::NetworkTime => echo::<NetworkTime>(args, |s| (s.host_ns, Some(s.seq))),
        ServiceKind::GnssSky => echo::<GnssSky>(args, |s| (s.stamp.host_ns, Some(s.stamp.seq))),
        ServiceKind::EventPose => echo::<EventPose>(args, |s| (s.host_ns, Some(s.seq))),
    }
}

/// One `--fields` path: keys and array indices.
#[derive(Debug, Clone, PartialEq)]
enum Step {
    Key(String),
    Index(usize),
}

/// Parses `a.b[2].c` into steps; `None` when malformed.
fn parse_path(path: &str) -> Option<Vec<Step>> {
    let mut steps = Vec::new();
    for part in path.split('.') {
        let (name, mut rest) = match part.find('[') {
            Some(i) => (&part[..i], &part[i..]),
            None => (part, ""),
        };
        if name.is_empty() {
            return None;
        }
        steps.push(Step::Key(name.to_string()));
        while !rest.is_empty() {
            let close = rest.find(']')?;
            steps.push(Step::Index(rest[1..close].parse().ok()?));
            rest = &rest[close + 1..];
            if !rest.is_empty() && !rest.starts_with('[') {
                return None;
            }
        }
    }
    Some(steps)
}

fn lookup<'a>(v: &'a Value, steps: &[Step]) -> Option<&'a Value> {
    steps.iter().try_fold(v, |v, s| match s {
        Step::Key(k) => v.get(k.as_str()),
        Step::Index(i) => v.get(*i),
    })
}

/// The selected fields of a sample as one JSON object keyed by the paths as given.
fn select(v: &Value, fields: &[(String, Vec<Step>)]) -> Value {
    let mut m = Map::new();
    for (name, steps) in fields {
        m.insert(name.clone(), lookup(v, steps).cloned().unwrap_or(Value::Null));
    }
    Value::Object(m)
}

/// Checks `--fields` against the type's field table.
fn field_paths<T: Reflect>(fields: &[String]) -> Result<Vec<(String, Vec<Step>)>, EchoError> {
    let template = to_json(&T::zeroed());
    let unknown = |path: &str| EchoError::UnknownField {
        type_name: T::TYPE_NAME,
        path: path.to_string(),
        known: T::FIELDS
            .iter()
            .map(|f| f.name)
            .filter(|n| *n != "reserved")
            .collect::<Vec<_>>()
            .join(", "),
    };
    fields
        .iter()
        .map(|f| f.trim())
        .filter(|f| !f.is_empty())
        .map(|f| {
            let steps = parse_path(f).ok_or_else(|| unknown(f))?;
            lookup(&template, &steps).ok_or_else(|| unknown(f))?;
            Ok((f.to_string(), steps))
        })
        .collect()
}

/// Rate measurement over one reporting interval.
#[derive(Debug, Default)]
struct RateWindow {
    n: u64,
    first_host: Option<i64>,
    last_host: i64,
    min_dt: i64,
    max_dt: i64,
    gaps: u64,
    last_seq: Option<u64>,
}

impl RateWindow {
    fn add(&mut self, host_ns: i64, seq: Option<u64>) {
        if self.n > 0 {
            let dt = host_ns - self.last_host;
            if self.n == 1 {
                (self.min_dt, self.max_dt) = (dt, dt);
            } else {
                self.min_dt = self.min_dt.min(dt);
                self.max_dt = self.max_dt.max(dt);
            }
        }
        if let (Some(prev), Some(s)) = (self.last_seq, seq)
            && s > prev + 1
        {
            self.gaps += s - prev - 1;
        }
        self.last_seq = seq;
        self.first_host.get_or_insert(host_ns);
        self.last_host = host_ns;
        self.n += 1;
    }

    /// The report as JSON and resets the window (the sequence carries over).
    fn report(&mut self, service: &str, wall_s: f64) -> Value {
        let span_ns = self.last_host - self.first_host.unwrap_or(self.last_host);
        let mean_ms = (self.n > 1).then(|| span_ns as f64 * 1e-6 / (self.n - 1) as f64);
        let v = serde_json::json!({
            "service": service,
            "rate_hz": self.n as f64 / wall_s.max(1e-9),
            "samples": self.n,
            "stamp_rate_hz": mean_ms.map(|m| 1e3 / m),
            "period_mean_ms": mean_ms,
            "period_min_ms": (self.n > 1).then_some(self.min_dt as f64 * 1e-6),
            "period_max_ms": (self.n > 1).then_some(self.max_dt as f64 * 1e-6),
            "seq_gaps": self.gaps,
        });
        let last_seq = self.last_seq;
        *self = Self {
            last_seq,
            ..Self::default()
        };
        v
    }
}

fn rate_line(v: &Value) -> String {
    let f = |k: &str, d: usize| v[k].as_f64().map_or("-".to_string(), |x| format!("{x:.d$}"));
    format!(
        "{}: {} Hz ({} samples)  stamps: {} Hz, period mean {} ms, min {} ms, max {} ms  seq gaps {}",
        v["service"].as_str().unwrap_or(""),
        f("rate_hz", 2),
        v["samples"],
        f("stamp_rate_hz", 2),
        f("period_mean_ms", 3),
        f("period_min_ms", 3),
        f("period_max_ms", 3),
        v["seq_gaps"]
    )
}

fn echo<T: navsync_shared::ipc::IpcSample>(
    args: &EchoArgs,
    stamp: impl Fn(&T) -> (i64, Option<u64>),
) -> Result<(), EchoError> {
    let fields = field_paths::<T>(&args.fields)?;
    let min_interval = match args.max_rate_hz {
        Some(r) if r.is_finite() && r > 0.0 => Some(Duration::from_secs_f64(1.0 / r)),
        Some(_) => return Err(EchoError::BadRate),
        None => None,
    };
    let node = IpcNode::new(&format!("echo-{}", std::process::id()))?;
    let sub = node.subscriber::<T>(&args.service)?;
    sub.set_busy_poll(args.busy_poll);
    navsync_shared::sd_notify::ready(&format!("echo {}", args.service));
    let mut out = std::io::stdout().lock();
    let mut printed = 0u64;
    let mut last = Instant::now();
    let mut last_print: Option<Instant> = None;
    // A sample held back by --rate, printed when its line is due.
    let mut pending: Option<T> = None;
    let mut window = RateWindow::default();
    let mut window_start = Instant::now();
    let print = |out: &mut std::io::StdoutLock, sample: &T| -> Result<(), EchoError> {
        let mut v = to_json(sample);
        if !args.json && !args.raw {
            name_enums(T::TYPE_NAME, &mut v);
        }
        if fields.is_empty() {
            if args.json {
                writeln!(out, "{v}")?;
            } else {
                writeln!(out, "{}", human(&v))?;
            }
        } else {
            let v = select(&v, &fields);
            if args.json {
                writeln!(out, "{v}")?;
            } else {
                writeln!(out, "{}", human_selected(&v))?;
            }
        }
        Ok(())
    };
    while args.count.is_none_or(|c| printed < c) && !node.termination_requested() {
        let wait = match (args.measure_rate, min_interval, last_print, pending.is_some()) {
            (true, _, _, _) => Duration::from_secs(1).saturating_sub(window_start.elapsed()),
            (false, Some(iv), Some(t), true) => iv.saturating_sub(t.elapsed()),
            _ => Duration::from_millis(200),
        };
        let got = sub.wait_next(wait.max(Duration::from_millis(1)))?;
        if let Some(sample) = got {
            last = Instant::now();
            if args.measure_rate {
                let (h, seq) = stamp(&sample);
                window.add(h, seq);
                // Drain what is buffered right away: the window counts every sample.
                while let Some(s) = sub.receive()? {
                    let (h, seq) = stamp(&s);
                    window.add(h, seq);
                }
            } else {
                pending = Some(sample);
                if min_interval.is_some() {
                    // Only the newest buffered sample can be printed next.
                    while let Some(s) = sub.receive()? {
                        pending = Some(s);
                    }
                }
            }
        } else if args.timeout.is_some_and(|t| last.elapsed() > t) {
            return Err(EchoError::Timeout(args.service.clone()));
        }
        if args.measure_rate {
            let wall = window_start.elapsed();
            if wall >= Duration::from_secs(1) {
                let v = window.report(&args.service, wall.as_secs_f64());
                window_start = Instant::now();
                if args.json {
                    writeln!(out, "{v}")?;
                } else {
                    writeln!(out, "{}", rate_line(&v))?;
                }
                printed += 1;
            }
            continue;
        }
        let due = match (min_interval, last_print) {
            (Some(iv), Some(t)) => t.elapsed() >= iv,
            _ => true,
        };
        if due && let Some(sample) = pending.take() {
            print(&mut out, &sample)?;
            printed += 1;
            last_print = Some(Instant::now());
        }
    }
    Ok(())
}

/// The name of value `v` of an enumerated field: `path` is the field's path with array
/// indices as `[]` (`imu[].reason`), `sample` the sample type's name without its version.
/// `None`: not an enumeration, or a value without a name (printed as its number).
fn enum_name(sample: &str, path: &str, v: u64) -> Option<&'static str> {
    let v = u8::try_from(v).ok()?;
    let named = |name: &'static str| (name != "unknown").then_some(name);
    match (sample, path) {
        (_, "stamp.source") if v <= 7 => Some(StampSource::from_u8(v).name()),
        ("NavState", "status") => named(NavStatus::name(v)),
        ("NavState" | "TimeState", "time_status" | "status") if v <= 5 => Some(TimeStatus::from_u8(v).name()),
        ("NavState" | "TimeState", "imu[].reason") => named(ImuSyncReason::name(v)),
        ("GnssFix", "mode") => ["unknown", "no-fix", "2d", "3d"].get(usize::from(v)).copied(),
        ("GnssFix", "quality") => match v {
            0 => Some("invalid"),
            1 => Some("gps"),
            2 => Some("dgps"),
            3 => Some("pps"),
            4 => Some("rtk-fixed"),
            5 => Some("rtk-float"),
            6 => Some("dead-reckoning"),
            7 => Some("manual"),
            8 => Some("simulation"),
            255 => Some("unknown"),
            _ => None,
        },
        ("GnssFix", "protocol") => match v {
            GNSS_PROTOCOL_NMEA => Some("nmea"),
            GNSS_PROTOCOL_UBX => Some("ubx"),
            GNSS_PROTOCOL_FILE => Some("file"),
            _ => None,
        },
        ("GnssTimePulse", "time_base") => ["gnss", "utc"].get(usize::from(v)).copied(),
        _ => None,
    }
}

/// Replaces the numbers of the enumerated fields of a sample of type `type_name` by their
/// names ([`enum_name`]).
fn name_enums(type_name: &str, v: &mut Value) {
    fn walk(sample: &str, path: &mut String, v: &mut Value) {
        match v {
            Value::Object(m) => {
                for (k, x) in m.iter_mut() {
                    let len = path.len();
                    if !path.is_empty() {
                        path.push('.');
                    }
                    path.push_str(k);
                    walk(sample, path, x);
                    path.truncate(len);
                }
            }
            Value::Array(a) => {
                let len = path.len();
                path.push_str("[]");
                for x in a.iter_mut().filter(|x| x.is_object()) {
                    walk(sample, path, x);
                }
                path.truncate(len);
            }
            Value::Number(n) => {
                if let Some(name) = n.as_u64().and_then(|x| enum_name(sample, path, x)) {
                    *v = Value::String(name.to_string());
                }
            }
            _ => {}
        }
    }
    // `navsync.NavState.v2` → `NavState`.
    let sample = type_name.split('.').nth(1).unwrap_or(type_name);
    walk(sample, &mut String::new(), v);
}

/// The line of `--fields`: every field asked for, in the order asked, `null` when it has no
/// value (the full line leaves unknowns out; a field asked for is never dropped).
fn human_selected(v: &Value) -> String {
    let mut parts = Vec::new();
    if let Value::Object(m) = v {
        for (k, x) in m {
            match x {
                Value::Null => parts.push(format!("{k}=null")),
                Value::String(s) if s.is_empty() => parts.push(format!("{k}=\"\"")),
                _ => {
                    let before = parts.len();
                    flatten(k, x, &mut parts);
                    if parts.len() == before {
                        // An object or array whose every part is empty.
                        parts.push(format!("{k}={x}"));
                    }
                }
            }
        }
    }
    parts.join(" ")
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

    #[test]
    fn field_paths_select_nested_and_indexed_fields() {
        let paths =
            field_paths::<NavState>(&["lat_deg".into(), "vel_ned_mps[2]".into(), "imu[1].offset_s".into()]).unwrap();
        let mut n = NavState::zeroed();
        n.lat_deg = 48.5;
        n.vel_ned_mps[2] = -0.25;
        n.imu[1].offset_s = 0.01;
        let v = select(&to_json(&n), &paths);
        assert_eq!(
            v.to_string(),
            r#"{"lat_deg":48.5,"vel_ned_mps[2]":-0.25,"imu[1].offset_s":0.01}"#
        );
        assert_eq!(human(&v), "lat_deg=48.5 vel_ned_mps[2]=-0.25 imu[1].offset_s=0.01");
        let paths = field_paths::<ImuSample>(&["stamp.host_ns".into()]).unwrap();
        assert_eq!(paths[0].1, vec![Step::Key("stamp".into()), Step::Key("host_ns".into())]);
        for bad in ["lat", "stamp.nope", "vel_ned_mps[3]", "vel_ned_mps[x]", "a..b"] {
            assert!(field_paths::<NavState>(&[bad.into()]).is_err(), "{bad}");
        }
    }

    #[test]
    fn enums_print_as_names_and_asked_for_nulls_as_null() {
        let mut n = NavState::zeroed();
        n.status = NavStatus::Aligned as u8;
        n.time_status = TimeStatus::Locked as u8;
        n.imu_count = 1;
        n.imu[0].reason = ImuSyncReason::Converging as u8;
        n.gnss_delay_s = f64::NAN;
        let mut v = to_json(&n);
        name_enums(NavState::TYPE_NAME, &mut v);
        assert_eq!(v["status"], "aligned");
        assert_eq!(v["time_status"], "locked");
        assert_eq!(v["imu"][0]["reason"], "converging");
        assert_eq!(v["imu_count"], 1, "not an enumeration");
        let line = human(&v);
        assert!(
            line.contains("status=aligned") && line.contains("time_status=locked"),
            "{line}"
        );
        let paths = field_paths::<NavState>(&["status".into(), "gnss_delay_s".into(), "seq".into()]).unwrap();
        assert_eq!(
            human_selected(&select(&v, &paths)),
            "status=aligned gnss_delay_s=null seq=0"
        );
        let mut fix = to_json(&GnssFix::empty(Stamp::host(5, 1, StampSource::KernelPps)));
        name_enums(GnssFix::TYPE_NAME, &mut fix);
        assert_eq!(fix["stamp"]["source"], "kernel-pps");
        // A value without a name stays a number.
        n.status = 200;
        let mut v = to_json(&n);
        name_enums(NavState::TYPE_NAME, &mut v);
        assert_eq!(v["status"], 200);
    }

    #[test]
    fn rate_window_measures_spacing_and_gaps() {
        let mut w = RateWindow::default();
        for (i, seq) in [0u64, 1, 2, 5, 6].iter().enumerate() {
            w.add(1_000_000_000 + i as i64 * 10_000_000, Some(*seq));
        }
        let v = w.report("s", 0.5);
        assert_eq!(v["samples"], 5);
        assert_eq!(v["seq_gaps"], 2);
        assert!((v["rate_hz"].as_f64().unwrap() - 10.0).abs() < 1e-9);
        assert!((v["period_mean_ms"].as_f64().unwrap() - 10.0).abs() < 1e-9);
        assert!((v["stamp_rate_hz"].as_f64().unwrap() - 100.0).abs() < 1e-6);
        // The next window continues the sequence.
        w.add(2_000_000_000, Some(8));
        assert_eq!(w.report("s", 1.0)["seq_gaps"], 1);
    }
}
