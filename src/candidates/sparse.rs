//! Sparse appearance-space neighbourhoods (Lin 2009 §3.4.3 and Fig. 3.5,
//! after Lefebvre and Hoppe 2006): a voxel is described in each of its
//! three planes by the appearance vectors at the 4 diagonal locations
//! h·(±1, ±1) around it, 12 locations in all. Each appearance vector
//! already summarises an N×N exemplar neighbourhood, so the 12 locations
//! cover (N + 2)² pixels per plane while the correction reads only its
//! direct neighbours.
//!
//! The candidate side of the match: the 12-location vectors of each
//! exemplar pixel's best [`BEST_CANDIDATES`] 3D candidates, PCA-reduced to
//! [`SPARSE_DIMS`] and quantised to bytes, and each pixel's share of that
//! projection per plane, so that any triple (a coherent one too) is scored
//! from three shares without a projection.

use super::PlaneCandidates;
use super::geometry::Dims;
use crate::appearance::{AppearanceLevel, Pca, Projector, dot};
use rayon::prelude::*;

/// Dimensions of a quantised sparse neighbourhood vector: one SSE register.
pub const SPARSE_DIMS: usize = 16;

/// The four diagonal locations of a plane, as (u, v) steps of the level
/// spacing.
pub const DIAGONALS: [(i64, i64); 4] = [(-1, -1), (1, -1), (-1, 1), (1, 1)];

/// A quantised sparse neighbourhood vector.
pub type SparseVector = [u8; SPARSE_DIMS];

/// 3D candidates of a pixel that a correction tries (Dong et al.'s number
/// at the finest level), best crossbar error first.
pub const BEST_CANDIDATES: usize = 4;

/// The vectors of a pixel's [`BEST_CANDIDATES`] candidates: one cache
/// line, found from the pixel alone (no offsets table to read first), so
/// a correction can prefetch it as soon as it knows the pixel. A pixel
/// with fewer candidates repeats its last one.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub struct BestVectors(pub [SparseVector; BEST_CANDIDATES]);

/// The triples of [`BestVectors`], in the same order.
pub type BestTriples = [[u32; 3]; BEST_CANDIDATES];

/// The sparse neighbourhood tables of one level.
#[derive(Clone, Debug)]
pub struct SparseTables {
    /// Appearance dimensions per location.
    dims: usize,
    /// From the 12 concatenated locations (xy, yz, zx; diagonals in
    /// [`DIAGONALS`] order) to [`SPARSE_DIMS`] dimensions.
    projector: Projector,
    /// Byte = round(v·scale) + 128.
    scale: f32,
    /// Each pixel's share of the projection, per plane.
    shares: [Vec<[f32; SPARSE_DIMS]>; 3],
    /// The projected mean, which a sum of shares still contains.
    offsets: [f32; SPARSE_DIMS],
    /// Each pixel's best candidates' quantised vectors, per plane.
    vectors: [Vec<BestVectors>; 3],
    /// Their triples.
    triples: [Vec<BestTriples>; 3],
}

/// The 4 diagonal appearance vectors of pixel `c` of one plane,
/// concatenated into `out` (4·dims floats).
fn diagonals(app: &AppearanceLevel, dims: Dims, h: i64, c: u32, out: &mut [f32]) {
    let d = app.pca.dims;
    for (l, &(i, j)) in DIAGONALS.iter().enumerate() {
        let at = dims.shift(c, i * h, j * h);
        out[l * d..(l + 1) * d].copy_from_slice(app.vector(at as usize));
    }
}

