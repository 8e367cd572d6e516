//! The global reference: a non-lazy, quality-first synthesis of a periodic
//! block by texture optimisation (Kopf et al. 2007, "Solid texture
//! synthesis from 2D exemplars"), with the discrete solver and the position
//! histogram of Chen & Wang 2010 ("High quality solid texture synthesis
//! using position and index histogram matching").
//!
//! The energy is the sum, over a sparse grid of voxels and the three
//! orthogonal slices through each, of ‖s − e‖^r: the slice's N×N
//! neighbourhood against its nearest exemplar neighbourhood, r = 0.8. Each
//! iteration alternates a search (every neighbourhood's nearest exemplar
//! neighbourhood, in PCA space) and an optimisation: every voxel is set
//! from the exemplar colours that the neighbourhoods overlapping it
//! predict, weighted by ‖s − e‖^(r−2) (iteratively reweighted least
//! squares), and by two histogram terms that push the block's statistics
//! back to the exemplar's: its colour histogram (over a palette of the
//! exemplar's colours) and the usage of exemplar positions, so over-used
//! calm pixels lose weight and rare vein or crack pixels gain it. The
//! discrete solver then copies the exemplar colour nearest the weighted
//! mean instead of writing the mean, which keeps features sharp.
//! Coarse to fine over a Gaussian stack: level k's voxels stand for 2^k
//! finest voxels and read the exemplar blurred and sampled 2^k apart.
//!
//! Every index wraps around the block, so the result tiles seamlessly.
//! Randomness hashes (seed, level, iteration, position): the block does not
//! depend on the thread count.

pub(crate) mod palette;

use crate::analysis::appearance::{Pca, Projector};
use crate::analysis::exemplar::ExemplarSet;
use crate::analysis::stack::{GaussianStack, spacing};
use crate::candidates::geometry::AXES;
use crate::error::{Error, Result};
use crate::hash::hash_pos;
use kiddo::SquaredEuclidean;
use palette::Palette;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Dimensions of the PCA-reduced neighbourhoods the search compares.
const DIMS: usize = 16;
type Tree = kiddo::ImmutableKdTree<f32, DIMS>;

/// Parameters of the reference synthesis.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ReferenceParams {
    /// Side of the periodic block in finest voxels; a multiple of
    /// 2^(levels − 1).
    pub size: u32,
    /// Seed of the initialisation and the sparse grids' offsets.
    pub seed: u64,
    /// Pyramid levels, coarse to fine.
    pub levels: u32,
    /// Neighbourhood side N (odd) of the slices matched.
    pub neighbourhood: u32,
    /// Spacing of the sparse grid of neighbourhood centres in each slice
    /// (Kwatra et al.: about N/4).
    pub grid: u32,
    /// Iterations (search and optimisation) per level, the finest excepted.
    pub iterations: u32,
    /// Iterations at the finest level.
    pub finest_iterations: u32,
    /// Exponent r of the robust energy ‖s − e‖^r (Kopf et al.: 0.8).
    pub robust: f32,
    /// Strength of the colour-histogram weight (0 disables it).
    pub colour_histogram: f32,
    /// Strength of the position-histogram weight (0 disables it).
    pub position_histogram: f32,
    /// End with one more iteration that copies, for every voxel, the
    /// exemplar colour nearest the weighted mean (Chen & Wang's discrete
    /// solver) instead of writing the mean, which a blend of several
    /// slightly different predictions softens.
    pub copy: bool,
}

impl Default for ReferenceParams {
    fn default() -> Self {
        ReferenceParams {
            size: 64,
            seed: 1,
            levels: 4,
            neighbourhood: 7,
            grid: 2,
            iterations: 6,
            finest_iterations: 4,
            robust: 0.8,
            colour_histogram: 3.0,
            position_histogram: 4.0,
            copy: true,
        }
    }
}

/// Largest block side: 256³ voxels already hold 48 MiB of state per level.
pub const MAX_REFERENCE_SIZE: u32 = 256;

impl ReferenceParams {
    /// Levels that leave a block of 8 voxels per side at the coarsest (at
    /// least 1, at most 5), where the exemplar is blurred enough for the
    /// layout of its largest features; every level's side a multiple of
    /// the grid.
    pub fn default_levels(size: u32, grid: u32) -> u32 {
        let mut levels = 1;
        while levels < 5 && (size >> levels) >= 8 && size.is_multiple_of(grid << levels) {
            levels += 1;
        }
        levels
    }

