//! `--transports futex-floor`: the floor of any shared-memory transport on this machine, to
//! bound what navsync's services could reach. A ring of [`SLOTS`] slots in one `/dev/shm` file
//! and one futex word that every subscriber sleeps on: the publisher writes the slot, publishes
//! its sequence number, adds one to the word and, when anyone sleeps, wakes them all with one
//! `FUTEX_WAKE` (`futex(2)`; the lost-wake-up argument of Drepper, "Futexes Are Tricky", §5).
//! No iceoryx2, no per-subscriber notification, no connection or node bookkeeping: what is
//! left is the kernel waking each subscriber and the subscriber reading the stamp in place.
//! Not a transport for the product (no dead-publisher detection, no back-pressure: a
//! subscriber more than [`SLOTS`] samples behind loses them, counted).

use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};

use navsync_shared::ipc::futex::futex;

/// Slots of the ring.
pub const SLOTS: u64 = 64;
/// Header bytes: the futex word (u32) and the sleeper count (u32), one cache line.
const HEADER: usize = 64;

/// Bytes per slot: its sequence number in a cache line of its own, then the payload.
fn stride(payload: usize) -> usize {
    64 + payload.div_ceil(64) * 64
}

/// Creates (or truncates) the ring file for a payload of `payload` bytes, zeroed.
pub fn create(path: &Path, payload: usize) -> std::io::Result<()> {
    let f = std::fs::File::create(path)?;
    f.set_len((HEADER + SLOTS as usize * stride(payload)) as u64)
}

/// A mapped ring.
pub struct Ring {
    base: *mut u8,
    len: usize,
    stride: usize,
}

impl Drop for Ring {
    fn drop(&mut self) {
        // SAFETY: unmapping our own mapping once.
        unsafe { libc::munmap(self.base.cast(), self.len) };
    }
}

impl Ring {
    /// Maps the ring file made by [`create`] for a payload of `payload` bytes.
    pub fn open(path: &Path, payload: usize) -> std::io::Result<Self> {
        use std::os::fd::AsRawFd;
        let f = std::fs::OpenOptions::new().read(true).write(true).open(path)?;
        let len = HEADER + SLOTS as usize * stride(payload);
        if f.metadata()?.len() < len as u64 {
            return Err(std::io::Error::other(format!(
                "{} is shorter than {len} bytes",
                path.display()
            )));
        }
        // SAFETY: a shared read-write mapping of a file of at least `len` bytes.
        let p = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                len,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED,
                f.as_raw_fd(),
                0,
            )
        };
        if p == libc::MAP_FAILED {
            return Err(std::io::Error::last_os_error());
        }
        Ok(Self {
            base: p.cast(),
            len,
            stride: stride(payload),
        })
    }

    fn word(&self) -> &AtomicU32 {
        // SAFETY: offset 0 of a page-aligned mapping, 4-aligned, inside it.
        unsafe { &*self.base.cast::<AtomicU32>() }
    }

    fn sleepers(&self) -> &AtomicU32 {
        // SAFETY: offset 4, 4-aligned, inside the mapping.
        unsafe { &*self.base.add(4).cast::<AtomicU32>() }
    }

    fn slot(&self, seq: u64) -> *mut u8 {
        // SAFETY: (seq mod SLOTS) < SLOTS slots of `stride` bytes after the header.
        unsafe { self.base.add(HEADER + (seq % SLOTS) as usize * self.stride) }
    }

    /// The sequence number + 1 of the sample in `seq`'s slot (0: empty or being written).
    fn slot_seq(&self, seq: u64) -> &AtomicU64 {
        // SAFETY: a 64-aligned slot start inside the mapping.
        unsafe { &*self.slot(seq).cast::<AtomicU64>() }
    }

    /// Writes sample `seq` (made in place by `make`) and wakes every sleeping subscriber.
    pub fn publish<T: Copy>(&self, seq: u64, make: impl FnOnce() -> T) {
        let s = self.slot_seq(seq);
        s.store(0, Ordering::Release);
        // SAFETY: the payload area of the slot is 64-aligned and `stride − 64` ≥ size_of::<T>()
        // bytes long (the ring was opened for this payload size).
        unsafe { std::ptr::write(self.slot(seq).add(64).cast::<T>(), make()) };
        s.store(seq + 1, Ordering::Release);
        self.word().fetch_add(1, Ordering::SeqCst);
        if self.sleepers().load(Ordering::SeqCst) > 0 {
            futex(self.word(), libc::FUTEX_WAKE, i32::MAX as u32, None);
        }
    }

    /// Waits for sample `next` (or a later one, when `next` was overwritten) and hands it to
    /// `f` in place; `None` when `stop` was set. Returns the sample's sequence number too.
    pub fn wait_with<T: Copy, R>(&self, next: u64, stop: &AtomicBool, f: impl Fn(&T) -> R) -> Option<(u64, R)> {
        loop {
            let a = self.slot_seq(next).load(Ordering::Acquire);
            if a > next {
                // Sample a − 1 (≥ next: later ones mean the ring overwrote the ones between).
                // SAFETY: the slot's payload was written as a T by `publish` (plain integers
                // and floats, any bytes valid); a torn read is discarded by the check below.
                let r = f(unsafe { &*self.slot(next).add(64).cast::<T>() });
                if self.slot_seq(next).load(Ordering::Acquire) == a {
                    return Some((a - 1, r));
                }
                continue;
            }
            if stop.load(Ordering::Relaxed) {
                return None;
            }
            self.sleepers().fetch_add(1, Ordering::SeqCst);
            let w = self.word().load(Ordering::SeqCst);
            if self.slot_seq(next).load(Ordering::SeqCst) <= next {
                let t = libc::timespec {
                    tv_sec: 0,
                    tv_nsec: 100_000_000,
                };
                futex(self.word(), libc::FUTEX_WAIT, w, Some(&t));
            }
            self.sleepers().fetch_sub(1, Ordering::SeqCst);
        }
    }
}

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_term(_: libc::c_int) {
    STOP.store(true, Ordering::Relaxed);
}

/// The flag set by SIGTERM (installed on the first call): the bench stops a subscriber that
/// lost the last sample this way.
pub fn stop_flag() -> &'static AtomicBool {
    // SAFETY: the handler only stores to an atomic (async-signal-safe).
    unsafe { libc::signal(libc::SIGTERM, on_term as *const () as libc::sighandler_t) };
    &STOP
}
