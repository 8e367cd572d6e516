//! Mesh files into vertices, triangles and texture coordinates. Parsers
//! see untrusted bytes: every count is checked against the limits before
//! anything is allocated for it, every accessor against the bytes it reads.

use super::MAX_TRIANGLES;
use crate::error::{Error, Result};
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{
    ElementDef, Encoding, Property, PropertyAccess, PropertyAccessResult, PropertyType, ScalarType,
};

type Parts = (Vec<[f32; 3]>, Vec<[u32; 3]>, Option<Vec<[f32; 2]>>);

fn malformed(what: &str, e: impl std::fmt::Display) -> Error {
    Error::InvalidRequest(format!("malformed {what}: {e}"))
}

fn too_many(n: usize) -> Error {
    Error::TooLarge(format!("{n} triangles (limit {MAX_TRIANGLES})"))
}

/// A Wavefront OBJ: every object, polygons fanned into triangles, one
/// vertex per distinct (position, texture coordinate) pair. OBJ's v grows
/// upwards; it is flipped to glTF's.
pub(super) fn obj(bytes: &[u8]) -> Result<Parts> {
    let options = tobj::LoadOptions {
        single_index: true,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
    };
    let mut reader = std::io::BufReader::new(bytes);
    let (models, _materials) = tobj::load_obj_buf(&mut reader, &options, |_| {
        Err(tobj::LoadError::OpenFileFailed)
    })
    .map_err(|e| malformed("OBJ", e))?;
    let triangles: usize = models.iter().map(|m| m.mesh.indices.len() / 3).sum();
    if triangles > MAX_TRIANGLES {
        return Err(too_many(triangles));
    }
    let with_uvs = models
        .iter()
        .all(|m| m.mesh.texcoords.len() / 2 == m.mesh.positions.len() / 3);
    let (mut positions, mut tris, mut uvs) = (Vec::new(), Vec::new(), Vec::new());
    for m in &models {
        let base = u32::try_from(positions.len()).map_err(|_| too_many(triangles))?;
        positions.extend(m.mesh.positions.chunks_exact(3).map(|p| [p[0], p[1], p[2]]));
        if with_uvs {
            uvs.extend(m.mesh.texcoords.chunks_exact(2).map(|t| [t[0], 1.0 - t[1]]));
        }
        tris.extend(
            m.mesh
                .indices
                .chunks_exact(3)
                .map(|t| [t[0] + base, t[1] + base, t[2] + base]),
        );
    }
    Ok((positions, tris, with_uvs.then_some(uvs)))
}

/// A vertex of a PLY file: its position and, when given, its texture
/// coordinates (`s`/`t`, `u`/`v` or `texture_u`/`texture_v`).
#[derive(Default)]
struct PlyVertex {
    p: [Option<f32>; 3],
    uv: [Option<f32>; 2],
}

/// A face of a PLY file: its polygon's vertex indices (negative ones
/// become an index past every vertex, refused as such).
#[derive(Default)]
struct PlyFace(Vec<u32>);

/// An element of a PLY file that is read past (edges, materials, ...).
struct PlySkip;

fn ply_scalar(p: &Property) -> Option<f32> {
    Some(match *p {
        Property::Char(v) => f32::from(v),
        Property::UChar(v) => f32::from(v),
        Property::Short(v) => f32::from(v),
        Property::UShort(v) => f32::from(v),
        Property::Int(v) => v as f32,
        Property::UInt(v) => v as f32,
        Property::Float(v) => v,
        Property::Double(v) => v as f32,
        _ => return None,
    })
}

impl PropertyAccess for PlyVertex {
    fn new() -> Self {
        PlyVertex::default()
    }
    fn set_property(&mut self, name: &str, p: Property) -> PropertyAccessResult {
        let slot = match name {
            "x" => &mut self.p[0],
            "y" => &mut self.p[1],
            "z" => &mut self.p[2],
            "s" | "u" | "texture_u" | "texture_s" => &mut self.uv[0],
            "t" | "v" | "texture_v" | "texture_t" => &mut self.uv[1],
            _ => return PropertyAccessResult::Ignored,
        };
        match ply_scalar(&p) {
            Some(v) => {
                *slot = Some(v);
                PropertyAccessResult::Set
            }
            None => PropertyAccessResult::UnsupportedType,
        }
    }
}

impl PropertyAccess for PlyFace {
    fn new() -> Self {
        PlyFace::default()
    }
    fn set_property(&mut self, name: &str, p: Property) -> PropertyAccessResult {
        if name != "vertex_indices" && name != "vertex_index" {
            return PropertyAccessResult::Ignored;
        }
        let neg = |v: i64| u32::try_from(v).unwrap_or(u32::MAX);
        self.0 = match p {
            Property::ListChar(v) => v.into_iter().map(|i| neg(i.into())).collect(),
            Property::ListUChar(v) => v.into_iter().map(u32::from).collect(),
            Property::ListShort(v) => v.into_iter().map(|i| neg(i.into())).collect(),
            Property::ListUShort(v) => v.into_iter().map(u32::from).collect(),
            Property::ListInt(v) => v.into_iter().map(|i| neg(i.into())).collect(),
            Property::ListUInt(v) => v,
            _ => return PropertyAccessResult::UnsupportedType,
        };
        PropertyAccessResult::Set
    }
}

