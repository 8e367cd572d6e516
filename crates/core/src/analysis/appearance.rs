//! Appearance space (Lefebvre & Hoppe 2006): each exemplar pixel at each
//! level is described by its N×N RGB neighbourhood (sampled at the level's
//! spacing) projected by PCA to a few dimensions. Matching voxel
//! neighbourhoods against exemplar pixels then costs a handful of
//! multiply-adds instead of 3·N² per comparison.

use crate::analysis::stack::{GaussianStack, spacing};
use crate::simd;
use nalgebra::{DMatrix, SymmetricEigen};
use rayon::prelude::*;

/// A PCA basis: `mean` and `dims` row vectors of length `input`.
#[derive(Clone, Debug, PartialEq)]
pub struct Pca {
    /// Length of input vectors.
    pub input: usize,
    /// Number of output dimensions.
    pub dims: usize,
    /// Mean input vector.
    pub mean: Vec<f32>,
    /// `dims` rows of `input` weights each, strongest component first.
    pub basis: Vec<f32>,
}

impl Pca {
    /// Fits a basis to `samples` (each of length `input`), keeping `dims`
    /// components. Eigenvector signs are normalised (largest-magnitude
    /// weight positive) so the basis does not depend on solver details.
    pub fn fit(samples: &[f32], input: usize, dims: usize) -> Pca {
        let n = samples.len() / input;
        let mut mean = vec![0f64; input];
        for s in samples.chunks_exact(input) {
            for (m, &v) in mean.iter_mut().zip(s) {
                *m += v as f64;
            }
        }
        for m in &mut mean {
            *m /= n.max(1) as f64;
        }
        let upper = covariance_upper(samples, input, &mean);
        let cov = DMatrix::<f64>::from_fn(input, input, |i, j| {
            let (i, j) = (i.min(j), i.max(j));
            upper[i * input + j]
        });
        let eig = SymmetricEigen::new(cov);
        let mut order: Vec<usize> = (0..input).collect();
        order.sort_by(|&a, &b| {
            eig.eigenvalues[b]
                .partial_cmp(&eig.eigenvalues[a])
                .unwrap_or(std::cmp::Ordering::Equal)
                .then(a.cmp(&b))
        });
        let dims = dims.min(input);
        let mut basis = Vec::with_capacity(dims * input);
        for &c in order.iter().take(dims) {
            let col = eig.eigenvectors.column(c);
            let mut big = 0usize;
            for i in 0..input {
                if col[i].abs() > col[big].abs() + 1e-12 {
                    big = i;
                }
            }
            let sign = if col[big] < 0.0 { -1.0 } else { 1.0 };
            basis.extend(col.iter().map(|&v| (v * sign) as f32));
        }
        Pca {
            input,
            dims,
            mean: mean.iter().map(|&m| m as f32).collect(),
            basis,
        }
    }

    /// Projects one input vector into `out` (length `dims`).
    #[inline]
    pub fn project(&self, v: &[f32], out: &mut [f32]) {
        for (d, o) in out.iter_mut().enumerate().take(self.dims) {
            let row = &self.basis[d * self.input..(d + 1) * self.input];
            *o = dot(v, row) - dot(&self.mean, row);
        }
    }

    /// The projected mean: what [`Pca::project`] subtracts.
    pub fn mean_offsets(&self) -> Vec<f32> {
        (0..self.dims)
            .map(|d| {
                dot(
                    &self.mean,
                    &self.basis[d * self.input..(d + 1) * self.input],
                )
            })
            .collect()
    }
}

/// Samples that go through a row of the scatter matrix together.
const BLOCK: usize = 4;

