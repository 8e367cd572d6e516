//! Usage calibration: the lazy engine's counterpart of the histogram
//! matching of Kopf et al. 2007 and Chen & Wang 2010. Their optimisation
//! pushes the solid's colour histogram and its position histogram (how
//! often each exemplar pixel is used) back toward the exemplar's between
//! iterations: over-used calm pixels lose weight, rare vein or crack
//! pixels gain it. A lazy solid cannot look at itself as a whole, so the
//! weights are found once, at precompute: the engine synthesizes a block
//! of each coarse level, counts how often each exemplar pixel of each
//! plane and each palette colour is used, raises the penalty of what is
//! over-used and lowers (down to zero) that of what is under-used, and
//! repeats with the penalties in place; the correction adds a triple's
//! penalties to its distance. The penalties are stored with the candidates,
//! so a voxel stays a pure function of (texture, seed, position).

use super::Engine;
use super::cache::TileCache;
use super::colour;
use super::grid::Box3;
use crate::analysis::stack::spacing;
use crate::candidates::Candidates;
use crate::candidates::geometry::Dims;
use crate::error::{Error, Result};
use crate::params::SynthParams;
use crate::reference::palette::Palette;
use crate::simd;
use rayon::prelude::*;
use std::sync::Arc;

/// Side of the block counted at each level, in voxels of that level.
const BLOCK: i64 = 48;

/// Bytes of tile cache a calibration round may hold.
const CACHE_BYTES: usize = 128 << 20;

/// Bytes a calibration holds at most besides its per-pixel arrays: the
/// tile cache and a level's working boxes.
pub(crate) const PEAK_BYTES: u64 = CACHE_BYTES as u64 + (64 << 20);

/// The largest penalty a pixel reaches, in units of its level's typical
/// distance between close alternatives ([`margin`]): a cap so that no
/// pixel is priced out of use altogether.
const MOST: f64 = 4.0;

/// The finest level calibrated: at the finest, where a voxel's colour is
/// the mean of three fine exemplar colours, pushing the choice toward
/// under-used colours moved the mean toward the calm middle instead
/// (docs/quality.md); the coarse levels, which lay out the structure,
/// take the penalties.
const FINEST_CALIBRATED: usize = 1;

/// Calibration rounds: each synthesizes with the penalties of the last.
const ROUNDS: u32 = 4;

