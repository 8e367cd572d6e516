//! Exemplars: the small 2D RGB images a solid texture is synthesized from.
//!
//! One exemplar may serve all three planes (xy, yz, zx) or each plane gets
//! its own; all three must then have equal size.

use super::decode::{self, Header};
use crate::error::{Error, Result};

/// Smallest accepted exemplar side in pixels.
pub const MIN_SIDE: u32 = 16;
/// Largest accepted exemplar side in pixels.
pub const MAX_SIDE: u32 = 512;
/// Largest photo side that [`Exemplar::decode_fitting`] downscales to
/// `MAX_SIDE` (a 24-megapixel camera image, 6000×4000, fits).
pub const MAX_PHOTO_SIDE: u32 = 6000;

/// An RGB8 image, row-major, toroidally addressed by the synthesis, with
/// an optional feature mask: which pixels belong to the exemplar's
/// features (veins, cracks, mortar), as drawn by a user.
#[derive(Clone, PartialEq, Eq)]
pub struct Exemplar {
    width: u32,
    height: u32,
    pixels: Vec<[u8; 3]>,
    feature_mask: Option<Vec<bool>>,
}

impl std::fmt::Debug for Exemplar {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Exemplar({}x{}", self.width, self.height)?;
        if self.feature_mask.is_some() {
            write!(f, ", feature mask")?;
        }
        write!(f, ")")
    }
}

impl Exemplar {
    /// Largest side an exemplar may have, in pixels.
    pub const MAX_SIDE: u32 = MAX_SIDE;

    /// Builds an exemplar from packed RGB8 bytes, validating its size.
    pub fn from_rgb(width: u32, height: u32, rgb: &[u8]) -> Result<Self> {
        check_side(width, height)?;
        if rgb.len() != width as usize * height as usize * 3 {
            return Err(Error::MalformedImage(format!(
                "expected {} RGB bytes for {width}x{height}, got {}",
                width as usize * height as usize * 3,
                rgb.len()
            )));
        }
        let pixels = rgb.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        Ok(Exemplar {
            width,
            height,
            pixels,
            feature_mask: None,
        })
    }

    /// The same exemplar with `mask` (one flag per pixel, row-major; true
    /// for feature pixels) as its feature mask. A mask of one class only
    /// has no edges to measure a distance to, and is refused.
    pub fn with_feature_mask(mut self, mask: Vec<bool>) -> Result<Self> {
        if mask.len() != self.pixels.len() {
            return Err(Error::SizeMismatch(format!(
                "the feature mask has {} pixels but the exemplar {}x{} has {}",
                mask.len(),
                self.width,
                self.height,
                self.pixels.len()
            )));
        }
        let features = mask.iter().filter(|&&f| f).count();
        if features == 0 || features == mask.len() {
            return Err(Error::InvalidRequest(format!(
                "the feature mask is {} everywhere: mark the features in white \
                 and the rest in black",
                if features == 0 { "black" } else { "white" }
            )));
        }
        self.feature_mask = Some(mask);
        Ok(self)
    }

    /// The same exemplar with the feature mask drawn in `image`, an image of
    /// the same size: pixels of luminance at least 128 (light) are
    /// features.
    pub fn with_mask_image(self, image: &Exemplar) -> Result<Self> {
        if (image.width, image.height) != (self.width, self.height) {
            return Err(Error::SizeMismatch(format!(
                "the feature mask is {}x{} but the exemplar is {}x{}",
                image.width, image.height, self.width, self.height
            )));
        }
        let mask = image
            .pixels
            .iter()
            .map(|&p| luminance(p) >= 128.0)
            .collect();
        self.with_feature_mask(mask)
    }

    /// The feature mask, when one was given: a flag per pixel, row-major.
    pub fn feature_mask(&self) -> Option<&[bool]> {
        self.feature_mask.as_deref()
    }

    /// The feature mask as an RGB8 image (features white, the rest black),
    /// when one was given.
    pub fn feature_mask_image(&self) -> Option<Exemplar> {
        let mask = self.feature_mask.as_ref()?;
        Some(Exemplar {
            width: self.width,
            height: self.height,
            pixels: mask
                .iter()
                .map(|&f| if f { [255; 3] } else { [0; 3] })
                .collect(),
            feature_mask: None,
        })
    }

    /// Decodes a PNG or JPEG image of 16 to 512 pixels per side (as
    /// displayed: its EXIF orientation applied). The header is checked
    /// before any pixel is allocated, so a decompression bomb is rejected
    /// cheaply; data that ends early is an error.
    pub fn decode(bytes: &[u8]) -> Result<Self> {
        let header = Header::read(bytes)?;
        check_side(header.width, header.height)?;
        Self::from_decoded(decode::decode(bytes, &header, None)?)
    }

