//! The server across its life: restart from the data directory, recovery of
//! interrupted or damaged precomputes, graceful shutdown of the real binary
//! on SIGTERM, and many concurrent clients.

mod common;
mod server_support;

use serde_json::Value;
use server_support::*;
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Requests whose answers must not change across restarts and load.
fn sample_paths(id: &str) -> Vec<String> {
    vec![
        format!("/v1/textures/{id}/slices/z/3.png?u0=-4&v0=5&w=20&h=12"),
        format!("/v1/textures/{id}/slices/x/-2.png?w=10&h=10&lod=1"),
        format!("/v1/textures/{id}/cut.png?origin=1.5,2,3&u=0.6,0.8,0&v=0,0,1&w=12&h=9"),
        format!("/v1/textures/{id}/region.raw?x=1&y=-3&z=2&w=9&h=5&d=4"),
        format!("/v1/textures/{id}/bricks/0/0_-1_1.raw"),
        format!("/v1/textures/{id}/bricks/2/1_1_1.raw"),
    ]
}

async fn fetch_all(
    c: &reqwest::Client,
    s: &TestServer,
    paths: &[String],
) -> Vec<(Vec<u8>, String)> {
    let mut out = Vec::new();
    for p in paths {
        let (st, h, b) = get(c, &s.url(p)).await;
        assert_eq!(st, 200, "{p}: {}", String::from_utf8_lossy(&b));
        out.push((b, h["etag"].to_str().unwrap().to_string()));
    }
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn restart_serves_identical_bytes_without_recomputing() {
    let (dir, s, c, id) = server_with_texture(11).await;
    let before = fetch_all(&c, &s, &sample_paths(&id)).await;
    let meta_before: Value = get_json(&c, &s, &format!("/v1/textures/{id}")).await;
    s.stop().await;

    let s = TestServer::start(test_args(dir.path())).await;
    // Ready from the first request on: no precompute ran.
    let meta: Value = get_json(&c, &s, &format!("/v1/textures/{id}")).await;
    assert_eq!(meta["status"], "ready");
    assert_eq!(meta["params"], meta_before["params"]);
    assert_eq!(meta["created"], meta_before["created"]);
    let after = fetch_all(&c, &s, &sample_paths(&id)).await;
    assert_eq!(before, after, "bytes and ETags survive a restart");
    let text = metrics(&c, &s).await;
    assert_eq!(
        metric(&text, r#"solidtex_precomputes_total{outcome="ok"}"#),
        0.0,
        "{text}"
    );
    assert_eq!(
        metric(&text, "solidtex_precompute_duration_seconds_count"),
        0.0
    );
    assert_eq!(metric(&text, "solidtex_textures_loaded_total"), 1.0);
    // Uploading it again is known at once.
    let (st, v) = upload(&c, &s, exemplar_png(32, 11), SMALL_PARAMS).await;
    assert_eq!((st, v["id"].as_str().unwrap()), (201, id.as_str()));
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn interrupted_or_damaged_precomputes_are_redone() {
    let (dir, s, c, a) = server_with_texture(12).await;
    let b = ready_texture(&c, &s, 13).await;
    let f = ready_texture(&c, &s, 14).await;
    let ref_a = fetch_all(&c, &s, &sample_paths(&a)).await;
    let ref_b = fetch_all(&c, &s, &sample_paths(&b)).await;
    s.stop().await;

    let tex = dir.path().join("textures");
    // a: the precompute was interrupted (metadata still pending, no .stx,
    // a torn temporary file).
    let meta_path = tex.join(&a).join("meta.json");
    let mut meta: Value = serde_json::from_slice(&std::fs::read(&meta_path).unwrap()).unwrap();
    meta["status"] = "pending".into();
    std::fs::write(&meta_path, serde_json::to_vec(&meta).unwrap()).unwrap();
    std::fs::remove_file(tex.join(&a).join("candidates.stx")).unwrap();
    std::fs::write(tex.join(&a).join(".candidates.stx.99.tmp"), b"torn").unwrap();
    // b: its candidate file is damaged.
    let stx = tex.join(&b).join("candidates.stx");
    let mut bytes = std::fs::read(&stx).unwrap();
    let n = bytes.len();
    bytes.truncate(n / 2);
    std::fs::write(&stx, bytes).unwrap();
    // f: recorded as failed.
    let meta_path = tex.join(&f).join("meta.json");
    let mut meta: Value = serde_json::from_slice(&std::fs::read(&meta_path).unwrap()).unwrap();
    meta["status"] = "failed".into();
    meta["reason"] = "out of memory".into();
    std::fs::write(&meta_path, serde_json::to_vec(&meta).unwrap()).unwrap();
    // Debris of an upload that crashed before its metadata was written.
    std::fs::create_dir_all(tex.join("feedfeedfeedfeedfeedfeedfeedfeed")).unwrap();

    let s = TestServer::start(test_args(dir.path())).await;
    assert!(!tex.join(&a).join(".candidates.stx.99.tmp").exists());
    assert!(!tex.join("feedfeedfeedfeedfeedfeedfeedfeed").exists());
    // Never served half-made: either pending (409) or recomputed.
    for id in [&a, &b] {
        let (st, h, body) = get(&c, &s.url(&sample_paths(id)[0])).await;
        if st != 200 {
            assert_error(st, &h, &body, 409, "texture_pending");
        }
    }
    wait_ready(&c, &s, &a).await;
    wait_ready(&c, &s, &b).await;
    assert_eq!(fetch_all(&c, &s, &sample_paths(&a)).await, ref_a);
    assert_eq!(fetch_all(&c, &s, &sample_paths(&b)).await, ref_b);
    let text = metrics(&c, &s).await;
    assert_eq!(
        metric(&text, r#"solidtex_precomputes_total{outcome="ok"}"#),
        2.0,
        "{text}"
    );
    assert_eq!(metric(&text, "solidtex_textures_loaded_total"), 0.0);

    // The failed one says why, and voxel requests get 409.
    let v: Value = get_json(&c, &s, &format!("/v1/textures/{f}")).await;
    assert_eq!(v["status"], "failed");
    assert_eq!(v["reason"], "out of memory");
    let (st, h, body) = get(&c, &s.url(&sample_paths(&f)[0])).await;
    assert_error(st, &h, &body, 409, "texture_failed");
    // Uploading it again retries.
    let (st, v) = upload(&c, &s, exemplar_png(32, 14), SMALL_PARAMS).await;
    assert_eq!((st, v["id"].as_str().unwrap()), (202, f.as_str()));
    wait_ready(&c, &s, &f).await;
    s.stop().await;

    // Everything persisted: a third start loads all three.
    let s = TestServer::start(test_args(dir.path())).await;
    let text = metrics(&c, &s).await;
    assert_eq!(
        metric(&text, "solidtex_textures_loaded_total"),
        3.0,
        "{text}"
    );
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn concurrent_clients_match_a_sequential_client() {
    let (dir, s, c, id) = server_with_texture(15).await;
    // Overlapping slices and bricks at two levels of detail.
    let mut paths = Vec::new();
    for k in 0..4i64 {
        paths.push(format!(
            "/v1/textures/{id}/slices/z/{k}.png?u0={}&v0=-3&w=20&h=16",
            k * 5
        ));
        paths.push(format!(
            "/v1/textures/{id}/slices/y/{}.png?w=16&h=16&lod=1",
            k * 3
        ));
        paths.push(format!("/v1/textures/{id}/bricks/0/{}_0_0.raw", k - 1));
        paths.push(format!("/v1/textures/{id}/bricks/1/0_{}_0.raw", k - 2));
    }
    let reference = fetch_all(&c, &s, &paths).await;
    s.stop().await;

    // A fresh server (cold cache, loaded from disk) under 64 clients, each
    // asking for every request in its own order.
    let s = TestServer::start(test_args(dir.path())).await;
    let paths = std::sync::Arc::new(paths);
    let mut tasks = Vec::new();
    for client_no in 0..64usize {
        let c = client();
        let paths = paths.clone();
        let base = s.base.clone();
        tasks.push(tokio::spawn(async move {
            let n = paths.len();
            let mut got = vec![Vec::new(); n];
            for step in 0..n {
                let i = (step * 7 + client_no * 5) % n;
                let r = c.get(format!("{base}{}", paths[i])).send().await.unwrap();
                assert_eq!(r.status().as_u16(), 200);
                got[i] = r.bytes().await.unwrap().to_vec();
            }
            got
        }));
    }
    for t in tasks {
        let got = t.await.unwrap();
        for (i, bytes) in got.iter().enumerate() {
            assert!(
                bytes == &reference[i].0,
                "client result differs for {}",
                paths[i]
            );
        }
    }
    let text = metrics(&c, &s).await;
    assert_eq!(metric(&text, "solidtex_jobs_rejected_total"), 0.0);
    s.stop().await;
}

/// Reads the `listening on` line the binary prints.
fn listening_addr(child: &mut std::process::Child) -> String {
    let out = child.stdout.take().unwrap();
    let mut line = String::new();
    BufReader::new(out).read_line(&mut line).unwrap();
    line.trim()
        .strip_prefix("solidtex listening on ")
        .unwrap_or_else(|| panic!("unexpected first line {line:?}"))
        .to_string()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn binary_shuts_down_gracefully_on_sigterm() {
    let dir = tempfile::tempdir().unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_solidtex"))
        .arg("serve")
        .env("SOLIDTEX_ADDR", "127.0.0.1:0")
        .env("SOLIDTEX_DATA_DIR", dir.path())
        .env("SOLIDTEX_BRICK_SIZE", "32")
        .env("SOLIDTEX_WORKER_THREADS", "1")
        .env("SOLIDTEX_PRECOMPUTE_THREADS", "2")
        .env("SOLIDTEX_MAX_PRECOMPUTES", "2")
        .env("SOLIDTEX_LOG_FORMAT", "json")
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let base = listening_addr(&mut child);
    assert!(base.starts_with("http://127.0.0.1:"), "{base}");
    let c = client();

    // The bundled exemplar is registered at start.
    let v: Value = get_json_url(&c, &format!("{base}/v1/textures/default")).await;
    assert_eq!(v["id"], "default");
    assert_eq!(v["exemplar"]["width"], 128);
    assert_eq!(v["brick_size"], 32, "configured from the environment");
    // Not ready while it is registered and precomputed.
    let r = c.get(format!("{base}/readyz")).send().await.unwrap();
    if r.status().as_u16() == 503 {
        let status = r.json::<Value>().await.unwrap()["status"].clone();
        assert!(status == "loading" || status == "starting", "{status}");
    } else {
        let v: Value = get_json_url(&c, &format!("{base}/v1/textures/default")).await;
        assert_eq!(v["status"], "ready");
    }

    // A small texture of our own, then a request in flight at SIGTERM.
    let r = c
        .post(format!("{base}/v1/textures?{SMALL_PARAMS}"))
        .header("content-type", "image/png")
        .body(exemplar_png(32, 16))
        .send()
        .await
        .unwrap();
    let id = r.json::<Value>().await.unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string();
    let t0 = Instant::now();
    loop {
        let v: Value = get_json_url(&c, &format!("{base}/v1/textures/{id}")).await;
        if v["status"] == "ready" {
            break;
        }
        assert!(t0.elapsed() < Duration::from_secs(120));
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    let slow = {
        let c = c.clone();
        let url = format!("{base}/v1/textures/{id}/bricks/0/5_5_5.raw");
        tokio::spawn(async move { c.get(url).send().await })
    };
    tokio::time::sleep(Duration::from_millis(150)).await;
    let killed = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());

    // The request in flight is answered in full…
    let r = slow.await.unwrap().expect("in-flight request answered");
    assert_eq!(r.status().as_u16(), 200);
    assert_eq!(r.bytes().await.unwrap().len(), 32 * 32 * 32 * 3);
    // …and the process exits 0 promptly, abandoning the background
    // precompute of the default texture.
    let t0 = Instant::now();
    let status = loop {
        if let Some(st) = child.try_wait().unwrap() {
            break st;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "server did not exit"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    };
    assert!(status.success(), "exit status {status}");
    // No longer accepting.
    assert!(c.get(format!("{base}/healthz")).send().await.is_err());
}
