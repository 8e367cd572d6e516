//! Correction (Dong et al. "Correction", Zhang et al. §4.3): a voxel's
//! triple is replaced by the candidate whose three exemplar neighbourhoods
//! best match the voxel's three axis-aligned N×N slice neighbourhoods.
//! A neighbour's colour in plane p's neighbourhood is half its voxel colour
//! (the mean of its three exemplar colours) and half plane p's exemplar
//! colour at its coordinate for p (the thesis's per-direction feature
//! lookup). Means alone are flatter than any exemplar patch and pull the
//! matches to bland regions; exemplar colours alone make the initial slab
//! blocks a fixed point and leave their seams (docs/quality.md measures
//! the blend against both).
//!
//! With sparse slices (the default, [`crate::Slices::Sparse`]) a correction
//! reads only its direct neighbours: a slice voxel beyond them gets the
//! triple that the nearest direct neighbour predicts for it (its triple
//! moved by the offset, Zhang et al.'s `T + d`), so the query still covers
//! N×N pixels while the dependency radius is 1 instead of N/2.
//!
//! Before matching, the gathered colours are stretched around their mean
//! by the texture's `contrast`: averaged voxel colours are flatter than any
//! exemplar patch, and flat queries drift to the exemplar's calm regions.
//!
//! A coherent triple continues its neighbour's exemplar patches in all
//! three planes, but nothing makes its three exemplar colours agree: along
//! z a voxel's xy coordinate never changes, so a vein of the xy exemplar
//! that the yz and zx exemplars do not share is extruded into a straight
//! streak across x and y slices. Coherent triples therefore pay for the
//! disagreement of their three colours ([`SynthParams::consistency`]); the
//! precomputed 3D candidates agree by construction (low crossbar error).
//!
//! Candidates come in two stages. For each plane, the 3×3 in-plane
//! neighbours' triples, moved back by their offset, point at exemplar
//! pixels; those pixels' 2D similarity sets are compared in appearance space
//! and the best pixel per plane is kept. The 3D candidates of those three
//! pixels are then compared by their quantised, PCA-projected
//! 3-neighbourhoods, together with the coherent triples (each neighbour's
//! triple moved back by its offset), which get a bonus for continuing an
//! exemplar patch.

mod appearance;

use super::colour::{colour, third};
use super::grid::{Box3, Grid};
use crate::appearance::Projector;
use crate::candidates::geometry::{AXES, Dims, offset_triple};
use crate::candidates::{Candidates, Level, SIMILAR_DIMS, quantise, sum_of_squares};
use crate::field::{Frame, FrameField, round};
use crate::params::{Correction, Slices, SynthParams};
use crate::stack::spacing;
use appearance::AppearanceCorrector;
use rayon::prelude::*;

const MAX_NEIGHBOURHOOD: usize = 9 * 9 * 3;
const MAX_DIMS: usize = 16;

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

/// Reusable per-thread buffers.
pub struct Scratch {
    /// One float of slack: gathered colours are written four floats at a
    /// time, three apart.
    neigh: [f32; MAX_NEIGHBOURHOOD + 1],
    app: [[f32; MAX_DIMS]; 3],
    concat: [f32; 3 * MAX_DIMS],
    joint: [f32; MAX_DIMS],
}

impl Default for Scratch {
    fn default() -> Self {
        Scratch {
            neigh: [0.0; MAX_NEIGHBOURHOOD + 1],
            app: [[0.0; MAX_DIMS]; 3],
            concat: [0.0; 3 * MAX_DIMS],
            joint: [0.0; MAX_DIMS],
        }
    }
}

