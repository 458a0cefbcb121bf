//! navsync's iceoryx2 service type: iceoryx2's inter-process concepts with a futex wake-up
//! (and a thread-safety policy that recycles its memory, [`super::pooled`]).
//!
//! iceoryx2 composes a service type from `iceoryx2-cal` concepts; `ipc::Service` wakes a
//! listener through a Unix datagram (`sendto` at the notifier; `epoll`/`poll`, then `fcntl`,
//! `recvfrom`, `fcntl` at the listener). [`Service`] is the same composition with one concept
//! replaced: the event trigger is a 32-bit futex word in the listener's shared management
//! segment (`futex(2)`, `FUTEX_WAIT`/`FUTEX_WAKE` on a shared mapping):
//!
//! * word = `count << 1 | sleeping`; a notifier adds 2 and calls `FUTEX_WAKE` only when the
//!   listener set `sleeping`, so a notification to a listener that is busy costs two atomic
//!   operations and no system call;
//! * the listener waits only after setting `sleeping` and seeing no new count; the kernel's
//!   `FUTEX_WAIT` compares the word with what it saw, so a notification between the two is
//!   never lost (Drepper, "Futexes Are Tricky", 2011, §5);
//! * one listener per trigger (iceoryx2 gives every listener port its own), any number of
//!   notifiers.
//!
//! The trigger has no file descriptor, so listeners of this type cannot be attached to a
//! `WaitSet`; a process waiting on several inputs waits on one event instead
//! ([`super::Wake`]). Everything else (payload segments, connections, node monitoring) is
//! iceoryx2's `ipc::Service` as is, so other iceoryx2 programs can open navsync's
//! publish-subscribe services, only not its events.

use core::fmt::Debug;
use core::marker::PhantomData;
use core::mem::MaybeUninit;
use core::ptr::NonNull;
use core::sync::atomic::{AtomicBool, AtomicPtr, AtomicU8, AtomicU32, AtomicU64, AtomicUsize, Ordering};
use core::time::Duration;

use iceoryx2::prelude::ZeroCopySend;
use iceoryx2_bb_elementary_traits::testing::abandonable::Abandonable;
use iceoryx2_bb_lock_free::mpmc::counting_bit_set::RelocatableCountingBitSet;
use iceoryx2_bb_system_types::file_name::FileName;
use iceoryx2_bb_system_types::path::Path;
use iceoryx2_cal::dynamic_storage::DynamicStorage;
use iceoryx2_cal::event::common::EventImpl;
use iceoryx2_cal::event::event_state::EventState;
use iceoryx2_cal::event::trigger::{Configuration, HandlerInterface, State, WaiterInterface};
use iceoryx2_cal::event::{ListenerCreateError, ListenerWaitError, NotifierNotifyError, NotifierOpenError};
use iceoryx2_cal::named_concept::{NamedConceptPathHintRemoveError, NamedConceptRemoveError};
use iceoryx2_cal::shm_allocator::bump_allocator::BumpAllocator;
use iceoryx2_cal::shm_allocator::pool_allocator::PoolAllocator;
use iceoryx2_cal::{
    bag, dynamic_storage as storage, hash, monitoring, reactor, resizable_shared_memory, serialize, shared_memory,
    static_storage, zero_copy_connection,
};

/// Bit 0 of the futex word: the listener is in (or about to enter) `FUTEX_WAIT`.
const SLEEPING: u32 = 1;
/// What a notification adds to the futex word (the count lives above bit 0).
const COUNT_STEP: u32 = 2;

/// The trigger's state in the listener's shared management segment.
#[derive(Debug)]
#[repr(C)]
pub struct FutexMgmt {
    /// `count << 1 | sleeping`.
    word: AtomicU32,
}

// SAFETY: one `AtomicU32`, no pointers: valid in any process that maps it.
unsafe impl ZeroCopySend for FutexMgmt {}

