//! The caller's targets and formats through `Renderer::record` and `Renderer::new`: a target
//! that does not match the renderer (format, usage, samples, mip levels, layers, size of the
//! view) is an error naming what was expected and what was found, never a wgpu validation
//! panic; a view of one mip level or one layer that does match draws; a colour format the
//! device cannot draw into is refused saying why and which formats it can.

mod common;

use glam::DVec3;
use verdant::aa::AntiAliasing;
use verdant::world::World;
use verdant::{Camera, FrameInput, Renderer, RendererError, RendererOptions};
use wgpu::TextureFormat as F;
use wgpu::TextureUsages as U;

const W: u32 = 64;
const H: u32 = 36;
const CF: F = F::Rgba16Float;
const DF: F = F::Depth32Float;

fn camera() -> Camera {
    Camera::new(DVec3::new(20230.0, 28202.0, 52.0), -22.0, -6.0)
}

fn world() -> World {
    World::open(&common::default_world()).unwrap()
}

/// A texture of `(width, height, layers)`, `mips` levels and `samples` samples.
fn texture(
    device: &wgpu::Device,
    (width, height, layers): (u32, u32, u32),
    format: F,
    usage: U,
    mips: u32,
    samples: u32,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some("test target"),
        size: wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: layers,
        },
        mip_level_count: mips,
        sample_count: samples,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    })
}

fn whole(t: &wgpu::Texture) -> wgpu::TextureView {
    t.create_view(&Default::default())
}

/// A 2D view of mip level `mip` of layer `layer`.
fn level(t: &wgpu::Texture, mip: u32, layer: u32) -> wgpu::TextureView {
    t.create_view(&wgpu::TextureViewDescriptor {
        dimension: Some(wgpu::TextureViewDimension::D2),
        base_mip_level: mip,
        mip_level_count: Some(1),
        base_array_layer: layer,
        array_layer_count: Some(1),
        ..Default::default()
    })
}

fn record(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    renderer: &mut Renderer,
    color: &wgpu::TextureView,
    depth: &wgpu::TextureView,
) -> Result<(), RendererError> {
    let mut encoder = device.create_command_encoder(&Default::default());
    let result = renderer.record(&mut encoder, color, depth);
    queue.submit([encoder.finish()]);
    result
}

