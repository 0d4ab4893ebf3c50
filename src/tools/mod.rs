//! The tools built on the engine (feature `cli`): the headless [`Scene`] (offscreen targets
//! around a [`crate::Renderer`]), `fly` and its report, `soak`, the truth the benchmarks
//! measure against (supersampled reference frames), the benchmarks (`bench lod`,
//! `bench features`, `bench blades`), the evaluations (`eval derive`, `eval sway`), charts and image metrics,
//! the interactive viewer (`view`), and `serve`, a static server of a world folder.

pub mod bench;
pub mod bench_aa;
pub mod bench_blades;
pub mod bench_features;
pub mod bench_lod;
pub mod check;
pub mod eval_derive;
pub mod eval_sway;
pub mod fault_proxy;
pub mod faults;
pub mod fly;
pub mod metrics;
pub mod options;
pub mod output;
pub mod report;
pub(crate) mod rng;
pub mod scene;
pub mod serve;
pub mod soak;
pub mod stop;
pub mod sway_integrators;
pub mod timing;
pub mod truth;
pub mod view;

pub use bench::{BenchLodOptions, Measures};
pub use bench_features::{BenchFeaturesReport, FeatureResult, run_bench_features};
pub use bench_lod::{
    BenchLodReport, FAR_BAND_FACTOR, FarBand, FarBandView, LodSetting, lod_settings, run_bench_lod,
};
pub use fly::{FlyOptions, FlyProgress, run_fly, write_json};
pub use report::{AdapterReport, FlyReport, FlySummary, FrameRecord};
pub use scene::{Scene, SceneError};
pub use soak::{SoakFaults, SoakOptions, SoakReport, TeleportRecord, resident_bytes, run_soak};
pub use truth::Truth;

use std::path::Path;
use std::sync::Arc;

use crate::stream::{HttpOptions, HttpSource, TileSource};
use crate::world::World;

/// The `atlas_slots` of a tool's [`crate::stream::ServiceConfig`] that stands for the world's
/// default ([`crate::renderer::default_atlas_slots`]): what the command line passes unless
/// `--atlas-slots` is given.
pub const WORLD_ATLAS_SLOTS: u32 = 0;

/// A tool's `service` limits over `config` (a [`crate::RendererConfig::for_world`]'s): an
/// `atlas_slots` of [`WORLD_ATLAS_SLOTS`] keeps the config's, sized to the world.
pub fn service_over(
    service: crate::stream::ServiceConfig,
    config: &crate::RendererConfig,
) -> crate::stream::ServiceConfig {
    crate::stream::ServiceConfig {
        atlas_slots: if service.atlas_slots == WORLD_ATLAS_SLOTS {
            config.service.atlas_slots
        } else {
            service.atlas_slots
        },
        ..service
    }
}

/// The camera path `name` of `world` (opened from `location`), or its first path when `name`
/// is `None`; a missing one is an error naming the world and the paths it has.
pub fn camera_path(
    world: &World,
    location: &Path,
    name: Option<&str>,
) -> anyhow::Result<crate::world::CameraPath> {
    use anyhow::Context;
    match name {
        Some(name) => world.manifest.path(name).cloned().with_context(|| {
            let paths = &world.manifest.paths;
            format!(
                "world {} has no camera path {name:?} ({})",
                location.display(),
                if paths.is_empty() {
                    "it has none".to_owned()
                } else {
                    format!(
                        "it has: {}",
                        crate::world::name_list(paths.iter().map(|p| p.name.as_str()))
                    )
                }
            )
        }),
        None => world
            .manifest
            .paths
            .first()
            .cloned()
            .with_context(|| format!("world {} has no camera paths", location.display())),
    }
}

/// Checks `--wind SCENE` against `world` before anything is opened or written: the scene must
/// be one of the world's `[[wind_scenes]]`; the error names the option and the scenes the world
/// has (or says that it has none).
pub fn check_wind_option(world: &World, scene: Option<&str>) -> anyhow::Result<()> {
    use anyhow::Context;
    if let Some(name) = scene {
        crate::wind::WindConfig::from_scene(&world.manifest, Some(name)).with_context(|| {
            format!("--wind {name:?}: the option takes the name of one of the world's wind scenes")
        })?;
    }
    Ok(())
}

/// Opens a world and the source of its tiles: its folder, or, when `location` is an `http://`
/// address, the world served there (`stream::HttpSource`).
pub fn open_world(
    location: &Path,
    http: &HttpOptions,
) -> anyhow::Result<(World, Arc<dyn TileSource>)> {
    match location.to_str() {
        Some(url) if crate::stream::http::is_url(url) => {
            let (world, source) = HttpSource::open(url, http.clone())?;
            Ok((world, Arc::new(source)))
        }
        _ => {
            let world = World::open(location)?;
            Ok((world.clone(), Arc::new(world)))
        }
    }
}

/// [`open_world`], given up at once when `stop` is set while a world over HTTP is being
/// fetched (a server that does not answer holds a request up to its deadline, which may be an
/// hour): the world is opened on a thread of its own, left to its request when the stop comes
/// (it ends with its request's deadline and retries: the command line exits before),
/// and [`stop::Stopped`] is returned (the command line exits with status 130). A folder, or
/// no stop, is opened as [`open_world`] opens it.
pub fn open_world_until(
    location: &Path,
    http: &HttpOptions,
    stop: Option<&crate::bake::CancelFlag>,
) -> anyhow::Result<(World, Arc<dyn TileSource>)> {
    let remote = location.to_str().is_some_and(crate::stream::http::is_url);
    use anyhow::Context as _;
    let Some(stop) = stop.filter(|_| remote) else {
        return open_world(location, http);
    };
    let (tx, rx) = std::sync::mpsc::channel();
    let (at, options) = (location.to_path_buf(), http.clone());
    let opener = std::thread::Builder::new()
        .name("open world".into())
        .spawn(move || {
            // The receiver is gone once the run stopped: nothing is left to tell.
            let _ = tx.send(open_world(&at, &options));
        })
        .context("starting the thread that opens the world")?;
    loop {
        match rx.recv_timeout(std::time::Duration::from_millis(50)) {
            Ok(opened) => return opened,
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) if stop.is_cancelled() => {
                return Err(anyhow::Error::new(stop::Stopped).context(format!(
                    "{}: stopped while the world was being fetched",
                    location.display()
                )));
            }
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
            // It panicked: the panic goes on here, as it would have had the world been
            // opened on this thread.
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => match opener.join() {
                Err(panic) => std::panic::resume_unwind(panic),
                Ok(()) => anyhow::bail!(
                    "{}: the thread opening the world ended without an answer",
                    location.display()
                ),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_camera_path_is_found_by_name_or_first_and_a_missing_one_names_the_others() {
        let (world, _) = crate::tools::bench_blades::flat_field(200.0).unwrap();
        let here = Path::new("field");
        let first = camera_path(&world, here, None).unwrap();
        assert_eq!(first.name, world.manifest.paths[0].name);
        let named = camera_path(&world, here, Some(&first.name)).unwrap();
        assert_eq!(named.name, first.name);
        let err = format!("{:#}", camera_path(&world, here, Some("nope")).unwrap_err());
        assert!(
            err.contains("field") && err.contains("\"nope\"") && err.contains(&first.name),
            "{err}"
        );
    }
}
