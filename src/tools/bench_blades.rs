//! `verdant bench blades`: the benchmark people use to compare grass renderers.
//!
//! A flat square field generated in memory (no world files), one grass type at uniform full
//! density, seen from a camera given by position, target and vertical field of view; swept over
//! blade counts (the field's blades at the high-LOD spacing, 100 thousand to 10 million by
//! default). Per count: blades considered, drawn per LOD, vertices drawn, GPU time per pass, ns
//! per blade drawn and per vertex, and the image error against the truth of the same field
//! ([`crate::tools::truth`]: supersampled K x K, no LOD, 16 segments everywhere) by pixel FLIP and by
//! the coarse FLIP (see [`crate::tools::bench`]), with the old figure against the same field
//! drawn with no LOD at the same resolution.
//! In the same run the floor: a bare pass that draws the same number of vertices (the same
//! instances of the same strip lengths) with a trivial shader, so that the grass draw's cost is
//! given as a ratio to what the hardware needs for that many vertices.
//!
//! Coordinates: the field spans `[0, field_m]` in x (east) and y (north), z is up. The common
//! y-up description of the default camera, "(-20, 15, -20) looking at (100, 0, 100)", is
//! `camera_m = (-20, -20, 15)` and `target_m = (100, 100, 0)` here.

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{Context, Result, bail};
use glam::{DVec2, DVec3, Vec3};
use serde::Serialize;

use crate::RendererConfig;
use crate::camera::Camera;
use crate::gpu::GpuContext;
use crate::grass::{BATCH_TILES, Blade};
use crate::lod::RingSettings;
use crate::renderer::FrameStats;
use crate::stream::TileSource;
use crate::tools::bench::{Measures, rgb};
use crate::tools::fly::{OptionError, OutDir, Outputs, check_range, check_size, write_text};
use crate::tools::metrics::{LineChart, Series, flip_compare};
use crate::tools::stop::{Stop, caught, chart_title};
use crate::tools::timing::{FrameCounts, Timing, ramp_up, run_frames};
use crate::tools::truth::Truth;
use crate::tools::{AdapterReport, Scene, write_json};
use crate::world::{Manifest, TileData, TileId, World, WorldError};

/// What `verdant bench blades` is asked to do.
#[derive(Clone, Debug)]
pub struct BenchBladesOptions {
    /// Output folder.
    pub out: PathBuf,
    /// Image size.
    pub size: (u32, u32),
    /// Edge of the square field, metres.
    pub field_m: f64,
    /// Camera position (x east, y north, z up), metres.
    pub camera_m: [f64; 3],
    /// The point the camera looks at, metres.
    pub target_m: [f64; 3],
    /// Vertical field of view, degrees.
    pub fov_deg: f64,
    /// Blade counts of the sweep (blades in the whole field at the high-LOD spacing).
    pub counts: Vec<u64>,
    /// Untimed frames, timed frames and rounds (default: by adapter).
    pub warmup_frames: Option<u32>,
    /// Timed frames of each measurement per round.
    pub timed_frames: Option<u32>,
    /// Interleaved rounds.
    pub rounds: Option<u32>,
    /// Sub-samples a pixel side of the truth (`--truth`, 1..=8).
    pub truth_k: u32,
    /// A flag that ends the run early (Ctrl-C on the command line): at the next blade count or
    /// timing, what was measured so far is written, the report marked interrupted (see
    /// [`crate::tools::stop`]).
    pub stop: Option<crate::bake::CancelFlag>,
}

impl Default for BenchBladesOptions {
    fn default() -> Self {
        Self {
            out: PathBuf::from("out/bench-blades"),
            size: (1920, 1080),
            field_m: 200.0,
            camera_m: [-20.0, -20.0, 15.0],
            target_m: [100.0, 100.0, 0.0],
            fov_deg: 45.0,
            counts: vec![100_000, 300_000, 1_000_000, 3_000_000, 10_000_000],
            warmup_frames: None,
            timed_frames: None,
            rounds: None,
            truth_k: crate::tools::truth::DEFAULT_K,
            stop: None,
        }
    }
}

/// The most blade counts of one sweep (`--counts`): each keeps a scene with a grass pool of
/// its own for the timings.
pub const MAX_SWEEP_COUNTS: usize = 32;

/// The most blades a slot of the grass pool holds on any device: half the pool
/// ([`BATCH_TILES`] slots of [`Blade`]s) is bound as one storage buffer, and no device binds
/// more than 4 GiB. (A device that binds less clamps its slots, with a warning, and counts the
/// blades that do not fit as overflow.)
pub const MAX_SLOT_BLADES: u64 =
    (1 << 32) / (BATCH_TILES as u64 * std::mem::size_of::<Blade>() as u64);

/// The largest camera or target coordinate, metres (`--camera`, `--target`).
pub const MAX_COORDINATE_M: f64 = 100_000.0;

/// Edge of the field's grass tiles (the tiles of its finest level), metres.
pub const FIELD_TILE_M: f64 = 50.0;

/// The high-LOD blade spacing that puts `count` blades in a square field `field_m` metres
/// wide, metres.
pub fn field_spacing_m(count: u64, field_m: f64) -> f64 {
    field_m / (count as f64).sqrt()
}

/// Blades a slot of the grass pool needs for `count` blades in a field `field_m` metres wide
/// of grass tiles `tile_m` metres wide: a tile's grid of `(tile_m / spacing)^2` points (at
/// least one), counted in 64 bits; `None` where even that does not hold it.
pub fn slot_blades(count: u64, field_m: f64, tile_m: f64) -> Option<u64> {
    let grid = (tile_m / field_spacing_m(count, field_m)).round();
    if !(grid.is_finite() && (0.0..=f64::from(u32::MAX)).contains(&grid)) {
        return None;
    }
    let grid = (grid as u64).max(1);
    grid.checked_mul(grid)
}

