//! Dependency planning: which voxels of which level and step a request
//! needs, for both correction schemes.

/// Splits tiles into groups whose bounding boxes hold at most `max` tiles:
/// one group shares its halo of dependencies (large groups waste less), and
/// its working memory is bounded (the dense working box covers the group's
/// bounding box). Empty space inside a box costs memory but no synthesis:
/// only the exact dependency set is computed.
pub fn group_cells(cells: &[[i64; 3]], max: usize) -> Vec<Vec<[i64; 3]>> {
    let mut out = Vec::new();
    split(cells.to_vec(), max, &mut out);
    out
}

fn split(mut cells: Vec<[i64; 3]>, max: usize, out: &mut Vec<Vec<[i64; 3]>>) {
    if cells.is_empty() {
        return;
    }
    let lo = [0, 1, 2].map(|a| cells.iter().map(|c| c[a]).min().expect("non-empty"));
    let hi = [0, 1, 2].map(|a| cells.iter().map(|c| c[a]).max().expect("non-empty"));
    let ext = [0, 1, 2].map(|a| hi[a] - lo[a] + 1);
    let volume: i64 = ext.iter().product();
    if cells.len() == 1 || volume <= max as i64 {
        out.push(cells);
        return;
    }
    let axis = (0..3)
        .max_by_key(|&a| (ext[a], -(a as i64)))
        .expect("three axes");
    cells.sort_by_key(|c| (c[axis], c[(axis + 1) % 3], c[(axis + 2) % 3]));
    let right = cells.split_off(cells.len() / 2);
    split(cells, max, out);
    split(right, max, out);
}

use super::dual_grid::Step;
use super::grid::{Box3, Grid};
use super::history::HistoryWindow;
use super::schedule::LevelSchedule;
use crate::params::SynthParams;
use crate::period::Intervals;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

/// The subpasses of a pass, as the planner and the synthesis walk them
/// (see [`SynthParams::parity_levels`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Classes {
    /// Voxels congruent modulo the side on every axis: side³ subpasses.
    Blocks(i64),
    /// Even coordinate sums, then odd ones.
    Parity,
}

impl Classes {
    /// The subpasses of level `k` (0 = finest) under a texture's
    /// parameters.
    pub fn at(params: &SynthParams, k: usize) -> Classes {
        if k < params.parity_levels as usize {
            Classes::Parity
        } else {
            Classes::Blocks(params.subpass_side as i64)
        }
    }

    /// Subpasses per pass.
    pub fn count(self) -> i64 {
        match self {
            Classes::Blocks(side) => side * side * side,
            Classes::Parity => 2,
        }
    }

    /// Period of the pattern along each axis.
    fn period(self) -> i64 {
        match self {
            Classes::Blocks(side) => side,
            Classes::Parity => 2,
        }
    }

    /// The members of `need` in subpass `class`, column by column: columns
    /// of 16×16 voxels along z, y-major. The voxels of one subpass are
    /// independent, so their order is free; in this one each thread's
    /// share of a subpass reads a compact part of the working grid. The
    /// columns are scanned in parallel.
    fn members_in_columns(self, need: &Mask, class: i64, radius: i64) -> Vec<[i64; 3]> {
        const SIDE: i64 = 16;
        let bounds = need.bounds();
        if bounds.is_empty() {
            return Vec::new();
        }
        let columns =
            |a: usize| bounds.lo[a].div_euclid(SIDE)..=(bounds.hi[a] - 1).div_euclid(SIDE);
        let mut boxes = Vec::new();
        for cy in columns(1) {
            for cx in columns(0) {
                let column = Box3 {
                    lo: [cx * SIDE, cy * SIDE, bounds.lo[2]],
                    hi: [(cx + 1) * SIDE, (cy + 1) * SIDE, bounds.hi[2]],
                };
                boxes.push(bounds.intersect(&column));
            }
        }
        let per_column: Vec<Vec<[i64; 3]>> = boxes
            .par_iter()
            .map(|b| {
                let mut found = Vec::new();
                self.for_class(b, class, radius, |v| {
                    if need.contains(v) {
                        found.push(v);
                    }
                });
                found
            })
            .collect();
        per_column.concat()
    }

