//! Quality scores for synthesized texture slices.
//!
//! [`score_slice`] compares a synthesized 2D slice (RGB8) with the exemplar it
//! was synthesized from and reports three numbers, all "lower is better":
//!
//! * **coherence** – every slice patch should look like some exemplar patch;
//! * **completeness** – every exemplar patch should appear somewhere in the slice;
//! * **histogram** – the colour distributions should match.
//!
//! Patch distances are the mean squared difference per pixel-channel with
//! colours scaled to `0..=1`, so a distance lies in `0..=1`.
//!
//! [`anisotropy`] adds what patch distances miss: whether a slice is
//! stretched along one of its axes (streaks, extruded blocks) more than
//! the exemplar is along the matching axis. [`structure`] compares texture
//! statistics: the luminance's energy per octave band and per direction.
//!
//! # Nearest-patch search
//!
//! Exhaustive search over `p*p*3`-dimensional patch vectors is far too slow for
//! realistic sizes (a 256×256 slice against a 128×128 exemplar with 7×7
//! patches needs about 10¹¹ byte operations per direction), so the search is
//! approximate:
//!
//! 1. A deterministic sample of patches from both images (at most 2048 from
//!    each) gives a covariance matrix; its 16 leading principal directions are
//!    found by oversampled block power iteration followed by a Rayleigh–Ritz
//!    step (nalgebra's symmetric eigen solver on the small projected matrix).
//! 2. Every patch is reduced to its 16 principal coordinates plus the norm of
//!    its residual outside them. Euclidean distance between reduced vectors is
//!    a lower bound of the true patch distance. The database patches are
//!    indexed by a kd-tree over the reduced vectors. The tree is our own rather
//!    than kiddo's (used elsewhere in this crate): kiddo only answers exact
//!    k-nearest queries, which in 17 dimensions visit most leaves for noisy
//!    patches and make scoring several times slower than the leaf budget.
//! 3. The match of the query's left neighbour, shifted one pixel to the right,
//!    is tried first (synthesized textures are mostly coherent copies); a
//!    perfect match ends the search, otherwise its distance bounds it.
//! 4. The kd-tree yields the 16 reduced-space nearest neighbours, visiting at
//!    most 64 leaves, and these candidates are re-ranked by the exact distance
//!    in the full patch space, computed in integer arithmetic.
//!
//! Every reported patch distance is therefore the exact distance to a real
//! patch: the approximation can only overestimate the true nearest-patch
//! distance, never underestimate it. On smooth structured textures the
//! overestimate is typically 1–5 %; on patches dominated by per-pixel noise,
//! where 16 components capture little of the variance, it grows to 10–15 %.
//! An exact duplicate of a query patch always lies in the first leaf the
//! search visits, so a slice cut out of the (tiled) exemplar scores exactly 0.
//!
//! # Determinism
//!
//! All per-patch distances are integers summed exactly, and the floating-point
//! reductions (covariance, histograms) use a fixed chunking and a sequential
//! final sum, so results do not depend on the number of rayon threads.

#![deny(unsafe_code)]

mod structure;

pub use structure::{Structure, structure};

use crate::hash::mix;
use nalgebra::{DMatrix, SymmetricEigen};
use rayon::prelude::*;
use std::cmp::Ordering;

/// Number of principal components used for the approximate patch search.
const REDUCED_DIMS: usize = 16;
/// Number of reduced-space nearest neighbours re-ranked in the full patch space.
const CANDIDATES: usize = 16;
/// Maximum number of kd-tree leaves visited per query patch.
const MAX_LEAVES: usize = 64;
/// Number of bins per colour channel of the colour histogram.
const HISTOGRAM_BINS: usize = 8;

const LEAF_SIZE: usize = 8;
const SEARCH_DIMS: usize = REDUCED_DIMS + 1;
const PCA_SAMPLES_PER_IMAGE: usize = 2048;
const PCA_CHUNK: usize = 256;
const POWER_ITERATIONS: usize = 32;
const POWER_OVERSAMPLING: usize = 8;

// Every point of the first leaf a search visits must fit in the candidate list.
const _: () = assert!(LEAF_SIZE <= CANDIDATES);

/// Borrowed RGB8 image, row-major, 3 bytes per pixel.
#[derive(Clone, Copy, Debug)]
pub struct RgbView<'a> {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Pixel data, `width * height * 3` bytes, row-major, `R, G, B` per pixel.
    pub rgb: &'a [u8],
}

impl RgbView<'_> {
    fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }

    fn check(&self, what: &str) {
        assert!(
            self.rgb.len() >= self.pixel_count() * 3,
            "{what} buffer holds {} bytes, expected {} for {}x{} RGB8",
            self.rgb.len(),
            self.pixel_count() * 3,
            self.width,
            self.height
        );
    }

    fn pixel(&self, x: usize, y: usize) -> &[u8] {
        let i = (y * self.width as usize + x) * 3;
        &self.rgb[i..i + 3]
    }
}

/// How visible the seams of an image tiled 2×2 are (see [`tiling_seam`]).
#[derive(Clone, Debug, PartialEq)]
pub struct TilingSeam {
    /// Mean absolute luminance step across the vertical border (the last
    /// column to the first) and across the horizontal one (last row to
    /// first).
    pub border: [f64; 2],
    /// The same mean step between every other pair of neighbouring
    /// columns, then rows: the steps inside a tile, sorted.
    pub inside: Vec<f64>,
}

impl TilingSeam {
    /// Where the larger border step ranks among the steps inside: the
    /// fraction of them that are smaller (1: above every one of them).
    pub fn rank(&self) -> f64 {
        let b = self.border[0].max(self.border[1]);
        self.inside.iter().filter(|&&s| s < b).count() as f64 / self.inside.len().max(1) as f64
    }

    /// Whether both border steps lie within the distribution of the steps
    /// inside (no larger than the largest of them).
    pub fn within(&self) -> bool {
        let max = self.inside.last().copied().unwrap_or(0.0);
        self.border.iter().all(|&b| b <= max)
    }
}

