//! Lazy, spatially deterministic pyramid synthesis (Dong et al. 2008 with
//! Zhang et al. 2011's history windows and dual-grid correction).
//!
//! Each level k (0 = finest) holds a coordinate triple per voxel. Version 0
//! of a level comes from the jittered candidate slab (coarsest synthesized
//! level) or from upsampling the parent level; correction steps refine it.
//! A correction's history window ([`history`]) says which version of each
//! neighbour it reads:
//!
//! - **standard** (Dong et al.): the latest version of every neighbour, so
//!   the dependency set grows by N/2 with every subpass;
//! - **dual grid** (Zhang et al., [`dual_grid`]): ⌈P/2⌉ passes on a grid of
//!   M³ cells, then ⌊P/2⌋ on the grid shifted by M/2; a neighbour across the
//!   cell wall is read at the version the step started from, which bounds
//!   the set.
//!
//! Each level's [`schedule::LevelSchedule`] (steps, subpass classes, history
//! window, reach) is built once with the texture and read by the planner,
//! the synthesis and the estimator alike.
//!
//! A request is answered from final-version tiles (level-aligned cubes of
//! [`TILE`] voxels) kept in the shared [`cache::TileCache`]. Missing tiles of
//! a level are synthesized together: [`plan::backward`] walks the history
//! windows back from them to the exact voxels each subpass must correct and
//! the version-0 voxels needed, whose parents come from the parent level's
//! tiles (recursively), and only those voxels are computed. What a request
//! computes beyond what it was asked for is kept where it is reusable: every
//! voxel it corrects, with its value after that pass (final after the last
//! pass), so overlapping requests end their chains on it.

pub mod cache;
pub mod cancel;
pub(crate) mod colour;
pub mod correction;
pub mod dual_grid;
pub mod estimate;
pub mod grid;
mod group;
pub mod history;
pub mod init;
mod inspect;
#[cfg(test)]
mod periodic_tests;
pub mod plan;
pub mod schedule;
mod stats;

use crate::candidates::Candidates;
use crate::error::Result;
use crate::field::FrameField;
use crate::params::SynthParams;
use crate::period::Period;
use crate::request::{CutPlane, Filter, Region};
use cache::{Claim, Tile, TileCache, TileKey};
use colour::{colour, rgb8, triple_rgb8};
use grid::{Box3, Grid};
pub use inspect::SlabViews;
use rayon::prelude::*;
use rustc_hash::FxHashMap as HashMap;
use schedule::LevelSchedule;
pub use stats::SynthStats;
use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

/// Side of the final-version tiles cached per level (TILE³ = 64 voxels,
/// one bit each in a tile's mask).
pub const TILE: i64 = 4;

/// Voxels wanted per tile: cell → mask of its voxels.
type Wanted = BTreeMap<[i64; 3], u64>;

/// Most tiles synthesized together in one group (bounds working memory).
/// Neighbouring groups share their halos through the cached after-pass
/// voxels, so smaller groups cost little time and save much resident
/// memory on large slices (docs/quality.md, "Cost of a correction").
const MAX_GROUP_TILES: usize = 4096;

/// Counters gathered while serving one request.
pub(crate) struct Acc {
    voxels: Vec<AtomicU64>,
    corrections: Vec<AtomicU64>,
    computed: AtomicU64,
    cached: AtomicU64,
    /// Count the work without doing it (tiles hold zeros).
    dry: bool,
    /// The request's cancellation flag (see [`cancel`]).
    cancel: Option<cancel::CancelFlag>,
}

impl Acc {
    fn new(levels: usize, dry: bool) -> Acc {
        Acc {
            dry,
            cancel: cancel::current(),
            voxels: (0..levels).map(|_| AtomicU64::new(0)).collect(),
            corrections: (0..levels).map(|_| AtomicU64::new(0)).collect(),
            computed: AtomicU64::new(0),
            cached: AtomicU64::new(0),
        }
    }

    fn stats(&self) -> SynthStats {
        SynthStats {
            voxels_per_level: self
                .voxels
                .iter()
                .map(|a| a.load(Ordering::Relaxed))
                .collect(),
            corrections_per_level: self
                .corrections
                .iter()
                .map(|a| a.load(Ordering::Relaxed))
                .collect(),
            tiles_computed: self.computed.load(Ordering::Relaxed),
            tiles_from_cache: self.cached.load(Ordering::Relaxed),
        }
    }
}

