//! The tile cache: synthesized cells of every level and correction step,
//! kept in an LRU bounded in bytes and shared by all textures and threads.
//! A tile may hold only some of its voxels (those a request depended on),
//! marked in a 64-bit mask; later requests add to it. A tile is claimed
//! before it is computed, so concurrent requests for the same missing
//! voxels compute them once: the others wait. A voxel's value never depends
//! on cache state, so evicting, recomputing and merging are harmless.

use super::TILE;
use super::grid::Grid;
use lru::LruCache;
use parking_lot::{Condvar, Mutex, MutexGuard};
use rustc_hash::FxHashMap as HashMap;
use std::sync::Arc;

/// Identifies a tile: texture, level, version and cell position.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TileKey {
    /// Hash of the texture's candidates and synthesis parameters.
    pub texture: u64,
    /// Pyramid level (0 = finest).
    pub level: u8,
    /// Version the tile holds: 0 for the final one, s ≥ 1 for the
    /// version after the level's first s correction passes.
    pub version: u8,
    /// Cell coordinates.
    pub cell: [i64; 3],
}

/// The voxels of one cell that are known, and their triples. Only known
/// voxels are stored: intermediate versions are often sparse.
#[derive(Clone, Debug)]
pub struct TileData {
    /// Lowest corner of the cell.
    origin: [i64; 3],
    /// Bit i set: voxel i of the cell (x fastest) is known.
    pub mask: u64,
    /// Triples of the known voxels, in bit order, packed (see [`pack`]).
    triples: Vec<u64>,
}

/// Bits per packed coordinate: exemplars have at most 512² = 2¹⁸ pixels.
const COORD_BITS: u32 = 21;
const COORD_MASK: u64 = (1 << COORD_BITS) - 1;
const _: () = assert!(
    (crate::analysis::exemplar::MAX_SIDE as u64).pow(2) <= COORD_MASK + 1,
    "a pixel index must fit a packed coordinate"
);

/// A triple in one word: 8 bytes per cached voxel instead of 12, so the
/// same cache budget holds half as many voxels again.
#[inline]
fn pack(t: [u32; 3]) -> u64 {
    debug_assert!(t.iter().all(|&c| (c as u64) <= COORD_MASK), "{t:?}");
    t[0] as u64 | (t[1] as u64) << COORD_BITS | (t[2] as u64) << (2 * COORD_BITS)
}

#[inline]
fn unpack(w: u64) -> [u32; 3] {
    [0, 1, 2].map(|i| (w >> (i * COORD_BITS) & COORD_MASK) as u32)
}

/// Position in the cell at `origin` of bit `i`.
#[inline]
fn voxel_of_bit(origin: [i64; 3], i: u32) -> [i64; 3] {
    let i = i as i64;
    [
        origin[0] + i % TILE,
        origin[1] + (i / TILE) % TILE,
        origin[2] + i / (TILE * TILE),
    ]
}

/// Set bits of `mask`, lowest first.
fn bits(mut mask: u64) -> impl Iterator<Item = u32> {
    std::iter::from_fn(move || {
        (mask != 0).then(|| {
            let i = mask.trailing_zeros();
            mask &= mask - 1;
            i
        })
    })
}

/// The triples for the set bits of `mask`, allocated exactly (the cache
/// budget counts capacity).
fn triples_for(mask: u64, f: impl FnMut(u32) -> u64) -> Vec<u64> {
    let mut out = Vec::with_capacity(mask.count_ones() as usize);
    out.extend(bits(mask).map(f));
    out
}

impl TileData {
    /// The voxels of `mask` in the cell at `origin`, read from `src` (which
    /// must hold them).
    pub fn from_grid(src: &Grid<[u32; 3]>, origin: [i64; 3], mask: u64) -> TileData {
        TileData {
            origin,
            mask,
            triples: triples_for(mask, |i| {
                let p = voxel_of_bit(origin, i);
                debug_assert!(src.bounds.contains(p), "voxel {p:?} outside the source");
                pack(src.get(p))
            }),
        }
    }

    /// Whether every voxel of `want` is known.
    #[inline]
    pub fn covers(&self, want: u64) -> bool {
        self.mask & want == want
    }

