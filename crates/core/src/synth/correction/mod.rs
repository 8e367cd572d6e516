//! Correction (Dong et al. "Correction", Zhang et al. §4.3): a voxel's
//! triple is replaced by the candidate whose neighbourhoods in its three
//! planes best match the voxel's. The neighbourhoods are sparse
//! appearance-space ones (see [`matching`] for the query and the match,
//! [`tables`] for the candidates' side): a correction reads only its
//! direct neighbours, so the dependency radius is 1.
//!
//! A coherent triple continues its neighbour's exemplar patches in all
//! three planes, but nothing makes its three exemplar colours agree: along
//! z a voxel's xy coordinate never changes, so a vein of the xy exemplar
//! that the yz and zx exemplars do not share is extruded into a straight
//! streak across x and y slices. Coherent triples therefore pay for the
//! disagreement of their three colours ([`SynthParams::consistency`]); the
//! precomputed 3D candidates agree by construction (low crossbar error).

use super::colour::colour;
use super::grid::{Box3, Grid};
use crate::candidates::Candidates;
use crate::candidates::geometry::{AXES, Dims, offset_triple};
use crate::field::{Frame, FrameField, round};
use crate::params::SynthParams;
use crate::simd::prefetch;
use matching::AppearanceCorrector;
use rayon::prelude::*;

/// Triples and colours of a working box; colours are kept in step with
/// triples so neighbourhood gathering reads one array.
#[derive(Clone)]
pub struct Work {
    /// Triples.
    pub triples: Grid<[u32; 3]>,
    /// Mean exemplar colour of each triple.
    pub colours: Grid<[f32; 3]>,
}

impl Work {
    /// Wraps triples and computes their colours.
    pub fn new(c: &Candidates, k: usize, triples: Grid<[u32; 3]>) -> Work {
        let mut colours = Grid::new(triples.bounds);
        colours
            .data
            .par_iter_mut()
            .zip(&triples.data)
            .with_min_len(4096)
            .for_each(|(dst, t)| *dst = colour(c, k, *t));
        Work { triples, colours }
    }
}

/// The correction of one level, as the texture's parameters choose it.
pub enum Corrector<'a> {
    /// Sparse appearance-space neighbourhoods.
    Appearance(Box<AppearanceCorrector<'a>>),
    /// Sparse appearance-space neighbourhoods in each voxel's local frame:
    /// the field, and the neighbourhood once for all voxels when the field
    /// is the same everywhere.
    Field(
        Box<AppearanceCorrector<'a>>,
        &'a FrameField,
        Option<Box<Local>>,
    ),
}

impl<'a> Corrector<'a> {
    /// The corrector of level `k`, in the frames of `field` if there is one.
    pub fn new(
        cands: &'a Candidates,
        k: usize,
        params: &SynthParams,
        field: Option<&'a FrameField>,
    ) -> Self {
        let c = AppearanceCorrector::new(cands, k, params);
        match field {
            None => Corrector::Appearance(Box::new(c)),
            Some(f) => {
                let constant = f
                    .constant()
                    .map(|frame| Box::new(Local::new(frame, c.spacing())));
                Corrector::Field(Box::new(c), f, constant)
            }
        }
    }

    /// The best candidate triple for the voxel at `p`. Its history window
    /// decides which version of each neighbour it reads: the latest (`work`)
    /// inside `barrier`'s cell, the step's starting version (`barrier`'s
    /// work) outside it; without a barrier, always the latest.
    #[inline]
    pub fn correct(&self, work: &Work, barrier: Option<(&Work, &Box3)>, p: [i64; 3]) -> [u32; 3] {
        // Offsets along each axis that stay inside the barrier cell (every
        // offset when there is none); `start` has the same layout as `work`.
        let (start, inside) = match barrier {
            Some((start, cell)) => (
                start,
                [0, 1, 2].map(|a| (cell.lo[a] - p[a], cell.hi[a] - 1 - p[a])),
            ),
            None => (work, [(i64::MIN, i64::MAX); 3]),
        };
        // Most voxels read no neighbour across the cell wall: their copy of
        // the correction has no version choices to make.
        if inside.iter().all(|&(lo, hi)| lo <= -REACH && hi >= REACH) {
            self.correct_with::<false>(work, start, inside, p)
        } else {
            self.correct_with::<true>(work, start, inside, p)
        }
    }

