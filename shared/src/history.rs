//! The pose at any instant: the estimator's recent navigation states in a ring in shared
//! memory that any process maps read-only and queries without asking the estimator
//! ([`History::state_at_host`], [`History::state_at`]), interpolated between the two states
//! around the instant.
//!
//! ```no_run
//! use navsync_shared::history::History;
//!
//! # fn main() -> Result<(), navsync_shared::history::HistoryError> {
//! let h = History::open()?; // the instance of $NAVSYNC_IPC_PREFIX
//! let host_ns = navsync_shared::time::monotonic_now_ns() - 50_000_000; // 50 ms ago
//! let p = h.state_at_host(host_ns)?;
//! let (q, s) = (p.pose, p.pose.pos_std_ned_m);
//! println!("{:.7} {:.7} {:.2} m ±{:.2} m", q.lat_deg, q.lon_deg, q.height_m, s[0]);
//! # Ok(()) }
//! ```
//!
//! # The file
//!
//! `/dev/shm/<prefix>nav_history` ([`path_for`]; the prefix is `$NAVSYNC_IPC_PREFIX`, so two
//! instances, e.g. two tests, never meet), made by the estimator (the one writer) with mode
//! 0640 (the owner writes, its group reads, others nothing, like the iceoryx2 resources:
//! `docs/guide/service.md`), written in place under a temporary name and renamed into place,
//! so a reader never sees a half-made header; removed when the estimator stops. An estimator
//! killed with SIGKILL leaves it; the next one replaces it (it holds an `flock` on the file
//! while it writes, so a second estimator of the same prefix is refused, not mixed in).
//!
//! Layout, little-endian 64-bit words: a header of [`HEADER_WORDS`] (magic `NAVSHIST`, layout
//! version [`LAYOUT_VERSION`], the `NavState` type name it holds, 32 bytes, capacity, words per
//! record, header words, the write index: records written so far, the writer's pid), then
//! `capacity` records of [`RECORD_WORDS`] words ([`Record`]: word 0 the record's sequence
//! lock, word 1 its index, then the state's fields; `docs/guide/history.md` has the table).
//! Record `i` is in slot `i % capacity`; a record holds an estimator state ([`Source`]):
//! predicted now, fused (the delayed filter's state at that instant) reserved for the next
//! step of issue 39.
//!
//! # Memory ordering (a sequence lock per record)
//!
//! One writer, any number of readers, and neither ever waits for the other: a reader stopped
//! anywhere (SIGSTOP mid-read) cannot hold the writer up, since the writer takes no lock a
//! reader holds, and the writer never blocks a reader (a reader that meets a record being
//! written retries; one the writer lapped is an error, not a wait). Each record's word 0 is
//! its sequence `s`, even when the record is complete. The writer (the pattern of Boehm, "Can
//! seqlocks get along with programming language memory models?", MSPC 2012, fig. 6):
//!
//! 1. `s.store(s0 + 1, Relaxed)` (odd: being written), `fence(Release)`;
//! 2. every payload word `store(_, Relaxed)`;
//! 3. `s.store(s0 + 2, Release)`, then the header's write index `store(i + 1, Release)`.
//!
//! A reader: `s1 = s.load(Acquire)`; every payload word `load(Relaxed)`; `fence(Acquire)`;
//! `s2 = s.load(Relaxed)`; the copy is good when `s1 == s2` and `s1` is even, else it retries.
//! Why: if a payload load saw a store of a later write (step 2), the reader's acquire fence
//! synchronises with the writer's release fence of step 1, so that write's odd store happens
//! before the `s2` load, which therefore sees it or later: `s2 != s1`. If `s1` read the even
//! value of step 3, its acquire makes every payload store of that write visible. The payload
//! words are atomics too (relaxed loads and stores compile to plain moves on x86-64 and
//! AArch64), so a torn read is a retry and never undefined behaviour, and a copy is a few
//! dozen loads into a [`Record`] on the stack: no allocation per write or per query. Word 1
//! (the record's index) tells a good copy of a slot the writer lapped from the one wanted.
//!
//! # Interpolation
//!
//! Between the records `a` and `b` around the instant, `τ = (t − t_a)/h`, `h = t_b − t_a`:
//!
//! - position: cubic Hermite (the basis `h00 = 2τ³ − 3τ² + 1`, `h10 = τ³ − 2τ² + τ`,
//!   `h01 = −2τ³ + 3τ²`, `h11 = τ³ − τ²`; e.g. Kincaid & Cheney, *Numerical Analysis*, §6.3)
//!   on `a`'s and `b`'s positions with their NED velocities as the end slopes, in a local NED
//!   frame at `a` (north = Δφ·(R_M + h_a), east = Δλ·(R_N + h_a)·cos φ_a, down = −Δh, undone
//!   the same way): exact for a constant acceleration (a quadratic is a cubic);
//! - velocity: linear, i.e. a constant acceleration `(v_b − v_a)/h` over the interval (the
//!   derivative of the position polynomial would add the position's noise to the velocity);
//! - attitude: slerp of the quaternions (Shoemake, "Animating rotation with quaternion
//!   curves", SIGGRAPH 1985) along the shorter arc, roll/pitch/yaw from the result;
//! - σ's and UTC: linear; the answer carries the [`Source`] and status of both records.
//!
//! [`History::state_at`] takes a UTC instant (ns since 1970, the GNSS time as UTC), finds the
//! records around it by their UTC, maps it to host time linearly between them, and
//! interpolates as above.

use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering, fence};

use crate::earth;
use crate::reflect::Reflect;
use crate::samples::NavState;

/// `NAVSHIST`, little-endian, word 0 of the header.
pub const MAGIC: u64 = u64::from_le_bytes(*b"NAVSHIST");
/// The layout of the header and the records (word 1 of the header).
pub const LAYOUT_VERSION: u64 = 1;
/// Words of the header.
pub const HEADER_WORDS: usize = 16;
/// Words of one record (256 bytes).
pub const RECORD_WORDS: usize = 32;
/// Records per second of history the estimator keeps: its reference IMU at up to 1 kHz.
pub const RECORDS_PER_S: f64 = 1000.0;

