//! Anisotropic exemplars (Zhang et al. §6.1): measuring how strongly an
//! exemplar is oriented, and laying it on the three planes so that two of
//! them agree.
//!
//! An exemplar whose grain runs along its u axis is a stack of layers seen
//! edge on. Shown as it is on all three planes it asks for layers normal
//! to y (xy plane), to z (yz) and to x (zx) at once, and the correction
//! settles on a grainless compromise. Layers normal to one axis can show
//! in the two planes that contain that axis, one of them seeing the
//! exemplar turned a quarter; the third plane cuts along a layer, which no
//! part of the exemplar looks like, so it counts little in the matching.
//!
//! The arrangement chosen keeps the xy plane (the z slices) as the
//! exemplar is, and takes the layers normal to the axis across its grain:
//!
//! | grain along | layers normal to | rotate (xy, yz, zx) | weights |
//! | --- | --- | --- | --- |
//! | u | y | 0, 270, 0 | 1, 1, w |
//! | v | x | 0, 0, 90 | 1, w, 1 |
//!
//! The turn keeps the grain's profile in the same order along the shared
//! axis (xy's v runs along +y like yz's u; the exemplar's u along +x like
//! zx's v), so an asymmetric profile (sharp on one side, fading on the
//! other) still matches across the crossbar.
//!
//! Only axis-aligned grain is arranged: a quarter turn maps a tilted grain
//! to a grain tilted the other way, which no layering shows in both
//! planes, and turning by any other angle would break the exemplar's
//! wrap-around.

use crate::analysis::exemplar::{Exemplar, ExemplarSet, luminance};
use crate::error::{Error, Result};
use crate::params::{Arrangement, Orientation};

/// Coherence from which an exemplar counts as strongly oriented: between
/// the shared exemplars that are (wood_wood5, animal_leather) and those
/// that are not (docs/quality.md).
pub const COHERENCE_THRESHOLD: f32 = 0.6;

/// Largest angle between the grain and an image axis for the grain to
/// count as along that axis, in degrees.
pub const AXIS_TOLERANCE: f32 = 15.0;

/// Weight of the plane that cuts along the layers (docs/quality.md).
pub const ACROSS_WEIGHT: f32 = 0.25;

/// How strongly an exemplar is oriented, from the structure tensor of its
/// luminance: the gradients' outer products summed over the whole image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grain {
    /// (λ₁ − λ₂) / (λ₁ + λ₂) of the summed tensor: 0 when gradients point
    /// every way alike, 1 when all are parallel (perfect stripes).
    pub coherence: f32,
    /// Direction of the grain (across the dominant gradient), in degrees
    /// from the image's u axis towards v, in (−90, 90]: 0 is grain along u,
    /// 90 along v.
    pub degrees: f32,
}

impl Grain {
    /// Measures `e` at the pixel scale, where the fine grain of the shared
    /// wood lives (at coarser scales it fades into the noise of other
    /// exemplars' shading).
    pub fn measure(e: &Exemplar) -> Grain {
        let (w, h) = (e.width() as usize, e.height() as usize);
        let lum: Vec<f64> = e.pixels().iter().map(|p| luminance(*p)).collect();
        Grain::of(w, h, true, |x, y| lum[(y % h) * w + x % w])
    }

    /// Measures the `w`×`h` image whose luminance at (x, y) is `at`: over
    /// every pixel with `wrap` (reading `at` one past the edges), else
    /// between the pixels only.
    pub(crate) fn of(w: usize, h: usize, wrap: bool, at: impl Fn(usize, usize) -> f64) -> Grain {
        let (nx, ny) = if wrap {
            (w, h)
        } else {
            (w.saturating_sub(1), h.saturating_sub(1))
        };
        let (mut xx, mut yy, mut xy) = (0f64, 0f64, 0f64);
        for y in 0..ny {
            for x in 0..nx {
                // The gradient at the corner between four pixels: centred,
                // and reaching one pixel rather than two.
                let (a, b, c, d) = (at(x, y), at(x + 1, y), at(x, y + 1), at(x + 1, y + 1));
                let gx = (b - a + d - c) / 2.0;
                let gy = (c - a + d - b) / 2.0;
                xx += gx * gx;
                yy += gy * gy;
                xy += gx * gy;
            }
        }
        let trace = xx + yy;
        let coherence = if trace > 0.0 {
            ((xx - yy).powi(2) + 4.0 * xy * xy).sqrt() / trace
        } else {
            0.0
        };
        // The dominant gradient's angle, in (−90°, 90°]; the grain is
        // across it.
        let gradient = 0.5 * (2.0 * xy).atan2(xx - yy).to_degrees();
        let degrees = if gradient > 0.0 {
            gradient - 90.0
        } else {
            gradient + 90.0
        };
        Grain {
            coherence: coherence as f32,
            degrees: degrees as f32,
        }
    }

