//! `POST /v1/textures/{id}/bake`: a mesh (OBJ, PLY or GLB, the request
//! body) textured from the solid, answered as a glTF binary. The mesh is
//! read and laid out off the async threads; the bake then goes through
//! [`answer`] like any voxel request (cut by the `cut` planes first,
//! when given), under the budget of an export
//! (`--max-export-work`), and stops when the client hangs up.
//!
//! With `Prefer: respond-async` it runs instead as a background job
//! ([`crate::background`], beside the exports): 202 at once with the
//! job's status and `Location: /v1/bakes/{bid}`, where its progress is
//! (texels baked, voxels synthesized against the prediction); the file is
//! at `/v1/bakes/{bid}/file` once done, the same bytes and ETag as the
//! synchronous answer. The job's id is derived from the texture, the
//! body's bytes and the parsed query, so the same bake asked again joins
//! the one running without reading the mesh again.

use super::AppState;
use super::answer::{Encoding, admit, answer, texture};
use super::background::{answer_job, respond_async};
use super::params::{
    Int, QueryValue, TextureId, TexturePath, TypedPath, TypedQuery, ValueSchema, Vec3,
    document_query, named_value,
};
use super::voxels::Lod;
use crate::background::{BakeDetail, Detail, Kind, Progress, Spec};
use crate::error::ApiError;
use crate::registry::Entry;
use axum::body::Bytes;
use axum::extract::State;
use axum::http::HeaderMap;
use axum::response::Response;
use serde::Deserialize;
use sha2::{Digest, Sha256};
use solidtex_core::mesh::{
    Bake, BakeOptions, Colours, MAX_RESOLUTION, MAX_SPREAD, Mesh, MeshFormat, Plane, Uvs,
};
use solidtex_core::{Filter, MAX_SLICE_SIDE, Request, RequestKind, Texture};
use std::sync::Arc;

/// Voxels spanned by the mesh's longest side, 256 unless given.
type Resolution = Int<1, { MAX_RESOLUTION as i64 }, 256>;
/// Side of the baked texture.
type TextureSize = Int<16, { MAX_SLICE_SIDE as i64 }>;

/// How the mesh is placed and baked.
#[derive(Debug, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub(super) struct BakeQuery {
    resolution: Resolution,
    rotation: Option<Vec3>,
    offset: Option<Vec3>,
    texture_size: Option<TextureSize>,
    uvs: Uvs,
    colours: Colours,
    filter: Filter,
    format: Option<FormatName>,
    lod: Lod,
    cut: Option<Cut>,
    spread: Spread,
}

document_query!(BakeQuery {
    resolution: "Voxels of `lod` spanned by the longest side of the mesh's bounding box.",
    rotation: "Degrees about x, then y, then z, around the bounding box's centre (default \
               `0,0,0`).",
    offset: "Where the bounding box's lowest corner lies, `x,y,z` in voxels of `lod` (default \
             `0,0,0`).",
    texture_size: "Side of the baked texture; about one texel per voxel of surface (256 to 4096) \
                   when omitted.",
    uvs: "Whose texture coordinates the texture follows: the mesh's own (`mesh`; `auto` when \
          every vertex has one within [0, 1]) or a generated atlas of one chart per triangle \
          with a gutter around each (`atlas`).",
    colours: "`texture`: a base-colour texture; `vertex`: one colour per vertex (`COLOR_0`, \
              linear) and no texture.",
    filter: "How a surface point reads the solid: the nearest voxel, or a trilinear blend of \
             the eight around it.",
    format: "The mesh's format, when its first bytes should not decide (any case; `gltf` reads \
             as `glb`).",
    lod: super::voxels::LOD,
    cut: "Planes that cut the mesh into pieces before baking, each `nx,ny,nz,d` (the points p \
          with n·p = d, in the mesh file's own coordinates), several separated by `;` for a \
          fracture (at most 8). Each piece, one side of every plane, is closed by caps textured \
          from the inside of the solid, and is a node and mesh of its own in the answer. \
          Refused (400 `invalid_parameter`): a plane that is not four finite numbers, a zero \
          normal, a plane that misses the mesh, more than 8 planes, and `colours=vertex` or \
          `uvs=mesh` with a cut (the caps need a generated atlas).",
    spread: "How far the pieces of a cut are pulled apart in the answer, each away from the \
             planes, as a share of the mesh's longest side (the texture is baked where they \
             were).",
});

named_value!(Uvs, Colours);

/// A mesh format by its name: `obj`, `glb` (or `gltf`), `ply`, any case.
#[derive(Clone, Copy, Debug)]
struct FormatName(MeshFormat);

