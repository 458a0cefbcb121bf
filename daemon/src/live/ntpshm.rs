//! `navsync ntpshm --unit N [--sock PATH] [--max-std-us F]`: exports navsync's GNSS time to
//! chrony or ntpd through the NTP shared-memory reference clock (ntpd's `refclock_shm.c`
//! driver, "type 28"; chrony's `refclock SHM N`; gpsd writes the same segment), and with
//! `--sock` through chrony's socket reference clock too (`refclock SOCK PATH`, the interface
//! gpsd uses: one datagram per sample, chrony's `refclock_sock.c` `struct sock_sample`).
//!
//! The segment is System V shared memory with key `0x4e545030 + N` ("NTP0" + unit) holding
//! one [`ShmTime`]. The writer uses mode 1, the count/valid protocol: set `valid = 0`,
//! increment `count`, write the fields, increment `count` again, set `valid = 1`; the reader
//! copies the structure and uses it only if `count` did not change while it copied and `valid`
//! was set, then clears `valid` (ntpd `refclock_shm.c`, `shm_query`).
//!
//! What goes in. A sample is a pair of readings of the same instant h:
//! - `clockTimeStamp` = GNSS time (UTC) at h from the published [`TimeState`] mapping;
//! - `receiveTimeStamp` = the system's `CLOCK_REALTIME` at h.
//!
//! The reference clock's offset that chrony/ntpd measure is their difference. h is chosen now:
//! (monotonic, realtime, monotonic) are read back to back, h is the middle of the monotonic
//! pair (the tightest of three tries, < 1 µs wide), and the mapping gives GNSS time at h (the
//! mapping is continuous in host time; when locked it is at most ~1 s from its last PPS edge).
//! One sample per second while the mapping is usable: locked, in holdover (chrony keeps
//! disciplining through a PPS or GNSS loss; the mapping's uncertainty grows honestly and is
//! written as `precision`), or software sync; nothing while it is acquiring or unknown, and
//! nothing when no `TimeState` arrived for [`STALE_AFTER_NS`] (the estimator is gone).
//!
//! The bound. A sample whose mapping 1σ at the instant exceeds `--max-std-us` (default
//! [`DEFAULT_MAX_STD_US`]) is withheld, on both interfaces: a long holdover or a software-only
//! mapping then stops feeding chrony, which sees the refclock go unreachable and falls back on
//! its own selection and holdover (the SHM `precision` field carries the σ, but chrony's SOCK
//! sample has no such field). Counted as `withheld_over_bound`.

use std::time::Duration;

use navsync_shared::health_reporter::HealthReporter;
use navsync_shared::ipc::{IpcError, IpcNode};
use navsync_shared::samples::{TimeState, TimeStatus};
use navsync_shared::services;
use navsync_shared::time::{NS_PER_S, monotonic_now_ns};
use tracing::{info, info_span, warn};

/// Key of unit 0: "NTP0".
pub const NTP_SHM_BASE_KEY: i32 = 0x4e54_5030;
/// Consecutive failed waits (other than for a termination signal) before giving up.
const MAX_IPC_ERRORS: u32 = 100;
/// A `TimeState` older than this is not exported, ns.
pub const STALE_AFTER_NS: i64 = 5 * NS_PER_S;
/// Default bound on the exported mapping's 1σ, µs: beyond it a sample is withheld.
pub const DEFAULT_MAX_STD_US: f64 = 1000.0;
/// `struct sock_sample`'s protocol identifier ("SOCK"; chrony `refclock_sock.c`).
pub const SOCK_MAGIC: i32 = 0x534f_434b;

/// chrony's `struct sock_sample` (`refclock_sock.c`), native layout: one datagram per sample.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SockSample {
    /// System time of the measurement (`struct timeval`), seconds since 1970.
    pub tv_sec: libc::time_t,
    /// Its µs part.
    pub tv_usec: libc::suseconds_t,
    /// True (GNSS) time minus the system time at `tv`, s.
    pub offset: f64,
    /// 0: the sample carries the whole time, not only a pulse.
    pub pulse: i32,
    /// 0 normal, 1 insert, 2 delete a leap second.
    pub leap: i32,
    /// Padding.
    pub pad: i32,
    /// [`SOCK_MAGIC`].
    pub magic: i32,
}

