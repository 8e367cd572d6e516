//! What a texture is asked for, as one value: a [`Request`] is a box of
//! voxels, an axis slice, an oblique cut or a set of voxels, checked
//! against every limit once, when it is built. [`crate::Texture`] renders,
//! plans and estimates any request through the same three methods, and a
//! request names itself ([`Request::key`]) for caches and validators.
//!
//! A new kind of request (a surface shell, an export) is a new
//! [`RequestKind`] variant with its checks in [`Request::new`] and its
//! arms in the texture's three methods; nothing else changes shape.

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};

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
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
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

    /// The axis's name, `x`, `y` or `z`.
    pub fn name(self) -> &'static str {
        match self {
            Axis::X => "x",
            Axis::Y => "y",
            Axis::Z => "z",
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

/// A rectangle of a plane: pixel (i, j) is (u0 + i, v0 + j).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Window {
    /// First u coordinate.
    pub u0: i64,
    /// First v coordinate.
    pub v0: i64,
    /// Pixels along u.
    pub width: u32,
    /// Pixels along v.
    pub height: u32,
}

impl Window {
    /// The `width` × `height` rectangle from (`u0`, `v0`).
    pub const fn new(u0: i64, v0: i64, width: u32, height: u32) -> Window {
        Window {
            u0,
            v0,
            width,
            height,
        }
    }
}

/// An axis-aligned slice: the plane `axis = at`, seen through `window` in
/// its (u, v) coordinates (see [`Axis::frame`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Slice {
    /// The plane's normal.
    pub axis: Axis,
    /// The plane's coordinate along `axis`.
    pub at: i64,
    /// The part of the plane asked for.
    pub window: Window,
}

impl Slice {
    /// The one-voxel-thick box the slice covers.
    pub fn region(&self) -> Region {
        let w = self.window;
        Region::slice(self.axis, self.at, w.u0, w.v0, w.width, w.height)
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

impl CutPlane {
    /// Where pixel (i, j) samples.
    pub fn at(&self, i: u32, j: u32) -> [f64; 3] {
        [0, 1, 2].map(|a| self.origin[a] + f64::from(i) * self.u[a] + f64::from(j) * self.v[a])
    }
}

/// How an oblique cut samples between voxel centres.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Filter {
    /// The nearest voxel.
    #[default]
    Nearest,
    /// Trilinear blend of the eight surrounding voxels.
    Trilinear,
}

/// An oblique cut: a plane and how it samples the voxels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cut {
    /// Where the pixels lie.
    pub plane: CutPlane,
    /// How each pixel reads the voxels around it.
    pub filter: Filter,
}

/// What a request asks for. Build a [`Request`] from it to use it.
#[derive(Clone, Debug, PartialEq)]
pub enum RequestKind {
    /// A box of voxels, answered x fastest, then y, then z.
    Region(Region),
    /// An axis slice, answered as rows of its window (u fastest).
    Slice(Slice),
    /// An oblique cut, answered as rows of its plane (i fastest).
    Cut(Cut),
    /// Voxels anywhere, answered in the order given.
    Points(Vec<[i64; 3]>),
    /// A mesh's surface: the texels of its baked texture, row by row, or
    /// its vertices in order (see [`crate::mesh::Bake`]).
    Bake(crate::mesh::Bake),
}

/// A request that passed every check: within the coordinate limit, of a
/// size the engine answers, and well formed. Answers are RGB8, three bytes
/// per voxel or pixel, in the order [`RequestKind`] gives.
#[derive(Clone, Debug, PartialEq)]
pub struct Request(RequestKind);

impl Request {
    /// Checks `kind` and makes it a request.
    pub fn new(kind: RequestKind) -> Result<Request> {
        match &kind {
            RequestKind::Region(r) => check_region(r)?,
            RequestKind::Slice(s) => check_slice(s)?,
            RequestKind::Cut(c) => check_cut(&c.plane)?,
            RequestKind::Points(p) => check_points(p)?,
            // Checked when it was built.
            RequestKind::Bake(_) => {}
        }
        Ok(Request(kind))
    }

