//! Crossbar search (Dong et al., "3D candidates selection"). For a pixel of
//! plane p, the two other planes' neighbourhoods meet p's neighbourhood along
//! two strips of N pixels; the S strips most similar to them are found among
//! the PCA-reduced strips with a k-d tree (nearest in the reduced space),
//! and the S² resulting triples are ranked by the full crossbar error (the
//! three pairwise strip differences).

use super::geometry::Dims;
use crate::analysis::appearance::{Pca, sq_dist};
use crate::analysis::stack::{GaussianStack, spacing};
use crate::simd;
#[cfg(target_arch = "x86_64")]
use crate::simd::strip_dist_avx;
use crate::synth::cancel::CancelFlag;
use kiddo::SquaredEuclidean;
use rayon::prelude::*;
use std::collections::BinaryHeap;
use std::num::NonZero;

/// Dimensions of the reduced strips the k-d trees index.
const STRIP_DIMS: usize = 6;
type StripTree = kiddo::ImmutableKdTree<f32, STRIP_DIMS>;

/// The u- and v-strips (horizontal and vertical runs of N pixels, spaced
/// h_k apart) through every pixel of one plane at one level.
pub struct Strips {
    /// Floats per strip, padded to a multiple of 8 for SIMD distances.
    len: usize,
    /// Meaningful floats per strip (3·N).
    raw: usize,
    /// `len` floats per pixel: the run along the image's u axis.
    pub u: Vec<f32>,
    /// `len` floats per pixel: the run along the image's v axis.
    pub v: Vec<f32>,
}

impl Strips {
    /// Extracts both strips of every pixel.
    pub fn new(stack: &GaussianStack, k: usize, n: u32) -> Strips {
        let (w, h) = (stack.width() as i64, stack.height() as i64);
        let r = (n / 2) as i64;
        let step = spacing(k) as i64;
        let raw = n as usize * 3;
        let len = raw.div_ceil(8) * 8;
        let mut u = Vec::with_capacity((w * h) as usize * len);
        let mut v = Vec::with_capacity((w * h) as usize * len);
        for y in 0..h {
            for x in 0..w {
                for t in -r..=r {
                    u.extend_from_slice(&stack.at(k, x + t * step, y));
                }
                u.resize(u.len() + len - raw, 0.0);
                for t in -r..=r {
                    v.extend_from_slice(&stack.at(k, x, y + t * step));
                }
                v.resize(v.len() + len - raw, 0.0);
            }
        }
        Strips { len, raw, u, v }
    }

    #[inline]
    fn u(&self, c: u32) -> &[f32] {
        &self.u[c as usize * self.len..(c as usize + 1) * self.len]
    }

    #[inline]
    fn v(&self, c: u32) -> &[f32] {
        &self.v[c as usize * self.len..(c as usize + 1) * self.len]
    }
}

/// A scored triple.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scored {
    /// Crossbar error.
    pub error: f32,
    /// Pixel indices in the xy, yz and zx exemplars.
    pub triple: [u32; 3],
}

fn reduce(pca: &Pca, strip: &[f32]) -> [f32; STRIP_DIMS] {
    let mut out = [0f32; STRIP_DIMS];
    pca.project(&strip[..pca.input], &mut out[..pca.dims]);
    out
}

fn tree(pca: &Pca, strips: &[f32], len: usize) -> StripTree {
    let pts: Vec<[f32; STRIP_DIMS]> = strips.chunks_exact(len).map(|s| reduce(pca, s)).collect();
    StripTree::new_from_slice(&pts)
}

