//! The CPU cache of decoded tiles: least recently used first out, bounded in bytes.

use std::sync::Arc;

use lru::LruCache;

use crate::world::{TileData, TileId};

/// Counters of a [`TileCache`].
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CacheStats {
    /// Bytes held now.
    pub bytes: u64,
    /// Most bytes ever held.
    pub peak_bytes: u64,
    /// Tiles held now.
    pub tiles: u64,
    /// Lookups that found their tile.
    pub hits: u64,
    /// Lookups that did not.
    pub misses: u64,
    /// Tiles dropped to stay under the ceiling.
    pub evictions: u64,
}

impl CacheStats {
    /// Hits over lookups (1 when there were none).
    pub fn hit_rate(&self) -> f64 {
        let lookups = self.hits + self.misses;
        if lookups == 0 {
            1.0
        } else {
            self.hits as f64 / lookups as f64
        }
    }
}

/// Decoded tiles, never more than `ceiling_bytes` of them.
pub struct TileCache {
    tiles: LruCache<TileId, Arc<TileData>>,
    ceiling_bytes: u64,
    stats: CacheStats,
}

impl TileCache {
    /// An empty cache that holds at most `ceiling_bytes` of tile data.
    pub fn new(ceiling_bytes: u64) -> Self {
        Self {
            tiles: LruCache::unbounded(),
            ceiling_bytes,
            stats: CacheStats::default(),
        }
    }

    /// The ceiling in bytes.
    pub fn ceiling_bytes(&self) -> u64 {
        self.ceiling_bytes
    }

    /// The tile, if held; marks it most recently used and counts a hit or a miss.
    pub fn get(&mut self, id: TileId) -> Option<Arc<TileData>> {
        match self.tiles.get(&id) {
            Some(t) => {
                self.stats.hits += 1;
                Some(Arc::clone(t))
            }
            None => {
                self.stats.misses += 1;
                None
            }
        }
    }

    /// Whether the tile is held (not counted as a lookup).
    pub fn contains(&self, id: TileId) -> bool {
        self.tiles.contains(&id)
    }

    /// Adds a tile, evicting the least recently used ones until the cache fits its ceiling.
    /// A tile larger than the whole ceiling is not kept; returns whether it was.
    pub fn insert(&mut self, tile: Arc<TileData>) -> bool {
        let size = tile.byte_size() as u64;
        if size > self.ceiling_bytes {
            return false;
        }
        if let Some(old) = self.tiles.pop(&tile.id) {
            self.stats.bytes -= old.byte_size() as u64;
        }
        while self.stats.bytes + size > self.ceiling_bytes {
            match self.tiles.pop_lru() {
                Some((_, old)) => {
                    self.stats.bytes -= old.byte_size() as u64;
                    self.stats.evictions += 1;
                }
                None => break,
            }
        }
        self.tiles.put(tile.id, tile);
        self.stats.bytes += size;
        self.stats.peak_bytes = self.stats.peak_bytes.max(self.stats.bytes);
        self.stats.tiles = self.tiles.len() as u64;
        true
    }

    /// The counters.
    pub fn stats(&self) -> CacheStats {
        CacheStats {
            tiles: self.tiles.len() as u64,
            ..self.stats
        }
    }
}