    /// Calls `f` for each voxel of `bounds` in subpass `class` (for reads
    /// `radius` voxels away), x fastest.
    fn for_class(self, bounds: &Box3, class: i64, radius: i64, mut f: impl FnMut([i64; 3])) {
        match self {
            Classes::Blocks(side) => {
                bounds.for_class(subpass_phase(class, side, radius), side, f);
            }
            Classes::Parity => {
                for z in bounds.lo[2]..bounds.hi[2] {
                    for y in bounds.lo[1]..bounds.hi[1] {
                        let lo = bounds.lo[0];
                        let mut x = lo + (class - lo - y - z).rem_euclid(2);
                        while x < bounds.hi[0] {
                            f([x, y, z]);
                            x += 2;
                        }
                    }
                }
            }
        }
    }
}

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
/// gather candidates), or with `cube` the whole (2r + 1)³ cube around it
/// (a correction in a local frame, whose rotated neighbourhoods reach the
/// corners).
fn shape(v: [i64; 3], r: i64, cube: bool, mut f: impl FnMut([i64; 3])) {
    if cube {
        for z in -r..=r {
            for y in -r..=r {
                for x in -r..=r {
                    f([v[0] + x, v[1] + y, v[2] + z]);
                }
            }
        }
        return;
    }
    for (a, b) in [(0usize, 1usize), (1, 2), (2, 0)] {
        for j in -r..=r {
            for i in -r..=r {
                let mut q = v;
                q[a] += i;
                q[b] += j;
                // The planes share their axis lines: xy reports the x and y
                // lines, yz the z line, so every voxel comes once.
                let repeated = match (a, b) {
                    (0, 1) => false,
                    (1, 2) => j == 0,
                    _ => i == 0 || j == 0,
                };
                if !repeated {
                    f(q);
                }
            }
        }
    }
}

/// A dense set of voxels inside a fixed box. Members are atomic flags so
/// that the voxels of one subpass mark their neighbourhoods in parallel
/// (marking is idempotent, so the set does not depend on the order).
pub struct Mask {
    /// Geometry only (a grid of zero-sized cells allocates nothing).
    shape: Grid<()>,
    flags: Vec<AtomicBool>,
    count: u64,
}

impl Mask {
    /// An empty set able to hold the voxels of `b`.
    pub fn new(b: Box3) -> Mask {
        Mask {
            shape: Grid::new(b),
            flags: (0..b.volume()).map(|_| AtomicBool::new(false)).collect(),
            count: 0,
        }
    }

    #[inline]
    fn has_index(&self, i: usize) -> bool {
        self.flags[i].load(Ordering::Relaxed)
    }

    /// Whether `p` (which must lie inside the box) is a member.
    #[inline]
    pub fn contains(&self, p: [i64; 3]) -> bool {
        self.has_index(self.shape.index(p))
    }

    /// Adds `p` (which must lie inside the box).
    #[inline]
    pub fn insert(&mut self, p: [i64; 3]) {
        let i = self.shape.index(p);
        if !self.flags[i].swap(true, Ordering::Relaxed) {
            self.count += 1;
        }
    }

    /// Removes `p` (which must lie inside the box) without keeping the
    /// count, like [`Mask::mark`] (call [`Mask::recount`] after a batch).
    #[inline]
    pub fn unmark(&self, p: [i64; 3]) {
        self.flags[self.shape.index(p)].store(false, Ordering::Relaxed);
    }

    /// Adds `p` without keeping the count (call [`Mask::recount`] after a
    /// batch of marks); the hot path of dependency planning, callable from
    /// many threads at once.
    #[inline]
    pub fn mark(&self, p: [i64; 3]) {
        self.flags[self.shape.index(p)].store(true, Ordering::Relaxed);
    }

    /// The index step of the offset `d`.
    fn offset_of(&self, d: [i64; 3]) -> isize {
        let s = self.shape.strides();
        (d[0] * s[0] + d[1] * s[1] + d[2] * s[2]) as isize
    }