    /// The image axis the grain runs along (0 = u, 1 = v), when it is
    /// strongly oriented along one.
    pub fn axis(&self) -> Option<usize> {
        if self.coherence < COHERENCE_THRESHOLD {
            return None;
        }
        let off_u = self.degrees.abs();
        if off_u <= AXIS_TOLERANCE {
            Some(0)
        } else if off_u >= 90.0 - AXIS_TOLERANCE {
            Some(1)
        } else {
            None
        }
    }
}

/// The arrangement a texture's candidates are computed with, and what was
/// measured to choose it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Layout {
    /// Each plane's rotation and weight.
    pub arrangement: Arrangement,
    /// The grain of the xy exemplar.
    pub grain: Grain,
    /// `auto` would arrange this exemplar: one image for all planes,
    /// square, and strongly oriented along one of its axes.
    pub detected: bool,
}

impl Layout {
    /// Resolves `orientation` for `set`. An explicit quarter turn of a
    /// non-square exemplar is refused (the planes share one size).
    pub fn resolve(set: &ExemplarSet, orientation: &Orientation) -> Result<Layout> {
        let grain = Grain::measure(set.plane(0));
        let square = set.width() == set.height();
        let auto = match grain.axis() {
            Some(axis) if set.is_single() && square => Some(arrangement_for(axis)),
            _ => None,
        };
        let arrangement = match orientation {
            Orientation::Auto => auto.unwrap_or_default(),
            Orientation::None => Arrangement::default(),
            Orientation::Given(a) => {
                a.validate()?;
                if !square && a.rotate.iter().any(|r| r % 180 != 0) {
                    return Err(Error::InvalidRequest(format!(
                        "orientation: a quarter turn needs a square exemplar, not {}x{}",
                        set.width(),
                        set.height()
                    )));
                }
                *a
            }
        };
        Ok(Layout {
            arrangement,
            grain,
            detected: auto.is_some(),
        })
    }

    /// The exemplars as the analysis sees them: each plane's turned by its
    /// rotation.
    pub fn apply(&self, set: &ExemplarSet) -> Result<ExemplarSet> {
        let rotate = self.arrangement.rotate;
        if rotate == [0; 3] {
            return Ok(set.clone());
        }
        let [xy, yz, zx] = [0, 1, 2].map(|p| set.plane(p).rotated(rotate[p]));
        ExemplarSet::triple(xy, yz, zx)
    }
}

