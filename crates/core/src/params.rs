//! Every tunable number of the method, in one place with its default and
//! its valid range. Analysis parameters shape the precomputed candidates;
//! synthesis parameters shape the voxels produced from them.

use crate::analysis::exemplar::ExemplarSet;
use crate::error::{Error, Result};
use crate::field::Field;
use serde::{Deserialize, Serialize};

pub mod knobs;

use knobs::{Before, Values, int, knobs, number};

knobs! {
    /// Parameters of the exemplar analysis and 3D candidate precomputation.
    #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
    #[serde(default, deny_unknown_fields)]
    pub struct AnalysisParams(Analysis, ANALYSIS_KNOBS) {
        neighbourhood: u32 = 5,
            Values::Integer { min: 3, max: 9, odd: true },
            "Neighbourhood side N (odd) of the exemplar analysis (the papers use 5).";
        pca_dims: u32 = 8,
            int(2, 16),
            "Appearance-space dimensions per exemplar pixel: the PCA of its N×N colour \
             neighbourhood (the papers use 8).";
        strips: u32 = 65,
            int(4, 256),
            "Most similar strips searched in each other exemplar for every pixel's 3D candidates \
             (Dong et al.: 65).";
        triples: u32 = 100,
            int(4, 1000),
            "Triples kept per pixel by crossbar error before the coherence filtering.";
        max_candidates: u32 = 12,
            int(1, 32),
            "3D candidates kept per pixel after the coherence filtering (Dong et al.: 12).";
        /// The synthesis starts at the coarsest level (L−3 with the
        /// default 4).
        levels: u32 = 4,
            int(1, 6),
            "Pyramid levels analysed; the synthesis starts at the coarsest.";
        similar_coarse: u32 = 4,
            int(1, 8),
            "2D candidates (most similar pixels) kept per exemplar pixel for the correction at the \
             coarse levels.";
        similar_fine: u32 = 2,
            int(1, 8),
            "2D candidates kept per exemplar pixel at the finest level.";
        /// See [`Orientation`].
        orientation: Orientation = Orientation::Auto,
            Values::Text { max_len: None, pattern: None, strict: false },
            "How the exemplar is laid on the three planes: `auto` (default) turns one plane a \
             quarter and weights the plane that cuts along the grain down when one exemplar for \
             all planes is square and strongly oriented along one of its axes, and leaves it as it \
             is otherwise; `none` shows it as it is on every plane; an arrangement is given as the \
             JSON text of an object (see `Arrangement`). The texture's `orientation` says what was \
             chosen.",
            before = Before::Value(r#""none""#);
        /// See `analysis::feature`. Off by default, since the
        /// channel found automatically made the shared exemplars'
        /// statistics worse (docs/quality.md); not written when 0, so
        /// textures without the channel keep their ids.
        #[serde(serialize_with = "shortest_f32", skip_serializing_if = "is_zero")]
        feature_weight: f32 = 0.0,
            number(0.0, 4.0),
            "Weight of the feature-distance channel in the appearance vectors, relative to the \
             exemplar's luminance: a signed distance to the edges of the exemplar's features: the \
             uploaded feature mask, or else the smaller side of its Otsu luminance threshold, found \
             automatically. 0 (default) matches colour alone. Not written into the texture's \
             parameters when 0.",
            before = Before::Value("0");
        /// See [`Initialisation`]. Not written when the slab, so textures
        /// that start from it keep their ids.
        #[serde(skip_serializing_if = "Initialisation::is_slab")]
        initialisation: Initialisation = Initialisation::Slab,
            Values::Choice(&["reference", "slab"]),
            "What the synthesis starts from: `slab` (default), the candidate slab of Dong et al.; \
             `reference`, a periodic block of the global reference (texture optimisation over a \
             whole block) optimised at precompute and tiled in cells at hashed offsets. Written \
             into the texture's parameters only when `reference`.",
            before = Before::Value(r#""slab""#);
        /// With a level, a request at or above it corrects only that
        /// level; `None` is cheap to precompute (the finer levels are
        /// upsampled and corrected as before).
        #[serde(skip_serializing_if = "Option::is_none")]
        reference_level: Option<u32> = None,
            int(0, 5),
            "With `initialisation=reference`, the finest level that starts from its own block of \
             the reference (at most `levels` − 1); every coarser level does too. Omitted: the \
             coarsest level only. 0 is the quality preset (every level; minutes of precompute and \
             larger stored candidates).";
    }
}

/// What the lazy synthesis's first version of a level is made from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, Hash)]
#[serde(rename_all = "kebab-case")]
pub enum Initialisation {
    /// A periodic block of the global reference (texture optimisation
    /// over a whole block, [`crate::reference`]), optimised once at
    /// precompute and tiled in Voronoi cells, each reading the block at
    /// its own hashed offset (not jittered: a warp would break the thin
    /// features the block holds). Its structure is three-dimensional
    /// from the start, so the correction refines a solid that already
    /// continues the exemplar in every plane.
    Reference,
    /// The candidate slab of Dong et al., tiled and jittered (the
    /// default: docs/quality.md measures the two).
    #[default]
    Slab,
}

impl Initialisation {
    /// Whether this is the slab (the default, not written).
    pub fn is_slab(&self) -> bool {
        *self == Initialisation::Slab
    }
}

impl std::fmt::Display for Initialisation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Initialisation::Reference => "reference",
            Initialisation::Slab => "slab",
        })
    }
}

