//! What a texture is made of: its exemplars and parameters, and the content
//! id derived from them.
//!
//! Clients give parameters as one flat JSON object (`{"seed": 7,
//! "neighbourhood": 5, "scheme": "dual-grid"}`); each key belongs either to
//! the analysis ([`AnalysisParams`]) or to the synthesis ([`SynthParams`]).
//! The id hashes the decoded pixels and the *complete* parameters after
//! defaults are filled in, so an upload is idempotent whatever the encoding
//! of the PNG and whichever defaults were spelled out.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};
use sha2::{Digest, Sha256};
use solidtex_core::Layout;
use solidtex_core::knobs::{self, Part};
use solidtex_core::{AnalysisParams, Exemplar, ExemplarSet, SynthParams};

/// Why parameters are refused.
#[derive(Debug, thiserror::Error)]
pub enum SpecError {
    /// The parameters cannot be read: not an object, an unknown or
    /// repeated key, a wrong type, an unknown preset.
    #[error("{0}")]
    InvalidParams(String),
    /// The engine refuses their values.
    #[error(transparent)]
    Engine(#[from] solidtex_core::Error),
}

/// Analysis and synthesis parameters of one texture.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TextureParams {
    /// Shapes the precomputed candidates.
    pub analysis: AnalysisParams,
    /// Shapes the voxels synthesized from them.
    pub synth: SynthParams,
}

/// The keys of one part's knobs.
fn keys_of(part: Part) -> Vec<String> {
    knobs::knobs_of(part).map(|k| k.name.to_string()).collect()
}

/// The analysis parameters' keys.
fn analysis_keys() -> Vec<String> {
    keys_of(Part::Analysis)
}

impl TextureParams {
    /// Splits a flat object of parameters into analysis and synthesis
    /// parameters, rejecting unknown keys, wrong types and out-of-range
    /// values.
    ///
    /// `preset` names a set of synthesis parameters to start from instead
    /// of the defaults (`preview`: [`SynthParams::preview`]); keys given
    /// beside it win. It is not kept: the texture's parameters, and so its
    /// id, are those the preset expands to.
    pub fn from_flat(obj: &Map<String, Value>) -> Result<TextureParams, SpecError> {
        let analysis_keys = analysis_keys();
        let synth_keys = keys_of(Part::Synthesis);
        let mut a = Map::new();
        let mut s = Map::new();
        if let Some(preset) = obj.get("preset") {
            let Some((_, base)) = knobs::PRESETS
                .iter()
                .find(|(name, _)| preset.as_str() == Some(name))
            else {
                let known: Vec<&str> = knobs::PRESETS.iter().map(|(name, _)| *name).collect();
                return Err(invalid_params(format!(
                    "unknown preset {preset} (known: {})",
                    known.join(", ")
                )));
            };
            let base = base();
            if let Ok(Value::Object(m)) = serde_json::to_value(base) {
                s = m;
            }
        }
        for (k, v) in obj {
            if k == "preset" {
                continue;
            }
            if analysis_keys.contains(k) {
                a.insert(k.clone(), v.clone());
            } else if synth_keys.contains(k) {
                s.insert(k.clone(), v.clone());
            } else {
                let preset = "preset".to_string();
                let mut known: Vec<&String> = analysis_keys
                    .iter()
                    .chain(&synth_keys)
                    .chain([&preset])
                    .collect();
                known.sort();
                let known: Vec<&str> = known.iter().map(|k| k.as_str()).collect();
                return Err(invalid_params(format!(
                    "unknown parameter `{k}` (known: {})",
                    known.join(", ")
                )));
            }
        }
        let analysis: AnalysisParams =
            serde_json::from_value(Value::Object(a)).map_err(|e| invalid_params(e.to_string()))?;
        let synth: SynthParams =
            serde_json::from_value(Value::Object(s)).map_err(|e| invalid_params(e.to_string()))?;
        analysis.validate()?;
        synth.validate()?;
        // The period must fit the levels the analysis makes: refused with
        // the upload, not when the precompute is done.
        if let Some(period) = synth.period {
            solidtex_core::period::check(period, analysis.levels as usize, &synth)?;
        }
        Ok(TextureParams { analysis, synth })
    }

