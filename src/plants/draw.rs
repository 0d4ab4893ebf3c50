//! The plants' draw stage on the GPU (`shaders/plants_draw.wgsl`): one indexed indirect draw per
//! (type, level of detail), bent by the wind in the vertex stage (mirrored in
//! [`crate::plants::bend_cpu`]); the full meshes lit per pixel, the reduced meshes and the cards
//! per vertex; [`crate::plants::renderer`] binds it and records it.

use crate::gpu::Targets;
use crate::gpu::layout::*;
use crate::gpu::pipeline::render_pipeline;

/// The draws of the pool's regions (`shaders/plants_draw.wgsl`).
pub(crate) struct DrawPass {
    /// Group 0: the frame, the meshes, the wind, the textures, the sway springs.
    pub(crate) layout: wgpu::BindGroupLayout,
    /// Group 1: a region of the pool, by a dynamic offset.
    pub(crate) region_layout: wgpu::BindGroupLayout,
    /// The full meshes' pipeline (lit per pixel), then the reduced meshes' and cards' (lit per
    /// vertex).
    pub(crate) pipelines: [wgpu::RenderPipeline; 2],
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
        let (layout, region_layout) = Self::layouts(device, region_bytes);
        let pipelines = Self::pipelines(device, targets, &layout, &region_layout, samples);
        Self {
            layout,
            region_layout,
            pipelines,
        }
    }

    /// Group 0's and group 1's layouts, for regions of `region_bytes`.
    fn layouts(
        device: &wgpu::Device,
        region_bytes: u64,
    ) -> (wgpu::BindGroupLayout, wgpu::BindGroupLayout) {
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
        (layout, region_layout)
    }

    /// The draw of a shadow caster: the same layouts, one depth-only pipeline for every level
    /// (`vs_plant_shadow`, `fs_plant_shadow`) into a [`crate::plants::shadow::SHADOW_FORMAT`]
    /// layer.
    pub(crate) fn new_shadow(device: &wgpu::Device, region_bytes: u64) -> Self {
        let (layout, region_layout) = Self::layouts(device, region_bytes);
        let module = crate::shaders::module(device, "plants_draw.wgsl");
        let pipelines = [(), ()].map(|_| {
            render_pipeline(
                "plants shadow draw",
                &module,
                ("vs_plant_shadow", "fs_plant_shadow"),
                wgpu::TextureFormat::Rgba8Unorm,
            )
            .depth_only()
            .layouts(&[&layout, &region_layout])
            .depth(
                crate::plants::shadow::SHADOW_FORMAT,
                true,
                wgpu::CompareFunction::Greater,
            )
            .build(device)
        });
        Self {
            layout,
            region_layout,
            pipelines,
        }
    }

    /// The pipelines over the two layouts (see [`DrawPass::pipelines`]), for targets of
    /// `samples` samples a pixel.
    pub(crate) fn pipelines(
        device: &wgpu::Device,
        targets: &Targets,
        layout: &wgpu::BindGroupLayout,
        region_layout: &wgpu::BindGroupLayout,
        samples: u32,
    ) -> [wgpu::RenderPipeline; 2] {
        let module = crate::shaders::module(device, "plants_draw.wgsl");
        let coverage = if samples > 1 { 1.0 } else { 0.0 };
        let fs_constants = [
            ("ENCODE_SRGB", targets.encode_srgb()),
            ("COVERAGE", coverage),
        ];
        [
            ("plants draw", ("vs_plant", "fs_plant")),
            ("plants draw far", ("vs_plant_far", "fs_plant_far")),
        ]
        .map(|(label, entries)| {
            render_pipeline(label, &module, entries, targets.color_format)
                .layouts(&[layout, region_layout])
                .constants(&[], &fs_constants)
                .depth(targets.depth_format, true, wgpu::CompareFunction::Greater)
                .multisample(samples, samples > 1)
                .build(device)
        })
    }
}
