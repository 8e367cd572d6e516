//! Command-line subcommands. Each one loads a texture (a `.stx` file or an
//! exemplar image precomputed on the fly), calls the library and writes
//! files; no synthesis logic lives here.

use anyhow::{Context, bail};
use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use solidtex::{
    AnalysisParams, Axis, Candidates, Correction, Exemplar, ExemplarSet, Region, Scheme,
    SlabTiling, Slices, Stage, SynthParams, Texture, TileCache,
};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

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
    Precompute(PrecomputeArgs),
    /// Write PNGs showing precomputed data: candidate slab, crossbar error.
    Inspect(InspectArgs),
    /// Synthesize a box of voxels as raw RGB8 (x fastest, then y, then z).
    Region(RegionArgs),
    /// Synthesize an axis-aligned slice as a PNG.
    Slice(SliceArgs),
    /// Synthesize an oblique cut (any plane) as a PNG.
    Cut(CutArgs),
    /// Synthesize a full cube plus three orthogonal middle slices.
    Volume(VolumeArgs),
    /// Count voxels and corrections per level for a slice or region, for
    /// the standard and dual-grid schemes, and the single-voxel chain.
    Plan(PlanArgs),
    /// Time precomputation and synthesis on the shared exemplars.
    Bench(BenchArgs),
    /// Score synthesized slices against their exemplar, next to baselines.
    Eval(EvalArgs),
    /// Run the HTTP voxel service.
    Serve(solidtex::server::ServeArgs),
    /// Measure a running server under concurrent voxel requests.
    Loadtest(LoadtestArgs),
}

