//! Plants on lavapipe against their CPU mirrors: placement and culling of several tiles (every
//! instance, its type and level of detail, and the counters), the pool's bound, and the bending
//! of the vertex stage.

mod common;

use std::time::Duration;

use glam::{DVec3, Vec4};
use verdant::RendererConfig;
use verdant::camera::Camera;
use verdant::features::Features;
use verdant::gpu::{GpuContext, GpuTimer, Targets};
use verdant::grass::{HiZ, HiZPyramid, TileJob};
use verdant::lod::Frustum;
use verdant::plants::place_cpu::{
    CROWD_BINS, LEVELS, PlantInstance, PlantJob, REGIONS, UNCROWDED, counter, crowd_distances,
    place_tile, place_tile_crowded,
};
use verdant::plants::{PlantLayer, PlantRenderer, PlantSet, PlantSettings, Recipe, generate};
use verdant::stream::TileAtlas;
use verdant::world::{Manifest, TileData, TileId, World};

const ALTITUDE: f32 = 101.7;
const W: u32 = 160;
const H: u32 = 90;

struct Rig {
    ctx: GpuContext,
    atlas: TileAtlas,
    depth: wgpu::Texture,
    color: wgpu::Texture,
    hiz: HiZPyramid,
    plants: PlantRenderer,
    manifest: Manifest,
    tile_m: f32,
}

fn targets() -> Targets {
    Targets {
        color_format: verdant::terrain::COLOR_FORMAT,
        depth_format: verdant::terrain::DEPTH_FORMAT,
        width: W,
        height: H,
    }
}

impl Rig {
    fn new(capacity: u32) -> Self {
        let rig = Self::with_world(&common::default_world(), capacity);
        assert!(
            rig.manifest.plant_types.len() >= 3,
            "the default world has plants"
        );
        rig
    }

    /// The rig over the world in `dir`, with regions of `capacity` instances.
    fn with_world(dir: &std::path::Path, capacity: u32) -> Self {
        Self::with_layer(dir, PlantLayer::Plants, |_| PlantSettings {
            capacity,
            lod_m: [18.0, 45.0],
            view_m: [60.0, 90.0],
            ..Default::default()
        })
    }

    /// The rig of `layer` over the world in `dir`, with the settings `settings` makes for grass
    /// tiles of the given edge (metres).
    fn with_layer(
        dir: &std::path::Path,
        layer: PlantLayer,
        settings: impl FnOnce(f32) -> PlantSettings,
    ) -> Self {
        let ctx = common::gpu();
        let world = World::open(dir).unwrap();
        let manifest = world.manifest.clone();
        let grass = RendererConfig::for_world(&world)
            .grass_settings(&world)
            .unwrap();
        let atlas = TileAtlas::new(&ctx.device, manifest.pyramid.samples_per_side(), 8);
        let target = |format, usage| {
            verdant::gpu::target_texture(&ctx.device, "plants test", format, usage, (W, H))
        };
        let depth = target(
            verdant::terrain::DEPTH_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
        );
        let color = target(
            verdant::terrain::COLOR_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        let hiz = HiZPyramid::new(&ctx.device, &ctx.queue, W, H);
        let buffer = |size, usage| {
            ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: None,
                size,
                usage,
                mapped_at_creation: false,
            })
        };
        let lookup = buffer(
            32,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        );
        let cells = buffer(8 * 8 * 16, wgpu::BufferUsages::STORAGE);
        let sway = buffer(
            8 * 8 * verdant::wind::SWAY_TYPES as u64 * 16,
            wgpu::BufferUsages::STORAGE,
        );
        let set = PlantSet::build(&manifest, &world.dir).unwrap();
        let plants = PlantRenderer::new(
            &ctx.device,
            &ctx.queue,
            &manifest,
            &set,
            layer,
            &atlas,
            &targets(),
            &hiz,
            grass.tile_m,
            settings(grass.tile_m),
            verdant::plants::renderer::PlantWindBindings {
                lookup: &lookup,
                cells: &cells,
                sway: &sway,
            },
        );
        Self {
            ctx,
            atlas,
            depth,
            color,
            hiz,
            plants,
            manifest,
            tile_m: grass.tile_m,
        }
    }

    /// Places and draws the plants of `jobs` (tiles already in the atlas) over a cleared depth
    /// target (the terrain's occlusion, shared with the grass, is tested there); returns the
    /// Hi-Z placement saw.
    fn run(&mut self, camera: &Camera, jobs: &[PlantJob]) -> HiZ {
        let view_proj = camera.view_proj_relative(W as f32 / H as f32);
        self.plants.set_frame(
            &self.ctx.queue,
            0.0,
            Features::all(),
            camera.position,
            view_proj,
            &Frustum::from_view_proj(view_proj),
            camera.near_m,
        );
        let mut timer = GpuTimer::new(&self.ctx.device, &self.ctx.queue, false, 0);
        let dv = self.depth.create_view(&Default::default());
        let cv = self.color.create_view(&Default::default());
        let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
        {
            encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: None,
                color_attachments: &[],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &dv,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(0.0),
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
        }
        self.hiz
            .record(&self.ctx.device, &mut encoder, &dv, &mut timer);
        self.plants
            .record(&self.ctx.queue, &mut encoder, jobs, &cv, &dv, &mut timer);
        self.ctx.queue.submit([encoder.finish()]);
        self.hiz.read_back(&self.ctx.device, &self.ctx.queue)
    }
}

