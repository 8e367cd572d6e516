//! Version 0 of a level: the reference's block of triples tiled over space
//! at a level that starts from one, else at the coarsest synthesized level
//! the candidate slab tiled over space and warped by the jitter field; at
//! finer levels, the parent's triples upsampled.

use crate::analysis::stack::spacing;
use crate::candidates::Candidates;
use crate::candidates::geometry::offset_triple;
use crate::field::{FrameField, round, world};
use crate::hash::{hash_pos, mix, unit as unit_f};
use crate::params::SlabTiling;
use crate::period::Intervals;

const TAG_SLAB: u32 = 1;
const TAG_JITTER: u32 = 2;
const TAG_CELL: u32 = 3;
const TAG_BLOCK: u32 = 4;

/// Gaussians per jitter cell; cells are a quarter of the exemplar period,
/// so the density matches the slides' G = 200 per exemplar-sized volume.
const GAUSSIANS_PER_CELL: u64 = 3;

/// The candidate slab (Dong et al.): every xy pixel's first candidate,
/// thickened along z by its own neighbourhoods, `thickness` voxels thick
/// (Dong et al.: N). It is tiled over space in pieces about half an exemplar
/// period wide and one layer thick, each shifted by a hashed offset, so the
/// initialisation has no period at all; the seams between pieces are what
/// the correction then repairs (Zhang et al.'s subpart initialisation,
/// §4.1). The pieces are `tiling`'s: the correction mends a seam only
/// locally, so whatever shape the pieces have stays visible.
pub struct Slab<'a> {
    /// The candidates whose slab is tiled.
    pub cands: &'a Candidates,
    /// The texture's seed.
    pub seed: u64,
    /// Layer thickness (see [`crate::SynthParams::slab_thickness`]).
    pub thickness: u32,
    /// How the slab is cut into pieces.
    pub tiling: SlabTiling,
    /// The texture's field, if any.
    pub field: Option<&'a FrameField>,
    /// The period of a periodic solid at this level.
    pub period: Option<[i64; 3]>,
}

