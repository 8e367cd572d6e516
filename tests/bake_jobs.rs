//! Long bakes as background jobs (`POST /v1/textures/{id}/bake` with
//! `Prefer: respond-async`): 202 and a status that reports progress, the
//! file equal to the synchronous bake's, the same bake joining the one
//! held, `DELETE` stopping a running bake, unknown ids, and a full queue.

mod common;
mod server_support;

use serde_json::Value;
use server_support::*;
use std::time::{Duration, Instant};

fn torus_obj() -> Vec<u8> {
    std::fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/meshes/torus.obj"
    ))
    .unwrap()
}

/// POSTs the torus to `url`, asynchronously when `prefer`; returns
/// (status, headers, body).
async fn post_bake(
    c: &reqwest::Client,
    url: &str,
    prefer: bool,
) -> (u16, reqwest::header::HeaderMap, Vec<u8>) {
    let mut r = c.post(url).body(torus_obj());
    if prefer {
        r = r.header("prefer", "respond-async");
    }
    let r = r.send().await.unwrap();
    let status = r.status().as_u16();
    let headers = r.headers().clone();
    (status, headers, r.bytes().await.unwrap().to_vec())
}

fn json(body: &[u8]) -> Value {
    serde_json::from_slice(body).unwrap_or_else(|_| panic!("{}", String::from_utf8_lossy(body)))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_async_bake_reports_progress_and_serves_the_synchronous_bytes() {
    let (_dir, s, c, id) = server_with_texture(11).await;
    let url = s.url(&format!(
        "/v1/textures/{id}/bake?resolution=200&texture_size=2048&uvs=atlas"
    ));
    let (st, h, body) = post_bake(&c, &url, true).await;
    assert_eq!(st, 202, "{}", String::from_utf8_lossy(&body));
    let first = json(&body);
    let location = h["location"].to_str().unwrap().to_string();
    assert!(location.starts_with("/v1/bakes/"), "{location}");
    assert_eq!(first["url"], location);
    assert_eq!(first["kind"], "bake");
    assert_eq!(first["unit"], "texels");
    assert_eq!(first["total"], 2048 * 2048);
    assert!(first["predicted_voxels"].as_u64().unwrap() > 0, "{first}");
    assert!(
        first["created"].as_u64().unwrap() > 1_700_000_000,
        "{first}"
    );
    assert!(
        first["state"] == "queued" || first["state"] == "running",
        "{first}"
    );
    // The same bake again joins it.
    let (st, h, body) = post_bake(&c, &url, true).await;
    if st == 202 {
        assert_eq!(h["location"], location.as_str());
        assert_eq!(json(&body)["created"], first["created"]);
    } else {
        assert_eq!(st, 200, "{}", String::from_utf8_lossy(&body));
    }
    let (mut progress, mut done, mut synthesized) = (-1.0, 0, 0);
    let mut running_polls = 0;
    let t0 = Instant::now();
    let status = loop {
        let v = get_json(&c, &s, &location).await;
        let p = v["progress"].as_f64().unwrap();
        let d = v["done"].as_u64().unwrap();
        let n = v["synthesized_voxels"].as_u64().unwrap();
        assert!((0.0..=1.0).contains(&p), "{v}");
        assert!(
            p >= progress && d >= done && n >= synthesized,
            "not monotone: {v}"
        );
        (progress, done, synthesized) = (p, d, n);
        if v["state"] == "done" {
            break v;
        }
        assert!(v["state"] == "running" || v["state"] == "queued", "{v}");
        if v["state"] == "running" {
            running_polls += 1;
            let (st, h, b) = get(&c, &s.url(&format!("{location}/file"))).await;
            if st == 409 {
                assert_error(st, &h, &b, 409, "bake_running");
                assert!(h.contains_key("retry-after"));
            }
        }
        assert!(t0.elapsed() < Duration::from_secs(600), "{v}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    assert_eq!(status["progress"], 1.0);
    assert_eq!(status["done"], status["total"]);
    assert_eq!(status["stage"], "done");
    assert!(status["synthesized_voxels"].as_u64().unwrap() > 0);
    assert!(running_polls > 0, "never seen running");
    let (st, h, file) = get(&c, &s.url(&format!("{location}/file"))).await;
    assert_eq!(st, 200);
    assert_eq!(h["content-type"], "model/gltf-binary");
    assert_eq!(status["bytes"], file.len());
    // The synchronous bake: the same bytes and validator.
    let (st, sync_h, sync) = post_bake(&c, &url, false).await;
    assert_eq!(st, 200);
    assert!(
        file == sync,
        "the async file differs from the synchronous bake"
    );
    assert_eq!(h["etag"], sync_h["etag"]);
    // Revalidation of the file.
    let r = c
        .get(s.url(&format!("{location}/file")))
        .header("if-none-match", h["etag"].to_str().unwrap())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 304);
    // Asked again once done, the file comes at once.
    let (st, _, again) = post_bake(&c, &url, true).await;
    assert_eq!(st, 200);
    assert!(again == file);
    // The metrics count it, and its file's bytes.
    let (st, _, metrics) = get(&c, &s.url("/metrics")).await;
    assert_eq!(st, 200);
    let metrics = String::from_utf8_lossy(&metrics);
    for line in [
        "solidtex_background_jobs{kind=\"bake\",state=\"done\"} 1".to_string(),
        "solidtex_background_jobs{kind=\"bake\",state=\"running\"} 0".to_string(),
        format!("solidtex_background_held_bytes {}", file.len()),
    ] {
        assert!(
            metrics.lines().any(|l| l == line),
            "no `{line}` in\n{metrics}"
        );
    }
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn delete_stops_a_running_bake_and_a_full_queue_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    // One job held at a time; a budget that admits the large bake.
    args.export_queue = 0;
    args.max_export_work = 1 << 36;
    let s = TestServer::start(args).await;
    let c = client();
    let id = ready_texture(&c, &s, 12).await;
    let large = s.url(&format!(
        "/v1/textures/{id}/bake?resolution=2048&texture_size=4096&uvs=atlas"
    ));
    let (st, h, body) = post_bake(&c, &large, true).await;
    assert_eq!(st, 202, "{}", String::from_utf8_lossy(&body));
    let location = h["location"].to_str().unwrap().to_string();
    // Another bake while it runs: the queue is full.
    let small = s.url(&format!(
        "/v1/textures/{id}/bake?resolution=16&texture_size=64"
    ));
    let (st, h, b) = post_bake(&c, &small, true).await;
    assert_error(st, &h, &b, 503, "overloaded");
    assert!(h.contains_key("retry-after"));
    // Once it is synthesizing, cancel it.
    let t0 = Instant::now();
    loop {
        let v = get_json(&c, &s, &location).await;
        assert_eq!(v["state"], "running", "{v}");
        if v["synthesized_voxels"].as_u64().unwrap() > 0 {
            break;
        }
        assert!(t0.elapsed() < Duration::from_secs(120), "{v}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let (st, file_h, b) = get(&c, &s.url(&format!("{location}/file"))).await;
    assert_error(st, &file_h, &b, 409, "bake_running");
    let r = c.delete(s.url(&location)).send().await.unwrap();
    assert_eq!(r.status(), 200);
    let v: Value = r.json().await.unwrap();
    assert_eq!(v["state"], "cancelled", "{v}");
    // The synthesis stops: its count settles, and the slot frees, well
    // before the bake could have finished.
    let stopped = Instant::now();
    let mut last = u64::MAX;
    loop {
        let v = get_json(&c, &s, &location).await;
        assert_eq!(v["state"], "cancelled", "{v}");
        let n = v["synthesized_voxels"].as_u64().unwrap();
        let (st, _, _) = post_bake(&c, &small, true).await;
        if n == last && st != 503 {
            assert!(st == 202 || st == 200, "{st}");
            eprintln!(
                "cancelled at {n} of {} predicted voxels; stopped and freed within {:.1} s",
                v["predicted_voxels"],
                stopped.elapsed().as_secs_f64()
            );
            break;
        }
        last = n;
        assert!(
            stopped.elapsed() < Duration::from_secs(30),
            "still synthesizing after DELETE: {v}"
        );
        tokio::time::sleep(Duration::from_millis(300)).await;
    }
    let v = get_json(&c, &s, &location).await;
    assert!(
        v["done"].as_u64().unwrap() < v["total"].as_u64().unwrap(),
        "{v}"
    );
    let (st, h, b) = get(&c, &s.url(&format!("{location}/file"))).await;
    assert_error(st, &h, &b, 410, "cancelled");
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unknown_jobs_are_404() {
    let (_dir, s, c, id) = server_with_texture(13).await;
    let unknown = "0123456789abcdef0123456789abcdef";
    for path in [
        format!("/v1/bakes/{unknown}"),
        format!("/v1/bakes/{unknown}/file"),
    ] {
        let (st, h, b) = get(&c, &s.url(&path)).await;
        assert_error(st, &h, &b, 404, "unknown_bake");
    }
    let r = c
        .delete(s.url(&format!("/v1/bakes/{unknown}")))
        .send()
        .await
        .unwrap();
    let (st, h) = (r.status().as_u16(), r.headers().clone());
    assert_error(st, &h, &r.bytes().await.unwrap(), 404, "unknown_bake");
    // A bake's id is not an export's.
    let url = s.url(&format!(
        "/v1/textures/{id}/bake?resolution=16&texture_size=64"
    ));
    let (st, h, body) = post_bake(&c, &url, true).await;
    assert!(st == 202 || st == 200, "{}", String::from_utf8_lossy(&body));
    assert_eq!(st, 202, "a new job is not done when it is answered");
    let location = h["location"].to_str().unwrap();
    let bid = location.rsplit('/').next().unwrap();
    let (st, h, b) = get(&c, &s.url(&format!("/v1/exports/{bid}"))).await;
    assert_error(st, &h, &b, 404, "unknown_export");
    let (st, _, _) = get(&c, &s.url(&format!("/v1/bakes/{bid}"))).await;
    assert_eq!(st, 200);
    s.stop().await;
}
