//! Frames from sketched curves, interpolated over a grid (Zhang et al. §3).
//!
//! Each curve fixes a frame at every one of its samples: the tangent is the
//! local axis named by [`Curve::along`], the curve's normal (made
//! perpendicular to the tangent) the axis two after it, and the third axis
//! completes a right-handed frame. Frames become unit quaternions, and the
//! quaternions of all grid nodes `Q` are harmonic (Zhang's eq. 1) with the
//! curves as soft constraints (their eq. 2, w = 100), in the least-squares
//! sense of the Dirichlet energy:
//!
//! ```text
//! Σ_edges ||q_i − q_j||² + Σ_samples w² ||q(sample) − q̄(sample)||²,
//! ```
//!
//! over the grid's 6-neighbourhood edges, with `q(sample)` the trilinear
//! interpolation of the eight nodes around the sample, the same
//! interpolation that reading the field uses. Its normal equations
//! `(L + w² CᵀC) Q = w² Cᵀ q̄`, with `L` the grid's graph Laplacian, say
//! `Δq = 0` wherever no curve pulls, which is eq. (1); minimising
//! `||L Q||²` instead, the other reading of "least squares", solves the
//! biharmonic equation, which overshoots between curves that turn
//! differently (frames swung past 90° where the curves differ by 50°).
//! A harmonic field stays within its constraints' range, component by
//! component. The system shares one sparse symmetric positive definite
//! matrix across the four quaternion components, factored once by a
//! sparse Cholesky decomposition.
//!
//! Choices made where the paper leaves them open:
//!
//! - **Samples.** Each segment of a polyline is cut into equal pieces no
//!   longer than half the grid spacing. A sample inside a segment takes
//!   the segment's direction as its tangent; a sample at a vertex takes the
//!   normalised sum of the unit directions of the segments on either side
//!   (the one segment's direction at an end, the incoming segment's
//!   direction where the curve doubles back on itself).
//! - **Signs.** `q` and `−q` are the same rotation, so signs are fixed
//!   before the solve: the first sample of the first curve gets `w ≥ 0`;
//!   along a curve each quaternion takes the sign nearer the previous one;
//!   the first sample of a later curve takes the sign nearer the quaternion
//!   of the nearest sample of the curves before it (the first of them at
//!   equal distance).
//! - **Grid.** The curves' bounding box plus a margin on every side, with
//!   one spacing on all axes: the smallest (within 1%) that keeps every
//!   axis within [`MAX_AXIS_NODES`] nodes and the grid within
//!   [`MAX_NODES`] nodes, and no smaller than [`Sketch::spacing`] when
//!   that is given. Constraints tie each sample to the eight nodes around
//!   it by its trilinear weights, not to the nearest node, so curves
//!   between nodes pull on the field where they are.
//! - **Outside the grid** the boundary value holds: reading clamps the
//!   point to the grid box.
//!
//! Determinism: the system is assembled in a fixed order, duplicates are
//! summed in that order, and `nalgebra-sparse`'s Cholesky factorisation and
//! triangular solves are plain single-threaded scalar loops, so the solved
//! quaternions are the same bits on every machine. Reading the field uses
//! only `+ − × ÷`, `floor` and `sqrt`.

use super::{Frame, IDENTITY, cross, dot, norm, scale, sub};
use crate::error::{Error, Result};
use nalgebra::DMatrix;
use nalgebra_sparse::CscMatrix;
use nalgebra_sparse::factorization::CscCholesky;
use serde::{Deserialize, Serialize};

/// Most curves in one sketch.
pub(crate) const MAX_CURVES: usize = 32;
/// Most points in one curve.
pub(crate) const MAX_CURVE_POINTS: usize = 256;
/// Most points in all the curves of a sketch together.
pub(crate) const MAX_POINTS: usize = 2048;
/// Largest coordinate, margin or spacing, in voxels.
pub(crate) const MAX_COORD: f64 = 1e6;
/// Most grid nodes along one axis.
pub(crate) const MAX_AXIS_NODES: usize = 32;
/// Most grid nodes in all. The sparse Cholesky factorisation's work grows
/// about as the square of the node count on a 3D grid (its last separators
/// are dense planes), so the texture's creation would wait seconds for a
/// grid of 32³ nodes against a fraction of one at this budget (BENCHMARKS.md
/// has the solve time). The field is smooth and read by trilinear
/// interpolation, so a coarse grid loses little.
pub(crate) const MAX_NODES: usize = 8192;
/// Weight of the curve constraints against smoothness (Zhang's `w`).
const WEIGHT: f64 = 100.0;
/// Default margin as a fraction of the curves' largest extent.
const MARGIN_FRACTION: f64 = 0.25;
/// Smallest default margin, in voxels.
const MIN_MARGIN: f64 = 8.0;
/// Points closer than this to the previous kept point are duplicates.
const DUPLICATE: f64 = 1e-6;
/// A normal whose part perpendicular to the tangent is shorter than this
/// fraction of its length is parallel to the curve.
const PARALLEL: f64 = 1e-3;
/// Interpolated quaternions with a squared length below this are treated
/// as zero (the constraints are unit quaternions).
const TINY: f64 = 1e-12;

