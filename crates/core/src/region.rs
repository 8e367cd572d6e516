//! Regions (Zhang et al. 2011, §6 and Fig. 15: bark outside, wood
//! within): a second solid fills a region of space, the first one the
//! rest, and the two mix across a band around the region's boundary.
//!
//! A region is a signed-distance function in texture space, in voxels of
//! level of detail 0, negative inside: a half-space, a sphere, a box with
//! rounded edges, a capped cylinder — each exact, so its value is the
//! Euclidean distance to the boundary, and a box of voxels lies wholly on
//! one side when its centre is farther from the boundary than its corners
//! are from its centre — or a shell of some thickness below a baked mesh's
//! surface, whose distance only a bake knows (see [`crate::mesh`]).
//!
//! A voxel's colour is `(1 − w)·outer + w·inner` with `w` the smoothstep
//! of its signed distance over the band (0 beyond half a band outside, 1
//! beyond half a band inside; a band of 0 is a hard boundary): a pure
//! function of the two solids, the region and the position. Where `w` is 0
//! or 1 the other solid is never read, so a request far from the boundary
//! synthesizes one solid only.

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};

/// Largest coordinate, radius or extent of a shape (voxels of level 0):
/// twice the coordinate limit, so that any shape reaching the served space
/// can be written.
pub const MAX_EXTENT: f64 = (1u64 << 32) as f64;
/// Widest transition band (voxels of level 0).
pub const MAX_BAND: f64 = 65536.0;
/// Thickest shell (voxels of level 0).
pub const MAX_THICKNESS: f64 = 65536.0;
/// Region textures nested in each other at most (a region texture whose
/// outer or inner solid is itself one counts one more).
pub const MAX_DEPTH: usize = 4;

/// The region the inner solid fills.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "shape", rename_all = "snake_case", deny_unknown_fields)]
pub enum Shape {
    /// The side of a plane its normal points away from.
    HalfSpace {
        /// A point of the plane.
        point: [f64; 3],
        /// The plane's normal, towards the outside (any length but 0).
        normal: [f64; 3],
    },
    /// A ball.
    Sphere {
        /// Its centre.
        centre: [f64; 3],
        /// Its radius (> 0).
        radius: f64,
    },
    /// An axis-aligned box whose edges and corners are rounded.
    Box {
        /// Its centre.
        centre: [f64; 3],
        /// Half its extent along x, y, z (each > 0).
        half_size: [f64; 3],
        /// Radius of the rounded edges (0 for sharp ones), at most the
        /// smallest half size.
        #[serde(default)]
        rounding: f64,
    },
    /// A cylinder with flat ends.
    Cylinder {
        /// The centre of one end.
        from: [f64; 3],
        /// The centre of the other end (not `from`).
        to: [f64; 3],
        /// Its radius (> 0).
        radius: f64,
    },
    /// Everything deeper than `thickness` below a baked mesh's surface:
    /// the surface shows the outer solid, the caps of a cut the inner one
    /// inside the shell. Only a bake has a surface to measure from.
    Shell {
        /// Depth of the shell (> 0).
        thickness: f64,
    },
}

/// How two solids share space: the region the inner one fills and the
/// width of the band across its boundary where they mix.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Split {
    /// The inner solid's region.
    pub region: Shape,
    /// Width of the transition band, centred on the boundary (0: a hard
    /// boundary).
    #[serde(default)]
    pub band: f64,
}

/// Which solids a set of points reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Side {
    /// Only the outer solid.
    Outer,
    /// Only the inner solid.
    Inner,
    /// Either, or both.
    Mixed,
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// The signed distance of a 2D point (x, y) to the negative quadrant: the
/// cross-section of a box or a capped cylinder, exact.
fn quadrant(q: &[f64]) -> f64 {
    let outside = q.iter().map(|c| c.max(0.0).powi(2)).sum::<f64>().sqrt();
    let inside = q.iter().copied().fold(f64::MIN, f64::max).min(0.0);
    outside + inside
}

fn range(name: &'static str, value: f64, min: f64, max: f64) -> Result<()> {
    if value.is_finite() && (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(Error::InvalidRange {
            name,
            value,
            min,
            max,
        })
    }
}

fn point(name: &'static str, p: [f64; 3]) -> Result<()> {
    p.iter()
        .try_for_each(|&c| range(name, c, -MAX_EXTENT, MAX_EXTENT))
}

/// Smallest radius or half size accepted: a thousandth of a voxel.
const MIN_SIZE: f64 = 1e-3;

