//! Reading the server's `/metrics` (Prometheus text) into totals per
//! metric name, and the differences a load test reports: voxels
//! synthesized, tiles computed versus served from the cache, requests shed,
//! and the server's resident memory against the bound it reports for
//! itself.

use serde::Serialize;
use std::collections::HashMap;

/// One scrape: every sample summed over its labels, keyed by metric name.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scrape(HashMap<String, f64>);

impl Scrape {
    /// Parses the text exposition format; comments and malformed lines are
    /// skipped.
    pub fn parse(text: &str) -> Scrape {
        let mut totals = HashMap::new();
        for line in text.lines() {
            if line.starts_with('#') || line.trim().is_empty() {
                continue;
            }
            // `name{labels} value` or `name value`; label values may hold
            // spaces, so split at the closing brace first.
            let (name, rest) = match line.find('{') {
                Some(open) => match line.rfind('}') {
                    Some(close) if close > open => (&line[..open], &line[close + 1..]),
                    _ => continue,
                },
                None => match line.split_once(' ') {
                    Some((n, r)) => (n, r),
                    None => continue,
                },
            };
            let Some(value) = rest
                .split_whitespace()
                .next()
                .and_then(|v| v.parse::<f64>().ok())
            else {
                continue;
            };
            *totals.entry(name.to_string()).or_insert(0.0) += value;
        }
        Scrape(totals)
    }

    /// The total of `name` (0 when absent).
    pub fn get(&self, name: &str) -> f64 {
        self.0.get(name).copied().unwrap_or(0.0)
    }

    /// Whether the scrape has `name` at all.
    pub fn has(&self, name: &str) -> bool {
        self.0.contains_key(name)
    }
}

/// Names of the server's metrics, as exposed.
mod name {
    pub const VOXELS: &str = "solidtex_synth_voxels_total";
    pub const CORRECTIONS: &str = "solidtex_synth_corrections_total";
    pub const TILES_COMPUTED: &str = "solidtex_synth_tiles_computed_total";
    pub const TILES_FROM_CACHE: &str = "solidtex_synth_tiles_from_cache_total";
    pub const CACHE_HITS: &str = "solidtex_cache_hits_total";
    pub const CACHE_MISSES: &str = "solidtex_cache_misses_total";
    pub const CACHE_COALESCED: &str = "solidtex_cache_coalesced_total";
    pub const CACHE_EVICTIONS: &str = "solidtex_cache_evictions_total";
    pub const CACHE_BYTES: &str = "solidtex_cache_bytes";
    pub const CACHE_MAX_BYTES: &str = "solidtex_cache_max_bytes";
    pub const REJECTED: &str = "solidtex_jobs_rejected_total";
    pub const RESIDENT: &str = "solidtex_process_resident_bytes";
    pub const MEMORY_BOUND: &str = "solidtex_memory_bound_bytes";
    pub const THREADS: &str = "solidtex_process_threads";
}

/// Memory headroom a server that reports no bound of its own may use
/// beyond its tile cache (candidates, request working sets, allocator
/// slack) before a run is flagged.
pub const RSS_HEADROOM_BYTES: f64 = 256.0 * 1024.0 * 1024.0;

/// The largest resident memory and thread count seen while sampling, and
/// how close resident memory came to the server's own bound.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Peaks {
    /// Largest `process_resident_bytes` seen.
    pub resident_bytes: f64,
    /// Largest `process_threads` seen.
    pub threads: f64,
    /// The least of the server's bound minus its resident memory, over the
    /// samples that had both (negative: over the bound); `None` when the
    /// server reports no bound.
    pub least_margin_bytes: Option<f64>,
    /// The bound at that sample.
    pub bound_at_least_margin: f64,
}

impl Peaks {
    /// Folds one scrape in.
    pub fn observe(&mut self, s: &Scrape) {
        let resident = s.get(name::RESIDENT);
        self.resident_bytes = self.resident_bytes.max(resident);
        self.threads = self.threads.max(s.get(name::THREADS));
        if s.has(name::MEMORY_BOUND) && s.has(name::RESIDENT) {
            let bound = s.get(name::MEMORY_BOUND);
            let margin = bound - resident;
            if self.least_margin_bytes.is_none_or(|m| margin < m) {
                self.least_margin_bytes = Some(margin);
                self.bound_at_least_margin = bound;
            }
        }
    }
}

/// What the server did during a run, from scrapes before and after it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ServerDelta {
    /// Voxels synthesized (all levels).
    pub voxels_synthesized: f64,
    /// Voxel corrections (all levels).
    pub corrections: f64,
    /// Final tiles computed by requests.
    pub tiles_computed: f64,
    /// Final tiles requests got from the cache or a concurrent request.
    pub tiles_from_cache: f64,
    /// `tiles_from_cache / (tiles_computed + tiles_from_cache)`.
    pub tile_hit_rate: f64,
    /// Cache lookups that found their tile.
    pub cache_hits: f64,
    /// Cache lookups that computed their tile.
    pub cache_misses: f64,
    /// Cache lookups that waited for a concurrent computation.
    pub cache_coalesced: f64,
    /// Tiles evicted.
    pub cache_evictions: f64,
    /// Requests the server shed with 503.
    pub jobs_rejected: f64,
    /// Tile bytes cached at the end.
    pub cache_bytes: f64,
    /// The cache's bound.
    pub cache_max_bytes: f64,
    /// Resident memory at the end (0 when the server does not report it).
    pub resident_bytes_end: f64,
    /// Peak resident memory and threads seen while the run was sampled.
    pub peaks: Peaks,
    /// Whether resident memory stayed within the server's own bound at
    /// every sample (for a server that reports none: whether the peak
    /// stayed within cache bound + 256 MiB); `None` when the server does
    /// not report its memory.
    pub resident_within_budget: Option<bool>,
}

