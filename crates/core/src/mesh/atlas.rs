//! Which surface point each texel of a baked texture shows.
//!
//! A texel samples the solid at the point of its triangle nearest to the
//! texel's centre, inside a triangle the point under the centre itself.
//! Texels just outside a triangle (its gutter) thus repeat the colours of
//! its edge, so that filtering across the edge of a chart reads the same
//! colours as inside it: no seam shows however the charts lie.
//!
//! The generated atlas gives each triangle its own right isosceles chart,
//! two to a square cell (one each side of the diagonal), with a texel of
//! gutter along the cell's border and two across the diagonal, so that a
//! bilinear read inside one chart never reaches its neighbour's texels.

use crate::error::{Error, Result};

/// Texels of gutter a mesh's own charts get around them.
const GUTTER: f32 = 2.0;
/// Smallest cell of the generated atlas: charts with legs of two texels.
pub(super) const MIN_CELL: u32 = 6;

/// Where the texels of a baked texture lie on the mesh.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum Layout {
    /// The generated atlas: `grid`² cells of `cell` texels, two triangles
    /// to a cell in order, row by row.
    Cells {
        /// Texture side.
        side: u32,
        /// Cells per row.
        grid: u32,
        /// Cell side in texels.
        cell: u32,
    },
    /// The mesh's own texture coordinates: the triangle each texel shows
    /// (`u32::MAX` where none is within the gutter).
    Owners {
        /// Texture side.
        side: u32,
        /// Triangle per texel, row by row.
        owner: Vec<u32>,
    },
}

impl Layout {
    /// The generated atlas of `triangles` triangles on a `side`² texture.
    pub(super) fn cells(triangles: usize, side: u32) -> Result<Layout> {
        let grid = (triangles.div_ceil(2) as f64).sqrt().ceil().max(1.0) as u32;
        let cell = side / grid;
        if cell < MIN_CELL {
            return Err(Error::TooLarge(format!(
                "{triangles} triangles need a texture of at least {0}×{0} texels in a \
                 generated atlas (texture_size {side}); bake vertex colours instead",
                grid * MIN_CELL
            )));
        }
        Ok(Layout::Cells { side, grid, cell })
    }

    /// The mesh's own charts: each texel goes to the triangle under its
    /// centre, or within [`GUTTER`] texels of it, the nearest one.
    pub(super) fn owners(uv_triangles: &[[[f32; 2]; 3]], side: u32) -> Layout {
        let s = side as usize;
        let mut owner = vec![u32::MAX; s * s];
        let mut best = vec![f32::INFINITY; s * s];
        for (i, uv) in uv_triangles.iter().enumerate() {
            let t = uv.map(|p| p.map(|c| c * side as f32));
            let lo = |a: usize| (t.iter().map(|p| p[a]).fold(f32::MAX, f32::min) - GUTTER).floor();
            let hi = |a: usize| (t.iter().map(|p| p[a]).fold(f32::MIN, f32::max) + GUTTER).ceil();
            let clamp = |v: f32| v.clamp(0.0, side as f32) as usize;
            for y in clamp(lo(1))..clamp(hi(1)) {
                for x in clamp(lo(0))..clamp(hi(0)) {
                    let c = [x as f32 + 0.5, y as f32 + 0.5];
                    let q = on_triangle(t, c);
                    let d = ((q[0] - c[0]).powi(2) + (q[1] - c[1]).powi(2)).sqrt();
                    let at = y * s + x;
                    if d <= GUTTER && d < best[at] {
                        best[at] = d;
                        owner[at] = i as u32;
                    }
                }
            }
        }
        Layout::Owners { side, owner }
    }

    /// Texture side in texels.
    pub(super) fn side(&self) -> u32 {
        match self {
            Layout::Cells { side, .. } | Layout::Owners { side, .. } => *side,
        }
    }

    /// The chart corners of triangle `i` in the generated atlas, in texels.
    pub(super) fn chart(cell: u32, grid: u32, i: usize) -> [[f32; 2]; 3] {
        let pair = (i / 2) as u32;
        let o = [(pair % grid * cell) as f32, (pair / grid * cell) as f32];
        let c = cell as f32;
        let local = if i.is_multiple_of(2) {
            [[1.0, 1.0], [c - 3.0, 1.0], [1.0, c - 3.0]]
        } else {
            [[c - 1.0, c - 1.0], [3.0, c - 1.0], [c - 1.0, 3.0]]
        };
        local.map(|p| [o[0] + p[0], o[1] + p[1]])
    }

    /// The triangle texel `at` shows and where on it (barycentric weights
    /// of its second and third corners), given each triangle's chart in
    /// texels (`charts`, for the mesh's own UVs).
    pub(super) fn texel(
        &self,
        at: usize,
        triangles: usize,
        charts: &dyn Fn(usize) -> [[f32; 2]; 3],
    ) -> Option<(usize, [f32; 2])> {
        let (side, tri) = match self {
            Layout::Cells { side, grid, cell } => {
                let (x, y) = ((at % *side as usize) as u32, (at / *side as usize) as u32);
                let (cx, cy) = (x / cell, y / cell);
                if cx >= *grid || cy >= *grid {
                    return None;
                }
                let pair = (cy * grid + cx) as usize;
                let (lx, ly) = (x % cell, y % cell);
                let second = lx + ly + 1 >= *cell && pair * 2 + 1 < triangles;
                let tri = pair * 2 + usize::from(second);
                if tri >= triangles {
                    return None;
                }
                (*side, tri)
            }
            Layout::Owners { side, owner } => match owner[at] {
                u32::MAX => return None,
                t => (*side, t as usize),
            },
        };
        let c = [
            (at % side as usize) as f32 + 0.5,
            (at / side as usize) as f32 + 0.5,
        ];
        let t = charts(tri);
        Some((tri, weights(t, on_triangle(t, c))))
    }
}

