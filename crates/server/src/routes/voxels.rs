//! Voxel endpoints: axis slices and oblique cuts as PNG, regions and
//! aligned bricks as raw RGB8.
//!
//! Each handler validates everything it can before queueing (a bad request
//! never takes a job slot), derives a strong ETag from the texture's content
//! hash and the normalised request, answers `If-None-Match` with 304
//! without synthesizing, and otherwise runs the synthesis on the job queue.
//! The answer depends only on (texture, parameters, coordinates), so it is
//! marked immutable.

use super::paths::{Png, Raw, Stem, TypedPath};
use super::{AppState, IMMUTABLE};
use crate::error::ApiError;
use crate::query::{Query, parse_int};
use crate::registry::Entry;
use crate::spec::{hex, valid_id};
use axum::body::Body;
use axum::extract::{Path, RawQuery, State};
use axum::http::{HeaderMap, HeaderName, HeaderValue, StatusCode, header};
use axum::response::Response;
use serde::Deserialize;
use sha2::{Digest, Sha256};
use solidtex_core::png;
use solidtex_core::{Axis, CutPlane, Filter, Region, SynthStats, Texture, WorkEstimate};
use solidtex_core::{COORD_LIMIT, MAX_REGION_VOXELS, MAX_SLICE_SIDE};
use std::sync::Arc;

const DEFAULT_SIDE: u32 = 256;
const DEFAULT_REGION_SIDE: u32 = 64;

/// The texture of a voxel request, ready; the span records its id.
/// The texture `id` ready to synthesize. One still being precomputed is
/// waited for up to the server's `--pending-wait` before the request is
/// answered 409, so that a first request right after an upload (or after
/// start, for the bundled texture) gets its voxels.
pub(super) async fn texture(s: &AppState, id: &str) -> Result<(Arc<Entry>, Texture), ApiError> {
    if !valid_id(id) {
        return Err(ApiError::unknown_texture(id));
    }
    tracing::Span::current().record("texture", id);
    let found = s.registry.find(id).await?;
    if !s.pending_wait.is_zero()
        && let Some(e) = found
    {
        e.settle(tokio::time::Instant::now() + s.pending_wait).await;
    }
    Ok(s.registry.loaded(id).await?)
}

pub(super) fn lod(q: &Query, t: &Texture) -> Result<u32, ApiError> {
    q.int("lod", 0u32, 0, t.max_lod())
}

/// A coordinate parameter: any integer within ±2^31.
pub(super) fn coord(q: &Query, name: &str) -> Result<i64, ApiError> {
    q.int(name, 0i64, -COORD_LIMIT, COORD_LIMIT)
}

/// Refuses before any work a request predicted to synthesize more than the
/// budget. The prediction bounds a cold-cache synthesis from above, so a
/// request is refused or admitted the same whatever the cache holds; the
/// job's own count stays as a backstop.
pub(super) fn check_work(
    s: &AppState,
    predicted: solidtex_core::Result<WorkEstimate>,
) -> Result<(), ApiError> {
    let e = predicted?;
    if e.complete && e.total <= s.max_request_work {
        return Ok(());
    }
    s.metrics.over_budget("predicted");
    Err(ApiError::predicted_over_budget(
        e.total,
        e.complete,
        s.max_request_work,
    ))
}

/// Checks a request's work against the server's budget.
pub(super) fn check_budget(s: &AppState, what: &str, voxels: u64) -> Result<(), ApiError> {
    if voxels > s.max_request_voxels {
        return Err(ApiError::too_large(format!(
            "{what} costs {voxels} voxels; this server's budget per request is {}",
            s.max_request_voxels
        )));
    }
    Ok(())
}

/// Where on its plane an axis slice (or its frames) is asked for.
pub(super) struct SliceWindow {
    pub u0: i64,
    pub v0: i64,
    pub w: u32,
    pub h: u32,
    pub lod: u32,
}

