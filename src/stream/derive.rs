//! The derivation stage: a compute pass that derives child tiles from parents already in the
//! tile atlas (`shaders/stream_derive.wgsl`), then copies each result into its own atlas slot.
//! Its CPU mirror is [`crate::stream::derive_cpu`].

use bytemuck::{Pod, Zeroable};

use crate::gpu::GpuTimer;
use crate::gpu::layout::{bind_group, view};
use crate::gpu::pipeline::{array_view, buffer, compute_pipeline_auto};
use crate::stream::{DeriveParams, MAX_LEVELS, TileAtlas};
use crate::world::{Pyramid, TileId};

/// One child to derive: its address, its parent's slot and the slot to fill.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DeriveJob {
    /// The child tile.
    pub child: TileId,
    /// Atlas slot holding the child's parent.
    pub parent_slot: u32,
    /// Atlas slot the child goes to.
    pub child_slot: u32,
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct JobGpu {
    child_x: u32,
    child_y: u32,
    child_level: u32,
    parent_layer: u32,
    out_layer: u32,
    cell_parent: f32,
    cell_child: f32,
    detail_child: f32,
    detail_parent: f32,
    _pad: [u32; 3],
    /// The child's identity in the atlas (`TileAtlas::claim`), written by the pass.
    identity: [u32; 4],
    /// What the parent's slot must hold: a derivation from anything else writes a poisoned
    /// identity (generation 0), so the child counts as a hole.
    parent_identity: [u32; 4],
}
const _: () = assert!(std::mem::size_of::<JobGpu>() == 80);

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ParamsGpu {
    grid: [u32; 4],
    detail: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<ParamsGpu>() == 32);

/// Pipeline, staging textures and buffers of the derivation stage.
pub struct DeriveStage {
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    jobs: wgpu::Buffer,
    staging_heights: wgpu::Texture,
    staging_grass: wgpu::Texture,
    staging_identity: wgpu::Buffer,
    pyramid: Pyramid,
    /// Detail amplitude per level, 0 for stored levels.
    level_detail: [f32; MAX_LEVELS],
    batch: u32,
}

