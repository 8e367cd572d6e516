//! `/v1/textures`: upload exemplars, list, inspect and delete textures.

use super::AppState;
use super::IMMUTABLE;
use super::answer::{ETag, body};
use super::params::{NoQuery, TextureId, TexturePath, TypedPath, TypedQuery};
use crate::error::ApiError;
use crate::query::Query;
use crate::regions::{ID_PREFIX, RegionDef, Stored};
use crate::registry::{Entry, RegistryError, Status, Submitted};
use crate::spec::{ExemplarInfo, Planes, TextureParams, TextureSpec, params_object, valid_id};
use axum::Json;
use axum::body::Bytes;
use axum::extract::{FromRequest, Multipart, Request, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use schemars::JsonSchema;
use serde::Serialize;
use serde_json::{Map, Value, json};
use solidtex_core::Exemplar;
use solidtex_core::Layout;
use std::sync::Arc;

// openapi.yaml's `Texture`, `Layout` and `TextureList` schemas are
// generated from these types: their doc comments are the document's
// descriptions. Fields are in alphabetical order, the order the bodies had
// when they were built as JSON maps, so the bytes stay the same.

/// A texture: its exemplars, parameters and precompute.
#[derive(Debug, Serialize, JsonSchema)]
#[schemars(rename = "Texture")]
pub(crate) struct TextureView {
    /// Edge of the bricks served under `/bricks/`.
    pub(crate) brick_size: u32,
    /// Creation time, seconds since the Unix epoch.
    pub(crate) created: u64,
    #[serde(serialize_with = "in_map_order")]
    #[schemars(with = "ExemplarInfo")]
    pub(crate) exemplar: ExemplarInfo,
    pub(crate) id: String,
    /// Highest level of detail served (when ready).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "u32")]
    pub(crate) max_lod: Option<u32>,
    /// The uploaded file's name (multipart file name, or the `name` query
    /// parameter), for people; not part of the id. The first upload of a
    /// content names it.
    pub(crate) name: Option<String>,
    /// Only in the answer to an upload: what was done to the images, e.g. a
    /// photo downscaled to the exemplar size limit.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub(crate) notes: Vec<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "LayoutView")]
    pub(crate) orientation: Option<LayoutView>,
    #[schemars(schema_with = "params_schema")]
    pub(crate) params: Map<String, Value>,
    /// Heap bytes the precompute is expected to peak at (from the exemplar
    /// size and the analysis parameters); precomputes run together only
    /// while these add up to the server's bound.
    pub(crate) precompute_estimated_bytes: u64,
    /// Heap bytes the precompute peaked at, as counted by the server's
    /// allocator (absent when not measured, e.g. for the bundled or shared
    /// candidates).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "u64")]
    pub(crate) precompute_peak_bytes: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "f64")]
    pub(crate) precompute_seconds: Option<f64>,
    /// Precompute progress.
    #[schemars(range(min = 0, max = 1))]
    pub(crate) progress: f64,
    /// Why the precompute failed.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "String")]
    pub(crate) reason: Option<String>,
    /// Current precompute stage (`queued`, `analysis`, `search`,
    /// `coherence`, `finish`, `done`, `failed`).
    pub(crate) stage: &'static str,
    pub(crate) status: TextureStatus,
}

/// Whether the texture's candidates are precomputed.
#[derive(Debug, Clone, Copy, Serialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
#[schemars(inline)]
pub(crate) enum TextureStatus {
    Pending,
    Ready,
    Failed,
}

/// `value` with its keys in alphabetical order, as a JSON map writes them
/// (the type's own order is its stored metadata's).
fn in_map_order<T: Serialize, S: serde::Serializer>(value: &T, s: S) -> Result<S::Ok, S::Error> {
    serde_json::to_value(value)
        .map_err(serde::ser::Error::custom)?
        .serialize(s)
}

/// The `Params` schema: the knobs' own section of the document.
fn params_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
    schemars::json_schema!({ "$ref": "#/components/schemas/Params" })
}

