//! The targets the renderer draws into: the formats and sizes it accepts, checked when it is
//! made or resized and on every recorded frame.
//!
//! A `wgpu::TextureView` tells only its texture (wgpu 30 has no getter for a view's format,
//! dimension, mip levels or layers). So a caller's view is checked in two steps: its texture
//! (format, usage, samples, dimension, and a mip level of the renderer's size) on every frame,
//! then the view itself, the first time a pair of views is given, by asking wgpu under an
//! error scope: a render pass over it beside the renderer's own target of its size with a
//! pipeline of its formats, and (depth) a bind group that reads it as `texture_depth_2d`. What
//! wgpu refuses there is returned as [`RendererError::Target`], never a validation panic.

use super::{Renderer, RendererError};
use crate::gpu::Targets;
use crate::gpu::layout::{bind_group_layout, sequential, texture_depth_2d};
use crate::gpu::pipeline::render_pipeline;
use crate::terrain::GBUFFER_FORMAT;
use wgpu::TextureFormat as F;
use wgpu::TextureUsages as U;

/// Depth formats the renderer draws into (the Hi-Z pyramid reads them as depth textures).
pub const DEPTH_FORMATS: [wgpu::TextureFormat; 2] = [
    wgpu::TextureFormat::Depth32Float,
    wgpu::TextureFormat::Depth24Plus,
];

/// Colour formats the renderer draws into where the device can (see [`color_format_problem`]):
/// the 8-bit ones and `Rgb10a2Unorm` on every device, `Rgba16Float` too; `Rgba32Float` with
/// `FLOAT32_BLENDABLE`, `Rg11b10Ufloat` with `RG11B10UFLOAT_RENDERABLE`, `Rgba16Unorm` with
/// `TEXTURE_FORMAT_16BIT_NORM` where the adapter renders it.
pub const COLOR_FORMATS: [wgpu::TextureFormat; 9] = [
    F::Rgba8Unorm,
    F::Rgba8UnormSrgb,
    F::Bgra8Unorm,
    F::Bgra8UnormSrgb,
    F::Rgb10a2Unorm,
    F::Rgba16Float,
    F::Rgba32Float,
    F::Rg11b10Ufloat,
    F::Rgba16Unorm,
];

/// Usages the renderer's own textures of the colour format need (the anti-aliasing's frame is
/// drawn, read and copied into).
const COLOR_FORMAT_USAGES: U = U::RENDER_ATTACHMENT
    .union(U::TEXTURE_BINDING)
    .union(U::COPY_DST);

/// The passes of the check: a vertex that draws nothing and fragments of each target's type.
const PROBE_WGSL: &str = "
@vertex fn vs() -> @builtin(position) vec4<f32> { return vec4<f32>(0.0, 0.0, 0.0, 1.0); }
struct Both { @location(0) color: vec4<f32>, @location(1) gbuffer: vec2<u32> }
@fragment fn fs_color() -> @location(0) vec4<f32> { return vec4<f32>(1.0); }
@fragment fn fs_both() -> Both { return Both(vec4<f32>(1.0), vec2<u32>(0u)); }
@fragment fn fs_gbuffer() -> @location(0) vec2<u32> { return vec2<u32>(0u); }
";

/// What checks the caller's views (see the module docs), and the last pair found to match.
pub(super) struct TargetCheck {
    /// Draws into the colour format and the G-buffer's.
    color: wgpu::RenderPipeline,
    /// Draws into the G-buffer's format with the depth format.
    depth: wgpu::RenderPipeline,
    /// `texture_depth_2d`, as the Hi-Z pyramid and the passes after it read the depth.
    depth_layout: wgpu::BindGroupLayout,
    /// The colour and depth views last found to match, with the size and the capture of the
    /// terrain-only depth they matched.
    matched: Option<(wgpu::TextureView, wgpu::TextureView, (u32, u32), bool)>,
}