    /// These parameters with some synthesis parameters replaced: the
    /// parameters of a variant of a texture. `overrides` is a flat object
    /// of synthesis keys (`null` for `field` drops the field); `preset`
    /// starts from that preset instead of these synthesis parameters.
    /// Analysis keys are refused: they shape the candidates, which a
    /// variant shares.
    pub fn with_overrides(
        &self,
        overrides: &Map<String, Value>,
    ) -> Result<TextureParams, SpecError> {
        let analysis_keys = analysis_keys();
        if let Some(k) = overrides.keys().find(|k| analysis_keys.contains(k)) {
            return Err(invalid_params(format!(
                "parameter `{k}` shapes the precomputed candidates: a variant shares them and \
                 changes synthesis parameters only; upload the exemplars again with it \
                 (a new precompute)"
            )));
        }
        let mut flat = if overrides.contains_key("preset") {
            match serde_json::to_value(&self.analysis) {
                Ok(Value::Object(m)) => m,
                _ => Map::new(),
            }
        } else {
            self.to_flat()
        };
        for (k, v) in overrides {
            flat.insert(k.clone(), v.clone());
        }
        Self::from_flat(&flat)
    }

    /// Parameters as a data directory stored them. Stored parameters are
    /// complete, so a key added since they were written takes the value that
    /// reproduces the texture's voxels as they were then, not today's
    /// default: the same id keeps serving the same bytes across upgrades.
    pub fn from_stored(obj: &Map<String, Value>) -> Result<TextureParams, SpecError> {
        let mut obj = obj.clone();
        knobs::strip_removed(&mut obj).map_err(SpecError::InvalidParams)?;
        // A knob added since stores what textures written before it
        // behaved as: a value, or the value of an older knob.
        for k in knobs::KNOBS {
            let then = match k.before {
                None => continue,
                Some(knobs::Before::Value(json)) => {
                    serde_json::from_str(json).expect("declared as JSON text")
                }
                Some(knobs::Before::SameAs(other)) => {
                    obj.get(other).cloned().unwrap_or_else(|| {
                        knobs::knob(other)
                            .and_then(knobs::default_of)
                            .expect("a knob with a default")
                    })
                }
            };
            obj.entry(k.name).or_insert(then);
        }
        Self::from_flat(&obj)
    }

    /// Parses a JSON text holding a flat object of parameters.
    pub fn from_json(text: &str) -> Result<TextureParams, SpecError> {
        Self::from_flat(&params_object(text)?)
    }

    /// Parameters from query-string pairs: each value is read as a JSON
    /// scalar when it is one (`seed=7`, `jitter=0.5`, `correct_init_level=false`)
    /// and as a string otherwise (`scheme=dual-grid`). A knob with a
    /// strict text grammar ([`knobs::Values::Text`]) stays a string
    /// whatever it holds: JSON's reading would let `period=null` or
    /// `period=%2016` through, outside the pattern openapi.yaml documents.
    pub fn flat_from_pairs<'a>(
        pairs: impl Iterator<Item = (&'a str, &'a str)>,
    ) -> Map<String, Value> {
        pairs
            .map(|(k, v)| {
                let value = match serde_json::from_str::<Value>(v) {
                    Ok(j) if !j.is_object() && !j.is_array() && !strict_text(k) => j,
                    _ => Value::String(v.to_string()),
                };
                (k.to_string(), value)
            })
            .collect()
    }

    /// All parameters as one flat object.
    pub fn to_flat(&self) -> Map<String, Value> {
        let mut m = Map::new();
        for v in [
            serde_json::to_value(&self.analysis),
            serde_json::to_value(&self.synth),
        ]
        .into_iter()
        .flatten()
        {
            if let Value::Object(o) = v {
                m.extend(o);
            }
        }
        m
    }
}

/// Whether `key` is a knob whose text is always kept a string.
fn strict_text(key: &str) -> bool {
    knobs::knob(key).is_some_and(|k| matches!(k.values, knobs::Values::Text { strict: true, .. }))
}

/// The members of a JSON object in the order written, repeated keys kept.
struct Members(Vec<(String, Value)>);

impl<'de> Deserialize<'de> for Members {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Members, D::Error> {
        struct Visit;
        impl<'de> serde::de::Visitor<'de> for Visit {
            type Value = Members;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a JSON object")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                mut m: A,
            ) -> Result<Members, A::Error> {
                let mut out = Vec::new();
                while let Some(kv) = m.next_entry::<String, Value>()? {
                    out.push(kv);
                }
                Ok(Members(out))
            }
        }
        d.deserialize_map(Visit)
    }
}

/// A JSON value whose objects, at any depth, were checked for keys given
/// twice (a JSON parser would keep the last one silently, so a field
/// object's `{"kind": "slant", "kind": "zigzag"}` would pass in a body
/// while the same text in a query is refused).
struct Strict(Value);

impl<'de> Deserialize<'de> for Strict {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Strict, D::Error> {
        d.deserialize_any(StrictVisitor).map(Strict)
    }
}

struct StrictVisitor;

