//! The standard MCAP tooling reads navsync's recordings: the `mcap` package from PyPI (installed
//! here into a scratch directory with pip) opens the checked-in simulator recording, a file
//! written by `navsync replay --estimate`, and one written by `navsync record` from live
//! services, validates every CRC and the summary, and decodes every message with nothing but
//! the JSON schema stored in the file (tests/python/check_mcap.py). The counts and the decoded
//! values agree with navsync's own reader.
//!
//! Needs `python3` with pip and access to PyPI; without them the test fails and says why.

use std::collections::BTreeMap;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use navsync_recording::SampleReader;
use navsync_recording::channels::sample_json;
use navsync_tests::{TestEnv, python_with};
use serde_json::Value;

fn manifest() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Runs check_mcap.py on `file`; its JSON report.
fn check(py: &Path, pythonpath: &Option<PathBuf>, file: &Path) -> Value {
    let mut c = Command::new(py);
    c.arg(manifest().join("python/check_mcap.py")).arg(file);
    if let Some(p) = pythonpath {
        c.env("PYTHONPATH", p);
    }
    let o = c.output().expect("running python");
    assert!(
        o.status.success(),
        "the mcap package rejected {}: {}",
        file.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).expect("report")
}

/// navsync's reader: messages per topic, first and last sample (as JSON) per topic.
fn ours(file: &Path) -> (BTreeMap<String, u64>, BTreeMap<String, (Value, Value)>) {
    let mut r = SampleReader::open(file).unwrap();
    let mut counts = BTreeMap::new();
    let mut ends: BTreeMap<String, (Value, Value)> = BTreeMap::new();
    while let Some(s) = r.next_sample().unwrap() {
        *counts.entry(s.service.to_string()).or_insert(0) += 1;
        let v = sample_json(&s.sample);
        ends.entry(s.service.to_string())
            .and_modify(|e| e.1 = v.clone())
            .or_insert((v.clone(), v));
    }
    (counts, ends)
}

fn compare(py: &Path, pythonpath: &Option<PathBuf>, file: &Path) -> u64 {
    let report = check(py, pythonpath, file);
    let (counts, ends) = ours(file);
    let theirs: BTreeMap<String, u64> = report["topics"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(k, v)| (k.clone(), v.as_u64().unwrap()))
        .collect();
    assert_eq!(theirs, counts, "{}: messages per topic", file.display());
    for (topic, (first, last)) in &ends {
        assert_eq!(&report["first"][topic], first, "{}: first on {topic}", file.display());
        assert_eq!(&report["last"][topic], last, "{}: last on {topic}", file.display());
    }
    report["messages"].as_u64().unwrap()
}

#[test]
fn the_mcap_package_reads_and_decodes_every_recording() {
    let mut env = TestEnv::new("recpython");
    let (py, pythonpath) = python_with(&env.dir, &["mcap"])
        .unwrap_or_else(|why| panic!("cannot install the `mcap` Python package (needs python3, pip and PyPI): {why}"));

    // The simulator recording in the repository.
    let data = manifest().join("data/record_drive.mcap");
    let n = compare(&py, &pythonpath, &data);
    println!("{}: {n} messages", data.display());

    // A file written by the offline estimator.
    let nav = env.dir.join("nav.mcap");
    let o = env
        .command(&[
            "replay",
            &data.display().to_string(),
            "--estimate",
            "--out",
            &nav.display().to_string(),
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let n = compare(&py, &pythonpath, &nav);
    println!("{}: {n} messages", nav.display());

    // A live recording: `navsync record` of everything while the recording is replayed at x8.
    let live = env.dir.join("live.mcap");
    let log = File::create(env.dir.join("record.log")).unwrap();
    let mut recorder = env
        .command(&["record", &live.display().to_string()])
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
    let n = compare(&py, &pythonpath, &live);
    println!("{}: {n} messages", live.display());
    let (counts, _) = ours(&live);
    assert!(
        counts.get("navsync/imu/0/sample").copied().unwrap_or(0) > 1500,
        "the recorder found the replayed services late or not at all: {counts:?}"
    );
    env.assert_running();
    env.finish();
}
