//! The baker: turns a DEM ([`Dem`]) into a world: a pyramid of stored tiles and `world.toml`.
//!
//! 0. The DEM is opened (`source`): a file small enough for a quarter of the memory limit
//!    is read whole ([`Dem::load_with`]: GeoTIFF, SRTM `.hgt` or PNG + sidecar, told apart by
//!    content) and its nodata samples filled; a larger one, one over HTTP, and several files
//!    (a folder or a VRT, joined by [`crate::world::mosaic`]) are read in filled chunks of
//!    their joined grid, each file a window of rows at a time ([`crate::world::window`]).
//! 1. The finest grid: the DEM resampled (Catmull-Rom bicubic in its own, non-square grid) to
//!    square cells at the finest stored level, over the whole root grid plus a margin for the
//!    tile borders of every level; beyond the DEM the height of the nearest edge point is
//!    repeated. It is never held whole ([`plan`]): a survey streams it once for the height
//!    range, the calibration window and a subsample (every `stride`-th sample, the whole grid
//!    where it fits), and the finer levels are resampled again block by block.
//! 2. Grass type and density are painted from slope (measured on the finest grid), altitude and
//!    value noise seeded by [`BakeOptions::seed`]: no grass where the slope exceeds 35 degrees,
//!    lush meadow and tall grass low down, dry grass high up and on dry (noise) ground. A
//!    sample's paint depends only on where it lies.
//! 3. Coarser levels are point samples of the finest grid: the sample at level `L` is the
//!    sample at the same position at level `L + 1` (every other one). Coarse and fine tiles
//!    therefore agree exactly where their samples coincide, so a fine tile morphed to its
//!    parent's resolution meets the parent without cracks, and children derived from a parent
//!    start from the parent's own values.
//! 4. Every tile is cut (borders included) from the painted subsample or from a painted block
//!    of the finest grid, which agree wherever they overlap, so neighbours share identical edge
//!    and border samples; tiles are written through temporary files.
//! 5. Seven camera paths are computed from the terrain ("tour", the default, "overview", "low",
//!    "meadow", "helicopter", and "wind-tour" with its "walker"), their heights above the ground
//!    the renderer draws (the finest derived level, Catmull-Rom halvings of the finest grid, not
//!    its bilinear surface, tens of metres off between cells kilometres wide), four wind scenes
//!    are added ("calm", "breeze", "storm" and "helicopter", see [`default_wind_scenes`]; the
//!    wind tour shows them in turn), and `world.toml` is written last, so a world with a
//!    manifest is a complete world.
//!
//! The bake is deterministic: the same DEM, options and seed give byte-identical files.
//!
//! The world is written into a staging folder beside the output folder (`.NAME.baking.*`,
//! never inside it) and moved into place at the end; a bake that fails or is cancelled
//! ([`BakeOptions::cancel`]) removes it and leaves the output folder as it was. A bake holds
//! an OS lock on a file in its staging folder while it runs, so that the next bake beside the
//! same output folder removes the staging folders of bakes that were killed (whose lock is
//! free) and leaves those of running bakes alone. A bake killed while moving its world in is
//! put right first, from the record its staging folder holds: the folder gets back the world
//! it held (and a sharded bake's parts folder its tiles), or, where the new `world.toml` was
//! already in, the world stays published.
//!
//! The stages live in submodules: `plan` (how the memory limit is spent), `source` (the DEM
//! whole or in chunks), `survey` (the one pass over the whole grid), `resample` (windows and
//! subsamples of the finest grid), `paint` (grass types and density), `tiles` (blocks, cutting
//! and writing the pyramid), `author` (camera paths and wind scenes), `shard` (sharded bakes)
//! and `publish` (the staging folder, the safe replacement of `world.toml` and `tiles/`, and
//! cancellation).

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::world::dem::{Dem, DemFormat, DemOptions};
use crate::world::error::WorldError;
use crate::world::format::write_atomic;
use crate::world::manifest::{
    MIN_GRASS_TILE_M, Manifest, Sky, WindDefaults, WorldSource, forbidden_control,
    without_control_characters,
};
use crate::world::tile::Pyramid;

mod author;
mod cancel;
mod carry;
pub mod ceiling;
pub mod cover;
mod paint;
pub mod plan;
mod publish;
mod resample;
pub mod shard;
mod source;
mod survey;
#[cfg(test)]
mod tests;
mod tiles;

pub use author::{
    HELICOPTER_PATH, WALKER_PATH, WIND_TOUR_PATH, WIND_TOUR_SCENES, default_wind_scenes,
};
pub use cancel::CancelFlag;
pub use carry::Carried;
pub use paint::{MAX_GRASS_SLOPE_DEG, default_grass_types, default_plant_types};

use author::{helicopter_path, low_path, meadow_path, overview_path, tour_path, wind_tour_paths};
use paint::check_painted_types;
use plan::Plan;
use publish::{Staging, check_out, resolve_out};
use source::DemSource;
use tiles::produce;

pub use shard::ShardStep;

/// Shared samples beyond each tile edge in baked worlds.
pub const BAKE_BORDER: u32 = 2;
/// Levels finer than the stored ones that baked worlds ask the runtime to derive, at the least:
/// a coarser DEM gets more ([`derived_levels_for`]).
pub const BAKE_DERIVED_LEVELS: u8 = 6;

/// Widest finest tile (the grass's) a bake aims for, metres: a DEM coarse enough that six
/// derived levels leave wider tiles gets more derived levels, up to the 24 levels a pyramid
/// holds (the default world's tiles are 50 m; an SRTM bake's at 30 m cells 60 m).
pub const BAKE_GRASS_TILE_M: f64 = 64.0;