    /// Checks every field against its range.
    pub fn validate(&self) -> Result<()> {
        let range = |name: &'static str, v: f64, min: f64, max: f64| {
            if (min..=max).contains(&v) {
                Ok(())
            } else {
                Err(Error::InvalidRange {
                    name,
                    value: v,
                    min,
                    max,
                })
            }
        };
        range("levels", self.levels as f64, 1.0, 5.0)?;
        range("size", self.size as f64, 8.0, MAX_REFERENCE_SIZE as f64)?;
        range("neighbourhood", self.neighbourhood as f64, 3.0, 11.0)?;
        range("grid", self.grid as f64, 1.0, 4.0)?;
        range("iterations", self.iterations as f64, 0.0, 32.0)?;
        range(
            "finest_iterations",
            self.finest_iterations as f64,
            0.0,
            32.0,
        )?;
        range("robust", self.robust as f64, 0.1, 2.0)?;
        range("colour_histogram", self.colour_histogram as f64, 0.0, 4.0)?;
        range(
            "position_histogram",
            self.position_histogram as f64,
            0.0,
            16.0,
        )?;
        if self.neighbourhood.is_multiple_of(2) {
            return Err(Error::InvalidRequest("neighbourhood must be odd".into()));
        }
        let coarsest = self.size >> (self.levels - 1);
        // The sparse grid tiles every level's block, so each level's side
        // is a multiple of the grid's spacing.
        let unit = self.grid << (self.levels - 1);
        if !self.size.is_multiple_of(unit) || coarsest < 2 * self.grid {
            return Err(Error::InvalidRequest(format!(
                "size {} must be a multiple of grid · 2^(levels − 1) = {unit} with at least {} voxels at the coarsest level",
                self.size,
                2 * self.grid
            )));
        }
        Ok(())
    }
}

/// A periodic block: `size`³ RGB8 voxels, x fastest, then y, then z.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Block {
    /// Side in voxels.
    pub size: u32,
    /// RGB8 voxels.
    pub rgb: Vec<u8>,
}

/// What one level's iteration reached, for progress reports.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IterationReport {
    /// Pyramid level (0 = finest).
    pub level: usize,
    /// Iteration within the level.
    pub iteration: u32,
    /// Mean RMS difference per neighbourhood value between the slices'
    /// neighbourhoods and their matches, after the search (planes summed
    /// by weight).
    pub energy: f64,
    /// Voxels whose source changed in the optimisation.
    pub changed: usize,
}

/// Dimensions of the vectors the similar sets are found by.
const SHORT_DIMS: usize = 8;

/// Similar pixels kept per exemplar pixel for the k-coherence search.
const SIMILAR: usize = 4;

/// One plane's exemplar at one level, ready to be searched.
struct PlaneLevel {
    w: u32,
    h: u32,
    /// Colours of the Gaussian stack level.
    colours: Vec<[f32; 3]>,
    /// PCA vectors of every pixel's neighbourhood, `DIMS` each.
    vectors: Vec<[f32; DIMS]>,
    projector: Projector,
    tree: Tree,
    /// Each pixel's `SIMILAR` most similar pixels (not itself, none
    /// within two samples of it).
    similar: Vec<u32>,
    /// Each pixel's palette entry.
    index: Vec<u16>,
}

impl PlaneLevel {
    fn new(stack: &GaussianStack, k: usize, n: u32, palette: &Palette) -> PlaneLevel {
        let (w, h) = (stack.width(), stack.height());
        let all = crate::analysis::appearance::all_neighbourhoods(stack, k, n);
        let input = (n * n * 3) as usize;
        let pca = Pca::fit(&all, input, DIMS);
        let projector = Projector::new(&pca);
        let vectors: Vec<[f32; DIMS]> = all
            .par_chunks_exact(input)
            .map(|hood| {
                let mut out = [0f32; DIMS + 8];
                projector.project(hood, &mut out);
                let mut v = [0f32; DIMS];
                v.copy_from_slice(&out[..DIMS]);
                v
            })
            .collect();
        let tree = Tree::new_from_slice(&vectors);
        let step = spacing(k) as i64;
        let (wi, hi) = (w as i64, h as i64);
        // Similar pixels by their strongest components alone: a tree over
        // fewer dimensions answers many times faster, and a similar set
        // only proposes candidates, which the search then scores in full.
        let short: Vec<[f32; SHORT_DIMS]> = vectors
            .iter()
            .map(|v| std::array::from_fn(|d| v[d]))
            .collect();
        let short_tree = kiddo::ImmutableKdTree::<f32, SHORT_DIMS>::new_from_slice(&short);
        let want = std::num::NonZero::new((SIMILAR * 8).min(vectors.len())).expect("pixels");
        let similar = (0..vectors.len())
            .into_par_iter()
            .flat_map_iter(|c| {
                let mut nn = short_tree.nearest_n::<SquaredEuclidean>(&short[c], want);
                nn.sort_by(|a, b| a.distance.total_cmp(&b.distance).then(a.item.cmp(&b.item)));
                let (cx, cy) = (c as i64 % wi, c as i64 / wi);
                let mut out = Vec::with_capacity(SIMILAR);
                for m in nn {
                    let q = m.item as i64;
                    let (x, y) = (q % wi, q / wi);
                    let dx = (x - cx).rem_euclid(wi).min((cx - x).rem_euclid(wi));
                    let dy = (y - cy).rem_euclid(hi).min((cy - y).rem_euclid(hi));
                    if dx.max(dy) >= 2 * step && out.len() < SIMILAR {
                        out.push(q as u32);
                    }
                }
                while out.len() < SIMILAR {
                    out.push(c as u32);
                }
                out
            })
            .collect();
        let colours = stack.level(k).to_vec();
        let index = colours.iter().map(|c| palette.nearest(*c)).collect();
        PlaneLevel {
            w,
            h,
            colours,
            vectors,
            projector,
            tree,
            similar,
            index,
        }
    }