impl SockSample {
    /// The datagram of `s`: the system time at the instant and GNSS minus system time.
    pub fn of(s: &ShmSample) -> Self {
        let (sec, usec, _) = split(s.receive_ns);
        // The offset from the µs-truncated system time chrony receives (tv), ns exact.
        let tv_ns = s.receive_ns - s.receive_ns.rem_euclid(1000);
        Self {
            tv_sec: sec,
            tv_usec: usec as libc::suseconds_t,
            offset: (s.clock_ns - tv_ns) as f64 * 1e-9,
            pulse: 0,
            leap: 0,
            pad: 0,
            magic: SOCK_MAGIC,
        }
    }

    /// The datagram's bytes: each field at its `repr(C)` offset, native byte order, any
    /// padding zero.
    pub fn bytes(&self) -> [u8; size_of::<SockSample>()] {
        use std::mem::offset_of;
        let mut b = [0u8; size_of::<SockSample>()];
        let mut put = |at: usize, v: &[u8]| b[at..at + v.len()].copy_from_slice(v);
        put(offset_of!(SockSample, tv_sec), &self.tv_sec.to_ne_bytes());
        put(offset_of!(SockSample, tv_usec), &self.tv_usec.to_ne_bytes());
        put(offset_of!(SockSample, offset), &self.offset.to_ne_bytes());
        put(offset_of!(SockSample, pulse), &self.pulse.to_ne_bytes());
        put(offset_of!(SockSample, leap), &self.leap.to_ne_bytes());
        put(offset_of!(SockSample, pad), &self.pad.to_ne_bytes());
        put(offset_of!(SockSample, magic), &self.magic.to_ne_bytes());
        b
    }
}

/// ntpd's `struct shmTime` (ntpd `refclock_shm.c`, gpsd `ntpshm.h`), native layout.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ShmTime {
    /// 0: valid-flag protocol only; 1: count/valid protocol (navsync writes 1).
    pub mode: i32,
    /// Incremented before and after each write.
    pub count: i32,
    /// Reference (GNSS) time, seconds since 1970.
    pub clock_time_stamp_sec: libc::time_t,
    /// Reference time, µs part.
    pub clock_time_stamp_usec: i32,
    /// System clock at the same instant, seconds.
    pub receive_time_stamp_sec: libc::time_t,
    /// System clock, µs part.
    pub receive_time_stamp_usec: i32,
    /// Leap indicator: 0 none, 1 insert, 2 delete, 3 not synchronised.
    pub leap: i32,
    /// log2 of the sample's precision, s.
    pub precision: i32,
    /// Unused (ntpd's filter length).
    pub nsamples: i32,
    /// 1 when the fields hold a new sample.
    pub valid: i32,
    /// Reference time, ns part (must agree with the µs part).
    pub clock_time_stamp_nsec: u32,
    /// System clock, ns part.
    pub receive_time_stamp_nsec: u32,
    /// Reserved.
    pub dummy: [i32; 8],
}

/// One sample to write.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShmSample {
    /// GNSS (UTC) time of the instant, ns since 1970.
    pub clock_ns: i64,
    /// `CLOCK_REALTIME` at the same instant, ns since 1970.
    pub receive_ns: i64,
    /// log2 of the 1-sigma, s.
    pub precision: i32,
}

/// The sample for instant `host_ns` (`CLOCK_MONOTONIC`) read as `realtime_ns` on the system
/// clock, from the mapping `state`; `None` when the mapping must not be exported (not usable,
/// stale, or its 1σ at the instant above `max_std_ns`). Pure.
pub fn sample_for(state: &TimeState, host_ns: i64, realtime_ns: i64, max_std_ns: f64) -> Option<ShmSample> {
    let sigma_s = exportable_std_ns(state, host_ns, max_std_ns)? * 1e-9;
    let precision = if sigma_s.is_finite() && sigma_s > 0.0 {
        sigma_s.log2().ceil().clamp(-30.0, 0.0) as i32
    } else {
        -20
    };
    Some(ShmSample {
        clock_ns: state.utc_ns_at(host_ns),
        receive_ns: realtime_ns,
        precision,
    })
}