/// The upper triangle of the centred samples' scatter matrix (row-major,
/// `input` × `input`; the lower triangle is left 0). Each entry sums its
/// products in sample order, one product at a time (none fused), so the
/// floats do not depend on the blocking, the threads or the CPU: rows are
/// shared out among threads, and samples go [`BLOCK`] at a time through
/// each row, which is read and written once per block. Products with a
/// zero factor are added too: a sum that starts at +0 never becomes −0,
/// so adding ±0 leaves it as it is.
fn covariance_upper(samples: &[f32], input: usize, mean: &[f64]) -> Vec<f64> {
    // Rows per task: the triangle's rows shorten, so later tasks take more.
    const TASKS: usize = 16;
    let n = samples.len() / input;
    let mut centred = vec![0f64; n.div_ceil(BLOCK) * BLOCK * input];
    centred
        .par_chunks_mut(input)
        .zip(samples.par_chunks_exact(input))
        .for_each(|(c, s)| {
            for (c, (&v, &m)) in c.iter_mut().zip(s.iter().zip(mean)) {
                *c = v as f64 - m;
            }
        });
    let mut upper = vec![0f64; input * input];
    // Row boundaries with about equal areas of the triangle.
    let mut bounds = vec![0usize];
    let area = |i: usize| (input - i) * (input - i);
    for t in 1..TASKS {
        let target = area(0) * (TASKS - t) / TASKS;
        let i = (0..input).find(|&i| area(i) <= target).unwrap_or(input);
        if i > *bounds.last().expect("starts at 0") {
            bounds.push(i);
        }
    }
    bounds.push(input);
    let mut rows: Vec<(usize, &mut [f64])> = Vec::new();
    let mut rest = upper.as_mut_slice();
    for w in bounds.windows(2) {
        let (chunk, tail) = rest.split_at_mut((w[1] - w[0]) * input);
        rows.push((w[0], chunk));
        rest = tail;
    }
    let avx = simd::avx();
    rows.into_par_iter().for_each(|(first, chunk)| {
        #[cfg(target_arch = "x86_64")]
        if avx {
            // SAFETY: `avx` is only set when the CPU has AVX.
            #[allow(unsafe_code)]
            unsafe {
                scatter_rows_avx(&centred, n, input, first, chunk)
            };
            return;
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = avx;
        scatter_rows(&centred, n, input, first, chunk);
    });
    upper
}

/// [`scatter_rows`] compiled for AVX (the same floats: separate multiplies
/// and adds, lane by lane).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[allow(unsafe_code)]
fn scatter_rows_avx(centred: &[f64], n: usize, input: usize, first: usize, chunk: &mut [f64]) {
    scatter_rows(centred, n, input, first, chunk)
}

/// Adds every sample's products to rows `first..` of the upper triangle
/// (`chunk`, whole rows), [`BLOCK`] samples at a time; `centred` is padded
/// with zero samples to a whole block, whose products are left out.
#[inline(always)]
fn scatter_rows(centred: &[f64], n: usize, input: usize, first: usize, chunk: &mut [f64]) {
    const _: () = assert!(BLOCK == 4, "the loop below is written out for four");
    for (b, four) in centred.chunks_exact(BLOCK * input).enumerate() {
        let live = (n - b * BLOCK).min(BLOCK);
        let (s0, rest) = four.split_at(input);
        let (s1, rest) = rest.split_at(input);
        let (s2, s3) = rest.split_at(input);
        for (r, row) in chunk.chunks_exact_mut(input).enumerate() {
            let i = first + r;
            let (a0, a1, a2, a3) = (s0[i], s1[i], s2[i], s3[i]);
            let row = &mut row[i..];
            let (s0, s1, s2, s3) = (&s0[i..], &s1[i..], &s2[i..], &s3[i..]);
            if live == 4 {
                for j in 0..row.len() {
                    let mut o = row[j];
                    o += a0 * s0[j];
                    o += a1 * s1[j];
                    o += a2 * s2[j];
                    o += a3 * s3[j];
                    row[j] = o;
                }
            } else {
                let (a, s) = ([a0, a1, a2, a3], [s0, s1, s2, s3]);
                for (&a, s) in a.iter().zip(s).take(live) {
                    for (o, &v) in row.iter_mut().zip(s) {
                        *o += a * v;
                    }
                }
            }
        }
    }
}

/// A [`Pca`] laid out for projecting one vector at a time into all its
/// outputs at once: the basis is transposed into blocks of four outputs, so
/// each input is broadcast once per block instead of being read once per
/// output. Each output keeps [`dot`]'s eight accumulators and summation
/// order, so the results are the same floats as [`Pca::project`].
#[derive(Clone, Debug)]
pub struct Projector {
    input: usize,
    dims: usize,
    /// Per block of four outputs, `input` rows of four weights.
    blocks: Vec<[f32; 4]>,
    /// The same weights in blocks of eight outputs, for CPUs with AVX
    /// (empty without): one 256-bit register per accumulator lane.
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    wide: Vec<[f32; 8]>,
    /// The projected mean, padded to whole blocks.
    offsets: Vec<f32>,
}

impl Projector {
    /// Transposes `pca`'s basis.
    pub fn new(pca: &Pca) -> Projector {
        let nb = pca.dims.div_ceil(4);
        let mut blocks = vec![[0f32; 4]; nb * pca.input];
        for d in 0..pca.dims {
            for i in 0..pca.input {
                blocks[(d / 4) * pca.input + i][d % 4] = pca.basis[d * pca.input + i];
            }
        }
        let mut wide = Vec::new();
        if simd::avx() {
            wide = vec![[0f32; 8]; pca.dims.div_ceil(8) * pca.input];
            for d in 0..pca.dims {
                for i in 0..pca.input {
                    wide[(d / 8) * pca.input + i][d % 8] = pca.basis[d * pca.input + i];
                }
            }
        }
        let mut offsets = pca.mean_offsets();
        offsets.resize(pca.dims.div_ceil(8) * 8, 0.0);
        Projector {
            input: pca.input,
            dims: pca.dims,
            blocks,
            wide,
            offsets,
        }
    }

    /// Projects `v` (`input` floats) into `out` (at least `dims` floats).
    #[inline]
    pub fn project(&self, v: &[f32], out: &mut [f32]) {
        #[cfg(target_arch = "x86_64")]
        if !self.wide.is_empty() {
            // SAFETY: `wide` is only filled when the CPU has AVX.
            #[allow(unsafe_code)]
            unsafe {
                simd::project_avx(&self.wide, &self.offsets, self.input, self.dims, v, out)
            };
            return;
        }
        self.project_narrow(v, out);
    }

    /// [`Projector::project`] in blocks of four outputs (SSE registers).
    fn project_narrow(&self, v: &[f32], out: &mut [f32]) {
        let v = &v[..self.input];
        let (chunks, tail) = v.as_chunks::<8>();
        for (b, rows) in self.blocks.chunks_exact(self.input).enumerate() {
            let (row_chunks, row_tail) = rows.as_chunks::<8>();
            let mut acc = [[0f32; 4]; 8];
            for (x, w) in chunks.iter().zip(row_chunks) {
                for l in 0..8 {
                    for d in 0..4 {
                        acc[l][d] += x[l] * w[l][d];
                    }
                }
            }
            let mut rest = [0f32; 4];
            for (&x, w) in tail.iter().zip(row_tail) {
                for d in 0..4 {
                    rest[d] += x * w[d];
                }
            }
            let n = (self.dims - 4 * b).min(4);
            for d in 0..n {
                let sum = ((acc[0][d] + acc[4][d]) + (acc[1][d] + acc[5][d]))
                    + ((acc[2][d] + acc[6][d]) + (acc[3][d] + acc[7][d]))
                    + rest[d];
                out[4 * b + d] = sum - self.offsets[4 * b + d];
            }
        }
    }
}

/// Sum of `term` over paired elements with eight independent accumulators,
/// so the compiler can keep it in SIMD registers; the summation order is
/// fixed, so results do not depend on the caller.
#[inline(always)]
fn sum8(a: &[f32], b: &[f32], term: impl Fn(f32, f32) -> f32) -> f32 {
    let n = a.len().min(b.len());
    let (ca, ta) = a[..n].as_chunks::<8>();
    let (cb, tb) = b[..n].as_chunks::<8>();
    let mut acc = [0f32; 8];
    for (x, y) in ca.iter().zip(cb) {
        for l in 0..8 {
            acc[l] += term(x[l], y[l]);
        }
    }
    let mut tail = 0f32;
    for (x, y) in ta.iter().zip(tb) {
        tail += term(*x, *y);
    }
    ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7])) + tail
}