/// Everything the correction of one level reads.
pub struct ColourCorrector<'a> {
    level: &'a Level,
    k: usize,
    n: i64,
    dims: Dims,
    /// Each plane's appearance projection, and the joint one.
    projectors: [Projector; 3],
    joint: Projector,
    joint_offsets: Vec<f32>,
    /// 3D candidates tried per pixel (best crossbar error first).
    max_3d: usize,
    /// Each plane's exemplar colours at this level.
    plane_colours: [&'a [[f32; 3]]; 3],
    /// The same, padded to four floats.
    padded_colours: [&'a [[f32; 4]]; 3],
    /// Each plane's sparse query, pixel by pixel (see [`SparsePixel`]).
    sparse_pixels: [Vec<SparsePixel>; 3],
    /// Gain on neighbourhood colours around their mean (see
    /// [`crate::SynthParams::contrast`]).
    contrast: f32,
    /// Reads only the direct neighbours (see [`Slices::Sparse`]).
    sparse: bool,
    /// How far a correction reads (see [`reach`]).
    reach: i64,
    /// Weight of a coherent triple's colour disagreement, in quantised
    /// joint-distance units per squared colour difference (see
    /// [`SynthParams::consistency`]).
    consistency: f32,
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
    /// Colour neighbourhoods.
    Colour(Box<ColourCorrector<'a>>),
}

impl<'a> Corrector<'a> {
    /// The corrector of level `k`, in the frames of `field` if there is one
    /// (the parameters' validation keeps fields to the appearance
    /// correction).
    pub fn new(
        cands: &'a Candidates,
        k: usize,
        params: &SynthParams,
        field: Option<&'a FrameField>,
    ) -> Self {
        match (params.correction, field) {
            (Correction::Appearance, None) => {
                Corrector::Appearance(Box::new(AppearanceCorrector::new(cands, k, params)))
            }
            (Correction::Appearance, Some(f)) => {
                let c = AppearanceCorrector::new(cands, k, params);
                let constant = f
                    .constant()
                    .map(|frame| Box::new(Local::new(frame, c.spacing())));
                Corrector::Field(Box::new(c), f, constant)
            }
            (Correction::Colour, _) => {
                Corrector::Colour(Box::new(ColourCorrector::new(cands, k, params)))
            }
        }
    }

    /// The best candidate triple for the voxel at `p`. Its history window
    /// decides which version of each neighbour it reads: the latest (`work`)
    /// inside `barrier`'s cell, the step's starting version (`barrier`'s
    /// work) outside it; without a barrier, always the latest.
    #[inline]
    pub fn correct(
        &self,
        work: &Work,
        barrier: Option<(&Work, &Box3)>,
        p: [i64; 3],
        s: &mut Scratch,
    ) -> [u32; 3] {
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
        let r = match self {
            Corrector::Appearance(_) | Corrector::Field(..) => 1,
            Corrector::Colour(c) => c.reach,
        };
        if inside.iter().all(|&(lo, hi)| lo <= -r && hi >= r) {
            self.correct_with::<false>(work, start, inside, p, s)
        } else {
            self.correct_with::<true>(work, start, inside, p, s)
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
        s: &mut Scratch,
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
            Corrector::Colour(c) => c.correct_with::<BY_WALL>(work, start, inside, p, s),
        }
    }
}

/// Weight (out of 256) of a coherent triple's distance: favouring triples
/// that continue their neighbours keeps exemplar patches together
/// (Ashikhmin's and Lefebvre and Hoppe's coherence parameter); its effect
/// on the share of coherent neighbour pairs is in docs/quality.md.
const COHERENT_WEIGHT: u32 = 128;

/// 3D candidates tried per exemplar pixel at the finest level, where
/// neighbourhoods are already coherent (Dong et al.: 4 there, all 12 at
/// coarser levels).
const FINE_3D_CANDIDATES: usize = 4;

impl<'a> ColourCorrector<'a> {
    /// A corrector for level `k` with the texture's matching and contrast.
    pub fn new(cands: &'a Candidates, k: usize, params: &SynthParams) -> Self {
        ColourCorrector {
            level: cands.level(k),
            k,
            n: cands.params().neighbourhood as i64,
            dims: cands.dims(),
            projectors: [0, 1, 2].map(|p| Projector::new(&cands.level(k).appearance[p].pca)),
            joint: Projector::new(cands.level(k).joint_pca()),
            joint_offsets: cands.level(k).joint_pca().mean_offsets(),
            plane_colours: [0, 1, 2].map(|p| cands.stack(p).level(k)),
            padded_colours: [0, 1, 2].map(|p| cands.stack(p).level_padded(k)),
            sparse_pixels: [0, 1, 2].map(|p| sparse_pixels(p, cands.params().neighbourhood)),
            contrast: params.contrast,
            sparse: params.slices == Slices::Sparse,
            reach: reach(params, cands.params().neighbourhood),
            consistency: {
                let scale = cands.level(k).quant_scale();
                params.consistency * scale * scale
            },
            max_3d: if k == 0 {
                FINE_3D_CANDIDATES
            } else {
                usize::MAX
            },
        }
    }

    /// See [`Corrector::correct_with`].
    #[inline(always)]
    fn correct_with<const BY_WALL: bool>(
        &self,
        work: &Work,
        start: &Work,
        inside: [(i64, i64); 3],
        p: [i64; 3],
        s: &mut Scratch,
    ) -> [u32; 3] {
        let h = spacing(self.k) as i64;
        let strides = work.triples.strides();
        let centre = work.triples.index(p) as i64;
        let pick = |a: usize, i: i64, b: usize, j: i64| -> &Work {
            let (la, ha) = inside[a];
            let (lb, hb) = inside[b];
            if !BY_WALL || (i >= la && i <= ha && j >= lb && j <= hb) {
                work
            } else {
                start
            }
        };
        // The direct neighbours (the 19 offsets with a zero coordinate,
        // which the three in-plane 3×3 windows hold), read once in the
        // version their history window gives; corners are never read.
        let (near, moved) = gather_near::<BY_WALL>(work, start, inside, p, self.dims, h);
        // The exemplar pixels whose similarity sets each plane scans (the
        // in-plane neighbours' coherent pixels), and the coherent triples,
        // are known from the triples alone: prefetch their tables, so the
        // cache misses overlap the neighbourhood gathering and projection
        // below.
        let mut bases = [[u32::MAX; 9]; 3];
        let mut bases_n = [0usize; 3];
        for (plane, &(a, b)) in AXES.iter().enumerate() {
            for j in -1..=1i64 {
                for i in -1..=1i64 {
                    let base = moved[in_plane_slot(a, i, b, j)][plane];
                    // Coherent neighbours usually point at the same pixel:
                    // visit each base pixel once.
                    if bases[plane][..bases_n[plane]].contains(&base) {
                        continue;
                    }
                    bases[plane][bases_n[plane]] = base;
                    bases_n[plane] += 1;
                    prefetch(self.level.similar_vectors(plane, base));
                    prefetch(self.level.similar(plane, base));
                }
            }
        }
        let (coherent, coherent_n) = coherent_triples(&moved);
        for t in &coherent[..coherent_n] {
            for (p, &c) in t.iter().enumerate() {
                prefetch(self.level.joint_share(p, c));
            }
        }
        let mut best2d = [0u32; 3];
        for plane in 0..3 {
            if self.sparse {
                self.sparse_query(&near, plane, s);
            } else {
                self.slice_query(&pick, strides, centre, plane, s);
            }
            let dims = self.level.appearance[plane].pca.dims;
            let query = self.level.quantise_appearance(plane, &s.app[plane][..dims]);
            let mut best = (u32::MAX, u32::MAX);
            for &base in &bases[plane][..bases_n[plane]] {
                let ids = self.level.similar(plane, base);
                let vectors = self.level.similar_vectors(plane, base);
                for (&cand, v) in ids.iter().zip(vectors) {
                    let d = sq_dist_i16(&query, v);
                    if d < best.0 || (d == best.0 && cand < best.1) {
                        best = (d, cand);
                    }
                }
            }
            best2d[plane] = best.1;
            // Stage two reads this pixel's 3D candidates.
            let cands = self.level.candidates(plane);
            let range = cands.range(best.1);
            let jd = self.level.joint_dims();
            let take = range.len().min(self.max_3d);
            let vectors = &self.level.vectors[plane][range.start * jd..(range.start + take) * jd];
            for line in vectors.chunks(64) {
                prefetch(line);
            }
            for line in cands.triples[range.start..range.start + take].chunks(5) {
                prefetch(line);
            }
        }
        // Stage two: 3D candidates of the best pixel of each plane.
        let mut len = 0;
        for plane in 0..3 {
            let d = self.level.appearance[plane].pca.dims;
            s.concat[len..len + d].copy_from_slice(&s.app[plane][..d]);
            len += d;
        }
        let jd = self.joint.dims();
        self.joint.project(&s.concat[..len], &mut s.joint[..jd]);
        let scale = self.level.quant_scale();
        let mut query = [0u8; MAX_DIMS];
        for (q, &v) in query.iter_mut().zip(&s.joint[..jd]) {
            *q = quantise(v, scale);
        }
        let mut best = (u32::MAX, [u32::MAX; 3]);
        for &t in &coherent[..coherent_n] {
            let shares = [0, 1, 2].map(|p| self.level.joint_share(p, t[p]));
            let mut dist = 0u32;
            for (j, &q) in query[..jd].iter().enumerate() {
                let v = shares[0][j] + shares[1][j] + shares[2][j] - self.joint_offsets[j];
                let e = quantise(v, scale) as i32 - q as i32;
                dist += (e * e) as u32;
            }
            // Saturating: a large `consistency` can push the penalty to u32::MAX.
            let dist = (dist * COHERENT_WEIGHT / 256).saturating_add(disagreement(
                &self.plane_colours,
                self.consistency,
                t,
            ));
            if dist < best.0 || (dist == best.0 && t < best.1) {
                best = (dist, t);
            }
        }
        for (plane, &pixel) in best2d.iter().enumerate() {
            let cands = self.level.candidates(plane);
            let vectors = &self.level.vectors[plane];
            let range = cands.range(pixel);
            let range = range.start..range.end.min(range.start.saturating_add(self.max_3d));
            for ci in range {
                let d = sq_dist_u8(&query[..jd], &vectors[ci * jd..(ci + 1) * jd]);
                let t = cands.triples[ci];
                if d < best.0 || (d == best.0 && t < best.1) {
                    best = (d, t);
                }
            }
        }
        best.1
    }

    /// Plane `plane`'s query from the voxel's full N×N colour slice, v
    /// rows and u columns like the exemplar neighbourhoods.
    fn slice_query<'w>(
        &self,
        pick: &impl Fn(usize, i64, usize, i64) -> &'w Work,
        strides: [i64; 3],
        centre: i64,
        plane: usize,
        s: &mut Scratch,
    ) {
        let r = self.n / 2;
        let (a, b) = AXES[plane];
        let mut o = 0;
        for j in -r..=r {
            for i in -r..=r {
                let idx = (centre + i * strides[a] + j * strides[b]) as usize;
                let w = pick(a, i, b, j);
                let own = self.plane_colours[plane][w.triples.data[idx][plane] as usize];
                s.neigh[o..o + 3].copy_from_slice(&blend(w.colours.data[idx], own));
                o += 3;
            }
        }
        self.project_query(plane, o, s);
    }

    /// Plane `plane`'s query with sparse slices: the direct neighbours'
    /// colours, and beyond them the colours of the triples that the nearest
    /// direct neighbour predicts (its triple moved by the offset, Zhang et
    /// al.'s `T + d`). An in-plane offset (du, dv) moves the plane's own
    /// coordinate by both, the next plane's (which shares the v axis as
    /// its u) by dv along u, and the previous plane's (which shares the u
    /// axis as its v) by du along v.
    fn sparse_query(&self, near: &Near, plane: usize, s: &mut Scratch) {
        let h = spacing(self.k) as i64;
        let (next, prev) = ((plane + 1) % 3, (plane + 2) % 3);
        let colours = self.padded_colours;
        let pixels = &self.sparse_pixels[plane];
        for (o, px) in pixels.iter().enumerate() {
            let slot = px.slot as usize;
            let t = near.triples[slot];
            let c = if px.du == 0 && px.dv == 0 {
                blend4(near.colours[slot], colours[plane][t[plane] as usize])
            } else {
                let (du, dv) = (px.du as i64 * h, px.dv as i64 * h);
                let mut m = t;
                m[plane] = self.dims.shift(t[plane], du, dv);
                m[next] = self.dims.shift(t[next], dv, 0);
                m[prev] = self.dims.shift(t[prev], 0, du);
                let moved = [0, 1, 2].map(|p| colours[p][m[p] as usize]);
                let mean = [0, 1, 2, 3].map(|ch| third(moved[0][ch] + moved[1][ch] + moved[2][ch]));
                blend4(mean, moved[plane])
            };
            // Four floats written three apart: the slack float of the last
            // one is never read.
            s.neigh[3 * o..3 * o + 4].copy_from_slice(&c);
        }
        self.project_query(plane, 3 * pixels.len(), s);
    }

    /// Stretches the `len` gathered floats and projects them into plane
    /// `plane`'s appearance space.
    fn project_query(&self, plane: usize, len: usize, s: &mut Scratch) {
        if self.contrast != 1.0 {
            stretch(&mut s.neigh[..len], self.contrast);
        }
        let dims = self.projectors[plane].dims();
        self.projectors[plane].project(&s.neigh[..len], &mut s.app[plane][..dims]);
    }
}

/// A neighbour's colour in a plane's query: half its voxel colour, half
/// the plane's own exemplar colour.
#[inline(always)]
fn blend(voxel: [f32; 3], own: [f32; 3]) -> [f32; 3] {
    [0, 1, 2].map(|ch| 0.5 * (voxel[ch] + own[ch]))
}

/// [`blend`] on padded colours.
#[inline(always)]
fn blend4(voxel: [f32; 4], own: [f32; 4]) -> [f32; 4] {
    [0, 1, 2, 3].map(|ch| 0.5 * (voxel[ch] + own[ch]))
}

/// The direct neighbours a sparse correction reads: offsets in {-1, 0, 1}³
/// with at least one zero coordinate (the union of the three in-plane 3×3
/// windows), z outermost.
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

/// How far along x [`gather_near`] prefetches, in voxels.
const AHEAD: i64 = 16;

/// The direct neighbours of `p`, each in the version its history window
/// gives (`work` for offsets within `inside`, `start` beyond), and the
/// coherent triples: each neighbour's triple moved back by its offset, in
/// all three planes at once. Both by [`near_slot`].
#[inline(always)]
fn gather_near<const BY_WALL: bool>(
    work: &Work,
    start: &Work,
    inside: [(i64, i64); 3],
    p: [i64; 3],
    dims: Dims,
    h: i64,
) -> (Near, [[u32; 3]; 27]) {
    let strides = work.triples.strides();
    let centre = work.triples.index(p) as i64;
    let inside3 =
        |d: [i64; 3]| !BY_WALL || (0..3).all(|a| d[a] >= inside[a].0 && d[a] <= inside[a].1);
    let mut near = Near::default();
    let mut moved = [[u32::MAX; 3]; 27];
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
    for &d in &DIRECT {
        let k = near_slot(d);
        let idx = (centre + d[0] * strides[0] + d[1] * strides[1] + d[2] * strides[2]) as usize;
        let src = if inside3(d) { work } else { start };
        near.triples[k] = src.triples.data[idx];
        let [r, g, b] = src.colours.data[idx];
        near.colours[k] = [r, g, b, 0.0];
        moved[k] = offset_triple(dims, near.triples[k], d.map(|v| -v), h);
    }
    (near, moved)
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
                    let k = (13 + d(0) + 3 * d(1) + 9 * d(2)) as usize;
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
) -> (Near, [[u32; 3]; 27]) {
    let strides = work.triples.strides();
    let centre = work.triples.index(p) as i64;
    let mut near = Near::default();
    let mut moved = [[u32::MAX; 3]; 27];
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
        moved[k] = offset_triple(dims, near.triples[k], local.offset[k].map(|v| -v), 1);
    }
    (near, moved)
}