/// The blade counts `--counts` takes for a field `field_m` metres wide of grass tiles `tile_m`
/// metres wide: at least 1000, at least one blade a grass tile (`(field_m / tile_m)^2`) and no
/// wider spacing than the renderer draws ([`crate::renderer::SPACING_RANGE_M`], 5 m); at most
/// the count whose grass tiles need [`MAX_SLOT_BLADES`] blades a slot, and no finer spacing than
/// the renderer draws (2 cm): 1,600..=100,000,004 for the default 200 m field.
pub fn count_range(field_m: f64, tile_m: f64) -> std::ops::RangeInclusive<u64> {
    let tiles_a_side = field_m / tile_m;
    let spacing = crate::renderer::SPACING_RANGE_M;
    // The counts whose spacing, as the renderer takes it (f32), is within its range.
    let drawn = |n: u64| spacing.contains(&(field_spacing_m(n, field_m) as f32));
    let mut widest = (field_m / f64::from(*spacing.end()))
        .powi(2)
        .round()
        .max(1.0) as u64;
    while !drawn(widest) && widest < u64::MAX / 2 {
        widest += 1;
    }
    let mut finest = (field_m / f64::from(*spacing.start())).powi(2).round() as u64;
    while !drawn(finest) && finest > widest {
        finest -= 1;
    }
    let min = ((tiles_a_side * tiles_a_side).ceil() as u64)
        .max(1000)
        .max(widest);
    // A grid of at most `side` points a tile edge: `side^2` blades fit a slot.
    let side = MAX_SLOT_BLADES.isqrt() as f64;
    let max = ((side * tiles_a_side).powi(2).floor() as u64).min(finest);
    min..=max
}

impl BenchBladesOptions {
    /// Checks every option against its range (stated in the error), before any GPU work:
    /// `--size` 1..=16384 pixels a side, `--field-m` 10..=5000, `--fov-deg` between 1 and 170
    /// (both excluded), `--camera` and `--target` within 100 km of the origin in each
    /// coordinate and at least 1 cm apart, 1..=32 `--counts` each in [`count_range`], `--truth`
    /// 1..=8, and the timing options (see [`crate::tools::bench::check_timing`]).
    pub fn validate(&self) -> Result<()> {
        check_size("--size", self.size)?;
        crate::tools::truth::check_k("--truth", self.truth_k)?;
        check_range("--field-m", self.field_m, 10.0..=5000.0, "m")?;
        if !(self.fov_deg > 1.0 && self.fov_deg < 170.0) {
            return Err(OptionError::new(
                "--fov-deg",
                self.fov_deg,
                "between 1 and 170 degrees, both excluded",
            )
            .into());
        }
        for (option, v) in [("--camera", self.camera_m), ("--target", self.target_m)] {
            if !v.iter().all(|c| c.abs() <= MAX_COORDINATE_M) {
                return Err(OptionError::new(
                    option,
                    format!("{},{},{}", v[0], v[1], v[2]),
                    format!("X,Y,Z each in -{MAX_COORDINATE_M}..={MAX_COORDINATE_M} m"),
                )
                .into());
            }
        }
        let eye = DVec3::from_array(self.camera_m);
        let target = DVec3::from_array(self.target_m);
        if eye.distance(target) < 0.01 {
            let v = self.target_m;
            return Err(OptionError::new(
                "--target",
                format!("{},{},{}", v[0], v[1], v[2]),
                "at least 0.01 m from --camera",
            )
            .into());
        }
        if !(1..=MAX_SWEEP_COUNTS).contains(&self.counts.len()) {
            return Err(OptionError::new(
                "--counts",
                format!("{:?}", self.counts),
                format!("1..={MAX_SWEEP_COUNTS} blade counts"),
            )
            .into());
        }
        if let Some(n) = crate::tools::bench::repeated(&self.counts) {
            anyhow::bail!("--counts lists {n} twice");
        }
        let range = count_range(self.field_m, FIELD_TILE_M);
        if let Some(&n) = self.counts.iter().find(|n| !range.contains(n)) {
            return Err(OptionError::new(
                "--counts",
                n,
                format!(
                    "in {}..={} with --field-m {} (at least one blade a {FIELD_TILE_M} m grass \
                     tile, blades 2 cm to 5 m apart as the renderer draws them, and at most \
                     {MAX_SLOT_BLADES} blades a tile: the most a slot of the grass pool holds, \
                     {BATCH_TILES} slots being bound in one GPU buffer of at most 4 GiB)",
                    range.start(),
                    range.end(),
                    self.field_m
                ),
            )
            .into());
        }
        crate::tools::bench::check_timing(self.warmup_frames, self.timed_frames, self.rounds)?;
        Ok(())
    }
}

