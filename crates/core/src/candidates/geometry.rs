//! Plane and coordinate conventions shared by the candidate search and the
//! synthesis. Plane p's exemplar has its u axis along volume axis `AXES[p].0`
//! and its v axis along `AXES[p].1`: xy (u=x, v=y), yz (u=y, v=z),
//! zx (u=z, v=x). Exemplar coordinates are pixel indices `y * width + x`.

/// Volume axes (u, v) of each plane: 0 = xy, 1 = yz, 2 = zx.
pub const AXES: [(usize, usize); 3] = [(0, 1), (1, 2), (2, 0)];

/// Exemplar dimensions used to wrap coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Dims {
    /// Width in pixels.
    pub w: u32,
    /// Height in pixels.
    pub h: u32,
    /// ⌈2^RECIP_SHIFT / w⌉: a pixel's column without a division.
    recip: u64,
}

/// Exact for every pixel index below 2^20 and widths up to 2^13 (larger
/// exemplars are refused long before): the rounding of `recip` adds less
/// than 2^-20 to c / w, whose fractional part is at most 1 − 1/w, and
/// c · recip stays below 2^60.
const RECIP_SHIFT: u32 = 40;

impl Dims {
    /// Dimensions of a `w` × `h` image.
    pub fn new(w: u32, h: u32) -> Dims {
        assert!(
            w > 0 && w <= 1 << 13 && (w as u64 * h as u64) <= 1 << 20,
            "exemplar size {w}×{h} out of range"
        );
        Dims {
            w,
            h,
            recip: (1u64 << RECIP_SHIFT).div_ceil(w as u64),
        }
    }

    /// Column of pixel `c`.
    #[inline(always)]
    fn column(self, c: u32) -> u32 {
        self.column_row(c).0
    }

    /// Column and row of pixel `c`, without a division.
    #[inline(always)]
    fn column_row(self, c: u32) -> (u32, u32) {
        debug_assert!(c < 1 << 20);
        let q = ((c as u64 * self.recip) >> RECIP_SHIFT) as u32;
        (c - q * self.w, q)
    }

    /// Pixel `c` moved to the nearest point of the grid of multiples of
    /// `h` (a power of two) in each coordinate, halves rounding up,
    /// wrapping: at spacing h, coordinates closer than h/2 sample the same
    /// content. No division: the coherence filter calls it for every
    /// candidate it tests.
    #[inline]
    pub fn snap(self, c: u32, h: u32) -> u32 {
        debug_assert!(h.is_power_of_two());
        if h == 1 {
            return c;
        }
        let (x, y) = self.column_row(c);
        let shift = h.trailing_zeros();
        let round = |v: u32, n: u32| {
            let mut r = ((v + h / 2) >> shift) << shift;
            while r >= n {
                r -= n;
            }
            r
        };
        round(y, self.h) * self.w + round(x, self.w)
    }

    /// Number of pixels.
    #[inline]
    pub fn len(self) -> usize {
        self.w as usize * self.h as usize
    }

    /// True for a zero-sized image.
    pub fn is_empty(self) -> bool {
        self.len() == 0
    }

    /// (x, y) of pixel index `c`.
    #[inline]
    pub fn xy(self, c: u32) -> (i64, i64) {
        ((c % self.w) as i64, (c / self.w) as i64)
    }

    /// Pixel index of (x, y), wrapping.
    #[inline]
    pub fn index(self, x: i64, y: i64) -> u32 {
        let xi = x.rem_euclid(self.w as i64) as u32;
        let yi = y.rem_euclid(self.h as i64) as u32;
        yi * self.w + xi
    }

    /// Pixel `c` moved by (du, dv), wrapping. Hot in the correction: a move
    /// along v is a multiple of the width (no division), and a move along u
    /// needs only the column.
    #[inline]
    pub fn shift(self, c: u32, du: i64, dv: i64) -> u32 {
        let w = self.w as i64;
        let mut c = c as i64;
        if du != 0 {
            let x = self.column(c as u32) as i64;
            let nx = x + du;
            let nx = if (0..w).contains(&nx) {
                nx
            } else {
                nx.rem_euclid(w)
            };
            c += nx - x;
        }
        if dv != 0 {
            let len = self.len() as i64;
            c += dv * w;
            if !(0..len).contains(&c) {
                c = c.rem_euclid(len);
            }
        }
        c as u32
    }
}

/// The (u, v) offset in plane `p` of a 3D offset `d`: Zhang et al.'s
/// `T + d` (eq. 4) applies this to each coordinate of a triple.
#[inline]
pub fn project(p: usize, d: [i64; 3]) -> (i64, i64) {
    let (a, b) = AXES[p];
    (d[a], d[b])
}

/// A triple moved coherently by the 3D offset `d` scaled by `h`.
#[inline(always)]
pub fn offset_triple(dims: Dims, t: [u32; 3], d: [i64; 3], h: i64) -> [u32; 3] {
    let mut out = t;
    for (p, o) in out.iter_mut().enumerate() {
        let (du, dv) = project(p, d);
        *o = dims.shift(t[p], du * h, dv * h);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_need_no_division() {
        for w in [
            1, 2, 3, 7, 13, 100, 127, 128, 129, 1000, 4093, 6000, 8191, 8192,
        ] {
            let dims = Dims::new(w, 1);
            let rows = (1u32 << 20) / w;
            for y in [0, 1, 2, rows / 3, rows / 2, rows - 2, rows - 1] {
                for x in [0, 1, w / 2, w - 1].into_iter().filter(|&x| x < w) {
                    let c = y * w + x;
                    assert_eq!(dims.column(c), x, "w {w}, pixel {c}");
                }
            }
        }
    }

    #[test]
    fn snapping_rounds_each_coordinate_to_the_grid_and_wraps() {
        for (w, h) in [(16, 16), (17, 23), (100, 100), (128, 96), (13, 40)] {
            let dims = Dims::new(w, h);
            for step in [1, 2, 4, 8, 16, 32] {
                for c in 0..dims.len() as u32 {
                    let (x, y) = dims.xy(c);
                    let round = |v: i64| (v + step / 2).div_euclid(step) * step;
                    assert_eq!(
                        dims.snap(c, step as u32),
                        dims.index(round(x), round(y)),
                        "{w}×{h}, spacing {step}, pixel {c}"
                    );
                }
            }
        }
    }

    #[test]
    fn shifting_a_pixel_wraps_like_its_coordinates() {
        let dims = Dims::new(13, 7);
        for c in 0..dims.len() as u32 {
            let (x, y) = dims.xy(c);
            for du in -30..=30 {
                for dv in [-22, -8, -7, -1, 0, 1, 3, 6, 7, 15] {
                    assert_eq!(
                        dims.shift(c, du, dv),
                        dims.index(x + du, y + dv),
                        "pixel {c} moved by ({du}, {dv})"
                    );
                }
            }
        }
    }
}
