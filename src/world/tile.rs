//! Tile addressing: [`TileId`] quadtree math, world-space [`Bounds`], and the [`Pyramid`] that
//! says how big tiles are at each level and how many there are.
//!
//! Coordinates: x grows eastward, y northward, in metres from the world's south-west corner.
//! Level 0 is the coarsest; each level halves the tile size and doubles the tile count per axis.

use glam::DVec2;
use serde::{Deserialize, Serialize};

/// One tile of the quadtree: a level and a position in that level's grid.
///
/// `x` grows eastward and `y` northward; tile (0, 0) of every level sits at the world origin.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct TileId {
    /// Level in the pyramid; 0 is the coarsest.
    pub level: u8,
    /// Column, from the west.
    pub x: u32,
    /// Row, from the south.
    pub y: u32,
}

/// `L2 5_8`: the level, then the column and row, as the tile's files are named.
impl std::fmt::Display for TileId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "L{} {}_{}", self.level, self.x, self.y)
    }
}

impl TileId {
    /// The tile at `(x, y)` of `level`.
    pub const fn new(level: u8, x: u32, y: u32) -> Self {
        TileId { level, x, y }
    }

    /// The tile one level coarser that contains this one; `None` at level 0.
    pub fn parent(self) -> Option<TileId> {
        if self.level == 0 {
            None
        } else {
            Some(TileId::new(self.level - 1, self.x >> 1, self.y >> 1))
        }
    }

    /// The four tiles one level finer that make up this one, in the order SW, SE, NW, NE.
    pub fn children(self) -> [TileId; 4] {
        let (l, x, y) = (self.level + 1, self.x * 2, self.y * 2);
        [
            TileId::new(l, x, y),
            TileId::new(l, x + 1, y),
            TileId::new(l, x, y + 1),
            TileId::new(l, x + 1, y + 1),
        ]
    }

    /// Which quarter of its parent this tile is: `(x & 1, y & 1)`, so (0, 0) is the SW quarter.
    pub fn quadrant_in_parent(self) -> (u32, u32) {
        (self.x & 1, self.y & 1)
    }

    /// The tile at `level` that contains this one: itself at its own level, `None` for a finer
    /// level.
    pub fn ancestor_at(self, level: u8) -> Option<TileId> {
        if level > self.level {
            return None;
        }
        let shift = u32::from(self.level - level);
        Some(TileId::new(
            level,
            self.x.checked_shr(shift).unwrap_or(0),
            self.y.checked_shr(shift).unwrap_or(0),
        ))
    }
}

/// An axis-aligned rectangle in world metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    /// South-west corner.
    pub min: DVec2,
    /// North-east corner.
    pub max: DVec2,
}

impl Bounds {
    /// Width (east-west) and height (north-south).
    pub fn size(&self) -> DVec2 {
        self.max - self.min
    }

    /// The centre point.
    pub fn center(&self) -> DVec2 {
        (self.min + self.max) * 0.5
    }

    /// Whether `p` lies inside or on the edge.
    pub fn contains(&self, p: DVec2) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }

    /// Distance from `p` to the nearest point of the rectangle; 0 inside.
    pub fn distance_to(&self, p: DVec2) -> f64 {
        let d = (self.min - p).max(p - self.max).max(DVec2::ZERO);
        d.length()
    }
}

/// The tile pyramid of a world (part of the manifest).
///
/// Each tile stores `samples_per_side()` height/type/density samples per edge: `tile_cells + 1`
/// posts from its west edge to its east edge (so neighbours share their edge samples), plus
/// `border` extra samples beyond each edge, taken from the same global grid as the neighbour's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pyramid {
    /// Edge length of a level-0 tile, metres.
    pub root_tile_size_m: f64,
    /// Level-0 grid: tiles along x (east) and y (north).
    #[serde(deserialize_with = "crate::world::manifest::exact")]
    pub root_tiles: [u32; 2],
    /// Cells per tile edge (a power of two, e.g. 128).
    pub tile_cells: u32,
    /// Extra shared samples beyond each tile edge (e.g. 2).
    pub border: u32,
    /// Levels `0..stored_levels` are stored on disk.
    pub stored_levels: u8,
    /// Finer levels, derived at run time from their parents.
    #[serde(default)]
    pub derived_levels: u8,
}

/// `2^-level` as an exact f64.
fn half_pow(level: u8) -> f64 {
    2f64.powi(-i32::from(level))
}

impl Pyramid {
    /// Edge length of a tile at `level`, metres.
    pub fn tile_size_m(&self, level: u8) -> f64 {
        self.root_tile_size_m * half_pow(level)
    }

