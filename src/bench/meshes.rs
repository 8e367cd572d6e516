//! Shell efficiency: a mesh of about 100 K triangles baked cold at growing
//! resolutions. Only the voxels its surface samples and their dependency
//! chains are synthesized (Dong et al. 2008: a gargoyle at the equivalent
//! of 1024³ with 0.42 % of the voxels); the rows give that share of R³
//! at the finest level and over all levels, the wall time and the peak
//! memory. Then the knot fractured by two planes: the cut alone (welding,
//! splitting, chaining and capping), and its pieces baked cold.

use super::{Row, load_average, measure, texture};
use solidtex_core::mesh::{Bake, BakeOptions, Mesh, Plane};
use solidtex_core::{Candidates, Request, Scheme};
use std::f64::consts::TAU;
use std::sync::Arc;

/// Rows of this module are named so, and the page gives them a section.
pub const ROW_PREFIX: &str = "mesh bake";

/// The papers' figure for the same measurement.
const PAPER: &str = "Dong 2008: 0.42 % of 1024³, 5.4 s, 17.9 MB (GPU); statues 4.1–17 s";

/// A (2, 3) torus knot tube of `rings` × `sides` quads (2·rings·sides
/// triangles), a closed surface that turns through every direction.
pub fn knot(rings: usize, sides: usize) -> Mesh {
    let curve = |t: f64| {
        let (p, q) = (2.0, 3.0);
        let r = 1.0 + 0.4 * (q * t).cos();
        [r * (p * t).cos(), r * (p * t).sin(), 0.4 * (q * t).sin()]
    };
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let unit = |a: [f64; 3]| {
        let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
        a.map(|c| c / n)
    };
    let mut positions = Vec::with_capacity(rings * sides);
    for i in 0..rings {
        let t = TAU * i as f64 / rings as f64;
        let (c, ahead) = (curve(t), curve(t + 1e-4));
        let tangent = unit(sub(ahead, c));
        let normal = unit(cross(tangent, [0.0, 0.0, 1.0]));
        let binormal = cross(tangent, normal);
        for j in 0..sides {
            let a = TAU * j as f64 / sides as f64;
            let (ca, sa) = (0.18 * a.cos(), 0.18 * a.sin());
            positions.push([0, 1, 2].map(|k| (c[k] + ca * normal[k] + sa * binormal[k]) as f32));
        }
    }
    let at = |i: usize, j: usize| ((i % rings) * sides + j % sides) as u32;
    let mut triangles = Vec::with_capacity(rings * sides * 2);
    for i in 0..rings {
        for j in 0..sides {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    Mesh::new(positions, triangles, None).expect("the knot is a valid mesh")
}

/// Cold bakes of the knot at each of `resolutions`, a fresh cache each.
pub fn rows(c: &Arc<Candidates>, resolutions: &[u32], rows: &mut Vec<Row>) -> anyhow::Result<()> {
    let mesh = Arc::new(knot(392, 128));
    let triangles = mesh.triangles().len();
    for &r in resolutions {
        // The machine may be shared: its load says how far to trust the time.
        let load = load_average();
        let bake = Bake::new(mesh.clone(), BakeOptions::new(r))?;
        let side = bake.texture_side().unwrap_or_default();
        let request = Request::bake(bake)?;
        let tex = texture(c, Scheme::DualGrid);
        let m = measure(1, || tex.render(&request, 0));
        let (_, stats) = m.value?;
        let cube = f64::from(r).powi(3);
        let finest = stats.voxels_per_level.first().copied().unwrap_or(0);
        let all: u64 = stats.voxels_per_level.iter().sum();
        rows.push(Row {
            name: format!("{ROW_PREFIX} {triangles} triangles at resolution {r}, cold"),
            seconds: Some(m.seconds),
            runs: 1,
            peak_bytes: Some(m.peak_bytes),
            target: (r == 1024).then_some("≤ 30 s"),
            paper: (r == 1024).then_some(PAPER),
            detail: format!(
                "{side}² texture; {finest} voxels at the finest level ({:.3} % of {r}³), \
                 {all} over all levels ({:.3} %), {} tiles; load average {load} at the start",
                100.0 * finest as f64 / cube,
                100.0 * all as f64 / cube,
                stats.tiles_computed
            ),
        });
    }
    if let Some(&r) = resolutions.iter().find(|&&r| r == CUT_RESOLUTION) {
        cut_rows(c, &mesh, r, rows)?;
    }
    Ok(())
}

/// The resolution the fractured knot is baked at, when the run has it.
const CUT_RESOLUTION: u32 = 512;

/// Two planes through the knot, one across its hole and one slanted
/// through its ring, in the mesh's coordinates.
const CUT_PLANES: &str = "0,0,1,0.05;1,0.3,0,-0.1";

/// The knot cut into pieces (timed alone), then the pieces baked cold.
fn cut_rows(c: &Arc<Candidates>, mesh: &Mesh, r: u32, rows: &mut Vec<Row>) -> anyhow::Result<()> {
    let triangles = mesh.triangles().len();
    let planes = Plane::parse_list(CUT_PLANES)?;
    let load = load_average();
    let m = measure(1, || mesh.cut(&planes));
    let pieces = Arc::new(m.value?);
    let once = |name: String, seconds: f64, peak_bytes: u64, detail: String| Row {
        name: format!("{ROW_PREFIX}: {name}"),
        seconds: Some(seconds),
        runs: 1,
        peak_bytes: Some(peak_bytes),
        target: None,
        paper: None,
        detail: format!("{detail}; load average {load} at the start"),
    };
    rows.push(once(
        format!("cut of {triangles} triangles by 2 planes"),
        m.seconds,
        m.peak_bytes,
        format!(
            "planes {CUT_PLANES}; {} triangles out, caps included",
            pieces.triangles().len()
        ),
    ));
    let request = Request::bake(Bake::new(pieces.clone(), BakeOptions::new(r))?)?;
    let tex = texture(c, Scheme::DualGrid);
    let m = measure(1, || tex.render(&request, 0));
    let (_, stats) = m.value?;
    rows.push(once(
        format!("the cut pieces at resolution {r}, cold"),
        m.seconds,
        m.peak_bytes,
        format!(
            "{} voxels over all levels, {} tiles",
            stats.voxels_per_level.iter().sum::<u64>(),
            stats.tiles_computed
        ),
    ));
    Ok(())
}
