//! Headless fly-throughs: a camera path rendered frame by frame to PNG, with a JSON report of
//! what each frame drew and what it cost.

use std::collections::{BTreeMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::{Arc, mpsc};
use std::time::Instant;

use anyhow::{Result, bail};

use crate::camera::{sample_path, walker_at};
use crate::gpu::GpuContext;
use crate::renderer::WarmUp;
use crate::stream::TileSource;
use crate::tools::metrics::{COVERAGE_DISTANCE_M, Summary};
use crate::tools::report::{
    AdapterReport, CoverageRecord, FlyReport, FlySummary, FlyTotals, FrameRecord,
    MAX_REPORT_FRAMES, Thinned,
};

use crate::renderer::{ConfigError, DEFAULT_MESH_STEP, GrassConfig, RendererConfig};
use crate::tools::scene::Scene;
use crate::world::World;

// The option checks and output files that every tool shares, at the paths they had when
// they lived here.
pub use crate::tools::options::{MAX_IMAGE_SIDE, OptionError, check_range, check_size};
pub use crate::tools::output::{
    LOCK_FILE, OutDir, OutDirError, Outputs, WriteError, write_atomic, write_json, write_png,
    write_text,
};

/// Frames whose grass coverage a fly-through without images measures: evenly spaced over the
/// path, drawn again after the flight (never among the timed frames).
pub const COVERAGE_FRAMES: u32 = 8;

/// What `verdant fly` is asked to do.
#[derive(Clone, Debug)]
pub struct FlyOptions {
    /// The world's folder, or its `http://` address.
    pub world: PathBuf,
    /// How a world over HTTP is fetched.
    pub http: crate::stream::HttpOptions,
    /// Camera path name; the manifest's first path when `None`.
    pub path: Option<String>,
    /// Frames to render, spread evenly over the path's duration.
    pub frames: u32,
    /// Image width and height.
    pub size: (u32, u32),
    /// Output folder for the PNG frames and `report.json`.
    pub out: PathBuf,
    /// Write a PNG for every frame (the report is always written).
    pub write_images: bool,
    /// Limits of the tile service; `atlas_slots` [`super::WORLD_ATLAS_SLOTS`] sizes the atlas to
    /// the world.
    pub service: crate::stream::ServiceConfig,
    /// Wind scene of the manifest for the whole flight (default: the path's wind keys if it has
    /// any, else `breeze`, else the manifest's wind).
    pub wind_scene: Option<String>,
    /// Features of the grass model to switch off, on top of the manifest's `[features]`.
    pub disable: Vec<crate::features::Feature>,
    /// Features to switch on that the manifest switches off.
    pub enable: Vec<crate::features::Feature>,
    /// The grass's settings (default: the renderer's).
    pub grass: GrassConfig,
    /// The grass's view distance, metres (`None`: the renderer's, [`crate::lod::DEFAULT_VIEW_TILES`]
    /// grass tiles).
    pub grass_view_m: Option<f64>,
    /// Terrain mesh step in samples (default: the renderer's).
    pub mesh_step: u32,
    /// How the frames are anti-aliased (default: the renderer's).
    pub aa: crate::aa::AntiAliasing,
    /// The temporal anti-aliasing's settings (with `aa` taa).
    pub taa: crate::aa::taa::TaaSettings,
    /// Distances of the plants' switches from the full mesh to the reduced one and from that
    /// to the cards, metres (default: the renderer's).
    pub plant_lod_m: [f32; 2],
    /// How far plants reach beyond the grass, in view distances (default: the renderer's).
    pub plant_card_reach: f32,
    /// Where plants start to thin out with distance, metres (default: the renderer's).
    pub plant_thin_m: f32,
    /// The trees' level-of-detail switches, metres (default: the renderer's).
    pub tree_lod_m: Option<[f32; 2]>,
    /// Where trees start to thin out with distance, metres (default: the renderer's).
    pub tree_thin_m: Option<f32>,
    /// The fewest trees the thinning keeps (default: the renderer's).
    pub tree_min_keep: Option<f32>,
    /// The trees' shadows (used where the renderer has them: a world with trees).
    pub tree_shadows: crate::plants::shadow::TreeShadows,
    /// A flag that ends the flight early (Ctrl-C on the command line): the frames flown so far
    /// are written and reported, the report marked [`FlyReport::interrupted`].
    pub stop: Option<crate::bake::CancelFlag>,
}

/// Progress of a fly-through, for a progress bar.
pub enum FlyProgress {
    /// The tiles of the first frame are loading.
    WarmingUp,
    /// The warm-up ended with tiles missing (one line each); the run goes on without them.
    WarmUpIncomplete(Vec<String>),
    /// Frames rendered so far, of a total.
    Frame(u64, u64),
    /// Frame images in the output folder that this run does not write (an earlier run's):
    /// how many, and the first and last of their names.
    StaleFrames(usize, String, String),
    /// The other kind of run's report in the output folder (`truth.json` beside a flight's
    /// frames, `report.json` beside the truth's), describing frames this run writes over.
    StaleReport(&'static str),
}

/// Tells `progress` of what an earlier run left in `out` that this one, writing `frames` frame
/// images, leaves beside them: frame images past them, and `other_report` (the other kind of
/// run's report) when it writes any.
pub fn warn_of_stale_outputs(
    out: &Path,
    frames: u32,
    other_report: &'static str,
    progress: &mut dyn FnMut(FlyProgress),
) {
    let stale = stale_frames(out, frames);
    if let (Some(first), Some(last)) = (stale.first(), stale.last()) {
        progress(FlyProgress::StaleFrames(
            stale.len(),
            first.clone(),
            last.clone(),
        ));
    }
    if frames > 0 && out.join(other_report).exists() {
        progress(FlyProgress::StaleReport(other_report));
    }
}

/// The name of frame `i`'s image: `frame_00042.png`.
pub fn frame_file_name(i: u32) -> String {
    format!("frame_{i:05}.png")
}

/// The index of the frame image named `name`, if it is one ([`frame_file_name`]).
pub fn frame_index(name: &str) -> Option<u32> {
    let i = name
        .strip_prefix("frame_")?
        .strip_suffix(".png")?
        .parse()
        .ok()?;
    (frame_file_name(i) == name).then_some(i)
}

/// The frame images (`frame_NNNNN.png`) in `dir` that a run writing `written` of them leaves as
/// they were, by name, in order.
pub fn stale_frames(dir: &Path, written: u32) -> Vec<String> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut stale: Vec<String> = entries
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|name| {
            name.strip_prefix("frame_")
                .and_then(|n| n.strip_suffix(".png"))
                .filter(|n| n.len() >= 5 && n.bytes().all(|b| b.is_ascii_digit()))
                .and_then(|n| n.parse::<u64>().ok())
                .is_some_and(|i| i >= u64::from(written))
        })
        .collect();
    stale.sort();
    stale
}

