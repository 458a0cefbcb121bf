//! # navsync-tests
//!
//! Helpers for multi-process integration tests: each test gets its own iceoryx2 resource
//! prefix (so parallel tests and a running demo never meet), starts real `navsync` processes
//! with it, talks to them from the test process over real iceoryx2 services, and at the end
//! checks that no shared memory was left behind.
//!
//! The `navsync` binary is the one cargo built next to the test executable
//! (`target/<profile>/navsync`), or `$NAVSYNC_BIN`. `cargo test --workspace` builds it, and
//! `navsync-bench`, because the daemon and the bench crates have integration tests of their own
//! (`daemon/tests/`, `bench/tests/`: cargo builds a package's executables for its integration
//! tests); keep one in each.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use navsync_shared::ipc::{IpcNode, Subscriber};
use navsync_shared::samples::Health;
use navsync_shared::services;
use navsync_shared::time::monotonic_now_ns;

/// Path of the `navsync` executable under test.
pub fn navsync_bin() -> PathBuf {
    if let Ok(p) = std::env::var("NAVSYNC_BIN") {
        return PathBuf::from(p);
    }
    workspace_bin("navsync")
}

/// Path of the `navsync-bench` executable (the benchmarks, a crate of their own).
pub fn bench_bin() -> PathBuf {
    workspace_bin("navsync-bench")
}

/// An example program of the workspace (`<crate>/examples/<name>.rs`), which
/// `cargo test --workspace` builds into `target/<profile>/examples/`.
pub fn workspace_example(name: &str) -> PathBuf {
    built(&Path::new("examples").join(name), "the examples")
}

/// A binary of the workspace that cargo built next to the test executable.
fn workspace_bin(name: &str) -> PathBuf {
    built(Path::new(name), "the binaries (or set NAVSYNC_BIN for `navsync`)")
}

/// `rel` under the profile directory cargo builds into (`target/<profile>/`, where the test
/// executable is `deps/<test>-<hash>`); panics saying how to build it when it is missing.
fn built(rel: &Path, what: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    let bin = exe
        .parent()
        .and_then(Path::parent)
        .map(|d| d.join(rel))
        .expect("target dir");
    assert!(
        bin.exists(),
        "{} not found: run the tests with `cargo test --workspace`, which builds {what}",
        bin.display()
    );
    bin
}

/// The rtklibexplorer walk's reference positions (`datasets/rtklibexplorer-walk0827`: its
/// `gnss.pos` epochs with the `gnss_q.txt` quality of each, 1 RTK fixed, 2 float):
/// (GPS s of week, lat°, lon°, Q).
pub fn walk0827_reference() -> Vec<(f64, f64, f64, f64)> {
    let data = shared_material("datasets/rtklibexplorer-walk0827");
    let rows = |f: &str| -> Vec<Vec<f64>> {
        std::fs::read_to_string(data.join(f))
            .unwrap()
            .lines()
            .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
            .map(|l| l.split_whitespace().map(|x| x.parse().unwrap()).collect())
            .collect()
    };
    let q: HashMap<i64, f64> = rows("gnss_q.txt")
        .iter()
        .map(|r| ((r[0] * 1e3).round() as i64, r[1]))
        .collect();
    rows("gnss.pos")
        .iter()
        .filter_map(|r| Some((r[0], r[1], r[2], *q.get(&((r[0] * 1e3).round() as i64))?)))
        .collect()
}