#[derive(Args)]
struct LoadtestArgs {
    /// The server's base URL.
    #[arg(long, default_value = "http://127.0.0.1:8080")]
    url: String,
    /// Texture id.
    #[arg(long, default_value = "default")]
    texture: String,
    /// Concurrent closed-loop clients.
    #[arg(long, default_value_t = 8)]
    concurrency: usize,
    /// How long new requests are sent (e.g. 30s, 2m); requests in flight
    /// at the end are waited for.
    #[arg(long, default_value = "30s", value_parser = solidtex::loadtest::parse_duration)]
    duration: std::time::Duration,
    /// Request kinds, drawn uniformly: slices, cuts, bricks.
    #[arg(long, value_delimiter = ',', default_value = "slices,cuts,bricks")]
    mix: Vec<solidtex::loadtest::workload::Kind>,
    /// Seed of the request sequences.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Level of detail of every request (each step is 8× less work).
    #[arg(long, default_value_t = 0)]
    lod: u32,
    /// Side of slices and cuts, pixels.
    #[arg(long, default_value_t = 256)]
    size: u32,
    /// Fraction of requests inside a small shared box (overlapping work).
    #[arg(long, default_value_t = 0.5)]
    overlap: f64,
    /// Fraction of requests revalidating an earlier answer (304).
    #[arg(long, default_value_t = 0.05)]
    revalidate: f64,
    /// Replay interactive cutting instead: each client sweeps a plane one
    /// voxel per request (`axis` slices or `oblique` cuts); reports cuts/s.
    #[arg(long, num_args = 0..=1, default_missing_value = "axis")]
    sweep: Option<solidtex::loadtest::workload::SweepPlane>,
    /// Give up on one request after this long.
    #[arg(long, default_value = "120s", value_parser = solidtex::loadtest::parse_duration)]
    timeout: std::time::Duration,
    /// A soak: also upload, read and delete small textures and hang up on
    /// requests while the load runs.
    #[arg(long)]
    churn: bool,
    /// Compare a sample of the answers, byte for byte, with a fresh server
    /// at this URL serving the same texture; differences fail the command.
    #[arg(long)]
    verify_url: Option<String>,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
struct EvalArgs {
    /// Exemplar images to evaluate.
    #[arg(required = true)]
    exemplars: Vec<PathBuf>,
    /// Slice side.
    #[arg(long, default_value_t = 128)]
    side: u32,
    /// Also score the standard scheme.
    #[arg(long)]
    standard: bool,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
    /// Parameters of the corrected slices (the slab baseline shares the
    /// seed and jitter).
    #[command(flatten)]
    synth: SynthArgs,
}

#[derive(Args)]
struct BenchArgs {
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
    #[arg(long, default_value = "60s", value_parser = solidtex::loadtest::parse_duration)]
    load_duration: std::time::Duration,
    /// The loaded server's `--max-queue-wait`, seconds: how long a job may
    /// wait for a slot before it is answered 503.
    #[arg(long, default_value_t = 1.0, value_parser = solidtex::server::config::parse_wait)]
    load_max_wait: f64,
    /// Write the results as a Markdown page (e.g. BENCHMARKS.md).
    #[arg(long)]
    markdown: Option<PathBuf>,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
struct PlanArgs {
    #[command(flatten)]
    src: SourceArgs,
    /// Slice side: a square slice normal to `--axis` at `--at`.
    #[arg(long, default_value_t = 256)]
    slice: u32,
    /// Axis normal to the slice: x, y or z.
    #[arg(long, default_value = "z")]
    axis: Axis,
    /// Position of the slice along its axis. Where a slice lies changes
    /// its chain: with subpasses, voxels of later classes read their
    /// neighbours' new values.
    #[arg(long, default_value_t = 0, allow_hyphen_values = true)]
    at: i64,
    /// Slice corner along its u axis (x for z slices, y for x, z for y).
    #[arg(long, default_value_t = 0, allow_hyphen_values = true)]
    u0: i64,
    /// Slice corner along its v axis (y for z slices, z for x, x for y).
    #[arg(long, default_value_t = 0, allow_hyphen_values = true)]
    v0: i64,
    /// Plan a box instead of a slice: X,Y,Z,W,H,D (corner, then size).
    #[arg(
        long,
        value_delimiter = ',',
        num_args = 1,
        allow_hyphen_values = true,
        conflicts_with_all = ["slice", "axis", "at", "u0", "v0"]
    )]
    region: Option<Vec<i64>>,
    /// Also count the slice's exact chains for these neighbourhood sides
    /// (geometry only, no precomputation; Zhang et al. measured N = 9).
    #[arg(long = "neighbourhood", value_delimiter = ',')]
    neighbourhoods: Vec<u32>,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

#[derive(Args, Clone)]
struct SourceArgs {
    /// A `.stx` file, or an exemplar image (precomputed on the fly; the
    /// bundled default exemplar when omitted).
    source: Option<PathBuf>,
    /// Correction scheme: standard or dual-grid.
    #[arg(long, default_value = "dual-grid")]
    scheme: Scheme,
    #[command(flatten)]
    synth: SynthArgs,
    /// Level of detail (0 = finest).
    #[arg(long, default_value_t = 0)]
    lod: u32,
}

/// Synthesis parameters other than the scheme.
#[derive(Args, Clone)]
struct SynthArgs {
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Preview parameters: one correction pass per level and the finest
    /// level upsampled without correction; cold slices 5–7× faster for
    /// about 10 % worse patch coherence (docs/quality.md).
    #[arg(long, conflicts_with_all = ["passes", "finest_passes", "fine_levels"])]
    preview: bool,
    /// Correction passes per level, the fine levels excepted.
    #[arg(long, default_value_t = 2)]
    passes: u32,
    /// Correction passes at the finest levels (see `--fine-levels`).
    #[arg(long, default_value_t = 1)]
    finest_passes: u32,
    /// Levels, counted from the finest, corrected with `--finest-passes`
    /// passes instead of `--passes`.
    #[arg(long, default_value_t = solidtex::params::DEFAULT_FINE_LEVELS)]
    fine_levels: u32,
    /// Dual-grid cell side M.
    #[arg(long, default_value_t = 12)]
    grid: u32,
    /// Jitter strength (0 disables).
    #[arg(long, default_value_t = 1.0)]
    jitter: f32,
    /// Subpass block side s (s³ subpasses per pass; 1 disables subpasses).
    #[arg(long, default_value_t = 2)]
    subpass_side: u32,
    /// Gain on correction queries around their mean colour (1 disables).
    #[arg(long, default_value_t = solidtex::params::DEFAULT_CONTRAST)]
    contrast: f32,
    /// Voxels the colour correction reads: sparse (direct neighbours, the rest of
    /// each N×N slice extrapolated) or full (every voxel of the slices).
    #[arg(long, default_value = "sparse")]
    slices: Slices,
    /// Penalty on coherent triples whose three exemplar colours disagree
    /// (0 disables).
    #[arg(long, default_value_t = solidtex::params::DEFAULT_CONSISTENCY)]
    consistency: f32,
    /// Thickness of the candidate slab's layers, in voxels of the
    /// initialisation level (Dong et al.: N).
    #[arg(long, default_value_t = solidtex::params::DEFAULT_SLAB_THICKNESS)]
    slab_thickness: u32,
    /// How the slab is cut for tiling: cells (a jittered grid, borders at
    /// every angle) or blocks (axis-aligned squares).
    #[arg(long, default_value_t = SynthParams::default().slab_tiling)]
    slab_tiling: SlabTiling,
    /// What a correction matches: appearance (sparse appearance-space
    /// neighbourhoods, 12 diagonal locations) or colour (N×N colour
    /// neighbourhoods).
    #[arg(long, default_value_t = SynthParams::default().correction)]
    correction: Correction,
}

impl SynthArgs {
    fn params(&self, scheme: Scheme) -> SynthParams {
        // The preview sets the passes (clap refuses them beside it).
        let base = if self.preview {
            SynthParams::preview()
        } else {
            SynthParams {
                passes: self.passes,
                finest_passes: self.finest_passes,
                fine_levels: self.fine_levels,
                ..SynthParams::default()
            }
        };
        SynthParams {
            seed: self.seed,
            scheme,
            grid: self.grid,
            jitter: self.jitter,
            subpass_side: self.subpass_side,
            contrast: self.contrast,
            slices: self.slices,
            consistency: self.consistency,
            slab_thickness: self.slab_thickness,
            slab_tiling: self.slab_tiling,
            correction: self.correction,
            ..base
        }
    }
}

#[derive(Args)]
struct PrecomputeArgs {
    /// Exemplar image used for the xy plane (and all planes unless --yz/--zx).
    exemplar: PathBuf,
    /// Exemplar for the yz plane.
    #[arg(long)]
    yz: Option<PathBuf>,
    /// Exemplar for the zx plane.
    #[arg(long)]
    zx: Option<PathBuf>,
    /// Output `.stx` file.
    #[arg(short, long)]
    output: PathBuf,
    /// Pyramid levels analysed.
    #[arg(long, default_value_t = 4)]
    levels: u32,
    /// How the exemplar is laid on the planes: auto (turn one plane and
    /// weight the third down when the exemplar is strongly oriented along
    /// an axis), none, or an arrangement as JSON, e.g.
    /// '{"rotate": [0, 270, 0], "weights": [1, 1, 0.25]}'.
    #[arg(long, default_value = "auto")]
    orientation: solidtex::Orientation,
    /// Also print each stage's time and each level's candidate statistics.
    #[arg(long)]
    verbose: bool,
}

#[derive(Args)]
struct InspectArgs {
    /// The `.stx` file.
    stx: PathBuf,
    /// Output directory.
    #[arg(long)]
    out: PathBuf,
}

#[derive(Args)]
struct RegionArgs {
    #[command(flatten)]
    src: SourceArgs,
    /// Lowest corner, x.
    #[arg(long, allow_hyphen_values = true)]
    x: i64,
    /// Lowest corner, y.
    #[arg(long, allow_hyphen_values = true)]
    y: i64,
    /// Lowest corner, z.
    #[arg(long, allow_hyphen_values = true)]
    z: i64,
    /// Extent along x, voxels.
    #[arg(long = "width", alias = "w")]
    w: u32,
    /// Extent along y, voxels.
    #[arg(long = "height", alias = "h")]
    h: u32,
    /// Extent along z, voxels.
    #[arg(long = "depth", alias = "d")]
    d: u32,
    /// Output file.
    #[arg(short, long)]
    output: PathBuf,
}

#[derive(Args)]
struct SliceArgs {
    #[command(flatten)]
    src: SourceArgs,
    /// Axis normal to the slice: x, y or z.
    #[arg(long)]
    axis: Axis,
    /// Position along the axis.
    #[arg(long, allow_hyphen_values = true)]
    at: i64,
    /// Slice corner along its u axis (x for z slices, y for x, z for y).
    #[arg(long, default_value_t = 0, allow_hyphen_values = true)]
    u0: i64,
    /// Slice corner along its v axis (y for z slices, z for x, x for y).
    #[arg(long, default_value_t = 0, allow_hyphen_values = true)]
    v0: i64,
    /// Width in pixels (along u).
    #[arg(long = "width", alias = "w", default_value_t = 256)]
    w: u32,
    /// Height in pixels (along v).
    #[arg(long = "height", alias = "h", default_value_t = 256)]
    h: u32,
    /// Output PNG.
    #[arg(short, long)]
    output: PathBuf,
}

#[derive(Args)]
struct CutArgs {
    #[command(flatten)]
    src: SourceArgs,
    /// Position of pixel (0, 0), `x,y,z` in voxels of the level served.
    #[arg(long, value_parser = parse_vec3, default_value = "0,0,0", allow_hyphen_values = true)]
    origin: [f64; 3],
    /// Step per pixel to the right, `x,y,z`.
    #[arg(long, value_parser = parse_vec3, default_value = "0.7071,0.7071,0", allow_hyphen_values = true)]
    u: [f64; 3],
    /// Step per pixel downwards, `x,y,z`.
    #[arg(long, value_parser = parse_vec3, default_value = "-0.4082,0.4082,0.8165", allow_hyphen_values = true)]
    v: [f64; 3],
    /// Width in pixels.
    #[arg(long, default_value_t = 256)]
    width: u32,
    /// Height in pixels.
    #[arg(long, default_value_t = 256)]
    height: u32,
    /// Sampling between voxel centres: nearest or trilinear.
    #[arg(long, default_value = "nearest")]
    filter: CutFilter,
    /// Output PNG.
    #[arg(short, long)]
    output: PathBuf,
}

/// How `cut` samples between voxel centres.
#[derive(Clone, Copy, clap::ValueEnum)]
enum CutFilter {
    /// The nearest voxel.
    Nearest,
    /// A trilinear blend of the eight nearest voxels.
    Trilinear,
}

/// Parses `x,y,z` into three finite numbers.
fn parse_vec3(s: &str) -> Result<[f64; 3], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let [x, y, z] = parts[..] else {
        return Err(format!("`{s}` is not three numbers `x,y,z`"));
    };
    let num = |t: &str| match t.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(format!("`{t}` is not a finite number")),
    };
    Ok([num(x)?, num(y)?, num(z)?])
}

