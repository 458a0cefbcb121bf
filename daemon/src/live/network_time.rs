//! The network time service of a host without a receiver (`navsync estimator --time-source
//! chrony|system`): a thread reads it about once a second and hands each reading to the
//! estimator's loop as a [`NetworkTime`] sample (published on `navsync/time/network`, fused
//! by the time synchronisation, status `network`).
//!
//! - chrony: `chronyc -c -n -h ADDRESS tracking` (chronyc(1), "tracking"; the CSV fields in
//!   [`parse_chrony_tracking`]). chronyd's "System time" is the correction it still has to
//!   apply to the system clock (positive: the clock is slow), so UTC = `CLOCK_REALTIME` + that
//!   correction, whether chronyd slews the clock or only tracks it (`chronyd -x`, where the
//!   correction keeps the whole offset and its frequency term). The error bound chronyc(1)
//!   gives is root dispersion + root delay / 2 once the offset is corrected.
//! - system: `adjtimex(2)` with no mode bits (read only): the clock a daemon disciplines is
//!   UTC to within the kernel's `esterror`, bounded by `maxerror`; `STA_UNSYNC` means it is not.
//!
//! σ: the bound is a worst case (dispersions add up along the path, each growing at chrony's
//! `maxclockerror` since its last update), so [`BOUND_TO_SIGMA`] of it is taken as 1σ; the
//! time-sync test in tests/tests/timing/network_time.rs measures the error against that σ.

use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::time::{Duration, Instant};

use navsync_estimator::settings::TimeSource;
use navsync_shared::samples::{NetworkSource, NetworkTime};
use tracing::warn;

use super::ntpshm::paired_clocks_ns;

/// 1σ as a fraction of the source's error bound (module docs).
pub const BOUND_TO_SIGMA: f64 = 0.5;
/// Interval between readings.
pub const READ_INTERVAL: Duration = Duration::from_secs(1);
/// A `chronyc` that has not answered in this long is killed (chronyd gone or stuck).
const CHRONYC_TIMEOUT: Duration = Duration::from_secs(3);

/// What `chronyc -c tracking` says, in the units navsync uses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChronyTracking {
    /// Stratum of this host's chronyd (0: not synchronised).
    pub stratum: u8,
    /// Correction still to be applied to the system clock, s (positive: the clock is slow of
    /// NTP time).
    pub correction_s: f64,
    /// Frequency of the system clock as chronyd has it, ppm (positive: slow).
    pub freq_ppm: f64,
    /// Root delay, s.
    pub root_delay_s: f64,
    /// Root dispersion, s.
    pub root_dispersion_s: f64,
    /// Leap status is not "Not synchronised".
    pub synchronised: bool,
}

impl ChronyTracking {
    /// chronyc(1)'s bound on the error of the corrected clock, s.
    pub fn max_error_s(&self) -> f64 {
        self.root_dispersion_s + 0.5 * self.root_delay_s
    }
}

/// Errors of reading the network time service.
#[derive(Debug, thiserror::Error)]
pub enum NetworkTimeError {
    /// `chronyc` could not run or failed.
    #[error("chronyc -h {address}: {why}")]
    Chronyc {
        /// chronyd's command address or socket.
        address: String,
        /// What went wrong.
        why: String,
    },
    /// Its output was not the CSV tracking report.
    #[error("chronyc tracking: field {field}: {why} in `{line}`")]
    Parse {
        /// The field (chronyc(1)'s name).
        field: &'static str,
        /// What was wrong with it.
        why: String,
        /// The line.
        line: String,
    },
    /// adjtimex(2) failed.
    #[error("adjtimex: {0}")]
    Adjtimex(std::io::Error),
}