impl std::str::FromStr for Initialisation {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "reference" => Ok(Initialisation::Reference),
            "slab" => Ok(Initialisation::Slab),
            _ => Err(Error::InvalidRequest(format!(
                "unknown initialisation `{s}` (expected reference or slab)"
            ))),
        }
    }
}

fn is_zero(v: &f32) -> bool {
    *v == 0.0
}

impl AnalysisParams {
    /// The quality preset: the reference kept at every level, so the
    /// finest level starts from the reference's own solid (see
    /// [`AnalysisParams::reference_level`]).
    pub fn quality() -> AnalysisParams {
        AnalysisParams {
            initialisation: Initialisation::Reference,
            reference_level: Some(0),
            ..AnalysisParams::default()
        }
    }

    /// The levels that start from a block of the reference, finest first
    /// (empty for the slab).
    pub fn reference_levels(&self) -> std::ops::RangeInclusive<u32> {
        let coarsest = self.levels - 1;
        match self.initialisation {
            Initialisation::Reference => self.reference_level.unwrap_or(coarsest)..=coarsest,
            #[allow(clippy::reversed_empty_ranges)]
            Initialisation::Slab => 1..=0,
        }
    }

    /// [`AnalysisParams::validate`], and that the parameters can use what
    /// `exemplars` bring: a feature mask needs the feature-distance channel
    /// (`feature_weight` above 0), which is the only thing that reads it.
    pub fn validate_for(&self, exemplars: &ExemplarSet) -> Result<()> {
        self.validate()?;
        if exemplars.has_feature_mask() && self.feature_weight <= 0.0 {
            return Err(Error::InvalidRequest(
                "a feature mask is only used by the feature-distance channel: \
                 give feature_weight above 0 with it"
                    .into(),
            ));
        }
        Ok(())
    }

    /// Checks every field against its range.
    pub fn validate(&self) -> Result<()> {
        knobs::check_ranges(knobs::Part::Analysis, &as_json(self)?)?;
        if let Orientation::Given(a) = &self.orientation {
            a.validate()?;
        }
        if let Some(level) = self.reference_level {
            range("reference_level", level, 0, self.levels - 1)?;
            if self.initialisation != Initialisation::Reference {
                return Err(Error::InvalidRequest(
                    "reference_level needs initialisation reference".into(),
                ));
            }
        }
        Ok(())
    }
}

/// How one exemplar is laid on the three planes. A strongly oriented
/// exemplar (grain, stripes) cannot show its orientation consistently in
/// all three planes: turning it a quarter for one plane lets two planes
/// agree, and the third, which cuts along the layers, counts less in the
/// matching (Zhang et al. §6.1).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Orientation {
    /// Measure the exemplar's orientation when the candidates are
    /// precomputed and, when it is strongly oriented along one of its axes,
    /// choose the arrangement `analysis::orientation` describes; otherwise
    /// as [`Orientation::None`].
    #[default]
    Auto,
    /// Every plane shows the exemplar as it is, all weighted alike.
    None,
    /// The arrangement given.
    Given(Arrangement),
}

