//! The truth: the frame as it should look, against which the benchmarks measure image error.
//!
//! A truth frame is the frame supersampled K x K (K = [`DEFAULT_K`] unless asked otherwise) by
//! jittered sub-pixel accumulation: K*K renders of the same camera at the same time, each shifted
//! by [`crate::renderer::FrameInput::jitter_px`] to the centre of one cell of a K x K grid over the
//! pixel (offsets `(i + 0.5) / K - 0.5` pixels, see [`offsets`]), read back and averaged in linear
//! light (each sRGB8 value decoded to linear f32, the mean encoded back to sRGB8). Nothing is
//! rendered larger than the frame, so the truth works at any size the renderer supports.
//!
//! It is drawn with the most accurate settings ([`truth_config`]): no LOD (every grass tile high
//! LOD, with no fade of the blades the low grid would drop), [`SEGMENTS`] blade segments
//! everywhere (curves true to a millimetre), and blades out to [`REACH_FACTOR`] times the default
//! view distance (600 m in the default world). The grass is a pure function of the world, the time and the camera: the first
//! sub-sample of a frame advances the wind and the sway by the time since the last frame, the
//! others at the same time advance nothing (the renderer's time step is 0), so that a sequence of
//! truth frames steps exactly like the frames it judges, and re-rendering a sub-sample is exact.
//!
//! Memory stays bounded: the grass pool's size does not depend on the view distance (its slots
//! hold the densest grass tile, whatever the rings), a frame generates at most
//! [`crate::grass::renderer::MAX_JOBS`] grass tiles, and the rings out to `REACH_FACTOR` times
//! the view distance want at most [`grass_tiles_bound`] of them (729 in the default world, whose
//! grass tiles are 50 m wide), within that; the atlas gets slots for all of them besides the
//! terrain's ([`atlas_slots`]; about 141 KB of GPU memory a slot in the default world).

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{Context, Result, bail};
use glam::{DVec2, Vec2};
use serde::Serialize;

use crate::RendererConfig;
use crate::camera::{Camera, sample_path, walker_at};
use crate::gpu::GpuContext;
use crate::lod::RingSettings;
use crate::stream::TileSource;
use crate::tools::fly::{
    FlyOptions, FlyProgress, OptionError, OutDir, Outputs, check_range, frame_file_name,
    frame_index, write_png,
};
use crate::tools::metrics::{decode_srgb8, encode_srgb8};
use crate::tools::{AdapterReport, Scene, write_json};
use crate::world::World;

/// Checks `reach` (`option` in messages) is in 1..=[`REACH_FACTOR`].
pub fn check_reach(option: &'static str, reach: f64) -> Result<(), OptionError> {
    check_range(option, reach, 1.0..=REACH_FACTOR, "")
}

/// Sub-samples a pixel side of the truth unless asked otherwise (`--truth`).
pub const DEFAULT_K: u32 = 4;
/// The most sub-samples a pixel side (`--truth`): 64 renders a frame.
pub const MAX_K: u32 = 8;
/// How far the truth draws blades, in default view distances: 600 m in the default world, whose
/// view distance is 67 m ([`crate::lod::DEFAULT_VIEW_TILES`] grass tiles of 50 m). The truth was
/// defined as four view distances when the view distance was three tiles; the factor grew as the
/// view distance shrank (6 at two tiles), so that the truth stayed the same scene.
pub const REACH_FACTOR: f64 = 9.0;
/// Blade segments of the truth everywhere: a blade's polyline then lies within a millimetre of
/// its curve (a tenth of the default's near segments' error), under a pixel from a metre away
/// at 1920x1080, at a quarter of the vertices of the 64 the grass draw allows.
pub const SEGMENTS: u32 = 16;
/// Atlas slots the truth keeps for terrain tiles besides its grass tiles.
const TERRAIN_SLOTS: u32 = 256;
/// The CPU cache of decoded tiles the truth keeps at least, bytes.
const CACHE_BYTES: u64 = 256 << 20;

/// Checks a supersampling factor given as `option`: 1..=[`MAX_K`] sub-samples a pixel side.
pub fn check_k(option: &'static str, k: u32) -> Result<(), OptionError> {
    check_range(option, k, 1..=MAX_K, "sub-samples a pixel side")
}

