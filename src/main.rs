//! The `solidtex` binary: the allocator, its options, and the command line
//! of the `solidtex` library.

/// Counts heap bytes for `solidtex bench` and per precompute in the server.
#[global_allocator]
static ALLOC: solidtex_server::peak_alloc::PeakAlloc = solidtex_server::peak_alloc::PeakAlloc;

/// jemalloc's options, read once before its first allocation: it looks up
/// this symbol by name (a NUL-terminated C string, the `malloc_conf` of
/// jemalloc's manual under the prefix of the `tikv-jemalloc-sys` build);
/// `_RJEM_MALLOC_CONF` overrides them.
///
/// - `background_thread:true,dirty_decay_ms:1000`: pages freed by a job or
///   a precompute go back to the system within about a second, from a
///   thread of jemalloc's own, instead of staying resident for ten seconds
///   or until the next allocation in their arena. The server's memory bound
///   (`server::memory`) counts on it. Measured numbers: docs/server.md.
/// - Transparent huge pages are left to the system's default: advising
///   them (`thp:always`) made no request faster and kept more memory
///   resident (docs/server.md).
#[unsafe(export_name = "_rjem_malloc_conf")]
pub static JEMALLOC_CONF: &[u8; 43] = b"background_thread:true,dirty_decay_ms:1000\0";

use clap::Parser;

fn main() -> anyhow::Result<()> {
    solidtex::run(solidtex::Cli::parse())
}