/// Derived levels for stored finest tiles `stored_finest_m` wide under `stored_levels`:
/// [`BAKE_DERIVED_LEVELS`], or as many more as bring the finest tiles within
/// [`BAKE_GRASS_TILE_M`], within 24 levels in all; fewer where data finer than the grass needs
/// would leave tiles narrower than [`MIN_GRASS_TILE_M`](crate::world::manifest::MIN_GRASS_TILE_M)
/// (lidar at 5 cm cells gets three).
pub fn derived_levels_for(stored_finest_m: f64, stored_levels: u8) -> u8 {
    let halvings = |tile_m: f64| {
        let h = (stored_finest_m / tile_m).log2();
        if h.is_finite() {
            h.clamp(0.0, 24.0)
        } else {
            0.0
        }
    };
    let wanted = (halvings(BAKE_GRASS_TILE_M).ceil() as u8).max(BAKE_DERIVED_LEVELS);
    let finest = halvings(crate::world::manifest::MIN_GRASS_TILE_M).floor() as u8;
    wanted.min(finest).min(24u8.saturating_sub(stored_levels))
}

/// What to bake, and how.
#[derive(Clone, Debug, PartialEq)]
pub struct BakeOptions {
    /// The DEM: a GeoTIFF, an SRTM `.hgt` tile, or a 16-bit PNG whose sidecar sits beside it
    /// with the extension `.json`.
    pub dem: PathBuf,
    /// More DEM files joined to `dem` into one on their georeferencing (see
    /// [`crate::world::mosaic`]); `dem` itself may also be a folder of DEM files or a GDAL VRT.
    pub more_dems: Vec<PathBuf>,
    /// Spacing of the DEM's samples in metres (east-west, north-south), in place of what the
    /// file says; needed for a TIFF without GeoTIFF tags.
    pub dem_cell_size_m: Option<[f64; 2]>,
    /// The world directory to write (`.`, `..` and relative paths are resolved first). The
    /// world is baked into a staging folder beside it and moved into place at the end; an
    /// existing folder that is not empty is refused unless `replace` is set. A bake writes, and
    /// replaces, only `world.toml` and `tiles/` in it: its other files (a README, the source
    /// DEM) are never moved or changed.
    pub out: PathBuf,
    /// World name; by default the name of `out`.
    pub name: Option<String>,
    /// Cell size at the finest stored level, metres; by default the DEM's smaller cell size
    /// rounded to 1, 2, 2.5 or 5 times a power of ten (25 m for 24.585 m).
    pub cell_size_m: Option<f64>,
    /// Cells per tile edge (power of two, 8..=1024).
    pub tile_cells: u32,
    /// Stored levels (1..=12), or 0: as many as the world needs, at least 3, for its level-0
    /// tiles to number at most [`MAX_AUTO_ROOT_TILES`] (the runtime keeps them all resident).
    pub stored_levels: u8,
    /// Seed of the grass noise.
    pub seed: u64,
    /// Replace the world (`world.toml` and `tiles/`) in `out` if `out` exists and is not empty
    /// (otherwise such a folder is refused).
    pub replace: bool,
    /// With `replace`: write the baked manifest alone. Without it, the replaced `world.toml`'s
    /// plant types and its camera paths of names the bake does not write are kept (see
    /// [`Carried`]).
    pub fresh_manifest: bool,
    /// A land-cover map and the table of what grows on its classes (a file, or a built-in
    /// table's name): see [`cover`]. `None`: the procedural rule paints everywhere.
    pub land_cover: Option<(PathBuf, PathBuf)>,
    /// A density map (0 to 1) that scales the painted grass cover: see [`cover::ValueMap`].
    pub density_map: Option<PathBuf>,
    /// A mask: nothing grows where it is not 0 (roads, paths, yards).
    pub mask: Option<PathBuf>,
    /// Stops the bake when set (checked between rows and between tiles): the bake then fails
    /// with [`WorldError::Cancelled`], removes its staging folder and leaves `out` as it was.
    pub cancel: Option<CancelFlag>,
    /// One shard of a sharded bake, or its finish (see [`shard`]); `None`: the whole bake.
    pub shard: Option<ShardStep>,
    /// The most memory the bake may hold, MiB (see [`plan`]); the result does not depend on
    /// it, except for the camera paths and the derivation's calibration of worlds too large
    /// to hold whole.
    pub memory_mib: u64,
}
impl Default for BakeOptions {
    fn default() -> Self {
        BakeOptions {
            dem: PathBuf::new(),
            more_dems: Vec::new(),
            dem_cell_size_m: None,
            out: PathBuf::new(),
            name: None,
            cell_size_m: None,
            tile_cells: 128,
            stored_levels: 3,
            seed: 1,
            replace: false,
            fresh_manifest: false,
            land_cover: None,
            density_map: None,
            mask: None,
            cancel: None,
            shard: None,
            memory_mib: plan::DEFAULT_MEMORY_MIB,
        }
    }
}

/// The stages of a bake, reported to the progress callback.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum BakeStage {
    /// Reading the DEM (total 1).
    LoadDem,
    /// Surveying the finest grid: the DEM resampled square by square for the height range, the
    /// calibration and the coarse subsample (total = squares).
    Resample,
    /// Painting grass type and density on the coarse subsample (total = its rows); the blocks
    /// are painted as their tiles are written.
    Paint,
    /// Computing camera paths (total = paths).
    Paths,
    /// Writing tiles (total = stored tiles).
    WriteTiles,
    /// Writing `world.toml` (total 1).
    WriteManifest,
}

