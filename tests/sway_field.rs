//! The sway stage (`shaders/wind_sway.wgsl`) against its CPU mirror (`update_sway`), over
//! frames with a moving camera, a 0.5 s hitch and a jump beyond the wind field.

mod common;

use glam::{DVec2, DVec3};
use verdant::gpu::GpuTimer;
use verdant::wind::{SWAY_TYPES, SwayConfig, SwayField, WindConfig, WindField, update_sway};
use verdant::world::World;

/// Largest difference allowed between GPU and CPU sway, blade heights: the same f32 arithmetic
/// from the same step matrices; a GPU may fuse multiply-adds (an ulp or two a frame), and the
/// spring's damping keeps such differences from growing.
const TOLERANCE: f32 = 1e-4;

#[test]
fn gpu_sway_matches_the_cpu_mirror_through_hitches_and_jumps() {
    let ctx = common::gpu();
    let world = World::open(&common::default_world()).unwrap();
    let config = WindConfig::from_scene(&world.manifest, Some("storm")).unwrap();
    let mut wind = WindField::new(&ctx.device, &ctx.queue, &config);
    let mut sway = SwayField::new(
        &ctx.device,
        SwayConfig::from_manifest(&world.manifest),
        config.cells,
        wind.buffer(),
    );
    sway.reset(&ctx.queue);
    let n = config.cells as usize;
    let mut cpu_sway = vec![[0.0f32; 4]; n * n * SWAY_TYPES];
    let mut cpu_owners = vec![[i32::MIN, i32::MIN]; n * n];
    let mut timer = GpuTimer::new(&ctx.device, &ctx.queue, false, 0);
    let start = DVec2::new(20_000.0, 28_000.0);
    let mut t = 0.0;
    // (time step, camera move): ordinary frames, a 0.5 s hitch, a jump of 2 km.
    let frames: Vec<(f32, DVec2)> = (0..6)
        .map(|_| (1.0 / 30.0, DVec2::new(3.0, 1.0)))
        .chain([
            (0.5, DVec2::new(2.0, 0.0)),
            (1.0 / 30.0, DVec2::new(2000.0, 0.0)),
        ])
        .chain((0..3).map(|_| (1.0 / 60.0, DVec2::new(-1.0, 2.0))))
        .collect();
    let mut camera = start;
    let mut worst = 0.0f32;
    let mut moved = 0.0f32;
    for (dt, step) in frames {
        t += f64::from(dt);
        camera += step;
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        wind.update(
            &ctx.queue,
            &mut encoder,
            DVec3::new(camera.x, camera.y, 60.0),
            t,
            dt,
            Some(camera),
            &mut timer,
        );
        let lookup = wind.lookup();
        sway.update(&ctx.queue, &mut encoder, &lookup, dt, &mut timer);
        ctx.queue.submit([encoder.finish()]);
        let cells = wind.read_back(&ctx.device, &ctx.queue);
        update_sway(sway.last_params(), &cells, &mut cpu_sway, &mut cpu_owners);
        let (gpu_sway, gpu_owners) = sway.read_back(&ctx.device, &ctx.queue);
        assert_eq!(
            gpu_owners, cpu_owners,
            "cells belong to different world cells"
        );
        for (g, c) in gpu_sway.iter().zip(&cpu_sway) {
            for k in 0..4 {
                let d = (g[k] - c[k]).abs();
                worst = worst.max(d);
                assert!(d <= TOLERANCE, "GPU {g:?} CPU {c:?}");
                assert!(g[k].is_finite());
            }
            moved = moved.max(g[0].abs() + g[1].abs());
        }
    }
    eprintln!("largest GPU-CPU sway difference {worst:e}");
    assert!(moved > 0.05, "the storm should bend the grass");
}