    /// Pixel `q` moved by (du, dv) pixels, wrapping.
    #[inline]
    fn moved(&self, q: u32, du: i64, dv: i64) -> u32 {
        let (w, h) = (self.w as i64, self.h as i64);
        let x = (q as i64 % w + du).rem_euclid(w);
        let y = (q as i64 / w + dv).rem_euclid(h);
        (y * w + x) as u32
    }
}

/// The block at one level. Each voxel has a pixel in each plane's exemplar
/// (where the slices through it continue that exemplar, as far as the
/// optimisation decided), and shows the colour of one of them.
struct State {
    side: usize,
    pos: [Vec<u32>; 3],
    pick: Vec<u8>,
    colours: Vec<[f32; 3]>,
}

impl State {
    /// A state from each voxel's pixel per plane and the plane it shows:
    /// its colour is that plane's pixel.
    fn new<'a>(
        side: usize,
        pos: [Vec<u32>; 3],
        pick: Vec<u8>,
        plane: impl Fn(usize) -> &'a PlaneLevel + Sync,
    ) -> State {
        let colours = (0..pick.len())
            .into_par_iter()
            .map(|i| plane(pick[i] as usize).colours[pos[pick[i] as usize][i] as usize])
            .collect();
        State {
            side,
            pos,
            pick,
            colours,
        }
    }

    #[inline]
    fn index(&self, p: [usize; 3]) -> usize {
        (p[2] * self.side + p[1]) * self.side + p[0]
    }
}

/// The neighbourhood matches of one plane: for each centre of the sparse
/// grid (offset `offset`, spacing g in the plane's two axes, every layer
/// along its normal), the exemplar pixel matched and its weight.
struct Matches {
    offset: [usize; 2],
    pixel: Vec<u32>,
    weight: Vec<f32>,
    /// ‖s − e‖ of each match, per neighbourhood value (RMS).
    distance: Vec<f32>,
}

/// Synthesizes a periodic block from `exemplars` (already laid out by
/// their orientation), each plane's neighbourhoods counted with its
/// `weights`. `report` is called after every iteration.
pub fn synthesize(
    exemplars: &ExemplarSet,
    weights: [f32; 3],
    params: &ReferenceParams,
    report: impl FnMut(IterationReport),
) -> Result<Block> {
    let (s, _) = optimise_block(exemplars, weights, params, 0, report)?;
    let rgb = s
        .colours
        .iter()
        .flat_map(|c| c.map(|v| v.round().clamp(0.0, 255.0) as u8))
        .collect();
    Ok(Block {
        size: params.size,
        rgb,
    })
}

/// A periodic block of triples at one level of the Gaussian stack: for
/// each voxel, its pixel in each plane's exemplar, as the lazy engine's
/// triples are.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TripleBlock {
    /// Side in voxels of `level`.
    pub side: u32,
    /// Stack level the pixels are sampled at (spacing 2^level).
    pub level: u32,
    /// Triples, x fastest, then y, then z.
    pub triples: Vec<[u32; 3]>,
}

impl TripleBlock {
    /// The triple at `p`, wrapping.
    #[inline]
    pub fn at(&self, p: [i64; 3]) -> [u32; 3] {
        let s = self.side as i64;
        let [x, y, z] = p.map(|c| c.rem_euclid(s) as usize);
        self.triples[(z * self.side as usize + y) * self.side as usize + x]
    }
}

/// The reference optimised down to stack level `finest` (its voxels 2^finest
/// wide, `params.size` of them per side), returned as the triples of every
/// level it passed through, coarsest first: each level's block is the
/// coarse version its finer one was upsampled from and refined.
/// `progress(fraction)` is called after every iteration (and may unwind to
/// cancel).
pub fn triple_blocks(
    exemplars: &ExemplarSet,
    weights: [f32; 3],
    params: &ReferenceParams,
    finest: usize,
    progress: &(dyn Fn(f32) + Sync),
) -> Result<Vec<TripleBlock>> {
    // Work per level grows eightfold towards the finest.
    let levels = params.levels as i32;
    let work = |j: i32, its: u32| its as f64 * 8f64.powi(levels - 1 - j);
    let total: f64 = (0..levels)
        .map(|j| {
            work(
                j,
                if j == 0 {
                    params.finest_iterations
                } else {
                    params.iterations
                },
            )
        })
        .sum();
    let mut done = 0.0;
    let report = |r: IterationReport| {
        done += work(r.level as i32 - finest as i32, 1);
        progress((done / total.max(1.0)) as f32);
    };
    Ok(optimise_block(exemplars, weights, params, finest, report)?.1)
}

/// The reference that the lazy synthesis starts from, for exemplars of
/// `width` × `height` pixels, kept from stack level `finest` to `coarsest`:
/// its pyramid reaches two levels above `finest` at least, and its block
/// spans twice the exemplar when only the coarsest level is kept (so that
/// cells read at hashed offsets rarely repeat a feature side by side), one
/// exemplar when every level is, within [`MAX_SEED_VOXELS`].
pub fn seeding_params(width: u32, height: u32, finest: u32, coarsest: u32) -> ReferenceParams {
    let levels = (coarsest.max(finest + 2) - finest) + 1;
    let unit = ReferenceParams::default().grid << (levels - 1);
    let span = width.max(height) * if finest == coarsest { 2 } else { 1 };
    let cap = if finest == coarsest { 64 } else { 128 };
    let side = (span >> finest).div_ceil(unit) * unit;
    ReferenceParams {
        size: side.clamp((2 * unit).max(16), cap),
        levels,
        ..ReferenceParams::default()
    }
}

