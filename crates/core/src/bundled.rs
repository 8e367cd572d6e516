//! The bundled default exemplar and its precomputed candidates, embedded in
//! the binary so that the default texture answers at once on a fresh data
//! directory, and the CLI needs no precompute without an exemplar.
//!
//! The candidates are exactly what [`Candidates::compute`] makes of the
//! exemplar with the default analysis parameters (a test checks it; after a
//! change to the analysis, regenerate them from the repository root with
//! `solidtex precompute crates/core/assets/default.png -o
//! crates/core/assets/default.stx`). They are only used when the exemplar
//! and parameters asked for are those, so they can never stand in for
//! another texture's.

use crate::{AnalysisParams, Candidates, Exemplar, ExemplarSet};

/// The bundled exemplar, PNG-encoded.
pub const EXEMPLAR_PNG: &[u8] = include_bytes!("../assets/default.png");

/// Its candidates for the default analysis parameters, as a `.stx` file.
const CANDIDATES_STX: &[u8] = include_bytes!("../assets/default.stx");

/// The bundled exemplar.
pub fn exemplar() -> Exemplar {
    Exemplar::decode(EXEMPLAR_PNG).expect("the bundled exemplar decodes")
}

/// The bundled candidates, when `set` and `params` are the ones they were
/// computed from; `None` otherwise (compute them).
pub fn candidates_for(set: &ExemplarSet, params: &AnalysisParams) -> Option<Candidates> {
    if params != &AnalysisParams::default() || set != &ExemplarSet::single(exemplar()) {
        return None;
    }
    let c = Candidates::load(CANDIDATES_STX).ok()?;
    // The file carries its own exemplar and parameters: trust it only when
    // they are the ones asked for.
    (c.exemplars() == set && c.params() == params).then_some(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bundled_candidates_are_what_precompute_makes() {
        let set = ExemplarSet::single(exemplar());
        let params = AnalysisParams::default();
        let computed = Candidates::compute(&set, &params, &|_, _| {}).unwrap();
        assert!(
            computed.to_bytes() == CANDIDATES_STX,
            "crates/core/assets/default.stx is stale: regenerate it with \
             `solidtex precompute crates/core/assets/default.png -o crates/core/assets/default.stx`"
        );
        assert!(candidates_for(&set, &params).is_some());
        let other = AnalysisParams {
            levels: 3,
            ..AnalysisParams::default()
        };
        assert!(candidates_for(&set, &other).is_none());
    }
}
