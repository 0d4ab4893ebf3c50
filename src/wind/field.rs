//! The wind field on the GPU (`shaders/wind_field.wgsl`): one compute pass a frame updates an
//! `n x n` grid of cells (256 x 1.25 m by default: 320 m around the camera) kept in storage
//! buffers. CPU mirror: [`super::field_cpu`].
//!
//! # What a cell holds
//! `array<vec4<f32>>`, `n * n` entries, row by row: `xy` the wind in m/s (x east, y north) =
//! ambient + source-driven, `zw` the walker's trail push (a bend of 0..=1 along its direction).
//! World cell `(i, j) = floor(world_xy / cell_m)` is stored at index
//! `(j mod n) * n + (i mod n)` (Euclidean mod): the grid follows the camera toroidally, so
//! moving only refreshes the cells that scroll in (their state restarts, settled on the sources,
//! with no trail); nothing is copied.
//!
//! Per cell and frame:
//! - **ambient**: four octaves of value noise (48, 24, 12, 6 m), gusts along the mean direction
//!   (`speed * (1 + gustiness * gust)`) and a smaller cross-wind from a second channel; the
//!   pattern travels with the wind (finer octaves a little faster, so it evolves). It is read
//!   through a sampling window that scrolls for [`WindConfig::window_s`] seconds and is then
//!   replaced by one at a fresh hashed position of the (bounded, periodic) noise domain, the two
//!   cross-faded over [`WindConfig::blend_s`] seconds: continuous, and never repeating.
//! - **sources** (at most 8, summed like lights): directional (uniform), omni (outward) and
//!   vortex (tangential, plus inflow), omni and vortex falling off as `(1 - d/r)^2`; each scaled
//!   by its strength keys and placed at its point or on its camera path at the current time.
//! - **decay**: the cell's source-driven wind `S` follows the sources' sum `T` as
//!   `S = T + (S - T) exp(-dt / tau)`, `tau` = [`WindConfig::attack_s`] when `|T| > |S|`, else
//!   [`WindConfig::release_s`]: where no source acts, the wind relaxes to the ambient field.
//!   Stable for any `dt >= 0`.
//! - **trail**: the push fades as `exp(-dt / trail_fade_s)`; the walker's step since the last
//!   frame stamps a capsule of radius [`WindConfig::trail_radius_m`] pushing away from its axis,
//!   `1 - smoothstep(0, r, distance)` strong, kept where stronger than the faded push (never
//!   summed, so it stays within 0..=1).
//!
//! # Reading the field from another shader (the grass draw)
//! 1. Include `shaders/shared/wind_lookup.wgsl` in the shader (`#include
//!    "shared/wind_lookup.wgsl"`, resolved by [`crate::shaders`]; for a shader of your own,
//!    `crate::shaders::shared("shared/wind_lookup.wgsl")`).
//! 2. Declare in that shader, at the group and bindings of its choice:
//!    ```wgsl
//!    @group(0) @binding(5) var<uniform> wind_lookup: WindLookup;
//!    @group(0) @binding(6) var<storage, read> wind_cells: array<vec4<f32>>;
//!    ```
//! 3. In the pipeline's bind group layout: `wind_lookup` is
//!    `BindingType::Buffer { ty: Uniform, has_dynamic_offset: false, min_binding_size: 32 }`
//!    ([`WindLookup`], 32 bytes), `wind_cells` is
//!    `BindingType::Buffer { ty: Storage { read_only: true }, .. }` of `n * n * 16` bytes
//!    ([`WindField::cells_bytes`]), with the stages that read them (e.g. `VERTEX`). Bind
//!    [`WindField::lookup_uniform`] and [`WindField::buffer`] (`as_entire_binding()`).
//! 4. Call `wind_at(rel_xy)` with a position relative to the camera (metres, f32, x east,
//!    y north): it returns `vec4<f32>` (xy wind m/s, zw push), bilinear between the four nearest
//!    cell centres; beyond the field's edge it returns the edge. The camera's world position
//!    reaches the shader as its world cell (i32) and an offset within it computed in f64
//!    ([`WindLookup`]), so lookups are exact to f32 precision of the camera-relative position,
//!    anywhere in a world.
//! 5. Record [`WindField::update`] before the draw in the same submission (one update per
//!    submission: the uniforms are written with `Queue::write_buffer`).

use bytemuck::Zeroable;
use glam::{DVec2, DVec3};

use super::config::{CellState, FieldDriver, FieldParams, WindConfig, WindLookup};
use crate::gpu::GpuTimer;
use crate::gpu::layout::bind_group;
use crate::gpu::pipeline::compute_pipeline_auto;

/// The wind field's pipeline and buffers.
pub struct WindField {
    driver: FieldDriver,
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    params_buffer: wgpu::Buffer,
    lookup_buffer: wgpu::Buffer,
    cells: wgpu::Buffer,
    state: wgpu::Buffer,
    params: FieldParams,
    lookup: WindLookup,
}

