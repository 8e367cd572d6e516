//! `solidtex volume`: a cube as raw RGB8 plus its three orthogonal middle slices.

use super::source::{SourceArgs, load_source, summary, write_png};
use anyhow::Context;
use clap::Args;
use solidtex_core::{Axis, Region, Request, Window};
use solidtex_server::write_atomic;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args)]
pub struct VolumeArgs {
    #[command(flatten)]
    src: SourceArgs,
    /// Cube side.
    #[arg(long, default_value_t = 128)]
    size: u32,
    /// Output directory.
    #[arg(short, long)]
    output: PathBuf,
}

/// Runs `solidtex volume`.
pub fn run(a: VolumeArgs) -> anyhow::Result<()> {
    let tex = load_source(&a.src)?;
    std::fs::create_dir_all(&a.output)?;
    let s = a.size;
    let t0 = Instant::now();
    let (rgb, stats) = tex.render(
        &Request::region(Region {
            origin: [0, 0, 0],
            size: [s, s, s],
        })?,
        a.src.lod,
    )?;
    let raw = a.output.join(format!("volume_{s}.raw"));
    write_atomic(&raw, &rgb).with_context(|| format!("writing {}", raw.display()))?;
    eprintln!(
        "{} (and its three middle slices)",
        summary(
            &format!("a {s}³ volume (RGB8, x fastest)"),
            &raw,
            t0,
            &stats
        )
    );
    let mid = (s / 2) as i64;
    for axis in [Axis::X, Axis::Y, Axis::Z] {
        let (img, _) = tex.render(
            &Request::slice(axis, mid, Window::new(0, 0, s, s))?,
            a.src.lod,
        )?;
        let name = format!("slice_{axis:?}.png").to_lowercase();
        write_png(&a.output.join(name), s, s, img)?;
    }
    Ok(())
}
