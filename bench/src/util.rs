//! What the benchmarks share: exact percentiles, the machine and its load,
//! per-process CPU time and memory from `/proc`, child processes with their own iceoryx2
//! prefix, and the JSON output.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use navsync_shared::cpu_wakeup::CpuWakeupHold;

/// Percentiles of a set of latencies, µs (exact: computed from every value).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Percentiles {
    /// Number of values.
    pub count: u64,
    /// Median, µs.
    pub p50_us: f64,
    /// 99th percentile, µs.
    pub p99_us: f64,
    /// 99.9th percentile, µs.
    pub p999_us: f64,
    /// Largest value, µs.
    pub max_us: f64,
    /// Mean, µs.
    pub mean_us: f64,
}

impl Percentiles {
    /// From latencies in ns (sorted in place). Nearest-rank percentiles; all zero when empty.
    pub fn from_ns(values: &mut [i64]) -> Self {
        if values.is_empty() {
            return Self::default();
        }
        values.sort_unstable();
        let n = values.len();
        let rank = |q: f64| values[((q * n as f64).ceil() as usize).clamp(1, n) - 1] as f64 * 1e-3;
        let sum: i128 = values.iter().map(|&v| i128::from(v)).sum();
        Self {
            count: n as u64,
            p50_us: rank(0.5),
            p99_us: rank(0.99),
            p999_us: rank(0.999),
            max_us: values[n - 1] as f64 * 1e-3,
            mean_us: sum as f64 / n as f64 * 1e-3,
        }
    }

    /// True when the figures are finite, non-negative and ordered p50 ≤ p99 ≤ p99.9 ≤ max.
    pub fn is_sane(&self) -> bool {
        let v = [self.p50_us, self.p99_us, self.p999_us, self.max_us, self.mean_us];
        v.iter().all(|x| x.is_finite() && *x >= 0.0)
            && self.p50_us <= self.p99_us
            && self.p99_us <= self.p999_us
            && self.p999_us <= self.max_us
    }
}

/// The machine a benchmark ran on and how busy it was.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Machine {
    /// CPU model (`/proc/cpuinfo`).
    pub cpu: String,
    /// Online CPUs.
    pub cpus: usize,
    /// Kernel release.
    pub kernel: String,
    /// 1-minute load average at the start.
    pub load_start: f64,
    /// 1-minute load average at the end.
    pub load_end: f64,
    /// The cpuidle driver (`/sys/devices/system/cpu/cpuidle/current_driver`).
    pub cpuidle: String,
    /// True while the run held the CPU wake-up latency request at 0 ([`CpuWakeupHold`]).
    pub idle_polling: bool,
    /// Time the hypervisor kept the vCPUs from running while they had work, % of their busy
    /// time over the run (`/proc/stat` steal ÷ (user + nice + system + irq + softirq +
    /// steal)); `NaN` where not reported. On a VM whose idle vCPUs halt, waking one goes
    /// through the host, and that wait is counted here: the wake-up latency no scheduling
    /// setting inside the guest removes.
    pub steal_percent: f64,
    /// `/proc/stat` counters at the start (busy, steal), jiffies.
    #[serde(skip)]
    cpu_ticks_start: Option<(u64, u64)>,
}

impl Machine {
    /// The machine now (`load_end` = `load_start` until [`finish`](Self::finish)).
    pub fn now() -> Self {
        let cpu = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|s| {
                s.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split_once(':'))
                    .map(|(_, v)| v.trim().to_string())
            })
            .unwrap_or_else(|| "unknown".into());
        let kernel = std::fs::read_to_string("/proc/sys/kernel/osrelease")
            .map(|s| s.trim().to_string())
            .unwrap_or_default();
        let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
        let load = load_average();
        let cpuidle = std::fs::read_to_string("/sys/devices/system/cpu/cpuidle/current_driver")
            .map(|s| s.trim().to_string())
            .unwrap_or_else(|_| "none".into());
        Self {
            cpu,
            cpus,
            kernel,
            load_start: load,
            load_end: load,
            cpuidle,
            idle_polling: false,
            steal_percent: f64::NAN,
            cpu_ticks_start: busy_and_steal_ticks(),
        }
    }

    /// Records the load and the stolen time at the end.
    pub fn finish(&mut self) {
        self.load_end = load_average();
        if let (Some((b0, s0)), Some((b1, s1))) = (self.cpu_ticks_start, busy_and_steal_ticks())
            && b1 > b0
        {
            self.steal_percent = 100.0 * s1.saturating_sub(s0) as f64 / (b1 - b0) as f64;
        }
    }

    /// One line for the tables.
    pub fn line(&self) -> String {
        format!(
            "machine: {} × {}, Linux {}, cpuidle {}{}; load average {:.2} at start, {:.2} at end; \
             host steal {:.1} % of busy time",
            self.cpus,
            self.cpu,
            self.kernel,
            self.cpuidle,
            if self.idle_polling {
                " (held at 0 µs wake-up latency: idle CPUs poll)"
            } else {
                ""
            },
            self.load_start,
            self.load_end,
            self.steal_percent
        )
    }
}