/// A tile of `kind` at `id`: "meadow" (rolling, meadow with patches of tall grass), "steep"
/// (too steep for most plants), "bare" (no grass), "high" (above every plant's altitude),
/// "flat" (level meadow, the same at every level).
fn synthetic_tile(manifest: &Manifest, id: TileId, kind: &str) -> TileData {
    let s = manifest.pyramid.samples_per_side();
    let cell = manifest.pyramid.cell_size_m(id.level) as f32;
    let n = (s * s) as usize;
    let mut t = TileData {
        id,
        size: s,
        heights: vec![100.0; n],
        grass_type: vec![1; n],
        density: vec![230; n],
        material: Vec::new(),
    };
    for j in 0..s {
        for i in 0..s {
            let k = (j * s + i) as usize;
            match kind {
                "meadow" => {
                    t.heights[k] = 100.0 + 0.3 * ((i as f32) * 0.4).sin() * cell;
                    t.grass_type[k] = if (i / 9 + j / 7) % 3 == 0 { 2 } else { 1 };
                    t.density[k] = 160 + ((i * 5 + j * 11) % 90) as u8;
                }
                "steep" => t.heights[k] = 100.0 + 1.2 * cell * i as f32,
                "bare" => t.grass_type[k] = 0,
                "high" => t.heights[k] = 9500.0,
                "flat" => {}
                other => panic!("no tile kind {other}"),
            }
        }
    }
    t
}

fn key(p: &PlantInstance) -> (u32, u32) {
    (p.hash, p.kind)
}

/// Tiles of the four kinds side by side in front of the camera, placed on the GPU and by the
/// CPU mirror: the GPU's instances (sorted), the CPU's (sorted), the CPU's counters, the
/// instances per tile, and the GPU's counters.
struct Placed {
    gpu: Vec<PlantInstance>,
    cpu: Vec<PlantInstance>,
    stats: [u32; counter::COUNT],
    per_tile: Vec<usize>,
    gpu_stats: verdant::plants::renderer::PlantStats,
    /// The triangles of the CPU's instances' meshes.
    triangles: u64,
    hiz: HiZ,
}

fn place_four_tiles(rig: &mut Rig) -> Placed {
    let level = rig.manifest.pyramid.max_level();
    let cell = rig.manifest.pyramid.cell_size_m(level) as f32;
    let kinds = ["meadow", "steep", "bare", "high"];
    let tm = rig.tile_m;
    let mut work = Vec::new();
    for (k, kind) in kinds.iter().enumerate() {
        // Side by side in front of the camera (which looks north), the first nearest.
        let j = TileJob {
            origin: [
                -0.5 * tm + tm * (k % 2) as f32 - 0.5 * tm,
                2.0 + tm * (k / 2) as f32,
            ],
            cell,
            layer: k as u32,
            tile_x: 5000 + k as u32,
            tile_y: 7000,
            lod: (k % 2) as u32,
            slot: 0,
        };
        let t = synthetic_tile(&rig.manifest, TileId::new(level, j.tile_x, j.tile_y), kind);
        work.push((PlantJob::near(&j), t));
    }
    place_jobs(rig, &work)
}

/// Uploads each job's data tile to the atlas slot the job names, places the jobs on the GPU
/// and by the CPU mirror, from a camera 1.7 m above the tiles looking north.
fn place_jobs(rig: &mut Rig, work: &[(PlantJob, TileData)]) -> Placed {
    for (j, t) in work {
        rig.atlas.upload(&rig.ctx.queue, j.layer, t).unwrap();
    }
    let jobs: Vec<PlantJob> = work.iter().map(|w| w.0).collect();
    let camera = Camera::new(DVec3::new(0.0, 0.0, f64::from(ALTITUDE)), 90.0, -20.0);
    let hiz = rig.run(&camera, &jobs);
    let gpu = rig.plants.read_instances(&rig.ctx.device, &rig.ctx.queue);
    let gpu_stats = rig.plants.read_stats(&rig.ctx.device, &rig.ctx.queue);
    let mut cpu: Vec<PlantInstance> = Vec::new();
    let mut stats = [0u32; counter::COUNT];
    let mut per_tile = Vec::new();
    for (j, t) in work {
        let out = place_tile(rig.plants.params(), j, t, &hiz);
        for (s, o) in stats.iter_mut().zip(out.stats) {
            *s += o;
        }
        per_tile.push(out.instances.len());
        cpu.extend(out.instances);
    }
    let mut gpu_all: Vec<PlantInstance> = gpu.iter().flatten().copied().collect();
    for (r, region) in gpu.iter().enumerate() {
        for p in region {
            assert_eq!(
                p.plant_type() * LEVELS + p.level(),
                r,
                "an instance in its region"
            );
        }
    }
    gpu_all.sort_by_key(key);
    cpu.sort_by_key(key);
    let meshes = rig.plants.params().meshes;
    let triangles = cpu
        .iter()
        .map(|p| u64::from(meshes[p.plant_type() * LEVELS + p.level()][0] / 3))
        .sum();
    Placed {
        gpu: gpu_all,
        cpu,
        stats,
        per_tile,
        gpu_stats,
        triangles,
        hiz,
    }
}

