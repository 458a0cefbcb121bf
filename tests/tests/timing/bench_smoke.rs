//! The benchmarks run briefly (`--quick`) and produce sane output: every case has figures,
//! percentiles are ordered, nothing is lost that is not counted, and the JSON file is written.
//! Never an assertion on absolute time (README "## Performance" has the figures).

use std::path::Path;

use navsync_tests::{TestEnv, bench_bin, navsync_bin, prefixed_files, workspace_example};
use serde_json::Value;

fn run_json(env: &TestEnv, args: &[&str], json: &Path) -> Value {
    let mut a: Vec<&str> = args.to_vec();
    let j = json.display().to_string();
    a.extend(["--quick", "--json", &j]);
    // The live benchmarks start the `navsync` roles beside `navsync-bench`, or `$NAVSYNC_BIN`.
    let o = env
        .command_of(bench_bin(), &a)
        .env("NAVSYNC_BIN", navsync_bin())
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "navsync-bench {a:?}: {}\n{out}\n{}",
        o.status,
        String::from_utf8_lossy(&o.stderr)
    );
    println!("{out}");
    serde_json::from_str(&std::fs::read_to_string(json).unwrap()).unwrap()
}

fn percentiles_sane(p: &Value, what: &str) {
    let f = |k: &str| p[k].as_f64().unwrap_or_else(|| panic!("{what}: {k} in {p}"));
    assert!(p["count"].as_u64().unwrap() > 0, "{what}: {p}");
    assert!(
        0.0 < f("p50_us") && f("p50_us") <= f("p99_us") && f("p99_us") <= f("p999_us") && f("p999_us") <= f("max_us"),
        "{what}: {p}"
    );
}

