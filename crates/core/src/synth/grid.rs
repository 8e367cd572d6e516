//! Boxes of voxels at one pyramid level and dense grids of triples over them.

/// A half-open box `[lo, hi)` of voxel positions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Box3 {
    /// Lowest corner (inclusive).
    pub lo: [i64; 3],
    /// Highest corner (exclusive).
    pub hi: [i64; 3],
}

/// A request's region as the engine's half-open box: the public type keeps
/// the request's shape (corner and unsigned size, checked once), this one
/// the arithmetic the planner and grids need.
impl From<&crate::request::Region> for Box3 {
    fn from(r: &crate::request::Region) -> Self {
        Box3::new(r.origin, r.size.map(i64::from))
    }
}

impl Box3 {
    /// The box of `size` voxels starting at `lo`.
    pub fn new(lo: [i64; 3], size: [i64; 3]) -> Self {
        Box3 {
            lo,
            hi: [lo[0] + size[0], lo[1] + size[1], lo[2] + size[2]],
        }
    }

    /// Calls `f` for each voxel whose coordinates are congruent to `phase`
    /// modulo `side`: one subpass class of the box.
    pub fn for_class(&self, phase: [i64; 3], side: i64, mut f: impl FnMut([i64; 3])) {
        let start = |a: usize| self.lo[a] + (phase[a] - self.lo[a]).rem_euclid(side);
        let mut z = start(2);
        while z < self.hi[2] {
            let mut y = start(1);
            while y < self.hi[1] {
                let mut x = start(0);
                while x < self.hi[0] {
                    f([x, y, z]);
                    x += side;
                }
                y += side;
            }
            z += side;
        }
    }

    /// Extent per axis.
    pub fn size(&self) -> [i64; 3] {
        [
            self.hi[0] - self.lo[0],
            self.hi[1] - self.lo[1],
            self.hi[2] - self.lo[2],
        ]
    }

    /// Number of voxels.
    pub fn volume(&self) -> u64 {
        self.size().iter().map(|&s| s.max(0) as u64).product()
    }

    /// Grown by `r` on every side.
    pub fn dilate(&self, r: i64) -> Self {
        Box3 {
            lo: self.lo.map(|v| v - r),
            hi: self.hi.map(|v| v + r),
        }
    }

    /// Smallest box of parent-level voxels whose children cover this box.
    pub fn parent(&self) -> Self {
        Box3 {
            lo: self.lo.map(|v| v.div_euclid(2)),
            hi: self.hi.map(|v| (v - 1).div_euclid(2) + 1),
        }
    }

    /// True if `p` lies inside.
    #[inline]
    pub fn contains(&self, p: [i64; 3]) -> bool {
        (0..3).all(|a| p[a] >= self.lo[a] && p[a] < self.hi[a])
    }

    /// Intersection (may be empty).
    pub fn intersect(&self, o: &Box3) -> Box3 {
        Box3 {
            lo: [0, 1, 2].map(|a| self.lo[a].max(o.lo[a])),
            hi: [0, 1, 2].map(|a| self.hi[a].min(o.hi[a])),
        }
    }

    /// True if no voxel lies inside.
    pub fn is_empty(&self) -> bool {
        (0..3).any(|a| self.hi[a] <= self.lo[a])
    }

    /// Smallest box containing both.
    pub fn union(&self, o: &Box3) -> Box3 {
        Box3 {
            lo: [0, 1, 2].map(|a| self.lo[a].min(o.lo[a])),
            hi: [0, 1, 2].map(|a| self.hi[a].max(o.hi[a])),
        }
    }
}

/// A dense box of values, x fastest.
#[derive(Clone, Debug)]
pub struct Grid<T> {
    /// The box covered.
    pub bounds: Box3,
    /// Values, x fastest, then y, then z.
    pub data: Vec<T>,
    sx: usize,
    sy: usize,
}

impl<T: Copy + Default> Grid<T> {
    /// A grid over `bounds` filled with the default value.
    pub fn new(bounds: Box3) -> Self {
        let s = bounds.size();
        Grid {
            bounds,
            data: vec![T::default(); bounds.volume() as usize],
            sx: s[0] as usize,
            sy: s[1] as usize,
        }
    }

    /// Index steps along x, y and z.
    pub fn strides(&self) -> [i64; 3] {
        [1, self.sx as i64, (self.sx * self.sy) as i64]
    }

    /// Linear index of `p` (must be inside).
    #[inline]
    pub fn index(&self, p: [i64; 3]) -> usize {
        let x = (p[0] - self.bounds.lo[0]) as usize;
        let y = (p[1] - self.bounds.lo[1]) as usize;
        let z = (p[2] - self.bounds.lo[2]) as usize;
        (z * self.sy + y) * self.sx + x
    }

    /// Value at `p` (must be inside).
    #[inline]
    pub fn get(&self, p: [i64; 3]) -> T {
        self.data[self.index(p)]
    }

    /// Position of linear index `i`.
    #[inline]
    pub fn position(&self, i: usize) -> [i64; 3] {
        let x = i % self.sx;
        let y = (i / self.sx) % self.sy;
        let z = i / (self.sx * self.sy);
        [
            self.bounds.lo[0] + x as i64,
            self.bounds.lo[1] + y as i64,
            self.bounds.lo[2] + z as i64,
        ]
    }

    /// Copies the part of `src` that overlaps this grid.
    pub fn copy_from(&mut self, src: &Grid<T>) {
        let b = self.bounds.intersect(&src.bounds);
        if b.is_empty() {
            return;
        }
        let run = (b.hi[0] - b.lo[0]) as usize;
        for z in b.lo[2]..b.hi[2] {
            for y in b.lo[1]..b.hi[1] {
                let d = self.index([b.lo[0], y, z]);
                let s = src.index([b.lo[0], y, z]);
                self.data[d..d + run].copy_from_slice(&src.data[s..s + run]);
            }
        }
    }
}