/// A written frame whose camera moved farther than this since the last frame waits for its
/// tiles (metres: half a grass tile of the default world, more than a path covers in a frame
/// at 60 fps and any sensible speed).
const WAIT_JUMP_M: f64 = 25.0;
/// The longest a written frame waits for its tiles.
const FRAME_TILE_WAIT: std::time::Duration = std::time::Duration::from_secs(30);

fn path_start_position(path: &crate::world::CameraPath) -> glam::DVec3 {
    sample_path(path, path.start_s()).position
}

/// The longest the first frame waits for its tiles.
pub const FIRST_FRAME_WAIT: std::time::Duration = std::time::Duration::from_secs(60);

impl Default for FlyOptions {
    /// The command line's defaults: the default world's first path, 240 frames at 640x360
    /// into `out/fly`, the renderer's own grass settings.
    fn default() -> Self {
        Self {
            world: PathBuf::from("worlds/santa-cruz"),
            http: Default::default(),
            path: None,
            frames: 240,
            size: (640, 360),
            out: PathBuf::from("out/fly"),
            write_images: true,
            service: Default::default(),
            wind_scene: None,
            disable: Vec::new(),
            enable: Vec::new(),
            grass: GrassConfig::default(),
            grass_view_m: None,
            mesh_step: DEFAULT_MESH_STEP,
            aa: Default::default(),
            taa: Default::default(),
            plant_lod_m: crate::plants::PlantSettings::default().lod_m,
            plant_card_reach: crate::plants::PlantSettings::default().card_reach,
            plant_thin_m: crate::plants::PlantSettings::default().thin_m,
            tree_lod_m: None,
            tree_thin_m: None,
            tree_min_keep: None,
            tree_shadows: Default::default(),
            stop: None,
        }
    }
}

