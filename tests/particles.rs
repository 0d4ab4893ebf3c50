//! The leaves the trees and the petals the flowers shed (`shaders/particles.wgsl`) against their
//! CPU mirror (`src/plants/particles_cpu.rs`): one step of a pool in a wind field and over trees
//! and flowers made up here, on software Vulkan; and through the renderer, a forest's leaves in the air around the
//! camera, drawn and carried downwind.

mod common;

use glam::Vec3;
use verdant::gpu::Targets;
use verdant::hash::{hash_u32, rand01};
use verdant::plants::particles::{
    FlowerSource, ParticleSettings, ParticleStage, ParticleWind, TreeSource,
};
use verdant::plants::particles_cpu::{self, Particle, ParticleParams};
use verdant::plants::place_cpu::PlantInstance;
use verdant::wind::WindLookup;
use verdant::wind::field_cpu::wind_at;

#[test]
fn one_step_of_the_leaves_matches_the_cpu_mirror() {
    use wgpu::BufferUsages as U;
    use wgpu::util::DeviceExt;
    let ctx = common::gpu();
    let (device, queue) = (&ctx.device, &ctx.queue);
    // A wind field of 16 x 16 cells of 8 m, each its own wind.
    let lookup = WindLookup {
        origin_cell: [100, -40],
        n: 16,
        cell_m: 8.0,
        camera_offset: [3.0, 5.5],
        _pad: [0.0; 2],
    };
    let cells: Vec<[f32; 4]> = (0..256u32)
        .map(|i| {
            let r = |k: u32| rand01(hash_u32(i * 7 + k)) * 2.0 - 1.0;
            [6.0 * r(1), 6.0 * r(2), 0.0, 0.0]
        })
        .collect();
    let buffer = |label, contents: &[u8], usage| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents,
            usage,
        })
    };
    let lookup_buffer = buffer("lookup", bytemuck::bytes_of(&lookup), U::UNIFORM);
    let cells_buffer = buffer("cells", bytemuck::cast_slice(&cells), U::STORAGE);
    // Two tree types, regions of 8: type 0 with 3 full meshes, type 1 with 2 reduced ones.
    let cap = 8u32;
    let tree = |x: f32, y: f32, z: f32, kind: u32| PlantInstance {
        pos: [x, y, z],
        yaw: 0.0,
        scale: 14.0,
        kind,
        hash: 0,
        fade: 1.0,
    };
    let mut trees = vec![tree(0.0, 0.0, 0.0, 0); (2 * 3 * cap) as usize];
    for (k, x) in [10.0f32, -20.0, 35.0].into_iter().enumerate() {
        trees[k] = tree(x, 12.0, -4.0, 0);
    }
    for (k, x) in [50.0f32, -60.0].into_iter().enumerate() {
        trees[(4 * cap) as usize + k] = tree(x, -30.0, -2.0, 1 | 1 << 8);
    }
    let mut args = [0u32; 6 * 5];
    args[1] = 3;
    args[4 * 5 + 1] = 2;
    let drawn: Vec<u32> = (0..6).map(|r| args[r * 5 + 1]).collect();
    let trees_buffer = buffer("trees", bytemuck::cast_slice(&trees), U::STORAGE);
    let args_buffer = buffer("args", bytemuck::cast_slice(&args), U::STORAGE);
    // Two plant types, regions of 8: type 0 (no petals) with 3 full meshes, type 1 (a flower)
    // with 4 full and 2 reduced ones.
    let flower = |x: f32, y: f32, kind: u32| PlantInstance {
        scale: 0.6,
        ..tree(x, y, -1.0, kind)
    };
    let mut plants = vec![flower(0.0, 0.0, 0); (2 * 3 * cap) as usize];
    for (k, fern) in plants.iter_mut().take(3).enumerate() {
        *fern = flower(-40.0 + k as f32, 3.0, 0);
    }
    for k in 0..4 {
        plants[(3 * cap) as usize + k] = flower(20.0 + 2.0 * k as f32, -7.0, 1);
    }
    for k in 0..2 {
        plants[(4 * cap) as usize + k] = flower(-15.0 - 2.0 * k as f32, -9.0, 1 | 1 << 8);
    }
    let mut plant_args = [0u32; 6 * 5];
    plant_args[1] = 3;
    plant_args[3 * 5 + 1] = 4;
    plant_args[4 * 5 + 1] = 2;
    let plant_drawn: Vec<u32> = (0..6).map(|r| plant_args[r * 5 + 1]).collect();
    let plants_buffer = buffer("plants", bytemuck::cast_slice(&plants), U::STORAGE);
    let plant_args_buffer = buffer("plant args", bytemuck::cast_slice(&plant_args), U::STORAGE);
    let petals = [None, Some([0.8, 0.1, 0.03])];

    let settings = ParticleSettings {
        count: 256,
        ..Default::default()
    };
    let targets = Targets {
        color_format: wgpu::TextureFormat::Rgba8UnormSrgb,
        depth_format: wgpu::TextureFormat::Depth32Float,
        width: 64,
        height: 64,
    };
    let sky = verdant::world::Sky::default();
    let mut stage = ParticleStage::new(
        device,
        &targets,
        settings,
        TreeSource {
            instances: &trees_buffer,
            args: &args_buffer,
            capacity: cap,
            types: 2,
        },
        Some(FlowerSource {
            instances: &plants_buffer,
            args: &plant_args_buffer,
            capacity: cap,
            petals: &petals,
        }),
        ParticleWind {
            lookup: &lookup_buffer,
            cells: &cells_buffer,
        },
        &[[0.1, 0.3, 0.05], [0.05, 0.2, 0.05]],
        &sky,
    );
    // Particles in the air at every stage of life; every eighth over, every ninth below its
    // ground, so that some are shed again.
    let particles: Vec<Particle> = (0..settings.count)
        .map(|i| {
            let r = |k: u32| rand01(hash_u32(i * 13 + k));
            Particle {
                pos: [60.0 * r(1) - 30.0, 60.0 * r(2) - 30.0, 3.0 + 10.0 * r(3)],
                age: 5.0 * r(4),
                vel: [r(5) - 0.5, r(6) - 0.5, -0.5 * r(7)],
                life: if i % 8 == 0 { 1.0 } else { 6.0 },
                ground: if i % 9 == 0 { 20.0 } else { -5.0 },
                kind: i % 2,
                seed: hash_u32(i),
                spin: r(8),
            }
        })
        .collect();
    stage.write_particles(queue, &particles);
    let params = ParticleParams {
        delta: [0.4, -0.3, 0.05, 1.0 / 60.0],
        counts: [settings.count, 2, cap, 77],
        // Every shed particle flies (5 trees, 100 leaves each, and 6 flowers, 30 petals each,
        // over a pool of 256); a tree has 3 tickets to a flower's 1.
        shed: [100.0, 30.0, 0.0, 0.0],
        flowers: [2, cap, 0b10, 3],
        ..*stage.params()
    };
    assert_eq!(stage.params().flowers[..3], [2, cap, 0b10]);
    stage.write_params(queue, params);
    let mut timer = verdant::gpu::GpuTimer::new(device, queue, false, 4);
    let mut encoder = device.create_command_encoder(&Default::default());
    stage.record_step(&mut encoder, &mut timer);
    queue.submit([encoder.finish()]);
    let gpu = stage.read_particles(device, queue);
    let flowers = particles_cpu::Flowers {
        instances: &plants,
        drawn: &plant_drawn,
    };
    let cpu = particles_cpu::advance(&particles, &params, &trees, &drawn, Some(flowers), &|p| {
        wind_at(&lookup, &cells, p)
    });
    let mut shed = 0;
    for (i, (g, c)) in gpu.iter().zip(&cpu).enumerate() {
        let d = (Vec3::from(g.pos) - Vec3::from(c.pos)).length()
            + (Vec3::from(g.vel) - Vec3::from(c.vel)).length();
        assert!(
            d < 1e-3 && (g.age - c.age).abs() < 1e-5 && (g.life - c.life).abs() < 1e-4,
            "particle {i}: GPU {g:?} CPU {c:?}"
        );
        assert_eq!((g.kind, g.seed), (c.kind, c.seed), "particle {i}");
        if c.age == 0.0 {
            shed += 1;
        }
    }
    // 32 over their life, 29 below their ground, some both.
    assert!(shed > 50, "{shed} shed again");
    // Each shed leaf starts in the crown of a tree drawn this frame, each petal at the head of
    // a flower drawn this frame (type 1's; type 0 sheds none).
    let drawn_trees: Vec<&PlantInstance> = trees[..3]
        .iter()
        .chain(&trees[(4 * cap) as usize..(4 * cap + 2) as usize])
        .collect();
    let drawn_flowers: Vec<&PlantInstance> = plants[(3 * cap) as usize..(3 * cap + 4) as usize]
        .iter()
        .chain(&plants[(4 * cap) as usize..(4 * cap + 2) as usize])
        .collect();
    let new: Vec<&Particle> = cpu
        .iter()
        .filter(|c| c.age == 0.0 && c.life > 0.0)
        .collect();
    let petals: Vec<&&Particle> = new
        .iter()
        .filter(|c| c.kind >= particles_cpu::PETAL)
        .collect();
    assert!(
        petals.len() > 5 && petals.len() < new.len() / 2,
        "{} petals of {} shed",
        petals.len(),
        new.len()
    );
    for c in &petals {
        assert_eq!(c.kind, particles_cpu::PETAL + 1);
        let p = Vec3::from(c.pos);
        assert!(
            drawn_flowers.iter().any(|f| {
                let root = Vec3::from(f.pos);
                (p.truncate() - root.truncate()).length() <= 0.15 * f.scale + 1e-3
                    && p.z >= root.z + 0.75 * f.scale - 1e-3
                    && p.z <= root.z + 0.95 * f.scale + 1e-3
            }),
            "petal at {p} on no flower"
        );
    }
    for c in new.iter().filter(|c| c.kind < particles_cpu::PETAL) {
        let p = Vec3::from(c.pos);
        assert!(
            drawn_trees.iter().any(|t| {
                let root = Vec3::from(t.pos);
                (p.truncate() - root.truncate()).length() <= 0.35 * t.scale + 1e-3
                    && p.z >= root.z + 0.5 * t.scale - 1e-3
                    && p.z <= root.z + 0.9 * t.scale + 1e-3
            }),
            "{p} in no crown"
        );
    }
}