    /// Lowest corner of the cell the voxels are placed in.
    pub fn origin(&self) -> [i64; 3] {
        self.origin
    }

    /// The same voxels placed in the cell at `origin` (a copy of the cell
    /// one or more periods away, in a periodic solid).
    pub fn moved_to(&self, origin: [i64; 3]) -> TileData {
        TileData {
            origin,
            ..self.clone()
        }
    }

    /// The triple of known voxel `p`, of this cell or of a copy of it one
    /// or more periods away (by its place in the cell).
    #[inline]
    pub fn get(&self, p: [i64; 3]) -> [u32; 3] {
        let l = p.map(|v| v.rem_euclid(TILE));
        let i = l[0] + TILE * (l[1] + TILE * l[2]);
        debug_assert!(self.mask >> i & 1 == 1, "voxel {p:?} is not known");
        let below = self.mask & ((1u64 << i) - 1);
        unpack(self.triples[below.count_ones() as usize])
    }

    /// Writes the known voxels that lie inside `g` into it.
    pub fn copy_into(&self, g: &mut Grid<[u32; 3]>) {
        for (i, &t) in bits(self.mask).zip(&self.triples) {
            let p = voxel_of_bit(self.origin, i);
            if g.bounds.contains(p) {
                let j = g.index(p);
                g.data[j] = unpack(t);
            }
        }
    }

    /// The union of two partial tiles of the same cell.
    pub fn merged(&self, other: &TileData) -> TileData {
        let mask = self.mask | other.mask;
        let (mut a, mut b) = (self.triples.iter(), other.triples.iter());
        let triples = triples_for(mask, |i| {
            let mine = self.mask >> i & 1 == 1;
            let theirs = other.mask >> i & 1 == 1;
            let t = if theirs {
                *b.next().expect("bit")
            } else {
                *a.next().expect("bit")
            };
            if mine && theirs {
                a.next();
            }
            t
        });
        TileData {
            origin: self.origin,
            mask,
            triples,
        }
    }

    /// Bytes held, for the cache's budget.
    fn bytes(&self) -> usize {
        self.triples.capacity() * std::mem::size_of::<u64>() + 136
    }
}

/// A synthesized tile, shared.
pub type Tile = Arc<TileData>;

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

#[derive(Default)]
struct Flight {
    done: Mutex<Option<Option<Tile>>>,
    cv: Condvar,
}

struct Inner {
    lru: LruCache<TileKey, Tile>,
    flights: HashMap<TileKey, Arc<Flight>>,
    stats: CacheStats,
}

/// Byte-bounded tile cache shared by textures and threads.
pub struct TileCache {
    max_bytes: usize,
    inner: Mutex<Inner>,
}

/// The outcome of claiming a tile.
pub enum Claim {
    /// Already cached.
    Ready(Tile),
    /// Missing: the caller computes it and must [`TileCache::publish`] or
    /// drop the ticket.
    Mine(Ticket),
    /// Being computed by another request: [`TileCache::wait`] for it.
    Wait(Waiter),
}

/// The right and duty to compute one tile. Dropping it unpublished (on an
/// error or panic) releases anyone waiting, who then compute it themselves.
pub struct Ticket {
    key: TileKey,
    partial: Option<Tile>,
    flight: Arc<Flight>,
    cache: Arc<TileCache>,
    published: bool,
}

impl Ticket {
    /// The tile to compute.
    pub fn key(&self) -> TileKey {
        self.key
    }

    /// What the cache already knows of the tile: only the voxels it lacks
    /// need computing.
    pub fn partial(&self) -> Option<&Tile> {
        self.partial.as_ref()
    }
}

/// A handle on a tile another request is computing.
pub struct Waiter {
    key: TileKey,
    flight: Arc<Flight>,
}

impl Waiter {
    /// The awaited tile.
    pub fn key(&self) -> TileKey {
        self.key
    }
}

fn tile_bytes(t: &Tile) -> usize {
    t.bytes()
}