/// Calibrates `cands` for synthesis with `params`: [`ROUNDS`] rounds, each
/// moving a pixel's penalty by `strength` margins times its relative
/// over-use. Deterministic: every step is a count or a rational function
/// of counts.
pub(crate) fn calibrate(
    cands: Candidates,
    params: &SynthParams,
    strength: f32,
    progress: &(dyn Fn(f32) + Sync),
) -> Result<Candidates> {
    let levels = cands.level_count();
    let dims = cands.dims();
    let n = dims.len();
    let margins: Vec<f64> = (0..levels).map(|k| margin(&cands, k)).collect();
    let mut penalty: Vec<[Vec<f64>; 3]> = (0..levels)
        .map(|_| [0, 1, 2].map(|_| vec![0.0; n]))
        .collect();
    let palettes: Vec<Palette> = (0..levels)
        .map(|k| {
            let all: Vec<[f32; 3]> = (0..3)
                .flat_map(|p| cands.stack(p).level(k).iter().copied())
                .collect();
            Palette::fit(&all, PALETTE_SEED)
        })
        .collect();
    let exemplar_hists: Vec<Vec<f64>> = (0..levels)
        .map(|k| {
            histogram(
                &palettes[k],
                (0..3).flat_map(|p| cands.stack(p).level(k).iter().copied()),
            )
        })
        .collect();
    let mut cands = cands;
    let calibrated = FINEST_CALIBRATED.min(levels - 1)..levels;
    let steps = ROUNDS as usize * calibrated.len();
    for round in 0..ROUNDS {
        let shared = Arc::new(cands);
        let engine = Engine::new(
            shared.clone(),
            params.clone(),
            Arc::new(TileCache::new(CACHE_BYTES)),
        )?;
        for k in calibrated.clone() {
            // A block of its own each round, so that no penalty is fitted
            // to one block's accidents.
            let lo = i64::from(round) * 4 * BLOCK;
            let b = Box3::new([lo, -lo, lo / 2], [BLOCK; 3]);
            let triples = engine.level_box(k, &b, &engine.new_acc()).data;
            // Pixels closer than the level's spacing are near copies in
            // its Gaussian stack: their use is counted together.
            let radius = (spacing(k) as usize)
                .min(dims.w.min(dims.h) as usize / 8)
                .max(1);
            // Smaller steps as the rounds settle.
            let step = f64::from(strength) * margins[k] / f64::from(round + 1);
            // How much the voxels over-use each palette colour, from −1
            // (never used) to 1 (used where the exemplars never are).
            let synth_hist = histogram(
                &palettes[k],
                triples.iter().map(|&t| colour::colour(&shared, k, t)),
            );
            let colour_over: Vec<f64> = synth_hist
                .iter()
                .zip(&exemplar_hists[k])
                .map(|(&s, &e)| if s + e > 0.0 { (s - e) / (s + e) } else { 0.0 })
                .collect();
            let expected = triples.len() as f64 / n as f64;
            let window = ((2 * radius + 1) * (2 * radius + 1)) as f64;
            let most = MOST * margins[k];
            penalty[k]
                .par_iter_mut()
                .enumerate()
                .for_each(|(plane, pen)| {
                    let mut count = vec![0u32; n];
                    for t in &triples {
                        count[t[plane] as usize] += 1;
                    }
                    let used = blur(&count, dims, radius);
                    let own = shared.stack(plane).level(k);
                    for ((p, &u), &c) in pen.iter_mut().zip(&used).zip(own) {
                        // The pixel's own over-use (position histogram, Chen
                        // and Wang) and its colour's (colour histogram, Kopf
                        // et al.), equally: over-use alone spreads the choice
                        // over more pixels but toward the calm mean colour.
                        let u = f64::from(u) / window;
                        let usage = (u - expected) / (u + expected);
                        let colour = colour_over[palettes[k].nearest(c) as usize];
                        *p = (*p + step * 0.5 * (usage + colour)).clamp(0.0, most);
                    }
                });
            let done = round as usize * calibrated.len() + k + 1 - calibrated.start;
            progress(done as f32 / steps as f32);
        }
        drop(engine);
        // The engine, the only other holder, is gone.
        cands = Arc::try_unwrap(shared).map_err(|_| {
            Error::InvalidRequest("candidates still shared after calibration".into())
        })?;
        cands.set_usage_penalty(quantise(&penalty));
    }
    Ok(cands)
}

/// Seed of the palettes' k-means.
const PALETTE_SEED: u64 = 0x5553_4147;

/// The share of `colours` nearest each entry of `palette`.
fn histogram(palette: &Palette, colours: impl Iterator<Item = [f32; 3]>) -> Vec<f64> {
    let mut h = vec![0f64; palette.len()];
    let mut n = 0usize;
    for c in colours {
        h[palette.nearest(c) as usize] += 1.0;
        n += 1;
    }
    h.iter_mut().for_each(|v| *v /= n.max(1) as f64);
    h
}

/// Penalties as stored: each plane's shifted so its least is zero (only
/// differences between candidates matter), rounded.
fn quantise(penalty: &[[Vec<f64>; 3]]) -> Vec<[Vec<u16>; 3]> {
    penalty
        .iter()
        .map(|planes| {
            [0, 1, 2].map(|p| {
                let least = planes[p].iter().copied().fold(f64::INFINITY, f64::min);
                planes[p]
                    .iter()
                    .map(|&v| (v - least + 0.5).clamp(0.0, u16::MAX as f64) as u16)
                    .collect()
            })
        })
        .collect()
}

/// Sums of `count` over the (2r+1)² window around each pixel, wrapping.
fn blur(count: &[u32], dims: Dims, r: usize) -> Vec<u32> {
    let (w, h) = (dims.w as usize, dims.h as usize);
    let mut rows = vec![0u32; w * h];
    for y in 0..h {
        for x in 0..w {
            let mut s = 0;
            for d in 0..=2 * r {
                s += count[y * w + (x + w * (r + 1) + d - r) % w];
            }
            rows[y * w + x] = s;
        }
    }
    let mut out = vec![0u32; w * h];
    for y in 0..h {
        for x in 0..w {
            let mut s = 0;
            for d in 0..=2 * r {
                s += rows[((y + h * (r + 1) + d - r) % h) * w + x];
            }
            out[y * w + x] = s;
        }
    }
    out
}