    /// [`Corrector::correct`] with the history window resolved:
    /// `BY_WALL` says whether some neighbours lie outside the barrier cell
    /// (`inside` bounds the offsets that do not).
    #[inline(always)]
    fn correct_with<const BY_WALL: bool>(
        &self,
        work: &Work,
        start: &Work,
        inside: [(i64, i64); 3],
        p: [i64; 3],
    ) -> [u32; 3] {
        match self {
            Corrector::Appearance(c) => c.correct_with::<BY_WALL>(work, start, inside, p),
            Corrector::Field(c, _, Some(local)) => {
                c.correct_local_with::<BY_WALL>(work, start, inside, p, local)
            }
            Corrector::Field(c, field, None) => {
                let local = Local::new(&field.frame_at(c.level_index(), p), c.spacing());
                c.correct_local_with::<BY_WALL>(work, start, inside, p, &local)
            }
        }
    }
}

/// The direct neighbours a sparse correction reads: offsets in {-1, 0, 1}³
/// with at least one zero coordinate (the union of the three in-plane 3×3
/// windows), z outermost. The correction reads them written out
/// ([`for_each_direct`]); the tests check that list against this one.
#[cfg(test)]
const DIRECT: [[i64; 3]; 19] = {
    let mut out = [[0i64; 3]; 19];
    let mut n = 0;
    let mut k = 0;
    while k < 27 {
        let d = [
            (k % 3) as i64 - 1,
            ((k / 3) % 3) as i64 - 1,
            (k / 9) as i64 - 1,
        ];
        if d[0] == 0 || d[1] == 0 || d[2] == 0 {
            out[n] = d;
            n += 1;
        }
        k += 1;
    }
    out
};

/// Calls `$m!(x, y, z)` for each offset of [`DIRECT`], in its order.
macro_rules! for_each_direct {
    ($m:ident) => {
        $m!(0, -1, -1);
        $m!(-1, 0, -1);
        $m!(0, 0, -1);
        $m!(1, 0, -1);
        $m!(0, 1, -1);
        $m!(-1, -1, 0);
        $m!(0, -1, 0);
        $m!(1, -1, 0);
        $m!(-1, 0, 0);
        $m!(0, 0, 0);
        $m!(1, 0, 0);
        $m!(-1, 1, 0);
        $m!(0, 1, 0);
        $m!(1, 1, 0);
        $m!(0, -1, 1);
        $m!(-1, 0, 1);
        $m!(0, 0, 1);
        $m!(1, 0, 1);
        $m!(0, 1, 1);
    };
}

// After `for_each_direct`, which it uses.
mod matching;
pub mod tables;

/// How far along x [`gather_near`] prefetches, in voxels.
const AHEAD: i64 = 16;

/// Fills `near` with the direct neighbours of `p`, each in the version its
/// history window gives (`work` for offsets within `inside`, `start`
/// beyond), and the coherent triples: each neighbour's triple moved back
/// by its offset, in all three planes at once. Both by [`near_slot`].
/// (Filled in place: returned, the table was copied out.)
#[inline(always)]
fn gather_near<const BY_WALL: bool>(
    work: &Work,
    start: &Work,
    inside: [(i64, i64); 3],
    p: [i64; 3],
    dims: Dims,
    h: i64,
    near: &mut Near,
) {
    let strides = work.triples.strides();
    let centre = work.triples.index(p) as i64;
    let inside3 =
        |d: [i64; 3]| !BY_WALL || (0..3).all(|a| d[a] >= inside[a].0 && d[a] <= inside[a].1);
    // Corrections walk along x: fetch the neighbour rows a few voxels
    // ahead, so the next corrections find them in cache.
    for dz in -1..=1 {
        for dy in -1..=1 {
            let ahead = centre + AHEAD + dy * strides[1] + dz * strides[2];
            if let Ok(ahead) = usize::try_from(ahead)
                && ahead < work.triples.data.len()
            {
                prefetch(&work.triples.data[ahead..]);
                prefetch(&work.colours.data[ahead..]);
            }
        }
    }
    // Written out per offset: with `d` a constant, the slot, the history
    // test and which moves are zero are settled when compiling.
    macro_rules! one {
        ($x:literal, $y:literal, $z:literal) => {{
            let d: [i64; 3] = [$x, $y, $z];
            let k = near_slot(d);
            let idx = (centre + d[0] * strides[0] + d[1] * strides[1] + d[2] * strides[2]) as usize;
            let src = if inside3(d) { work } else { start };
            near.triples[k] = src.triples.data[idx];
            let [r, g, b] = src.colours.data[idx];
            near.colours[k] = [r, g, b, 0.0];
            near.moved[k] = offset_triple(dims, near.triples[k], [-$x, -$y, -$z], h);
        }};
    }
    for_each_direct!(one);
}

