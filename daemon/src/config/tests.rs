use navsync_estimator::nav::navigator::Navigator;
use navsync_estimator::settings::{Coupling, ReceiverOscillator, Settings};

use super::*;

const EXAMPLE: &str = include_str!("../../../systemd/navsync.toml.example");

/// The estimator's settings from `l` alone.
fn est(l: &Loaded) -> Settings {
    super::estimator::EstimatorFlags::default().settings(l).unwrap()
}

fn err(text: &str) -> ConfigError {
    Loaded::parse(text, Path::new("t.toml")).expect_err("should be rejected")
}

#[test]
fn the_example_is_valid_and_complete() {
    let l = Loaded::parse(EXAMPLE, Path::new("navsync.toml.example")).unwrap_or_else(|e| panic!("{e}"));
    let c = &l.config;
    assert_eq!(c.gnss["0"].baud, Some(Baud::Auto));
    assert_eq!(c.gnss["0"].protocol, Some(Protocol::Auto));
    assert_eq!(c.gnss["0"].configure, Some(false));
    assert_eq!(c.gnss["0"].lever_arm_m, [0.10, 0.0, -1.20]);
    assert_eq!(c.pps["0"].source.to_string(), "kernel:/dev/pps0");
    assert_eq!(c.imu["0"].axes, Some("x,-y,-z".parse().unwrap()));
    assert_eq!(c.imu["1"].mounting.rotation_deg, [0.0, 0.0, 90.0]);
    assert_eq!(c.imu["1"].mounting.lever_arm_m, [0.35, -0.20, 0.05]);
    let s = est(&l);
    assert_eq!(s.inputs.imus, vec!["0".to_string(), "1".to_string()]);
    assert_eq!(s.nav.coupling, Coupling::Loose);
    assert_eq!(s.nav.receiver_oscillator, ReceiverOscillator::Tcxo);
    assert_eq!(
        c.outputs.ntpshm,
        Some(NtpShmOutput {
            unit: 0,
            ..Default::default()
        })
    );
    assert_eq!(c.logging.level.as_deref(), Some("info"));
}

#[test]
fn empty_file_is_all_defaults() {
    let l = Loaded::parse("", Path::new("e.toml")).unwrap();
    assert_eq!(l.config, Config::default());
    assert_eq!(est(&l), Settings::default());
    assert!(l.from_file());
    assert!(!Loaded::none().from_file());
}

#[test]
fn ids_default_to_the_sections() {
    let l = Loaded::parse("[imu.b]\nsource=\"sim\"\n[imu.a]\nsource=\"sim\"\n", Path::new("x")).unwrap();
    assert_eq!(est(&l).inputs.imus, vec!["a".to_string(), "b".to_string()]);
    assert_eq!(est(&l).inputs.gnss, Settings::default().inputs.gnss);
}

#[test]
fn unknown_key_names_file_line_and_field() {
    let e = err("[imu.0]\nsource = \"sim\"\nrate = 200\n");
    assert_eq!(e.line.map(|l| l.0), Some(3), "{e}");
    assert!(e.message.contains("unknown field `rate`"), "{e}");
    assert!(e.message.contains("rate_hz"), "lists what is expected: {e}");
    assert!(e.to_string().starts_with("t.toml:3:"), "{e}");
    let e = err("[imu.0]\nsource = \"sim\"\n[estimatr]\nimus = []\n");
    assert_eq!(e.line.map(|l| l.0), Some(3), "{e}");
    assert!(e.message.contains("unknown field `estimatr`"), "{e}");
}

