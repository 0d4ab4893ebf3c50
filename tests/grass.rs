//! GPU grass against its CPU mirror on lavapipe: generation and culling of several tiles (flat,
//! steep, empty, densest), the bounds of the instance pool, and the low-LOD grid as a subset of
//! the high-LOD grid.

mod common;

use glam::DVec3;
use verdant::RendererConfig;
use verdant::camera::Camera;
use verdant::gpu::{GpuContext, GpuTimer};
use verdant::grass::{Blade, GrassRenderer, GrassStats, HiZ, TileBlades, TileJob, generate_tile};
use verdant::lod::Frustum;
use verdant::stream::TileAtlas;
use verdant::world::{Manifest, TileData, TileId, World};

const ALTITUDE: f32 = 106.0;
const W: u32 = 320;
const H: u32 = 180;

/// Relative tolerance of blade attributes between GPU and CPU (the same arithmetic; a GPU may
/// fuse multiply-adds, moving results by an ulp or two).
const TOLERANCE: f32 = 1e-4;

struct Rig {
    ctx: GpuContext,
    atlas: TileAtlas,
    depth: wgpu::Texture,
    color: wgpu::Texture,
    grass: GrassRenderer,
    manifest: Manifest,
    occluder: wgpu::RenderPipeline,
}

/// A wind field of 8 x 8 cells of still air, for the generation tests.
fn still_lookup() -> verdant::wind::WindLookup {
    verdant::wind::WindLookup {
        origin_cell: [0, 0],
        n: 8,
        cell_m: 1.25,
        camera_offset: [0.0; 2],
        _pad: [0.0; 2],
    }
}

/// The CPU mirror of generation followed by the wind pass in still air with every feature
/// off, as the rig's GPU runs them.
fn cpu_blades(rig: &Rig, job: &TileJob, tile: &TileData, hiz: &HiZ) -> TileBlades {
    let mut out = generate_tile(rig.grass.params(), job, tile, hiz);
    let (cells, sway) = (
        vec![[0.0f32; 4]; 64],
        vec![[0.0f32; 4]; 64 * verdant::wind::SWAY_TYPES],
    );
    verdant::grass::wind_cpu::apply_wind(
        rig.grass.wind_params(),
        &still_lookup(),
        &cells,
        &sway,
        &mut out.blades,
    );
    out
}

fn synthetic_tile(manifest: &Manifest, id: TileId, kind: &str) -> TileData {
    let s = manifest.pyramid.samples_per_side();
    let cell = manifest.pyramid.cell_size_m(id.level) as f32;
    let n = (s * s) as usize;
    let mut t = TileData {
        id,
        size: s,
        heights: vec![100.0; n],
        grass_type: vec![1; n],
        density: vec![255; n],
        material: Vec::new(),
    };
    for j in 0..s {
        for i in 0..s {
            let k = (j * s + i) as usize;
            match kind {
                "flat" => {
                    t.density[k] = 150 + ((i * 7 + j * 3) % 100) as u8;
                    // Meadow and dry grass in squares of 3x3 texels.
                    t.grass_type[k] = if (i / 3 + j / 3) % 2 == 0 { 1 } else { 3 };
                }
                "steep" => {
                    t.heights[k] = 100.0 + 0.8 * cell * i as f32 + 0.1 * cell * j as f32;
                    t.grass_type[k] = 2;
                    t.density[k] = 200;
                }
                "empty" => t.density[k] = 0,
                "densest" => t.grass_type[k] = 1,
                other => panic!("no tile kind {other}"),
            }
        }
    }
    t
}

/// The low ring's widening of the tests that check it on the GPU (the default draws no widening).
const LOD_WIDEN: f32 = 2.0;

impl Rig {
    fn new(capacity: Option<u32>) -> Self {
        Self::with_lod_widen(capacity, verdant::renderer::DEFAULT_LOD_WIDEN)
    }

    /// A rig whose low ring's blades are `lod_widen` times as wide.
    fn with_lod_widen(capacity: Option<u32>, lod_widen: f32) -> Self {
        Self::with_grass(capacity, |g| g.lod_widen = lod_widen)
    }