impl FlyOptions {
    /// Checks the fly-through's own numeric options against their range (stated in the
    /// error), before anything is opened or written: `--frames` 1..=4294967295, `--size`
    /// 1..=16384 pixels a side. The renderer's settings are checked by
    /// [`RendererConfig::validate`] (see [`FlyOptions::renderer_config`]).
    pub fn validate(&self) -> Result<(), OptionError> {
        if self.frames == 0 {
            return Err(OptionError::new("--frames", 0, "in 1..=4294967295"));
        }
        check_size("--size", self.size)
    }

    /// The renderer's settings for flying `path` through `world`, checked by
    /// [`RendererConfig::validate_for`]; a setting out of its range names its command-line
    /// option.
    pub fn renderer_config(
        &self,
        world: &World,
        path: &crate::world::CameraPath,
    ) -> Result<RendererConfig, SettingError> {
        let mut config = RendererConfig::for_world(world);
        config.service = super::service_over(self.service, &config);
        config.wind_scene = self.wind_scene.clone();
        config.wind_keys = path.wind.clone();
        config.features = config.features.switched(&self.disable, &self.enable);
        config.grass = self.grass;
        if let (Some(m), Some(rings)) = (self.grass_view_m, config.grass_rings.as_mut()) {
            rings.low_radius_m = m;
        }
        config.mesh_step = self.mesh_step;
        config.aa = self.aa;
        config.taa = self.taa;
        config.plants.lod_m = self.plant_lod_m;
        config.plants.card_reach = self.plant_card_reach;
        config.plants.thin_m = self.plant_thin_m;
        if let Some(mut t) = config.tree_settings(world) {
            t.lod_m = self.tree_lod_m.unwrap_or(t.lod_m);
            t.thin_m = self.tree_thin_m.unwrap_or(t.thin_m);
            t.min_keep = self.tree_min_keep.unwrap_or(t.min_keep);
            config.trees = Some(t);
        }
        if config.tree_shadows.is_some() {
            config.tree_shadows = Some(self.tree_shadows);
        }
        // What depends on the world too (the rings' reach in its grass tiles), so that a
        // setting out of range there names its option as well.
        config.validate_for(world).map_err(SettingError::from)?;
        Ok(config)
    }
}

/// A renderer setting out of its range, with the command-line option that sets it.
#[derive(Debug, thiserror::Error)]
#[error("{option}: {source}")]
pub struct SettingError {
    /// The option, e.g. `--grass-segments` (the setting's field where no option sets it).
    pub option: &'static str,
    /// What is wrong, with the range.
    #[source]
    pub source: ConfigError,
}

impl From<ConfigError> for SettingError {
    fn from(source: ConfigError) -> Self {
        let option = match source.field {
            "grass.spacing_m" => "--grass-spacing-m",
            "grass.width_scale" => "--grass-width-scale",
            "grass.infill_m" => "--grass-infill-m",
            "grass.segments" => "--grass-segments",
            "grass.near_m" => "--grass-near-m",
            "grass.lod_widen" => "--grass-lod-widen",
            "grass.elevation_fade" => "--grass-elevation-fade",
            "grass_rings.low_radius_m" => "--grass-view-m",
            "mesh_step" => "--mesh-step",
            "plants.lod_m" => "--plant-lod-m",
            "plants.card_reach" => "--plant-card-reach",
            "plants.thin_m" => "--plant-thin-m",
            "trees.lod_m" => "--tree-lod-m",
            "trees.thin_m" => "--tree-thin-m",
            "trees.min_keep" => "--tree-min-keep",
            "tree_shadows.distance_m" => "--tree-shadow-m",
            "tree_shadows.size" => "--tree-shadow-size",
            "tree_shadows.cascades" => "--tree-shadow-cascades",
            "tree_shadows.lod_m" => "--tree-shadow-lod-m",
            "taa.max_samples" => "--taa-samples",
            "taa.clip_sigma" => "--taa-clip",
            "taa.motion_falloff" => "--taa-falloff",
            "taa.pixel_spread" => "--taa-pixel-spread",
            "taa.parallax_falloff" => "--taa-parallax-falloff",
            "taa.sway_falloff" => "--taa-sway-falloff",
            "taa.min_samples" => "--taa-min-samples",
            "taa.reconstruct_px" => "--taa-reconstruct",
            field => field,
        };
        Self { option, source }
    }
}

