//! The texture as a standard volume: Neuroglancer precomputed and Zarr v3,
//! so that existing viewers and array libraries read it with no adapter.
//!
//! Both formats describe finite arrays, so each level of detail k is
//! presented as a window of 2^(20−k) voxels per side centred on the origin:
//! array index i along an axis is texture coordinate i − 2^(19−k) at that
//! level. The precomputed `voxel_offset` says exactly that, so precomputed
//! clients see the texture's own coordinates; Zarr has no offsets, so Zarr
//! indices are shifted by 2^(19−k) (the group's attributes repeat it).
//!
//! The Zarr hierarchy is an OME-Zarr image (OME-NGFF 0.5 `multiscales`:
//! axes c, z, y, x, one dataset per level of detail with its scale and
//! translation in finest voxels), so that napari and `ome-zarr` open it.
//! Its arrays are (c, z, y, x), channel first as OME-NGFF orders axes; a
//! `transpose` codec stores each chunk as (z, y, x, c), the region's own
//! interleaved bytes.
//!
//! Chunks are compressed unless the server was started with
//! `--chunk-compression false`: Zarr chunks with zstd (declared in the
//! arrays' codecs), precomputed chunks with gzip as HTTP content coding,
//! for clients that send `Accept-Encoding: gzip` (the precomputed format
//! leaves compression to HTTP).
//!
//! Chunks are cubes of the configured edge (a power of two, so they tile
//! every window exactly and there are no partial chunks). Each chunk is a
//! region request: synthesized on the job queue through the shared tile
//! cache, with a strong ETag, 304 on `If-None-Match`, and immutable caching.
//! The metadata documents carry an ETag too but are revalidated
//! (`no-cache`), because they name the server's chunk size.

use super::AppState;
use super::answer::{ETag, Encoding, ZSTD_LEVEL, accepts_gzip, answer, body, texture};
use super::params::{NoQuery, TextureId, TexturePath, TypedPath, TypedQuery};
use crate::error::ApiError;
use crate::registry::Entry;
use axum::extract::State;
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::Response;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};
use solidtex_core::{Region, Request};

/// log2 of the window side at level of detail 0.
pub const WINDOW_LOG2: u32 = 20;

/// The served window of level of detail `lod` along one axis: its side and
/// the texture coordinate of array index 0.
pub fn window(lod: u32) -> (i64, i64) {
    let side = 1i64 << (WINDOW_LOG2 - lod);
    (side, -side / 2)
}

/// `Cache-Control` of the metadata documents.
const REVALIDATE: &str = "no-cache";

/// A JSON metadata document with its ETag, or 304.
fn metadata_response(
    entry: &Entry,
    key: &str,
    headers: &HeaderMap,
    doc: &impl Serialize,
) -> Response {
    let tag = ETag::new(entry, key);
    if tag.matches(headers) {
        return tag.not_modified(REVALIDATE);
    }
    let text = serde_json::to_vec(doc).expect("metadata serialise");
    let json = body(text, "application/json");
    tag.stamp(json, REVALIDATE)
}

/// 404 for a path that is well formed but names no chunk or array.
fn no_chunk(what: impl std::fmt::Display) -> ApiError {
    ApiError::new(StatusCode::NOT_FOUND, "no_chunk", format!("{what}"))
}

/// A level of detail named in a path: a plain decimal up to `max_lod`.
fn path_lod(s: &str, max_lod: u32) -> Result<u32, ApiError> {
    let lod = (!s.is_empty() && s.len() <= 2 && s.bytes().all(|b| b.is_ascii_digit()))
        .then(|| s.parse::<u32>().ok())
        .flatten()
        .filter(|&l| l <= max_lod && l.to_string() == s);
    lod.ok_or_else(|| no_chunk(format_args!("no level of detail `{s}` (0..={max_lod})")))
}

