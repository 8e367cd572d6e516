//! Version 0 of a level: at the coarsest synthesized level, the candidate
//! slab tiled over space and warped by the jitter field; at finer levels,
//! the parent's triples upsampled.

use super::hash::{hash_pos, unit};
use crate::candidates::Candidates;
use crate::candidates::geometry::offset_triple;
use crate::stack::spacing;

const TAG_SLAB: u32 = 1;
const TAG_JITTER: u32 = 2;

/// Gaussians per jitter cell; cells are a quarter of the exemplar period,
/// so the density matches the slides' G = 200 per exemplar-sized volume.
const GAUSSIANS_PER_CELL: u64 = 3;

/// The candidate slab (Dong et al.): every xy pixel's first candidate,
/// thickened along z by its own neighbourhoods, N voxels thick. Copies are
/// stacked along z, each copy shifted in xy by a hashed offset so the tiling
/// has no short period along z.
pub fn slab_triple(c: &Candidates, seed: u64, k: usize, p: [i64; 3]) -> [u32; 3] {
    let n = c.params().neighbourhood as i64;
    let r = n / 2;
    let h = spacing(k) as i64;
    let dims = c.dims();
    let block = (p[2] + r).div_euclid(n);
    let dz = (p[2] + r).rem_euclid(n) - r;
    let o = hash_pos(seed, k as u32, TAG_SLAB, [0, 0, block]);
    let ox = (o % dims.w as u64) as i64;
    let oy = ((o >> 32) % dims.h as u64) as i64;
    let pixel = dims.index(p[0] * h + ox, p[1] * h + oy);
    let cands = c.level(k).candidates(0);
    let first = cands.triples[cands.range(pixel).start];
    offset_triple(dims, first, [0, 0, dz], h)
}

/// The jitter deformation (Dong et al.): a sum of Gaussian bumps with hashed
/// centres, directions, amplitudes and widths, defined cell by cell so it
/// exists everywhere without a global list. Returns a displacement in
/// voxels of level `k`. Larger amplitudes go with smaller widths, so small
/// scales are disturbed strongly and coarse scales only subtly.
pub fn jitter(c: &Candidates, seed: u64, strength: f32, k: usize, p: [i64; 3]) -> [f32; 3] {
    if strength == 0.0 {
        return [0.0; 3];
    }
    let dims = c.dims();
    let period = (dims.w.min(dims.h) as f32 / spacing(k) as f32).max(1.0);
    let cell = (period / 4.0).max(1.0);
    let pc = p.map(|v| (v as f32 / cell).floor() as i64);
    let mut d = [0f32; 3];
    for cz in pc[2] - 1..=pc[2] + 1 {
        for cy in pc[1] - 1..=pc[1] + 1 {
            for cx in pc[0] - 1..=pc[0] + 1 {
                for g in 0..GAUSSIANS_PER_CELL {
                    let hsh = |i: u64| {
                        unit(hash_pos(
                            seed,
                            k as u32,
                            TAG_JITTER + ((g * 8 + i) << 8) as u32,
                            [cx, cy, cz],
                        ))
                    };
                    let centre = [
                        (cx as f32 + hsh(0)) * cell,
                        (cy as f32 + hsh(1)) * cell,
                        (cz as f32 + hsh(2)) * cell,
                    ];
                    let t = hsh(3);
                    let sigma = (0.01 + 0.04 * t) * period;
                    let amp = (0.3 - 0.2 * t) * period * strength;
                    let mut dir = [hsh(4) * 2.0 - 1.0, hsh(5) * 2.0 - 1.0, hsh(6) * 2.0 - 1.0];
                    let len = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
                    if len < 1e-3 {
                        continue;
                    }
                    dir = dir.map(|v| v / len);
                    let dist2: f32 = (0..3).map(|a| (p[a] as f32 - centre[a]).powi(2)).sum();
                    let w = (-dist2 / (sigma * sigma)).exp();
                    for a in 0..3 {
                        d[a] += amp * w * dir[a];
                    }
                }
            }
        }
    }
    d
}

/// Version 0 of the initial level at `p`: the slab, warped by the jitter.
pub fn initial_triple(c: &Candidates, seed: u64, strength: f32, k: usize, p: [i64; 3]) -> [u32; 3] {
    let d = jitter(c, seed, strength, k, p);
    let q = [0, 1, 2].map(|a| p[a] + d[a].round() as i64);
    slab_triple(c, seed, k, q)
}

/// Upsampling (Zhang et al. eq. 3–4): a child inherits its parent's triple
/// moved by its offset within the parent, scaled by the child level's
/// spacing.
#[inline]
pub fn upsample(c: &Candidates, parent: [u32; 3], k: usize, p: [i64; 3]) -> [u32; 3] {
    let o = p.map(|v| v.rem_euclid(2));
    offset_triple(c.dims(), parent, o, spacing(k) as i64)
}
