//! The grass's draw stage on the GPU (`shaders/grass_draw.wgsl`): the indirect draw of a pool
//! slot's blades. The blade's shape has its CPU mirror in [`crate::grass::blade`];
//! [`crate::grass::renderer`] binds the stage to its pool and records it.

use crate::aa::taa::MOTION_FORMAT;
use crate::gpu::Targets;
use crate::gpu::layout::*;
use crate::gpu::pipeline::render_pipeline;

/// The indirect draw of a slot's blades (`shaders/grass_draw.wgsl`): one pipeline per blade
/// length.
pub(crate) struct DrawPass {
    pub(crate) layout: wgpu::BindGroupLayout,
    pub(crate) near: wgpu::RenderPipeline,
    pub(crate) high: wgpu::RenderPipeline,
    pub(crate) low: wgpu::RenderPipeline,
}

impl DrawPass {
    /// Pipelines drawing into `targets` from slots of `slot_bytes`, with blades of `segments`
    /// segments near the camera, in the rest of the high ring and in the low ring. With
    /// `samples` above 1 the targets are multisampled and a blade narrower than a pixel is
    /// drawn a pixel wide with its true width as its coverage (alpha to coverage).
    pub(crate) fn new(
        device: &wgpu::Device,
        targets: &Targets,
        segments: [u32; 3],
        slot_bytes: u64,
        samples: u32,
    ) -> Self {
        let layout = bind_group_layout(
            device,
            "grass draw",
            &sequential(
                wgpu::ShaderStages::VERTEX_FRAGMENT,
                [
                    uniform_buffer(),
                    // A slot of the pool, chosen by a dynamic offset.
                    storage_buffer_read_only()
                        .dynamic()
                        .min_size(slot_bytes)
                        .visible_in(wgpu::ShaderStages::VERTEX),
                ],
            ),
        );
        let [near, high, low] = Self::pipelines(device, targets, segments, &layout, samples, false);
        Self {
            near,
            high,
            low,
            layout,
        }
    }

    /// The three pipelines (near, high LOD, low LOD) over `layout`, for targets of `samples`
    /// samples a pixel; with `motion`, each also writes its blades' motion vectors into a
    /// second target of [`MOTION_FORMAT`] (`vs_blade_motion`, `fs_blade_motion`).
    pub(crate) fn pipelines(
        device: &wgpu::Device,
        targets: &Targets,
        segments: [u32; 3],
        layout: &wgpu::BindGroupLayout,
        samples: u32,
        motion: bool,
    ) -> [wgpu::RenderPipeline; 3] {
        let module = crate::shaders::module(device, "grass_draw.wgsl");
        let coverage = if samples > 1 { 1.0 } else { 0.0 };
        let pipeline = |label, segments: u32| {
            let segments = f64::from(segments.clamp(1, 64));
            let constants = [("SEGMENTS", segments), ("COVERAGE", coverage)];
            let fs_constants = [
                ("SEGMENTS", segments),
                ("ENCODE_SRGB", targets.encode_srgb()),
                ("COVERAGE", coverage),
            ];
            let entries = if motion {
                ("vs_blade_motion", "fs_blade_motion")
            } else {
                ("vs_blade", "fs_blade")
            };
            let layouts = [layout];
            let builder = render_pipeline(label, &module, entries, targets.color_format)
                .layouts(&layouts)
                .constants(&constants, &fs_constants)
                .triangle_strips()
                .depth(targets.depth_format, true, wgpu::CompareFunction::Greater)
                .multisample(samples, samples > 1);
            if motion {
                builder.second_target(MOTION_FORMAT).build(device)
            } else {
                builder.build(device)
            }
        };
        let [near, high, low] = segments;
        [
            pipeline("grass near blades", near),
            pipeline("grass high LOD", high),
            pipeline("grass low LOD", low),
        ]
    }
}