/// `futex(2)` on a word of a shared mapping (not `FUTEX_PRIVATE_FLAG`: the word is shared
/// between processes). Also the benchmark's yardstick ring (`navsync-bench`, `ipc/floor.rs`).
pub fn futex(word: &AtomicU32, op: libc::c_int, val: u32, timeout: Option<&libc::timespec>) -> libc::c_long {
    let ts = timeout.map_or(core::ptr::null(), |t| t as *const libc::timespec);
    // SAFETY: `word` is a valid, aligned u32 for the call's duration; `ts` is null or points
    // to a live timespec; the remaining arguments are unused by FUTEX_WAIT and FUTEX_WAKE.
    unsafe {
        libc::syscall(
            libc::SYS_futex,
            word.as_ptr(),
            op,
            val,
            ts,
            core::ptr::null::<u32>(),
            0u32,
        )
    }
}

/// Listeners asleep without a kernel timer. `FUTEX_WAIT` with a timeout arms and cancels an
/// hrtimer per wait, i.e. per sample (0.3–2 µs of subscriber CPU per sample on the benchmark
/// VM); the socket's blocking `recv` arms none. So every wait registers here instead and
/// sleeps without a timeout: a termination signal wakes all of them ([`on_termination`], SIGTERM
/// may reach another thread), and the process's alarm thread ([`alarm_loop`]) wakes those whose
/// deadline passed. The alarm re-arms only when a deadline earlier than its own comes in, so
/// a listener that is woken by samples long before its timeout (the estimator's liveness
/// deadlines, a client's `recv(timeout)`) costs one timer per timeout period, not per sample.
const SLEEPER_SLOTS: usize = 64;

/// Timeouts shorter than this arm the kernel's timer (`FUTEX_WAIT` with a timeout): a second
/// thread's wake-up would cost more than the timer, and their precision matters.
pub const ALARM_MIN: Duration = Duration::from_millis(1);

/// One sleeper's futex word and deadline, and whether someone else is looking at the word.
struct SleeperSlot {
    word: AtomicPtr<AtomicU32>,
    /// CLOCK_MONOTONIC ns at which the alarm wakes `word`; 0: none (woken by notifications and
    /// termination only).
    deadline_ns: AtomicU64,
    /// Signal handlers and the alarm thread using `word` now; the sleeper leaves only when 0
    /// (its word's mapping must outlive their use of it).
    busy: AtomicUsize,
}

static SLEEPERS: [SleeperSlot; SLEEPER_SLOTS] = [const {
    SleeperSlot {
        word: AtomicPtr::new(core::ptr::null_mut()),
        deadline_ns: AtomicU64::new(0),
        busy: AtomicUsize::new(0),
    }
}; SLEEPER_SLOTS];

/// The SIGINT and SIGTERM actions [`on_termination`] replaced (iceoryx2's), called after it
/// latched the request: `sa_sigaction` as a number (0: none to call) and whether it takes
/// `SA_SIGINFO`'s three arguments.
static PREVIOUS_SIGINT: AtomicUsize = AtomicUsize::new(0);
static PREVIOUS_SIGTERM: AtomicUsize = AtomicUsize::new(0);
static PREVIOUS_SIGINT_INFO: AtomicBool = AtomicBool::new(false);
static PREVIOUS_SIGTERM_INFO: AtomicBool = AtomicBool::new(false);
/// True once [`on_termination`] is installed for both signals.
static INSTALLED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();

/// `*w += COUNT_STEP` and wake its waiters in one `FUTEX_WAKE_OP`: the kernel does the add
/// under the futex bucket lock, so a `FUTEX_WAIT` about to start sees the new value and does
/// not sleep (no lost wake-up), and no user-space store touches a mapping that may be going
/// away. Async-signal-safe.
///
/// # Safety
/// `w` points to a futex word whose mapping stays for the call (the slot's `busy` count).
unsafe fn bump_and_wake(w: *mut AtomicU32) {
    let op = (libc::FUTEX_OP_ADD << 28) | ((COUNT_STEP as libc::c_int & 0xfff) << 12);
    // SAFETY: per the caller; the kernel reports a fault as EFAULT instead of raising it.
    unsafe {
        libc::syscall(libc::SYS_futex, w, libc::FUTEX_WAKE_OP, i32::MAX, 0usize, w, op);
    }
}

