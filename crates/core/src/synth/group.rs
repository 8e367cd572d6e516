//! Synthesis of a group of tiles of one level: plan the exact dependency
//! chain backwards through the history windows, build version 0 of what it
//! needs (slab or upsampled parents), run the correction subpasses
//! forwards, and publish every pass's values to the tile cache.

use super::cache::{Tile, TileData};
use super::colour::colour;
use super::correction::{Corrector, Work};
use super::grid::{Box3, Grid};
use super::{Acc, Engine, MAX_GROUP_TILES, TILE, cancel, init, plan, tile_masks, tile_voxels};
use rayon::prelude::*;
use rustc_hash::FxHashMap as HashMap;
use std::sync::Arc;
use std::sync::atomic::Ordering;

/// Voxels whose values after a pass were found in the cache, by the
/// forward subpass that writes them.
type Ends = HashMap<usize, Vec<([i64; 3], [u32; 3])>>;

impl Engine {
    /// Synthesizes the wanted voxels of tiles of level `k` (no cache
    /// lookups for them; their prerequisites go through the cache). Tiles
    /// are processed in compact groups so memory stays bounded and
    /// scattered tiles never pull in the space between them. Only the
    /// wanted voxels and their exact dependency chain are computed.
    pub(super) fn compute(
        &self,
        k: usize,
        tiles: &[([i64; 3], u64)],
        acc: &Acc,
    ) -> HashMap<[i64; 3], Tile> {
        let masks: HashMap<[i64; 3], u64> = tiles.iter().copied().collect();
        let cells: Vec<[i64; 3]> = tiles.iter().map(|t| t.0).collect();
        let mut out = HashMap::default();
        for group in plan::group_cells(&cells, MAX_GROUP_TILES) {
            let group: Vec<([i64; 3], u64)> = group.into_iter().map(|c| (c, masks[&c])).collect();
            out.extend(self.compute_group(k, &group, acc));
        }
        out
    }

    /// One group of tiles: plan the exact chain backwards, build version 0
    /// of what it needs, run the correction subpasses forwards, publish.
    fn compute_group(
        &self,
        k: usize,
        tiles: &[([i64; 3], u64)],
        acc: &Acc,
    ) -> Vec<([i64; 3], Tile)> {
        let mut targets = Vec::with_capacity(tiles.len() * (TILE * TILE * TILE) as usize);
        for &(t, mask) in tiles {
            targets.extend(tile_voxels(t, mask).map(|(_, p)| p));
        }
        cancel::check(&acc.cancel);
        let (chain, ends) = self.plan_group(k, &targets, acc);
        cancel::check(&acc.cancel);
        if !acc.dry {
            cancel::charge(&acc.cancel, chain.need.count());
        }
        acc.voxels[k].fetch_add(chain.need.count(), Ordering::Relaxed);
        acc.corrections[k].fetch_add(chain.corrections(), Ordering::Relaxed);
        let triples = self.version0_with(k, &chain, &ends, acc);
        // Voxels corrected in the last pass: their final values.
        let (triples, mut ended) = if acc.dry {
            (triples, HashMap::default())
        } else {
            self.run_subpasses(k, &chain, &ends, triples, acc)
        };
        // Every voxel corrected in the last pass holds its final value,
        // though only the wanted ones were asked for: the requested tiles
        // keep theirs, the rest go to the cache as final voxels, so that a
        // neighbouring request (the next plane of a sweeping cut) finds
        // them instead of walking their chains again.
        let own: Vec<([i64; 3], u64)> = tiles
            .iter()
            .map(|&(t, mask)| (t, mask | ended.remove(&t).unwrap_or(0)))
            .collect();
        self.publish_ended(k, 0, &ended, &triples);
        own.par_iter()
            .map(|&(t, mask)| (t, Self::tile_from(&triples, t, mask)))
            .collect()
    }