/// What a bake did.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BakeReport {
    /// Tiles written (each is three files, four with materials).
    pub tiles_written: u64,
    /// Stored levels.
    pub levels: u8,
    /// Extent of the data area, metres.
    pub extent_m: [f64; 2],
    /// Lowest and highest stored height, metres.
    pub height_range_m: [f32; 2],
    /// Wall-clock time of the bake.
    pub seconds: f64,
    /// The DEM's format.
    pub dem_format: DemFormat,
    /// The DEM's samples (west-east, south-north).
    pub dem_samples: [u32; 2],
    /// The DEM's cell size in metres (east-west, north-south).
    pub dem_cell_size_m: [f64; 2],
    /// Nodata samples of the DEM filled from the heights around them.
    pub nodata_filled: u64,
    /// A shard that was already done (its record matched): nothing was run again.
    #[serde(default)]
    pub already_done: bool,
    /// The densest grass of the finest tiles this bake wrote (the manifest's `grass_peak`).
    #[serde(default)]
    pub grass_peak: f32,
    /// The memory limit the bake was planned for, MiB.
    #[serde(default)]
    pub memory_limit_mib: u64,
    /// What the plan expected to hold at most, MiB.
    #[serde(default)]
    pub planned_mib: u64,
    /// The process's peak resident memory when the bake ended, MiB (0 where unknown).
    #[serde(default)]
    pub peak_memory_mib: f64,
    /// What was kept of the replaced manifest (nothing for a new world).
    #[serde(default)]
    pub carried: Carried,
    /// What the bake put right before it began, one note each: a bake into the same folder
    /// that was killed while moving its world in (see [`bake`]). Also logged as warnings.
    #[serde(default)]
    pub recovered: Vec<String>,
    /// The id the bake stamped its tiles with (the manifest's `bake_id`).
    #[serde(default)]
    pub bake_id: String,
    /// A DEM read in chunks (a large file, one over HTTP, several joined): the bytes read from
    /// its files, headers among them, and the files' sizes; `None` for a DEM read whole.
    #[serde(default)]
    pub dem_bytes_read: Option<[u64; 2]>,
}

