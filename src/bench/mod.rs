//! `solidtex bench`: wall-clock and memory measurements of the engine on
//! the shared exemplars, the dependency sets of both correction schemes,
//! and optionally the service under load; printed as a table, as JSON or
//! as the `BENCHMARKS.md` page.
//!
//! - [`machine`]: what the numbers were measured on.
//! - [`markdown`]: the `BENCHMARKS.md` page, next to the papers' figures.
//! - [`service`]: a server in this process measured by `solidtex loadtest`.
//!
//! "Cold" runs use a fresh tile cache; "warm" ones repeat a request on the
//! texture that just served it. Times are medians. A cold request whose
//! plan predicts more than `--max-seconds` is skipped and says so, so a
//! slow engine never makes the suite run for hours.

pub mod machine;
pub mod markdown;
pub mod meshes;
pub mod service;
pub mod structure;

use anyhow::Context;
use serde::Serialize;
use solidtex_core::{
    AnalysisParams, Axis, Candidates, Curve, CutPlane, Exemplar, ExemplarSet, Field, Filter,
    Region, Request, Scheme, Sketch, SynthParams, SynthStats, Texture, TileCache, Window,
};
use solidtex_server::peak_alloc;
use std::collections::HashMap;
use std::collections::hash_map::Entry;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

/// What to measure.
#[derive(Clone, Debug)]
pub struct Options {
    /// Directory of exemplar PNGs.
    pub exemplars: PathBuf,
    /// Small sizes only (seconds), for CI.
    pub quick: bool,
    /// Skip a cold request whose plan predicts more seconds than this.
    pub max_seconds: f64,
    /// Also measure the service under load (see [`service`]).
    pub load: Option<service::LoadOptions>,
    /// Only one section's rows.
    pub only: Option<Only>,
}

/// A section measured alone.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Only {
    /// The mesh rows (see [`meshes`]).
    Meshes,
    /// The structure rows (see [`structure`]).
    Structure,
}

/// One measurement.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    /// What was measured.
    pub name: String,
    /// Median seconds; `None` when skipped.
    pub seconds: Option<f64>,
    /// Runs the median is over.
    pub runs: usize,
    /// Most heap bytes in use at once during a run, above what was in use
    /// before it.
    pub peak_bytes: Option<u64>,
    /// The target on a 2-core machine, where there is one.
    pub target: Option<&'static str>,
    /// The papers' figure for the same measurement, where there is one.
    pub paper: Option<&'static str>,
    /// Sizes, counts, or why it was skipped.
    pub detail: String,
}

/// Voxels and corrections per level (finest first) of one request under
/// one correction scheme.
#[derive(Clone, Debug, Serialize)]
pub struct PlanRow {
    /// `standard` or `dual-grid`.
    pub scheme: &'static str,
    /// The request.
    pub request: String,
    /// Voxels produced per level.
    pub voxels_per_level: Vec<u64>,
    /// Corrections per level.
    pub corrections_per_level: Vec<u64>,
}

impl PlanRow {
    /// A row from per-level (voxels, corrections) pairs.
    fn from_chain(scheme: &'static str, request: String, chain: &[(u64, u64)]) -> PlanRow {
        PlanRow {
            scheme,
            request,
            voxels_per_level: chain.iter().map(|l| l.0).collect(),
            corrections_per_level: chain.iter().map(|l| l.1).collect(),
        }
    }
}

/// Everything one run of the suite measured.
#[derive(Clone, Debug, Serialize)]
pub struct Results {
    /// Whether this was the short CI mode.
    pub quick: bool,
    /// The exemplar synthesis was measured on.
    pub synthesis_exemplar: String,
    /// Pyramid levels analysed.
    pub levels: u32,
    /// Engine measurements.
    pub rows: Vec<Row>,
    /// Dependency sets of both schemes.
    pub plans: Vec<PlanRow>,
    /// The service under load, when measured.
    pub load: Vec<service::LoadRow>,
}

