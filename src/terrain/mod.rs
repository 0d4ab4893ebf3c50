//! Terrain drawing: a regular grid per tile, displaced by the tile atlas's heights, lit by the
//! sun and a sky hemisphere and fogged toward the horizon; then the sky where no terrain is.
//!
//! Everything is drawn camera-relative (see `shaders/terrain_gbuffer.wgsl`). The shading is
//! deferred: the terrain's draw writes only a G-buffer (where in the atlas each pixel's ground
//! is, `shaders/terrain_gbuffer.wgsl`), a compute pass over the whole target shades every
//! pixel, terrain and sky (`shaders/terrain_shade.wgsl`), and a full-screen pass writes that
//! into the colour target (`shaders/terrain_composite.wgsl`). This file sets up and records
//! that family of three passes; the contact shadows are a stage of their own
//! ([`contact_shadow`], mirror [`contact_shadow_cpu`]), and [`far_field`] mirrors the far
//! field of `shaders/shared/terrain_shading.wgsl`.

use bytemuck::{Pod, Zeroable};
use glam::{DVec2, DVec3, Mat4, Vec3};
use wgpu::util::DeviceExt;

use crate::gpu::layout::*;
use crate::gpu::pass::render_pass;
use crate::gpu::pipeline::{DepthBound, array_view, buffer, compute_pipeline, render_pipeline};
use crate::gpu::{GpuTimer, Targets};
use crate::plants::shadow::{CANOPY_BANDS, CanopyDepth};
use crate::stream::TileAtlas;
use crate::world::{Manifest, Pyramid, Sky, TileId};

pub mod contact_shadow;
pub mod contact_shadow_cpu;
pub mod far_field;
pub mod material;

/// Colour target format of the headless tools and the reference images (any format of
/// [`crate::shaders::encode_srgb_for`] works).
pub const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
/// Depth format of the headless tools (reverse-Z: cleared to 0, greater is nearer).
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// How many grass types the shader's colour table holds.
pub const MAX_GRASS_TYPES: usize = 16;

/// Format of the G-buffer: per pixel the atlas texel (x, y, 8.8 fixed point), the slot, the
/// drawn tile's level and metres per texel (half float), packed into two words (see
/// `fs_gbuffer` in `shaders/terrain_gbuffer.wgsl`). Eight bytes a pixel, not sixteen: on GPUs whose
/// raster units are few, the G-buffer's bytes are much of the terrain pass's time.
pub const GBUFFER_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rg32Uint;
/// Atlas slots the G-buffer can name (12 bits).
pub const GBUFFER_MAX_SLOTS: u32 = 4096;
/// Format of the shaded colour (linear) that the composite pass copies into the colour target.
pub const SHADED_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

/// Bytes of the terrain's internal textures (G-buffer and shaded colour) for a `width` x
/// `height` target.
pub fn deferred_bytes(width: u32, height: u32) -> u64 {
    let per_pixel = GBUFFER_FORMAT.block_copy_size(None).unwrap_or(16)
        + SHADED_FORMAT.block_copy_size(None).unwrap_or(8);
    u64::from(width) * u64::from(height) * u64::from(per_pixel)
}

/// Per-frame uniforms; mirrors `Frame` in `shaders/shared/terrain_shading.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct FrameUniforms {
    view_proj: [[f32; 4]; 4],
    inv_view_proj: [[f32; 4]; 4],
    camera: [f32; 4],
    sun_dir: [f32; 4],
    sun_color: [f32; 4],
    sky_color: [f32; 4],
    horizon_color: [f32; 4],
    grid: [u32; 4],
    ground_colors: [[f32; 4]; MAX_GRASS_TYPES],
    overlay: [f32; 4],
    camera_world: [f32; 4],
    grass_view: [f32; 4],
    clump: [u32; 4],
    clump_offset: [f32; 4],
    base_colors: [[f32; 4]; MAX_GRASS_TYPES],
    tip_colors: [[f32; 4]; MAX_GRASS_TYPES],
    roots: [u32; 4],
    root_slots: [[u32; 4]; MAX_ROOT_TILES / 4],
    canopy: [[f32; 4]; MAX_GRASS_TYPES / 4 * CANOPY_BANDS],
    canopy_fade: [f32; 4],
    canopy_edges: [[f32; 4]; CANOPY_BANDS / 4],
}
const _: () = assert!(std::mem::size_of::<FrameUniforms>() == 1904);

