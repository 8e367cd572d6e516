//! Cuts and fractures (Dong et al. 2008, §6: new surfaces textured on
//! demand "when interactively breaking or cutting objects"): planes split a
//! mesh into pieces, one per side of every plane, and each piece is closed
//! by cap polygons where a plane crossed it. A cap lies inside the object,
//! so baking it reads the solid's inside, the same voxels the surface shows
//! along the cut line.
//!
//! A triangle straddling a plane is clipped into the polygons either side;
//! the crossing points are named by the edge they lie on (or the vertex,
//! for a vertex on the plane), so that both triangles along an edge and the
//! cap meet at one vertex. The crossing segments chain into closed loops;
//! a loop inside an odd number of others is a hole of the smallest loop
//! around it, and each outer loop with its holes is triangulated by ear
//! clipping (`earcutr`). A mesh that is not closed along a plane leaves
//! open chains, which get no cap.

use super::{Mesh, Piece};
use crate::error::{Error, Result};
use rustc_hash::FxHashMap;

/// Most planes one cut may have (2⁸ pieces at most).
pub const MAX_CUTS: usize = 8;

/// The plane of points `p` with `normal · p = offset`, in the mesh file's
/// own coordinates; the piece on the side the normal points to is the
/// "positive" one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    /// Unit normal.
    pub normal: [f64; 3],
    /// Signed distance of the plane from the origin along the normal.
    pub offset: f64,
}

impl Plane {
    /// The plane `n · p = d`; `n` need not be unit length (both are scaled
    /// by 1/|n|), but must be finite and not zero.
    pub fn new(n: [f64; 3], d: f64) -> Result<Plane> {
        let len = n.iter().map(|c| c * c).sum::<f64>().sqrt();
        if !(len.is_finite() && d.is_finite()) || len < 1e-12 {
            return Err(Error::InvalidParameter {
                name: "cut",
                reason: format!(
                    "the plane {n:?}·p = {d} is degenerate: its normal must be finite and \
                     not zero, its offset finite"
                ),
            });
        }
        Ok(Plane {
            normal: n.map(|c| c / len),
            offset: d / len,
        })
    }

    /// Planes written `nx,ny,nz,d`, several separated by `;` (the
    /// command line's `--cut` and the bake route's `cut`).
    pub fn parse_list(s: &str) -> Result<Vec<Plane>> {
        let bad = |reason: String| Error::InvalidParameter {
            name: "cut",
            reason,
        };
        let planes: Vec<&str> = s.split(';').filter(|p| !p.trim().is_empty()).collect();
        if planes.len() > MAX_CUTS {
            return Err(bad(format!(
                "{} planes given (at most {MAX_CUTS})",
                planes.len()
            )));
        }
        planes
            .into_iter()
            .map(|p| {
                let v: Vec<f64> = p
                    .split(',')
                    .map(|c| c.trim().parse::<f64>())
                    .collect::<std::result::Result<_, _>>()
                    .map_err(|_| bad(format!("`{p}` is not four comma-separated numbers")))?;
                match v[..] {
                    [x, y, z, d] => Plane::new([x, y, z], d),
                    _ => Err(bad(format!("`{p}` is not four numbers nx,ny,nz,d"))),
                }
            })
            .collect()
    }

    fn distance(&self, p: [f32; 3]) -> f64 {
        (0..3)
            .map(|a| self.normal[a] * f64::from(p[a]))
            .sum::<f64>()
            - self.offset
    }
}

/// Where a point of a clipped triangle lies: a vertex of the mesh, or the
/// crossing on the edge between two (smaller index first).
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
enum Point {
    Vertex(u32),
    Edge(u32, u32),
}

/// The positions being built and the crossing points made so far for one
/// plane.
struct Builder<'a> {
    positions: &'a mut Vec<[f32; 3]>,
    crossings: FxHashMap<(u32, u32), u32>,
}

impl Builder<'_> {
    fn index(&mut self, p: Point, d: &[f64]) -> u32 {
        match p {
            Point::Vertex(v) => v,
            Point::Edge(a, b) => *self.crossings.entry((a, b)).or_insert_with(|| {
                let (pa, pb) = (self.positions[a as usize], self.positions[b as usize]);
                let t = d[a as usize] / (d[a as usize] - d[b as usize]);
                let q = [0, 1, 2]
                    .map(|k| (f64::from(pa[k]) + t * (f64::from(pb[k]) - f64::from(pa[k]))) as f32);
                self.positions.push(q);
                (self.positions.len() - 1) as u32
            }),
        }
    }
}

