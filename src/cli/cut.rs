//! `solidtex cut`: an oblique cut (any plane) as a PNG.

use super::source::{SourceArgs, load_source, summary, write_png};
use clap::Args;
use solidtex_core::{CutPlane, Filter, Request};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args)]
pub struct CutArgs {
    #[command(flatten)]
    src: SourceArgs,
    /// Position of pixel (0, 0), `x,y,z` in voxels of the level served.
    #[arg(long, value_parser = parse_vec3, default_value = "0,0,0", allow_hyphen_values = true)]
    origin: [f64; 3],
    /// Step per pixel to the right, `x,y,z`.
    #[arg(long, value_parser = parse_vec3, default_value = "0.7071,0.7071,0", allow_hyphen_values = true)]
    u: [f64; 3],
    /// Step per pixel downwards, `x,y,z`.
    #[arg(long, value_parser = parse_vec3, default_value = "-0.4082,0.4082,0.8165", allow_hyphen_values = true)]
    v: [f64; 3],
    /// Width in pixels.
    #[arg(long, default_value_t = 256)]
    width: u32,
    /// Height in pixels.
    #[arg(long, default_value_t = 256)]
    height: u32,
    /// Sampling between voxel centres: nearest or trilinear.
    #[arg(long, default_value = "nearest")]
    filter: CutFilter,
    /// Output PNG.
    #[arg(short, long)]
    output: PathBuf,
}

/// Runs `solidtex cut`.
pub fn run(a: CutArgs) -> anyhow::Result<()> {
    let tex = load_source(&a.src)?;
    let plane = CutPlane {
        origin: a.origin,
        u: a.u,
        v: a.v,
        width: a.width,
        height: a.height,
    };
    let filter = match a.filter {
        CutFilter::Nearest => Filter::Nearest,
        CutFilter::Trilinear => Filter::Trilinear,
    };
    let t0 = Instant::now();
    let (rgb, stats) = tex.render(&Request::cut(plane, filter)?, a.src.lod)?;
    write_png(&a.output, a.width, a.height, rgb)?;
    let what = format!(
        "a {}×{} oblique cut from ({}, {}, {})",
        a.width, a.height, a.origin[0], a.origin[1], a.origin[2]
    );
    eprintln!("{}", summary(&what, &a.output, t0, &stats));
    Ok(())
}

/// How `cut` samples between voxel centres.
#[derive(Clone, Copy, clap::ValueEnum)]
enum CutFilter {
    /// The nearest voxel.
    Nearest,
    /// A trilinear blend of the eight nearest voxels.
    Trilinear,
}

/// Parses `x,y,z` into three finite numbers.
pub(super) fn parse_vec3(s: &str) -> Result<[f64; 3], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let [x, y, z] = parts[..] else {
        return Err(format!("`{s}` is not three numbers `x,y,z`"));
    };
    let num = |t: &str| match t.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(format!("`{t}` is not a finite number")),
    };
    Ok([num(x)?, num(y)?, num(z)?])
}