    /// [`Mask::mark`] for each of `reads` (from [`Mask::offset_of`])
    /// around `p`; every one must lie inside the box.
    #[inline]
    pub fn mark_around(&self, p: [i64; 3], reads: &[isize]) {
        let base = self.shape.index(p) as isize;
        for &d in reads {
            self.flags[(base + d) as usize].store(true, Ordering::Relaxed);
        }
    }

    /// Recomputes the count after [`Mask::mark`] calls.
    pub fn recount(&mut self) {
        self.count = self
            .flags
            .par_iter()
            .with_min_len(1 << 16)
            .filter(|f| f.load(Ordering::Relaxed))
            .count() as u64;
    }

    /// Shrinks the box to the members' bounding box (no change when
    /// empty), so grids laid over [`Mask::bounds`] hold no dead margin.
    pub fn shrink_to_fit(&mut self) {
        let b = self.shape.bounds;
        let s = b.size();
        let (sx, sy) = (s[0] as usize, s[1] as usize);
        if self.flags.is_empty() {
            return;
        }
        let member = |f: &AtomicBool| f.load(Ordering::Relaxed);
        // Each x row's first and last member, as a box; their union.
        let tight = self
            .flags
            .par_chunks(sx)
            .enumerate()
            .with_min_len(64)
            .filter_map(|(row, flags)| {
                let first = flags.iter().position(member)? as i64;
                let last = flags.iter().rposition(member)? as i64;
                let (y, z) = ((row % sy) as i64, (row / sy) as i64);
                let lo = [b.lo[0] + first, b.lo[1] + y, b.lo[2] + z];
                Some(Box3::new(lo, [last - first + 1, 1, 1]))
            })
            .reduce_with(|a, c| a.union(&c));
        let Some(tight) = tight else {
            return;
        };
        if tight == b {
            return;
        }
        let mut smaller = Mask::new(tight);
        let t = tight.size();
        let (tx, ty) = (t[0] as usize, t[1] as usize);
        smaller
            .flags
            .par_chunks(tx)
            .enumerate()
            .with_min_len(64)
            .for_each(|(row, dst)| {
                let y = tight.lo[1] + (row % ty) as i64;
                let z = tight.lo[2] + (row / ty) as i64;
                let from = self.shape.index([tight.lo[0], y, z]);
                for (d, f) in dst.iter().zip(&self.flags[from..from + tx]) {
                    d.store(member(f), Ordering::Relaxed);
                }
            });
        smaller.count = self.count;
        *self = smaller;
    }

    /// Number of voxels in the set.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// The box the set lives in.
    pub fn bounds(&self) -> Box3 {
        self.shape.bounds
    }

    /// Members in x-fastest order.
    pub fn positions(&self) -> impl Iterator<Item = [i64; 3]> + '_ {
        let b = self.shape.bounds;
        (b.lo[2]..b.hi[2]).flat_map(move |z| self.layer(z))
    }

    /// Members of one z layer, x fastest (row by row: positions follow
    /// from the row, with no division per member).
    pub fn layer(&self, z: i64) -> impl Iterator<Item = [i64; 3]> + '_ {
        let b = self.shape.bounds;
        let sx = b.size()[0] as usize;
        (b.lo[1]..b.hi[1]).flat_map(move |y| {
            let start = self.shape.index([b.lo[0], y, z]);
            self.flags[start..start + sx]
                .iter()
                .zip(b.lo[0]..)
                .filter(|(f, _)| f.load(Ordering::Relaxed))
                .map(move |(_, x)| [x, y, z])
        })
    }
}

/// What synthesizing some voxels of one level at their final version
/// requires: the version-0 voxels, and for every subpass in forward order
/// the voxels to correct.
pub struct LevelChain {
    /// Voxels whose version 0 is needed.
    pub need: Mask,
    /// Per subpass (all steps, forward order): its step index and the voxels
    /// it corrects.
    pub subpasses: Vec<(usize, Vec<[i64; 3]>)>,
}

impl LevelChain {
    /// Total corrections.
    pub fn corrections(&self) -> u64 {
        self.subpasses.iter().map(|s| s.1.len() as u64).sum()
    }
}