/// The seams of `image` laid 2×2 (as a shader repeating a texture shows
/// it): the luminance step across each tile border, against the steps
/// between neighbouring columns and rows inside the tile. A tile that
/// continues across its borders has border steps like the inside ones; a
/// block cut from an aperiodic texture has a border between unrelated
/// voxels, a step larger than any inside.
pub fn tiling_seam(image: RgbView) -> TilingSeam {
    image.check("image");
    let (w, h) = (image.width as usize, image.height as usize);
    let lum = |x: usize, y: usize| {
        let p = image.pixel(x, y);
        crate::analysis::exemplar::luminance([p[0], p[1], p[2]])
    };
    let column_step =
        |a: usize, b: usize| (0..h).map(|y| (lum(a, y) - lum(b, y)).abs()).sum::<f64>() / h as f64;
    let row_step =
        |a: usize, b: usize| (0..w).map(|x| (lum(x, a) - lum(x, b)).abs()).sum::<f64>() / w as f64;
    let mut inside: Vec<f64> = (0..w.saturating_sub(1))
        .map(|x| column_step(x, x + 1))
        .chain((0..h.saturating_sub(1)).map(|y| row_step(y, y + 1)))
        .collect();
    inside.sort_by(f64::total_cmp);
    TilingSeam {
        border: [column_step(w - 1, 0), row_step(h - 1, 0)],
        inside,
    }
}

/// The grain of one window of an image (see [`grain_map`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WindowGrain {
    /// The window's centre, in pixels.
    pub centre: [f64; 2],
    /// Its grain: direction in degrees from u towards v, and coherence.
    pub grain: crate::Grain,
}

/// The dominant orientation of each `window`×`window` square of `image`
/// (whole squares only), from the structure tensor of its luminance: how a
/// synthesized slice's grain can be checked against a field.
pub fn grain_map(image: RgbView, window: u32) -> Vec<WindowGrain> {
    image.check("image");
    let n = window.max(2) as usize;
    let mut out = Vec::new();
    for wy in 0..image.height as usize / n {
        for wx in 0..image.width as usize / n {
            let (x0, y0) = (wx * n, wy * n);
            let grain = crate::Grain::of(n, n, false, |x, y| {
                let p = image.pixel(x0 + x, y0 + y);
                crate::analysis::exemplar::luminance([p[0], p[1], p[2]])
            });
            out.push(WindowGrain {
                centre: [x0 as f64 + n as f64 / 2.0, y0 as f64 + n as f64 / 2.0],
                grain,
            });
        }
    }
    out
}

/// The angle between two undirected lines given in degrees, 0 to 90.
pub fn line_angle(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(180.0);
    d.min(180.0 - d)
}

/// Scores of one slice against an exemplar; lower is better for all three.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SliceScores {
    /// Mean over slice patches of the squared L2 distance (per pixel-channel,
    /// colours in `0..=1`) to the nearest exemplar patch ("coherence": does
    /// every part of the slice look like the exemplar?).
    pub coherence: f64,
    /// Mean over exemplar patches of the squared L2 distance (per
    /// pixel-channel, colours in `0..=1`) to the nearest slice patch
    /// ("completeness": does the slice show everything the exemplar has?).
    pub completeness: f64,
    /// Total-variation distance between the normalised colour histograms
    /// (8×8×8 bins, i.e. the top 3 bits of each channel): half the L1
    /// distance, in `0..=1`.
    pub histogram: f64,
}

/// Scores `slice` against `exemplar` with `patch`×`patch` windows (7 is typical).
///
/// Exemplar patches are taken toroidally: every exemplar pixel is the centre of
/// a patch, wrapping around the borders. Slice patches are the windows fully
/// inside the slice.
///
/// `patch` is rounded down to an odd size (at least 1), and further clamped to
/// the largest odd size that fits inside the slice when the slice is smaller
/// than the window. If either image has no pixels, every score is `1.0`, the
/// worst possible value.
///
/// See the module documentation for the approximation used by the
/// nearest-patch search.
///
/// # Panics
///
/// Panics if an image buffer is shorter than `width * height * 3` bytes.
pub fn score_slice(slice: RgbView, exemplar: RgbView, patch: u32) -> SliceScores {
    slice.check("slice");
    exemplar.check("exemplar");
    if slice.pixel_count() == 0 || exemplar.pixel_count() == 0 {
        return SliceScores {
            coherence: 1.0,
            completeness: 1.0,
            histogram: 1.0,
        };
    }
    let fit = slice.width.min(slice.height);
    let mut p = patch.max(1).min(fit);
    if p.is_multiple_of(2) {
        p -= 1;
    }
    let p = p as usize;

    let (slice_set, exemplar_set) = rayon::join(
        || PatchSet::interior(slice, p),
        || PatchSet::toroidal(exemplar, p),
    );
    let basis = Basis::principal(&slice_set, &exemplar_set);
    let (slice_reduced, exemplar_reduced) = rayon::join(
        || basis.project(&slice_set),
        || basis.project(&exemplar_set),
    );
    let (slice_tree, exemplar_tree) = rayon::join(
        || KdTree::build(&slice_reduced, basis.dims),
        || KdTree::build(&exemplar_reduced, basis.dims),
    );
    let slice_side = Indexed {
        set: &slice_set,
        reduced: &slice_reduced,
        tree: &slice_tree,
    };
    let exemplar_side = Indexed {
        set: &exemplar_set,
        reduced: &exemplar_reduced,
        tree: &exemplar_tree,
    };
    let (coherence, completeness) = rayon::join(
        || mean_nearest_distance(&slice_side, &exemplar_side),
        || mean_nearest_distance(&exemplar_side, &slice_side),
    );
    SliceScores {
        coherence,
        completeness,
        histogram: histogram_distance(slice, exemplar),
    }
}