/// The Dong et al. 2008 and Zhang et al. 2011 figures quoted next to ours.
mod paper {
    pub const VOLUME_64: &str = "Dong 2008: 220 ms (GeForce 8800 Ultra)";
    pub const VOLUME_128: &str = "Dong 2008: 1.7 s (GeForce 8800 Ultra)";
    pub const CUT_256: &str =
        "Dong 2008: 8 ms per 256² cut (GPU); Zhang 2011: new cut in 10–20 s (8 CPU cores)";
    pub const CUT_MEMORY: &str = "Dong 2008: 14.4 MB per 256² cut";
}

/// A median time, the largest peak of its runs and the last result.
struct Measured<T> {
    seconds: f64,
    peak_bytes: u64,
    value: T,
}

fn measure<T>(runs: usize, mut f: impl FnMut() -> T) -> Measured<T> {
    let mut times = Vec::with_capacity(runs);
    let mut peak = 0;
    let mut last = None;
    for _ in 0..runs.max(1) {
        drop(last.take());
        let baseline = peak_alloc::reset();
        let t0 = Instant::now();
        let v = f();
        times.push(t0.elapsed().as_secs_f64());
        peak = peak.max(peak_alloc::peak_above(baseline));
        last = Some(v);
    }
    times.sort_by(|a, b| a.total_cmp(b));
    Measured {
        seconds: times[times.len() / 2],
        peak_bytes: peak,
        value: last.expect("at least one run"),
    }
}

/// The one-minute load average (`/proc/loadavg`), or "unknown": on a
/// shared machine it says how far to trust a time.
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|l| l.split_whitespace().next().map(str::to_string))
        .unwrap_or_else(|| "unknown".into())
}

fn texture(c: &Arc<Candidates>, scheme: Scheme) -> Texture {
    texture_with(
        c,
        SynthParams {
            scheme,
            ..SynthParams::default()
        },
    )
}

fn texture_with(c: &Arc<Candidates>, params: SynthParams) -> Texture {
    Texture::new(c.clone(), params, Arc::new(TileCache::new(2 << 30))).expect("valid params")
}

fn total(v: &[u64]) -> u64 {
    v.iter().sum()
}

/// Engine throughput learnt from the cold runs so far, used to predict
/// whether the next cold request fits in `--max-seconds`.
struct Predictor {
    corrections_per_s: f64,
    max_seconds: f64,
}

impl Predictor {
    fn learn(&mut self, stats: &SynthStats, seconds: f64) {
        let c = total(&stats.corrections_per_level) as f64;
        if c > 10_000.0 && seconds > 0.0 {
            self.corrections_per_s = c / seconds;
        }
    }

    /// Why a request of `corrections` would be skipped, if it would.
    fn too_slow(&self, corrections: u64) -> Option<String> {
        let est = corrections as f64 / self.corrections_per_s;
        (est > self.max_seconds).then(|| {
            format!(
                "skipped: its plan needs {corrections} corrections, about {est:.0} s at the \
                 measured {:.0} corrections/s (over --max-seconds {})",
                self.corrections_per_s, self.max_seconds
            )
        })
    }
}

/// Thread time per correction, the engine's unit of cost (corrections are
/// most of a cold request): "; 3.1 µs·thread each" on the pool's threads.
fn per_correction(stats: &SynthStats, seconds: f64) -> String {
    let c = total(&stats.corrections_per_level);
    if c < 1000 {
        return String::new();
    }
    let threads = rayon::current_num_threads() as f64;
    format!("; {:.1} µs·thread each", seconds * threads * 1e6 / c as f64)
}

/// The suite's sizes: tiny in quick mode, the in full mode.
struct Sizes {
    /// Pyramid levels analysed (fewer levels: shorter dependency chains).
    levels: u32,
    precompute: &'static [&'static str],
    synthesis: &'static str,
    volumes: &'static [u32],
    sides: &'static [u32],
    brick: u32,
    plan_side: u32,
    warm_runs: usize,
    /// Resolutions of the mesh bakes.
    mesh_resolutions: &'static [u32],
}

const QUICK: Sizes = Sizes {
    levels: 2,
    precompute: &["animal_leather.png"],
    synthesis: "animal_leather.png",
    volumes: &[8, 16],
    sides: &[16, 32],
    brick: 8,
    plan_side: 32,
    warm_runs: 2,
    mesh_resolutions: &[32],
};

