//! Shared-memory permissions: navsync's iceoryx2 resources are not accessible to other users.
//!
//! iceoryx2 0.10 creates every shared-memory segment and file owner-only (0600, directories
//! 0750) and its per-prefix node counter world-writable (0666), which navsync tightens to 0660
//! (`shared/src/ipc.rs`). So with the services running as the `navsync` user
//! (`systemd/navsync-*.service`), a process of another user outside the `navsync` group can
//! neither create a node under navsync's prefix nor open a service: it is refused.
//!
//! The test runs `navsync sim` as the test's own user (root), checks that no resource of its
//! prefix grants anything to "others", that `navsync echo` as the same user receives a sample
//! (the positive control), and that the same `navsync echo` as `nobody` (uid/gid 65534, no
//! supplementary groups, through util-linux `setpriv`) fails without printing a sample.
//! Switching users needs root: as another user the test says why it is skipped.

use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use navsync_shared::samples::ImuSample;
use navsync_shared::services;
use navsync_tests::{TestEnv, navsync_bin, prefixed_files};

/// uid and gid of `nobody` / `nogroup` on Debian.
const OUTSIDER_ID: &str = "65534";

/// Runs a command to its end, killing it after `timeout`.
fn run_with_timeout(mut cmd: Command, timeout: Duration) -> Output {
    let mut child = cmd.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    let t0 = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t0.elapsed() > timeout {
            let _ = child.kill();
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

#[test]
fn a_subscriber_of_another_user_outside_the_group_is_refused() {
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        println!("skipped: switching to another user (setpriv) needs root; run the tests as root to check this");
        return;
    }
    if Command::new("setpriv").arg("--version").output().is_err() {
        println!("skipped: util-linux `setpriv` is not installed");
        return;
    }
    let mut env = TestEnv::new("perm");
    let scen = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/clients_drive.toml");
    env.spawn("sim", &["sim", "--scenario", &scen.display().to_string()]);
    let node = env.node("observer");
    let imu = node.subscriber::<ImuSample>(&services::imu_sample("0")).unwrap();
    let t0 = Instant::now();
    while imu.receive().unwrap().is_none() {
        env.assert_running();
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "no IMU sample from the simulator"
        );
        std::thread::sleep(Duration::from_millis(20));
    }

    // Nothing of this prefix is open to "others" (mode bits 0o007).
    let files = prefixed_files(&env.prefix);
    assert!(files.len() >= 3, "expected the simulator's resources, found {files:?}");
    for f in &files {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(f).unwrap().permissions().mode();
        assert_eq!(mode & 0o007, 0, "{} has mode {mode:o}", f.display());
    }

    let echo = ["echo", "navsync/imu/0/sample", "--count", "1", "--timeout", "5"];
    // The positive control: the owner receives a sample with the same command.
    let own = run_with_timeout(env.command(&echo), Duration::from_secs(10));
    let own_out = String::from_utf8_lossy(&own.stdout);
    assert!(
        own.status.success() && own_out.contains("gyro_rps"),
        "the owner's echo failed: {}\n{own_out}\n{}",
        own.status,
        String::from_utf8_lossy(&own.stderr)
    );

    // The outsider: uid and gid 65534, no supplementary groups, same prefix and command.
    let mut outsider = Command::new("setpriv");
    outsider
        .args(["--reuid", OUTSIDER_ID, "--regid", OUTSIDER_ID, "--clear-groups", "--"])
        .arg(navsync_bin())
        .args(echo)
        .env(services::PREFIX_ENV, &env.prefix)
        .env("RUST_BACKTRACE", "0")
        .env("RUST_LOG", "warn");
    let other = run_with_timeout(outsider, Duration::from_secs(10));
    let out = String::from_utf8_lossy(&other.stdout);
    let err = String::from_utf8_lossy(&other.stderr);
    println!(
        "as uid {OUTSIDER_ID}: {}; stderr: {}",
        other.status,
        err.lines().take(4).collect::<Vec<_>>().join(" | ")
    );
    assert!(!other.status.success(), "the outsider's echo succeeded:\n{out}");
    assert!(!out.contains("gyro_rps"), "the outsider received a sample:\n{out}");
    assert!(err.contains("Error"), "the refusal is reported: {err}");
    // The refused process left nothing behind and the simulator is unharmed.
    assert!(
        prefixed_files(&env.prefix).iter().all(|f| {
            use std::os::unix::fs::MetadataExt;
            std::fs::metadata(f).is_ok_and(|m| m.uid() == 0)
        }),
        "a resource owned by the outsider appeared"
    );
    env.assert_running();
    drop((imu, node));
    env.finish();
}