/// The north and east error (m) of a KF-GINS-format output (`rows`: week, s of week, lat°,
/// lon°, …, yaw° in column 10) against the walk's reference position (`lat`°, `lon`°) at
/// `sow`: the output interpolated there, the antenna 5 cm left of the IMU (the walk's lever arm,
/// body y = −0.05 m) through the yaw. `None` outside the output.
pub fn walk0827_antenna_error(rows: &[Vec<f64>], sow: f64, lat: f64, lon: f64) -> Option<(f64, f64)> {
    const R: f64 = 6_378_137.0;
    let k = rows.partition_point(|r| r[1] <= sow);
    if k == 0 || k >= rows.len() {
        return None;
    }
    let (a, b) = (&rows[k - 1], &rows[k]);
    let w = (sow - a[1]) / (b[1] - a[1]);
    let (la, lo) = (a[2] + w * (b[2] - a[2]), a[3] + w * (b[3] - a[3]));
    let yaw = b[10].to_radians();
    let (dn, de) = (0.05 * yaw.sin(), -0.05 * yaw.cos());
    Some((
        (la - lat).to_radians() * R + dn,
        (lo - lon).to_radians() * R * la.to_radians().cos() + de,
    ))
}

/// Material provided beside the checkout (`../shared/<rel>`: corpora, datasets), else under
/// `$NAVSYNC_SHARED_DIR` (set by `.ci/run` for clones elsewhere); panics saying where it was
/// looked for.
pub fn shared_material(rel: &str) -> PathBuf {
    let beside = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared").join(rel);
    if beside.exists() {
        return beside;
    }
    if let Some(dir) = std::env::var_os("NAVSYNC_SHARED_DIR") {
        let p = Path::new(&dir).join(rel);
        if p.exists() {
            return p;
        }
    }
    panic!(
        "{rel} is not at {} nor under $NAVSYNC_SHARED_DIR: put shared/ beside the checkout or set NAVSYNC_SHARED_DIR",
        beside.display()
    )
}

/// A Python 3 with `packages` installed by pip into a virtual environment in `dir` (else with
/// `pip --target` into `dir/pylib`, returned for PYTHONPATH), or which step failed and why.
pub fn python_with(dir: &Path, packages: &[&str]) -> Result<(PathBuf, Option<PathBuf>), String> {
    let venv = dir.join("venv");
    let venv_ok = Command::new("python3")
        .args(["-m", "venv", &venv.display().to_string()])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    let (py, target) = if venv_ok {
        (venv.join("bin/python"), None)
    } else {
        (PathBuf::from("python3"), Some(dir.join("pylib")))
    };
    let mut args = vec!["-m".to_string(), "pip".into(), "install".into(), "--quiet".into()];
    if let Some(t) = &target {
        args.extend(["--target".to_string(), t.display().to_string()]);
    }
    args.extend(packages.iter().map(|p| p.to_string()));
    match Command::new(&py).args(&args).output() {
        Ok(o) if o.status.success() => Ok((py, target)),
        Ok(o) => Err(format!(
            "`{} {}` failed ({}): {}",
            py.display(),
            args.join(" "),
            o.status,
            String::from_utf8_lossy(&o.stderr).trim()
        )),
        Err(e) => Err(format!("cannot run {}: {e}", py.display())),
    }
}

/// Path of the gpsd NMEA corpus provided beside the checkout.
pub fn corpus_dir() -> PathBuf {
    shared_material("corpora/gpsd-nmea")
}

static SEQ: AtomicU32 = AtomicU32::new(0);

/// One isolated navsync instance: a unique prefix, a scratch directory, child processes.
pub struct TestEnv {
    /// iceoryx2 resource prefix of this test.
    pub prefix: String,
    /// Scratch directory, removed at the end.
    pub dir: PathBuf,
    children: Vec<(String, Child)>,
    /// The arguments each child name was last started with (for [`TestEnv::respawn`]).
    args: HashMap<String, Vec<String>>,
}

impl TestEnv {
    /// A fresh environment; `name` is a short tag for the prefix (letters and digits).
    pub fn new(name: &str) -> Self {
        let n = SEQ.fetch_add(1, Ordering::Relaxed);
        let tag: String = name.chars().filter(|c| c.is_ascii_alphanumeric()).take(12).collect();
        let prefix = format!("nst{}_{n}_{tag}_", std::process::id());
        let dir = std::env::temp_dir().join(format!("navsync-test-{prefix}"));
        std::fs::create_dir_all(&dir).expect("scratch dir");
        Self {
            prefix,
            dir,
            children: Vec::new(),
            args: HashMap::new(),
        }
    }

