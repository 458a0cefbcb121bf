//! `navsync web` on the live set of processes (sim, gnss, pps, estimator with two IMUs):
//!
//! * the page in headless Chromium (`--dump-dom`, `--screenshot`; Debian's `chromium`, which
//!   `.ci/run` installs; skipped with the reason without it): two loads show different
//!   states, and the values in the rendered DOM are those `navsync echo` printed for the same
//!   state (the same sequence number), published within a second of the load;
//! * the receiver's sky: a `GnssSky` the test publishes on `navsync/gnss/sky-test/sky` (the
//!   simulator's NMEA receiver writes no GSV) is in the snapshot, drawn as a polar plot with one
//!   dot per satellite (filled when used) and counted in `navsync_gnss_satellites`;
//! * `/metrics`: every line of the exposition format parses, the names follow Prometheus's
//!   rules; `promtool check metrics` is clean and a real Prometheus server scrapes it and
//!   answers the offset and the IMU sample counter through its HTTP API (Debian's
//!   `prometheus`; skipped with the reason without it);
//! * hostile clients: connections over the caps answered 503, a huge request head 431, a body
//!   413, a POST 405, a client that does not read dropped, each counted in
//!   `navsync/health/web`; the estimator keeps running; and after the estimator is killed and
//!   started again, the page shows the new one.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::os::fd::FromRawFd;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::clients_common::{command_in, start_live, wait_ready};
use navsync_shared::samples::{GnssSky, NavState, SkySatellite, Stamp, StampSource};
use navsync_shared::services;
use navsync_shared::time::monotonic_now_ns;
use navsync_tests::{HealthWatch, TestEnv, chromium, run_chromium};
use serde_json::Value;

