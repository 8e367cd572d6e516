//! `solidtex loadtest`: a closed-loop HTTP client that measures a running
//! server under concurrent voxel requests.
//!
//! Each of `concurrency` clients sends a request, waits for the whole
//! answer, records it and sends the next, until the duration is over; the
//! requests still in flight then are waited for, so every request sent is
//! accounted for. A 503 is honoured: the client sleeps its `Retry-After`
//! (as a well-behaved renderer would) instead of hammering the queue.
//!
//! - [`workload`]: which requests are sent (random mixed, or a sweep).
//! - [`report`]: histograms, status counts, the table and JSON.
//! - [`scrape`]: the server's `/metrics` before, during and after the run.

pub mod churn;
pub mod report;
pub mod scrape;
pub mod workload;

use anyhow::{Context, bail};
use parking_lot::Mutex;
use report::{Recorder, Report};
use reqwest::header::{ETAG, IF_NONE_MATCH, RETRY_AFTER};
use scrape::{Peaks, Scrape, ServerDelta};
use std::sync::Arc;
use std::time::{Duration, Instant};
use workload::{Kind, Mixed, Request, Shape, Sweep, SweepPlane};

/// How a load test runs.
#[derive(Clone, Debug)]
pub struct LoadConfig {
    /// The server, e.g. `http://127.0.0.1:8080`.
    pub url: String,
    /// Texture id.
    pub texture: String,
    /// Concurrent clients.
    pub concurrency: usize,
    /// How long new requests are sent.
    pub duration: Duration,
    /// Kinds of the mixed workload, drawn uniformly.
    pub mix: Vec<Kind>,
    /// Seed of every client's request sequence.
    pub seed: u64,
    /// Level of detail of every request (higher is cheaper).
    pub lod: u32,
    /// Side of slices and cuts, pixels.
    pub side: u32,
    /// Fraction of mixed requests inside a small shared box (overlapping).
    pub overlap: f64,
    /// Fraction of requests that revalidate an earlier answer with
    /// `If-None-Match` (expecting 304).
    pub revalidate: f64,
    /// Replay plane sweeps instead of the mixed workload.
    pub sweep: Option<SweepPlane>,
    /// Give up on one request after this long.
    pub timeout: Duration,
    /// Also upload, read and delete textures and hang up on requests
    /// while the load runs (a soak).
    pub churn: bool,
    /// Compare a sample of the answers with this fresh server's (base URL,
    /// serving the same texture).
    pub verify_url: Option<String>,
}

impl LoadConfig {
    /// A short default workload against `url` and `texture`.
    pub fn new(url: impl Into<String>, texture: impl Into<String>) -> LoadConfig {
        LoadConfig {
            url: url.into(),
            texture: texture.into(),
            concurrency: 8,
            duration: Duration::from_secs(30),
            mix: Kind::ALL.to_vec(),
            seed: 1,
            lod: 0,
            side: 256,
            overlap: 0.5,
            revalidate: 0.05,
            sweep: None,
            timeout: Duration::from_secs(120),
            churn: false,
            verify_url: None,
        }
    }

    fn describe(&self) -> String {
        match self.sweep {
            Some(p) => format!(
                "sweep of {}² {} planes, lod {}",
                self.side,
                match p {
                    SweepPlane::Axis => "axis",
                    SweepPlane::Oblique => "oblique",
                },
                self.lod
            ),
            None => format!(
                "mix {} at {}², lod {}, {:.0} % overlapping, {:.0} % revalidations, seed {}",
                self.mix
                    .iter()
                    .map(|k| k.name())
                    .collect::<Vec<_>>()
                    .join(","),
                self.side,
                self.lod,
                100.0 * self.overlap,
                100.0 * self.revalidate,
                self.seed
            ),
        }
    }
}

/// Parses a duration such as `30s`, `2m`, `500ms` or `1.5` (seconds).
pub fn parse_duration(s: &str) -> Result<Duration, String> {
    let t = s.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let n: f64 = num
        .parse()
        .map_err(|_| format!("`{s}` is not a duration (e.g. 30s, 2m, 500ms)"))?;
    let seconds = match unit {
        "" | "s" => n,
        "ms" => n / 1000.0,
        "m" | "min" => n * 60.0,
        "h" => n * 3600.0,
        other => return Err(format!("unknown duration unit `{other}` (use ms, s, m, h)")),
    };
    Duration::try_from_secs_f64(seconds).map_err(|e| format!("`{s}`: {e}"))
}

/// What the load test needs to know about the texture.
struct TextureInfo {
    brick_size: u32,
    max_lod: u32,
}