/// One blade count's figures.
#[derive(Clone, Debug, Serialize)]
pub struct BladesResult {
    /// Blades in the field at the high-LOD spacing.
    pub blades: u64,
    /// The high-LOD spacing that gives them, metres.
    pub spacing_m: f64,
    /// Grid points considered per frame, per LOD (high, low).
    pub considered: [u32; 2],
    /// Points without grass, summed over both LODs.
    pub empty: u32,
    /// Culled by distance, frustum and occlusion, and overflowing, summed over both LODs.
    pub culled: u32,
    /// Of those, the blades that passed every test but did not fit their tile's slot of the
    /// grass pool (summed over both LODs): 0 unless the field's blades a tile need more than
    /// the device binds, and then the figures are of a frame that lacks them.
    pub overflow: u32,
    /// Blades drawn per LOD.
    pub drawn: [u32; 2],
    /// Vertices the grass draw runs.
    pub vertices: u64,
    /// GPU time of generation (with the per-blade wind), milliseconds.
    pub generate: Timing,
    /// GPU time of the grass draw, milliseconds.
    pub draw: Timing,
    /// GPU time of the whole frame, milliseconds.
    pub frame: Timing,
    /// GPU time of the floor pass (the same vertices with a trivial shader), milliseconds.
    pub floor: Timing,
    /// Vertices the floor pass drew.
    pub floor_vertices: u64,
    /// Grass draw time per blade drawn, nanoseconds (`None` where no blade was drawn: the
    /// camera sees no grass).
    pub ns_per_blade: Option<f64>,
    /// Grass draw time per vertex, nanoseconds (`None` where no vertex was drawn).
    pub ns_per_vertex: Option<f64>,
    /// The grass draw's time over the floor's (`None` where the floor took no time).
    pub ratio_to_floor: Option<f64>,
    /// Error of the frame against the truth of the same field, by both measures.
    pub vs_truth: Measures,
    /// Pixel FLIP of the frame against the same field with no LOD (the old figure).
    pub flip_vs_no_lod: f64,
}

/// Everything `bench_blades.json` holds.
#[derive(Clone, Debug, Serialize)]
pub struct BenchBladesReport {
    /// The adapter.
    pub adapter: AdapterReport,
    /// Image size.
    pub size: (u32, u32),
    /// Sub-samples a pixel side of the truth.
    pub truth_k: u32,
    /// The frame counts of the timings.
    pub counts: FrameCounts,
    /// One row per blade count (of a run stopped early, the counts whose images were
    /// captured, with the rounds timed so far: none where `draw.frames` is 0).
    pub results: Vec<BladesResult>,
    /// Whether the run was stopped before its end (Ctrl-C; [`BenchBladesOptions::stop`]): the
    /// report holds what was measured until then.
    pub interrupted: bool,
}

/// The field's manifest: one grass type, tiles of 50 m at the finest level (the grass level),
/// heights up to `top_m`.
fn field_manifest(field_m: f64, top_m: f32) -> Result<Manifest> {
    let levels = 3u32;
    let root = FIELD_TILE_M * f64::from(1u32 << (levels - 1));
    let roots = (field_m / root).ceil().max(1.0) as u32;
    let top = top_m.max(1.0);
    let text = format!(
        r#"name = "blades-field"
description = "A flat field of one grass type at full density, generated in memory."
extent_m = [{field_m}, {field_m}]
height_range_m = [0.0, {top}]

[pyramid]
root_tile_size_m = {root}
root_tiles = [{roots}, {roots}]
tile_cells = 128
border = 2
stored_levels = {levels}
derived_levels = 0

[[grass_types]]
name = "bare"
ground_color = [0.3, 0.27, 0.23]
base_color = [0.3, 0.27, 0.23]
tip_color = [0.3, 0.27, 0.23]
height_m = [0.0, 0.0]
width_m = [0.0, 0.0]
stiffness = 1.0

[[grass_types]]
name = "meadow"
ground_color = [0.1, 0.16, 0.05]
base_color = [0.04, 0.14, 0.02]
tip_color = [0.22, 0.45, 0.08]
height_m = [0.5, 0.7]
width_m = [0.02, 0.035]
stiffness = 0.6

[wind]
direction_deg = 30.0
speed_mps = 4.0
gustiness = 0.4

[sky]
sun_azimuth_deg = 210.0
sun_elevation_deg = 40.0
sun_color = [1.0, 0.95, 0.85]
sky_color = [0.45, 0.6, 0.85]
horizon_color = [0.75, 0.82, 0.9]
fog_distance_m = 4000.0

[[paths]]
name = "still"
duration_s = 1.0

[[paths.keys]]
t_s = 0.0
position_m = [0.0, 0.0, 10.0]
yaw_deg = 45.0
pitch_deg = -10.0

[[paths.keys]]
t_s = 1.0
position_m = [1.0, 1.0, 10.0]
yaw_deg = 45.0
pitch_deg = -10.0
"#
    );
    Ok(Manifest::parse(
        &text,
        std::path::Path::new("<bench blades field>"),
    )?)
}

/// The height of a generated field at a world position (metres).
pub type HeightFn = Arc<dyn Fn(DVec2) -> f32 + Send + Sync>;

/// Tiles of the field, made on request: heights from `height` (flat at 0 for the benchmark),
/// the grass type everywhere inside the field, bare outside, full density.
struct FlatField {
    manifest: Manifest,
    field_m: f64,
    height: Option<HeightFn>,
}

impl TileSource for FlatField {
    fn load(&self, id: TileId) -> Result<TileData, WorldError> {
        let p = &self.manifest.pyramid;
        let size = p.samples_per_side();
        let b = p.bounds(id);
        let cell = p.cell_size_m(id.level);
        let n = (size * size) as usize;
        let mut grass_type = vec![0u8; n];
        let mut heights = vec![0.0; n];
        for j in 0..size {
            for i in 0..size {
                let x = b.min.x + (f64::from(i) - f64::from(p.border)) * cell;
                let y = b.min.y + (f64::from(j) - f64::from(p.border)) * cell;
                if (0.0..=self.field_m).contains(&x) && (0.0..=self.field_m).contains(&y) {
                    grass_type[(j * size + i) as usize] = 1;
                }
                if let Some(h) = &self.height {
                    heights[(j * size + i) as usize] = h(DVec2::new(x, y));
                }
            }
        }
        Ok(TileData {
            id,
            size,
            heights,
            grass_type,
            density: vec![255; n],
            material: Vec::new(),
        })
    }
}

/// A flat square field `field_m` metres wide of one grass type at full density, generated in
/// memory (no world files): its world and its tile source.
pub fn flat_field(field_m: f64) -> Result<(World, Arc<dyn TileSource>)> {
    field_with_heights(field_m, None, 0.0)
}

