//! The feature-distance channel (Lefebvre and Hoppe 2006; the feature
//! masks of Zhang et al. §4 and Fig. 16). Veins, cracks and mortar are
//! thin: a 5×5 colour neighbourhood sees a line only where it crosses it,
//! so matching in colour alone lets features break off and drift.
//! A signed distance to the feature's edges tells every pixel how far it
//! is from the nearest feature, so neighbourhoods next to a vein match
//! only pixels next to a vein, and the vein continues.
//!
//! The feature is the exemplar's feature mask when one was given (drawn by
//! the user, Zhang et al. Fig. 16). Otherwise it is found automatically:
//! the exemplar's luminance, lightly blurred, is split in two by Otsu's
//! threshold, and the smaller class is the feature. The distance is
//! clamped to a radius that grows with the exemplar and scaled so its
//! spread is `weight` times the luminance's.

use crate::analysis::exemplar::Exemplar;

/// Signed distance to the feature's edges, one value per pixel (row-major,
/// wrapping at the borders), positive inside the feature, scaled by
/// `weight` times the luminance's standard deviation per standard
/// deviation of the distance.
pub fn feature_distance(e: &Exemplar, weight: f32) -> Vec<f32> {
    let (w, h) = (e.width() as usize, e.height() as usize);
    let luma = smoothed_luminance(e);
    let mask = match e.feature_mask() {
        Some(given) => given.to_vec(),
        None => automatic_mask(&luma),
    };
    let radius = (w.min(h) / 16).max(4);
    let signed = signed_distance(&mask, w, h, radius);
    let spread = |v: &[f32]| {
        let n = v.len().max(1) as f64;
        let mean = v.iter().map(|&x| x as f64).sum::<f64>() / n;
        (v.iter().map(|&x| (x as f64 - mean).powi(2)).sum::<f64>() / n).sqrt()
    };
    let (sl, sd) = (spread(&luma), spread(&signed));
    if sd == 0.0 {
        return vec![0.0; signed.len()];
    }
    let gain = (weight as f64 * sl / sd) as f32;
    signed.into_iter().map(|s| s * gain).collect()
}

/// The feature found in the (smoothed) luminance: Otsu's threshold splits
/// it in two, and the smaller class (the darker one on a tie) is the
/// feature.
fn automatic_mask(luma: &[f32]) -> Vec<bool> {
    let threshold = otsu(luma);
    let above = luma.iter().filter(|&&l| l > threshold).count();
    let dark_feature = above * 2 >= luma.len();
    luma.iter()
        .map(|&l| (l > threshold) != dark_feature)
        .collect()
}

/// Rec. 601 luminance blurred by the 3×3 binomial kernel, so that single
/// noisy pixels do not make features of their own.
fn smoothed_luminance(e: &Exemplar) -> Vec<f32> {
    let (w, h) = (e.width() as i64, e.height() as i64);
    let luma: Vec<f32> = e
        .pixels()
        .iter()
        .map(|p| 0.299 * p[0] as f32 + 0.587 * p[1] as f32 + 0.114 * p[2] as f32)
        .collect();
    let at = |x: i64, y: i64| luma[(y.rem_euclid(h) * w + x.rem_euclid(w)) as usize];
    const TAPS: [f32; 3] = [0.25, 0.5, 0.25];
    let mut out = Vec::with_capacity(luma.len());
    for y in 0..h {
        for x in 0..w {
            let mut acc = 0f32;
            for (j, &wj) in TAPS.iter().enumerate() {
                for (i, &wi) in TAPS.iter().enumerate() {
                    acc += wj * wi * at(x + i as i64 - 1, y + j as i64 - 1);
                }
            }
            out.push(acc);
        }
    }
    out
}