/// The GPU's placement is the CPU mirror's: the same instances (type, level, position, size,
/// turn, fade) and the same counters.
fn assert_same_placement(p: &Placed) {
    let (gpu_all, cpu, stats, gpu_stats) = (&p.gpu, &p.cpu, &p.stats, &p.gpu_stats);
    assert_eq!(gpu_all.len(), cpu.len(), "instances, GPU against CPU");
    for (g, c) in gpu_all.iter().zip(cpu) {
        assert_eq!(key(g), key(c));
        for k in 0..3 {
            assert!((g.pos[k] - c.pos[k]).abs() < 1e-3, "{g:?} against {c:?}");
        }
        assert!((g.scale - c.scale).abs() < 1e-5 && (g.yaw - c.yaw).abs() < 1e-4);
        assert!((g.fade - c.fade).abs() < 1e-4, "{g:?} against {c:?}");
    }
    assert_eq!(gpu_stats.considered, stats[counter::CONSIDERED]);
    assert_eq!(gpu_stats.empty, stats[counter::EMPTY]);
    assert_eq!(gpu_stats.ruled_out, stats[counter::RULED_OUT]);
    assert_eq!(gpu_stats.culled_frustum, stats[counter::FRUSTUM]);
    assert_eq!(gpu_stats.culled_distance, stats[counter::DISTANCE]);
    assert_eq!(gpu_stats.culled_occlusion, stats[counter::OCCLUSION]);
    assert_eq!(gpu_stats.drawn as usize, cpu.len());
    assert_eq!(gpu_stats.overflow, 0);
    assert_eq!(gpu_stats.crowded, 0);
    assert_eq!(stats[counter::CROWDED], 0);
    assert_eq!(gpu_stats.triangles, p.triangles);
}

#[test]
fn gpu_placement_matches_the_cpu_mirror_on_meadow_steep_bare_and_high_tiles() {
    let mut rig = Rig::new(16_384);
    let placed = place_four_tiles(&mut rig);
    let (cpu, stats, per_tile) = (&placed.cpu, &placed.stats, &placed.per_tile);
    // The meadow tile has plants of several types at several levels; the others none.
    assert!(per_tile[0] > 100, "meadow plants: {per_tile:?}");
    assert_eq!(&per_tile[2..], &[0, 0], "bare and high tiles: {per_tile:?}");
    let types: std::collections::HashSet<usize> = cpu.iter().map(|p| p.plant_type()).collect();
    let levels: std::collections::HashSet<usize> = cpu.iter().map(|p| p.level()).collect();
    assert!(types.len() >= 3, "types placed: {types:?}");
    assert!(levels.len() >= 2, "levels placed: {levels:?}");
    assert!(
        stats[counter::RULED_OUT] > 0,
        "the steep tile rules plants out"
    );
    assert!(
        stats[counter::FRUSTUM] > 0,
        "some plants fall outside the frustum"
    );
    assert_same_placement(&placed);
}

#[test]
fn far_jobs_take_over_at_the_view_distance_and_match_the_cpu_mirror() {
    let mut rig = Rig::new(16_384);
    let level = rig.manifest.pyramid.max_level();
    let p = rig.manifest.pyramid.clone();
    let tm = rig.tile_m;
    // A grass tile across the hand-over (60..90 m ahead), a far job over the same data, and a
    // far job beyond the view distance reading a quarter of a coarser tile.
    let near = PlantJob::near(&TileJob {
        origin: [-0.5 * tm, 40.0],
        cell: p.cell_size_m(level) as f32,
        layer: 0,
        tile_x: 5000,
        tile_y: 7000,
        lod: 0,
        slot: 0,
    });
    let same = PlantJob { far: 1, ..near };
    let half = (p.tile_cells / 2) as f32;
    let coarse = PlantJob {
        origin: [-0.5 * tm, 40.0 + tm],
        texel: [half, half],
        cell: p.cell_size_m(level - 1) as f32,
        layer: 1,
        tile_x: 5000,
        tile_y: 7001,
        far: 1,
        cells: 0,
        pad: [0; 2],
    };
    let fine = synthetic_tile(&rig.manifest, TileId::new(level, 5000, 7000), "meadow");
    let parent = synthetic_tile(&rig.manifest, TileId::new(level - 1, 2500, 3500), "meadow");
    let work = [(near, fine.clone()), (same, fine.clone()), (coarse, parent)];
    let placed = place_jobs(&mut rig, &work);
    assert_same_placement(&placed);
    let per_tile = &placed.per_tile;
    assert!(
        per_tile.iter().all(|&n| n > 20),
        "plants per job: {per_tile:?}"
    );

    let params = *rig.plants.params();
    let [_, _, start, view] = params.dims;
    let hiz = &placed.hiz;
    let dist = |i: &PlantInstance| glam::Vec3::from(i.pos).length();
    let hashes = |v: &[PlantInstance]| -> std::collections::BTreeSet<u32> {
        v.iter().map(|i| i.hash).collect()
    };
    let by_near = place_tile(&params, &near, &fine, hiz).instances;
    let by_far = place_tile(&params, &same, &fine, hiz).instances;
    assert!(by_near.iter().all(|i| dist(i) < view));
    assert!(by_far.iter().all(|i| dist(i) > start));
    assert!(
        hashes(&by_near).is_disjoint(&hashes(&by_far)),
        "no plant placed by both"
    );
    // Without the far thinning, the two jobs place together what one job without the
    // hand-over places.
    let mut whole = params;
    whole.dims[2] = 1e6;
    whole.dims[3] = 2e6;
    let mut unthinned = params;
    unthinned.cards[0] = 1e6;
    unthinned.cards[1] = 2e6;
    let all = hashes(&place_tile(&whole, &near, &fine, hiz).instances);
    let mut parts = hashes(&by_near);
    parts.extend(hashes(&place_tile(&unthinned, &same, &fine, hiz).instances));
    assert_eq!(parts, all);
    // Beyond the view distance every plant is a card.
    let beyond = place_tile(&params, &coarse, &work[2].1, hiz).instances;
    assert!(beyond.iter().all(|i| i.level() == 2 && dist(i) > view));
    // There half the plants are left (the thinning with distance), each grown by the square
    // root of 2.
    let [thin, keep] = [params.cards[2], params.cards[3]];
    assert_eq!(keep, verdant::plants::place_cpu::MIN_KEEP);
    assert!(thin * thin / (view * view) < keep);
    for i in &beyond {
        let [lo, hi] = [0, 1].map(|k| params.types[i.plant_type()].size[k] / keep.sqrt());
        assert!(i.scale >= lo - 1e-4 && i.scale <= hi + 1e-4, "{i:?}");
    }
}

