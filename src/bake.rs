//! The baker: turns a DEM ([`Dem`]) into a world: a pyramid of stored tiles and `world.toml`.
//!
//! 0. The DEM is read ([`Dem::load_with`]: GeoTIFF, SRTM `.hgt` or PNG + sidecar, told apart
//!    by content) and its nodata samples are filled from the valid heights around them.
//! 1. The DEM is resampled (Catmull-Rom bicubic in its own, non-square grid) to square cells at
//!    the finest stored level, over the whole root grid plus a margin for the tile borders of
//!    every level. Beyond the DEM the height of the nearest edge point is repeated.
//! 2. Grass type and density are painted on that grid from slope, altitude and value noise
//!    seeded by [`BakeOptions::seed`]: no grass where the slope exceeds 35 degrees, lush meadow
//!    and tall grass low down, dry grass high up and on dry (noise) ground.
//! 3. Coarser levels are point samples of the finest grid: the sample at level `L` is the
//!    sample at the same position at level `L + 1` (every other one). Coarse and fine tiles
//!    therefore agree exactly where their samples coincide, so a fine tile morphed to its
//!    parent's resolution meets the parent without cracks, and children derived from a parent
//!    start from the parent's own values.
//! 4. Every tile of every stored level is cut from that one global grid (borders included), so
//!    neighbours share identical edge and border samples, and written through temporary files.
//! 5. Seven camera paths are computed from the terrain ("tour", the default, "overview", "low",
//!    "meadow", "helicopter", and "wind-tour" with its "walker"), four wind scenes are added
//!    ("calm", "breeze", "storm" and "helicopter", see [`default_wind_scenes`]; the wind tour
//!    shows them in turn), and `world.toml` is written last, so a world with a manifest is a
//!    complete world.
//!
//! The bake is deterministic: the same DEM, options and seed give byte-identical files.
//!
//! The world is written into a staging folder beside the output folder (`.NAME.baking.*`,
//! never inside it) and moved into place at the end; a bake that fails or is cancelled
//! ([`BakeOptions::cancel`]) removes it and leaves the output folder as it was. A bake holds
//! an OS lock on a file in its staging folder while it runs, so that the next bake beside the
//! same output folder removes the staging folders of bakes that were killed (whose lock is
//! free) and leaves those of running bakes alone.

use std::path::{Component, Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant, SystemTime};

use glam::DVec2;

use crate::stream::{DeriveParams, HeightField, calibrate};
use crate::world::dem::{Dem, DemFormat, DemOptions};
use crate::world::error::WorldError;
use crate::world::format::{TileData, write_atomic, write_tile};
use crate::world::manifest::{
    CameraKey, CameraPath, DEFAULT_WIND_BLEND_S, DeriveCalibration, GrassType, Manifest, Sky,
    WindDefaults, WindKey, WindScene, WindSource, WorldSource,
};
use crate::world::tile::{Pyramid, TileId};

/// Shared samples beyond each tile edge in baked worlds.
pub const BAKE_BORDER: u32 = 2;
/// Levels finer than the stored ones that baked worlds ask the runtime to derive.
pub const BAKE_DERIVED_LEVELS: u8 = 6;
/// Steepest slope that carries grass, degrees.
pub const MAX_GRASS_SLOPE_DEG: f64 = 35.0;
/// Largest finest-level grid the baker will hold in memory, samples.
const MAX_GRID_SAMPLES: u64 = 1 << 30;

/// What to bake, and how.
#[derive(Clone, Debug, PartialEq)]
pub struct BakeOptions {
    /// The DEM: a GeoTIFF, an SRTM `.hgt` tile, or a 16-bit PNG whose sidecar sits beside it
    /// with the extension `.json`.
    pub dem: PathBuf,
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
    /// Stored levels (1..=12).
    pub stored_levels: u8,
    /// Seed of the grass noise.
    pub seed: u64,
    /// Replace the world (`world.toml` and `tiles/`) in `out` if `out` exists and is not empty
    /// (otherwise such a folder is refused).
    pub replace: bool,
    /// Stops the bake when set (checked between rows and between tiles): the bake then fails
    /// with [`WorldError::Cancelled`], removes its staging folder and leaves `out` as it was.
    pub cancel: Option<CancelFlag>,
}

/// A flag that cancels a running bake, from another thread or a signal handler
/// ([`CancelFlag::shared`] gives the atomic to hand to one). Clones share the flag; two flags
/// are equal when they are the same flag.
#[derive(Clone, Debug, Default)]
pub struct CancelFlag(Arc<AtomicBool>);

impl CancelFlag {
    /// A flag that is not set.
    pub fn new() -> Self {
        Self::default()
    }

    /// Asks the bake to stop.
    pub fn cancel(&self) {
        self.0.store(true, Ordering::SeqCst);
    }

    /// Whether the bake was asked to stop.
    pub fn is_cancelled(&self) -> bool {
        self.0.load(Ordering::SeqCst)
    }

    /// The flag itself, for a signal handler to set (e.g. `signal_hook::flag::register`).
    pub fn shared(&self) -> Arc<AtomicBool> {
        Arc::clone(&self.0)
    }

    /// A flag that SIGINT and SIGTERM (Ctrl-C, `kill`) set, for the command line: the first
    /// signal cancels the bake, which then removes its staging folder; a second one ends the
    /// process at once (status 130), and the next bake removes the staging folder it leaves.
    #[cfg(feature = "cli")]
    pub fn on_termination_signals() -> std::io::Result<Self> {
        use signal_hook::consts::{SIGINT, SIGTERM};
        let flag = Self::new();
        for signal in [SIGINT, SIGTERM] {
            // Registered first, so that it sees the flag as the previous signal left it.
            signal_hook::flag::register_conditional_shutdown(signal, 130, flag.shared())?;
            signal_hook::flag::register(signal, flag.shared())?;
        }
        Ok(flag)
    }
}

impl PartialEq for CancelFlag {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }
}

impl Default for BakeOptions {
    fn default() -> Self {
        BakeOptions {
            dem: PathBuf::new(),
            dem_cell_size_m: None,
            out: PathBuf::new(),
            name: None,
            cell_size_m: None,
            tile_cells: 128,
            stored_levels: 3,
            seed: 1,
            replace: false,
            cancel: None,
        }
    }
}

/// The stages of a bake, reported to the progress callback.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum BakeStage {
    /// Reading the DEM (total 1).
    LoadDem,
    /// Resampling the DEM to the finest grid (total = grid rows).
    Resample,
    /// Painting grass type and density (total = grid rows).
    Paint,
    /// Computing camera paths (total = paths).
    Paths,
    /// Writing tiles (total = stored tiles).
    WriteTiles,
    /// Writing `world.toml` (total 1).
    WriteManifest,
}

/// What a bake did.
#[derive(Clone, Debug, PartialEq)]
pub struct BakeReport {
    /// Tiles written (each is three files).
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
    let dem = Dem::load_with(
        &opts.dem,
        &DemOptions {
            cell_size_m: opts.dem_cell_size_m,
        },
    )?;
    progress(BakeStage::LoadDem, 1, 1);
    check_dem_heights(&dem, &opts.dem)?;
    cancelled()?;

    let cell = match opts.cell_size_m {
        Some(c) => c,
        None => nice_cell_size(dem.cell_ew_m.min(dem.cell_ns_m)),
    };
    check_cell_size(&dem, &opts.dem, opts.cell_size_m, cell)?;