async fn texture_info(client: &reqwest::Client, cfg: &LoadConfig) -> anyhow::Result<TextureInfo> {
    let url = format!("{}/v1/textures/{}", cfg.url, cfg.texture);
    let r = client
        .get(&url)
        .send()
        .await
        .with_context(|| format!("GET {url}"))?;
    let status = r.status();
    let v: serde_json::Value = r.json().await.context("texture description")?;
    if !status.is_success() {
        bail!("GET {url}: {status} {v}");
    }
    if v["status"] != "ready" {
        bail!("texture `{}` is not ready: {}", cfg.texture, v["status"]);
    }
    let field = |name: &str| {
        v[name]
            .as_u64()
            .map(|n| n as u32)
            .with_context(|| format!("texture description lacks `{name}`"))
    };
    Ok(TextureInfo {
        brick_size: field("brick_size")?,
        max_lod: field("max_lod")?,
    })
}

async fn scrape(client: &reqwest::Client, base: &str) -> Option<Scrape> {
    let r = client.get(format!("{base}/metrics")).send().await.ok()?;
    if !r.status().is_success() {
        return None;
    }
    Some(Scrape::parse(&r.text().await.ok()?))
}

/// A client's request source.
enum Source {
    Mixed(Mixed),
    Sweep(Sweep),
}

impl Source {
    fn next_request(&mut self) -> Request {
        match self {
            Source::Mixed(m) => m.next_request(),
            Source::Sweep(s) => s.next_request(),
        }
    }
}

/// Answers a client keeps for revalidation (a bounded ring).
const REMEMBERED: usize = 64;

/// Answers a client keeps the fingerprint of, for `verify_url`.
const SAMPLED: usize = 48;

