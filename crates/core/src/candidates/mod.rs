//! Everything computed once per texture before any voxel is synthesized
//! (Dong et al. §"Candidate pre-computation"): Gaussian stacks, appearance
//! vectors, 2D similarity sets, 3D candidate triples (crossbar search, then
//! coherence filtering) and the PCA-projected, 8-bit quantised
//! 3-neighbourhood of every candidate. [`Candidates::save`] and
//! [`Candidates::load`] move it to and from the `.stx` format.

pub mod coherence;
mod format;
pub mod geometry;
pub mod search;

use crate::analysis::appearance::{self, AppearanceLevel, Pca};
use crate::analysis::exemplar::ExemplarSet;
use crate::analysis::feature;
use crate::analysis::orientation::Layout;
use crate::analysis::stack::{GaussianStack, spacing};
use crate::error::{Error, Result};
use crate::params::AnalysisParams;
use crate::synth::cancel::CancelFlag;
use crate::synth::correction::tables::SparseTables;
use geometry::Dims;
use kiddo::SquaredEuclidean;
use rayon::prelude::*;
use search::{Scored, Strips};
use std::num::NonZero;
use std::sync::Arc;
use std::time::Instant;

/// Stages of the precomputation, for progress reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// Gaussian stacks and appearance vectors.
    Analysis,
    /// Strip search and crossbar errors.
    Search,
    /// Coherence filtering.
    Coherence,
    /// 2D similarity sets and neighbourhood vectors.
    Finish,
    /// The reference's blocks of triples (texture optimisation of a
    /// periodic block), when the synthesis starts from them.
    Reference,
}

/// Per-level summary of the candidate sets.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LevelReport {
    /// `histogram[n]` pixels (over all three planes) have n candidates.
    pub histogram: Vec<u64>,
    /// Pixels that fell back to their best triple.
    pub fallbacks: u64,
    /// Coherence filter iterations.
    pub iterations: u32,
    /// Mean crossbar error of every pixel's first candidate.
    pub mean_best_error: f64,
    /// Mean crossbar error of hashed random triples, for comparison.
    pub mean_random_error: f64,
}

/// Summary of a precomputation: time per stage and candidate statistics.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PrecomputeReport {
    /// Seconds spent per stage name.
    pub stage_seconds: Vec<(String, f64)>,
    /// One entry per level, finest first.
    pub levels: Vec<LevelReport>,
}

/// Candidate triples of one plane at one level, in compressed-row form.
#[derive(Clone, Debug, PartialEq)]
pub struct PlaneCandidates {
    /// `offsets[c]..offsets[c + 1]` indexes the candidates of pixel c
    /// (shared by the rotated copies of a single exemplar's planes).
    pub offsets: Arc<Vec<u32>>,
    /// Triples (xy, yz, zx pixel indices), best first per pixel.
    pub triples: Vec<[u32; 3]>,
    /// Crossbar error of each triple.
    pub errors: Vec<f32>,
}

impl PlaneCandidates {
    fn from_lists(lists: &[Vec<Scored>]) -> Self {
        let mut offsets = Vec::with_capacity(lists.len() + 1);
        let mut triples = Vec::new();
        let mut errors = Vec::new();
        offsets.push(0);
        for l in lists {
            for s in l {
                triples.push(s.triple);
                errors.push(s.error);
            }
            offsets.push(triples.len() as u32);
        }
        PlaneCandidates {
            offsets: Arc::new(offsets),
            triples,
            errors,
        }
    }

    /// Candidate index range of pixel `c`.
    #[inline]
    pub fn range(&self, c: u32) -> std::ops::Range<usize> {
        self.offsets[c as usize] as usize..self.offsets[c as usize + 1] as usize
    }

    /// The same candidates seen from plane `p` when all three exemplars are
    /// one image: coordinates rotate with the plane roles.
    fn rotated(&self, p: usize) -> Self {
        let triples = self
            .triples
            .iter()
            .map(|t| {
                let mut o = [0u32; 3];
                for (j, &c) in t.iter().enumerate() {
                    o[(j + p) % 3] = c;
                }
                o
            })
            .collect();
        PlaneCandidates {
            offsets: self.offsets.clone(),
            triples,
            errors: self.errors.clone(),
        }
    }
}

/// What is stored per level; the rest is derived at load.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct StoredLevel {
    pub appearance_pca: [Pca; 3],
    pub candidates: [PlaneCandidates; 3],
    /// `k2` most similar pixels per pixel (itself first), per plane.
    pub similar: [Vec<u32>; 3],
    pub k2: usize,
}