impl WindField {
    /// A field for `config`; its cells are filled by the first [`Self::update`].
    ///
    /// Panics if `config.cells` is odd or less than 8.
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, config: &WindConfig) -> Self {
        assert!(
            config.cells >= 8 && config.cells.is_multiple_of(2),
            "wind field cells per side must be even and at least 8, not {}",
            config.cells
        );
        let count = config.cell_count();
        let module = crate::shaders::module(device, "wind_field.wgsl");
        let params_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("wind params"),
            size: std::mem::size_of::<FieldParams>() as u64,
            // Bound as `var<storage, read>` (see `shaders/wind_field.wgsl`): as a uniform,
            // lavapipe recompiles the shader at every dispatch and leaks each variant.
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let lookup_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("wind lookup"),
            size: std::mem::size_of::<WindLookup>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        // wgpu zeroes new buffers: no wind, no push.
        let cells = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("wind cells"),
            size: count as u64 * 16,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        // Every cell starts holding no world cell, so the first update fills them all.
        let state = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("wind state"),
            size: count as u64 * std::mem::size_of::<CellState>() as u64,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        queue.write_buffer(
            &state,
            0,
            bytemuck::cast_slice(&vec![CellState::EMPTY; count]),
        );
        let pipeline = compute_pipeline_auto(device, "update_wind", &module, "update_wind");
        let bind_group = bind_group(
            device,
            "wind",
            &pipeline.get_bind_group_layout(0),
            [
                params_buffer.as_entire_binding(),
                state.as_entire_binding(),
                cells.as_entire_binding(),
            ],
        );
        Self {
            driver: FieldDriver::new(config),
            pipeline,
            bind_group,
            params_buffer,
            lookup_buffer,
            cells,
            state,
            params: FieldParams::zeroed(),
            lookup: WindLookup::default(),
        }
    }

    /// The configuration.
    pub fn config(&self) -> &WindConfig {
        self.driver.config()
    }

    /// Changes the scene from `change.at_s` on, blending the ambient wind over its `blend_s`
    /// (at or after the last change's time).
    pub fn change_scene(&mut self, change: crate::wind::SceneChange) {
        self.driver.push_change(change);
    }

    /// Records one frame's update (a compute pass named `wind` for `timer`): the camera at
    /// `camera_world`, scene time `time_s`, `dt_s` seconds since the last update (0 or more;
    /// any size is stable), the walker that leaves the trail at `walker_world` (`None`: no
    /// walker this frame; the trail only fades). Writes both uniforms with
    /// `queue.write_buffer`, so submit `encoder` before the next update.
    #[allow(clippy::too_many_arguments)]
    pub fn update(
        &mut self,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        camera_world: DVec3,
        time_s: f64,
        dt_s: f32,
        walker_world: Option<DVec2>,
        timer: &mut GpuTimer,
    ) {
        let (params, lookup) = self.driver.frame(camera_world, time_s, dt_s, walker_world);
        queue.write_buffer(&self.params_buffer, 0, bytemuck::bytes_of(&params));
        queue.write_buffer(&self.lookup_buffer, 0, bytemuck::bytes_of(&lookup));
        self.params = params;
        self.lookup = lookup;
        let n = self.driver.config().cells;
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("wind"),
            timestamp_writes: timer.compute_pass("wind"),
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.bind_group, &[]);
        pass.dispatch_workgroups(n.div_ceil(8), n.div_ceil(8), 1);
    }

    /// The cells (`array<vec4<f32>>`, `n * n`; see the module docs), for binding as
    /// `var<storage, read> wind_cells`.
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.cells
    }

    /// Size of [`Self::buffer`], bytes (`n * n * 16`).
    pub fn cells_bytes(&self) -> u64 {
        self.cells.size()
    }

    /// The per-cell state (`array<CellState>`: source-driven wind and the world cell held).
    pub fn state_buffer(&self) -> &wgpu::Buffer {
        &self.state
    }

    /// The lookup uniform ([`WindLookup`], 32 bytes) for binding as
    /// `var<uniform> wind_lookup`; rewritten by every update.
    pub fn lookup_uniform(&self) -> &wgpu::Buffer {
        &self.lookup_buffer
    }

    /// The lookup uniform's value as of the last update.
    pub fn lookup(&self) -> WindLookup {
        self.lookup
    }

    /// The compute uniform as of the last update (what the CPU mirror needs to repeat it).
    pub fn params(&self) -> &FieldParams {
        &self.params
    }

    /// Reads the cells back (for tests and tools; waits for the GPU).
    pub fn read_back(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> Vec<[f32; 4]> {
        bytemuck::pod_collect_to_vec(
            &crate::gpu::read_buffer(device, queue, &self.cells, ..)
                .expect("read back the wind cells"),
        )
    }

    /// Reads the cells' state back (for tests and tools; waits for the GPU).
    pub fn read_back_state(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> Vec<CellState> {
        bytemuck::pod_collect_to_vec(
            &crate::gpu::read_buffer(device, queue, &self.state, ..)
                .expect("read back the wind state"),
        )
    }
}