/// The chunk of edge `edge` at `origin` (texture coordinates of its
/// level), as a request.
fn chunk(origin: [i64; 3], edge: u32) -> Result<Request, ApiError> {
    Ok(Request::region(Region {
        origin,
        size: [edge; 3],
    })?)
}

// ---------------------------------------------------------------------
// Neuroglancer precomputed

/// Neuroglancer's precomputed `info`: a multiscale volume. Fields are in
/// alphabetical order, the order its bytes have always had.
#[derive(Debug, Serialize, JsonSchema)]
pub(crate) struct PrecomputedInfo {
    /// `neuroglancer_multiscale_volume`.
    #[serde(rename = "@type")]
    at_type: &'static str,
    /// `uint8`.
    data_type: &'static str,
    /// 3: red, green, blue.
    num_channels: u32,
    /// One scale per level of detail, finest first.
    scales: Vec<PrecomputedScale>,
    /// `image`.
    #[serde(rename = "type")]
    volume_type: &'static str,
}

/// One scale of [`PrecomputedInfo`]: a level of detail's window.
#[derive(Debug, Serialize, JsonSchema)]
pub(crate) struct PrecomputedScale {
    /// The chunk shape, one.
    chunk_sizes: Vec<[u32; 3]>,
    /// `raw`.
    encoding: &'static str,
    /// The level of detail, as the chunks' path names it.
    key: String,
    /// Finest voxels per voxel along x, y and z: 2^lod.
    resolution: [u64; 3],
    /// The window's side in voxels of the level, along x, y and z.
    size: [i64; 3],
    /// The texture coordinate of the window's first voxel.
    voxel_offset: [i64; 3],
}

/// The `info` document: one scale per level of detail, finest first.
fn precomputed_info(max_lod: u32, chunk: u32) -> PrecomputedInfo {
    PrecomputedInfo {
        at_type: "neuroglancer_multiscale_volume",
        data_type: "uint8",
        num_channels: 3,
        scales: (0..=max_lod)
            .map(|lod| {
                let (side, offset) = window(lod);
                let res = 1u64 << lod;
                PrecomputedScale {
                    chunk_sizes: vec![[chunk; 3]],
                    encoding: "raw",
                    key: lod.to_string(),
                    resolution: [res; 3],
                    size: [side; 3],
                    voxel_offset: [offset; 3],
                }
            })
            .collect(),
        volume_type: "image",
    }
}

/// `GET /v1/textures/{id}/precomputed/info`
pub(super) async fn precomputed_info_route(
    State(s): State<AppState>,
    TypedPath(TexturePath { id: TextureId(id) }): TypedPath<TexturePath>,
    TypedQuery(NoQuery {}): TypedQuery<NoQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let (entry, tex) = texture(&s, &id).await?;
    let doc = precomputed_info(tex.max_lod(), s.chunk_size);
    let key = format!("precomputed/info/{}", s.chunk_size);
    Ok(metadata_response(&entry, &key, &headers, &doc))
}

/// Parses one `start-end` bound of a chunk name; `start` may be negative
/// (`-64--32`), so the separator is the first `-` after the first byte.
fn parse_bound(part: &str) -> Option<(i64, i64)> {
    let sep = part.get(1..)?.find('-')? + 1;
    let (a, b) = (&part[..sep], &part[sep + 1..]);
    let ok = |t: &str| {
        let digits = t.strip_prefix('-').unwrap_or(t);
        !digits.is_empty() && digits.len() <= 12 && digits.bytes().all(|c| c.is_ascii_digit())
    };
    if !ok(a) || !ok(b) {
        return None;
    }
    Some((a.parse().ok()?, b.parse().ok()?))
}

