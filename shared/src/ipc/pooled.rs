//! A single-threaded reference count whose memory is recycled: the thread-safety policy of
//! navsync's iceoryx2 service type.
//!
//! iceoryx2 0.10 wraps every loaned sample's bookkeeping in its service type's
//! `ArcThreadSafetyPolicy` (`ChunkMutSharedState::new`, once per `loan_uninit`); the stock
//! `SingleThreaded` policy is an `Rc`, so every publish allocated once. [`Pooled`] has `Rc`'s
//! semantics (not `Send`, shared ownership within a thread) but returns a freed block to a
//! per-thread free list of its layout and takes the next one from there: after the first
//! loans, publishing allocates nothing (`tests/tests/process/no_alloc_drivers.rs`).

use core::alloc::Layout;
use core::cell::{Cell, RefCell};
use core::fmt::Debug;
use core::marker::PhantomData;
use core::ops::Deref;
use core::ptr::NonNull;

use iceoryx2_bb_elementary_traits::testing::abandonable::Abandonable;
use iceoryx2_cal::arc_sync_policy::{ArcSyncPolicy, ArcSyncPolicyCreationError, LockGuard};

/// Freed blocks per layout; few layouts exist (one per shared-state type).
type FreeLists = Vec<(Layout, Vec<NonNull<u8>>)>;

thread_local! {
    static FREE: RefCell<FreeLists> = const { RefCell::new(Vec::new()) };
}

/// A block for `layout`: a recycled one, else a new allocation.
fn take(layout: Layout) -> Option<NonNull<u8>> {
    let recycled = FREE
        .try_with(|f| {
            let mut f = f.borrow_mut();
            f.iter_mut().find(|(l, _)| *l == layout).and_then(|(_, v)| v.pop())
        })
        .ok()
        .flatten();
    // SAFETY: `layout` has a non-zero size (it holds a count).
    recycled.or_else(|| NonNull::new(unsafe { std::alloc::alloc(layout) }))
}

/// Returns a block of `layout` to this thread's free list (freed if the thread is ending).
fn give(layout: Layout, p: NonNull<u8>) {
    let kept = FREE
        .try_with(|f| {
            let mut f = f.borrow_mut();
            match f.iter_mut().find(|(l, _)| *l == layout) {
                Some((_, v)) => v.push(p),
                None => f.push((layout, vec![p])),
            }
        })
        .is_ok();
    if !kept {
        // SAFETY: `p` was allocated with `layout` by `take` and is no longer used.
        unsafe { std::alloc::dealloc(p.as_ptr(), layout) };
    }
}

struct Inner<T> {
    count: Cell<usize>,
    value: T,
}

/// `Rc<T>` with recycled memory (see the module documentation).
pub struct Pooled<T: Send + Debug + Abandonable> {
    inner: NonNull<Inner<T>>,
    /// Owns an `Inner<T>`; not `Send`, not `Sync` (the count is not atomic).
    _owns: PhantomData<(Inner<T>, *const ())>,
}

impl<T: Send + Debug + Abandonable> Pooled<T> {
    fn inner(&self) -> &Inner<T> {
        // SAFETY: `inner` is live while any `Pooled` pointing to it is.
        unsafe { self.inner.as_ref() }
    }
}

impl<T: Send + Debug + Abandonable> Debug for Pooled<T> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Pooled").field("value", &self.inner().value).finish()
    }
}

impl<T: Send + Debug + Abandonable> Clone for Pooled<T> {
    fn clone(&self) -> Self {
        let c = &self.inner().count;
        c.set(c.get() + 1);
        Self {
            inner: self.inner,
            _owns: PhantomData,
        }
    }
}

impl<T: Send + Debug + Abandonable> Drop for Pooled<T> {
    fn drop(&mut self) {
        let c = &self.inner().count;
        let n = c.get() - 1;
        c.set(n);
        if n == 0 {
            // SAFETY: the last owner: drop the value, then recycle its block.
            unsafe { core::ptr::drop_in_place(&mut (*self.inner.as_ptr()).value) };
            give(Layout::new::<Inner<T>>(), self.inner.cast());
        }
    }
}

impl<T: Send + Debug + Abandonable> Abandonable for Pooled<T> {
    unsafe fn abandon_in_place(mut this: NonNull<Self>) {
        // As iceoryx2's `SingleThreaded`: the sole owner abandons the value (and leaks its
        // block), a shared owner only gives up its share.
        // SAFETY: the caller hands over `this`, which is valid.
        let this = unsafe { this.as_mut() };
        if this.inner().count.get() == 1 {
            // SAFETY: sole owner; the value is not used again.
            unsafe { T::abandon_in_place(NonNull::from_mut(&mut (*this.inner.as_ptr()).value)) };
        } else {
            // SAFETY: dropping this share once.
            unsafe { core::ptr::drop_in_place(this) };
        }
    }
}

/// The lock guard: single-threaded, so a plain reference.
pub struct Guard<'parent, T: Send + Debug> {
    value: &'parent T,
}

impl<T: Send + Debug> Deref for Guard<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        self.value
    }
}

impl<'parent, T: Send + Debug + Abandonable> LockGuard<'parent, T> for Guard<'parent, T> {}

impl<T: Send + Debug + Abandonable> ArcSyncPolicy<T> for Pooled<T> {
    type LockGuard<'parent>
        = Guard<'parent, T>
    where
        Self: 'parent,
        T: 'parent;

    fn new(value: T) -> Result<Self, ArcSyncPolicyCreationError> {
        let p = take(Layout::new::<Inner<T>>()).ok_or(ArcSyncPolicyCreationError::InsufficientResources)?;
        let inner = p.cast::<Inner<T>>();
        // SAFETY: a block of `Inner<T>`'s layout, unused: initialise it.
        unsafe {
            inner.as_ptr().write(Inner {
                count: Cell::new(1),
                value,
            })
        };
        Ok(Self {
            inner,
            _owns: PhantomData,
        })
    }

    fn lock(&self) -> Guard<'_, T> {
        Guard {
            value: &self.inner().value,
        }
    }
}
