//! `verdant bench lod`: the LOD transition benchmark.
//!
//! (a) Popping: a camera dolly over the meadow crosses the high/low ring boundary of many grass
//! tiles. Each frame is rendered twice, with the default LOD settings and with no LOD (every
//! tile high LOD), and the two are compared by FLIP. A pop would show as a jump of that error on
//! a frame where tiles switch ring; the jumps on frames without switches are the noise floor.
//! (b) Speed against accuracy: for a set of LOD settings (ring radii, blade spacing, segments,
//! view distance), GPU time per frame against the FLIP error to a full-detail reference render,
//! with the Pareto front; the default setting is marked. The images are captured first; then
//! the settings are timed in interleaved rounds, each measurement's frames back to back with
//! nothing in between (see [`crate::tools::timing`]): a median with its interquartile range
//! per view, a setting whose spread is above 10% flagged.
//! (c) The far field: beyond the view distance the terrain is shaded with what the grass would
//! show there. At the same views, a far reference draws real blades out to
//! [`FAR_BAND_FACTOR`] times the default view distance; the default setting is compared with
//! it, with the far field on and off, by the mean FLIP over the band of pixels whose surface (in
//! the reference's depth) lies between the view distance and that factor times it.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use glam::DVec3;
use serde::Serialize;

use crate::camera::{Camera, sample_path};
use crate::gpu::GpuContext;
use crate::lod::RingSettings;
use crate::renderer::RendererConfig;
use crate::tools::fly::{OptionError, OutDir, check_range, check_size, write_text};
use crate::tools::metrics::{
    COVERAGE_DISTANCE_M, Chart, ChartPoint, LineChart, Series, Summary, band_mask, flip_compare,
    flip_error_map, masked_mean, pareto_front, ray_distances,
};
use crate::tools::timing::{FrameCounts, Timing, frame_ms, run_frames};
use crate::tools::{AdapterReport, Scene, write_json};
use crate::world::World;

/// What `verdant bench lod` is asked to do.
#[derive(Clone, Debug)]
pub struct BenchLodOptions {
    /// The world's folder.
    pub world: PathBuf,
    /// Output folder.
    pub out: PathBuf,
    /// Image size.
    pub size: (u32, u32),
    /// Frames of the dolly.
    pub dolly_frames: u32,
    /// Untimed frames before each measurement's timed ones (default: by adapter, see
    /// [`FrameCounts::for_adapter`]).
    pub warmup_frames: Option<u32>,
    /// Timed frames of each measurement per round (default: by adapter).
    pub timed_frames: Option<u32>,
    /// Interleaved rounds over the settings (default: by adapter).
    pub rounds: Option<u32>,
    /// Camera path the views are taken from (default: "meadow", else the first path).
    pub path: Option<String>,
}

impl Default for BenchLodOptions {
    fn default() -> Self {
        Self {
            world: PathBuf::from("worlds/santa-cruz"),
            out: PathBuf::from("out/bench-lod"),
            size: (480, 270),
            dolly_frames: 48,
            warmup_frames: None,
            timed_frames: None,
            rounds: None,
            path: None,
        }
    }
}

/// The most untimed frames before each measurement (`--warmup-frames`).
pub const MAX_WARMUP_FRAMES: u32 = 100;
/// The most timed frames of each measurement per round (`--timed-frames`); with the warm-up,
/// within the 256 frames that `bench blades` times its floor pass over at once.
pub const MAX_TIMED_FRAMES: u32 = 150;
/// The most interleaved rounds (`--rounds`).
pub const MAX_ROUNDS: u32 = 100;
/// The most frames of the dolly (`--dolly-frames`).
pub const MAX_DOLLY_FRAMES: u32 = 1000;

/// Checks the timing options of a benchmark: `--warmup-frames` 0..=100, `--timed-frames`
/// 1..=150, `--rounds` 1..=100 (those not given take the adapter's defaults, which lie within).
pub fn check_timing(
    warmup_frames: Option<u32>,
    timed_frames: Option<u32>,
    rounds: Option<u32>,
) -> Result<(), OptionError> {
    if let Some(n) = warmup_frames {
        check_range("--warmup-frames", n, 0..=MAX_WARMUP_FRAMES, "")?;
    }
    if let Some(n) = timed_frames {
        check_range("--timed-frames", n, 1..=MAX_TIMED_FRAMES, "")?;
    }
    if let Some(n) = rounds {
        check_range("--rounds", n, 1..=MAX_ROUNDS, "")?;
    }
    Ok(())
}

impl BenchLodOptions {
    /// Checks the options of `bench lod`: `--size` 1..=16384 pixels a side, `--dolly-frames`
    /// 2..=1000, and the timing options (see [`check_timing`]).
    pub fn validate(&self) -> Result<(), OptionError> {
        self.validate_features()?;
        check_range(
            "--dolly-frames",
            self.dolly_frames,
            2..=MAX_DOLLY_FRAMES,
            "",
        )
    }

    /// Checks the options `bench features` uses: `--size` and the timing options (see
    /// [`check_timing`]).
    pub fn validate_features(&self) -> Result<(), OptionError> {
        check_size("--size", self.size)?;
        check_timing(self.warmup_frames, self.timed_frames, self.rounds)
    }
}