impl Slab<'_> {
    /// Version 0 of the initial level `k` at `p`: the slab, warped by the
    /// jitter.
    /// `sites` remembers the cell sites last looked at: voxels visited in
    /// rows mostly share them.
    pub fn initial_triple(
        &self,
        jitter: &JitterField,
        k: usize,
        p: [i64; 3],
        sites: &mut Sites,
    ) -> [u32; 3] {
        let d = jitter.displacement(p);
        let q = [0, 1, 2].map(|a| p[a] + d[a].round() as i64);
        self.triple(k, q, sites)
    }

    /// The tiled slab's triple at `p` of level `k`.
    fn triple(&self, k: usize, p: [i64; 3], sites: &mut Sites) -> [u32; 3] {
        let (c, seed, tiling) = (self.cands, self.seed, self.tiling);
        let n = self.thickness as i64;
        let r = n / 2;
        let h = spacing(k) as i64;
        let dims = c.dims();
        let side = (period_of(c, k) as i64 / 2).max(4);
        let pieces = [0, 1, 2].map(|a| Intervals::nearest(self.period.map(|q| q[a]), side));
        // The piece that holds `p`, and the point it turns about in a
        // field. In a periodic solid, the piece and `p` are moved together
        // into the piece's copy in the period at the origin: every number
        // below is then the same for p and p + P.
        let (piece, pivot, p) = match tiling {
            SlabTiling::Blocks => {
                let block = [0, 1].map(|a| pieces[a].index_of(p[a]));
                let shift = [
                    pieces[0].copy_of(block[0]) * pieces[0].period(),
                    pieces[1].copy_of(block[1]) * pieces[1].period(),
                    self.period.map_or(0, |q| p[2].div_euclid(q[2]) * q[2]),
                ];
                let p = [0, 1, 2].map(|a| p[a] - shift[a]);
                let centre = [0, 1].map(|a| {
                    let start = pieces[a].start(block[a]) - shift[a];
                    start as f64 + (pieces[a].size(block[a]) as f64 - 1.0) / 2.0
                });
                let block = [0, 1].map(|a| pieces[a].label(block[a]));
                (Piece::Block(block), [centre[0], centre[1], p[2] as f64], p)
            }
            SlabTiling::Cells => {
                let (cube, site) = sites.nearest(seed, k, &pieces, p);
                let shift = [0, 1, 2].map(|a| pieces[a].copy_of(cube[a]) * pieces[a].period());
                let p = [0, 1, 2].map(|a| p[a] - shift[a]);
                let site = [0, 1, 2]
                    .map(|a| (site[a] - shift[a] * SITE_STEPS) as f64 / SITE_STEPS as f64 - 0.5);
                let cube = [0, 1, 2].map(|a| pieces[a].label(cube[a]));
                (Piece::Cell(cube), site, p)
            }
        };
        // In a field, each piece is the slab turned into the local frame at
        // its pivot (Zhang et al. §4.1's T([q⁻¹ v]), piece by piece as their
        // subpart initialisation): one frame for a whole piece keeps the
        // piece undistorted wherever the field bends.
        let p = match self.field {
            None => p,
            Some(f) => {
                let frame = f.frame(world(k, pivot));
                let d = [0, 1, 2].map(|a| p[a] as f64 - pivot[a]);
                [0, 1, 2].map(|a| {
                    let e = frame[a][0] * d[0] + frame[a][1] * d[1] + frame[a][2] * d[2];
                    round(pivot[a] + e)
                })
            }
        };
        let layer = (p[2] + r).div_euclid(n);
        let o = match piece {
            Piece::Block(block) => hash_pos(seed, k as u32, TAG_SLAB, [block[0], block[1], layer]),
            // Cells that share a layer differ in their cube's x, y or z.
            Piece::Cell(cube) => {
                mix(hash_pos(seed, k as u32, TAG_SLAB, [cube[0], cube[1], layer]) ^ cube[2] as u64)
            }
        };
        let dz = (p[2] + r).rem_euclid(n) - r;
        let ox = (o % dims.w as u64) as i64;
        let oy = ((o >> 32) % dims.h as u64) as i64;
        let pixel = dims.index(p[0] * h + ox, p[1] * h + oy);
        let cands = c.level(k).candidates(0);
        let first = cands.triples[cands.range(pixel).start];
        offset_triple(dims, first, [0, 0, dz], h)
    }
}

/// The reference's periodic blocks of triples tiled over space: cells of a
/// jittered grid, each reading the blocks at its own hashed offset, so the
/// initialisation has no period (Zhang et al.'s subpart initialisation,
/// §4.1, with pieces of a solid instead of a slab). No jitter warps them:
/// the block's features are already solid, and a warp would tear the fine
/// ones. The cells and offsets are laid out once for all levels that
/// start from a block, in voxels of the finest of them, so that every
/// level of detail shows the same pieces, each level reading its own
/// block (the reference's coarser version of the finest).
pub struct BlockTiling<'a> {
    /// The candidates whose blocks are tiled.
    pub cands: &'a Candidates,
    /// The texture's seed.
    pub seed: u64,
    /// The texture's field, if any.
    pub field: Option<&'a FrameField>,
    /// The period of a periodic solid at the finest block's level.
    pub period: Option<[i64; 3]>,
}

