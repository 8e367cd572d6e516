//! Every texture-definition knob as users see it: its name, the values it
//! takes, what it does and what textures stored before it behaved as. Each
//! is declared once, beside its field, by the `knobs!` blocks in
//! `params.rs`, which expand to the structs, their defaults and the
//! table here. Validation reads the ranges here, the server reads the
//! names here to sort a flat object of parameters and to upgrade stored
//! ones, the command line builds its flags from here, and openapi.yaml's
//! parameter sections are generated from here (tests/server_openapi.rs
//! checks them).

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
    /// For a knob added after the first stored layout: what textures
    /// stored without it behaved as.
    pub before: Option<Before>,
}

/// What a texture stored before a knob existed behaved as, so that its id
/// keeps serving the same bytes across upgrades.
#[derive(Clone, Copy, Debug)]
pub enum Before {
    /// This value, as JSON text.
    Value(&'static str),
    /// The stored value of that other knob (its default when absent).
    SameAs(&'static str),
}

impl Knob {
    /// The command line's flag for the knob, without the dashes.
    pub fn flag_name(&self) -> String {
        self.name.replace('_', "-")
    }
}

/// Declares a parameters struct and its knobs in one place: each field's
/// type, default, values and user text, which is also its doc comment (a
/// field's own `///` lines follow it as notes for developers). Expands to
/// the struct, its `Default` and a table of its [`Knob`]s in field order.
///
/// ```text
/// knobs! {
///     /// Doc of the struct.
///     #[derive(…)]
///     pub struct Name(Part, TABLE) {
///         #[serde(…)]                      // optional attributes
///         field: Type = default, values, "user text" [, flag = false] [, before = Before::…];
///     }
/// }
/// ```
macro_rules! knobs {
    (
        $(#[$meta:meta])*
        pub struct $name:ident($part:ident, $table:ident) {
            $(
                $(#[$fmeta:meta])*
                $field:ident: $ty:ty = $default:expr, $values:expr, $about:literal
                    $(, flag = $flag:literal)?
                    $(, before = $before:expr)?;
            )*
        }
    ) => {
        $(#[$meta])*
        pub struct $name {
            $(
                #[doc = $about]
                $(#[$fmeta])*
                pub $field: $ty,
            )*
        }

        impl Default for $name {
            fn default() -> Self {
                $name { $($field: $default,)* }
            }
        }

        /// The knobs of these parameters, in field order.
        pub(crate) const $table: [$crate::params::knobs::Knob; [$(stringify!($field)),*].len()] = [$(
            $crate::params::knobs::Knob {
                name: stringify!($field),
                part: $crate::params::knobs::Part::$part,
                values: $values,
                about: $about,
                flag: true $(&& $flag)?,
                before: $crate::params::knobs::knobs!(@before $($before)?),
            },
        )*];
    };
    (@before) => { None };
    (@before $before:expr) => { Some($before) };
}
pub(crate) use knobs;

/// The knob called `name`.
pub fn knob(name: &str) -> Option<&'static Knob> {
    KNOBS.iter().find(|k| k.name == name)
}

/// The knobs of one part, in declaration order.
pub fn knobs_of(part: Part) -> impl Iterator<Item = &'static Knob> {
    KNOBS.iter().filter(move |k| k.part == part)
}

/// An integer in `min..=max`.
pub(crate) const fn int(min: u64, max: u64) -> Values {
    Values::Integer {
        min,
        max,
        odd: false,
    }
}

/// A number in `min..=max`.
pub(crate) const fn number(min: f64, max: f64) -> Values {
    Values::Number { min, max }
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

/// Every knob, synthesis first, each part in the order of its struct
/// (declared with the structs in `params.rs`).
pub const KNOBS: &[Knob] = &join::<SYNTH, ANALYSIS, { SYNTH + ANALYSIS }>(
    crate::params::SYNTH_KNOBS,
    crate::params::ANALYSIS_KNOBS,
);
const SYNTH: usize = crate::params::SYNTH_KNOBS.len();
const ANALYSIS: usize = crate::params::ANALYSIS_KNOBS.len();

/// `a` then `b` in one array (`N` = `A + B`).
const fn join<const A: usize, const B: usize, const N: usize>(
    a: [Knob; A],
    b: [Knob; B],
) -> [Knob; N] {
    assert!(A > 0 && A + B == N);
    let mut out = [a[0]; N];
    let mut i = 0;
    while i < N {
        out[i] = if i < A { a[i] } else { b[i - A] };
        i += 1;
    }
    out
}

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
                    "field `{key}` has no knob in KNOBS"
                );
            }
        }
    }

    #[test]
    fn what_textures_stored_before_a_knob_behaved_as_is_well_formed() {
        let mut added = 0;
        for k in KNOBS {
            match k.before {
                None => {}
                Some(Before::Value(json)) => {
                    let v: Value = serde_json::from_str(json)
                        .unwrap_or_else(|e| panic!("{}: `{json}` is not JSON: {e}", k.name));
                    assert!(v.is_number() || v.is_string(), "{}: {v}", k.name);
                    added += 1;
                }
                Some(Before::SameAs(other)) => {
                    let o = knob(other).unwrap_or_else(|| panic!("{}: no knob `{other}`", k.name));
                    assert!(
                        o.before.is_none(),
                        "{}: `{other}` was added later too",
                        k.name
                    );
                    assert!(
                        matches!(
                            (o.values, k.values),
                            (Values::Integer { .. }, Values::Integer { .. })
                        ),
                        "{}: `{other}` takes other values",
                        k.name
                    );
                    added += 1;
                }
            }
        }
        assert!(added > 0, "no knob declares the stored layout before it");
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
