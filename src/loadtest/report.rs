//! What a load test measured: latency histograms per request kind (HDR
//! histograms in microseconds, merged across clients), bytes and status
//! counts, and how they are shown — an aligned table for people, JSON for
//! machines.

use super::scrape::ServerDelta;
use super::workload::Kind;
use hdrhistogram::Histogram;
use serde::Serialize;
use std::fmt::Write;

/// Responses by status class.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct StatusCounts {
    /// 2xx.
    pub ok: u64,
    /// 304 Not Modified (revalidations).
    pub not_modified: u64,
    /// 503 Service Unavailable (shed by the server).
    pub unavailable: u64,
    /// Any other status.
    pub other: u64,
    /// No response: connection errors and timeouts.
    pub transport_errors: u64,
}

impl StatusCounts {
    /// Counts one HTTP status.
    pub fn count(&mut self, status: u16) {
        match status {
            200..=299 => self.ok += 1,
            304 => self.not_modified += 1,
            503 => self.unavailable += 1,
            _ => self.other += 1,
        }
    }

    /// Adds another client's counts.
    pub fn merge(&mut self, o: &StatusCounts) {
        self.ok += o.ok;
        self.not_modified += o.not_modified;
        self.unavailable += o.unavailable;
        self.other += o.other;
        self.transport_errors += o.transport_errors;
    }

    /// Every request sent.
    pub fn total(&self) -> u64 {
        self.ok + self.not_modified + self.unavailable + self.other + self.transport_errors
    }
}

/// Raw measurements of one request kind.
pub struct KindRecorder {
    /// Latency of answered (2xx and 304) requests, microseconds.
    pub latency: Histogram<u64>,
    /// Body bytes received.
    pub bytes: u64,
    /// Responses by status.
    pub statuses: StatusCounts,
}

impl Default for KindRecorder {
    fn default() -> Self {
        KindRecorder {
            // 1 µs to 1 hour at 3 significant digits.
            latency: Histogram::new_with_bounds(1, 3_600_000_000, 3).expect("valid bounds"),
            bytes: 0,
            statuses: StatusCounts::default(),
        }
    }
}

impl KindRecorder {
    /// Records an answered request.
    pub fn answered(&mut self, status: u16, micros: u64, bytes: u64) {
        self.statuses.count(status);
        if status == 304 || (200..300).contains(&status) {
            self.latency.saturating_record(micros.max(1));
        }
        self.bytes += bytes;
    }

    /// Adds another client's measurements.
    pub fn merge(&mut self, o: &KindRecorder) {
        self.latency.add(&o.latency).expect("same bounds");
        self.bytes += o.bytes;
        self.statuses.merge(&o.statuses);
    }

    fn summary(&self, kind: Kind, seconds: f64) -> KindSummary {
        let ms = |q: f64| self.latency.value_at_quantile(q) as f64 / 1000.0;
        let answered = self.latency.len();
        KindSummary {
            kind: kind.name(),
            requests: self.statuses.total(),
            requests_per_s: self.statuses.total() as f64 / seconds,
            megabytes_per_s: self.bytes as f64 / 1e6 / seconds,
            p50_ms: if answered > 0 { ms(0.5) } else { 0.0 },
            p95_ms: if answered > 0 { ms(0.95) } else { 0.0 },
            p99_ms: if answered > 0 { ms(0.99) } else { 0.0 },
            max_ms: self.latency.max() as f64 / 1000.0,
            statuses: self.statuses,
        }
    }
}

/// One client's or a whole run's measurements, per kind.
#[derive(Default)]
pub struct Recorder {
    kinds: [KindRecorder; 3],
}

impl Recorder {
    /// The measurements of `kind`.
    pub fn kind(&mut self, kind: Kind) -> &mut KindRecorder {
        &mut self.kinds[kind as usize]
    }

    /// Adds another client's measurements.
    pub fn merge(&mut self, o: &Recorder) {
        for (a, b) in self.kinds.iter_mut().zip(&o.kinds) {
            a.merge(b);
        }
    }

