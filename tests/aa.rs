//! The temporal anti-aliasing resolve on the GPU (`shaders/aa_taa.wgsl`) against its CPU
//! mirror (`verdant::aa::taa_cpu`): the same frames, depths and camera moves give the same
//! output, frame after frame; and the renderer with it on converges on a still view.

mod common;

use glam::{DVec3, Mat4, Vec3, Vec4};
use verdant::aa::taa::{Taa, TaaSettings, reprojection};
use verdant::aa::taa_cpu::ResolveInput;
use verdant::camera::Camera;
use verdant::gpu::{GpuTimer, Targets};

const W: u32 = 40;
const H: u32 = 28;

fn srgb_to_linear(v: u8) -> f32 {
    let c = f32::from(v) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

fn linear_to_srgb(c: f32) -> f32 {
    let c = c.max(0.0);
    255.0
        * if c <= 0.0031308 {
            c * 12.92
        } else {
            1.055 * c.powf(1.0 / 2.4) - 0.055
        }
}

/// A frame of thin bright lines on a dark gradient (the kind of image the method is for),
/// shifted by `phase` pixels, and a depth with a near band and a sky strip.
fn frame(phase: u32) -> (Vec<u8>, Vec<f32>) {
    let mut rgba = Vec::new();
    let mut depth = Vec::new();
    for y in 0..H {
        for x in 0..W {
            let line = (x + phase).is_multiple_of(7) || (x + 2 * y + phase).is_multiple_of(11);
            let base = [20 + (y * 3) as u8, 60 + (x * 2) as u8, 30];
            let c = if line { [230, 240, 120] } else { base };
            rgba.extend_from_slice(&[c[0], c[1], c[2], 255]);
            depth.push(if y < 4 {
                0.0
            } else if (12..18).contains(&y) {
                0.2
            } else {
                0.01 + 0.001 * y as f32
            });
        }
    }
    (rgba, depth)
}

/// A half float's bits, for values in its normal range or 0 (the mantissa truncated).
fn f16_bits(v: f32) -> u16 {
    if v == 0.0 {
        return 0;
    }
    let b = v.to_bits();
    let exp = ((b >> 23) & 0xff) as i32 - 127 + 15;
    assert!(
        (1..31).contains(&exp),
        "{v} is outside a half float's normal range"
    );
    (((b >> 16) & 0x8000) | ((exp as u32) << 10) | ((b >> 13) & 0x3ff)) as u16
}

/// The value of a half float's bits (normal range or 0).
fn f16_value(h: u16) -> f32 {
    if h & 0x7fff == 0 {
        return 0.0;
    }
    let (sign, exp, man) = (
        (h >> 15) as u32,
        ((h >> 10) & 0x1f) as u32,
        (h & 0x3ff) as u32,
    );
    f32::from_bits((sign << 31) | ((exp + 127 - 15) << 23) | (man << 13))
}

/// Blades' motion vectors over `depth`: every third pixel moved by a step that changes with
/// `phase`, at its own depth (the blade is the pixel's surface), and on the left half some
/// pixels whose depth is not the frame's (a blade covered by something drawn after it); among
/// the rest, falling leaves' marks, at the pixel's depth and not. As half floats, and as the
/// values those hold.
fn motion(phase: u32, depth: &[f32]) -> (Vec<u16>, Vec<Vec4>) {
    let mut bits = Vec::new();
    for y in 0..H {
        for x in 0..W {
            let d = depth[(y * W + x) as usize];
            let m = match (x + y + phase) % 3 {
                0 if d > 0.0 => [1.5, -0.75 + 0.5 * phase as f32, d, 1.0],
                1 if d > 0.0 && x < W / 2 => [-2.0, 1.0, 0.5 * d, 1.0],
                // Falling leaves' marks: the pixel's current sample alone, where the leaf is
                // still its surface, and not under something drawn over it.
                2 if d > 0.0 && (x * 7 + y * 5 + phase).is_multiple_of(4) => [0.0, 0.0, d, 2.0],
                2 if d > 0.0 && (x * 7 + y * 5 + phase) % 4 == 1 => [0.0, 0.0, 0.5 * d, 2.0],
                _ => [0.0; 4],
            };
            bits.extend(m.map(f16_bits));
        }
    }
    let values = bits
        .chunks(4)
        .map(|c| {
            Vec4::new(
                f16_value(c[0]),
                f16_value(c[1]),
                f16_value(c[2]),
                f16_value(c[3]),
            )
        })
        .collect();
    (bits, values)
}

const DEPTH_IN: &str = r#"
@group(0) @binding(0) var values: texture_2d<f32>;

@vertex
fn vs(@builtin(vertex_index) vi: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2<f32>(f32((vi << 1u) & 2u), f32(vi & 2u));
    return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
}

@fragment
fn fs(@builtin(position) pos: vec4<f32>) -> @builtin(frag_depth) f32 {
    return textureLoad(values, vec2<i32>(pos.xy), 0).r;
}
"#;

#[test]
fn the_gpu_resolve_matches_its_cpu_mirror_over_a_moving_sequence() {
    let ctx = common::gpu();
    // The neighbourhood's clip with and without a history that shortens with parallax, the
    // clip that also reaches the pixel's own spread over time, and a short history that a
    // surface moving far enough drops down to its current sample, reconstructed at the
    // pixels' centres from the jittered samples.
    // The last two: the defaults, and a history that shortens with the blades' own motion
    // (their sway) too.
    let mut outputs = Vec::new();
    for (pixel_spread, parallax_falloff, max_samples, min_samples, reconstruct_px, sway_falloff) in [
        (0.0, 0.0, 24, 2.0, 0.0, 0.0),
        (0.0, 2.0, 24, 2.0, 0.0, 0.0),
        (2.5, 2.0, 24, 2.0, 0.0, 0.0),
        (0.0, 2.0, 8, 1.0, 0.0, 0.0),
        (0.0, 2.0, 8, 1.0, 0.4, 0.0),
        (0.0, 2.0, 24, 1.0, 0.45, 0.0),
        (0.0, 2.0, 24, 1.0, 0.45, 4.0),
    ] {
        outputs.push(resolve_matches_mirror(
            &ctx,
            TaaSettings {
                pixel_spread,
                parallax_falloff,
                max_samples,
                min_samples,
                reconstruct_px,
                sway_falloff,
                ..TaaSettings::default()
            },
        ));
    }
    // The sway's falloff changes what the GPU resolves where blades wrote their motion.
    let (plain, sway) = (&outputs[outputs.len() - 2], &outputs[outputs.len() - 1]);
    let differ = plain
        .iter()
        .zip(sway)
        .filter(|(a, b)| a.abs_diff(**b) > 1)
        .count();
    assert!(
        differ > 100,
        "the sway falloff changed only {differ} channels"
    );
}

/// The resolve on the GPU with `settings` against its CPU mirror over six frames; returns the
/// GPU's frames, one after another (RGBA8).
fn resolve_matches_mirror(ctx: &verdant::gpu::GpuContext, settings: TaaSettings) -> Vec<u8> {
    let targets = Targets {
        color_format: wgpu::TextureFormat::Rgba8UnormSrgb,
        depth_format: wgpu::TextureFormat::Depth32Float,
        width: W,
        height: H,
    };
    let mut taa = Taa::new(&ctx.device, &targets, settings);
    let size = wgpu::Extent3d {
        width: W,
        height: H,
        depth_or_array_layers: 1,
    };
    let depth_tex = ctx.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("depth"),
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Depth32Float,
        usage: wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::COPY_DST
            | wgpu::TextureUsages::RENDER_ATTACHMENT,
        view_formats: &[],
    });
    let color = verdant::gpu::target_texture(
        &ctx.device,
        "color",
        targets.color_format,
        wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        (W, H),
    );
    let color_view = color.create_view(&Default::default());
    let depth_view = depth_tex.create_view(&Default::default());
    // Depth targets take no copies: a full-screen pass writes the test's depths into it.
    let depth_src = verdant::gpu::target_texture(
        &ctx.device,
        "depth values",
        wgpu::TextureFormat::R32Float,
        wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        (W, H),
    );
    let module = ctx
        .device
        .create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("depth in"),
            source: wgpu::ShaderSource::Wgsl(DEPTH_IN.into()),
        });
    let depth_in = ctx
        .device
        .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("depth in"),
            layout: None,
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: Default::default(),
            depth_stencil: Some(wgpu::DepthStencilState {
                format: wgpu::TextureFormat::Depth32Float,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Always),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs"),
                compilation_options: Default::default(),
                targets: &[],
            }),
            multiview_mask: None,
            cache: None,
        });
    let depth_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("depth in"),
        layout: &depth_in.get_bind_group_layout(0),
        entries: &[wgpu::BindGroupEntry {
            binding: 0,
            resource: wgpu::BindingResource::TextureView(
                &depth_src.create_view(&Default::default()),
            ),
        }],
    });
    let mut timer = GpuTimer::new(&ctx.device, &ctx.queue, false, 0);
    let write = |texture: &wgpu::Texture, bytes: &[u8], aspect| {
        ctx.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect,
            },
            bytes,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(4 * W),
                rows_per_image: Some(H),
            },
            size,
        );
    };

    // A camera that holds still, then moves sideways and turns a little: the history is
    // reprojected by the depth (or by the blades' motion where they are the pixel's surface),
    // clipped, and blended.
    let mut camera = Camera::new(DVec3::new(0.0, 0.0, 10.0), 0.0, -5.0);
    let aspect = W as f32 / H as f32;
    let mut history = vec![Vec4::ZERO; (W * H) as usize];
    let mut spread = vec![Vec4::ZERO; (W * H) as usize];
    let mut last: Option<(Mat4, DVec3)> = None;
    let mut frames = Vec::new();
    for step in 0..6u32 {
        if step >= 3 {
            camera.position.y += 0.3;
            camera.yaw_deg += 0.7;
        }
        let vp = camera.view_proj_relative(aspect);
        let (rgba, depth) = frame(step);
        write(taa.scene_view().texture(), &rgba, wgpu::TextureAspect::All);
        write(
            &depth_src,
            bytemuck::cast_slice(&depth),
            wgpu::TextureAspect::All,
        );
        let (motion_bits, motion) = motion(step, &depth);
        ctx.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: taa.motion_view().texture(),
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            bytemuck::cast_slice(&motion_bits),
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(8 * W),
                rows_per_image: Some(H),
            },
            size,
        );
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("depth in"),
                color_attachments: &[],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &depth_view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(0.0),
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&depth_in);
            pass.set_bind_group(0, &depth_group, &[]);
            pass.draw(0..3, 0..1);
        }
        ctx.queue.submit([encoder.finish()]);
        let projection = camera.view_and_projection(aspect).1;
        let reset = taa.prepare(
            &ctx.queue,
            vp,
            projection,
            camera.position,
            camera.forward(),
        );
        assert_eq!(reset, step == 0);
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        taa.record(
            &ctx.device,
            &mut encoder,
            &color_view,
            &depth_view,
            &mut timer,
        );
        ctx.queue.submit([encoder.finish()]);
        let gpu = verdant::gpu::read_texture_rgba8(&ctx.device, &ctx.queue, &color).unwrap();

        let current: Vec<Vec3> = rgba
            .chunks(4)
            .map(|p| {
                Vec3::new(
                    srgb_to_linear(p[0]),
                    srgb_to_linear(p[1]),
                    srgb_to_linear(p[2]),
                )
            })
            .collect();
        let input = ResolveInput {
            size: (W, H),
            current: &current,
            depth: &depth,
            history: &history,
            spread: &spread,
            pixel_spread: settings.pixel_spread,
            parallax_falloff: settings.parallax_falloff,
            min_samples: settings.min_samples,
            jitter: verdant::aa::jitter(u64::from(step)),
            reconstruct_px: settings.reconstruct_px,
            sway_falloff: settings.sway_falloff,
            motion: &motion,
            reproject: match last {
                Some((lvp, leye)) => reprojection(lvp, leye, vp, camera.position),
                None => Mat4::IDENTITY,
            },
            max_samples: settings.max_samples as f32,
            clip_sigma: settings.clip_sigma,
            motion_falloff: settings.motion_falloff,
            reset: last.is_none(),
        };
        (history, spread) = input.resolve_with_spread();
        last = Some((vp, camera.position));

        let mut worst = 0.0f32;
        let mut total = 0.0f32;
        let mut changed = 0;
        for (i, h) in history.iter().enumerate() {
            for c in 0..3 {
                let d = (linear_to_srgb(h[c]) - f32::from(gpu[4 * i + c])).abs();
                worst = worst.max(d);
                total += d;
            }
            if (h.truncate() - current[i]).length() > 0.02 {
                changed += 1;
            }
        }
        let mean = total / (3 * W * H) as f32;
        // The GPU keeps its history in half floats: a level or two of 255 apart at most.
        assert!(
            worst <= 2.5 && mean < 0.3,
            "frame {step}, {settings:?}: GPU and CPU differ by up to {worst} (mean {mean}) levels"
        );
        // After the first frame the history matters: the output is not the current frame.
        if step > 0 {
            assert!(changed > 50, "frame {step}: only {changed} pixels blended");
        }
        frames.extend_from_slice(&gpu);
    }
    frames
}

