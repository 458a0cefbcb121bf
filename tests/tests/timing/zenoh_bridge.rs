//! Two hosts on one machine: network namespaces `A` and `B` joined by a veth pair (created
//! here, addresses inside the namespaces only), each host with its own iceoryx2 prefix.
//! Host A runs the live pipeline (sim, drivers, estimator; processes of prefix A) and `navsync
//! bridge zenoh` in namespace A, listening on its veth address. Host B, in namespace B, runs
//! a bridge with `--import hostA` and a plain `navsync echo navsync/nav/state --json` on its
//! own iceoryx2, the Python `eclipse-zenoh` subscriber (shared/python/nav_subscriber_zenoh.py)
//! and the remote clients `echo --zenoh`, `status --zenoh`. Checked:
//! * both of B's subscribers receive NavStates whose content equals host A's (by sequence
//!   number), with consecutive exporter sequence numbers at 100 Hz (no loss) before the cut;
//! * the link is cut (`ip link set down`) for 5 s and restored: both resume within 2 s, and
//!   B's bridge counts the loss in its Health (`import_lost`);
//! * a slow remote subscriber (an `echo --zenoh` nobody reads) neither slows host B's import
//!   nor grows host A's bridge;
//! * host A's estimator killed and restarted: B receives its states again;
//! * `status --zenoh` from B sees host A's services, `echo --zenoh` prints A's states.
//!
//! Needs root (namespaces), `ip` (iproute2), python3 with pip and PyPI; where namespaces cannot
//! be created the test says so and returns.

use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use navsync_bench::netns::{NetnsPair, StopOnDrop as Daemon};
use navsync_recording::channels::sample_json;
use navsync_shared::samples::{AnySample, NavState};
use navsync_shared::services;
use navsync_tests::{HealthWatch, TestEnv, navsync_bin, python_with, write_drive_scenario};
use serde_json::Value;

/// Runs `program ARGS` in namespace `i` of `link` with `env`'s iceoryx2 prefix.
fn in_ns(link: &NetnsPair, i: usize, env: &TestEnv, program: &Path, args: &[&str]) -> Command {
    let mut c = link.command(i, program, args);
    c.env(navsync_shared::services::PREFIX_ENV, &env.prefix)
        .env("RUST_LOG", "warn");
    c
}

/// A child whose stdout lines are collected with their arrival time.
struct Lines {
    child: Child,
    lines: Arc<Mutex<Vec<(Instant, String)>>>,
}

impl Lines {
    fn spawn(mut c: Command, log: &Path) -> Self {
        let mut child = c
            .stdout(Stdio::piped())
            .stderr(std::fs::File::create(log).expect("log"))
            .spawn()
            .expect("spawning");
        let out = child.stdout.take().expect("stdout");
        let lines = Arc::new(Mutex::new(Vec::new()));
        let l = lines.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                l.lock().unwrap().push((Instant::now(), line));
            }
        });
        Lines { child, lines }
    }

    fn snapshot(&self) -> Vec<(Instant, String)> {
        self.lines.lock().unwrap().clone()
    }
}

impl Drop for Lines {
    fn drop(&mut self) {
        // SAFETY: signalling our own child.
        unsafe { libc::kill(self.child.id() as libc::pid_t, libc::SIGTERM) };
        let _ = self.child.wait();
    }
}

fn daemon(c: Command, log: &Path) -> Daemon {
    let mut c = c;
    Daemon(
        c.stdout(Stdio::null())
            .stderr(std::fs::File::create(log).expect("log"))
            .spawn()
            .expect("spawning"),
    )
}

/// (arrival, seq, sample JSON) of `echo --json` lines (the sample alone) or bridge-client
/// lines (`{"instance","seq","sample"}`, seq being the exporter's).
fn parse(lines: &[(Instant, String)]) -> Vec<(Instant, u64, Value)> {
    lines
        .iter()
        .filter_map(|(t, l)| {
            let v: Value = serde_json::from_str(l).ok()?;
            if v.get("sample").is_some() {
                Some((*t, v["seq"].as_u64()?, v["sample"].clone()))
            } else {
                Some((*t, v["seq"].as_u64()?, v))
            }
        })
        .collect()
}

/// Floats compared as values (Python and Rust print the shortest text differently).
fn same(a: &Value, b: &Value) -> bool {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => match (x.as_i64(), y.as_i64(), x.as_u64(), y.as_u64()) {
            (Some(p), Some(q), _, _) => p == q,
            (_, _, Some(p), Some(q)) => p == q,
            _ => x.as_f64() == y.as_f64(),
        },
        (Value::Array(x), Value::Array(y)) => x.len() == y.len() && x.iter().zip(y).all(|(p, q)| same(p, q)),
        (Value::Object(x), Value::Object(y)) => {
            x.len() == y.len() && x.iter().all(|(k, v)| y.get(k).is_some_and(|w| same(v, w)))
        }
        _ => a == b,
    }
}

