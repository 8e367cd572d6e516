//! Reading an exemplar from an image file, PNG or JPEG, with what it may
//! cost known before any pixel is decoded.
//!
//! - The header alone gives the size, and with it the most that decoding
//!   will allocate ([`Header::peak_bytes`]): a caller decoding many images
//!   at once (the server) admits each by that figure.
//! - A JPEG's header is also checked against the file's length: every 8×8
//!   block of its first component takes at least one bit, so a 15 KB file
//!   that claims 6000×6000 pixels is refused before its pixels are
//!   allocated.
//! - A photo larger than an exemplar may be is reduced as its rows arrive:
//!   each pixel of the reduced image is the mean of a box of f×f pixels
//!   (f the largest whole factor that keeps it at least as large as the
//!   exemplar), and a Lanczos3 resize does the rest (a factor below two,
//!   so that it still sees every pixel of the reduced image). A
//!   PNG is read row by row, so the full-size image is never held; an
//!   interlaced PNG and a JPEG (whose decoder writes the whole image) are
//!   decoded whole first, and their estimates say so.
//! - Decoding is strict: data that ends before the last row, or a PNG
//!   chunk that does not check, is an error, never rows padded with grey.
//!   A JPEG decoder reads past the end of a scan as zero bits (as
//!   libjpeg does, with a warning), so a JPEG whose scan is closed before
//!   its last row would pass: it is decoded a second time with bits of one
//!   put before its end marker, and refused when that changes a pixel.
//! - An EXIF orientation (a JPEG's APP1, a PNG's eXIf) is applied, so an
//!   image comes out the way a viewer displays it.

use crate::error::{Error, Result};
use image::metadata::Orientation;
use std::io::Cursor;

/// The two formats read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// PNG, any colour type and bit depth.
    Png,
    /// Baseline or progressive JPEG (Huffman-coded).
    Jpeg,
}

/// What an image's header says about it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Header {
    /// Its format.
    pub format: Format,
    /// Width in pixels, as stored (before any EXIF orientation).
    pub width: u32,
    /// Height in pixels, as stored.
    pub height: u32,
    /// A PNG stored interlaced, or a progressive JPEG: decoded whole.
    whole: bool,
    /// Colour components (a JPEG's), or samples per pixel (a PNG's).
    components: u32,
    /// Bytes of the file.
    len: u64,
}

/// Fixed costs of a decode besides its images: the decoders' tables and
/// buffers, the zlib window, the resize's kernels.
const DECODER_BYTES: u64 = 4 << 20;

