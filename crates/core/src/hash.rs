//! Position hashing: the only source of randomness. Every random choice is
//! a pure function of (seed, level, position, purpose), so any voxel can be
//! recomputed anywhere, in any order, on any thread.

/// SplitMix64 finaliser: a well-mixed 64-bit permutation.
#[inline]
pub fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Hash of a seed and three integers.
#[inline]
pub(crate) fn hash3(seed: u64, a: u64, b: u64, c: u64) -> u64 {
    mix(mix(mix(mix(seed) ^ a) ^ b) ^ c)
}

/// Hash of a seed, a level, a purpose tag and a 3D integer position.
#[inline]
pub(crate) fn hash_pos(seed: u64, level: u32, tag: u32, p: [i64; 3]) -> u64 {
    let lt = ((level as u64) << 32) | tag as u64;
    mix(hash3(
        seed ^ lt.rotate_left(17),
        p[0] as u64,
        p[1] as u64,
        p[2] as u64,
    ) ^ lt)
}

/// A hash mapped to [0, 1).
#[inline]
pub(crate) fn unit(h: u64) -> f32 {
    (h >> 40) as f32 / (1u64 << 24) as f32
}

/// A 64-bit fingerprint of a byte string (keys, not security).
pub(crate) fn fingerprint(bytes: &[u8]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for chunk in bytes.chunks(8) {
        let mut b = [0u8; 8];
        b[..chunk.len()].copy_from_slice(chunk);
        h = mix(h ^ u64::from_le_bytes(b));
    }
    mix(h ^ bytes.len() as u64)
}
