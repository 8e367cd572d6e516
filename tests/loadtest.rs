//! `solidtex loadtest` against a real server: the library entry point with
//! a mixed workload, and the command line with a plane sweep and JSON.

mod common;
mod server_support;

use serde_json::Value;
use server_support::*;
use solidtex::loadtest::workload::Kind;
use solidtex::loadtest::{LoadConfig, run};
use std::time::Duration;

fn small(base: &str, id: &str) -> LoadConfig {
    LoadConfig {
        concurrency: 4,
        duration: Duration::from_secs(2),
        side: 16,
        lod: 1,
        overlap: 0.5,
        revalidate: 0.2,
        timeout: Duration::from_secs(60),
        ..LoadConfig::new(base, id)
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mixed_load_is_measured_and_a_rerun_hits_the_cache() {
    let (_dir, s, _c, id) = server_with_texture(30).await;

    let first = run(&small(&s.base, &id)).await.unwrap();
    let t = &first.total;
    assert!(t.requests >= 4, "{t:?}");
    assert_eq!(t.statuses.other, 0, "{t:?}");
    assert_eq!(t.statuses.transport_errors, 0, "{t:?}");
    assert_eq!(t.statuses.total(), t.requests);
    assert!(t.p50_ms > 0.0 && t.p50_ms <= t.p99_ms && t.p99_ms <= t.max_ms);
    assert!(t.megabytes_per_s > 0.0);
    let per_kind: u64 = first.kinds.iter().map(|k| k.requests).sum();
    assert_eq!(per_kind, t.requests);
    let d1 = first.server.clone().expect("the server exposes metrics");
    assert!(d1.voxels_synthesized > 0.0 && d1.tiles_computed > 0.0);
    assert_eq!(d1.cache_max_bytes, 64.0 * 1024.0 * 1024.0);
    if cfg!(target_os = "linux") {
        // Checked against the bound the server reports for itself.
        assert!(d1.peaks.least_margin_bytes.is_some());
        assert_eq!(d1.resident_within_budget, Some(true));
        assert!(d1.peaks.resident_bytes > 0.0);
    }
    assert!(first.table().contains("tiles"));
    assert_eq!(first.cuts_per_s, None);

    // The same seed replays the same requests: those come from the cache,
    // so the rerun corrects fewer voxels per request (it may go on past
    // them into new ones, which cost what the first run's did).
    let again = run(&small(&s.base, &id)).await.unwrap();
    let d2 = again.server.unwrap();
    let per_request =
        |d: &solidtex::loadtest::scrape::ServerDelta, n: u64| d.corrections / n as f64;
    assert!(
        per_request(&d2, again.total.requests) < per_request(&d1, t.requests),
        "{} corrections in {} requests, then {} in {}",
        d1.corrections,
        t.requests,
        d2.corrections,
        again.total.requests
    );
    assert!(d2.tile_hit_rate > 0.0);
    assert!(again.total.requests >= t.requests);
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn command_line_sweep_reports_json() {
    let (_dir, s, _c, id) = server_with_texture(31).await;
    let base = s.base.clone();
    let out = tokio::task::spawn_blocking(move || {
        std::process::Command::new(env!("CARGO_BIN_EXE_solidtex"))
            .args(["loadtest", "--url", &base, "--texture", &id])
            .args(["--sweep", "--size", "8", "--lod", "2", "--duration", "8s"])
            .args(["--concurrency", "1", "--json"])
            .output()
            .unwrap()
    })
    .await
    .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["kinds"].as_array().unwrap().len(), 1);
    assert_eq!(v["kinds"][0]["kind"], Kind::Slice.name());
    let requests = v["total"]["requests"].as_u64().unwrap();
    assert!(requests >= 1, "{v}");
    assert_eq!(v["total"]["statuses"]["ok"].as_u64().unwrap(), requests);
    // Consecutive planes share tiles (tiles are 4 voxels thick), so of any
    // five consecutive planes at least three are served from the cache.
    if requests >= 5 {
        assert!(
            v["server"]["tiles_from_cache"].as_f64().unwrap() > 0.0,
            "{v}"
        );
    }
    assert!(v["workload"].as_str().unwrap().starts_with("sweep"));
    assert_eq!(v["cuts_per_s"], v["total"]["requests_per_s"]);
    s.stop().await;
}

/// A short soak: the load runs with uploads, deletions and hang-ups beside
/// it, nothing answers a server error, and the sampled answers are byte
/// for byte those of a fresh server that saw nothing else.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_soak_with_churn_matches_a_fresh_server() {
    let (dir, fresh_dir) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let s = TestServer::start(test_args(dir.path())).await;
    let fresh = TestServer::start(test_args(fresh_dir.path())).await;
    let c = client();
    let id = ready_texture(&c, &s, 31).await;
    assert_eq!(ready_texture(&c, &fresh, 31).await, id);
    let cfg = LoadConfig {
        duration: Duration::from_secs(3),
        churn: true,
        verify_url: Some(fresh.base.clone()),
        ..small(&s.base, &id)
    };
    let r = run(&cfg).await.unwrap();
    assert_eq!(r.total.statuses.other, 0, "{}", r.table());
    assert_eq!(r.total.statuses.transport_errors, 0, "{}", r.table());
    let churn = r.churn.clone().expect("churn ran");
    assert!(churn.uploads >= 1 && churn.deletes >= 1, "{churn:?}");
    assert!(churn.served >= 1, "{churn:?}");
    assert_eq!(churn.server_errors(), 0, "{churn:?}");
    let v = r.verify.clone().expect("verified");
    assert!(v.checked >= 4, "{v:?}");
    assert_eq!((v.mismatched, v.failed), (0, 0), "{v:?}");
    assert!(r.table().contains("verified against a fresh server"));
    s.stop().await;
    fresh.stop().await;
}
