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
//! - the same fixes → `navsync gpsd-server --report fix` → TCP (loopback) → `gpspipe -w`,
//!   stamped when a TPV line is read: navsync as a drop-in for gpsd;
//! - `gpsd -N -n -b` (read-only) on a second pseudo-terminal fed the same epochs half a
//!   spacing later → TCP (loopback) → `gpspipe -w`, stamped when a TPV line is read;
//! - the machine's floor, on a third terminal fed a quarter spacing after navsync's: a bare
//!   reader process (`helper pty-read`, a blocking `read(2)`, no decoding) stamps the read that
//!   completes the epoch ("floor: 1 wake-up": what any daemon pays before it can decode), and
//!   this benchmark stamps the line in which the reader reports it ("floor: 2 wake-ups": the
//!   least any daemon-plus-subscriber design pays; navsync's client path has two wake-ups,
//!   pty → driver → subscriber, the echo and gpspipe paths three).
//!
//! A fix is attributed to the latest epoch written before it arrived (the spacing is longer
//! than any latency measured); a second output for the same epoch is counted as extra, an
//! epoch without one as missing. A capture shorter than the run is looped: at each lap its time
//! goes back, and the driver holds back the first epochs of the new lap (its epochs' times
//! strictly increase; `*_not_after_last`) until the time line restarts, so a looped run counts
//! up to 3 missing epochs per lap. CPU per epoch: the driver's (and gpsd's) user + system time
//! over the run divided by the epochs written. gpsd is installed with apt when it is missing
//! and the benchmark runs as root; otherwise its rows say why they are empty.

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use navsync_drivers::gnss::ubx::framer::{Frame, UbxFramer, ubx_frame};
use navsync_drivers::pty::Pty;
use navsync_shared::time::monotonic_now_ns;
use serde::Serialize;

use crate::util::{BenchEnv, StopOnDrop, cpu_time_s, write_json};

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
    /// Smoke run: 15 epochs per capture (after the 5 of the warm-up: no lap of the shortest
    /// shared capture, 24 epochs).
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
    /// CPU time of the path's daemon processes per epoch, µs: navsync gnss (with
    /// gpsd-server on that path), or gpsd; none for the floor.
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

/// Per epoch written (`sizes`, bytes, in order), the stamp of the reader's report whose
/// running byte count completes it; `reads` are `(stamp ns, bytes)` in order.
fn completions(sizes: &[usize], reads: &[(i64, usize)]) -> Vec<i64> {
    let mut out = Vec::with_capacity(sizes.len());
    let (mut got, mut end, mut last) = (0usize, 0usize, 0i64);
    let mut reads = reads.iter();
    'epochs: for &n in sizes {
        end += n;
        while got < end {
            let Some(&(t, k)) = reads.next() else { break 'epochs };
            got += k;
            last = t;
        }
        out.push(last);
    }
    out
}

/// A free loopback TCP port.
fn free_port() -> std::io::Result<u16> {
    Ok(std::net::TcpListener::bind("127.0.0.1:0")?.local_addr()?.port())
}

/// What a lane measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum LaneKind {
    /// `navsync gnss` → the Rust client (`helper gnss-sub`).
    Client,
    /// `navsync gnss` → `navsync echo --json`.
    Echo,
    /// `navsync gnss` → `navsync gpsd-server --report fix` → `gpspipe -w`.
    Server,
    /// `gpsd` → `gpspipe -w`.
    Gpsd,
    /// A bare reader (`helper pty-read`).
    Floor,
}

/// One measured path: a terminal of its own and the processes behind it. Lanes are written
/// one after the other within each spacing, so no two paths compete for the CPUs.
struct Lane {
    kind: LaneKind,
    pty: Pty,
    /// Stamps of the measured writes, ns.
    writes: Vec<i64>,
    /// Sizes of every epoch written (warm-up included), bytes.
    sizes: Vec<usize>,
    /// The output lines, stamped as read by this process.
    lines: Lines,
    /// The daemon processes whose CPU time is the path's.
    cpu_pids: Vec<u32>,
    cpu_start: Option<f64>,
}

impl Lane {
    fn cpu_s(&self) -> Option<f64> {
        self.cpu_pids.iter().map(|&p| cpu_time_s(p)).sum()
    }
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
    let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<String>>();
    let below = |p: u8| p.saturating_sub(1).max(1);
    // Processes outside the BenchEnv (not navsync): killed when the run ends.
    let mut others: Vec<StopOnDrop> = Vec::new();
    let mut fifo: Vec<(u32, u8)> = Vec::new();
    let mut lanes: Vec<Lane> = Vec::new();
    // Lanes left out, with the reason (their rows say it).
    let mut skipped: Vec<(&str, String)> = Vec::new();
    let have_gpspipe = Command::new("gpspipe").arg("-V").output().is_ok();
    // gpspipe clients to start once the servers listen: (lane index, port).
    let mut pipes: Vec<(usize, String)> = Vec::new();