impl<'de> serde::de::Visitor<'de> for StrictVisitor {
    type Value = Value;
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a JSON value")
    }
    fn visit_bool<E>(self, v: bool) -> Result<Value, E> {
        Ok(Value::Bool(v))
    }
    fn visit_i64<E>(self, v: i64) -> Result<Value, E> {
        Ok(Value::from(v))
    }
    fn visit_u64<E>(self, v: u64) -> Result<Value, E> {
        Ok(Value::from(v))
    }
    fn visit_f64<E>(self, v: f64) -> Result<Value, E> {
        Ok(Value::from(v))
    }
    fn visit_str<E>(self, v: &str) -> Result<Value, E> {
        Ok(Value::String(v.to_string()))
    }
    fn visit_string<E>(self, v: String) -> Result<Value, E> {
        Ok(Value::String(v))
    }
    fn visit_unit<E>(self) -> Result<Value, E> {
        Ok(Value::Null)
    }
    fn visit_none<E>(self) -> Result<Value, E> {
        Ok(Value::Null)
    }
    fn visit_some<D: serde::Deserializer<'de>>(self, d: D) -> Result<Value, D::Error> {
        Strict::deserialize(d).map(|s| s.0)
    }
    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Value, A::Error> {
        let mut out = Vec::new();
        while let Some(Strict(v)) = seq.next_element()? {
            out.push(v);
        }
        Ok(Value::Array(out))
    }
    fn visit_map<A: serde::de::MapAccess<'de>>(self, mut m: A) -> Result<Value, A::Error> {
        let mut out = Map::new();
        while let Some(k) = m.next_key::<String>()? {
            if out.contains_key(&k) {
                return Err(serde::de::Error::custom(format!(
                    "key `{k}` given more than once"
                )));
            }
            let Strict(v) = m.next_value()?;
            out.insert(k, v);
        }
        Ok(Value::Object(out))
    }
}

/// Parses the JSON text of a `params` object. A key given twice, at the
/// top or inside a value (a field object), is refused.
pub fn params_object(text: &str) -> Result<Map<String, Value>, SpecError> {
    match serde_json::from_str(text) {
        Ok(Strict(Value::Object(m))) => Ok(m),
        Ok(_) => Err(invalid_params("`params` must be a JSON object".to_string())),
        Err(e) => Err(invalid_params(format!("`params`: {e}"))),
    }
}

fn invalid_params(message: String) -> SpecError {
    SpecError::InvalidParams(message)
}

/// The exemplars of an upload: one image for all planes or three.
#[derive(Clone, Debug)]
pub enum Planes {
    /// One exemplar for xy, yz and zx.
    Single(Exemplar),
    /// One exemplar per plane: xy, yz, zx.
    Triple(Box<[Exemplar; 3]>),
}

impl Planes {
    /// The exemplar set the engine works on.
    pub fn to_set(&self) -> solidtex_core::Result<ExemplarSet> {
        match self {
            Planes::Single(e) => Ok(ExemplarSet::single(e.clone())),
            Planes::Triple(t) => {
                let [xy, yz, zx] = (**t).clone();
                ExemplarSet::triple(xy, yz, zx)
            }
        }
    }

    /// Every stored image with its plane name.
    pub fn named(&self) -> Vec<(&'static str, &Exemplar)> {
        match self {
            Planes::Single(e) => vec![("exemplar", e)],
            Planes::Triple(t) => vec![("xy", &t[0]), ("yz", &t[1]), ("zx", &t[2])],
        }
    }

    /// How many of the images have a feature mask.
    pub fn feature_masks(&self) -> u32 {
        self.named()
            .iter()
            .filter(|(_, e)| e.feature_mask().is_some())
            .count() as u32
    }

    /// Width and height of every plane.
    pub fn size(&self) -> (u32, u32) {
        let e = self.named()[0].1;
        (e.width(), e.height())
    }
}

/// Everything a texture is made of.
#[derive(Clone, Debug)]
pub struct TextureSpec {
    /// Exemplar images.
    pub planes: Planes,
    /// Parameters.
    pub params: TextureParams,
}

impl TextureSpec {
    /// The content hash: SHA-256 over a version tag, the pixels (and
    /// feature masks, where given) of the xy, yz and zx exemplars (a single
    /// exemplar counts for all three) and the
    /// canonical JSON of the complete parameters; 32 hex digits.
    pub fn content_hash(&self) -> String {
        let mut h = Sha256::new();
        h.update(b"solidtex texture v1\0");
        self.hash_planes(&mut h);
        hash_json(&mut h, &self.params.analysis);
        hash_json(&mut h, &self.params.synth);
        hex(&h.finalize()[..16])
    }

