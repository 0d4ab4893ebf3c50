//! verdant: a streaming open-world terrain service with GPU grass, on wgpu.
//!
//! The engine is a library with one front door, [`Renderer`]: it draws a world's terrain and
//! grass into the caller's colour and depth targets, recording every pass into the caller's
//! command encoder (see `examples/embed.rs`). The command-line tools (fly, view, soak, bench,
//! eval, bake, serve, check) are built on top of it, behind the `cli` feature: `main.rs` parses the
//! arguments and dispatches, and each command's arguments and printing are in `src/cli/`.
//!
//! Crate map, leaves first:
//! - [`world`]: GPU-free world format: the `world.toml` manifest (its types and reading in
//!   `world/manifest.rs`, the wind scenes and camera paths in `manifest/scenes.rs`, the checks
//!   in `manifest/validate.rs`), [`world::TileId`] quadtree addressing, stored tiles (EXR
//!   heights, PNG grass type and density, and terrain materials, [`world::Material`], where a
//!   land-cover table names them), DEM reading (GeoTIFF, SRTM `.hgt`, PNG + sidecar; many files
//!   joined into one by [`world::mosaic`]).
//! - [`camera`]: the camera (f64 position, yaw and pitch, or the caller's own matrices) and
//!   sampling of the manifest's camera paths.
//! - [`features`]: the switchable features of the grass model and the terrain's look.
//! - [`hash`]: the integer hashes (and the value noise on them) that every stage draws its
//!   randomness from: the CPU mirror of `shaders/shared/hash.wgsl`, used by every stage's CPU
//!   mirror.
//! - [`shaders`]: every stage's WGSL, assembled from `shaders/` with the shared pieces
//!   (`shaders/shared/`) included once.
//! - [`gpu`]: what every stage shares: the headless GPU context (adapter choice from `WGPU_*`
//!   variables), buffer and texture readback, timestamp timing, and the set-up vocabulary
//!   (`gpu::layout`: bind group layouts one line a binding; `gpu::pipeline`; `gpu::pass`).
//! - [`stream`]: the tile service: async streamer, CPU cache, the GPU tile atlas, and child
//!   tiles derived on the GPU (`stream/derive.rs`, mirror [`stream::derive_cpu`]), with each
//!   derived level's detail fitted per world ([`mod@stream::calibrate`]); worlds streamed over
//!   HTTP (`stream::HttpSource`, feature `http`: the requests in `stream/http/client.rs`, the
//!   disk cache in `stream/http/cache.rs`).
//! - [`lod`]: which terrain tiles a camera needs, at which level, with frustum culling; grass
//!   rings with hysteresis.
//! - [`terrain`]: the terrain and sky: the G-buffer, shading and composite passes
//!   (`terrain/mod.rs`), the contact shadows ([`terrain::contact_shadow`], mirror
//!   [`terrain::contact_shadow_cpu`]), the far field's mirror ([`terrain::far_field`]) and the
//!   terrain materials' ([`terrain::material`]: their albedos, water, the sky and the fog).
//! - [`grass`]: GPU grass: Hi-Z ([`grass::hiz`], mirror [`grass::hiz_cpu`]), generation and
//!   culling (`grass/generate.rs`, mirror [`grass::generate_cpu`]), the wind on each blade
//!   (`grass/wind.rs`, mirror [`grass::wind_cpu`]), the draw (`grass/draw.rs`, the blade's shape
//!   mirrored in [`grass::blade`]); the instance pool that records them ([`grass::renderer`]).
//! - [`wind`]: the wind field around the camera (ambient noise, sources, trail;
//!   [`wind::field`], mirror [`wind::field_cpu`]) and the sway springs ([`wind::spring`]) of the
//!   grass and plant types in it ([`wind::sway`], mirror [`wind::sway_cpu`]); the wind scenes of a
//!   world made ready to run.
//! - [`plants`]: plants beyond grass (flowers, ferns, bushes, trees), placed on the GPU per grass tile
//!   and, past the grass, per grass-level tile of the terrain's tiles, and bent by the grass's wind: the vertex record and mesh every plant uses ([`plants::mesh`]),
//!   the procedural recipes ([`plants::recipe`]: flower, fern, bush, and the broadleaf and
//!   conifer trees of `plants/recipe/trees.rs`, at two levels of detail, built of the leaves, tubes and random streams in `plants/recipe/shapes.rs`), their far cards
//!   ([`plants::card`]: crossed cards with a picture rendered from the mesh), a user's plant read
//!   from glTF 2.0 ([`plants::gltf`]: the loader in `gltf/load.rs`, buffers and accessors in
//!   `gltf/accessor.rs`, the document's check in `gltf/validate.rs`, the writer in
//!   `gltf/write.rs`), a world's plant types made ready for the GPU ([`plants::set`]), placement
//!   and culling per job (`plants/place.rs`, mirror [`plants::place_cpu`],
//!   `shaders/plants_place.wgsl`), the draw (`plants/draw.rs`, the bending mirrored in
//!   [`plants::bend_cpu`], `shaders/plants_draw.wgsl`); the instance pool that records them
//!   ([`plants::renderer`]).
//! - [`bake`]: the baker that turns a DEM into a world (GPU-free; it fits the derived levels'
//!   detail with [`mod@stream::calibrate`]), one module per job: resampling, painting (from the
//!   procedural rule or a land-cover map, [`bake::cover`]), tiles, authoring camera paths and
//!   wind scenes, publishing, and sharded bakes for a batch engine ([`bake::shard`]).
//! - [`aa`]: anti-aliasing methods ([`aa::AntiAliasing`]: off, taa, msaa): temporal
//!   ([`aa::taa`], mirror [`aa::taa_cpu`], `shaders/aa_taa.wgsl`) and the grass multisampled
//!   with alpha to coverage ([`aa::msaa`], mirror [`aa::msaa_cpu`], `shaders/aa_msaa.wgsl`).
//! - [`renderer`]: the frame: [`Renderer`], the order of its passes top to bottom in one place
//!   ([`Renderer::record`], `renderer/mod.rs`; the hole check in `renderer/hole_check.rs`, the
//!   figures' readback ring in `renderer/readback.rs`); tile residency and streaming (the tiles a
//!   frame wants, uploads, derivations, [`Renderer::warm_up`], the grass and plant jobs) in
//!   `renderer/streaming.rs`; the frame's records ([`FrameInput`], [`FrameStats`], [`WarmUp`]) in
//!   `renderer/frame.rs`, [`RendererError`] in `renderer/error.rs`, the targets' formats and size
//!   checks in `renderer/targets.rs`; its settings in `renderer/config.rs`
//!   ([`RendererConfig`] with [`GrassConfig`], [`RendererOptions`];
//!   [`RendererConfig::validate`] checks every range once, [`RendererConfig::validate_for`]
//!   those that depend on the world too, called by [`Renderer::new`]); the
//!   frame's view, worked out once in [`Renderer::prepare`] (`renderer/view.rs`,
//!   [`renderer::FrameView`]).
//! - `tools` (feature `cli`): the headless scene, fly-throughs and their reports, soak, the
//!   tools' option ranges (`tools/options.rs`) and output files (`tools/output.rs`: atomic
//!   writes, held output folders), the supersampled truth (`tools/truth.rs`), benchmarks
//!   (`tools/bench.rs` shared, `bench_lod.rs`, `bench_features.rs`, `bench_blades.rs`,
//!   `bench_aa.rs`), evaluations, charts and image metrics (the coarse FLIP in
//!   `tools/metrics/coarse.rs`), the interactive viewer, and `serve` (a static server of a
//!   world folder).
//!
//! GPU stages are named by one rule. A stage `S` of module `M` is set up (its pipelines,
//! bindings and buffers) in `src/M/S.rs`; its CPU mirror, written loop for loop apart from the
//! shader and compared with it by a test, is `src/M/S_cpu.rs` beside it; its shader is
//! `shaders/M_S.wgsl`. Where one file sets up a family of passes that only run together, the
//! file is named after the family and each pass's shader is `shaders/M_PASS.wgsl`: the
//! terrain's G-buffer, shading and composite (`src/terrain/mod.rs`, `shaders/terrain_gbuffer.wgsl`,
//! `terrain_shade.wgsl`, `terrain_composite.wgsl`); the frame's hole check is
//! `src/renderer/hole_check.rs` with `shaders/renderer_hole_check.wgsl`. Anti-aliasing follows it
//! too: `src/aa/taa.rs`, `src/aa/taa_cpu.rs`, `shaders/aa_taa.wgsl`. WGSL included by more than
//! one stage is in `shaders/shared/`, and its Rust mirror is named after what it computes
//! ([`hash`] for `shared/hash.wgsl`, [`terrain::far_field`], `wind_at` in [`wind::field_cpu`]
//! for `shared/wind_lookup.wgsl`). Files that are not stages (settings, records, the pool) keep
//! names of their own.

pub mod aa;
pub mod bake;
pub mod camera;
pub mod features;
pub mod gpu;
pub mod grass;
pub mod hash;
pub mod lod;
pub mod plants;
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