/// Header word indices.
mod hw {
    pub const MAGIC: usize = 0;
    pub const VERSION: usize = 1;
    /// Words 2..6: the NavState type name, 32 bytes, NUL-padded.
    pub const TYPE_NAME: usize = 2;
    pub const CAPACITY: usize = 6;
    pub const RECORD_WORDS: usize = 7;
    pub const HEADER_WORDS: usize = 8;
    pub const WRITE_INDEX: usize = 9;
    pub const WRITER_PID: usize = 10;
}

/// Record word indices.
mod rw {
    pub const SEQ: usize = 0;
    pub const INDEX: usize = 1;
    pub const HOST_NS: usize = 2;
    pub const UTC_NS: usize = 3;
    pub const LAT: usize = 4;
    pub const LON: usize = 5;
    pub const HEIGHT: usize = 6;
    pub const VEL: usize = 7;
    pub const Q: usize = 10;
    pub const GYRO: usize = 14;
    pub const POS_STD: usize = 17;
    pub const VEL_STD: usize = 20;
    pub const ATT_STD: usize = 23;
    /// Bytes: source, status, time status, integrity.
    pub const FLAGS: usize = 26;
    pub const RPY: usize = 27;
}

/// Where a record's state comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Source {
    /// The real-time predictor's state, as published on `navsync/nav/state`.
    Predicted = 1,
    /// The delayed filter's state once it fused that instant (reserved: not written yet).
    Fused = 2,
}

impl Source {
    fn from_u8(v: u8) -> Option<Self> {
        match v {
            1 => Some(Self::Predicted),
            2 => Some(Self::Fused),
            _ => None,
        }
    }
}

/// Where the body is and how it moves at one instant, with the σ's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Latitude, degrees.
    pub lat_deg: f64,
    /// Longitude, degrees.
    pub lon_deg: f64,
    /// Height above the ellipsoid, m.
    pub height_m: f64,
    /// NED velocity, m/s.
    pub vel_ned_mps: [f64; 3],
    /// Attitude quaternion body→NED, [w, x, y, z].
    pub q_nb: [f64; 4],
    /// Roll, pitch, yaw (ZYX) of `q_nb`, rad.
    pub rpy_rad: [f64; 3],
    /// 1-σ position, NED, m.
    pub pos_std_ned_m: [f64; 3],
    /// 1-σ velocity, NED, m/s.
    pub vel_std_ned_mps: [f64; 3],
    /// 1-σ attitude, rad.
    pub att_std_rad: [f64; 3],
}

/// One state of the history (a copy out of shared memory).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Record {
    /// The record's index (records written before it).
    pub index: u64,
    /// Host time (`CLOCK_MONOTONIC` ns) of the state.
    pub host_ns: i64,
    /// UTC, ns since 1970 (`i64::MIN` while time is not known).
    pub utc_ns: i64,
    /// Position, velocity, attitude and their σ.
    pub pose: Pose,
    /// Angular rate, body FRD, rad/s.
    pub gyro_body_rps: [f64; 3],
    /// Where the state comes from (`None`: an unknown source byte).
    pub source: Option<Source>,
    /// The state's `NavStatus` as `u8`.
    pub status: u8,
    /// The state's `TimeStatus` as `u8`.
    pub time_status: u8,
    /// The state's integrity flags.
    pub integrity: u8,
}

impl Record {
    /// The record of `s` from `source`.
    pub fn of(s: &NavState, source: Source) -> Self {
        Self {
            index: 0,
            host_ns: s.host_ns,
            utc_ns: s.utc_ns,
            pose: Pose {
                lat_deg: s.lat_deg,
                lon_deg: s.lon_deg,
                height_m: s.height_m,
                vel_ned_mps: s.vel_ned_mps,
                q_nb: s.q_nb,
                rpy_rad: s.rpy_rad,
                pos_std_ned_m: s.pos_std_ned_m,
                vel_std_ned_mps: s.vel_std_ned_mps,
                att_std_rad: s.att_std_rad,
            },
            gyro_body_rps: s.gyro_body_rps,
            source: Some(source),
            status: s.status,
            time_status: s.time_status,
            integrity: s.integrity,
        }
    }

    fn encode(&self, w: &mut [u64; RECORD_WORDS]) {
        let f = |x: f64| x.to_bits();
        w[rw::INDEX] = self.index;
        w[rw::HOST_NS] = self.host_ns as u64;
        w[rw::UTC_NS] = self.utc_ns as u64;
        w[rw::LAT] = f(self.pose.lat_deg);
        w[rw::LON] = f(self.pose.lon_deg);
        w[rw::HEIGHT] = f(self.pose.height_m);
        let mut put = |at: usize, v: &[f64]| {
            for (k, x) in v.iter().enumerate() {
                w[at + k] = x.to_bits();
            }
        };
        put(rw::VEL, &self.pose.vel_ned_mps);
        put(rw::Q, &self.pose.q_nb);
        put(rw::GYRO, &self.gyro_body_rps);
        put(rw::POS_STD, &self.pose.pos_std_ned_m);
        put(rw::VEL_STD, &self.pose.vel_std_ned_mps);
        put(rw::ATT_STD, &self.pose.att_std_rad);
        put(rw::RPY, &self.pose.rpy_rad);
        w[rw::FLAGS] = u64::from_le_bytes([
            self.source.map_or(0, |s| s as u8),
            self.status,
            self.time_status,
            self.integrity,
            0,
            0,
            0,
            0,
        ]);
    }