#[derive(Args)]
struct VolumeArgs {
    #[command(flatten)]
    src: SourceArgs,
    /// Cube side.
    #[arg(long, default_value_t = 128)]
    size: u32,
    /// Output directory.
    #[arg(short, long)]
    output: PathBuf,
}

/// One sentence on what a synthesis command wrote and what it cost.
fn summary(what: &str, path: &Path, t0: Instant, stats: &solidtex::SynthStats) -> String {
    let corrections: u64 = stats.corrections_per_level.iter().sum();
    format!(
        "wrote {what} to {} in {:.2} s: {corrections} corrections over {} levels, \
         {} tiles synthesized, {} from the cache",
        path.display(),
        t0.elapsed().as_secs_f64(),
        stats.corrections_per_level.len(),
        stats.tiles_computed,
        stats.tiles_from_cache,
    )
}

fn progress_bar() -> ProgressBar {
    let bar = ProgressBar::new(1000);
    bar.set_style(
        ProgressStyle::with_template("{spinner} {msg:12} [{bar:40}] {percent}% {elapsed}")
            .expect("valid template"),
    );
    bar
}

fn precompute(
    set: &ExemplarSet,
    params: &AnalysisParams,
    quiet: bool,
) -> anyhow::Result<Candidates> {
    let bar = if quiet {
        ProgressBar::hidden()
    } else {
        progress_bar()
    };
    let stages = [
        Stage::Analysis,
        Stage::Search,
        Stage::Coherence,
        Stage::Finish,
    ];
    let cb = |s: Stage, f: f32| {
        let i = stages.iter().position(|&x| x == s).unwrap_or(0);
        bar.set_message(format!("{s:?}").to_lowercase());
        bar.set_position(((i as f32 + f) / 4.0 * 1000.0) as u64);
    };
    let c = Candidates::compute(set, params, &cb)?;
    bar.finish_and_clear();
    Ok(c)
}

