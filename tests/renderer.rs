//! The renderer through its front door: targets of other formats and sizes (and after a
//! resize) render what the reference images show, a frame is recorded and submitted without
//! waiting for the GPU, and its figures come back later through a bounded ring.

mod common;

use std::time::Duration;

use verdant::camera::{Camera, sample_path};
use verdant::renderer::{MAX_READY_STATS, READBACK_SLOTS};
use verdant::world::World;
use verdant::{FrameInput, Renderer, RendererError, RendererOptions};

/// The camera of `default_world_matches_reference_image` (tests/render_terrain.rs).
fn overview_camera(world: &World) -> Camera {
    let path = world.manifest.path("overview").expect("overview path");
    let t = path.keys[0].t_s + 0.3 * (path.keys[path.keys.len() - 1].t_s - path.keys[0].t_s);
    sample_path(path, t)
}

struct Targets {
    color: wgpu::Texture,
    color_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
}

fn targets(
    device: &wgpu::Device,
    color_format: wgpu::TextureFormat,
    depth_format: wgpu::TextureFormat,
    (width, height): (u32, u32),
) -> Targets {
    let make = |format, usage| {
        verdant::gpu::target_texture(device, "test target", format, usage, (width, height))
    };
    use wgpu::TextureUsages as U;
    let color = make(color_format, U::RENDER_ATTACHMENT | U::COPY_SRC);
    let depth = make(depth_format, U::RENDER_ATTACHMENT | U::TEXTURE_BINDING);
    Targets {
        color_view: color.create_view(&Default::default()),
        depth_view: depth.create_view(&Default::default()),
        color,
    }
}

/// One frame into `t`, waited for; the image as RGBA8 (sRGB-encoded bytes).
fn draw(
    ctx: &verdant::gpu::GpuContext,
    renderer: &mut Renderer,
    t: &Targets,
    camera: Camera,
) -> image::RgbaImage {
    renderer.prepare(&ctx.queue, &FrameInput::new(camera, 0.0));
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    renderer
        .record(&mut encoder, &t.color_view, &t.depth_view)
        .expect("record");
    ctx.queue.submit([encoder.finish()]);
    let mut pixels =
        verdant::gpu::read_texture_rgba8(&ctx.device, &ctx.queue, &t.color).expect("read back");
    if matches!(
        t.color.format(),
        wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb
    ) {
        for px in pixels.chunks_exact_mut(4) {
            px.swap(0, 2);
        }
    }
    image::RgbaImage::from_raw(t.color.width(), t.color.height(), pixels).expect("size")
}

#[test]
fn bgra_unorm_and_depth24_targets_render_the_reference() {
    let ctx = common::gpu();
    let world = World::open(&common::default_world()).unwrap();
    let camera = overview_camera(&world);
    // A window's usual format: 8-bit BGRA without sRGB encoding on store (the shaders encode).
    let (color, depth) = (
        wgpu::TextureFormat::Bgra8Unorm,
        wgpu::TextureFormat::Depth24Plus,
    );
    let mut options = RendererOptions::new(&world, color, depth, 256, 144);
    // The reference is the scene's shading, one sample at each pixel's centre (the temporal
    // method's own tests are in tests/aa.rs).
    options.config.aa = verdant::aa::AntiAliasing::Off;
    let mut renderer = Renderer::new(&ctx.device, &ctx.queue, world, options).unwrap();
    assert!(renderer.warm_up(&camera, Duration::from_secs(60)).unwrap());
    let t = targets(&ctx.device, color, depth, (256, 144));
    let image = draw(&ctx, &mut renderer, &t, camera);
    // Same bounds as the Rgba8UnormSrgb render of this reference: encoding in the shader and
    // on store round alike to within a code value.
    common::check_reference("terrain_overview", &image, 0.01, 0.10);
}

