//! The colour of a triple (the mean of its three exemplar colours) and
//! its rounding to RGB8, the one place synthesized colours become bytes.

use crate::candidates::Candidates;

/// Colour of a triple at level `k`: the mean of its three exemplar colours.
#[inline]
pub(crate) fn colour(c: &Candidates, k: usize, t: [u32; 3]) -> [f32; 3] {
    colour_at([0, 1, 2].map(|p| c.stack(p).level(k)), t)
}

/// Mean of a triple's three exemplar colours.
#[inline]
pub(crate) fn colour_at(planes: [&[[f32; 3]]; 3], t: [u32; 3]) -> [f32; 3] {
    let (a, b, d) = (
        planes[0][t[0] as usize],
        planes[1][t[1] as usize],
        planes[2][t[2] as usize],
    );
    [0, 1, 2].map(|ch| third(a[ch] + b[ch] + d[ch]))
}

/// `x / 3.0`, without a division. The product in f64 is within 2⁻⁵² of
/// the exact quotient, and an f32 divided by 3 never lies that close to a
/// rounding boundary of f32 (a midpoint would need an odd multiple of 3
/// among 24-bit significands), so the rounding is the same for every f32;
/// the unit test checks a spread of bit patterns.
#[inline(always)]
pub(crate) fn third(x: f32) -> f32 {
    (x as f64 * (1.0 / 3.0)) as f32
}

/// A colour rounded to RGB8.
#[inline]
pub(crate) fn rgb8(c: [f32; 3]) -> [u8; 3] {
    c.map(|v| v.round().clamp(0.0, 255.0) as u8)
}

/// The RGB8 colour of a triple at level `k`.
#[inline]
pub(crate) fn triple_rgb8(c: &Candidates, k: usize, t: [u32; 3]) -> [u8; 3] {
    rgb8(colour(c, k, t))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_third_rounds_like_the_division() {
        let same = |x: f32| assert_eq!(third(x).to_bits(), (x / 3.0).to_bits(), "{x:e}");
        // A spread of bit patterns: both signs, subnormals, every exponent.
        for bits in (0..=u32::MAX).step_by(4099) {
            let x = f32::from_bits(bits);
            if x.is_finite() {
                same(x);
            }
        }
        // Sums of three colour channels, finely spaced.
        for i in 0..=765 * 512 {
            same(i as f32 / 512.0);
        }
    }

    #[test]
    fn rgb8_rounds_and_clamps() {
        assert_eq!(rgb8([-3.0, 127.5, 300.0]), [0, 128, 255]);
        assert_eq!(rgb8([0.49, 254.5, 254.49]), [0, 255, 254]);
    }
}