/// One closed-loop client.
async fn client_loop(
    client: reqwest::Client,
    base: String,
    mut source: Source,
    mut rng: workload::Rng,
    revalidate: f64,
    deadline: Instant,
) -> (Recorder, Vec<(String, u64)>) {
    let mut rec = Recorder::default();
    let mut seen: Vec<(Request, String)> = Vec::new();
    let mut samples: Vec<(String, u64)> = Vec::new();
    while Instant::now() < deadline {
        let revisit = !seen.is_empty() && rng.unit() < revalidate;
        let (req, etag) = if revisit {
            let (r, e) = &seen[(rng.next_u64() % seen.len() as u64) as usize];
            (r.clone(), Some(e.clone()))
        } else {
            (source.next_request(), None)
        };
        let mut get = client.get(format!("{base}{}", req.path));
        if let Some(e) = &etag {
            get = get.header(IF_NONE_MATCH, e);
        }
        let t0 = Instant::now();
        let answer = match get.send().await {
            Ok(r) => {
                let status = r.status().as_u16();
                let tag = r
                    .headers()
                    .get(ETAG)
                    .and_then(|v| v.to_str().ok())
                    .map(String::from);
                let retry = r
                    .headers()
                    .get(RETRY_AFTER)
                    .and_then(|v| v.to_str().ok())
                    .and_then(|v| v.parse::<u64>().ok());
                r.bytes()
                    .await
                    .map(|b| (status, tag, retry, b.len(), churn::fingerprint(&b)))
            }
            Err(e) => Err(e),
        };
        let micros = t0.elapsed().as_micros() as u64;
        match answer {
            Ok((status, tag, retry, bytes, print)) => {
                rec.kind(req.kind).answered(status, micros, bytes as u64);
                if status == 200 && samples.len() < SAMPLED {
                    samples.push((req.path.clone(), print));
                }
                if let (200, Some(tag), None) = (status, tag, &etag) {
                    if seen.len() < REMEMBERED {
                        seen.push((req, tag));
                    } else {
                        let i = (rng.next_u64() % REMEMBERED as u64) as usize;
                        seen[i] = (req, tag);
                    }
                }
                if status == 503 {
                    let wait = Duration::from_secs(retry.unwrap_or(1).clamp(1, 10));
                    tokio::time::sleep_until((Instant::now() + wait).min(deadline).into()).await;
                }
            }
            Err(_) => {
                rec.kind(req.kind).statuses.transport_errors += 1;
                // A refused connection fails at once: don't spin on it.
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
        }
    }
    (rec, samples)
}

/// Runs a load test against a live server.
pub async fn run(cfg: &LoadConfig) -> anyhow::Result<Report> {
    if cfg.concurrency == 0 {
        bail!("concurrency must be at least 1");
    }
    if cfg.mix.is_empty() && cfg.sweep.is_none() {
        bail!("the mix needs at least one of slices, cuts, bricks");
    }
    let base = cfg.url.trim_end_matches('/').to_string();
    let client = reqwest::Client::builder()
        .no_proxy()
        .tcp_nodelay(true)
        .pool_max_idle_per_host(cfg.concurrency + 2)
        .timeout(cfg.timeout)
        .build()
        .context("building the HTTP client")?;
    let info = texture_info(
        &client,
        &LoadConfig {
            url: base.clone(),
            ..cfg.clone()
        },
    )
    .await?;
    if cfg.lod > info.max_lod {
        bail!(
            "lod {} exceeds the texture's max_lod {}",
            cfg.lod,
            info.max_lod
        );
    }
    let shape = Shape {
        lod: cfg.lod,
        side: cfg.side,
        brick_size: info.brick_size,
        overlap: cfg.overlap,
    };
    let before = scrape(&client, &base).await;
    let peaks = Arc::new(Mutex::new(Peaks::default()));
    if let Some(s) = &before {
        peaks.lock().observe(s);
    }
    let texture_url = format!("{base}/v1/textures/{}", cfg.texture);
    let t0 = Instant::now();
    let deadline = t0 + cfg.duration;
    // Memory peaks between the end scrapes matter: sample twice a second.
    let sampler = {
        let (client, base, peaks) = (client.clone(), base.clone(), peaks.clone());
        tokio::spawn(async move {
            loop {
                tokio::time::sleep(Duration::from_millis(500)).await;
                if let Some(s) = scrape(&client, &base).await {
                    peaks.lock().observe(&s);
                }
            }
        })
    };
    let mut clients = Vec::new();
    for worker in 0..cfg.concurrency as u64 {
        let source = match cfg.sweep {
            Some(plane) => Source::Sweep(Sweep::new(cfg.seed, worker, plane, shape.clone())),
            None => Source::Mixed(Mixed::new(cfg.seed, worker, cfg.mix.clone(), shape.clone())),
        };
        // A separate stream decides revalidations, so they don't shift the
        // request sequence.
        let rng = workload::Rng::new(cfg.seed ^ 0x5eed, worker);
        clients.push(tokio::spawn(client_loop(
            client.clone(),
            texture_url.clone(),
            source,
            rng,
            if cfg.sweep.is_some() {
                0.0
            } else {
                cfg.revalidate
            },
            deadline,
        )));
    }
    let churn = cfg.churn.then(|| {
        tokio::spawn(churn::churn(
            client.clone(),
            base.clone(),
            texture_url.clone(),
            cfg.seed,
            deadline,
        ))
    });
    let mut all = Recorder::default();
    let mut samples = Vec::new();
    for c in clients {
        let (rec, s) = c.await.context("client task")?;
        all.merge(&rec);
        samples.extend(s);
    }
    let churn = match churn {
        Some(c) => Some(c.await.context("churn task")?),
        None => None,
    };
    let elapsed = t0.elapsed().as_secs_f64();
    sampler.abort();
    let verify = match &cfg.verify_url {
        Some(fresh) => {
            let fresh = format!(
                "{}/v1/textures/{}",
                fresh.trim_end_matches('/'),
                cfg.texture
            );
            Some(churn::verify(&client, &fresh, &samples).await)
        }
        None => None,
    };
    let after = scrape(&client, &base).await;
    let server = match (before, after) {
        (Some(b), Some(a)) => {
            let mut p = *peaks.lock();
            p.observe(&a);
            Some(ServerDelta::between(&b, &a, p))
        }
        _ => None,
    };
    let (kinds, total) = all.summarise(elapsed);
    Ok(Report {
        workload: cfg.describe(),
        concurrency: cfg.concurrency,
        elapsed_s: elapsed,
        cuts_per_s: cfg.sweep.map(|_| total.requests_per_s),
        kinds,
        total,
        server,
        churn,
        verify,
    })
}

/// Runs a load test on a runtime of its own (for the command line).
pub fn run_blocking(cfg: &LoadConfig) -> anyhow::Result<Report> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .thread_name("loadtest")
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    rt.block_on(run(cfg))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations() {
        assert_eq!(parse_duration("30s"), Ok(Duration::from_secs(30)));
        assert_eq!(parse_duration("2m"), Ok(Duration::from_secs(120)));
        assert_eq!(parse_duration("500ms"), Ok(Duration::from_millis(500)));
        assert_eq!(parse_duration("1.5"), Ok(Duration::from_millis(1500)));
        assert!(parse_duration("soon").is_err());
        assert!(parse_duration("3 fortnights").is_err());
    }
}
