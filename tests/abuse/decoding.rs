//! Uploaded images are decoded within the server's bounds: a burst of
//! large photos stays within the memory bound the server reports, a decode
//! that could never fit is refused before it starts, and images that end
//! early or claim more pixels than they hold are refused, not padded.

use crate::server_support::*;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_burst_of_large_uploads_stays_within_the_memory_bound() {
    let dir = tempfile::tempdir().unwrap();
    let s = BinaryServer::start(
        dir.path(),
        &[
            ("SOLIDTEX_DEFAULT_TEXTURE", "false"),
            ("SOLIDTEX_CACHE_BYTES", "67108864"),
            ("SOLIDTEX_MAX_JOBS", "1"),
            // Every upload ends refused by its precompute's estimate, as
            // the photos are downscaled to 512 pixels.
            ("SOLIDTEX_MAX_PRECOMPUTE_BYTES", "104857600"),
            ("SOLIDTEX_MAX_DECODE_BYTES", "268435456"),
            ("SOLIDTEX_MAX_QUEUE_WAIT", "300"),
        ],
    );
    let c = client();
    // 6000² photos: a PNG of about 120 KB, a JPEG of about a megabyte,
    // and a 15 KB JPEG whose header claims 6000².
    let rgb = blocky_rgb(6000, 6000);
    let png = encode_png(6000, 6000, &rgb);
    let jpeg = encode_jpeg(6000, 6000, &rgb);
    drop(rgb);
    let small = decode_png(&exemplar_png(128, 1)).2;
    let lying = claim_jpeg_size(encode_jpeg(128, 128, &small), 6000, 6000);
    let url = s.url("/v1/textures");
    let mut burst = Vec::new();
    for i in 0..16 {
        let (bytes, kind) = match i % 4 {
            0 | 1 => (png.clone(), "image/png"),
            2 => (jpeg.clone(), "image/jpeg"),
            _ => (lying.clone(), "image/jpeg"),
        };
        let (c, url) = (c.clone(), url.clone());
        burst.push(tokio::spawn(async move {
            (i, post_body(&c, &url, kind, bytes).await)
        }));
    }
    for b in burst {
        let (i, (status, v)) = b.await.unwrap();
        let want = if i % 4 == 3 {
            (400, "malformed_image")
        } else {
            (413, "precompute_too_large")
        };
        assert_eq!(
            (status, v["error"]["code"].as_str().unwrap()),
            want,
            "{i}: {v}"
        );
    }
    let text = s.metrics(&c).await;
    let peak = metric(&text, "solidtex_process_peak_resident_bytes");
    let bound = memory_bound(&text);
    println!("peak resident {peak} bytes, bound {bound} bytes");
    assert!(peak > 0.0 && bound > 0.0, "{text}");
    assert!(peak <= bound, "peak resident {peak} over the bound {bound}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn images_that_end_early_or_lie_about_their_size_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    let c = client();
    let url = s.url("/v1/textures?levels=3");
    let rgb = decode_png(&exemplar_png(128, 2)).2;
    let jpeg = encode_jpeg(128, 128, &rgb);
    let png = encode_png(128, 128, &rgb);
    for (name, bytes, kind) in [
        ("half a JPEG", jpeg[..jpeg.len() / 2].to_vec(), "image/jpeg"),
        ("half a PNG", png[..png.len() / 2].to_vec(), "image/png"),
        (
            "a JPEG claiming 6000²",
            claim_jpeg_size(jpeg.clone(), 6000, 6000),
            "image/jpeg",
        ),
        (
            "a JPEG claiming more rows",
            claim_jpeg_size(jpeg.clone(), 128, 160),
            "image/jpeg",
        ),
    ] {
        let (status, v) = post_body(&c, &url, kind, bytes).await;
        assert_eq!(
            (status, v["error"]["code"].as_str()),
            (400, Some("malformed_image")),
            "{name}: {v}"
        );
    }
    let list = get_json(&c, &s, "/v1/textures").await;
    assert_eq!(list["textures"].as_array().unwrap().len(), 0, "{list}");
    // Whole, it is a texture; a photo's EXIF orientation is applied.
    let (status, v) = post_body(&c, &url, "image/jpeg", jpeg).await;
    assert_eq!(status, 202, "{v}");
    let (status, v) = post_body(&c, &url, "image/jpeg", image_fixture("rotated.jpg")).await;
    assert_eq!(status, 202, "{v}");
    assert_eq!(
        (
            v["exemplar"]["width"].as_u64(),
            v["exemplar"]["height"].as_u64()
        ),
        (Some(48), Some(80)),
        "{v}"
    );
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_decode_over_the_bound_is_refused_before_it_starts() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.max_upload_bytes = 8 << 20;
    args.max_decode_bytes = 16 << 20;
    let s = TestServer::start(args).await;
    let c = client();
    let url = s.url("/v1/textures?levels=3");
    // A 2000² JPEG is decoded whole (12 MB of RGB and more): over 16 MiB.
    let rgb = blocky_rgb(2000, 2000);
    let (status, v) = post_body(&c, &url, "image/jpeg", encode_jpeg(2000, 2000, &rgb)).await;
    assert_eq!(
        (status, v["error"]["code"].as_str()),
        (413, Some("image_too_large")),
        "{v}"
    );
    // A PNG of 6000² is read row by row: it fits, and is downscaled.
    let rgb = blocky_rgb(6000, 6000);
    let (status, v) = post_body(&c, &url, "image/png", encode_png(6000, 6000, &rgb)).await;
    assert_eq!(status, 202, "{v}");
    assert_eq!(v["exemplar"]["width"], 512, "{v}");
    assert!(
        v["notes"][0]
            .as_str()
            .unwrap()
            .contains("downscaled from 6000x6000"),
        "{v}"
    );
    // Its precompute (of 512²) is not what this test is about.
    let id = v["id"].as_str().unwrap();
    assert_eq!(delete(&c, &s.url(&format!("/v1/textures/{id}"))).await, 204);
    s.stop().await;
}
