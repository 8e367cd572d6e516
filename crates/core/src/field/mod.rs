//! Fields of local frames that steer the synthesis (Lin 2009 ch. 4–5,
//! Zhang et al. 2011 §3–4). A field gives every point of space a rotation
//! from the world axes to a local frame; the texture is synthesized so
//! that, around each voxel, it looks in the local frame as the unguided
//! texture looks in the world frame: wood grain that runs along the
//! field's x axis, stripes that turn with it.
//!
//! A field is part of the texture's definition and a pure function of
//! position, so laziness and spatial determinism are untouched. Frames are
//! worked out with basic arithmetic and square roots only (the preset
//! angles' sines and cosines come from the `libm` crate once), so every
//! machine computes the same bits.

mod sketch;

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
pub use sketch::{Along, Curve, Sketch};

/// A rotation from the world frame to a local frame: its columns are the
/// local x, y and z axes in world coordinates.
pub(crate) type Frame = [[f64; 3]; 3];

/// The identity frame.
pub(crate) const IDENTITY: Frame = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// Largest preset coordinate or period, in voxels of the finest level.
const MAX_COORD: f64 = 1e9;

/// A field that the texture's local x, y and z axes follow. Positions and
/// lengths are in voxels of the finest level; angles in degrees.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Field {
    /// One rotation everywhere: the local x axis turned `angle` degrees
    /// about z, from x towards y (Lin's slant control).
    Slant {
        /// Counter-clockwise angle in the xy plane.
        angle: f64,
    },
    /// Local x runs around `axis` through `centre` (circles in the planes
    /// normal to it), local z along the axis (Lin's circular control).
    Circular {
        /// A point on the axis.
        #[serde(default)]
        centre: [f64; 3],
        /// The axis direction (need not be unit length).
        #[serde(default = "z_axis")]
        axis: [f64; 3],
    },
    /// Local x points away from `axis` through `centre`, local z along the
    /// axis (Lin's emissive control).
    Emissive {
        /// A point on the axis.
        #[serde(default)]
        centre: [f64; 3],
        /// The axis direction (need not be unit length).
        #[serde(default = "z_axis")]
        axis: [f64; 3],
    },
    /// Bands `period` voxels wide across x, in which local x is turned by
    /// `angle` and by −`angle` in turn (Lin's zigzag control).
    Zigzag {
        /// Counter-clockwise angle in the xy plane in even bands.
        angle: f64,
        /// Width of a band along x.
        period: f64,
    },
    /// One rotation everywhere that turns local x to `direction`, with
    /// local y kept in the world's xy plane (Lin's 3D slant control).
    Slant3d {
        /// Where local x points (need not be unit length).
        direction: [f64; 3],
    },
    /// Frames given along a few curves and interpolated smoothly between
    /// them (Zhang et al. §3).
    Sketch(Sketch),
}

impl std::str::FromStr for Field {
    type Err = Error;
    /// A field as text ([`Field::from_text`]), validated.
    fn from_str(s: &str) -> Result<Field> {
        let field = Field::from_text(s)?;
        field.validate()?;
        Ok(field)
    }
}

