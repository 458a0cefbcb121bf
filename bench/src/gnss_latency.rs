//! `navsync-bench gnss-latency`: how long after the last byte of an epoch a subscriber has the
//! fix, for navsync and for gpsd in the same run.
//!
//! A real receiver capture (gpsd's regression corpora) is cut into its epochs (NMEA: a new
//! time tag in GGA/RMC/GNS/GLL starts one; UBX: a new `iTOW` in a NAV message; everything
//! else belongs to the epoch it follows; the capture's first and last epochs, cut by the
//! recording, are left out) and each epoch is written into a pseudo-terminal in
//! one write, [`GnssLatencyArgs::spacing_s`] apart, the capture looped until
//! [`GnssLatencyArgs::epochs`] have been written. The clock starts right before that write
//! (which puts the epoch's last byte into the terminal within microseconds; a reader woken
//! by the write may answer before `write` has returned to this process) and stops when the
//! subscriber has the fix:
//!
//! - `navsync gnss` → iceoryx2 → this benchmark's helper with the Rust client API
//!   (`Client<GnssFix>`), which stamps each fix with `CLOCK_MONOTONIC` as `next()` returns;
//! - the same fixes → `navsync echo navsync/gnss/{id}/fix --json`, stamped when its line is
//!   read from the pipe;
//! - `gpsd -N -n -b` (read-only) on a second pseudo-terminal fed the same epochs half a
//!   spacing later → TCP (loopback) → `gpspipe -w`, stamped when a TPV line is read.
//!
//! A fix is attributed to the latest epoch written before it arrived (the spacing is longer
//! than any latency measured); a second output for the same epoch is counted as extra, an
//! epoch without one as missing. CPU per epoch: the driver's (and gpsd's) user + system time
//! over the run divided by the epochs written. gpsd is installed with apt when it is missing
//! and the benchmark runs as root; otherwise its rows say why they are empty.

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use navsync_drivers::gnss::ubx::framer::{Frame, UbxFramer, ubx_frame};
use navsync_drivers::pty::Pty;
use navsync_shared::time::monotonic_now_ns;
use serde::Serialize;

use crate::util::{BenchEnv, cpu_time_s, write_json};

/// Settings of `navsync-bench gnss-latency`.
#[derive(Debug, Clone, clap::Args)]
pub struct GnssLatencyArgs {
    /// Captures: paths, or `gpsd-nmea/NAME` / `gpsd-ubx/NAME` in the corpora beside the
    /// checkout (`../shared/corpora`, or `$NAVSYNC_SHARED_DIR/corpora`).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "gpsd-nmea/bu353s4.log,gpsd-nmea/nmea-rtk.log,gpsd-ubx/u-blox-m8t-time.log,gpsd-ubx/ublox-neo-m8n.log,gpsd-ubx/ublox-glo.log"
    )]
    pub captures: Vec<String>,
    /// Epochs written per capture (the capture is looped as needed).
    #[arg(long, default_value_t = 300)]
    pub epochs: usize,
    /// Time between two epochs' writes, s (longer than any latency measured).
    #[arg(long, default_value_t = 0.2)]
    pub spacing_s: f64,
    /// Smoke run: 20 epochs per capture.
    #[arg(long)]
    pub quick: bool,
    /// Leave gpsd out.
    #[arg(long)]
    pub no_gpsd: bool,
    /// Run both chains (navsync gnss, its subscribers; gpsd, gpspipe) under SCHED_FIFO with
    /// this priority (1–99; needs CAP_SYS_NICE) and hold the CPU wake-up latency at 0, as a
    /// deployment would.
    #[arg(long, value_name = "PRIO", value_parser = clap::value_parser!(u8).range(1..=99))]
    pub realtime: Option<u8>,
    /// Write the results as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// One path's latencies on one capture.
#[derive(Debug, Clone, Serialize)]
pub struct PathResult {
    /// Capture file name.
    pub capture: String,
    /// `navsync client`, `navsync echo` or `gpsd gpspipe`.
    pub path: String,
    /// Epochs written.
    pub epochs: usize,
    /// Epochs with an output.
    pub received: usize,
    /// Epochs without.
    pub missing: usize,
    /// Outputs beyond the first for an epoch.
    pub extra: usize,
    /// Latency percentiles after the epoch's last byte, ms (None without outputs).
    pub p50_ms: Option<f64>,
    /// 90th percentile, ms.
    pub p90_ms: Option<f64>,
    /// 99th percentile, ms.
    pub p99_ms: Option<f64>,
    /// Largest, ms.
    pub max_ms: Option<f64>,
    /// CPU time of the driver process (navsync gnss, or gpsd) per epoch, µs.
    pub driver_cpu_us_per_epoch: Option<f64>,
    /// Why the path has no figures, when it has none.
    pub note: Option<String>,
}

