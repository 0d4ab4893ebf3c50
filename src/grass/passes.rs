//! The pipelines of the grass stage's passes, one set-up per pass: generation and culling,
//! the wind on each blade, and the draw. [`crate::grass::renderer`] binds them to its pool.

use crate::gpu::Targets;
use crate::gpu::layout::*;
use crate::gpu::pipeline::{compute_pipeline, compute_pipeline_auto, render_pipeline};

/// Generation and culling per tile (`shaders/grass_generate.wgsl`): blades into a pool slot,
/// then the slot's draw arguments.
pub(crate) struct GeneratePass {
    pub(crate) layout: wgpu::BindGroupLayout,
    /// Bind group 1: the Hi-Z pyramid the blades are culled against.
    pub(crate) hiz_layout: wgpu::BindGroupLayout,
    pub(crate) generate: wgpu::ComputePipeline,
    pub(crate) finalize: wgpu::ComputePipeline,
}

impl GeneratePass {
    pub(crate) fn new(device: &wgpu::Device) -> Self {
        let module = crate::shaders::module(device, "grass_generate.wgsl");
        let layout = bind_group_layout(
            device,
            "grass generate",
            &with_indices(
                wgpu::ShaderStages::COMPUTE,
                [
                    (0, uniform_buffer()),
                    (1, storage_buffer_read_only()),
                    (2, uniform_buffer().dynamic()),
                    (3, texture_2d_array(UNFILTERABLE_FLOAT)),
                    (4, texture_2d_array(wgpu::TextureSampleType::Uint)),
                    (6, storage_buffer()),
                    (7, storage_buffer()),
                    (8, storage_buffer()),
                    (9, storage_buffer()),
                    (10, storage_buffer()),
                ],
            ),
        );
        let hiz_layout = bind_group_layout(
            device,
            "grass hi-z",
            &sequential(wgpu::ShaderStages::COMPUTE, [storage_buffer_read_only()]),
        );
        let compute =
            |entry| compute_pipeline(device, entry, &module, entry, &[&layout, &hiz_layout]);
        let (generate, finalize) = (compute("generate"), compute("finalize"));
        Self {
            layout,
            hiz_layout,
            generate,
            finalize,
        }
    }
}

/// The wind on each generated blade, once per blade (`shaders/grass_wind.wgsl`), dispatched
/// indirectly by the generation.
pub(crate) struct WindPass {
    pub(crate) pipeline: wgpu::ComputePipeline,
}

impl WindPass {
    pub(crate) fn new(device: &wgpu::Device) -> Self {
        let module = crate::shaders::module(device, "grass_wind.wgsl");
        Self {
            pipeline: compute_pipeline_auto(device, "grass wind", &module, "apply_wind"),
        }
    }

    pub(crate) fn layout(&self) -> wgpu::BindGroupLayout {
        self.pipeline.get_bind_group_layout(0)
    }
}

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
    /// segments near the camera, in the rest of the high ring and in the low ring.
    pub(crate) fn new(
        device: &wgpu::Device,
        targets: &Targets,
        segments: [u32; 3],
        slot_bytes: u64,
    ) -> Self {
        let module = crate::shaders::module(device, "grass_draw.wgsl");
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
        let pipeline = |label, segments: u32| {
            let segments = f64::from(segments.clamp(1, 64));
            let constants = [("SEGMENTS", segments)];
            let fs_constants = [
                ("SEGMENTS", segments),
                ("ENCODE_SRGB", targets.encode_srgb()),
            ];
            render_pipeline(
                label,
                &module,
                ("vs_blade", "fs_blade"),
                targets.color_format,
            )
            .layouts(&[&layout])
            .constants(&constants, &fs_constants)
            .triangle_strips()
            .depth(targets.depth_format, true, wgpu::CompareFunction::Greater)
            .build(device)
        };
        let [near, high, low] = segments;
        Self {
            near: pipeline("grass near blades", near),
            high: pipeline("grass high LOD", high),
            low: pipeline("grass low LOD", low),
            layout,
        }
    }
}