/// Bakes `opts.dem` into a world at `opts.out`. `progress(stage, done, total)` is called as the
/// work goes on; the library prints nothing.
pub fn bake(
    opts: &BakeOptions,
    progress: &mut dyn FnMut(BakeStage, u64, u64),
) -> Result<BakeReport, WorldError> {
    let start = Instant::now();
    let manifest_path = opts.out.join("world.toml");
    check_options(opts)?;
    let out = resolve_out(&opts.out)?;
    // A bake into the same folder that was killed while moving its world in is put right
    // first, so that the folder is judged (and a sharded bake's parts opened) as it was.
    let recovered = publish::remove_stale_staging(&out);
    for note in &recovered {
        log::warn!("{note}");
    }
    check_out(&opts.out, opts.replace)?;
    // The replaced manifest's kept parts are read before hours of baking, not after.
    replaced_manifest(&out, opts)?;
    let dems: Vec<PathBuf> = std::iter::once(opts.dem.clone())
        .chain(opts.more_dems.iter().cloned())
        .collect();
    let files = crate::world::mosaic::dem_files(&dems)?;
    let parts = match opts.shard {
        None => None,
        Some(step) => {
            let parts = shard::Parts::open(&out, step, shard::fingerprint(opts, &files)?)?;
            match step {
                ShardStep::Shard { index, .. } => {
                    if let Some(mut report) = parts.done(index) {
                        report.already_done = true;
                        report.recovered = recovered;
                        return Ok(report);
                    }
                }
                ShardStep::Finish { .. } => {
                    parts.check_all_done()?;
                    // Every shard is done, so no shard writes here now: a temporary of a tile
                    // is a killed or failed shard's, and is not to be published with the tiles.
                    let swept = crate::world::format::sweep_tile_temporaries(
                        &parts.dir.join("tiles"),
                        std::time::Duration::ZERO,
                    );
                    if swept > 0 {
                        log::warn!(
                            "removed {swept} temporar{} of tile files that a shard's write cut \
                             short left in {}",
                            if swept == 1 { "y" } else { "ies" },
                            parts.dir.join("tiles").display()
                        );
                    }
                    // Where no tile crosses shards, the shards' manifest is all the finish
                    // needs: the world is published without being computed again.
                    if let Some(report) = finish_from_parts(&parts, &out, opts, step.count())? {
                        return Ok(BakeReport {
                            recovered,
                            ..report
                        });
                    }
                }
            }
            Some((step, parts))
        }
    };
    let cancelled = || {
        let stop = opts.cancel.as_ref().is_some_and(CancelFlag::is_cancelled);
        if stop {
            Err(WorldError::Cancelled {
                path: opts.out.clone(),
            })
        } else {
            Ok(())
        }
    };

    progress(BakeStage::LoadDem, 0, 1);
    let source = DemSource::open(
        &files,
        &opts.dem,
        &DemOptions {
            cell_size_m: opts.dem_cell_size_m,
        },
        opts.memory_mib,
    )?;
    progress(BakeStage::LoadDem, 1, 1);
    if let DemSource::Whole(dem) = &source {
        check_dem_heights(dem, &opts.dem)?;
    }
    let dem = source.header();
    cancelled()?;

    let cell = match opts.cell_size_m {
        Some(c) => c,
        None => nice_cell_size(dem.cell_ew_m.min(dem.cell_ns_m)),
    };
    check_cell_size(dem, opts, cell)?;

    // Millimetres are plenty, and keep the manifest free of float noise.
    let extent = dem.extent_m().map(|e| round_to(e, 3));
    let levels = match opts.stored_levels {
        0 => auto_levels(extent, cell, opts.tile_cells),
        n => n,
    };
    let finest = levels - 1;
    let root_size = cell * f64::from(opts.tile_cells) * 2f64.powi(i32::from(finest));
    let root_tiles =
        extent.map(|e| ((e / root_size).ceil().max(1.0)).min(f64::from(u32::MAX)) as u32);
    let pyramid = Pyramid {
        root_tile_size_m: root_size,
        root_tiles,
        tile_cells: opts.tile_cells,
        border: BAKE_BORDER,
        stored_levels: levels,
        derived_levels: derived_levels_for(cell * f64::from(opts.tile_cells), levels),
    };
    let name = opts
        .name
        .clone()
        .unwrap_or_else(|| default_name(&out, &opts.dem));
    // Checked again before anything is published: inputs that change during the bake refuse it.
    let inputs_at_start = shard::input_record(opts, &files)?;
    let bake_id = shard::bake_id_of(&inputs_at_start);
    let mut manifest = Manifest {
        name,
        description: description(dem, &opts.dem, cell),
        extent_m: extent,
        pyramid,
        height_range_m: [0.0, 1.0],
        grass_types: default_grass_types(),
        wind: WindDefaults::default(),
        sky: Sky::default(),
        paths: Vec::new(),
        wind_scenes: Vec::new(),
        features: Default::default(),
        source: Some(WorldSource {
            file: dems
                .iter()
                .map(|p| file_name(p))
                .collect::<Vec<_>>()
                .join(", "),
            format: dem.format,
            crs: without_control_characters(&dem.crs),
            origin: dem.origin,
            samples: [dem.width, dem.height],
            cell_size_m: [dem.cell_ew_m, dem.cell_ns_m],
            nodata_filled: dem.nodata_filled,
            land_cover: opts
                .land_cover
                .as_ref()
                .map(|(map, _)| file_name(map))
                .unwrap_or_default(),
            cover_table: String::new(),
            density_map: opts
                .density_map
                .as_deref()
                .map(file_name)
                .unwrap_or_default(),
            mask: opts.mask.as_deref().map(file_name).unwrap_or_default(),
        }),
        derive: None,
        grass_peak: None,
        plant_types: Vec::new(),
        materials: false,
        bake_id: Some(bake_id),
    };
    // Refuse absurd sizes before allocating anything, naming the options that made them: the
    // manifest is not written yet, so its fields would name nothing the user gave.
    manifest.validate(&manifest_path).map_err(|e| {
        let options = match opts.cell_size_m {
            Some(_) => "--cell-size, --tile-cells and --levels",
            None => "the DEM's cell (or --cell-size), --tile-cells and --levels",
        };
        let given = format!(
            "{} m, {}, {}",
            crate::world::error::short_number(cell),
            opts.tile_cells,
            levels
        );
        match e {
            // The finest tiles too wide (too narrow is refused by `check_cell_size`): said in
            // the options' terms, not the manifest's.
            WorldError::OutOfRange { field, .. } if field == "pyramid.derived_levels" => {
                use crate::world::manifest::MAX_GRASS_TILE_M;
                WorldError::bad_option(
                    options,
                    given,
                    format!(
                        "such that the finest tiles, where the grass grows, are \
                         {MIN_GRASS_TILE_M} to {MAX_GRASS_TILE_M} m wide: the finest stored \
                         level's tiles are {} m (the cell x the tile's cells), and the at most \
                         {} derived levels below them halve that only to {} m (a smaller cell, \
                         or fewer cells a tile or stored levels)",
                        crate::world::error::short_number(cell * f64::from(opts.tile_cells)),
                        24 - u32::from(levels),
                        crate::world::error::short_number(
                            cell * f64::from(opts.tile_cells) / 2f64.powi(24 - i32::from(levels))
                        ),
                    ),
                )
            }
            WorldError::OutOfRange { field, allowed, .. } if field.starts_with("pyramid.") => {
                WorldError::bad_option(
                    options,
                    given,
                    format!(
                        "such that the world's {} (the cell x the tile's cells x 2^(levels - \
                         1): {} m for the root tile) is {allowed}",
                        field.trim_start_matches("pyramid."),
                        crate::world::error::short_number(root_size)
                    ),
                )
            }
            // A root tile beyond f64's range: as much too large as any other.
            WorldError::NonFinite { field, .. } if field.starts_with("pyramid.") => {
                WorldError::bad_option(
                    options,
                    given,
                    format!(
                        "such that the world's {} (the cell x the tile's cells x 2^(levels - \
                         1)) is a number at most {} m: these make it {}",
                        field.trim_start_matches("pyramid."),
                        crate::world::error::short_number(crate::world::manifest::MAX_ROOT_TILE_M),
                        crate::world::error::short_number(root_size)
                    ),
                )
            }
            WorldError::TooManyTiles { count, max, .. } => WorldError::bad_option(
                options,
                given,
                format!(
                    "such that the finest stored level has at most {max} tiles ({count} with \
                     these; fewer levels or more cells a tile)"
                ),
            ),
            e => e,
        }
    })?;
    let cover = match &opts.land_cover {
        None => None,
        Some((map, table_path)) => {
            let table = cover::CoverTable::load(table_path)?;
            let map = cover::CoverMap::load(map, dem, &table, table_path, &manifest.grass_types)?;
            if let Some(s) = &mut manifest.source {
                s.cover_table = without_control_characters(&format!(
                    "{} ({})",
                    table.name,
                    file_name(table_path)
                ));
            }
            Some(map)
        }
    };
    let density = match &opts.density_map {
        Some(p) => Some(cover::ValueMap::density(p, dem)?),
        None => None,
    };
    let mask = match &opts.mask {
        Some(p) => Some(cover::ValueMap::mask(p, dem)?),
        None => None,
    };
    if let Some((ShardStep::Finish { .. }, parts)) = &parts {
        // Before the survey: a finish that cannot publish fails at once.
        // The shards' tiles are read before the survey has the height range and the cover its
        // grass types: any plausible height and type pass here, the stamp and the rest are
        // checked.
        let options = crate::world::format::ReadOptions {
            height_range_m: crate::world::PLAUSIBLE_HEIGHTS_M.map(|h| h as f32),
            grass_type_count: 256,
            materials: cover.as_ref().is_some_and(|c| c.has_materials()),
            bake_id: manifest.bake_id_value(),
        };
        parts.check_tiles(&manifest.pyramid, &options)?;
    }
    cancelled()?;

    let data_samples = extent
        .iter()
        .map(|e| (e / cell).floor() as u64 + 1)
        .product::<u64>();
    // The maps' windows, held to the end, and the most that reading one of them took (a
    // chunk of a GeoTIFF, a PNG whole): the peak before the plan, counted in it so that a
    // map that needs more than the limit is refused by it.
    let values = || [&density, &mask].into_iter().flatten();
    let map_bytes = cover.as_ref().map_or(0, cover::CoverMap::held_bytes)
        + values().map(cover::ValueMap::held_bytes).sum::<u64>()
        + cover
            .as_ref()
            .map(cover::CoverMap::read_bytes)
            .into_iter()
            .chain(values().map(cover::ValueMap::read_bytes))
            .max()
            .unwrap_or(0);
    let plan = Plan::new(
        opts.memory_mib,
        &manifest.pyramid,
        &source,
        map_bytes,
        data_samples,
    )?;
    source.set_cache(plan.cached);
    let survey = survey::survey(
        &source,
        &plan,
        extent,
        manifest.pyramid.derived_levels,
        &cancelled,
        progress,
    )?;
    let height_range = survey.height_range;
    manifest.height_range_m = height_range;
    manifest.derive = Some(survey.calibration);
    if let Some(s) = &mut manifest.source {
        s.nodata_filled = source.nodata_filled();
    }
    cancelled()?;

    let maps = paint::PaintMaps {
        cover: cover.as_ref(),
        density: density.as_ref(),
        mask: mask.as_ref(),
    };
    let slopes = survey.slopes;
    let mut painted = survey.coarse.paint(
        height_range,
        opts.seed,
        &maps,
        &|g, a, b| slopes[b * g.width + a],
        &cancelled,
        progress,
    )?;
    drop(slopes);
    painted.cancel = opts.cancel.clone();
    check_painted_types(&painted, &manifest, &manifest_path)?;
    manifest.materials = maps.cover.is_some_and(|c| c.has_materials());
    progress(BakeStage::Paths, 0, 2);
    let overview = overview_path(&painted, extent);
    progress(BakeStage::Paths, 1, 2);
    let low = low_path(&painted, extent);
    let meadow = meadow_path(&painted, extent);
    let tour = tour_path(&painted, extent);
    let helicopter = helicopter_path(&painted, extent);
    let (wind_tour, walker) = wind_tour_paths(&painted, extent);
    cancelled()?;
    progress(BakeStage::Paths, 2, 2);
    manifest.paths = vec![tour, overview, low, meadow, helicopter, wind_tour, walker];
    manifest.wind_scenes = default_wind_scenes();
    manifest.grass_peak = Some(grass_peak(&manifest.pyramid, 0.0));
    manifest.validate(&manifest_path)?;
    // What --replace keeps of the old manifest must fit this world: found out now, before the
    // tiles, and again when the manifest is written (a shard writes none).
    if !matches!(opts.shard, Some(ShardStep::Shard { .. })) {
        manifest_text(&manifest, &out, opts)?;
    }
    cancelled()?;

    let nodata_filled = source.nodata_filled();
    let (dem_format, dem_samples) = (dem.format, [dem.width, dem.height]);
    let dem_cell_size_m = [dem.cell_ew_m, dem.cell_ns_m];
    let report = |tiles_written, peak| BakeReport {
        tiles_written,
        levels,
        extent_m: extent,
        height_range_m: height_range,
        seconds: start.elapsed().as_secs_f64(),
        dem_format,
        dem_samples,
        dem_cell_size_m,
        nodata_filled,
        already_done: false,
        grass_peak: peak,
        memory_limit_mib: opts.memory_mib,
        planned_mib: plan.peak_bytes.div_ceil(1 << 20),
        peak_memory_mib: peak_memory_mib(),
        carried: Carried::default(),
        recovered: recovered.clone(),
        bake_id: manifest.bake_id.clone().unwrap_or_default(),
        dem_bytes_read: source.bytes_read(),
    };
    let paint_inputs = tiles::BlockPaint {
        height_range,
        seed: opts.seed,
        maps: &maps,
    };
    let producer = tiles::Producer {
        out: &out,
        pyramid: &manifest.pyramid.clone(),
        dem: &source,
        plan: &plan,
        coarse: &painted,
        paint: &paint_inputs,
        manifest: &manifest,
    };
    // A sharded bake: a shard writes its share into the parts folder and records it; the
    // finish writes the tiles that cross shards there and publishes them with the manifest.
    let pyramid = &manifest.pyramid;
    // The fingerprint record of the parts folder whose tiles a finish publishes: they stay
    // there until the publish moves them into the output folder, so that a finish that fails
    // or is stopped before then leaves them for the next.
    let mut from_parts = None;
    let mut peak = 0f32;
    if let Some((step, parts)) = &parts {
        let share = |want: Option<u32>| -> Vec<crate::world::tile::TileId> {
            tiles::stored_tiles(pyramid)
                .into_iter()
                .filter(|&id| shard::owner(pyramid, step.count(), id) == want)
                .collect()
        };
        let producer = tiles::Producer {
            out: &parts.dir,
            ..producer
        };
        parts.claim()?;
        match *step {
            ShardStep::Shard { index, .. } => {
                let (n, peak) = produce(&producer, share(Some(index)), &cancelled, progress)?;
                let mut manifest = manifest.clone();
                manifest.grass_peak = Some(grass_peak(pyramid, peak));
                write_atomic(&parts.dir.join("world.toml"), manifest.to_toml().as_bytes())?;
                let report = report(n, peak);
                shard::check_inputs_unchanged(opts, &files, &inputs_at_start)?;
                parts.mark_done(index, &report)?;
                return Ok(report);
            }
            ShardStep::Finish { count } => {
                let (_, own) = produce(&producer, share(None), &cancelled, progress)?;
                peak = (0..count)
                    .filter_map(|i| parts.done(i))
                    .fold(own, |p, r| p.max(r.grass_peak));
                from_parts = Some(parts.record());
            }
        }
    }

    let staging = Staging::begin(&out, &opts.out, opts.replace)?;
    let tiles_written = match &from_parts {
        Some(_) => tiles::stored_tiles(pyramid).len() as u64,
        None => {
            let producer = tiles::Producer {
                out: staging.world(),
                ..producer
            };
            let (n, p) = produce(
                &producer,
                tiles::stored_tiles(pyramid),
                &cancelled,
                progress,
            )?;
            peak = p;
            n
        }
    };
    manifest.grass_peak = Some(grass_peak(pyramid, peak));

    progress(BakeStage::WriteManifest, 0, 1);
    let (text, carried) = manifest_text(&manifest, &out, opts)?;
    write_atomic(&staging.world().join("world.toml"), text.as_bytes())?;
    // The last chance to stop: once the world is being moved into place, it is finished.
    cancelled()?;
    shard::check_inputs_unchanged(opts, &files, &inputs_at_start)?;
    // The world goes out; a sharded bake's parts are then spent, and removed.
    staging.publish(from_parts.as_deref())?;
    progress(BakeStage::WriteManifest, 1, 1);
    Ok(BakeReport {
        carried,
        ..report(tiles_written, peak)
    })
}