const FULL: Sizes = Sizes {
    levels: 4,
    // One exemplar of each size in the shared set.
    precompute: &[
        "animal_leather.png",
        "stone_brick.png",
        "stone_ground1.png",
        "stone_pink_marble.png",
        "stone_stone33.png",
    ],
    // 128², like the bundled exemplar and the papers' exemplars.
    synthesis: "stone_pink_marble.png",
    volumes: &[64, 128],
    sides: &[256, 512],
    brick: 64,
    plan_side: 256,
    warm_runs: 3,
    mesh_resolutions: &[256, 512, 1024],
};

/// Runs the suite.
pub fn run(opts: &Options) -> anyhow::Result<Results> {
    peak_alloc::start();
    let sizes = if opts.quick { &QUICK } else { &FULL };
    let mut rows = Vec::new();
    let mut synthesis = None;
    for name in sizes.precompute {
        if opts.only.is_some() && *name != sizes.synthesis {
            continue;
        }
        let path = opts.exemplars.join(name);
        let e = Exemplar::open(&path).with_context(|| {
            format!(
                "reading exemplar {} (give the exemplar folder with --exemplars)",
                path.display()
            )
        })?;
        let size = format!("{}×{}", e.width(), e.height());
        let set = ExemplarSet::single(e);
        let params = AnalysisParams {
            levels: sizes.levels,
            ..AnalysisParams::default()
        };
        let m = measure(1, || Candidates::compute(&set, &params, &|_, _| {}));
        let c = m.value?;
        let (compact, memory) = c.memory_bytes();
        rows.push(Row {
            name: format!("precompute {size} ({name}, {} levels)", sizes.levels),
            seconds: Some(m.seconds),
            runs: 1,
            peak_bytes: Some(m.peak_bytes),
            target: (size == "128×128").then_some("≤ 3 s"),
            paper: None,
            detail: format!(
                ".stx {} KiB; candidates {} KiB compact, {} KiB in memory",
                c.to_bytes().len() >> 10,
                compact >> 10,
                memory >> 10
            ),
        });
        if *name == sizes.synthesis {
            synthesis = Some((set, Arc::new(c)));
        }
    }
    let (set, c) = synthesis.expect("the synthesis exemplar is among the precomputed");
    let mut predictor = Predictor {
        corrections_per_s: 200_000.0,
        max_seconds: opts.max_seconds,
    };
    let mut plans_made = Vec::new();
    if opts.only.is_none() {
        plans_made = plans(&c, sizes.plan_side)?;
        synthesis_rows(&c, sizes, &mut predictor, &mut rows)?;
        preview_rows(&c, sizes, &mut predictor, &mut rows)?;
        field_rows(&c, sizes, &mut predictor, &mut rows)?;
    }
    if opts.only != Some(Only::Structure) {
        meshes::rows(&c, sizes.mesh_resolutions, &mut rows)?;
    }
    // Minutes of precompute and reference: left out of the quick run.
    if !opts.quick && opts.only != Some(Only::Meshes) {
        structure::rows(&set, &c, sizes.levels, &mut predictor, &mut rows)?;
    }
    let plans = plans_made;
    let load = match &opts.load {
        Some(l) => service::measure(&opts.exemplars.join(sizes.synthesis), sizes.levels, l)?,
        None => Vec::new(),
    };
    Ok(Results {
        quick: opts.quick,
        synthesis_exemplar: sizes.synthesis.to_string(),
        levels: sizes.levels,
        rows,
        plans,
        load,
    })
}

