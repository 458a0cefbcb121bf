//! `kernel:/dev/ppsN`: the Linux PPS API (RFC 2783, "Pulse-Per-Second API for UNIX-like
//! Operating Systems, Version 1.0"; Linux `include/uapi/linux/pps.h`).
//!
//! The kernel time-stamps each edge in the interrupt handler (`pps_get_ts`: `CLOCK_REALTIME`,
//! `struct pps_ktime`), counts assert and clear events, and `PPS_FETCH` returns the latest of
//! both, waiting up to a timeout for the next event (RFC 2783 §3.4.3 `time_pps_fetch`). A new
//! assert event is one whose `assert_sequence` changed.
//!
//! Time base. The kernel stamps are `CLOCK_REALTIME`; navsync's host time is
//! `CLOCK_MONOTONIC`. Right after each fetch the offset realtime − monotonic is measured
//! (three back-to-back readings, the tightest bracket kept) and subtracted. The edge is at
//! most a few ms old then, so a slewing system clock (≤ 500 ppm) adds < 1 µs; a step of the
//! system clock between the edge and the fetch shows as an early/late edge and is rejected.
//!
//! ioctl numbers. `linux/pps.h` declares them with the *pointer* type
//! (`_IOWR('p', 0xa4, struct pps_fdata *)`), so the size encoded in the number is
//! `sizeof(void *)`, not the size of the structure; [`PPS_FETCH`] etc. reproduce that quirk.
//! The layouts and numbers are checked against the system header by
//! `drivers/tests/conformance/pps_kernel_abi.rs`, which compiles a small C program with `cc`.

use std::fs::{File, OpenOptions};
use std::os::fd::AsRawFd;
use std::path::{Path, PathBuf};
use std::time::Duration;

use navsync_shared::time::NS_PER_S;

use super::PpsError;
use super::edge_validator::RawEdge;

/// `struct pps_ktime`: seconds and nanoseconds of `CLOCK_REALTIME`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PpsKtime {
    /// Seconds since 1970.
    pub sec: i64,
    /// Nanoseconds, 0..1e9.
    pub nsec: i32,
    /// [`PPS_TIME_INVALID`] for "no timeout" in `PPS_FETCH`.
    pub flags: u32,
}

/// `struct pps_kinfo`: event counters and times.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PpsKinfo {
    /// Assert events so far (wraps).
    pub assert_sequence: u32,
    /// Clear events so far (wraps).
    pub clear_sequence: u32,
    /// Time of the latest assert event.
    pub assert_tu: PpsKtime,
    /// Time of the latest clear event.
    pub clear_tu: PpsKtime,
    /// Current mode bits.
    pub current_mode: i32,
}

/// `struct pps_kparams`: API version, mode bits, offsets.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PpsKparams {
    /// [`PPS_API_VERS_1`].
    pub api_version: i32,
    /// Mode bits (`PPS_CAPTUREASSERT`, `PPS_TSFMT_TSPEC`, …).
    pub mode: i32,
    /// Offset added to assert stamps.
    pub assert_off_tu: PpsKtime,
    /// Offset added to clear stamps.
    pub clear_off_tu: PpsKtime,
}

/// `struct pps_fdata`: `PPS_FETCH`'s argument: the result and the timeout.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PpsFdata {
    /// Filled by the kernel.
    pub info: PpsKinfo,
    /// How long to wait for the next event.
    pub timeout: PpsKtime,
}

/// API version 1.
pub const PPS_API_VERS_1: i32 = 1;
/// `timeout` is invalid: wait forever.
pub const PPS_TIME_INVALID: u32 = 1;
/// Capture assert events.
pub const PPS_CAPTUREASSERT: i32 = 0x01;
/// Capture clear events.
pub const PPS_CAPTURECLEAR: i32 = 0x02;
/// `PPS_FETCH` can wait for an event.
pub const PPS_CANWAIT: i32 = 0x100;
/// Time stamps as `struct timespec`.
pub const PPS_TSFMT_TSPEC: i32 = 0x1000;

const IOC_WRITE: u64 = 1;
const IOC_READ: u64 = 2;

/// `_IOC(dir, type, nr, size)` of the generic Linux encoding (x86, ARM, RISC-V; not MIPS,
/// PowerPC, SPARC, whose direction bits differ).
pub const fn ioc(dir: u64, ty: u8, nr: u8, size: usize) -> u64 {
    (dir << 30) | ((size as u64) << 16) | ((ty as u64) << 8) | nr as u64
}

