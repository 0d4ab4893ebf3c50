//! Contact shadows from the depth buffer on the GPU (`shaders/terrain_contact_shadow.wgsl`);
//! the CPU mirror is [`ContactShadows::factors`], in [`crate::terrain::contact_shadow_cpu`].
//!
//! The grass cannot go into a shadow map cheaply: its blades exist only a batch of tiles at a
//! time, in a pool that is reused through the frame. Its shadows within about 30 m of the
//! camera are found instead in the finished depth buffer, where every blade is: from each
//! pixel's surface point a short ray marches toward the sun, and the pixel is in shadow where a
//! step lands behind a surface nearer than it by less than an occluder's thickness. The
//! colour is then multiplied by [`ContactShadows::shade`] (the sun's share of the light goes,
//! the sky's stays), faded out with distance.

use glam::{Mat4, Vec3};

use crate::gpu::layout::{view as view_of, *};
use crate::gpu::pass::render_pass;
use crate::gpu::pipeline::{DepthBound, buffer, compute_pipeline, render_pipeline};

/// Settings of the contact shadows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactShadows {
    /// Length of the ray toward the sun, metres (the longest shadow a blade casts).
    pub ray_m: f32,
    /// How far behind a nearer surface a step may be and still be shadowed by it, metres.
    pub thickness_m: f32,
    /// The colour's factor in full shadow.
    pub shade: f32,
    /// Steps along the ray.
    pub steps: u32,
    /// Distance where the shadows start to fade, metres.
    pub fade_start_m: f32,
    /// Distance where they have faded out, metres.
    pub fade_end_m: f32,
}

impl Default for ContactShadows {
    fn default() -> Self {
        Self {
            ray_m: 1.2,
            thickness_m: 0.6,
            shade: 0.55,
            steps: 12,
            fade_start_m: 22.0,
            fade_end_m: 32.0,
        }
    }
}

/// Uniforms of `shaders/terrain_contact_shadow.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    view_proj: [[f32; 4]; 4],
    inv_view_proj: [[f32; 4]; 4],
    sun_dir: [f32; 4],
    size: [f32; 4],
    march: [f32; 4],
}

/// Format of the factors' texture (a storage format of every adapter).
pub const FACTOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Float;

/// The contact shadows' passes: each pixel's factor worked out in a compute pass over the
/// target, reading the depth target (which it does not write), into a texture of the pass's;
/// then a full-screen triangle that multiplies the colour target by the factors.
pub struct ContactShadowPass {
    settings: ContactShadows,
    compute: wgpu::ComputePipeline,
    compute_layout: wgpu::BindGroupLayout,
    pipeline: wgpu::RenderPipeline,
    apply_layout: wgpu::BindGroupLayout,
    factors: wgpu::TextureView,
    apply: wgpu::BindGroup,
    params: Params,
    buffer: wgpu::Buffer,
    /// The bind group of the last depth target, made again only when the target changes.
    bound: DepthBound,
}

/// The factors' texture of a `size` target and the bind group of the pass that applies them.
fn factor_texture(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    size: (u32, u32),
) -> (wgpu::TextureView, wgpu::BindGroup) {
    let texture = crate::gpu::target_texture(
        device,
        "contact shadow factors",
        FACTOR_FORMAT,
        wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::TEXTURE_BINDING,
        size,
    );
    let view = texture.create_view(&Default::default());
    let bind_group = bind_group_with_indices(
        device,
        "contact shadows apply",
        layout,
        [(3, view_of(&view))],
    );
    (view, bind_group)
}

