//! A global allocator that counts heap bytes in use and their high-water
//! mark: over the whole process once [`start`] is called (`solidtex bench`
//! reports the peak memory of one request), and at any time per group of
//! threads that [`Meter::attach`] tied to a [`Meter`] (the server measures
//! each precompute on its pool). Without either, every call costs two
//! relaxed loads and a thread-local read. The binary installs it; a library
//! user that does not gets no counts ([`installed`] is false).
//!
//! The allocator underneath is jemalloc: glibc's per-thread arenas
//! fragment as jobs come and go, and the server's peak resident memory
//! under load is lower with jemalloc (docs/server.md). Its options
//! (how soon freed pages go back to the system) are set by the binary.
//!
//! Unsafe code here, because `GlobalAlloc` is an unsafe trait; every method
//! forwards to jemalloc unchanged.
#![allow(unsafe_code)]

use std::alloc::{GlobalAlloc, Layout};
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, AtomicIsize, Ordering};
use tikv_jemallocator::Jemalloc;

/// jemalloc plus byte counters.
pub struct PeakAlloc;

static ENABLED: AtomicBool = AtomicBool::new(false);
/// Bytes allocated minus freed since counting started (frees of blocks
/// allocated earlier can make it negative).
static CURRENT: AtomicIsize = AtomicIsize::new(0);
static PEAK: AtomicIsize = AtomicIsize::new(0);

/// Set by the first allocation through [`PeakAlloc`].
static INSTALLED: AtomicBool = AtomicBool::new(false);

thread_local! {
    /// The meter this thread's allocations count on, if any. A plain
    /// reference, so that the slot needs no destructor (registering one
    /// could allocate from inside the allocator).
    static THREAD_METER: Cell<Option<&'static Meter>> = const { Cell::new(None) };
}

fn thread_meter() -> Option<&'static Meter> {
    THREAD_METER.try_with(Cell::get).ok().flatten()
}

fn grow(bytes: usize) {
    if !INSTALLED.load(Ordering::Relaxed) {
        INSTALLED.store(true, Ordering::Relaxed);
    }
    if ENABLED.load(Ordering::Relaxed) {
        let now = CURRENT.fetch_add(bytes as isize, Ordering::Relaxed) + bytes as isize;
        PEAK.fetch_max(now, Ordering::Relaxed);
    }
    if let Some(m) = thread_meter() {
        m.grow(bytes);
    }
}

fn shrink(bytes: usize) {
    if ENABLED.load(Ordering::Relaxed) {
        CURRENT.fetch_sub(bytes as isize, Ordering::Relaxed);
    }
    if let Some(m) = thread_meter() {
        m.shrink(bytes);
    }
}

// SAFETY: every call is forwarded to `Jemalloc` with the caller's arguments;
// the counters never touch the memory.
unsafe impl GlobalAlloc for PeakAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: same contract as ours.
        let p = unsafe { Jemalloc.alloc(layout) };
        if !p.is_null() {
            grow(layout.size());
        }
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: same contract as ours.
        let p = unsafe { Jemalloc.alloc_zeroed(layout) };
        if !p.is_null() {
            grow(layout.size());
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as ours.
        unsafe { Jemalloc.dealloc(ptr, layout) };
        shrink(layout.size());
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: same contract as ours.
        let p = unsafe { Jemalloc.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            shrink(layout.size());
            grow(new_size);
        }
        p
    }
}

/// Starts counting (idempotent).
pub fn start() {
    ENABLED.store(true, Ordering::Relaxed);
}

/// Forgets the high-water mark and returns the bytes in use now: the
/// baseline of [`peak_above`].
pub fn reset() -> isize {
    let now = CURRENT.load(Ordering::Relaxed);
    PEAK.store(now, Ordering::Relaxed);
    now
}

/// The most bytes in use at once since the last [`reset`], above its
/// `baseline` (0 when counting is off).
pub fn peak_above(baseline: isize) -> u64 {
    (PEAK.load(Ordering::Relaxed) - baseline).max(0) as u64
}

/// Heap bytes in use now, counted since [`start`] (`None` before it, or
/// when [`PeakAlloc`] is not the process's allocator).
pub fn in_use() -> Option<u64> {
    (installed() && ENABLED.load(Ordering::Relaxed))
        .then(|| CURRENT.load(Ordering::Relaxed).max(0) as u64)
}

/// Whether [`PeakAlloc`] is the process's allocator (its counts are real).
pub fn installed() -> bool {
    INSTALLED.load(Ordering::Relaxed)
}

/// Heap bytes allocated minus freed by the threads attached to it, and
/// their high-water mark. Memory allocated on one of them and freed on
/// another thread stays counted, and the other way round is subtracted.
#[derive(Debug, Default)]
pub struct Meter {
    current: AtomicIsize,
    peak: AtomicIsize,
}

impl Meter {
    /// A meter that lives as long as the process, as threads that point
    /// at it may.
    pub fn leaked() -> &'static Meter {
        Box::leak(Box::default())
    }

    /// Counts the calling thread's allocations on this meter from now on
    /// (a pool's start handler calls it on each of its threads).
    pub fn attach(&'static self) {
        let _ = THREAD_METER.try_with(|m| m.set(Some(self)));
    }

    fn grow(&self, bytes: usize) {
        let now = self.current.fetch_add(bytes as isize, Ordering::Relaxed) + bytes as isize;
        self.peak.fetch_max(now, Ordering::Relaxed);
    }

    fn shrink(&self, bytes: usize) {
        self.current.fetch_sub(bytes as isize, Ordering::Relaxed);
    }

    /// Forgets the high-water mark and returns the bytes counted now: the
    /// baseline of [`Meter::peak_above`].
    pub fn reset(&self) -> isize {
        let now = self.current.load(Ordering::Relaxed);
        self.peak.store(now, Ordering::Relaxed);
        now
    }

    /// The most bytes counted at once since the last [`Meter::reset`],
    /// above its `baseline`.
    pub fn peak_above(&self, baseline: isize) -> u64 {
        (self.peak.load(Ordering::Relaxed) - baseline).max(0) as u64
    }
}
