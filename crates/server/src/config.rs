//! Configuration of `solidtex serve`: every option is a flag and a
//! `SOLIDTEX_*` environment variable, with defaults that run a useful
//! server on a laptop.

use clap::{Args, ValueEnum};
use std::net::SocketAddr;
use std::path::PathBuf;

/// Options of the HTTP service.
#[derive(Args, Clone, Debug)]
pub struct ServeArgs {
    /// Address to listen on (`0.0.0.0:8080` to accept remote clients).
    #[arg(long, env = "SOLIDTEX_ADDR", default_value = "127.0.0.1:8080")]
    pub addr: SocketAddr,

    /// Where exemplars and precomputed `.stx` candidate files are kept
    /// [default: the user's data directory + `/solidtex`, else `./data`].
    #[arg(long, env = "SOLIDTEX_DATA_DIR")]
    pub data_dir: Option<PathBuf>,

    /// Keep textures in an S3-compatible bucket shared by replicas instead
    /// of the data directory: `s3://BUCKET` or `s3://BUCKET/PREFIX`.
    /// Credentials come from `AWS_ACCESS_KEY_ID`, `AWS_SECRET_ACCESS_KEY`
    /// (and `AWS_SESSION_TOKEN`), or the instance's role.
    #[arg(long, env = "SOLIDTEX_STORE")]
    pub store: Option<String>,

    /// Endpoint of an S3-compatible store other than AWS
    /// (`http://127.0.0.1:9000`; `http://` allows plain HTTP).
    #[arg(long, env = "SOLIDTEX_S3_ENDPOINT")]
    pub s3_endpoint: Option<String>,

    /// Region of the bucket.
    #[arg(long, env = "SOLIDTEX_S3_REGION", default_value = "us-east-1")]
    pub s3_region: String,

    /// Seconds between two listings of a shared store, after which
    /// textures deleted through another replica are gone here too.
    #[arg(long, env = "SOLIDTEX_STORE_POLL", default_value_t = 2.0, value_parser = parse_poll)]
    pub store_poll: f64,

    /// Bytes of synthesized tiles kept in the shared LRU cache (suffixes
    /// K, M, G accepted).
    #[arg(long, env = "SOLIDTEX_CACHE_BYTES", default_value = "512M", value_parser = parse_bytes)]
    pub cache_bytes: u64,

    /// Synthesis jobs (slices, cuts, regions, bricks) running at once;
    /// half the cores unless given. Each job already uses every core
    /// through rayon, so more jobs only add memory and latency.
    #[arg(long, env = "SOLIDTEX_MAX_JOBS", default_value_t = default_max_jobs(), value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub max_jobs: u32,

    /// Synthesis jobs allowed to wait for a running slot; beyond that a
    /// request is answered 503 with `Retry-After`.
    #[arg(long, env = "SOLIDTEX_QUEUE", default_value_t = 16, value_parser = clap::value_parser!(u32).range(0..=100_000))]
    pub queue: u32,

    /// Longest a synthesis job may wait for a running slot, in seconds; a
    /// job predicted to wait longer is refused on arrival. Both get 503
    /// with `Retry-After`, which bounds latency under overload.
    #[arg(long, env = "SOLIDTEX_MAX_QUEUE_WAIT", default_value_t = 10.0, value_parser = parse_wait)]
    pub max_queue_wait: f64,

    /// Precomputations running at once.
    #[arg(long, env = "SOLIDTEX_MAX_PRECOMPUTES", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub max_precomputes: u32,

    /// Precomputations allowed to wait; a new upload beyond that gets 503.
    #[arg(long, env = "SOLIDTEX_PRECOMPUTE_QUEUE", default_value_t = 16)]
    pub precompute_queue: u32,

    /// Threads of the synthesis pool (0: one per core).
    #[arg(long, env = "SOLIDTEX_WORKER_THREADS", default_value_t = 0)]
    pub worker_threads: usize,

    /// Threads of the precompute pool, kept apart from the synthesis pool
    /// so that an upload never starves voxel requests (0: half the cores).
    #[arg(long, env = "SOLIDTEX_PRECOMPUTE_THREADS", default_value_t = 0)]
    pub precompute_threads: usize,

    /// Threads answering HTTP (the synthesis runs elsewhere).
    #[arg(long, env = "SOLIDTEX_HTTP_THREADS", default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=256))]
    pub http_threads: u32,

