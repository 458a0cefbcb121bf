//! Clients on hosts without a local navsync: `navsync echo --zenoh ENDPOINT SERVICE` prints the
//! samples of a service of any instance reachable through Zenoh, `navsync status --zenoh
//! ENDPOINT` lists the instances and services heard there.

use std::collections::BTreeMap;
use std::io::Write;
use std::time::{Duration, Instant};

use navsync_recording::channels::sample_json;
use navsync_shared::samples::AnySample;
use zenoh::Wait;

use crate::bridge::{BridgeError, Mode, SessionSettings};
use crate::wire;

/// A client session connected to `endpoint`.
pub fn client(endpoint: &str) -> Result<zenoh::Session, BridgeError> {
    SessionSettings {
        mode: Some(Mode::Client),
        connect: vec![endpoint.to_string()],
        ..SessionSettings::default()
    }
    .open()
}

/// What `echo --zenoh` does.
#[derive(Debug, Clone)]
pub struct RemoteEcho {
    /// e.g. `tcp/10.0.0.1:7447`.
    pub endpoint: String,
    /// The service, e.g. `navsync/nav/state`.
    pub service: String,
    /// The instance (default: any).
    pub instance: Option<String>,
    /// Stop after this many samples.
    pub count: Option<u64>,
    /// Fail when nothing arrives for this long.
    pub timeout: Option<Duration>,
}

/// Prints one JSON line per sample (`{"instance":…,"seq":…,"sample":{…}}`, the sample as
/// `navsync echo --json` prints it) until `count` or the timeout; refused samples are reported
/// on stderr once per key.
pub fn echo(e: &RemoteEcho, out: &mut impl Write) -> Result<u64, BridgeError> {
    if navsync_shared::services::ServiceKind::of(&e.service).is_none() {
        return Err(BridgeError::Settings(format!(
            "`{}` is not a navsync service",
            e.service
        )));
    }
    let session = client(&e.endpoint)?;
    let key = wire::key_of(e.instance.as_deref().unwrap_or("*"), &e.service);
    let sub = session
        .declare_subscriber(key.clone())
        .with(zenoh::handlers::FifoChannel::new(1024))
        .wait()
        .map_err(|err| BridgeError::Zenoh {
            what: "subscribing",
            detail: err.to_string(),
        })?;
    let mut n = 0u64;
    let mut last = Instant::now();
    let mut warned = std::collections::HashSet::new();
    loop {
        if e.count.is_some_and(|c| n >= c) {
            break;
        }
        if let Ok(Some(sample)) = sub.recv_timeout(Duration::from_millis(200)) {
            {
                let k = sample.key_expr().as_str();
                let payload = sample.payload().to_bytes();
                let att = sample.attachment().map(|a| a.to_bytes());
                match wire::decode(k, &payload, att.as_deref()) {
                    Ok((r, _)) => {
                        let line = serde_json::json!({
                            "instance": r.instance,
                            "seq": r.seq,
                            "sample": sample_json(&r.sample),
                        });
                        writeln!(out, "{line}").map_err(|err| BridgeError::Settings(format!("writing: {err}")))?;
                        n += 1;
                        last = Instant::now();
                    }
                    Err(err) => {
                        if warned.insert(k.to_string()) {
                            eprintln!("echo: {err}");
                        }
                    }
                }
            }
        }
        if let Some(t) = e.timeout
            && last.elapsed() > t
        {
            return Err(BridgeError::Settings(format!(
                "no sample of {} on {key} through {} for {:.1} s",
                e.service,
                e.endpoint,
                t.as_secs_f64()
            )));
        }
    }
    let _ = session.close().wait();
    Ok(n)
}

/// One instance's service as `status --zenoh` heard it.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct Heard {
    /// Samples in the window.
    pub samples: u64,
    /// Samples per second.
    pub rate_hz: f64,
    /// The exporter's sequence gaps (losses) in the window.
    pub lost: u64,
}

/// What `status --zenoh` prints: per instance, per service; and each process's health
/// counters.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct RemoteStatus {
    /// instance → service → heard.
    pub services: BTreeMap<String, BTreeMap<String, Heard>>,
    /// instance → process → counters.
    pub health: BTreeMap<String, BTreeMap<String, BTreeMap<String, u64>>>,
    /// Keys refused (another layout version, not navsync's), with why.
    pub refused: BTreeMap<String, String>,
}

/// Listens on `navsync/**` through `endpoint` for `window`; an error when nothing was heard.
pub fn status(endpoint: &str, window: Duration) -> Result<RemoteStatus, BridgeError> {
    let session = client(endpoint)?;
    let sub = session
        .declare_subscriber("navsync/**")
        .with(zenoh::handlers::FifoChannel::new(65536))
        .wait()
        .map_err(|err| BridgeError::Zenoh {
            what: "subscribing",
            detail: err.to_string(),
        })?;
    let t0 = Instant::now();
    let mut st = RemoteStatus::default();
    let mut gaps = wire::GapCounter::default();
    while t0.elapsed() < window {
        let Ok(Some(sample)) = sub.recv_timeout(Duration::from_millis(50)) else {
            continue;
        };
        let k = sample.key_expr().as_str().to_string();
        let payload = sample.payload().to_bytes();
        let att = sample.attachment().map(|a| a.to_bytes());
        match wire::decode(&k, &payload, att.as_deref()) {
            Ok((r, service)) => {
                let lost = gaps.note(&k, r.seq);
                let h = st
                    .services
                    .entry(r.instance.to_string())
                    .or_default()
                    .entry(service)
                    .or_default();
                h.samples += 1;
                h.lost += lost;
                if let AnySample::Health(x) = r.sample {
                    let counters = x
                        .counters
                        .iter()
                        .map(|c| (navsync_shared::reflect::str_of(&c.name).to_string(), c.value))
                        .filter(|(name, _)| !name.is_empty())
                        .collect();
                    st.health
                        .entry(r.instance.to_string())
                        .or_default()
                        .insert(navsync_shared::reflect::str_of(&x.process).to_string(), counters);
                }
            }
            Err(e) => {
                st.refused.insert(k, e.to_string());
            }
        }
    }
    let s = window.as_secs_f64();
    for services in st.services.values_mut() {
        for h in services.values_mut() {
            h.rate_hz = h.samples as f64 / s;
        }
    }
    let _ = session.close().wait();
    if st.services.is_empty() && st.refused.is_empty() {
        return Err(BridgeError::Settings(format!(
            "nothing heard on navsync/** through {endpoint} in {s:.1} s (is a bridge exporting there?)"
        )));
    }
    Ok(st)
}
