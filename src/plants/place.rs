//! The plants' placement stage on the GPU (`shaders/plants_place.wgsl`): plants placed and
//! culled per grass tile into the regions of the instance pool, then each region's
//! indirect draw. Its CPU mirror is [`crate::plants::place_cpu`];
//! [`crate::plants::renderer`] binds it to the pool and records it.

use crate::gpu::layout::*;
use crate::gpu::pipeline::compute_pipeline;

/// Placement per tile and the draws' arguments (`shaders/plants_place.wgsl`).
pub(crate) struct PlacePass {
    pub(crate) layout: wgpu::BindGroupLayout,
    pub(crate) place: wgpu::ComputePipeline,
    pub(crate) finalize: wgpu::ComputePipeline,
}

impl PlacePass {
    pub(crate) fn new(device: &wgpu::Device) -> Self {
        let module = crate::shaders::module(device, "plants_place.wgsl");
        let layout = bind_group_layout(
            device,
            "plants place",
            &sequential(
                wgpu::ShaderStages::COMPUTE,
                [
                    uniform_buffer(),
                    storage_buffer_read_only(),
                    texture_2d_array(UNFILTERABLE_FLOAT),
                    texture_2d_array(wgpu::TextureSampleType::Uint),
                    storage_buffer_read_only(),
                    storage_buffer(),
                    storage_buffer(),
                    storage_buffer(),
                    storage_buffer(),
                ],
            ),
        );
        let compute = |entry| compute_pipeline(device, entry, &module, entry, &[&layout]);
        Self {
            place: compute("place"),
            finalize: compute("finalize_draws"),
            layout,
        }
    }
}