/// The sub-pixel offsets of a K x K truth, in pixels (x right, y down), row by row: the centres
/// of the cells of a K x K grid over the pixel, `(i + 0.5) / K - 0.5`.
pub fn offsets(k: u32) -> Vec<Vec2> {
    let k = k.max(1);
    let at = |i: u32| (i as f32 + 0.5) / k as f32 - 0.5;
    (0..k)
        .flat_map(|j| (0..k).map(move |i| Vec2::new(at(i), at(j))))
        .collect()
}

/// The most grass tiles the truth's rings want at once: every tile within [`REACH_FACTOR`]
/// times the default view distance (plus the rings' hysteresis) of the camera, counted as the
/// square of tiles around it.
pub fn grass_tiles_bound(world: &World) -> u32 {
    let base = RingSettings::for_pyramid(&world.manifest.pyramid);
    RingSettings {
        low_radius_m: REACH_FACTOR * base.low_radius_m,
        ..base
    }
    .most_tiles(&world.manifest.pyramid)
}

/// Atlas slots the truth asks for: room for every grass tile of [`grass_tiles_bound`] and the
/// terrain's tiles besides, within what `device` binds (the adapter's texture array layers and
/// the G-buffer's [`crate::terrain::GBUFFER_MAX_SLOTS`]).
pub fn atlas_slots(world: &World, device: &wgpu::Device) -> u32 {
    let most = device
        .limits()
        .max_texture_array_layers
        .min(crate::terrain::GBUFFER_MAX_SLOTS);
    (grass_tiles_bound(world) + TERRAIN_SLOTS).min(most)
}

/// The truth's settings on top of `base` (its features, wind and grass; the service's limits at
/// least as large): no LOD (every grass tile high LOD, the high ring reaching so far beyond the
/// view distance that the fade of the blades the low grid drops never starts within it), blades
/// out to [`REACH_FACTOR`] times the default view distance, [`SEGMENTS`] segments everywhere, every
/// plant its full mesh, every tree its full mesh out to [`TREE_MESH_M`] and none thinned, and
/// an atlas of `atlas_slots` slots (see [`atlas_slots`]). A `base` without grass stays without.
pub fn truth_config(world: &World, base: &RendererConfig, atlas_slots: u32) -> RendererConfig {
    truth_config_reaching(world, base, atlas_slots, REACH_FACTOR)
}

/// Like [`truth_config`], with blades out to `reach` (in 1..=[`REACH_FACTOR`]) times the
/// default view distance: a cheaper truth, for quick runs on a software renderer (the far
/// band beyond `reach` view distances is then not the truth's).
pub fn truth_config_reaching(
    world: &World,
    base: &RendererConfig,
    atlas_slots: u32,
    reach: f64,
) -> RendererConfig {
    let mut c = base.clone();
    let default = RingSettings::for_pyramid(&world.manifest.pyramid);
    let view = reach.clamp(1.0, REACH_FACTOR) * default.low_radius_m;
    // Blades the low grid drops fade over the outer 30% of the high ring
    // (`RendererConfig::grass_settings`): a ring of view / 0.7 starts that fade at the view
    // distance, where every blade is gone anyway.
    c.grass_rings = base.grass_rings.map(|r| RingSettings {
        high_radius_m: view / 0.7,
        low_radius_m: view,
        ..r
    });
    c.grass.segments = [SEGMENTS; 3];
    // Every blade at its own width (the rings above leave no low ring to widen anyway).
    c.grass.lod_widen = 1.0;
    // Real blades over bare ground: the far field only where they end.
    c.grass.far_field_under_blades = false;
    // Every plant its full mesh, wherever it grows; the pool's regions large enough for the
    // plants out to the truth's reach.
    c.plants.lod_m = [crate::renderer::MAX_PLANT_LOD_M; 2];
    // Its meshes reach as far as its blades, none thinned: no cards beyond.
    c.plants.card_reach = 1.0;
    c.plants.thin_m = crate::renderer::MAX_PLANT_LOD_M;
    c.plants.capacity = base.plants.capacity.saturating_mul(4);
    // The trees: full meshes out to TREE_MESH_M, cards beyond (a tree there is a few pixels),
    // none thinned out; four times the regions, as far as a pool can be bound.
    if let Some(t) = base.tree_settings(world) {
        let types = world
            .manifest
            .plant_types
            .iter()
            .filter(|t| t.is_tree())
            .count();
        c.trees = Some(crate::plants::PlantSettings {
            lod_m: [TREE_MESH_M; 2],
            thin_m: crate::renderer::MAX_PLANT_LOD_M,
            min_keep: 1.0,
            capacity: t
                .capacity
                .saturating_mul(4)
                .min(crate::plants::renderer::max_capacity(types as u32)),
            ..t
        });
    }
    // The sub-samples are the anti-aliasing: each one a plain frame.
    c.aa = crate::aa::AntiAliasing::Off;
    c.service.atlas_slots = c.service.atlas_slots.max(atlas_slots);
    c.service.cache_bytes = c.service.cache_bytes.max(CACHE_BYTES);
    c
}

