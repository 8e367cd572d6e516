//! The `solidtex` command line: precompute candidates, inspect them,
//! synthesize regions, slices and volumes, plan dependency sets, evaluate
//! quality, run benchmarks and load-test a server.

mod bench;
mod cli;
mod evalcmd;

/// Counts heap bytes for `solidtex bench` and per precompute in the server.
#[global_allocator]
static ALLOC: solidtex::peak_alloc::PeakAlloc = solidtex::peak_alloc::PeakAlloc;

/// jemalloc's options, read once before its first allocation: it looks up
/// this symbol by name (a NUL-terminated C string, the `malloc_conf` of
/// jemalloc's manual under the prefix of the `tikv-jemalloc-sys` build).
///
/// Memory is advised for transparent huge pages: a correction reads its
/// candidate tables (tens of MB per texture) at random, and with 4 KiB
/// pages its loads miss the TLB. On a cold 256² slice on one thread that
/// took 5–7 % of the time (min and median of 10 interleaved runs); the
/// price is about 10 % more resident memory under load (whole huge pages
/// are zeroed and kept). Where the system disables transparent huge pages
/// the advice does nothing; `_RJEM_MALLOC_CONF` overrides it.
#[unsafe(export_name = "_rjem_malloc_conf")]
pub static JEMALLOC_CONF: &[u8; 11] = b"thp:always\0";

use clap::Parser;

fn main() -> anyhow::Result<()> {
    let args = cli::Cli::parse();
    cli::run(args)
}
