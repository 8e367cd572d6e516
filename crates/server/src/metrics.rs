//! Prometheus metrics of the service, served as text at `/metrics`.
//!
//! Each server owns its registry (no process-global state), so several
//! servers in one process — as in the tests — count separately. Request
//! counters and latency histograms are labelled by route template (never
//! by raw path, which would explode cardinality); tile-cache counters and
//! the process's resident memory and threads are read at scrape time.

use prometheus_client::collector::Collector;
use prometheus_client::encoding::{DescriptorEncoder, EncodeLabelSet, EncodeMetric};
use prometheus_client::metrics::counter::{ConstCounter, Counter};
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::{ConstGauge, Gauge};
use prometheus_client::metrics::histogram::{Histogram, exponential_buckets};
use prometheus_client::registry::Registry;
use solidtex_core::{SynthStats, TileCache};
use std::sync::Arc;

/// Labels of a request counter.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct RequestLabels {
    /// Route template, e.g. `/v1/textures/{id}/cut.png`.
    pub route: String,
    /// HTTP method: a standard one's name, else `other`.
    pub method: String,
    /// Response status code.
    pub status: String,
}

/// Labels of a per-route histogram.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct RouteLabels {
    /// Route template.
    pub route: String,
}

/// Labels of per-level counters.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct LevelLabels {
    /// Pyramid level, 0 = finest.
    pub level: String,
}

/// Labels of precompute outcomes.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct OutcomeLabels {
    /// `ok`, `reused` (candidates shared with another texture), `failed`
    /// or `cancelled` (its texture deleted while it ran).
    pub outcome: String,
}

/// Labels of the over-budget counter.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct StageLabels {
    /// `predicted` (refused before any work) or `running` (stopped).
    pub stage: String,
}

/// Labels of the memory bound's parts.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct PartLabels {
    /// `base`, `cache`, `candidates`, `precomputes`, `jobs`, `decodes`,
    /// `allocator`.
    pub part: String,
}

/// Labels of the background job gauge.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct BackgroundLabels {
    /// `export` or `bake`.
    pub kind: String,
    /// `queued`, `running`, `done`, `failed` or `cancelled`.
    pub state: String,
}

/// Labels of the texture gauge.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct StatusLabels {
    /// `pending`, `ready` or `failed`.
    pub status: String,
}

fn latency_histogram() -> Histogram {
    Histogram::new(exponential_buckets(0.0005, 2.0, 18))
}

fn precompute_histogram() -> Histogram {
    Histogram::new(exponential_buckets(0.05, 2.0, 14))
}

/// All metrics of one server.
pub struct Metrics {
    registry: Registry,
    /// HTTP requests by route, method and status.
    pub requests: Family<RequestLabels, Counter>,
    /// Request latency by route, seconds.
    pub latency: Family<RouteLabels, Histogram, fn() -> Histogram>,
    /// Voxels produced by synthesis, per level.
    pub voxels: Family<LevelLabels, Counter>,
    /// Voxel corrections performed, per level.
    pub corrections: Family<LevelLabels, Counter>,
    /// Tiles computed by requests.
    pub tiles_computed: Counter,
    /// Tiles requests found in the cache.
    pub tiles_from_cache: Counter,
    /// Synthesis jobs waiting for a slot.
    pub jobs_queued: Gauge,
    /// Synthesis jobs running.
    pub jobs_running: Gauge,
    /// Requests turned away: queue full, predicted wait too long, or wait
    /// limit reached.
    pub jobs_rejected: Counter,
    /// Of those, jobs that waited the whole limit without a slot.
    pub jobs_timed_out: Counter,
    /// Running jobs stopped because their client went away.
    pub jobs_cancelled: Counter,
    /// Time admitted jobs waited for a running slot, seconds.
    pub job_wait: Histogram,
    /// Requests answered 400 `over_budget`, by when.
    pub over_budget: Family<StageLabels, Counter>,
    /// Precomputations finished, by outcome.
    pub precomputes: Family<OutcomeLabels, Counter>,
    /// Precomputation duration, seconds.
    pub precompute_seconds: Histogram,
    /// Precomputations queued or running.
    pub precomputes_pending: Gauge,
    /// Heap bytes each precomputation peaked at.
    pub precompute_peak_bytes: Histogram,
    /// Estimated peak bytes of the precomputations running.
    pub precompute_reserved_bytes: Gauge,
    /// Open client connections.
    pub connections_open: Gauge,
    /// Idle connections closed to make room for new ones.
    pub connections_evicted: Counter,
    /// Connections answered 503 because every open one was busy.
    pub connections_refused: Counter,
    /// Textures loaded from the data directory at start.
    pub textures_loaded: Counter,
    /// Stored textures not served because they do not match their id.
    pub textures_refused: Counter,
    /// Textures by status.
    pub textures: Family<StatusLabels, Gauge>,
    /// The server's bound on its resident memory, by part (see
    /// [`super::memory`]); set at each scrape.
    pub memory_bound: Family<PartLabels, Gauge>,
    /// Background jobs (exports, bakes) held, by kind and state; set at
    /// each scrape.
    pub background_jobs: Family<BackgroundLabels, Gauge>,
    /// Bytes of the finished background jobs' files held; set at each
    /// scrape.
    pub background_bytes: Gauge,
}