/// The lowest corner of the chunk named `x0-x1_y0-y1_z0-z1` in the grid of
/// level `lod`, or why it names none.
fn precomputed_chunk_origin(name: &str, lod: u32, edge: u32) -> Result<[i64; 3], ApiError> {
    let parts: Vec<&str> = name.split('_').collect();
    if parts.len() != 3 {
        return Err(ApiError::invalid_parameter(
            "chunk",
            format_args!("`{name}` is not x0-x1_y0-y1_z0-z1"),
        ));
    }
    let (side, offset) = window(lod);
    let e = i64::from(edge);
    let mut origin = [0i64; 3];
    for (a, part) in parts.iter().enumerate() {
        let (lo, hi) = parse_bound(part).ok_or_else(|| {
            ApiError::invalid_parameter(
                "chunk",
                format_args!("`{part}` is not two integers start-end"),
            )
        })?;
        let inside = lo >= offset && hi <= offset + side;
        if !inside || hi - lo != e || (lo - offset) % e != 0 {
            return Err(no_chunk(format_args!(
                "`{name}` is not a chunk of scale {lod} (edge {edge}, window {offset}..{})",
                offset + side
            )));
        }
        origin[a] = lo;
    }
    Ok(origin)
}

/// The path of a precomputed chunk: `{scale}/{x0}-{x1}_{y0}-{y1}_{z0}-{z1}`.
#[derive(Deserialize)]
pub(super) struct PrecomputedChunkPath {
    id: String,
    scale: String,
    chunk: String,
}

/// `GET /v1/textures/{id}/precomputed/{scale}/{chunk}`: raw chunk, x
/// fastest, then y, then z, then channel.
pub(super) async fn precomputed_chunk(
    State(s): State<AppState>,
    TypedPath(p): TypedPath<PrecomputedChunkPath>,
    TypedQuery(NoQuery {}): TypedQuery<NoQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let t = texture(&s, &p.id).await?;
    let lod = path_lod(&p.scale, t.1.max_lod())?;
    let origin = precomputed_chunk_origin(&p.chunk, lod, s.chunk_size)?;
    let request = chunk(origin, s.chunk_size)?;
    let gzip = s.chunk_compression && accepts_gzip(&headers);
    let encoding = if gzip {
        Encoding::PlanarGzip
    } else {
        Encoding::Planar
    };
    let mut res = answer(&s, t, request, lod, encoding, &headers).await?;
    if s.chunk_compression {
        res.headers_mut()
            .insert(header::VARY, HeaderValue::from_static("accept-encoding"));
    }
    Ok(res)
}

// ---------------------------------------------------------------------
// Zarr v3

/// Where index 0 of the array of `lod` lies, in finest voxels (the
/// centre of its voxel, which stands for the 2^lod-wide cube around it).
fn translation(lod: u32) -> f64 {
    let (_, offset) = window(lod);
    (offset as f64 + 0.5) * f64::from(1u32 << lod) - 0.5
}

/// The root group: an OME-Zarr image (OME-NGFF 0.5 multiscales), and
/// attributes that say how array indices map to texture coordinates.
fn zarr_group(max_lod: u32, chunk: u32) -> Value {
    let levels: Vec<Value> = (0..=max_lod)
        .map(|lod| {
            let (side, offset) = window(lod);
            json!({
                "path": lod.to_string(),
                "lod": lod,
                "voxel_size": 1u64 << lod,
                "shape": [3, side, side, side],
                "origin_zyx": [offset, offset, offset],
            })
        })
        .collect();
    let datasets: Vec<Value> = (0..=max_lod)
        .map(|lod| {
            let s = f64::from(1u32 << lod);
            let t = translation(lod);
            json!({
                "path": lod.to_string(),
                "coordinateTransformations": [
                    {"type": "scale", "scale": [1.0, s, s, s]},
                    {"type": "translation", "translation": [0.0, t, t, t]},
                ],
            })
        })
        .collect();
    let channel = |label: &str, color: &str| {
        json!({
            "label": label,
            "color": color,
            "active": true,
            "coefficient": 1,
            "family": "linear",
            "inverted": false,
            "window": {"min": 0, "max": 255, "start": 0, "end": 255},
        })
    };
    json!({
        "zarr_format": 3,
        "node_type": "group",
        "attributes": {
            "ome": {
                "version": "0.5",
                "multiscales": [{
                    "name": "solidtex",
                    "axes": [
                        {"name": "c", "type": "channel"},
                        {"name": "z", "type": "space"},
                        {"name": "y", "type": "space"},
                        {"name": "x", "type": "space"},
                    ],
                    "datasets": datasets,
                    "type": "gaussian",
                    "metadata": {
                        "description": "each level of detail is synthesized at its own \
                                        pyramid level, from a Gaussian stack of the exemplar",
                    },
                }],
                "omero": {
                    "channels": [
                        channel("red", "FF0000"),
                        channel("green", "00FF00"),
                        channel("blue", "0000FF"),
                    ],
                    "rdefs": {"model": "color", "defaultZ": 1u64 << (WINDOW_LOG2 - 1)},
                },
            },
            "solidtex": {
                "description": "An infinite solid texture shown through a finite window per level of detail: index i along z, y or x of array `lod` is texture coordinate i + origin at that level (voxels 2^lod finest voxels wide); the OME translation is the same place in finest voxels.",
                "axes": ["c", "z", "y", "x"],
                "chunk_size": chunk,
                "levels": levels,
            }
        }
    })
}