impl Header {
    /// Reads the header of a PNG or JPEG image without decoding pixels.
    pub fn read(bytes: &[u8]) -> Result<Header> {
        if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
            let reader = png_reader(bytes)?;
            let info = reader.info();
            let (color, _) = reader.output_color_type();
            Ok(Header {
                format: Format::Png,
                width: info.width,
                height: info.height,
                whole: info.interlaced,
                components: color.samples() as u32,
                len: bytes.len() as u64,
            })
        } else if bytes.starts_with(&[0xff, 0xd8]) {
            let mut d = jpeg_decoder(bytes);
            d.decode_headers().map_err(jpeg_error)?;
            let info = d
                .info()
                .ok_or_else(|| malformed("JPEG without a frame header"))?;
            let header = Header {
                format: Format::Jpeg,
                width: u32::from(info.width),
                height: u32::from(info.height),
                whole: !info.sof.is_sequential_dct(),
                components: u32::from(info.components).max(1),
                len: bytes.len() as u64,
            };
            header.check_jpeg_length(bytes.len())?;
            Ok(header)
        } else {
            Err(malformed(
                "unrecognised image format (expected PNG or JPEG)",
            ))
        }
    }

    /// Refuses a JPEG too short to hold the pixels its header claims: each
    /// 8×8 block of the full-resolution component is Huffman-coded with at
    /// least one bit (its DC code) in some scan.
    fn check_jpeg_length(&self, len: usize) -> Result<()> {
        let blocks = u64::from(self.width.div_ceil(8)) * u64::from(self.height.div_ceil(8));
        if (len as u64).saturating_mul(8) < blocks {
            return Err(malformed(&format!(
                "the JPEG claims {}x{} pixels ({blocks} blocks of 8x8) but has only {len} \
                 bytes, fewer than one bit per block",
                self.width, self.height
            )));
        }
        Ok(())
    }

    /// The most bytes decoding this image to `fit` allocates at once, from
    /// the header alone: the image decoded whole when it must be, else a
    /// few rows; the reduced image, the resize's buffers and the result;
    /// the decoders' own tables.
    pub fn peak_bytes(&self, fit: (u32, u32)) -> u64 {
        let (w, h) = (u64::from(self.width), u64::from(self.height));
        let c = u64::from(self.components);
        let source = match (self.format, self.whole) {
            // Rows of up to 16-bit samples, the previous row, the output row.
            (Format::Png, false) => 6 * w * c * 2,
            (Format::Png, true) => w * h * c + 6 * w * c * 2,
            // The RGB output, and the MCU rows of every component.
            (Format::Jpeg, false) => w * h * 3 + c * (w + 64) * 64 * 2,
            // The RGB output, and every component's coefficients, as i16.
            (Format::Jpeg, true) => w * h * 3 + c * (w + 64) * (h + 64) * 2,
        };
        // The copy of a JPEG decoded a second time.
        let copy = if self.format == Format::Jpeg {
            self.len + 64
        } else {
            0
        };
        let f = u64::from(box_factor(self.width, self.height, fit));
        let (rw, rh) = (w.div_ceil(f), h.div_ceil(f));
        // The reduced image and its row of sums; the resize's f32 image
        // between its two passes; the result as RGB, as pixels, turned.
        let reduced = rw * rh * 3 + rw * 3 * 4;
        let (fw, fh) = (u64::from(fit.0), u64::from(fit.1));
        let resize = rw.max(fw) * rh.max(fh) * 3 * 4;
        let result = fw * fh * 3 * 3;
        source + copy + reduced + resize + result + DECODER_BYTES
    }
}

/// The whole factor of the box reduction for an image of `w`×`h` to be
/// fitted into `fit`: the largest that leaves it at least `fit`.
fn box_factor(w: u32, h: u32, fit: (u32, u32)) -> u32 {
    (w / fit.0.max(1)).min(h / fit.1.max(1)).max(1)
}

fn malformed(what: &str) -> Error {
    Error::MalformedImage(what.to_string())
}

fn png_error(e: png::DecodingError) -> Error {
    match e {
        png::DecodingError::IoError(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
            malformed("the PNG ends before its last row")
        }
        e => Error::MalformedImage(format!("PNG: {e}")),
    }
}

fn jpeg_error(e: zune_jpeg::errors::DecodeErrors) -> Error {
    Error::MalformedImage(format!("JPEG: {e}"))
}

/// Allocations the PNG decoder may make for itself (ancillary chunks, its
/// row buffers); the image buffer of an interlaced one is ours.
const PNG_DECODER_LIMIT: usize = 16 << 20;

fn png_reader(bytes: &[u8]) -> Result<png::Reader<Cursor<&[u8]>>> {
    let mut d = png::Decoder::new_with_limits(
        Cursor::new(bytes),
        png::Limits {
            bytes: PNG_DECODER_LIMIT,
        },
    );
    // 8-bit grey, grey and alpha, RGB or RGBA, whatever was stored.
    d.set_transformations(png::Transformations::normalize_to_color8());
    d.read_info().map_err(png_error)
}

