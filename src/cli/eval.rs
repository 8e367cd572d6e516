//! `solidtex eval`: scores synthesized slices against their exemplar
//! (nearest-patch coherence and completeness, colour histogram distance,
//! the band spectrum's distance, and for axis slices the anisotropy and
//! the gradient directions against the exemplar's) in the xy,
//! yz, zx and an oblique orientation (an axis slice against its plane's
//! exemplar, turned where the orientation turned it), next to two baselines computed the
//! same way: the slab initialisation without correction, and a per-pixel
//! shuffle of the exemplar; on request also the quality preset and the
//! global reference (slices through its periodic block, wrapping).

use super::knob_flags::SynthArgs;
use super::source::open_exemplar;
use clap::Args;
use solidtex_core::eval::{
    RgbView, SliceScores, Structure, anisotropy, score_slice, shuffled_exemplar, structure,
};
use solidtex_core::reference::{self, Block, ReferenceParams};
use solidtex_core::{
    AnalysisParams, Axis, Candidates, CutPlane, Exemplar, ExemplarSet, Filter, Initialisation,
    Request, Scheme, SynthParams, Texture, TileCache, Window,
};
use std::path::PathBuf;
use std::sync::Arc;

#[derive(Args)]
pub struct EvalArgs {
    /// Exemplar images to evaluate.
    #[arg(required = true)]
    exemplars: Vec<PathBuf>,
    /// Slice side.
    #[arg(long, default_value_t = 128)]
    side: u32,
    /// Also score the standard scheme.
    #[arg(long)]
    standard: bool,
    /// Also score the lazy synthesis started from the reference
    /// (`initialisation=reference`) and the quality preset (minutes of
    /// precompute per exemplar).
    #[arg(long)]
    quality: bool,
    /// Also score the global reference: slices through a periodic block
    /// of this side (`solidtex reference`), wrapping where the slice is
    /// larger. 64³ takes tens of seconds, 128³ minutes.
    #[arg(long, value_name = "SIDE")]
    reference: Option<u32>,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
    /// Parameters of the corrected slices (the slab baseline shares the
    /// seed and jitter).
    #[command(flatten)]
    synth: SynthArgs,
}

/// Runs `solidtex eval`.
pub fn run(a: EvalArgs) -> anyhow::Result<()> {
    let mut all = Vec::new();
    for path in &a.exemplars {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let e = open_exemplar(path)?;
        let extra = Extra {
            standard: a.standard,
            quality: a.quality,
            reference: a.reference,
        };
        let scores = evaluate(&name, &e, a.side, extra, &a.synth.params())?;
        if !a.json {
            print(&scores)?;
        }
        all.extend(scores);
    }
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&all)?)?;
    }
    Ok(())
}

/// One scored slice.
#[derive(serde::Serialize)]
pub struct Score {
    /// Exemplar file name.
    pub exemplar: String,
    /// xy, yz, zx or oblique.
    pub orientation: String,
    /// dual-grid (the default), standard, reference-init, quality,
    /// slab-only, reference or shuffled.
    pub method: String,
    /// Mean nearest-patch distance, slice → exemplar (lower is better).
    pub coherence: f64,
    /// Mean nearest-patch distance, exemplar → slice (lower is better).
    pub completeness: f64,
    /// Colour histogram distance (lower is better).
    pub histogram: f64,
    /// Axis slices: how much more the slice is stretched along one of its
    /// axes than the exemplar along the matching one (lower is better;
    /// see [`solidtex_core::eval::anisotropy`]). None for the oblique cut and
    /// the shuffle, which have no matching exemplar axes.
    pub anisotropy: Option<f64>,
    /// Mean |ln| ratio of the luminance energy per octave band, slice
    /// against exemplar (lower is better; see
    /// [`solidtex_core::eval::Structure`]).
    pub spectrum: f64,
    /// Distance between the gradient direction histograms, 0 to 1 (lower
    /// is better). None for the oblique cut, whose plane turns the
    /// exemplar's directions.
    pub directions: Option<f64>,
    /// Distance between the sizes of connected dark and light features,
    /// 0 to 1 (lower is better): broken veins and cracks, merged spots.
    pub components: f64,
}

fn slices(tex: &Texture, side: u32) -> anyhow::Result<Vec<(&'static str, Vec<u8>)>> {
    let mut out = Vec::new();
    for (name, axis) in [("xy", Axis::Z), ("yz", Axis::X), ("zx", Axis::Y)] {
        out.push((
            name,
            tex.render(&Request::slice(axis, 21, Window::new(3, 5, side, side))?, 0)?
                .0,
        ));
    }
    out.push((
        "oblique",
        tex.render(&Request::cut(oblique(side), Filter::Nearest)?, 0)?
            .0,
    ));
    Ok(out)
}