    fn decode(w: &[u64; RECORD_WORDS]) -> Self {
        let f = |i: usize| f64::from_bits(w[i]);
        let v3 = |i: usize| [f(i), f(i + 1), f(i + 2)];
        let flags = w[rw::FLAGS].to_le_bytes();
        Self {
            index: w[rw::INDEX],
            host_ns: w[rw::HOST_NS] as i64,
            utc_ns: w[rw::UTC_NS] as i64,
            pose: Pose {
                lat_deg: f(rw::LAT),
                lon_deg: f(rw::LON),
                height_m: f(rw::HEIGHT),
                vel_ned_mps: v3(rw::VEL),
                q_nb: [f(rw::Q), f(rw::Q + 1), f(rw::Q + 2), f(rw::Q + 3)],
                rpy_rad: v3(rw::RPY),
                pos_std_ned_m: v3(rw::POS_STD),
                vel_std_ned_mps: v3(rw::VEL_STD),
                att_std_rad: v3(rw::ATT_STD),
            },
            gyro_body_rps: v3(rw::GYRO),
            source: Source::from_u8(flags[0]),
            status: flags[1],
            time_status: flags[2],
            integrity: flags[3],
        }
    }
}

/// Which clock an instant of an error is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Clock {
    /// Host `CLOCK_MONOTONIC`, ns.
    Host,
    /// UTC, ns since 1970.
    Utc,
}

impl std::fmt::Display for Clock {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Host => "host ns",
            Self::Utc => "UTC ns",
        })
    }
}

/// What went wrong opening or querying the history.
#[derive(Debug, thiserror::Error)]
pub enum HistoryError {
    /// No history file: no estimator of this prefix is running (or it is older).
    #[error("{path}: no history (is `navsync estimator` running with this $NAVSYNC_IPC_PREFIX?)")]
    Missing {
        /// The file looked for.
        path: PathBuf,
    },
    /// The operating system refused.
    #[error("{path}: {what}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What was being done.
        what: &'static str,
        /// The cause.
        source: std::io::Error,
    },
    /// The file is not safe to use or not a history of this version.
    #[error("{path}: refused: {why}")]
    Refused {
        /// The file.
        path: PathBuf,
        /// Why.
        why: String,
    },
    /// Fewer than two states written yet.
    #[error("the history holds fewer than two states yet")]
    Empty,
    /// The instant is older than the oldest state kept.
    #[error("{requested} {clock} is older than the history: the oldest state is at {oldest} {clock}")]
    TooOld {
        /// The instant asked for.
        requested: i64,
        /// The oldest state's instant.
        oldest: i64,
        /// Their clock.
        clock: Clock,
    },
    /// The instant is newer than the newest state.
    #[error("{requested} {clock} is newer than the history: the newest state is at {newest} {clock}")]
    TooNew {
        /// The instant asked for.
        requested: i64,
        /// The newest state's instant.
        newest: i64,
        /// Their clock.
        clock: Clock,
    },
    /// The states around a UTC instant have no UTC yet (time not known).
    #[error("the states around {0} UTC ns have no UTC (time not known yet)")]
    TimeUnknown(i64),
    /// The writer kept overwriting the records a query read (a reader far too slow).
    #[error("the writer overwrote the records faster than they could be read")]
    Overrun,
}

/// The history file of resource prefix `prefix`: `/dev/shm/<prefix>nav_history`.
pub fn path_for(prefix: &str) -> PathBuf {
    PathBuf::from(format!("/dev/shm/{prefix}nav_history"))
}

/// The history's capacity in records for `history_s` seconds: [`RECORDS_PER_S`] each (the
/// reference IMU at up to 1 kHz; a slower IMU's states last longer), 256 bytes a record
/// (10 s: 10 000 records, 2.56 MB).
pub fn capacity_for(history_s: f64) -> u64 {
    (history_s * RECORDS_PER_S).ceil().max(2.0) as u64
}

fn type_name_words() -> [u64; 4] {
    let mut b = [0u8; 32];
    let n = NavState::TYPE_NAME.len().min(32);
    b[..n].copy_from_slice(&NavState::TYPE_NAME.as_bytes()[..n]);
    std::array::from_fn(|i| u64::from_le_bytes(b[i * 8..i * 8 + 8].try_into().unwrap_or([0; 8])))
}

fn io<'a>(path: &'a Path, what: &'static str) -> impl FnOnce(std::io::Error) -> HistoryError + 'a {
    move |source| HistoryError::Io {
        path: path.to_path_buf(),
        what,
        source,
    }
}

/// A shared mapping of a history file.
struct Mapping {
    ptr: *mut libc::c_void,
    len: usize,
}

// SAFETY: the mapping is only accessed through atomics.
unsafe impl Send for Mapping {}
// SAFETY: as above.
unsafe impl Sync for Mapping {}

impl Mapping {
    fn new(fd: &OwnedFd, len: usize, writable: bool, path: &Path) -> Result<Self, HistoryError> {
        let prot = if writable {
            libc::PROT_READ | libc::PROT_WRITE
        } else {
            libc::PROT_READ
        };
        // SAFETY: a fresh shared mapping of `len` bytes of an open file; checked for failure.
        let ptr = unsafe { libc::mmap(std::ptr::null_mut(), len, prot, libc::MAP_SHARED, fd.as_raw_fd(), 0) };
        if ptr == libc::MAP_FAILED {
            return Err(io(path, "mapping")(std::io::Error::last_os_error()));
        }
        Ok(Self { ptr, len })
    }

    fn words(&self) -> &[AtomicU64] {
        // SAFETY: the mapping is page-aligned, `len` bytes long and lives as long as `self`;
        // every access goes through the atomics (the other processes' too).
        unsafe { std::slice::from_raw_parts(self.ptr as *const AtomicU64, self.len / 8) }
    }
}

impl Drop for Mapping {
    fn drop(&mut self) {
        // SAFETY: unmapping what `new` mapped.
        unsafe { libc::munmap(self.ptr, self.len) };
    }
}

fn file_len(capacity: u64) -> usize {
    (HEADER_WORDS + capacity as usize * RECORD_WORDS) * 8
}