#[test]
fn benchmarks_run_and_report_sane_figures() {
    let _alone = navsync_tests::alone();
    let env = TestEnv::new("bench");

    let ipc = run_json(&env, &["ipc"], &env.dir.join("ipc.json"));
    let cases = ipc["cases"].as_array().unwrap();
    // imu, nav × 1000 Hz, max × iceoryx2, socket.
    assert_eq!(cases.len(), 8, "{ipc}");
    for c in cases {
        let sent = c["sent"].as_u64().unwrap();
        let subs = c["subscribers"].as_u64().unwrap();
        assert!(sent > 0);
        assert_eq!(
            c["received"].as_u64().unwrap() + c["lost"].as_u64().unwrap(),
            sent * subs,
            "{c}"
        );
        percentiles_sane(&c["latency"], "ipc");
        assert_eq!(c["latency"]["count"].as_u64(), c["received"].as_u64(), "{c}");
    }

    // The futex floor (a ring in /dev/shm, one wake-up for all subscribers), in two rounds:
    // every sample reaches every subscriber at 1 kHz (a 64-slot ring loses only behind a 64 ms stall), and
    // the ring file is gone afterwards.
    let floor = run_json(
        &env,
        &[
            "ipc",
            "--transports",
            "futex-floor,socket",
            "--kinds",
            "imu",
            "--rates",
            "1000",
            "--subscribers",
            "1,4",
            "--rounds",
            "2",
        ],
        &env.dir.join("floor.json"),
    );
    let cases = floor["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 4, "{floor}");
    for c in cases {
        // Two rounds of 1000 samples (`--quick`: 2000 per case) pooled into one case.
        assert_eq!(c["sent"].as_u64(), Some(2000), "{c}");
        let expected = c["sent"].as_u64().unwrap() * c["subscribers"].as_u64().unwrap();
        let received = c["received"].as_u64().unwrap();
        assert!(expected > 0 && received * 100 >= expected * 99, "{c}");
        percentiles_sane(&c["latency"], "futex-floor");
    }
    // Round by round, the floor against the socket, for 1 and 4 subscribers.
    let paired = floor["paired"].as_array().unwrap();
    assert_eq!(paired.len(), 2, "{floor}");
    for p in paired {
        assert_eq!(p["rounds"].as_u64(), Some(2), "{p}");
        assert_eq!(p["transport"].as_str(), Some("futex-floor"), "{p}");
        for m in 0..4 {
            assert!(p["at_or_below"][m].as_u64().unwrap() <= 2, "{p}");
            let r = p["median_ratio"][m].as_f64().unwrap();
            let pw = p["p_worse"][m].as_f64().unwrap();
            assert!(r > 0.0 && r.is_finite() && (0.0..=1.0).contains(&pw), "{p}");
        }
    }
    let left: Vec<_> = std::fs::read_dir("/dev/shm")
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with("navsync-bench-floor-"))
        .collect();
    assert!(left.is_empty(), "ring files left behind: {left:?}");

    let e2e = run_json(&env, &["e2e"], &env.dir.join("e2e.json"));
    // The host's share of the vCPUs' busy time over the run, from /proc/stat (Linux has it).
    let steal = e2e["machine"]["steal_percent"].as_f64();
    assert!(
        steal.is_some_and(|v| (0.0..=100.0).contains(&v)),
        "steal: {}",
        e2e["machine"]
    );
    for c in e2e["cases"].as_array().unwrap() {
        assert!(c["nav_states"].as_u64().unwrap() > 100, "{c}");
        assert!(c["matched"].as_u64().unwrap() > 0, "{c}");
        percentiles_sane(&c["end_to_end"], "e2e");
        let procs = c["processes"].as_array().unwrap();
        let est = procs
            .iter()
            .find(|p| p["name"] == "estimator")
            .expect("estimator figures");
        assert!(est["peak_rss_mib"].as_f64().unwrap() > 0.0, "{est}");
        assert!(est["cpu_percent"].as_f64().unwrap() > 0.0, "{est}");
    }

    // The chain pinned to one CPU (`CPUAffinity=`-like): it still runs and says so.
    let pinned = run_json(&env, &["e2e", "--pin-chain", "0"], &env.dir.join("e2e-pinned.json"));
    for c in pinned["cases"].as_array().unwrap() {
        assert_eq!(c["pin_chain"].as_u64(), Some(0), "{c}");
        assert!(c["nav_states"].as_u64().unwrap() > 100, "{c}");
        percentiles_sane(&c["end_to_end"], "e2e pinned");
    }
    // A CPU the machine does not have is refused before anything starts.
    let o = env
        .command_of(bench_bin(), &["e2e", "--quick", "--pin-chain", "4096"])
        .env("NAVSYNC_BIN", navsync_bin())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("--pin-chain 4096"), "{err}");

    // The machine's own wake-up stalls: every CPU's sleeper woke as often as asked, and
    // every stall is in one phase bin.
    let host = run_json(&env, &["host"], &env.dir.join("host.json"));
    let expected = host["expected_per_cpu"].as_u64().unwrap();
    assert!(expected > 1000, "{host}");
    let cpus = host["cpus"].as_array().unwrap();
    assert!(!cpus.is_empty(), "{host}");
    for c in cpus {
        assert_eq!(c["lateness"]["count"].as_u64(), Some(expected), "{c}");
        percentiles_sane(&c["lateness"], "host");
        let bins: u64 = c["stall_phase_bins"]
            .as_array()
            .unwrap()
            .iter()
            .map(|b| b.as_u64().unwrap())
            .sum();
        assert_eq!(bins, c["stalls"].as_u64().unwrap(), "{c}");
        assert!(bins <= expected, "{c}");
    }

    let thr = run_json(&env, &["throughput"], &env.dir.join("throughput.json"));
    let cases = thr["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 2, "{thr}");
    for c in cases {
        assert!(c["imu_samples"].as_u64().unwrap() > 0);
        assert!(c["imu_samples_per_s"].as_f64().unwrap() > 0.0);
        assert!(!c["blocks"].as_array().unwrap().is_empty(), "{c}");
    }
    env.finish();
}