fn jpeg_decoder(bytes: &[u8]) -> zune_jpeg::JpegDecoder<zune_core::bytestream::ZCursor<&[u8]>> {
    let options = zune_core::options::DecoderOptions::default()
        // An error for data that ends early or markers out of place,
        // instead of rows padded with grey.
        .set_strict_mode(true)
        .set_max_width(usize::from(u16::MAX))
        .set_max_height(usize::from(u16::MAX))
        .jpeg_set_out_colorspace(zune_core::colorspace::ColorSpace::RGB);
    zune_jpeg::JpegDecoder::new_with_options(zune_core::bytestream::ZCursor::new(bytes), options)
}

/// An image decoded to RGB8, reduced to fit, oriented.
pub(crate) struct Decoded {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
}

/// Decodes an image whose header is `header` to RGB8 of at most `fit`
/// (width, height as stored; `None`: as large as it is), then applies its
/// EXIF orientation.
pub(crate) fn decode(bytes: &[u8], header: &Header, fit: Option<(u32, u32)>) -> Result<Decoded> {
    let (w, h) = (header.width, header.height);
    let f = fit.map_or(1, |fit| box_factor(w, h, fit));
    let mut reducer = BoxReducer::new(w, h, f);
    let orientation = match header.format {
        Format::Png => decode_png(bytes, &mut reducer)?,
        Format::Jpeg => decode_jpeg(bytes, &mut reducer)?,
    };
    let reduced = reducer.finish()?;
    let fitted = match fit {
        Some((fw, fh)) if (reduced.width(), reduced.height()) != (fw, fh) => {
            image::imageops::resize(&reduced, fw, fh, image::imageops::FilterType::Lanczos3)
        }
        _ => reduced,
    };
    let mut img = image::DynamicImage::ImageRgb8(fitted);
    if let Some(o) = orientation {
        img.apply_orientation(o);
    }
    let img = img.into_rgb8();
    Ok(Decoded {
        width: img.width(),
        height: img.height(),
        rgb: img.into_raw(),
    })
}

/// Feeds a PNG's rows to `reducer`; returns its orientation, if it has one.
fn decode_png(bytes: &[u8], reducer: &mut BoxReducer) -> Result<Option<Orientation>> {
    let mut reader = png_reader(bytes)?;
    let samples = reader.output_color_type().0.samples();
    if reader.info().interlaced {
        let size = reader
            .output_buffer_size()
            .ok_or_else(|| malformed("PNG too large"))?;
        let mut frame = vec![0; size];
        let out = reader.next_frame(&mut frame).map_err(png_error)?;
        for row in frame[..out.buffer_size()].chunks_exact(out.line_size) {
            reducer.push_row(row, samples);
        }
    } else {
        while let Some(row) = reader.next_row().map_err(png_error)? {
            reducer.push_row(row.data(), samples);
        }
    }
    // The chunks after the image must check too (an eXIf may be there).
    reader.finish().map_err(png_error)?;
    Ok(reader
        .info()
        .exif_metadata
        .as_deref()
        .and_then(Orientation::from_exif_chunk))
}

/// Feeds a JPEG's rows to `reducer`; returns its orientation, if it has
/// one.
fn decode_jpeg(bytes: &[u8], reducer: &mut BoxReducer) -> Result<Option<Orientation>> {
    let mut d = jpeg_decoder(bytes);
    let rgb = d.decode().map_err(jpeg_error)?;
    let width = reducer.width as usize;
    if rgb.len() != width * reducer.height as usize * 3 {
        return Err(malformed("JPEG: decoded size differs from its header"));
    }
    let digest = crate::hash::fingerprint(&rgb);
    for row in rgb.chunks_exact(width * 3) {
        reducer.push_row(row, 3);
    }
    drop(rgb);
    let orientation = d.exif().and_then(|e| Orientation::from_exif_chunk(e));
    drop(d);
    // The same file with bits of one before its end marker: where the scan
    // held every row, they are never read and nothing changes.
    if let Some(end) = jpeg_end(bytes) {
        let mut ones = Vec::with_capacity(bytes.len() + ONES.len());
        ones.extend_from_slice(&bytes[..end]);
        ones.extend_from_slice(&ONES);
        ones.extend_from_slice(&bytes[end..]);
        let again = jpeg_decoder(&ones).decode();
        if again.map(|rgb| crate::hash::fingerprint(&rgb)).ok() != Some(digest) {
            return Err(malformed("the JPEG's data ends before its last row"));
        }
    }
    Ok(orientation)
}