/// The 1σ (ns) of the mapping `state` at host time `host_ns` when GNSS time may be handed on
/// from it (to chrony, ntpd or a sensor): locked, in holdover or software sync, computed at
/// most [`STALE_AFTER_NS`] ago, σ known and at most `max_std_ns`. Pure.
pub fn exportable_std_ns(state: &TimeState, host_ns: i64, max_std_ns: f64) -> Option<f64> {
    let usable = matches!(
        state.status(),
        TimeStatus::Locked | TimeStatus::Holdover | TimeStatus::Software
    ) && host_ns - state.computed_host_ns <= STALE_AFTER_NS;
    let std = state.utc_std_ns_at(host_ns);
    // A σ that is not a number is over any bound.
    (usable && !std.is_nan() && std <= max_std_ns).then_some(std)
}

fn split(ns: i64) -> (libc::time_t, i32, u32) {
    let sec = ns.div_euclid(NS_PER_S);
    let nsec = ns.rem_euclid(NS_PER_S) as u32;
    (sec as libc::time_t, (nsec / 1000) as i32, nsec)
}

/// Writes `s` into `shm` with the mode-1 count/valid protocol.
///
/// # Safety
/// `shm` must point to a mapped `ShmTime` (it may be shared with other processes).
pub unsafe fn write_sample(shm: *mut ShmTime, s: &ShmSample) {
    use core::ptr::{addr_of_mut, read_volatile, write_volatile};
    use core::sync::atomic::{Ordering, fence};
    let (cs, cu, cn) = split(s.clock_ns);
    let (rs, ru, rn) = split(s.receive_ns);
    // SAFETY (whole block): the caller guarantees `shm` is mapped; volatile accesses because a
    // reader in another process polls the same memory.
    unsafe {
        write_volatile(addr_of_mut!((*shm).mode), 1);
        write_volatile(addr_of_mut!((*shm).valid), 0);
        let c = read_volatile(addr_of_mut!((*shm).count));
        write_volatile(addr_of_mut!((*shm).count), c.wrapping_add(1));
        fence(Ordering::SeqCst);
        write_volatile(addr_of_mut!((*shm).clock_time_stamp_sec), cs);
        write_volatile(addr_of_mut!((*shm).clock_time_stamp_usec), cu);
        write_volatile(addr_of_mut!((*shm).clock_time_stamp_nsec), cn);
        write_volatile(addr_of_mut!((*shm).receive_time_stamp_sec), rs);
        write_volatile(addr_of_mut!((*shm).receive_time_stamp_usec), ru);
        write_volatile(addr_of_mut!((*shm).receive_time_stamp_nsec), rn);
        write_volatile(addr_of_mut!((*shm).leap), 0);
        write_volatile(addr_of_mut!((*shm).precision), s.precision);
        write_volatile(addr_of_mut!((*shm).nsamples), 3);
        fence(Ordering::SeqCst);
        let c = read_volatile(addr_of_mut!((*shm).count));
        write_volatile(addr_of_mut!((*shm).count), c.wrapping_add(1));
        write_volatile(addr_of_mut!((*shm).valid), 1);
    }
}

/// Errors of the SHM exporter.
#[derive(Debug, thiserror::Error)]
pub enum NtpShmError {
    /// The segment could not be created or attached.
    #[error("NTP SHM unit {unit} (key {key:#x}): {what}: {source}")]
    Shm {
        /// Unit.
        unit: u32,
        /// Key.
        key: i32,
        /// The call.
        what: &'static str,
        /// Cause.
        source: std::io::Error,
    },
    /// A segment of the unit exists and is not one navsync may write.
    #[error(
        "NTP SHM unit {unit} (key {key:#x}): the existing segment {problem}: refused; remove it with `ipcrm -M {key:#x}` once nothing uses it (chronyd, ntpd, gpsd), or use another --unit"
    )]
    Segment {
        /// Unit.
        unit: u32,
        /// Key.
        key: i32,
        /// What is wrong with it.
        problem: String,
    },
    /// The socket for chrony's SOCK refclock could not be created.
    #[error("socket for chrony's refclock {path}: {source}")]
    Sock {
        /// The refclock's path.
        path: std::path::PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// IPC failure.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// A health counter could not be registered.
    #[error(transparent)]
    Health(#[from] navsync_shared::health_reporter::HealthError),
}

/// What an existing segment is (`shmctl(IPC_STAT)`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SegmentInfo {
    /// Bytes.
    pub size: usize,
    /// Owner.
    pub uid: u32,
    /// Permission bits.
    pub mode: u32,
}