const PTR: usize = size_of::<*mut u8>();
/// `_IOR('p', 0xa1, struct pps_kparams *)`.
pub const PPS_GETPARAMS: u64 = ioc(IOC_READ, b'p', 0xa1, PTR);
/// `_IOW('p', 0xa2, struct pps_kparams *)`.
pub const PPS_SETPARAMS: u64 = ioc(IOC_WRITE, b'p', 0xa2, PTR);
/// `_IOR('p', 0xa3, int *)`.
pub const PPS_GETCAP: u64 = ioc(IOC_READ, b'p', 0xa3, PTR);
/// `_IOWR('p', 0xa4, struct pps_fdata *)`.
pub const PPS_FETCH: u64 = ioc(IOC_READ | IOC_WRITE, b'p', 0xa4, PTR);

/// A `pps_ktime` as ns since 1970, `None` when out of range.
pub fn ktime_to_ns(t: &PpsKtime) -> Option<i64> {
    if !(0..1_000_000_000).contains(&t.nsec) {
        return None;
    }
    t.sec.checked_mul(NS_PER_S)?.checked_add(t.nsec as i64)
}

/// A timeout as a `pps_ktime`.
pub fn ktime_of(d: Duration) -> PpsKtime {
    PpsKtime {
        sec: d.as_secs().min(i64::MAX as u64) as i64,
        nsec: d.subsec_nanos() as i32,
        flags: 0,
    }
}

/// Turns fetched event counters into edges: tracks `assert_sequence` (32-bit, wrapping) and
/// extends it to 64 bits. Pure.
#[derive(Debug, Clone, Default)]
pub struct FetchDecoder {
    last_assert: Option<u32>,
    assert_count: u64,
    /// Assert events the kernel counted but this process never saw (more than one event
    /// between two fetches).
    pub skipped: u64,
    /// Fetches whose assert time was out of range.
    pub bad_times: u64,
}

impl FetchDecoder {
    /// The new assert edge in `info`, if any, converted to host time with
    /// `realtime_minus_monotonic_ns` (measured right after the fetch).
    pub fn decode(&mut self, info: &PpsKinfo, realtime_minus_monotonic_ns: i64) -> Option<RawEdge> {
        let seq = info.assert_sequence;
        let advanced = match self.last_assert {
            None => seq != 0,
            Some(prev) => seq != prev,
        };
        if !advanced {
            return None;
        }
        let delta = match self.last_assert {
            Some(prev) => seq.wrapping_sub(prev) as u64,
            None => 1,
        };
        self.last_assert = Some(seq);
        self.skipped += delta.saturating_sub(1);
        self.assert_count = self.assert_count.saturating_add(delta);
        let Some(real_ns) = ktime_to_ns(&info.assert_tu) else {
            self.bad_times += 1;
            return None;
        };
        Some(RawEdge {
            host_ns: real_ns.saturating_sub(realtime_minus_monotonic_ns),
            source_seq: self.assert_count,
            assert: true,
        })
    }
}

fn clock_ns(clock: libc::clockid_t) -> i64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: valid, writable timespec.
    unsafe { libc::clock_gettime(clock, &mut ts) };
    ts.tv_sec * NS_PER_S + ts.tv_nsec
}

/// `CLOCK_REALTIME − CLOCK_MONOTONIC`, ns: of three (mono, real, mono) readings the one with
/// the tightest bracket, real minus the bracket's midpoint.
pub fn realtime_minus_monotonic_ns() -> i64 {
    let mut best = (i64::MAX, 0i64);
    for _ in 0..3 {
        let a = clock_ns(libc::CLOCK_MONOTONIC);
        let r = clock_ns(libc::CLOCK_REALTIME);
        let b = clock_ns(libc::CLOCK_MONOTONIC);
        if b - a < best.0 {
            best = (b - a, r - (a + (b - a) / 2));
        }
    }
    best.1
}

/// An open kernel PPS device.
pub struct KernelPps {
    file: File,
    path: PathBuf,
    decoder: FetchDecoder,
}

fn ioctl<T>(file: &File, path: &Path, what: &'static str, req: u64, arg: *mut T) -> Result<(), PpsError> {
    // SAFETY: `arg` points to a live value of the type the request expects (checked against
    // the kernel header by the ABI test); the kernel only reads/writes that object.
    let rc = unsafe { libc::ioctl(file.as_raw_fd(), req as _, arg) };
    if rc < 0 {
        return Err(PpsError::Ioctl {
            what,
            path: path.display().to_string(),
            source: std::io::Error::last_os_error(),
        });
    }
    Ok(())
}

