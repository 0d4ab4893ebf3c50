//! Child tiles derived on the GPU (`shaders/stream_derive.wgsl`) against the CPU mirror
//! (`src/stream/derive_cpu.rs`), seams between derived neighbours, and determinism.

mod common;

use verdant::gpu::{GpuContext, GpuTimer};
use verdant::stream::calibrate::{MIN_DECAY_LOG2, SCALE_INVARIANT_TREND_LOG2};
use verdant::stream::{DeriveJob, DeriveParams, DeriveStage, TileAtlas, derive_child};
use verdant::tools::eval_derive as eval;
use verdant::world::{DeriveMode, Pyramid, TileData, TileId, World};

/// Largest height difference allowed between GPU and CPU, metres. The two run the same
/// arithmetic in the same order; a GPU may fuse a multiply and an add, which moves the result
/// by an ulp or two of the height (about 1e-4 m at 1000 m). On llvmpipe the two agree bit for
/// bit.
const HEIGHT_TOLERANCE_M: f32 = 2e-3;

struct Rig {
    ctx: GpuContext,
    atlas: TileAtlas,
    stage: DeriveStage,
    pyramid: Pyramid,
    params: DeriveParams,
}

impl Rig {
    fn new(world: &World, slots: u32) -> Self {
        Self::with_params(world, slots, DeriveParams::default())
    }

    fn with_params(world: &World, slots: u32, params: DeriveParams) -> Self {
        let ctx = common::gpu();
        let pyramid = world.manifest.pyramid.clone();
        let atlas = TileAtlas::new(&ctx.device, pyramid.samples_per_side(), slots);
        let stage = DeriveStage::new(&ctx.device, &ctx.queue, &pyramid, &params, &atlas, 8);
        Self {
            ctx,
            atlas,
            stage,
            pyramid,
            params,
        }
    }

    fn derive(&self, jobs: &[DeriveJob]) {
        let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
        let mut timer = GpuTimer::new(&self.ctx.device, &self.ctx.queue, false, 0);
        let n = self
            .stage
            .record(&self.ctx.queue, &mut encoder, &self.atlas, jobs, &mut timer);
        assert_eq!(n, jobs.len());
        self.ctx.queue.submit([encoder.finish()]);
    }

    fn read(&self, slot: u32, id: TileId) -> TileData {
        self.atlas
            .read_back(&self.ctx.device, &self.ctx.queue, slot, id)
            .unwrap()
    }
}

fn assert_matches_mirror(gpu: &TileData, cpu: &TileData) {
    assert_eq!(gpu.size, cpu.size);
    let mut worst = 0.0f32;
    for (k, (g, c)) in gpu.heights.iter().zip(&cpu.heights).enumerate() {
        let d = (g - c).abs();
        worst = worst.max(d);
        assert!(
            d <= HEIGHT_TOLERANCE_M,
            "{:?} sample {k}: GPU {g} CPU {c}",
            gpu.id
        );
    }
    assert_eq!(
        gpu.grass_type, cpu.grass_type,
        "{:?}: grass types differ",
        gpu.id
    );
    assert_eq!(gpu.density, cpu.density, "{:?}: densities differ", gpu.id);
    assert_eq!(gpu.material, cpu.material, "{:?}: materials differ", gpu.id);
    eprintln!(
        "{:?}: largest GPU-CPU height difference {worst:e} m",
        gpu.id
    );
}

