//! What the synthesis commands share: where a texture comes from (a
//! `.stx`, an exemplar image, or the bundled default), its synthesis
//! parameters, and how results are written and summarised.

use anyhow::Context;
use clap::builder::PossibleValuesParser;
use clap::error::ErrorKind;
use clap::parser::ValueSource;
use clap::{Arg, ArgAction, ArgMatches, Args, Command, FromArgMatches};
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;
use serde::de::DeserializeOwned;
use solidtex_core::knobs::{self, Knob, Part, Values};
use solidtex_core::{
    AnalysisParams, Candidates, Exemplar, ExemplarSet, Stage, SynthParams, SynthStats, Texture,
    TileCache,
};
use solidtex_server::spec::TextureParams;
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
}

/// Synthesis parameters: one flag per synthesis knob
/// ([`solidtex_core::knobs`]), read as the server reads a query string,
/// and `--preview`.
#[derive(Clone, Debug, Default)]
pub struct SynthArgs {
    params: SynthParams,
}

impl SynthArgs {
    pub fn params(&self) -> SynthParams {
        self.params.clone()
    }
}

const PREVIEW: &str = "preview";

/// The knobs of `part` that have a flag.
fn flagged(part: Part) -> impl Iterator<Item = &'static Knob> {
    knobs::knobs_of(part).filter(|k| k.flag)
}

/// One flag per knob of `part` that has one, described, with its default.
pub fn knob_flags(part: Part) -> impl Iterator<Item = Arg> {
    flagged(part).map(flag_of)
}

fn flag_of(k: &'static Knob) -> Arg {
    let about = k.about;
    let short = about
        .split(". ")
        .next()
        .unwrap_or(about)
        .trim_end_matches('.');
    let mut arg = Arg::new(k.name)
        .long(k.flag_name())
        .help(format!("{short}."))
        .long_help(about)
        .action(ArgAction::Set);
    if let Some(d) = knobs::default_of(k) {
        let text = match d {
            serde_json::Value::String(s) => s,
            other => other.to_string(),
        };
        arg = arg.default_value(text);
    }
    match k.values {
        Values::Choice(names) => arg
            .value_name("NAME")
            .value_parser(PossibleValuesParser::new(names)),
        Values::Flag => arg
            .value_name("BOOL")
            .value_parser(PossibleValuesParser::new(["true", "false"])),
        Values::Integer { .. } => arg.value_name("N"),
        Values::Number { .. } => arg.value_name("X"),
        Values::Text { .. } => arg.value_name("TEXT"),
    }
}

/// A refused flag value, as clap reports one.
pub fn invalid(e: impl std::fmt::Display) -> clap::Error {
    clap::Error::raw(ErrorKind::ValueValidation, e.to_string())
}

/// `base` with the flags of `part` given on the command line laid over
/// it, each value read as the server reads a query string's (`@FILE`
/// reads a field from the file).
pub fn given_over<T: Serialize + DeserializeOwned>(
    m: &ArgMatches,
    part: Part,
    base: &T,
) -> Result<T, clap::Error> {
    let mut given = Vec::new();
    for k in flagged(part) {
        if m.value_source(k.name) != Some(ValueSource::CommandLine) {
            continue;
        }
        let Some(v) = m.get_one::<String>(k.name) else {
            continue;
        };
        let v = match (k.name, v.strip_prefix('@')) {
            ("field", Some(path)) => std::fs::read_to_string(path)
                .map_err(|e| invalid(format!("--field: reading {path}: {e}")))?,
            _ => v.clone(),
        };
        given.push((k.name, v));
    }
    let mut flat = match serde_json::to_value(base) {
        Ok(serde_json::Value::Object(o)) => o,
        _ => serde_json::Map::new(),
    };
    flat.extend(TextureParams::flat_from_pairs(
        given.iter().map(|(k, v)| (*k, v.as_str())),
    ));
    serde_json::from_value(serde_json::Value::Object(flat)).map_err(invalid)
}

impl Args for SynthArgs {
    fn augment_args(cmd: Command) -> Command {
        let preview = Arg::new(PREVIEW)
            .long(PREVIEW)
            .action(ArgAction::SetTrue)
            .help(
                "Preview parameters: one correction pass per level and the finest level \
                 upsampled without correction: faster cold slices for worse patch coherence \
                 (docs/quality.md).",
            )
            .conflicts_with_all(["passes", "finest_passes", "fine_levels"]);
        cmd.args(knob_flags(Part::Synthesis)).arg(preview)
    }

    fn augment_args_for_update(cmd: Command) -> Command {
        Self::augment_args(cmd)
    }
}

impl FromArgMatches for SynthArgs {
    fn from_arg_matches(m: &ArgMatches) -> Result<Self, clap::Error> {
        // The flags given override the preset's values.
        let preset = if m.get_flag(PREVIEW) {
            SynthParams::preview()
        } else {
            SynthParams::default()
        };
        let params = given_over(m, Part::Synthesis, &preset)?;
        params.validate().map_err(invalid)?;
        Ok(SynthArgs { params })
    }

    fn update_from_arg_matches(&mut self, m: &ArgMatches) -> Result<(), clap::Error> {
        *self = Self::from_arg_matches(m)?;
        Ok(())
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
    let params = src.synth.params();
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
