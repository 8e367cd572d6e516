//! The one declaration of every texture-definition knob as users see it:
//! its name, the values it takes and what it does. The structs in
//! [`crate::params`] hold the values; their defaults live in their
//! `Default` impls. Validation reads the ranges here, the server reads the
//! names here to sort a flat object of parameters, the command line builds
//! its flags from here, and openapi.yaml's parameter sections are
//! generated from here (tests/server_openapi.rs checks them).

use crate::error::{Error, Result};

/// Which parameters a knob belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Part {
    /// [`crate::AnalysisParams`]: shapes the precomputed candidates.
    Analysis,
    /// [`crate::SynthParams`]: shapes the voxels synthesized from them.
    Synthesis,
}

/// The values a knob takes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Values {
    /// An integer in `min..=max`; with `odd`, odd ones only.
    Integer {
        /// Smallest accepted value.
        min: u64,
        /// Largest accepted value.
        max: u64,
        /// Only odd values are accepted.
        odd: bool,
    },
    /// A number in `min..=max` (NaN refused).
    Number {
        /// Smallest accepted value.
        min: f64,
        /// Largest accepted value.
        max: f64,
    },
    /// `true` or `false`.
    Flag,
    /// One of these names.
    Choice(&'static [&'static str]),
    /// A value with a text grammar of its own, which its own parser reads
    /// (a query string or a flag gives it as that text; a JSON body may
    /// give its structured form too).
    Text {
        /// Longest text accepted in a query string, where there is a
        /// limit of its own.
        max_len: Option<u32>,
        /// The grammar as a regular expression, where one is exact.
        pattern: Option<&'static str>,
        /// Whether the text is always kept a string when a query or flag
        /// gives it (else a value that reads as a JSON scalar is one).
        strict: bool,
    },
}

/// One knob of a texture's definition.
#[derive(Clone, Copy, Debug)]
pub struct Knob {
    /// The key in JSON, query strings and stored parameters; the command
    /// line's flag is the same with `-` for `_`.
    pub name: &'static str,
    /// The parameters it belongs to.
    pub part: Part,
    /// The values it takes.
    pub values: Values,
    /// What it does, for users (API document and `--help`).
    pub about: &'static str,
    /// Whether the command line offers it (a knob with one value left
    /// does not).
    pub flag: bool,
}

impl Knob {
    /// The command line's flag for the knob, without the dashes.
    pub fn flag_name(&self) -> String {
        self.name.replace('_', "-")
    }
}

/// The knob called `name`.
pub fn knob(name: &str) -> Option<&'static Knob> {
    KNOBS.iter().find(|k| k.name == name)
}

/// The knobs of one part, in declaration order.
pub fn knobs_of(part: Part) -> impl Iterator<Item = &'static Knob> {
    KNOBS.iter().filter(move |k| k.part == part)
}

const fn int(min: u64, max: u64) -> Values {
    Values::Integer {
        min,
        max,
        odd: false,
    }
}

const fn number(min: f64, max: f64) -> Values {
    Values::Number { min, max }
}

const fn synth(name: &'static str, values: Values, about: &'static str) -> Knob {
    Knob {
        name,
        part: Part::Synthesis,
        values,
        about,
        flag: true,
    }
}

const fn analysis(name: &'static str, values: Values, about: &'static str) -> Knob {
    Knob {
        name,
        part: Part::Analysis,
        values,
        about,
        flag: true,
    }
}

/// A knob with one value left, kept so that texture ids do not change:
/// accepted and documented, but no flag.
const fn kept(knob: Knob) -> Knob {
    Knob {
        flag: false,
        ..knob
    }
}

