//! The plant stage on the GPU: the bounded instance pool (a region of fixed capacity per plant
//! type and level of detail), placement and culling per grass tile in compute
//! (`shaders/plants_place.wgsl`) and one indexed indirect draw per region
//! (`shaders/plants_draw.wgsl`), culled against the grass's Hi-Z pyramid and bent by the grass's
//! wind field. The pool's size is fixed when the stage is made, whatever the view: a region whose
//! plants wanted more than [fits](crate::plants::place_cpu::crowd_fill) in one frame thins them
//! from a distance in the next ([`crate::plants::place_cpu::crowd_distances`]: the nearest all
//! kept, the farther ones by their own numbers, the same plants frame after frame, grown to keep
//! the cover), after a cut measuring first ([`PlantRenderer::set_cut`]); a region that fills up
//! all the same drops the rest of its plants and counts them as overflow.

use bytemuck::{Pod, Zeroable};
use glam::Mat4;

use crate::gpu::layout::*;
use crate::gpu::pass::render_pass;
use crate::gpu::pipeline::{array_view, buffer as gpu_buffer};
use crate::gpu::{GpuTimer, Targets};
use crate::grass::renderer::hiz_levels;
use crate::grass::{HiZPyramid, TileJob};
use crate::lod::Frustum;
use crate::plants::bend_cpu::PlantWindGpu;
use crate::plants::draw::DrawPass;
use crate::plants::place::PlacePass;
use crate::plants::place_cpu::{
    CROWD_BINS, LEVELS, PlaceParams, PlantInstance, PlantJob, PlantTypeGpu, REGIONS, TYPES,
    UNCROWDED, counter,
};
use crate::plants::set::{PlantSet, TEXTURE_SIZE, mips};
use crate::stream::TileAtlas;
use crate::terrain::sun_direction;
use crate::world::Manifest;

/// Bytes of an instance.
const INSTANCE_BYTES: u64 = std::mem::size_of::<PlantInstance>() as u64;
/// Grass tiles a frame places plants on at most (the job buffer's size).
pub const MAX_JOBS: u32 = 1024;

/// Largest instance pool of one plant stage, bytes: a storage buffer bound whole, within the
/// 128 MiB every wgpu device binds.
pub const MAX_POOL_BYTES: u64 = 128 << 20;

/// The most instances a (type, level) region of a pool for `types` plant types can hold within
/// [`MAX_POOL_BYTES`] (a multiple of 8). A stage asked for more gets this many.
pub fn max_capacity(types: u32) -> u32 {
    let regions = u64::from(types.max(1)) * LEVELS as u64;
    let most = MAX_POOL_BYTES / (regions * INSTANCE_BYTES);
    (most.min(u64::from(u32::MAX)) as u32) / 8 * 8
}

/// Which of a world's plant types a plant stage draws.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlantLayer {
    /// The plants among the grass (lower than [`crate::world::TREE_MIN_HEIGHT_M`]).
    Plants,
    /// The trees, placed on a coarser grid out to the fog.
    Trees,
}

impl PlantLayer {
    /// Whether the layer draws `t`.
    pub fn includes(self, t: &crate::world::PlantType) -> bool {
        t.is_tree() == (self == PlantLayer::Trees)
    }

    /// The indices of `manifest`'s plant types the layer draws (at most [`TYPES`]).
    pub fn types(self, manifest: &Manifest) -> Vec<usize> {
        manifest
            .plant_types
            .iter()
            .enumerate()
            .filter(|(_, t)| self.includes(t))
            .map(|(i, _)| i)
            .take(TYPES)
            .collect()
    }

    /// The names of its passes' timings: placement, draw.
    pub fn pass_names(self) -> [&'static str; 2] {
        match self {
            PlantLayer::Plants => ["plants_place", "plants_draw"],
            PlantLayer::Trees => ["trees_place", "trees_draw"],
        }
    }

    /// The feature that switches it on.
    pub fn feature(self) -> crate::features::Feature {
        match self {
            PlantLayer::Plants => crate::features::Feature::Plants,
            PlantLayer::Trees => crate::features::Feature::Trees,
        }
    }
}

/// Settings of the plant stage.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlantSettings {
    /// Instances each (type, level of detail) region holds.
    pub capacity: u32,
    /// Distances of the switches from the full mesh to the reduced one and from that to the
    /// cards, metres.
    pub lod_m: [f32; 2],
    /// Width of the dithered cross-fade band around each switch, metres.
    pub band_m: f32,
    /// The start of the thinning before the view distance, and the view distance (the grass's),
    /// metres: the grass tiles' jobs hand their plants over to the far jobs there.
    pub view_m: [f32; 2],
    /// How far the far jobs' plants (cards by default) reach, in view distances: they thin out
    /// from the view distance to this many times it (1: none beyond the view distance).
    pub card_reach: f32,
    /// Beyond this distance (metres) plants thin out as the square of the distance, down to
    /// half of them ([`crate::plants::place_cpu::MIN_KEEP`]), each survivor grown to keep the
    /// cover: a few pixels each there, they cost the draw per plant, not per pixel.
    pub thin_m: f32,
    /// The fewest plants that thinning keeps (0 < `min_keep` <= 1): each survivor grows by at
    /// most one over its square root.
    pub min_keep: f32,
    /// Edge of a cell of the placement grid, metres (each holds at most one plant); it must
    /// divide the grass tile's edge.
    pub cell_m: f32,
    /// Seed of the placement's hashes.
    pub seed: u32,
}

