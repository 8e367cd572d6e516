//! Command-line subcommands. Each one loads a texture (a `.stx` file or an
//! exemplar image precomputed on the fly), calls the library and writes
//! files; no synthesis logic lives here.

mod bake;
mod bench;
mod cut;
mod eval;
mod export;
mod inspect;
mod knob_flags;
mod loadtest;
mod plan;
mod precompute;
mod reference;
mod region;
mod slice;
mod source;
mod volume;

use clap::{Parser, Subcommand};

/// Infinite, spatially deterministic solid textures from 2D exemplars.
#[derive(Parser)]
#[command(name = "solidtex", version, about)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Precompute 3D candidates of an exemplar into a `.stx` file.
    Precompute(precompute::PrecomputeArgs),
    /// Write PNGs showing precomputed data: candidate slab, crossbar error.
    Inspect(inspect::InspectArgs),
    /// Synthesize a box of voxels as raw RGB8 (x fastest, then y, then z).
    Region(region::RegionArgs),
    /// Synthesize an axis-aligned slice as a PNG.
    Slice(slice::SliceArgs),
    /// Synthesize an oblique cut (any plane) as a PNG.
    Cut(cut::CutArgs),
    /// Texture a mesh (OBJ or GLB) from the solid: a glTF binary with a
    /// baked base-colour texture or vertex colours.
    Bake(bake::BakeArgs),
    /// Synthesize a full cube plus three orthogonal middle slices.
    Volume(volume::VolumeArgs),
    /// Write a box of the solid, or one period, as KTX2, a PNG slice
    /// atlas, NRRD or raw voxels.
    Export(export::ExportArgs),
    /// Count voxels and corrections per level for a slice or region, for
    /// the standard and dual-grid schemes, and the single-voxel chain.
    Plan(plan::PlanArgs),
    /// Time precomputation and synthesis on the shared exemplars.
    Bench(bench::BenchArgs),
    /// Score synthesized slices against their exemplar, next to baselines.
    Eval(eval::EvalArgs),
    /// Synthesize the global reference: a periodic block by texture
    /// optimisation over the whole block (minutes, not lazy).
    Reference(reference::ReferenceArgs),
    /// Run the HTTP voxel service.
    Serve(solidtex_server::ServeArgs),
    /// Measure a running server under concurrent voxel requests.
    Loadtest(loadtest::LoadtestArgs),
}

/// Runs one subcommand. A command whose reader stops reading its output
/// (`| head`) ends there, successfully, as other command-line tools do.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match run_command(cli) {
        Err(e) if closed_stdout(&e) => Ok(()),
        result => result,
    }
}

/// Whether `e` is a write to stdout whose reader has gone (marked by
/// `out!` and `outln!`; a broken pipe elsewhere stays an error).
fn closed_stdout(e: &anyhow::Error) -> bool {
    e.chain().any(|cause| {
        cause
            .downcast_ref::<std::io::Error>()
            .and_then(|io| io.get_ref())
            .is_some_and(|inner| inner.is::<crate::StdoutClosed>())
    })
}

fn run_command(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Serve(a) => solidtex_server::serve_main(a),
        Command::Loadtest(a) => loadtest::run(a),
        Command::Precompute(a) => precompute::run(a),
        Command::Inspect(a) => inspect::run(a),
        Command::Plan(a) => plan::run(&a),
        Command::Eval(a) => eval::run(a),
        Command::Bench(a) => bench::run(a),
        Command::Region(a) => region::run(a),
        Command::Slice(a) => slice::run(a),
        Command::Cut(a) => cut::run(a),
        Command::Volume(a) => volume::run(a),
        Command::Bake(a) => bake::run(a),
        Command::Reference(a) => reference::run(a),
        Command::Export(a) => export::run(a),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    /// Only stdout's broken pipe ends a command quietly: one from a socket
    /// (a load test's server going away) is still an error.
    #[test]
    fn only_a_closed_stdout_is_quiet() {
        let pipe = || std::io::Error::from(std::io::ErrorKind::BrokenPipe);
        let stdout = crate::stdout_written(Err(pipe())).unwrap_err();
        assert!(closed_stdout(
            &anyhow::Error::new(stdout).context("printing")
        ));
        assert!(!closed_stdout(
            &anyhow::Error::new(pipe()).context("sending")
        ));
        let other = crate::stdout_written(Err(std::io::ErrorKind::Other.into())).unwrap_err();
        assert!(!closed_stdout(&anyhow::Error::new(other)));
    }

    /// Every option and argument of every command says what it is.
    #[test]
    fn every_option_has_help() {
        fn walk(cmd: &clap::Command, path: &str, missing: &mut Vec<String>) {
            for arg in cmd.get_arguments() {
                let id = arg.get_id().as_str();
                if id == "help" || id == "version" {
                    continue;
                }
                if arg.get_help().is_none() && arg.get_long_help().is_none() {
                    missing.push(format!("{path} {id}"));
                }
            }
            for sub in cmd.get_subcommands() {
                walk(sub, &format!("{path} {}", sub.get_name()), missing);
            }
        }
        let mut missing = Vec::new();
        walk(&Cli::command(), "solidtex", &mut missing);
        assert!(missing.is_empty(), "options without help: {missing:?}");
    }
}
