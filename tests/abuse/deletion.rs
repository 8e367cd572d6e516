//! Deleting a texture stops its precompute: the core it kept busy, the
//! memory it reserved and its place in the queue are free within a second,
//! and the next upload is precomputed at once.

use crate::server_support::*;
use std::time::{Duration, Instant};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn deleting_a_texture_stops_its_running_precompute() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.max_upload_bytes = 1 << 20;
    let s = TestServer::start(args).await;
    let c = client();
    let pending = || metric(&s.state.metrics.encode(), "solidtex_precomputes_pending");
    // A 256² exemplar with the default parameters: tens of seconds of
    // precompute on two cores.
    let (status, v) = upload(&c, &s, exemplar_png(256, 41), "").await;
    assert_eq!(status, 202, "{v}");
    let id = v["id"].as_str().unwrap().to_string();
    let t0 = Instant::now();
    while s.state.registry.precompute_reserved().0 == 0 {
        assert!(t0.elapsed() < Duration::from_secs(30), "never started");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    // Well into its analysis and search.
    tokio::time::sleep(Duration::from_millis(1500)).await;
    assert_eq!(pending(), 1.0);
    assert_eq!(delete(&c, &s.url(&format!("/v1/textures/{id}"))).await, 204);
    let deleted = Instant::now();
    while s.state.registry.precompute_reserved().0 > 0 || pending() > 0.0 {
        assert!(
            deleted.elapsed() < Duration::from_secs(1),
            "the precompute still runs {:?} after its texture was deleted",
            deleted.elapsed()
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let text = s.state.metrics.encode();
    assert_eq!(
        metric(&text, r#"solidtex_precomputes_total{outcome="cancelled"}"#),
        1.0,
        "{text}"
    );
    assert_eq!(
        metric(&text, r#"solidtex_precomputes_total{outcome="ok"}"#),
        0.0
    );
    // Gone for good, and the next upload has the precompute slot at once.
    assert_eq!(get(&c, &s.url(&format!("/v1/textures/{id}"))).await.0, 404);
    assert!(!dir.path().join("textures").join(&id).exists());
    let next = Instant::now();
    ready_texture(&c, &s, 42).await;
    assert!(
        next.elapsed() < Duration::from_secs(20),
        "{:?}",
        next.elapsed()
    );
    s.stop().await;
}