impl BlockTiling<'_> {
    /// The triple at `p` of level `k`, which has a block.
    pub fn triple(&self, k: usize, p: [i64; 3], sites: &mut Sites) -> [u32; 3] {
        let blocks = self.cands.blocks();
        let finest = &blocks[0];
        let f = finest.level as usize;
        let coarsest = blocks[blocks.len() - 1].level as usize;
        let block = self.cands.block(k).expect("a level with a block");
        // `p` in voxels of the finest block's level: the voxel at the
        // centre of the ones it stands for.
        let up = k - f;
        let centre = ((1i64 << up) - 1) / 2;
        let q = p.map(|v| (v << up) + centre);
        let side = finest.side as i64;
        let cells = [0, 1, 2].map(|a| Intervals::nearest(self.period.map(|per| per[a]), side / 2));
        let (cube, site) = sites.nearest(self.seed, f, &cells, q);
        let shift = [0, 1, 2].map(|a| cells[a].copy_of(cube[a]) * cells[a].period());
        let label = [0, 1, 2].map(|a| cells[a].label(cube[a]));
        // The offset, in whole voxels of the coarsest block so that every
        // level reads the same place of its own block.
        let step = 1i64 << (coarsest - f);
        let o = hash_pos(self.seed, f as u32, TAG_BLOCK, label);
        let off = [o, o >> 21, o >> 42].map(|v| (v % (side / step) as u64) as i64 * step);
        // In a periodic solid, `p` moves into its cell's copy in the period
        // at the origin, where p and p + P read the same voxel.
        let q = [0, 1, 2].map(|a| q[a] - shift[a]);
        // In a field, each cell is the block turned into the local frame at
        // its site, as the slab's pieces are.
        let q = match self.field {
            None => q,
            Some(field) => {
                let pivot = [0, 1, 2]
                    .map(|a| (site[a] - shift[a] * SITE_STEPS) as f64 / SITE_STEPS as f64 - 0.5);
                let frame = field.frame(world(f, pivot));
                let d = [0, 1, 2].map(|a| q[a] as f64 - pivot[a]);
                [0, 1, 2].map(|a| {
                    let e = frame[a][0] * d[0] + frame[a][1] * d[1] + frame[a][2] * d[2];
                    round(pivot[a] + e)
                })
            }
        };
        block.at([0, 1, 2].map(|a| (q[a] + off[a]) >> up))
    }
}

/// A piece of the tiled slab.
enum Piece {
    /// An axis-aligned block, by its x and y index.
    Block([i64; 2]),
    /// A cell, by the cube of its site.
    Cell([i64; 3]),
}

/// Sub-voxel steps of a cell's site: voxel centres lie half a voxel off the
/// sites' grid, so a voxel is almost never equally far from two sites.
const SITE_STEPS: i64 = 256;

/// The sites of the cubes around one cube (see [`Sites::nearest`]).
#[derive(Default)]
pub struct Sites {
    /// The level, cubes and cube they are for.
    key: Option<(usize, [Intervals; 3], [i64; 3])>,
    /// Each cube around it, z outermost, and its site.
    around: [([i64; 3], [i64; 3]); 27],
}

impl Sites {
    /// The cell that holds `p`: its site's cube, and the site in
    /// [`SITE_STEPS`] of a voxel. The cubes (`cubes` along x, y and z)
    /// each own one site at a hashed position inside them, and a voxel
    /// belongs to the nearest site among its own cube's and the 26 around
    /// it (a jittered-grid Voronoi partition, in integers so every machine
    /// draws the same borders). Borders run at every angle, and they are
    /// the same in neighbouring layers, as the blocks' were: a seam
    /// scattered anew in every layer would spoil far more x and y slice
    /// neighbourhoods than one that continues across the layers.
    fn nearest(
        &mut self,
        seed: u64,
        k: usize,
        cubes: &[Intervals; 3],
        p: [i64; 3],
    ) -> ([i64; 3], [i64; 3]) {
        let at = p.map(|v| v * SITE_STEPS + SITE_STEPS / 2);
        let cube = [0, 1, 2].map(|a| cubes[a].index_of(p[a]));
        if self.key != Some((k, *cubes, cube)) {
            let mut n = 0;
            for dz in -1..=1 {
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        let c = [cube[0] + dx, cube[1] + dy, cube[2] + dz];
                        let label = [0, 1, 2].map(|a| cubes[a].label(c[a]));
                        let hs = hash_pos(seed, k as u32, TAG_CELL, label);
                        let hz = mix(hs);
                        let place = |a: usize, h: u64| {
                            let span = cubes[a].size(c[a]) * SITE_STEPS;
                            cubes[a].start(c[a]) * SITE_STEPS + (h % span as u64) as i64
                        };
                        let site = [place(0, hs), place(1, hs >> 32), place(2, hz)];
                        self.around[n] = (c, site);
                        n += 1;
                    }
                }
            }
            self.key = Some((k, *cubes, cube));
        }
        let mut best = (i64::MAX, cube, at);
        for &(c, site) in &self.around {
            let d2: i64 = (0..3).map(|a| (at[a] - site[a]).pow(2)).sum();
            if d2 < best.0 {
                best = (d2, c, site);
            }
        }
        (best.1, best.2)
    }
}