impl<'de> Deserialize<'de> for FormatName {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let name = String::deserialize(d)?;
        MeshFormat::from_name(&name)
            .map(FormatName)
            .map_err(|e| serde::de::Error::custom(reason(e)))
    }
}

impl QueryValue for FormatName {
    fn schema() -> ValueSchema {
        ValueSchema::Choice(&["obj", "glb", "ply"])
    }

    fn written(&self) -> Option<String> {
        Some(
            match self.0 {
                MeshFormat::Obj => "obj",
                MeshFormat::Glb => "glb",
                MeshFormat::Ply => "ply",
            }
            .into(),
        )
    }
}

/// The cutting planes, written `nx,ny,nz,d;…` (see [`Plane::parse_list`]).
#[derive(Clone, Debug)]
struct Cut(Vec<Plane>);

/// Longest `cut` accepted: eight planes of four long numbers fit.
const MAX_CUT_TEXT: u32 = 1024;

impl<'de> Deserialize<'de> for Cut {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        if text.len() > MAX_CUT_TEXT as usize {
            return Err(serde::de::Error::custom(format_args!(
                "{} bytes (at most {MAX_CUT_TEXT})",
                text.len()
            )));
        }
        Plane::parse_list(&text)
            .map(Cut)
            .map_err(|e| serde::de::Error::custom(reason(e)))
    }
}

impl QueryValue for Cut {
    fn schema() -> ValueSchema {
        ValueSchema::Text {
            max_len: Some(MAX_CUT_TEXT),
            pattern: None,
            example: None,
        }
    }

    fn written(&self) -> Option<String> {
        None
    }
}

/// A number; its range (0 to [`MAX_SPREAD`]) is checked with the rest of
/// the bake, as `out_of_range`.
#[derive(Clone, Copy, Debug, Default)]
struct Spread(f32);

impl<'de> Deserialize<'de> for Spread {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        text.trim()
            .parse()
            .map(Spread)
            .map_err(|_| serde::de::Error::custom(format_args!("`{text}` is not a number")))
    }
}

impl QueryValue for Spread {
    fn schema() -> ValueSchema {
        ValueSchema::Number {
            min: 0.0,
            max: f64::from(MAX_SPREAD),
        }
    }

    fn written(&self) -> Option<String> {
        Some(self.0.to_string())
    }
}

/// What a core error says about a parameter, without its name (the
/// query's error names it).
fn reason(e: solidtex_core::Error) -> String {
    match e {
        solidtex_core::Error::InvalidParameter { reason, .. } => reason,
        other => other.to_string(),
    }
}

/// A bake as the query asks for it, the mesh not yet read.
struct Asked {
    format: Option<MeshFormat>,
    options: BakeOptions,
    planes: Option<Vec<Plane>>,
    lod: u32,
}

impl Asked {
    fn new(q: &BakeQuery) -> Asked {
        let mut options = BakeOptions::new(q.resolution.get_u32());
        options.placement.rotation = q.rotation.map_or([0.0; 3], |v| v.0);
        options.placement.offset = q.offset.map_or([0.0; 3], |v| v.0);
        options.texture_size = q.texture_size.map(Int::get_u32);
        (options.uvs, options.colours, options.filter) = (q.uvs, q.colours, q.filter);
        options.spread = q.spread.0;
        Asked {
            format: q.format.map(|f| f.0),
            options,
            planes: q.cut.clone().map(|c| c.0).filter(|p| !p.is_empty()),
            lod: q.lod.get_u32(),
        }
    }

    /// The bake of the mesh `body`: read, cut and laid out.
    fn request(self, body: &[u8]) -> Result<Request, ApiError> {
        let mut mesh = Mesh::parse(body, self.format)?;
        if let Some(planes) = &self.planes {
            mesh = mesh.cut(planes)?;
        }
        Ok(Request::bake(Bake::new(Arc::new(mesh), self.options)?)?)
    }

    /// What the bake's job id is made from besides the texture: the
    /// body's hash and everything parsed from the query.
    fn key(&self, body: &[u8]) -> String {
        let body = crate::spec::hex(&Sha256::digest(body));
        format!(
            "bake/{body}/{:?}/{:?}/{:?}/{}/{}",
            self.format,
            self.options,
            self.planes,
            self.lod,
            env!("CARGO_PKG_VERSION"),
        )
    }
}

/// `POST /v1/textures/{id}/bake`
pub(super) async fn bake(
    State(s): State<AppState>,
    TypedPath(TexturePath { id: TextureId(id) }): TypedPath<TexturePath>,
    TypedQuery(q): TypedQuery<BakeQuery>,
    headers: HeaderMap,
    body: Bytes,
) -> Result<Response, ApiError> {
    let t = texture(&s, &id).await?;
    let asked = Asked::new(&q);
    if respond_async(&headers) {
        return bake_async(&s, t, asked, body, &headers).await;
    }
    let lod = asked.lod;
    let request = tokio::task::spawn_blocking(move || asked.request(&body))
        .await
        .map_err(|e| ApiError::internal(format!("reading the mesh failed: {e}")))??;
    answer(&s, t, request, lod, Encoding::Glb, &headers).await
}