    /// Summaries of the kinds that saw requests, then the total.
    pub fn summarise(&self, seconds: f64) -> (Vec<KindSummary>, KindSummary) {
        let mut all = KindRecorder::default();
        let mut per = Vec::new();
        for kind in Kind::ALL {
            let r = &self.kinds[kind as usize];
            all.merge(r);
            if r.statuses.total() > 0 {
                per.push(r.summary(kind, seconds));
            }
        }
        let mut total = all.summary(Kind::Slice, seconds);
        total.kind = "all";
        (per, total)
    }
}

/// Throughput and latency of one kind of request (or `all`).
#[derive(Clone, Debug, Serialize)]
pub struct KindSummary {
    /// `slice`, `cut`, `brick` or `all`.
    pub kind: &'static str,
    /// Requests sent.
    pub requests: u64,
    /// Requests per second over the run.
    pub requests_per_s: f64,
    /// Body megabytes (10^6) per second.
    pub megabytes_per_s: f64,
    /// Median latency of answered requests, ms.
    pub p50_ms: f64,
    /// 95th percentile, ms.
    pub p95_ms: f64,
    /// 99th percentile, ms.
    pub p99_ms: f64,
    /// Slowest, ms.
    pub max_ms: f64,
    /// Responses by status.
    pub statuses: StatusCounts,
}

/// The outcome of a load test.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// What ran: the workload in words.
    pub workload: String,
    /// Concurrent clients.
    pub concurrency: usize,
    /// Seconds from the first request to the last answer (in-flight
    /// requests are waited for after the duration ends).
    pub elapsed_s: f64,
    /// Per kind.
    pub kinds: Vec<KindSummary>,
    /// All kinds together.
    pub total: KindSummary,
    /// Planes per second over all clients, for a sweep.
    pub cuts_per_s: Option<f64>,
    /// The server's metrics over the run, when it exposes them.
    pub server: Option<ServerDelta>,
    /// Uploads, deletions and hang-ups alongside the load (a soak).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub churn: Option<super::churn::ChurnReport>,
    /// Sampled answers against a fresh server's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub verify: Option<super::churn::VerifyReport>,
}

fn mib(bytes: f64) -> String {
    format!("{:.0} MiB", bytes / (1024.0 * 1024.0))
}