/// One LOD setting.
#[derive(Clone, Debug, Serialize)]
pub struct LodSetting {
    /// Name in tables and charts.
    pub name: String,
    /// High-LOD ring radius, in grass tile edges.
    pub high_radius_tiles: f64,
    /// View distance (low-LOD ring radius), in grass tile edges.
    pub view_distance_tiles: f64,
    /// Blade spacing of the high-LOD grid, metres.
    pub spacing_m: f32,
    /// Blade segments near the camera, in the rest of the high ring and in the low ring.
    pub segments: [u32; 3],
    /// Radii of the grass infill near the camera, metres (half and quarter spacing).
    pub infill_m: [f32; 2],
    /// Every grass type's blade width times this.
    pub width_scale: f32,
}

impl LodSetting {
    fn new(name: &str, high: f64, view: f64, spacing_m: f32, segments: [u32; 3]) -> Self {
        Self {
            name: name.into(),
            high_radius_tiles: high,
            view_distance_tiles: view,
            spacing_m,
            segments,
            infill_m: crate::renderer::DEFAULT_INFILL_M,
            width_scale: 1.0,
        }
    }

    /// The same setting with blades `width_scale` times as wide.
    fn with_width(mut self, width_scale: f32) -> Self {
        self.width_scale = width_scale;
        self
    }

    /// The same setting with the infill radii `infill_m`.
    fn with_infill(mut self, infill_m: [f32; 2]) -> Self {
        self.infill_m = infill_m;
        self
    }

    /// The scene configuration of this setting for `world`.
    pub fn config(&self, world: &World) -> RendererConfig {
        let mut c = RendererConfig::for_world(world);
        let base = RingSettings::for_pyramid(&world.manifest.pyramid);
        let size = world.manifest.pyramid.tile_size_m(base.level);
        c.grass_rings = Some(RingSettings {
            high_radius_m: self.high_radius_tiles * size,
            low_radius_m: self.view_distance_tiles * size,
            ..base
        });
        c.grass.spacing_m = self.spacing_m;
        c.grass.segments = self.segments;
        c.grass.infill_m = self.infill_m;
        c.grass.width_scale = self.width_scale;
        c
    }
}

/// The settings the benchmark compares; the first is the renderer's default.
pub fn lod_settings(world: &World) -> Vec<LodSetting> {
    let d = RendererConfig::for_world(world);
    let rings = d
        .grass_rings
        .unwrap_or_else(|| RingSettings::for_pyramid(&world.manifest.pyramid));
    let size = world.manifest.pyramid.tile_size_m(rings.level);
    let (h, v) = (rings.high_radius_m / size, rings.low_radius_m / size);
    let (s, seg, infill) = (d.grass.spacing_m, d.grass.segments, d.grass.infill_m);
    vec![
        LodSetting::new("default", h, v, s, seg),
        LodSetting::new("near ring x0.5", h * 0.5, v, s, seg),
        LodSetting::new("near ring x2", h * 2.0, v, s, seg),
        LodSetting::new("view x0.67", h, v * 2.0 / 3.0, s, seg),
        LodSetting::new("view x1.33", h, v * 4.0 / 3.0, s, seg),
        LodSetting::new("spacing x1.4", h, v, s * 1.4, seg),
        LodSetting::new("spacing x0.8", h, v, s * 0.8, seg),
        LodSetting::new("segments 7/7/3", h, v, s, [7, 7, 3]),
        LodSetting::new("segments 5/3/2", h, v, s, [5, 3, 2]),
        LodSetting::new("segments 3/2/1", h, v, s, [3, 2, 1]),
        LodSetting::new("infill off", h, v, s, seg).with_infill([0.0; 2]),
        LodSetting::new("infill x0.8", h, v, s, seg).with_infill(infill.map(|r| 0.8 * r)),
        LodSetting::new("infill x1.2", h, v, s, seg).with_infill(infill.map(|r| 1.2 * r)),
        LodSetting::new("width x0.67", h, v, s, seg).with_width(2.0 / 3.0),
        LodSetting::new("width x1.5", h, v, s, seg).with_width(1.5),
        LodSetting::new("no LOD", v, v, s, [seg[0]; 3]),
    ]
}

/// The full-detail reference: every tile high LOD out to a third further than the default view.
pub fn reference_setting(world: &World) -> LodSetting {
    let s = &lod_settings(world)[0];
    let v = s.view_distance_tiles * 4.0 / 3.0;
    LodSetting::new("reference", v, v, s.spacing_m, [s.segments[0]; 3])
}

/// Result of one setting.
#[derive(Clone, Debug, Serialize)]
pub struct SettingResult {
    /// The setting.
    pub setting: LodSetting,
    /// GPU time per frame over all passes (mean over the views of their medians and
    /// quartiles; the largest spread), milliseconds; zero without timestamps.
    pub gpu: Timing,
    /// Wall time per frame, frames back to back, milliseconds.
    pub frame: Timing,
    /// Mean FLIP error to the reference over the views.
    pub flip_mean: f64,
    /// Blades drawn per frame (median).
    pub blades_drawn: f64,
    /// Grass coverage within [`COVERAGE_DISTANCE_M`] (see
    /// [`crate::tools::metrics::grass_coverage`]), mean over the views, measured on the
    /// captured frames, not the timed ones.
    pub coverage: f64,
    /// On the Pareto front of GPU time against error.
    pub pareto: bool,
}