#[test]
fn wrong_type_names_the_field() {
    let e = err("[imu.0]\nsource = \"sim\"\nrate_hz = \"fast\"\n");
    assert_eq!(e.line, Some((3, 11)), "{e}");
    assert_eq!(e.field.as_deref(), Some("imu.0.rate_hz"), "{e}");
    assert_eq!(e.message, "expected a number, found \"fast\" (text)", "{e}");
    assert_eq!(
        e.to_string(),
        "t.toml:3:11: imu.0.rate_hz: expected a number, found \"fast\" (text)"
    );
    let e = err("[outputs.ntpshm]\nunit = -1\n");
    assert_eq!(e.message, "expected a whole number ≥ 0, found -1", "{e}");
    let e = err("[gps.0]\nport = \"/dev/x\"\nconfigure = \"yes\"\n");
    assert_eq!(e.message, "expected true or false, found \"yes\" (text)", "{e}");
    // The estimator's settings (read by their declarations) say it the same way.
    let e = err("[estimator]\ngnss_vel_std_mps = \"fast\"\n");
    assert_eq!(
        e.to_string(),
        "t.toml:2:20: estimator.gnss_vel_std_mps: expected a number, found \"fast\" (text)"
    );
    let e = err("[gps.0]\nport = \"/dev/x\"\nbaud = \"fast\"\n");
    assert_eq!(e.field.as_deref(), Some("gps.0.baud"), "{e}");
    assert!(e.message.contains("\"auto\""), "{e}");
    let e = err("[gps.0]\nport = \"/dev/x\"\nbaud = -5\n");
    assert_eq!(e.field.as_deref(), Some("gps.0.baud"), "{e}");
    let e = err("[gps.0]\nport = \"/dev/x\"\nbaud = 12345\n");
    assert_eq!(e.field.as_deref(), Some("gps.0.baud"), "{e}");
    assert!(e.message.contains("standard baud rate"), "{e}");
    assert!(e.message.ends_with("found 12345"), "{e}");
    let e = err("[gps.0]\nbaud = 9600\n");
    assert!(e.message.contains("missing field `port`"), "{e}");
    // `[gnss.ID]` is the name; `[gps.ID]` reads the same.
    let l = Loaded::parse("[gnss.0]\nport = \"/dev/x\"\nbaud = 4800\n", Path::new("x")).unwrap();
    assert_eq!(l.config.gnss["0"].baud, Some(Baud::Fixed(4800)));
    let e = err("[gnss.0]\nport = \"/dev/x\"\nprotocol = \"sirf\"\n");
    assert_eq!(e.field.as_deref(), Some("gnss.0.protocol"), "{e}");
    assert!(e.message.contains("nmea"), "{e}");
    let e = err("[imu.0]\nsource = \"spi:0\"\n");
    assert_eq!(e.field.as_deref(), Some("imu.0.source"), "{e}");
    assert!(e.message.contains("is not an IMU source"), "{e}");
    let e = err("[imu.0]\nsource = \"sim\"\naxes = \"x,y\"\n");
    assert_eq!(e.field.as_deref(), Some("imu.0.axes"), "{e}");
    let e = err("[imu.0]\nsource = \"sim\"\nmounting = { rotation_deg = [0, 0] }\n");
    assert_eq!(e.line.map(|l| l.0), Some(3), "{e}");
}

#[test]
fn serde_wording_becomes_the_readers() {
    for (serde, user) in [
        (
            "invalid type: string \"fast\", expected f64",
            "expected a number, found \"fast\" (text)",
        ),
        (
            "invalid type: integer `3`, expected a string",
            "expected text in quotes, found 3",
        ),
        (
            "invalid type: floating point `1.5`, expected u32",
            "expected a whole number ≥ 0, found 1.5",
        ),
        (
            "invalid type: boolean `true`, expected i64",
            "expected a whole number, found true",
        ),
        (
            "invalid type: sequence, expected a boolean",
            "expected true or false, found a list",
        ),
        (
            "invalid length 2, expected an array of length 3",
            "expected a list of 3 values [...], found 2",
        ),
        ("missing field `port`", "missing field `port`"),
    ] {
        assert_eq!(user_wording(serde), user, "{serde}");
    }
}

#[test]
fn syntax_error_has_a_position() {
    let e = err("[imu.0\nsource = 1\n");
    assert_eq!(e.line.map(|l| l.0), Some(1), "{e}");
}

#[test]
fn semantic_errors_are_located() {
    let e = err("[imu.0]\nsource = \"sim\"\n\nrate_hz = 0.5\n");
    assert_eq!(
        (e.line.map(|l| l.0), e.field.as_deref()),
        (Some(4), Some("imu.0.rate_hz")),
        "{e}"
    );
    assert!(e.message.contains("1 < rate"), "{e}");
    let e = err("[pps.0]\nsource = \"gpio:1\"\n");
    assert_eq!(e.line.map(|l| l.0), Some(2), "{e}");
    assert!(e.message.contains("kernel:/dev/ppsN"), "{e}");
    let e = err("[estimator]\nimus = [\"0\", \"a b\"]\n");
    assert_eq!(e.field.as_deref(), Some("estimator.imus[1]"), "{e}");
    assert_eq!(e.line.map(|l| l.0), Some(2), "{e}");
    let e = err("[estimator]\nimu_model = \"military\"\n");
    assert!(e.message.contains("`consumer`, `industrial`, `perfect`"), "{e}");
    let e = err("[logging]\nlevel = \"loud\"\n");
    assert_eq!(e.field.as_deref(), Some("logging.level"), "{e}");
    let e = err("[\"imu\".\"a b\"]\nsource = \"sim\"\n");
    assert!(e.message.contains("is not an id"), "{e}");
    let e = err("[imu.0]\nsource = \"sim\"\nmounting.lever_arm_m = [0, nan, 0]\n");
    assert_eq!(e.field.as_deref(), Some("imu.0.mounting.lever_arm_m[1]"), "{e}");
    let e = err("[ipc]\nprefix = \"a/b\"\n");
    assert_eq!(e.field.as_deref(), Some("ipc.prefix"), "{e}");
}