/// Each plane's rotation of its exemplar and weight in the matching
/// (planes in the order xy, yz, zx).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Arrangement {
    /// Clockwise rotation of the plane's exemplar as displayed (u right, v
    /// down), in degrees: 0, 90, 180 or 270. 90 and 270 need a square
    /// exemplar (all planes share one size).
    pub rotate: [u32; 3],
    /// Weight of the plane's neighbourhood in the correction's matching,
    /// 0 to 1.
    #[serde(serialize_with = "shortest_f32s")]
    pub weights: [f32; 3],
}

impl Default for Arrangement {
    fn default() -> Self {
        Arrangement {
            rotate: [0; 3],
            weights: [1.0; 3],
        }
    }
}

impl Arrangement {
    /// Checks the rotations and weights.
    pub fn validate(&self) -> Result<()> {
        if let Some(r) = self
            .rotate
            .iter()
            .find(|r| !matches!(r, 0 | 90 | 180 | 270))
        {
            return Err(Error::InvalidRequest(format!(
                "orientation: rotate {r} is not 0, 90, 180 or 270 degrees"
            )));
        }
        for &w in &self.weights {
            range("orientation.weights", w, 0.0, 1.0)?;
        }
        if self.weights.iter().all(|&w| w == 0.0) {
            return Err(Error::InvalidRequest(
                "orientation: at least one plane weight must be above 0".into(),
            ));
        }
        Ok(())
    }
}

impl Serialize for Orientation {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            Orientation::Auto => s.serialize_str("auto"),
            Orientation::None => s.serialize_str("none"),
            Orientation::Given(a) => a.serialize(s),
        }
    }
}

impl<'de> Deserialize<'de> for Orientation {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct Visit;
        impl<'de> serde::de::Visitor<'de> for Visit {
            type Value = Orientation;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str(r#""auto", "none" or {"rotate": [...], "weights": [...]}"#)
            }
            fn visit_str<E: serde::de::Error>(
                self,
                v: &str,
            ) -> std::result::Result<Orientation, E> {
                v.parse().map_err(E::custom)
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                m: A,
            ) -> std::result::Result<Orientation, A::Error> {
                let a = Arrangement::deserialize(serde::de::value::MapAccessDeserializer::new(m))?;
                Ok(Orientation::Given(a))
            }
        }
        d.deserialize_any(Visit)
    }
}

impl std::str::FromStr for Orientation {
    type Err = Error;
    /// `auto`, `none`, or the JSON object of an [`Arrangement`] (so that a
    /// query string or a command-line flag can carry one).
    fn from_str(s: &str) -> Result<Self> {
        match s.trim() {
            "auto" => Ok(Orientation::Auto),
            "none" => Ok(Orientation::None),
            t if t.starts_with('{') => serde_json::from_str::<Arrangement>(t)
                .map(Orientation::Given)
                .map_err(|e| Error::InvalidRequest(format!("orientation: {e}"))),
            _ => Err(Error::InvalidRequest(format!(
                r#"unknown orientation `{s}` (expected auto, none or {{"rotate": [...], "weights": [...]}})"#
            ))),
        }
    }
}

/// How correction passes choose which version of each neighbour to read
/// (Zhang et al.'s history windows).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Hash)]
#[serde(rename_all = "kebab-case")]
pub enum Scheme {
    /// Dong et al.: every pass reads the latest version of every neighbour;
    /// the dependency chain grows with passes × subpasses.
    Standard,
    /// Zhang et al.: ⌈P/2⌉ passes on a primary grid of M³ cells then ⌊P/2⌋ on
    /// the dual grid; neighbours across a cell wall read the version the
    /// step started from, which bounds the dependency set.
    DualGrid,
}

