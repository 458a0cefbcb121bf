//! A wait without a timeout (`Subscriber::wait_next(Duration::MAX)`: no kernel timer armed
//! per wait) ends on a sample, and on a SIGTERM delivered to *another* thread of the process
//! (the handler chained in front of iceoryx2's wakes every untimed sleeper). A process of its own
//! (`in_own_process!`): the signal goes to the whole process.

use std::time::{Duration, Instant};

use navsync_shared::ipc::IpcNode;
use navsync_shared::reflect::Reflect;
use navsync_shared::samples::ImuSample;
use navsync_shared::services;
use navsync_tests::TestEnv;

#[test]
fn untimed_wait_ends_on_a_sample_and_on_sigterm_to_another_thread() {
    if !navsync_tests::in_own_process!() {
        return;
    }
    let env = TestEnv::new("termuntimed");
    let node = IpcNode::with_prefix("sleeper", &env.prefix).expect("node");
    let service = services::imu_sample("0");
    let sub = node.subscriber::<ImuSample>(&service).unwrap();

    // A sample published 200 ms later, from a node of another thread, ends the wait.
    let prefix = env.prefix.clone();
    let publisher = std::thread::spawn(move || {
        let node = IpcNode::with_prefix("publisher", &prefix).expect("node");
        let mut p = node.publisher::<ImuSample>(&service).unwrap();
        std::thread::sleep(Duration::from_millis(200));
        let mut s = ImuSample::zeroed();
        s.stamp.seq = 7;
        p.publish(&s).unwrap();
        // Keep the publisher until the sample was taken.
        std::thread::sleep(Duration::from_millis(500));
    });
    let got = sub
        .wait_next(Duration::MAX)
        .unwrap()
        .expect("a sample, not a termination");
    // The handler is chained (not the 50 ms slices of the fallback).
    assert!(navsync_shared::ipc::futex::termination_wakes_sleepers());
    assert_eq!(got.stamp.seq, 7);
    publisher.join().unwrap();
    assert!(!node.termination_requested());

    // SIGTERM raised on another thread (delivered there, not to this one) ends the wait.
    let signaller = std::thread::spawn(|| {
        std::thread::sleep(Duration::from_millis(300));
        // SAFETY: raising a signal in our own process; the node's handler catches it.
        unsafe { libc::raise(libc::SIGTERM) };
    });
    let t0 = Instant::now();
    assert!(
        sub.wait_next(Duration::MAX).unwrap().is_none(),
        "only a termination ends it"
    );
    let waited = t0.elapsed();
    signaller.join().unwrap();
    assert!(waited < Duration::from_secs(5), "waited {waited:?}");
    assert!(node.termination_requested());
    // Once requested, an untimed wait returns at once.
    assert!(sub.wait_next(Duration::MAX).unwrap().is_none());
    drop((sub, node));
    env.finish();
}
