//! Operational endpoints: liveness, readiness, metrics and the API document.

use super::AppState;
use crate::memory;
use crate::metrics::{BackgroundLabels, PartLabels};
use crate::registry::Status;
use axum::Json;
use axum::extract::State;
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use schemars::JsonSchema;
use serde::Serialize;

/// The OpenAPI document of this service.
pub const OPENAPI_YAML: &str = include_str!("../../../../openapi.yaml");

// openapi.yaml's `Health` schema is generated from this type.
/// Whether the server answers, and whether it is ready.
#[derive(Serialize, JsonSchema)]
pub(crate) struct Health {
    pub(crate) status: HealthStatus,
}

/// `ok` from `/healthz`; `ready` or why not from `/readyz`.
#[derive(Clone, Copy, Serialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
#[schemars(inline)]
pub(crate) enum HealthStatus {
    Ok,
    Ready,
    Loading,
    Starting,
    Overloaded,
    DefaultMissing,
}

/// `GET /healthz`: the process answers.
pub async fn healthz() -> Json<Health> {
    Json(Health {
        status: HealthStatus::Ok,
    })
}

/// `GET /readyz`: 200 once the stored textures are loaded, the bundled
/// texture (when registered) is ready and the synthesis queue has room;
/// 503 otherwise, also when the bundled texture was deleted.
pub async fn readyz(State(s): State<AppState>) -> Response {
    let default = s.registry.get(crate::DEFAULT_ID);
    let starting = default
        .as_ref()
        .is_some_and(|e| matches!(e.status(), Status::Pending));
    let (code, status) = if !s.registry.recovered() {
        // The stored textures (and the bundled one) are still loading.
        (StatusCode::SERVICE_UNAVAILABLE, HealthStatus::Loading)
    } else if s.default_texture && default.is_none() {
        // Deleted: this server no longer serves what it was started for.
        (
            StatusCode::SERVICE_UNAVAILABLE,
            HealthStatus::DefaultMissing,
        )
    } else if starting {
        (StatusCode::SERVICE_UNAVAILABLE, HealthStatus::Starting)
    } else if s.jobs.is_full() {
        (StatusCode::SERVICE_UNAVAILABLE, HealthStatus::Overloaded)
    } else {
        (StatusCode::OK, HealthStatus::Ready)
    };
    let mut res = (code, Json(Health { status })).into_response();
    if code != StatusCode::OK {
        res.headers_mut()
            .insert(header::RETRY_AFTER, header::HeaderValue::from_static("1"));
    }
    res
}

/// `GET /metrics`: Prometheus text exposition, with the memory bound
/// brought up to date.
pub async fn metrics(State(s): State<AppState>) -> Response {
    let inputs = memory::Inputs {
        cache_max_bytes: s.registry.cache().max_bytes() as u64,
        candidates_bytes: s.registry.resident_candidate_bytes(),
        precompute_bytes: s.registry.precompute_reserved().0,
        max_jobs: s.jobs.max_jobs() as u64,
        decode_bytes: s.decodes.max_bytes(),
        answer_voxels: s.max_request_voxels.min(s.max_request_work),
    };
    let (jobs, held) = s.background.census();
    for (kind, state, n) in jobs {
        s.metrics
            .background_jobs
            .get_or_create(&BackgroundLabels {
                kind: kind.name().to_string(),
                state: state.to_string(),
            })
            .set(i64::try_from(n).unwrap_or(i64::MAX));
    }
    s.metrics
        .background_bytes
        .set(i64::try_from(held).unwrap_or(i64::MAX));
    for part in memory::bound(&inputs) {
        s.metrics
            .memory_bound
            .get_or_create(&PartLabels {
                part: part.name.to_string(),
            })
            .set(i64::try_from(part.bytes).unwrap_or(i64::MAX));
    }
    (
        [(
            header::CONTENT_TYPE,
            "application/openmetrics-text; version=1.0.0; charset=utf-8",
        )],
        s.metrics.encode(),
    )
        .into_response()
}

/// `GET /openapi.yaml`.
pub async fn openapi() -> Response {
    (
        [(header::CONTENT_TYPE, "application/yaml; charset=utf-8")],
        OPENAPI_YAML,
    )
        .into_response()
}