fn load_source(src: &SourceArgs) -> anyhow::Result<Texture> {
    let cands = match &src.source {
        Some(p) if p.extension().is_some_and(|e| e == "stx") => {
            let bytes = std::fs::read(p).with_context(|| format!("reading {}", p.display()))?;
            Candidates::load(&bytes)?
        }
        Some(p) => {
            eprintln!(
                "precomputing the candidates of {} (save them with `solidtex precompute` to skip this)",
                p.display()
            );
            precompute(
                &ExemplarSet::single(open_exemplar(p)?),
                &AnalysisParams::default(),
                false,
            )?
        }
        None => {
            let set = ExemplarSet::single(solidtex::bundled::exemplar());
            match solidtex::bundled::candidates_for(&set, &AnalysisParams::default()) {
                Some(c) => c,
                None => precompute(&set, &AnalysisParams::default(), false)?,
            }
        }
    };
    let params = src.synth.params(src.scheme);
    Ok(Texture::new(
        Arc::new(cands),
        params,
        Arc::new(TileCache::new(1 << 30)),
    )?)
}

/// Opens a PNG or JPEG exemplar; a photo larger than the exemplar limit is
/// downscaled, and the user told so.
fn open_exemplar(path: &Path) -> anyhow::Result<Exemplar> {
    let (e, original) =
        Exemplar::open_fitting(path).with_context(|| format!("reading {}", path.display()))?;
    if let Some((w, h)) = original {
        eprintln!(
            "{}: downscaled from {w}x{h} to {}x{} (exemplars are at most {} pixels per side)",
            path.display(),
            e.width(),
            e.height(),
            solidtex::exemplar::MAX_SIDE
        );
    }
    Ok(e)
}

