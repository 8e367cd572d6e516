//! Objects, not only blocks (Dong et al. 2008, §6 "surfaces and cuts"): a
//! triangle mesh placed in texture space is textured by synthesizing only
//! the voxels its surface samples, the thin shell around it, never the
//! volume it encloses.
//!
//! [`Mesh`] reads OBJ, PLY and glTF binary (GLB) from bytes and checks it, and
//! [`Mesh::cut`] splits it by planes into closed pieces;
//! [`Placement`] puts it in texture space; [`Bake`] lays out the texels of
//! its base-colour texture (the mesh's own UVs or a generated atlas) and is
//! answered as a [`crate::Request`] like any other; [`Bake::glb`] writes
//! the textured mesh.

mod atlas;
mod bake;
mod cut;
mod glb;
mod place;
mod read;
mod surface;

pub use bake::{Bake, BakeOptions, Colours, MAX_SPREAD, Uvs};
pub use cut::{MAX_CUTS, Plane};
pub use place::{MAX_RESOLUTION, Placement};
pub(crate) use surface::Surface;

use crate::error::{Error, Result};

/// Largest mesh file accepted, in bytes.
pub const MAX_MESH_BYTES: usize = 128 << 20;
/// Most triangles a mesh may have (after triangulating its polygons).
pub const MAX_TRIANGLES: usize = 4 << 20;

/// The file formats [`Mesh::parse`] reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshFormat {
    /// Wavefront OBJ (polygons are triangulated; materials are ignored).
    Obj,
    /// glTF 2.0 binary: every triangle primitive of the default scene
    /// (or of every mesh when there is no scene), with node transforms.
    Glb,
    /// Stanford PLY, ASCII or binary (polygons are triangulated).
    Ply,
}

impl MeshFormat {
    /// The format of a file by its first bytes: GLB starts with `glTF`,
    /// PLY with `ply` and a line end, anything else is read as OBJ text.
    pub fn sniff(bytes: &[u8]) -> MeshFormat {
        if bytes.starts_with(b"glTF") {
            MeshFormat::Glb
        } else if bytes.starts_with(b"ply\n") || bytes.starts_with(b"ply\r\n") {
            MeshFormat::Ply
        } else {
            MeshFormat::Obj
        }
    }

    /// The format by name (`obj`, `glb`, `ply`), in either case.
    pub fn from_name(name: &str) -> Result<MeshFormat> {
        match name.to_ascii_lowercase().as_str() {
            "obj" => Ok(MeshFormat::Obj),
            "glb" | "gltf" => Ok(MeshFormat::Glb),
            "ply" => Ok(MeshFormat::Ply),
            _ => Err(Error::InvalidParameter {
                name: "format",
                reason: format!("unknown mesh format `{name}` (expected obj, glb or ply)"),
            }),
        }
    }
}

/// A triangle mesh that passed every check: finite vertices, indices in
/// range, at least one triangle of non-zero area, within the limits.
/// Degenerate triangles (zero area, repeated vertex) are dropped; meshes
/// need not be closed or manifold.
#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    positions: Vec<[f32; 3]>,
    triangles: Vec<[u32; 3]>,
    uvs: Option<Vec<[f32; 2]>>,
    dropped: usize,
    /// Per triangle, whether it closes a cut (empty for an uncut mesh).
    caps: Vec<bool>,
    pieces: Vec<Piece>,
}

/// A piece of a cut mesh: one side of every plane.
#[derive(Clone, Debug, PartialEq)]
pub struct Piece {
    /// Its triangles, a range of [`Mesh::triangles`].
    pub triangles: std::ops::Range<usize>,
    /// The unit direction away from the planes (the sum of their normals,
    /// each turned to the piece's side), for pulling pieces apart;
    /// zero for an uncut mesh.
    pub away: [f32; 3],
}

impl Mesh {
    /// Reads a mesh file of `format` (sniffed from the bytes when `None`).
    pub fn parse(bytes: &[u8], format: Option<MeshFormat>) -> Result<Mesh> {
        if bytes.len() > MAX_MESH_BYTES {
            return Err(Error::TooLarge(format!(
                "mesh of {} bytes (limit {MAX_MESH_BYTES})",
                bytes.len()
            )));
        }
        if bytes.is_empty() {
            return Err(Error::InvalidRequest("the mesh file is empty".into()));
        }
        let (positions, triangles, uvs) = match format.unwrap_or(MeshFormat::sniff(bytes)) {
            MeshFormat::Obj => read::obj(bytes)?,
            MeshFormat::Glb => read::glb(bytes)?,
            MeshFormat::Ply => read::ply(bytes)?,
        };
        Mesh::new(positions, triangles, uvs)
    }

