//! The tile service: the streamer (async loads on its own tokio runtime), the CPU cache of
//! decoded tiles, residency in the GPU tile atlas, and child tiles derived from their parents
//! (the GPU stage, `derive_gpu.rs` with `shaders/derive_child.wgsl`, beside its CPU mirror,
//! `derive_child.rs`). With the `http` feature, [`http::HttpSource`] streams a world's tiles
//! from any HTTP server.

mod atlas;
mod cache;
pub mod derive_child;
mod derive_gpu;
#[cfg(feature = "http")]
pub mod http;
mod residency;
mod service;

pub use atlas::{AtlasError, TileAtlas, pack_grass};
pub use derive_gpu::{DeriveJob, DeriveStage};

pub use cache::{CacheStats, TileCache};
pub use derive_child::{
    DeriveParams, FIT_OCTAVES, HeightField, MAX_LEVELS, OctaveFit, calibrate, derive_child,
    hash_u32, measure_octaves,
};
#[cfg(feature = "http")]
pub use http::{HttpCacheConfig, HttpError, HttpOptions, HttpSource, HttpStats};
pub use residency::{ResidencyPlan, ResidencyStats, ServiceConfig, TileService, fault_retry_delay};
pub use service::{
    Loaded, MAX_LOADS_IN_FLIGHT, StreamConfig, StreamStats, Streamer, TileSource, Want,
};