/// Runs a fly-through and writes its frames and `report.json` into `opts.out`.
pub fn run_fly(opts: &FlyOptions, progress: &mut dyn FnMut(FlyProgress)) -> Result<FlyReport> {
    opts.validate()?;
    let (world, source) =
        crate::tools::open_world_until(&opts.world, &opts.http, opts.stop.as_ref())?;
    run_fly_with_source(opts, world, source, FIRST_FRAME_WAIT, progress)
}

/// Like [`run_fly`], on a world already opened with its tiles from `source` (`opts.world` and
/// `opts.http` only name it), the first frame waiting at most `first_frame_wait` for its tiles.
/// Tests use this with sources that are slow or failing on purpose.
pub fn run_fly_with_source(
    opts: &FlyOptions,
    world: World,
    source: Arc<dyn TileSource>,
    first_frame_wait: std::time::Duration,
    progress: &mut dyn FnMut(FlyProgress),
) -> Result<FlyReport> {
    opts.validate()?;
    let path = crate::tools::camera_path(&world, &opts.world, opts.path.as_deref())?;
    // Checked before anything is written.
    crate::tools::check_wind_option(&world, opts.wind_scene.as_deref())?;
    let config = opts.renderer_config(&world, &path)?;
    let frames = if opts.write_images { opts.frames } else { 0 };
    let out_dir = OutDir::create_for(
        &opts.out,
        "fly",
        &Outputs::matching(|n| n == "report.json" || frame_index(n).is_some_and(|i| i < frames)),
    )?;
    warn_of_stale_outputs(&opts.out, frames, "truth.json", progress);

    let ctx = GpuContext::new()?;
    let world_name = world.manifest.name.clone();
    let (width, height) = opts.size;
    let mut scene = Scene::with_source(&ctx, world, source, width, height, config)?;
    // The first frame starts with its tiles resident; after that, streaming keeps up or the
    // report shows that it did not.
    // A stop asked for (Ctrl-C) ends the warm-up too, and then the run before its first frame.
    let stopped = || opts.stop.as_ref().is_some_and(|s| s.is_cancelled());
    progress(FlyProgress::WarmingUp);
    let first_camera = sample_path(&path, path.start_s());
    let warm_up = scene.warm_up_until(&first_camera, first_frame_wait, &stopped)?;
    let mut warm_up_missing = Vec::new();
    if !stopped() {
        check_streaming(
            &opts.world,
            &scene.world().manifest.pyramid,
            &scene.service().stats(),
            &warm_up,
        )?;
        warm_up_missing = warm_up.describe(20);
        if !warm_up_missing.is_empty() {
            progress(FlyProgress::WarmUpIncomplete(warm_up_missing.clone()));
        }
    }

    // PNG encoding runs beside the renderer; the bounded channel keeps at most a few frames queued.
    let (tx, rx) = mpsc::sync_channel::<(PathBuf, image::RgbaImage)>(4);
    let writer = std::thread::spawn(move || -> Result<()> {
        for (file, img) in rx {
            write_png(&file, &img)?;
        }
        Ok(())
    });

    // Bounded whatever --frames asks for: an evenly spaced sample of at most MAX_REPORT_FRAMES.
    let mut records = Records {
        kept: Thinned::new(MAX_REPORT_FRAMES),
        totals: FlyTotals::default(),
    };
    let last = (opts.frames.max(2) - 1) as f64;
    // Without images nothing needs a frame back: frames are submitted as an application
    // submits them, at most FRAMES_IN_FLIGHT ahead of the GPU, and their figures are taken as
    // they come back. With images, each frame is waited for and read back.
    let mut waiting: VecDeque<FrameRecord> = VecDeque::new();
    // With images, the grass coverage of every frame written (read back like its image).
    let mut coverage = Thinned::new(MAX_REPORT_FRAMES);
    scene.set_coverage_capture(opts.write_images)?;
    let mut last_position = path_start_position(&path);
    let mut interrupted = false;
    for i in 0..opts.frames {
        if stopped() {
            interrupted = true;
            break;
        }
        let t_s = path.time_at(f64::from(i) / last);
        let camera = sample_path(&path, t_s);
        // Frames written far apart along the path (a short fly-through) wait, boundedly, for
        // the tiles they need: each picture shows the world at full detail where its camera
        // stands, not what streaming could catch up with in one frame.
        let mut wait = (0.0, 0u32);
        if opts.write_images && camera.position.distance(last_position) > WAIT_JUMP_M {
            let waited = Instant::now();
            let report = scene.warm_up_until(&camera, FRAME_TILE_WAIT, &stopped)?;
            wait = (
                waited.elapsed().as_secs_f64() * 1e3,
                report.missing.len() as u32,
            );
        }
        last_position = camera.position;
        let start = Instant::now();
        let walker_xy = walker_at(&scene.world().manifest, &path, t_s);
        let mut record = FrameRecord {
            index: i,
            t_s,
            camera_m: camera.position.to_array(),
            walker_m: walker_xy.to_array(),
            wind_scene: scene.wind_scene_at(t_s),
            tile_wait_ms: wait.0,
            tiles_missing_after_wait: wait.1,
            ..FrameRecord::default()
        };
        if opts.write_images {
            let stats = scene.render_frame(&ctx, &camera, t_s, Some(walker_xy))?;
            let image = scene.read_image(&ctx)?;
            record.frame_ms = start.elapsed().as_secs_f64() * 1e3;
            record.fill(stats);
            records.push(record);
            let c = scene.coverage(&ctx, COVERAGE_DISTANCE_M)?;
            coverage.push(CoverageRecord {
                index: i,
                t_s,
                coverage: c.fraction,
                pixels: c.pixels,
                covered: c.covered,
            });
            let file = opts.out.join(frame_file_name(i));
            if tx.send((file, image)).is_err() {
                break; // the writer failed; its error is reported below
            }
        } else {
            scene.submit_frame(&ctx, &camera, t_s, Some(walker_xy))?;
            record.frame_ms = start.elapsed().as_secs_f64() * 1e3;
            waiting.push_back(record);
            take_figures(&mut scene, &mut waiting, &mut records)?;
        }
        progress(FlyProgress::Frame(u64::from(i) + 1, u64::from(opts.frames)));
    }
    ctx.wait_idle();
    take_figures(&mut scene, &mut waiting, &mut records)?;
    if let Some(r) = waiting.front() {
        bail!(
            "the figures of frame {} did not come back from the GPU",
            r.index
        );
    }
    drop(tx);
    writer
        .join()
        .map_err(|_| anyhow::anyhow!("the frame writer thread panicked"))??;
    // Without images, the coverage of a few frames drawn again after the timed flight, each
    // after a warm-up (it is a jump back along the path); not after an interrupted one, and
    // cut short by a stop asked for meanwhile.
    interrupted |= stopped();
    if !opts.write_images && !interrupted {
        scene.set_coverage_capture(true)?;
        let n = opts.frames.min(COVERAGE_FRAMES);
        let span = f64::from(opts.frames - 1);
        for k in 0..n {
            if stopped() {
                interrupted = true;
                break;
            }
            let i = if n > 1 {
                (span * f64::from(k) / f64::from(n - 1)).round() as u32
            } else {
                0
            };
            let t_s = path.time_at(f64::from(i) / last);
            let camera = sample_path(&path, t_s);
            scene.warm_up_until(&camera, std::time::Duration::from_secs(30), &stopped)?;
            let walker_xy = walker_at(&scene.world().manifest, &path, t_s);
            scene.render_frame(&ctx, &camera, t_s, Some(walker_xy))?;
            let c = scene.coverage(&ctx, COVERAGE_DISTANCE_M)?;
            coverage.push(CoverageRecord {
                index: i,
                t_s,
                coverage: c.fraction,
                pixels: c.pixels,
                covered: c.covered,
            });
        }
    }
    scene.set_coverage_capture(false)?;

    let mut report = FlyReport::new(
        world_name,
        path.name.clone(),
        opts.size,
        AdapterReport::of(&ctx),
        records.kept,
        records.totals,
    );
    report.warm_up_missing = warm_up_missing;
    report.interrupted = interrupted;
    report.coverage = coverage.into_items();
    let fractions: Vec<f64> = report.coverage.iter().map(|c| c.coverage).collect();
    report.summary.coverage = Summary::of(&fractions);
    write_json(&opts.out.join("report.json"), &report)?;
    out_dir.keep();
    Ok(report)
}