    /// A mesh from its parts; `uvs`, when given, has one entry per vertex
    /// (glTF's convention: v grows downwards in the image).
    pub fn new(
        positions: Vec<[f32; 3]>,
        triangles: Vec<[u32; 3]>,
        uvs: Option<Vec<[f32; 2]>>,
    ) -> Result<Mesh> {
        if triangles.len() > MAX_TRIANGLES {
            return Err(Error::TooLarge(format!(
                "{} triangles (limit {MAX_TRIANGLES})",
                triangles.len()
            )));
        }
        if let Some(i) = positions
            .iter()
            .position(|p| !p.iter().all(|c| c.is_finite()))
        {
            return Err(Error::InvalidRequest(format!(
                "vertex {i} has a coordinate that is not a finite number"
            )));
        }
        let n = positions.len();
        if let Some(t) = triangles
            .iter()
            .find(|t| t.iter().any(|&i| i as usize >= n))
        {
            return Err(Error::InvalidRequest(format!(
                "a triangle names vertex {} of {n}",
                t.iter().max().copied().unwrap_or(0)
            )));
        }
        let total = triangles.len();
        let kept: Vec<[u32; 3]> = triangles
            .into_iter()
            .filter(|t| !degenerate(t.map(|i| positions[i as usize])))
            .collect();
        if kept.is_empty() {
            return Err(Error::InvalidRequest(if total == 0 {
                "the mesh has no triangles".into()
            } else {
                format!("all {total} triangles of the mesh have zero area")
            }));
        }
        let uvs = uvs.filter(|u| u.len() == n);
        Ok(Mesh {
            dropped: total - kept.len(),
            pieces: vec![Piece {
                triangles: 0..kept.len(),
                away: [0.0; 3],
            }],
            caps: Vec::new(),
            positions,
            triangles: kept,
            uvs,
        })
    }

    /// The mesh cut by `planes` (in its own coordinates) into pieces, one
    /// per side of every plane that holds any of it, each closed by caps
    /// where a plane crossed it (see [`Plane`]). Texture coordinates are
    /// dropped: the caps have none. A plane that misses the mesh, more than
    /// [`MAX_CUTS`] planes or a degenerate plane are refused.
    pub fn cut(&self, planes: &[Plane]) -> Result<Mesh> {
        cut::cut(self, planes)
    }

    /// The pieces of a cut, or the whole mesh as one piece.
    pub fn pieces(&self) -> &[Piece] {
        &self.pieces
    }

    /// Whether triangle `t` is part of a cut's cap.
    pub fn is_cap(&self, t: usize) -> bool {
        self.caps.get(t).copied().unwrap_or(false)
    }

    /// Whether the mesh was cut.
    pub fn is_cut(&self) -> bool {
        !self.caps.is_empty()
    }

    /// Vertex positions, in the file's own units.
    pub fn positions(&self) -> &[[f32; 3]] {
        &self.positions
    }

    /// The triangles kept, as vertex indices.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// Texture coordinates per vertex, when the file had them for all.
    pub fn uvs(&self) -> Option<&[[f32; 2]]> {
        self.uvs.as_deref()
    }

    /// Degenerate triangles dropped while reading.
    pub fn dropped(&self) -> usize {
        self.dropped
    }

    /// A 64-bit fingerprint of the mesh, for request keys.
    pub(crate) fn fingerprint(&self) -> u64 {
        let mut bytes = Vec::with_capacity(self.positions.len() * 20 + self.triangles.len() * 12);
        for p in &self.positions {
            bytes.extend(p.iter().flat_map(|c| c.to_le_bytes()));
        }
        for t in &self.triangles {
            bytes.extend(t.iter().flat_map(|i| i.to_le_bytes()));
        }
        for uv in self.uvs.iter().flatten() {
            bytes.extend(uv.iter().flat_map(|c| c.to_le_bytes()));
        }
        bytes.extend(self.caps.iter().map(|&c| u8::from(c)));
        for p in &self.pieces {
            bytes.extend((p.triangles.end as u64).to_le_bytes());
            bytes.extend(p.away.iter().flat_map(|c| c.to_le_bytes()));
        }
        crate::hash::fingerprint(&bytes)
    }

