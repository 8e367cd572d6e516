//! A mesh baked from the solid: what is asked (mesh, placement, texture
//! layout, filter) and which surface point each output texel or vertex
//! shows. A [`Bake`] is the payload of [`crate::RequestKind::Bake`].

use super::atlas::{Layout, MIN_CELL};
use super::place::{Placement, Transform};
use super::{Mesh, glb};
use crate::error::{Error, Result};
use crate::request::{Filter, MAX_SLICE_SIDE};
use std::sync::Arc;

/// Whose texture coordinates the baked texture follows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Uvs {
    /// The mesh's own when it has valid ones (all within [0, 1]), else a
    /// generated atlas.
    #[default]
    Auto,
    /// The mesh's own; a mesh without valid ones is refused.
    Mesh,
    /// A generated atlas, one chart per triangle.
    Atlas,
}

/// Where the colours go.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Colours {
    /// A base-colour texture.
    #[default]
    Texture,
    /// One colour per vertex (`COLOR_0`), no texture: for dense meshes.
    Vertex,
}

/// What a bake asks for besides the mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BakeOptions {
    /// Where the mesh lies in texture space.
    pub placement: Placement,
    /// Side of the baked texture in texels; `None` chooses about one texel
    /// per voxel of surface, from 256 to 4096.
    pub texture_size: Option<u32>,
    /// Whose texture coordinates the texture follows.
    pub uvs: Uvs,
    /// Texture or vertex colours.
    pub colours: Colours,
    /// How a surface point reads the voxels around it.
    pub filter: Filter,
    /// How far the pieces of a cut mesh are pulled apart in the output,
    /// each away from the planes, as a share of the mesh's longest side
    /// (0 to [`MAX_SPREAD`]); the texture is baked where they were.
    pub spread: f32,
}

/// Largest [`BakeOptions::spread`].
pub const MAX_SPREAD: f32 = 1.0;

impl BakeOptions {
    /// A texture baked at `resolution` with every other choice left to the
    /// defaults.
    pub fn new(resolution: u32) -> BakeOptions {
        BakeOptions {
            placement: Placement::new(resolution),
            texture_size: None,
            uvs: Uvs::Auto,
            colours: Colours::Texture,
            filter: Filter::Nearest,
            spread: 0.0,
        }
    }
}

/// Smallest texture side chosen or accepted.
const MIN_TEXTURE: u32 = 16;
/// Smallest texture side chosen automatically.
const AUTO_MIN_TEXTURE: u32 = 256;

/// A checked bake: the mesh, where it lies and where each output texel
/// (or vertex) samples the solid. Cheap to clone.
#[derive(Clone)]
pub struct Bake(Arc<Inner>);

struct Inner {
    mesh: Arc<Mesh>,
    options: BakeOptions,
    transform: Transform,
    /// `None` for vertex colours.
    layout: Option<Layout>,
    fingerprint: u64,
}

impl Bake {
    /// Places `mesh` and lays out its texture as `options` ask.
    pub fn new(mesh: Arc<Mesh>, options: BakeOptions) -> Result<Bake> {
        options.placement.check()?;
        if !(0.0..=MAX_SPREAD).contains(&options.spread) {
            return Err(Error::InvalidRange {
                name: "spread",
                value: f64::from(options.spread),
                min: 0.0,
                max: f64::from(MAX_SPREAD),
            });
        }
        if mesh.is_cut() && options.colours == Colours::Vertex {
            return Err(Error::InvalidParameter {
                name: "colours",
                reason: "a cut mesh needs a texture: colours at the vertices cannot show \
                         the inside of its caps"
                    .into(),
            });
        }
        let transform = options.placement.transform(&mesh);
        let layout = match options.colours {
            Colours::Vertex => None,
            Colours::Texture => Some(layout(&mesh, &options, &transform)?),
        };
        Ok(Bake(Arc::new(Inner {
            fingerprint: mesh.fingerprint(),
            mesh,
            options,
            transform,
            layout,
        })))
    }

    /// The mesh baked.
    pub fn mesh(&self) -> &Mesh {
        &self.0.mesh
    }