/// A voxel's neighbourhood in its local frame (Zhang et al. §4.3): which
/// world neighbour stands at each in-plane offset of each local plane, and
/// where each world neighbour lies in local coordinates. The neighbours
/// are the nearest voxels to the rotated offsets; a rotated offset of at
/// most √2 rounds into {−1, 0, 1}³, so the reads stay within radius 1,
/// corners included.
pub struct Local {
    /// Per plane, per in-plane offset (i, j) at `3 (j + 1) + i + 1`, the
    /// [`near_slot`] of the world neighbour there.
    slot: [[u8; 9]; 3],
    /// Per [`near_slot`], the world offset in local coordinates times the
    /// level's spacing, rounded: exemplar pixels to move by.
    offset: [[i64; 3]; 27],
    /// The distinct slots of `slot`, ascending: the neighbours a
    /// correction reads, first `used_n` of them.
    used: [u8; 27],
    used_n: usize,
}

impl Local {
    /// The neighbours a correction in this frame reads, by [`near_slot`].
    #[inline(always)]
    fn used(&self) -> &[u8] {
        &self.used[..self.used_n]
    }

    /// The neighbourhood of a voxel whose local frame is `frame`, at a
    /// level of spacing `h`.
    pub fn new(frame: &Frame, h: i64) -> Local {
        let mut slot = [[0u8; 9]; 3];
        let mut seen = [false; 27];
        for (plane, &(a, b)) in AXES.iter().enumerate() {
            let (fa, fb) = (frame[a], frame[b]);
            let mut n = 0;
            for j in [-1.0, 0.0, 1.0] {
                for i in [-1.0, 0.0, 1.0] {
                    let d = |w: usize| round(fa[w] * i + fb[w] * j).clamp(-1, 1);
                    let k = (CENTRE as i64 + d(0) + 3 * d(1) + 9 * d(2)) as usize;
                    slot[plane][n] = k as u8;
                    seen[k] = true;
                    n += 1;
                }
            }
        }
        // Offsets of the neighbours read only: the others are never moved.
        let hf = h as f64;
        let mut offset = [[0i64; 3]; 27];
        let mut used = [0u8; 27];
        let mut used_n = 0;
        for k in (0..27).filter(|&k| seen[k]) {
            // z outermost, as [`near_slot`] counts.
            let d = [
                (k % 3) as f64 - 1.0,
                ((k / 3) % 3) as f64 - 1.0,
                (k / 9) as f64 - 1.0,
            ];
            offset[k] = [0, 1, 2].map(|a| {
                round((frame[a][0] * d[0] + frame[a][1] * d[1] + frame[a][2] * d[2]) * hf)
            });
            used[used_n] = k as u8;
            used_n += 1;
        }
        Local {
            slot,
            offset,
            used,
            used_n,
        }
    }

    /// The near slot at in-plane offset (i, j) of `plane`.
    #[inline(always)]
    fn slot(&self, plane: usize, i: i64, j: i64) -> usize {
        self.slot[plane][(3 * (j + 1) + i + 1) as usize] as usize
    }
}