    /// Largest accepted upload in bytes (suffixes K, M, G accepted).
    #[arg(long, env = "SOLIDTEX_MAX_UPLOAD_BYTES", default_value = "8M", value_parser = parse_bytes)]
    pub max_upload_bytes: u64,

    /// Edge of the aligned bricks served under `/bricks/` (voxels).
    #[arg(long, env = "SOLIDTEX_BRICK_SIZE", default_value_t = 64, value_parser = clap::value_parser!(u32).range(1..=256))]
    pub brick_size: u32,

    /// Edge of the chunks of the Neuroglancer precomputed and Zarr views
    /// (voxels; a power of two from 8 to 256). Smaller chunks arrive
    /// sooner; larger ones amortise the synthesis of their borders.
    #[arg(long, env = "SOLIDTEX_CHUNK_SIZE", default_value_t = 32, value_parser = parse_chunk_size)]
    pub chunk_size: u32,

    /// Work budget of one voxel request, in voxels: w·h for slices,
    /// w·h·d for regions and bricks, w·h·clamp(|u|,1,8)·clamp(|v|,1,8) for
    /// cuts. Requests over it get 400 `too_large`. The default allows the
    /// documented caps (4096² slices, 16 Mi-voxel regions); lower it on
    /// shared servers.
    #[arg(long, env = "SOLIDTEX_MAX_REQUEST_VOXELS", default_value_t = 16 << 20, value_parser = clap::value_parser!(u64).range(1..))]
    pub max_request_voxels: u64,

    /// Most voxels one request may synthesize, all pyramid levels together.
    /// Before any work a request's synthesis from a cold cache is bounded
    /// from above in microseconds; over this it is refused with 400
    /// `over_budget`, and a running one that goes over anyway is stopped.
    /// The default keeps any request on a 128² exemplar to about ten
    /// seconds on two cores and admits 256² slices and cuts at lod 0 and 1,
    /// 128² at every lod, and regions up to 128³.
    #[arg(long, env = "SOLIDTEX_MAX_REQUEST_WORK", default_value_t = 4 << 20, value_parser = clap::value_parser!(u64).range(1..))]
    pub max_request_work: u64,

    /// Most voxels in one export (`/v1/textures/{id}/export`); larger ones
    /// get 400 `too_large`. At most 256³.
    #[arg(long, env = "SOLIDTEX_MAX_EXPORT_VOXELS", default_value_t = 1 << 24, value_parser = clap::value_parser!(u64).range(1..=1 << 24))]
    pub max_export_voxels: u64,

    /// Most voxels one export may synthesize, all pyramid levels together
    /// (as `--max-request-work` for other requests): predicted over it,
    /// 400 `over_budget`. The default admits a 256³ export at lod 0 of a
    /// 128² exemplar, a few minutes on two cores.
    #[arg(long, env = "SOLIDTEX_MAX_EXPORT_WORK", default_value_t = 96 << 20, value_parser = clap::value_parser!(u64).range(1..))]
    pub max_export_work: u64,

    /// Exports and background bakes waiting behind the one that runs;
    /// more get 503.
    #[arg(long, env = "SOLIDTEX_EXPORT_QUEUE", default_value_t = 8)]
    pub export_queue: u32,

    /// Bytes of finished export and bake files kept in memory for their
    /// clients to fetch (suffixes K, M, G accepted), the least recently
    /// read dropped first; a dropped one is made again when asked for.
    #[arg(long, env = "SOLIDTEX_MAX_EXPORT_BYTES", default_value = "1G", value_parser = parse_bytes)]
    pub max_export_bytes: u64,

    /// Seconds a finished export or background bake is kept after it was
    /// last asked for.
    #[arg(long, env = "SOLIDTEX_EXPORT_TTL", default_value_t = 3600, value_parser = clap::value_parser!(u64).range(1..))]
    pub export_ttl: u64,

    /// Compress the chunks of the volume views: Zarr v3 arrays declare the
    /// zstd codec, and Neuroglancer precomputed chunks are sent gzipped to
    /// clients that accept gzip (`Accept-Encoding`). `off` serves both
    /// raw, as before.
    #[arg(long, env = "SOLIDTEX_CHUNK_COMPRESSION", default_value_t = true, action = clap::ArgAction::Set)]
    pub chunk_compression: bool,