/// The `u0`, `v0`, `w`, `h` and `lod` of a slice request, each in range
/// and the rectangle within the coordinate limit.
pub(super) fn slice_window(q: &Query, t: &Texture) -> Result<SliceWindow, ApiError> {
    let u0 = coord(q, "u0")?;
    let v0 = coord(q, "v0")?;
    let w = q.int("w", DEFAULT_SIDE, 1, MAX_SLICE_SIDE)?;
    let h = q.int("h", DEFAULT_SIDE, 1, MAX_SLICE_SIDE)?;
    let lod = lod(q, t)?;
    check_extent("u0", u0, w)?;
    check_extent("v0", v0, h)?;
    Ok(SliceWindow { u0, v0, w, h, lod })
}

/// Checks that `start + len - 1` stays within the coordinate limit.
pub(super) fn check_extent(name: &str, start: i64, len: u32) -> Result<(), ApiError> {
    let last = start + len as i64 - 1;
    if last > COORD_LIMIT {
        return Err(ApiError::out_of_range(
            name,
            format_args!("{start} + {len} - 1"),
            -COORD_LIMIT,
            COORD_LIMIT,
        ));
    }
    Ok(())
}

/// Strong validator of a response: the texture's content, the engine
/// version and the normalised request.
pub(super) fn etag(entry: &Entry, key: &str) -> String {
    let mut h = Sha256::new();
    h.update(b"solidtex etag v1\0");
    h.update(env!("CARGO_PKG_VERSION").as_bytes());
    h.update(b"\0");
    h.update(entry.content_hash.as_bytes());
    h.update(b"\0");
    h.update(key.as_bytes());
    format!("\"{}\"", hex(&h.finalize()[..16]))
}

/// True when `If-None-Match` lists `etag` (weak comparison) or `*`.
pub(super) fn not_modified(headers: &HeaderMap, etag: &str) -> bool {
    headers
        .get_all(header::IF_NONE_MATCH)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .map(|t| t.trim())
        .any(|t| t == "*" || t.strip_prefix("W/").unwrap_or(t) == etag)
}

pub(super) fn cache_headers(res: &mut Response, etag: &str) {
    let h = res.headers_mut();
    if let Ok(v) = HeaderValue::from_str(etag) {
        h.insert(header::ETAG, v);
    }
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static(IMMUTABLE));
}

pub(super) fn not_modified_response(etag: &str) -> Response {
    let mut res = Response::new(Body::empty());
    *res.status_mut() = StatusCode::NOT_MODIFIED;
    cache_headers(&mut res, etag);
    res
}

pub(super) fn body_response(bytes: Vec<u8>, content_type: &'static str, etag: &str) -> Response {
    let mut res = Response::new(Body::from(bytes));
    res.headers_mut()
        .insert(header::CONTENT_TYPE, HeaderValue::from_static(content_type));
    cache_headers(&mut res, etag);
    res
}

/// Records what a synthesis cost in the span and the metrics.
fn account(s: &AppState, stats: &SynthStats) {
    s.metrics.observe_synthesis(stats);
    let span = tracing::Span::current();
    span.record("voxels", stats.voxels_per_level.iter().sum::<u64>());
    span.record("tiles_computed", stats.tiles_computed);
    span.record("tiles_cached", stats.tiles_from_cache);
}

/// Runs a synthesis returning RGB8 on the job queue and encodes it as PNG
/// (on the same blocking thread).
async fn png_job(
    s: &AppState,
    width: u32,
    height: u32,
    f: impl FnOnce() -> solidtex_core::Result<(Vec<u8>, SynthStats)> + Send + 'static,
) -> Result<Vec<u8>, ApiError> {
    let (png, stats) = s
        .jobs
        .run(move || -> Result<_, ApiError> {
            let (rgb, stats) = f()?;
            let png = png::encode(width, height, &rgb)
                .map_err(|e| ApiError::internal(format!("PNG encoding failed: {e}")))?;
            Ok((png, stats))
        })
        .await??;
    account(s, &stats);
    Ok(png)
}

