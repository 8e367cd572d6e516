//! The public face of synthesis: a [`Texture`] answers [`Request`]s (voxel
//! regions, axis slices, oblique cuts, scattered voxels) by synthesizing
//! exactly their dependency set (see [`crate::synth`]). A texture is one
//! solid, or two sharing space across a region ([`crate::region`]).

use crate::candidates::Candidates;
use crate::error::{Error, Result};
use crate::mesh::{Bake, Surface};
use crate::params::SynthParams;
use crate::region::{self, Side, Split};
use crate::request::{Request, RequestKind, Slice};
use crate::synth::cache::TileCache;
use crate::synth::colour::rgb8;
use crate::synth::estimate::{Masks, WorkEstimate, add_voxel};
use crate::synth::{Engine, SynthStats, filtered_rgb, plane_points, sample_voxels, unique_voxels};
use rayon::prelude::*;
use std::ops::ControlFlow;
use std::sync::Arc;

/// Texels (or vertices) of a bake synthesized per step: a step's sample
/// points and voxels stay in memory at once.
const BAKE_STEP: usize = 1 << 20;

/// Side of the blocks a bake's estimate bounds one by one: the thinner
/// the blocks, the closer the bound hugs the shell a surface needs, and
/// the more often it counts the coarse levels they share.
const ESTIMATE_BLOCK: u32 = 16;

/// Most tiles a bake's estimate holds the voxels of (a tile's mask is 8
/// bytes beside its 24-byte key).
const MAX_ESTIMATE_TILES: usize = 1 << 22;

/// Hands `each` the voxels a bake reads, a step of texels at a time (so
/// few sample points are in memory at once), until it breaks.
fn bake_voxels(b: &Bake, mut each: impl FnMut(Vec<[i64; 3]>) -> ControlFlow<()>) {
    for start in (0..b.items()).step_by(BAKE_STEP) {
        let end = (start + BAKE_STEP).min(b.items());
        let points: Vec<[f64; 3]> = (start..end)
            .into_par_iter()
            .filter_map(|i| b.sample(i))
            .collect();
        if each(sample_voxels(&points, b.options().filter).0).is_break() {
            return;
        }
    }
}

/// A solid texture ready to be sampled anywhere. Cheap to clone; safe to
/// share between threads. Every method blocks while it synthesizes (using
/// rayon); call it from a blocking context.
#[derive(Clone)]
pub struct Texture {
    /// The solid, or for a region texture its outermost outer solid (whose
    /// candidates and parameters the texture reports).
    engine: Arc<Engine>,
    /// Two textures sharing space, for a region texture.
    split: Option<Arc<Composite>>,
}

/// A region texture: `inner` fills the region, `outer` the rest.
struct Composite {
    outer: Texture,
    inner: Texture,
    split: Split,
    /// Region textures nested, this one included.
    depth: usize,
}

impl Texture {
    /// Prepares synthesis from precomputed candidates. Tiles are kept in
    /// `cache`, which may be shared by many textures.
    pub fn new(
        candidates: Arc<Candidates>,
        params: SynthParams,
        cache: Arc<TileCache>,
    ) -> Result<Texture> {
        params.validate()?;
        Ok(Texture {
            engine: Arc::new(Engine::new(candidates, params, cache)?),
            split: None,
        })
    }

    /// A region texture: `inner` in the region of `split`, `outer`
    /// elsewhere, mixed across its band (see [`crate::region`]). Each keeps
    /// synthesizing lazily on its own; nesting is bounded by
    /// [`region::MAX_DEPTH`], and neither may be periodic (a region does
    /// not repeat).
    pub fn with_region(outer: Texture, inner: Texture, split: Split) -> Result<Texture> {
        split.check()?;
        let depth = 1 + outer.depth().max(inner.depth());
        if depth > region::MAX_DEPTH {
            return Err(Error::InvalidRequest(format!(
                "region textures nest at most {} deep",
                region::MAX_DEPTH
            )));
        }
        if [&outer, &inner].iter().any(|t| t.is_periodic()) {
            return Err(Error::InvalidRequest(
                "a region texture cannot use a periodic texture: the region does not repeat".into(),
            ));
        }
        Ok(Texture {
            engine: outer.engine.clone(),
            split: Some(Arc::new(Composite {
                outer,
                inner,
                split,
                depth,
            })),
        })
    }

