//! The HTTP surface: the route table, the shared state handlers see, and
//! the middleware stack every request passes through.
//!
//! Outermost first: CORS → tracing span → metrics → head size limits →
//! Host allow-list → bearer token → panic catcher → request body deadline
//! → JSON error shape → handler. Handlers only parse, call the registry or the job
//! queue, and shape responses; no synthesis logic lives here.

mod answer;
mod background;
mod bake;
mod exports;
mod frames;
mod ops;
mod params;
mod textures;
mod viewer;
mod volumes;
mod voxels;

pub use params::{QueryParam, ValueSchema};
pub use volumes::{WINDOW_LOG2, window};

use super::decodes::Decodes;
use super::error::{ApiError, echo, json_errors, panic_response};
use super::host::AllowedHosts;
use super::jobs::Jobs;
use super::metrics::Metrics;
use super::registry::Registry;
use axum::Router;
use axum::extract::{DefaultBodyLimit, MatchedPath, Request, State};
use axum::http::{HeaderName, Method, StatusCode};
use axum::middleware::{self, Next};
use axum::response::Response;
use axum::routing::{get, post};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::cors::{AllowOrigin, Any, CorsLayer};
use tower_http::timeout::{DeadlineBody, TimeoutError};
use tower_http::trace::TraceLayer;

/// Every route as (method, path in OpenAPI notation). The router below
/// serves exactly these; a test checks them against `openapi.yaml`.
pub const ROUTES: &[(&str, &str)] = &[
    ("GET", "/healthz"),
    ("GET", "/readyz"),
    ("GET", "/metrics"),
    ("GET", "/openapi.yaml"),
    ("GET", "/v1/textures"),
    ("POST", "/v1/textures"),
    ("GET", "/v1/textures/{id}"),
    ("DELETE", "/v1/textures/{id}"),
    ("GET", "/v1/textures/{id}/exemplar.png"),
    ("POST", "/v1/textures/{id}/variants"),
    ("GET", "/v1/textures/{id}/frames/{axis}/{at}.json"),
    ("GET", "/v1/textures/{id}/slices/{axis}/{at}.png"),
    ("GET", "/v1/textures/{id}/cut.png"),
    ("GET", "/v1/textures/{id}/region.raw"),
    ("GET", "/v1/textures/{id}/bricks/{lod}/{bx}_{by}_{bz}.raw"),
    ("GET", "/v1/textures/{id}/precomputed/info"),
    ("GET", "/v1/textures/{id}/precomputed/{scale}/{chunk}"),
    ("GET", "/v1/textures/{id}/zarr/zarr.json"),
    ("GET", "/v1/textures/{id}/zarr/{lod}/zarr.json"),
    ("GET", "/v1/textures/{id}/zarr/{lod}/c/{cc}/{cz}/{cy}/{cx}"),
    ("POST", "/v1/textures/{id}/bake"),
    ("GET", "/v1/textures/{id}/export"),
    ("GET", "/v1/textures/{id}/export.json"),
    ("GET", "/v1/exports/{eid}"),
    ("DELETE", "/v1/exports/{eid}"),
    ("GET", "/v1/exports/{eid}/file"),
    ("GET", "/v1/bakes/{bid}"),
    ("DELETE", "/v1/bakes/{bid}"),
    ("GET", "/v1/bakes/{bid}/file"),
    ("GET", "/"),
    ("GET", "/viewer.js"),
];

/// The query parameters of the operations whose query struct declares
/// them, by operationId; openapi.yaml's sections `query OPERATION` are
/// generated from these ([`crate::openapi`]).
pub fn documented_queries() -> Vec<(&'static str, Vec<QueryParam>)> {
    use params::DocumentedQuery;
    vec![
        ("getFrames", frames::FramesQuery::params()),
        ("getSlice", voxels::SliceQuery::params()),
        ("getCut", voxels::CutQuery::params()),
        ("getRegion", voxels::RegionQuery::params()),
        ("getExport", exports::ExportQuery::params()),
        ("describeExport", exports::ExportQuery::params()),
        ("bakeMesh", bake::BakeQuery::params()),
    ]
}

/// The path parameters declared once as components, by component name;
/// openapi.yaml's section `path-parameters` is generated from the routes'
/// path structs ([`crate::openapi`]).
pub fn documented_paths() -> Vec<(&'static str, Vec<QueryParam>)> {
    use params::DocumentedQuery;
    vec![
        ("TextureId", params::TexturePath::params()),
        ("ExportId", background::ExportPath::params()),
        ("BakeId", background::BakePath::params()),
    ]
}

