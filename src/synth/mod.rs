//! Lazy, spatially deterministic pyramid synthesis (Dong et al. 2008 with
//! Zhang et al. 2011's history windows and dual-grid correction).
//!
//! Each level k (0 = finest) holds a coordinate triple per voxel. Version 0
//! of a level comes from the jittered candidate slab (coarsest synthesized
//! level) or from upsampling the parent level. Correction steps then refine
//! it. A step's history window decides which version of each neighbour a
//! correction reads; both schemes are expressed by what a tile's working box
//! contains:
//!
//! - **dual grid**: space is cut into M³ cells. A primary-grid step corrects
//!   one cell from a box holding version 0 around it: neighbours inside the
//!   cell are read at their latest version, neighbours across the wall at
//!   version 0 (the barrier). The dual-grid step does the same on cells
//!   shifted by M/2, starting from the primary result. A cell's result thus
//!   depends on a bounded neighbourhood, whatever P and s.
//! - **standard**: every correction reads the latest version of every
//!   neighbour (Dong et al.), so the box a tile needs grows by N/2 per
//!   subpass; tiles are computed in batches over their dilated bounding box.
//!
//! Results are cut into level-aligned tiles (cells) that the shared
//! [`cache::TileCache`] keeps, so coarse levels are computed once for many
//! requests.

pub mod cache;
pub mod correction;
pub mod grid;
pub mod hash;
pub mod init;
pub mod plan;

use crate::candidates::Candidates;
use crate::error::Result;
use crate::params::{Scheme, SynthParams};
use crate::texture::{CutPlane, Filter, Region, SynthStats};
use cache::{Claim, Tile, TileCache, TileKey};
use correction::{Corrector, Work, colour};
use grid::{Box3, Grid};
use rayon::prelude::*;
use std::collections::{BTreeSet, HashMap};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

/// One correction step of a level: cells of side M shifted by `offset`,
/// corrected `passes` times.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Step {
    /// Grid shift (0 for the primary grid, M/2 for the dual grid).
    pub offset: i64,
    /// Passes in this step.
    pub passes: u32,
}

/// Counters gathered while serving one request.
pub(crate) struct Acc {
    voxels: Vec<AtomicU64>,
    corrections: Vec<AtomicU64>,
    computed: AtomicU64,
    cached: AtomicU64,
    /// Count the work without doing it (tiles hold zeros).
    dry: bool,
}

impl Acc {
    fn new(levels: usize, dry: bool) -> Acc {
        Acc {
            dry,
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
    cache: Arc<TileCache>,
    key: u64,
    init_level: usize,
    radius: i64,
    cell: i64,
    steps: Vec<Step>,
}

fn fingerprint(bytes: &[u8]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for chunk in bytes.chunks(8) {
        let mut b = [0u8; 8];
        b[..chunk.len()].copy_from_slice(chunk);
        h = hash::mix(h ^ u64::from_le_bytes(b));
    }
    hash::mix(h ^ bytes.len() as u64)
}

impl Engine {
    pub(crate) fn new(cands: Arc<Candidates>, params: SynthParams, cache: Arc<TileCache>) -> Self {
        let mut bytes = cands.to_bytes();
        bytes.extend_from_slice(&serde_json::to_vec(&params).expect("params serialise"));
        let key = fingerprint(&bytes);
        let steps = match params.scheme {
            Scheme::DualGrid => [
                Step {
                    offset: 0,
                    passes: params.passes.div_ceil(2),
                },
                Step {
                    offset: params.grid as i64 / 2,
                    passes: params.passes / 2,
                },
            ]
            .into_iter()
            .filter(|s| s.passes > 0)
            .collect(),
            Scheme::Standard if params.passes > 0 => vec![Step {
                offset: 0,
                passes: params.passes,
            }],
            Scheme::Standard => Vec::new(),
        };
        Engine {
            init_level: cands.level_count() - 1,
            radius: (cands.params().neighbourhood as i64 / 2).max(1),
            cell: params.grid as i64,
            cands,
            params,
            cache,
            key,
            steps,
        }
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

    /// Correction steps applied at level `k`.
    pub(crate) fn steps_at(&self, k: usize) -> &[Step] {
        if k == self.init_level && !self.params.correct_init_level {
            &[]
        } else {
            &self.steps
        }
    }

    /// Grid shift of the tiles of step `step` (0 = version 0).
    fn offset_of(&self, k: usize, step: usize) -> i64 {
        if step == 0 {
            0
        } else {
            self.steps_at(k)[step - 1].offset
        }
    }

    fn cell_box(&self, k: usize, step: usize, c: [i64; 3]) -> Box3 {
        let o = self.offset_of(k, step);
        Box3::new(c.map(|v| v * self.cell + o), [self.cell; 3])
    }

    fn cells_covering(&self, k: usize, step: usize, b: &Box3) -> Vec<[i64; 3]> {
        let o = self.offset_of(k, step);
        let lo = b.lo.map(|v| (v - o).div_euclid(self.cell));
        let hi = b.hi.map(|v| (v - 1 - o).div_euclid(self.cell));
        let mut out = Vec::new();
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    out.push([x, y, z]);
                }
            }
        }
        out
    }