    /// The exact dependency chain of `targets` at level `k`. Values after a
    /// pass that earlier requests cached end the chain there (see
    /// `plan::backward`), so that overlapping requests (a sweeping cut)
    /// share their work instead of redoing it: they come back by forward
    /// subpass.
    fn plan_group(&self, k: usize, targets: &[[i64; 3]], acc: &Acc) -> (plan::LevelChain, Ends) {
        let mut ends: Ends = HashMap::default();
        let mut peeked: HashMap<([i64; 3], usize), Option<Tile>> = HashMap::default();
        let chain = plan::backward(
            targets,
            self.schedule(k),
            self.field.is_some(),
            |pass, forward, voxels| {
                if acc.dry {
                    return Vec::new();
                }
                // One lookup per tile (the voxels come in runs within one):
                // on a cold cache nothing is found and nothing is filtered.
                let mut any = false;
                let mut last = None;
                for &q in voxels.iter() {
                    let t = Self::tile_of(q);
                    if last != Some(t) {
                        last = Some(t);
                        any |= peeked
                            .entry((t, pass))
                            .or_insert_with(|| self.cache.peek(&self.after_pass_key(k, pass, t)))
                            .is_some();
                    }
                }
                if !any {
                    return Vec::new();
                }
                let mut found = Vec::new();
                voxels.retain(|&q| {
                    let t = Self::tile_of(q);
                    let tile = peeked
                        .entry((t, pass))
                        .or_insert_with(|| self.cache.peek(&self.after_pass_key(k, pass, t)));
                    match tile {
                        Some(tile) if tile.mask & Self::bit_of(q) != 0 => {
                            found.push((q, tile.get(q)));
                            false
                        }
                        _ => true,
                    }
                });
                let removed = found.iter().map(|f| f.0).collect();
                if !found.is_empty() {
                    ends.insert(forward, found);
                }
                removed
            },
        );
        (chain, ends)
    }

    /// Version 0 of the chain's voxels, on a grid that also spans the
    /// voxels whose cached values end the chain.
    fn version0_with(
        &self,
        k: usize,
        chain: &plan::LevelChain,
        ends: &Ends,
        acc: &Acc,
    ) -> Grid<[u32; 3]> {
        let known_box = ends
            .values()
            .flatten()
            .map(|(p, _)| Box3::new(*p, [1, 1, 1]))
            .reduce(|a, b| a.union(&b));
        match known_box {
            // Everything came from cached passes: no version 0 at all.
            Some(kb) if chain.need.count() == 0 => Grid::new(kb),
            Some(kb) => {
                let v0 = self.version0(k, &chain.need, acc);
                let mut wider = Grid::new(v0.bounds.union(&kb));
                wider.copy_from(&v0);
                wider
            }
            None => self.version0(k, &chain.need, acc),
        }
    }

    /// Runs the chain's subpasses forwards over `triples`, caching each
    /// pass's values as it ends; returns the triples and the tile masks of
    /// the voxels corrected in the last pass.
    fn run_subpasses(
        &self,
        k: usize,
        chain: &plan::LevelChain,
        ends: &Ends,
        triples: Grid<[u32; 3]>,
        acc: &Acc,
    ) -> (Grid<[u32; 3]>, HashMap<[i64; 3], u64>) {
        let schedule = self.schedule(k);
        // Voxels corrected in the current pass: their values after it,
        // cached once it ends.
        let mut ended: HashMap<[i64; 3], u64> = HashMap::default();
        let mut work = Work::new(&self.cands, k, triples);
        let corrector = Corrector::new(&self.cands, k, &self.params, self.field.as_deref());
        let mut step_start: Option<(usize, Work)> = None;
        let mut current_pass = 0;
        let classes = schedule.subpasses_per_pass();
        for (forward, (si, voxels)) in chain.subpasses.iter().enumerate() {
            cancel::check(&acc.cancel);
            if forward / classes != current_pass {
                // The values after the pass just done.
                let done = schedule.version_after_pass(current_pass);
                self.publish_ended(k, done, &ended, &work.triples);
                ended.clear();
                current_pass = forward / classes;
            }
            if schedule.window.has_walls() && step_start.as_ref().is_none_or(|s| s.0 != *si) {
                step_start = Some((*si, work.clone()));
            }
            let offset = schedule.steps[*si].offset;
            let start = step_start.as_ref().map(|s| &s.1);
            let w = &work;
            let new: Vec<(usize, [u32; 3], [f32; 3])> = voxels
                .par_iter()
                .map(|&p| {
                    let barrier = schedule.window.latest_within(p, offset);
                    let t = match (start, barrier) {
                        (Some(st), Some(cell)) => corrector.correct(w, Some((st, &cell)), p),
                        _ => corrector.correct(w, None, p),
                    };
                    (w.triples.index(p), t, colour(&self.cands, k, t))
                })
                .collect();
            for (i, t, c) in new {
                work.triples.data[i] = t;
                work.colours.data[i] = c;
            }
            for &(p, t) in ends.get(&forward).into_iter().flatten() {
                let i = work.triples.index(p);
                work.triples.data[i] = t;
                work.colours.data[i] = colour(&self.cands, k, t);
            }
            mark_ended(&mut ended, voxels);
        }
        (work.triples, ended)
    }

