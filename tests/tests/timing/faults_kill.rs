//! Fault injection with `kill -9` on the live pipeline (issue 8), real processes over real
//! iceoryx2: `navsync sim` (two industrial IMUs at 100 Hz through the Xsens path, NMEA into a
//! pseudo-terminal, raw PPS), `navsync gps`, `navsync pps --source sim`, `navsync imu` × 2 and
//! `navsync estimator`, observed from this test process.
//!
//! * A killed driver (gps, pps, the second IMU, the first IMU): the estimator flags the input stale in its
//!   `Health` (`stale_<kind>_<id>`) within 200 ms of the SIGKILL as seen here (and in
//!   `NavState`: inertial-only status without the receiver, the IMU out of the array), keeps
//!   publishing NavStates without a gap, and uses the sensor again within 2 s of the driver's
//!   restart (GNSS: a fix of the restarted driver taken in, NavStates GNSS-aided again; the
//!   filter fuses it when its delayed state reaches the fix's epoch, checked within 2 s plus
//!   that 1.5 s horizon; PPS: an edge used in the time mapping; IMU: back in the array); no
//!   other process restarts. The first IMU is the configured reference, whose samples pace
//!   the NavStates: the estimator hands the reference over to the second IMU (NavStates go on
//!   at its rate) and the first returns as an ordinary member of the array.
//! * A killed estimator, 20 times: the drivers keep publishing, the restarted estimator
//!   publishes NavStates again without manual cleanup, and the number of shared-memory and
//!   iceoryx2 files of the test's prefix does not grow.
//!
//! The two tests take the machine in turns (a lock): each runs seven processes.

use std::sync::Mutex;
use std::time::{Duration, Instant};

use navsync_shared::ipc::{IpcNode, Subscriber};
use navsync_shared::samples::*;
use navsync_shared::services;
use navsync_shared::time::monotonic_now_ns;
use navsync_tests::{HealthWatch, TestEnv, prefixed_files, write_drive_scenario};

/// One live pipeline at a time in this test binary.
static MACHINE: Mutex<()> = Mutex::new(());

/// SIGKILL of a driver → stale flag seen by a subscriber (issue 8), ns.
const STALE_BOUND_NS: i64 = 200_000_000;
/// Restart of a driver → its input used again (issue 8), ns.
const RESUME_BOUND_NS: i64 = 2_000_000_000;
/// The navigation filter fuses a fix when its delayed state reaches the fix's epoch, 1.5 s
/// behind the present (README "Same samples, same results"): a received fix counts in
/// `fixes_used` that much after it was taken in.
const FUSION_HORIZON_NS: i64 = 1_500_000_000;
/// How long a killed driver stays dead.
const DEAD_FOR: Duration = Duration::from_secs(3);
/// IMU rate of the test drive, Hz (NavStates come at this rate).
const IMU_RATE_HZ: f64 = 100.0;

fn lock_machine() -> std::sync::MutexGuard<'static, ()> {
    MACHINE.lock().unwrap_or_else(|e| e.into_inner())
}

/// What this test process sees of the estimator.
struct Observer {
    nav: Subscriber<NavState>,
    time: Subscriber<TimeState>,
    health: HealthWatch,
    last_nav: Option<NavState>,
    last_time: Option<TimeState>,
    /// NavStates received and sequence gaps among them.
    nav_count: u64,
    nav_gaps: u64,
}

impl Observer {
    fn new(node: &IpcNode) -> Self {
        Self {
            nav: node.subscriber(services::NAV_STATE).unwrap(),
            time: node.subscriber(services::TIME_STATE).unwrap(),
            health: HealthWatch::new(node, &["estimator"]),
            last_nav: None,
            last_time: None,
            nav_count: 0,
            nav_gaps: 0,
        }
    }

    /// Drains NavStates and TimeStates; calls `f(receipt_ns, state)` for each NavState.
    fn drain(&mut self, mut f: impl FnMut(i64, &NavState)) {
        while let Some(n) = self.nav.receive().unwrap() {
            let now = monotonic_now_ns();
            if let Some(p) = &self.last_nav
                && n.seq > p.seq + 1
            {
                self.nav_gaps += n.seq - p.seq - 1;
            }
            self.nav_count += 1;
            f(now, &n);
            self.last_nav = Some(n);
        }
        while let Some(t) = self.time.receive().unwrap() {
            self.last_time = Some(t);
        }
    }