/// The distinct coherent triples among `moved` (see [`gather_near`]), in
/// [`DIRECT`] order, and their count.
#[inline(always)]
fn coherent_triples(moved: &[[u32; 3]; 27]) -> ([[u32; 3]; 19], usize) {
    let mut coherent = [[u32::MAX; 3]; 19];
    let mut n = 0;
    for &d in &DIRECT {
        let t = moved[near_slot(d)];
        if !coherent[..n].contains(&t) {
            coherent[n] = t;
            n += 1;
        }
    }
    (coherent, n)
}

/// How much a triple's three exemplar colours disagree (squared
/// differences of each pair), times `weight`.
#[inline]
fn disagreement(plane_colours: &[&[[f32; 3]]; 3], weight: f32, t: [u32; 3]) -> u32 {
    if weight == 0.0 {
        return 0;
    }
    let [a, b, c] = [0, 1, 2].map(|p| plane_colours[p][t[p] as usize]);
    let mut d = 0f32;
    for ch in 0..3 {
        d += (a[ch] - b[ch]).powi(2) + (b[ch] - c[ch]).powi(2) + (c[ch] - a[ch]).powi(2);
    }
    (d * weight) as u32
}

/// Slot of offset `d` (in {-1, 0, 1}³) in a [`Near`] table.
#[inline(always)]
fn near_slot(d: [i64; 3]) -> usize {
    (13 + d[0] + 3 * d[1] + 9 * d[2]) as usize
}

