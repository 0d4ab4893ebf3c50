//! The wind field: the GPU stage (`shaders/wind_field.wgsl`) against its CPU mirror
//! (`src/wind/field_cpu.rs`), the lookup snippet (`shaders/wind_lookup.wgsl`) against its
//! mirror, each source kind, the ambient noise across its window restarts, decay, the trail, and
//! the wind scenes of the manifest.

mod common;

use std::path::Path;

use glam::{DVec2, DVec3, Vec2};
use verdant::camera::sample_path;
use verdant::gpu::{GpuContext, GpuTimer};
use verdant::wind::config::{DEFAULT_CELL_M, DEFAULT_CELLS};
use verdant::wind::{
    AmbientWind, SourceConfig, WindConfig, WindError, WindField, WindFieldCpu, ambient_at,
};
use verdant::world::{Manifest, WindSource, WorldError};

/// Largest wind difference allowed between GPU and CPU, m/s. Both run the same f32 arithmetic
/// in the same order from the same uniform (everything needing f64, `exp` or `sin` is computed
/// once on the CPU); lattice values are exact. What may differ: a GPU may fuse a multiply and
/// an add (an ulp or two), and `length`, division and `normalize` are allowed a few ulps on
/// Vulkan. Winds reach about 30 m/s, where an ulp is 2e-6 m/s; through a few dozen dependent
/// operations and the decay's feedback (a contraction: errors shrink from frame to frame) that
/// stays far below 1e-3 m/s.
const WIND_TOLERANCE_MPS: f32 = 1e-3;
/// Largest trail push difference allowed (the push is at most 1; same reasoning).
const PUSH_TOLERANCE: f32 = 1e-4;

fn timer(ctx: &GpuContext) -> GpuTimer {
    GpuTimer::new(&ctx.device, &ctx.queue, false, 0)
}

/// A GPU field and a CPU mirror stepped together.
struct Pair {
    ctx: GpuContext,
    gpu: WindField,
    cpu: WindFieldCpu,
}

impl Pair {
    fn new(config: &WindConfig) -> Self {
        let ctx = common::gpu();
        let gpu = WindField::new(&ctx.device, &ctx.queue, config);
        let cpu = WindFieldCpu::new(config);
        Self { ctx, gpu, cpu }
    }

    fn step(&mut self, camera: DVec3, t: f64, dt: f32, walker: Option<DVec2>) {
        let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
        let mut timer = timer(&self.ctx);
        self.gpu.update(
            &self.ctx.queue,
            &mut encoder,
            camera,
            t,
            dt,
            walker,
            &mut timer,
        );
        self.ctx.queue.submit([encoder.finish()]);
        self.cpu.update(camera, t, dt, walker);
        assert_eq!(self.gpu.params(), self.cpu.params());
    }

    /// Largest wind and push differences between GPU and CPU.
    fn compare(&self) -> (f32, f32) {
        let gpu = self.gpu.read_back(&self.ctx.device, &self.ctx.queue);
        let cpu = self.cpu.cells();
        assert_eq!(gpu.len(), cpu.len());
        let (mut wind, mut push) = (0.0f32, 0.0f32);
        for (g, c) in gpu.iter().zip(cpu) {
            assert!(g.iter().all(|v| v.is_finite()), "non-finite cell {g:?}");
            wind = wind.max((g[0] - c[0]).abs()).max((g[1] - c[1]).abs());
            push = push.max((g[2] - c[2]).abs()).max((g[3] - c[3]).abs());
        }
        let states_gpu = self.gpu.read_back_state(&self.ctx.device, &self.ctx.queue);
        for (g, c) in states_gpu.iter().zip(self.cpu.state()) {
            assert_eq!(g.tag, c.tag, "cells hold different world cells");
        }
        (wind, push)
    }
}

fn world() -> Manifest {
    Manifest::from_path(&common::default_world().join("world.toml")).unwrap()
}

#[test]
fn gpu_field_matches_the_cpu_mirror_over_frames() {
    let m = world();
    let config = WindConfig::from_scene(&m, Some("helicopter")).unwrap();
    assert_eq!(config.cells, DEFAULT_CELLS);
    let mut pair = Pair::new(&config);
    // Under the helicopter's pass (its path loops every 20 s: at 88 s it is at its 8 s key),
    // walking; starting 2 s before a noise window restart (90 s).
    let heli = m.path("helicopter").unwrap();
    let start = DVec2::from_slice(&heli.keys[3].position_m[..2]);
    let mut t = 88.0;
    let mut cam = DVec3::new(start.x, start.y, 60.0);
    let mut frames: Vec<(DVec3, f32, Option<DVec2>, &str)> = Vec::new();
    for k in 0..8 {
        cam += DVec3::new(0.9, 0.4, 0.0);
        frames.push((
            cam,
            1.0 / 30.0,
            Some(cam.truncate()),
            if k == 0 { "first" } else { "walk" },
        ));
    }
    // A hitch, walking on.
    cam += DVec3::new(1.5, -0.5, 0.0);
    frames.push((cam, 0.5, Some(cam.truncate()), "0.5 s hitch"));
    // Across the window restart at 90 s, then a jump larger than the grid (a teleport).
    for _ in 0..3 {
        cam += DVec3::new(0.5, 0.5, 0.0);
        frames.push((cam, 1.0, Some(cam.truncate()), "restart"));
    }
    cam += DVec3::new(1234.5, -987.6, 0.0);
    frames.push((cam, 1.0 / 30.0, Some(cam.truncate()), "jump"));
    for _ in 0..2 {
        cam += DVec3::new(-3.3, 2.2, 0.0);
        frames.push((cam, 1.0 / 60.0, None, "after the jump"));
    }
    let (mut worst_wind, mut worst_push) = (0.0f32, 0.0f32);
    let mut restarts = 0;
    for (cam, dt, walker, what) in frames {
        let before = t;
        t += f64::from(dt);
        if (before / config.window_s).floor() != (t / config.window_s).floor() {
            restarts += 1;
        }
        pair.step(cam, t, dt, walker);
        let (wind, push) = pair.compare();
        let pushed = pair
            .cpu
            .cells()
            .iter()
            .filter(|c| c[2] != 0.0 || c[3] != 0.0)
            .count();
        assert!(
            walker.is_none() || what == "jump" || pushed > 0,
            "{what}: no trail"
        );
        eprintln!("t = {t:.3} s ({what}): GPU-CPU wind {wind:e} m/s, push {push:e}");
        assert!(
            wind <= WIND_TOLERANCE_MPS,
            "{what}: wind differs by {wind} m/s"
        );
        assert!(push <= PUSH_TOLERANCE, "{what}: push differs by {push}");
        worst_wind = worst_wind.max(wind);
        worst_push = worst_push.max(push);
    }
    eprintln!("largest GPU-CPU differences: wind {worst_wind:e} m/s, push {worst_push:e}");
    assert_eq!(restarts, 1, "the frames cross one noise window restart");
    // The scene's sources did act on the field.
    let p = pair.cpu.params();
    assert_eq!(p.counts[0], 2, "both helicopter sources active");
}

