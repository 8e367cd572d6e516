//! The baked mesh as a glTF 2.0 binary: positions in the mesh's own units,
//! smooth normals, and either texture coordinates with a PNG base-colour
//! texture or linear vertex colours. The material is rough and
//! non-metallic, so viewers show the colours under their own light.

use super::Bake;
use crate::error::{Error, Result};
use serde_json::{Value, json};

const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;
const LINEAR: u32 = 9729;
const CLAMP_TO_EDGE: u32 = 33071;

/// Vertices, indices and the texture of the output, before packing.
struct Parts {
    positions: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
    /// Texture coordinates or linear colours, per vertex.
    third: Third,
    /// One mesh and node per piece of a cut (one for an uncut mesh).
    pieces: Vec<PieceOut>,
    png: Option<Vec<u8>>,
}

/// A piece's vertices (a range of the parts'), its triangles (indices
/// into that range) and where its node moves it.
struct PieceOut {
    vertices: std::ops::Range<usize>,
    indices: Vec<u32>,
    translation: [f32; 3],
}

enum Third {
    Uvs(Vec<[f32; 2]>),
    Colours(Vec<[f32; 3]>),
}

pub(super) fn write(bake: &Bake, rgb: &[u8]) -> Result<Vec<u8>> {
    let parts = parts(bake, rgb)?;
    Ok(pack(&parts))
}

/// The whole mesh as one piece on shared vertices.
fn whole(bake: &Bake) -> Vec<PieceOut> {
    let mesh = bake.mesh();
    vec![PieceOut {
        vertices: 0..mesh.positions().len(),
        indices: mesh.triangles().iter().flatten().copied().collect(),
        translation: [0.0; 3],
    }]
}

fn parts(bake: &Bake, rgb: &[u8]) -> Result<Parts> {
    let mesh = bake.mesh();
    let normals = mesh.vertex_normals();
    let tris = mesh.triangles();
    let Some(side) = bake.texture_side() else {
        let colours = rgb
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]].map(srgb_to_linear))
            .collect();
        return Ok(Parts {
            positions: mesh.positions().to_vec(),
            normals,
            third: Third::Colours(colours),
            pieces: whole(bake),
            png: None,
        });
    };
    let png = crate::png::encode(side, side, rgb)
        .map_err(|e| Error::Io(std::io::Error::other(format!("PNG encoding: {e}"))))?;
    if bake.uses_mesh_uvs() {
        return Ok(Parts {
            positions: mesh.positions().to_vec(),
            normals,
            third: Third::Uvs(mesh.uvs().unwrap_or_default().to_vec()),
            pieces: whole(bake),
            png: Some(png),
        });
    }
    // The generated atlas: three vertices of its own per triangle, so a
    // cap's corners take its flat normal beside the surface's smooth one.
    let s = side as f32;
    let mut positions = Vec::with_capacity(tris.len() * 3);
    let mut normal_out = Vec::with_capacity(tris.len() * 3);
    let mut uvs = Vec::with_capacity(tris.len() * 3);
    for (i, t) in tris.iter().enumerate() {
        let chart = bake.chart(i);
        let flat = mesh.is_cap(i).then(|| mesh.face_normal(i));
        for (corner, &k) in t.iter().enumerate() {
            positions.push(mesh.positions()[k as usize]);
            normal_out.push(flat.unwrap_or(normals[k as usize]));
            uvs.push(chart[corner].map(|c| c / s));
        }
    }
    let shift = bake.options().spread * longest_side(mesh.positions());
    let pieces = mesh
        .pieces()
        .iter()
        .map(|p| PieceOut {
            vertices: p.triangles.start * 3..p.triangles.end * 3,
            indices: (0..(p.triangles.len() * 3) as u32).collect(),
            translation: p.away.map(|c| c * shift),
        })
        .collect();
    Ok(Parts {
        positions,
        normals: normal_out,
        third: Third::Uvs(uvs),
        pieces,
        png: Some(png),
    })
}

/// The longest side of the points' bounding box.
fn longest_side(points: &[[f32; 3]]) -> f32 {
    (0..3)
        .map(|a| {
            let lo = points.iter().map(|p| p[a]).fold(f32::MAX, f32::min);
            let hi = points.iter().map(|p| p[a]).fold(f32::MIN, f32::max);
            hi - lo
        })
        .fold(0.0, f32::max)
}

