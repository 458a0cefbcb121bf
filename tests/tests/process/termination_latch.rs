//! A termination request (SIGTERM, SIGINT) that reaches a navsync process after it created its
//! iceoryx2 node but before its first wait is latched, not fatal: iceoryx2 0.10 installs its
//! signal handler lazily on the first wait, and `IpcNode` installs it at creation. Without
//! that, `systemctl stop` right after a start, or a benchmark stopping a publisher that has
//! just finished, killed the process by the signal (no clean shutdown, resources left to the
//! dead-node reclaim). A process of its own (`in_own_process!`): the signal goes to the whole process.

use navsync_shared::ipc::IpcNode;
use navsync_tests::TestEnv;

#[test]
fn sigterm_before_the_first_wait_is_latched() {
    if !navsync_tests::in_own_process!() {
        return;
    }
    let env = TestEnv::new("latch");
    let node = IpcNode::with_prefix("latch", &env.prefix).expect("node");
    // SAFETY: raising a signal in our own process; the node's handler catches it.
    assert_eq!(unsafe { libc::raise(libc::SIGTERM) }, 0);
    assert!(node.termination_requested(), "the request was not latched");
    assert!(
        !node.sleep(std::time::Duration::from_millis(1)),
        "a wait after it must say so"
    );
    drop(node);
    env.finish();
}