    /// Uploaded textures kept at most; more uploads get 507 `storage_full`
    /// until some are deleted (the bundled texture is not counted).
    #[arg(long, env = "SOLIDTEX_MAX_TEXTURES", default_value_t = 256, value_parser = clap::value_parser!(u32).range(1..))]
    pub max_textures: u32,

    /// Bytes the textures may take on disk (exemplars and candidates; a
    /// 128² exemplar takes about 6 MB, a 512² one about 100 MB). An upload
    /// that would go over gets 507 `storage_full` (suffixes K, M, G
    /// accepted).
    #[arg(long, env = "SOLIDTEX_MAX_STORED_BYTES", default_value = "4G", value_parser = parse_positive_bytes)]
    pub max_stored_bytes: u64,

    /// Bytes of precomputed candidates kept in memory (a 128² texture
    /// takes about 60 MB). Beyond it the least recently used textures are
    /// evicted, and loaded again from disk (in about a second) when next
    /// asked for (suffixes K, M, G accepted).
    #[arg(long, env = "SOLIDTEX_MAX_RESIDENT_BYTES", default_value = "2G", value_parser = parse_positive_bytes)]
    pub max_resident_bytes: u64,

    /// Memory the precomputes running at once may take, by their
    /// estimated peaks (from the exemplar's size and the analysis
    /// parameters: a 128² exemplar with the defaults about 0.15 GB, a 512²
    /// one about 2.5 GB, three 512² exemplars about 6 GB; resident memory
    /// runs 1.2–1.4 times higher). An upload whose own estimate is over it
    /// is refused with 413 `precompute_too_large`; others wait in the
    /// precompute queue until the running ones leave room.
    #[arg(long, env = "SOLIDTEX_MAX_PRECOMPUTE_BYTES", default_value = "6G", value_parser = parse_bytes)]
    pub max_precompute_bytes: u64,

    /// Memory the decodes of uploaded images may take at once, by the
    /// estimates their headers give (a PNG is read row by row and takes a
    /// few MB whatever its size; a JPEG about 3 bytes per pixel, a 24
    /// megapixel photo about 80 MB, progressive ones up to twice that). An
    /// upload waits for room, up to `--max-queue-wait`, then gets 503; one
    /// whose own estimate is over it gets 413 `image_too_large` (suffixes
    /// K, M, G accepted).
    #[arg(long, env = "SOLIDTEX_MAX_DECODE_BYTES", default_value = "512M", value_parser = parse_positive_bytes)]
    pub max_decode_bytes: u64,

    /// Register the bundled exemplar under the id `default` at start.
    #[arg(long, env = "SOLIDTEX_DEFAULT_TEXTURE", default_value_t = true, action = clap::ArgAction::Set)]
    pub default_texture: bool,

    /// Seconds a voxel request waits for a texture that is still being
    /// precomputed before it is answered 409 with Retry-After, and a
    /// request waits for a start to load the stored textures before 503.
    #[arg(long, env = "SOLIDTEX_PENDING_WAIT", default_value_t = 15.0, value_parser = parse_pending_wait)]
    pub pending_wait: f64,

    /// Bearer token that uploads, deletions and `/metrics` require
    /// (`Authorization: Bearer TOKEN`); without one they are open, as
    /// reading voxels always is.
    #[arg(long, env = "SOLIDTEX_TOKEN", hide_env_values = true)]
    pub token: Option<String>,

    /// Origins (e.g. `https://app.example`) whose pages may upload and
    /// delete across origins; without any, browsers on other origins may
    /// only read (GET and HEAD).
    #[arg(long, env = "SOLIDTEX_CORS_ORIGINS", value_delimiter = ',')]
    pub cors_origins: Vec<String>,

    /// Seconds a client has to send a complete request head, counted from
    /// its first byte (from when the connection opens, for its first
    /// request); a slower client is disconnected without an answer.
    #[arg(long, env = "SOLIDTEX_HEADER_TIMEOUT", default_value_t = 10.0, value_parser = parse_wait)]
    pub header_timeout: f64,

    /// Seconds a keep-alive connection may rest between requests (from the
    /// end of its last answer) before it is closed.
    #[arg(long, env = "SOLIDTEX_IDLE_TIMEOUT", default_value_t = 60.0, value_parser = parse_wait)]
    pub idle_timeout: f64,

