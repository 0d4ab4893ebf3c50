//! Steps 3 and 4 of the bake: every stored tile cut, borders included, from a painted block of
//! the finest grid or from its painted subsample, and written; and the densest grass over the
//! finest tiles, for the manifest.

use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc;

use crate::world::error::WorldError;
use crate::world::format::{TileData, write_tile_with};
use crate::world::manifest::Manifest;
use crate::world::tile::{Pyramid, TileId};

use super::BakeStage;
use super::paint::{PaintMaps, Painted};
use super::plan::Plan;
use super::resample::Grid;
use super::source::DemSource;

/// Every stored tile, level by level (coarsest first), rows south to north, west to east.
pub(super) fn stored_tiles(pyramid: &Pyramid) -> Vec<TileId> {
    (0..pyramid.stored_levels)
        .flat_map(|level| {
            let [nx, ny] = pyramid.tiles_at(level);
            (0..ny).flat_map(move |y| (0..nx).map(move |x| TileId::new(level, x, y)))
        })
        .collect()
}

/// What [`produce`] makes tiles from.
pub(super) struct Producer<'a> {
    pub(super) out: &'a Path,
    pub(super) pyramid: &'a Pyramid,
    pub(super) dem: &'a DemSource,
    pub(super) plan: &'a Plan,
    /// The painted subsample of the finest grid that the coarse levels are cut from.
    pub(super) coarse: &'a Painted,
    pub(super) paint: &'a BlockPaint<'a>,
    /// The grass types, for the densest grass of the finest tiles.
    pub(super) manifest: &'a Manifest,
}

/// How a block is painted: the inputs of [`Grid::paint`] besides the grid.
pub(super) struct BlockPaint<'a> {
    pub(super) height_range: [f32; 2],
    pub(super) seed: u64,
    pub(super) maps: &'a PaintMaps<'a>,
}

/// One piece of work: a tile cut from the coarse subsample, or a block of the finest grid
/// resampled and painted and the tiles inside it cut from it.
enum Work {
    Coarse(TileId),
    Block(TileId, Vec<TileId>),
}

/// Makes `tiles` and writes them into `out`, on as many threads as the plan allows; stops
/// between tiles when `cancelled` says so. Returns the tiles written and the densest grass
/// of the finest ones among them (see [`crate::world::GrassPeak`]).
pub(super) fn produce(
    p: &Producer<'_>,
    tiles: Vec<TileId>,
    cancelled: &(dyn Fn() -> Result<(), WorldError> + Sync),
    progress: &mut dyn FnMut(BakeStage, u64, u64),
) -> Result<(u64, f32), WorldError> {
    use crate::world::grass_density::{SHORT_GRASS_M, split_shares, tile_peak, window_cells};
    let pyramid = p.pyramid;
    let total = tiles.len() as u64;
    progress(BakeStage::WriteTiles, 0, total);
    let mut work: Vec<Work> = Vec::new();
    let mut blocks: std::collections::BTreeMap<TileId, Vec<TileId>> = Default::default();
    for id in tiles {
        if p.plan.coarse_level(id.level) {
            work.push(Work::Coarse(id));
        } else {
            let up = id.level - p.plan.block_level;
            let block = TileId::new(p.plan.block_level, id.x >> up, id.y >> up);
            blocks.entry(block).or_default().push(id);
        }
    }
    work.extend(blocks.into_iter().map(|(b, ids)| Work::Block(b, ids)));
    let finest = pyramid.stored_levels - 1;
    let window = window_cells(pyramid, pyramid.tile_size_m(pyramid.max_level()));
    let split = split_shares(&p.manifest.grass_types, SHORT_GRASS_M);
    let bake_id = p.manifest.bake_id_value();
    let write = |tile: TileData| -> Result<f32, WorldError> {
        cancelled()?;
        let peak = if tile.id.level == finest {
            tile_peak(&tile, pyramid, window, &split)
        } else {
            0.0
        };
        write_tile_with(p.out, pyramid, &tile, bake_id)?;
        Ok(peak)
    };
    let next = AtomicUsize::new(0);
    let (tx, rx) = mpsc::sync_channel::<Result<f32, WorldError>>(64);
    let mut first_error = None;
    let mut peak = 0f32;
    std::thread::scope(|scope| {
        let started = super::spawn_workers(scope, p.plan.threads, || {
            let tx = tx.clone();
            let (work, next, write) = (&work, &next, &write);
            move || {
                while let Some(item) = work.get(next.fetch_add(1, Ordering::Relaxed)) {
                    let failed = match item {
                        Work::Coarse(id) => {
                            let result = write(cut_tile(pyramid, p.coarse, *id));
                            let failed = result.is_err();
                            tx.send(result).is_err() || failed
                        }
                        Work::Block(block, ids) => match paint_block(p, *block, cancelled) {
                            Err(e) => {
                                let _ = tx.send(Err(e));
                                true
                            }
                            Ok(painted) => {
                                let mut failed = false;
                                for &id in ids {
                                    let result = write(cut_tile(pyramid, &painted, id));
                                    failed = result.is_err();
                                    if tx.send(result).is_err() || failed {
                                        failed = true;
                                        break;
                                    }
                                }
                                failed
                            }
                        },
                    };
                    if failed {
                        break;
                    }
                }
            }
        });
        drop(tx);
        if let Err(e) = started {
            first_error = Some(e);
            return;
        }
        let mut done = 0;
        for result in rx {
            match result {
                Ok(p) => {
                    peak = peak.max(p);
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
        None => Ok((total, peak)),
    }
}

/// Block `id` of the finest grid (its tile's samples, borders included, and a ring for the
/// slopes) resampled and painted.
fn paint_block(
    p: &Producer<'_>,
    id: TileId,
    cancelled: &dyn Fn() -> Result<(), WorldError>,
) -> Result<Painted, WorldError> {
    cancelled()?;
    let span = p
        .plan
        .shape
        .tile_span(p.pyramid, id)
        .map(|[lo, hi]| [lo - 1, hi + 1]);
    let grid = Grid::resample(p.dem, p.plan.shape, span)?;
    let paint = p.paint;
    grid.paint(
        paint.height_range,
        paint.seed,
        paint.maps,
        &|g, a, b| g.slope_deg(a, b),
        cancelled,
        &mut |_, _, _| {},
    )
}

/// The samples of tile `id`, taken from the finest grid every `2^(finest - level)` samples,
/// from a painted window or subsample that holds them.
pub(super) fn cut_tile(pyramid: &Pyramid, painted: &Painted, id: TileId) -> TileData {
    let grid = &painted.grid;
    let size = pyramid.samples_per_side();
    let step = 1i64 << (grid.shape.finest - id.level);
    let border = i64::from(pyramid.border);
    let cells = i64::from(pyramid.tile_cells);
    let margin = grid.shape.margin;
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
        let b = (i64::from(id.y) * cells + j - border) * step + margin;
        for i in 0..i64::from(size) {
            let a = (i64::from(id.x) * cells + i - border) * step + margin;
            let k = grid.local(a, b);
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