impl Field {
    /// A field as JSON (`{"kind":"slant","angle":30}`, the only form for a
    /// sketch), or a preset in short: `slant:ANGLE`, `circular[:CX,CY]`,
    /// `emissive[:CX,CY]`, `zigzag:ANGLE,PERIOD`, `slant3d:DX,DY,DZ` (the
    /// centres on the z axis through (CX, CY)). Only its form is checked:
    /// its numbers are checked by [`Field::validate`], as an object's are,
    /// so that both forms of one field are refused alike.
    pub fn from_text(s: &str) -> Result<Field> {
        let s = s.trim();
        let field = if s.starts_with('{') {
            serde_json::from_str(s).map_err(|e| Error::InvalidRequest(format!("field: {e}")))?
        } else {
            let (kind, args) = s.split_once(':').unwrap_or((s, ""));
            let nums: Vec<f64> = if args.is_empty() {
                Vec::new()
            } else {
                args.split(',')
                    .map(|v| v.trim().parse::<f64>())
                    .collect::<std::result::Result<_, _>>()
                    .map_err(|_| {
                        Error::InvalidRequest(format!("field: `{args}` is not a list of numbers"))
                    })?
            };
            let want = |n: &[usize]| -> Result<()> {
                if n.contains(&nums.len()) {
                    Ok(())
                } else {
                    Err(Error::InvalidRequest(format!(
                        "field: `{kind}` takes {} numbers, not {}",
                        n.iter()
                            .map(|v| v.to_string())
                            .collect::<Vec<_>>()
                            .join(" or "),
                        nums.len()
                    )))
                }
            };
            let centre = || {
                [
                    nums.first().copied().unwrap_or(0.0),
                    nums.get(1).copied().unwrap_or(0.0),
                    0.0,
                ]
            };
            match kind {
                "slant" => {
                    want(&[1])?;
                    Field::Slant { angle: nums[0] }
                }
                "circular" => {
                    want(&[0, 2])?;
                    Field::Circular {
                        centre: centre(),
                        axis: Z,
                    }
                }
                "emissive" => {
                    want(&[0, 2])?;
                    Field::Emissive {
                        centre: centre(),
                        axis: Z,
                    }
                }
                "zigzag" => {
                    want(&[2])?;
                    Field::Zigzag {
                        angle: nums[0],
                        period: nums[1],
                    }
                }
                "slant3d" => {
                    want(&[3])?;
                    Field::Slant3d {
                        direction: [nums[0], nums[1], nums[2]],
                    }
                }
                _ => {
                    return Err(Error::InvalidRequest(format!(
                        "field: unknown preset `{kind}` (expected slant, circular, emissive, \
                         zigzag, slant3d, or a JSON object)"
                    )));
                }
            }
        };
        Ok(field)
    }
}

fn z_axis() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}

impl Field {
    /// Checks the field's numbers: finite, in range, non-degenerate.
    pub fn validate(&self) -> Result<()> {
        let bad = |what: String| Err(Error::InvalidRequest(format!("field: {what}")));
        let finite = |name: &str, v: &[f64]| -> Result<()> {
            if v.iter().all(|x| x.is_finite() && x.abs() <= MAX_COORD) {
                Ok(())
            } else {
                bad(format!(
                    "{name} must be finite numbers of at most {MAX_COORD:e}"
                ))
            }
        };
        match self {
            Field::Slant { angle } => finite("angle", &[*angle]),
            Field::Circular { centre, axis } | Field::Emissive { centre, axis } => {
                finite("centre", centre)?;
                finite("axis", axis)?;
                if norm(*axis) < 1e-9 {
                    return bad("axis must not be zero".into());
                }
                Ok(())
            }
            Field::Zigzag { angle, period } => {
                finite("angle", &[*angle])?;
                finite("period", &[*period])?;
                if *period < 1.0 {
                    return bad(format!("period must be at least 1 voxel, not {period}"));
                }
                Ok(())
            }
            Field::Slant3d { direction } => {
                finite("direction", direction)?;
                if norm(*direction) < 1e-9 {
                    return bad("direction must not be zero".into());
                }
                Ok(())
            }
            Field::Sketch(s) => s.validate(),
        }
    }

    /// The field made ready to read: angles turned into directions, a
    /// sketch's frames interpolated over its grid.
    pub(crate) fn compile(&self) -> Result<FrameField> {
        self.validate()?;
        Ok(match *self {
            Field::Slant { angle } => FrameField::Constant(frame_from_x(in_plane(angle), Z)),
            Field::Circular { centre, axis } => FrameField::Around {
                centre,
                axis: unit(axis),
                radial: false,
            },
            Field::Emissive { centre, axis } => FrameField::Around {
                centre,
                axis: unit(axis),
                radial: true,
            },
            Field::Zigzag { angle, period } => FrameField::Bands {
                frames: [
                    frame_from_x(in_plane(angle), Z),
                    frame_from_x(in_plane(-angle), Z),
                ],
                period,
            },
            Field::Slant3d { direction } => FrameField::Constant(frame_from_x(unit(direction), Z)),
            Field::Sketch(ref s) => FrameField::Sketch(Box::new(s.solve()?)),
        })
    }
}

