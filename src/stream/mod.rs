//! The tile service: the streamer (async loads on its own tokio runtime), the CPU cache of
//! decoded tiles, residency in the GPU tile atlas, and child tiles derived from their parents
//! (the GPU stage, `derive_gpu.rs` with `shaders/derive_child.wgsl`, beside its CPU mirror,
//! `derive_child.rs`).

mod atlas;
mod cache;
pub mod derive_child;
mod derive_gpu;
mod residency;
mod service;

pub use atlas::{AtlasError, TileAtlas, pack_grass};
pub use derive_gpu::{DeriveJob, DeriveStage};

pub use cache::{CacheStats, TileCache};
pub use derive_child::{
    DeriveParams, FIT_OCTAVES, HeightField, MAX_LEVELS, OctaveFit, calibrate, derive_child,
    hash_u32, measure_octaves,
};
pub use residency::{ResidencyPlan, ResidencyStats, ServiceConfig, TileService};
pub use service::{Loaded, StreamConfig, StreamStats, Streamer, TileSource, Want};
