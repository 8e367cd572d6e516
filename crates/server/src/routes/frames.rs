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
use super::IMMUTABLE;
use super::answer::{ETag, body, texture};
use super::params::{Int, Json, Stem, TypedPath, TypedQuery, document_query};
use super::voxels::{Coord, LOD, Lod, Side};
use crate::error::ApiError;
use axum::extract::State;
use axum::http::HeaderMap;
use axum::response::Response;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use solidtex_core::{Axis, MAX_SLICE_SIDE, Request, SynthParams, Texture, Window};

/// Most samples one request may ask for.
pub const MAX_FRAME_SAMPLES: u64 = 4096;

/// The path of a frames request: `/v1/textures/{id}/frames/{axis}/{at}.json`.
#[derive(Deserialize)]
pub(super) struct FramesPath {
    id: String,
    axis: Axis,
    at: Stem<Json, Coord>,
}

/// The slice window sampled, and the distance between samples (in voxels
/// of the lod, 16 unless given).
#[derive(Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub(super) struct FramesQuery {
    u0: Coord,
    v0: Coord,
    w: Side,
    h: Side,
    lod: Lod,
    step: Int<1, { MAX_SLICE_SIDE as i64 }, 16>,
}

document_query!(FramesQuery {
    u0: "First u coordinate of the sampled window.",
    v0: "First v coordinate of the sampled window.",
    w: "Width of the sampled window, in voxels of `lod`.",
    h: "Height of the sampled window, in voxels of `lod`.",
    lod: LOD,
    step: "Distance between samples along u and v, in voxels of `lod`.",
});

// openapi.yaml's `Frames`, `FrameSample` and `ProjectedAxis` schemas are
// generated from these types. Fields are in alphabetical order, the order
// the answer had when it was built as a JSON map, so the bytes stay the same.

/// The frames of a texture's field at a grid of samples of an axis slice.
#[derive(Serialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
pub(super) struct Frames {
    at: i64,
    #[schemars(extend("enum" = ["x", "y", "z"]))]
    axis: &'static str,
    /// Samples per row, ⌈w/step⌉.
    #[schemars(range(min = 1))]
    columns: u32,
    /// The `kind` of the texture's field; null without one.
    field_kind: Option<String>,
    #[schemars(range(min = 1, max = MAX_SLICE_SIDE))]
    h: u32,
    lod: u32,
    /// Rows of samples, ⌈h/step⌉.
    #[schemars(range(min = 1))]
    rows: u32,
    #[schemars(length(max = MAX_FRAME_SAMPLES))]
    samples: Vec<FrameSample>,
    #[schemars(range(min = 1, max = MAX_SLICE_SIDE))]
    step: u32,
    u0: i64,
    /// The world axis along the slice's u.
    #[schemars(extend("enum" = ["x", "y", "z"]))]
    u_axis: &'static str,
    v0: i64,
    /// The world axis along the slice's v.
    #[schemars(extend("enum" = ["x", "y", "z"]))]
    v_axis: &'static str,
    #[schemars(range(min = 1, max = MAX_SLICE_SIDE))]
    w: u32,
}

/// The local frame at one sample.
#[derive(Serialize, JsonSchema)]
#[schemars(deny_unknown_fields)]
struct FrameSample {
    u: i64,
    v: i64,
    x: ProjectedAxis,
    y: ProjectedAxis,
    z: ProjectedAxis,
}

/// A local axis (unit length) by its components along the slice's u and v
/// axes and along its normal, rounded to 1e-6.
#[derive(Serialize, JsonSchema)]
#[serde(transparent)]
struct ProjectedAxis([f64; 3]);

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
    TypedPath(p): TypedPath<FramesPath>,
    TypedQuery(q): TypedQuery<FramesQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let (entry, tex) = texture(&s, &p.id).await?;
    let (grid, slice) = Grid::new(&p, &q, tex.max_lod())?;
    let tag = ETag::new(
        &entry,
        &format!("frames/{}/{}", grid.step, slice.key(grid.lod)),
    );
    if tag.matches(&headers) {
        return Ok(tag.not_modified(IMMUTABLE));
    }
    let kind = field_kind(&entry.params.synth);
    let json = tokio::task::spawn_blocking(move || grid.answer(&tex, kind))
        .await
        .map_err(|e| ApiError::internal(e.to_string()))?;
    Ok(tag.stamp(body(json.into_bytes(), "application/json"), IMMUTABLE))
}