/// `mesh` cut by `planes`: its vertices welded (equal positions become
/// one, so that texture seams do not open the surface), the triangles of
/// every piece in turn, each piece closed by its caps, texture coordinates
/// dropped (caps have none).
pub(super) fn cut(mesh: &Mesh, planes: &[Plane]) -> Result<Mesh> {
    if planes.is_empty() || planes.len() > MAX_CUTS {
        return Err(Error::InvalidParameter {
            name: "cut",
            reason: format!("{} planes given (1 to {MAX_CUTS})", planes.len()),
        });
    }
    let (mut positions, welded) = weld(mesh);
    let scale = extent(&positions);
    for (k, plane) in planes.iter().enumerate() {
        let eps = 1e-7 * scale;
        // Vertices strictly on both sides (a plane through a vertex ring
        // with the mesh on both sides crosses it; one touching it does not).
        let (mut below, mut above) = (false, false);
        for &v in welded.iter().flatten() {
            let d = snap(plane.distance(positions[v as usize]), eps);
            below |= d < 0.0;
            above |= d > 0.0;
        }
        let crosses = below && above;
        if !crosses {
            return Err(Error::InvalidParameter {
                name: "cut",
                reason: format!("plane {} ({plane:?}) does not cross the mesh", k + 1),
            });
        }
    }
    // Each piece: triangles, cap flags, and its side of every plane so far.
    let mut pieces: Vec<(Vec<[u32; 3]>, Vec<bool>, Sides)> =
        vec![(welded.clone(), vec![false; welded.len()], Vec::new())];
    for plane in planes {
        let eps = 1e-7 * scale;
        let d: Vec<f64> = positions
            .iter()
            .map(|&p| snap(plane.distance(p), eps))
            .collect();
        let mut next = Vec::with_capacity(pieces.len() * 2);
        let mut b = Builder {
            positions: &mut positions,
            crossings: FxHashMap::default(),
        };
        for (tris, caps, sides) in pieces {
            let [neg, pos] = split(&tris, &caps, &d, plane, &mut b);
            for (side, (t, c)) in [(-1i8, neg), (1, pos)] {
                if !t.is_empty() {
                    let mut s = sides.clone();
                    s.push(side);
                    next.push((t, c, s));
                }
            }
        }
        pieces = next;
    }
    let total: usize = pieces.iter().map(|p| p.0.len()).sum();
    if total > super::MAX_TRIANGLES {
        return Err(Error::TooLarge(format!(
            "the cut mesh has {total} triangles (limit {})",
            super::MAX_TRIANGLES
        )));
    }
    let (mut triangles, mut caps, mut out) = (Vec::new(), Vec::new(), Vec::new());
    for (t, c, sides) in pieces {
        let start = triangles.len();
        triangles.extend(t);
        caps.extend(c);
        let away: [f64; 3] = [0, 1, 2].map(|a| {
            planes
                .iter()
                .zip(&sides)
                .map(|(p, &s)| f64::from(s) * p.normal[a])
                .sum()
        });
        let len = away.iter().map(|c| c * c).sum::<f64>().sqrt();
        out.push(Piece {
            triangles: start..triangles.len(),
            away: if len > 1e-9 {
                away.map(|c| (c / len) as f32)
            } else {
                [0.0; 3]
            },
        });
    }
    Ok(Mesh {
        positions,
        triangles,
        uvs: None,
        dropped: mesh.dropped,
        caps,
        pieces: out,
    })
}

/// Distances within `eps` of the plane count as on it.
fn snap(d: f64, eps: f64) -> f64 {
    if d.abs() <= eps { 0.0 } else { d }
}

/// The longest side of the positions' bounding box.
fn extent(positions: &[[f32; 3]]) -> f64 {
    let (mut lo, mut hi) = ([f64::MAX; 3], [f64::MIN; 3]);
    for p in positions {
        for a in 0..3 {
            lo[a] = lo[a].min(f64::from(p[a]));
            hi[a] = hi[a].max(f64::from(p[a]));
        }
    }
    (0..3).map(|a| hi[a] - lo[a]).fold(0.0, f64::max)
}