/// What the `orientation` parameter resolved to, and what was measured on
/// the xy exemplar.
#[derive(Debug, Serialize, JsonSchema)]
#[schemars(rename = "Layout")]
pub(crate) struct LayoutView {
    /// Coherence of the structure tensor of the exemplar's luminance (2×2
    /// pixel differences summed over the image): 0 when its gradients point
    /// every way, 1 for perfect stripes.
    #[schemars(range(min = 0, max = 1))]
    pub(crate) coherence: f64,
    /// The exemplar is one image for all planes, square, and strongly
    /// oriented along one of its axes (coherence at least 0.6, grain within
    /// 15° of an axis): `auto` arranges it.
    pub(crate) detected: bool,
    /// Direction of the grain, in degrees from the image's u axis towards
    /// v, in (-90, 90]: 0 is along u, 90 along v.
    pub(crate) grain_degrees: f64,
    /// The rotation of each plane's exemplar in use (xy, yz, zx).
    pub(crate) rotate: [u32; 3],
    /// The weight of each plane in use.
    pub(crate) weights: [f64; 3],
}

/// Every texture.
#[derive(Debug, Serialize, JsonSchema)]
pub(crate) struct TextureList {
    /// The region textures (two textures sharing space), oldest first.
    #[schemars(schema_with = "regions_schema")]
    pub(crate) regions: Vec<Value>,
    pub(crate) textures: Vec<TextureView>,
}

/// The region textures' schema: written by hand beside the generated ones.
fn regions_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
    schemars::json_schema!({
        "type": "array",
        "items": { "$ref": "#/components/schemas/RegionTexture" }
    })
}

/// The view of a texture.
pub(crate) fn view(e: &Entry, brick_size: u32) -> TextureView {
    let (status, max_lod, reason) = match e.status() {
        Status::Pending => (TextureStatus::Pending, None, None),
        Status::Ready(_) | Status::Stored => (TextureStatus::Ready, Some(e.max_lod()), None),
        Status::Failed(r) => (TextureStatus::Failed, None, Some(r)),
    };
    TextureView {
        brick_size,
        created: e.created,
        exemplar: e.exemplar,
        id: e.id.clone(),
        max_lod,
        name: e.name.clone(),
        notes: Vec::new(),
        orientation: e.layout.as_ref().map(layout_view),
        params: e.params.to_flat(),
        precompute_estimated_bytes: e.precompute_estimate,
        precompute_peak_bytes: e.precompute_peak(),
        precompute_seconds: e.precompute_seconds(),
        // Widened as a JSON map widened it, so the digits stay the same.
        progress: f64::from(e.progress()),
        reason,
        stage: e.stage(),
        status,
    }
}

/// What the `orientation` parameter resolved to, and what was measured.
fn layout_view(l: &Layout) -> LayoutView {
    let round = |x: f32, places: i32| {
        let s = 10f64.powi(places);
        (x as f64 * s).round() / s
    };
    let a = &l.arrangement;
    LayoutView {
        coherence: round(l.grain.coherence, 3),
        detected: l.detected,
        grain_degrees: round(l.grain.degrees, 1),
        rotate: a.rotate,
        weights: a.weights.map(|w| round(w, 3)),
    }
}

/// `GET /v1/textures`: once the stored textures are loaded (a list of
/// some of them would read as if the others were gone).
pub(super) async fn list(
    State(s): State<AppState>,
    TypedQuery(NoQuery {}): TypedQuery<NoQuery>,
) -> Result<Json<TextureList>, ApiError> {
    s.registry.await_recovered().await?;
    let textures = s
        .registry
        .list()
        .iter()
        .map(|e| view(e, s.brick_size))
        .collect();
    let regions = s.regions.clone();
    let regions: Vec<Value> = blocking(move || regions.list())
        .await?
        .iter()
        .map(|r| region_view(r, s.brick_size))
        .collect();
    Ok(Json(TextureList { regions, textures }))
}