/// Dependency sets of an axis slice and of a single voxel, both schemes.
fn plans(c: &Arc<Candidates>, side: u32) -> anyhow::Result<Vec<PlanRow>> {
    let mut out = Vec::new();
    for (scheme, name) in [
        (Scheme::Standard, "standard"),
        (Scheme::DualGrid, "dual-grid"),
    ] {
        let tex = texture(c, scheme);
        let z0 = [Region::slice(Axis::Z, 0, 0, 0, side, side)];
        let p = tex.plan(&Request::region(z0[0])?, 0)?;
        out.push(PlanRow {
            scheme: name,
            request: format!("{side}² axis slice (4³ tiles, cold cache)"),
            voxels_per_level: p.voxels_per_level,
            corrections_per_level: p.corrections_per_level,
        });
        out.push(PlanRow::from_chain(
            name,
            "single voxel (exact dependency chain)".into(),
            &tex.dependency_chain(&[[0, 0, 0]], 0, None)?,
        ));
        // Zhang et al. measured their dual grid at N = 9, where the
        // standard chain is much thicker; the chains are geometry only.
        // Full slices read N/2 = 2 voxels away (the N = 5 setting)
        // and 4 at N = 9, Zhang et al.'s; both papers correct every level,
        // the finest included, with P = 2 passes.
        for n in [5, 9] {
            out.push(PlanRow::from_chain(
                name,
                format!(
                    "{side}² axis slice, full slices at N = {n}, P = 2 at every level (exact chain, geometry only)"
                ),
                &full_slice_chain(c, scheme, 12, n, &z0)?,
            ));
        }
        // Where a slice lies changes its chain: with subpasses, a voxel of
        // a later class reads its neighbours' new values, and which axis
        // and parity come later depends on the class order. The slice at
        // z = 0 above is one of the cheapest for the standard scheme.
        // The smallest cell the parameters accept (M = 4) against the
        // default 12 at N = 5: M = 10–15 suits Zhang et al.'s N = 9.
        let six: Vec<Region> = [Axis::X, Axis::Y, Axis::Z]
            .into_iter()
            .flat_map(|axis| [4, 5].map(|at| Region::slice(axis, at, 0, 0, side, side)))
            .collect();
        let mut counted = HashMap::new();
        for (n, grid) in [(5, 12), (5, 4), (9, 12)] {
            // The cell only matters to the dual grid.
            let key = (n, if scheme == Scheme::DualGrid { grid } else { 0 });
            let chain = match counted.entry(key) {
                Entry::Occupied(known) => known.into_mut(),
                Entry::Vacant(slot) => slot.insert(full_slice_chain(c, scheme, grid, n, &six)?),
            };
            out.push(PlanRow::from_chain(
                name,
                format!(
                    "six {side}² axis slices (x, y and z at 4 and 5, summed), full slices at N = {n}, P = 2 at every level, dual-grid cell M = {grid} (exact chain, geometry only)"
                ),
                chain,
            ));
        }
    }
    Ok(out)
}

/// Exact chains of every voxel of `slices` with full N×N slices and two
/// passes at every level, summed per level: (voxels, corrections).
fn full_slice_chain(
    c: &Arc<Candidates>,
    scheme: Scheme,
    grid: u32,
    n: u32,
    slices: &[Region],
) -> anyhow::Result<Vec<(u64, u64)>> {
    let tex = Texture::new(
        c.clone(),
        SynthParams {
            scheme,
            finest_passes: 2,
            parity_levels: 0,
            grid,
            ..SynthParams::default()
        },
        Arc::new(TileCache::new(1 << 20)),
    )?;
    let mut sum = Vec::<(u64, u64)>::new();
    for slice in slices {
        let voxels: Vec<[i64; 3]> = slice.voxels().collect();
        let chain = tex.dependency_chain(&voxels, 0, Some(n))?;
        sum.resize(chain.len(), (0, 0));
        for (s, l) in sum.iter_mut().zip(&chain) {
            *s = (s.0 + l.0, s.1 + l.1);
        }
    }
    Ok(sum)
}

