//! Crossbar search (Dong et al., "3D candidates selection"). For a pixel of
//! plane p, the two other planes' neighbourhoods meet p's neighbourhood along
//! two strips of N pixels; the S strips most similar to them are found with a
//! k-d tree over PCA-reduced strips (approximate nearest neighbours), and the
//! S² resulting triples are ranked by the full crossbar error (the three
//! pairwise strip differences).

use super::geometry::Dims;
use crate::appearance::{Pca, sq_dist};
use crate::stack::{GaussianStack, spacing};
use kiddo::SquaredEuclidean;
use rayon::prelude::*;
use std::num::NonZero;

/// Dimensions of the reduced strips the k-d trees index.
const STRIP_DIMS: usize = 6;
type StripTree = kiddo::ImmutableKdTree<f32, STRIP_DIMS>;

/// The u- and v-strips (horizontal and vertical runs of N pixels, spaced
/// h_k apart) through every pixel of one plane at one level.
pub struct Strips {
    /// Floats per strip, padded to a multiple of 8 for SIMD distances.
    len: usize,
    /// Meaningful floats per strip (3·N).
    raw: usize,
    /// `len` floats per pixel: the run along the image's u axis.
    pub u: Vec<f32>,
    /// `len` floats per pixel: the run along the image's v axis.
    pub v: Vec<f32>,
}

impl Strips {
    /// Extracts both strips of every pixel.
    pub fn new(stack: &GaussianStack, k: usize, n: u32) -> Strips {
        let (w, h) = (stack.width() as i64, stack.height() as i64);
        let r = (n / 2) as i64;
        let step = spacing(k) as i64;
        let raw = n as usize * 3;
        let len = raw.div_ceil(8) * 8;
        let mut u = Vec::with_capacity((w * h) as usize * len);
        let mut v = Vec::with_capacity((w * h) as usize * len);
        for y in 0..h {
            for x in 0..w {
                for t in -r..=r {
                    u.extend_from_slice(&stack.at(k, x + t * step, y));
                }
                u.resize(u.len() + len - raw, 0.0);
                for t in -r..=r {
                    v.extend_from_slice(&stack.at(k, x, y + t * step));
                }
                v.resize(v.len() + len - raw, 0.0);
            }
        }
        Strips { len, raw, u, v }
    }

    #[inline]
    fn u(&self, c: u32) -> &[f32] {
        &self.u[c as usize * self.len..(c as usize + 1) * self.len]
    }

    #[inline]
    fn v(&self, c: u32) -> &[f32] {
        &self.v[c as usize * self.len..(c as usize + 1) * self.len]
    }
}

/// A scored triple.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scored {
    /// Crossbar error.
    pub error: f32,
    /// Pixel indices in the xy, yz and zx exemplars.
    pub triple: [u32; 3],
}

fn reduce(pca: &Pca, strip: &[f32]) -> [f32; STRIP_DIMS] {
    let mut out = [0f32; STRIP_DIMS];
    pca.project(&strip[..pca.input], &mut out[..pca.dims]);
    out
}

fn tree(pca: &Pca, strips: &[f32], len: usize) -> StripTree {
    let pts: Vec<[f32; STRIP_DIMS]> = strips.chunks_exact(len).map(|s| reduce(pca, s)).collect();
    StripTree::new_from_slice(&pts)
}

/// Finds, for every pixel of plane `p`, its `keep` best triples by crossbar
/// error among the S² formed from the S nearest strips in the other two
/// planes. Results are sorted by (error, triple) so they are independent of
/// thread count.
pub fn search_plane(
    p: usize,
    strips: [&Strips; 3],
    dims: Dims,
    s: usize,
    keep: usize,
) -> Vec<Vec<Scored>> {
    let len = strips[0].len;
    // Plane q = p−1 meets p along p's u axis (q's v-strip), plane r = p+1
    // meets p along p's v axis (r's u-strip).
    let q = (p + 2) % 3;
    let r = (p + 1) % 3;
    let mut sample = Vec::new();
    let stride = (dims.len() / 4096).max(1);
    for st in strips {
        for c in (0..dims.len()).step_by(stride) {
            sample.extend_from_slice(&st.u(c as u32)[..st.raw]);
            sample.extend_from_slice(&st.v(c as u32)[..st.raw]);
        }
    }
    let raw = strips[0].raw;
    let pca = Pca::fit(&sample, raw, STRIP_DIMS.min(raw));
    let q_tree = tree(&pca, &strips[q].v, len);
    let r_tree = tree(&pca, &strips[r].u, len);
    let s = NonZero::new(s.min(dims.len())).expect("non-empty exemplar");

    (0..dims.len() as u32)
        .into_par_iter()
        .map(|c| {
            let pu = strips[p].u(c);
            let pv = strips[p].v(c);
            let mut qs: Vec<(f32, u32)> = q_tree
                .nearest_n::<SquaredEuclidean>(&reduce(&pca, pu), s)
                .into_iter()
                .map(|nn| (sq_dist(strips[q].v(nn.item as u32), pu), nn.item as u32))
                .collect();
            let mut rs: Vec<(f32, u32)> = r_tree
                .nearest_n::<SquaredEuclidean>(&reduce(&pca, pv), s)
                .into_iter()
                .map(|nn| (sq_dist(pv, strips[r].u(nn.item as u32)), nn.item as u32))
                .collect();
            qs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            rs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            best_pairs(p, c, &qs, &rs, strips, keep)
        })
        .collect()
}

/// Keeps the `keep` lowest-error triples from all (q, r) pairs; both lists
/// are sorted by their partial error so the pair loops stop early.
fn best_pairs(
    p: usize,
    c: u32,
    qs: &[(f32, u32)],
    rs: &[(f32, u32)],
    strips: [&Strips; 3],
    keep: usize,
) -> Vec<Scored> {
    let q = (p + 2) % 3;
    let r = (p + 1) % 3;
    let mut best: Vec<Scored> = Vec::with_capacity(keep + 1);
    let mut worst = f32::INFINITY;
    for &(e1, qc) in qs {
        if best.len() == keep && e1 + rs[0].0 >= worst {
            break;
        }
        let qu = strips[q].u(qc);
        for &(e2, rc) in rs {
            let partial = e1 + e2;
            if best.len() == keep && partial >= worst {
                break;
            }
            let e = partial + sq_dist(strips[r].v(rc), qu);
            if best.len() == keep && e >= worst {
                continue;
            }
            let mut triple = [0u32; 3];
            triple[p] = c;
            triple[q] = qc;
            triple[r] = rc;
            let item = Scored { error: e, triple };
            let pos = best
                .binary_search_by(|b| {
                    b.error
                        .total_cmp(&item.error)
                        .then(b.triple.cmp(&item.triple))
                })
                .unwrap_or_else(|x| x);
            best.insert(pos, item);
            if best.len() > keep {
                best.pop();
            }
            if best.len() == keep {
                worst = best[keep - 1].error;
            }
        }
    }
    best
}