/// Slot of the in-plane offset (i along axis `a`, j along axis `b`).
#[inline(always)]
fn in_plane_slot(a: usize, i: i64, b: usize, j: i64) -> usize {
    const STEP: [i64; 3] = [1, 3, 9];
    (13 + i * STEP[a] + j * STEP[b]) as usize
}

/// The direct neighbours' triples and colours, by [`near_slot`], in the
/// version the correction's history window reads.
struct Near {
    triples: [[u32; 3]; 27],
    colours: [[f32; 4]; 27],
}

impl Default for Near {
    fn default() -> Self {
        Near {
            triples: [[0; 3]; 27],
            colours: [[0.0; 4]; 27],
        }
    }
}

/// One pixel of a sparse query: the direct neighbour it comes from (its
/// [`near_slot`]) and how far beyond it the pixel lies along the plane's
/// u and v axes, in voxels (0, 0 for the neighbour itself).
#[derive(Clone, Copy, Debug)]
struct SparsePixel {
    slot: u8,
    du: i8,
    dv: i8,
}

/// Plane `plane`'s sparse query pixels for an N×N neighbourhood, v rows
/// and u columns like the exemplar neighbourhoods.
fn sparse_pixels(plane: usize, neighbourhood: u32) -> Vec<SparsePixel> {
    let r = neighbourhood as i64 / 2;
    let (a, b) = AXES[plane];
    let mut out = Vec::with_capacity((2 * r as usize + 1).pow(2));
    for j in -r..=r {
        for i in -r..=r {
            let (qi, qj) = (i.clamp(-1, 1), j.clamp(-1, 1));
            out.push(SparsePixel {
                slot: in_plane_slot(a, qi, b, qj) as u8,
                du: (i - qi) as i8,
                dv: (j - qj) as i8,
            });
        }
    }
    out
}