/// Runs a blocking storage call off the async threads.
async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> std::io::Result<T> + Send + 'static,
) -> Result<T, ApiError> {
    tokio::task::spawn_blocking(f)
        .await
        .map_err(|e| ApiError::internal(e.to_string()))?
        .map_err(|e| ApiError::internal(format!("reading the region textures: {e}")))
}

/// Region texture `id`, when it is one.
pub(super) async fn region(s: &AppState, id: &str) -> Result<Option<Stored>, ApiError> {
    if !id.starts_with(ID_PREFIX) {
        return Ok(None);
    }
    let (regions, id) = (s.regions.clone(), id.to_string());
    blocking(move || regions.get(&id)).await
}

/// The JSON view of a region texture.
fn region_view(r: &Stored, brick_size: u32) -> Value {
    json!({
        "id": r.id,
        "kind": "region",
        "status": "ready",
        "created": r.created,
        "outer": r.def.outer,
        "inner": r.def.inner,
        "region": r.def.region,
        "band": r.def.band,
        "brick_size": brick_size,
    })
}

/// Largest region texture definition accepted, bytes.
const MAX_REGION_BODY: usize = 16 << 10;

/// `POST /v1/textures` with a JSON body: a region texture made of two
/// textures the server has. Both must be ready (so that nesting, periods
/// and levels are checked now, not at the first request).
async fn create_region(s: &AppState, req: Request) -> Result<Response, ApiError> {
    let bytes = read_body(req, MAX_REGION_BODY).await?;
    let def: RegionDef = serde_json::from_slice(&bytes).map_err(|e| {
        ApiError::new(
            StatusCode::BAD_REQUEST,
            "invalid_region",
            format!("a region texture is {{\"outer\", \"inner\", \"region\", \"band\"}}: {e}"),
        )
    })?;
    def.split().check()?;
    let (_, outer) = super::answer::texture(s, &def.outer).await?;
    let (_, inner) = super::answer::texture(s, &def.inner).await?;
    let max_lod = solidtex_core::Texture::with_region(outer, inner, def.split())?.max_lod();
    let regions = s.regions.clone();
    let (stored, _) = blocking(move || regions.create(def, crate::registry::now())).await?;
    tracing::Span::current().record("texture", stored.id.as_str());
    let mut body = region_view(&stored, s.brick_size);
    body["max_lod"] = max_lod.into();
    let mut res = (StatusCode::CREATED, Json(body)).into_response();
    if let Ok(loc) = HeaderValue::from_str(&format!("/v1/textures/{}", stored.id)) {
        res.headers_mut().insert(header::LOCATION, loc);
    }
    Ok(res)
}

fn checked_id(id: &str) -> Result<(), ApiError> {
    if valid_id(id) {
        Ok(())
    } else {
        Err(ApiError::unknown_texture(id))
    }
}

/// The texture `id`, in any status; the span records its id.
async fn known(s: &AppState, id: &str) -> Result<Arc<Entry>, ApiError> {
    checked_id(id)?;
    tracing::Span::current().record("texture", id);
    s.registry
        .find(id)
        .await?
        .ok_or_else(|| ApiError::unknown_texture(id))
}

/// `GET /v1/textures/{id}`.
pub(super) async fn show(
    State(s): State<AppState>,
    TypedPath(TexturePath { id: TextureId(id) }): TypedPath<TexturePath>,
    TypedQuery(NoQuery {}): TypedQuery<NoQuery>,
) -> Result<Response, ApiError> {
    checked_id(&id)?;
    if let Some(r) = region(&s, &id).await? {
        let mut v = region_view(&r, s.brick_size);
        if let Ok((_, t)) = super::answer::texture(&s, &id).await {
            v["max_lod"] = t.max_lod().into();
        }
        return Ok(Json(v).into_response());
    }
    let e = known(&s, &id).await?;
    Ok(Json(view(&e, s.brick_size)).into_response())
}