    for kind in [
        LaneKind::Client,
        LaneKind::Echo,
        LaneKind::Server,
        LaneKind::Gpsd,
        LaneKind::Floor,
    ] {
        let tag = format!("{kind:?}").to_lowercase();
        let link = env.dir.join(format!("rx-{tag}"));
        let port = link.display().to_string();
        let mut cpu_pids = Vec::new();
        let mut out = None;
        match kind {
            LaneKind::Server if !have_gpspipe => {
                skipped.push((
                    "navsync gpsd-server",
                    "gpspipe missing: apt-get install gpsd-clients".into(),
                ));
            }
            LaneKind::Client | LaneKind::Echo | LaneKind::Server => {
                let id = format!("lat-{tag}");
                let service = navsync_shared::services::gnss_fix(&id);
                let pty = Pty::open(Some(&link)).map_err(setup("pseudo-terminal"))?;
                let (gnss_pid, _) = env
                    .spawn(
                        &format!("gnss-{tag}"),
                        &s(&[
                            "gnss",
                            "--port",
                            &port,
                            "--baud",
                            "115200",
                            "--protocol",
                            "auto",
                            "--id",
                            &id,
                        ]),
                        false,
                    )
                    .map_err(setup("navsync gnss"))?;
                cpu_pids.push(gnss_pid);
                let (sub_pid, sub_out) = match kind {
                    LaneKind::Client => env
                        .spawn("client", &s(&["helper", "gnss-sub", "--service", &service]), true)
                        .map_err(setup("client helper"))?,
                    LaneKind::Echo => env
                        .spawn("echo", &s(&["echo", &service, "--json"]), true)
                        .map_err(setup("navsync echo"))?,
                    _ => {
                        let tcp = free_port().map_err(setup("loopback port"))?.to_string();
                        let (pid, _) = env
                            .spawn(
                                "gpsd-server",
                                &s(&[
                                    "gpsd-server",
                                    "--listen",
                                    &format!("127.0.0.1:{tcp}"),
                                    "--report",
                                    "fix",
                                    "--gnss-id",
                                    &id,
                                ]),
                                false,
                            )
                            .map_err(setup("navsync gpsd-server"))?;
                        cpu_pids.push(pid);
                        pipes.push((lanes.len(), tcp));
                        (pid, None)
                    }
                };
                if let Some(p) = args.realtime {
                    fifo.extend([(gnss_pid, p), (sub_pid, below(p))]);
                }
                let lines = match sub_out {
                    Some(o) => collect_lines(o),
                    None => Lines::default(),
                };
                out = Some((pty, lines));
            }
            LaneKind::Gpsd => match (args.no_gpsd, gpsd) {
                (true, _) => skipped.push(("gpsd gpspipe", "--no-gpsd".to_string())),
                (_, Err(why)) => skipped.push(("gpsd gpspipe", why.clone())),
                (false, Ok(bin)) => {
                    let pty = Pty::open(Some(&link)).map_err(setup("pseudo-terminal"))?;
                    let tcp = free_port().map_err(setup("loopback port"))?.to_string();
                    let d = Command::new(bin)
                        .args(["-N", "-n", "-b", "-S", &tcp, "-F"])
                        .arg(env.dir.join("gpsd.sock"))
                        .arg(&link)
                        .stdout(Stdio::null())
                        .stderr(Stdio::null())
                        .spawn()
                        .map_err(setup("gpsd"))?;
                    cpu_pids.push(d.id());
                    if let Some(p) = args.realtime {
                        fifo.push((d.id(), p));
                    }
                    others.push(StopOnDrop(d));
                    pipes.push((lanes.len(), tcp));
                    out = Some((pty, Lines::default()));
                }
            },
            LaneKind::Floor => {
                let pty = Pty::open(Some(&link)).map_err(setup("pseudo-terminal"))?;
                let mut r = env
                    .command(&s(&["helper", "pty-read", "--port", &port]))
                    .map_err(setup("floor reader"))?
                    .stdout(Stdio::piped())
                    .stderr(Stdio::null())
                    .spawn()
                    .map_err(setup("floor reader"))?;
                let o = r.stdout.take();
                if let Some(p) = args.realtime {
                    fifo.push((r.id(), p));
                }
                others.push(StopOnDrop(r));
                let o = o.ok_or_else(|| GnssLatencyError::Setup("floor reader stdout".into()))?;
                out = Some((pty, collect_lines(o)));
            }
        }
        if let Some((pty, lines)) = out {
            lanes.push(Lane {
                kind,
                pty,
                writes: Vec::new(),
                sizes: Vec::new(),
                lines,
                cpu_pids,
                cpu_start: None,
            });
        }
    }
    for (pid, prio) in fifo {
        crate::util::set_fifo(pid, prio).map_err(setup("SCHED_FIFO (needs CAP_SYS_NICE)"))?;
    }
    // Wait until the subscribers are there (the client helper prints "ready"), then connect
    // gpspipe to navsync's gpsd-server and to gpsd.
    let ready = |l: &Lines| l.lock().map(|v| v.iter().any(|(_, x)| x == "ready")).unwrap_or(false);
    let t0 = Instant::now();
    while !lanes
        .iter()
        .filter(|l| l.kind == LaneKind::Client)
        .all(|l| ready(&l.lines))
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
    for (i, tcp) in pipes {
        let mut p = Command::new("gpspipe")
            .args(["-w", &format!("127.0.0.1:{tcp}")])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .map_err(setup("gpspipe"))?;
        let o = p
            .stdout
            .take()
            .ok_or_else(|| GnssLatencyError::Setup("gpspipe stdout".into()))?;
        lanes[i].lines = collect_lines(o);
        if let Some(prio) = args.realtime {
            crate::util::set_fifo(p.id(), below(prio)).map_err(setup("SCHED_FIFO (needs CAP_SYS_NICE)"))?;
        }
        others.push(StopOnDrop(p));
    }
    std::thread::sleep(Duration::from_millis(300));