#[test]
fn gpu_derivation_matches_the_cpu_mirror_over_two_generations() {
    let world = World::open(&common::default_world()).unwrap();
    let rig = Rig::new(&world, 16);
    // A steep tile in the mountains and a flat one in the valley, the latter with a material
    // map of every material in a pattern (the default world has none).
    for (slot0, parent_id) in [(0u32, TileId::new(2, 3, 5)), (8, TileId::new(2, 7, 10))] {
        let mut parent = world.load_tile(parent_id).unwrap();
        if slot0 == 8 {
            let n = parent.heights.len();
            parent.material = (0..n)
                .map(|k| ((k * 7 + k / 13) % verdant::world::MATERIAL_COUNT) as u8)
                .collect();
        }
        rig.atlas.upload(&rig.ctx.queue, slot0, &parent).unwrap();
        let children = parent_id.children();
        let jobs: Vec<DeriveJob> = children
            .iter()
            .enumerate()
            .map(|(k, &child)| DeriveJob {
                child,
                parent_slot: slot0,
                child_slot: slot0 + 1 + k as u32,
            })
            .collect();
        rig.derive(&jobs);
        let mut cpu_children = Vec::new();
        for job in &jobs {
            let gpu = rig.read(job.child_slot, job.child);
            let cpu = derive_child(&rig.pyramid, &parent, job.child, &rig.params);
            assert_matches_mirror(&gpu, &cpu);
            cpu_children.push(cpu);
        }
        // Second generation: from a derived tile, on both sides.
        let grandchild = children[3].children()[0];
        rig.derive(&[DeriveJob {
            child: grandchild,
            parent_slot: slot0 + 4,
            child_slot: slot0 + 5,
        }]);
        let gpu = rig.read(slot0 + 5, grandchild);
        let cpu = derive_child(&rig.pyramid, &cpu_children[3], grandchild, &rig.params);
        assert_matches_mirror(&gpu, &cpu);
    }
}

/// Compares the samples two horizontally neighbouring tiles share (edge and border columns).
fn assert_shared_columns_identical(west: &TileData, east: &TileData, pyramid: &Pyramid) {
    let n = pyramid.tile_cells;
    let b = pyramid.border;
    let s = west.size;
    for j in 0..s {
        for k in 0..=2 * b {
            let (iw, ie) = (n + k, k);
            let (a, c) = (west.index(iw, j), east.index(ie, j));
            assert_eq!(
                west.heights[a].to_bits(),
                east.heights[c].to_bits(),
                "{:?}/{:?} row {j} column {k}: {} vs {}",
                west.id,
                east.id,
                west.heights[a],
                east.heights[c]
            );
            assert_eq!(west.grass_type[a], east.grass_type[c]);
            assert_eq!(west.density[a], east.density[c]);
        }
    }
}

#[test]
fn neighbours_derived_from_different_parents_share_their_borders_exactly() {
    let world = World::open(&common::default_world()).unwrap();
    let rig = Rig::new(&world, 8);
    let (pw, pe) = (TileId::new(2, 4, 6), TileId::new(2, 5, 6));
    let (tw, te) = (world.load_tile(pw).unwrap(), world.load_tile(pe).unwrap());
    rig.atlas.upload(&rig.ctx.queue, 0, &tw).unwrap();
    rig.atlas.upload(&rig.ctx.queue, 1, &te).unwrap();
    // The east child of the west parent borders the west child of the east parent.
    let (cw, ce) = (TileId::new(3, 9, 13), TileId::new(3, 10, 13));
    assert_eq!(cw.parent(), Some(pw));
    assert_eq!(ce.parent(), Some(pe));
    rig.derive(&[
        DeriveJob {
            child: cw,
            parent_slot: 0,
            child_slot: 2,
        },
        DeriveJob {
            child: ce,
            parent_slot: 1,
            child_slot: 3,
        },
    ]);
    let (gw, ge) = (rig.read(2, cw), rig.read(3, ce));
    assert_shared_columns_identical(&gw, &ge, &rig.pyramid);
    let (cpu_w, cpu_e) = (
        derive_child(&rig.pyramid, &tw, cw, &rig.params),
        derive_child(&rig.pyramid, &te, ce, &rig.params),
    );
    assert_shared_columns_identical(&cpu_w, &cpu_e, &rig.pyramid);
    // And the detail is really there away from the edges (the derivation is not a plain copy).
    let bicubic_only = rig.params.bicubic();
    let smooth = derive_child(&rig.pyramid, &tw, cw, &bicubic_only);
    let differs = smooth
        .heights
        .iter()
        .zip(&cpu_w.heights)
        .filter(|(a, b)| a != b)
        .count();
    assert!(
        differs > cpu_w.heights.len() / 4,
        "detail noise changed only {differs} samples"
    );
}