/// One level, with derived data for synthesis.
#[derive(Clone, Debug)]
pub struct Level {
    pub(crate) stored: StoredLevel,
    /// Appearance vectors per plane.
    pub appearance: [AppearanceLevel; 3],
    /// The plane whose 2D tables (similarity sets and their vectors) plane
    /// p reads: with one exemplar for all three planes those tables are
    /// equal, and reading one copy keeps it in cache where three would not
    /// stay.
    alias: [usize; 3],
    /// Each plane's weight in the sparse neighbourhoods' matching.
    weights: [f32; 3],
    /// Sparse appearance-space neighbourhoods, built when a correction
    /// first needs them.
    sparse: std::sync::OnceLock<SparseTables>,
}

impl Level {
    /// Candidate triples of plane `p`.
    pub fn candidates(&self, p: usize) -> &PlaneCandidates {
        &self.stored.candidates[p]
    }

    /// The 2D similarity set of pixel `c` in plane `p`.
    pub fn similar(&self, p: usize, c: u32) -> &[u32] {
        let k2 = self.stored.k2;
        &self.stored.similar[self.alias[p]][c as usize * k2..(c as usize + 1) * k2]
    }

    /// The sparse appearance-space tables of this level (level `k` of an
    /// exemplar of size `dims`), built on first use.
    ///
    /// They are built outside the cell and then offered to it: building
    /// runs on the thread pool, and a worker that waits for its helpers
    /// may meanwhile take up another first use of the same level, which
    /// would wait forever for a cell that it is itself filling. Callers
    /// that race may each build the tables; the first one set is kept.
    pub fn sparse_tables(&self, dims: Dims, k: usize) -> &SparseTables {
        if let Some(t) = self.sparse.get() {
            return t;
        }
        let built = SparseTables::new(
            &self.appearance,
            &self.stored.candidates,
            dims,
            spacing(k) as i64,
            self.weights,
        );
        self.sparse.get_or_init(|| built)
    }
}

/// Precomputed candidate data of one texture.
pub struct Candidates {
    exemplars: ExemplarSet,
    /// The exemplars as analysed: each plane's turned by the layout.
    analysed: ExemplarSet,
    layout: Layout,
    params: AnalysisParams,
    dims: Dims,
    stacks: [GaussianStack; 3],
    levels: Vec<Level>,
    /// The reference's blocks of triples, one per level that starts from
    /// one, finest first (none for the slab).
    blocks: Vec<crate::reference::TripleBlock>,
    report: PrecomputeReport,
    /// Content fingerprint, the texture part of tile cache keys: taken
    /// from the file when loaded, else from the encoding on first use.
    digest: std::sync::OnceLock<u64>,
}

impl std::fmt::Debug for Candidates {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "Candidates({}x{}, {} levels)",
            self.dims.w,
            self.dims.h,
            self.levels.len()
        )
    }
}

/// The reference's blocks for the levels `params` starts from one, finest
/// first, optimised once down to the finest of them.
fn reference_blocks(
    exemplars: &ExemplarSet,
    weights: [f32; 3],
    params: &AnalysisParams,
    progress: &(dyn Fn(f32) + Sync),
) -> Result<Vec<crate::reference::TripleBlock>> {
    let levels = params.reference_levels();
    if levels.is_empty() {
        return Ok(Vec::new());
    }
    let (finest, coarsest) = (*levels.start(), *levels.end());
    let rp =
        crate::reference::seeding_params(exemplars.width(), exemplars.height(), finest, coarsest);
    let blocks =
        crate::reference::triple_blocks(exemplars, weights, &rp, finest as usize, progress)?;
    Ok(blocks
        .into_iter()
        .filter(|b| b.level <= coarsest)
        .rev()
        .collect())
}

/// Appearance dimensions used by the similarity k-d tree.
pub const SIMILAR_DIMS: usize = 8;

