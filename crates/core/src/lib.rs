//! solidtex: infinite, spatially deterministic solid textures synthesized
//! lazily from 2D exemplars (Dong et al. 2008, Zhang et al. 2011).
//!
//! Data flows one way: [`Exemplar`]s → [`Candidates`] (Gaussian stack,
//! appearance vectors, 3D candidate triples; computed once and saved as
//! `.stx`) → [`Texture`] (pyramid synthesis of exactly the voxels a request
//! depends on, in level-aligned tiles kept in a shared [`TileCache`]).
//!
//! A voxel's colour is a pure function of (candidates, synthesis parameters,
//! integer position): request shape, thread count and cache state never
//! change a byte.
#![deny(unsafe_code)]
#![warn(missing_docs)]

mod analysis;
pub mod bundled;
mod candidates;
mod error;
pub mod eval;
pub mod export;
mod field;
pub mod hash;
pub mod mesh;
mod params;
pub mod period;
pub mod png;
pub mod reference;
pub mod region;
mod request;
mod simd;
mod synth;
mod texture;

pub use analysis::exemplar::{Exemplar, ExemplarSet};
pub use analysis::orientation::{Grain, Layout};
pub use candidates::{Candidates, PrecomputeReport, Stage};
pub use error::{CorruptKind, Error, Result};
pub use field::{Along, Curve, Field, Sketch};
pub use params::{
    AnalysisParams, Arrangement, Correction, Initialisation, Orientation, Scheme, SlabTiling,
    Slices, SynthParams, knobs,
};
pub use request::{
    Axis, COORD_LIMIT, Cut, CutPlane, Filter, MAX_REGION_VOXELS, MAX_SLICE_SIDE, Region, Request,
    RequestKind, Slice, Window,
};
pub use synth::cache::{CacheStats, TileCache};
pub use synth::cancel::{CancelFlag, Cancelled, run_cancellable};
pub use synth::estimate::WorkEstimate;
pub use synth::{SlabViews, SynthStats};
pub use texture::Texture;
