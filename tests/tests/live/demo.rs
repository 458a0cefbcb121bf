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

/// `navsync demo` on a terminal (a pseudo-terminal as its stderr, read from the master side as
/// a terminal emulator would): the children's log lines are printed above the status line,
/// never into it; the status line shows the time mapping without `NaN` and the filter's
/// state; the simulator runs as long as the demo; the stop is clean (no driver warns of a
/// vanished port); the summary lists only counters that moved and says why there is no
/// accuracy yet (the drive starts by standing still).
#[test]
fn demo_on_a_terminal_keeps_logs_above_its_status_line() {
    use std::io::Read;
    use std::process::Stdio;
    use std::time::{Duration, Instant};

    let env = TestEnv::new("demotty");
    let pty = navsync_drivers::pty::Pty::open(None).expect("a pseudo-terminal");
    let slave = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(pty.path())
        .expect("the pseudo-terminal's slave side");
    let mut child = env
        .command(&["demo", "--duration", "10", "--imus", "1"])
        // The children's start and stop lines, which a default run prints.
        .env("RUST_LOG", "info")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::from(slave))
        .spawn()
        .expect("run demo");
    let mut stdout = child.stdout.take().unwrap();
    let out = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stdout.read_to_string(&mut s);
        s
    });
    // What the terminal shows: read the master while the demo runs (a full pseudo-terminal
    // buffer would block its writes).
    let mut pty = pty;
    let mut screen = Vec::new();
    let mut buf = [0u8; 4096];
    let t0 = Instant::now();
    let status = loop {
        while let Ok(n) = pty.read(&mut buf) {
            if n == 0 {
                break;
            }
            screen.extend_from_slice(&buf[..n]);
        }
        if let Some(st) = child.try_wait().unwrap() {
            break st;
        }
        assert!(t0.elapsed() < Duration::from_secs(90), "demo did not stop");
        std::thread::sleep(Duration::from_millis(20));
    };
    while let Ok(n) = pty.read(&mut buf) {
        if n == 0 {
            break;
        }
        screen.extend_from_slice(&buf[..n]);
    }
    let stdout = out.join().unwrap();
    let screen = String::from_utf8_lossy(&screen).to_string();
    assert!(status.success(), "demo failed: {status}\n{screen}\n{stdout}");

    // Each line as it stays on the screen: what follows its last clear-line.
    let visible: Vec<&str> = screen
        .split('\n')
        .map(|l| l.rsplit("\x1b[2K").next().unwrap_or(l).trim_start_matches('\r'))
        .collect();
    let status_lines: Vec<&&str> = visible.iter().filter(|l| l.contains("] imu ")).collect();
    assert!(!status_lines.is_empty(), "no status line on the terminal:\n{screen}");
    for l in &visible {
        assert!(
            !(l.contains("] imu ") && l.contains(" INFO ")),
            "a log line inside the status line: {l:?}"
        );
    }
    assert!(
        screen.contains("] imu ") && screen.contains(" nav aligning"),
        "the status line shows the filter's state:\n{screen}"
    );
    assert!(!screen.contains("NaN"), "NaN on the terminal:\n{screen}");
    assert!(
        screen.contains("sim: ") && screen.contains("duration_s=12"),
        "the simulator runs as long as the demo (10 s + 2):\n{screen}"
    );
    assert!(
        !screen.contains("WARN") && !screen.contains("reopening"),
        "a warning at a clean stop:\n{screen}"
    );
    for l in stdout.lines().filter(|l| l.starts_with("health ")) {
        assert!(
            !l.split_whitespace().any(|c| c.ends_with("=0")),
            "a counter that did not move: {l}"
        );
    }
    assert!(
        stdout.contains("no accuracy yet") && stdout.contains("standing still"),
        "the summary says why there is no accuracy:\n{stdout}"
    );
    assert!(leftovers(&env.prefix).is_empty(), "left {:?}", leftovers(&env.prefix));
    env.finish();
}
