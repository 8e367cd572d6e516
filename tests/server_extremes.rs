//! Every voxel route against extreme values of every one of its numbers:
//! whatever a client sends, the answer is a success or a JSON 4xx (or a
//! 503 with Retry-After), never a 5xx, a hang or a crash; sizes, counts
//! and costs are multiplied with checked arithmetic.

mod common;
mod server_support;

use serde_json::Value;
use server_support::*;
use std::time::{Duration, Instant};

/// Integers around every width a size or coordinate is kept in, and text
/// that is almost a number.
const INTEGERS: &[&str] = &[
    "0",
    "1",
    "-1",
    "4096",
    "4097",
    "65535",
    "65536",
    "2147483647",
    "2147483648",
    "-2147483648",
    "-2147483649",
    "4294967295",
    "4294967296",
    "16777216",
    "9223372036854775807",
    "-9223372036854775808",
    "18446744073709551615",
    "99999999999999999999999999",
    "1e3",
    "NaN",
    "",
    "0x10",
    "+7",
    "%00",
];

/// Vectors with huge, tiny, non-finite and missing components.
const VECTORS: &[&str] = &[
    "0,0,0",
    "1e308,0,0",
    "-1e308,1e308,1e308",
    "inf,0,0",
    "NaN,1,1",
    "5e-324,0,0",
    "2147483647,0,0",
    "2147483648,0,0",
    "1000,0,0",
    "1,1",
    "1,2,3,4",
    "a,b,c",
    "",
];

/// One request for each (route, parameter, extreme value); the other
/// parameters are small, so that what is accepted is cheap.
fn requests(id: &str) -> Vec<String> {
    let mut out = Vec::new();
    let slice = ["at", "u0", "v0", "w", "h", "lod"];
    for p in slice {
        for v in INTEGERS {
            let at = if p == "at" { v } else { "3" };
            let mut q = vec![("w", "8"), ("h", "8")];
            q.retain(|(k, _)| *k != p);
            if p != "at" {
                q.push((p, v));
            }
            let q: Vec<String> = q.iter().map(|(k, v)| format!("{k}={v}")).collect();
            out.push(format!(
                "/v1/textures/{id}/slices/z/{at}.png?{}",
                q.join("&")
            ));
        }
    }
    for p in ["x", "y", "z", "w", "h", "d", "lod"] {
        for v in INTEGERS {
            let mut q = vec![("w", "4"), ("h", "4"), ("d", "4")];
            q.retain(|(k, _)| *k != p);
            q.push((p, v));
            let q: Vec<String> = q.iter().map(|(k, v)| format!("{k}={v}")).collect();
            out.push(format!("/v1/textures/{id}/region.raw?{}", q.join("&")));
        }
    }
    for p in ["origin", "u", "v"] {
        for v in VECTORS {
            out.push(format!("/v1/textures/{id}/cut.png?w=8&h=8&{p}={v}"));
            out.push(format!(
                "/v1/textures/{id}/cut.png?w=8&h=8&filter=trilinear&{p}={v}"
            ));
        }
    }
    for p in ["w", "h", "lod"] {
        for v in INTEGERS {
            let mut q = vec![("w", "8"), ("h", "8")];
            q.retain(|(k, _)| *k != p);
            q.push((p, v));
            let q: Vec<String> = q.iter().map(|(k, v)| format!("{k}={v}")).collect();
            out.push(format!(
                "/v1/textures/{id}/cut.png?u=0.6,0.8,0&v=0,0,1&{}",
                q.join("&")
            ));
        }
    }
    for v in INTEGERS {
        out.push(format!("/v1/textures/{id}/bricks/{v}/0_0_0.raw"));
        out.push(format!("/v1/textures/{id}/bricks/0/{v}_0_0.raw"));
        out.push(format!("/v1/textures/{id}/bricks/0/0_{v}_-1.raw"));
        out.push(format!("/v1/textures/{id}/zarr/{v}/zarr.json"));
        out.push(format!("/v1/textures/{id}/zarr/0/c/{v}/0/0/0"));
        out.push(format!("/v1/textures/{id}/zarr/0/c/0/0/{v}/0"));
        out.push(format!("/v1/textures/{id}/zarr/0/c/0/0/0/{v}"));
        out.push(format!("/v1/textures/{id}/precomputed/{v}/0-16_0-16_0-16"));
        out.push(format!("/v1/textures/{id}/precomputed/0/{v}-16_0-16_0-16"));
        out.push(format!("/v1/textures/{id}/precomputed/0/0-{v}_0-16_0-16"));
    }
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_voxel_route_survives_extreme_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    // Whatever is accepted stays cheap, so that the sweep is quick.
    args.max_request_work = 200_000;
    let s = TestServer::start(args).await;
    let c = client();
    let id = ready_texture(&c, &s, 5).await;
    let urls = requests(&id);
    assert!(urls.len() > 400, "{}", urls.len());
    let mut statuses = std::collections::BTreeMap::<u16, usize>::new();
    for path in &urls {
        let t0 = Instant::now();
        let r = c.get(s.url(path)).send().await;
        let r = r.unwrap_or_else(|e| panic!("{path}: {e}"));
        let status = r.status().as_u16();
        let headers = r.headers().clone();
        let body = r.bytes().await.unwrap();
        let took = t0.elapsed();
        *statuses.entry(status).or_default() += 1;
        assert!(
            took < Duration::from_secs(20),
            "{path} took {took:?} (status {status})"
        );
        match status {
            200 => assert!(!body.is_empty(), "{path}"),
            400..=499 | 503 => {
                let v: Value = serde_json::from_slice(&body)
                    .unwrap_or_else(|_| panic!("{path}: {status} body is not JSON: {body:?}"));
                assert!(v["error"]["code"].is_string(), "{path}: {v}");
                if status == 503 {
                    assert!(headers.contains_key("retry-after"), "{path}");
                }
            }
            _ => panic!(
                "{path}: status {status}: {}",
                String::from_utf8_lossy(&body)
            ),
        }
    }
    println!("{} requests: {statuses:?}", urls.len());
    // The sweep reached both sides: some extremes are served, most refused.
    assert!(statuses.get(&200).is_some_and(|&n| n > 20), "{statuses:?}");
    assert!(statuses.get(&400).is_some_and(|&n| n > 100), "{statuses:?}");
    // And the server is still well.
    let (st, _, _) = get(&c, &s.url("/healthz")).await;
    assert_eq!(st, 200);
    s.stop().await;
}