/// The synthesis engine behind a [`crate::Texture`].
pub(crate) struct Engine {
    cands: Arc<Candidates>,
    params: SynthParams,
    /// The texture's field of local frames, ready to read.
    field: Option<Arc<FrameField>>,
    cache: Arc<TileCache>,
    key: u64,
    init_level: usize,
    /// The solid's period, if it has one.
    period: Option<Period>,
    /// Whether a tile and its copies a period away share one cache key
    /// (always, but in the tests that synthesize copies apart to check
    /// that they come out the same).
    share_copies: bool,
    /// How each level is corrected, finest first.
    schedules: Vec<LevelSchedule>,
}

impl Engine {
    pub(crate) fn new(
        cands: Arc<Candidates>,
        params: SynthParams,
        cache: Arc<TileCache>,
    ) -> Result<Self> {
        if let Some(p) = params.period {
            crate::period::check(p, cands.level_count(), &params)?;
        }
        let period = Period::of(&params);
        let field = params
            .field
            .as_ref()
            .map(|f| f.compile().map(|f| Arc::new(f.repeating(period.as_ref()))))
            .transpose()?;
        let mut bytes = cands.digest().to_le_bytes().to_vec();
        bytes.extend_from_slice(&serde_json::to_vec(&params).expect("params serialise"));
        let key = crate::hash::fingerprint(&bytes);
        // The appearance tables are built with the texture, not by its
        // first request.
        (0..cands.level_count())
            .into_par_iter()
            .for_each(|k| _ = cands.level(k).sparse_tables(cands.dims(), k));
        let init_level = cands.level_count() - 1;
        let schedules = (0..=init_level)
            .map(|k| {
                LevelSchedule::of_level(&params, period.as_ref(), k, init_level, correction::REACH)
            })
            .collect();
        Ok(Engine {
            init_level,
            period,
            share_copies: true,
            cands,
            params,
            field,
            cache,
            key,
            schedules,
        })
    }

    /// The texture's field, ready to read.
    pub(crate) fn field(&self) -> Option<&FrameField> {
        self.field.as_deref()
    }

    /// The period whose copies of a tile share its key.
    fn shared_period(&self) -> Option<Period> {
        self.period.filter(|_| self.share_copies)
    }

    /// The period at level `k` of a periodic solid.
    /// The levels a request at level of detail `lod` reaches: from `lod`
    /// up to the first level that starts from a block of the reference, or
    /// to the coarsest.
    pub(crate) fn chain(&self, lod: u32) -> std::ops::RangeInclusive<usize> {
        let lod = lod as usize;
        let start = (lod..self.init_level)
            .find(|&k| self.cands.block(k).is_some())
            .unwrap_or(self.init_level);
        lod..=start
    }

    pub(crate) fn period_at(&self, k: usize) -> Option<[i64; 3]> {
        self.period.map(|p| p.at(k))
    }

    /// How far a correction reads, in voxels of its level.
    pub(crate) fn radius(&self) -> i64 {
        correction::REACH
    }

    pub(crate) fn shared_candidates(&self) -> &Arc<Candidates> {
        &self.cands
    }

    pub(crate) fn candidates(&self) -> &Candidates {
        &self.cands
    }

    pub(crate) fn params(&self) -> &SynthParams {
        &self.params
    }

    pub(crate) fn max_lod(&self) -> u32 {
        self.init_level as u32
    }

    /// How level `k` is corrected.
    pub(crate) fn schedule(&self, k: usize) -> &LevelSchedule {
        &self.schedules[k]
    }

    fn tile_of(p: [i64; 3]) -> [i64; 3] {
        p.map(|v| v.div_euclid(TILE))
    }

    fn tile_box(t: [i64; 3]) -> Box3 {
        Box3::new(t.map(|v| v * TILE), [TILE; 3])
    }