    /// Distance between neighbouring samples at `level`, metres.
    pub fn cell_size_m(&self, level: u8) -> f64 {
        self.tile_size_m(level) / f64::from(self.tile_cells)
    }

    /// Tiles along x and y at `level` (saturating at `u32::MAX` for absurd levels).
    pub fn tiles_at(&self, level: u8) -> [u32; 2] {
        let scale = 1u64.checked_shl(u32::from(level)).unwrap_or(u64::MAX);
        self.root_tiles
            .map(|n| u64::from(n).saturating_mul(scale).min(u64::from(u32::MAX)) as u32)
    }

    /// Samples per tile edge: `tile_cells + 1 + 2 * border`.
    pub fn samples_per_side(&self) -> u32 {
        self.tile_cells + 1 + 2 * self.border
    }

    /// Number of levels, stored and derived.
    pub fn level_count(&self) -> u8 {
        self.stored_levels.saturating_add(self.derived_levels)
    }

    /// The finest level: `stored_levels + derived_levels - 1`.
    pub fn max_level(&self) -> u8 {
        self.level_count().saturating_sub(1)
    }

    /// Whether `id` is a tile of this pyramid, stored or derived.
    pub fn contains(&self, id: TileId) -> bool {
        let [nx, ny] = self.tiles_at(id.level);
        id.level < self.level_count() && id.x < nx && id.y < ny
    }

    /// Whether `id` is stored on disk.
    pub fn is_stored(&self, id: TileId) -> bool {
        id.level < self.stored_levels && self.contains(id)
    }

    /// The world-space rectangle a tile covers (its edges, not its border samples).
    pub fn bounds(&self, id: TileId) -> Bounds {
        let size = self.tile_size_m(id.level);
        let min = DVec2::new(f64::from(id.x) * size, f64::from(id.y) * size);
        Bounds {
            min,
            max: min + DVec2::splat(size),
        }
    }

    /// The tile at `level` that contains `p`; `None` outside the grid or beyond the finest
    /// level. Tiles own their west and south edges; points on the grid's east or north edge
    /// belong to the last tile.
    pub fn tile_at(&self, level: u8, p: DVec2) -> Option<TileId> {
        if level >= self.level_count() || !p.is_finite() {
            return None;
        }
        let size = self.tile_size_m(level);
        let [nx, ny] = self.tiles_at(level);
        let index = |v: f64, n: u32| -> Option<u32> {
            let f = (v / size).floor();
            if f < 0.0 {
                None
            } else if f < f64::from(n) {
                Some(f as u32)
            } else if n > 0 && v == f64::from(n) * size {
                Some(n - 1)
            } else {
                None
            }
        };
        Some(TileId::new(level, index(p.x, nx)?, index(p.y, ny)?))
    }

    /// The tiles next to `id` at the same level, in the order W, E, S, N; `None` outside the
    /// grid.
    pub fn neighbours(&self, id: TileId) -> [Option<TileId>; 4] {
        let at = |x: Option<u32>, y: Option<u32>| {
            let t = TileId::new(id.level, x?, y?);
            self.contains(t).then_some(t)
        };
        [
            at(id.x.checked_sub(1), Some(id.y)),
            at(id.x.checked_add(1), Some(id.y)),
            at(Some(id.x), id.y.checked_sub(1)),
            at(Some(id.x), id.y.checked_add(1)),
        ]
    }

    /// World position of sample `(i, j)` of tile `id`: `bounds.min + (i - border, j - border) * cell`.
    pub fn sample_position(&self, id: TileId, i: u32, j: u32) -> DVec2 {
        let cell = self.cell_size_m(id.level);
        let b = f64::from(self.border);
        self.bounds(id).min + DVec2::new(f64::from(i) - b, f64::from(j) - b) * cell
    }

