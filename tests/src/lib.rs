//! # navsync-tests
//!
//! Helpers for multi-process integration tests: each test gets its own iceoryx2 resource
//! prefix (so parallel tests and a running demo never meet), starts real `navsync` processes
//! with it, talks to them from the test process over real iceoryx2 services, and at the end
//! checks that no shared memory was left behind.
//!
//! The `navsync` binary is the one cargo built next to the test executable
//! (`target/<profile>/navsync`; `cargo test --workspace` builds it), or `$NAVSYNC_BIN`.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use navsync_shared::ipc::IpcNode;

/// Path of the `navsync` executable under test.
pub fn navsync_bin() -> PathBuf {
    if let Ok(p) = std::env::var("NAVSYNC_BIN") {
        return PathBuf::from(p);
    }
    let exe = std::env::current_exe().expect("test executable path");
    // target/<profile>/deps/<test>-<hash> → target/<profile>/navsync
    let bin = exe
        .parent()
        .and_then(Path::parent)
        .map(|d| d.join("navsync"))
        .expect("target dir");
    assert!(
        bin.exists(),
        "{} not found: run the tests with `cargo test --workspace` (which builds the binary) or set NAVSYNC_BIN",
        bin.display()
    );
    bin
}

/// Path of the gpsd NMEA corpus provided beside the checkout.
pub fn corpus_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/corpora/gpsd-nmea")
}

static SEQ: AtomicU32 = AtomicU32::new(0);

/// One isolated navsync instance: a unique prefix, a scratch directory, child processes.
pub struct TestEnv {
    /// iceoryx2 resource prefix of this test.
    pub prefix: String,
    /// Scratch directory, removed at the end.
    pub dir: PathBuf,
    children: Vec<(String, Child)>,
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
        }
    }

    /// A `navsync` command with this environment's prefix.
    pub fn command(&self, args: &[&str]) -> Command {
        let mut c = Command::new(navsync_bin());
        c.args(args)
            .env(navsync_shared::services::PREFIX_ENV, &self.prefix)
            .env("RUST_LOG", "warn");
        c
    }

    /// Starts `navsync ARGS` as a child; its stderr goes to `<dir>/<name>.log`.
    pub fn spawn(&mut self, name: &str, args: &[&str]) -> u32 {
        let log = std::fs::File::create(self.dir.join(format!("{name}.log"))).expect("log file");
        let child = self
            .command(args)
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .unwrap_or_else(|e| panic!("starting navsync {args:?}: {e}"));
        let pid = child.id();
        self.children.push((name.to_string(), child));
        pid
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
    let mut visit = vec![PathBuf::from("/dev/shm"), PathBuf::from("/tmp/iceoryx2")];
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

/// Shared-memory and iceoryx2 files of this prefix other than the persistent node counter.
pub fn leftovers(prefix: &str) -> Vec<PathBuf> {
    list_prefixed(prefix)
        .into_iter()
        .filter(|p| !p.to_string_lossy().ends_with(".global_mgmt"))
        .collect()
}