/// The exemplar's period in voxels of level `k`.
fn period_of(c: &Candidates, k: usize) -> f32 {
    let dims = c.dims();
    (dims.w.min(dims.h) as f32 / spacing(k) as f32).max(1.0)
}

#[derive(Clone, Copy)]
struct Bump {
    centre: [f32; 3],
    inv_sigma2: f32,
    reach2: f32,
    push: [f32; 3],
}

/// The jitter deformation (Dong et al.): a sum of Gaussian bumps with hashed
/// centres, directions, amplitudes and widths, defined cell by cell so it
/// exists everywhere without a global list (the slides' G = 200 bumps per
/// exemplar-period cube). Larger amplitudes go with smaller widths, so small
/// scales are disturbed strongly and coarse scales only subtly. A field is
/// built for one box: the bumps of the cells around it are generated once.
/// A periodic solid's field has a whole number of cells per period, hashed
/// by their number within it, and is read at the point moved into the
/// period at the origin; its bumps are generated where they are read.
pub struct JitterField {
    seed: u64,
    strength: f32,
    k: usize,
    /// The exemplar's period at the level.
    unit: f32,
    kind: Cells,
}

enum Cells {
    /// The cells around one box, `cell` voxels wide, and their bumps.
    Table {
        lo: [i64; 3],
        cells: [i64; 3],
        cell: f32,
        bumps: Vec<[Bump; GAUSSIANS_PER_CELL as usize]>,
    },
    /// Cells laid per period, and how many cells around a voxel's own
    /// its bumps may reach from.
    Periodic { cells: [Intervals; 3], around: i64 },
}

/// Most a bump reaches, in exemplar periods (3σ at the widest σ).
const BUMP_REACH: f32 = 0.15;

impl JitterField {
    /// The field over `b` (voxels of level `k`), or over all space in a
    /// solid of period `period` (voxels of level `k`).
    pub fn new(
        c: &Candidates,
        seed: u64,
        strength: f32,
        k: usize,
        b: &super::grid::Box3,
        period: Option<[i64; 3]>,
    ) -> Self {
        let unit = period_of(c, k);
        let cell = (unit / 4.0).max(1.0);
        let mut field = JitterField {
            seed,
            strength,
            k,
            unit,
            kind: Cells::Periodic {
                cells: [Intervals::Uniform(1); 3],
                around: 1,
            },
        };
        if let Some(period) = period {
            let side = (cell.round() as i64).max(1);
            let cells = period.map(|p| Intervals::nearest(Some(p), side));
            let narrowest = cells.iter().map(Intervals::narrowest).min().unwrap_or(1);
            let around = ((BUMP_REACH * unit / narrowest as f32).ceil() as i64).max(1);
            field.kind = Cells::Periodic { cells, around };
            return field;
        }
        let to_cell = |v: i64| (v as f32 / cell).floor() as i64;
        let lo = b.lo.map(|v| to_cell(v) - 1);
        let hi = b.hi.map(|v| to_cell(v - 1) + 1);
        let cells = [0, 1, 2].map(|a| hi[a] - lo[a] + 1);
        let mut bumps = Vec::with_capacity((cells[0] * cells[1] * cells[2]) as usize);
        for cz in lo[2]..=hi[2] {
            for cy in lo[1]..=hi[1] {
                for cx in lo[0]..=hi[0] {
                    let c = [cx, cy, cz];
                    bumps.push(field.bumps(c, |a, h| (c[a] as f32 + h) * cell));
                }
            }
        }
        field.kind = Cells::Table {
            lo,
            cells,
            cell,
            bumps,
        };
        field
    }

