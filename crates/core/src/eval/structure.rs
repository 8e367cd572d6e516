//! Texture statistics that patch scores miss, cheap enough for CI: how the
//! luminance's energy spreads over scales (a band-pass spectrum) and over
//! directions (a gradient orientation histogram). A slice pieced together
//! from exemplar patches with its structure broken (dashes where cracks
//! were, clouds where veins were, blur) keeps its patch scores and loses
//! energy at the exemplar's scales and directions, and the sizes of its
//! connected dark and light features (connected components): veins and
//! cracks that fall apart into specks, or spots that merge into blobs.

use super::RgbView;

/// Octave bands of [`band_energies`], finest first.
const BANDS: usize = 4;

/// Orientation bins over 180° of [`orientation_histogram`].
const ORIENTATION_BINS: usize = 12;

/// Octave bins of component sizes of [`component_histograms`]: 1 pixel,
/// 2–3, 4–7, … (the last also holds everything larger).
const SIZE_BINS: usize = 12;

/// The dark and light features of [`component_histograms`]: pixels at or
/// below the image's own 25th luminance percentile, or at or above its
/// 75th.
const FEATURE_TAILS: [(f64, bool); 2] = [(0.25, true), (0.75, false)];

/// How far a slice's statistics are from its exemplar's (lower is better;
/// the spectrum and orientation are 0 for an image against itself, the
/// components near 0, as they compare with crops of it).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Structure {
    /// Mean over four octave bands of |ln(slice ÷ exemplar)| of
    /// the band's luminance energy: 0.7 is a band with half (or twice) the
    /// exemplar's energy. Blur lowers the fine bands, lost large features
    /// the coarse ones, noise raises the fine ones.
    pub spectrum: f64,
    /// Total-variation distance between the gradient orientation
    /// histograms (weighted by squared gradient), 0 to 1: how differently
    /// the edges are turned.
    pub orientation: f64,
    /// Total-variation distance between the sizes of connected features,
    /// 0 to 1, the mean over dark and light features (each pixel of the
    /// image's darkest and lightest quarter counts the size of its
    /// 4-connected component, in octave bins). Broken veins and cracks
    /// move weight to small sizes, merged spots to large ones. Compared
    /// with crops of the tiled exemplar of the slice's size, so borders
    /// cut both alike.
    pub components: f64,
}

/// Scores `slice` against `exemplar`, which is read as tileable (it wraps
/// at its borders); the slice is mirrored at its borders.
pub fn structure(slice: RgbView, exemplar: RgbView) -> Structure {
    slice.check("slice");
    exemplar.check("exemplar");
    let (s, e) = (Luma::new(slice, false), Luma::new(exemplar, true));
    let (bs, be) = (band_energies(&s), band_energies(&e));
    // A band the exemplar barely has does not dominate the mean (nor the
    // slice's borders, which the exemplar does not have): energies are
    // compared above a floor of 2 % of the exemplar's total.
    let floor = 0.02 * be.iter().sum::<f64>().max(1e-9);
    let spectrum = bs
        .iter()
        .zip(&be)
        .map(|(a, b)| ((a + floor) / (b + floor)).ln().abs())
        .sum::<f64>()
        / BANDS as f64;
    let (hs, he) = (orientation_histogram(&s), orientation_histogram(&e));
    let orientation = total_variation(&hs, &he);
    let components = components_distance(&s, &e);
    Structure {
        spectrum,
        orientation,
        components,
    }
}

/// Half the L1 distance of two histograms that each sum to 1.
fn total_variation(a: &[f64], b: &[f64]) -> f64 {
    0.5 * a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f64>()
}

