//! A box of voxels from an exemplar image, as raw RGB8 (x fastest):
//! `cargo run --release -p solidtex-core --example region -- EXEMPLAR.png out.raw`

use solidtex_core::{
    AnalysisParams, Candidates, Exemplar, ExemplarSet, Region, Request, SynthParams, Texture,
    TileCache,
};
use std::sync::Arc;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let (Some(exemplar), Some(out)) = (args.next(), args.next()) else {
        return Err("usage: region EXEMPLAR.png OUT.raw".into());
    };
    // Analysis runs once per exemplar (seconds); save it with `to_bytes`
    // and `Candidates::load` it next time.
    let set = ExemplarSet::single(Exemplar::open(&exemplar)?);
    let candidates = Candidates::compute(&set, &AnalysisParams::default(), &|_, _| {})?;
    let cache = Arc::new(TileCache::new(256 << 20));
    let texture = Texture::new(Arc::new(candidates), SynthParams::default(), cache)?;
    // Any box, anywhere: the same voxels whatever else was asked before.
    let region = Region {
        origin: [-1000, 250, 7],
        size: [64, 64, 16],
    };
    let (rgb, _) = texture.render(&Request::region(region)?, 0)?;
    std::fs::write(&out, rgb)?;
    println!("wrote {out}: 64×64×16 voxels, RGB8, x fastest");
    Ok(())
}