impl Shape {
    /// Checks every number: finite, within [`MAX_EXTENT`], sizes positive.
    pub fn check(&self) -> Result<()> {
        match *self {
            Shape::HalfSpace { point: p, normal } => {
                point("region.point", p)?;
                point("region.normal", normal)?;
                if norm(normal) == 0.0 {
                    return Err(Error::InvalidParameter {
                        name: "region.normal",
                        reason: "must not be zero".into(),
                    });
                }
                Ok(())
            }
            Shape::Sphere { centre, radius } => {
                point("region.centre", centre)?;
                range("region.radius", radius, MIN_SIZE, MAX_EXTENT)
            }
            Shape::Box {
                centre,
                half_size,
                rounding,
            } => {
                point("region.centre", centre)?;
                for h in half_size {
                    range("region.half_size", h, MIN_SIZE, MAX_EXTENT)?;
                }
                let smallest = half_size.iter().copied().fold(f64::MAX, f64::min);
                range("region.rounding", rounding, 0.0, smallest)
            }
            Shape::Cylinder { from, to, radius } => {
                point("region.from", from)?;
                point("region.to", to)?;
                range("region.radius", radius, MIN_SIZE, MAX_EXTENT)?;
                if norm(sub(to, from)) < MIN_SIZE {
                    return Err(Error::InvalidParameter {
                        name: "region.to",
                        reason: "must differ from `from`: the cylinder needs a length".into(),
                    });
                }
                Ok(())
            }
            Shape::Shell { thickness } => {
                range("region.thickness", thickness, MIN_SIZE, MAX_THICKNESS)
            }
        }
    }

    /// Whether the region is measured from a baked mesh's surface.
    pub fn is_shell(&self) -> bool {
        matches!(self, Shape::Shell { .. })
    }

    /// Signed distance from `p` (voxels of level 0) to the boundary,
    /// negative inside; `None` for a shell, which needs a surface.
    pub(crate) fn distance(&self, p: [f64; 3]) -> Option<f64> {
        Some(match *self {
            Shape::HalfSpace { point, normal } => dot(sub(p, point), normal) / norm(normal),
            Shape::Sphere { centre, radius } => norm(sub(p, centre)) - radius,
            Shape::Box {
                centre,
                half_size,
                rounding,
            } => {
                let d = sub(p, centre);
                let q = [0, 1, 2].map(|a| d[a].abs() - (half_size[a] - rounding));
                quadrant(&q) - rounding
            }
            Shape::Cylinder { from, to, radius } => {
                let axis = sub(to, from);
                let length = norm(axis);
                let d = sub(p, from);
                let along = dot(d, axis) / length;
                let across = norm(sub(d, axis.map(|c| c * along / length)));
                quadrant(&[across - radius, (along - length / 2.0).abs() - length / 2.0])
            }
            Shape::Shell { .. } => return None,
        })
    }
}

impl Split {
    /// Checks the region and the band.
    pub fn check(&self) -> Result<()> {
        self.region.check()?;
        range("band", self.band, 0.0, MAX_BAND)
    }

    /// The inner solid's weight at signed distance `d`: 0 from half a band
    /// outside the boundary on, 1 from half a band inside, a smoothstep
    /// between (a step at the boundary for a band of 0).
    pub(crate) fn weight(&self, d: f64) -> f32 {
        if self.band == 0.0 {
            return if d < 0.0 { 1.0 } else { 0.0 };
        }
        let x = (0.5 - d / self.band).clamp(0.0, 1.0);
        (x * x * (3.0 - 2.0 * x)) as f32
    }

    /// Which solids the points within `radius` of `centre` read, from the
    /// signed distance `d` at the centre (an exact distance changes no
    /// faster than the position).
    pub(crate) fn side_near(&self, d: f64, radius: f64) -> Side {
        let half = self.band / 2.0;
        if d - radius >= half {
            Side::Outer
        } else if d + radius < -half {
            Side::Inner
        } else {
            Side::Mixed
        }
    }

    /// Which solids the voxels of level of detail `lod` in the box `lo..=hi`
    /// (voxel coordinates of that level) read; always mixed for a shell.
    pub(crate) fn side_of_box(&self, lod: u32, lo: [f64; 3], hi: [f64; 3]) -> Side {
        let (a, b) = (world(lod, lo), world(lod, hi));
        let centre = [0, 1, 2].map(|i| (a[i] + b[i]) / 2.0);
        let radius = norm(sub(b, a)) / 2.0;
        match self.region.distance(centre) {
            Some(d) => self.side_near(d, radius),
            None => Side::Mixed,
        }
    }
}

