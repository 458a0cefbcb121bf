//! Foxglove's live protocol: `navsync web --foxglove-listen` on the live simulated pipeline, and
//! the Foxglove WebSocket client Foxglove and Lichtblick use (the npm package
//! `@foxglove/ws-protocol` with `ws`, run with node: tests/js/foxglove_client.js). It must see
//! NavState and IMU channels advertised with the recordings' schemas (ros2msg, CDR), subscribe,
//! and receive messages that navsync's own CDR decoder turns into exactly the samples this
//! test receives over iceoryx2 (matched by sequence number).
//!
//! Needs node and npm with the registry reachable (the packages go into the test's scratch
//! directory); without them the test says why and returns.

use std::collections::HashMap;
use std::process::{Command, Stdio};
use std::time::Duration;

use navsync_recording::channels::{ChannelType, Codec, decode, topic_of};
use navsync_shared::samples::{AnySample, ImuSample, NavState};
use navsync_shared::services::{self, ServiceKind};
use navsync_tests::TestEnv;
use serde_json::Value;

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

#[test]
fn foxglove_clients_receive_the_recordings_cdr() {
    let mut env = TestEnv::new("foxglove");
    let node_dir = env.dir.join("node");
    std::fs::create_dir_all(&node_dir).expect("node dir");
    let npm = Command::new("npm")
        .args(["install", "--silent", "--no-audit", "--no-fund", "--prefix"])
        .arg(&node_dir)
        .args(["@foxglove/ws-protocol@0.8", "ws@8"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .output();
    match npm {
        Ok(o) if o.status.success() => {}
        Ok(o) => {
            println!(
                "SKIPPED: npm could not install @foxglove/ws-protocol: {}",
                String::from_utf8_lossy(&o.stderr).trim()
            );
            return;
        }
        Err(e) => {
            println!("SKIPPED: npm is not available ({e}); Debian's `npm` and `nodejs`");
            return;
        }
    }

    let link = env.dir.join("gnss0");
    let link_s = link.display().to_string();
    env.spawn(
        "sim",
        &["sim", "--pty-link", &link_s, "--imus", "1", "--duration", "90"],
    );
    env.wait_for_path(&link, Duration::from_secs(20));
    env.spawn("gnss", &["gnss", "--port", &link_s, "--baud", "115200", "--id", "0"]);
    env.spawn("pps", &["pps", "--source", "sim", "--id", "0"]);
    env.spawn("estimator", &["estimator", "--gnss", "0", "--pps", "0", "--imus", "0"]);
    let obs = env.node("observer");
    let nav_sub = obs.subscriber::<NavState>(services::NAV_STATE).unwrap();
    let imu_sub = obs.subscriber::<ImuSample>(&services::imu_sample("0")).unwrap();
    let port = free_port().to_string();
    let fox = format!("127.0.0.1:{port}");
    env.spawn("web", &["web", "--listen", "127.0.0.1:0", "--foxglove-listen", &fox]);
    // The web process discovers the services once a second.
    std::thread::sleep(Duration::from_secs(3));

    let nav_topic = topic_of(services::NAV_STATE);
    let imu_topic = topic_of(&services::imu_sample("0"));
    let topics = serde_json::to_string(&[&nav_topic, &imu_topic]).unwrap();
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("js/foxglove_client.js");
    let out = Command::new("node")
        .arg(&script)
        .arg(format!("ws://{fox}"))
        .arg(&topics)
        .arg("100")
        .env("NODE_PATH", node_dir.join("node_modules"))
        .output()
        .expect("running node");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "the Foxglove client failed ({}): {}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr),
        env.log("web")
    );
    // What navsync published meanwhile, by sequence number.
    let mut navs: HashMap<u64, NavState> = HashMap::new();
    while let Some(n) = nav_sub.receive().unwrap() {
        navs.insert(n.seq, n);
    }
    let mut imus: HashMap<u64, ImuSample> = HashMap::new();
    while let Some(s) = imu_sub.receive().unwrap() {
        imus.insert(s.stamp.seq, s);
    }

    let (mut advertised, mut matched, mut decoded) = (0, HashMap::<String, usize>::new(), 0);
    for line in stdout.lines() {
        let v: Value = serde_json::from_str(line).unwrap_or_else(|e| panic!("{e}: {line}"));
        if let Some(topic) = v["advertised"].as_str() {
            let kind = if topic == nav_topic {
                ServiceKind::NavState
            } else {
                ServiceKind::ImuSample
            };
            let enc = navsync_recording::channels::Encoding::Cdr;
            assert_eq!(v["encoding"], "cdr", "{line}");
            assert_eq!(v["schemaEncoding"], "ros2msg", "{line}");
            assert_eq!(v["schemaName"].as_str(), Some(enc.schema_name(kind).as_str()), "{line}");
            advertised += 1;
        }
        let (Some(topic), Some(data)) = (v["topic"].as_str(), v["data"].as_str()) else {
            continue;
        };
        let bytes = hex_decode(data);
        let kind = if topic == nav_topic {
            ServiceKind::NavState
        } else {
            ServiceKind::ImuSample
        };
        let sample = decode(
            ChannelType {
                kind,
                codec: Codec::Cdr,
            },
            &bytes,
        )
        .expect("navsync's decoder");
        decoded += 1;
        // Equal field for field, NaN for NaN: the same CDR bytes as the published sample's.
        let cdr = |s: &AnySample| {
            let mut out = Vec::new();
            navsync_recording::channels::Encoding::Cdr.encode(s, &mut out);
            out
        };
        let published = match sample {
            AnySample::Nav(n) => navs.get(&n.seq).map(|x| AnySample::Nav(*x)),
            AnySample::Imu(s) => imus.get(&s.stamp.seq).map(|x| AnySample::Imu(*x)),
            _ => panic!("{topic}: not the channel's type"),
        };
        let same = published.map(|p| cdr(&p) == bytes && cdr(&sample) == bytes);
        match same {
            Some(true) => *matched.entry(topic.to_string()).or_default() += 1,
            Some(false) => panic!("a {topic} message differs from the sample navsync published"),
            None => {} // published before this test subscribed, or after it drained
        }
    }
    println!("advertised {advertised}, decoded {decoded}, equal to iceoryx2's by sequence number: {matched:?}");
    assert_eq!(advertised, 2);
    assert!(decoded >= 200, "{decoded} messages");
    for t in [&nav_topic, &imu_topic] {
        assert!(matched.get(t.as_str()).copied().unwrap_or(0) >= 50, "{t}: {matched:?}");
    }
    drop((nav_sub, imu_sub, obs));
    env.finish();
}

/// The payload as node's `Buffer.toString("hex")` writes it.
fn hex_decode(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).expect("hex"))
        .collect()
}

