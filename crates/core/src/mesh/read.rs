//! Mesh files into vertices, triangles and texture coordinates. Parsers
//! see untrusted bytes: every count is checked against the limits before
//! anything is allocated for it, every accessor against the bytes it reads.

use super::MAX_TRIANGLES;
use crate::error::{Error, Result};

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