/// [`gather_near`] in a local frame: the neighbours the frame's planes
/// hold (turned offsets may reach the corners), each moved back by its
/// offset in local coordinates.
#[inline(always)]
fn gather_local<const BY_WALL: bool>(
    work: &Work,
    start: &Work,
    inside: [(i64, i64); 3],
    p: [i64; 3],
    dims: Dims,
    local: &Local,
    near: &mut Near,
) {
    let strides = work.triples.strides();
    let centre = work.triples.index(p) as i64;
    for &k in local.used() {
        let k = k as usize;
        let d = [
            (k % 3) as i64 - 1,
            ((k / 3) % 3) as i64 - 1,
            (k / 9) as i64 - 1,
        ];
        let idx = (centre + d[0] * strides[0] + d[1] * strides[1] + d[2] * strides[2]) as usize;
        let inside = !BY_WALL || (0..3).all(|a| d[a] >= inside[a].0 && d[a] <= inside[a].1);
        let src = if inside { work } else { start };
        near.triples[k] = src.triples.data[idx];
        let [r, g, b] = src.colours.data[idx];
        near.colours[k] = [r, g, b, 0.0];
        near.moved[k] = offset_triple(dims, near.triples[k], local.offset[k].map(|v| -v), 1);
    }
}

/// How much a triple's three exemplar colours disagree (squared
/// differences of each pair), times `weight`.
#[inline(always)]
fn disagreement(plane_colours: &[&[[f32; 3]]; 3], weight: f32, t: [u32; 3]) -> u32 {
    if weight == 0.0 {
        return 0;
    }
    // Spelled out: an array `map` here is compiled out of line.
    let a = plane_colours[0][t[0] as usize];
    let b = plane_colours[1][t[1] as usize];
    let c = plane_colours[2][t[2] as usize];
    let mut d = 0f32;
    for ch in 0..3 {
        d += (a[ch] - b[ch]).powi(2) + (b[ch] - c[ch]).powi(2) + (c[ch] - a[ch]).powi(2);
    }
    (d * weight) as u32
}

/// The [`near_slot`] of the voxel itself.
const CENTRE: usize = 13;

/// Slot of offset `d` (in {-1, 0, 1}³) in a [`Near`] table.
#[inline(always)]
fn near_slot(d: [i64; 3]) -> usize {
    (CENTRE as i64 + d[0] + 3 * d[1] + 9 * d[2]) as usize
}

/// Slot of the in-plane offset (i along axis `a`, j along axis `b`).
#[inline(always)]
fn in_plane_slot(a: usize, i: i64, b: usize, j: i64) -> usize {
    const STEP: [i64; 3] = [1, 3, 9];
    (CENTRE as i64 + i * STEP[a] + j * STEP[b]) as usize
}

/// The direct neighbours' triples and colours, by [`near_slot`], in the
/// version the correction's history window reads, and their triples moved
/// back by their offsets (the coherent triples).
struct Near {
    triples: [[u32; 3]; 27],
    colours: [[f32; 4]; 27],
    moved: [[u32; 3]; 27],
}

impl Default for Near {
    fn default() -> Self {
        Near {
            triples: [[0; 3]; 27],
            colours: [[0.0; 4]; 27],
            moved: [[u32::MAX; 3]; 27],
        }
    }
}

/// How far a correction reads, in voxels of its level along each axis:
/// its direct neighbours. The dependency planner and the barrier test
/// share it.
pub const REACH: i64 = 1;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_direct_neighbours_are_the_three_in_plane_windows() {
        let mut windows: Vec<[i64; 3]> = Vec::new();
        for &(a, b) in &AXES {
            for j in -1..=1 {
                for i in -1..=1 {
                    let mut d = [0; 3];
                    d[a] = i;
                    d[b] = j;
                    assert_eq!(in_plane_slot(a, i, b, j), near_slot(d));
                    if !windows.contains(&d) {
                        windows.push(d);
                    }
                }
            }
        }
        windows.sort();
        let mut direct = DIRECT.to_vec();
        direct.sort();
        assert_eq!(direct, windows);
    }

    /// The written-out gathering visits exactly [`DIRECT`], in order.
    #[test]
    fn each_direct_offset_is_written_out() {
        let mut listed: Vec<[i64; 3]> = Vec::new();
        macro_rules! push {
            ($x:literal, $y:literal, $z:literal) => {
                listed.push([$x, $y, $z])
            };
        }
        for_each_direct!(push);
        assert_eq!(listed, DIRECT.to_vec());
    }
}
