//! What one request cost, as the engine counts it.

/// What one request cost: voxels synthesized and corrected per pyramid level
/// (index 0 is the finest level) and tiles computed or found in the cache.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SynthStats {
    /// Voxels whose triple was produced (upsampled or initialised), per level.
    pub voxels_per_level: Vec<u64>,
    /// Voxel corrections performed, per level.
    pub corrections_per_level: Vec<u64>,
    /// Tiles synthesized by this request.
    pub tiles_computed: u64,
    /// Tiles served from the cache (or computed by a concurrent request),
    /// counting those of which the cache held some of the voxels needed.
    pub tiles_from_cache: u64,
}

impl SynthStats {
    /// Adds another request's counts to these.
    pub fn merge(&mut self, other: &SynthStats) {
        for (dst, src) in [
            (&mut self.voxels_per_level, &other.voxels_per_level),
            (
                &mut self.corrections_per_level,
                &other.corrections_per_level,
            ),
        ] {
            if dst.len() < src.len() {
                dst.resize(src.len(), 0);
            }
            for (d, s) in dst.iter_mut().zip(src) {
                *d += s;
            }
        }
        self.tiles_computed += other.tiles_computed;
        self.tiles_from_cache += other.tiles_from_cache;
    }
}
