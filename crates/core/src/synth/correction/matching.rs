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
//! whole neighbourhood in appearance space, which couples the planes.
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
//! [`BEST_CANDIDATES`](crate::synth::correction::tables::BEST_CANDIDATES)
//! precomputed 3D candidates. The coherent triples
//! (each direct neighbour's triple moved back) compete on equal terms,
//! with a penalty when their three exemplar colours disagree; a bonus for
//! them left upsampled blocks standing (docs/quality.md).
//! The best by distance of the quantised 12-location vectors wins.

use super::tables::{
    BestCandidates, DIAGONALS, SPARSE_DIMS, SparseTables, WIDE_RANGE, WideVector, appearance_stride,
};
use super::{
    CENTRE, Local, Near, Work, disagreement, gather_local, gather_near, in_plane_slot, near_slot,
};
use crate::analysis::stack::spacing;
use crate::candidates::geometry::{AXES, Dims};
use crate::candidates::{Candidates, Level};
use crate::params::SynthParams;
use crate::simd::{self, best_distances, prefetch};

/// Slots of the set of proposed pixels (keys tagged by plane): more than
/// [`MAX_PROPOSED`], so probing always ends.
const SEEN_SLOTS: usize = 256;

/// Adds `key` (non-zero) to the open-addressed set `seen`; whether it was
/// new.
#[inline(always)]
fn first_time(seen: &mut [u32; SEEN_SLOTS], key: u32) -> bool {
    let mut h = (key.wrapping_mul(0x9E37_79B1) >> 24) as usize;
    loop {
        let v = seen[h];
        if v == key {
            return false;
        }
        if v == 0 {
            seen[h] = key;
            return true;
        }
        h = (h + 1) % SEEN_SLOTS;
    }
}

/// The neighbourhood of the world frame, for the unguided correction
/// (which never reads it: its offsets are constants).
static WORLD: Local = Local {
    slot: [[0; 9]; 3],
    offset: [[0; 3]; 27],
    used: [0; 27],
    used_n: 0,
};

/// Largest appearance dimension count per location (`pca_dims` ≤ 16).
const MAX_LOCATION_DIMS: usize = 16;

/// Largest 2D similarity set (`similar_coarse`, `similar_fine` ≤ 8).
const MAX_SIMILAR: usize = 8;

/// Most proposed pixels: 9 in-plane neighbours in each of 3 planes, each
/// with its similarity set.
const MAX_PROPOSED: usize = 3 * 9 * MAX_SIMILAR;
const _: () = assert!(MAX_PROPOSED < SEEN_SLOTS);