/// The arrangement for grain along image axis `axis` (0 = u, 1 = v); see
/// the module's table.
fn arrangement_for(axis: usize) -> Arrangement {
    if axis == 0 {
        Arrangement {
            rotate: [0, 270, 0],
            weights: [1.0, 1.0, ACROSS_WEIGHT],
        }
    } else {
        Arrangement {
            rotate: [0, 0, 90],
            weights: [1.0, ACROSS_WEIGHT, 1.0],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Stripes of period 8 whose profile rises over 6 pixels and drops at
    /// once, along u (`along_u`) or along v, with a little hashed noise.
    fn stripes(side: u32, along_u: bool) -> Exemplar {
        let mut rgb = Vec::new();
        for v in 0..side {
            for u in 0..side {
                let across = if along_u { v } else { u };
                let noise = (crate::hash::hash3(3, u as u64, v as u64, 0) % 24) as u32;
                let l = ((across % 8) * 24 + noise) as u8;
                rgb.extend_from_slice(&[l, l, l]);
            }
        }
        Exemplar::from_rgb(side, side, &rgb).unwrap()
    }

    fn noise(side: u32) -> Exemplar {
        let rgb: Vec<u8> = (0..side as u64 * side as u64 * 3)
            .map(|i| crate::hash::hash3(7, i, 0, 0) as u8)
            .collect();
        Exemplar::from_rgb(side, side, &rgb).unwrap()
    }

    #[test]
    fn stripes_are_oriented_and_noise_is_not() {
        let u = Grain::measure(&stripes(32, true));
        assert!(u.coherence > 0.9, "{u:?}");
        assert!(u.degrees.abs() < 1.0, "{u:?}");
        assert_eq!(u.axis(), Some(0));
        let v = Grain::measure(&stripes(32, false));
        assert!(v.coherence > 0.9, "{v:?}");
        assert!(v.degrees.abs() > 89.0, "{v:?}");
        assert_eq!(v.axis(), Some(1));
        let n = Grain::measure(&noise(64));
        assert!(n.coherence < 0.1, "{n:?}");
        assert_eq!(n.axis(), None);
        let flat = Exemplar::from_rgb(16, 16, &[9; 16 * 16 * 3]).unwrap();
        assert_eq!(Grain::measure(&flat).coherence, 0.0);
    }

    #[test]
    fn diagonal_stripes_are_oriented_but_not_arranged() {
        let side = 32u32;
        let mut rgb = Vec::new();
        for v in 0..side {
            for u in 0..side {
                let l = (((u + v) % 8) * 30) as u8;
                rgb.extend_from_slice(&[l, l, l]);
            }
        }
        let e = Exemplar::from_rgb(side, side, &rgb).unwrap();
        let g = Grain::measure(&e);
        assert!(
            g.coherence > 0.9 && (g.degrees.abs() - 45.0).abs() < 1.0,
            "{g:?}"
        );
        let layout = Layout::resolve(&ExemplarSet::single(e), &Orientation::Auto).unwrap();
        assert!(!layout.detected);
        assert_eq!(layout.arrangement, Arrangement::default());
    }

    #[test]
    fn auto_turns_one_plane_so_that_two_show_the_same_layers() {
        for along_u in [true, false] {
            let e = stripes(32, along_u);
            let set = ExemplarSet::single(e.clone());
            let layout = Layout::resolve(&set, &Orientation::Auto).unwrap();
            assert!(layout.detected);
            let planes = layout.apply(&set).unwrap();
            assert!(!planes.is_single());
            // Layers normal to y (grain along u) or x (along v). The yz
            // plane's u and the zx plane's v run along +y and +x like xy's
            // v and u: along those, the plane shows the profile xy shows.
            let profile = |p: usize, along_v: bool| -> Vec<u8> {
                let img = planes.plane(p);
                (0..32)
                    .map(|i| {
                        let (u, v) = if along_v { (0, i) } else { (i, 0) };
                        img.pixels()[v * 32 + u][0] / 24
                    })
                    .collect()
            };
            if along_u {
                assert_eq!(layout.arrangement.rotate, [0, 270, 0]);
                assert_eq!(profile(1, false), profile(0, true));
                assert_eq!(layout.arrangement.weights, [1.0, 1.0, ACROSS_WEIGHT]);
            } else {
                assert_eq!(layout.arrangement.rotate, [0, 0, 90]);
                assert_eq!(profile(2, true), profile(0, false));
                assert_eq!(layout.arrangement.weights, [1.0, ACROSS_WEIGHT, 1.0]);
            }
            // `none` and a given arrangement win over detection.
            let none = Layout::resolve(&set, &Orientation::None).unwrap();
            assert!(none.detected);
            assert_eq!(none.arrangement, Arrangement::default());
            assert_eq!(none.apply(&set).unwrap(), set);
            // One exemplar per plane is the uploader's arrangement.
            let triple = ExemplarSet::triple(e.clone(), e.rotated(90), e).unwrap();
            let own = Layout::resolve(&triple, &Orientation::Auto).unwrap();
            assert!(!own.detected);
            assert_eq!(own.apply(&triple).unwrap(), triple);
        }
    }

    #[test]
    fn a_quarter_turn_needs_a_square_exemplar() {
        let rgb = vec![0u8; 32 * 16 * 3];
        let set = ExemplarSet::single(Exemplar::from_rgb(32, 16, &rgb).unwrap());
        let turn = |r| {
            Orientation::Given(Arrangement {
                rotate: [0, r, 0],
                ..Arrangement::default()
            })
        };
        assert!(matches!(
            Layout::resolve(&set, &turn(90)),
            Err(Error::InvalidRequest(_))
        ));
        let half = Layout::resolve(&set, &turn(180)).unwrap();
        let planes = half.apply(&set).unwrap();
        assert_eq!(planes.plane(1), &set.plane(1).rotated(180));
    }
}