/// Bytes of all-one bits in entropy-coded data (0xFF is followed by a
/// stuffed zero byte there).
const ONES: [u8; 32] = [
    0xff, 0x00, 0xff, 0x00, 0xff, 0x00, 0xff, 0x00, 0xff, 0x00, 0xff, 0x00, 0xff, 0x00, 0xff, 0x00,
    0xff, 0x00, 0xff, 0x00, 0xff, 0x00, 0xff, 0x00, 0xff, 0x00, 0xff, 0x00, 0xff, 0x00, 0xff, 0x00,
];

/// The offset of the end marker (EOI) of a JPEG's image: its marker
/// segments are walked from the start (so that a thumbnail inside an APP
/// segment is passed over) and its scans searched for the next marker.
/// `None` for a file that ends first.
fn jpeg_end(bytes: &[u8]) -> Option<usize> {
    let mut i = 2;
    let mut in_scan = false;
    while i + 1 < bytes.len() {
        if in_scan {
            let j = i + bytes[i..].iter().position(|&b| b == 0xff)?;
            match *bytes.get(j + 1)? {
                // A stuffed byte or a restart marker: still the scan.
                0x00 | 0xd0..=0xd7 => i = j + 2,
                0xff => i = j + 1,
                _ => {
                    in_scan = false;
                    i = j;
                }
            }
            continue;
        }
        if bytes[i] != 0xff {
            return None;
        }
        match bytes[i + 1] {
            0xd9 => return Some(i),
            // Fill bytes, and markers without a length.
            0xff => i += 1,
            0x01 | 0xd0..=0xd8 => i += 2,
            m => {
                let len = usize::from(u16::from_be_bytes([*bytes.get(i + 2)?, *bytes.get(i + 3)?]));
                if len < 2 {
                    return None;
                }
                i += 2 + len;
                in_scan = m == 0xda;
            }
        }
    }
    None
}

/// Averages boxes of f×f pixels as rows arrive (the last row and column
/// of boxes may be narrower), into an RGB8 image of ⌈w/f⌉×⌈h/f⌉.
struct BoxReducer {
    width: u32,
    height: u32,
    f: u32,
    rows: u32,
    sums: Vec<u32>,
    out: Vec<u8>,
}

impl BoxReducer {
    fn new(width: u32, height: u32, f: u32) -> BoxReducer {
        let (rw, rh) = (width.div_ceil(f) as usize, height.div_ceil(f) as usize);
        BoxReducer {
            width,
            height,
            f,
            rows: 0,
            sums: vec![0; rw * 3],
            out: Vec::with_capacity(rw * rh * 3),
        }
    }

    /// Adds a row of `samples` bytes per pixel: grey (1), grey and alpha
    /// (2), RGB (3) or RGBA (4); alpha is dropped.
    fn push_row(&mut self, row: &[u8], samples: usize) {
        if self.rows >= self.height {
            return;
        }
        let f = self.f as usize;
        for (x, px) in row
            .chunks_exact(samples)
            .take(self.width as usize)
            .enumerate()
        {
            let rgb = if samples < 3 {
                [px[0]; 3]
            } else {
                [px[0], px[1], px[2]]
            };
            let o = x / f * 3;
            for (s, v) in self.sums[o..o + 3].iter_mut().zip(rgb) {
                *s += u32::from(v);
            }
        }
        self.rows += 1;
        if self.rows.is_multiple_of(self.f) || self.rows == self.height {
            let band = self.rows - (self.rows - 1) / self.f * self.f;
            for (bx, sum) in self.sums.chunks_exact_mut(3).enumerate() {
                let across = (self.width - bx as u32 * self.f).min(self.f);
                let n = across * band;
                for s in sum.iter_mut() {
                    self.out.push(((*s + n / 2) / n) as u8);
                    *s = 0;
                }
            }
        }
    }

