//! The hole check (`shaders/renderer_hole_check.wgsl`): every atlas read of a frame compared
//! on the GPU with what its slot holds.

use crate::stream::TileAtlas;
use crate::world::TileId;

/// Most atlas reads a frame checks (terrain draws and grass jobs).
const MAX_HOLE_CHECKS: usize = 8192;

/// The hole count, observed on the GPU: each frame's atlas reads (slot and expected identity)
/// are compared by a compute pass (`shaders/renderer_hole_check.wgsl`) with the identity that the
/// uploads and derivations left in each slot ([`TileAtlas::identity`]).
pub(super) struct HoleCheck {
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    checks: wgpu::Buffer,
    /// The frame's count of mismatches (u32, then padding), copied to the figures.
    pub(super) counter: wgpu::Buffer,
}

impl HoleCheck {
    pub(super) fn new(device: &wgpu::Device, atlas: &TileAtlas) -> Self {
        let module = crate::shaders::module(device, "renderer_hole_check.wgsl");
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("hole_check"),
            layout: None,
            module: &module,
            entry_point: Some("hole_check"),
            compilation_options: Default::default(),
            cache: None,
        });
        let checks = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("hole checks"),
            size: 16 + MAX_HOLE_CHECKS as u64 * 32,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let counter = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("holes"),
            size: 16,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("hole check"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: checks.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: atlas.identity.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: counter.as_entire_binding(),
                },
            ],
        });
        Self {
            pipeline,
            bind_group,
            checks,
            counter,
        }
    }

    /// Records the check of `reads` (after the frame's derivations, which claim their slots);
    /// returns the reads that fail already on the CPU (a slot given to another tile).
    pub(super) fn record(
        &self,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        atlas: &TileAtlas,
        reads: &[(u32, TileId)],
    ) -> u32 {
        let mut cpu_holes = 0;
        let mut words: Vec<u32> = vec![0; 4];
        for &(slot, tile) in reads.iter().take(MAX_HOLE_CHECKS) {
            let claimed = atlas.claimed(slot);
            if claimed[..3] != [u32::from(tile.level), tile.x, tile.y] || claimed[3] == 0 {
                cpu_holes += 1;
                continue;
            }
            words.extend_from_slice(&claimed);
            words.extend_from_slice(&[slot, 0, 0, 0]);
        }
        let n = (words.len() - 4) / 8;
        words[0] = n as u32;
        queue.write_buffer(&self.checks, 0, bytemuck::cast_slice(&words));
        encoder.clear_buffer(&self.counter, 0, None);
        if n > 0 {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("hole check"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.bind_group, &[]);
            pass.dispatch_workgroups((n as u32).div_ceil(64), 1, 1);
        }
        cpu_holes
    }
}
