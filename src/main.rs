//! The `solidtex` command line: precompute candidates, inspect them,
//! synthesize regions, slices and volumes, plan dependency sets, evaluate
//! quality, run benchmarks and load-test a server.

mod bench;
mod cli;
mod evalcmd;
mod peak_alloc;

/// Counts heap bytes for `solidtex bench` (off unless the bench starts it).
#[global_allocator]
static ALLOC: peak_alloc::PeakAlloc = peak_alloc::PeakAlloc;

use clap::Parser;

fn main() -> anyhow::Result<()> {
    let args = cli::Cli::parse();
    cli::run(args)
}