    /// A box of voxels.
    pub fn region(region: Region) -> Result<Request> {
        Request::new(RequestKind::Region(region))
    }

    /// The slice of the plane `axis = at` seen through `window`.
    pub fn slice(axis: Axis, at: i64, window: Window) -> Result<Request> {
        Request::new(RequestKind::Slice(Slice { axis, at, window }))
    }

    /// An oblique cut.
    pub fn cut(plane: CutPlane, filter: Filter) -> Result<Request> {
        Request::new(RequestKind::Cut(Cut { plane, filter }))
    }

    /// Voxels anywhere.
    pub fn points(points: Vec<[i64; 3]>) -> Result<Request> {
        Request::new(RequestKind::Points(points))
    }

    /// A mesh baked from the solid.
    pub fn bake(bake: crate::mesh::Bake) -> Result<Request> {
        Request::new(RequestKind::Bake(bake))
    }

    /// What is asked for.
    pub fn kind(&self) -> &RequestKind {
        &self.0
    }

    /// The answer's extent: (width, height, depth) of a box, (width,
    /// height, 1) of an image, (count, 1, 1) of points.
    pub fn size(&self) -> [u32; 3] {
        match &self.0 {
            RequestKind::Region(r) => r.size,
            RequestKind::Slice(s) => [s.window.width, s.window.height, 1],
            RequestKind::Cut(c) => [c.plane.width, c.plane.height, 1],
            // At most MAX_REGION_VOXELS points.
            RequestKind::Points(p) => [p.len() as u32, 1, 1],
            RequestKind::Bake(b) => b.size(),
        }
    }

    /// Voxels (or pixels) in the answer.
    pub fn voxels(&self) -> u64 {
        self.size().iter().map(|&s| u64::from(s)).product()
    }

    /// A name of this request answered at level of detail `lod`, equal for
    /// equal answers of the same texture and different otherwise: what a
    /// cache or an HTTP validator keys the answer by.
    pub fn key(&self, lod: u32) -> String {
        match &self.0 {
            RequestKind::Region(r) => {
                let ([x, y, z], [w, h, d]) = (r.origin, r.size);
                format!("region/{x}/{y}/{z}/{w}/{h}/{d}/{lod}")
            }
            RequestKind::Slice(s) => {
                let Window {
                    u0,
                    v0,
                    width,
                    height,
                } = s.window;
                let (axis, at) = (s.axis.name(), s.at);
                format!("slice/{axis}/{at}/{u0}/{v0}/{width}/{height}/{lod}")
            }
            RequestKind::Cut(Cut { plane, filter }) => {
                // Bit patterns make the key exact for any float spelling
                // (and one key for 0 and -0).
                let bits = |a: [f64; 3]| a.map(|x| format!("{:x}", (x + 0.0).to_bits())).join(",");
                let (w, h) = (plane.width, plane.height);
                format!(
                    "cut/{}/{}/{}/{w}/{h}/{lod}/{filter:?}",
                    bits(plane.origin),
                    bits(plane.u),
                    bits(plane.v)
                )
            }
            RequestKind::Points(p) => {
                let bytes: Vec<u8> = p.iter().flatten().flat_map(|c| c.to_le_bytes()).collect();
                let n = p.len();
                format!("points/{n}/{:x}/{lod}", crate::hash::fingerprint(&bytes))
            }
            RequestKind::Bake(b) => b.key(lod),
        }
    }
}

impl TryFrom<RequestKind> for Request {
    type Error = Error;
    fn try_from(kind: RequestKind) -> Result<Request> {
        Request::new(kind)
    }
}