pub(super) async fn raw_job(
    s: &AppState,
    f: impl FnOnce() -> solidtex_core::Result<(Vec<u8>, SynthStats)> + Send + 'static,
) -> Result<Vec<u8>, ApiError> {
    let (rgb, stats) = s.jobs.run(move || f().map_err(ApiError::from)).await??;
    account(s, &stats);
    Ok(rgb)
}

pub(super) fn parse_axis(s: &str) -> Result<Axis, ApiError> {
    Axis::from_name(s).ok_or_else(|| {
        ApiError::new(
            StatusCode::BAD_REQUEST,
            "invalid_axis",
            format!("unknown axis `{s}` (expected x, y or z)"),
        )
    })
}

/// The path of a slice: `/v1/textures/{id}/slices/{axis}/{at}.png`.
#[derive(Deserialize)]
pub(super) struct SlicePath {
    id: String,
    axis: String,
    at: Stem<Png>,
}

/// `GET /v1/textures/{id}/slices/{axis}/{at}.png`
pub(super) async fn slice(
    State(s): State<AppState>,
    TypedPath(SlicePath { id, axis, at }): TypedPath<SlicePath>,
    RawQuery(raw): RawQuery,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let (entry, tex) = texture(&s, &id).await?;
    let axis = parse_axis(&axis)?;
    let at = parse_int("at", at.as_str(), -COORD_LIMIT, COORD_LIMIT)?;
    let q = Query::parse(raw.as_deref())?;
    let SliceWindow { u0, v0, w, h, lod } = slice_window(&q, &tex)?;
    check_budget(&s, "slice", w as u64 * h as u64)?;
    let region = Region::slice(axis, at, u0, v0, w, h);
    check_work(&s, tex.estimate(&region, lod, s.max_request_work))?;
    let name = match axis {
        Axis::X => "x",
        Axis::Y => "y",
        Axis::Z => "z",
    };
    let tag = etag(
        &entry,
        &format!("slice/{name}/{at}/{u0}/{v0}/{w}/{h}/{lod}"),
    );
    if not_modified(&headers, &tag) {
        return Ok(not_modified_response(&tag));
    }
    let png = png_job(&s, w, h, move || tex.slice(axis, at, u0, v0, w, h, lod)).await?;
    Ok(body_response(png, "image/png", &tag))
}

