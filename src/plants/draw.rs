//! The plants' draw stage on the GPU (`shaders/plants_draw.wgsl`): one indexed indirect draw per
//! (type, level of detail), bent by the wind in the vertex stage (mirrored in
//! [`crate::plants::bend_cpu`]); [`crate::plants::renderer`] binds it and records it.

use crate::gpu::Targets;
use crate::gpu::layout::*;
use crate::gpu::pipeline::render_pipeline;

/// The draws of the pool's regions (`shaders/plants_draw.wgsl`).
pub(crate) struct DrawPass {
    /// Group 0: the frame, the meshes, the wind, the textures, the sway springs.
    pub(crate) layout: wgpu::BindGroupLayout,
    /// Group 1: a region of the pool, by a dynamic offset.
    pub(crate) region_layout: wgpu::BindGroupLayout,
    pub(crate) pipeline: wgpu::RenderPipeline,
}

impl DrawPass {
    /// The draw into `targets` of regions of `region_bytes`, into targets of `samples` samples
    /// a pixel (above 1: the cards' alpha as coverage).
    pub(crate) fn new(
        device: &wgpu::Device,
        targets: &Targets,
        region_bytes: u64,
        samples: u32,
    ) -> Self {
        use wgpu::ShaderStages as S;
        let layout = bind_group_layout(
            device,
            "plants draw",
            &sequential(
                S::VERTEX_FRAGMENT,
                [
                    uniform_buffer(),
                    storage_buffer_read_only(),
                    uniform_buffer(),
                    storage_buffer_read_only(),
                    texture_2d_array(wgpu::TextureSampleType::Float { filterable: true })
                        .visible_in(S::FRAGMENT),
                    wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering).into(),
                    // The frame again, for the feature bits (the shader says why).
                    storage_buffer_read_only(),
                    // The sway springs' state.
                    storage_buffer_read_only(),
                ],
            ),
        );
        let region_layout = bind_group_layout(
            device,
            "plants region",
            &sequential(
                S::VERTEX,
                [storage_buffer_read_only().dynamic().min_size(region_bytes)],
            ),
        );
        let pipeline = Self::pipeline(device, targets, &layout, &region_layout, samples);
        Self {
            layout,
            region_layout,
            pipeline,
        }
    }

    /// The pipeline over the two layouts, for targets of `samples` samples a pixel.
    pub(crate) fn pipeline(
        device: &wgpu::Device,
        targets: &Targets,
        layout: &wgpu::BindGroupLayout,
        region_layout: &wgpu::BindGroupLayout,
        samples: u32,
    ) -> wgpu::RenderPipeline {
        let module = crate::shaders::module(device, "plants_draw.wgsl");
        let coverage = if samples > 1 { 1.0 } else { 0.0 };
        let fs_constants = [
            ("ENCODE_SRGB", targets.encode_srgb()),
            ("COVERAGE", coverage),
        ];
        render_pipeline(
            "plants draw",
            &module,
            ("vs_plant", "fs_plant"),
            targets.color_format,
        )
        .layouts(&[layout, region_layout])
        .constants(&[], &fs_constants)
        .depth(targets.depth_format, true, wgpu::CompareFunction::Greater)
        .multisample(samples, samples > 1)
        .build(device)
    }
}
