//! The HTTP API against a real server on a loopback port: every route,
//! every error class, ETag/304, CORS, idempotent uploads and overload.

mod common;
mod server_support;

use serde_json::Value;
use server_support::*;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn operations_endpoints() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    let c = client();

    let (st, h, b) = get(&c, &s.url("/healthz")).await;
    assert_eq!(st, 200);
    assert_eq!(h["content-type"], "application/json");
    assert_eq!(serde_json::from_slice::<Value>(&b).unwrap()["status"], "ok");

    let (st, _, b) = get(&c, &s.url("/readyz")).await;
    assert_eq!(st, 200);
    assert_eq!(
        serde_json::from_slice::<Value>(&b).unwrap()["status"],
        "ready"
    );

    let (st, h, b) = get(&c, &s.url("/openapi.yaml")).await;
    assert_eq!(st, 200);
    assert!(
        h["content-type"]
            .to_str()
            .unwrap()
            .starts_with("application/yaml")
    );
    assert!(String::from_utf8(b).unwrap().starts_with("openapi: 3."));

    let (st, _, b) = get(&c, &s.url("/v1/textures")).await;
    assert_eq!(st, 200);
    assert_eq!(
        serde_json::from_slice::<Value>(&b).unwrap()["textures"],
        serde_json::json!([])
    );

    let text = metrics(&c, &s).await;
    assert!(
        text.contains("# TYPE solidtex_http_requests counter"),
        "{text}"
    );
    assert_eq!(
        metric(
            &text,
            r#"solidtex_http_requests_total{route="/healthz",method="GET",status="200"}"#
        ),
        1.0
    );
    for name in [
        "solidtex_cache_hits_total",
        "solidtex_cache_misses_total",
        "solidtex_cache_bytes",
        "solidtex_cache_evictions_total",
        "solidtex_jobs_queued",
        "solidtex_jobs_running",
        "solidtex_http_request_duration_seconds_bucket",
        "solidtex_precompute_duration_seconds_count",
    ] {
        assert!(text.contains(name), "missing {name}");
    }
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn upload_is_idempotent_and_voxel_routes_agree() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    let c = client();

    // First upload: accepted, computing.
    let png = exemplar_png(32, 1);
    let r = c
        .post(s.url(&format!("/v1/textures?{SMALL_PARAMS}")))
        .header("content-type", "image/png")
        .body(png.clone())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 202);
    assert!(r.headers().contains_key("retry-after"));
    let location = r.headers()["location"].to_str().unwrap().to_string();
    let v: Value = r.json().await.unwrap();
    let id = v["id"].as_str().unwrap().to_string();
    assert_eq!(id.len(), 32);
    assert_eq!(location, format!("/v1/textures/{id}"));
    assert_eq!(v["status"], "pending");
    assert_eq!(v["params"]["levels"], 3);
    assert_eq!(
        v["exemplar"],
        serde_json::json!({"width": 32, "height": 32, "planes": 1})
    );

    let ready = wait_ready(&c, &s, &id).await;
    assert_eq!(ready["progress"], 1.0);
    assert_eq!(ready["brick_size"], 16);
    let max_lod = ready["max_lod"].as_u64().unwrap();
    assert_eq!(max_lod, 2);
    // The server's bound on its memory: the cache at its bound, the
    // candidates it holds, every job slot at its most.
    let bound = |text: &str, part: &str| {
        metric(
            text,
            &format!(r#"solidtex_memory_bound_bytes{{part="{part}"}}"#),
        )
    };
    let text = metrics(&c, &s).await;
    assert_eq!(bound(&text, "cache"), (64u64 << 20) as f64);
    let candidates = bound(&text, "candidates");
    assert!(candidates > 0.0, "{text}");
    let job = solidtex_server::memory::JOB_WORKING_BYTES
        + solidtex_server::memory::JOB_BYTES_PER_VOXEL * (4 << 20);
    assert_eq!(bound(&text, "jobs"), (4 * job) as f64);
    assert_eq!(bound(&text, "precomputes"), 0.0);

    // Same pixels re-encoded, same params spelled differently: same texture, 201.
    let (_, _, pixels) = decode_png(&png);
    let mut other_encoding = Vec::new();
    {
        use image::ImageEncoder;
        image::codecs::png::PngEncoder::new_with_quality(
            &mut other_encoding,
            image::codecs::png::CompressionType::Best,
            image::codecs::png::FilterType::Paeth,
        )
        .write_image(&pixels, 32, 32, image::ExtendedColorType::Rgb8)
        .unwrap();
    }
    assert_ne!(other_encoding, png);
    let (st, v) = upload(&c, &s, other_encoding, "levels=3&seed=1&scheme=dual-grid").await;
    assert_eq!(st, 201);
    assert_eq!(v["id"], id.as_str());
    assert_eq!(v["status"], "ready");
    // Another seed is another texture.
    let (st, v) = upload(&c, &s, png.clone(), "levels=3&seed=2").await;
    assert_eq!(st, 202);
    assert_ne!(v["id"], id.as_str());
    // …which shares the candidates instead of precomputing them again.
    let other = wait_ready(&c, &s, v["id"].as_str().unwrap()).await;
    assert_eq!(other["params"]["seed"], 2);
    let text = metrics(&c, &s).await;
    assert_eq!(
        metric(&text, r#"solidtex_precomputes_total{outcome="ok"}"#),
        1.0
    );
    assert_eq!(
        metric(&text, r#"solidtex_precomputes_total{outcome="reused"}"#),
        1.0
    );
    // Shared candidates are held, and counted, once.
    assert_eq!(bound(&text, "candidates"), candidates);
    let (_, _, a) = get(
        &c,
        &s.url(&format!("/v1/textures/{id}/slices/z/0.png?w=16&h=16")),
    )
    .await;
    let (_, _, b) = get(
        &c,
        &s.url(&format!(
            "/v1/textures/{}/slices/z/0.png?w=16&h=16",
            other["id"].as_str().unwrap()
        )),
    )
    .await;
    assert_ne!(a, b, "another seed, other voxels");

    let list: Value = get_json(&c, &s, "/v1/textures").await;
    let ids: Vec<&str> = list["textures"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t["id"].as_str().unwrap())
        .collect();
    assert!(ids.contains(&id.as_str()));
    assert_eq!(ids.len(), 2);

    // A region: the reference all other routes are checked against.
    let (x0, y0, z0) = (-5i64, 7i64, 3i64);
    let (w, h, d) = (12u32, 10u32, 6u32);
    let url = s.url(&format!(
        "/v1/textures/{id}/region.raw?x={x0}&y={y0}&z={z0}&w={w}&h={h}&d={d}"
    ));
    let (st, hd, region) = get(&c, &url).await;
    assert_eq!(st, 200);
    assert_eq!(hd["content-type"], "application/octet-stream");
    assert_eq!(hd["x-solidtex-width"], "12");
    assert_eq!(hd["x-solidtex-height"], "10");
    assert_eq!(hd["x-solidtex-depth"], "6");
    assert_eq!(hd["x-solidtex-origin"], "-5,7,3");
    assert_eq!(hd["x-solidtex-lod"], "0");
    assert_eq!(hd["cache-control"], "public, max-age=31536000, immutable");
    assert_eq!(region.len(), (w * h * d * 3) as usize);
    let voxel = |x: i64, y: i64, z: i64| -> [u8; 3] {
        let (i, j, k) = ((x - x0) as usize, (y - y0) as usize, (z - z0) as usize);
        let o = ((k * h as usize + j) * w as usize + i) * 3;
        [region[o], region[o + 1], region[o + 2]]
    };
    let pixel = |rgb: &[u8], width: u32, i: usize, j: usize| -> [u8; 3] {
        let o = (j * width as usize + i) * 3;
        [rgb[o], rgb[o + 1], rgb[o + 2]]
    };

    // Slices: z → (u, v) = (x, y); x → (y, z); y → (z, x).
    let (st, hd, z_png) = get(
        &c,
        &s.url(&format!(
            "/v1/textures/{id}/slices/z/{}.png?u0={x0}&v0={y0}&w={w}&h={h}",
            z0 + 2
        )),
    )
    .await;
    assert_eq!(st, 200);
    assert_eq!(hd["content-type"], "image/png");
    let (pw, ph, z_rgb) = decode_png(&z_png);
    assert_eq!((pw, ph), (w, h));
    for j in 0..h as usize {
        for i in 0..w as usize {
            assert_eq!(
                pixel(&z_rgb, w, i, j),
                voxel(x0 + i as i64, y0 + j as i64, z0 + 2)
            );
        }
    }
    let (st, _, x_png) = get(
        &c,
        &s.url(&format!(
            "/v1/textures/{id}/slices/x/{}.png?u0={y0}&v0={z0}&w={h}&h={d}",
            x0 + 4
        )),
    )
    .await;
    assert_eq!(st, 200);
    let (_, _, x_rgb) = decode_png(&x_png);
    for j in 0..d as usize {
        for i in 0..h as usize {
            assert_eq!(
                pixel(&x_rgb, h, i, j),
                voxel(x0 + 4, y0 + i as i64, z0 + j as i64)
            );
        }
    }
    let (st, _, y_png) = get(
        &c,
        &s.url(&format!(
            "/v1/textures/{id}/slices/y/{}.png?u0={z0}&v0={x0}&w={d}&h={w}",
            y0 + 1
        )),
    )
    .await;
    assert_eq!(st, 200);
    let (_, _, y_rgb) = decode_png(&y_png);
    for j in 0..w as usize {
        for i in 0..d as usize {
            assert_eq!(
                pixel(&y_rgb, d, i, j),
                voxel(x0 + j as i64, y0 + 1, z0 + i as i64)
            );
        }
    }

    // An axis-aligned cut with integer steps is the z slice.
    let (st, _, cut_png) = get(
        &c,
        &s.url(&format!(
            "/v1/textures/{id}/cut.png?origin={x0},{y0},{}&u=1,0,0&v=0,1,0&w={w}&h={h}",
            z0 + 2
        )),
    )
    .await;
    assert_eq!(st, 200);
    assert_eq!(decode_png(&cut_png).2, z_rgb);
    // Without origin, u and v a cut is the xy plane through the origin:
    // the z = 0 slice.
    let (st, _, default_cut) = get(&c, &s.url(&format!("/v1/textures/{id}/cut.png?w=5&h=4"))).await;
    let (st2, _, slice0) = get(
        &c,
        &s.url(&format!("/v1/textures/{id}/slices/z/0.png?w=5&h=4")),
    )
    .await;
    assert_eq!((st, st2), (200, 200));
    assert_eq!(decode_png(&default_cut).2, decode_png(&slice0).2);
    // An oblique trilinear cut has the asked size.
    let (st, _, obl) = get(&c, &s.url(&format!("/v1/textures/{id}/cut.png?origin=0.5,1,2&u=0.7,0.7,0&v=0,0.6,0.8&w=9&h=7&filter=trilinear"))).await;
    assert_eq!(st, 200);
    assert_eq!(decode_png(&obl).0, 9);

    // A brick is the aligned region of edge 16.
    let (st, hd, brick) = get(
        &c,
        &s.url(&format!("/v1/textures/{id}/bricks/0/-1_0_2.raw")),
    )
    .await;
    assert_eq!(st, 200);
    assert_eq!(hd["x-solidtex-origin"], "-16,0,32");
    assert_eq!(brick.len(), 16 * 16 * 16 * 3);
    let (_, _, same) = get(
        &c,
        &s.url(&format!(
            "/v1/textures/{id}/region.raw?x=-16&y=0&z=32&w=16&h=16&d=16"
        )),
    )
    .await;
    assert_eq!(brick, same);

    // Coarser levels of detail.
    for lod in 1..=max_lod {
        let (st, _, b) = get(
            &c,
            &s.url(&format!("/v1/textures/{id}/bricks/{lod}/0_0_0.raw")),
        )
        .await;
        assert_eq!(st, 200);
        assert_eq!(b.len(), 16 * 16 * 16 * 3);
        let (st, _, p) = get(
            &c,
            &s.url(&format!(
                "/v1/textures/{id}/slices/z/0.png?w=8&h=8&lod={lod}"
            )),
        )
        .await;
        assert_eq!(st, 200);
        assert_eq!(decode_png(&p).0, 8);
    }

    // ETag and 304.
    let slice_url = s.url(&format!(
        "/v1/textures/{id}/slices/z/{}.png?u0={x0}&v0={y0}&w={w}&h={h}",
        z0 + 2
    ));
    let (_, h1, b1) = get(&c, &slice_url).await;
    let tag = h1["etag"].to_str().unwrap().to_string();
    assert!(tag.starts_with('"') && tag.ends_with('"') && !tag.starts_with("W/"));
    assert_eq!(b1, z_png, "same request, same bytes");
    let r = c
        .get(&slice_url)
        .header("if-none-match", &tag)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 304);
    assert_eq!(r.headers()["etag"].to_str().unwrap(), tag);
    assert_eq!(
        r.headers()["cache-control"],
        "public, max-age=31536000, immutable"
    );
    assert!(r.bytes().await.unwrap().is_empty());
    let r = c
        .get(&slice_url)
        .header("if-none-match", "\"other\"")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 200);
    let (_, h2, _) = get(
        &c,
        &s.url(&format!(
            "/v1/textures/{id}/slices/z/{}.png?u0={x0}&v0={y0}&w={w}&h={h}",
            z0 + 3
        )),
    )
    .await;
    assert_ne!(h2["etag"], tag.as_str());
    let brick_url = s.url(&format!("/v1/textures/{id}/bricks/0/-1_0_2.raw"));
    let (_, hb, _) = get(&c, &brick_url).await;
    let r = c
        .get(&brick_url)
        .header("if-none-match", hb["etag"].to_str().unwrap())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 304);

    // Metrics saw the synthesis.
    let text = metrics(&c, &s).await;
    assert!(metric(&text, r#"solidtex_synth_voxels_total{level="0"}"#) > 0.0);
    assert!(metric(&text, "solidtex_cache_hits_total") > 0.0);
    assert!(metric(&text, r#"solidtex_precomputes_total{outcome="ok"}"#) >= 1.0);
    assert_eq!(metric(&text, "solidtex_jobs_running"), 0.0);

    // Delete: gone, files gone, second delete 404.
    let r = c
        .delete(s.url(&format!("/v1/textures/{id}")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 204);
    assert!(!dir.path().join("textures").join(&id).exists());
    let (st, hd, b) = get(&c, &s.url(&format!("/v1/textures/{id}"))).await;
    assert_error(st, &hd, &b, 404, "unknown_texture");
    let r = c
        .delete(s.url(&format!("/v1/textures/{id}")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 404);
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_preset_upload_is_the_texture_it_spells_out() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    let c = client();
    let png = exemplar_png(32, 3);
    let (st, preset) = upload(&c, &s, png.clone(), "levels=3&preset=preview").await;
    assert_eq!(st, 202, "{preset}");
    let params = &preset["params"];
    assert_eq!(
        (
            &params["passes"],
            &params["finest_passes"],
            &params["fine_levels"]
        ),
        (&1.into(), &0.into(), &1.into()),
        "{preset}"
    );
    assert!(params.get("preset").is_none(), "{preset}");
    let id = preset["id"].as_str().unwrap().to_string();
    wait_ready(&c, &s, &id).await;
    let spelled = "levels=3&passes=1&finest_passes=0&fine_levels=1";
    let (st, v) = upload(&c, &s, png.clone(), spelled).await;
    assert_eq!((st, v["id"].as_str()), (201, Some(id.as_str())), "{v}");
    // Keys beside the preset win; an unknown preset is a 400.
    let (_, v) = upload(&c, &s, png.clone(), "levels=3&preset=preview&passes=2").await;
    assert_eq!(v["params"]["passes"], 2, "{v}");
    assert_eq!(v["params"]["finest_passes"], 0, "{v}");
    let (st, v) = upload(&c, &s, png, "levels=3&preset=fast").await;
    assert_eq!(st, 400, "{v}");
    assert_eq!(v["error"]["code"], "invalid_params", "{v}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn oriented_exemplars_are_turned_and_say_so() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    let c = client();
    let (st, auto) = upload(&c, &s, grain_png(32, 32), "levels=3").await;
    assert_eq!(st, 202, "{auto}");
    assert_eq!(auto["params"]["orientation"], "auto");
    let o = &auto["orientation"];
    assert_eq!(o["detected"], true, "{auto}");
    assert_eq!(o["rotate"], serde_json::json!([0, 270, 0]), "{auto}");
    assert_eq!(o["weights"], serde_json::json!([1.0, 1.0, 0.25]), "{auto}");
    assert!(o["coherence"].as_f64().unwrap() > 0.6, "{auto}");
    assert!(o["grain_degrees"].as_f64().unwrap().abs() < 15.0, "{auto}");
    let id = auto["id"].as_str().unwrap().to_string();
    let ready = wait_ready(&c, &s, &id).await;
    assert_eq!(ready["orientation"], auto["orientation"]);
    let (st, _, b) = get(
        &c,
        &s.url(&format!("/v1/textures/{id}/slices/x/0.png?w=8&h=8")),
    )
    .await;
    assert_eq!((st, decode_png(&b).0), (200, 8));

    // Asked not to, it leaves the planes as they are: another texture.
    let (_, none) = upload(&c, &s, grain_png(32, 32), "levels=3&orientation=none").await;
    assert_ne!(none["id"], auto["id"]);
    assert_eq!(none["orientation"]["detected"], true, "{none}");
    assert_eq!(none["orientation"]["rotate"], serde_json::json!([0, 0, 0]));
    // An arrangement as JSON text in the query, or as an object in a form.
    let given = r#"{"rotate":[0,270,0],"weights":[1,1,0.5]}"#;
    let (_, q) = upload(
        &c,
        &s,
        grain_png(32, 32),
        &format!("levels=3&orientation={}", urlencode(given)),
    )
    .await;
    assert_eq!(
        q["orientation"]["weights"],
        serde_json::json!([1.0, 1.0, 0.5])
    );
    let form = reqwest::multipart::Form::new()
        .part(
            "image",
            reqwest::multipart::Part::bytes(grain_png(32, 32))
                .file_name("g.png")
                .mime_str("image/png")
                .unwrap(),
        )
        .text(
            "params",
            format!(r#"{{"levels": 3, "orientation": {given}}}"#),
        );
    let (_, f) = upload_form(&c, &s, form).await;
    assert_eq!(f["id"], q["id"], "{f}");
    // Without grain, `auto` changes nothing.
    let (_, plain) = upload(&c, &s, exemplar_png(32, 1), "levels=3").await;
    assert_eq!(plain["orientation"]["detected"], false, "{plain}");
    assert_eq!(
        plain["orientation"]["weights"],
        serde_json::json!([1.0, 1.0, 1.0])
    );

    for (png, query, code) in [
        (
            grain_png(32, 32),
            "orientation=sideways".to_string(),
            "invalid_params",
        ),
        (
            grain_png(32, 32),
            format!("orientation={}", urlencode(r#"{"weights":[1,2,1]}"#)),
            "out_of_range",
        ),
        (
            grain_png(32, 32),
            format!("orientation={}", urlencode(r#"{"rotate":[0,45,0]}"#)),
            "invalid_request",
        ),
        (
            grain_png(32, 16),
            format!("orientation={}", urlencode(r#"{"rotate":[90,0,0]}"#)),
            "invalid_request",
        ),
    ] {
        let (st, v) = upload(&c, &s, png, &query).await;
        assert_eq!(
            (st, v["error"]["code"].as_str()),
            (400, Some(code)),
            "{query}: {v}"
        );
    }
    s.stop().await;
}

/// Percent-encodes a query value.
fn urlencode(s: &str) -> String {
    s.bytes()
        .map(|b| match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'_' | b'.' => (b as char).to_string(),
            _ => format!("%{b:02X}"),
        })
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn multipart_uploads() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    let c = client();
    let part = png_part;

    let form = reqwest::multipart::Form::new()
        .part("xy", part(exemplar_png(32, 1)))
        .part("yz", part(exemplar_png(32, 2)))
        .part("zx", part(exemplar_png(32, 3)))
        .text("params", r#"{"levels": 3, "seed": 5}"#);
    let (status, v) = upload_form(&c, &s, form).await;
    assert_eq!(status, 202);
    assert_eq!(v["exemplar"]["planes"], 3);
    assert_eq!(v["params"]["seed"], 5);
    let id = v["id"].as_str().unwrap().to_string();
    let ready = wait_ready(&c, &s, &id).await;
    assert_eq!(ready["status"], "ready");
    let (st, _, b) = get(
        &c,
        &s.url(&format!("/v1/textures/{id}/slices/y/0.png?w=8&h=8&lod=1")),
    )
    .await;
    assert_eq!(st, 200);
    assert_eq!(decode_png(&b).0, 8);

    // One image in a form is the same texture as the raw PNG upload.
    let form = reqwest::multipart::Form::new()
        .part("image", part(exemplar_png(32, 4)))
        .text("params", r#"{"levels": 3}"#);
    let (status, v) = upload_form(&c, &s, form).await;
    assert_eq!(status, 202);
    let (_, raw) = upload(&c, &s, exemplar_png(32, 4), "levels=3").await;
    assert_eq!(v["id"], raw["id"]);

    // Form errors.
    let cases: Vec<(reqwest::multipart::Form, u16, &str)> = vec![
        (
            reqwest::multipart::Form::new().text("params", "{}"),
            400,
            "missing_exemplar",
        ),
        (
            reqwest::multipart::Form::new()
                .part("xy", part(exemplar_png(32, 1)))
                .part("yz", part(exemplar_png(32, 2))),
            400,
            "missing_exemplar",
        ),
        (
            reqwest::multipart::Form::new()
                .part("xy", part(exemplar_png(32, 1)))
                .part("yz", part(exemplar_png(16, 2)))
                .part("zx", part(exemplar_png(32, 3))),
            400,
            "size_mismatch",
        ),
        (
            reqwest::multipart::Form::new()
                .part("image", part(exemplar_png(32, 1)))
                .text("params", "{nope"),
            400,
            "invalid_params",
        ),
        (
            reqwest::multipart::Form::new()
                .part("image", part(exemplar_png(32, 1)))
                .text("params", r#"{"passes": 100}"#),
            400,
            "out_of_range",
        ),
        (
            reqwest::multipart::Form::new()
                .part("image", part(exemplar_png(32, 1)))
                .text("colour", "red"),
            400,
            "invalid_request",
        ),
        (
            reqwest::multipart::Form::new().part("image", part(b"not a png".to_vec())),
            400,
            "malformed_image",
        ),
    ];
    for (form, status, code) in cases {
        let (st, h, b) = post_form(&c, &s.url("/v1/textures"), form).await;
        assert_error(st, &h, &b, status, code);
    }
    s.stop().await;
}

/// A PNG whose header claims a huge image over a tiny compressed body.
fn bomb_png() -> Vec<u8> {
    fn chunk(out: &mut Vec<u8>, kind: &[u8], data: &[u8]) {
        out.extend_from_slice(&(data.len() as u32).to_be_bytes());
        let mut crc = crc32fast::Hasher::new();
        crc.update(kind);
        crc.update(data);
        out.extend_from_slice(kind);
        out.extend_from_slice(data);
        out.extend_from_slice(&crc.finalize().to_be_bytes());
    }
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&100_000u32.to_be_bytes());
    ihdr.extend_from_slice(&100_000u32.to_be_bytes());
    ihdr.extend_from_slice(&[8, 2, 0, 0, 0]);
    chunk(&mut out, b"IHDR", &ihdr);
    // A zlib stream of zeros: a few KiB that would inflate to gigabytes.
    let mut z = vec![0x78, 0x9c];
    z.extend(std::iter::repeat_n(0u8, 4096));
    chunk(&mut out, b"IDAT", &z);
    chunk(&mut out, b"IEND", &[]);
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_error_class_is_json() {
    let (_dir, s, c, id) = server_with_texture(7).await;
    let t = |p: &str| s.url(&format!("/v1/textures/{id}{p}"));

    let cases: Vec<(String, u16, &str)> = vec![
        // Unknown texture and routes.
        (
            s.url("/v1/textures/0123456789abcdef0123456789abcdef"),
            404,
            "unknown_texture",
        ),
        (
            s.url("/v1/textures/nope/slices/z/0.png"),
            404,
            "unknown_texture",
        ),
        (
            s.url("/v1/textures/nope/bricks/0/0_0_0.raw"),
            404,
            "unknown_texture",
        ),
        (s.url("/v1/nothing"), 404, "no_route"),
        (t("/slices/z/0.jpg"), 404, "no_route"),
        (t("/bricks/0/0_0_0.bin"), 404, "no_route"),
        // Bad axis, non-numeric and out-of-range parameters.
        (t("/slices/w/0.png"), 400, "invalid_axis"),
        (t("/slices/z/abc.png"), 400, "invalid_parameter"),
        (t("/slices/z/0.png?u0=left"), 400, "invalid_parameter"),
        (t("/slices/z/0.png?w=8.5"), 400, "invalid_parameter"),
        (t("/slices/z/0.png?w=8&w=9"), 400, "invalid_parameter"),
        (t("/slices/z/2147483649.png"), 400, "out_of_range"),
        (
            t("/slices/z/99999999999999999999999.png"),
            400,
            "out_of_range",
        ),
        (t("/slices/z/0.png?u0=2147483647&w=8"), 400, "out_of_range"),
        (t("/slices/z/0.png?lod=3"), 400, "out_of_range"),
        (t("/slices/z/0.png?lod=-1"), 400, "out_of_range"),
        (t("/cut.png?origin=1,2"), 400, "invalid_parameter"),
        (t("/cut.png?u=a,b,c"), 400, "invalid_parameter"),
        (t("/cut.png?u=inf,0,0"), 400, "invalid_parameter"),
        (t("/cut.png?filter=cubic"), 400, "invalid_parameter"),
        (
            t("/cut.png?origin=2147483000,0,0&u=1000,0,0&w=4&h=4"),
            400,
            "out_of_range",
        ),
        (t("/region.raw?x=zero"), 400, "invalid_parameter"),
        (t("/bricks/x/0_0_0.raw"), 400, "invalid_parameter"),
        (t("/bricks/0/0_0.raw"), 400, "invalid_parameter"),
        (t("/bricks/0/a_0_0.raw"), 400, "invalid_parameter"),
        (t("/bricks/0/134217728_0_0.raw"), 400, "out_of_range"),
        (t("/bricks/9/0_0_0.raw"), 400, "out_of_range"),
        // Zero and oversize requests.
        (t("/slices/z/0.png?w=0"), 400, "out_of_range"),
        (t("/slices/z/0.png?h=4097"), 400, "out_of_range"),
        (t("/cut.png?w=5000"), 400, "out_of_range"),
        (t("/region.raw?d=0"), 400, "out_of_range"),
        (t("/region.raw?w=512&h=512&d=512"), 400, "too_large"),
        // Sides whose product wraps a u64 to 0.
        (
            t("/region.raw?w=16777216&h=16777216&d=16777216"),
            400,
            "too_large",
        ),
        (
            t("/region.raw?w=16777216&h=16777216&d=65537"),
            400,
            "too_large",
        ),
    ];
    for (url, status, code) in cases {
        let (st, h, b) = get(&c, &url).await;
        assert_eq!(st, status, "{url}: {}", String::from_utf8_lossy(&b));
        assert_error(st, &h, &b, status, code);
    }

    // Method not allowed keeps the JSON shape and the Allow header.
    let r = c.put(s.url("/healthz")).send().await.unwrap();
    let st = r.status().as_u16();
    let h = r.headers().clone();
    assert!(h.contains_key("allow"));
    assert_error(st, &h, &r.bytes().await.unwrap(), 405, "method_not_allowed");

    // Uploads: malformed image, wrong sizes, decompression bomb, wrong or
    // missing content type, too large, bad parameters.
    let post = |body: Vec<u8>, ct: Option<&str>, query: &str| {
        let mut r = c.post(s.url(&format!("/v1/textures{query}"))).body(body);
        if let Some(ct) = ct {
            r = r.header("content-type", ct);
        }
        r.send()
    };
    let tiny = {
        let rgb = vec![9u8; 8 * 8 * 3];
        encode_png(8, 8, &rgb)
    };
    let huge_side = {
        let rgb = vec![9u8; 600 * 16 * 3];
        encode_png(600, 16, &rgb)
    };
    // (body, content type, query, status, code)
    type UploadCase<'a> = (Vec<u8>, Option<&'a str>, &'a str, u16, &'a str);
    let cases: Vec<UploadCase> = vec![
        (
            b"GIF89a not really".to_vec(),
            Some("image/png"),
            "",
            400,
            "malformed_image",
        ),
        (
            exemplar_png(32, 1)[..60].to_vec(),
            Some("image/png"),
            "",
            400,
            "malformed_image",
        ),
        (Vec::new(), Some("image/png"), "", 400, "malformed_image"),
        (tiny, Some("image/png"), "", 400, "image_size"),
        (huge_side, Some("image/png"), "", 400, "image_size"),
        (bomb_png(), Some("image/png"), "", 400, "image_size"),
        (
            exemplar_png(32, 1),
            Some("text/plain"),
            "",
            415,
            "unsupported_media_type",
        ),
        // JSON defines a region texture: an image is no definition.
        (
            exemplar_png(32, 1),
            Some("application/json"),
            "",
            400,
            "invalid_region",
        ),
        (exemplar_png(32, 1), None, "", 415, "unsupported_media_type"),
        (
            vec![0u8; 300 << 10],
            Some("image/png"),
            "",
            413,
            "payload_too_large",
        ),
        (
            exemplar_png(32, 1),
            Some("image/png"),
            "?sed=4",
            400,
            "invalid_params",
        ),
        (
            exemplar_png(32, 1),
            Some("image/png"),
            "?seed=-4",
            400,
            "invalid_params",
        ),
        (
            exemplar_png(32, 1),
            Some("image/png"),
            "?jitter=9",
            400,
            "out_of_range",
        ),
        (
            exemplar_png(32, 1),
            Some("image/png"),
            "?scheme=fancy",
            400,
            "invalid_params",
        ),
        (
            exemplar_png(32, 1),
            Some("multipart/form-data"),
            "",
            400,
            "malformed_multipart",
        ),
    ];
    for (body, ct, query, status, code) in cases {
        let r = post(body, ct, query).await.unwrap();
        let st = r.status().as_u16();
        let h = r.headers().clone();
        let b = r.bytes().await.unwrap();
        assert_error(st, &h, &b, status, code);
    }

    // Not ready: with one precompute slot, the second upload waits behind
    // the first and answers 409 with Retry-After meanwhile.
    let (_, a) = upload(&c, &s, exemplar_png(32, 20), SMALL_PARAMS).await;
    let (st, b) = upload(&c, &s, exemplar_png(32, 21), SMALL_PARAMS).await;
    assert_eq!(st, 202);
    let pending = b["id"].as_str().unwrap();
    let (st, h, body) = get(
        &c,
        &s.url(&format!("/v1/textures/{pending}/slices/z/0.png?w=4&h=4")),
    )
    .await;
    assert_error(st, &h, &body, 409, "texture_pending");
    assert_eq!(h["retry-after"], "1");
    wait_ready(&c, &s, a["id"].as_str().unwrap()).await;
    wait_ready(&c, &s, pending).await;

    // Nothing above was a server error.
    let text = metrics(&c, &s).await;
    assert!(
        !text
            .lines()
            .any(|l| l.starts_with("solidtex_http_requests_total") && l.contains("status=\"5")),
        "{text}"
    );
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cors_headers() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    let c = client();
    let r = c
        .request(
            reqwest::Method::OPTIONS,
            s.url("/v1/textures/default/slices/z/0.png"),
        )
        .header("origin", "https://viewer.example")
        .header("access-control-request-method", "GET")
        .header("access-control-request-headers", "if-none-match")
        .send()
        .await
        .unwrap();
    assert!(r.status().is_success(), "{}", r.status());
    assert_eq!(r.headers()["access-control-allow-origin"], "*");
    assert!(
        r.headers()["access-control-allow-methods"]
            .to_str()
            .unwrap()
            .contains("GET")
    );
    let r = c
        .get(s.url("/healthz"))
        .header("origin", "https://viewer.example")
        .send()
        .await
        .unwrap();
    assert_eq!(r.headers()["access-control-allow-origin"], "*");
    let exposed = r.headers()["access-control-expose-headers"]
        .to_str()
        .unwrap()
        .to_string();
    for h in ["etag", "retry-after", "x-solidtex-width"] {
        assert!(exposed.contains(h), "{exposed}");
    }
    // Errors carry CORS headers too.
    let r = c
        .get(s.url("/nope"))
        .header("origin", "https://viewer.example")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 404);
    assert_eq!(r.headers()["access-control-allow-origin"], "*");
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn concurrent_uploads_cannot_all_pass_the_precompute_bound() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.max_precomputes = 1;
    args.precompute_queue = 2;
    let s = TestServer::start(args).await;
    let c = client();
    // Distinct images, all sent at once: each is a new texture.
    let mut tasks = Vec::new();
    for seed in 0..24 {
        let c = c.clone();
        let url = s.url("/v1/textures?levels=2");
        tasks.push(tokio::spawn(async move {
            let r = c
                .post(url)
                .header("content-type", "image/png")
                .body(exemplar_png(16, 1000 + seed))
                .send()
                .await
                .unwrap();
            r.status().as_u16()
        }));
    }
    let mut accepted = 0;
    for t in tasks {
        match t.await.unwrap() {
            202 => accepted += 1,
            503 => {}
            other => panic!("unexpected {other}"),
        }
    }
    // One precompute running and two waiting at most (the bundled default
    // may hold one of those places).
    assert!((1..=3).contains(&accepted), "{accepted} uploads accepted");
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn full_queue_answers_503_with_retry_after() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.max_jobs = 1;
    args.queue = 0;
    let s = TestServer::start(args).await;
    let c = client();
    let id = ready_texture(&c, &s, 9).await;
    // Distinct bricks, so no request is served from another's tiles.
    let mut tasks = Vec::new();
    for i in 0..8 {
        let c = c.clone();
        let url = s.url(&format!(
            "/v1/textures/{id}/bricks/0/{}_{}_0.raw",
            i * 7,
            i * 3
        ));
        tasks.push(tokio::spawn(async move {
            let r = c.get(url).send().await.unwrap();
            let st = r.status().as_u16();
            let h = r.headers().clone();
            (st, h, r.bytes().await.unwrap())
        }));
    }
    let mut ok = 0;
    let mut refused = 0;
    for t in tasks {
        let (st, h, b) = t.await.unwrap();
        match st {
            200 => ok += 1,
            503 => {
                assert_error(st, &h, &b, 503, "overloaded");
                assert_eq!(h["retry-after"], "1");
                refused += 1;
            }
            other => panic!("unexpected {other}"),
        }
    }
    assert!(ok >= 1 && refused >= 1, "ok {ok}, refused {refused}");
    let text = metrics(&c, &s).await;
    assert_eq!(
        metric(&text, "solidtex_jobs_rejected_total"),
        refused as f64
    );
    // The server is still fine afterwards.
    let (st, _, _) = get(&c, &s.url(&format!("/v1/textures/{id}/bricks/0/0_0_0.raw"))).await;
    assert_eq!(st, 200);
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn request_budget_is_enforced() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.max_request_voxels = 4096;
    args.chunk_size = 16; // volume chunks must fit the budget too
    let s = TestServer::start(args).await;
    let c = client();
    let id = ready_texture(&c, &s, 10).await;
    let t = |p: &str| s.url(&format!("/v1/textures/{id}{p}"));
    for (path, status) in [
        ("/slices/z/0.png?w=64&h=64", 200),
        ("/slices/z/0.png?w=65&h=64", 400),
        ("/region.raw?w=16&h=16&d=16", 200),
        ("/region.raw?w=16&h=16&d=17", 400),
        ("/bricks/0/0_0_0.raw", 200),
        ("/cut.png?w=16&h=16&u=2,0,0&v=0,2,0", 200),
        ("/cut.png?w=16&h=16&u=100,0,0&v=0,100,0", 400),
    ] {
        let (st, h, b) = get(&c, &t(path)).await;
        if status == 200 {
            assert_eq!(st, 200, "{path}");
        } else {
            assert_error(st, &h, &b, 400, "too_large");
        }
    }
    s.stop().await;

    // Bricks larger than the budget are a configuration error.
    let mut args = test_args(dir.path());
    args.max_request_voxels = 1000;
    let err = solidtex_server::Server::bind(&args).await.err().unwrap();
    assert!(err.to_string().contains("budget"), "{err}");
    // So are volume chunks larger than the budget.
    let mut args = test_args(dir.path());
    args.max_request_voxels = 4096;
    args.brick_size = 16;
    args.chunk_size = 32;
    let err = solidtex_server::Server::bind(&args).await.err().unwrap();
    assert!(err.to_string().contains("chunks"), "{err}");
}

/// What a request may synthesize is bounded, whatever its shape, and a
/// request over the bound is refused before any work: a small image whose
/// pixels land far apart, a thin column, a slice at a coarse level and a
/// region whose chains cost more than its own voxels synthesize nothing,
/// like a large slice; cheap requests still pass.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn synthesis_work_per_request_is_bounded_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.max_request_work = 60_000;
    let s = TestServer::start(args).await;
    let c = client();
    let id = ready_texture(&c, &s, 11).await;
    let t = |p: &str| s.url(&format!("/v1/textures/{id}{p}"));
    let (st, _, small) = get(&c, &t("/slices/z/0.png?w=8&h=8")).await;
    assert_eq!(st, 200);
    let scrape = |text: &str, name: &str| {
        text.lines()
            .filter(|l| l.starts_with(name))
            .filter_map(|l| l.rsplit(' ').next()?.parse::<f64>().ok())
            .sum::<f64>()
    };
    let before = metrics(&c, &s).await;
    let voxels = scrape(&before, "solidtex_synth_voxels_total");
    assert!(voxels > 0.0, "the small slice synthesized voxels");
    let refused = [
        "/slices/z/0.png?w=256&h=256",
        "/slices/x/5.png?w=300&h=300",
        "/cut.png?w=16&h=16&u=1000,0,0&v=0,0,1000",
        "/cut.png?w=64&h=2&u=300,0,0&v=0,0,1",
        "/region.raw?w=32&h=32&d=32",
        "/region.raw?w=1&h=1&d=4000",
        "/slices/y/0.png?w=160&h=160&lod=2",
    ];
    for path in refused {
        // Each of these has fewer own voxels than the budget but one.
        let (st, h, b) = get(&c, &t(path)).await;
        assert_error(st, &h, &b, 400, "over_budget");
        let message = serde_json::from_slice::<serde_json::Value>(&b).unwrap()["error"]["message"]
            .to_string();
        assert!(
            message.contains("predicted") && message.contains("60000"),
            "{message}"
        );
    }
    let after = metrics(&c, &s).await;
    assert_eq!(scrape(&after, "solidtex_synth_voxels_total"), voxels);
    assert_eq!(scrape(&after, "solidtex_jobs_running"), 0.0);
    assert_eq!(
        scrape(
            &after,
            "solidtex_requests_over_budget_total{stage=\"predicted\"}"
        ),
        refused.len() as f64
    );
    // The cache is as it was: the small slice is the same bytes again.
    let (st, _, again) = get(&c, &t("/slices/z/0.png?w=8&h=8")).await;
    assert_eq!((st, again), (200, small));
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_token_guards_uploads_deletions_and_metrics() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.token = Some("s3cret".into());
    let s = TestServer::start(args).await;
    let c = client();
    let post = |auth: Option<&'static str>| {
        let mut r = c
            .post(s.url("/v1/textures?levels=2"))
            .header("content-type", "image/png")
            .body(exemplar_png(16, 77));
        if let Some(a) = auth {
            r = r.header("authorization", a);
        }
        r.send()
    };
    for auth in [
        None,
        Some("Bearer nope"),
        Some("s3cret"),
        Some("Basic s3cret"),
    ] {
        let r = post(auth).await.unwrap();
        let (st, h) = (r.status().as_u16(), r.headers().clone());
        assert_eq!(h["www-authenticate"], "Bearer", "{auth:?}");
        assert_error(st, &h, &r.bytes().await.unwrap(), 401, "unauthorized");
    }
    let r = post(Some("Bearer s3cret")).await.unwrap();
    assert_eq!(r.status().as_u16(), 202);
    let id = r.json::<Value>().await.unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string();
    wait_ready(&c, &s, &id).await;
    // Reading needs no token.
    let (st, _, _) = get(
        &c,
        &s.url(&format!("/v1/textures/{id}/slices/z/0.png?w=8&h=8")),
    )
    .await;
    assert_eq!(st, 200);
    // Metrics and deletions do.
    let (st, h, b) = get(&c, &s.url("/metrics")).await;
    assert_error(st, &h, &b, 401, "unauthorized");
    let r = c
        .get(s.url("/metrics"))
        .header("authorization", "Bearer s3cret")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 200);
    let url = s.url(&format!("/v1/textures/{id}"));
    let r = c.delete(&url).send().await.unwrap();
    assert_eq!(r.status().as_u16(), 401);
    let r = c
        .delete(&url)
        .header("authorization", "Bearer s3cret")
        .send()
        .await
        .unwrap();
    assert!(r.status().is_success(), "{}", r.status());
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pages_on_other_origins_only_read_unless_their_origin_is_configured() {
    let preflight = |c: &reqwest::Client, url: String, method: &'static str| {
        c.request(reqwest::Method::OPTIONS, url)
            .header("origin", "https://app.example")
            .header("access-control-request-method", method)
            .send()
    };
    let allowed = |r: &reqwest::Response| {
        r.headers()
            .get("access-control-allow-methods")
            .map(|v| v.to_str().unwrap().to_string())
            .unwrap_or_default()
    };
    for (origins, deletes) in [(vec![], false), (vec!["https://app.example".into()], true)] {
        let dir = tempfile::tempdir().unwrap();
        let mut args = test_args(dir.path());
        args.cors_origins = origins;
        let s = TestServer::start(args).await;
        let c = client();
        let r = preflight(&c, s.url("/v1/textures/default"), "DELETE")
            .await
            .unwrap();
        assert_eq!(allowed(&r).contains("DELETE"), deletes, "{}", allowed(&r));
        let r = preflight(&c, s.url("/v1/textures/default/slices/z/0.png"), "GET")
            .await
            .unwrap();
        assert!(allowed(&r).contains("GET"), "{}", allowed(&r));
        s.stop().await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn readyz_reports_a_deleted_default_texture() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.default_texture = true;
    let s = TestServer::start(args).await;
    let c = client();
    wait_ready(&c, &s, "default").await;
    let (st, _, _) = get(&c, &s.url("/readyz")).await;
    assert_eq!(st, 200);
    let r = c
        .delete(s.url("/v1/textures/default"))
        .send()
        .await
        .unwrap();
    assert!(r.status().is_success(), "{}", r.status());
    let (st, _, b) = get(&c, &s.url("/readyz")).await;
    assert_eq!(st, 503);
    assert_eq!(
        serde_json::from_slice::<Value>(&b).unwrap()["status"],
        "default_missing"
    );
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_request_right_after_an_upload_waits_for_its_precompute() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.pending_wait = 60.0;
    let s = TestServer::start(args).await;
    let c = client();
    let (st, body) = upload(&c, &s, exemplar_png(24, 4242), "levels=2").await;
    assert_eq!(st, 202, "{body}");
    let id = body["id"].as_str().unwrap().to_string();
    // Asked at once, answered once the precompute ends, not 409.
    let (st, h, b) = get(
        &c,
        &s.url(&format!("/v1/textures/{id}/slices/z/0.png?w=8&h=8")),
    )
    .await;
    assert_eq!(st, 200, "{h:?} {}", String::from_utf8_lossy(&b));
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_cors_origin_that_is_no_header_value_is_refused_at_start() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.cors_origins = vec!["https://a.example\nx".into()];
    let err = solidtex_server::Server::bind(&args)
        .await
        .err()
        .expect("refused");
    assert!(format!("{err:#}").contains("CORS origin"), "{err:#}");
}

/// Encodes RGB8 as a JPEG.
fn encode_jpeg(w: u32, h: u32, rgb: &[u8]) -> Vec<u8> {
    use image::ImageEncoder;
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 90)
        .write_image(rgb, w, h, image::ExtendedColorType::Rgb8)
        .unwrap();
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn uploads_keep_their_name_take_jpeg_and_downscale_photos() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    let c = client();

    // A multipart file name becomes the texture's name, without its path.
    let png = exemplar_png(32, 7);
    let part = reqwest::multipart::Part::bytes(png.clone())
        .file_name("some/dir/leaf.png")
        .mime_str("image/png")
        .unwrap();
    let form = reqwest::multipart::Form::new()
        .part("image", part)
        .text("params", r#"{"levels": 3}"#);
    let (status, v) = upload_form(&c, &s, form).await;
    assert_eq!(status, 202);
    assert_eq!(v["name"], "leaf.png");
    assert!(v.get("notes").is_none(), "{v}");
    let id = v["id"].as_str().unwrap().to_string();
    let (_, _, list) = get(&c, &s.url("/v1/textures")).await;
    let list: Value = serde_json::from_slice(&list).unwrap();
    assert!(
        list["textures"]
            .as_array()
            .unwrap()
            .iter()
            .any(|t| t["id"] == id.as_str() && t["name"] == "leaf.png"),
        "{list}"
    );

    // The exemplar thumbnail is the uploaded image, revalidated by ETag.
    let url = s.url(&format!("/v1/textures/{id}/exemplar.png"));
    let (st, h, b) = get(&c, &url).await;
    assert_eq!(st, 200);
    assert_eq!(h["content-type"], "image/png");
    assert_eq!(decode_png(&b), decode_png(&png));
    let tag = h["etag"].to_str().unwrap().to_string();
    let r = c
        .get(&url)
        .header("if-none-match", tag)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 304);
    let (st, _, _) = get(&c, &s.url("/v1/textures/nope/exemplar.png")).await;
    assert_eq!(st, 404);

    // A raw JPEG body, named by the query string (which is no parameter).
    let rgb = decode_png(&exemplar_png(40, 3)).2;
    let r = c
        .post(s.url("/v1/textures?levels=3&name=photo.jpg"))
        .header("content-type", "image/jpeg")
        .body(encode_jpeg(40, 40, &rgb))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 202);
    let v: Value = r.json().await.unwrap();
    assert_eq!(v["name"], "photo.jpg");
    assert_eq!(v["exemplar"]["width"], 40);

    // A photo over the size limit is downscaled, keeping its aspect, and
    // the answer says so.
    let (w, h) = (1040u32, 32u32);
    let wide: Vec<u8> = (0..w * h)
        .flat_map(|i| {
            let (x, y) = (i % w, i / w);
            [
                (x * 7 % 256) as u8,
                (y * 9 % 256) as u8,
                ((x ^ y) % 256) as u8,
            ]
        })
        .collect();
    let r = c
        .post(s.url("/v1/textures?levels=3"))
        .header("content-type", "image/jpeg")
        .body(encode_jpeg(w, h, &wide))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 202);
    let v: Value = r.json().await.unwrap();
    assert_eq!(v["exemplar"]["width"], 512);
    assert_eq!(v["exemplar"]["height"], 16);
    let notes = v["notes"].to_string();
    assert!(notes.contains("downscaled from 1040x32 to 512x16"), "{v}");
    s.stop().await;
}

/// Uploads beyond the configured number of textures, or beyond the bytes
/// they may take on disk, are refused with 507 until some are deleted.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stored_textures_are_bounded_in_number_and_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.max_textures = 2;
    let s = TestServer::start(args).await;
    let c = client();
    let first = ready_texture(&c, &s, 41).await;
    ready_texture(&c, &s, 42).await;
    let (st, v) = upload(&c, &s, exemplar_png(32, 43), SMALL_PARAMS).await;
    assert_eq!(st, 507, "{v}");
    assert_eq!(v["error"]["code"], "storage_full");
    // Known textures are still answered, and a deletion makes room.
    let (st, _) = upload(&c, &s, exemplar_png(32, 42), SMALL_PARAMS).await;
    assert_eq!(st, 201);
    let r = c
        .delete(s.url(&format!("/v1/textures/{first}")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 204);
    let (st, v) = upload(&c, &s, exemplar_png(32, 43), SMALL_PARAMS).await;
    assert_eq!(st, 202, "{v}");
    s.stop().await;

    // 300 kB on disk: a 32² exemplar's candidates would need more, a 16²
    // one's fit.
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.max_stored_bytes = 300_000;
    let s = TestServer::start(args).await;
    let (st, v) = upload(&c, &s, exemplar_png(32, 44), SMALL_PARAMS).await;
    assert_eq!(st, 507, "{v}");
    assert!(
        v["error"]["message"]
            .as_str()
            .unwrap()
            .contains("--max-stored-bytes"),
        "{v}"
    );
    let (st, v) = upload(&c, &s, exemplar_png(16, 44), SMALL_PARAMS).await;
    assert_eq!(st, 202, "{v}");
    s.stop().await;
}

/// Beyond the memory bound the least recently used textures leave memory;
/// asked for again, they come back from disk and give the same voxels as a
/// server that never let them go.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn textures_beyond_the_memory_bound_are_evicted_and_loaded_again() {
    let (dir, fresh_dir) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let mut args = test_args(dir.path());
    // Only the texture last used stays in memory.
    args.max_resident_bytes = 1;
    let s = TestServer::start(args).await;
    let fresh = TestServer::start(test_args(fresh_dir.path())).await;
    let c = client();
    let a = ready_texture(&c, &s, 51).await;
    let b = ready_texture(&c, &s, 52).await;
    assert_eq!(ready_texture(&c, &fresh, 51).await, a);
    let loaded = |text: &str| metric(text, "solidtex_textures_loaded_total");
    let before = loaded(&metrics(&c, &s).await);
    // `a` was evicted when `b` became ready: a cold slice of it loads it
    // back (evicting `b`), then `b` comes back the same way.
    let slice = |srv: &TestServer, id: &str| {
        srv.url(&format!(
            "/v1/textures/{id}/slices/x/-9.png?u0=4&v0=-20&w=24&h=24"
        ))
    };
    let (st, _, got) = get(&c, &slice(&s, &a)).await;
    assert_eq!(st, 200);
    let (st, _, want) = get(&c, &slice(&fresh, &a)).await;
    assert_eq!(st, 200);
    assert_eq!(got, want);
    let (st, _, _) = get(&c, &slice(&s, &b)).await;
    assert_eq!(st, 200);
    assert_eq!(loaded(&metrics(&c, &s).await) - before, 2.0);
    let (_, _, listing) = get(&c, &s.url(&format!("/v1/textures/{a}"))).await;
    let v: Value = serde_json::from_slice(&listing).unwrap();
    assert_eq!(v["status"], "ready");
    assert!(v["max_lod"].as_u64().is_some(), "{v}");
    s.stop().await;
    fresh.stop().await;
}

/// A `side`² mask image: light diagonal bands two pixels wide.
fn mask_png(side: u32) -> Vec<u8> {
    let rgb: Vec<u8> = (0..side * side)
        .flat_map(|i| {
            let l = if (i % side + i / side) % 8 < 2 {
                255
            } else {
                0
            };
            [l, l, l]
        })
        .collect();
    solidtex_core::png::encode(side, side, &rgb).unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn feature_masks_make_their_own_texture_and_survive_a_restart() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    let c = client();
    let part = png_part;
    let params = r#"{"levels": 3, "feature_weight": 1}"#;
    let form = reqwest::multipart::Form::new()
        .part("image", part(exemplar_png(32, 7)))
        .part("feature_mask", part(mask_png(32)))
        .text("params", params);
    let (status, v) = upload_form(&c, &s, form).await;
    assert_eq!(status, 202, "{v}");
    assert_eq!(v["exemplar"]["feature_masks"], 1);
    let id = v["id"].as_str().unwrap().to_string();
    // The same exemplar and parameters without the mask: another texture,
    // whose view says nothing of masks.
    let form = reqwest::multipart::Form::new()
        .part("image", part(exemplar_png(32, 7)))
        .text("params", params);
    let (_, plain) = upload_form(&c, &s, form).await;
    assert_ne!(plain["id"], v["id"]);
    assert!(plain["exemplar"].get("feature_masks").is_none(), "{plain}");
    let plain_id = plain["id"].as_str().unwrap().to_string();
    wait_ready(&c, &s, &id).await;
    wait_ready(&c, &s, &plain_id).await;
    let slice = |id: &str| format!("/v1/textures/{id}/slices/z/3.png?w=24&h=24");
    let (st, _, masked_png) = get(&c, &s.url(&slice(&id))).await;
    assert_eq!(st, 200);
    let (_, _, plain_png) = get(&c, &s.url(&slice(&plain_id))).await;
    assert_ne!(masked_png, plain_png, "the mask changes the voxels");
    s.stop().await;

    // Stored with the texture: after a restart the same id is ready with
    // the same bytes, and no precompute ran.
    let s = TestServer::start(test_args(dir.path())).await;
    let meta = get_json(&c, &s, &format!("/v1/textures/{id}")).await;
    assert_eq!(meta["status"], "ready");
    assert_eq!(meta["exemplar"]["feature_masks"], 1);
    let (_, _, again) = get(&c, &s.url(&slice(&id))).await;
    assert_eq!(again, masked_png);
    assert_eq!(
        metric(
            &metrics(&c, &s).await,
            r#"solidtex_precomputes_total{outcome="ok"}"#
        ),
        0.0
    );

    // Masks that cannot be used, beside the one image: (field, mask,
    // whether the channel is on, the error).
    let black = solidtex_core::png::encode(32, 32, &[0u8; 32 * 32 * 3]).unwrap();
    let cases: Vec<(&str, Vec<u8>, bool, &str)> = vec![
        // Without the feature-distance channel nothing reads it.
        ("feature_mask", mask_png(32), false, "invalid_request"),
        ("feature_mask", mask_png(16), true, "size_mismatch"),
        // All dark: no feature at all.
        ("feature_mask", black, true, "invalid_request"),
        ("feature_mask_xy", mask_png(32), true, "invalid_request"),
        (
            "feature_mask",
            b"not a png".to_vec(),
            true,
            "malformed_image",
        ),
    ];
    let mut forms: Vec<(reqwest::multipart::Form, &str)> = cases
        .into_iter()
        .map(|(field, mask, channel, code)| {
            let form = reqwest::multipart::Form::new()
                .part("image", part(exemplar_png(32, 7)))
                .part(field, part(mask));
            let form = if channel {
                form.text("params", params)
            } else {
                form
            };
            (form, code)
        })
        .collect();
    // The single image's mask field beside three planes.
    forms.push((
        reqwest::multipart::Form::new()
            .part("xy", part(exemplar_png(32, 1)))
            .part("yz", part(exemplar_png(32, 2)))
            .part("zx", part(exemplar_png(32, 3)))
            .part("feature_mask", part(mask_png(32)))
            .text("params", params),
        "invalid_request",
    ));
    for (form, code) in forms {
        let (st, h, b) = post_form(&c, &s.url("/v1/textures"), form).await;
        assert_error(st, &h, &b, 400, code);
    }
    // One mask of three planes is fine.
    let form = reqwest::multipart::Form::new()
        .part("xy", part(exemplar_png(32, 1)))
        .part("yz", part(exemplar_png(32, 2)))
        .part("zx", part(exemplar_png(32, 3)))
        .part("feature_mask_yz", part(mask_png(32)))
        .text("params", params);
    let (status, v) = upload_form(&c, &s, form).await;
    assert_eq!(status, 202, "{v}");
    assert_eq!(v["exemplar"]["feature_masks"], 1);
    // Its precompute uses the data directory until it ends: the next
    // server could not take the directory before then.
    wait_ready(&c, &s, v["id"].as_str().unwrap()).await;
    s.stop().await;

    // A stored mask that went missing makes the pixels disagree with the
    // id: the texture is not served rather than served without its mask.
    let mask = dir
        .path()
        .join("textures")
        .join(&id)
        .join("exemplar.mask.png");
    std::fs::remove_file(&mask).unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    let (st, _, _) = get(&c, &s.url(&format!("/v1/textures/{id}"))).await;
    assert_eq!(st, 404);
    let (st, _, _) = get(&c, &s.url(&format!("/v1/textures/{plain_id}"))).await;
    assert_eq!(st, 200);
    s.stop().await;
}