/// The bake as a background job: joined when the same one is held, else
/// read, checked against the budgets and started.
async fn bake_async(
    s: &AppState,
    (entry, tex): (Arc<Entry>, Texture),
    asked: Asked,
    body: Bytes,
    headers: &HeaderMap,
) -> Result<Response, ApiError> {
    let id = Kind::Bake.job_id(&entry.content_hash, &asked.key(&body));
    if let Some(job) = s.background.joinable(Kind::Bake, &id) {
        return answer_job(s, &job, headers).await;
    }
    let lod = asked.lod;
    let (state, checked) = (s.clone(), tex.clone());
    let (request, predicted) = tokio::task::spawn_blocking(move || {
        let request = asked.request(&body)?;
        let predicted = admit(&state, &checked, &request, lod)?;
        Ok::<_, ApiError>((request, predicted))
    })
    .await
    .map_err(|e| ApiError::internal(format!("reading the mesh failed: {e}")))??;
    let RequestKind::Bake(bake) = request.kind() else {
        return Err(ApiError::internal("a bake request is not a bake"));
    };
    let bake = bake.clone();
    let detail = Detail::Bake(BakeDetail {
        triangles: bake.mesh().triangles().len() as u64,
        resolution: bake.options().placement.resolution,
        texture_size: bake.texture_side(),
        lod,
    });
    let spec = Spec {
        file_name: format!("{}-{}.glb", entry.id, &id[..8]),
        id,
        kind: Kind::Bake,
        texture: entry.id.clone(),
        media_type: "model/gltf-binary",
        etag_key: request.key(lod),
        unit: match bake.options().colours {
            Colours::Texture => "texels",
            Colours::Vertex => "vertices",
        },
        total: bake.items() as u64,
        predicted,
        detail,
    };
    let work = move |p: &Progress| -> Result<Bytes, ApiError> {
        p.set_stage("planning");
        p.set_predicted(tex.predict(&request, lod)?);
        p.set_stage("synthesis");
        let (rgb, _) = tex.render_progress(&request, lod, &|done, _| p.set_done(done))?;
        p.set_stage("writing");
        Ok(Bytes::from(bake.glb(&rgb)?))
    };
    let job = s.background.start(spec, Box::new(work))?;
    answer_job(s, &job, headers).await
}

#[cfg(test)]
mod tests {
    use super::super::params::from_pairs;
    use super::*;

    fn parse(q: &str) -> Result<BakeQuery, ApiError> {
        from_pairs(form_urlencoded::parse(q.as_bytes()))
    }

    #[test]
    fn format_cut_and_spread_read_as_their_values() {
        let q = parse("format=GLTF&cut=0,0,1,0;1,0,0,0.5&spread=0.25").unwrap();
        assert!(matches!(q.format, Some(FormatName(MeshFormat::Glb))));
        assert_eq!(q.cut.map(|c| c.0.len()), Some(2));
        assert_eq!(q.spread.0, 0.25);
        let q = parse("").unwrap();
        assert!(q.format.is_none() && q.cut.is_none() && q.spread.0 == 0.0);
        // Eight planes padded to exactly the limit read; one byte more does not.
        let planes = |len: usize| {
            let mut text = ["0,0,1,0"; 8].join(";");
            let pad = len - text.len();
            text.insert_str(7, &format!(".{}", "0".repeat(pad - 1)));
            assert_eq!(text.len(), len);
            text
        };
        let at = parse(&format!("cut={}", planes(MAX_CUT_TEXT as usize))).unwrap();
        assert_eq!(at.cut.map(|c| c.0.len()), Some(8));
        let past = format!("cut={}", planes(MAX_CUT_TEXT as usize + 1));
        let long = format!("cut={}", "0,0,1,0;".repeat(130));
        for (query, message) in [
            (
                "format=stl",
                "parameter `format`: unknown mesh format `stl` (expected obj, glb or ply)",
            ),
            (
                "cut=0,0,1",
                "parameter `cut`: `0,0,1` is not four numbers nx,ny,nz,d",
            ),
            ("spread=x", "parameter `spread`: `x` is not a number"),
            (&long, "parameter `cut`: 1040 bytes (at most 1024)"),
            (&past, "parameter `cut`: 1025 bytes (at most 1024)"),
        ] {
            let e = parse(query).unwrap_err();
            assert_eq!((e.code, e.message.as_str()), ("invalid_parameter", message));
        }
    }
}