    /// Sleeps on the estimator's Health for up to 5 ms, then drains.
    fn step(&mut self, f: impl FnMut(i64, &NavState)) {
        self.health.wait(Duration::from_millis(5));
        self.drain(f);
    }

    fn stale(&self, input: &str) -> Option<u64> {
        self.health.counter("estimator", &format!("stale_{input}"))
    }
}

fn nav_status(n: &NavState) -> &'static str {
    NavStatus::name(n.status)
}

/// Aligned and fusing GNSS (`degraded`: some fixes rejected or IMUs out of the array).
fn gnss_aided(n: &NavState) -> bool {
    n.status == NavStatus::Aligned as u8 || n.status == NavStatus::Degraded as u8
}

/// Slot of IMU `id` in a NavState's per-IMU table.
fn imu_slot(n: &NavState, id: &str) -> Option<ImuSync> {
    n.imu[..usize::from(n.imu_count)]
        .iter()
        .find(|s| navsync_shared::reflect::str_of(&s.imu_id) == id)
        .copied()
}

/// Waits until the filter is aided by GNSS, time locked, both IMUs in the array and no input
/// stale.
fn wait_healthy(env: &mut TestEnv, obs: &mut Observer, inputs: &[&str], timeout: Duration) {
    let t0 = Instant::now();
    loop {
        obs.step(|_, _| {});
        let nav_ok = obs.last_nav.as_ref().is_some_and(|n| {
            gnss_aided(n)
                && n.time_status == TimeStatus::Locked as u8
                && ["0", "1"]
                    .iter()
                    .all(|id| imu_slot(n, id).is_some_and(|s| s.in_array == 1))
        });
        let fresh = inputs.iter().all(|i| obs.stale(i) == Some(0));
        if nav_ok && fresh {
            return;
        }
        env.assert_running();
        assert!(
            t0.elapsed() < timeout,
            "pipeline not healthy within {timeout:?}: nav {:?}, stale {:?}\nestimator log:\n{}",
            obs.last_nav
                .as_ref()
                .map(|n| (nav_status(n), n.time_status, n.imu[1].in_array, n.imu[1].reason)),
            inputs.iter().map(|i| (*i, obs.stale(i))).collect::<Vec<_>>(),
            env.log("estimator")
        );
    }
}

/// Which driver is killed and how its input shows in the estimator's outputs.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Sensor {
    Gnss,
    Pps,
    /// The second IMU (not the reference, whose samples pace the NavStates).
    Imu1,
    /// The first IMU, the configured reference: the array hands the reference over to IMU 1
    /// and IMU 0 returns as an ordinary member.
    Imu0,
}

impl Sensor {
    fn child(self) -> &'static str {
        match self {
            Sensor::Gnss => "gnss",
            Sensor::Pps => "pps",
            Sensor::Imu1 => "imu1",
            Sensor::Imu0 => "imu0",
        }
    }

    fn input(self) -> &'static str {
        match self {
            Sensor::Gnss => "gnss_0",
            Sensor::Pps => "pps_0",
            Sensor::Imu1 => "imu_1",
            Sensor::Imu0 => "imu_0",
        }
    }

    /// The NavState shows the sensor missing (PPS: only Health says it at once; the time
    /// mapping goes to holdover on its own schedule).
    fn nav_flags_missing(self, n: &NavState) -> Option<bool> {
        match self {
            Sensor::Gnss => Some(n.status == NavStatus::InsOnly as u8),
            Sensor::Pps => None,
            Sensor::Imu1 | Sensor::Imu0 => Some(
                imu_slot(n, self.imu_id()).is_some_and(|s| s.in_array == 0 && s.reason == ImuSyncReason::Stale as u8),
            ),
        }
    }

    fn imu_id(self) -> &'static str {
        if self == Sensor::Imu0 { "0" } else { "1" }
    }
}