/// Otsu's threshold over 256 bins: the level that maximises the variance
/// between the classes at or below it and above it (the lowest such level
/// on a tie).
fn otsu(values: &[f32]) -> f32 {
    let mut histogram = [0u64; 256];
    for &v in values {
        histogram[v.round().clamp(0.0, 255.0) as usize] += 1;
    }
    let total = values.len() as f64;
    let sum: f64 = histogram
        .iter()
        .enumerate()
        .map(|(i, &c)| i as f64 * c as f64)
        .sum();
    let (mut below, mut below_sum) = (0f64, 0f64);
    let (mut best, mut best_t) = (-1f64, 0usize);
    for (t, &c) in histogram.iter().enumerate() {
        below += c as f64;
        below_sum += t as f64 * c as f64;
        let above = total - below;
        if below == 0.0 || above == 0.0 {
            continue;
        }
        let d = below_sum / below - (sum - below_sum) / above;
        let between = below * above * d * d;
        if between > best {
            best = between;
            best_t = t;
        }
    }
    best_t as f32 + 0.5
}

/// Signed Euclidean distance from each pixel's centre to the nearest pixel
/// of the other class, less half a pixel so both sides of an edge are
/// ±0.5 from it: positive where `mask` is set. Clamped to ±`radius`, which
/// also bounds the wrapped margin that makes the transform tileable.
fn signed_distance(mask: &[bool], w: usize, h: usize, radius: usize) -> Vec<f32> {
    let inside = squared_distance_to(mask, w, h, radius, false);
    let outside = squared_distance_to(mask, w, h, radius, true);
    let r = radius as f32;
    mask.iter()
        .zip(inside.iter().zip(&outside))
        .map(|(&m, (&di, &dout))| {
            if m {
                (di.sqrt() - 0.5).min(r)
            } else {
                -(dout.sqrt() - 0.5).min(r)
            }
        })
        .collect()
}

/// Squared distance from each pixel to the nearest pixel whose mask is
/// `target`, exact up to `radius` (larger distances come out larger than
/// radius²), on the torus: the image is extended by `radius` pixels of
/// wrapped margin and transformed by rows then columns (Felzenszwalb and
/// Huttenlocher's lower envelope of parabolas).
fn squared_distance_to(mask: &[bool], w: usize, h: usize, radius: usize, target: bool) -> Vec<f32> {
    let m = radius + 1;
    let (ew, eh) = (w + 2 * m, h + 2 * m);
    let far = ((ew + eh) * (ew + eh)) as f32;
    let mut grid = vec![far; ew * eh];
    for y in 0..eh {
        let sy = (y + h * m - m) % h;
        for x in 0..ew {
            let sx = (x + w * m - m) % w;
            if mask[sy * w + sx] == target {
                grid[y * ew + x] = 0.0;
            }
        }
    }
    let mut line = Vec::new();
    let mut out = Vec::new();
    for y in 0..eh {
        line.clear();
        line.extend_from_slice(&grid[y * ew..(y + 1) * ew]);
        envelope(&line, &mut out);
        grid[y * ew..(y + 1) * ew].copy_from_slice(&out);
    }
    let mut result = vec![0f32; w * h];
    for x in m..m + w {
        line.clear();
        line.extend((0..eh).map(|y| grid[y * ew + x]));
        envelope(&line, &mut out);
        for y in m..m + h {
            result[(y - m) * w + (x - m)] = out[y];
        }
    }
    result
}