    /// A rig with the default grass settings changed by `change`.
    fn with_grass(
        capacity: Option<u32>,
        change: impl FnOnce(&mut verdant::renderer::GrassConfig),
    ) -> Self {
        let ctx = common::gpu();
        let world = World::open(&common::default_world()).unwrap();
        let manifest = world.manifest.clone();
        let mut config = RendererConfig::for_world(&world);
        change(&mut config.grass);
        let settings = config.grass_settings(&world).unwrap();
        let atlas = TileAtlas::new(&ctx.device, manifest.pyramid.samples_per_side(), 8);
        let target = |format, usage| {
            ctx.device.create_texture(&wgpu::TextureDescriptor {
                label: None,
                size: wgpu::Extent3d {
                    width: W,
                    height: H,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let depth = target(
            verdant::terrain::DEPTH_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
        );
        let color = target(
            verdant::terrain::COLOR_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        let capacity = match capacity {
            Some(c) => c,
            None => verdant::grass::estimate_capacity(&world, &settings).unwrap(),
        };
        // The draw reads a wind field; generation, under test here, does not: still air.
        let still = |size, usage| {
            ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: None,
                size,
                usage,
                mapped_at_creation: false,
            })
        };
        let lookup = still(
            32,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        );
        ctx.queue
            .write_buffer(&lookup, 0, bytemuck::bytes_of(&still_lookup()));
        let cells = still(8 * 8 * 16, wgpu::BufferUsages::STORAGE);
        let sway = still(
            8 * 8 * verdant::wind::SWAY_TYPES as u64 * 16,
            wgpu::BufferUsages::STORAGE,
        );
        let grass = GrassRenderer::new(
            &ctx.device,
            &ctx.queue,
            &manifest,
            &atlas,
            &verdant::gpu::Targets {
                color_format: verdant::terrain::COLOR_FORMAT,
                depth_format: verdant::terrain::DEPTH_FORMAT,
                width: W,
                height: H,
            },
            settings,
            capacity,
            verdant::grass::WindBindings {
                lookup: &lookup,
                cells: &cells,
                sway: &sway,
            },
        );
        // A wall over the left third of the screen, 30 m away: blades behind it are occluded.
        let module = ctx
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("test occluder"),
                source: wgpu::ShaderSource::Wgsl(
                    "@vertex fn vs(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
                    let x = array<f32, 6>(-1.0, -0.33, -1.0, -1.0, -0.33, -0.33);
                    let y = array<f32, 6>(-1.0, -1.0, 1.0, 1.0, -1.0, 1.0);
                    return vec4<f32>(x[i], y[i], 0.5 / 30.0, 1.0);
                }"
                    .into(),
                ),
            });
        let occluder = ctx
            .device
            .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("test occluder"),
                layout: None,
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                primitive: Default::default(),
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: verdant::terrain::DEPTH_FORMAT,
                    depth_write_enabled: Some(true),
                    depth_compare: Some(wgpu::CompareFunction::Always),
                    stencil: Default::default(),
                    bias: Default::default(),
                }),
                multisample: Default::default(),
                fragment: None,
                multiview_mask: None,
                cache: None,
            });
        Self {
            ctx,
            atlas,
            depth,
            color,
            grass,
            manifest,
            occluder,
        }
    }

    /// Runs the grass stage for `jobs` (tiles already in the atlas) and returns the GPU stats
    /// and the Hi-Z the generation saw.
    fn run(&mut self, camera: &Camera, jobs: &[TileJob]) -> (GrassStats, HiZ) {
        let view_proj = camera.view_proj_relative(W as f32 / H as f32);
        self.grass
            .set_frame(0.0, 1.0, verdant::features::Features::none(), DVec3::ZERO);
        self.grass.set_camera(
            &self.ctx.queue,
            view_proj,
            &Frustum::from_view_proj(view_proj),
            camera.position.z as f32,
            camera.near_m,
        );
        let mut timer = GpuTimer::new(&self.ctx.device, &self.ctx.queue, false, 0);
        let dv = self.depth.create_view(&Default::default());
        let cv = self.color.create_view(&Default::default());
        let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
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
            pass.set_pipeline(&self.occluder);
            pass.draw(0..6, 0..1);
        }
        self.grass
            .hiz
            .record(&self.ctx.device, &mut encoder, &dv, &mut timer);
        let tiles = self.grass.record(
            &self.ctx.queue,
            &mut encoder,
            jobs,
            &cv,
            None,
            &dv,
            &mut timer,
        );
        self.ctx.queue.submit([encoder.finish()]);
        let stats = self
            .grass
            .read_stats(&self.ctx.device, &self.ctx.queue, tiles);
        let hiz = self.grass.hiz.read_back(&self.ctx.device, &self.ctx.queue);
        (stats, hiz)
    }
}

fn camera() -> Camera {
    // Above the tiles' south edge, looking north and down.
    Camera::new(DVec3::new(0.0, 0.0, f64::from(ALTITUDE)), 90.0, -25.0)
}

fn job(k: usize, layer: u32, lod: u32, cell: f32) -> TileJob {
    TileJob {
        origin: [-40.0 + 20.0 * (k % 4) as f32, 4.0 + 8.0 * (k / 4) as f32],
        cell,
        layer,
        tile_x: 1000 + k as u32,
        tile_y: 2000,
        lod,
        slot: 0,
    }
}

/// Grass types meet along clump borders, not along the map's texel edges: the blades of a
/// clump (its colour, from the clump's hash) share one type, but for those mixed in near its
/// border; the map's squares of types are smaller than a clump, so texel edges would split most
/// clumps.
fn assert_types_follow_clumps(blades: &[Blade]) {
    let mut clumps: std::collections::HashMap<u32, [usize; 16]> = Default::default();
    for b in blades {
        clumps.entry(b.color).or_default()[(b.kind & 0xff) as usize] += 1;
    }
    let (mut majority, mut total) = (0usize, 0usize);
    let mut mixed_types = false;
    for counts in clumps.values().filter(|c| c.iter().sum::<usize>() >= 8) {
        majority += counts.iter().max().unwrap();
        total += counts.iter().sum::<usize>();
        mixed_types |= counts[1] > 0 && counts[3] > 0;
    }
    assert!(total > 500, "too few blades in clumps: {total}");
    let share = majority as f64 / total as f64;
    eprintln!("blades of their clump's main type: {share:.3} of {total}");
    assert!(share > 0.85, "clumps are split between types: {share:.3}");
    assert!(mixed_types, "no clump border mixes types");
    let types: std::collections::HashSet<u32> = blades.iter().map(|b| b.kind & 0xff).collect();
    assert!(
        types.contains(&1) && types.contains(&3),
        "both types grow: {types:?}"
    );
}

