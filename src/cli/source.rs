//! What the synthesis commands share: where a texture comes from (a
//! `.stx`, an exemplar image, or the bundled default), its synthesis
//! parameters, and how results are written and summarised.

use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use solidtex_core::{
    AnalysisParams, Candidates, Exemplar, ExemplarSet, Field, Scheme, SlabTiling, Stage,
    SynthParams, SynthStats, Texture, TileCache,
};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

#[derive(Args, Clone)]
pub struct SourceArgs {
    /// A `.stx` file, or an exemplar image (precomputed on the fly; the
    /// bundled default exemplar when omitted).
    pub source: Option<PathBuf>,
    /// Correction scheme: standard or dual-grid.
    #[arg(long, default_value = "dual-grid")]
    pub scheme: Scheme,
    #[command(flatten)]
    pub synth: SynthArgs,
    /// Level of detail (0 = finest).
    #[arg(long, default_value_t = 0)]
    pub lod: u32,
}

/// Synthesis parameters other than the scheme.
#[derive(Args, Clone)]
pub struct SynthArgs {
    /// Random seed.
    #[arg(long, default_value_t = SynthParams::default().seed)]
    seed: u64,
    /// Preview parameters: one correction pass per level and the finest
    /// level upsampled without correction: faster cold slices for worse
    /// patch coherence (docs/quality.md).
    #[arg(long, conflicts_with_all = ["passes", "finest_passes", "fine_levels"])]
    preview: bool,
    /// Correction passes per level, the fine levels excepted.
    #[arg(long, default_value_t = SynthParams::default().passes)]
    passes: u32,
    /// Correction passes at the finest levels (see `--fine-levels`).
    #[arg(long, default_value_t = SynthParams::default().finest_passes)]
    finest_passes: u32,
    /// Levels, counted from the finest, corrected with `--finest-passes`
    /// passes instead of `--passes`.
    #[arg(long, default_value_t = SynthParams::default().fine_levels)]
    fine_levels: u32,
    /// Dual-grid cell side M.
    #[arg(long, default_value_t = SynthParams::default().grid)]
    grid: u32,
    /// Jitter strength (0 disables).
    #[arg(long, default_value_t = SynthParams::default().jitter)]
    jitter: f32,
    /// Levels, counted from the finest, whose passes run as two parity
    /// subpasses (even coordinate sums, then odd: short chains) instead
    /// of s³ block subpasses.
    #[arg(long, default_value_t = SynthParams::default().parity_levels)]
    parity_levels: u32,
    /// Subpass block side s of block subpasses (s³ subpasses per pass; 1
    /// disables subpasses there).
    #[arg(long, default_value_t = SynthParams::default().subpass_side)]
    subpass_side: u32,
    /// Gain on correction queries around their mean colour (1 disables).
    #[arg(long, default_value_t = SynthParams::default().contrast)]
    contrast: f32,
    /// Penalty on coherent triples whose three exemplar colours disagree
    /// (0 disables).
    #[arg(long, default_value_t = SynthParams::default().consistency)]
    consistency: f32,
    /// Thickness of the candidate slab's layers, in voxels of the
    /// initialisation level (Dong et al.: N).
    #[arg(long, default_value_t = SynthParams::default().slab_thickness)]
    slab_thickness: u32,
    /// How the slab is cut for tiling: cells (a jittered grid, borders at
    /// every angle) or blocks (axis-aligned squares).
    #[arg(long, default_value_t = SynthParams::default().slab_tiling)]
    slab_tiling: SlabTiling,
    /// A field of local frames the texture follows: a preset
    /// (`slant:ANGLE`, `circular[:CX,CY]`, `emissive[:CX,CY]`,
    /// `zigzag:ANGLE,PERIOD`, `slant3d:DX,DY,DZ`), a JSON object, or
    /// `@FILE` holding one (docs/fields.md).
    #[arg(long, value_parser = parse_field)]
    field: Option<Field>,
    /// Make the solid periodic with this period in finest voxels: one
    /// side (`128`) or three (`128,128,64`), each a multiple of the
    /// coarsest level's spacing times 4 (32 by default).
    #[arg(long, value_parser = parse_period)]
    period: Option<[u32; 3]>,
}

fn parse_period(s: &str) -> anyhow::Result<[u32; 3]> {
    Ok(solidtex_core::period::parse(s)?)
}

/// A `--field` value, reading `@FILE` from the file.
fn parse_field(s: &str) -> anyhow::Result<Field> {
    let text = match s.strip_prefix('@') {
        Some(path) => std::fs::read_to_string(path).with_context(|| format!("reading {path}"))?,
        None => s.to_string(),
    };
    Ok(text.parse()?)
}

impl SynthArgs {
    pub fn params(&self, scheme: Scheme) -> SynthParams {
        // The preview sets the passes (clap refuses them beside it).
        let base = if self.preview {
            SynthParams::preview()
        } else {
            SynthParams {
                passes: self.passes,
                finest_passes: self.finest_passes,
                fine_levels: self.fine_levels,
                ..SynthParams::default()
            }
        };
        SynthParams {
            seed: self.seed,
            scheme,
            grid: self.grid,
            jitter: self.jitter,
            parity_levels: self.parity_levels,
            subpass_side: self.subpass_side,
            contrast: self.contrast,
            consistency: self.consistency,
            slab_thickness: self.slab_thickness,
            slab_tiling: self.slab_tiling,
            field: self.field.clone(),
            period: self.period,
            ..base
        }
    }
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
        Stage::Calibration,
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
    let cands = match &src.source {
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
    };
    let params = src.synth.params(src.scheme);
    Ok(Texture::new(
        Arc::new(cands),
        params,
        Arc::new(TileCache::new(1 << 30)),
    )?)
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