/// One frame of the dolly.
#[derive(Clone, Debug, Serialize)]
pub struct DollyFrame {
    /// Frame.
    pub frame: u32,
    /// FLIP error of the LOD frame against the no-LOD frame.
    pub flip_vs_no_lod: f64,
    /// FLIP change from the previous LOD frame.
    pub change_lod: f64,
    /// FLIP change from the previous no-LOD frame.
    pub change_no_lod: f64,
    /// How much `flip_vs_no_lod` moved since the previous frame: a pop shows as a jump.
    pub jump: f64,
    /// Grass tiles that changed ring this frame.
    pub ring_switches: u32,
}

/// How far the far reference draws real blades, in default view distances.
pub const FAR_BAND_FACTOR: f64 = 4.0;

/// The far band at one view: the default setting against the far reference over the pixels
/// whose surface lies between the view distance and [`FAR_BAND_FACTOR`] times it.
#[derive(Clone, Debug, Serialize)]
pub struct FarBandView {
    /// The view (0-based, of the four along the path).
    pub view: u32,
    /// Pixels in the band.
    pub band_pixels: u64,
    /// Mean FLIP over the band with the far field on (`None` when the band is empty).
    pub flip_far_field: Option<f64>,
    /// The same with the far field switched off.
    pub flip_no_far_field: Option<f64>,
}

/// The far band over the views.
#[derive(Clone, Debug, Serialize)]
pub struct FarBand {
    /// Where the band starts: the default view distance, metres along the view ray.
    pub near_m: f64,
    /// Where it ends: [`FAR_BAND_FACTOR`] times that, the far reference's view distance.
    pub far_m: f64,
    /// Pixels in the band, all views together.
    pub band_pixels: u64,
    /// Mean FLIP over the band's pixels of all views, far field on (`None` if none).
    pub flip_far_field: Option<f64>,
    /// The same, far field off.
    pub flip_no_far_field: Option<f64>,
    /// Each view.
    pub views: Vec<FarBandView>,
}

/// Everything `bench_lod.json` holds.
#[derive(Clone, Debug, Serialize)]
pub struct BenchLodReport {
    /// The adapter.
    pub adapter: AdapterReport,
    /// Image size.
    pub size: (u32, u32),
    /// The dolly.
    pub dolly: Vec<DollyFrame>,
    /// Largest jump of the LOD run's error against the no-LOD run on a frame where grass tiles
    /// switched ring: the popping, as a number.
    pub worst_pop: f64,
    /// The same on frames without switches (the noise floor of the measure).
    pub worst_change_without_switch: f64,
    /// The settings.
    pub settings: Vec<SettingResult>,
    /// Whether the default setting is on the Pareto front.
    pub default_on_front: bool,
    /// The frame counts of the timings.
    pub counts: FrameCounts,
    /// The far field against real blades out to [`FAR_BAND_FACTOR`] times the view distance.
    pub far_band: FarBand,
}

fn rgb(img: &image::RgbaImage) -> image::RgbImage {
    image::DynamicImage::ImageRgba8(img.clone()).to_rgb8()
}

fn flip(a: &image::RgbaImage, b: &image::RgbaImage) -> Result<f64> {
    Ok(f64::from(flip_compare(&rgb(a), &rgb(b))?.mean))
}

struct Bench<'a> {
    ctx: &'a GpuContext,
    world: &'a World,
    size: (u32, u32),
}

impl Bench<'_> {
    fn scene(&self, setting: &LodSetting) -> Result<Scene> {
        Ok(Scene::new(
            self.ctx,
            self.world.clone(),
            self.size.0,
            self.size.1,
            setting.config(self.world),
        )?)
    }

    /// Renders `camera` after bringing its tiles in; returns the image and the stats.
    fn frame(
        &self,
        scene: &mut Scene,
        camera: &Camera,
    ) -> Result<(image::RgbaImage, crate::renderer::FrameStats)> {
        warm_up(scene, camera)?;
        let stats = scene.render(self.ctx, camera)?;
        Ok((scene.read_image(self.ctx)?, stats))
    }

    /// Like [`Bench::frame`], with the frame's grass coverage (the capture of the terrain-only
    /// depth is on for this frame only).
    fn frame_with_coverage(
        &self,
        scene: &mut Scene,
        camera: &Camera,
    ) -> Result<(image::RgbaImage, crate::renderer::FrameStats, f64)> {
        scene.set_coverage_capture(true)?;
        let (img, stats) = self.frame(scene, camera)?;
        let coverage = scene.coverage(self.ctx, COVERAGE_DISTANCE_M)?.fraction;
        scene.set_coverage_capture(false)?;
        Ok((img, stats, coverage))
    }
}

/// Brings in the tiles `camera` wants, waiting up to [`crate::tools::fly::FIRST_FRAME_WAIT`];
/// fails if streaming delivered nothing (see [`crate::tools::fly::check_streaming`]). Tiles
/// still missing otherwise are drawn from their ancestors, as in any frame.
fn warm_up(scene: &mut Scene, camera: &Camera) -> Result<()> {
    let report = scene.warm_up_report(camera, crate::tools::fly::FIRST_FRAME_WAIT)?;
    crate::tools::fly::check_streaming(
        &scene.world().dir,
        &scene.world().manifest.pyramid,
        &scene.service().stats(),
        &report,
    )?;
    Ok(())
}

