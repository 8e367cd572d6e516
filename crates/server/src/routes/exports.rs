//! Exports over HTTP: the same files as `solidtex export` (see
//! [`solidtex_core::export`]).
//!
//! `GET /v1/textures/{id}/export` makes the file, or joins the same export
//! already being made, and answers it when done. With `Prefer:
//! respond-async` (RFC 7240) it answers at once 202 with the export's
//! status and its URL in `Location`; `GET /v1/exports/{eid}` then reports
//! progress, and `/v1/exports/{eid}/file` serves the file once it is done.
//! `GET /v1/textures/{id}/export.json` describes an export (the sidecar
//! JSON) without making it.
//!
//! Every export is checked before any work: the box against the server's
//! `--max-export-voxels` (400 `too_large`), the predicted synthesis against
//! `--max-export-work` (400 `over_budget`), and the parameters (400).

use super::answer::{ETag, texture};
use super::params::{Int, NoQuery, TypedPath, TypedQuery};
use super::voxels::{Coord, Lod};
use super::{AppState, IMMUTABLE};
use crate::error::ApiError;
use crate::exports::{ExportJob, Phase, export_key};
use axum::Json;
use axum::body::{Body, Bytes};
use axum::extract::{Path, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use serde_json::Value;
use solidtex_core::export::{Export, Format, MAX_EXPORT_VOXELS, Mips};
use solidtex_core::{Region, Texture};

/// A side of an export's box, 64 unless given (the voxel budget binds
/// before the largest).
type ExportSide = Int<1, { MAX_EXPORT_VOXELS as i64 }, 64>;

/// The export a query names: `format` (required), the box (`box=period`,
/// or `x`, `y`, `z`, `w`, `h`, `d`), `lod`, and for KTX2 `mips` and
/// `colour`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ExportQuery {
    format: Option<String>,
    #[serde(rename = "box")]
    whole: Option<String>,
    x: Option<Coord>,
    y: Option<Coord>,
    z: Option<Coord>,
    w: Option<ExportSide>,
    h: Option<ExportSide>,
    d: Option<ExportSide>,
    #[serde(default)]
    lod: Lod,
    mips: Option<String>,
    colour: Option<String>,
}

/// The export `q` names, checked against the texture, the limits and the
/// budgets. Returns it with the predicted synthesis (an upper bound,
/// voxels).
fn parse_export(s: &AppState, q: &ExportQuery, tex: &Texture) -> Result<(Export, u64), ApiError> {
    let format: Format = q
        .format
        .as_deref()
        .ok_or_else(|| ApiError::invalid_parameter("format", "required: ktx2, atlas, nrrd or raw"))?
        .parse()
        .map_err(|e: solidtex_core::Error| ApiError::invalid_parameter("format", e))?;
    let lod = q.lod.get_u32();
    let corner = [
        ("x", q.x.is_some()),
        ("y", q.y.is_some()),
        ("z", q.z.is_some()),
        ("w", q.w.is_some()),
        ("h", q.h.is_some()),
        ("d", q.d.is_some()),
    ]
    .into_iter()
    .find_map(|(k, given)| given.then_some(k));
    let region = match q.whole.as_deref() {
        Some("period") => {
            if let Some(k) = corner {
                return Err(ApiError::invalid_parameter(
                    k,
                    "give either `box=period` or the box's x, y, z, w, h, d",
                ));
            }
            Export::one_period(tex, lod)?
        }
        Some(other) => {
            return Err(ApiError::invalid_parameter(
                "box",
                format_args!("`{other}` is not `period` (give x, y, z, w, h, d for a box)"),
            ));
        }
        None if corner.is_none() && tex.params().period.is_some() => Export::one_period(tex, lod)?,
        None => Region {
            origin: [q.x, q.y, q.z].map(|c| c.unwrap_or_default().get()),
            size: [q.w, q.h, q.d].map(|c| c.unwrap_or_default().get_u32()),
        },
    };
    let mips = match q.mips.as_deref() {
        None => Mips::default(),
        Some(m) => m
            .parse()
            .map_err(|e: solidtex_core::Error| ApiError::invalid_parameter("mips", e))?,
    };
    let srgb = match q.colour.as_deref() {
        None | Some("srgb") => true,
        Some("linear") => false,
        Some(other) => {
            return Err(ApiError::invalid_parameter(
                "colour",
                format_args!("`{other}` is not srgb or linear"),
            ));
        }
    };
    if format != Format::Ktx2 && (q.mips.is_some() || q.colour.is_some()) {
        return Err(ApiError::invalid_parameter(
            if q.mips.is_some() { "mips" } else { "colour" },
            format_args!("applies to ktx2 exports only, not {format}"),
        ));
    }
    let export = Export {
        mips,
        srgb,
        ..Export::new(format, region, lod)
    };
    export.check(tex)?;
    let voxels = export.region.voxel_count().unwrap_or(u64::MAX);
    let budget = s.max_export_voxels.min(MAX_EXPORT_VOXELS);
    if voxels > budget {
        let [w, h, d] = export.region.size;
        return Err(ApiError::too_large(format!(
            "an export of {w}x{h}x{d} = {voxels} voxels; this server's budget per export is \
             {budget} voxels (--max-export-voxels)"
        )));
    }
    let e = export.estimate(tex, s.max_export_work)?;
    if !e.complete || e.total > s.max_export_work {
        s.metrics.over_budget("predicted");
        let more = if e.complete { "" } else { "more than " };
        return Err(ApiError::new(
            StatusCode::BAD_REQUEST,
            "over_budget",
            format!(
                "this export is predicted to synthesize up to {more}{} voxels from a cold \
                 cache, over the server's budget of {} voxels per export (--max-export-work); \
                 export a smaller box or a coarser lod",
                e.total, s.max_export_work
            ),
        ));
    }
    Ok((export, e.total))
}