/// All CPUs' busy time (user + nice + system + irq + softirq + steal) and stolen time so far,
/// jiffies (`/proc/stat`, first line).
fn busy_and_steal_ticks() -> Option<(u64, u64)> {
    let stat = std::fs::read_to_string("/proc/stat").ok()?;
    let f: Vec<u64> = stat
        .lines()
        .next()?
        .split_whitespace()
        .skip(1)
        .map(|v| v.parse().ok())
        .collect::<Option<_>>()?;
    // user nice system idle iowait irq softirq steal ...; all but idle and iowait are busy.
    let steal = *f.get(7)?;
    let busy: u64 = [0, 1, 2, 5, 6].iter().map(|&i| f[i]).sum::<u64>() + steal;
    Some((busy, steal))
}

/// 1-minute load average.
pub fn load_average() -> f64 {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| s.split_whitespace().next().and_then(|v| v.parse().ok()))
        .unwrap_or(f64::NAN)
}

/// CPU time (user + system) of a process so far, s (`/proc/PID/stat` utime + stime).
pub fn cpu_time_s(pid: u32) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name is in parentheses and may contain spaces: fields start after the last ')'.
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    // After the name: state(3) ... utime(14) stime(15), i.e. indices 11 and 12 here.
    let utime: f64 = f.get(11)?.parse().ok()?;
    let stime: f64 = f.get(12)?.parse().ok()?;
    // SAFETY: sysconf with a valid name.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) }.max(1) as f64;
    Some((utime + stime) / hz)
}

/// CPU time of the calling process so far, s (getrusage: µs resolution).
pub fn own_cpu_time_s() -> f64 {
    // SAFETY: getrusage fills a zeroed struct.
    let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: valid pointer to a rusage.
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut ru) };
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    tv(ru.ru_utime) + tv(ru.ru_stime)
}

/// Peak resident set size of a process, KiB (`VmHWM` in `/proc/PID/status`).
pub fn peak_rss_kib(pid: u32) -> Option<u64> {
    status_field_kib(pid, "VmHWM:")
}

/// Current resident set size of a process, KiB (`VmRSS`).
pub fn rss_kib(pid: u32) -> Option<u64> {
    status_field_kib(pid, "VmRSS:")
}

fn status_field_kib(pid: u32, field: &str) -> Option<u64> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    s.lines()
        .find(|l| l.starts_with(field))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()
}

/// A unique iceoryx2 resource prefix and scratch directory for one benchmark run.
pub struct BenchEnv {
    /// iceoryx2 resource prefix (passed to every child as `$NAVSYNC_IPC_PREFIX`).
    pub prefix: String,
    /// Scratch directory, removed on drop.
    pub dir: PathBuf,
    children: Vec<(String, Child)>,
}

/// A child process stopped (and reaped) on drop: SIGTERM, up to 5 s to exit, then SIGKILL.
pub struct StopOnDrop(pub std::process::Child);

