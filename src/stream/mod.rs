//! The tile service: the streamer (async loads on its own tokio runtime), the CPU cache of
//! decoded tiles, residency in the GPU tile atlas, and child tiles derived from their parents
//! (the GPU stage, `derive.rs` with `shaders/stream_derive.wgsl`, beside its CPU mirror,
//! [`derive_cpu`]), with the detail of each derived level fitted per world by [`mod@calibrate`].
//! With the `http` feature, [`http::HttpSource`] streams a world's tiles from any HTTP server.

mod atlas;
mod cache;
pub mod calibrate;
mod derive;
pub mod derive_cpu;
#[cfg(feature = "http")]
pub mod http;
mod residency;
mod service;

pub use atlas::{AtlasError, TileAtlas, pack_grass};
pub use derive::{DeriveJob, DeriveStage};

pub use cache::{CacheStats, TileCache};
pub use calibrate::{FIT_OCTAVES, HeightField, OctaveFit, calibrate, measure_octaves};
pub use derive_cpu::{DeriveParams, MAX_LEVELS, derive_child, hash_u32};
#[cfg(feature = "http")]
pub use http::{HttpCacheConfig, HttpError, HttpOptions, HttpSource, HttpStats};
pub use residency::{ResidencyPlan, ResidencyStats, ServiceConfig, TileService, fault_retry_delay};
pub use service::{
    Loaded, MAX_LOADS_IN_FLIGHT, StreamConfig, StreamStats, Streamer, TileSource, Want,
};