/// [`Structure::components`] of slice `s` against exemplar `e`. The
/// exemplar's histogram is the mean over four crops of it tiled, each of
/// the slice's size, at offsets spread over its period: a feature larger
/// than the slice is cut by the slice's border as by a crop's.
fn components_distance(s: &Luma, e: &Luma) -> f64 {
    if s.v.is_empty() || e.v.is_empty() {
        return 0.0;
    }
    const CROPS: [(i64, i64); 4] = [(0, 0), (1, 2), (2, 1), (2, 2)];
    let mut reference = [[0.0; SIZE_BINS]; FEATURE_TAILS.len()];
    for &(a, b) in &CROPS {
        let crop = e.crop(a * e.w / 3, b * e.h / 3, s.w, s.h);
        for (r, h) in reference.iter_mut().zip(component_histograms(&crop)) {
            for (r, v) in r.iter_mut().zip(h) {
                *r += v / CROPS.len() as f64;
            }
        }
    }
    component_histograms(s)
        .iter()
        .zip(&reference)
        .map(|(h, r)| total_variation(h, r))
        .sum::<f64>()
        / FEATURE_TAILS.len() as f64
}

/// For each of [`FEATURE_TAILS`], the share of its pixels whose
/// 4-connected component (within the image, not wrapping) has each
/// octave of size, normalised to sum 1.
fn component_histograms(l: &Luma) -> [[f64; SIZE_BINS]; FEATURE_TAILS.len()] {
    let mut sorted = l.v.clone();
    sorted.sort_by(f64::total_cmp);
    FEATURE_TAILS.map(|(q, dark)| {
        let t = sorted[((sorted.len() - 1) as f64 * q) as usize];
        tail_histogram(l, |v| if dark { v <= t } else { v >= t })
    })
}

/// [`component_histograms`] of the pixels whose luminance is `member`.
fn tail_histogram(l: &Luma, member: impl Fn(f64) -> bool) -> [f64; SIZE_BINS] {
    let member: Vec<bool> = l.v.iter().map(|&v| member(v)).collect();
    let (w, h) = (l.w as usize, l.h as usize);
    let mut seen = vec![false; member.len()];
    let mut bins = [0.0; SIZE_BINS];
    let mut stack = Vec::new();
    for start in 0..member.len() {
        if !member[start] || seen[start] {
            continue;
        }
        // Flood fill; the component's size is added once per member.
        seen[start] = true;
        stack.push(start);
        let mut size = 0usize;
        while let Some(i) = stack.pop() {
            size += 1;
            let (x, y) = (i % w, i / w);
            let mut visit = |j: usize| {
                if member[j] && !seen[j] {
                    seen[j] = true;
                    stack.push(j);
                }
            };
            if x > 0 {
                visit(i - 1);
            }
            if x + 1 < w {
                visit(i + 1);
            }
            if y > 0 {
                visit(i - w);
            }
            if y + 1 < h {
                visit(i + w);
            }
        }
        let bin = (size.ilog2() as usize).min(SIZE_BINS - 1);
        bins[bin] += size as f64;
    }
    let total: f64 = bins.iter().sum();
    bins.map(|b| b / total)
}

/// Luminance with its border rule.
struct Luma {
    w: i64,
    h: i64,
    v: Vec<f64>,
    wrap: bool,
}

impl Luma {
    fn new(image: RgbView, wrap: bool) -> Luma {
        let n = image.pixel_count();
        let v = image.rgb[..n * 3]
            .chunks_exact(3)
            .map(|c| crate::analysis::exemplar::luminance([c[0], c[1], c[2]]))
            .collect();
        Luma {
            w: image.width as i64,
            h: image.height as i64,
            v,
            wrap,
        }
    }

    fn index(&self, x: i64, y: i64) -> usize {
        let (x, y) = if self.wrap {
            (x.rem_euclid(self.w), y.rem_euclid(self.h))
        } else {
            (mirror(x, self.w), mirror(y, self.h))
        };
        (y * self.w + x) as usize
    }