impl Candidates {
    /// Heap bytes that [`Candidates::compute`] is expected to peak at for
    /// exemplars of `width`×`height` pixels (`distinct_planes`: three
    /// different exemplars, searched one by one), an upper bound fitted to
    /// measurements (docs/server.md). Most of it is the search's lists: for
    /// every level, searched plane and pixel its best `triples` candidates (16
    /// bytes each), all kept until the coherence filter reads them.
    pub fn estimated_peak_bytes(
        width: u32,
        height: u32,
        distinct_planes: bool,
        params: &AnalysisParams,
    ) -> u64 {
        let pixels = f64::from(width) * f64::from(height);
        let searched = if distinct_planes { 3.0 } else { 1.0 };
        let levels = f64::from(params.levels);
        let list = 16.0 * (f64::from(params.triples) + 1.0) + 54.0;
        // The lists of every level, and the filter's working copy of about
        // two thirds of one more.
        let search = (searched * levels + 1.7) * list;
        // With few triples the peak comes later, in the coherence filter and
        // the final tables.
        let later = 500.0 * searched * levels;
        let n = f64::from(params.neighbourhood);
        let wider = 11.0 * (n * n - 25.0).max(0.0);
        let kept = 40.0 * (f64::from(params.max_candidates) - 12.0).max(0.0);
        let per_pixel = search.max(later) + wider + kept;
        // Small exemplars peak at fixed costs (samples of set sizes, trees).
        let analysis = ((pixels * per_pixel) as u64 + (4 << 20)).max(6 << 20);
        // The reference block's optimisation state (positions, colours,
        // matches and the blocks kept), per voxel of its finest level.
        const REFERENCE_BYTES_PER_VOXEL: u64 = 80;
        let levels = params.reference_levels();
        let reference = if levels.is_empty() {
            0
        } else {
            let rp =
                crate::reference::seeding_params(width, height, *levels.start(), *levels.end());
            u64::from(rp.size).pow(3) * REFERENCE_BYTES_PER_VOXEL
        };
        analysis + reference
    }

    /// Runs the whole precomputation; `progress(stage, fraction 0..1)` is
    /// called as it advances. Uses the current rayon pool; the result is
    /// identical whatever its size.
    pub fn compute(
        exemplars: &ExemplarSet,
        params: &AnalysisParams,
        progress: &(dyn Fn(Stage, f32) + Sync),
    ) -> Result<Candidates> {
        params.validate_for(exemplars)?;
        let layout = Layout::resolve(exemplars, &params.orientation)?;
        let given = exemplars;
        // Turned planes differ from each other: the search takes the
        // general path, one plane at a time.
        let analysed = layout.apply(given)?;
        let exemplars = &analysed;
        let dims = Dims::new(exemplars.width(), exemplars.height());
        let single = exemplars.is_single();
        let levels_n = params.levels as usize;
        let mut report = PrecomputeReport::default();
        let mut timer = Instant::now();
        let mut lap = |report: &mut PrecomputeReport, name: &str| {
            report
                .stage_seconds
                .push((name.to_string(), timer.elapsed().as_secs_f64()));
            timer = Instant::now();
        };

        progress(Stage::Analysis, 0.0);
        // Watched between pixels of the search and between stages: a
        // server stops the precompute of a texture deleted meanwhile.
        let cancel = crate::synth::cancel::current();
        let stacks = build_stacks(exemplars, levels_n, params);
        let stages = Stages {
            stacks: &stacks,
            dims,
            params,
            single,
            progress,
            cancel: cancel.as_ref(),
        };
        let appearance_pca = stages.fit_appearance();
        lap(&mut report, "analysis");
        let raw_lists = stages.search_levels();
        lap(&mut report, "search");
        let filtered_levels = stages.filter_levels(raw_lists, &mut report);
        lap(&mut report, "coherence");
        let (stored, appearance) = stages.finish_levels(filtered_levels, appearance_pca);
        let levels = derive_levels(stored, appearance, single, layout.arrangement.weights);
        lap(&mut report, "finish");
        let blocks = reference_blocks(exemplars, layout.arrangement.weights, params, &|f| {
            progress(Stage::Reference, f);
            if let Some(c) = cancel.as_ref() {
                c.unwind_if_set();
            }
        })?;
        lap(&mut report, "reference");
        Ok(Candidates {
            exemplars: given.clone(),
            analysed,
            layout,
            params: params.clone(),
            dims,
            stacks,
            levels,
            blocks,
            report,
            digest: std::sync::OnceLock::new(),
        })
    }

    /// The reference's block of triples that level `k` starts from, if
    /// it starts from one.
    pub fn block(&self, k: usize) -> Option<&crate::reference::TripleBlock> {
        self.blocks.iter().find(|b| b.level as usize == k)
    }

    /// Every block of the reference kept, finest first.
    pub(crate) fn blocks(&self) -> &[crate::reference::TripleBlock] {
        &self.blocks
    }

