//! The Host allow-list (DNS rebinding).

use crate::raw::get_with_host;
use crate::server_support::*;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_loopback_server_answers_loopback_names_only() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    let port = s.addr.port();
    for host in [
        format!("127.0.0.1:{port}"),
        format!("localhost:{port}"),
        "localhost".to_string(),
        "[::1]:80".to_string(),
    ] {
        let a = get_with_host(s.addr, "/healthz", Some(&host)).await;
        assert_eq!(a.status, 200, "{host}: {}", a.head);
    }
    for host in [
        format!("evil.example:{port}"),
        "localhost.evil.example".to_string(),
        "127.0.0.2".to_string(),
    ] {
        let a = get_with_host(s.addr, "/v1/textures", Some(&host)).await;
        a.assert_error(421, "host_not_allowed");
    }
    // A Host that is no text is no allowed name either.
    let a = crate::raw::send(
        s.addr,
        b"GET /healthz HTTP/1.1\r\nhost: local\xffhost\r\nconnection: close\r\n\r\n",
    )
    .await;
    a.assert_error(421, "host_not_allowed");
    // Without any (HTTP/1.0): browsers always send one, so this is no
    // rebinding.
    let a = crate::raw::send(s.addr, b"GET /healthz HTTP/1.0\r\n\r\n").await;
    assert_eq!(a.status, 200);
    // Through an HTTP client too (its Host is the address it connects to).
    let (status, _, _) = get(&client(), &s.url("/healthz")).await;
    assert_eq!(status, 200);
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn configured_hosts_replace_the_loopback_names() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.allowed_hosts = vec!["tiles.example".into(), "api.example:8443".into()];
    let s = TestServer::start(args).await;
    for (host, status) in [
        ("tiles.example", 200),
        ("TILES.example.:80", 200),
        ("api.example:8443", 200),
        ("api.example", 421),
        ("localhost", 421),
    ] {
        let a = get_with_host(s.addr, "/healthz", Some(host)).await;
        assert_eq!(a.status, status, "{host}");
        if status == 421 {
            a.assert_error(421, "host_not_allowed");
        }
    }
    s.stop().await;
    let mut args = test_args(dir.path());
    args.allowed_hosts = vec!["*".into()];
    let s = TestServer::start(args).await;
    let a = get_with_host(s.addr, "/healthz", Some("anything.example")).await;
    assert_eq!(a.status, 200);
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_malformed_allow_list_stops_the_start() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.allowed_hosts = vec!["not a host".into()];
    let err = solidtex_server::Server::bind(&args)
        .await
        .err()
        .expect("a bad host name is refused");
    assert!(err.to_string().contains("allowed-hosts"), "{err:#}");
}
