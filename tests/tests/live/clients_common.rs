//! The live navsync set of the client-side tests: `navsync sim` on `tests/data/clients_drive.toml`
//! (two IMUs at 100 Hz, aligned after ~15 s, runs for two minutes), `navsync gps` on its
//! pseudo-terminal, `navsync pps --source sim` and `navsync estimator`, all in one `TestEnv`.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use navsync_shared::ipc::IpcNode;
use navsync_shared::samples::{NavState, NavStatus, TimeState, TimeStatus};
use navsync_shared::services;
use navsync_tests::TestEnv;

/// `tests/data/clients_drive.toml`.
pub fn scenario() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/clients_drive.toml")
}

/// The repository root.
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Starts sim, gps, pps and estimator (two IMUs).
pub fn start_live(env: &mut TestEnv) {
    start_live_speaking(env, "nmea");
}

/// [`start_live`] with the simulated receiver speaking `protocol` (`nmea` or `ubx`: NAV-PVT
/// epochs and TIM-TP time pulses), read by `navsync gnss --protocol auto`.
pub fn start_live_speaking(env: &mut TestEnv, protocol: &str) {
    start_live_with(env, protocol, &[]);
}

/// [`start_live_speaking`] with more flags for the estimator.
pub fn start_live_with(env: &mut TestEnv, protocol: &str, estimator_flags: &[&str]) {
    let link = env.dir.join("gnss0");
    let link_s = link.display().to_string();
    let scen = scenario().display().to_string();
    let mut args = vec!["estimator", "--gnss", "0", "--pps", "0", "--imus", "0,1"];
    args.extend_from_slice(estimator_flags);
    env.spawn("estimator", &args);
    env.spawn("pps", &["pps", "--source", "sim", "--id", "0"]);
    env.spawn(
        "sim",
        &[
            "sim",
            "--scenario",
            &scen,
            "--pty-link",
            &link_s,
            "--gnss-protocol",
            protocol,
        ],
    );
    env.wait_for_path(&link, Duration::from_secs(20));
    env.spawn(
        "gnss",
        &[
            "gnss",
            "--port",
            &link_s,
            "--baud",
            "115200",
            "--id",
            "0",
            "--protocol",
            "auto",
        ],
    );
}

/// Waits until the time mapping is locked and (with `aligned`) the filter is aligned; the last
/// time and navigation states.
pub fn wait_ready(env: &mut TestEnv, node: &IpcNode, aligned: bool, timeout: Duration) -> (TimeState, NavState) {
    let time = node.subscriber::<TimeState>(services::TIME_STATE).unwrap();
    let nav = node.subscriber::<NavState>(services::NAV_STATE).unwrap();
    let t0 = Instant::now();
    let (mut t, mut n) = (None, None);
    loop {
        while let Some(x) = time.receive().unwrap() {
            t = Some(x);
        }
        while let Some(x) = nav.receive().unwrap() {
            n = Some(x);
        }
        let locked = t.is_some_and(|t| t.status() == TimeStatus::Locked);
        let ok = n.is_some_and(|n| !aligned || n.status == NavStatus::Aligned as u8);
        if locked && ok {
            return (t.unwrap(), n.unwrap());
        }
        env.assert_running();
        assert!(
            t0.elapsed() < timeout,
            "not ready within {timeout:?}: time {:?}, nav status {:?}\nestimator log:\n{}",
            t.map(|t| t.status()),
            n.map(|n| n.status),
            env.log("estimator")
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Runs `navsync ARGS` in the environment to the end; its stdout (panics with stderr on failure).
pub fn run_ok(env: &TestEnv, args: &[&str]) -> String {
    let o = env
        .command(args)
        .output()
        .unwrap_or_else(|e| panic!("navsync {args:?}: {e}"));
    assert!(
        o.status.success(),
        "navsync {args:?}: {}\n{}",
        o.status,
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8(o.stdout).expect("utf-8 output")
}

/// A command with this environment's prefix for a program other than navsync.
pub fn command_in(env: &TestEnv, program: impl AsRef<std::ffi::OsStr>) -> Command {
    let mut c = Command::new(program);
    c.env(services::PREFIX_ENV, &env.prefix);
    c
}
