//! Exports: a finite box of the solid (any box, or one period of a
//! periodic solid) at any level of detail, in files that other tools load:
//!
//! - **KTX2** (`.ktx2`): a 3D texture, RGBA8 marked sRGB (samplers decode
//!   it) or linear (the same bytes, read as they are), with a full mip
//!   chain ([`Mips`]): by default a box filter (each texel of level m + 1
//!   the mean of the 2×2×2 texels below it, in linear light when sRGB),
//!   or the solid's own coarser levels of detail (synthesized, not
//!   filtered; a box filter below the coarsest level). three.js loads it
//!   with `KTX2Loader` as a `Data3DTexture`.
//! - **Slice atlas** (`.png`): the "pseudo-volume" that Unreal's Volume
//!   Texture and common shader graphs import: the z slices as tiles of a
//!   grid, slice z at column z mod C and row z div C, C the smallest power
//!   of two at least √depth. The layout is in the file name and the
//!   sidecar JSON.
//! - **NRRD** (`.nrrd`): 3D Slicer, ParaView and ImageJ/Fiji read it; RGB
//!   voxels with their spacing and origin in finest voxels.
//! - **Raw** (`.raw`): RGB8, x fastest, then y, then z, with a sidecar
//!   JSON saying so.
//!
//! Every export has a description ([`Export::describe`]), the sidecar
//! JSON. The bytes depend only on the texture and the export, so the
//! command line and the server write the same files.

mod atlas;
pub mod ktx2;
mod nrrd;

use crate::error::{Error, Result};
use crate::request::{Region, Request};
use crate::synth::SynthStats;
use crate::synth::estimate::WorkEstimate;
use crate::texture::Texture;
use serde_json::{Value, json};

/// Most voxels in one export: 256³.
pub const MAX_EXPORT_VOXELS: u64 = 1 << 24;

/// Largest side of a KTX2 3D texture: what current GPUs and APIs take
/// (WebGL 2 guarantees only 256; desktop GPUs take 2048 and more).
pub const MAX_KTX2_SIDE: u32 = 2048;

/// Voxels synthesized per step of an export, between reports of progress.
const STEP_VOXELS: u64 = 1 << 20;

/// A file format of an export (serde reads it by [`Format::name`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// KTX 2.0 3D texture.
    Ktx2,
    /// PNG slice atlas.
    Atlas,
    /// NRRD volume.
    Nrrd,
    /// Raw RGB8 voxels.
    Raw,
}

impl Format {
    /// Every format, as named.
    pub const ALL: [Format; 4] = [Format::Ktx2, Format::Atlas, Format::Nrrd, Format::Raw];

    /// The format's name (`ktx2`, `atlas`, `nrrd`, `raw`).
    pub fn name(self) -> &'static str {
        match self {
            Format::Ktx2 => "ktx2",
            Format::Atlas => "atlas",
            Format::Nrrd => "nrrd",
            Format::Raw => "raw",
        }
    }

    /// The file extension.
    pub fn extension(self) -> &'static str {
        match self {
            Format::Ktx2 => "ktx2",
            Format::Atlas => "png",
            Format::Nrrd => "nrrd",
            Format::Raw => "raw",
        }
    }

    /// The media type.
    pub fn media_type(self) -> &'static str {
        match self {
            Format::Ktx2 => "image/ktx2",
            Format::Atlas => "image/png",
            Format::Nrrd => "application/x-nrrd",
            Format::Raw => "application/octet-stream",
        }
    }
}

impl std::str::FromStr for Format {
    type Err = Error;
    fn from_str(s: &str) -> Result<Format> {
        Format::ALL
            .into_iter()
            .find(|f| f.name() == s)
            .ok_or_else(|| {
                Error::InvalidRequest(format!(
                    "unknown export format `{s}` (expected ktx2, atlas, nrrd or raw)"
                ))
            })
    }
}

impl std::fmt::Display for Format {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// How a KTX2 export's mip chain is made (serde reads it by name).
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Mips {
    /// A box filter of the level below.
    #[default]
    Box,
    /// The solid's own levels of detail, synthesized: level m of an export
    /// at lod l is lod l + m (the box halved); a box filter below the
    /// coarsest level.
    Levels,
    /// Level 0 alone.
    None,
}

impl Mips {
    fn name(self) -> &'static str {
        match self {
            Mips::Box => "box",
            Mips::Levels => "levels",
            Mips::None => "none",
        }
    }
}