#[test]
fn tree_jobs_of_every_size_place_one_grid_of_trees_as_the_cpu_mirror_does() {
    let tmp = tempfile::tempdir().unwrap();
    let w = common::world_with_trees(tmp.path(), "broadleaf", 0.02);
    // The thinning from 800 m, so that the job 1.2 km ahead (below) lies where it thins.
    let mut rig = Rig::with_layer(&w, PlantLayer::Trees, |tile_m| PlantSettings {
        lod_m: [30.0, 60.0],
        thin_m: 800.0,
        ..PlantSettings::trees(tile_m, 3000.0)
    });
    let p = rig.manifest.pyramid.clone();
    let g = p.max_level();
    let params = *rig.plants.params();
    let cell_m = params.dims[0];
    let per_tile = (rig.tile_m / cell_m).round() as u32;
    assert!(
        (rig.tile_m / cell_m - per_tile as f32).abs() < 1e-4 && (4.0..=6.0).contains(&cell_m),
        "tree cells of {cell_m} m divide the grass tile of {} m",
        rig.tile_m
    );
    assert!(
        params.grid[0] >= 4 * per_tile,
        "jobs of several grass tiles"
    );
    // A grass tile's job, its parent's job (four grass tiles, the first that one), and 1.2 km
    // ahead a job three levels up, each reading its own level of a level meadow.
    let job = |level: u8, x: u32, y: u32, origin: [f32; 2], layer: u32| PlantJob {
        origin,
        texel: [0.0; 2],
        cell: p.cell_size_m(level) as f32,
        layer,
        tile_x: x,
        tile_y: y,
        far: 0,
        cells: per_tile << (g - level),
        pad: [0; 2],
    };
    let a = job(g, 5000, 7000, [-25.0, 30.0], 0);
    let b = job(g - 1, 2500, 3500, [-25.0, 30.0], 1);
    let c = job(g - 3, 625, 876, [-200.0, 1200.0], 2);
    let work: Vec<(PlantJob, TileData)> = [a, b, c]
        .iter()
        .map(|j| {
            let level = g - (j.cells / per_tile).ilog2() as u8;
            let id = TileId::new(level, j.tile_x, j.tile_y);
            (*j, synthetic_tile(&rig.manifest, id, "flat"))
        })
        .collect();
    let placed = place_jobs(&mut rig, &work);
    assert_same_placement(&placed);
    let hiz = &placed.hiz;
    let trees = |j: &PlantJob, t: &TileData| place_tile(&params, j, t, hiz).instances;
    let (in_a, in_b, in_c) = (
        trees(&a, &work[0].1),
        trees(&b, &work[1].1),
        trees(&c, &work[2].1),
    );
    assert!(
        in_a.len() > 10 && in_c.len() > 10,
        "{} and {}",
        in_a.len(),
        in_c.len()
    );
    // The parent's job places, over the grass tile, exactly the grass tile's trees.
    let square = |i: &PlantInstance| {
        i.pos[0] >= -25.0
            && i.pos[0] < -25.0 + rig.tile_m
            && i.pos[1] >= 30.0
            && i.pos[1] < 30.0 + rig.tile_m
    };
    let mut over_a: Vec<PlantInstance> = in_b.iter().filter(|i| square(i)).copied().collect();
    assert!(in_a.iter().all(square));
    let mut own = in_a.clone();
    for v in [&mut own, &mut over_a] {
        v.sort_by_key(key);
    }
    assert_eq!(own.len(), over_a.len(), "trees of the tile, by either job");
    for (x, y) in own.iter().zip(&over_a) {
        assert_eq!(key(x), key(y));
        assert!((glam::Vec3::from(x.pos) - glam::Vec3::from(y.pos)).length() < 1e-3);
        assert_eq!(x.scale, y.scale);
    }
    // 1.2 km ahead: cards only, thinned as the square of the distance beyond the thinning's
    // start (down to no fewer than the fewest it keeps), each grown to keep the cover.
    let [thin_m, min_keep] = [params.cards[2], params.cards[3]];
    assert!((min_keep - 1.0 / 6.0).abs() < 1e-6, "{min_keep}");
    let keep_at = |i: &PlantInstance| {
        let d = glam::Vec3::from(i.pos).length();
        (thin_m * thin_m / (d * d)).clamp(min_keep, 1.0)
    };
    let mut unthinned = params;
    unthinned.cards[2] = 1e6;
    let all = place_tile(&unthinned, &c, &work[2].1, hiz).instances;
    let expected: f32 = all.iter().map(keep_at).sum();
    assert!(
        expected < 0.8 * all.len() as f32,
        "the job 1.2 km ahead lies where the trees thin out: {expected} of {}",
        all.len()
    );
    let kept = in_c.len() as f32;
    assert!(
        (kept / expected - 1.0).abs() < 0.15,
        "{kept} kept where the thinning keeps {expected} of {}",
        all.len()
    );
    for i in &in_c {
        assert_eq!(i.level(), 2, "{i:?}");
        let grown = keep_at(i).sqrt();
        let [lo, hi] = [0, 1].map(|k| params.types[0].size[k] / grown);
        assert!(i.scale >= lo - 1e-3 && i.scale <= hi + 1e-3, "{i:?}");
    }
}

