//! The public face of synthesis: a [`Texture`] answers requests for voxel
//! regions, axis slices and oblique cuts by synthesizing exactly their
//! dependency set (see [`crate::synth`]).

use crate::candidates::Candidates;
use crate::error::{Error, Result};
use crate::params::SynthParams;
use crate::request::{
    Axis, CutPlane, Filter, MAX_REGION_VOXELS, Region, check_coords, check_region, check_side,
};
use crate::synth::cache::TileCache;
use crate::synth::estimate::WorkEstimate;
use crate::synth::{Engine, SynthStats};
use std::sync::Arc;

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

    /// RGB8 voxels of `region` at level of detail `lod`, x fastest, then y,
    /// then z.
    pub fn region(&self, region: &Region, lod: u32) -> Result<(Vec<u8>, SynthStats)> {
        self.check_lod(lod)?;
        check_region(region)?;
        self.engine.region_rgb(region, lod)
    }

    /// An axis-aligned slice as RGB8 rows: pixel (i, j) is voxel
    /// (u0 + i, v0 + j) in the plane `axis = at`, with (u, v) = (x, y) for z,
    /// (y, z) for x and (z, x) for y.
    #[allow(clippy::too_many_arguments)]
    pub fn slice(
        &self,
        axis: Axis,
        at: i64,
        u0: i64,
        v0: i64,
        width: u32,
        height: u32,
        lod: u32,
    ) -> Result<(Vec<u8>, SynthStats)> {
        check_side(width, height)?;
        let (_, u, v) = axis.frame();
        let region = Region::slice(axis, at, u0, v0, width, height);
        let (rgb, stats) = self.region(&region, lod)?;
        if u < v {
            // Region order is x fastest: for z slices (u=x, v=y) and x
            // slices (u=y, v=z) that already is row-major (u fastest).
            return Ok((rgb, stats));
        }
        // y slices: u = z, v = x, but the region is stored x fastest.
        let mut out = vec![0u8; rgb.len()];
        for j in 0..height as usize {
            for i in 0..width as usize {
                let src = (i * height as usize + j) * 3;
                let dst = (j * width as usize + i) * 3;
                out[dst..dst + 3].copy_from_slice(&rgb[src..src + 3]);
            }
        }
        Ok((out, stats))
    }

    /// An oblique cut as RGB8 rows (see [`CutPlane`]).
    pub fn cut(&self, plane: &CutPlane, lod: u32, filter: Filter) -> Result<(Vec<u8>, SynthStats)> {
        self.check_lod(lod)?;
        check_side(plane.width, plane.height)?;
        for c in plane.origin.iter().chain(&plane.u).chain(&plane.v) {
            if !c.is_finite() {
                return Err(Error::InvalidRequest("cut plane must be finite".into()));
            }
        }
        self.engine.cut_rgb(plane, lod, filter)
    }

    /// What a cold-cache synthesis of the cut `plane` would compute, per
    /// level, counted without computing it.
    pub fn plan_cut(&self, plane: &CutPlane, lod: u32, filter: Filter) -> Result<SynthStats> {
        self.check_lod(lod)?;
        check_side(plane.width, plane.height)?;
        Ok(self.engine.plan_cut(plane, lod, filter))
    }

    /// An upper bound of the voxels a cold-cache synthesis of `region`
    /// computes over all levels (what [`Texture::plan`] counts), found in
    /// time that depends on the request's size in tile groups rather than
    /// voxels. Counting stops once the bound passes `limit`.
    pub fn estimate(&self, region: &Region, lod: u32, limit: u64) -> Result<WorkEstimate> {
        self.check_lod(lod)?;
        check_region(region)?;
        Ok(self.engine.estimate_region(region, lod, limit))
    }

    /// [`Texture::estimate`] for the cut `plane` (what
    /// [`Texture::plan_cut`] counts).
    pub fn estimate_cut(
        &self,
        plane: &CutPlane,
        lod: u32,
        filter: Filter,
        limit: u64,
    ) -> Result<WorkEstimate> {
        self.check_lod(lod)?;
        check_side(plane.width, plane.height)?;
        for c in plane.origin.iter().chain(&plane.u).chain(&plane.v) {
            if !c.is_finite() {
                return Err(Error::InvalidRequest("cut plane must be finite".into()));
            }
        }
        Ok(self.engine.estimate_cut(plane, lod, filter, limit))
    }

    /// RGB8 colours of arbitrary voxels at level of detail `lod`.
    pub fn points(&self, points: &[[i64; 3]], lod: u32) -> Result<(Vec<[u8; 3]>, SynthStats)> {
        self.check_lod(lod)?;
        if points.len() as u64 > MAX_REGION_VOXELS {
            return Err(Error::TooLarge(format!(
                "{} points (limit {MAX_REGION_VOXELS})",
                points.len()
            )));
        }
        for p in points {
            check_coords(p)?;
        }
        self.engine.points_rgb(points, lod)
    }

    /// What a cold-cache synthesis of `region` would compute, per level,
    /// counted without computing it (the paper's Table 1/2 form).
    pub fn plan(&self, region: &Region, lod: u32) -> Result<SynthStats> {
        self.check_lod(lod)?;
        check_region(region)?;
        Ok(self.engine.plan_region(region, lod))
    }

    /// Exact voxel-level dependency chain of a few voxels at `lod`:
    /// version-0 voxels and corrections per level, finest first. It follows
    /// what a correction reads: its direct neighbours (radius 1).
    pub fn dependency_chain(&self, voxels: &[[i64; 3]], lod: u32) -> Result<Vec<(u64, u64)>> {
        self.check_lod(lod)?;
        self.chain(voxels, lod, self.engine.radius())
    }

    /// Like [`Texture::dependency_chain`], for neighbourhood side
    /// `neighbourhood` instead of the analysed one: the chain is geometry
    /// only, so this answers what a larger N (Zhang et al. use 9) would cost
    /// without precomputing for it.
    pub fn dependency_chain_for(
        &self,
        voxels: &[[i64; 3]],
        lod: u32,
        neighbourhood: u32,
    ) -> Result<Vec<(u64, u64)>> {
        self.check_lod(lod)?;
        if neighbourhood.is_multiple_of(2) || !(3..=9).contains(&neighbourhood) {
            return Err(Error::InvalidRequest(
                "neighbourhood must be odd, 3 to 9".into(),
            ));
        }
        self.chain(voxels, lod, neighbourhood as i64 / 2)
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
