//! Reclaiming dead iceoryx2 nodes off the latency path.
//!
//! A driver killed with `kill -9` leaves its node's resources behind, and its publisher keeps
//! counting on its service until some node reclaims the dead node. The estimator needs that
//! within tens of ms to flag the input stale, but a reclaim pass lists every node of the
//! prefix (directory scans, file reads, a few hundred µs on the 2-core benchmark machine); run
//! in the estimator's loop every 50 ms it delayed the `NavState`s that arrived meanwhile (the
//! end-to-end p99). So a background thread with its own node does it, under `SCHED_IDLE`
//! whatever the process runs under; the loop only reads the (cheap) publisher counts. Not
//! `SCHED_OTHER`: a pass takes ~1 ms of CPU here, and EEVDF lets a running `SCHED_OTHER` task
//! finish its slice before a woken one (`RUN_TO_PARITY`), so every task woken on that CPU
//! meanwhile (drivers, the estimator, subscribers) waited up to 1.7 ms (`perf sched timehist`
//! under `navsync-bench e2e --imus 4`); any non-idle wake-up preempts a `SCHED_IDLE` task at
//! once. Under full CPU load a pass waits for idle time (dead nodes are found later).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use navsync_shared::ipc::IpcNode;
use tracing::warn;

/// The reclaiming thread; stopped and joined on drop.
pub struct Reclaimer {
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
}

impl Reclaimer {
    /// Starts a thread with an iceoryx2 node `node_name` that reclaims dead nodes every
    /// `period` until dropped (or SIGINT/SIGTERM).
    pub fn start(node_name: &str, period: Duration) -> std::io::Result<Self> {
        let stop = Arc::new(AtomicBool::new(false));
        let (flag, name) = (stop.clone(), node_name.to_string());
        let handle = std::thread::Builder::new().name(name.clone()).spawn(move || {
            // Below any policy the process was given, preempted by any other wake-up.
            super::run_as_observer("dead-node reclaimer");
            let node = match IpcNode::new(&name) {
                Ok(n) => n,
                Err(e) => {
                    warn!("dead-node reclaimer not started: {e}");
                    return;
                }
            };
            while !flag.load(Ordering::Relaxed) {
                node.reclaim_dead_nodes();
                if !node.sleep(period) {
                    break;
                }
            }
        })?;
        Ok(Self {
            stop,
            handle: Some(handle),
        })
    }
}

impl Drop for Reclaimer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}