/// Builds a `width`×`height` RGB8 baseline image whose pixels are exemplar
/// pixels chosen independently per pixel.
///
/// The pixel at column `x`, row `y` copies the exemplar pixel selected by a hash
/// of `(seed, x, y)`, so the result is deterministic and has (up to sampling)
/// the exemplar's colour histogram but none of its structure. An empty exemplar
/// yields a black image.
///
/// # Panics
///
/// Panics if the exemplar buffer is shorter than
/// `exemplar.width * exemplar.height * 3` bytes.
pub fn shuffled_exemplar(exemplar: RgbView, width: u32, height: u32, seed: u64) -> Vec<u8> {
    exemplar.check("exemplar");
    let (w, h) = (width as usize, height as usize);
    let mut out = vec![0u8; w * h * 3];
    let n = exemplar.pixel_count() as u64;
    if n == 0 || w == 0 {
        return out;
    }
    let seed_hash = mix(seed ^ 0x5851_f42d_4c95_7f2d);
    out.par_chunks_mut(w * 3).enumerate().for_each(|(y, row)| {
        for (x, px) in row.chunks_exact_mut(3).enumerate() {
            let key = ((x as u64) << 32) | y as u64;
            let pick = (mix(seed_hash ^ mix(key)) % n) as usize;
            px.copy_from_slice(&exemplar.rgb[pick * 3..pick * 3 + 3]);
        }
    });
    out
}

/// Pixel distances at which [`directional_ratio`] compares pixels.
const ANISOTROPY_SHIFTS: [usize; 3] = [2, 4, 8];

/// How much faster an image changes down its columns (v) than along its
/// rows (u): the mean squared luminance difference between pixels 2, 4 and
/// 8 apart along v, over the same along u. Features stretched along v
/// (streaks) make it small, along u large. A constant image gives 1.
pub fn directional_ratio(image: RgbView) -> f64 {
    image.check("image");
    let (w, h) = (image.width as usize, image.height as usize);
    let luma: Vec<f64> = image.rgb[..w * h * 3]
        .chunks_exact(3)
        .map(|c| (c[0] as f64 + c[1] as f64 + c[2] as f64) / 3.0)
        .collect();
    let mean_sq = |du: usize, dv: usize| -> f64 {
        if du >= w || dv >= h {
            return 0.0;
        }
        let mut sum = 0.0;
        for y in 0..h - dv {
            for x in 0..w - du {
                let e = luma[(y + dv) * w + x + du] - luma[y * w + x];
                sum += e * e;
            }
        }
        sum / ((h - dv) * (w - du)) as f64
    };
    if w <= ANISOTROPY_SHIFTS[0] || h <= ANISOTROPY_SHIFTS[0] {
        // Too short along an axis to compare: no direction is preferred.
        return 1.0;
    }
    let along_v: f64 = ANISOTROPY_SHIFTS.iter().map(|&d| mean_sq(0, d)).sum();
    let along_u: f64 = ANISOTROPY_SHIFTS.iter().map(|&d| mean_sq(d, 0)).sum();
    if along_u == 0.0 || along_v == 0.0 {
        // Constant along one axis: as flat as the other only when both are.
        return if along_u == along_v {
            1.0
        } else if along_u == 0.0 {
            f64::MAX
        } else {
            f64::MIN_POSITIVE
        };
    }
    along_v / along_u
}

/// How far a slice's [`directional_ratio`] is from its exemplar's, as
/// |ln(slice ÷ exemplar)|: 0 when the slice is as (an)isotropic along its
/// u and v axes as the exemplar is along the matching axes, 0.3 when it is
/// 35 % off. Features extruded along one axis of the slice raise it, which
/// the patch scores barely see (a streak is made of exemplar colours).
pub fn anisotropy(slice: RgbView, exemplar: RgbView) -> f64 {
    (directional_ratio(slice).ln() - directional_ratio(exemplar).ln()).abs()
}

fn histogram(image: RgbView) -> Vec<f64> {
    let shift = 8 - HISTOGRAM_BINS.trailing_zeros();
    let mut counts = vec![0u64; HISTOGRAM_BINS.pow(3)];
    for px in image.rgb[..image.pixel_count() * 3].chunks_exact(3) {
        let bin = |c: u8| (c >> shift) as usize;
        counts[(bin(px[0]) * HISTOGRAM_BINS + bin(px[1])) * HISTOGRAM_BINS + bin(px[2])] += 1;
    }
    let total = image.pixel_count() as f64;
    counts.into_iter().map(|c| c as f64 / total).collect()
}

fn histogram_distance(a: RgbView, b: RgbView) -> f64 {
    let (ha, hb) = (histogram(a), histogram(b));
    let l1: f64 = ha.iter().zip(&hb).map(|(x, y)| (x - y).abs()).sum();
    (0.5 * l1).clamp(0.0, 1.0)
}

/// All patches of one image as flat `u8` vectors laid out on a grid of
/// `cols`×`rows` patch positions.
struct PatchSet {
    dim: usize,
    cols: usize,
    rows: usize,
    toroidal: bool,
    data: Vec<u8>,
}

impl PatchSet {
    /// Windows fully inside `image`, indexed by their top-left corner.
    fn interior(image: RgbView, p: usize) -> Self {
        let (w, h) = (image.width as usize, image.height as usize);
        let (cols, rows) = (w + 1 - p, h + 1 - p);
        Self::collect(cols, rows, p, false, |x, y| image.pixel(x, y))
    }

    /// One window centred on every pixel of `image`, wrapping at the borders.
    fn toroidal(image: RgbView, p: usize) -> Self {
        let (w, h) = (image.width as usize, image.height as usize);
        let r = p / 2;
        Self::collect(w, h, p, true, |x, y| {
            image.pixel((x + w * p - r) % w, (y + h * p - r) % h)
        })
    }

    fn collect<'a, F>(cols: usize, rows: usize, p: usize, toroidal: bool, pixel: F) -> Self
    where
        F: Fn(usize, usize) -> &'a [u8] + Sync,
    {
        let dim = p * p * 3;
        let mut data = vec![0u8; cols * rows * dim];
        data.par_chunks_mut(cols * dim)
            .enumerate()
            .for_each(|(y, row)| {
                for (x, out) in row.chunks_exact_mut(dim).enumerate() {
                    for (dy, line) in out.chunks_exact_mut(p * 3).enumerate() {
                        for (dx, px) in line.chunks_exact_mut(3).enumerate() {
                            px.copy_from_slice(pixel(x + dx, y + dy));
                        }
                    }
                }
            });
        PatchSet {
            dim,
            cols,
            rows,
            toroidal,
            data,
        }
    }