fn open_fd(path: &Path, flags: i32, mode: u32) -> Result<OwnedFd, std::io::Error> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(path.as_os_str().as_bytes()).map_err(std::io::Error::other)?;
    // SAFETY: a NUL-terminated path; the descriptor is owned below.
    let fd = unsafe { libc::open(c.as_ptr(), flags | libc::O_CLOEXEC | libc::O_NOFOLLOW, mode) };
    if fd < 0 {
        return Err(std::io::Error::last_os_error());
    }
    // SAFETY: a fresh descriptor of ours.
    Ok(unsafe { OwnedFd::from_raw_fd(fd) })
}

/// Whether `gid` is this process's effective group or one of its supplementary groups.
fn in_my_groups(gid: u32) -> bool {
    // SAFETY: getegid has no preconditions.
    if unsafe { libc::getegid() } == gid {
        return true;
    }
    let mut groups = vec![0 as libc::gid_t; 256];
    // SAFETY: the buffer holds `groups.len()` entries.
    let n = unsafe { libc::getgroups(groups.len() as libc::c_int, groups.as_mut_ptr()) };
    n > 0 && groups[..n as usize].contains(&gid)
}

fn try_lock(fd: &OwnedFd) -> bool {
    // SAFETY: flock on an open descriptor.
    unsafe { libc::flock(fd.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) == 0 }
}

/// The estimator's side: appends states.
pub struct HistoryWriter {
    map: Mapping,
    path: PathBuf,
    /// Holds the lock while the writer lives.
    _fd: OwnedFd,
    /// The file's device and inode: removed at the end only while it is still this one.
    id: (u64, u64),
    capacity: u64,
    next: u64,
    last_host_ns: i64,
    rejected: u64,
}

impl HistoryWriter {
    /// Makes the history of prefix `prefix` ([`path_for`]) with room for `capacity` records,
    /// replacing one a dead writer left; refused when a live writer holds it.
    pub fn create(prefix: &str, capacity: u64) -> Result<Self, HistoryError> {
        Self::create_at(&path_for(prefix), capacity)
    }

    /// [`create`](Self::create) at `path`.
    pub fn create_at(path: &Path, capacity: u64) -> Result<Self, HistoryError> {
        let capacity = capacity.max(2);
        if let Ok(old) = open_fd(path, libc::O_RDONLY, 0)
            && !try_lock(&old)
        {
            return Err(HistoryError::Refused {
                path: path.to_path_buf(),
                why: "another estimator of this prefix writes it".into(),
            });
        }
        let tmp = PathBuf::from(format!("{}.new{}", path.display(), std::process::id()));
        let _ = std::fs::remove_file(&tmp);
        let fd = open_fd(&tmp, libc::O_RDWR | libc::O_CREAT | libc::O_EXCL, 0o640).map_err(io(&tmp, "creating"))?;
        let len = file_len(capacity);
        let made = (|| {
            // The mode despite the umask (the group reads), and the size.
            // SAFETY: fchmod and ftruncate on our own descriptor.
            let failed = unsafe {
                libc::fchmod(fd.as_raw_fd(), 0o640) != 0 || libc::ftruncate(fd.as_raw_fd(), len as libc::off_t) != 0
            };
            if failed {
                return Err(io(&tmp, "sizing")(std::io::Error::last_os_error()));
            }
            if !try_lock(&fd) {
                return Err(io(&tmp, "locking")(std::io::Error::last_os_error()));
            }
            let map = Mapping::new(&fd, len, true, &tmp)?;
            let w = map.words();
            w[hw::VERSION].store(LAYOUT_VERSION, Ordering::Relaxed);
            for (k, t) in type_name_words().into_iter().enumerate() {
                w[hw::TYPE_NAME + k].store(t, Ordering::Relaxed);
            }
            w[hw::CAPACITY].store(capacity, Ordering::Relaxed);
            w[hw::RECORD_WORDS].store(RECORD_WORDS as u64, Ordering::Relaxed);
            w[hw::HEADER_WORDS].store(HEADER_WORDS as u64, Ordering::Relaxed);
            w[hw::WRITER_PID].store(u64::from(std::process::id()), Ordering::Relaxed);
            w[hw::MAGIC].store(MAGIC, Ordering::Release);
            std::fs::rename(&tmp, path).map_err(io(path, "renaming into place"))?;
            Ok(map)
        })();
        let map = match made {
            Ok(m) => m,
            Err(e) => {
                let _ = std::fs::remove_file(&tmp);
                return Err(e);
            }
        };
        let m = std::fs::metadata(path).map_err(io(path, "inspecting"))?;
        Ok(Self {
            map,
            path: path.to_path_buf(),
            _fd: fd,
            id: (m.dev(), m.ino()),
            capacity,
            next: 0,
            last_host_ns: i64::MIN,
            rejected: 0,
        })
    }

    /// Appends `s` from `source`; false (and counted in [`rejected`](Self::rejected)) when its
    /// host time is not after the last one's (the ring is in time order).
    pub fn append(&mut self, s: &NavState, source: Source) -> bool {
        if s.host_ns <= self.last_host_ns {
            self.rejected += 1;
            return false;
        }
        self.last_host_ns = s.host_ns;
        let mut rec = Record::of(s, source);
        rec.index = self.next;
        let mut words = [0u64; RECORD_WORDS];
        rec.encode(&mut words);
        let w = self.map.words();
        let base = HEADER_WORDS + (self.next % self.capacity) as usize * RECORD_WORDS;
        let r = &w[base..base + RECORD_WORDS];
        let seq = r[rw::SEQ].load(Ordering::Relaxed);
        r[rw::SEQ].store(seq.wrapping_add(1) | 1, Ordering::Relaxed);
        fence(Ordering::Release);
        for (a, v) in r.iter().zip(words.iter()).skip(1) {
            a.store(*v, Ordering::Relaxed);
        }
        r[rw::SEQ].store((seq | 1).wrapping_add(1), Ordering::Release);
        self.next += 1;
        w[hw::WRITE_INDEX].store(self.next, Ordering::Release);
        true
    }