    /// Region textures nested in this one, itself included (0 for a solid).
    fn depth(&self) -> usize {
        self.split.as_ref().map_or(0, |c| c.depth)
    }

    /// Whether this texture, or one it is made of, repeats with a period.
    fn is_periodic(&self) -> bool {
        match &self.split {
            None => self.engine.params().period.is_some(),
            Some(c) => c.outer.is_periodic() || c.inner.is_periodic(),
        }
    }

    /// The region and band of a region texture.
    pub fn region(&self) -> Option<&Split> {
        self.split.as_ref().map(|c| &c.split)
    }

    /// The same candidates under other synthesis parameters, sharing what
    /// was derived from them.
    pub fn with_params(&self, params: SynthParams, cache: Arc<TileCache>) -> Result<Texture> {
        Texture::new(self.engine.shared_candidates().clone(), params, cache)
    }

    /// The precomputed candidates this texture synthesizes from (a region
    /// texture's outer solid's).
    pub fn candidates(&self) -> &Candidates {
        self.engine.candidates()
    }

    /// The synthesis parameters (a region texture's outer solid's).
    pub fn params(&self) -> &SynthParams {
        self.engine.params()
    }

    /// The local frame of the texture's field at `p`, in voxels of level
    /// of detail `lod` (a voxel stands for the 2^lod-wide cube around its
    /// centre): the local x, y and z axes in world coordinates, the world
    /// axes when the texture has no field.
    pub fn frame(&self, lod: u32, p: [f64; 3]) -> [[f64; 3]; 3] {
        self.engine.field().map_or(crate::field::IDENTITY, |f| {
            f.frame(crate::field::world(lod as usize, p))
        })
    }

    /// Highest level of detail served: lod k is pyramid level L−k, voxels
    /// 2^k finest voxels wide, addressed in its own voxel units.
    pub fn max_lod(&self) -> u32 {
        match &self.split {
            None => self.engine.max_lod(),
            Some(c) => c.outer.max_lod().min(c.inner.max_lod()),
        }
    }

    /// The answer to `request` at level of detail `lod`, as RGB8 in the
    /// order its kind gives (see [`RequestKind`]), with what it cost.
    pub fn render(&self, request: &Request, lod: u32) -> Result<(Vec<u8>, SynthStats)> {
        self.render_progress(request, lod, &|_, _| {})
    }