/// Like [`flat_field`], with the heights of `height` (none: flat at 0), which stay within
/// 0..=`top_m`.
pub fn field_with_heights(
    field_m: f64,
    height: Option<HeightFn>,
    top_m: f32,
) -> Result<(World, Arc<dyn TileSource>)> {
    let manifest = field_manifest(field_m, top_m)?;
    let world = World {
        dir: PathBuf::from("<memory>"),
        manifest: manifest.clone(),
    };
    Ok((
        world,
        Arc::new(FlatField {
            manifest,
            field_m,
            height,
        }),
    ))
}

/// The camera of `opts`.
pub fn field_camera(opts: &BenchBladesOptions, aspect: f32) -> Camera {
    let eye = DVec3::from_array(opts.camera_m);
    let dir = (DVec3::from_array(opts.target_m) - eye)
        .normalize()
        .as_vec3();
    // Looking straight up or down, z cannot be the view's up: north is.
    let up = if dir.z.abs() > 0.999 {
        Vec3::Y
    } else {
        Vec3::Z
    };
    let view = glam::camera::rh::view::look_to_mat4(Vec3::ZERO, dir, up);
    let proj = glam::camera::rh::proj::directx::perspective_infinite_reverse(
        (opts.fov_deg as f32).to_radians(),
        aspect,
        0.1,
    );
    Camera::with_view(eye, view, proj)
}

/// The files [`run_bench_blades`] writes into its output folder.
const FILES: [&str; 5] = [
    "bench_blades.json",
    "blades.csv",
    "blades_time.png",
    "blades_ratio.png",
    "blades_error.png",
];