/// Parses one line of `chronyc -c tracking`: reference id, reference name, stratum, reference
/// time, system time, last offset, RMS offset, frequency, residual frequency, skew, root delay,
/// root dispersion, update interval, leap status (chronyc(1), "tracking"). Pure.
pub fn parse_chrony_tracking(csv: &str) -> Result<ChronyTracking, NetworkTimeError> {
    let line = csv.lines().next().unwrap_or("").trim();
    let f: Vec<&str> = line.split(',').collect();
    let err = |field: &'static str, why: &str| NetworkTimeError::Parse {
        field,
        why: why.into(),
        line: line.into(),
    };
    if f.len() < 14 {
        return Err(err("all", &format!("{} fields, expected 14", f.len())));
    }
    let num = |i: usize, field: &'static str| -> Result<f64, NetworkTimeError> {
        let v: f64 = f[i].trim().parse().map_err(|_| err(field, "not a number"))?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(err(field, "not finite"))
        }
    };
    let stratum = f[2].trim().parse::<u8>().map_err(|_| err("stratum", "not a stratum"))?;
    Ok(ChronyTracking {
        stratum,
        correction_s: num(4, "system time")?,
        freq_ppm: num(7, "frequency")?,
        root_delay_s: num(10, "root delay")?,
        root_dispersion_s: num(11, "root dispersion")?,
        synchronised: f[13].trim() != "Not synchronised" && stratum != 0,
    })
}

/// The reading of `t` at the instant (`host_ns`, `realtime_ns`) (`CLOCK_MONOTONIC`,
/// `CLOCK_REALTIME`). Pure.
pub fn chrony_sample(t: &ChronyTracking, host_ns: i64, realtime_ns: i64, seq: u64) -> NetworkTime {
    let mut s = <NetworkTime as navsync_shared::reflect::Reflect>::zeroed();
    s.host_ns = host_ns;
    s.utc_ns = realtime_ns + (t.correction_s * 1e9).round() as i64;
    s.seq = seq;
    s.max_error_ns = t.max_error_s() * 1e9;
    s.std_ns = s.max_error_ns * BOUND_TO_SIGMA;
    // chronyd's frequency is relative to the clock it reads; with the kernel disciplining the
    // clock it is already applied, with `-x` it is not: not knowable here, so not stated.
    s.rate_error = f64::NAN;
    s.stratum = t.stratum;
    s.source = NetworkSource::Chrony as u8;
    s.synchronised = u8::from(t.synchronised);
    s
}

fn read_chrony(address: &str) -> Result<ChronyTracking, NetworkTimeError> {
    let fail = |why: String| NetworkTimeError::Chronyc {
        address: address.to_string(),
        why,
    };
    let mut child = Command::new("chronyc")
        .args(["-c", "-n", "-h", address])
        .arg("tracking")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| fail(format!("cannot run chronyc (Debian package `chrony`): {e}")))?;
    let t0 = Instant::now();
    loop {
        match child.try_wait() {
            Ok(Some(_)) => break,
            Ok(None) if t0.elapsed() > CHRONYC_TIMEOUT => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(fail(format!("no answer in {CHRONYC_TIMEOUT:?}")));
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(2)),
            Err(e) => return Err(fail(e.to_string())),
        }
    }
    let out = child.wait_with_output().map_err(|e| fail(e.to_string()))?;
    if !out.status.success() {
        return Err(fail(format!(
            "{}: {}",
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        )));
    }
    parse_chrony_tracking(&String::from_utf8_lossy(&out.stdout))
}

/// The kernel's NTP state, read only (`adjtimex(2)` with `modes = 0`).
fn read_system(seq: u64) -> Result<NetworkTime, NetworkTimeError> {
    // SAFETY: a zeroed timex with modes 0 only reads the kernel's state.
    let mut tx: libc::timex = unsafe { std::mem::zeroed() };
    let (host_ns, realtime_ns) = paired_clocks_ns();
    // SAFETY: `tx` is a valid timex; modes 0 changes nothing.
    let state = unsafe { libc::adjtimex(&mut tx) };
    if state < 0 {
        return Err(NetworkTimeError::Adjtimex(std::io::Error::last_os_error()));
    }
    let mut s = <NetworkTime as navsync_shared::reflect::Reflect>::zeroed();
    s.host_ns = host_ns;
    s.utc_ns = realtime_ns;
    s.seq = seq;
    // esterror and maxerror are in µs (adjtimex(2)).
    s.max_error_ns = tx.maxerror as f64 * 1e3;
    s.std_ns = (tx.esterror as f64 * 1e3).max(s.max_error_ns * BOUND_TO_SIGMA);
    s.rate_error = f64::NAN;
    s.source = NetworkSource::System as u8;
    s.synchronised = u8::from(tx.status & libc::STA_UNSYNC == 0 && state != libc::TIME_ERROR);
    Ok(s)
}