    /// What was asked.
    pub fn options(&self) -> &BakeOptions {
        &self.0.options
    }

    /// Whether the texture follows the mesh's own texture coordinates.
    pub fn uses_mesh_uvs(&self) -> bool {
        matches!(self.0.layout, Some(Layout::Owners { .. }))
    }

    /// Side of the baked texture (`None` for vertex colours).
    pub fn texture_side(&self) -> Option<u32> {
        self.0.layout.as_ref().map(Layout::side)
    }

    /// The answer's extent: the texture's (side, side, 1), or (vertices,
    /// 1, 1) for vertex colours.
    pub fn size(&self) -> [u32; 3] {
        match self.texture_side() {
            Some(s) => [s, s, 1],
            // At most u32::MAX vertices (read::glb checks).
            None => [self.mesh().positions().len() as u32, 1, 1],
        }
    }

    /// Texels (or vertices) in the answer, each RGB8 in row order.
    pub fn items(&self) -> usize {
        let [w, h, _] = self.size();
        w as usize * h as usize
    }

    /// Where a point of the mesh lies in texture space (voxels of the
    /// level baked).
    pub(crate) fn place(&self, p: [f32; 3]) -> [f64; 3] {
        self.0.transform.apply(p)
    }

    /// Where in texture space item `i` (a texel, row by row, or a vertex)
    /// samples the solid; `None` for a texel no triangle shows.
    pub fn sample(&self, i: usize) -> Option<[f64; 3]> {
        let inner = &*self.0;
        let mesh = &inner.mesh;
        let Some(layout) = &inner.layout else {
            return Some(inner.transform.apply(mesh.positions()[i]));
        };
        let tris = mesh.triangles();
        let (tri, [v, w]) = layout.texel(i, tris.len(), &|t| self.chart(t))?;
        let p = tris[tri].map(|k| inner.transform.apply(mesh.positions()[k as usize]));
        let (v, w) = (f64::from(v), f64::from(w));
        Some([0, 1, 2].map(|a| p[0][a] + v * (p[1][a] - p[0][a]) + w * (p[2][a] - p[0][a])))
    }

    /// The triangle texel `i` of the baked texture shows (`None` for a
    /// texel no triangle shows, and for vertex colours).
    pub fn texel_triangle(&self, i: usize) -> Option<usize> {
        let layout = self.0.layout.as_ref()?;
        let tris = self.mesh().triangles().len();
        layout.texel(i, tris, &|t| self.chart(t)).map(|(t, _)| t)
    }

    /// Triangle `t`'s chart in texels of the baked texture.
    pub(super) fn chart(&self, t: usize) -> [[f32; 2]; 3] {
        match &self.0.layout {
            Some(Layout::Cells { grid, cell, .. }) => Layout::chart(*cell, *grid, t),
            Some(Layout::Owners { side, .. }) => {
                let uvs = self.mesh().uvs().unwrap_or_default();
                let s = *side as f32;
                self.mesh().triangles()[t].map(|k| uvs[k as usize].map(|c| c * s))
            }
            None => [[0.0; 2]; 3],
        }
    }

    /// The textured mesh as a glTF 2.0 binary, from the answer `rgb` of
    /// this bake (as [`crate::Texture::render`] gives it).
    pub fn glb(&self, rgb: &[u8]) -> Result<Vec<u8>> {
        if rgb.len() != self.items() * 3 {
            return Err(Error::InvalidRequest(format!(
                "{} bytes of colour for a bake of {} items",
                rgb.len(),
                self.items()
            )));
        }
        glb::write(self, rgb)
    }

    /// A name of this bake at level of detail `lod`, equal for equal
    /// answers (see [`crate::Request::key`]).
    pub(crate) fn key(&self, lod: u32) -> String {
        let o = &self.0.options;
        let p = &o.placement;
        let bits = |a: [f64; 3]| a.map(|x| format!("{:x}", (x + 0.0).to_bits())).join(",");
        format!(
            "bake/{:x}/{}/{}/{}/{:?}/{:?}/{:?}/{:?}/{:x}/{lod}",
            self.0.fingerprint,
            p.resolution,
            bits(p.rotation),
            bits(p.offset),
            self.texture_side(),
            self.uses_mesh_uvs(),
            o.colours,
            o.filter,
            o.spread.to_bits(),
        )
    }
}