#[test]
fn a_resized_renderer_renders_the_reference_at_its_new_size() {
    let ctx = common::gpu();
    let world = World::open(&common::default_world()).unwrap();
    let camera = overview_camera(&world);
    let (color, depth) = (
        wgpu::TextureFormat::Rgba8Unorm,
        wgpu::TextureFormat::Depth32Float,
    );
    let mut options = RendererOptions::new(&world, color, depth, 96, 200);
    // The reference is the scene's shading, one sample at each pixel's centre (the temporal
    // method's own tests are in tests/aa.rs).
    options.config.aa = verdant::aa::AntiAliasing::Off;
    let mut renderer = Renderer::new(&ctx.device, &ctx.queue, world, options).unwrap();
    assert!(renderer.warm_up(&camera, Duration::from_secs(60)).unwrap());
    let small = targets(&ctx.device, color, depth, (96, 200));
    draw(&ctx, &mut renderer, &small, camera);

    // Targets of the old size are refused after the resize, with both sizes named.
    renderer.resize(256, 144).unwrap();
    renderer.prepare(&ctx.queue, &FrameInput::new(camera, 0.0));
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    let err = renderer
        .record(&mut encoder, &small.color_view, &small.depth_view)
        .unwrap_err();
    assert!(matches!(err, RendererError::Target { .. }), "{err}");
    assert!(
        err.to_string().contains("96x200") && err.to_string().contains("256x144"),
        "{err}"
    );

    assert!(renderer.warm_up(&camera, Duration::from_secs(60)).unwrap());
    let big = targets(&ctx.device, color, depth, (256, 144));
    let image = draw(&ctx, &mut renderer, &big, camera);
    common::check_reference("terrain_overview", &image, 0.01, 0.10);
}

#[test]
fn unsupported_formats_and_a_missing_prepare_are_refused() {
    let ctx = common::gpu();
    let world = World::open(&common::default_world()).unwrap();
    let bad_color = RendererOptions::new(
        &world,
        wgpu::TextureFormat::R8Unorm,
        wgpu::TextureFormat::Depth32Float,
        64,
        64,
    );
    let e = Renderer::new(&ctx.device, &ctx.queue, world.clone(), bad_color)
        .err()
        .expect("R8Unorm refused");
    assert!(e.to_string().contains("R8Unorm"), "{e}");
    let bad_depth = RendererOptions::new(
        &world,
        wgpu::TextureFormat::Rgba8UnormSrgb,
        wgpu::TextureFormat::Depth16Unorm,
        64,
        64,
    );
    let e = Renderer::new(&ctx.device, &ctx.queue, world.clone(), bad_depth)
        .err()
        .expect("Depth16Unorm refused");
    assert!(e.to_string().contains("Depth16Unorm"), "{e}");

    let (c, d) = (
        wgpu::TextureFormat::Rgba8UnormSrgb,
        wgpu::TextureFormat::Depth32Float,
    );
    let mut renderer = Renderer::new(
        &ctx.device,
        &ctx.queue,
        world,
        RendererOptions::new(
            &World::open(&common::default_world()).unwrap(),
            c,
            d,
            64,
            64,
        ),
    )
    .unwrap();
    let t = targets(&ctx.device, c, d, (64, 64));
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    let e = renderer
        .record(&mut encoder, &t.color_view, &t.depth_view)
        .unwrap_err();
    assert!(matches!(e, RendererError::NotPrepared), "{e}");
}

#[test]
fn a_frame_is_recorded_and_submitted_without_waiting_and_its_figures_come_later() {
    let ctx = common::gpu();
    let world = World::open(&common::default_world()).unwrap();
    // Standing in the meadow: a frame full of grass, slow on a software renderer.
    let path = world.manifest.path("meadow").unwrap().clone();
    let camera = sample_path(&path, path.keys[0].t_s);
    let (c, d) = (
        wgpu::TextureFormat::Rgba8UnormSrgb,
        wgpu::TextureFormat::Depth32Float,
    );
    let size = (320, 180);
    let options = RendererOptions::new(&world, c, d, size.0, size.1);
    let mut renderer = Renderer::new(&ctx.device, &ctx.queue, world, options).unwrap();
    assert!(renderer.warm_up(&camera, Duration::from_secs(60)).unwrap());
    let t = targets(&ctx.device, c, d, size);
    assert!(renderer.stats().is_none(), "no frame yet, no figures");

    let done = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    renderer.prepare(&ctx.queue, &FrameInput::new(camera, 0.0));
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    renderer
        .record(&mut encoder, &t.color_view, &t.depth_view)
        .unwrap();
    let flag = done.clone();
    ctx.queue.submit([encoder.finish()]);
    ctx.queue
        .on_submitted_work_done(move || flag.store(true, std::sync::atomic::Ordering::SeqCst));
    // Back from prepare, record and submit while the GPU still works on the frame: nothing
    // in them waited for it.
    let _ = ctx.device.poll(wgpu::PollType::Poll);
    assert!(
        !done.load(std::sync::atomic::Ordering::SeqCst),
        "the frame's GPU work had finished when submit returned"
    );
    assert!(
        renderer.stats().is_none(),
        "figures before the GPU finished"
    );

    let _ = ctx.device.poll(wgpu::PollType::wait_indefinitely());
    assert!(done.load(std::sync::atomic::Ordering::SeqCst));
    let stats = renderer
        .stats()
        .expect("figures once the GPU finished")
        .clone();
    assert_eq!(stats.frame, 0);
    assert!(stats.tiles_drawn > 0);
    assert!(
        stats.grass.drawn[0] > 10_000,
        "meadow blades drawn: {:?}",
        stats.grass.drawn
    );
    if ctx.timestamps {
        assert!(stats.gpu.iter().any(|(n, t)| n == "grass_draw" && *t > 0.0));
    }
}

