//! `solidtex bake`: a mesh textured from the solid, as a glTF binary.

use super::cut::parse_vec3;
use super::source::{SourceArgs, load_source, progress_bar, summary};
use anyhow::Context;
use clap::Args;
use indicatif::ProgressBar;
use solidtex_core::mesh::{Bake, BakeOptions, Colours, Mesh, MeshFormat, Plane, Uvs};
use solidtex_core::{
    CancelFlag, Cancelled, Filter, Request, RequestKind, SynthStats, Texture, run_cancellable,
};
use solidtex_server::write_atomic;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

#[derive(Args)]
pub struct BakeArgs {
    /// The mesh: OBJ, PLY or glTF binary (GLB).
    mesh: PathBuf,
    #[command(flatten)]
    src: SourceArgs,
    /// Voxels spanned by the longest side of the mesh's bounding box.
    #[arg(long, default_value_t = 256)]
    resolution: u32,
    /// Turn, degrees about x, then y, then z (around the box's centre).
    #[arg(long, value_parser = parse_vec3, default_value = "0,0,0", allow_hyphen_values = true)]
    rotation: [f64; 3],
    /// Where the box's lowest corner lies, `x,y,z` in voxels.
    #[arg(long, value_parser = parse_vec3, default_value = "0,0,0", allow_hyphen_values = true)]
    offset: [f64; 3],
    /// Side of the baked texture (about one texel per voxel of surface
    /// when omitted).
    #[arg(long)]
    texture_size: Option<u32>,
    /// Whose texture coordinates: auto (the mesh's when valid), mesh or atlas.
    #[arg(long, default_value = "auto")]
    uvs: UvArg,
    /// Bake one colour per vertex instead of a texture.
    #[arg(long)]
    vertex_colours: bool,
    /// Read the solid between voxel centres trilinearly.
    #[arg(long)]
    trilinear: bool,
    /// Cut the mesh by the plane `nx,ny,nz,d` (the points p with n·p = d, in
    /// the mesh file's coordinates) into closed pieces whose caps show the
    /// inside; repeat for a fracture (at most 8 planes).
    #[arg(long, allow_hyphen_values = true)]
    cut: Vec<String>,
    /// Pull the pieces of a cut apart by this share of the mesh's longest
    /// side (0 to 1), each away from the planes.
    #[arg(long, default_value_t = 0.0)]
    spread: f32,
    /// Output `.glb`.
    #[arg(short, long)]
    output: PathBuf,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum UvArg {
    Auto,
    Mesh,
    Atlas,
}

/// Renders the bake `request`, moving `bar` as it goes: by the texels
/// answered, a step of about a million at a time, and between them by the
/// voxels of the shell synthesized against the `predicted` guess, whose
/// count the message shows.
fn render_watched(
    tex: &Texture,
    request: &Request,
    lod: u32,
    predicted: u64,
    bar: &ProgressBar,
) -> anyhow::Result<(Vec<u8>, SynthStats)> {
    let flag = CancelFlag::new();
    let texels = AtomicU64::new(0);
    let items = match request.kind() {
        RequestKind::Bake(b) => b.items().max(1) as f64,
        _ => 1.0,
    };
    let show = |texels: u64| {
        let share = (texels as f64 / items).max(flag.share_of(predicted));
        bar.set_position((share * 1000.0) as u64);
        // A warm cache synthesizes less than predicted: the count itself
        // shows the synthesis moving.
        bar.set_message(format!(
            "synthesis, {:.1} M voxels",
            flag.synthesized() as f64 / 1e6
        ));
    };
    std::thread::scope(|scope| {
        let work = scope.spawn(|| {
            run_cancellable(&flag, || {
                tex.render_progress(request, lod, &|done, _| {
                    texels.fetch_max(done, Ordering::Relaxed);
                })
            })
        });
        while !work.is_finished() {
            show(texels.load(Ordering::Relaxed));
            std::thread::sleep(Duration::from_millis(100));
        }
        match work.join() {
            Ok(Ok(answer)) => Ok(answer?),
            Ok(Err(Cancelled)) => Err(anyhow::anyhow!("the bake was cancelled")),
            Err(panic) => std::panic::resume_unwind(panic),
        }
    })
}

/// Runs `solidtex bake`.
pub fn run(a: BakeArgs) -> anyhow::Result<()> {
    let bytes = std::fs::read(&a.mesh).with_context(|| format!("reading {}", a.mesh.display()))?;
    let format = match a.mesh.extension().and_then(|e| e.to_str()) {
        Some(ext) => MeshFormat::from_name(ext).ok(),
        None => None,
    };
    let mut mesh = Mesh::parse(&bytes, format).with_context(|| a.mesh.display().to_string())?;
    if !a.cut.is_empty() {
        let planes = Plane::parse_list(&a.cut.join(";"))?;
        mesh = mesh.cut(&planes)?;
    }
    let tex = load_source(&a.src)?;
    let mut options = BakeOptions::new(a.resolution);
    options.placement.rotation = a.rotation;
    options.placement.offset = a.offset;
    options.texture_size = a.texture_size;
    options.uvs = match a.uvs {
        UvArg::Auto => Uvs::Auto,
        UvArg::Mesh => Uvs::Mesh,
        UvArg::Atlas => Uvs::Atlas,
    };
    if a.vertex_colours {
        options.colours = Colours::Vertex;
    }
    options.spread = a.spread;
    if a.trilinear {
        options.filter = Filter::Trilinear;
    }
    let triangles = mesh.triangles().len();
    let dropped = mesh.dropped();
    let bake = Bake::new(Arc::new(mesh), options)?;
    let t0 = Instant::now();
    let bar = progress_bar();
    bar.set_message("planning");
    let request = Request::bake(bake.clone())?;
    let predicted = tex.predict(&request, a.src.lod)?;
    let (rgb, stats) = render_watched(&tex, &request, a.src.lod, predicted, &bar)?;
    bar.set_position(1000);
    bar.set_message("writing");
    let glb = bake.glb(&rgb)?;
    bar.finish_and_clear();
    write_atomic(&a.output, &glb).with_context(|| format!("writing {}", a.output.display()))?;
    let layout = match bake.texture_side() {
        Some(s) if bake.uses_mesh_uvs() => format!("a {s}² texture on the mesh's UVs"),
        Some(s) => format!("a {s}² texture in a generated atlas"),
        None => "vertex colours".to_string(),
    };
    let pieces = match bake.mesh().pieces().len() {
        1 => String::new(),
        n => format!(", {n} pieces"),
    };
    let what = format!(
        "{triangles} triangles ({dropped} degenerate dropped{pieces}) at resolution {} with {layout}",
        a.resolution
    );
    eprintln!("{}", summary(&what, &a.output, t0, &stats));
    Ok(())
}