/// The permission bits navsync gives unit `unit`'s segment: units 0 and 1 root-only (0600) as
/// in ntpd and gpsd, the others 0666 (the convention for unprivileged time sources).
pub fn unit_mode(unit: u32) -> u32 {
    if unit < 2 { 0o600 } else { 0o666 }
}

/// Whether an existing segment of `unit` may be used by a process of user `me`: large enough
/// for the NTP SHM layout, owned by `me` or root, and no more open than the unit's mode (a
/// root-only unit that others may write would let them set the time).
pub fn check_segment(unit: u32, seg: &SegmentInfo, me: u32) -> Result<(), String> {
    let need = size_of::<ShmTime>();
    if seg.size < need {
        return Err(format!(
            "has {} bytes, fewer than the {need} of an NTP SHM segment (another program's?)",
            seg.size
        ));
    }
    if seg.uid != me && seg.uid != 0 {
        return Err(format!(
            "belongs to uid {}, not to this user (uid {me}) or root: its owner could set the time chrony/ntpd takes",
            seg.uid
        ));
    }
    let extra = seg.mode & 0o777 & !unit_mode(unit);
    if extra != 0 {
        return Err(format!(
            "has mode {:04o}, more open than unit {unit}'s {:04o}: others could write it",
            seg.mode & 0o777,
            unit_mode(unit)
        ));
    }
    Ok(())
}

/// An attached SHM segment.
pub struct ShmSegment {
    ptr: *mut ShmTime,
}

impl ShmSegment {
    /// The key of `unit`.
    pub fn key(unit: u32) -> i32 {
        NTP_SHM_BASE_KEY.wrapping_add(unit as i32)
    }

    /// Creates and attaches the segment of `unit` ([`unit_mode`]); an existing one is first
    /// checked ([`check_segment`]: size, owner, mode) and refused with what to do.
    pub fn open(unit: u32) -> Result<Self, NtpShmError> {
        let key = Self::key(unit);
        let perm = unit_mode(unit) as libc::c_int;
        let fail = |what, source| NtpShmError::Shm {
            unit,
            key,
            what,
            source,
        };
        // SAFETY: System V shared memory calls with checked results; `ds` is a plain struct.
        unsafe {
            let mut id = libc::shmget(key, size_of::<ShmTime>(), libc::IPC_CREAT | libc::IPC_EXCL | perm);
            if id < 0 && std::io::Error::last_os_error().raw_os_error() == Some(libc::EEXIST) {
                // There already: look at it before using it.
                id = libc::shmget(key, 0, 0);
                if id < 0 {
                    return Err(fail("shmget", std::io::Error::last_os_error()));
                }
                let mut ds: libc::shmid_ds = core::mem::zeroed();
                if libc::shmctl(id, libc::IPC_STAT, &mut ds) != 0 {
                    return Err(fail("shmctl(IPC_STAT)", std::io::Error::last_os_error()));
                }
                let seg = SegmentInfo {
                    size: ds.shm_segsz,
                    uid: ds.shm_perm.uid,
                    mode: u32::from(ds.shm_perm.mode),
                };
                check_segment(unit, &seg, libc::geteuid()).map_err(|problem| NtpShmError::Segment {
                    unit,
                    key,
                    problem,
                })?;
            }
            if id < 0 {
                return Err(fail("shmget", std::io::Error::last_os_error()));
            }
            let p = libc::shmat(id, std::ptr::null(), 0);
            if p as isize == -1 {
                return Err(fail("shmat", std::io::Error::last_os_error()));
            }
            Ok(Self { ptr: p.cast() })
        }
    }

    /// Writes one sample.
    pub fn write(&mut self, s: &ShmSample) {
        // SAFETY: `ptr` is our attached segment of at least size_of::<ShmTime>().
        unsafe { write_sample(self.ptr, s) }
    }
}

impl Drop for ShmSegment {
    fn drop(&mut self) {
        // The segment stays (as with gpsd) so a running chronyd keeps its attachment valid.
        // SAFETY: detaching our own attachment.
        unsafe { libc::shmdt(self.ptr.cast()) };
    }
}