#[test]
fn lookup_snippet_matches_its_mirror_and_the_toroidal_layout() {
    let ctx = common::gpu();
    let mut config = WindConfig::new(AmbientWind {
        direction_deg: 70.0,
        speed_mps: 6.0,
        gustiness: 0.6,
    });
    config.cells = 64;
    let mut field = WindField::new(&ctx.device, &ctx.queue, &config);
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    // Far from the origin, at a negative cell index on x.
    let camera = DVec3::new(-40_123.37, 7_654_321.18, 10.0);
    field.update(
        &ctx.queue,
        &mut encoder,
        camera,
        12.5,
        0.1,
        None,
        &mut timer(&ctx),
    );
    ctx.queue.submit([encoder.finish()]);
    let cells = field.read_back(&ctx.device, &ctx.queue);
    let lookup = field.lookup();

    // Probe positions relative to the camera: cell centres, in between, beyond the edge.
    let mut probes: Vec<Vec2> = Vec::new();
    for k in 0..200 {
        let a = k as f32 * 0.37;
        let r = (k as f32 * 0.29) % 45.0;
        probes.push(Vec2::new(a.cos() * r, a.sin() * r));
    }
    let source = "#include \"shared/wind_lookup.wgsl\"
@group(0) @binding(0) var<uniform> wind_lookup: WindLookup;
@group(0) @binding(1) var<storage, read> wind_cells: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> probes: array<vec2<f32>>;
@group(0) @binding(3) var<storage, read_write> results: array<vec4<f32>>;
@compute @workgroup_size(64)
fn probe(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x < arrayLength(&probes) {
        results[gid.x] = wind_at(probes[gid.x]);
    }
}"
    .to_string();
    use wgpu::util::DeviceExt;
    let module = ctx
        .device
        .create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("wind probe"),
            source: wgpu::ShaderSource::Wgsl(
                verdant::shaders::assemble(&source)
                    .expect("assemble the probe")
                    .into(),
            ),
        });
    let pipeline = ctx
        .device
        .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("wind probe"),
            layout: None,
            module: &module,
            entry_point: Some("probe"),
            compilation_options: Default::default(),
            cache: None,
        });
    let probe_buffer = ctx
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: None,
            contents: bytemuck::cast_slice(&probes),
            usage: wgpu::BufferUsages::STORAGE,
        });
    let results = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: probes.len() as u64 * 16,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let bind = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: field.lookup_uniform().as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: field.buffer().as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: probe_buffer.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 3,
                resource: results.as_entire_binding(),
            },
        ],
    });
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.dispatch_workgroups((probes.len() as u32).div_ceil(64), 1, 1);
    }
    ctx.queue.submit([encoder.finish()]);
    let gpu: Vec<[f32; 4]> =
        verdant::gpu::read_buffer_pod(&ctx.device, &ctx.queue, &results, ..).expect("read back");

    let mut worst = 0.0f32;
    for (p, g) in probes.iter().zip(&gpu) {
        let c = verdant::wind::field_cpu::wind_at(&lookup, &cells, *p);
        for k in 0..4 {
            worst = worst.max((g[k] - c[k]).abs());
        }
    }
    eprintln!("lookup GPU-CPU: {worst:e}");
    assert!(worst <= 1e-4, "wind_at differs from its mirror by {worst}");

    // At a cell centre, wind_at returns that world cell's storage entry.
    let cell = f64::from(config.cell_m);
    for (di, dj) in [(0i32, 0i32), (5, -7), (-31, 30), (-20, 12)] {
        let origin = config.world_cell(camera.truncate());
        let world_cell = [origin[0] + di, origin[1] + dj];
        let centre = DVec2::new(
            (f64::from(world_cell[0]) + 0.5) * cell,
            (f64::from(world_cell[1]) + 0.5) * cell,
        );
        let rel = (centre - camera.truncate()).as_vec2();
        let got = verdant::wind::field_cpu::wind_at(&lookup, &cells, rel);
        let want = cells[config.storage_index(world_cell)];
        for k in 0..4 {
            assert!(
                (got[k] - want[k]).abs() < 1e-4,
                "{world_cell:?}: {got:?} vs {want:?}"
            );
        }
    }
}

/// A config with no ambient wind, no trail and the given sources at fixed points.
fn sources_only(sources: Vec<WindSource>) -> WindConfig {
    let mut config = WindConfig::new(AmbientWind {
        direction_deg: 0.0,
        speed_mps: 0.0,
        gustiness: 0.0,
    });
    config.cells = 64;
    config.trail = false;
    config.source_list = sources
        .into_iter()
        .map(|source| SourceConfig { source, path: None })
        .collect();
    config
}

fn fixed(kind: &str, at: DVec2, radius: f64, speed: f64, extra: &str) -> WindSource {
    let text = format!(
        "kind = \"{kind}\"\nradius_m = {radius}\nspeed_mps = {speed}\nposition_m = [{}, {}]\n{extra}",
        at.x, at.y
    );
    toml::from_str(&text).unwrap()
}

fn directional(direction_deg: f64, speed_mps: f64) -> WindSource {
    WindSource::Directional {
        direction_deg,
        speed_mps,
        position_m: None,
        path: None,
        start_s: 0.0,
        strength: Vec::new(),
        repeat: false,
    }
}

/// The settled field of `config` with the camera at `camera` (a 10 s step: the attack factor
/// `exp(-10 / 0.15)` is 0), as (world position of the cell centre, wind).
fn settled(ctx: &GpuContext, config: &WindConfig, camera: DVec2) -> Vec<(DVec2, Vec2)> {
    let mut field = WindField::new(&ctx.device, &ctx.queue, config);
    for t in [1.0, 11.0] {
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        field.update(
            &ctx.queue,
            &mut encoder,
            camera.extend(5.0),
            t,
            10.0,
            None,
            &mut timer(ctx),
        );
        ctx.queue.submit([encoder.finish()]);
    }
    let cells = field.read_back(&ctx.device, &ctx.queue);
    let n = config.cells as i32;
    let origin = config.world_cell(camera);
    let cell = f64::from(config.cell_m);
    let mut out = Vec::new();
    for dj in -n / 2..n / 2 {
        for di in -n / 2..n / 2 {
            let wc = [origin[0] + di, origin[1] + dj];
            let v = cells[config.storage_index(wc)];
            let centre = DVec2::new(
                (f64::from(wc[0]) + 0.5) * cell,
                (f64::from(wc[1]) + 0.5) * cell,
            );
            out.push((centre, Vec2::new(v[0], v[1])));
        }
    }
    out
}

/// Expected falloff of omni and vortex sources at `d` of radius `r` (outside the core).
fn falloff(d: f64, r: f64) -> f64 {
    if d >= r { 0.0 } else { (1.0 - d / r).powi(2) }
}

