//! The one pipeline every voxel route ends in: a route parses its path and
//! query into a core [`Request`] and names an [`Encoding`]; [`answer`]
//! budgets it, predicts its synthesis, answers `If-None-Match` from a
//! strong [`ETag`] without synthesizing, and otherwise renders and encodes
//! it on the job queue.
//!
//! A bad request never takes a job slot: everything that can be checked is
//! checked before queueing. An answer depends only on (texture, request,
//! encoding), so it is marked immutable.

use super::{AppState, IMMUTABLE};
use crate::error::ApiError;
use crate::registry::Entry;
use crate::spec::{hex, valid_id};
use axum::body::Body;
use axum::http::{HeaderMap, HeaderName, HeaderValue, StatusCode, header};
use axum::response::Response;
use sha2::{Digest, Sha256};
use solidtex_core::{Request, RequestKind, SynthStats, Texture, WorkEstimate, png};
use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;

/// The texture `id` ready to synthesize. One still being precomputed is
/// waited for up to the server's `--pending-wait` before the request is
/// answered 409, so that a first request right after an upload (or after
/// start, for the bundled texture) gets its voxels. A region texture is
/// its two textures, each ready. The span records its id.
pub(super) async fn texture(s: &AppState, id: &str) -> Result<(Arc<Entry>, Texture), ApiError> {
    if !valid_id(id) {
        return Err(ApiError::unknown_texture(id));
    }
    tracing::Span::current().record("texture", id);
    resolve(s, id.to_string(), 0).await
}

/// A texture ready to synthesize, with its entry.
type Ready = Result<(Arc<Entry>, Texture), ApiError>;

/// [`texture`], a region texture's own textures in turn (`depth` region
/// textures above).
fn resolve(
    s: &AppState,
    id: String,
    depth: usize,
) -> Pin<Box<dyn Future<Output = Ready> + Send + '_>> {
    Box::pin(async move {
        if let Some(r) = super::textures::region(s, &id).await? {
            if depth >= solidtex_core::region::MAX_DEPTH {
                return Err(ApiError::internal(format!(
                    "region texture `{id}` nests deeper than {}",
                    solidtex_core::region::MAX_DEPTH
                )));
            }
            let (oe, outer) = resolve(s, r.def.outer.clone(), depth + 1).await?;
            let (ie, inner) = resolve(s, r.def.inner.clone(), depth + 1).await?;
            let tex = Texture::with_region(outer, inner, r.def.split())?;
            let hash = r.def.content_hash(&oe.content_hash, &ie.content_hash);
            return Ok((Arc::new(oe.standing_for(id, hash, tex.clone())), tex));
        }
        // With a shared store, a texture another replica stored is taken up.
        let found = s.registry.find(&id).await?;
        if !s.pending_wait.is_zero()
            && let Some(e) = found
        {
            e.settle(tokio::time::Instant::now() + s.pending_wait).await;
        }
        Ok(s.registry.loaded(&id).await?)
    })
}

/// How a rendered request is sent.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Encoding {
    /// A PNG of an image request (slice, cut).
    Png,
    /// RGB8 as rendered, its shape in `X-Solidtex-*` headers (region, brick).
    Raw,
    /// RGB8 as rendered: a box is C order over (z, y, x, c) (a Zarr chunk).
    Chunk,
    /// One plane per channel, each x fastest (a precomputed chunk).
    Planar,
    /// [`Encoding::Chunk`] compressed with zstd (the Zarr array's codec).
    ChunkZstd,
    /// [`Encoding::Planar`] gzipped, sent as `Content-Encoding: gzip`.
    PlanarGzip,
    /// A bake's textured mesh as a glTF binary.
    Glb,
}