/// The oblique plane every method is cut along.
fn oblique(side: u32) -> CutPlane {
    CutPlane {
        origin: [0.0, 0.0, 0.0],
        u: [0.8, 0.0, 0.6],
        v: [-0.36, 0.8, 0.48],
        width: side,
        height: side,
    }
}

/// The same slices as [`slices`] through a periodic reference block,
/// wrapping: its voxels are the finest level's.
fn reference_slices(block: &Block, side: u32) -> Vec<(&'static str, Vec<u8>)> {
    let n = block.size as i64;
    let at = |p: [i64; 3]| {
        let [x, y, z] = p.map(|c| c.rem_euclid(n));
        let i = (((z * n + y) * n + x) * 3) as usize;
        [block.rgb[i], block.rgb[i + 1], block.rgb[i + 2]]
    };
    let s = side as i64;
    let image = |f: &dyn Fn(i64, i64) -> [i64; 3]| -> Vec<u8> {
        (0..s)
            .flat_map(|v| (0..s).map(move |u| (u, v)))
            .flat_map(|(u, v)| at(f(u, v)))
            .collect()
    };
    // As `slices`: through (3, 5, 21), u and v as the axis slices' own.
    let plane = oblique(side);
    vec![
        ("xy", image(&|u, v| [3 + u, 5 + v, 21])),
        ("yz", image(&|u, v| [21, 3 + u, 5 + v])),
        ("zx", image(&|u, v| [5 + v, 21, 3 + u])),
        (
            "oblique",
            image(&|u, v| {
                let p = |k: usize| {
                    (plane.origin[k] + u as f64 * plane.u[k] + v as f64 * plane.v[k]).floor() as i64
                };
                [p(0), p(1), p(2)]
            }),
        ),
    ]
}

/// The methods scored beside the default and the two baselines.
#[derive(Clone, Copy, Debug, Default)]
pub struct Extra {
    /// The standard scheme.
    pub standard: bool,
    /// The reference initialisation and the quality preset
    /// ([`AnalysisParams::quality`]).
    pub quality: bool,
    /// The global reference, a periodic block of this side.
    pub reference: Option<u32>,
}

