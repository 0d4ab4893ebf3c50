//! Wind-carried leaves and petals on the GPU (`shaders/particles.wgsl`): a bounded pool of
//! particles shed by the trees and the flowers near the camera and carried by the same wind field as the grass and the plants
//! (God of War's particles follow the interactive wind: a gust sends them flying, the
//! helicopter's downwash scatters them). One compute pass steps the pool each frame; one draw
//! turns each live particle into a small leaf facing the camera. The pool's size is fixed when
//! the stage is made. CPU mirror of the step: [`crate::plants::particles_cpu`].

use glam::{DVec3, Mat4};

use crate::gpu::layout::*;
use crate::gpu::pass::render_pass;
use crate::gpu::pipeline::{buffer, compute_pipeline, render_pipeline};
use crate::gpu::{GpuTimer, Targets};
use crate::plants::particles_cpu::{PETAL, PICK_BUCKETS, PICK_INDICES, Particle, ParticleParams};

/// Settings of the leaves.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParticleSettings {
    /// Particles in the pool.
    pub count: u32,
    /// How fast a leaf takes the wind's speed, 1/s.
    pub drag: f32,
    /// How fast a leaf sinks in still air, m/s.
    pub fall_mps: f32,
    /// How fast it flutters about its course, m/s.
    pub flutter_mps: f32,
    /// A leaf's length, metres.
    pub size_m: f32,
    /// The range of a leaf's life, seconds.
    pub life_s: [f32; 2],
    /// Leaves in the air per tree near the camera (those drawn with a full or reduced mesh),
    /// as far as the pool goes.
    pub per_tree: f32,
    /// Petals in the air per flower near the camera (a plant of the `flower` recipe drawn with
    /// a full or reduced mesh), as far as the pool goes.
    pub per_flower: f32,
}

impl Default for ParticleSettings {
    fn default() -> Self {
        Self {
            count: 4096,
            drag: 1.5,
            fall_mps: 0.8,
            flutter_mps: 0.5,
            size_m: 0.1,
            life_s: [4.0, 10.0],
            per_tree: 8.0,
            per_flower: 0.02,
        }
    }
}

impl ParticleSettings {
    /// Whether the settings are usable; the error names the setting, its value and its range.
    pub fn validate(&self) -> Result<(), (&'static str, String, String)> {
        let bad = |field, value: f32, range: &str| Err((field, value.to_string(), range.into()));
        if !(1..=MAX_PARTICLES).contains(&self.count) {
            let range = format!("1 to {MAX_PARTICLES}");
            return Err(("particles.count", self.count.to_string(), range));
        }
        let positive = |v: f32| v.is_finite() && v > 0.0;
        let at_least_0 = |v: f32| v.is_finite() && v >= 0.0;
        if !positive(self.drag) {
            return bad("particles.drag", self.drag, "above 0 (1/s)");
        }
        if !at_least_0(self.fall_mps) {
            return bad("particles.fall_mps", self.fall_mps, "0 or more m/s");
        }
        if !at_least_0(self.flutter_mps) {
            return bad("particles.flutter_mps", self.flutter_mps, "0 or more m/s");
        }
        if !positive(self.size_m) {
            return bad("particles.size_m", self.size_m, "above 0 m");
        }
        if !at_least_0(self.per_tree) {
            return bad("particles.per_tree", self.per_tree, "0 or more leaves");
        }
        if !at_least_0(self.per_flower) {
            return bad("particles.per_flower", self.per_flower, "0 or more petals");
        }
        let [a, b] = self.life_s;
        if !(positive(a) && a <= b && b.is_finite()) {
            return Err((
                "particles.life_s",
                format!("{a},{b}"),
                "MIN,MAX with 0 < MIN <= MAX".into(),
            ));
        }
        Ok(())
    }
}

/// The most particles a pool may hold.
pub const MAX_PARTICLES: u32 = 1 << 20;

/// A camera step longer than this (metres) sheds every particle again: a teleport or a cut.
pub const RESET_JUMP_M: f64 = 50.0;

