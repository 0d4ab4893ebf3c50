//! The Hi-Z pyramid on the GPU (`shaders/grass_hiz.wgsl`): the depth target copied into level
//! 0 of a storage buffer, then each further level the farthest depth of the texels below it.
//! Its CPU mirror is [`crate::grass::hiz_cpu`].

use crate::gpu::GpuTimer;
use crate::gpu::layout::*;
use crate::gpu::pipeline::{DepthBound, buffer as gpu_buffer, compute_pipeline};

/// The Hi-Z pyramid of a depth target, in a storage buffer (levels one after another).
pub struct HiZPyramid {
    /// The levels, f32, finest first, rows top first.
    pub buffer: wgpu::Buffer,
    copy: wgpu::ComputePipeline,
    reduce: wgpu::ComputePipeline,
    copy_layout: wgpu::BindGroupLayout,
    level_buffer: wgpu::Buffer,
    /// The depth view the copy reads and its bind group (made again when the view changes).
    copy_group: DepthBound,
    reduce_group: wgpu::BindGroup,
    /// (offset in floats, width, height) of each level.
    levels: Vec<(u32, u32, u32)>,
}

/// Mip levels of a pyramid over `width` x `height`, down to 1x1.
pub fn mip_count(width: u32, height: u32) -> u32 {
    32 - width.max(height).max(1).leading_zeros()
}

const LEVEL_STRIDE: u64 = 256;
/// Bytes of a level's record: where to read and where to write.
const LEVEL_BYTES: u64 = 24;

impl HiZPyramid {
    /// A pyramid over depth targets of `w` x `h` (a depth format, with `TEXTURE_BINDING`).
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, w: u32, h: u32) -> Self {
        let mips = mip_count(w, h);
        let mut levels = Vec::new();
        let mut offset = 0u32;
        for m in 0..mips {
            let (lw, lh) = ((w >> m).max(1), (h >> m).max(1));
            levels.push((offset, lw, lh));
            offset += lw * lh;
        }
        let buffer = gpu_buffer(
            device,
            "hi-z",
            u64::from(offset) * 4,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        );
        // One uniform record per level: where to read and where to write.
        let mut records = vec![0u8; levels.len() * LEVEL_STRIDE as usize];
        for (m, &(off, lw, lh)) in levels.iter().enumerate() {
            let (so, sw, sh) = if m == 0 { (0, lw, lh) } else { levels[m - 1] };
            let rec = [so, sw, sh, off, lw, lh];
            records[m * LEVEL_STRIDE as usize..][..24].copy_from_slice(bytemuck::cast_slice(&rec));
        }
        let level_buffer = gpu_buffer(
            device,
            "hi-z levels",
            records.len() as u64,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        );
        queue.write_buffer(&level_buffer, 0, &records);
        let module = crate::shaders::module(device, "grass_hiz.wgsl");
        // Each level's record is bound through a dynamic offset.
        let level = || uniform_buffer().dynamic().min_size(LEVEL_BYTES);
        let copy_layout = bind_group_layout(
            device,
            "hi-z copy",
            &sequential(
                wgpu::ShaderStages::COMPUTE,
                [texture_depth_2d(), storage_buffer(), level()],
            ),
        );
        let reduce_layout = bind_group_layout(
            device,
            "hi-z reduce",
            &with_indices(
                wgpu::ShaderStages::COMPUTE,
                [(1, storage_buffer()), (2, level())],
            ),
        );
        let pipeline = |entry, layout| compute_pipeline(device, entry, &module, entry, &[layout]);
        let (copy, reduce) = (
            pipeline("copy_depth", &copy_layout),
            pipeline("reduce", &reduce_layout),
        );
        let reduce_group = bind_group_with_indices(
            device,
            "hi-z reduce",
            &reduce_layout,
            [
                (1, buffer.as_entire_binding()),
                (2, buffer_prefix(&level_buffer, LEVEL_BYTES)),
            ],
        );
        Self {
            buffer,
            copy,
            reduce,
            copy_layout,
            level_buffer,
            copy_group: DepthBound::default(),
            reduce_group,
            levels,
        }
    }

    /// A bind group of `layout` (one read-only storage buffer at binding 0) over the pyramid.
    /// The pyramid's levels, finest first, as one buffer of floats (see [`Self::levels`]).
    pub(crate) fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    pub(crate) fn read_group(
        &self,
        device: &wgpu::Device,
        layout: &wgpu::BindGroupLayout,
    ) -> wgpu::BindGroup {
        bind_group(
            device,
            "grass hi-z",
            layout,
            [self.buffer.as_entire_binding()],
        )
    }

    /// Mip levels.
    pub fn mips(&self) -> u32 {
        self.levels.len() as u32
    }

    /// (offset in floats, width, height) of each level.
    pub fn levels(&self) -> &[(u32, u32, u32)] {
        &self.levels
    }

    /// Reads every level back (for tests and tools; waits for the GPU).
    pub fn read_back(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> crate::grass::HiZ {
        let all: Vec<f32> = crate::gpu::read_buffer_pod(device, queue, &self.buffer, ..)
            .expect("read back the Hi-Z pyramid");
        let mips = self
            .levels
            .iter()
            .map(|&(o, w, h)| (w, h, all[o as usize..(o + w * h) as usize].to_vec()))
            .collect();
        crate::grass::HiZ { mips }
    }

    /// Records the build of the pyramid from `depth` (a view of the pyramid's size; its bind
    /// group is made when the view differs from the last one's).
    pub fn record(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        depth: &wgpu::TextureView,
        timer: &mut GpuTimer,
    ) {
        let copy_group = self.copy_group.get(depth, |depth| {
            bind_group(
                device,
                "hi-z copy",
                &self.copy_layout,
                [
                    view(depth),
                    self.buffer.as_entire_binding(),
                    buffer_prefix(&self.level_buffer, LEVEL_BYTES),
                ],
            )
        });
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("hi-z"),
            timestamp_writes: timer.compute_pass("hiz"),
        });
        let (_, w, h) = self.levels[0];
        pass.set_pipeline(&self.copy);
        pass.set_bind_group(0, copy_group, &[0]);
        pass.dispatch_workgroups(w.div_ceil(8), h.div_ceil(8), 1);
        pass.set_pipeline(&self.reduce);
        for (m, &(_, w, h)) in self.levels.iter().enumerate().skip(1) {
            pass.set_bind_group(0, &self.reduce_group, &[(m as u64 * LEVEL_STRIDE) as u32]);
            pass.dispatch_workgroups(w.div_ceil(8), h.div_ceil(8), 1);
        }
    }
}