impl PartialEq for Bake {
    fn eq(&self, other: &Bake) -> bool {
        Arc::ptr_eq(&self.0, &other.0) || self.key(0) == other.key(0)
    }
}

impl std::fmt::Debug for Bake {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bake")
            .field("triangles", &self.mesh().triangles().len())
            .field("options", &self.0.options)
            .field("texture_side", &self.texture_side())
            .finish()
    }
}

/// The texture layout `options` ask for.
fn layout(mesh: &Mesh, options: &BakeOptions, transform: &Transform) -> Result<Layout> {
    let tris = mesh.triangles();
    let valid_uvs = mesh.uvs().filter(|uv| {
        uv.iter()
            .all(|p| p.iter().all(|c| (-1e-4..=1.0 + 1e-4).contains(c)))
    });
    let own = match (options.uvs, valid_uvs) {
        (Uvs::Atlas, _) => None,
        (Uvs::Auto, uv) => uv,
        (Uvs::Mesh, Some(uv)) => Some(uv),
        (Uvs::Mesh, None) if mesh.is_cut() => {
            return Err(Error::InvalidParameter {
                name: "uvs",
                reason: "a cut mesh has no texture coordinates of its own (its caps are new): \
                         use a generated atlas"
                    .into(),
            });
        }
        (Uvs::Mesh, None) => {
            return Err(Error::InvalidParameter {
                name: "uvs",
                reason: "the mesh has no texture coordinates within [0, 1] for every vertex".into(),
            });
        }
    };
    // Surface area in voxels² of the level served.
    let area: f64 = tris
        .iter()
        .map(|t| {
            let p = t.map(|k| transform.apply(mesh.positions()[k as usize]));
            let (u, v) = (
                [0, 1, 2].map(|a| p[1][a] - p[0][a]),
                [0, 1, 2].map(|a| p[2][a] - p[0][a]),
            );
            let c = [
                u[1] * v[2] - u[2] * v[1],
                u[2] * v[0] - u[0] * v[2],
                u[0] * v[1] - u[1] * v[0],
            ];
            (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt() / 2.0
        })
        .sum();
    let side = match options.texture_size {
        Some(s) if (MIN_TEXTURE..=MAX_SLICE_SIDE).contains(&s) => s,
        Some(s) => {
            return Err(Error::InvalidRange {
                name: "texture_size",
                value: f64::from(s),
                min: f64::from(MIN_TEXTURE),
                max: f64::from(MAX_SLICE_SIDE),
            });
        }
        None => auto_side(area, own.is_some(), tris.len()),
    };
    Ok(match own {
        Some(uv) => {
            let charts: Vec<[[f32; 2]; 3]> =
                tris.iter().map(|t| t.map(|k| uv[k as usize])).collect();
            Layout::owners(&charts, side)
        }
        None => Layout::cells(tris.len(), side)?,
    })
}

/// About one texel per voxel² of surface: the generated atlas fills about
/// half its texels with charts, a mesh's own UVs are taken to fill most.
fn auto_side(area: f64, own_uvs: bool, triangles: usize) -> u32 {
    let fill = if own_uvs { 0.7 } else { 0.4 };
    let wanted = (area / fill).sqrt().ceil();
    let atlas_min = if own_uvs {
        0.0
    } else {
        f64::from(MIN_CELL) * (triangles.div_ceil(2) as f64).sqrt().ceil()
    };
    let side = wanted.max(atlas_min).max(f64::from(AUTO_MIN_TEXTURE));
    // Rounded up to a multiple of 64 (whole 4×4 blocks for compressors).
    let side = (side / 64.0).ceil() * 64.0;
    side.min(f64::from(MAX_SLICE_SIDE)) as u32
}
