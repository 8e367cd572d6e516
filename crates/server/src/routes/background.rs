//! The routes of background jobs ([`crate::background`]), the same for
//! exports and bakes: `GET /v1/{exports,bakes}/{id}` reports a job's
//! progress, `/file` serves its file once done (409 with `Retry-After`
//! before, 410 once cancelled), and `DELETE` cancels it and frees its file.
//! A route that starts a job answers, when the client asked for it with
//! `Prefer: respond-async` (RFC 7240), 202 with the job's status and its
//! URL in `Location`.

use super::answer::{ETag, texture};
use super::params::{NoQuery, TypedPath, TypedQuery, document_query};
use super::{AppState, IMMUTABLE};
use crate::background::{Job, JobStatus, Kind, Phase};
use crate::error::ApiError;
use axum::Json;
use axum::body::{Body, Bytes};
use axum::extract::State;
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;

/// Whether the client asked for an asynchronous answer.
pub(super) fn respond_async(headers: &HeaderMap) -> bool {
    headers
        .get_all("prefer")
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|p| p.trim().eq_ignore_ascii_case("respond-async"))
}

/// A job's file: its bytes, type, name and validator.
pub(super) fn file_response(job: &Job, bytes: Bytes, tag: &ETag) -> Response {
    let mut res = Response::new(Body::from(bytes));
    let h = res.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static(job.spec.media_type),
    );
    if let Ok(v) =
        HeaderValue::from_str(&format!("attachment; filename=\"{}\"", job.spec.file_name))
    {
        h.insert(header::CONTENT_DISPOSITION, v);
    }
    tag.stamp(res, IMMUTABLE)
}

/// 202 with the job's status, and where to follow it.
pub(super) fn accepted(job: &Job) -> Response {
    let status = job.status();
    let mut res = (StatusCode::ACCEPTED, Json(&status)).into_response();
    if let Ok(v) = HeaderValue::from_str(&status.url) {
        res.headers_mut().insert(header::LOCATION, v);
    }
    res
}

/// What a route that started (or joined) `job` answers: 202 when the
/// client prefers it and the job is not done, else the file once it is
/// (waiting for it).
pub(super) async fn answer_job(
    s: &AppState,
    job: &Job,
    headers: &HeaderMap,
) -> Result<Response, ApiError> {
    if respond_async(headers) && !job.phase().finished() {
        return Ok(accepted(job));
    }
    let phase = job.finished().await;
    let (entry, _) = texture(s, &job.spec.texture).await?;
    let tag = ETag::new(&entry, &job.spec.etag_key);
    finished_file(job, phase, &tag)
}

/// The file of a finished job, or why there is none.
fn finished_file(job: &Job, phase: Phase, tag: &ETag) -> Result<Response, ApiError> {
    let (kind, id) = (job.spec.kind, &job.spec.id);
    match phase {
        Phase::Done(bytes) => Ok(file_response(job, bytes, tag)),
        Phase::Failed(e) => Err(e),
        Phase::Cancelled => Err(ApiError::new(
            StatusCode::GONE,
            "cancelled",
            format!(
                "{} `{id}` was cancelled and its file dropped; ask for it again",
                kind.name()
            ),
        )),
        Phase::Queued | Phase::Running => Err(ApiError::new(
            StatusCode::CONFLICT,
            match kind {
                Kind::Export => "export_running",
                Kind::Bake => "bake_running",
            },
            format!(
                "{} `{id}` is {:.0} % done; its status is at /v1/{}/{id}",
                kind.name(),
                100.0 * job.status().progress,
                kind.collection()
            ),
        )
        .retry_after(1)),
    }
}

fn unknown(kind: Kind, id: &str) -> ApiError {
    ApiError::new(
        StatusCode::NOT_FOUND,
        match kind {
            Kind::Export => "unknown_export",
            Kind::Bake => "unknown_bake",
        },
        format!(
            "no {} `{id}` (finished ones are kept a while; ask for it again)",
            kind.name()
        ),
    )
}

