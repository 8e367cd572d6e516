//! A cheap upper bound of the voxels a request synthesizes from a cold
//! cache, so that a request too expensive to answer is refused before any
//! work. The exact count ([`super::plan::backward`] level by level, as
//! `Texture::plan` does) costs a large part of the synthesis itself; this
//! follows the same structure with boxes instead of voxels, in time that
//! depends on the number of tile groups, not of voxels.
//!
//! A request's voxels at its own level lie in a *piece*: the lattice points
//! of a zonotope `origin + s·U + t·V + box` (s, t ∈ [0, 1]), where `U`, `V`
//! span an oblique cut (zero for boxes) and `box` is an axis-aligned box.
//! The engine splits the voxels it needs into groups of at most
//! [`super::MAX_GROUP_TILES`] tiles by bounding box and walks each group's
//! chain on its own; the estimate splits pieces the same way. A group's
//! chain needs voxels within the level's [`Reach`] of its targets, so its
//! count is at most the lattice points of the piece grown by the reach,
//! which is at most the volume of that zonotope grown by half a voxel on
//! every side (the unit cubes around the lattice points are disjoint and
//! lie inside it). Their parents one level up lie in the grown piece
//! halved, grown by half a voxel downwards; they are the next level's
//! targets. Sparse requests (a cut whose pixels lie voxels apart) are
//! bounded a second way: each pixel's samples form a cluster whose chain
//! is counted alone, and a group counts the smaller of the two bounds.
//!
//! Where the engine finds a coarser tile already computed for an earlier
//! group it does not compute it again; the estimate counts it again, which
//! keeps it above the engine's count.
//!
//! A surface's voxels (a bake) are no zonotope: bounded piece by piece,
//! the pieces' shared chains would be counted many times over. They are
//! grouped as the engine groups them instead, and each group's chain is
//! counted voxel by voxel as one union per level ([`grouped_union`]).

use super::TILE;
use super::plan::Reach;

/// Voxels of one level lying in a zonotope, in clusters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Piece {
    /// Lowest corner of the box at `s = t = 0`.
    pub origin: [f64; 3],
    /// Step between neighbouring pixels along the cut's rows.
    pub u: [f64; 3],
    /// Pixels along `u` (≥ 1).
    pub nu: u64,
    /// Step between neighbouring pixels along the cut's columns.
    pub v: [f64; 3],
    /// Pixels along `v` (≥ 1).
    pub nv: u64,
    /// Extent of the axis-aligned box added to the plane (≥ 0).
    pub size: [f64; 3],
    /// Voxels per axis of the cluster one pixel needs (`nu·nv` of them).
    pub cluster: [u64; 3],
}

impl Piece {
    /// The voxels of an axis-aligned box of `size` voxels from `origin`.
    pub fn region(origin: [i64; 3], size: [u32; 3]) -> Piece {
        Piece {
            origin: origin.map(|c| c as f64),
            u: [0.0; 3],
            nu: 1,
            v: [0.0; 3],
            nv: 1,
            size: size.map(|s| f64::from(s.max(1) - 1)),
            cluster: size.map(|s| u64::from(s.max(1))),
        }
    }

    /// The voxels a cut samples: pixel (i, j) at `origin + i·u + j·v`
    /// rounded to the nearest voxel, or (`corners`) the eight voxels
    /// around it.
    pub fn cut(
        origin: [f64; 3],
        u: [f64; 3],
        v: [f64; 3],
        width: u32,
        height: u32,
        corners: bool,
    ) -> Piece {
        // Rounding moves a sample by at most half a voxel; the corners lie
        // within one voxel below and above.
        let (below, extent) = if corners { (1.0, 2.0) } else { (0.5, 1.0) };
        Piece {
            origin: origin.map(|c| c - below),
            u,
            nu: u64::from(width.max(1)),
            v,
            nv: u64::from(height.max(1)),
            size: [extent; 3],
            cluster: [if corners { 2 } else { 1 }; 3],
        }
    }

    fn span_u(&self) -> [f64; 3] {
        self.u.map(|c| c * (self.nu - 1) as f64)
    }

    fn span_v(&self) -> [f64; 3] {
        self.v.map(|c| c * (self.nv - 1) as f64)
    }