impl Default for PlantSettings {
    fn default() -> Self {
        Self {
            capacity: 16_384,
            lod_m: [25.0, 150.0],
            band_m: 4.0,
            view_m: [120.0, 150.0],
            card_reach: 2.0,
            thin_m: 50.0,
            min_keep: crate::plants::place_cpu::MIN_KEEP,
            cell_m: crate::plants::PLANT_CELL_M,
            seed: 7,
        }
    }
}

impl PlantSettings {
    /// The trees' defaults for grass tiles of `tile_m` metres and fog at `fog_m`: cells of
    /// about [`TREE_CELL_M`] (dividing the tile), the full mesh to 60 m, the reduced one to
    /// 300 m, cards to the fog (thinning out over its last tenth); beyond [`TREE_THIN_M`] a tree
    /// is kept with a chance falling as the square of the distance, to no fewer than one in six,
    /// each grown to keep the forest's cover.
    pub fn trees(tile_m: f32, fog_m: f32) -> Self {
        let per_tile = (tile_m / TREE_CELL_M).round().max(1.0);
        Self {
            capacity: 262_144,
            // Against the truth's meshes, switches at 30/150 m erred 15% more in bench lod's
            // views (a valley oak 30-60 m away drawn as one leaf in eight) for no measurable
            // time (docs/anti-aliasing.md, "The skyline's trees").
            lod_m: [60.0, 300.0],
            band_m: 10.0,
            view_m: [0.9 * fog_m, fog_m],
            card_reach: 1.0,
            thin_m: TREE_THIN_M,
            min_keep: 1.0 / 6.0,
            cell_m: tile_m / per_tile,
            seed: 7,
        }
    }
}

/// Where the trees start to thin out with distance by default, metres. Measured against the truth
/// (every tree out to 1,000 m, none thinned): thinning from 400 m grew the skyline's few kept oaks
/// up to 2.4 times their size, a row of large dark crowns where the truth has many small ones; from
/// 800 m the default frame supersampled erred 15% less on the meadow for the same median GPU time
/// (see docs/anti-aliasing.md, "The skyline's trees"), and from 1,600 m the temporal frame errs
/// 1.9-2.3% less along the three paths at 960x540 and 1920x1080 for 0.06 ms more on the tour's mean
/// frame, none on the meadow's (docs/anti-aliasing.md, "The skyline's trees, thinned from 1,600
/// m").
pub const TREE_THIN_M: f32 = 1600.0;

/// The trees' placement cell, metres (about: [`PlantSettings::trees`] rounds it to divide the
/// grass tile).
pub const TREE_CELL_M: f32 = 5.0;
/// Most cells along the edge of a tree job: a coarser terrain tile is split into jobs of at
/// most this many cells a side.
pub const MAX_TREE_JOB_CELLS: u32 = 96;

/// Plant GPU figures of one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PlantStats {
    /// Placement cells looked at.
    pub considered: u32,
    /// Cells without a plant.
    pub empty: u32,
    /// Plants ruled out by slope or altitude.
    pub ruled_out: u32,
    /// Plants thinned toward the view distance.
    pub culled_distance: u32,
    /// Plants outside the frustum.
    pub culled_frustum: u32,
    /// Plants behind the terrain.
    pub culled_occlusion: u32,
    /// Instances that did not fit their region.
    pub overflow: u32,
    /// Instances drawn (a plant in a cross-fade counts twice).
    pub drawn: u32,
    /// Instances thinned out because their region was crowded the frame before (a plant in a
    /// cross-fade counts twice, as in `drawn`).
    #[serde(default)]
    pub crowded: u32,
    /// Triangles the draws draw: each (type, level)'s instances times its mesh's triangles.
    #[serde(default)]
    pub triangles: u64,
}

impl PlantStats {
    /// The figures from the counters of `shaders/plants_place.wgsl` (no triangles: see
    /// [`PlantStats::with_draws`]).
    pub fn from_counts(c: &[u32; counter::COUNT]) -> Self {
        Self {
            considered: c[counter::CONSIDERED],
            empty: c[counter::EMPTY],
            ruled_out: c[counter::RULED_OUT],
            culled_distance: c[counter::DISTANCE],
            culled_frustum: c[counter::FRUSTUM],
            culled_occlusion: c[counter::OCCLUSION],
            overflow: c[counter::OVERFLOW],
            drawn: c[counter::DRAWN],
            crowded: c[counter::CROWDED],
            triangles: 0,
        }
    }

    /// These figures with the triangles of the draws `args` (the indexed indirect draws of
    /// [`PlantRenderer::args_buffer`], 5 u32 each: index count, instances, ...).
    pub fn with_draws(self, args: &[u32]) -> Self {
        let triangles = args
            .chunks_exact(5)
            .map(|a| u64::from(a[0] / 3) * u64::from(a[1]))
            .sum();
        Self { triangles, ..self }
    }
}

/// Bytes of a plant stage's draw arguments ([`PlantRenderer::args_buffer`]).
pub const ARGS_BYTES: u64 = REGIONS as u64 * 20;
/// How far the camera moves between frames, metres, or turns, degrees, for the plant stages to
/// take the frame as a cut ([`is_cut`]): the temporal anti-aliasing's defaults.
pub const CUT_DISTANCE_M: f64 = 20.0;
/// See [`CUT_DISTANCE_M`].
pub const CUT_ANGLE_DEG: f64 = 30.0;

/// Whether a camera at `eye` looking along `forward` (unit) starts afresh from the last frame's,
/// `last` (none: the first frame): moved more than [`CUT_DISTANCE_M`] or turned more than
/// [`CUT_ANGLE_DEG`]. After a cut the plant stages measure how crowded each region is before
/// they place ([`PlantRenderer::set_cut`]), where the last frame's figures say nothing of this
/// view.
pub fn is_cut(
    last: Option<(glam::DVec3, glam::DVec3)>,
    eye: glam::DVec3,
    forward: glam::DVec3,
) -> bool {
    last.is_none_or(|(last_eye, last_forward)| {
        let angle = last_forward
            .dot(forward)
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees();
        eye.distance(last_eye) > CUT_DISTANCE_M || angle > CUT_ANGLE_DEG
    })
}