/// Where the point `p` of level `k` (in its voxels) sits, in voxels of the
/// finest level: a voxel stands for the 2^k-wide cube around its centre.
pub(crate) fn world(k: usize, p: [f64; 3]) -> [f64; 3] {
    let h = (1u64 << k) as f64;
    p.map(|v| (v + 0.5) * h - 0.5)
}

/// A [`Field`] ready to read at any point.
pub(crate) enum FrameField {
    /// The same frame everywhere.
    Constant(Frame),
    /// Circles or rays about an axis line.
    Around {
        centre: [f64; 3],
        axis: [f64; 3],
        radial: bool,
    },
    /// Alternating frames in bands across x.
    Bands { frames: [Frame; 2], period: f64 },
    /// Interpolated from sketched curves.
    Sketch(Box<sketch::SolvedSketch>),
    /// Another field read at the point moved into the period at the
    /// origin (finest voxels per axis): a periodic solid's field.
    Repeating(Box<FrameField>, [f64; 3]),
}

impl FrameField {
    /// This field, read modulo `period` when there is one.
    pub(crate) fn repeating(self, period: Option<&crate::period::Period>) -> FrameField {
        match period {
            None => self,
            Some(p) => FrameField::Repeating(Box::new(self), p.finest()),
        }
    }

    /// The frame, when it is the same everywhere.
    pub(crate) fn constant(&self) -> Option<&Frame> {
        match self {
            FrameField::Constant(f) => Some(f),
            FrameField::Repeating(f, _) => f.constant(),
            _ => None,
        }
    }

    /// The local frame of voxel `p` of level `k`.
    pub(crate) fn frame_at(&self, k: usize, p: [i64; 3]) -> Frame {
        self.frame(world(k, p.map(|v| v as f64)))
    }

    /// The local frame at `p` (voxels of the finest level).
    pub(crate) fn frame(&self, p: [f64; 3]) -> Frame {
        match self {
            FrameField::Constant(f) => *f,
            FrameField::Around {
                centre,
                axis,
                radial,
            } => {
                let r = sub(p, *centre);
                let along = dot(r, *axis);
                let out = sub(r, scale(*axis, along));
                let len = norm(out);
                if len < 1e-9 {
                    // On the axis every direction is as good: take the
                    // frame that the axis alone fixes.
                    return frame_from_z(*axis);
                }
                let out = scale(out, 1.0 / len);
                let x = if *radial { out } else { cross(*axis, out) };
                frame_from_xz(x, *axis)
            }
            FrameField::Bands { frames, period } => {
                let band = (p[0] / period).floor();
                frames[(band.rem_euclid(2.0)) as usize]
            }
            FrameField::Sketch(s) => s.frame(p),
            // Exact for p and p + period: both are sums of halves and
            // whole voxels, and the remainder of a float is exact.
            FrameField::Repeating(f, period) => {
                f.frame([0, 1, 2].map(|a| p[a].rem_euclid(period[a])))
            }
        }
    }
}

const Z: [f64; 3] = [0.0, 0.0, 1.0];

/// The unit vector `angle` degrees from x towards y.
fn in_plane(angle: f64) -> [f64; 3] {
    let a = angle.to_radians();
    [libm::cos(a), libm::sin(a), 0.0]
}