/// Everything the appearance-space correction of one level reads.
pub struct AppearanceCorrector<'a> {
    level: &'a Level,
    /// The level's index (0 = finest).
    k: usize,
    tables: &'a SparseTables,
    dims: Dims,
    /// The level's spacing.
    h: i64,
    /// Values per fixed-point appearance vector.
    stride: usize,
    /// Each plane's appearance vectors, in fixed point.
    app: [&'a [i16]; 3],
    /// Each plane's exemplar colours at this level.
    plane_colours: [&'a [[f32; 3]]; 3],
    /// Weight of a coherent triple's colour disagreement, in quantised
    /// distance units per squared colour difference.
    consistency: f32,
    /// The query as one linear map (see [`QueryMap`]).
    map: QueryMap,
    /// Whether a pixel that several neighbours propose is scored once. At
    /// the coarse levels, where neighbours that do not continue each other
    /// still lie a pixel or two apart in an exemplar blurred over many,
    /// their similarity sets overlap: a sixth to a half of the proposals
    /// are repeats at spacing 4 and two thirds or more at spacing 8; at
    /// the fine levels too few are to pay for the test (docs/quality.md).
    /// The choice never changes a result: a repeat scores the same.
    distinct: bool,
    /// Whether the CPU has AVX2, which the same code compiles to in half
    /// the instructions (the results are the same: every float operation
    /// is done lane by lane in the same order, and none is fused).
    avx2: bool,
}

/// A query, from the sums that each of its 12 locations reads to its
/// quantised vector, folded into one linear map when the corrector is
/// made: the average of the three predictions, their colour offset, the
/// contrast stretch around the location's mean colour, the projection to
/// [`SPARSE_DIMS`] and the quantisation scale are all linear (or affine)
/// in the summed appearance vectors and the summed colour offsets.
struct QueryMap {
    /// Per location (plane-major, [`DIAGONALS`] order), a column for each
    /// of the [`appearance_stride`] values of the summed appearance
    /// vectors (zero beyond their dimensions), then 3 for the summed
    /// colour offsets.
    columns: Vec<[f32; SPARSE_DIMS]>,
    /// The affine part, with the byte bias of the stored vectors.
    constant: [f32; SPARSE_DIMS],
}

impl QueryMap {
    /// Each location is the mean o = (S + U·s)/3 of its three
    /// predictions: S the summed appearance vectors, s the summed colour
    /// offsets, and U·c the appearance vector of a neighbourhood of one
    /// colour c everywhere less the PCA's mean (`uniform`). Its mean
    /// colour is m = m₀ + Uᵀ·o / pixels (exactly, for a vector of the
    /// PCA's span), and the stretch by the gain g around the flat
    /// neighbourhood of m is o' = g·o − (g − 1)·(U·m − offsets), so
    /// o' = M·o + c with M = g·I − (g − 1)/pixels·U·Uᵀ and
    /// c = −(g − 1)·(U·m₀ − offsets). The query is the projection of the
    /// 12 o' less the projected mean, times the scale, plus the byte bias.
    fn new(level: &Level, tables: &SparseTables, gain: f32) -> QueryMap {
        let d = tables.location_dims();
        let w = appearance_stride(d);
        let pca = tables.pca();
        let scale = tables.scale() as f64;
        let g = gain as f64;
        let mut columns = vec![[0f32; SPARSE_DIMS]; 12 * (w + 3)];
        let mut constant = [0f64; SPARSE_DIMS];
        for (k, m) in constant.iter_mut().zip(pca.mean_offsets()) {
            *k = 128.0 - scale * m as f64;
        }
        for plane in 0..3 {
            let local = &level.appearance[plane].pca;
            // Each pixel's values: its colour, then its feature distance
            // if any, which a colour offset leaves as it is.
            let channels = level.appearance[plane].channels;
            let pixels = (local.input / channels) as f64;
            // U: d rows of 3 (the sum of each basis row's channel weights).
            let mut u = vec![[0f64; 3]; d];
            for (row, out) in u.iter_mut().enumerate() {
                for px in
                    local.basis[row * local.input..(row + 1) * local.input].chunks_exact(channels)
                {
                    for ch in 0..3 {
                        out[ch] += px[ch] as f64;
                    }
                }
            }
            let mut m0 = [0f64; 3];
            for px in local.mean.chunks_exact(channels) {
                for ch in 0..3 {
                    m0[ch] += px[ch] as f64 / pixels;
                }
            }
            let offsets = local.mean_offsets();
            let m = |i: usize, j: usize| {
                let uu: f64 = (0..3).map(|ch| u[i][ch] * u[j][ch]).sum();
                (if i == j { g } else { 0.0 }) - (g - 1.0) / pixels * uu
            };
            let c: Vec<f64> = (0..d)
                .map(|i| {
                    let level: f64 = (0..3).map(|ch| u[i][ch] * m0[ch]).sum();
                    -(g - 1.0) * (level - offsets[i] as f64)
                })
                .collect();
            for l in 0..4 {
                let block = (4 * plane + l) * d;
                let p = |k: usize, i: usize| pca.basis[k * pca.input + block + i] as f64;
                let out = &mut columns[(4 * plane + l) * (w + 3)..(4 * plane + l + 1) * (w + 3)];
                // The summed vectors arrive in fixed point.
                let fixed = tables.appearance_scale(plane) as f64;
                for k in 0..pca.dims {
                    for (j, column) in out[..d].iter_mut().enumerate() {
                        let v: f64 = (0..d).map(|i| p(k, i) * m(i, j)).sum();
                        column[k] = (scale * v / 3.0 / fixed) as f32;
                    }
                    for ch in 0..3 {
                        let v: f64 = (0..d)
                            .map(|i| p(k, i) * (0..d).map(|j| m(i, j) * u[j][ch]).sum::<f64>())
                            .sum();
                        out[w + ch][k] = (scale * v / 3.0) as f32;
                    }
                    constant[k] += scale * (0..d).map(|i| p(k, i) * c[i]).sum::<f64>();
                }
            }
        }
        QueryMap {
            columns,
            constant: constant.map(|v| v as f32),
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
            k,
            tables,
            dims: cands.dims(),
            h: spacing(k) as i64,
            stride: appearance_stride(tables.location_dims()),
            app: [0, 1, 2].map(|p| tables.appearance(p)),
            plane_colours: [0, 1, 2].map(|p| cands.stack(p).level(k)),
            consistency: params.consistency * scale * scale,
            map: QueryMap::new(level, tables, params.contrast),
            distinct: spacing(k) >= 4,
            avx2: simd::avx2(),
        }
    }

    /// The same corrector, made to run the portable code (to test that it
    /// agrees with the AVX2 one).
    #[cfg(test)]
    pub fn portable(mut self) -> Self {
        self.avx2 = false;
        self
    }

    /// The same corrector, scoring every proposed pixel however often it
    /// is proposed (`distinct` off) or once (on).
    #[cfg(test)]
    pub fn with_distinct(mut self, on: bool) -> Self {
        self.distinct = on;
        self
    }

    /// The level's index (0 = finest).
    pub(super) fn level_index(&self) -> usize {
        self.k
    }

    /// The level's spacing.
    pub(super) fn spacing(&self) -> i64 {
        self.h
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
        self.dispatch::<BY_WALL, false>(work, start, inside, p, &WORLD)
    }

    /// [`AppearanceCorrector::correct_with`] in the local frame `local`.
    #[inline(always)]
    pub(super) fn correct_local_with<const BY_WALL: bool>(
        &self,
        work: &Work,
        start: &Work,
        inside: [(i64, i64); 3],
        p: [i64; 3],
        local: &Local,
    ) -> [u32; 3] {
        self.dispatch::<BY_WALL, true>(work, start, inside, p, local)
    }

    /// Runs the AVX2 build where the CPU has it.
    #[inline(always)]
    fn dispatch<const BY_WALL: bool, const FIELD: bool>(
        &self,
        work: &Work,
        start: &Work,
        inside: [(i64, i64); 3],
        p: [i64; 3],
        local: &Local,
    ) -> [u32; 3] {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: `avx2` is only set when the CPU has AVX2.
            #[allow(unsafe_code)]
            return unsafe { self.correct_avx2::<BY_WALL, FIELD>(work, start, inside, p, local) };
        }
        self.correct_any::<BY_WALL, false, FIELD>(work, start, inside, p, local)
    }

    /// The correction for the texture's appearance width.
    #[inline(always)]
    fn correct_any<const BY_WALL: bool, const AVX2: bool, const FIELD: bool>(
        &self,
        work: &Work,
        start: &Work,
        inside: [(i64, i64); 3],
        p: [i64; 3],
        local: &Local,
    ) -> [u32; 3] {
        if self.stride == 8 {
            self.correct_portable::<BY_WALL, 8, AVX2, FIELD>(work, start, inside, p, local)
        } else {
            self.correct_portable::<BY_WALL, 16, AVX2, FIELD>(work, start, inside, p, local)
        }
    }

    /// [`AppearanceCorrector::correct_any`] compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[allow(unsafe_code)]
    fn correct_avx2<const BY_WALL: bool, const FIELD: bool>(
        &self,
        work: &Work,
        start: &Work,
        inside: [(i64, i64); 3],
        p: [i64; 3],
        local: &Local,
    ) -> [u32; 3] {
        self.correct_any::<BY_WALL, true, FIELD>(work, start, inside, p, local)
    }

    /// The correction, for appearance vectors of `W` values (see
    /// [`appearance_stride`]); `AVX2` when compiled for it; in the local
    /// frame `local` when `FIELD`, else on the world axes.
    #[inline(always)]
    fn correct_portable<
        const BY_WALL: bool,
        const W: usize,
        const AVX2: bool,
        const FIELD: bool,
    >(
        &self,
        work: &Work,
        start: &Work,
        inside: [(i64, i64); 3],
        p: [i64; 3],
        local: &Local,
    ) -> [u32; 3] {
        let h = self.h;
        let mut near = Near::default();
        if FIELD {
            gather_local::<BY_WALL>(work, start, inside, p, self.dims, local, &mut near);
        } else {
            gather_near::<BY_WALL>(work, start, inside, p, self.dims, h, &mut near);
        }
        let moved = &near.moved;
        // The near slot at in-plane offset (i, j) of a plane.
        let slot_of = |plane: usize, a: usize, i: i64, b: usize, j: i64| {
            if FIELD {
                local.slot(plane, i, j)
            } else {
                in_plane_slot(a, i, b, j)
            }
        };
        // The exemplar pixel each of the 3 predictions of each location
        // reads, by plane and location; their vectors are fetched while
        // the candidates are proposed. The predictions' colour offsets
        // are summed here, where their neighbours are at hand.
        let mut predicted = [[[0u32; 3]; 4]; 3];
        let mut offsets = [[[0f32; 3]; 4]; 3];
        // Written out per plane and location, so that the axes, the
        // offsets and the slots are constants when compiling.
        macro_rules! predict {
            ($plane:literal, $l:literal) => {{
                let plane: usize = $plane;
                let (a, b) = AXES[$plane];
                let (i, j) = DIAGONALS[$l];
                for (k, (du, dv)) in [(i, j), (i, 0), (0, j)].into_iter().enumerate() {
                    let slot = slot_of(plane, a, du, b, dv);
                    let t = near.triples[slot][plane];
                    let c = if FIELD {
                        let o = local.offset[slot];
                        self.dims.shift(t, i * h - o[a], j * h - o[b])
                    } else {
                        self.dims.shift(t, (i - du) * h, (j - dv) * h)
                    };
                    prefetch(&self.app[plane][c as usize * W..]);
                    predicted[plane][$l][k] = c;
                    let own = self.plane_colours[plane][t as usize];
                    for ch in 0..3 {
                        offsets[plane][$l][ch] += near.colours[slot][ch] - own[ch];
                    }
                }
            }};
        }
        predict!(0, 0);
        predict!(0, 1);
        predict!(0, 2);
        predict!(0, 3);
        predict!(1, 0);
        predict!(1, 1);
        predict!(1, 2);
        predict!(1, 3);
        predict!(2, 0);
        predict!(2, 1);
        predict!(2, 2);
        predict!(2, 3);
        // The proposed pixels and the coherent triples are known from the
        // triples alone: prefetch what scoring them reads, so the cache
        // misses overlap the query's arithmetic below. A pixel proposed
        // twice is scored twice unless `distinct` says otherwise.
        // Their candidate lists, kept from the prefetch (the entries
        // past `proposed_n` are placeholders).
        let mut proposed = [self.tables.best(0, 0); MAX_PROPOSED];
        let proposed_n = if self.distinct {
            self.propose::<FIELD, true>(moved, local, &mut proposed)
        } else {
            self.propose::<FIELD, false>(moved, local, &mut proposed)
        };
        // The coherent triples: each direct neighbour's triple moved back
        // (in a local frame, the in-plane neighbours the frame's planes
        // hold: Zhang et al.'s reduced candidate set). A neighbour that
        // continues the voxel moves back onto the voxel's own triple, which
        // is listed once; other repeats are scored twice, which is cheaper
        // than finding them.
        let own = near.triples[CENTRE];
        let mut coherent = [[u32::MAX; 3]; 27];
        let mut coherent_n = 0;
        if FIELD {
            for &k in local.used() {
                let t = moved[k as usize];
                if k as usize == CENTRE || t != own {
                    coherent[coherent_n] = t;
                    coherent_n += 1;
                }
            }
        } else {
            // Written out, so each slot is a constant; without a branch,
            // as whether a neighbour continues the voxel is hard to predict.
            macro_rules! keep {
                ($x:literal, $y:literal, $z:literal) => {{
                    let d: [i64; 3] = [$x, $y, $z];
                    let t = moved[near_slot(d)];
                    coherent[coherent_n] = t;
                    coherent_n += usize::from(d == [0; 3] || t != own);
                }};
            }
            for_each_direct!(keep);
        }
        let coherent = &coherent[..coherent_n];
        // Their shares, found once: fetched now, summed when scored.
        let mut shares = [self.tables.shares_of([0; 3]); 27];
        for (s, &t) in shares.iter_mut().zip(coherent) {
            *s = self.tables.shares_of(t);
            for share in *s {
                prefetch(std::slice::from_ref(share));
            }
        }

        let mut q = self.map.constant;
        for plane in 0..3 {
            let app = self.app[plane];
            for l in 0..DIAGONALS.len() {
                // W appearance sums, then 3 colour offsets.
                let mut sum = [0f32; MAX_LOCATION_DIMS + 3];
                for &c in &predicted[plane][l] {
                    let c = c as usize;
                    let row: &[i16; W] = app[c * W..(c + 1) * W].try_into().expect("W values");
                    for (o, &v) in sum[..W].iter_mut().zip(row) {
                        *o += v as f32;
                    }
                }
                sum[W..W + 3].copy_from_slice(&offsets[plane][l]);
                let columns = &self.map.columns[(4 * plane + l) * (W + 3)..][..W + 3];
                for (column, &x) in columns.iter().zip(&sum) {
                    for (o, w) in q.iter_mut().zip(column) {
                        *o += w * x;
                    }
                }
            }
        }
        // Rounds half up by truncating a non-negative value (no libm call).
        // `max` then `min` rather than `clamp`, which has to keep a NaN
        // and so is not vectorised; a NaN comes out as `lo` either way.
        let (lo, hi) = (WIDE_RANGE.0 as f32, WIDE_RANGE.1 as f32);
        let mut query = WideVector([0; SPARSE_DIMS]);
        for (o, v) in query.0.iter_mut().zip(q) {
            *o = ((v.max(lo).min(hi) - lo + 0.5) as i32 + lo as i32) as i16;
        }

        // The smallest (distance, triple); a penalty is only worth working
        // out for a triple that could still win.
        let mut best = (u32::MAX, [u32::MAX; 3]);
        for cands in &proposed[..proposed_n] {
            let dists = best_distances::<AVX2>(&cands.vectors, &query);
            if dists.iter().all(|&dist| dist > best.0) {
                continue;
            }
            for (&dist, &t) in dists.iter().zip(&cands.triples) {
                if dist < best.0 || (dist == best.0 && t < best.1) {
                    best = (dist, t);
                }
            }
        }
        // Coherent triples last: with the proposals' best known, few are
        // close enough to need their penalty worked out.
        for (&t, &s) in coherent.iter().zip(&shares) {
            let dist = simd::distance(&self.tables.sum_shares(s), &query);
            if dist <= best.0 {
                // Saturating: a large `consistency` can push the penalty to u32::MAX.
                let dist =
                    dist.saturating_add(disagreement(&self.plane_colours, self.consistency, t));
                if dist < best.0 || (dist == best.0 && t < best.1) {
                    best = (dist, t);
                }
            }
        }
        best.1
    }
}