/// A row for a cold request, or a skipped row when its plan is too big.
#[allow(clippy::too_many_arguments)]
fn cold_row<T>(
    name: String,
    plan: Option<&SynthStats>,
    predictor: &mut Predictor,
    target: Option<&'static str>,
    paper: Option<&'static str>,
    run: impl FnOnce() -> anyhow::Result<(T, SynthStats)>,
) -> anyhow::Result<Row> {
    if let Some(why) = plan.and_then(|p| predictor.too_slow(total(&p.corrections_per_level))) {
        return Ok(Row {
            name,
            seconds: None,
            runs: 0,
            peak_bytes: None,
            target,
            paper,
            detail: why,
        });
    }
    let mut run = Some(run);
    let m = measure(1, || (run.take().expect("one run"))());
    let (_, stats) = m.value?;
    predictor.learn(&stats, m.seconds);
    Ok(Row {
        name,
        seconds: Some(m.seconds),
        runs: 1,
        peak_bytes: Some(m.peak_bytes),
        target,
        paper,
        detail: format!(
            "{} voxels, {} corrections, {} tiles{}",
            total(&stats.voxels_per_level),
            total(&stats.corrections_per_level),
            stats.tiles_computed,
            per_correction(&stats, m.seconds)
        ),
    })
}

fn warm_row(
    name: String,
    runs: usize,
    target: Option<&'static str>,
    run: impl FnMut() -> solidtex_core::Result<(Vec<u8>, SynthStats)>,
) -> anyhow::Result<Row> {
    let m = measure(runs, run);
    let (bytes, stats) = m.value?;
    Ok(Row {
        name,
        seconds: Some(m.seconds),
        runs,
        peak_bytes: Some(m.peak_bytes),
        target,
        paper: None,
        detail: format!(
            "{} bytes out; {} tiles from the cache, {} computed",
            bytes.len(),
            stats.tiles_from_cache,
            stats.tiles_computed
        ),
    })
}

fn synthesis_rows(
    c: &Arc<Candidates>,
    sizes: &Sizes,
    predictor: &mut Predictor,
    rows: &mut Vec<Row>,
) -> anyhow::Result<()> {
    let far = [12_345, -678, 91_011];
    // The single voxel calibrates the predictor: a small, exact chain.
    let tex = texture(c, Scheme::DualGrid);
    rows.push(cold_row(
        "single voxel, cold (dependency chain)".into(),
        None,
        predictor,
        None,
        None,
        || Ok(tex.render(&Request::points([far].to_vec())?, 0)?),
    )?);

    let tex = texture(c, Scheme::DualGrid);
    let b = sizes.brick;
    let brick = Region {
        origin: [640, -320, 128],
        size: [b; 3],
    };
    let target = (b == 64).then_some("≤ 150 ms");
    rows.push(cold_row(
        format!("brick {b}³ cold"),
        Some(&tex.plan(&Request::region(brick)?, 0)?),
        predictor,
        target,
        None,
        || Ok(tex.render(&Request::region(brick)?, 0)?),
    )?);
    if rows.last().is_some_and(|r| r.seconds.is_some()) {
        rows.push(warm_row(
            format!("brick {b}³ warm"),
            sizes.warm_runs,
            None,
            || tex.render(&Request::region(brick)?, 0),
        )?);
    }

    for &n in sizes.volumes {
        let tex = texture(c, Scheme::DualGrid);
        let cube = Region {
            origin: [0, 0, 0],
            size: [n; 3],
        };
        let (target, paper) = match n {
            64 => (None, Some(paper::VOLUME_64)),
            128 => (Some("≤ 1.5 s"), Some(paper::VOLUME_128)),
            _ => (None, None),
        };
        rows.push(cold_row(
            format!("full volume {n}³ cold"),
            Some(&tex.plan(&Request::region(cube)?, 0)?),
            predictor,
            target,
            paper,
            || Ok(tex.render(&Request::region(cube)?, 0)?),
        )?);
    }

    for &side in sizes.sides {
        let is_256 = side == 256;
        let tex = texture(c, Scheme::DualGrid);
        let slice = Region {
            origin: [0, 0, 5],
            size: [side, side, 1],
        };
        let plan = tex.plan(&Request::region(slice)?, 0)?;
        let cold = cold_row(
            format!("axis slice {side}² cold"),
            Some(&plan),
            predictor,
            is_256.then_some("≤ 200 ms"),
            is_256.then_some(paper::CUT_256),
            || {
                Ok(tex.render(
                    &Request::slice(Axis::Z, 5, Window::new(0, 0, side, side))?,
                    0,
                )?)
            },
        )?;
        let measured = cold.seconds.is_some();
        rows.push(cold);
        if measured {
            rows.push(warm_row(
                format!("axis slice {side}² warm"),
                sizes.warm_runs,
                is_256.then_some("≤ 10 ms"),
                || {
                    tex.render(
                        &Request::slice(Axis::Z, 5, Window::new(0, 0, side, side))?,
                        0,
                    )
                },
            )?);
        }
        // Chains grow differently along each axis (the subpass order), so
        // the other two axes get cold rows of their own.
        for (axis, name, origin, size) in [
            (Axis::X, "x", [5, 0, 0], [1, side, side]),
            (Axis::Y, "y", [0, 5, 0], [side, 1, side]),
        ] {
            let tex = texture(c, Scheme::DualGrid);
            let region = Region { origin, size };
            rows.push(cold_row(
                format!("axis slice {side}² cold, {name} axis"),
                Some(&tex.plan(&Request::region(region)?, 0)?),
                predictor,
                is_256.then_some("≤ 200 ms"),
                None,
                || Ok(tex.render(&Request::slice(axis, 5, Window::new(0, 0, side, side))?, 0)?),
            )?);
        }
        // A cut has no plan of its own; its dependency set is about that
        // of an axis slice of the same side, so the slice's plan decides.
        let plane = CutPlane {
            origin: [0.0, 0.0, 0.0],
            u: [0.8, 0.6, 0.0],
            v: [0.0, 0.6, 0.8],
            width: side,
            height: side,
        };
        let tex = texture(c, Scheme::DualGrid);
        let cold = cold_row(
            format!("oblique cut {side}² cold"),
            Some(&plan),
            predictor,
            None,
            is_256.then_some(paper::CUT_MEMORY),
            || Ok(tex.render(&Request::cut(plane, Filter::Nearest)?, 0)?),
        )?;
        let measured = cold.seconds.is_some();
        rows.push(cold);
        if measured {
            rows.push(warm_row(
                format!("oblique cut {side}² warm"),
                sizes.warm_runs,
                None,
                || tex.render(&Request::cut(plane, Filter::Nearest)?, 0),
            )?);
        }
    }
    Ok(())
}