    /// Caches the voxels of `ended` (tile masks) from `triples` as the
    /// version of level `k` after `done` passes (0: final values).
    fn publish_ended(
        &self,
        k: usize,
        done: usize,
        ended: &HashMap<[i64; 3], u64>,
        triples: &Grid<[u32; 3]>,
    ) {
        let tiles: Vec<([i64; 3], Tile)> = ended
            .par_iter()
            .map(|(&t, &mask)| (t, Self::tile_from(triples, t, mask)))
            .collect();
        for (t, tile) in tiles {
            self.cache.merge(self.version_key(k, done, t), tile);
        }
    }

    /// Tile `t` of `triples`, holding the voxels of `mask`.
    fn tile_from(triples: &Grid<[u32; 3]>, t: [i64; 3], mask: u64) -> Tile {
        Arc::new(TileData::from_grid(triples, Self::tile_box(t).lo, mask))
    }

    /// Version 0 of level `k` at the voxels of `need` (a grid over its
    /// box; other voxels are left unset): the jittered slab at the initial
    /// level, else the parent level's final triples upsampled.
    fn version0(&self, k: usize, need: &plan::Mask, acc: &Acc) -> Grid<[u32; 3]> {
        let b = need.bounds();
        let mut g = Grid::new(b);
        let zs: Vec<i64> = (b.lo[2]..b.hi[2]).collect();
        let layer = (b.size()[0] * b.size()[1]) as usize;
        if self.cands.block(k).is_some() {
            if acc.dry {
                return g;
            }
            let f = self.cands.blocks()[0].level as usize;
            let tiling = init::BlockTiling {
                cands: &self.cands,
                seed: self.params.seed,
                field: self.field.as_deref(),
                period: self.period_at(f),
            };
            g.data
                .par_chunks_mut(layer)
                .zip(zs.par_iter())
                .for_each(|(dst, &z)| {
                    let mut sites = init::Sites::default();
                    for p in need.layer(z) {
                        let i = ((p[1] - b.lo[1]) * b.size()[0] + (p[0] - b.lo[0])) as usize;
                        dst[i] = tiling.triple(k, p, &mut sites);
                    }
                });
            return g;
        }
        if k == self.init_level {
            if acc.dry {
                return g;
            }
            let period = self.period_at(k);
            let jitter = init::JitterField::new(
                &self.cands,
                self.params.seed,
                self.params.jitter,
                k,
                &b,
                period,
            );
            let slab = init::Slab {
                cands: &self.cands,
                seed: self.params.seed,
                thickness: self.params.slab_thickness,
                tiling: self.params.slab_tiling,
                field: self.field.as_deref(),
                period,
            };
            g.data
                .par_chunks_mut(layer)
                .zip(zs.par_iter())
                .for_each(|(dst, &z)| {
                    let mut sites = init::Sites::default();
                    for p in need.layer(z) {
                        let i = ((p[1] - b.lo[1]) * b.size()[0] + (p[0] - b.lo[0])) as usize;
                        dst[i] = slab.initial_triple(&jitter, k, p, &mut sites);
                    }
                });
            return g;
        }
        let parent_tiles = tile_masks(need, 2);
        let parents = self.tiles(k + 1, parent_tiles, acc);
        if acc.dry {
            return g;
        }
        g.data
            .par_chunks_mut(layer)
            .zip(zs.par_iter())
            .for_each(|(dst, &z)| {
                for p in need.layer(z) {
                    let q = p.map(|v| v.div_euclid(2));
                    let parent = parents[&Self::tile_of(q)].get(q);
                    let i = ((p[1] - b.lo[1]) * b.size()[0] + (p[0] - b.lo[0])) as usize;
                    dst[i] = init::upsample(&self.cands, parent, k, p, self.field.as_deref());
                }
            });
        g
    }
}

/// Adds sorted voxels to their tiles' masks; they come in runs within one
/// tile, so one map update per run.
fn mark_ended(ended: &mut HashMap<[i64; 3], u64>, voxels: &[[i64; 3]]) {
    let mut run: Option<([i64; 3], u64)> = None;
    for &p in voxels {
        let t = Engine::tile_of(p);
        match &mut run {
            Some((rt, bits)) if *rt == t => *bits |= Engine::bit_of(p),
            _ => {
                if let Some((rt, bits)) = run {
                    *ended.entry(rt).or_default() |= bits;
                }
                run = Some((t, Engine::bit_of(p)));
            }
        }
    }
    if let Some((rt, bits)) = run {
        *ended.entry(rt).or_default() |= bits;
    }
}