impl TargetCheck {
    pub(super) fn new(device: &wgpu::Device, targets: &Targets) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("target check"),
            source: wgpu::ShaderSource::Wgsl(PROBE_WGSL.into()),
        });
        let color = render_pipeline(
            "target check: colour",
            &module,
            ("vs", "fs_both"),
            targets.color_format,
        )
        .second_target(GBUFFER_FORMAT)
        .build(device);
        let depth = render_pipeline(
            "target check: depth",
            &module,
            ("vs", "fs_gbuffer"),
            GBUFFER_FORMAT,
        )
        .depth(targets.depth_format, false, wgpu::CompareFunction::Always)
        .build(device);
        let depth_layout = bind_group_layout(
            device,
            "target check: depth",
            &sequential(wgpu::ShaderStages::COMPUTE, [texture_depth_2d()]),
        );
        Self {
            color,
            depth,
            depth_layout,
            matched: None,
        }
    }
}

fn plural(n: u32, one: &str) -> String {
    if n == 1 {
        format!("1 {one}")
    } else {
        format!("{n} {one}s")
    }
}

/// The size of mip level `mip` of `texture`.
fn level_size(texture: &wgpu::Texture, mip: u32) -> (u32, u32) {
    (
        (texture.width() >> mip).max(1),
        (texture.height() >> mip).max(1),
    )
}

/// A texture in words: size, format, levels (with their sizes), layers, samples, usage.
fn describe(texture: &wgpu::Texture) -> String {
    let mips = texture.mip_level_count();
    let levels = if mips > 1 {
        let sizes: Vec<String> = (0..mips)
            .map(|m| {
                let (w, h) = level_size(texture, m);
                format!("{w}x{h}")
            })
            .collect();
        format!(": {}", sizes.join(", "))
    } else {
        String::new()
    };
    let dimension = match texture.dimension() {
        wgpu::TextureDimension::D2 => String::new(),
        d => format!("{d:?} "),
    };
    format!(
        "a view of a {}x{} {:?} {dimension}texture ({}{levels}; {}; {}; {:?})",
        texture.width(),
        texture.height(),
        texture.format(),
        plural(mips, "mip level"),
        plural(texture.depth_or_array_layers(), "layer"),
        plural(texture.sample_count(), "sample"),
        texture.usage(),
    )
}

/// A wgpu error on one line.
fn one_line(error: &wgpu::Error) -> String {
    error
        .to_string()
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
}

impl Renderer {
    /// Checks the caller's targets against the renderer's (see the module docs): an error
    /// names what was expected and what was found.
    pub(super) fn check_targets(
        &mut self,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
    ) -> Result<(), RendererError> {
        let t = self.targets;
        let capture = self.terrain_depth.is_some();
        let size = (t.width, t.height);
        let expected = |format: F, usage: U, also: &str| {
            format!(
                "a {}x{} {format:?} 2D (D2) view of one mip level and one layer, 1 sample, of a \
                 texture with {usage:?}{also}",
                t.width, t.height
            )
        };
        let has_level =
            |tex: &wgpu::Texture| (0..tex.mip_level_count()).any(|m| level_size(tex, m) == size);
        let plain = |tex: &wgpu::Texture, usage: U| {
            tex.usage().contains(usage)
                && tex.sample_count() == 1
                && tex.dimension() == wgpu::TextureDimension::D2
                && has_level(tex)
        };

        let c = color.texture();
        let color_usage = U::RENDER_ATTACHMENT;
        // The view may be the texture's format with or without sRGB (`view_formats`): the
        // check of the view below tells.
        let color_expected = || expected(t.color_format, color_usage, "");
        if !plain(c, color_usage)
            || c.format().remove_srgb_suffix() != t.color_format.remove_srgb_suffix()
        {
            return Err(RendererError::Target {
                which: "colour",
                found: describe(c),
                expected: color_expected(),
            });
        }

        let d = depth.texture();
        let mut depth_usage = U::RENDER_ATTACHMENT | U::TEXTURE_BINDING;
        if capture {
            depth_usage |= U::COPY_SRC;
        }
        // The terrain-only depth is copied from the texture's first level and layer.
        let depth_expected = || {
            let capture_note = if capture {
                format!(
                    ", the texture itself {}x{} with one layer (the capture of the terrain-only \
                     depth copies its first level and layer)",
                    t.width, t.height
                )
            } else {
                String::new()
            };
            expected(t.depth_format, depth_usage, &capture_note)
        };
        if !plain(d, depth_usage)
            || d.format() != t.depth_format
            || capture && (level_size(d, 0) != size || d.depth_or_array_layers() != 1)
        {
            return Err(RendererError::Target {
                which: "depth",
                found: describe(d),
                expected: depth_expected(),
            });
        }

        if self
            .target_check
            .matched
            .as_ref()
            .is_some_and(|(mc, md, ms, mcap)| {
                mc == color && md == depth && *ms == size && *mcap == capture
            })
        {
            return Ok(());
        }
        let refused = |which, texture: &wgpu::Texture, error: &wgpu::Error, expected: String| {
            RendererError::Target {
                which,
                found: format!(
                    "{} that wgpu refuses ({})",
                    describe(texture),
                    one_line(error)
                ),
                expected,
            }
        };
        if let Some(e) = self.probe_depth(depth) {
            return Err(refused("depth", d, &e, depth_expected()));
        }
        if let Some(e) = self.probe_color(color) {
            return Err(refused("colour", c, &e, color_expected()));
        }
        self.target_check.matched = Some((color.clone(), depth.clone(), size, capture));
        Ok(())
    }