    /// Rebuilds derived data around stored levels (used by `load`).
    pub(crate) fn from_stored(
        exemplars: ExemplarSet,
        params: AnalysisParams,
        layout: Layout,
        stored: Vec<StoredLevel>,
        blocks: Vec<crate::reference::TripleBlock>,
        report: PrecomputeReport,
    ) -> Result<Candidates> {
        params.validate()?;
        // One block per level the parameters start from, finest first.
        let want: Vec<u32> = params.reference_levels().collect();
        let have: Vec<u32> = blocks.iter().map(|b| b.level).collect();
        if want != have {
            return Err(Error::CorruptFile(crate::error::CorruptKind::Invalid(
                "reference blocks".into(),
            )));
        }
        let analysed = layout.apply(&exemplars)?;
        let dims = Dims::new(analysed.width(), analysed.height());
        if stored.len() != params.levels as usize {
            return Err(Error::CorruptFile(crate::error::CorruptKind::Invalid(
                "level count".into(),
            )));
        }
        let stacks = build_stacks(&analysed, stored.len(), &params);
        let single = analysed.is_single();
        let appearance = stored
            .iter()
            .enumerate()
            .map(|(k, s)| {
                level_appearance(&stacks, k, params.neighbourhood, &s.appearance_pca, single)
            })
            .collect();
        let levels = derive_levels(stored, appearance, single, layout.arrangement.weights);
        Ok(Candidates {
            exemplars,
            analysed,
            layout,
            params,
            dims,
            stacks,
            levels,
            blocks,
            report,
            digest: std::sync::OnceLock::new(),
        })
    }

    /// Writes the `.stx` form.
    pub fn save(&self, w: &mut dyn std::io::Write) -> Result<()> {
        let bytes = format::encode(self);
        w.write_all(&bytes)?;
        Ok(())
    }

    /// The `.stx` form as bytes.
    pub fn to_bytes(&self) -> Vec<u8> {
        format::encode(self)
    }

    /// Reads the `.stx` form; a truncated, corrupt or foreign file is an
    /// error.
    pub fn load(bytes: &[u8]) -> Result<Candidates> {
        let c = format::decode(bytes)?;
        _ = c.digest.set(crate::hash::fingerprint(bytes));
        Ok(c)
    }

    /// A fingerprint of the content: equal candidates loaded from the same
    /// file, or computed once, share it; different ones differ.
    pub(crate) fn digest(&self) -> u64 {
        *self
            .digest
            .get_or_init(|| crate::hash::fingerprint(&self.to_bytes()))
    }

    /// The exemplars as given.
    pub fn exemplars(&self) -> &ExemplarSet {
        &self.exemplars
    }

    /// The exemplars as analysed and synthesized from: each plane's turned
    /// by [`Candidates::layout`].
    pub fn analysed(&self) -> &ExemplarSet {
        &self.analysed
    }

    /// How the exemplar is laid on the planes, and what was measured to
    /// choose it.
    pub fn layout(&self) -> &Layout {
        &self.layout
    }

    /// The analysis parameters.
    pub fn params(&self) -> &AnalysisParams {
        &self.params
    }

    /// Exemplar size.
    pub fn dims(&self) -> Dims {
        self.dims
    }

    /// Precomputation summary.
    pub fn report(&self) -> &PrecomputeReport {
        &self.report
    }

    /// Number of levels (finest is 0).
    pub fn level_count(&self) -> usize {
        self.levels.len()
    }

    /// Level `k` (0 = finest).
    pub fn level(&self, k: usize) -> &Level {
        &self.levels[k]
    }

    /// Gaussian stack of plane `p`.
    pub fn stack(&self, p: usize) -> &GaussianStack {
        &self.stacks[p]
    }

    pub(crate) fn stored_levels(&self) -> impl Iterator<Item = &StoredLevel> {
        self.levels.iter().map(|l| &l.stored)
    }

    /// Crossbar error of any triple at level `k`, from the stacks.
    pub fn crossbar_error(&self, k: usize, t: [u32; 3]) -> f32 {
        triple_error(&self.stacks, k, self.params.neighbourhood, self.dims, t)
    }

    /// Bytes held by the candidate triples in their stored form (two
    /// foreign coordinates per triple, a count per pixel), and bytes of
    /// everything held in memory, derived data included (the appearance
    /// correction's tables once a texture has built them).
    pub fn memory_bytes(&self) -> (usize, usize) {
        let coord_bits = (self.dims.len() as f64).log2().ceil() as usize;
        let mut compact = 0usize;
        let mut total = 0usize;
        for l in &self.levels {
            let planes = if self.analysed.is_single() { 1 } else { 3 };
            for p in 0..planes {
                let c = &l.stored.candidates[p];
                compact += (c.triples.len() * 2 * coord_bits).div_ceil(8) + self.dims.len();
            }
            for p in 0..3 {
                let c = &l.stored.candidates[p];
                total += c.triples.len() * 16 + c.offsets.len() * 4;
                total += l.stored.similar[p].len() * 4;
                total += l.appearance[p].vectors.len() * 4;
            }
            total += l.sparse.get().map_or(0, |t| t.memory_bytes());
        }
        for s in &self.stacks {
            total += s.len() * self.dims.len() * 12;
        }
        (compact, total)
    }
}