/// Positions with duplicates merged, and the triangles on them. Every
/// distinct position is kept, used or not, so the bounding box (and with
/// it the placement) is the uncut mesh's.
fn weld(mesh: &Mesh) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let mut first: FxHashMap<[u32; 3], u32> = FxHashMap::default();
    let mut positions = Vec::new();
    let map: Vec<u32> = mesh
        .positions
        .iter()
        .map(|p| {
            // +0.0 so that -0.0 and 0.0 weld.
            let key = p.map(|c| (c + 0.0).to_bits());
            *first.entry(key).or_insert_with(|| {
                positions.push(*p);
                (positions.len() - 1) as u32
            })
        })
        .collect();
    let triangles = mesh
        .triangles
        .iter()
        .map(|t| t.map(|v| map[v as usize]))
        .collect();
    (positions, triangles)
}

/// Triangles and their cap flags.
type Side = (Vec<[u32; 3]>, Vec<bool>);
/// Which side of each plane so far: -1 below, +1 above.
type Sides = Vec<i8>;

/// One piece split by `plane`: the triangles below it and above it, each
/// side closed by the caps of the loops the plane cuts.
fn split(tris: &[[u32; 3]], caps: &[bool], d: &[f64], plane: &Plane, b: &mut Builder) -> [Side; 2] {
    let mut sides: [Side; 2] = Default::default();
    let mut segments = Vec::new();
    for (t, &cap) in tris.iter().zip(caps) {
        let up = t.map(|v| d[v as usize] >= 0.0);
        if up.iter().all(|&u| u == up[0]) {
            let s = &mut sides[usize::from(up[0])];
            s.0.push(*t);
            s.1.push(cap);
            continue;
        }
        let mut crossing = Vec::with_capacity(2);
        for (side, s) in sides.iter_mut().enumerate() {
            let mut poly: Vec<Point> = Vec::with_capacity(4);
            for i in 0..3 {
                let (a, c) = (t[i], t[(i + 1) % 3]);
                if usize::from(up[i]) == side {
                    poly.push(Point::Vertex(a));
                }
                if up[i] != up[(i + 1) % 3] {
                    let p = if d[a as usize] == 0.0 {
                        Point::Vertex(a)
                    } else if d[c as usize] == 0.0 {
                        Point::Vertex(c)
                    } else {
                        Point::Edge(a.min(c), a.max(c))
                    };
                    poly.push(p);
                    if side == 0 {
                        crossing.push(p);
                    }
                }
            }
            poly.dedup();
            while poly.len() > 1 && poly.first() == poly.last() {
                poly.pop();
            }
            let ids: Vec<u32> = poly.iter().map(|&p| b.index(p, d)).collect();
            for k in 1..ids.len().saturating_sub(1) {
                s.0.push([ids[0], ids[k], ids[k + 1]]);
                s.1.push(cap);
            }
        }
        if let [p, q] = crossing[..] {
            let (p, q) = (b.index(p, d), b.index(q, d));
            if p != q {
                segments.push((p.min(q), p.max(q)));
            }
        }
    }
    segments.sort_unstable();
    segments.dedup();
    let loops = chain(&segments);
    let cap = triangulate(&loops, b.positions, plane);
    // Wound so that the cap faces +normal, outwards from the side below.
    for t in cap {
        sides[0].0.push(t);
        sides[0].1.push(true);
        sides[1].0.push([t[0], t[2], t[1]]);
        sides[1].1.push(true);
    }
    sides
}

/// The closed loops the segments form (open chains are left out).
fn chain(segments: &[(u32, u32)]) -> Vec<Vec<u32>> {
    let mut next: FxHashMap<u32, Vec<u32>> = FxHashMap::default();
    for &(a, c) in segments {
        next.entry(a).or_default().push(c);
        next.entry(c).or_default().push(a);
    }
    let mut used: rustc_hash::FxHashSet<(u32, u32)> = Default::default();
    let mut loops = Vec::new();
    for &(a, c) in segments {
        if used.contains(&(a, c)) {
            continue;
        }
        used.insert((a, c));
        let mut path = vec![a, c];
        let closed = loop {
            let here = *path.last().unwrap_or(&a);
            let step = next[&here].iter().copied().find(|&n| {
                let key = (here.min(n), here.max(n));
                !used.contains(&key)
            });
            let Some(n) = step else { break false };
            used.insert((here.min(n), here.max(n)));
            if n == a {
                break true;
            }
            path.push(n);
        };
        if closed && path.len() >= 3 {
            loops.push(path);
        }
    }
    loops
}