/// `DELETE /v1/textures/{id}`.
pub(super) async fn remove(
    State(s): State<AppState>,
    TypedPath(TexturePath { id: TextureId(id) }): TypedPath<TexturePath>,
    TypedQuery(NoQuery {}): TypedQuery<NoQuery>,
) -> Result<StatusCode, ApiError> {
    checked_id(&id)?;
    tracing::Span::current().record("texture", id.as_str());
    let regions = s.regions.clone();
    let of = id.clone();
    let users = blocking(move || regions.users_of(&of)).await?;
    if !users.is_empty() {
        return Err(ApiError::new(
            StatusCode::CONFLICT,
            "texture_in_use",
            format!(
                "texture `{id}` is part of region texture{} {}: delete {} first",
                if users.len() > 1 { "s" } else { "" },
                users.join(", "),
                if users.len() > 1 { "them" } else { "it" },
            ),
        ));
    }
    if id.starts_with(ID_PREFIX) {
        let regions = s.regions.clone();
        let of = id.clone();
        if blocking(move || regions.remove(&of)).await? {
            return Ok(StatusCode::NO_CONTENT);
        }
        return Err(ApiError::unknown_texture(&id));
    }
    s.registry.delete(&id).await?;
    Ok(StatusCode::NO_CONTENT)
}

/// Exemplar images as uploaded, before decoding, each with its feature
/// mask image if one was sent.
enum RawPlanes {
    Single(Bytes, Option<Bytes>),
    Triple([Bytes; 3], [Option<Bytes>; 3]),
}

impl RawPlanes {
    /// Every image with the name of its form field.
    fn images(&self) -> Vec<(String, &Bytes)> {
        let named: Vec<(&str, &Bytes, &Option<Bytes>)> = match self {
            RawPlanes::Single(b, m) => vec![("image", b, m)],
            RawPlanes::Triple(planes, masks) => ["xy", "yz", "zx"]
                .into_iter()
                .zip(planes)
                .zip(masks)
                .map(|((name, b), m)| (name, b, m))
                .collect(),
        };
        let mut out = Vec::new();
        for (name, image, mask) in named {
            out.push((name.to_string(), image));
            if let Some(m) = mask {
                out.push((mask_field(name), m));
            }
        }
        out
    }

    /// The most heap bytes decoding every image takes (they are decoded
    /// one after the other, and each result is small), from their headers;
    /// an error names the image whose header is refused.
    fn decode_peak_bytes(&self) -> Result<u64, ApiError> {
        let mut total = 0u64;
        for (name, bytes) in self.images() {
            check_not_empty(&name, bytes)?;
            let peak = Exemplar::decode_peak_bytes(bytes).map_err(|e| named(&name, e))?;
            total = total.saturating_add(peak);
        }
        Ok(total)
    }
}

/// The form field of the feature mask of the image in field `name`.
fn mask_field(name: &str) -> String {
    if name == "image" {
        "feature_mask".to_string()
    } else {
        format!("feature_mask_{name}")
    }
}

fn check_not_empty(name: &str, bytes: &[u8]) -> Result<(), ApiError> {
    if bytes.is_empty() {
        return Err(ApiError::new(
            StatusCode::BAD_REQUEST,
            "malformed_image",
            format!("{name}: empty image"),
        ));
    }
    Ok(())
}

/// An engine error about the image of form field `name`.
fn named(name: &str, e: solidtex_core::Error) -> ApiError {
    let mut a = ApiError::from(e);
    a.message = format!("{name}: {}", a.message);
    a
}

/// Longest texture name kept, in characters.
const MAX_NAME_CHARS: usize = 120;