/// The typical distance between close alternatives at level `k`: the
/// median, over a sample of pixels, of the distance between the best
/// triple of a pixel and that of its most similar other pixel.
fn margin(cands: &Candidates, k: usize) -> f64 {
    let level = cands.level(k);
    let tables = level.sparse_tables(cands.dims(), k);
    let n = cands.dims().len() as u32;
    let mut d: Vec<u32> = (0..3)
        .flat_map(|p| (0..n).step_by(7).map(move |c| (p, c)))
        .filter_map(|(p, c)| {
            let other = *level.similar(p, c).get(1)?;
            let a = tables.sum_shares(tables.shares_of(tables.best(p, c).triples[0]));
            let b = tables.sum_shares(tables.shares_of(tables.best(p, other).triples[0]));
            Some(simd::distance(&a, &b))
        })
        .filter(|&d| d > 0)
        .collect();
    if d.is_empty() {
        return 1.0;
    }
    let mid = d.len() / 2;
    f64::from(*d.select_nth_unstable(mid).1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::exemplar::{Exemplar, ExemplarSet};
    use crate::params::AnalysisParams;
    use crate::request::{Region, Request, RequestKind};
    use crate::{Texture, TileCache};

    /// Pale noise with a few dark lines: a rare feature on a calm ground.
    fn veined(side: u32) -> ExemplarSet {
        let rgb: Vec<u8> = (0..side * side)
            .flat_map(|i| {
                let (x, y) = (i % side, i / side);
                let noise = (i.wrapping_mul(2_654_435_761) >> 28) as u8;
                if (x + 2 * y) % 13 == 0 {
                    [70 + noise, 40, 50]
                } else {
                    [200 + noise, 180 + noise, 170]
                }
            })
            .collect();
        ExemplarSet::single(Exemplar::from_rgb(side, side, &rgb).unwrap())
    }

    fn compute(strength: f32) -> Candidates {
        let params = AnalysisParams {
            levels: 2,
            histogram_matching: strength,
            ..AnalysisParams::default()
        };
        Candidates::compute(&veined(24), &params, &|_, _| {}).unwrap()
    }

    fn block(c: Candidates) -> Vec<u8> {
        let t = Texture::new(
            Arc::new(c),
            SynthParams::default(),
            Arc::new(TileCache::new(64 << 20)),
        )
        .unwrap();
        let r = Request::new(RequestKind::Region(Region {
            origin: [-5, 3, 7],
            size: [12, 10, 8],
        }))
        .unwrap();
        t.render(&r, 0).unwrap().0
    }

    /// The penalties, and so the file and every voxel, are the same for
    /// any thread count; they are not all zero, and they change voxels.
    #[test]
    fn calibration_is_deterministic_and_changes_the_solid() {
        let run = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| compute(1.0))
        };
        let one = run(1);
        let two = run(2);
        assert_eq!(one.to_bytes(), two.to_bytes());
        // The finest level is left unweighted, the coarser one is not.
        let weighted = |k| {
            let u = one.usage_penalty(k).expect("calibrated");
            u.iter().any(|plane| plane.iter().any(|&v| v > 0))
        };
        assert!(!weighted(0));
        assert!(weighted(1));
        let loaded = Candidates::load(&one.to_bytes()).unwrap();
        assert_eq!(loaded.usage_penalty(0), one.usage_penalty(0));
        assert_eq!(block(loaded), block(two));
        assert_ne!(block(one), block(compute(0.0)));
    }

    /// Penalties that are zero everywhere choose what no penalties choose:
    /// the weighted scoring leaves an unweighted correction as it was.
    #[test]
    fn zero_penalties_change_nothing() {
        let plain = compute(0.0);
        assert!(plain.usage_penalty(0).is_none());
        let mut zero = compute(0.0);
        let n = zero.dims().len();
        zero.set_usage_penalty((0..2).map(|_| [0, 1, 2].map(|_| vec![0u16; n])).collect());
        assert_eq!(block(plain), block(zero));
    }

    #[test]
    fn the_blur_sums_a_wrapping_window() {
        let dims = Dims::new(5, 4);
        let mut count = vec![0u32; 20];
        count[0] = 3;
        let b = blur(&count, dims, 1);
        // The corner's window reaches the far column and row.
        for (x, y) in [(0, 0), (1, 0), (4, 0), (0, 1), (0, 3), (4, 3), (1, 1)] {
            assert_eq!(b[y * 5 + x], 3, "({x}, {y})");
        }
        assert_eq!(b[2 * 5 + 2], 0);
        assert_eq!(b.iter().sum::<u32>(), 27);
    }
}
