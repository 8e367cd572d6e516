//! NRRD volumes (the "Nearly Raw Raster Data" format of Teem, read by 3D
//! Slicer, ParaView, ImageJ/Fiji and pynrrd): a text header, a blank line,
//! then the raw voxels.

use crate::request::Region;

/// The NRRD of RGB8 voxels `rgb` (x fastest, then y, then z) of `region`
/// at `lod`: axes RGB, x, y, z, spaced 2^lod finest voxels apart, the
/// first voxel's centre at its place in finest voxels.
pub(super) fn encode(region: &Region, lod: u32, rgb: &[u8]) -> Vec<u8> {
    let [w, h, d] = region.size;
    let s = 1u64 << lod;
    // Where a voxel of `lod` sits in finest voxels (its cube's centre).
    let origin = region.origin.map(|o| (o as f64 + 0.5) * s as f64 - 0.5);
    let header = format!(
        "NRRD0004\n\
         # solidtex export, level of detail {lod}; coordinates in finest voxels\n\
         type: uint8\n\
         dimension: 4\n\
         space dimension: 3\n\
         sizes: 3 {w} {h} {d}\n\
         kinds: RGB-color domain domain domain\n\
         labels: \"rgb\" \"x\" \"y\" \"z\"\n\
         space directions: none ({s},0,0) (0,{s},0) (0,0,{s})\n\
         space origin: ({},{},{})\n\
         encoding: raw\n\
         \n",
        origin[0], origin[1], origin[2]
    );
    let mut out = Vec::with_capacity(header.len() + rgb.len());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(rgb);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_then_voxels() {
        let r = Region {
            origin: [-2, 0, 5],
            size: [2, 1, 1],
        };
        let b = encode(&r, 1, &[1, 2, 3, 4, 5, 6]);
        let text = String::from_utf8_lossy(&b);
        let (head, data) = text.split_once("\n\n").unwrap();
        assert!(head.starts_with("NRRD0004\n"));
        assert!(head.contains("sizes: 3 2 1 1\n"));
        assert!(head.contains("space directions: none (2,0,0) (0,2,0) (0,0,2)\n"));
        assert!(head.contains("space origin: (-3.5,0.5,10.5)"), "{head}");
        assert_eq!(data.as_bytes(), &[1, 2, 3, 4, 5, 6]);
    }
}