#[test]
fn a_gltf_plant_is_placed_where_its_rule_puts_it_as_the_cpu_mirror_places_it() {
    let tmp = tempfile::tempdir().unwrap();
    let w = common::world_with_plant(tmp.path(), "plants/marigold.gltf");
    std::fs::create_dir_all(w.join("plants")).unwrap();
    verdant::plants::write_plant_gltf(
        &w.join("plants/marigold.gltf"),
        &common::small_plant(),
        None,
    )
    .unwrap();
    let mut rig = Rig::with_world(&w, 16_384);
    assert_eq!(rig.manifest.plant_types.len(), 1);
    let placed = place_four_tiles(&mut rig);
    // The one type grows on the meadow tile, at both mesh levels and as cards, and nowhere on
    // the bare and high tiles.
    let per_tile = &placed.per_tile;
    assert!(per_tile[0] > 100, "marigolds on the meadow: {per_tile:?}");
    assert_eq!(&per_tile[2..], &[0, 0], "bare and high tiles: {per_tile:?}");
    assert!(placed.cpu.iter().all(|p| p.plant_type() == 0));
    let levels: std::collections::HashSet<usize> = placed.cpu.iter().map(|p| p.level()).collect();
    assert!(levels.len() >= 2, "levels placed: {levels:?}");
    assert_same_placement(&placed);
}

#[test]
fn a_heavy_gltf_plant_switches_to_its_reduced_level_nearer_as_the_cpu_mirror_does() {
    let tmp = tempfile::tempdir().unwrap();
    let w = common::world_with_plant(tmp.path(), "plants/dome.gltf");
    std::fs::create_dir_all(w.join("plants")).unwrap();
    // 19,602 triangles at 1.5 plants per m2: drawn in full within about 6.6 m.
    let dome = common::dome_plant(100);
    verdant::plants::write_plant_gltf(&w.join("plants/dome.gltf"), &dome, None).unwrap();
    let mut rig = Rig::with_world(&w, 16_384);
    let settings = *rig.plants.settings();
    let set = PlantSet::build(&rig.manifest, &w).unwrap();
    let reach = set.models[0].full_mesh_reach_m;
    assert!(
        reach > 4.0 && reach + 0.5 * settings.band_m < settings.lod_m[0],
        "{reach} m"
    );
    let placed = place_four_tiles(&mut rig);
    assert_same_placement(&placed);
    let dist = |p: &PlantInstance| glam::Vec3::from_array(p.pos).length();
    let near: Vec<f32> = placed
        .cpu
        .iter()
        .filter(|p| p.level() == 0)
        .map(dist)
        .collect();
    // Full meshes near the camera, none beyond the reach; reduced ones well within the
    // settings' switch.
    assert!(near.len() > 5, "{near:?}");
    assert!(near.iter().all(|&d| d < reach), "{reach} m: {near:?}");
    let reduced_near = placed
        .cpu
        .iter()
        .filter(|p| p.level() == 1 && dist(p) < settings.lod_m[0] - 2.0)
        .count();
    assert!(reduced_near > 50, "{reduced_near}");
}