fn key(b: &Blade) -> (u32, u32, u32) {
    (b.hash, b.pos[0].to_bits(), b.pos[1].to_bits())
}

fn assert_blades_match(gpu: &[Blade], cpu: &[Blade], what: &str) {
    assert_eq!(gpu.len(), cpu.len(), "{what}: blade counts differ");
    let mut g = gpu.to_vec();
    let mut c = cpu.to_vec();
    g.sort_by_key(|b| (b.hash, b.kind));
    c.sort_by_key(|b| (b.hash, b.kind));
    let close = |a: f32, b: f32| (a - b).abs() <= TOLERANCE * (1.0 + a.abs().max(b.abs()));
    for (a, b) in g.iter().zip(&c) {
        assert_eq!(
            (a.hash, a.kind, a.color),
            (b.hash, b.kind, b.color),
            "{what}: blade identity differs"
        );
        let fa = [
            a.pos[0],
            a.pos[1],
            a.pos[2],
            a.facing,
            a.growth[0],
            a.growth[1],
            a.height,
            a.width,
            a.tilt,
            a.bend,
            a.side_curve,
            a.wind,
            a.fade,
        ];
        let fb = [
            b.pos[0],
            b.pos[1],
            b.pos[2],
            b.facing,
            b.growth[0],
            b.growth[1],
            b.height,
            b.width,
            b.tilt,
            b.bend,
            b.side_curve,
            b.wind,
            b.fade,
        ];
        for (i, (x, y)) in fa.iter().zip(&fb).enumerate() {
            assert!(
                close(*x, *y),
                "{what}: blade {:#x} attribute {i}: GPU {x} CPU {y}",
                a.hash
            );
        }
    }
}

#[test]
fn gpu_generation_matches_the_cpu_mirror_on_flat_steep_empty_and_densest_tiles() {
    // The low ring widened, so that the widening (the low job, the high tiles' fade band) is
    // compared too.
    let mut rig = Rig::with_lod_widen(None, LOD_WIDEN);
    let level = rig.manifest.pyramid.max_level();
    let cell = rig.manifest.pyramid.cell_size_m(level) as f32;
    // The flat tile's near blades are a job of their own (LOD 2), in the second half's slot.
    let kinds = ["flat", "steep", "empty", "densest", "flat near"];
    let mut tiles = Vec::new();
    let mut jobs = Vec::new();
    for (k, kind) in kinds.iter().enumerate().take(4) {
        let j = job(k, k as u32, if k == 3 { 1 } else { 0 }, cell);
        let t = synthetic_tile(&rig.manifest, TileId::new(level, j.tile_x, j.tile_y), kind);
        rig.atlas.upload(&rig.ctx.queue, k as u32, &t).unwrap();
        tiles.push(t);
        jobs.push(j);
    }
    tiles.push(tiles[0].clone());
    jobs.push(TileJob { lod: 2, ..jobs[0] });
    let (stats, hiz) = rig.run(&camera(), &jobs);
    let mut cpu_total = verdant::grass::GenerateStats::default();
    for (k, kind) in kinds.iter().enumerate() {
        let cpu: TileBlades = cpu_blades(&rig, &jobs[k], &tiles[k], &hiz);
        let (args, gpu) =
            rig.grass
                .read_slot(&rig.ctx.device, &rig.ctx.queue, k / 4, (k % 4) as u32);
        let segments = rig.grass.settings().segments;
        let vertices = 2 * segments[[1, 2, 0][jobs[k].lod as usize]] + 1;
        assert_eq!(
            args,
            [vertices, cpu.blades.len() as u32, 0, 0],
            "{kind}: indirect args"
        );
        assert_blades_match(&gpu, &cpu.blades, kind);
        if *kind == "flat" {
            assert_types_follow_clumps(&cpu.blades);
        }
        for l in 0..2 {
            for c in 0..8 {
                cpu_total.counts[l][c] += cpu.stats.counts[l][c];
            }
        }
        eprintln!(
            "{kind}: {} blades, counters {:?}",
            cpu.blades.len(),
            cpu.stats.counts
        );
        if *kind == "empty" {
            assert!(cpu.blades.is_empty());
        } else {
            assert!(!cpu.blades.is_empty(), "{kind}: expected blades");
        }
    }
    assert_eq!(
        stats.to_generate_stats(),
        cpu_total,
        "GPU and CPU counters differ"
    );
    // Every culling test did some work in this view.
    let s = &cpu_total.counts[0];
    use verdant::grass::generate_cpu::counter;
    // The flat tile reaches within the infill radii of the camera: its near cells were filled
    // in, so its two jobs looked at more points than its grid has.
    let g = rig.grass.params().grid[0];
    let flat: Vec<TileBlades> = [0, 4]
        .map(|k| cpu_blades(&rig, &jobs[k], &tiles[k], &hiz))
        .into();
    let considered: u32 = flat
        .iter()
        .map(|b| b.stats.counts[0][counter::CONSIDERED])
        .sum();
    assert!(
        considered > g * g,
        "no infill: {considered} points for a grid of {g}x{g}"
    );
    // Its two jobs split its blades: together they are the blades of one job with no near
    // radius, each once.
    assert!(!flat[1].blades.is_empty(), "no near blades");
    let mut whole = *rig.grass.params();
    whole.near[0] = 0.0;
    let all = generate_tile(&whole, &jobs[0], &tiles[0], &hiz);
    let mut split: Vec<_> = flat.iter().flat_map(|b| b.blades.iter().map(key)).collect();
    let mut one: Vec<_> = all.blades.iter().map(key).collect();
    split.sort();
    one.sort();
    assert_eq!(
        split, one,
        "the near job and the rest are not a partition of the tile"
    );
    for (c, name) in [
        (counter::DISTANCE, "distance"),
        (counter::FRUSTUM, "frustum"),
        (counter::OCCLUSION, "occlusion"),
    ] {
        assert!(s[c] > 0, "no blade was culled by {name}: {s:?}");
    }
}