/// The buffers of the trees' stage that the leaves are shed from.
#[derive(Clone, Copy)]
pub struct TreeSource<'a> {
    /// The trees' instance pool.
    pub instances: &'a wgpu::Buffer,
    /// Its indexed indirect draws, one per (type, level) region (their instance counts).
    pub args: &'a wgpu::Buffer,
    /// Instances a region holds.
    pub capacity: u32,
    /// Tree types.
    pub types: u32,
}

/// The buffers of the plants' stage that the petals are shed from.
#[derive(Clone, Copy)]
pub struct FlowerSource<'a> {
    /// The plants' instance pool.
    pub instances: &'a wgpu::Buffer,
    /// Its indexed indirect draws, one per (type, level) region.
    pub args: &'a wgpu::Buffer,
    /// Instances a region holds.
    pub capacity: u32,
    /// Per type of the plants' layer (at most 8): its petals' colour where it sheds petals (a
    /// flower), `None` where it does not.
    pub petals: &'a [Option<[f32; 3]>],
}

/// The wind the leaves fly in: the wind field's lookup uniform and cells.
#[derive(Clone, Copy)]
pub struct ParticleWind<'a> {
    /// `WindLookup` uniform.
    pub lookup: &'a wgpu::Buffer,
    /// The cells.
    pub cells: &'a wgpu::Buffer,
}

/// The leaves' pool, step and draw.
pub struct ParticleStage {
    settings: ParticleSettings,
    params: ParticleParams,
    params_buffer: wgpu::Buffer,
    particles: wgpu::Buffer,
    group: wgpu::BindGroup,
    step: wgpu::ComputePipeline,
    pick_keys: wgpu::ComputePipeline,
    pick_plants: wgpu::ComputePipeline,
    pick_list: wgpu::ComputePipeline,
    picks: wgpu::Buffer,
    draw_layouts: [wgpu::BindGroupLayout; 2],
    draw_groups: [wgpu::BindGroup; 2],
    draw: wgpu::RenderPipeline,
    targets: Targets,
    samples: u32,
    /// With temporal anti-aliasing ([`Self::set_reactive`]): the leaves drawn again into its
    /// motion vectors, marking their pixels.
    mark: Option<wgpu::RenderPipeline>,
    last_eye: Option<DVec3>,
    frame: u32,
}

