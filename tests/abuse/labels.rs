//! Clients cannot mint metric labels: a method the server does not know
//! is counted as `other` and a path no route matches as `unmatched`, so
//! `/metrics` stays small whatever is sent.

use crate::raw::send;
use crate::server_support::*;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn odd_methods_and_paths_share_one_label_each() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    let before = s.state.metrics.encode().len();
    for i in 0..200 {
        let method = format!("X{i}{}", "M".repeat(2000));
        let path = if i % 2 == 0 {
            "/healthz".to_string()
        } else {
            format!("/nowhere/{i}")
        };
        let a = send(
            s.addr,
            format!("{method} {path} HTTP/1.1\r\nhost: localhost\r\nconnection: close\r\n\r\n")
                .as_bytes(),
        )
        .await;
        assert!(a.status == 404 || a.status == 405, "{}", a.status);
        // The answer does not carry the method back in full either.
        assert!(a.body.len() < 1024, "{} bytes", a.body.len());
    }
    let text = s.state.metrics.encode();
    for line in text.lines().filter(|l| l.contains("method=\"")) {
        let method = line.split("method=\"").nth(1).unwrap().split('"').next();
        assert!(
            matches!(method, Some("GET" | "POST" | "DELETE" | "other")),
            "{line}"
        );
    }
    let others: f64 = text
        .lines()
        .filter(|l| {
            l.starts_with("solidtex_http_requests_total{") && l.contains("method=\"other\"")
        })
        .map(|l| l.rsplit_once(' ').unwrap().1.parse::<f64>().unwrap())
        .sum();
    assert_eq!(others, 200.0, "{text}");
    assert!(
        text.len() < before + (8 << 10),
        "/metrics grew from {before} to {} bytes",
        text.len()
    );
    s.stop().await;
}
