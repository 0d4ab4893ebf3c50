//! GPU grass: blades generated and culled per tile in compute into a bounded instance pool,
//! drawn with one indirect draw per tile.
//!
//! - [`blade`]: the blade record and its shape (cubic Bezier, length kept when bent).
//! - [`generate`]: the CPU mirror of `shaders/grass_generate.wgsl`.
//! - [`hiz`]: the CPU mirror of `shaders/hiz_build.wgsl` (the occlusion pyramid).
//! - [`wind_pass`]: the CPU mirror of `shaders/grass_wind.wgsl` (the wind on each blade).

pub mod blade;
pub mod generate;
pub mod hiz;
pub mod renderer;
pub mod wind_pass;

pub use blade::{Blade, bezier, bezier_length_estimate, blade_curve, blade_curve_bent};
pub use generate::{
    GenerateParams, GenerateStats, GrassTypeGpu, HiZ, TileBlades, TileJob, generate_tile,
};
pub use renderer::{
    BATCH_TILES, GrassRenderer, GrassSettings, GrassStats, HiZPyramid, POOL_SLOTS, WindBindings,
};

use crate::world::{World, WorldError};

/// The blades a slot must hold: the densest grass tile's count, estimated from the finest stored
/// level. Every window of a grass tile's size is looked at; a point of the grid carries grass
/// with the window's mean density, and grass whose type can be shorter than the split height is
/// counted twice. A tile denser than this at run time is clamped and counted as overflow.
pub fn estimate_capacity(world: &World, settings: &GrassSettings) -> Result<u32, WorldError> {
    let m = &world.manifest;
    let level = m.pyramid.stored_levels - 1;
    let cell = m.pyramid.cell_size_m(level) as f32;
    let window = ((settings.tile_m / cell).round() as u32).max(1);
    // Largest share of blades that are split, per type: 1 if any blade of the type can be
    // shorter than the split height (heights shrink to 0.35 of the range with clump and density).
    let split: Vec<f32> = m
        .grass_types
        .iter()
        .map(|t| {
            if t.height_m[0] * 0.35 < settings.short_m {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    let mut densest = 0.0f32;
    for id in world.stored_tiles().filter(|t| t.level == level) {
        let tile = world.load_tile(id)?;
        let b = m.pyramid.border;
        let n = m.pyramid.tile_cells;
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
    }
    let g = settings.grid() as f32;
    Ok(((g * g * densest * 1.1).ceil() as u32).max(64))
}
