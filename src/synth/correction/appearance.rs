//! Correction in sparse appearance space (Lin 2009 §3.4.3 and Fig. 3.5,
//! after Lefebvre and Hoppe 2006).
//!
//! A voxel's query is, for each plane, the appearance vectors at the 4
//! diagonal locations h·(±1, ±1) around it. Each location is the average
//! of what the 3 direct neighbours next to it predict for it: the diagonal
//! neighbour's own exemplar coordinate for that plane, and the two edge
//! neighbours' coordinates moved on by the rest of the offset. Lin writes
//! the three as the voxels beyond the diagonal, which reads two voxels
//! away; Lefebvre and Hoppe's form, used here, stays within the direct
//! neighbours, so the dependency radius is 1.
//!
//! A plane's own coordinates do not see what the other two planes add to
//! a voxel's colour (a seam in the yz coordinates along x is invisible to
//! the yz query), so each prediction also carries its voxel's colour
//! offset from the plane's own exemplar colour, as a uniform offset of the
//! whole neighbourhood in appearance space: the planes are coupled as in
//! the colour correction's blend of voxel and own colours.
//!
//! Averages of three predictions and of three exemplar colours are flatter
//! than any exemplar neighbourhood, and flat queries pick the exemplar's
//! calm regions. Each location is therefore stretched by the texture's
//! `contrast` around the flat neighbourhood of its own mean colour: its
//! local contrast grows, its mean colour stays (stretching around the
//! appearance-space origin instead darkens dark regions pass after pass
//! into blotches).
//!
//! Candidates come by k-coherence (Lin §3.2): every in-plane neighbour's
//! exemplar pixel, moved back by its offset, proposes its similarity set;
//! each proposed pixel is completed to triples by its best
//! [`BEST_CANDIDATES`](crate::candidates::sparse::BEST_CANDIDATES)
//! precomputed 3D candidates. The coherent triples
//! (each direct neighbour's triple moved back) compete on equal terms,
//! with a penalty when their three exemplar colours disagree; a bonus for
//! them, as the colour correction gives, left upsampled blocks standing.
//! The best by distance of the quantised 12-location vectors wins.

use super::{Work, coherent_triples, disagreement, gather_near, in_plane_slot, prefetch};
use crate::candidates::geometry::{AXES, Dims};
use crate::candidates::sparse::{DIAGONALS, SparseTables, sparse_distance};
use crate::candidates::{Candidates, Level};
use crate::params::SynthParams;
use crate::stack::spacing;

/// Largest appearance dimension count per location (`pca_dims` ≤ 16).
const MAX_LOCATION_DIMS: usize = 16;

/// Largest 2D similarity set (`similar_coarse`, `similar_fine` ≤ 8).
const MAX_SIMILAR: usize = 8;