fn status(s: &AppState, kind: Kind, id: &str) -> Result<Json<JobStatus>, ApiError> {
    let job = s
        .background
        .get(kind, id)
        .ok_or_else(|| unknown(kind, id))?;
    Ok(Json(job.status()))
}

async fn file(
    s: &AppState,
    kind: Kind,
    id: &str,
    headers: &HeaderMap,
) -> Result<Response, ApiError> {
    let job = s
        .background
        .get(kind, id)
        .ok_or_else(|| unknown(kind, id))?;
    let (entry, _) = texture(s, &job.spec.texture).await?;
    let tag = ETag::new(&entry, &job.spec.etag_key);
    if tag.matches(headers) && matches!(job.phase(), Phase::Done(_)) {
        return Ok(tag.not_modified(IMMUTABLE));
    }
    finished_file(&job, job.phase(), &tag)
}

fn cancel(s: &AppState, kind: Kind, id: &str) -> Result<Json<JobStatus>, ApiError> {
    let job = s
        .background
        .cancel(kind, id)
        .ok_or_else(|| unknown(kind, id))?;
    Ok(Json(job.status()))
}

/// The path of an export: `/v1/exports/{eid}`.
#[derive(Deserialize, Default)]
pub(super) struct ExportPath {
    eid: String,
}

document_query!(ExportPath {
    eid: "The export's id (from `Location`).",
});

/// The path of a bake: `/v1/bakes/{bid}`.
#[derive(Deserialize, Default)]
pub(super) struct BakePath {
    bid: String,
}

document_query!(BakePath {
    bid: "The bake's id (from `Location`).",
});

/// `GET /v1/exports/{eid}`
pub(super) async fn export_status(
    State(s): State<AppState>,
    TypedPath(ExportPath { eid }): TypedPath<ExportPath>,
    TypedQuery(NoQuery {}): TypedQuery<NoQuery>,
) -> Result<Json<JobStatus>, ApiError> {
    status(&s, Kind::Export, &eid)
}

/// `GET /v1/exports/{eid}/file`
pub(super) async fn export_file(
    State(s): State<AppState>,
    TypedPath(ExportPath { eid }): TypedPath<ExportPath>,
    TypedQuery(NoQuery {}): TypedQuery<NoQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    file(&s, Kind::Export, &eid, &headers).await
}

/// `DELETE /v1/exports/{eid}`
pub(super) async fn export_cancel(
    State(s): State<AppState>,
    TypedPath(ExportPath { eid }): TypedPath<ExportPath>,
    TypedQuery(NoQuery {}): TypedQuery<NoQuery>,
) -> Result<Json<JobStatus>, ApiError> {
    cancel(&s, Kind::Export, &eid)
}

/// `GET /v1/bakes/{bid}`
pub(super) async fn bake_status(
    State(s): State<AppState>,
    TypedPath(BakePath { bid }): TypedPath<BakePath>,
    TypedQuery(NoQuery {}): TypedQuery<NoQuery>,
) -> Result<Json<JobStatus>, ApiError> {
    status(&s, Kind::Bake, &bid)
}

/// `GET /v1/bakes/{bid}/file`
pub(super) async fn bake_file(
    State(s): State<AppState>,
    TypedPath(BakePath { bid }): TypedPath<BakePath>,
    TypedQuery(NoQuery {}): TypedQuery<NoQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    file(&s, Kind::Bake, &bid, &headers).await
}

/// `DELETE /v1/bakes/{bid}`
pub(super) async fn bake_cancel(
    State(s): State<AppState>,
    TypedPath(BakePath { bid }): TypedPath<BakePath>,
    TypedQuery(NoQuery {}): TypedQuery<NoQuery>,
) -> Result<Json<JobStatus>, ApiError> {
    cancel(&s, Kind::Bake, &bid)
}