/// One sketched curve: a polyline on a reference plane.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Curve {
    /// The polyline's points, in voxels of the finest level: 2 to 256,
    /// at least two of them distinct, coordinates of at most 1e6. A point
    /// equal to the one before it (within 1e-6 voxels) is ignored.
    pub points: Vec<[f64; 3]>,
    /// Normal of the reference plane the curve lies on; it must not be
    /// parallel to the curve anywhere.
    pub normal: [f64; 3],
    /// The local axis that runs along the curve: `x` (the default), `y`
    /// or `z`. The normal becomes the axis two after it (z for x, x for y,
    /// y for z), so the frame stays right-handed.
    #[serde(default)]
    pub along: Along,
}

/// A local axis, by name.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Along {
    /// Local x.
    #[default]
    X,
    /// Local y.
    Y,
    /// Local z.
    Z,
}

impl Along {
    fn index(self) -> usize {
        match self {
            Along::X => 0,
            Along::Y => 1,
            Along::Z => 2,
        }
    }
}

/// Curves whose frames are interpolated into a field.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sketch {
    /// The curves, in the order they were drawn: 1 to 32, with at most
    /// 2048 points in all. Order matters only for the quaternion signs:
    /// each curve is made consistent with those before.
    pub curves: Vec<Curve>,
    /// Space left around the curves' bounding box on every side, in
    /// voxels (0 to 1e6). By default a quarter of the box's largest side,
    /// and at least 8.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub margin: Option<f64>,
    /// Smallest distance between grid nodes, in voxels (positive, at most
    /// 1e6). The grid is made coarser than this where its limits, 32 nodes
    /// along an axis and 8192 in all, need it; by default it is as fine as
    /// they allow.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spacing: Option<f64>,
}

impl Sketch {
    /// Checks the curves: counts, finite coordinates, distinct points and
    /// normals that are neither zero nor parallel to their curve.
    pub fn validate(&self) -> Result<()> {
        self.prepare().map(|_| ())
    }

    /// Interpolates the curves' frames over a grid.
    pub(crate) fn solve(&self) -> Result<SolvedSketch> {
        let polys = self.prepare()?;
        let grid = Grid::around(&polys, self.margin, self.spacing);
        let targets = signed_samples(&polys, grid.spacing);
        let quats = solve_grid(&grid, &targets)?;
        Ok(SolvedSketch { grid, quats })
    }

    /// Validates the sketch and reduces its curves to distinct points with
    /// their tangents.
    fn prepare(&self) -> Result<Vec<Poly>> {
        let n = self.curves.len();
        if !(1..=MAX_CURVES).contains(&n) {
            return bad(format!("a sketch needs 1 to {MAX_CURVES} curves, not {n}"));
        }
        if let Some(m) = self.margin
            && !(m.is_finite() && (0.0..=MAX_COORD).contains(&m))
        {
            return bad(format!(
                "margin must be a finite number from 0 to {MAX_COORD:e}, not {m}"
            ));
        }
        if let Some(s) = self.spacing
            && !(s.is_finite() && s > 0.0 && s <= MAX_COORD)
        {
            return bad(format!(
                "spacing must be a positive finite number of at most {MAX_COORD:e}, not {s}"
            ));
        }
        let mut total = 0;
        for (i, c) in self.curves.iter().enumerate() {
            let k = c.points.len();
            if !(2..=MAX_CURVE_POINTS).contains(&k) {
                return bad(format!(
                    "curve {i} needs 2 to {MAX_CURVE_POINTS} points, not {k}"
                ));
            }
            total += k;
        }
        if total > MAX_POINTS {
            return bad(format!(
                "the curves have {total} points in all; at most {MAX_POINTS} are allowed"
            ));
        }
        self.curves
            .iter()
            .enumerate()
            .map(|(i, c)| Poly::new(i, c))
            .collect()
    }
}

fn bad<T>(what: String) -> Result<T> {
    Err(Error::InvalidRequest(format!("field: {what}")))
}

fn finite(v: [f64; 3]) -> bool {
    v.iter().all(|x| x.is_finite() && x.abs() <= MAX_COORD)
}

fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// A validated curve: distinct points, unit segment directions, a unit
/// tangent per point.
struct Poly {
    points: Vec<[f64; 3]>,
    /// `dirs[k]` runs from `points[k]` to `points[k + 1]`.
    dirs: Vec<[f64; 3]>,
    tangents: Vec<[f64; 3]>,
    normal: [f64; 3],
    along: usize,
}