/// SIGINT/SIGTERM: navsync's own record of the request, sticky (`super::TERMINATED`: nothing
/// clears it, unlike iceoryx2's "last signal", which a SIGCONT right after the SIGTERM, as
/// systemd and `timeout` send, overwrites), then the handler that was there (iceoryx2's), then
/// every registered sleeper woken. Async-signal-safe: atomics and `futex(2)`.
extern "C" fn on_termination(sig: libc::c_int, info: *mut libc::siginfo_t, ctx: *mut libc::c_void) {
    super::TERMINATED.store(true, Ordering::SeqCst);
    let (previous, takes_info) = if sig == libc::SIGINT {
        (&PREVIOUS_SIGINT, &PREVIOUS_SIGINT_INFO)
    } else {
        (&PREVIOUS_SIGTERM, &PREVIOUS_SIGTERM_INFO)
    };
    let h = previous.load(Ordering::SeqCst);
    if h != 0 && h != libc::SIG_DFL && h != libc::SIG_IGN {
        if takes_info.load(Ordering::SeqCst) {
            // SAFETY: `h` is the SA_SIGINFO handler sigaction reported as installed.
            let f: extern "C" fn(libc::c_int, *mut libc::siginfo_t, *mut libc::c_void) =
                unsafe { core::mem::transmute(h) };
            f(sig, info, ctx);
        } else {
            // SAFETY: `h` is the plain handler sigaction reported as installed.
            let f: extern "C" fn(libc::c_int) = unsafe { core::mem::transmute(h) };
            f(sig);
        }
    }
    for slot in &SLEEPERS {
        slot.busy.fetch_add(1, Ordering::SeqCst);
        let w = slot.word.load(Ordering::SeqCst);
        if !w.is_null() {
            // SAFETY: the slot is registered, so its sleeper keeps the mapping until `busy`
            // is 0 again.
            unsafe { bump_and_wake(w) };
        }
        slot.busy.fetch_sub(1, Ordering::SeqCst);
    }
}

/// Installs [`on_termination`] in front of the SIGINT/SIGTERM handlers once (after
/// iceoryx2's, which it chains to); false if that failed (waits then keep kernel timeouts,
/// untimed ones sliced at `WAIT_SLICE`, and the request is read from iceoryx2's record).
/// `IpcNode` does it when it is created.
pub fn termination_wakes_sleepers() -> bool {
    *INSTALLED.get_or_init(|| {
        // iceoryx2 installs its handlers on first use (and would replace ours then); make sure
        // they are there to chain to, and latch a request that came before.
        if iceoryx2_bb_posix::signal::SignalHandler::termination_requested() {
            super::TERMINATED.store(true, Ordering::SeqCst);
        }
        for (sig, previous, takes_info) in [
            (libc::SIGINT, &PREVIOUS_SIGINT, &PREVIOUS_SIGINT_INFO),
            (libc::SIGTERM, &PREVIOUS_SIGTERM, &PREVIOUS_SIGTERM_INFO),
        ] {
            // SAFETY: sigaction with valid structs; the handler is async-signal-safe.
            unsafe {
                let mut old: libc::sigaction = core::mem::zeroed();
                if libc::sigaction(sig, core::ptr::null(), &mut old) != 0 {
                    return false;
                }
                previous.store(old.sa_sigaction, Ordering::SeqCst);
                takes_info.store(old.sa_flags & libc::SA_SIGINFO != 0, Ordering::SeqCst);
                let mut new = old;
                new.sa_sigaction =
                    on_termination as extern "C" fn(libc::c_int, *mut libc::siginfo_t, *mut libc::c_void) as usize;
                new.sa_flags = (old.sa_flags | libc::SA_SIGINFO) & !libc::SA_RESETHAND;
                if libc::sigaction(sig, &new, core::ptr::null_mut()) != 0 {
                    return false;
                }
            }
        }
        // A child forked without exec has none of the parent's other threads: no alarm
        // thread and no sleepers; it starts its own alarm on its first timed wait.
        // SAFETY: registers a plain function; failure only leaves that reset out.
        unsafe { libc::pthread_atfork(None, None, Some(after_fork_in_child)) };
        true
    })
}