/// Most root (level-0) tiles whose heights the long shadow rays march over; a world with more
/// has terrain shadows from each tile's own heights only.
pub const MAX_ROOT_TILES: usize = 64;

/// One tile (or the part of an ancestor standing in for it) to draw; mirrors `TileDraw` in
/// `shaders/terrain_gbuffer.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct TileDraw {
    /// South-west corner of the drawn area relative to the camera, metres.
    pub origin: [f32; 2],
    /// Metres between grid vertices.
    pub cell_size: f32,
    /// Atlas slot the data comes from.
    pub layer: u32,
    /// Atlas texel at the drawn area's south-west corner.
    pub tex_origin: [f32; 2],
    /// Atlas texels per grid cell (1, or 1/2^k for an ancestor k levels up).
    pub tex_step: f32,
    /// Distance at which morphing toward the coarser grid starts, metres.
    pub morph_start: f32,
}
const _: () = assert!(std::mem::size_of::<TileDraw>() == 32);

impl TileDraw {
    /// The draw of the tile `id`, whose data sits in atlas slot `layer` and belongs to the tile
    /// `source` (`id` itself, or an ancestor standing in for it), seen from `eye`, with a grid
    /// vertex every `mesh_step` samples. Positions are made relative to the eye in f64, so the
    /// f32 that reaches the GPU is small.
    pub fn new(
        pyramid: &Pyramid,
        id: TileId,
        source: TileId,
        layer: u32,
        eye: DVec2,
        morph_start: f32,
        mesh_step: u32,
    ) -> Self {
        let b = pyramid.bounds(id);
        let rel = (b.min - eye).as_vec2();
        let up = u32::from(id.level.saturating_sub(source.level));
        let scale = 1.0 / f64::from(1u32 << up);
        // Offset of `id` inside `source`, in source cells.
        let n = f64::from(pyramid.tile_cells);
        let (fx, fy) = (
            f64::from(id.x) * scale - f64::from(source.x),
            f64::from(id.y) * scale - f64::from(source.y),
        );
        let border = f64::from(pyramid.border);
        Self {
            origin: rel.to_array(),
            cell_size: (pyramid.cell_size_m(id.level) * f64::from(mesh_step)) as f32,
            layer,
            tex_origin: [(border + fx * n) as f32, (border + fy * n) as f32],
            tex_step: (scale * f64::from(mesh_step)) as f32,
            morph_start,
        }
    }
}

/// Unit vector toward the sun; the manifest's azimuth runs counter-clockwise from east.
pub fn sun_direction(sky: &Sky) -> Vec3 {
    let (az, el) = (
        sky.sun_azimuth_deg.to_radians(),
        sky.sun_elevation_deg.to_radians(),
    );
    Vec3::new(az.cos() * el.cos(), az.sin() * el.cos(), el.sin()).normalize()
}

/// The internal textures of the deferred shading, at the targets' size.
struct Deferred {
    gbuffer: wgpu::TextureView,
    shaded: wgpu::TextureView,
    composite: wgpu::BindGroup,
}

impl Deferred {
    fn new(device: &wgpu::Device, layout: &wgpu::BindGroupLayout, size: (u32, u32)) -> Self {
        let usage = wgpu::TextureUsages::TEXTURE_BINDING;
        let gbuffer = crate::gpu::target_texture(
            device,
            "terrain G-buffer",
            GBUFFER_FORMAT,
            usage | wgpu::TextureUsages::RENDER_ATTACHMENT,
            size,
        );
        let shaded = crate::gpu::target_texture(
            device,
            "terrain shaded",
            SHADED_FORMAT,
            usage | wgpu::TextureUsages::STORAGE_BINDING,
            size,
        );
        let shaded = shaded.create_view(&Default::default());
        let composite = bind_group(device, "composite", layout, [view(&shaded)]);
        Self {
            gbuffer: gbuffer.create_view(&Default::default()),
            shaded,
            composite,
        }
    }
}