    /// A `navsync` command with this environment's prefix.
    pub fn command(&self, args: &[&str]) -> Command {
        self.command_of(navsync_bin(), args)
    }

    /// `program ARGS` (a workspace binary) with this environment's prefix.
    pub fn command_of(&self, program: PathBuf, args: &[&str]) -> Command {
        let mut c = Command::new(program);
        c.args(args)
            .env(navsync_shared::services::PREFIX_ENV, &self.prefix)
            .env("RUST_LOG", "warn");
        c
    }

    /// Starts `navsync ARGS` as a child; its stderr goes to `<dir>/<name>.log` (appended to,
    /// so a restarted child's log follows its predecessor's).
    pub fn spawn(&mut self, name: &str, args: &[&str]) -> u32 {
        self.spawn_inner(name, args, false)
    }

    /// Like [`spawn`](Self::spawn), with the child's stdout in `<dir>/<name>.out`
    /// ([`TestEnv::stdout_len`]).
    pub fn spawn_capturing(&mut self, name: &str, args: &[&str]) -> u32 {
        self.spawn_inner(name, args, true)
    }

    fn spawn_inner(&mut self, name: &str, args: &[&str], capture: bool) -> u32 {
        let append = |file: String| {
            std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(self.dir.join(file))
                .expect("log file")
        };
        let stdout = if capture {
            Stdio::from(append(format!("{name}.out")))
        } else {
            Stdio::null()
        };
        let child = self
            .command(args)
            .stdout(stdout)
            .stderr(append(format!("{name}.log")))
            .spawn()
            .unwrap_or_else(|e| panic!("starting navsync {args:?}: {e}"));
        let pid = child.id();
        self.children.push((name.to_string(), child));
        self.args
            .insert(name.to_string(), args.iter().map(|a| a.to_string()).collect());
        pid
    }

    /// Starts `name` again with the arguments it was last started with (after
    /// [`kill9`](Self::kill9)); its new pid.
    pub fn respawn(&mut self, name: &str) -> u32 {
        let args = self
            .args
            .get(name)
            .cloned()
            .unwrap_or_else(|| panic!("{name} was never started"));
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        let capture = self.dir.join(format!("{name}.out")).exists();
        self.spawn_inner(name, &a, capture)
    }

    /// `kill -9` of a running child: sends SIGKILL, reaps it and forgets it. Returns the host
    /// `CLOCK_MONOTONIC` time (ns) taken right before the signal.
    pub fn kill9(&mut self, name: &str) -> i64 {
        let i = self
            .children
            .iter()
            .position(|(n, _)| n == name)
            .unwrap_or_else(|| panic!("no child {name}"));
        let (_, mut c) = self.children.remove(i);
        if let Ok(Some(st)) = c.try_wait() {
            panic!("{name} had already exited ({st}); log:\n{}", self.log(name));
        }
        let t = monotonic_now_ns();
        // SAFETY: signalling our own child by pid.
        unsafe { libc::kill(c.id() as libc::pid_t, libc::SIGKILL) };
        let _ = c.wait();
        t
    }

    /// Pid of a child by name.
    pub fn pid(&self, name: &str) -> Option<u32> {
        self.children.iter().find(|(n, _)| n == name).map(|(_, c)| c.id())
    }

    /// Names and pids of the children.
    pub fn pids(&self) -> Vec<(String, u32)> {
        self.children.iter().map(|(n, c)| (n.clone(), c.id())).collect()
    }

    /// Bytes the child wrote to stdout so far (children started with
    /// [`spawn_capturing`](Self::spawn_capturing)).
    pub fn stdout_len(&self, name: &str) -> u64 {
        std::fs::metadata(self.dir.join(format!("{name}.out"))).map_or(0, |m| m.len())
    }

