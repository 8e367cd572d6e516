//! `solidtex plan`: voxels and corrections per level for a slice or box,
//! under the standard and dual-grid schemes, and the single-voxel chain.

use super::source::{SourceArgs, load_source};
use anyhow::bail;
use clap::Args;
use solidtex_core::{Axis, Region, Request, Scheme, SynthParams, Texture, TileCache};
use std::sync::Arc;

#[derive(Args)]
pub struct PlanArgs {
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

/// Voxels and corrections, per level.
type PerLevel = Vec<(u64, u64)>;

/// What `plan` counts under one scheme.
struct Counts {
    scheme: Scheme,
    /// The engine's tile-level counts for the request, from a cold cache.
    tiles: solidtex_core::SynthStats,
    /// The exact dependency chain of the single voxel at the origin.
    chain: PerLevel,
    /// The request's exact dependency set, when it is small enough.
    exact: Option<PerLevel>,
    /// Exact sets for the extra neighbourhood sides asked for.
    other_n: Vec<(u32, PerLevel)>,
}

/// Runs `solidtex plan`.
pub fn run(a: &PlanArgs) -> anyhow::Result<()> {
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
    let points: Vec<[i64; 3]> = if exact_too {
        region.voxels().collect()
    } else {
        Vec::new()
    };
    let rows = [Scheme::Standard, Scheme::DualGrid]
        .into_iter()
        .map(|scheme| count(&base, scheme, &region, exact_too.then_some(&points[..]), a))
        .collect::<anyhow::Result<Vec<_>>>()?;
    if a.json {
        print_json(&rows, &region, &what, a)
    } else {
        print_table(&rows, &what, voxels, a)?;
        Ok(())
    }
}

fn count(
    base: &Texture,
    scheme: Scheme,
    region: &Region,
    points: Option<&[[i64; 3]]>,
    a: &PlanArgs,
) -> anyhow::Result<Counts> {
    let params = SynthParams {
        scheme,
        ..base.params().clone()
    };
    let tex = base.with_params(params, Arc::new(TileCache::new(1 << 20)))?;
    let lod = a.src.lod;
    let mut other_n = Vec::new();
    for &n in &a.neighbourhoods {
        let points = points.unwrap_or_default();
        other_n.push((n, tex.dependency_chain(points, lod, Some(n))?));
    }
    Ok(Counts {
        scheme,
        tiles: tex.plan(&Request::region(*region)?, lod)?,
        chain: tex.dependency_chain(&[[0, 0, 0]], lod, None)?,
        exact: points
            .map(|p| tex.dependency_chain(p, lod, None))
            .transpose()?,
        other_n,
    })
}

/// Sums of voxels and corrections over the levels.
fn totals(v: &[(u64, u64)]) -> (u64, u64) {
    v.iter().fold((0, 0), |a, l| (a.0 + l.0, a.1 + l.1))
}

/// How many per cent fewer `d` is than `s`.
fn fewer(s: u64, d: u64) -> f64 {
    100.0 * (1.0 - d as f64 / s.max(1) as f64)
}

fn print_json(rows: &[Counts], region: &Region, what: &str, a: &PlanArgs) -> anyhow::Result<()> {
    let per_level = |v: &PerLevel| {
        v.iter()
            .map(|(v, c)| serde_json::json!({"voxels": v, "corrections": c}))
            .collect::<Vec<_>>()
    };
    let schemes: Vec<serde_json::Value> = rows
        .iter()
        .map(|r| {
            serde_json::json!({
                "scheme": r.scheme,
                "request": what,
                "origin": region.origin,
                "size": region.size,
                "voxels_per_level": r.tiles.voxels_per_level,
                "corrections_per_level": r.tiles.corrections_per_level,
                "exact_per_level": r.exact.as_ref().map(per_level),
                "single_voxel_chain": per_level(&r.chain),
            })
        })
        .collect();
    let other: Vec<serde_json::Value> = a
        .neighbourhoods
        .iter()
        .enumerate()
        .map(|(i, n)| {
            let (s, d) = (totals(&rows[0].other_n[i].1), totals(&rows[1].other_n[i].1));
            serde_json::json!({
                "neighbourhood": n,
                "standard": {"voxels": s.0, "corrections": s.1},
                "dual_grid": {"voxels": d.0, "corrections": d.1},
                "fewer_voxels_percent": fewer(s.0, d.0),
                "fewer_corrections_percent": fewer(s.1, d.1),
            })
        })
        .collect();
    let out = serde_json::json!({ "schemes": schemes, "other_neighbourhoods": other });
    outln!("{}", serde_json::to_string_pretty(&out)?)?;
    Ok(())
}

fn print_table(rows: &[Counts], what: &str, voxels: u64, a: &PlanArgs) -> std::io::Result<()> {
    outln!(
        "{what} at lod {} (level 0 = finest; what the engine computes from a cold cache; \
         corrections read their direct neighbours)",
        a.src.lod,
    )?;
    outln!(
        "{:<10} {:>5} {:>14} {:>14}",
        "scheme",
        "level",
        "voxels",
        "corrections"
    )?;
    for r in rows {
        let name = format!("{:?}", r.scheme);
        let t = &r.tiles;
        for (k, (v, c)) in t
            .voxels_per_level
            .iter()
            .zip(&t.corrections_per_level)
            .enumerate()
        {
            outln!("{name:<10} {k:>5} {v:>14} {c:>14}")?;
        }
        let v: u64 = t.voxels_per_level.iter().sum();
        let c: u64 = t.corrections_per_level.iter().sum();
        outln!("{name:<10} {:>5} {v:>14} {c:>14}", "all")?;
    }
    let total = |i: usize| rows[i].tiles.voxels_per_level.iter().sum::<u64>();
    let corrections = |i: usize| rows[i].tiles.corrections_per_level.iter().sum::<u64>();
    outln!(
        "dual grid computes {:.1} % fewer voxels and {:.1} % fewer corrections",
        fewer(total(0), total(1)),
        fewer(corrections(0), corrections(1))
    )?;
    if let (Some(standard), Some(dual)) = (&rows[0].exact, &rows[1].exact) {
        outln!(
            "cross-check, the planner's exact dependency sets (history-window masks), voxels/corrections per level:"
        )?;
        for r in rows {
            let per: Vec<String> = r
                .exact
                .iter()
                .flatten()
                .map(|(v, c)| format!("{v}/{c}"))
                .collect();
            outln!("  {:<10} {}", format!("{:?}", r.scheme), per.join(" "))?;
        }
        outln!(
            "dual grid needs {:.1} % fewer voxels (exact)",
            fewer(totals(standard).0, totals(dual).0)
        )?;
    } else {
        outln!(
            "exact dependency sets not counted: {voxels} voxels, more than {PLAN_MAX_VOXELS} (the counts above are the engine's, tile by tile)"
        )?;
    }
    for (i, n) in a.neighbourhoods.iter().enumerate() {
        let (s, d) = (totals(&rows[0].other_n[i].1), totals(&rows[1].other_n[i].1));
        outln!(
            "N = {n} (exact sets, geometry only): standard {}/{}, dual grid {}/{} voxels/corrections: {:.1} % fewer voxels, {:.1} % fewer corrections",
            s.0,
            s.1,
            d.0,
            d.1,
            fewer(s.0, d.0),
            fewer(s.1, d.1)
        )?;
    }
    outln!("single-voxel exact dependency chain (history-window masks):")?;
    for r in rows {
        let (v, c) = totals(&r.chain);
        let per: Vec<String> = r.chain.iter().map(|(v, c)| format!("{v}/{c}")).collect();
        outln!(
            "  {:<10} {v} voxels, {c} corrections (per level voxels/corrections: {})",
            format!("{:?}", r.scheme),
            per.join(" ")
        )?;
    }
    Ok(())
}
