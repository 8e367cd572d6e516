//! PNG encoding of synthesized images and stored exemplars.

use image::ImageEncoder;
use image::codecs::png::{CompressionType, FilterType, PngEncoder};

/// Encodes packed RGB8 rows as a PNG.
pub fn encode(width: u32, height: u32, rgb: &[u8]) -> Result<Vec<u8>, image::ImageError> {
    let mut out = Vec::with_capacity(rgb.len() / 2 + 64);
    PngEncoder::new_with_quality(&mut out, CompressionType::Fast, FilterType::Adaptive)
        .write_image(rgb, width, height, image::ExtendedColorType::Rgb8)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    #[test]
    fn round_trip() {
        let rgb: Vec<u8> = (0..20 * 17 * 3).map(|i| (i * 13) as u8).collect();
        let png = super::encode(20, 17, &rgb).unwrap();
        let img = image::load_from_memory(&png).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (20, 17));
        assert_eq!(img.as_raw(), &rgb);
    }
}