#[test]
fn a_crowded_region_thins_the_same_plants_frame_after_frame_and_the_pool_does_not_grow() {
    let mut small = Rig::new(64);
    let level = small.manifest.pyramid.max_level();
    let cell = small.manifest.pyramid.cell_size_m(level) as f32;
    let tm = small.tile_m;
    let bytes = small.plants.pool_bytes();
    let mut work = Vec::new();
    for k in 0..4u32 {
        let t = synthetic_tile(&small.manifest, TileId::new(level, 100 + k, 100), "meadow");
        small.atlas.upload(&small.ctx.queue, k, &t).unwrap();
        let job = PlantJob::near(&TileJob {
            origin: [-tm + tm * (k % 2) as f32, 1.0 + tm * (k / 2) as f32],
            cell,
            layer: k,
            tile_x: 100 + k,
            tile_y: 100,
            lod: 0,
            slot: 0,
        });
        work.push((job, t));
    }
    let jobs: Vec<PlantJob> = work.iter().map(|w| w.0).collect();
    let camera = Camera::new(DVec3::new(0.0, 0.0, f64::from(ALTITUDE)), 90.0, -20.0);
    let (device, queue) = (&small.ctx.device.clone(), &small.ctx.queue.clone());
    // The CPU mirror's placement of the four tiles with the regions' crowding `from`: the
    // instances (sorted), the counters and what each region wanted by distance.
    let mirror =
        |params: &verdant::plants::place_cpu::PlaceParams, from: &[f32; REGIONS], hiz: &HiZ| {
            let mut instances = Vec::new();
            let mut stats = [0u32; counter::COUNT];
            let mut wanted = vec![0u32; REGIONS * CROWD_BINS];
            for (j, t) in &work {
                let out = place_tile_crowded(params, from, j, t, hiz);
                instances.extend(out.instances);
                for (s, o) in stats.iter_mut().zip(out.stats) {
                    *s += o;
                }
                for (w, o) in wanted.iter_mut().zip(out.wanted) {
                    *w += o;
                }
            }
            instances.sort_by_key(key);
            (instances, stats, wanted)
        };
    let close = |gpu: &[f32; REGIONS], cpu: &[f32; REGIONS]| {
        for r in 0..REGIONS {
            assert!(
                (gpu[r] - cpu[r]).abs() <= 1e-3 * cpu[r],
                "region {r}: crowded from {} m on the GPU against {} m on the CPU",
                gpu[r],
                cpu[r]
            );
        }
    };

    // The first frame: no region was crowded before it; the full ones drop the rest.
    let hiz = small.run(&camera, &jobs);
    let first = small.plants.read_stats(device, queue);
    let regions = small.plants.read_instances(device, queue);
    assert!(first.overflow > 0, "{first:?}");
    assert_eq!(first.crowded, 0, "{first:?}");
    assert!(regions.iter().all(|r| r.len() <= 64));
    assert_eq!(
        first.drawn as usize,
        regions.iter().map(Vec::len).sum::<usize>()
    );
    let (from, wanted) = small.plants.read_crowding(device, queue);
    let params = *small.plants.params();
    let (unthinned, _, cpu_wanted) = mirror(&params, &[UNCROWDED; REGIONS], &hiz);
    assert_eq!(
        wanted, cpu_wanted,
        "what each region wanted, GPU against CPU"
    );
    close(&from, &crowd_distances(&cpu_wanted, 64));
    assert!(
        from.iter().any(|&d| d < UNCROWDED),
        "some region is crowded"
    );

    // The next frames of the same view: every crowded region thinned to fit, nothing dropped,
    // the same plants as the CPU mirror keeps from the distances of the frame before. (A
    // crowded region culls with the sphere its plants may grow to, so the first of them may
    // want a little more than the frame before; then the same plants frame after frame.)
    let fill = verdant::plants::place_cpu::crowd_fill(64);
    let mut last: Option<([f32; REGIONS], Vec<PlantInstance>)> = None;
    for frame in 0.. {
        let (from, _) = small.plants.read_crowding(device, queue);
        let hiz = small.run(&camera, &jobs);
        let stats = small.plants.read_stats(device, queue);
        let regions = small.plants.read_instances(device, queue);
        let (cpu, cpu_stats, cpu_wanted) = mirror(&params, &from, &hiz);
        assert_eq!(stats.overflow, 0, "{stats:?}");
        assert_eq!(stats.crowded, cpu_stats[counter::CROWDED], "{stats:?}");
        assert!(stats.crowded > 0, "{stats:?}");
        let mut gpu: Vec<PlantInstance> = regions.iter().flatten().copied().collect();
        gpu.sort_by_key(key);
        assert_eq!(gpu.len(), cpu.len(), "instances, GPU against CPU");
        for (g, c) in gpu.iter().zip(&cpu) {
            assert_eq!(key(g), key(c));
            assert!((g.scale - c.scale).abs() < 1e-5, "{g:?} against {c:?}");
        }
        let (next, wanted) = small.plants.read_crowding(device, queue);
        assert_eq!(wanted, cpu_wanted);
        close(&next, &crowd_distances(&cpu_wanted, 64));
        let dist = |p: &PlantInstance| glam::Vec3::from_array(p.pos).length();
        for (r, region) in regions.iter().enumerate() {
            if from[r] < UNCROWDED {
                // Thinned to its aim at most, and every plant within the distance kept.
                assert!(region.len() as f32 <= 64.0, "region {r}: {}", region.len());
                let near = unthinned
                    .iter()
                    .filter(|p| p.plant_type() * LEVELS + p.level() == r && dist(p) <= from[r])
                    .filter(|p| region.iter().all(|q| key(q) != key(p)))
                    .count();
                assert_eq!(near, 0, "region {r}: plants within {} m thinned", from[r]);
            }
        }
        let total: usize = regions.iter().map(Vec::len).sum();
        assert!(total as f32 > 0.5 * fill, "{total} drawn");
        // A survivor grows with both thinnings together by at most what the thinning with
        // distance alone may (for the plants, the square root of 2).
        let before: std::collections::HashMap<_, _> =
            unthinned.iter().map(|p| (key(p), p.scale)).collect();
        for p in &gpu {
            if let Some(was) = before.get(&key(p)) {
                let grown = p.scale / was;
                assert!(
                    (1.0 - 1e-5..=std::f32::consts::SQRT_2 + 1e-4).contains(&grown),
                    "{p:?}: grown {grown}"
                );
            }
        }
        if let Some((last_from, last_gpu)) = &last
            && *last_from == from
        {
            assert_eq!(*last_gpu, gpu, "the same plants in consecutive frames");
            break;
        }
        assert!(frame < 4, "the crowding settles within a few frames");
        last = Some((from, gpu));
    }

    // A cut measures first: from its first frame, a fresh stage thins instead of dropping.
    let mut fresh = Rig::new(64);
    for (j, t) in &work {
        fresh.atlas.upload(&fresh.ctx.queue, j.layer, t).unwrap();
    }
    fresh.plants.set_cut(true);
    fresh.run(&camera, &jobs);
    let cut = fresh.plants.read_stats(&fresh.ctx.device, &fresh.ctx.queue);
    assert_eq!(cut.overflow, 0, "{cut:?}");
    assert!(cut.crowded > 0, "{cut:?}");
    assert_eq!(small.plants.pool_bytes(), bytes, "the pool's size is fixed");
    // The pool's size follows the capacity and the types, never the view.
    let types = small
        .manifest
        .plant_types
        .iter()
        .filter(|t| !t.is_tree())
        .count() as u64;
    assert!(bytes >= 64 * 32 * types * LEVELS as u64);
}

