//! Headless fly-throughs: a camera path rendered frame by frame to PNG, with a JSON report of
//! what each frame drew and what it cost.

use std::collections::{BTreeMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Instant;

use anyhow::{Context, Result, bail};

use crate::camera::{sample_path, walker_at};
use crate::gpu::GpuContext;
use crate::tools::metrics::{COVERAGE_DISTANCE_M, Summary};
use crate::tools::report::{
    AdapterReport, CoverageRecord, FlyReport, FlySummary, FlyTotals, FrameRecord,
    MAX_REPORT_FRAMES, Thinned,
};

/// Frames whose grass coverage a fly-through without images measures: evenly spaced over the
/// path, drawn again after the flight (never among the timed frames).
pub const COVERAGE_FRAMES: u32 = 8;
use crate::tools::scene::{Scene, SceneConfig};

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
    /// Limits of the tile service.
    pub service: crate::stream::ServiceConfig,
    /// Wind scene of the manifest for the whole flight (default: the path's wind keys if it has
    /// any, else `breeze`, else the manifest's wind).
    pub wind_scene: Option<String>,
    /// Features of the grass model to switch off, on top of the manifest's `[features]`.
    pub disable: Vec<crate::features::Feature>,
    /// Features to switch on that the manifest switches off.
    pub enable: Vec<crate::features::Feature>,
    /// Blade spacing of the near grass grid, metres (None: the renderer's default).
    pub grass_spacing_m: Option<f32>,
    /// Blade width scale (None: the renderer's default).
    pub grass_width_scale: Option<f32>,
    /// Radii of the grass infill near the camera, half and quarter spacing (None: the
    /// renderer's default).
    pub grass_infill_m: Option<[f32; 2]>,
    /// Blade segments near the camera, in the rest of the high ring and in the low ring (None:
    /// the renderer's default).
    pub grass_segments: Option<[u32; 3]>,
    /// Horizontal radius of the near blades, metres (None: the renderer's default).
    pub grass_near_m: Option<f32>,
    /// Terrain mesh step in samples (None: the renderer's default).
    pub mesh_step: Option<u32>,
}

/// Progress of a fly-through, for a progress bar.
pub enum FlyProgress {
    /// The tiles of the first frame are loading.
    WarmingUp,
    /// The warm-up ended with tiles missing (one line each); the run goes on without them.
    WarmUpIncomplete(Vec<String>),
    /// Frames rendered so far, of a total.
    Frame(u64, u64),
}

/// A written frame whose camera moved farther than this since the last frame waits for its
/// tiles (metres: half a grass tile of the default world, more than a path covers in a frame
/// at 60 fps and any sensible speed).
const WAIT_JUMP_M: f64 = 25.0;
/// The longest a written frame waits for its tiles.
const FRAME_TILE_WAIT: std::time::Duration = std::time::Duration::from_secs(30);

fn path_start_position(path: &crate::world::CameraPath) -> glam::DVec3 {
    sample_path(path, path.keys[0].t_s).position
}

