//! Precomputation (API placeholder while the engine lands).
use crate::error::Result;
use crate::exemplar::ExemplarSet;
use crate::params::AnalysisParams;

/// Stages of the precomputation, for progress reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// Gaussian stacks and appearance vectors.
    Analysis,
    /// Strip search and crossbar errors.
    Search,
    /// Coherence filtering.
    Coherence,
    /// Slab and neighbourhood vectors.
    Finish,
}

/// Summary of a precomputation.
#[derive(Clone, Debug, Default)]
pub struct PrecomputeReport {}

/// Precomputed candidate data of one texture.
pub struct Candidates {
    exemplars: ExemplarSet,
    params: AnalysisParams,
}

impl Candidates {
    /// Runs the precomputation; `progress(stage, fraction 0..1)`.
    pub fn compute(
        _exemplars: &ExemplarSet,
        _params: &AnalysisParams,
        _progress: &(dyn Fn(Stage, f32) + Sync),
    ) -> Result<Candidates> {
        todo!()
    }
    /// Writes the `.stx` form.
    pub fn save(&self, _w: &mut dyn std::io::Write) -> Result<()> {
        todo!()
    }
    /// Reads the `.stx` form.
    pub fn load(_bytes: &[u8]) -> Result<Candidates> {
        todo!()
    }
    /// The exemplars.
    pub fn exemplars(&self) -> &ExemplarSet {
        &self.exemplars
    }
    /// The analysis parameters.
    pub fn params(&self) -> &AnalysisParams {
        &self.params
    }
}