/// The blades' fade at the view distance counts the camera's height above them
/// (`GrassConfig::elevation_fade` metres a metre), on the GPU as its mirror says: seen from 12 m
/// above a flat tile, the more each metre counts, the nearer the blades end.
#[test]
fn the_far_fade_by_the_cameras_height_matches_the_cpu_mirror() {
    let mut drawn = Vec::new();
    for k in [0.0f32, 1.0, 3.0] {
        let mut rig = Rig::with_grass(None, |g| g.elevation_fade = k);
        assert_eq!(rig.grass.params().near[2], k);
        let level = rig.manifest.pyramid.max_level();
        let cell = rig.manifest.pyramid.cell_size_m(level) as f32;
        let flat = synthetic_tile(&rig.manifest, TileId::new(level, 3, 5), "flat");
        rig.atlas.upload(&rig.ctx.queue, 0, &flat).unwrap();
        // A tile from 5 m ahead of the camera to past the view distance.
        let mut tile = job(0, 0, 0, cell);
        tile.origin = [-25.0, 5.0];
        let camera = Camera::new(DVec3::new(0.0, 0.0, 112.0), 90.0, -12.0);
        let (stats, hiz) = rig.run(&camera, &[tile]);
        let cpu = cpu_blades(&rig, &tile, &flat, &hiz);
        let (_, gpu) = rig.grass.read_slot(&rig.ctx.device, &rig.ctx.queue, 0, 0);
        assert_blades_match(&gpu, &cpu.blades, &format!("elevation fade {k}"));
        assert_eq!(stats.to_generate_stats(), cpu.stats, "elevation fade {k}");
        // Every blade drawn stands before the view distance by its fade's distance.
        let view = rig.grass.params().ranges[3];
        for b in &cpu.blades {
            let p = glam::Vec3::from_array(b.pos);
            let faded_at = verdant::terrain::far_field::far_distance(p.length(), -p.z, k);
            assert!(
                faded_at < view,
                "elevation fade {k}: a blade at {faded_at} m"
            );
        }
        drawn.push(cpu.blades.len());
    }
    eprintln!("blades drawn with the term at 0, 1 and 3: {drawn:?}");
    assert!(
        drawn[0] > drawn[1] && drawn[1] > drawn[2] && drawn[2] > 0,
        "blades drawn with the term at 0, 1 and 3: {drawn:?}"
    );
}

#[test]
fn an_overflowing_tile_is_clamped_and_counted_without_touching_its_neighbours() {
    let mut rig = Rig::new(Some(1000));
    let level = rig.manifest.pyramid.max_level();
    let cell = rig.manifest.pyramid.cell_size_m(level) as f32;
    let dense = synthetic_tile(&rig.manifest, TileId::new(level, 1000, 2000), "densest");
    let flat = synthetic_tile(&rig.manifest, TileId::new(level, 1001, 2000), "empty");
    rig.atlas.upload(&rig.ctx.queue, 0, &dense).unwrap();
    rig.atlas.upload(&rig.ctx.queue, 1, &flat).unwrap();
    let jobs = [job(2, 0, 0, cell), job(3, 1, 0, cell)];
    let (stats, hiz) = rig.run(&camera(), &jobs);
    let capacity = rig.grass.capacity();
    let cpu = generate_tile(rig.grass.params(), &jobs[0], &dense, &hiz);
    assert!(
        cpu.wanted > capacity,
        "the test tile should overflow: {} <= {capacity}",
        cpu.wanted
    );
    let (args, gpu) = rig.grass.read_slot(&rig.ctx.device, &rig.ctx.queue, 0, 0);
    assert_eq!(args[1], capacity, "clamped to the slot");
    assert_eq!(stats.overflow[0], cpu.wanted - capacity);
    assert_eq!(stats.drawn[0], capacity);
    // Which blades won the race to the slot differs between GPU and CPU; all are real ones.
    let cpu_all = generate_tile(
        &{
            let mut p = *rig.grass.params();
            p.limits[1] = u32::MAX;
            p
        },
        &jobs[0],
        &dense,
        &hiz,
    );
    let known: std::collections::HashSet<(u32, u32, u32)> =
        cpu_all.blades.iter().map(key).collect();
    assert!(
        gpu.iter().all(|b| known.contains(&key(b))),
        "a blade in the slot is not one the tile generates"
    );
    // The neighbouring slot is intact (its tile is empty: zero blades, zero args).
    let (args1, _) = rig.grass.read_slot(&rig.ctx.device, &rig.ctx.queue, 0, 1);
    let high = 2 * rig.grass.settings().segments[1] + 1;
    assert_eq!(args1, [high, 0, 0, 0]);
}