    /// wgpu's error, if any, for `depth` as the depth target of a pass beside the G-buffer (of
    /// the renderer's size) drawn by a pipeline of the depth format, and read as
    /// `texture_depth_2d`. Nothing is submitted.
    fn probe_depth(&self, depth: &wgpu::TextureView) -> Option<wgpu::Error> {
        let gbuffer = [Some(load(self.terrain.gbuffer_view()))];
        self.probe_pass(&gbuffer, Some(depth), &self.target_check.depth, || {
            drop(self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("target check: depth"),
                layout: &self.target_check.depth_layout,
                entries: &[wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(depth),
                }],
            }));
        })
    }

    /// wgpu's error, if any, for `color` as the colour target of a pass beside the G-buffer
    /// drawn by a pipeline of the colour format. Nothing is submitted.
    fn probe_color(&self, color: &wgpu::TextureView) -> Option<wgpu::Error> {
        let targets = [Some(load(color)), Some(load(self.terrain.gbuffer_view()))];
        self.probe_pass(&targets, None, &self.target_check.color, || {})
    }

    /// wgpu's validation error, if any, from a render pass of `pipeline` over `colors` (and
    /// `depth`), recorded and finished but never submitted, and from `also` after it.
    fn probe_pass(
        &self,
        colors: &[Option<wgpu::RenderPassColorAttachment<'_>>],
        depth: Option<&wgpu::TextureView>,
        pipeline: &wgpu::RenderPipeline,
        also: impl FnOnce(),
    ) -> Option<wgpu::Error> {
        let device = &self.device;
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let label = Some("target check");
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label });
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label,
                color_attachments: colors,
                depth_stencil_attachment: depth.map(|view| {
                    wgpu::RenderPassDepthStencilAttachment {
                        view,
                        depth_ops: Some(wgpu::Operations {
                            load: wgpu::LoadOp::Load,
                            store: wgpu::StoreOp::Store,
                        }),
                        stencil_ops: None,
                    }
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(pipeline);
        }
        drop(encoder.finish());
        also();
        pollster::block_on(scope.pop())
    }
}

/// `view` as a colour attachment that keeps what it holds.
fn load(view: &wgpu::TextureView) -> wgpu::RenderPassColorAttachment<'_> {
    wgpu::RenderPassColorAttachment {
        view,
        depth_slice: None,
        resolve_target: None,
        ops: wgpu::Operations {
            load: wgpu::LoadOp::Load,
            store: wgpu::StoreOp::Store,
        },
    }
}