/// The grid of samples a request reads: every `step`-th voxel of a slice
/// window, at one level of detail.
struct Grid {
    axis: Axis,
    at: i64,
    window: Window,
    lod: u32,
    step: u32,
    columns: u32,
    rows: u32,
}

impl Grid {
    /// The request's grid and the slice request of its window (which
    /// checks the window against the coordinate limit, and keys the
    /// answer); a lod past the texture's or more than
    /// [`MAX_FRAME_SAMPLES`] samples are refused.
    fn new(p: &FramesPath, q: &FramesQuery, max_lod: u32) -> Result<(Grid, Request), ApiError> {
        let (axis, at) = (p.axis, p.at.0.get());
        let window = Window::new(q.u0.get(), q.v0.get(), q.w.get_u32(), q.h.get_u32());
        let slice = Request::slice(axis, at, window)?;
        let (lod, step) = (q.lod.get_u32(), q.step.get_u32());
        if lod > max_lod {
            return Err(ApiError::out_of_range("lod", lod, 0, max_lod));
        }
        let columns = window.width.div_ceil(step);
        let rows = window.height.div_ceil(step);
        if u64::from(columns) * u64::from(rows) > MAX_FRAME_SAMPLES {
            return Err(ApiError::too_large(format!(
                "{columns}x{rows} samples (w / step by h / step, rounded up); at most \
                 {MAX_FRAME_SAMPLES}: ask for a smaller area or a larger step"
            )));
        }
        let grid = Grid {
            axis,
            at,
            window,
            lod,
            step,
            columns,
            rows,
        };
        Ok((grid, slice))
    }

    /// The frame at every sample, in the slice's (u, v, normal) axes, and
    /// the grid, as the answer's JSON text.
    fn answer(&self, tex: &Texture, field_kind: Option<String>) -> String {
        let (n, ia, ib) = self.axis.frame();
        let Window { u0, v0, .. } = self.window;
        let mut samples = Vec::with_capacity(self.columns as usize * self.rows as usize);
        // Every sample lies within the window the slice request bounded.
        for j in 0..self.rows {
            let v = v0 + i64::from(j) * i64::from(self.step);
            for i in 0..self.columns {
                let u = u0 + i64::from(i) * i64::from(self.step);
                let mut p = [0.0; 3];
                p[ia] = u as f64;
                p[ib] = v as f64;
                p[n] = self.at as f64;
                let f = tex.frame(self.lod, p);
                let project =
                    |a: [f64; 3]| ProjectedAxis([short(a[ia]), short(a[ib]), short(a[n])]);
                samples.push(FrameSample {
                    u,
                    v,
                    x: project(f[0]),
                    y: project(f[1]),
                    z: project(f[2]),
                });
            }
        }
        let frames = Frames {
            at: self.at,
            axis: self.axis.name(),
            columns: self.columns,
            field_kind,
            h: self.window.height,
            lod: self.lod,
            rows: self.rows,
            samples,
            step: self.step,
            u0,
            u_axis: axis_name(ia),
            v0,
            v_axis: axis_name(ib),
            w: self.window.width,
        };
        serde_json::to_string(&frames).expect("frames serialise")
    }
}

/// The `kind` of the texture's field, if it has one.
fn field_kind(synth: &SynthParams) -> Option<String> {
    match synth.field.as_ref().map(serde_json::to_value) {
        Some(Ok(Value::Object(m))) => m.get("kind")?.as_str().map(str::to_string),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_answer_is_written_as_its_json_map_was() {
        let frames = Frames {
            at: -3,
            axis: "z",
            columns: 1,
            field_kind: Some("slant".into()),
            h: 4,
            lod: 0,
            rows: 1,
            samples: vec![FrameSample {
                u: 0,
                v: 1,
                x: ProjectedAxis([1.0, 0.0, 0.0]),
                y: ProjectedAxis([0.0, 0.5, 0.866_025]),
                z: ProjectedAxis([0.0, -0.866_025, 0.5]),
            }],
            step: 16,
            u0: 0,
            u_axis: "x",
            v0: 1,
            v_axis: "y",
            w: 4,
        };
        assert!(crate::openapi::keys_in_map_order(&frames));
    }

    #[test]
    fn components_are_short_and_never_negative_zero() {
        assert_eq!(short(-1e-9), 0.0);
        assert!(short(-1e-9).is_sign_positive());
        assert_eq!(short(0.123_456_789), 0.123_457);
    }
}