impl TileCache {
    /// A cache holding at most `max_bytes` of tiles.
    pub fn new(max_bytes: usize) -> Self {
        TileCache {
            max_bytes,
            inner: Mutex::new(Inner {
                lru: LruCache::unbounded(),
                flights: HashMap::default(),
                stats: CacheStats::default(),
            }),
        }
    }

    /// The byte bound.
    pub fn max_bytes(&self) -> usize {
        self.max_bytes
    }

    /// Current counters.
    pub fn stats(&self) -> CacheStats {
        self.lock().stats
    }

    fn lock(&self) -> MutexGuard<'_, Inner> {
        self.inner.lock()
    }

    /// Looks up the voxels `want` of a tile, claiming the tile if it lacks
    /// some of them and nobody is computing it.
    pub fn claim(self: &Arc<Self>, key: TileKey, want: u64) -> Claim {
        let mut g = self.lock();
        self.claim_locked(&mut g, key, want)
    }

    /// [`TileCache::claim`] for many tiles at once, atomically: two
    /// requests for the same tiles arriving together do not split them
    /// (each computing part, and both the shared chains below), the first
    /// claims every missing tile and the second waits for all of them.
    pub fn claim_all(self: &Arc<Self>, wants: &[(TileKey, u64)]) -> Vec<Claim> {
        let mut g = self.lock();
        wants
            .iter()
            .map(|&(key, want)| self.claim_locked(&mut g, key, want))
            .collect()
    }

    fn claim_locked(self: &Arc<Self>, g: &mut Inner, key: TileKey, want: u64) -> Claim {
        let partial = match g.lru.get(&key) {
            Some(t) if t.covers(want) => {
                let t = t.clone();
                g.stats.hits += 1;
                return Claim::Ready(t);
            }
            other => other.cloned(),
        };
        if let Some(f) = g.flights.get(&key) {
            let flight = f.clone();
            g.stats.coalesced += 1;
            return Claim::Wait(Waiter { key, flight });
        }
        g.stats.misses += 1;
        let flight = Arc::new(Flight::default());
        g.flights.insert(key, flight.clone());
        Claim::Mine(Ticket {
            key,
            partial,
            flight,
            cache: self.clone(),
            published: false,
        })
    }

    /// Stores a computed tile (merged with what the cache already knows
    /// of it) and wakes its waiters with the merged tile.
    pub fn publish(&self, mut ticket: Ticket, tile: Tile) {
        ticket.published = true;
        let tile = {
            let mut g = self.lock();
            g.flights.remove(&ticket.key);
            self.store(&mut g, ticket.key, tile)
        };
        let mut done = ticket.flight.done.lock();
        *done = Some(Some(tile));
        ticket.flight.cv.notify_all();
    }

    /// Merges `tile` into what is cached under `key` and stores it,
    /// evicting least recently used tiles beyond the byte limit.
    fn store(&self, g: &mut Inner, key: TileKey, tile: Tile) -> Tile {
        let tile = match g.lru.peek(&key) {
            Some(old) if !tile.covers(old.mask) => Arc::new(old.merged(&tile)),
            _ => tile,
        };
        let bytes = tile_bytes(&tile);
        if bytes <= self.max_bytes {
            if let Some(old) = g.lru.put(key, tile.clone()) {
                g.stats.bytes -= tile_bytes(&old) as u64;
            }
            g.stats.bytes += bytes as u64;
            while g.stats.bytes > self.max_bytes as u64 {
                match g.lru.pop_lru() {
                    Some((_, old)) => {
                        g.stats.bytes -= tile_bytes(&old) as u64;
                        g.stats.evictions += 1;
                    }
                    None => break,
                }
            }
        }
        g.stats.entries = g.lru.len() as u64;
        tile
    }

    /// The tile cached under `key`, whatever voxels it holds, without
    /// claiming it: for intermediate versions, which a request computes
    /// itself when they are missing rather than waiting for another.
    pub fn peek(&self, key: &TileKey) -> Option<Tile> {
        self.lock().lru.get(key).cloned()
    }

    /// Merges an intermediate-version tile into the cache (see
    /// [`TileCache::peek`]).
    pub fn merge(&self, key: TileKey, tile: Tile) {
        let mut g = self.lock();
        self.store(&mut g, key, tile);
    }

    /// Blocks until the awaited tile is published; `None` if its computation
    /// failed (the caller then computes it itself).
    pub fn wait(&self, w: Waiter) -> Option<Tile> {
        let mut done = w.flight.done.lock();
        while done.is_none() {
            w.flight.cv.wait(&mut done);
        }
        done.clone().flatten()
    }

    /// Drops every tile (counters are kept).
    pub fn clear(&self) {
        let mut g = self.lock();
        g.lru.clear();
        g.stats.bytes = 0;
        g.stats.entries = 0;
    }
}

