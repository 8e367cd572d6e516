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
        write!(std::io::stdout().lock(), $($arg)*)
    }};
}

/// `println!` as [`out!`] is to `print!`.
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        writeln!(std::io::stdout().lock(), $($arg)*)
    }};
}

mod bench;
mod cli;
pub mod loadtest;

pub use cli::{Cli, run};