#[test]
fn each_source_kind_at_a_point() {
    let ctx = common::gpu();
    let camera = DVec2::new(5_012.3, 3_987.6);
    let centre = camera + DVec2::new(3.1, -2.4);
    let r = 20.0;
    // Well outside the core (1 m) and inside the radius.
    let ring = |p: DVec2| {
        let d = p.distance(centre);
        (2.0..r - 0.5).contains(&d)
    };

    // Directional: its vector everywhere; two of them add.
    let one = settled(&ctx, &sources_only(vec![directional(30.0, 5.0)]), camera);
    let want = DVec2::from_angle(30f64.to_radians()) * 5.0;
    for (_, v) in &one {
        assert!((v.as_dvec2() - want).length() < 1e-5, "{v} vs {want}");
    }
    let two = settled(
        &ctx,
        &sources_only(vec![directional(30.0, 5.0), directional(120.0, 2.0)]),
        camera,
    );
    let want = want + DVec2::from_angle(120f64.to_radians()) * 2.0;
    for (_, v) in &two {
        assert!((v.as_dvec2() - want).length() < 1e-5, "sum {v} vs {want}");
    }

    // Omni: away from the centre, 10 m/s * (1 - d/20)^2 (2.5 m/s at 10 m), nothing beyond.
    let omni = settled(
        &ctx,
        &sources_only(vec![fixed("omni", centre, r, 10.0, "")]),
        camera,
    );
    let mut checked = 0;
    for (p, v) in &omni {
        let off = *p - centre;
        let d = off.length();
        let want = falloff(d, r) * 10.0;
        let v = v.as_dvec2();
        if ring(*p) {
            assert!(v.normalize().dot(off / d) > 0.99999, "omni at {off}: {v}");
            assert!(
                (v.length() - want).abs() < 1e-4,
                "omni |v| {} vs {want} at {d} m",
                v.length()
            );
            checked += 1;
        } else if d >= r {
            assert_eq!(v, DVec2::ZERO, "omni beyond its radius at {d} m");
        }
    }
    assert!(checked > 500, "{checked}");
    assert_eq!(falloff(10.0, 20.0) * 10.0, 2.5);
    // The cell nearest 10 m east of the centre.
    let (p, v) = omni
        .iter()
        .min_by(|a, b| {
            let t = centre + DVec2::new(10.0, 0.0);
            a.0.distance(t).total_cmp(&b.0.distance(t))
        })
        .unwrap();
    let d = p.distance(centre);
    assert!((f64::from(v.length()) - 10.0 * falloff(d, r)).abs() < 1e-4);
    assert!(
        v.x > 2.0,
        "about 2.5 m/s eastward 10 m east of the centre: {v}"
    );

    // Vortex: tangential, counter-clockwise by default, 6 m/s * (1 - d/20)^2.
    for (extra, sense) in [("", 1.0), ("clockwise = true", -1.0)] {
        let field = settled(
            &ctx,
            &sources_only(vec![fixed("vortex", centre, r, 6.0, extra)]),
            camera,
        );
        for (p, v) in &field {
            let off = *p - centre;
            let d = off.length();
            let v = v.as_dvec2();
            if ring(*p) {
                let radial = off / d;
                assert!(
                    v.dot(radial).abs() < 1e-4,
                    "vortex has a radial part at {off}: {v}"
                );
                // Counter-clockwise: the wind turns the radius toward +90 degrees.
                assert!(
                    sense * radial.perp_dot(v) > 0.0,
                    "vortex turns the wrong way at {off}"
                );
                assert!((v.length() - 6.0 * falloff(d, r)).abs() < 1e-4);
            } else if d >= r {
                assert_eq!(v, DVec2::ZERO);
            }
        }
    }
    // Vortex with inflow: the radial part points inward, inflow * falloff.
    let field = settled(
        &ctx,
        &sources_only(vec![fixed("vortex", centre, r, 6.0, "inflow_mps = 3.0")]),
        camera,
    );
    for (p, v) in &field {
        if ring(*p) {
            let off = *p - centre;
            let d = off.length();
            let radial_part = v.as_dvec2().dot(off / d);
            assert!(
                (radial_part + 3.0 * falloff(d, r)).abs() < 1e-4,
                "{radial_part}"
            );
        }
    }
    // Omni and directional sum.
    let sum = settled(
        &ctx,
        &sources_only(vec![
            fixed("omni", centre, r, 10.0, ""),
            directional(200.0, 3.0),
        ]),
        camera,
    );
    let dir = DVec2::from_angle(200f64.to_radians()) * 3.0;
    for ((_, a), (_, b)) in sum.iter().zip(&omni) {
        assert!((a.as_dvec2() - b.as_dvec2() - dir).length() < 1e-4);
    }
}

/// Frame time of the continuity checks, seconds.
const FRAME_S: f64 = 1.0 / 60.0;

/// Largest change of any of `points`' ambient wind between frames of [`FRAME_S`] from `from`
/// to `to`, m/s.
fn largest_frame_step(config: &WindConfig, points: &[DVec2], from: f64, to: f64) -> f32 {
    let mut worst = 0.0f32;
    for p in points {
        let mut prev = ambient_at(config, *p, from);
        let mut t = from;
        while t < to {
            t += FRAME_S;
            let v = ambient_at(config, *p, t);
            worst = worst.max((v - prev).length());
            prev = v;
        }
    }
    worst
}

#[test]
fn ambient_is_continuous_across_window_restarts_and_never_repeats() {
    let config = WindConfig::new(AmbientWind {
        direction_deg: 20.0,
        speed_mps: 4.0,
        gustiness: 0.35,
    });
    let (period, blend) = (config.window_s, config.blend_s);
    let points: Vec<DVec2> = (0..300)
        .map(|k| {
            let a = k as f64 * 2.399;
            let r = (k as f64).sqrt() * 9.0;
            DVec2::new(20_300.0, 28_150.0) + DVec2::from_angle(a) * r
        })
        .collect();
    let largest_step = |from: f64, to: f64| largest_frame_step(&config, &points, from, to);
    let ordinary = largest_step(2.0 * period + 20.0, 2.0 * period + 40.0);
    let restart = largest_step(3.0 * period - 2.0, 3.0 * period + blend + 2.0);
    eprintln!(
        "largest frame-to-frame change: ordinary {ordinary} m/s, across a restart {restart} m/s"
    );
    assert!(ordinary > 0.0);
    // The cross-fade adds at most a comparable rate of change (see the report for the figure).
    assert!(
        restart <= 1.5 * ordinary,
        "restart changes the wind by {restart} m/s in a frame, ordinarily {ordinary}"
    );
    // Right at the restart, the field does not jump.
    let t0 = 3.0 * period;
    for p in &points {
        let (a, b) = (
            ambient_at(&config, *p, t0 - 1e-4),
            ambient_at(&config, *p, t0 + 1e-4),
        );
        assert!((a - b).length() < 1e-3, "jump at the restart: {a} -> {b}");
    }

    // No repetition: a window period later the field is a different one.
    let field_at =
        |t: f64| -> Vec<Vec2> { points.iter().map(|p| ambient_at(&config, *p, t)).collect() };
    let now = field_at(2.0 * period + 30.0);
    let avg = now.iter().copied().sum::<Vec2>() / now.len() as f32;
    let spread =
        (now.iter().map(|v| (*v - avg).length_squared()).sum::<f32>() / now.len() as f32).sqrt();
    assert!(
        spread > 0.2,
        "gusts vary across the field: spread {spread} m/s"
    );
    assert!((avg.length() - 4.0).abs() < 1.0, "mean wind {avg}");
    for later in [1.0, 2.0, 7.0] {
        let then = field_at(2.0 * period + 30.0 + later * period);
        let rms = (now
            .iter()
            .zip(&then)
            .map(|(a, b)| (*a - *b).length_squared())
            .sum::<f32>()
            / now.len() as f32)
            .sqrt();
        assert!(
            rms > 0.5 * spread,
            "{later} periods later the field differs by only {rms} m/s (spread {spread})"
        );
    }
}

/// Steps `field` with a fixed camera and no walker; returns the cell `index`'s source-driven
/// wind (state) and total wind.
fn step_fixed(
    ctx: &GpuContext,
    field: &mut WindField,
    camera: DVec2,
    t: f64,
    dt: f32,
    index: usize,
) -> (Vec2, Vec2) {
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    field.update(
        &ctx.queue,
        &mut encoder,
        camera.extend(3.0),
        t,
        dt,
        None,
        &mut timer(ctx),
    );
    ctx.queue.submit([encoder.finish()]);
    let s = field.read_back_state(&ctx.device, &ctx.queue)[index].source;
    let c = field.read_back(&ctx.device, &ctx.queue)[index];
    (Vec2::from_array(s), Vec2::new(c[0], c[1]))
}