/// Bytes of a plant stage's counters ([`PlantRenderer::stats_buffer`]).
pub const STATS_BYTES: u64 = counter::COUNT as u64 * 4;
/// Bytes of the per-region counters that a frame starts from zero (appended, and wanted by
/// distance); the distances from which crowded regions thin follow them and carry over to the
/// next frame.
const REGION_COUNTER_BYTES: u64 = (REGIONS + REGIONS * CROWD_BINS) as u64 * 4;

/// The draw's frame constants; mirrors `PlantFrame` in the shader.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct PlantFrame {
    view_proj: [[f32; 4]; 4],
    misc: [f32; 4],
    sun_dir: [f32; 4],
    sun_color: [f32; 4],
    sky_color: [f32; 4],
    horizon_color: [f32; 4],
    flags: [u32; 4],
    wind: [PlantWindGpu; TYPES],
    layers: [[u32; 4]; TYPES],
}
const _: () = assert!(std::mem::size_of::<PlantFrame>() == 64 + 96 + 256 + 128);

/// The wind buffers the plants bend in.
#[derive(Clone, Copy)]
pub struct PlantWindBindings<'a> {
    /// The wind field's `WindLookup` uniform.
    pub lookup: &'a wgpu::Buffer,
    /// The wind field's cells.
    pub cells: &'a wgpu::Buffer,
    /// The sway springs' state (`crate::wind::SwayField::buffer`), whose slots after
    /// [`crate::wind::GRASS_SWAY_TYPES`] are the plant types'.
    pub sway: &'a wgpu::Buffer,
}

/// Pipelines, meshes, textures and the instance pool of the plant stage.
pub struct PlantRenderer {
    layer: PlantLayer,
    settings: PlantSettings,
    types: u32,
    place_pass: PlacePass,
    draw_pass: DrawPass,
    params: PlaceParams,
    params_buffer: wgpu::Buffer,
    jobs: wgpu::Buffer,
    instances: wgpu::Buffer,
    counters: wgpu::Buffer,
    stats: wgpu::Buffer,
    args: wgpu::Buffer,
    frame: PlantFrame,
    frame_buffer: wgpu::Buffer,
    /// A shadow caster's frame record and draw bind group per cascade (empty for a stage
    /// that draws into the frame).
    casts: Vec<(wgpu::Buffer, wgpu::BindGroup)>,
    /// The meshes (bound in `draw_group`; kept with the stage that owns them).
    _vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    place_group: wgpu::BindGroup,
    draw_group: wgpu::BindGroup,
    region_group: wgpu::BindGroup,
    targets: Targets,
    samples: u32,
    atlas_views: (wgpu::TextureView, wgpu::TextureView),
    /// Whether the frame is a cut ([`PlantRenderer::set_cut`]).
    cut: bool,
}

/// Per level of detail of each type of `ids` (indices into `set`): the meshes packed into one
/// vertex and one index buffer, with each (type, level)'s index count, first index and base
/// vertex.
fn pack_meshes(
    set: &PlantSet,
    ids: &[usize],
) -> (
    Vec<crate::plants::PlantVertex>,
    Vec<u32>,
    [[u32; 4]; REGIONS],
) {
    let mut vertices = Vec::new();
    let mut indices = Vec::new();
    let mut table = [[0u32; 4]; REGIONS];
    for (t, &id) in ids.iter().take(TYPES).enumerate() {
        for (l, mesh) in set.models[id].lods.iter().enumerate() {
            table[t * LEVELS + l] = [
                mesh.indices.len() as u32,
                indices.len() as u32,
                vertices.len() as u32,
                0,
            ];
            vertices.extend_from_slice(&mesh.vertices);
            indices.extend_from_slice(&mesh.indices);
        }
    }
    if vertices.is_empty() {
        vertices.push(Default::default());
        indices.extend([0, 0, 0]);
    }
    (vertices, indices, table)
}

/// Where `model`'s own switch from its full mesh to its reduced one lies ([`PlantTypeGpu::lod`]):
/// half of `settings`' cross-fade band short of its reach
/// ([`crate::plants::set::PlantModel::full_mesh_reach_m`]), so that no full mesh is drawn
/// beyond it; [`f32::MAX`] (the settings' switch) for a model without one.
pub fn full_mesh_switch(model: &crate::plants::set::PlantModel, settings: &PlantSettings) -> f32 {
    if model.full_mesh_reach_m == f32::MAX {
        f32::MAX
    } else {
        // Negative where the reach is within half the cross-fade band: the full mesh then shows
        // only faded, within the reach.
        model.full_mesh_reach_m - 0.5 * settings.band_m.max(0.0)
    }
}

/// The per-type constants of the placement for the types `ids`, from the manifest, the models
/// and the settings.
fn type_table(
    manifest: &Manifest,
    set: &PlantSet,
    ids: &[usize],
    settings: &PlantSettings,
) -> [PlantTypeGpu; TYPES] {
    let mut types = [PlantTypeGpu::default(); TYPES];
    for (i, &id) in ids.iter().take(TYPES).enumerate() {
        let (t, m) = (&manifest.plant_types[id], &set.models[id]);
        let mut density = [[0.0f32; 4]; 4];
        for (g, grass) in manifest.grass_types.iter().take(16).enumerate() {
            density[g / 4][g % 4] = t.density.get(&grass.name).copied().unwrap_or(0.0);
        }
        types[i] = PlantTypeGpu {
            size: [
                t.size_m[0],
                t.size_m[1],
                t.max_slope_deg.to_radians().cos(),
                t.clump_m,
            ],
            limits: [
                t.altitude_m[0],
                t.altitude_m[1],
                t.clump_cover,
                m.radius_ratio,
            ],
            density,
            // The full mesh is drawn out to its switch and half a band beyond: the switch
            // half a band short of the model's reach keeps it within.
            lod: [full_mesh_switch(m, settings), 0.0, 0.0, 0.0],
        };
    }
    types
}