impl Drop for StopOnDrop {
    fn drop(&mut self) {
        // SAFETY: signalling our own child.
        unsafe { libc::kill(self.0.id() as libc::pid_t, libc::SIGTERM) };
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(5) {
            if let Ok(Some(_)) = self.0.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The `navsync` binary the benchmarks start: `$NAVSYNC_BIN`, else the one beside this
/// executable (`cargo build --release` puts both into `target/release/`).
pub fn navsync_exe() -> std::io::Result<PathBuf> {
    if let Some(p) = std::env::var_os("NAVSYNC_BIN") {
        return Ok(PathBuf::from(p));
    }
    let exe = std::env::current_exe()?;
    let p = exe.with_file_name("navsync");
    if p.exists() {
        Ok(p)
    } else {
        Err(std::io::Error::new(
            std::io::ErrorKind::NotFound,
            format!(
                "no navsync binary beside {} (build it: cargo build --release -p navsync; or set $NAVSYNC_BIN)",
                exe.display()
            ),
        ))
    }
}

/// A comma-separated IMU count (1 to `MAX_IMUS`).
pub fn imu_count(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if (1..=navsync_shared::samples::MAX_IMUS).contains(&n) => Ok(n),
        _ => Err(format!("`{s}`: 1 to {} IMUs", navsync_shared::samples::MAX_IMUS)),
    }
}

/// A subscriber count (1 to `MAX_SUBSCRIBERS`).
pub fn subscriber_count(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if (1..=navsync_shared::services::MAX_SUBSCRIBERS).contains(&n) => Ok(n),
        _ => Err(format!(
            "`{s}`: 1 to {} subscribers",
            navsync_shared::services::MAX_SUBSCRIBERS
        )),
    }
}

impl BenchEnv {
    /// A fresh environment tagged `tag`.
    pub fn new(tag: &str) -> std::io::Result<Self> {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos());
        let prefix = format!("nsb{}_{tag}_{nanos:x}_", std::process::id());
        let dir = std::env::temp_dir().join(format!("navsync-bench-{prefix}"));
        std::fs::create_dir_all(&dir)?;
        Ok(Self {
            prefix,
            dir,
            children: Vec::new(),
        })
    }

    /// A command in this environment: `navsync-bench helper …` (this executable) when
    /// `args` start with `helper`, else `navsync ARGS` ([`navsync_exe`]).
    pub fn command(&self, args: &[String]) -> std::io::Result<Command> {
        let program = if args.first().is_some_and(|a| a == "helper") {
            std::env::current_exe()?
        } else {
            navsync_exe()?
        };
        let mut c = Command::new(program);
        c.args(args)
            .env(navsync_shared::services::PREFIX_ENV, &self.prefix)
            .env("RUST_LOG", "warn");
        Ok(c)
    }

    /// Starts `navsync ARGS` as a child named `name`; stdout is piped when `pipe_stdout`
    /// (returned), stderr goes to `<dir>/<name>.log`. Returns the pid.
    pub fn spawn(
        &mut self,
        name: &str,
        args: &[String],
        pipe_stdout: bool,
    ) -> std::io::Result<(u32, Option<ChildStdout>)> {
        let log = std::fs::File::create(self.dir.join(format!("{name}.log")))?;
        let mut child = self
            .command(args)?
            .stdout(if pipe_stdout { Stdio::piped() } else { Stdio::null() })
            .stderr(log)
            .spawn()?;
        let out = child.stdout.take();
        let pid = child.id();
        self.children.push((name.to_string(), child));
        Ok((pid, out))
    }

    /// The stderr log of a child.
    pub fn log(&self, name: &str) -> String {
        std::fs::read_to_string(self.dir.join(format!("{name}.log"))).unwrap_or_default()
    }

    /// Fails if a child has exited (with the end of its log).
    pub fn check_running(&mut self) -> Result<(), String> {
        for (name, c) in &mut self.children {
            if let Ok(Some(st)) = c.try_wait() {
                let log = std::fs::read_to_string(self.dir.join(format!("{name}.log"))).unwrap_or_default();
                let tail: String = log
                    .lines()
                    .rev()
                    .take(8)
                    .collect::<Vec<_>>()
                    .into_iter()
                    .rev()
                    .collect::<Vec<_>>()
                    .join("\n");
                return Err(format!("{name} exited early ({st}):\n{tail}"));
            }
        }
        Ok(())
    }