impl Encoding {
    fn content_type(self) -> &'static str {
        match self {
            Encoding::Png => "image/png",
            Encoding::Glb => "model/gltf-binary",
            Encoding::Raw
            | Encoding::Chunk
            | Encoding::Planar
            | Encoding::ChunkZstd
            | Encoding::PlanarGzip => "application/octet-stream",
        }
    }

    /// What the ETag adds to the request's key: the bytes differ from
    /// what the request's own kind is sent as when planar or compressed.
    fn tag(self) -> &'static str {
        match self {
            Encoding::Planar => "planar/",
            Encoding::ChunkZstd => "zstd/",
            Encoding::PlanarGzip => "planar/gzip/",
            Encoding::Png | Encoding::Raw | Encoding::Chunk | Encoding::Glb => "",
        }
    }

    fn encode(self, request: &Request, rgb: Vec<u8>) -> Result<Vec<u8>, ApiError> {
        match self {
            Encoding::Png => {
                let [w, h, _] = request.size();
                png::encode(w, h, &rgb)
                    .map_err(|e| ApiError::internal(format!("PNG encoding failed: {e}")))
            }
            Encoding::Raw | Encoding::Chunk => Ok(rgb),
            Encoding::Planar => Ok(planar(&rgb)),
            Encoding::ChunkZstd => zstd_chunk(&rgb),
            Encoding::PlanarGzip => gzip_chunk(&planar(&rgb)),
            Encoding::Glb => match request.kind() {
                RequestKind::Bake(b) => Ok(b.glb(&rgb)?),
                _ => Err(ApiError::internal("only a bake is sent as glTF")),
            },
        }
    }

    /// The `Content-Encoding` its bytes are sent with, if any.
    fn content_encoding(self) -> Option<&'static str> {
        (self == Encoding::PlanarGzip).then_some("gzip")
    }
}

/// Reorders interleaved RGB8 (channel fastest) into planes (channel
/// slowest), as precomputed `raw` chunks are laid out.
fn planar(rgb: &[u8]) -> Vec<u8> {
    let n = rgb.len() / 3;
    let mut out = vec![0u8; rgb.len()];
    for (i, px) in rgb.chunks_exact(3).enumerate() {
        out[i] = px[0];
        out[n + i] = px[1];
        out[2 * n + i] = px[2];
    }
    out
}

/// zstd level of Zarr chunks (BENCHMARKS.md compares levels).
pub(super) const ZSTD_LEVEL: i32 = 3;

/// gzip level of precomputed chunks (BENCHMARKS.md compares levels).
const GZIP_LEVEL: u32 = 6;

/// A chunk's bytes compressed with zstd at [`ZSTD_LEVEL`].
fn zstd_chunk(bytes: &[u8]) -> Result<Vec<u8>, ApiError> {
    zstd::bulk::compress(bytes, ZSTD_LEVEL)
        .map_err(|e| ApiError::internal(format!("zstd compression failed: {e}")))
}

/// A chunk's bytes gzipped at [`GZIP_LEVEL`].
fn gzip_chunk(bytes: &[u8]) -> Result<Vec<u8>, ApiError> {
    use std::io::Write;
    let mut enc = flate2::write::GzEncoder::new(
        Vec::with_capacity(bytes.len() / 2),
        flate2::Compression::new(GZIP_LEVEL),
    );
    enc.write_all(bytes)
        .and_then(|_| enc.finish())
        .map_err(|e| ApiError::internal(format!("gzip compression failed: {e}")))
}

/// Whether `Accept-Encoding` accepts gzip (a `gzip` or `*` coding whose
/// quality is not 0).
pub(super) fn accepts_gzip(headers: &HeaderMap) -> bool {
    headers
        .get_all(header::ACCEPT_ENCODING)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|coding| {
            let mut parts = coding.split(';');
            let name = parts.next().unwrap_or("").trim();
            let refused = parts.any(|p| {
                p.trim()
                    .strip_prefix("q=")
                    .and_then(|q| q.trim().parse::<f64>().ok())
                    .is_some_and(|q| q == 0.0)
            });
            (name.eq_ignore_ascii_case("gzip") || name == "*") && !refused
        })
}

/// A strong validator: the texture's content, the engine version and the
/// key of what is sent.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) struct ETag(String);

impl ETag {
    /// The validator of the answer keyed `key` of the texture `entry`.
    pub(super) fn new(entry: &Entry, key: &str) -> ETag {
        let mut h = Sha256::new();
        h.update(b"solidtex etag v1\0");
        h.update(env!("CARGO_PKG_VERSION").as_bytes());
        h.update(b"\0");
        h.update(entry.content_hash.as_bytes());
        h.update(b"\0");
        h.update(key.as_bytes());
        ETag(format!("\"{}\"", hex(&h.finalize()[..16])))
    }

