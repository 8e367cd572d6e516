//! The `solidtex` command line: precompute candidates, inspect them,
//! synthesize regions, slices and volumes, plan dependency sets, evaluate
//! quality, run the HTTP service, benchmark it and load-test it.
//!
//! The method is `solidtex_core`; the service is `solidtex_server`. This
//! crate only parses arguments, reads and writes files and reports.
#![deny(unsafe_code)]
#![warn(missing_docs)]

mod bench;
mod cli;
pub mod loadtest;

pub use cli::{Cli, run};
