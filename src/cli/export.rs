//! `solidtex export`: a box of the solid, or one period of a periodic one,
//! as a file other tools load: a KTX2 3D texture, a PNG slice atlas, NRRD,
//! or raw RGB8 (the atlas and the raw voxels with a JSON sidecar that says
//! how to read them). The bytes are the server's for the same export.

use super::source::{SourceArgs, load_source, progress_bar, summary};
use anyhow::Context;
use clap::Args;
use solidtex_core::Region;
use solidtex_core::export::{Export, Format, Mips};
use solidtex_server::write_atomic;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args)]
pub struct ExportArgs {
    #[command(flatten)]
    src: SourceArgs,
    /// File format: ktx2 (3D texture), atlas (PNG of z slices), nrrd or
    /// raw.
    #[arg(long)]
    format: Format,
    /// The box: `period` (one period of a periodic texture, the default
    /// for one) or X,Y,Z,W,H,D in voxels of the level of detail.
    #[arg(long = "box", allow_hyphen_values = true)]
    region: Option<String>,
    /// KTX2 mip chain: box (a box filter, in linear light when sRGB),
    /// levels (the solid's own coarser levels of detail) or none.
    #[arg(long, default_value = "box")]
    mips: Mips,
    /// KTX2 texels marked as linear (UNORM) instead of sRGB.
    #[arg(long)]
    linear: bool,
    /// Output file (default: a name that says the box and the layout, in
    /// the current directory). The atlas and raw formats also write a
    /// JSON sidecar beside it (the same name, ending `.json`).
    #[arg(short, long)]
    output: Option<PathBuf>,
}

/// Reads `X,Y,Z,W,H,D`.
fn parse_box(text: &str) -> anyhow::Result<Region> {
    let v: Vec<i64> = text
        .split(',')
        .map(|s| s.trim().parse::<i64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("--box `{text}` is not `period` or X,Y,Z,W,H,D"))?;
    let [x, y, z, w, h, d] = v[..] else {
        anyhow::bail!("--box `{text}` is not `period` or six numbers X,Y,Z,W,H,D");
    };
    let side = |s: i64| u32::try_from(s).context("box sides must be whole numbers from 1");
    Ok(Region {
        origin: [x, y, z],
        size: [side(w)?, side(h)?, side(d)?],
    })
}

/// Runs `solidtex export`.
pub fn run(a: ExportArgs) -> anyhow::Result<()> {
    let tex = load_source(&a.src)?;
    let lod = a.src.lod;
    let region = match a.region.as_deref() {
        None | Some("period") => Export::one_period(&tex, lod)?,
        Some(text) => parse_box(text)?,
    };
    let export = Export {
        mips: a.mips,
        srgb: !a.linear,
        ..Export::new(a.format, region, lod)
    };
    export.check(&tex)?;
    let stem = a
        .src
        .source
        .as_ref()
        .and_then(|p| p.file_stem())
        .map_or("solidtex".to_string(), |s| s.to_string_lossy().into_owned());
    let output = a
        .output
        .unwrap_or_else(|| PathBuf::from(export.file_name(&stem)));
    let t0 = Instant::now();
    let bar = progress_bar();
    bar.set_message("synthesis");
    let (bytes, stats) = export.run(&tex, &|done, total| {
        bar.set_position(done * 1000 / total.max(1));
    })?;
    bar.finish_and_clear();
    write_atomic(&output, &bytes).with_context(|| format!("writing {}", output.display()))?;
    if matches!(export.format, Format::Atlas | Format::Raw) {
        let sidecar = output.with_extension("json");
        let json = serde_json::to_vec_pretty(&export.describe(&tex))?;
        write_atomic(&sidecar, &json).with_context(|| format!("writing {}", sidecar.display()))?;
        eprintln!("wrote its layout to {}", sidecar.display());
    }
    let [w, h, d] = region.size;
    eprintln!(
        "{}",
        summary(
            &format!("a {w}×{h}×{d} {} export", export.format),
            &output,
            t0,
            &stats
        )
    );
    Ok(())
}