#[test]
fn figures_of_frames_in_flight_stay_within_the_ring() {
    let ctx = common::gpu();
    let (mut renderer, t, camera) = small_renderer(&ctx);
    // Many frames submitted back to back, none waited for, figures never taken.
    let frames = 3 * MAX_READY_STATS as u64;
    for i in 0..frames {
        frame(
            &ctx,
            &mut renderer,
            &t,
            &FrameInput::new(camera, i as f64 / 60.0),
        )
        .unwrap();
    }
    let _ = ctx.device.poll(wgpu::PollType::wait_indefinitely());
    let delivered = renderer.take_stats();
    assert!(
        delivered.len() <= MAX_READY_STATS,
        "{} figures kept",
        delivered.len()
    );
    assert!(!delivered.is_empty());
    // Oldest first, and the newest frames' figures are the ones kept.
    assert!(delivered.windows(2).all(|w| w[0].frame < w[1].frame));
    // Every frame's figures were delivered or counted as lost.
    assert_eq!(delivered.len() as u64 + renderer.stats_dropped(), frames);
    assert_eq!(
        delivered.last().unwrap().frame,
        frames - 1,
        "the newest are kept"
    );
    assert!(renderer.take_stats().is_empty(), "taken once");
    // The newest figures stay readable after they were taken (stats() said None).
    assert_eq!(renderer.stats().map(|s| s.frame), Some(frames - 1));
    // With figures taken every frame and the GPU waited for, none is lost.
    let before = renderer.stats_dropped();
    for i in 0..2 * READBACK_SLOTS as u64 {
        let input = FrameInput::new(camera, 1.0 + i as f64 / 60.0);
        frame(&ctx, &mut renderer, &t, &input).unwrap();
        let _ = ctx.device.poll(wgpu::PollType::wait_indefinitely());
        let got = renderer.take_stats();
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].frame, frames + i);
    }
    assert_eq!(renderer.stats_dropped(), before);
}

/// A device made with limits below WebGPU's defaults (a downlevel profile: four storage buffers
/// a stage, where the grass's compute pass binds six) is refused by `Renderer::new` naming the
/// limits (it panicked in wgpu's validation as a pipeline was made).
#[test]
fn a_device_with_downlevel_limits_is_refused_naming_them() {
    let ctx = common::gpu();
    let (device, queue) = device_with_limits(&ctx, wgpu::Limits::downlevel_defaults());
    let world = World::open(&common::default_world()).unwrap();
    let options = RendererOptions::new(
        &world,
        wgpu::TextureFormat::Rgba8UnormSrgb,
        wgpu::TextureFormat::Depth32Float,
        64,
        36,
    );
    let e = Renderer::new(&device, &queue, world, options)
        .err()
        .expect("refused");
    assert!(matches!(e, RendererError::DeviceLimits { .. }), "{e}");
    let text = e.to_string();
    assert!(
        text.contains("max_storage_buffers_per_shader_stage 4 (8 needed)")
            && text.contains("adapter.limits()"),
        "{text}"
    );
    // The adapter's own limits (what the tools and the example ask for) are enough.
    verdant::renderer::check_device_limits(&ctx.device).unwrap();
}

/// A device of the test's adapter with `limits`.
fn device_with_limits(
    ctx: &verdant::gpu::GpuContext,
    limits: wgpu::Limits,
) -> (wgpu::Device, wgpu::Queue) {
    pollster::block_on(ctx.adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("lower limits"),
        required_limits: limits,
        ..Default::default()
    }))
    .expect("a device with lower limits")
}

/// A device of the test's adapter whose largest storage buffer binding is 128 MiB (the WebGPU
/// default; many adapters allow no more).
fn device_with_small_buffers(ctx: &verdant::gpu::GpuContext) -> (wgpu::Device, wgpu::Queue) {
    let mut limits = ctx.adapter.limits();
    limits.max_storage_buffer_binding_size = limits.max_storage_buffer_binding_size.min(128 << 20);
    device_with_limits(ctx, limits)
}

