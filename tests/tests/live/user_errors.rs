//! A user's mistake is one message in the user's words: with `RUST_BACKTRACE=1` in the
//! environment (common among Rust users) a configuration or flag error prints no backtrace
//! (only `-v` or `RUST_LOG=debug` add it); a wrong type is "expected a number", not serde's
//! "expected f64"; a baud rate that is not a standard one is refused, in the file and on the
//! command line.

use navsync_tests::TestEnv;

/// `navsync ARGS` with `envs`; (success, stderr).
fn run(env: &TestEnv, envs: &[(&str, &str)], args: &[&str]) -> (bool, String) {
    let o = env
        .command(args)
        .envs(envs.iter().copied())
        .output()
        .expect("running navsync");
    (o.status.success(), String::from_utf8_lossy(&o.stderr).into_owned())
}

#[test]
fn a_configuration_error_is_one_message_in_the_users_words_without_a_backtrace() {
    let env = TestEnv::new("usererr");
    let file = env.dir.join("navsync.toml");
    std::fs::write(&file, "[imu.0]\nsource = \"sim\"\nrate_hz = \"fast\"\n").unwrap();
    let f = file.to_str().unwrap();
    let wanted = format!("{f}:3:11: imu.0.rate_hz: expected a number, found \"fast\" (text)");
    let bt = [("RUST_BACKTRACE", "1")];
    // Through check-config and through a role that reads the file.
    for args in [
        &["--config", f, "check-config"][..],
        &["--config", f, "echo", "navsync/nav/state"],
    ] {
        let (ok, err) = run(&env, &bt, args);
        assert!(!ok, "{args:?} accepted");
        assert!(err.contains(&wanted), "{args:?}: {err}");
        assert!(!err.contains("f64"), "Rust's wording: {err}");
        assert!(
            !err.contains("acktrace") && !err.contains("main.rs"),
            "a backtrace: {err}"
        );
        assert!(err.lines().count() <= 2, "{err}");
    }
    // -v and RUST_LOG=debug show it (when one was captured: RUST_BACKTRACE=1).
    let (ok, err) = run(&env, &bt, &["-v", "--config", f, "check-config"]);
    assert!(!ok && err.contains(&wanted) && err.contains("Backtrace"), "{err}");
    let (ok, err) = run(
        &env,
        &[("RUST_BACKTRACE", "1"), ("RUST_LOG", "debug")],
        &["--config", f, "check-config"],
    );
    assert!(!ok && err.contains("Backtrace"), "{err}");
    // The estimator's settings say it the same way.
    std::fs::write(&file, "[estimator]\ngnss_vel_std_mps = \"fast\"\n").unwrap();
    let (ok, err) = run(&env, &bt, &["--config", f, "check-config"]);
    assert!(
        !ok && err.contains("estimator.gnss_vel_std_mps: expected a number, found \"fast\" (text)"),
        "{err}"
    );
    assert!(!err.contains("acktrace"), "{err}");
    let _ = std::fs::remove_dir_all(&env.dir);
}

#[test]
fn a_number_flag_says_what_it_expected() {
    let env = TestEnv::new("flagnum");
    for (args, wanted) in [
        (
            &["echo", "navsync/nav/state", "--count", "x"][..],
            "expected a whole number",
        ),
        (&["echo", "navsync/nav/state", "--rate", "fast"], "expected a number"),
        (&["estimator", "--gnss-vel-std", "fast"], "is not a number"),
    ] {
        let (ok, err) = run(&env, &[("RUST_BACKTRACE", "1")], args);
        assert!(!ok, "{args:?} accepted");
        assert!(err.contains(wanted), "{args:?}: {err}");
        assert!(
            !err.contains("invalid digit") && !err.contains("float literal"),
            "Rust's wording: {err}"
        );
        assert!(!err.contains("acktrace"), "{err}");
    }
    // Help is still help, on stdout, with success.
    let o = env.command(&["echo", "--help"]).output().unwrap();
    assert!(o.status.success() && String::from_utf8_lossy(&o.stdout).contains("--raw"));
}

#[test]
fn only_standard_baud_rates_are_accepted() {
    let env = TestEnv::new("baud");
    let file = env.dir.join("navsync.toml");
    std::fs::write(&file, "[gnss.0]\nport = \"/dev/null\"\nbaud = 12345\n").unwrap();
    let f = file.to_str().unwrap();
    let (ok, err) = run(&env, &[], &["--config", f, "check-config"]);
    assert!(!ok, "baud = 12345 accepted");
    assert!(
        err.contains("gnss.0.baud") && err.contains("standard baud rate") && err.contains("12345"),
        "{err}"
    );
    std::fs::write(&file, "[gnss.0]\nport = \"/dev/null\"\nbaud = 115200\n").unwrap();
    let (ok, err) = run(&env, &[], &["--config", f, "check-config"]);
    assert!(ok, "a standard rate refused: {err}");
    for args in [
        &["gnss", "--port", "/dev/null", "--baud", "12345"][..],
        &["imu", "--source", "xsens:/dev/null:12345"],
        &["feed", "/dev/null", "--baud", "12345"],
    ] {
        let (ok, err) = run(&env, &[("RUST_BACKTRACE", "1")], args);
        assert!(!ok, "{args:?} accepted");
        assert!(
            err.contains("12345") && err.contains("standard baud rate"),
            "{args:?}: {err}"
        );
        assert!(!err.contains("acktrace"), "{err}");
    }
    let _ = std::fs::remove_dir_all(&env.dir);
}
