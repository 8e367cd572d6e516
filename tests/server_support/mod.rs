//! The HTTP side of the tests: a real server on a free loopback port, an
//! HTTP client, and helpers to upload, poll, read answers and metrics.
//! Exemplars come from `common`.
#![allow(dead_code)]

#[allow(unused_imports)]
pub use crate::common::{
    blocky_rgb, claim_jpeg_size, decode_png, encode_jpeg, encode_png, exemplar_png, grain_png,
    image_fixture,
};
use serde_json::Value;
use solidtex_server::{ServeArgs, Server};
use std::net::SocketAddr;
use std::path::Path;
use std::time::{Duration, Instant};
use tokio::sync::oneshot;
use tokio::task::JoinHandle;

/// Fast analysis parameters for a 32² exemplar (precompute well under a
/// second).
pub const SMALL_PARAMS: &str = "levels=3";

/// Server options for tests: loopback port 0, data in `dir`, small bricks.
pub fn test_args(dir: &Path) -> ServeArgs {
    let mut a = ServeArgs::for_data_dir(dir);
    a.brick_size = 16;
    a.cache_bytes = 64 << 20;
    a.max_upload_bytes = 256 << 10;
    a
}

/// A server running in this process.
pub struct TestServer {
    /// `http://127.0.0.1:PORT`
    pub base: String,
    /// Bound address.
    pub addr: SocketAddr,
    /// Handler state.
    pub state: solidtex_server::routes::AppState,
    stop: Option<oneshot::Sender<()>>,
    handle: Option<JoinHandle<anyhow::Result<()>>>,
}

impl TestServer {
    /// Binds and runs a server.
    pub async fn start(args: ServeArgs) -> TestServer {
        let server = Server::bind(&args).await.expect("server binds");
        // The tests ask for what the data directory held as soon as they
        // start; the start in the background is tested on its own.
        server.loaded().await;
        let addr = server.local_addr().unwrap();
        assert!(addr.ip().is_loopback());
        let state = server.state();
        let (tx, rx) = oneshot::channel::<()>();
        let handle = tokio::spawn(server.run(async move {
            let _ = rx.await;
        }));
        TestServer {
            base: format!("http://{addr}"),
            addr,
            state,
            stop: Some(tx),
            handle: Some(handle),
        }
    }

    /// Absolute URL of `path`.
    pub fn url(&self, path: &str) -> String {
        format!("{}{}", self.base, path)
    }

    /// Stops accepting and waits for in-flight requests.
    pub async fn stop(mut self) {
        if let Some(tx) = self.stop.take() {
            let _ = tx.send(());
        }
        if let Some(h) = self.handle.take() {
            h.await.unwrap().unwrap();
        }
    }
}

/// An HTTP client without connection reuse surprises.
pub fn client() -> reqwest::Client {
    reqwest::Client::builder()
        .no_proxy()
        .timeout(Duration::from_secs(120))
        .build()
        .unwrap()
}

/// Uploads a PNG with query parameters; returns (status, body).
pub async fn upload(
    c: &reqwest::Client,
    s: &TestServer,
    png: Vec<u8>,
    query: &str,
) -> (u16, Value) {
    let r = c
        .post(s.url(&format!("/v1/textures?{query}")))
        .header("content-type", "image/png")
        .body(png)
        .send()
        .await
        .unwrap();
    let status = r.status().as_u16();
    (status, r.json().await.unwrap())
}

/// A multipart form part holding PNG bytes, as a browser sends a file.
pub fn png_part(bytes: Vec<u8>) -> reqwest::multipart::Part {
    reqwest::multipart::Part::bytes(bytes)
        .file_name("e.png")
        .mime_str("image/png")
        .unwrap()
}

/// Uploads a multipart form; returns (status, body).
pub async fn upload_form(
    c: &reqwest::Client,
    s: &TestServer,
    form: reqwest::multipart::Form,
) -> (u16, Value) {
    let (status, _, body) = post_form(c, &s.url("/v1/textures"), form).await;
    (status, serde_json::from_slice(&body).unwrap())
}

/// POSTs a multipart form and returns (status, headers, body).
pub async fn post_form(
    c: &reqwest::Client,
    url: &str,
    form: reqwest::multipart::Form,
) -> (u16, reqwest::header::HeaderMap, Vec<u8>) {
    let r = c.post(url).multipart(form).send().await.unwrap();
    let status = r.status().as_u16();
    let headers = r.headers().clone();
    (status, headers, r.bytes().await.unwrap().to_vec())
}

/// GETs `path` and reads its JSON body, whatever the status.
pub async fn get_json(c: &reqwest::Client, s: &TestServer, path: &str) -> Value {
    get_json_url(c, &s.url(path)).await
}

/// GETs a URL and reads its JSON body, whatever the status.
pub async fn get_json_url(c: &reqwest::Client, url: &str) -> Value {
    c.get(url).send().await.unwrap().json().await.unwrap()
}

/// Polls a texture until it is ready (panics if it fails or takes too long).
pub async fn wait_ready(c: &reqwest::Client, s: &TestServer, id: &str) -> Value {
    let t0 = Instant::now();
    loop {
        let v = get_json(c, s, &format!("/v1/textures/{id}")).await;
        match v["status"].as_str() {
            Some("ready") => return v,
            Some("pending") => {}
            other => panic!("texture {id} is {other:?}: {v}"),
        }
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "precompute too slow"
        );
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
}

