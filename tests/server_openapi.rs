//! `openapi.yaml` is a valid OpenAPI 3 document, describes exactly the
//! routes the router serves, and its parameter sections are the ones
//! generated from their declarations in Rust.

mod common;
mod server_support;

use axum::body::Body;
use axum::http::{Method, Request};
use serde_json::Value;
use solidtex_server::Server;
use solidtex_server::routes::{ROUTES, router};
use std::collections::BTreeSet;
use tower::ServiceExt;

const DOC: &str = include_str!("../openapi.yaml");
const METHODS: [&str; 8] = [
    "get", "put", "post", "delete", "options", "head", "patch", "trace",
];

fn doc_routes() -> BTreeSet<(String, String)> {
    let v: serde_yaml_ng::Value = serde_yaml_ng::from_str(DOC).unwrap();
    let mut out = BTreeSet::new();
    for (path, item) in v["paths"].as_mapping().unwrap() {
        for (k, _) in item.as_mapping().unwrap() {
            let k = k.as_str().unwrap();
            if METHODS.contains(&k) {
                out.insert((k.to_uppercase(), path.as_str().unwrap().to_string()));
            }
        }
    }
    out
}

/// The parameter sections are generated from
/// crates/core/src/params/knobs.rs and the voxel routes' query structs
/// (`solidtex_server::openapi`); with
/// `SOLIDTEX_WRITE_OPENAPI=1` this test writes them into openapi.yaml.
#[test]
fn parameter_sections_are_generated_from_the_knobs() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("openapi.yaml");
    let on_disk = std::fs::read_to_string(&path).unwrap();
    let generated = solidtex_server::openapi::regenerate(&on_disk).unwrap();
    if generated == on_disk {
        return;
    }
    if std::env::var_os("SOLIDTEX_WRITE_OPENAPI").is_some() {
        std::fs::write(&path, &generated).unwrap();
        return;
    }
    let first = on_disk
        .lines()
        .zip(generated.lines())
        .position(|(a, b)| a != b)
        .unwrap_or(on_disk.lines().count().min(generated.lines().count()));
    panic!(
        "openapi.yaml's generated sections are out of date with the knobs of \
         crates/core/src/params/knobs.rs or the query structs of \
         crates/server/src/routes (first difference at line {}).\n\
         Regenerate them with:\n    \
         SOLIDTEX_WRITE_OPENAPI=1 cargo test --release --test server_openapi \
         parameter_sections\nand commit openapi.yaml.",
        first + 1
    );
}

#[test]
fn document_is_openapi_3() {
    // The document is parsed once; the typed check reads those values,
    // which compiles to less code than deserializing the types from YAML.
    let json: Value = serde_yaml_ng::from_str(DOC).unwrap();
    let api: openapiv3::OpenAPI = serde_json::from_value(json.clone()).expect("valid OpenAPI 3.0");
    assert!(api.openapi.starts_with("3.0"));
    assert!(!api.paths.paths.is_empty());
    // Every operation has an id, documents a JSON error, and every
    // response is described.
    for (path, item) in &api.paths.paths {
        let item = item.as_item().expect("inline path items");
        for (method, op) in item.iter() {
            assert!(
                op.operation_id.is_some(),
                "{method} {path} has no operationId"
            );
            assert!(
                op.responses.default.is_some(),
                "{method} {path} has no default error"
            );
            assert!(!op.responses.responses.is_empty(), "{method} {path}");
        }
    }
    // Every $ref resolves inside the document.
    let mut refs = Vec::new();
    collect_refs(&json, &mut refs);
    assert!(!refs.is_empty());
    for r in refs {
        let pointer = r.strip_prefix('#').expect("local ref");
        assert!(json.pointer(pointer).is_some(), "dangling $ref {r}");
    }
}

fn collect_refs(v: &Value, out: &mut Vec<String>) {
    match v {
        Value::Object(m) => {
            for (k, v) in m {
                if k == "$ref" {
                    out.push(v.as_str().unwrap().to_string());
                } else {
                    collect_refs(v, out);
                }
            }
        }
        Value::Array(a) => a.iter().for_each(|v| collect_refs(v, out)),
        _ => {}
    }
}

#[test]
fn route_table_matches_document() {
    let table: BTreeSet<(String, String)> = ROUTES
        .iter()
        .map(|(m, p)| (m.to_string(), p.to_string()))
        .collect();
    assert_eq!(table, doc_routes());
}

/// A concrete URL for a templated path.
fn instantiate(path: &str) -> String {
    path.replace("{id}", "0123456789abcdef0123456789abcdef")
        .replace("{axis}", "z")
        .replace("{at}", "0")
        .replace("{lod}", "0")
        .replace("{bx}", "1")
        .replace("{by}", "2")
        .replace("{bz}", "3")
        .replace("{scale}", "0")
        .replace("{chunk}", "0-32_0-32_0-32")
        .replace("{cz}", "1")
        .replace("{cy}", "2")
        .replace("{cx}", "3")
        .replace("{cc}", "0")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn router_serves_every_documented_route() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::bind(&server_support::test_args(dir.path()))
        .await
        .unwrap();
    server.loaded().await;
    let app = router(server.state());
    let codes_of = |body: &[u8]| -> String {
        serde_json::from_slice::<Value>(body)
            .ok()
            .and_then(|v| v["error"]["code"].as_str().map(str::to_string))
            .unwrap_or_default()
    };
    for (method, path) in doc_routes() {
        let uri = instantiate(&path);
        let req = Request::builder()
            .method(Method::from_bytes(method.as_bytes()).unwrap())
            .uri(&uri)
            .header("content-type", "image/png")
            .body(Body::empty())
            .unwrap();
        let res = app.clone().oneshot(req).await.unwrap();
        let status = res.status();
        let body = axum::body::to_bytes(res.into_body(), 1 << 20)
            .await
            .unwrap();
        let code = codes_of(&body);
        assert!(
            code != "no_route" && code != "method_not_allowed",
            "{method} {uri} is documented but not routed ({status} {code})"
        );
    }
    // And a path that is not documented is not routed.
    for uri in ["/v1/texture", "/v1/textures/x/slices", "/v2/textures"] {
        let req = Request::builder().uri(uri).body(Body::empty()).unwrap();
        let res = app.clone().oneshot(req).await.unwrap();
        let body = axum::body::to_bytes(res.into_body(), 1 << 20)
            .await
            .unwrap();
        assert_eq!(codes_of(&body), "no_route", "{uri}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn served_document_is_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::bind(&server_support::test_args(dir.path()))
        .await
        .unwrap();
    server.loaded().await;
    let app = router(server.state());
    let req = Request::builder()
        .uri("/openapi.yaml")
        .body(Body::empty())
        .unwrap();
    let res = app.oneshot(req).await.unwrap();
    assert_eq!(res.status(), 200);
    let body = axum::body::to_bytes(res.into_body(), 1 << 20)
        .await
        .unwrap();
    assert_eq!(body, DOC.as_bytes());
}
