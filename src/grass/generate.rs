//! The grass's generation stage on the GPU (`shaders/grass_generate.wgsl`): blades generated
//! and culled per tile into a pool slot, then the slot's draw arguments. Its CPU mirror is
//! [`crate::grass::generate_cpu`]; [`crate::grass::renderer`] binds the stage to its pool and
//! records it.

use crate::gpu::layout::*;
use crate::gpu::pipeline::compute_pipeline;

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