impl Poly {
    fn new(i: usize, c: &Curve) -> Result<Poly> {
        if !finite(c.normal) {
            return bad(format!(
                "curve {i}: normal must be finite numbers of at most {MAX_COORD:e}"
            ));
        }
        let nlen = norm(c.normal);
        if nlen < 1e-9 {
            return bad(format!("curve {i}: normal must not be zero"));
        }
        let normal = scale(c.normal, 1.0 / nlen);
        // Original indices of the kept points, to name them in errors.
        let mut points = Vec::with_capacity(c.points.len());
        let mut index = Vec::with_capacity(c.points.len());
        for (j, &p) in c.points.iter().enumerate() {
            if !finite(p) {
                return bad(format!(
                    "curve {i}, point {j}: coordinates must be finite numbers of at most {MAX_COORD:e}"
                ));
            }
            if points.last().is_none_or(|&q| norm(sub(p, q)) >= DUPLICATE) {
                points.push(p);
                index.push(j);
            }
        }
        if points.len() < 2 {
            return bad(format!(
                "curve {i} is degenerate: it needs at least 2 distinct points"
            ));
        }
        let dirs: Vec<[f64; 3]> = points
            .windows(2)
            .map(|w| {
                let d = sub(w[1], w[0]);
                scale(d, 1.0 / norm(d))
            })
            .collect();
        let last = dirs.len();
        let tangents: Vec<[f64; 3]> = (0..points.len())
            .map(|k| match k {
                0 => dirs[0],
                k if k == last => dirs[last - 1],
                k => {
                    let s = add(dirs[k - 1], dirs[k]);
                    let len = norm(s);
                    if len < 1e-6 {
                        dirs[k - 1]
                    } else {
                        scale(s, 1.0 / len)
                    }
                }
            })
            .collect();
        // Every tangent a sample can get: the vertices' and the segments'.
        let parallel = |t: [f64; 3]| norm(perpendicular(normal, t)) <= PARALLEL;
        for (k, &t) in tangents.iter().enumerate() {
            if parallel(t) {
                return bad(format!(
                    "curve {i}, point {}: normal is parallel to the curve",
                    index[k]
                ));
            }
            if k < last && parallel(dirs[k]) {
                return bad(format!(
                    "curve {i}, points {} to {}: normal is parallel to the curve",
                    index[k],
                    index[k + 1]
                ));
            }
        }
        Ok(Poly {
            points,
            dirs,
            tangents,
            normal,
            along: c.along.index(),
        })
    }

    /// The sample positions and tangents, no more than `step` apart.
    fn samples(&self, step: f64) -> Vec<([f64; 3], [f64; 3])> {
        let mut out = Vec::new();
        for (k, w) in self.points.windows(2).enumerate() {
            out.push((w[0], self.tangents[k]));
            let d = sub(w[1], w[0]);
            let pieces = (norm(d) / step).ceil().max(1.0) as usize;
            for s in 1..pieces {
                let p = add(w[0], scale(d, s as f64 / pieces as f64));
                out.push((p, self.dirs[k]));
            }
        }
        let last = self.points.len() - 1;
        out.push((self.points[last], self.tangents[last]));
        out
    }

    /// The frame at a sample with unit tangent `t`: `t` on the named axis,
    /// the normal on the axis two after it, the third axis completing a
    /// right-handed frame.
    fn frame(&self, t: [f64; 3]) -> Frame {
        let n = perpendicular(self.normal, t);
        let n = scale(n, 1.0 / norm(n));
        let a = self.along;
        let mut f = [[0.0; 3]; 3];
        f[a] = t;
        f[(a + 2) % 3] = n;
        f[(a + 1) % 3] = cross(n, t);
        f
    }
}

/// `n` less its component along the unit vector `t`.
fn perpendicular(n: [f64; 3], t: [f64; 3]) -> [f64; 3] {
    sub(n, scale(t, dot(n, t)))
}

type Quat = [f64; 4];

fn qdot(a: Quat, b: Quat) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]
}

fn qneg(q: Quat) -> Quat {
    [-q[0], -q[1], -q[2], -q[3]]
}

/// The unit quaternion `(w, x, y, z)` of a rotation, by Shepperd's
/// method: the largest of `4w², 4x², 4y², 4z²` is taken from the diagonal
/// and the others divided by it, so no division is by a small number.
fn quat_from_frame(f: &Frame) -> Quat {
    // m[r][c] is row r, column c of the matrix whose columns are the axes.
    let m = |r: usize, c: usize| f[c][r];
    let (m00, m11, m22) = (m(0, 0), m(1, 1), m(2, 2));
    let cands = [
        1.0 + m00 + m11 + m22,
        1.0 + m00 - m11 - m22,
        1.0 - m00 + m11 - m22,
        1.0 - m00 - m11 + m22,
    ];
    let mut k = 0;
    for i in 1..4 {
        if cands[i] > cands[k] {
            k = i;
        }
    }
    let r = cands[k].sqrt();
    let h = 0.5 / r;
    let half = 0.5 * r;
    let q = match k {
        0 => [
            half,
            (m(2, 1) - m(1, 2)) * h,
            (m(0, 2) - m(2, 0)) * h,
            (m(1, 0) - m(0, 1)) * h,
        ],
        1 => [
            (m(2, 1) - m(1, 2)) * h,
            half,
            (m(0, 1) + m(1, 0)) * h,
            (m(0, 2) + m(2, 0)) * h,
        ],
        2 => [
            (m(0, 2) - m(2, 0)) * h,
            (m(0, 1) + m(1, 0)) * h,
            half,
            (m(1, 2) + m(2, 1)) * h,
        ],
        _ => [
            (m(1, 0) - m(0, 1)) * h,
            (m(0, 2) + m(2, 0)) * h,
            (m(1, 2) + m(2, 1)) * h,
            half,
        ],
    };
    let inv = 1.0 / qdot(q, q).sqrt();
    [q[0] * inv, q[1] * inv, q[2] * inv, q[3] * inv]
}