/// True once [`termination_wakes_sleepers`] installed navsync's handler (the latch is then
/// exact: nothing but that handler needs to be asked).
pub(crate) fn handler_installed() -> bool {
    INSTALLED.get().copied().unwrap_or(false)
}

/// The alarm thread: not started (0), running (1), could not be started (2), being started
/// by another thread (3).
static ALARM_STATE: AtomicU8 = AtomicU8::new(0);
/// Bumped (and woken) when a deadline earlier than [`ALARM_TARGET`] is registered.
static ALARM_WORD: AtomicU32 = AtomicU32::new(0);
/// The deadline (CLOCK_MONOTONIC ns) the alarm sleeps towards; `u64::MAX`: none; 0: it is
/// scanning the slots, so every new deadline must wake it.
static ALARM_TARGET: AtomicU64 = AtomicU64::new(0);
/// `timeouts_by_kernel(true)`: every timed wait arms the kernel's timer (benchmark A/B).
static KERNEL_TIMEOUTS: AtomicBool = AtomicBool::new(false);

/// Timed waits arm the kernel's timer per wait (`true`) or register with the alarm thread
/// (`false`, the default). For measuring what the alarm saves (`navsync-bench ipc
/// --transports iceoryx2-wake,iceoryx2-wake-timer`); both end a wait at its timeout.
pub fn timeouts_by_kernel(on: bool) {
    KERNEL_TIMEOUTS.store(on, Ordering::SeqCst);
}

extern "C" fn after_fork_in_child() {
    for slot in &SLEEPERS {
        slot.deadline_ns.store(0, Ordering::SeqCst);
        slot.word.store(core::ptr::null_mut(), Ordering::SeqCst);
        slot.busy.store(0, Ordering::SeqCst);
    }
    ALARM_TARGET.store(0, Ordering::SeqCst);
    ALARM_STATE.store(0, Ordering::SeqCst);
}

/// CLOCK_MONOTONIC now, ns (never negative).
fn monotonic_ns() -> u64 {
    crate::time::monotonic_now_ns().max(0) as u64
}

/// True once the alarm thread runs (started here on first use).
fn alarm_running() -> bool {
    match ALARM_STATE.load(Ordering::SeqCst) {
        1 => true,
        2 => false,
        _ => {
            if ALARM_STATE
                .compare_exchange(0, 3, Ordering::SeqCst, Ordering::SeqCst)
                .is_ok()
            {
                let ok = std::thread::Builder::new()
                    .name("navsync-alarm".into())
                    .spawn(alarm_loop)
                    .is_ok();
                ALARM_STATE.store(if ok { 1 } else { 2 }, Ordering::SeqCst);
                ok
            } else {
                // Another thread is starting it (state 3): use the kernel's timer this once.
                false
            }
        }
    }
}

/// Sleeps until the earliest registered deadline, wakes the sleepers whose deadline passed
/// (each once: its deadline is cleared), and again. Never returns.
///
/// No lost deadline: a sleeper stores its deadline, then reads [`ALARM_TARGET`] and wakes the
/// alarm if that is 0 (scanning) or later. The alarm sets 0 and reads [`ALARM_WORD`] before it
/// scans, and publishes its target after; so a deadline the scan missed was stored after the
/// scan's read of it, and its sleeper reads 0 (and bumps the word the alarm will wait on) or
/// the new target (bumping the word if it is later, else the alarm wakes first and rescans).
fn alarm_loop() {
    loop {
        ALARM_TARGET.store(0, Ordering::SeqCst);
        let seen = ALARM_WORD.load(Ordering::SeqCst);
        let now = monotonic_ns();
        let mut next = u64::MAX;
        for slot in &SLEEPERS {
            let d = slot.deadline_ns.load(Ordering::SeqCst);
            if d == 0 {
                continue;
            }
            if d > now {
                next = next.min(d);
                continue;
            }
            slot.busy.fetch_add(1, Ordering::SeqCst);
            let w = slot.word.load(Ordering::SeqCst);
            if !w.is_null()
                && slot
                    .deadline_ns
                    .compare_exchange(d, 0, Ordering::SeqCst, Ordering::SeqCst)
                    .is_ok()
            {
                // SAFETY: registered, and `busy` keeps its sleeper (and the mapping) there.
                unsafe { bump_and_wake(w) };
            }
            slot.busy.fetch_sub(1, Ordering::SeqCst);
        }
        ALARM_TARGET.store(next, Ordering::SeqCst);
        let at = (next != u64::MAX).then_some(libc::timespec {
            tv_sec: (next / 1_000_000_000) as libc::time_t,
            tv_nsec: (next % 1_000_000_000) as libc::c_long,
        });
        let ts = at.as_ref().map_or(core::ptr::null(), |t| t as *const libc::timespec);
        // FUTEX_WAIT_BITSET takes an absolute CLOCK_MONOTONIC time (no drift over rescans).
        // SAFETY: a static word, a live timespec or null; val3 is the match-any bitset.
        unsafe {
            libc::syscall(
                libc::SYS_futex,
                ALARM_WORD.as_ptr(),
                libc::FUTEX_WAIT_BITSET | libc::FUTEX_PRIVATE_FLAG,
                seen,
                ts,
                core::ptr::null::<u32>(),
                libc::FUTEX_BITSET_MATCH_ANY,
            );
        }
    }
}