fn write_png(path: &Path, w: u32, h: u32, rgb: Vec<u8>) -> anyhow::Result<()> {
    let img = image::RgbImage::from_raw(w, h, rgb).context("image size")?;
    img.save(path)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// Runs one subcommand.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Serve(a) => return solidtex::server::serve_main(a),
        Command::Loadtest(a) => {
            let cfg = solidtex::loadtest::LoadConfig {
                url: a.url,
                texture: a.texture,
                concurrency: a.concurrency,
                duration: a.duration,
                mix: a.mix,
                seed: a.seed,
                lod: a.lod,
                side: a.size,
                overlap: a.overlap.clamp(0.0, 1.0),
                revalidate: a.revalidate.clamp(0.0, 1.0),
                sweep: a.sweep,
                timeout: a.timeout,
                churn: a.churn,
                verify_url: a.verify_url,
            };
            let report = solidtex::loadtest::run_blocking(&cfg)?;
            if a.json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else {
                print!("{}", report.table());
            }
            if let Some(v) = &report.verify
                && v.mismatched > 0
            {
                bail!("{} answers differ from a fresh server's", v.mismatched);
            }
        }
        Command::Precompute(a) => {
            let xy = open_exemplar(&a.exemplar)?;
            let set = match (&a.yz, &a.zx) {
                (None, None) => ExemplarSet::single(xy),
                (Some(yz), Some(zx)) => {
                    ExemplarSet::triple(xy, open_exemplar(yz)?, open_exemplar(zx)?)?
                }
                _ => bail!("give both --yz and --zx, or neither"),
            };
            let params = AnalysisParams {
                levels: a.levels,
                orientation: a.orientation,
                ..AnalysisParams::default()
            };
            let (w, h) = (set.width(), set.height());
            let estimate =
                solidtex::candidates::estimated_peak_bytes(w, h, !set.is_single(), &params);
            solidtex::peak_alloc::start();
            let baseline = solidtex::peak_alloc::reset();
            let t0 = Instant::now();
            let c = precompute(&set, &params, false)?;
            let total = t0.elapsed().as_secs_f64();
            let peak = solidtex::peak_alloc::peak_above(baseline);
            let bytes = c.to_bytes();
            write_atomically(&a.output, &bytes)?;
            print_report(&c, &a.output, total, bytes.len(), a.verbose);
            let mib = |b: u64| b as f64 / (1 << 20) as f64;
            println!(
                "peak heap while computing {:.0} MiB (estimated {:.0} MiB)",
                mib(peak),
                mib(estimate)
            );
        }
        Command::Inspect(a) => inspect(&a)?,
        Command::Plan(a) => plan(&a)?,
        Command::Eval(a) => {
            let mut all = Vec::new();
            for path in &a.exemplars {
                let name = path
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default();
                let e = open_exemplar(path)?;
                let scores = crate::evalcmd::evaluate(
                    &name,
                    &e,
                    a.side,
                    a.standard,
                    &a.synth.params(Scheme::DualGrid),
                )?;
                if !a.json {
                    crate::evalcmd::print(&scores);
                }
                all.extend(scores);
            }
            if a.json {
                println!("{}", serde_json::to_string_pretty(&all)?);
            }
        }
        Command::Bench(a) => bench(a)?,
        Command::Region(a) => {
            let tex = load_source(&a.src)?;
            let region = Region {
                origin: [a.x, a.y, a.z],
                size: [a.w, a.h, a.d],
            };
            let t0 = Instant::now();
            let (rgb, stats) = tex.region(&region, a.src.lod)?;
            write_atomically(&a.output, &rgb)?;
            let [w, h, d] = region.size;
            eprintln!(
                "{}",
                summary(
                    &format!("{w}×{h}×{d} voxels (RGB8, x fastest)"),
                    &a.output,
                    t0,
                    &stats
                )
            );
        }
        Command::Slice(a) => {
            let tex = load_source(&a.src)?;
            let t0 = Instant::now();
            let (rgb, stats) = tex.slice(a.axis, a.at, a.u0, a.v0, a.w, a.h, a.src.lod)?;
            write_png(&a.output, a.w, a.h, rgb)?;
            let axis = format!("{:?}", a.axis).to_lowercase();
            let what = format!("a {}×{} {axis} slice at {axis} = {}", a.w, a.h, a.at);
            eprintln!("{}", summary(&what, &a.output, t0, &stats));
        }
        Command::Cut(a) => {
            let tex = load_source(&a.src)?;
            let plane = solidtex::CutPlane {
                origin: a.origin,
                u: a.u,
                v: a.v,
                width: a.width,
                height: a.height,
            };
            let filter = match a.filter {
                CutFilter::Nearest => solidtex::Filter::Nearest,
                CutFilter::Trilinear => solidtex::Filter::Trilinear,
            };
            let t0 = Instant::now();
            let (rgb, stats) = tex.cut(&plane, a.src.lod, filter)?;
            write_png(&a.output, a.width, a.height, rgb)?;
            let what = format!(
                "a {}×{} oblique cut from ({}, {}, {})",
                a.width, a.height, a.origin[0], a.origin[1], a.origin[2]
            );
            eprintln!("{}", summary(&what, &a.output, t0, &stats));
        }
        Command::Volume(a) => {
            let tex = load_source(&a.src)?;
            std::fs::create_dir_all(&a.output)?;
            let s = a.size;
            let t0 = Instant::now();
            let (rgb, stats) = tex.region(
                &Region {
                    origin: [0, 0, 0],
                    size: [s, s, s],
                },
                a.src.lod,
            )?;
            let raw = a.output.join(format!("volume_{s}.raw"));
            write_atomically(&raw, &rgb)?;
            eprintln!(
                "{} (and its three middle slices)",
                summary(
                    &format!("a {s}³ volume (RGB8, x fastest)"),
                    &raw,
                    t0,
                    &stats
                )
            );
            let mid = (s / 2) as i64;
            for axis in [Axis::X, Axis::Y, Axis::Z] {
                let (img, _) = tex.slice(axis, mid, 0, 0, s, s, a.src.lod)?;
                let name = format!("slice_{axis:?}.png").to_lowercase();
                write_png(&a.output.join(name), s, s, img)?;
            }
        }
    }
    Ok(())
}