/// The manifest to publish into `out` (resolved): `manifest`, and with `--replace` (unless
/// `--fresh-manifest`) what the replaced `world.toml` keeps ([`carry::carry`]); it is named in
/// errors as the user spelled `--out`.
fn manifest_text(
    manifest: &Manifest,
    out: &Path,
    opts: &BakeOptions,
) -> Result<(String, Carried), WorldError> {
    let text = manifest.to_toml();
    match replaced_manifest(out, opts)? {
        None => Ok((text, Carried::default())),
        Some(old_text) => carry::carry(&text, &old_text, &opts.out.join("world.toml")),
    }
}

/// The text of the `world.toml` that a bake with `--replace` (and without `--fresh-manifest`)
/// replaces in `out` (resolved) and keeps parts of; `None` where it keeps none. Its kept parts
/// are read here too, so that a manifest that cannot give them is refused before the bake
/// starts rather than when it ends.
fn replaced_manifest(out: &Path, opts: &BakeOptions) -> Result<Option<String>, WorldError> {
    let old = out.join("world.toml");
    if !opts.replace || opts.fresh_manifest || std::fs::symlink_metadata(&old).is_err() {
        return Ok(None);
    }
    let shown = opts.out.join("world.toml");
    let refuse = |e: WorldError| WorldError::Carry {
        path: shown.clone(),
        kept: String::new(),
        source: Box::new(e),
    };
    let bytes =
        crate::world::format::read_regular(&shown, crate::world::manifest::MAX_MANIFEST_BYTES)
            .map_err(refuse)?;
    let old_text = String::from_utf8(bytes).map_err(|e| {
        refuse(WorldError::ManifestSyntax {
            path: shown.clone(),
            message: format!("not UTF-8 text: {e}"),
        })
    })?;
    carry::kept_parts(&old_text, &shown).map_err(refuse)?;
    Ok(Some(old_text))
}

