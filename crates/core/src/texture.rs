//! The public face of synthesis: a [`Texture`] answers [`Request`]s (voxel
//! regions, axis slices, oblique cuts, scattered voxels) by synthesizing
//! exactly their dependency set (see [`crate::synth`]).

use crate::candidates::Candidates;
use crate::error::{Error, Result};
use crate::mesh::Bake;
use crate::params::SynthParams;
use crate::request::{Request, RequestKind, Slice};
use crate::synth::cache::TileCache;
use crate::synth::estimate::WorkEstimate;
use crate::synth::{Engine, SynthStats, sample_voxels};
use rayon::prelude::*;
use std::sync::Arc;

/// Texels (or vertices) of a bake synthesized per step: a step's sample
/// points and voxels stay in memory at once.
const BAKE_STEP: usize = 1 << 20;

/// Side of the blocks a bake's estimate bounds one by one: the thinner
/// the blocks, the closer the bound hugs the shell a surface needs, and
/// the more often it counts the coarse levels they share.
const ESTIMATE_BLOCK: u32 = 16;

/// A solid texture ready to be sampled anywhere. Cheap to clone; safe to
/// share between threads. Every method blocks while it synthesizes (using
/// rayon); call it from a blocking context.
#[derive(Clone)]
pub struct Texture {
    engine: Arc<Engine>,
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
        })
    }

    /// The same candidates under other synthesis parameters, sharing what
    /// was derived from them.
    pub fn with_params(&self, params: SynthParams, cache: Arc<TileCache>) -> Result<Texture> {
        Texture::new(self.engine.shared_candidates().clone(), params, cache)
    }

    /// The precomputed candidates this texture synthesizes from.
    pub fn candidates(&self) -> &Candidates {
        self.engine.candidates()
    }

    /// The synthesis parameters.
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
        self.engine.max_lod()
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
        for start in (0..n).step_by(BAKE_STEP) {
            let end = (start + BAKE_STEP).min(n);
            let (items, points): (Vec<usize>, Vec<[f64; 3]>) = (start..end)
                .into_par_iter()
                .filter_map(|i| b.sample(i).map(|p| (i, p)))
                .unzip();
            let (rgb, s) = self.engine.samples_rgb(&points, lod, b.options().filter)?;
            stats.merge(&s);
            for (&i, c) in items.iter().zip(rgb.chunks_exact(3)) {
                out[i * 3..i * 3 + 3].copy_from_slice(c);
            }
            progress(end as u64, n as u64);
        }
        Ok((out, stats))
    }

    /// The bounds of the aligned blocks of [`ESTIMATE_BLOCK`] voxels a
    /// bake reads, summed. Each block counts at least its own voxels, so
    /// counting stops once there are more blocks than the limit pays for.
    fn estimate_bake(&self, b: &Bake, lod: u32, limit: u64) -> WorkEstimate {
        let side = i64::from(ESTIMATE_BLOCK);
        let most = limit / u64::from(ESTIMATE_BLOCK).pow(3) + 1;
        let mut blocks = rustc_hash::FxHashSet::default();
        for start in (0..b.items()).step_by(BAKE_STEP) {
            let end = (start + BAKE_STEP).min(b.items());
            let points: Vec<[f64; 3]> = (start..end)
                .into_par_iter()
                .filter_map(|i| b.sample(i))
                .collect();
            for v in sample_voxels(&points, b.options().filter).0 {
                blocks.insert(v.map(|c| c.div_euclid(side) * side));
            }
            if blocks.len() as u64 > most {
                return WorkEstimate {
                    per_level: Vec::new(),
                    total: limit.saturating_add(1),
                    complete: false,
                };
            }
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
        let e = &self.engine;
        Ok(match request.kind() {
            RequestKind::Region(r) => e.estimate_region(r, lod, limit),
            RequestKind::Slice(s) => e.estimate_region(&s.region(), lod, limit),
            RequestKind::Cut(c) => e.estimate_cut(&c.plane, lod, c.filter, limit),
            RequestKind::Points(p) => e.estimate_points(p, lod, limit),
            RequestKind::Bake(b) => self.estimate_bake(b, lod, limit),
        })
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