/// The centre of voxel `p` of level of detail `lod` in voxels of level 0
/// (where the region is defined).
pub(crate) fn world(lod: u32, p: [f64; 3]) -> [f64; 3] {
    crate::field::world(lod as usize, p)
}

/// Parses a shape written `sphere:CX,CY,CZ,R`, `box:CX,CY,CZ,HX,HY,HZ[,ROUNDING]`,
/// `cylinder:X0,Y0,Z0,X1,Y1,Z1,R`, `half_space:PX,PY,PZ,NX,NY,NZ` or
/// `shell:T`, or as its JSON object.
impl std::str::FromStr for Shape {
    type Err = Error;
    fn from_str(s: &str) -> Result<Shape> {
        let bad = |reason: String| Error::InvalidParameter {
            name: "region",
            reason,
        };
        if s.trim_start().starts_with('{') {
            return serde_json::from_str(s).map_err(|e| bad(e.to_string()));
        }
        let (name, numbers) = s.split_once(':').ok_or_else(|| {
            bad(format!(
                "`{s}`: expected SHAPE:NUMBERS (e.g. sphere:0,0,0,32)"
            ))
        })?;
        let v: Vec<f64> = numbers
            .split(',')
            .map(|n| n.trim().parse::<f64>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|e| bad(format!("`{numbers}`: {e}")))?;
        let three = |i: usize| [v[i], v[i + 1], v[i + 2]];
        let shape = match (name, v.len()) {
            ("sphere", 4) => Shape::Sphere {
                centre: three(0),
                radius: v[3],
            },
            ("box", 6 | 7) => Shape::Box {
                centre: three(0),
                half_size: three(3),
                rounding: v.get(6).copied().unwrap_or(0.0),
            },
            ("cylinder", 7) => Shape::Cylinder {
                from: three(0),
                to: three(3),
                radius: v[6],
            },
            ("half_space" | "half-space", 6) => Shape::HalfSpace {
                point: three(0),
                normal: three(3),
            },
            ("shell", 1) => Shape::Shell { thickness: v[0] },
            _ => {
                return Err(bad(format!(
                    "`{s}`: expected sphere:CX,CY,CZ,R, box:CX,CY,CZ,HX,HY,HZ[,ROUNDING], \
                     cylinder:X0,Y0,Z0,X1,Y1,Z1,R, half_space:PX,PY,PZ,NX,NY,NZ or shell:T"
                )));
            }
        };
        shape.check()?;
        Ok(shape)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn split(region: Shape, band: f64) -> Split {
        Split { region, band }
    }

    #[test]
    fn distances_are_exact_on_simple_points() {
        let sphere: Shape = "sphere:1,2,3,4".parse().unwrap();
        assert_eq!(sphere.distance([1.0, 2.0, 3.0]), Some(-4.0));
        assert_eq!(sphere.distance([1.0, 2.0, 10.0]), Some(3.0));
        let plane: Shape = "half_space:0,0,5,0,0,2".parse().unwrap();
        assert_eq!(plane.distance([9.0, -9.0, 8.0]), Some(3.0));
        assert_eq!(plane.distance([9.0, -9.0, 1.0]), Some(-4.0));
        let sharp: Shape = "box:0,0,0,2,3,4".parse().unwrap();
        assert_eq!(sharp.distance([0.0, 0.0, 0.0]), Some(-2.0));
        assert_eq!(sharp.distance([5.0, 0.0, 0.0]), Some(3.0));
        assert_eq!(sharp.distance([5.0, 7.0, 0.0]), Some(5.0));
        let round: Shape = "box:0,0,0,2,2,2,1".parse().unwrap();
        // Beyond a rounded corner the distance is to the corner's sphere.
        let d = round.distance([3.0, 3.0, 3.0]).unwrap();
        assert!((d - (12f64.sqrt() - 1.0)).abs() < 1e-12, "{d}");
        assert_eq!(round.distance([5.0, 0.0, 0.0]), Some(3.0));
        let cyl: Shape = "cylinder:0,0,0,0,0,10,2".parse().unwrap();
        assert_eq!(cyl.distance([0.0, 0.0, 5.0]), Some(-2.0));
        assert_eq!(cyl.distance([5.0, 0.0, 5.0]), Some(3.0));
        assert_eq!(cyl.distance([0.0, 0.0, 13.0]), Some(3.0));
        assert_eq!(cyl.distance([6.0, 0.0, 13.0]), Some(5.0));
        assert_eq!("shell:3".parse::<Shape>().unwrap().distance([0.0; 3]), None);
    }

    #[test]
    fn distances_change_no_faster_than_the_position() {
        // What the one-side test of a box relies on.
        let shapes: Vec<Shape> = [
            "sphere:3,-4,5,20",
            "half_space:1,2,3,1,-2,0.5",
            "box:0,0,0,10,20,5,3",
            "cylinder:-5,0,3,20,10,-7,6",
        ]
        .iter()
        .map(|s| s.parse().unwrap())
        .collect();
        let mut h = 1u64;
        let mut next = || {
            h = crate::hash::mix(h);
            (h >> 11) as f64 / (1u64 << 53) as f64 * 80.0 - 40.0
        };
        for s in &shapes {
            for _ in 0..2000 {
                let a = [next(), next(), next()];
                let b = [next(), next(), next()];
                let (da, db) = (s.distance(a).unwrap(), s.distance(b).unwrap());
                assert!(
                    (da - db).abs() <= norm(sub(a, b)) + 1e-9,
                    "{s:?} {a:?} {b:?}"
                );
            }
        }
    }

    #[test]
    fn the_band_mixes_monotonically_and_ends_exactly() {
        let s = split("sphere:0,0,0,10".parse().unwrap(), 8.0);
        assert_eq!(s.weight(4.0), 0.0);
        assert_eq!(s.weight(100.0), 0.0);
        assert_eq!(s.weight(-4.0), 1.0);
        assert_eq!(s.weight(-100.0), 1.0);
        assert_eq!(s.weight(0.0), 0.5);
        let mut last = 0.0;
        for i in 0..=800 {
            let w = s.weight(4.0 - f64::from(i) / 100.0);
            assert!(w >= last, "{i}");
            last = w;
        }
        let hard = split("sphere:0,0,0,10".parse().unwrap(), 0.0);
        assert_eq!(hard.weight(0.0), 0.0);
        assert_eq!(hard.weight(-1e-9), 1.0);
    }

    #[test]
    fn boxes_wholly_on_one_side_are_told_apart() {
        let s = split("sphere:0,0,0,100".parse().unwrap(), 10.0);
        assert_eq!(s.side_of_box(0, [-10.0; 3], [10.0; 3]), Side::Inner);
        assert_eq!(s.side_of_box(0, [200.0; 3], [300.0; 3]), Side::Outer);
        assert_eq!(
            s.side_of_box(0, [90.0, 0.0, 0.0], [99.0, 0.0, 0.0]),
            Side::Mixed
        );
        // Level 1 voxels are twice as far out: 40 is at 80.5, 48 at 96.5.
        assert_eq!(
            s.side_of_box(1, [40.0, 0.0, 0.0], [40.0, 0.0, 0.0]),
            Side::Inner
        );
        assert_eq!(
            s.side_of_box(1, [48.0, 0.0, 0.0], [48.0, 0.0, 0.0]),
            Side::Mixed
        );
        assert_eq!(
            s.side_of_box(1, [60.0, 0.0, 0.0], [61.0, 0.0, 0.0]),
            Side::Outer
        );
        let shell = split("shell:4".parse().unwrap(), 2.0);
        assert_eq!(shell.side_of_box(0, [0.0; 3], [1.0; 3]), Side::Mixed);
    }

    #[test]
    fn bad_shapes_are_refused_by_name() {
        let name = |s: &str| match s.parse::<Shape>() {
            Err(Error::InvalidRange { name, .. } | Error::InvalidParameter { name, .. }) => name,
            other => panic!("{s}: {other:?}"),
        };
        assert_eq!(name("sphere:0,0,0,-1"), "region.radius");
        assert_eq!(name("sphere:0,0,NaN,1"), "region.centre");
        assert_eq!(name("box:0,0,0,1,1,1,2"), "region.rounding");
        assert_eq!(name("cylinder:1,1,1,1,1,1,3"), "region.to");
        assert_eq!(name("half_space:0,0,0,0,0,0"), "region.normal");
        assert_eq!(name("shell:0"), "region.thickness");
        assert_eq!(name("cube:1,2,3"), "region");
        assert_eq!(name("sphere:1,2"), "region");
        let json: Shape = r#"{"shape":"sphere","centre":[1,2,3],"radius":4}"#.parse().unwrap();
        assert_eq!(json, "sphere:1,2,3,4".parse().unwrap());
        assert!(
            r#"{"shape":"sphere","centre":[1,2,3],"radius":4,"x":1}"#
                .parse::<Shape>()
                .is_err()
        );
        let band = Split {
            region: "sphere:0,0,0,1".parse().unwrap(),
            band: f64::NAN,
        };
        assert!(matches!(
            band.check(),
            Err(Error::InvalidRange { name: "band", .. })
        ));
    }
}