/// The manifest's record of the densest grass, `density` over windows of the finest grass
/// tiles (`Pyramid::max_level`).
fn grass_peak(pyramid: &Pyramid, density: f32) -> crate::world::GrassPeak {
    crate::world::GrassPeak {
        window_m: pyramid.tile_size_m(pyramid.max_level()),
        short_m: crate::world::grass_density::SHORT_GRASS_M,
        density,
    }
}

/// Starts up to `threads` workers on `scope`, each running the closure `make` gives it: as many
/// as the system lets start, at least one, or the error of the first that could not.
fn spawn_workers<'scope, F>(
    scope: &'scope std::thread::Scope<'scope, '_>,
    threads: usize,
    mut make: impl FnMut() -> F,
) -> Result<usize, WorldError>
where
    F: FnOnce() + Send + 'scope,
{
    let mut started = 0;
    for k in 0..threads.max(1) {
        match std::thread::Builder::new()
            .name(format!("bake-{k}"))
            .spawn_scoped(scope, make())
        {
            Ok(_) => started += 1,
            Err(_) if started > 0 => break,
            Err(source) => return Err(WorldError::Threads { source }),
        }
    }
    Ok(started)
}

/// The process's peak resident memory so far, MiB (Linux's `VmHWM`; 0 where unknown).
pub fn peak_memory_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("VmHWM:"))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<f64>().ok())
        })
        .map_or(0.0, |kb| kb / 1024.0)
}

/// The finish of a sharded bake whose tiles all belong to shards: the manifest the shards wrote
/// into the parts folder is published with their tiles, nothing computed again. `None` where
/// tiles cross shards (or the parts hold no manifest): the finish then bakes them.
fn finish_from_parts(
    parts: &shard::Parts,
    out: &Path,
    opts: &BakeOptions,
    count: u32,
) -> Result<Option<BakeReport>, WorldError> {
    let path = parts.dir.join("world.toml");
    let Ok(text) = std::fs::read_to_string(&path) else {
        return Ok(None);
    };
    let mut manifest = Manifest::parse(&text, &path)?;
    let pyramid = &manifest.pyramid.clone();
    let all = tiles::stored_tiles(pyramid);
    if all
        .iter()
        .any(|&id| shard::owner(pyramid, count, id).is_none())
    {
        return Ok(None);
    }
    let Some(mut report) = parts.done(0) else {
        return Ok(None);
    };
    // Each shard knows the densest grass of its own tiles only.
    let peak = (0..count)
        .filter_map(|i| parts.done(i))
        .fold(0f32, |p, r| p.max(r.grass_peak));
    manifest.grass_peak = Some(grass_peak(pyramid, peak));
    let options = crate::world::format::ReadOptions {
        height_range_m: manifest.height_range_m,
        grass_type_count: manifest.grass_types.len(),
        materials: manifest.materials,
        bake_id: manifest.bake_id_value(),
    };
    parts.check_tiles(pyramid, &options)?;
    let start = Instant::now();
    let staging = Staging::begin(out, &opts.out, opts.replace)?;
    let (text, carried) = manifest_text(&manifest, out, opts)?;
    write_atomic(&staging.world().join("world.toml"), text.as_bytes())?;
    // The shards' tiles go straight from the parts folder into the output folder, and the
    // parts folder is removed once they are in.
    staging.publish(Some(&parts.record()))?;
    report.tiles_written = all.len() as u64;
    report.seconds = start.elapsed().as_secs_f64();
    report.grass_peak = peak;
    report.peak_memory_mib = peak_memory_mib();
    report.carried = carried;
    Ok(Some(report))
}