    // Millimetres are plenty, and keep the manifest free of float noise.
    let extent = dem.extent_m().map(|e| round_to(e, 3));
    let finest = opts.stored_levels.saturating_sub(1);
    let root_size = cell * f64::from(opts.tile_cells) * 2f64.powi(i32::from(finest));
    let root_tiles =
        extent.map(|e| ((e / root_size).ceil().max(1.0)).min(f64::from(u32::MAX)) as u32);
    let pyramid = Pyramid {
        root_tile_size_m: root_size,
        root_tiles,
        tile_cells: opts.tile_cells,
        border: BAKE_BORDER,
        stored_levels: opts.stored_levels,
        derived_levels: BAKE_DERIVED_LEVELS,
    };
    let name = opts
        .name
        .clone()
        .unwrap_or_else(|| default_name(&out, &opts.dem));
    let mut manifest = Manifest {
        name,
        description: description(&dem, &opts.dem, cell),
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
            file: file_name(&opts.dem),
            format: dem.format,
            crs: dem.crs.clone(),
            origin: dem.origin,
            samples: [dem.width, dem.height],
            cell_size_m: [dem.cell_ew_m, dem.cell_ns_m],
            nodata_filled: dem.nodata_filled,
        }),
        derive: None,
        grass_peak: None,
    };
    // Refuse absurd sizes before allocating anything.
    manifest.validate(&manifest_path)?;

    let grid = Grid::resample(&dem, &manifest.pyramid, &opts.dem, &cancelled, progress)?;
    let height_range = grid.height_range();
    manifest.height_range_m = height_range;
    manifest.derive = Some(grid.calibrate(extent, manifest.pyramid.derived_levels));
    cancelled()?;

    let mut painted = grid.paint(height_range, opts.seed, &cancelled, progress)?;
    painted.cancel = opts.cancel.clone();
    check_painted_types(&painted, &manifest, &manifest_path)?;
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
    manifest.grass_peak = Some(grass_peak(&manifest, &painted));
    manifest.validate(&manifest_path)?;
    cancelled()?;

    let staging = Staging::begin(&out, &opts.out, opts.replace)?;
    let tiles_written = write_all_tiles(
        staging.world(),
        &manifest.pyramid,
        &painted,
        &cancelled,
        progress,
    )?;

    progress(BakeStage::WriteManifest, 0, 1);
    write_atomic(
        &staging.world().join("world.toml"),
        manifest.to_toml().as_bytes(),
    )?;
    // The last chance to stop: once the world is being moved into place, it is finished.
    cancelled()?;
    staging.publish()?;
    progress(BakeStage::WriteManifest, 1, 1);

    Ok(BakeReport {
        tiles_written,
        levels: manifest.pyramid.stored_levels,
        extent_m: extent,
        height_range_m: height_range,
        seconds: start.elapsed().as_secs_f64(),
        dem_format: dem.format,
        dem_samples: [dem.width, dem.height],
        dem_cell_size_m: [dem.cell_ew_m, dem.cell_ns_m],
        nodata_filled: dem.nodata_filled,
    })
}

/// The grass types of a baked world: 0 bare rock, 1 meadow, 2 tall grass, 3 dry grass. The
/// widths are chosen for coverage at the least cost: on an H100 at 1920x1080, doubling them
/// from 2-3.5 cm (meadow) took the meadow's coverage within 30 m from 19% to 33% for 0.4 ms
/// more grass time, where halving the spacing to reach as much would have cost 4 times the
/// blades.
pub fn default_grass_types() -> Vec<GrassType> {
    vec![
        GrassType {
            name: "bare".into(),
            ground_color: [0.30, 0.27, 0.23],
            base_color: [0.30, 0.27, 0.23],
            tip_color: [0.30, 0.27, 0.23],
            height_m: [0.0, 0.0],
            width_m: [0.0, 0.0],
            stiffness: 1.0,
        },
        GrassType {
            name: "meadow".into(),
            ground_color: [0.10, 0.16, 0.05],
            base_color: [0.04, 0.14, 0.02],
            tip_color: [0.22, 0.45, 0.08],
            height_m: [0.15, 0.35],
            width_m: [0.04, 0.07],
            stiffness: 0.6,
        },
        GrassType {
            name: "tall grass".into(),
            ground_color: [0.09, 0.13, 0.05],
            base_color: [0.05, 0.12, 0.02],
            tip_color: [0.32, 0.42, 0.10],
            height_m: [0.5, 1.1],
            width_m: [0.05, 0.09],
            stiffness: 0.35,
        },
        GrassType {
            name: "dry grass".into(),
            ground_color: [0.28, 0.21, 0.10],
            base_color: [0.25, 0.18, 0.06],
            tip_color: [0.70, 0.52, 0.22],
            height_m: [0.25, 0.6],
            width_m: [0.03, 0.06],
            stiffness: 0.5,
        },
    ]
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

/// The name of the (resolved) output folder, else the DEM's stem.
fn default_name(out: &Path, dem: &Path) -> String {
    out.file_name()
        .or_else(|| dem.file_stem())
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "world".into())
}

fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

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
    text
}

/// The finest stored level over the whole root grid, with a margin wide enough for the border
/// samples of every coarser level. Array index `(a, b)` is global sample `(a - margin,
/// b - margin)` at world position `(a - margin, b - margin) * cell`.
struct Grid {
    width: usize,
    height: usize,
    margin: i64,
    cell: f64,
    finest: u8,
    heights: Vec<f32>,
}

/// The finest grid with grass painted on it.
struct Painted {
    grid: Grid,
    grass_type: Vec<u8>,
    density: Vec<u8>,
    /// The bake's cancel flag, which the long searches for camera paths check as they go.
    cancel: Option<CancelFlag>,
}

impl Painted {
    /// Whether the bake was cancelled: a search then ends early, its result unused.
    fn cancelled(&self) -> bool {
        self.cancel.as_ref().is_some_and(CancelFlag::is_cancelled)
    }

    /// Index of the painted sample nearest `p` (metres; clamped to the grid).
    fn index_at(&self, p: DVec2) -> usize {
        let g = &self.grid;
        let a = ((p.x / g.cell).round() as i64 + g.margin).clamp(0, g.width as i64 - 1);
        let b = ((p.y / g.cell).round() as i64 + g.margin).clamp(0, g.height as i64 - 1);
        b as usize * g.width + a as usize
    }
}

impl Grid {
    fn resample(
        dem: &Dem,
        pyramid: &Pyramid,
        dem_path: &Path,
        cancelled: &dyn Fn() -> Result<(), WorldError>,
        progress: &mut dyn FnMut(BakeStage, u64, u64),
    ) -> Result<Grid, WorldError> {
        let finest = pyramid.stored_levels - 1;
        let margin = i64::from(pyramid.border) << finest;
        let [nx, ny] = pyramid.tiles_at(finest);
        let cells = |n: u32| i64::from(n) * i64::from(pyramid.tile_cells);
        let width = (cells(nx) + 1 + 2 * margin) as usize;
        let height = (cells(ny) + 1 + 2 * margin) as usize;
        if width as u64 * height as u64 > MAX_GRID_SAMPLES {
            return Err(WorldError::OutOfRange {
                path: dem_path.to_path_buf(),
                field: "finest grid (root grid / cell size)".into(),
                value: format!("{width}x{height} samples"),
                allowed: format!("at most {MAX_GRID_SAMPLES} samples"),
            });
        }
        let cell = pyramid.cell_size_m(finest);
        let mut heights = vec![0f32; width * height];
        let total = height as u64;
        for (b, row) in heights.chunks_exact_mut(width).enumerate() {
            let y = (b as i64 - margin) as f64 * cell;
            for (a, h) in row.iter_mut().enumerate() {
                let x = (a as i64 - margin) as f64 * cell;
                *h = dem.sample(x, y) as f32;
            }
            if b % 64 == 0 || b + 1 == height {
                cancelled()?;
                progress(BakeStage::Resample, b as u64 + 1, total);
            }
        }
        Ok(Grid {
            width,
            height,
            margin,
            cell,
            finest,
            heights,
        })
    }

    fn at(&self, a: usize, b: usize) -> f32 {
        self.heights[b * self.width + a]
    }

    /// Fits the detail of the derived levels to the data area of the finest stored level (the
    /// coarser stored levels are its subsamples): see [`calibrate`].
    fn calibrate(&self, extent: [f64; 2], derived_levels: u8) -> DeriveCalibration {
        let m = self.margin as usize;
        let samples = |e: f64, n: usize| ((e / self.cell).floor() as usize + 1).min(n - m);
        let (w, h) = (
            samples(extent[0], self.width),
            samples(extent[1], self.height),
        );
        let mut heights = Vec::with_capacity(w * h);
        for b in m..m + h {
            let row = b * self.width + m;
            heights.extend_from_slice(&self.heights[row..row + w]);
        }
        calibrate(
            &HeightField {
                width: w,
                height: h,
                cell_m: (self.cell, self.cell),
                heights: &heights,
            },
            derived_levels,
            DeriveParams::default().seed,
        )
    }

