//! A global allocator for the no-allocation tests: it forwards to the system allocator and
//! counts, per thread, how many allocations (and reallocations) were made.
//!
//! Why per thread: a test binary has other threads (libtest's main thread waits on a channel
//! and may allocate its waker the first time it blocks, at a moment that depends on
//! scheduling). A process-wide counter saw those allocations on a loaded CI machine and failed
//! a step that made none; counting only the measuring thread is what the tests mean.
//!
//! Use it in a test binary:
//! ```
//! #[global_allocator]
//! static GLOBAL: counting_alloc::Counting = counting_alloc::Counting;
//!
//! let mut samples = Vec::with_capacity(16);
//! let ((), made) = counting_alloc::count(|| samples.extend_from_slice(&[1u64, 2, 3]));
//! assert_eq!(made, 0, "pushing within capacity does not allocate");
//! let ((), made) = counting_alloc::count(|| samples.extend(0..100));
//! assert!(made >= 1, "growing past capacity does");
//! ```

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

/// The counting allocator; install it with `#[global_allocator]` in the test binary.
pub struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

fn count_one() {
    // `try_with`: during thread teardown the counter may be gone; such allocations are not ours.
    let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
}

// SAFETY: forwards every call to the system allocator unchanged; the counter is a
// const-initialised thread local, which needs no allocation to reach.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count_one();
        // SAFETY: the caller upholds `GlobalAlloc::alloc`'s contract, which is the system's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count_one();
        // SAFETY: as for `alloc`.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from this allocator, i.e. from the system's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count_one();
        // SAFETY: as for `dealloc`, and the caller upholds `realloc`'s contract.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

/// Allocations made so far on the calling thread (only while [`Counting`] is the global
/// allocator; otherwise always 0).
pub fn allocations() -> u64 {
    ALLOCATIONS.with(|c| c.get())
}

/// Runs `f` and returns its result with the allocations it made on this thread.
pub fn count<T>(f: impl FnOnce() -> T) -> (T, u64) {
    let before = allocations();
    let out = f();
    (out, allocations() - before)
}
