//! Grey-level co-occurrence features (Chang et al. 2012, after Haralick
//! et al. and Clausi): for every exemplar pixel, the co-occurrence
//! probabilities of the grey levels in a window around it, for four
//! displacements one pixel long (0°, 45°, 90°, 135°), summarised by their
//! entropy, contrast and correlation: 12 values per pixel. They describe
//! how grey levels sit next to each other around a pixel, which a 5×5
//! colour neighbourhood alone does not: matching on them keeps rough
//! next to rough and smooth next to smooth.
//!
//! The paper quantises to G = 32 grey levels over a 15×15 window; both
//! carry over. Each feature is standardised over the exemplar and the
//! twelve together are scaled so that their total variance is `weight`²
//! times the three colour channels' (the paper's weights 0.4 : 0.6 for
//! colour textures are `weight` = 2/3). The paper appends a pixel's
//! features to its appearance vector after the PCA; here they are extra
//! values of every neighbourhood pixel before it, like the
//! feature-distance channel ([`crate::analysis::feature`]), so the
//! appearance vectors keep their length and the correction its cost.

use crate::analysis::exemplar::Exemplar;

/// Grey levels of the quantisation.
pub const GREY_LEVELS: usize = 32;
/// Side of the window around each pixel.
pub const WINDOW: i64 = 15;
/// The four displacements, one pixel long: 0°, 45°, 90° and 135°.
const DISPLACEMENTS: [(i64, i64); 4] = [(1, 0), (1, -1), (0, -1), (-1, -1)];
/// Values per pixel: entropy, contrast and correlation per displacement.
pub const CHANNELS: usize = 12;

/// The 12 co-occurrence features of every pixel, `CHANNELS` per pixel
/// (row-major pixels; the window wraps), scaled as the module says.
pub fn glcp_features(e: &Exemplar, weight: f32) -> Vec<f32> {
    let (w, h) = (e.width() as i64, e.height() as i64);
    let grey: Vec<u8> = e
        .pixels()
        .iter()
        .map(|p| {
            let l = 0.299 * p[0] as f32 + 0.587 * p[1] as f32 + 0.114 * p[2] as f32;
            ((l * GREY_LEVELS as f32 / 256.0) as usize).min(GREY_LEVELS - 1) as u8
        })
        .collect();
    let at = |x: i64, y: i64| grey[(y.rem_euclid(h) * w + x.rem_euclid(w)) as usize] as usize;
    let r = WINDOW / 2;
    let mut out = vec![0f32; (w * h) as usize * CHANNELS];
    let mut counts = vec![0u32; GREY_LEVELS * GREY_LEVELS];
    let mut touched: Vec<usize> = Vec::with_capacity(2 * (WINDOW * WINDOW) as usize);
    for y in 0..h {
        for x in 0..w {
            let px = &mut out[((y * w + x) as usize) * CHANNELS..][..CHANNELS];
            for (d, &(dx, dy)) in DISPLACEMENTS.iter().enumerate() {
                // Symmetric counts: each pair is seen both ways.
                let mut n = 0u32;
                let (mut sum, mut sum_sq, mut sum_xy, mut contrast) = (0f64, 0f64, 0f64, 0f64);
                for j in -r..=r {
                    for i in -r..=r {
                        let a = at(x + i, y + j);
                        let b = at(x + i + dx, y + j + dy);
                        for (p, q) in [(a, b), (b, a)] {
                            let cell = p * GREY_LEVELS + q;
                            if counts[cell] == 0 {
                                touched.push(cell);
                            }
                            counts[cell] += 1;
                        }
                        n += 2;
                        let (fa, fb) = (a as f64, b as f64);
                        sum += fa + fb;
                        sum_sq += fa * fa + fb * fb;
                        sum_xy += 2.0 * fa * fb;
                        contrast += 2.0 * (fa - fb) * (fa - fb);
                    }
                }
                let nf = n as f64;
                let mut entropy = 0f64;
                for &cell in &touched {
                    let c = counts[cell] as f64 / nf;
                    entropy -= c * c.ln();
                    counts[cell] = 0;
                }
                touched.clear();
                let mean = sum / nf;
                let var = sum_sq / nf - mean * mean;
                let correlation = if var > 1e-12 {
                    (sum_xy / nf - mean * mean) / var
                } else {
                    1.0
                };
                px[d * 3] = entropy as f32;
                px[d * 3 + 1] = (contrast / nf) as f32;
                px[d * 3 + 2] = correlation as f32;
            }
        }
    }
    scale(
        &mut out,
        colour_spread(e) * weight * (3.0 / CHANNELS as f32).sqrt(),
    );
    out
}