#[test]
fn more_tiles_than_slots_are_all_drawn() {
    let mut rig = Rig::new(None);
    let level = rig.manifest.pyramid.max_level();
    let cell = rig.manifest.pyramid.cell_size_m(level) as f32;
    let flat = synthetic_tile(&rig.manifest, TileId::new(level, 0, 0), "flat");
    rig.atlas.upload(&rig.ctx.queue, 0, &flat).unwrap();
    // Eleven tiles in a row, all reading the same data: three batches through two halves.
    let jobs: Vec<TileJob> = (0..11).map(|k| job(k, 0, (k % 2) as u32, cell)).collect();
    let (stats, hiz) = rig.run(&camera(), &jobs);
    assert_eq!(stats.tiles, [6, 5]);
    let mut drawn = [0u32; 2];
    let mut considered = [0u32; 2];
    for j in &jobs {
        let cpu = generate_tile(rig.grass.params(), j, &flat, &hiz);
        drawn[j.lod as usize] += cpu.blades.len() as u32;
        considered[j.lod as usize] += cpu.stats.counts[j.lod as usize][0];
    }
    assert_eq!(stats.considered, considered);
    assert_eq!(stats.drawn, drawn, "every tile's blades are drawn");
    assert_eq!(
        rig.grass.pool_bytes(),
        2 * (4 * u64::from(rig.grass.capacity()) * 96 + 16 + 64)
    );
}

#[test]
fn the_low_lod_grid_is_a_subset_of_the_high_lod_grid() {
    let mut rig = Rig::with_lod_widen(None, LOD_WIDEN);
    let level = rig.manifest.pyramid.max_level();
    let cell = rig.manifest.pyramid.cell_size_m(level) as f32;
    let flat = synthetic_tile(&rig.manifest, TileId::new(level, 7, 9), "flat");
    rig.atlas.upload(&rig.ctx.queue, 0, &flat).unwrap();
    // Far from the camera, but before the view distance: no LOD fade, little culling.
    let mut high = job(0, 0, 0, cell);
    high.origin = [-25.0, 45.0];
    let low = TileJob { lod: 1, ..high };
    let (_, hiz) = rig.run(
        &Camera::new(
            DVec3::new(0.0, 0.0, f64::from(ALTITUDE) + 10.0),
            90.0,
            -10.0,
        ),
        &[high, low],
    );
    let mut params = *rig.grass.params();
    params.ranges = [1e6, 2e6, 3e6, 4e6]; // no distance culling, no fade
    // The low ring's blades at their own width first (widened, their culling spheres grow).
    let k = params.near[1];
    params.near[1] = 1.0;
    let h = generate_tile(&params, &high, &flat, &hiz);
    let l = generate_tile(&params, &low, &flat, &hiz);
    assert!(!l.blades.is_empty() && l.blades.len() < h.blades.len());
    let high_at: std::collections::HashMap<u32, &Blade> =
        h.blades.iter().map(|b| (b.hash, b)).collect();
    for b in &l.blades {
        let twin = high_at
            .get(&b.hash)
            .expect("a low-LOD blade missing from the high-LOD grid");
        assert_eq!(
            (twin.pos, twin.height, twin.facing),
            (b.pos, b.height, b.facing)
        );
    }
    // About a quarter of the high blades survive at low LOD (every other point each way).
    let ratio = l.blades.len() as f64 / h.blades.len() as f64;
    assert!((0.2..0.3).contains(&ratio), "low/high ratio {ratio}");
    // Widened (GrassConfig::lod_widen), in the low ring they are drawn that many times as
    // wide, keeping the others' cover.
    assert_eq!(k, LOD_WIDEN);
    params.near[1] = k;
    let l = generate_tile(&params, &low, &flat, &hiz);
    let twins = l
        .blades
        .iter()
        .filter(|b| high_at.contains_key(&b.hash))
        .count();
    assert!(twins as f64 >= 0.98 * l.blades.len() as f64);
    for b in l.blades.iter().filter(|b| high_at.contains_key(&b.hash)) {
        let twin = high_at[&b.hash];
        assert!(
            (b.width - k * twin.width).abs() <= 1e-6 * b.width,
            "low-LOD blade {} m wide, its high-LOD twin {} m",
            b.width,
            twin.width
        );
    }
    // Within the LOD fade band the blades the low grid keeps widen toward it as the others
    // shrink: here the band spans the tile.
    let dists: Vec<f32> = h
        .blades
        .iter()
        .map(|b| glam::Vec3::from(b.pos).length())
        .collect();
    let (near, far) = dists
        .iter()
        .fold((f32::MAX, 0f32), |(a, b), &d| (a.min(d), b.max(d)));
    let mut banded = params;
    banded.ranges[0] = near;
    banded.ranges[1] = far + 1.0;
    let hb = generate_tile(&banded, &high, &flat, &hiz);
    let kept: std::collections::HashSet<u32> = l.blades.iter().map(|b| b.hash).collect();
    let (mut widened, mut shrunk) = (0, 0);
    for b in hb.blades.iter().filter(|b| high_at.contains_key(&b.hash)) {
        // (A short blade's second half stands beside it with its width: the ratios hold.)
        let own = high_at[&b.hash].width;
        if kept.contains(&b.hash) {
            assert!(
                b.width >= own * 0.999 && b.width <= k * own * 1.001 && b.fade == 1.0,
                "a kept blade {} m wide, its own width {own} m",
                b.width
            );
            widened += usize::from(b.width > own * 1.01);
        } else {
            assert!(
                (b.width - own * b.fade).abs() <= 1e-6 && b.fade < 1.0,
                "a dropped blade {} m wide at fade {}, its own width {own} m",
                b.width,
                b.fade
            );
            shrunk += usize::from(b.width < own * 0.99);
        }
    }
    assert!(
        widened > 10 && shrunk > 10,
        "{widened} widened, {shrunk} shrunk"
    );
    // The GPU agrees: its low slot holds the CPU's low blades, widened.
    let (_, gpu_low) = rig.grass.read_slot(&rig.ctx.device, &rig.ctx.queue, 0, 1);
    let cpu_low = cpu_blades(&rig, &low, &flat, &hiz);
    assert!(!cpu_low.blades.is_empty(), "no low-LOD blade in view");
    assert!(
        cpu_low.blades.iter().any(|b| high_at.contains_key(&b.hash)
            && (b.width - k * high_at[&b.hash].width).abs() <= 1e-6 * b.width),
        "no widened blade in the low slot"
    );
    assert_blades_match(&gpu_low, &cpu_low.blades, "low LOD");
}

