//! The grass stage on the GPU: the bounded instance pool, generation and culling per tile in
//! compute (`shaders/grass_generate.wgsl`), the wind on each blade (`shaders/grass_wind.wgsl`)
//! and one indirect draw per tile (`shaders/grass_draw.wgsl`), culled against the Hi-Z pyramid
//! of [`crate::grass::hiz`].
//!
//! The pool has 8 tile slots in two halves of 4, each half with buffers of its own: a batch of 4
//! tiles is generated into one half and drawn while the next batch is generated into the other.
//! Its size is fixed when the stage is made, whatever the view distance.

use bytemuck::{Pod, Zeroable};
use glam::Mat4;

use crate::gpu::layout::*;
use crate::gpu::pass::render_pass_into;
use crate::gpu::pipeline::{array_view, buffer as gpu_buffer};
use crate::gpu::{GpuTimer, Targets};
use crate::grass::draw::DrawPass;
use crate::grass::generate::GeneratePass;
use crate::grass::generate_cpu::counter;
pub use crate::grass::hiz::HiZPyramid;
use crate::grass::wind::WindPass;
use crate::grass::wind_cpu::WindPassParams;
use crate::grass::{GenerateParams, GenerateStats, GrassTypeGpu, TileJob};
use crate::lod::Frustum;
use crate::stream::TileAtlas;
use crate::terrain::sun_direction;
use crate::world::Manifest;

/// Bytes of a blade record.
const BLADE_BYTES: u64 = std::mem::size_of::<crate::grass::Blade>() as u64;

/// Tile slots of the pool.
pub const POOL_SLOTS: u32 = 8;
/// Tiles a batch (half the pool).
pub const BATCH_TILES: u32 = 4;
/// Grass tiles a frame generates and draws at most (the job buffer's size); more are left out.
pub const MAX_JOBS: u32 = 1024;
const BATCH_STRIDE: u64 = 256;
/// The share of an infill radius over which its blades shrink away.
pub const INFILL_FADE: f32 = 0.3;

/// Settings of grass generation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GrassSettings {
    /// Blade spacing of the high-LOD grid, metres (the low-LOD grid has twice this).
    pub spacing_m: f32,
    /// Every grass type's blade width times this.
    pub width_scale: f32,
    /// Edge of a grass tile, metres.
    pub tile_m: f32,
    /// Radius of the high-LOD ring, metres: blades the low grid drops are gone here.
    pub high_radius_m: f32,
    /// Width of the band before it over which those blades fade out, metres.
    pub lod_fade_m: f32,
    /// Radii of the infill near the camera, metres: out to the first, every high-LOD cell gets
    /// three more blades (half the spacing), out to the second twelve more (a quarter of it).
    /// Each set shrinks away over the outer [`INFILL_FADE`] of its radius; 0 turns it off.
    pub infill_m: [f32; 2],
    /// View distance of grass, metres (the low ring's radius).
    pub view_distance_m: f32,
    /// Width of the dithered fade before the view distance, metres.
    pub far_fade_m: f32,
    /// Voronoi clump cell, metres.
    pub clump_m: f32,
    /// Blades shorter than this are split in two, metres.
    pub short_m: f32,
    /// Seed of every per-blade hash.
    pub seed: u32,
    /// Segments of a blade near the camera (within [`Self::near_m`]), in the rest of the high
    /// ring and in the low ring (by default 5, 3 and 3: 11, 7 and 7 vertices).
    pub segments: [u32; 3],
    /// Horizontal radius of the near blades, metres: the high-LOD tiles it reaches get a second
    /// job for their blades within it.
    pub near_m: f32,
    /// The blades of the low-LOD grid are this many times as wide in the low ring: over the
    /// band in which the blades the low grid drops fade out, the ones it keeps widen from their
    /// own width to this, so that a quarter of the blades keeps the ground's cover.
    pub lod_widen: f32,
    /// Metres toward the fade at the view distance per metre the camera stands above a blade
    /// ([`crate::terrain::far_field::far_distance`]).
    pub elevation_fade: f32,
    /// Whether the far field lies under the blades (the gaps between near blades read as
    /// grass), or only where they fade out before the view distance (the ground between them
    /// bare, as a field of real blades has it: the truth's setting).
    pub far_field_under_blades: bool,
}