#[test]
fn source_wind_decays_toward_the_ambient_and_stays_bounded_with_hitches() {
    let ctx = common::gpu();
    let camera = DVec2::new(12_345.6, 6_543.2);
    let centre = camera + DVec2::new(4.0, 1.0);
    // An omni source on until 5 s, off from 5.01 s, on again from 20.01 s.
    let keys = "strength = [[0.0, 1.0], [5.0, 1.0], [5.01, 0.0], [20.0, 0.0], [20.01, 1.0]]";
    let mut config = sources_only(vec![fixed("omni", centre, 20.0, 12.0, keys)]);
    config.ambient = AmbientWind {
        direction_deg: 20.0,
        speed_mps: 4.0,
        gustiness: 0.35,
    };
    let probe_cell = config.world_cell(centre + DVec2::new(6.0, 0.0));
    let probe_centre = DVec2::new(
        (f64::from(probe_cell[0]) + 0.5) * f64::from(config.cell_m),
        (f64::from(probe_cell[1]) + 0.5) * f64::from(config.cell_m),
    );
    let index = config.storage_index(probe_cell);
    let release = (-0.5f64 / f64::from(config.release_s)).exp() as f32;
    let attack = (-0.5f64 / f64::from(config.attack_s)).exp() as f32;

    // 0.5 s hitches throughout.
    let mut field = WindField::new(&ctx.device, &ctx.queue, &config);
    // A fresh cell settles on its sources at once.
    let (s_on, _) = step_fixed(&ctx, &mut field, camera, 4.0, 0.5, index);
    let (s, _) = step_fixed(&ctx, &mut field, camera, 4.5, 0.5, index);
    assert!(
        (s - s_on).length() < 1e-5 && s_on.length() > 5.0,
        "{s_on} {s}"
    );
    let (s, _) = step_fixed(&ctx, &mut field, camera, 5.0, 0.5, index);
    assert!((s - s_on).length() < 1e-5);
    // Off: every step keeps exp(-0.5 / 1.5) of the source wind, never overshooting, and the
    // rest of the cell's wind is the ambient field there.
    let mut prev = s_on;
    for k in 1..=29 {
        let t = 5.0 + 0.5 * f64::from(k);
        let (s, wind) = step_fixed(&ctx, &mut field, camera, t, 0.5, index);
        assert!(
            (s - prev * release).length() <= 1e-5 * s_on.length(),
            "t {t}: {s} vs {}",
            prev * release
        );
        assert!(
            s.dot(s_on) >= 0.0 && s.length() <= prev.length(),
            "t {t}: {s} after {prev}"
        );
        let ambient = ambient_at(&config, probe_centre, t);
        assert!(
            (wind - s - ambient).length() < 1e-3,
            "t {t}: wind {wind}, source {s}, ambient {ambient}"
        );
        prev = s;
    }
    assert!(
        prev.length() < s_on.length() * 1e-4,
        "after 14.5 s off: {prev}"
    );
    // On again at 20.01 s: the attack (0.15 s) brings it 96 % of the way in one 0.5 s step.
    let (s, _) = step_fixed(&ctx, &mut field, camera, 20.5, 0.5, index);
    let want = s_on + (prev - s_on) * attack;
    assert!((s - want).length() < 1e-4 * s_on.length(), "{s} vs {want}");
    assert!(s.length() > 0.95 * s_on.length());

    // At 1/32 s frames: one release time (1.5 s) after the source went off, exp(-1) remains.
    let mut field = WindField::new(&ctx.device, &ctx.queue, &config);
    let dt = 1.0f32 / 32.0;
    let (s_at_5, _) = step_fixed(&ctx, &mut field, camera, 5.0, dt, index);
    let mut s = s_at_5;
    for k in 1..=48 {
        s = step_fixed(
            &ctx,
            &mut field,
            camera,
            5.0 + f64::from(dt) * f64::from(k),
            dt,
            index,
        )
        .0;
    }
    let ratio = s.length() / s_at_5.length();
    assert!(
        (ratio - (-1.0f32).exp()).abs() < 1e-4,
        "after one release time {ratio} remains"
    );
}

#[test]
fn trail_pushes_away_from_the_path_fades_and_stays_bounded() {
    let ctx = common::gpu();
    let mut config = WindConfig::new(AmbientWind {
        direction_deg: 20.0,
        speed_mps: 4.0,
        gustiness: 0.35,
    });
    config.cells = 64;
    let mut field = WindField::new(&ctx.device, &ctx.queue, &config);
    let cell = f64::from(config.cell_m);
    // Walk east along the edge between two rows of cells, whose centres lie 0.625 m north and
    // south of the path.
    let (x0, y0) = (1200.0 * cell, 800.0 * cell);
    let mut t = 0.0;
    let mut run = |field: &mut WindField, cam: DVec2, walker: Option<DVec2>, dt: f32| {
        t += f64::from(dt);
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        field.update(
            &ctx.queue,
            &mut encoder,
            cam.extend(1.7),
            t,
            dt,
            walker,
            &mut timer(&ctx),
        );
        ctx.queue.submit([encoder.finish()]);
        let cells = field.read_back(&ctx.device, &ctx.queue);
        for c in &cells {
            let push = Vec2::new(c[2], c[3]).length();
            assert!(push <= 1.0 + 1e-6, "push {push} exceeds 1");
        }
        cells
    };
    let frame = 1.0f32 / 30.0;
    let mut cells = Vec::new();
    for k in 0..=20 {
        let p = DVec2::new(x0 + 0.5 * f64::from(k), y0);
        cells = run(&mut field, p, Some(p), frame);
    }
    // Standing still for a while: still bounded (a stamp keeps the larger push, never a sum).
    let end = DVec2::new(x0 + 10.0, y0);
    for _ in 0..10 {
        cells = run(&mut field, end, Some(end), frame);
    }
    let push_at = |cells: &[[f32; 4]], p: DVec2| -> Vec2 {
        let c = cells[config.storage_index(config.world_cell(p))];
        Vec2::new(c[2], c[3])
    };
    // The cells centred 5.625 m along the path: stamped by the step at k = 12 (5.5 -> 6 m), then
    // faded over 8 walking and 10 standing frames.
    let mid = x0 + 5.625;
    let north = push_at(&cells, DVec2::new(mid, y0 + 0.6));
    let south = push_at(&cells, DVec2::new(mid, y0 - 0.6));
    let far = push_at(&cells, DVec2::new(mid, y0 + 1.9));
    eprintln!("push north {north}, south {south}, 1.875 m away {far}");
    let u = 0.625f32 / config.trail_radius_m;
    assert!(
        config.trail_radius_m < 1.875,
        "the far cell must lie outside the capsule"
    );
    let fade = (-f64::from(frame) / f64::from(config.trail_fade_s))
        .exp()
        .powi(18) as f32;
    let want = (1.0 - u * u * (3.0 - 2.0 * u)) * fade;
    assert!(
        (north.y - want).abs() < 1e-4 && north.x.abs() < 1e-5,
        "north: {north}, want {want}"
    );
    assert!(
        (south.y + want).abs() < 1e-4 && south.x.abs() < 1e-5,
        "south: {south}"
    );
    assert_eq!(far, Vec2::ZERO, "beyond the capsule's radius");

    // No walker: the trail fades by exp(-1) over the fade time (3 s), and stays where it was in
    // the world while the camera moves away (toroidal addressing moves no data).
    let before = north;
    let mut cam = end;
    for _ in 0..30 {
        cam += DVec2::new(0.2, 0.1);
        cells = run(&mut field, cam, None, 0.1);
    }
    let after = push_at(&cells, DVec2::new(mid, y0 + 0.6));
    let ratio = after.y / before.y;
    assert!(
        (ratio - (-1.0f32).exp()).abs() < 1e-4,
        "after the fade time {ratio} remains"
    );
    assert!(after.x.abs() < 1e-5);
    // A jump beyond the trail's longest step starts a new trail: no capsule across the gap.
    let from = cam;
    run(&mut field, from, Some(from), frame);
    let to = from + DVec2::new(20.0, 0.0);
    cells = run(&mut field, to, Some(to), frame);
    let gap = push_at(&cells, from + DVec2::new(10.0, 0.3));
    assert_eq!(gap, Vec2::ZERO, "a teleport left a trail");
    // ... but it does stamp where the walker landed.
    let mut landed = 0.0f32;
    for (dx, dy) in [
        (-1.0, -1.0),
        (-1.0, 0.0),
        (-1.0, 1.0),
        (0.0, -1.0),
        (0.0, 1.0),
        (1.0, -1.0),
        (1.0, 0.0),
        (1.0, 1.0),
        (0.0, 0.0),
    ] {
        landed = landed.max(push_at(&cells, to + DVec2::new(dx, dy) * cell).length());
    }
    assert!(landed > 0.2, "no push where the walker landed: {landed}");
}

// ---------------------------------------------------------------------------------------------
// Wind scenes in the manifest.

