//! Steps 3 and 4 of the bake: every stored tile cut from the one painted grid, borders
//! included, and written; and the densest grass over the finest tiles, for the manifest.

use std::path::Path;
use std::sync::mpsc;

use crate::world::error::WorldError;
use crate::world::format::{TileData, write_tile};
use crate::world::manifest::Manifest;
use crate::world::tile::{Pyramid, TileId};

use super::BakeStage;
use super::paint::Painted;

/// Every stored tile, level by level (coarsest first), rows south to north, west to east.
pub(super) fn stored_tiles(pyramid: &Pyramid) -> Vec<TileId> {
    (0..pyramid.stored_levels)
        .flat_map(|level| {
            let [nx, ny] = pyramid.tiles_at(level);
            (0..ny).flat_map(move |y| (0..nx).map(move |x| TileId::new(level, x, y)))
        })
        .collect()
}

/// Cuts every stored tile from the painted grid and writes it (see [`write_tiles`]).
pub(super) fn write_all_tiles(
    out: &Path,
    pyramid: &Pyramid,
    painted: &Painted,
    cancelled: &(dyn Fn() -> Result<(), WorldError> + Sync),
    progress: &mut dyn FnMut(BakeStage, u64, u64),
) -> Result<u64, WorldError> {
    write_tiles(
        out,
        pyramid,
        painted,
        stored_tiles(pyramid),
        cancelled,
        progress,
    )
}

/// Cuts `tiles` from the painted grid and writes them, on as many threads as the machine
/// offers; stops between tiles when `cancelled` says so.
pub(super) fn write_tiles(
    out: &Path,
    pyramid: &Pyramid,
    painted: &Painted,
    tiles: Vec<TileId>,
    cancelled: &(dyn Fn() -> Result<(), WorldError> + Sync),
    progress: &mut dyn FnMut(BakeStage, u64, u64),
) -> Result<u64, WorldError> {
    let total = tiles.len() as u64;
    progress(BakeStage::WriteTiles, 0, total);
    let threads = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
        .min(8);
    let (tx, rx) = mpsc::channel::<Result<(), WorldError>>();
    let mut first_error = None;
    std::thread::scope(|scope| {
        for t in 0..threads {
            let tx = tx.clone();
            let tiles = &tiles;
            scope.spawn(move || {
                for &id in tiles.iter().skip(t).step_by(threads) {
                    let result = cancelled()
                        .and_then(|()| write_tile(out, pyramid, &cut_tile(pyramid, painted, id)));
                    let failed = result.is_err();
                    if tx.send(result).is_err() || failed {
                        break;
                    }
                }
            });
        }
        drop(tx);
        let mut done = 0;
        for result in rx {
            match result {
                Ok(()) => {
                    done += 1;
                    progress(BakeStage::WriteTiles, done, total);
                }
                Err(e) => {
                    first_error.get_or_insert(e);
                }
            }
        }
    });
    match first_error {
        Some(e) => Err(e),
        None => Ok(total),
    }
}

/// The samples of tile `id`, taken from the finest grid every `2^(finest - level)` samples.
pub(super) fn cut_tile(pyramid: &Pyramid, painted: &Painted, id: TileId) -> TileData {
    let grid = &painted.grid;
    let size = pyramid.samples_per_side();
    let step = 1i64 << (grid.finest - id.level);
    let border = i64::from(pyramid.border);
    let cells = i64::from(pyramid.tile_cells);
    let n = size as usize * size as usize;
    let mut tile = TileData {
        id,
        size,
        heights: Vec::with_capacity(n),
        grass_type: Vec::with_capacity(n),
        density: Vec::with_capacity(n),
        material: Vec::with_capacity(if painted.material.is_empty() { 0 } else { n }),
    };
    for j in 0..i64::from(size) {
        let b = ((i64::from(id.y) * cells + j - border) * step + grid.margin) as usize;
        for i in 0..i64::from(size) {
            let a = ((i64::from(id.x) * cells + i - border) * step + grid.margin) as usize;
            let k = b * grid.width + a;
            tile.heights.push(grid.heights[k]);
            tile.grass_type.push(painted.grass_type[k]);
            tile.density.push(painted.density[k]);
            if let Some(&m) = painted.material.get(k) {
                tile.material.push(m);
            }
        }
    }
    tile
}

/// The densest grass of the finest stored level over windows of the finest grass tiles
/// (`Pyramid::max_level`), for the manifest's `grass_peak`.
pub(super) fn grass_peak(manifest: &Manifest, painted: &Painted) -> crate::world::GrassPeak {
    use crate::world::grass_density::{SHORT_GRASS_M, split_shares, tile_peak, window_cells};
    let pyramid = &manifest.pyramid;
    let level = pyramid.stored_levels - 1;
    let window_m = pyramid.tile_size_m(pyramid.max_level());
    let window = window_cells(pyramid, window_m);
    let split = split_shares(&manifest.grass_types, SHORT_GRASS_M);
    let [nx, ny] = pyramid.tiles_at(level);
    let mut density = 0.0f32;
    for y in 0..ny {
        for x in 0..nx {
            let tile = cut_tile(pyramid, painted, TileId::new(level, x, y));
            density = density.max(tile_peak(&tile, pyramid, window, &split));
        }
    }
    crate::world::GrassPeak {
        window_m,
        short_m: SHORT_GRASS_M,
        density,
    }
}
