//! A level's schedule: how its voxels are corrected, decided once per
//! level when a texture is made and read alike by the planner (which walks
//! it backwards), the synthesis (which runs it forwards) and the estimator
//! (which bounds how far it reaches).
//!
//! It is the triple of Zhang et al. §5: the correction steps of the
//! [dual grid](super::dual_grid) (passes on a grid, then on its shift), the
//! subpass classes of each pass (independent voxels corrected together),
//! and the [history window](super::history) that says which version of
//! each neighbour a correction reads; with the radius a correction reads
//! and the [`Reach`] that follows from them.

use super::dual_grid::{self, Step};
use super::history::HistoryWindow;
use super::plan::{self, Classes, Reach};
use crate::params::SynthParams;
use crate::period::Period;
use rustc_hash::FxHashMap as HashMap;

/// How one level is corrected.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LevelSchedule {
    /// The correction steps, in order (empty: the level is not corrected).
    pub steps: Vec<Step>,
    /// The subpasses of each pass.
    pub classes: Classes,
    /// Which version of each neighbour a correction reads.
    pub window: HistoryWindow,
    /// How far a correction reads, in voxels of the level.
    pub radius: i64,
    /// How far the level's dependency chain reaches from its targets.
    pub reach: Reach,
}

impl LevelSchedule {
    /// The schedule of level `k` (0 = finest, `init_level` the coarsest,
    /// the one the slab initialises) under `params`, for corrections that
    /// read `radius` voxels away.
    pub fn of_level(
        params: &SynthParams,
        period: Option<&Period>,
        k: usize,
        init_level: usize,
        radius: i64,
    ) -> LevelSchedule {
        let passes = if k == init_level && !params.correct_init_level {
            0
        } else if k < params.fine_levels as usize {
            params.finest_passes
        } else {
            params.passes
        };
        LevelSchedule::new(
            dual_grid::steps(params, passes),
            Classes::at(params, k),
            HistoryWindow::of(dual_grid::cells(params, period, k)),
            radius,
        )
    }

    /// A schedule of these parts, with its reach.
    pub fn new(
        steps: Vec<Step>,
        classes: Classes,
        window: HistoryWindow,
        radius: i64,
    ) -> LevelSchedule {
        let reach = known_reach(&steps, radius, classes, window.uniform_side());
        LevelSchedule {
            steps,
            classes,
            window,
            radius,
            reach,
        }
    }

    /// The same schedule for corrections that read `radius` voxels away
    /// (what a larger neighbourhood would cost).
    pub fn with_radius(&self, radius: i64) -> LevelSchedule {
        LevelSchedule::new(self.steps.clone(), self.classes, self.window, radius)
    }

    /// Passes over all steps.
    pub fn passes(&self) -> usize {
        self.steps.iter().map(|s| s.passes as usize).sum()
    }

    /// Subpasses of one pass.
    pub fn subpasses_per_pass(&self) -> usize {
        self.classes.count() as usize
    }

    /// The version after pass `pass` (counted over all steps from 0):
    /// `pass + 1`, or 0, the final version, after the last pass.
    pub fn version_after_pass(&self, pass: usize) -> usize {
        if pass + 1 < self.passes() {
            pass + 1
        } else {
            0
        }
    }
}

/// [`plan::reach`], computed once per process for each set of arguments:
/// textures with the same synthesis parameters share it.
fn known_reach(steps: &[Step], radius: i64, classes: Classes, cell: Option<i64>) -> Reach {
    type Key = (Vec<Step>, i64, Classes, Option<i64>);
    static KNOWN: std::sync::LazyLock<parking_lot::Mutex<HashMap<Key, Reach>>> =
        std::sync::LazyLock::new(Default::default);
    let key = (steps.to_vec(), radius, classes, cell);
    if let Some(r) = KNOWN.lock().get(&key) {
        return *r;
    }
    let r = plan::reach(steps, radius, classes, cell);
    KNOWN.lock().insert(key, r);
    r
}
