//! Tile cache (API placeholder while the engine lands).

/// Cache counters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CacheStats {
    /// Lookups that found a tile.
    pub hits: u64,
    /// Lookups that had to compute a tile.
    pub misses: u64,
    /// Lookups that waited for a concurrent computation of the same tile.
    pub coalesced: u64,
    /// Bytes held.
    pub bytes: u64,
    /// Tiles held.
    pub entries: u64,
    /// Tiles evicted to respect the byte bound.
    pub evictions: u64,
}

/// Byte-bounded tile cache shared by textures and threads.
pub struct TileCache {
    max_bytes: usize,
}

impl TileCache {
    /// A cache holding at most `max_bytes` of tiles.
    pub fn new(max_bytes: usize) -> Self {
        TileCache { max_bytes }
    }
    /// The byte bound.
    pub fn max_bytes(&self) -> usize {
        self.max_bytes
    }
    /// Current counters.
    pub fn stats(&self) -> CacheStats {
        CacheStats::default()
    }
}
