//! verdant: a streaming open-world terrain service with GPU grass, on wgpu.
//!
//! Crate map:
//! - [`world`]: GPU-free world format: the `world.toml` manifest, [`world::TileId`] quadtree
//!   addressing, stored tiles (EXR heights, PNG grass type and density) and the DEM baker.
//! - [`stream`]: the tile service: async streamer, CPU cache, atlas residency, derived tiles.
//! - [`lod`]: which terrain tiles a camera needs, at which level, with frustum culling.
//! - [`gpu`]: the headless GPU context (adapter choice from `WGPU_*` variables), the tile atlas,
//!   timestamp timing and readback.
//! - [`grass`]: GPU grass: blade generation and culling (CPU mirrors), the instance pool.
//! - [`terrain`]: the terrain and sky passes (`shaders/terrain.wgsl`).
//! - [`features`]: the grass model's switchable features.
//! - [`flythrough`]: cameras, camera paths, the headless fly-through and its report.
//! - [`metrics`]: percentiles and image error (FLIP).
//! - [`wind`]: the grass sway spring and its integrators (`verdant eval sway`); the wind field
//!   around the camera (ambient noise, sources, trail) on the GPU with its CPU mirror, and the
//!   wind scenes of a world made ready to run.

pub mod features;
pub mod flythrough;
pub mod gpu;
pub mod grass;
pub mod lod;
pub mod metrics;
pub mod stream;
pub mod terrain;
pub mod wind;
pub mod world;