/// Scores one exemplar with every method; `params` are those of the
/// corrected slices, and the other methods differ from them only in what
/// defines the method (the scheme, the initialisation, or no correction).
pub fn evaluate(
    name: &str,
    exemplar: &Exemplar,
    side: u32,
    extra: Extra,
    params: &SynthParams,
) -> anyhow::Result<Vec<Score>> {
    let set = ExemplarSet::single(exemplar.clone());
    let analyse = |analysis: &AnalysisParams| -> anyhow::Result<Arc<Candidates>> {
        Ok(Arc::new(Candidates::compute(&set, analysis, &|_, _| {})?))
    };
    let cands = analyse(&AnalysisParams::default())?;
    // Dong et al.'s slab, uncorrected: the baseline every correction must
    // beat, whatever the default starts from.
    let slab = analyse(&AnalysisParams {
        initialisation: Initialisation::Slab,
        ..AnalysisParams::default()
    })?;
    let ex_rgb = exemplar.to_rgb_bytes();
    let ex = RgbView {
        width: exemplar.width(),
        height: exemplar.height(),
        rgb: &ex_rgb,
    };
    // Each plane's exemplar as the analysis turned it (an oriented exemplar
    // is laid turned on one plane).
    let analysed = cands.analysed();
    let plane_rgb: Vec<Vec<u8>> = (0..3).map(|p| analysed.plane(p).to_rgb_bytes()).collect();
    let plane_view = |p: usize| RgbView {
        width: analysed.width(),
        height: analysed.height(),
        rgb: &plane_rgb[p],
    };
    let mut methods = vec![
        (
            "dual-grid",
            cands.clone(),
            SynthParams {
                scheme: Scheme::DualGrid,
                ..params.clone()
            },
        ),
        (
            "slab-only",
            slab,
            SynthParams {
                passes: 0,
                finest_passes: 0,
                correct_init_level: false,
                ..params.clone()
            },
        ),
    ];
    if extra.standard {
        methods.push((
            "standard",
            cands.clone(),
            SynthParams {
                scheme: Scheme::Standard,
                ..params.clone()
            },
        ));
    }
    if extra.quality {
        methods.push((
            "reference-init",
            analyse(&AnalysisParams {
                initialisation: Initialisation::Reference,
                ..AnalysisParams::default()
            })?,
            SynthParams {
                scheme: Scheme::DualGrid,
                ..params.clone()
            },
        ));
        methods.push((
            "quality",
            analyse(&AnalysisParams::quality())?,
            SynthParams {
                scheme: Scheme::DualGrid,
                ..params.clone()
            },
        ));
    }
    let mut out = Vec::new();
    let push = |out: &mut Vec<Score>,
                orientation: &str,
                method: &str,
                s: SliceScores,
                anisotropy: Option<f64>,
                st: Structure| {
        out.push(Score {
            exemplar: name.to_string(),
            orientation: orientation.to_string(),
            method: method.to_string(),
            coherence: s.coherence,
            completeness: s.completeness,
            histogram: s.histogram,
            anisotropy,
            spectrum: st.spectrum,
            directions: (orientation != "oblique").then_some(st.orientation),
            components: st.components,
        })
    };
    let mut rendered = Vec::new();
    for (method, cands, params) in methods {
        let tex = Texture::new(cands, params, Arc::new(TileCache::new(1 << 30)))?;
        rendered.push((method, slices(&tex, side)?));
    }
    if let Some(size) = extra.reference {
        let layout = cands.layout();
        let rp = ReferenceParams {
            size,
            ..ReferenceParams::default()
        };
        let block = reference::synthesize(analysed, layout.arrangement.weights, &rp, |_| {})?;
        rendered.push(("reference", reference_slices(&block, side)));
    }
    for (method, planes) in rendered {
        for (p, (orientation, rgb)) in planes.into_iter().enumerate() {
            let view = RgbView {
                width: side,
                height: side,
                rgb: &rgb,
            };
            // An axis slice's (u, v) are its plane's exemplar axes.
            let axis = orientation != "oblique";
            let own = if axis { plane_view(p) } else { ex };
            let aniso = axis.then(|| anisotropy(view, own));
            push(
                &mut out,
                orientation,
                method,
                score_slice(view, own, 7),
                aniso,
                structure(view, own),
            );
        }
    }
    let shuffled = shuffled_exemplar(ex, side, side, 7);
    let view = RgbView {
        width: side,
        height: side,
        rgb: &shuffled,
    };
    push(
        &mut out,
        "any",
        "shuffled",
        score_slice(view, ex, 7),
        None,
        structure(view, ex),
    );
    Ok(out)
}

/// Prints scores as a table.
pub fn print(scores: &[Score]) -> std::io::Result<()> {
    outln!("Every score is a distance: lower is better. `worse than slab` marks a corrected")?;
    outln!("slice that scores worse than the uncorrected slab initialisation it started from.")?;
    outln!(
        "{:<24} {:<8} {:<10} {:>12} {:>12} {:>10} {:>10} {:>9} {:>10} {:>10}  note",
        "exemplar",
        "plane",
        "method",
        "coherence",
        "completeness",
        "histogram",
        "anisotropy",
        "spectrum",
        "directions",
        "components"
    )?;
    for s in scores {
        let aniso = s.anisotropy.map_or("-".to_string(), |a| format!("{a:.3}"));
        let directions = s.directions.map_or("-".to_string(), |a| format!("{a:.3}"));
        let losses = losses_to_slab(scores, s);
        let note = if losses.is_empty() {
            String::new()
        } else {
            format!("worse than slab: {}", losses.join(", "))
        };
        outln!(
            "{:<24} {:<8} {:<10} {:>12.5} {:>12.5} {:>10.4} {:>10} {:>9.3} {:>10} {:>10.3}  {note}",
            s.exemplar,
            s.orientation,
            s.method,
            s.coherence,
            s.completeness,
            s.histogram,
            aniso,
            s.spectrum,
            directions,
            s.components
        )?;
    }
    Ok(())
}