/// Runs the benchmark and writes `bench_lod.json`, `dolly.csv`, `dolly.png`, `lod_settings.csv`,
/// `lod_settings.png`, `lod_coverage.png` and `far_band.csv` into `opts.out`.
pub fn run_bench_lod(
    opts: &BenchLodOptions,
    progress: &mut dyn FnMut(&str, u64, u64),
) -> Result<BenchLodReport> {
    opts.validate()?;
    let world = World::open(&opts.world)?;
    let path = match &opts.path {
        Some(n) => world
            .manifest
            .path(n)
            .cloned()
            .with_context(|| format!("no camera path {n:?}"))?,
        None => match world
            .manifest
            .path("meadow")
            .or(world.manifest.paths.first())
        {
            Some(p) => p.clone(),
            None => bail!("world {} has no camera paths", opts.world.display()),
        },
    };
    let out_dir = OutDir::create_for(&opts.out, "bench lod")?;
    let ctx = GpuContext::new()?;
    let bench = Bench {
        ctx: &ctx,
        world: &world,
        size: opts.size,
    };
    let settings = lod_settings(&world);

    // (a) The dolly: forward along the path's direction, from where the path starts.
    let start = sample_path(&path, path.keys[0].t_s);
    let ring_m = settings[0].high_radius_tiles
        * world
            .manifest
            .pyramid
            .tile_size_m(RingSettings::for_pyramid(&world.manifest.pyramid).level);
    // Far enough that tiles ahead cross the high/low boundary during the dolly.
    let step = 1.5 * ring_m / f64::from(opts.dolly_frames);
    let mut lod_scene = bench.scene(&settings[0])?;
    let no_lod = settings
        .iter()
        .find(|s| s.name == "no LOD")
        .expect("the no-LOD setting")
        .clone();
    let mut full_scene = bench.scene(&no_lod)?;
    let mut dolly = Vec::new();
    let mut prev: Option<(image::RgbaImage, image::RgbaImage)> = None;
    let mut prev_rings: Option<Vec<(crate::world::TileId, crate::lod::Ring)>> = None;
    for f in 0..opts.dolly_frames {
        let fwd = start.forward();
        let horizontal = DVec3::new(fwd.x, fwd.y, 0.0).normalize_or_zero();
        let mut cam = start;
        cam.position += horizontal * step * f64::from(f);
        let (a, _) = bench.frame(&mut lod_scene, &cam)?;
        let rings = lod_scene.grass_rings();
        let (b, _) = bench.frame(&mut full_scene, &cam)?;
        let switches = match &prev_rings {
            Some(p) => rings
                .iter()
                .filter(|r| p.iter().any(|q| q.0 == r.0 && q.1 != r.1))
                .count() as u32,
            None => 0,
        };
        let (change_lod, change_no_lod) = match &prev {
            Some((pa, pb)) => (flip(pa, &a)?, flip(pb, &b)?),
            None => (0.0, 0.0),
        };
        let e = flip(&a, &b)?;
        let jump = dolly
            .last()
            .map_or(0.0, |d: &DollyFrame| (e - d.flip_vs_no_lod).abs());
        dolly.push(DollyFrame {
            frame: f,
            flip_vs_no_lod: e,
            change_lod,
            change_no_lod,
            jump,
            ring_switches: switches,
        });
        prev = Some((a, b));
        prev_rings = Some(rings);
        progress("dolly", u64::from(f) + 1, u64::from(opts.dolly_frames));
    }
    drop((lod_scene, full_scene));
    let worst_pop = dolly
        .iter()
        .skip(1)
        .filter(|d| d.ring_switches > 0)
        .map(|d| d.jump)
        .fold(0.0, f64::max);
    let worst_change_without_switch = dolly
        .iter()
        .skip(1)
        .filter(|d| d.ring_switches == 0)
        .map(|d| d.jump)
        .fold(0.0, f64::max);

    // (b) Settings against the reference, at four views along the path.
    let views: Vec<Camera> = [0.1, 0.35, 0.6, 0.85]
        .iter()
        .map(|u| sample_path(&path, path.keys[0].t_s + u * path.duration_s))
        .collect();
    let mut reference = bench.scene(&reference_setting(&world))?;
    let mut ref_images = Vec::new();
    for v in &views {
        ref_images.push(bench.frame(&mut reference, v)?.0);
    }
    drop(reference);
    // (c) The far band's reference and masks, and the default without the far field.
    let tile_m = world
        .manifest
        .pyramid
        .tile_size_m(RingSettings::for_pyramid(&world.manifest.pyramid).level);
    let near_m = settings[0].view_distance_tiles * tile_m;
    let far_m = FAR_BAND_FACTOR * near_m;
    let mut far_setting = settings[0].clone();
    far_setting.name = "far reference".into();
    far_setting.view_distance_tiles *= FAR_BAND_FACTOR;
    let (w, h) = opts.size;
    let (mut far_refs, mut masks) = (Vec::new(), Vec::new());
    let mut scene = bench.scene(&far_setting)?;
    for v in &views {
        let (img, _) = bench.frame(&mut scene, v)?;
        let depth = scene.read_depth(&ctx)?;
        let inv = v.view_proj_relative(w as f32 / h as f32).inverse();
        let distances = ray_distances(&depth, w, h, inv);
        masks.push(band_mask(&distances, near_m as f32, far_m as f32));
        far_refs.push(rgb(&img));
    }
    drop(scene);
    let mut config = settings[0].config(&world);
    config.features = config.features.without(crate::features::Feature::FarField);
    let mut scene = Scene::new(&ctx, world.clone(), w, h, config)?;
    let mut no_far_field = Vec::new();
    for v in &views {
        no_far_field.push(bench.frame(&mut scene, v)?.0);
    }
    drop(scene);
    progress("far band", 1, 1);
    let mut default_images = Vec::new();
    // Images first, every setting's scene kept for the timings.
    let mut scenes = Vec::new();
    let mut partial = Vec::new();
    let total = settings.len() as u64;
    for (k, s) in settings.iter().enumerate() {
        let mut scene = bench.scene(s)?;
        let (mut flips, mut blades, mut coverage) = (Vec::new(), Vec::new(), Vec::new());
        for (v, r) in views.iter().zip(&ref_images) {
            let (img, stats, c) = bench.frame_with_coverage(&mut scene, v)?;
            flips.push(flip(&img, r)?);
            blades.push(f64::from(stats.grass.drawn[0] + stats.grass.drawn[1]));
            coverage.push(c);
            if k == 0 {
                default_images.push(img);
            }
        }
        scenes.push(scene);
        partial.push((flips, blades, coverage));
        progress("images", k as u64 + 1, total);
    }
    let far_band = far_band(
        (near_m, far_m),
        &far_refs,
        &masks,
        &default_images,
        &no_far_field,
    )?;
    drop((far_refs, masks, default_images, no_far_field));
    // Then the timings, in interleaved rounds.
    let counts = FrameCounts::for_adapter(&ctx.info).with(
        opts.warmup_frames,
        opts.timed_frames,
        opts.rounds,
    );
    let n_views = views.len();
    let mut gpu_samples = vec![vec![Vec::new(); n_views]; settings.len()];
    let mut wall_samples = vec![vec![Vec::new(); n_views]; settings.len()];
    let steps = u64::from(counts.rounds) * total;
    for round in 0..counts.rounds {
        for (k, scene) in scenes.iter_mut().enumerate() {
            for (vi, v) in views.iter().enumerate() {
                let walker = Some(v.position.truncate());
                for (stats, wall) in
                    run_frames(&ctx, scene, v, 0.0, walker, counts.warmup, counts.timed)?
                {
                    gpu_samples[k][vi].push(frame_ms(&stats, wall, true));
                    wall_samples[k][vi].push(wall);
                }
            }
            progress("timing", u64::from(round) * total + k as u64 + 1, steps);
        }
    }
    drop(scenes);
    let mut results = Vec::new();
    for (k, s) in settings.iter().enumerate() {
        let (flips, blades, coverage) = &partial[k];
        let timing = |samples: &[Vec<f64>]| {
            Timing::over_views(&samples.iter().map(|v| Timing::of(v)).collect::<Vec<_>>())
        };
        results.push(SettingResult {
            setting: s.clone(),
            gpu: if ctx.timestamps {
                timing(&gpu_samples[k])
            } else {
                Timing::default()
            },
            frame: timing(&wall_samples[k]),
            flip_mean: flips.iter().sum::<f64>() / flips.len() as f64,
            blades_drawn: Summary::of(blades).median,
            coverage: coverage.iter().sum::<f64>() / coverage.len() as f64,
            pareto: false,
        });
    }
    // Time is GPU time when the adapter has timestamps, else wall time.
    let time = |r: &SettingResult| {
        if ctx.timestamps {
            r.gpu.median_ms
        } else {
            r.frame.median_ms
        }
    };
    let xy: Vec<(f64, f64)> = results.iter().map(|r| (time(r), r.flip_mean)).collect();
    for i in pareto_front(&xy) {
        results[i].pareto = true;
    }

    write_outputs(opts, &dolly, &results, ctx.timestamps)?;
    write_far_band(opts, &far_band)?;
    let report = BenchLodReport {
        adapter: AdapterReport::of(&ctx),
        size: opts.size,
        worst_pop,
        worst_change_without_switch,
        default_on_front: results[0].pareto,
        counts,
        dolly,
        settings: results,
        far_band,
    };
    write_json(&opts.out.join("bench_lod.json"), &report)?;
    out_dir.keep();
    Ok(report)
}