/// A flat field of grass generated in memory at the blade spacing `spacing_m` (coarse, so
/// that software Vulkan draws it in seconds), a camera at its edge looking across it, and the
/// renderer's settings for it.
fn field(
    spacing_m: f32,
) -> (
    verdant::World,
    std::sync::Arc<dyn verdant::stream::TileSource>,
    verdant::RendererConfig,
    Camera,
) {
    let (world, source) = verdant::tools::bench_blades::flat_field(200.0).unwrap();
    let mut config = verdant::RendererConfig::for_world(&world);
    config.grass.spacing_m = spacing_m;
    let g = config.grass_settings(&world).unwrap().grid();
    config.grass.capacity = Some(3 * g * g);
    let camera = Camera::new(DVec3::new(100.0, 100.0, 2.5), 45.0, -30.0);
    (world, source, config, camera)
}

/// The field drawn with `aa`: `frames` frames of a still camera at one time (so that nothing
/// moves and a temporal method converges), the last returned.
fn field_frame(
    ctx: &verdant::gpu::GpuContext,
    aa: verdant::aa::AntiAliasing,
    frames: u32,
) -> image::RgbaImage {
    field_frame_with(ctx, aa, frames, false)
}

/// [`field_frame`], the blades writing their own motion vectors with `blade_motion`.
fn field_frame_with(
    ctx: &verdant::gpu::GpuContext,
    aa: verdant::aa::AntiAliasing,
    frames: u32,
    blade_motion: bool,
) -> image::RgbaImage {
    let (world, source, mut config, camera) = field(0.5);
    config.aa = aa;
    config.taa.blade_motion = blade_motion;
    let mut scene =
        verdant::tools::Scene::with_source(ctx, world, source, SIZE.0, SIZE.1, config).unwrap();
    scene
        .warm_up(ctx, &camera, std::time::Duration::from_secs(60))
        .unwrap();
    for _ in 0..frames {
        scene.render_at(ctx, &camera, 1.0).unwrap();
    }
    scene.read_image(ctx).unwrap()
}