#[test]
fn sizes_beyond_the_adapters_buffers_are_refused_with_the_limit_named() {
    let ctx = common::gpu();
    let (device, queue) = device_with_small_buffers(&ctx);
    let limits = device.limits();
    let world = World::open(&common::default_world()).unwrap();
    let (c, d) = (
        wgpu::TextureFormat::Rgba8UnormSrgb,
        wgpu::TextureFormat::Depth32Float,
    );
    // 7680x4320 fits every adapter's 2D textures; its Hi-Z pyramid (177 MB) does not fit a
    // 128 MiB binding.
    assert!(verdant::renderer::hiz_bytes(7680, 4320) > 128 << 20);
    let side = limits.max_texture_dimension_2d;
    for (w, h) in [(7680, 4320), (side, side)] {
        let options = RendererOptions::new(&world, c, d, w, h);
        let e = Renderer::new(&device, &queue, world.clone(), options)
            .err()
            .expect("refused");
        assert!(
            matches!(e, RendererError::SizeBeyondLimit { .. }),
            "{w}x{h}: {e}"
        );
        let text = e.to_string();
        assert!(
            text.contains("max_storage_buffer_binding_size") && text.contains(&format!("{w}x{h}")),
            "{text}"
        );
    }
    // A renderer resized beyond the limit refuses too, and keeps working at its old size.
    let options = RendererOptions::new(&world, c, d, 64, 36);
    let mut renderer = Renderer::new(&device, &queue, world.clone(), options).unwrap();
    let e = renderer.resize(7680, 4320).unwrap_err();
    assert!(matches!(e, RendererError::SizeBeyondLimit { .. }), "{e}");
    assert_eq!(
        (renderer.targets().width, renderer.targets().height),
        (64, 36)
    );
    // Without grass there is no Hi-Z pyramid, and the size is served.
    let mut options = RendererOptions::new(&world, c, d, 7680, 4320);
    options.config.grass_rings = None;
    Renderer::new(&device, &queue, world, options).unwrap();
}

#[test]
fn a_cache_too_small_for_one_tile_is_refused() {
    let ctx = common::gpu();
    let world = World::open(&common::default_world()).unwrap();
    let mut options = RendererOptions::new(
        &world,
        wgpu::TextureFormat::Rgba8UnormSrgb,
        wgpu::TextureFormat::Depth32Float,
        64,
        36,
    );
    options.config.service.cache_bytes = 0;
    let e = Renderer::new(&ctx.device, &ctx.queue, world, options)
        .err()
        .expect("refused");
    assert!(matches!(e, RendererError::CacheTooSmall { .. }), "{e}");
    assert!(e.to_string().contains("1 MiB"), "{e}");
}

/// A setting out of its range is refused by `Renderer::new` (through `RendererConfig::validate`)
/// with the field and its range named, never a panic: the library checks what every front end
/// hands it.
#[test]
fn settings_out_of_range_are_refused_by_the_renderer_with_their_range() {
    let ctx = common::gpu();
    let world = World::open(&common::default_world()).unwrap();
    let options = RendererOptions::new(
        &world,
        wgpu::TextureFormat::Rgba8UnormSrgb,
        wgpu::TextureFormat::Depth32Float,
        64,
        36,
    );
    type Change = dyn Fn(&mut verdant::RendererConfig);
    let cases: [(&Change, &str, &str); 4] = [
        (
            &|c| c.grass.segments = [5, 0, 3],
            "grass.segments",
            "1..=64 each",
        ),
        (
            &|c| c.grass.spacing_m = f32::NAN,
            "grass.spacing_m",
            "0.02..=5 m",
        ),
        (
            &|c| c.mesh_step = 5,
            "mesh_step",
            "a power of two in 1..=16",
        ),
        (&|c| c.lod_factor = -1.0, "lod_factor", "0.25..=8"),
    ];
    for (change, field, range) in cases {
        let mut options = options.clone();
        change(&mut options.config);
        let e = Renderer::new(&ctx.device, &ctx.queue, world.clone(), options)
            .err()
            .expect("refused");
        assert!(
            matches!(&e, RendererError::Config(c) if c.field == field),
            "{e}"
        );
        let text = e.to_string();
        assert!(text.contains(field) && text.contains(range), "{text}");
    }
}

/// Tiles of the world, except that every load at `level` fails.
struct FailingLevel {
    world: World,
    level: u8,
}