impl Metrics {
    /// A fresh registry; `cache` is read at every scrape. The handles are
    /// made here and registered, in this order, by concern.
    pub fn new(cache: Arc<TileCache>) -> Metrics {
        let mut m = Metrics {
            registry: Registry::with_prefix("solidtex"),
            requests: Default::default(),
            latency: Family::<RouteLabels, Histogram, fn() -> Histogram>::new_with_constructor(
                latency_histogram as fn() -> Histogram,
            ),
            voxels: Default::default(),
            corrections: Default::default(),
            tiles_computed: Default::default(),
            tiles_from_cache: Default::default(),
            jobs_queued: Default::default(),
            jobs_running: Default::default(),
            jobs_rejected: Default::default(),
            jobs_timed_out: Default::default(),
            jobs_cancelled: Default::default(),
            job_wait: latency_histogram(),
            over_budget: Default::default(),
            precomputes: Default::default(),
            precompute_seconds: precompute_histogram(),
            precomputes_pending: Default::default(),
            precompute_peak_bytes: Histogram::new(exponential_buckets(4.0 * 1048576.0, 2.0, 14)),
            precompute_reserved_bytes: Default::default(),
            connections_open: Default::default(),
            connections_evicted: Default::default(),
            connections_refused: Default::default(),
            textures_loaded: Default::default(),
            textures_refused: Default::default(),
            textures: Default::default(),
            memory_bound: Default::default(),
            background_jobs: Default::default(),
            background_bytes: Default::default(),
        };
        m.register_requests();
        m.register_synthesis();
        m.register_jobs();
        m.register_precomputes();
        m.register_connections();
        m.register_textures();
        m.registry
            .register_collector(Box::new(CacheCollector { cache }));
        m.registry.register_collector(Box::new(ProcessCollector));
        m
    }

    /// Registers the HTTP requests' metrics: counted, and timed, by route.
    fn register_requests(&mut self) {
        self.registry.register(
            "http_requests",
            "HTTP requests by route, method and status",
            self.requests.clone(),
        );
        self.registry.register_with_unit(
            "http_request_duration",
            "HTTP request latency by route",
            prometheus_client::registry::Unit::Seconds,
            self.latency.clone(),
        );
    }

    /// Registers the synthesis's metrics: voxels and corrections per level,
    /// tiles computed or found.
    fn register_synthesis(&mut self) {
        self.registry.register(
            "synth_voxels",
            "Voxels synthesized, per pyramid level (0 = finest)",
            self.voxels.clone(),
        );
        self.registry.register(
            "synth_corrections",
            "Voxel corrections performed, per pyramid level",
            self.corrections.clone(),
        );
        self.registry.register(
            "synth_tiles_computed",
            "Tiles synthesized by requests",
            self.tiles_computed.clone(),
        );
        self.registry.register(
            "synth_tiles_from_cache",
            "Tiles requests found in the cache or got from a concurrent request",
            self.tiles_from_cache.clone(),
        );
    }

    /// Registers the job queue's metrics (queued, running, turned away,
    /// stopped, waits) and the requests over budget.
    fn register_jobs(&mut self) {
        self.registry.register(
            "jobs_queued",
            "Synthesis jobs waiting for a slot",
            self.jobs_queued.clone(),
        );
        self.registry.register(
            "jobs_running",
            "Synthesis jobs running",
            self.jobs_running.clone(),
        );
        self.registry.register(
            "jobs_rejected",
            "Requests answered 503 because the queue was full or too slow",
            self.jobs_rejected.clone(),
        );
        self.registry.register(
            "jobs_cancelled",
            "Running synthesis jobs stopped because their client went away",
            self.jobs_cancelled.clone(),
        );
        self.registry.register(
            "jobs_timed_out",
            "Queued jobs answered 503 after waiting the whole wait limit",
            self.jobs_timed_out.clone(),
        );
        self.registry.register_with_unit(
            "job_wait",
            "Time admitted synthesis jobs waited for a running slot",
            prometheus_client::registry::Unit::Seconds,
            self.job_wait.clone(),
        );
        self.registry.register(
            "requests_over_budget",
            "Voxel requests answered 400 over_budget: predicted over it before any work, \
             or stopped while running",
            self.over_budget.clone(),
        );
    }