    /// Bit of voxel `p` in its tile's mask.
    #[inline]
    fn bit_of(p: [i64; 3]) -> u64 {
        let l = p.map(|v| v.rem_euclid(TILE));
        1 << (l[0] + TILE * (l[1] + TILE * l[2]))
    }

    /// The voxels of `b`, tile by tile.
    fn wanted_box(b: &Box3) -> Wanted {
        let lo = Self::tile_of(b.lo);
        let hi = Self::tile_of(b.hi.map(|v| v - 1));
        let mut out = Wanted::new();
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    let t = Self::tile_box([x, y, z]).intersect(b);
                    let mut mask = 0u64;
                    for pz in t.lo[2]..t.hi[2] {
                        for py in t.lo[1]..t.hi[1] {
                            for px in t.lo[0]..t.hi[0] {
                                mask |= Self::bit_of([px, py, pz]);
                            }
                        }
                    }
                    out.insert([x, y, z], mask);
                }
            }
        }
        out
    }

    /// Final triples of level `k` over `b`.
    pub(crate) fn level_box(&self, k: usize, b: &Box3, acc: &Acc) -> Grid<[u32; 3]> {
        let tiles = self.tiles(k, Self::wanted_box(b), acc);
        let mut g = Grid::new(*b);
        for t in tiles.values() {
            t.copy_into(&mut g);
        }
        g
    }

    /// Final tiles of level `k` holding at least the wanted voxels, from
    /// the cache or computed. In a periodic solid a tile is its copy in the
    /// period at the origin: the wanted voxels of all copies are gathered
    /// there, synthesized once, and each copy gets the tile moved to its
    /// place.
    fn tiles(&self, k: usize, wanted: Wanted, acc: &Acc) -> HashMap<[i64; 3], Tile> {
        let Some(period) = self.shared_period() else {
            return self.tiles_at_home(k, wanted, acc);
        };
        let mut home = Wanted::new();
        for (&c, &mask) in &wanted {
            *home.entry(period.wrap_tile(k, c)).or_default() |= mask;
        }
        let found = self.tiles_at_home(k, home, acc);
        wanted
            .keys()
            .map(|&c| {
                let t = &found[&period.wrap_tile(k, c)];
                let origin = Self::tile_box(c).lo;
                let t = if t.origin() == origin {
                    t.clone()
                } else {
                    Arc::new(t.moved_to(origin))
                };
                (c, t)
            })
            .collect()
    }

    /// [`Engine::tiles`] for tiles that are their own keys; a tile another
    /// request is computing is waited for (outside rayon).
    fn tiles_at_home(&self, k: usize, wanted: Wanted, acc: &Acc) -> HashMap<[i64; 3], Tile> {
        let mut out = HashMap::default();
        let mut mine = Vec::new();
        let mut theirs = Vec::new();
        let in_pool = rayon::current_thread_index().is_some();
        let mut unclaimed = Vec::new();
        let keys: Vec<(TileKey, u64)> = wanted
            .iter()
            .map(|(&c, &want)| (self.version_key(k, 0, c), want))
            .collect();
        for ((key, want), claim) in keys.iter().zip(self.cache.claim_all(&keys)) {
            let (c, want) = (key.cell, *want);
            match claim {
                Claim::Ready(t) => {
                    acc.cached.fetch_add(1, Ordering::Relaxed);
                    out.insert(c, t);
                }
                Claim::Mine(ticket) => mine.push(ticket),
                // Blocking a rayon worker on another computation could
                // deadlock the pool, so inside it we compute instead.
                Claim::Wait(_) if in_pool => unclaimed.push((c, want)),
                Claim::Wait(w) => theirs.push(w),
            }
        }
        // Voxels the cache already holds are not computed again.
        let mut todo: Vec<([i64; 3], u64)> = mine
            .iter()
            .map(|t| {
                let known = t.partial().map_or(0, |p| p.mask);
                if known != 0 {
                    acc.cached.fetch_add(1, Ordering::Relaxed);
                }
                (t.key().cell, wanted[&t.key().cell] & !known)
            })
            .collect();
        todo.extend(&unclaimed);
        if !todo.is_empty() {
            let mut computed = self.compute(k, &todo, acc);
            acc.computed
                .fetch_add(computed.len() as u64, Ordering::Relaxed);
            for ticket in mine {
                let c = ticket.key().cell;
                let mut t = computed.remove(&c).expect("computed");
                if let Some(p) = ticket.partial() {
                    t = Arc::new(p.merged(&t));
                }
                self.cache.publish(ticket, t.clone());
                out.insert(c, t);
            }
            out.extend(computed);
        }
        for w in theirs {
            let c = w.key().cell;
            let want = wanted[&c];
            match self.cache.wait(w).filter(|t| t.covers(want)) {
                Some(t) => {
                    acc.cached.fetch_add(1, Ordering::Relaxed);
                    out.insert(c, t);
                }
                None => {
                    let mut t = self.compute(k, &[(c, want)], acc);
                    acc.computed.fetch_add(1, Ordering::Relaxed);
                    out.insert(c, t.remove(&c).expect("one tile"));
                }
            }
        }
        out
    }

    /// Key of the values after pass `pass` (counted over all steps from 0)
    /// of level `k` in tile `cell`: the version after `pass + 1` passes, or
    /// the final version after the last pass.
    fn after_pass_key(&self, k: usize, pass: usize, cell: [i64; 3]) -> TileKey {
        let version = self.schedule(k).version_after_pass(pass);
        self.version_key(k, version, cell)
    }

    /// Key of the version after `done` correction passes of level `k` (0:
    /// the final version) in tile `cell` (in a periodic solid, shared by
    /// its copies).
    fn version_key(&self, k: usize, done: usize, cell: [i64; 3]) -> TileKey {
        TileKey {
            texture: self.key,
            level: k as u8,
            version: done as u8,
            cell: self.shared_period().map_or(cell, |p| p.wrap_tile(k, cell)),
        }
    }

    pub(crate) fn new_acc(&self) -> Acc {
        Acc::new(self.init_level + 1, false)
    }

    /// Counts what synthesizing `r` from a cold cache would compute, per
    /// level, without computing it.
    pub(crate) fn plan_region(&self, r: &Region, lod: u32) -> SynthStats {
        let acc = Acc::new(self.init_level + 1, true);
        let b = Box3::from(r);
        self.dry().level_box(lod as usize, &b, &acc);
        acc.stats()
    }

    /// Counts what the cut `plane` would compute from a cold cache.
    pub(crate) fn plan_cut(&self, plane: &CutPlane, lod: u32, filter: Filter) -> SynthStats {
        self.plan_samples(&plane_points(plane), lod, filter)
    }

    /// Counts what the voxels `points` would compute from a cold cache.
    pub(crate) fn plan_points(&self, points: &[[i64; 3]], lod: u32) -> SynthStats {
        let acc = Acc::new(self.init_level + 1, true);
        self.dry().tiles(lod as usize, wanted_points(points), &acc);
        acc.stats()
    }

    /// The same engine over a private, unbounded cache, for counting.
    fn dry(&self) -> Engine {
        Engine {
            cands: self.cands.clone(),
            params: self.params.clone(),
            field: self.field.clone(),
            cache: Arc::new(TileCache::new(usize::MAX)),
            key: self.key,
            init_level: self.init_level,
            period: self.period,
            share_copies: self.share_copies,
            schedules: self.schedules.clone(),
        }
    }

    /// An upper bound of what [`Engine::plan_region`] counts, found without
    /// walking voxels (see [`estimate`]); counting stops past `limit`.
    pub(crate) fn estimate_region(
        &self,
        r: &Region,
        lod: u32,
        limit: u64,
    ) -> estimate::WorkEstimate {
        let piece = estimate::Piece::region(r.origin, r.size);
        estimate::estimate(piece, &self.reach_from(lod), MAX_GROUP_TILES, limit)
    }

    /// An upper bound of what [`Engine::plan_cut`] counts.
    pub(crate) fn estimate_cut(
        &self,
        plane: &CutPlane,
        lod: u32,
        filter: Filter,
        limit: u64,
    ) -> estimate::WorkEstimate {
        let piece = estimate::Piece::cut(
            plane.origin,
            plane.u,
            plane.v,
            plane.width,
            plane.height,
            filter == Filter::Trilinear,
        );
        estimate::estimate(piece, &self.reach_from(lod), MAX_GROUP_TILES, limit)
    }

    /// An upper bound of what [`Engine::plan_points`] counts: the sum of
    /// each voxel's own bound (the chain of a set of voxels lies in the
    /// union of their chains).
    pub(crate) fn estimate_points(
        &self,
        points: &[[i64; 3]],
        lod: u32,
        limit: u64,
    ) -> estimate::WorkEstimate {
        self.estimate_boxes(points.iter().map(|&p| (p, [1; 3])), lod, limit)
    }

    /// The sum of the bounds of boxes (origin, size), stopping past `limit`.
    fn estimate_boxes(
        &self,
        boxes: impl Iterator<Item = ([i64; 3], [u32; 3])>,
        lod: u32,
        limit: u64,
    ) -> estimate::WorkEstimate {
        let reach = &self.reach_from(lod);
        let mut out = estimate::WorkEstimate {
            per_level: vec![0; reach.len()],
            total: 0,
            complete: true,
        };
        for (origin, size) in boxes {
            let left = limit.saturating_sub(out.total);
            let one = estimate::estimate(
                estimate::Piece::region(origin, size),
                reach,
                MAX_GROUP_TILES,
                left,
            );
            for (sum, n) in out.per_level.iter_mut().zip(&one.per_level) {
                *sum = sum.saturating_add(*n);
            }
            out.total = out.total.saturating_add(one.total);
            if !one.complete || out.total > limit {
                out.complete = false;
                break;
            }
        }
        out
    }

    /// How far the chain of each level reaches, from level `lod` on.
    fn reach_from(&self, lod: u32) -> Vec<plan::Reach> {
        self.schedules[self.chain(lod)]
            .iter()
            .map(|s| s.reach)
            .collect()
    }

    /// Exact voxel-level dependency chain of a few voxels (see
    /// [`plan::exact_chain`]).
    /// `radius` is the neighbourhood's half side (the analysis's own unless
    /// a caller asks what another N would need).
    pub(crate) fn exact_chain(
        &self,
        voxels: &[[i64; 3]],
        lod: u32,
        radius: i64,
    ) -> Vec<plan::LevelPlan> {
        let schedules: Vec<LevelSchedule> = self.schedules[self.chain(lod)]
            .iter()
            .map(|s| s.with_radius(radius))
            .collect();
        plan::exact_chain(voxels, &schedules, self.field.is_some())
    }

    pub(crate) fn region_rgb(&self, r: &Region, lod: u32) -> Result<(Vec<u8>, SynthStats)> {
        let acc = self.new_acc();
        let b = Box3::from(r);
        let k = lod as usize;
        let g = self.level_box(k, &b, &acc);
        let mut rgb = vec![0u8; g.data.len() * 3];
        rgb.par_chunks_mut(3)
            .zip(g.data.par_iter())
            .for_each(|(dst, t)| dst.copy_from_slice(&triple_rgb8(&self.cands, k, *t)));
        Ok((rgb, acc.stats()))
    }

    /// Final triples at arbitrary voxels of level `k`, fetched tile by tile
    /// so scattered points never pull in their bounding box.
    fn triples_at(&self, k: usize, points: &[[i64; 3]], acc: &Acc) -> Vec<[u32; 3]> {
        let tiles = self.tiles(k, wanted_points(points), acc);
        points
            .iter()
            .map(|p| tiles[&Self::tile_of(*p)].get(*p))
            .collect()
    }

    pub(crate) fn points_rgb(
        &self,
        points: &[[i64; 3]],
        lod: u32,
    ) -> Result<(Vec<u8>, SynthStats)> {
        let acc = self.new_acc();
        let k = lod as usize;
        let triples = self.triples_at(k, points, &acc);
        let out = triples
            .par_iter()
            .flat_map_iter(|t| triple_rgb8(&self.cands, k, *t))
            .collect();
        Ok((out, acc.stats()))
    }

    pub(crate) fn cut_rgb(
        &self,
        plane: &CutPlane,
        lod: u32,
        filter: Filter,
    ) -> Result<(Vec<u8>, SynthStats)> {
        self.samples_rgb(&plane_points(plane), lod, filter)
    }

    /// The colours at points anywhere (in voxels of level of detail `lod`),
    /// read through `filter`, each voxel synthesized once however many
    /// points read it.
    pub(crate) fn samples_rgb(
        &self,
        points: &[[f64; 3]],
        lod: u32,
        filter: Filter,
    ) -> Result<(Vec<u8>, SynthStats)> {
        let (pts, weights) = sample_voxels(points, filter);
        let unique = unique_voxels(&pts);
        let (colours, stats) = self.colours_at(&unique, lod)?;
        Ok((
            filtered_rgb(&pts, &weights, filter, &unique, &colours),
            stats,
        ))
    }

    /// The colours of voxels anywhere at level of detail `lod`, in the
    /// order given.
    pub(crate) fn colours_at(
        &self,
        points: &[[i64; 3]],
        lod: u32,
    ) -> Result<(Vec<[f32; 3]>, SynthStats)> {
        let acc = self.new_acc();
        if points.is_empty() {
            return Ok((Vec::new(), acc.stats()));
        }
        let k = lod as usize;
        let t = self.triples_at(k, points, &acc);
        let colours = t.par_iter().map(|t| colour(&self.cands, k, *t)).collect();
        Ok((colours, acc.stats()))
    }

    /// Counts what the colours at `points` would compute from a cold cache.
    pub(crate) fn plan_samples(&self, points: &[[f64; 3]], lod: u32, filter: Filter) -> SynthStats {
        self.plan_points(&unique_voxels(&sample_voxels(points, filter).0), lod)
    }

    /// An upper bound of what a cold cache computes for the voxels of
    /// `masks` at level of detail `lod` (see [`estimate::grouped_union`]).
    pub(crate) fn estimate_grouped(
        &self,
        masks: &estimate::Masks,
        lod: u32,
        limit: u64,
    ) -> estimate::WorkEstimate {
        estimate::grouped_union(masks, &self.reach_from(lod), MAX_GROUP_TILES, limit)
    }

    /// A guess of what a cold cache computes for the voxels of `masks` at
    /// level of detail `lod` (see [`estimate::union`]).
    pub(crate) fn predict_union(&self, masks: estimate::Masks, lod: u32) -> u64 {
        estimate::union(masks, &self.reach_from(lod))
    }

    /// An upper bound of what synthesizing every voxel of the aligned
    /// cubes of `side` voxels from `corners` would count: a bound for any
    /// voxels inside them.
    pub(crate) fn estimate_blocks(
        &self,
        corners: &[[i64; 3]],
        side: u32,
        lod: u32,
        limit: u64,
    ) -> estimate::WorkEstimate {
        self.estimate_boxes(corners.iter().map(|&o| (o, [side; 3])), lod, limit)
    }
}

