//! `navsync demo` starts its children, stops them cleanly at the end of `--duration`, prints a
//! summary, leaves no shared memory behind, and a second demo right after the first works.

use navsync_tests::{TestEnv, leftovers};

#[test]
fn demo_runs_twice_in_a_row_and_cleans_up() {
    let env = TestEnv::new("demo");
    for round in 1..=2 {
        let out = env
            .command(&["demo", "--duration", "8", "--imus", "2"])
            .output()
            .expect("run demo");
        let stdout = String::from_utf8_lossy(&out.stdout);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            out.status.success(),
            "demo round {round} failed: {}\n{stdout}\n{stderr}",
            out.status
        );
        assert!(stdout.contains("=== navsync demo summary ==="), "{stdout}");
        for service in [
            "navsync/imu/0/sample",
            "navsync/imu/1/sample",
            "navsync/pps/0/edge",
            "navsync/gnss/0/fix",
        ] {
            let line = stdout
                .lines()
                .find(|l| l.starts_with(service))
                .unwrap_or_else(|| panic!("{service} missing:\n{stdout}"));
            let n: u64 = line.split_whitespace().last().and_then(|v| v.parse().ok()).unwrap_or(0);
            assert!(n > 0, "round {round}: no samples on {service}:\n{stdout}");
        }
        // The IMUs run through the Xsens path by default: one `navsync imu` per IMU.
        for child in ["sim", "gnss", "estimator", "imu0", "imu1"] {
            assert!(
                stdout.contains(&format!("{child}: exit status: 0")),
                "round {round}: {child} did not exit cleanly:\n{stdout}"
            );
        }
        assert!(
            leftovers(&env.prefix).is_empty(),
            "round {round} left {:?}",
            leftovers(&env.prefix)
        );
    }
    env.finish();
}