#[test]
fn committed_world_has_the_wind_scenes_and_the_helicopter_path() {
    let m = world();
    let names: Vec<&str> = m.wind_scenes.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["calm", "breeze", "storm", "helicopter"]);
    let heli_path = m.path("helicopter").expect("helicopter path");
    assert!((15.0..=20.0).contains(&heli_path.duration_s));
    let speed = |name: &str| m.wind_scene(name).unwrap().ambient.speed_mps;
    assert!(
        speed("calm") < 1.5 && (3.0..=5.0).contains(&speed("breeze")) && speed("storm") >= 12.0
    );
    let storm = m.wind_scene("storm").unwrap();
    assert!(storm.ambient.gustiness >= 0.6);
    assert!(
        storm
            .sources
            .iter()
            .filter(|s| s.kind_name() == "directional")
            .count()
            >= 2
    );

    // The default scene is the breeze; the helicopter's downwash follows its path.
    let breeze = WindConfig::from_scene(&m, None).unwrap();
    assert_eq!(breeze.scene, "breeze");
    assert!(breeze.source_list.is_empty());
    let heli = WindConfig::from_scene(&m, Some("helicopter")).unwrap();
    assert!(!heli.source_list.is_empty());
    for s in &heli.source_list {
        assert!(
            matches!(s.source, WindSource::Omni { radius_m, .. } | WindSource::Vortex { radius_m, .. } if (20.0..=30.0).contains(&radius_m))
        );
        let p0 = s.position_at(0.0).unwrap();
        let want = DVec2::from_slice(&heli_path.keys[0].position_m[..2]);
        assert!(p0.distance(want) < 1e-6);
        // It loops over the path's duration.
        let p1 = s.position_at(heli_path.duration_s * 0.5).unwrap();
        let p2 = s.position_at(heli_path.duration_s * 1.5).unwrap();
        assert!(p1.distance(p0) > 10.0 && p1.distance(p2) < 1e-6);
        assert_eq!(s.strength_at(-1.0), 0.0);
        assert_eq!(s.strength_at(1.0), 0.5);
        assert_eq!(s.strength_at(60.0), 1.0);
    }
    assert!(matches!(
        WindConfig::from_scene(&m, Some("hurricane")),
        Err(WindError::UnknownScene { ref name, ref available }) if name == "hurricane" && available.contains("storm")
    ));
    // A world without scenes falls back to its wind defaults.
    let mut bare = m.clone();
    bare.wind_scenes.clear();
    let c = WindConfig::from_scene(&bare, None).unwrap();
    assert_eq!(c.ambient, AmbientWind::from(&m.wind));
    assert_eq!(c.cell_m, DEFAULT_CELL_M);
    // Asking it for a scene by name says that it has none, not an empty list.
    let err = WindConfig::from_scene(&bare, Some("breeze")).unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("no wind scene called \"breeze\"")
            && text.contains("the world has no wind scenes")
            && text.contains("[[wind_scenes]]"),
        "{text}"
    );
}

/// A source that follows a camera path loops over the whole path as its keys span it (the
/// length every tool flies), not over what a `duration_s` field says.
#[test]
fn a_path_following_source_loops_over_the_whole_path() {
    let m = parse(SMALL).unwrap();
    let config = WindConfig::from_scene(&m, Some("gusty")).unwrap();
    let mut source = config.source_list[1].clone();
    let path = source.path.as_mut().unwrap();
    assert_eq!(path.name, "overview");
    // What validation refuses; set here to tell the keys' span (10 s) from the field.
    path.duration_s = 4.0;
    let path = path.clone();
    for t in [1.0, 7.0, 9.5] {
        let want = sample_path(&path, t).position.truncate();
        let at = source.position_at(t).unwrap();
        assert!(at.distance(want) < 1e-9, "at {t} s: {at} instead of {want}");
        let again = source.position_at(t + 10.0).unwrap();
        assert!(
            again.distance(want) < 1e-6,
            "at {} s: {again} instead of {want}",
            t + 10.0
        );
    }
}

const SMALL: &str = r#"
name = "test"
extent_m = [900.0, 1000.0]
height_range_m = [-10.0, 500.0]

[pyramid]
root_tile_size_m = 512.0
root_tiles = [2, 2]
tile_cells = 16
border = 2
stored_levels = 2
derived_levels = 1

[[grass_types]]
name = "bare"
ground_color = [0.3, 0.3, 0.3]
base_color = [0.3, 0.3, 0.3]
tip_color = [0.3, 0.3, 0.3]
height_m = [0.0, 0.0]
width_m = [0.0, 0.0]
stiffness = 1.0

[[paths]]
name = "overview"
duration_s = 10.0
keys = [
    { t_s = 0.0, position_m = [10.0, 10.0, 600.0], yaw_deg = 45.0, pitch_deg = -10.0 },
    { t_s = 10.0, position_m = [800.0, 900.0, 600.0], yaw_deg = 45.0, pitch_deg = -10.0 },
]

[[wind_scenes]]
name = "gusty"
ambient = { direction_deg = 10.0, speed_mps = 6.0, gustiness = 0.5 }
sources = [
    { kind = "directional", direction_deg = 90.0, speed_mps = 3.0, strength = [[0.0, 0.0], [2.0, 1.0]] },
    { kind = "omni", radius_m = 25.0, speed_mps = 10.0, path = "overview" },
    { kind = "vortex", radius_m = 15.0, speed_mps = 5.0, inflow_mps = -2.0, position_m = [300.0, 400.0] },
]
"#;

fn parse(text: &str) -> Result<Manifest, WorldError> {
    Manifest::parse(text, Path::new("worlds/test/world.toml"))
}

/// Parses SMALL with `from` replaced by `to` (which must occur), expecting an error naming the
/// file.
fn broken(from: &str, to: &str) -> WorldError {
    assert!(SMALL.contains(from), "{from}");
    let err = parse(&SMALL.replacen(from, to, 1)).expect_err(to);
    assert!(
        err.to_string().starts_with("worlds/test/world.toml: "),
        "message does not name the file: {err}"
    );
    err
}

#[test]
fn wind_scenes_parse_and_old_manifests_still_do() {
    let m = parse(SMALL).unwrap();
    let scene = m.wind_scene("gusty").unwrap();
    assert_eq!(scene.sources.len(), 3);
    assert_eq!(scene.sources[2].kind_name(), "vortex");
    // Round trip.
    assert_eq!(parse(&m.to_toml()).unwrap(), m);
    // A manifest without wind scenes (as written before they existed) still parses.
    let old = &SMALL[..SMALL.find("[[wind_scenes]]").unwrap()];
    let m = parse(old).unwrap();
    assert!(m.wind_scenes.is_empty());
}