fn bench(a: BenchArgs) -> anyhow::Result<()> {
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
    };
    let results = bench::run(&opts)?;
    if let Some(path) = &a.markdown {
        let command = std::iter::once("solidtex".to_string())
            .chain(std::env::args().skip(1))
            .collect::<Vec<_>>()
            .join(" ");
        let page = bench::markdown::page(&results, &bench::machine::current(), &command);
        write_atomically(path, page.as_bytes())?;
        eprintln!("wrote {}", path.display());
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&results)?);
    } else {
        bench::print(&results);
    }
    Ok(())
}

fn write_atomically(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, bytes).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path)?;
    Ok(())
}

fn print_report(c: &Candidates, path: &Path, total: f64, file_bytes: usize, verbose: bool) {
    let (compact, total_mem) = c.memory_bytes();
    let mib = |b: usize| b as f64 / (1 << 20) as f64;
    println!(
        "wrote {}: candidates of a {}×{} exemplar over {} levels in {total:.1} s; \
         {:.1} MiB on disk, {:.0} MiB in memory when loaded",
        path.display(),
        c.dims().w,
        c.dims().h,
        c.level_count(),
        mib(file_bytes),
        mib(total_mem),
    );
    println!("{}", describe_layout(c.params().orientation, c.layout()));
    if !verbose {
        return;
    }
    let r = c.report();
    for (name, s) in &r.stage_seconds {
        println!("  {name:<10} {s:.3} s");
    }
    for (k, l) in r.levels.iter().enumerate() {
        println!(
            "  level {k}: crossbar error best {:.0} vs random {:.0}; fallbacks {}; filter iterations {}",
            l.mean_best_error, l.mean_random_error, l.fallbacks, l.iterations
        );
        let hist: Vec<String> = l
            .histogram
            .iter()
            .enumerate()
            .filter(|(_, n)| **n > 0)
            .map(|(i, n)| format!("{i}:{n}"))
            .collect();
        println!("    candidates per pixel {}", hist.join(" "));
    }
    println!("  candidates compact {compact} bytes; in memory {total_mem} bytes");
}

