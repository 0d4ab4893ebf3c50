//! What the far field should show, measured against the truth: the data its per-type fit
//! (`src/terrain/far_field.rs`, `visible_t` and `cover`) was made from.
//!
//! `cargo run --release --example far_field_fit -- [OUT.csv [WIDTH HEIGHT [TYPE]]]` (defaults
//! out/far_field_fit.csv 320 180, every grass type): for each grass type of the default world, on a flat field of
//! that type at full density lit by the world's sky and moved by its wind (no fog), from
//! cameras 1.7 to 80 m up looking over the ground 1.8 view distances away, renders the 4x4
//! truth (blades out to nine view distances, 600 m), the default frame supersampled 4x4 and the
//! same without the far field (the bare ground it covers). Each row is one band of distance
//! beyond the view distance (where the default shows the far field only): the pixels' count,
//! mean distance and sine of the view's elevation, the three renders' mean linear colours, and
//! the far field's CPU mirror of the grass alone (`light_far_grass`, the blades' colour at t
//! with the pixels' clump tint and colour variation, sun fully seen) for t = 0, 0.1 .. 1.
use anyhow::Result;
use glam::{DVec2, DVec3, Vec3, Vec4};
use std::fmt::Write as _;
use verdant::RendererConfig;
use verdant::aa::AntiAliasing;
use verdant::camera::Camera;
use verdant::features::Feature;
use verdant::gpu::GpuContext;
use verdant::terrain::far_field::{self, Light};
use verdant::tools::bench_blades::flat_field;
use verdant::tools::metrics::decode_srgb8;
use verdant::tools::truth::{Truth, atlas_slots, truth_config};
use verdant::world::World;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let out = std::path::PathBuf::from(
        args.get(1)
            .cloned()
            .unwrap_or("out/far_field_fit.csv".into()),
    );
    let size = |i: usize, d: u32| -> Result<u32> {
        args.get(i).map_or(Ok(d), |s| {
            s.parse()
                .map_err(|e| anyhow::anyhow!("argument {i} ({s:?}) is not a size: {e}"))
        })
    };
    let (w, h) = (size(2, 320)?, size(3, 180)?);
    let only = args.get(4).cloned();
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let home = World::open(std::path::Path::new("worlds/santa-cruz"))?;
    let ctx = GpuContext::new()?;
    let mut csv = String::from("type,height_m,band,pixels,dist_m,sin_e");
    for who in ["truth", "default", "bare"] {
        for c in ["r", "g", "b"] {
            write!(csv, ",{who}_{c}")?;
        }
    }
    let ts: Vec<f32> = (0..=10).map(|i| i as f32 / 10.0).collect();
    for t in &ts {
        for c in ["r", "g", "b"] {
            write!(csv, ",grass{t:.1}_{c}")?;
        }
    }
    csv.push('\n');

    for kind in 1..home.manifest.grass_types.len() {
        let (mut world, source) = flat_field(4000.0)?;
        world.manifest.grass_types[1] = home.manifest.grass_types[kind].clone();
        world.manifest.sky = home.manifest.sky.clone();
        world.manifest.sky.fog_distance_m = 100_000.0;
        world.manifest.wind = home.manifest.wind.clone();
        let name = world.manifest.grass_types[1].name.clone();
        if only.as_ref().is_some_and(|o| *o != name) {
            continue;
        }
        let mut base = RendererConfig::for_world(&world);
        base.aa = AntiAliasing::Off;
        let settings = base.grass_settings(&world).expect("grass");
        // Room in each pool slot for a whole tile of blades at full density.
        base.grass.capacity = Some(settings.grid() * settings.grid());
        let view = f64::from(settings.view_distance_m);
        let slots = atlas_slots(&world, &ctx.device);
        base.service.atlas_slots = base.service.atlas_slots.max(slots);
        let mut bare = base.clone();
        bare.features = base.features.without(Feature::FarField);
        let configs = [
            ("truth", truth_config(&world, &base, slots)),
            ("default", base.clone()),
            ("bare", bare),
        ];
        let sky = &world.manifest.sky;
        let light = Light::of_sky(sky);
        let gt = &world.manifest.grass_types[1];
        for z in [1.7f64, 3.0, 6.0, 10.0, 20.0, 40.0, 80.0] {
            let aim = 1.8 * view;
            let mut camera = Camera::new(
                DVec3::new(500.0, 500.0, z),
                45.0,
                -(z / aim).atan().to_degrees(),
            );
            camera.fov_y_deg = 10.0;
            let mut images = Vec::new();
            for (label, cfg) in &configs {
                let mut truth = Truth::with_config(
                    &ctx,
                    world.clone(),
                    source.clone(),
                    (w, h),
                    4,
                    cfg.clone(),
                )?;
                truth
                    .scene()
                    .warm_up_report(&camera, std::time::Duration::from_secs(120))?;
                let dt = 1.0 / 60.0;
                for i in 0..6 {
                    truth.advance(&ctx, &camera, f64::from(i) * dt, None)?;
                }
                let img = truth.render(&ctx, &camera, 6.0 * dt, None)?;
                img.save(out.with_file_name(format!(
                    "far_fit_{}_{z}_{label}.png",
                    name.replace(' ', "_")
                )))?;
                images.push(img);
            }
            // Bands of the grass's fade distance beyond the view distance (the default's far
            // field alone) and short of the truth's own fade.
            let bands = [
                (view + 25.0, 1.6 * view),
                (1.6 * view, 2.3 * view),
                (2.3 * view, 3.1 * view),
            ];
            let inv = camera.view_proj_relative(w as f32 / h as f32).inverse();
            for (bi, &(lo, hi)) in bands.iter().enumerate() {
                let mut n = 0usize;
                let (mut dist_sum, mut sin_sum) = (0.0f64, 0.0f64);
                let mut sums = [Vec3::ZERO; 3];
                let mut grass = vec![Vec3::ZERO; ts.len()];
                for y in 0..h {
                    for x in 0..w {
                        let ndc = glam::Vec2::new(
                            (x as f32 + 0.5) / w as f32 * 2.0 - 1.0,
                            1.0 - (y as f32 + 0.5) / h as f32 * 2.0,
                        );
                        let p = inv * Vec4::new(ndc.x, ndc.y, 0.5, 1.0);
                        let d = (p.truncate() / p.w).as_dvec3().normalize();
                        if d.z > -1e-6 {
                            continue;
                        }
                        let ground = camera.position + d * (-camera.position.z / d.z);
                        let dist = (ground - camera.position).length();
                        let faded_at = f64::from(far_field::far_distance(
                            dist as f32,
                            z as f32,
                            far_field::ELEVATION_DISTANCE,
                        ));
                        if !(lo..hi).contains(&faded_at) {
                            continue;
                        }
                        n += 1;
                        dist_sum += dist;
                        sin_sum += -d.z;
                        let i = (y * w + x) as usize;
                        for (s, img) in sums.iter_mut().zip(&images) {
                            let px = &img.as_raw()[i * 4..i * 4 + 3];
                            *s += Vec3::new(
                                decode_srgb8(px[0]),
                                decode_srgb8(px[1]),
                                decode_srgb8(px[2]),
                            );
                        }
                        let xy = DVec2::new(ground.x, ground.y);
                        let world_mod =
                            DVec2::new(xy.x.rem_euclid(4096.0), xy.y.rem_euclid(4096.0));
                        let tint = Vec3::ONE.lerp(
                            far_field::clump_tint(xy, settings.clump_m, settings.seed),
                            far_field::clump_visibility(dist as f32, settings.clump_m),
                        ) * far_field::color_variation(world_mod.as_vec2());
                        for (g, &t) in grass.iter_mut().zip(&ts) {
                            // The blades' colour and light at t alone: albedo moments t and t^2.
                            let albedo = Vec3::from_array(gt.base_color)
                                .lerp(Vec3::from_array(gt.tip_color), t)
                                * tint;
                            *g += far_field::light_far_grass(
                                [albedo, albedo * t],
                                Vec3::Z,
                                1.0,
                                &light,
                            );
                        }
                    }
                }
                if n == 0 {
                    continue;
                }
                let nf = n as f32;
                write!(
                    csv,
                    "{name},{z},{bi},{n},{:.1},{:.5}",
                    dist_sum / n as f64,
                    sin_sum / n as f64
                )?;
                for s in sums.iter().chain(grass.iter()) {
                    let m = *s / nf;
                    write!(csv, ",{:.6},{:.6},{:.6}", m.x, m.y, m.z)?;
                }
                csv.push('\n');
            }
            eprintln!("{name} from {z} m: done");
        }
    }
    std::fs::write(&out, &csv)?;
    print!("{csv}");
    Ok(())
}