/// Through the renderer: a second and a half of 16 Hz frames standing among trees at the meadow,
/// the leaves are drawn (the last frame differs from the same frames without them), the leaves
/// in the air are about the settings' eight a tree near the camera, the meadow's
/// flowers shed some petals, each above the ground it was shed over, and carried: moving
/// sideways faster than they flutter, not only falling.
#[test]
fn a_forests_leaves_fly_in_the_wind_around_the_camera() {
    use glam::DVec3;
    use verdant::camera::Camera;
    use verdant::{FrameInput, Renderer, RendererOptions, World};
    let ctx = common::gpu();
    let tmp = tempfile::tempdir().unwrap();
    let dir = common::world_with_trees(tmp.path(), "broadleaf", 0.004);
    // And poppies, whose petals fly too.
    let manifest = std::fs::read_to_string(dir.join("world.toml")).unwrap();
    let at = manifest.find("[wind]").unwrap();
    let poppy = "[[plant_types]]\nname = \"poppy\"\nmesh = \"flower\"\n\
                 color = [0.8, 0.1, 0.03]\nsize_m = [0.35, 0.65]\n\
                 density = { meadow = 0.45, \"tall grass\" = 0.3 }\n\n";
    let edited = format!("{}{poppy}{}", &manifest[..at], &manifest[at..]);
    std::fs::write(dir.join("world.toml"), edited).unwrap();
    let world = World::open(&dir).unwrap();
    let toward = f64::from(world.manifest.wind.direction_deg).to_radians();
    let path = world
        .manifest
        .paths
        .iter()
        .find(|p| p.name == "meadow")
        .unwrap();
    let start = verdant::camera::sample_path(path, path.keys[0].t_s);
    let camera = Camera::new(start.position + DVec3::new(0.0, 0.0, 4.0), 30.0, -5.0);
    let (c, d) = (
        wgpu::TextureFormat::Rgba8UnormSrgb,
        wgpu::TextureFormat::Depth32Float,
    );
    let (w, h) = (192, 108);
    // The same frames with the leaves and without: the renderer after them and its last frame.
    let fly = |features: verdant::features::Features| {
        let mut options = RendererOptions::new(&world, c, d, w, h);
        options.config.features = features;
        let mut renderer = Renderer::new(&ctx.device, &ctx.queue, world.clone(), options).unwrap();
        use wgpu::TextureUsages as U;
        let color = verdant::gpu::target_texture(
            &ctx.device,
            "c",
            c,
            U::RENDER_ATTACHMENT | U::COPY_SRC,
            (w, h),
        );
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
        renderer
            .warm_up(&camera, std::time::Duration::from_secs(60))
            .unwrap();
        for f in 0..24 {
            renderer.prepare(&ctx.queue, &FrameInput::new(camera, f64::from(f) / 16.0));
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            renderer.record(&mut encoder, &cv, &dv).unwrap();
            ctx.queue.submit([encoder.finish()]);
            ctx.wait_idle();
        }
        let pixels = verdant::gpu::read_texture_rgba8(&ctx.device, &ctx.queue, &color).unwrap();
        (renderer, pixels)
    };
    let all = verdant::features::Features::all();
    let (renderer, with_leaves) = fly(all);
    // Drawn: among the trees, leaves a few metres from the camera cover whole pixels of the
    // frame (the rest of the scene is the same function of the world, the time and the camera).
    let (_, without) = fly(all.without(verdant::features::Feature::Particles));
    let changed = with_leaves
        .chunks(4)
        .zip(without.chunks(4))
        .filter(|(a, b)| a.iter().zip(b.iter()).any(|(x, y)| x.abs_diff(*y) > 8))
        .count();
    eprintln!("{changed} of {} pixels changed by the leaves", w * h);
    assert!(changed >= 5, "the leaves cover {changed} pixels");
    let trees = renderer
        .read_tree_instances()
        .iter()
        .filter(|t| t.kind >> 8 < 2)
        .count();
    let pool = renderer.read_particles();
    let flying: Vec<_> = pool.iter().filter(|p| p.life > 0.0).collect();
    let leaves = flying
        .iter()
        .filter(|p| p.kind < particles_cpu::PETAL)
        .count();
    // The meadow's poppies and cornflowers shed petals too.
    let petals = flying.len() - leaves;
    eprintln!(
        "{leaves} leaves and {petals} petals of {} in the air over {trees} near trees",
        pool.len()
    );
    assert_eq!(pool.len(), 4096, "the pool's size is fixed");
    assert!(trees > 20, "{trees} trees near the camera");
    assert!(
        leaves > 2 * trees && leaves < 16 * trees + 50,
        "{leaves} leaves for {trees} trees"
    );
    assert!(petals > 0 && petals < leaves, "{petals} petals");
    for p in &flying {
        assert!(p.pos[2] >= p.ground - 0.2, "{p:?} below its ground");
        assert!(glam::Vec3::from(p.pos).length() < 400.0, "{p:?} far away");
    }
    // The ones that have flown half a second and more: their mean velocity across the ground.
    let old: Vec<_> = flying.iter().filter(|p| p.age > 0.5).collect();
    assert!(old.len() > 10, "{} leaves half a second old", old.len());
    let mean = old
        .iter()
        .map(|p| glam::Vec2::new(p.vel[0], p.vel[1]))
        .sum::<glam::Vec2>()
        / old.len() as f32;
    eprintln!("their mean velocity across the ground {mean} m/s");
    assert!(mean.length() > 0.5, "leaves not carried: {mean}");
    // Downwind: within 30 degrees of the way the world's wind blows.
    let wind = glam::Vec2::new(toward.cos() as f32, toward.sin() as f32);
    assert!(
        mean.normalize().dot(wind) > 30f32.to_radians().cos(),
        "leaves drift {mean}, the wind blows toward {wind}"
    );
}
