//! Every error is JSON: oversized heads, degenerate cut planes, parameters
//! given twice, coordinates at the edge of the served range.

use crate::raw::send;
use crate::server_support::*;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn oversized_targets_and_heads_get_json_errors() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    let long = "a".repeat(9000);
    let a = send(
        s.addr,
        format!("GET /healthz?x={long} HTTP/1.1\r\nhost: localhost\r\nconnection: close\r\n\r\n")
            .as_bytes(),
    )
    .await;
    a.assert_error(414, "uri_too_long");

    let many: String = (0..150).map(|i| format!("x-h{i}: v\r\n")).collect();
    let a = send(
        s.addr,
        format!("GET /healthz HTTP/1.1\r\nhost: localhost\r\n{many}connection: close\r\n\r\n")
            .as_bytes(),
    )
    .await;
    a.assert_error(431, "headers_too_large");

    let big = "b".repeat(40 << 10);
    let a = send(
        s.addr,
        format!(
            "GET /healthz HTTP/1.1\r\nhost: localhost\r\nx-big: {big}\r\nconnection: close\r\n\r\n"
        )
        .as_bytes(),
    )
    .await;
    a.assert_error(431, "headers_too_large");

    // Beyond what hyper buffers (64 KiB) it answers by itself, in JSON
    // too.
    let huge = "c".repeat(100 << 10);
    let a = send(
        s.addr,
        format!("GET /healthz HTTP/1.1\r\nhost: localhost\r\nx-huge: {huge}\r\n\r\n").as_bytes(),
    )
    .await;
    a.assert_error(431, "headers_too_large");

    // Within the limits all is well.
    let a = send(
        s.addr,
        b"GET /healthz HTTP/1.1\r\nhost: localhost\r\nconnection: close\r\n\r\n",
    )
    .await;
    assert_eq!(a.status, 200);
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn requests_hyper_cannot_parse_get_json_errors() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    for request in [
        &b"GARBAGE\r\n\r\n"[..],
        b"GET /healthz HTTP/1.1\r\nhost: localhost\r\nno colon here\r\n\r\n",
        b"GET /hea lthz HTTP/1.1\r\nhost: localhost\r\n\r\n",
        b"GET /healthz HTTP/9.9\r\nhost: localhost\r\n\r\n",
        b"GET /healthz HTTP/1.1\r\nho\x01st: localhost\r\n\r\n",
    ] {
        let a = send(s.addr, request).await;
        a.assert_error(400, "malformed_request");
        assert!(a.head.contains("connection: close"), "{}", a.head);
    }
    // On a kept-alive connection, after a good answer, too.
    let mut c = tokio::net::TcpStream::connect(s.addr).await.unwrap();
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    c.write_all(b"GET /healthz HTTP/1.1\r\nhost: localhost\r\n\r\n")
        .await
        .unwrap();
    let mut buf = vec![0u8; 4096];
    let n = c.read(&mut buf).await.unwrap();
    assert!(buf[..n].starts_with(b"HTTP/1.1 200"));
    c.write_all(b"BROKEN REQUEST\r\n\r\n").await.unwrap();
    let (bytes, closed) =
        crate::raw::read_until_closed(&mut c, std::time::Duration::from_secs(10)).await;
    assert!(closed);
    crate::raw::parse(&bytes).assert_error(400, "malformed_request");
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn degenerate_cut_planes_are_refused() {
    let (_dir, s, c, id) = server_with_texture(3).await;
    let cut = |q: &str| s.url(&format!("/v1/textures/{id}/cut.png?w=8&h=8&{q}"));
    for q in [
        "u=0,0,0",
        "v=0,0,0",
        "u=0,0,0&v=0,0,0",
        "u=1,0,0&v=2,0,0",
        "u=1,1,0&v=-2,-2,0",
        "u=0.5,0.25,1&v=1,0.5,2",
        "u=1e-300,0,0&v=1,0,0",
    ] {
        let (st, h, b) = get(&c, &cut(q)).await;
        assert_error(st, &h, &b, 400, "invalid_parameter");
    }
    for q in [
        "u=1,0,0&v=0,1,0",
        "u=0.6,0.8,0&v=0,0,1",
        "u=1,1e-6,0&v=1,0,0",
    ] {
        let (st, _, b) = get(&c, &cut(q)).await;
        assert_eq!(st, 200, "{q}: {}", String::from_utf8_lossy(&b));
    }
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cuts_reach_as_far_as_slices() {
    let (_dir, s, c, id) = server_with_texture(4).await;
    let t = |p: &str| s.url(&format!("/v1/textures/{id}{p}"));
    // The plane x = 2^31, as a slice and as a cut sampling whole voxels.
    let (st, _, slice) = get(&c, &t("/slices/x/2147483648.png?u0=5&v0=6&w=4&h=4")).await;
    assert_eq!(st, 200);
    let (st, _, cut) = get(
        &c,
        &t("/cut.png?origin=2147483648,5,6&u=0,1,0&v=0,0,1&w=4&h=4"),
    )
    .await;
    assert_eq!(st, 200, "{}", String::from_utf8_lossy(&cut));
    assert_eq!(decode_png(&slice), decode_png(&cut));
    let (st, _, cut) = get(
        &c,
        &t("/cut.png?origin=-2147483648,5,6&u=0,1,0&v=0,0,1&w=4&h=4&filter=trilinear"),
    )
    .await;
    assert_eq!(st, 200, "{}", String::from_utf8_lossy(&cut));
    // One step further is out of range for both.
    let (st, h, b) = get(&c, &t("/slices/x/2147483649.png?w=4&h=4")).await;
    assert_error(st, &h, &b, 400, "out_of_range");
    let (st, h, b) = get(&c, &t("/cut.png?origin=2147483648.5,0,0&w=1&h=1")).await;
    assert_error(st, &h, &b, 400, "out_of_range");
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn parameters_given_twice_are_refused() {
    let (_dir, s, c, id) = server_with_texture(5).await;
    let (st, h, b) = get(
        &c,
        &s.url(&format!("/v1/textures/{id}/slices/z/0.png?w=4&h=4&w=8")),
    )
    .await;
    assert_error(st, &h, &b, 400, "invalid_parameter");
    let (st, v) = upload(&c, &s, exemplar_png(32, 6), "levels=3&seed=1&seed=2").await;
    assert_eq!(st, 400, "{v}");
    assert_eq!(v["error"]["code"], "invalid_parameter");

    let form = |params: &[&str]| {
        params.iter().fold(
            reqwest::multipart::Form::new().part("image", png_part(exemplar_png(32, 6))),
            |f, p| f.text("params", p.to_string()),
        )
    };
    let refused = [
        // Two `params` fields.
        (
            form(&[r#"{"levels": 3}"#, r#"{"seed": 9}"#]),
            "",
            "invalid_request",
        ),
        // A key twice in one `params`.
        (
            form(&[r#"{"levels": 3, "seed": 1, "seed": 2}"#]),
            "",
            "invalid_params",
        ),
        // A key in the query and in `params`.
        (
            form(&[r#"{"levels": 3, "seed": 2}"#]),
            "?seed=1",
            "invalid_params",
        ),
    ];
    for (f, query, code) in refused {
        let (st, h, b) = post_form(&c, &s.url(&format!("/v1/textures{query}")), f).await;
        assert_error(st, &h, &b, 400, code);
    }
    // Each once: accepted.
    let (st, _, b) = post_form(
        &c,
        &s.url("/v1/textures?seed=1"),
        form(&[r#"{"levels": 3}"#]),
    )
    .await;
    let v: serde_json::Value = serde_json::from_slice(&b).unwrap();
    assert!(st == 201 || st == 202, "{st} {v}");
    assert_eq!(v["params"]["seed"], 1);
    s.stop().await;
}