/// One line on how the exemplar is laid on the planes.
fn describe_layout(asked: solidtex::Orientation, l: &solidtex::orientation::Layout) -> String {
    let a = l.arrangement;
    let how = match asked {
        solidtex::Orientation::Auto if l.detected => "auto: strongly oriented along an axis",
        solidtex::Orientation::Auto => "auto: not strongly oriented along an axis",
        solidtex::Orientation::None => "none",
        solidtex::Orientation::Given(_) => "given",
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

fn inspect(a: &InspectArgs) -> anyhow::Result<()> {
    let bytes = std::fs::read(&a.stx)?;
    let c = Candidates::load(&bytes)?;
    std::fs::create_dir_all(&a.out)?;
    let dims = c.dims();
    for k in 0..c.level_count() {
        // The slab: the xy exemplar rebuilt from each pixel's first
        // candidate (mean of its three colours), and its crossbar error.
        let level = c.level(k);
        let cands = level.candidates(0);
        let mut slab = Vec::with_capacity(dims.len() * 3);
        let mut errs = Vec::with_capacity(dims.len());
        for px in 0..dims.len() as u32 {
            let t = cands.triples[cands.range(px).start];
            let col = solidtex::synth::correction::colour(&c, k, t);
            slab.extend(col.map(|v| v.round().clamp(0.0, 255.0) as u8));
            errs.push(c.crossbar_error(k, t));
        }
        write_png(
            &a.out.join(format!("slab_level{k}.png")),
            dims.w,
            dims.h,
            slab,
        )?;
        // The slab seen from the side: the x–z section through the middle
        // row, each of its N layers drawn 4 pixels tall.
        let n = c.params().neighbourhood as i64;
        let y0 = dims.h / 2;
        let h = 1i64 << k;
        let mut side = Vec::new();
        for row in 0..n * 4 {
            let dz = row / 4 - n / 2;
            for x in 0..dims.w {
                let px = y0 * dims.w + x;
                let t = cands.triples[cands.range(px).start];
                let t = solidtex::candidates::geometry::offset_triple(dims, t, [0, 0, dz], h);
                let col = solidtex::synth::correction::colour(&c, k, t);
                side.extend(col.map(|v| v.round().clamp(0.0, 255.0) as u8));
            }
        }
        write_png(
            &a.out.join(format!("slab_side_level{k}.png")),
            dims.w,
            (n * 4) as u32,
            side,
        )?;
        let max = errs.iter().cloned().fold(1e-6f32, f32::max);
        let heat: Vec<u8> = errs.iter().flat_map(|&e| heat(e / max)).collect();
        write_png(
            &a.out.join(format!("crossbar_error_level{k}.png")),
            dims.w,
            dims.h,
            heat,
        )?;
    }
    println!("wrote {} levels to {}", c.level_count(), a.out.display());
    Ok(())
}

fn heat(t: f32) -> [u8; 3] {
    let t = t.clamp(0.0, 1.0);
    let r = (t * 3.0).min(1.0);
    let g = (t * 3.0 - 1.0).clamp(0.0, 1.0);
    let b = (t * 3.0 - 2.0).clamp(0.0, 1.0);
    [(r * 255.0) as u8, (g * 255.0) as u8, (b * 255.0) as u8]
}

/// Most voxels `plan` follows exactly (the library's limit for exact
/// dependency chains).
const PLAN_MAX_VOXELS: u64 = 1 << 20;

/// The box `plan` counts, and how to name it.
fn plan_request(a: &PlanArgs) -> anyhow::Result<(Region, String)> {
    if let Some(r) = &a.region {
        let [x, y, z, w, h, d] = r[..] else {
            bail!("--region takes six numbers: X,Y,Z,W,H,D");
        };
        let size = [w, h, d].map(|s| u32::try_from(s).unwrap_or(0));
        if size.contains(&0) {
            bail!("--region sizes must be between 1 and {}", u32::MAX);
        }
        let what = format!("{w}×{h}×{d} box at ({x}, {y}, {z})");
        return Ok((
            Region {
                origin: [x, y, z],
                size,
            },
            what,
        ));
    }
    let (n, u, v) = a.axis.frame();
    let name = |i: usize| ["x", "y", "z"][i];
    let what = format!(
        "{}² {}-axis slice at {} = {} ({} from {}, {} from {})",
        a.slice,
        name(n),
        name(n),
        a.at,
        name(u),
        a.u0,
        name(v),
        a.v0
    );
    Ok((
        Region::slice(a.axis, a.at, a.u0, a.v0, a.slice, a.slice),
        what,
    ))
}

fn plan(a: &PlanArgs) -> anyhow::Result<()> {
    let mut rows = Vec::new();
    let mut by_neighbourhood = Vec::new();
    let (region, what) = plan_request(a)?;
    // Exact chains follow every voxel; a larger box gets the engine's
    // tile-level counts only.
    let voxels: u64 = region.size.iter().map(|&s| s as u64).product();
    let exact_too = voxels <= PLAN_MAX_VOXELS;
    if !exact_too && !a.neighbourhoods.is_empty() {
        bail!(
            "--neighbourhood counts exact chains: at most {PLAN_MAX_VOXELS} voxels, not {voxels}"
        );
    }
    let base = load_source(&a.src)?;
    let plane: Vec<[i64; 3]> = if exact_too {
        region.voxels().collect()
    } else {
        Vec::new()
    };
    for scheme in [Scheme::Standard, Scheme::DualGrid] {
        let params = SynthParams {
            scheme,
            ..base.params().clone()
        };
        let cands = Arc::new(Candidates::load(&base.candidates().to_bytes())?);
        let tex = Texture::new(cands, params, Arc::new(TileCache::new(1 << 20)))?;
        let slice = tex.plan(&region, a.src.lod)?;
        let chain = tex.dependency_chain(&[[0, 0, 0]], a.src.lod)?;
        let exact = exact_too
            .then(|| tex.dependency_chain(&plane, a.src.lod))
            .transpose()?;
        let mut other_n = Vec::new();
        for &n in &a.neighbourhoods {
            other_n.push((n, tex.dependency_chain_for(&plane, a.src.lod, n)?));
        }
        rows.push((scheme, slice, chain, exact));
        by_neighbourhood.push(other_n);
    }
    // Per extra N: (N, standard totals, dual-grid totals), each total
    // (voxels, corrections).
    let sums = |v: &[(u64, u64)]| v.iter().fold((0, 0), |a, l| (a.0 + l.0, a.1 + l.1));
    type Totals = (u64, u64);
    let other: Vec<(u32, Totals, Totals)> = a
        .neighbourhoods
        .iter()
        .enumerate()
        .map(|(i, &n)| {
            (
                n,
                sums(&by_neighbourhood[0][i].1),
                sums(&by_neighbourhood[1][i].1),
            )
        })
        .collect();
    let fewer = |s: u64, d: u64| 100.0 * (1.0 - d as f64 / s.max(1) as f64);
    if a.json {
        let v: Vec<serde_json::Value> = rows
            .iter()
            .map(|(scheme, slice, chain, exact)| {
                serde_json::json!({
                    "scheme": scheme,
                    "request": what,
                    "origin": region.origin,
                    "size": region.size,
                    "voxels_per_level": slice.voxels_per_level,
                    "corrections_per_level": slice.corrections_per_level,
                    "exact_per_level": exact.as_ref().map(|e| e.iter().map(|(v, c)| serde_json::json!({"voxels": v, "corrections": c})).collect::<Vec<_>>()),
                    "single_voxel_chain": chain.iter().map(|(v, c)| serde_json::json!({"voxels": v, "corrections": c})).collect::<Vec<_>>(),
                })
            })
            .collect();
        let other: Vec<serde_json::Value> = other
            .iter()
            .map(|(n, s, d)| {
                serde_json::json!({
                    "neighbourhood": n,
                    "standard": {"voxels": s.0, "corrections": s.1},
                    "dual_grid": {"voxels": d.0, "corrections": d.1},
                    "fewer_voxels_percent": fewer(s.0, d.0),
                    "fewer_corrections_percent": fewer(s.1, d.1),
                })
            })
            .collect();
        let out = serde_json::json!({ "schemes": v, "other_neighbourhoods": other });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    println!(
        "{what} at lod {} (level 0 = finest; what the engine computes from a cold cache), {} slices",
        a.src.lod,
        match base.params().slices {
            Slices::Sparse => "sparse (corrections read their direct neighbours)",
            Slices::Full => "full (corrections read N/2 voxels away)",
        }
    );
    println!(
        "{:<10} {:>5} {:>14} {:>14}",
        "scheme", "level", "voxels", "corrections"
    );
    for (scheme, slice, _, _) in &rows {
        for (k, (v, c)) in slice
            .voxels_per_level
            .iter()
            .zip(&slice.corrections_per_level)
            .enumerate()
        {
            println!("{:<10} {:>5} {:>14} {:>14}", format!("{scheme:?}"), k, v, c);
        }
        println!(
            "{:<10} {:>5} {:>14} {:>14}",
            format!("{scheme:?}"),
            "all",
            slice.voxels_per_level.iter().sum::<u64>(),
            slice.corrections_per_level.iter().sum::<u64>()
        );
    }
    let total = |i: usize| rows[i].1.voxels_per_level.iter().sum::<u64>() as f64;
    let corrections = |i: usize| rows[i].1.corrections_per_level.iter().sum::<u64>() as f64;
    println!(
        "dual grid computes {:.1} % fewer voxels and {:.1} % fewer corrections",
        100.0 * (1.0 - total(1) / total(0)),
        100.0 * (1.0 - corrections(1) / corrections(0))
    );
    if let (Some(standard), Some(dual)) = (&rows[0].3, &rows[1].3) {
        println!(
            "cross-check, the planner's exact dependency sets (history-window masks), voxels/corrections per level:"
        );
        for (scheme, exact) in [(Scheme::Standard, standard), (Scheme::DualGrid, dual)] {
            let per: Vec<String> = exact.iter().map(|(v, c)| format!("{v}/{c}")).collect();
            println!("  {:<10} {}", format!("{scheme:?}"), per.join(" "));
        }
        let total = |e: &[(u64, u64)]| e.iter().map(|c| c.0).sum::<u64>() as f64;
        println!(
            "dual grid needs {:.1} % fewer voxels (exact)",
            100.0 * (1.0 - total(dual) / total(standard))
        );
    } else {
        println!(
            "exact dependency sets not counted: {voxels} voxels, more than {PLAN_MAX_VOXELS} (the counts above are the engine's, tile by tile)"
        );
    }
    for (n, s, d) in &other {
        println!(
            "N = {n} (exact sets, geometry only): standard {}/{}, dual grid {}/{} voxels/corrections: {:.1} % fewer voxels, {:.1} % fewer corrections",
            s.0,
            s.1,
            d.0,
            d.1,
            fewer(s.0, d.0),
            fewer(s.1, d.1)
        );
    }
    println!("single-voxel exact dependency chain (history-window masks):");
    for (scheme, _, chain, _) in &rows {
        let v: u64 = chain.iter().map(|c| c.0).sum();
        let c: u64 = chain.iter().map(|c| c.1).sum();
        let per: Vec<String> = chain.iter().map(|(v, c)| format!("{v}/{c}")).collect();
        println!(
            "  {:<10} {v} voxels, {c} corrections (per level voxels/corrections: {})",
            format!("{scheme:?}"),
            per.join(" ")
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

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