/// The JSON bodies the routes answer with, registered in `generator`;
/// openapi.yaml's section `response-schemas` is generated from their
/// types ([`crate::openapi`]).
pub fn documented_responses(generator: &mut schemars::SchemaGenerator) {
    generator.subschema_for::<crate::error::ErrorBody>();
    generator.subschema_for::<textures::TextureList>();
    generator.subschema_for::<ops::Health>();
    generator.subschema_for::<frames::Frames>();
    generator.subschema_for::<crate::background::JobStatus>();
    generator.subschema_for::<volumes::PrecomputedInfo>();
    generator.subschema_for::<volumes::ZarrArray>();
}

/// The `lod` query parameter every voxel route takes.
pub fn lod_parameter() -> QueryParam {
    params::query_param(|l: voxels::Lod| l, "lod", voxels::LOD)
}

/// What handlers share.
pub struct Shared {
    /// The textures.
    pub registry: Arc<Registry>,
    /// The region textures, made of those.
    pub(crate) regions: Arc<crate::regions::Regions>,
    /// The synthesis job queue.
    pub(crate) jobs: Jobs,
    /// The bound on decoding uploaded images.
    pub(crate) decodes: Decodes,
    /// Metrics.
    pub metrics: Arc<Metrics>,
    /// Edge of served bricks.
    pub(crate) brick_size: u32,
    /// Edge of the chunks of the precomputed and Zarr views.
    pub(crate) chunk_size: u32,
    /// Work budget of one voxel request (see [`crate::ServeArgs`]).
    pub(crate) max_request_voxels: u64,
    /// Most voxels one request may synthesize (see `ServeArgs`).
    pub(crate) max_request_work: u64,
    /// Exports and background bakes running and made.
    pub(crate) background: Arc<crate::background::Background>,
    /// Most voxels in one export.
    pub(crate) max_export_voxels: u64,
    /// Most voxels one export may synthesize.
    pub(crate) max_export_work: u64,
    /// Whether volume chunks are compressed (see `ServeArgs`).
    pub(crate) chunk_compression: bool,
    /// Largest accepted upload, bytes.
    pub(crate) max_upload_bytes: usize,
    /// Bearer token that mutating routes and `/metrics` require, if any.
    pub(crate) token: Option<String>,
    /// Origins allowed to upload and delete across origins.
    pub(crate) cors_origins: Vec<axum::http::HeaderValue>,
    /// Whether the bundled texture is registered at start (`/readyz`
    /// waits for it and reports it missing).
    pub(crate) default_texture: bool,
    /// How long a voxel request waits for a pending texture before 409.
    pub(crate) pending_wait: std::time::Duration,
    /// Time a request body may take to arrive in full.
    pub(crate) body_timeout: std::time::Duration,
    /// Which `Host` headers are answered.
    pub(crate) allowed_hosts: AllowedHosts,
}

/// Longest request target (path and query) answered, bytes; longer: 414.
pub const MAX_URI_BYTES: usize = 8 << 10;
/// Most header fields in a request; more: 431.
pub const MAX_HEADERS: usize = 100;
/// Largest total of header names and values (plus 4 bytes per field for
/// `: ` and CRLF); larger: 431.
pub const MAX_HEADER_BYTES: usize = 32 << 10;
/// Largest request head hyper buffers, bytes, and most header fields it
/// parses: above the limits `head_limits` enforces, so that requests
/// between the two get a JSON answer instead of hyper's empty one.
pub const MAX_HEAD_BYTES: usize = 64 << 10;
/// See [`MAX_HEAD_BYTES`].
pub const HYPER_MAX_HEADERS: usize = 2 * MAX_HEADERS;

/// Handler state: cheap to clone.
pub type AppState = Arc<Shared>;

/// Response headers a browser may read across origins.
const EXPOSED: [&str; 10] = [
    "etag",
    "retry-after",
    "location",
    "x-solidtex-width",
    "x-solidtex-height",
    "x-solidtex-depth",
    "x-solidtex-origin",
    "x-solidtex-lod",
    "content-disposition",
    "x-solidtex-predicted-voxels",
];