impl std::str::FromStr for Scheme {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "standard" => Ok(Scheme::Standard),
            "dual-grid" | "dual_grid" | "dualgrid" => Ok(Scheme::DualGrid),
            _ => Err(Error::InvalidRequest(format!(
                "unknown scheme `{s}` (expected standard or dual-grid)"
            ))),
        }
    }
}

/// Which voxels a correction reads (see [`SynthParams::slices`]). One
/// value is left: `full` slices belonged to the colour correction, which
/// is gone; the key stays so that texture ids do not change.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, Hash)]
#[serde(rename_all = "kebab-case", try_from = "String")]
pub enum Slices {
    /// Only the direct neighbours: the dependency radius is 1.
    #[default]
    Sparse,
}

impl TryFrom<String> for Slices {
    type Error = Error;
    fn try_from(s: String) -> Result<Self> {
        s.parse()
    }
}

impl std::str::FromStr for Slices {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "sparse" => Ok(Slices::Sparse),
            "full" => Err(Error::InvalidRequest(
                "slices `full` was removed with the colour correction (only sparse is left)".into(),
            )),
            _ => Err(Error::InvalidRequest(format!(
                "unknown slices `{s}` (expected sparse)"
            ))),
        }
    }
}

/// What a correction matches (see [`SynthParams::correction`]). One value
/// is left: the colour correction (N×N colour neighbourhoods projected per
/// query, Dong et al.) lost to this one on every measure and is gone; the
/// key stays so that texture ids do not change.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, Hash)]
#[serde(rename_all = "kebab-case", try_from = "String")]
pub enum Correction {
    /// Sparse appearance-space neighbourhoods (Lin 2009 §3.4.3, after
    /// Lefebvre and Hoppe 2006): in each plane the appearance vectors at
    /// the 4 diagonal locations, each averaged over the 3 direct
    /// neighbours that predict it; candidates by k-coherence.
    #[default]
    Appearance,
}

impl std::fmt::Display for Correction {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Correction::Appearance => "appearance",
        })
    }
}

impl TryFrom<String> for Correction {
    type Error = Error;
    fn try_from(s: String) -> Result<Self> {
        s.parse()
    }
}

impl std::str::FromStr for Correction {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "appearance" => Ok(Correction::Appearance),
            "colour" | "color" => Err(Error::InvalidRequest(
                "the colour correction was removed (only appearance is left)".into(),
            )),
            _ => Err(Error::InvalidRequest(format!(
                "unknown correction `{s}` (expected appearance)"
            ))),
        }
    }
}

/// How the candidate slab is cut into pieces for tiling, each piece with
/// its own hashed offset (see [`SynthParams::slab_tiling`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, Hash)]
#[serde(rename_all = "kebab-case")]
pub enum SlabTiling {
    /// Axis-aligned squares. Each copies one region of the exemplar, and
    /// the correction mends their seams only locally: the squares, with
    /// their straight borders and the brightness of the region each copied,
    /// stay visible in the result (docs/quality.md). Textures stored before
    /// cells keep them.
    Blocks,
    /// Cells of a jittered 3D grid as large as the blocks (a Voronoi
    /// partition of hashed sites), cut by the slab layers: borders at
    /// every angle, none on an axis.
    #[default]
    Cells,
}

impl std::fmt::Display for SlabTiling {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            SlabTiling::Blocks => "blocks",
            SlabTiling::Cells => "cells",
        })
    }
}

impl std::str::FromStr for SlabTiling {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "blocks" => Ok(SlabTiling::Blocks),
            "cells" => Ok(SlabTiling::Cells),
            _ => Err(Error::InvalidRequest(format!(
                "unknown slab tiling `{s}` (expected cells or blocks)"
            ))),
        }
    }
}