impl std::str::FromStr for Mips {
    type Err = Error;
    fn from_str(s: &str) -> Result<Mips> {
        match s {
            "box" => Ok(Mips::Box),
            "levels" => Ok(Mips::Levels),
            "none" => Ok(Mips::None),
            _ => Err(Error::InvalidRequest(format!(
                "unknown mips `{s}` (expected box, levels or none)"
            ))),
        }
    }
}

/// What to export.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Export {
    /// The file format.
    pub format: Format,
    /// The box, in voxels of `lod`.
    pub region: Region,
    /// The level of detail.
    pub lod: u32,
    /// The mip chain (KTX2 only).
    pub mips: Mips,
    /// Whether the KTX2 texels are marked sRGB (else linear).
    pub srgb: bool,
}

impl Export {
    /// An export of `region` at `lod` in `format`, with the defaults: a
    /// box-filtered mip chain, sRGB.
    pub fn new(format: Format, region: Region, lod: u32) -> Export {
        Export {
            format,
            region,
            lod,
            mips: Mips::Box,
            srgb: true,
        }
    }

    /// The box of one period of `t` at `lod`, from the origin: it tiles
    /// space without a seam.
    pub fn one_period(t: &Texture, lod: u32) -> Result<Region> {
        let period = t.params().period.ok_or_else(|| {
            Error::InvalidRequest(
                "the texture has no period: one period needs a periodic texture \
                 (give it `period`), or give the box"
                    .into(),
            )
        })?;
        let size = period.map(|p| (p >> lod).max(1));
        Ok(Region {
            origin: [0; 3],
            size,
        })
    }

    /// Checks the export against the texture and the limits: the level of
    /// detail, the box (at most [`MAX_EXPORT_VOXELS`], coordinates within
    /// range), a KTX2's sides (at most [`MAX_KTX2_SIDE`]) and that only a
    /// KTX2 takes mips or a colour encoding.
    pub fn check(&self, t: &Texture) -> Result<()> {
        if self.lod > t.max_lod() {
            return Err(Error::InvalidRange {
                name: "lod",
                value: self.lod as f64,
                min: 0.0,
                max: t.max_lod() as f64,
            });
        }
        let r = &self.region;
        if r.size.contains(&0) {
            return Err(Error::InvalidRequest(
                "an export's box must be at least 1 voxel on every axis".into(),
            ));
        }
        match r.voxel_count() {
            Some(n) if n <= MAX_EXPORT_VOXELS => {}
            _ => {
                let [w, h, d] = r.size;
                return Err(Error::TooLarge(format!(
                    "an export of {w}x{h}x{d} voxels (at most {MAX_EXPORT_VOXELS}, 256³)"
                )));
            }
        }
        Request::region(*r)?;
        if self.format == Format::Ktx2 {
            if let Some(&side) = r.size.iter().find(|&&s| s > MAX_KTX2_SIDE) {
                return Err(Error::TooLarge(format!(
                    "a KTX2 side of {side} texels (at most {MAX_KTX2_SIDE})"
                )));
            }
        } else if self.mips != Mips::Box || !self.srgb {
            return Err(Error::InvalidRequest(format!(
                "mips and colour apply to ktx2 exports only, not {}",
                self.format
            )));
        }
        Ok(())
    }

    /// The boxes synthesized, with their level of detail: the box, then
    /// for synthesized mips each coarser level's.
    fn syntheses(&self, t: &Texture) -> Vec<(Region, u32)> {
        let mut out = vec![(self.region, self.lod)];
        if self.format == Format::Ktx2 && self.mips == Mips::Levels {
            for m in 1..self.levels() {
                let lod = self.lod + m;
                if lod > t.max_lod() {
                    break;
                }
                let origin = self.region.origin.map(|o| o >> m);
                let size = self.region.size.map(|s| (s >> m).max(1));
                out.push((Region { origin, size }, lod));
            }
        }
        out
    }

