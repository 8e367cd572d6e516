//! The distance from a point to a baked mesh's own surface — its
//! triangles, not the caps a cut added — for shell regions (Zhang et al.
//! 2011, Fig. 15: bark within a given depth of the surface, wood below;
//! [`crate::region::Shape::Shell`]). Caps lie inside the mesh and the
//! surface on it, so the points a bake reads are never outside by more
//! than a voxel: the distance is unsigned, and a point deeper than the
//! shell is one farther from the surface than its thickness.
//!
//! A bounding-volume hierarchy of the triangles (boxes split at the median
//! of their longest side) answers each query exactly, looking only as far
//! as the caller needs.

use super::Bake;

/// Triangles per leaf at most.
const LEAF: usize = 4;

struct Node {
    lo: [f64; 3],
    hi: [f64; 3],
    /// Children (indices into the node list), or a leaf's range of
    /// triangles.
    kind: Kind,
}

enum Kind {
    Inner(usize, usize),
    Leaf(usize, usize),
}

/// A mesh's surface, in voxels of level of detail 0.
pub(crate) struct Surface {
    tris: Vec<[[f64; 3]; 3]>,
    nodes: Vec<Node>,
}

impl Surface {
    /// The surface of `bake`'s mesh (caps left out), placed as baked at
    /// level of detail `lod`, in voxels of level 0.
    pub(crate) fn of(bake: &Bake, lod: u32) -> Surface {
        let mesh = bake.mesh();
        let at = |k: u32| {
            let p = bake.place(mesh.positions()[k as usize]);
            crate::region::world(lod, p)
        };
        let tris = mesh
            .triangles()
            .iter()
            .enumerate()
            .filter(|&(t, _)| !mesh.is_cap(t))
            .map(|(_, tri)| tri.map(at))
            .collect();
        Surface::new(tris)
    }

    fn new(mut tris: Vec<[[f64; 3]; 3]>) -> Surface {
        let mut nodes = Vec::with_capacity(2 * tris.len() / LEAF + 1);
        if !tris.is_empty() {
            let n = tris.len();
            build(&mut tris, 0, n, &mut nodes);
        }
        Surface { tris, nodes }
    }

    /// The distance from `p` to the surface, or `reach` when it is no
    /// nearer than that.
    pub(crate) fn distance(&self, p: [f64; 3], reach: f64) -> f64 {
        let mut best = reach * reach;
        if !self.nodes.is_empty() {
            self.nearest(0, p, &mut best);
        }
        best.sqrt().min(reach)
    }

    fn nearest(&self, i: usize, p: [f64; 3], best: &mut f64) {
        let node = &self.nodes[i];
        if box_distance2(node.lo, node.hi, p) >= *best {
            return;
        }
        match node.kind {
            Kind::Leaf(a, b) => {
                for t in &self.tris[a..b] {
                    *best = best.min(triangle_distance2(p, t));
                }
            }
            Kind::Inner(l, r) => {
                // The nearer child first: the other is then often pruned.
                let dl = box_distance2(self.nodes[l].lo, self.nodes[l].hi, p);
                let dr = box_distance2(self.nodes[r].lo, self.nodes[r].hi, p);
                let (first, second) = if dl <= dr { (l, r) } else { (r, l) };
                self.nearest(first, p, best);
                self.nearest(second, p, best);
            }
        }
    }
}