    /// Tiles of the bounding box of the lattice points inside.
    fn tile_box(&self) -> f64 {
        let (su, sv) = (self.span_u(), self.span_v());
        (0..3)
            .map(|a| {
                let lo = self.origin[a] + su[a].min(0.0) + sv[a].min(0.0);
                let hi = self.origin[a] + su[a].max(0.0) + sv[a].max(0.0) + self.size[a];
                let (first, last) = ((lo - 1e-9).ceil(), (hi + 1e-9).floor());
                let t = TILE as f64;
                ((last / t).floor() - (first / t).floor() + 1.0).max(1.0)
            })
            .product()
    }

    /// Two pieces holding the voxels of this one, cut across the axis along
    /// which its tile box is longest, as the engine cuts a group too large;
    /// `None` when nothing spans that axis.
    fn split(&self) -> Option<(Piece, Piece)> {
        let (su, sv) = (self.span_u(), self.span_v());
        let tiles = |a: usize| (su[a].abs() + sv[a].abs() + self.size[a]) / TILE as f64;
        let a = (0..3).fold(0, |best, a| if tiles(a) > tiles(best) { a } else { best });
        let (du, dv, db) = (su[a].abs(), sv[a].abs(), self.size[a]);
        let (mut first, mut second) = (*self, *self);
        if du >= dv && du >= db && self.nu > 1 {
            first.nu = self.nu.div_ceil(2);
            second.nu = self.nu - first.nu;
            for c in 0..3 {
                second.origin[c] += self.u[c] * first.nu as f64;
            }
        } else if dv >= db && self.nv > 1 {
            first.nv = self.nv.div_ceil(2);
            second.nv = self.nv - first.nv;
            for c in 0..3 {
                second.origin[c] += self.v[c] * first.nv as f64;
            }
        } else if db >= 1.0 {
            // Both halves keep the plane's clusters: a cluster may lie on
            // either side.
            first.size[a] = db / 2.0;
            second.size[a] = db / 2.0;
            second.origin[a] += db / 2.0;
        } else {
            return None;
        }
        Some((first, second))
    }

    /// The piece grown by `r`: where the chain of its voxels lies.
    fn grown(&self, r: &Reach) -> Piece {
        let mut p = *self;
        for a in 0..3 {
            p.origin[a] -= r.lo[a] as f64;
            p.size[a] += (r.lo[a] + r.hi[a]) as f64;
            p.cluster[a] += (r.lo[a] + r.hi[a]) as u64;
        }
        p
    }

    /// The parents (one level coarser) of its voxels.
    fn parents(&self) -> Piece {
        let mut p = *self;
        for a in 0..3 {
            // ⌊q/2⌋ lies in [q/2 − ½, q/2]; a run of n voxels has at most
            // ⌊n/2⌋ + 1 parents.
            p.origin[a] = self.origin[a] / 2.0 - 0.5;
            p.size[a] = self.size[a] / 2.0 + 0.5;
            p.u[a] = self.u[a] / 2.0;
            p.v[a] = self.v[a] / 2.0;
            p.cluster[a] = self.cluster[a] / 2 + 1;
        }
        p
    }

    /// At most how many lattice points lie inside: the smaller of the
    /// zonotope's volume grown by half a voxel and the clusters' voxels.
    fn voxels(&self) -> f64 {
        let (gu, gv) = (self.span_u(), self.span_v());
        let s = self.size.map(|x| x + 1.0);
        let cross = [
            gu[1] * gv[2] - gu[2] * gv[1],
            gu[2] * gv[0] - gu[0] * gv[2],
            gu[0] * gv[1] - gu[1] * gv[0],
        ];
        // The volume of a zonotope is the sum of |det| over every three of
        // its generators: U, V and the box's three edges.
        let mut dense = s[0] * s[1] * s[2];
        for a in 0..3 {
            let (b, c) = ((a + 1) % 3, (a + 2) % 3);
            dense += cross[a].abs() * s[a] + (gu[a].abs() + gv[a].abs()) * s[b] * s[c];
        }
        let clusters = self.nu as f64 * self.nv as f64;
        let sparse = clusters * self.cluster.iter().map(|&c| c as f64).product::<f64>();
        dense.min(sparse).ceil()
    }
}