    fn len(&self) -> usize {
        self.cols * self.rows
    }

    fn patch(&self, i: usize) -> &[u8] {
        &self.data[i * self.dim..(i + 1) * self.dim]
    }

    /// The patch one pixel to the right of patch `i`, if there is one.
    fn right_of(&self, i: usize) -> Option<usize> {
        let (x, y) = (i % self.cols, i / self.cols);
        if x + 1 < self.cols {
            Some(i + 1)
        } else if self.toroidal {
            Some(y * self.cols)
        } else {
            None
        }
    }
}

fn patch_distance(a: &[u8], b: &[u8]) -> u32 {
    a.iter()
        .zip(b)
        .map(|(&x, &y)| {
            let d = i32::from(x) - i32::from(y);
            (d * d) as u32
        })
        .sum()
}

/// Orthonormal projection onto the leading principal directions of patch
/// space, extended by the norm of the residual outside those directions.
///
/// Euclidean distances between projected patches are lower bounds of the
/// distances between the patches themselves (colours in `0..=1`).
struct Basis {
    /// Number of coordinates of a projected patch: the principal components
    /// followed by the residual norm.
    dims: usize,
    patch_dim: usize,
    /// Mean patch, colours in `0..=1`.
    mean: Vec<f32>,
    /// `patch_dim × (dims - 1)`, row-major.
    weights: Vec<f32>,
}

impl Basis {
    fn principal(a: &PatchSet, b: &PatchSet) -> Self {
        let n = a.dim;
        let components = REDUCED_DIMS.min(n);
        let mut samples: Vec<&[u8]> = Vec::new();
        for set in [a, b] {
            let step = set.len().div_ceil(PCA_SAMPLES_PER_IMAGE).max(1);
            samples.extend((0..set.len()).step_by(step).map(|i| set.patch(i)));
        }
        let (mean, cov) = covariance(&samples, n);
        let vectors = leading_eigenvectors(&cov, n, components);
        let mut weights = vec![0f32; n * components];
        for (c, v) in vectors.iter().enumerate() {
            for (d, &x) in v.iter().enumerate() {
                weights[d * components + c] = x as f32;
            }
        }
        Basis {
            dims: components + 1,
            patch_dim: n,
            mean: mean.iter().map(|&m| (m / 255.0) as f32).collect(),
            weights,
        }
    }

    fn project(&self, set: &PatchSet) -> Vec<f32> {
        let components = self.dims - 1;
        let mut out = vec![0f32; set.len() * self.dims];
        out.par_chunks_mut(self.dims * 64)
            .zip(set.data.par_chunks(self.patch_dim * 64))
            .for_each(|(out, patches)| {
                for (o, patch) in out
                    .chunks_exact_mut(self.dims)
                    .zip(patches.chunks_exact(self.patch_dim))
                {
                    let mut acc = [0f32; REDUCED_DIMS];
                    let acc = &mut acc[..components];
                    let mut norm2 = 0f32;
                    for ((&v, &m), w) in patch
                        .iter()
                        .zip(&self.mean)
                        .zip(self.weights.chunks_exact(components))
                    {
                        let v = f32::from(v) / 255.0 - m;
                        norm2 += v * v;
                        for (a, &w) in acc.iter_mut().zip(w) {
                            *a += v * w;
                        }
                    }
                    let projected: f32 = acc.iter().map(|a| a * a).sum();
                    o[..components].copy_from_slice(acc);
                    o[components] = (norm2 - projected).max(0.0).sqrt();
                }
            });
        out
    }
}

/// Mean and covariance (`n × n`, row-major) of `samples`, reduced in
/// fixed-size chunks.
fn covariance(samples: &[&[u8]], n: usize) -> (Vec<f64>, Vec<f64>) {
    let count = samples.len().max(1) as f64;
    let mut mean = vec![0f64; n];
    for s in samples {
        for (m, &v) in mean.iter_mut().zip(s.iter()) {
            *m += f64::from(v);
        }
    }
    mean.iter_mut().for_each(|m| *m /= count);
    let partials: Vec<Vec<f64>> = samples
        .par_chunks(PCA_CHUNK)
        .map(|chunk| {
            let mut acc = vec![0f64; n * n];
            let mut centred = vec![0f64; n];
            for s in chunk {
                for ((c, &v), m) in centred.iter_mut().zip(s.iter()).zip(&mean) {
                    *c = f64::from(v) - m;
                }
                for i in 0..n {
                    let ci = centred[i];
                    for (a, &cj) in acc[i * n + i..(i + 1) * n].iter_mut().zip(&centred[i..]) {
                        *a += ci * cj;
                    }
                }
            }
            acc
        })
        .collect();
    let mut cov = vec![0f64; n * n];
    for part in &partials {
        for (c, p) in cov.iter_mut().zip(part) {
            *c += p;
        }
    }
    for i in 0..n {
        for j in i..n {
            let v = cov[i * n + j] / count;
            cov[i * n + j] = v;
            cov[j * n + i] = v;
        }
    }
    (mean, cov)
}