impl ContactShadowPass {
    /// The pass for `targets`, with `settings`.
    pub fn new(
        device: &wgpu::Device,
        targets: &crate::gpu::Targets,
        settings: ContactShadows,
    ) -> Self {
        let module = crate::shaders::module(device, "terrain_contact_shadow.wgsl");
        let compute_layout = bind_group_layout(
            device,
            "contact shadows",
            &with_indices(
                wgpu::ShaderStages::COMPUTE,
                [
                    (0, uniform_buffer()),
                    (1, texture_depth_2d()),
                    (2, texture_storage_2d(FACTOR_FORMAT)),
                    // Binding 3 is the apply pass's; 4 and 5 the trees' shadow map.
                    (4, texture_depth_2d_array()),
                    (5, uniform_buffer()),
                ],
            ),
        );
        let compute = compute_pipeline(
            device,
            "contact shadows",
            &module,
            "cs_contact_shadow",
            &[&compute_layout],
        );
        let apply_layout = bind_group_layout(
            device,
            "contact shadows apply",
            &with_indices(
                wgpu::ShaderStages::FRAGMENT,
                [(3, texture_2d(UNFILTERABLE_FLOAT))],
            ),
        );
        // The colour target times the pass's output; its alpha kept.
        let blend = wgpu::BlendState {
            color: wgpu::BlendComponent {
                src_factor: wgpu::BlendFactor::Zero,
                dst_factor: wgpu::BlendFactor::Src,
                operation: wgpu::BlendOperation::Add,
            },
            alpha: wgpu::BlendComponent {
                src_factor: wgpu::BlendFactor::Zero,
                dst_factor: wgpu::BlendFactor::One,
                operation: wgpu::BlendOperation::Add,
            },
        };
        let constants = [("ENCODE_SRGB", targets.encode_srgb())];
        let target = wgpu::ColorTargetState {
            format: targets.color_format,
            blend: Some(blend),
            write_mask: wgpu::ColorWrites::ALL,
        };
        let pipeline = render_pipeline(
            "contact shadows apply",
            &module,
            ("vs_full", "fs_contact_shadow"),
            target,
        )
        .layouts(&[&apply_layout])
        .constants(&[], &constants)
        .build(device);
        let buffer = buffer(
            device,
            "contact shadows",
            std::mem::size_of::<Params>() as u64,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        );
        let params = Params {
            view_proj: Mat4::IDENTITY.to_cols_array_2d(),
            inv_view_proj: Mat4::IDENTITY.to_cols_array_2d(),
            sun_dir: [0.0, 0.0, 1.0, 0.0],
            size: [
                targets.width as f32,
                targets.height as f32,
                settings.fade_end_m,
                settings.fade_start_m,
            ],
            march: [
                settings.ray_m,
                settings.thickness_m,
                settings.shade,
                settings.steps as f32,
            ],
        };
        let (factors, apply) =
            factor_texture(device, &apply_layout, (targets.width, targets.height));
        Self {
            settings,
            compute,
            compute_layout,
            pipeline,
            apply_layout,
            factors,
            apply,
            params,
            buffer,
            bound: DepthBound::default(),
        }
    }

    /// Follows a resize of the targets: the factors' texture at the new size.
    pub fn resize(&mut self, device: &wgpu::Device, width: u32, height: u32) {
        (self.factors, self.apply) = factor_texture(device, &self.apply_layout, (width, height));
        self.bound.clear();
    }

    /// The settings.
    pub fn settings(&self) -> &ContactShadows {
        &self.settings
    }

    /// Writes the frame's camera (camera-relative `view_proj`), sun and target size, and
    /// whether the contact shadows are on (`contact`; off, the pass applies only the trees').
    pub fn prepare(
        &mut self,
        queue: &wgpu::Queue,
        view_proj: Mat4,
        sun_dir: Vec3,
        (width, height): (u32, u32),
        contact: bool,
    ) {
        self.params.march[3] = if contact {
            self.settings.steps as f32
        } else {
            0.0
        };
        self.params.view_proj = view_proj.to_cols_array_2d();
        self.params.inv_view_proj = view_proj.inverse().to_cols_array_2d();
        self.params.sun_dir = sun_dir.extend(0.0).to_array();
        self.params.size[0] = width as f32;
        self.params.size[1] = height as f32;
        queue.write_buffer(&self.buffer, 0, bytemuck::bytes_of(&self.params));
    }

    /// Records the passes: the factors found in `depth` and the trees' shadow `map`
    /// (compute, `contact_shadows`), then `color` multiplied by them (`contact_shadows_apply`).
    /// The compute pass's bind group is made again only when the depth view changes (or
    /// the targets are resized); `map` must be the same every frame.
    pub fn record(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        map: &crate::plants::shadow::TreeShadowMap,
        timer: &mut crate::gpu::GpuTimer,
    ) {
        let group = self.bound.get(depth, |depth| {
            bind_group_with_indices(
                device,
                "contact shadows",
                &self.compute_layout,
                [
                    (0, self.buffer.as_entire_binding()),
                    (1, view_of(depth)),
                    (2, view_of(&self.factors)),
                    (4, view_of(map.view())),
                    (5, map.buffer().as_entire_binding()),
                ],
            )
        });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("contact shadows"),
                timestamp_writes: timer.compute_pass("contact_shadows"),
            });
            // The targets' size (the caller's depth may be a view of one level of a larger
            // texture).
            let size = self.factors.texture().size();
            pass.set_pipeline(&self.compute);
            pass.set_bind_group(0, group, &[]);
            pass.dispatch_workgroups(size.width.div_ceil(8), size.height.div_ceil(8), 1);
        }
        let mut pass = render_pass(
            encoder,
            "contact shadows apply",
            (color, wgpu::LoadOp::Load),
            None,
            timer.render_pass("contact_shadows_apply"),
        );
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.apply, &[]);
        pass.draw(0..3, 0..1);
    }
}