/// The reader thread; stops when dropped.
pub struct NetworkTimeReader {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
    rx: Receiver<NetworkTime>,
}

impl NetworkTimeReader {
    /// Starts reading `source` (`chrony` at `address`, chronyc's `-h`, or `system`); `None`
    /// for [`TimeSource::Gnss`].
    pub fn start(source: TimeSource, address: &str) -> std::io::Result<Option<Self>> {
        if !source.is_network() {
            return Ok(None);
        }
        let stop = Arc::new(AtomicBool::new(false));
        let (tx, rx) = channel();
        let address = address.to_string();
        let flag = stop.clone();
        let thread = std::thread::Builder::new()
            .name("network-time".into())
            .spawn(move || read_loop(source, &address, &flag, &tx))?;
        Ok(Some(Self {
            stop,
            thread: Some(thread),
            rx,
        }))
    }

    /// The readings taken since the last call.
    pub fn drain(&self, mut f: impl FnMut(NetworkTime)) {
        while let Ok(s) = self.rx.try_recv() {
            f(s);
        }
    }
}

impl Drop for NetworkTimeReader {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn read_loop(source: TimeSource, address: &str, stop: &AtomicBool, tx: &Sender<NetworkTime>) {
    let mut seq = 0u64;
    let mut failing = false;
    while !stop.load(Ordering::Relaxed) {
        let t0 = Instant::now();
        let reading = match source {
            TimeSource::Chrony => read_chrony(address).map(|t| {
                let (host_ns, realtime_ns) = paired_clocks_ns();
                chrony_sample(&t, host_ns, realtime_ns, seq)
            }),
            _ => read_system(seq),
        };
        match reading {
            Ok(s) => {
                if failing {
                    warn!(source = ?source, "network time readable again");
                    failing = false;
                }
                seq += 1;
                if tx.send(s).is_err() {
                    return;
                }
            }
            // Once per failure streak: the status goes to holdover by itself.
            Err(e) if !failing => {
                warn!("network time: {e}");
                failing = true;
            }
            Err(_) => {}
        }
        let rest = READ_INTERVAL.saturating_sub(t0.elapsed());
        let end = Instant::now() + rest;
        while Instant::now() < end && !stop.load(Ordering::Relaxed) {
            std::thread::sleep(Duration::from_millis(50).min(end.saturating_duration_since(Instant::now())));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_a_tracking_report_and_maps_the_system_clock() {
        // chronyc -c tracking of chronyd -x with the system clock 0.125 s slow of its source.
        let csv = "4E415653,NAVS,1,1796342400.123456789,0.125000123,0.000000412,0.000001234,-0.512,0.001,0.020,0.000041000,0.000012000,2.0,Normal\n";
        let t = parse_chrony_tracking(csv).unwrap();
        assert_eq!(t.stratum, 1);
        assert!(t.synchronised);
        assert!((t.max_error_s() - (12e-6 + 20.5e-6)).abs() < 1e-12);
        let s = chrony_sample(&t, 5_000_000_000, 1_796_342_400_000_000_000, 7);
        assert_eq!(s.utc_ns, 1_796_342_400_125_000_123);
        assert!((s.std_ns - 32_500.0 * BOUND_TO_SIGMA).abs() < 1e-6);
        assert_eq!(s.seq, 7);
        assert_eq!(NetworkSource::from_u8(s.source), NetworkSource::Chrony);
    }

    #[test]
    fn an_unsynchronised_chronyd_says_so_and_bad_lines_name_the_field() {
        let csv = "00000000,,0,0.000000000,0.000000000,0.000000000,0.000000000,0.000,0.000,0.000,1.000000000,1.000000000,0.0,Not synchronised";
        assert!(!parse_chrony_tracking(csv).unwrap().synchronised);
        let e = parse_chrony_tracking("4E415653,NAVS,1,0,x,0,0,0,0,0,0,0,0,Normal").unwrap_err();
        assert!(e.to_string().contains("system time"), "{e}");
        let e = parse_chrony_tracking("506 Cannot talk to daemon").unwrap_err();
        assert!(e.to_string().contains("fields"), "{e}");
    }
}