    /// Like [`Exemplar::decode`], but a photo larger than `MAX_SIDE` (up to
    /// `MAX_PHOTO_SIDE` per side) is downscaled to fit, keeping its aspect
    /// ratio, without holding it at full size where its format allows
    /// (see `decode`). Returns the original size when it was downscaled,
    /// so that the caller can say so.
    pub fn decode_fitting(bytes: &[u8]) -> Result<(Self, Option<(u32, u32)>)> {
        let header = Header::read(bytes)?;
        let (w, h) = (header.width, header.height);
        match fitted_size(&header)? {
            None => Ok((Self::decode(bytes)?, None)),
            Some(fit) => {
                let e = Self::from_decoded(decode::decode(bytes, &header, Some(fit))?)?;
                Ok((e, Some((w, h))))
            }
        }
    }

    /// The most heap bytes [`Exemplar::decode_fitting`] takes to decode
    /// `bytes`, from its header alone; an error when the header is
    /// unreadable or the size is refused (as the decode would refuse it).
    pub fn decode_peak_bytes(bytes: &[u8]) -> Result<u64> {
        let header = Header::read(bytes)?;
        let fit = match fitted_size(&header)? {
            Some(fit) => fit,
            None => {
                check_side(header.width, header.height)?;
                (header.width, header.height)
            }
        };
        Ok(header.peak_bytes(fit))
    }

    fn from_decoded(d: decode::Decoded) -> Result<Self> {
        Self::from_rgb(d.width, d.height, &d.rgb)
    }

    /// Reads and decodes an image file.
    pub fn open(path: impl AsRef<std::path::Path>) -> Result<Self> {
        let bytes = std::fs::read(path)?;
        Self::decode(&bytes)
    }

    /// Reads and decodes an image file, downscaling a large photo
    /// ([`Exemplar::decode_fitting`]).
    pub fn open_fitting(path: impl AsRef<std::path::Path>) -> Result<(Self, Option<(u32, u32)>)> {
        let bytes = std::fs::read(path)?;
        Self::decode_fitting(&bytes)
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Pixels, row-major.
    pub fn pixels(&self) -> &[[u8; 3]] {
        &self.pixels
    }

    /// The image turned clockwise as displayed (u right, v down) by
    /// `degrees`: 0, 90, 180 or 270 (anything else is taken modulo 360 and
    /// rounded down to a quarter turn). A quarter turn swaps width and
    /// height.
    /// The feature mask turns with the image.
    pub fn rotated(&self, degrees: u32) -> Exemplar {
        let quarters = degrees % 360 / 90;
        if quarters == 0 {
            return self.clone();
        }
        let (w, h) = (self.width as usize, self.height as usize);
        let (width, height) = if quarters == 2 { (w, h) } else { (h, w) };
        Exemplar {
            width: width as u32,
            height: height as u32,
            pixels: turned(&self.pixels, w, h, quarters),
            feature_mask: self
                .feature_mask
                .as_ref()
                .map(|m| turned(m, w, h, quarters)),
        }
    }

    /// Packed RGB8 bytes, row-major.
    pub fn to_rgb_bytes(&self) -> Vec<u8> {
        self.pixels.iter().flatten().copied().collect()
    }
}

/// Rec. 601 luminance of an RGB8 pixel.
pub(crate) fn luminance(p: [u8; 3]) -> f64 {
    0.299 * p[0] as f64 + 0.587 * p[1] as f64 + 0.114 * p[2] as f64
}

/// The `w`×`h` row-major image `image` turned clockwise by `quarters`
/// quarter turns (1 to 3).
fn turned<T: Copy>(image: &[T], w: usize, h: usize, quarters: u32) -> Vec<T> {
    let at = |u: usize, v: usize| image[v * w + u];
    match quarters {
        // The left column, bottom to top, becomes the top row.
        1 => grid(h, w, |u, v| at(v, h - 1 - u)),
        2 => grid(w, h, |u, v| at(w - 1 - u, h - 1 - v)),
        // The right column, top to bottom, becomes the top row.
        _ => grid(h, w, |u, v| at(w - 1 - v, u)),
    }
}

/// A `width`×`height` image, row-major, from a function of (u, v).
fn grid<T>(width: usize, height: usize, f: impl Fn(usize, usize) -> T) -> Vec<T> {
    (0..height)
        .flat_map(|v| (0..width).map(move |u| (u, v)))
        .map(|(u, v)| f(u, v))
        .collect()
}

/// The size a photo larger than `MAX_SIDE` is downscaled to (its longer
/// side `MAX_SIDE`, the aspect ratio kept), `None` for an image that fits
/// already; an error for one over `MAX_PHOTO_SIDE`, or too thin to keep
/// [`MIN_SIDE`] once downscaled.
fn fitted_size(header: &Header) -> Result<Option<(u32, u32)>> {
    let (w, h) = (header.width, header.height);
    if w <= MAX_SIDE && h <= MAX_SIDE {
        return Ok(None);
    }
    let refused = |max| Error::ImageSize {
        width: w,
        height: h,
        min: MIN_SIDE,
        max,
    };
    if w > MAX_PHOTO_SIDE || h > MAX_PHOTO_SIDE {
        // Photos up to MAX_PHOTO_SIDE are downscaled; larger ones are not.
        return Err(refused(MAX_PHOTO_SIDE));
    }
    let long = u64::from(w.max(h));
    let fit = |s: u32| ((u64::from(s) * u64::from(MAX_SIDE) + long / 2) / long) as u32;
    let (fw, fh) = (fit(w), fit(h));
    // Too thin to keep MIN_SIDE once downscaled: say what was sent.
    check_side(fw, fh).map_err(|_| refused(MAX_SIDE))?;
    Ok(Some((fw, fh)))
}

fn check_side(width: u32, height: u32) -> Result<()> {
    let ok = |s: u32| (MIN_SIDE..=MAX_SIDE).contains(&s);
    if ok(width) && ok(height) {
        Ok(())
    } else {
        Err(Error::ImageSize {
            width,
            height,
            min: MIN_SIDE,
            max: MAX_SIDE,
        })
    }
}

/// The exemplars of the three planes. `xy` is sampled in the plane spanned by
/// the x and y axes (image u along x, v along y), `yz` with u along y and v
/// along z, `zx` with u along z and v along x.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ExemplarSet {
    planes: [Exemplar; 3],
}