/// The targeted requests again with [`SynthParams::preview`]: what the
/// speed targets cost in quality (docs/quality.md weighs it).
fn preview_rows(
    c: &Arc<Candidates>,
    sizes: &Sizes,
    predictor: &mut Predictor,
    rows: &mut Vec<Row>,
) -> anyhow::Result<()> {
    let side = sizes.sides[0];
    let b = sizes.brick;
    let n = *sizes.volumes.last().expect("a volume size");
    let target = |full: bool, t: &'static str| full.then_some(t);
    let requests = [
        (
            format!("preview: axis slice {side}² cold"),
            Region::slice(Axis::Z, 5, 0, 0, side, side),
            target(side == 256, "≤ 200 ms"),
        ),
        (
            format!("preview: axis slice {side}² cold, x axis"),
            Region::slice(Axis::X, 5, 0, 0, side, side),
            target(side == 256, "≤ 200 ms"),
        ),
        (
            format!("preview: axis slice {side}² cold, y axis"),
            Region::slice(Axis::Y, 5, 0, 0, side, side),
            target(side == 256, "≤ 200 ms"),
        ),
        (
            format!("preview: brick {b}³ cold"),
            Region {
                origin: [640, -320, 128],
                size: [b; 3],
            },
            target(b == 64, "≤ 150 ms"),
        ),
        (
            format!("preview: full volume {n}³ cold"),
            Region {
                origin: [0, 0, 0],
                size: [n; 3],
            },
            target(n == 128, "≤ 1.5 s"),
        ),
    ];
    for (name, region, target) in requests {
        let tex = texture_with(c, SynthParams::preview());
        rows.push(cold_row(
            name,
            Some(&tex.plan(&Request::region(region)?, 0)?),
            predictor,
            target,
            None,
            || Ok(tex.render(&Request::region(region)?, 0)?),
        )?);
    }
    Ok(())
}