    /// Mip levels of a KTX2 export (1 without mips).
    fn levels(&self) -> u32 {
        match self.mips {
            Mips::None => 1,
            _ => {
                let largest = self.region.size.into_iter().max().unwrap_or(1);
                32 - largest.leading_zeros()
            }
        }
    }

    /// Voxels synthesized (the total that progress counts to).
    pub fn voxels(&self, t: &Texture) -> u64 {
        self.syntheses(t)
            .iter()
            .map(|(r, _)| r.voxel_count().unwrap_or(u64::MAX))
            .fold(0u64, u64::saturating_add)
    }

    /// An upper bound of the voxels a cold-cache export synthesizes at all
    /// levels (see [`Texture::estimate`]); counting stops past `limit`. In
    /// a periodic solid a box larger than a period costs one period.
    pub fn estimate(&self, t: &Texture, limit: u64) -> Result<WorkEstimate> {
        let mut total = WorkEstimate {
            per_level: Vec::new(),
            total: 0,
            complete: true,
        };
        for (r, lod) in self.syntheses(t) {
            let mut r = r;
            if let Some(period) = t.params().period {
                for (a, side) in period.into_iter().enumerate() {
                    let p = (side >> lod).max(1);
                    if r.size[a] >= p {
                        r.size[a] = p;
                        r.origin[a] = 0;
                    }
                }
            }
            let e = t.estimate(&Request::region(r)?, lod, limit.saturating_sub(total.total))?;
            total.total = total.total.saturating_add(e.total);
            total.complete &= e.complete;
            if total.per_level.len() < e.per_level.len() {
                total.per_level.resize(e.per_level.len(), 0);
            }
            for (d, s) in total.per_level.iter_mut().zip(&e.per_level) {
                *d += s;
            }
            if !total.complete {
                break;
            }
        }
        Ok(total)
    }

    /// The file name for an export of the texture named `stem`: the box,
    /// level of detail, and an atlas's layout.
    pub fn file_name(&self, stem: &str) -> String {
        let [w, h, d] = self.region.size;
        let layout = match self.format {
            Format::Atlas => {
                let (c, r) = atlas::grid(d);
                format!("-atlas{c}x{r}")
            }
            _ => String::new(),
        };
        format!(
            "{stem}-lod{}-{w}x{h}x{d}{layout}.{}",
            self.lod,
            self.format.extension()
        )
    }

    /// Whether the box is a whole number of periods of a periodic `t`
    /// along every axis, so that it tiles space without a seam.
    pub fn tiles(&self, t: &Texture) -> bool {
        t.params().period.is_some_and(|period| {
            (0..3).all(|a| {
                let p = (period[a] >> self.lod).max(1);
                self.region.size[a].is_multiple_of(p)
            })
        })
    }

    /// The export's description (the sidecar JSON): what the file holds
    /// and where it lies in the solid, and for each format how to read
    /// it.
    pub fn describe(&self, t: &Texture) -> Value {
        let r = &self.region;
        let [w, h, d] = r.size;
        let scale = 1u64 << self.lod;
        let mut v = json!({
            "format": self.format.name(),
            "media_type": self.format.media_type(),
            "lod": self.lod,
            "voxel_size": scale,
            "origin": r.origin,
            "size": r.size,
            "tiles": self.tiles(t),
            "period": t.params().period.map(|p| p.map(|s| (s >> self.lod).max(1))),
            "synthesis": t.params(),
        });
        let o = v.as_object_mut().expect("an object");
        match self.format {
            Format::Ktx2 => {
                o.insert(
                    "vk_format".into(),
                    json!(if self.srgb {
                        ktx2::VK_FORMAT_R8G8B8A8_SRGB
                    } else {
                        ktx2::VK_FORMAT_R8G8B8A8_UNORM
                    }),
                );
                o.insert(
                    "colour".into(),
                    json!(if self.srgb { "srgb" } else { "linear" }),
                );
                o.insert("mips".into(), json!(self.mips.name()));
                o.insert("levels".into(), json!(self.levels()));
                o.insert(
                    "texels".into(),
                    json!("RGBA8, x fastest, then y, then z; alpha 255"),
                );
            }
            Format::Atlas => {
                let (columns, rows) = atlas::grid(d);
                o.insert(
                    "layout".into(),
                    json!({
                        "tile_width": w,
                        "tile_height": h,
                        "slices": d,
                        "columns": columns,
                        "rows": rows,
                        "width": w * columns,
                        "height": h * rows,
                        "order": "slice z at column z % columns, row z / columns; \
                                  x right, y down in each tile; unused tiles black",
                    }),
                );
            }
            Format::Nrrd => {
                o.insert(
                    "voxels".into(),
                    json!("RGB8 (NRRD kind RGB-color), x fastest, then y, then z"),
                );
            }
            Format::Raw => {
                o.insert("dtype".into(), json!("uint8"));
                o.insert("shape_zyxc".into(), json!([d, h, w, 3]));
                o.insert(
                    "order".into(),
                    json!("C order over (z, y, x, channel): x fastest after R, G, B"),
                );
                o.insert(
                    "bytes".into(),
                    json!(u64::from(w) * u64::from(h) * u64::from(d) * 3),
                );
            }
        }
        v
    }