knobs! {
    /// Parameters of the synthesis itself; changing them changes the voxels
    /// but not the precomputed candidates. Defaults marked measured were
    /// chosen on the shared exemplars (docs/quality.md).
    #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
    #[serde(default, deny_unknown_fields)]
    pub struct SynthParams(Synthesis, SYNTH_KNOBS) {
        seed: u64 = 1,
            int(0, u64::MAX),
            "Random seed of the synthesis, hashed with level and position for every random choice.";
        passes: u32 = 2,
            int(0, 6),
            "Correction passes per level, the fine levels excepted (see `fine_levels`).";
        /// Each pass there widens a request's dependency set by the
        /// subpass chains of a whole level at full resolution, while the
        /// coarse passes have already settled which exemplar patches the
        /// voxels continue.
        finest_passes: u32 = 1,
            int(0, 6),
            "Correction passes at the fine levels (see `fine_levels`). A pass there costs far more \
             than a coarse one (every pass widens a request's dependency set at full resolution); \
             one pass keeps most of the quality of two for about half the work of a cold slice.",
            before = Before::SameAs("passes");
        /// Measured: level 1's two passes cost a cold 256² slice more
        /// corrections than level 0, so one pass there too makes cold
        /// slices much faster for a little patch coherence.
        fine_levels: u32 = 2,
            int(1, 16),
            "How many levels, counted from the finest, are corrected with `finest_passes` passes \
             instead of `passes`. Each pass at a level widens a request's dependency set there and \
             at every coarser level.",
            before = Before::Value("1");
        /// Measured: the finest level's chains are the largest part of a
        /// cold slice, and it changes the least; the coarser levels, which
        /// lay out the structure, converge better with blocks.
        parity_levels: u32 = 1,
            int(0, 16),
            "How many levels, counted from the finest, correct each pass in two parity subpasses \
             (coordinate sums even, then odd) instead of s³ block subpasses (see `subpass_side`). \
             A voxel's chain steps back once through parity subpasses, so a cold slice needs its \
             own plane and half of each plane beside it at those levels, whatever its axis; block \
             subpasses reach up to five planes but converge better at the coarser levels. Textures \
             stored before it keep 0.",
            before = Before::Value("0");
        subpass_side: u32 = 2,
            int(1, 3),
            "Block side s of the block subpasses: s³ subpasses per pass (2 gives 8; 1 corrects \
             every voxel of a pass at once).";
        scheme: Scheme = Scheme::DualGrid,
            Values::Choice(&["standard", "dual-grid"]),
            "Correction scheme: `dual-grid` (Zhang et al.: passes alternate between a primary grid \
             of cells and its dual, and a correction reads across a cell wall the version its step \
             started from, which bounds a request's dependency set) or `standard` (Dong et al.: \
             every correction reads the latest version of its neighbours).";
        grid: u32 = 12,
            int(4, 64),
            "Cell side M of the dual-grid scheme, in voxels of the level.";
        #[serde(serialize_with = "shortest_f32")]
        jitter: f32 = 1.0,
            number(0.0, 4.0),
            "Jitter strength (0 disables it).";
        correct_init_level: bool = true,
            Values::Flag,
            "Also correct the coarsest synthesized level after the jitter.";
        /// Measured. A voxel's colour is the mean of three exemplar
        /// colours, so synthesized neighbourhoods are flatter than the
        /// exemplar's and, matched as they are, pick its calm regions:
        /// rare dark or bright features fade.
        #[serde(serialize_with = "shortest_f32")]
        contrast: f32 = 1.6,
            number(1.0, 4.0),
            "Gain on each correction's query around its mean colour (1 disables it): on each \
             appearance-space location around the flat neighbourhood of its mean colour.";
        slices: Slices = Slices::Sparse,
            Values::Choice(&["sparse"]),
            "Voxels a correction reads: `sparse`, its direct neighbours (dependency radius 1), is \
             the only value left; `full` went with the colour correction. Kept so that texture ids \
             do not change.",
            flag = false,
            before = Before::Value(r#""full""#);
        /// Measured; in units of a quantised neighbourhood distance of one
        /// colour level per squared colour difference.
        #[serde(serialize_with = "shortest_f32")]
        consistency: f32 = 32.0,
            number(0.0, 1024.0),
            "Penalty on coherent triples whose three exemplar colours disagree (0 disables it). \
             Without it, a feature that only one plane's exemplar has is extruded along that \
             plane's normal into straight streaks on the other planes.",
            before = Before::Value("0");
        /// Measured. Within a layer a voxel's xy coordinate does not
        /// change along z, so an N-thick layer starts every x and y slice
        /// with features extruded N coarse voxels (8N finest voxels) along
        /// z, which the correction only partly removes; one-voxel layers
        /// start those slices isotropic.
        slab_thickness: u32 = 1,
            int(1, 9),
            "Thickness of the candidate slab's layers that initialise the coarsest synthesized \
             level, in voxels of that level (Dong et al. use N). Thick layers extrude features \
             along z into x and y slices.",
            before = Before::SameAs("neighbourhood");
        slab_tiling: SlabTiling = SlabTiling::default(),
            Values::Choice(&["cells", "blocks"]),
            "How the candidate slab is cut into pieces, each tiled with its own hashed offset: \
             `cells` (a jittered grid, borders at every angle) or `blocks` (axis-aligned squares, \
             whose outlines stay visible as square blocks). Textures stored before `cells` keep \
             `blocks`.",
            before = Before::Value(r#""blocks""#);
        correction: Correction = Correction::default(),
            Values::Choice(&["appearance"]),
            "What a correction matches: `appearance`, sparse appearance-space neighbourhoods (in \
             each plane the appearance vectors at the 4 diagonal locations, each averaged over the \
             3 direct neighbours that predict it; candidates by k-coherence), is the only value \
             left: the colour correction was removed. Kept so that texture ids do not change.",
            flag = false,
            before = Before::Value(r#""colour""#);
        /// See [`Field`]; none keeps every voxel's frame on the world axes.
        #[serde(
            skip_serializing_if = "Option::is_none",
            deserialize_with = "field_or_text"
        )]
        field: Option<Field> = None,
            Values::Text { max_len: Some(4096), pattern: None, strict: false },
            "A field of local frames that the texture follows (docs/fields.md): a preset in short, \
             `slant:ANGLE`, `circular[:CX,CY]`, `emissive[:CX,CY]`, `zigzag:ANGLE,PERIOD` or \
             `slant3d:DX,DY,DZ` (angles in degrees, positions and lengths in voxels of the finest \
             level), or the JSON text of a `Field` object. Part of the texture's id. Omitted: no \
             field. A request target is at most 8 KiB: a long sketch goes in the `params` form \
             field instead.";
        /// See [`crate::period`]: each side a multiple of
        /// [`crate::period::multiple`]. Not written when none, so
        /// aperiodic textures keep their ids.
        #[serde(
            skip_serializing_if = "Option::is_none",
            deserialize_with = "crate::period::deserialize"
        )]
        period: Option<[u32; 3]> = None,
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
             `subpass_side` 3). Part of the texture's id. Omitted: the solid has no period.";
    }
}

