//! Fields over HTTP: a field given at upload is part of the texture;
//! variants change a texture's synthesis parameters (its field, its seed)
//! without a new precompute and are found again by content; the frames
//! route samples the field on a slice for drawing.

mod common;
mod server_support;

use serde_json::{Value, json};
use server_support::*;

/// POSTs `body` (JSON text) as a variant of `id`; returns (status, body).
async fn variant(c: &reqwest::Client, s: &TestServer, id: &str, body: &str) -> (u16, Value) {
    let r = c
        .post(s.url(&format!("/v1/textures/{id}/variants")))
        .header("content-type", "application/json")
        .body(body.to_string())
        .send()
        .await
        .unwrap();
    let status = r.status().as_u16();
    (status, r.json().await.unwrap())
}

/// A variant that must be created or found; waits until it is ready and
/// returns its id.
async fn ready_variant(c: &reqwest::Client, s: &TestServer, id: &str, body: &str) -> String {
    let (status, v) = variant(c, s, id, body).await;
    assert!(status == 201 || status == 202, "{status} {v}");
    let vid = v["id"].as_str().unwrap().to_string();
    wait_ready(c, s, &vid).await;
    vid
}

async fn slice(c: &reqwest::Client, s: &TestServer, id: &str) -> Vec<u8> {
    let (st, _, body) = get(
        c,
        &s.url(&format!("/v1/textures/{id}/slices/z/0.png?w=48&h=48")),
    )
    .await;
    assert_eq!(st, 200, "{}", String::from_utf8_lossy(&body));
    body
}

async fn frames(c: &reqwest::Client, s: &TestServer, id: &str, rest: &str) -> (u16, Value) {
    let (st, _, body) = get(c, &s.url(&format!("/v1/textures/{id}/frames/{rest}"))).await;
    (st, serde_json::from_slice(&body).unwrap())
}