    /// Waits until the child `name` exits by itself (up to `timeout`); its exit status.
    pub fn wait_exit(&mut self, name: &str, timeout: Duration) -> Option<std::process::ExitStatus> {
        let t0 = Instant::now();
        let c = &mut self.children.iter_mut().find(|(n, _)| n == name)?.1;
        loop {
            if let Ok(Some(st)) = c.try_wait() {
                return Some(st);
            }
            if t0.elapsed() > timeout {
                return None;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Sends SIGTERM to the child `name`.
    pub fn terminate(&self, name: &str) {
        if let Some((_, c)) = self.children.iter().find(|(n, _)| n == name) {
            // SAFETY: signalling our own child by pid.
            unsafe { libc::kill(c.id() as libc::pid_t, libc::SIGTERM) };
        }
    }

    /// Stops every child (SIGTERM, last started first; SIGKILL after 5 s) and returns the names
    /// of those that did not exit cleanly.
    pub fn stop_all(&mut self) -> Vec<String> {
        for (_, c) in self.children.iter().rev() {
            // SAFETY: signalling our own child by pid.
            unsafe { libc::kill(c.id() as libc::pid_t, libc::SIGTERM) };
        }
        let t0 = Instant::now();
        let mut bad = Vec::new();
        for (name, c) in self.children.iter_mut().rev() {
            let ok = loop {
                match c.try_wait() {
                    Ok(Some(st)) => break st.success(),
                    Ok(None) if t0.elapsed() < Duration::from_secs(5) => std::thread::sleep(Duration::from_millis(5)),
                    _ => {
                        let _ = c.kill();
                        let _ = c.wait();
                        break false;
                    }
                }
            };
            if !ok {
                bad.push(name.clone());
            }
        }
        self.children.clear();
        bad
    }
}

impl Drop for BenchEnv {
    fn drop(&mut self) {
        if !self.children.is_empty() {
            self.stop_all();
        }
        let _ = std::fs::remove_dir_all(&self.dir);
        remove_prefix_files(&self.prefix);
    }
}

/// Removes what iceoryx2 leaves of a prefix once every process of it is gone (its node
/// counter, `/dev/shm/<prefix>…global_mgmt`), and anything else of the prefix in `/dev/shm`
/// and `/tmp/iceoryx2`.
pub fn remove_prefix_files(prefix: &str) {
    for d in ["/dev/shm", "/tmp/iceoryx2"] {
        remove_prefixed(Path::new(d), prefix);
    }
}

fn remove_prefixed(dir: &Path, prefix: &str) {
    let Ok(rd) = std::fs::read_dir(dir) else { return };
    for e in rd.flatten() {
        let p = e.path();
        if p.is_dir() {
            remove_prefixed(&p, prefix);
        } else if e.file_name().to_string_lossy().starts_with(prefix) {
            let _ = std::fs::remove_file(p);
        }
    }
}

/// Reads lines from a child's stdout until one equals `line` (or the pipe closes / `timeout`).
pub fn wait_for_line(out: &mut BufReader<ChildStdout>, line: &str, timeout: Duration) -> bool {
    // The child prints the line right after it set up; a blocking read is enough, the timeout
    // guards against a child that hangs before printing (it is then killed by the caller).
    let t0 = Instant::now();
    let mut buf = String::new();
    while t0.elapsed() < timeout {
        buf.clear();
        match out.read_line(&mut buf) {
            Ok(0) | Err(_) => return false,
            Ok(_) if buf.trim_end() == line => return true,
            Ok(_) => {}
        }
    }
    false
}

/// Reads `out` up to and including its next JSON line; None at end of output.
pub fn next_json_line(out: &mut BufReader<ChildStdout>) -> Option<serde_json::Value> {
    let mut buf = String::new();
    loop {
        buf.clear();
        match out.read_line(&mut buf) {
            Ok(0) | Err(_) => return None,
            Ok(_) => {
                if let Ok(v) = serde_json::from_str::<serde_json::Value>(buf.trim()) {
                    return Some(v);
                }
            }
        }
    }
}

/// Reads the rest of a child's stdout and returns the last line that parses as JSON.
pub fn last_json_line(out: &mut BufReader<ChildStdout>) -> Option<serde_json::Value> {
    let mut last = None;
    while let Some(v) = next_json_line(out) {
        last = Some(v);
    }
    last
}

/// Writes `value` as pretty JSON to `path`.
pub fn write_json<T: Serialize>(path: &Path, value: &T) -> std::io::Result<()> {
    let text = serde_json::to_string_pretty(value).map_err(std::io::Error::other)?;
    std::fs::write(path, text + "\n")
}

/// Writes latencies (ns) as little-endian i64 to `path`.
pub fn write_latencies(path: &Path, values: &[i64]) -> std::io::Result<()> {
    let mut bytes = Vec::with_capacity(values.len() * 8);
    for v in values {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    std::fs::write(path, bytes)
}

/// Reads latencies written by [`write_latencies`].
pub fn read_latencies(path: &Path) -> std::io::Result<Vec<i64>> {
    let bytes = std::fs::read(path)?;
    Ok(bytes
        .chunks_exact(8)
        .map(|c| i64::from_le_bytes(c.try_into().unwrap_or([0; 8])))
        .collect())
}

/// Takes the [`CpuWakeupHold`] when `hold` (a `--realtime` or `--idle-polling` run): `None`
/// (with a warning) when not allowed; records in `machine` whether it is held.
pub fn wakeup_hold(hold: bool, machine: &mut Machine) -> Option<CpuWakeupHold> {
    if !hold {
        return None;
    }
    match CpuWakeupHold::take() {
        Ok(h) => {
            machine.idle_polling = true;
            Some(h)
        }
        Err(e) => {
            eprintln!("note: CPU wake-up latency not held (/dev/cpu_dma_latency: {e}); idle CPUs may halt");
            None
        }
    }
}

/// CPUs online (`sysconf(_SC_NPROCESSORS_ONLN)`), at least 1.
pub fn online_cpus() -> usize {
    // SAFETY: sysconf has no preconditions.
    let n = unsafe { libc::sysconf(libc::_SC_NPROCESSORS_ONLN) };
    usize::try_from(n).unwrap_or(1).max(1)
}

fn cpu_set(cpus: &[usize]) -> libc::cpu_set_t {
    // SAFETY: an all-zero cpu_set_t is the empty set.
    let mut set: libc::cpu_set_t = unsafe { core::mem::zeroed() };
    for &c in cpus {
        // SAFETY: CPU_SET on a valid set; indices beyond its size are ignored by libc.
        unsafe { libc::CPU_SET(c, &mut set) };
    }
    set
}

/// Restricts thread `tid` (0: the calling thread) to `cpus`.
fn set_thread_affinity(tid: libc::pid_t, cpus: &[usize]) -> std::io::Result<()> {
    let set = cpu_set(cpus);
    // SAFETY: a valid set for the call's duration.
    if unsafe { libc::sched_setaffinity(tid, size_of::<libc::cpu_set_t>(), &set) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

/// Restricts the calling thread to `cpus`.
pub fn pin_this_thread(cpus: &[usize]) -> std::io::Result<()> {
    set_thread_affinity(0, cpus)
}

/// Restricts every thread of process `pid` to `cpus` (threads it starts later inherit it).
pub fn set_affinity(pid: u32, cpus: &[usize]) -> std::io::Result<()> {
    for task in std::fs::read_dir(format!("/proc/{pid}/task"))? {
        let Some(tid) = task?.file_name().to_str().and_then(|t| t.parse::<libc::pid_t>().ok()) else {
            continue;
        };
        match set_thread_affinity(tid, cpus) {
            // A thread that ended meanwhile is not an error.
            Err(e) if e.raw_os_error() != Some(libc::ESRCH) => return Err(e),
            _ => {}
        }
    }
    Ok(())
}

/// Puts the main thread of process `pid` under SCHED_FIFO with priority `prio` (threads it
/// starts later inherit it; helper threads such as the estimator's dead-node reclaimer put
/// themselves under SCHED_IDLE).
pub fn set_fifo(pid: u32, prio: u8) -> std::io::Result<()> {
    let param = libc::sched_param {
        sched_priority: i32::from(prio),
    };
    // SAFETY: sched_setscheduler with a valid sched_param for the call's duration.
    if unsafe { libc::sched_setscheduler(pid as libc::pid_t, libc::SCHED_FIFO, &param) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_exact() {
        let mut v: Vec<i64> = (1..=1000).rev().map(|us| us * 1000).collect();
        let p = Percentiles::from_ns(&mut v);
        assert_eq!(p.count, 1000);
        assert_eq!(p.p50_us, 500.0);
        assert_eq!(p.p99_us, 990.0);
        assert_eq!(p.p999_us, 999.0);
        assert_eq!(p.max_us, 1000.0);
        assert!(p.is_sane());
        assert_eq!(Percentiles::from_ns(&mut []), Percentiles::default());
    }

    #[test]
    fn own_process_figures() {
        let pid = std::process::id();
        assert!(cpu_time_s(pid).is_some_and(|t| t >= 0.0));
        assert!(peak_rss_kib(pid).is_some_and(|k| k > 0));
        assert!(rss_kib(pid).is_some_and(|k| k > 0));
        assert!(load_average() >= 0.0);
    }
}
