//! `GET /v1/textures/{id}/frames/{axis}/{at}.json`: the texture's field of
//! local frames sampled on a grid of an axis slice, for drawing the field
//! over the slice (the viewer's arrows).
//!
//! Reading a frame is cheap (a closed form, or a trilinear lookup for a
//! sketch) and nothing is synthesized, so the answer comes from a blocking
//! thread without a place in the synthesis queue. Like the voxel routes,
//! it depends only on the texture and the request: strong `ETag`,
//! immutable.

use super::AppState;
use super::paths::{Json, Stem, TypedPath};
use super::voxels::{
    SliceWindow, body_response, etag, not_modified, not_modified_response, parse_axis,
    slice_window, texture,
};
use crate::error::ApiError;
use crate::query::{Query, parse_int};
use axum::extract::{RawQuery, State};
use axum::http::HeaderMap;
use axum::response::Response;
use serde::Deserialize;
use serde_json::{Value, json};
use solidtex_core::{COORD_LIMIT, MAX_SLICE_SIDE};

/// Most samples one request may ask for.
pub const MAX_FRAME_SAMPLES: u64 = 4096;
/// Distance between samples when not given, in voxels of the lod.
const DEFAULT_STEP: u32 = 16;

/// The path of a frames request: `/v1/textures/{id}/frames/{axis}/{at}.json`.
#[derive(Deserialize)]
pub(super) struct FramesPath {
    id: String,
    axis: String,
    at: Stem<Json>,
}

fn axis_name(i: usize) -> &'static str {
    ["x", "y", "z"][i]
}

/// A component rounded to 1e-6 (plenty for drawing; keeps the answer
/// short), without negative zeros.
fn short(x: f64) -> f64 {
    (x * 1e6).round() / 1e6 + 0.0
}

/// `GET /v1/textures/{id}/frames/{axis}/{at}.json`
pub(super) async fn frames(
    State(s): State<AppState>,
    TypedPath(FramesPath { id, axis, at }): TypedPath<FramesPath>,
    RawQuery(raw): RawQuery,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let (entry, tex) = texture(&s, &id).await?;
    let axis = parse_axis(&axis)?;
    let at = parse_int("at", at.as_str(), -COORD_LIMIT, COORD_LIMIT)?;
    let q = Query::parse(raw.as_deref())?;
    let SliceWindow { u0, v0, w, h, lod } = slice_window(&q, &tex)?;
    let step = q.int("step", DEFAULT_STEP, 1, MAX_SLICE_SIDE)?;
    let columns = w.div_ceil(step);
    let rows = h.div_ceil(step);
    let count = u64::from(columns) * u64::from(rows);
    if count > MAX_FRAME_SAMPLES {
        return Err(ApiError::too_large(format!(
            "{columns}x{rows} samples (w / step by h / step, rounded up); at most \
             {MAX_FRAME_SAMPLES}: ask for a smaller area or a larger step"
        )));
    }
    let (n, ia, ib) = axis.frame();
    let name = axis_name(n);
    let tag = etag(
        &entry,
        &format!("frames/{name}/{at}/{u0}/{v0}/{w}/{h}/{step}/{lod}"),
    );
    if not_modified(&headers, &tag) {
        return Ok(not_modified_response(&tag));
    }
    let kind = entry
        .params
        .synth
        .field
        .as_ref()
        .map(|f| match serde_json::to_value(f) {
            Ok(Value::Object(m)) => m.get("kind").cloned().unwrap_or(Value::Null),
            _ => Value::Null,
        });
    let body = tokio::task::spawn_blocking(move || {
        let mut samples = Vec::with_capacity(count as usize);
        // Every sample lies within the rectangle that check_extent bounded.
        for j in 0..rows {
            let v = v0 + i64::from(j) * i64::from(step);
            for i in 0..columns {
                let u = u0 + i64::from(i) * i64::from(step);
                let mut p = [0.0; 3];
                p[ia] = u as f64;
                p[ib] = v as f64;
                p[n] = at as f64;
                let f = tex.frame(lod, p);
                let project = |a: [f64; 3]| [short(a[ia]), short(a[ib]), short(a[n])];
                samples.push(json!({
                    "u": u,
                    "v": v,
                    "x": project(f[0]),
                    "y": project(f[1]),
                    "z": project(f[2]),
                }));
            }
        }
        json!({
            "axis": name,
            "at": at,
            "lod": lod,
            "u_axis": axis_name(ia),
            "v_axis": axis_name(ib),
            "u0": u0,
            "v0": v0,
            "w": w,
            "h": h,
            "step": step,
            "columns": columns,
            "rows": rows,
            "field_kind": kind.unwrap_or(Value::Null),
            "samples": samples,
        })
        .to_string()
    })
    .await
    .map_err(|e| ApiError::internal(e.to_string()))?;
    Ok(body_response(body.into_bytes(), "application/json", &tag))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn components_are_short_and_never_negative_zero() {
        assert_eq!(short(-1e-9), 0.0);
        assert!(short(-1e-9).is_sign_positive());
        assert_eq!(short(0.123_456_789), 0.123_457);
    }
}
