//! History windows (Zhang et al. §5): which version of each neighbour a
//! correction reads. A level's corrections run in passes of subpasses, and
//! every subpass writes a new version of the voxels it corrects; a
//! correction in subpass t reads its neighbours either
//!
//! - at their latest version, the one after subpass t − 1 (Dong et al.'s
//!   standard scheme): the dependency set of a voxel then grows by the
//!   correction's radius with every subpass, or
//! - at their latest version inside the voxel's cell of the step's
//!   [dual grid](super::dual_grid), and across the cell's walls at the
//!   version the step started from: the wall is a barrier that dependency
//!   chains do not cross within a step.
//!
//! The planner ([`super::plan::backward`]) walks these windows backwards to
//! the voxels each subpass must correct; the synthesis reads them forwards
//! (`Corrector::correct`, which resolves once per voxel whether any of its
//! reads lies beyond the wall). Both ask the window the same question:
//! [`HistoryWindow::latest_within`].

use super::dual_grid::cell_of;
use super::grid::Box3;
use crate::period::Intervals;

/// Which version of each neighbour a correction reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum HistoryWindow {
    /// The latest version of every neighbour (standard scheme).
    Latest,
    /// The latest inside the voxel's cell of these cells (shifted by the
    /// step's offset), the step's starting version beyond its walls.
    Cells([Intervals; 3]),
}

impl HistoryWindow {
    /// The window of a level corrected on `cells` (`None`: no dual grid).
    pub fn of(cells: Option<[Intervals; 3]>) -> HistoryWindow {
        cells.map_or(HistoryWindow::Latest, HistoryWindow::Cells)
    }

    /// Whether some reads go back to the step's starting version, which
    /// the synthesis must then keep.
    pub fn has_walls(&self) -> bool {
        matches!(self, HistoryWindow::Cells(_))
    }

    /// The box inside which a correction of `p`, in the step whose grid is
    /// shifted by `offset`, reads its neighbours' latest versions (beyond
    /// it, their versions at the step's start); `None`: the latest
    /// everywhere.
    #[inline]
    pub fn latest_within(&self, p: [i64; 3], offset: i64) -> Option<Box3> {
        match self {
            HistoryWindow::Latest => None,
            HistoryWindow::Cells(cells) => Some(cell_of(cells, p, offset)),
        }
    }

    /// The cells' side when every cell has the same (the form the reach of
    /// a level is walked for; per-period cells are bounded without walls).
    pub fn uniform_side(&self) -> Option<i64> {
        match self {
            HistoryWindow::Cells([Intervals::Uniform(m), ..]) => Some(*m),
            _ => None,
        }
    }
}
