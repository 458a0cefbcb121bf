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
//! record, header words, the write index of the predicted ring: records written so far, the
//! writer's pid, the write index of the fused ring), then two rings of `capacity` records of
//! [`RECORD_WORDS`] words each ([`Record`]: word 0 the record's sequence lock, word 1 its index,
//! then the state's fields; `docs/guide/history.md` has the table): first the real-time
//! predictor's states ([`Source::Predicted`], as published on `navsync/nav/state`), then the
//! delayed filter's ([`Source::Fused`]: its state at each instant it stepped over, with every
//! measurement up to that instant fused, about the fusion horizon behind the present).
//! Record `i` of a ring is in its slot `i % capacity`. A query answers from the fused states
//! where they reach the instant and from the predicted ones after them, so an answer improves
//! once the delayed filter has passed its instant ([`Interpolated::sources`] says which).

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
//! Between the two records around the instant as [`navsync_wire::interpolation`] describes
//! (cubic Hermite position, linear velocity, slerp attitude, linear σ's), found by the rule of
//! [`bracket_index`]; the estimator's event poses use the same functions on the same fused
//! states, so an event's pose equals `state_at` of its time.
//!
//! [`History::state_at`] takes a UTC instant (ns since 1970, the GNSS time as UTC), finds the
//! records around it by their UTC, maps it to host time linearly between them, and
//! interpolates as above.

use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering, fence};

pub use crate::interpolation::{
    Interpolated, Pose, Record, Source, at_utc, bracket_index, hermite, interpolate, rpy_of, slerp,
};
use crate::reflect::Reflect;
use crate::samples::NavState;

/// `NAVSHIST`, little-endian, word 0 of the header.
pub const MAGIC: u64 = u64::from_le_bytes(*b"NAVSHIST");
/// The layout of the header and the records (word 1 of the header).
pub const LAYOUT_VERSION: u64 = 2;
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
    /// Records written to the ring of predicted states.
    pub const WRITE_INDEX: usize = 9;
    pub const WRITER_PID: usize = 10;
    /// Records written to the ring of fused states.
    pub const FUSED_WRITE_INDEX: usize = 11;
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

/// Writes `r` into the words of a record (word 0, the sequence, left out).
fn encode(this: &Record, w: &mut [u64; RECORD_WORDS]) {
    let f = |x: f64| x.to_bits();
    w[rw::INDEX] = this.index;
    w[rw::HOST_NS] = this.host_ns as u64;
    w[rw::UTC_NS] = this.utc_ns as u64;
    w[rw::LAT] = f(this.pose.lat_deg);
    w[rw::LON] = f(this.pose.lon_deg);
    w[rw::HEIGHT] = f(this.pose.height_m);
    let mut put = |at: usize, v: &[f64]| {
        for (k, x) in v.iter().enumerate() {
            w[at + k] = x.to_bits();
        }
    };
    put(rw::VEL, &this.pose.vel_ned_mps);
    put(rw::Q, &this.pose.q_nb);
    put(rw::GYRO, &this.gyro_body_rps);
    put(rw::POS_STD, &this.pose.pos_std_ned_m);
    put(rw::VEL_STD, &this.pose.vel_std_ned_mps);
    put(rw::ATT_STD, &this.pose.att_std_rad);
    put(rw::RPY, &this.pose.rpy_rad);
    w[rw::FLAGS] = u64::from_le_bytes([
        this.source.map_or(0, |s| s as u8),
        this.status,
        this.time_status,
        this.integrity,
        0,
        0,
        0,
        0,
    ]);
}

