//! The dual grid (Zhang et al. §5): a level's P correction passes run as
//! two steps, ⌈P/2⌉ passes on a grid of M³ cells, then ⌊P/2⌋ on the same
//! grid shifted by M/2 along every axis, so that every voxel near a wall
//! of the first grid lies well inside a cell of the second. Within a step,
//! a correction reads across its cell's walls only the versions the step
//! started from (see [`super::history`]), which bounds how far the
//! dependencies of a voxel spread: a step's chain stays inside its cell
//! and a ring of the correction's radius around it.
//!
//! The standard scheme (Dong et al.) is one step on no grid. A periodic
//! solid lays its cells per period (see [`crate::period`]): at most M
//! voxels each, a whole number per period.

use super::grid::Box3;
use crate::params::{Scheme, SynthParams};
use crate::period::{Intervals, Period};

/// One correction step of a level: cells shifted by `offset`, corrected
/// `passes` times.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Step {
    /// Grid shift (0 for the primary grid, M/2 for the dual grid).
    pub offset: i64,
    /// Passes in this step.
    pub passes: u32,
}

/// The correction steps of `passes` passes under the texture's scheme.
pub fn steps(params: &SynthParams, passes: u32) -> Vec<Step> {
    match params.scheme {
        Scheme::DualGrid => [
            Step {
                offset: 0,
                passes: passes.div_ceil(2),
            },
            Step {
                offset: params.grid as i64 / 2,
                passes: passes / 2,
            },
        ]
        .into_iter()
        .filter(|s| s.passes > 0)
        .collect(),
        Scheme::Standard if passes > 0 => vec![Step { offset: 0, passes }],
        Scheme::Standard => Vec::new(),
    }
}

/// The cells of level `k` along x, y and z, or `None` under the standard
/// scheme: M voxels each, or laid per period for a periodic solid.
pub fn cells(params: &SynthParams, period: Option<&Period>, k: usize) -> Option<[Intervals; 3]> {
    let m = params.grid as i64;
    match (params.scheme, period) {
        (Scheme::Standard, _) => None,
        (Scheme::DualGrid, None) => Some([Intervals::Uniform(m); 3]),
        (Scheme::DualGrid, Some(p)) => Some(p.cells(k, m)),
    }
}

/// The cell holding `v` of the grid of `cells` shifted by `offset`.
#[inline]
pub fn cell_of(cells: &[Intervals; 3], v: [i64; 3], offset: i64) -> Box3 {
    // Spelled out: an array `map` here is compiled out of line.
    let (ix, iy, iz) = (
        cells[0].index_of(v[0] - offset),
        cells[1].index_of(v[1] - offset),
        cells[2].index_of(v[2] - offset),
    );
    Box3::new(
        [
            cells[0].start(ix) + offset,
            cells[1].start(iy) + offset,
            cells[2].start(iz) + offset,
        ],
        [cells[0].size(ix), cells[1].size(iy), cells[2].size(iz)],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passes_split_between_the_grid_and_its_shift() {
        let dual = SynthParams {
            scheme: Scheme::DualGrid,
            grid: 12,
            ..SynthParams::default()
        };
        let step = |offset, passes| Step { offset, passes };
        assert_eq!(steps(&dual, 3), vec![step(0, 2), step(6, 1)]);
        assert_eq!(steps(&dual, 1), vec![step(0, 1)]);
        assert!(steps(&dual, 0).is_empty());
        let standard = SynthParams {
            scheme: Scheme::Standard,
            ..dual
        };
        assert_eq!(steps(&standard, 3), vec![step(0, 3)]);
        assert!(cells(&standard, None, 0).is_none());
    }

    #[test]
    fn cells_hold_their_voxels() {
        let cells = [Intervals::Uniform(12); 3];
        for (v, offset) in [([0, 0, 0], 0), ([-1, 11, 12], 0), ([5, 6, -7], 6)] {
            let c = cell_of(&cells, v, offset);
            assert!(c.contains(v), "{v:?} {c:?}");
            assert_eq!(c.size(), [12; 3]);
            assert!(c.lo.iter().all(|&lo| (lo - offset).rem_euclid(12) == 0));
        }
    }
}