impl verdant::stream::TileSource for FailingLevel {
    fn load(
        &self,
        id: verdant::world::TileId,
    ) -> Result<verdant::world::TileData, verdant::world::WorldError> {
        if id.level == self.level {
            return self.world.load_tile(verdant::world::TileId::new(99, 0, 0));
        }
        self.world.load_tile(id)
    }
}

#[test]
fn a_warm_up_says_which_tiles_failed_and_does_not_wait_for_them() {
    let ctx = common::gpu();
    let world = World::open(&common::default_world()).unwrap();
    let source = std::sync::Arc::new(FailingLevel {
        world: world.clone(),
        level: 1,
    });
    let options = RendererOptions::new(
        &world,
        wgpu::TextureFormat::Rgba8UnormSrgb,
        wgpu::TextureFormat::Depth32Float,
        64,
        36,
    );
    let camera = overview_camera(&world);
    let mut renderer =
        Renderer::with_source(&ctx.device, &ctx.queue, world, source, options).unwrap();
    let start = std::time::Instant::now();
    let report = renderer
        .warm_up_report(&camera, Duration::from_secs(60))
        .unwrap();
    let waited = start.elapsed();
    assert!(
        waited < Duration::from_secs(20),
        "the warm-up waited {waited:?} for tiles that failed"
    );
    assert!(
        !report.missing.is_empty(),
        "level-1 tiles should be missing"
    );
    let lines = report.describe(5).join("\n");
    assert!(lines.contains("failed to load"), "{lines}");
    assert!(lines.contains("tile L"), "{lines}");
}

/// Renders `frames` frames along the tour's start, prepared, recorded and submitted one after
/// another, and returns the holes each frame's figures report.
fn holes_along_the_tour(skip_uploads: u32, frames: u32) -> Vec<u32> {
    let ctx = common::gpu();
    let world = World::open(&common::default_world()).unwrap();
    let path = world.manifest.paths[0].clone();
    let (c, d) = (
        wgpu::TextureFormat::Rgba8UnormSrgb,
        wgpu::TextureFormat::Depth32Float,
    );
    let mut options = RendererOptions::new(&world, c, d, 64, 36);
    options.config.grass_rings = None;
    let mut renderer = Renderer::new(&ctx.device, &ctx.queue, world, options).unwrap();
    renderer.skip_next_uploads(skip_uploads);
    let t = targets(&ctx.device, c, d, (64, 36));
    let mut holes = Vec::new();
    for f in 0..frames {
        let t_s = path.keys[0].t_s + f64::from(f) * 0.5;
        renderer.prepare(&ctx.queue, &FrameInput::new(sample_path(&path, t_s), t_s));
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        renderer
            .record(&mut encoder, &t.color_view, &t.depth_view)
            .unwrap();
        ctx.queue.submit([encoder.finish()]);
        ctx.wait_idle();
        // Let loads finish between frames, as frames of an application would.
        std::thread::sleep(Duration::from_millis(50));
        holes.extend(renderer.take_stats().iter().map(|s| s.residency.holes));
    }
    holes
}

#[test]
fn holes_are_counted_on_the_gpu_when_an_upload_is_lost() {
    // Every frame's atlas reads are checked against what the GPU's uploads and derivations
    // left in each slot. Streaming as it should: no holes.
    let clean = holes_along_the_tour(0, 12);
    assert_eq!(clean.len(), 12, "every frame's figures came back");
    assert!(
        clean.iter().all(|&h| h == 0),
        "holes without a fault: {clean:?}"
    );
    // The first uploads after start-up planned but never written: the tiles read from those
    // slots (and children derived from them) are holes.
    let lost = holes_along_the_tour(4, 12);
    assert!(
        lost.iter().any(|&h| h > 0),
        "lost uploads went unseen: {lost:?}"
    );
}

/// Standing in the meadow (1.7 m above the ground where the meadow path starts) looking
/// slightly down, with the terrain-only depth captured.
fn meadow_coverage(grass: bool) -> verdant::tools::metrics::Coverage {
    use verdant::RendererConfig;
    use verdant::tools::Scene;
    let ctx = common::gpu();
    let world = World::open(&common::default_world()).unwrap();
    let path = world.manifest.path("meadow").unwrap().clone();
    let mut camera = sample_path(&path, path.keys[0].t_s);
    let ground = common::Terrain::load(&common::default_world()).height(camera.position.truncate());
    camera.position.z = ground + 1.7;
    camera.pitch_deg = -12.0;
    let mut config = RendererConfig::for_world(&world);
    if !grass {
        config.grass_rings = None;
    }
    let mut scene = Scene::new(&ctx, world, 160, 90, config).unwrap();
    assert!(
        scene
            .warm_up(&ctx, &camera, Duration::from_secs(60))
            .unwrap()
    );
    assert!(matches!(
        scene.coverage(&ctx, 30.0),
        Err(verdant::tools::SceneError::NoCapture)
    ));
    scene.set_coverage_capture(true).unwrap();
    let stats = scene.render(&ctx, &camera).unwrap();
    // The pool's estimated capacity holds the densest view there is: standing in the meadow,
    // the infill and the near job's blades included.
    assert_eq!(stats.grass.overflow, [0, 0], "{:?}", stats.grass);
    scene.coverage(&ctx, 30.0).unwrap()
}