    /// The bumps of the cell hashed as `label`, each centred at
    /// `centre(axis, u)` for a hashed u in [0, 1) per axis.
    fn bumps(
        &self,
        label: [i64; 3],
        centre: impl Fn(usize, f32) -> f32,
    ) -> [Bump; GAUSSIANS_PER_CELL as usize] {
        let unit = self.unit;
        std::array::from_fn(|g| {
            let hsh = |i: u64| {
                unit_f(hash_pos(
                    self.seed,
                    self.k as u32,
                    TAG_JITTER + (((g as u64) * 8 + i) << 8) as u32,
                    label,
                ))
            };
            let centre = [centre(0, hsh(0)), centre(1, hsh(1)), centre(2, hsh(2))];
            let t = hsh(3);
            let sigma = (0.01 + 0.04 * t) * unit;
            let amp = (0.3 - 0.2 * t) * unit * self.strength;
            let dir = [hsh(4) * 2.0 - 1.0, hsh(5) * 2.0 - 1.0, hsh(6) * 2.0 - 1.0];
            let len = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
            let push = if len < 1e-3 {
                [0.0; 3]
            } else {
                dir.map(|v| v / len * amp)
            };
            Bump {
                centre,
                inv_sigma2: 1.0 / (sigma * sigma),
                reach2: 9.0 * sigma * sigma,
                push,
            }
        })
    }

    /// Displacement at `p` (inside the field's box), in voxels.
    pub fn displacement(&self, p: [i64; 3]) -> [f32; 3] {
        let mut d = [0f32; 3];
        match &self.kind {
            Cells::Table {
                lo,
                cells,
                cell,
                bumps,
            } => {
                let pc = p.map(|v| (v as f32 / cell).floor() as i64);
                let pf = p.map(|v| v as f32);
                for cz in pc[2] - 1..=pc[2] + 1 {
                    for cy in pc[1] - 1..=pc[1] + 1 {
                        for cx in pc[0] - 1..=pc[0] + 1 {
                            let i =
                                ((cz - lo[2]) * cells[1] + (cy - lo[1])) * cells[0] + (cx - lo[0]);
                            push_by(&mut d, pf, &bumps[i as usize]);
                        }
                    }
                }
            }
            Cells::Periodic { cells, around } => {
                let p = [0, 1, 2].map(|a| p[a].rem_euclid(cells[a].period()));
                let pc = [0, 1, 2].map(|a| cells[a].index_of(p[a]));
                let pf = p.map(|v| v as f32);
                let r = *around;
                for cz in pc[2] - r..=pc[2] + r {
                    for cy in pc[1] - r..=pc[1] + r {
                        for cx in pc[0] - r..=pc[0] + r {
                            let c = [cx, cy, cz];
                            let label = [0, 1, 2].map(|a| cells[a].label(c[a]));
                            let bumps = self.bumps(label, |a, h| {
                                cells[a].start(c[a]) as f32 + h * cells[a].size(c[a]) as f32
                            });
                            push_by(&mut d, pf, &bumps);
                        }
                    }
                }
            }
        }
        d
    }
}