/// How far the truth draws every tree's full mesh, metres (cards beyond, none thinned).
pub const TREE_MESH_M: f32 = 1000.0;

/// A running mean of images in linear light.
#[derive(Clone, Debug)]
pub struct Accumulator {
    size: (u32, u32),
    sums: Vec<f32>,
    n: u32,
}

impl Accumulator {
    /// An empty mean of `width` x `height` images.
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            size: (width, height),
            sums: vec![0.0; width as usize * height as usize * 4],
            n: 0,
        }
    }

    /// Adds `image` (sRGB8 colour, linear alpha) of the accumulator's size.
    pub fn add(&mut self, image: &image::RgbaImage) {
        assert_eq!(image.dimensions(), self.size, "images of one size");
        for (s, p) in self.sums.chunks_exact_mut(4).zip(image.pixels()) {
            for c in 0..3 {
                s[c] += decode_srgb8(p[c]);
            }
            s[3] += f32::from(p[3]) / 255.0;
        }
        self.n += 1;
    }

    /// The mean of the images added, encoded back to sRGB8 (black if none).
    pub fn mean(&self) -> image::RgbaImage {
        let n = self.n.max(1) as f32;
        let (w, h) = self.size;
        let mut out = image::RgbaImage::new(w, h);
        for (p, s) in out.pixels_mut().zip(self.sums.chunks_exact(4)) {
            let a = (s[3] / n * 255.0).round().clamp(0.0, 255.0) as u8;
            *p = image::Rgba([
                encode_srgb8(s[0] / n),
                encode_srgb8(s[1] / n),
                encode_srgb8(s[2] / n),
                a,
            ]);
        }
        out
    }
}

/// The mean of `images` (all of one size) in linear light (see [`Accumulator`]).
pub fn mean_linear(images: &[image::RgbaImage]) -> Option<image::RgbaImage> {
    let first = images.first()?;
    let mut acc = Accumulator::new(first.width(), first.height());
    for i in images {
        acc.add(i);
    }
    Some(acc.mean())
}

/// The truth renderer: a [`Scene`] with the truth's settings and the supersampling factor.
pub struct Truth {
    scene: Scene,
    k: u32,
    stop: crate::tools::stop::Stop,
}

impl Truth {
    /// The truth of `world` at `width` x `height`, K = `k` (1..=[`MAX_K`]), with the renderer's
    /// default grass, features and wind under [`truth_config`].
    pub fn new(ctx: &GpuContext, world: World, width: u32, height: u32, k: u32) -> Result<Self> {
        let base = RendererConfig::for_world(&world);
        let source: Arc<dyn TileSource> = Arc::new(world.clone());
        let config = truth_config(&world, &base, atlas_slots(&world, &ctx.device));
        Self::with_config(ctx, world, source, (width, height), k, config)
    }

    /// The truth of `world` with its tiles from `source`, drawn with `config` as given (make it
    /// with [`truth_config`]).
    pub fn with_config(
        ctx: &GpuContext,
        world: World,
        source: Arc<dyn TileSource>,
        (width, height): (u32, u32),
        k: u32,
        config: RendererConfig,
    ) -> Result<Self> {
        check_k("--truth", k)?;
        // The sub-samples are the anti-aliasing, each a plain frame: a temporal method would
        // fold them into its history.
        let config = RendererConfig {
            aa: crate::aa::AntiAliasing::Off,
            ..config
        };
        let scene = Scene::with_source(ctx, world, source, width, height, config)
            .context("the truth's renderer")?;
        Ok(Self {
            scene,
            k,
            stop: crate::tools::stop::Stop::default(),
        })
    }

    /// This truth with its warm-ups and frames ended by `stop` (Ctrl-C): a frame whose warm-up
    /// or sub-samples were stopped is not finished, [`crate::tools::stop::Stopped`] is returned
    /// instead.
    pub fn with_stop(mut self, stop: crate::tools::stop::Stop) -> Self {
        self.stop = stop;
        self
    }