/// Figures of one driver kill.
#[derive(Debug)]
struct KillFigures {
    sensor: Sensor,
    /// SIGKILL → Health with the stale flag received here, ms.
    health_flag_ms: f64,
    /// SIGKILL → the time the estimator wrote into the flag, ms.
    declared_ms: f64,
    /// SIGKILL → first NavState showing the sensor missing, ms.
    nav_flag_ms: Option<f64>,
    /// NavStates received while the driver was dead, and expected at the IMU rate.
    nav_while_dead: u64,
    nav_expected: u64,
    /// Restart → stale flag cleared, ms.
    cleared_ms: f64,
    /// Restart → the sensor used again, ms (GNSS: a fix taken in, the NavState GNSS-aided again).
    used_ms: f64,
    /// GNSS: restart → the first new fix fused (`fixes_used` grows), ms.
    fused_ms: Option<f64>,
}

fn kill_and_restart(env: &mut TestEnv, obs: &mut Observer, sensor: Sensor) -> KillFigures {
    let (child, input) = (sensor.child(), sensor.input());
    let others: Vec<(String, u32)> = env.pids().into_iter().filter(|(n, _)| n != child).collect();
    obs.drain(|_, _| {});
    let fixes_before = obs.last_nav.as_ref().map_or(0, |n| n.fixes_used);
    let pps_before = obs.last_time.as_ref().map_or(0, |t| t.pps_used);
    let gaps_before = obs.nav_gaps;

    let t_kill = env.kill9(child);
    let (mut health_flag, mut declared, mut nav_flag) = (None::<i64>, None::<i64>, None::<i64>);
    let mut nav_while_dead = 0u64;
    let mut flapped = false;
    let dead_until = t_kill + DEAD_FOR.as_nanos() as i64;
    while monotonic_now_ns() < dead_until {
        obs.step(|rx, n| {
            nav_while_dead += 1;
            if nav_flag.is_none() && sensor.nav_flags_missing(n) == Some(true) {
                nav_flag = Some(rx);
            }
        });
        match obs.stale(input) {
            Some(v) if v != 0 && health_flag.is_none() => {
                health_flag = Some(monotonic_now_ns());
                declared = Some(v as i64);
            }
            Some(0) if health_flag.is_some() => flapped = true,
            _ => {}
        }
    }
    let ms = |t: i64| t as f64 * 1e-6;
    let health_flag = health_flag.unwrap_or_else(|| {
        panic!(
            "{input} not flagged stale within {DEAD_FOR:?} of killing {child}\nestimator log:\n{}",
            env.log("estimator")
        )
    });
    assert!(!flapped, "{input}: the stale flag cleared while {child} was dead");
    if sensor.nav_flags_missing(obs.last_nav.as_ref().unwrap()).is_some() {
        assert!(
            sensor.nav_flags_missing(obs.last_nav.as_ref().unwrap()) == Some(true),
            "the last NavState before the restart does not show {input} missing: {:?}",
            obs.last_nav
        );
    }
    // Still aided by GNSS while only the PPS or an IMU is gone.
    if sensor != Sensor::Gnss {
        let n = obs.last_nav.as_ref().unwrap();
        assert!(gnss_aided(n), "{input} gone: NavState {}", nav_status(n));
    }

    let t_restart = monotonic_now_ns();
    env.respawn(child);
    let (mut cleared, mut used, mut fused) = (None::<i64>, None::<i64>, None::<i64>);
    while cleared.is_none() || used.is_none() || (sensor == Sensor::Gnss && fused.is_none()) {
        obs.step(|rx, n| {
            let again = match sensor {
                Sensor::Gnss => gnss_aided(n),
                Sensor::Pps => false,
                Sensor::Imu1 | Sensor::Imu0 => imu_slot(n, sensor.imu_id()).is_some_and(|s| s.in_array == 1),
            };
            if again && used.is_none() {
                used = Some(rx);
            }
            if sensor == Sensor::Gnss && n.fixes_used > fixes_before && fused.is_none() {
                fused = Some(rx);
            }
        });
        if sensor == Sensor::Pps
            && used.is_none()
            && obs
                .last_time
                .as_ref()
                .is_some_and(|t| t.pps_used > pps_before && t.last_pps_host_ns > t_restart)
        {
            used = Some(monotonic_now_ns());
        }
        if cleared.is_none() && obs.stale(input) == Some(0) {
            cleared = Some(monotonic_now_ns());
        }
        let waited = monotonic_now_ns() - t_restart;
        assert!(
            waited < 4 * RESUME_BOUND_NS,
            "{input} not back {:.0} ms after restarting {child}: cleared {cleared:?}, used {used:?}, last nav {:?}\n\
             {child} log:\n{}\nestimator log:\n{}",
            ms(waited),
            obs.last_nav
                .as_ref()
                .map(|n| (nav_status(n), n.fixes_used, imu_slot(n, "0"), imu_slot(n, "1"))),
            env.log(child),
            env.log("estimator")
        );
    }
    for (name, pid) in &others {
        assert_eq!(env.pid(name), Some(*pid), "{name} was restarted");
        assert!(
            env.is_running(name),
            "{name} died after {child} was killed:\n{}",
            env.log(name)
        );
    }
    assert_eq!(obs.nav_gaps, gaps_before, "NavStates lost while {child} was dead");
    KillFigures {
        sensor,
        health_flag_ms: ms(health_flag - t_kill),
        declared_ms: ms(declared.unwrap() - t_kill),
        nav_flag_ms: nav_flag.map(|t| ms(t - t_kill)),
        nav_while_dead,
        nav_expected: (DEAD_FOR.as_secs_f64() * IMU_RATE_HZ) as u64,
        cleared_ms: ms(cleared.unwrap() - t_restart),
        used_ms: ms(used.unwrap() - t_restart),
        fused_ms: fused.map(|t| ms(t - t_restart)),
    }
}