/// Dot product (see [`sum8`]).
#[inline]
pub fn dot(a: &[f32], b: &[f32]) -> f32 {
    sum8(a, b, |x, y| x * y)
}

/// Squared L2 distance (see [`sum8`]).
#[inline]
pub fn sq_dist(a: &[f32], b: &[f32]) -> f32 {
    sum8(a, b, |x, y| (x - y) * (x - y))
}

/// Gathers the N×N neighbourhood of (x, y) at level `k` (spacing 2^k),
/// row by row (v outer, u inner): per pixel its RGB colour, then its
/// feature distance when the stack has one ([`GaussianStack::channels`]).
pub fn neighbourhood(stack: &GaussianStack, k: usize, n: u32, x: i64, y: i64, out: &mut [f32]) {
    let r = (n / 2) as i64;
    let h = spacing(k) as i64;
    let (w, hh) = (stack.width() as i64, stack.height() as i64);
    let feature = stack.feature_level(k);
    let mut o = 0;
    for j in -r..=r {
        for i in -r..=r {
            let (px, py) = (x + i * h, y + j * h);
            out[o..o + 3].copy_from_slice(&stack.at(k, px, py));
            o += 3;
            if let Some(f) = feature {
                out[o] = f[(py.rem_euclid(hh) * w + px.rem_euclid(w)) as usize];
                o += 1;
            }
        }
    }
}

/// Appearance vectors of every pixel of one plane at one level.
#[derive(Clone, Debug, PartialEq)]
pub struct AppearanceLevel {
    /// The neighbourhood PCA.
    pub pca: Pca,
    /// Values per neighbourhood pixel: 3 colours, and a feature distance
    /// when the stack has one.
    pub channels: usize,
    /// `dims` floats per pixel, row-major pixels.
    pub vectors: Vec<f32>,
}

impl AppearanceLevel {
    /// Vector of pixel index `i`.
    #[inline]
    pub fn vector(&self, i: usize) -> &[f32] {
        &self.vectors[i * self.pca.dims..(i + 1) * self.pca.dims]
    }
}