    /// The reduced image; an error when rows are missing.
    fn finish(self) -> Result<image::RgbImage> {
        if self.rows < self.height {
            return Err(malformed("the image ends before its last row"));
        }
        let (rw, rh) = (self.width.div_ceil(self.f), self.height.div_ceil(self.f));
        image::RgbImage::from_raw(rw, rh, self.out)
            .ok_or_else(|| malformed("decoded size differs from its header"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boxes_average_what_they_cover_and_a_factor_of_one_copies() {
        // 5×3 grey, f = 2: boxes of 2×2, 1×2, 2×1 and 1×1 at the edges.
        let rows: [[u8; 5]; 3] = [[0, 2, 4, 6, 8], [2, 4, 6, 8, 10], [10, 20, 30, 40, 50]];
        let mut r = BoxReducer::new(5, 3, 2);
        for row in &rows {
            r.push_row(row, 1);
        }
        let img = r.finish().unwrap();
        assert_eq!((img.width(), img.height()), (3, 2));
        let grey: Vec<u8> = img.pixels().map(|p| p.0[0]).collect();
        assert_eq!(grey, [2, 6, 9, 15, 35, 50]);
        let mut one = BoxReducer::new(2, 1, 1);
        one.push_row(&[1, 2, 3, 9, 4, 5, 6, 9], 4);
        assert_eq!(one.finish().unwrap().into_raw(), [1, 2, 3, 4, 5, 6]);
        // Rows missing: an error.
        let mut short = BoxReducer::new(2, 2, 1);
        short.push_row(&[0; 6], 3);
        assert!(short.finish().is_err());
    }

    #[test]
    fn the_end_of_a_jpeg_is_found_past_a_thumbnail_and_between_scans() {
        let rgb: Vec<u8> = (0..40 * 24 * 3).map(|i| (i * 7 % 251) as u8).collect();
        let mut jpeg = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 80)
            .encode(&rgb, 40, 24, image::ExtendedColorType::Rgb8)
            .unwrap();
        assert_eq!(jpeg_end(&jpeg), Some(jpeg.len() - 2));
        // An APP1 holding what looks like a whole JPEG, as an EXIF
        // thumbnail does; and bytes after the end marker.
        let fake = [0xff, 0xd8, 0xff, 0xda, 0, 2, 1, 0xff, 0xd9];
        let mut app1 = vec![0xff, 0xe1, 0, (fake.len() + 2) as u8];
        app1.extend_from_slice(&fake);
        let mut with = jpeg[..2].to_vec();
        with.extend_from_slice(&app1);
        with.extend_from_slice(&jpeg[2..]);
        with.extend_from_slice(b"trailing");
        assert_eq!(jpeg_end(&with), Some(jpeg.len() - 2 + app1.len()));
        let header = Header::read(&with).unwrap();
        let a = decode(&with, &header, None).unwrap();
        let b = decode(&jpeg, &Header::read(&jpeg).unwrap(), None).unwrap();
        assert_eq!(a.rgb, b.rgb);
        // Cut anywhere: no end.
        assert_eq!(jpeg_end(&jpeg[..jpeg.len() - 1]), None);
    }

    #[test]
    fn the_factor_keeps_the_reduced_image_at_least_as_large_as_the_fit() {
        for (w, h, fit) in [
            (6000, 6000, (512, 512)),
            (6000, 4000, (512, 341)),
            (1023, 40, (512, 20)),
            (600, 600, (512, 512)),
        ] {
            let f = box_factor(w, h, fit);
            assert!(w / f >= fit.0 && h / f >= fit.1, "{w}x{h}");
            assert!(w / (f + 1) < fit.0 || h / (f + 1) < fit.1, "{w}x{h}");
        }
    }
}