/// Finds, for every pixel of plane `p`, its `keep` best triples by crossbar
/// error among the S² formed from the S nearest strips in the other two
/// planes. Results are sorted by (error, triple) so they are independent of
/// thread count. Unwinds out (between pixels) once `cancel` is set.
pub fn search_plane(
    p: usize,
    strips: [&Strips; 3],
    dims: Dims,
    s: usize,
    keep: usize,
    cancel: Option<&CancelFlag>,
) -> Vec<Vec<Scored>> {
    let len = strips[0].len;
    // Plane q = p−1 meets p along p's u axis (q's v-strip), plane r = p+1
    // meets p along p's v axis (r's u-strip).
    let q = (p + 2) % 3;
    let r = (p + 1) % 3;
    let mut sample = Vec::new();
    let stride = (dims.len() / 4096).max(1);
    for st in strips {
        for c in (0..dims.len()).step_by(stride) {
            sample.extend_from_slice(&st.u(c as u32)[..st.raw]);
            sample.extend_from_slice(&st.v(c as u32)[..st.raw]);
        }
    }
    let raw = strips[0].raw;
    let pca = Pca::fit(&sample, raw, STRIP_DIMS.min(raw));
    let q_tree = tree(&pca, &strips[q].v, len);
    let r_tree = tree(&pca, &strips[r].u, len);
    let s = NonZero::new(s.min(dims.len())).expect("non-empty exemplar");

    (0..dims.len() as u32)
        .into_par_iter()
        .map(|c| {
            if let Some(f) = cancel {
                f.unwind_if_set();
            }
            let pu = strips[p].u(c);
            let pv = strips[p].v(c);
            let mut qs: Vec<(f32, u32)> = q_tree
                .nearest_n::<SquaredEuclidean>(&reduce(&pca, pu), s)
                .into_iter()
                .map(|nn| (sq_dist(strips[q].v(nn.item as u32), pu), nn.item as u32))
                .collect();
            let mut rs: Vec<(f32, u32)> = r_tree
                .nearest_n::<SquaredEuclidean>(&reduce(&pca, pv), s)
                .into_iter()
                .map(|nn| (sq_dist(pv, strips[r].u(nn.item as u32)), nn.item as u32))
                .collect();
            qs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            rs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            best_pairs(p, c, &qs, &rs, strips, keep)
        })
        .collect()
}

