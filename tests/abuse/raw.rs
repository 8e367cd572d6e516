//! Requests written byte by byte, for what HTTP clients refuse to send.

use std::net::SocketAddr;
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

/// Reads until the peer closes the connection or `limit` passes; returns
/// what was read and whether it closed.
pub async fn read_until_closed(s: &mut TcpStream, limit: Duration) -> (Vec<u8>, bool) {
    let mut out = Vec::new();
    let deadline = Instant::now() + limit;
    let mut buf = [0u8; 4096];
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match tokio::time::timeout(left, s.read(&mut buf)).await {
            Err(_) => return (out, false),
            Ok(Ok(0)) | Ok(Err(_)) => return (out, true),
            Ok(Ok(n)) => out.extend_from_slice(&buf[..n]),
        }
    }
}

/// An answer: status, lowercase headers, body.
pub struct Answer {
    pub status: u16,
    pub head: String,
    pub body: Vec<u8>,
}

impl Answer {
    /// The body as JSON (panics otherwise).
    pub fn json(&self) -> serde_json::Value {
        serde_json::from_slice(&self.body).unwrap_or_else(|_| {
            panic!(
                "not JSON: {}\n{}",
                self.head,
                String::from_utf8_lossy(&self.body)
            )
        })
    }

    /// Asserts a JSON error with this status and code.
    pub fn assert_error(&self, status: u16, code: &str) {
        let v = self.json();
        assert_eq!(self.status, status, "{v}");
        assert!(
            self.head.contains("content-type: application/json"),
            "{}",
            self.head
        );
        assert_eq!(v["error"]["code"], code, "{v}");
    }
}

/// Sends `request` as is on a new connection and reads the answer (the
/// request should say `connection: close`).
pub async fn send(addr: SocketAddr, request: &[u8]) -> Answer {
    let mut c = TcpStream::connect(addr).await.unwrap();
    c.write_all(request).await.unwrap();
    let (bytes, _) = read_until_closed(&mut c, Duration::from_secs(30)).await;
    parse(&bytes)
}

/// Parses an HTTP/1.1 answer (with a content-length body).
pub fn parse(bytes: &[u8]) -> Answer {
    let text = String::from_utf8_lossy(bytes);
    let (head, _) = text
        .split_once("\r\n\r\n")
        .unwrap_or_else(|| panic!("no complete answer: {text:?}"));
    let head_len = head.len() + 4;
    let status = head
        .split(' ')
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no status: {head}"));
    Answer {
        status,
        head: head.to_ascii_lowercase(),
        body: bytes[head_len..].to_vec(),
    }
}

/// A GET of `target` with the given Host (none when `None`).
pub async fn get_with_host(addr: SocketAddr, target: &str, host: Option<&str>) -> Answer {
    let host = host.map(|h| format!("host: {h}\r\n")).unwrap_or_default();
    send(
        addr,
        format!("GET {target} HTTP/1.1\r\n{host}connection: close\r\n\r\n").as_bytes(),
    )
    .await
}