impl KernelPps {
    /// Opens `/dev/ppsN`, checks that it can capture and wait for assert events, and enables
    /// assert capture (RFC 2783 `time_pps_create`, `time_pps_getcap`, `time_pps_setparams`).
    pub fn open(path: &Path) -> Result<Self, PpsError> {
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
            .or_else(|_| OpenOptions::new().read(true).open(path))
            .map_err(|source| PpsError::Open {
                path: path.display().to_string(),
                source,
            })?;
        let mut caps: i32 = 0;
        ioctl(&file, path, "PPS_GETCAP", PPS_GETCAP, &mut caps)?;
        if caps & PPS_CAPTUREASSERT == 0 || caps & PPS_CANWAIT == 0 {
            return Err(PpsError::Unsupported {
                path: path.display().to_string(),
                what: format!("capabilities {caps:#x} lack assert capture or waiting"),
            });
        }
        let mut params = PpsKparams::default();
        ioctl(&file, path, "PPS_GETPARAMS", PPS_GETPARAMS, &mut params)?;
        if params.mode & PPS_CAPTUREASSERT == 0 {
            params.api_version = PPS_API_VERS_1;
            params.mode |= PPS_CAPTUREASSERT | PPS_TSFMT_TSPEC;
            ioctl(&file, path, "PPS_SETPARAMS", PPS_SETPARAMS, &mut params)?;
        }
        Ok(Self {
            file,
            path: path.to_path_buf(),
            decoder: FetchDecoder::default(),
        })
    }

    /// Waits up to `timeout` for the next event; the new assert edge, if one came.
    pub fn next_edge(&mut self, timeout: Duration) -> Result<Option<RawEdge>, PpsError> {
        let mut fdata = PpsFdata {
            timeout: ktime_of(timeout),
            ..Default::default()
        };
        match ioctl(&self.file, &self.path, "PPS_FETCH", PPS_FETCH, &mut fdata) {
            Ok(()) => {}
            Err(PpsError::Ioctl { source, .. })
                if matches!(source.raw_os_error(), Some(libc::ETIMEDOUT) | Some(libc::EINTR)) =>
            {
                return Ok(None);
            }
            Err(e) => return Err(e),
        }
        let offset = realtime_minus_monotonic_ns();
        Ok(self.decoder.decode(&fdata.info, offset))
    }

    /// The fetch decoder's counters.
    pub fn decoder(&self) -> &FetchDecoder {
        &self.decoder
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layouts_follow_the_c_rules() {
        assert_eq!(size_of::<PpsKtime>(), 16);
        assert_eq!(size_of::<PpsKinfo>(), 48);
        assert_eq!(size_of::<PpsKparams>(), 40);
        assert_eq!(size_of::<PpsFdata>(), 64);
        assert_eq!(PPS_FETCH, 0xc008_70a4);
    }

    #[test]
    fn decodes_new_assert_events_across_the_counter_wrap() {
        let mut d = FetchDecoder::default();
        let info = |seq: u32, sec: i64| PpsKinfo {
            assert_sequence: seq,
            assert_tu: PpsKtime {
                sec,
                nsec: 250,
                flags: 0,
            },
            ..Default::default()
        };
        assert_eq!(d.decode(&info(0, 0), 0), None, "no event yet");
        let e = d.decode(&info(u32::MAX, 1_700_000_000), 1_000).expect("edge");
        assert_eq!(e.host_ns, 1_700_000_000 * NS_PER_S + 250 - 1_000);
        assert_eq!(e.source_seq, 1);
        assert_eq!(d.decode(&info(u32::MAX, 1_700_000_000), 1_000), None, "same event");
        let e = d.decode(&info(1, 1_700_000_002), 0).expect("edge after the wrap");
        assert_eq!(e.source_seq, 3);
        assert_eq!(d.skipped, 1);
        let mut bad = info(2, 5);
        bad.assert_tu.nsec = -1;
        assert_eq!(d.decode(&bad, 0), None);
        assert_eq!(d.bad_times, 1);
    }

    #[test]
    fn offset_between_the_clocks_is_stable() {
        let a = realtime_minus_monotonic_ns();
        let b = realtime_minus_monotonic_ns();
        assert!((a - b).abs() < 1_000_000, "{a} {b}");
    }

    #[test]
    fn opening_something_that_is_not_a_pps_device_is_an_error() {
        let err = KernelPps::open(Path::new("/dev/null")).err().expect("error");
        assert!(err.to_string().contains("/dev/null"), "{err}");
        let err = KernelPps::open(Path::new("/nonexistent/pps0")).err().expect("error");
        assert!(matches!(err, PpsError::Open { .. }), "{err}");
    }
}
