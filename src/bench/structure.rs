//! The structure rows: what the quality preset and the global reference
//! cost beside the default, on the synthesis exemplar, in one run. The
//! quality preset starts every level from a block of the reference
//! optimised at precompute (docs/quality.md, "Structure"); its requests
//! cost what the default's do, its precompute minutes. The reference is
//! the non-lazy texture optimisation of a periodic block.

use super::{Predictor, Row, cold_row, load_average, measure, texture};
use solidtex_core::reference::{ReferenceParams, synthesize};
use solidtex_core::{
    AnalysisParams, Candidates, ExemplarSet, Layout, Orientation, Region, Request, Scheme,
};
use std::sync::Arc;

/// Rows of this module are named so, and the page gives them a section.
pub const ROW_PREFIX: &str = "structure";

/// Appends the rows: the quality preset's precompute; a cold 256² axis
/// slice and a cold 128³ volume for the default (`default`, already
/// precomputed) and the preset; the reference's 64³ and 128³ blocks.
pub(super) fn rows(
    set: &ExemplarSet,
    default: &Arc<Candidates>,
    levels: u32,
    predictor: &mut Predictor,
    rows: &mut Vec<Row>,
) -> anyhow::Result<()> {
    let size = format!("{}×{}", set.width(), set.height());
    let params = AnalysisParams {
        levels,
        ..AnalysisParams::quality()
    };
    let load = load_average();
    let m = measure(1, || Candidates::compute(set, &params, &|_, _| {}));
    let quality = Arc::new(m.value?);
    rows.push(one_run(
        format!("{ROW_PREFIX}: quality preset, precompute {size}"),
        m.seconds,
        m.peak_bytes,
        format!(
            ".stx {} KiB; the reference's blocks at every level; load average {load} at the start",
            quality.to_bytes().len() >> 10
        ),
    ));
    for (label, c) in [("default", default), ("quality preset", &quality)] {
        let requests = [
            (
                "axis slice 256² cold",
                Region::slice(solidtex_core::Axis::Z, 5, 0, 0, 256, 256),
            ),
            (
                "full volume 128³ cold",
                Region {
                    origin: [0, 0, 0],
                    size: [128; 3],
                },
            ),
        ];
        for (what, region) in requests {
            let tex = texture(c, Scheme::DualGrid);
            let load = load_average();
            let mut row = cold_row(
                format!("{ROW_PREFIX}: {label}: {what}"),
                Some(&tex.plan(&Request::region(region)?, 0)?),
                predictor,
                None,
                None,
                || Ok(tex.render(&Request::region(region)?, 0)?),
            )?;
            row.detail = format!("{}; load average {load} at the start", row.detail);
            rows.push(row);
        }
    }
    let layout = Layout::resolve(set, &Orientation::Auto)?;
    let laid = layout.apply(set)?;
    for side in [64, 128] {
        let defaults = ReferenceParams::default();
        let params = ReferenceParams {
            size: side,
            levels: ReferenceParams::default_levels(side, defaults.grid),
            ..defaults
        };
        let load = load_average();
        let m = measure(1, || {
            synthesize(&laid, layout.arrangement.weights, &params, |_| {})
        });
        m.value?;
        rows.push(one_run(
            format!("{ROW_PREFIX}: reference {side}³ (`solidtex reference --size {side}`)"),
            m.seconds,
            m.peak_bytes,
            format!(
                "a periodic block, {} levels; load average {load} at the start",
                params.levels
            ),
        ));
    }
    Ok(())
}

/// A row of one timed run, with no target or papers' figure.
fn one_run(name: String, seconds: f64, peak_bytes: u64, detail: String) -> Row {
    Row {
        name,
        seconds: Some(seconds),
        runs: 1,
        peak_bytes: Some(peak_bytes),
        target: None,
        paper: None,
        detail,
    }
}