/// The frame whose x axis is `x` (unit), with y perpendicular to `up` where
/// it can be (world y when `x` is along `up`).
pub(crate) fn frame_from_x(x: [f64; 3], up: [f64; 3]) -> Frame {
    let mut y = cross(up, x);
    if norm(y) < 1e-6 {
        y = cross([1.0, 0.0, 0.0], x);
        if norm(y) < 1e-6 {
            y = cross([0.0, 1.0, 0.0], x);
        }
    }
    let y = unit(y);
    [x, y, cross(x, y)]
}

/// The frame with unit axes x and z (perpendicular), y completing it.
pub(crate) fn frame_from_xz(x: [f64; 3], z: [f64; 3]) -> Frame {
    [x, cross(z, x), z]
}

/// A frame whose z axis is `z` (unit).
fn frame_from_z(z: [f64; 3]) -> Frame {
    let x = frame_from_x(z, [1.0, 0.0, 0.0])[1];
    frame_from_xz(x, z)
}

/// `x` rounded to the nearest integer, halves away from zero, as
/// `f64::round` does, but in two inline instructions: without SSE4.1 the
/// standard one is a library call, and a correction in a field rounds
/// about 160 offsets.
#[inline(always)]
pub(crate) fn round(x: f64) -> i64 {
    (x + 0.5f64.copysign(x)) as i64
}

pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

pub(crate) fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

pub(crate) fn unit(a: [f64; 3]) -> [f64; 3] {
    scale(a, 1.0 / norm(a))
}