    /// Registers the precomputations' metrics: outcomes, time, memory.
    fn register_precomputes(&mut self) {
        self.registry.register(
            "precomputes",
            "Candidate precomputations finished, by outcome",
            self.precomputes.clone(),
        );
        self.registry.register_with_unit(
            "precompute_duration",
            "Candidate precomputation time",
            prometheus_client::registry::Unit::Seconds,
            self.precompute_seconds.clone(),
        );
        self.registry.register(
            "precomputes_pending",
            "Precomputations queued or running",
            self.precomputes_pending.clone(),
        );
        self.registry.register_with_unit(
            "precompute_peak",
            "Heap bytes each candidate precomputation peaked at (counted by the server's \
             allocator on the precompute threads)",
            prometheus_client::registry::Unit::Bytes,
            self.precompute_peak_bytes.clone(),
        );
        self.registry.register_with_unit(
            "precompute_reserved",
            "Estimated peak bytes of the precomputations running (bounded by \
             --max-precompute-bytes)",
            prometheus_client::registry::Unit::Bytes,
            self.precompute_reserved_bytes.clone(),
        );
    }

    /// Registers the client connections' metrics.
    fn register_connections(&mut self) {
        self.registry.register(
            "connections_open",
            "Open client connections",
            self.connections_open.clone(),
        );
        self.registry.register(
            "connections_evicted",
            "Idle connections closed to make room under the connection cap",
            self.connections_evicted.clone(),
        );
        self.registry.register(
            "connections_refused",
            "Connections answered 503 because every open one had a request in flight",
            self.connections_refused.clone(),
        );
    }

    /// Registers the textures' metrics and the resident-memory bound.
    fn register_textures(&mut self) {
        self.registry.register(
            "textures_loaded",
            "Ready textures loaded from the data directory without recomputation",
            self.textures_loaded.clone(),
        );
        self.registry.register(
            "textures_refused",
            "Stored textures not served because their content does not match their id",
            self.textures_refused.clone(),
        );
        self.registry
            .register("textures", "Textures by status", self.textures.clone());
        self.registry.register(
            "background_jobs",
            "Background jobs (exports, and bakes asked for with Prefer: respond-async) held, \
             by kind and state; they run outside the interactive job queue",
            self.background_jobs.clone(),
        );
        self.registry.register_with_unit(
            "background_held",
            "Bytes of the finished background jobs' files held (--max-export-bytes bounds them)",
            prometheus_client::registry::Unit::Bytes,
            self.background_bytes.clone(),
        );
        self.registry.register_with_unit(
            "memory_bound",
            "The server's bound on its resident memory, by part (the bound is their sum): \
             from its limits and what it holds now",
            prometheus_client::registry::Unit::Bytes,
            self.memory_bound.clone(),
        );
    }

    /// Counts one finished request. Every label comes from a small set
    /// the server fixes: `route` is a route template (or `unmatched`), and
    /// a method the server does not know is counted as `other`, so that no
    /// client can add labels (each one is kept for the life of the process).
    pub fn observe_request(&self, route: &str, method: &str, status: u16, seconds: f64) {
        self.requests
            .get_or_create(&RequestLabels {
                route: route.to_string(),
                method: method_label(method).to_string(),
                status: status.to_string(),
            })
            .inc();
        self.latency
            .get_or_create(&RouteLabels {
                route: route.to_string(),
            })
            .observe(seconds);
    }

    /// Adds what a synthesis request cost.
    pub fn observe_synthesis(&self, stats: &SynthStats) {
        for (k, &n) in stats.voxels_per_level.iter().enumerate() {
            if n > 0 {
                self.voxels
                    .get_or_create(&LevelLabels {
                        level: k.to_string(),
                    })
                    .inc_by(n);
            }
        }
        for (k, &n) in stats.corrections_per_level.iter().enumerate() {
            if n > 0 {
                self.corrections
                    .get_or_create(&LevelLabels {
                        level: k.to_string(),
                    })
                    .inc_by(n);
            }
        }
        self.tiles_computed.inc_by(stats.tiles_computed);
        self.tiles_from_cache.inc_by(stats.tiles_from_cache);
    }

    /// Counts a request answered `over_budget` at `stage`.
    pub fn over_budget(&self, stage: &str) {
        self.over_budget
            .get_or_create(&StageLabels {
                stage: stage.to_string(),
            })
            .inc();
    }

