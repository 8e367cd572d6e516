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
use super::params::{Int, TypedQuery, Vec3};
use super::voxels::Lod;
use crate::background::{BakeDetail, Detail, Kind, Progress, Spec};
use crate::error::ApiError;
use crate::registry::Entry;
use axum::body::Bytes;
use axum::extract::{Path, State};
use axum::http::HeaderMap;
use axum::response::Response;
use serde::Deserialize;
use sha2::{Digest, Sha256};
use solidtex_core::mesh::{
    Bake, BakeOptions, Colours, MAX_RESOLUTION, Mesh, MeshFormat, Plane, Uvs,
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
    format: Option<String>,
    lod: Lod,
    /// Planes `nx,ny,nz,d` separated by `;`, in the mesh's coordinates.
    cut: Option<String>,
    /// A number; its range is checked with the rest of the bake.
    spread: Option<String>,
}

/// A bake as the query asks for it, the mesh not yet read.
struct Asked {
    format: Option<MeshFormat>,
    options: BakeOptions,
    planes: Option<Vec<Plane>>,
    lod: u32,
}

impl Asked {
    fn new(q: &BakeQuery) -> Result<Asked, ApiError> {
        let format = q.format.as_deref().map(MeshFormat::from_name).transpose()?;
        let mut options = BakeOptions::new(q.resolution.get_u32());
        options.placement.rotation = q.rotation.map_or([0.0; 3], |v| v.0);
        options.placement.offset = q.offset.map_or([0.0; 3], |v| v.0);
        options.texture_size = q.texture_size.map(Int::get_u32);
        (options.uvs, options.colours, options.filter) = (q.uvs, q.colours, q.filter);
        if let Some(v) = &q.spread {
            options.spread =
                v.trim()
                    .parse()
                    .map_err(|_| solidtex_core::Error::InvalidParameter {
                        name: "spread",
                        reason: format!("`{v}` is not a number"),
                    })?;
        }
        let planes = q.cut.as_deref().map(Plane::parse_list).transpose()?;
        Ok(Asked {
            format,
            options,
            planes: planes.filter(|p| !p.is_empty()),
            lod: q.lod.get_u32(),
        })
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
    Path(id): Path<String>,
    TypedQuery(q): TypedQuery<BakeQuery>,
    headers: HeaderMap,
    body: Bytes,
) -> Result<Response, ApiError> {
    let t = texture(&s, &id).await?;
    let asked = Asked::new(&q)?;
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