/// Asserts that `f` is a rotation: orthonormal axes, right-handed.
#[cfg(test)]
fn assert_rotation(f: &Frame) {
    for i in 0..3 {
        for j in 0..3 {
            let want = if i == j { 1.0 } else { 0.0 };
            assert!((dot(f[i], f[j]) - want).abs() < 1e-9, "{f:?}");
        }
    }
    // Right-handed: x × y = z.
    let z = cross(f[0], f[1]);
    assert!(sub(z, f[2]).iter().all(|v| v.abs() < 1e-9), "{f:?}");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_give_right_handed_frames_that_point_where_documented() {
        let fields = [
            Field::Slant { angle: 30.0 },
            Field::Circular {
                centre: [10.0, -4.0, 0.0],
                axis: [0.0, 0.0, 2.0],
            },
            Field::Emissive {
                centre: [10.0, -4.0, 0.0],
                axis: [1.0, 1.0, 0.0],
            },
            Field::Zigzag {
                angle: 45.0,
                period: 16.0,
            },
            Field::Slant3d {
                direction: [1.0, 2.0, 3.0],
            },
            Field::Slant3d {
                direction: [0.0, 0.0, -3.0],
            },
        ];
        for field in &fields {
            let f = field.compile().unwrap();
            for p in [[0.0, 0.0, 0.0], [10.0, -4.0, 5.0], [37.5, 12.0, -90.0]] {
                assert_rotation(&f.frame(p));
            }
        }
        let slant = fields[0].compile().unwrap().frame([5.0, 6.0, 7.0]);
        assert!((slant[0][0] - 30f64.to_radians().cos()).abs() < 1e-12);
        assert!((slant[0][1] - 0.5).abs() < 1e-12);
        // Circular: at +x of the centre, local x points along +y.
        let circ = fields[1].compile().unwrap().frame([20.0, -4.0, 3.0]);
        assert!(
            sub(circ[0], [0.0, 1.0, 0.0])
                .iter()
                .all(|v| v.abs() < 1e-12)
        );
        // Emissive: local x points away from the axis.
        let emis = fields[2].compile().unwrap().frame([10.0, -4.0, 7.0]);
        assert!(
            sub(emis[0], [0.0, 0.0, 1.0])
                .iter()
                .all(|v| v.abs() < 1e-12)
        );
        // Zigzag: the angle flips from one band to the next.
        let zig = fields[3].compile().unwrap();
        assert!(zig.frame([1.0, 0.0, 0.0])[0][1] > 0.7);
        assert!(zig.frame([17.0, 0.0, 0.0])[0][1] < -0.7);
        assert!(zig.frame([-1.0, 0.0, 0.0])[0][1] < -0.7);
        let s3 = fields[4].compile().unwrap().frame([0.0; 3]);
        assert!(
            sub(s3[0], unit([1.0, 2.0, 3.0]))
                .iter()
                .all(|v| v.abs() < 1e-12)
        );
    }

    #[test]
    fn bad_fields_are_refused_with_a_reason() {
        for (json, says) in [
            (r#"{"kind":"slant","angle":1e300}"#, "angle"),
            (r#"{"kind":"circular","axis":[0,0,0]}"#, "axis"),
            (r#"{"kind":"zigzag","angle":10,"period":0}"#, "period"),
            (r#"{"kind":"slant3d","direction":[0,0,0]}"#, "direction"),
        ] {
            let f: Field = serde_json::from_str(json).unwrap();
            let e = f.validate().unwrap_err().to_string();
            assert!(e.contains(says), "{json}: {e}");
        }
        // At and past the bounds.
        Field::Slant { angle: MAX_COORD }.validate().unwrap();
        assert!(
            Field::Slant {
                angle: -1.1 * MAX_COORD
            }
            .validate()
            .is_err()
        );
        let zigzag = |period| Field::Zigzag {
            angle: 10.0,
            period,
        };
        zigzag(1.0).validate().unwrap();
        assert!(zigzag(0.99).validate().is_err());
        for json in [
            r#"{"kind":"spiral"}"#,
            r#"{"kind":"slant","angle":1,"extra":2}"#,
            r#"{"kind":"slant"}"#,
        ] {
            assert!(serde_json::from_str::<Field>(json).is_err(), "{json}");
        }
    }

    #[test]
    fn short_forms_name_the_presets() {
        assert_eq!(
            "slant:30".parse::<Field>().unwrap(),
            Field::Slant { angle: 30.0 }
        );
        assert_eq!(
            "circular:64,-8".parse::<Field>().unwrap(),
            Field::Circular {
                centre: [64.0, -8.0, 0.0],
                axis: [0.0, 0.0, 1.0]
            }
        );
        assert_eq!(
            "zigzag:40, 32".parse::<Field>().unwrap(),
            Field::Zigzag {
                angle: 40.0,
                period: 32.0
            }
        );
        assert_eq!(
            r#"{"kind":"slant3d","direction":[1,0,1]}"#.parse::<Field>().unwrap(),
            Field::Slant3d {
                direction: [1.0, 0.0, 1.0]
            }
        );
        for bad in [
            "spiral",
            "slant",
            "slant:x",
            "zigzag:40",
            "emissive:1",
            "zigzag:40,0",
        ] {
            assert!(bad.parse::<Field>().is_err(), "{bad}");
        }
    }

    #[test]
    fn coarse_voxels_sit_at_their_centres() {
        assert_eq!(world(0, [3.0, 0.0, 0.0]), [3.0, 0.0, 0.0]);
        assert_eq!(world(1, [0.0, 0.0, 0.0]), [0.5; 3]);
        assert_eq!(world(2, [-1.0, -1.0, -1.0]), [-2.5; 3]);
    }

    #[test]
    fn rounding_takes_halves_away_from_zero() {
        for x in [
            -2.5, -1.5, -1.49, -0.5, -0.2, 0.0, 0.2, 0.5, 1.49, 1.5, 2.5, 7.75,
        ] {
            assert_eq!(round(x), x.round() as i64, "{x}");
        }
    }

    #[test]
    fn a_field_reads_back_as_written() {
        let f = Field::Circular {
            centre: [1.0, 2.0, 3.0],
            axis: [0.0, 0.0, 1.0],
        };
        let json = serde_json::to_string(&f).unwrap();
        assert_eq!(
            json,
            r#"{"kind":"circular","centre":[1.0,2.0,3.0],"axis":[0.0,0.0,1.0]}"#
        );
        assert_eq!(serde_json::from_str::<Field>(&json).unwrap(), f);
    }
}