/// Builds the node of `tris[a..b]` (reordering them) and returns its index.
fn build(tris: &mut [[[f64; 3]; 3]], a: usize, b: usize, nodes: &mut Vec<Node>) -> usize {
    let (mut lo, mut hi) = ([f64::MAX; 3], [f64::MIN; 3]);
    for t in &tris[a..b] {
        for v in t {
            for k in 0..3 {
                lo[k] = lo[k].min(v[k]);
                hi[k] = hi[k].max(v[k]);
            }
        }
    }
    let index = nodes.len();
    nodes.push(Node {
        lo,
        hi,
        kind: Kind::Leaf(a, b),
    });
    if b - a > LEAF {
        let axis = (0..3)
            .max_by(|&x, &y| (hi[x] - lo[x]).total_cmp(&(hi[y] - lo[y])))
            .unwrap_or(0);
        let centre = |t: &[[f64; 3]; 3]| t[0][axis] + t[1][axis] + t[2][axis];
        let mid = (a + b) / 2;
        tris[a..b].select_nth_unstable_by(mid - a, |s, t| centre(s).total_cmp(&centre(t)));
        let l = build(tris, a, mid, nodes);
        let r = build(tris, mid, b, nodes);
        nodes[index].kind = Kind::Inner(l, r);
    }
    index
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Squared distance from `p` to the box `lo..hi`.
fn box_distance2(lo: [f64; 3], hi: [f64; 3], p: [f64; 3]) -> f64 {
    (0..3)
        .map(|k| (lo[k] - p[k]).max(p[k] - hi[k]).max(0.0).powi(2))
        .sum()
}

/// Squared distance from `p` to the triangle `t`: to the nearest point of
/// its face, edges or corners, found from the barycentric regions of `p`'s
/// projection (Ericson, Real-Time Collision Detection, §5.1.5).
fn triangle_distance2(p: [f64; 3], t: &[[f64; 3]; 3]) -> f64 {
    let [a, b, c] = *t;
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let to = |q: [f64; 3]| {
        let d = sub(p, q);
        dot(d, d)
    };
    let along = |o: [f64; 3], e: [f64; 3], s: f64| [0, 1, 2].map(|k| o[k] + s * e[k]);
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return to(a);
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return to(b);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return to(along(a, ab, d1 / (d1 - d3)));
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return to(c);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return to(along(a, ac, d2 / (d2 - d6)));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return to(along(b, sub(c, b), (d4 - d3) / ((d4 - d3) + (d5 - d6))));
    }
    let denom = va + vb + vc;
    if denom == 0.0 {
        // A degenerate triangle: the nearest of its corners and edges.
        return [to(a), to(b), to(c)].into_iter().fold(f64::MAX, f64::min);
    }
    let (v, w) = (vb / denom, vc / denom);
    to([0, 1, 2].map(|k| a[k] + ab[k] * v + ac[k] * w))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distances_to_a_triangle_by_region() {
        let t = [[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [0.0, 4.0, 0.0]];
        let d = |p| triangle_distance2(p, &t).sqrt();
        assert_eq!(d([1.0, 1.0, 3.0]), 3.0);
        assert_eq!(d([-3.0, -4.0, 0.0]), 5.0);
        assert_eq!(d([2.0, -2.0, 0.0]), 2.0);
        assert_eq!(d([-1.0, 2.0, 0.0]), 1.0);
        assert!((d([3.0, 3.0, 0.0]) - 2f64.sqrt()).abs() < 1e-12);
        assert_eq!(d([7.0, 0.0, 4.0]), 5.0);
    }

    #[test]
    fn the_hierarchy_finds_what_a_scan_finds() {
        // A bumpy sheet of many triangles.
        let mut tris = Vec::new();
        let h = |x: f64, y: f64| (x * 0.7).sin() * 3.0 + (y * 0.3).cos() * 2.0;
        for i in 0..30 {
            for j in 0..30 {
                let (x, y) = (f64::from(i), f64::from(j));
                let q = |dx: f64, dy: f64| [x + dx, y + dy, h(x + dx, y + dy)];
                tris.push([q(0.0, 0.0), q(1.0, 0.0), q(0.0, 1.0)]);
                tris.push([q(1.0, 0.0), q(1.0, 1.0), q(0.0, 1.0)]);
            }
        }
        let s = Surface::new(tris.clone());
        let mut seed = 5u64;
        for _ in 0..300 {
            let mut r = || {
                seed = crate::hash::mix(seed);
                (seed >> 11) as f64 / (1u64 << 53) as f64
            };
            let p = [r() * 40.0 - 5.0, r() * 40.0 - 5.0, r() * 20.0 - 10.0];
            let scan = tris
                .iter()
                .map(|t| triangle_distance2(p, t))
                .fold(f64::MAX, f64::min)
                .sqrt();
            assert_eq!(s.distance(p, 1e9), scan);
            assert_eq!(s.distance(p, 2.0), scan.min(2.0));
        }
        assert_eq!(Surface::new(Vec::new()).distance([0.0; 3], 3.0), 3.0);
    }
}