/// The bound found, per level from the request's own.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct WorkEstimate {
    /// Voxels per level, the request's level first.
    pub per_level: Vec<u64>,
    /// Their sum (saturating).
    pub total: u64,
    /// False when counting stopped early: the total passed the limit, or
    /// the request split into more groups than are worth counting.
    pub complete: bool,
}

/// Most groups counted before the estimate gives up (and reports the
/// request as over any limit).
const MAX_GROUPS: usize = 1 << 18;

/// Bounds the voxels synthesized for `piece` at the level whose reach is
/// `reach[0]` and at every coarser level (`reach[1..]`), when groups hold
/// at most `max_group_tiles` tiles. Counting stops once the total passes
/// `limit`.
pub fn estimate(piece: Piece, reach: &[Reach], max_group_tiles: usize, limit: u64) -> WorkEstimate {
    let mut e = Walk {
        reach,
        max_group_tiles: max_group_tiles as f64,
        limit,
        groups: 0,
        out: WorkEstimate {
            per_level: vec![0; reach.len()],
            total: 0,
            complete: true,
        },
    };
    e.level(piece, 0);
    e.out
}

struct Walk<'a> {
    reach: &'a [Reach],
    max_group_tiles: f64,
    limit: u64,
    groups: usize,
    out: WorkEstimate,
}

impl Walk<'_> {
    fn level(&mut self, piece: Piece, k: usize) {
        let Some(r) = self.reach.get(k) else {
            return;
        };
        let mut todo = vec![piece];
        while let Some(p) = todo.pop() {
            if !self.out.complete {
                return;
            }
            if p.tile_box() > self.max_group_tiles
                && let Some((a, b)) = p.split()
            {
                todo.push(b);
                todo.push(a);
                continue;
            }
            self.groups += 1;
            let need = p.grown(r);
            let n = need.voxels().min(u64::MAX as f64) as u64;
            self.out.per_level[k] = self.out.per_level[k].saturating_add(n);
            self.out.total = self.out.total.saturating_add(n);
            if self.out.total > self.limit || self.groups > MAX_GROUPS {
                self.out.complete = false;
                return;
            }
            self.level(need.parents(), k + 1);
        }
    }
}

/// A close guess, for progress, of the voxels a cold cache synthesizes for
/// the voxels in `masks` (at the level whose reach is `reach[0]`): per
/// level, the union of the voxels within its reach of a voxel needed, then
/// their parents one level up. The pieces of a surface share most of their
/// chains, which the union counts once where [`estimate`]'s bound counts
/// them once per piece, many times over. It is no bound either way: the
/// engine's groups may compute a shared border twice, and the union
/// undercounts the coarsest levels' chains for large requests.
pub fn union(masks: Masks, reach: &[Reach]) -> u64 {
    let mut level = masks;
    let mut total = 0u64;
    for r in reach {
        let need = grown(level, r);
        let count: u64 = need.values().map(|m| u64::from(m.count_ones())).sum();
        total = total.saturating_add(count);
        level = parents(&need);
    }
    total
}

/// An upper bound of the voxels the engine synthesizes for the voxels in
/// `masks` from a cold cache: it splits them into groups of at most
/// `max_group_tiles` tiles as the engine does ([`super::plan::group_cells`])
/// and counts each group's chain through every level as one union, as if
/// no group found anything another computed. Counting stops once the total
/// passes `limit`.
pub fn grouped_union(
    masks: &Masks,
    reach: &[Reach],
    max_group_tiles: usize,
    limit: u64,
) -> WorkEstimate {
    use rayon::prelude::*;
    let cells: Vec<[i64; 3]> = masks.keys().copied().collect();
    let groups = super::plan::group_cells(&cells, max_group_tiles);
    let per_group: Vec<Vec<u64>> = groups
        .par_iter()
        .map(|g| per_level_union(g.iter().map(|c| (*c, masks[c])).collect(), reach))
        .collect();
    let mut out = WorkEstimate {
        per_level: vec![0; reach.len()],
        total: 0,
        complete: true,
    };
    for counts in per_group {
        for (sum, n) in out.per_level.iter_mut().zip(&counts) {
            *sum = sum.saturating_add(*n);
        }
        out.total = out.total.saturating_add(counts.iter().sum());
    }
    if out.total > limit {
        out.complete = false;
    }
    out
}