/// The frame records of a fly-through: a bounded sample, and tallies over every frame.
struct Records {
    kept: Thinned<FrameRecord>,
    totals: FlyTotals,
}

impl Records {
    fn push(&mut self, record: FrameRecord) {
        self.totals.add(&record);
        self.kept.push(record);
    }
}

/// Completes the waiting records (oldest first) with the figures that came back.
fn take_figures(
    scene: &mut Scene,
    waiting: &mut VecDeque<FrameRecord>,
    records: &mut Records,
) -> Result<()> {
    for stats in scene.renderer().take_stats() {
        if let Some(mut r) = waiting.pop_front() {
            if u64::from(r.index) != stats.frame {
                bail!(
                    "the figures of frame {} did not come back from the GPU",
                    r.index
                );
            }
            r.fill(stats);
            records.push(r);
        }
    }
    Ok(())
}

/// The warning for a run of which no frame drew any terrain (its camera outside the world, or
/// looking away from it), given the most terrain tiles a frame drew; `None` where a frame drew
/// some. `camera` says where the run's camera was. `fly` and `view` both warn with it.
pub fn no_terrain_drawn(most_tiles_drawn: u32, camera: &str) -> Option<String> {
    (most_tiles_drawn == 0).then(|| {
        format!(
            "no frame drew any terrain: the camera path runs outside the world or looks away \
             from it ({camera})"
        )
    })
}