/// Runs the benchmark and writes `bench_blades.json`, `blades.csv`, `blades_time.png`,
/// `blades_ratio.png` and `blades_error.png` into `opts.out`. Stopped early
/// ([`BenchBladesOptions::stop`]), it writes them with the counts measured so far, the report
/// marked interrupted; stopped before the first count's images, it writes nothing.
pub fn run_bench_blades(
    opts: &BenchBladesOptions,
    progress: &mut dyn FnMut(&str, u64, u64),
) -> Result<BenchBladesReport> {
    opts.validate()?;
    let out_dir = OutDir::create_for(&opts.out, "bench blades", &Outputs::named(&FILES))?;
    let (world, source) = flat_field(opts.field_m)?;
    let ctx = GpuContext::new()?;
    let camera = field_camera(opts, opts.size.0 as f32 / opts.size.1 as f32);
    let counts = FrameCounts::for_adapter(&ctx.info).with(
        opts.warmup_frames,
        opts.timed_frames,
        opts.rounds,
    );
    let base = RingSettings::for_pyramid(&world.manifest.pyramid);
    let tile_m = world.manifest.pyramid.tile_size_m(base.level);
    // The whole field in view: the far corner from the camera is inside the view distance.
    let corner = DVec3::new(opts.field_m, opts.field_m, 0.0) - DVec3::from_array(opts.camera_m);
    let view_m = (corner.length() * 1.3).max(4.0 * tile_m);
    // The whole field is in view, so every stored tile of it is resident at once: the atlas
    // holds them all, or the field is refused for this GPU before anything is drawn.
    let most_slots = ctx
        .device
        .limits()
        .max_texture_array_layers
        .min(crate::terrain::GBUFFER_MAX_SLOTS);
    let field_tiles = world.manifest.pyramid.stored_tile_count();
    if field_tiles > u64::from(most_slots) {
        bail!(
            "--field-m {}: the field's {field_tiles} tiles, all in view, need more atlas slots \
             than this GPU binds ({most_slots}); take a smaller field",
            opts.field_m
        );
    }
    let field_slots = (field_tiles as u32 + 16).min(most_slots);
    let config = |(spacing, slot): (f64, u32), lod: bool| -> RendererConfig {
        let mut c = RendererConfig::for_world(&world);
        c.service.atlas_slots = c.service.atlas_slots.max(field_slots);
        c.grass_rings = Some(RingSettings {
            high_radius_m: if lod { 2.0 * tile_m } else { view_m },
            low_radius_m: view_m,
            ..base
        });
        c.grass.spacing_m = spacing as f32;
        c.grass.capacity = Some(slot);
        c
    };
    // Each count's spacing and the blades a slot needs for it (within MAX_SLOT_BLADES, which
    // fits a u32, once validated).
    let sizes: Vec<(f64, u32)> = opts
        .counts
        .iter()
        .map(|&n| {
            let slot = slot_blades(n, opts.field_m, tile_m)
                .and_then(|b| u32::try_from(b).ok())
                .with_context(|| format!("--counts {n}: too many blades a grass tile"))?;
            Ok((field_spacing_m(n, opts.field_m), slot))
        })
        .collect::<Result<_>>()?;
    let spacings: Vec<f64> = sizes.iter().map(|s| s.0).collect();
    let total = spacings.len() as u64;
    let stop = Stop::new(opts.stop.clone());
    let scene_for = |size: (f64, u32), lod: bool| -> Result<Scene> {
        let mut scene = Scene::with_source(
            &ctx,
            world.clone(),
            source.clone(),
            opts.size.0,
            opts.size.1,
            config(size, lod),
        )?;
        let warm_up = stop.warm_up(&mut scene, &camera, std::time::Duration::from_secs(60))?;
        if !warm_up.missing.is_empty() {
            bail!("the field's tiles did not load");
        }
        Ok(scene)
    };

    // Images (and the counts) first, against the truth of the same field and against it with
    // no LOD. The truth's blades reach nine times the default view distance, or as far as the
    // no-LOD render's where that is further (a large field); its pool slots are the count's.
    let slots = crate::tools::truth::atlas_slots(&world, &ctx.device);
    let truth_config = |size: (f64, u32)| {
        let mut c = crate::tools::truth::truth_config(&world, &config(size, false), slots);
        c.grass_rings = c.grass_rings.map(|r| {
            let view = r.low_radius_m.max(view_m);
            RingSettings {
                high_radius_m: r.high_radius_m.max(view / 0.7),
                low_radius_m: view,
                ..r
            }
        });
        c
    };
    // Then the timings, in interleaved rounds: the grass frame, then its floor.
    // The floor per statistics LOD: the high ring's near blades have more segments than the
    // rest of it; the floor counts them all at the rest's.
    let [_, high, low] = RendererConfig::for_world(&world).grass.segments;
    let segments = [high, low];
    let mut scenes = Vec::new();
    let mut images = Vec::new();
    let mut frame_samples = vec![Vec::new(); spacings.len()];
    let mut generate_samples = vec![Vec::new(); spacings.len()];
    let mut draw_samples = vec![Vec::new(); spacings.len()];
    let mut floor_samples = vec![Vec::new(); spacings.len()];
    let mut floor_vertices = vec![0u64; spacings.len()];
    // Stopped (Ctrl-C) at a count or a timing, the counts whose images were captured are
    // reported, with the rounds timed so far.
    let interrupted = caught((|| -> Result<()> {
        for (k, &size) in sizes.iter().enumerate() {
            stop.check()?;
            let truth = Truth::with_config(
                &ctx,
                world.clone(),
                source.clone(),
                opts.size,
                opts.truth_k,
                truth_config(size),
            )?;
            let walker = Some(camera.position.truncate());
            let truth_image = truth
                .with_stop(stop.clone())
                .render(&ctx, &camera, 0.0, walker)?;
            let mut reference = scene_for(size, false)?;
            reference.render(&ctx, &camera)?;
            let no_lod = reference.read_image(&ctx)?;
            drop(reference);
            let mut scene = scene_for(size, true)?;
            let stats = scene.render(&ctx, &camera)?;
            let image = scene.read_image(&ctx)?;
            let flip = f64::from(flip_compare(&rgb(&no_lod), &rgb(&image))?.mean);
            images.push((stats, Measures::of(&truth_image, &image)?, flip));
            scenes.push(scene);
            progress("images", k as u64 + 1, total);
        }

        let floor = FloorPass::new(&ctx, opts.size, segments);
        if let Some(scene) = scenes.first_mut() {
            ramp_up(&ctx, scene, &camera, 0.0, Some(camera.position.truncate()))?;
        }
        for round in 0..counts.rounds {
            for (k, scene) in scenes.iter_mut().enumerate() {
                stop.check()?;
                let walker = Some(camera.position.truncate());
                for (stats, wall) in run_frames(
                    &ctx,
                    scene,
                    &camera,
                    0.0,
                    walker,
                    counts.warmup,
                    counts.timed,
                )? {
                    let pass = |name: &str| {
                        stats
                            .gpu
                            .iter()
                            .filter(|(n, _)| n == name)
                            .map(|(_, t)| t)
                            .sum::<f64>()
                    };
                    frame_samples[k].push(if ctx.timestamps {
                        stats.gpu.iter().map(|(_, t)| t).sum()
                    } else {
                        wall
                    });
                    generate_samples[k].push(pass("grass_generate"));
                    draw_samples[k].push(pass("grass_draw"));
                }
                let drawn = images[k].0.grass.drawn;
                let (times, vertices) = floor.time(&ctx, drawn, counts)?;
                floor_samples[k].extend(times);
                floor_vertices[k] = vertices;
                progress(
                    "timing",
                    u64::from(round) * total + k as u64 + 1,
                    u64::from(counts.rounds) * total,
                );
            }
        }
        Ok(())
    })())?;
    drop(scenes);

    let mut results = Vec::new();
    for (k, &spacing) in spacings.iter().enumerate().take(images.len()) {
        let (stats, vs_truth, flip): &(FrameStats, Measures, f64) = &images[k];
        let g = &stats.grass;
        let vertices = strip_vertices(g.drawn, segments);
        let draw = Timing::of(&draw_samples[k]);
        let floor_t = Timing::of(&floor_samples[k]);
        let drawn = u64::from(g.drawn[0]) + u64::from(g.drawn[1]);
        let culled = (0..2)
            .map(|l| {
                g.culled_distance[l] + g.culled_frustum[l] + g.culled_occlusion[l] + g.overflow[l]
            })
            .sum();
        results.push(BladesResult {
            blades: opts.counts[k],
            spacing_m: spacing,
            considered: g.considered,
            empty: g.empty[0] + g.empty[1],
            culled,
            overflow: g.overflow[0] + g.overflow[1],
            drawn: g.drawn,
            vertices,
            generate: Timing::of(&generate_samples[k]),
            draw,
            frame: Timing::of(&frame_samples[k]),
            floor: floor_t,
            floor_vertices: floor_vertices[k],
            ns_per_blade: (drawn > 0).then(|| draw.median_ms * 1e6 / drawn as f64),
            ns_per_vertex: (vertices > 0).then(|| draw.median_ms * 1e6 / vertices as f64),
            ratio_to_floor: (floor_t.median_ms > 0.0).then(|| draw.median_ms / floor_t.median_ms),
            vs_truth: *vs_truth,
            flip_vs_no_lod: *flip,
        });
    }
    let report = BenchBladesReport {
        adapter: AdapterReport::of(&ctx),
        size: opts.size,
        truth_k: opts.truth_k,
        counts,
        results,
        interrupted,
    };
    if report.results.is_empty() {
        // Stopped before the first count's images: nothing measured, nothing written (an
        // earlier run's files stay as they were).
        return Ok(report);
    }
    write_outputs(opts, &report)?;
    write_json(&opts.out.join("bench_blades.json"), &report)?;
    out_dir.keep();
    Ok(report)
}

