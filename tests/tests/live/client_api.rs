//! The Rust client API (`navsync_shared::client`) and its example program
//! (`shared/examples/nav_subscriber.rs`) against a live estimator: blocking waits with a
//! timeout, the latest state with a staleness check, any sensor service, and what happens when
//! the publisher stops.

use std::time::Duration;

use crate::clients_common::{command_in, start_live, wait_ready};
use navsync_shared::client::{Client, ClientError, NavClient};
use navsync_shared::ipc::IpcNode;
use navsync_shared::samples::{ImuSample, NavState};
use navsync_shared::services;
use navsync_tests::{TestEnv, workspace_example};

#[test]
fn clients_wait_check_staleness_and_notice_a_stopped_publisher() {
    let mut env = TestEnv::new("client");
    start_live(&mut env);
    let node = env.node("observer");
    wait_ready(&mut env, &node, true, Duration::from_secs(60));

    let mut nav = NavClient::with_node(
        IpcNode::with_prefix("nav-client", &env.prefix).unwrap(),
        services::NAV_STATE,
    )
    .unwrap();
    let first = nav.next(Duration::from_secs(5)).unwrap().expect("a state within 5 s");
    let second = nav.next(Duration::from_secs(5)).unwrap().expect("another state");
    assert_eq!(second.seq, first.seq + 1, "next() yields every state in order");
    assert!((first.lat_deg - 48.137154).abs() < 0.01);
    // A 100 Hz stream: the newest state is fresh.
    std::thread::sleep(Duration::from_millis(100));
    let latest = nav.latest(Duration::from_millis(500)).unwrap().expect("a fresh state");
    assert!(latest.seq > second.seq);
    let (_, age) = nav.latest_with_age().unwrap().unwrap();
    assert!(age < Duration::from_millis(500), "{age:?}");
    assert!(
        nav.wait_fresh(Duration::from_millis(500), Duration::from_secs(2))
            .unwrap()
            .is_some()
    );

    // Any sensor service, with its sample type.
    let mut imu = Client::<ImuSample>::with_node(
        IpcNode::with_prefix("imu-client", &env.prefix).unwrap(),
        &services::imu_sample("1"),
    )
    .unwrap();
    let s = imu.next(Duration::from_secs(5)).unwrap().expect("an IMU sample");
    assert_eq!(navsync_shared::reflect::str_of(&s.imu_id), "1");
    // A service that carries another type is refused.
    let e = Client::<NavState>::with_node(
        IpcNode::with_prefix("bad-client", &env.prefix).unwrap(),
        &services::imu_sample("0"),
    )
    .err()
    .expect("refused");
    assert!(matches!(e, ClientError::WrongService { .. }), "{e}");

    // The example program prints states and exits after --count.
    let example = workspace_example("nav_subscriber");
    let o = command_in(&env, &example).args(["--count", "5"]).output().unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{}\n{out}\n{}",
        o.status,
        String::from_utf8_lossy(&o.stderr)
    );
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), 6, "{out}");
    assert!(lines[0].starts_with("seq ") && lines[0].contains(" lat 48.13"), "{out}");
    assert!(lines[5].starts_with("5 states printed"), "{out}");

    // The estimator stops: the latest state turns stale and waits time out.
    env.signal("estimator", libc::SIGTERM);
    std::thread::sleep(Duration::from_millis(1500));
    while nav.try_next().unwrap().is_some() {}
    assert!(
        nav.latest(Duration::from_millis(500)).unwrap().is_none(),
        "stale state reported fresh"
    );
    let (_, age) = nav.latest_with_age().unwrap().expect("the last state is kept");
    assert!(age >= Duration::from_millis(500), "{age:?}");
    assert!(nav.next(Duration::from_millis(300)).unwrap().is_none());
    println!(
        "received {} states; last state {age:?} old after the estimator stopped",
        nav.received()
    );
    drop((nav, imu, node));
    env.finish();
}