#[test]
fn the_hiz_pyramid_matches_its_cpu_mirror() {
    let mut rig = Rig::new(Some(64));
    let (_, hiz) = rig.run(&camera(), &[]);
    let (w, h, level0) = &hiz.mips[0];
    // Level 0 is the depth buffer: the wall over the left third, nothing elsewhere.
    let wall = level0.iter().filter(|d| **d > 0.0).count();
    assert_eq!(wall, (W as f32 * 0.335).round() as usize * H as usize);
    let cpu = verdant::grass::hiz_cpu::build_hiz(*w, *h, level0);
    assert_eq!(cpu.mips.len(), hiz.mips.len());
    for (m, (g, c)) in hiz.mips.iter().zip(&cpu.mips).enumerate() {
        assert_eq!((g.0, g.1), (c.0, c.1), "level {m} size");
        assert_eq!(g.2, c.2, "level {m} differs");
    }
}

/// The wind pass (`shaders/grass_wind.wgsl`) on generated blades against its CPU mirror
/// (`grass::wind_cpu::apply_wind`), in the storm, after a few frames of sway.
#[test]
fn gpu_wind_on_blades_matches_the_cpu_mirror() {
    use verdant::grass::wind_cpu::apply_wind;
    use verdant::wind::{SwayConfig, SwayField, WindConfig, WindField};
    let ctx = common::gpu();
    let world = World::open(&common::default_world()).unwrap();
    let manifest = world.manifest.clone();
    let settings = RendererConfig::for_world(&world)
        .grass_settings(&world)
        .unwrap();
    let atlas = TileAtlas::new(&ctx.device, manifest.pyramid.samples_per_side(), 2);
    let target = |format, usage| {
        ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: None,
            size: wgpu::Extent3d {
                width: W,
                height: H,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        })
    };
    let depth = target(
        verdant::terrain::DEPTH_FORMAT,
        wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
    );
    let color = target(
        verdant::terrain::COLOR_FORMAT,
        wgpu::TextureUsages::RENDER_ATTACHMENT,
    );
    let config = WindConfig::from_scene(&manifest, Some("storm")).unwrap();
    let mut wind = WindField::new(&ctx.device, &ctx.queue, &config);
    let mut sway = SwayField::new(
        &ctx.device,
        SwayConfig::from_manifest(&manifest),
        config.cells,
        wind.buffer(),
    );
    sway.reset(&ctx.queue);
    let mut grass = GrassRenderer::new(
        &ctx.device,
        &ctx.queue,
        &manifest,
        &atlas,
        &verdant::gpu::Targets {
            color_format: verdant::terrain::COLOR_FORMAT,
            depth_format: verdant::terrain::DEPTH_FORMAT,
            width: W,
            height: H,
        },
        settings,
        verdant::grass::estimate_capacity(&world, &settings).unwrap(),
        verdant::grass::WindBindings {
            lookup: wind.lookup_uniform(),
            cells: wind.buffer(),
            sway: sway.buffer(),
        },
    );
    let level = manifest.pyramid.max_level();
    let cell = manifest.pyramid.cell_size_m(level) as f32;
    let tile = synthetic_tile(&manifest, TileId::new(level, 1000, 2000), "flat");
    atlas.upload(&ctx.queue, 0, &tile).unwrap();
    let job = job(1, 0, 0, cell);
    let cam = camera();
    let world_cam = DVec3::new(20_000.0, 28_000.0, f64::from(ALTITUDE));
    let view_proj = cam.view_proj_relative(W as f32 / H as f32);
    let (dv, cv) = (
        depth.create_view(&Default::default()),
        color.create_view(&Default::default()),
    );
    let mut timer = GpuTimer::new(&ctx.device, &ctx.queue, false, 0);
    for k in 0..4 {
        let t = 3.0 + f64::from(k) / 30.0;
        grass.set_frame(
            t,
            config.ambient.speed_mps as f32,
            verdant::features::Features::all(),
            world_cam,
        );
        // The blades' motion over the frame's step, for the motion vectors.
        grass.set_motion(1.0 / 30.0, view_proj, view_proj);
        grass.set_camera(
            &ctx.queue,
            view_proj,
            &Frustum::from_view_proj(view_proj),
            ALTITUDE,
            cam.near_m,
        );
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        // The walker crosses the tile, so that the trail's push (and its lean) is compared too.
        let walker = glam::DVec2::new(world_cam.x + 3.0 + f64::from(k), world_cam.y + 30.0);
        wind.update(
            &ctx.queue,
            &mut encoder,
            world_cam,
            t,
            1.0 / 30.0,
            Some(walker),
            &mut timer,
        );
        sway.update(
            &ctx.queue,
            &mut encoder,
            &wind.lookup(),
            1.0 / 30.0,
            &mut timer,
        );
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
        grass.hiz.record(&ctx.device, &mut encoder, &dv, &mut timer);
        grass.record(&ctx.queue, &mut encoder, &[job], &cv, None, &dv, &mut timer);
        ctx.queue.submit([encoder.finish()]);
        ctx.wait_idle();
    }
    let (_, gpu) = grass.read_slot(&ctx.device, &ctx.queue, 0, 0);
    let cells = wind.read_back(&ctx.device, &ctx.queue);
    let (sway_state, _) = sway.read_back(&ctx.device, &ctx.queue);
    let hiz = grass.hiz.read_back(&ctx.device, &ctx.queue);
    let mut cpu = generate_tile(grass.params(), &job, &tile, &hiz).blades;
    apply_wind(
        grass.wind_params(),
        &wind.lookup(),
        &cells,
        &sway_state,
        &mut cpu,
    );
    assert_eq!(gpu.len(), cpu.len());
    assert!(gpu.len() > 100, "too few blades: {}", gpu.len());
    let mut g = gpu.clone();
    g.sort_by_key(|b| (b.hash, b.kind));
    cpu.sort_by_key(|b| (b.hash, b.kind));
    let trampled = cpu
        .iter()
        .filter(|b| {
            let w = verdant::wind::field_cpu::wind_at(
                &wind.lookup(),
                &cells,
                glam::Vec2::new(b.pos[0], b.pos[1]),
            );
            w[2].hypot(w[3]) > 0.3
        })
        .count();
    assert!(
        trampled > 10,
        "only {trampled} blades in the walker's trail"
    );
    let mut worst = 0.0f32;
    let mut max_lean = 0.0f32;
    let mut max_moved = [0.0f32; 3];
    for (a, b) in g.iter().zip(&cpu) {
        assert_eq!(a.hash, b.hash);
        for (x, y) in [a.lean[0], a.lean[1], a.sway, a.flutter, a.fade]
            .iter()
            .chain(&a.moved)
            .zip(
                [b.lean[0], b.lean[1], b.sway, b.flutter, b.fade]
                    .iter()
                    .chain(&b.moved),
            )
        {
            worst = worst.max((x - y).abs());
        }
        max_moved[0] = max_moved[0].max(a.moved[0].hypot(a.moved[1]));
        max_moved[1] = max_moved[1].max(a.moved[2].abs());
        max_moved[2] = max_moved[2].max(a.moved[3].abs());
        for s in [0, 8, 16] {
            let (ca, cb) = ((a.color >> s) & 255, (b.color >> s) & 255);
            assert!(ca.abs_diff(cb) <= 1, "colour channels differ: {ca} vs {cb}");
        }
        max_lean = max_lean.max(a.lean[0].hypot(a.lean[1]));
    }
    eprintln!(
        "wind pass: {} blades, largest difference {worst:e}, largest lean {max_lean}",
        g.len()
    );
    assert!(
        worst <= 1e-4,
        "GPU and CPU wind on blades differ by {worst}"
    );
    assert!(
        max_lean > 0.05,
        "the storm should lean the blades: {max_lean}"
    );
    // In the storm every part of the blades' motion is there to compare: the springs' lean,
    // the sway and the flutter each changed over the step.
    assert!(
        max_moved.iter().all(|&m| m > 1e-3),
        "the blades' motion over the step (lean, sway, flutter): {max_moved:?}"
    );
}