trait PopSingle {
    fn pop_single(self) -> PlaneCandidates;
}

/// What every precompute stage reads.
#[derive(Clone, Copy)]
struct Stages<'a> {
    stacks: &'a [GaussianStack; 3],
    dims: Dims,
    params: &'a AnalysisParams,
    single: bool,
    progress: &'a (dyn Fn(Stage, f32) + Sync),
    cancel: Option<&'a CancelFlag>,
}

impl Stages<'_> {
    /// Unwinds out of the precompute if it was cancelled; else reports
    /// `stage` done to `fraction`.
    fn advance(&self, stage: Stage, fraction: f32) {
        self.checkpoint();
        (self.progress)(stage, fraction);
    }

    /// Unwinds out of the precompute if it was cancelled.
    fn checkpoint(&self) {
        if let Some(c) = self.cancel {
            c.unwind_if_set();
        }
    }

    /// Appearance PCA of every level's N×N neighbourhoods, per plane (fitted on
    /// a sample of pixels).
    fn fit_appearance(&self) -> Vec<[Pca; 3]> {
        let (levels_n, n) = (self.params.levels as usize, self.params.neighbourhood);
        let mut appearance_pca: Vec<[Pca; 3]> = Vec::new();
        for k in 0..levels_n {
            let fit = |p: usize| {
                self.checkpoint();
                let all = appearance::all_neighbourhoods(&self.stacks[p], k, n);
                let stride = (self.dims.len() / 8192).max(1);
                let len = (n * n) as usize * self.stacks[p].channels();
                let sample: Vec<f32> = all
                    .chunks_exact(len)
                    .step_by(stride)
                    .flatten()
                    .copied()
                    .collect();
                Pca::fit(&sample, len, self.params.pca_dims as usize)
            };
            let first = fit(0);
            let pcas = if self.single {
                [first.clone(), first.clone(), first]
            } else {
                [first, fit(1), fit(2)]
            };
            appearance_pca.push(pcas);
            self.advance(Stage::Analysis, (k + 1) as f32 / levels_n as f32);
        }
        appearance_pca
    }

    /// Per level and searched plane, every pixel's best triples by crossbar
    /// error (Dong et al.'s candidate search).
    fn search_levels(&self) -> Vec<Vec<Vec<Vec<Scored>>>> {
        let (levels_n, n) = (self.params.levels as usize, self.params.neighbourhood);
        let mut raw_lists: Vec<Vec<Vec<Vec<Scored>>>> = Vec::new();
        for k in 0..levels_n {
            let strips: Vec<Strips> = if self.single {
                vec![Strips::new(&self.stacks[0], k, n)]
            } else {
                (0..3).map(|p| Strips::new(&self.stacks[p], k, n)).collect()
            };
            let refs: [&Strips; 3] = if self.single {
                [&strips[0], &strips[0], &strips[0]]
            } else {
                [&strips[0], &strips[1], &strips[2]]
            };
            let planes = if self.single { 1 } else { 3 };
            let per_plane: Vec<Vec<Vec<Scored>>> = (0..planes)
                .map(|p| {
                    search::search_plane(
                        p,
                        refs,
                        self.dims,
                        self.params.strips as usize,
                        self.params.triples as usize,
                        self.cancel,
                    )
                })
                .collect();
            raw_lists.push(per_plane);
            self.advance(Stage::Search, (k + 1) as f32 / levels_n as f32);
        }
        raw_lists
    }

    /// The searched lists filtered for coherence, per level and plane, with
    /// each level's report.
    fn filter_levels(
        &self,
        raw_lists: Vec<Vec<Vec<Vec<Scored>>>>,
        report: &mut PrecomputeReport,
    ) -> Vec<[PlaneCandidates; 3]> {
        let (levels_n, n) = (self.params.levels as usize, self.params.neighbourhood);
        let mut filtered_levels: Vec<[PlaneCandidates; 3]> = Vec::new();
        for (k, per_plane) in raw_lists.into_iter().enumerate() {
            let h = spacing(k) as i64;
            let mut level_report = LevelReport {
                histogram: vec![0; self.params.max_candidates as usize + 1],
                ..Default::default()
            };
            let mut planes: Vec<PlaneCandidates> = Vec::new();
            for (p, lists) in per_plane.into_iter().enumerate() {
                let f = coherence::filter(
                    p,
                    lists,
                    self.dims,
                    h,
                    self.params.max_candidates as usize,
                    self.cancel,
                );
                let copies = if self.single { 3 } else { 1 };
                for l in &f.lists {
                    level_report.histogram[l.len()] += copies;
                }
                level_report.fallbacks += f.fallbacks as u64 * copies;
                level_report.iterations = level_report.iterations.max(f.iterations as u32);
                planes.push(PlaneCandidates::from_lists(&f.lists));
            }
            let planes: [PlaneCandidates; 3] = if self.single {
                let base = planes.pop_single();
                [base.clone(), base.rotated(1), base.rotated(2)]
            } else {
                planes.try_into().expect("three planes")
            };
            level_report.mean_best_error = mean_best_error(&planes);
            level_report.mean_random_error = mean_random_error(self.stacks, k, n, self.dims);
            report.levels.push(level_report);
            filtered_levels.push(planes);
            self.advance(Stage::Coherence, (k + 1) as f32 / levels_n as f32);
        }
        filtered_levels
    }

    /// What is stored per level: the candidates with their appearance PCA
    /// and similarity sets; and each level's appearance vectors.
    fn finish_levels(
        &self,
        filtered_levels: Vec<[PlaneCandidates; 3]>,
        appearance_pca: Vec<[Pca; 3]>,
    ) -> (Vec<StoredLevel>, Vec<[AppearanceLevel; 3]>) {
        let (levels_n, n) = (self.params.levels as usize, self.params.neighbourhood);
        let mut stored = Vec::new();
        let mut vectors = Vec::new();
        for (k, candidates) in filtered_levels.into_iter().enumerate() {
            let pcas = appearance_pca[k].clone();
            let appearance = level_appearance(self.stacks, k, n, &pcas, self.single);
            let k2 = if k == 0 {
                self.params.similar_fine
            } else {
                self.params.similar_coarse
            } as usize;
            self.checkpoint();
            let similar_0 = similar_sets(&appearance[0], self.dims, k2, spacing(k) as i64);
            let similar = if self.single {
                [similar_0.clone(), similar_0.clone(), similar_0]
            } else {
                [
                    similar_0,
                    similar_sets(&appearance[1], self.dims, k2, spacing(k) as i64),
                    similar_sets(&appearance[2], self.dims, k2, spacing(k) as i64),
                ]
            };
            stored.push(StoredLevel {
                appearance_pca: pcas,
                candidates,
                similar,
                k2,
            });
            vectors.push(appearance);
            self.advance(Stage::Finish, (k + 1) as f32 / levels_n as f32);
        }
        (stored, vectors)
    }
}

