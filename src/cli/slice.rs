//! `solidtex slice`: an axis-aligned slice as a PNG.

use super::source::{SourceArgs, load_source, summary, write_png};
use clap::Args;
use solidtex_core::{Axis, Request, Window};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args)]
pub struct SliceArgs {
    #[command(flatten)]
    src: SourceArgs,
    /// Axis normal to the slice: x, y or z.
    #[arg(long)]
    axis: Axis,
    /// Position along the axis.
    #[arg(long, allow_hyphen_values = true)]
    at: i64,
    /// Slice corner along its u axis (x for z slices, y for x, z for y).
    #[arg(long, default_value_t = 0, allow_hyphen_values = true)]
    u0: i64,
    /// Slice corner along its v axis (y for z slices, z for x, x for y).
    #[arg(long, default_value_t = 0, allow_hyphen_values = true)]
    v0: i64,
    /// Width in pixels (along u).
    #[arg(long = "width", alias = "w", default_value_t = 256)]
    w: u32,
    /// Height in pixels (along v).
    #[arg(long = "height", alias = "h", default_value_t = 256)]
    h: u32,
    /// Output PNG.
    #[arg(short, long)]
    output: PathBuf,
}

/// Runs `solidtex slice`.
pub fn run(a: SliceArgs) -> anyhow::Result<()> {
    let tex = load_source(&a.src)?;
    let t0 = Instant::now();
    let (rgb, stats) = tex.render(
        &Request::slice(a.axis, a.at, Window::new(a.u0, a.v0, a.w, a.h))?,
        a.src.lod,
    )?;
    write_png(&a.output, a.w, a.h, rgb)?;
    let axis = format!("{:?}", a.axis).to_lowercase();
    let what = format!("a {}×{} {axis} slice at {axis} = {}", a.w, a.h, a.at);
    eprintln!("{}", summary(&what, &a.output, t0, &stats));
    Ok(())
}