/// The scores in which a corrected row (`dual-grid`, `standard`, `quality`) is worse
/// than the slab-only row of the same exemplar and plane.
fn losses_to_slab(scores: &[Score], s: &Score) -> Vec<&'static str> {
    if !matches!(
        s.method.as_str(),
        "dual-grid" | "standard" | "reference-init" | "quality"
    ) {
        return Vec::new();
    }
    let Some(slab) = scores.iter().find(|r| {
        r.method == "slab-only" && r.exemplar == s.exemplar && r.orientation == s.orientation
    }) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    if s.coherence > slab.coherence {
        out.push("coherence");
    }
    if s.completeness > slab.completeness {
        out.push("completeness");
    }
    if s.histogram > slab.histogram {
        out.push("histogram");
    }
    if let (Some(a), Some(b)) = (s.anisotropy, slab.anisotropy)
        && a > b
    {
        out.push("anisotropy");
    }
    if s.spectrum > slab.spectrum {
        out.push("spectrum");
    }
    if let (Some(a), Some(b)) = (s.directions, slab.directions)
        && a > b
    {
        out.push("directions");
    }
    if s.components > slab.components {
        out.push("components");
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corrected_rows_worse_than_the_slab_are_named() {
        let row = |method: &str, c: f64, h: f64| Score {
            exemplar: "e".into(),
            orientation: "xy".into(),
            method: method.into(),
            coherence: c,
            completeness: 1.0,
            histogram: h,
            anisotropy: None,
            spectrum: 0.5,
            directions: Some(0.1),
            components: 0.3,
        };
        let scores = [
            row("slab-only", 2.0, 0.1),
            row("dual-grid", 1.0, 0.2),
            row("standard", 3.0, 0.05),
        ];
        assert_eq!(losses_to_slab(&scores, &scores[0]), Vec::<&str>::new());
        assert_eq!(losses_to_slab(&scores, &scores[1]), ["histogram"]);
        assert_eq!(losses_to_slab(&scores, &scores[2]), ["coherence"]);
    }

    #[test]
    fn reference_slices_cut_the_block_where_the_engine_slices_are_cut() {
        // Each voxel's colour is its own coordinates, so a pixel says
        // which voxel it came from.
        let n = 8u32;
        let rgb = (0..n * n * n)
            .flat_map(|i| [(i % n) as u8, (i / n % n) as u8, (i / (n * n)) as u8])
            .collect();
        let block = Block { size: n, rgb };
        let slices = reference_slices(&block, 12);
        let pixel = |plane: usize, u: usize, v: usize| {
            let img = &slices[plane].1;
            let i = (v * 12 + u) * 3;
            [img[i], img[i + 1], img[i + 2]]
        };
        let wrap = |c: i64| c.rem_euclid(8) as u8;
        // xy through z = 21: (3 + u, 5 + v); yz: (21, 3 + u, 5 + v); zx: (5 + v, 21, 3 + u).
        assert_eq!(pixel(0, 10, 4), [wrap(13), wrap(9), wrap(21)]);
        assert_eq!(pixel(1, 10, 4), [wrap(21), wrap(13), wrap(9)]);
        assert_eq!(pixel(2, 10, 4), [wrap(9), wrap(21), wrap(13)]);
        assert_eq!(slices.len(), 4);
        assert_eq!(slices[3].0, "oblique");
        assert_eq!(pixel(3, 0, 0), [0, 0, 0]);
    }

    #[test]
    fn synthesis_parameters_reach_the_corrected_slices_only() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/fixtures/exemplars/animal_leather.png"
        );
        let e = Exemplar::open(std::path::Path::new(path)).unwrap();
        let score =
            |params: &SynthParams| evaluate("leather", &e, 24, Extra::default(), params).unwrap();
        let default = score(&SynthParams::default());
        let flat = score(&SynthParams {
            contrast: 1.0,
            ..SynthParams::default()
        });
        let rows = |s: &[Score], method: &str| -> Vec<f64> {
            s.iter()
                .filter(|r| r.method == method)
                .map(|r| r.coherence)
                .collect()
        };
        assert_eq!(rows(&default, "dual-grid").len(), 4, "xy, yz, zx, oblique");
        // Only axis slices have exemplar axes to compare stretch with.
        let has_anisotropy: Vec<bool> = default
            .iter()
            .filter(|r| r.method == "dual-grid")
            .map(|r| r.anisotropy.is_some_and(f64::is_finite))
            .collect();
        assert_eq!(has_anisotropy, [true, true, true, false]);
        let has_directions: Vec<bool> = default
            .iter()
            .filter(|r| r.method == "dual-grid")
            .map(|r| r.directions.is_some())
            .collect();
        assert_eq!(has_directions, [true, true, true, false]);
        assert!(
            default
                .iter()
                .all(|r| r.spectrum.is_finite() && r.spectrum >= 0.0)
        );
        assert_ne!(rows(&default, "dual-grid"), rows(&flat, "dual-grid"));
        assert_eq!(rows(&default, "slab-only"), rows(&flat, "slab-only"));
    }
}