/// Refuses formats the renderer does not draw into, and a colour format this device cannot
/// draw the renderer's passes into (multisampled: `msaa`).
pub(super) fn check_formats(
    device: &wgpu::Device,
    targets: &Targets,
    msaa: bool,
) -> Result<(), RendererError> {
    let format = targets.color_format;
    if crate::shaders::encode_srgb_for(format).is_none() {
        return Err(RendererError::ColorFormat(format));
    }
    if !DEPTH_FORMATS.contains(&targets.depth_format) {
        return Err(RendererError::DepthFormat(targets.depth_format));
    }
    if let Some(reason) = color_format_problem(device, format, msaa) {
        return Err(RendererError::ColorFormatOnDevice {
            format,
            reason,
            usable: usable_color_formats(device, msaa),
        });
    }
    Ok(())
}

/// The formats of [`COLOR_FORMATS`] that `device` draws the renderer's passes into (with
/// multisampling: `msaa`).
pub fn usable_color_formats(device: &wgpu::Device, msaa: bool) -> Vec<wgpu::TextureFormat> {
    COLOR_FORMATS
        .into_iter()
        .filter(|&f| color_format_problem(device, f, msaa).is_none())
        .collect()
}

/// Why `device` cannot draw the renderer's passes into a colour target of `format` (one of
/// [`COLOR_FORMATS`]), `None` where it can: the renderer renders into it, reads it and copies
/// into it, blends into it (the contact shadows multiply the frame), and with multisampling
/// (`msaa`) draws it 4 times a pixel and resolves it.
///
/// This is what wgpu validates against: the format features WebGPU guarantees with the
/// device's features. A device made with `TEXTURE_ADAPTER_SPECIFIC_FORMAT_FEATURES` is
/// validated against its adapter's, which a device does not tell: there the format's texture
/// and pipelines are made under an error scope and wgpu's answer taken.
pub fn color_format_problem(
    device: &wgpu::Device,
    format: wgpu::TextureFormat,
    msaa: bool,
) -> Option<String> {
    let features = device.features();
    let needs = format.required_features();
    if !features.contains(needs) {
        let missing: Vec<&str> = needs
            .difference(features)
            .iter_names()
            .map(|(name, _)| name)
            .collect();
        return Some(format!(
            "it needs the device feature {} (wgpu::Features)",
            missing.join(" and ")
        ));
    }
    if features.contains(wgpu::Features::TEXTURE_ADAPTER_SPECIFIC_FORMAT_FEATURES) {
        return try_color_format(device, format, msaa);
    }
    let guaranteed = format.guaranteed_format_features(features);
    let flags = guaranteed.flags;
    if !guaranteed.allowed_usages.contains(U::RENDER_ATTACHMENT) {
        let hint = match format {
            F::Rg11b10Ufloat => " without the device feature RG11B10UFLOAT_RENDERABLE",
            F::Rgba16Unorm => {
                " (WebGPU does not promise it: a device made with \
                 TEXTURE_ADAPTER_SPECIFIC_FORMAT_FEATURES renders it where its adapter does)"
            }
            _ => "",
        };
        return Some(format!("it cannot be a render target{hint}"));
    }
    if !guaranteed.allowed_usages.contains(COLOR_FORMAT_USAGES) {
        return Some(format!(
            "its textures cannot have the usages {COLOR_FORMAT_USAGES:?}"
        ));
    }
    if !flags.contains(wgpu::TextureFormatFeatureFlags::BLENDABLE) {
        let hint = if format == F::Rgba32Float {
            " without the device feature FLOAT32_BLENDABLE"
        } else {
            ""
        };
        return Some(format!(
            "it cannot be blended{hint} (the contact shadows multiply the frame)"
        ));
    }
    let msaa_flags = wgpu::TextureFormatFeatureFlags::MULTISAMPLE_X4
        | wgpu::TextureFormatFeatureFlags::MULTISAMPLE_RESOLVE;
    if msaa && !flags.contains(msaa_flags) {
        return Some(
            "it cannot be multisampled 4 times a pixel and resolved, as AntiAliasing::Msaa \
             does (choose AntiAliasing::Taa or Off, or another format)"
                .into(),
        );
    }
    None
}