/// Cap triangles for `loops` on `plane`, wound to face +normal.
fn triangulate(loops: &[Vec<u32>], positions: &[[f32; 3]], plane: &Plane) -> Vec<[u32; 3]> {
    if loops.is_empty() {
        return Vec::new();
    }
    let n = plane.normal;
    // u ⟂ n, v = n × u, so u × v = n: counter-clockwise in (u, v) faces +n.
    let helper = if n[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let u = {
        let c = cross(n, helper);
        let l = c.iter().map(|x| x * x).sum::<f64>().sqrt();
        c.map(|x| x / l)
    };
    let v = cross(n, u);
    let flat = |i: u32| {
        let p = positions[i as usize].map(f64::from);
        [
            u[0] * p[0] + u[1] * p[1] + u[2] * p[2],
            v[0] * p[0] + v[1] * p[1] + v[2] * p[2],
        ]
    };
    let rings: Vec<Vec<[f64; 2]>> = loops
        .iter()
        .map(|l| l.iter().map(|&i| flat(i)).collect())
        .collect();
    // Each loop's parent: the smallest loop around it; depth by parents.
    let area: Vec<f64> = rings.iter().map(|r| signed_area(r).abs()).collect();
    let parent: Vec<Option<usize>> = (0..rings.len())
        .map(|i| {
            (0..rings.len())
                .filter(|&j| j != i && area[j] > area[i] && inside(&rings[j], rings[i][0]))
                .min_by(|&a, &b| area[a].total_cmp(&area[b]))
        })
        .collect();
    let depth = |mut i: usize| {
        let mut k = 0;
        while let Some(p) = parent[i] {
            k += 1;
            i = p;
            if k > rings.len() {
                break;
            }
        }
        k
    };
    let mut out = Vec::new();
    for outer in (0..rings.len()).filter(|&i| depth(i) % 2 == 0) {
        let holes: Vec<usize> = (0..rings.len())
            .filter(|&j| parent[j] == Some(outer))
            .collect();
        let mut ids: Vec<u32> = loops[outer].clone();
        let mut coords: Vec<f64> = rings[outer].iter().flatten().copied().collect();
        let mut starts = Vec::new();
        for &h in &holes {
            starts.push(ids.len());
            ids.extend(&loops[h]);
            coords.extend(rings[h].iter().flatten());
        }
        let Ok(tri) = earcutr::earcut(&coords, &starts, 2) else {
            continue;
        };
        let mut faces: Vec<[u32; 3]> = tri
            .chunks_exact(3)
            .map(|c| {
                let t = [ids[c[0]], ids[c[1]], ids[c[2]]];
                let [a, b2, c2] = [c[0], c[1], c[2]].map(|k| [coords[2 * k], coords[2 * k + 1]]);
                let turn = (b2[0] - a[0]) * (c2[1] - a[1]) - (b2[1] - a[1]) * (c2[0] - a[0]);
                if turn < 0.0 { [t[0], t[2], t[1]] } else { t }
            })
            .collect();
        // Ear clipping leaves out points collinear with their neighbours;
        // splitting the triangle edges that pass over them keeps the cap's
        // border the same edges as the piece's, so the piece stays closed.
        let mut rings_of_ids = vec![loops[outer].clone()];
        rings_of_ids.extend(holes.iter().map(|&h| loops[h].clone()));
        restore_skipped(&mut faces, &rings_of_ids);
        out.extend(faces);
    }
    out
}

/// Splits every triangle edge that passes over loop points the
/// triangulation skipped, so that each loop edge is a triangle edge.
fn restore_skipped(faces: &mut Vec<[u32; 3]>, rings: &[Vec<u32>]) {
    let used: rustc_hash::FxHashSet<u32> = faces.iter().flatten().copied().collect();
    // Between consecutive used points of a ring, the skipped ones in order.
    let mut between: FxHashMap<(u32, u32), Vec<u32>> = FxHashMap::default();
    for ring in rings {
        let Some(first) = ring.iter().position(|p| used.contains(p)) else {
            continue;
        };
        let n = ring.len();
        let mut from = ring[first];
        let mut skipped = Vec::new();
        for k in 1..=n {
            let p = ring[(first + k) % n];
            if used.contains(&p) {
                if !skipped.is_empty() {
                    between.insert((from, p), std::mem::take(&mut skipped));
                }
                from = p;
            } else {
                skipped.push(p);
            }
        }
    }
    if between.is_empty() {
        return;
    }
    let mut work = std::mem::take(faces);
    while let Some(t) = work.pop() {
        let found = (0..3).find_map(|e| {
            let (a, c) = (t[e], t[(e + 1) % 3]);
            if let Some(s) = between.get(&(a, c)) {
                Some((e, s.clone()))
            } else {
                between
                    .get(&(c, a))
                    .map(|s| (e, s.iter().rev().copied().collect()))
            }
        });
        let Some((e, pts)) = found else {
            faces.push(t);
            continue;
        };
        // Fan from the corner opposite the edge: a, p1, …, pk, c.
        let (a, c, o) = (t[e], t[(e + 1) % 3], t[(e + 2) % 3]);
        let chain: Vec<u32> = std::iter::once(a)
            .chain(pts)
            .chain(std::iter::once(c))
            .collect();
        for w in chain.windows(2) {
            work.push([w[0], w[1], o]);
        }
    }
}

fn signed_area(r: &[[f64; 2]]) -> f64 {
    let n = r.len();
    (0..n)
        .map(|i| {
            let (p, q) = (r[i], r[(i + 1) % n]);
            p[0] * q[1] - q[0] * p[1]
        })
        .sum::<f64>()
        / 2.0
}

/// Whether `p` lies inside the ring (even-odd rule).
fn inside(r: &[[f64; 2]], p: [f64; 2]) -> bool {
    let n = r.len();
    let mut inside = false;
    for i in 0..n {
        let (a, b) = (r[i], r[(i + 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if p[0] < x {
                inside = !inside;
            }
        }
    }
    inside
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    /// A closed torus about z (radii 1 and 0.35), `rings` × `sides` quads,
    /// with vertex rings lying exactly on z = 0.
    fn torus(rings: usize, sides: usize) -> Mesh {
        let mut p = Vec::new();
        for i in 0..rings {
            let a = TAU * i as f64 / rings as f64;
            for j in 0..sides {
                let b = TAU * j as f64 / sides as f64;
                let r = 1.0 + 0.35 * b.cos();
                p.push([
                    (r * a.cos()) as f32,
                    (r * a.sin()) as f32,
                    (0.35 * b.sin()) as f32,
                ]);
            }
        }
        let at = |i: usize, j: usize| ((i % rings) * sides + j % sides) as u32;
        let mut t = Vec::new();
        for i in 0..rings {
            for j in 0..sides {
                t.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                t.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
            }
        }
        Mesh::new(p, t, None).unwrap()
    }

    /// Every directed edge of the piece is matched by its reverse exactly
    /// once: closed, and consistently wound.
    fn assert_closed(m: &Mesh, piece: &Piece) {
        let mut count: FxHashMap<(u32, u32), i32> = FxHashMap::default();
        for t in &m.triangles()[piece.triangles.clone()] {
            for e in 0..3 {
                *count.entry((t[e], t[(e + 1) % 3])).or_default() += 1;
            }
        }
        for (&(a, b), &n) in &count {
            assert_eq!(n, 1, "edge {a}-{b} used {n} times one way");
            assert_eq!(count.get(&(b, a)), Some(&1), "edge {a}-{b} has no twin");
        }
    }

    /// The caps of a piece: (V − E + F, area).
    fn cap_shape(m: &Mesh, piece: &Piece) -> (i64, f64) {
        let caps: Vec<usize> = piece.triangles.clone().filter(|&t| m.is_cap(t)).collect();
        let mut v = rustc_hash::FxHashSet::default();
        let mut e = rustc_hash::FxHashSet::default();
        let mut area = 0.0;
        for &t in &caps {
            let tri = m.triangles()[t];
            for k in 0..3 {
                v.insert(tri[k]);
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                e.insert((a.min(b), a.max(b)));
            }
            let c = super::super::cross_of(tri.map(|i| m.positions()[i as usize]));
            area += (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt() / 2.0;
        }
        (v.len() as i64 - e.len() as i64 + caps.len() as i64, area)
    }

    #[test]
    fn a_torus_cut_across_its_hole_gets_annulus_caps() {
        let m = torus(48, 24);
        // Through two vertex rings, and between rings.
        for z in [0.0, 0.1] {
            let cut = m.cut(&[Plane::new([0.0, 0.0, 1.0], z).unwrap()]).unwrap();
            assert_eq!(cut.pieces().len(), 2);
            for piece in cut.pieces() {
                assert_closed(&cut, piece);
                let (euler, area) = cap_shape(&cut, piece);
                // An annulus (one hole): χ = 0; its area 4πRr at z = 0.
                assert_eq!(euler, 0, "z = {z}");
                if z == 0.0 {
                    let exact = 2.0 * TAU * 0.35;
                    assert!((area - exact).abs() < 0.03 * exact, "{area} vs {exact}");
                }
                // The cap faces out of its piece: up for the piece below.
                let below = piece.away[2] < 0.0;
                for t in piece.triangles.clone().filter(|&t| cut.is_cap(t)) {
                    let n = cut.face_normal(t);
                    assert_eq!(n[2] > 0.9, below, "{n:?}");
                }
            }
            assert!(!cut.uvs().is_some_and(|_| true));
        }
    }

    #[test]
    fn a_torus_cut_through_its_ring_gets_two_discs_per_piece() {
        let m = torus(48, 24);
        let cut = m
            .cut(&[Plane::new([1.0, 0.0, 0.0], 0.013).unwrap()])
            .unwrap();
        assert_eq!(cut.pieces().len(), 2);
        for piece in cut.pieces() {
            assert_closed(&cut, piece);
            // Two discs, χ = 1 each.
            assert_eq!(cap_shape(&cut, piece).0, 2);
        }
    }

    #[test]
    fn a_fracture_of_three_planes_leaves_closed_pieces_and_collinear_points_kept() {
        // A cube cut across its faces' diagonals: the crossings on the
        // diagonals are collinear with the corners' and must stay cap corners.
        let c = Mesh::unit_cube();
        let cut = c
            .cut(&[
                Plane::new([0.0, 0.0, 1.0], 0.5).unwrap(),
                Plane::new([1.0, 0.0, 0.0], 0.3).unwrap(),
                Plane::new([1.0, 1.0, 0.0], 1.2).unwrap(),
            ])
            .unwrap();
        assert!(cut.pieces().len() >= 6, "{}", cut.pieces().len());
        for piece in cut.pieces() {
            assert_closed(&cut, piece);
        }
        let m = torus(40, 20);
        let planes = [
            Plane::new([0.3, 0.2, 1.0], 0.05).unwrap(),
            Plane::new([1.0, -0.4, 0.1], 0.2).unwrap(),
            Plane::new([0.2, 1.0, 0.0], -0.3).unwrap(),
        ];
        let cut = m.cut(&planes).unwrap();
        assert!(cut.pieces().len() >= 6);
        for piece in cut.pieces() {
            assert_closed(&cut, piece);
        }
    }

    #[test]
    fn planes_that_miss_or_are_degenerate_are_refused() {
        let m = torus(16, 8);
        let miss = Plane::new([0.0, 0.0, 1.0], 5.0).unwrap();
        assert!(matches!(
            m.cut(&[miss]),
            Err(Error::InvalidParameter { .. })
        ));
        // Touching the top ring only: no triangle on both sides.
        let touch = Plane::new([0.0, 0.0, 1.0], 0.35 * (TAU / 4.0).sin()).unwrap();
        assert!(m.cut(&[touch]).is_err());
        assert!(Plane::new([0.0, 0.0, 0.0], 1.0).is_err());
        assert!(Plane::new([f64::NAN, 0.0, 1.0], 1.0).is_err());
        assert!(Plane::new([0.0, 0.0, 1.0], f64::INFINITY).is_err());
        let p = Plane::new([0.0, 0.0, 2.0], 0.1).unwrap();
        assert_eq!((p.normal, p.offset), ([0.0, 0.0, 1.0], 0.05));
        assert!(m.cut(&[p; MAX_CUTS + 1]).is_err());
        assert!(m.cut(&[]).is_err());
        let two = Plane::parse_list("0,0,1,0.1; 1,0,0,0").unwrap();
        assert_eq!(two.len(), 2);
        assert_eq!(two[1].normal, [1.0, 0.0, 0.0]);
        for bad in ["0,0,1", "0,0,1,x", "0,0,0,1", "1,2,3,4,5", "0,0,1,inf"] {
            assert!(Plane::parse_list(bad).is_err(), "{bad}");
        }
        assert!(Plane::parse_list(&["0,0,1,0"; MAX_CUTS + 1].join(";")).is_err());
        // At the limit: accepted.
        assert_eq!(
            Plane::parse_list(&["0,0,1,0"; MAX_CUTS].join(";"))
                .unwrap()
                .len(),
            MAX_CUTS
        );
        let fan: Vec<Plane> = (0..MAX_CUTS)
            .map(|k| {
                let a = k as f64 * TAU / (2.0 * MAX_CUTS as f64) + 0.05;
                Plane::new([a.cos(), a.sin(), 0.0], 0.0).unwrap()
            })
            .collect();
        assert!(m.cut(&fan).is_ok());
    }
}
