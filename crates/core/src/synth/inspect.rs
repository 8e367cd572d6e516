//! Pictures of precomputed candidates for `solidtex inspect`: the slab the
//! initialisation tiles, seen from above and from the side, and how well
//! its triples' crossbars agree.

use super::colour::triple_rgb8;
use crate::candidates::Candidates;
use crate::candidates::geometry::offset_triple;

/// Pixel rows each slab layer gets in [`SlabViews::side`].
const SIDE_ROWS_PER_LAYER: u32 = 4;

/// Images of one level's candidate slab (Dong et al.), RGB8, rows of the
/// exemplar's width.
pub struct SlabViews {
    /// The xy exemplar rebuilt from each pixel's first candidate: the mean
    /// of its three colours.
    pub slab: Vec<u8>,
    /// The x–z section through the middle row: each of the slab's N layers,
    /// a few pixel rows tall.
    pub side: Vec<u8>,
    /// Rows of [`SlabViews::side`].
    pub side_height: u32,
    /// Each pixel's first candidate's crossbar error (exemplar size).
    pub crossbar_error: Vec<f32>,
}

impl Candidates {
    /// The slab of level `k` as images.
    pub fn slab_views(&self, k: usize) -> SlabViews {
        let dims = self.dims();
        let cands = self.level(k).candidates(0);
        let first = |px: u32| cands.triples[cands.range(px).start];
        let pixels = 0..dims.len() as u32;
        let slab = pixels
            .clone()
            .flat_map(|px| triple_rgb8(self, k, first(px)))
            .collect();
        let crossbar_error = pixels.map(|px| self.crossbar_error(k, first(px))).collect();
        let n = self.params().neighbourhood;
        let side_height = n * SIDE_ROWS_PER_LAYER;
        let row = dims.h / 2 * dims.w;
        let spacing = 1i64 << k;
        let side = (0..side_height)
            .flat_map(|r| {
                let dz = i64::from(r / SIDE_ROWS_PER_LAYER) - i64::from(n / 2);
                (0..dims.w).flat_map(move |x| {
                    let t = offset_triple(dims, first(row + x), [0, 0, dz], spacing);
                    triple_rgb8(self, k, t)
                })
            })
            .collect();
        SlabViews {
            slab,
            side,
            side_height,
            crossbar_error,
        }
    }
}