    /// Sub-samples a pixel side.
    pub fn k(&self) -> u32 {
        self.k
    }

    /// The scene the truth draws with (its renderer, figures and depth).
    pub fn scene(&mut self) -> &mut Scene {
        &mut self.scene
    }

    /// Draws one plain frame (no jitter, nothing read back) at `time_s`: a step of a lead-in
    /// that brings the wind, the sway and the trail to where a sequence's frame has them.
    pub fn advance(
        &mut self,
        ctx: &GpuContext,
        camera: &Camera,
        time_s: f64,
        walker: Option<DVec2>,
    ) -> Result<()> {
        self.scene.set_jitter(Vec2::ZERO);
        self.scene.render_frame(ctx, camera, time_s, walker)?;
        Ok(())
    }

    /// The truth frame from `camera` at `time_s` with the trail left by `walker` (see the module
    /// docs): the tiles the camera wants are brought in first (waiting up to
    /// [`crate::tools::fly::FIRST_FRAME_WAIT`], or until its stop is asked for: see
    /// [`Truth::with_stop`]), then the K*K sub-samples are drawn and averaged in linear light.
    pub fn render(
        &mut self,
        ctx: &GpuContext,
        camera: &Camera,
        time_s: f64,
        walker: Option<DVec2>,
    ) -> Result<image::RgbaImage> {
        let (w, h) = self.scene.size();
        let mut acc = Accumulator::new(w, h);
        self.each_sample(ctx, camera, time_s, walker, &mut |img| acc.add(&img))?;
        Ok(acc.mean())
    }

    /// The K*K sub-samples of [`Truth::render`], in the order of [`offsets`].
    pub fn render_samples(
        &mut self,
        ctx: &GpuContext,
        camera: &Camera,
        time_s: f64,
        walker: Option<DVec2>,
    ) -> Result<Vec<image::RgbaImage>> {
        let mut out = Vec::new();
        self.each_sample(ctx, camera, time_s, walker, &mut |img| out.push(img))?;
        Ok(out)
    }

    /// Tile loads that failed so far (drawn from their ancestors).
    pub fn failed_loads(&self) -> u64 {
        self.scene.service().stats().stream.failed
    }

    fn each_sample(
        &mut self,
        ctx: &GpuContext,
        camera: &Camera,
        time_s: f64,
        walker: Option<DVec2>,
        sink: &mut dyn FnMut(image::RgbaImage),
    ) -> Result<()> {
        let report =
            self.stop
                .warm_up(&mut self.scene, camera, crate::tools::fly::FIRST_FRAME_WAIT)?;
        crate::tools::fly::check_streaming(
            &self.scene.world().dir,
            &self.scene.world().manifest.pyramid,
            &self.scene.service().stats(),
            &report,
        )?;
        for (i, offset) in offsets(self.k).into_iter().enumerate() {
            // A stop asked for between sub-samples ends the frame: at 8x8 and a large size a
            // frame's 64 draws take seconds.
            if let Err(stopped) = self.stop.check() {
                self.scene.set_jitter(Vec2::ZERO);
                return Err(stopped.into());
            }
            self.scene.set_jitter(offset);
            // Every sub-sample at the same time: only the first advances the wind and sway.
            let drawn = self.scene.render_frame(ctx, camera, time_s, walker);
            if let Err(e) = drawn {
                self.scene.set_jitter(Vec2::ZERO);
                return Err(e).with_context(|| format!("truth sub-sample {i}"));
            }
            sink(self.scene.read_image(ctx)?);
        }
        self.scene.set_jitter(Vec2::ZERO);
        Ok(())
    }

    /// The depth of the last sub-sample drawn (reverse-Z, row-major): the frame's depth within
    /// half a pixel.
    pub fn read_depth(&self, ctx: &GpuContext) -> Result<Vec<f32>> {
        Ok(self.scene.read_depth(ctx)?)
    }
}

/// One frame of `verdant fly --truth`.
#[derive(Clone, Debug, Serialize)]
pub struct TruthFrame {
    /// Frame index (its file is `frame_{index:05}.png`).
    pub index: u32,
    /// Time along the path, seconds.
    pub t_s: f64,
    /// Camera position, metres.
    pub camera_m: [f64; 3],
}

