//! An axis-aligned slice of the bundled marble as a PNG:
//! `cargo run --release -p solidtex-core --example slice -- slice.png`

use solidtex_core::{
    AnalysisParams, Axis, ExemplarSet, Request, SynthParams, Texture, TileCache, Window, bundled,
};
use std::sync::Arc;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "slice.png".into());
    // The bundled exemplar ships with its candidates precomputed.
    let set = ExemplarSet::single(bundled::exemplar());
    let candidates = bundled::candidates_for(&set, &AnalysisParams::default())
        .expect("the bundled candidates match the default analysis");
    let cache = Arc::new(TileCache::new(256 << 20));
    let texture = Texture::new(Arc::new(candidates), SynthParams::default(), cache)?;
    // A 256² slice normal to z at z = 40, corner (0, 0), finest level.
    let (rgb, stats) = texture.render(
        &Request::slice(Axis::Z, 40, Window::new(0, 0, 256, 256))?,
        0,
    )?;
    std::fs::write(&out, solidtex_core::png::encode(256, 256, &rgb)?)?;
    let corrections: u64 = stats.corrections_per_level.iter().sum();
    println!("wrote {out}: {corrections} voxel corrections");
    Ok(())
}