const SIZE: (u32, u32) = (96, 64);

fn flip(a: &image::RgbaImage, b: &image::RgbaImage) -> f32 {
    let rgb = |i: &image::RgbaImage| image::DynamicImage::ImageRgba8(i.clone()).to_rgb8();
    verdant::tools::metrics::flip_compare(&rgb(a), &rgb(b))
        .unwrap()
        .mean
}

#[test]
fn blades_that_hold_still_resolve_alike_through_their_motion_vectors_and_their_depth() {
    // A still camera at a fixed time: every blade's motion is zero, so the blades' own motion
    // vectors (drawn into the second target, taken by the resolve where a blade is the
    // pixel's surface) must fetch the history where the depth's reprojection does.
    let ctx = common::gpu();
    use verdant::aa::AntiAliasing::Taa;
    let by_depth = field_frame_with(&ctx, Taa, 6, false);
    let by_motion = field_frame_with(&ctx, Taa, 6, true);
    let differ = by_depth
        .pixels()
        .zip(by_motion.pixels())
        .filter(|(a, b)| a.0.iter().zip(b.0).any(|(x, y)| x.abs_diff(y) > 2))
        .count();
    // Seen on software Vulkan: none.
    assert!(
        differ <= by_depth.len() as usize / 4 / 200,
        "{differ} pixels differ by more than 2 levels"
    );
}