/// Registers `word` as a sleeper, with an alarm at `deadline_ns` (CLOCK_MONOTONIC) if not 0;
/// None if termination cannot wake it or every slot is taken (the caller then arms the
/// kernel's timer).
fn register(word: &AtomicU32, deadline_ns: u64) -> Option<&'static SleeperSlot> {
    if !termination_wakes_sleepers() || (deadline_ns != 0 && !alarm_running()) {
        return None;
    }
    let p = word as *const AtomicU32 as *mut AtomicU32;
    let slot = SLEEPERS.iter().find(|slot| {
        slot.word
            .compare_exchange(core::ptr::null_mut(), p, Ordering::SeqCst, Ordering::SeqCst)
            .is_ok()
    })?;
    if deadline_ns != 0 {
        slot.deadline_ns.store(deadline_ns, Ordering::SeqCst);
        let target = ALARM_TARGET.load(Ordering::SeqCst);
        if target == 0 || deadline_ns < target {
            ALARM_WORD.fetch_add(1, Ordering::SeqCst);
            futex(&ALARM_WORD, libc::FUTEX_WAKE | libc::FUTEX_PRIVATE_FLAG, 1, None);
        }
    }
    Some(slot)
}

fn unregister(slot: &SleeperSlot) {
    slot.deadline_ns.store(0, Ordering::SeqCst);
    slot.word.store(core::ptr::null_mut(), Ordering::SeqCst);
    while slot.busy.load(Ordering::SeqCst) != 0 {
        core::hint::spin_loop();
    }
}

/// The notifier's side: bumps the count and wakes a sleeping listener.
#[derive(Debug)]
pub struct FutexHandle<E: EventState, S: DynamicStorage<State<E, FutexMgmt>>> {
    /// Into the listener's management segment, which the iceoryx2 handle that owns this keeps
    /// mapped for this value's lifetime.
    word: NonNull<AtomicU32>,
    _p: PhantomData<(E, S)>,
}

// SAFETY: the pointee is an atomic in shared memory; all access is atomic.
unsafe impl<E: EventState, S: DynamicStorage<State<E, FutexMgmt>>> Send for FutexHandle<E, S> {}
// SAFETY: as above.
unsafe impl<E: EventState, S: DynamicStorage<State<E, FutexMgmt>>> Sync for FutexHandle<E, S> {}

impl<E: EventState, S: DynamicStorage<State<E, FutexMgmt>>> Abandonable for FutexHandle<E, S> {
    unsafe fn abandon_in_place(_this: NonNull<Self>) {}
}

impl<E: EventState, S: DynamicStorage<State<E, FutexMgmt>>> HandlerInterface<E, FutexMgmt, S> for FutexHandle<E, S> {
    fn open(_name: &FileName, _config: &Configuration, mgmt: &FutexMgmt) -> Result<Self, NotifierOpenError> {
        Ok(Self {
            word: NonNull::from(&mgmt.word),
            _p: PhantomData,
        })
    }