impl ExemplarSet {
    /// One exemplar used for all three planes.
    pub fn single(e: Exemplar) -> Self {
        ExemplarSet {
            planes: [e.clone(), e.clone(), e],
        }
    }

    /// Three exemplars of equal size, for the xy, yz and zx planes.
    pub fn triple(xy: Exemplar, yz: Exemplar, zx: Exemplar) -> Result<Self> {
        let (w, h) = (xy.width, xy.height);
        for (name, e) in [("yz", &yz), ("zx", &zx)] {
            if (e.width, e.height) != (w, h) {
                return Err(Error::SizeMismatch(format!(
                    "xy is {w}x{h} but {name} is {}x{}",
                    e.width, e.height
                )));
            }
        }
        Ok(ExemplarSet {
            planes: [xy, yz, zx],
        })
    }

    /// The exemplar of plane `p` (0 = xy, 1 = yz, 2 = zx).
    pub fn plane(&self, p: usize) -> &Exemplar {
        &self.planes[p]
    }

    /// True when all three planes hold the same image, which lets the
    /// candidate search run once and derive the other planes by symmetry.
    pub fn is_single(&self) -> bool {
        self.planes[0] == self.planes[1] && self.planes[1] == self.planes[2]
    }

    /// True when some plane has a feature mask.
    pub fn has_feature_mask(&self) -> bool {
        self.planes.iter().any(|e| e.feature_mask.is_some())
    }

    /// Width of every plane.
    pub fn width(&self) -> u32 {
        self.planes[0].width
    }