/// Vertices of the grass draw: a strip of `2 * segments + 1` vertices a blade, per LOD.
pub fn strip_vertices(drawn: [u32; 2], segments: [u32; 2]) -> u64 {
    (0..2)
        .map(|l| u64::from(drawn[l]) * u64::from(2 * segments[l] + 1))
        .sum()
}

/// Writes the table and the charts; the figures a run stopped early did not time are empty
/// cells, and left off the charts.
fn write_outputs(opts: &BenchBladesOptions, report: &BenchBladesReport) -> Result<()> {
    use std::fmt::Write as _;
    let results = &report.results;
    let title = |t: &str| chart_title(t, report.interrupted);
    let mut csv = String::from(
        "blades,spacing_m,considered_high,considered_low,empty,culled,drawn_high,drawn_low,vertices,\
         generate_ms,draw_ms,draw_q1_ms,draw_q3_ms,draw_spread,frame_ms,floor_ms,floor_spread,\
         floor_vertices,ns_per_blade,ns_per_vertex,ratio_to_floor,noisy,flip_vs_truth,\
         coarse_flip_vs_truth,flip_vs_no_lod,overflow\n",
    );
    for r in results {
        // A count's draw, frame, generation and floor are timed together.
        let t = &r.draw;
        let _ = writeln!(
            csv,
            "{},{:.4},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{:.5},{:.5},{:.5},{}",
            r.blades,
            r.spacing_m,
            r.considered[0],
            r.considered[1],
            r.empty,
            r.culled,
            r.drawn[0],
            r.drawn[1],
            r.vertices,
            t.cell(r.generate.median_ms, 4),
            t.cell(r.draw.median_ms, 4),
            t.cell(r.draw.q1_ms, 4),
            t.cell(r.draw.q3_ms, 4),
            t.cell(r.draw.spread, 4),
            t.cell(r.frame.median_ms, 4),
            t.cell(r.floor.median_ms, 4),
            t.cell(r.floor.spread, 4),
            if t.measured() {
                r.floor_vertices.to_string()
            } else {
                String::new()
            },
            r.ns_per_blade.map_or(String::new(), |v| t.cell(v, 3)),
            r.ns_per_vertex.map_or(String::new(), |v| t.cell(v, 4)),
            r.ratio_to_floor.map_or(String::new(), |v| t.cell(v, 3)),
            if t.measured() {
                (r.draw.noisy || r.floor.noisy).to_string()
            } else {
                String::new()
            },
            r.vs_truth.flip,
            r.vs_truth.coarse,
            r.flip_vs_no_lod,
            r.overflow
        );
    }
    write_text(&opts.out.join("blades.csv"), &csv)?;
    let series = |name: &str, f: &dyn Fn(&BladesResult) -> f64| Series {
        name: name.into(),
        points: results.iter().map(|r| (r.blades as f64, f(r))).collect(),
    };
    let timed_series = |name: &str, f: &dyn Fn(&BladesResult) -> Option<f64>| Series {
        name: name.into(),
        points: results
            .iter()
            .filter(|r| r.draw.measured())
            .filter_map(|r| Some((r.blades as f64, f(r)?)))
            .collect(),
    };
    LineChart {
        title: title("Grass GPU time against blade count"),
        x_label: "blades in the field".into(),
        y_label: "GPU time (ms)".into(),
        log_x: true,
        log_y: true,
        series: vec![
            timed_series("grass draw", &|r| Some(r.draw.median_ms)),
            timed_series("floor (same vertices, trivial shader)", &|r| {
                Some(r.floor.median_ms)
            }),
            timed_series("generation + wind", &|r| Some(r.generate.median_ms)),
            timed_series("whole frame", &|r| Some(r.frame.median_ms)),
        ],
    }
    .write_png(&opts.out.join("blades_time.png"), 900, 600)?;
    LineChart {
        title: title("Grass draw against the vertex floor"),
        x_label: "blades in the field".into(),
        y_label: "grass draw time / floor time".into(),
        log_x: true,
        log_y: false,
        series: vec![timed_series("ratio to floor", &|r| r.ratio_to_floor)],
    }
    .write_png(&opts.out.join("blades_ratio.png"), 900, 600)?;
    LineChart {
        title: title("Image error against blade count"),
        x_label: "blades in the field".into(),
        y_label: "FLIP".into(),
        log_x: true,
        log_y: false,
        series: vec![
            series("pixel FLIP against the truth", &|r| r.vs_truth.flip),
            series("coarse FLIP (8x8 blocks) against the truth", &|r| {
                r.vs_truth.coarse
            }),
            series("pixel FLIP against no LOD", &|r| r.flip_vs_no_lod),
        ],
    }
    .write_png(&opts.out.join("blades_error.png"), 900, 600)?;
    Ok(())
}

/// The floor: triangle strips of the grass draw's lengths and instance counts, drawn with a
/// trivial shader (each strip a sub-pixel sliver at a hashed place, so that it costs vertex and
/// primitive work but next to no fragments; one flat colour), timed with timestamps around the
/// pass. The pass loads its targets, as the grass draw does, so that no clear is timed.
struct FloorPass {
    /// A pipeline per LOD, its strips as long as the grass's.
    pipelines: [wgpu::RenderPipeline; 2],
    segments: [u32; 2],
    color: wgpu::TextureView,
    depth: wgpu::TextureView,
    queries: Option<(wgpu::QuerySet, wgpu::Buffer)>,
    period_ns: f64,
}