impl PopSingle for Vec<PlaneCandidates> {
    fn pop_single(mut self) -> PlaneCandidates {
        self.pop().expect("one plane")
    }
}

/// Each plane's stack, with its feature-distance channel when
/// `feature_weight` is above 0.
fn build_stacks(
    exemplars: &ExemplarSet,
    levels: usize,
    params: &AnalysisParams,
) -> [GaussianStack; 3] {
    let stack = |p: usize| {
        let s = GaussianStack::new(exemplars.plane(p), levels);
        if params.feature_weight > 0.0 {
            s.with_feature(feature::feature_distance(
                exemplars.plane(p),
                params.feature_weight,
            ))
        } else {
            s
        }
    };
    if exemplars.is_single() {
        let s = stack(0);
        [s.clone(), s.clone(), s]
    } else {
        [0, 1, 2].map(stack)
    }
}

/// A level's appearance vectors per plane. `single`: one exemplar serves
/// all three planes, so their stacks and PCAs are equal and the vectors are
/// projected once.
fn level_appearance(
    stacks: &[GaussianStack; 3],
    k: usize,
    n: u32,
    pcas: &[Pca; 3],
    single: bool,
) -> [AppearanceLevel; 3] {
    if single {
        let a = appearance::project_all(&stacks[0], k, n, &pcas[0]);
        [a.clone(), a.clone(), a]
    } else {
        [0, 1, 2].map(|p| appearance::project_all(&stacks[p], k, n, &pcas[p]))
    }
}