/// The rotation of the unit quaternion `q`, as a frame (columns local x,
/// y, z).
fn frame_from_quat(q: Quat) -> Frame {
    let [w, x, y, z] = q;
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y + w * z),
            2.0 * (x * z - w * y),
        ],
        [
            2.0 * (x * y - w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z + w * x),
        ],
        [
            2.0 * (x * z + w * y),
            2.0 * (y * z - w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// The constraints: every sample of every curve with its quaternion, the
/// signs made consistent (see the module docs).
fn signed_samples(polys: &[Poly], spacing: f64) -> Vec<([f64; 3], Quat)> {
    let mut out: Vec<([f64; 3], Quat)> = Vec::new();
    for poly in polys {
        let start = out.len();
        for (k, (p, t)) in poly.samples(spacing * 0.5).into_iter().enumerate() {
            let mut q = quat_from_frame(&poly.frame(t));
            let reference = if k > 0 {
                Some(out[out.len() - 1].1)
            } else {
                nearest(&out[..start], p)
            };
            match reference {
                Some(r) if qdot(q, r) < 0.0 => q = qneg(q),
                None if q[0] < 0.0 => q = qneg(q),
                _ => {}
            }
            out.push((p, q));
        }
    }
    out
}

/// The quaternion of the sample nearest `p` (the first at equal distance).
fn nearest(samples: &[([f64; 3], Quat)], p: [f64; 3]) -> Option<Quat> {
    let mut best: Option<(f64, Quat)> = None;
    for &(s, q) in samples {
        let d = sub(s, p);
        let d2 = dot(d, d);
        if best.is_none_or(|(b, _)| d2 < b) {
            best = Some((d2, q));
        }
    }
    best.map(|(_, q)| q)
}

/// A regular grid: `dims` nodes per axis, `spacing` apart, the first at
/// `origin`.
#[derive(Clone, Debug, PartialEq)]
struct Grid {
    origin: [f64; 3],
    spacing: f64,
    dims: [usize; 3],
}

impl Grid {
    /// The grid over the curves' bounding box and margin.
    fn around(polys: &[Poly], margin: Option<f64>, spacing: Option<f64>) -> Grid {
        let mut lo = polys[0].points[0];
        let mut hi = lo;
        for p in polys.iter().flat_map(|c| &c.points) {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        let size = sub(hi, lo);
        let largest = size[0].max(size[1]).max(size[2]);
        let margin = margin.unwrap_or((MARGIN_FRACTION * largest).max(MIN_MARGIN));
        let extent = size.map(|s| s + 2.0 * margin);
        let widest = extent[0].max(extent[1]).max(extent[2]);
        // Distinct points are apart, so `widest` is positive.
        let mut s = (widest / (MAX_AXIS_NODES - 1) as f64).max(spacing.unwrap_or(0.0));
        let dims = loop {
            let dims = extent.map(|e| ((e / s).ceil() as usize + 1).max(2));
            if dims.iter().all(|&d| d <= MAX_AXIS_NODES)
                && dims.iter().product::<usize>() <= MAX_NODES
            {
                break dims;
            }
            s *= 1.01;
        };
        let origin =
            std::array::from_fn(|a| 0.5 * (lo[a] + hi[a]) - 0.5 * (dims[a] - 1) as f64 * s);
        Grid {
            origin,
            spacing: s,
            dims,
        }
    }

    fn nodes(&self) -> usize {
        self.dims.iter().product()
    }

    fn index(&self, c: [usize; 3]) -> usize {
        c[0] + self.dims[0] * (c[1] + self.dims[1] * c[2])
    }

    /// `p` in grid units, clamped to the grid box (a NaN to the first
    /// node).
    fn local(&self, p: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|a| {
            let u = (p[a] - self.origin[a]) / self.spacing;
            let top = (self.dims[a] - 1) as f64;
            if u > top {
                top
            } else if u > 0.0 {
                u
            } else {
                0.0
            }
        })
    }

    /// The cell holding `p` (its lowest corner) and the eight corners'
    /// trilinear weights, corner `c` at offset `(c & 1, c >> 1 & 1, c >> 2)`.
    fn cell(&self, p: [f64; 3]) -> ([usize; 3], [f64; 8]) {
        let u = self.local(p);
        let base: [usize; 3] =
            std::array::from_fn(|a| (u[a].floor() as usize).min(self.dims[a] - 2));
        let f: [f64; 3] = std::array::from_fn(|a| u[a] - base[a] as f64);
        let w = std::array::from_fn(|c| {
            let along = |a: usize| if c >> a & 1 == 1 { f[a] } else { 1.0 - f[a] };
            along(0) * along(1) * along(2)
        });
        (base, w)
    }

    fn corner(&self, base: [usize; 3], c: usize) -> usize {
        self.index([
            base[0] + (c & 1),
            base[1] + (c >> 1 & 1),
            base[2] + (c >> 2),
        ])
    }

    /// An elimination order that keeps the Cholesky factor sparse: nested
    /// dissection, cutting the longest side of a box by a slab two nodes
    /// thick (`LᵀL` couples nodes two apart) and numbering the two halves
    /// before the slab.
    fn dissection(&self) -> Vec<usize> {
        fn cut(g: &Grid, lo: [usize; 3], hi: [usize; 3], out: &mut Vec<usize>) {
            let ext: [usize; 3] = std::array::from_fn(|a| hi[a] - lo[a]);
            let mut a = 0;
            for b in 1..3 {
                if ext[b] > ext[a] {
                    a = b;
                }
            }
            if ext[a] <= 4 {
                for z in lo[2]..hi[2] {
                    for y in lo[1]..hi[1] {
                        for x in lo[0]..hi[0] {
                            out.push(g.index([x, y, z]));
                        }
                    }
                }
                return;
            }
            let mid = lo[a] + ext[a] / 2 - 1;
            let (mut left_hi, mut right_lo) = (hi, lo);
            left_hi[a] = mid;
            right_lo[a] = mid + 2;
            cut(g, lo, left_hi, out);
            cut(g, right_lo, hi, out);
            let (mut slab_lo, mut slab_hi) = (lo, hi);
            slab_lo[a] = mid;
            slab_hi[a] = mid + 2;
            cut(g, slab_lo, slab_hi, out);
        }
        let mut out = Vec::with_capacity(self.nodes());
        cut(self, [0; 3], self.dims, &mut out);
        out
    }
}

/// Solves Zhang's eq. (2) on `grid` for the constraint samples.
fn solve_grid(grid: &Grid, targets: &[([f64; 3], Quat)]) -> Result<Vec<Quat>> {
    let n = grid.nodes();
    let order = grid.dissection();
    let mut rank = vec![0; n];
    for (k, &v) in order.iter().enumerate() {
        rank[v] = k;
    }
    // Each column's entries as (row, value), in elimination order; equal
    // rows are summed later in the order pushed.
    let mut cols: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
    let mut push = |i: usize, j: usize, v: f64| cols[rank[j]].push((rank[i], v));

    // The Dirichlet energy Σ over grid edges of (q_i − q_j)²: its matrix is
    // the graph Laplacian, degree on the diagonal and −1 per edge.
    let [dx, dy, dz] = grid.dims;
    for z in 0..dz {
        for y in 0..dy {
            for x in 0..dx {
                let c = [x, y, z];
                let i = grid.index(c);
                for a in 0..3 {
                    if c[a] + 1 < grid.dims[a] {
                        let mut d = c;
                        d[a] += 1;
                        let j = grid.index(d);
                        push(i, i, 1.0);
                        push(j, j, 1.0);
                        push(i, j, -1.0);
                        push(j, i, -1.0);
                    }
                }
            }
        }
    }

    // w² CᵀC and w² Cᵀq̄, gathered per cell first so that a long curve adds
    // one 8×8 block per cell it crosses.
    let cells = (dx - 1) * (dy - 1) * (dz - 1);
    let mut blocks: Vec<Option<[[f64; 8]; 8]>> = vec![None; cells];
    let mut rhs = vec![[0.0; 4]; n];
    let w2 = WEIGHT * WEIGHT;
    for &(p, q) in targets {
        let (base, wt) = grid.cell(p);
        let cell = base[0] + (dx - 1) * (base[1] + (dy - 1) * base[2]);
        let block = blocks[cell].get_or_insert([[0.0; 8]; 8]);
        for i in 0..8 {
            for j in 0..8 {
                block[i][j] += wt[i] * wt[j];
            }
            let r = &mut rhs[grid.corner(base, i)];
            for (r, q) in r.iter_mut().zip(q) {
                *r += wt[i] * q;
            }
        }
    }
    for z in 0..dz - 1 {
        for y in 0..dy - 1 {
            for x in 0..dx - 1 {
                let cell = x + (dx - 1) * (y + (dy - 1) * z);
                if let Some(block) = &blocks[cell] {
                    for (i, entries) in block.iter().enumerate() {
                        let ni = grid.corner([x, y, z], i);
                        for (j, v) in entries.iter().enumerate() {
                            push(ni, grid.corner([x, y, z], j), w2 * v);
                        }
                    }
                }
            }
        }
    }

    // Compressed columns, rows ascending, duplicates summed in push order
    // (a stable sort keeps it).
    let mut offsets = Vec::with_capacity(n + 1);
    let mut indices = Vec::new();
    let mut values = Vec::new();
    offsets.push(0);
    for col in &mut cols {
        col.sort_by_key(|e| e.0);
        for &(r, v) in col.iter() {
            if indices.len() > *offsets.last().unwrap() && *indices.last().unwrap() == r {
                *values.last_mut().unwrap() += v;
            } else {
                indices.push(r);
                values.push(v);
            }
        }
        offsets.push(indices.len());
    }
    let matrix = CscMatrix::try_from_csc_data(n, n, offsets, indices, values)
        .map_err(|e| Error::InvalidRequest(format!("field: sketch system: {e}")))?;
    let cholesky = CscCholesky::factor(&matrix).map_err(|_| {
        Error::InvalidRequest("field: the sketch's system is not positive definite".into())
    })?;
    let b = DMatrix::from_fn(n, 4, |k, c| w2 * rhs[order[k]][c]);
    let x = cholesky.solve(&b);
    Ok((0..n)
        .map(|v| std::array::from_fn(|c| x[(rank[v], c)]))
        .collect())
}

/// A sketch's frames, solved on a grid.
pub(crate) struct SolvedSketch {
    grid: Grid,
    /// One quaternion `(w, x, y, z)` per node, x fastest; not unit length
    /// between the curves.
    quats: Vec<Quat>,
}

impl SolvedSketch {
    /// The frame at `p`: the trilinear interpolation of the nodes'
    /// quaternions, normalised. Where it vanishes the nearest node's
    /// quaternion stands in, and the identity where that vanishes too.
    pub(crate) fn frame(&self, p: [f64; 3]) -> Frame {
        let g = &self.grid;
        let (base, wt) = g.cell(p);
        let mut q = [0.0; 4];
        for (c, w) in wt.iter().enumerate() {
            let node = self.quats[g.corner(base, c)];
            for (q, v) in q.iter_mut().zip(node) {
                *q += w * v;
            }
        }
        if qdot(q, q) < TINY {
            let u = g.local(p);
            q = self.quats[g.index(u.map(|u| (u + 0.5).floor() as usize))];
            if qdot(q, q) < TINY {
                return IDENTITY;
            }
        }
        let inv = 1.0 / qdot(q, q).sqrt();
        frame_from_quat(q.map(|v| v * inv))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::assert_rotation;

    fn curve(points: &[[f64; 3]], normal: [f64; 3], along: Along) -> Curve {
        Curve {
            points: points.to_vec(),
            normal,
            along,
        }
    }

    fn sketch(curves: Vec<Curve>) -> Sketch {
        Sketch {
            curves,
            margin: None,
            spacing: None,
        }
    }

    /// Deterministic points in `[lo, hi)³`.
    fn points(n: usize, lo: f64, hi: f64) -> Vec<[f64; 3]> {
        let mut s: u64 = 0x9e37_79b9_7f4a_7c15;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            lo + (hi - lo) * ((s >> 11) as f64 / (1u64 << 53) as f64)
        };
        (0..n).map(|_| [next(), next(), next()]).collect()
    }

    /// Angle in degrees of the rotation taking frame `a` to frame `b`.
    fn angle(a: &Frame, b: &Frame) -> f64 {
        let trace = dot(a[0], b[0]) + dot(a[1], b[1]) + dot(a[2], b[2]);
        ((trace - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees()
    }

    /// Angle in degrees between unit vectors.
    fn between(a: [f64; 3], b: [f64; 3]) -> f64 {
        dot(a, b).clamp(-1.0, 1.0).acos().to_degrees()
    }

    fn quarter_circle(along: Along, normal: [f64; 3]) -> Curve {
        let pts: Vec<[f64; 3]> = (0..=24)
            .map(|i| {
                let t = i as f64 / 24.0 * std::f64::consts::FRAC_PI_2;
                [40.0 * t.cos(), 40.0 * t.sin(), 5.0]
            })
            .collect();
        curve(&pts, normal, along)
    }

    #[test]
    fn parallel_straight_curves_give_their_frame_everywhere() {
        let s = sketch(vec![
            curve(
                &[[0.0, 0.0, 0.0], [60.0, 0.0, 0.0]],
                [0.0, 1.0, 1.0],
                Along::X,
            ),
            curve(
                &[[0.0, 30.0, 0.0], [60.0, 30.0, 0.0]],
                [0.0, 1.0, 1.0],
                Along::X,
            ),
        ]);
        let solved = s.solve().unwrap();
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let want: Frame = [[1.0, 0.0, 0.0], [0.0, h, -h], [0.0, h, h]];
        for p in points(200, -200.0, 260.0) {
            let f = solved.frame(p);
            for a in 0..3 {
                assert!(
                    sub(f[a], want[a]).iter().all(|v| v.abs() < 1e-3),
                    "{p:?}: {f:?}"
                );
            }
        }
    }

    #[test]
    fn the_named_axis_follows_a_curved_curve() {
        for along in [Along::X, Along::Y, Along::Z] {
            let c = quarter_circle(along, [0.0, 0.0, 1.0]);
            let s = sketch(vec![c.clone()]);
            let solved = s.solve().unwrap();
            let poly = Poly::new(0, &c).unwrap();
            let a = along.index();
            for (p, t) in poly.samples(solved.grid.spacing * 0.5) {
                let f = solved.frame(p);
                assert!(
                    between(f[a], t) < 5.0,
                    "{along:?} at {p:?}: {:?} vs {t:?}",
                    f[a]
                );
                // The normal sits on the axis two after.
                assert!(
                    between(f[(a + 2) % 3], [0.0, 0.0, 1.0]) < 5.0,
                    "{along:?} at {p:?}"
                );
            }
        }
    }

    #[test]
    fn y_and_z_put_the_tangent_on_their_axis() {
        for (along, axis) in [(Along::Y, 1), (Along::Z, 2)] {
            let s = sketch(vec![curve(
                &[[0.0, 0.0, 0.0], [10.0, 10.0, 0.0]],
                [0.0, 0.0, 1.0],
                along,
            )]);
            let f = s.solve().unwrap().frame([5.0, 5.0, 0.0]);
            let t = [
                std::f64::consts::FRAC_1_SQRT_2,
                std::f64::consts::FRAC_1_SQRT_2,
                0.0,
            ];
            assert!(between(f[axis], t) < 1e-3, "{along:?}: {f:?}");
            assert!(
                between(f[(axis + 2) % 3], [0.0, 0.0, 1.0]) < 1e-3,
                "{along:?}: {f:?}"
            );
            assert_rotation(&f);
        }
    }

    #[test]
    fn frames_are_rotations_everywhere() {
        let s = sketch(vec![
            quarter_circle(Along::X, [0.0, 0.0, 1.0]),
            curve(
                &[[0.0, 0.0, 30.0], [20.0, 10.0, 40.0], [35.0, 35.0, 45.0]],
                [1.0, -1.0, 0.5],
                Along::Y,
            ),
            curve(
                &[[10.0, 40.0, -10.0], [40.0, 10.0, -10.0]],
                [0.0, 0.0, 1.0],
                Along::Z,
            ),
        ]);
        let solved = s.solve().unwrap();
        for p in points(2000, -150.0, 200.0) {
            assert_rotation(&solved.frame(p));
        }
    }

    fn ninety_degrees() -> Sketch {
        // The second curve's frame is the first's turned 90° about x.
        sketch(vec![
            curve(
                &[[0.0, 0.0, 0.0], [40.0, 0.0, 0.0]],
                [0.0, 0.0, 1.0],
                Along::X,
            ),
            curve(
                &[[0.0, 40.0, 0.0], [40.0, 40.0, 0.0]],
                [0.0, 1.0, 0.0],
                Along::X,
            ),
        ])
    }

    #[test]
    fn solving_twice_gives_the_same_bits() {
        let s = ninety_degrees();
        let (a, b) = (s.solve().unwrap(), s.solve().unwrap());
        assert_eq!(a.grid, b.grid);
        let bits = |s: &SolvedSketch| -> Vec<u64> {
            s.quats.iter().flatten().map(|v| v.to_bits()).collect()
        };
        assert_eq!(bits(&a), bits(&b));
        for p in points(100, -50.0, 90.0) {
            let (fa, fb) = (a.frame(p), b.frame(p));
            assert!(
                fa.iter()
                    .flatten()
                    .zip(fb.iter().flatten())
                    .all(|(x, y)| x.to_bits() == y.to_bits())
            );
        }
    }

    #[test]
    fn the_field_turns_smoothly_between_curves_ninety_degrees_apart() {
        let solved = ninety_degrees().solve().unwrap();
        let first = solved.frame([20.0, 0.0, 0.0]);
        let last = solved.frame([20.0, 40.0, 0.0]);
        assert!(angle(&first, &last) > 85.0, "{}", angle(&first, &last));
        let mid = solved.frame([20.0, 20.0, 0.0]);
        let (a, b) = (angle(&first, &mid), angle(&mid, &last));
        assert!(a > 20.0 && b > 20.0, "the turn is spread out: {a} {b}");
        for x in [0.0, 20.0, 40.0] {
            for z in [-10.0, 0.0, 10.0] {
                for y in -10..50 {
                    let p = [x, y as f64, z];
                    let q = [x, y as f64 + 1.0, z];
                    let d = angle(&solved.frame(p), &solved.frame(q));
                    assert!(d < 8.0, "{p:?}: {d}° to the next voxel");
                }
            }
        }
    }

    #[test]
    fn sketches_at_the_limits_are_taken() {
        let z = [0.0, 0.0, 1.0];
        let line = |n: usize, y: f64| {
            let pts: Vec<[f64; 3]> = (0..n).map(|i| [i as f64, y, 0.0]).collect();
            curve(&pts, z, Along::X)
        };
        // 32 curves, 2048 points in all.
        let full = sketch((0..MAX_CURVES).map(|c| line(64, 4.0 * c as f64)).collect());
        assert_eq!(full.curves.len(), MAX_CURVES);
        full.validate().unwrap();
        // One curve of 256 points.
        sketch(vec![line(MAX_CURVE_POINTS, 0.0)])
            .validate()
            .unwrap();
        // Coordinates at ±1e6.
        let far = curve(
            &[[-MAX_COORD, 0.0, 0.0], [MAX_COORD, 0.0, 0.0]],
            z,
            Along::X,
        );
        sketch(vec![far]).validate().unwrap();
    }

    #[test]
    fn bad_sketches_are_refused_with_a_reason() {
        let line = |normal| curve(&[[0.0, 0.0, 0.0], [10.0, 0.0, 0.0]], normal, Along::X);
        let z = [0.0, 0.0, 1.0];
        let many = curve(&points(200, 0.0, 10.0), z, Along::X);
        let cases: Vec<(Sketch, &str)> = vec![
            (sketch(vec![]), "1 to 32 curves"),
            (sketch(vec![line(z); 33]), "1 to 32 curves"),
            (sketch(vec![many.clone(); 11]), "2200 points in all"),
            (
                sketch(vec![line(z), curve(&points(257, 0.0, 9.0), z, Along::X)]),
                "curve 1 needs 2 to 256",
            ),
            (
                sketch(vec![curve(&[[0.0; 3]], z, Along::X)]),
                "curve 0 needs 2 to 256",
            ),
            (
                sketch(vec![
                    line(z),
                    curve(&[[0.0; 3], [1.0, f64::NAN, 0.0]], z, Along::X),
                ]),
                "curve 1, point 1: coordinates must be finite",
            ),
            (
                sketch(vec![curve(&[[0.0; 3], [2e6, 0.0, 0.0]], z, Along::X)]),
                "curve 0, point 1",
            ),
            (
                sketch(vec![line([f64::INFINITY, 0.0, 0.0])]),
                "curve 0: normal must be finite",
            ),
            (
                sketch(vec![line(z), line([0.0; 3])]),
                "curve 1: normal must not be zero",
            ),
            (
                sketch(vec![curve(
                    &[[1.0, 2.0, 3.0], [1.0, 2.0, 3.0]],
                    z,
                    Along::X,
                )]),
                "curve 0 is degenerate",
            ),
            (
                sketch(vec![line(z), line([2.0, 0.0, 0.0])]),
                "curve 1, point 0: normal is parallel",
            ),
            (
                sketch(vec![curve(
                    &[
                        [0.0; 3],
                        [0.0, 0.0, 0.0],
                        [10.0, 0.0, 0.0],
                        [10.0, 0.0, 10.0],
                    ],
                    [0.0, 0.0, 1.0],
                    Along::X,
                )]),
                "curve 0, points 2 to 3: normal is parallel",
            ),
        ];
        for (s, says) in cases {
            let e = s.validate().unwrap_err().to_string();
            assert!(e.starts_with("invalid request: field: "), "{e}");
            assert!(e.contains(says), "want {says:?}, got {e:?}");
            assert!(s.solve().is_err());
        }
        let mut s = sketch(vec![line(z)]);
        s.margin = Some(-1.0);
        assert!(s.validate().unwrap_err().to_string().contains("margin"));
        s.margin = None;
        s.spacing = Some(0.0);
        assert!(s.validate().unwrap_err().to_string().contains("spacing"));
        // Repeated points are skipped, not refused.
        let ok = sketch(vec![curve(
            &[
                [0.0; 3],
                [0.0; 3],
                [5.0, 0.0, 0.0],
                [5.0, 0.0, 0.0],
                [10.0, 1.0, 0.0],
            ],
            z,
            Along::X,
        )]);
        ok.validate().unwrap();
    }

    #[test]
    fn a_sketch_reads_from_json() {
        let json = r#"{"curves":[{"points":[[0,0,0],[10,0,0]],"normal":[0,0,1]}]}"#;
        let s: Sketch = serde_json::from_str(json).unwrap();
        assert_eq!(
            s,
            sketch(vec![curve(
                &[[0.0; 3], [10.0, 0.0, 0.0]],
                [0.0, 0.0, 1.0],
                Along::X
            )])
        );
        let back: Sketch = serde_json::from_str(&serde_json::to_string(&s).unwrap()).unwrap();
        assert_eq!(back, s);
        let f = s.solve().unwrap().frame([5.0, 0.0, 0.0]);
        assert!(between(f[0], [1.0, 0.0, 0.0]) < 1e-6, "{f:?}");
        let with: Sketch = serde_json::from_str(
            r#"{"curves":[{"points":[[0,0,0],[10,0,0]],"normal":[0,0,1],"along":"z"}],"margin":4,"spacing":2}"#,
        )
        .unwrap();
        assert_eq!(
            (with.curves[0].along, with.margin, with.spacing),
            (Along::Z, Some(4.0), Some(2.0))
        );
        assert!(serde_json::from_str::<Sketch>(r#"{"curves":[],"extra":1}"#).is_err());
    }

    #[test]
    fn the_grid_keeps_its_limits() {
        let big = sketch(vec![curve(
            &[[0.0; 3], [1000.0, 900.0, 800.0]],
            [0.0, 0.0, 1.0],
            Along::X,
        )]);
        let g = Grid::around(&big.prepare().unwrap(), None, None);
        assert!(
            g.dims.iter().all(|&d| (2..=MAX_AXIS_NODES).contains(&d)),
            "{g:?}"
        );
        assert!(g.nodes() <= MAX_NODES, "{g:?}");
        // Covers the box and margin.
        for a in 0..3 {
            assert!(g.origin[a] <= -250.0 + 1e-9);
            assert!(
                g.origin[a] + (g.dims[a] - 1) as f64 * g.spacing
                    >= [1250.0, 1150.0, 1050.0][a] - 1e-9
            );
        }
        let flat = sketch(vec![curve(
            &[[0.0; 3], [100.0, 0.0, 0.0]],
            [0.0, 0.0, 1.0],
            Along::X,
        )]);
        let g = Grid::around(&flat.prepare().unwrap(), Some(0.0), None);
        assert_eq!(g.dims, [MAX_AXIS_NODES, 2, 2], "{g:?}");
        // The default margin: a quarter of the length, at least 8 voxels.
        let g = Grid::around(&flat.prepare().unwrap(), None, None);
        assert!(g.origin[0] <= -25.0 && g.origin[1] <= -25.0, "{g:?}");
        let short = sketch(vec![curve(
            &[[0.0; 3], [4.0, 0.0, 0.0]],
            [0.0, 0.0, 1.0],
            Along::X,
        )]);
        let g = Grid::around(&short.prepare().unwrap(), None, None);
        assert!(g.origin[0] <= -8.0 && g.origin[2] <= -8.0, "{g:?}");
        assert!(g.origin[0] > -9.0, "{g:?}");
        let g = Grid::around(&flat.prepare().unwrap(), Some(0.0), Some(50.0));
        assert_eq!(g.dims, [3, 2, 2], "{g:?}");
        // Every node ranks once in the elimination order.
        let mut order = Grid::around(&big.prepare().unwrap(), None, None).dissection();
        order.sort_unstable();
        assert!(order.iter().enumerate().all(|(i, &v)| i == v));
    }

    #[test]
    fn quaternions_round_trip_through_frames() {
        let s = sketch(vec![quarter_circle(Along::X, [0.3, -0.2, 1.0])]);
        let poly = &s.prepare().unwrap()[0];
        // Cover Shepperd's four branches: half-turns about each axis too.
        let mut frames: Vec<Frame> = poly
            .samples(1.0)
            .iter()
            .map(|&(_, t)| poly.frame(t))
            .collect();
        frames.push([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]);
        frames.push([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]);
        frames.push([[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]]);
        for f in frames {
            assert_rotation(&f);
            let g = frame_from_quat(quat_from_frame(&f));
            for a in 0..3 {
                assert!(
                    sub(f[a], g[a]).iter().all(|v| v.abs() < 1e-12),
                    "{f:?} {g:?}"
                );
            }
        }
    }
}
