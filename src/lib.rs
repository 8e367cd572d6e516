//! The `solidtex` command line: precompute candidates, inspect them,
//! synthesize regions, slices and volumes, plan dependency sets, evaluate
//! quality, run the HTTP service, benchmark it and load-test it.
//!
//! The method is `solidtex_core`; the service is `solidtex_server`. This
//! crate only parses arguments, reads and writes files and reports.
#![deny(unsafe_code)]
#![warn(missing_docs)]

/// `print!` that returns the write's error instead of panicking on it:
/// stdout may be a pipe that its reader closed early (`solidtex plan … |
/// head`), which [`run`] treats as the end of the command.
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        $crate::stdout_written(write!(std::io::stdout().lock(), $($arg)*))
    }};
}

/// `println!` as [`out!`] is to `print!`.
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        $crate::stdout_written(writeln!(std::io::stdout().lock(), $($arg)*))
    }};
}

/// The result of a write to stdout, its broken pipe marked as
/// [`StdoutClosed`]: only that one ends a command quietly, not a broken
/// pipe of a socket or a child process.
fn stdout_written(result: std::io::Result<()>) -> std::io::Result<()> {
    result.map_err(|e| match e.kind() {
        std::io::ErrorKind::BrokenPipe => {
            std::io::Error::new(std::io::ErrorKind::BrokenPipe, StdoutClosed)
        }
        _ => e,
    })
}

/// Stdout's reader has gone.
#[derive(Debug)]
struct StdoutClosed;

impl std::fmt::Display for StdoutClosed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("standard output closed by its reader")
    }
}

impl std::error::Error for StdoutClosed {}

mod bench;
mod cli;
pub mod loadtest;

pub use cli::{Cli, run};
