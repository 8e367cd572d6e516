//! `solidtex bench`: times precomputation, synthesis and the service.

use anyhow::Context;
use clap::Args;
use solidtex_server::write_atomic;
use std::path::PathBuf;

#[derive(Args)]
pub struct BenchArgs {
    /// Directory of exemplar PNGs.
    #[arg(long, default_value = "../shared/exemplars")]
    exemplars: PathBuf,
    /// Small sizes only (seconds), for CI.
    #[arg(long)]
    quick: bool,
    /// Skip a cold request whose plan predicts more seconds than this.
    #[arg(long, default_value_t = 120.0)]
    max_seconds: f64,
    /// Also load a server in this process with `loadtest` runs.
    #[arg(long)]
    load: bool,
    /// Level of detail of the mixed load runs.
    #[arg(long, default_value_t = 0)]
    load_lod: u32,
    /// Level of detail of the sweep load run.
    #[arg(long, default_value_t = 0)]
    sweep_lod: u32,
    /// Side of the slices, cuts and sweep planes of the load runs.
    #[arg(long, default_value_t = 256)]
    load_size: u32,
    /// Side of the sweep's planes, when it differs from `--load-size` (the
    /// sweep target is set at 256²).
    #[arg(long)]
    sweep_size: Option<u32>,
    /// Clients of the concurrent load run.
    #[arg(long, default_value_t = 32)]
    load_clients: usize,
    /// Duration of each load run.
    #[arg(long, default_value = "60s", value_parser = crate::loadtest::parse_duration)]
    load_duration: std::time::Duration,
    /// The loaded server's `--max-queue-wait`, seconds: how long a job may
    /// wait for a slot before it is answered 503.
    #[arg(long, default_value_t = 1.0, value_parser = solidtex_server::config::parse_wait)]
    load_max_wait: f64,
    /// Only the mesh bakes (shell efficiency), on the synthesis exemplar.
    #[arg(long, conflicts_with = "structure_only")]
    meshes_only: bool,
    /// Only the structure rows (the quality preset and the reference beside
    /// the default), on the synthesis exemplar.
    #[arg(long)]
    structure_only: bool,
    /// Write the results as a Markdown page (e.g. BENCHMARKS.md).
    #[arg(long)]
    markdown: Option<PathBuf>,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

/// Runs `solidtex bench`.
pub fn run(a: BenchArgs) -> anyhow::Result<()> {
    use crate::bench;
    let quick = a.quick;
    let opts = bench::Options {
        exemplars: a.exemplars,
        quick,
        max_seconds: a.max_seconds,
        load: a.load.then_some(bench::service::LoadOptions {
            // Quick mode (2 levels) at lod 1 synthesizes the coarse level only.
            lod: if quick { 1 } else { a.load_lod },
            sweep_lod: if quick { 1 } else { a.sweep_lod },
            // Quick mode shrinks the load too, so CI stays in seconds.
            side: if quick { 32 } else { a.load_size },
            sweep_side: if quick {
                32
            } else {
                a.sweep_size.unwrap_or(a.load_size)
            },
            clients: a.load_clients,
            duration: a.load_duration,
            cache_bytes: 512 << 20,
            brick_size: if quick { 16 } else { 64 },
            max_queue_wait: a.load_max_wait,
        }),
        only: if a.meshes_only {
            Some(bench::Only::Meshes)
        } else if a.structure_only {
            Some(bench::Only::Structure)
        } else {
            None
        },
    };
    let results = bench::run(&opts)?;
    if let Some(path) = &a.markdown {
        let command = std::iter::once("solidtex".to_string())
            .chain(std::env::args().skip(1))
            .collect::<Vec<_>>()
            .join(" ");
        let machine = bench::machine::current();
        let apart = match opts.only {
            Some(bench::Only::Meshes) => Some(&bench::markdown::MESHES),
            Some(bench::Only::Structure) => Some(&bench::markdown::STRUCTURE),
            None => None,
        };
        let page = if let Some(sec) = apart {
            // The rest of the page stays as it was measured.
            let rows = bench::markdown::rows_of(sec, &results.rows);
            let text = bench::markdown::section(sec, &rows, Some((&machine, &command)));
            let old = std::fs::read_to_string(path).unwrap_or_default();
            bench::markdown::splice(&old, sec, &text)
        } else {
            bench::markdown::page(&results, &machine, &command)
        };
        write_atomic(path, page.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&results)?)?;
    } else {
        bench::print(&results)?;
    }
    Ok(())
}