/// `GET /v1/textures/{id}/cut.png`
pub async fn cut(
    State(s): State<AppState>,
    Path(id): Path<String>,
    RawQuery(raw): RawQuery,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let (entry, tex) = texture(&s, &id).await?;
    let q = Query::parse(raw.as_deref())?;
    let origin = q.vec3("origin", [0.0; 3])?;
    let u = q.vec3("u", [1.0, 0.0, 0.0])?;
    let v = q.vec3("v", [0.0, 1.0, 0.0])?;
    let w = q.int("w", DEFAULT_SIDE, 1, MAX_SLICE_SIDE)?;
    let h = q.int("h", DEFAULT_SIDE, 1, MAX_SLICE_SIDE)?;
    let lod = lod(&q, &tex)?;
    let filter = match q.raw("filter").unwrap_or("nearest") {
        "nearest" => Filter::Nearest,
        "trilinear" => Filter::Trilinear,
        other => {
            return Err(ApiError::invalid_parameter(
                "filter",
                format_args!("`{other}` is not nearest or trilinear"),
            ));
        }
    };
    check_plane(u, v)?;
    // Every sample point within ±2^31, like every integer coordinate (a
    // trilinear sample exactly at +2^31 also reads its neighbour at weight 0).
    let limit = COORD_LIMIT as f64;
    for (i, j) in [(0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1)] {
        for a in 0..3 {
            let c = origin[a] + i as f64 * u[a] + j as f64 * v[a];
            if c.abs() > limit {
                return Err(ApiError::out_of_range(
                    "cut coordinate",
                    format_args!("{c} (pixel {i},{j})"),
                    -limit,
                    limit,
                ));
            }
        }
    }
    let spread = |a: [f64; 3]| {
        (a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
            .sqrt()
            .clamp(1.0, 8.0)
    };
    let work = (w as f64 * h as f64 * spread(u) * spread(v)).ceil() as u64;
    check_budget(&s, "cut", work)?;
    let plane = CutPlane {
        origin,
        u,
        v,
        width: w,
        height: h,
    };
    check_work(
        &s,
        tex.estimate_cut(&plane, lod, filter, s.max_request_work),
    )?;
    // Bit patterns make the key exact for any float spelling.
    let bits = |a: [f64; 3]| a.map(|x| format!("{:x}", (x + 0.0).to_bits())).join(",");
    let key = format!(
        "cut/{}/{}/{}/{w}/{h}/{lod}/{filter:?}",
        bits(origin),
        bits(u),
        bits(v)
    );
    let tag = etag(&entry, &key);
    if not_modified(&headers, &tag) {
        return Ok(not_modified_response(&tag));
    }
    let png = png_job(&s, w, h, move || tex.cut(&plane, lod, filter)).await?;
    Ok(body_response(png, "image/png", &tag))
}

/// Checks that `u` and `v` span a plane: neither is zero and they are not
/// parallel (a degenerate cut would show one line of voxels stretched).
fn check_plane(u: [f64; 3], v: [f64; 3]) -> Result<(), ApiError> {
    // Scaled by their largest component so that no product overflows.
    let unit = |a: [f64; 3]| {
        let m = a.iter().fold(0f64, |m, x| m.max(x.abs()));
        (m > 0.0).then(|| a.map(|x| x / m))
    };
    let Some(a) = unit(u) else {
        return Err(ApiError::invalid_parameter("u", "must not be zero"));
    };
    let Some(b) = unit(v) else {
        return Err(ApiError::invalid_parameter("v", "must not be zero"));
    };
    let norm = |x: [f64; 3]| (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
    let cross = [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ];
    // |u × v| = |u||v| sin θ: parallel below about 1e-9 rad.
    if norm(cross) <= 1e-9 * norm(a) * norm(b) {
        return Err(ApiError::invalid_parameter(
            "v",
            "is parallel to `u`: they must span a plane",
        ));
    }
    Ok(())
}

fn shape_headers(res: &mut Response, origin: [i64; 3], size: [u32; 3], lod: u32) {
    let h = res.headers_mut();
    let mut set = |name: &'static str, v: String| {
        if let Ok(v) = HeaderValue::from_str(&v) {
            h.insert(HeaderName::from_static(name), v);
        }
    };
    set("x-solidtex-width", size[0].to_string());
    set("x-solidtex-height", size[1].to_string());
    set("x-solidtex-depth", size[2].to_string());
    set(
        "x-solidtex-origin",
        format!("{},{},{}", origin[0], origin[1], origin[2]),
    );
    set("x-solidtex-lod", lod.to_string());
}

async fn region_response(
    s: &AppState,
    entry: &Entry,
    tex: Texture,
    region: Region,
    lod: u32,
    headers: &HeaderMap,
) -> Result<Response, ApiError> {
    let [x, y, z] = region.origin;
    let [w, h, d] = region.size;
    let tag = etag(entry, &format!("region/{x}/{y}/{z}/{w}/{h}/{d}/{lod}"));
    let mut res = if not_modified(headers, &tag) {
        not_modified_response(&tag)
    } else {
        let rgb = raw_job(s, move || tex.region(&region, lod)).await?;
        body_response(rgb, "application/octet-stream", &tag)
    };
    shape_headers(&mut res, region.origin, region.size, lod);
    Ok(res)
}

/// `GET /v1/textures/{id}/region.raw`
pub async fn region(
    State(s): State<AppState>,
    Path(id): Path<String>,
    RawQuery(raw): RawQuery,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let (entry, tex) = texture(&s, &id).await?;
    let q = Query::parse(raw.as_deref())?;
    let origin = [coord(&q, "x")?, coord(&q, "y")?, coord(&q, "z")?];
    let max_side = MAX_REGION_VOXELS as u32;
    let size = [
        q.int("w", DEFAULT_REGION_SIDE, 1, max_side)?,
        q.int("h", DEFAULT_REGION_SIDE, 1, max_side)?,
        q.int("d", DEFAULT_REGION_SIDE, 1, max_side)?,
    ];
    let lod = lod(&q, &tex)?;
    let region = Region { origin, size };
    // Checked: three sides of 2^24 would wrap to 0 and pass.
    let voxels = match region.voxel_count() {
        Some(v) if v <= MAX_REGION_VOXELS => v,
        _ => {
            return Err(ApiError::too_large(format!(
                "{}x{}x{} voxels (limit {MAX_REGION_VOXELS})",
                size[0], size[1], size[2]
            )));
        }
    };
    for (a, name) in ["x", "y", "z"].iter().enumerate() {
        check_extent(name, origin[a], size[a])?;
    }
    check_budget(&s, "region", voxels)?;
    check_work(&s, tex.estimate(&region, lod, s.max_request_work))?;
    region_response(&s, &entry, tex, region, lod, &headers).await
}

/// The path of a brick: `/v1/textures/{id}/bricks/{lod}/{bx}_{by}_{bz}.raw`.
#[derive(Deserialize)]
pub(super) struct BrickPath {
    id: String,
    lod: String,
    brick: Stem<Raw>,
}

/// `GET /v1/textures/{id}/bricks/{lod}/{bx}_{by}_{bz}.raw`
pub(super) async fn brick(
    State(s): State<AppState>,
    TypedPath(BrickPath { id, lod, brick }): TypedPath<BrickPath>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let stem = brick.as_str();
    let (entry, tex) = texture(&s, &id).await?;
    let lod = parse_int("lod", &lod, 0u32, tex.max_lod())?;
    let e = s.brick_size as i64;
    let parts: Vec<&str> = stem.split('_').collect();
    if parts.len() != 3 {
        return Err(ApiError::invalid_parameter(
            "brick",
            format_args!("`{stem}` is not bx_by_bz"),
        ));
    }
    let (lo, hi) = (-COORD_LIMIT / e, (COORD_LIMIT + 1) / e - 1);
    let mut origin = [0i64; 3];
    for (a, (p, n)) in parts.iter().zip(["bx", "by", "bz"]).enumerate() {
        origin[a] = parse_int(n, p, lo, hi)? * e;
    }
    let region = Region {
        origin,
        size: [s.brick_size; 3],
    };
    check_work(&s, tex.estimate(&region, lod, s.max_request_work))?;
    region_response(&s, &entry, tex, region, lod, &headers).await
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn if_none_match_forms() {
        let tag = "\"abc\"";
        let mut h = HeaderMap::new();
        assert!(!not_modified(&h, tag));
        h.insert(
            header::IF_NONE_MATCH,
            HeaderValue::from_static("\"x\", W/\"abc\""),
        );
        assert!(not_modified(&h, tag));
        h.insert(header::IF_NONE_MATCH, HeaderValue::from_static("*"));
        assert!(not_modified(&h, tag));
        h.insert(header::IF_NONE_MATCH, HeaderValue::from_static("\"abcd\""));
        assert!(!not_modified(&h, tag));
    }

    #[test]
    fn axes() {
        assert_eq!(parse_axis("x").unwrap(), Axis::X);
        assert_eq!(parse_axis("w").unwrap_err().code, "invalid_axis");
    }

    #[test]
    fn extents() {
        assert!(check_extent("u0", COORD_LIMIT - 9, 10).is_ok());
        assert!(check_extent("u0", COORD_LIMIT - 9, 11).is_err());
        assert!(check_extent("u0", -COORD_LIMIT, 4096).is_ok());
    }
}