    /// The content hash as it was computed when `stored`, the flat
    /// parameters of a `meta.json`, were written: parameters added since
    /// were not part of it (the hash is over each parameter struct's JSON,
    /// and the structs had only the stored keys then, in today's order).
    pub fn content_hash_as_stored(&self, stored: &Map<String, Value>) -> String {
        let mut h = Sha256::new();
        h.update(b"solidtex texture v1\0");
        self.hash_planes(&mut h);
        hash_json_keys(&mut h, &self.params.analysis, stored);
        hash_json_keys(&mut h, &self.params.synth, stored);
        hex(&h.finalize()[..16])
    }

    /// What the precomputed candidates depend on: the pixels and the
    /// analysis parameters only. Textures that differ in synthesis
    /// parameters alone share their candidates.
    pub fn analysis_hash(&self) -> String {
        let mut h = Sha256::new();
        h.update(b"solidtex candidates v1\0");
        self.hash_planes(&mut h);
        hash_json(&mut h, &self.params.analysis);
        hex(&h.finalize()[..16])
    }

    /// How the exemplars are laid on the planes (what the precompute will
    /// use): refused when the orientation asks a quarter turn of a
    /// non-square exemplar, or when the analysis parameters cannot use
    /// the exemplars (a feature mask without the feature-distance channel).
    pub fn layout(&self) -> solidtex_core::Result<Layout> {
        let set = self.planes.to_set()?;
        self.params.analysis.validate_for(&set)?;
        Layout::resolve(&set, &self.params.analysis.orientation)
    }

    fn hash_planes(&self, h: &mut Sha256) {
        let planes: [&Exemplar; 3] = match &self.planes {
            Planes::Single(e) => [e, e, e],
            Planes::Triple(t) => [&t[0], &t[1], &t[2]],
        };
        for e in planes {
            h.update(e.width().to_le_bytes());
            h.update(e.height().to_le_bytes());
            for p in e.pixels() {
                h.update(p);
            }
            // Only a masked plane hashes more, so ids of textures without
            // masks stay as they were.
            if let Some(mask) = e.feature_mask() {
                h.update(b"feature mask\0");
                h.update(mask.iter().map(|&f| f as u8).collect::<Vec<u8>>());
            }
        }
    }
}

fn hash_json<T: Serialize>(h: &mut Sha256, v: &T) {
    let s = serde_json::to_string(v).unwrap_or_default();
    h.update((s.len() as u64).to_le_bytes());
    h.update(s.as_bytes());
}

/// [`hash_json`] of `v` restricted to the keys of `keep`, members in the
/// order `v` writes them.
fn hash_json_keys<T: Serialize>(h: &mut Sha256, v: &T, keep: &Map<String, Value>) {
    let full = serde_json::to_string(v).unwrap_or_default();
    let Ok(Members(members)) = serde_json::from_str::<Members>(&full) else {
        return hash_json(h, v);
    };
    // Nothing to leave out: the text as written. Rewriting it would sort
    // the members of nested objects (a field's `kind` first no more) and
    // change the hash.
    if members.iter().all(|(k, _)| keep.contains_key(k)) {
        return hash_json(h, v);
    }
    let kept: Vec<String> = members
        .iter()
        .filter(|(k, _)| keep.contains_key(k))
        .map(|(k, v)| format!("{}:{v}", Value::String(k.clone())))
        .collect();
    let s = format!("{{{}}}", kept.join(","));
    h.update((s.len() as u64).to_le_bytes());
    h.update(s.as_bytes());
}

/// Lowercase hex of bytes.
pub fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// True for strings that can be a texture id: 1 to 64 characters of
/// `[A-Za-z0-9_-]` (content ids are 32 hex digits; `default` is the other).
pub fn valid_id(id: &str) -> bool {
    (1..=64).contains(&id.len())
        && id
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
}

// Stored in a texture's metadata and shown in the API; openapi.yaml's
// `ExemplarInfo` schema is generated from it (not written when no mask
// came, so metadata stored before masks reads the same).
/// The exemplar images' size.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq, JsonSchema)]
pub struct ExemplarInfo {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// 1 (one image for all planes) or 3.
    #[schemars(extend("enum" = [1, 3]))]
    pub planes: u32,
    /// How many of the images came with a feature mask; absent when none
    /// did.
    #[serde(default, skip_serializing_if = "is_zero")]
    #[schemars(range(min = 1, max = 3))]
    pub feature_masks: u32,
}

fn is_zero(n: &u32) -> bool {
    *n == 0
}

#[cfg(test)]
mod tests {
    use super::*;
    use solidtex_core::Initialisation;