impl GrassSettings {
    /// Most segments of a blade: [`crate::RendererConfig::validate`] refuses more (each count
    /// is packed into 8 bits of the generate pass's uniforms).
    pub const MAX_SEGMENTS: u32 = 64;

    /// Grid points along a tile edge at high LOD.
    pub fn grid(&self) -> u32 {
        (self.tile_m / self.spacing_m).round().max(1.0) as u32
    }
}

/// Grass GPU figures of one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GrassStats {
    /// Tiles generated and drawn, per LOD (high, low).
    pub tiles: [u32; 2],
    /// Grid points considered, per LOD.
    pub considered: [u32; 2],
    /// Points without grass (bare type, zero density or height), per LOD.
    pub empty: [u32; 2],
    /// Blades culled by distance (LOD fade, view-distance dither), per LOD.
    pub culled_distance: [u32; 2],
    /// Blades culled by the frustum, per LOD.
    pub culled_frustum: [u32; 2],
    /// Blades culled by the terrain's Hi-Z, per LOD.
    pub culled_occlusion: [u32; 2],
    /// Blades that did not fit their slot, per LOD.
    pub overflow: [u32; 2],
    /// Blades drawn, per LOD.
    pub drawn: [u32; 2],
}

impl GrassStats {
    /// The figures from the 16 counters of `shaders/grass_generate.wgsl`.
    pub fn from_counts(tiles: [u32; 2], c: &[u32; 16]) -> Self {
        let pick = |k: usize| [c[k], c[counter::COUNT + k]];
        Self {
            tiles,
            considered: pick(counter::CONSIDERED),
            empty: pick(counter::EMPTY),
            culled_distance: pick(counter::DISTANCE),
            culled_frustum: pick(counter::FRUSTUM),
            culled_occlusion: pick(counter::OCCLUSION),
            overflow: pick(counter::OVERFLOW),
            drawn: pick(counter::DRAWN),
        }
    }

    /// The same figures as the CPU mirror's counters.
    pub fn to_generate_stats(&self) -> GenerateStats {
        let mut s = GenerateStats::default();
        for l in 0..2 {
            s.counts[l][counter::CONSIDERED] = self.considered[l];
            s.counts[l][counter::EMPTY] = self.empty[l];
            s.counts[l][counter::DISTANCE] = self.culled_distance[l];
            s.counts[l][counter::FRUSTUM] = self.culled_frustum[l];
            s.counts[l][counter::OCCLUSION] = self.culled_occlusion[l];
            s.counts[l][counter::EMITTED] = self.drawn[l] + self.overflow[l];
            s.counts[l][counter::OVERFLOW] = self.overflow[l];
            s.counts[l][counter::DRAWN] = self.drawn[l];
        }
        s
    }
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct DrawFrame {
    view_proj: [[f32; 4]; 4],
    misc: [f32; 4],
    sun_dir: [f32; 4],
    sun_color: [f32; 4],
    sky_color: [f32; 4],
    horizon_color: [f32; 4],
    // x: feature bits
    flags: [u32; 4],
    base_colors: [[f32; 4]; 16],
    tip_colors: [[f32; 4]; 16],
    // This frame's view-projection unjittered and the last frame's, from this frame's
    // camera-relative positions (the motion vectors').
    unjittered: [[f32; 4]; 4],
    last_view_proj: [[f32; 4]; 4],
}
const _: () = assert!(std::mem::size_of::<DrawFrame>() == 64 + 96 + 512 + 128);

struct Half {
    blades: wgpu::Buffer,
    counters: wgpu::Buffer,
    args: wgpu::Buffer,
    generate: wgpu::BindGroup,
    draw: wgpu::BindGroup,
    wind: wgpu::BindGroup,
    wind_dispatch: wgpu::Buffer,
}

/// The wind buffers the grass draw reads.
#[derive(Clone, Copy)]
pub struct WindBindings<'a> {
    /// The wind field's `WindLookup` uniform.
    pub lookup: &'a wgpu::Buffer,
    /// The wind field's cells.
    pub cells: &'a wgpu::Buffer,
    /// The sway state (per cell and grass type).
    pub sway: &'a wgpu::Buffer,
}

