//! The tools built on the engine (feature `cli`): the headless [`Scene`] (offscreen targets
//! around a [`crate::Renderer`]), `fly` and its report, `soak`, the benchmarks (`bench lod`,
//! `bench features`), the evaluations (`eval derive`, `eval sway`), charts and image metrics,
//! and the interactive viewer (`view`).

pub mod bench;
pub mod bench_blades;
pub mod eval_derive;
pub mod eval_sway;
pub mod fly;
pub mod metrics;
pub mod report;
pub mod scene;
pub mod soak;
pub mod timing;
pub mod view;

pub use bench::{
    BenchFeaturesReport, BenchLodOptions, BenchLodReport, FeatureResult, LodSetting, lod_settings,
    reference_setting, run_bench_features, run_bench_lod,
};
pub use fly::{FlyOptions, FlyProgress, run_fly, write_json};
pub use report::{AdapterReport, FlyReport, FlySummary, FrameRecord};
pub use scene::{Scene, SceneConfig, SceneError};
pub use soak::{SoakOptions, SoakReport, TeleportRecord, resident_bytes, run_soak};