    /// The `w` × `h` window from (`x0`, `y0`), read by the border rule,
    /// as an image of its own that does not wrap.
    fn crop(&self, x0: i64, y0: i64, w: i64, h: i64) -> Luma {
        let v = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| self.v[self.index(x0 + x, y0 + y)])
            .collect();
        Luma {
            w,
            h,
            v,
            wrap: false,
        }
    }

    /// `src` blurred by the binomial [1 4 6 4 1]/16 with taps `step` apart
    /// along x then y.
    fn blur(&self, src: &[f64], step: i64) -> Vec<f64> {
        const TAPS: [f64; 5] = [1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0];
        let pass = |src: &[f64], dx: i64, dy: i64| -> Vec<f64> {
            let mut out = Vec::with_capacity(src.len());
            for y in 0..self.h {
                for x in 0..self.w {
                    let mut acc = 0.0;
                    for (t, &wt) in TAPS.iter().enumerate() {
                        let o = t as i64 - 2;
                        acc += wt * src[self.index(x + o * dx, y + o * dy)];
                    }
                    out.push(acc);
                }
            }
            out
        };
        pass(&pass(src, step, 0), 0, step)
    }
}

/// `i` reflected into `0..n` (…, 1, 0, 0, 1, …, n − 1, n − 1, n − 2, …).
fn mirror(i: i64, n: i64) -> i64 {
    let m = i.rem_euclid(2 * n);
    if m < n { m } else { 2 * n - 1 - m }
}

/// Mean squared value of each octave band of the luminance: band k is the
/// image blurred at scale 2^k less the image blurred at 2^(k+1) ("à
/// trous", as the synthesis's Gaussian stack), finest first.
fn band_energies(l: &Luma) -> [f64; BANDS] {
    let mut out = [0.0; BANDS];
    if l.v.is_empty() {
        return out;
    }
    let mut fine = l.v.clone();
    for (k, e) in out.iter_mut().enumerate() {
        let coarse = l.blur(&fine, 1 << k);
        *e = fine
            .iter()
            .zip(&coarse)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            / fine.len() as f64;
        fine = coarse;
    }
    out
}