#[test]
fn invalid_wind_sources_get_errors_naming_the_field() {
    let field_of = |e: &WorldError| -> String {
        match e {
            WorldError::NonFinite { field, .. }
            | WorldError::NonPositive { field, .. }
            | WorldError::Negative { field, .. }
            | WorldError::OutOfRange { field, .. }
            | WorldError::UnknownPathRef { field, .. }
            | WorldError::WindSourcePlacement { field, .. }
            | WorldError::StrengthKeysOutOfOrder { field, .. } => field.clone(),
            other => panic!("unexpected error {other}"),
        }
    };
    let cases: [(&str, &str, &str); 10] = [
        (
            "path = \"overview\"",
            "path = \"tour\"",
            "wind_scenes[0].sources[1].path",
        ),
        (
            "radius_m = 25.0",
            "radius_m = -25.0",
            "wind_scenes[0].sources[1].radius_m",
        ),
        (
            "radius_m = 15.0",
            "radius_m = 0.0",
            "wind_scenes[0].sources[2].radius_m",
        ),
        (
            "speed_mps = 5.0",
            "speed_mps = -5.0",
            "wind_scenes[0].sources[2].speed_mps",
        ),
        (
            "speed_mps = 3.0",
            "speed_mps = nan",
            "wind_scenes[0].sources[0].speed_mps",
        ),
        (
            "inflow_mps = -2.0",
            "inflow_mps = inf",
            "wind_scenes[0].sources[2].inflow_mps",
        ),
        (
            "[2.0, 1.0]",
            "[-1.0, 1.0]",
            "wind_scenes[0].sources[0].strength",
        ),
        (
            "position_m = [300.0, 400.0]",
            "position_m = [300.0, nan]",
            "wind_scenes[0].sources[2].position_m[1]",
        ),
        (
            "position_m = [300.0, 400.0]",
            "position_m = [1.0, 2.0], path = \"overview\"",
            "wind_scenes[0].sources[2]",
        ),
        (
            "speed_mps = 6.0",
            "speed_mps = -6.0",
            "wind_scenes[0].ambient.speed_mps",
        ),
    ];
    for (from, to, field) in cases {
        let err = broken(from, to);
        assert_eq!(field_of(&err), field, "{to}: {err}");
        assert!(err.to_string().contains(field), "{err}");
        eprintln!("{err}");
    }
    assert!(matches!(
        broken("[2.0, 1.0]", "[-1.0, 1.0]"),
        WorldError::StrengthKeysOutOfOrder { index: 1, .. }
    ));
    assert!(matches!(
        broken("path = \"overview\"", "path = \"tour\""),
        WorldError::UnknownPathRef { ref name, .. } if name == "tour"
    ));
    // An omni source needs a place.
    let err = broken(", path = \"overview\"", "");
    assert!(
        matches!(err, WorldError::WindSourcePlacement { ref field, .. } if field == "wind_scenes[0].sources[1]"),
        "{err}"
    );
    // Duplicate scene names.
    let twice = format!("{SMALL}\n[[wind_scenes]]\nname = \"gusty\"\n");
    assert!(matches!(
        parse(&twice),
        Err(WorldError::DuplicateWindScene { ref name, .. }) if name == "gusty"
    ));
    // Unknown kinds and fields are refused by the parser, naming them.
    let err = broken("kind = \"omni\"", "kind = \"tornado\"");
    assert!(
        matches!(err, WorldError::ManifestSyntax { .. }) && err.to_string().contains("tornado"),
        "{err}"
    );
    let err = broken("inflow_mps = -2.0", "inflow_mps = -2.0, spin = 1.0");
    assert!(
        matches!(err, WorldError::ManifestSyntax { .. }) && err.to_string().contains("spin"),
        "{err}"
    );
    // A field of another kind, and one a kind needs, are named.
    let err = broken(
        "inflow_mps = -2.0",
        "inflow_mps = -2.0, direction_deg = 1.0",
    );
    assert!(err.to_string().contains("`direction_deg`"), "{err}");
    let err = broken("radius_m = 25.0, ", "");
    assert!(err.to_string().contains("`radius_m`"), "{err}");
    // An unknown kind is shown where it is written, and a field of another kind on its own
    // source's line or header (both were shown at the list's start: `sources = [`, or the first
    // `[[wind_scenes.sources]]`).
    let err = broken("kind = \"omni\"", "kind = \"tornado\"").to_string();
    assert!(err.contains("{ kind = \"tornado\""), "{err}");
    let err = broken(
        "inflow_mps = -2.0",
        "inflow_mps = -2.0, direction_deg = 1.0",
    )
    .to_string();
    assert!(err.contains("{ kind = \"vortex\""), "{err}");
    let tables = format!(
        "{SMALL}\n[[wind_scenes]]\nname = \"still\"\n\n[[wind_scenes.sources]]\nkind = \"omni\"\n\
         radius_m = 30.0\nspeed_mps = 10.0\nposition_m = [1.0, 2.0]\n\n\
         [[wind_scenes.sources]]\nkind = \"omni\"\nradius_m = 30.0\nspeed_mps = 10.0\n\
         position_m = [1.0, 2.0]\nclockwise = true\n"
    );
    let line_of = |text: &str, what: &str, nth: usize| {
        text.lines()
            .enumerate()
            .filter(|(_, l)| l.contains(what))
            .nth(nth)
            .unwrap()
            .0
            + 1
    };
    let second = line_of(&tables, "[[wind_scenes.sources]]", 1);
    let err = parse(&tables).unwrap_err().to_string();
    assert!(
        err.contains(&format!("line {second},")) && err.contains("`clockwise`"),
        "{err}"
    );
    let bad_kind = tables.replacen(
        "kind = \"omni\"\nradius_m = 30.0\nspeed_mps = 10.0\nposition_m = [1.0, 2.0]\nclockwise",
        "kind = \"whirl\"\nradius_m = 30.0\nspeed_mps = 10.0\nposition_m = [1.0, 2.0]\nclockwise",
        1,
    );
    let err = parse(&bad_kind).unwrap_err().to_string();
    let kind_line = line_of(&bad_kind, "kind = \"whirl\"", 0);
    assert!(
        err.contains(&format!("line {kind_line},")) && err.contains("whirl"),
        "{err}"
    );
    // A value of the wrong shape in a source written as a table is shown on its own line (it
    // was shown on the table's header, without the field).
    let table = format!(
        "{SMALL}\n[[wind_scenes]]\nname = \"still\"\n\n[[wind_scenes.sources]]\nkind = \"omni\"\n\
         radius_m = 30.0\nspeed_mps = 10.0\nposition_m = [1.0, 2.0, 3.0]\n"
    );
    let err = parse(&table).unwrap_err().to_string();
    assert!(
        err.contains("position_m = [1.0, 2.0, 3.0]") && err.contains("invalid length 3"),
        "{err}"
    );
    // And a strength key of three numbers.
    let err = broken("[2.0, 1.0]", "[2.0, 1.0, 5.0]").to_string();
    assert!(err.contains("invalid length 3"), "{err}");
    // Too many sources.
    let many = (0..9)
        .map(|_| "{ kind = \"directional\", direction_deg = 0.0, speed_mps = 1.0 }")
        .collect::<Vec<_>>()
        .join(", ");
    let err = parse(&format!(
        "{SMALL}\n[[wind_scenes]]\nname = \"many\"\nsources = [{many}]\n"
    ))
    .unwrap_err();
    assert_eq!(field_of(&err), "wind_scenes[1].sources");
}