#[test]
fn both_methods_bring_the_frame_closer_to_the_supersampled_render() {
    let ctx = common::gpu();
    // The same settings supersampled 4 x 4 in linear light: what anti-aliasing tends to.
    let (world, source, config, camera) = field(0.5);
    let mut truth =
        verdant::tools::truth::Truth::with_config(&ctx, world, source, SIZE, 4, config).unwrap();
    truth
        .scene()
        .warm_up(&ctx, &camera, std::time::Duration::from_secs(60))
        .unwrap();
    let reference = truth
        .render(&ctx, &camera, 1.0, Some(camera.position.truncate()))
        .unwrap();
    use verdant::aa::AntiAliasing::{Msaa, Off, Taa};
    let off = flip(&reference, &field_frame(&ctx, Off, 1));
    let taa = flip(&reference, &field_frame(&ctx, Taa, 24));
    let msaa = flip(&reference, &field_frame(&ctx, Msaa, 1));
    eprintln!("FLIP against the 4x4 render: off {off:.4}, taa {taa:.4}, msaa {msaa:.4}");
    // On software Vulkan at this size: off 0.161, taa 0.126, msaa 0.137.
    assert!(taa < 0.85 * off, "taa {taa} against off {off}");
    assert!(msaa < 0.92 * off, "msaa {msaa} against off {off}");
}