/// Runs a fly-through and writes its frames and `report.json` into `opts.out`.
pub fn run_fly(opts: &FlyOptions, progress: &mut dyn FnMut(FlyProgress)) -> Result<FlyReport> {
    if opts.frames == 0 {
        bail!("--frames must be at least 1");
    }
    let (world, source) = crate::tools::open_world(&opts.world, &opts.http)?;
    let path = match &opts.path {
        Some(name) => world.manifest.path(name).cloned().with_context(|| {
            let names: Vec<&str> = world
                .manifest
                .paths
                .iter()
                .map(|p| p.name.as_str())
                .collect();
            format!(
                "world {} has no camera path {name:?} (it has: {})",
                opts.world.display(),
                names.join(", ")
            )
        })?,
        None => world
            .manifest
            .paths
            .first()
            .cloned()
            .with_context(|| format!("world {} has no camera paths", opts.world.display()))?,
    };
    let out_dir = OutDir::create(&opts.out)?;

    let ctx = GpuContext::new()?;
    let world_name = world.manifest.name.clone();
    let (width, height) = opts.size;
    let mut config = SceneConfig::for_world(&world);
    config.service = opts.service;
    config.wind_scene = opts.wind_scene.clone();
    config.wind_keys = path.wind.clone();
    config.features = config.features.switched(&opts.disable, &opts.enable);
    if let Some(s) = opts.grass_spacing_m {
        if !(0.02..=5.0).contains(&s) {
            bail!("--grass-spacing-m must be between 0.02 and 5 m, not {s}");
        }
        config.grass_spacing_m = s;
    }
    if let Some(w) = opts.grass_width_scale {
        if !(0.05..=20.0).contains(&w) {
            bail!("--grass-width-scale must be between 0.05 and 20, not {w}");
        }
        config.grass_width_scale = w;
    }
    if let Some([half, quarter]) = opts.grass_infill_m {
        if !(0.0..=100.0).contains(&half) || !(0.0..=100.0).contains(&quarter) {
            bail!("--grass-infill-m radii must be between 0 and 100 m, not {half},{quarter}");
        }
        config.grass_infill_m = [half, quarter];
    }
    if let Some(seg) = opts.grass_segments {
        if seg.iter().any(|s| !(1..=64).contains(s)) {
            bail!("--grass-segments must be between 1 and 64 each, not {seg:?}");
        }
        config.grass_segments = seg;
    }
    if let Some(r) = opts.grass_near_m {
        if !(0.0..=200.0).contains(&r) {
            bail!("--grass-near-m must be between 0 and 200 m, not {r}");
        }
        config.grass_near_m = r;
    }
    if let Some(step) = opts.mesh_step {
        if !step.is_power_of_two() || step > 16 {
            bail!("--mesh-step must be a power of two up to 16, not {step}");
        }
        config.mesh_step = step;
    }
    let mut scene = Scene::with_source(&ctx, world, source, width, height, config)?;
    // The first frame starts with its tiles resident; after that, streaming keeps up or the
    // report shows that it did not.
    progress(FlyProgress::WarmingUp);
    let warm_up = scene.warm_up_report(
        &sample_path(&path, path.keys[0].t_s),
        std::time::Duration::from_secs(60),
    )?;
    let warm_up_missing = warm_up.describe(20);
    if !warm_up_missing.is_empty() {
        progress(FlyProgress::WarmUpIncomplete(warm_up_missing.clone()));
    }

    // PNG encoding runs beside the renderer; the bounded channel keeps at most a few frames queued.
    let (tx, rx) = mpsc::sync_channel::<(PathBuf, image::RgbaImage)>(4);
    let writer = std::thread::spawn(move || -> Result<()> {
        for (file, img) in rx {
            img.save(&file)
                .with_context(|| format!("cannot write frame {}", file.display()))?;
        }
        Ok(())
    });

    // Bounded whatever --frames asks for: an evenly spaced sample of at most MAX_REPORT_FRAMES.
    let mut records = Records {
        kept: Thinned::new(MAX_REPORT_FRAMES),
        totals: FlyTotals::default(),
    };
    let last = (opts.frames.max(2) - 1) as f64;
    let (t0, t1) = (path.keys[0].t_s, path.keys[path.keys.len() - 1].t_s);
    // Without images nothing needs a frame back: frames are submitted as an application
    // submits them, at most FRAMES_IN_FLIGHT ahead of the GPU, and their figures are taken as
    // they come back. With images, each frame is waited for and read back.
    let mut waiting: VecDeque<FrameRecord> = VecDeque::new();
    // With images, the grass coverage of every frame written (read back like its image).
    let mut coverage = Thinned::new(MAX_REPORT_FRAMES);
    scene.set_coverage_capture(opts.write_images)?;
    let mut last_position = path_start_position(&path);
    for i in 0..opts.frames {
        let t_s = t0 + (t1 - t0) * f64::from(i) / last;
        let camera = sample_path(&path, t_s);
        // Frames written far apart along the path (a short fly-through) wait, boundedly, for
        // the tiles they need: each picture shows the world at full detail where its camera
        // stands, not what streaming could catch up with in one frame.
        let mut wait = (0.0, 0u32);
        if opts.write_images && camera.position.distance(last_position) > WAIT_JUMP_M {
            let waited = Instant::now();
            let report = scene.warm_up_report(&camera, FRAME_TILE_WAIT)?;
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
            let file = opts.out.join(format!("frame_{i:05}.png"));
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
    // after a warm-up (it is a jump back along the path).
    if !opts.write_images {
        scene.set_coverage_capture(true)?;
        let n = opts.frames.min(COVERAGE_FRAMES);
        let span = f64::from(opts.frames - 1);
        for k in 0..n {
            let i = if n > 1 {
                (span * f64::from(k) / f64::from(n - 1)).round() as u32
            } else {
                0
            };
            let t_s = t0 + (t1 - t0) * f64::from(i) / last;
            let camera = sample_path(&path, t_s);
            scene.warm_up_report(&camera, std::time::Duration::from_secs(30))?;
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

/// Writes `value` as pretty JSON, via a temporary file so a reader never sees half a report.
pub fn write_json<T: serde::Serialize>(file: &Path, value: &T) -> Result<()> {
    let tmp = file.with_extension("json.tmp");
    let text = serde_json::to_string_pretty(value)?;
    std::fs::write(&tmp, text).with_context(|| format!("cannot write {}", tmp.display()))?;
    if let Err(e) = std::fs::rename(&tmp, file) {
        let _ = std::fs::remove_file(&tmp);
        return Err(e).with_context(|| format!("cannot write {}", file.display()));
    }
    Ok(())
}

/// An output folder made for a run. If the run created it and fails before writing anything
/// into it, it is removed again (only while empty), so an early failure leaves no trace.
pub struct OutDir {
    path: PathBuf,
    created: bool,
    kept: bool,
}

impl OutDir {
    /// Creates `path` (and its parents) where needed.
    pub fn create(path: &Path) -> Result<Self> {
        let created = !path.exists();
        std::fs::create_dir_all(path)
            .with_context(|| format!("cannot create output folder {}", path.display()))?;
        Ok(Self {
            path: path.to_path_buf(),
            created,
            kept: false,
        })
    }

    /// The run succeeded: the folder stays.
    pub fn keep(mut self) {
        self.kept = true;
    }
}

impl Drop for OutDir {
    fn drop(&mut self) {
        if self.created && !self.kept {
            // Fails, and so keeps the folder, when anything was written into it.
            let _ = std::fs::remove_dir(&self.path);
        }
    }
}

impl FlySummary {
    /// Summarises the frames of a fly-through.
    pub fn of(frames: &[FrameRecord]) -> Self {
        let series = |f: &dyn Fn(&FrameRecord) -> f64| frames.iter().map(f).collect::<Vec<f64>>();
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
            grass_considered: Summary::of(&series(&|f| {
                f64::from(f.grass.considered[0]) + f64::from(f.grass.considered[1])
            })),
            grass_drawn_high: Summary::of(&series(&|f| f64::from(f.grass.drawn[0]))),
            grass_drawn_low: Summary::of(&series(&|f| f64::from(f.grass.drawn[1]))),
            coverage: Summary::default(),
        }
    }
}