/// Ten curves winding through a 240-voxel box: the sketch whose solve is
/// timed.
fn ten_curves() -> Field {
    let curves: Vec<Curve> = (0..10)
        .map(|c| {
            let c = c as f64;
            Curve {
                points: (0..40)
                    .map(|i| {
                        let t = i as f64 / 39.0;
                        [
                            5.0 + 240.0 * t,
                            20.0 * c + 30.0 * (6.0 * t + c).sin(),
                            20.0 * c + 15.0 * t,
                        ]
                    })
                    .collect(),
                normal: [0.1 * c, 0.3, 1.0],
                along: Default::default(),
            }
        })
        .collect();
    Field::Sketch(Sketch {
        curves,
        margin: None,
        spacing: None,
    })
}

/// Fields of local frames: what reading the field costs a cold slice
/// (its neighbourhoods reach the corners, and each voxel's frame is
/// worked out), and the sketch solve that creating such a texture does.
fn field_rows(
    c: &Arc<Candidates>,
    sizes: &Sizes,
    predictor: &mut Predictor,
    rows: &mut Vec<Row>,
) -> anyhow::Result<()> {
    let side = sizes.sides[0];
    let sketch = ten_curves();
    let m = measure(3, || {
        texture_with(
            c,
            SynthParams {
                field: Some(sketch.clone()),
                ..SynthParams::default()
            },
        )
    });
    rows.push(Row {
        name: "sketch field solve, 10 curves of 40 points".into(),
        seconds: Some(m.seconds),
        runs: 3,
        peak_bytes: Some(m.peak_bytes),
        target: None,
        paper: None,
        detail: "creating the texture: curve frames interpolated over the grid".into(),
    });
    let slice = Region::slice(Axis::Z, 5, 0, 0, side, side);
    for (name, field) in [
        ("slant 30°", Field::Slant { angle: 30.0 }),
        (
            "circular",
            Field::Circular {
                centre: [side as f64 / 2.0, side as f64 / 2.0, 0.0],
                axis: [0.0, 0.0, 1.0],
            },
        ),
        ("sketch of 10 curves", sketch),
    ] {
        let tex = texture_with(
            c,
            SynthParams {
                field: Some(field),
                ..SynthParams::default()
            },
        );
        rows.push(cold_row(
            format!("field {name}: axis slice {side}² cold"),
            Some(&tex.plan(&Request::region(slice)?, 0)?),
            predictor,
            (side == 256).then_some("≤ 2× unguided"),
            None,
            || Ok(tex.render(&Request::region(slice)?, 0)?),
        )?);
    }
    Ok(())
}

fn human_bytes(b: u64) -> String {
    if b >= 10 << 20 {
        format!("{:.0} MiB", b as f64 / (1u64 << 20) as f64)
    } else {
        format!("{:.1} MiB", b as f64 / (1u64 << 20) as f64)
    }
}

fn human_seconds(s: f64) -> String {
    if s < 1.0 {
        format!("{:.1} ms", s * 1000.0)
    } else {
        format!("{s:.2} s")
    }
}

/// Prints the results as aligned tables.
pub fn print(r: &Results) -> std::io::Result<()> {
    outln!("synthesis exemplar: {}", r.synthesis_exemplar)?;
    outln!(
        "{:<44} {:>10} {:>10}  detail",
        "benchmark",
        "time",
        "peak heap"
    )?;
    for row in &r.rows {
        outln!(
            "{:<44} {:>10} {:>10}  {}",
            row.name,
            row.seconds.map_or("-".into(), human_seconds),
            row.peak_bytes.map_or("-".into(), human_bytes),
            row.detail
        )?;
    }
    if !r.plans.is_empty() {
        outln!("\nvoxels/corrections per level (finest first):")?;
    }
    for p in &r.plans {
        outln!(
            "  {:<10} {:<40} {}",
            p.scheme,
            p.request,
            markdown::per_level(p)
        )?;
    }
    if !r.load.is_empty() {
        outln!()?;
        out!("{}", service::table(&r.load))?;
    }
    Ok(())
}