/// Joins each stored level with its appearance vectors into the synthesis
/// tables. `single`: one exemplar serves all three planes, so the per-plane
/// 2D tables are computed once.
fn derive_levels(
    stored: Vec<StoredLevel>,
    appearance: Vec<[AppearanceLevel; 3]>,
    single: bool,
    weights: [f32; 3],
) -> Vec<Level> {
    let alias = if single { [0, 0, 0] } else { [0, 1, 2] };
    stored
        .into_iter()
        .zip(appearance)
        .map(|(s, appearance)| Level {
            stored: s,
            appearance,
            alias,
            weights,
            sparse: std::sync::OnceLock::new(),
        })
        .collect()
}

/// The `k2` pixels most similar to each pixel in appearance space, itself
/// first, skipping pixels closer than 2·h (they would only repeat the
/// coherent candidate).
fn similar_sets(app: &AppearanceLevel, dims: Dims, k2: usize, h: i64) -> Vec<u32> {
    let d = app.pca.dims.min(SIMILAR_DIMS);
    let point = |c: usize| {
        let mut p = [0f32; SIMILAR_DIMS];
        p[..d].copy_from_slice(&app.vector(c)[..d]);
        p
    };
    let pts: Vec<[f32; SIMILAR_DIMS]> = (0..dims.len()).map(point).collect();
    let tree: kiddo::ImmutableKdTree<f32, SIMILAR_DIMS> =
        kiddo::ImmutableKdTree::new_from_slice(&pts);
    let want = NonZero::new((k2 * 6 + 1).min(dims.len())).expect("non-empty");
    let (w, hh) = (dims.w as i64, dims.h as i64);
    (0..dims.len())
        .into_par_iter()
        .map(|c| {
            let mut nn = tree.nearest_n::<SquaredEuclidean>(&pts[c], want);
            nn.sort_by(|a, b| a.distance.total_cmp(&b.distance).then(a.item.cmp(&b.item)));
            let (cx, cy) = dims.xy(c as u32);
            let mut out = vec![c as u32];
            for n in nn {
                if out.len() == k2 {
                    break;
                }
                let (x, y) = dims.xy(n.item as u32);
                let dx = (x - cx).rem_euclid(w).min((cx - x).rem_euclid(w));
                let dy = (y - cy).rem_euclid(hh).min((cy - y).rem_euclid(hh));
                if dx.max(dy) >= 2 * h {
                    out.push(n.item as u32);
                }
            }
            while out.len() < k2 {
                out.push(c as u32);
            }
            out
        })
        .flatten()
        .collect()
}

