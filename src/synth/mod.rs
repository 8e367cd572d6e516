//! Synthesis (API placeholder while the engine lands).
pub mod cache;
use crate::candidates::Candidates;
use crate::error::Result;
use crate::params::SynthParams;
use crate::texture::{CutPlane, Filter, Region, SynthStats};
use cache::TileCache;
use std::sync::Arc;

pub(crate) struct Engine {
    candidates: Arc<Candidates>,
    params: SynthParams,
    _cache: Arc<TileCache>,
}

impl Engine {
    pub(crate) fn new(candidates: Arc<Candidates>, params: SynthParams, cache: Arc<TileCache>) -> Self {
        Engine { candidates, params, _cache: cache }
    }
    pub(crate) fn candidates(&self) -> &Candidates { &self.candidates }
    pub(crate) fn params(&self) -> &SynthParams { &self.params }
    pub(crate) fn max_lod(&self) -> u32 { 3 }
    pub(crate) fn region_rgb(&self, _r: &Region, _lod: u32) -> Result<(Vec<u8>, SynthStats)> { todo!() }
    pub(crate) fn cut_rgb(&self, _p: &CutPlane, _lod: u32, _f: Filter) -> Result<(Vec<u8>, SynthStats)> { todo!() }
    pub(crate) fn points_rgb(&self, _p: &[[i64; 3]], _lod: u32) -> Result<(Vec<[u8; 3]>, SynthStats)> { todo!() }
}