#[test]
fn grass_covers_nine_tenths_of_the_near_meadow_and_nothing_covers_it_without_grass() {
    let with = meadow_coverage(true);
    let without = meadow_coverage(false);
    eprintln!("meadow coverage at 160x90: with grass {with:?}, without {without:?}");
    assert!(with.pixels > 1000, "{with:?}");
    // The target for a full-density meadow seen from standing height.
    assert!(with.fraction >= 0.9, "{with:?}");
    assert_eq!(without.pixels, with.pixels, "the same terrain either way");
    assert_eq!((without.covered, without.fraction), (0, 0.0), "{without:?}");
}

/// Coverage standing 1.7 m up in a flat field at full density of the default world's grass type
/// `kind`, looking 12 degrees down.
fn field_coverage(kind: &str) -> verdant::tools::metrics::Coverage {
    use verdant::RendererConfig;
    use verdant::tools::Scene;
    use verdant::tools::bench_blades::flat_field;
    let ctx = common::gpu();
    let default = World::open(&common::default_world()).unwrap();
    let ty = default
        .manifest
        .grass_types
        .iter()
        .find(|t| t.name == kind)
        .unwrap()
        .clone();
    let (mut world, source) = flat_field(400.0).unwrap();
    world.manifest.grass_types[1] = ty;
    let mut config = RendererConfig::for_world(&world);
    // The field is generated, not read: room for a tile's blades, split and infilled.
    let g = config.grass_settings(&world).unwrap().grid();
    config.grass.capacity = Some(3 * g * g);
    let mut scene = Scene::with_source(&ctx, world, source, 160, 90, config).unwrap();
    let camera = Camera::new(glam::DVec3::new(200.0, 200.0, 1.7), 30.0, -12.0);
    assert!(
        scene
            .warm_up(&ctx, &camera, Duration::from_secs(60))
            .unwrap()
    );
    scene.set_coverage_capture(true).unwrap();
    scene.render(&ctx, &camera).unwrap();
    scene.coverage(&ctx, 30.0).unwrap()
}

#[test]
fn full_density_meadow_and_tall_grass_reach_their_coverage_from_standing_height() {
    for (kind, target) in [("meadow", 0.9), ("tall grass", 0.95)] {
        let c = field_coverage(kind);
        eprintln!("{kind} field at 160x90: {c:?}");
        assert!(c.pixels > 3000, "{kind}: {c:?}");
        assert!(
            c.fraction >= target,
            "{kind}: coverage {c:?} below {target}"
        );
    }
}

#[test]
fn the_terrain_depth_capture_needs_a_depth_target_it_can_copy() {
    let ctx = common::gpu();
    let world = World::open(&common::default_world()).unwrap();
    let options = RendererOptions::new(
        &world,
        wgpu::TextureFormat::Rgba8UnormSrgb,
        wgpu::TextureFormat::Depth24Plus,
        64,
        36,
    );
    let mut renderer = Renderer::new(&ctx.device, &ctx.queue, world, options).unwrap();
    let e = renderer.set_terrain_depth_capture(true).unwrap_err();
    assert!(matches!(e, RendererError::DepthCapture(_)), "{e}");
    assert!(renderer.terrain_depth().is_none());
    renderer.set_terrain_depth_capture(false).unwrap();

    // Depth32Float can be copied; the capture then needs a depth target it can copy from.
    let (c, d) = (
        wgpu::TextureFormat::Rgba8UnormSrgb,
        wgpu::TextureFormat::Depth32Float,
    );
    let world = World::open(&common::default_world()).unwrap();
    let camera = overview_camera(&world);
    let options = RendererOptions::new(&world, c, d, 64, 36);
    let mut renderer = Renderer::new(&ctx.device, &ctx.queue, world, options).unwrap();
    renderer.set_terrain_depth_capture(true).unwrap();
    renderer.resize(48, 27).unwrap();
    let copy = renderer.terrain_depth().expect("the capture is on");
    assert_eq!((copy.width(), copy.height(), copy.format()), (48, 27, d));
    let t = targets(&ctx.device, c, d, (48, 27));
    renderer.prepare(&ctx.queue, &FrameInput::new(camera, 0.0));
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    let e = renderer
        .record(&mut encoder, &t.color_view, &t.depth_view)
        .unwrap_err();
    assert!(
        matches!(e, RendererError::Target { which: "depth", .. }),
        "{e}"
    );
}