    fn notify(&self) -> Result<(), NotifierNotifyError> {
        // SAFETY: see `word`.
        let word = unsafe { self.word.as_ref() };
        if word.fetch_add(COUNT_STEP, Ordering::SeqCst) & SLEEPING != 0 {
            futex(word, libc::FUTEX_WAKE, 1, None);
        }
        Ok(())
    }
}

/// The listener's side: sleeps in `FUTEX_WAIT` until the count moves.
#[derive(Debug)]
pub struct FutexWaiter<E: EventState, S: DynamicStorage<State<E, FutexMgmt>>> {
    /// Into this listener's own management segment (see [`FutexHandle::word`]).
    word: NonNull<AtomicU32>,
    /// The count (bits above 0) this listener has consumed.
    seen: AtomicU32,
    _p: PhantomData<(E, S)>,
}

// SAFETY: see `FutexHandle`.
unsafe impl<E: EventState, S: DynamicStorage<State<E, FutexMgmt>>> Send for FutexWaiter<E, S> {}
// SAFETY: as above.
unsafe impl<E: EventState, S: DynamicStorage<State<E, FutexMgmt>>> Sync for FutexWaiter<E, S> {}

impl<E: EventState, S: DynamicStorage<State<E, FutexMgmt>>> Abandonable for FutexWaiter<E, S> {
    unsafe fn abandon_in_place(_this: NonNull<Self>) {}
}

impl<E: EventState, S: DynamicStorage<State<E, FutexMgmt>>> FutexWaiter<E, S> {
    fn word(&self) -> &AtomicU32 {
        // SAFETY: see `FutexHandle::word`.
        unsafe { self.word.as_ref() }
    }

    /// Consumes pending notifications; true if there were any.
    fn consume(&self) -> bool {
        let now = self.word().load(Ordering::SeqCst) & !SLEEPING;
        self.seen.swap(now, Ordering::Relaxed) != now
    }

    /// Sleeps until a notification or `timeout` (`None`: none), without a kernel timer where
    /// it can: registered as a sleeper, which a SIGINT/SIGTERM to any thread of the process
    /// wakes ([`on_termination`]) and, for a timeout of at least [`ALARM_MIN`], the alarm
    /// thread at the deadline. Otherwise a timed `FUTEX_WAIT` (an untimed wait sliced at
    /// `WAIT_SLICE`, so that termination is still noticed).
    fn sleep(&self, timeout: Option<Duration>) -> Result<(), ListenerWaitError> {
        if self.consume() {
            return Ok(());
        }
        let deadline_ns = match timeout {
            None => Some(0),
            Some(t) if t >= ALARM_MIN && !KERNEL_TIMEOUTS.load(Ordering::Relaxed) => {
                Some(monotonic_ns().saturating_add(t.as_nanos().min(u64::MAX as u128) as u64))
            }
            Some(_) => None,
        };
        let slot = deadline_ns.and_then(|d| register(self.word(), d));
        match (timeout, slot) {
            (_, Some(slot)) => {
                let r = self.sleep_on_word(None);
                unregister(slot);
                r
            }
            (None, None) => self.sleep_on_word(Some(super::WAIT_SLICE)),
            (Some(t), None) => self.sleep_on_word(Some(t)),
        }
    }

    fn sleep_on_word(&self, timeout: Option<Duration>) -> Result<(), ListenerWaitError> {
        let seen = self.seen.load(Ordering::Relaxed);
        let before = self.word().fetch_or(SLEEPING, Ordering::SeqCst);
        // A termination before this sleeper was registered woke nobody: do not sleep.
        if before & !SLEEPING == seen && !(timeout.is_none() && super::TERMINATED.load(Ordering::SeqCst)) {
            let ts = timeout.map(|t| libc::timespec {
                tv_sec: t.as_secs().min(i32::MAX as u64) as libc::time_t,
                tv_nsec: t.subsec_nanos() as libc::c_long,
            });
            if futex(self.word(), libc::FUTEX_WAIT, seen | SLEEPING, ts.as_ref()) < 0 {
                let e = std::io::Error::last_os_error().raw_os_error();
                // EAGAIN: notified before the wait; ETIMEDOUT: nothing came.
                if e == Some(libc::EINTR) {
                    self.word().fetch_and(!SLEEPING, Ordering::SeqCst);
                    return Err(ListenerWaitError::InterruptSignal);
                }
            }
        }
        let now = self.word().fetch_and(!SLEEPING, Ordering::SeqCst) & !SLEEPING;
        self.seen.store(now, Ordering::Relaxed);
        Ok(())
    }
}

