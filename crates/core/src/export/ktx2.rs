//! KTX 2.0 containers of uncompressed RGBA8 3D textures (Khronos KTX 2.0
//! specification; the data format descriptor of the Khronos Data Format
//! specification 1.3, basic descriptor block).
//!
//! Layout: identifier, header, index, level index (level 0 first), the
//! data format descriptor, key/value data, then the levels' bytes from the
//! smallest level to level 0, each at a multiple of 4 bytes (the texel
//! size). No supercompression.

/// `«KTX 20»\r\n\x1A\n`.
const IDENTIFIER: [u8; 12] = [
    0xAB, 0x4B, 0x54, 0x58, 0x20, 0x32, 0x30, 0xBB, 0x0D, 0x0A, 0x1A, 0x0A,
];

/// `VK_FORMAT_R8G8B8A8_UNORM`.
pub const VK_FORMAT_R8G8B8A8_UNORM: u32 = 37;
/// `VK_FORMAT_R8G8B8A8_SRGB`.
pub const VK_FORMAT_R8G8B8A8_SRGB: u32 = 43;

/// One mip level: its extent and RGBA8 texels, x fastest, then y, then z.
pub struct Level {
    /// Width, height and depth in texels.
    pub size: [u32; 3],
    /// `4 · width · height · depth` bytes.
    pub rgba: Vec<u8>,
}