#[test]
fn every_slot_holds_its_own_tiles_blades_after_a_half_is_reused() {
    let mut rig = Rig::new(None);
    let level = rig.manifest.pyramid.max_level();
    let cell = rig.manifest.pyramid.cell_size_m(level) as f32;
    let flat = synthetic_tile(&rig.manifest, TileId::new(level, 0, 0), "flat");
    let steep = synthetic_tile(&rig.manifest, TileId::new(level, 1, 0), "steep");
    rig.atlas.upload(&rig.ctx.queue, 0, &flat).unwrap();
    rig.atlas.upload(&rig.ctx.queue, 1, &steep).unwrap();
    // Eleven tiles at eleven places, alternating data and LOD: batches 0..4 (half A), 4..8
    // (half B) and 8..11 (half A again, over the first batch's blades).
    let jobs: Vec<TileJob> = (0..11)
        .map(|k| job(k, (k % 2) as u32, ((k / 2) % 2) as u32, cell))
        .collect();
    let (_, hiz) = rig.run(&camera(), &jobs);
    let tiles = [&flat, &steep];
    let mut seen_blades = 0;
    for (half, range) in [(0usize, 8..11usize), (1, 4..8)] {
        for (k, j) in range.enumerate() {
            let cpu = cpu_blades(&rig, &jobs[j], tiles[j % 2], &hiz);
            let (args, gpu) = rig
                .grass
                .read_slot(&rig.ctx.device, &rig.ctx.queue, half, k as u32);
            let segments = rig.grass.settings().segments;
            let vertices = 2 * segments[[1, 2, 0][jobs[j].lod as usize]] + 1;
            assert_eq!(
                args,
                [vertices, cpu.blades.len() as u32, 0, 0],
                "job {j} in half {half} slot {k}: indirect args"
            );
            assert_blades_match(
                &gpu,
                &cpu.blades,
                &format!("job {j} in half {half} slot {k}"),
            );
            seen_blades += gpu.len();
        }
    }
    assert!(seen_blades > 0, "the view should hold blades");
}

