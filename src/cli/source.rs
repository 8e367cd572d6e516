//! What the synthesis commands share: where a texture comes from (a
//! `.stx`, an exemplar image, or the bundled default), its synthesis
//! parameters, and how results are written and summarised.

use super::knob_flags::SynthArgs;
use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use solidtex_core::region::{Shape, Split};
use solidtex_core::{
    AnalysisParams, Candidates, Exemplar, ExemplarSet, Stage, SynthStats, Texture, TileCache,
};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

#[derive(Args, Clone)]
pub struct SourceArgs {
    /// A `.stx` file, or an exemplar image (precomputed on the fly; the
    /// bundled default exemplar when omitted).
    pub source: Option<PathBuf>,
    #[command(flatten)]
    pub synth: SynthArgs,
    /// Level of detail (0 = finest).
    #[arg(long, default_value_t = 0)]
    pub lod: u32,
    /// A second texture (`.stx` or exemplar image) filling `--inner-region`:
    /// a region texture, the first texture outside (docs/meshes.md).
    #[arg(long, requires = "inner_region")]
    pub inner: Option<PathBuf>,
    /// The region `--inner` fills, in voxels of level of detail 0:
    /// `sphere:CX,CY,CZ,R`, `box:CX,CY,CZ,HX,HY,HZ[,ROUNDING]`,
    /// `cylinder:X0,Y0,Z0,X1,Y1,Z1,R`, `half_space:PX,PY,PZ,NX,NY,NZ`,
    /// `shell:T` (depth below a baked mesh's surface; bakes only) or the
    /// same as a JSON object.
    #[arg(long, requires = "inner")]
    pub inner_region: Option<Shape>,
    /// Width of the band across the region's boundary where the two
    /// textures mix (0: a hard boundary).
    #[arg(long, default_value_t = 0.0, requires = "inner")]
    pub band: f64,
}

/// One sentence on what a synthesis command wrote and what it cost.
pub fn summary(what: &str, path: &Path, t0: Instant, stats: &SynthStats) -> String {
    let corrections: u64 = stats.corrections_per_level.iter().sum();
    format!(
        "wrote {what} to {} in {:.2} s: {corrections} corrections over {} levels, \
         {} tiles synthesized, {} from the cache",
        path.display(),
        t0.elapsed().as_secs_f64(),
        stats.corrections_per_level.len(),
        stats.tiles_computed,
        stats.tiles_from_cache,
    )
}

pub fn progress_bar() -> ProgressBar {
    let bar = ProgressBar::new(1000);
    bar.set_style(
        ProgressStyle::with_template("{spinner} {msg:12} [{bar:40}] {percent}% {elapsed}")
            .expect("valid template"),
    );
    bar
}

pub fn precompute(
    set: &ExemplarSet,
    params: &AnalysisParams,
    quiet: bool,
) -> anyhow::Result<Candidates> {
    let bar = if quiet {
        ProgressBar::hidden()
    } else {
        progress_bar()
    };
    let stages = [
        Stage::Analysis,
        Stage::Search,
        Stage::Coherence,
        Stage::Finish,
        Stage::Reference,
    ];
    let cb = |s: Stage, f: f32| {
        let i = stages.iter().position(|&x| x == s).unwrap_or(0);
        bar.set_message(format!("{s:?}").to_lowercase());
        bar.set_position(((i as f32 + f) / stages.len() as f32 * 1000.0) as u64);
    };
    let c = Candidates::compute(set, params, &cb)?;
    bar.finish_and_clear();
    Ok(c)
}

pub fn load_source(src: &SourceArgs) -> anyhow::Result<Texture> {
    let cache = Arc::new(TileCache::new(1 << 30));
    let params = src.synth.params();
    let outer = Texture::new(
        Arc::new(load_candidates(src.source.as_deref())?),
        params.clone(),
        cache.clone(),
    )?;
    let (Some(inner), Some(region)) = (&src.inner, &src.inner_region) else {
        return Ok(outer);
    };
    let inner = Texture::new(Arc::new(load_candidates(Some(inner))?), params, cache)?;
    let split = Split {
        region: region.clone(),
        band: src.band,
    };
    Ok(Texture::with_region(outer, inner, split)?)
}

/// The candidates of a `.stx` file, of an exemplar image (precomputed
/// now), or of the bundled default.
fn load_candidates(path: Option<&Path>) -> anyhow::Result<Candidates> {
    Ok(match path {
        Some(p) if p.extension().is_some_and(|e| e == "stx") => {
            let bytes = std::fs::read(p).with_context(|| format!("reading {}", p.display()))?;
            Candidates::load(&bytes)?
        }
        Some(p) => {
            eprintln!(
                "precomputing the candidates of {} (save them with `solidtex precompute` to skip this)",
                p.display()
            );
            precompute(
                &ExemplarSet::single(open_exemplar(p)?),
                &AnalysisParams::default(),
                false,
            )?
        }
        None => {
            let set = ExemplarSet::single(solidtex_core::bundled::exemplar());
            match solidtex_core::bundled::candidates_for(&set, &AnalysisParams::default()) {
                Some(c) => c,
                None => precompute(&set, &AnalysisParams::default(), false)?,
            }
        }
    })
}

/// Opens a PNG or JPEG exemplar; a photo larger than the exemplar limit is
/// downscaled, and the user told so.
pub fn open_exemplar(path: &Path) -> anyhow::Result<Exemplar> {
    let (e, original) =
        Exemplar::open_fitting(path).with_context(|| format!("reading {}", path.display()))?;
    if let Some((w, h)) = original {
        eprintln!(
            "{}: downscaled from {w}x{h} to {}x{} (exemplars are at most {} pixels per side)",
            path.display(),
            e.width(),
            e.height(),
            solidtex_core::Exemplar::MAX_SIDE
        );
    }
    Ok(e)
}

pub fn write_png(path: &Path, w: u32, h: u32, rgb: Vec<u8>) -> anyhow::Result<()> {
    let img = image::RgbImage::from_raw(w, h, rgb).context("image size")?;
    img.save(path)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