/// Pipelines, the instance pool and the Hi-Z pyramid of the grass stage.
pub struct GrassRenderer {
    settings: GrassSettings,
    capacity: u32,
    gen_pass: GeneratePass,
    wind_pass: WindPass,
    draw_pass: DrawPass,
    params: GenerateParams,
    params_buffer: wgpu::Buffer,
    jobs: wgpu::Buffer,
    batches: wgpu::Buffer,
    stats: wgpu::Buffer,
    draw_frame: DrawFrame,
    draw_frame_buffer: wgpu::Buffer,
    wind_params: WindPassParams,
    wind_params_buffer: wgpu::Buffer,
    halves: [Half; 2],
    hiz_read_group: wgpu::BindGroup,
    /// The occlusion pyramid (built from the depth of the terrain's G-buffer pass).
    pub hiz: HiZPyramid,
    /// The targets the blades are drawn into, and their samples a pixel.
    targets: Targets,
    samples: u32,
    /// Whether the blades write their motion vectors (for the temporal anti-aliasing).
    motion: bool,
}

/// What a half of the pool binds besides its own buffers.
struct PoolBindings<'a> {
    gen_pass: &'a GeneratePass,
    wind_layout: &'a wgpu::BindGroupLayout,
    draw_layout: &'a wgpu::BindGroupLayout,
    params: &'a wgpu::Buffer,
    jobs: &'a wgpu::Buffer,
    batches: &'a wgpu::Buffer,
    stats: &'a wgpu::Buffer,
    draw_frame: &'a wgpu::Buffer,
    wind_params: &'a wgpu::Buffer,
    /// The atlas's heights and grass, as 2D arrays.
    atlas: (wgpu::TextureView, wgpu::TextureView),
    wind: WindBindings<'a>,
}

impl Half {
    /// Half `label` of a pool of `slot_bytes` slots, with its bind groups.
    fn new(device: &wgpu::Device, label: &str, slot_bytes: u64, b: &PoolBindings<'_>) -> Self {
        use wgpu::BufferUsages as U;
        let buffer = |label, size: u64, usage| gpu_buffer(device, label, size, usage);
        let blades = buffer(
            label,
            slot_bytes * u64::from(BATCH_TILES),
            U::STORAGE | U::COPY_SRC | U::COPY_DST,
        );
        let counters = buffer("grass counters", 16, U::STORAGE | U::COPY_DST);
        let args = buffer(
            "grass draw args",
            64,
            U::STORAGE | U::INDIRECT | U::COPY_SRC,
        );
        let wind_dispatch = buffer("grass wind dispatch", 12, U::STORAGE | U::INDIRECT);
        let generate = bind_group_with_indices(
            device,
            "grass generate",
            &b.gen_pass.layout,
            [
                (0, b.params.as_entire_binding()),
                (1, b.jobs.as_entire_binding()),
                (2, buffer_prefix(b.batches, 16)),
                (3, view(&b.atlas.0)),
                (4, view(&b.atlas.1)),
                (6, blades.as_entire_binding()),
                (7, counters.as_entire_binding()),
                (8, b.stats.as_entire_binding()),
                (9, args.as_entire_binding()),
                (10, wind_dispatch.as_entire_binding()),
            ],
        );
        let draw = bind_group(
            device,
            "grass draw",
            b.draw_layout,
            [
                b.draw_frame.as_entire_binding(),
                buffer_prefix(&blades, slot_bytes),
            ],
        );
        let wind = bind_group(
            device,
            "grass wind",
            b.wind_layout,
            [
                b.wind_params.as_entire_binding(),
                b.wind.lookup.as_entire_binding(),
                b.wind.cells.as_entire_binding(),
                b.wind.sway.as_entire_binding(),
                blades.as_entire_binding(),
                args.as_entire_binding(),
            ],
        );
        Self {
            blades,
            counters,
            args,
            generate,
            draw,
            wind,
            wind_dispatch,
        }
    }
}

