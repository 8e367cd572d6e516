//! The requests a load test sends: random axis slices, oblique cuts and
//! bricks, some far apart (fresh work for the server) and some inside a
//! small shared box (overlapping requests that share tiles), plus sweeps of
//! a plane advancing one voxel per request. Every sequence is a pure
//! function of (seed, worker), so two runs send the same requests.

use serde::Serialize;

/// What kind of voxel request.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    /// An axis-aligned slice PNG.
    #[value(alias = "slices")]
    Slice,
    /// An oblique cut PNG.
    #[value(alias = "cuts")]
    Cut,
    /// An aligned raw brick.
    #[value(alias = "bricks")]
    Brick,
}

impl Kind {
    /// Every kind, in report order.
    pub const ALL: [Kind; 3] = [Kind::Slice, Kind::Cut, Kind::Brick];

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Slice => "slice",
            Kind::Cut => "cut",
            Kind::Brick => "brick",
        }
    }
}

/// Which plane a sweep moves.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum SweepPlane {
    /// An axis-z slice whose `z` grows by one voxel per request.
    Axis,
    /// A tilted cut whose origin moves one voxel along its normal per request.
    Oblique,
}

/// One request: its kind and its path and query below the texture's URL.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Request {
    /// Kind, for the per-kind statistics.
    pub kind: Kind,
    /// E.g. `/slices/z/40.png?u0=0&v0=0&w=256&h=256&lod=0`.
    pub path: String,
}

/// Far-apart requests are drawn within ±FAR voxels of the served level:
/// far enough that two of them practically never share a tile, well inside
/// the ±2^31 coordinate limit at any level of detail.
const FAR: i64 = 1 << 24;