/// Most level-0 tiles a bake that chooses its levels ([`BakeOptions::stored_levels`] 0) leaves.
pub const MAX_AUTO_ROOT_TILES: u64 = 64;

/// The fewest stored levels, at least 3 and at most 12, that leave a world of `extent` metres
/// at `cell` metres and `tile_cells` cells a tile at most [`MAX_AUTO_ROOT_TILES`] level-0 tiles.
pub fn auto_levels(extent: [f64; 2], cell: f64, tile_cells: u32) -> u8 {
    (3..=12u8)
        .find(|&levels| {
            let root = cell * f64::from(tile_cells) * 2f64.powi(i32::from(levels) - 1);
            let n = extent.map(|e| (e / root).ceil().max(1.0));
            n[0] * n[1] <= MAX_AUTO_ROOT_TILES as f64
        })
        .unwrap_or(12)
}

/// Rounds a cell size to 1, 2, 2.5 or 5 times a power of ten, whichever is nearest in ratio.
pub fn nice_cell_size(c: f64) -> f64 {
    if !(c.is_finite() && c > 0.0) {
        return c;
    }
    let base = 10f64.powf(c.log10().floor());
    [1.0, 2.0, 2.5, 5.0, 10.0]
        .map(|m| m * base)
        .into_iter()
        .min_by(|a, b| (a / c).ln().abs().total_cmp(&(b / c).ln().abs()))
        .unwrap_or(c)
}

/// The name of the (resolved) output folder, else the DEM's stem; its control characters
/// replaced by U+FFFD.
fn default_name(out: &Path, dem: &Path) -> String {
    out.file_name()
        .or_else(|| dem.file_stem())
        .map(|n| without_control_characters(&n.to_string_lossy()))
        .unwrap_or_else(|| "world".into())
}

/// The file name of `path` as the manifest records it: its control characters replaced by
/// U+FFFD (a file's name is no fault of the user's, and must not reach a terminal raw).
fn file_name(path: &Path) -> String {
    // An address's query (a signed URL's token) and fragment are not written into the manifest.
    without_control_characters(&crate::world::window::file_name_of(path))
}

/// The manifest's description of a baked world: the sidecar's `place`, the DEM and the cell
/// size, the nodata filled and the sidecar's `source`; its control characters (from a file's
/// name or its sidecar) replaced by U+FFFD.
fn description(dem: &Dem, dem_path: &Path, cell: f64) -> String {
    let file = file_name(dem_path);
    let mut text = String::new();
    if !dem.place.is_empty() {
        text.push_str(dem.place.trim_end_matches('.'));
        text.push_str(". ");
    }
    text.push_str(&format!(
        "Baked from {file} ({}, {}x{} samples of {} m x {} m) at {cell} m cells.",
        dem.format.name(),
        dem.width,
        dem.height,
        round_to(dem.cell_ew_m, 3),
        round_to(dem.cell_ns_m, 3)
    ));
    if dem.nodata_filled > 0 {
        text.push_str(&format!(
            " {} nodata samples filled from the heights around them.",
            dem.nodata_filled
        ));
    }
    if !dem.source.is_empty() {
        text.push(' ');
        text.push_str(&dem.source);
    }
    without_control_characters(&text)
}
/// `v` rounded to `decimals` places, as the f64 nearest that decimal (so it prints short).
pub(super) fn round_to(v: f64, decimals: usize) -> f64 {
    format!("{v:.decimals$}").parse().unwrap_or(v)
}

/// Refuses bake options out of range before anything is read, naming the option.
fn check_options(opts: &BakeOptions) -> Result<(), WorldError> {
    if let Some(step) = opts.shard {
        step.check()?;
    }
    let t = opts.tile_cells;
    if !(8..=1024).contains(&t) || !t.is_power_of_two() {
        return Err(WorldError::bad_option(
            "--tile-cells",
            t,
            "a power of two in 8..=1024".into(),
        ));
    }
    if !(0..=12).contains(&opts.stored_levels) {
        return Err(WorldError::bad_option(
            "--levels",
            opts.stored_levels,
            "in 1..=12 (0: as many as the world needs)".into(),
        ));
    }
    if let Some(name) = &opts.name
        && let Some(c) = name.chars().find(|&c| forbidden_control(c))
    {
        return Err(WorldError::bad_option(
            "--name",
            format!("{name:?}"),
            format!(
                "a name without control characters (U+{:04X} here; tabs and line breaks \
                 aside): a world's name is printed to terminals and window titles",
                u32::from(c)
            ),
        ));
    }
    if let Some(name) = &opts.name
        && name.trim().is_empty()
    {
        return Err(WorldError::bad_option(
            "--name",
            format!("{name:?}"),
            "a name, not empty: a world's name is printed in lines and window titles (leave \
             --name out for the output folder's name)"
                .into(),
        ));
    }
    if let Some(name) = &opts.name
        && name.chars().count() > crate::world::manifest::MAX_NAME_CHARS
    {
        return Err(WorldError::bad_option(
            "--name",
            format!("of {} characters", name.chars().count()),
            format!(
                "a name of at most {} characters: a world's name is printed in lines and \
                 window titles",
                crate::world::manifest::MAX_NAME_CHARS
            ),
        ));
    }
    if let Some(c) = opts.cell_size_m {
        if !(c.is_finite() && c > 0.0) {
            return Err(WorldError::bad_option(
                "--cell-size",
                given_number(c),
                "a positive number of metres".into(),
            ));
        }
        if c < min_bake_cell_m(t) {
            // More cells a tile make tiles of this cell wide enough, where there are such.
            let tiles = (MIN_GRASS_TILE_M / c).log2().ceil().exp2();
            let hint = if c >= MIN_BAKE_CELL_M && tiles <= 1024.0 {
                format!(", or pass --tile-cells {tiles} or more")
            } else {
                String::new()
            };
            return Err(WorldError::bad_option(
                "--cell-size",
                given_number(c),
                format!("{}{hint}", least_cell_words(t)),
            ));
        }
    }
    Ok(())
}