    /// The stderr log of a child so far.
    pub fn log(&self, name: &str) -> String {
        std::fs::read_to_string(self.dir.join(format!("{name}.log"))).unwrap_or_default()
    }

    /// An iceoryx2 node of the test process in this environment.
    pub fn node(&self, name: &str) -> IpcNode {
        IpcNode::with_prefix(name, &self.prefix).expect("test node")
    }

    /// Sends `signal` to a child by name.
    pub fn signal(&self, name: &str, signal: i32) {
        if let Some((_, c)) = self.children.iter().find(|(n, _)| n == name) {
            // SAFETY: signalling our own child by pid.
            unsafe { libc::kill(c.id() as libc::pid_t, signal) };
        }
    }

    /// Waits until `path` exists.
    pub fn wait_for_path(&self, path: &Path, timeout: Duration) {
        let t0 = Instant::now();
        while !path.exists() {
            assert!(
                t0.elapsed() < timeout,
                "{} did not appear within {timeout:?}",
                path.display()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Panics if a child has exited (with its log).
    pub fn assert_running(&mut self) {
        for (name, c) in &mut self.children {
            if let Ok(Some(st)) = c.try_wait() {
                let log = std::fs::read_to_string(self.dir.join(format!("{name}.log"))).unwrap_or_default();
                panic!("{name} exited early ({st}); log:\n{log}");
            }
        }
    }

    /// Stops all children with SIGTERM (SIGKILL after 10 s), asserts they exited cleanly, and
    /// asserts that no shared memory or iceoryx2 files with this prefix remain.
    pub fn finish(mut self) {
        let statuses = self.stop_children();
        for (name, st) in &statuses {
            assert!(
                st.as_deref() == Some("exit status: 0"),
                "{name} did not exit cleanly: {st:?}\n{}",
                self.log(name)
            );
        }
        let left = leftovers(&self.prefix);
        remove_persistent_segment(&self.prefix);
        assert!(left.is_empty(), "shared memory left behind: {left:?}");
        let _ = std::fs::remove_dir_all(&self.dir);
    }

    fn stop_children(&mut self) -> Vec<(String, Option<String>)> {
        for (_, c) in &self.children {
            // SAFETY: signalling our own child by pid.
            unsafe { libc::kill(c.id() as libc::pid_t, libc::SIGTERM) };
        }
        let t0 = Instant::now();
        let mut out = Vec::new();
        for (name, c) in &mut self.children {
            let st = loop {
                match c.try_wait() {
                    Ok(Some(st)) => break Some(st.to_string()),
                    Ok(None) if t0.elapsed() < Duration::from_secs(10) => std::thread::sleep(Duration::from_millis(10)),
                    _ => {
                        let _ = c.kill();
                        let _ = c.wait();
                        break None;
                    }
                }
            };
            out.push((name.clone(), st));
        }
        self.children.clear();
        out
    }
}

impl Drop for TestEnv {
    fn drop(&mut self) {
        // Best effort after a failed test; `finish` does the checked version.
        if !self.children.is_empty() {
            self.stop_children();
        }
        for f in list_prefixed(&self.prefix) {
            let _ = std::fs::remove_file(f);
        }
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// iceoryx2 keeps one 16-byte persistent segment per resource prefix (its node counter,
/// `<prefix>node.<version>.global_mgmt`) by design; a test's prefix is never reused, so the
/// test removes it after all its processes have exited.
fn remove_persistent_segment(prefix: &str) {
    for f in list_prefixed(prefix) {
        if f.to_string_lossy().ends_with(".global_mgmt") {
            let _ = std::fs::remove_file(f);
        }
    }
}

fn list_prefixed(prefix: &str) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut visit = vec![PathBuf::from("/dev/shm"), navsync_shared::ipc::root_dir()];
    while let Some(d) = visit.pop() {
        let Ok(rd) = std::fs::read_dir(&d) else { continue };
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                visit.push(p);
            } else if e.file_name().to_string_lossy().starts_with(prefix) {
                out.push(p);
            }
        }
    }
    out
}

/// Every shared-memory and iceoryx2 file of this prefix (in `/dev/shm` and iceoryx2's root,
/// [`navsync_shared::ipc::root_dir`]),
/// the persistent node counter included.
pub fn prefixed_files(prefix: &str) -> Vec<PathBuf> {
    list_prefixed(prefix)
}

/// Shared-memory and iceoryx2 files of this prefix other than the persistent node counter.
pub fn leftovers(prefix: &str) -> Vec<PathBuf> {
    list_prefixed(prefix)
        .into_iter()
        .filter(|p| !p.to_string_lossy().ends_with(".global_mgmt"))
        .collect()
}

// ---------------------------------------------------------------------------------------------
// Tests that share a test binary (one per area, `tests/tests/<area>/main.rs`).

/// Serialises the tests that take it.
static ALONE: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Taken first by a test that must have the machine to itself while it runs (it asserts
/// latency, jitter or deadlines, or uses machine-wide state such as `/dev/cpu_dma_latency`):
/// every test of `tests/tests/timing/` takes it, so they run one at a time, and cargo runs one
/// test binary at a time. A test binary whose tests do not all take it gives no such guarantee.
pub fn alone() -> std::sync::MutexGuard<'static, ()> {
    ALONE.lock().unwrap_or_else(|e| e.into_inner())
}

/// Set in the child process [`in_own_process!`] starts: the name of the one test it runs.
const OWN_PROCESS_ENV: &str = "NAVSYNC_TEST_OWN_PROCESS";

/// Runs the calling `#[test]` in a process of its own, for tests whose subject is the whole
/// process (a signal raised in it, its alarm thread, a global allocator counting all its
/// allocations): the test binary starts itself again with only this test (`--exact`), and
/// passes when that child passed. `true` in the child (go on with the test's body), `false` in
/// the parent once the child passed (return); the child's output is printed as the test's.
///
/// ```text
/// #[test]
/// fn sigterm_is_latched() {
///     if !navsync_tests::in_own_process!() {
///         return;
///     }
///     // … the test itself, alone in its process …
/// }
/// ```
#[macro_export]
macro_rules! in_own_process {
    () => {{
        fn here() {}
        $crate::run_in_own_process(::std::any::type_name_of_val(&here))
    }};
}

/// The work of [`in_own_process!`]; `here` is the type name of a function item declared in the
/// test (`<crate>::<module>::<test>::here`).
#[doc(hidden)]
pub fn run_in_own_process(here: &str) -> bool {
    // libtest names a test by its path without the crate: `<module>::<test>`.
    let path = here
        .strip_suffix("::here")
        .expect("in_own_process! inside a test function");
    let test = path.split_once("::").map_or(path, |(_, rest)| rest);
    if std::env::var_os(OWN_PROCESS_ENV).is_some_and(|v| v == test) {
        return true;
    }
    let exe = std::env::current_exe().expect("test executable path");
    let out = Command::new(&exe)
        .args([test, "--exact", "--test-threads=1", "--nocapture"])
        .env(OWN_PROCESS_ENV, test)
        .stdin(Stdio::null())
        .output()
        .unwrap_or_else(|e| panic!("starting {} for {test}: {e}", exe.display()));
    let stdout = String::from_utf8_lossy(&out.stdout);
    print!("{stdout}");
    eprint!("{}", String::from_utf8_lossy(&out.stderr));
    assert!(
        out.status.success(),
        "{test} failed in its own process ({})",
        out.status
    );
    assert!(
        stdout.contains("test result: ok. 1 passed"),
        "{test} did not run in its own process"
    );
    false
}

// ---------------------------------------------------------------------------------------------
// Live pipelines, fault injection and soak measurements.

/// Heap allocations counted by [`CountingAllocator`] since the process started.
static ALLOCATIONS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

thread_local! {
    /// The same, of this thread only (a `const` initialiser: no lazy set-up, no destructor, so
    /// the allocator may use it).
    static THREAD_ALLOCATIONS: std::cell::Cell<u64> = const { std::cell::Cell::new(0) };
}

fn count_allocation() {
    ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    THREAD_ALLOCATIONS.with(|c| c.set(c.get() + 1));
}

/// A global allocator that forwards to the system's and counts every allocation and
/// reallocation of the process, for the no-allocation tests (`tests/tests/process/` installs it
/// with `#[global_allocator] static GLOBAL: CountingAllocator = CountingAllocator;` and runs
/// each test [`in_own_process!`], so that what is counted is that test's).
pub struct CountingAllocator;

// SAFETY: forwards to the system allocator; only counts.
unsafe impl std::alloc::GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: std::alloc::Layout) -> *mut u8 {
        count_allocation();
        // SAFETY: the caller's contract is the system allocator's.
        unsafe { std::alloc::System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: std::alloc::Layout) {
        // SAFETY: as above.
        unsafe { std::alloc::System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: std::alloc::Layout, new_size: usize) -> *mut u8 {
        count_allocation();
        // SAFETY: as above.
        unsafe { std::alloc::System.realloc(ptr, layout, new_size) }
    }
}

/// Allocations counted so far by [`CountingAllocator`] (0 when it is not installed).
pub fn allocations() -> u64 {
    ALLOCATIONS.load(Ordering::Relaxed)
}

/// Allocations of the calling thread so far (for code that runs on the caller's thread, where
/// the test harness's own threads must not count).
pub fn thread_allocations() -> u64 {
    THREAD_ALLOCATIONS.with(std::cell::Cell::get)
}

/// `navsync decode --yuma` of gpsd's `ublox-ned-m8t-sbfrx3` capture: the real GPS almanac as
/// YUMA text, for simulator scenarios with `[gnss.sky]` (the simulator parses it).
pub fn m8t_yuma() -> String {
    let capture = shared_material("corpora/gpsd-ubx").join("ublox-ned-m8t-sbfrx3.log");
    let out = Command::new(navsync_bin())
        .args(["decode", "--yuma"])
        .arg(&capture)
        .output()
        .expect("navsync decode");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).expect("YUMA is text")
}

/// Writes a drive scenario for live tests lasting at least `duration_s` of scenario time: 8 s
/// standing still (levelling), a drive-off and a turn (the filter aligns after ~15 s), then
/// 60° turns alternating with 12 s cruises to the end, so the IMU offsets stay observable and
/// the filter keeps being aided; `imus` industrial IMUs at `imu_rate_hz` (the second and later
/// late by the simulator's default offsets), GNSS at 1 Hz, truth at 10 Hz.
pub fn write_drive_scenario(path: &Path, duration_s: f64, imus: usize, imu_rate_hz: f64) {
    let mut s = String::from(
        "# Written by navsync_tests::write_drive_scenario.\nseed = 23\n\n[trajectory.start]\n\
         lat_deg = 48.137154\nlon_deg = 11.576124\nheight_m = 567.0\nheading_deg = 75.0\nspeed_mps = 0.0\n\n\
         [[trajectory.segment]]\nkind = \"static\"\nduration_s = 8.0\n\n\
         [[trajectory.segment]]\nkind = \"accelerate\"\nduration_s = 6.0\nto_speed_mps = 10.0\n",
    );
    let (mut t, mut sign) = (14.0, 1.0);
    while t < duration_s + 10.0 {
        let _ = write!(
            s,
            "\n[[trajectory.segment]]\nkind = \"turn\"\nduration_s = 8.0\nheading_change_deg = {:.1}\n\n\
             [[trajectory.segment]]\nkind = \"cruise\"\nduration_s = 12.0\n",
            60.0 * sign
        );
        t += 20.0;
        sign = -sign;
    }
    let _ = write!(
        s,
        "\n[imu]\ncount = {imus}\npreset = \"industrial\"\nrate_hz = {imu_rate_hz:.1}\n\n[truth]\nrate_hz = 10.0\n"
    );
    std::fs::write(path, s).expect("writing the scenario");
}

impl TestEnv {
    /// Starts the live pipeline as separate processes, as `navsync demo` does with xsens IMUs:
    /// `estimator` (first, so it sees every sample from the start), `pps` (`--source sim`),
    /// `sim` (on `scenario`, NMEA into a pseudo-terminal, each IMU as Xsens messages into its
    /// own), `gnss` on the NMEA pseudo-terminal and `imu0`…`imu{n-1}` on theirs.
    pub fn spawn_pipeline(&mut self, scenario: &Path, imus: usize) {
        let ids: Vec<String> = (0..imus).map(|i| i.to_string()).collect();
        let ids = ids.join(",");
        self.spawn("estimator", &["estimator", "--gnss", "0", "--pps", "0", "--imus", &ids]);
        self.spawn("pps", &["pps", "--source", "sim", "--id", "0"]);
        let link = self.dir.join("gnss0");
        let (link_s, dir_s) = (link.display().to_string(), self.dir.display().to_string());
        let (scen, n) = (scenario.display().to_string(), imus.to_string());
        self.spawn(
            "sim",
            &[
                "sim",
                "--scenario",
                &scen,
                "--imus",
                &n,
                "--pty-link",
                &link_s,
                "--imu-output",
                "xsens",
                "--imu-pty-dir",
                &dir_s,
            ],
        );
        self.wait_for_path(&link, Duration::from_secs(30));
        self.spawn("gnss", &["gnss", "--port", &link_s, "--baud", "115200", "--id", "0"]);
        for i in 0..imus {
            let port = self.dir.join(format!("imu{i}"));
            self.wait_for_path(&port, Duration::from_secs(30));
            let source = format!("xsens:{}:921600", port.display());
            self.spawn(
                &format!("imu{i}"),
                &["imu", "--source", &source, "--id", &i.to_string()],
            );
        }
    }

