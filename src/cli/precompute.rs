//! `solidtex precompute`: 3D candidates of an exemplar into a `.stx` file.

use super::knob_flags::AnalysisArgs;
use super::source::{open_exemplar, precompute};
use anyhow::{Context, bail};
use clap::Args;
use solidtex_core::{Candidates, Exemplar, ExemplarSet, Layout, Orientation};
use solidtex_server::write_atomic;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Args)]
pub struct PrecomputeArgs {
    /// Exemplar image used for the xy plane (and all planes unless --yz/--zx).
    exemplar: PathBuf,
    /// Exemplar for the yz plane.
    #[arg(long)]
    yz: Option<PathBuf>,
    /// Exemplar for the zx plane.
    #[arg(long)]
    zx: Option<PathBuf>,
    /// Feature mask of the exemplar (of the xy plane with --yz/--zx): an
    /// image of its size, features (veins, cracks, mortar) light, the rest
    /// dark. The feature-distance channel measures from it instead of a
    /// threshold of the luminance; needs --feature-weight above 0.
    #[arg(long)]
    feature_mask: Option<PathBuf>,
    /// Feature mask of the yz exemplar.
    #[arg(long, requires = "yz")]
    feature_mask_yz: Option<PathBuf>,
    /// Feature mask of the zx exemplar.
    #[arg(long, requires = "zx")]
    feature_mask_zx: Option<PathBuf>,
    /// Output `.stx` file.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    analysis: AnalysisArgs,
    /// Also print each stage's time and each level's candidate statistics.
    #[arg(long)]
    verbose: bool,
}

/// Runs `solidtex precompute`.
pub fn run(a: PrecomputeArgs) -> anyhow::Result<()> {
    let xy = masked(open_exemplar(&a.exemplar)?, a.feature_mask.as_deref())?;
    let set = match (&a.yz, &a.zx) {
        (None, None) => ExemplarSet::single(xy),
        (Some(yz), Some(zx)) => ExemplarSet::triple(
            xy,
            masked(open_exemplar(yz)?, a.feature_mask_yz.as_deref())?,
            masked(open_exemplar(zx)?, a.feature_mask_zx.as_deref())?,
        )?,
        _ => bail!("give both --yz and --zx, or neither"),
    };
    let params = a.analysis.params();
    let (w, h) = (set.width(), set.height());
    let estimate = Candidates::estimated_peak_bytes(w, h, !set.is_single(), &params);
    solidtex_server::peak_alloc::start();
    let baseline = solidtex_server::peak_alloc::reset();
    let t0 = Instant::now();
    let c = precompute(&set, &params, false)?;
    let total = t0.elapsed().as_secs_f64();
    let peak = solidtex_server::peak_alloc::peak_above(baseline);
    let bytes = c.to_bytes();
    write_atomic(&a.output, &bytes).with_context(|| format!("writing {}", a.output.display()))?;
    print_report(&c, &a.output, total, bytes.len(), a.verbose)?;
    let mib = |b: u64| b as f64 / (1 << 20) as f64;
    outln!(
        "peak heap while computing {:.0} MiB (estimated {:.0} MiB)",
        mib(peak),
        mib(estimate)
    )?;
    Ok(())
}

/// `e` with the feature mask drawn in the image at `mask`, if any.
fn masked(e: Exemplar, mask: Option<&Path>) -> anyhow::Result<Exemplar> {
    let Some(path) = mask else { return Ok(e) };
    let image = open_exemplar(path)?;
    e.with_mask_image(&image)
        .with_context(|| format!("feature mask {}", path.display()))
}

fn print_report(
    c: &Candidates,
    path: &Path,
    total: f64,
    file_bytes: usize,
    verbose: bool,
) -> std::io::Result<()> {
    let (compact, total_mem) = c.memory_bytes();
    let mib = |b: usize| b as f64 / (1 << 20) as f64;
    outln!(
        "wrote {}: candidates of a {}×{} exemplar over {} levels in {total:.1} s; \
         {:.1} MiB on disk, {:.0} MiB in memory when loaded",
        path.display(),
        c.dims().w,
        c.dims().h,
        c.level_count(),
        mib(file_bytes),
        mib(total_mem),
    )?;
    outln!("{}", describe_layout(c.params().orientation, c.layout()))?;
    if !verbose {
        return Ok(());
    }
    let r = c.report();
    for (name, s) in &r.stage_seconds {
        outln!("  {name:<10} {s:.3} s")?;
    }
    for (k, l) in r.levels.iter().enumerate() {
        outln!(
            "  level {k}: crossbar error best {:.0} vs random {:.0}; fallbacks {}; filter iterations {}",
            l.mean_best_error,
            l.mean_random_error,
            l.fallbacks,
            l.iterations
        )?;
        let hist: Vec<String> = l
            .histogram
            .iter()
            .enumerate()
            .filter(|(_, n)| **n > 0)
            .map(|(i, n)| format!("{i}:{n}"))
            .collect();
        outln!("    candidates per pixel {}", hist.join(" "))?;
    }
    outln!("  candidates compact {compact} bytes; in memory {total_mem} bytes")
}

/// One line on how the exemplar is laid on the planes.
fn describe_layout(asked: Orientation, l: &Layout) -> String {
    let a = l.arrangement;
    let how = match asked {
        Orientation::Auto if l.detected => "auto: strongly oriented along an axis",
        Orientation::Auto => "auto: not strongly oriented along an axis",
        Orientation::None => "none",
        Orientation::Given(_) => "given",
    };
    format!(
        "orientation ({how}; coherence {:.3}, grain {:.1}° from u): rotate xy {}°, yz {}°, zx {}°; weights {}, {}, {}",
        l.grain.coherence,
        l.grain.degrees,
        a.rotate[0],
        a.rotate[1],
        a.rotate[2],
        a.weights[0],
        a.weights[1],
        a.weights[2]
    )
}