/// [`color_format_problem`] on a device validated against its adapter's format features:
/// makes a texture of `format` with the usages the renderer's have, a pipeline blending into
/// it and (`msaa`) one drawing 4 samples a pixel and a pass resolving them, under an error
/// scope; wgpu's error is the answer.
fn try_color_format(
    device: &wgpu::Device,
    format: wgpu::TextureFormat,
    msaa: bool,
) -> Option<String> {
    let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let texture = |samples, usage| {
        crate::gpu::multisampled_texture(
            device,
            "colour format check",
            format,
            usage,
            (1, 1),
            samples,
        )
    };
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("colour format check"),
        source: wgpu::ShaderSource::Wgsl(PROBE_WGSL.into()),
    });
    let target = wgpu::ColorTargetState {
        format,
        blend: Some(wgpu::BlendState::ALPHA_BLENDING),
        write_mask: wgpu::ColorWrites::ALL,
    };
    let single = texture(1, COLOR_FORMAT_USAGES);
    drop(
        render_pipeline(
            "colour format check",
            &module,
            ("vs", "fs_color"),
            target.clone(),
        )
        .build(device),
    );
    if msaa {
        let samples = crate::aa::msaa::SAMPLES;
        let multi = texture(samples, U::RENDER_ATTACHMENT);
        drop(
            render_pipeline("colour format check", &module, ("vs", "fs_color"), target)
                .multisample(samples, false)
                .build(device),
        );
        let mut encoder = device.create_command_encoder(&Default::default());
        let (multi_view, single_view) = (
            multi.create_view(&Default::default()),
            single.create_view(&Default::default()),
        );
        drop(encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("colour format check"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                resolve_target: Some(&single_view),
                ..load(&multi_view)
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        }));
        drop(encoder.finish());
    }
    pollster::block_on(scope.pop()).map(|e| format!("wgpu refuses it ({})", one_line(&e)))
}

/// Refuses a target size that the adapter cannot serve: beyond its largest 2D texture, or (with
/// grass) a Hi-Z pyramid larger than the largest storage buffer binding or buffer. Checked here,
/// against this device's limits, so that no wgpu validation error can follow.
pub(super) fn check_size(
    device: &wgpu::Device,
    width: u32,
    height: u32,
    grass: bool,
) -> Result<(), RendererError> {
    let limits = device.limits();
    let limit = limits.max_texture_dimension_2d;
    if width == 0 || height == 0 || width > limit || height > limit {
        return Err(RendererError::BadSize {
            width,
            height,
            limit,
        });
    }
    if grass {
        let bytes = hiz_bytes(width, height);
        let (limit_name, limit) =
            if limits.max_storage_buffer_binding_size <= limits.max_buffer_size {
                (
                    "max_storage_buffer_binding_size",
                    limits.max_storage_buffer_binding_size,
                )
            } else {
                ("max_buffer_size", limits.max_buffer_size)
            };
        if bytes > limit {
            let pixels = u64::from(width) * u64::from(height);
            return Err(RendererError::SizeBeyondLimit {
                width,
                height,
                what: "Hi-Z pyramid storage buffer",
                bytes,
                limit_name,
                limit,
                max_pixels: (pixels as f64 * limit as f64 / bytes as f64) as u64,
            });
        }
    }
    Ok(())
}

/// Bytes of the Hi-Z pyramid of a `width` x `height` target (f32 levels down to 1x1).
pub fn hiz_bytes(width: u32, height: u32) -> u64 {
    (0..crate::grass::hiz::mip_count(width, height))
        .map(|m| u64::from((width >> m).max(1)) * u64::from((height >> m).max(1)) * 4)
        .sum()
}