#[test]
fn gpu_bending_matches_the_cpu_mirror() {
    let rig = Rig::new(64);
    let set = PlantSet::build(&rig.manifest, &common::default_world()).unwrap();
    // Vertices of every type's full mesh (the probe bends vertex i of the packed meshes), each
    // as a plant of some type in some wind.
    let mut vertices: Vec<_> = set
        .models
        .iter()
        .flat_map(|m| m.lods[0].vertices.iter().copied())
        .take(400)
        .collect();
    // And the trees' (trunk, branches and leaf clusters), drawn at a tree's scale below.
    let small = vertices.len();
    for recipe in [Recipe::Broadleaf, Recipe::Conifer] {
        let tree = generate(recipe, 5, [0.1, 0.25, 0.05]);
        vertices.extend(tree.lods[0].vertices.iter().step_by(17).take(60));
    }
    let n = vertices.len();
    assert!(n >= 200);
    // The plants' layer's types (the world's trees are another layer's).
    let types = rig
        .manifest
        .plant_types
        .iter()
        .filter(|t| !t.is_tree())
        .count() as u32;
    let instances: Vec<PlantInstance> = (0..n as u32)
        .map(|i| PlantInstance {
            pos: [i as f32 * 0.1 - 20.0, 5.0 + (i % 7) as f32, -1.0],
            yaw: i as f32 * 0.37,
            scale: if (i as usize) < small {
                0.3 + (i % 5) as f32 * 0.2
            } else {
                6.0 + (i % 5) as f32 * 4.0
            },
            kind: i % types,
            hash: verdant::hash::hash_u32(i),
            fade: 1.0,
        })
        .collect();
    let winds: Vec<[f32; 4]> = (0..n)
        .map(|i| {
            let a = i as f32 * 0.21;
            [6.0 * a.cos(), 6.0 * a.sin(), 0.2 * (i % 3) as f32, 0.0]
        })
        .collect();
    // The sway springs' leans at the roots (plant heights), as the sway stage leaves them.
    let leans: Vec<[f32; 2]> = (0..n)
        .map(|i| {
            let a = i as f32 * 0.47;
            [0.3 * a.cos(), 0.3 * a.sin()]
        })
        .collect();
    // The frame's wind constants and time come from set_frame.
    let mut rig = rig;
    let camera = Camera::new(DVec3::new(0.0, 0.0, 100.0), 90.0, -10.0);
    let view_proj = camera.view_proj_relative(W as f32 / H as f32);
    let time = 3.7;
    rig.plants.set_frame(
        &rig.ctx.queue,
        time,
        Features::all(),
        camera.position,
        view_proj,
        &Frustum::from_view_proj(view_proj),
        camera.near_m,
    );
    let gpu = rig.plants.probe_bend(
        &rig.ctx.device,
        &rig.ctx.queue,
        &vertices,
        &instances,
        &winds,
        &leans,
    );
    let mut moved = 0;
    for i in 0..n {
        let t = instances[i].plant_type();
        let pw = verdant::plants::bend_cpu::PlantWindGpu::new(&rig.manifest.plant_types[t].wind);
        let (p, nrm) = verdant::plants::bend_cpu::bend_vertex(
            &vertices[i],
            &instances[i],
            Vec4::from_array(winds[i]),
            glam::Vec2::from_array(leans[i]),
            time as f32,
            &pw,
            Features::all(),
        );
        let (gp, gn) = gpu[i];
        let dp = (p - glam::Vec3::from_array(gp)).length();
        assert!(
            dp < 2e-4 * (1.0 + p.length()),
            "vertex {i}: {p} against {gp:?}"
        );
        assert!(
            (nrm - glam::Vec3::from_array(gn)).length() < 1e-3,
            "normal {i}"
        );
        let (still, _) = verdant::plants::bend_cpu::bend_vertex(
            &vertices[i],
            &instances[i],
            Vec4::ZERO,
            glam::Vec2::ZERO,
            time as f32,
            &pw,
            Features::all(),
        );
        if (still - p).length() > 1e-3 {
            moved += 1;
        }
    }
    assert!(
        moved > n / 2,
        "the wind moves most vertices: {moved} of {n}"
    );
}