    /// Records written.
    pub fn written(&self) -> u64 {
        self.next
    }

    /// States refused because their host time was not after the previous one's.
    pub fn rejected(&self) -> u64 {
        self.rejected
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Its capacity in records.
    pub fn capacity(&self) -> u64 {
        self.capacity
    }
}

impl Drop for HistoryWriter {
    fn drop(&mut self) {
        // Remove the file only while it is still ours (not replaced by another writer).
        if std::fs::symlink_metadata(&self.path).is_ok_and(|m| (m.dev(), m.ino()) == self.id) {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

/// A reader of the history: maps the file read-only; every query is a few dozen loads from
/// shared memory, no system call and no allocation.
pub struct History {
    map: Mapping,
    capacity: u64,
    path: PathBuf,
    /// The file's device and inode ([`History::is_current`]).
    id: (u64, u64),
}

/// How often a query starts again when the writer lapped what it read, and how often it reads
/// a record the writer is in the middle of before giving up.
const RESTARTS: usize = 8;
const SPINS: usize = 10_000;

impl History {
    /// Opens the history of this process's prefix (`$NAVSYNC_IPC_PREFIX`, else `navsync_`).
    pub fn open() -> Result<Self, HistoryError> {
        Self::open_prefix(&crate::ipc::prefix())
    }

    /// Opens the history of resource prefix `prefix`.
    pub fn open_prefix(prefix: &str) -> Result<Self, HistoryError> {
        Self::open_at(&path_for(prefix))
    }

    /// Opens the history at `path`. The file must be a regular file that neither its group nor
    /// others may write, owned by this user, root, or the owner of iceoryx2's root directory
    /// (the navsync service user), or of one of this process's groups (the estimator's group
    /// reads it: only a member can give a file that group).
    pub fn open_at(path: &Path) -> Result<Self, HistoryError> {
        let refused = |why: String| HistoryError::Refused {
            path: path.to_path_buf(),
            why,
        };
        let fd = open_fd(path, libc::O_RDONLY, 0).map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => HistoryError::Missing {
                path: path.to_path_buf(),
            },
            _ => io(path, "opening")(e),
        })?;
        let file = std::fs::File::from(fd);
        let m = file.metadata().map_err(io(path, "inspecting"))?;
        if !m.file_type().is_file() {
            return Err(refused("not a regular file".into()));
        }
        if m.mode() & 0o022 != 0 {
            return Err(refused(format!("mode {:04o}: others may write it", m.mode() & 0o7777)));
        }
        let me = crate::runtime_dir::effective_uid();
        let service_user = std::fs::metadata(crate::ipc::root_dir()).map(|d| d.uid()).ok();
        if m.uid() != me && m.uid() != 0 && Some(m.uid()) != service_user && !in_my_groups(m.gid()) {
            return Err(refused(format!(
                "it belongs to uid {} and gid {}: neither this user ({me}), root, the owner of iceoryx2's root nor one of this process's groups",
                m.uid(),
                m.gid()
            )));
        }
        let id = (m.dev(), m.ino());
        let len = m.len() as usize;
        if len < HEADER_WORDS * 8 {
            return Err(refused(format!("{len} bytes: shorter than the header")));
        }
        let fd = OwnedFd::from(file);
        let map = Mapping::new(&fd, len, false, path)?;
        let w = map.words();
        let word = |i: usize| w[i].load(Ordering::Acquire);
        if word(hw::MAGIC) != MAGIC {
            return Err(refused("not a navsync history (magic)".into()));
        }
        let name: Vec<u8> = (0..4)
            .flat_map(|k| word(hw::TYPE_NAME + k).to_le_bytes())
            .take_while(|&b| b != 0)
            .collect();
        if word(hw::VERSION) != LAYOUT_VERSION
            || type_name_words() != std::array::from_fn(|k| word(hw::TYPE_NAME + k))
            || word(hw::RECORD_WORDS) != RECORD_WORDS as u64
            || word(hw::HEADER_WORDS) != HEADER_WORDS as u64
        {
            return Err(refused(format!(
                "layout {} of {} ({} words a record), this program reads layout {LAYOUT_VERSION} of {}",
                word(hw::VERSION),
                String::from_utf8_lossy(&name),
                word(hw::RECORD_WORDS),
                NavState::TYPE_NAME
            )));
        }
        let capacity = word(hw::CAPACITY);
        if capacity < 2 || file_len(capacity) != len {
            return Err(refused(format!("capacity {capacity} does not fit its {len} bytes")));
        }
        Ok(Self {
            map,
            capacity,
            path: path.to_path_buf(),
            id,
        })
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Its capacity in records.
    pub fn capacity(&self) -> u64 {
        self.capacity
    }

    /// False once the file at the path is no longer the one mapped (its writer stopped, or a
    /// restarted estimator made a new one): open it again. A `stat(2)`, not for every query.
    pub fn is_current(&self) -> bool {
        std::fs::symlink_metadata(&self.path).is_ok_and(|m| (m.dev(), m.ino()) == self.id)
    }

    /// Records written so far (the write index).
    pub fn write_index(&self) -> u64 {
        self.map.words()[hw::WRITE_INDEX].load(Ordering::Acquire)
    }

    /// The writer's process id.
    pub fn writer_pid(&self) -> u32 {
        self.map.words()[hw::WRITER_PID].load(Ordering::Relaxed) as u32
    }

    /// A consistent copy of record `index`; `None` when the writer lapped it (or it was never
    /// written), `Err(Overrun)` when the writer stayed in the middle of it.
    pub fn record(&self, index: u64) -> Result<Option<Record>, HistoryError> {
        let w = self.map.words();
        let base = HEADER_WORDS + (index % self.capacity) as usize * RECORD_WORDS;
        let r = &w[base..base + RECORD_WORDS];
        let mut words = [0u64; RECORD_WORDS];
        for spin in 0..SPINS {
            let s1 = r[rw::SEQ].load(Ordering::Acquire);
            if s1 & 1 == 0 {
                for (v, a) in words.iter_mut().zip(r.iter()).skip(1) {
                    *v = a.load(Ordering::Relaxed);
                }
                fence(Ordering::Acquire);
                if r[rw::SEQ].load(Ordering::Relaxed) == s1 {
                    if s1 == 0 || words[rw::INDEX] != index {
                        return Ok(None);
                    }
                    return Ok(Some(Record::decode(&words)));
                }
            }
            if spin > 64 {
                std::thread::yield_now();
            } else {
                std::hint::spin_loop();
            }
        }
        Err(HistoryError::Overrun)
    }

    /// The newest record.
    pub fn newest(&self) -> Result<Record, HistoryError> {
        for _ in 0..RESTARTS {
            let n = self.write_index();
            if n == 0 {
                return Err(HistoryError::Empty);
            }
            if let Some(r) = self.record(n - 1)? {
                return Ok(r);
            }
        }
        Err(HistoryError::Overrun)
    }

    /// The state at host time `host_ns` (`CLOCK_MONOTONIC`), interpolated between the two
    /// records around it.
    pub fn state_at_host(&self, host_ns: i64) -> Result<Interpolated, HistoryError> {
        let (a, b) = self.bracket(host_ns, Clock::Host)?;
        Ok(interpolate(&a, &b, host_ns))
    }

    /// The state at UTC `utc_ns` (ns since 1970: the GNSS time as UTC), interpolated between
    /// the two records around it; the host instant is mapped linearly between them.
    pub fn state_at(&self, utc_ns: i64) -> Result<Interpolated, HistoryError> {
        let (a, b) = self.bracket(utc_ns, Clock::Utc)?;
        if a.utc_ns == i64::MIN || b.utc_ns == i64::MIN {
            return Err(HistoryError::TimeUnknown(utc_ns));
        }
        let host_ns = if b.utc_ns == a.utc_ns {
            a.host_ns
        } else {
            let f = (utc_ns - a.utc_ns) as f64 / (b.utc_ns - a.utc_ns) as f64;
            a.host_ns + ((b.host_ns - a.host_ns) as f64 * f).round() as i64
        };
        let mut out = interpolate(&a, &b, host_ns);
        out.utc_ns = utc_ns;
        Ok(out)
    }

    /// The records `a`, `b` (consecutive) with `key(a) ≤ t ≤ key(b)`.
    fn bracket(&self, t: i64, clock: Clock) -> Result<(Record, Record), HistoryError> {
        let key = |r: &Record| match clock {
            Clock::Host => r.host_ns,
            Clock::Utc => r.utc_ns,
        };
        'restart: for _ in 0..RESTARTS {
            let n = self.write_index();
            if n < 2 {
                return Err(HistoryError::Empty);
            }
            // The slot the writer fills next holds the oldest record: left out.
            let (mut lo, mut hi) = (n.saturating_sub(self.capacity - 1), n - 1);
            let Some(mut b) = self.record(hi)? else { continue };
            if t > key(&b) {
                return Err(HistoryError::TooNew {
                    requested: t,
                    newest: key(&b),
                    clock,
                });
            }
            let Some(mut a) = self.record(lo)? else { continue };
            if t < key(&a) {
                return Err(HistoryError::TooOld {
                    requested: t,
                    oldest: key(&a),
                    clock,
                });
            }
            while hi - lo > 1 {
                let mid = lo + (hi - lo) / 2;
                let Some(m) = self.record(mid)? else {
                    continue 'restart;
                };
                if key(&m) <= t {
                    (lo, a) = (mid, m);
                } else {
                    (hi, b) = (mid, m);
                }
            }
            // `a` may have been lapped since it was read; the copies are consistent anyway,
            // and consecutive.
            return Ok((a, b));
        }
        Err(HistoryError::Overrun)
    }
}

/// A state interpolated between two records of the history.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interpolated {
    /// The host instant, ns.
    pub host_ns: i64,
    /// Its UTC, ns since 1970 (`i64::MIN` when a record around it has none).
    pub utc_ns: i64,
    /// Position, velocity, attitude and their σ, interpolated.
    pub pose: Pose,
    /// Where the records before and after the instant come from.
    pub sources: [Option<Source>; 2],
    /// Their `NavStatus`es.
    pub status: [u8; 2],
    /// Their host times, ns.
    pub bracket_host_ns: [i64; 2],
    /// `τ = (t − t_a)/(t_b − t_a)`.
    pub fraction: f64,
}

fn lerp(a: f64, b: f64, t: f64) -> f64 {
    a + (b - a) * t
}

fn lerp3(a: [f64; 3], b: [f64; 3], t: f64) -> [f64; 3] {
    std::array::from_fn(|i| lerp(a[i], b[i], t))
}

/// Cubic Hermite: the value at `τ` of the cubic through `p0`, `p1` with slopes `m0`, `m1`
/// (per unit of τ).
pub fn hermite(p0: f64, m0: f64, p1: f64, m1: f64, tau: f64) -> f64 {
    let (t2, t3) = (tau * tau, tau * tau * tau);
    (2.0 * t3 - 3.0 * t2 + 1.0) * p0 + (t3 - 2.0 * t2 + tau) * m0 + (-2.0 * t3 + 3.0 * t2) * p1 + (t3 - t2) * m1
}

/// Spherical linear interpolation of unit quaternions [w, x, y, z] along the shorter arc
/// (Shoemake 1985); normalised.
pub fn slerp(a: [f64; 4], b: [f64; 4], t: f64) -> [f64; 4] {
    let mut dot: f64 = a.iter().zip(b.iter()).map(|(x, y)| x * y).sum();
    let b = if dot < 0.0 {
        dot = -dot;
        b.map(|x| -x)
    } else {
        b
    };
    let (wa, wb) = if dot > 0.9995 {
        (1.0 - t, t)
    } else {
        let th = dot.clamp(-1.0, 1.0).acos();
        let s = th.sin();
        (((1.0 - t) * th).sin() / s, (t * th).sin() / s)
    };
    let q: [f64; 4] = std::array::from_fn(|i| wa * a[i] + wb * b[i]);
    let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    if n > 0.0 { q.map(|x| x / n) } else { a }
}

/// Roll, pitch, yaw (ZYX Euler) of the body→NED quaternion [w, x, y, z], rad.
pub fn rpy_of(q: [f64; 4]) -> [f64; 3] {
    let [w, x, y, z] = q;
    [
        (2.0 * (w * x + y * z)).atan2(1.0 - 2.0 * (x * x + y * y)),
        (2.0 * (w * y - z * x)).clamp(-1.0, 1.0).asin(),
        (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z)),
    ]
}

