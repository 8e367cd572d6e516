//! The Neuroglancer precomputed and Zarr v3 views: their metadata, and
//! chunks that hold exactly the voxels of the same box read through
//! `region.raw`, in each format's layout. (The real clients read them in
//! `tests/clients/`.)

mod common;
mod server_support;

use serde_json::Value;
use server_support::*;

async fn json(c: &reqwest::Client, url: &str) -> Value {
    let (status, headers, body) = get(c, url).await;
    assert_eq!(status, 200, "{url}: {}", String::from_utf8_lossy(&body));
    assert_eq!(headers["content-type"], "application/json");
    assert_eq!(headers["cache-control"], "no-cache");
    assert!(headers.contains_key("etag"));
    serde_json::from_slice(&body).unwrap()
}

async fn region(
    c: &reqwest::Client,
    s: &TestServer,
    id: &str,
    o: [i64; 3],
    e: u32,
    lod: u32,
) -> Vec<u8> {
    let url = s.url(&format!(
        "/v1/textures/{id}/region.raw?x={}&y={}&z={}&w={e}&h={e}&d={e}&lod={lod}",
        o[0], o[1], o[2]
    ));
    let (status, _, body) = get(c, &url).await;
    assert_eq!(status, 200);
    body
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn metadata_describes_a_centred_window_per_level() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.chunk_size = 16;
    let s = TestServer::start(args).await;
    let c = client();
    let id = ready_texture(&c, &s, 3).await;
    let max_lod = get_json(&c, &s, &format!("/v1/textures/{id}")).await["max_lod"]
        .as_u64()
        .unwrap();

    let info = json(&c, &s.url(&format!("/v1/textures/{id}/precomputed/info"))).await;
    assert_eq!(info["@type"], "neuroglancer_multiscale_volume");
    assert_eq!(info["type"], "image");
    assert_eq!(info["data_type"], "uint8");
    assert_eq!(info["num_channels"], 3);
    let scales = info["scales"].as_array().unwrap();
    assert_eq!(scales.len() as u64, max_lod + 1);
    for (k, sc) in scales.iter().enumerate() {
        let side = 1i64 << (20 - k);
        assert_eq!(sc["key"], k.to_string());
        assert_eq!(sc["encoding"], "raw");
        assert_eq!(sc["size"], serde_json::json!([side, side, side]));
        assert_eq!(sc["voxel_offset"][2], -side / 2);
        assert_eq!(sc["resolution"][0], 1 << k);
        assert_eq!(sc["chunk_sizes"], serde_json::json!([[16, 16, 16]]));
    }

    let group = json(&c, &s.url(&format!("/v1/textures/{id}/zarr/zarr.json"))).await;
    assert_eq!(group["zarr_format"], 3);
    assert_eq!(group["node_type"], "group");
    for k in 0..=max_lod {
        let a = json(&c, &s.url(&format!("/v1/textures/{id}/zarr/{k}/zarr.json"))).await;
        let side = 1i64 << (20 - k);
        assert_eq!(a["node_type"], "array");
        assert_eq!(a["shape"], serde_json::json!([3, side, side, side]));
        assert_eq!(
            a["dimension_names"],
            serde_json::json!(["c", "z", "y", "x"])
        );
        let codecs: Vec<&str> = a["codecs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c["name"].as_str().unwrap())
            .collect();
        assert_eq!(codecs, ["transpose", "bytes", "zstd"]);
        assert_eq!(a["chunk_key_encoding"]["name"], "default");
    }
    // The group is an OME-Zarr image: one dataset per level of detail.
    let ms = &group["attributes"]["ome"]["multiscales"][0];
    assert_eq!(group["attributes"]["ome"]["version"], "0.5");
    assert_eq!(ms["datasets"].as_array().unwrap().len() as u64, max_lod + 1);
    assert_eq!(ms["axes"][0]["type"], "channel");

    // Metadata revalidates to 304 with its ETag.
    let url = s.url(&format!("/v1/textures/{id}/zarr/0/zarr.json"));
    let (_, h, _) = get(&c, &url).await;
    let r = c
        .get(&url)
        .header("if-none-match", h["etag"].clone())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 304);

    // A level past max_lod, and the pending/unknown cases, are errors.
    for (path, status, code) in [
        (
            format!("/v1/textures/{id}/zarr/{}/zarr.json", max_lod + 1),
            404,
            "no_chunk",
        ),
        (
            format!("/v1/textures/{id}/precomputed/9/0-16_0-16_0-16"),
            404,
            "no_chunk",
        ),
        (
            "/v1/textures/nope/precomputed/info".to_string(),
            404,
            "unknown_texture",
        ),
        (
            "/v1/textures/nope/zarr/zarr.json".to_string(),
            404,
            "unknown_texture",
        ),
    ] {
        let (st, h, b) = get(&c, &s.url(&path)).await;
        assert_error(st, &h, &b, status, code);
    }
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn chunks_hold_the_region_in_each_layout() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.chunk_size = 16;
    let s = TestServer::start(args).await;
    let c = client();
    let id = ready_texture(&c, &s, 4).await;
    let lod = 1u32;
    let offset = -(1i64 << (19 - lod));
    // Chunk (ix, iy, iz) = (2^(18) / 16 + 1, 3, 8190): x just past the
    // origin, y at the window's low edge, z near the high edge.
    let (ix, iy, iz) = ((1i64 << 18) / 16 + 1, 3i64, (1i64 << 19) / 16 - 2);
    let origin = [offset + ix * 16, offset + iy * 16, offset + iz * 16];
    let want = region(&c, &s, &id, origin, 16, lod).await;
    assert_eq!(want.len(), 16 * 16 * 16 * 3);

    // Zarr: C order over (z, y, x, c) is the region's own layout, what the
    // transpose codec stores, compressed with zstd.
    let url = s.url(&format!("/v1/textures/{id}/zarr/{lod}/c/0/{iz}/{iy}/{ix}"));
    let (status, headers, zarr) = get(&c, &url).await;
    assert_eq!(status, 200);
    assert_eq!(
        headers["cache-control"],
        "public, max-age=31536000, immutable"
    );
    assert_eq!(headers["access-control-allow-origin"], "*");
    assert!(zarr.len() < want.len(), "{} bytes", zarr.len());
    assert_eq!(zstd::bulk::decompress(&zarr, want.len()).unwrap(), want);
    let r = c
        .get(&url)
        .header("if-none-match", headers["etag"].clone())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 304);

    // Precomputed: the same voxels, each channel a plane.
    let name = format!(
        "{}-{}_{}-{}_{}-{}",
        origin[0],
        origin[0] + 16,
        origin[1],
        origin[1] + 16,
        origin[2],
        origin[2] + 16
    );
    // The test client asks for no content coding: raw bytes.
    let pre_url = s.url(&format!("/v1/textures/{id}/precomputed/{lod}/{name}"));
    let (status, headers, pre) = get(&c, &pre_url).await;
    assert_eq!(status, 200);
    assert!(headers.get("content-encoding").is_none());
    assert_eq!(headers["vary"], "accept-encoding");
    assert_eq!(pre.len(), want.len());
    // Gzipped for a client that accepts it, under its own validator.
    let r = c
        .get(&pre_url)
        .header("accept-encoding", "gzip")
        .send()
        .await
        .unwrap();
    assert_eq!(r.headers()["content-encoding"], "gzip");
    assert_ne!(r.headers()["etag"], headers["etag"]);
    let gz = r.bytes().await.unwrap();
    assert!(gz.len() < pre.len(), "{} bytes", gz.len());
    let mut unzipped = Vec::new();
    std::io::Read::read_to_end(&mut flate2::read::GzDecoder::new(&gz[..]), &mut unzipped).unwrap();
    assert_eq!(unzipped, pre);
    let n = 16 * 16 * 16;
    for i in (0..n).step_by(37).chain([0, n - 1]) {
        for ch in 0..3 {
            assert_eq!(pre[ch * n + i], want[i * 3 + ch], "voxel {i} channel {ch}");
        }
    }

    // Chunks off the grid or outside the window name nothing; malformed
    // names and indices are refused before any synthesis.
    let end = (1i64 << 19) / 16;
    for (path, status, code) in [
        (
            format!("/v1/textures/{id}/zarr/{lod}/c/0/0/0/{end}"),
            404,
            "no_chunk",
        ),
        (
            format!("/v1/textures/{id}/zarr/{lod}/c/1/0/0/0"),
            404,
            "no_chunk",
        ),
        (
            format!("/v1/textures/{id}/zarr/{lod}/c/0/0/-1/0"),
            404,
            "no_chunk",
        ),
        (
            format!("/v1/textures/{id}/precomputed/{lod}/1-17_0-16_0-16"),
            404,
            "no_chunk",
        ),
        (
            format!("/v1/textures/{id}/precomputed/{lod}/0-32_0-16_0-16"),
            404,
            "no_chunk",
        ),
        (
            format!("/v1/textures/{id}/precomputed/{lod}/0-16_0-16"),
            400,
            "invalid_parameter",
        ),
        (
            format!("/v1/textures/{id}/precomputed/{lod}/a-b_0-16_0-16"),
            400,
            "invalid_parameter",
        ),
    ] {
        let (st, h, b) = get(&c, &s.url(&path)).await;
        assert_error(st, &h, &b, status, code);
    }
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn viewer_is_served_from_the_binary() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    let c = client();
    let (status, h, page) = get(&c, &s.url("/")).await;
    assert_eq!(status, 200);
    assert!(h["content-type"].to_str().unwrap().starts_with("text/html"));
    let page = String::from_utf8(page).unwrap();
    assert!(page.contains("viewer.js"), "{page}");
    let (status, h, script) = get(&c, &s.url("/viewer.js")).await;
    assert_eq!(status, 200);
    assert!(
        h["content-type"]
            .to_str()
            .unwrap()
            .starts_with("text/javascript")
    );
    assert!(String::from_utf8(script).unwrap().contains("/v1/textures"));
    s.stop().await;
}

/// With `--chunk-compression false` the volume views serve raw chunks, as
/// before compression.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn chunk_compression_can_be_turned_off() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.chunk_compression = false;
    args.chunk_size = 8;
    let s = TestServer::start(args).await;
    let c = client();
    let id = ready_texture(&c, &s, 2).await;
    let meta = get_json(&c, &s, &format!("/v1/textures/{id}/zarr/0/zarr.json")).await;
    let codecs: Vec<&str> = meta["codecs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["name"].as_str().unwrap())
        .collect();
    assert_eq!(codecs, ["transpose", "bytes"]);
    let (st, _, chunk) = get(
        &c,
        &s.url(&format!("/v1/textures/{id}/zarr/0/c/0/65536/65536/65536")),
    )
    .await;
    assert_eq!(st, 200);
    assert_eq!(chunk.len(), 8 * 8 * 8 * 3);
    let r = c
        .get(s.url(&format!("/v1/textures/{id}/precomputed/0/0-8_0-8_0-8")))
        .header("accept-encoding", "gzip")
        .send()
        .await
        .unwrap();
    assert!(r.headers().get("content-encoding").is_none());
    assert_eq!(r.bytes().await.unwrap().len(), 8 * 8 * 8 * 3);
    s.stop().await;
}