/// Walks the correction steps of one level's `schedule` backwards from
/// `targets` (voxels needed at the final version), following each
/// correction's [history window](super::history): a neighbour is needed at
/// the previous subpass's version, or, across the wall of the step's cell
/// of the dual grid, at the version the step started from (Zhang et al.'s
/// barrier). `cube`: corrections read the whole cube around them (see
/// [`shape`]).
///
/// A voxel's correction in a pass produces its value at the end of that
/// pass (its final value in the last pass), so `known_after(pass, subpass,
/// voxels)` (the pass counted over all steps, the subpass's index in
/// forward order) may take out of `voxels` those whose value after the pass
/// is known and return them: they are not corrected (their chain stops),
/// and the synthesis writes that value into place right after the subpass,
/// which is when a correction would have put it there. This also covers
/// the values at a step boundary: every voxel needed there is corrected in
/// the earlier step's last pass.
pub fn backward(
    targets: &[[i64; 3]],
    schedule: &LevelSchedule,
    cube: bool,
    known_after: impl FnMut(usize, usize, &mut Vec<[i64; 3]>) -> Vec<[i64; 3]>,
) -> LevelChain {
    let s = schedule;
    walk_back(
        targets,
        &s.steps,
        s.radius,
        cube,
        s.classes,
        &s.window,
        known_after,
    )
}

/// [`backward`] over the parts of a schedule.
fn walk_back(
    targets: &[[i64; 3]],
    steps: &[Step],
    radius: i64,
    cube: bool,
    order: Classes,
    window: &HistoryWindow,
    mut known_after: impl FnMut(usize, usize, &mut Vec<[i64; 3]>) -> Vec<[i64; 3]>,
) -> LevelChain {
    let classes = order.count();
    let first = targets.first().copied().unwrap_or([0; 3]);
    let bounds = targets.iter().fold(Box3::new(first, [1, 1, 1]), |b, p| {
        b.union(&Box3::new(*p, [1, 1, 1]))
    });
    let growth: i64 = steps
        .iter()
        .map(|s| s.passes as i64 * classes * radius)
        .sum();
    let mut need = Mask::new(bounds.dilate(growth + radius));
    for p in targets {
        need.insert(*p);
    }
    let mut subpasses = Vec::new();
    let total: i64 = steps.iter().map(|s| s.passes as i64 * classes).sum();
    let mut forward_end = total;
    // What a correction reads, as index offsets in `need` (whose box
    // never changes during the walk).
    let mut reads = Vec::new();
    shape([0; 3], radius, cube, |d| reads.push(need.offset_of(d)));
    for (si, step) in steps.iter().enumerate().rev() {
        let mut start = Mask::new(need.bounds());
        let step_subpasses = step.passes as i64 * classes;
        let first_of_step = forward_end - step_subpasses;
        for t in (0..step_subpasses).rev() {
            let class = t % classes;
            let mut corrected = order.members_in_columns(&need, class, radius);
            let forward = first_of_step + t;
            let pass = (forward / classes) as usize;
            // The count is refreshed when the step's walk ends.
            for q in known_after(pass, forward as usize, &mut corrected) {
                need.unmark(q);
            }
            // The voxels of one subpass are independent: they mark their
            // reads in parallel. A voxel whose reads all lie inside its
            // barrier cell (most of them) marks them by index offsets.
            corrected.par_iter().with_min_len(1024).for_each(|&v| {
                match window.latest_within(v, step.offset) {
                    None => need.mark_around(v, &reads),
                    Some(cell_box) => {
                        let (lo, hi) = (cell_box.lo, cell_box.hi);
                        if (0..3).all(|a| v[a] - radius >= lo[a] && v[a] + radius < hi[a]) {
                            need.mark_around(v, &reads);
                            return;
                        }
                        shape(v, radius, cube, |q| {
                            if cell_box.contains(q) {
                                need.mark(q);
                            } else {
                                start.mark(q);
                            }
                        });
                    }
                }
            });
            subpasses.push((si, corrected));
        }
        need.recount();
        start.recount();
        let extra: Vec<[i64; 3]> = start.positions().collect();
        for q in extra {
            need.insert(q);
        }
        forward_end = first_of_step;
    }
    subpasses.reverse();
    // The box was sized for the worst-case growth; the working grids of
    // the synthesis follow it, so keep only what the chain touches.
    need.shrink_to_fit();
    LevelChain { need, subpasses }
}

