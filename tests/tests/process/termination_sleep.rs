//! A SIGTERM that arrives while a navsync process sleeps in `IpcNode::sleep` (iceoryx2's node
//! wait, which reports the signal once and clears it) is latched: the sleep says so and every
//! later check too. A process of its own (`in_own_process!`): the signal goes to the whole process.

use std::time::Duration;

use navsync_shared::ipc::{IpcNode, termination_requested};
use navsync_tests::TestEnv;

#[test]
fn sigterm_during_a_sleep_is_latched() {
    if !navsync_tests::in_own_process!() {
        return;
    }
    let env = TestEnv::new("termsleep");
    let node = IpcNode::with_prefix("sleeper", &env.prefix).expect("node");
    let signaller = std::thread::spawn(|| {
        std::thread::sleep(Duration::from_millis(200));
        // SAFETY: raising a signal in our own process; the node's handler catches it.
        unsafe { libc::raise(libc::SIGTERM) };
    });
    let mut slept = 0;
    while node.sleep(Duration::from_millis(50)) {
        slept += 1;
        assert!(slept < 200, "the request was never seen");
    }
    signaller.join().unwrap();
    assert!(termination_requested(), "latched");
    assert!(node.termination_requested(), "latched for the node too");
    assert!(!node.sleep(Duration::from_millis(1)));
    drop(node);
    env.finish();
}