/// A display name from an uploaded file's name: its last path component,
/// without control characters, at most [`MAX_NAME_CHARS`] long; none when
/// nothing printable is left.
fn display_name(raw: &str) -> Option<String> {
    let base = raw.rsplit(['/', '\\']).next().unwrap_or("");
    let clean: String = base
        .chars()
        .filter(|c| !c.is_control())
        .take(MAX_NAME_CHARS)
        .collect();
    let clean = clean.trim();
    (!clean.is_empty()).then(|| clean.to_string())
}

/// `POST /v1/textures`: a PNG body, or multipart `xy`/`yz`/`zx` (or one
/// `image`) with optional JSON `params` and optional feature masks
/// (`feature_mask` with `image`, `feature_mask_xy` … with the planes);
/// parameters may also be given in the query string. A JSON body defines
/// a region texture instead (see [`crate::regions`]).
pub async fn create(State(s): State<AppState>, req: Request) -> Result<Response, ApiError> {
    let query = Query::parse(req.uri().query())?;
    // `name` labels the texture; it is not a parameter and not in the id.
    let mut name = query.raw("name").and_then(display_name);
    let mut flat = TextureParams::flat_from_pairs(query.pairs().filter(|(k, _)| *k != "name"));
    let content_type = req
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_string();
    let essence = content_type
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_ascii_lowercase();
    let limit = s.max_upload_bytes;
    let raw = match essence.as_str() {
        "application/json" => return create_region(&s, req).await,
        "image/png" | "image/jpeg" => RawPlanes::Single(read_body(req, limit).await?, None),
        "multipart/form-data" => read_multipart(req, &mut flat, &mut name).await?,
        "" => {
            return Err(unsupported(
                "missing Content-Type (send image/png, image/jpeg, multipart/form-data or application/json)",
            ));
        }
        other => {
            return Err(unsupported(&format!(
                "unsupported Content-Type `{other}` (send image/png, image/jpeg, multipart/form-data or application/json)"
            )));
        }
    };
    let params = TextureParams::from_flat(&flat)?;
    // Room for the decodes, by what the headers say they will take, before
    // any pixel is decoded.
    let admitted = s.decodes.admit(raw.decode_peak_bytes()?).await?;
    let (spec, notes) = tokio::task::spawn_blocking(move || {
        let _admitted = admitted;
        decode(raw, params)
    })
    .await
    .map_err(|e| ApiError::internal(e.to_string()))??;
    let submitted = s.registry.submit(None, spec, name).await?;
    let (entry, status) = match submitted {
        Submitted::Known(e) => (e, StatusCode::CREATED),
        Submitted::Pending(e) => (e, StatusCode::ACCEPTED),
    };
    tracing::Span::current().record("texture", entry.id.as_str());
    Ok(created_response(&entry, status, s.brick_size, &notes))
}

fn created_response(
    entry: &Arc<Entry>,
    status: StatusCode,
    brick_size: u32,
    notes: &[String],
) -> Response {
    let body = TextureView {
        notes: notes.to_vec(),
        ..view(entry, brick_size)
    };
    let mut res = (status, Json(body)).into_response();
    if let Ok(loc) = HeaderValue::from_str(&format!("/v1/textures/{}", entry.id)) {
        res.headers_mut().insert(header::LOCATION, loc);
    }
    if status == StatusCode::ACCEPTED {
        res.headers_mut()
            .insert(header::RETRY_AFTER, HeaderValue::from_static("1"));
    }
    res
}

fn unsupported(message: &str) -> ApiError {
    ApiError::new(
        StatusCode::UNSUPPORTED_MEDIA_TYPE,
        "unsupported_media_type",
        message,
    )
}

fn too_large(limit: usize) -> ApiError {
    ApiError::new(
        StatusCode::PAYLOAD_TOO_LARGE,
        "payload_too_large",
        format!("request body larger than {limit} bytes"),
    )
}

async fn read_body(req: Request, limit: usize) -> Result<Bytes, ApiError> {
    let declared = req
        .headers()
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    if declared.is_some_and(|n| n > limit as u64) {
        return Err(too_large(limit));
    }
    axum::body::to_bytes(req.into_body(), limit)
        .await
        .map_err(|_| too_large(limit))
}

