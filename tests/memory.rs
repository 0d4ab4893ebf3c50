//! Memory of the per-frame compute passes over many frames, in a test binary of its own (the
//! resident size is the whole process's, so nothing may run beside it).

mod common;

use glam::DVec3;
use verdant::gpu::GpuTimer;
use verdant::tools::resident_bytes;
use verdant::wind::{SwayConfig, SwayField, WindConfig, WindField};
use verdant::world::Manifest;

#[test]
fn the_wind_and_sway_passes_hold_their_memory_over_many_frames() {
    // Regression test: with their per-frame parameters in uniform buffers, Mesa's lavapipe
    // compiled a fresh variant of each shader at every dispatch (it inlines uniform values that
    // steer branches and loops) and never freed it: about 0.4 MB a dispatch. The parameters now
    // live in read-only storage buffers.
    let ctx = common::gpu();
    let m = Manifest::from_path(&common::default_world().join("world.toml")).unwrap();
    let tour = m.path("wind-tour").unwrap();
    let config = WindConfig::from_keys(&m, &tour.wind).unwrap();
    let mut field = WindField::new(&ctx.device, &ctx.queue, &config);
    let mut sway = SwayField::new(
        &ctx.device,
        SwayConfig::from_manifest(&m),
        config.cells,
        field.buffer(),
    );
    sway.reset(&ctx.queue);
    let mut timer = GpuTimer::new(&ctx.device, &ctx.queue, false, 0);
    let mut frame = |k: u32| {
        // Through the helicopter scene, so that sources, trail and noise all act.
        let t = 36.0 + f64::from(k) / 30.0;
        let cam = verdant::camera::sample_path(tour, t).position;
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        field.update(
            &ctx.queue,
            &mut encoder,
            cam + DVec3::new(f64::from(k) * 0.5, 0.0, 0.0),
            t,
            1.0 / 30.0,
            Some(cam.truncate()),
            &mut timer,
        );
        sway.update(
            &ctx.queue,
            &mut encoder,
            &field.lookup(),
            1.0 / 30.0,
            &mut timer,
        );
        ctx.queue.submit([encoder.finish()]);
        ctx.wait_idle();
    };
    for k in 0..30 {
        frame(k);
    }
    let before = resident_bytes();
    let frames = 150;
    for k in 30..30 + frames {
        frame(k);
    }
    let growth = resident_bytes().saturating_sub(before);
    eprintln!(
        "resident memory grew {:.2} MiB over {frames} frames of the wind and sway passes",
        growth as f64 / 1048576.0
    );
    assert!(
        growth < 8 << 20,
        "resident memory grew {:.1} MiB over {frames} frames",
        growth as f64 / 1048576.0
    );
}