/// The far band's figures from the far reference's images and band masks, and the default
/// setting's images with the far field on and off (all in the order of the views).
fn far_band(
    (near_m, far_m): (f64, f64),
    references: &[image::RgbImage],
    masks: &[Vec<bool>],
    with: &[image::RgbaImage],
    without: &[image::RgbaImage],
) -> Result<FarBand> {
    let mut views = Vec::new();
    let (mut sum_with, mut sum_without, mut pixels) = (0.0, 0.0, 0u64);
    for (i, (r, mask)) in references.iter().zip(masks).enumerate() {
        let band_pixels = mask.iter().filter(|&&m| m).count() as u64;
        let with = masked_mean(&flip_error_map(r, &rgb(&with[i]))?, mask);
        let without = masked_mean(&flip_error_map(r, &rgb(&without[i]))?, mask);
        if let (Some(a), Some(b)) = (with, without) {
            sum_with += a * band_pixels as f64;
            sum_without += b * band_pixels as f64;
            pixels += band_pixels;
        }
        views.push(FarBandView {
            view: i as u32,
            band_pixels,
            flip_far_field: with,
            flip_no_far_field: without,
        });
    }
    let mean = |sum: f64| (pixels > 0).then(|| sum / pixels as f64);
    Ok(FarBand {
        near_m,
        far_m,
        band_pixels: pixels,
        flip_far_field: mean(sum_with),
        flip_no_far_field: mean(sum_without),
        views,
    })
}