    /// True when `If-None-Match` lists this tag (weak comparison) or `*`.
    pub(super) fn matches(&self, headers: &HeaderMap) -> bool {
        headers
            .get_all(header::IF_NONE_MATCH)
            .iter()
            .filter_map(|v| v.to_str().ok())
            .flat_map(|v| v.split(','))
            .map(|t| t.trim())
            .any(|t| t == "*" || t.strip_prefix("W/").unwrap_or(t) == self.0)
    }

    /// 304: the client holds the answer.
    pub(super) fn not_modified(&self, cache_control: &'static str) -> Response {
        let mut res = Response::new(Body::empty());
        *res.status_mut() = StatusCode::NOT_MODIFIED;
        self.stamp(res, cache_control)
    }

    /// `res` with this tag and `cache_control`.
    pub(super) fn stamp(&self, mut res: Response, cache_control: &'static str) -> Response {
        let h = res.headers_mut();
        if let Ok(v) = HeaderValue::from_str(&self.0) {
            h.insert(header::ETAG, v);
        }
        h.insert(
            header::CACHE_CONTROL,
            HeaderValue::from_static(cache_control),
        );
        res
    }
}

/// A body with its content type.
pub(super) fn body(bytes: Vec<u8>, content_type: &'static str) -> Response {
    let mut res = Response::new(Body::from(bytes));
    res.headers_mut()
        .insert(header::CONTENT_TYPE, HeaderValue::from_static(content_type));
    res
}

/// What a request costs against the server's per-request budget
/// (`--max-request-voxels`): its voxels or pixels, and for a cut its
/// pixels times how far apart each pixel's neighbours sample.
fn budget_cost(request: &Request) -> u64 {
    match request.kind() {
        RequestKind::Cut(c) => {
            let spread = |a: [f64; 3]| {
                (a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
                    .sqrt()
                    .clamp(1.0, 8.0)
            };
            let (u, v) = (c.plane.u, c.plane.v);
            (request.voxels() as f64 * spread(u) * spread(v)).ceil() as u64
        }
        _ => request.voxels(),
    }
}

fn kind_name(request: &Request) -> &'static str {
    match request.kind() {
        RequestKind::Region(_) => "region",
        RequestKind::Slice(_) => "slice",
        RequestKind::Cut(_) => "cut",
        RequestKind::Points(_) => "points",
        RequestKind::Bake(_) => "bake",
    }
}

/// Refuses a request over the server's budget per request.
fn check_budget(s: &AppState, request: &Request) -> Result<(), ApiError> {
    let voxels = budget_cost(request);
    if voxels > s.max_request_voxels {
        return Err(ApiError::too_large(format!(
            "{} costs {voxels} voxels; this server's budget per request is {}",
            kind_name(request),
            s.max_request_voxels
        )));
    }
    Ok(())
}

/// Refuses before any work a request predicted to synthesize more than the
/// budget. The prediction bounds a cold-cache synthesis from above, so a
/// request is refused or admitted the same whatever the cache holds; the
/// job's own count stays as a backstop.
fn check_work(
    s: &AppState,
    predicted: solidtex_core::Result<WorkEstimate>,
    request: &Request,
) -> Result<u64, ApiError> {
    let e = predicted?;
    let budget = work_budget(s, request);
    if e.complete && e.total <= budget {
        return Ok(e.total);
    }
    s.metrics.over_budget("predicted");
    let (flag, advice) = match request.kind() {
        RequestKind::Bake(_) => (
            "--max-export-work",
            "ask for a lower resolution, a smaller texture or vertex colours",
        ),
        _ => (
            "--max-request-work",
            "ask for fewer pixels, pixels closer together or a smaller box",
        ),
    };
    Err(ApiError::predicted_over_budget(
        e.total, e.complete, budget, flag, advice,
    ))
}

/// Most voxels `request` may synthesize: a bake, the size of an export
/// (`--max-export-work`), anything else an interactive request's.
fn work_budget(s: &AppState, request: &Request) -> u64 {
    match request.kind() {
        RequestKind::Bake(_) => s.max_export_work,
        _ => s.max_request_work,
    }
}

/// Records what a synthesis cost in the span and the metrics.
fn account(s: &AppState, stats: &SynthStats) {
    s.metrics.observe_synthesis(stats);
    let span = tracing::Span::current();
    span.record("voxels", stats.voxels_per_level.iter().sum::<u64>());
    span.record("tiles_computed", stats.tiles_computed);
    span.record("tiles_cached", stats.tiles_from_cache);
}