    /// Sets the texture gauge.
    pub fn set_textures(&self, pending: i64, ready: i64, failed: i64) {
        for (s, n) in [("pending", pending), ("ready", ready), ("failed", failed)] {
            self.textures
                .get_or_create(&StatusLabels { status: s.into() })
                .set(n);
        }
    }

    /// The Prometheus/OpenMetrics text exposition.
    pub fn encode(&self) -> String {
        let mut out = String::new();
        if let Err(e) = prometheus_client::encoding::text::encode(&mut out, &self.registry) {
            tracing::error!(error = %e, "encoding metrics failed");
        }
        out
    }
}

/// Methods counted under their own name; any other is `other`.
const KNOWN_METHODS: [&str; 9] = [
    "GET", "HEAD", "POST", "PUT", "DELETE", "OPTIONS", "PATCH", "CONNECT", "TRACE",
];

/// The label of a request's method: its name when it is a standard one,
/// else `other`.
pub fn method_label(method: &str) -> &'static str {
    KNOWN_METHODS
        .into_iter()
        .find(|m| *m == method)
        .unwrap_or("other")
}

/// Reads the tile cache's counters at scrape time.
struct CacheCollector {
    cache: Arc<TileCache>,
}

impl std::fmt::Debug for CacheCollector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("CacheCollector")
    }
}

impl Collector for CacheCollector {
    fn encode(&self, mut encoder: DescriptorEncoder) -> Result<(), std::fmt::Error> {
        let s = self.cache.stats();
        for (name, help, v) in [
            ("cache_hits", "Tile lookups served from the cache", s.hits),
            (
                "cache_misses",
                "Tile lookups that computed the tile",
                s.misses,
            ),
            (
                "cache_coalesced",
                "Tile lookups that waited for a concurrent computation",
                s.coalesced,
            ),
            (
                "cache_evictions",
                "Tiles evicted to respect the byte bound",
                s.evictions,
            ),
        ] {
            let c = ConstCounter::new(v);
            let m = encoder.encode_descriptor(name, help, None, c.metric_type())?;
            c.encode(m)?;
        }
        for (name, help, v) in [
            (
                "cache_bytes",
                "Bytes of tiles held in the cache",
                s.bytes as i64,
            ),
            ("cache_entries", "Tiles held in the cache", s.entries as i64),
            (
                "cache_max_bytes",
                "Byte bound of the cache",
                self.cache.max_bytes() as i64,
            ),
        ] {
            let g = ConstGauge::new(v);
            let m = encoder.encode_descriptor(name, help, None, g.metric_type())?;
            g.encode(m)?;
        }
        Ok(())
    }
}

/// Reads the process's resident memory and threads at scrape time.
#[derive(Debug)]
struct ProcessCollector;

impl Collector for ProcessCollector {
    fn encode(&self, mut encoder: DescriptorEncoder) -> Result<(), std::fmt::Error> {
        if let Some(bytes) = crate::peak_alloc::in_use() {
            let g = ConstGauge::new(bytes as i64);
            let m = encoder.encode_descriptor(
                "heap_bytes",
                "Heap bytes in use, as the server's allocator counts them (resident memory \
                 adds the allocator's free pages and the binary)",
                None,
                g.metric_type(),
            )?;
            g.encode(m)?;
        }
        let Some(s) = super::process::current() else {
            return Ok(());
        };
        for (name, help, v) in [
            (
                "process_resident_bytes",
                "Resident memory of the server process",
                s.resident_bytes,
            ),
            (
                "process_peak_resident_bytes",
                "Peak resident memory of the server process since it started",
                s.peak_resident_bytes,
            ),
            (
                "process_threads",
                "Threads of the server process (HTTP, blocking jobs, rayon pools)",
                s.threads,
            ),
        ] {
            let g = ConstGauge::new(v as i64);
            let m = encoder.encode_descriptor(name, help, None, g.metric_type())?;
            g.encode(m)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clients_cannot_add_method_labels() {
        let m = Metrics::new(Arc::new(TileCache::new(1 << 20)));
        m.observe_request("/healthz", "GET", 200, 0.001);
        for i in 0..100 {
            m.observe_request(
                "unmatched",
                &format!("X{i}{}", "M".repeat(1000)),
                405,
                0.001,
            );
        }
        m.observe_request("unmatched", "get", 405, 0.001);
        let text = m.encode();
        assert!(text.contains(r#"route="/healthz",method="GET",status="200"} 1"#));
        assert!(
            text.contains(r#"route="unmatched",method="other",status="405"} 101"#),
            "{text}"
        );
        assert!(text.len() < 16 << 10, "{} bytes", text.len());
    }
}