    /// Total number of tiles in the stored levels.
    pub fn stored_tile_count(&self) -> u64 {
        (0..self.stored_levels)
            .map(|l| {
                let [nx, ny] = self.tiles_at(l);
                u64::from(nx) * u64::from(ny)
            })
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pyramid() -> Pyramid {
        Pyramid {
            root_tile_size_m: 1000.0,
            root_tiles: [2, 3],
            tile_cells: 16,
            border: 2,
            stored_levels: 3,
            derived_levels: 2,
        }
    }

    #[test]
    fn parent_child_round_trip() {
        let id = TileId::new(3, 5, 6);
        for (q, c) in id.children().into_iter().enumerate() {
            assert_eq!(c.parent(), Some(id));
            assert_eq!(c.quadrant_in_parent(), (q as u32 & 1, q as u32 >> 1));
        }
        assert_eq!(TileId::new(0, 1, 1).parent(), None);
    }

    #[test]
    fn ancestor_at_walks_parents() {
        let id = TileId::new(4, 13, 9);
        assert_eq!(id.ancestor_at(4), Some(id));
        assert_eq!(id.ancestor_at(3), id.parent());
        assert_eq!(id.ancestor_at(1), Some(TileId::new(1, 1, 1)));
        assert_eq!(id.ancestor_at(5), None);
    }

    #[test]
    fn neighbours_round_trip() {
        let p = pyramid();
        for level in 0..p.level_count() {
            let [nx, ny] = p.tiles_at(level);
            for y in 0..ny {
                for x in 0..nx {
                    let id = TileId::new(level, x, y);
                    let [w, e, s, n] = p.neighbours(id);
                    assert_eq!(w.is_none(), x == 0);
                    assert_eq!(e.is_none(), x + 1 == nx);
                    assert_eq!(s.is_none(), y == 0);
                    assert_eq!(n.is_none(), y + 1 == ny);
                    if let Some(w) = w {
                        assert_eq!(p.neighbours(w)[1], Some(id));
                    }
                    if let Some(e) = e {
                        assert_eq!(p.neighbours(e)[0], Some(id));
                    }
                    if let Some(s) = s {
                        assert_eq!(p.neighbours(s)[3], Some(id));
                    }
                    if let Some(n) = n {
                        assert_eq!(p.neighbours(n)[2], Some(id));
                    }
                }
            }
        }
    }

    #[test]
    fn children_tile_the_parent() {
        let p = pyramid();
        let id = TileId::new(1, 2, 3);
        let b = p.bounds(id);
        let kids = id.children().map(|c| p.bounds(c));
        assert_eq!(kids[0].min, b.min);
        assert_eq!(kids[3].max, b.max);
        assert_eq!(kids[0].max, kids[3].min);
        assert_eq!(kids[1].min, DVec2::new(b.center().x, b.min.y));
        assert_eq!(kids[2].min, DVec2::new(b.min.x, b.center().y));
        let area: f64 = kids.iter().map(|k| k.size().x * k.size().y).sum();
        assert_eq!(area, b.size().x * b.size().y);
    }

    #[test]
    fn tile_at_inverts_bounds() {
        let p = pyramid();
        for level in 0..p.level_count() {
            let [nx, ny] = p.tiles_at(level);
            for y in 0..ny {
                for x in 0..nx {
                    let id = TileId::new(level, x, y);
                    let b = p.bounds(id);
                    assert_eq!(p.tile_at(level, b.min), Some(id));
                    assert_eq!(p.tile_at(level, b.center()), Some(id));
                }
            }
        }
        let top = DVec2::new(2000.0, 3000.0);
        assert_eq!(p.tile_at(0, top), Some(TileId::new(0, 1, 2)));
        assert_eq!(p.tile_at(0, DVec2::new(-0.1, 5.0)), None);
        assert_eq!(p.tile_at(0, DVec2::new(2000.1, 5.0)), None);
        assert_eq!(p.tile_at(5, DVec2::ZERO), None);
    }

    #[test]
    fn bounds_distance() {
        let b = Bounds {
            min: DVec2::ZERO,
            max: DVec2::new(10.0, 10.0),
        };
        assert_eq!(b.distance_to(DVec2::new(5.0, 5.0)), 0.0);
        assert_eq!(b.distance_to(DVec2::new(13.0, 14.0)), 5.0);
        assert_eq!(b.distance_to(DVec2::new(-2.0, 5.0)), 2.0);
        assert!(b.contains(DVec2::new(10.0, 0.0)));
    }

    #[test]
    fn sizes() {
        let p = pyramid();
        assert_eq!(p.tile_size_m(2), 250.0);
        assert_eq!(p.cell_size_m(2), 250.0 / 16.0);
        assert_eq!(p.tiles_at(2), [8, 12]);
        assert_eq!(p.samples_per_side(), 21);
        assert_eq!(p.max_level(), 4);
        assert!(p.contains(TileId::new(4, 31, 47)));
        assert!(!p.contains(TileId::new(4, 32, 0)));
        assert!(!p.contains(TileId::new(5, 0, 0)));
        assert_eq!(p.stored_tile_count(), 6 + 24 + 96);
        assert_eq!(
            p.sample_position(TileId::new(0, 1, 0), 2, 2),
            DVec2::new(1000.0, 0.0)
        );
    }
}
