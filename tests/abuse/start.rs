//! A restart over many textures: the server listens and answers liveness
//! at once, loads its textures in the background (readiness says when),
//! and a request for a texture not loaded yet waits for it or is answered
//! 503 with Retry-After, never 404.

use crate::server_support::*;

/// A sketch variant body: two curves whose bend depends on `k`.
fn sketch(k: u32) -> String {
    format!(
        r#"{{"field": {{"kind": "sketch", "curves": [
            {{"points": [[2, 0, 0], [{}, 16, 0], [6, 31, 0]], "normal": [0, 0, 1]}},
            {{"points": [[26, 31, 0], [29, 0, 0]], "normal": [0, 0, 1]}}
        ]}}}}"#,
        4 + k
    )
}

fn slice_path(id: &str) -> String {
    format!("/v1/textures/{id}/slices/z/0.png?w=32&h=32")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_restart_answers_liveness_while_its_textures_load() {
    const VARIANTS: u32 = 8;
    let (dir, s, c, plain) = server_with_texture(31).await;
    let mut ids = vec![plain.clone()];
    for k in 0..VARIANTS {
        let url = s.url(&format!("/v1/textures/{plain}/variants"));
        let (status, v) = post_body(&c, &url, "application/json", sketch(k)).await;
        assert!(status == 201 || status == 202, "{status} {v}");
        let id = v["id"].as_str().unwrap().to_string();
        wait_ready(&c, &s, &id).await;
        ids.push(id);
    }
    let mut before = Vec::new();
    for id in &ids {
        let (st, _, body) = get(&c, &s.url(&slice_path(id))).await;
        assert_eq!(st, 200);
        before.push(body);
    }
    s.stop().await;

    // Asked at once, with no wait allowed: alive, not ready, and a list
    // that would leave textures out is refused, to be asked again.
    let b = BinaryServer::start(
        dir.path(),
        &[
            ("SOLIDTEX_DEFAULT_TEXTURE", "false"),
            ("SOLIDTEX_PENDING_WAIT", "0"),
        ],
    );
    let (st, _, _) = get(&c, &b.url("/healthz")).await;
    assert_eq!(st, 200);
    let (st, h, body) = get(&c, &b.url("/readyz")).await;
    assert_eq!(
        (st, String::from_utf8_lossy(&body).contains("\"loading\"")),
        (503, true),
        "{}",
        String::from_utf8_lossy(&body)
    );
    assert_eq!(h["retry-after"], "1");
    let (st, h, body) = get(&c, &b.url("/v1/textures")).await;
    let v: serde_json::Value = serde_json::from_slice(&body).unwrap();
    assert_eq!((st, v["error"]["code"].as_str()), (503, Some("starting")));
    assert_eq!(h["retry-after"], "1");
    // Ready once every texture is loaded, each as it was.
    let t0 = std::time::Instant::now();
    while get(&c, &b.url("/readyz")).await.0 != 200 {
        assert!(t0.elapsed().as_secs() < 120, "never ready");
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
    let v = get_json_url(&c, &b.url("/v1/textures")).await;
    assert_eq!(v["textures"].as_array().unwrap().len(), ids.len(), "{v}");
    drop(b);

    // With the default wait, the texture loaded last is answered, not 404.
    let b = BinaryServer::start(dir.path(), &[("SOLIDTEX_DEFAULT_TEXTURE", "false")]);
    let mut answers = Vec::new();
    for id in ids.iter().rev() {
        let (st, _, body) = get(&c, &b.url(&slice_path(id))).await;
        assert_eq!(st, 200, "{}", String::from_utf8_lossy(&body));
        answers.push(body);
    }
    answers.reverse();
    assert!(answers == before, "answers changed across the restart");
}
