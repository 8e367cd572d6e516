//! The public face of synthesis: a [`Texture`] answers requests for voxel
//! regions, axis slices and oblique cuts by synthesizing exactly their
//! dependency set (see [`crate::synth`]).

use crate::candidates::Candidates;
use crate::error::{Error, Result};
use crate::params::SynthParams;
use crate::synth::Engine;
use crate::synth::cache::TileCache;
pub use crate::synth::estimate::WorkEstimate;
use std::sync::Arc;

/// Largest side of a slice or cut, in pixels.
pub const MAX_SLICE_SIDE: u32 = 4096;
/// Largest number of voxels in one region request.
pub const MAX_REGION_VOXELS: u64 = 16 << 20;
/// Coordinates must lie within ±2^31 (finest-level voxels).
pub const COORD_LIMIT: i64 = 1 << 31;

/// An axis-aligned box of voxels: `origin` is its lowest corner, `size` its
/// extent along x, y, z.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Region {
    /// Lowest corner.
    pub origin: [i64; 3],
    /// Extent along x, y, z (each ≥ 1).
    pub size: [u32; 3],
}

impl Region {
    /// Number of voxels, or `None` where the product of the sides does not
    /// fit a `u64` (three sides of 2^24 would wrap to 0).
    pub fn voxel_count(&self) -> Option<u64> {
        self.size
            .iter()
            .try_fold(1u64, |n, &side| n.checked_mul(side as u64))
    }

    /// The `width` × `height` slice normal to `axis` at `at`, with its
    /// (u, v) corner at (`u0`, `v0`); (u, v) is (x, y) for z, (y, z) for x
    /// and (z, x) for y.
    pub fn slice(axis: Axis, at: i64, u0: i64, v0: i64, width: u32, height: u32) -> Region {
        let (n, u, v) = axis.frame();
        let mut origin = [0i64; 3];
        let mut size = [1u32; 3];
        origin[n] = at;
        origin[u] = u0;
        origin[v] = v0;
        size[u] = width;
        size[v] = height;
        Region { origin, size }
    }

    /// Every voxel of the box, x fastest, then y, then z.
    pub fn voxels(&self) -> impl Iterator<Item = [i64; 3]> + '_ {
        let [w, h, d] = self.size.map(|s| s as i64);
        let o = self.origin;
        (0..d).flat_map(move |z| {
            (0..h).flat_map(move |y| (0..w).map(move |x| [o[0] + x, o[1] + y, o[2] + z]))
        })
    }
}

/// A volume axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Axis {
    /// The x axis (slices span y, z).
    X,
    /// The y axis (slices span z, x).
    Y,
    /// The z axis (slices span x, y).
    Z,
}

impl std::str::FromStr for Axis {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "x" | "X" => Ok(Axis::X),
            "y" | "Y" => Ok(Axis::Y),
            "z" | "Z" => Ok(Axis::Z),
            _ => Err(Error::InvalidRequest(format!(
                "unknown axis `{s}` (expected x, y or z)"
            ))),
        }
    }
}

impl Axis {
    /// (normal axis index, u axis index, v axis index): u, v are (x, y) for
    /// z, (y, z) for x and (z, x) for y.
    pub fn frame(self) -> (usize, usize, usize) {
        match self {
            Axis::Z => (2, 0, 1),
            Axis::X => (0, 1, 2),
            Axis::Y => (1, 2, 0),
        }
    }
}

/// An oblique plane: pixel (i, j) samples `origin + i·u + j·v`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CutPlane {
    /// Position of pixel (0, 0), in voxels of the served level.
    pub origin: [f64; 3],
    /// Step per pixel along the image's horizontal axis.
    pub u: [f64; 3],
    /// Step per pixel along the image's vertical axis.
    pub v: [f64; 3],
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
}

/// How an oblique cut samples between voxel centres.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Filter {
    /// The nearest voxel.
    #[default]
    Nearest,
    /// Trilinear blend of the eight surrounding voxels.
    Trilinear,
}

/// What one request cost: voxels synthesized and corrected per pyramid level
/// (index 0 is the finest level) and tiles computed or found in the cache.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SynthStats {
    /// Voxels whose triple was produced (upsampled or initialised), per level.
    pub voxels_per_level: Vec<u64>,
    /// Voxel corrections performed, per level.
    pub corrections_per_level: Vec<u64>,
    /// Tiles synthesized by this request.
    pub tiles_computed: u64,
    /// Tiles served from the cache (or computed by a concurrent request),
    /// counting those of which the cache held some of the voxels needed.
    pub tiles_from_cache: u64,
}

impl SynthStats {
    /// Adds another request's counts to these.
    pub fn merge(&mut self, other: &SynthStats) {
        for (dst, src) in [
            (&mut self.voxels_per_level, &other.voxels_per_level),
            (
                &mut self.corrections_per_level,
                &other.corrections_per_level,
            ),
        ] {
            if dst.len() < src.len() {
                dst.resize(src.len(), 0);
            }
            for (d, s) in dst.iter_mut().zip(src) {
                *d += s;
            }
        }
        self.tiles_computed += other.tiles_computed;
        self.tiles_from_cache += other.tiles_from_cache;
    }
}

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
            engine: Arc::new(Engine::new(candidates, params, cache)),
        })
    }

    /// The precomputed candidates this texture synthesizes from.
    pub fn candidates(&self) -> &Candidates {
        self.engine.candidates()
    }

    /// The synthesis parameters.
    pub fn params(&self) -> &SynthParams {
        self.engine.params()
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
    /// what a correction reads: radius 1 with sparse slices, N/2 with full
    /// ones.
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

fn check_side(width: u32, height: u32) -> Result<()> {
    if width == 0 || height == 0 {
        return Err(Error::InvalidRequest("width and height must be ≥ 1".into()));
    }
    if width > MAX_SLICE_SIDE || height > MAX_SLICE_SIDE {
        return Err(Error::TooLarge(format!(
            "{width}x{height} (each side ≤ {MAX_SLICE_SIDE})"
        )));
    }
    Ok(())
}

fn check_coords(p: &[i64; 3]) -> Result<()> {
    for &c in p {
        if !(-COORD_LIMIT..=COORD_LIMIT).contains(&c) {
            return Err(Error::InvalidRange {
                name: "coordinate",
                value: c as f64,
                min: -(COORD_LIMIT as f64),
                max: COORD_LIMIT as f64,
            });
        }
    }
    Ok(())
}

fn check_region(r: &Region) -> Result<()> {
    if r.size.contains(&0) {
        return Err(Error::InvalidRequest(
            "region size must be ≥ 1 on every axis".into(),
        ));
    }
    match r.voxel_count() {
        Some(voxels) if voxels <= MAX_REGION_VOXELS => {}
        _ => {
            let [w, h, d] = r.size;
            return Err(Error::TooLarge(format!(
                "{w}x{h}x{d} voxels (limit {MAX_REGION_VOXELS})"
            )));
        }
    }
    check_coords(&r.origin)?;
    let far = [
        r.origin[0] + r.size[0] as i64 - 1,
        r.origin[1] + r.size[1] as i64 - 1,
        r.origin[2] + r.size[2] as i64 - 1,
    ];
    check_coords(&far)
}