/// The voxels of tile `cell` whose bits are set in `mask`, with their
/// index in the tile.
fn tile_voxels(cell: [i64; 3], mask: u64) -> impl Iterator<Item = (usize, [i64; 3])> {
    let b = Engine::tile_box(cell);
    (0..(TILE * TILE * TILE) as usize)
        .filter(move |i| mask >> i & 1 == 1)
        .map(move |i| (i, position(&b, i)))
}

/// Tile masks of the members of `need` divided by `scale` (1: the members
/// themselves, 2: their parents one level up), built one dense layer of
/// tiles at a time in parallel.
fn tile_masks(need: &plan::Mask, scale: i64) -> Wanted {
    let b = need.bounds();
    let lo = Engine::tile_of(b.lo.map(|v| v.div_euclid(scale)));
    let hi = Engine::tile_of(b.hi.map(|v| (v - 1).div_euclid(scale)));
    let (tx, ty) = ((hi[0] - lo[0] + 1) as usize, (hi[1] - lo[1] + 1) as usize);
    let layers: Vec<(i64, Vec<u64>)> = (lo[2]..=hi[2])
        .into_par_iter()
        .map(|tz| {
            let mut masks = vec![0u64; tx * ty];
            let zs = tz * TILE * scale..(tz + 1) * TILE * scale;
            for z in zs.start.max(b.lo[2])..zs.end.min(b.hi[2]) {
                for p in need.layer(z) {
                    let q = p.map(|v| v.div_euclid(scale));
                    let c = Engine::tile_of(q);
                    masks[(c[1] - lo[1]) as usize * tx + (c[0] - lo[0]) as usize] |=
                        Engine::bit_of(q);
                }
            }
            (tz, masks)
        })
        .collect();
    let mut out = Wanted::new();
    for (tz, masks) in layers {
        for (i, &m) in masks.iter().enumerate().filter(|(_, m)| **m != 0) {
            out.insert([lo[0] + (i % tx) as i64, lo[1] + (i / tx) as i64, tz], m);
        }
    }
    out
}