/// Root mean variance of the three colour channels.
fn colour_spread(e: &Exemplar) -> f32 {
    let n = e.pixels().len().max(1) as f64;
    let var: f64 = (0..3)
        .map(|ch| {
            let mean = e.pixels().iter().map(|p| p[ch] as f64).sum::<f64>() / n;
            e.pixels()
                .iter()
                .map(|p| (p[ch] as f64 - mean).powi(2))
                .sum::<f64>()
                / n
        })
        .sum::<f64>()
        / 3.0;
    var.sqrt() as f32
}

/// Standardises each channel, then multiplies it by `gain` (a constant
/// channel becomes 0).
fn scale(values: &mut [f32], gain: f32) {
    let pixels = values.len() / CHANNELS;
    for ch in 0..CHANNELS {
        let get = |i: usize| values[i * CHANNELS + ch] as f64;
        let n = pixels.max(1) as f64;
        let mean = (0..pixels).map(get).sum::<f64>() / n;
        let sd = ((0..pixels).map(|i| (get(i) - mean).powi(2)).sum::<f64>() / n).sqrt();
        for i in 0..pixels {
            let v = &mut values[i * CHANNELS + ch];
            *v = if sd > 1e-9 {
                ((*v as f64 - mean) / sd * gain as f64) as f32
            } else {
                0.0
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(w: u32, h: u32, f: impl Fn(u32, u32) -> u8) -> Exemplar {
        let mut rgb = Vec::new();
        for y in 0..h {
            for x in 0..w {
                rgb.extend([f(x, y); 3]);
            }
        }
        Exemplar::from_rgb(w, h, &rgb).unwrap()
    }

    #[test]
    fn stripes_and_noise_differ_in_contrast_and_correlation() {
        // Left half: vertical stripes two pixels wide; right half: noise.
        let e = image(64, 32, |x, y| {
            if x < 32 {
                if (x / 2) % 2 == 0 { 0 } else { 255 }
            } else {
                ((x * 7919 + y * 104_729) % 251) as u8
            }
        });
        let f = glcp_features(&e, 1.0);
        let px = |x: usize, y: usize| &f[(y * 64 + x) * CHANNELS..][..CHANNELS];
        let (stripes, noise) = (px(16, 16), px(48, 16));
        // At 90° (vertical displacement) stripes correlate perfectly and
        // have no contrast; noise has both lower correlation and entropy
        // higher than the two-level stripes.
        assert!(stripes[3 * 2 + 2] > noise[3 * 2 + 2]);
        assert!(stripes[3 * 2 + 1] < noise[3 * 2 + 1]);
        assert!(stripes[3 * 2] < noise[3 * 2]);
        // The features are scaled: every channel has zero mean.
        for ch in 0..CHANNELS {
            let m: f32 = (0..64 * 32).map(|i| f[i * CHANNELS + ch]).sum::<f32>() / 2048.0;
            assert!(m.abs() < 1e-3, "channel {ch} mean {m}");
        }
    }

    #[test]
    fn a_flat_image_has_no_features() {
        let f = glcp_features(&image(16, 16, |_, _| 90), 0.5);
        assert!(f.iter().all(|&v| v == 0.0));
    }
}
