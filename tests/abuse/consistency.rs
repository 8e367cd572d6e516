//! The same request is refused the same way whatever form it takes: a key
//! given twice inside a field object, a field's bound in its short and its
//! object form; an error repeats at most a little of what was sent; and a
//! variant that changes nothing is its source, not a copy.

use crate::server_support::*;
use serde_json::Value;

async fn variant(c: &reqwest::Client, s: &TestServer, id: &str, body: String) -> (u16, Value) {
    let url = s.url(&format!("/v1/textures/{id}/variants"));
    post_body(c, &url, "application/json", body).await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn repeated_keys_and_field_bounds_are_refused_alike_in_every_form() {
    let (_dir, s, c, id) = server_with_texture(31).await;
    let repeated = r#"{"kind": "slant", "angle": 30, "angle": 40}"#;
    // In a variant body, in an upload's `params`, and in the query.
    let (status, v) = variant(&c, &s, &id, format!(r#"{{"field": {repeated}}}"#)).await;
    assert_eq!(
        (status, v["error"]["code"].as_str()),
        (400, Some("invalid_params")),
        "{v}"
    );
    let form = reqwest::multipart::Form::new()
        .part("image", png_part(exemplar_png(32, 31)))
        .text("params", format!(r#"{{"levels": 3, "field": {repeated}}}"#));
    let (status, v) = upload_form(&c, &s, form).await;
    assert_eq!(
        (status, v["error"]["code"].as_str()),
        (400, Some("invalid_params")),
        "{v}"
    );
    let query = format!("{SMALL_PARAMS}&field={}", urlencoding(repeated));
    let (status, v) = upload(&c, &s, exemplar_png(32, 31), &query).await;
    assert_eq!(
        (status, v["error"]["code"].as_str()),
        (400, Some("invalid_params")),
        "{v}"
    );

    // A field's bound: the same code in the short form and as an object,
    // in a variant and at upload.
    for field in [
        r#""zigzag:10,0""#,
        r#"{"kind": "zigzag", "angle": 10, "period": 0}"#,
    ] {
        let (status, v) = variant(&c, &s, &id, format!(r#"{{"field": {field}}}"#)).await;
        assert_eq!(
            (status, v["error"]["code"].as_str()),
            (400, Some("invalid_request")),
            "{field}: {v}"
        );
    }
    for field in ["zigzag:10,0", r#"{"kind":"zigzag","angle":10,"period":0}"#] {
        let query = format!("{SMALL_PARAMS}&field={}", urlencoding(field));
        let (status, v) = upload(&c, &s, exemplar_png(32, 31), &query).await;
        assert_eq!(
            (status, v["error"]["code"].as_str()),
            (400, Some("invalid_request")),
            "{field}: {v}"
        );
    }
    s.stop().await;
}

/// Percent-encodes a query value.
fn urlencoding(v: &str) -> String {
    v.bytes()
        .map(|b| match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'_' | b'.' => (b as char).to_string(),
            _ => format!("%{b:02X}"),
        })
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn errors_repeat_little_of_what_was_sent() {
    let (_dir, s, c, id) = server_with_texture(32).await;
    let key = "k".repeat(500 << 10);
    let (status, v) = variant(&c, &s, &id, format!(r#"{{"{key}": 1}}"#)).await;
    assert_eq!(
        (status, v["error"]["code"].as_str()),
        (400, Some("invalid_params"))
    );
    let message = v["error"]["message"].as_str().unwrap();
    assert!(message.len() < 1024, "{} bytes", message.len());
    assert!(message.contains("known: "), "{message}");
    // A long value in the query, and a long unknown enum value in a body.
    let (status, v) = upload(
        &c,
        &s,
        exemplar_png(32, 32),
        &format!("scheme={}", "s".repeat(7000)),
    )
    .await;
    assert_eq!(status, 400, "{v}");
    assert!(v.to_string().len() < 1024, "{v}");
    let (status, v) = variant(
        &c,
        &s,
        &id,
        format!(r#"{{"scheme": "{}"}}"#, "s".repeat(400 << 10)),
    )
    .await;
    assert_eq!(status, 400, "{v}");
    assert!(v.to_string().len() < 1024, "{v}");
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_variant_that_changes_nothing_is_its_source() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.default_texture = true;
    args.max_textures = 1;
    let s = TestServer::start(args).await;
    let c = client();
    wait_ready(&c, &s, "default").await;
    for body in ["{}", r#"{"seed": 1}"#] {
        let (status, v) = variant(&c, &s, "default", body.to_string()).await;
        assert_eq!(
            (status, v["id"].as_str()),
            (201, Some("default")),
            "{body}: {v}"
        );
    }
    let list = get_json(&c, &s, "/v1/textures").await;
    assert_eq!(list["textures"].as_array().unwrap().len(), 1, "{list}");
    // Nothing was counted against --max-textures: an upload still fits.
    let (status, v) = upload(&c, &s, exemplar_png(32, 33), SMALL_PARAMS).await;
    assert_eq!(status, 202, "{v}");
    s.stop().await;
}