    // Warm-up: a few epochs that are not measured (the decoders learn the cycle, gpsd its
    // device), then the measured ones; each epoch goes to every lane in turn, a slot apart.
    let warmup = 5.min(epochs.len());
    let spacing = Duration::from_secs_f64(args.spacing_s);
    let slot = spacing / lanes.len() as u32;
    let mut next = Instant::now();
    for k in 0..warmup + n_epochs {
        if k == warmup {
            for l in &mut lanes {
                l.cpu_start = l.cpu_s();
            }
        }
        let e = &epochs[k % epochs.len()];
        for (i, l) in lanes.iter_mut().enumerate() {
            std::thread::sleep((next + slot * i as u32).saturating_duration_since(Instant::now()));
            let t = monotonic_now_ns();
            l.pty.write(e).map_err(setup("writing the epoch"))?;
            l.sizes.push(e.len());
            if k >= warmup {
                l.writes.push(t);
            }
        }
        next += spacing;
        if k % 20 == 0 {
            env.check_running().map_err(GnssLatencyError::Setup)?;
        }
    }
    std::thread::sleep(spacing.max(Duration::from_millis(200)));

    let mut results = Vec::new();
    for l in &lanes {
        let cpu = l.cpu_start.zip(l.cpu_s()).map(|(a, b)| (b - a) * 1e6 / n_epochs as f64);
        let stamps = |f: &dyn Fn(&(i64, String)) -> Option<i64>| -> Vec<i64> {
            l.lines
                .lock()
                .map(|v| v.iter().filter_map(f).collect())
                .unwrap_or_default()
        };
        let mut row = |path: &str, arrivals: &[i64], cpu: Option<f64>| {
            let mut r = attribute(&name, path, &l.writes, arrivals);
            r.driver_cpu_us_per_epoch = cpu;
            results.push(r);
        };
        match l.kind {
            LaneKind::Client => row("navsync client", &stamps(&|(_, x)| x.parse().ok()), cpu),
            LaneKind::Echo => row("navsync echo", &stamps(&|(t, x)| x.starts_with('{').then_some(*t)), cpu),
            LaneKind::Server => row("navsync gpsd-server", &tpv_times(&l.lines), cpu),
            LaneKind::Gpsd => row("gpsd gpspipe", &tpv_times(&l.lines), cpu),
            LaneKind::Floor => {
                // The reader's own stamps (1 wake-up) and this process's (2 wake-ups).
                let reads: Vec<((i64, i64), usize)> = l
                    .lines
                    .lock()
                    .map(|v| {
                        v.iter()
                            .filter_map(|(bench_t, x)| {
                                let (t, n) = x.split_once(' ')?;
                                Some(((t.parse().ok()?, *bench_t), n.parse().ok()?))
                            })
                            .collect()
                    })
                    .unwrap_or_default();
                for (path, second) in [("floor: 1 wake-up", false), ("floor: 2 wake-ups", true)] {
                    let stamped: Vec<(i64, usize)> = reads
                        .iter()
                        .map(|&((a, b), n)| (if second { b } else { a }, n))
                        .collect();
                    let done = completions(&l.sizes, &stamped);
                    row(path, done.get(warmup..).unwrap_or(&[]), None);
                }
            }
        }
    }
    for (path, why) in skipped {
        results.push(empty_row(&name, path, Some(why)));
    }
    drop(others);
    let bad = env.stop_all();
    if !bad.is_empty() {
        return Err(GnssLatencyError::Setup(format!("{bad:?} did not exit cleanly")));
    }
    Ok(results)
}