/// Exact voxel-level dependency sets of a request (Dong et al.'s
/// "Mask ⊗ Neighborhood" chain, with Zhang et al.'s history windows),
/// level by level from the finest: for each level, the version-0 voxels and
/// the corrections needed, under `schedules[k]` for the k-th level from the
/// request's.
pub fn exact_chain(
    request: &[[i64; 3]],
    schedules: &[LevelSchedule],
    cube: bool,
) -> Vec<LevelPlan> {
    let mut points: Vec<[i64; 3]> = request.to_vec();
    let mut out = Vec::new();
    for schedule in schedules {
        if points.is_empty() {
            break;
        }
        let chain = backward(&points, schedule, cube, |_, _, _| Vec::new());
        out.push(LevelPlan {
            voxels: chain.need.count(),
            corrections: chain.corrections(),
        });
        let mut parents: Vec<[i64; 3]> = chain
            .need
            .positions()
            .map(|p| p.map(|v| v.div_euclid(2)))
            .collect();
        parents.sort_unstable();
        parents.dedup();
        points = parents;
    }
    out
}

/// How far the dependency chain of one level reaches from the voxels it
/// starts from: every voxel it needs lies within `lo` below and `hi` above
/// some starting voxel, per axis.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Reach {
    /// Voxels below, per axis.
    pub lo: [i64; 3],
    /// Voxels above, per axis.
    pub hi: [i64; 3],
}

/// Most voxels the walks of [`reach`] may cover before it settles for the
/// looser bound that needs no walk.
const REACH_WALK_VOXELS: i64 = 1 << 25;

/// The [`Reach`] of one level corrected by `steps` (see [`backward`]).
///
/// The chains are periodic (the subpass classes repeat every period of
/// `order`, the cells every `cell`), so the largest reach below and above
/// along axis `a` is found by walking back from one layer `a = c` of a
/// period in the other two axes, for every `c` in a period: the need of a
/// layer is the union of its voxels' needs. Where those walks would be
/// large (long periods, many passes) the bound is taken from the scheme
/// instead: a subpass reads `radius` further, and under the dual grid a
/// step's chain stays within its cell and a ring of `radius` around it.
pub fn reach(steps: &[Step], radius: i64, order: Classes, cell: Option<i64>) -> Reach {
    if steps.is_empty() {
        return Reach::default();
    }
    let classes = order.count();
    let growth: i64 = steps
        .iter()
        .map(|s| s.passes as i64 * classes * radius + radius)
        .sum();
    let side = order.period();
    let period = cell.map_or(side, |m| lcm(side, m));
    let walk = period + 2 * growth;
    if 3 * period * walk * walk * (1 + 2 * growth) > REACH_WALK_VOXELS {
        let r: i64 = steps
            .iter()
            .map(|s| {
                let chain = s.passes as i64 * classes * radius;
                cell.map_or(chain, |m| chain.min(m - 1)) + radius
            })
            .sum();
        return Reach {
            lo: [r; 3],
            hi: [r; 3],
        };
    }
    let mut out = Reach::default();
    for a in 0..3 {
        let (b, c) = ((a + 1) % 3, (a + 2) % 3);
        for at in 0..period {
            let mut layer = Vec::with_capacity((period * period) as usize);
            for j in 0..period {
                for i in 0..period {
                    let mut p = [0i64; 3];
                    p[a] = at;
                    p[b] = i;
                    p[c] = j;
                    layer.push(p);
                }
            }
            // The cube reads no further along an axis than the planes.
            let window = HistoryWindow::of(cell.map(|m| [Intervals::Uniform(m); 3]));
            let need = walk_back(&layer, steps, radius, false, order, &window, |_, _, _| {
                Vec::new()
            })
            .need
            .bounds();
            out.lo[a] = out.lo[a].max(at - need.lo[a]);
            out.hi[a] = out.hi[a].max(need.hi[a] - 1 - at);
        }
    }
    out
}

fn lcm(a: i64, b: i64) -> i64 {
    let gcd = |mut x: i64, mut y: i64| {
        while y != 0 {
            (x, y) = (y, x % y);
        }
        x
    };
    a / gcd(a, b) * b
}

