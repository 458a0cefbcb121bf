//! Timed waits without a kernel timer per wait (`ipc::futex`'s alarm thread): every wait
//! ends at its timeout, never before, also when deadlines come in earlier than the one the
//! alarm sleeps towards (each must wake it); each deadline wakes its sleeper once (the alarm
//! does not spin); and the kernel-timer path (`futex::timeouts_by_kernel`) keeps the same
//! semantics. A process of its own (`in_own_process!`): the alarm is per process.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use navsync_shared::ipc::{IpcNode, futex};
use navsync_shared::samples::ImuSample;
use navsync_shared::services;
use navsync_tests::TestEnv;

/// The alarm thread's voluntary context switches (its wake-ups), from /proc.
fn alarm_wakeups() -> Option<u64> {
    for task in std::fs::read_dir("/proc/self/task").ok()? {
        let dir = task.ok()?.path();
        if std::fs::read_to_string(dir.join("comm")).ok()?.trim() == "navsync-alarm" {
            let status = std::fs::read_to_string(dir.join("status")).ok()?;
            return status
                .lines()
                .find_map(|l| l.strip_prefix("voluntary_ctxt_switches:"))
                .and_then(|v| v.trim().parse().ok());
        }
    }
    None
}

/// `rounds` waits of `timeout` on a service nobody publishes; the elapsed times.
fn idle_waits(prefix: &str, id: usize, timeout: Duration, rounds: usize) -> Vec<Duration> {
    let node = IpcNode::with_prefix(&format!("sleeper-{id}"), prefix).expect("node");
    let sub = node
        .subscriber::<ImuSample>(&services::imu_sample(&format!("silent{id}")))
        .unwrap();
    (0..rounds)
        .map(|_| {
            let t0 = Instant::now();
            assert!(sub.wait_next(timeout).unwrap().is_none(), "nothing is published");
            t0.elapsed()
        })
        .collect()
}

#[test]
fn timed_waits_end_at_their_timeouts_through_the_alarm() {
    if !navsync_tests::in_own_process!() {
        return;
    }
    let env = TestEnv::new("alarmtimeouts");
    // A lost deadline would wait for ever (nothing is published): fail instead of hanging.
    std::thread::spawn(|| {
        std::thread::sleep(Duration::from_secs(120));
        eprintln!("a timed wait never ended: a deadline was lost");
        std::process::exit(101);
    });
    // Eight sleepers: the later one starts, the earlier its deadline (thread k starts 8·k ms
    // in and waits 90 − 10·k ms), so every new deadline undercuts the alarm's target.
    let started = Arc::new(AtomicUsize::new(0));
    let threads: Vec<_> = (0..8usize)
        .map(|k| {
            let prefix = env.prefix.clone();
            let started = started.clone();
            std::thread::spawn(move || {
                std::thread::sleep(Duration::from_millis(8 * k as u64));
                started.fetch_add(1, Ordering::SeqCst);
                let timeout = Duration::from_millis(90 - 10 * k as u64);
                (timeout, idle_waits(&prefix, k, timeout, 5))
            })
        })
        .collect();
    let mut waits = 0u64;
    for t in threads {
        let (timeout, elapsed) = t.join().unwrap();
        for e in elapsed {
            assert!(e >= timeout, "a wait of {timeout:?} ended after {e:?}");
            // Liveness, not speed: a deadline the alarm noticed late.
            assert!(e < timeout + Duration::from_secs(3), "a wait of {timeout:?} took {e:?}");
            waits += 1;
        }
    }
    assert_eq!(started.load(Ordering::SeqCst), 8);
    // Each slice of each wait is one deadline: the alarm woke about once per deadline (plus
    // once per registration that undercut it), not in a loop.
    let wakeups = alarm_wakeups().expect("the alarm thread runs");
    println!("{waits} timed waits, alarm woke {wakeups} times");
    assert!(wakeups >= 1, "the waits went through the alarm");
    assert!(
        wakeups <= 4 * waits + 10,
        "alarm woke {wakeups} times for {waits} waits"
    );

    // The kernel's timer gives the same semantics (the benchmark's A/B switch).
    futex::timeouts_by_kernel(true);
    let before = alarm_wakeups().unwrap();
    for e in idle_waits(&env.prefix, 99, Duration::from_millis(20), 5) {
        assert!(e >= Duration::from_millis(20), "{e:?}");
    }
    assert_eq!(alarm_wakeups().unwrap(), before, "kernel timeouts do not use the alarm");
    futex::timeouts_by_kernel(false);
    env.finish();
}