    /// The error code a client would see.
    fn code(e: SpecError) -> &'static str {
        crate::error::ApiError::from(e).code
    }

    fn img(seed: u8) -> Exemplar {
        let rgb: Vec<u8> = (0..16 * 16 * 3)
            .map(|i| (i as u8).wrapping_mul(seed))
            .collect();
        Exemplar::from_rgb(16, 16, &rgb).unwrap()
    }

    #[test]
    fn a_preset_expands_to_its_parameters_and_yields_to_explicit_keys() {
        let flat = |text: &str| match serde_json::from_str::<Value>(text).unwrap() {
            Value::Object(m) => TextureParams::from_flat(&m),
            _ => unreachable!(),
        };
        let preview = flat(r#"{"preset": "preview", "seed": 7}"#).unwrap();
        let spelled = flat(r#"{"passes": 1, "finest_passes": 0, "fine_levels": 1, "seed": 7}"#);
        assert_eq!(preview, spelled.unwrap());
        assert_eq!(preview.synth.seed, 7);
        assert!(!preview.to_flat().contains_key("preset"));
        let overridden = flat(r#"{"preset": "preview", "passes": 2}"#).unwrap();
        assert_eq!(overridden.synth.passes, 2);
        assert_eq!(overridden.synth.finest_passes, 0);
        assert_eq!(
            flat(r#"{"preset": "default"}"#).unwrap(),
            TextureParams::default()
        );
        let structured = flat(r#"{"preset": "structured"}"#).unwrap();
        let spelled = flat(
            r#"{"scheme": "standard", "passes": 2, "finest_passes": 2, "fine_levels": 1,
                "parity_levels": 0}"#,
        );
        assert_eq!(structured, spelled.unwrap());
        for bad in [r#"{"preset": "fast"}"#, r#"{"preset": 1}"#] {
            let e = flat(bad).unwrap_err();
            assert!(format!("{e:?}").contains("preset"), "{bad}: {e:?}");
        }
    }

    #[test]
    fn flat_params_split() {
        let p =
            TextureParams::from_json(r#"{"seed": 9, "neighbourhood": 7, "scheme": "standard"}"#)
                .unwrap();
        assert_eq!(p.synth.seed, 9);
        assert_eq!(p.analysis.neighbourhood, 7);
        assert_eq!(p.synth.scheme, solidtex_core::Scheme::Standard);
        let flat = p.to_flat();
        assert_eq!(flat["seed"], 9);
        assert_eq!(flat["levels"], AnalysisParams::default().levels);
        assert_eq!(TextureParams::from_flat(&flat).unwrap(), p);
    }

    #[test]
    fn stored_params_without_a_newer_key_keep_their_old_meaning() {
        let new = TextureParams::default().to_flat();
        assert_eq!(new["slices"], "sparse");
        let mut old = new.clone();
        old.remove("slices");
        // A fresh upload that omits the key gets today's default...
        assert_eq!(
            TextureParams::from_flat(&old).unwrap().synth.slices,
            solidtex_core::Slices::Sparse
        );
        // ...but a stored texture written before the key existed was
        // synthesized with full slices, which went with the colour
        // correction: it is refused, never served with other bytes.
        let e = TextureParams::from_stored(&old).unwrap_err();
        assert!(format!("{e:?}").contains("removed"), "{e:?}");
        assert_eq!(
            TextureParams::from_stored(&new).unwrap(),
            TextureParams::default()
        );
        // The finest level had the texture's own number of passes.
        let mut old = new.clone();
        old.remove("finest_passes");
        old.insert("passes".into(), 3.into());
        assert_eq!(
            TextureParams::from_flat(&old).unwrap().synth.finest_passes,
            1
        );
        assert_eq!(
            TextureParams::from_stored(&old)
                .unwrap()
                .synth
                .finest_passes,
            3
        );
        old.remove("passes");
        assert_eq!(
            TextureParams::from_stored(&old)
                .unwrap()
                .synth
                .finest_passes,
            2
        );
        // Only level 0 took `finest_passes`.
        old.remove("fine_levels");
        assert_eq!(
            TextureParams::from_stored(&old).unwrap().synth.fine_levels,
            1
        );
        assert_eq!(
            TextureParams::from_flat(&old).unwrap().synth.fine_levels,
            SynthParams::default().fine_levels
        );
        // Nor did it penalise inconsistent triples.
        old.remove("consistency");
        assert_eq!(
            TextureParams::from_stored(&old).unwrap().synth.consistency,
            0.0
        );
        assert_eq!(
            TextureParams::from_flat(&old).unwrap().synth.consistency,
            SynthParams::default().consistency
        );
        // It matched colour neighbourhoods, which is refused likewise.
        let mut colour = old.clone();
        colour.remove("correction");
        let e = TextureParams::from_stored(&colour).unwrap_err();
        assert!(
            format!("{e:?}").contains("colour correction was removed"),
            "{e:?}"
        );
        // Knobs measured and removed: at 0 as if absent, else refused.
        for key in knobs::REMOVED {
            let mut with = new.clone();
            with.insert((*key).into(), 0.into());
            assert_eq!(
                TextureParams::from_stored(&with).unwrap(),
                TextureParams::default()
            );
            with.insert((*key).into(), 0.5.into());
            let e = TextureParams::from_stored(&with).unwrap_err();
            assert!(format!("{e}").contains(key), "{e}");
            assert!(TextureParams::from_flat(&with).is_err());
        }
        // Its slab was N thick.
        old.remove("slab_thickness");
        old.insert("neighbourhood".into(), 7.into());
        assert_eq!(
            TextureParams::from_stored(&old)
                .unwrap()
                .synth
                .slab_thickness,
            7
        );
        old.remove("neighbourhood");
        assert_eq!(
            TextureParams::from_stored(&old)
                .unwrap()
                .synth
                .slab_thickness,
            5
        );
        assert_eq!(
            TextureParams::from_flat(&old).unwrap().synth.slab_thickness,
            SynthParams::default().slab_thickness
        );
        // Nor did it turn any plane, whatever its exemplar.
        old.remove("orientation");
        assert_eq!(
            TextureParams::from_stored(&old)
                .unwrap()
                .analysis
                .orientation,
            solidtex_core::Orientation::None
        );
        assert_eq!(
            TextureParams::from_flat(&old).unwrap().analysis.orientation,
            solidtex_core::Orientation::Auto
        );
        // Its slab was tiled in axis-aligned blocks.
        old.remove("slab_tiling");
        assert_eq!(
            TextureParams::from_stored(&old).unwrap().synth.slab_tiling,
            solidtex_core::SlabTiling::Blocks
        );
        assert_eq!(
            TextureParams::from_flat(&old).unwrap().synth.slab_tiling,
            solidtex_core::SlabTiling::Cells
        );
        // Its passes ran as block subpasses at every level.
        old.remove("parity_levels");
        assert_eq!(
            TextureParams::from_stored(&old)
                .unwrap()
                .synth
                .parity_levels,
            0
        );
        assert_eq!(
            TextureParams::from_flat(&old).unwrap().synth.parity_levels,
            SynthParams::default().parity_levels
        );
    }

    #[test]
    fn bad_params() {
        assert_eq!(
            code(TextureParams::from_json(r#"{"sed": 1}"#).unwrap_err()),
            "invalid_params"
        );
        assert_eq!(
            code(TextureParams::from_json(r#"{"seed": "x"}"#).unwrap_err()),
            "invalid_params"
        );
        assert_eq!(
            code(TextureParams::from_json("[1]").unwrap_err()),
            "invalid_params"
        );
        assert_eq!(
            code(TextureParams::from_json("{").unwrap_err()),
            "invalid_params"
        );
        assert_eq!(
            code(TextureParams::from_json(r#"{"passes": 99}"#).unwrap_err()),
            "out_of_range"
        );
        assert_eq!(
            code(TextureParams::from_json(r#"{"parity_levels": 17}"#).unwrap_err()),
            "out_of_range"
        );
        assert_eq!(
            code(TextureParams::from_json(r#"{"parity_levels": -1}"#).unwrap_err()),
            "invalid_params"
        );
        assert_eq!(
            code(TextureParams::from_json(r#"{"slices": "dense"}"#).unwrap_err()),
            "invalid_params"
        );
        assert_eq!(
            code(TextureParams::from_json(r#"{"slab_tiling": "squares"}"#).unwrap_err()),
            "invalid_params"
        );
        assert_eq!(
            code(TextureParams::from_json(r#"{"neighbourhood": 4}"#).unwrap_err()),
            "invalid_request"
        );
    }

    #[test]
    fn a_feature_channel_is_an_analysis_parameter_of_the_appearance_correction() {
        let p = TextureParams::from_json(r#"{"feature_weight": 0.5}"#).unwrap();
        assert_eq!(p.analysis.feature_weight, 0.5);
        assert_eq!(p.to_flat()["feature_weight"], 0.5);
        assert!(
            !TextureParams::default()
                .to_flat()
                .contains_key("feature_weight")
        );
        assert_eq!(
            code(TextureParams::from_json(r#"{"feature_weight": 9}"#).unwrap_err()),
            "out_of_range"
        );
        // A variant shares the candidates, so it cannot add the channel.
        let overrides = TextureParams::flat_from_pairs([("feature_weight", "1")].into_iter());
        assert_eq!(
            code(p.with_overrides(&overrides).unwrap_err()),
            "invalid_params"
        );
    }

    #[test]
    fn query_pairs_typed() {
        let pairs = [
            ("seed", "7"),
            ("scheme", "dual-grid"),
            ("jitter", "0.5"),
            ("correct_init_level", "false"),
            ("contrast", "1.25"),
            ("slices", "sparse"),
            ("slab_tiling", "blocks"),
        ];
        let flat = TextureParams::flat_from_pairs(pairs.into_iter());
        let p = TextureParams::from_flat(&flat).unwrap();
        assert_eq!(p.synth.slices, solidtex_core::Slices::Sparse);
        assert_eq!(p.synth.slab_tiling, solidtex_core::SlabTiling::Blocks);
        assert_eq!(p.synth.seed, 7);
        assert_eq!(p.synth.jitter, 0.5);
        assert!(!p.synth.correct_init_level);
        assert_eq!(p.synth.contrast, 1.25);
        // A period is text in a query, read by its own strict grammar.
        let period = |v| {
            TextureParams::from_flat(&TextureParams::flat_from_pairs(
                [("levels", "3"), ("period", v)].into_iter(),
            ))
            .map(|p| p.synth.period)
        };
        assert_eq!(period("16").unwrap(), Some([16; 3]));
        assert_eq!(period("16,32,48").unwrap(), Some([16, 32, 48]));
        for bad in ["null", " 16", "16 ", "[16,16,16]", "1.6e1"] {
            assert!(period(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn a_field_comes_as_text_or_object_and_is_part_of_the_id() {
        let text = TextureParams::flat_from_pairs([("field", "slant:30")].into_iter());
        let object = TextureParams::from_json(r#"{"field": {"kind": "slant", "angle": 30}}"#);
        let json_text = TextureParams::flat_from_pairs(
            [("field", r#"{"kind":"slant","angle":30}"#)].into_iter(),
        );
        let a = TextureParams::from_flat(&text).unwrap();
        assert_eq!(a, object.unwrap());
        assert_eq!(a, TextureParams::from_flat(&json_text).unwrap());
        assert_eq!(
            a.synth.field,
            Some(solidtex_core::Field::Slant { angle: 30.0 })
        );
        // Stored as the object, it reads back the same.
        assert_eq!(TextureParams::from_flat(&a.to_flat()).unwrap(), a);
        let id = |params: TextureParams| {
            TextureSpec {
                planes: Planes::Single(img(3)),
                params,
            }
            .content_hash()
        };
        assert_ne!(id(a.clone()), id(TextureParams::default()));
        // No field hashes as before fields existed: no `field` key at all.
        assert!(!TextureParams::default().to_flat().contains_key("field"));
        for bad in [
            r#"{"field": "spiral"}"#,
            r#"{"field": {"kind": "zigzag", "angle": 10, "period": 0}}"#,
            r#"{"field": {"kind": "slant", "angle": "x"}}"#,
            r#"{"field": 3}"#,
        ] {
            assert!(TextureParams::from_json(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn ids_are_content_hashes() {
        let spec = |e: Exemplar, seed| TextureSpec {
            planes: Planes::Single(e),
            params: TextureParams {
                synth: SynthParams {
                    seed,
                    ..Default::default()
                },
                ..Default::default()
            },
        };
        let a = spec(img(3), 1).content_hash();
        assert_eq!(a.len(), 32);
        assert!(valid_id(&a));
        assert_eq!(a, spec(img(3), 1).content_hash());
        assert_ne!(a, spec(img(5), 1).content_hash());
        assert_ne!(a, spec(img(3), 2).content_hash());
        let triple = TextureSpec {
            planes: Planes::Triple(Box::new([img(3), img(3), img(3)])),
            params: spec(img(3), 1).params,
        };
        assert_eq!(a, triple.content_hash());
        // Candidates depend on pixels and analysis parameters only.
        assert_eq!(
            spec(img(3), 1).analysis_hash(),
            spec(img(3), 2).analysis_hash()
        );
        assert_ne!(
            spec(img(3), 1).analysis_hash(),
            spec(img(5), 1).analysis_hash()
        );
    }

    /// The synthesis parameters as the first stored layout had them, in
    /// their order then.
    #[derive(Serialize)]
    struct SynthParamsVersion1 {
        seed: u64,
        passes: u32,
        subpass_side: u32,
        scheme: Value,
        grid: u32,
        jitter: f32,
        correct_init_level: bool,
        contrast: f32,
    }

    #[test]
    fn ids_are_recomputed_as_they_were_stored() {
        let now = TextureSpec {
            planes: Planes::Single(img(3)),
            params: TextureParams {
                synth: SynthParams {
                    seed: 7,
                    ..Default::default()
                },
                ..Default::default()
            },
        };
        assert_eq!(
            now.content_hash_as_stored(&now.params.to_flat()),
            now.content_hash()
        );
        // Nested objects keep their members' order: a field whose `kind`
        // comes first hashes as written.
        let mut guided = now.clone();
        guided.params.synth.field = Some(solidtex_core::Field::Circular {
            centre: [4.0, 4.0, 0.0],
            axis: [0.0, 0.0, 1.0],
        });
        assert_eq!(
            guided.content_hash_as_stored(&guided.params.to_flat()),
            guided.content_hash()
        );
        // A texture stored by the first layout: its parameters lack the
        // keys added since, and its id hashed the structs of then.
        let mut old = now.params.to_flat();
        for k in [
            "slices",
            "consistency",
            "fine_levels",
            "correction",
            "finest_passes",
            "slab_thickness",
            "slab_tiling",
            "parity_levels",
        ] {
            old.remove(k);
        }
        let d = SynthParams::default();
        let then = SynthParamsVersion1 {
            seed: 7,
            passes: d.passes,
            subpass_side: d.subpass_side,
            scheme: old["scheme"].clone(),
            grid: d.grid,
            jitter: d.jitter,
            correct_init_level: d.correct_init_level,
            contrast: d.contrast,
        };
        let mut h = Sha256::new();
        h.update(b"solidtex texture v1\0");
        now.hash_planes(&mut h);
        hash_json(&mut h, &now.params.analysis);
        hash_json(&mut h, &then);
        let id_then = hex(&h.finalize()[..16]);
        // Such a texture matched colour neighbourhoods, which are gone, so
        // it is no longer served; hashing only the keys a texture stored is
        // still how the ids of later layouts are checked.
        assert!(TextureParams::from_stored(&old).is_err());
        assert_ne!(now.content_hash(), id_then);
        assert_eq!(now.content_hash_as_stored(&old), id_then);
        // Another seed or other pixels do not match.
        let mut other = now.clone();
        other.params.synth.seed = 8;
        assert_ne!(other.content_hash_as_stored(&old), id_then);
    }

    /// The analysis parameters before orientations, in their order then.
    #[derive(Serialize)]
    struct AnalysisParamsBeforeOrientation {
        neighbourhood: u32,
        pca_dims: u32,
        strips: u32,
        triples: u32,
        max_candidates: u32,
        levels: u32,
        similar_coarse: u32,
        similar_fine: u32,
    }

    #[test]
    fn ids_of_textures_stored_before_orientations_are_kept() {
        let now = TextureSpec {
            planes: Planes::Single(img(3)),
            params: TextureParams::default(),
        };
        let mut old = now.params.to_flat();
        old.remove("orientation");
        old.remove("initialisation");
        let a = AnalysisParams::default();
        let then = AnalysisParamsBeforeOrientation {
            neighbourhood: a.neighbourhood,
            pca_dims: a.pca_dims,
            strips: a.strips,
            triples: a.triples,
            max_candidates: a.max_candidates,
            levels: a.levels,
            similar_coarse: a.similar_coarse,
            similar_fine: a.similar_fine,
        };
        let mut h = Sha256::new();
        h.update(b"solidtex texture v1\0");
        now.hash_planes(&mut h);
        hash_json(&mut h, &then);
        hash_json(&mut h, &now.params.synth);
        let id_then = hex(&h.finalize()[..16]);
        let loaded = TextureSpec {
            planes: now.planes.clone(),
            params: TextureParams::from_stored(&old).unwrap(),
        };
        assert_eq!(loaded.content_hash_as_stored(&old), id_then);
        assert_ne!(now.content_hash(), id_then);
    }

    #[test]
    fn textures_stored_before_the_reference_start_from_the_slab() {
        let mut old = TextureParams::default().to_flat();
        old.remove("initialisation");
        let loaded = TextureParams::from_stored(&old).unwrap();
        assert_eq!(loaded.analysis.initialisation, Initialisation::Slab);
        // The slab is the default and is not written: ids stay.
        assert!(
            !TextureParams::default()
                .to_flat()
                .contains_key("initialisation")
        );
        let reference = TextureParams::from_json(r#"{"initialisation": "reference"}"#).unwrap();
        assert_eq!(reference.analysis.initialisation, Initialisation::Reference);
        assert_eq!(reference.to_flat()["initialisation"], "reference");
    }

    #[test]
    fn params_objects_refuse_repeated_keys() {
        assert_eq!(params_object(r#"{"seed": 1}"#).unwrap()["seed"], 1);
        for bad in [
            r#"{"seed": 1, "seed": 1}"#,
            r#"{"field": {"kind": "slant", "angle": 30, "angle": 40}}"#,
            r#"{"field": {"kind": "sketch", "curves": [{"points": [], "points": []}]}}"#,
            "[1]",
            "7",
            "{",
        ] {
            assert_eq!(
                code(params_object(bad).unwrap_err()),
                "invalid_params",
                "{bad}"
            );
        }
    }

    #[test]
    fn id_syntax() {
        assert!(valid_id("default"));
        assert!(!valid_id(""));
        assert!(!valid_id("../etc"));
        assert!(!valid_id(&"a".repeat(65)));
    }
}
