//! `solidtex region`: a box of voxels as raw RGB8 (x fastest, then y, then z).

use super::source::{SourceArgs, load_source, summary};
use anyhow::Context;
use clap::Args;
use solidtex_core::{Region, Request};
use solidtex_server::write_atomic;
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
    write_atomic(&a.output, &rgb).with_context(|| format!("writing {}", a.output.display()))?;
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