impl SynthParams {
    /// Parameters for previews and interactive cutting: one correction
    /// pass per level, and the finest level upsampled from level 1 without
    /// correction. A cold slice needs a quarter to an eighth of the
    /// defaults' corrections (BENCHMARKS.md). The price is worse patch
    /// coherence and visibly more broken-up features on spotted or blocky
    /// exemplars (docs/quality.md). Their voxels differ from the
    /// defaults', as any other parameter change makes them.
    pub fn preview() -> SynthParams {
        SynthParams {
            passes: 1,
            finest_passes: 0,
            fine_levels: 1,
            ..SynthParams::default()
        }
    }

    /// Dong et al.'s own schedule: every level corrected with two passes
    /// of 8 block subpasses under the standard scheme. About 2.2× the
    /// defaults' cold time for cleaner spots, longer veins and closed
    /// crack cells on structured exemplars; grain across wood and leather
    /// comes out more blotchy (docs/quality.md, "The papers' own
    /// settings").
    pub fn structured() -> SynthParams {
        SynthParams {
            scheme: Scheme::Standard,
            passes: 2,
            finest_passes: 2,
            fine_levels: 1,
            parity_levels: 0,
            ..SynthParams::default()
        }
    }

    /// Checks every field against its range.
    pub fn validate(&self) -> Result<()> {
        knobs::check_ranges(knobs::Part::Synthesis, &as_json(self)?)?;
        if let Some(field) = &self.field {
            field.validate()?;
        }
        if let Some(period) = self.period {
            for side in period {
                range("period", side, 1, crate::period::MAX_PERIOD)?;
            }
        }
        Ok(())
    }
}