    /// Unit normal per vertex: the area-weighted mean of the normals of
    /// the triangles around it (the first such triangle's where they cancel).
    /// Caps are left out, so the surface stays smooth up to a cut's edge
    /// (a cap's corners take its own flat normal, [`Mesh::face_normal`]).
    pub(crate) fn vertex_normals(&self) -> Vec<[f32; 3]> {
        let mut sum = vec![[0f64; 3]; self.positions.len()];
        let mut first = vec![None; self.positions.len()];
        for (i, t) in self.triangles.iter().enumerate() {
            if self.is_cap(i) {
                continue;
            }
            let n = cross_of(t.map(|i| self.positions[i as usize]));
            for &i in t {
                let s = &mut sum[i as usize];
                for a in 0..3 {
                    s[a] += n[a];
                }
                first[i as usize].get_or_insert(n);
            }
        }
        sum.iter()
            .zip(&first)
            .map(|(s, f)| {
                unit(*s)
                    .or_else(|| f.and_then(unit))
                    .unwrap_or([0.0, 0.0, 1.0])
            })
            .collect()
    }
}

impl Mesh {
    /// Triangle `t`'s unit normal, by its winding.
    pub(crate) fn face_normal(&self, t: usize) -> [f32; 3] {
        unit(cross_of(
            self.triangles[t].map(|i| self.positions[i as usize]),
        ))
        .unwrap_or([0.0, 0.0, 1.0])
    }
}

/// Twice the triangle's area vector (f64, so thin triangles keep a normal).
fn cross_of(p: [[f32; 3]; 3]) -> [f64; 3] {
    let d = |a: [f32; 3], b: [f32; 3]| [0, 1, 2].map(|i| f64::from(b[i]) - f64::from(a[i]));
    let (u, v) = (d(p[0], p[1]), d(p[0], p[2]));
    [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ]
}

fn unit(v: [f64; 3]) -> Option<[f32; 3]> {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    (n > 0.0 && n.is_finite()).then(|| v.map(|c| (c / n) as f32))
}

/// Zero area relative to the triangle's size: a repeated vertex, or sides
/// so nearly parallel that no normal can be trusted.
fn degenerate(p: [[f32; 3]; 3]) -> bool {
    let c = cross_of(p);
    let area2 = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
    let len2 = |a: [f32; 3], b: [f32; 3]| {
        (0..3)
            .map(|i| (f64::from(b[i]) - f64::from(a[i])).powi(2))
            .sum::<f64>()
    };
    let longest = len2(p[0], p[1]).max(len2(p[1], p[2])).max(len2(p[2], p[0]));
    // |u × v|² against the longest side⁴: sin² of the smallest angle,
    // roughly. NaN (no area to speak of) counts as degenerate.
    area2.partial_cmp(&(1e-14 * longest * longest)) != Some(std::cmp::Ordering::Greater)
}

#[cfg(test)]
impl Mesh {
    /// The unit cube, two outward-wound triangles per face (for tests).
    pub(crate) fn unit_cube() -> Mesh {
        let p = (0..8)
            .map(|k| [0, 1, 2].map(|a| ((k >> a) & 1) as f32))
            .collect();
        let quads: [[u32; 4]; 6] = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        let t = quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect();
        Mesh::new(p, t, None).unwrap()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        let p = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        (p, vec![[0, 1, 2], [0, 2, 3]])
    }

    #[test]
    fn degenerate_triangles_are_dropped_and_an_empty_mesh_refused() {
        let (p, mut t) = square();
        t.push([0, 0, 1]);
        t.push([0, 1, 1]);
        let m = Mesh::new(p.clone(), t, None).unwrap();
        assert_eq!((m.triangles().len(), m.dropped()), (2, 2));
        let line = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]];
        assert!(matches!(
            Mesh::new(line, vec![[0, 1, 2]], None),
            Err(Error::InvalidRequest(_))
        ));
        assert!(Mesh::new(p, vec![], None).is_err());
    }

    #[test]
    fn bad_vertices_and_indices_are_refused() {
        let (mut p, t) = square();
        assert!(Mesh::new(p.clone(), vec![[0, 1, 9]], None).is_err());
        p[2][1] = f32::NAN;
        assert!(matches!(
            Mesh::new(p, t, None),
            Err(Error::InvalidRequest(_))
        ));
    }

    #[test]
    fn normals_are_unit_and_face_the_winding() {
        let (p, t) = square();
        let m = Mesh::new(p, t, None).unwrap();
        for n in m.vertex_normals() {
            assert_eq!(n, [0.0, 0.0, 1.0]);
        }
    }
}
