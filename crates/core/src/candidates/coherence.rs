//! Coherence filtering (Dong et al., "Triples of coherent candidates"): a
//! triple of pixel P in plane p survives only if each of its two foreign
//! coordinates is continued by some candidate of a neighbouring pixel
//! P ± h·e (e a unit step in p's plane): that candidate's coordinate in the
//! same plane must equal this one moved by the same 3D step. Such triples
//! can grow coherent 3D patches during synthesis. Removal is simultaneous
//! per iteration, so the result does not depend on visiting order.

use super::geometry::{AXES, Dims, project};
use super::search::Scored;
use crate::synth::cancel::CancelFlag;
use rayon::prelude::*;

/// Dong et al. report about two iterations; removal cascades slowly after
/// that, so the filter stops here and keeps the best `max` of what is left.
const MAX_ITERATIONS: usize = 3;

/// Outcome of filtering one plane at one level.
pub struct Filtered {
    /// Surviving triples per pixel, best first, at most `max` each.
    pub lists: Vec<Vec<Scored>>,
    /// Pixels where nothing survived and the best triple was kept instead.
    pub fallbacks: usize,
    /// Iterations run.
    pub iterations: usize,
}

/// Filters `lists` (candidates of every pixel of plane `p`, sorted by
/// error) until every pixel has at most `max` or nothing changes. Unwinds
/// out (between iterations) once `cancel` is set.
pub fn filter(
    p: usize,
    lists: Vec<Vec<Scored>>,
    dims: Dims,
    h: i64,
    max: usize,
    cancel: Option<&CancelFlag>,
) -> Filtered {
    // The four unit steps in plane p: each one's move in p (to the
    // neighbouring pixel) and in every plane (for the coordinate there).
    let (a, b) = AXES[p];
    let steps: [Step; 4] = std::array::from_fn(|i| {
        let mut d = [0i64; 3];
        d[[a, b][i / 2]] = [-1, 1][i % 2];
        [0, 1, 2].map(|j| {
            let (u, v) = project(j, d);
            (u * h, v * h)
        })
    });
    let original: Vec<Option<Scored>> = lists.iter().map(|l| l.first().copied()).collect();
    let mut lists = lists;
    let mut iterations = 0;
    while iterations < MAX_ITERATIONS && lists.iter().any(|l| l.len() > max) {
        if let Some(f) = cancel {
            f.unwind_if_set();
        }
        iterations += 1;
        // Per pixel and foreign plane, the sorted coordinates its
        // candidates use (plane p's own coordinate is the pixel itself).
        let coords: Vec<[Vec<u32>; 3]> = lists
            .par_iter()
            .map(|l| {
                let mut out: [Vec<u32>; 3] = Default::default();
                for (j, o) in out.iter_mut().enumerate() {
                    if j == p {
                        continue;
                    }
                    *o = l.iter().map(|s| dims.snap(s.triple[j], h as u32)).collect();
                    o.sort_unstable();
                    o.dedup();
                }
                out
            })
            .collect();
        // The test reads `coords`, taken before any removal, so filtering
        // in place is still simultaneous. Every list must be filtered: a
        // reduction, not a short-circuiting `any`.
        let changed = lists
            .par_iter_mut()
            .enumerate()
            .map(|(c, l)| {
                let before = l.len();
                let neighbours = steps.map(|st| {
                    let (du, dv) = st[p];
                    dims.shift(c as u32, du, dv)
                });
                l.retain(|s| coherent(p, s.triple, &neighbours, &coords, &steps, dims, h));
                l.len() != before
            })
            .reduce(|| false, |a, b| a || b);
        if !changed {
            break;
        }
    }
    let mut fallbacks = 0;
    for (l, orig) in lists.iter_mut().zip(&original) {
        if let (true, Some(o)) = (l.is_empty(), orig) {
            l.push(*o);
            fallbacks += 1;
        }
        l.truncate(max);
    }
    Filtered {
        lists,
        fallbacks,
        iterations,
    }
}

/// A unit step of plane p, as (u, v) moves of `h` pixels in each plane.
type Step = [(i64, i64); 3];

/// Whether both foreign coordinates of triple `t` are continued by a
/// candidate of one of the pixel's `neighbours` (one per step).
fn coherent(
    p: usize,
    t: [u32; 3],
    neighbours: &[u32; 4],
    coords: &[[Vec<u32>; 3]],
    steps: &[Step; 4],
    dims: Dims,
    h: i64,
) -> bool {
    (0..3).filter(|&j| j != p).all(|j| {
        steps.iter().zip(neighbours).any(|(st, &neighbour)| {
            let (ju, jv) = st[j];
            let want = dims.shift(t[j], ju, jv);
            coords[neighbour as usize][j]
                .binary_search(&dims.snap(want, h as u32))
                .is_ok()
        })
    })
}