/// Adds the push of each of `bumps` at `pf` to `d`.
#[inline]
fn push_by(d: &mut [f32; 3], pf: [f32; 3], bumps: &[Bump]) {
    for bump in bumps {
        let dist2: f32 = (0..3).map(|a| (pf[a] - bump.centre[a]).powi(2)).sum();
        if dist2 > bump.reach2 {
            continue;
        }
        let w = exp_neg(dist2 * bump.inv_sigma2);
        for (da, pa) in d.iter_mut().zip(bump.push) {
            *da += w * pa;
        }
    }
}

/// Upsampling (Zhang et al. eq. 3–4): a child inherits its parent's triple
/// moved by its offset within the parent, scaled by the child level's
/// spacing.
/// In a field the offset is taken in the parent's local frame (their
/// eq. 3), rounded to exemplar pixels.
#[inline]
pub fn upsample(
    c: &Candidates,
    parent: [u32; 3],
    k: usize,
    p: [i64; 3],
    field: Option<&FrameField>,
) -> [u32; 3] {
    let o = p.map(|v| v.rem_euclid(2));
    match field {
        None => offset_triple(c.dims(), parent, o, spacing(k) as i64),
        Some(f) => {
            let frame = f.frame_at(k + 1, p.map(|v| v.div_euclid(2)));
            let h = spacing(k) as f64;
            let local = [0, 1, 2].map(|a| {
                let e = frame[a][0] * o[0] as f64
                    + frame[a][1] * o[1] as f64
                    + frame[a][2] * o[2] as f64;
                round(e * h)
            });
            offset_triple(c.dims(), parent, local, 1)
        }
    }
}

/// e^(−x) for x ≥ 0 from basic arithmetic only, so every machine computes
/// the same bits (libm's `exp` may differ in the last place between
/// platforms, and a rounded displacement would then differ too).
fn exp_neg(x: f32) -> f32 {
    if x > 80.0 {
        return 0.0;
    }
    // e^(−x) = 2^(−n) · e^(−r) with r = x − n·ln 2 in [0, ln 2).
    let n = (x * std::f32::consts::LOG2_E).floor();
    let r = x - n * std::f32::consts::LN_2;
    // Taylor series of e^(−r) to r¹⁰/10!: truncation below 1e−8 on [0, ln 2).
    let mut term = 1.0f32;
    let mut sum = 1.0f32;
    for i in 1..11 {
        term *= -r / i as f32;
        sum += term;
    }
    let mut scale = 1.0f32;
    for _ in 0..n as u32 {
        scale *= 0.5;
    }
    sum * scale
}

#[cfg(test)]
mod tests {
    use super::{Intervals, Sites, exp_neg};

    /// Sites remembered from the last voxel give the same cell as sites
    /// looked up afresh, wherever the walk goes next (rows, jumps, other
    /// levels and cube sides).
    #[test]
    fn remembered_sites_are_the_sites() {
        let mut kept = Sites::default();
        let walk = (-40..40i64)
            .map(|x| (0, 8, [x, 3, -2]))
            .chain((0..200i64).map(|i| {
                let h = i.wrapping_mul(2_654_435_761);
                (
                    (i % 3) as usize,
                    4 + i % 5,
                    [h % 97 - 48, (h >> 8) % 61 - 30, (h >> 16) % 13 - 6],
                )
            }));
        for (k, side, p) in walk {
            for cubes in [
                [Intervals::Uniform(side); 3],
                [Intervals::nearest(Some(8 * side + 4), side); 3],
            ] {
                assert_eq!(
                    kept.nearest(7, k, &cubes, p),
                    Sites::default().nearest(7, k, &cubes, p),
                    "level {k}, cubes {cubes:?}, voxel {p:?}"
                );
            }
        }
    }

    #[test]
    fn exp_neg_matches_exp() {
        for i in 0..2000 {
            let x = i as f32 * 0.01;
            let want = (-x).exp();
            assert!((exp_neg(x) - want).abs() <= 2e-6 * want, "x = {x}");
        }
    }
}