/// `navsync-bench gnss-latency --quick` on two real captures (NMEA and UBX): every epoch's fix
/// reaches each navsync subscriber (client, echo, gpsd-server through gpspipe) once, the bare
/// reader of the floor rows sees every epoch, the figures are ordered, and a row without
/// figures (gpsd's, gpsd-server's when gpspipe is missing) says why.
#[test]
fn gnss_latency_runs_on_real_captures() {
    let _alone = navsync_tests::alone();
    let env = TestEnv::new("benchgnss");
    let captures = [
        navsync_tests::shared_material("corpora/gpsd-nmea/bu353s4.log"),
        navsync_tests::shared_material("corpora/gpsd-ubx/u-blox-m8t-time.log"),
    ]
    .map(|p| p.display().to_string())
    .join(",");
    let json = env.dir.join("gnss.json");
    let v = run_json(&env, &["gnss-latency", "--captures", &captures], &json);
    let rows = v.as_array().expect("rows");
    assert_eq!(rows.len(), 12, "{v}");
    for r in rows {
        let f = |k: &str| r[k].as_f64();
        let path = r["path"].as_str().unwrap();
        if (path.starts_with("navsync") || path.starts_with("floor")) && r["note"].is_null() {
            assert_eq!(r["epochs"], 15, "{r}");
            assert_eq!(
                (r["received"].as_u64(), r["extra"].as_u64()),
                (Some(15), Some(0)),
                "one fix per epoch: {r}"
            );
        }
        match (f("p50_ms"), f("p90_ms"), f("p99_ms"), f("max_ms")) {
            (Some(a), Some(b), Some(c), Some(d)) => assert!(0.0 < a && a <= b && b <= c && c <= d, "{r}"),
            _ => assert!(r["note"].is_string(), "no figures and no reason: {r}"),
        }
    }
    env.finish();
}

#[test]
fn zenoh_benchmark_crosses_two_namespaces() {
    let _alone = navsync_tests::alone();
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        println!("SKIPPED: navsync-bench zenoh needs root for network namespaces");
        return;
    }
    let env = TestEnv::new("benchz");
    let r = run_json(&env, &["zenoh"], &env.dir.join("zenoh.json"));
    let cases = r["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 2, "{r}");
    for c in cases {
        assert!(c["received"].as_u64().unwrap() > 0, "{c}");
        assert!(c["received"].as_u64() <= c["sent"].as_u64(), "{c}");
        percentiles_sane(&c["latency"], "zenoh");
        assert!(c["bridge_a_cpu_us_per_msg"].as_f64().unwrap() >= 0.0, "{c}");
    }
}

/// `bench/examples/receive_cost.rs` (built by `cargo test --workspace`): three rows of
/// positive costs, and nothing of its prefix left in `/dev/shm`.
#[test]
fn receive_cost_example_reports_and_cleans_up() {
    let _alone = navsync_tests::alone();
    let child = std::process::Command::new(workspace_example("receive_cost"))
        .arg("2000")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let pid = child.id();
    let o = child.wait_with_output().unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{}\n{out}\n{}",
        o.status,
        String::from_utf8_lossy(&o.stderr)
    );
    println!("{out}");
    let rows: Vec<&str> = out
        .lines()
        .filter(|l| l.starts_with("| ") && !l.starts_with("| round"))
        .collect();
    assert_eq!(rows.len(), 3, "{out}");
    for r in rows {
        let cells: Vec<&str> = r.trim_matches('|').split('|').map(str::trim).collect();
        assert_eq!(cells.len(), 8, "{r}");
        for c in &cells[1..] {
            let v: f64 = c.split_whitespace().next().unwrap().parse().unwrap();
            assert!(v > 0.0 && v.is_finite(), "{r}");
        }
    }
    // The example's own prefix; it removes its node counter too.
    let left = prefixed_files(&format!("navsync_receive_cost_{pid}_"));
    assert!(left.is_empty(), "left behind: {left:?}");
}