/// Most voxels a block that the lazy synthesis starts from holds per
/// side.
pub const MAX_SEED_VOXELS: u32 = 128;

/// The optimisation itself, coarse to fine, its finest level at stack
/// level `finest`.
fn optimise_block(
    exemplars: &ExemplarSet,
    weights: [f32; 3],
    params: &ReferenceParams,
    finest: usize,
    mut report: impl FnMut(IterationReport),
) -> Result<(State, Vec<TripleBlock>)> {
    params.validate()?;
    let mut blocks = Vec::with_capacity(params.levels as usize);
    let levels = params.levels as usize;
    let n = params.neighbourhood;
    let same = exemplars.is_single();
    let stacks: Vec<GaussianStack> = (0..if same { 1 } else { 3 })
        .map(|p| GaussianStack::new(exemplars.plane(p), levels + finest))
        .collect();
    let palette = Palette::fit(
        &(0..3)
            .flat_map(|p| exemplars.plane(p).pixels().iter())
            .map(|c| [c[0] as f32, c[1] as f32, c[2] as f32])
            .collect::<Vec<_>>(),
        params.seed,
    );
    let mut state: Option<State> = None;
    for j in (0..levels).rev() {
        let k = j + finest;
        let planes: Vec<PlaneLevel> = stacks
            .iter()
            .map(|s| PlaneLevel::new(s, k, n, &palette))
            .collect();
        let plane = |p: usize| &planes[if same { 0 } else { p }];
        let side = (params.size >> j) as usize;
        let mut s = match state.take() {
            None => initial(side, params.seed, k, plane),
            Some(parent) => upsample(&parent, k, plane),
        };
        let target = exemplar_histogram(&palette, weights, plane);
        let iterations = if j == 0 {
            params.finest_iterations
        } else {
            params.iterations
        };
        // The finest level copies exemplar colours (the discrete solver).
        let copying = j == 0 && params.copy;
        for it in 0..iterations {
            // The first search of the coarsest level starts from noise,
            // where coherence has nothing to follow.
            let full = j + 1 == levels && it == 0;
            let matches: Vec<Matches> = (0..3)
                .map(|p| search(&s, p, plane(p), params, k, it, full))
                .collect();
            let energy = matches
                .iter()
                .zip(weights)
                .map(|(m, w)| {
                    w as f64 * m.distance.iter().map(|&x| x as f64).sum::<f64>()
                        / m.distance.len() as f64
                })
                .sum::<f64>();
            let factors = Factors::new(&s, &matches, &palette, &target, params, plane);
            let step = Step {
                level: k,
                copy: copying,
            };
            let changed = optimise(&mut s, &matches, weights, &factors, params, step, plane);
            report(IterationReport {
                level: k,
                iteration: it,
                energy,
                changed,
            });
        }
        blocks.push(TripleBlock {
            side: s.side as u32,
            level: k as u32,
            triples: (0..s.pick.len())
                .map(|i| [s.pos[0][i], s.pos[1][i], s.pos[2][i]])
                .collect(),
        });
        state = Some(s);
    }
    Ok((state.expect("at least one level"), blocks))
}

/// Random pixels at the coarsest level, hashed per voxel and plane; each
/// voxel shows a hashed plane's.
fn initial<'a>(
    side: usize,
    seed: u64,
    k: usize,
    plane: impl Fn(usize) -> &'a PlaneLevel + Sync,
) -> State {
    let count = side * side * side;
    let at = |i: usize| [i % side, (i / side) % side, i / (side * side)].map(|c| c as i64);
    let pos = [0, 1, 2].map(|p| {
        let len = (plane(p).w * plane(p).h) as u64;
        (0..count)
            .map(|i| (hash_pos(seed, k as u32, TAG_INIT + p as u32, at(i)) % len) as u32)
            .collect::<Vec<u32>>()
    });
    let pick: Vec<u8> = (0..count)
        .map(|i| (hash_pos(seed, k as u32, TAG_INIT + 3, at(i)) % 3) as u8)
        .collect();
    State::new(side, pos, pick, plane)
}

const TAG_INIT: u32 = 0x5245_4601;
const TAG_GRID: u32 = 0x5245_4610;
const TAG_RANDOM: u32 = 0x5245_4620;