/// Keeps the `keep` lowest-error triples from all (q, r) pairs; both lists
/// are sorted by their partial error so the pair loops stop early.
#[allow(unsafe_code)]
fn best_pairs(
    p: usize,
    c: u32,
    qs: &[(f32, u32)],
    rs: &[(f32, u32)],
    strips: [&Strips; 3],
    keep: usize,
) -> Vec<Scored> {
    // Strips of N = 3 … 9 pixels are 2, 3 or 4 blocks of eight floats.
    debug_assert!((16..=32).contains(&strips[0].len));
    macro_rules! with_blocks {
        ($b:literal) => {{
            #[cfg(target_arch = "x86_64")]
            if simd::avx() {
                // SAFETY: the CPU runs AVX instructions (checked above).
                return unsafe { best_pairs_avx::<$b>(p, c, qs, rs, strips, keep) };
            }
            best_pairs_with::<$b>(p, c, qs, rs, strips, keep, |a, b| {
                sq_dist(a.as_flattened(), b.as_flattened())
            })
        }};
    }
    match strips[0].len / 8 {
        ..=2 => with_blocks!(2),
        3 => with_blocks!(3),
        _ => with_blocks!(4),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn best_pairs_avx<const B: usize>(
    p: usize,
    c: u32,
    qs: &[(f32, u32)],
    rs: &[(f32, u32)],
    strips: [&Strips; 3],
    keep: usize,
) -> Vec<Scored> {
    best_pairs_with::<B>(p, c, qs, rs, strips, keep, |a, b| strip_dist_avx(a, b))
}

/// The first `B` blocks of eight floats of a strip.
#[inline(always)]
fn blocks<const B: usize>(strip: &[f32]) -> [[f32; 8]; B] {
    std::array::from_fn(|i| std::array::from_fn(|l| strip[8 * i + l]))
}

/// An error's bits, reordered so that unsigned order is `f32::total_cmp`.
fn error_key(e: f32) -> u32 {
    let bits = e.to_bits();
    if bits >> 31 == 1 {
        !bits
    } else {
        bits | 1 << 31
    }
}

fn key_error(key: u32) -> f32 {
    f32::from_bits(if key >> 31 == 1 {
        key & !(1 << 31)
    } else {
        !key
    })
}

/// [`best_pairs`] with the strip distance given. The kept triples are a
/// max-heap of (error, triple) packed in one integer, so its top is the
/// triple a better one evicts: a triple enters only while the list is short
/// or when it beats the worst kept error, and then it replaces that top.
#[inline(always)]
fn best_pairs_with<const B: usize>(
    p: usize,
    c: u32,
    qs: &[(f32, u32)],
    rs: &[(f32, u32)],
    strips: [&Strips; 3],
    keep: usize,
    dist: impl Fn(&[[f32; 8]; B], &[[f32; 8]; B]) -> f32,
) -> Vec<Scored> {
    let q = (p + 2) % 3;
    let r = (p + 1) % 3;
    // The triple's two foreign coordinates in plane order: with plane p's
    // fixed at `c`, they order triples as `[u32; 3]` does.
    let pack = |e: f32, qc: u32, rc: u32| {
        let (a, b) = if q < r { (qc, rc) } else { (rc, qc) };
        (error_key(e) as u128) << 64 | (a as u128) << 32 | b as u128
    };
    let r_strips: Vec<[[f32; 8]; B]> = rs.iter().map(|&(_, rc)| blocks(strips[r].v(rc))).collect();
    let mut best: BinaryHeap<u128> = BinaryHeap::with_capacity(keep);
    let top_error = |best: &BinaryHeap<u128>| {
        best.peek()
            .map_or(f32::INFINITY, |&t| key_error((t >> 64) as u32))
    };
    // The first `keep` pairs in loop order all enter.
    let filled = keep.min(qs.len() * rs.len());
    for t in 0..filled {
        let (i, j) = (t / rs.len(), t % rs.len());
        let ((e1, qc), (e2, rc)) = (qs[i], rs[j]);
        let e = e1 + e2 + dist(&r_strips[j], &blocks(strips[q].u(qc)));
        best.push(pack(e, qc, rc));
    }
    if best.len() < keep {
        return unpack_all(best, p, c);
    }
    // Then a pair enters only below the worst kept error, replacing that
    // triple; both lists ascend, so a row (and all rows) can stop early.
    let mut worst = top_error(&best);
    let (i0, j0) = (filled / rs.len(), filled % rs.len());
    for (i, &(e1, qc)) in qs.iter().enumerate().skip(i0) {
        if e1 + rs[0].0 >= worst {
            break;
        }
        let qu = blocks::<B>(strips[q].u(qc));
        let start = if i == i0 { j0 } else { 0 };
        for (&(e2, rc), rv) in rs[start..].iter().zip(&r_strips[start..]) {
            let partial = e1 + e2;
            if partial >= worst {
                break;
            }
            let e = partial + dist(rv, &qu);
            if e >= worst {
                continue;
            }
            if let Some(mut top) = best.peek_mut() {
                *top = pack(e, qc, rc);
            }
            worst = top_error(&best);
        }
    }
    unpack_all(best, p, c)
}

/// The kept triples, best first.
fn unpack_all(best: BinaryHeap<u128>, p: usize, c: u32) -> Vec<Scored> {
    let (q, r) = ((p + 2) % 3, (p + 1) % 3);
    let (first, second) = (q.min(r), q.max(r));
    best.into_sorted_vec()
        .into_iter()
        .map(|key| {
            let mut triple = [0u32; 3];
            triple[p] = c;
            triple[first] = (key >> 32) as u32;
            triple[second] = key as u32;
            Scored {
                error: key_error((key >> 64) as u32),
                triple,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sorted-insertion form of [`best_pairs`]: the list the heap must
    /// reproduce, ties included.
    fn best_pairs_sorted(
        p: usize,
        c: u32,
        qs: &[(f32, u32)],
        rs: &[(f32, u32)],
        strips: [&Strips; 3],
        keep: usize,
    ) -> Vec<Scored> {
        let q = (p + 2) % 3;
        let r = (p + 1) % 3;
        let mut best: Vec<Scored> = Vec::new();
        let mut worst = f32::INFINITY;
        for &(e1, qc) in qs {
            for &(e2, rc) in rs {
                let e = e1 + e2 + sq_dist(strips[r].v(rc), strips[q].u(qc));
                if best.len() == keep && e >= worst {
                    continue;
                }
                let mut triple = [0u32; 3];
                triple[p] = c;
                triple[q] = qc;
                triple[r] = rc;
                let item = Scored { error: e, triple };
                let pos = best
                    .binary_search_by(|b| b.error.total_cmp(&e).then(b.triple.cmp(&triple)))
                    .unwrap_or_else(|x| x);
                best.insert(pos, item);
                best.truncate(keep);
                if best.len() == keep {
                    worst = best[keep - 1].error;
                }
            }
        }
        best
    }

    /// Strips of `count` pixels with few distinct values, so equal errors
    /// (and the tie rules) are common.
    fn strips(count: usize, len: usize, seed: u32) -> Strips {
        let mut state = seed;
        let mut next = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 28) as f32 * 0.25
        };
        let mut u = Vec::new();
        let mut v = Vec::new();
        for _ in 0..count {
            for i in 0..len {
                u.push(if i < 15 { next() } else { 0.0 });
                v.push(if i < 15 { next() } else { 0.0 });
            }
        }
        Strips { len, raw: 15, u, v }
    }

    #[test]
    fn heap_keeps_what_sorted_insertion_keeps() {
        let all = [strips(40, 16, 1), strips(40, 16, 2), strips(40, 16, 3)];
        let refs = [&all[0], &all[1], &all[2]];
        for p in 0..3 {
            for keep in [1, 4, 17, 100, 1000] {
                for c in 0..6u32 {
                    let list = |plane: usize, seed: u32| -> Vec<(f32, u32)> {
                        let mut l: Vec<(f32, u32)> = (0..30u32)
                            .map(|i| (((i * 7 + seed + c) % 5) as f32, (i * 11 + seed) % 40))
                            .collect();
                        l.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                        l.dedup_by_key(|x| x.1);
                        let _ = plane;
                        l
                    };
                    let (qs, rs) = (list(0, 3), list(1, 5));
                    let expected = best_pairs_sorted(p, c, &qs, &rs, refs, keep);
                    assert_eq!(best_pairs(p, c, &qs, &rs, refs, keep), expected);
                    let portable = best_pairs_with::<2>(p, c, &qs, &rs, refs, keep, |a, b| {
                        sq_dist(a.as_flattened(), b.as_flattened())
                    });
                    assert_eq!(portable, expected);
                }
            }
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[allow(unsafe_code)]
    fn avx_distance_matches<const B: usize>() {
        let s = strips(50, 8 * B, 9);
        for i in 0..50u32 {
            for j in 0..50u32 {
                let (a, b) = (s.u(i), s.v(j));
                // SAFETY: the CPU runs AVX instructions (asserted by the caller).
                let fast = unsafe { strip_dist_avx::<B>(&blocks(a), &blocks(b)) };
                assert_eq!(fast.to_bits(), sq_dist(a, b).to_bits());
            }
        }
    }

    #[test]
    #[cfg(target_arch = "x86_64")]
    fn avx_strip_distance_is_the_same_float() {
        assert!(simd::avx(), "the x86_64 machines this runs on have AVX");
        avx_distance_matches::<2>();
        avx_distance_matches::<3>();
        avx_distance_matches::<4>();
    }

    #[test]
    fn error_keys_order_as_total_cmp() {
        let values = [
            f32::NEG_INFINITY,
            -3.5,
            -1e-30,
            -0.0,
            0.0,
            1e-30,
            0.25,
            7.0,
            1e30,
            f32::INFINITY,
        ];
        for &a in &values {
            assert_eq!(key_error(error_key(a)).to_bits(), a.to_bits());
            for &b in &values {
                assert_eq!(
                    error_key(a).cmp(&error_key(b)),
                    a.total_cmp(&b),
                    "{a} vs {b}"
                );
            }
        }
    }
}