impl<'a> AppearanceCorrector<'a> {
    /// The k-coherence proposals: each in-plane neighbour's pixel moved
    /// back by its offset (`moved`, by near slot) proposes its similarity
    /// set; their candidate lists go to `proposed`, whose length is
    /// returned. With `DISTINCT` a pixel proposed again is left out.
    #[inline(always)]
    fn propose<const FIELD: bool, const DISTINCT: bool>(
        &self,
        moved: &[[u32; 3]; 27],
        local: &Local,
        proposed: &mut [&'a BestCandidates; MAX_PROPOSED],
    ) -> usize {
        let mut n = 0;
        let mut seen = [0u32; SEEN_SLOTS];
        for (plane, &(a, b)) in AXES.iter().enumerate() {
            let mut bases = [u32::MAX; 9];
            let mut bases_n = 0;
            for j in -1..=1i64 {
                for i in -1..=1i64 {
                    let slot = if FIELD {
                        local.slot(plane, i, j)
                    } else {
                        in_plane_slot(a, i, b, j)
                    };
                    let base = moved[slot][plane];
                    // Coherent neighbours usually point at the same pixel.
                    if bases[..bases_n].contains(&base) {
                        continue;
                    }
                    bases[bases_n] = base;
                    bases_n += 1;
                    for &s in self.level.similar(plane, base) {
                        // Pixels are fewer than 2^30: the key is unique.
                        if DISTINCT && !first_time(&mut seen, (s << 2 | plane as u32) + 1) {
                            continue;
                        }
                        let best = self.tables.best(plane, s);
                        prefetch(std::slice::from_ref(best));
                        // The triples' line, for the candidates that win.
                        prefetch(&best.triples[2..]);
                        proposed[n] = best;
                        n += 1;
                    }
                }
            }
        }
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::exemplar::{Exemplar, ExemplarSet};
    use crate::synth::grid::{Box3, Grid};

    /// The AVX2 build of the correction and the portable one choose the
    /// same triple for every voxel, at every level and appearance width:
    /// bytes must not depend on the CPU (nor on whether repeated proposals
    /// are scored again).
    #[test]
    fn every_cpu_chooses_the_same_triples() {
        let rgb: Vec<u8> = (0..32 * 32 * 3u32)
            .map(|i| {
                ((i / 3 % 32) * 5 + (i / 96) * 3 + (i % 3) * 40) as u8
                    ^ (i.wrapping_mul(2_654_435_761) >> 27) as u8
            })
            .collect();
        let set = ExemplarSet::single(Exemplar::from_rgb(32, 32, &rgb).unwrap());
        for pca_dims in [8, 12] {
            let params = crate::AnalysisParams {
                levels: 2,
                pca_dims,
                ..Default::default()
            };
            let cands = Candidates::compute(&set, &params, &|_, _| {}).unwrap();
            let pixels = cands.dims().len() as u32;
            for k in 0..2 {
                let bounds = Box3::new([-3, 5, 2], [9, 8, 7]);
                let mut triples = Grid::new(bounds);
                for (i, t) in triples.data.iter_mut().enumerate() {
                    let i = i as u32;
                    *t = [
                        i * 7919 % pixels,
                        i * 104_729 % pixels,
                        i * 1_299_709 % pixels,
                    ];
                }
                let work = Work::new(&cands, k, triples);
                let synth = SynthParams::default();
                let fast = AppearanceCorrector::new(&cands, k, &synth);
                let portable = AppearanceCorrector::new(&cands, k, &synth).portable();
                // Repeated proposals score the same: leaving them out (or
                // not) changes nothing.
                let once = AppearanceCorrector::new(&cands, k, &synth).with_distinct(true);
                let again = AppearanceCorrector::new(&cands, k, &synth).with_distinct(false);
                let inside = [(i64::MIN, i64::MAX); 3];
                for z in bounds.lo[2] + 1..bounds.hi[2] - 1 {
                    for y in bounds.lo[1] + 1..bounds.hi[1] - 1 {
                        for x in bounds.lo[0] + 1..bounds.hi[0] - 1 {
                            let p = [x, y, z];
                            let t = fast.correct_with::<false>(&work, &work, inside, p);
                            assert_eq!(
                                t,
                                portable.correct_with::<false>(&work, &work, inside, p),
                                "level {k}, voxel {p:?}, {pca_dims} dimensions"
                            );
                            assert_eq!(t, once.correct_with::<false>(&work, &work, inside, p));
                            assert_eq!(t, again.correct_with::<false>(&work, &work, inside, p));
                        }
                    }
                }
            }
        }
    }
}
