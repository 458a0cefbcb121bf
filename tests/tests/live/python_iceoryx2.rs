//! A Python program subscribes to `navsync/nav/state` with the official `iceoryx2` Python
//! package (PyPI, the 0.10 line of the Rust crate) and the generated ctypes layouts
//! (`shared/python/nav_subscriber.py`, `shared/python/navsync_types.py`), against a live estimator: the
//! service opens (same type name, size, alignment, QoS), and the states it prints are the
//! estimator's.
//!
//! The package is installed by this test with pip into a virtual environment in the test's
//! scratch directory. Without python3, pip, PyPI or a wheel for this platform the test fails
//! and says which step failed and why.

use std::time::Duration;

use crate::clients_common::{command_in, repo_root, start_live, wait_ready};
use navsync_tests::{TestEnv, python_with};
use serde_json::Value;

/// The iceoryx2 version on PyPI that matches the Rust crate (Cargo.lock: iceoryx2 0.10.0).
const ICEORYX2_PY: &str = "iceoryx2==0.10.0";

#[test]
fn a_python_iceoryx2_subscriber_reads_the_live_navigation_state() {
    let mut env = TestEnv::new("pyice");
    let (py, target) = python_with(&env.dir, &[ICEORYX2_PY]).unwrap_or_else(|why| {
        panic!("cannot install the `{ICEORYX2_PY}` Python package (needs python3, pip, PyPI and a wheel for this platform): {why}")
    });
    start_live(&mut env);
    let node = env.node("observer");
    let (_, nav) = wait_ready(&mut env, &node, true, Duration::from_secs(60));

    let mut pythonpath = repo_root().join("shared/python").display().to_string();
    if let Some(t) = &target {
        pythonpath = format!("{pythonpath}:{}", t.display());
    }
    let o = command_in(&env, &py)
        .arg(repo_root().join("shared/python/nav_subscriber.py"))
        .args(["--count", "50", "--json", "--timeout", "10"])
        .env("PYTHONPATH", pythonpath)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "python subscriber: {}\n{}",
        o.status,
        String::from_utf8_lossy(&o.stderr)
    );
    let rows: Vec<Value> = String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect();
    assert_eq!(rows.len(), 50);
    for w in rows.windows(2) {
        assert_eq!(
            w[1]["seq"].as_u64().unwrap(),
            w[0]["seq"].as_u64().unwrap() + 1,
            "states missing"
        );
        assert!(w[1]["host_ns"].as_i64() > w[0]["host_ns"].as_i64());
    }
    let first = &rows[0];
    assert_eq!(first["type_name"], "navsync.NavState.v2");
    // The Python process saw the states the estimator is publishing now.
    assert!(first["seq"].as_u64().unwrap() > nav.seq, "{first} vs seq {}", nav.seq);
    assert!((first["lat_deg"].as_f64().unwrap() - 48.137154).abs() < 0.01, "{first}");
    assert!((first["lon_deg"].as_f64().unwrap() - 11.576124).abs() < 0.01, "{first}");
    assert!((first["height_m"].as_f64().unwrap() - 567.0).abs() < 50.0, "{first}");
    assert_eq!(first["imu_ids"], serde_json::json!(["0", "1"]));
    assert_eq!(first["time_status"], "locked");
    println!("python received: {first}");
    drop(node);
    env.finish();
}
