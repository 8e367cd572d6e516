//! The `solidtex` command line: precompute candidates, inspect them,
//! synthesize regions, slices and volumes, plan dependency sets, evaluate
//! quality and run benchmarks.

mod bench;
mod cli;
mod evalcmd;

use clap::Parser;

fn main() -> anyhow::Result<()> {
    let args = cli::Cli::parse();
    cli::run(args)
}