impl Drop for Ticket {
    fn drop(&mut self) {
        if self.published {
            return;
        }
        self.cache.lock().flights.remove(&self.key);
        let mut done = self.flight.done.lock();
        *done = Some(None);
        self.flight.cv.notify_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::grid::Box3;

    fn tile(mask: u64, value: u32) -> Tile {
        let mut grid = Grid::new(Box3::new([0; 3], [4; 3]));
        for (i, v) in grid.data.iter_mut().enumerate() {
            *v = [value, i as u32, 0];
        }
        Arc::new(TileData::from_grid(&grid, [0; 3], mask))
    }

    const KEY: TileKey = TileKey {
        texture: 1,
        level: 0,
        version: 0,
        cell: [0, 0, 0],
    };

    #[test]
    fn packed_triples_read_back_unchanged() {
        let largest = 512 * 512 - 1;
        for t in [
            [0, 0, 0],
            [1, 2, 3],
            [largest, 0, largest],
            [largest; 3],
            [7, largest, 65536],
        ] {
            assert_eq!(unpack(pack(t)), t);
        }
    }

    #[test]
    fn requests_arriving_together_do_not_split_their_tiles() {
        let keys: Vec<(TileKey, u64)> = (0..512)
            .map(|i| {
                let key = TileKey {
                    cell: [i, 0, 0],
                    ..KEY
                };
                (key, u64::MAX)
            })
            .collect();
        for _ in 0..20 {
            let cache = Arc::new(TileCache::new(1 << 20));
            let start = std::sync::Barrier::new(2);
            let mine: Vec<usize> = std::thread::scope(|s| {
                let claimers: Vec<_> = (0..2)
                    .map(|_| {
                        s.spawn(|| {
                            start.wait();
                            let claims = cache.claim_all(&keys);
                            let n = claims
                                .iter()
                                .filter(|c| matches!(c, Claim::Mine(_)))
                                .count();
                            // Tickets dropped unpublished release their tiles
                            // only after both have claimed.
                            start.wait();
                            n
                        })
                    })
                    .collect();
                claimers.into_iter().map(|c| c.join().unwrap()).collect()
            });
            let mut mine = mine;
            mine.sort();
            assert_eq!(mine, vec![0, keys.len()], "one request claims every tile");
        }
    }

    #[test]
    fn a_partial_tile_lends_its_voxels_and_grows() {
        let cache = Arc::new(TileCache::new(1 << 20));
        let Claim::Mine(ticket) = cache.claim(KEY, 0b0011) else {
            panic!("an empty cache hands out the claim");
        };
        assert!(ticket.partial().is_none());
        cache.publish(ticket, tile(0b0011, 7));
        // Voxels it holds: a hit.
        assert!(matches!(cache.claim(KEY, 0b0001), Claim::Ready(_)));
        // One more voxel: a claim that carries what is known.
        let Claim::Mine(ticket) = cache.claim(KEY, 0b0110) else {
            panic!("a missing voxel is claimed");
        };
        assert_eq!(ticket.partial().map(|t| t.mask), Some(0b0011));
        cache.publish(ticket, tile(0b0100, 9));
        let Claim::Ready(t) = cache.claim(KEY, 0b0111) else {
            panic!("the merged tile covers both requests");
        };
        assert_eq!(t.mask, 0b0111);
        assert_eq!(t.get([0, 0, 0]), [7, 0, 0]);
        assert_eq!(t.get([1, 0, 0]), [7, 1, 0]);
        assert_eq!(t.get([2, 0, 0]), [9, 2, 0]);
        assert_eq!(cache.stats().entries, 1);
    }
}