    /// Seconds a client has to send a whole request body (an upload)
    /// once its head has arrived; a slower one is answered 408.
    #[arg(long, env = "SOLIDTEX_BODY_TIMEOUT", default_value_t = 60.0, value_parser = parse_wait)]
    pub body_timeout: f64,

    /// Open client connections at most. A new connection over it closes
    /// the oldest idle one (no request in flight); when every connection
    /// is busy it is answered 503 with `Retry-After` and closed.
    #[arg(long, env = "SOLIDTEX_MAX_CONNECTIONS", default_value_t = 1024, value_parser = clap::value_parser!(u32).range(1..=1_000_000))]
    pub max_connections: u32,

    /// Host names (or `host:port`) that requests may name in their `Host`
    /// header, comma-separated; others get 421 `host_not_allowed`, which
    /// defeats DNS rebinding. `*` allows any. Default: `localhost`,
    /// `127.0.0.1` and `[::1]` when listening on a loopback address, any
    /// host otherwise.
    #[arg(long, env = "SOLIDTEX_ALLOWED_HOSTS", value_delimiter = ',')]
    pub allowed_hosts: Vec<String>,

    /// Seconds to wait for in-flight requests after SIGINT/SIGTERM.
    #[arg(long, env = "SOLIDTEX_SHUTDOWN_TIMEOUT", default_value_t = 30)]
    pub shutdown_timeout: u64,

    /// Log format.
    #[arg(long, env = "SOLIDTEX_LOG_FORMAT", value_enum, default_value_t = LogFormat::Pretty)]
    pub log_format: LogFormat,

    /// Log filter (tracing `EnvFilter` syntax, e.g. `info,solidtex=debug`).
    #[arg(long, env = "SOLIDTEX_LOG", default_value = "info")]
    pub log: String,
}

/// How log lines are written.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum LogFormat {
    /// Human-readable lines.
    Pretty,
    /// One JSON object per line.
    Json,
}

impl ServeArgs {
    /// Defaults for embedding the server (tests, benchmarks): loopback on a
    /// free port, data under `data_dir`, no default texture.
    pub fn for_data_dir(data_dir: impl Into<PathBuf>) -> ServeArgs {
        ServeArgs {
            addr: SocketAddr::from(([127, 0, 0, 1], 0)),
            data_dir: Some(data_dir.into()),
            store: None,
            s3_endpoint: None,
            s3_region: "us-east-1".into(),
            store_poll: 2.0,
            cache_bytes: 256 << 20,
            max_jobs: 4,
            queue: 64,
            max_queue_wait: 600.0,
            max_precomputes: 1,
            precompute_queue: 16,
            worker_threads: 0,
            precompute_threads: 0,
            http_threads: 2,
            max_upload_bytes: 8 << 20,
            brick_size: 64,
            chunk_size: 32,
            max_request_voxels: 16 << 20,
            max_request_work: 4 << 20,
            max_export_voxels: 1 << 24,
            max_export_work: 96 << 20,
            export_queue: 8,
            chunk_compression: true,
            max_export_bytes: 1 << 30,
            export_ttl: 3600,
            max_textures: 256,
            max_stored_bytes: 4 << 30,
            max_resident_bytes: 2 << 30,
            max_precompute_bytes: 6 << 30,
            max_decode_bytes: 512 << 20,
            default_texture: false,
            token: None,
            cors_origins: Vec::new(),
            pending_wait: 0.0,
            header_timeout: 10.0,
            idle_timeout: 60.0,
            body_timeout: 60.0,
            max_connections: 1024,
            allowed_hosts: Vec::new(),
            shutdown_timeout: 30,
            log_format: LogFormat::Pretty,
            log: "info".into(),
        }
    }

    /// Threads of the precompute pool in effect.
    pub fn resolved_precompute_threads(&self) -> usize {
        if self.precompute_threads > 0 {
            return self.precompute_threads;
        }
        let cores = std::thread::available_parallelism().map_or(2, |n| n.get());
        (cores / 2).max(1)
    }

    /// The data directory in effect.
    pub fn resolved_data_dir(&self) -> PathBuf {
        match &self.data_dir {
            Some(d) => d.clone(),
            None => dirs::data_dir()
                .map(|d| d.join("solidtex"))
                .unwrap_or_else(|| PathBuf::from("data")),
        }
    }
}

