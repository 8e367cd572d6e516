//! A cube of the bundled marble at a coarser level of detail, and proof
//! that a voxel does not depend on how it was asked for:
//! `cargo run --release -p solidtex-core --example volume -- cube.raw`

use solidtex_core::{
    AnalysisParams, ExemplarSet, Region, Request, SynthParams, Texture, TileCache, bundled,
};
use std::sync::Arc;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args().nth(1).unwrap_or_else(|| "cube.raw".into());
    let set = ExemplarSet::single(bundled::exemplar());
    let candidates = bundled::candidates_for(&set, &AnalysisParams::default())
        .expect("the bundled candidates match the default analysis");
    let cache = Arc::new(TileCache::new(256 << 20));
    let texture = Texture::new(Arc::new(candidates), SynthParams::default(), cache)?;
    // lod 1: voxels twice as wide, an eighth of the work.
    let cube = Region {
        origin: [0, 0, 0],
        size: [64, 64, 64],
    };
    let (rgb, _) = texture.render(&Request::region(cube)?, 1)?;
    std::fs::write(&out, &rgb)?;
    // The voxel at (5, 6, 7), asked for alone, has the same colour.
    let (one, _) = texture.render(
        &Request::region(Region {
            origin: [5, 6, 7],
            size: [1, 1, 1],
        })?,
        1,
    )?;
    let at = 3 * (5 + 64 * (6 + 64 * 7));
    assert_eq!(one[..], rgb[at..at + 3]);
    println!("wrote {out}: 64³ voxels at lod 1, RGB8, x fastest");
    Ok(())
}