#[test]
fn the_same_tile_derives_to_the_same_bits_every_time() {
    let world = World::open(&common::default_world()).unwrap();
    let rig = Rig::new(&world, 4);
    let parent_id = TileId::new(2, 7, 9);
    rig.atlas
        .upload(&rig.ctx.queue, 0, &world.load_tile(parent_id).unwrap())
        .unwrap();
    let child = parent_id.children()[2];
    rig.derive(&[DeriveJob {
        child,
        parent_slot: 0,
        child_slot: 1,
    }]);
    rig.derive(&[DeriveJob {
        child,
        parent_slot: 0,
        child_slot: 2,
    }]);
    let (a, b) = (rig.read(1, child), rig.read(2, child));
    let bits = |t: &TileData| t.heights.iter().map(|h| h.to_bits()).collect::<Vec<u32>>();
    assert_eq!(bits(&a), bits(&b));
    assert_eq!((a.grass_type, a.density), (b.grass_type, b.density));
    let parent = world.load_tile(parent_id).unwrap();
    let (c1, c2) = (
        derive_child(&rig.pyramid, &parent, child, &rig.params),
        derive_child(&rig.pyramid, &parent, child, &rig.params),
    );
    assert_eq!(bits(&c1), bits(&c2));
}

/// The default world's calibrated settings; fails unless the manifest carries a fractal fit.
fn calibrated(world: &World) -> DeriveParams {
    let fit = world
        .manifest
        .derive
        .as_ref()
        .expect("world.toml has a [derive] table");
    assert_eq!(fit.method, DeriveMode::Fractal, "{}", fit.note);
    let params = DeriveParams::for_manifest(&world.manifest);
    let first = world.manifest.pyramid.stored_levels;
    // Distinct amplitudes per derived level, none zero, as fitted.
    for (k, &d) in fit.detail.iter().enumerate() {
        assert!(d > 0.0);
        assert_eq!(params.detail_at(first + k as u8), d);
    }
    params
}

#[test]
fn calibrated_gpu_derivation_matches_the_mirror_over_three_generations() {
    let world = World::open(&common::default_world()).unwrap();
    let rig = Rig::with_params(&world, 8, calibrated(&world));
    let parent_id = TileId::new(2, 3, 5);
    let parent = world.load_tile(parent_id).unwrap();
    rig.atlas.upload(&rig.ctx.queue, 0, &parent).unwrap();
    // Down three levels: each generation's parent carries detail of its own that the GPU and
    // the mirror both take off again.
    let mut cpu_parent = parent;
    let mut id = parent_id;
    for generation in 0..3u32 {
        let child = id.children()[(generation as usize + 1) % 4];
        rig.derive(&[DeriveJob {
            child,
            parent_slot: generation,
            child_slot: generation + 1,
        }]);
        let gpu = rig.read(generation + 1, child);
        let cpu = derive_child(&rig.pyramid, &cpu_parent, child, &rig.params);
        assert_matches_mirror(&gpu, &cpu);
        cpu_parent = cpu;
        id = child;
    }
}

#[test]
fn calibrated_neighbours_from_derived_parents_share_their_borders_exactly() {
    let world = World::open(&common::default_world()).unwrap();
    let rig = Rig::with_params(&world, 8, calibrated(&world));
    let (pw, pe) = (TileId::new(2, 4, 6), TileId::new(2, 5, 6));
    rig.atlas
        .upload(&rig.ctx.queue, 0, &world.load_tile(pw).unwrap())
        .unwrap();
    rig.atlas
        .upload(&rig.ctx.queue, 1, &world.load_tile(pe).unwrap())
        .unwrap();
    // Derived parents from different stored parents, then their children across the seam.
    let (cw, ce) = (TileId::new(3, 9, 13), TileId::new(3, 10, 13));
    let (gw, ge) = (TileId::new(4, 19, 26), TileId::new(4, 20, 26));
    assert_eq!((gw.parent(), ge.parent()), (Some(cw), Some(ce)));
    rig.derive(&[
        DeriveJob {
            child: cw,
            parent_slot: 0,
            child_slot: 2,
        },
        DeriveJob {
            child: ce,
            parent_slot: 1,
            child_slot: 3,
        },
    ]);
    rig.derive(&[
        DeriveJob {
            child: gw,
            parent_slot: 2,
            child_slot: 4,
        },
        DeriveJob {
            child: ge,
            parent_slot: 3,
            child_slot: 5,
        },
    ]);
    assert_shared_columns_identical(&rig.read(4, gw), &rig.read(5, ge), &rig.pyramid);
    let cpu = |p: TileId, c: TileId, g: TileId| {
        let stored = world.load_tile(p).unwrap();
        let derived = derive_child(&rig.pyramid, &stored, c, &rig.params);
        derive_child(&rig.pyramid, &derived, g, &rig.params)
    };
    assert_shared_columns_identical(&cpu(pw, cw, gw), &cpu(pe, ce, ge), &rig.pyramid);
}

