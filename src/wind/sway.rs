//! The sway of the grass on the GPU (`shaders/wind_sway.wgsl`): for every cell of the wind
//! field and every grass type, a damped spring ([`crate::wind::spring`]) driven toward a bend
//! proportional to the cell's wind, advanced each frame by the exact step of
//! [`RENDERER_INTEGRATOR`] (stable at every step the renderer can meet, a 0.5 s hitch
//! included). Its CPU mirror is [`crate::wind::sway_cpu::update_sway`].
//!
//! The state follows the wind field's toroidal layout: each cell remembers which world cell it
//! belongs to, and a cell that scrolls in starts at rest on its target.

use bytemuck::{Pod, Zeroable};

use super::config::WindLookup;
use super::spring::{RENDERER_INTEGRATOR, SwaySpring};
use crate::gpu::GpuTimer;
use crate::gpu::layout::bind_group;
use crate::gpu::pipeline::{buffer, compute_pipeline_auto};

/// Grass types the sway keeps state for.
pub const SWAY_TYPES: usize = 4;

/// The stage's uniform; mirrors `SwayParams` in the shader.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct SwayParams {
    /// The camera's world cell.
    pub origin_cell: [i32; 2],
    /// Cells along a side.
    pub n: u32,
    /// Grass types with state.
    pub types: u32,
    /// Per type, the step matrix for `(x - target, v)`, row-major.
    pub step: [[f32; 4]; SWAY_TYPES],
    /// Per type: bend per m/s of wind, largest bend (blade heights).
    pub gain: [[f32; 4]; SWAY_TYPES],
}
const _: () = assert!(std::mem::size_of::<SwayParams>() == 16 + 64 + 64);

/// Per-type springs and gains of a world's grass.
#[derive(Clone, Debug)]
pub struct SwayConfig {
    /// Spring per type.
    pub springs: Vec<SwaySpring>,
    /// Bend per m/s of wind per type (blade heights).
    pub gains: Vec<f32>,
    /// Largest bend per type.
    pub max_bend: Vec<f32>,
}

impl SwayConfig {
    /// From the manifest's grass types (their `stiffness`), at most [`SWAY_TYPES`]: softer grass
    /// bends further in the same wind.
    pub fn from_manifest(manifest: &crate::world::Manifest) -> Self {
        let types: Vec<f32> = manifest
            .grass_types
            .iter()
            .take(SWAY_TYPES)
            .map(|t| t.stiffness)
            .collect();
        Self {
            springs: types.iter().map(|&s| SwaySpring::from_grass(s)).collect(),
            gains: types
                .iter()
                .map(|&s| 0.06 * (1.2 - s.clamp(0.0, 1.0)))
                .collect(),
            max_bend: types
                .iter()
                .map(|&s| 1.1 - 0.5 * s.clamp(0.0, 1.0))
                .collect(),
        }
    }

    /// The uniform for a frame of `dt_s` seconds around the field described by `lookup`.
    pub fn params(&self, lookup: &WindLookup, dt_s: f32) -> SwayParams {
        let mut p = SwayParams {
            origin_cell: lookup.origin_cell,
            n: lookup.n,
            types: self.springs.len().min(SWAY_TYPES) as u32,
            step: [[0.0; 4]; SWAY_TYPES],
            gain: [[0.0; 4]; SWAY_TYPES],
        };
        for (t, spring) in self.springs.iter().take(SWAY_TYPES).enumerate() {
            let m = RENDERER_INTEGRATOR.amplification(spring, f64::from(dt_s.max(0.0)));
            p.step[t] = [
                m[0][0] as f32,
                m[0][1] as f32,
                m[1][0] as f32,
                m[1][1] as f32,
            ];
            p.gain[t] = [self.gains[t], self.max_bend[t], 0.0, 0.0];
        }
        p
    }
}

/// The sway stage's pipeline and buffers.
pub struct SwayField {
    config: SwayConfig,
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    params_buffer: wgpu::Buffer,
    sway: wgpu::Buffer,
    owners: wgpu::Buffer,
    n: u32,
    last: SwayParams,
}

impl SwayField {
    /// The stage over a wind field of `n` x `n` cells whose cells are in `wind_cells`.
    pub fn new(
        device: &wgpu::Device,
        config: SwayConfig,
        n: u32,
        wind_cells: &wgpu::Buffer,
    ) -> Self {
        let cells = u64::from(n) * u64::from(n);
        let buffer = |label, size, usage| buffer(device, label, size, usage);
        use wgpu::BufferUsages as U;
        let params_buffer = buffer(
            "sway params",
            std::mem::size_of::<SwayParams>() as u64,
            // Bound as `var<storage, read>` (see `shaders/wind_sway.wgsl`): as a uniform,
            // lavapipe recompiles the shader at every dispatch and leaks each variant.
            U::STORAGE | U::COPY_DST,
        );
        let sway = buffer(
            "sway state",
            cells * SWAY_TYPES as u64 * 16,
            U::STORAGE | U::COPY_SRC | U::COPY_DST,
        );
        let owners = buffer(
            "sway owners",
            cells * 8,
            U::STORAGE | U::COPY_SRC | U::COPY_DST,
        );
        let module = crate::shaders::module(device, "wind_sway.wgsl");
        let pipeline = compute_pipeline_auto(device, "grass sway", &module, "update_sway");
        let bind_group = bind_group(
            device,
            "grass sway",
            &pipeline.get_bind_group_layout(0),
            [
                params_buffer.as_entire_binding(),
                wind_cells.as_entire_binding(),
                sway.as_entire_binding(),
                owners.as_entire_binding(),
            ],
        );
        Self {
            config,
            pipeline,
            bind_group,
            params_buffer,
            sway,
            owners,
            n,
            last: SwayParams::zeroed(),
        }
    }

    /// Initialises the owners so that every cell starts fresh (a world cell no window holds).
    pub fn reset(&self, queue: &wgpu::Queue) {
        let cells = (self.n * self.n) as usize;
        queue.write_buffer(
            &self.owners,
            0,
            bytemuck::cast_slice(&vec![[i32::MIN, i32::MIN]; cells]),
        );
    }

    /// Records the frame's update for the wind field described by `lookup`, `dt_s` after the
    /// last one. Record it after the wind field's update.
    pub fn update(
        &mut self,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        lookup: &WindLookup,
        dt_s: f32,
        timer: &mut GpuTimer,
    ) {
        self.last = self.config.params(lookup, dt_s);
        queue.write_buffer(&self.params_buffer, 0, bytemuck::bytes_of(&self.last));
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("sway"),
            timestamp_writes: timer.compute_pass("sway"),
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.bind_group, &[]);
        pass.dispatch_workgroups(self.n.div_ceil(8), self.n.div_ceil(8), 1);
    }

    /// The state buffer: per cell (wind field layout) and type, bend xy and velocity zw.
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.sway
    }

    /// The uniform of the last update.
    pub fn last_params(&self) -> &SwayParams {
        &self.last
    }

    /// Reads the state and the owners back (for tests; waits for the GPU).
    pub fn read_back(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> (Vec<[f32; 4]>, Vec<[i32; 2]>) {
        let read = |b: &wgpu::Buffer| {
            crate::gpu::read_buffer(device, queue, b, ..).expect("read back the sway state")
        };
        (
            bytemuck::pod_collect_to_vec(&read(&self.sway)),
            bytemuck::pod_collect_to_vec(&read(&self.owners)),
        )
    }
}