    /// True while the child `name` runs.
    pub fn is_running(&mut self, name: &str) -> bool {
        self.children
            .iter_mut()
            .find(|(n, _)| n == name)
            .is_some_and(|(_, c)| matches!(c.try_wait(), Ok(None)))
    }
}

/// The latest `Health` of some processes, by process name (`estimator`, `gnss-0`, `imu-1`, …).
pub struct HealthWatch {
    subs: Vec<(String, Subscriber<Health>)>,
    latest: HashMap<String, Health>,
}

impl HealthWatch {
    /// Subscribes to `navsync/health/{process}` for each process.
    pub fn new(node: &IpcNode, processes: &[&str]) -> Self {
        Self {
            subs: processes
                .iter()
                .map(|p| {
                    (
                        p.to_string(),
                        node.subscriber(&services::health(p)).expect("health subscriber"),
                    )
                })
                .collect(),
            latest: HashMap::new(),
        }
    }

    /// Takes every pending report; true if there was one.
    pub fn poll(&mut self) -> bool {
        let mut any = false;
        for (p, s) in &self.subs {
            while let Some(h) = s.receive().expect("receiving health") {
                self.latest.insert(p.clone(), h);
                any = true;
            }
        }
        any
    }

    /// The latest report of `process`.
    pub fn latest(&self, process: &str) -> Option<&Health> {
        self.latest.get(process)
    }