impl SparseTables {
    /// Builds the tables of a level from its appearance vectors and
    /// candidates (`h`: the level's spacing). Plane p's 4 locations are
    /// scaled by `weights[p]` here and in every query.
    pub fn new(
        appearance: &[AppearanceLevel; 3],
        candidates: &[PlaneCandidates; 3],
        dims: Dims,
        h: i64,
        weights: [f32; 3],
    ) -> SparseTables {
        let d = appearance[0].pca.dims;
        let input = 12 * d;
        let concat = |t: [u32; 3], out: &mut [f32]| {
            for p in 0..3 {
                diagonals(
                    &appearance[p],
                    dims,
                    h,
                    t[p],
                    &mut out[4 * d * p..4 * d * (p + 1)],
                );
                out[4 * d * p..4 * d * (p + 1)]
                    .iter_mut()
                    .for_each(|v| *v *= weights[p]);
            }
        };
        // The basis is fitted to a fixed, evenly spaced sample of the
        // candidates: the same triples whatever the thread count.
        let total: usize = candidates.iter().map(|c| c.triples.len()).sum();
        let stride = (total / 8192).max(1);
        let mut sample = Vec::new();
        let mut buf = vec![0f32; input];
        for c in candidates {
            for t in c.triples.iter().step_by(stride) {
                concat(*t, &mut buf);
                sample.extend_from_slice(&buf);
            }
        }
        let pca = Pca::fit(&sample, input, SPARSE_DIMS);
        let projector = Projector::new(&for_unweighted(&pca, 4 * d, weights));
        let mut offsets = [0f32; SPARSE_DIMS];
        for (o, m) in offsets.iter_mut().zip(pca.mean_offsets()) {
            *o = m;
        }
        let pixels = dims.len();
        let shares = [0, 1, 2].map(|p| {
            (0..pixels as u32)
                .into_par_iter()
                .map_init(
                    || vec![0f32; 4 * d],
                    |buf, c| {
                        diagonals(&appearance[p], dims, h, c, buf);
                        buf.iter_mut().for_each(|v| *v *= weights[p]);
                        let mut s = [0f32; SPARSE_DIMS];
                        for (j, o) in s.iter_mut().enumerate().take(pca.dims) {
                            let row =
                                &pca.basis[j * input + 4 * d * p..j * input + 4 * d * (p + 1)];
                            *o = dot(buf, row);
                        }
                        s
                    },
                )
                .collect::<Vec<_>>()
        });
        // Candidates are scored exactly like coherent triples: from their
        // three shares, which also costs far less than a projection each.
        let sum = |t: [u32; 3]| {
            let mut v = [0f32; SPARSE_DIMS];
            for (j, o) in v.iter_mut().enumerate() {
                *o = shares[0][t[0] as usize][j]
                    + shares[1][t[1] as usize][j]
                    + shares[2][t[2] as usize][j]
                    - offsets[j];
            }
            v
        };
        let mut max = 1e-6f32;
        for c in candidates {
            for t in c.triples.iter().step_by(stride) {
                for v in sum(*t) {
                    max = max.max(v.abs());
                }
            }
        }
        let scale = 127.0 / max;
        let best = |p: usize, c: usize| -> BestTriples {
            let all = &candidates[p].triples[candidates[p].range(c as u32)];
            debug_assert!(!all.is_empty(), "coherence filtering keeps a candidate");
            let last = all.len().clamp(1, BEST_CANDIDATES) - 1;
            std::array::from_fn(|i| all.get(i.min(last)).copied().unwrap_or([0; 3]))
        };
        let triples = [0, 1, 2].map(|p| (0..pixels).map(|c| best(p, c)).collect::<Vec<_>>());
        let vectors = [0, 1, 2].map(|p| {
            triples[p]
                .par_iter()
                .map(|ts| BestVectors(ts.map(|t| quantise_vector(&sum(t), scale))))
                .collect()
        });
        SparseTables {
            dims: d,
            projector,
            scale,
            shares,
            offsets,
            vectors,
            triples,
        }
    }

    /// Appearance dimensions per location.
    #[inline]
    pub fn location_dims(&self) -> usize {
        self.dims
    }

    /// Quantisation scale: vector units per appearance unit.
    #[inline]
    pub fn scale(&self) -> f32 {
        self.scale
    }

    /// The best candidates of pixel `c` in plane `p`: their vectors.
    #[inline]
    pub fn best_vectors(&self, p: usize, c: u32) -> &BestVectors {
        &self.vectors[p][c as usize]
    }

    /// The best candidates of pixel `c` in plane `p`: their triples.
    #[inline]
    pub fn best_triples(&self, p: usize, c: u32) -> &BestTriples {
        &self.triples[p][c as usize]
    }