/// Fails when a warm-up ended with tiles missing and not one tile beyond the level-0 tiles
/// (resident from the start) became resident: streaming delivered nothing, and a run would
/// draw the coarsest terrain only while reporting success.
pub fn check_streaming(
    world: &Path,
    pyramid: &crate::world::Pyramid,
    stats: &crate::stream::ResidencyStats,
    warm_up: &WarmUp,
) -> Result<(), NothingStreamed> {
    let [nx, ny] = pyramid.tiles_at(0);
    if warm_up.missing.is_empty() || u64::from(stats.atlas_used) > u64::from(nx) * u64::from(ny) {
        return Ok(());
    }
    Err(NothingStreamed {
        world: world.to_path_buf(),
        missing: warm_up.missing.len(),
        first: warm_up.describe(3),
    })
}

/// A run whose tile streaming delivered nothing (see [`check_streaming`]).
#[derive(Debug, thiserror::Error)]
#[error(
    "world {}: no tile became resident beyond the level-0 tiles: the {missing} other tiles \
     the first frame wants never loaded ({}); check the world's tiles and --max-loads",
    world.display(),
    first.join("; ")
)]
pub struct NothingStreamed {
    /// The world, as given.
    pub world: PathBuf,
    /// Wanted tiles that are not resident.
    pub missing: usize,
    /// The first few of them, each with the reason.
    pub first: Vec<String>,
}