/// The state at `host_ns` between records `a` and `b` (`a` before `b`): see the
/// [module](self) documentation for the formulas. Outside `[a, b]` it extrapolates.
pub fn interpolate(a: &Record, b: &Record, host_ns: i64) -> Interpolated {
    let h = (b.host_ns - a.host_ns) as f64 * 1e-9;
    let tau = if h > 0.0 {
        (host_ns - a.host_ns) as f64 * 1e-9 / h
    } else {
        0.0
    };
    let (pa, pb) = (&a.pose, &b.pose);
    // Local NED at a.
    let lat_a = pa.lat_deg.to_radians();
    let (rm, rn) = earth::radii(lat_a);
    let (kn, ke) = (rm + pa.height_m, (rn + pa.height_m) * lat_a.cos());
    let d1 = [
        (pb.lat_deg - pa.lat_deg).to_radians() * kn,
        (pb.lon_deg - pa.lon_deg).to_radians() * ke,
        -(pb.height_m - pa.height_m),
    ];
    let p: [f64; 3] = std::array::from_fn(|i| hermite(0.0, pa.vel_ned_mps[i] * h, d1[i], pb.vel_ned_mps[i] * h, tau));
    let q_nb = slerp(pa.q_nb, pb.q_nb, tau);
    let utc_ns = if a.utc_ns == i64::MIN || b.utc_ns == i64::MIN {
        i64::MIN
    } else {
        a.utc_ns + ((b.utc_ns - a.utc_ns) as f64 * tau).round() as i64
    };
    Interpolated {
        host_ns,
        utc_ns,
        pose: Pose {
            lat_deg: pa.lat_deg + (p[0] / kn).to_degrees(),
            lon_deg: pa.lon_deg + (p[1] / ke).to_degrees(),
            height_m: pa.height_m - p[2],
            vel_ned_mps: lerp3(pa.vel_ned_mps, pb.vel_ned_mps, tau),
            q_nb,
            rpy_rad: rpy_of(q_nb),
            pos_std_ned_m: lerp3(pa.pos_std_ned_m, pb.pos_std_ned_m, tau),
            vel_std_ned_mps: lerp3(pa.vel_std_ned_mps, pb.vel_std_ned_mps, tau),
            att_std_rad: lerp3(pa.att_std_rad, pb.att_std_rad, tau),
        },
        sources: [a.source, b.source],
        status: [a.status, b.status],
        bracket_host_ns: [a.host_ns, b.host_ns],
        fraction: tau,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A record on a straight line with constant acceleration (NED, from a point), at `t` s.
    fn on_line(t: f64, p0: [f64; 3], v0: [f64; 3], acc: [f64; 3]) -> Record {
        let lat0 = 48.0f64;
        let (rm, rn) = earth::radii(lat0.to_radians());
        let ned: [f64; 3] = std::array::from_fn(|i| p0[i] + v0[i] * t + 0.5 * acc[i] * t * t);
        let mut s = NavState::zeroed();
        s.host_ns = (t * 1e9).round() as i64;
        s.utc_ns = 1_700_000_000_000_000_000 + s.host_ns;
        // Small offsets from one origin: the flat-earth map is what the interpolation inverts.
        s.lat_deg = lat0 + (ned[0] / (rm + 500.0)).to_degrees();
        s.lon_deg = 11.0 + (ned[1] / ((rn + 500.0) * lat0.to_radians().cos())).to_degrees();
        s.height_m = 500.0 - ned[2];
        s.vel_ned_mps = std::array::from_fn(|i| v0[i] + acc[i] * t);
        s.q_nb = [1.0, 0.0, 0.0, 0.0];
        s.pos_std_ned_m = [t, 2.0 * t, 3.0 * t];
        Record::of(&s, Source::Predicted)
    }

    #[test]
    fn hermite_is_exact_for_a_constant_acceleration() {
        let (p0, v0, acc) = ([3.0, -2.0, 1.0], [12.0, -5.0, 0.5], [1.5, -2.5, 0.2]);
        // 10 ms apart, as at 100 Hz; then far apart (a gap of 2 s).
        for (t0, t1) in [(4.0, 4.01), (4.0, 6.0)] {
            let (a, b) = (on_line(t0, p0, v0, acc), on_line(t1, p0, v0, acc));
            for k in 0..=10 {
                let t = t0 + (t1 - t0) * k as f64 / 10.0;
                let want = on_line(t, p0, v0, acc);
                let got = interpolate(&a, &b, want.host_ns);
                let (rm, rn) = earth::radii(a.pose.lat_deg.to_radians());
                let dn = (got.pose.lat_deg - want.pose.lat_deg).to_radians() * (rm + a.pose.height_m);
                let de = (got.pose.lon_deg - want.pose.lon_deg).to_radians()
                    * (rn + a.pose.height_m)
                    * a.pose.lat_deg.to_radians().cos();
                let dd = want.pose.height_m - got.pose.height_m;
                // Exact but for the flat-earth map at `a` against the one the states were made
                // with (at the origin: another height and latitude): below 0.1 mm over 40 m.
                assert!(
                    dn.abs() < 1e-4 && de.abs() < 1e-4 && dd.abs() < 1e-6,
                    "{t}: {dn} {de} {dd}"
                );
                for i in 0..3 {
                    assert!((got.pose.vel_ned_mps[i] - want.pose.vel_ned_mps[i]).abs() < 1e-9);
                    assert!((got.pose.pos_std_ned_m[i] - want.pose.pos_std_ned_m[i]).abs() < 1e-9);
                }
                assert_eq!(got.utc_ns, want.utc_ns);
            }
        }
    }

    #[test]
    fn slerp_halfway_on_a_known_rotation() {
        // 90° about down (yaw) → halfway is 45°.
        let h = std::f64::consts::FRAC_PI_4;
        let a = [1.0, 0.0, 0.0, 0.0];
        let b = [h.cos(), 0.0, 0.0, h.sin()];
        let m = slerp(a, b, 0.5);
        let r = rpy_of(m);
        assert!(
            (r[2] - h).abs() < 1e-12 && r[0].abs() < 1e-12 && r[1].abs() < 1e-12,
            "{r:?}"
        );
        // The other sign of the same rotation takes the same (short) way.
        let m2 = slerp(a, b.map(|x| -x), 0.5);
        assert!((rpy_of(m2)[2] - h).abs() < 1e-12);
        // Roll 10° → 30° through 20°, a quarter of the way 15°.
        let roll = |d: f64| {
            let x = d.to_radians() / 2.0;
            [x.cos(), x.sin(), 0.0, 0.0]
        };
        assert!((rpy_of(slerp(roll(10.0), roll(30.0), 0.25))[0] - 15f64.to_radians()).abs() < 1e-12);
    }

    fn temp_path(tag: &str) -> PathBuf {
        std::env::temp_dir().join(format!("navsync-history-{tag}-{}", std::process::id()))
    }

    #[test]
    fn queries_outside_say_which_side_and_the_ring_keeps_the_newest() {
        let path = temp_path("ring");
        let mut w = HistoryWriter::create_at(&path, 50).unwrap();
        let h = History::open_at(&path).unwrap();
        assert!(matches!(h.state_at_host(0), Err(HistoryError::Empty)));
        let (p0, v0, acc) = ([0.0; 3], [10.0, 0.0, 0.0], [0.5, 0.0, 0.0]);
        for k in 0..200 {
            let mut s = NavState::zeroed();
            let r = on_line(1.0 + k as f64 * 0.01, p0, v0, acc);
            (s.host_ns, s.utc_ns, s.lat_deg, s.lon_deg, s.height_m) =
                (r.host_ns, r.utc_ns, r.pose.lat_deg, r.pose.lon_deg, r.pose.height_m);
            s.vel_ned_mps = r.pose.vel_ned_mps;
            s.q_nb = r.pose.q_nb;
            assert!(w.append(&s, Source::Predicted));
            assert!(!w.append(&s, Source::Predicted), "the same time twice");
        }
        assert_eq!(h.write_index(), 200);
        assert_eq!(h.newest().unwrap().host_ns, 2_990_000_000);
        // 49 readable: indices 151..=199.
        match h.state_at_host(1_000_000_000) {
            Err(HistoryError::TooOld {
                oldest,
                clock: Clock::Host,
                ..
            }) => assert_eq!(oldest, 2_510_000_000),
            other => panic!("{other:?}"),
        }
        let e = h.state_at_host(3_000_000_000).unwrap_err();
        assert!(
            matches!(
                e,
                HistoryError::TooNew {
                    newest: 2_990_000_000,
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("newer"), "{e}");
        let got = h.state_at_host(2_755_000_000).unwrap();
        assert_eq!(got.bracket_host_ns, [2_750_000_000, 2_760_000_000]);
        assert!((got.fraction - 0.5).abs() < 1e-9);
        assert_eq!(got.sources, [Some(Source::Predicted); 2]);
        let want = on_line(2.755, p0, v0, acc);
        assert!((got.pose.lat_deg - want.pose.lat_deg).abs() < 1e-11);
        // By UTC: the same instant.
        let by_utc = h.state_at(want.utc_ns).unwrap();
        assert_eq!(by_utc.host_ns, 2_755_000_000);
        assert!(matches!(
            h.state_at(0),
            Err(HistoryError::TooOld { clock: Clock::Utc, .. })
        ));
        // Ends inclusive.
        assert_eq!(h.state_at_host(2_990_000_000).unwrap().fraction, 1.0);
        assert_eq!(h.state_at_host(2_510_000_000).unwrap().fraction, 0.0);
        // A second writer is refused while the first lives; the file goes with the writer.
        assert!(matches!(
            HistoryWriter::create_at(&path, 50),
            Err(HistoryError::Refused { .. })
        ));
        let mode = std::fs::metadata(&path).unwrap().mode() & 0o777;
        assert_eq!(mode, 0o640);
        assert!(h.is_current());
        drop(w);
        assert!(!path.exists());
        // The reader keeps its mapping, and knows it is no longer the file.
        assert_eq!(h.write_index(), 200);
        assert!(!h.is_current());
    }

    #[test]
    fn a_file_of_a_dead_writer_is_replaced_and_foreign_layouts_refused() {
        let (path, stale) = (temp_path("live"), temp_path("stale"));
        let w = HistoryWriter::create_at(&path, 10).unwrap();
        // As after SIGKILL: a history file nobody holds the lock of.
        std::fs::copy(&path, &stale).unwrap();
        drop(w);
        assert!(History::open_at(&stale).is_ok());
        let w2 = HistoryWriter::create_at(&stale, 10).unwrap();
        assert!(History::open_at(&stale).is_ok());
        drop(w2);
        assert!(!stale.exists());
        std::fs::write(&path, vec![0u8; 4096]).unwrap();
        assert!(matches!(History::open_at(&path), Err(HistoryError::Refused { .. })));
        std::fs::remove_file(&path).unwrap();
        assert!(matches!(History::open_at(&path), Err(HistoryError::Missing { .. })));
    }
}