    /// A counter of the latest report of `process` (None before the first report).
    pub fn counter(&self, process: &str, name: &str) -> Option<u64> {
        self.latest.get(process).and_then(|h| h.counter(name))
    }

    /// Waits up to `timeout` for the next report of any watched process (sleeping on the
    /// first subscriber's event, polling the others every 5 ms); true if one came.
    pub fn wait(&mut self, timeout: Duration) -> bool {
        let t0 = Instant::now();
        loop {
            if self.poll() {
                return true;
            }
            if t0.elapsed() >= timeout {
                return false;
            }
            let step = Duration::from_millis(5).min(timeout.saturating_sub(t0.elapsed()));
            if let Some((p, s)) = self.subs.first()
                && let Some(h) = s.wait_next(step).expect("waiting for health")
            {
                self.latest.insert(p.clone(), h);
                return true;
            }
        }
    }
}

/// Resident set size of a process, KiB (`VmRSS` of `/proc/<pid>/status`); None once it is gone.
pub fn rss_kib(pid: u32) -> Option<u64> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    s.lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
}

/// The state letter of a process (`R`, `S`, `T` when stopped, …; `/proc/<pid>/stat`).
pub fn process_state(pid: u32) -> Option<char> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // pid (comm) state …: comm may hold spaces and parentheses; the state follows the last ')'.
    s.rsplit_once(')')
        .and_then(|(_, rest)| rest.trim_start().chars().next())
}