/// A Foxglove client of this test: the handshake with the subprotocol, then every channel
/// subscribed when `subscribe`.
fn foxglove_client(addr: &str) -> Result<tungstenite::WebSocket<std::net::TcpStream>, String> {
    use tungstenite::client::IntoClientRequest;
    let stream = std::net::TcpStream::connect(addr).map_err(|e| e.to_string())?;
    let mut req = format!("ws://{addr}/")
        .into_client_request()
        .map_err(|e| e.to_string())?;
    req.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        "foxglove.websocket.v1".parse().expect("header"),
    );
    tungstenite::client(req, stream)
        .map(|(ws, _)| ws)
        .map_err(|e| e.to_string())
}

/// Hostile Foxglove clients are bounded and counted: one more than `--max-connections` is
/// closed (`foxglove_refused`), a client without the subprotocol is refused at the handshake,
/// and a client that subscribes to everything and never reads is dropped once its unsent data
/// pass the bound (`foxglove_dropped`); the estimator keeps publishing throughout.
#[test]
fn hostile_foxglove_clients_are_bounded_and_counted() {
    use tungstenite::Message;
    let mut env = TestEnv::new("foxhostile");
    env.spawn("sim", &["sim", "--imus", "2", "--duration", "90"]);
    env.spawn("estimator", &["estimator", "--imus", "0,1", "--software-sync"]);
    let fox = format!("127.0.0.1:{}", free_port());
    env.spawn(
        "web",
        &[
            "web",
            "--listen",
            "127.0.0.1:0",
            "--foxglove-listen",
            &fox,
            "--max-connections",
            "2",
            "--max-streams",
            "1",
        ],
    );
    let obs = env.node("observer");
    let mut health = navsync_tests::HealthWatch::new(&obs, &["web"]);
    let nav = obs.subscriber::<NavState>(services::NAV_STATE).unwrap();
    std::thread::sleep(Duration::from_secs(3));

    // Without the subprotocol: refused at the handshake.
    let plain = std::net::TcpStream::connect(&fox).expect("connect");
    assert!(
        tungstenite::client(format!("ws://{fox}/"), plain).is_err(),
        "a client without the subprotocol was accepted"
    );
    // Two clients are served; the third is closed.
    let mut a = foxglove_client(&fox).expect("client a");
    let _b = foxglove_client(&fox).expect("client b");
    let third = foxglove_client(&fox).and_then(|mut c| {
        c.get_ref().set_read_timeout(Some(Duration::from_secs(3))).ok();
        loop {
            match c.read() {
                Ok(Message::Close(_)) | Err(_) => return Ok(false),
                Ok(Message::Text(t)) if t.contains("serverInfo") => return Ok(true),
                Ok(_) => {}
            }
        }
    });
    assert_eq!(third, Ok(false), "a third client was served beyond --max-connections 2");
    // Client a subscribes to every channel and stops reading.
    a.get_ref().set_read_timeout(Some(Duration::from_secs(3))).ok();
    let mut subscribed = 0;
    while subscribed == 0 {
        match a.read() {
            Ok(Message::Text(t)) if t.contains("\"advertise\"") => {
                let v: Value = serde_json::from_str(t.as_str()).unwrap();
                let subs: Vec<Value> = v["channels"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .enumerate()
                    .map(|(i, c)| serde_json::json!({"id": i, "channelId": c["id"]}))
                    .collect();
                subscribed = subs.len();
                let op = serde_json::json!({"op": "subscribe", "subscriptions": subs});
                a.send(Message::text(op.to_string())).expect("subscribe");
            }
            Ok(_) => {}
            Err(e) => panic!("client a: {e}"),
        }
    }
    // Never read again: the server must drop it rather than buffer without end.
    let t0 = std::time::Instant::now();
    let mut counts = (0, 0);
    while t0.elapsed() < Duration::from_secs(60) {
        health.wait(Duration::from_secs(1));
        env.assert_running();
        counts = (
            health.counter("web", "foxglove_refused").unwrap_or(0),
            health.counter("web", "foxglove_dropped").unwrap_or(0),
        );
        if counts.0 >= 2 && counts.1 >= 1 {
            break;
        }
    }
    let mut states = 0;
    while nav.receive().unwrap().is_some() {
        states += 1;
    }
    println!(
        "subscribed to {subscribed} channels; refused {}, dropped {} after {:.1} s; {states} NavStates meanwhile",
        counts.0,
        counts.1,
        t0.elapsed().as_secs_f64()
    );
    assert!(counts.0 >= 2, "refused {} (the plain client and the third)", counts.0);
    assert!(
        counts.1 >= 1,
        "the client that never reads was not dropped\n{}",
        env.log("web")
    );
    assert!(states > 100, "the estimator stopped publishing: {states}");
    drop((nav, health, obs, a));
    env.finish();
}
