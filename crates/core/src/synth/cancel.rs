//! Cooperative cancellation of a synthesis whose answer nobody will read
//! (a client that hung up), or of a precompute whose texture was deleted.
//! The caller runs the engine inside [`run_cancellable`]; the engine looks
//! at the flag between correction subpasses (a precompute: between pixels
//! of its search and between its stages) and, once it is set, unwinds out
//! of the request. Unwinding is
//! safe for the shared cache: tiles finished before the flag was seen are
//! complete and stay published, and the tickets of tiles in flight are
//! released, so requests waiting for them compute them themselves. Nothing
//! partial is ever published.

use std::cell::RefCell;
use std::panic::{AssertUnwindSafe, catch_unwind, resume_unwind};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// A flag that asks the syntheses run under it to stop, and optionally a
/// budget of voxels they may synthesize before they are stopped.
#[derive(Clone, Debug, Default)]
pub struct CancelFlag(Arc<State>);

#[derive(Debug, Default)]
struct State {
    cancelled: AtomicBool,
    /// Voxels still allowed; `None`: no budget.
    budget: Option<AtomicU64>,
    over_budget: AtomicBool,
    /// Voxels charged so far, budget or not: what a progress report reads.
    charged: AtomicU64,
}

impl CancelFlag {
    /// A flag not yet set, without a budget.
    pub fn new() -> CancelFlag {
        CancelFlag::default()
    }

    /// A flag that also stops the syntheses under it once they have
    /// synthesized more than `voxels` voxels (all levels together; voxels
    /// found in the cache are free).
    pub fn with_budget(voxels: u64) -> CancelFlag {
        CancelFlag(Arc::new(State {
            budget: Some(AtomicU64::new(voxels)),
            ..State::default()
        }))
    }

    /// Asks the syntheses under this flag to stop at their next check.
    pub fn cancel(&self) {
        self.0.cancelled.store(true, Ordering::Relaxed);
    }

    /// Whether [`CancelFlag::cancel`] was called, or the budget ran out.
    pub fn is_cancelled(&self) -> bool {
        self.0.cancelled.load(Ordering::Relaxed)
    }

    /// Unwinds out of the work under this flag (see [`check`]) if it is set.
    pub(crate) fn unwind_if_set(&self) {
        if self.is_cancelled() {
            resume_unwind(Box::new(Cancelled));
        }
    }

    /// Whether the syntheses were stopped because they went over budget.
    pub fn is_over_budget(&self) -> bool {
        self.0.over_budget.load(Ordering::Relaxed)
    }

    /// Voxels the syntheses under this flag have set out to synthesize so
    /// far (all levels; counted as each group of tiles starts, so slightly
    /// ahead of the finished work).
    pub fn synthesized(&self) -> u64 {
        self.0.charged.load(Ordering::Relaxed)
    }

    /// The share of `predicted` voxels (a cold-cache upper bound, see
    /// [`crate::Texture::estimate`]) synthesized so far, short of 1: the
    /// bound is seldom reached, so only the end of the work says it is done.
    pub fn share_of(&self, predicted: u64) -> f64 {
        (self.synthesized() as f64 / predicted.max(1) as f64).min(0.99)
    }

    /// Takes `voxels` from the budget; false (and the flag set) when that
    /// is more than is left.
    fn charge(&self, voxels: u64) -> bool {
        self.0.charged.fetch_add(voxels, Ordering::Relaxed);
        let Some(left) = &self.0.budget else {
            return true;
        };
        let ok = left
            .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |l| {
                l.checked_sub(voxels)
            })
            .is_ok();
        if !ok {
            self.0.over_budget.store(true, Ordering::Relaxed);
            self.cancel();
        }
        ok
    }
}

/// The error of a synthesis stopped by its flag.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Cancelled;

thread_local! {
    /// The flag of the synthesis started on this thread, if any.
    static CURRENT: RefCell<Option<CancelFlag>> = const { RefCell::new(None) };
}

/// Runs `f` (which calls the engine on this thread) under `flag`: a
/// synthesis started inside it stops soon after the flag is set, and this
/// then returns `Err(Cancelled)`. Other panics pass through unchanged.
pub fn run_cancellable<T>(flag: &CancelFlag, f: impl FnOnce() -> T) -> Result<T, Cancelled> {
    struct Restore(Option<CancelFlag>);
    impl Drop for Restore {
        fn drop(&mut self) {
            let old = self.0.take();
            CURRENT.with(|c| *c.borrow_mut() = old);
        }
    }
    let _restore = Restore(CURRENT.with(|c| c.borrow_mut().replace(flag.clone())));
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(v) => Ok(v),
        Err(payload) if payload.is::<Cancelled>() => Err(Cancelled),
        Err(payload) => resume_unwind(payload),
    }
}

/// The flag the engine should watch for a request starting on this thread.
pub(crate) fn current() -> Option<CancelFlag> {
    CURRENT.with(|c| c.borrow().clone())
}

/// Unwinds out of the synthesis if `flag` is set (no panic message: this
/// is not an error of the engine).
pub(crate) fn check(flag: &Option<CancelFlag>) {
    if let Some(f) = flag {
        f.unwind_if_set();
    }
}

/// Charges `voxels` about to be synthesized to the flag's budget, and
/// unwinds out of the synthesis when they do not fit.
pub(crate) fn charge(flag: &Option<CancelFlag>, voxels: u64) {
    if let Some(f) = flag
        && !f.charge(voxels)
    {
        resume_unwind(Box::new(Cancelled));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_budget_stops_what_goes_over_it() {
        let flag = CancelFlag::with_budget(100);
        let r = run_cancellable(&flag, || {
            charge(&current(), 60);
            charge(&current(), 40);
            assert!(!flag.is_cancelled());
            charge(&current(), 1);
            unreachable!("over budget");
        });
        assert_eq!(r, Err(Cancelled));
        assert!(flag.is_over_budget() && flag.is_cancelled());
        assert_eq!(flag.synthesized(), 101);
        // Without a budget, charges are free, and still counted.
        let free = CancelFlag::new();
        assert_eq!(
            run_cancellable(&free, || charge(&current(), u64::MAX)),
            Ok(())
        );
        assert!(!free.is_over_budget());
        assert_eq!(free.synthesized(), u64::MAX);
    }

    #[test]
    fn a_set_flag_stops_at_the_next_check() {
        let flag = CancelFlag::new();
        let r = run_cancellable(&flag, || {
            check(&current());
            flag.cancel();
            check(&current());
            unreachable!("the second check unwinds");
        });
        assert_eq!(r, Err(Cancelled));
        // Outside the scope no flag is watched.
        assert!(current().is_none());
        assert_eq!(run_cancellable(&CancelFlag::new(), || 3), Ok(3));
    }

    #[test]
    fn other_panics_pass_through() {
        let r = std::panic::catch_unwind(|| run_cancellable(&CancelFlag::new(), || panic!("boom")));
        assert!(r.is_err());
        assert!(current().is_none());
    }
}