    fn final_step(&self, k: usize) -> usize {
        self.steps_at(k).len()
    }

    /// Final triples of level `k` over `b`.
    pub(crate) fn level_box(&self, k: usize, b: &Box3, acc: &Acc) -> Grid<[u32; 3]> {
        let step = self.final_step(k);
        let cells: BTreeSet<[i64; 3]> = self.cells_covering(k, step, b).into_iter().collect();
        let tiles = self.tiles(k, step, cells, acc);
        let mut g = Grid::new(*b);
        for t in tiles.values() {
            g.copy_from(t);
        }
        g
    }

    /// Tiles of step `step` at level `k`, from the cache or computed; a
    /// tile another request is computing is waited for (outside rayon).
    fn tiles(
        &self,
        k: usize,
        step: usize,
        cells: BTreeSet<[i64; 3]>,
        acc: &Acc,
    ) -> HashMap<[i64; 3], Tile> {
        let mut out = HashMap::new();
        let mut mine = Vec::new();
        let mut theirs = Vec::new();
        let in_pool = rayon::current_thread_index().is_some();
        let mut unclaimed = Vec::new();
        for c in cells {
            let key = TileKey {
                texture: self.key,
                level: k as u8,
                step: step as u8,
                cell: c,
            };
            match self.cache.claim(key) {
                Claim::Ready(t) => {
                    acc.cached.fetch_add(1, Ordering::Relaxed);
                    out.insert(c, t);
                }
                Claim::Mine(ticket) => mine.push(ticket),
                // Blocking a rayon worker on another computation could
                // deadlock the pool, so inside it we compute instead.
                Claim::Wait(_) if in_pool => unclaimed.push(c),
                Claim::Wait(w) => theirs.push(w),
            }
        }
        let mut todo: Vec<[i64; 3]> = mine.iter().map(|t| t.key().cell).collect();
        todo.extend(&unclaimed);
        if !todo.is_empty() {
            let computed = self.compute(k, step, &todo, acc);
            acc.computed
                .fetch_add(computed.len() as u64, Ordering::Relaxed);
            let mut by_cell: HashMap<[i64; 3], Tile> = todo.iter().copied().zip(computed).collect();
            for ticket in mine {
                let c = ticket.key().cell;
                let t = by_cell.remove(&c).expect("computed");
                self.cache.publish(ticket, t.clone());
                out.insert(c, t);
            }
            out.extend(by_cell);
        }
        for w in theirs {
            let c = w.key().cell;
            match self.cache.wait(w) {
                Some(t) => {
                    acc.cached.fetch_add(1, Ordering::Relaxed);
                    out.insert(c, t);
                }
                None => {
                    let t = self.compute(k, step, &[c], acc).pop().expect("one tile");
                    acc.computed.fetch_add(1, Ordering::Relaxed);
                    out.insert(c, t);
                }
            }
        }
        out
    }