/// The plants' pool through the renderer: the same bytes on every path of the default world
/// (the standing-height meadow, the tour's glide, the overview), with plants drawn on each
/// path that sees grass and none overflowing at the default capacity.
#[test]
fn the_plant_pool_is_the_same_on_every_path() {
    let drawn = pool_on_every_path(&common::default_world(), PlantLayer::Plants);
    assert!(drawn["meadow"] > 100, "{drawn:?}");
}

#[test]
fn the_tree_pool_is_the_same_on_every_path() {
    let tmp = tempfile::tempdir().unwrap();
    let w = common::world_with_trees(tmp.path(), "broadleaf", 0.02);
    let drawn = pool_on_every_path(&w, PlantLayer::Trees);
    // From the tour's height the trees reach the fog: far more of them than on the meadow.
    assert!(drawn["tour"] > 20_000 && drawn["meadow"] > 100, "{drawn:?}");
}

/// Renders the middle of the meadow, the tour and the overview with the world in `dir` (at a
/// small size): `layer`'s pool keeps its size, nothing overflows; the instances drawn per path.
fn pool_on_every_path(
    dir: &std::path::Path,
    layer: PlantLayer,
) -> std::collections::BTreeMap<&'static str, u32> {
    use verdant::camera::sample_path;
    use verdant::{FrameInput, Renderer, RendererOptions};
    let ctx = common::gpu();
    let world = World::open(dir).unwrap();
    let (c, d) = (
        wgpu::TextureFormat::Rgba8UnormSrgb,
        wgpu::TextureFormat::Depth32Float,
    );
    let (w, h) = (96, 54);
    let options = RendererOptions::new(&world, c, d, w, h);
    let paths = world.manifest.paths.clone();
    let has_trees = world.manifest.plant_types.iter().any(|t| t.is_tree());
    let mut renderer = Renderer::new(&ctx.device, &ctx.queue, world, options).unwrap();
    let pool = |r: &Renderer| match layer {
        PlantLayer::Plants => r.plant_pool_bytes(),
        PlantLayer::Trees => r.tree_pool_bytes(),
    };
    let bytes = pool(&renderer).expect("the world has the layer's types");
    // With trees, the shadow map and its casters' pool too.
    let shadow_bytes = renderer.tree_shadow_bytes();
    assert_eq!(shadow_bytes.is_some(), has_trees);
    use wgpu::TextureUsages as U;
    let color = verdant::gpu::target_texture(&ctx.device, "c", c, U::RENDER_ATTACHMENT, (w, h));
    let depth = verdant::gpu::target_texture(
        &ctx.device,
        "d",
        d,
        U::RENDER_ATTACHMENT | U::TEXTURE_BINDING,
        (w, h),
    );
    let (cv, dv) = (
        color.create_view(&Default::default()),
        depth.create_view(&Default::default()),
    );
    let mut drawn = std::collections::BTreeMap::new();
    for name in ["meadow", "tour", "overview"] {
        let path = paths.iter().find(|p| p.name == name).expect(name);
        let t_s = path.keys[path.keys.len() / 2].t_s;
        let camera = sample_path(path, t_s);
        renderer.warm_up(&camera, Duration::from_secs(60)).unwrap();
        for _ in 0..3 {
            renderer.prepare(&ctx.queue, &FrameInput::new(camera, t_s));
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            renderer.record(&mut encoder, &cv, &dv).unwrap();
            ctx.queue.submit([encoder.finish()]);
            ctx.wait_idle();
        }
        ctx.wait_idle();
        let stats = renderer.take_stats();
        let last = stats
            .last()
            .and_then(|s| match layer {
                PlantLayer::Plants => s.plants,
                PlantLayer::Trees => s.trees,
            })
            .expect("the layer's figures");
        assert_eq!(last.overflow, 0, "{name}: {last:?}");
        drawn.insert(name, last.drawn);
        assert_eq!(pool(&renderer), Some(bytes), "{name}");
        assert_eq!(renderer.tree_shadow_bytes(), shadow_bytes, "{name}");
        if layer == PlantLayer::Trees {
            let casters = renderer.read_shadow_casters();
            assert!(
                casters.len() < verdant::plants::shadow::CASTER_CAPACITY as usize,
                "{name}: {} casters",
                casters.len()
            );
        }
    }
    drawn
}