/// What `verdant fly --truth` writes into `truth.json`.
#[derive(Clone, Debug, Serialize)]
pub struct TruthReport {
    /// The world's name.
    pub world: String,
    /// The camera path.
    pub path: String,
    /// Image size.
    pub size: (u32, u32),
    /// Sub-samples a pixel side.
    pub k: u32,
    /// The adapter.
    pub adapter: AdapterReport,
    /// Wall time of the whole run, seconds.
    pub seconds: f64,
    /// The frames.
    pub frames: Vec<TruthFrame>,
    /// Whether the run was stopped before its last frame ([`FlyOptions::stop`], Ctrl-C): the
    /// report covers the frames written.
    #[serde(default)]
    pub interrupted: bool,
    /// Tile loads that failed during the run (a damaged file, a server that failed): those
    /// tiles were drawn from their ancestors, so the frames are not the truth of the world's
    /// stored tiles where they show them.
    #[serde(default)]
    pub failed_loads: u64,
}

/// `verdant fly --truth K`: the path's frames (the same times, cameras, walker and wind as
/// [`crate::tools::run_fly`] draws) as the truth, K x K sub-samples each, written as
/// `frame_NNNNN.png` with `truth.json` into `opts.out`. The grass options of `opts` (spacing,
/// width, infill) describe the grass and are kept; its LOD and segments are the truth's.
pub fn run_fly_truth(
    opts: &FlyOptions,
    k: u32,
    progress: &mut dyn FnMut(FlyProgress),
) -> Result<TruthReport> {
    opts.validate()?;
    check_k("--truth", k)?;
    if !opts.write_images {
        bail!("--truth writes the frames as images: it cannot be used with --no-images");
    }
    let started = std::time::Instant::now();
    let (world, source) =
        crate::tools::open_world_until(&opts.world, &opts.http, opts.stop.as_ref())?;
    let path = crate::tools::camera_path(&world, &opts.world, opts.path.as_deref())?;
    let out_dir = OutDir::create_for(
        &opts.out,
        "fly",
        &Outputs::matching(|n| {
            n == "truth.json" || frame_index(n).is_some_and(|i| i < opts.frames)
        }),
    )?;
    crate::tools::fly::warn_of_stale_outputs(&opts.out, opts.frames, "report.json", progress);
    let ctx = GpuContext::new()?;
    let mut base = RendererConfig::for_world(&world);
    base.service = super::service_over(opts.service, &base);
    base.wind_scene = opts.wind_scene.clone();
    base.wind_keys = path.wind.clone();
    base.features = base.features.switched(&opts.disable, &opts.enable);
    base.grass = opts.grass;
    base.mesh_step = opts.mesh_step;
    let config = truth_config(&world, &base, atlas_slots(&world, &ctx.device));
    let world_name = world.manifest.name.clone();
    let manifest = world.manifest.clone();
    // Ctrl-C ends the run between frames, inside a frame's warm-up or between its sub-samples;
    // the frames drawn are kept and described.
    let mut truth = Truth::with_config(&ctx, world, source, opts.size, k, config)?
        .with_stop(crate::tools::stop::Stop::new(opts.stop.clone()));
    progress(FlyProgress::WarmingUp);
    let last = f64::from(opts.frames.max(2) - 1);
    let mut frames = Vec::new();
    let mut interrupted = false;
    for i in 0..opts.frames {
        if opts.stop.as_ref().is_some_and(|s| s.is_cancelled()) {
            interrupted = true;
            break;
        }
        let t_s = path.time_at(f64::from(i) / last);
        let camera = sample_path(&path, t_s);
        let walker = walker_at(&manifest, &path, t_s);
        let image = match truth.render(&ctx, &camera, t_s, Some(walker)) {
            Ok(image) => image,
            Err(e) if e.is::<crate::tools::stop::Stopped>() => {
                interrupted = true;
                break;
            }
            Err(e) => return Err(e),
        };
        let file: PathBuf = opts.out.join(frame_file_name(i));
        write_png(&file, &image)?;
        frames.push(TruthFrame {
            index: i,
            t_s,
            camera_m: camera.position.to_array(),
        });
        progress(FlyProgress::Frame(u64::from(i) + 1, u64::from(opts.frames)));
    }
    let report = TruthReport {
        world: world_name,
        path: path.name.clone(),
        size: opts.size,
        k,
        adapter: AdapterReport::of(&ctx),
        seconds: started.elapsed().as_secs_f64(),
        frames,
        interrupted,
        failed_loads: truth.failed_loads(),
    };
    write_json(&opts.out.join("truth.json"), &report)?;
    out_dir.keep();
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offsets_are_the_centres_of_the_cells() {
        assert_eq!(offsets(1), vec![Vec2::ZERO]);
        assert_eq!(
            offsets(2),
            vec![
                Vec2::new(-0.25, -0.25),
                Vec2::new(0.25, -0.25),
                Vec2::new(-0.25, 0.25),
                Vec2::new(0.25, 0.25)
            ]
        );
        let o = offsets(4);
        assert_eq!(o.len(), 16);
        assert!(o.iter().all(|v| v.abs().max_element() <= 0.375));
        let mean = o.iter().copied().sum::<Vec2>() / 16.0;
        assert!(mean.length() < 1e-6, "{mean}");
    }

    #[test]
    fn a_bad_factor_is_refused_naming_the_option_and_its_range() {
        for k in [0, MAX_K + 1, u32::MAX] {
            let e = check_k("--truth", k).unwrap_err().to_string();
            assert!(
                e.contains(&format!("--truth {k}")) && e.contains("1..=8"),
                "{e}"
            );
        }
        check_k("--truth", 1).unwrap();
        check_k("--truth", MAX_K).unwrap();
    }

    #[test]
    fn the_mean_is_taken_in_linear_light() {
        let black = image::RgbaImage::from_pixel(3, 2, image::Rgba([0, 0, 0, 255]));
        let white = image::RgbaImage::from_pixel(3, 2, image::Rgba([255, 255, 255, 255]));
        let m = mean_linear(&[black.clone(), white]).unwrap();
        assert!(m.pixels().all(|p| p.0 == [188, 188, 188, 255]), "{m:?}");
        assert_eq!(mean_linear(std::slice::from_ref(&black)).unwrap(), black);
        assert!(mean_linear(&[]).is_none());
    }

    #[test]
    fn the_truths_grass_tiles_fit_a_frame_and_the_atlas() {
        let world = World::open(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/santa-cruz"),
        )
        .unwrap();
        let n = grass_tiles_bound(&world);
        // 50 m tiles, 9 x 67 m + 5 m of hysteresis: 13 tiles each side of the camera's.
        assert_eq!(n, 27 * 27);
        // A high-LOD tile near the camera can get a second job: at most 4 of them.
        assert!(n + 4 <= crate::grass::renderer::MAX_JOBS, "{n}");
        assert!(n + TERRAIN_SLOTS <= crate::terrain::GBUFFER_MAX_SLOTS);
    }

    #[test]
    fn the_truth_reaches_600_m_in_the_default_world_whatever_the_view_distance() {
        // The truth is the scene every figure is measured against: its blades reached four view
        // distances of 150 m when it was defined, six of 100 m later, and reach the same 600 m
        // with the view distance at 67 m.
        let world = World::open(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/santa-cruz"),
        )
        .unwrap();
        let base = RendererConfig::for_world(&world);
        let view = base.grass_rings.unwrap().low_radius_m;
        assert!((view - 200.0 / 3.0).abs() < 1e-9, "{view}");
        let truth = truth_config(&world, &base, 512);
        let reach = truth.grass_rings.unwrap().low_radius_m;
        assert!((reach - 600.0).abs() < 1e-9, "{reach}");
        // A quicker truth, out to one view distance: the default's.
        let near = truth_config_reaching(&world, &base, 512, 1.0);
        assert_eq!(near.grass_rings.unwrap().low_radius_m, view);
    }

    #[test]
    fn the_truths_trees_are_full_meshes_none_thinned() {
        let world = World::open(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/santa-cruz"),
        )
        .unwrap();
        let base = RendererConfig::for_world(&world);
        let default = base.tree_settings(&world).unwrap();
        let t = truth_config(&world, &base, 64).trees.unwrap();
        assert_eq!(t.lod_m, [TREE_MESH_M; 2]);
        assert!(t.lod_m[0] > default.lod_m[1] && t.min_keep == 1.0);
        // Four times the default's regions, within what a pool binds: the default world's
        // three tree types get 466,032 instances a region.
        let types = world
            .manifest
            .plant_types
            .iter()
            .filter(|t| t.is_tree())
            .count() as u32;
        assert_eq!(types, 3);
        assert_eq!(
            t.capacity,
            (4 * default.capacity).min(crate::plants::renderer::max_capacity(types))
        );
        assert_eq!(t.capacity, 466_032);
        assert_eq!((t.cell_m, t.view_m), (default.cell_m, default.view_m));
        truth_config(&world, &base, 64).validate().unwrap();
    }
}