/// All N×N neighbourhoods of a level, flattened.
pub fn all_neighbourhoods(stack: &GaussianStack, k: usize, n: u32) -> Vec<f32> {
    let (w, h) = (stack.width() as i64, stack.height() as i64);
    let len = (n * n) as usize * stack.channels();
    let mut all = vec![0f32; (w * h) as usize * len];
    for (i, chunk) in all.chunks_exact_mut(len).enumerate() {
        let (x, y) = (i as i64 % w, i as i64 / w);
        neighbourhood(stack, k, n, x, y, chunk);
    }
    all
}

/// Projects every pixel's neighbourhood with `pca` (with the arithmetic of
/// [`Pca::project`]), a row of pixels per task.
pub fn project_all(stack: &GaussianStack, k: usize, n: u32, pca: &Pca) -> AppearanceLevel {
    let w = stack.width() as usize;
    let len = (n * n) as usize * stack.channels();
    let projector = Projector::new(pca);
    let mut vectors = vec![0f32; w * stack.height() as usize * pca.dims];
    vectors
        .par_chunks_mut(w * pca.dims)
        .enumerate()
        .for_each_init(
            || vec![0f32; len],
            |hood, (y, row)| {
                for (x, out) in row.chunks_exact_mut(pca.dims).enumerate() {
                    neighbourhood(stack, k, n, x as i64, y as i64, hood);
                    projector.project(hood, out);
                }
            },
        );
    AppearanceLevel {
        pca: pca.clone(),
        channels: stack.channels(),
        vectors,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The blocked, threaded scatter matrix is the same floats as one sum
    /// per entry in sample order, whatever the sample count (a partial
    /// last block) and with zeros among the values.
    #[test]
    fn scatter_matrix_sums_in_sample_order() {
        for (n, input) in [(1, 3), (7, 5), (64, 37), (103, 96)] {
            let samples: Vec<f32> = (0..n * input)
                .map(|i| {
                    let h = (i as u32).wrapping_mul(2_654_435_761) >> 8;
                    if h.is_multiple_of(5) {
                        0.0
                    } else {
                        (h % 2001) as f32 / 7.0 - 140.0
                    }
                })
                .collect();
            let mean: Vec<f64> = (0..input)
                .map(|j| (0..n).map(|s| samples[s * input + j] as f64).sum::<f64>() / n as f64)
                .collect();
            let got = covariance_upper(&samples, input, &mean);
            for i in 0..input {
                for j in 0..input {
                    let mut want = 0f64;
                    if j >= i {
                        for s in samples.chunks_exact(input) {
                            want += (s[i] as f64 - mean[i]) * (s[j] as f64 - mean[j]);
                        }
                    }
                    assert_eq!(
                        got[i * input + j].to_bits(),
                        want.to_bits(),
                        "{n}×{input}, ({i}, {j})"
                    );
                }
            }
        }
    }

    #[test]
    fn pca_recovers_dominant_direction() {
        // Points spread along (1, 2, 0) with small noise on the other axes.
        let mut s = Vec::new();
        for i in 0..200 {
            let t = i as f32 / 10.0 - 10.0;
            let noise = ((i * 37) % 11) as f32 / 100.0;
            s.extend_from_slice(&[t, 2.0 * t + noise, noise]);
        }
        let p = Pca::fit(&s, 3, 1);
        let b = &p.basis[0..3];
        let norm = (1.0f32 + 4.0).sqrt();
        assert!((b[0] - 1.0 / norm).abs() < 0.01 && (b[1] - 2.0 / norm).abs() < 0.01);
    }

    #[test]
    fn projector_gives_the_same_floats_as_project() {
        // Awkward sizes: a tail after the chunks of eight, partial blocks.
        for (input, dims) in [(75, 8), (24, 12), (27, 5), (7, 3), (40, 16)] {
            let samples: Vec<f32> = (0..input * 40)
                .map(|i| ((i * 7919) % 997) as f32 / 97.0 - 5.0 + (i % 13) as f32 * 0.01)
                .collect();
            let pca = Pca::fit(&samples, input, dims);
            let projector = Projector::new(&pca);
            for v in samples.chunks_exact(input) {
                let mut want = vec![0f32; dims];
                pca.project(v, &mut want);
                // The path this CPU takes (wide with AVX), and the narrow one.
                let mut got = vec![0f32; dims];
                projector.project(v, &mut got);
                let mut narrow = vec![0f32; dims];
                projector.project_narrow(v, &mut narrow);
                let bits = |x: &[f32]| x.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&want), bits(&got), "input {input}, dims {dims}");
                assert_eq!(bits(&want), bits(&narrow), "input {input}, dims {dims}");
            }
        }
    }
}