impl PropertyAccess for PlySkip {
    fn new() -> Self {
        PlySkip
    }
}

/// The fewest bytes one element of `e` takes in `encoding`: a count
/// claiming more elements than the file could hold is refused before
/// anything is allocated for them.
fn ply_min_bytes(e: &ElementDef, encoding: Encoding) -> usize {
    let scalar = |t: &ScalarType| match t {
        ScalarType::Char | ScalarType::UChar => 1,
        ScalarType::Short | ScalarType::UShort => 2,
        ScalarType::Int | ScalarType::UInt | ScalarType::Float => 4,
        ScalarType::Double => 8,
    };
    e.properties
        .values()
        .map(|p| match (&p.data_type, encoding) {
            // A number and its separator.
            (_, Encoding::Ascii) => 2,
            (PropertyType::Scalar(t), _) => scalar(t),
            (PropertyType::List(count, _), _) => scalar(count),
        })
        .sum::<usize>()
        .max(1)
}

/// A Stanford PLY, ASCII or binary: the `vertex` element's x, y, z (and
/// texture coordinates when every vertex has them), the `face` element's
/// polygons fanned into triangles; other elements are read past. PLY's v
/// grows upwards; it is flipped to glTF's.
pub(super) fn ply(bytes: &[u8]) -> Result<Parts> {
    let bad = |e: &dyn std::fmt::Display| malformed("PLY", e);
    let mut reader = Reader::new(std::io::BufReader::new(bytes));
    let header = Parser::<PlySkip>::new()
        .read_header(&mut reader)
        .map_err(|e| bad(&e))?;
    // The count first: a file claiming too many is refused as such.
    if let Some(faces) = header
        .elements
        .get("face")
        .filter(|f| f.count > MAX_TRIANGLES)
    {
        return Err(too_many(faces.count));
    }
    for e in header.elements.values() {
        let least = e.count.checked_mul(ply_min_bytes(e, header.encoding));
        if least.is_none_or(|n| n > bytes.len()) {
            return Err(bad(&format!(
                "the header claims {} {} elements, more than the file holds (truncated?)",
                e.count, e.name
            )));
        }
    }
    let (mut vertices, mut faces) = (Vec::new(), Vec::new());
    for e in header.elements.values() {
        match e.name.as_str() {
            "vertex" => {
                vertices = Parser::<PlyVertex>::new()
                    .read_payload_for_element(&mut reader, e, &header)
                    .map_err(|e| bad(&e))?;
            }
            "face" => {
                faces = Parser::<PlyFace>::new()
                    .read_payload_for_element(&mut reader, e, &header)
                    .map_err(|e| bad(&e))?;
            }
            _ => {
                Parser::<PlySkip>::new()
                    .read_payload_for_element(&mut reader, e, &header)
                    .map_err(|e| bad(&e))?;
            }
        }
    }
    let mut positions = Vec::with_capacity(vertices.len());
    for (i, v) in vertices.iter().enumerate() {
        match v.p {
            [Some(x), Some(y), Some(z)] => positions.push([x, y, z]),
            _ => return Err(bad(&format!("vertex {i} lacks one of x, y and z"))),
        }
    }
    let with_uvs =
        !vertices.is_empty() && vertices.iter().all(|v| v.uv.iter().all(Option::is_some));
    let uvs = with_uvs.then(|| {
        vertices
            .iter()
            .map(|v| [v.uv[0].unwrap_or(0.0), 1.0 - v.uv[1].unwrap_or(0.0)])
            .collect()
    });
    let mut tris = Vec::new();
    for f in &faces {
        for k in 1..f.0.len().saturating_sub(1) {
            tris.push([f.0[0], f.0[k], f.0[k + 1]]);
            if tris.len() > MAX_TRIANGLES {
                return Err(too_many(tris.len()));
            }
        }
    }
    Ok((positions, tris, uvs))
}

/// Deepest node hierarchy followed (a cycle is refused by validation; a
/// deep chain is refused here rather than recursed into).
const MAX_NODE_DEPTH: usize = 64;