/// Order of the 2³ subpasses when corrections read only their direct
/// neighbours, as phases x + 2y + 4z: each z layer of the 2×2×2 block in
/// Gray-code order (000, 100, 110, 010, then 101, 001, 011, 111). Within a
/// pass a chain can only step to an earlier subpass, so the order sets how
/// far chains grow along each axis; this one measured the least work of
/// all orders tried: 128² axis slices (z, x, y) 0.24 / 0.38 / 0.40 M
/// corrections against 0.27 / 0.59 / 0.44 M in lexicographic order, and a
/// 32³ region 0.16 M against 0.20 M. With radius 2 the lexicographic order
/// is the cheaper one (a 32³ region 0.53 M against 0.76 M), so it stays.
const DIRECT_NEIGHBOUR_ORDER: [i64; 8] = [0, 1, 3, 2, 5, 4, 6, 7];

/// Phase of subpass `class` (voxels whose coordinates are congruent to it
/// modulo `side` are corrected together) for reads `radius` voxels away.
fn subpass_phase(class: i64, side: i64, radius: i64) -> [i64; 3] {
    if side == 2 && radius == 1 {
        let c = DIRECT_NEIGHBOUR_ORDER[class as usize];
        return [c & 1, (c >> 1) & 1, c >> 2];
    }
    [class % side, (class / side) % side, class / (side * side)]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A layer's members and all members come x fastest, as a scan of
    /// every voxel in index order finds them.
    #[test]
    fn layers_and_positions_list_the_members_in_order() {
        let b = Box3::new([-4, 2, -3], [9, 5, 4]);
        let mut m = Mask::new(b);
        for i in 0..b.volume() as i64 {
            if i.wrapping_mul(2_654_435_761) % 7 < 3 {
                m.insert(m.shape.position(i as usize));
            }
        }
        let scan = |z: Option<i64>| -> Vec<[i64; 3]> {
            (0..m.flags.len())
                .map(|i| m.shape.position(i))
                .filter(|p| m.contains(*p) && z.is_none_or(|z| p[2] == z))
                .collect()
        };
        for z in b.lo[2]..b.hi[2] {
            assert_eq!(m.layer(z).collect::<Vec<_>>(), scan(Some(z)), "layer {z}");
        }
        assert_eq!(m.positions().collect::<Vec<_>>(), scan(None));
        assert_eq!(m.positions().count() as u64, m.count());
    }

    /// Marking by index offsets marks what marking each read does.
    #[test]
    fn marking_around_a_voxel_marks_its_reads() {
        for (radius, cube) in [(1, false), (1, true), (2, false)] {
            let b = Box3::new([-5, -6, -4], [11, 12, 9]);
            let (mut by_offsets, mut one_by_one) = (Mask::new(b), Mask::new(b));
            let mut reads = Vec::new();
            shape([0; 3], radius, cube, |d| {
                reads.push(by_offsets.offset_of(d))
            });
            for v in [[0, 0, 0], [-2, 3, 1], [3, -3, -1]] {
                by_offsets.mark_around(v, &reads);
                shape(v, radius, cube, |q| one_by_one.mark(q));
            }
            by_offsets.recount();
            one_by_one.recount();
            assert_eq!(
                by_offsets.positions().collect::<Vec<_>>(),
                one_by_one.positions().collect::<Vec<_>>()
            );
            assert!(by_offsets.count() > 0);
        }
    }

    #[test]
    fn shrinking_keeps_the_members_in_a_tight_box() {
        let mut m = Mask::new(Box3::new([-10, -10, -10], [30, 30, 30]));
        for p in [[-3, 2, 5], [4, -1, 5], [0, 0, 7]] {
            m.insert(p);
        }
        m.shrink_to_fit();
        assert_eq!(m.bounds(), Box3::new([-3, -1, 5], [8, 4, 3]));
        let mut got: Vec<[i64; 3]> = m.positions().collect();
        got.sort();
        assert_eq!(got, vec![[-3, 2, 5], [0, 0, 7], [4, -1, 5]]);
        assert_eq!(m.count(), 3);
        let mut empty = Mask::new(Box3::new([0, 0, 0], [4, 4, 4]));
        empty.shrink_to_fit();
        assert_eq!(empty.bounds(), Box3::new([0, 0, 0], [4, 4, 4]));
    }

    #[test]
    fn shape_has_sixty_one_voxels_for_n5() {
        let mut s = std::collections::HashSet::new();
        shape([0, 0, 0], 2, false, |q| {
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
        let blocks = |s: Vec<Vec<Step>>, cells| -> Vec<_> {
            s.into_iter()
                .map(|steps| {
                    LevelSchedule::new(steps, Classes::Blocks(2), HistoryWindow::of(cells), 2)
                })
                .collect()
        };
        let twelve = Some([Intervals::Uniform(12); 3]);
        let dual = exact_chain(&[[5, 5, 5]], &blocks(steps, twelve), false);
        let standard = exact_chain(&[[5, 5, 5]], &blocks(standard_steps, None), false);
        let total = |v: &[LevelPlan]| v.iter().map(|l| l.voxels).sum::<u64>();
        assert!(total(&dual) < total(&standard), "{dual:?} vs {standard:?}");
    }

    #[test]
    fn reach_bounds_every_voxel_chain_and_is_met() {
        let one = |passes| Step { offset: 0, passes };
        let dual = vec![
            one(1),
            Step {
                offset: 3,
                passes: 1,
            },
        ];
        let blocks = Classes::Blocks(2);
        for (steps, radius, order, cell) in [
            (vec![one(1)], 1, blocks, None),
            (vec![one(2)], 1, blocks, None),
            (dual.clone(), 1, blocks, Some(6)),
            (dual.clone(), 2, blocks, Some(6)),
            (vec![one(1)], 1, Classes::Parity, None),
            (vec![one(2)], 1, Classes::Parity, None),
            (dual, 1, Classes::Parity, Some(6)),
        ] {
            let r = reach(&steps, radius, order, cell);
            let period = cell.map_or(order.period(), |m| lcm(order.period(), m));
            let mut met = Reach::default();
            for z in 0..period {
                for y in 0..period {
                    for x in 0..period {
                        let p = [x, y, z];
                        let cells = cell.map(|m| [Intervals::Uniform(m); 3]);
                        let schedule = LevelSchedule {
                            steps: steps.clone(),
                            classes: order,
                            window: HistoryWindow::of(cells),
                            radius,
                            reach: r,
                        };
                        let b = backward(&[p], &schedule, false, |_, _, _| Vec::new())
                            .need
                            .bounds();
                        for (a, c) in p.into_iter().enumerate() {
                            met.lo[a] = met.lo[a].max(c - b.lo[a]);
                            met.hi[a] = met.hi[a].max(b.hi[a] - 1 - c);
                        }
                    }
                }
            }
            assert_eq!(r, met, "{steps:?} radius {radius} cell {cell:?}");
        }
        assert_eq!(reach(&[], 1, blocks, Some(12)), Reach::default());
    }

    #[test]
    fn parity_subpasses_split_a_box_by_coordinate_sum() {
        let b = Box3::new([-3, 2, -1], [5, 4, 3]);
        let mut seen = std::collections::HashSet::new();
        for class in 0..Classes::Parity.count() {
            Classes::Parity.for_class(&b, class, 1, |v| {
                assert_eq!((v[0] + v[1] + v[2]).rem_euclid(2), class, "{v:?}");
                assert!(b.contains(v), "{v:?}");
                assert!(seen.insert(v), "{v:?} twice");
            });
        }
        assert_eq!(seen.len() as u64, b.volume());
    }

    #[test]
    fn every_subpass_order_visits_each_phase_once() {
        for (side, radius) in [(1, 1), (2, 1), (2, 2), (3, 1), (3, 2)] {
            let mut phases: Vec<[i64; 3]> = (0..side * side * side)
                .map(|c| subpass_phase(c, side, radius))
                .collect();
            assert!(phases.iter().flatten().all(|&p| (0..side).contains(&p)));
            phases.sort();
            phases.dedup();
            assert_eq!(phases.len() as i64, side * side * side, "side {side}");
        }
    }
}