    /// Computes tiles of step `step` at level `k` (no cache lookups for
    /// them; prerequisites go through the cache).
    fn compute(&self, k: usize, step: usize, cells: &[[i64; 3]], acc: &Acc) -> Vec<Tile> {
        if step == 0 {
            let boxes: Vec<Box3> = cells.iter().map(|&c| self.cell_box(k, 0, c)).collect();
            return self
                .version0(k, &boxes, acc)
                .into_iter()
                .map(Arc::new)
                .collect();
        }
        match self.params.scheme {
            Scheme::DualGrid => self.compute_grid_step(k, step, cells, acc),
            Scheme::Standard => self.compute_standard(k, cells, acc),
        }
    }

    /// A dual-grid step: each cell is corrected inside a box that holds the
    /// previous step's result N/2 around it; neighbours outside the cell
    /// stay at that version (the barrier of its history window).
    fn compute_grid_step(&self, k: usize, step: usize, cells: &[[i64; 3]], acc: &Acc) -> Vec<Tile> {
        let r = self.radius;
        let boxes: Vec<Box3> = cells.iter().map(|&c| self.cell_box(k, step, c)).collect();
        let inputs: Vec<Grid<[u32; 3]>> = if step == 1 {
            self.version0(
                k,
                &boxes.iter().map(|b| b.dilate(r)).collect::<Vec<_>>(),
                acc,
            )
        } else {
            let mut need = BTreeSet::new();
            for b in &boxes {
                need.extend(self.cells_covering(k, step - 1, &b.dilate(r)));
            }
            let prev = self.tiles(k, step - 1, need, acc);
            boxes
                .iter()
                .map(|b| {
                    let mut g = Grid::new(b.dilate(r));
                    for c in self.cells_covering(k, step - 1, &g.bounds) {
                        g.copy_from(&prev[&c]);
                    }
                    g
                })
                .collect()
        };
        let passes = self.steps_at(k)[step - 1].passes;
        let side = self.params.subpass_side as i64;
        let corrector = Corrector::new(&self.cands, k);
        inputs
            .into_par_iter()
            .zip(boxes.par_iter())
            .map(|(input, b)| {
                if acc.dry {
                    acc.corrections[k].fetch_add(passes as u64 * b.volume(), Ordering::Relaxed);
                    let mut out = Grid::new(*b);
                    out.copy_from(&input);
                    return Arc::new(out);
                }
                let mut work = Work::new(&self.cands, k, input);
                let n = corrector.run(&mut work, |_| *b, passes, side, false);
                acc.corrections[k].fetch_add(n, Ordering::Relaxed);
                let mut out = Grid::new(*b);
                out.copy_from(&work.triples);
                Arc::new(out)
            })
            .collect()
    }

    /// Dong's standard correction for a batch of cells: every step reads
    /// the latest version of every neighbour, so the box needed grows by
    /// N/2 per subpass going back; the batch is computed over that box.
    fn compute_standard(&self, k: usize, cells: &[[i64; 3]], acc: &Acc) -> Vec<Tile> {
        let mut out = Vec::with_capacity(cells.len());
        for group in plan::group_cells(cells, self.cell) {
            let boxes: Vec<Box3> = group.iter().map(|&c| self.cell_box(k, 1, c)).collect();
            let target = boxes.iter().skip(1).fold(boxes[0], |a, b| a.union(b));
            let side = self.params.subpass_side as i64;
            let passes = self.steps[0].passes;
            let total = (passes as i64 * side * side * side) as usize;
            let r = self.radius;
            // Step t updates target ⊕ r·(total − 1 − t).
            let update = |t: usize| target.dilate(r * (total - 1 - t) as i64);
            let input = self
                .version0(k, &[target.dilate(r * total as i64)], acc)
                .pop()
                .expect("one box");
            let triples = if acc.dry {
                let n: u64 = (0..total)
                    .map(|t| {
                        let class = (t as i64) % (side * side * side);
                        let phase = [class % side, (class / side) % side, class / (side * side)];
                        let mut c = 0u64;
                        correction::for_class(&update(t), phase, side, |_| c += 1);
                        c
                    })
                    .sum();
                acc.corrections[k].fetch_add(n, Ordering::Relaxed);
                input
            } else {
                let mut work = Work::new(&self.cands, k, input);
                let n = Corrector::new(&self.cands, k).run(&mut work, update, passes, side, true);
                acc.corrections[k].fetch_add(n, Ordering::Relaxed);
                work.triples
            };
            for b in boxes {
                let mut g = Grid::new(b);
                g.copy_from(&triples);
                out.push(Arc::new(g));
            }
        }
        // Groups reorder cells; restore the caller's order.
        let mut by_cell: HashMap<[i64; 3], Tile> = HashMap::new();
        for t in out {
            let c = t.bounds.lo.map(|v| v.div_euclid(self.cell));
            by_cell.insert(c, t);
        }
        cells.iter().map(|c| by_cell[c].clone()).collect()
    }