#[test]
fn passes_past_the_timers_room_are_counted_untimed_and_a_frame_has_room_for_every_batch() {
    let ctx = verdant::gpu::GpuContext::new().expect("a GPU adapter (software Vulkan will do)");
    assert!(ctx.timestamps, "the adapter has no timestamp queries");
    let mut timer = verdant::gpu::GpuTimer::new(&ctx.device, &ctx.queue, true, 2);
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    for frame in 0..2 {
        timer.begin_frame();
        for i in 0..3 {
            let writes = timer.compute_pass(&format!("pass {i}"));
            assert_eq!(writes.is_some(), i < 2, "frame {frame}, pass {i}");
            drop(encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: None,
                timestamp_writes: writes,
            }));
        }
        assert_eq!(timer.names(), ["pass 0", "pass 1"]);
        // Counted afresh each frame.
        assert_eq!(timer.untimed(), 1);
    }
    timer.resolve(&mut encoder);
    ctx.queue.submit([encoder.finish()]);
    // The renderer's timer: two passes for every batch of the most grass jobs a frame takes.
    let batches = verdant::grass::renderer::MAX_JOBS.div_ceil(verdant::grass::BATCH_TILES);
    assert!(verdant::renderer::MAX_TIMED_PASSES >= 2 * batches + 32);
    // and a query set of that many is one the device makes.
    let scope = ctx.device.push_error_scope(wgpu::ErrorFilter::Validation);
    let full = verdant::gpu::GpuTimer::new(
        &ctx.device,
        &ctx.queue,
        true,
        verdant::renderer::MAX_TIMED_PASSES,
    );
    let error = pollster::block_on(scope.pop());
    assert!(error.is_none(), "{error:?}");
    assert!(full.enabled());
}

/// A small renderer of the default world with its targets, for the tests of the front door's
/// refusals.
fn small_renderer(ctx: &verdant::gpu::GpuContext) -> (Renderer, Targets, Camera) {
    let world = World::open(&common::default_world()).unwrap();
    let camera = overview_camera(&world);
    let (c, d) = (
        wgpu::TextureFormat::Rgba8UnormSrgb,
        wgpu::TextureFormat::Depth32Float,
    );
    let options = RendererOptions::new(&world, c, d, 64, 36);
    let renderer = Renderer::new(&ctx.device, &ctx.queue, world, options).unwrap();
    (renderer, targets(&ctx.device, c, d, (64, 36)), camera)
}

/// Prepares and records one frame of `input` into `t`; submits it where it was recorded.
fn frame(
    ctx: &verdant::gpu::GpuContext,
    renderer: &mut Renderer,
    t: &Targets,
    input: &FrameInput,
) -> Result<(), RendererError> {
    renderer.prepare(&ctx.queue, input);
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    renderer.record(&mut encoder, &t.color_view, &t.depth_view)?;
    ctx.queue.submit([encoder.finish()]);
    Ok(())
}

/// A frame recorded into an encoder the application drops without submitting (its error
/// path) held its readback slot for ever: four such frames stopped every later frame's figures
/// for good, and fewer lost theirs without counting them. Now such a frame's figures are counted
/// as dropped, and its slot serves the next frames.
#[test]
fn frames_whose_encoders_are_dropped_unsubmitted_are_counted_and_the_ring_goes_on() {
    let ctx = common::gpu();
    let (mut renderer, t, camera) = small_renderer(&ctx);
    let abandoned = READBACK_SLOTS as u64 + 1;
    for i in 0..abandoned {
        renderer.prepare(&ctx.queue, &FrameInput::new(camera, i as f64 / 60.0));
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        renderer
            .record(&mut encoder, &t.color_view, &t.depth_view)
            .unwrap();
        if i % 2 == 1 {
            // Finished into a command buffer, which is dropped in its turn.
            drop(encoder.finish());
        }
    }
    for i in abandoned..abandoned + 3 {
        frame(
            &ctx,
            &mut renderer,
            &t,
            &FrameInput::new(camera, i as f64 / 60.0),
        )
        .unwrap();
        let _ = ctx.device.poll(wgpu::PollType::wait_indefinitely());
        let got = renderer.take_stats();
        assert_eq!(
            got.iter().map(|s| s.frame).collect::<Vec<_>>(),
            [i],
            "figures of the frame submitted"
        );
    }
    // Every abandoned frame counted: the last one's slot was free for the first frame after.
    assert_eq!(renderer.stats_dropped(), abandoned);
}