/// Degrees of the projected arrow (u, v) from the slice's u axis.
fn degrees(a: &Value) -> f64 {
    let (u, v) = (a[0].as_f64().unwrap(), a[1].as_f64().unwrap());
    v.atan2(u).to_degrees()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_field_given_at_upload_is_in_the_texture() {
    let (_dir, s, c, plain) = server_with_texture(21).await;
    let (status, v) = upload(
        &c,
        &s,
        exemplar_png(32, 21),
        &format!("{SMALL_PARAMS}&field=slant:30"),
    )
    .await;
    assert!(status == 201 || status == 202, "{status} {v}");
    assert_eq!(
        v["params"]["field"],
        json!({"kind": "slant", "angle": 30.0})
    );
    let id = v["id"].as_str().unwrap();
    assert_ne!(id, plain, "the field is part of the id");
    let meta = wait_ready(&c, &s, id).await;
    assert_eq!(meta["params"]["field"]["kind"], "slant");
    let plain_meta = get_json(&c, &s, &format!("/v1/textures/{plain}")).await;
    assert!(plain_meta["params"].get("field").is_none(), "{plain_meta}");
    // A bad field is refused at upload.
    let (status, v) = upload(
        &c,
        &s,
        exemplar_png(32, 21),
        &format!("{SMALL_PARAMS}&field=spiral"),
    )
    .await;
    assert_eq!(
        (status, v["error"]["code"].as_str()),
        (400, Some("invalid_params"))
    );
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn variants_change_synthesis_parameters_and_are_found_again() {
    let (_dir, s, c, plain) = server_with_texture(22).await;
    let body = r#"{"field": {"kind": "slant", "angle": 30}}"#;
    let slanted = ready_variant(&c, &s, &plain, body).await;
    assert_ne!(slanted, plain);
    // The same body finds the same texture, now ready: 201.
    let (status, v) = variant(&c, &s, &plain, body).await;
    assert_eq!((status, v["id"].as_str()), (201, Some(slanted.as_str())));
    // The short form of the same field is the same texture.
    let (_, v) = variant(&c, &s, &plain, r#"{"field": "slant:30"}"#).await;
    assert_eq!(v["id"].as_str(), Some(slanted.as_str()));
    let meta = get_json(&c, &s, &format!("/v1/textures/{slanted}")).await;
    assert_eq!(meta["params"]["field"]["angle"], 30.0);
    assert_eq!(meta["params"]["levels"], 3, "analysis parameters are kept");
    assert_eq!(meta["params"]["seed"], 1, "other synthesis parameters too");
    assert_ne!(slice(&c, &s, &plain).await, slice(&c, &s, &slanted).await);

    // Dropping the field gives back the unguided texture.
    let (status, v) = variant(&c, &s, &slanted, r#"{"field": null}"#).await;
    assert_eq!(
        (status, v["id"].as_str()),
        (201, Some(plain.as_str())),
        "{v}"
    );
    // An empty body changes nothing: the same texture.
    let (status, v) = variant(&c, &s, &plain, "{}").await;
    assert_eq!(
        (status, v["id"].as_str()),
        (201, Some(plain.as_str())),
        "{v}"
    );

    // Another seed is another texture, sharing the candidates (ready
    // without a search: the precompute counter says reused).
    let seeded = ready_variant(&c, &s, &slanted, r#"{"seed": 7}"#).await;
    let meta = get_json(&c, &s, &format!("/v1/textures/{seeded}")).await;
    assert_eq!(meta["params"]["seed"], 7);
    assert_eq!(meta["params"]["field"]["kind"], "slant");
    let text = metrics(&c, &s).await;
    assert_eq!(
        metric(&text, r#"solidtex_precomputes_total{outcome="ok"}"#),
        1.0,
        "{text}"
    );
    assert_eq!(
        metric(&text, r#"solidtex_precomputes_total{outcome="reused"}"#),
        2.0
    );
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn variants_refuse_what_they_cannot_do() {
    let (_dir, s, c, plain) = server_with_texture(23).await;
    for (body, code) in [
        (r#"{"levels": 2}"#, "invalid_params"),
        (r#"{"neighbourhood": 7, "seed": 2}"#, "invalid_params"),
        (r#"{"field": "spiral"}"#, "invalid_params"),
        (
            r#"{"field": {"kind": "zigzag", "angle": 10, "period": 0}}"#,
            "invalid_request",
        ),
        (
            r#"{"field": "slant:30", "correction": "colour"}"#,
            "invalid_params",
        ),
        (r#"{"sed": 1}"#, "invalid_params"),
        (r#"{"seed": 1, "seed": 2}"#, "invalid_params"),
        ("[1]", "invalid_params"),
        ("", "invalid_params"),
        (r#"{"passes": 99}"#, "out_of_range"),
    ] {
        let (status, v) = variant(&c, &s, &plain, body).await;
        assert_eq!(status, 400, "{body}: {v}");
        assert_eq!(v["error"]["code"], code, "{body}: {v}");
    }
    let (_, v) = variant(&c, &s, &plain, r#"{"levels": 2}"#).await;
    let message = v["error"]["message"].as_str().unwrap();
    assert!(message.contains("precompute"), "{message}");
    // Unknown texture: 404, whatever the body.
    let (status, v) = variant(&c, &s, "0123456789abcdef0123456789abcdef", "{}").await;
    assert_eq!(
        (status, v["error"]["code"].as_str()),
        (404, Some("unknown_texture"))
    );
    // Not JSON: 415; too large: 413.
    let url = s.url(&format!("/v1/textures/{plain}/variants"));
    let r = c.post(&url).body("{}").send().await.unwrap();
    assert_eq!(r.status().as_u16(), 415);
    let big = format!(r#"{{"seed": 1, "x": "{}"}}"#, "a".repeat(600 << 10));
    // The server answers from the headers and closes without reading the
    // body, so a client still writing it may see the pipe break before it
    // reads the answer: then it asks again.
    let mut answer = None;
    for _ in 0..5 {
        match c
            .post(&url)
            .header("content-type", "application/json")
            .body(big.clone())
            .send()
            .await
        {
            Ok(r) => {
                answer = Some(r);
                break;
            }
            Err(e) if e.is_request() => continue,
            Err(e) => panic!("{e}"),
        }
    }
    let r = answer.expect("an answer to one of five tries");
    assert_eq!(r.status().as_u16(), 413);
    let v: Value = r.json().await.unwrap();
    assert_eq!(v["error"]["code"], "payload_too_large");
    // Nothing was created by any of these.
    let list = get_json(&c, &s, "/v1/textures").await;
    assert_eq!(list["textures"].as_array().unwrap().len(), 1, "{list}");
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frames_show_the_field_on_a_slice() {
    let (_dir, s, c, plain) = server_with_texture(24).await;
    let slanted = ready_variant(&c, &s, &plain, r#"{"field": "slant:30"}"#).await;

    let (st, v) = frames(&c, &s, &slanted, "z/5.json?u0=-8&v0=4&w=40&h=20&step=10").await;
    assert_eq!(st, 200, "{v}");
    assert_eq!(
        (v["columns"].as_u64(), v["rows"].as_u64()),
        (Some(4), Some(2))
    );
    assert_eq!(
        (v["u_axis"].as_str(), v["v_axis"].as_str()),
        (Some("x"), Some("y"))
    );
    assert_eq!(v["field_kind"], "slant");
    let samples = v["samples"].as_array().unwrap();
    assert_eq!(samples.len(), 8);
    assert_eq!(
        (samples[0]["u"].as_i64(), samples[0]["v"].as_i64()),
        (Some(-8), Some(4))
    );
    assert_eq!(
        (samples[5]["u"].as_i64(), samples[5]["v"].as_i64()),
        (Some(2), Some(14))
    );
    for p in samples {
        // Local x at 30° from the slice's u axis, in the plane.
        assert!((degrees(&p["x"]) - 30.0).abs() < 1e-3, "{p}");
        assert!(p["x"][2].as_f64().unwrap().abs() < 1e-6, "{p}");
        assert!((degrees(&p["y"]) - 120.0).abs() < 1e-3, "{p}");
        assert_eq!(p["z"], json!([0.0, 0.0, 1.0]));
    }
    // Seen on an x slice ((u, v) = (y, z)), local x leaves the plane.
    let (_, v) = frames(&c, &s, &slanted, "x/0.json?w=1&h=1&lod=1").await;
    let x = &v["samples"][0]["x"];
    assert!((x[0].as_f64().unwrap() - 0.5).abs() < 1e-6, "{v}");
    assert!(
        (x[2].as_f64().unwrap() - 0.75f64.sqrt()).abs() < 1e-6,
        "{v}"
    );

    // Without a field every frame is the world's.
    let (st, v) = frames(&c, &s, &plain, "y/-3.json?w=3&h=3&step=1").await;
    assert_eq!(st, 200, "{v}");
    assert_eq!(v["field_kind"], Value::Null);
    assert_eq!(v["samples"].as_array().unwrap().len(), 9);
    for p in v["samples"].as_array().unwrap() {
        // y slice: (u, v) = (z, x), normal y.
        assert_eq!(p["x"], json!([0.0, 1.0, 0.0]), "{p}");
        assert_eq!(p["y"], json!([0.0, 0.0, 1.0]), "{p}");
        assert_eq!(p["z"], json!([1.0, 0.0, 0.0]), "{p}");
    }

    // Limits: each a JSON 400 with its code.
    for (rest, code) in [
        ("z/0.json?w=4096&h=4096&step=1", "too_large"),
        ("z/0.json?w=65&h=64&step=1", "too_large"),
        ("z/0.json?step=0", "out_of_range"),
        ("z/0.json?w=0", "out_of_range"),
        ("z/0.json?w=4097", "out_of_range"),
        ("z/0.json?u0=2147483648&w=2", "out_of_range"),
        ("z/2147483649.json", "out_of_range"),
        ("z/0.json?lod=9", "out_of_range"),
        ("w/0.json", "invalid_axis"),
        ("z/0.json?u0=x", "invalid_parameter"),
        ("z/0.json?step=1&step=2", "invalid_parameter"),
    ] {
        let (st, h, body) = get(&c, &s.url(&format!("/v1/textures/{slanted}/frames/{rest}"))).await;
        assert_error(st, &h, &body, 400, code);
    }
    // Exactly at the sample limit is fine.
    let (st, v) = frames(&c, &s, &plain, "z/0.json?w=64&h=64&step=1").await;
    assert_eq!(
        (st, v["samples"].as_array().map(Vec::len)),
        (200, Some(4096))
    );
    let (st, h, body) = get(&c, &s.url(&format!("/v1/textures/{plain}/frames/z/0.png"))).await;
    assert_error(st, &h, &body, 404, "no_route");
    let (st, h, body) = get(
        &c,
        &s.url("/v1/textures/0123456789abcdef0123456789abcdef/frames/z/0.json"),
    )
    .await;
    assert_error(st, &h, &body, 404, "unknown_texture");
    // Cached like voxels: revalidation answers 304.
    let url = s.url(&format!("/v1/textures/{slanted}/frames/z/0.json"));
    let (_, h, _) = get(&c, &url).await;
    let tag = h["etag"].to_str().unwrap().to_string();
    let r = c
        .get(&url)
        .header("if-none-match", &tag)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 304);
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_variant_survives_a_restart() {
    let (dir, s, c, plain) = server_with_texture(25).await;
    let slanted = ready_variant(&c, &s, &plain, r#"{"field": "circular:4,4"}"#).await;
    let before = slice(&c, &s, &slanted).await;
    s.stop().await;

    let s = TestServer::start(test_args(dir.path())).await;
    let meta = get_json(&c, &s, &format!("/v1/textures/{slanted}")).await;
    assert_eq!(meta["status"], "ready", "{meta}");
    assert_eq!(meta["params"]["field"]["kind"], "circular");
    assert_eq!(slice(&c, &s, &slanted).await, before);
    // Found again by content after the restart.
    let (status, v) = variant(&c, &s, &plain, r#"{"field": "circular:4,4"}"#).await;
    assert_eq!((status, v["id"].as_str()), (201, Some(slanted.as_str())));
    s.stop().await;
}

/// A variant of a texture whose candidates left memory reads them back
/// from disk instead of searching again.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_variant_of_an_evicted_texture_shares_its_stored_candidates() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    // Only the texture last used stays in memory.
    args.max_resident_bytes = 1;
    let s = TestServer::start(args).await;
    let c = client();
    let a = ready_texture(&c, &s, 26).await;
    // `a` leaves memory when `b` becomes ready.
    let _b = ready_texture(&c, &s, 27).await;
    let seeded = ready_variant(&c, &s, &a, r#"{"seed": 9, "field": "slant:15"}"#).await;
    let text = metrics(&c, &s).await;
    assert_eq!(
        metric(&text, r#"solidtex_precomputes_total{outcome="ok"}"#),
        2.0,
        "{text}"
    );
    assert_eq!(
        metric(&text, r#"solidtex_precomputes_total{outcome="reused"}"#),
        1.0
    );
    assert_ne!(slice(&c, &s, &seeded).await, slice(&c, &s, &a).await);
    s.stop().await;
}