/// Writes an `f32` as the shortest decimal that reads back to it (`1.6`,
/// not the `1.600000023841858` of its exact `f64` value).
fn shortest_f32<S: serde::Serializer>(v: &f32, s: S) -> std::result::Result<S::Ok, S::Error> {
    s.serialize_f64(v.to_string().parse().unwrap_or(*v as f64))
}

fn shortest_f32s<S: serde::Serializer>(v: &[f32; 3], s: S) -> std::result::Result<S::Ok, S::Error> {
    use serde::ser::SerializeTuple;
    let mut t = s.serialize_tuple(3)?;
    for x in v {
        t.serialize_element(&x.to_string().parse::<f64>().unwrap_or(*x as f64))?;
    }
    t.end()
}

/// A field as its JSON object or as text (a preset's short form or the
/// object's JSON), which is how query strings and the command line give it.
fn field_or_text<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> std::result::Result<Option<Field>, D::Error> {
    use serde::de::Error as _;
    match serde_json::Value::deserialize(d)? {
        serde_json::Value::Null => Ok(None),
        // Its numbers are checked with the other parameters'.
        serde_json::Value::String(s) => Field::from_text(&s).map(Some).map_err(D::Error::custom),
        v => serde_json::from_value(v)
            .map(Some)
            .map_err(D::Error::custom),
    }
}

/// Parameters as their JSON object, which [`knobs::check_ranges`] reads.
fn as_json<T: Serialize>(params: &T) -> Result<serde_json::Value> {
    serde_json::to_value(params).map_err(|e| Error::InvalidRequest(e.to_string()))
}