/// Errors of the benchmark.
#[derive(Debug, thiserror::Error)]
pub enum GnssLatencyError {
    /// A capture could not be found or read.
    #[error("capture {0}: {1}")]
    Capture(String, String),
    /// A capture has no epoch.
    #[error("capture {0}: no epoch found (neither NMEA time tags nor UBX NAV messages)")]
    NoEpochs(String),
    /// A process or terminal could not be set up.
    #[error("{0}")]
    Setup(String),
    /// A path delivered far fewer fixes than epochs.
    #[error("{0}")]
    TooFew(String),
}

fn setup<E: std::fmt::Display>(what: &str) -> impl FnOnce(E) -> GnssLatencyError + '_ {
    move |e| GnssLatencyError::Setup(format!("{what}: {e}"))
}

/// Where a capture named `gpsd-nmea/NAME` lives.
fn capture_path(spec: &str) -> Result<PathBuf, GnssLatencyError> {
    let p = PathBuf::from(spec);
    if p.is_file() {
        return Ok(p);
    }
    let mut roots: Vec<PathBuf> = Vec::new();
    if let Some(d) = std::env::var_os("NAVSYNC_SHARED_DIR") {
        roots.push(PathBuf::from(d).join("corpora"));
    }
    roots.push(PathBuf::from("../shared/corpora"));
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    roots.push(manifest.join("../../shared/corpora"));
    for r in &roots {
        let c = r.join(spec);
        if c.is_file() {
            return Ok(c);
        }
    }
    Err(GnssLatencyError::Capture(
        spec.into(),
        format!("not a file, and not in {roots:?} (set NAVSYNC_SHARED_DIR)"),
    ))
}

/// The receiver's bytes of a gpsd capture: after its leading `#` lines.
fn receiver_bytes(bytes: &[u8]) -> &[u8] {
    let (header, _) = navsync_drivers::gnss::capture::gpsd_header(bytes);
    bytes.get(header..).unwrap_or(&[])
}

/// The time tag of an NMEA sentence (`hhmmss.ss` of GGA, RMC, GNS, GLL), as text.
fn nmea_time(line: &[u8]) -> Option<&[u8]> {
    let s = line.strip_prefix(b"$")?;
    let kind = s.get(2..5)?;
    let field = match kind {
        b"GGA" | b"RMC" | b"GNS" => 1,
        b"GLL" => 5,
        _ => return None,
    };
    let t = s.split(|&b| b == b',' || b == b'*').nth(field)?;
    (!t.is_empty()).then_some(t)
}

/// Cuts a capture into epochs (see the module doc). UBX when it holds UBX frames, else NMEA.
pub fn epochs_of(bytes: &[u8]) -> Vec<Vec<u8>> {
    let bytes = receiver_bytes(bytes);
    let mut framer = UbxFramer::new();
    // (bytes, NAV iTOW or NMEA time tag) per frame, in stream order.
    let mut frames: Vec<(Vec<u8>, Option<Vec<u8>>, bool)> = Vec::new();
    framer.push(bytes, 0, 0, &mut |f| match f {
        Frame::Ubx { class, id, payload, .. } => {
            let itow = (class == 0x01 && payload.len() >= 4).then(|| payload[..4].to_vec());
            frames.push((ubx_frame(class, id, payload), itow, true));
        }
        Frame::Nmea { text, .. } => {
            let mut b = text.to_vec();
            b.extend_from_slice(b"\r\n");
            frames.push((b, nmea_time(text).map(<[u8]>::to_vec), false));
        }
        Frame::Rtcm3 { .. } => {}
    });
    let ubx = frames.iter().any(|f| f.2 && f.1.is_some());
    let mut out: Vec<Vec<u8>> = Vec::new();
    let mut current: Option<Vec<u8>> = None;
    for (b, tag, is_ubx) in frames {
        let tag = if is_ubx == ubx { tag } else { None };
        if let Some(t) = tag
            && current.as_ref() != Some(&t)
        {
            if current.is_some() || out.is_empty() {
                out.push(Vec::new());
            }
            current = Some(t);
        }
        match out.last_mut() {
            Some(e) => e.extend_from_slice(&b),
            None => out.push(b),
        }
    }
    out
}