/// (monotonic, realtime) of one instant: of three back-to-back (mono, real, mono) readings
/// the one with the tightest bracket; the monotonic time is the bracket's middle.
pub fn paired_clocks_ns() -> (i64, i64) {
    let mut best = (i64::MAX, 0i64, 0i64);
    for _ in 0..3 {
        let a = monotonic_now_ns();
        let r = navsync_shared::time::realtime_now_ns();
        let b = monotonic_now_ns();
        if b - a < best.0 {
            best = (b - a, a + (b - a) / 2, r);
        }
    }
    (best.1, best.2)
}

/// `navsync ntpshm`: GNSS time (`navsync/time/state`) to chrony/ntpd as an NTP shared-memory
/// refclock.
#[derive(Debug, Clone, clap::Args)]
pub struct NtpShmArgs {
    /// SHM unit: segment key 0x4e545030 + unit (chrony: `refclock SHM <unit>`)
    /// [default: [outputs.ntpshm].unit, else 0].
    #[arg(long)]
    pub unit: Option<u32>,
    /// Also send each sample to chrony's socket refclock at PATH (chrony: `refclock SOCK PATH`;
    /// chronyd creates the socket) [default: [outputs.ntpshm].sock, else none].
    #[arg(long, value_name = "PATH")]
    pub sock: Option<std::path::PathBuf>,
    /// Withhold a sample whose time mapping 1σ exceeds this many µs (chrony then falls back on
    /// its other sources and its own holdover) [default: [outputs.ntpshm].max_std_us, else 1000].
    #[arg(long, value_name = "US", value_parser = positive_us)]
    pub max_std_us: Option<f64>,
}

/// A bound in µs: a finite number above 0 (`--max-std-us` of the exports).
pub(crate) fn positive_us(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("`{s}`: expected a number of µs above 0")),
    }
}

/// What `navsync ntpshm` exports, and where.
#[derive(Debug, Clone, PartialEq)]
pub struct Export {
    /// SHM unit.
    pub unit: u32,
    /// chrony's SOCK refclock socket, if any.
    pub sock: Option<std::path::PathBuf>,
    /// Bound on the mapping's 1σ, ns.
    pub max_std_ns: f64,
}

/// Runs `navsync ntpshm` with the unit: flag, else `[outputs.ntpshm].unit`, else 0.
pub fn main(opts: NtpShmArgs, cfg: &crate::config::Loaded) -> anyhow::Result<()> {
    use anyhow::Context;
    let unit = opts
        .unit
        .or(cfg.config.outputs.ntpshm.as_ref().map(|n| n.unit))
        .unwrap_or(0);
    let file = cfg.config.outputs.ntpshm.as_ref();
    let sock = opts.sock.or_else(|| file.and_then(|n| n.sock.clone()));
    // The file's value was checked when the file was read (`Loaded::check`), a flag's by clap.
    let max_std_us = opts
        .max_std_us
        .or(file.and_then(|n| n.max_std_us))
        .unwrap_or(DEFAULT_MAX_STD_US);
    run(&Export {
        unit,
        sock,
        max_std_ns: max_std_us * 1e3,
    })
    .context("ntpshm")
}