/// The complete service.
pub fn router(state: AppState) -> Router {
    let upload_limit = state.max_upload_bytes;
    let routes = Router::new()
        .route("/healthz", get(ops::healthz))
        .route("/readyz", get(ops::readyz))
        .route("/metrics", get(ops::metrics))
        .route("/openapi.yaml", get(ops::openapi))
        .route(
            "/v1/textures",
            get(textures::list)
                .post(textures::create)
                .layer(DefaultBodyLimit::max(upload_limit)),
        )
        .route(
            "/v1/textures/{id}",
            get(textures::show).delete(textures::remove),
        )
        .route("/v1/textures/{id}/exemplar.png", get(textures::exemplar))
        .route(
            "/v1/textures/{id}/variants",
            post(textures::variant).layer(DefaultBodyLimit::max(textures::MAX_VARIANT_BYTES)),
        )
        .route("/v1/textures/{id}/frames/{axis}/{at}", get(frames::frames))
        .route("/v1/textures/{id}/slices/{axis}/{at}", get(voxels::slice))
        .route("/v1/textures/{id}/cut.png", get(voxels::cut))
        .route("/v1/textures/{id}/region.raw", get(voxels::region))
        .route("/v1/textures/{id}/bricks/{lod}/{brick}", get(voxels::brick))
        .route(
            "/v1/textures/{id}/precomputed/info",
            get(volumes::precomputed_info_route),
        )
        .route(
            "/v1/textures/{id}/precomputed/{scale}/{chunk}",
            get(volumes::precomputed_chunk),
        )
        .route(
            "/v1/textures/{id}/zarr/zarr.json",
            get(volumes::zarr_group_route),
        )
        .route(
            "/v1/textures/{id}/zarr/{lod}/zarr.json",
            get(volumes::zarr_array_route),
        )
        .route(
            "/v1/textures/{id}/zarr/{lod}/c/{cc}/{cz}/{cy}/{cx}",
            get(volumes::zarr_chunk),
        )
        .route(
            "/v1/textures/{id}/bake",
            post(bake::bake).layer(DefaultBodyLimit::max(solidtex_core::mesh::MAX_MESH_BYTES)),
        )
        .route("/v1/textures/{id}/export", get(exports::export))
        .route("/v1/textures/{id}/export.json", get(exports::describe))
        .route(
            "/v1/exports/{eid}",
            get(background::export_status).delete(background::export_cancel),
        )
        .route("/v1/exports/{eid}/file", get(background::export_file))
        .route(
            "/v1/bakes/{bid}",
            get(background::bake_status).delete(background::bake_cancel),
        )
        .route("/v1/bakes/{bid}/file", get(background::bake_file))
        .route("/", get(viewer::page))
        .route("/viewer.js", get(viewer::script));
    with_middleware(routes, state)
}

/// Wraps routes in the middleware stack and the JSON 404 fallback.
fn with_middleware(routes: Router<AppState>, state: AppState) -> Router {
    // Any page may read; only configured origins may upload or delete
    // (otherwise any web page could delete textures from a visitor's
    // browser).
    let cors = if state.cors_origins.is_empty() {
        CorsLayer::new().allow_origin(Any).allow_methods([
            Method::GET,
            Method::HEAD,
            Method::OPTIONS,
        ])
    } else {
        CorsLayer::new()
            .allow_origin(AllowOrigin::list(state.cors_origins.clone()))
            .allow_methods([
                Method::GET,
                Method::POST,
                Method::DELETE,
                Method::HEAD,
                Method::OPTIONS,
            ])
    };
    let cors = cors
        .allow_headers(Any)
        .expose_headers(EXPOSED.map(HeaderName::from_static))
        .max_age(Duration::from_secs(86400));
    let trace = TraceLayer::new_for_http()
        .make_span_with(|req: &Request| {
            let route = req
                .extensions()
                .get::<MatchedPath>()
                .map(|m| m.as_str().to_string())
                .unwrap_or_else(|| "unmatched".into());
            tracing::info_span!(
                "request",
                method = %req.method(),
                route = %route,
                uri = %req.uri(),
                texture = tracing::field::Empty,
                voxels = tracing::field::Empty,
                tiles_computed = tracing::field::Empty,
                tiles_cached = tracing::field::Empty,
            )
        })
        .on_response(log_response)
        // Server errors are logged by `log_response`, at their own level.
        .on_failure(());
    routes
        .fallback(no_route)
        .layer(middleware::from_fn(json_errors))
        .layer(middleware::from_fn_with_state(state.clone(), body_deadline))
        .layer(CatchPanicLayer::custom(panic_response))
        .layer(middleware::from_fn_with_state(state.clone(), authorize))
        .layer(middleware::from_fn_with_state(state.clone(), check_host))
        .layer(middleware::from_fn(head_limits))
        .layer(middleware::from_fn_with_state(state.clone(), track))
        .layer(trace)
        .layer(cors)
        .with_state(state)
}

