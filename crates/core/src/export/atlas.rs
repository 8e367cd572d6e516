//! Slice atlases: the z slices of a box as the tiles of one PNG (the
//! "pseudo-volume" layout of Unreal's Volume Texture and shader graphs).

use crate::error::{Error, Result};

/// Columns and rows of the atlas of `slices` slices: the columns the
/// smallest power of two at least √slices, the rows as many as needed.
pub(super) fn grid(slices: u32) -> (u32, u32) {
    let mut columns = 1u32;
    while columns * columns < slices {
        columns *= 2;
    }
    (columns, slices.div_ceil(columns))
}

/// The atlas PNG of RGB8 voxels `rgb` (x fastest, then y, then z) of a
/// box of `size`: slice z at column z mod C, row z div C.
pub(super) fn encode(size: [u32; 3], rgb: &[u8]) -> Result<Vec<u8>> {
    let [w, h, d] = size.map(|s| s as usize);
    let (columns, rows) = grid(size[2]);
    let (aw, ah) = (w * columns as usize, h * rows as usize);
    let mut image = vec![0u8; aw * ah * 3];
    for z in 0..d {
        let (cx, cy) = (z % columns as usize, z / columns as usize);
        for y in 0..h {
            let src = ((z * h + y) * w) * 3;
            let dst = ((cy * h + y) * aw + cx * w) * 3;
            image[dst..dst + w * 3].copy_from_slice(&rgb[src..src + w * 3]);
        }
    }
    crate::png::encode(aw as u32, ah as u32, &image)
        .map_err(|e| Error::InvalidRequest(format!("the atlas could not be encoded: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grids_are_power_of_two_columns_wide() {
        assert_eq!(grid(1), (1, 1));
        assert_eq!(grid(64), (8, 8));
        assert_eq!(grid(100), (16, 7));
        assert_eq!(grid(128), (16, 8));
        assert_eq!(grid(256), (16, 16));
    }

    #[test]
    fn slices_land_in_their_tiles() {
        let size = [2u32, 3, 5];
        let rgb: Vec<u8> = (0..2 * 3 * 5 * 3).map(|i| i as u8 + 1).collect();
        let png = encode(size, &rgb).unwrap();
        let img = image::load_from_memory(&png).unwrap().to_rgb8();
        // 5 slices: 4 columns, 2 rows of 2×3 tiles.
        assert_eq!(img.dimensions(), (8, 6));
        for z in 0..5u32 {
            for y in 0..3u32 {
                for x in 0..2u32 {
                    let px = img.get_pixel((z % 4) * 2 + x, (z / 4) * 3 + y).0;
                    let i = (((z * 3 + y) * 2 + x) * 3) as usize;
                    assert_eq!(px, [rgb[i], rgb[i + 1], rgb[i + 2]]);
                }
            }
        }
        assert_eq!(img.get_pixel(7, 5).0, [0, 0, 0], "unused tile");
    }
}
