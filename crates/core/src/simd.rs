//! The hand-written SIMD kernels, and the one place that asks the CPU what
//! it runs.
//!
//! Each kernel gives exactly the integers or floats of the portable code
//! it stands for: the same lanes, the same summation order, no fused
//! multiply-adds. That is what keeps a voxel's bytes independent of the
//! machine, and the tests check it bit for bit. x86_64 only: SSE2 is its
//! baseline and is used unconditionally; AVX and AVX2 are asked for once
//! here ([`avx`], [`avx2`]); other CPUs run the portable code.
//!
//! Elsewhere, `#[target_feature]` copies of portable loops (the correction,
//! the PCA's scatter, the candidate search) are only entered where these
//! probes said yes.
#![allow(unsafe_code)]

use crate::synth::correction::tables::{BEST_CANDIDATES, SPARSE_DIMS, SparseVector, WideVector};

/// Whether the CPU runs AVX instructions.
pub(crate) fn avx() -> bool {
    #[cfg(target_arch = "x86_64")]
    return std::arch::is_x86_feature_detected!("avx");
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// Whether the CPU runs AVX2 instructions.
pub(crate) fn avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    return std::arch::is_x86_feature_detected!("avx2");
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// Asks the CPU to start loading the first cache line of `data`.
#[inline(always)]
pub(crate) fn prefetch<T>(data: &[T]) {
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

/// The lane-wise sum of four vectors, clamped to `range`.
#[inline(always)]
pub(crate) fn sum_clamped([a, b, c, d]: [&WideVector; 4], range: (i16, i16)) -> WideVector {
    // A correction scores 19 of these: the same sums, in registers (and
    // no array `map`, which is compiled out of line).
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::*;
        // SAFETY: SSE2 is part of the x86_64 baseline; every vector is
        // 32 bytes, 32-byte aligned.
        unsafe {
            let mut out = WideVector([0; SPARSE_DIMS]);
            let (lo, hi) = (_mm_set1_epi16(range.0), _mm_set1_epi16(range.1));
            for half in 0..2 {
                let at = |v: &WideVector| _mm_load_si128(v.0.as_ptr().cast::<__m128i>().add(half));
                let sum = _mm_add_epi16(_mm_add_epi16(at(a), at(b)), _mm_add_epi16(at(c), at(d)));
                let clamped = _mm_min_epi16(_mm_max_epi16(sum, lo), hi);
                _mm_store_si128(out.0.as_mut_ptr().cast::<__m128i>().add(half), clamped);
            }
            out
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    WideVector(std::array::from_fn(|j| {
        (a.0[j] + b.0[j] + c.0[j] + d.0[j]).clamp(range.0, range.1)
    }))
}

/// Squared distance between a vector and a query.
#[inline(always)]
pub(crate) fn distance(a: &WideVector, q: &WideVector) -> u32 {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::*;
        // SAFETY: SSE2 is part of the x86_64 baseline; both vectors are
        // 32 bytes, 32-byte aligned.
        unsafe {
            let pa = a.0.as_ptr().cast::<__m128i>();
            let pq = q.0.as_ptr().cast::<__m128i>();
            let lo = _mm_sub_epi16(_mm_load_si128(pa), _mm_load_si128(pq));
            let hi = _mm_sub_epi16(_mm_load_si128(pa.add(1)), _mm_load_si128(pq.add(1)));
            horizontal_sum(_mm_add_epi32(
                _mm_madd_epi16(lo, lo),
                _mm_madd_epi16(hi, hi),
            ))
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        scalar_distance(&a.0, q)
    }
}

/// Squared distances of a pixel's [`BEST_CANDIDATES`] stored vectors to a
/// query, four at once; `AVX2` says the caller runs with AVX2 enabled.
#[inline(always)]
pub(crate) fn best_distances<const AVX2: bool>(
    v: &[SparseVector; BEST_CANDIDATES],
    q: &WideVector,
) -> [u32; BEST_CANDIDATES] {
    #[cfg(target_arch = "x86_64")]
    {
        if AVX2 {
            // SAFETY: callers pass AVX2 only when the CPU has it.
            unsafe { best_distances_avx2(v, q) }
        } else {
            // SAFETY: SSE2 is part of the x86_64 baseline.
            unsafe { best_distances_sse2(v, q) }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        v.map(|a| scalar_distance(&a.map(|x| x as i16), q))
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn best_distances_avx2(
    v: &[SparseVector; BEST_CANDIDATES],
    q: &WideVector,
) -> [u32; BEST_CANDIDATES] {
    use std::arch::x86_64::*;
    // SAFETY: the loads read the 16 bytes of each vector (unaligned) and
    // the 32 bytes of the 32-byte aligned query; the store writes 16 bytes
    // of a local `[u32; 4]`.
    unsafe {
        let query = _mm256_load_si256(q.0.as_ptr().cast());
        let squares = |bytes: &SparseVector| {
            let e = _mm256_sub_epi16(
                _mm256_cvtepu8_epi16(_mm_loadu_si128(bytes.as_ptr().cast())),
                query,
            );
            _mm256_madd_epi16(e, e)
        };
        let [a, b, c, d] = [0, 1, 2, 3].map(|i| squares(&v[i]));
        // Pairwise sums within each 128-bit half: after two rounds, half h
        // holds (a, b, c, d) summed over its lanes.
        let abcd = _mm256_hadd_epi32(_mm256_hadd_epi32(a, b), _mm256_hadd_epi32(c, d));
        let sum = _mm_add_epi32(
            _mm256_castsi256_si128(abcd),
            _mm256_extracti128_si256::<1>(abcd),
        );
        let mut out = [0u32; BEST_CANDIDATES];
        _mm_storeu_si128(out.as_mut_ptr().cast(), sum);
        out
    }
}

#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn best_distances_sse2(
    v: &[SparseVector; BEST_CANDIDATES],
    q: &WideVector,
) -> [u32; BEST_CANDIDATES] {
    use std::arch::x86_64::*;
    // SAFETY: SSE2 is part of the x86_64 baseline; the loads read the 16
    // bytes of each vector (unaligned) and the 32 bytes of the 32-byte
    // aligned query; the store writes 16 bytes of a local `[u32; 4]`.
    unsafe {
        let pq = q.0.as_ptr().cast::<__m128i>();
        let (q_lo, q_hi) = (_mm_load_si128(pq), _mm_load_si128(pq.add(1)));
        let zero = _mm_setzero_si128();
        let squares = |bytes: &SparseVector| {
            let x = _mm_loadu_si128(bytes.as_ptr().cast());
            let lo = _mm_sub_epi16(_mm_unpacklo_epi8(x, zero), q_lo);
            let hi = _mm_sub_epi16(_mm_unpackhi_epi8(x, zero), q_hi);
            _mm_add_epi32(_mm_madd_epi16(lo, lo), _mm_madd_epi16(hi, hi))
        };
        let [a, b, c, d] = [0, 1, 2, 3].map(|i| squares(&v[i]));
        // Transpose-and-add: lane i of the result sums vector i's lanes.
        let ab = _mm_add_epi32(_mm_unpacklo_epi32(a, b), _mm_unpackhi_epi32(a, b));
        let cd = _mm_add_epi32(_mm_unpacklo_epi32(c, d), _mm_unpackhi_epi32(c, d));
        let sum = _mm_add_epi32(_mm_unpacklo_epi64(ab, cd), _mm_unpackhi_epi64(ab, cd));
        let mut out = [0u32; BEST_CANDIDATES];
        _mm_storeu_si128(out.as_mut_ptr().cast(), sum);
        out
    }
}

/// The sum of four lanes.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn horizontal_sum(v: std::arch::x86_64::__m128i) -> u32 {
    use std::arch::x86_64::*;
    // SAFETY: SSE2 is part of the x86_64 baseline.
    unsafe {
        let v = _mm_add_epi32(v, _mm_shuffle_epi32::<0b01_00_11_10>(v));
        let v = _mm_add_epi32(v, _mm_shuffle_epi32::<0b10_11_00_01>(v));
        _mm_cvtsi128_si32(v) as u32
    }
}

/// The distances above without SIMD: what they are tested against, and
/// what other CPUs run.
#[cfg_attr(target_arch = "x86_64", allow(dead_code))]
fn scalar_distance(a: &[i16; SPARSE_DIMS], q: &WideVector) -> u32 {
    a.iter()
        .zip(&q.0)
        .map(|(&x, &y)| {
            let e = x as i32 - y as i32;
            (e * e) as u32
        })
        .sum()
}

/// A PCA's projection of `v` in blocks of eight outputs, one AVX register
/// per accumulator lane: `wide` holds per block of eight outputs `input`
/// rows of eight weights, `offsets` the projected mean padded to whole
/// blocks. Each output still has eight lane accumulators, the same
/// summation tree and no fused multiply-adds, so the floats are those of
/// the portable projection.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
pub(crate) fn project_avx(
    wide: &[[f32; 8]],
    offsets: &[f32],
    input: usize,
    dims: usize,
    v: &[f32],
    out: &mut [f32],
) {
    use std::arch::x86_64::*;
    let v = &v[..input];
    let (chunks, tail) = v.as_chunks::<8>();
    // SAFETY: every load reads eight floats of an `[f32; 8]` or of
    // `offsets` (padded to whole blocks of eight), and the store
    // writes a local `[f32; 8]`.
    let load = |w: &[f32; 8]| unsafe { _mm256_loadu_ps(w.as_ptr()) };
    for (b, rows) in wide.chunks_exact(input).enumerate() {
        let (row_chunks, row_tail) = rows.as_chunks::<8>();
        let mut acc = [_mm256_setzero_ps(); 8];
        for (x, w) in chunks.iter().zip(row_chunks) {
            for l in 0..8 {
                acc[l] = _mm256_add_ps(acc[l], _mm256_mul_ps(_mm256_set1_ps(x[l]), load(&w[l])));
            }
        }
        let mut rest = _mm256_setzero_ps();
        for (&x, w) in tail.iter().zip(row_tail) {
            rest = _mm256_add_ps(rest, _mm256_mul_ps(_mm256_set1_ps(x), load(w)));
        }
        let pairs = |i: usize, j: usize| _mm256_add_ps(acc[i], acc[j]);
        let tree = _mm256_add_ps(
            _mm256_add_ps(pairs(0, 4), pairs(1, 5)),
            _mm256_add_ps(pairs(2, 6), pairs(3, 7)),
        );
        let offsets: &[f32; 8] = offsets[8 * b..8 * b + 8].try_into().expect("padded");
        let sum = _mm256_sub_ps(_mm256_add_ps(tree, rest), load(offsets));
        let mut lanes = [0f32; 8];
        unsafe { _mm256_storeu_ps(lanes.as_mut_ptr(), sum) };
        let n = (dims - 8 * b).min(8);
        out[8 * b..8 * b + n].copy_from_slice(&lanes[..n]);
    }
}

/// The squared distance of two strips in one AVX register: the same eight
/// lane accumulators and summation tree as the portable `sq_dist`, no
/// fused multiply-adds, so the same float.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[inline]
pub(crate) fn strip_dist_avx<const B: usize>(a: &[[f32; 8]; B], b: &[[f32; 8]; B]) -> f32 {
    use std::arch::x86_64::*;
    // SAFETY: each load reads the eight floats of an `[f32; 8]`.
    let load = |w: &[f32; 8]| unsafe { _mm256_loadu_ps(w.as_ptr()) };
    let mut acc = _mm256_setzero_ps();
    for (x, y) in a.iter().zip(b) {
        let d = _mm256_sub_ps(load(x), load(y));
        acc = _mm256_add_ps(acc, _mm256_mul_ps(d, d));
    }
    // Lanes l and l + 4 first, then ((0 + 1) + (2 + 3)).
    let s = _mm_add_ps(_mm256_castps256_ps128(acc), _mm256_extractf128_ps::<1>(acc));
    let t = _mm_add_ps(s, _mm_movehdup_ps(s));
    _mm_cvtss_f32(_mm_add_ss(t, _mm_movehl_ps(t, t))) + 0.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::correction::tables::WIDE_RANGE;

    #[test]
    fn distances_are_sums_of_squares_over_the_whole_range() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            (state >> 33) as u32
        };
        let (lo, hi) = (WIDE_RANGE.0 as i32, WIDE_RANGE.1 as i32);
        for round in 0..2000 {
            let mut wide = |extreme: bool| {
                WideVector(std::array::from_fn(|_| {
                    let v = if extreme {
                        [lo, hi][next() as usize % 2]
                    } else {
                        lo + (next() % (hi - lo + 1) as u32) as i32
                    };
                    v as i16
                }))
            };
            let (a, q) = (wide(round % 3 == 0), wide(round % 5 == 0));
            assert_eq!(distance(&a, &q), scalar_distance(&a.0, &q));
            let sum = sum_clamped([&a, &q, &a, &q], WIDE_RANGE);
            for j in 0..SPARSE_DIMS {
                let exact = 2 * (a.0[j] as i32 + q.0[j] as i32);
                let clamped = exact.clamp(WIDE_RANGE.0 as i32, WIDE_RANGE.1 as i32);
                assert_eq!(sum.0[j] as i32, clamped);
            }
            let four: [SparseVector; BEST_CANDIDATES] =
                std::array::from_fn(|_| std::array::from_fn(|_| next() as u8));
            let expected = four.map(|v| scalar_distance(&v.map(|x| x as i16), &q));
            assert_eq!(best_distances::<false>(&four, &q), expected);
            #[cfg(target_arch = "x86_64")]
            if avx2() {
                assert_eq!(best_distances::<true>(&four, &q), expected);
            }
        }
    }
}