    /// Version 0 of level `k` over each box: the jittered slab at the
    /// initial level, else the parent level's final triples upsampled.
    fn version0(&self, k: usize, boxes: &[Box3], acc: &Acc) -> Vec<Grid<[u32; 3]>> {
        let seed = self.params.seed;
        for b in boxes {
            acc.voxels[k].fetch_add(b.volume(), Ordering::Relaxed);
        }
        if acc.dry && k == self.init_level {
            return boxes.iter().map(|b| Grid::new(*b)).collect();
        }
        if k == self.init_level {
            let jitter = self.params.jitter;
            return boxes
                .par_iter()
                .map(|b| {
                    let field = init::JitterField::new(&self.cands, seed, jitter, k, b);
                    let mut g = Grid::new(*b);
                    for (i, t) in g.data.iter_mut().enumerate() {
                        let p = position(b, i);
                        *t = init::initial_triple(&self.cands, seed, &field, k, p);
                    }
                    g
                })
                .collect();
        }
        let parent_boxes: Vec<Box3> = boxes.iter().map(|b| b.parent()).collect();
        let step = self.final_step(k + 1);
        let mut need = BTreeSet::new();
        for pb in &parent_boxes {
            need.extend(self.cells_covering(k + 1, step, pb));
        }
        let parents = self.tiles(k + 1, step, need, acc);
        if acc.dry {
            return boxes.iter().map(|b| Grid::new(*b)).collect();
        }
        boxes
            .par_iter()
            .zip(parent_boxes.par_iter())
            .map(|(b, pb)| {
                let mut pg = Grid::new(*pb);
                for c in self.cells_covering(k + 1, step, pb) {
                    pg.copy_from(&parents[&c]);
                }
                let mut g = Grid::new(*b);
                for (i, t) in g.data.iter_mut().enumerate() {
                    let p = position(b, i);
                    let parent = pg.get(p.map(|v| v.div_euclid(2)));
                    *t = init::upsample(&self.cands, parent, k, p);
                }
                g
            })
            .collect()
    }

    pub(crate) fn new_acc(&self) -> Acc {
        Acc::new(self.init_level + 1, false)
    }

    /// Counts what synthesizing `r` from a cold cache would compute, per
    /// level, without computing it.
    pub(crate) fn plan_region(&self, r: &Region, lod: u32) -> SynthStats {
        let dry = Engine {
            cands: self.cands.clone(),
            params: self.params.clone(),
            cache: Arc::new(TileCache::new(usize::MAX)),
            key: self.key,
            init_level: self.init_level,
            radius: self.radius,
            cell: self.cell,
            steps: self.steps.clone(),
        };
        let acc = Acc::new(self.init_level + 1, true);
        let b = Box3::new(r.origin, r.size.map(|s| s as i64));
        dry.level_box(lod as usize, &b, &acc);
        acc.stats()
    }

    /// Exact voxel-level dependency chain of a few voxels (see
    /// [`plan::exact_chain`]).
    pub(crate) fn exact_chain(&self, voxels: &[[i64; 3]], lod: u32) -> Vec<plan::LevelPlan> {
        let levels: Vec<Vec<Step>> = (0..=self.init_level)
            .skip(lod as usize)
            .map(|k| self.steps_at(k).to_vec())
            .collect();
        let cell = match self.params.scheme {
            Scheme::DualGrid => Some(self.cell),
            Scheme::Standard => None,
        };
        plan::exact_chain(
            voxels,
            levels.len(),
            &levels,
            self.radius,
            self.params.subpass_side as i64,
            cell,
        )
    }

