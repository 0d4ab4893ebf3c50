//! Multisampling of the grass (`shaders/aa_msaa.wgsl`): the frame's terrain and sky are drawn
//! into a texture of the stage's, copied into every sample of its multisampled targets, the
//! blades drawn into those with alpha to coverage, and the result resolved into the caller's
//! targets. CPU mirror of its per-pixel rules and of the blades' coverage:
//! [`crate::aa::msaa_cpu`].

use crate::gpu::layout::{
    UNFILTERABLE_FLOAT, bind_group, bind_group_layout, sequential, texture_2d, texture_depth_2d,
    view as view_of, with_indices,
};
use crate::gpu::pipeline::{DepthBound, pipeline_layout, render_pipeline};

/// Samples a pixel.
pub const SAMPLES: u32 = 4;

/// The multisampled targets and the passes that fill and resolve them.
pub struct Msaa {
    color_format: wgpu::TextureFormat,
    depth_format: wgpu::TextureFormat,
    scene: wgpu::TextureView,
    color: wgpu::TextureView,
    depth: wgpu::TextureView,
    expand: wgpu::RenderPipeline,
    expand_layout: wgpu::BindGroupLayout,
    expand_group: DepthBound,
    depth_resolve: wgpu::RenderPipeline,
    resolve_layout: wgpu::BindGroupLayout,
    resolve_group: wgpu::BindGroup,
}

fn multisampled(
    device: &wgpu::Device,
    label: &str,
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
    size: (u32, u32),
) -> wgpu::TextureView {
    crate::gpu::multisampled_texture(device, label, format, usage, size, SAMPLES)
        .create_view(&Default::default())
}

/// The stage's textures at `size`: the frame's, the multisampled colour and depth, and the
/// depth resolve's bind group.
fn textures(
    device: &wgpu::Device,
    formats: (wgpu::TextureFormat, wgpu::TextureFormat),
    resolve_layout: &wgpu::BindGroupLayout,
    size: (u32, u32),
) -> (
    wgpu::TextureView,
    wgpu::TextureView,
    wgpu::TextureView,
    wgpu::BindGroup,
) {
    let usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
    let scene = crate::gpu::target_texture(device, "msaa frame", formats.0, usage, size)
        .create_view(&Default::default());
    let color = multisampled(
        device,
        "msaa colour",
        formats.0,
        wgpu::TextureUsages::RENDER_ATTACHMENT,
        size,
    );
    let depth = multisampled(device, "msaa depth", formats.1, usage, size);
    let depth_only = depth.texture().create_view(&wgpu::TextureViewDescriptor {
        aspect: wgpu::TextureAspect::DepthOnly,
        ..Default::default()
    });
    let group = bind_group_with(device, resolve_layout, &depth_only);
    (scene, color, depth, group)
}

fn bind_group_with(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    depth: &wgpu::TextureView,
) -> wgpu::BindGroup {
    crate::gpu::layout::bind_group_with_indices(
        device,
        "msaa depth resolve",
        layout,
        [(2, view_of(depth))],
    )
}

impl Msaa {
    /// The stage for `targets`.
    pub fn new(device: &wgpu::Device, targets: &crate::gpu::Targets) -> Self {
        let module = crate::shaders::module(device, "aa_msaa.wgsl");
        let expand_layout = bind_group_layout(
            device,
            "msaa expand",
            &sequential(
                wgpu::ShaderStages::FRAGMENT,
                [texture_2d(UNFILTERABLE_FLOAT), texture_depth_2d()],
            ),
        );
        let expand = render_pipeline(
            "msaa expand",
            &module,
            ("vs_full", "fs_msaa_expand"),
            targets.color_format,
        )
        .layouts(&[&expand_layout])
        .depth(targets.depth_format, true, wgpu::CompareFunction::Always)
        .multisample(SAMPLES, false)
        .build(device);
        let resolve_layout = bind_group_layout(
            device,
            "msaa depth resolve",
            &with_indices(
                wgpu::ShaderStages::FRAGMENT,
                [(
                    2,
                    wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Depth,
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: true,
                    }
                    .into(),
                )],
            ),
        );
        // Depth only: no colour target, so not the builder's one-target pipeline.
        let depth_resolve = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("msaa depth resolve"),
            layout: Some(&pipeline_layout(
                device,
                "msaa depth resolve",
                &[&resolve_layout],
            )),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_full"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: Default::default(),
            depth_stencil: Some(wgpu::DepthStencilState {
                format: targets.depth_format,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Always),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_msaa_depth"),
                compilation_options: Default::default(),
                targets: &[],
            }),
            multiview_mask: None,
            cache: None,
        });
        let formats = (targets.color_format, targets.depth_format);
        let (scene, color, depth, resolve_group) = textures(
            device,
            formats,
            &resolve_layout,
            (targets.width, targets.height),
        );
        Self {
            color_format: targets.color_format,
            depth_format: targets.depth_format,
            scene,
            color,
            depth,
            expand,
            expand_layout,
            expand_group: DepthBound::default(),
            depth_resolve,
            resolve_layout,
            resolve_group,
        }
    }

    /// Follows a resize of the targets.
    pub fn resize(&mut self, device: &wgpu::Device, width: u32, height: u32) {
        (self.scene, self.color, self.depth, self.resolve_group) = textures(
            device,
            (self.color_format, self.depth_format),
            &self.resolve_layout,
            (width, height),
        );
        self.expand_group.clear();
    }

    /// The texture the terrain and sky are drawn into (single-sampled).
    pub fn scene_view(&self) -> &wgpu::TextureView {
        &self.scene
    }

    /// The multisampled colour target the blades are drawn into.
    pub fn color_view(&self) -> &wgpu::TextureView {
        &self.color
    }

    /// The multisampled depth target the blades are drawn into.
    pub fn depth_view(&self) -> &wgpu::TextureView {
        &self.depth
    }

    /// Records the copy of the frame drawn so far ([`Msaa::scene_view`] and `depth`) into
    /// every sample of the multisampled targets (`msaa_expand`).
    pub fn record_expand(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        depth: &wgpu::TextureView,
        timer: &mut crate::gpu::GpuTimer,
    ) {
        let (scene, layout) = (&self.scene, &self.expand_layout);
        let group = self.expand_group.get(depth, |depth| {
            bind_group(
                device,
                "msaa expand",
                layout,
                [view_of(scene), view_of(depth)],
            )
        });
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("msaa expand"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &self.color,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &self.depth,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(0.0),
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: timer.render_pass("msaa_expand"),
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&self.expand);
        pass.set_bind_group(0, group, &[]);
        pass.draw(0..3, 0..1);
    }

    /// Records the resolve of the multisampled targets into `color` (the mean of each pixel's
    /// samples) and `depth` (the nearest sample), `msaa_resolve`.
    pub fn record_resolve(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        timer: &mut crate::gpu::GpuTimer,
    ) {
        {
            let _resolve = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("msaa colour resolve"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &self.color,
                    depth_slice: None,
                    resolve_target: Some(color),
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Load,
                        store: wgpu::StoreOp::Discard,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: timer.render_pass("msaa_resolve"),
                occlusion_query_set: None,
                multiview_mask: None,
            });
        }
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("msaa depth resolve"),
            color_attachments: &[],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: depth,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Load,
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: timer.render_pass("msaa_depth_resolve"),
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&self.depth_resolve);
        pass.set_bind_group(0, &self.resolve_group, &[]);
        pass.draw(0..3, 0..1);
    }
}