impl DeriveStage {
    /// A stage that derives up to `batch` tiles a call, reading parents from `atlas`.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        pyramid: &Pyramid,
        params: &DeriveParams,
        atlas: &TileAtlas,
        batch: u32,
    ) -> Self {
        let module = crate::shaders::module(device, "stream_derive.wgsl");
        let size = atlas.size();
        let staging = |label, format| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d {
                    width: size,
                    height: size,
                    depth_or_array_layers: batch,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC,
                view_formats: &[],
            })
        };
        let staging_heights = staging("derive heights", wgpu::TextureFormat::R32Float);
        let staging_grass = staging("derive grass", wgpu::TextureFormat::Rgba8Uint);
        use wgpu::BufferUsages as U;
        let params_buffer = buffer(
            device,
            "derive params",
            std::mem::size_of::<ParamsGpu>() as u64,
            U::UNIFORM | U::COPY_DST,
        );
        queue.write_buffer(
            &params_buffer,
            0,
            bytemuck::bytes_of(&ParamsGpu {
                grid: [
                    pyramid.tile_cells,
                    pyramid.border,
                    pyramid.samples_per_side(),
                    params.seed,
                ],
                detail: [0.0, params.window_cells, 0.0, 0.0],
            }),
        );
        let jobs = buffer(
            device,
            "derive jobs",
            u64::from(batch) * std::mem::size_of::<JobGpu>() as u64,
            U::STORAGE | U::COPY_DST,
        );
        let staging_identity = buffer(
            device,
            "derive identity",
            u64::from(batch.max(1)) * 16,
            U::STORAGE | U::COPY_SRC,
        );
        let pipeline = compute_pipeline_auto(device, "derive_child", &module, "derive_child");
        let layout = pipeline.get_bind_group_layout(0);
        let views = [
            array_view(&atlas.heights),
            array_view(&atlas.grass),
            array_view(&staging_heights),
            array_view(&staging_grass),
        ];
        let bind_group = bind_group(
            device,
            "derive",
            &layout,
            [
                params_buffer.as_entire_binding(),
                jobs.as_entire_binding(),
                view(&views[0]),
                view(&views[1]),
                view(&views[2]),
                view(&views[3]),
                atlas.identity.as_entire_binding(),
                staging_identity.as_entire_binding(),
            ],
        );
        Self {
            pipeline,
            bind_group,
            jobs,
            staging_heights,
            staging_grass,
            staging_identity,
            pyramid: pyramid.clone(),
            level_detail: std::array::from_fn(|level| {
                // Stored levels carry no detail.
                if level < usize::from(pyramid.stored_levels) {
                    0.0
                } else {
                    params.detail[level]
                }
            }),
            batch,
        }
    }

    fn detail_at(&self, level: u8) -> f32 {
        self.level_detail[usize::from(level).min(MAX_LEVELS - 1)]
    }

    /// Most tiles one call derives.
    pub fn batch(&self) -> u32 {
        self.batch
    }

    /// Records the derivation of `jobs` (at most [`Self::batch`]; the rest are ignored) and the
    /// copies into their slots. Returns how many were recorded.
    pub fn record(
        &self,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        atlas: &TileAtlas,
        jobs: &[DeriveJob],
        timer: &mut GpuTimer,
    ) -> usize {
        let jobs = &jobs[..jobs.len().min(self.batch as usize)];
        if jobs.is_empty() {
            return 0;
        }
        let gpu_jobs: Vec<JobGpu> = jobs
            .iter()
            .enumerate()
            .map(|(k, j)| JobGpu {
                child_x: j.child.x,
                child_y: j.child.y,
                child_level: u32::from(j.child.level),
                parent_layer: j.parent_slot,
                out_layer: k as u32,
                cell_parent: self.pyramid.cell_size_m(j.child.level - 1) as f32,
                cell_child: self.pyramid.cell_size_m(j.child.level) as f32,
                detail_child: self.detail_at(j.child.level),
                detail_parent: self.detail_at(j.child.level - 1),
                _pad: [0; 3],
                parent_identity: atlas.claimed(j.parent_slot),
                identity: atlas.claim(j.child_slot, j.child),
            })
            .collect();
        queue.write_buffer(&self.jobs, 0, bytemuck::cast_slice(&gpu_jobs));
        let size = atlas.size();
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("derive"),
                timestamp_writes: timer.compute_pass("derive"),
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.bind_group, &[]);
            pass.dispatch_workgroups(size.div_ceil(8), size.div_ceil(8), jobs.len() as u32);
        }
        for (k, j) in jobs.iter().enumerate() {
            for (from, to) in [
                (&self.staging_heights, &atlas.heights),
                (&self.staging_grass, &atlas.grass),
            ] {
                encoder.copy_texture_to_texture(
                    wgpu::TexelCopyTextureInfo {
                        texture: from,
                        mip_level: 0,
                        origin: wgpu::Origin3d {
                            x: 0,
                            y: 0,
                            z: k as u32,
                        },
                        aspect: wgpu::TextureAspect::All,
                    },
                    wgpu::TexelCopyTextureInfo {
                        texture: to,
                        mip_level: 0,
                        origin: wgpu::Origin3d {
                            x: 0,
                            y: 0,
                            z: j.child_slot,
                        },
                        aspect: wgpu::TextureAspect::All,
                    },
                    wgpu::Extent3d {
                        width: size,
                        height: size,
                        depth_or_array_layers: 1,
                    },
                );
            }
            encoder.copy_buffer_to_buffer(
                &self.staging_identity,
                k as u64 * 16,
                &atlas.identity,
                u64::from(j.child_slot) * 16,
                16,
            );
        }
        jobs.len()
    }
}