/// Each voxel of level k from its parent at level k + 1: the parent's
/// pixel in each plane moved by the child's offset within the parent, in
/// that plane's two axes, at level k's spacing.
fn upsample<'a>(parent: &State, k: usize, plane: impl Fn(usize) -> &'a PlaneLevel + Sync) -> State {
    let side = parent.side * 2;
    let h = spacing(k) as i64;
    let count = side * side * side;
    let at = |i: usize| [i % side, (i / side) % side, i / (side * side)];
    let pos = [0, 1, 2].map(|p| {
        let (a, b) = AXES[p];
        let pl = plane(p);
        (0..count)
            .into_par_iter()
            .map(|i| {
                let v = at(i);
                let q = parent.pos[p][parent.index(v.map(|c| c / 2))];
                pl.moved(q, (v[a] % 2) as i64 * h, (v[b] % 2) as i64 * h)
            })
            .collect::<Vec<u32>>()
    });
    let pick: Vec<u8> = (0..count)
        .map(|i| parent.pick[parent.index(at(i).map(|c| c / 2))])
        .collect();
    State::new(side, pos, pick, plane)
}

/// The sparse grid's offset for one plane, level and iteration: hashed,
/// so that grid positions do not print a lattice into the result.
fn grid_offset(params: &ReferenceParams, k: usize, it: u32, p: usize) -> [usize; 2] {
    let g = params.grid as u64;
    let h = hash_pos(params.seed, k as u32, TAG_GRID, [it as i64, p as i64, 0]);
    [(h % g) as usize, ((h >> 16) % g) as usize]
}

/// The search step for plane `p`: every sparse-grid centre's slice
/// neighbourhood, its nearest exemplar neighbourhood in PCA space, and the
/// robust weight ‖s − e‖^(r−2) of that match. Candidates come by
/// k-coherence (Tong et al. 2002): each voxel of the neighbourhood
/// proposes its pixel in this plane moved back by its offset, and that
/// pixel's similar pixels; `full` searches the whole exemplar instead.
#[allow(clippy::too_many_arguments)]
fn search(
    s: &State,
    p: usize,
    pl: &PlaneLevel,
    params: &ReferenceParams,
    k: usize,
    it: u32,
    full: bool,
) -> Matches {
    let side = s.side;
    let g = params.grid as usize;
    let per = side / g;
    let offset = grid_offset(params, k, it, p);
    let (a, b) = AXES[p];
    let o = 3 - a - b;
    let r = (params.neighbourhood / 2) as i64;
    let h = spacing(k) as i64;
    let input = (params.neighbourhood * params.neighbourhood * 3) as usize;
    // A perfect match would get an infinite weight: distances are floored
    // at one grey level of RMS difference over the neighbourhood.
    let floor = input as f32;
    let exponent = (params.robust - 2.0) / 2.0;
    let count = side * per * per;
    let len = (pl.w * pl.h) as u64;
    let mut pixel = vec![0u32; count];
    let mut weight = vec![0f32; count];
    let mut distance = vec![0f32; count];
    pixel
        .par_chunks_mut(per)
        .zip(weight.par_chunks_mut(per))
        .zip(distance.par_chunks_mut(per))
        .enumerate()
        .for_each_init(
            || (vec![0f32; input], [0f32; DIMS + 8]),
            |(hood, proj), (row, ((pix, wt), dist))| {
                let layer = row / per;
                let jb = row % per;
                for ja in 0..per {
                    let mut c = [0usize; 3];
                    c[o] = layer;
                    c[a] = offset[0] + ja * g;
                    c[b] = offset[1] + jb * g;
                    let mut t = 0;
                    for dv in -r..=r {
                        for du in -r..=r {
                            let mut q = c;
                            q[a] = (c[a] as i64 + du).rem_euclid(side as i64) as usize;
                            q[b] = (c[b] as i64 + dv).rem_euclid(side as i64) as usize;
                            hood[t..t + 3].copy_from_slice(&s.colours[s.index(q)]);
                            t += 3;
                        }
                    }
                    pl.projector.project(hood, proj);
                    let mut v = [0f32; DIMS];
                    v.copy_from_slice(&proj[..DIMS]);
                    let (best, best_d) = if full {
                        let nn = pl.tree.nearest_one::<SquaredEuclidean>(&v);
                        (nn.item as u32, nn.distance)
                    } else {
                        let mut best = u32::MAX;
                        let mut best_d = f32::INFINITY;
                        let mut try_pixel = |q: u32| {
                            let d =
                                crate::analysis::appearance::sq_dist(&v, &pl.vectors[q as usize]);
                            if d < best_d || (d == best_d && q < best) {
                                best_d = d;
                                best = q;
                            }
                        };
                        for dv in -r..=r {
                            for du in -r..=r {
                                let mut q = c;
                                q[a] = (c[a] as i64 + du).rem_euclid(side as i64) as usize;
                                q[b] = (c[b] as i64 + dv).rem_euclid(side as i64) as usize;
                                let here = s.pos[p][s.index(q)];
                                let back = pl.moved(here, -du * h, -dv * h);
                                try_pixel(back);
                                for &sim in &pl.similar[back as usize * SIMILAR..][..SIMILAR] {
                                    try_pixel(sim);
                                }
                            }
                        }
                        for t in 0..2u32 {
                            let hsh = hash_pos(
                                params.seed,
                                k as u32,
                                TAG_RANDOM + t,
                                [c[0] as i64, c[1] as i64, (c[2] as i64) << 8 | it as i64],
                            );
                            try_pixel((hsh % len) as u32);
                        }
                        (best, best_d)
                    };
                    pix[ja] = best;
                    wt[ja] = (best_d.max(0.0) + floor).powf(exponent);
                    dist[ja] = (best_d.max(0.0) / input as f32).sqrt();
                }
            },
        );
    Matches {
        offset,
        pixel,
        weight,
        distance,
    }
}