impl FlySummary {
    /// Summarises the frames of a fly-through.
    pub fn of(frames: &[FrameRecord]) -> Self {
        let series = |f: &dyn Fn(&FrameRecord) -> f64| frames.iter().map(f).collect::<Vec<f64>>();
        // A plant layer's figure over the frames that drew the layer.
        let layer = |f: &dyn Fn(&FrameRecord) -> Option<u32>| {
            Summary::of(
                &frames
                    .iter()
                    .filter_map(|r| f(r).map(f64::from))
                    .collect::<Vec<_>>(),
            )
        };
        let mut gpu_ms = BTreeMap::new();
        let passes: std::collections::BTreeSet<&String> =
            frames.iter().flat_map(|f| f.gpu_ms.keys()).collect();
        for pass in passes {
            let v: Vec<f64> = frames
                .iter()
                .filter_map(|f| f.gpu_ms.get(pass).copied())
                .collect();
            gpu_ms.insert(pass.clone(), Summary::of(&v));
        }
        Self {
            frame_ms: Summary::of(&series(&|f| f.frame_ms)),
            cpu_ms: Summary::of(&series(&|f| f.cpu_ms)),
            gpu_ms,
            tiles_drawn: Summary::of(&series(&|f| f64::from(f.tiles_drawn))),
            resident_fraction: Summary::of(&series(&|f| f.residency.resident_fraction)),
            holes: frames.iter().map(|f| u64::from(f.residency.holes)).sum(),
            cache_peak_bytes: frames
                .iter()
                .map(|f| f.residency.cache.peak_bytes)
                .max()
                .unwrap_or(0),
            atlas_peak_slots: frames
                .iter()
                .map(|f| f.residency.atlas_used)
                .max()
                .unwrap_or(0),
            atlas_peak_held: frames.iter().map(|f| f.residency.held).max().unwrap_or(0),
            grass_considered: Summary::of(&series(&|f| {
                f64::from(f.grass.considered[0]) + f64::from(f.grass.considered[1])
            })),
            grass_drawn_high: Summary::of(&series(&|f| f64::from(f.grass.drawn[0]))),
            grass_drawn_low: Summary::of(&series(&|f| f64::from(f.grass.drawn[1]))),
            grass_overflow: Summary::of(&series(&|f| {
                f64::from(f.grass.overflow[0]) + f64::from(f.grass.overflow[1])
            })),
            coverage: Summary::default(),
            plants_drawn: layer(&|f| f.plants.map(|p| p.drawn)),
            plants_overflow: layer(&|f| f.plants.map(|p| p.overflow)),
            plants_crowded: layer(&|f| f.plants.map(|p| p.crowded)),
            trees_drawn: layer(&|f| f.trees.map(|p| p.drawn)),
            trees_overflow: layer(&|f| f.trees.map(|p| p.overflow)),
            trees_crowded: layer(&|f| f.trees.map(|p| p.crowded)),
        }
    }
}
#[cfg(test)]
mod tests {
    use super::*;

    fn fly_options() -> FlyOptions {
        FlyOptions {
            world: PathBuf::from("w"),
            frames: 1,
            size: (64, 36),
            out: PathBuf::from("o"),
            write_images: false,
            ..FlyOptions::default()
        }
    }

    #[test]
    fn fly_options_out_of_range_name_the_option_and_the_range() {
        fly_options().validate().unwrap();
        let cases: Vec<(FlyOptions, &str, &str)> = vec![
            (
                FlyOptions {
                    frames: 0,
                    ..fly_options()
                },
                "--frames 0",
                "1..=4294967295",
            ),
            (
                FlyOptions {
                    size: (0, 36),
                    ..fly_options()
                },
                "--size 0x36",
                "1..=16384",
            ),
            (
                FlyOptions {
                    size: (64, 16385),
                    ..fly_options()
                },
                "--size 64x16385",
                "1..=16384",
            ),
        ];
        for (opts, option, range) in cases {
            let e = opts.validate().unwrap_err().to_string();
            assert!(e.contains(option) && e.contains(range), "{e}");
        }
        // The largest frame count is taken (frames are spaced in f64 and counted in u64).
        FlyOptions {
            frames: u32::MAX,
            ..fly_options()
        }
        .validate()
        .unwrap();
    }