/// Pipelines, buffers and internal textures of the terrain and sky passes.
pub struct TerrainRenderer {
    gbuffer: wgpu::RenderPipeline,
    shade: wgpu::ComputePipeline,
    shade_layout: wgpu::BindGroupLayout,
    composite: wgpu::RenderPipeline,
    composite_layout: wgpu::BindGroupLayout,
    deferred: Deferred,
    /// The shading pass's bind group for the last depth texture, made again only when it
    /// changes (or the targets are resized).
    shade_bound: DepthBound,
    heights_view: wgpu::TextureView,
    grass_view: wgpu::TextureView,
    bind_group: wgpu::BindGroup,
    frame_buffer: wgpu::Buffer,
    tile_buffer: wgpu::Buffer,
    index_buffer: wgpu::Buffer,
    index_count: u32,
    max_tiles: u32,
    uniforms: FrameUniforms,
    clump_m: f64,
    /// Each grass type's blade area index at one blade a square metre.
    blade_area: [f32; MAX_GRASS_TYPES],
}

impl TerrainRenderer {
    /// Builds the pipelines for `manifest`'s world, reading tiles from `atlas`; at most
    /// `max_tiles` tiles are drawn a frame, each a grid with a vertex every `mesh_step` samples
    /// (a power of two that divides the tile's cells).
    pub fn new(
        device: &wgpu::Device,
        manifest: &Manifest,
        atlas: &TileAtlas,
        targets: &Targets,
        max_tiles: u32,
        mesh_step: u32,
    ) -> Self {
        let module = crate::shaders::module(device, "terrain_gbuffer.wgsl");
        use wgpu::BufferUsages as U;
        let frame_buffer = buffer(
            device,
            "terrain frame",
            std::mem::size_of::<FrameUniforms>() as u64,
            U::UNIFORM | U::COPY_DST,
        );
        let tile_buffer = buffer(
            device,
            "terrain tiles",
            u64::from(max_tiles) * std::mem::size_of::<TileDraw>() as u64,
            U::STORAGE | U::COPY_DST,
        );
        let n = manifest.pyramid.tile_cells / mesh_step.clamp(1, manifest.pyramid.tile_cells);
        let indices = grid_indices(n + 3);
        let index_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("terrain grid indices"),
            contents: bytemuck::cast_slice(&indices),
            usage: U::INDEX,
        });

        let layout = bind_group_layout(
            device,
            "terrain",
            &sequential(
                wgpu::ShaderStages::VERTEX_FRAGMENT,
                [
                    uniform_buffer(),
                    storage_buffer_read_only().visible_in(wgpu::ShaderStages::VERTEX),
                    texture_2d_array(UNFILTERABLE_FLOAT),
                    texture_2d_array(wgpu::TextureSampleType::Uint),
                ],
            ),
        );
        let (hv, gv) = (array_view(&atlas.heights), array_view(&atlas.grass));
        let bind_group = bind_group(
            device,
            "terrain",
            &layout,
            [
                frame_buffer.as_entire_binding(),
                tile_buffer.as_entire_binding(),
                view(&hv),
                view(&gv),
            ],
        );
        // The G-buffer and the depth in one pass (the depth then feeds the Hi-Z pyramid): a
        // G-buffer texel costs little more than a depth-only one, a second pass of the mesh
        // more.
        let gbuffer = render_pipeline(
            "terrain",
            &module,
            ("vs_terrain", "fs_gbuffer"),
            GBUFFER_FORMAT,
        )
        .layouts(&[&layout])
        .cull_back()
        .depth(targets.depth_format, true, wgpu::CompareFunction::Greater)
        .build(device);

        // The shading: a compute pass over the target (terrain and sky).
        let shade_module = crate::shaders::module(device, "terrain_shade.wgsl");
        let shade_layout = bind_group_layout(
            device,
            "terrain shade",
            &with_indices(
                wgpu::ShaderStages::COMPUTE,
                [
                    (0, uniform_buffer()),
                    (2, texture_2d_array(UNFILTERABLE_FLOAT)),
                    (3, texture_2d_array(wgpu::TextureSampleType::Uint)),
                    (4, texture_depth_2d()),
                    (5, texture_2d(wgpu::TextureSampleType::Uint)),
                    (6, texture_storage_2d(SHADED_FORMAT)),
                ],
            ),
        );
        let shade = compute_pipeline(
            device,
            "terrain shade",
            &shade_module,
            "cs_shade",
            &[&shade_layout],
        );

        // The composite: the shaded colour into the caller's target.
        let composite_module = crate::shaders::module(device, "terrain_composite.wgsl");
        let composite_layout = bind_group_layout(
            device,
            "composite",
            &sequential(
                wgpu::ShaderStages::FRAGMENT,
                [texture_2d(UNFILTERABLE_FLOAT)],
            ),
        );
        let fs_constants = [("ENCODE_SRGB", targets.encode_srgb())];
        let composite = render_pipeline(
            "composite",
            &composite_module,
            ("vs_full", "fs_composite"),
            targets.color_format,
        )
        .layouts(&[&composite_layout])
        .constants(&[], &fs_constants)
        .build(device);
        let deferred = Deferred::new(device, &composite_layout, (targets.width, targets.height));

        let mut ground_colors = [[0.0; 4]; MAX_GRASS_TYPES];
        let mut base_colors = [[0.0; 4]; MAX_GRASS_TYPES];
        let mut tip_colors = [[0.0; 4]; MAX_GRASS_TYPES];
        // Each type's blade area at one blade a square metre (see `set_blade_density`).
        let mut blade_area = [0.0; MAX_GRASS_TYPES];
        for (i, t) in manifest
            .grass_types
            .iter()
            .take(MAX_GRASS_TYPES)
            .enumerate()
        {
            let c = t.ground_color;
            ground_colors[i] = [c[0], c[1], c[2], 1.0];
            let (b, tip) = (t.base_color, t.tip_color);
            base_colors[i] = [b[0], b[1], b[2], far_field::growth_blend(t.stiffness)];
            blade_area[i] = far_field::blade_area_index(t.width_m, t.height_m, 1.0, 1.0);
            tip_colors[i] = [tip[0], tip[1], tip[2], 0.0];
        }
        let roots = manifest.pyramid.root_tiles;
        let root_cell = manifest.pyramid.cell_size_m(0) as f32;
        let sky_cfg = &manifest.sky;
        // Manifest colours are linear RGB.
        let lin4 = |c: [f32; 3]| [c[0], c[1], c[2], 1.0];
        let uniforms = FrameUniforms {
            view_proj: Mat4::IDENTITY.to_cols_array_2d(),
            inv_view_proj: Mat4::IDENTITY.to_cols_array_2d(),
            camera: [0.0, sky_cfg.fog_distance_m, 2.0, 0.0],
            sun_dir: sun_direction(sky_cfg).extend(0.0).to_array(),
            sun_color: lin4(sky_cfg.sun_color),
            sky_color: lin4(sky_cfg.sky_color),
            horizon_color: lin4(sky_cfg.horizon_color),
            grid: [
                n,
                manifest.pyramid.border,
                manifest.grass_types.len().clamp(1, MAX_GRASS_TYPES) as u32,
                crate::features::Features::all().bits(),
            ],
            ground_colors,
            overlay: [
                0.0,
                0.0,
                0.0,
                (manifest.pyramid.cell_size_m(0) * f64::from(mesh_step)) as f32,
            ],
            camera_world: [0.0; 4],
            grass_view: [0.0; 4],
            clump: [0, 0, 0, 1.0f32.to_bits()],
            // z: 1 where the far field lies under the blades too, 0 where only past their fade;
            // w: the grass fade's metres per metre the camera stands above.
            clump_offset: [0.0, 0.0, 1.0, far_field::ELEVATION_DISTANCE],
            base_colors,
            tip_colors,
            roots: [roots[0], roots[1], root_cell.to_bits(), 0],
            root_slots: [[0; 4]; MAX_ROOT_TILES / 4],
            canopy: [[0.0; 4]; MAX_GRASS_TYPES / 4 * CANOPY_BANDS],
            canopy_fade: [0.0; 4],
            canopy_edges: [[f32::MAX; 4]; CANOPY_BANDS / 4],
        };
        let mut terrain = Self {
            gbuffer,
            shade,
            shade_layout,
            composite,
            composite_layout,
            deferred,
            shade_bound: DepthBound::default(),
            heights_view: hv,
            grass_view: gv,
            bind_group,
            frame_buffer,
            tile_buffer,
            index_buffer,
            index_count: indices.len() as u32,
            max_tiles,
            uniforms,
            clump_m: 1.0,
            blade_area,
        };
        // The default grid's until the grass's settings come.
        terrain.set_blade_density(
            crate::grass::DEFAULT_SPACING_M,
            crate::grass::DEFAULT_WIDTH_SCALE,
        );
        terrain
    }

    /// Puts each grass type's blade area index at full density into the tip colours' w: its
    /// blade area at one blade a square metre times the blades a square metre of the grid
    /// spaced and widened as `spacing_m` and `width_scale` say.
    fn set_blade_density(&mut self, spacing_m: f32, width_scale: f32) {
        let density = width_scale / (spacing_m * spacing_m).max(1e-6);
        for (tip, area) in self.uniforms.tip_colors.iter_mut().zip(self.blade_area) {
            tip[3] = area * density;
        }
    }

    /// Sets what the far field shows of the grass: the dithered fade to the view distance, the
    /// clump cells and seed of `settings`, the blades' area a square metre of ground (their
    /// spacing and width), and whether it lies under the blades; `None` (no grass drawn) shows
    /// the far field everywhere.
    pub fn set_grass(&mut self, settings: Option<&crate::grass::GrassSettings>) {
        match settings {
            Some(g) => {
                self.uniforms.grass_view[2] = g.view_distance_m - g.far_fade_m;
                self.uniforms.grass_view[3] = g.view_distance_m;
                self.uniforms.clump[2] = g.seed;
                self.uniforms.clump[3] = g.clump_m.to_bits();
                self.uniforms.clump_offset[2] = if g.far_field_under_blades { 1.0 } else { 0.0 };
                self.uniforms.clump_offset[3] = g.elevation_fade;
                self.clump_m = f64::from(g.clump_m);
                self.set_blade_density(g.spacing_m, g.width_scale);
            }
            None => {
                self.uniforms.grass_view[2] = 0.0;
                self.uniforms.grass_view[3] = 0.0;
                self.uniforms.clump_offset[2] = 1.0;
            }
        }
    }

    /// Sets the atlas slots of the root (level-0) tiles, `slots[y * root_tiles_x + x]`, over
    /// which long shadow rays march; `None` (a root tile not resident, or more than
    /// [`MAX_ROOT_TILES`]) leaves shadows to each tile's own heights.
    pub fn set_root_slots(&mut self, slots: Option<&[u32]>) {
        let n = (self.uniforms.roots[0] * self.uniforms.roots[1]) as usize;
        match slots {
            Some(s) if s.len() == n && n <= MAX_ROOT_TILES => {
                for (i, &slot) in s.iter().enumerate() {
                    self.uniforms.root_slots[i / 4][i % 4] = slot;
                }
                self.uniforms.roots[3] = 1;
            }
            _ => self.uniforms.roots[3] = 0,
        }
    }

    /// The trees' canopy over the ground beyond their shadow map: per band of altitude and
    /// grass type, the depth `tau` of the canopy's shade at full grass density (see
    /// [`crate::plants::shadow::canopy_depth`]), faded in between `fade` metres (the shadow
    /// map's fade-out); all zero: none.
    pub fn set_canopy(&mut self, tau: &CanopyDepth, fade: [f32; 2]) {
        for (band, row) in tau.depth.iter().enumerate() {
            for (g, t) in row.iter().enumerate() {
                self.uniforms.canopy[band * MAX_GRASS_TYPES / 4 + g / 4][g % 4] = *t;
            }
        }
        // The last of the uniform's edges is never used: it stays huge.
        for (i, e) in tau.edges.iter().enumerate() {
            self.uniforms.canopy_edges[i / 4][i % 4] = *e;
        }
        let on = tau.any();
        self.uniforms.canopy_fade = [fade[0], fade[1], f32::from(u8::from(on)), 0.0];
    }

    /// Sets the switched-on features (the terrain reads ground darkening, the far field and
    /// shadows).
    pub fn set_features(&mut self, features: crate::features::Features) {
        self.uniforms.grid[3] = features.bits();
    }

    /// Shows (or hides) the overlay: each tile tinted by its level, and circles at the grass
    /// rings' radii (metres; 0 for none) around the camera.
    pub fn set_overlay(&mut self, on: bool, ring_radii_m: [f32; 2]) {
        self.uniforms.overlay[0] = if on { 1.0 } else { 0.0 };
        self.uniforms.overlay[1] = ring_radii_m[0];
        self.uniforms.overlay[2] = ring_radii_m[1];
    }

    /// The G-buffer's view: a render target of the targets' size (the renderer checks a
    /// caller's view against it).
    pub fn gbuffer_view(&self) -> &wgpu::TextureView {
        &self.deferred.gbuffer
    }

    /// Most tiles a frame can draw.
    pub fn max_tiles(&self) -> u32 {
        self.max_tiles
    }

    /// Writes this frame's camera and tile list. Returns how many tiles will be drawn
    /// (`draws` past `max_tiles` are dropped).
    pub fn prepare(
        &mut self,
        queue: &wgpu::Queue,
        view_proj: Mat4,
        eye: DVec3,
        draws: &[TileDraw],
    ) -> u32 {
        self.uniforms.view_proj = view_proj.to_cols_array_2d();
        self.uniforms.inv_view_proj = view_proj.inverse().to_cols_array_2d();
        self.uniforms.camera[0] = eye.z as f32;
        let p = eye;
        self.uniforms.camera_world = [p.x as f32, p.y as f32, p.z as f32, 0.0];
        self.uniforms.grass_view[0] = p.x.rem_euclid(4096.0) as f32;
        self.uniforms.grass_view[1] = p.y.rem_euclid(4096.0) as f32;
        let (cx, cy) = ((p.x / self.clump_m).floor(), (p.y / self.clump_m).floor());
        self.uniforms.clump[0] = (cx as i32) as u32;
        self.uniforms.clump[1] = (cy as i32) as u32;
        self.uniforms.clump_offset[0] = (p.x - cx * self.clump_m) as f32;
        self.uniforms.clump_offset[1] = (p.y - cy * self.clump_m) as f32;
        queue.write_buffer(&self.frame_buffer, 0, bytemuck::bytes_of(&self.uniforms));
        let n = draws.len().min(self.max_tiles as usize);
        if n > 0 {
            queue.write_buffer(&self.tile_buffer, 0, bytemuck::cast_slice(&draws[..n]));
        }
        n as u32
    }

    /// Follows a resize of the targets: the internal textures at the new size.
    pub fn resize(&mut self, device: &wgpu::Device, width: u32, height: u32) {
        self.deferred = Deferred::new(device, &self.composite_layout, (width, height));
        self.shade_bound.clear();
    }

    /// Records the terrain's G-buffer pass (`terrain`): clears `depth` and writes the terrain's
    /// depth and, per pixel, where in the atlas its ground lies (see [`Self::record_shade`]).
    pub fn record_gbuffer(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        depth: &wgpu::TextureView,
        tiles: u32,
        timer: &mut GpuTimer,
    ) {
        {
            let mut pass = render_pass(
                encoder,
                "terrain",
                (
                    &self.deferred.gbuffer,
                    wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                ),
                Some((depth, wgpu::LoadOp::Clear(0.0))),
                timer.render_pass("terrain"),
            );
            if tiles > 0 {
                pass.set_bind_group(0, &self.bind_group, &[]);
                pass.set_pipeline(&self.gbuffer);
                pass.set_index_buffer(self.index_buffer.slice(..), wgpu::IndexFormat::Uint32);
                pass.draw_indexed(0..self.index_count, 0, 0..tiles);
            }
        }
    }

    /// Records the terrain's and the sky's colour into `color` from the G-buffer and the depth
    /// of [`Self::record_gbuffer`] (in `depth`, which it does not write): the shading of every
    /// pixel (compute, `terrain_shade`) and its composite into `color` (`composite`), which it
    /// overwrites.
    pub fn record_shade(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        timer: &mut GpuTimer,
    ) {
        let group = self.shade_bound.get(depth, |depth| {
            bind_group_with_indices(
                device,
                "terrain shade",
                &self.shade_layout,
                [
                    (0, self.frame_buffer.as_entire_binding()),
                    (2, view(&self.heights_view)),
                    (3, view(&self.grass_view)),
                    (4, view(depth)),
                    (5, view(&self.deferred.gbuffer)),
                    (6, view(&self.deferred.shaded)),
                ],
            )
        });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("terrain shade"),
                timestamp_writes: timer.compute_pass("terrain_shade"),
            });
            // The targets' size (the caller's depth may be a view of one level of a larger
            // texture).
            let size = self.deferred.gbuffer.texture().size();
            pass.set_pipeline(&self.shade);
            pass.set_bind_group(0, group, &[]);
            pass.dispatch_workgroups(size.width.div_ceil(8), size.height.div_ceil(8), 1);
        }
        let mut pass = render_pass(
            encoder,
            "composite",
            (color, wgpu::LoadOp::Clear(wgpu::Color::BLACK)),
            None,
            timer.render_pass("composite"),
        );
        pass.set_pipeline(&self.composite);
        pass.set_bind_group(0, &self.deferred.composite, &[]);
        pass.draw(0..3, 0..1);
    }
}