/// The port `navsync web` spawned as `name` listens on (from its log).
fn port_of(env: &mut TestEnv, name: &str) -> u16 {
    let t0 = Instant::now();
    loop {
        if let Some(l) = env.log(name).lines().find(|l| l.contains("listening on http://")) {
            let addr = l.rsplit("http://").next().unwrap().trim_end_matches('/');
            return addr.rsplit(':').next().unwrap().parse().unwrap();
        }
        env.assert_running();
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "web did not listen: {}",
            env.log(name)
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Sends `request` on a new connection; the status code and the whole answer.
fn http(port: u16, request: &[u8]) -> (u16, String) {
    let mut s = TcpStream::connect(("127.0.0.1", port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    s.write_all(request).unwrap();
    let mut buf = Vec::new();
    let _ = s.read_to_end(&mut buf);
    let text = String::from_utf8_lossy(&buf).into_owned();
    let code = text
        .split(' ')
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or_else(|| panic!("no status line: {text:?}"));
    (code, text)
}

fn get(port: u16, path: &str) -> (u16, String) {
    let (code, text) = http(
        port,
        format!("GET {path} HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n").as_bytes(),
    );
    let body = text.split_once("\r\n\r\n").map_or("", |(_, b)| b).to_string();
    (code, body)
}

fn state(port: u16) -> Value {
    let (code, body) = get(port, "/state.json");
    assert_eq!(code, 200, "{body}");
    serde_json::from_str(&body).unwrap()
}

/// An event stream, its head read.
fn open_stream(port: u16) -> TcpStream {
    let mut s = TcpStream::connect(("127.0.0.1", port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    s.write_all(b"GET /events HTTP/1.1\r\nHost: localhost\r\n\r\n").unwrap();
    let mut head = Vec::new();
    let mut b = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") {
        assert_eq!(
            s.read(&mut b).unwrap(),
            1,
            "stream closed: {}",
            String::from_utf8_lossy(&head)
        );
        head.push(b[0]);
    }
    let head = String::from_utf8_lossy(&head);
    assert!(
        head.starts_with("HTTP/1.1 200") && head.contains("text/event-stream"),
        "{head}"
    );
    s
}

/// The next `data:` event of a stream, as JSON.
fn next_event(s: &mut TcpStream) -> Value {
    let mut line = Vec::new();
    let mut b = [0u8; 1];
    loop {
        assert_eq!(s.read(&mut b).unwrap(), 1, "stream closed");
        if b[0] != b'\n' {
            line.push(b[0]);
            continue;
        }
        if let Some(data) = line.strip_prefix(b"data: ") {
            return serde_json::from_slice(data).unwrap();
        }
        line.clear();
    }
}

/// User and system CPU time of a process so far, clock ticks (`/proc/<pid>/stat`).
fn cpu_ticks(pid: u32) -> u64 {
    let s = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap();
    // After the command's closing parenthesis: state is field 3, utime 14 and stime 15.
    let rest: Vec<&str> = s.rsplit_once(')').unwrap().1.split_whitespace().collect();
    rest[11].parse::<u64>().unwrap() + rest[12].parse::<u64>().unwrap()
}

/// `data-v` of the element `id` in a rendered DOM.
fn data_v(dom: &str, id: &str) -> String {
    let k = format!("id=\"{id}\"");
    let at = dom.find(&k).unwrap_or_else(|| panic!("no #{id} in the DOM"));
    let tag = &dom[at..at + dom[at..].find('>').unwrap()];
    let v = tag
        .split("data-v=\"")
        .nth(1)
        .unwrap_or_else(|| panic!("#{id} has no data-v: {tag}"));
    v[..v.find('"').unwrap()].to_string()
}

fn data_f(dom: &str, id: &str) -> f64 {
    let v = data_v(dom, id);
    v.parse().unwrap_or_else(|_| panic!("#{id}: `{v}` is not a number"))
}

/// `navsync echo SERVICE --json` started in the background (its stdout in `<dir>/<name>.out`).
fn echo_in_background(env: &mut TestEnv, name: &str, service: &str) {
    env.spawn_capturing(name, &["echo", service, "--json"]);
}

fn echoed(env: &TestEnv, name: &str) -> Vec<Value> {
    std::fs::read_to_string(env.dir.join(format!("{name}.out")))
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

#[test]
fn the_page_shows_what_echo_shows_and_prometheus_scrapes_it() {
    let mut env = TestEnv::new("web");
    start_live(&mut env);
    env.spawn(
        "web",
        &[
            "web",
            "--listen",
            "127.0.0.1:0",
            "--max-connections",
            "6",
            "--max-streams",
            "3",
            "--write-timeout",
            "1",
        ],
    );
    let node = env.node("observer");
    wait_ready(&mut env, &node, true, Duration::from_secs(90));
    let port = port_of(&mut env, "web");
    // A receiver's sky: three satellites, two used, one without a position in the sky.
    let mut sky = GnssSky::empty(Stamp::host(monotonic_now_ns(), 0, StampSource::Receipt));
    for (sv, el, az, cno, used) in [
        (5, 60.0, 45.0, 47, 1),
        (12, 20.0, 200.0, 30, 1),
        (29, f32::NAN, f32::NAN, 0, 0),
    ] {
        sky.push(SkySatellite {
            elevation_deg: el,
            azimuth_deg: az,
            gnss_id: 0,
            sv_id: sv,
            cno_dbhz: cno,
            used,
        });
    }
    let mut sky_pub = node.publisher::<GnssSky>(&services::gnss_sky("sky-test")).unwrap();
    sky_pub.publish(&sky).unwrap();

    // The snapshot (once a second): the status report and what the page adds.
    let t0 = Instant::now();
    let mut s = state(port);
    while s["nav"]["status"] != "aligned" && t0.elapsed() < Duration::from_secs(5) {
        std::thread::sleep(Duration::from_millis(200));
        s = state(port);
    }
    assert_eq!(s["time"]["status"], "locked", "{s}");
    assert_eq!(s["nav"]["status"], "aligned");
    assert!(
        s["clock"]["offset_s"].is_number() && s["clock"]["sigma_s"].is_number(),
        "{}",
        s["clock"]
    );
    assert!(s["imu_samples"]["0"].as_u64().unwrap() > 100, "{}", s["imu_samples"]);
    assert!(s["fixes"][0]["mode"] == "3D", "{}", s["fixes"]);
    assert!(!s["track"]["en_m"].as_array().unwrap().is_empty());
    let t0 = Instant::now();
    while s["skies"].as_array().is_none_or(Vec::is_empty) && t0.elapsed() < Duration::from_secs(5) {
        // Published again, as a receiver does each epoch (a subscriber that comes later gets
        // the publisher's history when it publishes next).
        sky.stamp.seq += 1;
        sky_pub.publish(&sky).unwrap();
        std::thread::sleep(Duration::from_millis(200));
        s = state(port);
    }
    let k = &s["skies"][0];
    assert_eq!(
        (k["id"].as_str(), k["in_view"].as_u64(), k["used"].as_u64()),
        (Some("sky-test"), Some(3), Some(2)),
        "{k}"
    );
    assert_eq!(k["satellites"][0]["label"], "G05");
    // The event stream: one state a second, each newer than the last.
    let mut es = open_stream(port);
    let (a, b) = (next_event(&mut es), next_event(&mut es));
    let c = next_event(&mut es);
    assert!(b["seq"].as_u64() > a["seq"].as_u64() && c["seq"].as_u64() > b["seq"].as_u64());
    assert!(
        c["nav_sigma"]["seq"].as_u64() > b["nav_sigma"]["seq"].as_u64(),
        "the nav state moved"
    );
    drop(es);

    // What the web process costs with nothing connected: its CPU over 5 s, its memory.
    let pid = env.pid("web").unwrap();
    let (c0, t0) = (cpu_ticks(pid), Instant::now());
    std::thread::sleep(Duration::from_secs(5));
    // SAFETY: sysconf has no preconditions.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    let cpu = (cpu_ticks(pid) - c0) as f64 / hz / t0.elapsed().as_secs_f64();
    println!(
        "web process without clients: {:.1} % of a core over 5 s, {} KiB resident",
        cpu * 100.0,
        navsync_tests::rss_kib(pid).unwrap_or(0)
    );
    assert!(cpu < 0.2, "web takes {:.0} % of a core", cpu * 100.0);

    page_in_chromium(&mut env, port);
    metrics_and_prometheus(&mut env, port);
    hostile_clients(&mut env, &node, port);
    estimator_restarted(&mut env, &node, port);
    drop(sky_pub);
    drop(node);
    env.finish();
}

/// Two loads in headless Chromium: the DOM's values are `navsync echo`'s for the same state.
fn page_in_chromium(env: &mut TestEnv, port: u16) {
    let Some(bin) = chromium() else {
        println!("SKIPPED the Chromium part: no chromium on PATH (.ci/run installs Debian's `chromium`)");
        return;
    };
    let profile = env.dir.join("chromium-profile");
    std::fs::create_dir_all(&profile).unwrap();
    let url = format!("http://127.0.0.1:{port}/");
    echo_in_background(env, "echo-nav", services::NAV_STATE);
    echo_in_background(env, "echo-time", services::TIME_STATE);
    std::thread::sleep(Duration::from_secs(1));
    let mut loads = Vec::new();
    for _ in 0..2 {
        let t0 = monotonic_now_ns();
        let dom = run_chromium(&bin, &profile, &["--dump-dom".into(), url.clone()]);
        assert!(
            dom.contains("id=\"nav-lat\""),
            "no page: {}",
            &dom[..dom.len().min(300)]
        );
        loads.push((t0, dom));
        std::thread::sleep(Duration::from_millis(1500));
    }
    std::thread::sleep(Duration::from_millis(500));
    let navs = echoed(env, "echo-nav");
    let times = echoed(env, "echo-time");
    assert!(
        navs.len() > 100 && !times.is_empty(),
        "echo: {} nav, {} time states",
        navs.len(),
        times.len()
    );
    let mut seqs = Vec::new();
    for (t0, dom) in &loads {
        let seq = data_f(dom, "nav-utc") as u64;
        let nav = navs
            .iter()
            .find(|n| n["seq"].as_u64() == Some(seq))
            .unwrap_or_else(|| panic!("nav state {seq} of the page not echoed"));
        // The same state, published within a second of the load (the page inlines the state of
        // the last second, or the event stream's newest).
        let host_ns = nav["host_ns"].as_i64().unwrap();
        assert!(
            host_ns > t0 - 1_100_000_000,
            "the page's state is {} s older than the load",
            (t0 - host_ns) as f64 * 1e-9
        );
        for (id, field) in [
            ("nav-lat", "lat_deg"),
            ("nav-lon", "lon_deg"),
            ("nav-height", "height_m"),
        ] {
            let (page, echo) = (data_f(dom, id), nav[field].as_f64().unwrap());
            assert!((page - echo).abs() < 1e-9, "{id}: page {page}, echo {echo}");
        }
        assert_eq!(data_v(dom, "nav-status"), "aligned");
        // The time state of the same snapshot.
        let tseq = data_f(dom, "time-seq") as u64;
        let time = times
            .iter()
            .find(|t| t["seq"].as_u64() == Some(tseq))
            .unwrap_or_else(|| panic!("time state {tseq} of the page not echoed"));
        assert_eq!(time["status"], 1, "locked");
        assert_eq!(data_v(dom, "time-status"), "locked");
        let drift = time["rate_error"].as_f64().unwrap() * 1e6;
        assert!((data_f(dom, "time-drift") - drift).abs() < 1e-9, "drift {drift} ppm");
        let delay = nav["gnss_delay_s"].as_f64().unwrap();
        assert!((data_f(dom, "gnss-delay") - delay).abs() < 1e-12, "Δ {delay}");
        assert!(data_f(dom, "time-sigma") > 0.0 && data_f(dom, "time-sigma") < 1e-3);
        assert!(dom.contains("id=\"proc-estimator\"") && dom.contains("id=\"imu-1\""));
        assert!(
            dom.contains("<ellipse") && dom.contains("<polyline"),
            "the track is drawn"
        );
        // The sky: two satellites drawn (the third has no position), both used ones filled.
        assert_eq!(data_v(dom, "sky-sky-test"), "3");
        assert_eq!(dom.matches("class=\"sat used\"").count(), 2, "the sky is drawn");
        assert!(dom.contains(">G12<") && !dom.contains(">G29<"), "the sky's labels");
        println!(
            "Chromium load: nav state {seq} (lat {} lon {}), time state {tseq}, drift {drift:.4} ppm, {} event(s) from the stream",
            data_v(dom, "nav-lat"),
            data_v(dom, "nav-lon"),
            data_v(dom, "updates")
        );
        seqs.push(seq);
    }
    assert!(seqs[1] > seqs[0], "the second load shows a newer state: {seqs:?}");
    assert_ne!(
        data_v(&loads[0].1, "nav-lat"),
        data_v(&loads[1].1, "nav-lat"),
        "the vehicle moves"
    );

    let shot = env.dir.join("web.png");
    run_chromium(
        &bin,
        &profile,
        &[
            format!("--screenshot={}", shot.display()),
            "--window-size=1280,2200".into(),
            url,
        ],
    );
    let png = std::fs::read(&shot).unwrap_or_default();
    assert!(png.starts_with(b"\x89PNG"), "no screenshot written");
    // A blank page compresses to a few kB; tables, text and the track do not.
    assert!(png.len() > 60_000, "screenshot only {} bytes", png.len());
    println!("Chromium: screenshot {} bytes", png.len());
    if let Ok(keep) = std::env::var("NAVSYNC_KEEP_SCREENSHOT") {
        let _ = std::fs::copy(&shot, keep);
    }
}

/// Splits a sample line into its name, labels and value.
fn sample(line: &str) -> (&str, Vec<(String, String)>, f64) {
    let (series, value) = line.rsplit_once(' ').unwrap_or_else(|| panic!("no value: {line}"));
    let value: f64 = value.parse().unwrap_or_else(|_| panic!("value of {line}"));
    let (name, mut rest) = match series.find('{') {
        Some(i) => (&series[..i], &series[i + 1..]),
        None => (series, ""),
    };
    let mut labels = Vec::new();
    if !rest.is_empty() {
        rest = rest.strip_suffix('}').unwrap_or_else(|| panic!("labels of {line}"));
        // Label values are quoted with `\"`, `\\` and `\n` escaped.
        let mut chars = rest.chars().peekable();
        while chars.peek().is_some() {
            let key: String = chars.by_ref().take_while(|&c| c != '=').collect();
            assert_eq!(chars.next(), Some('"'), "{line}");
            let mut v = String::new();
            loop {
                match chars.next().unwrap_or_else(|| panic!("unterminated: {line}")) {
                    '\\' => v.push(chars.next().unwrap()),
                    '"' => break,
                    c => v.push(c),
                }
            }
            assert!(matches!(chars.peek(), None | Some(',')), "{line}");
            chars.next();
            labels.push((key, v));
        }
    }
    (name, labels, value)
}

fn valid_name(n: &str) -> bool {
    let mut b = n.bytes();
    b.next().is_some_and(|c| c.is_ascii_alphabetic() || c == b'_') && b.all(|c| c.is_ascii_alphanumeric() || c == b'_')
}

fn metrics_and_prometheus(env: &mut TestEnv, port: u16) {
    let (code, text) = get(port, "/metrics");
    assert_eq!(code, 200);
    let mut kinds = std::collections::BTreeMap::new();
    let mut names = std::collections::BTreeSet::new();
    for line in text.lines() {
        if let Some(rest) = line.strip_prefix("# TYPE ") {
            let (name, kind) = rest.split_once(' ').unwrap();
            assert!(
                kinds.insert(name.to_string(), kind.to_string()).is_none(),
                "{name} typed twice"
            );
            // Prometheus's rules: snake case under the application's prefix, counters end in
            // _total, units are base units (seconds, meters, ratio) spelled out.
            assert!(valid_name(name) && name.starts_with("navsync_"), "{name}");
            assert!(name.bytes().all(|c| !c.is_ascii_uppercase()), "{name}");
            assert_eq!(kind == "counter", name.ends_with("_total"), "{line}");
            for word in name.split('_') {
                let scaled = ["milli", "micro", "nano", "kilo", "mega"]
                    .iter()
                    .any(|p| word.starts_with(p));
                let abbreviated = ["ms", "us", "ns", "sec", "secs", "ppm", "hz", "m", "percent"].contains(&word);
                assert!(
                    !scaled && !abbreviated,
                    "{name}: unit `{word}` (base units, spelled out)"
                );
            }
            continue;
        }
        if line.starts_with("# HELP ") {
            assert!(line.len() > "# HELP x ".len(), "{line}");
            continue;
        }
        let (name, labels, value) = sample(line);
        assert!(kinds.contains_key(name), "{name} has no TYPE before its samples");
        assert!(value.is_finite(), "{line}");
        for (k, _) in &labels {
            assert!(valid_name(k) && !k.starts_with("__"), "{line}");
        }
        names.insert((name.to_string(), labels));
    }
    let has = |n: &str, l: &[(&str, &str)]| {
        names
            .iter()
            .any(|(name, labels)| name == n && l.iter().all(|(k, v)| labels.iter().any(|(lk, lv)| lk == k && lv == v)))
    };
    for (n, l) in [
        ("navsync_time_offset_seconds", &[][..]),
        ("navsync_time_sigma_seconds", &[]),
        ("navsync_gnss_delay_seconds", &[]),
        ("navsync_imu_samples_total", &[("imu", "0")]),
        ("navsync_imu_samples_total", &[("imu", "1")]),
        ("navsync_imu_offset_seconds", &[("imu", "1")]),
        (
            "navsync_health_value",
            &[("process", "estimator"), ("counter", "imu_samples")],
        ),
        ("navsync_nav_status", &[("status", "aligned")]),
        ("navsync_time_status", &[("status", "locked")]),
        ("navsync_web_requests_total", &[]),
        ("navsync_gnss_satellites", &[("receiver", "sky-test"), ("used", "true")]),
        (
            "navsync_gnss_satellites",
            &[("receiver", "sky-test"), ("used", "false")],
        ),
    ] {
        assert!(has(n, l), "{n}{l:?} missing:\n{text}");
    }
    println!("/metrics: {} families, {} series", kinds.len(), names.len());

    // promtool's own lint.
    let metrics_file = env.dir.join("metrics.txt");
    std::fs::write(&metrics_file, &text).unwrap();
    match Command::new("promtool")
        .args(["check", "metrics"])
        .stdin(std::fs::File::open(&metrics_file).unwrap())
        .output()
    {
        Err(_) => println!("SKIPPED promtool: not installed (Debian's `prometheus`; .ci/run installs it)"),
        Ok(o) => {
            let out = format!(
                "{}{}",
                String::from_utf8_lossy(&o.stdout),
                String::from_utf8_lossy(&o.stderr)
            );
            assert!(
                o.status.success() && out.trim().is_empty(),
                "promtool check metrics: {}\n{out}",
                o.status
            );
            println!("promtool check metrics: clean");
        }
    }

    // A real Prometheus server scraping it.
    if Command::new("prometheus").arg("--version").output().is_err() {
        println!("SKIPPED the Prometheus server: not installed (Debian's `prometheus`; .ci/run installs it)");
        return;
    }
    let prom_port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let config = env.dir.join("prometheus.yml");
    std::fs::write(
        &config,
        format!(
            "global:\n  scrape_interval: 1s\n  evaluation_interval: 1s\nscrape_configs:\n  - job_name: navsync\n    \
             static_configs:\n      - targets: ['127.0.0.1:{port}']\n"
        ),
    )
    .unwrap();
    let log = std::fs::File::create(env.dir.join("prometheus.log")).unwrap();
    let mut prom = command_in(env, "prometheus")
        .arg(format!("--config.file={}", config.display()))
        .arg(format!("--storage.tsdb.path={}", env.dir.join("tsdb").display()))
        .arg(format!("--web.listen-address=127.0.0.1:{prom_port}"))
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .unwrap();
    let query = |q: &str| -> Vec<Value> {
        let (code, body) = get(prom_port, &format!("/api/v1/query?query={q}"));
        if code != 200 {
            return Vec::new();
        }
        let v: Value = serde_json::from_str(&body).unwrap_or(Value::Null);
        v["data"]["result"].as_array().cloned().unwrap_or_default()
    };
    let t0 = Instant::now();
    let (mut offset, mut samples) = (Vec::new(), Vec::new());
    while t0.elapsed() < Duration::from_secs(30) {
        std::thread::sleep(Duration::from_millis(500));
        if TcpStream::connect(("127.0.0.1", prom_port)).is_err() {
            continue;
        }
        offset = query("navsync_time_offset_seconds");
        samples = query("navsync_imu_samples_total");
        if !offset.is_empty() && samples.len() >= 2 {
            break;
        }
    }
    let _ = prom.kill();
    let _ = prom.wait();
    assert!(
        !offset.is_empty() && samples.len() >= 2,
        "Prometheus answered offset {offset:?}, samples {samples:?}; its log:\n{}",
        std::fs::read_to_string(env.dir.join("prometheus.log")).unwrap_or_default()
    );
    let value = |r: &Value| r["value"][1].as_str().unwrap().parse::<f64>().unwrap();
    assert!(value(&offset[0]).abs() < 1.0, "{offset:?}");
    assert!(samples.iter().all(|r| value(r) > 100.0), "{samples:?}");
    println!(
        "Prometheus scraped navsync_time_offset_seconds = {} s, navsync_imu_samples_total = {:?} ({:.1} s after its start)",
        value(&offset[0]),
        samples
            .iter()
            .map(|r| (r["metric"]["imu"].clone(), value(r)))
            .collect::<Vec<_>>(),
        t0.elapsed().as_secs_f64()
    );
}

/// A client socket with a small receive buffer (set before connecting), that never reads.
fn non_reading_client(port: u16) -> TcpStream {
    // SAFETY: a new socket, options and connect with valid arguments; the descriptor is owned
    // by the TcpStream from then on.
    unsafe {
        let fd = libc::socket(libc::AF_INET, libc::SOCK_STREAM, 0);
        assert!(fd >= 0);
        let small: libc::c_int = 4096;
        libc::setsockopt(
            fd,
            libc::SOL_SOCKET,
            libc::SO_RCVBUF,
            (&small as *const libc::c_int).cast(),
            std::mem::size_of::<libc::c_int>() as libc::socklen_t,
        );
        let addr = libc::sockaddr_in {
            sin_family: libc::AF_INET as libc::sa_family_t,
            sin_port: port.to_be(),
            sin_addr: libc::in_addr {
                s_addr: u32::from(std::net::Ipv4Addr::LOCALHOST).to_be(),
            },
            sin_zero: [0; 8],
        };
        let r = libc::connect(
            fd,
            (&addr as *const libc::sockaddr_in).cast(),
            std::mem::size_of::<libc::sockaddr_in>() as libc::socklen_t,
        );
        assert_eq!(r, 0, "connect: {}", std::io::Error::last_os_error());
        TcpStream::from_raw_fd(fd)
    }
}

fn hostile_clients(env: &mut TestEnv, node: &navsync_shared::ipc::IpcNode, port: u16) {
    let mut health = HealthWatch::new(node, &["web"]);
    let nav = node.subscriber::<NavState>(services::NAV_STATE).unwrap();
    // Streams over --max-streams 3: 503.
    let streams: Vec<TcpStream> = (0..3).map(|_| open_stream(port)).collect();
    let (code, text) = get(port, "/events");
    assert_eq!(code, 503, "{text}");
    // Connections over --max-connections 6 (3 streams and 3 silent clients): 503 (once the
    // refused stream's connection has closed).
    std::thread::sleep(Duration::from_millis(700));
    let silent: Vec<TcpStream> = (0..3)
        .map(|_| TcpStream::connect(("127.0.0.1", port)).unwrap())
        .collect();
    std::thread::sleep(Duration::from_millis(300));
    let (code, text) = http(port, b"GET /metrics HTTP/1.1\r\n\r\n");
    assert_eq!(code, 503, "{text}");
    assert!(text.contains("Retry-After: 5"), "{text}");
    drop(streams);
    // The silent clients are answered 408 after 5 s; until then their slots are taken.
    for mut s in silent {
        s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        let mut answer = String::new();
        let _ = s.read_to_string(&mut answer);
        assert!(answer.starts_with("HTTP/1.1 408"), "{answer}");
    }
    std::thread::sleep(Duration::from_millis(200));
    // A huge request head, a body, a method that writes.
    let mut huge = b"GET / HTTP/1.1\r\nHost: localhost\r\nX-Big: ".to_vec();
    huge.extend(std::iter::repeat_n(b'a', 1 << 20));
    huge.extend_from_slice(b"\r\n\r\n");
    let (code, text) = http(port, &huge);
    assert_eq!(code, 431, "{text}");
    let (code, _) = http(port, b"GET / HTTP/1.1\r\nContent-Length: 100000\r\n\r\n");
    assert_eq!(code, 413);
    let (code, text) = http(port, b"POST /metrics HTTP/1.1\r\nContent-Length: 0\r\n\r\n");
    assert_eq!(code, 405);
    assert!(text.contains("Allow: GET, HEAD"), "{text}");
    let (code, _) = http(port, b"GARBAGE\r\n\r\n");
    assert_eq!(code, 400);
    // A page elsewhere that reached this loopback server through DNS rebinding.
    let (code, _) = http(port, b"GET /state.json HTTP/1.1\r\nHost: evil.example:8080\r\n\r\n");
    assert_eq!(code, 421);
    // A reader that stops reading: dropped after --write-timeout 1 once its buffers are full.
    let mut slow = non_reading_client(port);
    slow.write_all(b"GET /events HTTP/1.1\r\n\r\n").unwrap();
    let t0 = Instant::now();
    let mut dropped = 0;
    while t0.elapsed() < Duration::from_secs(60) {
        health.wait(Duration::from_secs(2));
        dropped = health.counter("web", "slow_clients_dropped").unwrap_or(0);
        if dropped > 0 {
            break;
        }
    }
    let slow_s = t0.elapsed().as_secs_f64();
    drop(slow);
    // The streams whose clients left end at their next write.
    let t0 = Instant::now();
    loop {
        health.wait(Duration::from_secs(2));
        let open = health.counter("web", "streams_active").unwrap_or(0);
        if open == 0 {
            break;
        }
        assert!(t0.elapsed() < Duration::from_secs(10), "{open} streams still open");
    }
    health.wait(Duration::from_secs(3));
    let c = |name: &str| health.counter("web", name).unwrap_or(0);
    println!(
        "web health: refused_streams {} refused_connections {} too_large {} request_timeouts {} \
         method_not_allowed {} bad_requests {} foreign_hosts {} slow_clients_dropped {} (after {slow_s:.1} s)",
        c("refused_streams"),
        c("refused_connections"),
        c("too_large"),
        c("request_timeouts"),
        c("method_not_allowed"),
        c("bad_requests"),
        c("foreign_hosts"),
        dropped
    );
    assert!(c("refused_streams") >= 1 && c("refused_connections") >= 1);
    assert!(c("too_large") >= 2 && c("request_timeouts") >= 3);
    assert!(c("method_not_allowed") >= 1 && c("bad_requests") >= 1 && c("foreign_hosts") >= 1);
    assert!(dropped >= 1, "a client that does not read was not dropped");
    // The same counts in /metrics, and the estimator kept running.
    let (code, text) = get(port, "/metrics");
    assert_eq!(code, 200);
    assert!(text.contains("\nnavsync_web_refused_streams_total "), "{text}");
    env.assert_running();
    let before = nav.receive().unwrap().map(|n| n.seq);
    std::thread::sleep(Duration::from_millis(200));
    let mut last = None;
    while let Some(n) = nav.receive().unwrap() {
        last = Some(n.seq);
    }
    assert!(
        last > before,
        "the estimator's states kept coming: {before:?} → {last:?}"
    );
}

/// The estimator killed: the page shows it gone; started again: the new one, alive, with its
/// own states.
fn estimator_restarted(env: &mut TestEnv, node: &navsync_shared::ipc::IpcNode, port: u16) {
    let old_pid = env.pid("estimator").unwrap() as i64;
    let old_seq = state(port)["nav_sigma"]["seq"].as_u64().unwrap();
    env.kill9("estimator");
    let t0 = Instant::now();
    loop {
        let s = state(port);
        let est = s["processes"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["name"] == "estimator" && p["pid"] == old_pid)
            .cloned();
        if est.as_ref().is_none_or(|p| p["state"] != "alive") {
            println!(
                "killed estimator shown as {:?} after {:.1} s",
                est.map(|p| p["state"].clone()),
                t0.elapsed().as_secs_f64()
            );
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(10),
            "the killed estimator is still shown alive"
        );
        std::thread::sleep(Duration::from_millis(250));
    }
    let new_pid = env.respawn("estimator") as i64;
    let t0 = Instant::now();
    loop {
        let s = state(port);
        let alive = s["processes"]
            .as_array()
            .unwrap()
            .iter()
            .any(|p| p["name"] == "estimator" && p["pid"] == new_pid && p["state"] == "alive");
        let seq = s["nav_sigma"]["seq"].as_u64();
        // The new estimator counts its states from the start again.
        if alive && seq.is_some_and(|q| q < old_seq) && s["time"]["status"].is_string() {
            println!(
                "restarted estimator on the page after {:.1} s (nav state {seq:?}, time {})",
                t0.elapsed().as_secs_f64(),
                s["time"]["status"]
            );
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "the restarted estimator is not on the page: {s}"
        );
        std::thread::sleep(Duration::from_millis(250));
    }
    // The killed one's files: the new estimator's reclaimer takes them when the CPU is idle;
    // the test does not wait for that.
    node.reclaim_dead_nodes();
}