/// One line per answered request, at a level that keeps the default log
/// quiet: successes and client errors (a viewer polls every second) are
/// DEBUG; overload (503, which `/readyz` also answers while the default
/// texture is loading) is INFO; other server errors are ERROR.
fn log_response(res: &Response, latency: Duration, _span: &tracing::Span) {
    let status = res.status().as_u16();
    let micros = latency.as_micros() as u64;
    match status {
        503 => tracing::info!(status, latency_us = micros, "answered"),
        500.. => tracing::error!(status, latency_us = micros, "answered"),
        _ => tracing::debug!(status, latency_us = micros, "answered"),
    }
}

async fn no_route(req: Request) -> ApiError {
    ApiError::new(
        StatusCode::NOT_FOUND,
        "no_route",
        format!(
            "no route for {} {}",
            echo(req.method().as_str()),
            echo(req.uri().path())
        ),
    )
}

/// With a token configured, uploads, deletions and `/metrics` need
/// `Authorization: Bearer TOKEN`; anything else is answered 401.
async fn authorize(State(s): State<AppState>, req: Request, next: Next) -> Response {
    let Some(token) = &s.token else {
        return next.run(req).await;
    };
    let guarded = !matches!(*req.method(), Method::GET | Method::HEAD | Method::OPTIONS)
        || req.uri().path() == "/metrics";
    let given = req
        .headers()
        .get(axum::http::header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "));
    if !guarded || given.is_some_and(|g| same_secret(g.as_bytes(), token.as_bytes())) {
        return next.run(req).await;
    }
    let message = if given.is_some() {
        "wrong bearer token"
    } else {
        "this route needs `Authorization: Bearer TOKEN`"
    };
    let mut res = axum::response::IntoResponse::into_response(ApiError::new(
        StatusCode::UNAUTHORIZED,
        "unauthorized",
        message,
    ));
    res.headers_mut().insert(
        axum::http::header::WWW_AUTHENTICATE,
        axum::http::HeaderValue::from_static("Bearer"),
    );
    res
}

/// Compares secrets in time that depends on their lengths only.
fn same_secret(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |d, (x, y)| d | (x ^ y)) == 0
}

/// Answers requests with an oversized target (414) or head (431) in JSON.
async fn head_limits(req: Request, next: Next) -> Response {
    let uri_len = req.uri().path_and_query().map_or(0, |p| p.as_str().len());
    if uri_len > MAX_URI_BYTES {
        return axum::response::IntoResponse::into_response(ApiError::new(
            StatusCode::URI_TOO_LONG,
            "uri_too_long",
            format!("request target of {uri_len} bytes; at most {MAX_URI_BYTES}"),
        ));
    }
    let count = req.headers().len();
    let bytes: usize = req
        .headers()
        .iter()
        .map(|(k, v)| k.as_str().len() + v.len() + 4)
        .sum();
    if count > MAX_HEADERS || bytes > MAX_HEADER_BYTES {
        return axum::response::IntoResponse::into_response(ApiError::new(
            StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE,
            "headers_too_large",
            format!(
                "{count} header fields of {bytes} bytes; at most {MAX_HEADERS} fields of \
                 {MAX_HEADER_BYTES} bytes"
            ),
        ));
    }
    next.run(req).await
}

/// Refuses requests whose `Host` is not on the allow-list (421), before
/// anything else looks at them.
async fn check_host(State(s): State<AppState>, req: Request, next: Next) -> Response {
    let host = req
        .headers()
        .get(axum::http::header::HOST)
        .map(|v| v.to_str().unwrap_or("\u{fffd}"))
        .or_else(|| req.uri().authority().map(|a| a.as_str()));
    if s.allowed_hosts.allows(host) {
        return next.run(req).await;
    }
    axum::response::IntoResponse::into_response(ApiError::new(
        StatusCode::MISDIRECTED_REQUEST,
        "host_not_allowed",
        format!(
            "host `{}` is not served here (see --allowed-hosts)",
            host.unwrap_or_default()
        ),
    ))
}

