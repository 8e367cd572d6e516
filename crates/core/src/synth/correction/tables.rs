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

use crate::analysis::appearance::{AppearanceLevel, Pca, Projector};
use crate::candidates::PlaneCandidates;
use crate::candidates::geometry::Dims;
use crate::simd;
use rayon::prelude::*;

/// Dimensions of a quantised sparse neighbourhood vector: one SSE register.
pub const SPARSE_DIMS: usize = 16;

/// The four diagonal locations of a plane, as (u, v) steps of the level
/// spacing.
pub const DIAGONALS: [(i64, i64); 4] = [(-1, -1), (1, -1), (-1, 1), (1, 1)];

/// A quantised sparse neighbourhood vector, as stored for the precomputed
/// candidates: round(v·scale) + 128, clamped to a byte.
pub type SparseVector = [u8; SPARSE_DIMS];

/// A sparse neighbourhood vector in the units of [`SparseVector`] with a
/// wider range: queries and coherent triples, which are not stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(C, align(32))]
pub struct WideVector(pub [i16; SPARSE_DIMS]);

/// The range of a [`WideVector`]'s values: wide enough that stretched
/// queries are not clipped, narrow enough that a squared distance over
/// sixteen of them cannot overflow.
pub const WIDE_RANGE: (i16, i16) = (-1024, 1280);

/// 3D candidates of a pixel that a correction tries (Dong et al.'s number
/// at the finest level), best crossbar error first.
pub const BEST_CANDIDATES: usize = 4;

/// A pixel's [`BEST_CANDIDATES`] 3D candidates, best first: their
/// vectors fill one cache line and their triples the next, found from the
/// pixel alone (no offsets table to read first), so a correction can
/// prefetch them as soon as it knows the pixel. A pixel with fewer
/// candidates repeats its last one.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(128))]
pub struct BestCandidates {
    /// Their vectors.
    pub vectors: [SparseVector; BEST_CANDIDATES],
    /// Their triples.
    pub triples: [[u32; 3]; BEST_CANDIDATES],
}

/// The sparse neighbourhood tables of one level.
#[derive(Clone, Debug)]
pub struct SparseTables {
    /// Appearance dimensions per location.
    dims: usize,
    /// From the 12 concatenated locations (xy, yz, zx; diagonals in
    /// [`DIAGONALS`] order) to [`SPARSE_DIMS`] dimensions.
    pca: Pca,
    /// Vector units per projected appearance unit.
    scale: f32,
    /// Each pixel's share of the projection per plane, in vector units:
    /// a triple's vector is the sum of its three shares and `bias`.
    shares: [Vec<WideVector>; 3],
    /// The byte offset 128 less the projected mean, in vector units.
    bias: WideVector,
    /// Each pixel's best candidates, per plane.
    best: [Vec<BestCandidates>; 3],
    /// Each plane's appearance vectors in fixed point, for building
    /// queries: a quarter of the floats' cache footprint. Planes of one
    /// exemplar share theirs (see `appearance_of`).
    appearance: Vec<Vec<i16>>,
    /// Index into `appearance` of each plane.
    appearance_of: [usize; 3],
    /// Fixed-point units per appearance unit, per plane.
    appearance_scale: [f32; 3],
}

/// Values per fixed-point appearance vector of `d` dimensions: one of
/// two fixed widths, which the correction is compiled for.
pub fn appearance_stride(d: usize) -> usize {
    if d <= 8 { 8 } else { 16 }
}