/// Parses the shared store's listing period: 0.1 to 3600 seconds.
pub fn parse_poll(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .parse()
        .map_err(|_| format!("`{s}` is not a number of seconds"))?;
    if (0.1..=3600.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{v} is outside 0.1..=3600 seconds"))
    }
}

/// Parses a chunk edge: a power of two from 8 to 256, so that chunks tile
/// the served window (2^20 voxels per side) exactly at every level.
pub fn parse_chunk_size(s: &str) -> Result<u32, String> {
    let n: u32 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not an integer"))?;
    if !(8..=256).contains(&n) || !n.is_power_of_two() {
        return Err(format!("{n} is not a power of two from 8 to 256"));
    }
    Ok(n)
}

/// Parses a queue wait limit in seconds, from 1 ms to a day.
pub fn parse_wait(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if (0.001..=86_400.0).contains(&v) => Ok(v),
        _ => Err(format!(
            "`{s}` is not a number of seconds from 0.001 to 86400"
        )),
    }
}

/// Parses `--pending-wait`: seconds from 0 (answer 409 at once) to 600.
pub fn parse_pending_wait(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if (0.0..=600.0).contains(&v) => Ok(v),
        _ => Err(format!("`{s}` is not a number of seconds from 0 to 600")),
    }
}

/// Default `--max-jobs`: half the cores, at least one. A job already uses
/// every core through rayon; more slots than that add queueing inside the
/// pool, not throughput, and lengthen the tail (docs/server.md).
fn default_max_jobs() -> u32 {
    let cores = std::thread::available_parallelism().map_or(2, |n| n.get());
    (cores / 2).max(1) as u32
}

/// Parses a byte count with an optional binary suffix: `1048576`, `512K`,
/// `64M`, `2G` (also `KiB`, `MB`…, case-insensitive).
pub fn parse_bytes(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let split = t.find(|c: char| !c.is_ascii_digit()).unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let n: u64 = num
        .parse()
        .map_err(|_| format!("`{s}` is not a byte count (e.g. 512M)"))?;
    let shift = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 0,
        "k" | "kb" | "kib" => 10,
        "m" | "mb" | "mib" => 20,
        "g" | "gb" | "gib" => 30,
        "t" | "tb" | "tib" => 40,
        other => return Err(format!("unknown byte unit `{other}` (use K, M, G)")),
    };
    n.checked_mul(1u64 << shift)
        .ok_or_else(|| format!("`{s}` is too large"))
}