/// Everything the appearance-space correction of one level reads.
pub struct AppearanceCorrector<'a> {
    level: &'a Level,
    tables: &'a SparseTables,
    dims: Dims,
    /// The level's spacing.
    h: i64,
    /// Appearance dimensions per location.
    d: usize,
    /// Each plane's appearance vectors.
    app: [&'a [f32]; 3],
    /// Each plane's exemplar colours at this level.
    plane_colours: [&'a [[f32; 3]]; 3],
    /// Weight of a coherent triple's colour disagreement, in quantised
    /// distance units per squared colour difference.
    consistency: f32,
    /// The texture's `contrast`.
    gain: f32,
    /// Per plane, how flat neighbourhoods look in appearance space.
    flat: [Flat; 3],
}

/// Flat neighbourhoods in one plane's appearance space: a neighbourhood of
/// one colour c everywhere has the appearance vector `uniform`·c −
/// `offsets`, and an appearance vector a has the mean colour
/// `mean_colour` + `uniform`ᵀ·a / pixels (exactly, for a vector of the
/// PCA's span).
struct Flat {
    uniform: [[f32; 3]; MAX_LOCATION_DIMS],
    offsets: [f32; MAX_LOCATION_DIMS],
    mean_colour: [f32; 3],
    inv_pixels: f32,
}

impl Flat {
    fn new(pca: &crate::appearance::Pca) -> Flat {
        let pixels = pca.input / 3;
        let mut uniform = [[0f32; 3]; MAX_LOCATION_DIMS];
        for (d, row) in uniform.iter_mut().enumerate().take(pca.dims) {
            for rgb in pca.basis[d * pca.input..(d + 1) * pca.input].chunks_exact(3) {
                for ch in 0..3 {
                    row[ch] += rgb[ch];
                }
            }
        }
        let mut offsets = [0f32; MAX_LOCATION_DIMS];
        for (o, m) in offsets.iter_mut().zip(pca.mean_offsets()) {
            *o = m;
        }
        let mut mean_colour = [0f32; 3];
        for rgb in pca.mean.chunks_exact(3) {
            for ch in 0..3 {
                mean_colour[ch] += rgb[ch] / pixels as f32;
            }
        }
        Flat {
            uniform,
            offsets,
            mean_colour,
            inv_pixels: 1.0 / pixels as f32,
        }
    }
}

impl<'a> AppearanceCorrector<'a> {
    /// The corrector of level `k`.
    pub fn new(cands: &'a Candidates, k: usize, params: &SynthParams) -> Self {
        let level = cands.level(k);
        let tables = level.sparse_tables(cands.dims(), k);
        let scale = tables.scale();
        AppearanceCorrector {
            level,
            tables,
            dims: cands.dims(),
            h: spacing(k) as i64,
            d: tables.location_dims(),
            app: [0, 1, 2].map(|p| level.appearance[p].vectors.as_slice()),
            plane_colours: [0, 1, 2].map(|p| cands.stack(p).level(k)),
            consistency: params.consistency * scale * scale,
            gain: params.contrast,
            flat: [0, 1, 2].map(|p| Flat::new(&level.appearance[p].pca)),
        }
    }

    /// See [`super::Corrector::correct_with`].
    #[inline(always)]
    pub(super) fn correct_with<const BY_WALL: bool>(
        &self,
        work: &Work,
        start: &Work,
        inside: [(i64, i64); 3],
        p: [i64; 3],
    ) -> [u32; 3] {
        let h = self.h;
        let d = self.d;
        let (near, moved) = gather_near::<BY_WALL>(work, start, inside, p, self.dims, h);
        // The proposed pixels and the coherent triples are known from the
        // triples alone: prefetch what scoring them reads, so the cache
        // misses overlap the query's arithmetic below.
        let mut pixels = [[u32::MAX; 9 * MAX_SIMILAR]; 3];
        let mut pixels_n = [0usize; 3];
        for (plane, &(a, b)) in AXES.iter().enumerate() {
            let (pixels, n) = (&mut pixels[plane], &mut pixels_n[plane]);
            let mut bases = [u32::MAX; 9];
            let mut bases_n = 0;
            for j in -1..=1i64 {
                for i in -1..=1i64 {
                    let base = moved[in_plane_slot(a, i, b, j)][plane];
                    // Coherent neighbours usually point at the same pixel.
                    if bases[..bases_n].contains(&base) {
                        continue;
                    }
                    bases[bases_n] = base;
                    bases_n += 1;
                    for &s in self.level.similar(plane, base) {
                        if !pixels[..*n].contains(&s) {
                            pixels[*n] = s;
                            *n += 1;
                            prefetch(std::slice::from_ref(self.tables.best_vectors(plane, s)));
                            prefetch(std::slice::from_ref(self.tables.best_triples(plane, s)));
                        }
                    }
                }
            }
        }
        let (coherent, coherent_n) = coherent_triples(&moved);
        for t in &coherent[..coherent_n] {
            for (q, &c) in t.iter().enumerate() {
                prefetch(std::slice::from_ref(self.tables.share(q, c)));
            }
        }
        let mut q = [0f32; 12 * MAX_LOCATION_DIMS];
        for (plane, &(a, b)) in AXES.iter().enumerate() {
            let app = self.app[plane];
            for (l, &(i, j)) in DIAGONALS.iter().enumerate() {
                let out = &mut q[(4 * plane + l) * d..(4 * plane + l + 1) * d];
                let mut shift = [0f32; 3];
                for (du, dv) in [(i, j), (i, 0), (0, j)] {
                    let slot = in_plane_slot(a, du, b, dv);
                    let t = near.triples[slot][plane];
                    let c = self.dims.shift(t, (i - du) * h, (j - dv) * h) as usize;
                    for (o, v) in out.iter_mut().zip(&app[c * d..(c + 1) * d]) {
                        *o += v;
                    }
                    let own = self.plane_colours[plane][t as usize];
                    for ch in 0..3 {
                        shift[ch] += near.colours[slot][ch] - own[ch];
                    }
                }
                let flat = &self.flat[plane];
                let mut mean = flat.mean_colour;
                for (o, u) in out.iter_mut().zip(&flat.uniform) {
                    let offset = u[0] * shift[0] + u[1] * shift[1] + u[2] * shift[2];
                    *o = (*o + offset) * (1.0 / 3.0);
                    for ch in 0..3 {
                        mean[ch] += u[ch] * *o * flat.inv_pixels;
                    }
                }
                for ((o, u), off) in out.iter_mut().zip(&flat.uniform).zip(&flat.offsets) {
                    let level = u[0] * mean[0] + u[1] * mean[1] + u[2] * mean[2] - off;
                    *o = self.gain * *o - (self.gain - 1.0) * level;
                }
            }
        }
        let query = self.tables.query(&q[..12 * d]);

        let mut best = (u32::MAX, [u32::MAX; 3]);
        let mut consider = |dist: u32, t: [u32; 3]| {
            if dist < best.0 || (dist == best.0 && t < best.1) {
                best = (dist, t);
            }
        };
        for &t in &coherent[..coherent_n] {
            let dist = sparse_distance(&self.tables.triple_vector(t), &query);
            // Saturating: a large `consistency` can push the penalty to u32::MAX.
            consider(
                dist.saturating_add(disagreement(&self.plane_colours, self.consistency, t)),
                t,
            );
        }
        for plane in 0..3 {
            for &px in &pixels[plane][..pixels_n[plane]] {
                let vectors = self.tables.best_vectors(plane, px);
                let triples = self.tables.best_triples(plane, px);
                for (v, &t) in vectors.0.iter().zip(triples) {
                    consider(sparse_distance(v, &query), t);
                }
            }
        }
        best.1
    }
}