/// Writes `far_band.csv`: one row a view, empty FLIP cells where the band is empty.
fn write_far_band(opts: &BenchLodOptions, band: &FarBand) -> Result<()> {
    let cell = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.6}"));
    let mut csv = String::from("view,band_pixels,flip_far_field,flip_no_far_field\n");
    for v in &band.views {
        csv.push_str(&format!(
            "{},{},{},{}\n",
            v.view,
            v.band_pixels,
            cell(v.flip_far_field),
            cell(v.flip_no_far_field)
        ));
    }
    write_text(&opts.out.join("far_band.csv"), &csv)?;
    Ok(())
}

fn write_outputs(
    opts: &BenchLodOptions,
    dolly: &[DollyFrame],
    results: &[SettingResult],
    gpu: bool,
) -> Result<()> {
    use std::fmt::Write as _;
    let mut csv =
        String::from("frame,flip_vs_no_lod,jump,change_lod,change_no_lod,ring_switches\n");
    for d in dolly {
        let _ = writeln!(
            csv,
            "{},{:.5},{:.5},{:.5},{:.5},{}",
            d.frame, d.flip_vs_no_lod, d.jump, d.change_lod, d.change_no_lod, d.ring_switches
        );
    }
    write_text(&opts.out.join("dolly.csv"), &csv)?;
    let line =
        |f: &dyn Fn(&DollyFrame) -> f64| dolly.iter().map(|d| (f64::from(d.frame), f(d))).collect();
    LineChart {
        title: "LOD dolly across the ring boundary".into(),
        x_label: "frame".into(),
        y_label: "FLIP".into(),
        log_x: false,
        log_y: false,
        series: vec![
            Series {
                name: "LOD vs no LOD".into(),
                points: line(&|d| d.flip_vs_no_lod),
            },
            Series {
                name: "jump of that error".into(),
                points: line(&|d| d.jump),
            },
            Series {
                name: "ring switches / 1000".into(),
                points: line(&|d| f64::from(d.ring_switches) / 1000.0),
            },
        ],
    }
    .write_png(&opts.out.join("dolly.png"), 900, 600)?;

    let mut csv = String::from(
        "setting,high_radius_tiles,view_distance_tiles,spacing_m,segments_near,segments_high,segments_low,infill_half_m,infill_quarter_m,width_scale,gpu_ms,gpu_q1_ms,gpu_q3_ms,gpu_spread,frame_ms,frame_spread,noisy,frames,flip_mean,blades_drawn,coverage,pareto\n",
    );
    for r in results {
        let s = &r.setting;
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{},{},{},{},{},{:.4},{:.4},{:.4},{:.4},{:.3},{:.4},{},{},{:.5},{:.0},{:.4},{}",
            s.name,
            s.high_radius_tiles,
            s.view_distance_tiles,
            s.spacing_m,
            s.segments[0],
            s.segments[1],
            s.segments[2],
            s.infill_m[0],
            s.infill_m[1],
            s.width_scale,
            r.gpu.median_ms,
            r.gpu.q1_ms,
            r.gpu.q3_ms,
            r.gpu.spread,
            r.frame.median_ms,
            r.frame.spread,
            if gpu { r.gpu.noisy } else { r.frame.noisy },
            r.frame.frames,
            r.flip_mean,
            r.blades_drawn,
            r.coverage,
            r.pareto
        );
    }
    write_text(&opts.out.join("lod_settings.csv"), &csv)?;
    Chart {
        title: "Grass LOD settings: speed against accuracy".into(),
        x_label: if gpu {
            "GPU time per frame (ms)".into()
        } else {
            "frame time (ms)".into()
        },
        y_label: "FLIP error vs full-detail reference".into(),
        log_x: true,
        log_y: false,
        points: results
            .iter()
            .map(|r| ChartPoint {
                label: if (gpu && r.gpu.noisy) || (!gpu && r.frame.noisy) {
                    format!("{} (noisy)", r.setting.name)
                } else {
                    r.setting.name.clone()
                },
                x: if gpu {
                    r.gpu.median_ms
                } else {
                    r.frame.median_ms
                },
                y: r.flip_mean,
                chosen: r.setting.name == "default",
            })
            .collect(),
    }
    .write_png(&opts.out.join("lod_settings.png"), 900, 600)?;
    // Coverage against cost: the ground a view of the near meadow leaves bare, so that lower
    // is better on both axes, as on the chart above.
    Chart {
        title: "Grass LOD settings: ground left bare against speed".into(),
        x_label: if gpu {
            "GPU time per frame (ms)".into()
        } else {
            "frame time (ms)".into()
        },
        y_label: "1 - grass coverage within 30 m".into(),
        log_x: true,
        log_y: false,
        points: results
            .iter()
            .map(|r| ChartPoint {
                label: r.setting.name.clone(),
                x: if gpu {
                    r.gpu.median_ms
                } else {
                    r.frame.median_ms
                },
                y: 1.0 - r.coverage,
                chosen: r.setting.name == "default",
            })
            .collect(),
    }
    .write_png(&opts.out.join("lod_coverage.png"), 900, 600)?;
    Ok(())
}

