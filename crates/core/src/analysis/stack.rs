//! Gaussian image stack (Lefebvre & Hoppe 2005; Zhang et al. §4.2.1): every
//! level keeps the exemplar's full resolution and is blurred further instead
//! of downsampled, so level k is sampled at spacing h_k = 2^k with any
//! sub-pixel phase. Boundaries wrap (exemplars are treated as tileable).

use crate::analysis::exemplar::Exemplar;
use std::sync::Arc;

/// Spacing of level `k` (0 = finest).
pub fn spacing(level: usize) -> u32 {
    1 << level
}

/// One plane's stack: `levels[k][y * width + x]` is an RGB colour in 0..255.
#[derive(Clone, Debug)]
pub struct GaussianStack {
    width: u32,
    height: u32,
    /// Shared, so that the three planes of a single exemplar hold one copy:
    /// the correction reads all three at random, and one copy stays in
    /// cache where three would not.
    levels: Arc<Vec<Vec<[f32; 3]>>>,
    /// The same colours padded to four floats (the fourth is 0), so that
    /// the correction loads a colour as one 16-byte vector.
    padded: Arc<Vec<Vec<[f32; 4]>>>,
    /// The feature-distance channel, blurred like the colours, when the
    /// analysis adds one (see [`crate::analysis::feature`]).
    feature: Option<Arc<Vec<Vec<f32>>>>,
}

impl GaussianStack {
    /// Builds `count` levels from an exemplar. Level k+1 is level k blurred
    /// by the binomial kernel [1 4 6 4 1]/16 with taps h_k apart ("à trous"),
    /// which approximates a Gaussian whose width doubles per level.
    pub fn new(exemplar: &Exemplar, count: usize) -> Self {
        let (w, h) = (exemplar.width(), exemplar.height());
        let base: Vec<[f32; 3]> = exemplar
            .pixels()
            .iter()
            .map(|p| [p[0] as f32, p[1] as f32, p[2] as f32])
            .collect();
        let levels = blurred_levels(base, w, h, count);
        let padded = levels
            .iter()
            .map(|l| l.iter().map(|&[r, g, b]| [r, g, b, 0.0]).collect())
            .collect();
        GaussianStack {
            width: w,
            height: h,
            levels: Arc::new(levels),
            padded: Arc::new(padded),
            feature: None,
        }
    }

    /// The same stack with a feature-distance channel (one value per
    /// pixel of the finest level), blurred level by level like the colours.
    pub fn with_feature(mut self, base: Vec<f32>) -> Self {
        debug_assert_eq!(base.len(), (self.width * self.height) as usize);
        let base = base.into_iter().map(|v| [v]).collect();
        let levels = blurred_levels(base, self.width, self.height, self.len());
        self.feature = Some(Arc::new(
            levels
                .into_iter()
                .map(|l| l.into_iter().map(|[v]| v).collect())
                .collect(),
        ));
        self
    }

    /// Values per pixel in an appearance neighbourhood: the three colours,
    /// and the feature distance when there is one.
    pub fn channels(&self) -> usize {
        if self.feature.is_some() { 4 } else { 3 }
    }

    /// The feature-distance channel of level `k`, if any.
    pub fn feature_level(&self, k: usize) -> Option<&[f32]> {
        self.feature.as_ref().map(|f| f[k].as_slice())
    }

    /// Number of levels.
    pub fn len(&self) -> usize {
        self.levels.len()
    }

    /// True if there are no levels.
    pub fn is_empty(&self) -> bool {
        self.levels.is_empty()
    }

    /// Width of every level.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height of every level.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// All pixels of level `k`.
    pub fn level(&self, k: usize) -> &[[f32; 3]] {
        &self.levels[k]
    }

    /// All pixels of level `k`, padded to four floats.
    pub fn level_padded(&self, k: usize) -> &[[f32; 4]] {
        &self.padded[k]
    }

    /// Colour of level `k` at (x, y), wrapping.
    #[inline]
    pub fn at(&self, k: usize, x: i64, y: i64) -> [f32; 3] {
        let xi = x.rem_euclid(self.width as i64) as usize;
        let yi = y.rem_euclid(self.height as i64) as usize;
        self.levels[k][yi * self.width as usize + xi]
    }
}

const BINOMIAL: [f32; 5] = [1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0];

/// `count` levels from `base`, each the previous one blurred.
fn blurred_levels<const C: usize>(
    base: Vec<[f32; C]>,
    w: u32,
    h: u32,
    count: usize,
) -> Vec<Vec<[f32; C]>> {
    let mut levels = vec![base];
    for k in 1..count {
        let prev = &levels[k - 1];
        let step = spacing(k - 1) as i64;
        let horizontal = blur(prev, w, h, step, 0);
        levels.push(blur(&horizontal, w, h, 0, step));
    }
    levels
}

fn blur<const C: usize>(src: &[[f32; C]], w: u32, h: u32, dx: i64, dy: i64) -> Vec<[f32; C]> {
    let (wi, hi) = (w as i64, h as i64);
    let mut out = vec![[0f32; C]; src.len()];
    for y in 0..hi {
        for x in 0..wi {
            let mut acc = [0f32; C];
            for (t, &wt) in BINOMIAL.iter().enumerate() {
                let o = t as i64 - 2;
                let sx = (x + o * dx).rem_euclid(wi);
                let sy = (y + o * dy).rem_euclid(hi);
                let c = src[(sy * wi + sx) as usize];
                for ch in 0..C {
                    acc[ch] += wt * c[ch];
                }
            }
            out[(y * wi + x) as usize] = acc;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blur_preserves_mean_and_reduces_variance() {
        let rgb: Vec<u8> = (0..32 * 32 * 3).map(|i| ((i * 7919) % 251) as u8).collect();
        let e = Exemplar::from_rgb(32, 32, &rgb).unwrap();
        let s = GaussianStack::new(&e, 4);
        let stats = |k: usize| {
            let l = s.level(k);
            let m: f32 = l.iter().map(|c| c[0]).sum::<f32>() / l.len() as f32;
            let v: f32 = l.iter().map(|c| (c[0] - m).powi(2)).sum::<f32>() / l.len() as f32;
            (m, v)
        };
        let (m0, v0) = stats(0);
        for k in 1..4 {
            let (m, v) = stats(k);
            assert!((m - m0).abs() < 0.01, "mean drifted at level {k}");
            assert!(v < v0 * 0.5, "level {k} not smoother: {v} vs {v0}");
        }
    }
}