/// Lines of a child's stdout with the `CLOCK_MONOTONIC` time each was read, collected by a
/// thread of their own.
type Lines = Arc<Mutex<Vec<(i64, String)>>>;

fn collect_lines(out: impl Read + Send + 'static) -> Lines {
    let lines: Lines = Arc::new(Mutex::new(Vec::new()));
    let l = lines.clone();
    std::thread::spawn(move || {
        let mut r = BufReader::new(out);
        let mut buf = String::new();
        while matches!(r.read_line(&mut buf), Ok(n) if n > 0) {
            let t = monotonic_now_ns();
            if let Ok(mut v) = l.lock() {
                v.push((t, buf.trim_end().to_string()));
            }
            buf.clear();
        }
    });
    lines
}

/// Latencies of outputs at `arrivals` (ns) after the writes at `writes` (ns, ascending).
fn attribute(capture: &str, path: &str, writes: &[i64], arrivals: &[i64]) -> PathResult {
    let mut first: Vec<Option<i64>> = vec![None; writes.len()];
    let mut extra = 0;
    for &a in arrivals {
        let k = writes.partition_point(|&w| w <= a);
        if k == 0 {
            continue; // before the first epoch: left over from a previous capture
        }
        match &mut first[k - 1] {
            Some(_) => extra += 1,
            slot => *slot = Some(a - writes[k - 1]),
        }
    }
    let mut lat: Vec<f64> = first.iter().flatten().map(|&d| d as f64 * 1e-6).collect();
    lat.sort_by(f64::total_cmp);
    let q = |p: f64| (!lat.is_empty()).then(|| lat[((p * lat.len() as f64).ceil() as usize).clamp(1, lat.len()) - 1]);
    PathResult {
        capture: capture.into(),
        path: path.into(),
        epochs: writes.len(),
        received: lat.len(),
        missing: writes.len() - lat.len(),
        extra,
        p50_ms: q(0.5),
        p90_ms: q(0.9),
        p99_ms: q(0.99),
        max_ms: lat.last().copied(),
        driver_cpu_us_per_epoch: None,
        note: None,
    }
}

/// A child that is killed (and reaped) when dropped.
struct Killed(Child);

