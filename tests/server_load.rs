//! The server under load: identical concurrent requests share their work,
//! a burst beyond the queue is shed with 503 at once instead of waiting
//! without bound, and the work of a client that hangs up is stopped.

mod common;
mod server_support;

use server_support::*;
use std::time::{Duration, Instant};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn identical_concurrent_requests_compute_their_tiles_once() {
    let dir = tempfile::tempdir().unwrap();
    let c = client();
    let path = |id: &str| format!("/v1/textures/{id}/slices/z/3.png?u0=-5&v0=7&w=24&h=20");

    // What one request computes from a cold cache.
    let s = TestServer::start(test_args(dir.path())).await;
    let id = ready_texture(&c, &s, 20).await;
    let (st, _, reference) = get(&c, &s.url(&path(&id))).await;
    assert_eq!(st, 200);
    let text = metrics(&c, &s).await;
    let one_tiles = metric(&text, "solidtex_synth_tiles_computed_total");
    let one_voxels = metric(&text, "solidtex_synth_voxels_total{level=\"0\"}");
    assert!(one_tiles > 0.0 && one_voxels > 0.0);
    s.stop().await;

    // 32 clients asking for the same thing at once on a fresh server (the
    // texture is loaded from disk, the cache is cold).
    let s = TestServer::start(test_args(dir.path())).await;
    let url = s.url(&path(&id));
    let tasks: Vec<_> = (0..32)
        .map(|_| {
            let (c, url) = (c.clone(), url.clone());
            tokio::spawn(async move { get(&c, &url).await })
        })
        .collect();
    for t in tasks {
        let (st, _, body) = t.await.unwrap();
        assert_eq!(st, 200);
        assert!(body == reference, "every client gets the same bytes");
    }
    let text = metrics(&c, &s).await;
    assert_eq!(
        metric(&text, "solidtex_synth_tiles_computed_total"),
        one_tiles,
        "the tiles were computed once, not once per request"
    );
    assert_eq!(
        metric(&text, "solidtex_synth_voxels_total{level=\"0\"}"),
        one_voxels
    );
    // The other 31 got them from the cache or by waiting for the first.
    let shared = metric(&text, "solidtex_synth_tiles_from_cache_total");
    assert!(shared >= 31.0, "{shared} tiles shared");
    assert_eq!(metric(&text, "solidtex_jobs_rejected_total"), 0.0);
    if cfg!(target_os = "linux") {
        let rss = metric(&text, "solidtex_process_resident_bytes");
        assert!(rss > 0.0 && rss < 64.0 * 1024.0 * 1024.0 * 1024.0, "{rss}");
        assert!(metric(&text, "solidtex_process_threads") >= 2.0);
    }
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_burst_of_1000_requests_is_shed_with_503_not_queued() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.max_jobs = 1;
    args.queue = 4;
    let s = TestServer::start(args).await;
    let c = client();
    let id = ready_texture(&c, &s, 21).await;
    // 1000 distinct, far-apart bricks: each is real work, none shares tiles.
    let t0 = Instant::now();
    let tasks: Vec<_> = (0..1000i64)
        .map(|i| {
            let c = c.clone();
            let url = s.url(&format!(
                "/v1/textures/{id}/bricks/0/{}_{}_{}.raw",
                i * 1009,
                -i * 131,
                i % 7
            ));
            tokio::spawn(async move {
                let t = Instant::now();
                let r = c.get(url).send().await.unwrap();
                let status = r.status().as_u16();
                let retry = r.headers().get("retry-after").cloned();
                let body = r.bytes().await.unwrap();
                (status, retry, body.len(), t.elapsed())
            })
        })
        .collect();
    let (mut ok, mut shed) = (0u32, 0u32);
    let mut shed_latency = Vec::new();
    for t in tasks {
        let (status, retry, len, took) = t.await.unwrap();
        match status {
            200 => {
                assert_eq!(len, 16 * 16 * 16 * 3);
                ok += 1;
            }
            503 => {
                // The predicted wait, at least a second.
                let retry: u32 = retry.unwrap().to_str().unwrap().parse().unwrap();
                assert!(retry >= 1);
                shed_latency.push(took);
                shed += 1;
            }
            other => panic!("unexpected status {other}"),
        }
    }
    let burst = t0.elapsed();
    assert_eq!(ok + shed, 1000);
    // One running and four waiting are admitted; only requests arriving
    // after one of those finished can be admitted too.
    assert!(ok >= 5, "{ok} answered");
    assert!(shed >= 900, "{shed} shed, {ok} answered in {burst:?}");
    // Shedding is immediate: a refused request never waits for a slot.
    shed_latency.sort();
    let median = shed_latency[shed_latency.len() / 2];
    assert!(
        median < Duration::from_secs(2),
        "median 503 took {median:?}"
    );
    let text = metrics(&c, &s).await;
    assert_eq!(
        metric(&text, "solidtex_jobs_rejected_total"),
        f64::from(shed)
    );
    assert_eq!(metric(&text, "solidtex_jobs_queued"), 0.0);
    assert_eq!(metric(&text, "solidtex_jobs_running"), 0.0);
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_that_hangs_up_stops_its_synthesis() {
    use std::io::Write;
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.max_jobs = 1;
    // Over the default budget: this test is about hanging up.
    args.max_request_work = 64 << 20;
    let s = TestServer::start(args).await;
    let c = client();
    let id = ready_texture(&c, &s, 22).await;
    // A large cold slice: seconds of work.
    let addr = s
        .url("")
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .to_string();
    let mut conn = std::net::TcpStream::connect(&addr).unwrap();
    let request = format!(
        "GET /v1/textures/{id}/slices/z/9.png?w=1024&h=1024 HTTP/1.1\r\nHost: {addr}\r\n\r\n"
    );
    conn.write_all(request.as_bytes()).unwrap();
    let started = Instant::now();
    while metric(&metrics(&c, &s).await, "solidtex_jobs_running") < 1.0 {
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "the job never ran"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    drop(conn);
    let hung_up = Instant::now();
    loop {
        let text = metrics(&c, &s).await;
        if metric(&text, "solidtex_jobs_running") == 0.0 {
            assert_eq!(metric(&text, "solidtex_jobs_cancelled_total"), 1.0);
            break;
        }
        assert!(
            hung_up.elapsed() < Duration::from_secs(60),
            "the job kept running after its client left"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    // The server still answers, and the same slice, asked for properly, is
    // whole: nothing half-computed was kept.
    let path = format!("/v1/textures/{id}/slices/z/9.png?w=64&h=64");
    let (st, _, small) = get(&c, &s.url(&path)).await;
    assert_eq!(st, 200);
    s.stop().await;
    let fresh = TestServer::start(test_args(dir.path())).await;
    let (st, _, reference) = get(&c, &fresh.url(&path)).await;
    assert_eq!(st, 200);
    assert!(
        small == reference,
        "same bytes as a server that never cancelled"
    );
    fresh.stop().await;
}