fn multipart_error(e: axum::extract::multipart::MultipartError) -> ApiError {
    let status = e.status();
    let code = match status {
        StatusCode::PAYLOAD_TOO_LARGE => "payload_too_large",
        _ => "malformed_multipart",
    };
    ApiError::new(status, code, e.body_text())
}

async fn read_multipart(
    req: Request,
    flat: &mut Map<String, Value>,
    label: &mut Option<String>,
) -> Result<RawPlanes, ApiError> {
    let mut mp = Multipart::from_request(req, &()).await.map_err(|e| {
        ApiError::new(
            StatusCode::BAD_REQUEST,
            "malformed_multipart",
            e.body_text(),
        )
    })?;
    let (mut single, mut xy, mut yz, mut zx) = (None, None, None, None);
    let mut masks: [Option<Bytes>; 4] = Default::default();
    let mut params_given = false;
    while let Some(field) = mp.next_field().await.map_err(multipart_error)? {
        let name = field.name().unwrap_or("").to_string();
        if matches!(name.as_str(), "image" | "exemplar" | "xy") && label.is_none() {
            *label = field.file_name().and_then(display_name);
        }
        let data = field.bytes().await.map_err(multipart_error)?;
        let slot = match name.as_str() {
            "image" | "exemplar" => &mut single,
            "xy" => &mut xy,
            "yz" => &mut yz,
            "zx" => &mut zx,
            "feature_mask" => &mut masks[0],
            "feature_mask_xy" => &mut masks[1],
            "feature_mask_yz" => &mut masks[2],
            "feature_mask_zx" => &mut masks[3],
            "params" => {
                if std::mem::replace(&mut params_given, true) {
                    return Err(ApiError::new(
                        StatusCode::BAD_REQUEST,
                        "invalid_request",
                        "form field `params` given more than once",
                    ));
                }
                let text = std::str::from_utf8(&data).map_err(|_| {
                    ApiError::new(
                        StatusCode::BAD_REQUEST,
                        "invalid_params",
                        "`params` is not UTF-8",
                    )
                })?;
                for (k, v) in params_object(text)? {
                    if flat.contains_key(&k) {
                        return Err(ApiError::new(
                            StatusCode::BAD_REQUEST,
                            "invalid_params",
                            format!("parameter `{k}` given both in the query and in `params`"),
                        ));
                    }
                    flat.insert(k, v);
                }
                continue;
            }
            other => {
                return Err(ApiError::new(
                    StatusCode::BAD_REQUEST,
                    "invalid_request",
                    format!(
                        "unknown form field `{other}` (expected xy, yz, zx or image, \
                         their feature masks, and params)"
                    ),
                ));
            }
        };
        if slot.replace(data).is_some() {
            return Err(ApiError::new(
                StatusCode::BAD_REQUEST,
                "invalid_request",
                format!("form field `{name}` given more than once"),
            ));
        }
    }
    let [mask, mask_xy, mask_yz, mask_zx] = masks;
    let misplaced = |field: &str, with: &str| {
        Err(ApiError::new(
            StatusCode::BAD_REQUEST,
            "invalid_request",
            format!("form field `{field}` goes with {with}"),
        ))
    };
    match (single, xy, yz, zx) {
        (Some(_), None, None, None)
            if mask_xy.is_some() || mask_yz.is_some() || mask_zx.is_some() =>
        {
            misplaced(
                "feature_mask_xy/_yz/_zx",
                "xy, yz and zx (with image, send feature_mask)",
            )
        }
        (None, Some(_), Some(_), Some(_)) if mask.is_some() => misplaced(
            "feature_mask",
            "image (with xy, yz and zx, send feature_mask_xy, _yz, _zx)",
        ),
        (Some(one), None, None, None) => Ok(RawPlanes::Single(one, mask)),
        (None, Some(a), Some(b), Some(c)) => {
            Ok(RawPlanes::Triple([a, b, c], [mask_xy, mask_yz, mask_zx]))
        }
        (None, None, None, None) => Err(ApiError::new(
            StatusCode::BAD_REQUEST,
            "missing_exemplar",
            "no exemplar: send fields xy, yz and zx, or one field image",
        )),
        _ => Err(ApiError::new(
            StatusCode::BAD_REQUEST,
            "missing_exemplar",
            "send either all of xy, yz and zx, or one field image",
        )),
    }
}