/// A glTF binary: the triangle primitives of the default scene's nodes
/// (of every mesh, untransformed, when the file has no scene), each under
/// its node's world transform. Other primitive modes are skipped.
pub(super) fn glb(bytes: &[u8]) -> Result<Parts> {
    let gltf = gltf::Gltf::from_slice(bytes).map_err(|e| malformed("glTF", e))?;
    let blob = gltf.blob.as_deref().unwrap_or(&[]);
    let doc = &gltf.document;
    let mut placed = Vec::new();
    match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(scene) => {
            let mut stack: Vec<_> = scene.nodes().map(|n| (n, IDENTITY, 0)).collect();
            while let Some((node, parent, depth)) = stack.pop() {
                if depth > MAX_NODE_DEPTH {
                    return Err(malformed("glTF", "node hierarchy too deep"));
                }
                let m = mul(parent, node.transform().matrix());
                if let Some(mesh) = node.mesh() {
                    placed.push((mesh, m));
                }
                stack.extend(node.children().map(|c| (c, m, depth + 1)));
            }
        }
        None => placed.extend(doc.meshes().map(|m| (m, IDENTITY))),
    }
    let mut prims = Vec::new();
    let mut triangles = 0usize;
    for (mesh, m) in &placed {
        for p in mesh.primitives() {
            if p.mode() != gltf::mesh::Mode::Triangles {
                continue;
            }
            let pos = p
                .get(&gltf::Semantic::Positions)
                .ok_or_else(|| malformed("glTF", "a primitive has no POSITION"))?;
            // The count first: a file claiming too many is refused as such.
            let n = p.indices().map_or(pos.count(), |ix| ix.count());
            triangles = triangles.saturating_add(n / 3);
            if triangles > MAX_TRIANGLES {
                return Err(too_many(triangles));
            }
            check_accessor(&pos, blob)?;
            if let Some(ix) = p.indices() {
                check_accessor(&ix, blob)?;
            }
            if let Some(uv) = p.get(&gltf::Semantic::TexCoords(0)) {
                check_accessor(&uv, blob)?;
            }
            prims.push((p, *m));
        }
    }
    let (mut positions, mut tris, mut uvs) = (Vec::new(), Vec::new(), Vec::new());
    let mut with_uvs = true;
    for (p, m) in &prims {
        let r = p.reader(|b| match b.source() {
            gltf::buffer::Source::Bin => Some(blob),
            gltf::buffer::Source::Uri(_) => None,
        });
        let base = positions.len();
        let read = r
            .read_positions()
            .ok_or_else(|| malformed("glTF", "positions outside the GLB's binary chunk"))?;
        positions.extend(read.map(|v| transform_point(m, v)));
        let n = positions.len() - base;
        let at = |i: u32| -> Result<u32> {
            if (i as usize) < n {
                Ok((base + i as usize) as u32)
            } else {
                Err(malformed("glTF", format!("index {i} past {n} vertices")))
            }
        };
        match r.read_indices() {
            Some(ix) => {
                let ix: Vec<u32> = ix.into_u32().collect();
                for t in ix.chunks_exact(3) {
                    tris.push([at(t[0])?, at(t[1])?, at(t[2])?]);
                }
            }
            None => {
                for i in (0..n as u32 / 3 * 3).step_by(3) {
                    tris.push([at(i)?, at(i + 1)?, at(i + 2)?]);
                }
            }
        }
        match r.read_tex_coords(0) {
            Some(t) if with_uvs => uvs.extend(t.into_f32()),
            _ => with_uvs = false,
        }
    }
    if positions.len() > u32::MAX as usize {
        return Err(too_many(triangles));
    }
    Ok((
        positions,
        tris,
        (with_uvs && !uvs.is_empty()).then_some(uvs),
    ))
}

/// Refuses an accessor that reads outside its buffer view, a view outside
/// its buffer, a buffer outside the binary chunk, or a sparse accessor.
fn check_accessor(a: &gltf::Accessor, blob: &[u8]) -> Result<()> {
    let bad = |what: &str| Err(malformed("glTF", format!("accessor {}: {what}", a.index())));
    if a.sparse().is_some() {
        return bad("sparse accessors are not supported");
    }
    let Some(view) = a.view() else {
        return bad("no buffer view");
    };
    let buffer = view.buffer();
    if !matches!(buffer.source(), gltf::buffer::Source::Bin) {
        return bad("external buffers are not supported: send a GLB with its data inside");
    }
    if buffer.length() > blob.len() {
        return bad("its buffer is longer than the binary chunk (truncated file?)");
    }
    let view_end = view.offset().checked_add(view.length());
    if view_end.is_none_or(|end| end > buffer.length()) {
        return bad("its buffer view lies outside the buffer");
    }
    let size = a.size();
    let stride = view.stride().unwrap_or(size).max(size);
    let needed = a
        .count()
        .checked_sub(1)
        .and_then(|last| last.checked_mul(stride))
        .and_then(|n| n.checked_add(size))
        .and_then(|n| n.checked_add(a.offset()))
        .unwrap_or(0);
    if needed > view.length() {
        return bad("it reads past the end of its buffer view");
    }
    Ok(())
}

const IDENTITY: [[f32; 4]; 4] = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
];

/// `a · b` of column-major 4×4 matrices.
fn mul(a: [[f32; 4]; 4], b: [[f32; 4]; 4]) -> [[f32; 4]; 4] {
    let mut out = [[0f32; 4]; 4];
    for (c, col) in out.iter_mut().enumerate() {
        for (r, v) in col.iter_mut().enumerate() {
            *v = (0..4).map(|k| a[k][r] * b[c][k]).sum();
        }
    }
    out
}

/// The point `v` under the column-major affine matrix `m`.
fn transform_point(m: &[[f32; 4]; 4], v: [f32; 3]) -> [f32; 3] {
    [0, 1, 2].map(|r| m[0][r] * v[0] + m[1][r] * v[1] + m[2][r] * v[2] + m[3][r])
}