impl ServerDelta {
    /// The difference between two scrapes, with the peaks sampled between.
    pub fn between(before: &Scrape, after: &Scrape, peaks: Peaks) -> ServerDelta {
        let d = |n: &str| after.get(n) - before.get(n);
        let computed = d(name::TILES_COMPUTED);
        let cached = d(name::TILES_FROM_CACHE);
        let max_bytes = after.get(name::CACHE_MAX_BYTES);
        let reports_memory = after.has(name::RESIDENT);
        ServerDelta {
            voxels_synthesized: d(name::VOXELS),
            corrections: d(name::CORRECTIONS),
            tiles_computed: computed,
            tiles_from_cache: cached,
            tile_hit_rate: if computed + cached > 0.0 {
                cached / (computed + cached)
            } else {
                0.0
            },
            cache_hits: d(name::CACHE_HITS),
            cache_misses: d(name::CACHE_MISSES),
            cache_coalesced: d(name::CACHE_COALESCED),
            cache_evictions: d(name::CACHE_EVICTIONS),
            jobs_rejected: d(name::REJECTED),
            cache_bytes: after.get(name::CACHE_BYTES),
            cache_max_bytes: max_bytes,
            resident_bytes_end: after.get(name::RESIDENT),
            peaks,
            resident_within_budget: match peaks.least_margin_bytes {
                Some(margin) => Some(margin >= 0.0),
                None => {
                    reports_memory.then_some(peaks.resident_bytes <= max_bytes + RSS_HEADROOM_BYTES)
                }
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEXT: &str = "# HELP solidtex_synth_voxels Voxels\n\
        # TYPE solidtex_synth_voxels counter\n\
        solidtex_synth_voxels_total{level=\"0\"} 100\n\
        solidtex_synth_voxels_total{level=\"1\"} 20\n\
        solidtex_http_requests_total{route=\"/a b\",method=\"GET\",status=\"200\"} 3\n\
        solidtex_cache_max_bytes 1000\n\
        solidtex_process_resident_bytes 500\n\
        # EOF\n";

    #[test]
    fn sums_over_labels() {
        let s = Scrape::parse(TEXT);
        assert_eq!(s.get("solidtex_synth_voxels_total"), 120.0);
        assert_eq!(s.get("solidtex_http_requests_total"), 3.0);
        assert_eq!(s.get("solidtex_cache_max_bytes"), 1000.0);
        assert_eq!(s.get("missing"), 0.0);
    }

    #[test]
    fn deltas_and_budget() {
        let before = Scrape::parse("solidtex_synth_tiles_computed_total 10\n");
        let after = Scrape::parse(
            "solidtex_synth_tiles_computed_total 40\n\
             solidtex_synth_tiles_from_cache_total 90\n\
             solidtex_cache_max_bytes 1000\n\
             solidtex_process_resident_bytes 2000\n",
        );
        let mut peaks = Peaks::default();
        peaks.observe(&after);
        let d = ServerDelta::between(&before, &after, peaks);
        assert_eq!(d.tiles_computed, 30.0);
        assert_eq!(d.tiles_from_cache, 90.0);
        assert!((d.tile_hit_rate - 0.75).abs() < 1e-12);
        assert_eq!(d.resident_within_budget, Some(true));
        let none = ServerDelta::between(&before, &before, Peaks::default());
        assert_eq!(none.resident_within_budget, None);
        assert_eq!(none.tile_hit_rate, 0.0);
    }

    #[test]
    fn resident_memory_is_checked_against_the_servers_own_bound() {
        let sample = |resident: u64, parts: [u64; 2]| {
            Scrape::parse(&format!(
                "solidtex_process_resident_bytes {resident}\n\
                 solidtex_memory_bound_bytes{{part=\"cache\"}} {}\n\
                 solidtex_memory_bound_bytes{{part=\"jobs\"}} {}\n",
                parts[0], parts[1]
            ))
        };
        let mut peaks = Peaks::default();
        peaks.observe(&sample(900, [500, 600]));
        peaks.observe(&sample(700, [300, 450]));
        // The tightest sample is the second (50 to spare), not the largest.
        assert_eq!(peaks.least_margin_bytes, Some(50.0));
        assert_eq!(peaks.bound_at_least_margin, 750.0);
        let d = ServerDelta::between(&Scrape::default(), &sample(700, [300, 450]), peaks);
        assert_eq!(d.resident_within_budget, Some(true));
        peaks.observe(&sample(800, [300, 450]));
        let d = ServerDelta::between(&Scrape::default(), &sample(700, [300, 450]), peaks);
        assert_eq!(d.resident_within_budget, Some(false));
    }
}