/// Histogram of gradient orientations (central differences, folded to
/// 0–180°), each gradient weighted by its squared magnitude, normalised to
/// sum 1 (uniform for a flat image).
fn orientation_histogram(l: &Luma) -> [f64; ORIENTATION_BINS] {
    let mut bins = [0.0; ORIENTATION_BINS];
    for y in 0..l.h {
        for x in 0..l.w {
            let gx = l.v[l.index(x + 1, y)] - l.v[l.index(x - 1, y)];
            let gy = l.v[l.index(x, y + 1)] - l.v[l.index(x, y - 1)];
            let m = gx * gx + gy * gy;
            if m == 0.0 {
                continue;
            }
            let a = gy.atan2(gx).rem_euclid(std::f64::consts::PI);
            let b = ((a / std::f64::consts::PI * ORIENTATION_BINS as f64) as usize)
                .min(ORIENTATION_BINS - 1);
            bins[b] += m;
        }
    }
    let total: f64 = bins.iter().sum();
    if total == 0.0 {
        return [1.0 / ORIENTATION_BINS as f64; ORIENTATION_BINS];
    }
    bins.map(|b| b / total)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::shuffled_exemplar;

    /// Soft blobs on a 64-pixel period (tileable), with fine grain.
    fn blobs(w: u32, h: u32, phase: u32) -> Vec<u8> {
        (0..w * h)
            .flat_map(|i| {
                let (x, y) = ((i % w + phase) as f64, (i / w) as f64);
                let t = std::f64::consts::TAU / 64.0;
                let s = (x * t).sin() * (y * t * 2.0).cos() + 0.5 * (x * t * 3.0 + y * t).sin();
                let g = ((i * 7919) % 13) as f64;
                let l = (120.0 + 60.0 * s + g).clamp(0.0, 255.0) as u8;
                [l, l / 2 + 40, 90]
            })
            .collect()
    }

    fn stripes(w: u32, h: u32, vertical: bool) -> Vec<u8> {
        (0..w * h)
            .flat_map(|i| {
                let (c, d) = if vertical {
                    (i % w, i / w)
                } else {
                    (i / w, i % w)
                };
                let l = if c % 12 < 4 { 40 } else { 200 } + ((c * 31 + d * 17) % 11) as u8;
                [l, l, l]
            })
            .collect()
    }

    fn view(rgb: &[u8], w: u32, h: u32) -> RgbView<'_> {
        RgbView {
            width: w,
            height: h,
            rgb,
        }
    }

    #[test]
    fn an_image_matches_itself_and_its_shifted_copy() {
        let e = blobs(64, 64, 0);
        let s = structure(view(&e, 64, 64), view(&e, 64, 64));
        assert!(s.spectrum < 0.05 && s.orientation < 0.02, "{s:?}");
        assert!(s.components < 0.2, "{s:?}");
        // A larger crop of the same pattern, at another phase, not tiled.
        let crop = blobs(96, 80, 17);
        let s = structure(view(&crop, 96, 80), view(&e, 64, 64));
        assert!(s.spectrum < 0.15 && s.orientation < 0.1, "{s:?}");
        assert!(s.components < 0.2, "{s:?}");
    }

    #[test]
    fn shuffles_blur_and_turns_are_far() {
        let e = blobs(64, 64, 0);
        let ex = view(&e, 64, 64);
        let shuffled = shuffled_exemplar(ex, 64, 64, 3);
        let noise = structure(view(&shuffled, 64, 64), ex);
        assert!(noise.spectrum > 1.0, "{noise:?}");
        // Blurred: the fine bands lose most of their energy.
        let l = Luma::new(ex, true);
        let blurred: Vec<u8> = l
            .blur(&l.blur(&l.v, 1), 2)
            .iter()
            .flat_map(|&v| [v as u8; 3])
            .collect();
        let blur = structure(view(&blurred, 64, 64), ex);
        assert!(blur.spectrum > 0.3, "{blur:?}");
        // Stripes turned a quarter: the same spectrum, other directions.
        let (h, v) = (stripes(96, 96, false), stripes(96, 96, true));
        let turned = structure(view(&v, 96, 96), view(&h, 96, 96));
        assert!(turned.orientation > 0.8, "{turned:?}");
        assert!(turned.spectrum < 0.2, "{turned:?}");
        let same = structure(view(&h, 96, 96), view(&h, 96, 96));
        assert!(same.orientation < 0.05 && same.spectrum < 0.2, "{same:?}");
        let flat = [128u8; 16 * 16 * 3];
        let s = structure(view(&flat, 16, 16), view(&flat, 16, 16));
        assert_eq!((s.spectrum, s.orientation, s.components), (0.0, 0.0, 0.0));
    }

    /// Dark stripes 4 pixels wide every 12, cut into dashes `dash` pixels
    /// long (0: unbroken).
    fn dashes(w: u32, h: u32, dash: u32) -> Vec<u8> {
        (0..w * h)
            .flat_map(|i| {
                let (x, y) = (i % w, i / w);
                let gap = dash > 0 && x % (2 * dash) >= dash;
                let l = if y % 12 < 4 && !gap { 30 } else { 200 } + ((x * 31 + y * 17) % 11) as u8;
                [l, l, l]
            })
            .collect()
    }

    #[test]
    fn broken_and_merged_features_are_far_in_size() {
        let e = dashes(48, 48, 0);
        let ex = view(&e, 48, 48);
        // Crops of the same stripes, at another phase: the same sizes.
        let s = dashes(96, 80, 0);
        let same = structure(view(&s, 96, 80), ex);
        assert!(same.components < 0.05, "{same:?}");
        // The stripes broken into dashes: the same dark share and
        // directions along them, but small components.
        let d = dashes(96, 80, 3);
        let broken = structure(view(&d, 96, 80), ex);
        assert!(broken.components > 0.4, "{broken:?}");
        // Dashes as the exemplar, unbroken stripes as the slice: merged.
        let dash_ex = dashes(48, 48, 3);
        let merged = structure(view(&s, 96, 80), view(&dash_ex, 48, 48));
        assert!(merged.components > 0.4, "{merged:?}");
        let shuffled = shuffled_exemplar(ex, 96, 80, 5);
        let noise = structure(view(&shuffled, 96, 80), ex);
        assert!(noise.components > 0.5, "{noise:?}");
    }
}
