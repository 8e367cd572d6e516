//! The parameters' flags, built from their one declaration
//! ([`solidtex_core::knobs`]): one flag per knob, with its range, default
//! and description, plus a preset flag; the flags given are laid over the
//! preset and read and validated as the server reads an upload's query
//! string, so a flag and a query key of the same name mean the same.

use clap::builder::PossibleValuesParser;
use clap::error::ErrorKind;
use clap::parser::ValueSource;
use clap::{Arg, ArgAction, ArgMatches, Args, Command, FromArgMatches};
use serde::Serialize;
use serde::de::DeserializeOwned;
use solidtex_core::knobs::{self, Knob, Part, Values};
use solidtex_core::{AnalysisParams, SynthParams};
use solidtex_server::spec::TextureParams;

/// Parameters that take their flags from the knobs of one part.
pub trait KnobParams:
    Clone + Default + Serialize + DeserializeOwned + Send + Sync + 'static
{
    /// The part whose knobs are the flags.
    const PART: Part;
    /// The preset flag's name and help.
    const PRESET_FLAG: (&'static str, &'static str);
    /// The knobs the preset sets, whose flags it refuses beside it.
    const PRESET_SETS: &'static [&'static str];
    /// What the preset flag starts from.
    fn preset() -> Self;
    /// Checks every value against its range.
    fn check(&self) -> solidtex_core::Result<()>;
}

impl KnobParams for SynthParams {
    const PART: Part = Part::Synthesis;
    const PRESET_FLAG: (&'static str, &'static str) = (
        "preview",
        "Preview parameters: one correction pass per level and the finest level upsampled \
         without correction: faster cold slices for worse patch coherence (docs/quality.md).",
    );
    const PRESET_SETS: &'static [&'static str] = &["passes", "finest_passes", "fine_levels"];
    fn preset() -> Self {
        SynthParams::preview()
    }
    fn check(&self) -> solidtex_core::Result<()> {
        self.validate()
    }
}

impl KnobParams for AnalysisParams {
    const PART: Part = Part::Analysis;
    const PRESET_FLAG: (&'static str, &'static str) = (
        "quality",
        "The quality preset: the reference kept at every level, so the finest level starts \
         from the reference's own solid (minutes of precompute; docs/quality.md says for which \
         exemplars).",
    );
    const PRESET_SETS: &'static [&'static str] = &["initialisation", "reference_level"];
    fn preset() -> Self {
        AnalysisParams::quality()
    }
    fn check(&self) -> solidtex_core::Result<()> {
        self.validate()
    }
}

/// Parameters of one part read from their flags.
#[derive(Clone, Debug, Default)]
pub struct KnobArgs<P>(P);

/// The synthesis parameters' flags, and `--preview`.
pub type SynthArgs = KnobArgs<SynthParams>;

/// The analysis parameters' flags, and `--quality`.
pub type AnalysisArgs = KnobArgs<AnalysisParams>;

impl<P: KnobParams> KnobArgs<P> {
    /// The parameters the flags give.
    pub fn params(&self) -> P {
        self.0.clone()
    }
}

/// The knobs of `part` that have a flag.
fn flagged(part: Part) -> impl Iterator<Item = &'static Knob> {
    knobs::knobs_of(part).filter(|k| k.flag)
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
fn invalid(e: impl std::fmt::Display) -> clap::Error {
    clap::Error::raw(ErrorKind::ValueValidation, e.to_string())
}

impl<P: KnobParams> Args for KnobArgs<P> {
    fn augment_args(cmd: Command) -> Command {
        let (name, help) = P::PRESET_FLAG;
        let preset = Arg::new(name)
            .long(name)
            .action(ArgAction::SetTrue)
            .help(help)
            .conflicts_with_all(P::PRESET_SETS);
        cmd.args(flagged(P::PART).map(flag_of)).arg(preset)
    }

    fn augment_args_for_update(cmd: Command) -> Command {
        Self::augment_args(cmd)
    }
}

impl<P: KnobParams> FromArgMatches for KnobArgs<P> {
    fn from_arg_matches(m: &ArgMatches) -> Result<Self, clap::Error> {
        // Only the flags given: the others keep the preset's values, or
        // the defaults'. `@FILE` gives a field from a file.
        let mut given = Vec::new();
        for k in flagged(P::PART) {
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
        let base = if m.get_flag(P::PRESET_FLAG.0) {
            P::preset()
        } else {
            P::default()
        };
        let mut flat = match serde_json::to_value(base) {
            Ok(serde_json::Value::Object(o)) => o,
            _ => serde_json::Map::new(),
        };
        flat.extend(TextureParams::flat_from_pairs(
            given.iter().map(|(k, v)| (*k, v.as_str())),
        ));
        let params: P = serde_json::from_value(serde_json::Value::Object(flat)).map_err(invalid)?;
        params.check().map_err(invalid)?;
        Ok(KnobArgs(params))
    }

    fn update_from_arg_matches(&mut self, m: &ArgMatches) -> Result<(), clap::Error> {
        *self = Self::from_arg_matches(m)?;
        Ok(())
    }
}
