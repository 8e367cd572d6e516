//! The service under load, for the benchmark page: `solidtex serve` in a
//! child process with default settings (its data in a temporary
//! directory), the synthesis exemplar uploaded over HTTP as a user would,
//! then four `solidtex loadtest` runs, each against a freshly started
//! server (cold cache) — one client, one client on a server synthesizing
//! on one thread (the throughput of one core, which the many-client run is
//! compared with: one client alone already keeps every core busy), many
//! clients, and an interactive plane sweep.

use crate::loadtest::report::{KindSummary, Report};
use crate::loadtest::workload::{Kind, SweepPlane};
use crate::loadtest::{self, LoadConfig};
use anyhow::{Context, bail};
use serde::Serialize;
use std::fmt::Write;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// How the service is loaded.
#[derive(Clone, Debug)]
pub struct LoadOptions {
    /// Level of detail of the mixed runs.
    pub lod: u32,
    /// Level of detail of the sweep.
    pub sweep_lod: u32,
    /// Side of slices and cuts.
    pub side: u32,
    /// Side of the sweep's planes.
    pub sweep_side: u32,
    /// Clients of the concurrent run.
    pub clients: usize,
    /// Duration of each run.
    pub duration: Duration,
    /// The server's tile cache bound, bytes.
    pub cache_bytes: u64,
    /// The server's brick edge.
    pub brick_size: u32,
    /// The server's limit on a job's wait for a slot, seconds.
    pub max_queue_wait: f64,
}

/// One load-test run.
#[derive(Clone, Debug, Serialize)]
pub struct LoadRow {
    /// What ran.
    pub name: String,
    /// The target, where there is one.
    pub target: Option<&'static str>,
    /// The load test's report.
    pub report: Report,
    /// Derived figures (scaling against one client).
    pub note: String,
}

/// Removes the temporary data directory however the run ends.
struct TempDir(PathBuf);

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A `solidtex serve` child process, killed when dropped. A process of its
/// own gives the server its own resident memory to measure, untouched by
/// the benchmark's earlier allocations.
struct ServerProcess {
    child: Child,
    base: String,
}

impl ServerProcess {
    fn start(data_dir: &Path, o: &LoadOptions, threads: usize) -> anyhow::Result<ServerProcess> {
        let mut child = Command::new(std::env::current_exe()?)
            .arg("serve")
            .env("SOLIDTEX_WORKER_THREADS", threads.to_string())
            .env("SOLIDTEX_ADDR", "127.0.0.1:0")
            .env("SOLIDTEX_DATA_DIR", data_dir)
            .env("SOLIDTEX_DEFAULT_TEXTURE", "false")
            .env("SOLIDTEX_CACHE_BYTES", o.cache_bytes.to_string())
            .env("SOLIDTEX_BRICK_SIZE", o.brick_size.to_string())
            .env("SOLIDTEX_MAX_QUEUE_WAIT", o.max_queue_wait.to_string())
            .env("SOLIDTEX_LOG", "warn")
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .context("starting `solidtex serve`")?;
        let out = child.stdout.take();
        // Owned from here on, so a failure below still kills the child.
        let mut server = ServerProcess {
            child,
            base: String::new(),
        };
        let mut line = String::new();
        BufReader::new(out.context("server stdout")?).read_line(&mut line)?;
        match line.trim().strip_prefix("solidtex listening on ") {
            Some(base) => {
                server.base = base.to_string();
                Ok(server)
            }
            None => bail!("the server did not start: {line:?}"),
        }
    }
}