fn triple_error(stacks: &[GaussianStack; 3], k: usize, n: u32, dims: Dims, t: [u32; 3]) -> f32 {
    let r = (n / 2) as i64;
    let h = spacing(k) as i64;
    let mut e = 0f32;
    for p in 0..3 {
        let next = (p + 1) % 3;
        let (px, py) = dims.xy(t[p]);
        let (nx, ny) = dims.xy(t[next]);
        for s in -r..=r {
            // p's v-strip against next's u-strip.
            let a = stacks[p].at(k, px, py + s * h);
            let b = stacks[next].at(k, nx + s * h, ny);
            e += (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f32>();
        }
    }
    e
}

fn mean_best_error(planes: &[PlaneCandidates; 3]) -> f64 {
    let mut sum = 0f64;
    let mut count = 0usize;
    for c in planes {
        for px in 0..c.offsets.len() - 1 {
            let r = c.range(px as u32);
            if !r.is_empty() {
                sum += c.errors[r.start] as f64;
                count += 1;
            }
        }
    }
    sum / count.max(1) as f64
}

fn mean_random_error(stacks: &[GaussianStack; 3], k: usize, n: u32, dims: Dims) -> f64 {
    let samples = 2000u64;
    let mut sum = 0f64;
    for i in 0..samples {
        let t =
            [0u64, 1, 2].map(|p| (crate::hash::hash3(0x5eed, i, p, 0) % dims.len() as u64) as u32);
        sum += triple_error(stacks, k, n, dims, t) as f64;
    }
    sum / samples as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::exemplar::Exemplar;
    use crate::synth::correction::tables;

    fn pattern(w: u32, seed: u32) -> Exemplar {
        let rgb: Vec<u8> = (0..w * w * 3)
            .map(|i| ((i ^ seed.wrapping_mul(0x9e37_79b9)).wrapping_mul(2_654_435_761) >> 24) as u8)
            .collect();
        Exemplar::from_rgb(w, w, &rgb).unwrap()
    }

    fn compute(set: &ExemplarSet) -> Candidates {
        let params = AnalysisParams {
            levels: 2,
            ..AnalysisParams::default()
        };
        Candidates::compute(set, &params, &|_, _| {}).unwrap()
    }

    #[test]
    fn a_cancelled_precompute_unwinds_out_of_any_stage() {
        use crate::synth::cancel::{Cancelled, run_cancellable};
        let set = ExemplarSet::single(pattern(32, 2));
        let params = AnalysisParams {
            levels: 2,
            ..AnalysisParams::default()
        };
        // Cancelled as each stage reports, in turn: the search's workers
        // and the stages' own loops see it. Nothing else is reported after.
        for stop_at in [Stage::Analysis, Stage::Search, Stage::Coherence] {
            let flag = CancelFlag::new();
            let after = std::sync::atomic::AtomicU32::new(0);
            let progress = |stage: Stage, _: f32| {
                if flag.is_cancelled() {
                    after.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                }
                if stage == stop_at {
                    flag.cancel();
                }
            };
            let r = run_cancellable(&flag, || Candidates::compute(&set, &params, &progress));
            assert_eq!(r.err(), Some(Cancelled), "{stop_at:?}");
            assert_eq!(after.into_inner(), 0, "{stop_at:?}");
        }
        // A flag never set changes nothing.
        let flag = CancelFlag::new();
        let r = run_cancellable(&flag, || Candidates::compute(&set, &params, &|_, _| {}));
        assert!(r.unwrap().is_ok());
    }

    /// A query is projected unweighted and the tables hold weighted
    /// vectors: a triple's own 12 locations, as a query, must land on the
    /// triple's vector, and the weights must change what is compared.
    #[test]
    fn weighted_planes_are_weighted_alike_in_tables_and_queries() {
        let e = pattern(16, 4);
        let tables_for = |weights: [f32; 3]| {
            let params = AnalysisParams {
                levels: 1,
                orientation: crate::params::Orientation::Given(crate::params::Arrangement {
                    rotate: [0, 270, 0],
                    weights,
                }),
                ..AnalysisParams::default()
            };
            Candidates::compute(&ExemplarSet::single(e.clone()), &params, &|_, _| {}).unwrap()
        };
        let weighted = tables_for([1.0, 0.5, 0.1]);
        let even = tables_for([1.0; 3]);
        let (level, dims) = (weighted.level(0), weighted.dims());
        let tables = level.sparse_tables(dims, 0);
        let d = tables.location_dims();
        let mut worst = 0;
        for px in 0..dims.len() as u32 {
            let t = tables.best(1, px).triples[0];
            let mut q = Vec::with_capacity(12 * d);
            for (p, &c) in t.iter().enumerate() {
                for &(i, j) in &tables::DIAGONALS {
                    let at = dims.shift(c, i, j) as usize;
                    q.extend_from_slice(level.appearance[p].vector(at));
                }
            }
            let got = tables.project(&q);
            worst = worst.max(crate::simd::distance(&got, &tables.triple_vector(t)));
        }
        // Shares are rounded one by one (three and the bias), so a triple's
        // vector is within 2 units per dimension of the direct projection;
        // an unweighted query side would be thousands away.
        assert!(worst <= 4 * tables::SPARSE_DIMS as u32, "{worst}");
        let other = even.level(0).sparse_tables(dims, 0);
        assert_ne!(other.best(1, 0).vectors, tables.best(1, 0).vectors);
        assert_eq!(other.best(1, 0).triples, tables.best(1, 0).triples);
    }

    /// Planes 1 and 2 of a single exemplar read plane 0's 2D tables, which
    /// is only right while the three planes' tables are equal.
    #[test]
    fn single_exemplar_planes_share_equal_2d_tables() {
        let single = compute(&ExemplarSet::single(pattern(16, 1)));
        for level in &single.levels {
            assert_eq!(level.alias, [0, 0, 0]);
            for p in 1..3 {
                assert_eq!(level.stored.similar[p], level.stored.similar[0]);
                assert_eq!(level.appearance[p].vectors, level.appearance[0].vectors);
            }
        }
        let reloaded = Candidates::load(&single.to_bytes()).unwrap();
        assert!(reloaded.levels.iter().all(|l| l.alias == [0, 0, 0]));

        let triple =
            compute(&ExemplarSet::triple(pattern(16, 1), pattern(16, 2), pattern(16, 3)).unwrap());
        for level in &triple.levels {
            assert_eq!(level.alias, [0, 1, 2]);
            assert_ne!(level.stored.similar[1], level.stored.similar[0]);
            assert_eq!(level.stored.similar[2].len(), level.stored.similar[0].len());
        }
    }
}
