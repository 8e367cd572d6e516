//! Plane and coordinate conventions shared by the candidate search and the
//! synthesis. Plane p's exemplar has its u axis along volume axis `AXES[p].0`
//! and its v axis along `AXES[p].1`: xy (u=x, v=y), yz (u=y, v=z),
//! zx (u=z, v=x). Exemplar coordinates are pixel indices `y * width + x`.

/// Volume axes (u, v) of each plane: 0 = xy, 1 = yz, 2 = zx.
pub const AXES: [(usize, usize); 3] = [(0, 1), (1, 2), (2, 0)];

/// Plane names, for reports.
pub const PLANE_NAMES: [&str; 3] = ["xy", "yz", "zx"];

/// Exemplar dimensions used to wrap coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Dims {
    /// Width in pixels.
    pub w: u32,
    /// Height in pixels.
    pub h: u32,
}

impl Dims {
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
            let x = (c as u32 % self.w) as i64;
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
#[inline]
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
    fn shifting_a_pixel_wraps_like_its_coordinates() {
        let dims = Dims { w: 13, h: 7 };
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