#[test]
fn two_hosts_over_zenoh_survive_a_cut_link() {
    let _alone = navsync_tests::alone();
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        println!(
            "SKIPPED: network namespaces need root; this test runs as uid {}",
            unsafe { libc::geteuid() }
        );
        return;
    }
    let link = match NetnsPair::new("nsy") {
        Ok(l) => l,
        Err(e) => {
            println!("SKIPPED: cannot create network namespaces here: {e}");
            return;
        }
    };
    let mut a = TestEnv::new("zenohA");
    let b = TestEnv::new("zenohB");
    let (py, pythonpath) = python_with(&b.dir, &["eclipse-zenoh==1.2.1"])
        .unwrap_or_else(|why| panic!("cannot install eclipse-zenoh (needs python3, pip and PyPI): {why}"));
    let endpoint = format!("tcp/{}:7447", link.addr[0]);
    let bin = navsync_bin();

    // Host A: the live pipeline (1 IMU at 100 Hz: NavStates at 100 Hz) and its bridge.
    let scenario = a.dir.join("drive.toml");
    write_drive_scenario(&scenario, 90.0, 1, 100.0);
    let node_a = a.node("observer");
    let nav_a = node_a.subscriber::<NavState>(services::NAV_STATE).unwrap();
    a.spawn_pipeline(&scenario, 1);
    let bridge_a = daemon(
        in_ns(
            &link,
            0,
            &a,
            &bin,
            &["bridge", "zenoh", "--instance", "hostA", "--listen", &endpoint],
        ),
        &a.dir.join("bridge.log"),
    );
    // Host B: an importing bridge, a plain echo on its own iceoryx2, the Python subscriber.
    let bridge_b = daemon(
        in_ns(
            &link,
            1,
            &b,
            &bin,
            &[
                "bridge",
                "zenoh",
                "--instance",
                "hostB",
                "--no-export",
                "--import",
                "hostA",
                "--connect",
                &endpoint,
            ],
        ),
        &b.dir.join("bridge.log"),
    );
    let echo = Lines::spawn(
        in_ns(&link, 1, &b, &bin, &["echo", services::NAV_STATE, "--json"]),
        &b.dir.join("echo.log"),
    );
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/python/nav_subscriber_zenoh.py");
    let mut pc = in_ns(
        &link,
        1,
        &b,
        &py,
        &[
            &script.display().to_string(),
            "--connect",
            &endpoint,
            "--instance",
            "hostA",
            "--json",
        ],
    );
    let shared_py = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/python");
    let pp = match &pythonpath {
        Some(p) => format!("{}:{}", shared_py.display(), p.display()),
        None => shared_py.display().to_string(),
    };
    pc.env("PYTHONPATH", pp);
    let python = Lines::spawn(pc, &b.dir.join("python.log"));

    // Collect host A's states while B receives: 12 s, then the link down for 5 s, up for 8 s.
    let mut states_a: HashMap<u64, NavState> = HashMap::new();
    let collect = |states: &mut HashMap<u64, NavState>, until: Instant| {
        while Instant::now() < until {
            if let Some(n) = nav_a.wait_next(Duration::from_millis(20)).unwrap() {
                states.insert(n.seq, n);
            }
        }
    };
    collect(&mut states_a, Instant::now() + Duration::from_secs(12));
    let (echo_before, py_before) = (parse(&echo.snapshot()).len(), parse(&python.snapshot()).len());
    assert!(
        echo_before > 300 && py_before > 300,
        "before the cut: echo {echo_before}, python {py_before} states\nbridge A: {}\nbridge B: {}\npython: {}",
        std::fs::read_to_string(a.dir.join("bridge.log")).unwrap_or_default(),
        std::fs::read_to_string(b.dir.join("bridge.log")).unwrap_or_default(),
        std::fs::read_to_string(b.dir.join("python.log")).unwrap_or_default()
    );
    let cut = Instant::now();
    link.set_link(false).expect("link down");
    collect(&mut states_a, cut + Duration::from_secs(5));
    let restored = Instant::now();
    link.set_link(true).expect("link up");
    collect(&mut states_a, restored + Duration::from_secs(3));
    // A slow remote subscriber: `echo --zenoh` on B whose output nobody reads (it blocks once
    // the pipe is full). Host A's bridge must neither block nor grow, and host B's own import
    // must keep its rate.
    let rss = |pid: u32| navsync_tests::rss_kib(pid).unwrap_or(0);
    let rss_a0 = rss(bridge_a.0.id());
    let mut slow = in_ns(&link, 1, &b, &bin, &["echo", "--zenoh", &endpoint, services::NAV_STATE])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let slow_from = Instant::now();
    collect(&mut states_a, slow_from + Duration::from_secs(6));
    let slow_to = Instant::now();
    let rss_a1 = rss(bridge_a.0.id());
    let during_slow = parse(&echo.snapshot())
        .iter()
        .filter(|(t, _, _)| *t > slow_from + Duration::from_secs(1) && *t < slow_to)
        .count();
    println!(
        "slow remote subscriber for 6 s: host B's echo got {during_slow} states in the last 5 s; host A's bridge {rss_a0} -> {rss_a1} KiB"
    );
    assert!(
        during_slow > 400,
        "a slow remote subscriber slowed host B's import: {during_slow} in 5 s"
    );
    assert!(
        rss_a1 < rss_a0 + 32 * 1024,
        "host A's bridge grew from {rss_a0} to {rss_a1} KiB"
    );
    let _ = slow.kill();
    let _ = slow.wait();
    // What the checks below compare (before the estimator restarts its sequence numbers).
    let (echo_lines, python_lines) = (echo.snapshot(), python.snapshot());

    // Host A's estimator killed and restarted: its service comes back, the bridge keeps
    // exporting it (the estimator starts its sequence numbers again at 1).
    let echo_before_restart = parse(&echo.snapshot()).len();
    a.kill9("estimator");
    std::thread::sleep(Duration::from_millis(500));
    let restarted = Instant::now();
    a.respawn("estimator");
    collect(&mut HashMap::new(), restarted + Duration::from_secs(6));
    let after_restart: Vec<Instant> = parse(&echo.snapshot())
        .into_iter()
        .skip(echo_before_restart)
        .map(|(t, _, _)| t)
        .filter(|t| *t > restarted)
        .collect();
    let first = after_restart.first().map(|t| t.duration_since(restarted).as_secs_f64());
    println!(
        "estimator restarted on host A: host B's echo got {} states in 6 s, the first {first:?} s after the restart",
        after_restart.len()
    );
    assert!(
        after_restart.len() > 100,
        "the bridge lost the restarted estimator's states"
    );

    // The remote clients, from B's namespace.
    let o = in_ns(
        &link,
        1,
        &b,
        &bin,
        &["status", "--zenoh", &endpoint, "--json", "--window", "2"],
    )
    .output()
    .unwrap();
    assert!(
        o.status.success(),
        "status --zenoh: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let st: Value = serde_json::from_slice(&o.stdout).unwrap();
    let rate = st["services"]["hostA"]["navsync/nav/state"]["rate_hz"]
        .as_f64()
        .unwrap_or(0.0);
    println!("status --zenoh: hostA navsync/nav/state at {rate:.1} Hz");
    assert!(rate > 80.0, "{st}");
    let o = in_ns(
        &link,
        1,
        &b,
        &bin,
        &["echo", "--zenoh", &endpoint, services::NAV_STATE, "--count", "20"],
    )
    .output()
    .unwrap();
    assert!(
        o.status.success(),
        "echo --zenoh: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let remote: Vec<Value> = String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(remote.len(), 20);
    assert!(remote.iter().all(|v| v["instance"] == "hostA"));

    // B's bridge counted the loss.
    let node_b = b.node("observer");
    let mut health = HealthWatch::new(&node_b, &["bridge-zenoh"]);
    assert!(health.wait(Duration::from_secs(3)), "no health from B's bridge");
    std::thread::sleep(Duration::from_millis(1100));
    health.poll();
    let lost = health.counter("bridge-zenoh", "import_lost").unwrap_or(0);
    let imported = health.counter("bridge-zenoh", "imported").unwrap_or(0);
    println!("B's bridge: imported {imported}, import_lost {lost}");
    assert!(lost > 0, "the cut link's loss is not counted");

    for (name, lines, exporter_seq) in [("echo", echo_lines, false), ("python", python_lines, true)] {
        let got = parse(&lines);
        // Content equals host A's state of the same sequence number.
        let mut compared = 0;
        for (_, _, v) in &got {
            let seq = v["seq"].as_u64().unwrap();
            if let Some(n) = states_a.get(&seq) {
                assert!(
                    same(v, &sample_json(&AnySample::Nav(*n))),
                    "{name}: state {seq} differs"
                );
                compared += 1;
            }
        }
        // No loss at 100 Hz before the cut.
        let before: Vec<u64> = got
            .iter()
            .filter(|(t, _, _)| *t < cut)
            .map(|(_, s, v)| if exporter_seq { *s } else { v["seq"].as_u64().unwrap() })
            .collect();
        let gaps: u64 = before.windows(2).map(|w| w[1].saturating_sub(w[0] + 1)).sum();
        // Resumed within 2 s of the link coming back.
        let first_after = got.iter().find(|(t, _, _)| *t > restored);
        let resume = first_after.map(|(t, _, _)| t.duration_since(restored).as_secs_f64());
        let during = got
            .iter()
            .filter(|(t, _, _)| *t > cut + Duration::from_millis(1500) && *t < restored)
            .count();
        println!(
            "{name}: {} states ({compared} compared with host A's), {} before the cut with {gaps} gaps, {during} during it, resumed {resume:?} s after the link came back",
            got.len(),
            before.len()
        );
        assert!(compared > 500, "{name}: only {compared} states compared");
        assert_eq!(gaps, 0, "{name}: lost states before the cut");
        assert!(resume.is_some_and(|r| r <= 2.0), "{name}: resumed after {resume:?} s");
        assert!(during < 20, "{name}: {during} states arrived while the link was down");
    }
    drop((echo, python));
    a.assert_running();
    drop((bridge_b, bridge_a));
    drop((nav_a, node_a, health, node_b));
    a.finish();
    b.finish();
}