/// Checks `min ≤ v ≤ max` (NaN fails the test and is refused too).
fn range<T: PartialOrd + Into<f64> + Copy>(name: &'static str, v: T, min: T, max: T) -> Result<()> {
    if (min..=max).contains(&v) {
        Ok(())
    } else {
        Err(Error::InvalidRange {
            name,
            value: v.into(),
            min: min.into(),
            max: max.into(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fractional_parameters_read_as_written() {
        let p = SynthParams {
            contrast: 1.6,
            jitter: 0.3,
            ..SynthParams::default()
        };
        let json = serde_json::to_string(&p).unwrap();
        assert!(json.contains(r#""contrast":1.6,"#), "{json}");
        assert!(json.contains(r#""jitter":0.3,"#), "{json}");
        assert_eq!(serde_json::from_str::<SynthParams>(&json).unwrap(), p);
    }

    #[test]
    fn feature_weights_out_of_range_are_refused() {
        for (w, ok) in [
            (0.0, true),
            (0.5, true),
            (4.0, true),
            (-0.5, false),
            (4.5, false),
            (f32::NAN, false),
        ] {
            let a = AnalysisParams {
                feature_weight: w,
                ..AnalysisParams::default()
            };
            assert_eq!(a.validate().is_ok(), ok, "{w}");
        }
    }

    #[test]
    fn the_removed_correction_and_slices_are_refused_by_name() {
        for (text, removed) in [("colour", true), ("color", true), ("dense", false)] {
            let e = text.parse::<Correction>().unwrap_err().to_string();
            assert_eq!(e.contains("removed"), removed, "{e}");
        }
        assert!(
            "full"
                .parse::<Slices>()
                .unwrap_err()
                .to_string()
                .contains("removed")
        );
        assert!(serde_json::from_str::<SynthParams>(r#"{"correction": "colour"}"#).is_err());
        assert!(serde_json::from_str::<SynthParams>(r#"{"slices": "full"}"#).is_err());
        let json = serde_json::to_string(&SynthParams::default()).unwrap();
        assert!(
            json.contains(r#""slices":"sparse""#) && json.contains(r#""correction":"appearance""#)
        );
    }

    #[test]
    fn orientations_read_as_written_and_bad_ones_are_refused() {
        let given = |rotate, weights| Orientation::Given(Arrangement { rotate, weights });
        let quarter = given([0, 270, 0], [1.0, 1.0, 0.25]);
        for (text, want) in [
            (r#""auto""#, Orientation::Auto),
            (r#""none""#, Orientation::None),
            (
                r#"{"rotate": [0, 270, 0], "weights": [1, 1, 0.25]}"#,
                quarter,
            ),
            // Either key may be left out.
            (r#"{"rotate": [90, 0, 0]}"#, given([90, 0, 0], [1.0; 3])),
            (
                r#"{"weights": [1, 0.5, 1]}"#,
                given([0; 3], [1.0, 0.5, 1.0]),
            ),
            // A query string or a flag carries the object as text.
            (
                r#""{\"rotate\": [0, 270, 0], \"weights\": [1, 1, 0.25]}""#,
                quarter,
            ),
        ] {
            let o: Orientation = serde_json::from_str(text).unwrap();
            assert_eq!(o, want, "{text}");
            let p = AnalysisParams {
                orientation: o,
                ..AnalysisParams::default()
            };
            p.validate().unwrap();
            let json = serde_json::to_string(&p).unwrap();
            assert_eq!(serde_json::from_str::<AnalysisParams>(&json).unwrap(), p);
        }
        let json = serde_json::to_string(&quarter).unwrap();
        assert_eq!(json, r#"{"rotate":[0,270,0],"weights":[1.0,1.0,0.25]}"#);
        assert_eq!("auto".parse::<Orientation>().unwrap(), Orientation::Auto);
        assert_eq!(AnalysisParams::default().orientation, Orientation::Auto);

        // Not JSON that names an orientation: refused when read.
        for text in [
            r#""sideways""#,
            r#"{"turn": [0, 0, 0]}"#,
            r#"{"rotate": [0, 90]}"#,
            r#"{"weights": "1,1,1"}"#,
            "3",
        ] {
            assert!(serde_json::from_str::<Orientation>(text).is_err(), "{text}");
        }
        // Read, but out of range: refused by validation.
        let invalid = |o: Orientation| {
            AnalysisParams {
                orientation: o,
                ..AnalysisParams::default()
            }
            .validate()
            .unwrap_err()
        };
        assert!(matches!(
            invalid(given([0, 45, 0], [1.0; 3])),
            Error::InvalidRequest(_)
        ));
        for weights in [[1.0, 2.0, 1.0], [1.0, 1.0, -0.1], [f32::NAN, 1.0, 1.0]] {
            assert!(
                matches!(
                    invalid(given([0; 3], weights)),
                    Error::InvalidRange {
                        name: "orientation.weights",
                        ..
                    }
                ),
                "{weights:?}"
            );
        }
        assert!(matches!(
            invalid(given([0; 3], [0.0; 3])),
            Error::InvalidRequest(_)
        ));
    }

    #[test]
    fn synthesis_parameters_outside_their_ranges_are_refused() {
        assert!(SynthParams::default().validate().is_ok());
        for contrast in [0.5, 4.5, f32::NAN] {
            let p = SynthParams {
                contrast,
                ..SynthParams::default()
            };
            assert!(
                matches!(
                    p.validate(),
                    Err(Error::InvalidRange {
                        name: "contrast",
                        ..
                    })
                ),
                "contrast {contrast} accepted"
            );
        }
        type Setter = fn(&mut SynthParams);
        let bad: [(Setter, &str); 8] = [
            (|p| p.passes = 7, "passes"),
            (|p| p.finest_passes = 7, "finest_passes"),
            (|p| p.fine_levels = 0, "fine_levels"),
            (|p| p.fine_levels = 17, "fine_levels"),
            (|p| p.consistency = -1.0, "consistency"),
            (|p| p.consistency = f32::NAN, "consistency"),
            (|p| p.slab_thickness = 0, "slab_thickness"),
            (|p| p.slab_thickness = 10, "slab_thickness"),
        ];
        for (set, name) in bad {
            let mut p = SynthParams::default();
            set(&mut p);
            assert!(
                matches!(p.validate(), Err(Error::InvalidRange { name: n, .. }) if n == name),
                "{name} accepted: {p:?}"
            );
        }
    }
}