#[test]
fn targets_that_do_not_match_are_refused_naming_both_and_matching_views_draw() {
    let ctx = common::gpu();
    let (device, queue) = (&ctx.device, &ctx.queue);
    let world = world();
    let mut options = RendererOptions::new(&world, CF, DF, W, H);
    options.config.aa = AntiAliasing::Off;
    let mut renderer = Renderer::new(device, queue, world, options).unwrap();
    renderer.prepare(queue, &FrameInput::new(camera(), 0.0));

    let color_usage = U::RENDER_ATTACHMENT | U::COPY_SRC;
    let depth_usage = U::RENDER_ATTACHMENT | U::TEXTURE_BINDING;
    let color =
        |size, format, usage, mips, samples| texture(device, size, format, usage, mips, samples);
    let good_color = whole(&color((W, H, 1), CF, color_usage, 1, 1));
    let good_depth = whole(&color((W, H, 1), DF, depth_usage, 1, 1));
    let c_mips = color((W, H, 1), CF, color_usage, 2, 1);
    let d_mips = color((W, H, 1), DF, depth_usage, 2, 1);
    let c_layers = color((W, H, 2), CF, color_usage, 1, 1);
    let d_layers = color((W, H, 2), DF, depth_usage, 1, 1);
    // (what, the targets, which is refused, words the error holds)
    let cases: Vec<(&str, wgpu::TextureView, wgpu::TextureView, &str, Vec<&str>)> = vec![
        (
            "colour format",
            whole(&color((W, H, 1), F::Rgba8UnormSrgb, color_usage, 1, 1)),
            good_depth.clone(),
            "colour",
            vec!["Rgba8UnormSrgb", "Rgba16Float"],
        ),
        (
            "colour usage",
            whole(&color((W, H, 1), CF, U::COPY_SRC, 1, 1)),
            good_depth.clone(),
            "colour",
            vec!["COPY_SRC", "RENDER_ATTACHMENT"],
        ),
        (
            "colour samples",
            whole(&color((W, H, 1), CF, U::RENDER_ATTACHMENT, 1, 4)),
            good_depth.clone(),
            "colour",
            vec!["4 samples", "1 sample"],
        ),
        (
            "colour size",
            whole(&color((W + 1, H, 1), CF, color_usage, 1, 1)),
            good_depth.clone(),
            "colour",
            vec!["65x36", "64x36"],
        ),
        (
            "colour view of two mip levels",
            whole(&c_mips),
            good_depth.clone(),
            "colour",
            vec!["64x36", "2 mip levels", "one mip level"],
        ),
        (
            "colour view of a mip level of the wrong size",
            level(&c_mips, 1, 0),
            good_depth.clone(),
            "colour",
            vec!["64x36", "32x18"],
        ),
        (
            "colour view of two layers",
            whole(&c_layers),
            good_depth.clone(),
            "colour",
            vec!["2 layers", "one layer"],
        ),
        (
            "depth format",
            good_color.clone(),
            whole(&color((W, H, 1), F::Depth24Plus, depth_usage, 1, 1)),
            "depth",
            vec!["Depth24Plus", "Depth32Float"],
        ),
        (
            "depth usage",
            good_color.clone(),
            whole(&color((W, H, 1), DF, U::RENDER_ATTACHMENT, 1, 1)),
            "depth",
            vec!["TEXTURE_BINDING"],
        ),
        (
            "depth samples",
            good_color.clone(),
            whole(&color((W, H, 1), DF, depth_usage, 1, 4)),
            "depth",
            vec!["4 samples", "1 sample"],
        ),
        (
            "depth size",
            good_color.clone(),
            whole(&color((2 * W, 2 * H, 1), DF, depth_usage, 1, 1)),
            "depth",
            vec!["128x72", "64x36"],
        ),
        (
            "depth view of two mip levels",
            good_color.clone(),
            whole(&d_mips),
            "depth",
            vec!["2 mip levels", "one mip level"],
        ),
        (
            "depth view of a mip level of the wrong size",
            good_color.clone(),
            level(&d_mips, 1, 0),
            "depth",
            vec!["64x36", "32x18"],
        ),
        (
            "depth view of two layers",
            good_color.clone(),
            whole(&d_layers),
            "depth",
            vec!["2 layers", "one layer"],
        ),
        (
            "depth view of one layer as a 2D array",
            good_color.clone(),
            d_layers.create_view(&wgpu::TextureViewDescriptor {
                dimension: Some(wgpu::TextureViewDimension::D2Array),
                array_layer_count: Some(1),
                ..Default::default()
            }),
            "depth",
            vec!["D2"],
        ),
    ];
    for (what, c, d, which, words) in &cases {
        // Twice: a refused pair is not remembered as checked.
        for _ in 0..2 {
            let e = record(device, queue, &mut renderer, c, d).expect_err(what);
            let RendererError::Target { which: w, .. } = &e else {
                panic!("{what}: {e}");
            };
            assert_eq!(w, which, "{what}: {e}");
            let text = e.to_string();
            for word in words {
                assert!(text.contains(word), "{what}: {word:?} not in: {text}");
            }
        }
    }

    // Views that match draw: the colour a view of mip 1 of a texture twice the size, the
    // depth a 2D view of the second layer (read by the Hi-Z pyramid and every pass through
    // the view, not the texture's first layer).
    let big = color((2 * W, 2 * H, 1), CF, color_usage, 2, 1);
    let layered = color((W, H, 2), DF, depth_usage, 1, 1);
    let (c, d) = (level(&big, 1, 0), level(&layered, 0, 1));
    for frame in 0..2 {
        renderer.prepare(queue, &FrameInput::new(camera(), f64::from(frame) / 60.0));
        record(device, queue, &mut renderer, &c, &d).expect("views that match");
    }
    renderer.prepare(queue, &FrameInput::new(camera(), 0.1));
    record(device, queue, &mut renderer, &good_color, &good_depth).expect("whole textures");
    device.poll(wgpu::PollType::wait_indefinitely()).unwrap();

    // The terrain-only depth is copied from the depth texture's first level and layer: with
    // the capture on, a view of another level or layer is refused.
    renderer.set_terrain_depth_capture(true).unwrap();
    renderer.prepare(queue, &FrameInput::new(camera(), 0.2));
    let copyable = color((W, H, 2), DF, depth_usage | U::COPY_SRC, 1, 1);
    let e = record(
        device,
        queue,
        &mut renderer,
        &good_color,
        &level(&copyable, 0, 1),
    )
    .expect_err("capture from layer 1");
    assert!(
        matches!(e, RendererError::Target { which: "depth", .. }),
        "{e}"
    );
    assert!(e.to_string().contains("capture"), "{e}");
}