/// Decodes one uploaded image; a photo larger than the exemplar limit is
/// downscaled, and a note says so.
fn decode_one(name: &str, bytes: &[u8], notes: &mut Vec<String>) -> Result<Exemplar, ApiError> {
    check_not_empty(name, bytes)?;
    let (e, original) = Exemplar::decode_fitting(bytes).map_err(|e| named(name, e))?;
    if let Some((w, h)) = original {
        notes.push(format!(
            "{name}: downscaled from {w}x{h} to {}x{} (exemplars are at most {} pixels per side)",
            e.width(),
            e.height(),
            solidtex_core::Exemplar::MAX_SIDE
        ));
    }
    Ok(e)
}

/// Decodes one uploaded image and its feature mask, if one was sent (the
/// mask is downscaled like the image, then split at half brightness).
fn decode_masked(
    name: &str,
    bytes: &[u8],
    mask: Option<&[u8]>,
    notes: &mut Vec<String>,
) -> Result<Exemplar, ApiError> {
    let e = decode_one(name, bytes, notes)?;
    let Some(mask) = mask else { return Ok(e) };
    let field = mask_field(name);
    let image = decode_one(&field, mask, &mut Vec::new())?;
    e.with_mask_image(&image).map_err(|e| named(&field, e))
}

fn decode(raw: RawPlanes, params: TextureParams) -> Result<(TextureSpec, Vec<String>), ApiError> {
    let mut notes = Vec::new();
    let planes = match raw {
        RawPlanes::Single(b, mask) => {
            Planes::Single(decode_masked("image", &b, mask.as_deref(), &mut notes)?)
        }
        RawPlanes::Triple([a, b, c], [ma, mb, mc]) => {
            let t = [
                decode_masked("xy", &a, ma.as_deref(), &mut notes)?,
                decode_masked("yz", &b, mb.as_deref(), &mut notes)?,
                decode_masked("zx", &c, mc.as_deref(), &mut notes)?,
            ];
            let p = Planes::Triple(Box::new(t));
            p.to_set()?;
            p
        }
    };
    let spec = TextureSpec { planes, params };
    spec.layout()?;
    Ok((spec, notes))
}

/// Largest body of a variant request: room for a sketch field of the
/// most curves and points a field may have, written out in full.
pub const MAX_VARIANT_BYTES: usize = 512 << 10;

/// `POST /v1/textures/{id}/variants`: the texture made of the same
/// exemplars and analysis parameters with the synthesis parameters of the
/// JSON body changed. Its id is a content hash like an upload's, so asking
/// twice finds the same texture, and it shares the source's candidates.
pub(super) async fn variant(
    State(s): State<AppState>,
    TypedPath(TexturePath { id: TextureId(id) }): TypedPath<TexturePath>,
    TypedQuery(NoQuery {}): TypedQuery<NoQuery>,
    req: Request,
) -> Result<Response, ApiError> {
    let source = known(&s, &id).await?;
    let essence = req
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.split(';').next())
        .map(|v| v.trim().to_ascii_lowercase());
    if essence.as_deref() != Some("application/json") {
        return Err(unsupported(
            "a variant is asked for with a JSON object of synthesis parameters \
             (Content-Type: application/json)",
        ));
    }
    let body = read_body(req, MAX_VARIANT_BYTES).await?;
    let text = std::str::from_utf8(&body).map_err(|_| {
        ApiError::new(
            StatusCode::BAD_REQUEST,
            "invalid_params",
            "the body is not UTF-8",
        )
    })?;
    let overrides = params_object(text)?;
    let mut spec = source.spec();
    spec.params = spec.params.with_overrides(&overrides)?;
    // Sharing the candidates needs them computed: a variant of a texture
    // still being precomputed would search for them a second time.
    if let Status::Pending = source.status() {
        return Err(RegistryError::Pending {
            id: source.id.clone(),
            progress: source.progress(),
        }
        .into());
    }
    let submitted = s.registry.submit(None, spec, source.name.clone()).await?;
    let (entry, status) = match submitted {
        Submitted::Known(e) => (e, StatusCode::CREATED),
        Submitted::Pending(e) => (e, StatusCode::ACCEPTED),
    };
    tracing::Span::current().record("texture", entry.id.as_str());
    Ok(created_response(&entry, status, s.brick_size, &[]))
}