/// A server on a fresh data directory (kept while the directory lives)
/// with one ready texture made from [`exemplar_png`] of `seed`, and a client.
pub async fn server_with_texture(
    seed: u32,
) -> (tempfile::TempDir, TestServer, reqwest::Client, String) {
    let dir = tempfile::tempdir().unwrap();
    let s = TestServer::start(test_args(dir.path())).await;
    let c = client();
    let id = ready_texture(&c, &s, seed).await;
    (dir, s, c, id)
}

/// Uploads a small exemplar and waits until it is ready; returns its id.
pub async fn ready_texture(c: &reqwest::Client, s: &TestServer, seed: u32) -> String {
    let (status, v) = upload(c, s, exemplar_png(32, seed), SMALL_PARAMS).await;
    assert!(status == 201 || status == 202, "{status} {v}");
    let id = v["id"].as_str().unwrap().to_string();
    wait_ready(c, s, &id).await;
    id
}

/// GETs a URL and returns (status, headers, body).
pub async fn get(c: &reqwest::Client, url: &str) -> (u16, reqwest::header::HeaderMap, Vec<u8>) {
    let r = c.get(url).send().await.unwrap();
    let status = r.status().as_u16();
    let headers = r.headers().clone();
    (status, headers, r.bytes().await.unwrap().to_vec())
}

/// Asserts an error response: status, JSON shape and code.
pub fn assert_error(
    status: u16,
    headers: &reqwest::header::HeaderMap,
    body: &[u8],
    want_status: u16,
    want_code: &str,
) {
    let v: Value = serde_json::from_slice(body)
        .unwrap_or_else(|_| panic!("error body is not JSON: {}", String::from_utf8_lossy(body)));
    assert_eq!(status, want_status, "{v}");
    assert_eq!(
        headers.get("content-type").unwrap().to_str().unwrap(),
        "application/json"
    );
    assert_eq!(v["error"]["code"], want_code, "{v}");
    assert!(
        v["error"]["message"]
            .as_str()
            .is_some_and(|m| !m.is_empty()),
        "{v}"
    );
}

/// The value of a metric sample in Prometheus text (`name{labels}` as
/// written), 0 when absent.
pub fn metric(text: &str, sample: &str) -> f64 {
    text.lines()
        .filter(|l| !l.starts_with('#'))
        .find_map(|l| {
            let (k, v) = l.rsplit_once(' ')?;
            (k == sample).then(|| v.parse().unwrap())
        })
        .unwrap_or(0.0)
}

/// Scrapes `/metrics`.
pub async fn metrics(c: &reqwest::Client, s: &TestServer) -> String {
    text_at(c, &s.url("/metrics")).await
}

/// GETs a URL and reads its body as text, whatever the status.
pub async fn text_at(c: &reqwest::Client, url: &str) -> String {
    c.get(url).send().await.unwrap().text().await.unwrap()
}

/// POSTs `body` as `content_type`; returns (status, JSON body).
pub async fn post_body(
    c: &reqwest::Client,
    url: &str,
    content_type: &str,
    body: impl Into<reqwest::Body>,
) -> (u16, Value) {
    let r = c
        .post(url)
        .header("content-type", content_type)
        .body(body)
        .send()
        .await
        .unwrap();
    let status = r.status().as_u16();
    (status, r.json().await.unwrap())
}

/// DELETEs a URL; returns the status.
pub async fn delete(c: &reqwest::Client, url: &str) -> u16 {
    c.delete(url).send().await.unwrap().status().as_u16()
}

/// The real binary, `solidtex serve`, on a free loopback port with its
/// data in `data_dir` and the `SOLIDTEX_*` variables of `env`; killed when
/// dropped.
pub struct BinaryServer {
    /// `http://127.0.0.1:PORT`
    pub base: String,
    child: std::process::Child,
}

impl BinaryServer {
    /// Starts it and waits for its `listening on` line.
    pub fn start(data_dir: &Path, env: &[(&str, &str)]) -> BinaryServer {
        use std::io::BufRead;
        let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_solidtex"));
        cmd.arg("serve")
            .env("SOLIDTEX_ADDR", "127.0.0.1:0")
            .env("SOLIDTEX_DATA_DIR", data_dir)
            .env("SOLIDTEX_LOG", "warn")
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::null());
        for (k, v) in env {
            cmd.env(k, v);
        }
        let mut child = cmd.spawn().unwrap();
        let mut line = String::new();
        std::io::BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let base = line
            .trim()
            .strip_prefix("solidtex listening on ")
            .unwrap_or_else(|| panic!("unexpected first line {line:?}"))
            .to_string();
        BinaryServer { base, child }
    }

    /// Absolute URL of `path`.
    pub fn url(&self, path: &str) -> String {
        format!("{}{}", self.base, path)
    }

    /// Its `/metrics` text.
    pub async fn metrics(&self, c: &reqwest::Client) -> String {
        text_at(c, &self.url("/metrics")).await
    }
}

impl Drop for BinaryServer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The server's bound on its resident memory in a `/metrics` text: the
/// sum of the parts of `solidtex_memory_bound_bytes`.
pub fn memory_bound(text: &str) -> f64 {
    text.lines()
        .filter(|l| l.starts_with("solidtex_memory_bound_bytes{"))
        .filter_map(|l| l.rsplit_once(' ')?.1.parse::<f64>().ok())
        .sum()
}