    /// The export's bytes. `progress` hears (voxels synthesized, total)
    /// after each step of `STEP_VOXELS` or so.
    pub fn run(
        &self,
        t: &Texture,
        progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<(Vec<u8>, SynthStats)> {
        self.check(t)?;
        let total = self.voxels(t);
        let mut done = 0u64;
        let mut stats = SynthStats::default();
        let mut synthesized = Vec::new();
        for (r, lod) in self.syntheses(t) {
            let rgb = synthesize(t, &r, lod, &mut |n, s| {
                done += n;
                stats.merge(s);
                progress(done, total);
            })?;
            synthesized.push((r.size, rgb));
        }
        let [w, h, d] = self.region.size;
        let bytes = match self.format {
            Format::Raw => synthesized.swap_remove(0).1,
            Format::Nrrd => nrrd::encode(&self.region, self.lod, &synthesized[0].1),
            Format::Atlas => atlas::encode([w, h, d], &synthesized[0].1)?,
            Format::Ktx2 => {
                let levels = mip_chain(synthesized, self.levels(), self.srgb);
                let extra = [("solidtex", self.describe(t).to_string())];
                ktx2::encode(&levels, self.srgb, &extra)
            }
        };
        Ok((bytes, stats))
    }
}

/// RGB8 voxels of `r` at `lod`, synthesized in slabs along z of about
/// `STEP_VOXELS`; `step` hears each slab's voxels and costs.
fn synthesize(
    t: &Texture,
    r: &Region,
    lod: u32,
    step: &mut dyn FnMut(u64, &SynthStats),
) -> Result<Vec<u8>> {
    let [w, h, d] = r.size;
    let plane = u64::from(w) * u64::from(h);
    let planes = (STEP_VOXELS / plane).clamp(1, u64::from(d)) as u32;
    let mut out = Vec::with_capacity((plane * u64::from(d) * 3) as usize);
    let mut z = 0;
    while z < d {
        let n = planes.min(d - z);
        let slab = Region {
            origin: [r.origin[0], r.origin[1], r.origin[2] + i64::from(z)],
            size: [w, h, n],
        };
        let (rgb, stats) = t.render(&Request::region(slab)?, lod)?;
        out.extend_from_slice(&rgb);
        step(plane * u64::from(n), &stats);
        z += n;
    }
    Ok(out)
}

/// The KTX2 levels: each synthesized box as RGBA, then box-filtered
/// levels down to `count`.
fn mip_chain(synthesized: Vec<([u32; 3], Vec<u8>)>, count: u32, srgb: bool) -> Vec<ktx2::Level> {
    let mut levels: Vec<ktx2::Level> = synthesized
        .into_iter()
        .map(|(size, rgb)| ktx2::Level {
            size,
            rgba: rgb
                .chunks_exact(3)
                .flat_map(|c| [c[0], c[1], c[2], 255])
                .collect(),
        })
        .collect();
    while (levels.len() as u32) < count {
        let next = halve(levels.last().expect("level 0"), srgb);
        levels.push(next);
    }
    levels
}

/// A level half as large (rounded down, at least 1): each texel the mean
/// of the up to 2×2×2 texels it covers, in linear light when `srgb`.
fn halve(l: &ktx2::Level, srgb: bool) -> ktx2::Level {
    let [w, h, d] = l.size.map(|s| s as usize);
    let size = l.size.map(|s| (s / 2).max(1));
    let [nw, nh, nd] = size.map(|s| s as usize);
    let linear = srgb_table();
    let mut rgba = Vec::with_capacity(nw * nh * nd * 4);
    for z in 0..nd {
        for y in 0..nh {
            for x in 0..nw {
                let mut sum = [0f64; 3];
                let mut n = 0f64;
                for sz in [2 * z, 2 * z + 1].into_iter().filter(|&v| v < d) {
                    for sy in [2 * y, 2 * y + 1].into_iter().filter(|&v| v < h) {
                        for sx in [2 * x, 2 * x + 1].into_iter().filter(|&v| v < w) {
                            let i = ((sz * h + sy) * w + sx) * 4;
                            for (c, s) in sum.iter_mut().enumerate() {
                                let v = l.rgba[i + c];
                                *s += if srgb { linear[v as usize] } else { v as f64 };
                            }
                            n += 1.0;
                        }
                    }
                }
                for s in sum {
                    let mean = s / n;
                    rgba.push(if srgb {
                        encode_srgb(&linear, mean)
                    } else {
                        mean.round() as u8
                    });
                }
                rgba.push(255);
            }
        }
    }
    ktx2::Level { size, rgba }
}

/// Linear light of each sRGB byte (IEC 61966-2-1), from a portable `pow`
/// so that every machine builds the same mips.
fn srgb_table() -> [f64; 256] {
    std::array::from_fn(|i| {
        let c = i as f64 / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            libm::pow((c + 0.055) / 1.055, 2.4)
        }
    })
}

