//! `solidtex bench`: wall-clock measurements of the engine on the shared
//! exemplars, printed as a table or JSON. Numbers are medians of a few runs;
//! every "cold" run uses a fresh tile cache.

use solidtex::{
    AnalysisParams, Axis, Candidates, CutPlane, Exemplar, ExemplarSet, Filter, Region, SynthParams,
    Texture, TileCache,
};
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

/// One measurement.
#[derive(serde::Serialize)]
pub struct Row {
    /// What was measured.
    pub name: String,
    /// Median seconds.
    pub seconds: f64,
    /// Free-form detail (sizes, counts).
    pub detail: String,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn time<T>(runs: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..runs {
        let t0 = Instant::now();
        last = Some(f());
        times.push(t0.elapsed().as_secs_f64());
    }
    (median(times), last.expect("at least one run"))
}

fn fresh(c: &Arc<Candidates>) -> Texture {
    Texture::new(c.clone(), SynthParams::default(), Arc::new(TileCache::new(2 << 30)))
        .expect("valid params")
}

/// Runs the suite; `quick` shrinks every size so it finishes in seconds.
pub fn run(exemplars: &Path, quick: bool) -> anyhow::Result<Vec<Row>> {
    let mut rows = Vec::new();
    let runs = if quick { 1 } else { 3 };
    let names: &[&str] = if quick {
        &["animal_leather.png"]
    } else {
        &["animal_leather.png", "stone_pink_marble.png"]
    };
    let mut main_cands = None;
    for name in names {
        let e = Exemplar::open(exemplars.join(name))?;
        let size = format!("{}x{}", e.width(), e.height());
        let set = ExemplarSet::single(e);
        let (s, c) = time(runs, || {
            Candidates::compute(&set, &AnalysisParams::default(), &|_, _| {}).expect("precompute")
        });
        let (compact, memory) = c.memory_bytes();
        rows.push(Row {
            name: format!("precompute {name}"),
            seconds: s,
            detail: format!(
                "{size}; .stx {} B; candidates compact {compact} B; in memory {memory} B",
                c.to_bytes().len()
            ),
        });
        if main_cands.is_none() {
            main_cands = Some(Arc::new(c));
        }
    }
    let c = main_cands.expect("one exemplar");
    let cube = |n: u32| Region {
        origin: [0, 0, 0],
        size: [n, n, n],
    };
    let volumes: &[u32] = if quick { &[16] } else { &[64, 128] };
    for &n in volumes {
        let (s, stats) = time(1, || fresh(&c).region(&cube(n), 0).expect("volume").1);
        rows.push(Row {
            name: format!("full volume {n}³ (cold)"),
            seconds: s,
            detail: format!("corrections per level {:?}", stats.corrections_per_level),
        });
    }
    let sides: &[u32] = if quick { &[32] } else { &[256, 512] };
    for &side in sides {
        let tex = fresh(&c);
        let (cold, stats) = time(1, || tex.slice(Axis::Z, 5, 0, 0, side, side, 0).expect("slice").1);
        let (warm, _) = time(runs, || tex.slice(Axis::Z, 5, 0, 0, side, side, 0).expect("slice"));
        rows.push(Row {
            name: format!("axis slice {side}² cold"),
            seconds: cold,
            detail: format!("voxels per level {:?}", stats.voxels_per_level),
        });
        rows.push(Row {
            name: format!("axis slice {side}² warm"),
            seconds: warm,
            detail: String::new(),
        });
        let plane = CutPlane {
            origin: [0.0, 0.0, 0.0],
            u: [0.8, 0.6, 0.0],
            v: [0.0, 0.6, 0.8],
            width: side,
            height: side,
        };
        let tex = fresh(&c);
        let (cold, _) = time(1, || tex.cut(&plane, 0, Filter::Nearest).expect("cut"));
        let (warm, _) = time(runs, || tex.cut(&plane, 0, Filter::Nearest).expect("cut"));
        rows.push(Row {
            name: format!("oblique cut {side}² cold"),
            seconds: cold,
            detail: String::new(),
        });
        rows.push(Row {
            name: format!("oblique cut {side}² warm"),
            seconds: warm,
            detail: String::new(),
        });
    }
    let brick = if quick { 16 } else { 64 };
    let tex = fresh(&c);
    let b = Region {
        origin: [640, -320, 128],
        size: [brick; 3],
    };
    let (cold, _) = time(1, || tex.region(&b, 0).expect("brick"));
    let (warm, _) = time(runs, || tex.region(&b, 0).expect("brick"));
    rows.push(Row {
        name: format!("brick {brick}³ cold"),
        seconds: cold,
        detail: String::new(),
    });
    rows.push(Row {
        name: format!("brick {brick}³ warm"),
        seconds: warm,
        detail: String::new(),
    });
    let (s, (rgb, stats)) = time(1, || fresh(&c).points(&[[12345, -678, 91011]], 0).expect("voxel"));
    rows.push(Row {
        name: "single voxel (cold)".into(),
        seconds: s,
        detail: format!(
            "colour {:?}; voxels per level {:?}",
            rgb[0], stats.voxels_per_level
        ),
    });
    Ok(rows)
}

/// Prints rows as an aligned table.
pub fn print(rows: &[Row]) {
    println!("{:<36} {:>10}  detail", "benchmark", "seconds");
    for r in rows {
        println!("{:<36} {:>10.4}  {}", r.name, r.seconds, r.detail);
    }
}