/// [`union`]'s count, per level.
fn per_level_union(masks: Masks, reach: &[Reach]) -> Vec<u64> {
    let mut level = masks;
    let mut out = Vec::with_capacity(reach.len());
    for r in reach {
        let need = grown(level, r);
        out.push(need.values().map(|m| u64::from(m.count_ones())).sum());
        level = parents(&need);
    }
    out
}

/// Voxels by tile: bit `x + 4y + 16z` of a tile's mask is its voxel at
/// (x, y, z) from the tile's corner.
pub type Masks = rustc_hash::FxHashMap<[i64; 3], u64>;

/// Adds voxel `v` to `masks`.
pub fn add_voxel(masks: &mut Masks, v: [i64; 3]) {
    let (t, bit) = tile_bit(v);
    *masks.entry(t).or_default() |= bit;
}

fn tile_bit(v: [i64; 3]) -> ([i64; 3], u64) {
    let [x, y, z] = v.map(|c| c.rem_euclid(TILE));
    (
        v.map(|c| c.div_euclid(TILE)),
        1 << (x + TILE * y + TILE * TILE * z),
    )
}

/// The bits of a tile's mask whose coordinate along axis `a` is below `n`.
fn below(a: usize, n: i64) -> u64 {
    (0..64)
        .filter(|i| (i / TILE.pow(a as u32)) % TILE < n)
        .fold(0, |m, i| m | 1 << i)
}

/// The voxels within `r` of a voxel of `masks`, grown one axis at a time
/// (a box's dilation is the product of three runs).
fn grown(mut masks: Masks, r: &Reach) -> Masks {
    for a in 0..3 {
        let stride = TILE.pow(a as u32);
        // For a shift by `inner` within a tile: the bits that stay in it.
        let stay: [u64; 4] = [0, 1, 2, 3].map(|inner| below(a, TILE - inner));
        let mut out = Masks::default();
        out.reserve(masks.len() * 2);
        for (t, &m) in &masks {
            for s in -r.lo[a]..=r.hi[a] {
                let (q, inner) = (s.div_euclid(TILE), s.rem_euclid(TILE));
                let kept = (m & stay[inner as usize]) << (inner * stride);
                let over = (m & !stay[inner as usize]) >> ((TILE - inner) * stride);
                for (d, bits) in [(q, kept), (q + 1, over)] {
                    if bits != 0 {
                        let mut n = *t;
                        n[a] += d;
                        *out.entry(n).or_default() |= bits;
                    }
                }
            }
        }
        masks = out;
    }
    masks
}