/// Wind values beyond their documented ranges (a wind of 1e30 m/s was accepted and drawn as
/// calm) are refused, naming the field and the range.
#[test]
fn wind_values_beyond_their_ranges_are_refused_naming_field_and_range() {
    let cases: &[(&str, &str, &str, &str)] = &[
        (
            "speed_mps = 6.0",
            "speed_mps = 1e30",
            "wind_scenes[0].ambient.speed_mps",
            "at most 120 m/s",
        ),
        (
            "gustiness = 0.5",
            "gustiness = 1.5",
            "wind_scenes[0].ambient.gustiness",
            "in 0..=1",
        ),
        (
            "direction_deg = 10.0",
            "direction_deg = 1e30",
            "wind_scenes[0].ambient.direction_deg",
            "in -36000..=36000 degrees",
        ),
        (
            "speed_mps = 3.0",
            "speed_mps = 121.0",
            "wind_scenes[0].sources[0].speed_mps",
            "at most 120 m/s",
        ),
        (
            "direction_deg = 90.0",
            "direction_deg = -1e300",
            "wind_scenes[0].sources[0].direction_deg",
            "in -36000..=36000 degrees",
        ),
        (
            "[2.0, 1.0]",
            "[2.0, 1e30]",
            "wind_scenes[0].sources[0].strength[1][1]",
            "at most 10",
        ),
        (
            "[2.0, 1.0]",
            "[1e30, 1.0]",
            "wind_scenes[0].sources[0].strength[1][0]",
            "in -1000000..=1000000 s",
        ),
        (
            "strength = [[0.0, 0.0]",
            "start_s = 1e30, strength = [[0.0, 0.0]",
            "wind_scenes[0].sources[0].start_s",
            "at most 1000000 s",
        ),
        (
            "radius_m = 25.0",
            "radius_m = 1e30",
            "wind_scenes[0].sources[1].radius_m",
            "at most 10000 m",
        ),
        (
            "speed_mps = 10.0",
            "speed_mps = 1e30",
            "wind_scenes[0].sources[1].speed_mps",
            "at most 120 m/s",
        ),
        (
            "inflow_mps = -2.0",
            "inflow_mps = -1e30",
            "wind_scenes[0].sources[2].inflow_mps",
            "in -120..=120 m/s",
        ),
        (
            "position_m = [300.0, 400.0]",
            "position_m = [300.0, 1e30]",
            "wind_scenes[0].sources[2].position_m[1]",
            "in -20000000..=20000000 m",
        ),
    ];
    for &(from, to, field, range) in cases {
        let err = broken(from, to);
        assert!(
            matches!(err, WorldError::OutOfRange { field: ref f, .. } if f == field),
            "{to}: {err}"
        );
        let text = err.to_string();
        assert!(text.contains(&format!(": {field} = ")), "{text}");
        assert!(text.ends_with(&format!("must be {range}")), "{text}");
    }
    // The largest values allowed are accepted.
    let edge = SMALL
        .replacen("speed_mps = 6.0", "speed_mps = 120.0", 1)
        .replacen("radius_m = 25.0", "radius_m = 10000.0", 1)
        .replacen("[2.0, 1.0]", "[2.0, 10.0]", 1);
    parse(&edge).unwrap();
    // A path's wind keys: times and blends.
    let text = with_keys();
    for (from, to, field) in [
        (
            "{ t_s = 4.0, scene = \"gusty\", blend_s = 2.0 }",
            "{ t_s = 4.0, scene = \"gusty\", blend_s = 1e30 }",
            "paths[0].wind[1].blend_s",
        ),
        (
            "{ t_s = 4.0, scene = \"gusty\", blend_s = 2.0 }",
            "{ t_s = 1e30, scene = \"gusty\", blend_s = 2.0 }",
            "paths[0].wind[1].t_s",
        ),
    ] {
        assert!(text.contains(from), "{from}");
        let err = parse(&text.replacen(from, to, 1)).unwrap_err();
        assert!(
            matches!(err, WorldError::OutOfRange { field: ref f, .. } if f == field),
            "{to}: {err}"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Wind scenes changing along a camera path, walkers and the [features] table.

/// SMALL with a second scene, the overview path's wind keys, a walker path and a features table.
fn with_keys() -> String {
    SMALL.replace(
        "keys = [\n    { t_s = 0.0, position_m = [10.0, 10.0, 600.0]",
        "walker = \"stroll\"\n\
         wind = [\n    { t_s = 0.0, scene = \"still\" },\n    { t_s = 4.0, scene = \"gusty\", blend_s = 2.0 },\n]\n\
         keys = [\n    { t_s = 0.0, position_m = [10.0, 10.0, 600.0]",
    ) + r#"
[[wind_scenes]]
name = "still"
ambient = { direction_deg = 200.0, speed_mps = 0.5, gustiness = 0.1 }

[[paths]]
name = "stroll"
duration_s = 10.0
keys = [
    { t_s = 0.0, position_m = [100.0, 100.0, 1.7], yaw_deg = 0.0, pitch_deg = 0.0 },
    { t_s = 10.0, position_m = [112.0, 100.0, 1.7], yaw_deg = 0.0, pitch_deg = 0.0 },
]

[features]
specular = false
ground-darkening = false
"#
}

#[test]
fn path_wind_keys_walkers_and_features_parse_and_bad_ones_are_named() {
    use verdant::features::{Feature, Features};
    let text = with_keys();
    let m = parse(&text).unwrap();
    let path = m.path("overview").unwrap();
    assert_eq!(path.walker.as_deref(), Some("stroll"));
    assert_eq!(path.wind.len(), 2);
    assert_eq!(path.wind[0].blend_s, verdant::world::DEFAULT_WIND_BLEND_S);
    assert_eq!(path.wind[1].blend_s, 2.0);
    let f = Features::from(&m.features);
    assert!(!f.has(Feature::Specular) && !f.has(Feature::GroundDarkening));
    assert!(f.has(Feature::Translucency) && f.has(Feature::Interaction));
    assert_eq!(parse(&m.to_toml()).unwrap(), m, "round trip");
    let no_trees = text.replace(
        "ground-darkening = false",
        "ground-darkening = false\ntrees = false",
    );
    let f = Features::from(&parse(&no_trees).unwrap().features);
    assert!(!f.has(Feature::Trees) && f.has(Feature::Plants));
    // Without a [features] table, everything is on.
    assert_eq!(
        Features::from(&parse(SMALL).unwrap().features),
        Features::all()
    );

    let bad = |from: &str, to: &str| -> WorldError {
        assert!(text.contains(from), "{from}");
        let err = parse(&text.replacen(from, to, 1)).expect_err(to);
        assert!(
            err.to_string().starts_with("worlds/test/world.toml: "),
            "message does not name the file: {err}"
        );
        eprintln!("{err}");
        err
    };
    let err = bad("scene = \"gusty\"", "scene = \"hurricane\"");
    assert!(
        matches!(err, WorldError::UnknownWindSceneRef { ref field, ref name, ref available, .. }
            if field == "paths[0].wind[1].scene" && name == "hurricane" && available.contains("still")),
        "{err}"
    );
    // A change may not start before the previous one has blended in (the first blends over 3 s).
    let err = bad("t_s = 4.0, scene", "t_s = 2.0, scene");
    assert!(
        matches!(err, WorldError::OutOfRange { ref field, .. } if field == "paths[0].wind[1].t_s"),
        "{err}"
    );
    let err = bad("blend_s = 2.0", "blend_s = -1.0");
    assert!(
        matches!(err, WorldError::Negative { ref field, .. } if field == "paths[0].wind[1].blend_s"),
        "{err}"
    );
    let err = bad("t_s = 4.0, scene", "t_s = nan, scene");
    assert!(
        matches!(err, WorldError::NonFinite { ref field, .. } if field == "paths[0].wind[1].t_s"),
        "{err}"
    );
    let err = bad("walker = \"stroll\"", "walker = \"nobody\"");
    assert!(
        matches!(err, WorldError::UnknownPathRef { ref field, ref name, .. }
            if field == "paths[0].walker" && name == "nobody"),
        "{err}"
    );
    let err = bad("specular = false", "sparkles = false");
    assert!(
        matches!(err, WorldError::ManifestSyntax { .. }) && err.to_string().contains("sparkles"),
        "{err}"
    );
    let err = bad("specular = false", "specular = 0");
    assert!(matches!(err, WorldError::ManifestSyntax { .. }), "{err}");
}

#[test]
fn scene_changes_blend_the_ambient_and_the_noise_moves_on_continuously() {
    let m = parse(&with_keys()).unwrap();
    let config = WindConfig::from_keys(&m, &m.path("overview").unwrap().wind).unwrap();
    let still = AmbientWind::from(&m.wind_scene("still").unwrap().ambient);
    let gusty = AmbientWind::from(&m.wind_scene("gusty").unwrap().ambient);
    // The scene in effect and its sources' clock.
    let before = config.scene_at(3.0);
    assert_eq!((before.name, before.sources.len()), ("still", 0));
    assert_eq!(before.ambient, still);
    let after = config.scene_at(9.0);
    assert_eq!((after.name, after.sources.len()), ("gusty", 3));
    assert_eq!(after.ambient, gusty);
    assert!((after.local_s - 5.0).abs() < 1e-12);
    // The directional source ramps up over 2 s from the change, not from time 0.
    let directional = &after.sources[0];
    assert_eq!(directional.strength_at(config.scene_at(5.0).local_s), 0.5);
    // Halfway through the blend: the mean wind vectors' average.
    let mid = config.scene_at(5.0).ambient;
    let want = (still.direction() * still.speed_mps + gusty.direction() * gusty.speed_mps) * 0.5;
    assert!(
        (mid.direction() * mid.speed_mps - want).length() < 1e-9,
        "{mid:?}"
    );
    assert!((mid.gustiness - 0.5 * (still.gustiness + gusty.gustiness)).abs() < 1e-12);

    // The drift is the integral of the mean wind: against a fine trapezoid sum.
    let velocity = |t: f64| {
        let a = config.ambient_at(t);
        a.direction() * a.speed_mps
    };
    for (t0, t1) in [(0.0, 3.0), (2.0, 7.5), (4.5, 5.5), (-3.0, 20.0), (9.0, 1.0)] {
        let n = 20_000;
        let h = (t1 - t0) / f64::from(n);
        let sum: DVec2 = (0..n)
            .map(|i| {
                (velocity(t0 + h * f64::from(i)) + velocity(t0 + h * f64::from(i + 1))) * 0.5 * h
            })
            .sum();
        let got = config.drift_between(t0, t1);
        assert!((got - sum).length() < 1e-6, "{t0}..{t1}: {got} vs {sum}");
    }

    // Through the blend the field changes no faster than the steady wind's gusts plus the ramp
    // of the mean wind (times the largest gust factor, 2) allow, and never jumps: had the
    // pattern scrolled by speed times window age instead of the drift's integral, it would race
    // across the field during the blend.
    let points: Vec<DVec2> = (0..200)
        .map(|k| {
            DVec2::new(300.0, 400.0) + DVec2::from_angle(k as f64 * 2.399) * (k as f64).sqrt() * 6.0
        })
        .collect();
    let dt = FRAME_S;
    let largest_step = |from: f64, to: f64| largest_frame_step(&config, &points, from, to);
    let steady = largest_step(8.0, 12.0);
    let change = largest_step(3.5, 6.5);
    eprintln!(
        "largest frame-to-frame change: steady gusty {steady} m/s, through the change {change} m/s"
    );
    assert!(steady > 0.0);
    let ramp = (gusty.direction() * gusty.speed_mps - still.direction() * still.speed_mps).length()
        * dt
        / 2.0;
    assert!(
        change <= (steady + 2.0 * ramp as f32) * 1.1,
        "the change moves the wind by {change} m/s in a frame (steady {steady}, ramp {ramp})"
    );
    for p in &points {
        let (a, b) = (
            ambient_at(&config, *p, 4.0 - 1e-4),
            ambient_at(&config, *p, 4.0 + 1e-4),
        );
        assert!((a - b).length() < 1e-3, "jump at the change: {a} -> {b}");
    }
}

#[test]
fn the_wind_tour_shows_every_scene_its_walker_and_the_helicopter() {
    use verdant::camera::sample_path;
    let m = world();
    let tour = m.path("wind-tour").expect("the wind tour");
    let scenes: Vec<&str> = tour.wind.iter().map(|k| k.scene.as_str()).collect();
    assert_eq!(scenes, ["calm", "breeze", "storm", "helicopter"]);
    let walker = m.path(tour.walker.as_deref().expect("a walker")).unwrap();
    let heli = m.path("helicopter").unwrap();
    let config = WindConfig::from_keys(&m, &tour.wind).unwrap();
    let aspect = 16.0 / 9.0;
    // Whether a world point is inside the camera's view (with a small margin).
    let in_view = |t: f64, p: DVec3| -> bool {
        let cam = sample_path(tour, t);
        let clip = cam.view_proj_relative(aspect) * (p - cam.position).as_vec3().extend(1.0);
        clip.w > 0.0 && clip.x.abs() < 0.9 * clip.w && clip.y.abs() < 0.9 * clip.w
    };
    let (mut heli_seen, mut steps) = (0, 0);
    let mut t = tour.keys[0].t_s;
    while t <= tour.duration_s {
        // The walker's feet are in view all the way round.
        let w = sample_path(walker, t).position;
        assert!(
            in_view(t, DVec3::new(w.x, w.y, w.z - 1.7)),
            "walker out of view at {t} s"
        );
        let now = config.scene_at(t);
        if now.name == "helicopter" {
            // The downwash's centre on the ground under the helicopter.
            let centre = now.sources[0].position_at(now.local_s).unwrap();
            let h = sample_path(heli, now.local_s).position;
            assert!(centre.distance(h.truncate()) < 1e-6);
            steps += 1;
            if in_view(t, DVec3::new(centre.x, centre.y, h.z - 16.0)) {
                heli_seen += 1;
            }
        }
        t += 0.5;
    }
    assert!(steps > 20);
    assert!(
        heli_seen * 2 >= steps,
        "the downwash's centre is in view for only {heli_seen} of {steps} half-seconds"
    );
}

#[test]
fn the_helicopter_flattens_the_tall_grass_under_it_and_the_grass_recovers() {
    use verdant::wind::{SWAY_TYPES, SwayConfig, update_sway};
    // The wind tour's helicopter scene through the mirrors of the wind field and the sway
    // springs (each checked against its GPU stage by the tests above and in sway_field.rs), at
    // 30 frames a second, the camera where the tour's is.
    let m = world();
    let tour = m.path("wind-tour").unwrap();
    let config = WindConfig::from_keys(&m, &tour.wind).unwrap();
    let heli_at = tour
        .wind
        .iter()
        .find(|k| k.scene == "helicopter")
        .unwrap()
        .t_s;
    let sway_config = SwayConfig::from_manifest(&m);
    let tall = m
        .grass_types
        .iter()
        .position(|g| g.name == "tall grass")
        .unwrap();
    let mut field = WindFieldCpu::new(&config);
    let count = config.cell_count();
    let mut sway = vec![[0.0f32; 4]; count * SWAY_TYPES];
    let mut owners = vec![[i32::MIN; 2]; count];
    let dt = 1.0f32 / 30.0;
    // The bend of tall grass at a world point, and the downwash's centre, at scene time t.
    let mut run_until = |t_end: f64, t: &mut f64| {
        while *t < t_end {
            *t += f64::from(dt);
            let cam = verdant::camera::sample_path(tour, *t).position;
            field.update(cam, *t, dt, None);
            let p = sway_config.params(field.lookup(), dt);
            update_sway(&p, field.cells(), &mut sway, &mut owners);
        }
    };
    let bend_at = |sway: &[[f32; 4]], p: DVec2| -> Vec2 {
        let s = sway[config.storage_index(config.world_cell(p)) * SWAY_TYPES + tall];
        Vec2::new(s[0], s[1])
    };
    let mut t = heli_at - 5.0;
    run_until(heli_at + 8.0, &mut t);
    let now = config.scene_at(t);
    assert_eq!(now.name, "helicopter");
    let centre = now.sources[0].position_at(now.local_s).unwrap();
    // Around the rotor, 3 to 10 m out: bent well over, away from the centre.
    let max_bend = 1.1 - 0.5 * m.grass_types[tall].stiffness;
    let mut outward = Vec::new();
    for k in 0..24 {
        let dir = DVec2::from_angle(k as f64 * std::f64::consts::TAU / 24.0);
        for r in [3.0, 6.0, 10.0] {
            let b = bend_at(&sway, centre + dir * r);
            assert!(
                b.length() > 0.5 * max_bend,
                "{r} m out at {k}: bend {b} (max {max_bend})"
            );
            outward.push(f64::from(b.normalize().dot(dir.as_vec2())));
        }
    }
    let mean_outward = outward.iter().sum::<f64>() / outward.len() as f64;
    assert!(
        mean_outward > 0.8,
        "the grass leans outward: {mean_outward}"
    );
    // 60 m away, the light air alone bends it far less.
    let far: f32 = (0..24)
        .map(|k| {
            let dir = DVec2::from_angle(k as f64 * std::f64::consts::TAU / 24.0);
            bend_at(&sway, centre + dir * 60.0).length()
        })
        .sum::<f32>()
        / 24.0;
    let near = bend_at(&sway, centre + DVec2::X * 6.0).length();
    eprintln!("bend of tall grass 6 m from the rotor {near}, 60 m away {far} (max {max_bend})");
    assert!(far < 0.4 * near, "far {far}, near {near}");
    // Where the helicopter was 5 s earlier (at full strength), the grass has recovered.
    assert!(now.sources[0].strength_at(now.local_s - 5.0) == 1.0);
    let earlier = now.sources[0].position_at(now.local_s - 5.0).unwrap();
    assert!(earlier.distance(centre) > 20.0);
    let behind = bend_at(&sway, earlier).length();
    assert!(
        behind < 0.4 * near,
        "behind the helicopter {behind}, under it {near}"
    );
}
