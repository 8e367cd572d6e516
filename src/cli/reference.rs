//! `solidtex reference`: the global reference, a periodic block made by
//! texture optimisation over the whole block (crates/core/src/reference),
//! written as raw RGB8 with its three middle slices and an oblique cut.

use super::source::{open_exemplar, write_png};
use clap::Args;
use solidtex_core::reference::{ReferenceParams, synthesize};
use solidtex_core::{ExemplarSet, Layout, Orientation};
use solidtex_server::write_atomic;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args)]
pub struct ReferenceArgs {
    /// The exemplar image.
    exemplar: PathBuf,
    /// Block side in voxels (the block tiles seamlessly).
    #[arg(long, default_value_t = ReferenceParams::default().size)]
    size: u32,
    /// Random seed.
    #[arg(long, default_value_t = ReferenceParams::default().seed)]
    seed: u64,
    /// Pyramid levels (by default as many as leave 8 voxels per side at
    /// the coarsest).
    #[arg(long)]
    levels: Option<u32>,
    /// Neighbourhood side N (odd).
    #[arg(long, default_value_t = ReferenceParams::default().neighbourhood)]
    neighbourhood: u32,
    /// Spacing of the sparse grid of neighbourhood centres.
    #[arg(long, default_value_t = ReferenceParams::default().grid)]
    grid: u32,
    /// Iterations per level, the finest excepted.
    #[arg(long, default_value_t = ReferenceParams::default().iterations)]
    iterations: u32,
    /// Iterations at the finest level.
    #[arg(long, default_value_t = ReferenceParams::default().finest_iterations)]
    finest_iterations: u32,
    /// Exponent r of the robust energy.
    #[arg(long, default_value_t = ReferenceParams::default().robust)]
    robust: f32,
    /// Strength of the colour-histogram weight (0 disables).
    #[arg(long, default_value_t = ReferenceParams::default().colour_histogram)]
    colour_histogram: f32,
    /// Strength of the position-histogram weight (0 disables).
    #[arg(long, default_value_t = ReferenceParams::default().position_histogram)]
    position_histogram: f32,
    /// Keep the weighted means of the last iteration instead of ending
    /// with an iteration that copies exemplar colours.
    #[arg(long)]
    no_copy: bool,
    /// Orientation of the exemplar on the three planes: auto, none or an
    /// arrangement's JSON (as `solidtex precompute`).
    #[arg(long, default_value = "auto")]
    orientation: Orientation,
    /// Print every iteration's energy.
    #[arg(long)]
    verbose: bool,
    /// Output directory.
    #[arg(short, long)]
    output: PathBuf,
}

/// Runs `solidtex reference`.
pub fn run(a: ReferenceArgs) -> anyhow::Result<()> {
    let exemplar = open_exemplar(&a.exemplar)?;
    let set = ExemplarSet::single(exemplar);
    let layout = Layout::resolve(&set, &a.orientation)?;
    let laid = layout.apply(&set)?;
    let params = ReferenceParams {
        size: a.size,
        seed: a.seed,
        levels: a
            .levels
            .unwrap_or_else(|| ReferenceParams::default_levels(a.size, a.grid)),
        neighbourhood: a.neighbourhood,
        grid: a.grid,
        iterations: a.iterations,
        finest_iterations: a.finest_iterations,
        robust: a.robust,
        colour_histogram: a.colour_histogram,
        position_histogram: a.position_histogram,
        copy: !a.no_copy,
    };
    std::fs::create_dir_all(&a.output)?;
    let t0 = Instant::now();
    let verbose = a.verbose;
    let block = synthesize(&laid, layout.arrangement.weights, &params, |r| {
        if verbose {
            eprintln!(
                "level {} iteration {}: energy {:.1}, {} voxels changed ({:.1} s)",
                r.level,
                r.iteration,
                r.energy,
                r.changed,
                t0.elapsed().as_secs_f64()
            );
        }
    })?;
    let s = block.size;
    let raw = a.output.join(format!("reference_{s}.raw"));
    write_atomic(&raw, &block.rgb)?;
    eprintln!(
        "wrote {} (a periodic {s}³ block, RGB8, x fastest) in {:.1} s",
        raw.display(),
        t0.elapsed().as_secs_f64()
    );
    let n = s as usize;
    let at = |x: usize, y: usize, z: usize| {
        let i = ((z % n * n + y % n) * n + x % n) * 3;
        [block.rgb[i], block.rgb[i + 1], block.rgb[i + 2]]
    };
    let mid = n / 2;
    // The same planes `solidtex volume` writes: z (u = x, v = y),
    // x (u = y, v = z), y (u = z, v = x).
    for name in ["z", "x", "y"] {
        let mut img = Vec::with_capacity(n * n * 3);
        for v in 0..n {
            for u in 0..n {
                img.extend_from_slice(&match name {
                    "z" => at(u, v, mid),
                    "x" => at(mid, u, v),
                    _ => at(v, mid, u),
                });
            }
        }
        write_png(&a.output.join(format!("slice_{name}.png")), s, s, img)?;
    }
    Ok(())
}