/// Headless Chromium on PATH (`chromium`, `chromium-browser` or `google-chrome`; `.ci/run`
/// installs Debian's `chromium`), if any.
pub fn chromium() -> Option<PathBuf> {
    ["chromium", "chromium-browser", "google-chrome"].iter().find_map(|c| {
        Command::new(c)
            .arg("--version")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .ok()
            .filter(|s| s.success())
            .map(|_| PathBuf::from(c))
    })
}

/// Runs headless Chromium `bin` with its profile in `profile` and `args` (e.g. `--dump-dom URL`,
/// `--screenshot=FILE URL`), killed after 40 s; its stdout.
pub fn run_chromium(bin: &Path, profile: &Path, args: &[String]) -> String {
    let mut child = Command::new(bin)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--disable-dev-shm-usage",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut out = child.stdout.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = std::io::Read::read_to_string(&mut out, &mut s);
        s
    });
    let t0 = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t0.elapsed() > Duration::from_secs(40) {
            let _ = child.kill();
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    reader.join().unwrap()
}

/// The `q` quantile (0…1, nearest rank) of `values` (sorted in place); NaN when empty.
pub fn quantile(values: &mut [f64], q: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    values.sort_by(f64::total_cmp);
    let k = ((q * values.len() as f64).ceil() as usize).clamp(1, values.len()) - 1;
    values[k]
}

