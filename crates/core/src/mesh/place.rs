//! Where a mesh lies in texture space. The mesh is turned by `rotation`
//! (degrees about x, then y, then z, around its bounding box's centre),
//! scaled uniformly so that the longest side of its turned bounding box
//! spans `resolution` voxels of the level served, and moved so that the
//! box's lowest corner lies at `offset` (voxels). Voxel centres lie at
//! integer coordinates, so a mesh of resolution R spans R + 1 of them.

use super::Mesh;
use crate::error::{Error, Result};
use crate::request::COORD_LIMIT;

/// Largest resolution accepted (the budget of a request bounds it further).
pub const MAX_RESOLUTION: u32 = 1 << 16;

/// How a mesh is placed in texture space (see the module's description).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    /// Voxels spanned by the longest side of the (turned) bounding box.
    pub resolution: u32,
    /// Degrees about x, then y, then z.
    pub rotation: [f64; 3],
    /// Where the bounding box's lowest corner lies, in voxels.
    pub offset: [f64; 3],
}

impl Placement {
    /// `resolution` voxels, unturned, from the origin.
    pub fn new(resolution: u32) -> Placement {
        Placement {
            resolution,
            rotation: [0.0; 3],
            offset: [0.0; 3],
        }
    }

    /// Checks the numbers alone.
    pub(crate) fn check(&self) -> Result<()> {
        if !(1..=MAX_RESOLUTION).contains(&self.resolution) {
            return Err(Error::InvalidRange {
                name: "resolution",
                value: f64::from(self.resolution),
                min: 1.0,
                max: f64::from(MAX_RESOLUTION),
            });
        }
        let limit = (COORD_LIMIT - i64::from(MAX_RESOLUTION) - 2) as f64;
        for (name, v, lim) in [
            ("rotation", self.rotation, f64::MAX),
            ("offset", self.offset, limit),
        ] {
            if let Some(&c) = v.iter().find(|c| !c.is_finite() || c.abs() > lim) {
                return Err(Error::InvalidRange {
                    name,
                    value: c,
                    min: -lim,
                    max: lim,
                });
            }
        }
        Ok(())
    }

    /// The affine map from the mesh's coordinates into texture space.
    pub(crate) fn transform(&self, mesh: &Mesh) -> Transform {
        let [ax, ay, az] = self.rotation.map(f64::to_radians);
        let (sx, cx, sy, cy, sz, cz) = (ax.sin(), ax.cos(), ay.sin(), ay.cos(), az.sin(), az.cos());
        // Rz · Ry · Rx, rows.
        let r = [
            [cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx],
            [sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx],
            [-sy, cy * sx, cy * cx],
        ];
        let turn = |p: [f32; 3]| {
            let p = p.map(f64::from);
            r.map(|row| row[0] * p[0] + row[1] * p[1] + row[2] * p[2])
        };
        let (mut lo, mut hi) = ([f64::MAX; 3], [f64::MIN; 3]);
        for &p in mesh.positions() {
            let q = turn(p);
            for a in 0..3 {
                lo[a] = lo[a].min(q[a]);
                hi[a] = hi[a].max(q[a]);
            }
        }
        let longest = (0..3).map(|a| hi[a] - lo[a]).fold(0f64, f64::max);
        // A mesh with a triangle of non-zero area has a non-zero extent.
        let scale = f64::from(self.resolution) / longest;
        Transform {
            rows: r.map(|row| row.map(|c| c * scale)),
            shift: [0, 1, 2].map(|a| self.offset[a] - lo[a] * scale),
        }
    }
}

/// An affine map `p ↦ rows · p + shift`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Transform {
    rows: [[f64; 3]; 3],
    shift: [f64; 3],
}

impl Transform {
    /// Where `p` lands.
    pub(crate) fn apply(&self, p: [f32; 3]) -> [f64; 3] {
        let p = p.map(f64::from);
        [0, 1, 2].map(|a| {
            let r = self.rows[a];
            r[0] * p[0] + r[1] * p[1] + r[2] * p[2] + self.shift[a]
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_longest_side_spans_the_resolution_from_the_offset() {
        let p = vec![[-1.0, 2.0, 0.0], [3.0, 2.0, 0.0], [-1.0, 4.0, 1.0]];
        let mesh = Mesh::new(p, vec![[0, 1, 2]], None).unwrap();
        let mut place = Placement::new(100);
        place.offset = [10.0, 20.0, 30.0];
        let t = place.transform(&mesh);
        assert_eq!(t.apply([-1.0, 2.0, 0.0]), [10.0, 20.0, 30.0]);
        assert_eq!(t.apply([3.0, 2.0, 0.0]), [110.0, 20.0, 30.0]);
        assert_eq!(t.apply([-1.0, 4.0, 1.0]), [10.0, 70.0, 55.0]);
        // A quarter turn about z puts x's extent along y.
        place.rotation = [0.0, 0.0, 90.0];
        let q = place.transform(&mesh).apply([3.0, 2.0, 0.0]);
        assert!((q[1] - 120.0).abs() < 1e-9, "{q:?}");
    }

    #[test]
    fn absurd_numbers_are_refused() {
        for bad in [
            Placement::new(0),
            Placement::new(MAX_RESOLUTION + 1),
            Placement {
                offset: [f64::NAN, 0.0, 0.0],
                ..Placement::new(8)
            },
            Placement {
                offset: [0.0, 3e9, 0.0],
                ..Placement::new(8)
            },
            Placement {
                rotation: [f64::INFINITY, 0.0, 0.0],
                ..Placement::new(8)
            },
        ] {
            assert!(bad.check().is_err(), "{bad:?}");
        }
    }
}