/// `GET /v1/textures/{id}/exemplar.png`: the texture's xy exemplar, for a
/// thumbnail beside its slices.
pub(super) async fn exemplar(
    State(s): State<AppState>,
    TypedPath(TexturePath { id: TextureId(id) }): TypedPath<TexturePath>,
    TypedQuery(NoQuery {}): TypedQuery<NoQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let e = known(&s, &id).await?;
    let tag = ETag::new(&e, "exemplar.png");
    if tag.matches(&headers) {
        return Ok(tag.not_modified(IMMUTABLE));
    }
    let xy = e.exemplar_xy().clone();
    let png = tokio::task::spawn_blocking(move || {
        solidtex_core::png::encode(xy.width(), xy.height(), &xy.to_rgb_bytes())
    })
    .await
    .map_err(|e| ApiError::internal(e.to_string()))?
    .map_err(|e| ApiError::internal(e.to_string()))?;
    Ok(tag.stamp(body(png, "image/png"), IMMUTABLE))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_texture_is_written_as_its_json_map_was() {
        let layout = LayoutView {
            coherence: 0.75,
            detected: true,
            grain_degrees: -12.5,
            rotate: [90, 0, 0],
            weights: [1.0, 0.25, 0.25],
        };
        assert!(crate::openapi::keys_in_map_order(&layout));
        let texture = TextureView {
            brick_size: 64,
            created: 1_700_000_000,
            exemplar: ExemplarInfo {
                width: 64,
                height: 64,
                planes: 3,
                feature_masks: 1,
            },
            id: "0123".into(),
            max_lod: Some(3),
            name: Some("marble.png".into()),
            notes: vec!["downscaled".into()],
            orientation: Some(layout),
            params: Map::from_iter([("seed".to_string(), Value::from(7))]),
            precompute_estimated_bytes: 1 << 20,
            precompute_peak_bytes: Some(1 << 19),
            precompute_seconds: Some(1.5),
            progress: f64::from(0.3f32),
            reason: Some("why".into()),
            stage: "done",
            status: TextureStatus::Failed,
        };
        assert!(crate::openapi::keys_in_map_order(&texture));
        assert!(crate::openapi::keys_in_map_order(&TextureList {
            regions: vec![json!({"id": "region-0"})],
            textures: vec![texture]
        }));
    }

    #[test]
    fn display_names_are_a_printable_file_name_of_bounded_length() {
        assert_eq!(
            display_name("../dir\\sub/leaf.png").as_deref(),
            Some("leaf.png")
        );
        assert_eq!(display_name(" a\u{1}b\n.jpg ").as_deref(), Some("ab.jpg"));
        assert_eq!(display_name("dir/"), None);
        assert_eq!(display_name("\u{7}"), None);
        let at = "x".repeat(MAX_NAME_CHARS);
        assert_eq!(display_name(&at).as_deref(), Some(at.as_str()));
        let past = "é".repeat(MAX_NAME_CHARS + 1);
        assert_eq!(display_name(&past).unwrap().chars().count(), MAX_NAME_CHARS);
    }
}