/// The `k` leading eigenvectors of the symmetric `n × n` matrix `m`, sorted by
/// decreasing eigenvalue, by oversampled block power iteration and a
/// Rayleigh–Ritz step.
fn leading_eigenvectors(m: &[f64], n: usize, k: usize) -> Vec<Vec<f64>> {
    let block = (k + POWER_OVERSAMPLING).min(n);
    let trace: f64 = (0..n).map(|i| m[i * n + i]).sum();
    let ridge = 1e-9 * trace / n as f64 + 1e-12;
    let apply = |v: &[f64]| -> Vec<f64> {
        (0..n)
            .map(|i| {
                let row = &m[i * n..(i + 1) * n];
                row.iter().zip(v).map(|(a, b)| a * b).sum::<f64>() + ridge * v[i]
            })
            .collect()
    };
    let mut q: Vec<Vec<f64>> = (0..block)
        .map(|j| {
            (0..n)
                .map(|i| {
                    let h = mix(((j as u64) << 32) | i as u64);
                    (h >> 11) as f64 / (1u64 << 53) as f64 - 0.5
                })
                .collect()
        })
        .collect();
    orthonormalise(&mut q);
    for _ in 0..POWER_ITERATIONS {
        q = q.iter().map(|v| apply(v)).collect();
        orthonormalise(&mut q);
    }
    let cq: Vec<Vec<f64>> = q.iter().map(|v| apply(v)).collect();
    // Symmetrised so that rounding cannot make the projected matrix
    // asymmetric. The sign of each eigenvector is arbitrary; flipping a
    // principal direction changes no reduced-space distance.
    let h = DMatrix::<f64>::from_fn(block, block, |i, j| {
        0.5 * (q[i].iter().zip(&cq[j]).map(|(x, y)| x * y).sum::<f64>()
            + q[j].iter().zip(&cq[i]).map(|(x, y)| x * y).sum::<f64>())
    });
    let eig = SymmetricEigen::new(h);
    let mut order: Vec<usize> = (0..block).collect();
    order.sort_by(|&x, &y| {
        eig.eigenvalues[y]
            .total_cmp(&eig.eigenvalues[x])
            .then(x.cmp(&y))
    });
    order
        .iter()
        .take(k)
        .map(|&c| {
            let mut v = vec![0f64; n];
            for (j, qj) in q.iter().enumerate() {
                let w = eig.eigenvectors[(j, c)];
                for (x, &y) in v.iter_mut().zip(qj) {
                    *x += w * y;
                }
            }
            v
        })
        .collect()
}

/// Modified Gram–Schmidt; a vector that vanishes is replaced by a unit axis
/// orthogonalised against the previous ones.
fn orthonormalise(q: &mut [Vec<f64>]) {
    let n = q.first().map_or(0, Vec::len);
    for j in 0..q.len() {
        let mut axis = 0;
        loop {
            let (done, rest) = q.split_at_mut(j);
            let v = &mut rest[0];
            for u in done.iter() {
                let d: f64 = u.iter().zip(v.iter()).map(|(a, b)| a * b).sum();
                v.iter_mut().zip(u).for_each(|(x, y)| *x -= d * y);
            }
            let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            if norm > 1e-150 {
                v.iter_mut().for_each(|x| *x /= norm);
                break;
            }
            if axis >= n {
                break;
            }
            v.iter_mut().for_each(|x| *x = 0.0);
            v[axis] = 1.0;
            axis += 1;
        }
    }
}

#[derive(Clone, Copy)]
enum Node {
    Leaf {
        start: u32,
        end: u32,
    },
    /// Points with `coordinate < threshold` are under `left`, the others
    /// under `right`.
    Split {
        dim: u32,
        threshold: f32,
        left: u32,
        right: u32,
    },
}

/// Kd-tree over reduced patch vectors.
struct KdTree {
    dims: usize,
    /// Points in leaf order, `dims` floats each.
    points: Vec<f32>,
    /// Original index of each point in leaf order.
    ids: Vec<u32>,
    nodes: Vec<Node>,
}

impl KdTree {
    fn build(reduced: &[f32], dims: usize) -> Self {
        let n = reduced.len() / dims;
        let mut ids: Vec<u32> = (0..n as u32).collect();
        let mut tree = KdTree {
            dims,
            points: Vec::new(),
            ids: Vec::new(),
            nodes: Vec::new(),
        };
        tree.build_node(&mut ids, 0, reduced);
        tree.points = ids
            .iter()
            .flat_map(|&i| {
                reduced[i as usize * dims..(i as usize + 1) * dims]
                    .iter()
                    .copied()
            })
            .collect();
        tree.ids = ids;
        tree
    }

    fn build_node(&mut self, ids: &mut [u32], start: usize, reduced: &[f32]) -> u32 {
        let index = self.nodes.len() as u32;
        let d = self.dims;
        if ids.len() <= LEAF_SIZE {
            self.nodes.push(Node::Leaf {
                start: start as u32,
                end: (start + ids.len()) as u32,
            });
            return index;
        }
        let mut lo = [f32::INFINITY; SEARCH_DIMS];
        let mut hi = [f32::NEG_INFINITY; SEARCH_DIMS];
        for &i in ids.iter() {
            let p = &reduced[i as usize * d..(i as usize + 1) * d];
            for c in 0..d {
                lo[c] = lo[c].min(p[c]);
                hi[c] = hi[c].max(p[c]);
            }
        }
        let mut dim = 0;
        for c in 1..d {
            if hi[c] - lo[c] > hi[dim] - lo[dim] {
                dim = c;
            }
        }
        let coord = |i: u32| reduced[i as usize * d + dim];
        let mid = ids.len() / 2;
        ids.select_nth_unstable_by(mid, |&a, &b| {
            coord(a)
                .partial_cmp(&coord(b))
                .unwrap_or(Ordering::Equal)
                .then(a.cmp(&b))
        });
        let value = coord(ids[mid]);
        // Points equal to the median go to one side as a whole, so that points
        // with identical coordinates always share the query's path.
        let below = partition(&mut ids[..mid], |i| coord(i) < value);
        let (split, threshold) = if below > 0 {
            (below, value)
        } else {
            let equal = partition(&mut ids[mid..], |i| coord(i) <= value);
            if mid + equal < ids.len() {
                (mid + equal, value.next_up())
            } else {
                (mid, value)
            }
        };
        self.nodes.push(Node::Leaf { start: 0, end: 0 });
        let (left_ids, right_ids) = ids.split_at_mut(split);
        let left = self.build_node(left_ids, start, reduced);
        let right = self.build_node(right_ids, start + split, reduced);
        self.nodes[index as usize] = Node::Split {
            dim: dim as u32,
            threshold,
            left,
            right,
        };
        index
    }