/// Blades a slot holds: `asked` rounded up to whole 256-byte slots, at most what the device
/// binds in a half of the pool.
fn pool_capacity(device: &wgpu::Device, asked: u32) -> u32 {
    // Slots start at multiples of 256 bytes (the storage offset alignment): 16 blades of
    // 96 bytes are 1536 bytes.
    // A half of the pool is bound whole: a world of coarse cells (large grass tiles) can
    // ask for more than the device binds. Its densest tiles then overflow, clamped and
    // counted, instead of the pool failing.
    let limits = device.limits();
    let bind_limit = limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size);
    let most = (bind_limit / (u64::from(BATCH_TILES) * BLADE_BYTES)) as u32 / 16 * 16;
    let (capacity, over) = capacity_within(asked, most);
    if over {
        log::warn!(
            "the grass pool needs {} blades a slot, more than the device binds ({most}); the \
             densest grass tiles will overflow",
            asked.max(16)
        );
    }
    capacity
}

/// `asked` rounded up to whole slots of 16 blades and held to `most` (itself whole slots, at
/// least one); and whether it was held. Saturating: a world of huge tiles asks for as many as
/// `u32` counts, which rounded up would wrap to 0.
fn capacity_within(asked: u32, most: u32) -> (u32, bool) {
    let capacity = asked.max(16).div_ceil(16).saturating_mul(16);
    (capacity.min(most).max(16), capacity > most)
}

/// The Hi-Z levels' table of the generation constants: (offset, width, height) per level.
pub(crate) fn hiz_levels(hiz: &HiZPyramid) -> [[u32; 4]; 16] {
    let mut t = [[0u32; 4]; 16];
    for (dst, &(o, w, h)) in t.iter_mut().zip(hiz.levels()) {
        *dst = [o, w, h, 0];
    }
    t
}

/// Per grass type of `manifest` (at most 16): its shape for the generation and its base and
/// tip colours for the draw.
fn type_tables(
    manifest: &Manifest,
    settings: &GrassSettings,
) -> ([GrassTypeGpu; 16], [[f32; 4]; 16], [[f32; 4]; 16]) {
    let mut types = [GrassTypeGpu::default(); 16];
    let mut base_colors = [[0.0; 4]; 16];
    let mut tip_colors = [[0.0; 4]; 16];
    for (i, t) in manifest.grass_types.iter().take(16).enumerate() {
        types[i] = GrassTypeGpu {
            height: t.height_m,
            width: t.width_m.map(|w| w * settings.width_scale),
            // Soft grass follows the slope more; stiff grass grows straighter up.
            growth_blend: crate::terrain::far_field::growth_blend(t.stiffness),
            stiffness: t.stiffness,
            _pad: [0.0; 2],
        };
        // Gloss per type in the colours' spare channels (exponent, strength): stiffer,
        // waxier blades are glossier.
        let s = t.stiffness.clamp(0.0, 1.0);
        base_colors[i] = [
            t.base_color[0],
            t.base_color[1],
            t.base_color[2],
            8.0 + 32.0 * s,
        ];
        tip_colors[i] = [
            t.tip_color[0],
            t.tip_color[1],
            t.tip_color[2],
            0.1 + 0.25 * s,
        ];
    }
    (types, base_colors, tip_colors)
}

/// The generation constants before the first camera: the grid, rings and grass types of
/// `settings` and `manifest`, slots of `capacity` blades, the targets' size and `hiz`'s levels.
fn generate_params(
    manifest: &Manifest,
    settings: &GrassSettings,
    targets: &Targets,
    hiz: &HiZPyramid,
    capacity: u32,
    types: [GrassTypeGpu; 16],
) -> GenerateParams {
    let p = &manifest.pyramid;
    GenerateParams {
        view_proj: Mat4::IDENTITY.to_cols_array_2d(),
        planes: [[0.0; 4]; 6],
        camera: [0.0, 0.5, targets.width as f32, targets.height as f32],
        grid: [settings.grid(), p.tile_cells, p.border, settings.seed],
        dims: [
            settings.spacing_m,
            settings.tile_m,
            settings.clump_m,
            settings.short_m,
        ],
        ranges: [
            settings.high_radius_m - settings.lod_fade_m,
            settings.high_radius_m,
            settings.view_distance_m - settings.far_fade_m,
            settings.view_distance_m,
        ],
        infill: {
            let [half, quarter] = settings.infill_m;
            let band = |r: f32| [(1.0 - INFILL_FADE) * r, r];
            let (q, h) = (band(quarter), band(half));
            [q[0], q[1], h[0], h[1]]
        },
        near: [
            settings.near_m,
            settings.lod_widen,
            settings.elevation_fade,
            0.0,
        ],
        limits: [
            hiz.mips(),
            capacity,
            manifest.grass_types.len().min(16) as u32,
            settings.segments[0].clamp(1, 64)
                | (settings.segments[1].clamp(1, 64) << 8)
                | (settings.segments[2].clamp(1, 64) << 16),
        ],
        hiz_levels: hiz_levels(hiz),
        types,
    }
}