    /// The grass options and the mesh step are checked once, by the renderer's own
    /// `RendererConfig::validate`; the error names the option that sets the value, and the
    /// range, before anything is written.
    #[test]
    fn renderer_settings_out_of_range_name_the_option_and_the_range() {
        let world =
            World::open(&Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/santa-cruz")).unwrap();
        let path = world.manifest.paths[0].clone();
        let config = fly_options().renderer_config(&world, &path).unwrap();
        // The grass's view distance: the renderer's unless given.
        let rings = config.grass_rings.unwrap();
        assert_eq!(
            rings,
            RendererConfig::for_world(&world).grass_rings.unwrap()
        );
        let far = FlyOptions {
            grass_view_m: Some(100.0),
            ..fly_options()
        }
        .renderer_config(&world, &path)
        .unwrap();
        let far_rings = far.grass_rings.unwrap();
        assert_eq!(far_rings.low_radius_m, 100.0);
        assert_eq!(far_rings.high_radius_m, rings.high_radius_m);
        let trees = config
            .trees
            .expect("the trees' settings, for the world's grass");
        assert_eq!(trees.lod_m, [60.0, 300.0]);
        assert_eq!(trees.thin_m, crate::plants::renderer::TREE_THIN_M);
        let set = FlyOptions {
            tree_lod_m: Some([20.0, 90.0]),
            tree_min_keep: Some(0.25),
            ..fly_options()
        };
        let trees = set.renderer_config(&world, &path).unwrap().trees.unwrap();
        assert_eq!((trees.lod_m, trees.min_keep), ([20.0, 90.0], 0.25));
        let with = |f: &dyn Fn(&mut FlyOptions)| {
            let mut o = fly_options();
            f(&mut o);
            o
        };
        let cases: Vec<(FlyOptions, &str, &str)> = vec![
            (
                with(&|o| o.grass.spacing_m = f32::NAN),
                "--grass-spacing-m",
                "0.02..=5 m",
            ),
            (
                with(&|o| o.grass.width_scale = f32::INFINITY),
                "--grass-width-scale",
                "0.05..=20",
            ),
            (
                with(&|o| o.grass.infill_m = [1.0, -1.0]),
                "--grass-infill-m",
                "0..=100 m each",
            ),
            (
                with(&|o| o.grass.infill_m = [5.0, 10.0]),
                "--grass-infill-m",
                "no larger than the half-spacing one",
            ),
            (
                with(&|o| o.plant_lod_m = [45.0, 18.0]),
                "--plant-lod-m",
                "0 < NEAR <= FAR <= 10000 m",
            ),
            (
                with(&|o| o.plant_lod_m = [f32::NAN, 18.0]),
                "--plant-lod-m",
                "0 < NEAR <= FAR <= 10000 m",
            ),
            (
                with(&|o| o.grass.segments = [1, 0, 3]),
                "--grass-segments",
                "1..=64 each",
            ),
            (
                with(&|o| o.grass.near_m = 1e30),
                "--grass-near-m",
                "0..=200 m",
            ),
            (
                with(&|o| o.grass.lod_widen = 0.5),
                "--grass-lod-widen",
                "1..=4",
            ),
            (
                with(&|o| o.grass.elevation_fade = -1.0),
                "--grass-elevation-fade",
                "0..=8 m a metre",
            ),
            (with(&|o| o.mesh_step = 0), "--mesh-step", "1..=16"),
            (with(&|o| o.mesh_step = 32), "--mesh-step", "1..=16"),
            (
                with(&|o| o.tree_lod_m = Some([200.0, 100.0])),
                "--tree-lod-m",
                "0 < NEAR <= FAR <= 10000 m",
            ),
            (
                with(&|o| o.tree_thin_m = Some(-1.0)),
                "--tree-thin-m",
                "at most 10000 m",
            ),
            (
                with(&|o| o.tree_min_keep = Some(0.0)),
                "--tree-min-keep",
                "above 0, at most 1",
            ),
            (
                with(&|o| o.tree_shadows.size = 100),
                "--tree-shadow-size",
                "tree_shadows.size = 100 is out of range: it must be 256 to 8192 texels",
            ),
            (
                with(&|o| o.tree_shadows.cascades = 5),
                "--tree-shadow-cascades",
                "= 5 is out of range: it must be 1 to 4",
            ),
            (
                with(&|o| o.tree_shadows.distance_m = f32::NAN),
                "--tree-shadow-m",
                "10 to 2000 m",
            ),
            (
                with(&|o| o.tree_shadows.lod_m = [30.0, 20.0]),
                "--tree-shadow-lod-m",
                "= 30,20 is out of range: it must be NEAR,FAR with 0 <= NEAR <= FAR <= 10000 m",
            ),
        ];
        for (opts, option, range) in cases {
            let e = opts.renderer_config(&world, &path).unwrap_err();
            assert_eq!(e.option, option);
            let text = e.to_string();
            assert!(text.contains(option) && text.contains(range), "{text}");
        }
        // What depends on the world names its option too: in a world of grass tiles 64 times
        // finer, a view the default world takes reaches too many of them.
        let mut fine = world.clone();
        fine.manifest.pyramid.derived_levels += 6;
        let e = FlyOptions {
            grass_view_m: Some(100.0),
            ..fly_options()
        }
        .renderer_config(&fine, &path)
        .unwrap_err();
        assert_eq!(e.option, "--grass-view-m");
        assert!(e.to_string().contains("m at most"), "{e}");
    }
}