    fn search(&self, query: &[f32], knn: &mut Knn) {
        let mut offsets = [0f32; SEARCH_DIMS];
        let mut budget = MAX_LEAVES;
        self.visit(0, query, 0.0, &mut offsets, knn, &mut budget);
    }

    fn visit(
        &self,
        node: u32,
        query: &[f32],
        bound: f32,
        offsets: &mut [f32; SEARCH_DIMS],
        knn: &mut Knn,
        budget: &mut usize,
    ) {
        match self.nodes[node as usize] {
            Node::Leaf { start, end } => {
                *budget = budget.saturating_sub(1);
                let d = self.dims;
                for i in start as usize..end as usize {
                    let p = &self.points[i * d..(i + 1) * d];
                    let dist = reduced_distance(query, p);
                    if dist < knn.worst() {
                        knn.insert(dist, self.ids[i]);
                    }
                }
            }
            Node::Split {
                dim,
                threshold,
                left,
                right,
            } => {
                let dim = dim as usize;
                let diff = query[dim] - threshold;
                let (near, far) = if query[dim] < threshold {
                    (left, right)
                } else {
                    (right, left)
                };
                self.visit(near, query, bound, offsets, knn, budget);
                let old = offsets[dim];
                let far_bound = bound - old * old + diff * diff;
                if *budget > 0 && far_bound < knn.worst() {
                    offsets[dim] = diff;
                    self.visit(far, query, far_bound, offsets, knn, budget);
                    offsets[dim] = old;
                }
            }
        }
    }
}

/// Reorders `ids` so that those satisfying `pred` come first; returns their
/// count.
fn partition(ids: &mut [u32], pred: impl Fn(u32) -> bool) -> usize {
    let mut count = 0;
    for i in 0..ids.len() {
        if pred(ids[i]) {
            ids.swap(i, count);
            count += 1;
        }
    }
    count
}

fn reduced_distance(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| {
            let d = x - y;
            d * d
        })
        .sum()
}

/// The `CANDIDATES` best (distance, id) pairs seen so far, sorted by distance,
/// ignoring points whose reduced distance is at least `cap`.
struct Knn {
    dist: [f32; CANDIDATES],
    ids: [u32; CANDIDATES],
    len: usize,
    cap: f32,
}

impl Knn {
    /// An empty list; `cap` is a reduced-space distance beyond which no point
    /// can beat a match already known.
    fn new(cap: f32) -> Self {
        Knn {
            dist: [0.0; CANDIDATES],
            ids: [0; CANDIDATES],
            len: 0,
            cap,
        }
    }

    fn worst(&self) -> f32 {
        if self.len < CANDIDATES {
            self.cap
        } else {
            self.dist[CANDIDATES - 1].min(self.cap)
        }
    }

    fn insert(&mut self, dist: f32, id: u32) {
        if dist >= self.worst() || self.ids[..self.len].contains(&id) {
            return;
        }
        let mut pos = self.len.min(CANDIDATES - 1);
        while pos > 0 && self.dist[pos - 1] > dist {
            self.dist[pos] = self.dist[pos - 1];
            self.ids[pos] = self.ids[pos - 1];
            pos -= 1;
        }
        self.dist[pos] = dist;
        self.ids[pos] = id;
        self.len = (self.len + 1).min(CANDIDATES);
    }
}

/// A reduced-space distance that no patch closer than `dist` (the integer
/// full-space distance) can reach, widened slightly against rounding.
fn reduced_bound(dist: u32) -> f32 {
    if dist == u32::MAX {
        f32::INFINITY
    } else {
        dist as f32 / (255.0 * 255.0) * (1.0 + 1e-4) + 1e-6
    }
}

/// A patch set with its reduced vectors and search tree.
struct Indexed<'a> {
    set: &'a PatchSet,
    reduced: &'a [f32],
    tree: &'a KdTree,
}