/// Checks `request` at level of detail `lod` against the budgets before
/// any work; returns its predicted synthesis (voxels, an upper bound).
pub(super) fn admit(
    s: &AppState,
    tex: &Texture,
    request: &Request,
    lod: u32,
) -> Result<u64, ApiError> {
    check_budget(s, request)?;
    let budget = work_budget(s, request);
    check_work(s, tex.estimate(request, lod, budget), request)
}

/// Answers `request` at level of detail `lod` of the texture `(entry,
/// tex)`, sent as `encoding`.
pub(super) async fn answer(
    s: &AppState,
    (entry, tex): (Arc<Entry>, Texture),
    request: Request,
    lod: u32,
    encoding: Encoding,
    headers: &HeaderMap,
) -> Result<Response, ApiError> {
    admit(s, &tex, &request, lod)?;
    let budget = work_budget(s, &request);
    let key = format!("{}{}", encoding.tag(), request.key(lod));
    let tag = ETag::new(&entry, &key);
    let mut res = if tag.matches(headers) {
        tag.not_modified(IMMUTABLE)
    } else {
        let req = request.clone();
        let job = move || -> Result<_, ApiError> {
            let (rgb, stats) = tex.render(&req, lod)?;
            Ok((encoding.encode(&req, rgb)?, stats))
        };
        let (bytes, stats) = match request.kind() {
            RequestKind::Bake(_) => s.jobs.run_within(Some(budget), job).await??,
            _ => s.jobs.run(job).await??,
        };
        account(s, &stats);
        let mut res = body(bytes, encoding.content_type());
        if let Some(coding) = encoding.content_encoding() {
            res.headers_mut()
                .insert(header::CONTENT_ENCODING, HeaderValue::from_static(coding));
        }
        tag.stamp(res, IMMUTABLE)
    };
    if let (Encoding::Raw, RequestKind::Region(r)) = (encoding, request.kind()) {
        shape_headers(&mut res, r.origin, r.size, lod);
    }
    Ok(res)
}

/// The shape of a raw box, for clients that read the bytes alone.
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn if_none_match_forms() {
        let tag = ETag("\"abc\"".into());
        let mut h = HeaderMap::new();
        assert!(!tag.matches(&h));
        h.insert(
            header::IF_NONE_MATCH,
            HeaderValue::from_static("\"x\", W/\"abc\""),
        );
        assert!(tag.matches(&h));
        h.insert(header::IF_NONE_MATCH, HeaderValue::from_static("*"));
        assert!(tag.matches(&h));
        h.insert(header::IF_NONE_MATCH, HeaderValue::from_static("\"abcd\""));
        assert!(!tag.matches(&h));
    }

    #[test]
    fn gzip_is_sent_to_clients_that_accept_it() {
        let h = |v: &str| {
            let mut m = HeaderMap::new();
            m.insert(header::ACCEPT_ENCODING, HeaderValue::from_str(v).unwrap());
            m
        };
        for (v, ok) in [
            ("gzip", true),
            ("deflate, gzip;q=0.5", true),
            ("GZIP", true),
            ("*", true),
            ("gzip;q=0", false),
            ("br, deflate", false),
            ("", false),
        ] {
            assert_eq!(accepts_gzip(&h(v)), ok, "{v}");
        }
        assert!(!accepts_gzip(&HeaderMap::new()));
    }

    #[test]
    fn compressed_chunks_decompress_to_the_voxels() {
        use std::io::Read;
        let rgb: Vec<u8> = (0..16 * 16 * 16 * 3).map(|i| (i / 7 % 251) as u8).collect();
        assert_eq!(
            zstd::bulk::decompress(&zstd_chunk(&rgb).unwrap(), rgb.len()).unwrap(),
            rgb
        );
        let mut out = Vec::new();
        flate2::read::GzDecoder::new(&gzip_chunk(&rgb).unwrap()[..])
            .read_to_end(&mut out)
            .unwrap();
        assert_eq!(out, rgb);
    }

    #[test]
    fn planar_puts_channels_last() {
        assert_eq!(planar(&[1, 2, 3, 4, 5, 6]), vec![1, 4, 2, 5, 3, 6]);
    }
}