/// The largest fixed-point appearance coordinate: a sum of three fits in
/// i16 with room to spare.
const APPEARANCE_MAX: f32 = 8000.0;

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
        // Fitted to weighted locations, kept for unweighted ones: shares
        // and queries are projected from the locations as they are.
        let pca = for_unweighted(&Pca::fit(&sample, input, SPARSE_DIMS), 4 * d, weights);
        let offsets = pca.mean_offsets();
        let pixels = dims.len();
        let shares = [0, 1, 2].map(|p| {
            // The plane's columns of the basis, with no mean: each output
            // is the `dot` of the pixel's locations with its part of a
            // row (the projector keeps `dot`'s arithmetic).
            let part = Projector::new(&Pca {
                input: 4 * d,
                dims: pca.dims,
                mean: vec![0.0; 4 * d],
                basis: pca
                    .basis
                    .chunks_exact(input)
                    .flat_map(|row| &row[4 * d * p..4 * d * (p + 1)])
                    .copied()
                    .collect(),
            });
            (0..pixels as u32)
                .into_par_iter()
                .map_init(
                    || vec![0f32; 4 * d],
                    |buf, c| {
                        diagonals(&appearance[p], dims, h, c, buf);
                        let mut s = [0f32; SPARSE_DIMS];
                        part.project(buf, &mut s[..pca.dims]);
                        s
                    },
                )
                .collect::<Vec<_>>()
        });
        let mut max = 1e-6f32;
        for c in candidates {
            for t in c.triples.iter().step_by(stride) {
                for (j, offset) in offsets.iter().enumerate() {
                    let v = shares[0][t[0] as usize][j]
                        + shares[1][t[1] as usize][j]
                        + shares[2][t[2] as usize][j]
                        - offset;
                    max = max.max(v.abs());
                }
            }
        }
        let scale = 127.0 / max;
        // A share alone can exceed the range of a sum; ±4096 keeps a sum
        // of three and the bias within i16.
        let to_units = |v: f32| (v * scale).clamp(-4096.0, 4096.0).round() as i16;
        let shares = shares.map(|plane| {
            plane
                .into_iter()
                .map(|s| WideVector(s.map(to_units)))
                .collect::<Vec<_>>()
        });
        let mut bias = WideVector([128; SPARSE_DIMS]);
        for (b, &o) in bias.0.iter_mut().zip(&offsets) {
            *b -= to_units(o);
        }
        let best = |p: usize, c: usize| -> [[u32; 3]; BEST_CANDIDATES] {
            let all = &candidates[p].triples[candidates[p].range(c as u32)];
            debug_assert!(!all.is_empty(), "coherence filtering keeps a candidate");
            let last = all.len().clamp(1, BEST_CANDIDATES) - 1;
            std::array::from_fn(|i| all.get(i.min(last)).copied().unwrap_or([0; 3]))
        };
        let triples = [0, 1, 2].map(|p| (0..pixels).map(|c| best(p, c)).collect::<Vec<_>>());
        let mut appearance_of = [0, 1, 2];
        for p in 1..3 {
            if let Some(q) = (0..p).find(|&q| appearance[q] == appearance[p]) {
                appearance_of[p] = appearance_of[q];
            }
        }
        let appearance_scale = [0, 1, 2].map(|p| {
            let max = appearance[p]
                .vectors
                .iter()
                .fold(1e-6f32, |m, v| m.max(v.abs()));
            APPEARANCE_MAX / max
        });
        let stride = appearance_stride(d);
        let appearance_fixed = (0..3)
            .filter(|&p| appearance_of[p] == p)
            .map(|p| {
                let s = appearance_scale[p];
                let mut rows = vec![0i16; pixels * stride];
                for (row, v) in rows
                    .chunks_exact_mut(stride)
                    .zip(appearance[p].vectors.chunks_exact(d))
                {
                    for (o, x) in row.iter_mut().zip(v) {
                        *o = (x * s).round() as i16;
                    }
                }
                rows
            })
            .collect();
        // Planes that share vectors are numbered by the distinct ones.
        let mut distinct = [0usize; 3];
        for p in 0..3 {
            distinct[p] = if appearance_of[p] == p {
                (0..p).filter(|&q| appearance_of[q] == q).count()
            } else {
                distinct[appearance_of[p]]
            };
        }
        let mut tables = SparseTables {
            dims: d,
            pca,
            scale,
            shares,
            bias,
            best: [Vec::new(), Vec::new(), Vec::new()],
            appearance: appearance_fixed,
            appearance_of: distinct,
            appearance_scale,
        };
        // Candidates are scored exactly like coherent triples: from their
        // three shares.
        let best = triples.map(|triples| {
            triples
                .into_par_iter()
                .map(|triples| BestCandidates {
                    vectors: triples.map(|t| tables.stored_vector(t)),
                    triples,
                })
                .collect()
        });
        tables.best = best;
        tables
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

    /// The best candidates of pixel `c` in plane `p`.
    #[inline(always)]
    pub fn best(&self, p: usize, c: u32) -> &BestCandidates {
        &self.best[p][c as usize]
    }

    /// The projection from the 12 concatenated locations.
    #[inline]
    pub fn pca(&self) -> &Pca {
        &self.pca
    }

    /// The vector of any triple, from its three shares.
    #[inline(always)]
    pub fn triple_vector(&self, t: [u32; 3]) -> WideVector {
        self.sum_shares(self.shares_of(t))
    }

    /// The three shares of triple `t`, one per plane.
    #[inline(always)]
    pub fn shares_of(&self, t: [u32; 3]) -> [&WideVector; 3] {
        [
            &self.shares[0][t[0] as usize],
            &self.shares[1][t[1] as usize],
            &self.shares[2][t[2] as usize],
        ]
    }

    /// A triple's vector from its three shares (see
    /// [`SparseTables::shares_of`]).
    #[inline(always)]
    pub fn sum_shares(&self, [a, b, c]: [&WideVector; 3]) -> WideVector {
        simd::sum_clamped([a, b, c, &self.bias], WIDE_RANGE)
    }

    /// The vector of 12 concatenated locations (xy, yz, zx; [`DIAGONALS`]
    /// order), projected directly: what [`SparseTables::triple_vector`]
    /// gives from shares.
    #[cfg(test)]
    pub fn project(&self, locations: &[f32]) -> WideVector {
        let mut out = [0f32; SPARSE_DIMS];
        self.pca.project(locations, &mut out[..self.pca.dims]);
        let units = |v: f32| {
            ((v * self.scale).round() as i32 + 128).clamp(WIDE_RANGE.0 as i32, WIDE_RANGE.1 as i32)
                as i16
        };
        WideVector(out.map(units))
    }

    /// [`SparseTables::triple_vector`] clamped to bytes, as stored.
    pub fn stored_vector(&self, t: [u32; 3]) -> SparseVector {
        self.triple_vector(t).0.map(|v| v.clamp(0, 255) as u8)
    }

    /// Plane `p`'s appearance vectors in fixed point, each padded with
    /// zeros to [`appearance_stride`] values.
    #[inline(always)]
    pub fn appearance(&self, p: usize) -> &[i16] {
        &self.appearance[self.appearance_of[p]]
    }

    /// Fixed-point units per appearance unit of plane `p`.
    #[inline]
    pub fn appearance_scale(&self, p: usize) -> f32 {
        self.appearance_scale[p]
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        (0..3)
            .map(|p| {
                self.shares[p].len() * std::mem::size_of::<WideVector>()
                    + self.best[p].len() * std::mem::size_of::<BestCandidates>()
            })
            .sum::<usize>()
            + self.appearance.iter().map(|a| a.len() * 2).sum::<usize>()
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_candidates_vector_is_its_triples_vector_and_fits_a_byte() {
        use crate::analysis::exemplar::{Exemplar, ExemplarSet};
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
                    let best = &tables.best(p, px).triples;
                    let vectors = &tables.best(p, px).vectors;
                    for i in 0..BEST_CANDIDATES {
                        // The best first, the last repeated.
                        assert_eq!(best[i], all[i.min(all.len() - 1)]);
                        let wide = tables.triple_vector(best[i]);
                        assert_eq!(vectors[i], wide.0.map(|v| v.clamp(0, 255) as u8));
                    }
                }
            }
            // The quantised vectors span the byte range without clipping
            // most of them.
            let clipped = (0..3)
                .flat_map(|p| &tables.best[p])
                .flat_map(|b| b.vectors.iter().flatten())
                .filter(|&&b| b == 0 || b == 255)
                .count();
            assert!(clipped * 100 < c.dims().len() * BEST_CANDIDATES * SPARSE_DIMS * 3);
        }
    }
}