/// Least-squares slope of `y` over `x`; 0 with fewer than two distinct `x`.
pub fn slope(points: &[(f64, f64)]) -> f64 {
    let n = points.len() as f64;
    if points.len() < 2 {
        return 0.0;
    }
    let (mx, my) = points.iter().fold((0.0, 0.0), |(a, b), (x, y)| (a + x / n, b + y / n));
    let (sxy, sxx) = points.iter().fold((0.0, 0.0), |(a, b), (x, y)| {
        (a + (x - mx) * (y - my), b + (x - mx) * (x - mx))
    });
    if sxx > 0.0 { sxy / sxx } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantile_and_slope() {
        let mut v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(quantile(&mut v, 0.99), 99.0);
        assert_eq!(quantile(&mut v, 0.5), 50.0);
        assert_eq!(quantile(&mut v, 1.0), 100.0);
        assert!(quantile(&mut [], 0.5).is_nan());
        let pts: Vec<(f64, f64)> = (0..10).map(|i| (f64::from(i), 3.0 + 2.0 * f64::from(i))).collect();
        assert!((slope(&pts) - 2.0).abs() < 1e-12);
        assert_eq!(slope(&pts[..1]), 0.0);
    }

    #[test]
    fn scenario_lasts_long_enough() {
        let dir = std::env::temp_dir().join(format!("navsync-scen-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("s.toml");
        write_drive_scenario(&p, 3600.0, 2, 100.0);
        let s = std::fs::read_to_string(&p).unwrap();
        let total: f64 = s
            .lines()
            .filter_map(|l| l.strip_prefix("duration_s = "))
            .map(|v| v.parse::<f64>().unwrap())
            .sum();
        assert!(total >= 3600.0, "{total}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