    /// [`Texture::render`], telling `progress` (items answered, total) as
    /// it goes: a bake step by step, anything else once, when done.
    pub fn render_progress(
        &self,
        request: &Request,
        lod: u32,
        progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<(Vec<u8>, SynthStats)> {
        self.check_lod(lod)?;
        if let Some(c) = &self.split {
            return self.render_split(c, request, lod, progress);
        }
        let e = &self.engine;
        match request.kind() {
            RequestKind::Region(r) => e.region_rgb(r, lod),
            RequestKind::Slice(s) => {
                let (rgb, stats) = e.region_rgb(&s.region(), lod)?;
                Ok((slice_rows(s, rgb), stats))
            }
            RequestKind::Cut(c) => e.cut_rgb(&c.plane, lod, c.filter),
            RequestKind::Points(p) => e.points_rgb(p, lod),
            RequestKind::Bake(b) => return self.render_bake(b, lod, progress),
        }
        .inspect(|_| progress(request.voxels(), request.voxels()))
    }

    /// [`Texture::render_progress`] of a region texture.
    fn render_split(
        &self,
        c: &Composite,
        request: &Request,
        lod: u32,
        progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<(Vec<u8>, SynthStats)> {
        match c.side(request, lod)? {
            Side::Outer => return c.outer.render_progress(request, lod, progress),
            Side::Inner => return c.inner.render_progress(request, lod, progress),
            Side::Mixed => {}
        }
        // A step of voxels at a time, so that a large box keeps its
        // positions and weights in memory a step at a time.
        let voxels = |all: &mut dyn Iterator<Item = [i64; 3]>| -> Result<(Vec<u8>, SynthStats)> {
            let mut out = Vec::with_capacity(request.voxels() as usize * 3);
            let mut stats = SynthStats::default();
            loop {
                let step: Vec<[i64; 3]> = (&mut *all).take(BAKE_STEP).collect();
                if step.is_empty() {
                    return Ok((out, stats));
                }
                let (colours, s) = c.colours(&step, lod, None)?;
                stats.merge(&s);
                out.extend(colours.iter().flat_map(|&c| rgb8(c)));
            }
        };
        match request.kind() {
            RequestKind::Region(r) => voxels(&mut r.voxels()),
            RequestKind::Slice(s) => {
                let (rgb, stats) = voxels(&mut s.region().voxels())?;
                Ok((slice_rows(s, rgb), stats))
            }
            RequestKind::Points(p) => voxels(&mut p.iter().copied()),
            RequestKind::Cut(cut) => {
                self.samples_rgb(&plane_points(&cut.plane), lod, cut.filter, None)
            }
            RequestKind::Bake(b) => return self.render_bake(b, lod, progress),
        }
        .inspect(|_| progress(request.voxels(), request.voxels()))
    }

    /// The colours at points anywhere, read through `filter`, each voxel
    /// synthesized once however many points read it.
    fn samples_rgb(
        &self,
        points: &[[f64; 3]],
        lod: u32,
        filter: crate::Filter,
        surface: Option<&Surface>,
    ) -> Result<(Vec<u8>, SynthStats)> {
        let Some(c) = &self.split else {
            return self.engine.samples_rgb(points, lod, filter);
        };
        let (pts, weights) = sample_voxels(points, filter);
        let unique = unique_voxels(&pts);
        let (colours, stats) = c.colours(&unique, lod, surface)?;
        Ok((
            filtered_rgb(&pts, &weights, filter, &unique, &colours),
            stats,
        ))
    }

    /// The colours of voxels anywhere at level of detail `lod`, in the
    /// order given: a region texture reads each of its solids only where
    /// the region's weight asks for it.
    fn colours(
        &self,
        voxels: &[[i64; 3]],
        lod: u32,
        surface: Option<&Surface>,
    ) -> Result<(Vec<[f32; 3]>, SynthStats)> {
        match &self.split {
            None => self.engine.colours_at(voxels, lod),
            Some(c) => c.colours(voxels, lod, surface),
        }
    }

    /// Whether a region of this texture, or of one it is made of, is a
    /// shell below a mesh's surface.
    fn has_shell(&self) -> bool {
        self.split.as_ref().is_some_and(|c| {
            c.split.region.is_shell() || c.outer.has_shell() || c.inner.has_shell()
        })
    }

    /// The surface a bake's shell regions are measured from, when any
    /// region needs one.
    fn surface(&self, b: &Bake, lod: u32) -> Option<Surface> {
        self.has_shell().then(|| Surface::of(b, lod))
    }

    /// What a cold-cache synthesis of the voxels `voxels` would compute.
    fn plan_voxels(
        &self,
        voxels: &[[i64; 3]],
        lod: u32,
        surface: Option<&Surface>,
    ) -> Result<SynthStats> {
        let Some(c) = &self.split else {
            return Ok(self.engine.plan_points(voxels, lod));
        };
        let (outer, inner, _) = c.partition(voxels, lod, surface)?;
        let mut stats = SynthStats::default();
        for (t, v) in [(&c.outer, outer), (&c.inner, inner)] {
            if !v.is_empty() {
                let pts: Vec<[i64; 3]> = v.iter().map(|&i| voxels[i]).collect();
                stats.merge(&t.plan_voxels(&pts, lod, surface)?);
            }
        }
        Ok(stats)
    }

    /// A bake's texels (or vertices), [`BAKE_STEP`] at a time.
    fn render_bake(
        &self,
        b: &Bake,
        lod: u32,
        progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<(Vec<u8>, SynthStats)> {
        let n = b.items();
        let mut out = vec![0u8; n * 3];
        let mut stats = SynthStats::default();
        let surface = self.surface(b, lod);
        for start in (0..n).step_by(BAKE_STEP) {
            let end = (start + BAKE_STEP).min(n);
            let (items, points): (Vec<usize>, Vec<[f64; 3]>) = (start..end)
                .into_par_iter()
                .filter_map(|i| b.sample(i).map(|p| (i, p)))
                .unzip();
            let (rgb, s) = self.samples_rgb(&points, lod, b.options().filter, surface.as_ref())?;
            stats.merge(&s);
            for (&i, c) in items.iter().zip(rgb.chunks_exact(3)) {
                out[i * 3..i * 3 + 3].copy_from_slice(c);
            }
            progress(end as u64, n as u64);
        }
        Ok((out, stats))
    }

    /// An upper bound of a bake's synthesis. The voxels it reads are
    /// grouped as the engine groups them and each group's chain counted as
    /// one union (`estimate::grouped_union`); every tile read holds a
    /// voxel of it, so counting stops once there are more tiles than the
    /// limit. Past [`MAX_ESTIMATE_TILES`] tiles (a bake of millions of
    /// scattered texels) the looser bound of the aligned blocks of
    /// [`ESTIMATE_BLOCK`] voxels it reads, each counted on its own, keeps
    /// the memory small; each block counts at least its own voxels, so
    /// that count stops once there are more blocks than the limit pays for.
    fn estimate_bake(&self, b: &Bake, lod: u32, limit: u64) -> WorkEstimate {
        self.estimate_bake_within(b, lod, limit, MAX_ESTIMATE_TILES)
    }

    /// [`Texture::estimate_bake`] with the blocks' bound past `max_tiles`.
    fn estimate_bake_within(
        &self,
        b: &Bake,
        lod: u32,
        limit: u64,
        max_tiles: usize,
    ) -> WorkEstimate {
        let side = i64::from(ESTIMATE_BLOCK);
        let most_blocks = limit / u64::from(ESTIMATE_BLOCK).pow(3) + 1;
        let over = || WorkEstimate {
            per_level: Vec::new(),
            total: limit.saturating_add(1),
            complete: false,
        };
        let mut blocks = rustc_hash::FxHashSet::default();
        let mut masks = Some(Masks::default());
        let mut too_many = false;
        bake_voxels(b, |voxels| {
            for v in voxels {
                blocks.insert(v.map(|c| c.div_euclid(side) * side));
                if let Some(m) = &mut masks {
                    add_voxel(m, v);
                }
            }
            match &masks {
                Some(m) if m.len() as u64 > limit => too_many = true,
                Some(m) if m.len() > max_tiles => masks = None,
                None if blocks.len() as u64 > most_blocks => too_many = true,
                _ => {}
            }
            if too_many {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        });
        if too_many {
            return over();
        }
        if let Some(m) = masks {
            return self.engine.estimate_grouped(&m, lod, limit);
        }
        let mut corners: Vec<[i64; 3]> = blocks.into_iter().collect();
        corners.sort_unstable();
        self.engine
            .estimate_blocks(&corners, ESTIMATE_BLOCK, lod, limit)
    }

    /// Every point a bake samples.
    fn bake_points(b: &Bake) -> Vec<[f64; 3]> {
        (0..b.items())
            .into_par_iter()
            .filter_map(|i| b.sample(i))
            .collect()
    }

    /// What a cold-cache synthesis of `request` would compute, per level,
    /// counted without computing it (the paper's Table 1/2 form).
    pub fn plan(&self, request: &Request, lod: u32) -> Result<SynthStats> {
        self.check_lod(lod)?;
        if let Some(c) = &self.split {
            return match c.side(request, lod)? {
                Side::Outer => c.outer.plan(request, lod),
                Side::Inner => c.inner.plan(request, lod),
                Side::Mixed => {
                    let surface = match request.kind() {
                        RequestKind::Bake(b) => self.surface(b, lod),
                        _ => None,
                    };
                    self.plan_voxels(&request_voxels(request), lod, surface.as_ref())
                }
            };
        }
        let e = &self.engine;
        Ok(match request.kind() {
            RequestKind::Region(r) => e.plan_region(r, lod),
            RequestKind::Slice(s) => e.plan_region(&s.region(), lod),
            RequestKind::Cut(c) => e.plan_cut(&c.plane, lod, c.filter),
            RequestKind::Points(p) => e.plan_points(p, lod),
            RequestKind::Bake(b) => e.plan_samples(&Self::bake_points(b), lod, b.options().filter),
        })
    }

    /// An upper bound of the voxels a cold-cache synthesis of `request`
    /// computes over all levels (what [`Texture::plan`] counts), found in
    /// time that depends on the request's size in tile groups rather than
    /// voxels. Counting stops once the bound passes `limit`.
    pub fn estimate(&self, request: &Request, lod: u32, limit: u64) -> Result<WorkEstimate> {
        self.check_lod(lod)?;
        if let Some(c) = &self.split {
            return match c.side(request, lod)? {
                Side::Outer => c.outer.estimate(request, lod, limit),
                Side::Inner => c.inner.estimate(request, lod, limit),
                Side::Mixed => {
                    let a = c.outer.estimate(request, lod, limit)?;
                    let b = c
                        .inner
                        .estimate(request, lod, limit.saturating_sub(a.total))?;
                    Ok(sum_estimates(a, b))
                }
            };
        }
        let e = &self.engine;
        Ok(match request.kind() {
            RequestKind::Region(r) => e.estimate_region(r, lod, limit),
            RequestKind::Slice(s) => e.estimate_region(&s.region(), lod, limit),
            RequestKind::Cut(c) => e.estimate_cut(&c.plane, lod, c.filter, limit),
            RequestKind::Points(p) => e.estimate_points(p, lod, limit),
            RequestKind::Bake(b) => self.estimate_bake(b, lod, limit),
        })
    }

    /// A guess of the voxels a cold-cache synthesis of `request` computes,
    /// for progress reports: what a share of finished work is measured
    /// against. For a bake it is much closer than [`Texture::estimate`]'s
    /// bound, and no bound itself; for the rest it is that bound.
    pub fn predict(&self, request: &Request, lod: u32) -> Result<u64> {
        self.check_lod(lod)?;
        if let Some(c) = &self.split {
            return match c.side(request, lod)? {
                Side::Outer => c.outer.predict(request, lod),
                Side::Inner => c.inner.predict(request, lod),
                Side::Mixed => Ok(c
                    .outer
                    .predict(request, lod)?
                    .saturating_add(c.inner.predict(request, lod)?)),
            };
        }
        let RequestKind::Bake(b) = request.kind() else {
            return Ok(self.estimate(request, lod, u64::MAX)?.total);
        };
        let mut masks = Masks::default();
        bake_voxels(b, |voxels| {
            voxels.into_iter().for_each(|v| add_voxel(&mut masks, v));
            ControlFlow::Continue(())
        });
        Ok(self.engine.predict_union(masks, lod))
    }

    /// Exact voxel-level dependency chain of a few voxels at `lod`:
    /// version-0 voxels and corrections per level, finest first. It
    /// follows what a correction reads, its direct neighbours, unless
    /// `neighbourhood` names another side N: the chain is geometry only,
    /// so this answers what a larger N (Zhang et al. use 9) would cost
    /// without precomputing for it.
    pub fn dependency_chain(
        &self,
        voxels: &[[i64; 3]],
        lod: u32,
        neighbourhood: Option<u32>,
    ) -> Result<Vec<(u64, u64)>> {
        self.check_lod(lod)?;
        if let Some(c) = &self.split {
            // Both solids' chains, as a voxel on the boundary reads both.
            let a = c.outer.dependency_chain(voxels, lod, neighbourhood)?;
            let b = c.inner.dependency_chain(voxels, lod, neighbourhood)?;
            let n = a.len().max(b.len());
            let at = |v: &[(u64, u64)], i: usize| v.get(i).copied().unwrap_or_default();
            return Ok((0..n)
                .map(|i| (at(&a, i).0 + at(&b, i).0, at(&a, i).1 + at(&b, i).1))
                .collect());
        }
        let radius = match neighbourhood {
            None => self.engine.radius(),
            Some(n) if !n.is_multiple_of(2) && (3..=9).contains(&n) => n as i64 / 2,
            Some(_) => {
                return Err(Error::InvalidRequest(
                    "neighbourhood must be odd, 3 to 9".into(),
                ));
            }
        };
        self.chain(voxels, lod, radius)
    }

    fn chain(&self, voxels: &[[i64; 3]], lod: u32, radius: i64) -> Result<Vec<(u64, u64)>> {
        if voxels.len() > 1 << 20 {
            return Err(Error::TooLarge("at most 2^20 voxels".into()));
        }
        Ok(self
            .engine
            .exact_chain(voxels, lod, radius)
            .into_iter()
            .map(|l| (l.voxels, l.corrections))
            .collect())
    }

    fn check_lod(&self, lod: u32) -> Result<()> {
        if lod > self.max_lod() {
            return Err(Error::InvalidRange {
                name: "lod",
                value: lod as f64,
                min: 0.0,
                max: self.max_lod() as f64,
            });
        }
        Ok(())
    }
}

impl Composite {
    /// Which solids `request` reads; a shell region, which needs a mesh's
    /// surface, answers only bakes.
    fn side(&self, request: &Request, lod: u32) -> Result<Side> {
        if self.split.region.is_shell() {
            return match request.kind() {
                RequestKind::Bake(_) => Ok(Side::Mixed),
                _ => Err(Error::InvalidRequest(
                    "this region texture's region is a shell below a mesh's surface: \
                     only a bake has a surface to measure it from"
                        .into(),
                )),
            };
        }
        let corners = |lo: [f64; 3], hi: [f64; 3]| self.split.side_of_box(lod, lo, hi);
        let boxed = |r: &crate::Region| {
            let lo = r.origin.map(|c| c as f64);
            corners(lo, [0, 1, 2].map(|a| lo[a] + f64::from(r.size[a]) - 1.0))
        };
        Ok(match request.kind() {
            RequestKind::Region(r) => boxed(r),
            RequestKind::Slice(s) => boxed(&s.region()),
            RequestKind::Cut(c) => {
                let p = &c.plane;
                let (i, j) = (p.width - 1, p.height - 1);
                let pts = [(0, 0), (i, 0), (0, j), (i, j)].map(|(i, j)| p.at(i, j));
                // A trilinear sample reads the voxels around it too.
                let (lo, hi) = bounds(pts.iter().copied());
                corners(lo.map(|c| c.floor() - 1.0), hi.map(|c| c.ceil() + 1.0))
            }
            RequestKind::Points(p) => {
                let (lo, hi) = bounds(p.iter().map(|v| v.map(|c| c as f64)));
                corners(lo, hi)
            }
            RequestKind::Bake(_) => Side::Mixed,
        })
    }

    /// The indices of `voxels` that read the outer solid, those that read
    /// the inner one, and every voxel's inner weight. A shell region is
    /// measured from `surface`.
    fn partition(
        &self,
        voxels: &[[i64; 3]],
        lod: u32,
        surface: Option<&Surface>,
    ) -> Result<(Vec<usize>, Vec<usize>, Vec<f32>)> {
        let split = &self.split;
        let distance = |p: [f64; 3]| match (&split.region, surface) {
            (region::Shape::Shell { thickness }, Some(s)) => {
                // Farther than the band's inner edge, any distance reads
                // the inner solid alone.
                let reach = thickness + split.band / 2.0 + 1.0;
                Some(thickness - s.distance(p, reach))
            }
            (region, _) => region.distance(p),
        };
        let weights: Vec<f32> = voxels
            .par_iter()
            .map(|v| distance(region::world(lod, v.map(|c| c as f64))).map(|d| split.weight(d)))
            .collect::<Option<_>>()
            .ok_or_else(|| {
                Error::InvalidRequest("a shell region needs a baked mesh's surface".into())
            })?;
        let outer = (0..voxels.len()).filter(|&i| weights[i] < 1.0).collect();
        let inner = (0..voxels.len()).filter(|&i| weights[i] > 0.0).collect();
        Ok((outer, inner, weights))
    }

    /// The mixed colours of `voxels`, each solid synthesized only at the
    /// voxels whose weight reads it.
    fn colours(
        &self,
        voxels: &[[i64; 3]],
        lod: u32,
        surface: Option<&Surface>,
    ) -> Result<(Vec<[f32; 3]>, SynthStats)> {
        let (outer, inner, weights) = self.partition(voxels, lod, surface)?;
        let mut stats = SynthStats::default();
        let mut read = |t: &Texture, idx: &[usize]| -> Result<Vec<[f32; 3]>> {
            let pts: Vec<[i64; 3]> = idx.iter().map(|&i| voxels[i]).collect();
            if pts.is_empty() {
                return Ok(Vec::new());
            }
            let (c, s) = t.colours(&pts, lod, surface)?;
            stats.merge(&s);
            Ok(c)
        };
        let (co, ci) = (read(&self.outer, &outer)?, read(&self.inner, &inner)?);
        let mut out = vec![[0f32; 3]; voxels.len()];
        for (&i, c) in outer.iter().zip(co) {
            out[i] = c;
        }
        for (&i, c) in inner.iter().zip(ci) {
            let w = weights[i];
            out[i] = if w == 1.0 {
                c
            } else {
                [0, 1, 2].map(|ch| (1.0 - w) * out[i][ch] + w * c[ch])
            };
        }
        Ok((out, stats))
    }
}

/// The lowest and highest coordinates of `points`.
fn bounds(points: impl Iterator<Item = [f64; 3]>) -> ([f64; 3], [f64; 3]) {
    points.fold(([f64::MAX; 3], [f64::MIN; 3]), |(lo, hi), p| {
        (
            [0, 1, 2].map(|a| lo[a].min(p[a])),
            [0, 1, 2].map(|a| hi[a].max(p[a])),
        )
    })
}

/// Every voxel `request` reads (those its samples read through its filter
/// for cuts and bakes), each once.
fn request_voxels(request: &Request) -> Vec<[i64; 3]> {
    match request.kind() {
        RequestKind::Region(r) => r.voxels().collect(),
        RequestKind::Slice(s) => s.region().voxels().collect(),
        RequestKind::Points(p) => unique_voxels(p),
        RequestKind::Cut(c) => unique_voxels(&sample_voxels(&plane_points(&c.plane), c.filter).0),
        RequestKind::Bake(b) => {
            unique_voxels(&sample_voxels(&Texture::bake_points(b), b.options().filter).0)
        }
    }
}

/// Two estimates added, level by level.
fn sum_estimates(a: WorkEstimate, b: WorkEstimate) -> WorkEstimate {
    let n = a.per_level.len().max(b.per_level.len());
    let at = |v: &[u64], i: usize| v.get(i).copied().unwrap_or(0);
    WorkEstimate {
        per_level: (0..n)
            .map(|i| at(&a.per_level, i).saturating_add(at(&b.per_level, i)))
            .collect(),
        total: a.total.saturating_add(b.total),
        complete: a.complete && b.complete,
    }
}

/// A slice's voxels, x fastest, as rows of its window (u fastest).
fn slice_rows(s: &Slice, rgb: Vec<u8>) -> Vec<u8> {
    let (_, u, v) = s.axis.frame();
    if u < v {
        // For z slices (u = x, v = y) and x slices (u = y, v = z) x fastest
        // already is u fastest.
        return rgb;
    }
    // y slices: u = z, v = x.
    let (width, height) = (s.window.width as usize, s.window.height as usize);
    let mut out = vec![0u8; rgb.len()];
    for j in 0..height {
        for i in 0..width {
            let src = (i * height + j) * 3;
            let dst = (j * width + i) * 3;
            out[dst..dst + 3].copy_from_slice(&rgb[src..src + 3]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bundled;
    use crate::mesh::{BakeOptions, Mesh};

    /// Past the tile cap a bake is bounded block by block: still at least
    /// what a cold cache synthesizes, and stopped once over the limit.
    #[test]
    fn a_bake_past_the_tile_cap_is_still_bounded_and_stops_over_the_limit() {
        let set = crate::ExemplarSet::single(bundled::exemplar());
        let candidates = bundled::candidates_for(&set, &Default::default()).expect("bundled");
        let cache = Arc::new(TileCache::new(64 << 20));
        let tex = Texture::new(Arc::new(candidates), SynthParams::default(), cache).unwrap();
        let bake = Bake::new(Arc::new(Mesh::unit_cube()), BakeOptions::new(48)).unwrap();
        let request = Request::bake(bake.clone()).unwrap();
        let exact: u64 = tex.plan(&request, 0).unwrap().voxels_per_level.iter().sum();
        let grouped = tex.estimate_bake_within(&bake, 0, u64::MAX, MAX_ESTIMATE_TILES);
        let blocks = tex.estimate_bake_within(&bake, 0, u64::MAX, 0);
        assert!(grouped.complete && blocks.complete);
        assert!(grouped.total >= exact, "{} under {exact}", grouped.total);
        assert!(blocks.total >= exact, "{} under {exact}", blocks.total);
        assert!(blocks.per_level.iter().sum::<u64>() == blocks.total);
        let small = tex.estimate_bake_within(&bake, 0, exact / 4, 0);
        assert!(!small.complete && small.total > exact / 4, "{small:?}");
    }
}
