//! A global allocator that counts heap bytes in use and their high-water
//! mark, so `solidtex bench` can report the peak memory of one request.
//! Counting is off until [`start`] is called, leaving every other command
//! (the server included) with nothing but one relaxed load per call.
//!
//! The allocator underneath is jemalloc: under 32 concurrent clients the
//! server's peak resident memory was 673 MiB with it against 747 MiB with
//! glibc's (same 60 s load, 444–449 MiB of cached tiles), whose per-thread
//! arenas fragment as jobs come and go.
//!
//! jemalloc is told to advise its memory for transparent huge pages
//! ([`JEMALLOC_CONF`]): a correction reads its candidate tables (tens of
//! MB per texture) at random, and with 4 KiB pages its loads miss the TLB.
//! On a cold 256² slice on one thread that took 5–7 % of the time (min and
//! median of 10 interleaved runs); the price is about 10 % more resident
//! memory under load (whole huge pages are zeroed and kept). Where the
//! system disables transparent huge pages the advice does nothing;
//! `_RJEM_MALLOC_CONF` overrides it.
//!
//! Unsafe code here, because `GlobalAlloc` is an unsafe trait; every method
//! forwards to jemalloc unchanged. The only other unsafe block
//! is the cache prefetch hint in `synth::correction`.

use std::alloc::{GlobalAlloc, Layout};
use std::sync::atomic::{AtomicBool, AtomicIsize, Ordering};
use tikv_jemallocator::Jemalloc;

/// jemalloc's options, read once before its first allocation: it looks up
/// this symbol by name (a NUL-terminated C string, the `malloc_conf` of
/// jemalloc's manual under the prefix of the `tikv-jemalloc-sys` build).
#[unsafe(export_name = "_rjem_malloc_conf")]
pub static JEMALLOC_CONF: &[u8; 11] = b"thp:always\0";

/// jemalloc plus byte counters.
pub struct PeakAlloc;

static ENABLED: AtomicBool = AtomicBool::new(false);
/// Bytes allocated minus freed since counting started (frees of blocks
/// allocated earlier can make it negative).
static CURRENT: AtomicIsize = AtomicIsize::new(0);
static PEAK: AtomicIsize = AtomicIsize::new(0);

fn grow(bytes: usize) {
    if ENABLED.load(Ordering::Relaxed) {
        let now = CURRENT.fetch_add(bytes as isize, Ordering::Relaxed) + bytes as isize;
        PEAK.fetch_max(now, Ordering::Relaxed);
    }
}

fn shrink(bytes: usize) {
    if ENABLED.load(Ordering::Relaxed) {
        CURRENT.fetch_sub(bytes as isize, Ordering::Relaxed);
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