#[test]
fn an_overflow_leaves_the_neighbouring_slots_blades_intact() {
    let mut rig = Rig::new(Some(1000));
    let level = rig.manifest.pyramid.max_level();
    let cell = rig.manifest.pyramid.cell_size_m(level) as f32;
    let dense = synthetic_tile(&rig.manifest, TileId::new(level, 1000, 2000), "densest");
    // Grass on one row in eight: a sparse tile whose blades fit the slot.
    let mut sparse = synthetic_tile(&rig.manifest, TileId::new(level, 1001, 2000), "flat");
    let size = sparse.size as usize;
    for (k, d) in sparse.density.iter_mut().enumerate() {
        if !(k / size).is_multiple_of(8) {
            *d = 0;
        }
    }
    rig.atlas.upload(&rig.ctx.queue, 0, &dense).unwrap();
    rig.atlas.upload(&rig.ctx.queue, 1, &sparse).unwrap();
    // The dense tile overflows slot 0; slot 1 holds a low-LOD tile of sparse grass that fits.
    let jobs = [job(2, 0, 0, cell), job(11, 1, 1, cell)];
    let (stats, hiz) = rig.run(&camera(), &jobs);
    let capacity = rig.grass.capacity();
    assert!(
        stats.overflow[0] > 0,
        "slot 0 should overflow: {:?}",
        stats.overflow
    );
    let cpu = cpu_blades(&rig, &jobs[1], &sparse, &hiz);
    assert!(
        !cpu.blades.is_empty() && (cpu.blades.len() as u32) < capacity,
        "the neighbour should have blades that fit: {}",
        cpu.blades.len()
    );
    let (args, gpu) = rig.grass.read_slot(&rig.ctx.device, &rig.ctx.queue, 0, 1);
    let low = 2 * rig.grass.settings().segments[2] + 1;
    assert_eq!(args, [low, cpu.blades.len() as u32, 0, 0]);
    assert_blades_match(&gpu, &cpu.blades, "the overflowing tile's neighbour");
}

#[test]
fn more_jobs_than_the_job_buffer_holds_are_cut_at_its_size() {
    let mut rig = Rig::new(None);
    let level = rig.manifest.pyramid.max_level();
    let cell = rig.manifest.pyramid.cell_size_m(level) as f32;
    let flat = synthetic_tile(&rig.manifest, TileId::new(level, 0, 0), "flat");
    rig.atlas.upload(&rig.ctx.queue, 0, &flat).unwrap();
    let max = verdant::grass::renderer::MAX_JOBS as usize;
    // Low-LOD tiles far behind the camera: every point is considered, none is drawn.
    let far = |k: usize| TileJob {
        origin: [
            -40.0 + 20.0 * (k % 4) as f32,
            -5000.0 - 8.0 * (k / 4) as f32,
        ],
        ..job(k, 0, 1, cell)
    };
    let jobs: Vec<TileJob> = (0..max + 6).map(far).collect();
    let (stats, hiz) = rig.run(&camera(), &jobs);
    assert_eq!(
        stats.tiles,
        [0, max as u32],
        "tiles beyond the job buffer were generated"
    );
    let one = generate_tile(rig.grass.params(), &jobs[0], &flat, &hiz);
    assert!(one.stats.counts[1][0] > 0);
    assert_eq!(
        stats.considered[1],
        max as u32 * one.stats.counts[1][0],
        "every job in the buffer considered its points once"
    );
    assert_eq!(stats.drawn, [0, 0]);
}

/// A world of coarse cells asks for a pool larger than the device binds: the pool is clamped to
/// what a binding holds (its densest tiles then overflow, counted) instead of failing.
#[test]
fn a_pool_larger_than_the_device_binds_is_clamped_and_still_draws() {
    let mut rig = Rig::new(Some(u32::MAX / 4));
    let limits = rig.ctx.device.limits();
    let bind = limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size);
    let blade = std::mem::size_of::<verdant::grass::Blade>() as u64;
    let capacity = u64::from(rig.grass.capacity());
    assert!(
        capacity >= 16 && capacity * blade * 4 <= bind,
        "{capacity} blades a slot"
    );
    let level = rig.manifest.pyramid.max_level();
    let cell = rig.manifest.pyramid.cell_size_m(level) as f32;
    let flat = synthetic_tile(&rig.manifest, TileId::new(level, 0, 0), "flat");
    rig.atlas.upload(&rig.ctx.queue, 0, &flat).unwrap();
    let (stats, _) = rig.run(&camera(), &[job(0, 0, 0, cell)]);
    assert!(stats.drawn[0] > 0, "{stats:?}");
}