/// Mean over `queries` patches of the distance to the nearest `database` patch,
/// normalised per pixel-channel with colours in `0..=1`.
fn mean_nearest_distance(queries: &Indexed, database: &Indexed) -> f64 {
    let dims = database.tree.dims;
    let qset = queries.set;
    let row_sums: Vec<u64> = (0..qset.rows)
        .into_par_iter()
        .map(|y| {
            let mut sum = 0u64;
            let mut previous: Option<usize> = None;
            for x in 0..qset.cols {
                let qi = y * qset.cols + x;
                let query = &queries.reduced[qi * dims..(qi + 1) * dims];
                let patch = qset.patch(qi);
                let mut best = (u32::MAX, 0usize);
                if let Some(s) = previous.and_then(|m| database.set.right_of(m)) {
                    best = (patch_distance(patch, database.set.patch(s)), s);
                }
                if best.0 > 0 {
                    let mut knn = Knn::new(reduced_bound(best.0));
                    database.tree.search(query, &mut knn);
                    for &id in &knn.ids[..knn.len] {
                        let d = patch_distance(patch, database.set.patch(id as usize));
                        if d < best.0 {
                            best = (d, id as usize);
                        }
                    }
                }
                sum += u64::from(best.0);
                previous = Some(best.1);
            }
            sum
        })
        .collect();
    let total: u64 = row_sums.iter().sum();
    total as f64 / (qset.len() as f64 * qset.dim as f64 * 255.0 * 255.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Smooth value noise plus stripes and a little pixel noise, periodic with
    /// `period` (a multiple of 8) in both directions, sampled at an offset.
    fn texture(w: usize, h: usize, period: usize, offset: (usize, usize), seed: u64) -> Vec<u8> {
        let cells = period / 8;
        let lattice = |i: usize, j: usize, c: usize| {
            let key = (((i % cells) as u64) << 40) | (((j % cells) as u64) << 20) | c as u64;
            (mix(seed ^ mix(key)) >> 56) as f64 / 255.0
        };
        let smooth = |t: f64| t * t * (3.0 - 2.0 * t);
        let mut out = Vec::with_capacity(w * h * 3);
        for y in 0..h {
            for x in 0..w {
                let (u, v) = ((x + offset.0) % period, (y + offset.1) % period);
                let (i, j) = (u / 8, v / 8);
                let (fx, fy) = (smooth((u % 8) as f64 / 8.0), smooth((v % 8) as f64 / 8.0));
                let phase = std::f64::consts::TAU * (2 * u + v) as f64 / period as f64;
                for c in 0..3 {
                    let top = lattice(i, j, c) * (1.0 - fx) + lattice(i + 1, j, c) * fx;
                    let bottom = lattice(i, j + 1, c) * (1.0 - fx) + lattice(i + 1, j + 1, c) * fx;
                    let noise = top * (1.0 - fy) + bottom * fy;
                    let stripes = 0.5 + 0.5 * (phase + c as f64).sin();
                    let grain = (mix(seed ^ ((u as u64) << 32 | v as u64) ^ c as u64) >> 61) as f64;
                    let value = 160.0 * noise + 80.0 * stripes + grain;
                    out.push(value.clamp(0.0, 255.0) as u8);
                }
            }
        }
        out
    }

    fn view(w: usize, h: usize, rgb: &[u8]) -> RgbView<'_> {
        RgbView {
            width: w as u32,
            height: h as u32,
            rgb,
        }
    }

    /// Exhaustive nearest-patch distance, for checking the approximate search.
    fn brute_force(queries: &PatchSet, database: &PatchSet) -> f64 {
        let total: u64 = (0..queries.len())
            .into_par_iter()
            .map(|q| {
                (0..database.len())
                    .map(|d| patch_distance(queries.patch(q), database.patch(d)))
                    .min()
                    .map_or(0, u64::from)
            })
            .sum();
        total as f64 / (queries.len() as f64 * queries.dim as f64 * 255.0 * 255.0)
    }

    #[test]
    fn streaks_are_anisotropic() {
        // Vertical stripes: constant down each column, changing along rows.
        let (w, h) = (32usize, 24usize);
        let stripes: Vec<u8> = (0..w * h)
            .flat_map(|i| {
                let v = ((i % w) * 37 % 251) as u8;
                [v, v, v]
            })
            .collect();
        let turned: Vec<u8> = (0..w * h)
            .flat_map(|i| {
                let v = ((i / w) * 37 % 251) as u8;
                [v, v, v]
            })
            .collect();
        let noise = texture(w, h, 16, (0, 0), 3);
        let (s, t, n) = (
            view(w, h, &stripes),
            view(w, h, &turned),
            view(w, h, &noise),
        );
        assert_eq!(directional_ratio(s), f64::MIN_POSITIVE);
        assert_eq!(directional_ratio(t), f64::MAX);
        assert_eq!(anisotropy(n, n), 0.0);
        assert!(anisotropy(s, n) > 5.0, "{}", anisotropy(s, n));
        let flat = vec![9u8; w * h * 3];
        assert_eq!(directional_ratio(view(w, h, &flat)), 1.0);
        let tiny = view(1, 1, &flat);
        assert_eq!(directional_ratio(tiny), 1.0);
        // One row changes along u but cannot be measured along v.
        assert_eq!(directional_ratio(view(w, 1, &stripes[..w * 3])), 1.0);
        assert!(anisotropy(tiny, n).is_finite());
    }

    #[test]
    fn exemplar_against_itself_scores_zero() {
        let ex = texture(64, 64, 64, (0, 0), 1);
        let s = score_slice(view(64, 64, &ex), view(64, 64, &ex), 7);
        assert_eq!(s.coherence, 0.0);
        assert_eq!(s.histogram, 0.0);
        assert!(s.completeness < 2e-3, "{s:?}");

        // A 2x2 tiling contains every toroidal exemplar patch exactly.
        let tiled = texture(128, 128, 64, (0, 0), 1);
        let s = score_slice(view(128, 128, &tiled), view(64, 64, &ex), 7);
        assert_eq!(s.coherence, 0.0);
        assert_eq!(s.completeness, 0.0);
        assert_eq!(s.histogram, 0.0);
    }

    #[test]
    fn duplicates_are_found_even_in_pure_noise() {
        let ex: Vec<u8> = (0..48 * 48 * 3).map(|i| (mix(i) >> 56) as u8).collect();
        let tiled: Vec<u8> = (0..80 * 70)
            .flat_map(|i| {
                let (x, y) = ((i % 80 + 17) % 48, (i / 80 + 5) % 48);
                ex[(y * 48 + x) * 3..][..3].to_vec()
            })
            .collect();
        let s = score_slice(view(80, 70, &tiled), view(48, 48, &ex), 7);
        assert_eq!(s.coherence, 0.0);
        assert_eq!(s.completeness, 0.0);
        // Reading the rows with the wrong stride breaks every vertical edge.
        let ragged = score_slice(view(40, 20, &tiled[..40 * 20 * 3]), view(48, 48, &ex), 7);
        assert!(ragged.coherence > 0.01, "{ragged:?}");
    }

    #[test]
    fn constant_grey_scores_worse_than_exemplar() {
        let ex = texture(64, 64, 64, (0, 0), 2);
        let own = score_slice(view(64, 64, &ex), view(64, 64, &ex), 7);
        let grey = vec![128u8; 96 * 96 * 3];
        let s = score_slice(view(96, 96, &grey), view(64, 64, &ex), 7);
        assert!(s.completeness > 0.01, "{s:?}");
        assert!(s.completeness > 10.0 * own.completeness, "{s:?} vs {own:?}");
        assert!(s.histogram > 0.5, "{s:?}");
        assert!(s.coherence.is_finite() && s.coherence >= 0.0);
    }

    #[test]
    fn shuffled_baseline_is_less_coherent_than_shifted_crop() {
        let ex = texture(64, 64, 64, (0, 0), 3);
        let exemplar = view(64, 64, &ex);
        let shifted = texture(100, 90, 64, (13, 29), 3);
        let crop = score_slice(view(100, 90, &shifted), exemplar, 7);
        let noise = shuffled_exemplar(exemplar, 100, 90, 42);
        let shuffled = score_slice(view(100, 90, &noise), exemplar, 7);
        assert_eq!(crop.coherence, 0.0);
        assert!(shuffled.coherence > 0.005, "{shuffled:?}");
        assert!(shuffled.coherence > crop.coherence + 0.005);
        assert!(shuffled.completeness > crop.completeness);
        assert!(shuffled.histogram < 0.2, "{shuffled:?}");
    }

    #[test]
    fn approximate_search_is_close_to_exhaustive() {
        let ex = texture(32, 32, 32, (0, 0), 4);
        let other = texture(48, 40, 64, (5, 7), 5);
        let (exemplar, slice) = (view(32, 32, &ex), view(48, 40, &other));
        let s = score_slice(slice, exemplar, 7);
        let slice_set = PatchSet::interior(slice, 7);
        let exemplar_set = PatchSet::toroidal(exemplar, 7);
        let coherence = brute_force(&slice_set, &exemplar_set);
        let completeness = brute_force(&exemplar_set, &slice_set);
        assert!(s.coherence >= coherence - 1e-12);
        assert!(s.completeness >= completeness - 1e-12);
        assert!(
            s.coherence <= coherence * 1.05,
            "{} vs {coherence}",
            s.coherence
        );
        assert!(
            s.completeness <= completeness * 1.05,
            "{} vs {completeness}",
            s.completeness
        );
    }

    #[test]
    fn results_do_not_depend_on_thread_count() {
        let ex = texture(64, 64, 64, (0, 0), 6);
        let exemplar = view(64, 64, &ex);
        let noise = shuffled_exemplar(exemplar, 80, 70, 7);
        let other = texture(80, 70, 32, (3, 1), 8);
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    (
                        score_slice(view(80, 70, &noise), exemplar, 7),
                        score_slice(view(80, 70, &other), exemplar, 5),
                        shuffled_exemplar(exemplar, 33, 17, 9),
                    )
                })
        };
        let (one, two) = (run(1), run(2));
        assert_eq!(one, two);
        assert_eq!(one.0.coherence.to_bits(), two.0.coherence.to_bits());
        assert_eq!(one.1.completeness.to_bits(), two.1.completeness.to_bits());
    }

    #[test]
    fn tiny_images_do_not_panic() {
        let ex = texture(16, 16, 16, (0, 0), 10);
        let exemplar = view(16, 16, &ex);
        let empty = view(0, 5, &[]);
        assert_eq!(score_slice(empty, exemplar, 7).coherence, 1.0);
        assert_eq!(score_slice(exemplar, empty, 7).completeness, 1.0);
        for (w, h) in [(1, 1), (2, 2), (3, 5), (7, 1), (6, 6), (9, 8)] {
            let slice = texture(w, h, 16, (1, 2), 10);
            for patch in [0, 1, 2, 7, 8] {
                let s = score_slice(view(w, h, &slice), exemplar, patch);
                for v in [s.coherence, s.completeness, s.histogram] {
                    assert!((0.0..=1.0).contains(&v), "{w}x{h} p{patch}: {s:?}");
                }
                let t = score_slice(exemplar, view(w, h, &slice), patch);
                assert!(t.coherence.is_finite() && t.completeness.is_finite());
            }
        }
        let px = [10u8, 200, 30];
        let one = view(1, 1, &px);
        let s = score_slice(one, one, 7);
        assert_eq!((s.coherence, s.completeness, s.histogram), (0.0, 0.0, 0.0));
        assert!(shuffled_exemplar(empty, 4, 4, 1).iter().all(|&b| b == 0));
        assert!(shuffled_exemplar(exemplar, 0, 3, 1).is_empty());
    }

    #[test]
    fn patch_size_is_clamped_to_fit_the_slice() {
        let ex = texture(32, 32, 32, (0, 0), 11);
        let slice = texture(9, 6, 32, (4, 4), 11);
        let (e, s) = (view(32, 32, &ex), view(9, 6, &slice));
        assert_eq!(score_slice(s, e, 7), score_slice(s, e, 5));
        assert_eq!(score_slice(s, e, 6), score_slice(s, e, 5));
        assert_eq!(score_slice(s, e, 4), score_slice(s, e, 3));
    }

    #[test]
    fn shuffled_exemplar_is_deterministic_and_uses_exemplar_pixels() {
        let ex = texture(16, 8, 8, (0, 0), 12);
        let exemplar = view(16, 8, &ex);
        let a = shuffled_exemplar(exemplar, 20, 10, 1);
        assert_eq!(a.len(), 20 * 10 * 3);
        assert_eq!(a, shuffled_exemplar(exemplar, 20, 10, 1));
        assert_ne!(a, shuffled_exemplar(exemplar, 20, 10, 2));
        let pixels: Vec<&[u8]> = ex.chunks_exact(3).collect();
        assert!(a.chunks_exact(3).all(|p| pixels.contains(&p)));
    }

    #[test]
    fn histogram_distance_is_total_variation() {
        let black = [0u8; 12];
        let white = [255u8; 12];
        let half: Vec<u8> = [[0u8; 6], [255u8; 6]].concat();
        let (b, w, h) = (view(2, 2, &black), view(2, 2, &white), view(2, 2, &half));
        assert_eq!(histogram_distance(b, w), 1.0);
        assert_eq!(histogram_distance(b, h), 0.5);
        assert_eq!(histogram_distance(h, h), 0.0);
    }

    #[test]
    fn principal_directions_match_full_eigen_decomposition() {
        let n = 40;
        let mut m = vec![0f64; n * n];
        for i in 0..n {
            m[i * n + i] = (n - i) as f64;
        }
        let vectors = leading_eigenvectors(&m, n, 4);
        for (c, v) in vectors.iter().enumerate() {
            assert!((v[c].abs() - 1.0).abs() < 1e-6, "{c}: {v:?}");
        }
    }
}