/// The sRGB byte whose linear light is nearest `v`.
fn encode_srgb(table: &[f64; 256], v: f64) -> u8 {
    let above = table.partition_point(|&t| t < v).min(255);
    if above > 0 && v - table[above - 1] <= table[above] - v {
        (above - 1) as u8
    } else {
        above as u8
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_and_mips_read_by_name() {
        for f in Format::ALL {
            assert_eq!(f.name().parse::<Format>().unwrap(), f);
        }
        assert!("png".parse::<Format>().is_err());
        assert_eq!("levels".parse::<Mips>().unwrap(), Mips::Levels);
        assert!("all".parse::<Mips>().is_err());
    }

    #[test]
    fn srgb_bytes_round_trip_through_linear_light() {
        let t = srgb_table();
        for b in 0..=255u8 {
            assert_eq!(encode_srgb(&t, t[b as usize]), b);
        }
        assert_eq!(encode_srgb(&t, -1.0), 0);
        assert_eq!(encode_srgb(&t, 2.0), 255);
    }

    /// Halving averages in linear light (black and white make a grey
    /// brighter than byte 128), keeps a uniform level, and stops at 1.
    #[test]
    fn halving_averages_in_linear_light() {
        let level = |size: [u32; 3], f: &dyn Fn(usize) -> u8| ktx2::Level {
            size,
            rgba: (0..(size[0] * size[1] * size[2]) as usize)
                .flat_map(|i| [f(i), f(i), f(i), 255])
                .collect(),
        };
        let checker = level([2, 2, 2], &|i| if i % 2 == 0 { 0 } else { 255 });
        let half = halve(&checker, true);
        assert_eq!(half.size, [1, 1, 1]);
        assert_eq!(half.rgba, vec![188, 188, 188, 255]);
        assert_eq!(halve(&checker, false).rgba, vec![128, 128, 128, 255]);
        let flat = level([5, 3, 1], &|_| 77);
        let half = halve(&flat, true);
        assert_eq!(half.size, [2, 1, 1]);
        assert!(half.rgba.chunks(4).all(|c| c == [77, 77, 77, 255]));
        let chain = mip_chain(vec![([5, 3, 1], vec![9; 45])], 3, true);
        assert_eq!(
            chain.iter().map(|l| l.size).collect::<Vec<_>>(),
            [[5, 3, 1], [2, 1, 1], [1, 1, 1]]
        );
    }
}
