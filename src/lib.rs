//! verdant: a streaming open-world terrain service with GPU grass, on wgpu.
//!
//! The engine is a library with one front door, [`Renderer`]: it draws a world's terrain and
//! grass into the caller's colour and depth targets, recording every pass into the caller's
//! command encoder (see `examples/embed.rs`). The command-line tools (fly, view, soak, bench,
//! eval, bake) are built on top of it, behind the `cli` feature.
//!
//! Crate map, leaves first:
//! - [`world`]: GPU-free world format: the `world.toml` manifest, [`world::TileId`] quadtree
//!   addressing, stored tiles (EXR heights, PNG grass type and density), DEM reading (GeoTIFF,
//!   SRTM `.hgt`, PNG + sidecar).
//! - [`camera`]: the camera (f64 position, yaw and pitch, or the caller's own matrices) and
//!   sampling of the manifest's camera paths.
//! - [`features`]: the grass model's switchable features.
//! - [`hash`]: the integer hashes (and the value noise on them) that every stage draws its
//!   randomness from: the CPU mirror of `shaders/shared/hash.wgsl`, used by every stage's CPU
//!   mirror.
//! - [`shaders`]: every stage's WGSL, assembled from `shaders/` with the shared pieces
//!   (`shaders/shared/`) included once.
//! - [`gpu`]: what every stage shares: the headless GPU context (adapter choice from `WGPU_*`
//!   variables), buffer and texture readback, timestamp timing, and the set-up vocabulary
//!   (`gpu::layout`: bind group layouts one line a binding; `gpu::pipeline`; `gpu::pass`).
//! - [`stream`]: the tile service: async streamer, CPU cache, the GPU tile atlas, and child
//!   tiles derived on the GPU (with the stage's CPU mirror beside it); worlds streamed over
//!   HTTP (`stream::HttpSource`, feature `http`).
//! - [`lod`]: which terrain tiles a camera needs, at which level, with frustum culling; grass
//!   rings with hysteresis.
//! - [`terrain`]: the terrain and sky passes (`shaders/terrain.wgsl`).
//! - [`grass`]: GPU grass: Hi-Z (`grass::hiz_gpu`, its mirror `grass::hiz`), blade generation
//!   and culling, per-blade wind, the instance pool and the draw; each stage with its CPU
//!   mirror.
//! - [`wind`]: the wind field around the camera (ambient noise, sources, trail) and the sway
//!   springs, on the GPU with their CPU mirrors; the wind scenes of a world made ready to run.
//! - [`bake`]: the baker that turns a DEM into a world (GPU-free; it fits the derived levels'
//!   detail with [`stream::calibrate`]), one module per job: resampling, painting, tiles,
//!   authoring camera paths and wind scenes, publishing.
//! - [`renderer`]: the frame: [`Renderer`], the order of its passes top to bottom in one place.
//! - `tools` (feature `cli`): the headless scene, fly-throughs and their reports, soak,
//!   benchmarks, evaluations, charts and image metrics, the interactive viewer, and `serve`
//!   (a static server of a world folder).

pub mod aa;
pub mod bake;
pub mod camera;
pub mod features;
pub mod gpu;
pub mod grass;
pub mod hash;
pub mod lod;
pub mod renderer;
pub mod shaders;
pub mod stream;
pub mod terrain;
#[cfg(feature = "cli")]
pub mod tools;
pub mod wind;
pub mod world;

pub use camera::Camera;
pub use renderer::{
    ConfigError, FrameInput, FrameStats, GrassConfig, MissingTile, Renderer, RendererConfig,
    RendererError, RendererOptions, WarmUp,
};
pub use world::World;