impl Report {
    /// The report as a plain-text table.
    pub fn table(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "{}; {} clients; {:.1} s",
            self.workload, self.concurrency, self.elapsed_s
        );
        let _ = writeln!(
            out,
            "{:<6} {:>8} {:>9} {:>8} {:>9} {:>9} {:>9} {:>9} {:>6} {:>5} {:>5} {:>5} {:>5}",
            "kind",
            "requests",
            "req/s",
            "MB/s",
            "p50 ms",
            "p95 ms",
            "p99 ms",
            "max ms",
            "2xx",
            "304",
            "503",
            "other",
            "error"
        );
        for k in self.kinds.iter().chain(std::iter::once(&self.total)) {
            let s = &k.statuses;
            let _ = writeln!(
                out,
                "{:<6} {:>8} {:>9.2} {:>8.2} {:>9.1} {:>9.1} {:>9.1} {:>9.1} {:>6} {:>5} {:>5} {:>5} {:>5}",
                k.kind,
                k.requests,
                k.requests_per_s,
                k.megabytes_per_s,
                k.p50_ms,
                k.p95_ms,
                k.p99_ms,
                k.max_ms,
                s.ok,
                s.not_modified,
                s.unavailable,
                s.other,
                s.transport_errors
            );
        }
        if let Some(c) = self.cuts_per_s {
            let _ = writeln!(out, "sweep: {c:.2} cuts/s");
        }
        match &self.server {
            None => {
                let _ = writeln!(out, "server metrics: unavailable");
            }
            Some(d) => {
                let _ = writeln!(
                    out,
                    "server: {:.0} voxels synthesized, {:.0} corrections; tiles {:.0} computed, \
                     {:.0} from cache (hit rate {:.1} %); cache lookups {:.0} hits, {:.0} misses, \
                     {:.0} coalesced, {:.0} evictions; {:.0} shed with 503",
                    d.voxels_synthesized,
                    d.corrections,
                    d.tiles_computed,
                    d.tiles_from_cache,
                    100.0 * d.tile_hit_rate,
                    d.cache_hits,
                    d.cache_misses,
                    d.cache_coalesced,
                    d.cache_evictions,
                    d.jobs_rejected
                );
                let verdict = match d.resident_within_budget {
                    Some(true) => "within",
                    Some(false) => "OVER",
                    None => "unknown against",
                };
                let bound = match d.peaks.least_margin_bytes {
                    Some(margin) => format!(
                        "the server's own bound at every sample (closest: {} of {})",
                        mib(d.peaks.bound_at_least_margin - margin),
                        mib(d.peaks.bound_at_least_margin)
                    ),
                    None => format!("cache bound {} + 256 MiB", mib(d.cache_max_bytes)),
                };
                let _ = writeln!(
                    out,
                    "server memory: resident peak {} (end {}), {verdict} {bound}; cache holds {}; \
                     threads peak {:.0}",
                    mib(d.peaks.resident_bytes),
                    mib(d.resident_bytes_end),
                    mib(d.cache_bytes),
                    d.peaks.threads
                );
            }
        }
        if let Some(c) = &self.churn {
            let statuses: Vec<String> = c
                .statuses
                .iter()
                .map(|(s, n)| format!("{s}: {n}"))
                .collect();
            let _ = writeln!(
                out,
                "churn: {} uploads ({} served a slice), {} deletions, {} hang-ups; answers {}; {} server errors",
                c.uploads,
                c.served,
                c.deletes,
                c.hangups,
                statuses.join(", "),
                c.server_errors()
            );
        }
        if let Some(v) = &self.verify {
            let _ = writeln!(
                out,
                "verified against a fresh server: {} answers, {} differ, {} not answered",
                v.checked, v.mismatched, v.failed
            );
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_and_statuses() {
        let mut a = Recorder::default();
        let mut b = Recorder::default();
        for ms in 1..=100u64 {
            a.kind(Kind::Slice).answered(200, ms * 1000, 10);
        }
        b.kind(Kind::Brick).answered(304, 500, 0);
        b.kind(Kind::Brick).answered(503, 50, 20);
        b.kind(Kind::Brick).statuses.transport_errors += 1;
        a.merge(&b);
        let (per, total) = a.summarise(2.0);
        assert_eq!(per.len(), 2);
        let slice = &per[0];
        assert_eq!(slice.kind, "slice");
        assert_eq!(slice.requests, 100);
        assert_eq!(slice.requests_per_s, 50.0);
        assert!((slice.p50_ms - 50.0).abs() < 0.1, "{}", slice.p50_ms);
        assert!((slice.p99_ms - 99.0).abs() < 0.1, "{}", slice.p99_ms);
        assert!((slice.max_ms - 100.0).abs() < 0.1);
        let brick = &per[1];
        assert_eq!(
            brick.statuses,
            StatusCounts {
                ok: 0,
                not_modified: 1,
                unavailable: 1,
                other: 0,
                transport_errors: 1
            }
        );
        // 503s are counted but not timed.
        assert!((brick.max_ms - 0.5).abs() < 0.01);
        assert_eq!(total.requests, 103);
        assert_eq!(total.megabytes_per_s, 1020.0 / 1e6 / 2.0);
        let report = Report {
            workload: "test".into(),
            concurrency: 2,
            elapsed_s: 2.0,
            kinds: per,
            total,
            cuts_per_s: Some(51.5),
            server: None,
            churn: Some(crate::loadtest::churn::ChurnReport {
                uploads: 3,
                served: 2,
                deletes: 2,
                hangups: 4,
                statuses: [(202, 3), (200, 2), (204, 2), (500, 1), (503, 1)].into(),
            }),
            verify: Some(crate::loadtest::churn::VerifyReport {
                checked: 9,
                mismatched: 1,
                failed: 0,
            }),
        };
        let table = report.table();
        assert!(
            table.contains("3 uploads (2 served a slice), 2 deletions, 4 hang-ups"),
            "{table}"
        );
        assert!(table.contains("; 1 server errors"), "{table}");
        assert!(
            table.contains("9 answers, 1 differ, 0 not answered"),
            "{table}"
        );
        assert!(table.lines().any(|l| l.starts_with("all ")), "{table}");
        assert!(table.contains("server metrics: unavailable"));
        assert!(table.contains("sweep: 51.50 cuts/s"));
    }
}
