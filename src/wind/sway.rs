//! The sway of the grass and the plants on the GPU (`shaders/wind_sway.wgsl`): for every cell
//! of the wind field, every grass type (slots 0..[`GRASS_SWAY_TYPES`]) and every plant type
//! (the slots after them), a damped spring ([`crate::wind::spring`]) driven toward a bend
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

/// Grass types the sway keeps state for (slots `0..GRASS_SWAY_TYPES`).
pub const GRASS_SWAY_TYPES: usize = 4;
/// Plant types the sway keeps state for (slots `GRASS_SWAY_TYPES..SWAY_TYPES`).
pub const PLANT_SWAY_TYPES: usize = crate::world::MAX_PLANT_TYPES;
/// Spring slots per cell: the grass types', then the plant types'.
pub const SWAY_TYPES: usize = GRASS_SWAY_TYPES + PLANT_SWAY_TYPES;

/// The stage's uniform; mirrors `SwayParams` in the shader.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct SwayParams {
    /// The camera's world cell.
    pub origin_cell: [i32; 2],
    /// Cells along a side.
    pub n: u32,
    /// Slots with state (the grass types', then the plant types' after
    /// [`GRASS_SWAY_TYPES`]).
    pub types: u32,
    /// Per type, the step matrix for `(x - target, v)`, row-major.
    pub step: [[f32; 4]; SWAY_TYPES],
    /// Per type: bend per m/s of wind, largest bend (blade heights).
    pub gain: [[f32; 4]; SWAY_TYPES],
}
const _: () = assert!(std::mem::size_of::<SwayParams>() == 16 + 2 * 16 * SWAY_TYPES);

/// Per-slot springs and gains of a world's grass types and plant types.
#[derive(Clone, Debug)]
pub struct SwayConfig {
    /// Spring per slot.
    pub springs: Vec<SwaySpring>,
    /// Bend per m/s of wind per slot (blade heights for grass, plant heights for plants).
    pub gains: Vec<f32>,
    /// Largest bend per slot.
    pub max_bend: Vec<f32>,
}

/// Largest lean of a plant's top on its sway spring, plant heights (its length is kept by the
/// stretch).
pub const PLANT_MAX_LEAN: f32 = 1.5;

impl SwayConfig {
    /// From the manifest's grass types (their `stiffness`), at most [`GRASS_SWAY_TYPES`]: softer
    /// grass bends further in the same wind; then, in the slots after [`GRASS_SWAY_TYPES`], its
    /// plant types: the spring of their `sway_spring_hz` and `sway_damping`, driven toward the
    /// lean of their main bending (see [`plant_lean_gain`]).
    pub fn from_manifest(manifest: &crate::world::Manifest) -> Self {
        let types: Vec<f32> = manifest
            .grass_types
            .iter()
            .take(GRASS_SWAY_TYPES)
            .map(|t| t.stiffness)
            .collect();
        let mut c = Self {
            springs: types.iter().map(|&s| SwaySpring::from_grass(s)).collect(),
            gains: types
                .iter()
                .map(|&s| 0.06 * (1.2 - s.clamp(0.0, 1.0)))
                .collect(),
            max_bend: types
                .iter()
                .map(|&s| 1.1 - 0.5 * s.clamp(0.0, 1.0))
                .collect(),
        };
        if !manifest.plant_types.is_empty() {
            // The plants' slots start after every grass slot, used or not.
            while c.springs.len() < GRASS_SWAY_TYPES {
                c.springs.push(SwaySpring::from_grass(0.5));
                c.gains.push(0.0);
                c.max_bend.push(0.0);
            }
            for p in manifest.plant_types.iter().take(PLANT_SWAY_TYPES) {
                let w = &p.wind;
                c.springs
                    .push(SwaySpring::from_frequency(w.sway_spring_hz, w.sway_damping));
                c.gains.push(plant_lean_gain(w));
                c.max_bend.push(PLANT_MAX_LEAN);
            }
        }
        c
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

/// Lean of a plant's top per m/s of wind at rest on its spring, plant heights: the wind it feels
/// (movement scale) times its bend, less for a stiff plant (`1 - 0.6 stiffness`), times its main
/// amplitude. The plants' vertex stage bends by the spring's state (`shaders/plants_draw.wgsl`).
pub fn plant_lean_gain(w: &crate::world::PlantWind) -> f32 {
    w.movement_scale * w.bend * (1.0 - 0.6 * w.stiffness) * w.main_amplitude
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

#[cfg(test)]
mod tests {
    use super::*;

    fn default_manifest() -> crate::world::Manifest {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/santa-cruz");
        crate::world::World::open(&dir).unwrap().manifest
    }

    #[test]
    fn plant_types_take_the_slots_after_the_grass_with_their_own_springs() {
        let m = default_manifest();
        assert!(!m.plant_types.is_empty());
        let c = SwayConfig::from_manifest(&m);
        assert_eq!(c.springs.len(), GRASS_SWAY_TYPES + m.plant_types.len());
        for (k, p) in m.plant_types.iter().enumerate() {
            let slot = GRASS_SWAY_TYPES + k;
            let w = &p.wind;
            assert_eq!(
                c.springs[slot],
                SwaySpring::from_frequency(w.sway_spring_hz, w.sway_damping)
            );
            assert_eq!(c.gains[slot], plant_lean_gain(w));
            assert_eq!(c.max_bend[slot], PLANT_MAX_LEAN);
        }
        let p = c.params(&WindLookup::zeroed(), 1.0 / 60.0);
        assert_eq!(p.types as usize, c.springs.len());
        // A lightly damped plant's spring keeps more of its velocity over a frame than a
        // heavily damped one's of the same frequency.
        let step = |zeta: f32| {
            RENDERER_INTEGRATOR.amplification(&SwaySpring::from_frequency(1.0, zeta), 1.0 / 60.0)[1]
                [1]
        };
        assert!(step(0.1) > step(1.0));
    }

    #[test]
    fn a_world_without_plants_keeps_only_its_grass_slots() {
        let mut m = default_manifest();
        m.plant_types.clear();
        let c = SwayConfig::from_manifest(&m);
        assert_eq!(c.springs.len(), m.grass_types.len().min(GRASS_SWAY_TYPES));
    }

    #[test]
    fn grass_types_beyond_the_grass_slots_leave_the_plants_slots_to_the_plants() {
        // Six grass types (types 4 and 5 share type 3's spring, as the shader reads them):
        // the plants still start at slot GRASS_SWAY_TYPES.
        let mut m = default_manifest();
        let mut extra = m.grass_types[1].clone();
        extra.stiffness = 0.05;
        m.grass_types.push(extra.clone());
        m.grass_types.push(extra);
        let c = SwayConfig::from_manifest(&m);
        assert_eq!(c.springs.len(), GRASS_SWAY_TYPES + m.plant_types.len());
        let w = &m.plant_types[0].wind;
        assert_eq!(
            c.springs[GRASS_SWAY_TYPES],
            SwaySpring::from_frequency(w.sway_spring_hz, w.sway_damping)
        );
        m.plant_types.clear();
        assert_eq!(
            SwayConfig::from_manifest(&m).springs.len(),
            GRASS_SWAY_TYPES
        );
    }
}