fn check_side(width: u32, height: u32) -> Result<()> {
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

/// Checks that `first..=first + len - 1` lies within the coordinate limit.
fn check_span(name: &'static str, first: i64, len: u32) -> Result<()> {
    for c in [first, first + i64::from(len) - 1] {
        if !(-COORD_LIMIT..=COORD_LIMIT).contains(&c) {
            return Err(Error::InvalidRange {
                name,
                value: c as f64,
                min: -(COORD_LIMIT as f64),
                max: COORD_LIMIT as f64,
            });
        }
    }
    Ok(())
}

fn check_region(r: &Region) -> Result<()> {
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
    for (a, name) in ["x", "y", "z"].into_iter().enumerate() {
        check_span(name, r.origin[a], r.size[a])?;
    }
    Ok(())
}

fn check_slice(s: &Slice) -> Result<()> {
    let w = s.window;
    check_side(w.width, w.height)?;
    check_span("at", s.at, 1)?;
    check_span("u0", w.u0, w.width)?;
    check_span("v0", w.v0, w.height)
}

fn check_cut(plane: &CutPlane) -> Result<()> {
    check_side(plane.width, plane.height)?;
    for (name, a) in [("origin", plane.origin), ("u", plane.u), ("v", plane.v)] {
        if !a.iter().all(|c| c.is_finite()) {
            return Err(Error::InvalidParameter {
                name,
                reason: "components must be finite".into(),
            });
        }
    }
    check_spans_a_plane(plane.u, plane.v)?;
    // Every sample within ±2^31, like every integer coordinate (a trilinear
    // sample exactly at +2^31 also reads its neighbour at weight 0). The
    // samples lie in the parallelogram of the four corner pixels.
    let limit = COORD_LIMIT as f64;
    let (i, j) = (plane.width - 1, plane.height - 1);
    for p in [(0, 0), (i, 0), (0, j), (i, j)].map(|(i, j)| plane.at(i, j)) {
        if let Some(&c) = p.iter().find(|c| c.abs() > limit) {
            return Err(Error::InvalidRange {
                name: "cut coordinate",
                value: c,
                min: -limit,
                max: limit,
            });
        }
    }
    Ok(())
}

/// Checks that `u` and `v` span a plane: neither is zero and they are not
/// parallel (a degenerate cut would show one line of voxels stretched).
fn check_spans_a_plane(u: [f64; 3], v: [f64; 3]) -> Result<()> {
    // Scaled by their largest component so that no product overflows.
    let unit = |a: [f64; 3]| {
        let m = a.iter().fold(0f64, |m, x| m.max(x.abs()));
        (m > 0.0).then(|| a.map(|x| x / m))
    };
    let zero = |name| Error::InvalidParameter {
        name,
        reason: "must not be zero".into(),
    };
    let a = unit(u).ok_or_else(|| zero("u"))?;
    let b = unit(v).ok_or_else(|| zero("v"))?;
    let norm = |x: [f64; 3]| (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
    let cross = [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ];
    // |u × v| = |u||v| sin θ: parallel below about 1e-9 rad.
    if norm(cross) <= 1e-9 * norm(a) * norm(b) {
        return Err(Error::InvalidParameter {
            name: "v",
            reason: "is parallel to `u`: they must span a plane".into(),
        });
    }
    Ok(())
}

fn check_points(points: &[[i64; 3]]) -> Result<()> {
    if points.len() as u64 > MAX_REGION_VOXELS {
        return Err(Error::TooLarge(format!(
            "{} points (limit {MAX_REGION_VOXELS})",
            points.len()
        )));
    }
    for p in points {
        for (a, name) in ["x", "y", "z"].into_iter().enumerate() {
            check_span(name, p[a], 1)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plane(u: [f64; 3], v: [f64; 3]) -> CutPlane {
        CutPlane {
            origin: [0.0; 3],
            u,
            v,
            width: 8,
            height: 8,
        }
    }

    #[test]
    fn slices_stay_within_the_coordinate_limit() {
        let ok = |u0, width| Request::slice(Axis::Z, 0, Window::new(u0, 0, width, 1)).is_ok();
        assert!(ok(COORD_LIMIT - 9, 10));
        assert!(!ok(COORD_LIMIT - 9, 11));
        assert!(ok(-COORD_LIMIT, 4096));
        assert!(!ok(0, 0));
        assert!(!ok(0, MAX_SLICE_SIDE + 1));
        let far = Request::slice(Axis::X, COORD_LIMIT + 1, Window::new(0, 0, 1, 1));
        assert!(matches!(far, Err(Error::InvalidRange { name: "at", .. })));
    }

    #[test]
    fn regions_are_bounded_without_overflow() {
        let region = |size| {
            Request::region(Region {
                origin: [0; 3],
                size,
            })
        };
        assert!(region([256, 256, 256]).is_ok());
        assert!(matches!(region([512; 3]), Err(Error::TooLarge(_))));
        assert!(matches!(region([1 << 24; 3]), Err(Error::TooLarge(_))));
        assert!(region([0, 1, 1]).is_err());
        let far = Request::region(Region {
            origin: [0, COORD_LIMIT, 0],
            size: [1, 2, 1],
        });
        assert!(matches!(far, Err(Error::InvalidRange { name: "y", .. })));
    }

    #[test]
    fn cuts_must_span_a_finite_plane_within_the_limit() {
        let cut = |u, v| Request::cut(plane(u, v), Filter::Nearest);
        assert!(cut([1.0, 0.0, 0.0], [0.0, 1.0, 0.0]).is_ok());
        assert!(cut([1.0, 1e-6, 0.0], [1.0, 0.0, 0.0]).is_ok());
        for (u, v, name) in [
            ([0.0; 3], [0.0, 1.0, 0.0], "u"),
            ([1.0, 0.0, 0.0], [0.0; 3], "v"),
            ([1.0, 0.0, 0.0], [2.0, 0.0, 0.0], "v"),
            ([1.0, 1.0, 0.0], [-2.0, -2.0, 0.0], "v"),
            ([f64::NAN, 0.0, 0.0], [0.0, 1.0, 0.0], "u"),
        ] {
            match cut(u, v) {
                Err(Error::InvalidParameter { name: n, .. }) => assert_eq!(n, name),
                other => panic!("{u:?} {v:?}: {other:?}"),
            }
        }
        let mut far = plane([1000.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        far.origin = [COORD_LIMIT as f64 - 5000.0, 0.0, 0.0];
        assert!(matches!(
            Request::cut(far, Filter::Nearest),
            Err(Error::InvalidRange { .. })
        ));
    }

    #[test]
    fn keys_tell_requests_apart() {
        let slice = Request::slice(Axis::Y, 3, Window::new(1, 2, 8, 9)).unwrap();
        assert_eq!(slice.key(1), "slice/y/3/1/2/8/9/1");
        assert_eq!(slice.size(), [8, 9, 1]);
        let region = Request::region(Region {
            origin: [1, -2, 3],
            size: [4, 5, 6],
        })
        .unwrap();
        assert_eq!(region.key(0), "region/1/-2/3/4/5/6/0");
        assert_eq!(region.voxels(), 120);
        let cut = |origin: [f64; 3], filter| {
            let mut p = plane([1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
            p.origin = origin;
            Request::cut(p, filter).unwrap().key(0)
        };
        assert_eq!(
            cut([0.0; 3], Filter::Nearest),
            cut([-0.0; 3], Filter::Nearest)
        );
        assert_ne!(
            cut([0.0; 3], Filter::Nearest),
            cut([0.0; 3], Filter::Trilinear)
        );
        assert_ne!(
            cut([0.0; 3], Filter::Nearest),
            cut([0.5, 0.0, 0.0], Filter::Nearest)
        );
        let points = |p: Vec<[i64; 3]>| Request::points(p).unwrap().key(0);
        assert_ne!(points(vec![[1, 2, 3]]), points(vec![[3, 2, 1]]));
    }
}
