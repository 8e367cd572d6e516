//! What a request names: regions, axes, oblique planes, filters, and the
//! limits every request is checked against, once, before any work.

use crate::error::{Error, Result};

/// Largest side of a slice or cut, in pixels.
pub const MAX_SLICE_SIDE: u32 = 4096;
/// Largest number of voxels in one region request.
pub const MAX_REGION_VOXELS: u64 = 16 << 20;
/// Coordinates must lie within ±2^31 (finest-level voxels).
pub const COORD_LIMIT: i64 = 1 << 31;

/// An axis-aligned box of voxels: `origin` is its lowest corner, `size` its
/// extent along x, y, z.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Region {
    /// Lowest corner.
    pub origin: [i64; 3],
    /// Extent along x, y, z (each ≥ 1).
    pub size: [u32; 3],
}

impl Region {
    /// Number of voxels, or `None` where the product of the sides does not
    /// fit a `u64` (three sides of 2^24 would wrap to 0).
    pub fn voxel_count(&self) -> Option<u64> {
        self.size
            .iter()
            .try_fold(1u64, |n, &side| n.checked_mul(side as u64))
    }

    /// The `width` × `height` slice normal to `axis` at `at`, with its
    /// (u, v) corner at (`u0`, `v0`); (u, v) is (x, y) for z, (y, z) for x
    /// and (z, x) for y.
    pub fn slice(axis: Axis, at: i64, u0: i64, v0: i64, width: u32, height: u32) -> Region {
        let (n, u, v) = axis.frame();
        let mut origin = [0i64; 3];
        let mut size = [1u32; 3];
        origin[n] = at;
        origin[u] = u0;
        origin[v] = v0;
        size[u] = width;
        size[v] = height;
        Region { origin, size }
    }

    /// Every voxel of the box, x fastest, then y, then z.
    pub fn voxels(&self) -> impl Iterator<Item = [i64; 3]> + '_ {
        let [w, h, d] = self.size.map(|s| s as i64);
        let o = self.origin;
        (0..d).flat_map(move |z| {
            (0..h).flat_map(move |y| (0..w).map(move |x| [o[0] + x, o[1] + y, o[2] + z]))
        })
    }
}

/// A volume axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Axis {
    /// The x axis (slices span y, z).
    X,
    /// The y axis (slices span z, x).
    Y,
    /// The z axis (slices span x, y).
    Z,
}

impl std::str::FromStr for Axis {
    type Err = Error;
    /// An axis by name, in either case.
    fn from_str(s: &str) -> Result<Self> {
        Axis::from_name(&s.to_ascii_lowercase()).ok_or_else(|| {
            Error::InvalidRequest(format!("unknown axis `{s}` (expected x, y or z)"))
        })
    }
}

impl Axis {
    /// The axis named exactly `x`, `y` or `z`.
    pub fn from_name(name: &str) -> Option<Axis> {
        match name {
            "x" => Some(Axis::X),
            "y" => Some(Axis::Y),
            "z" => Some(Axis::Z),
            _ => None,
        }
    }

    /// (normal axis index, u axis index, v axis index): u, v are (x, y) for
    /// z, (y, z) for x and (z, x) for y.
    pub fn frame(self) -> (usize, usize, usize) {
        match self {
            Axis::Z => (2, 0, 1),
            Axis::X => (0, 1, 2),
            Axis::Y => (1, 2, 0),
        }
    }
}

/// An oblique plane: pixel (i, j) samples `origin + i·u + j·v`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CutPlane {
    /// Position of pixel (0, 0), in voxels of the served level.
    pub origin: [f64; 3],
    /// Step per pixel along the image's horizontal axis.
    pub u: [f64; 3],
    /// Step per pixel along the image's vertical axis.
    pub v: [f64; 3],
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
}

/// How an oblique cut samples between voxel centres.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Filter {
    /// The nearest voxel.
    #[default]
    Nearest,
    /// Trilinear blend of the eight surrounding voxels.
    Trilinear,
}

pub(crate) fn check_side(width: u32, height: u32) -> Result<()> {
    if width == 0 || height == 0 {
        return Err(Error::InvalidRequest("width and height must be ≥ 1".into()));
    }
    if width > MAX_SLICE_SIDE || height > MAX_SLICE_SIDE {
        return Err(Error::TooLarge(format!(
            "{width}x{height} (each side ≤ {MAX_SLICE_SIDE})"
        )));
    }
    Ok(())
}

pub(crate) fn check_coords(p: &[i64; 3]) -> Result<()> {
    for &c in p {
        if !(-COORD_LIMIT..=COORD_LIMIT).contains(&c) {
            return Err(Error::InvalidRange {
                name: "coordinate",
                value: c as f64,
                min: -(COORD_LIMIT as f64),
                max: COORD_LIMIT as f64,
            });
        }
    }
    Ok(())
}

pub(crate) fn check_region(r: &Region) -> Result<()> {
    if r.size.contains(&0) {
        return Err(Error::InvalidRequest(
            "region size must be ≥ 1 on every axis".into(),
        ));
    }
    match r.voxel_count() {
        Some(voxels) if voxels <= MAX_REGION_VOXELS => {}
        _ => {
            let [w, h, d] = r.size;
            return Err(Error::TooLarge(format!(
                "{w}x{h}x{d} voxels (limit {MAX_REGION_VOXELS})"
            )));
        }
    }
    check_coords(&r.origin)?;
    let far = [
        r.origin[0] + r.size[0] as i64 - 1,
        r.origin[1] + r.size[1] as i64 - 1,
        r.origin[2] + r.size[2] as i64 - 1,
    ];
    check_coords(&far)
}