/// The stamps of the TPV lines gpspipe printed.
fn tpv_times(lines: &Lines) -> Vec<i64> {
    lines
        .lock()
        .map(|v| {
            v.iter()
                .filter(|(_, l)| l.contains("\"class\":\"TPV\""))
                .map(|(t, _)| *t)
                .collect()
        })
        .unwrap_or_default()
}

/// A row without figures, saying why.
fn empty_row(capture: &str, path: &str, note: Option<String>) -> PathResult {
    PathResult {
        capture: capture.into(),
        path: path.into(),
        epochs: 0,
        received: 0,
        missing: 0,
        extra: 0,
        p50_ms: None,
        p90_ms: None,
        p99_ms: None,
        max_ms: None,
        driver_cpu_us_per_epoch: None,
        note,
    }
}

fn ms(v: Option<f64>) -> String {
    v.map_or("-".into(), |x| format!("{x:.2}"))
}

/// Runs the benchmark and prints its table; fails when navsync delivered fewer than 90 % of
/// the epochs of a capture (never silent).
pub fn run(args: &GnssLatencyArgs) -> Result<Vec<PathResult>, GnssLatencyError> {
    let n = if args.quick { 15 } else { args.epochs.max(1) };
    let mut machine = crate::util::Machine::now();
    let _wakeup = crate::util::wakeup_hold(args.realtime.is_some(), &mut machine);
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
        "{:<24} {:<19} {:>6} {:>8} {:>5} {:>8} {:>8} {:>8} {:>8} {:>12}",
        "capture", "path", "epochs", "received", "extra", "p50 ms", "p90 ms", "p99 ms", "max ms", "CPU µs/epoch"
    );
    for spec in &args.captures {
        let rows = run_capture(args, spec, &gpsd, n)?;
        for r in &rows {
            println!(
                "{:<24} {:<19} {:>6} {:>8} {:>5} {:>8} {:>8} {:>8} {:>8} {:>12}{}",
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

/// `navsync-bench helper pty-read --port PATH`: prints "ready", then for every `read(2)` on the
/// terminal the `CLOCK_MONOTONIC` time (ns) right after it returned and the bytes read, until
/// the terminal closes or a signal ends it. Nothing else: the floor of `gnss-latency`.
pub fn helper_pty_read(port: &Path) -> std::io::Result<()> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    let mut f = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOCTTY)
        .open(port)?;
    let mut out = std::io::stdout().lock();
    writeln!(out, "ready")?;
    out.flush()?;
    let mut buf = [0u8; 8192];
    loop {
        match f.read(&mut buf) {
            Ok(0) => return Ok(()),
            Ok(n) => {
                let t = monotonic_now_ns();
                writeln!(out, "{t} {n}")?;
                out.flush()?;
            }
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
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
    fn an_epoch_is_complete_with_the_read_that_brings_its_last_byte() {
        // Epochs of 10, 5, 7 bytes; read as 4+6, 5, 3+4.
        let reads = [(1, 4), (2, 6), (3, 5), (4, 3), (5, 4)];
        assert_eq!(completions(&[10, 5, 7], &reads), vec![2, 3, 5]);
        // Two epochs in one read; a last epoch never completed.
        assert_eq!(completions(&[3, 3, 9], &[(7, 6), (8, 1)]), vec![7, 7]);
    }

    #[test]
    fn outputs_are_attributed_to_the_latest_write() {
        let r = attribute("c", "p", &[100, 200, 300], &[50, 150, 160, 310]);
        assert_eq!((r.received, r.missing, r.extra), (2, 1, 1));
        assert!((r.max_ms.unwrap() - 50e-6).abs() < 1e-12, "{:?}", r.max_ms);
    }
}
