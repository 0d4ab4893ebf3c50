//! The grass's wind stage on the GPU (`shaders/grass_wind.wgsl`): the wind on each generated
//! blade, once per blade, dispatched indirectly by the generation. Its CPU mirror is
//! [`crate::grass::wind_cpu`]; [`crate::grass::renderer`] binds it to its pool and records it.

use crate::gpu::pipeline::compute_pipeline_auto;

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
