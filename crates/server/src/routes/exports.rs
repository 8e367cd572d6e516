//! Exports over HTTP: the same files as `solidtex export` (see
//! [`solidtex_core::export`]).
//!
//! `GET /v1/textures/{id}/export` makes the file as a background job
//! ([`crate::background`]), or joins the same export already being made,
//! and answers it when done. With `Prefer: respond-async` (RFC 7240) it
//! answers at once 202 with the export's status and its URL in
//! `Location`; `GET /v1/exports/{eid}` then reports progress,
//! `/v1/exports/{eid}/file` serves the file once it is done, and `DELETE`
//! cancels it (routes in [`super::background`]).
//! `GET /v1/textures/{id}/export.json` describes an export (the sidecar
//! JSON) without making it.
//!
//! Every export is checked before any work: the box against the server's
//! `--max-export-voxels` (400 `too_large`), the predicted synthesis against
//! `--max-export-work` (400 `over_budget`), and the parameters (400).

use super::answer::{ETag, texture};
use super::background::answer_job;
use super::params::{
    Int, TextureId, TexturePath, TypedPath, TypedQuery, document_query, named_value,
};
use super::voxels::{Coord, Lod};
use super::{AppState, IMMUTABLE};
use crate::background::{Detail, Kind, Progress, Spec};
use crate::error::ApiError;
use axum::body::{Body, Bytes};
use axum::extract::State;
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::Response;
use serde::{Deserialize, Serialize};
use solidtex_core::export::{Export, Format, MAX_EXPORT_VOXELS, Mips};
use solidtex_core::{Region, Texture};

/// The normalised form of an export, for ids and ETags.
fn export_key(e: &Export) -> String {
    let r = &e.region;
    format!(
        "export/{}/{}/{}/{}/{}/{}/{}/{}/{}/{:?}/{}",
        e.format.name(),
        e.lod,
        r.origin[0],
        r.origin[1],
        r.origin[2],
        r.size[0],
        r.size[1],
        r.size[2],
        u8::from(e.srgb),
        e.mips,
        env!("CARGO_PKG_VERSION"),
    )
}

/// A side of an export's box, 64 unless given (the voxel budget binds
/// before the largest).
type ExportSide = Int<1, { MAX_EXPORT_VOXELS as i64 }, 64>;

/// The export a query names: `format` (required), the box (`box=period`,
/// or `x`, `y`, `z`, `w`, `h`, `d`), `lod`, and for KTX2 `mips` and
/// `colour`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ExportQuery {
    format: Format,
    #[serde(rename = "box")]
    whole: Option<Whole>,
    x: Option<Coord>,
    y: Option<Coord>,
    z: Option<Coord>,
    w: Option<ExportSide>,
    h: Option<ExportSide>,
    d: Option<ExportSide>,
    #[serde(default)]
    lod: Lod,
    mips: Option<Mips>,
    colour: Option<Colour>,
}

/// What a parameter left out stands for, as the document states it: the
/// box's corner and sides, KTX2's mips and colour. (A box left out of a
/// periodic texture's export is its period; `format` has no default.)
impl Default for ExportQuery {
    fn default() -> ExportQuery {
        ExportQuery {
            format: Format::Ktx2,
            whole: None,
            x: Some(Coord::default()),
            y: Some(Coord::default()),
            z: Some(Coord::default()),
            w: Some(ExportSide::default()),
            h: Some(ExportSide::default()),
            d: Some(ExportSide::default()),
            lod: Lod::default(),
            mips: Some(Mips::default()),
            colour: Some(Colour::Srgb),
        }
    }
}

document_query!(ExportQuery {
    format: "The file's format.",
    whole as "box": "`period`: one period of a periodic texture, from the origin.",
    x: "Lowest corner along x.",
    y: "Lowest corner along y.",
    z: "Lowest corner along z.",
    w: "Extent along x.",
    h: "Extent along y.",
    d: "Extent along z.",
    lod: super::voxels::LOD,
    mips: "KTX2 only. How the mip chain is made.",
    colour: "KTX2 only. `srgb` (VK_FORMAT_R8G8B8A8_SRGB) or `linear` (R8G8B8A8_UNORM, the \
             same bytes).",
});

/// The box an export takes whole, instead of its corner and sides.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(super) enum Whole {
    /// One period of a periodic texture, from the origin.
    Period,
}

/// How a KTX2 export's colours are marked.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(super) enum Colour {
    /// `VK_FORMAT_R8G8B8A8_SRGB`.
    Srgb,
    /// `VK_FORMAT_R8G8B8A8_UNORM`: the same bytes, read as linear.
    Linear,
}

named_value!(Whole, Colour);

/// The export `q` names, checked against the texture, the limits and the
/// budgets. Returns it with the predicted synthesis (an upper bound,
/// voxels).
fn parse_export(s: &AppState, q: &ExportQuery, tex: &Texture) -> Result<(Export, u64), ApiError> {
    let format = q.format;
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
    let region = match q.whole {
        Some(Whole::Period) => {
            if let Some(k) = corner {
                return Err(ApiError::invalid_parameter(
                    k,
                    "give either `box=period` or the box's x, y, z, w, h, d",
                ));
            }
            Export::one_period(tex, lod)?
        }
        None if corner.is_none() && tex.params().period.is_some() => Export::one_period(tex, lod)?,
        None => Region {
            origin: [q.x, q.y, q.z].map(|c| c.unwrap_or_default().get()),
            size: [q.w, q.h, q.d].map(|c| c.unwrap_or_default().get_u32()),
        },
    };
    let mips = q.mips.unwrap_or_default();
    let srgb = q.colour != Some(Colour::Linear);
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

/// `GET /v1/textures/{id}/export`
pub(super) async fn export(
    State(s): State<AppState>,
    TypedPath(TexturePath { id: TextureId(id) }): TypedPath<TexturePath>,
    TypedQuery(q): TypedQuery<ExportQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let (entry, tex) = texture(&s, &id).await?;
    let (export, predicted) = parse_export(&s, &q, &tex)?;
    let key = export_key(&export);
    let tag = ETag::new(&entry, &key);
    if tag.matches(&headers) {
        return Ok(tag.not_modified(IMMUTABLE));
    }
    let total = export.voxels(&tex);
    let spec = Spec {
        id: Kind::Export.job_id(&entry.content_hash, &key),
        kind: Kind::Export,
        texture: entry.id.clone(),
        file_name: export.file_name(&entry.id),
        media_type: export.format.media_type(),
        etag_key: key,
        unit: "voxels",
        total,
        predicted,
        detail: Detail::Export {
            format: export.format.name(),
        },
    };
    let work = move |p: &Progress| -> Result<Bytes, ApiError> {
        p.set_stage("synthesis");
        let (bytes, _) = export.run(&tex, &|done, _| p.set_done(done))?;
        Ok(Bytes::from(bytes))
    };
    let job = s.background.start(spec, Box::new(work))?;
    answer_job(&s, &job, &headers).await
}

/// `GET /v1/textures/{id}/export.json`: the sidecar JSON `solidtex
/// export` writes (the same bytes), and the predicted synthesis in
/// `X-Solidtex-Predicted-Voxels`.
pub(super) async fn describe(
    State(s): State<AppState>,
    TypedPath(TexturePath { id: TextureId(id) }): TypedPath<TexturePath>,
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