/// The point of triangle `t` nearest to `p` (Ericson, *Real-Time Collision
/// Detection*, §5.1.5, in the plane).
fn on_triangle(t: [[f32; 2]; 3], p: [f32; 2]) -> [f32; 2] {
    let sub = |a: [f32; 2], b: [f32; 2]| [a[0] - b[0], a[1] - b[1]];
    let dot = |a: [f32; 2], b: [f32; 2]| a[0] * b[0] + a[1] * b[1];
    let at = |v: f32, w: f32| {
        [
            t[0][0] + v * (t[1][0] - t[0][0]) + w * (t[2][0] - t[0][0]),
            t[0][1] + v * (t[1][1] - t[0][1]) + w * (t[2][1] - t[0][1]),
        ]
    };
    let (ab, ac) = (sub(t[1], t[0]), sub(t[2], t[0]));
    let ap = sub(p, t[0]);
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return t[0];
    }
    let bp = sub(p, t[1]);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return t[1];
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return at(d1 / (d1 - d3), 0.0);
    }
    let cp = sub(p, t[2]);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return t[2];
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return at(0.0, d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return at(1.0 - w, w);
    }
    let sum = va + vb + vc;
    if sum.abs() <= f32::MIN_POSITIVE {
        return t[0];
    }
    at(vb / sum, vc / sum)
}

/// Barycentric weights of `t`'s second and third corners at `q`, a point
/// of the triangle, clamped so that the three stay within [0, 1].
fn weights(t: [[f32; 2]; 3], q: [f32; 2]) -> [f32; 2] {
    let (e1, e2) = (
        [t[1][0] - t[0][0], t[1][1] - t[0][1]],
        [t[2][0] - t[0][0], t[2][1] - t[0][1]],
    );
    let d = [q[0] - t[0][0], q[1] - t[0][1]];
    let det = e1[0] * e2[1] - e1[1] * e2[0];
    if det.abs() <= f32::MIN_POSITIVE {
        return [0.0, 0.0];
    }
    let v = ((d[0] * e2[1] - d[1] * e2[0]) / det).clamp(0.0, 1.0);
    let w = ((e1[0] * d[1] - e1[1] * d[0]) / det).clamp(0.0, 1.0 - v);
    [v, w]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_points_lie_on_the_triangle() {
        let t = [[0.0, 0.0], [4.0, 0.0], [0.0, 4.0]];
        assert_eq!(on_triangle(t, [1.0, 1.0]), [1.0, 1.0]);
        assert_eq!(on_triangle(t, [-1.0, -1.0]), [0.0, 0.0]);
        assert_eq!(on_triangle(t, [2.0, -3.0]), [2.0, 0.0]);
        assert_eq!(on_triangle(t, [3.0, 3.0]), [2.0, 2.0]);
        assert_eq!(weights(t, [2.0, 2.0]), [0.5, 0.5]);
    }

    #[test]
    fn every_texel_of_a_used_cell_shows_its_own_triangle() {
        let layout = Layout::cells(3, 64).unwrap();
        let Layout::Cells { grid, cell, .. } = layout else {
            unreachable!()
        };
        assert_eq!((grid, cell), (2, 32));
        let charts = |i| Layout::chart(cell, grid, i);
        let owner = |x: usize, y: usize| layout.texel(y * 64 + x, 3, &charts).map(|t| t.0);
        assert_eq!(owner(0, 0), Some(0));
        assert_eq!(owner(31, 31), Some(1));
        assert_eq!(owner(40, 5), Some(2));
        // Triangle 2 has no partner: its cell is all its own.
        assert_eq!(owner(63, 31), Some(2));
        assert_eq!(owner(5, 40), None);
        assert!(matches!(
            Layout::cells(1 << 20, 1024),
            Err(Error::TooLarge(_))
        ));
    }

    #[test]
    fn mesh_charts_own_their_texels_and_a_gutter() {
        let uv = [[[0.25, 0.25], [0.75, 0.25], [0.25, 0.75]]];
        let layout = Layout::owners(&uv, 16);
        let charts = |_| uv[0].map(|p| p.map(|c| c * 16.0));
        let at = |x: usize, y: usize| layout.texel(y * 16 + x, 1, &charts);
        assert_eq!(at(5, 5).map(|t| t.0), Some(0));
        assert!(at(2, 5).is_some());
        assert!(at(0, 0).is_none());
        assert!(at(15, 15).is_none());
        let (_, w) = at(2, 5).unwrap();
        assert_eq!(w[0], 0.0);
    }
}
