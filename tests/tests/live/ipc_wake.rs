//! navsync's futex wake-ups (`shared/src/ipc/futex.rs`) between nodes: a subscriber asleep on
//! its service's event gets the sample a publisher on another node sends, a process with many
//! inputs is woken once by `navsync/wake` and told which kinds fired, and a wait that nothing
//! wakes ends empty. Each node lives on its own thread (iceoryx2 ports are single-threaded);
//! the shared memory and the futex word are the same as between processes.

use std::sync::mpsc;
use std::time::Duration;

use navsync_shared::ipc::IpcNode;
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::{GnssFix, ImuSample};
use navsync_shared::services::{self, ServiceKind};
use navsync_tests::TestEnv;

/// Publishes `n` IMU samples on `imu/0` from a node of its own once `go` says so, and keeps
/// its publisher until `go` says so again (a publisher that leaves takes its unread samples).
fn imu_publisher(prefix: String, go: mpsc::Receiver<()>, n: u64) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let node = IpcNode::with_prefix("pub", &prefix).unwrap();
        let mut p = node.publisher::<ImuSample>(&services::imu_sample("0")).unwrap();
        go.recv().unwrap();
        for seq in 0..n {
            let mut s = ImuSample::zeroed();
            s.stamp.seq = seq;
            p.publish(&s).unwrap();
            std::thread::sleep(Duration::from_millis(2));
        }
        let _ = go.recv();
    })
}

#[test]
fn a_sleeping_subscriber_is_woken_by_each_sample() {
    let env = TestEnv::new("ipcwake1");
    let node = IpcNode::with_prefix("sub", &env.prefix).unwrap();
    let sub = node.subscriber::<ImuSample>(&services::imu_sample("0")).unwrap();
    // Nothing published: the wait ends empty.
    assert!(sub.wait_next(Duration::from_millis(120)).unwrap().is_none());
    let (go, rx) = mpsc::channel();
    let t = imu_publisher(env.prefix.clone(), rx, 50);
    go.send(()).unwrap();
    let mut seqs = Vec::new();
    while let Some(s) = sub.wait_next(Duration::from_secs(5)).unwrap() {
        seqs.push(s.stamp.seq);
        if s.stamp.seq == 49 {
            break;
        }
    }
    go.send(()).unwrap();
    t.join().unwrap();
    assert_eq!(
        seqs,
        (0..50).collect::<Vec<_>>(),
        "every sample, in order, each after a wake-up"
    );
    drop((sub, node));
    env.finish();
}

#[test]
fn one_wake_up_for_many_inputs_names_the_kinds() {
    let env = TestEnv::new("ipcwake2");
    let node = IpcNode::with_prefix("multi", &env.prefix).unwrap();
    let imu = node.input::<ImuSample>(&services::imu_sample("0")).unwrap();
    let fix = node.input::<GnssFix>(&services::gnss_fix("0")).unwrap();
    let wake = node.wake().unwrap();
    // An input has no wake-up of its own.
    assert!(imu.wait_next(Duration::from_millis(1)).is_err());
    assert!(node.wait(&wake, Duration::from_millis(100)).unwrap());
    assert_eq!(wake.fired(), 0, "a timeout fires nothing");

    let (go, rx) = mpsc::channel();
    let prefix = env.prefix.clone();
    let t = std::thread::spawn(move || {
        let node = IpcNode::with_prefix("gps", &prefix).unwrap();
        let mut p = node.publisher::<GnssFix>(&services::gnss_fix("0")).unwrap();
        rx.recv().unwrap();
        p.publish(&GnssFix::zeroed()).unwrap();
        let _ = rx.recv();
    });
    go.send(()).unwrap();
    let mut fired = 0;
    while fired == 0 {
        assert!(node.wait(&wake, Duration::from_secs(5)).unwrap());
        fired = wake.fired();
    }
    assert!(wake.fired_kind(ServiceKind::GnssFix), "fired {fired:#b}");
    assert!(!wake.fired_kind(ServiceKind::ImuSample), "fired {fired:#b}");
    assert_eq!(fix.drain(|_| true).unwrap(), 1);
    assert_eq!(imu.drain(|_| true).unwrap(), 0);
    go.send(()).unwrap();
    t.join().unwrap();

    // Busy polling sees the same samples.
    wake.set_busy_poll(true);
    let (go, rx) = mpsc::channel();
    let t = imu_publisher(env.prefix.clone(), rx, 5);
    go.send(()).unwrap();
    let mut n = 0;
    while n < 5 {
        assert!(node.wait(&wake, Duration::from_secs(5)).unwrap());
        if wake.fired_kind(ServiceKind::ImuSample) {
            n += imu.drain(|_| true).unwrap();
        }
    }
    go.send(()).unwrap();
    t.join().unwrap();
    drop((imu, fix, wake, node));
    env.finish();
}