/// Whether the client asked for an asynchronous answer.
fn respond_async(headers: &HeaderMap) -> bool {
    headers
        .get_all("prefer")
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|p| p.trim().eq_ignore_ascii_case("respond-async"))
}

/// The file's response: its bytes, type, name and validator.
fn file_response(job: &ExportJob, bytes: Bytes, tag: &ETag) -> Response {
    let mut res = Response::new(Body::from(bytes));
    let h = res.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static(job.export.format.media_type()),
    );
    if let Ok(v) = HeaderValue::from_str(&format!("attachment; filename=\"{}\"", job.file_name)) {
        h.insert(header::CONTENT_DISPOSITION, v);
    }
    tag.stamp(res, IMMUTABLE)
}

/// 202 with the export's status, and where to follow it.
fn accepted(job: &ExportJob) -> Response {
    let mut res = (StatusCode::ACCEPTED, Json(job.status())).into_response();
    if let Ok(v) = HeaderValue::from_str(&format!("/v1/exports/{}", job.id)) {
        res.headers_mut().insert(header::LOCATION, v);
    }
    res
}

/// `GET /v1/textures/{id}/export`
pub(super) async fn export(
    State(s): State<AppState>,
    Path(id): Path<String>,
    TypedQuery(q): TypedQuery<ExportQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let (entry, tex) = texture(&s, &id).await?;
    let (export, _) = parse_export(&s, &q, &tex)?;
    let tag = ETag::new(&entry, &export_key(&export));
    if tag.matches(&headers) {
        return Ok(tag.not_modified(IMMUTABLE));
    }
    let job = s.exports.start(&entry, tex, export)?;
    if respond_async(&headers) && matches!(job.phase(), Phase::Running) {
        return Ok(accepted(&job));
    }
    match job.finished().await {
        Phase::Done(bytes) => Ok(file_response(&job, bytes, &tag)),
        Phase::Failed(e) => Err(e),
        Phase::Running => Err(ApiError::internal("the export stopped unfinished")),
    }
}

/// `GET /v1/textures/{id}/export.json`: the sidecar JSON `solidtex
/// export` writes (the same bytes), and the predicted synthesis in
/// `X-Solidtex-Predicted-Voxels`.
pub(super) async fn describe(
    State(s): State<AppState>,
    Path(id): Path<String>,
    TypedQuery(q): TypedQuery<ExportQuery>,
) -> Result<Response, ApiError> {
    let (_, tex) = texture(&s, &id).await?;
    let (export, predicted) = parse_export(&s, &q, &tex)?;
    let body = serde_json::to_vec_pretty(&export.describe(&tex))
        .map_err(|e| ApiError::internal(e.to_string()))?;
    let mut res = Response::new(Body::from(body));
    let h = res.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/json"),
    );
    h.insert("x-solidtex-predicted-voxels", HeaderValue::from(predicted));
    Ok(res)
}

/// The path of an export: `/v1/exports/{eid}`.
#[derive(Deserialize)]
pub(super) struct ExportPath {
    eid: String,
}

fn unknown_export(id: &str) -> ApiError {
    ApiError::new(
        StatusCode::NOT_FOUND,
        "unknown_export",
        format!("no export `{id}` (finished exports are kept a while; ask for it again)"),
    )
}

/// `GET /v1/exports/{eid}`
pub(super) async fn status(
    State(s): State<AppState>,
    TypedPath(ExportPath { eid }): TypedPath<ExportPath>,
    TypedQuery(NoQuery {}): TypedQuery<NoQuery>,
) -> Result<Json<Value>, ApiError> {
    let job = s.exports.get(&eid).ok_or_else(|| unknown_export(&eid))?;
    Ok(Json(job.status()))
}

/// `GET /v1/exports/{eid}/file`
pub(super) async fn file(
    State(s): State<AppState>,
    TypedPath(ExportPath { eid }): TypedPath<ExportPath>,
    TypedQuery(NoQuery {}): TypedQuery<NoQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let job = s.exports.get(&eid).ok_or_else(|| unknown_export(&eid))?;
    let (entry, _) = texture(&s, &job.texture).await?;
    let tag = ETag::new(&entry, &export_key(&job.export));
    if tag.matches(&headers) {
        return Ok(tag.not_modified(IMMUTABLE));
    }
    match job.phase() {
        Phase::Done(bytes) => Ok(file_response(&job, bytes, &tag)),
        Phase::Failed(e) => Err(e),
        Phase::Running => Err(ApiError::new(
            StatusCode::CONFLICT,
            "export_running",
            format!(
                "export `{eid}` is {:.0} % done; its status is at /v1/exports/{eid}",
                100.0 * job.done_voxels() as f64 / job.total.max(1) as f64
            ),
        )
        .retry_after(1)),
    }
}