/// A 3D texture of `levels` (level 0 first, each half the previous one,
/// rounded down, at least 1), RGBA8 in sRGB or linear encoding, with the
/// key/value pairs `extra` beside the writer's and the orientation.
pub fn encode(levels: &[Level], srgb: bool, extra: &[(&str, String)]) -> Vec<u8> {
    let [w, h, d] = levels[0].size;
    let vk_format = if srgb {
        VK_FORMAT_R8G8B8A8_SRGB
    } else {
        VK_FORMAT_R8G8B8A8_UNORM
    };
    let dfd = data_format_descriptor(srgb);
    let mut pairs: Vec<(&str, String)> = vec![
        ("KTXorientation", "rdi".to_string()),
        (
            "KTXwriter",
            format!("solidtex {}", env!("CARGO_PKG_VERSION")),
        ),
    ];
    pairs.extend(extra.iter().cloned());
    // The specification orders the pairs by key, byte by byte.
    pairs.sort_by(|a, b| a.0.as_bytes().cmp(b.0.as_bytes()));
    let kvd = key_values(&pairs);

    let n = levels.len();
    let index_end = 12 + 9 * 4 + 4 * 4 + 2 * 8;
    let dfd_offset = index_end + n * 24;
    let kvd_offset = dfd_offset + dfd.len();
    let mut data_offset = align4(kvd_offset + kvd.len());
    // Levels are stored smallest first.
    let mut offsets = vec![0usize; n];
    for i in (0..n).rev() {
        offsets[i] = data_offset;
        data_offset = align4(data_offset + levels[i].rgba.len());
    }

    let mut out = Vec::with_capacity(data_offset);
    out.extend_from_slice(&IDENTIFIER);
    for v in [vk_format, 1, w, h, d, 0, 1, n as u32, 0] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for v in [
        dfd_offset as u32,
        dfd.len() as u32,
        kvd_offset as u32,
        kvd.len() as u32,
    ] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&0u64.to_le_bytes());
    out.extend_from_slice(&0u64.to_le_bytes());
    for (level, &offset) in levels.iter().zip(&offsets) {
        let len = level.rgba.len() as u64;
        for v in [offset as u64, len, len] {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out.extend_from_slice(&dfd);
    out.extend_from_slice(&kvd);
    for i in (0..n).rev() {
        out.resize(offsets[i], 0);
        out.extend_from_slice(&levels[i].rgba);
    }
    out
}

fn align4(n: usize) -> usize {
    n.div_ceil(4) * 4
}

/// The descriptor of RGBA8: one basic block, model RGBSDA, BT.709
/// primaries, sRGB or linear transfer, one byte per channel.
fn data_format_descriptor(srgb: bool) -> Vec<u8> {
    const SAMPLES: u32 = 4;
    let block_size = 24 + 16 * SAMPLES;
    let mut out = Vec::with_capacity(4 + block_size as usize);
    out.extend_from_slice(&(4 + block_size).to_le_bytes());
    // Vendor Khronos (0), descriptor type basic (0).
    out.extend_from_slice(&0u32.to_le_bytes());
    // Version 2 (Data Format 1.3), then the block's size.
    out.extend_from_slice(&(2 | block_size << 16).to_le_bytes());
    const MODEL_RGBSDA: u8 = 1;
    const PRIMARIES_BT709: u8 = 1;
    let transfer: u8 = if srgb { 2 } else { 1 };
    out.extend_from_slice(&[MODEL_RGBSDA, PRIMARIES_BT709, transfer, 0]);
    // Texel block 1×1×1×1 (each dimension stored minus one).
    out.extend_from_slice(&[0, 0, 0, 0]);
    // Bytes per plane: 4 in plane 0.
    out.extend_from_slice(&[4, 0, 0, 0, 0, 0, 0, 0]);
    // R, G, B and A, 8 bits each; alpha is linear even in sRGB.
    const LINEAR: u8 = 0x80;
    for (i, channel) in [0u8, 1, 2, 15].into_iter().enumerate() {
        let qualifiers = if channel == 15 && srgb { LINEAR } else { 0 };
        let bit_offset = (8 * i) as u32;
        let bit_length_minus_one = 7u32;
        let word = bit_offset | bit_length_minus_one << 16 | u32::from(channel | qualifiers) << 24;
        out.extend_from_slice(&word.to_le_bytes());
        // Sample position 0, 0, 0, 0; lower and upper bounds 0 and 255.
        out.extend_from_slice(&0u32.to_le_bytes());
        out.extend_from_slice(&0u32.to_le_bytes());
        out.extend_from_slice(&255u32.to_le_bytes());
    }
    out
}

/// Key/value data: each pair's length, the key, a NUL, the value and its
/// NUL, padded to 4 bytes.
fn key_values(pairs: &[(&str, String)]) -> Vec<u8> {
    let mut out = Vec::new();
    for (k, v) in pairs {
        let len = k.len() + 1 + v.len() + 1;
        out.extend_from_slice(&(len as u32).to_le_bytes());
        out.extend_from_slice(k.as_bytes());
        out.push(0);
        out.extend_from_slice(v.as_bytes());
        out.push(0);
        out.resize(align4(out.len()), 0);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn u32_at(b: &[u8], at: usize) -> u32 {
        u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
    }

    fn u64_at(b: &[u8], at: usize) -> u64 {
        u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
    }

    /// The fields a reader needs are where the specification puts them,
    /// and each level's bytes are found through the level index.
    #[test]
    fn a_container_reads_back_through_its_index() {
        let level = |s: [u32; 3], v: u8| Level {
            size: s,
            rgba: vec![v; (4 * s[0] * s[1] * s[2]) as usize],
        };
        let levels = [
            level([4, 2, 3], 7),
            level([2, 1, 1], 8),
            level([1, 1, 1], 9),
        ];
        let b = encode(&levels, true, &[("solidtex", "{}".into())]);
        assert_eq!(&b[..12], &IDENTIFIER);
        assert_eq!(u32_at(&b, 12), VK_FORMAT_R8G8B8A8_SRGB);
        assert_eq!(
            [16, 20, 24, 28, 32, 36].map(|a| u32_at(&b, a)),
            [1, 4, 2, 3, 0, 1],
            "type size, width, height, depth, layers, faces"
        );
        assert_eq!(u32_at(&b, 40), 3, "levels");
        let (dfd_at, dfd_len) = (u32_at(&b, 48) as usize, u32_at(&b, 52) as usize);
        assert_eq!(u32_at(&b, dfd_at) as usize, dfd_len);
        assert_eq!(b[dfd_at + 12 + 2], 2, "sRGB transfer");
        let (kvd_at, kvd_len) = (u32_at(&b, 56) as usize, u32_at(&b, 60) as usize);
        let kvd = String::from_utf8_lossy(&b[kvd_at..kvd_at + kvd_len]);
        let order = ["KTXorientation", "KTXwriter", "solidtex"].map(|k| kvd.find(k).unwrap());
        assert!(order.is_sorted(), "{kvd:?}");
        let mut last_end = 0;
        for (i, l) in levels.iter().enumerate().rev() {
            let at = 80 + 24 * i;
            let (offset, len) = (u64_at(&b, at) as usize, u64_at(&b, at + 8) as usize);
            assert_eq!(offset % 4, 0);
            assert!(offset >= last_end, "smallest level first");
            assert_eq!(&b[offset..offset + len], &l.rgba[..]);
            last_end = offset + len;
        }
        assert_eq!(last_end, b.len());
    }
}