    /// Min and max of all samples; an empty range is widened to 1 m.
    fn height_range(&self) -> [f32; 2] {
        let (lo, hi) = self
            .heights
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &h| {
                (lo.min(h), hi.max(h))
            });
        if lo < hi {
            [lo, hi]
        } else {
            [lo - 0.5, hi + 0.5]
        }
    }

    /// Height at world position `p` by bilinear interpolation, clamped to the grid.
    fn height_bilinear(&self, p: DVec2) -> f64 {
        let u = (p.x / self.cell + self.margin as f64).clamp(0.0, (self.width - 1) as f64);
        let v = (p.y / self.cell + self.margin as f64).clamp(0.0, (self.height - 1) as f64);
        let (a, b) = (
            (u.floor() as usize).min(self.width - 2),
            (v.floor() as usize).min(self.height - 2),
        );
        let (fu, fv) = (u - a as f64, v - b as f64);
        let h = |a, b| f64::from(self.at(a, b));
        let south = h(a, b) * (1.0 - fu) + h(a + 1, b) * fu;
        let north = h(a, b + 1) * (1.0 - fu) + h(a + 1, b + 1) * fu;
        south * (1.0 - fv) + north * fv
    }

    /// Slope at sample `(a, b)` in degrees, from central differences (one-sided at the grid's
    /// edge).
    fn slope_deg(&self, a: usize, b: usize) -> f64 {
        let d = |lo: usize, hi: usize, get: &dyn Fn(usize) -> f32| {
            f64::from(get(hi) - get(lo)) / ((hi - lo) as f64 * self.cell)
        };
        let (a0, a1) = (a.saturating_sub(1), (a + 1).min(self.width - 1));
        let (b0, b1) = (b.saturating_sub(1), (b + 1).min(self.height - 1));
        let dx = d(a0, a1, &|i| self.at(i, b));
        let dy = d(b0, b1, &|j| self.at(a, j));
        (dx * dx + dy * dy).sqrt().atan().to_degrees()
    }

    fn position(&self, a: usize, b: usize) -> DVec2 {
        DVec2::new(
            (a as i64 - self.margin) as f64,
            (b as i64 - self.margin) as f64,
        ) * self.cell
    }

    fn paint(
        self,
        height_range: [f32; 2],
        seed: u64,
        cancelled: &dyn Fn() -> Result<(), WorldError>,
        progress: &mut dyn FnMut(BakeStage, u64, u64),
    ) -> Result<Painted, WorldError> {
        let n = self.width * self.height;
        let mut grass_type = vec![0u8; n];
        let mut density = vec![0u8; n];
        let span = f64::from(height_range[1] - height_range[0]);
        for b in 0..self.height {
            for a in 0..self.width {
                let altitude = (f64::from(self.at(a, b) - height_range[0]) / span).clamp(0.0, 1.0);
                let (t, d) =
                    paint_sample(self.slope_deg(a, b), altitude, self.position(a, b), seed);
                grass_type[b * self.width + a] = t;
                density[b * self.width + a] = d;
            }
            if b % 64 == 0 || b + 1 == self.height {
                cancelled()?;
                progress(BakeStage::Paint, b as u64 + 1, self.height as u64);
            }
        }
        Ok(Painted {
            grid: self,
            grass_type,
            density,
            cancel: None,
        })
    }
}

/// Grass type and density byte of one sample from its slope (degrees), altitude (0 at the
/// world's lowest point, 1 at its highest) and position (for the noise).
fn paint_sample(slope_deg: f64, altitude: f64, p: DVec2, seed: u64) -> (u8, u8) {
    if slope_deg > MAX_GRASS_SLOPE_DEG {
        return (0, 0);
    }
    // Large patches (a couple of km) decide how dry the ground is; small ones (a few hundred m)
    // break up the cover and place tall grass.
    let broad = fbm(p / 1800.0, seed, 3);
    let patch = fbm(p / 300.0, seed.wrapping_add(1), 3);
    let speckle = fbm(p / 90.0, seed.wrapping_add(2), 2);
    // Rocky outcrops on steep-ish ground.
    if slope_deg > 27.0 && patch > 0.58 {
        return (0, 0);
    }
    let dryness = 1.1 * altitude + 0.9 * (broad - 0.5) + 0.25 * slope_deg / MAX_GRASS_SLOPE_DEG;
    let kind = if dryness > 0.72 {
        3
    } else if patch > 0.56 && slope_deg < 18.0 {
        2
    } else {
        1
    };
    let steepness = smoothstep(18.0, MAX_GRASS_SLOPE_DEG, slope_deg);
    let cover = (0.55 + 0.45 * speckle) * (1.0 - steepness) * if kind == 3 { 0.8 } else { 1.0 };
    let byte = (cover.clamp(0.0, 1.0) * 255.0).round() as u8;
    if byte == 0 { (0, 0) } else { (kind, byte) }
}

fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// A hash of a lattice point to 0..1.
fn lattice(ix: i64, iy: i64, seed: u64) -> f64 {
    let mut z = seed
        ^ (ix as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (iy as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

/// Smooth value noise in 0..1 with one lattice cell per unit.
fn value_noise(p: DVec2, seed: u64) -> f64 {
    let f = p.floor();
    let (ix, iy) = (f.x as i64, f.y as i64);
    let t = p - f;
    let s = t * t * (DVec2::splat(3.0) - 2.0 * t);
    let v00 = lattice(ix, iy, seed);
    let v10 = lattice(ix + 1, iy, seed);
    let v01 = lattice(ix, iy + 1, seed);
    let v11 = lattice(ix + 1, iy + 1, seed);
    let south = v00 + (v10 - v00) * s.x;
    let north = v01 + (v11 - v01) * s.x;
    south + (north - south) * s.y
}

/// Fractal sum of `octaves` value noises, normalised to 0..1.
fn fbm(p: DVec2, seed: u64, octaves: u32) -> f64 {
    let (mut sum, mut norm, mut amp, mut freq) = (0.0, 0.0, 1.0, 1.0);
    for o in 0..octaves {
        sum += amp * value_noise(p * freq, seed.wrapping_add(u64::from(o) * 0x1000_0001));
        norm += amp;
        amp *= 0.5;
        freq *= 2.03;
    }
    sum / norm
}

/// Cuts every stored tile from the painted grid and writes it, on as many threads as the
/// machine offers; stops between tiles when `cancelled` says so.
fn write_all_tiles(
    out: &Path,
    pyramid: &Pyramid,
    painted: &Painted,
    cancelled: &(dyn Fn() -> Result<(), WorldError> + Sync),
    progress: &mut dyn FnMut(BakeStage, u64, u64),
) -> Result<u64, WorldError> {
    let tiles: Vec<TileId> = (0..pyramid.stored_levels)
        .flat_map(|level| {
            let [nx, ny] = pyramid.tiles_at(level);
            (0..ny).flat_map(move |y| (0..nx).map(move |x| TileId::new(level, x, y)))
        })
        .collect();
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
fn cut_tile(pyramid: &Pyramid, painted: &Painted, id: TileId) -> TileData {
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
    };
    for j in 0..i64::from(size) {
        let b = ((i64::from(id.y) * cells + j - border) * step + grid.margin) as usize;
        for i in 0..i64::from(size) {
            let a = ((i64::from(id.x) * cells + i - border) * step + grid.margin) as usize;
            let k = b * grid.width + a;
            tile.heights.push(grid.heights[k]);
            tile.grass_type.push(painted.grass_type[k]);
            tile.density.push(painted.density[k]);
        }
    }
    tile
}

/// Height of the camera above the highest terrain near the overview path, metres.
const OVERVIEW_CLEARANCE_M: f64 = 220.0;
/// Height of the camera above the highest terrain near the low path, metres.
const LOW_CLEARANCE_M: f64 = 32.0;
/// Height of the meadow glide above the highest ground near it, metres.
const MEADOW_CLEARANCE_M: f64 = 2.0;

/// Name of the baked camera path that the `helicopter` wind scene's downwash follows.
pub const HELICOPTER_PATH: &str = "helicopter";

/// The wind scenes of a baked world, the ambient wind of each blowing toward 20 degrees (east-
/// north-east), as [`WindDefaults::default`]:
/// - `calm`: 0.8 m/s, hardly gusting;
/// - `breeze`: 4 m/s, gustiness 0.35 (the world's default wind);
/// - `storm`: 14 m/s, gustiness 0.8, with two directional gust sources that swell and fade on
///   periods of 17 s and 23 s (so together they repeat only every 391 s), slightly off the mean
///   direction;
/// - `helicopter`: light air (2 m/s, gustiness 0.3) and a rotor's downwash following the
///   `helicopter` camera path: an omni source (25 m/s outward, radius 30 m) and a vortex
///   (4 m/s clockwise swirl, radius 30 m), both spinning up over the first 2 s.
pub fn default_wind_scenes() -> Vec<WindScene> {
    let ambient = |speed_mps: f32, gustiness: f32| WindDefaults {
        direction_deg: 20.0,
        speed_mps,
        gustiness,
    };
    let gust = |direction_deg: f64, speed_mps: f64, period_s: f64| WindSource::Directional {
        direction_deg,
        speed_mps,
        position_m: None,
        path: None,
        start_s: 0.0,
        strength: [(0.0, 0.0), (0.35, 0.0), (0.55, 1.0), (0.7, 1.0), (1.0, 0.0)]
            .map(|(u, f)| [round_to(period_s * u, 2), f])
            .to_vec(),
        repeat: true,
    };
    let spin_up = vec![[0.0, 0.0], [2.0, 1.0]];
    vec![
        WindScene {
            name: "calm".into(),
            ambient: ambient(0.8, 0.15),
            sources: Vec::new(),
        },
        WindScene {
            name: "breeze".into(),
            ambient: ambient(4.0, 0.35),
            sources: Vec::new(),
        },
        WindScene {
            name: "storm".into(),
            ambient: ambient(14.0, 0.8),
            sources: vec![gust(35.0, 6.0, 17.0), gust(5.0, 5.0, 23.0)],
        },
        WindScene {
            name: "helicopter".into(),
            ambient: ambient(2.0, 0.3),
            sources: vec![
                WindSource::Omni {
                    radius_m: 30.0,
                    speed_mps: 25.0,
                    position_m: None,
                    path: Some(HELICOPTER_PATH.into()),
                    start_s: 0.0,
                    strength: spin_up.clone(),
                    repeat: false,
                },
                WindSource::Vortex {
                    radius_m: 30.0,
                    speed_mps: 4.0,
                    clockwise: true,
                    inflow_mps: 0.0,
                    position_m: None,
                    path: Some(HELICOPTER_PATH.into()),
                    start_s: 0.0,
                    strength: spin_up,
                    repeat: false,
                },
            ],
        },
    ]
}

/// Highest terrain within `half_width` of the polyline through `points`, sampled every `step`.
fn max_terrain_along(grid: &Grid, points: &[DVec2], half_width: f64, step: f64) -> f64 {
    let mut best = f64::NEG_INFINITY;
    for w in points.windows(2) {
        let (p, q) = (w[0], w[1]);
        let d = q - p;
        let len = d.length();
        let side = if len > 0.0 {
            d.perp() / len
        } else {
            DVec2::ZERO
        };
        let n = (len / step).ceil().max(1.0) as usize;
        for s in 0..=n {
            let c = p + d * (s as f64 / n as f64);
            for o in [-1.0, -0.5, 0.0, 0.5, 1.0] {
                best = best.max(grid.height_bilinear(c + side * (o * half_width)));
            }
        }
    }
    best
}

/// Keys along `points` (one per key time): each key's height clears the highest terrain near
/// the path on both sides of it by `clearance`, so the straight line between two keys clears
/// the terrain under it by at least `clearance` too.
fn keys_along(
    grid: &Grid,
    points: &[DVec2],
    times: &[f64],
    clearance: f64,
    half_width: f64,
    pitch_deg: f64,
) -> Vec<CameraKey> {
    let last = points.len() - 1;
    let mut keys: Vec<CameraKey> = Vec::with_capacity(points.len());
    for k in 0..=last {
        let around = &points[k.saturating_sub(1)..=(k + 1).min(last)];
        let z = max_terrain_along(grid, around, half_width, grid.cell * 0.5) + clearance;
        let ahead = points[(k + 1).min(last)] - points[k.saturating_sub(1)];
        let mut yaw = ahead.y.atan2(ahead.x).to_degrees();
        if let Some(prev) = keys.last() {
            // Unwrap, so that interpolating yaw never turns the long way round.
            yaw = prev.yaw_deg + (yaw - prev.yaw_deg + 540.0).rem_euclid(360.0) - 180.0;
        }
        keys.push(CameraKey {
            t_s: times[k],
            position_m: [
                round_to(points[k].x, 2),
                round_to(points[k].y, 2),
                round_to(z, 2),
            ],
            yaw_deg: round_to(yaw, 3),
            pitch_deg,
        });
    }
    keys
}

/// `v` rounded to `decimals` places, as the f64 nearest that decimal (so it prints short).
fn round_to(v: f64, decimals: usize) -> f64 {
    format!("{v:.decimals$}").parse().unwrap_or(v)
}

/// A 60 s flight along a gentle S-curve from the south-west to the north-east of the data
/// area, high above the terrain, looking ahead and down.
fn overview_path(painted: &Painted, extent: [f64; 2]) -> CameraPath {
    let grid = &painted.grid;
    let e = DVec2::from(extent);
    let a = e * DVec2::new(0.12, 0.10);
    let b = e * DVec2::new(0.88, 0.90);
    let d = b - a;
    let side = d.perp().normalize_or_zero() * (0.07 * d.length());
    const DURATION: f64 = 60.0;
    const KEYS: usize = 31;
    let times: Vec<f64> = (0..KEYS)
        .map(|k| DURATION * k as f64 / (KEYS - 1) as f64)
        .collect();
    let points: Vec<DVec2> = times
        .iter()
        .map(|t| {
            let u = t / DURATION;
            a + d * u + side * (std::f64::consts::TAU * u).sin()
        })
        .collect();
    CameraPath {
        name: "overview".into(),
        duration_s: DURATION,
        walker: None,
        keys: keys_along(grid, &points, &times, OVERVIEW_CLEARANCE_M, 150.0, -14.0),
        wind: Vec::new(),
    }
}

/// The grassiest, gentlest 1.6 km line of the data area: its centre and its direction, heading
/// toward the higher ground.
fn grassy_line(painted: &Painted, extent: [f64; 2]) -> (DVec2, DVec2) {
    let grid = &painted.grid;
    const LENGTH: f64 = 1600.0;
    let e = DVec2::from(extent);
    let density_at = |p: DVec2| f64::from(painted.density[painted.index_at(p)]) / 255.0;
    // Candidates: centres on a grid inside the data area, eight headings each. Score: grass
    // cover along the line, less its height variation (a low pass over rugged ground would
    // either hit hills or fly high over valleys).
    let inset = (LENGTH * 0.6).min(e.min_element() * 0.45);
    let steps = 24;
    let mut best = (f64::NEG_INFINITY, e * 0.5, DVec2::X);
    for cy in 0..=steps {
        if painted.cancelled() {
            break;
        }
        for cx in 0..=steps {
            let c = DVec2::new(
                inset + (e.x - 2.0 * inset) * cx as f64 / steps as f64,
                inset + (e.y - 2.0 * inset) * cy as f64 / steps as f64,
            );
            for h in 0..8 {
                let dir = DVec2::from_angle(std::f64::consts::PI * h as f64 / 8.0);
                let (mut cover, mut lo, mut hi) = (0.0, f64::INFINITY, f64::NEG_INFINITY);
                let n = 32;
                for s in 0..=n {
                    let p = c + dir * LENGTH * (s as f64 / n as f64 - 0.5);
                    cover += density_at(p);
                    let z = grid.height_bilinear(p);
                    lo = lo.min(z);
                    hi = hi.max(z);
                }
                let score = cover / (n + 1) as f64 - (hi - lo) / 100.0;
                if score > best.0 {
                    best = (score, c, dir);
                }
            }
        }
    }
    let (_, c, mut dir) = best;
    // Fly toward the higher ground, so that the view ahead holds hills rather than plain.
    if grid.height_bilinear(c - dir * 3000.0) > grid.height_bilinear(c + dir * 3000.0) {
        dir = -dir;
    }
    (c, dir)
}

/// A 32 s pass 30-60 m above the ground along the grassy line, toward the higher ground.
fn low_path(painted: &Painted, extent: [f64; 2]) -> CameraPath {
    const LENGTH: f64 = 1600.0;
    const DURATION: f64 = 32.0;
    const KEYS: usize = 33;
    let grid = &painted.grid;
    let (c, dir) = grassy_line(painted, extent);
    let times: Vec<f64> = (0..KEYS)
        .map(|k| DURATION * k as f64 / (KEYS - 1) as f64)
        .collect();
    let points: Vec<DVec2> = times
        .iter()
        .map(|t| c + dir * LENGTH * (t / DURATION - 0.5))
        .collect();
    CameraPath {
        name: "low".into(),
        duration_s: DURATION,
        walker: None,
        keys: keys_along(grid, &points, &times, LOW_CLEARANCE_M, 20.0, -8.0),
        wind: Vec::new(),
    }
}

/// The tour, the default path: 30 s descending from high above the highest ground near the
/// meadow of the grassy line toward it, then 20 s gliding a couple of metres above it at
/// 8 m/s: terrain far and grass near in one flight.
fn tour_path(painted: &Painted, extent: [f64; 2]) -> CameraPath {
    const APPROACH_S: f64 = 30.0;
    const GLIDE_S: f64 = 20.0;
    const GLIDE_SPEED: f64 = 8.0;
    const KEYS_A_SECOND: f64 = 1.0;
    let grid = &painted.grid;
    let e = DVec2::from(extent);
    let (c, dir) = grassy_line(painted, extent);
    let glide = GLIDE_SPEED * GLIDE_S;
    let meadow_start = c - dir * (glide / 2.0);
    // Start over the highest ground 2 to 8 km from the meadow (inside the data area), so that
    // the first half of the flight shows ridges and valleys from the air; where the world has
    // no such ground, 2.5 km back along the line. The approach is a quadratic Bezier curve that
    // comes into the meadow along the line.
    let inside =
        |a: DVec2| a.x > 0.05 * e.x && a.y > 0.05 * e.y && a.x < 0.95 * e.x && a.y < 0.95 * e.y;
    let mut start = None;
    let mut best = f64::NEG_INFINITY;
    let step = 200.0;
    let n = (8000.0 / step) as i64;
    for j in -n..=n {
        for i in -n..=n {
            let p = meadow_start + DVec2::new(i as f64, j as f64) * step;
            let r = p.distance(meadow_start);
            if !(2000.0..=8000.0).contains(&r) || !inside(p) {
                continue;
            }
            let h = grid.height_bilinear(p);
            if h > best {
                best = h;
                start = Some(p);
            }
        }
    }
    let meadow_h = grid.height_bilinear(meadow_start);
    let start = match start {
        Some(p) if best > meadow_h + 100.0 => p,
        _ => {
            let mut back = 2500.0;
            while back > 200.0 && !inside(meadow_start - dir * back) {
                back *= 0.8;
            }
            meadow_start - dir * back
        }
    };
    let span = start.distance(meadow_start);
    let control = meadow_start - dir * (0.45 * span);
    let curve = |v: f64| {
        let w = 1.0 - v;
        start * (w * w) + control * (2.0 * w * v) + meadow_start * (v * v)
    };
    // The curve's length, for the speeds below.
    let back: f64 = (0..64)
        .map(|k| curve((k + 1) as f64 / 64.0).distance(curve(k as f64 / 64.0)))
        .sum();
    // Distance along the approach: cubic Hermite from 1.5 times the mean speed down to the
    // glide's speed, so the camera slows smoothly into the glide.
    let (v0, v1) = (1.5 * back / APPROACH_S, GLIDE_SPEED);
    let along = |u: f64| {
        let (u2, u3) = (u * u, u * u * u);
        (u3 - 2.0 * u2 + u) * APPROACH_S * v0
            + (-2.0 * u3 + 3.0 * u2) * back
            + (u3 - u2) * APPROACH_S * v1
    };
    let n_approach = (APPROACH_S * KEYS_A_SECOND) as usize;
    let n_glide = (GLIDE_S * KEYS_A_SECOND) as usize;
    let mut times = Vec::new();
    let mut points = Vec::new();
    let mut clearance = Vec::new();
    let mut pitch = Vec::new();
    for k in 0..n_approach {
        let u = k as f64 / n_approach as f64;
        times.push(APPROACH_S * u);
        points.push(curve((along(u) / back).clamp(0.0, 1.0)));
        let high = (1.0 - u) * (1.0 - u);
        clearance.push(MEADOW_CLEARANCE_M + (OVERVIEW_CLEARANCE_M - MEADOW_CLEARANCE_M) * high);
        pitch.push(-6.0 - 14.0 * high);
    }
    for k in 0..=n_glide {
        let u = k as f64 / n_glide as f64;
        times.push(APPROACH_S + GLIDE_S * u);
        points.push(meadow_start + dir * (glide * u));
        clearance.push(MEADOW_CLEARANCE_M);
        pitch.push(-6.0);
    }
    let mut keys = keys_along(grid, &points, &times, 0.0, 2.0, 0.0);
    for (k, key) in keys.iter_mut().enumerate() {
        key.position_m[2] = round_to(key.position_m[2] + clearance[k], 2);
        key.pitch_deg = round_to(pitch[k], 2);
    }
    CameraPath {
        name: "tour".into(),
        duration_s: APPROACH_S + GLIDE_S,
        walker: None,
        keys,
        wind: Vec::new(),
    }
}

/// A 24 s glide at 8 m/s a couple of metres above the meadow in the middle of the grassy line:
/// the view for grass.
fn meadow_path(painted: &Painted, extent: [f64; 2]) -> CameraPath {
    const LENGTH: f64 = 192.0;
    const DURATION: f64 = 24.0;
    const KEYS: usize = 25;
    let grid = &painted.grid;
    let (c, dir) = grassy_line(painted, extent);
    let times: Vec<f64> = (0..KEYS)
        .map(|k| DURATION * k as f64 / (KEYS - 1) as f64)
        .collect();
    let points: Vec<DVec2> = times
        .iter()
        .map(|t| c + dir * LENGTH * (t / DURATION - 0.5))
        .collect();
    CameraPath {
        name: "meadow".into(),
        duration_s: DURATION,
        walker: None,
        keys: keys_along(grid, &points, &times, MEADOW_CLEARANCE_M, 2.0, -6.0),
        wind: Vec::new(),
    }
}

/// The middle and direction of the helicopter's pass: the tall-grass spot nearest the middle
/// of the grassy line, along that line.
fn helicopter_line(painted: &Painted, extent: [f64; 2]) -> (DVec2, DVec2) {
    let (c, dir) = grassy_line(painted, extent);
    (tall_grass_spot(painted, extent, c), dir)
}

/// The point within 2 km of `near` (and at least 80 m inside the data area) whose surroundings
/// (40 m around) are most thoroughly tall grass, dense and level, nearest `near` among equals.
/// Wind reads best on tall blades.
fn tall_grass_spot(painted: &Painted, extent: [f64; 2], near: DVec2) -> DVec2 {
    const REACH_M: f64 = 2000.0;
    const AROUND_M: f64 = 40.0;
    let grid = &painted.grid;
    let e = DVec2::from(extent);
    let inset = DVec2::splat(80.0).min(e * 0.45);
    let inside = |p: DVec2| p.cmpge(inset).all() && p.cmple(e - inset).all();
    let sample = |p: DVec2| -> (u8, f64) {
        let i = painted.index_at(p);
        (painted.grass_type[i], f64::from(painted.density[i]) / 255.0)
    };
    let steps = (REACH_M / grid.cell).round() as i64;
    let ring = (AROUND_M / grid.cell).ceil() as i64;
    let mut best = (
        f64::NEG_INFINITY,
        f64::INFINITY,
        near.clamp(inset, e - inset),
    );
    for j in -steps..=steps {
        if painted.cancelled() {
            break;
        }
        for i in -steps..=steps {
            let p = near + DVec2::new(i as f64, j as f64) * grid.cell;
            if !inside(p) {
                continue;
            }
            let (mut score, mut lo, mut hi) = (0.0, f64::INFINITY, f64::NEG_INFINITY);
            let mut count = 0.0;
            for b in -ring..=ring {
                for a in -ring..=ring {
                    let q = p + DVec2::new(a as f64, b as f64) * grid.cell;
                    if q.distance(p) > AROUND_M {
                        continue;
                    }
                    let (kind, density) = sample(q);
                    if kind == 2 {
                        score += density;
                    }
                    let z = grid.height_bilinear(q);
                    (lo, hi) = (lo.min(z), hi.max(z));
                    count += 1.0;
                }
            }
            let score = score / count - (hi - lo) / 40.0;
            let distance = p.distance(near);
            if score > best.0 + 1e-9 || (score > best.0 - 1e-9 && distance < best.1) {
                best = (score, distance, p);
            }
        }
    }
    best.2
}

/// Height of the helicopter above the highest ground near its pass, metres.
const HELICOPTER_CLEARANCE_M: f64 = 16.0;

/// A 20 s pass at 5 m/s, 16 m above the highest ground near it, over the tall grass nearest
/// the middle of the grassy line, along that line, looking ahead and down: the helicopter that
/// the `helicopter` wind scene's downwash follows.
fn helicopter_path(painted: &Painted, extent: [f64; 2]) -> CameraPath {
    const LENGTH: f64 = 100.0;
    const DURATION: f64 = 20.0;
    const KEYS: usize = 11;
    let grid = &painted.grid;
    let (c, dir) = helicopter_line(painted, extent);
    let times: Vec<f64> = (0..KEYS)
        .map(|k| DURATION * k as f64 / (KEYS - 1) as f64)
        .collect();
    let points: Vec<DVec2> = times
        .iter()
        .map(|t| c + dir * LENGTH * (t / DURATION - 0.5))
        .collect();
    CameraPath {
        name: HELICOPTER_PATH.into(),
        duration_s: DURATION,
        walker: None,
        keys: keys_along(grid, &points, &times, HELICOPTER_CLEARANCE_M, 5.0, -30.0),
        wind: Vec::new(),
    }
}

/// Name of the baked fly-through that shows the wind scenes in turn.
pub const WIND_TOUR_PATH: &str = "wind-tour";
/// Name of the baked path of the walker whose trail the wind tour shows.
pub const WALKER_PATH: &str = "walker";
/// The wind tour's scenes and the times they start, seconds: each holds 12 s (the helicopter
/// 14 s, for its pass to cross the view), blending in over [`DEFAULT_WIND_BLEND_S`].
pub const WIND_TOUR_SCENES: [(&str, f64); 4] = [
    ("calm", 0.0),
    ("breeze", 12.0),
    ("storm", 24.0),
    ("helicopter", 36.0),
];
/// Length of the wind tour, seconds.
const WIND_TOUR_S: f64 = 50.0;

/// The wind tour and its walker. The camera stands 6 m above a patch of tall grass near the
/// grassy line (see [`tall_grass_spot`]), 18 m to the side of the helicopter's pass and looking
/// down across it (to the right of the pass's direction, so that for the baked world the sun is
/// behind the camera and bent blades catch it), and drifts 6 m along it over 50 s; the wind changes from calm to breeze to
/// storm to the helicopter scene (whose pass crosses the middle of the view about 10 s into it).
/// A walker circles 11 m in front of the camera (4 m radius, 1.25 m/s), leaving its trail in the
/// grass in every scene.
fn wind_tour_paths(painted: &Painted, extent: [f64; 2]) -> (CameraPath, CameraPath) {
    const SIDE_M: f64 = 18.0;
    const DRIFT_M: f64 = 6.0;
    const CLEARANCE_M: f64 = 6.0;
    const WALK_SIDE_M: f64 = 7.0;
    const WALK_RADIUS_M: f64 = 4.0;
    const WALK_SPEED: f64 = 1.25;
    let grid = &painted.grid;
    let (c, dir) = helicopter_line(painted, extent);
    let side = -dir.perp();
    let look = -side;
    let yaw = round_to(look.y.atan2(look.x).to_degrees(), 3);
    let keys_n = WIND_TOUR_S as usize;
    let times: Vec<f64> = (0..=keys_n).map(|k| k as f64).collect();
    let camera_points: Vec<DVec2> = times
        .iter()
        .map(|t| c + side * SIDE_M + dir * (DRIFT_M * (t / WIND_TOUR_S - 0.5)))
        .collect();
    let mut keys = keys_along(grid, &camera_points, &times, CLEARANCE_M, 1.0, -24.0);
    for k in &mut keys {
        k.yaw_deg = yaw;
    }
    let centre = c + side * WALK_SIDE_M;
    let omega = WALK_SPEED / WALK_RADIUS_M;
    let walk_points: Vec<DVec2> = times
        .iter()
        .map(|t| centre + DVec2::from_angle(omega * t) * WALK_RADIUS_M)
        .collect();
    let walker = CameraPath {
        name: WALKER_PATH.into(),
        duration_s: WIND_TOUR_S,
        walker: None,
        keys: keys_along(grid, &walk_points, &times, 1.7, 0.0, 0.0),
        wind: Vec::new(),
    };
    let tour = CameraPath {
        name: WIND_TOUR_PATH.into(),
        duration_s: WIND_TOUR_S,
        walker: Some(WALKER_PATH.into()),
        keys,
        wind: WIND_TOUR_SCENES
            .iter()
            .map(|&(scene, t_s)| WindKey {
                t_s,
                scene: scene.into(),
                blend_s: DEFAULT_WIND_BLEND_S,
            })
            .collect(),
    };
    (tour, walker)
}

/// Refuses bake options out of range before anything is read, naming the option.
fn check_options(opts: &BakeOptions) -> Result<(), WorldError> {
    let t = opts.tile_cells;
    if !(8..=1024).contains(&t) || !t.is_power_of_two() {
        return Err(WorldError::bad_option(
            "--tile-cells",
            t,
            "a power of two in 8..=1024".into(),
        ));
    }
    if !(1..=12).contains(&opts.stored_levels) {
        return Err(WorldError::bad_option(
            "--levels",
            opts.stored_levels,
            "in 1..=12".into(),
        ));
    }
    if let Some(c) = opts.cell_size_m
        && !(c.is_finite() && c > 0.0)
    {
        return Err(WorldError::bad_option(
            "--cell-size",
            c,
            "a positive number of metres".into(),
        ));
    }
    check_out(&opts.out, opts.replace)
}

/// Smallest cell a bake resamples to, metres.
pub const MIN_BAKE_CELL_M: f64 = 1e-3;

/// Most cells a side a bake resamples the DEM to.
pub const MAX_BAKE_CELLS: f64 = 65_536.0;

/// Refuses a cell size (given, or the DEM's own) below a millimetre or resampling the DEM to
/// more than [`MAX_BAKE_CELLS`] a side, naming the option or the sidecar's field.
fn check_cell_size(
    dem: &Dem,
    dem_path: &Path,
    option: Option<f64>,
    cell: f64,
) -> Result<(), WorldError> {
    let extent = dem.extent_m();
    let cells = extent[0].max(extent[1]) / cell;
    let least = (extent[0].max(extent[1]) / MAX_BAKE_CELLS).max(MIN_BAKE_CELL_M);
    if cell >= MIN_BAKE_CELL_M && cells <= MAX_BAKE_CELLS {
        return Ok(());
    }
    let allowed = format!(
        "at least {least} m for this DEM ({:.3} x {:.3} m; a bake resamples to at least 1 mm \
         cells and at most {MAX_BAKE_CELLS} cells a side)",
        extent[0], extent[1]
    );
    match option {
        Some(c) => Err(WorldError::bad_option("--cell-size", c, allowed)),
        None => Err(WorldError::OutOfRange {
            path: crate::world::dem::sidecar_path(dem_path),
            field: "cell_size_m".into(),
            value: format!("{} x {}", dem.cell_ew_m, dem.cell_ns_m),
            allowed: format!("{allowed}, or pass --cell-size"),
        }),
    }
}

/// Refuses a DEM whose heights leave [`crate::world::PLAUSIBLE_HEIGHTS_M`] (a wrong offset or scale in
/// its sidecar), naming the sidecar.
fn check_dem_heights(dem: &Dem, dem_path: &Path) -> Result<(), WorldError> {
    let [lo, hi] = crate::world::PLAUSIBLE_HEIGHTS_M;
    let bad = dem.heights.iter().position(|&h| {
        let h = f64::from(h);
        !(lo..=hi).contains(&h)
    });
    match bad {
        None => Ok(()),
        Some(k) => Err(WorldError::ImplausibleHeight {
            path: crate::world::dem::sidecar_path(dem_path),
            dem: dem_path.to_path_buf(),
            column: k as u32 % dem.width,
            row: k as u32 / dem.width,
            value: f64::from(dem.heights[k]),
            range: crate::world::PLAUSIBLE_HEIGHTS_M,
        }),
    }
}

/// The densest grass of the finest stored level over windows of the finest grass tiles
/// (`Pyramid::max_level`), for the manifest's `grass_peak`.
fn grass_peak(manifest: &Manifest, painted: &Painted) -> crate::world::GrassPeak {
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

/// Refuses an output folder that exists and is not empty, unless it is to be replaced.
fn check_out(out: &Path, replace: bool) -> Result<(), WorldError> {
    match std::fs::read_dir(out) {
        Ok(mut entries) => {
            if entries.next().is_some() && !replace {
                return Err(WorldError::OutputNotEmpty {
                    path: out.to_path_buf(),
                });
            }
            Ok(())
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(WorldError::io(out, e)),
    }
}

/// Refuses painted grass type indices beyond the types the manifest lists: the painter and
/// [`default_grass_types`] must agree, or the renderer would draw an unknown index as another
/// type.
fn check_painted_types(
    painted: &Painted,
    manifest: &Manifest,
    manifest_path: &Path,
) -> Result<(), WorldError> {
    let count = manifest.grass_types.len();
    match painted
        .grass_type
        .iter()
        .position(|&t| usize::from(t) >= count)
    {
        None => Ok(()),
        Some(k) => Err(WorldError::BadTileData {
            path: manifest_path.to_path_buf(),
            message: format!(
                "grass type index {} painted at sample {k}, but the world has only {count} \
                 grass types",
                painted.grass_type[k]
            ),
        }),
    }
}

/// `out` made absolute, without `.` or `..` components or a trailing slash: the longest part
/// that exists is canonicalised (symlinks followed) and the rest appended. The staging folder
/// goes beside this path, so that it is never inside the output folder however `--out` is
/// spelled (`.`, `..`, `w/`, `w/sub/..`).
fn resolve_out(out: &Path) -> Result<PathBuf, WorldError> {
    let not_a_folder = || {
        WorldError::bad_option(
            "--out",
            format!("\"{}\"", out.display()),
            "a folder other than the root of the file system".into(),
        )
    };
    if out.as_os_str().is_empty() {
        return Err(not_a_folder());
    }
    let absolute = std::path::absolute(out).map_err(|e| WorldError::io(out, e))?;
    let components: Vec<Component> = absolute.components().collect();
    let mut resolved = None;
    for n in (1..=components.len()).rev() {
        let prefix: PathBuf = components[..n].iter().collect();
        match prefix.canonicalize() {
            Ok(base) => {
                resolved = Some((base, n));
                break;
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(WorldError::io(out, e)),
        }
    }
    let Some((mut path, n)) = resolved else {
        return Err(not_a_folder());
    };
    // What does not exist yet holds no symlinks, so `..` may be taken lexically.
    for c in &components[n..] {
        match c {
            Component::Normal(name) => path.push(name),
            Component::ParentDir => {
                path.pop();
            }
            _ => {}
        }
    }
    if path.file_name().is_none() || path.parent().is_none() {
        return Err(not_a_folder());
    }
    Ok(path)
}

/// The lock file in a staging folder, locked while its bake runs.
const STAGING_LOCK: &str = "lock";
/// The folder in a staging folder that the new world is written to.
const STAGING_WORLD: &str = "world";
/// The folder in a staging folder that the replaced world is moved to while the new one goes in.
const STAGING_PREVIOUS: &str = "previous";
/// A staging folder without a lock file belongs to a bake that is just starting, unless it was
/// last changed longer ago than this (folders of older versions, which had no lock).
const UNLOCKED_STAGING_GRACE: Duration = Duration::from_secs(60);

/// A world being baked in a staging folder beside its output folder,
/// `PARENT/.NAME.baking.PID-N/`: `lock` (locked while the bake runs), `world/` (the new world)
/// and, while [`Staging::publish`] runs, `previous/` (the world it replaces). Publishing moves
/// `world.toml` and `tiles/` alone into the output folder, so that no other file of that folder
/// is ever moved; the staging folder is removed when the bake ends, however it ends.
struct Staging {
    out: PathBuf,
    dir: PathBuf,
    world: PathBuf,
    replace: bool,
    /// Held for the lock's sake: a bake that is killed releases it with its process.
    _lock: std::fs::File,
    /// Leave the staging folder in place (it holds the only copy of the replaced world).
    keep: bool,
}

impl Staging {
    /// Creates the staging folder beside `out` (resolved by [`resolve_out`]), first removing
    /// the staging folders of killed bakes into the same output folder.
    fn begin(out: &Path, shown: &Path, replace: bool) -> Result<Self, WorldError> {
        check_out(out, replace)?;
        let (Some(name), Some(parent)) = (out.file_name(), out.parent()) else {
            return Err(WorldError::bad_option(
                "--out",
                shown.display(),
                "a folder other than the root of the file system".into(),
            ));
        };
        let name = name.to_string_lossy();
        std::fs::create_dir_all(parent).map_err(|e| WorldError::io(parent, e))?;
        remove_stale_staging(parent, &name);
        static NEXT: AtomicU64 = AtomicU64::new(0);
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let dir = parent.join(format!(".{name}.baking.{}-{n}", std::process::id()));
        std::fs::create_dir(&dir).map_err(|e| WorldError::io(&dir, e))?;
        let lock = match lock_staging(&dir) {
            Ok(lock) => lock,
            Err(e) => {
                let _ = std::fs::remove_dir_all(&dir);
                return Err(e);
            }
        };
        let staging = Self {
            out: out.to_path_buf(),
            world: dir.join(STAGING_WORLD),
            dir,
            replace,
            _lock: lock,
            keep: false,
        };
        std::fs::create_dir(&staging.world).map_err(|e| WorldError::io(&staging.world, e))?;
        Ok(staging)
    }

    /// The folder the new world is written to.
    fn world(&self) -> &Path {
        &self.world
    }

    /// Moves the baked world into the output folder: the replaced world's `world.toml` and
    /// `tiles/` (if any) aside into the staging folder, then the new `tiles/` and, last, the new
    /// `world.toml` in. Nothing else in the output folder is touched. If a step fails, what was
    /// moved is moved back.
    fn publish(mut self) -> Result<(), WorldError> {
        check_out(&self.out, self.replace)?;
        let created = !self.out.exists();
        std::fs::create_dir_all(&self.out).map_err(|e| WorldError::io(&self.out, e))?;
        let previous = self.dir.join(STAGING_PREVIOUS);
        std::fs::create_dir(&previous).map_err(|e| WorldError::io(&previous, e))?;
        // Each move done, as (where it is now, where it came from).
        let mut moved: Vec<(PathBuf, PathBuf)> = Vec::new();
        let mut step = |from: PathBuf, to: PathBuf| -> Result<(), (PathBuf, std::io::Error)> {
            std::fs::rename(&from, &to).map_err(|e| (from.clone(), e))?;
            moved.push((to, from));
            Ok(())
        };
        // The old manifest goes first and the new one comes last, so that the folder never
        // holds a manifest over tiles it does not describe.
        let mut result = Ok(());
        for name in ["world.toml", "tiles"] {
            let old = self.out.join(name);
            if result.is_ok() && old.symlink_metadata().is_ok() {
                result = step(old, previous.join(name));
            }
        }
        for name in ["tiles", "world.toml"] {
            if result.is_ok() {
                result = step(self.world.join(name), self.out.join(name));
            }
        }
        let Err((failed, source)) = result else {
            return Ok(());
        };
        let restored = moved
            .iter()
            .rev()
            .all(|(now, was)| std::fs::rename(now, was).is_ok());
        if restored {
            if created {
                let _ = std::fs::remove_dir(&self.out);
            }
            return Err(WorldError::io(&failed, source));
        }
        // The previous world is in the staging folder: keep it, under a name that no later
        // bake removes.
        self.keep = true;
        let kept = self.dir.with_file_name(
            self.dir
                .file_name()
                .map(|n| n.to_string_lossy().replacen(".baking.", ".previous.", 1))
                .unwrap_or_default(),
        );
        let kept = match std::fs::rename(&self.dir, &kept) {
            Ok(()) => kept,
            Err(_) => self.dir.clone(),
        };
        Err(WorldError::PublishFailed {
            path: self.out.clone(),
            kept,
            source,
        })
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if !self.keep {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

/// Creates and locks the lock file of the staging folder `dir`. It is locked under another
/// name and then renamed, so that no other bake ever finds it unlocked.
fn lock_staging(dir: &Path) -> Result<std::fs::File, WorldError> {
    let path = dir.join(STAGING_LOCK);
    let new = dir.join(format!("{STAGING_LOCK}.new"));
    let file = std::fs::File::create_new(&new).map_err(|e| WorldError::io(&new, e))?;
    file.lock().map_err(|e| WorldError::io(&new, e))?;
    std::fs::rename(&new, &path).map_err(|e| WorldError::io(&path, e))?;
    Ok(file)
}

/// Removes the staging folders of bakes into `parent/name` that no running bake holds: those
/// whose lock file can be locked (its bake was killed), and those without one that were last
/// changed over [`UNLOCKED_STAGING_GRACE`] ago. Best effort: a folder that cannot be removed
/// is left for the next bake.
fn remove_stale_staging(parent: &Path, name: &str) {
    let prefix = format!(".{name}.baking.");
    let Ok(entries) = std::fs::read_dir(parent) else {
        return;
    };
    for entry in entries.flatten() {
        if !entry.file_name().to_string_lossy().starts_with(&prefix)
            || !entry.file_type().is_ok_and(|t| t.is_dir())
        {
            continue;
        }
        let dir = entry.path();
        let lock = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(dir.join(STAGING_LOCK));
        let stale = match &lock {
            Ok(file) => file.try_lock().is_ok(),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => entry
                .metadata()
                .and_then(|m| m.modified())
                .is_ok_and(|changed| {
                    SystemTime::now()
                        .duration_since(changed)
                        .is_ok_and(|age| age > UNLOCKED_STAGING_GRACE)
                }),
            Err(_) => false,
        };
        if stale {
            // Removed while the lock is held, so that no bake can take the folder meanwhile.
            let _ = std::fs::remove_dir_all(&dir);
        }
        drop(lock);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nice_cell_sizes() {
        assert_eq!(nice_cell_size(24.585), 25.0);
        assert_eq!(nice_cell_size(30.888), 25.0);
        assert_eq!(nice_cell_size(10.2), 10.0);
        assert_eq!(nice_cell_size(0.95), 1.0);
        assert_eq!(nice_cell_size(4.4), 5.0);
    }

    #[test]
    fn steep_ground_is_bare() {
        for slope in [36.0, 45.0, 80.0] {
            for k in 0..50 {
                let p = DVec2::new(k as f64 * 37.0, k as f64 * 91.0);
                assert_eq!(paint_sample(slope, 0.3, p, 7), (0, 0));
            }
        }
    }

    /// Every index the painter gives names one of the grass types a bake writes, and there are
    /// no more of those than the renderer draws.
    #[test]
    fn painted_indices_name_the_types_written() {
        let types = default_grass_types().len();
        assert!(types <= crate::world::MAX_GRASS_TYPES);
        let mut seen = [false; 256];
        for seed in [1, 7, 12345] {
            for s in 0..=90 {
                for a in 0..=20 {
                    for k in 0..20 {
                        let p = DVec2::new(k as f64 * 613.0, (s * 21 + a) as f64 * 97.0);
                        let (kind, _) = paint_sample(f64::from(s), f64::from(a) / 20.0, p, seed);
                        seen[usize::from(kind)] = true;
                    }
                }
            }
        }
        let used: Vec<usize> = (0..256).filter(|&k| seen[k]).collect();
        assert_eq!(
            used,
            (0..types).collect::<Vec<_>>(),
            "every type, and no other"
        );
    }

    /// A painted index beyond the manifest's types is refused before anything is written.
    #[test]
    fn painted_indices_beyond_the_types_are_refused() {
        let grid = Grid {
            width: 2,
            height: 2,
            margin: 0,
            cell: 1.0,
            finest: 0,
            heights: vec![0.0; 4],
        };
        let mut painted = Painted {
            grid,
            grass_type: vec![0, 1, 2, 3],
            density: vec![9; 4],
            cancel: None,
        };
        let mut manifest = crate::world::Manifest::parse(
            include_str!("../worlds/santa-cruz/world.toml"),
            Path::new("world.toml"),
        )
        .unwrap();
        assert!(check_painted_types(&painted, &manifest, Path::new("w/world.toml")).is_ok());
        painted.grass_type[2] = 4;
        let err = check_painted_types(&painted, &manifest, Path::new("w/world.toml")).unwrap_err();
        assert!(matches!(err, WorldError::BadTileData { .. }), "{err}");
        assert!(err.to_string().contains("grass type index 4"), "{err}");
        manifest.grass_types.truncate(2);
        painted.grass_type[2] = 2;
        assert!(check_painted_types(&painted, &manifest, Path::new("w/world.toml")).is_err());
    }

    /// Output paths resolve to a folder with a name and a parent, so that the staging folder
    /// goes beside it.
    #[test]
    fn output_paths_resolve_without_dots() {
        let dir = tempfile::tempdir().unwrap();
        let base = dir.path().canonicalize().unwrap();
        std::fs::create_dir_all(base.join("w/sub")).unwrap();
        for (given, want) in [
            (base.join("w"), base.join("w")),
            (base.join("w/."), base.join("w")),
            (base.join("w/sub/.."), base.join("w")),
            (base.join("w/sub/../"), base.join("w")),
            (base.join("new/deeper/.."), base.join("new")),
            (base.join("w/sub/new/../.."), base.join("w")),
        ] {
            assert_eq!(resolve_out(&given).unwrap(), want, "{}", given.display());
        }
        for bad in ["/", "/..", ""] {
            let err = resolve_out(Path::new(bad)).unwrap_err();
            assert!(err.to_string().starts_with("--out"), "{err}");
        }
    }

    /// When a world cannot be moved into place, the one it was to replace is put back, and the
    /// folder's other files are never touched.
    #[test]
    fn a_failed_publish_puts_the_previous_world_back() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().canonicalize().unwrap().join("w");
        std::fs::create_dir_all(out.join("tiles/L0")).unwrap();
        std::fs::write(out.join("tiles/L0/0_0.type.png"), "old tile").unwrap();
        std::fs::write(out.join("world.toml"), "old manifest").unwrap();
        std::fs::write(out.join("notes.txt"), "mine").unwrap();
        let staging = Staging::begin(&out, &out, true).unwrap();
        let dir_of_staging = staging.dir.clone();
        assert_eq!(dir_of_staging.parent(), out.parent());
        // The new world lacks its manifest: the last move fails.
        std::fs::create_dir_all(staging.world().join("tiles/L0")).unwrap();
        std::fs::write(staging.world().join("tiles/L0/0_0.type.png"), "new tile").unwrap();
        let err = staging.publish().unwrap_err();
        assert!(err.to_string().contains("world.toml"), "{err}");
        assert_eq!(
            std::fs::read(out.join("world.toml")).unwrap(),
            b"old manifest"
        );
        assert_eq!(
            std::fs::read(out.join("tiles/L0/0_0.type.png")).unwrap(),
            b"old tile"
        );
        assert_eq!(std::fs::read(out.join("notes.txt")).unwrap(), b"mine");
        assert!(!dir_of_staging.exists());

        // Into a new folder: nothing is left at all.
        let new = dir.path().canonicalize().unwrap().join("new");
        let staging = Staging::begin(&new, &new, false).unwrap();
        assert!(staging.publish().is_err());
        assert!(!new.exists());
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(left.len(), 1, "{left:?}");
    }

    #[test]
    fn noise_is_deterministic_and_bounded() {
        for k in 0..1000 {
            let p = DVec2::new(k as f64 * 0.37 - 100.0, k as f64 * 0.11);
            let v = fbm(p, 3, 3);
            assert!((0.0..=1.0).contains(&v));
            assert_eq!(v, fbm(p, 3, 3));
        }
        assert_ne!(
            fbm(DVec2::new(0.5, 0.5), 1, 3),
            fbm(DVec2::new(0.5, 0.5), 2, 3)
        );
    }
}
