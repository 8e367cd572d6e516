//! Dependency planning: which voxels of which level and step a request
//! needs, for both correction schemes.

/// Splits cells into groups whose bounding boxes are not much larger than
/// the cells themselves (so a standard-scheme batch never synthesizes the
/// empty space between scattered cells).
pub fn group_cells(cells: &[[i64; 3]], _cell: i64) -> Vec<Vec<[i64; 3]>> {
    let mut out = Vec::new();
    split(cells.to_vec(), &mut out);
    out
}

fn split(mut cells: Vec<[i64; 3]>, out: &mut Vec<Vec<[i64; 3]>>) {
    if cells.is_empty() {
        return;
    }
    let lo = [0, 1, 2].map(|a| cells.iter().map(|c| c[a]).min().expect("non-empty"));
    let hi = [0, 1, 2].map(|a| cells.iter().map(|c| c[a]).max().expect("non-empty"));
    let ext = [0, 1, 2].map(|a| hi[a] - lo[a] + 1);
    let volume: i64 = ext.iter().product();
    if cells.len() == 1 || volume <= 2 * cells.len() as i64 {
        out.push(cells);
        return;
    }
    let axis = (0..3)
        .max_by_key(|&a| (ext[a], -(a as i64)))
        .expect("three axes");
    cells.sort_by_key(|c| (c[axis], c[(axis + 1) % 3], c[(axis + 2) % 3]));
    let right = cells.split_off(cells.len() / 2);
    split(cells, out);
    split(right, out);
}

use super::Step;

/// Exact dependency counts of one level under a history-window scheme.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LevelPlan {
    /// Voxels whose version 0 is needed (upsampled or initialised).
    pub voxels: u64,
    /// Corrections performed over all passes and subpasses.
    pub corrections: u64,
}

/// The voxels a correction at `v` reads: its three axis-aligned N×N slice
/// neighbourhoods (which contain the 3×3 in-plane neighbours whose triples
/// gather candidates).
fn shape(v: [i64; 3], r: i64, mut f: impl FnMut([i64; 3])) {
    for (a, b) in [(0usize, 1usize), (1, 2), (2, 0)] {
        for j in -r..=r {
            for i in -r..=r {
                let mut q = v;
                q[a] += i;
                q[b] += j;
                // Each plane contains the centre lines of the others; only
                // the xy plane reports them, so every voxel comes once.
                let on_axis = (i == 0 || j == 0) && (a, b) != (0, 1);
                if !on_axis {
                    f(q);
                }
            }
        }
    }
}

fn class_of(p: [i64; 3], side: i64) -> i64 {
    p[0].rem_euclid(side) + side * p[1].rem_euclid(side) + side * side * p[2].rem_euclid(side)
}

/// A dense set of voxels inside a fixed box.
struct Mask {
    grid: super::grid::Grid<bool>,
    count: u64,
}

impl Mask {
    fn new(b: super::grid::Box3) -> Mask {
        Mask {
            grid: super::grid::Grid::new(b),
            count: 0,
        }
    }

    #[inline]
    fn insert(&mut self, p: [i64; 3]) {
        let i = self.grid.index(p);
        if !self.grid.data[i] {
            self.grid.data[i] = true;
            self.count += 1;
        }
    }

    fn positions(&self) -> impl Iterator<Item = [i64; 3]> + '_ {
        self.grid
            .data
            .iter()
            .enumerate()
            .filter(|(_, b)| **b)
            .map(|(i, _)| self.grid.position(i))
    }
}

/// Exact voxel-level dependency sets of a request (Dong et al.'s
/// "Mask ⊗ Neighborhood" chain, with Zhang et al.'s history windows),
/// level by level from the finest: for each level, the version-0 voxels and
/// the corrections needed. `steps_per_level[k]` lists the correction steps
/// at level k (empty: no correction); `cell` is the dual-grid cell side, or
/// `None` for the standard scheme, where every correction reads the latest
/// version of every neighbour. Within a grid step a neighbour across the
/// cell wall is read at the version the step started from.
pub fn exact_chain(
    request: &[[i64; 3]],
    levels: usize,
    steps_per_level: &[Vec<Step>],
    radius: i64,
    side: i64,
    cell: Option<i64>,
) -> Vec<LevelPlan> {
    use super::grid::Box3;
    let Some(first) = request.first() else {
        return Vec::new();
    };
    let mut bounds = request.iter().fold(Box3::new(*first, [1, 1, 1]), |b, p| {
        b.union(&Box3::new(*p, [1, 1, 1]))
    });
    let mut points: Vec<[i64; 3]> = request.to_vec();
    let mut out = Vec::new();
    let classes = side * side * side;
    for steps in steps_per_level.iter().take(levels) {
        let growth: i64 = steps
            .iter()
            .map(|s| s.passes as i64 * classes * radius)
            .sum();
        let mut need = Mask::new(bounds.dilate(growth + radius));
        for p in &points {
            need.insert(*p);
        }
        let mut corrections = 0u64;
        for step in steps.iter().rev() {
            let cell_of = |p: [i64; 3]| cell.map(|m| p.map(|v| (v - step.offset).div_euclid(m)));
            let mut start = Mask::new(need.grid.bounds);
            for t in (0..step.passes as i64 * classes).rev() {
                let class = t % classes;
                let corrected: Vec<[i64; 3]> = need
                    .positions()
                    .filter(|&v| class_of(v, side) == class)
                    .collect();
                corrections += corrected.len() as u64;
                for v in corrected {
                    let cv = cell_of(v);
                    shape(v, radius, |q| {
                        if cell_of(q) == cv {
                            need.insert(q);
                        } else {
                            start.insert(q);
                        }
                    });
                }
            }
            let extra: Vec<[i64; 3]> = start.positions().collect();
            for q in extra {
                need.insert(q);
            }
        }
        out.push(LevelPlan {
            voxels: need.count,
            corrections,
        });
        let mut parents: Vec<[i64; 3]> = need
            .positions()
            .map(|p| p.map(|v| v.div_euclid(2)))
            .collect();
        parents.sort_unstable();
        parents.dedup();
        bounds = need.grid.bounds.parent();
        points = parents;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shape_has_sixty_one_voxels_for_n5() {
        let mut s = std::collections::HashSet::new();
        shape([0, 0, 0], 2, |q| {
            assert!(s.insert(q), "duplicate {q:?}");
        });
        assert_eq!(s.len(), 61);
    }

    #[test]
    fn barriers_bound_the_chain() {
        let steps = vec![
            vec![
                Step {
                    offset: 0,
                    passes: 1,
                },
                Step {
                    offset: 6,
                    passes: 1,
                },
            ];
            3
        ];
        let standard_steps = vec![
            vec![Step {
                offset: 0,
                passes: 2,
            }];
            3
        ];
        let dual = exact_chain(&[[5, 5, 5]], 3, &steps, 2, 2, Some(12));
        let standard = exact_chain(&[[5, 5, 5]], 3, &standard_steps, 2, 2, None);
        let total = |v: &[LevelPlan]| v.iter().map(|l| l.voxels).sum::<u64>();
        assert!(total(&dual) < total(&standard), "{dual:?} vs {standard:?}");
    }
}