impl ParticleStage {
    /// The stage for `targets`, its leaves shed from `trees` (of the world's tree types, whose
    /// leaf colours are `colors`) and its petals from `flowers` where the world has any, carried
    /// by `wind`.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        device: &wgpu::Device,
        targets: &Targets,
        settings: ParticleSettings,
        trees: TreeSource<'_>,
        flowers: Option<FlowerSource<'_>>,
        wind: ParticleWind<'_>,
        colors: &[[f32; 3]],
        sky: &crate::world::Sky,
    ) -> Self {
        use wgpu::BufferUsages as U;
        use wgpu::ShaderStages as S;
        let layout = bind_group_layout(
            device,
            "particles",
            &sequential(
                S::COMPUTE,
                [
                    uniform_buffer(),
                    storage_buffer(),
                    uniform_buffer(),
                    storage_buffer_read_only(),
                    storage_buffer_read_only(),
                    storage_buffer_read_only(),
                    storage_buffer_read_only(),
                    storage_buffer_read_only(),
                    storage_buffer(),
                ],
            ),
        );
        let draw_layouts = [
            bind_group_layout(
                device,
                "particles draw",
                &sequential(S::VERTEX_FRAGMENT, [uniform_buffer()]),
            ),
            bind_group_layout(
                device,
                "particles pool",
                &sequential(S::VERTEX, [storage_buffer_read_only()]),
            ),
        ];
        let module = crate::shaders::module(device, "particles.wgsl");
        let step = compute_pipeline(device, "particles step", &module, "cs_step", &[&layout]);
        // The picks' three passes (see particles_cpu::Picks).
        let [pick_keys, pick_plants, pick_list] =
            ["cs_pick_keys", "cs_pick_plants", "cs_pick_list"]
                .map(|entry| compute_pipeline(device, entry, &module, entry, &[&layout]));
        // Per class and bucket, the largest key and the plant that holds it; per class, the
        // picked plants listed and their number.
        let picks = buffer(
            device,
            "particles picks",
            u64::from(6 * PICK_BUCKETS + 2) * 4,
            U::STORAGE | U::COPY_DST,
        );
        let params_buffer = buffer(
            device,
            "particles params",
            std::mem::size_of::<ParticleParams>() as u64,
            U::UNIFORM | U::COPY_DST,
        );
        let particles = buffer(
            device,
            "particles",
            u64::from(settings.count) * std::mem::size_of::<Particle>() as u64,
            U::STORAGE | U::COPY_DST | U::COPY_SRC,
        );
        let group = bind_group(
            device,
            "particles",
            &layout,
            [
                params_buffer.as_entire_binding(),
                particles.as_entire_binding(),
                wind.lookup.as_entire_binding(),
                wind.cells.as_entire_binding(),
                trees.instances.as_entire_binding(),
                trees.args.as_entire_binding(),
                // Without flowers the trees' buffers stand in, never read (no type sheds).
                flowers
                    .map_or(trees.instances, |f| f.instances)
                    .as_entire_binding(),
                flowers.map_or(trees.args, |f| f.args).as_entire_binding(),
                picks.as_entire_binding(),
            ],
        );
        let draw_groups = [
            bind_group(
                device,
                "particles draw",
                &draw_layouts[0],
                [params_buffer.as_entire_binding()],
            ),
            bind_group(
                device,
                "particles pool",
                &draw_layouts[1],
                [particles.as_entire_binding()],
            ),
        ];
        let c4 = |c: [f32; 3]| [c[0], c[1], c[2], 1.0];
        let mut leaf_colors = [[0.0; 4]; 16];
        for (dst, c) in leaf_colors.iter_mut().zip(colors) {
            *dst = c4(*c);
        }
        // The flowers: a bit per type that sheds, its petals' colour; a tree's tickets in the
        // draw against a flower's one, so that each sheds its share.
        let petals = flowers.map_or(&[][..], |f| f.petals);
        let mut mask = 0u32;
        for (t, c) in petals.iter().enumerate().take(8) {
            if let Some(c) = c {
                mask |= 1 << t;
                leaf_colors[PETAL as usize + t] = c4(*c);
            }
        }
        let tickets = if settings.per_flower > 0.0 {
            (settings.per_tree / settings.per_flower)
                .round()
                .clamp(1.0, 256.0) as u32
        } else {
            1
        };
        let flower_table = [
            petals.len().min(8) as u32,
            flowers.map_or(0, |f| f.capacity),
            mask,
            tickets,
        ];
        let params = ParticleParams {
            view_proj: Mat4::IDENTITY.to_cols_array_2d(),
            delta: [0.0; 4],
            motion: [
                settings.drag,
                settings.fall_mps,
                settings.flutter_mps,
                settings.size_m,
            ],
            life: [
                settings.life_s[0],
                settings.life_s[1],
                sky.fog_distance_m,
                0.0,
            ],
            counts: [settings.count, trees.types, trees.capacity, 0],
            shed: [settings.per_tree, settings.per_flower, 0.0, 0.0],
            flowers: flower_table,
            sun_dir: crate::terrain::sun_direction(sky).extend(0.0).to_array(),
            sun_color: c4(sky.sun_color),
            sky_color: c4(sky.sky_color),
            horizon_color: c4(sky.horizon_color),
            colors: leaf_colors,
        };
        let draw = Self::pipeline(device, &module, &draw_layouts, targets, 1);
        Self {
            settings,
            params,
            params_buffer,
            particles,
            group,
            step,
            pick_keys,
            pick_plants,
            pick_list,
            picks,
            draw_layouts,
            draw_groups,
            draw,
            targets: *targets,
            samples: 1,
            mark: None,
            last_eye: None,
            frame: 0,
        }
    }

    fn pipeline(
        device: &wgpu::Device,
        module: &wgpu::ShaderModule,
        [params, pool]: &[wgpu::BindGroupLayout; 2],
        targets: &Targets,
        samples: u32,
    ) -> wgpu::RenderPipeline {
        render_pipeline(
            "particles draw",
            module,
            ("vs_particle", "fs_particle"),
            targets.color_format,
        )
        .layouts(&[params, pool])
        .constants(&[], &[("ENCODE_SRGB", targets.encode_srgb())])
        .triangle_strips()
        .depth(targets.depth_format, true, wgpu::CompareFunction::Greater)
        .multisample(samples, false)
        .build(device)
    }

    /// The leaves drawn again into the temporal anti-aliasing's motion vectors, where the
    /// draw left each leaf's depth.
    fn mark_pipeline(
        device: &wgpu::Device,
        module: &wgpu::ShaderModule,
        [params, pool]: &[wgpu::BindGroupLayout; 2],
        targets: &Targets,
    ) -> wgpu::RenderPipeline {
        render_pipeline(
            "particles mark",
            module,
            ("vs_particle", "fs_particle_mark"),
            crate::aa::taa::MOTION_FORMAT,
        )
        .layouts(&[params, pool])
        .triangle_strips()
        .depth(
            targets.depth_format,
            false,
            wgpu::CompareFunction::GreaterEqual,
        )
        .build(device)
    }

    /// Draws into targets of `samples` samples a pixel from now on.
    pub fn set_samples(&mut self, device: &wgpu::Device, samples: u32) {
        if samples == self.samples {
            return;
        }
        let module = crate::shaders::module(device, "particles.wgsl");
        self.draw = Self::pipeline(device, &module, &self.draw_layouts, &self.targets, samples);
        self.samples = samples;
    }

    /// Whether the leaves also mark their pixels in the temporal anti-aliasing's motion
    /// vectors from now on ([`crate::aa::taa::MOTION_FORMAT`]: w = 2 at the leaf's depth, a
    /// pixel whose history does not hold what it shows; `shaders/aa_taa.wgsl` takes its current
    /// sample alone): then [`Self::record`] takes that target beside the colour. Single-sampled
    /// targets only.
    pub fn set_reactive(&mut self, device: &wgpu::Device, on: bool) {
        if on == self.mark.is_some() {
            return;
        }
        self.mark = on.then(|| {
            let module = crate::shaders::module(device, "particles.wgsl");
            Self::mark_pipeline(device, &module, &self.draw_layouts, &self.targets)
        });
    }

    /// The settings.
    pub fn settings(&self) -> &ParticleSettings {
        &self.settings
    }

    /// GPU memory of the pool, bytes (fixed).
    pub fn pool_bytes(&self) -> u64 {
        self.particles.size()
    }

    /// The step's uniforms of the frame (for the CPU mirror).
    pub fn params(&self) -> &ParticleParams {
        &self.params
    }

    /// Sets the frame: the camera at `eye` (world metres) with the camera-relative
    /// `view_proj`, the time since the last frame `dt` (s). A camera step of more than
    /// [`RESET_JUMP_M`] sheds every particle again.
    pub fn set_frame(&mut self, queue: &wgpu::Queue, eye: DVec3, view_proj: Mat4, dt: f32) {
        let step = self.last_eye.map_or(glam::DVec3::ZERO, |last| eye - last);
        let reset = self.last_eye.is_none() || step.length() > RESET_JUMP_M;
        self.last_eye = Some(eye);
        self.frame = self.frame.wrapping_add(1);
        self.params.view_proj = view_proj.to_cols_array_2d();
        let d = if reset {
            glam::Vec3::ZERO
        } else {
            step.as_vec3()
        };
        self.params.delta = [d.x, d.y, d.z, dt];
        self.params.life[3] = f32::from(u8::from(reset));
        self.params.counts[3] = self.frame;
        queue.write_buffer(&self.params_buffer, 0, bytemuck::bytes_of(&self.params));
    }

    /// Writes `particles` into the pool (for tests: a known state to step).
    pub fn write_particles(&self, queue: &wgpu::Queue, particles: &[Particle]) {
        queue.write_buffer(&self.particles, 0, bytemuck::cast_slice(particles));
    }

    /// Writes `params` as the frame's uniforms (for tests).
    pub fn write_params(&mut self, queue: &wgpu::Queue, params: ParticleParams) {
        self.params = params;
        queue.write_buffer(&self.params_buffer, 0, bytemuck::bytes_of(&self.params));
    }

    /// Records the step (compute): the picks of the plants particles are shed from
    /// ([`crate::plants::particles_cpu::Picks`]), over the largest region of the two pools,
    /// then the particles.
    pub fn record_step(&self, encoder: &mut wgpu::CommandEncoder, timer: &mut GpuTimer) {
        encoder.clear_buffer(&self.picks, 0, None);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("particles step"),
            timestamp_writes: timer.compute_pass("particles_step"),
        });
        pass.set_bind_group(0, &self.group, &[]);
        // A region holds at most a pool's bound over three levels (`MAX_POOL_BYTES`, 1.4
        // million instances): one dispatch reaches it.
        let region = self.params.counts[2]
            .max(self.params.flowers[1])
            .clamp(1, PICK_INDICES.min(65_535 * 64));
        for pipeline in [&self.pick_keys, &self.pick_plants] {
            pass.set_pipeline(pipeline);
            pass.dispatch_workgroups(region.div_ceil(64), 1, 1);
        }
        // One workgroup a class lists its picks.
        pass.set_pipeline(&self.pick_list);
        pass.dispatch_workgroups(2, 1, 1);
        pass.set_pipeline(&self.step);
        pass.dispatch_workgroups(self.settings.count.div_ceil(64), 1, 1);
    }

    /// Records the step, then the leaves' draw into `color` and `depth` (loaded), and with
    /// [`Self::set_reactive`] their marks into `motion` (loaded).
    ///
    /// # Panics
    /// With [`Self::set_reactive`] on and no `motion`.
    pub fn record(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        motion: Option<&wgpu::TextureView>,
        depth: &wgpu::TextureView,
        timer: &mut GpuTimer,
    ) {
        self.record_step(encoder, timer);
        let timestamps = timer.render_pass("particles_draw");
        self.draw_leaves(
            encoder,
            "particles draw",
            &self.draw,
            color,
            depth,
            timestamps,
        );
        if let Some(mark) = &self.mark {
            let motion = motion.expect("the leaves' marks need the motion vectors");
            self.draw_leaves(encoder, "particles mark", mark, motion, depth, None);
        }
    }

    /// One pass drawing every leaf with `pipeline` into `target` and `depth` (both loaded).
    fn draw_leaves(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        label: &str,
        pipeline: &wgpu::RenderPipeline,
        target: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        timestamps: Option<wgpu::RenderPassTimestampWrites<'_>>,
    ) {
        let mut pass = render_pass(
            encoder,
            label,
            (target, wgpu::LoadOp::Load),
            Some((depth, wgpu::LoadOp::Load)),
            timestamps,
        );
        pass.set_pipeline(pipeline);
        // Four vertices a leaf, as a strip.
        pass.set_bind_group(0, &self.draw_groups[0], &[]);
        pass.set_bind_group(1, &self.draw_groups[1], &[]);
        pass.draw(0..4, 0..self.settings.count);
    }

    /// Reads the pool back (for tests and tools: waits for the GPU).
    pub fn read_particles(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> Vec<Particle> {
        crate::gpu::read_buffer_pod(device, queue, &self.particles, ..)
            .expect("read back the particles")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_picks_reach_the_largest_region_in_one_dispatch() {
        // The largest region a pool can have (one type: three levels share the bound) fits
        // the picks' dispatch of at most 65,535 workgroups of 64 (and so their 24-bit indices).
        let most = crate::plants::renderer::max_capacity(1);
        assert!(most <= 65_535 * 64, "{most}");
        const { assert!(65_535 * 64 < PICK_INDICES) };
    }

    #[test]
    fn settings_out_of_range_say_which() {
        assert!(ParticleSettings::default().validate().is_ok());
        let bad = [
            (
                ParticleSettings {
                    count: 0,
                    ..Default::default()
                },
                "count",
            ),
            (
                ParticleSettings {
                    drag: 0.0,
                    ..Default::default()
                },
                "drag",
            ),
            (
                ParticleSettings {
                    life_s: [5.0, 1.0],
                    ..Default::default()
                },
                "life",
            ),
        ];
        for (s, word) in bad {
            let (field, _, _) = s.validate().unwrap_err();
            assert!(field.contains(word), "{field}");
        }
    }
}