/// A number as given, in full, unless that takes more than 16 characters (`1e-300`, not 300
/// zeros).
fn given_number(v: f64) -> String {
    let s = v.to_string();
    if s.len() > 16 { format!("{v:e}") } else { s }
}

/// Smallest cell a bake of `tile_cells` cells a tile resamples to: at least
/// [`MIN_BAKE_CELL_M`], and such that the finest stored tiles are at least
/// [`MIN_GRASS_TILE_M`] wide (derived levels only halve them, and are left out where they
/// would make them narrower).
pub fn min_bake_cell_m(tile_cells: u32) -> f64 {
    (MIN_GRASS_TILE_M / f64::from(tile_cells)).max(MIN_BAKE_CELL_M)
}

/// [`min_bake_cell_m`] in words, why included.
fn least_cell_words(tile_cells: u32) -> String {
    let least = min_bake_cell_m(tile_cells);
    if least > MIN_BAKE_CELL_M {
        // Exact: 0.5 over a power of two prints in full.
        format!(
            "at least {least} m with --tile-cells {tile_cells} (0.5 m / {tile_cells}: the finest \
             tiles, where the grass grows, must be at least {MIN_GRASS_TILE_M} m wide, and none \
             is narrower than a stored tile of {tile_cells} cells)"
        )
    } else {
        format!("at least {least} m (a bake resamples to at least 1 mm cells)")
    }
}

/// Smallest cell a bake resamples to, metres.
pub const MIN_BAKE_CELL_M: f64 = 1e-3;

/// Most cells a side a bake resamples the DEM to.
pub const MAX_BAKE_CELLS: f64 = 65_536.0;

/// Refuses a cell size (given, or the DEM's own) below [`min_bake_cell_m`] or resampling the
/// DEM to more than [`MAX_BAKE_CELLS`] a side, naming the option it came from (`--cell-size`, or
/// `--dem-cell-size` for the DEM's own) or else the sidecar's field. Where the cell is the
/// DEM's own and too many cells span the DEM, the DEM's cells may each be large enough: the
/// bake's cell is the smaller of them, and the extent comes from the larger; the error then
/// says so.
fn check_cell_size(dem: &Dem, opts: &BakeOptions, cell: f64) -> Result<(), WorldError> {
    use crate::world::error::short_number;
    let dem_path = opts.dem.as_path();
    let extent = dem.extent_m();
    let cells = extent[0].max(extent[1]) / cell;
    let floor = min_bake_cell_m(opts.tile_cells);
    let least = (extent[0].max(extent[1]) / MAX_BAKE_CELLS).max(floor);
    if cell >= floor && cells <= MAX_BAKE_CELLS {
        return Ok(());
    }
    let allowed = if cell < floor {
        // The DEM's own cell (a --cell-size this small was refused with the options).
        format!(
            "{}: the bake's cell, the DEM's smaller cell rounded, would be {} m; pass \
             --cell-size {least} or more",
            least_cell_words(opts.tile_cells),
            short_number(cell)
        )
    } else if opts.cell_size_m.is_none() {
        format!(
            "cells over which the DEM spans at most {MAX_BAKE_CELLS} of the bake's cells a \
             side: its {}x{} samples span {} x {} m, {} cells of {} m (the smaller cell, \
             rounded); correct them, or pass --cell-size {} or more",
            dem.width,
            dem.height,
            short_number(extent[0]),
            short_number(extent[1]),
            short_number(cells),
            short_number(cell),
            short_number(least)
        )
    } else {
        format!(
            "at least {} m for this DEM ({}x{} samples, {} x {} m; a bake resamples to at most \
             {MAX_BAKE_CELLS} cells a side)",
            short_number(least),
            dem.width,
            dem.height,
            short_number(extent[0]),
            short_number(extent[1])
        )
    };
    let cells = |[ew, ns]: [f64; 2]| format!("{} x {}", short_number(ew), short_number(ns));
    match (opts.cell_size_m, opts.dem_cell_size_m) {
        (Some(c), _) => Err(WorldError::bad_option(
            "--cell-size",
            given_number(c),
            allowed,
        )),
        // The DEM's cells came from the option, not from the file or its sidecar.
        (None, Some(given)) => Err(WorldError::bad_option(
            "--dem-cell-size",
            cells(given),
            allowed,
        )),
        (None, None) => Err(WorldError::OutOfRange {
            path: crate::world::dem::sidecar_of(dem_path).unwrap_or_else(|| dem_path.to_path_buf()),
            field: match crate::world::dem::sidecar_of(dem_path) {
                Some(_) => "cell_size_m".into(),
                None => "its cells".into(),
            },
            value: cells([dem.cell_ew_m, dem.cell_ns_m]),
            allowed,
        }),
    }
}

/// Refuses a DEM whose heights leave [`crate::world::PLAUSIBLE_HEIGHTS_M`] (a wrong offset or scale in
/// its sidecar), naming the sidecar.
pub(crate) fn check_dem_heights(dem: &Dem, dem_path: &Path) -> Result<(), WorldError> {
    let [lo, hi] = crate::world::PLAUSIBLE_HEIGHTS_M;
    let bad = dem.heights.iter().position(|&h| {
        let h = f64::from(h);
        !(lo..=hi).contains(&h)
    });
    match bad {
        None => Ok(()),
        Some(k) => Err(WorldError::ImplausibleHeight {
            path: crate::world::dem::sidecar_of(dem_path).unwrap_or_else(|| dem_path.to_path_buf()),
            dem: dem_path.to_path_buf(),
            column: k as u32 % dem.width,
            row: k as u32 / dem.width,
            value: f64::from(dem.heights[k]),
            range: crate::world::PLAUSIBLE_HEIGHTS_M,
        }),
    }
}