/// A preset's name and the synthesis parameters it expands to.
pub type Preset = (&'static str, fn() -> crate::SynthParams);

/// The presets a flat object of synthesis parameters may start from
/// (`preset`), the defaults first.
pub const PRESETS: &[Preset] = &[
    ("default", crate::SynthParams::default),
    ("preview", crate::SynthParams::preview),
    ("structured", crate::SynthParams::structured),
];

/// What `preset` does, for users.
pub const PRESET_ABOUT: &str = "Synthesis parameters to start from: `default`; `preview` \
    (one correction pass per level and the finest level upsampled without correction: cold \
    slices 3-5x faster for about 10 % worse patch coherence); or `structured` (Dong et al.'s \
    schedule: two passes of 8 subpasses at every level under the standard scheme: about 2.2x \
    the default's cold time for cleaner spots, longer veins and closed cracks; wood and \
    leather come out blotchier across the grain). Parameters given beside it win. \
    The texture stores the parameters it expands to, so its id is that of the spelled-out \
    parameters.";

/// Knobs that were measured, did not help and were removed
/// (docs/quality.md). A stored texture that gives one at 0 reads as
/// without it; one that gives it another value cannot be synthesized as
/// it was, and is refused.
pub const REMOVED: &[&str] = &["histogram_matching", "glcp_weight"];

/// Takes the [`REMOVED`] knobs out of a stored texture's parameters:
/// `Ok` when each was absent or 0, else an error naming the first that
/// was not.
pub fn strip_removed(
    params: &mut serde_json::Map<String, serde_json::Value>,
) -> std::result::Result<(), String> {
    for key in REMOVED {
        match params.remove(*key) {
            Some(v) if v.as_f64() != Some(0.0) => {
                return Err(format!(
                    "made with `{key}`, which this version no longer has: \
                     precompute the texture again"
                ));
            }
            _ => {}
        }
    }
    Ok(())
}

/// Every knob, synthesis first, each part in the order of its struct.
pub const KNOBS: &[Knob] = &[
    synth(
        "seed",
        int(0, u64::MAX),
        "Random seed of the synthesis, hashed with level and position for every random choice.",
    ),
    synth(
        "passes",
        int(0, 6),
        "Correction passes per level, the fine levels excepted (see `fine_levels`).",
    ),
    synth(
        "finest_passes",
        int(0, 6),
        "Correction passes at the fine levels (see `fine_levels`). A pass there costs far more \
         than a coarse one (every pass widens a request's dependency set at full resolution); \
         one pass keeps most of the quality of two for about half the work of a cold slice.",
    ),
    synth(
        "fine_levels",
        int(1, 16),
        "How many levels, counted from the finest, are corrected with `finest_passes` passes \
         instead of `passes`. Each pass at a level widens a request's dependency set there and \
         at every coarser level.",
    ),
    synth(
        "parity_levels",
        int(0, 16),
        "How many levels, counted from the finest, correct each pass in two parity subpasses \
         (coordinate sums even, then odd) instead of s³ block subpasses (see `subpass_side`). \
         A voxel's chain steps back once through parity subpasses, so a cold slice needs its \
         own plane and half of each plane beside it at those levels, whatever its axis; block \
         subpasses reach up to five planes but converge better at the coarser levels. Textures \
         stored before it keep 0.",
    ),
    synth(
        "subpass_side",
        int(1, 3),
        "Block side s of the block subpasses: s³ subpasses per pass (2 gives 8; 1 corrects \
         every voxel of a pass at once).",
    ),
    synth(
        "scheme",
        Values::Choice(&["standard", "dual-grid"]),
        "Correction scheme: `dual-grid` (Zhang et al.: passes alternate between a primary grid \
         of cells and its dual, and a correction reads across a cell wall the version its step \
         started from, which bounds a request's dependency set) or `standard` (Dong et al.: \
         every correction reads the latest version of its neighbours).",
    ),
    synth(
        "grid",
        int(4, 64),
        "Cell side M of the dual-grid scheme, in voxels of the level.",
    ),
    synth(
        "jitter",
        number(0.0, 4.0),
        "Jitter strength (0 disables it).",
    ),
    synth(
        "correct_init_level",
        Values::Flag,
        "Also correct the coarsest synthesized level after the jitter.",
    ),
    synth(
        "contrast",
        number(1.0, 4.0),
        "Gain on each correction's query around its mean colour (1 disables it): on each \
         appearance-space location around the flat neighbourhood of its mean colour.",
    ),
    kept(synth(
        "slices",
        Values::Choice(&["sparse"]),
        "Voxels a correction reads: `sparse`, its direct neighbours (dependency radius 1), is \
         the only value left; `full` went with the colour correction. Kept so that texture ids \
         do not change.",
    )),
    synth(
        "consistency",
        number(0.0, 1024.0),
        "Penalty on coherent triples whose three exemplar colours disagree (0 disables it). \
         Without it, a feature that only one plane's exemplar has is extruded along that \
         plane's normal into straight streaks on the other planes.",
    ),
    synth(
        "slab_thickness",
        int(1, 9),
        "Thickness of the candidate slab's layers that initialise the coarsest synthesized \
         level, in voxels of that level (Dong et al. use N). Thick layers extrude features \
         along z into x and y slices.",
    ),
    synth(
        "slab_tiling",
        Values::Choice(&["cells", "blocks"]),
        "How the candidate slab is cut into pieces, each tiled with its own hashed offset: \
         `cells` (a jittered grid, borders at every angle) or `blocks` (axis-aligned squares, \
         whose outlines stay visible as square blocks). Textures stored before `cells` keep \
         `blocks`.",
    ),
    kept(synth(
        "correction",
        Values::Choice(&["appearance"]),
        "What a correction matches: `appearance`, sparse appearance-space neighbourhoods (in \
         each plane the appearance vectors at the 4 diagonal locations, each averaged over the \
         3 direct neighbours that predict it; candidates by k-coherence), is the only value \
         left: the colour correction was removed. Kept so that texture ids do not change.",
    )),
    synth(
        "field",
        Values::Text {
            max_len: Some(4096),
            pattern: None,
            strict: false,
        },
        "A field of local frames that the texture follows (docs/fields.md): a preset in short, \
         `slant:ANGLE`, `circular[:CX,CY]`, `emissive[:CX,CY]`, `zigzag:ANGLE,PERIOD` or \
         `slant3d:DX,DY,DZ` (angles in degrees, positions and lengths in voxels of the finest \
         level), or the JSON text of a `Field` object. Part of the texture's id. Omitted: no \
         field. A request target is at most 8 KiB: a long sketch goes in the `params` form \
         field instead.",
    ),
    synth(
        "period",
        Values::Text {
            max_len: Some(40),
            pattern: Some("^[0-9]+(,[0-9]+,[0-9]+)?$"),
            strict: true,
        },
        "Makes the solid periodic: voxel(p) = voxel(p + period·eᵢ) exactly, at every level of \
         detail, so a block of one period tiles space without a seam. One side for all three \
         axes (`128`) or three (`128,128,64`: decimal digits and commas only, no brackets or \
         spaces), in voxels of the finest level, each 1 to 4096 and a multiple of the coarsest \
         level's spacing times the tile side 4 (32 with the default 4 levels; 96 with \
         `subpass_side` 3). Part of the texture's id. Omitted: the solid has no period.",
    ),
    analysis(
        "neighbourhood",
        Values::Integer {
            min: 3,
            max: 9,
            odd: true,
        },
        "Neighbourhood side N (odd) of the exemplar analysis (the papers use 5).",
    ),
    analysis(
        "pca_dims",
        int(2, 16),
        "Appearance-space dimensions per exemplar pixel: the PCA of its N×N colour \
         neighbourhood (the papers use 8).",
    ),
    analysis(
        "strips",
        int(4, 256),
        "Most similar strips searched in each other exemplar for every pixel's 3D candidates \
         (Dong et al.: 65).",
    ),
    analysis(
        "triples",
        int(4, 1000),
        "Triples kept per pixel by crossbar error before the coherence filtering.",
    ),
    analysis(
        "max_candidates",
        int(1, 32),
        "3D candidates kept per pixel after the coherence filtering (Dong et al.: 12).",
    ),
    analysis(
        "levels",
        int(1, 6),
        "Pyramid levels analysed; the synthesis starts at the coarsest.",
    ),
    analysis(
        "similar_coarse",
        int(1, 8),
        "2D candidates (most similar pixels) kept per exemplar pixel for the correction at the \
         coarse levels.",
    ),
    analysis(
        "similar_fine",
        int(1, 8),
        "2D candidates kept per exemplar pixel at the finest level.",
    ),
    analysis(
        "orientation",
        Values::Text {
            max_len: None,
            pattern: None,
            strict: false,
        },
        "How the exemplar is laid on the three planes: `auto` (default) turns one plane a \
         quarter and weights the plane that cuts along the grain down when one exemplar for \
         all planes is square and strongly oriented along one of its axes, and leaves it as it \
         is otherwise; `none` shows it as it is on every plane; an arrangement is given as the \
         JSON text of an object (see `Arrangement`). The texture's `orientation` says what was \
         chosen.",
    ),
    analysis(
        "feature_weight",
        number(0.0, 4.0),
        "Weight of the feature-distance channel in the appearance vectors, relative to the \
         exemplar's luminance: a signed distance to the edges of the exemplar's features: the \
         uploaded feature mask, or else the smaller side of its Otsu luminance threshold, found \
         automatically. 0 (default) matches colour alone. Not written into the texture's \
         parameters when 0.",
    ),
    analysis(
        "initialisation",
        Values::Choice(&["reference", "slab"]),
        "What the synthesis starts from: `slab` (default), the candidate slab of Dong et al.; \
         `reference`, a periodic block of the global reference (texture optimisation over a \
         whole block) optimised at precompute and tiled in cells at hashed offsets. Written \
         into the texture's parameters only when `reference`.",
    ),
    analysis(
        "reference_level",
        int(0, 5),
        "With `initialisation=reference`, the finest level that starts from its own block of \
         the reference (at most `levels` − 1); every coarser level does too. Omitted: the \
         coarsest level only. 0 is the quality preset (every level; minutes of precompute and \
         larger stored candidates).",
    ),
];

/// The knob's default as JSON: its value in the default parameters, or,
/// for a knob left out of their JSON at its default, the declared value
/// that reads back as the defaults. `None` for a knob whose default is
/// to be absent (no field, no period).
pub fn default_of(k: &Knob) -> Option<serde_json::Value> {
    use serde_json::{Value, json};
    fn reads_as_default<T>(name: &str, v: &Value) -> bool
    where
        T: serde::de::DeserializeOwned + Default + PartialEq,
    {
        serde_json::from_value::<T>(json!({ name: v })).is_ok_and(|p| p == T::default())
    }
    let written = match k.part {
        Part::Analysis => serde_json::to_value(crate::AnalysisParams::default()),
        Part::Synthesis => serde_json::to_value(crate::SynthParams::default()),
    };
    if let Some(v) = written.ok().and_then(|w| w.get(k.name).cloned()) {
        return Some(v);
    }
    let declared: Vec<Value> = match k.values {
        Values::Integer { min, max, .. } => vec![json!(min), json!(max)],
        Values::Number { min, max } => vec![json!(min), json!(max)],
        Values::Flag => vec![json!(false), json!(true)],
        Values::Choice(names) => names.iter().map(|n| json!(n)).collect(),
        Values::Text { .. } => Vec::new(),
    };
    declared.into_iter().find(|v| match k.part {
        Part::Analysis => reads_as_default::<crate::AnalysisParams>(k.name, v),
        Part::Synthesis => reads_as_default::<crate::SynthParams>(k.name, v),
    })
}

/// Checks every number of `part` in `params` (the parameters as their JSON
/// object) against its knob's range. A key left out (written only when not
/// its default) is not checked; `null` where a number belongs is a NaN,
/// which no range holds.
pub(crate) fn check_ranges(part: Part, params: &serde_json::Value) -> Result<()> {
    for k in knobs_of(part) {
        let Some(v) = params.get(k.name) else {
            continue;
        };
        let out = |value: f64, min: f64, max: f64| Error::InvalidRange {
            name: k.name,
            value,
            min,
            max,
        };
        match k.values {
            Values::Integer { min, max, odd } => {
                let Some(n) = v.as_u64() else {
                    return Err(out(v.as_f64().unwrap_or(f64::NAN), min as f64, max as f64));
                };
                if !(min..=max).contains(&n) {
                    return Err(out(n as f64, min as f64, max as f64));
                }
                if odd && n % 2 == 0 {
                    return Err(Error::InvalidRequest(format!("{} must be odd", k.name)));
                }
            }
            Values::Number { min, max } => {
                let x = v.as_f64().unwrap_or(f64::NAN);
                if !(min..=max).contains(&x) {
                    return Err(out(x, min, max));
                }
            }
            Values::Flag | Values::Choice(_) | Values::Text { .. } => {}
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{AnalysisParams, SynthParams};
    use serde_json::{Value, json};

    /// Whether `{name: value}` reads as parameters of `part`.
    fn reads(part: Part, name: &str, value: &Value) -> bool {
        let obj = json!({ name: value });
        match part {
            Part::Analysis => serde_json::from_value::<AnalysisParams>(obj).is_ok(),
            Part::Synthesis => serde_json::from_value::<SynthParams>(obj).is_ok(),
        }
    }

    fn sample(k: &Knob) -> Vec<Value> {
        match k.values {
            Values::Integer { min, max, .. } => vec![json!(min), json!(max)],
            Values::Number { min, max } => vec![json!(min), json!(max)],
            Values::Flag => vec![json!(true), json!(false)],
            Values::Choice(names) => names.iter().map(|n| json!(n)).collect(),
            Values::Text { .. } => match k.name {
                "field" => vec![json!("slant:30")],
                "period" => vec![json!("32")],
                "orientation" => vec![json!("none")],
                other => panic!("no sample text for `{other}`"),
            },
        }
    }

    #[test]
    fn every_knob_is_a_field_of_its_part_and_every_field_a_knob() {
        for k in KNOBS {
            let other = match k.part {
                Part::Analysis => Part::Synthesis,
                Part::Synthesis => Part::Analysis,
            };
            for v in sample(k) {
                assert!(reads(k.part, k.name, &v), "{} = {v} not read", k.name);
                assert!(!reads(other, k.name, &v), "{} read by both parts", k.name);
            }
        }
        let names: Vec<&str> = KNOBS.iter().map(|k| k.name).collect();
        let mut unique = names.clone();
        unique.sort();
        unique.dedup();
        assert_eq!(unique.len(), names.len(), "a knob declared twice");
        for (part, v) in [
            (
                Part::Analysis,
                serde_json::to_value(AnalysisParams::quality()),
            ),
            (
                Part::Synthesis,
                serde_json::to_value(SynthParams::default()),
            ),
        ] {
            let Ok(Value::Object(m)) = v else {
                panic!("parameters are an object")
            };
            for key in m.keys() {
                assert!(
                    knob(key).is_some_and(|k| k.part == part),
                    "field `{key}` has no knob in KNOBS (crates/core/src/params/knobs.rs)"
                );
            }
        }
    }

    #[test]
    fn choices_are_exactly_what_reads() {
        for k in KNOBS {
            if let Values::Choice(names) = k.values {
                assert!(
                    !reads(k.part, k.name, &json!("no-such-value")),
                    "{}",
                    k.name
                );
                for n in names {
                    assert!(reads(k.part, k.name, &json!(n)), "{} = {n}", k.name);
                }
            }
        }
    }

    #[test]
    fn defaults_and_presets_are_in_range_and_the_ends_are_refused_past() {
        AnalysisParams::default().validate().unwrap();
        AnalysisParams::quality().validate().unwrap();
        for (_, preset) in PRESETS {
            preset().validate().unwrap();
        }
        for k in KNOBS {
            let past = match k.values {
                Values::Integer { min, max, .. } => {
                    let mut v = vec![json!(max.checked_add(1))];
                    if min > 0 {
                        v.push(json!(min - 1));
                    }
                    v
                }
                Values::Number { min, max } => vec![json!(min - 0.5), json!(max + 0.5)],
                _ => continue,
            };
            for v in past {
                if v.is_null() {
                    continue;
                }
                let obj = json!({ k.name: v });
                let refused = match k.part {
                    Part::Analysis => serde_json::from_value::<AnalysisParams>(obj)
                        .map_or(true, |p| p.validate().is_err()),
                    Part::Synthesis => serde_json::from_value::<SynthParams>(obj)
                        .map_or(true, |p| p.validate().is_err()),
                };
                assert!(refused, "{} = {v} accepted", k.name);
            }
        }
    }
}
