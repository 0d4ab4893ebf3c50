//! GPU grass: blades generated and culled per tile in compute into a bounded instance pool,
//! drawn with one indirect draw per tile.
//!
//! Each stage is one file that sets it up, its CPU mirror beside it (`_cpu`), its shader named
//! after the module and the stage:
//! - [`hiz`]: the Hi-Z pyramid of the terrain's depth (`shaders/grass_hiz.wgsl`), the occlusion
//!   the blades are culled against; mirror [`hiz_cpu`].
//! - `generate`: generation and culling per tile (`shaders/grass_generate.wgsl`); mirror
//!   [`generate_cpu`].
//! - `wind`: the wind on each blade (`shaders/grass_wind.wgsl`); mirror [`wind_cpu`].
//! - `draw`: the indirect draw (`shaders/grass_draw.wgsl`); the blade's shape mirrored in
//!   [`blade`].
//!
//! [`renderer`] holds the instance pool and records the stages per batch of tiles; [`blade`]
//! is the blade record and its shape (cubic Bezier, length kept when bent).

pub mod blade;
mod draw;
mod generate;
pub mod generate_cpu;
pub mod hiz;
pub mod hiz_cpu;
pub mod renderer;
mod wind;
pub mod wind_cpu;

pub use blade::{Blade, bezier, bezier_length_estimate, blade_curve, blade_curve_bent};
pub use generate_cpu::{
    GenerateParams, GenerateStats, GrassTypeGpu, HiZ, TileBlades, TileJob, generate_tile,
};
pub use renderer::{
    BATCH_TILES, GrassRenderer, GrassSettings, GrassStats, HiZPyramid, POOL_SLOTS, WindBindings,
};

use crate::world::{World, WorldError};

/// The high-LOD grid's blade spacing by default, metres (the low-LOD grid's is twice this).
pub const DEFAULT_SPACING_M: f32 = 0.25;
/// What every grass type's blade width is scaled by, by default.
pub const DEFAULT_WIDTH_SCALE: f32 = 1.0;

/// The blades a slot must hold: the densest grass tile's count, infill included. A point of the grid carries
/// grass with the densest window's mean density, and grass whose type can be shorter than the
/// split height is counted twice. The density comes from the manifest's `grass_peak`, worked
/// out by the baker for these grass tiles; a world without it (or baked for other grass tiles)
/// has its finest stored tiles read, every window of a grass tile's size looked at, and a tile
/// that cannot be read skipped (it will never be resident, so never generates grass). A tile
/// denser than this at run time is clamped and counted as overflow.
pub fn estimate_capacity(world: &World, settings: &GrassSettings) -> Result<u32, WorldError> {
    let g = settings.grid() as f32;
    // The infill near the camera adds 3 points a cell out to its first radius and 12 more out
    // to its second, of which a frustum (narrower than 180 degrees) sees at most half. Points
    // within the near radius go to the tile's near job, the rest to its own job: a slot holds
    // the larger of the two.
    let [half, quarter] = settings.infill_m.map(|r| r.max(0.0));
    let near = settings.near_m.max(0.0);
    let disc =
        |r: f32| 0.5 * std::f32::consts::PI * r * r / (settings.spacing_m * settings.spacing_m);
    let beyond = |r: f32| disc(r) - disc(r.min(near));
    let tile_job = g * g + 3.0 * beyond(half) + 12.0 * beyond(quarter);
    let near_job = disc(near) + 3.0 * disc(half.min(near)) + 12.0 * disc(quarter.min(near));
    let points = tile_job.max(near_job);
    let blades = |densest: f32| ((points * densest * 1.1).ceil() as u32).max(64);
    let m = &world.manifest;
    if let Some(peak) = &m.grass_peak
        && (peak.window_m - f64::from(settings.tile_m)).abs() <= 1e-6 * peak.window_m
        && peak.short_m == settings.short_m
    {
        return Ok(blades(peak.density));
    }
    Ok(blades(scan_grass_peak(
        world,
        f64::from(settings.tile_m),
        settings.short_m,
    )))
}

/// The densest grass of the finest stored level over windows of `window_m` (see
/// [`crate::world::GrassPeak`]), from the tiles themselves; tiles that cannot be read are
/// skipped (logged).
pub fn scan_grass_peak(world: &World, window_m: f64, short_m: f32) -> f32 {
    use crate::world::grass_density::{split_shares, tile_peak, window_cells};
    let m = &world.manifest;
    let level = m.pyramid.stored_levels - 1;
    let window = window_cells(&m.pyramid, window_m);
    let split = split_shares(&m.grass_types, short_m);
    let mut densest = 0.0f32;
    for id in world.stored_tiles().filter(|t| t.level == level) {
        match world.load_tile(id) {
            Ok(tile) => densest = densest.max(tile_peak(&tile, &m.pyramid, window, &split)),
            Err(e) => log::warn!("grass pool sizing skips a tile that will be a fault: {e}"),
        }
    }
    densest
}
