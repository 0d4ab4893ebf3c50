//! The tile service: the streamer (async loads on its own tokio runtime), the CPU cache of
//! decoded tiles, residency in the GPU atlas, and child tiles derived from their parents.

mod cache;
mod derive_child;
pub mod eval;
mod residency;
mod service;

pub use cache::{CacheStats, TileCache};
pub use derive_child::{
    DeriveParams, FIT_OCTAVES, HeightField, MAX_LEVELS, OctaveFit, calibrate, derive_child,
    hash_u32, measure_octaves,
};
pub use residency::{ResidencyPlan, ResidencyStats, ServiceConfig, TileService};
pub use service::{Loaded, StreamConfig, StreamStats, Streamer, TileSource, Want};