/// Triangle indices of a `row` x `row` vertex grid, counter-clockwise seen from above.
fn grid_indices(row: u32) -> Vec<u32> {
    let mut out = Vec::with_capacity(((row - 1) * (row - 1) * 6) as usize);
    for j in 0..row - 1 {
        for i in 0..row - 1 {
            let a = j * row + i;
            let (b, c, d) = (a + 1, a + row, a + row + 1);
            out.extend_from_slice(&[a, b, d, a, d, c]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_triangles_face_up() {
        let idx = grid_indices(3);
        assert_eq!(idx.len(), 2 * 2 * 6);
        let pos = |v: u32| Vec3::new((v % 3) as f32, (v / 3) as f32, 0.0);
        for tri in idx.chunks(3) {
            let (a, b, c) = (pos(tri[0]), pos(tri[1]), pos(tri[2]));
            assert!((b - a).cross(c - a).z > 0.0);
        }
    }

    fn pyramid() -> Pyramid {
        Pyramid {
            root_tile_size_m: 65536.0,
            root_tiles: [1024, 1],
            tile_cells: 64,
            border: 2,
            stored_levels: 4,
            derived_levels: 0,
        }
    }

    #[test]
    fn camera_relative_origin_keeps_precision_far_from_the_world_origin() {
        let p = pyramid();
        let id = TileId::new(0, 600, 0);
        let eye = DVec2::new(600.0 * 65536.0 - 99.75, 7.5);
        let d = TileDraw::new(&p, id, id, 3, eye, 100.0, 1);
        assert_eq!(d.origin, [99.75, -7.5]);
        assert_eq!((d.tex_origin, d.tex_step, d.layer), ([2.0, 2.0], 1.0, 3));
    }

    #[test]
    fn an_ancestor_stands_in_with_the_right_texels() {
        let p = pyramid();
        let id = TileId::new(2, 3, 1); // level-0 tile (0, 0), quarter (3, 1) of 4x4
        let d = TileDraw::new(&p, id, TileId::new(0, 0, 0), 0, DVec2::ZERO, 100.0, 1);
        assert_eq!(d.tex_step, 0.25);
        assert_eq!(d.tex_origin, [2.0 + 48.0, 2.0 + 16.0]);
        assert_eq!(d.cell_size, (65536.0 / 4.0 / 64.0) as f32);
        let coarse = TileDraw::new(&p, id, TileId::new(0, 0, 0), 0, DVec2::ZERO, 100.0, 2);
        assert_eq!((coarse.tex_step, coarse.tex_origin), (0.5, d.tex_origin));
        assert_eq!(coarse.cell_size, 2.0 * d.cell_size);
    }
}
