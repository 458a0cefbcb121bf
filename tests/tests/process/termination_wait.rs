//! A SIGTERM that arrives while a navsync process sleeps in a timed futex wait ends the
//! wait: the signal reaches one thread (here the signaller, not the sleeper) and iceoryx2's
//! handler only records it, so every timed wait looks at the termination latch at least
//! every `ipc::WAIT_SLICE` (`termination_untimed.rs`: waits without a timeout). A process of its own (`in_own_process!`): the signal goes to the whole process.

use std::time::{Duration, Instant};

use navsync_shared::ipc::{IpcNode, WAIT_SLICE};
use navsync_shared::samples::ImuSample;
use navsync_shared::services;
use navsync_tests::TestEnv;

#[test]
fn sigterm_ends_a_long_wait() {
    if !navsync_tests::in_own_process!() {
        return;
    }
    let env = TestEnv::new("termwait");
    let node = IpcNode::with_prefix("sleeper", &env.prefix).expect("node");
    let sub = node.subscriber::<ImuSample>(&services::imu_sample("0")).unwrap();
    let wake = node.wake().unwrap();
    let signaller = std::thread::spawn(|| {
        std::thread::sleep(Duration::from_millis(300));
        // SAFETY: raising a signal in our own process; the node's handler catches it.
        unsafe { libc::raise(libc::SIGTERM) };
    });
    let t0 = Instant::now();
    assert!(
        !node.wait(&wake, Duration::from_secs(30)).unwrap(),
        "the wait must report the request"
    );
    let waited = t0.elapsed();
    signaller.join().unwrap();
    // Far below the 30 s asked for: the slice, not the timeout, bounds it.
    assert!(
        waited < Duration::from_secs(10),
        "waited {waited:?} (slice {WAIT_SLICE:?})"
    );
    assert!(sub.wait_next(Duration::from_secs(30)).unwrap().is_none());
    assert!(node.termination_requested());
    drop((sub, wake, node));
    env.finish();
}