impl<E: EventState, S: DynamicStorage<State<E, FutexMgmt>>> WaiterInterface<E, FutexMgmt, S> for FutexWaiter<E, S> {
    const IS_FILE_DESCRIPTOR_BASED: bool = false;

    unsafe fn remove(_name: &FileName, _config: &Configuration) -> Result<bool, NamedConceptRemoveError> {
        // Nothing besides the management segment, which iceoryx2 removes itself.
        Ok(true)
    }

    fn remove_path_hint(_value: &Path) -> Result<(), NamedConceptPathHintRemoveError> {
        Ok(())
    }

    fn create(
        _name: &FileName,
        _config: &Configuration,
        mgmt: &mut MaybeUninit<FutexMgmt>,
    ) -> Result<Self, ListenerCreateError> {
        let mgmt = mgmt.write(FutexMgmt {
            word: AtomicU32::new(0),
        });
        Ok(Self {
            word: NonNull::from(&mgmt.word),
            seen: AtomicU32::new(0),
            _p: PhantomData,
        })
    }

    fn try_wait(&self) -> Result<(), ListenerWaitError> {
        self.consume();
        Ok(())
    }

    fn timed_wait(&self, timeout: Duration) -> Result<(), ListenerWaitError> {
        self.sleep(Some(timeout))
    }

    fn blocking_wait(&self) -> Result<(), ListenerWaitError> {
        self.sleep(None)
    }

    fn empty_buffer(&self) -> Result<(), ListenerWaitError> {
        self.consume();
        Ok(())
    }
}

type FutexStorage = storage::posix_shared_memory::Storage<State<RelocatableCountingBitSet, FutexMgmt>>;

/// The futex event concept: iceoryx2's event state (a counting bit set of event ids and the
/// notified/idle hand-shake) with the futex trigger.
pub type FutexEvent = EventImpl<
    RelocatableCountingBitSet,
    FutexMgmt,
    FutexStorage,
    FutexHandle<RelocatableCountingBitSet, FutexStorage>,
    FutexWaiter<RelocatableCountingBitSet, FutexStorage>,
>;

/// navsync's iceoryx2 service type: `iceoryx2::service::ipc::Service` with [`FutexEvent`] and
/// a reference count with recycled memory ([`super::pooled::Pooled`]: no allocation per loan).
#[derive(Debug, Clone)]
pub struct Service {}

impl iceoryx2::service::Service for Service {
    type StaticStorage = static_storage::recommended::Ipc;
    type ConfigSerializer = serialize::recommended::Recommended;
    type PersistentDynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
        storage::recommended::PersistentIpc<T>;
    type Bag = bag::recommended::Recommended;
    type DynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> = storage::recommended::Ipc<T>;
    type ServiceNameHasher = hash::recommended::Recommended;
    type SharedMemory = shared_memory::recommended::Ipc<PoolAllocator>;
    type ResizableSharedMemory = resizable_shared_memory::recommended::Ipc<PoolAllocator>;
    type Connection = zero_copy_connection::recommended::Ipc;
    type Event = FutexEvent;
    type Monitoring = monitoring::recommended::Ipc;
    type Reactor = reactor::recommended::Ipc;
    type ArcThreadSafetyPolicy<T: Send + Debug + Abandonable> = super::pooled::Pooled<T>;
    type BlackboardMgmt<KeyType: Send + Sync + Debug + ZeroCopySend + 'static> = storage::recommended::Ipc<KeyType>;
    type BlackboardPayload = shared_memory::recommended::Ipc<BumpAllocator>;
    type UniqueId = iceoryx2::unique_id_generator::unique_system_id::UniqueSystemId;
}

impl iceoryx2::service::internal::ServiceInternal<Service> for Service {}