impl Drop for ServerProcess {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Runs the three load tests, each against a fresh server process (cold
/// cache, the texture loaded from the data directory).
pub fn measure(exemplar: &Path, levels: u32, o: &LoadOptions) -> anyhow::Result<Vec<LoadRow>> {
    let dir = TempDir(std::env::temp_dir().join(format!("solidtex-bench-{}", std::process::id())));
    std::fs::create_dir_all(&dir.0)?;
    let png = std::fs::read(exemplar).with_context(|| format!("reading {}", exemplar.display()))?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    // (name, clients, synthesis threads (0: every core), sweep, preview
    // parameters, target)
    type Run = (
        String,
        usize,
        usize,
        Option<SweepPlane>,
        bool,
        Option<&'static str>,
    );
    let sweep_target = Some("≥ 30 cuts/s at 256², lod 0");
    let runs: [Run; 5] = [
        (
            format!("1 client, mixed, {}², lod {}", o.side, o.lod),
            1,
            0,
            None,
            false,
            None,
        ),
        (
            format!(
                "1 client, mixed, {}², lod {}, one synthesis thread",
                o.side, o.lod
            ),
            1,
            1,
            None,
            false,
            None,
        ),
        (
            format!("{} clients, mixed, {}², lod {}", o.clients, o.side, o.lod),
            o.clients,
            0,
            None,
            false,
            Some("p99 ≤ 3 s; no errors but 503; RSS ≤ cache + 256 MiB"),
        ),
        (
            format!("sweep, axis {}², lod {}", o.sweep_side, o.sweep_lod),
            1,
            0,
            Some(SweepPlane::Axis),
            false,
            sweep_target,
        ),
        (
            format!(
                "sweep, axis {}², lod {}, preview parameters",
                o.sweep_side, o.sweep_lod
            ),
            1,
            0,
            Some(SweepPlane::Axis),
            true,
            sweep_target,
        ),
    ];
    let mut rows = Vec::new();
    // The default texture's id, and the preview texture's.
    let mut ids: [Option<String>; 2] = [None, None];
    for (i, (name, clients, threads, sweep, preview, target)) in runs.into_iter().enumerate() {
        let server = ServerProcess::start(&dir.0, o, threads)?;
        let base = server.base.clone();
        let report = runtime.block_on(async {
            let id = match &mut ids[preview as usize] {
                Some(id) => id,
                slot @ None => slot.insert(upload(&base, png.clone(), levels, preview).await?),
            };
            let cfg = LoadConfig {
                concurrency: clients,
                duration: o.duration,
                seed: i as u64 + 1,
                lod: if sweep.is_some() { o.sweep_lod } else { o.lod },
                side: if sweep.is_some() {
                    o.sweep_side
                } else {
                    o.side
                },
                sweep,
                timeout: Duration::from_secs(600),
                ..LoadConfig::new(base.clone(), id.clone())
            };
            loadtest::run(&cfg).await
        })?;
        drop(server);
        rows.push(LoadRow {
            name,
            target,
            report,
            note: String::new(),
        });
    }
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get()) as f64;
    // Throughput counts answers (2xx and 304), not the 503s shed.
    let answered = |r: &Report| {
        let s = &r.total.statuses;
        (s.ok + s.not_modified) as f64 / r.elapsed_s.max(1e-9)
    };
    let (single, one_core) = (answered(&rows[0].report), answered(&rows[1].report));
    if single > 0.0 && one_core > 0.0 {
        let many = answered(&rows[2].report);
        rows[2].note = format!(
            "{many:.2} answers/s: {:.0} % of one core's {one_core:.2}/s × {cores} cores \
             (target ≥ 85 %); {:.0} % of 1 client's {single:.2}/s × {cores}, a client \
             that already keeps every core busy",
            100.0 * many / (one_core * cores),
            100.0 * many / (single * cores)
        );
    }
    for row in &mut rows[3..] {
        row.note = format!("{:.2} cuts/s", row.report.total.requests_per_s);
    }
    Ok(rows)
}

/// Uploads the exemplar with `levels` levels, and with the preview
/// parameters (`SynthParams::preview`) when `preview` is set; waits until
/// the texture is ready.
async fn upload(base: &str, png: Vec<u8>, levels: u32, preview: bool) -> anyhow::Result<String> {
    let c = reqwest::Client::builder().no_proxy().build()?;
    let mut query = format!("levels={levels}");
    if preview {
        query += "&preset=preview";
    }
    let r = c
        .post(format!("{base}/v1/textures?{query}"))
        .header("content-type", "image/png")
        .body(png)
        .send()
        .await?;
    let status = r.status();
    let v: serde_json::Value = r.json().await?;
    if !status.is_success() {
        bail!("upload answered {status}: {v}");
    }
    let id = v["id"]
        .as_str()
        .context("upload answer lacks `id`")?
        .to_string();
    let t0 = Instant::now();
    loop {
        let v: serde_json::Value = c
            .get(format!("{base}/v1/textures/{id}"))
            .send()
            .await?
            .json()
            .await?;
        match v["status"].as_str() {
            Some("ready") => return Ok(id),
            Some("pending") if t0.elapsed() < Duration::from_secs(600) => {}
            _ => bail!("texture {id} did not become ready: {v}"),
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

fn statuses(k: &KindSummary) -> String {
    let s = &k.statuses;
    format!(
        "{}/{}/{}/{}/{}",
        s.ok, s.not_modified, s.unavailable, s.other, s.transport_errors
    )
}

/// The runs as a Markdown table (also readable as plain text).
pub fn table(rows: &[LoadRow]) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "| run | requests | req/s | MB/s | p50 | p95 | p99 | max | 2xx/304/503/other/error | \
         tiles computed / from cache | server RSS peak (cache bound) | target | note |"
    );
    let _ = writeln!(
        out,
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- | --- | --- | --- | --- |"
    );
    for r in rows {
        let t = &r.report.total;
        let server = r.report.server.as_ref();
        let tiles = server.map_or("-".into(), |d| {
            format!(
                "{:.0} / {:.0} ({:.0} % hits)",
                d.tiles_computed,
                d.tiles_from_cache,
                100.0 * d.tile_hit_rate
            )
        });
        let rss = server.map_or("-".into(), |d| {
            format!(
                "{:.0} MiB ({:.0} MiB)",
                d.peaks.resident_bytes / 1048576.0,
                d.cache_max_bytes / 1048576.0
            )
        });
        let _ = writeln!(
            out,
            "| {} | {} | {:.2} | {:.2} | {:.0} ms | {:.0} ms | {:.0} ms | {:.0} ms | {} | {} | {} | {} | {} |",
            r.name,
            t.requests,
            t.requests_per_s,
            t.megabytes_per_s,
            t.p50_ms,
            t.p95_ms,
            t.p99_ms,
            t.max_ms,
            statuses(t),
            tiles,
            rss,
            r.target.unwrap_or(""),
            r.note
        );
    }
    let kinds: Vec<&str> = Kind::ALL.iter().map(|k| k.name()).collect();
    let _ = writeln!(
        out,
        "\nMixed runs draw {} uniformly, half of them inside a shared box (overlapping), \
         5 % revalidations; each run lasts its duration plus the time to answer the \
         requests still in flight.",
        kinds.join(", ")
    );
    out
}
