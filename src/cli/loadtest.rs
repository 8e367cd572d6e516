//! `solidtex loadtest`: a running server under concurrent voxel requests.

use anyhow::bail;
use clap::Args;

#[derive(Args)]
pub struct LoadtestArgs {
    /// The server's base URL.
    #[arg(long, default_value = "http://127.0.0.1:8080")]
    url: String,
    /// Texture id.
    #[arg(long, default_value = "default")]
    texture: String,
    /// Concurrent closed-loop clients.
    #[arg(long, default_value_t = 8)]
    concurrency: usize,
    /// How long new requests are sent (e.g. 30s, 2m); requests in flight
    /// at the end are waited for.
    #[arg(long, default_value = "30s", value_parser = crate::loadtest::parse_duration)]
    duration: std::time::Duration,
    /// Request kinds, drawn uniformly: slices, cuts, bricks.
    #[arg(long, value_delimiter = ',', default_value = "slices,cuts,bricks")]
    mix: Vec<crate::loadtest::workload::Kind>,
    /// Seed of the request sequences.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Level of detail of every request (each step is 8× less work).
    #[arg(long, default_value_t = 0)]
    lod: u32,
    /// Side of slices and cuts, pixels.
    #[arg(long, default_value_t = 256)]
    size: u32,
    /// Fraction of requests inside a small shared box (overlapping work).
    #[arg(long, default_value_t = 0.5)]
    overlap: f64,
    /// Fraction of requests revalidating an earlier answer (304).
    #[arg(long, default_value_t = 0.05)]
    revalidate: f64,
    /// Replay interactive cutting instead: each client sweeps a plane one
    /// voxel per request (`axis` slices or `oblique` cuts); reports cuts/s.
    #[arg(long, num_args = 0..=1, default_missing_value = "axis")]
    sweep: Option<crate::loadtest::workload::SweepPlane>,
    /// Give up on one request after this long.
    #[arg(long, default_value = "120s", value_parser = crate::loadtest::parse_duration)]
    timeout: std::time::Duration,
    /// A soak: also upload, read and delete small textures and hang up on
    /// requests while the load runs.
    #[arg(long)]
    churn: bool,
    /// Compare a sample of the answers, byte for byte, with a fresh server
    /// at this URL serving the same texture; differences fail the command.
    #[arg(long)]
    verify_url: Option<String>,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

/// Runs `solidtex loadtest`.
pub fn run(a: LoadtestArgs) -> anyhow::Result<()> {
    let cfg = crate::loadtest::LoadConfig {
        url: a.url,
        texture: a.texture,
        concurrency: a.concurrency,
        duration: a.duration,
        mix: a.mix,
        seed: a.seed,
        lod: a.lod,
        side: a.size,
        overlap: a.overlap.clamp(0.0, 1.0),
        revalidate: a.revalidate.clamp(0.0, 1.0),
        sweep: a.sweep,
        timeout: a.timeout,
        churn: a.churn,
        verify_url: a.verify_url,
    };
    let report = crate::loadtest::run_blocking(&cfg)?;
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&report)?)?;
    } else {
        out!("{}", report.table())?;
    }
    if let Some(v) = &report.verify
        && v.mismatched > 0
    {
        bail!("{} answers differ from a fresh server's", v.mismatched);
    }
    Ok(())
}
