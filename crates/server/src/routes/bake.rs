//! `POST /v1/textures/{id}/bake`: a mesh (OBJ or GLB, the request body)
//! textured from the solid, answered as a glTF binary. The mesh is read
//! and laid out off the async threads; the bake then goes through
//! [`answer`] like any voxel request (cut by the `cut` planes first,
//! when given), under the budget of an export
//! (`--max-export-work`), and stops when the client hangs up.

use super::AppState;
use super::answer::{Encoding, answer, texture};
use super::params::{Int, TypedQuery, Vec3};
use super::voxels::Lod;
use crate::error::ApiError;
use axum::body::Bytes;
use axum::extract::{Path, State};
use axum::http::HeaderMap;
use axum::response::Response;
use serde::Deserialize;
use solidtex_core::mesh::{
    Bake, BakeOptions, Colours, MAX_RESOLUTION, Mesh, MeshFormat, Plane, Uvs,
};
use solidtex_core::{Filter, MAX_SLICE_SIDE, Request};
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

/// `POST /v1/textures/{id}/bake`
pub(super) async fn bake(
    State(s): State<AppState>,
    Path(id): Path<String>,
    TypedQuery(q): TypedQuery<BakeQuery>,
    headers: HeaderMap,
    body: Bytes,
) -> Result<Response, ApiError> {
    let t = texture(&s, &id).await?;
    let format = q.format.as_deref().map(MeshFormat::from_name).transpose()?;
    let mut options = BakeOptions::new(q.resolution.get_u32());
    options.placement.rotation = q.rotation.map_or([0.0; 3], |v| v.0);
    options.placement.offset = q.offset.map_or([0.0; 3], |v| v.0);
    options.texture_size = q.texture_size.map(Int::get_u32);
    (options.uvs, options.colours, options.filter) = (q.uvs, q.colours, q.filter);
    if let Some(v) = &q.spread {
        options.spread = v
            .trim()
            .parse()
            .map_err(|_| solidtex_core::Error::InvalidParameter {
                name: "spread",
                reason: format!("`{v}` is not a number"),
            })?;
    }
    let planes = q.cut.as_deref().map(Plane::parse_list).transpose()?;
    let bake = tokio::task::spawn_blocking(move || -> Result<Bake, ApiError> {
        let mut mesh = Mesh::parse(&body, format)?;
        if let Some(planes) = planes.filter(|p| !p.is_empty()) {
            mesh = mesh.cut(&planes)?;
        }
        Ok(Bake::new(Arc::new(mesh), options)?)
    })
    .await
    .map_err(|e| ApiError::internal(format!("reading the mesh failed: {e}")))??;
    let request = Request::bake(bake)?;
    answer(&s, t, request, q.lod.get_u32(), Encoding::Glb, &headers).await
}