/// How far a correction reads, in voxels of its level along each axis:
/// its direct neighbours in appearance space or with sparse slices, half
/// the neighbourhood with full ones. The dependency planner and the
/// barrier test share it.
pub fn reach(params: &SynthParams, neighbourhood: u32) -> i64 {
    match (params.correction, params.slices) {
        (Correction::Colour, Slices::Full) => (neighbourhood as i64 / 2).max(1),
        _ => 1,
    }
}

/// Moves RGB colours away from their mean by `gain` (per channel).
fn stretch(rgb: &mut [f32], gain: f32) {
    let n = (rgb.len() / 3) as f32;
    let mut mean = [0f32; 3];
    for c in rgb.chunks_exact(3) {
        for ch in 0..3 {
            mean[ch] += c[ch];
        }
    }
    let mean = mean.map(|m| m / n);
    for c in rgb.chunks_exact_mut(3) {
        for ch in 0..3 {
            c[ch] = mean[ch] + gain * (c[ch] - mean[ch]);
        }
    }
}

/// Asks the CPU to start loading the first cache line of `data`.
#[inline(always)]
#[allow(unsafe_code)]
fn prefetch<T>(data: &[T]) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        // SAFETY: SSE is part of the x86_64 baseline, and a prefetch is a
        // hint that never faults, whatever the address.
        unsafe { _mm_prefetch::<_MM_HINT_T0>(data.as_ptr().cast()) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = data;
}