    /// Height of every plane.
    pub fn height(&self) -> u32 {
        self.planes[0].height
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn png(w: u32, h: u32) -> Vec<u8> {
        let rgb: Vec<u8> = (0..w * h * 3).map(|i| (i % 251) as u8).collect();
        crate::png::encode(w, h, &rgb).unwrap()
    }

    #[test]
    fn rotations_turn_the_image_clockwise_and_compose() {
        // 16 wide, 20 tall: pixel (u, v) holds [u, v, 0].
        let (w, h) = (16u8, 20u8);
        let rgb: Vec<u8> = (0..h)
            .flat_map(|v| (0..w).flat_map(move |u| [u, v, 0]))
            .collect();
        let e = Exemplar::from_rgb(w as u32, h as u32, &rgb).unwrap();
        let at = |e: &Exemplar, u: u32, v: u32| e.pixels()[(v * e.width() + u) as usize];
        let cw = e.rotated(90);
        assert_eq!((cw.width(), cw.height()), (20, 16));
        // Clockwise: the bottom-left corner comes to the top left, the
        // top-left corner to the top right.
        assert_eq!(at(&cw, 0, 0), [0, h - 1, 0]);
        assert_eq!(at(&cw, 19, 0), [0, 0, 0]);
        assert_eq!(at(&cw, 0, 1), [1, h - 1, 0]);
        // Counter-clockwise: the top-right corner comes to the top left.
        let ccw = e.rotated(270);
        assert_eq!(at(&ccw, 0, 0), [w - 1, 0, 0]);
        assert_eq!(at(&e.rotated(180), 0, 0), [w - 1, h - 1, 0]);
        assert_eq!(e.rotated(0), e);
        assert_eq!(e.rotated(360), e);
        assert_eq!(cw.rotated(90), e.rotated(180));
        assert_eq!(cw.rotated(270), e);
        assert_eq!(ccw.rotated(90), e);
        assert_eq!(e.rotated(180).rotated(180), e);
    }

    #[test]
    fn photos_up_to_the_photo_limit_are_downscaled_and_larger_ones_refused() {
        let (e, original) = Exemplar::decode_fitting(&png(MAX_PHOTO_SIDE, 376)).unwrap();
        assert_eq!((e.width(), e.height()), (MAX_SIDE, 32));
        assert_eq!(original, Some((MAX_PHOTO_SIDE, 376)));
        // At the exemplar limit nothing is downscaled.
        let (e, original) = Exemplar::decode_fitting(&png(MAX_SIDE, 20)).unwrap();
        assert_eq!((e.width(), e.height(), original), (MAX_SIDE, 20, None));
        let size_error = |w, h| match Exemplar::decode_fitting(&png(w, h)) {
            Err(Error::ImageSize { width, height, .. }) => (width, height),
            other => panic!("{w}x{h}: {other:?}"),
        };
        // Past the photo limit, and too thin to keep MIN_SIDE: the size sent.
        assert_eq!(
            size_error(MAX_PHOTO_SIDE + 1, 376),
            (MAX_PHOTO_SIDE + 1, 376)
        );
        assert_eq!(size_error(600, 16), (600, 16));
        // The strict decoder still refuses anything over MAX_SIDE.
        assert!(Exemplar::decode(&png(MAX_SIDE + 1, 20)).is_err());
    }

    #[test]
    fn a_feature_mask_turns_with_the_image_and_needs_both_classes() {
        let (w, h) = (16u32, 20u32);
        let rgb: Vec<u8> = (0..w * h * 3).map(|i| (i % 251) as u8).collect();
        let e = Exemplar::from_rgb(w, h, &rgb).unwrap();
        // A light mask pixel at (3, 1) and at (0, 19) marks the features.
        let mut mask_rgb = vec![0u8; (w * h * 3) as usize];
        for (u, v) in [(3u32, 1u32), (0, 19)] {
            mask_rgb[((v * w + u) * 3) as usize..][..3].copy_from_slice(&[250, 240, 200]);
        }
        let image = Exemplar::from_rgb(w, h, &mask_rgb).unwrap();
        let masked = e.clone().with_mask_image(&image).unwrap();
        let mask = masked.feature_mask().unwrap();
        assert_eq!(mask.iter().filter(|&&f| f).count(), 2);
        assert!(mask[(w + 3) as usize] && mask[(19 * w) as usize]);
        assert_ne!(masked, e, "the mask is part of the exemplar");
        assert_eq!(masked.feature_mask_image().unwrap(), {
            let white: Vec<u8> = mask
                .iter()
                .flat_map(|&f| if f { [255; 3] } else { [0; 3] })
                .collect();
            Exemplar::from_rgb(w, h, &white).unwrap()
        });
        // Turned, the mask follows its pixels: the bottom-left corner comes
        // to the top left.
        for degrees in [90, 180, 270] {
            let turned = masked.rotated(degrees);
            let want = image.rotated(degrees);
            let flags: Vec<bool> = want.pixels().iter().map(|p| p[0] > 128).collect();
            assert_eq!(turned.feature_mask().unwrap(), &flags[..], "{degrees}°");
            assert_eq!(turned.pixels(), e.rotated(degrees).pixels());
        }
        assert!(masked.rotated(90).feature_mask().unwrap()[0]);
        // One class only, or another size, is refused.
        let black = Exemplar::from_rgb(w, h, &vec![0u8; (w * h * 3) as usize]).unwrap();
        assert!(matches!(
            e.clone().with_mask_image(&black),
            Err(Error::InvalidRequest(_))
        ));
        let white = Exemplar::from_rgb(w, h, &vec![255u8; (w * h * 3) as usize]).unwrap();
        assert!(e.clone().with_mask_image(&white).is_err());
        assert!(matches!(
            e.with_mask_image(&image.rotated(90)),
            Err(Error::SizeMismatch(_))
        ));
    }
}