/// sRGB-encoded 8-bit to linear, as glTF's `COLOR_0` is.
fn srgb_to_linear(c: u8) -> f32 {
    let c = f32::from(c) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// The binary chunk being assembled, and the views and accessors into it.
#[derive(Default)]
struct Packer {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Packer {
    /// Appends `bytes` as a buffer view (4-byte aligned); its index.
    fn view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let mut v = json!({"buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len()});
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        self.bin.extend_from_slice(bytes);
        self.views.push(v);
        self.views.len() - 1
    }

    /// Appends float vectors as a view and an accessor; the accessor's index.
    fn floats<const N: usize>(&mut self, data: &[[f32; N]], bounds: bool) -> usize {
        let bytes: Vec<u8> = data
            .iter()
            .flatten()
            .flat_map(|c| c.to_le_bytes())
            .collect();
        let view = self.view(&bytes, Some(ARRAY_BUFFER));
        let kind = ["SCALAR", "VEC2", "VEC3", "VEC4"][N - 1];
        let mut a =
            json!({"bufferView": view, "componentType": FLOAT, "count": data.len(), "type": kind});
        if bounds {
            let (mut lo, mut hi) = ([f32::MAX; N], [f32::MIN; N]);
            for v in data {
                for i in 0..N {
                    lo[i] = lo[i].min(v[i]);
                    hi[i] = hi[i].max(v[i]);
                }
            }
            a["min"] = json!(lo.to_vec());
            a["max"] = json!(hi.to_vec());
        }
        self.accessors.push(a);
        self.accessors.len() - 1
    }

    fn indices(&mut self, data: &[u32]) -> usize {
        let bytes: Vec<u8> = data.iter().flat_map(|c| c.to_le_bytes()).collect();
        let view = self.view(&bytes, Some(ELEMENT_ARRAY_BUFFER));
        self.accessors.push(json!({
            "bufferView": view, "componentType": UNSIGNED_INT,
            "count": data.len(), "type": "SCALAR"
        }));
        self.accessors.len() - 1
    }
}

fn pack(parts: &Parts) -> Vec<u8> {
    let mut p = Packer::default();
    let mut meshes = Vec::with_capacity(parts.pieces.len());
    let mut nodes = Vec::with_capacity(parts.pieces.len());
    for (i, piece) in parts.pieces.iter().enumerate() {
        let r = piece.vertices.clone();
        let position = p.floats(&parts.positions[r.clone()], true);
        let normal = p.floats(&parts.normals[r.clone()], false);
        let mut attributes = json!({"POSITION": position, "NORMAL": normal});
        match &parts.third {
            Third::Uvs(uv) => attributes["TEXCOORD_0"] = json!(p.floats(&uv[r], false)),
            Third::Colours(c) => attributes["COLOR_0"] = json!(p.floats(&c[r], false)),
        }
        let indices = p.indices(&piece.indices);
        meshes.push(json!({
            "primitives": [{"attributes": attributes, "indices": indices, "material": 0}]
        }));
        let mut node = json!({"mesh": i});
        if parts.pieces.len() > 1 {
            node["name"] = json!(format!("piece {i}"));
        }
        if piece.translation != [0.0; 3] {
            node["translation"] = json!(piece.translation.to_vec());
        }
        nodes.push(node);
    }
    let mut pbr = json!({"metallicFactor": 0.0, "roughnessFactor": 1.0});
    let mut doc = json!({
        "asset": {"version": "2.0", "generator": "solidtex"},
        "scene": 0,
        "scenes": [{"nodes": (0..nodes.len()).collect::<Vec<_>>()}],
        "nodes": nodes,
        "meshes": meshes,
    });
    if let Some(png) = &parts.png {
        let view = p.view(png, None);
        pbr["baseColorTexture"] = json!({"index": 0});
        doc["textures"] = json!([{"sampler": 0, "source": 0}]);
        // No mipmaps: a coarser mip level would average texels of
        // neighbouring charts of the generated atlas together.
        doc["samplers"] = json!([{
            "magFilter": LINEAR, "minFilter": LINEAR,
            "wrapS": CLAMP_TO_EDGE, "wrapT": CLAMP_TO_EDGE
        }]);
        doc["images"] = json!([{"bufferView": view, "mimeType": "image/png"}]);
    }
    doc["materials"] = json!([{"pbrMetallicRoughness": pbr, "doubleSided": true}]);
    while !p.bin.len().is_multiple_of(4) {
        p.bin.push(0);
    }
    doc["bufferViews"] = json!(p.views);
    doc["accessors"] = json!(p.accessors);
    doc["buffers"] = json!([{"byteLength": p.bin.len()}]);
    let mut text = serde_json::to_vec(&doc).unwrap_or_default();
    while !text.len().is_multiple_of(4) {
        text.push(b' ');
    }
    let total = 12 + 8 + text.len() + 8 + p.bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(text.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&text);
    out.extend_from_slice(&(p.bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&p.bin);
    out
}