const FLOOR_WGSL: &str = r#"
override SEGMENTS: u32 = 7u;
fn hash(v: u32) -> u32 {
    var x = v;
    x ^= x >> 16u; x *= 0x7feb352du; x ^= x >> 15u; x *= 0x846ca68bu; x ^= x >> 16u;
    return x;
}
@vertex
fn vs(@builtin(vertex_index) vi: u32, @builtin(instance_index) ii: u32) -> @builtin(position) vec4<f32> {
    let h = hash(ii);
    let base = vec2<f32>(f32(h & 0xffffu), f32(h >> 16u)) / 65535.0 * 2.0 - 1.0;
    let side = f32(vi & 1u) * 0.0002;
    let up = f32(vi >> 1u) / f32(SEGMENTS) * 0.0004;
    return vec4<f32>(base + vec2<f32>(side, up), 0.5, 1.0);
}
@fragment
fn fs() -> @location(0) vec4<f32> {
    return vec4<f32>(0.2, 0.5, 0.1, 1.0);
}
"#;

impl FloorPass {
    fn new(ctx: &GpuContext, (width, height): (u32, u32), segments: [u32; 2]) -> Self {
        let device = &ctx.device;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("vertex floor"),
            source: wgpu::ShaderSource::Wgsl(FLOOR_WGSL.into()),
        });
        let target = |format, usage| {
            crate::gpu::target_texture(device, "vertex floor", format, usage, (width, height))
                .create_view(&Default::default())
        };
        let color = target(
            crate::terrain::COLOR_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        let depth = target(
            crate::terrain::DEPTH_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        let pipelines = segments.map(|n| floor_pipeline(device, &module, n));
        let queries = ctx.timestamps.then(|| {
            (
                device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("vertex floor"),
                    ty: wgpu::QueryType::Timestamp,
                    count: 2 * MAX_FLOOR_FRAMES,
                }),
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("vertex floor timestamps"),
                    size: u64::from(2 * MAX_FLOOR_FRAMES) * 8,
                    usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                }),
            )
        });
        Self {
            pipelines,
            segments,
            color,
            depth,
            queries,
            period_ns: f64::from(ctx.queue.get_timestamp_period()),
        }
    }

    /// Times `counts.warmup + counts.timed` floor frames back to back; returns the timed ones'
    /// GPU times (milliseconds; wall times between submissions without timestamps) and the
    /// vertices a frame drew, counted from the ranges of its draw calls.
    fn time(
        &self,
        ctx: &GpuContext,
        drawn: [u32; 2],
        counts: FrameCounts,
    ) -> Result<(Vec<f64>, u64)> {
        let frames = (counts.warmup + counts.timed).min(MAX_FLOOR_FRAMES);
        let mut walls = Vec::new();
        let mut vertices = 0u64;
        let mut last = std::time::Instant::now();
        for f in 0..frames {
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            {
                let mut pass = crate::gpu::pass::render_pass(
                    &mut encoder,
                    "vertex floor",
                    (&self.color, wgpu::LoadOp::Load),
                    Some((&self.depth, wgpu::LoadOp::Load)),
                    self.queries
                        .as_ref()
                        .map(|(q, _)| wgpu::RenderPassTimestampWrites {
                            query_set: q,
                            beginning_of_pass_write_index: Some(2 * f),
                            end_of_pass_write_index: Some(2 * f + 1),
                        }),
                );
                vertices = 0;
                for (l, pipeline) in self.pipelines.iter().enumerate() {
                    let (strip, instances) = (0..2 * self.segments[l] + 1, 0..drawn[l]);
                    vertices += u64::from(strip.len() as u32) * u64::from(instances.len() as u32);
                    pass.set_pipeline(pipeline);
                    pass.draw(strip, instances);
                }
            }
            if f + 1 == frames
                && let Some((q, b)) = &self.queries
            {
                encoder.resolve_query_set(q, 0..2 * frames, b, 0);
            }
            ctx.queue.submit([encoder.finish()]);
            let now = std::time::Instant::now();
            walls.push((now - last).as_secs_f64() * 1e3);
            last = now;
        }
        ctx.wait_idle();
        let skip = counts.warmup.min(frames) as usize;
        let times = match &self.queries {
            Some((_, b)) => {
                let ticks: Vec<u64> = crate::gpu::read_buffer_pod(
                    &ctx.device,
                    &ctx.queue,
                    b,
                    ..u64::from(frames) * 16,
                )?;
                ticks
                    .chunks_exact(2)
                    .skip(skip)
                    .map(|t| t[1].saturating_sub(t[0]) as f64 * self.period_ns / 1e6)
                    .collect()
            }
            None => walls.into_iter().skip(skip).collect(),
        };
        Ok((times, vertices))
    }
}

/// The floor's pipeline for strips of `segments` segments (`2 * segments + 1` vertices).
fn floor_pipeline(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    segments: u32,
) -> wgpu::RenderPipeline {
    let constants = [("SEGMENTS", f64::from(segments.max(1)))];
    crate::gpu::pipeline::render_pipeline(
        "vertex floor",
        module,
        ("vs", "fs"),
        crate::terrain::COLOR_FORMAT,
    )
    .constants(&constants, &[])
    .triangle_strips()
    .depth(
        crate::terrain::DEPTH_FORMAT,
        true,
        wgpu::CompareFunction::Greater,
    )
    .build(device)
}