#[test]
fn killed_driver_is_flagged_within_200_ms_and_used_again_within_2_s_of_restart() {
    let _alone = navsync_tests::alone();
    let _machine = lock_machine();
    let mut env = TestEnv::new("killdrv");
    let scen = env.dir.join("drive.toml");
    write_drive_scenario(&scen, 240.0, 2, IMU_RATE_HZ);
    let node = env.node("observer");
    let mut obs = Observer::new(&node);
    env.spawn_pipeline(&scen, 2);
    let inputs = ["gnss_0", "pps_0", "imu_0", "imu_1"];
    wait_healthy(&mut env, &mut obs, &inputs, Duration::from_secs(120));

    let mut figures = Vec::new();
    for sensor in [Sensor::Gnss, Sensor::Pps, Sensor::Imu1, Sensor::Imu0] {
        let f = kill_and_restart(&mut env, &mut obs, sensor);
        println!(
            "kill -9 {:<4}: stale in Health after {:6.1} ms (declared at {:6.1} ms), in NavState after {}; \
             {} NavStates while dead ({} expected at {IMU_RATE_HZ} Hz); after restart: flag cleared in {:6.1} ms, \
             sensor used in {:6.1} ms{}",
            f.sensor.child(),
            f.health_flag_ms,
            f.declared_ms,
            f.nav_flag_ms.map_or("-".to_string(), |v| format!("{v:.1} ms")),
            f.nav_while_dead,
            f.nav_expected,
            f.cleared_ms,
            f.used_ms,
            f.fused_ms
                .map_or(String::new(), |v| format!(", first new fix fused in {v:.1} ms"))
        );
        figures.push(f);
        // Back to a healthy pipeline before the next fault.
        wait_healthy(&mut env, &mut obs, &inputs, Duration::from_secs(30));
    }
    for f in &figures {
        let bound_ms = STALE_BOUND_NS as f64 * 1e-6;
        assert!(
            f.health_flag_ms <= bound_ms,
            "{f:?}: Health flag later than {bound_ms} ms"
        );
        if let Some(v) = f.nav_flag_ms {
            assert!(v <= bound_ms, "{f:?}: NavState flag later than {bound_ms} ms");
        }
        assert!(
            f.sensor == Sensor::Pps || f.nav_flag_ms.is_some(),
            "{f:?}: no NavState showed the sensor missing"
        );
        // NavStates keep coming: no gap (checked per kill), at least half the IMU rate on a
        // loaded machine (a stop would give none).
        assert!(f.nav_while_dead * 2 >= f.nav_expected, "{f:?}: NavStates stopped");
        let bound_ms = RESUME_BOUND_NS as f64 * 1e-6;
        assert!(
            f.cleared_ms <= bound_ms && f.used_ms <= bound_ms,
            "{f:?}: not resumed within {bound_ms} ms"
        );
        if let Some(v) = f.fused_ms {
            let bound_ms = (RESUME_BOUND_NS + FUSION_HORIZON_NS) as f64 * 1e-6;
            assert!(v <= bound_ms, "{f:?}: no new fix fused within {bound_ms} ms");
        }
    }
    println!("{} NavStates received, {} sequence gaps", obs.nav_count, obs.nav_gaps);
    drop((obs, node));
    env.finish();
}