/// Zarr v3 metadata of one level of detail's array. Fields are in
/// alphabetical order, the order its bytes have always had.
#[derive(Debug, Serialize, JsonSchema)]
pub(crate) struct ZarrArray {
    /// Where the array lies in the texture (`solidtex`).
    attributes: ZarrArrayAttributes,
    /// `regular` chunks of shape (3, E, E, E).
    chunk_grid: ChunkGrid,
    /// `default` keys, separated by `/`.
    chunk_key_encoding: ChunkKeyEncoding,
    /// `transpose` (stored z, y, x, c), `bytes`, and `zstd` when on.
    codecs: Vec<Codec>,
    /// `uint8`.
    data_type: &'static str,
    /// `c`, `z`, `y`, `x`.
    dimension_names: [&'static str; 4],
    /// 0.
    fill_value: u8,
    /// `array`.
    node_type: &'static str,
    /// (3, side, side, side).
    shape: [i64; 4],
    /// 3.
    zarr_format: u32,
}

/// The chunk grid: its name and configuration.
#[derive(Debug, Serialize, JsonSchema)]
pub(crate) struct ChunkGrid {
    configuration: ChunkShape,
    name: &'static str,
}

/// How chunk keys are made: the encoding's name and configuration.
#[derive(Debug, Serialize, JsonSchema)]
pub(crate) struct ChunkKeyEncoding {
    configuration: KeySeparator,
    name: &'static str,
}

/// A codec: its name and configuration.
#[derive(Debug, Serialize, JsonSchema)]
pub(crate) struct Codec {
    configuration: CodecConfiguration,
    name: &'static str,
}

/// The regular chunk grid's configuration.
#[derive(Debug, Serialize, JsonSchema)]
pub(crate) struct ChunkShape {
    chunk_shape: [u32; 4],
}

/// The default chunk key encoding's configuration.
#[derive(Debug, Serialize, JsonSchema)]
pub(crate) struct KeySeparator {
    separator: &'static str,
}

/// A codec's configuration.
#[derive(Debug, Serialize, JsonSchema)]
#[serde(untagged)]
pub(crate) enum CodecConfiguration {
    /// `transpose`: the order the dimensions are stored in.
    Transpose { order: [u32; 4] },
    /// `bytes`: the byte order.
    Bytes { endian: &'static str },
    /// `zstd`: its level and whether a checksum is kept.
    Zstd { checksum: bool, level: i32 },
}

/// An array's own attributes.
#[derive(Debug, Serialize, JsonSchema)]
pub(crate) struct ZarrArrayAttributes {
    solidtex: ArrayPlacement,
}

/// Where an array lies in the texture.
#[derive(Debug, Serialize, JsonSchema)]
pub(crate) struct ArrayPlacement {
    /// The level of detail.
    lod: u32,
    /// The texture coordinate (z, y, x) of index 0, at that level.
    origin_zyx: [i64; 3],
    /// Finest voxels per voxel: 2^lod.
    voxel_size: u64,
}

/// The array of one level of detail: (c, z, y, x) uint8, regular chunks
/// of all three channels, stored (z, y, x, c) by a transpose codec, and
/// compressed with zstd when `zstd`.
fn zarr_array(lod: u32, chunk: u32, zstd: bool) -> ZarrArray {
    let (side, offset) = window(lod);
    let named = |name, configuration| Codec {
        configuration,
        name,
    };
    let mut codecs = vec![
        named(
            "transpose",
            CodecConfiguration::Transpose {
                order: [1, 2, 3, 0],
            },
        ),
        named("bytes", CodecConfiguration::Bytes { endian: "little" }),
    ];
    if zstd {
        codecs.push(named(
            "zstd",
            CodecConfiguration::Zstd {
                checksum: false,
                level: ZSTD_LEVEL,
            },
        ));
    }
    ZarrArray {
        attributes: ZarrArrayAttributes {
            solidtex: ArrayPlacement {
                lod,
                origin_zyx: [offset; 3],
                voxel_size: 1u64 << lod,
            },
        },
        chunk_grid: ChunkGrid {
            configuration: ChunkShape {
                chunk_shape: [3, chunk, chunk, chunk],
            },
            name: "regular",
        },
        chunk_key_encoding: ChunkKeyEncoding {
            configuration: KeySeparator { separator: "/" },
            name: "default",
        },
        codecs,
        data_type: "uint8",
        dimension_names: ["c", "z", "y", "x"],
        fill_value: 0,
        node_type: "array",
        shape: [3, side, side, side],
        zarr_format: 3,
    }
}

/// `GET /v1/textures/{id}/zarr/zarr.json`
pub(super) async fn zarr_group_route(
    State(s): State<AppState>,
    TypedPath(TexturePath { id: TextureId(id) }): TypedPath<TexturePath>,
    TypedQuery(NoQuery {}): TypedQuery<NoQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let (entry, tex) = texture(&s, &id).await?;
    let doc = zarr_group(tex.max_lod(), s.chunk_size);
    let key = format!("zarr/ome-group/{}", s.chunk_size);
    Ok(metadata_response(&entry, &key, &headers, &doc))
}

/// The path of a Zarr array's metadata: `{lod}/zarr.json`.
#[derive(Deserialize)]
pub(super) struct ZarrArrayPath {
    id: String,
    lod: String,
}

/// `GET /v1/textures/{id}/zarr/{lod}/zarr.json`
pub(super) async fn zarr_array_route(
    State(s): State<AppState>,
    TypedPath(ZarrArrayPath { id, lod }): TypedPath<ZarrArrayPath>,
    TypedQuery(NoQuery {}): TypedQuery<NoQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let (entry, tex) = texture(&s, &id).await?;
    let lod = path_lod(&lod, tex.max_lod())?;
    let doc = zarr_array(lod, s.chunk_size, s.chunk_compression);
    let key = format!(
        "zarr/array/{lod}/{}/{}",
        s.chunk_size,
        if s.chunk_compression { "zstd" } else { "raw" }
    );
    Ok(metadata_response(&entry, &key, &headers, &doc))
}

/// A chunk index named in a Zarr key: a plain decimal below `count`.
fn chunk_index(s: &str, count: i64) -> Result<i64, ApiError> {
    let i = (!s.is_empty() && s.len() <= 12 && s.bytes().all(|b| b.is_ascii_digit()))
        .then(|| s.parse::<i64>().ok())
        .flatten()
        .filter(|&i| i < count && i.to_string() == s);
    i.ok_or_else(|| no_chunk(format_args!("no chunk index `{s}` (0..{count})")))
}

/// The path of a Zarr chunk: `{lod}/c/{cc}/{cz}/{cy}/{cx}`.
#[derive(Deserialize)]
pub(super) struct ZarrChunkPath {
    id: String,
    lod: String,
    cc: String,
    cz: String,
    cy: String,
    cx: String,
}

/// `GET /v1/textures/{id}/zarr/{lod}/c/{cc}/{cz}/{cy}/{cx}`: the chunk
/// (all three channels) as C-order bytes of shape (edge, edge, edge, 3),
/// which is how a region is rendered (x fastest, then y, then z, channel
/// interleaved) and what the transpose codec stores; zstd-compressed
/// unless compression is off.
pub(super) async fn zarr_chunk(
    State(s): State<AppState>,
    TypedPath(p): TypedPath<ZarrChunkPath>,
    TypedQuery(NoQuery {}): TypedQuery<NoQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let t = texture(&s, &p.id).await?;
    let lod = path_lod(&p.lod, t.1.max_lod())?;
    let (side, offset) = window(lod);
    let edge = i64::from(s.chunk_size);
    let count = side / edge;
    let [iz, iy, ix] = [&p.cz, &p.cy, &p.cx].map(|c| chunk_index(c, count));
    let (iz, iy, ix) = (iz?, iy?, ix?);
    chunk_index(&p.cc, 1)?;
    let origin = [offset + ix * edge, offset + iy * edge, offset + iz * edge];
    let request = chunk(origin, s.chunk_size)?;
    let encoding = if s.chunk_compression {
        Encoding::ChunkZstd
    } else {
        Encoding::Chunk
    };
    answer(&s, t, request, lod, encoding, &headers).await
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn windows_are_centred_and_nest() {
        assert_eq!(window(0), (1 << 20, -(1 << 19)));
        assert_eq!(window(3), (1 << 17, -(1 << 16)));
        // Every level starts at the same physical place.
        for lod in 0..6 {
            let (_, offset) = window(lod);
            assert_eq!(offset << lod, -(1 << 19));
        }
    }

    #[test]
    fn chunk_bounds_parse_with_negatives() {
        assert_eq!(parse_bound("0-32"), Some((0, 32)));
        assert_eq!(parse_bound("-64--32"), Some((-64, -32)));
        assert_eq!(parse_bound("-32-0"), Some((-32, 0)));
        for bad in ["", "-", "5", "1-", "-1-", "a-b", "1--", "1-2-3", "+1-2"] {
            assert_eq!(parse_bound(bad), None, "{bad}");
        }
    }

    #[test]
    fn chunk_names_must_lie_on_the_grid() {
        assert_eq!(
            precomputed_chunk_origin("0-32_-32-0_64-96", 0, 32).unwrap(),
            [0, -32, 64]
        );
        let first = -(1i64 << 19);
        let name = format!("{first}-{}_0-32_0-32", first + 32);
        assert_eq!(
            precomputed_chunk_origin(&name, 0, 32).unwrap(),
            [first, 0, 0]
        );
        for bad in [
            "1-33_0-32_0-32",
            "0-64_0-32_0-32",
            "0-32_0-32",
            "0-32_0-32_0-32_0-32",
            "x_y_z",
        ] {
            assert!(precomputed_chunk_origin(bad, 0, 32).is_err(), "{bad}");
        }
        // Outside the window of a coarser level.
        let edge = (1i64 << 18) - 32;
        let name = format!("{edge}-{}_0-32_0-32", edge + 32);
        assert!(precomputed_chunk_origin(&name, 0, 32).is_ok());
        assert!(precomputed_chunk_origin(&name, 2, 32).is_err());
    }

    #[test]
    fn lod_and_index_paths() {
        assert_eq!(path_lod("2", 3).unwrap(), 2);
        for bad in ["4", "", "-1", "+1", "01x", "999", "00", "01"] {
            assert!(path_lod(bad, 3).is_err(), "{bad}");
        }
        assert_eq!(chunk_index("5", 6).unwrap(), 5);
        assert!(chunk_index("6", 6).is_err());
        assert!(chunk_index("-1", 6).is_err());
        assert!(chunk_index("05", 6).is_err());
    }

    /// The typed documents write the very bytes the `json!` maps they
    /// replaced wrote.
    #[test]
    fn typed_documents_keep_their_bytes() {
        let (side, offset) = window(1);
        let scale = |lod: u32| {
            let (side, offset) = window(lod);
            let res = 1u64 << lod;
            json!({
                "key": lod.to_string(),
                "size": [side, side, side],
                "voxel_offset": [offset, offset, offset],
                "resolution": [res, res, res],
                "chunk_sizes": [[32, 32, 32]],
                "encoding": "raw",
            })
        };
        let info = json!({
            "@type": "neuroglancer_multiscale_volume",
            "type": "image",
            "data_type": "uint8",
            "num_channels": 3,
            "scales": [scale(0), scale(1), scale(2)],
        });
        fn text(v: &impl serde::Serialize) -> String {
            serde_json::to_string(v).unwrap()
        }
        assert_eq!(text(&precomputed_info(2, 32)), info.to_string());
        for zstd in [false, true] {
            let mut codecs = vec![
                json!({ "name": "transpose", "configuration": { "order": [1, 2, 3, 0] } }),
                json!({ "name": "bytes", "configuration": { "endian": "little" } }),
            ];
            if zstd {
                codecs.push(json!({
                    "name": "zstd",
                    "configuration": { "level": ZSTD_LEVEL, "checksum": false }
                }));
            }
            let array = json!({
                "zarr_format": 3,
                "node_type": "array",
                "shape": [3, side, side, side],
                "data_type": "uint8",
                "chunk_grid": {
                    "name": "regular",
                    "configuration": { "chunk_shape": [3, 16, 16, 16] }
                },
                "chunk_key_encoding": {
                    "name": "default",
                    "configuration": { "separator": "/" }
                },
                "fill_value": 0,
                "codecs": codecs,
                "dimension_names": ["c", "z", "y", "x"],
                "attributes": {
                    "solidtex": {
                        "lod": 1,
                        "voxel_size": 2,
                        "origin_zyx": [offset, offset, offset],
                    }
                }
            });
            assert_eq!(text(&zarr_array(1, 16, zstd)), array.to_string());
        }
    }

    #[test]
    fn documents_describe_every_level() {
        let info = serde_json::to_value(precomputed_info(2, 32)).unwrap();
        assert_eq!(info["scales"].as_array().unwrap().len(), 3);
        assert_eq!(info["scales"][2]["resolution"], json!([4, 4, 4]));
        assert_eq!(info["scales"][2]["voxel_offset"][0], -(1i64 << 17));
        let a = serde_json::to_value(zarr_array(1, 16, true)).unwrap();
        assert_eq!(a["shape"], json!([3, 1 << 19, 1 << 19, 1 << 19]));
        assert_eq!(a["chunk_grid"]["configuration"]["chunk_shape"][1], 16);
        assert_eq!(a["codecs"][2]["name"], "zstd");
        assert_eq!(
            serde_json::to_value(zarr_array(1, 16, false)).unwrap()["codecs"]
                .as_array()
                .unwrap()
                .len(),
            2
        );
        let g = zarr_group(2, 16);
        assert_eq!(g["attributes"]["solidtex"]["levels"][2]["path"], "2");
        let ms = &g["attributes"]["ome"]["multiscales"][0];
        assert_eq!(ms["datasets"].as_array().unwrap().len(), 3);
        // Index 0 of every level is the same place: the window's corner.
        for lod in 0..3 {
            let t = ms["datasets"][lod]["coordinateTransformations"][1]["translation"][1]
                .as_f64()
                .unwrap();
            let s = ms["datasets"][lod]["coordinateTransformations"][0]["scale"][1]
                .as_f64()
                .unwrap();
            assert_eq!(t - (s - 1.0) / 2.0, -((1u64 << 19) as f64), "lod {lod}");
        }
    }
}