/// Gives the request body `body_timeout` to arrive in full (a client
/// trickling an upload would otherwise hold its connection and buffer for
/// ever) and answers 408 when it does not.
async fn body_deadline(State(s): State<AppState>, req: Request, next: Next) -> Response {
    use http_body_util::BodyExt;
    use std::sync::atomic::{AtomicBool, Ordering};
    let expired = Arc::new(AtomicBool::new(false));
    let flag = expired.clone();
    let req = req.map(|b| {
        axum::body::Body::new(DeadlineBody::new(s.body_timeout, b).map_err(move |e| {
            if e.is::<TimeoutError>() {
                flag.store(true, Ordering::SeqCst);
            }
            e
        }))
    });
    let res = next.run(req).await;
    if !expired.load(Ordering::SeqCst) {
        return res;
    }
    let mut res = axum::response::IntoResponse::into_response(ApiError::new(
        StatusCode::REQUEST_TIMEOUT,
        "body_timeout",
        format!(
            "the request body did not arrive within {} s",
            s.body_timeout.as_secs_f64()
        ),
    ));
    // The rest of the body is never read: the connection cannot be reused.
    res.headers_mut().insert(
        axum::http::header::CONNECTION,
        axum::http::HeaderValue::from_static("close"),
    );
    res
}

/// Counts requests and their latency per route template.
async fn track(State(s): State<AppState>, req: Request, next: Next) -> Response {
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map(|m| m.as_str().to_string())
        .unwrap_or_else(|| "unmatched".into());
    let method = req.method().clone();
    let t0 = Instant::now();
    let res = next.run(req).await;
    s.metrics.observe_request(
        &route,
        method.as_str(),
        res.status().as_u16(),
        t0.elapsed().as_secs_f64(),
    );
    res
}

/// `Cache-Control` of responses that never change.
pub const IMMUTABLE: &str = "public, max-age=31536000, immutable";

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{ServeArgs, Server};
    use axum::body::Body;
    use tower::ServiceExt;

    #[test]
    fn documented_queries_name_every_field_in_order() {
        use params::{DocumentedQuery, fields_of};
        let fields = [
            fields_of::<frames::FramesQuery>(),
            fields_of::<voxels::SliceQuery>(),
            fields_of::<voxels::CutQuery>(),
            fields_of::<voxels::RegionQuery>(),
            fields_of::<exports::ExportQuery>(),
            fields_of::<exports::ExportQuery>(),
            fields_of::<bake::BakeQuery>(),
        ];
        let documented = documented_queries();
        assert_eq!(documented.len(), fields.len());
        for ((operation, params), fields) in documented.into_iter().zip(fields) {
            let names: Vec<&str> = params.iter().map(|p| p.name).collect();
            assert_eq!(names, fields, "{operation}");
            assert!(params.iter().all(|p| !p.about.is_empty()), "{operation}");
        }
        // What serde requires is what the document marks required.
        let export = exports::ExportQuery::params();
        let required: Vec<&str> = export
            .iter()
            .filter(|p| p.required)
            .map(|p| p.name)
            .collect();
        assert_eq!(required, ["format"]);
        let slice = voxels::SliceQuery::params();
        assert!(slice.iter().all(|p| !p.required));
    }

    #[test]
    fn documented_path_parameters_are_required_and_in_routes() {
        for (component, params) in documented_paths() {
            for p in params {
                assert!(p.required, "{component}");
                let captured = format!("{{{}}}", p.name);
                assert!(
                    ROUTES.iter().any(|(_, path)| path.contains(&captured)),
                    "{component}"
                );
            }
        }
    }

    async fn boom() -> StatusCode {
        let v: Vec<u8> = Vec::new();
        if v.is_empty() {
            panic!("boom");
        }
        StatusCode::OK
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_panicking_handler_is_a_json_500_and_the_server_goes_on() {
        let dir = tempfile::tempdir().unwrap();
        let server = Server::bind(&ServeArgs::for_data_dir(dir.path()))
            .await
            .unwrap();
        let state = server.state();
        let routes = Router::new()
            .route("/boom", get(boom))
            .route("/healthz", get(ops::healthz));
        let app = with_middleware(routes, state.clone());
        let call = |uri: &'static str| {
            let app = app.clone();
            async move {
                let res = app
                    .oneshot(axum::http::Request::get(uri).body(Body::empty()).unwrap())
                    .await
                    .unwrap();
                let status = res.status();
                let body = axum::body::to_bytes(res.into_body(), 1 << 16)
                    .await
                    .unwrap();
                (
                    status,
                    serde_json::from_slice::<serde_json::Value>(&body).unwrap(),
                )
            }
        };
        let (status, v) = call("/boom").await;
        assert_eq!(status, StatusCode::INTERNAL_SERVER_ERROR);
        assert_eq!(v["error"]["code"], "internal");
        let (status, _) = call("/healthz").await;
        assert_eq!(status, StatusCode::OK);
        assert!(state.metrics.encode().contains(
            r#"solidtex_http_requests_total{route="/boom",method="GET",status="500"} 1"#
        ));
    }
}
