//! The robotics ecosystem's tools read navsync's recordings as they are, and navsync reads
//! theirs. With the `mcap` and `rosbags` packages from PyPI (installed here into a scratch
//! directory with pip), for the checked-in JSON recording of an earlier navsync, its
//! `navsync convert` into a ROS 2 bag, a file written by `navsync replay --estimate --out
//! --ros-std`, and one written by `navsync record --ros-std` from live services:
//! * `mcap` validates every CRC and the summary, counts every message and decodes the JSON
//!   channels with nothing but the schema in the file (tests/python/check_mcap.py);
//! * `rosbags` opens the CDR files as ROS 2 bags and deserialises every message: navsync's
//!   types with the `ros2msg` definitions in the file, the standard ones (`sensor_msgs/msg/Imu`,
//!   `NavSatFix`, `nav_msgs/msg/Odometry`, `TimeReference`) with its built-in ROS 2 Humble type
//!   store (tests/python/check_rosbag.py);
//! * counts and values equal navsync's own reader's, as `navsync echo --json` prints them
//!   (the same JSON codec), and the standard messages carry the values of the samples they
//!   come from;
//! * a bag written by rosbags (every message deserialised and serialised again by its CDR code,
//!   no navsync metadata: tests/python/write_rosbag.py) is read by navsync sample for sample,
//!   and `replay --estimate` over it gives the summary of the original.
//!
//! Needs `python3` with pip and access to PyPI; without them the test fails and says why.

use std::collections::BTreeMap;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use navsync_recording::SampleReader;
use navsync_recording::channels::{self, sample_json};
use navsync_shared::samples::AnySample;
use navsync_tests::{TestEnv, python_with};
use serde_json::Value;