/// Files of the prefix by kind, for the report.
fn file_summary(prefix: &str) -> String {
    let mut kinds = std::collections::BTreeMap::<String, usize>::new();
    for f in prefixed_files(prefix) {
        let name = f.file_name().unwrap().to_string_lossy().into_owned();
        let kind = name.rsplit('.').next().unwrap_or("").to_string();
        *kinds.entry(kind).or_default() += 1;
    }
    format!("{kinds:?}")
}

/// The iceoryx2 connections of the prefix as "publisher node → subscriber node" (node names
/// from the nodes' details files; `?` for a port whose node is gone).
fn connections(prefix: &str) -> Vec<String> {
    let files = prefixed_files(prefix);
    let node_of = |port: &str| -> String {
        files
            .iter()
            .find(|f| f.to_string_lossy().ends_with(&format!("{port}.port_tag")))
            .and_then(|f| std::fs::read(f.parent()?.join(format!("{prefix}node.details"))).ok())
            .and_then(|b| {
                let s = String::from_utf8_lossy(&b).into_owned();
                let line = s.lines().find(|l| l.trim_start().starts_with("name"))?;
                Some(line.split_once('=')?.1.trim().trim_matches('"').to_string())
            })
            .unwrap_or_else(|| "?".into())
    };
    let mut out: Vec<String> = files
        .iter()
        .filter_map(|f| {
            let n = f.file_name()?.to_string_lossy().into_owned();
            let ids: Vec<&str> = n.strip_suffix(".connection")?.rsplit('_').take(2).collect();
            Some(format!("{} → {}", node_of(ids[1]), node_of(ids[0])))
        })
        .collect();
    out.sort();
    out
}

