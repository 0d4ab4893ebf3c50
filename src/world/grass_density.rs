//! The densest grass of a world, which sizes the grass instance pool: worked out by the baker
//! from the finest stored level and kept in the manifest ([`GrassPeak`]), so that a renderer
//! sizes its pool without reading every tile (and a bad tile is a fault, not a failure).

use serde::{Deserialize, Serialize};

use super::format::TileData;
use super::manifest::GrassType;
use super::tile::Pyramid;

/// Grass shorter than this is split in two blades (the renderer's default).
pub const SHORT_GRASS_M: f32 = 0.3;

/// The manifest's `[grass_peak]` table: the densest grass of the finest stored level, over
/// windows of a grass tile's size.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GrassPeak {
    /// Edge of the window (a grass tile), metres.
    pub window_m: f64,
    /// Grass whose type can be shorter than this is split in two, so counts twice, metres.
    pub short_m: f32,
    /// The largest window mean of density (0..=1) times 2 for split types, 1 for others:
    /// 0..=2.
    pub density: f32,
}

/// Per grass type: 1 if a blade of the type can be shorter than `short_m` (heights shrink to
/// 0.35 of the type's range with clump and density), so that it is split, else 0.
pub fn split_shares(types: &[GrassType], short_m: f32) -> Vec<f32> {
    types
        .iter()
        .map(|t| {
            if t.height_m[0] * 0.35 < short_m {
                1.0
            } else {
                0.0
            }
        })
        .collect()
}

/// Cells of the finest stored level in a window of `window_m`.
pub fn window_cells(pyramid: &Pyramid, window_m: f64) -> u32 {
    let cell = pyramid.cell_size_m(pyramid.stored_levels - 1);
    ((window_m / cell).round() as u32).clamp(1, pyramid.tile_cells.max(1))
}

/// The densest window of `window` cells of a tile (windows half a window apart, inside the
/// tile's own cells): the mean of density times `1 + split[type]`; type 0 (bare) and types
/// without an entry in `split` count nothing.
pub fn tile_peak(tile: &TileData, pyramid: &Pyramid, window: u32, split: &[f32]) -> f32 {
    let b = pyramid.border;
    let n = pyramid.tile_cells;
    let window = window.clamp(1, n.max(1));
    let mut densest = 0.0f32;
    let mut y = 0;
    while y + window <= n {
        let mut x = 0;
        while x + window <= n {
            let mut sum = 0.0f32;
            for j in y..y + window {
                for i in x..x + window {
                    let k = tile.index(i + b, j + b);
                    let t = tile.grass_type[k] as usize;
                    if t > 0 && t < split.len() {
                        sum += f32::from(tile.density[k]) / 255.0 * (1.0 + split[t]);
                    }
                }
            }
            densest = densest.max(sum / (window * window) as f32);
            x += window.div_ceil(2);
        }
        y += window.div_ceil(2);
    }
    densest
}
