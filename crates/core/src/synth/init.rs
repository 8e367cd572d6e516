//! Version 0 of a level: at the coarsest synthesized level, the candidate
//! slab tiled over space and warped by the jitter field; at finer levels,
//! the parent's triples upsampled.

use crate::analysis::stack::spacing;
use crate::candidates::Candidates;
use crate::candidates::geometry::offset_triple;
use crate::field::{FrameField, round, world};
use crate::hash::{hash_pos, mix, unit as unit_f};
use crate::params::SlabTiling;

const TAG_SLAB: u32 = 1;
const TAG_JITTER: u32 = 2;
const TAG_CELL: u32 = 3;

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
        let side = (period(c, k) as i64 / 2).max(4);
        // The piece that holds `p`, and the point it turns about in a field.
        let (piece, pivot) = match tiling {
            SlabTiling::Blocks => {
                let block = [p[0].div_euclid(side), p[1].div_euclid(side)];
                let centre = block.map(|b| (b * side) as f64 + (side as f64 - 1.0) / 2.0);
                (Piece::Block(block), [centre[0], centre[1], p[2] as f64])
            }
            SlabTiling::Cells => {
                let (cube, site) = sites.nearest(seed, k, side, p);
                let site = site.map(|v| v as f64 / SITE_STEPS as f64 - 0.5);
                (Piece::Cell(cube), site)
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
    /// The level, cube side and cube they are for.
    key: Option<(usize, i64, [i64; 3])>,
    /// Each cube around it, z outermost, and its site.
    around: [([i64; 3], [i64; 3]); 27],
}

impl Sites {
    /// The cell that holds `p`: its site's cube, and the site in
    /// [`SITE_STEPS`] of a voxel. Cubes of side `side` each own one site
    /// at a hashed position inside them, and a voxel belongs to the
    /// nearest site among its own cube's and the 26 around it (a
    /// jittered-grid Voronoi partition, in integers so every machine draws
    /// the same borders). Borders run at every angle, and they are the
    /// same in neighbouring layers, as the blocks' were: a seam scattered
    /// anew in every layer would spoil far more x and y slice
    /// neighbourhoods than one that continues across the layers.
    fn nearest(&mut self, seed: u64, k: usize, side: i64, p: [i64; 3]) -> ([i64; 3], [i64; 3]) {
        let span = side * SITE_STEPS;
        let at = p.map(|v| v * SITE_STEPS + SITE_STEPS / 2);
        let cube = at.map(|v| v.div_euclid(span));
        if self.key != Some((k, side, cube)) {
            let mut n = 0;
            for dz in -1..=1 {
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        let c = [cube[0] + dx, cube[1] + dy, cube[2] + dz];
                        let hs = hash_pos(seed, k as u32, TAG_CELL, c);
                        let hz = mix(hs);
                        let site = [
                            c[0] * span + (hs % span as u64) as i64,
                            c[1] * span + ((hs >> 32) % span as u64) as i64,
                            c[2] * span + (hz % span as u64) as i64,
                        ];
                        self.around[n] = (c, site);
                        n += 1;
                    }
                }
            }
            self.key = Some((k, side, cube));
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
fn period(c: &Candidates, k: usize) -> f32 {
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
pub struct JitterField {
    lo: [i64; 3],
    cells: [i64; 3],
    cell: f32,
    bumps: Vec<[Bump; GAUSSIANS_PER_CELL as usize]>,
}

impl JitterField {
    /// The field over `b` (voxels of level `k`).
    pub fn new(c: &Candidates, seed: u64, strength: f32, k: usize, b: &super::grid::Box3) -> Self {
        let unit = period(c, k);
        let cell = (unit / 4.0).max(1.0);
        let to_cell = |v: i64| (v as f32 / cell).floor() as i64;
        let lo = b.lo.map(|v| to_cell(v) - 1);
        let hi = b.hi.map(|v| to_cell(v - 1) + 1);
        let cells = [0, 1, 2].map(|a| hi[a] - lo[a] + 1);
        let mut bumps = Vec::with_capacity((cells[0] * cells[1] * cells[2]) as usize);
        for cz in lo[2]..=hi[2] {
            for cy in lo[1]..=hi[1] {
                for cx in lo[0]..=hi[0] {
                    bumps.push(std::array::from_fn(|g| {
                        let hsh = |i: u64| {
                            unit_f(hash_pos(
                                seed,
                                k as u32,
                                TAG_JITTER + (((g as u64) * 8 + i) << 8) as u32,
                                [cx, cy, cz],
                            ))
                        };
                        let centre = [
                            (cx as f32 + hsh(0)) * cell,
                            (cy as f32 + hsh(1)) * cell,
                            (cz as f32 + hsh(2)) * cell,
                        ];
                        let t = hsh(3);
                        let sigma = (0.01 + 0.04 * t) * unit;
                        let amp = (0.3 - 0.2 * t) * unit * strength;
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
                    }));
                }
            }
        }
        JitterField {
            lo,
            cells,
            cell,
            bumps,
        }
    }

    /// Displacement at `p` (inside the field's box), in voxels.
    pub fn displacement(&self, p: [i64; 3]) -> [f32; 3] {
        let pc = p.map(|v| (v as f32 / self.cell).floor() as i64);
        let pf = p.map(|v| v as f32);
        let mut d = [0f32; 3];
        for cz in pc[2] - 1..=pc[2] + 1 {
            for cy in pc[1] - 1..=pc[1] + 1 {
                for cx in pc[0] - 1..=pc[0] + 1 {
                    let i = ((cz - self.lo[2]) * self.cells[1] + (cy - self.lo[1])) * self.cells[0]
                        + (cx - self.lo[0]);
                    for bump in &self.bumps[i as usize] {
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
            }
        }
        d
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
    use super::{Sites, exp_neg};

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
            assert_eq!(
                kept.nearest(7, k, side, p),
                Sites::default().nearest(7, k, side, p),
                "level {k}, side {side}, voxel {p:?}"
            );
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