    /// Projects and quantises a query (12 locations of
    /// [`SparseTables::location_dims`] floats).
    #[inline]
    pub fn query(&self, locations: &[f32]) -> SparseVector {
        let mut out = [0f32; SPARSE_DIMS];
        self.projector.project(locations, &mut out);
        quantise_vector(&out, self.scale)
    }

    /// The quantised vector of any triple, from its three shares.
    #[inline]
    pub fn triple_vector(&self, t: [u32; 3]) -> SparseVector {
        let mut v = [0f32; SPARSE_DIMS];
        for (j, o) in v.iter_mut().enumerate() {
            *o = self.shares[0][t[0] as usize][j]
                + self.shares[1][t[1] as usize][j]
                + self.shares[2][t[2] as usize][j]
                - self.offsets[j];
        }
        quantise_vector(&v, self.scale)
    }

    /// Plane `p`'s share of pixel `c` (for prefetching).
    #[inline]
    pub fn share(&self, p: usize, c: u32) -> &[f32; SPARSE_DIMS] {
        &self.shares[p][c as usize]
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        (0..3)
            .map(|p| {
                self.shares[p].len() * 4 * SPARSE_DIMS
                    + self.vectors[p].len() * std::mem::size_of::<BestVectors>()
                    + self.triples[p].len() * std::mem::size_of::<BestTriples>()
            })
            .sum()
    }
}

/// `pca`, fitted to inputs whose block p (`block` floats) was scaled by
/// `weights[p]`, made to take unscaled inputs: queries are projected to
/// what the weighted input gives, without being weighted first.
fn for_unweighted(pca: &Pca, block: usize, weights: [f32; 3]) -> Pca {
    let mut out = pca.clone();
    for (i, m) in out.mean.iter_mut().enumerate() {
        let w = weights[i / block];
        *m = if w > 0.0 { *m / w } else { 0.0 };
    }
    for row in out.basis.chunks_exact_mut(pca.input) {
        for (i, b) in row.iter_mut().enumerate() {
            *b *= weights[i / block];
        }
    }
    out
}

fn quantise_vector(v: &[f32; SPARSE_DIMS], scale: f32) -> SparseVector {
    v.map(|x| super::quantise(x, scale))
}

/// Squared distance between two quantised vectors.
#[inline(always)]
pub fn sparse_distance(a: &SparseVector, b: &SparseVector) -> u32 {
    let e: [i16; SPARSE_DIMS] = std::array::from_fn(|j| a[j] as i16 - b[j] as i16);
    super::sum_of_squares(&e)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_candidates_vector_is_its_triples_vector_and_fits_a_byte() {
        use crate::exemplar::{Exemplar, ExemplarSet};
        let rgb: Vec<u8> = (0..24 * 24 * 3u32)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 24) as u8)
            .collect();
        let set = ExemplarSet::single(Exemplar::from_rgb(24, 24, &rgb).unwrap());
        let params = crate::AnalysisParams {
            levels: 2,
            ..Default::default()
        };
        let c = crate::Candidates::compute(&set, &params, &|_, _| {}).unwrap();
        for k in 0..2 {
            let level = c.level(k);
            let tables = level.sparse_tables(c.dims(), k);
            for p in 0..3 {
                let cands = level.candidates(p);
                for px in 0..c.dims().len() as u32 {
                    let all = &cands.triples[cands.range(px)];
                    let best = tables.best_triples(p, px);
                    let vectors = tables.best_vectors(p, px);
                    for i in 0..BEST_CANDIDATES {
                        // The best first, the last repeated.
                        assert_eq!(best[i], all[i.min(all.len() - 1)]);
                        assert_eq!(vectors.0[i], tables.triple_vector(best[i]));
                    }
                }
            }
            // The quantised vectors span the byte range without clipping
            // most of them.
            let clipped = (0..3)
                .flat_map(|p| &tables.vectors[p])
                .flat_map(|b| b.0.iter().flatten())
                .filter(|&&b| b == 0 || b == 255)
                .count();
            assert!(clipped * 100 < c.dims().len() * BEST_CANDIDATES * SPARSE_DIMS * 3);
        }
    }
}