/// Multipliers of every contribution's weight from the two histograms.
struct Factors {
    /// Per palette entry: the exemplar's share over the block's, raised to
    /// the colour strength.
    colour: Vec<f32>,
    /// Per plane and exemplar pixel: 1 / (1 + λ · excess usage).
    position: Vec<Vec<f32>>,
}

/// The exemplar's palette histogram, planes weighted as in the matching.
fn exemplar_histogram<'a>(
    palette: &Palette,
    weights: [f32; 3],
    plane: impl Fn(usize) -> &'a PlaneLevel,
) -> Vec<f64> {
    let mut hist = vec![0f64; palette.len()];
    for (p, w) in weights.iter().enumerate() {
        let pl = plane(p);
        let share = *w as f64 / pl.index.len() as f64;
        for &i in &pl.index {
            hist[i as usize] += share;
        }
    }
    let total: f64 = hist.iter().sum();
    hist.iter().map(|h| h / total).collect()
}

impl Factors {
    fn new<'a>(
        s: &State,
        matches: &[Matches],
        palette: &Palette,
        target: &[f64],
        params: &ReferenceParams,
        plane: impl Fn(usize) -> &'a PlaneLevel,
    ) -> Factors {
        let mut hist = vec![0f64; palette.len()];
        for (i, &pk) in s.pick.iter().enumerate() {
            let pl = plane(pk as usize);
            hist[pl.index[s.pos[pk as usize][i] as usize] as usize] += 1.0;
        }
        let total = s.pick.len() as f64;
        let colour = hist
            .iter()
            .zip(target)
            .map(|(&h, &t)| {
                if params.colour_histogram == 0.0 || t == 0.0 {
                    return 1.0;
                }
                // Half a voxel's share keeps an empty bin finite.
                let ratio = t / (h / total).max(0.5 / total);
                (ratio.powf(params.colour_histogram as f64) as f32).clamp(0.25, 4.0)
            })
            .collect();
        let position = (0..3)
            .map(|p| {
                let pl = plane(p);
                let len = (pl.w * pl.h) as usize;
                if params.position_histogram == 0.0 {
                    return vec![1.0; len];
                }
                let mut used = vec![0f32; len];
                for &q in &matches[p].pixel {
                    used[q as usize] += 1.0;
                }
                // Usage is spread over the 3×3 pixels around each match:
                // neighbouring pixels carry nearly the same neighbourhood.
                let spread = box3(&used, pl.w as usize, pl.h as usize);
                let mean = matches[p].pixel.len() as f32 / len as f32;
                spread
                    .iter()
                    .map(|&u| 1.0 / (1.0 + params.position_histogram * (u / mean - 1.0).max(0.0)))
                    .collect()
            })
            .collect();
        Factors { colour, position }
    }
}

/// Mean over the 3×3 pixels around each pixel, wrapping.
fn box3(v: &[f32], w: usize, h: usize) -> Vec<f32> {
    let mut out = vec![0f32; v.len()];
    for y in 0..h {
        for x in 0..w {
            let mut acc = 0.0;
            for dy in [h - 1, 0, 1] {
                for dx in [w - 1, 0, 1] {
                    acc += v[((y + dy) % h) * w + (x + dx) % w];
                }
            }
            out[y * w + x] = acc / 9.0;
        }
    }
    out
}

/// How fast a prediction's claim to be the voxel's pixel in its plane
/// falls with its colour's distance from the voxel's: 1 / (2σ²), σ = 12
/// grey levels.
const AGREE: f32 = 1.0 / (2.0 * 12.0 * 12.0);

/// One prediction for a voxel: the plane, its exemplar pixel, its colour
/// and its weight.
#[derive(Clone, Copy)]
struct Contribution {
    plane: u8,
    pixel: u32,
    colour: [f32; 3],
    weight: f32,
}

/// Which optimisation step an iteration takes: its stack level, and
/// whether it copies exemplar colours instead of averaging them.
#[derive(Clone, Copy)]
struct Step {
    level: usize,
    copy: bool,
}