/// The tiles of `points`, each with the mask of the points in it.
fn wanted_points(points: &[[i64; 3]]) -> Wanted {
    let mut wanted = Wanted::new();
    for &p in points {
        *wanted.entry(Engine::tile_of(p)).or_default() |= Engine::bit_of(p);
    }
    wanted
}

#[inline]
fn position(b: &Box3, i: usize) -> [i64; 3] {
    let s = b.size();
    let (sx, sy) = (s[0] as usize, s[1] as usize);
    [
        b.lo[0] + (i % sx) as i64,
        b.lo[1] + ((i / sx) % sy) as i64,
        b.lo[2] + (i / (sx * sy)) as i64,
    ]
}

/// Where the pixels of a cut sample, row by row.
pub(crate) fn plane_points(plane: &CutPlane) -> Vec<[f64; 3]> {
    let w = plane.width;
    (0..w * plane.height)
        .map(|i| plane.at(i % w, i / w))
        .collect()
}

/// `voxels` sorted, each once.
pub(crate) fn unique_voxels(voxels: &[[i64; 3]]) -> Vec<[i64; 3]> {
    let mut unique = voxels.to_vec();
    unique.par_sort_unstable();
    unique.dedup();
    unique
}

/// RGB8 of the samples that read the voxels `pts` with `weights` (as
/// [`sample_voxels`] gives them), from the colours of the sorted voxels
/// `unique` that include them.
pub(crate) fn filtered_rgb(
    pts: &[[i64; 3]],
    weights: &[f32],
    filter: Filter,
    unique: &[[i64; 3]],
    colours: &[[f32; 3]],
) -> Vec<u8> {
    let at = |p: &[i64; 3]| colours[unique.binary_search(p).unwrap_or_default()];
    match filter {
        Filter::Nearest => pts.par_iter().flat_map_iter(|p| rgb8(at(p))).collect(),
        Filter::Trilinear => {
            let mut out = vec![0u8; pts.len() / 8 * 3];
            out.par_chunks_mut(3).enumerate().for_each(|(i, dst)| {
                let mut c = [0f32; 3];
                for j in i * 8..i * 8 + 8 {
                    let col = at(&pts[j]);
                    for ch in 0..3 {
                        c[ch] += weights[j] * col[ch];
                    }
                }
                dst.copy_from_slice(&rgb8(c));
            });
            out
        }
    }
}

/// The voxels points read: each rounded to the nearest voxel, or for the
/// trilinear filter the eight corners around each with their weights
/// (nearest: no weights).
pub(crate) fn sample_voxels(points: &[[f64; 3]], filter: Filter) -> (Vec<[i64; 3]>, Vec<f32>) {
    match filter {
        Filter::Nearest => {
            let pts = points.iter().map(|q| q.map(|v| v.round() as i64)).collect();
            (pts, Vec::new())
        }
        Filter::Trilinear => {
            let mut pts = Vec::with_capacity(points.len() * 8);
            let mut weights = Vec::with_capacity(points.len() * 8);
            for q in points {
                let base = q.map(|v| v.floor());
                let f = [0, 1, 2].map(|a| q[a] - base[a]);
                for corner in 0..8 {
                    let o = [corner & 1, (corner >> 1) & 1, corner >> 2];
                    pts.push([0, 1, 2].map(|a| base[a] as i64 + o[a] as i64));
                    let wgt: f64 = (0..3)
                        .map(|a| if o[a] == 1 { f[a] } else { 1.0 - f[a] })
                        .product();
                    weights.push(wgt as f32);
                }
            }
            (pts, weights)
        }
    }
}