#[test]
fn a_derived_level_does_not_pass_its_detail_on() {
    let world = World::open(&common::default_world()).unwrap();
    let pyramid = &world.manifest.pyramid;
    let params = calibrated(&world);
    let first = pyramid.stored_levels;
    // The same chain with no detail at the first derived level.
    let mut plain_first = params;
    plain_first.detail[usize::from(first)] = 0.0;
    let stored_id = TileId::new(2, 3, 5);
    let stored = world.load_tile(stored_id).unwrap();
    let child = stored_id.children()[1];
    let grandchild = child.children()[2];
    let derive2 = |p: &DeriveParams| {
        let c = derive_child(pyramid, &stored, child, p);
        (c.clone(), derive_child(pyramid, &c, grandchild, p))
    };
    let (with_child, with) = derive2(&params);
    let (plain_child, without) = derive2(&plain_first);
    // The first derived level differs (it has detail of its own)...
    let changed = with_child
        .heights
        .iter()
        .zip(&plain_child.heights)
        .filter(|(a, b)| (*a - *b).abs() > 1e-3)
        .count();
    assert!(changed > with_child.heights.len() / 4, "{changed}");
    // ...but the level below it is the same up to rounding: it interpolates the smooth
    // surface and adds only its own detail.
    let worst = with
        .heights
        .iter()
        .zip(&without.heights)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-3, "the grandchild moved by {worst} m");
}

// ---- The calibrated method against held-out truth (CPU; `verdant eval derive`'s measures) ----

/// A fractional Brownian surface of Hurst exponent `hurst` by midpoint displacement (diamond
/// and square steps, the displacement shrinking by `2^(-hurst / 2)` at each, Gaussian,
/// seeded): `2^exponent + 1` samples a side of `cell_m`, relief about `sigma_m`.
fn fbm_surface(hurst: f64, exponent: u32, seed: u64, cell_m: f64, sigma_m: f64) -> eval::Grid {
    let n = 1usize << exponent;
    let w = n + 1;
    let mut rng = common::Rng(seed);
    let mut gauss = move || {
        let (u, v) = (rng.unit().max(1e-12), rng.unit());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    };
    let mut h = vec![0.0f64; w * w];
    for (x, y) in [(0, 0), (n, 0), (0, n), (n, n)] {
        h[y * w + x] = sigma_m * gauss();
    }
    let shrink = 0.5f64.powf(hurst / 2.0);
    let (mut step, mut scale) = (n, sigma_m);
    while step > 1 {
        let half = step / 2;
        scale *= shrink;
        for y in (half..w).step_by(step) {
            for x in (half..w).step_by(step) {
                let corners = h[(y - half) * w + x - half]
                    + h[(y - half) * w + x + half]
                    + h[(y + half) * w + x - half]
                    + h[(y + half) * w + x + half];
                h[y * w + x] = corners / 4.0 + scale * gauss();
            }
        }
        scale *= shrink;
        for y in (0..w).step_by(half) {
            let first = if (y / half) % 2 == 0 { half } else { 0 };
            for x in (first..w).step_by(step) {
                let mut sum = 0.0;
                let mut count = 0.0;
                for (dx, dy) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                    let (nx, ny) = (x as i64 + dx * half as i64, y as i64 + dy * half as i64);
                    if (0..w as i64).contains(&nx) && (0..w as i64).contains(&ny) {
                        sum += h[ny as usize * w + nx as usize];
                        count += 1.0;
                    }
                }
                h[y * w + x] = sum / count + scale * gauss();
            }
        }
        step = half;
    }
    eval::Grid {
        width: w,
        height: w,
        cell: (cell_m, cell_m),
        data: h.iter().map(|&v| v as f32).collect(),
    }
}