/// SplitMix64: tiny, fast and good enough to pick request positions.
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    /// A generator for `stream` of `seed` (streams are independent).
    pub fn new(seed: u64, stream: u64) -> Rng {
        let mut r = Rng(seed ^ stream.wrapping_mul(0xd1b5_4a32_d192_ed03));
        r.next_u64();
        r
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        let z = solidtex_core::hash::mix(self.0);
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        z
    }

    /// Uniform in `[0, 1)`.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `lo..hi` (`hi > lo`).
    pub fn range(&mut self, lo: i64, hi: i64) -> i64 {
        lo + (self.next_u64() % (hi - lo) as u64) as i64
    }

    /// A uniformly distributed unit vector.
    pub fn direction(&mut self) -> [f64; 3] {
        loop {
            let v = [0, 1, 2].map(|_| self.unit() * 2.0 - 1.0);
            let n = norm(v);
            if n > 0.1 && n <= 1.0 {
                return v.map(|c| c / n);
            }
        }
    }
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Two orthonormal in-plane axes of the plane with unit normal `n`.
fn plane_axes(n: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let helper = if n[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let u = cross(helper, n);
    let u = u.map(|c| c / norm(u));
    (u, cross(n, u))
}

/// A vector as the query expects it; 5 decimals keep URLs short and exact.
fn vec3(v: [f64; 3]) -> String {
    v.map(|c| format!("{c:.5}")).join(",")
}

/// What every generator needs to know about the texture and the workload.
#[derive(Clone, Debug)]
pub struct Shape {
    /// Level of detail of every request.
    pub lod: u32,
    /// Side of slices and cuts, pixels.
    pub side: u32,
    /// Edge of the server's bricks.
    pub brick_size: u32,
    /// Probability that a request falls in the shared box.
    pub overlap: f64,
}

impl Shape {
    /// Edge of the shared box: two request sides, so overlapping requests
    /// share most of their tiles but rarely all of them.
    fn hot_extent(&self) -> i64 {
        2 * self.side.max(self.brick_size) as i64
    }

    fn lod_query(&self) -> String {
        format!("lod={}", self.lod)
    }
}

/// The random mixed workload of one client.
pub struct Mixed {
    rng: Rng,
    mix: Vec<Kind>,
    shape: Shape,
}

impl Mixed {
    /// Client `worker` of a run seeded with `seed`.
    pub fn new(seed: u64, worker: u64, mix: Vec<Kind>, shape: Shape) -> Mixed {
        assert!(!mix.is_empty(), "a workload needs at least one kind");
        Mixed {
            rng: Rng::new(seed, worker),
            mix,
            shape,
        }
    }

    /// The next request.
    pub fn next_request(&mut self) -> Request {
        let kind = self.mix[(self.rng.next_u64() % self.mix.len() as u64) as usize];
        let hot = self.rng.unit() < self.shape.overlap;
        let s = &self.shape;
        let side = s.side as i64;
        // A start coordinate such that `len` voxels from it stay in range.
        let hot_extent = s.hot_extent();
        let mut start = |len: i64| {
            if hot {
                self.rng.range(0, (hot_extent - len).max(1))
            } else {
                self.rng.range(-FAR, FAR)
            }
        };
        let path = match kind {
            Kind::Slice => {
                let at = start(1);
                let (u0, v0) = (start(side), start(side));
                let axis = ["x", "y", "z"][(self.rng.next_u64() % 3) as usize];
                format!(
                    "/slices/{axis}/{at}.png?u0={u0}&v0={v0}&w={side}&h={side}&{}",
                    s.lod_query()
                )
            }
            Kind::Cut => {
                // The cut spans side·√2 voxels at most along any axis.
                let o = [0, 1, 2].map(|_| start(side * 3 / 2) as f64);
                let (u, v) = plane_axes(self.rng.direction());
                // Centre the plane on `o` so tilted cuts stay in the box.
                let half = side as f64 / 2.0;
                let origin = [0, 1, 2].map(|a| o[a] + half - half * (u[a] + v[a]));
                format!(
                    "/cut.png?origin={}&u={}&v={}&w={side}&h={side}&{}",
                    vec3(origin),
                    vec3(u),
                    vec3(v),
                    s.lod_query()
                )
            }
            Kind::Brick => {
                let e = s.brick_size as i64;
                let b = [0, 1, 2].map(|_| start(e).div_euclid(e));
                format!("/bricks/{}/{}_{}_{}.raw", s.lod, b[0], b[1], b[2])
            }
        };
        Request { kind, path }
    }
}

/// A plane sweeping through the volume one voxel per request: the
/// interactive cutting session of the papers. Each client sweeps its own,
/// far-apart part of the volume.
pub struct Sweep {
    plane: SweepPlane,
    shape: Shape,
    origin: [i64; 3],
    normal: [f64; 3],
    axes: ([f64; 3], [f64; 3]),
    step: i64,
}

impl Sweep {
    /// The sweep of client `worker`.
    pub fn new(seed: u64, worker: u64, plane: SweepPlane, shape: Shape) -> Sweep {
        let mut rng = Rng::new(seed, worker);
        let origin = [0, 1, 2].map(|_| rng.range(-FAR, FAR));
        let normal = rng.direction();
        Sweep {
            plane,
            shape,
            origin,
            normal,
            axes: plane_axes(normal),
            step: 0,
        }
    }

    /// The next position of the plane.
    pub fn next_request(&mut self) -> Request {
        let s = &self.shape;
        let side = s.side;
        let [x, y, z] = self.origin;
        let t = self.step;
        self.step += 1;
        match self.plane {
            SweepPlane::Axis => Request {
                kind: Kind::Slice,
                path: format!(
                    "/slices/z/{}.png?u0={x}&v0={y}&w={side}&h={side}&{}",
                    z + t,
                    s.lod_query()
                ),
            },
            SweepPlane::Oblique => {
                let (u, v) = self.axes;
                let origin = [0, 1, 2].map(|a| self.origin[a] as f64 + t as f64 * self.normal[a]);
                Request {
                    kind: Kind::Cut,
                    path: format!(
                        "/cut.png?origin={}&u={}&v={}&w={side}&h={side}&{}",
                        vec3(origin),
                        vec3(u),
                        vec3(v),
                        s.lod_query()
                    ),
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shape() -> Shape {
        Shape {
            lod: 1,
            side: 32,
            brick_size: 16,
            overlap: 0.5,
        }
    }

    #[test]
    fn sequences_depend_only_on_seed_and_worker() {
        let all = Kind::ALL.to_vec();
        let take = |seed, worker| {
            let mut g = Mixed::new(seed, worker, all.clone(), shape());
            (0..50).map(|_| g.next_request()).collect::<Vec<_>>()
        };
        assert_eq!(take(7, 0), take(7, 0));
        assert_ne!(take(7, 0), take(7, 1));
        assert_ne!(take(7, 0), take(8, 0));
        let kinds: std::collections::HashSet<Kind> = take(7, 0).iter().map(|r| r.kind).collect();
        assert_eq!(kinds.len(), 3, "every kind of the mix is drawn");
    }

    #[test]
    fn overlap_zero_is_far_apart_and_one_stays_in_the_shared_box() {
        let bricks = |overlap| {
            let mut g = Mixed::new(3, 0, vec![Kind::Brick], Shape { overlap, ..shape() });
            (0..200)
                .map(|_| {
                    let p = g.next_request().path;
                    let stem = p.rsplit('/').next().unwrap().trim_end_matches(".raw");
                    stem.split('_')
                        .map(|v| v.parse::<i64>().unwrap())
                        .collect::<Vec<_>>()
                })
                .collect::<Vec<_>>()
        };
        // Shared box: 64 voxels = 4 bricks of 16 per axis.
        assert!(bricks(1.0).iter().flatten().all(|&b| (0..4).contains(&b)));
        let far = bricks(0.0);
        let distinct: std::collections::HashSet<_> = far.iter().collect();
        assert_eq!(distinct.len(), far.len(), "far bricks never repeat");
    }

    #[test]
    fn axis_sweep_advances_one_voxel() {
        let mut s = Sweep::new(1, 2, SweepPlane::Axis, shape());
        let at = |p: &str| -> i64 {
            p.split('/')
                .nth(3)
                .unwrap()
                .split('.')
                .next()
                .unwrap()
                .parse()
                .unwrap()
        };
        let a = s.next_request().path;
        let b = s.next_request().path;
        assert_eq!(at(&b), at(&a) + 1);
        assert!(a.ends_with("w=32&h=32&lod=1"), "{a}");
    }

    #[test]
    fn oblique_axes_are_orthonormal() {
        let mut rng = Rng::new(5, 0);
        for _ in 0..100 {
            let n = rng.direction();
            let (u, v) = plane_axes(n);
            let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
            assert!((dot(u, u) - 1.0).abs() < 1e-9 && (dot(v, v) - 1.0).abs() < 1e-9);
            assert!(dot(u, v).abs() < 1e-9 && dot(u, n).abs() < 1e-9 && dot(v, n).abs() < 1e-9);
        }
    }
}