/// Squared L2 distance between quantised vectors, in integers.
#[inline]
fn sq_dist_u8(a: &[u8], b: &[u8]) -> u32 {
    a.iter()
        .zip(b)
        .map(|(&x, &y)| {
            let e = x as i32 - y as i32;
            (e * e) as u32
        })
        .sum()
}

/// Squared L2 distance between wide-quantised appearance vectors. Values
/// lie within ±4095, so differences fit an `i16`.
#[inline]
fn sq_dist_i16(a: &[i16; SIMILAR_DIMS], b: &[i16; SIMILAR_DIMS]) -> u32 {
    let e: [i16; SIMILAR_DIMS] = std::array::from_fn(|l| a[l].wrapping_sub(b[l]));
    sum_of_squares(&e)
}

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

    #[test]
    fn sparse_pixels_extrapolate_from_the_nearest_direct_neighbour() {
        for n in [3, 5, 9] {
            let r = n as i64 / 2;
            for (plane, &(a, b)) in AXES.iter().enumerate() {
                let pixels = sparse_pixels(plane, n);
                assert_eq!(pixels.len(), (n * n) as usize);
                for (o, px) in pixels.iter().enumerate() {
                    // v rows, u columns.
                    let (i, j) = ((o as i64 % n as i64) - r, (o as i64 / n as i64) - r);
                    let (qi, qj) = (i - px.du as i64, j - px.dv as i64);
                    assert!(
                        qi.abs() <= 1 && qj.abs() <= 1,
                        "({i}, {j}) from ({qi}, {qj})"
                    );
                    // Nearest: no step of the offset could have been saved.
                    assert!(i.abs() <= 1 || qi.abs() == 1);
                    assert!(j.abs() <= 1 || qj.abs() == 1);
                    assert_eq!(px.slot as usize, in_plane_slot(a, qi, b, qj));
                }
            }
        }
    }
}