/// One feature's cost and contribution.
#[derive(Clone, Debug, Serialize)]
pub struct FeatureResult {
    /// The feature (or "all" for the full render).
    pub feature: String,
    /// Median GPU time per frame with the feature off (all: everything on), milliseconds (wall
    /// time without timestamps).
    pub gpu_ms: f64,
    /// That time's quartiles and spread.
    pub timing: Timing,
    /// GPU time the feature costs: the full render's minus this one's, milliseconds.
    pub cost_ms: f64,
    /// Mean FLIP between the full render and the render without the feature: its contribution
    /// to the image.
    pub contribution: f64,
    /// Grass coverage within [`COVERAGE_DISTANCE_M`] with the feature off (all: everything
    /// on), mean over the views, measured on the captured frames, not the timed ones.
    pub coverage: f64,
}

/// Everything `bench_features.json` holds.
#[derive(Clone, Debug, Serialize)]
pub struct BenchFeaturesReport {
    /// The adapter.
    pub adapter: AdapterReport,
    /// Image size.
    pub size: (u32, u32),
    /// The full render first, then one row per feature switched off.
    pub features: Vec<FeatureResult>,
}

/// `verdant bench features`: each feature's GPU cost against its contribution to the image
/// (FLIP between the full render and the render with that feature off), charted one against
/// the other. The views come from the world's first camera path with wind keys (the baked
/// `wind-tour`): one late in each of its wind scenes, each reached by two seconds of flight
/// along the path in as many frames as the untimed warm-up has (at least one; the sway's exact
/// step is stable at any frame time), so that the sway, the gusts, the sources and the walker's
/// trail are under way. The images are captured first; then the variants are timed in interleaved
/// rounds at each view's time (see [`crate::tools::timing`]). A world without such a path is viewed
/// along `meadow` (else its first path) in the storm. Writes `bench_features.json`, `features.csv` and `features.png`.
pub fn run_bench_features(
    opts: &BenchLodOptions,
    progress: &mut dyn FnMut(&str, u64, u64),
) -> Result<BenchFeaturesReport> {
    use crate::features::{Feature, Features};
    const LEAD_S: f64 = 2.0;
    opts.validate_features()?;
    let world = World::open(&opts.world)?;
    let m = &world.manifest;
    let toured = m.paths.iter().find(|p| !p.wind.is_empty());
    let path = match toured.or(m.path("meadow")).or(m.paths.first()) {
        Some(p) => p.clone(),
        None => bail!("world {} has no camera paths", opts.world.display()),
    };
    let t0 = path.keys[0].t_s;
    let end = t0 + path.duration_s;
    // One view 70% of the way through each wind scene (at least LEAD_S into the path), or four
    // views along a path without wind keys.
    let times: Vec<f64> = if path.wind.is_empty() {
        [0.1, 0.35, 0.6, 0.85]
            .iter()
            .map(|u| t0 + u * path.duration_s)
            .collect()
    } else {
        path.wind
            .iter()
            .enumerate()
            .map(|(i, k)| {
                let next = path.wind.get(i + 1).map_or(end, |n| n.t_s);
                (k.t_s + 0.7 * (next - k.t_s)).clamp(t0 + LEAD_S, end)
            })
            .collect()
    };
    let scene_name =
        (path.wind.is_empty() && m.wind_scene("storm").is_some()).then(|| "storm".to_owned());
    let out_dir = OutDir::create_for(&opts.out, "bench features")?;
    let ctx = GpuContext::new()?;
    let variants: Vec<(String, Features)> = std::iter::once(("all".to_owned(), Features::all()))
        .chain(
            Feature::ALL
                .iter()
                .map(|f| (f.name().to_owned(), Features::all().without(*f))),
        )
        .collect();
    let walker_at = |t: f64| crate::camera::walker_at(m, &path, t);
    let counts = FrameCounts::for_adapter(&ctx.info).with(
        opts.warmup_frames,
        opts.timed_frames,
        opts.rounds,
    );
    let lead_frames = counts.warmup.max(1);
    let mut scenes = Vec::new();
    let mut all_images = Vec::new();
    let total = variants.len() as u64;
    for (k, (_, features)) in variants.iter().enumerate() {
        let mut config = RendererConfig::for_world(&world);
        config.features = *features;
        config.wind_scene = scene_name.clone();
        config.wind_keys = path.wind.clone();
        let mut scene = Scene::new(&ctx, world.clone(), opts.size.0, opts.size.1, config)?;
        let (mut images, mut coverage) = (Vec::new(), Vec::new());
        scene.set_coverage_capture(true)?;
        for &t in &times {
            warm_up(&mut scene, &sample_path(&path, t))?;
            // The lead-in: the camera and the walker along the path up to the view's time.
            for f in 0..=lead_frames {
                let tf = t - LEAD_S * (1.0 - f64::from(f) / f64::from(lead_frames));
                scene.render_frame(&ctx, &sample_path(&path, tf), tf, Some(walker_at(tf)))?;
            }
            images.push(scene.read_image(&ctx)?);
            coverage.push(scene.coverage(&ctx, COVERAGE_DISTANCE_M)?.fraction);
        }
        scene.set_coverage_capture(false)?;
        scenes.push(scene);
        all_images.push((images, coverage));
        progress("images", k as u64 + 1, total);
    }
    // Timed frames hold each view's time: the same image every frame.
    let mut samples = vec![vec![Vec::new(); times.len()]; variants.len()];
    for round in 0..counts.rounds {
        for (k, scene) in scenes.iter_mut().enumerate() {
            for (vi, &t) in times.iter().enumerate() {
                let cam = sample_path(&path, t);
                for (stats, wall) in run_frames(
                    &ctx,
                    scene,
                    &cam,
                    t,
                    Some(walker_at(t)),
                    counts.warmup,
                    counts.timed,
                )? {
                    samples[k][vi].push(frame_ms(&stats, wall, ctx.timestamps));
                }
            }
            progress(
                "timing",
                u64::from(round) * total + k as u64 + 1,
                u64::from(counts.rounds) * total,
            );
        }
    }
    drop(scenes);
    let rows: Vec<(String, Timing, Vec<image::RgbaImage>, f64)> = variants
        .iter()
        .zip(samples)
        .zip(all_images)
        .map(|(((name, _), views), (images, coverage))| {
            let t = Timing::over_views(&views.iter().map(|v| Timing::of(v)).collect::<Vec<_>>());
            let c = coverage.iter().sum::<f64>() / coverage.len().max(1) as f64;
            (name.clone(), t, images, c)
        })
        .collect();
    let full_ms = rows[0].1.median_ms;
    let mut features = Vec::new();
    for (name, timing, images, coverage) in &rows {
        let mut flips = Vec::new();
        for (a, b) in rows[0].2.iter().zip(images) {
            flips.push(flip(a, b)?);
        }
        features.push(FeatureResult {
            feature: name.clone(),
            gpu_ms: timing.median_ms,
            timing: *timing,
            cost_ms: full_ms - timing.median_ms,
            contribution: flips.iter().sum::<f64>() / flips.len() as f64,
            coverage: *coverage,
        });
    }
    use std::fmt::Write as _;
    let mut csv = String::from(
        "feature,gpu_ms_without,q1_ms,q3_ms,spread,noisy,frames,cost_ms,contribution_flip,coverage\n",
    );
    for r in &features {
        let _ = writeln!(
            csv,
            "{},{:.4},{:.4},{:.4},{:.4},{},{},{:.4},{:.5},{:.4}",
            r.feature,
            r.gpu_ms,
            r.timing.q1_ms,
            r.timing.q3_ms,
            r.timing.spread,
            r.timing.noisy,
            r.timing.frames,
            r.cost_ms,
            r.contribution,
            r.coverage
        );
    }
    write_text(&opts.out.join("features.csv"), &csv)?;
    Chart {
        title: "Grass features: GPU cost against contribution to the image".into(),
        x_label: "GPU cost (ms a frame, full render minus the render without it)".into(),
        y_label: "FLIP between the render with and without it".into(),
        log_x: false,
        log_y: false,
        points: features
            .iter()
            .skip(1)
            .map(|r| ChartPoint {
                label: if r.timing.noisy {
                    format!("{} (noisy)", r.feature)
                } else {
                    r.feature.clone()
                },
                x: r.cost_ms,
                y: r.contribution,
                chosen: false,
            })
            .collect(),
    }
    .write_png_with_front(&opts.out.join("features.png"), 900, 600, |_| false)?;
    let report = BenchFeaturesReport {
        adapter: AdapterReport::of(&ctx),
        size: opts.size,
        features,
    };
    write_json(&opts.out.join("bench_features.json"), &report)?;
    out_dir.keep();
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bench_options_out_of_range_name_the_option_and_its_range() {
        let d = BenchLodOptions::default;
        d().validate().unwrap();
        let cases = [
            (
                BenchLodOptions {
                    dolly_frames: 0,
                    ..d()
                },
                "--dolly-frames 0",
                "2..=1000",
            ),
            (
                BenchLodOptions {
                    dolly_frames: u32::MAX,
                    ..d()
                },
                "--dolly-frames 4294967295",
                "2..=1000",
            ),
            (
                BenchLodOptions {
                    size: (0, 0),
                    ..d()
                },
                "--size 0x0",
                "1..=16384",
            ),
            (
                BenchLodOptions {
                    warmup_frames: Some(101),
                    ..d()
                },
                "--warmup-frames 101",
                "0..=100",
            ),
            (
                BenchLodOptions {
                    timed_frames: Some(0),
                    ..d()
                },
                "--timed-frames 0",
                "1..=150",
            ),
            (
                BenchLodOptions {
                    rounds: Some(0),
                    ..d()
                },
                "--rounds 0",
                "1..=100",
            ),
        ];
        for (opts, option, range) in cases {
            let e = opts.validate().unwrap_err().to_string();
            assert!(e.contains(option) && e.contains(range), "{e}");
        }
        // `bench features` has no dolly.
        BenchLodOptions {
            dolly_frames: 0,
            ..d()
        }
        .validate_features()
        .unwrap();
        check_timing(
            Some(MAX_WARMUP_FRAMES),
            Some(MAX_TIMED_FRAMES),
            Some(MAX_ROUNDS),
        )
        .unwrap();
    }
}