/// The record in the words `w`.
fn decode(w: &[u64; RECORD_WORDS]) -> Record {
    let f = |i: usize| f64::from_bits(w[i]);
    let v3 = |i: usize| [f(i), f(i + 1), f(i + 2)];
    let flags = w[rw::FLAGS].to_le_bytes();
    Record {
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

/// The rings of the file: the real-time predictor's states, and the delayed filter's.
const RINGS: usize = 2;

fn file_len(capacity: u64) -> usize {
    (HEADER_WORDS + RINGS * capacity as usize * RECORD_WORDS) * 8
}

/// The ring of `source`'s states: 0 predicted, 1 fused.
fn ring_of(source: Source) -> usize {
    match source {
        Source::Predicted => 0,
        Source::Fused => 1,
    }
}

/// The header word with the write index of ring `ring`.
fn write_index_word(ring: usize) -> usize {
    if ring == 0 {
        hw::WRITE_INDEX
    } else {
        hw::FUSED_WRITE_INDEX
    }
}

/// The first word of record `index` of ring `ring`.
fn record_base(capacity: u64, ring: usize, index: u64) -> usize {
    HEADER_WORDS + (ring * capacity as usize + (index % capacity) as usize) * RECORD_WORDS
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
    /// Records written, per ring.
    next: [u64; RINGS],
    /// The newest record's host time, per ring.
    last_host_ns: [i64; RINGS],
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
            next: [0; RINGS],
            last_host_ns: [i64::MIN; RINGS],
            rejected: 0,
        })
    }

    /// Appends `s` from `source` to that source's ring; false (and counted in
    /// [`rejected`](Self::rejected)) when its host time is not after the last one's of that
    /// ring (each ring is in time order).
    pub fn append(&mut self, s: &NavState, source: Source) -> bool {
        let ring = ring_of(source);
        if s.host_ns <= self.last_host_ns[ring] {
            self.rejected += 1;
            return false;
        }
        self.last_host_ns[ring] = s.host_ns;
        let mut rec = Record::of(s, source);
        let next = self.next[ring];
        rec.index = next;
        let mut words = [0u64; RECORD_WORDS];
        encode(&rec, &mut words);
        let w = self.map.words();
        let base = record_base(self.capacity, ring, next);
        let r = &w[base..base + RECORD_WORDS];
        let seq = r[rw::SEQ].load(Ordering::Relaxed);
        r[rw::SEQ].store(seq.wrapping_add(1) | 1, Ordering::Relaxed);
        fence(Ordering::Release);
        for (a, v) in r.iter().zip(words.iter()).skip(1) {
            a.store(*v, Ordering::Relaxed);
        }
        r[rw::SEQ].store((seq | 1).wrapping_add(1), Ordering::Release);
        self.next[ring] = next + 1;
        w[write_index_word(ring)].store(next + 1, Ordering::Release);
        true
    }

    /// Records written to the ring of predicted states.
    pub fn written(&self) -> u64 {
        self.next[0]
    }

    /// Records written to the ring of `source`'s states.
    pub fn written_of(&self, source: Source) -> u64 {
        self.next[ring_of(source)]
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

    /// Records written so far to the ring of predicted states (its write index).
    pub fn write_index(&self) -> u64 {
        self.write_index_of(Source::Predicted)
    }

    /// Records written so far to the ring of `source`'s states.
    pub fn write_index_of(&self, source: Source) -> u64 {
        self.map.words()[write_index_word(ring_of(source))].load(Ordering::Acquire)
    }

    /// The writer's process id.
    pub fn writer_pid(&self) -> u32 {
        self.map.words()[hw::WRITER_PID].load(Ordering::Relaxed) as u32
    }

    /// A consistent copy of record `index` of the predicted states; `None` when the writer
    /// lapped it (or it was never written), `Err(Overrun)` when the writer stayed in the
    /// middle of it.
    pub fn record(&self, index: u64) -> Result<Option<Record>, HistoryError> {
        self.record_of(Source::Predicted, index)
    }

    /// [`record`](Self::record) of the ring of `source`'s states.
    pub fn record_of(&self, source: Source, index: u64) -> Result<Option<Record>, HistoryError> {
        let w = self.map.words();
        let base = record_base(self.capacity, ring_of(source), index);
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
                    return Ok(Some(decode(&words)));
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
    /// records around it: the fused states' where they reach, else the predicted states'.
    pub fn state_at_host(&self, host_ns: i64) -> Result<Interpolated, HistoryError> {
        let (a, b) = self.bracket_either(host_ns, Clock::Host)?;
        Ok(interpolate(&a, &b, host_ns))
    }

    /// The state at UTC `utc_ns` (ns since 1970: the GNSS time as UTC), interpolated between
    /// the two records around it (fused where they reach, else predicted); the host instant
    /// is mapped linearly between them.
    pub fn state_at(&self, utc_ns: i64) -> Result<Interpolated, HistoryError> {
        let (a, b) = self.bracket_either(utc_ns, Clock::Utc)?;
        if a.utc_ns == i64::MIN || b.utc_ns == i64::MIN {
            return Err(HistoryError::TimeUnknown(utc_ns));
        }
        Ok(at_utc(&a, &b, utc_ns))
    }

    /// The records around `t` among the fused states, else among the predicted ones (an
    /// instant the delayed filter has not reached yet, or before its first state).
    fn bracket_either(&self, t: i64, clock: Clock) -> Result<(Record, Record), HistoryError> {
        match self.bracket(Source::Fused, t, clock) {
            Err(HistoryError::Overrun) => Err(HistoryError::Overrun),
            Ok((a, b)) if clock == Clock::Host || (a.utc_ns != i64::MIN && b.utc_ns != i64::MIN) => Ok((a, b)),
            _ => self.bracket(Source::Predicted, t, clock),
        }
    }

    /// The records `a`, `b` (consecutive) of `source`'s ring with `key(a) ≤ t ≤ key(b)`,
    /// found by the rule of [`bracket_index`].
    fn bracket(&self, source: Source, t: i64, clock: Clock) -> Result<(Record, Record), HistoryError> {
        let key = |r: &Record| match clock {
            Clock::Host => r.host_ns,
            Clock::Utc => r.utc_ns,
        };
        'restart: for _ in 0..RESTARTS {
            let n = self.write_index_of(source);
            if n < 2 {
                return Err(HistoryError::Empty);
            }
            // The slot the writer fills next holds the oldest record: left out.
            let (mut lo, mut hi) = (n.saturating_sub(self.capacity - 1), n - 1);
            let Some(mut b) = self.record_of(source, hi)? else {
                continue;
            };
            if t > key(&b) {
                return Err(HistoryError::TooNew {
                    requested: t,
                    newest: key(&b),
                    clock,
                });
            }
            let Some(mut a) = self.record_of(source, lo)? else {
                continue;
            };
            if t < key(&a) {
                return Err(HistoryError::TooOld {
                    requested: t,
                    oldest: key(&a),
                    clock,
                });
            }
            while hi - lo > 1 {
                let mid = lo + (hi - lo) / 2;
                let Some(m) = self.record_of(source, mid)? else {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::earth;

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
    fn fused_states_answer_where_they_reach_and_the_predicted_after_them() {
        let path = temp_path("fused");
        let mut w = HistoryWriter::create_at(&path, 500).unwrap();
        let h = History::open_at(&path).unwrap();
        let (p0, v0, acc) = ([0.0; 3], [10.0, 0.0, 0.0], [0.5, 0.0, 0.0]);
        let state = |t: f64, north_offset_m: f64| {
            let mut s = NavState::zeroed();
            let r = on_line(t, [p0[0] + north_offset_m, 0.0, 0.0], v0, acc);
            (s.host_ns, s.utc_ns, s.lat_deg, s.lon_deg, s.height_m) =
                (r.host_ns, r.utc_ns, r.pose.lat_deg, r.pose.lon_deg, r.pose.height_m);
            s.vel_ned_mps = r.pose.vel_ned_mps;
            s.q_nb = r.pose.q_nb;
            s
        };
        // Predicted 1.00..2.99 s; fused (1 m further north: a correction) 1.00..1.99 s.
        for k in 0..200 {
            assert!(w.append(&state(1.0 + k as f64 * 0.01, 0.0), Source::Predicted));
        }
        for k in 0..100 {
            assert!(w.append(&state(1.0 + k as f64 * 0.01, 1.0), Source::Fused));
        }
        assert_eq!(
            (w.written_of(Source::Predicted), w.written_of(Source::Fused)),
            (200, 100)
        );
        assert_eq!(h.write_index_of(Source::Fused), 100);
        let lat_north = |x: &Interpolated, t: f64| {
            let want = on_line(t, p0, v0, acc);
            let (rm, _) = earth::radii(want.pose.lat_deg.to_radians());
            (x.pose.lat_deg - want.pose.lat_deg).to_radians() * rm
        };
        let early = h.state_at_host(1_505_000_000).unwrap();
        assert_eq!(early.sources, [Some(Source::Fused); 2]);
        assert!(
            (lat_north(&early, 1.505) - 1.0).abs() < 1e-3,
            "{}",
            lat_north(&early, 1.505)
        );
        // By UTC as by host time.
        assert_eq!(h.state_at(early.utc_ns).unwrap().sources, [Some(Source::Fused); 2]);
        let late = h.state_at_host(2_505_000_000).unwrap();
        assert_eq!(late.sources, [Some(Source::Predicted); 2]);
        assert!(lat_north(&late, 2.505).abs() < 1e-3);
        // Between the newest fused state and the next predicted one: the predicted states.
        assert_eq!(
            h.state_at_host(1_995_000_000).unwrap().sources,
            [Some(Source::Predicted); 2]
        );
        // The same two records and formula as any holder of them (the estimator's event poses).
        let recs: Vec<Record> = (0..100)
            .map(|i| h.record_of(Source::Fused, i).unwrap().unwrap())
            .collect();
        let t = early.utc_ns + 1234;
        let (a, b) = bracket_index(recs.len(), |k| recs[k].utc_ns, t).unwrap();
        assert_eq!(h.state_at(t).unwrap(), at_utc(&recs[a], &recs[b], t));
        drop(w);
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