/// One-dimensional squared distance transform of `f`: out[q] =
/// min over p of (q − p)² + f[p].
fn envelope(f: &[f32], out: &mut Vec<f32>) {
    let n = f.len();
    out.clear();
    out.resize(n, 0.0);
    let mut v = vec![0usize; n];
    let mut z = vec![0f32; n + 1];
    let mut k = 0usize;
    z[0] = f32::NEG_INFINITY;
    z[1] = f32::INFINITY;
    let meet = |q: usize, p: usize| {
        ((f[q] + (q * q) as f32) - (f[p] + (p * p) as f32)) / (2.0 * q as f32 - 2.0 * p as f32)
    };
    for q in 1..n {
        let mut s = meet(q, v[k]);
        while s <= z[k] {
            k -= 1;
            s = meet(q, v[k]);
        }
        k += 1;
        v[k] = q;
        z[k] = s;
        z[k + 1] = f32::INFINITY;
    }
    k = 0;
    for (q, o) in out.iter_mut().enumerate() {
        while z[k + 1] < q as f32 {
            k += 1;
        }
        let d = q as f32 - v[k] as f32;
        *o = d * d + f[v[k]];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Brute-force squared distance on the torus.
    fn brute(mask: &[bool], w: usize, h: usize, target: bool) -> Vec<f32> {
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as i64, (i / w) as i64);
                (0..w * h)
                    .filter(|&j| mask[j] == target)
                    .map(|j| {
                        let dx = (x - (j % w) as i64).rem_euclid(w as i64);
                        let dy = (y - (j / w) as i64).rem_euclid(h as i64);
                        let dx = dx.min(w as i64 - dx);
                        let dy = dy.min(h as i64 - dy);
                        (dx * dx + dy * dy) as f32
                    })
                    .fold(f32::INFINITY, f32::min)
            })
            .collect()
    }

    #[test]
    fn distances_are_exact_within_the_radius_and_wrap() {
        let (w, h) = (23, 17);
        let mask: Vec<bool> = (0..w * h)
            .map(|i| (i * 7919 + i / 5) % 37 == 0 || i % w == 3)
            .collect();
        let radius = 5;
        for target in [true, false] {
            let got = squared_distance_to(&mask, w, h, radius, target);
            let want = brute(&mask, w, h, target);
            for (i, (g, wt)) in got.iter().zip(&want).enumerate() {
                if *wt <= (radius * radius) as f32 {
                    assert_eq!(g, wt, "pixel {i}, target {target}");
                } else {
                    assert!(*g > (radius * radius) as f32, "pixel {i}");
                }
            }
        }
    }

    #[test]
    fn thin_dark_lines_are_the_feature() {
        // Light ground with dark vertical lines two pixels wide, 16 apart.
        let side = 64u32;
        let rgb: Vec<u8> = (0..side * side)
            .flat_map(|i| {
                let x = i % side;
                let l = if x % 16 < 2 {
                    30
                } else {
                    200 + (i * 13 % 7) as u8
                };
                [l, l, l]
            })
            .collect();
        let e = Exemplar::from_rgb(side, side, &rgb).unwrap();
        let f = feature_distance(&e, 1.0);
        let at = |x: u32| f[(5 * side + x) as usize];
        // Positive on the lines, negative off them, falling with distance.
        assert!(at(0) > 0.0 && at(1) > 0.0);
        assert!(at(2) < 0.0 && at(15) < 0.0);
        assert!(at(8) < at(4) && at(4) < at(2));
        // Symmetric about the middle between two lines.
        assert!((at(5) - at(12)).abs() < 1e-3);
        // No feature at all: a flat exemplar gets a zero channel.
        let flat = Exemplar::from_rgb(16, 16, &[90u8; 16 * 16 * 3]).unwrap();
        assert!(feature_distance(&flat, 1.0).iter().all(|&v| v == 0.0));
    }

    #[test]
    fn a_given_mask_is_the_feature_whatever_the_colours() {
        // The same dark lines, but the mask marks a horizontal band that no
        // colour shows: the distance follows the mask.
        let side = 32u32;
        let rgb: Vec<u8> = (0..side * side)
            .flat_map(|i| {
                let l = if i % side % 8 < 2 { 30 } else { 200 };
                [l, l, l]
            })
            .collect();
        let e = Exemplar::from_rgb(side, side, &rgb).unwrap();
        let mask: Vec<bool> = (0..side * side)
            .map(|i| (10..13).contains(&(i / side)))
            .collect();
        let masked = e.clone().with_feature_mask(mask).unwrap();
        let f = feature_distance(&masked, 1.0);
        let at = |x: u32, y: u32| f[(y * side + x) as usize];
        // Inside the band positive, outside negative, along every column
        // alike (the lines do not matter).
        assert!(at(0, 11) > 0.0 && at(5, 11) > 0.0);
        assert!(at(0, 20) < 0.0 && at(5, 20) < 0.0);
        for x in 0..side {
            assert_eq!(at(x, 20), at(0, 20), "column {x}");
            assert!(at(x, 14) > at(x, 20), "column {x}");
        }
        // Without the mask the lines are the feature, and giving the mask
        // found automatically changes nothing.
        let auto = feature_distance(&e, 1.0);
        assert!(auto[0] > 0.0 && auto[5] < 0.0);
        let found = automatic_mask(&smoothed_luminance(&e));
        let given = e.with_feature_mask(found).unwrap();
        assert_eq!(feature_distance(&given, 1.0), auto);
    }
}