impl Drop for Killed {
    fn drop(&mut self) {
        // SAFETY: signalling our own child by pid.
        unsafe { libc::kill(self.0.id() as libc::pid_t, libc::SIGTERM) };
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(3) {
            if let Ok(Some(_)) = self.0.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The gpsd binary, installed with apt when missing and possible; Err says why not.
fn gpsd_binary() -> Result<PathBuf, String> {
    let find = || {
        ["/usr/sbin/gpsd", "/usr/bin/gpsd", "/usr/local/sbin/gpsd"]
            .iter()
            .map(PathBuf::from)
            .find(|p| p.exists())
    };
    let have_gpspipe = || Command::new("gpspipe").arg("-V").output().is_ok();
    if let (Some(p), true) = (find(), have_gpspipe()) {
        return Ok(p);
    }
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        return Err("gpsd or gpspipe missing and not root: apt-get install gpsd gpsd-clients".into());
    }
    eprintln!("gnss-latency: installing gpsd and gpsd-clients with apt-get");
    let st = Command::new("apt-get")
        .args(["install", "-y", "-q", "--no-install-recommends", "gpsd", "gpsd-clients"])
        .env("DEBIAN_FRONTEND", "noninteractive")
        .stdout(Stdio::null())
        .status();
    match (st, find(), have_gpspipe()) {
        (Ok(s), Some(p), true) if s.success() => Ok(p),
        (st, ..) => Err(format!("apt-get install gpsd gpsd-clients failed ({st:?})")),
    }
}

/// A free loopback TCP port.
fn free_port() -> std::io::Result<u16> {
    Ok(std::net::TcpListener::bind("127.0.0.1:0")?.local_addr()?.port())
}

/// Runs the benchmark on one capture.
fn run_capture(
    args: &GnssLatencyArgs,
    spec: &str,
    gpsd: &Result<PathBuf, String>,
    n_epochs: usize,
) -> Result<Vec<PathResult>, GnssLatencyError> {
    let path = capture_path(spec)?;
    let name = path
        .file_name()
        .map_or(spec.into(), |n| n.to_string_lossy().to_string());
    let bytes = std::fs::read(&path).map_err(|e| GnssLatencyError::Capture(spec.into(), e.to_string()))?;
    let mut epochs = epochs_of(&bytes);
    // A capture starts and ends mid-epoch: looped, its partial first and last epochs would be
    // cycles the receiver never sent.
    if epochs.len() > 4 {
        epochs = epochs[1..epochs.len() - 1].to_vec();
    }
    if epochs.is_empty() {
        return Err(GnssLatencyError::NoEpochs(name));
    }
    let mut env = BenchEnv::new("gnsslat").map_err(setup("bench environment"))?;
    let id = "lat";
    let service = navsync_shared::services::gnss_fix(id);

    // navsync: driver, the client helper, echo.
    let link = env.dir.join("rx-navsync");
    let mut pty = Pty::open(Some(&link)).map_err(setup("pseudo-terminal"))?;
    let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<String>>();
    let (client_pid, client_out) = env
        .spawn("client", &s(&["helper", "gnss-sub", "--service", &service]), true)
        .map_err(setup("client helper"))?;
    let (echo_pid, echo_out) = env
        .spawn("echo", &s(&["echo", &service, "--json"]), true)
        .map_err(setup("navsync echo"))?;
    let (gnss_pid, _) = env
        .spawn(
            "gnss",
            &s(&[
                "gnss",
                "--port",
                &link.display().to_string(),
                "--baud",
                "115200",
                "--protocol",
                "auto",
                "--id",
                id,
            ]),
            false,
        )
        .map_err(setup("navsync gnss"))?;
    let mut fifo: Vec<(u32, u8)> = Vec::new();
    if let Some(p) = args.realtime {
        let below = p.saturating_sub(1).max(1);
        fifo.extend([(gnss_pid, p), (client_pid, below), (echo_pid, below)]);
    }
    let client_lines = collect_lines(client_out.ok_or_else(|| GnssLatencyError::Setup("client stdout".into()))?);
    let echo_lines = collect_lines(echo_out.ok_or_else(|| GnssLatencyError::Setup("echo stdout".into()))?);

    // gpsd on a second terminal.
    let mut gpsd_side = None;
    let mut gpsd_note = None;
    if args.no_gpsd {
        gpsd_note = Some("--no-gpsd".to_string());
    } else {
        match gpsd {
            Err(why) => gpsd_note = Some(why.clone()),
            Ok(bin) => {
                let glink = env.dir.join("rx-gpsd");
                let gpty = Pty::open(Some(&glink)).map_err(setup("pseudo-terminal"))?;
                let port = free_port().map_err(setup("loopback port"))?.to_string();
                let d = Command::new(bin)
                    .args(["-N", "-n", "-b", "-S", &port, "-F"])
                    .arg(env.dir.join("gpsd.sock"))
                    .arg(&glink)
                    .stdout(Stdio::null())
                    .stderr(Stdio::null())
                    .spawn()
                    .map_err(setup("gpsd"))?;
                let d = Killed(d);
                std::thread::sleep(Duration::from_millis(300));
                let mut p = Command::new("gpspipe")
                    .args(["-w", &format!("127.0.0.1:{port}")])
                    .stdout(Stdio::piped())
                    .stderr(Stdio::null())
                    .spawn()
                    .map_err(setup("gpspipe"))?;
                let lines = collect_lines(
                    p.stdout
                        .take()
                        .ok_or_else(|| GnssLatencyError::Setup("gpspipe stdout".into()))?,
                );
                if let Some(prio) = args.realtime {
                    fifo.extend([(d.0.id(), prio), (p.id(), prio.saturating_sub(1).max(1))]);
                }
                gpsd_side = Some((gpty, d, Killed(p), lines));
            }
        }
    }

    for (pid, prio) in fifo {
        crate::util::set_fifo(pid, prio).map_err(setup("SCHED_FIFO (needs CAP_SYS_NICE)"))?;
    }
    // Wait until the subscribers are there (the helper prints "ready").
    let t0 = Instant::now();
    while !client_lines
        .lock()
        .map(|v| v.iter().any(|(_, l)| l == "ready"))
        .unwrap_or(false)
    {
        env.check_running().map_err(GnssLatencyError::Setup)?;
        if t0.elapsed() > Duration::from_secs(20) {
            return Err(GnssLatencyError::Setup(format!(
                "client helper not ready:\n{}",
                env.log("client")
            )));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(500));

    // Warm-up: a few epochs that are not measured (the decoders learn the cycle, gpsd its
    // device), then the measured ones.
    let warmup = 5.min(epochs.len());
    let spacing = Duration::from_secs_f64(args.spacing_s);
    let cpu0 = (
        cpu_time_s(gnss_pid),
        gpsd_side.as_ref().and_then(|g| cpu_time_s(g.1.0.id())),
    );
    let mut writes = Vec::new();
    let mut gwrites = Vec::new();
    let mut cpu_start = cpu0;
    let mut next = Instant::now();
    for k in 0..warmup + n_epochs {
        if k == warmup {
            cpu_start = (
                cpu_time_s(gnss_pid),
                gpsd_side.as_ref().and_then(|g| cpu_time_s(g.1.0.id())),
            );
        }
        let e = &epochs[k % epochs.len()];
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
        next += spacing;
        let t = monotonic_now_ns();
        pty.write(e).map_err(setup("writing the epoch"))?;
        if k >= warmup {
            writes.push(t);
        }
        if let Some(g) = &mut gpsd_side {
            std::thread::sleep(spacing / 2);
            let t = monotonic_now_ns();
            g.0.write(e).map_err(setup("writing the epoch for gpsd"))?;
            if k >= warmup {
                gwrites.push(t);
            }
        }
        if k % 20 == 0 {
            env.check_running().map_err(GnssLatencyError::Setup)?;
        }
    }
    std::thread::sleep(spacing.max(Duration::from_millis(200)));
    let cpu_end = (
        cpu_time_s(gnss_pid),
        gpsd_side.as_ref().and_then(|g| cpu_time_s(g.1.0.id())),
    );
    let per_epoch = |a: Option<f64>, b: Option<f64>| Some((b? - a?) * 1e6 / n_epochs as f64);

    let mut results = Vec::new();
    let client: Vec<i64> = client_lines
        .lock()
        .map(|v| v.iter().filter_map(|(_, l)| l.parse::<i64>().ok()).collect())
        .unwrap_or_default();
    let mut r = attribute(&name, "navsync client", &writes, &client);
    r.driver_cpu_us_per_epoch = per_epoch(cpu_start.0, cpu_end.0);
    results.push(r);
    let echo: Vec<i64> = echo_lines
        .lock()
        .map(|v| v.iter().filter(|(_, l)| l.starts_with('{')).map(|(t, _)| *t).collect())
        .unwrap_or_default();
    results.push(attribute(&name, "navsync echo", &writes, &echo));
    match gpsd_side {
        Some((_, _, _, lines)) => {
            let tpv: Vec<i64> = lines
                .lock()
                .map(|v| {
                    v.iter()
                        .filter(|(_, l)| l.contains("\"class\":\"TPV\""))
                        .map(|(t, _)| *t)
                        .collect()
                })
                .unwrap_or_default();
            let mut r = attribute(&name, "gpsd gpspipe", &gwrites, &tpv);
            r.driver_cpu_us_per_epoch = per_epoch(cpu_start.1, cpu_end.1);
            results.push(r);
        }
        None => results.push(PathResult {
            capture: name.clone(),
            path: "gpsd gpspipe".into(),
            epochs: 0,
            received: 0,
            missing: 0,
            extra: 0,
            p50_ms: None,
            p90_ms: None,
            p99_ms: None,
            max_ms: None,
            driver_cpu_us_per_epoch: None,
            note: gpsd_note,
        }),
    }
    let bad = env.stop_all();
    if !bad.is_empty() {
        return Err(GnssLatencyError::Setup(format!("{bad:?} did not exit cleanly")));
    }
    Ok(results)
}

fn ms(v: Option<f64>) -> String {
    v.map_or("-".into(), |x| format!("{x:.2}"))
}

/// Runs the benchmark and prints its table; fails when navsync delivered fewer than 90 % of
/// the epochs of a capture (never silent).
pub fn run(args: &GnssLatencyArgs) -> Result<Vec<PathResult>, GnssLatencyError> {
    let n = if args.quick { 20 } else { args.epochs.max(1) };
    let mut machine = crate::util::Machine::now();
    let _wakeup = crate::util::wakeup_hold_for_realtime(args.realtime, &mut machine);
    let gpsd = if args.no_gpsd {
        Err("--no-gpsd".into())
    } else {
        gpsd_binary()
    };
    if let Err(why) = &gpsd {
        eprintln!("gnss-latency: gpsd left out: {why}");
    }
    let mut all = Vec::new();
    println!(
        "{:<24} {:<15} {:>6} {:>8} {:>5} {:>8} {:>8} {:>8} {:>8} {:>12}",
        "capture", "path", "epochs", "received", "extra", "p50 ms", "p90 ms", "p99 ms", "max ms", "CPU µs/epoch"
    );
    for spec in &args.captures {
        let rows = run_capture(args, spec, &gpsd, n)?;
        for r in &rows {
            println!(
                "{:<24} {:<15} {:>6} {:>8} {:>5} {:>8} {:>8} {:>8} {:>8} {:>12}{}",
                r.capture,
                r.path,
                r.epochs,
                r.received,
                r.extra,
                ms(r.p50_ms),
                ms(r.p90_ms),
                ms(r.p99_ms),
                ms(r.max_ms),
                r.driver_cpu_us_per_epoch.map_or("-".into(), |c| format!("{c:.0}")),
                r.note.as_ref().map_or(String::new(), |n| format!("  ({n})"))
            );
            if r.path.starts_with("navsync") && (r.received as f64) < 0.9 * r.epochs as f64 {
                return Err(GnssLatencyError::TooFew(format!(
                    "{}: {} delivered {} fixes for {} epochs",
                    r.capture, r.path, r.received, r.epochs
                )));
            }
        }
        all.extend(rows);
    }
    if let Some(p) = &args.json {
        write_json(p, &all).map_err(setup("writing the JSON"))?;
    }
    Ok(all)
}

/// `navsync-bench helper gnss-sub`: prints "ready", then the `CLOCK_MONOTONIC` time (ns) at
/// which each fix on `service` was received, one per line, until SIGTERM.
pub fn helper_sub(service: &str) -> Result<(), navsync_shared::client::ClientError> {
    use std::io::Write;
    let mut c = navsync_shared::client::Client::<navsync_shared::samples::GnssFix>::connect_to(service)?;
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "ready");
    let _ = out.flush();
    while !c.termination_requested() {
        if c.next(Duration::from_millis(200))?.is_some() {
            let t = monotonic_now_ns();
            let _ = writeln!(out, "{t}");
            let _ = out.flush();
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nmea_epochs_split_on_time_tags() {
        // The framer drops sentences with wrong checksums: build valid ones.
        let fix = |body: &str| {
            let sum = body.bytes().fold(0u8, |c, b| c ^ b);
            format!("${body}*{sum:02X}\r\n")
        };
        let s = [
            "GPGGA,120000.00,4807.0,N,01131.0,E,1,08,0.9,545.4,M,46.9,M,,",
            "GPGSV,1,1,01,05,40,083,46",
            "GPRMC,120000.00,A,4807.0,N,01131.0,E,0.0,0.0,010126,,",
            "GPGGA,120001.00,4807.0,N,01131.0,E,1,08,0.9,545.4,M,46.9,M,,",
            "GPRMC,120001.00,A,4807.0,N,01131.0,E,0.0,0.0,010126,,",
        ]
        .map(fix)
        .concat();
        let e = epochs_of(format!("# a capture\n{s}").as_bytes());
        assert_eq!(e.len(), 2);
        assert_eq!(String::from_utf8_lossy(&e[0]).matches('$').count(), 3);
        assert!(e[1].starts_with(b"$GPGGA,120001.00"));
    }

    #[test]
    fn ubx_epochs_split_on_itow() {
        let nav = |itow: u32, id: u8| ubx_frame(0x01, id, &[itow.to_le_bytes().to_vec(), vec![0; 12]].concat());
        let tp = ubx_frame(0x0D, 0x01, &[0; 16]);
        let s = [
            nav(1000, 7),
            nav(1000, 0x61),
            tp.clone(),
            nav(2000, 7),
            tp,
            nav(2000, 0x61),
        ]
        .concat();
        let e = epochs_of(&s);
        assert_eq!(e.len(), 2);
        assert_eq!(e[0].len(), 2 * 24 + 24);
    }

    #[test]
    fn outputs_are_attributed_to_the_latest_write() {
        let r = attribute("c", "p", &[100, 200, 300], &[50, 150, 160, 310]);
        assert_eq!((r.received, r.missing, r.extra), (2, 1, 1));
        assert!((r.max_ms.unwrap() - 50e-6).abs() < 1e-12, "{:?}", r.max_ms);
    }
}