/// Most floor frames timed in one call.
pub(crate) const MAX_FLOOR_FRAMES: u32 = 256;
// The largest timing options that benchmarks take stay within the floor pass's frames.
const _: () = assert!(
    crate::tools::bench::MAX_WARMUP_FRAMES + crate::tools::bench::MAX_TIMED_FRAMES
        <= MAX_FLOOR_FRAMES
);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_field_has_grass_tiles_of_the_stated_size() {
        let (world, _) = flat_field(200.0).unwrap();
        let level = RingSettings::for_pyramid(&world.manifest.pyramid).level;
        assert_eq!(world.manifest.pyramid.tile_size_m(level), FIELD_TILE_M);
    }

    #[test]
    fn slot_sizes_near_the_bound_do_not_wrap() {
        // The largest slot fits a u32 with room for the renderer's rounding up to 16.
        assert_eq!(MAX_SLOT_BLADES, 11_184_810);
        let range = count_range(200.0, FIELD_TILE_M);
        let top = slot_blades(*range.end(), 200.0, FIELD_TILE_M).unwrap();
        assert!(top <= MAX_SLOT_BLADES, "{top}");
        // In the default field the renderer's finest spacing, 2 cm, binds first: 2,500^2.
        assert_eq!(top, 2500 * 2500);
        // One past the bound needs no more (the grid rounds), but the counts beyond it do, and
        // they are counted in 64 bits: 10^12 blades are 250,000^2 a slot, not that wrapped
        // to 2,370,457,856 in 32 bits.
        assert_eq!(
            slot_blades(1_000_000_000_000, 200.0, FIELD_TILE_M),
            Some(62_500_000_000)
        );
        assert_eq!(slot_blades(u64::MAX, 10.0, FIELD_TILE_M), None);
        // Each end of every field's range keeps a slot within the bound and a blade a tile.
        for field in [10.0, 200.0, 1234.5, 5000.0] {
            let r = count_range(field, FIELD_TILE_M);
            for n in [*r.start(), *r.end()] {
                let slot = slot_blades(n, field, FIELD_TILE_M).unwrap();
                assert!((1..=MAX_SLOT_BLADES).contains(&slot), "{field} {n} {slot}");
                assert!(field_spacing_m(n, field) <= FIELD_TILE_M, "{field} {n}");
                let spacing = field_spacing_m(n, field) as f32;
                assert!(
                    crate::renderer::SPACING_RANGE_M.contains(&spacing),
                    "{field} {n} {spacing}"
                );
            }
        }
        // A big field needs a blade a tile (100 x 100 tiles) and no wider spacing than 5 m.
        assert_eq!(*count_range(5000.0, FIELD_TILE_M).start(), 1_000_000);
        // 100,000,004 blades are 1.99999996 cm apart, 2 cm as the renderer's f32 takes it.
        assert_eq!(count_range(200.0, FIELD_TILE_M), 1_600..=100_000_004);
    }

    #[test]
    fn absurd_options_name_the_option_and_its_range() {
        BenchBladesOptions::default().validate().unwrap();
        let bad = |o: BenchBladesOptions, needles: &[&str]| {
            let e = o.validate().unwrap_err().to_string();
            for n in needles {
                assert!(e.contains(n), "{n:?} not in {e:?}");
            }
        };
        let d = BenchBladesOptions::default;
        bad(
            BenchBladesOptions {
                counts: vec![1600, 1_000_000_000_000],
                ..d()
            },
            &[
                "--counts 1000000000000",
                "1600..=100000004",
                "--field-m 200",
            ],
        );
        bad(
            BenchBladesOptions {
                counts: vec![10],
                ..d()
            },
            &["--counts 10", "1600..="],
        );
        bad(
            BenchBladesOptions {
                counts: vec![5000, 9000, 5000],
                ..d()
            },
            &["--counts lists 5000 twice"],
        );
        bad(
            BenchBladesOptions {
                counts: vec![],
                ..d()
            },
            &["--counts", "1..=32 blade counts"],
        );
        bad(
            BenchBladesOptions {
                counts: vec![5000; 33],
                ..d()
            },
            &["--counts", "1..=32 blade counts"],
        );
        bad(
            BenchBladesOptions {
                field_m: f64::NAN,
                ..d()
            },
            &["--field-m NaN", "10..=5000 m"],
        );
        bad(
            BenchBladesOptions {
                fov_deg: 170.0,
                ..d()
            },
            &["--fov-deg 170", "between 1 and 170"],
        );
        bad(
            BenchBladesOptions {
                camera_m: [0.0, f64::INFINITY, 1.0],
                ..d()
            },
            &["--camera 0,inf,1", "-100000..=100000 m"],
        );
        bad(
            BenchBladesOptions {
                target_m: [-20.0, -20.0, 15.0],
                ..d()
            },
            &["--target -20,-20,15", "0.01 m from --camera"],
        );
        bad(
            BenchBladesOptions {
                size: (1920, 0),
                ..d()
            },
            &["--size 1920x0", "1..=16384"],
        );
        // Frame counts that would run for ever or wrap when added up.
        bad(
            BenchBladesOptions {
                warmup_frames: Some(u32::MAX),
                ..d()
            },
            &["--warmup-frames 4294967295", "0..=100"],
        );
        bad(
            BenchBladesOptions {
                timed_frames: Some(0),
                ..d()
            },
            &["--timed-frames 0", "1..=150"],
        );
        bad(
            BenchBladesOptions {
                rounds: Some(1_000_000),
                ..d()
            },
            &["--rounds 1000000", "1..=100"],
        );
    }

    #[test]
    fn a_camera_looking_straight_down_sees_the_field() {
        let opts = BenchBladesOptions {
            camera_m: [100.0, 100.0, 50.0],
            target_m: [100.0, 100.0, 0.0],
            ..BenchBladesOptions::default()
        };
        let cam = field_camera(&opts, 16.0 / 9.0);
        let m = cam.view_proj_relative(16.0 / 9.0);
        assert!(m.to_cols_array().iter().all(|v| v.is_finite()), "{m}");
        // The point below the camera is in the middle of the view.
        let p = m.project_point3(glam::Vec3::new(0.0, 0.0, -50.0));
        assert!(p.x.abs() < 1e-4 && p.y.abs() < 1e-4, "{p}");
    }
}