/// How far the fitted Hurst exponent may be from the surface's: midpoint displacement makes
/// only approximately fractional Brownian surfaces, and four octaves of a coarse grid are few.
const HURST_TOLERANCE: f64 = 0.1;

#[test]
fn calibrated_method_recovers_fractal_surfaces_of_known_hurst_exponent() {
    for (hurst, seed) in [
        (0.3, 3),
        (0.3, 103),
        (0.5, 5),
        (0.5, 105),
        (0.8, 8),
        (0.8, 108),
    ] {
        // Relief for an RMS slope of about 0.3 at the finest samples.
        let truth = fbm_surface(hurst, 10, seed, 2.0, 0.6 * 1024f64.powf(hurst));
        for factor in [4, 8] {
            let bicubic = eval::evaluate(&truth, factor, eval::DeriveMethod::Bicubic, 1);
            let r = eval::evaluate_calibrated(&truth, factor, 1);
            let fit = r.fit.clone().unwrap();
            eprintln!(
                "H {hurst} seed {seed} factor {factor}: fitted H {:.3}, roughness {:.3} \
                 (bicubic {:.3}), RMSE {:.3}x bicubic, {}",
                fit.hurst,
                r.roughness_ratio,
                bicubic.roughness_ratio,
                r.rmse_m / bicubic.rmse_m,
                r.parameters()
            );
            assert_eq!(fit.method, DeriveMode::Fractal, "{}", fit.note);
            assert!(
                (fit.hurst - hurst).abs() <= HURST_TOLERANCE,
                "H {hurst} factor {factor}: fitted H {}",
                fit.hurst
            );
            assert!(
                (0.8..=1.2).contains(&r.roughness_ratio),
                "H {hurst} factor {factor}: roughness {} of the truth's",
                r.roughness_ratio
            );
            assert!(
                r.rmse_m <= 1.15 * bicubic.rmse_m,
                "H {hurst} factor {factor}: RMSE {} m, bicubic {} m",
                r.rmse_m,
                bicubic.rmse_m
            );
            // A fractal is taken as scale-invariant: each depth's amplitude is carried to its
            // own scale nearly unchanged.
            assert!(
                fit.decay_log2 <= SCALE_INVARIANT_TREND_LOG2,
                "H {hurst} factor {factor}: {}",
                fit.note
            );
        }
    }
}

#[test]
fn calibrated_method_keeps_real_terrain_rough_at_bicubic_height_error() {
    for dem in [
        common::root().join("worlds/santa-cruz/source/santa_cruz_1024.png"),
        common::root().join("tests/data/east_bay_768.png"),
    ] {
        let truth = eval::dem_grid(&verdant::world::Dem::load(&dem).unwrap());
        for factor in [4, 8] {
            let bicubic = eval::evaluate(&truth, factor, eval::DeriveMethod::Bicubic, 1);
            let r = eval::evaluate_calibrated(&truth, factor, 1);
            let name = dem.file_name().unwrap().to_string_lossy();
            eprintln!(
                "{name} factor {factor}: roughness {:.3}, RMSE {:.3} m ({:.3}x bicubic), {}",
                r.roughness_ratio,
                r.rmse_m,
                r.rmse_m / bicubic.rmse_m,
                r.parameters()
            );
            assert!(
                (0.8..=1.2).contains(&r.roughness_ratio),
                "{name} factor {factor}: roughness {} of the truth's",
                r.roughness_ratio
            );
            assert!(
                r.rmse_m <= 1.15 * bicubic.rmse_m,
                "{name} factor {factor}: RMSE {} m, bicubic {} m",
                r.rmse_m,
                bicubic.rmse_m
            );
            // Plain bicubic smooths the terrain; the calibrated detail is what restores it.
            assert!(bicubic.roughness_ratio < 0.6);
            // SRTM smooths out toward its finest scales: the amplitudes fall below the data.
            let fit = r.fit.as_ref().unwrap();
            assert!(fit.decay_log2 >= MIN_DECAY_LOG2, "{name}: {}", fit.note);
        }
    }
}