/// The parents (one level coarser) of the voxels of `masks`.
fn parents(masks: &Masks) -> Masks {
    let mut out = Masks::default();
    for (t, &m) in masks {
        let mut bits = m;
        while bits != 0 {
            let i = i64::from(bits.trailing_zeros());
            bits &= bits - 1;
            let v = [i % TILE, (i / TILE) % TILE, i / (TILE * TILE)];
            let (p, bit) = tile_bit([0, 1, 2].map(|a| (t[a] * TILE + v[a]).div_euclid(2)));
            *out.entry(p).or_default() |= bit;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reach(r: i64) -> Reach {
        Reach {
            lo: [r; 3],
            hi: [r; 3],
        }
    }

    fn voxel_union(voxels: impl IntoIterator<Item = [i64; 3]>, reach: &[Reach]) -> u64 {
        let mut masks = Masks::default();
        voxels.into_iter().for_each(|v| add_voxel(&mut masks, v));
        union(masks, reach)
    }

    #[test]
    fn the_union_counts_shared_boxes_once() {
        // One voxel grown by 2 at its own level, then its parents' box (the
        // grown 5³ from −2 has parents −1..=1) grown by 1.
        assert_eq!(voxel_union([[0; 3]], &[reach(2)]), 125);
        assert_eq!(voxel_union([[0; 3]], &[reach(2), reach(1)]), 125 + 125);
        // Two neighbours share all but a layer of their boxes, across a
        // tile's side and below zero as well as inside one tile.
        for (a, b) in [
            ([1, 1, 1], [2, 1, 1]),
            ([3, 0, 0], [4, 0, 0]),
            ([-1, 5, 9], [0, 5, 9]),
        ] {
            assert_eq!(voxel_union([a, b], &[reach(1)]), 4 * 3 * 3, "{a:?} {b:?}");
        }
        // Far apart, they add up; a repeated voxel counts once.
        assert_eq!(voxel_union([[0; 3], [100, 0, 0]], &[reach(1)]), 2 * 27);
        assert_eq!(voxel_union([[7, 7, 7]; 3], &[reach(0), reach(0)]), 2);
        // Uneven reach: 2 below and 5 above along x only.
        let r = Reach {
            lo: [2, 0, 0],
            hi: [5, 0, 0],
        };
        assert_eq!(voxel_union([[-9, 3, 3]], &[r]), 8);
        // A run of 10 voxels from 1 has parents 0..=5.
        let run = (1..11).map(|x| [x, 0, 0]);
        assert_eq!(voxel_union(run, &[reach(0), reach(0)]), 10 + 6);
    }

    #[test]
    fn a_box_without_reach_counts_its_voxels() {
        let e = estimate(
            Piece::region([3, -2, 7], [5, 6, 7]),
            &[reach(0)],
            4096,
            u64::MAX,
        );
        assert_eq!(e.per_level, [210]);
        // Grown by one on every side.
        let e = estimate(
            Piece::region([0; 3], [5, 6, 7]),
            &[reach(1)],
            4096,
            u64::MAX,
        );
        assert_eq!(e.per_level, [7 * 8 * 9]);
        assert!(e.complete);
    }

    #[test]
    fn parents_cover_the_children() {
        // 10 voxels from 1 have parents 0..=5 (6 of them).
        let p = Piece::region([1, 1, 1], [10, 1, 1]).parents();
        assert!(p.origin[0] <= 0.0 && p.origin[0] + p.size[0] >= 5.0);
        assert!(p.cluster[0] >= 6);
        let e = estimate(
            Piece::region([1, 1, 1], [10, 1, 1]),
            &[reach(0); 2],
            4096,
            u64::MAX,
        );
        assert!(e.per_level[1] >= 6, "{e:?}");
    }

    #[test]
    fn an_axis_cut_counts_like_its_slice() {
        let slice = estimate(
            Piece::region([0; 3], [64, 64, 1]),
            &[reach(1)],
            4096,
            u64::MAX,
        );
        let cut = Piece::cut([0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 64, 64, false);
        let cut = estimate(cut, &[reach(1)], 4096, u64::MAX);
        assert_eq!(slice.total, 66 * 66 * 3);
        // Rounding adds at most a voxel's slack per axis.
        assert!(
            cut.total >= slice.total && cut.total <= 67 * 67 * 4,
            "{cut:?}"
        );
    }

    #[test]
    fn sparse_pixels_are_counted_per_pixel() {
        // Pixels 1000 voxels apart: each needs its own 3³ voxels, not the
        // plane between them.
        let cut = Piece::cut(
            [0.0; 3],
            [1000.0, 0.0, 0.0],
            [0.0, 1000.0, 0.0],
            8,
            8,
            false,
        );
        let e = estimate(cut, &[reach(1)], 4096, u64::MAX);
        assert_eq!(e.total, 64 * 27);
    }

    #[test]
    fn large_requests_split_into_groups_and_stop_past_the_limit() {
        let one = estimate(
            Piece::region([0; 3], [64, 64, 4]),
            &[reach(2)],
            4096,
            u64::MAX,
        );
        let split = estimate(
            Piece::region([0; 3], [64, 64, 4]),
            &[reach(2)],
            64,
            u64::MAX,
        );
        // Each group grows on its own.
        assert!(split.total > one.total, "{split:?} vs {one:?}");
        let stopped = estimate(Piece::region([0; 3], [64, 64, 4]), &[reach(2)], 64, 1000);
        assert!(!stopped.complete && stopped.total > 1000);
    }
}
