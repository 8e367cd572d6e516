//! Connection limits: the cap, the header, idle and body timeouts.

use crate::raw::read_until_closed;
use crate::server_support::*;
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn idle_sockets_over_the_cap_leave_room_for_health_checks() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.max_connections = 8;
    args.header_timeout = 60.0;
    let s = TestServer::start(args).await;
    let mut idle = Vec::new();
    for _ in 0..40 {
        idle.push(TcpStream::connect(s.addr).await.unwrap());
    }
    tokio::time::sleep(Duration::from_millis(200)).await;
    let t0 = Instant::now();
    let (status, _, body) = get(&client(), &s.url("/healthz")).await;
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    assert!(t0.elapsed() < Duration::from_secs(2), "{:?}", t0.elapsed());
    // The oldest idle sockets were closed to make room; at most the cap
    // are still open.
    let mut open = 0;
    for sock in &mut idle {
        let (_, closed) = read_until_closed(sock, Duration::from_millis(100)).await;
        open += usize::from(!closed);
    }
    assert!(open <= 8, "{open} idle sockets still open over a cap of 8");
    let (_, closed) = read_until_closed(&mut idle[0], Duration::from_millis(10)).await;
    assert!(closed, "the oldest idle socket is closed first");
    let text = s.state.metrics.encode();
    assert!(
        metric(&text, "solidtex_connections_evicted_total") >= 32.0,
        "{text}"
    );
    drop(idle);
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn when_every_connection_is_busy_a_new_one_gets_503() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.max_connections = 2;
    args.body_timeout = 30.0;
    let s = TestServer::start(args).await;
    // Two uploads whose bodies never finish keep both connections busy.
    let mut busy = Vec::new();
    for _ in 0..2 {
        let mut c = TcpStream::connect(s.addr).await.unwrap();
        c.write_all(
            b"POST /v1/textures HTTP/1.1\r\nHost: localhost\r\ncontent-type: image/png\r\ncontent-length: 1000\r\n\r\n0123456789",
        )
        .await
        .unwrap();
        busy.push(c);
    }
    tokio::time::sleep(Duration::from_millis(300)).await;
    let mut third = TcpStream::connect(s.addr).await.unwrap();
    let (answer, closed) = read_until_closed(&mut third, Duration::from_secs(5)).await;
    assert!(closed);
    let text = String::from_utf8_lossy(&answer);
    assert!(text.starts_with("HTTP/1.1 503"), "{text}");
    assert!(text.contains("retry-after: 1"), "{text}");
    let body = text.split("\r\n\r\n").nth(1).unwrap();
    let v: serde_json::Value = serde_json::from_str(body).unwrap();
    assert_eq!(v["error"]["code"], "overloaded");
    // A client that sends its request at once still reads the answer
    // (closing over unread bytes would reset the connection instead).
    for _ in 0..5 {
        let mut c = TcpStream::connect(s.addr).await.unwrap();
        c.write_all(b"GET /healthz HTTP/1.1\r\nHost: localhost\r\n\r\n")
            .await
            .unwrap();
        tokio::time::sleep(Duration::from_millis(50)).await;
        let (answer, _) = read_until_closed(&mut c, Duration::from_secs(5)).await;
        let text = String::from_utf8_lossy(&answer);
        assert!(text.starts_with("HTTP/1.1 503"), "{text:?}");
    }
    drop(busy);
    // Once they are gone, a client gets through again.
    tokio::time::sleep(Duration::from_millis(200)).await;
    let (status, _, _) = get(&client(), &s.url("/healthz")).await;
    assert_eq!(status, 200);
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_partial_request_head_is_closed_after_the_header_timeout() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.header_timeout = 0.5;
    let s = TestServer::start(args).await;
    let mut c = TcpStream::connect(s.addr).await.unwrap();
    c.write_all(b"GET /healthz HTTP/1.1\r\nHost: localhost\r\n")
        .await
        .unwrap();
    let t0 = Instant::now();
    let (_, closed) = read_until_closed(&mut c, Duration::from_secs(5)).await;
    assert!(closed, "a slow head keeps its connection");
    let took = t0.elapsed();
    assert!(
        took >= Duration::from_millis(400) && took < Duration::from_secs(3),
        "{took:?}"
    );
    s.stop().await;
}

/// Sends a GET of /healthz on `c` and reads its answer, keeping the
/// connection open.
async fn healthz(c: &mut TcpStream) {
    c.write_all(b"GET /healthz HTTP/1.1\r\nHost: localhost\r\n\r\n")
        .await
        .unwrap();
    let mut buf = [0u8; 1024];
    let n = c.read(&mut buf).await.unwrap();
    assert!(buf[..n].starts_with(b"HTTP/1.1 200"), "{:?}", &buf[..n]);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_idle_keep_alive_connection_is_closed_after_the_idle_timeout() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.header_timeout = 60.0;
    args.idle_timeout = 0.5;
    let s = TestServer::start(args).await;
    let mut c = TcpStream::connect(s.addr).await.unwrap();
    healthz(&mut c).await;
    let t0 = Instant::now();
    let (_, closed) = read_until_closed(&mut c, Duration::from_secs(5)).await;
    assert!(closed, "an idle keep-alive connection stays open");
    assert!(t0.elapsed() < Duration::from_secs(3), "{:?}", t0.elapsed());
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_keep_alive_connection_rests_longer_than_the_header_timeout() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.header_timeout = 0.3;
    args.idle_timeout = 60.0;
    let s = TestServer::start(args).await;
    let mut c = TcpStream::connect(s.addr).await.unwrap();
    healthz(&mut c).await;
    // At rest for several header timeouts, it still takes a request.
    tokio::time::sleep(Duration::from_millis(1200)).await;
    healthz(&mut c).await;
    // A request head started on it must still arrive within the header
    // timeout.
    c.write_all(b"GET /healthz HTTP/1.1\r\n").await.unwrap();
    let (_, closed) = read_until_closed(&mut c, Duration::from_secs(5)).await;
    assert!(closed, "a slow head keeps its connection");
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_trickled_body_is_answered_408() {
    let dir = tempfile::tempdir().unwrap();
    let mut args = test_args(dir.path());
    args.body_timeout = 0.5;
    let s = TestServer::start(args).await;
    let mut c = TcpStream::connect(s.addr).await.unwrap();
    c.write_all(
        b"POST /v1/textures HTTP/1.1\r\nHost: localhost\r\ncontent-type: image/png\r\ncontent-length: 1000\r\n\r\n0123456789",
    )
    .await
    .unwrap();
    let t0 = Instant::now();
    let (answer, closed) = read_until_closed(&mut c, Duration::from_secs(5)).await;
    assert!(closed);
    assert!(t0.elapsed() < Duration::from_secs(3), "{:?}", t0.elapsed());
    let text = String::from_utf8_lossy(&answer);
    assert!(text.starts_with("HTTP/1.1 408"), "{text}");
    let body = text.split("\r\n\r\n").nth(1).unwrap();
    let v: serde_json::Value = serde_json::from_str(body).unwrap();
    assert_eq!(v["error"]["code"], "body_timeout");
    s.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn shutdown_closes_idle_connections_and_returns() {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    let mut idle = TcpStream::connect(s.addr).await.unwrap();
    tokio::time::sleep(Duration::from_millis(100)).await;
    tokio::time::timeout(Duration::from_secs(5), s.stop())
        .await
        .expect("shutdown waits for no idle connection");
    let (_, closed) = read_until_closed(&mut idle, Duration::from_secs(2)).await;
    assert!(closed);
}