/// A device of `features` on the test adapter; `None` where the adapter lacks one.
fn device_with(features: wgpu::Features) -> (wgpu::Device, wgpu::Queue) {
    let instance = verdant::gpu::GpuContext::instance(None);
    let adapter = pollster::block_on(instance.request_adapter(&Default::default()))
        .expect("a GPU adapter (software Vulkan is enough)");
    // Software Vulkan (lavapipe) and desktop GPUs have both; a test that cannot run fails.
    assert!(
        adapter.features().contains(features),
        "the adapter lacks {:?}, which this test needs",
        features.difference(adapter.features())
    );
    pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        required_features: features,
        required_limits: adapter.limits(),
        ..Default::default()
    }))
    .expect("a device with the features")
}

#[test]
fn colour_formats_the_device_cannot_draw_into_are_refused_saying_why() {
    let ctx = common::gpu();
    let world = world();
    for (format, why) in [
        (F::Rgba32Float, "FLOAT32_BLENDABLE"),
        (F::Rg11b10Ufloat, "RG11B10UFLOAT_RENDERABLE"),
        (F::Rgba16Unorm, "TEXTURE_FORMAT_16BIT_NORM"),
    ] {
        let options = RendererOptions::new(&world, format, DF, W, H);
        let e = Renderer::new(&ctx.device, &ctx.queue, world.clone(), options)
            .err()
            .unwrap_or_else(|| panic!("{format:?} accepted on a device without {why}"));
        assert!(
            matches!(e, RendererError::ColorFormatOnDevice { .. }),
            "{format:?}: {e}"
        );
        let text = e.to_string();
        for word in [&format!("{format:?}"), why, "Rgba16Float", "Bgra8UnormSrgb"] {
            assert!(text.contains(word), "{format:?}: {word:?} not in: {text}");
        }
        // The feature by its name, not wgpu's structure ("Features { features_wgpu: ...").
        assert!(!text.contains("Features {"), "{format:?}: {text}");
    }
}

#[test]
fn float_formats_draw_on_a_device_with_their_features_and_msaa_asks_for_its_own() {
    let features = wgpu::Features::FLOAT32_BLENDABLE | wgpu::Features::RG11B10UFLOAT_RENDERABLE;
    let (device, queue) = device_with(features);
    let world = world();
    for format in [F::Rg11b10Ufloat, F::Rgba32Float] {
        let mut options = RendererOptions::new(&world, format, DF, W, H);
        options.config.aa = AntiAliasing::Off;
        let mut renderer = Renderer::new(&device, &queue, world.clone(), options).unwrap();
        renderer.prepare(&queue, &FrameInput::new(camera(), 0.0));
        let c = whole(&texture(
            &device,
            (W, H, 1),
            format,
            U::RENDER_ATTACHMENT,
            1,
            1,
        ));
        let d = texture(
            &device,
            (W, H, 1),
            DF,
            U::RENDER_ATTACHMENT | U::TEXTURE_BINDING,
            1,
            1,
        );
        record(&device, &queue, &mut renderer, &c, &whole(&d)).unwrap();
        device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
        if format == F::Rgba32Float {
            // Switched to multisampling later: refused as at the start, the frame as it was.
            let e = renderer
                .set_anti_aliasing(AntiAliasing::Msaa)
                .expect_err("Rgba32Float switched to multisampling");
            assert!(e.to_string().contains("multisampl"), "{e}");
            assert_eq!(renderer.anti_aliasing(), AntiAliasing::Off);
        }
    }
    // Rgba32Float is never multisampled (WebGPU guarantees no 4x samples of it).
    let mut options = RendererOptions::new(&world, F::Rgba32Float, DF, W, H);
    options.config.aa = AntiAliasing::Msaa;
    let e = Renderer::new(&device, &queue, world, options)
        .err()
        .expect("Rgba32Float with multisampling");
    assert!(e.to_string().contains("multisampl"), "{e}");
}