#[test]
fn killed_estimator_restarts_20_times_without_stale_shared_memory() {
    let _alone = navsync_tests::alone();
    let _machine = lock_machine();
    let mut env = TestEnv::new("killest");
    let scen = env.dir.join("drive.toml");
    write_drive_scenario(&scen, 240.0, 2, IMU_RATE_HZ);
    let node = env.node("observer");
    let nav = node.subscriber::<NavState>(services::NAV_STATE).unwrap();
    let imus: Vec<Subscriber<ImuSample>> = (0..2)
        .map(|i| node.subscriber(&services::imu_sample(&i.to_string())).unwrap())
        .collect();
    let fix = node.subscriber::<GnssFix>(&services::gnss_fix("0")).unwrap();
    let pps = node.subscriber::<PpsEdge>(&services::pps_edge("0")).unwrap();
    let mut health = HealthWatch::new(&node, &["estimator"]);
    env.spawn_pipeline(&scen, 2);

    // NavStates flowing, then the baseline file count.
    let t0 = Instant::now();
    while nav.receive().unwrap().is_none() {
        env.assert_running();
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "no NavState\n{}",
            env.log("estimator")
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_secs(3));
    let drain_all = |counts: &mut [u64; 4]| {
        for (i, s) in imus.iter().enumerate() {
            counts[i] += s.for_each(|_| {}).unwrap() as u64;
        }
        counts[2] += fix.for_each(|_| {}).unwrap() as u64;
        counts[3] += pps.for_each(|_| {}).unwrap() as u64;
    };
    let mut counts = [0u64; 4];
    drain_all(&mut counts);
    counts = [0; 4];
    let baseline_files = prefixed_files(&env.prefix);
    let baseline = baseline_files.len();
    let baseline_connections = connections(&env.prefix);
    println!("baseline: {baseline} files of the prefix {}", file_summary(&env.prefix));
    let drivers: Vec<(String, u32)> = env.pids().into_iter().filter(|(n, _)| n != "estimator").collect();

    const CYCLES: usize = 20;
    let mut after = Vec::new();
    let mut reattach_ms = Vec::new();
    let mut imu_while_dead = Vec::new();
    let t_start = Instant::now();
    for cycle in 0..CYCLES {
        let old_pid = env.pid("estimator").unwrap();
        env.kill9("estimator");
        // The drivers keep publishing while the estimator is dead.
        let before = counts;
        std::thread::sleep(Duration::from_millis(300));
        drain_all(&mut counts);
        let imu_dead = (counts[0] - before[0]).min(counts[1] - before[1]);
        imu_while_dead.push(imu_dead);
        assert!(
            imu_dead > 0,
            "cycle {cycle}: IMU samples stopped while the estimator was dead"
        );
        while nav.receive().unwrap().is_some() {}
        let t_restart = monotonic_now_ns();
        let new_pid = env.respawn("estimator");
        // It publishes NavStates again, and its Health is its own.
        let mut got_nav = false;
        let mut own_health = false;
        loop {
            health.poll();
            own_health |= health.latest("estimator").is_some_and(|h| h.pid == new_pid);
            got_nav |= nav.receive().unwrap().is_some();
            if got_nav && own_health {
                break;
            }
            assert!(
                monotonic_now_ns() - t_restart < 20_000_000_000,
                "cycle {cycle}: the restarted estimator (pid {new_pid}, was {old_pid}) published no NavState \
                 (nav {got_nav}, health {own_health})\n{}",
                env.log("estimator")
            );
            std::thread::sleep(Duration::from_millis(10));
        }
        reattach_ms.push((monotonic_now_ns() - t_restart) as f64 * 1e-6);
        // A publisher drops its connection to a dead subscriber (reclaimed by the new node) at
        // its next send: count the files once the 1 Hz receiver and PPS have sent again.
        // (What is queued here now was sent before the new estimator's node reclaimed the dead one.)
        drain_all(&mut counts);
        let (fixes, edges) = (counts[2], counts[3]);
        while counts[2] == fixes || counts[3] == edges {
            assert!(
                monotonic_now_ns() - t_restart < 10_000_000_000,
                "cycle {cycle}: no fix or PPS edge within 10 s"
            );
            std::thread::sleep(Duration::from_millis(20));
            drain_all(&mut counts);
        }
        for (name, pid) in &drivers {
            assert_eq!(env.pid(name), Some(*pid), "{name} was restarted");
            assert!(env.is_running(name), "{name} died in cycle {cycle}:\n{}", env.log(name));
        }
        let files = prefixed_files(&env.prefix);
        let n = files.len();
        after.push(n);
        assert!(
            n <= baseline,
            "cycle {cycle}: {n} files of the prefix after the restart, {baseline} before the first kill: \
             {}; connections {:?} (baseline {baseline_connections:?}); new: {:?}; gone: {:?}",
            file_summary(&env.prefix),
            connections(&env.prefix),
            files.iter().filter(|f| !baseline_files.contains(f)).collect::<Vec<_>>(),
            baseline_files.iter().filter(|f| !files.contains(f)).collect::<Vec<_>>()
        );
    }
    let secs = t_start.elapsed().as_secs_f64();
    drain_all(&mut counts);
    println!("files of the prefix after each of the {CYCLES} kill/restart cycles: {after:?} (baseline {baseline})");
    println!(
        "restart → first NavState and own Health: min {:.0} / max {:.0} ms; IMU samples in the 300 ms without \
         estimator: min {} max {}",
        reattach_ms.iter().copied().fold(f64::INFINITY, f64::min),
        reattach_ms.iter().copied().fold(0.0, f64::max),
        imu_while_dead.iter().min().unwrap(),
        imu_while_dead.iter().max().unwrap()
    );
    println!(
        "received during the cycles: imu0 {} imu1 {} fixes {} pps {} in {secs:.1} s",
        counts[0], counts[1], counts[2], counts[3]
    );
    // Fixes and PPS edges at 1 Hz went on through all cycles.
    assert!(
        counts[2] as f64 >= 0.8 * secs && counts[3] as f64 >= 0.8 * secs,
        "fixes {} / PPS edges {} in {secs:.1} s",
        counts[2],
        counts[3]
    );
    drop((nav, imus, fix, pps, health, node));
    env.finish();
}
