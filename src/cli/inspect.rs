//! `solidtex inspect`: PNGs of precomputed data, per level: the candidate
//! slab from above and from the side, and its crossbar error.

use super::source::write_png;
use clap::Args;
use solidtex_core::Candidates;
use std::path::PathBuf;

#[derive(Args)]
pub struct InspectArgs {
    /// The `.stx` file.
    stx: PathBuf,
    /// Output directory.
    #[arg(long)]
    out: PathBuf,
}

/// Runs `solidtex inspect`.
pub fn run(a: InspectArgs) -> anyhow::Result<()> {
    let bytes = std::fs::read(&a.stx)?;
    let c = Candidates::load(&bytes)?;
    std::fs::create_dir_all(&a.out)?;
    let dims = c.dims();
    for k in 0..c.level_count() {
        let v = c.slab_views(k);
        let name = |what: &str| a.out.join(format!("{what}_level{k}.png"));
        write_png(&name("slab"), dims.w, dims.h, v.slab)?;
        write_png(&name("slab_side"), dims.w, v.side_height, v.side)?;
        let errs = v.crossbar_error;
        let max = errs.iter().cloned().fold(1e-6f32, f32::max);
        let heat: Vec<u8> = errs.iter().flat_map(|&e| heat(e / max)).collect();
        write_png(&name("crossbar_error"), dims.w, dims.h, heat)?;
    }
    outln!("wrote {} levels to {}", c.level_count(), a.out.display())?;
    Ok(())
}

fn heat(t: f32) -> [u8; 3] {
    let t = t.clamp(0.0, 1.0);
    let r = (t * 3.0).min(1.0);
    let g = (t * 3.0 - 1.0).clamp(0.0, 1.0);
    let b = (t * 3.0 - 2.0).clamp(0.0, 1.0);
    [(r * 255.0) as u8, (g * 255.0) as u8, (b * 255.0) as u8]
}