/// Parses a byte count as [`parse_bytes`] does, refusing zero.
pub fn parse_positive_bytes(s: &str) -> Result<u64, String> {
    match parse_bytes(s)? {
        0 => Err(format!("`{s}` must be at least one byte")),
        n => Ok(n),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        serve: ServeArgs,
    }

    #[test]
    fn byte_counts() {
        assert_eq!(parse_bytes("1024"), Ok(1024));
        assert_eq!(parse_bytes("512M"), Ok(512 << 20));
        assert_eq!(parse_bytes("2gib"), Ok(2 << 30));
        assert_eq!(parse_bytes(" 3K "), Ok(3 << 10));
        assert!(parse_bytes("lots").is_err());
        assert!(parse_bytes("3Q").is_err());
        assert!(parse_bytes("99999999999T").is_err());
        assert_eq!(parse_positive_bytes("60M"), Ok(60 << 20));
        assert!(parse_positive_bytes("0").is_err());
    }

    #[test]
    fn every_byte_flag_takes_a_suffix() {
        let c = Cli::try_parse_from(["x"]).unwrap().serve;
        assert_eq!(
            (c.max_stored_bytes, c.max_resident_bytes),
            (4 << 30, 2 << 30)
        );
        let flags = [
            "--cache-bytes",
            "--max-upload-bytes",
            "--max-stored-bytes",
            "--max-resident-bytes",
            "--max-precompute-bytes",
            "--max-decode-bytes",
        ];
        for flag in flags {
            let c = Cli::try_parse_from(["x", flag, "60M"])
                .unwrap_or_else(|e| panic!("{flag} 60M: {e}"))
                .serve;
            let got = match flag {
                "--cache-bytes" => c.cache_bytes,
                "--max-upload-bytes" => c.max_upload_bytes,
                "--max-stored-bytes" => c.max_stored_bytes,
                "--max-resident-bytes" => c.max_resident_bytes,
                "--max-decode-bytes" => c.max_decode_bytes,
                _ => c.max_precompute_bytes,
            };
            assert_eq!(got, 60 << 20, "{flag}");
        }
        for flag in ["--max-stored-bytes", "--max-resident-bytes"] {
            assert!(Cli::try_parse_from(["x", flag, "0"]).is_err(), "{flag}");
        }
    }

    #[test]
    fn wait_limits() {
        assert_eq!(parse_wait("1.5"), Ok(1.5));
        assert_eq!(parse_wait(" 10 "), Ok(10.0));
        assert!(parse_wait("0").is_err());
        assert!(parse_wait("-1").is_err());
        assert!(parse_wait("NaN").is_err());
        assert!(parse_wait("inf").is_err());
        assert!(parse_wait("soon").is_err());
        let c = Cli::try_parse_from(["x"]).unwrap().serve;
        assert_eq!(c.max_queue_wait, 10.0);
        assert!(Cli::try_parse_from(["x", "--max-queue-wait", "100000"]).is_err());
    }

    #[test]
    fn pending_wait_limits() {
        assert_eq!(parse_pending_wait("0"), Ok(0.0));
        assert_eq!(parse_pending_wait("600"), Ok(600.0));
        assert!(parse_pending_wait("600.5").is_err());
        assert!(parse_pending_wait("-0.1").is_err());
        assert!(parse_pending_wait("NaN").is_err());
        assert!(parse_pending_wait("later").is_err());
        let c = Cli::try_parse_from(["x"]).unwrap().serve;
        assert_eq!(c.pending_wait, 15.0);
        assert_eq!(c.token, None);
        assert!(c.cors_origins.is_empty());
        let c = Cli::try_parse_from([
            "x",
            "--token",
            "t",
            "--cors-origins",
            "https://a.example,https://b.example",
        ])
        .unwrap()
        .serve;
        assert_eq!(c.token.as_deref(), Some("t"));
        assert_eq!(c.cors_origins, ["https://a.example", "https://b.example"]);
    }

    #[test]
    fn chunk_sizes() {
        assert_eq!(parse_chunk_size("32"), Ok(32));
        assert_eq!(parse_chunk_size("256"), Ok(256));
        assert!(parse_chunk_size("48").is_err());
        assert!(parse_chunk_size("4").is_err());
        assert!(parse_chunk_size("512").is_err());
        assert!(parse_chunk_size("x").is_err());
    }

    #[test]
    fn flags_parse_and_default() {
        let c = Cli::try_parse_from(["x"]).unwrap().serve;
        assert_eq!(c.addr.port(), 8080);
        assert_eq!(c.cache_bytes, 512 << 20);
        assert!(c.default_texture);
        let c = Cli::try_parse_from([
            "x",
            "--addr",
            "0.0.0.0:9000",
            "--cache-bytes",
            "1G",
            "--default-texture",
            "false",
            "--log-format",
            "json",
        ])
        .unwrap()
        .serve;
        assert_eq!(c.addr.port(), 9000);
        assert_eq!(c.cache_bytes, 1 << 30);
        assert!(!c.default_texture);
        assert_eq!(c.log_format, LogFormat::Json);
        assert!(Cli::try_parse_from(["x", "--max-jobs", "0"]).is_err());
        let c = Cli::try_parse_from(["x"]).unwrap().serve;
        assert_eq!(
            (c.header_timeout, c.idle_timeout, c.body_timeout),
            (10.0, 60.0, 60.0)
        );
        assert_eq!(c.max_connections, 1024);
        assert!(Cli::try_parse_from(["x", "--idle-timeout", "0"]).is_err());
        assert!(Cli::try_parse_from(["x", "--max-connections", "0"]).is_err());
        assert!(Cli::try_parse_from(["x", "--header-timeout", "0"]).is_err());
        assert!(c.allowed_hosts.is_empty());
        let c = Cli::try_parse_from(["x", "--allowed-hosts", "a.example,b.example:8443"])
            .unwrap()
            .serve;
        assert_eq!(c.allowed_hosts, ["a.example", "b.example:8443"]);
    }
}
