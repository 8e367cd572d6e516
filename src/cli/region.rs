//! `solidtex region`: a box of voxels as raw RGB8 (x fastest, then y, then z).

use super::source::{SourceArgs, load_source, summary, write_atomically};
use clap::Args;
use solidtex_core::{Region, Request};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args)]
pub struct RegionArgs {
    #[command(flatten)]
    src: SourceArgs,
    /// Lowest corner, x.
    #[arg(long, allow_hyphen_values = true)]
    x: i64,
    /// Lowest corner, y.
    #[arg(long, allow_hyphen_values = true)]
    y: i64,
    /// Lowest corner, z.
    #[arg(long, allow_hyphen_values = true)]
    z: i64,
    /// Extent along x, voxels.
    #[arg(long = "width", alias = "w")]
    w: u32,
    /// Extent along y, voxels.
    #[arg(long = "height", alias = "h")]
    h: u32,
    /// Extent along z, voxels.
    #[arg(long = "depth", alias = "d")]
    d: u32,
    /// Output file.
    #[arg(short, long)]
    output: PathBuf,
}

/// Runs `solidtex region`.
pub fn run(a: RegionArgs) -> anyhow::Result<()> {
    let tex = load_source(&a.src)?;
    let region = Region {
        origin: [a.x, a.y, a.z],
        size: [a.w, a.h, a.d],
    };
    let t0 = Instant::now();
    let (rgb, stats) = tex.render(&Request::region(region)?, a.src.lod)?;
    write_atomically(&a.output, &rgb)?;
    let [w, h, d] = region.size;
    eprintln!(
        "{}",
        summary(
            &format!("{w}×{h}×{d} voxels (RGB8, x fastest)"),
            &a.output,
            t0,
            &stats
        )
    );
    Ok(())
}