    pub(crate) fn region_rgb(&self, r: &Region, lod: u32) -> Result<(Vec<u8>, SynthStats)> {
        let acc = self.new_acc();
        let b = Box3::new(r.origin, r.size.map(|s| s as i64));
        let k = lod as usize;
        let g = self.level_box(k, &b, &acc);
        let mut rgb = vec![0u8; g.data.len() * 3];
        rgb.par_chunks_mut(3)
            .zip(g.data.par_iter())
            .for_each(|(dst, t)| {
                let c = colour(&self.cands, k, *t);
                for ch in 0..3 {
                    dst[ch] = c[ch].round().clamp(0.0, 255.0) as u8;
                }
            });
        Ok((rgb, acc.stats()))
    }

    /// Final triples at arbitrary voxels of level `k`, fetched tile by tile
    /// so scattered points never pull in their bounding box.
    fn triples_at(&self, k: usize, points: &[[i64; 3]], acc: &Acc) -> Vec<[u32; 3]> {
        let step = self.final_step(k);
        let o = self.offset_of(k, step);
        let cell_of = |p: &[i64; 3]| p.map(|v| (v - o).div_euclid(self.cell));
        let cells: BTreeSet<[i64; 3]> = points.iter().map(cell_of).collect();
        let tiles = self.tiles(k, step, cells, acc);
        points.iter().map(|p| tiles[&cell_of(p)].get(*p)).collect()
    }

    pub(crate) fn points_rgb(
        &self,
        points: &[[i64; 3]],
        lod: u32,
    ) -> Result<(Vec<[u8; 3]>, SynthStats)> {
        let acc = self.new_acc();
        let k = lod as usize;
        let triples = self.triples_at(k, points, &acc);
        let out = triples
            .par_iter()
            .map(|t| colour(&self.cands, k, *t).map(|v| v.round().clamp(0.0, 255.0) as u8))
            .collect();
        Ok((out, acc.stats()))
    }

    pub(crate) fn cut_rgb(
        &self,
        plane: &CutPlane,
        lod: u32,
        filter: Filter,
    ) -> Result<(Vec<u8>, SynthStats)> {
        let acc = self.new_acc();
        let k = lod as usize;
        let (w, h) = (plane.width as usize, plane.height as usize);
        let at = |i: usize, j: usize| {
            [0, 1, 2].map(|a| plane.origin[a] + i as f64 * plane.u[a] + j as f64 * plane.v[a])
        };
        let limit = crate::texture::COORD_LIMIT as f64;
        for (i, j) in [(0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1)] {
            if at(i, j).iter().any(|v| v.abs() > limit) {
                return Err(crate::Error::InvalidRange {
                    name: "cut coordinate",
                    value: at(i, j).iter().fold(0f64, |m, v| m.max(v.abs())),
                    min: -limit,
                    max: limit,
                });
            }
        }
        let rgb = match filter {
            Filter::Nearest => {
                let pts: Vec<[i64; 3]> = (0..w * h)
                    .map(|i| at(i % w, i / w).map(|v| v.round() as i64))
                    .collect();
                let t = self.triples_at(k, &pts, &acc);
                t.par_iter()
                    .flat_map_iter(|t| {
                        colour(&self.cands, k, *t).map(|v| v.round().clamp(0.0, 255.0) as u8)
                    })
                    .collect()
            }
            Filter::Trilinear => {
                let mut pts = Vec::with_capacity(w * h * 8);
                let mut weights = Vec::with_capacity(w * h * 8);
                for i in 0..w * h {
                    let q = at(i % w, i / w);
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
                let t = self.triples_at(k, &pts, &acc);
                let mut out = vec![0u8; w * h * 3];
                out.par_chunks_mut(3).enumerate().for_each(|(i, dst)| {
                    let mut c = [0f32; 3];
                    for j in i * 8..i * 8 + 8 {
                        let col = colour(&self.cands, k, t[j]);
                        for ch in 0..3 {
                            c[ch] += weights[j] * col[ch];
                        }
                    }
                    for ch in 0..3 {
                        dst[ch] = c[ch].round().clamp(0.0, 255.0) as u8;
                    }
                });
                out
            }
        };
        Ok((rgb, acc.stats()))
    }
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