/// Runs the exporter until SIGINT/SIGTERM.
pub fn run(export: &Export) -> Result<(), NtpShmError> {
    let unit = export.unit;
    let process = format!("ntpshm-{unit}");
    let _span = info_span!("ntpshm", unit).entered();
    let node = IpcNode::new(&process)?;
    let time = node.subscriber::<TimeState>(services::TIME_STATE)?;
    let mut health = HealthReporter::new(&node, &process)?;
    let c_written = health.counter("samples_written")?;
    let c_skipped = health.counter("seconds_not_exported")?;
    let c_holdover = health.counter("holdover_samples")?;
    let c_withheld = health.counter("withheld_over_bound")?;
    let c_sock_sent = health.counter("sock_samples_sent")?;
    let c_sock_failed = health.counter("sock_send_failed")?;
    let mut shm = ShmSegment::open(unit)?;
    // Unbound: each datagram is addressed to chrony's socket, which may come and go.
    let sock = match &export.sock {
        Some(path) => Some((
            std::os::unix::net::UnixDatagram::unbound().map_err(|source| NtpShmError::Sock {
                path: path.clone(),
                source,
            })?,
            path,
        )),
        None => None,
    };
    let mut sock_failing = false;
    info!(
        key = format!("{:#x}", ShmSegment::key(unit)),
        sock = ?export.sock,
        max_std_us = export.max_std_ns * 1e-3,
        "NTP SHM exporter running"
    );
    let mut latest: Option<TimeState> = None;
    let mut next_write = monotonic_now_ns();
    let mut last_status = TimeStatus::None;
    let mut ipc_errors = 0u32;
    navsync_shared::sd_notify::ready(&format!("NTP SHM unit {}", unit));
    loop {
        navsync_shared::sd_notify::watchdog();
        let now = monotonic_now_ns();
        let wait = Duration::from_nanos((next_write - now).clamp(1_000_000, NS_PER_S) as u64);
        match time.wait_next(wait) {
            Ok(Some(s)) => {
                latest = Some(s);
                while let Some(s) = time.receive()? {
                    latest = Some(s);
                }
                ipc_errors = 0;
            }
            Ok(None) => {}
            // A signal interrupts the wait: SIGTERM/SIGINT end the loop below; others are retried.
            Err(e) => {
                ipc_errors += 1;
                if ipc_errors > MAX_IPC_ERRORS && !node.termination_requested() {
                    return Err(e.into());
                }
            }
        }
        if node.termination_requested() {
            break;
        }
        let now = monotonic_now_ns();
        if now < next_write {
            continue;
        }
        next_write = now + NS_PER_S;
        let (h, real) = paired_clocks_ns();
        match latest
            .as_ref()
            .and_then(|s| sample_for(s, h, real, export.max_std_ns).map(|x| (x, s.status())))
        {
            Some((sample, status)) => {
                shm.write(&sample);
                health.add(c_written, 1);
                if let Some((socket, path)) = &sock {
                    match socket.send_to(&SockSample::of(&sample).bytes(), path) {
                        Ok(_) => {
                            health.add(c_sock_sent, 1);
                            sock_failing = false;
                        }
                        Err(e) => {
                            health.add(c_sock_failed, 1);
                            if !sock_failing {
                                warn!(
                                    "sending to chrony's socket {}: {e} (is chronyd running with `refclock SOCK {}`?)",
                                    path.display(),
                                    path.display()
                                );
                                sock_failing = true;
                            }
                        }
                    }
                }
                if status == TimeStatus::Holdover {
                    health.add(c_holdover, 1);
                }
                if status != last_status {
                    info!(status = status.name(), "exporting");
                    last_status = status;
                }
            }
            None => {
                health.add(c_skipped, 1);
                if latest
                    .as_ref()
                    .is_some_and(|s| sample_for(s, h, real, f64::INFINITY).is_some())
                {
                    health.add(c_withheld, 1);
                }
            }
        }
        if let Err(e) = health.maybe_publish(now) {
            warn!("publishing health: {e}");
        }
    }
    navsync_shared::sd_notify::stopping();
    let _ = health.publish_final();
    info!("NTP SHM exporter stopped");
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn an_existing_segment_must_fit_belong_to_us_and_be_no_more_open_than_its_unit() {
        let size = size_of::<ShmTime>();
        let ok = |unit, seg: SegmentInfo| check_segment(unit, &seg, 1000);
        assert_eq!(
            ok(
                0,
                SegmentInfo {
                    size,
                    uid: 1000,
                    mode: 0o600
                }
            ),
            Ok(())
        );
        assert_eq!(
            ok(
                2,
                SegmentInfo {
                    size,
                    uid: 0,
                    mode: 0o666
                }
            ),
            Ok(())
        );
        assert_eq!(
            ok(
                3,
                SegmentInfo {
                    size: size + 16,
                    uid: 1000,
                    mode: 0o644
                }
            ),
            Ok(())
        );
        let e = ok(
            4,
            SegmentInfo {
                size: 16,
                uid: 1000,
                mode: 0o666,
            },
        )
        .unwrap_err();
        assert!(e.contains("16 bytes"), "{e}");
        let e = ok(
            4,
            SegmentInfo {
                size,
                uid: 65534,
                mode: 0o666,
            },
        )
        .unwrap_err();
        assert!(e.contains("uid 65534"), "{e}");
        let e = ok(
            0,
            SegmentInfo {
                size,
                uid: 1000,
                mode: 0o666,
            },
        )
        .unwrap_err();
        assert!(e.contains("0666"), "{e}");
    }

    use super::*;

    fn locked(ref_host_ns: i64, ref_utc_ns: i64) -> TimeState {
        let mut s = TimeState::unknown();
        s.status = TimeStatus::Locked as u8;
        s.ref_host_ns = ref_host_ns;
        s.ref_utc_ns = ref_utc_ns;
        s.computed_host_ns = ref_host_ns;
        s.rate_error = 1e-6;
        s.offset_std_ns = 500.0;
        s.rate_std = 1e-9;
        s.offset_rate_cov_ns = 0.0;
        s.q_offset_ns2_per_s = 0.0;
        s.q_rate_per_s = 0.0;
        s
    }

    #[test]
    fn sample_pairs_gnss_time_and_system_time_of_one_instant() {
        let s = locked(5_000_000_000, 1_790_000_000_000_000_000);
        let x = sample_for(&s, 5_500_000_000, 1_790_000_000_250_000_123, 1e6).expect("sample");
        assert_eq!(x.clock_ns, 1_790_000_000_000_000_000 + 500_000_000 + 500);
        assert_eq!(x.receive_ns, 1_790_000_000_250_000_123);
        assert_eq!(x.precision, -20, "σ ≈ 0.5 µs → 2^-20 s");
        let mut acquiring = s;
        acquiring.status = TimeStatus::Acquiring as u8;
        assert_eq!(sample_for(&acquiring, 5_500_000_000, 0, 1e6), None);
        assert_eq!(
            sample_for(&s, 5_000_000_000 + STALE_AFTER_NS + 1, 0, 1e6),
            None,
            "stale"
        );
        let mut holdover = s;
        holdover.status = TimeStatus::Holdover as u8;
        assert!(sample_for(&holdover, 6_000_000_000, 0, 1e6).is_some());
        // The bound: σ ≈ 0.5 µs passes 1 µs, not 0.4 µs.
        assert!(sample_for(&s, 5_500_000_000, 0, 1_000.0).is_some());
        assert_eq!(sample_for(&s, 5_500_000_000, 0, 400.0), None, "over the bound");
    }

    #[test]
    fn sock_sample_is_chronys_struct() {
        let x = ShmSample {
            clock_ns: 1_700_000_001_250_000_500,
            receive_ns: 1_700_000_001_125_000_999,
            precision: -20,
        };
        let d = SockSample::of(&x);
        assert_eq!((d.tv_sec, d.tv_usec), (1_700_000_001, 125_000));
        assert!((d.offset - 0.125_000_5).abs() < 1e-12, "{}", d.offset);
        assert_eq!((d.pulse, d.leap, d.magic), (0, 0, 0x534f_434b));
        if size_of::<libc::time_t>() == 8 {
            // chrony's struct sock_sample on LP64: timeval 16, double 8, four ints.
            assert_eq!(size_of::<SockSample>(), 40);
            let b = d.bytes();
            assert_eq!(&b[36..40], &SOCK_MAGIC.to_ne_bytes());
            assert_eq!(f64::from_ne_bytes(b[16..24].try_into().unwrap()), d.offset);
        }
    }

    #[test]
    fn protocol_fields_are_consistent() {
        let mut t = ShmTime::default();
        let s = ShmSample {
            clock_ns: 1_700_000_001_123_456_789,
            receive_ns: -1,
            precision: -19,
        };
        // SAFETY: a local ShmTime.
        unsafe { write_sample(&mut t, &s) };
        assert_eq!((t.mode, t.count, t.valid), (1, 2, 1));
        assert_eq!(t.clock_time_stamp_sec, 1_700_000_001);
        assert_eq!(
            (t.clock_time_stamp_usec, t.clock_time_stamp_nsec),
            (123_456, 123_456_789)
        );
        assert_eq!(t.receive_time_stamp_sec, -1);
        assert_eq!(t.receive_time_stamp_nsec, 999_999_999);
        assert_eq!(t.precision, -19);
    }

    #[test]
    fn layout_matches_ntpd_on_lp64() {
        if size_of::<libc::time_t>() == 8 {
            assert_eq!(size_of::<ShmTime>(), 96);
            assert_eq!(std::mem::offset_of!(ShmTime, receive_time_stamp_sec), 24);
            assert_eq!(std::mem::offset_of!(ShmTime, valid), 48);
            assert_eq!(std::mem::offset_of!(ShmTime, clock_time_stamp_nsec), 52);
        }
    }
}