/// Cells along the edge of the largest tree job for grass tiles of `per_tile` cells: the tile's
/// cells doubled while they stay within [`MAX_TREE_JOB_CELLS`].
pub fn tree_job_cells(per_tile: u32) -> u32 {
    let mut n = per_tile.max(1);
    while n * 2 <= MAX_TREE_JOB_CELLS {
        n *= 2;
    }
    n
}

impl PlantRenderer {
    /// The plant stage for `manifest`'s plant types of `layer` (their models in `set`), placing
    /// on the tiles of `atlas` (grass tiles of `tile_m` metres), drawing into `targets`, culling
    /// against `hiz`, bending in `wind`.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        manifest: &Manifest,
        set: &PlantSet,
        layer: PlantLayer,
        atlas: &TileAtlas,
        targets: &Targets,
        hiz: &HiZPyramid,
        tile_m: f32,
        settings: PlantSettings,
        wind: PlantWindBindings<'_>,
    ) -> Self {
        Self::build(
            device, queue, manifest, set, layer, atlas, targets, hiz, tile_m, settings, wind, 0,
        )
    }

    /// A stage that draws the trees' depth into the `cascades` layers of a shadow map
    /// ([`crate::plants::shadow`]) instead of into the frame: the trees' placement with
    /// `settings`, culled by the cascades' box ([`PlantRenderer::set_shadow_frame`]) and not
    /// by the terrain's Hi-Z, and their draw with the cards turned to the sun, depth only.
    #[allow(clippy::too_many_arguments)]
    pub fn new_caster(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        manifest: &Manifest,
        set: &PlantSet,
        atlas: &TileAtlas,
        targets: &Targets,
        hiz: &HiZPyramid,
        tile_m: f32,
        settings: PlantSettings,
        wind: PlantWindBindings<'_>,
        cascades: u32,
    ) -> Self {
        Self::build(
            device,
            queue,
            manifest,
            set,
            PlantLayer::Trees,
            atlas,
            targets,
            hiz,
            tile_m,
            settings,
            wind,
            cascades.max(1),
        )
    }

    #[allow(clippy::too_many_arguments)]
    fn build(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        manifest: &Manifest,
        set: &PlantSet,
        layer: PlantLayer,
        atlas: &TileAtlas,
        targets: &Targets,
        hiz: &HiZPyramid,
        tile_m: f32,
        settings: PlantSettings,
        wind: PlantWindBindings<'_>,
        cascades: u32,
    ) -> Self {
        use wgpu::BufferUsages as U;
        let ids = layer.types(manifest);
        let types = ids.len() as u32;
        let capacity =
            (settings.capacity.max(8).div_ceil(8).saturating_mul(8)).min(max_capacity(types));
        let settings = PlantSettings {
            capacity,
            ..settings
        };
        let buffer = |label, size: u64, usage| gpu_buffer(device, label, size, usage);
        let cell = settings.cell_m;
        let per_tile = (tile_m / cell).round().max(1.0) as u32;
        let p = &manifest.pyramid;
        let (vertex_data, index_data, meshes) = pack_meshes(set, &ids);
        if cascades == 0 {
            for &id in &ids {
                let (t, m) = (&manifest.plant_types[id], &set.models[id]);
                let switch = full_mesh_switch(m, &settings);
                if switch <= 0.0 {
                    log::warn!(
                        "plant type {:?}: its mesh of {} triangles is drawn only faded into its \
                         reduced level of {} triangles, within {:.1} m of the camera, so that its \
                         full meshes at {} plants per m2 stay within {} triangles around it",
                        t.name,
                        m.lods[0].triangles(),
                        m.lods[1].triangles(),
                        m.full_mesh_reach_m,
                        t.density.values().copied().fold(0.0f32, f32::max),
                        crate::plants::set::FULL_MESH_TRIANGLE_BUDGET,
                    );
                } else if switch < settings.lod_m[0] {
                    log::warn!(
                        "plant type {:?}: its mesh of {} triangles switches to its reduced level \
                         of {} triangles at {:.1} m from the camera, not {} m, so that its full \
                         meshes (within {:.1} m) at {} plants per m2 stay within {} triangles \
                         around the camera",
                        t.name,
                        m.lods[0].triangles(),
                        m.lods[1].triangles(),
                        switch,
                        settings.lod_m[0],
                        m.full_mesh_reach_m,
                        t.density.values().copied().fold(0.0f32, f32::max),
                        crate::plants::set::FULL_MESH_TRIANGLE_BUDGET,
                    );
                }
            }
        }
        let params = PlaceParams {
            view_proj: Mat4::IDENTITY.to_cols_array_2d(),
            planes: [[0.0; 4]; 6],
            camera: [0.0, 0.5, targets.width as f32, targets.height as f32],
            grid: [
                match layer {
                    PlantLayer::Plants => per_tile,
                    PlantLayer::Trees => tree_job_cells(per_tile),
                },
                p.tile_cells,
                p.border,
                settings.seed,
            ],
            dims: [cell, tile_m, settings.view_m[0], settings.view_m[1]],
            lod: [settings.lod_m[0], settings.lod_m[1], settings.band_m, 0.0],
            cards: [
                settings.view_m[1],
                settings.view_m[1] * settings.card_reach.max(1.0),
                settings.thin_m,
                settings.min_keep,
            ],
            limits: [
                hiz.mips(),
                capacity,
                types,
                manifest.grass_types.len().min(16) as u32,
            ],
            hiz_levels: hiz_levels(hiz),
            types: type_table(manifest, set, &ids, &settings),
            meshes,
        };
        let params_buffer = buffer(
            "plants params",
            std::mem::size_of::<PlaceParams>() as u64,
            U::UNIFORM | U::COPY_DST,
        );
        let jobs = buffer(
            "plants jobs",
            u64::from(MAX_JOBS) * std::mem::size_of::<PlantJob>() as u64,
            U::STORAGE | U::COPY_DST,
        );
        let region_bytes = u64::from(capacity) * INSTANCE_BYTES;
        let instances = buffer(
            "plants instances",
            region_bytes * u64::from(types.max(1)) * LEVELS as u64,
            U::STORAGE | U::COPY_SRC | U::COPY_DST,
        );
        let counters = buffer(
            "plants counters",
            REGION_COUNTER_BYTES + REGIONS as u64 * 4,
            U::STORAGE | U::COPY_DST | U::COPY_SRC,
        );
        // No region crowded before the first frame.
        queue.write_buffer(
            &counters,
            REGION_COUNTER_BYTES,
            bytemuck::cast_slice(&[UNCROWDED; REGIONS]),
        );
        let stats = buffer(
            "plants stats",
            STATS_BYTES,
            U::STORAGE | U::COPY_DST | U::COPY_SRC,
        );
        let args = buffer(
            "plants draw args",
            ARGS_BYTES,
            U::STORAGE | U::INDIRECT | U::COPY_SRC,
        );
        let vertices = buffer(
            "plants vertices",
            std::mem::size_of_val(vertex_data.as_slice()) as u64,
            U::STORAGE | U::COPY_DST,
        );
        queue.write_buffer(&vertices, 0, bytemuck::cast_slice(&vertex_data));
        let indices = buffer(
            "plants indices",
            (index_data.len() * 4) as u64,
            U::INDEX | U::COPY_DST,
        );
        queue.write_buffer(&indices, 0, bytemuck::cast_slice(&index_data));

        // Texture layers: per type, its meshes' texture then its card's picture.
        let layers = (2 * types).max(1);
        let mip_count = TEXTURE_SIZE.ilog2() + 1;
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("plants textures"),
            size: wgpu::Extent3d {
                width: TEXTURE_SIZE,
                height: TEXTURE_SIZE,
                depth_or_array_layers: layers,
            },
            mip_level_count: mip_count,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba8UnormSrgb,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        let mut frame_layers = [[0u32; 4]; TYPES];
        for (t, &id) in ids.iter().enumerate() {
            let m = &set.models[id];
            for (k, img) in [&m.texture, &m.card].into_iter().enumerate() {
                let layer = (2 * t + k) as u32;
                for (level, data) in mips(img).iter().enumerate() {
                    let size = (TEXTURE_SIZE >> level).max(1);
                    queue.write_texture(
                        wgpu::TexelCopyTextureInfo {
                            texture: &texture,
                            mip_level: level as u32,
                            origin: wgpu::Origin3d {
                                x: 0,
                                y: 0,
                                z: layer,
                            },
                            aspect: wgpu::TextureAspect::All,
                        },
                        data,
                        wgpu::TexelCopyBufferLayout {
                            offset: 0,
                            bytes_per_row: Some(4 * size),
                            rows_per_image: Some(size),
                        },
                        wgpu::Extent3d {
                            width: size,
                            height: size,
                            depth_or_array_layers: 1,
                        },
                    );
                }
            }
            frame_layers[t] = [2 * t as u32, 2 * t as u32 + 1, id as u32, 0];
        }
        let texture_view = texture.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("plants"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Linear,
            ..Default::default()
        });

        let sky = &manifest.sky;
        let c4 = |c: [f32; 3]| [c[0], c[1], c[2], 1.0];
        let mut wind_table = [PlantWindGpu::default(); TYPES];
        for (i, &id) in ids.iter().enumerate() {
            wind_table[i] = PlantWindGpu::new(&manifest.plant_types[id].wind);
        }
        let frame = PlantFrame {
            view_proj: Mat4::IDENTITY.to_cols_array_2d(),
            misc: [sky.fog_distance_m, 0.0, 0.0, 0.0],
            sun_dir: sun_direction(sky).extend(0.0).to_array(),
            sun_color: c4(sky.sun_color),
            sky_color: c4(sky.sky_color),
            horizon_color: c4(sky.horizon_color),
            flags: [
                crate::features::Features::all().bits(),
                u32::from(layer == PlantLayer::Trees),
                u32::from(cascades > 0),
                0,
            ],
            wind: wind_table,
            layers: frame_layers,
        };
        let frame_buffer = buffer(
            "plants frame",
            std::mem::size_of::<PlantFrame>() as u64,
            U::UNIFORM | U::STORAGE | U::COPY_DST,
        );

        let place_pass = PlacePass::new(device);
        let draw_pass = if cascades > 0 {
            DrawPass::new_shadow(device, region_bytes)
        } else {
            DrawPass::new(device, targets, region_bytes, 1)
        };
        let atlas_views = (array_view(&atlas.heights), array_view(&atlas.grass));
        let place_group = Self::place_group(
            device,
            &place_pass,
            [&params_buffer, &jobs],
            &atlas_views,
            hiz,
            [&instances, &counters, &stats, &args],
        );
        let draw_group_of = |frame: &wgpu::Buffer| {
            bind_group(
                device,
                "plants draw",
                &draw_pass.layout,
                [
                    frame.as_entire_binding(),
                    vertices.as_entire_binding(),
                    wind.lookup.as_entire_binding(),
                    wind.cells.as_entire_binding(),
                    view(&texture_view),
                    wgpu::BindingResource::Sampler(&sampler),
                    frame.as_entire_binding(),
                    wind.sway.as_entire_binding(),
                ],
            )
        };
        let draw_group = draw_group_of(&frame_buffer);
        let casts = (0..cascades)
            .map(|_| {
                let b = buffer(
                    "plants shadow frame",
                    std::mem::size_of::<PlantFrame>() as u64,
                    U::UNIFORM | U::STORAGE | U::COPY_DST,
                );
                let g = draw_group_of(&b);
                (b, g)
            })
            .collect();
        // Every byte of the pool written once, so that its memory is committed up front (a
        // driver may commit pages on first use, which would look like growth later).
        let mut encoder = device.create_command_encoder(&Default::default());
        encoder.clear_buffer(&instances, 0, None);
        queue.submit([encoder.finish()]);
        let region_group = bind_group(
            device,
            "plants region",
            &draw_pass.region_layout,
            [buffer_prefix(&instances, region_bytes)],
        );
        Self {
            layer,
            settings,
            types,
            place_pass,
            draw_pass,
            params,
            params_buffer,
            jobs,
            instances,
            counters,
            stats,
            args,
            frame,
            frame_buffer,
            casts,
            _vertices: vertices,
            indices,
            place_group,
            draw_group,
            region_group,
            targets: *targets,
            samples: 1,
            atlas_views,
            cut: false,
        }
    }

    fn place_group(
        device: &wgpu::Device,
        pass: &PlacePass,
        [params, jobs]: [&wgpu::Buffer; 2],
        atlas: &(wgpu::TextureView, wgpu::TextureView),
        hiz: &HiZPyramid,
        [instances, counters, stats, args]: [&wgpu::Buffer; 4],
    ) -> wgpu::BindGroup {
        bind_group(
            device,
            "plants place",
            &pass.layout,
            [
                params.as_entire_binding(),
                jobs.as_entire_binding(),
                view(&atlas.0),
                view(&atlas.1),
                hiz.buffer().as_entire_binding(),
                instances.as_entire_binding(),
                counters.as_entire_binding(),
                stats.as_entire_binding(),
                args.as_entire_binding(),
            ],
        )
    }

    /// Follows a new Hi-Z pyramid (the targets were resized).
    pub fn resize(&mut self, device: &wgpu::Device, hiz: &HiZPyramid) {
        let (_, width, height) = hiz.levels()[0];
        self.params.camera[2] = width as f32;
        self.params.camera[3] = height as f32;
        self.params.limits[0] = hiz.mips();
        self.params.hiz_levels = hiz_levels(hiz);
        self.place_group = Self::place_group(
            device,
            &self.place_pass,
            [&self.params_buffer, &self.jobs],
            &self.atlas_views,
            hiz,
            [&self.instances, &self.counters, &self.stats, &self.args],
        );
    }

    /// Draws into targets of `samples` samples a pixel from now on.
    pub fn set_samples(&mut self, device: &wgpu::Device, samples: u32) {
        if samples == self.samples || !self.casts.is_empty() {
            return;
        }
        self.draw_pass.pipelines = DrawPass::pipelines(
            device,
            &self.targets,
            &self.draw_pass.layout,
            &self.draw_pass.region_layout,
            samples,
        );
        self.samples = samples;
    }

    /// The plant types it draws.
    pub fn layer(&self) -> PlantLayer {
        self.layer
    }

    /// The settings.
    pub fn settings(&self) -> &PlantSettings {
        &self.settings
    }

    /// Plant types drawn.
    pub fn types(&self) -> u32 {
        self.types
    }

    /// GPU memory of the instance pool, bytes (fixed: it does not depend on the view).
    pub fn pool_bytes(&self) -> u64 {
        self.instances.size() + self.counters.size() + self.args.size()
    }

    /// The placement's constants of the frame (for the CPU mirror).
    pub fn params(&self) -> &PlaceParams {
        &self.params
    }

    /// Sets the frame: time (seconds), switched-on features, the camera's world position, its
    /// camera-relative view-projection and frustum, its altitude and near plane.
    #[allow(clippy::too_many_arguments)]
    pub fn set_frame(
        &mut self,
        queue: &wgpu::Queue,
        time_s: f64,
        features: crate::features::Features,
        camera_world: glam::DVec3,
        view_proj: Mat4,
        frustum: &Frustum,
        near: f32,
    ) {
        self.params.view_proj = view_proj.to_cols_array_2d();
        for (dst, p) in self.params.planes.iter_mut().zip(frustum.planes()) {
            *dst = p.to_array();
        }
        self.params.camera[0] = camera_world.z as f32;
        self.params.camera[1] = near;
        self.frame.view_proj = self.params.view_proj;
        self.frame.misc[1] = (time_s % 3600.0) as f32;
        self.frame.misc[2] = camera_world.x.rem_euclid(4096.0) as f32;
        self.frame.misc[3] = camera_world.y.rem_euclid(4096.0) as f32;
        self.frame.flags[0] = features.bits();
        queue.write_buffer(&self.params_buffer, 0, bytemuck::bytes_of(&self.params));
        queue.write_buffer(&self.frame_buffer, 0, bytemuck::bytes_of(&self.frame));
    }

    /// Sets a shadow caster's frame ([`PlantRenderer::new_caster`]): time, features, the
    /// camera's world position, the box of the cascades (`caster_box`, camera-relative, whose
    /// sides and sun-facing side cull the trees) and each cascade's view-projection.
    pub fn set_shadow_frame(
        &mut self,
        queue: &wgpu::Queue,
        time_s: f64,
        features: crate::features::Features,
        camera_world: glam::DVec3,
        caster_box: Mat4,
        cascades: &[crate::plants::shadow::Cascade],
    ) {
        // No occlusion test: a near plane no orthographic point is beyond.
        self.set_frame(
            queue,
            time_s,
            features,
            camera_world,
            caster_box,
            &Frustum::from_view_proj(caster_box),
            f32::MAX,
        );
        for ((buffer, _), c) in self.casts.iter().zip(cascades) {
            let frame = PlantFrame {
                view_proj: c.view_proj.to_cols_array_2d(),
                ..self.frame
            };
            queue.write_buffer(buffer, 0, bytemuck::bytes_of(&frame));
        }
    }

    /// Sets whether the next recorded frame is a cut ([`is_cut`]): then its placement runs twice,
    /// the first time only to measure what each region of the pool wants, so that a view
    /// crowded from its first frame (a teleport over a forest, a frame of a path's far apart
    /// views) thins its plants at once instead of dropping those that came last.
    pub fn set_cut(&mut self, cut: bool) {
        self.cut = cut;
    }

    /// Records a shadow caster's placement on `jobs` and its draws into each of `cascades`
    /// layers of `map` (cleared here).
    pub fn record_shadow(
        &self,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        jobs: &[PlantJob],
        map: &crate::plants::shadow::TreeShadowMap,
        cascades: usize,
        timer: &mut GpuTimer,
    ) {
        self.record_place(queue, encoder, jobs, timer, "tree_shadows_place");
        for (i, (_, group)) in self.casts.iter().enumerate().take(cascades) {
            let mut pass = crate::gpu::pass::depth_pass(
                encoder,
                "tree shadows draw",
                map.layer(i),
                timer.render_pass("tree_shadows_draw"),
            );
            self.record_draws(&mut pass, group);
        }
    }

    /// Records the placement of `jobs` (see [`PlantRenderer::record`]).
    fn record_place(
        &self,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        jobs: &[PlantJob],
        timer: &mut GpuTimer,
        name: &str,
    ) {
        let jobs = &jobs[..jobs.len().min(MAX_JOBS as usize)];
        if !jobs.is_empty() {
            queue.write_buffer(&self.jobs, 0, bytemuck::cast_slice(jobs));
        }
        // After a cut, a first placement measures each region's crowding for the second (both
        // timed as the stage's placement).
        let runs = if self.cut && !jobs.is_empty() { 2 } else { 1 };
        for _ in 0..runs {
            encoder.clear_buffer(&self.stats, 0, None);
            encoder.clear_buffer(&self.counters, 0, Some(REGION_COUNTER_BYTES));
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("plants place"),
                timestamp_writes: timer.compute_pass(name),
            });
            pass.set_bind_group(0, &self.place_group, &[]);
            if !jobs.is_empty() {
                let n = self.params.grid[0];
                pass.set_pipeline(&self.place_pass.place);
                pass.dispatch_workgroups(n.div_ceil(8), n.div_ceil(8), jobs.len() as u32);
            }
            pass.set_pipeline(&self.place_pass.finalize);
            pass.dispatch_workgroups(1, 1, 1);
        }
    }

    /// Records the indirect draw of every (type, level) region with the draw bind group `group`.
    fn record_draws(&self, pass: &mut wgpu::RenderPass<'_>, group: &wgpu::BindGroup) {
        pass.set_bind_group(0, group, &[]);
        pass.set_index_buffer(self.indices.slice(..), wgpu::IndexFormat::Uint32);
        let region_bytes = u64::from(self.settings.capacity) * INSTANCE_BYTES;
        // The full meshes first, then the rest: one pipeline switch.
        for (pipeline, levels) in self.draw_pass.pipelines.iter().zip([0..1, 1..LEVELS]) {
            pass.set_pipeline(pipeline);
            for t in 0..self.types as usize {
                for level in levels.clone() {
                    let region = t * LEVELS + level;
                    pass.set_bind_group(
                        1,
                        &self.region_group,
                        &[(region as u64 * region_bytes) as u32],
                    );
                    pass.draw_indexed_indirect(&self.args, region as u64 * 20);
                }
            }
        }
    }

    /// The jobs of a frame: one per grass tile (a high-LOD tile's near job covers part of the
    /// same tile and is left out), then the far jobs, at most [`MAX_JOBS`] in all (the nearest
    /// first: the far jobs come sorted by distance).
    pub fn plant_jobs(grass_jobs: &[TileJob], far_jobs: &[PlantJob]) -> Vec<PlantJob> {
        grass_jobs
            .iter()
            .filter(|j| j.lod != 2)
            .map(PlantJob::near)
            .chain(far_jobs.iter().copied())
            .take(MAX_JOBS as usize)
            .collect()
    }

    /// Records placement on `jobs` (see [`PlantRenderer::plant_jobs`]; those past
    /// [`MAX_JOBS`] are left out) and the draws into `color` and `depth` (loaded, not cleared).
    pub fn record(
        &self,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        jobs: &[PlantJob],
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        timer: &mut GpuTimer,
    ) {
        self.record_place(queue, encoder, jobs, timer, self.layer.pass_names()[0]);
        let mut pass = render_pass(
            encoder,
            "plants draw",
            (color, wgpu::LoadOp::Load),
            Some((depth, wgpu::LoadOp::Load)),
            timer.render_pass(self.layer.pass_names()[1]),
        );
        self.record_draws(&mut pass, &self.draw_group);
    }

    /// The instance pool (regions of [`PlantSettings::capacity`] instances, type * 3 + level).
    pub fn instance_buffer(&self) -> &wgpu::Buffer {
        &self.instances
    }

    /// The indexed indirect draws of the regions (20 bytes each, written by the placement).
    pub fn args_buffer(&self) -> &wgpu::Buffer {
        &self.args
    }

    /// The buffer of the frame's counters ([`STATS_BYTES`]: `counter::*`), for a readback.
    pub fn stats_buffer(&self) -> &wgpu::Buffer {
        &self.stats
    }

    /// Reads the counters and the draws' triangles of the last recorded frame (for tests and
    /// tools: waits for the GPU).
    pub fn read_stats(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> PlantStats {
        let c: Vec<u32> = crate::gpu::read_buffer_pod(device, queue, &self.stats, ..)
            .expect("read back the plant counters");
        let args: Vec<u32> = crate::gpu::read_buffer_pod(device, queue, &self.args, ..)
            .expect("read back the draw arguments");
        PlantStats::from_counts(&c[..counter::COUNT].try_into().expect("the counters"))
            .with_draws(&args)
    }

    /// Reads each region's distance from which it thins its plants in the next frame (`type *
    /// 3 + level`; [`crate::plants::place_cpu::crowd_distances`] of what the last recorded
    /// frame wanted, [`UNCROWDED`] where nothing crowds it), and what each region wanted in that
    /// frame by distance (`region * CROWD_BINS + bin`; for tests: waits for the GPU).
    pub fn read_crowding(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> ([f32; REGIONS], Vec<u32>) {
        let words: Vec<u32> = crate::gpu::read_buffer_pod(device, queue, &self.counters, ..)
            .expect("read back the plant regions' counters");
        let wanted = words[REGIONS..REGIONS + REGIONS * CROWD_BINS].to_vec();
        let from = &words[REGIONS + REGIONS * CROWD_BINS..];
        (std::array::from_fn(|r| f32::from_bits(from[r])), wanted)
    }

    /// Reads back the instances of every region of the last recorded frame (for tests): per
    /// region (`type * 3 + level`), the instances its draw draws.
    pub fn read_instances(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Vec<Vec<PlantInstance>> {
        let args: Vec<u32> = crate::gpu::read_buffer_pod(device, queue, &self.args, ..)
            .expect("read back the draw arguments");
        let all: Vec<PlantInstance> =
            crate::gpu::read_buffer_pod(device, queue, &self.instances, ..)
                .expect("read back the instances");
        let cap = self.settings.capacity as usize;
        (0..self.types as usize * LEVELS)
            .map(|r| {
                let n = args[r * 5 + 1] as usize;
                all[r * cap..r * cap + n].to_vec()
            })
            .collect()
    }

    /// Bends `vertices` on the GPU, vertex i as `instances[i]` in the wind `winds[i]`, with the
    /// frame's time, features and the types' wind (for the test against
    /// [`crate::plants::bend_cpu::bend_vertex`]): per vertex, position and normal.
    pub fn probe_bend(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        vertices: &[crate::plants::PlantVertex],
        instances: &[PlantInstance],
        winds: &[[f32; 4]],
        leans: &[[f32; 2]],
    ) -> Vec<([f32; 3], [f32; 3])> {
        use wgpu::util::DeviceExt;
        let module = crate::shaders::module(device, "plants_draw.wgsl");
        let pipeline = crate::gpu::pipeline::compute_pipeline_auto(
            device,
            "plants probe bend",
            &module,
            "probe_bend",
        );
        let n = instances
            .len()
            .min(vertices.len())
            .min(winds.len())
            .min(leans.len());
        let init = |label, contents: &[u8], usage| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage,
            })
        };
        use wgpu::BufferUsages as U;
        let v = init(
            "probe vertices",
            bytemuck::cast_slice(&vertices[..n]),
            U::STORAGE,
        );
        let i = init(
            "probe instances",
            bytemuck::cast_slice(&instances[..n]),
            U::STORAGE,
        );
        let w = init("probe winds", bytemuck::cast_slice(&winds[..n]), U::STORAGE);
        let l = init("probe leans", bytemuck::cast_slice(&leans[..n]), U::STORAGE);
        let out = gpu_buffer(
            device,
            "probe out",
            (n * 32) as u64,
            U::STORAGE | U::COPY_SRC,
        );
        let g0 = bind_group_with_indices(
            device,
            "probe frame",
            &pipeline.get_bind_group_layout(0),
            [
                (0, self.frame_buffer.as_entire_binding()),
                (1, v.as_entire_binding()),
                (6, self.frame_buffer.as_entire_binding()),
            ],
        );
        let g1 = bind_group_with_indices(
            device,
            "probe",
            &pipeline.get_bind_group_layout(1),
            [
                (1, i.as_entire_binding()),
                (2, w.as_entire_binding()),
                (3, out.as_entire_binding()),
                (4, l.as_entire_binding()),
            ],
        );
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &g0, &[]);
            pass.set_bind_group(1, &g1, &[]);
            pass.dispatch_workgroups((n as u32).div_ceil(64), 1, 1);
        }
        queue.submit([encoder.finish()]);
        let r: Vec<[f32; 4]> =
            crate::gpu::read_buffer_pod(device, queue, &out, ..).expect("read back the probe");
        (0..n)
            .map(|k| {
                let p = r[2 * k];
                let q = r[2 * k + 1];
                ([p[0], p[1], p[2]], [q[0], q[1], q[2]])
            })
            .collect()
    }
}