/// Inputs that cannot be drawn (a camera, time or jitter that is not finite, a field of view of
/// 0 or 180 degrees, a near plane at 0, matrices of the caller's that cannot be inverted, and
/// finite values whose projection is not, in 32 bits) gave
/// a frame of sky, or of nothing, with `Ok`, and a warm-up from a NaN camera said every tile was
/// resident. Each is refused naming what is wrong, and the next good frame draws. So is the
/// record of a frame prepared before a resize or a switch of anti-aliasing (it was drawn black,
/// or at the old size, with `Ok`).
#[test]
fn inputs_that_cannot_be_drawn_and_stale_frames_are_refused() {
    let ctx = common::gpu();
    let (mut renderer, t, camera) = small_renderer(&ctx);
    let with = |f: &dyn Fn(&mut FrameInput)| {
        let mut input = FrameInput::new(camera, 0.5);
        f(&mut input);
        input
    };
    let zero = verdant::camera::CustomView {
        view: glam::Mat4::IDENTITY,
        proj: glam::Mat4::ZERO,
    };
    let cases: Vec<(FrameInput, &str)> = vec![
        (with(&|i| i.camera.position.x = f64::NAN), "camera position"),
        (with(&|i| i.camera.yaw_deg = f64::INFINITY), "yaw inf"),
        (
            with(&|i| i.camera.fov_y_deg = 0.0),
            "field of view 0 degrees",
        ),
        (
            with(&|i| i.camera.fov_y_deg = 180.0),
            "field of view 180 degrees",
        ),
        (with(&|i| i.camera.near_m = 0.0), "near plane 0 m"),
        (with(&|i| i.camera.custom = Some(zero)), "projection matrix"),
        (with(&|i| i.time_s = f64::NAN), "time NaN s"),
        (with(&|i| i.jitter_px.x = f32::NAN), "jitter"),
        (
            with(&|i| i.walker = Some(glam::DVec2::NAN)),
            "walker position",
        ),
        // Finite each, but not in the projection they make (drawn as flat sky with `Ok`).
        (
            with(&|i| i.camera.fov_y_deg = 1e-40),
            "view-projection is not finite and invertible",
        ),
        (
            with(&|i| i.camera.near_m = 1e-45),
            "view-projection is not finite and invertible",
        ),
        (
            with(&|i| i.jitter_px = glam::Vec2::splat(3e38)),
            "view-projection with its jitter is not finite",
        ),
    ];
    for (input, want) in &cases {
        let e = frame(&ctx, &mut renderer, &t, input).unwrap_err();
        assert!(matches!(e, RendererError::FrameInput(_)), "{e}");
        let message = e.to_string();
        assert!(message.contains(want), "{want:?} in {message}");
        assert!(message.starts_with("the frame's input cannot be drawn: "));
    }
    let mut nan = camera;
    nan.pitch_deg = f64::NAN;
    let e = renderer
        .warm_up(&nan, Duration::from_secs(1))
        .expect_err("a warm-up from a NaN camera");
    assert!(e.to_string().contains("pitch NaN"), "{e}");
    frame(&ctx, &mut renderer, &t, &FrameInput::new(camera, 1.0)).unwrap();

    // A change between prepare and record.
    for change in ["resized", "switched"] {
        renderer.prepare(&ctx.queue, &FrameInput::new(camera, 2.0));
        if change == "resized" {
            renderer.resize(32, 18).unwrap();
        } else {
            renderer
                .set_anti_aliasing(verdant::aa::AntiAliasing::Msaa)
                .unwrap();
        }
        let t = targets(
            &ctx.device,
            t.color.format(),
            wgpu::TextureFormat::Depth32Float,
            (32, 18),
        );
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        let e = renderer
            .record(&mut encoder, &t.color_view, &t.depth_view)
            .unwrap_err();
        assert!(matches!(e, RendererError::ChangedAfterPrepare(_)), "{e}");
        assert!(
            e.to_string().contains(change) && e.to_string().contains("prepare the frame again"),
            "{e}"
        );
        frame(&ctx, &mut renderer, &t, &FrameInput::new(camera, 3.0)).unwrap();
    }
}