/// The optimisation step: every voxel from the predictions of the matched
/// neighbourhoods that overlap it. Returns how many voxels changed colour.
fn optimise<'a>(
    s: &mut State,
    matches: &[Matches],
    weights: [f32; 3],
    factors: &Factors,
    params: &ReferenceParams,
    step: Step,
    plane: impl Fn(usize) -> &'a PlaneLevel + Sync,
) -> usize {
    let Step { level: k, copy } = step;
    let side = s.side;
    let g = params.grid as usize;
    let per = side / g;
    let r = (params.neighbourhood / 2) as i64;
    let h = spacing(k) as i64;
    let old = &*s;
    let results: Vec<([u32; 3], u8, [f32; 3])> = (0..side * side * side)
        .into_par_iter()
        .map_init(Vec::new, |contrib: &mut Vec<Contribution>, i| {
            let v = [i % side, (i / side) % side, i / (side * side)];
            contrib.clear();
            for (p, m) in matches.iter().enumerate() {
                if weights[p] == 0.0 {
                    continue;
                }
                let pl = plane(p);
                let (a, b) = AXES[p];
                let o = 3 - a - b;
                // Centres c ≡ offset (mod g) with |v − c| ≤ r in both axes.
                let first = |axis: usize, off: usize| {
                    let lo = v[axis] as i64 - r;
                    lo + (off as i64 - lo).rem_euclid(g as i64)
                };
                let (fa, fb) = (first(a, m.offset[0]), first(b, m.offset[1]));
                let mut cb = fb;
                while cb <= v[b] as i64 + r {
                    let jb = (cb.rem_euclid(side as i64) as usize - m.offset[1]) / g;
                    let mut ca = fa;
                    while ca <= v[a] as i64 + r {
                        let ja = (ca.rem_euclid(side as i64) as usize - m.offset[0]) / g;
                        let at = (v[o] * per + jb) * per + ja;
                        let q = m.pixel[at];
                        let du = v[a] as i64 - ca;
                        let dv = v[b] as i64 - cb;
                        let px = pl.moved(q, du * h, dv * h);
                        contrib.push(Contribution {
                            plane: p as u8,
                            pixel: px,
                            colour: pl.colours[px as usize],
                            weight: weights[p]
                                * m.weight[at]
                                * factors.colour[pl.index[px as usize] as usize]
                                * factors.position[p][q as usize],
                        });
                        ca += g as i64;
                    }
                    cb += g as i64;
                }
            }
            let total: f32 = contrib.iter().map(|c| c.weight).sum();
            let mut mean = [0f32; 3];
            for c in contrib.iter() {
                for (m, v) in mean.iter_mut().zip(c.colour) {
                    *m += v * c.weight;
                }
            }
            let mean = mean.map(|m| m / total);
            // Per plane, where the voxel continues that plane's exemplar:
            // the prediction with the most weight among those that agree
            // with the mean. Weight favours the best-matched
            // neighbourhoods, which cover several voxels alike, so
            // neighbouring voxels keep continuing the same patch.
            let mut pos = [0, 1, 2].map(|p| old.pos[p][i]);
            let mut best = [f32::NEG_INFINITY; 3];
            let mut near = [[0f32; 3]; 3];
            for c in contrib.iter() {
                let d = (0..3)
                    .map(|ch| (c.colour[ch] - mean[ch]).powi(2))
                    .sum::<f32>();
                let score = c.weight * (-d * AGREE).exp();
                let p = c.plane as usize;
                if score > best[p] {
                    best[p] = score;
                    pos[p] = c.pixel;
                    near[p] = c.colour;
                }
            }
            // The colour is the mean, or (copying) the exemplar colour of
            // the plane whose pixel claims the voxel most. The voxel's
            // plane for the colour histogram stays as it was drawn.
            let pick = old.pick[i];
            let mut colour = mean;
            if copy {
                let mut top = f32::NEG_INFINITY;
                for (p, &b) in best.iter().enumerate() {
                    if b > top {
                        top = b;
                        colour = near[p];
                    }
                }
            }
            (pos, pick, colour)
        })
        .collect();
    let mut changed = 0;
    for (i, (pos, pick, colour)) in results.into_iter().enumerate() {
        for (plane, p) in s.pos.iter_mut().zip(pos) {
            plane[i] = p;
        }
        changed += (s.colours[i] != colour) as usize;
        s.pick[i] = pick;
        s.colours[i] = colour;
    }
    changed
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::exemplar::Exemplar;

    #[test]
    fn default_levels_leave_eight_voxels_at_the_coarsest() {
        assert_eq!(ReferenceParams::default_levels(64, 2), 4);
        assert_eq!(ReferenceParams::default_levels(128, 2), 5);
        assert_eq!(ReferenceParams::default_levels(32, 2), 3);
        assert_eq!(ReferenceParams::default_levels(24, 2), 2);
        // Every level a multiple of the grid: 36 → 18 → 9 would not be.
        assert_eq!(ReferenceParams::default_levels(36, 2), 2);
    }

    fn stripes() -> ExemplarSet {
        let w = 32;
        let rgb: Vec<u8> = (0..w * w)
            .flat_map(|i| {
                let (x, y) = (i % w, i / w);
                let v = if (x / 4 + y / 8) % 2 == 0 { 40 } else { 200 };
                [v, v / 2, 255 - v]
            })
            .collect();
        ExemplarSet::single(Exemplar::from_rgb(w as u32, w as u32, &rgb).unwrap())
    }

    /// Mean luminance step between x-neighbours across the block's wrap
    /// (x = side − 1 to x = 0) and between all others.
    fn steps(b: &Block) -> (f64, f64) {
        let n = b.size as usize;
        let lum = |x: usize, y: usize, z: usize| {
            let i = ((z * n + y) * n + x) * 3;
            b.rgb[i..i + 3].iter().map(|&v| v as f64).sum::<f64>() / 3.0
        };
        let (mut across, mut inside) = (0.0, 0.0);
        for z in 0..n {
            for y in 0..n {
                across += (lum(n - 1, y, z) - lum(0, y, z)).abs();
                for x in 0..n - 1 {
                    inside += (lum(x + 1, y, z) - lum(x, y, z)).abs();
                }
            }
        }
        (across / (n * n) as f64, inside / (n * n * (n - 1)) as f64)
    }

    #[test]
    fn a_block_tiles_without_a_seam() {
        let params = ReferenceParams {
            size: 32,
            levels: 3,
            iterations: 3,
            finest_iterations: 2,
            ..Default::default()
        };
        let b = synthesize(&stripes(), [1.0; 3], &params, |_| {}).unwrap();
        let (across, inside) = steps(&b);
        assert!(inside > 1.0, "a flat block says nothing: {inside}");
        assert!(
            across < 1.5 * inside,
            "seam: {across} across the wrap, {inside} inside"
        );
        // The check can fail: two halves of different blocks side by side.
        let other = synthesize(
            &stripes(),
            [1.0; 3],
            &ReferenceParams { seed: 9, ..params },
            |_| {},
        )
        .unwrap();
        let n = 32usize;
        let mut spliced = b.clone();
        for z in 0..n {
            for y in 0..n {
                let row = ((z * n + y) * n) * 3;
                spliced.rgb[row..row + n / 2 * 3].copy_from_slice(&other.rgb[row..row + n / 2 * 3]);
            }
        }
        let (across, inside) = steps(&spliced);
        assert!(
            across > 1.5 * inside,
            "a splice shows no seam: {across} vs {inside}"
        );
    }

    #[test]
    fn blocks_for_the_lazy_synthesis_hold_exemplar_pixels_at_every_level() {
        let set = stripes();
        let params = seeding_params(32, 32, 0, 1);
        assert_eq!(params.levels, 3);
        let blocks = triple_blocks(&set, [1.0; 3], &params, 0, &|_| {}).unwrap();
        assert_eq!(
            blocks.iter().map(|b| b.level).collect::<Vec<_>>(),
            [2, 1, 0]
        );
        for b in &blocks {
            assert_eq!(b.triples.len(), (b.side as usize).pow(3));
            assert!(b.triples.iter().flatten().all(|&c| c < 32 * 32));
        }
        assert_eq!(blocks[2].side, 2 * blocks[1].side);
        // The block reads wrap: p and p + side are the same voxel.
        let b = &blocks[2];
        let s = b.side as i64;
        assert_eq!(b.at([1, 2, 3]), b.at([1 + s, 2 - s, 3 + 2 * s]));
    }

    #[test]
    fn seeding_blocks_span_the_exemplar_within_their_bounds() {
        // The coarsest level alone: twice the exemplar.
        let p = seeding_params(128, 128, 3, 3);
        assert_eq!((p.size, p.levels), (32, 3));
        // Every level: one exemplar, capped.
        let p = seeding_params(128, 128, 0, 3);
        assert_eq!((p.size, p.levels), (128, 4));
        assert_eq!(seeding_params(512, 512, 0, 3).size, MAX_SEED_VOXELS);
        assert_eq!(seeding_params(16, 16, 3, 3).size, 16);
        for (w, f, c) in [
            (100, 3, 3),
            (100, 0, 3),
            (62, 0, 3),
            (156, 0, 3),
            (512, 3, 3),
            (40, 1, 2),
        ] {
            assert!(seeding_params(w, w, f, c).validate().is_ok(), "{w} {f} {c}");
        }
    }

    #[test]
    fn parameters_out_of_range_are_refused() {
        assert!(ReferenceParams::default().validate().is_ok());
        for bad in [
            ReferenceParams {
                size: 60,
                ..Default::default()
            },
            ReferenceParams {
                neighbourhood: 6,
                ..Default::default()
            },
            ReferenceParams {
                levels: 0,
                ..Default::default()
            },
            ReferenceParams {
                size: 512,
                ..Default::default()
            },
            // Just past the largest block (a multiple of the grid's unit).
            ReferenceParams {
                size: MAX_REFERENCE_SIZE + 32,
                levels: 5,
                ..Default::default()
            },
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
        let largest = ReferenceParams {
            size: MAX_REFERENCE_SIZE,
            levels: 5,
            ..Default::default()
        };
        assert!(largest.validate().is_ok());
    }

    #[test]
    fn a_block_is_made_of_exemplar_colours_and_does_not_depend_on_threads() {
        let params = ReferenceParams {
            size: 16,
            levels: 2,
            iterations: 2,
            finest_iterations: 1,
            ..Default::default()
        };
        let set = stripes();
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| synthesize(&set, [1.0; 3], &params, |_| {}).unwrap());
        let many = synthesize(&set, [1.0; 3], &params, |_| {}).unwrap();
        assert_eq!(one, many);
        assert_eq!(one.rgb.len(), 16 * 16 * 16 * 3);
        let colours: std::collections::HashSet<[u8; 3]> =
            set.plane(0).pixels().iter().copied().collect();
        for v in one.rgb.chunks_exact(3) {
            assert!(
                colours.contains(&[v[0], v[1], v[2]]),
                "{v:?} is not an exemplar colour"
            );
        }
    }
}