fn manifest() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Runs a script of tests/python on `args`; its JSON report (stdout).
fn script(py: &Path, pythonpath: &Option<PathBuf>, name: &str, args: &[&Path]) -> String {
    let mut c = Command::new(py);
    c.arg(manifest().join("python").join(name)).args(args);
    if let Some(p) = pythonpath {
        c.env("PYTHONPATH", p);
    }
    let o = c.output().expect("running python");
    assert!(
        o.status.success(),
        "{name} {args:?} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn check(py: &Path, pythonpath: &Option<PathBuf>, name: &str, file: &Path) -> Value {
    serde_json::from_str(&script(py, pythonpath, name, &[file])).expect("report")
}

/// navsync's reader: messages per service, first and last sample (as JSON) per service.
fn ours(file: &Path) -> (BTreeMap<String, u64>, BTreeMap<String, (AnySample, AnySample)>) {
    let mut r = SampleReader::open(file).unwrap();
    let mut counts = BTreeMap::new();
    let mut ends: BTreeMap<String, (AnySample, AnySample)> = BTreeMap::new();
    while let Some(s) = r.next_sample().unwrap() {
        *counts.entry(s.service.to_string()).or_insert(0) += 1;
        let x = s.sample;
        ends.entry(s.service.to_string())
            .and_modify(|e| e.1 = x)
            .or_insert((x, x));
    }
    (counts, ends)
}

/// The navsync topics of a report, by service.
fn navsync_counts(report: &Value) -> BTreeMap<String, u64> {
    report["topics"]
        .as_object()
        .unwrap()
        .iter()
        .filter(|(k, _)| navsync_shared::services::ServiceKind::of(channels::service_of(k)).is_some())
        .map(|(k, v)| (channels::service_of(k).to_string(), v.as_u64().unwrap()))
        .collect()
}

/// Checks `file` with both packages (rosbags only for CDR files); returns the rosbags report.
fn compare(py: &Path, pythonpath: &Option<PathBuf>, file: &Path, cdr: bool) -> Option<Value> {
    let report = check(py, pythonpath, "check_mcap.py", file);
    let (counts, ends) = ours(file);
    assert_eq!(
        navsync_counts(&report),
        counts,
        "{}: messages per topic (mcap)",
        file.display()
    );
    let first_last = |r: &Value| {
        for (service, (first, last)) in &ends {
            let topic = if cdr {
                channels::topic_of(service)
            } else {
                service.clone()
            };
            assert_eq!(
                r["first"][&topic],
                sample_json(first),
                "{}: first on {topic}",
                file.display()
            );
            assert_eq!(
                r["last"][&topic],
                sample_json(last),
                "{}: last on {topic}",
                file.display()
            );
        }
    };
    if !cdr {
        assert_eq!(report["profile"], "", "{}", file.display());
        first_last(&report);
        return None;
    }
    assert_eq!(report["profile"], "ros2", "{}", file.display());
    assert_eq!(report["compression"], serde_json::json!(["zstd"]), "{}", file.display());
    let bag = check(py, pythonpath, "check_rosbag.py", file);
    assert_eq!(
        navsync_counts(&bag),
        counts,
        "{}: messages per topic (rosbags)",
        file.display()
    );
    first_last(&bag);
    println!(
        "{}: {} messages (mcap), {} topics (rosbags)",
        file.display(),
        report["messages"],
        bag["topics"].as_object().unwrap().len()
    );
    Some(bag)
}

fn close(a: &Value, b: f64) -> bool {
    a.as_f64().is_some_and(|a| (a - b).abs() <= 1e-9 * b.abs().max(1.0))
}

/// The standard messages carry the values of the samples they come from.
fn check_standard(bag: &Value, file: &Path) {
    let (_, ends) = ours(file);
    let mut seen = 0;
    for (service, (_, last)) in &ends {
        let std_topic = match last {
            AnySample::Imu(_) => service.replace("/sample", "/imu"),
            AnySample::GnssFix(_) => service.replace("/fix", "/navsatfix"),
            AnySample::Nav(_) => "navsync/nav/odometry".to_string(),
            AnySample::Time(_) => "navsync/time/reference".to_string(),
            _ => continue,
        };
        let m = &bag["last"][format!("/{std_topic}")];
        assert!(!m.is_null(), "{}: no /{std_topic}", file.display());
        match last {
            AnySample::Imu(x) => {
                assert!(close(&m["angular_velocity"]["z"], x.gyro_rps[2]), "{m}");
                assert!(close(&m["linear_acceleration"]["x"], x.accel_mps2[0]), "{m}");
                assert_eq!(m["orientation_covariance"][0], -1.0);
            }
            AnySample::GnssFix(f) => {
                assert!(
                    close(&m["latitude"], f.lat_deg) && close(&m["longitude"], f.lon_deg),
                    "{m}"
                );
                let ns = m["header"]["stamp"]["sec"].as_i64().unwrap() * 1_000_000_000
                    + m["header"]["stamp"]["nanosec"].as_i64().unwrap();
                assert_eq!(ns, f.utc_ns, "{m}");
            }
            AnySample::Nav(n) => {
                let ns = m["header"]["stamp"]["sec"].as_i64().unwrap() * 1_000_000_000
                    + m["header"]["stamp"]["nanosec"].as_i64().unwrap();
                assert_eq!(ns, n.utc_ns, "{m}");
                let q = &m["pose"]["pose"]["orientation"];
                let norm: f64 = ["x", "y", "z", "w"]
                    .iter()
                    .map(|k| q[k].as_f64().unwrap().powi(2))
                    .sum();
                assert!((norm - 1.0).abs() < 1e-9, "{m}");
                // Speed is frame-independent.
                let v = &m["twist"]["twist"]["linear"];
                let speed: f64 = ["x", "y", "z"]
                    .iter()
                    .map(|k| v[k].as_f64().unwrap().powi(2))
                    .sum::<f64>()
                    .sqrt();
                let want = n.vel_ned_mps.iter().map(|x| x * x).sum::<f64>().sqrt();
                assert!((speed - want).abs() < 1e-9, "{speed} vs {want}");
                assert_eq!(m["child_frame_id"], "base_link");
            }
            AnySample::Time(t) => {
                let ns =
                    m["time_ref"]["sec"].as_i64().unwrap() * 1_000_000_000 + m["time_ref"]["nanosec"].as_i64().unwrap();
                assert_eq!(ns, t.ref_utc_ns, "{m}");
            }
            _ => {}
        }
        seen += 1;
    }
    assert!(seen >= 2, "{}: {seen} standard topics checked", file.display());
}

#[test]
fn rosbags_and_mcap_read_every_recording_and_navsync_reads_theirs() {
    let mut env = TestEnv::new("recpython");
    let (py, pythonpath) = python_with(&env.dir, &["mcap", "rosbags"]).unwrap_or_else(|why| {
        panic!("cannot install the `mcap` and `rosbags` Python packages (needs python3, pip and PyPI): {why}")
    });

    // The JSON recording of an earlier navsync in the repository, and the same as a ROS 2 bag.
    let data = manifest().join("data/record_drive.mcap");
    compare(&py, &pythonpath, &data, false);
    let bag = env.dir.join("drive_cdr.mcap");
    let o = env
        .command(&["convert", &data.display().to_string(), &bag.display().to_string()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    compare(&py, &pythonpath, &bag, true);
    let (old, _) = ours(&data);
    let (new, _) = ours(&bag);
    assert_eq!(old, new, "convert kept every sample");

    // A file written by the offline estimator, with the standard messages.
    let nav = env.dir.join("nav.mcap");
    let o = env
        .command(&[
            "replay",
            &data.display().to_string(),
            "--estimate",
            "--out",
            &nav.display().to_string(),
            "--ros-std",
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let std = compare(&py, &pythonpath, &nav, true).unwrap();
    check_standard(&std, &nav);

    // A bag written by rosbags is read by navsync as the original.
    let rb = env.dir.join("rosbags_out");
    let n: u64 = script(&py, &pythonpath, "write_rosbag.py", &[&bag, &rb])
        .trim()
        .parse()
        .unwrap();
    let rb_file = rb.join("rosbags_out.mcap");
    let (theirs, _) = ours(&rb_file);
    assert_eq!(theirs, new, "navsync reads the rosbags-written bag sample for sample");
    assert_eq!(theirs.values().sum::<u64>(), n);
    let mut a = SampleReader::open(&bag).unwrap();
    let mut b = SampleReader::open(&rb_file).unwrap();
    while let Some(x) = a.next_sample().unwrap() {
        let (sx, xv) = (x.service.to_string(), sample_json(&x.sample));
        let y = b.next_sample().unwrap().expect("as many samples");
        assert_eq!((sx, xv), (y.service.to_string(), sample_json(&y.sample)));
    }
    // The receiver velocity sigma and the IMU model travel in navsync's channel metadata, which
    // rosbags does not write: both runs get them as flags (the recording's IMU is the
    // industrial preset).
    let vel_std = SampleReader::open(&data)
        .unwrap()
        .channel_metadata("navsync/gnss/0/fix")
        .into_iter()
        .find(|(k, _)| k == channels::META_GNSS_VEL_STD)
        .map(|(_, v)| v)
        .expect("velocity sigma in the recording");
    let summary = |file: &Path, name: &str| -> Value {
        let out = env.dir.join(name);
        let o = env
            .command(&[
                "replay",
                &file.display().to_string(),
                "--estimate",
                "--gnss-vel-std",
                &vel_std,
                "--imu-model",
                "industrial",
                "--summary-json",
                &out.display().to_string(),
            ])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let mut v: Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
        // Throughput figures are measurements of this run, not results.
        v.as_object_mut()
            .unwrap()
            .retain(|k, _| !k.ends_with("per_s") && !k.contains("wall") && k != "estimator_s");
        v
    };
    assert_eq!(summary(&rb_file, "rb.json"), summary(&bag, "bag.json"));

    // A live recording: `navsync record --ros-std` of everything while the recording is
    // replayed at x8.
    let live = env.dir.join("live.mcap");
    let log = File::create(env.dir.join("record.log")).unwrap();
    let mut recorder = env
        .command(&["record", &live.display().to_string(), "--ros-std"])
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .unwrap();
    env.wait_for_path(&live, Duration::from_secs(20));
    let o = env
        .command(&["replay", &data.display().to_string(), "--speed", "8"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The progress line ends at the recording's end, not at t+0.
    let stderr = String::from_utf8_lossy(&o.stderr);
    let last = stderr
        .lines()
        .rfind(|l| l.contains("100%"))
        .unwrap_or_else(|| panic!("no final progress line:\n{stderr}"));
    let t_end: f64 = last
        .split("t+")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no t+ in {last}"));
    assert!(t_end > 1.0, "the final progress line says t+{t_end} s: {last}");
    std::thread::sleep(Duration::from_millis(700));
    // SAFETY: signalling our own child.
    unsafe { libc::kill(recorder.id() as libc::pid_t, libc::SIGTERM) };
    let t0 = Instant::now();
    let st = loop {
        if let Some(st) = recorder.try_wait().unwrap() {
            break st;
        }
        assert!(t0.elapsed() < Duration::from_secs(20), "recorder did not stop");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(st.success(), "record: {st}\n{}", env.log("record"));
    let std = compare(&py, &pythonpath, &live, true).unwrap();
    check_standard(&std, &live);
    let (counts, _) = ours(&live);
    assert!(
        counts.get("navsync/imu/0/sample").copied().unwrap_or(0) > 1500,
        "the recorder found the replayed services late or not at all: {counts:?}"
    );
    env.assert_running();
    env.finish();
}