#[test]
fn error_at_locates_fields_for_the_roles() {
    let l = Loaded::parse("[imu.0]\nsource = \"sim:/tmp\"\n", Path::new("f.toml")).unwrap();
    let e = l.error_at("imu.0.source", "no such directory");
    assert_eq!(e.to_string(), "f.toml:2:10: imu.0.source: no such directory");
}

#[test]
fn rotation_matrix() {
    let m = Mounting {
        rotation_deg: [0.0, 0.0, 90.0],
        lever_arm_m: [0.0; 3],
    };
    let c = m.c_b_s();
    // Yaw 90°: the IMU's x axis points to the body's right (y).
    let x = [c[0][0], c[1][0], c[2][0]];
    assert!(
        (x[0]).abs() < 1e-12 && (x[1] - 1.0).abs() < 1e-12 && x[2].abs() < 1e-12,
        "{c:?}"
    );
    let id = Mounting::default().c_b_s();
    assert_eq!(id, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
}

#[test]
fn a_coupling_that_does_not_exist_names_the_field() {
    let e = err("[estimator]\ncoupling = \"tigth\"\n");
    assert_eq!(e.field.as_deref(), Some("estimator.coupling"), "{e}");
    assert!(e.message.contains("tight"), "lists what is expected: {e}");
}

#[test]
fn the_coupling_flows_flag_over_file_over_default() {
    let mut flags = super::estimator::EstimatorFlags::default();
    let s = flags.settings(&Loaded::none()).unwrap();
    assert_eq!(
        (s.nav.coupling, s.nav.receiver_oscillator),
        (Coupling::Loose, ReceiverOscillator::Tcxo)
    );
    assert!(
        Navigator::new(s.pipeline_config().nav).config().noise.clock.is_none(),
        "loose: the clock states are frozen"
    );
    let file = Loaded::parse(
        "[estimator]\ncoupling = \"tight\"\nreceiver_oscillator = \"crystal\"\n",
        Path::new("f.toml"),
    )
    .unwrap();
    let s = flags.settings(&file).unwrap();
    assert_eq!(
        (s.nav.coupling, s.nav.receiver_oscillator),
        (Coupling::Tight, ReceiverOscillator::Crystal)
    );
    assert!(Navigator::new(s.pipeline_config().nav).config().noise.clock.is_some());
    assert!(s.input_services().iter().any(|x| x.ends_with("/raw")));
    flags.given.push(("coupling", "loose".into()));
    assert_eq!(flags.settings(&file).unwrap().nav.coupling, Coupling::Loose);
}

#[test]
fn only_a_regular_file_of_bounded_size_is_read() {
    // A device and a directory: refused without reading (/dev/zero never ends).
    for p in ["/dev/zero", "/dev/urandom", "/"] {
        let e = Loaded::load(Path::new(p)).unwrap_err();
        assert!(e.message.contains("not a regular file"), "{p}: {e}");
    }
    let dir = std::env::temp_dir().join(format!("navsync-config-bounds-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // A FIFO with no writer: refused at once, not waited on.
    let fifo = dir.join("fifo.toml");
    let c = std::ffi::CString::new(fifo.display().to_string()).unwrap();
    // SAFETY: mkfifo with a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let t0 = std::time::Instant::now();
    let e = Loaded::load(&fifo).unwrap_err();
    assert!(e.message.contains("not a regular file"), "{e}");
    assert!(t0.elapsed() < std::time::Duration::from_secs(1));
    // Larger than the bound.
    let big = dir.join("big.toml");
    std::fs::write(&big, vec![b'#'; MAX_FILE_BYTES as usize + 1]).unwrap();
    let e = Loaded::load(&big).unwrap_err();
    assert!(e.message.contains("more than"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_huge_value_is_cut_in_the_error() {
    let value = "x".repeat(10 << 20);
    let e = err(&format!("[imu.0]\nsource = \"{value}\"\n"));
    let shown = e.to_string();
    assert!(shown.len() < 1000, "{} bytes shown", shown.len());
    assert!(shown.contains("more characters"), "{shown}");
    assert!(shown.starts_with("t.toml:2:"), "{shown}");
}