impl DrawFrame {
    /// The draw's constants before the first camera: the sky's light and the types' colours.
    fn new(
        sky: &crate::world::Sky,
        base_colors: [[f32; 4]; 16],
        tip_colors: [[f32; 4]; 16],
    ) -> Self {
        let c4 = |c: [f32; 3]| [c[0], c[1], c[2], 1.0];
        Self {
            view_proj: Mat4::IDENTITY.to_cols_array_2d(),
            misc: [sky.fog_distance_m, 0.0, 0.0, 0.0],
            sun_dir: sun_direction(sky).extend(0.0).to_array(),
            sun_color: c4(sky.sun_color),
            sky_color: c4(sky.sky_color),
            horizon_color: c4(sky.horizon_color),
            flags: [crate::features::Features::all().bits(), 0, 0, 0],
            base_colors,
            tip_colors,
            unjittered: Mat4::IDENTITY.to_cols_array_2d(),
            last_view_proj: Mat4::IDENTITY.to_cols_array_2d(),
        }
    }
}

impl GrassRenderer {
    /// The grass stage for `manifest`'s world, reading tile data from `atlas`, with slots of
    /// `capacity` blades, drawing into `targets` and culling against the Hi-Z pyramid of their
    /// depth; blades bend with the wind
    /// field (`wind.lookup`, `wind.cells`) and sway on its springs (`wind.sway`).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        manifest: &Manifest,
        atlas: &TileAtlas,
        targets: &Targets,
        settings: GrassSettings,
        capacity: u32,
        wind: WindBindings<'_>,
    ) -> Self {
        let capacity = pool_capacity(device, capacity);
        let hiz = HiZPyramid::new(device, queue, targets.width, targets.height);
        let (types, base_colors, tip_colors) = type_tables(manifest, &settings);
        let params = generate_params(manifest, &settings, targets, &hiz, capacity, types);
        let draw_frame = DrawFrame::new(&manifest.sky, base_colors, tip_colors);

        let buffer = |label, size: u64, usage| gpu_buffer(device, label, size, usage);
        use wgpu::BufferUsages as U;
        let params_buffer = buffer(
            "grass params",
            std::mem::size_of::<GenerateParams>() as u64,
            U::UNIFORM | U::COPY_DST,
        );
        let jobs = buffer(
            "grass jobs",
            u64::from(MAX_JOBS) * 32,
            U::STORAGE | U::COPY_DST,
        );
        let max_batches = MAX_JOBS.div_ceil(BATCH_TILES) as u64;
        let batches = buffer(
            "grass batches",
            max_batches * BATCH_STRIDE,
            U::UNIFORM | U::COPY_DST,
        );
        let stats = buffer("grass stats", 64, U::STORAGE | U::COPY_DST | U::COPY_SRC);
        let draw_frame_buffer = buffer(
            "grass draw frame",
            std::mem::size_of::<DrawFrame>() as u64,
            U::UNIFORM | U::COPY_DST,
        );
        let wind_params_buffer = buffer(
            "grass wind params",
            std::mem::size_of::<WindPassParams>() as u64,
            U::UNIFORM | U::COPY_DST,
        );

        let slot_bytes = u64::from(capacity) * BLADE_BYTES;
        let gen_pass = GeneratePass::new(device);
        let wind_pass = WindPass::new(device);
        let draw_pass = DrawPass::new(device, targets, settings.segments, slot_bytes, 1);
        let bindings = PoolBindings {
            gen_pass: &gen_pass,
            wind_layout: &wind_pass.layout(),
            draw_layout: &draw_pass.layout,
            params: &params_buffer,
            jobs: &jobs,
            batches: &batches,
            stats: &stats,
            draw_frame: &draw_frame_buffer,
            wind_params: &wind_params_buffer,
            atlas: (array_view(&atlas.heights), array_view(&atlas.grass)),
            wind,
        };
        let halves = ["grass pool half A", "grass pool half B"]
            .map(|label| Half::new(device, label, slot_bytes, &bindings));
        let hiz_read_group = hiz.read_group(device, &gen_pass.hiz_layout);
        Self {
            settings,
            capacity,
            gen_pass,
            wind_pass,
            draw_pass,
            params,
            params_buffer,
            jobs,
            batches,
            stats,
            draw_frame,
            draw_frame_buffer,
            wind_params: WindPassParams {
                misc: [0.0; 4],
                flags: [crate::features::Features::all().bits(), capacity, 0, 0],
                motion: [0.0; 4],
            },
            wind_params_buffer,
            halves,
            hiz_read_group,
            hiz,
            targets: *targets,
            samples: 1,
            motion: false,
        }
    }

    /// Draws into targets of `samples` samples a pixel from now on (1: single-sampled; more:
    /// multisampled, a blade narrower than a pixel drawn a pixel wide with its width as its
    /// coverage).
    pub fn set_samples(&mut self, device: &wgpu::Device, samples: u32) {
        if samples == self.samples {
            return;
        }
        [self.draw_pass.near, self.draw_pass.high, self.draw_pass.low] = DrawPass::pipelines(
            device,
            &self.targets,
            self.settings.segments,
            &self.draw_pass.layout,
            samples,
            self.motion,
        );
        self.samples = samples;
    }

    /// Whether the blades write their motion vectors from now on: then [`Self::record`] takes
    /// a target of [`crate::aa::taa::MOTION_FORMAT`] beside the colour.
    pub fn set_motion_vectors(&mut self, device: &wgpu::Device, on: bool) {
        if on == self.motion {
            return;
        }
        self.motion = on;
        [self.draw_pass.near, self.draw_pass.high, self.draw_pass.low] = DrawPass::pipelines(
            device,
            &self.targets,
            self.settings.segments,
            &self.draw_pass.layout,
            self.samples,
            on,
        );
    }

    /// Sets what the blades' motion over the last frame is taken from (before
    /// [`Self::set_camera`], which uploads it): the frame's time step (the wind on each blade
    /// a step ago), this frame's unjittered view-projection and the last frame's, both from
    /// this frame's camera-relative positions.
    pub fn set_motion(&mut self, dt_s: f32, unjittered: Mat4, last_view_proj: Mat4) {
        self.wind_params.motion[0] = dt_s;
        self.draw_frame.unjittered = unjittered.to_cols_array_2d();
        self.draw_frame.last_view_proj = last_view_proj.to_cols_array_2d();
    }

    /// Follows a resize of the targets to `width` x `height`: a new Hi-Z pyramid of that size.
    pub fn resize(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, width: u32, height: u32) {
        self.hiz = HiZPyramid::new(device, queue, width, height);
        self.hiz_read_group = self.hiz.read_group(device, &self.gen_pass.hiz_layout);
        self.params.camera[2] = width as f32;
        self.params.camera[3] = height as f32;
        self.params.limits[0] = self.hiz.mips();
        self.params.hiz_levels = hiz_levels(&self.hiz);
    }

    /// Writes every byte of the pool once, so that its memory is committed up front (a driver
    /// may otherwise commit pages on first use, which would look like growth later).
    pub fn commit_pool(&self, device: &wgpu::Device, queue: &wgpu::Queue) {
        let mut encoder = device.create_command_encoder(&Default::default());
        for h in &self.halves {
            encoder.clear_buffer(&h.blades, 0, None);
        }
        queue.submit([encoder.finish()]);
    }

    /// Blades a slot holds.
    pub fn capacity(&self) -> u32 {
        self.capacity
    }

    /// The settings.
    pub fn settings(&self) -> &GrassSettings {
        &self.settings
    }

    /// GPU memory of the instance pool, bytes (fixed: it does not depend on the view).
    pub fn pool_bytes(&self) -> u64 {
        self.halves
            .iter()
            .map(|h| h.blades.size() + h.counters.size() + h.args.size())
            .sum()
    }

    /// The wind pass's constants of the frame (for its CPU mirror).
    pub fn wind_params(&self) -> &WindPassParams {
        &self.wind_params
    }

    /// The generation constants of the frame (for the CPU mirror).
    pub fn params(&self) -> &GenerateParams {
        &self.params
    }

    /// Sets the frame's time (seconds), ambient wind speed (m/s, for gust highlights), the
    /// switched-on features and the camera's world position (for world-space colour noise).
    pub fn set_frame(
        &mut self,
        time_s: f64,
        ambient_speed: f32,
        features: crate::features::Features,
        camera_world: glam::DVec3,
    ) {
        self.draw_frame.flags[0] = features.bits();
        self.wind_params.misc = [
            (time_s % 3600.0) as f32,
            ambient_speed,
            camera_world.x.rem_euclid(4096.0) as f32,
            camera_world.y.rem_euclid(4096.0) as f32,
        ];
        self.wind_params.flags[0] = features.bits();
    }

    /// Sets the camera of this frame: its camera-relative view-projection and that's frustum.
    pub fn set_camera(
        &mut self,
        queue: &wgpu::Queue,
        view_proj: Mat4,
        frustum: &Frustum,
        camera_altitude: f32,
        near: f32,
    ) {
        self.params.view_proj = view_proj.to_cols_array_2d();
        self.params.planes = [[0.0; 4]; 6];
        for (dst, p) in self.params.planes.iter_mut().zip(frustum.planes()) {
            *dst = p.to_array();
        }
        self.params.camera[0] = camera_altitude;
        self.params.camera[1] = near;
        self.draw_frame.view_proj = self.params.view_proj;
        // The target's height, for the blades' width in pixels, and its width, for their
        // motion in pixels.
        self.draw_frame.misc[1] = self.params.camera[3];
        self.draw_frame.misc[2] = self.params.camera[2];
        queue.write_buffer(&self.params_buffer, 0, bytemuck::bytes_of(&self.params));
        queue.write_buffer(
            &self.draw_frame_buffer,
            0,
            bytemuck::bytes_of(&self.draw_frame),
        );
        queue.write_buffer(
            &self.wind_params_buffer,
            0,
            bytemuck::bytes_of(&self.wind_params),
        );
    }

    /// Records generation and drawing of `jobs` in batches of 4 (their `slot` fields are set
    /// here), into `color` and `depth` (loaded, not cleared), and with motion vectors on
    /// ([`Self::set_motion_vectors`]) the blades' motion into `motion` (loaded). Returns the
    /// tiles per LOD.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        jobs: &[TileJob],
        color: &wgpu::TextureView,
        motion: Option<&wgpu::TextureView>,
        depth: &wgpu::TextureView,
        timer: &mut GpuTimer,
    ) -> [u32; 2] {
        let jobs = &jobs[..jobs.len().min(MAX_JOBS as usize)];
        encoder.clear_buffer(&self.stats, 0, None);
        let mut tiles = [0u32; 2];
        if jobs.is_empty() {
            return tiles;
        }
        let mut gpu_jobs: Vec<TileJob> = jobs.to_vec();
        for (i, j) in gpu_jobs.iter_mut().enumerate() {
            j.slot = (i as u32) % BATCH_TILES;
            // A near job is the second of its tile's.
            if j.lod != 2 {
                tiles[crate::grass::generate_cpu::stats_lod(j.lod)] += 1;
            }
        }
        queue.write_buffer(&self.jobs, 0, bytemuck::cast_slice(&gpu_jobs));
        let n_batches = gpu_jobs.len().div_ceil(BATCH_TILES as usize);
        let mut batch_data = vec![0u8; n_batches * BATCH_STRIDE as usize];
        for b in 0..n_batches {
            let first = (b as u32) * BATCH_TILES;
            let count = (gpu_jobs.len() as u32 - first).min(BATCH_TILES);
            batch_data[b * BATCH_STRIDE as usize..][..8]
                .copy_from_slice(bytemuck::cast_slice(&[first, count]));
        }
        queue.write_buffer(&self.batches, 0, &batch_data);
        let g = self.settings.grid();
        for (b, chunk) in gpu_jobs.chunks(BATCH_TILES as usize).enumerate() {
            let half = &self.halves[b % 2];
            let offset = (b as u64 * BATCH_STRIDE) as u32;
            encoder.clear_buffer(&half.counters, 0, None);
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("grass generate"),
                    timestamp_writes: timer.compute_pass("grass_generate"),
                });
                pass.set_bind_group(0, &half.generate, &[offset]);
                pass.set_bind_group(1, &self.hiz_read_group, &[]);
                pass.set_pipeline(&self.gen_pass.generate);
                pass.dispatch_workgroups(g.div_ceil(8), g.div_ceil(8), chunk.len() as u32);
                pass.set_pipeline(&self.gen_pass.finalize);
                pass.dispatch_workgroups(1, 1, 1);
                // The wind on each generated blade, once per blade.
                pass.set_pipeline(&self.wind_pass.pipeline);
                pass.set_bind_group(0, &half.wind, &[]);
                pass.dispatch_workgroups_indirect(&half.wind_dispatch, 0);
            }
            let colors: &[_] = match motion.filter(|_| self.motion) {
                Some(m) => &[(color, wgpu::LoadOp::Load), (m, wgpu::LoadOp::Load)],
                None => &[(color, wgpu::LoadOp::Load)],
            };
            let mut pass = render_pass_into(
                encoder,
                "grass draw",
                colors,
                Some((depth, wgpu::LoadOp::Load)),
                timer.render_pass("grass_draw"),
            );
            for (k, job) in chunk.iter().enumerate() {
                pass.set_pipeline(match job.lod {
                    0 => &self.draw_pass.high,
                    2 => &self.draw_pass.near,
                    _ => &self.draw_pass.low,
                });
                let slot_offset = (k as u64 * u64::from(self.capacity) * BLADE_BYTES) as u32;
                pass.set_bind_group(0, &half.draw, &[slot_offset]);
                pass.draw_indirect(&half.args, k as u64 * 16);
            }
        }
        tiles
    }

    /// The buffer of the frame's counters (16 u32: blades considered, culled by each test and
    /// drawn, per LOD), for a readback after [`Self::record`].
    pub fn stats_buffer(&self) -> &wgpu::Buffer {
        &self.stats
    }

    /// Reads the counters of the last recorded frame (for tests and tools: waits for the GPU).
    pub fn read_stats(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        tiles: [u32; 2],
    ) -> GrassStats {
        let c: Vec<u32> = crate::gpu::read_buffer_pod(device, queue, &self.stats, ..)
            .expect("read back the grass counters");
        GrassStats::from_counts(tiles, &c[..16].try_into().expect("16 counters"))
    }

    /// Reads back slot `k` of pool half `half` (for tests): the draw arguments and the blades.
    pub fn read_slot(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        half: usize,
        k: u32,
    ) -> ([u32; 4], Vec<crate::grass::Blade>) {
        let h = &self.halves[half];
        let slot_bytes = u64::from(self.capacity) * BLADE_BYTES;
        let args: Vec<u32> = crate::gpu::read_buffer_pod(device, queue, &h.args, ..)
            .expect("read back the draw arguments");
        let a = [
            args[k as usize * 4],
            args[k as usize * 4 + 1],
            args[k as usize * 4 + 2],
            args[k as usize * 4 + 3],
        ];
        let start = u64::from(k) * slot_bytes;
        let all: Vec<crate::grass::Blade> =
            crate::gpu::read_buffer_pod(device, queue, &h.blades, start..start + slot_bytes)
                .expect("read back the blades");
        (a, all[..a[1] as usize].to_vec())
    }
}

#[cfg(test)]
mod pool_tests {
    #[test]
    fn the_pool_asked_for_is_rounded_up_and_held_without_wrapping() {
        use super::capacity_within;
        assert_eq!(capacity_within(0, 4096), (16, false));
        assert_eq!(capacity_within(17, 4096), (32, false));
        assert_eq!(capacity_within(5000, 4096), (4096, true));
        for huge in [u32::MAX, u32::MAX - 15, u32::MAX - 16] {
            assert_eq!(capacity_within(huge, 349_520), (349_520, true), "{huge}");
        }
    }
}
