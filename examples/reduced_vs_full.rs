//! How far the plants' and trees' reduced levels of detail stand from their full meshes in the
//! default frame, by distance from the camera.
//!
//! `cargo run --release --example reduced_vs_full -- [WIDTH HEIGHT [PATH]]` (defaults 240 135
//! meadow): one view of the default world's path (the meadow's first; 30% along any other),
//! after six frames of the same wind, drawn twice with the default settings at 3x3 sub-samples a
//! pixel (so that aliasing does not hide the difference): with every plant's full mesh to 150 m
//! and every tree's to 300 m, and as the default draws them (the reduced meshes, and the cards
//! beyond). Prints the mean FLIP between the two over the frame and over bands of distance (from
//! the full-mesh render's depth), and in each band the default's mean luminance over the
//! full meshes'.
use anyhow::{Context, Result};
use std::sync::Arc;
use verdant::RendererConfig;
use verdant::aa::AntiAliasing;
use verdant::camera::sample_path;
use verdant::gpu::GpuContext;
use verdant::tools::metrics::{
    band_mask, flip_error_map, masked_luminance, masked_mean, ray_distances, rgb,
};
use verdant::tools::truth::{Truth, atlas_slots};
use verdant::world::World;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let number = |i: usize, default: u32| -> Result<u32> {
        args.get(i).map_or(Ok(default), |s| {
            s.parse()
                .with_context(|| format!("argument {i} ({s:?}) is not a size"))
        })
    };
    let (w, h) = (number(1, 240)?, number(2, 135)?);
    let pathname = args.get(3).cloned().unwrap_or("meadow".into());
    let wdir = std::path::PathBuf::from("worlds/santa-cruz");
    let world = World::open(&wdir)?;
    let path = verdant::tools::camera_path(&world, &wdir, Some(&pathname))?;
    let along = if pathname == "meadow" { 0.0 } else { 0.3 };
    let t0 = path.keys[0].t_s + along * (path.keys[path.keys.len() - 1].t_s - path.keys[0].t_s);
    let cam = sample_path(&path, t0);
    let ctx = GpuContext::new()?;
    let slots = atlas_slots(&world, &ctx.device);
    let base = RendererConfig::for_world(&world);
    let mut default = base.clone();
    default.aa = AntiAliasing::Off;
    default.service.atlas_slots = default.service.atlas_slots.max(slots);
    let mut full = default.clone();
    full.plants.lod_m = [150.0, 150.0];
    full.trees = base
        .tree_settings(&world)
        .map(|t| verdant::plants::PlantSettings {
            lod_m: [300.0, 300.0],
            ..t
        });
    let walker = Some(cam.position.truncate());
    let mut images = Vec::new();
    let mut depth = Vec::new();
    for (i, config) in [full, default].into_iter().enumerate() {
        let mut render = Truth::with_config(
            &ctx,
            world.clone(),
            Arc::new(world.clone()),
            (w, h),
            3,
            config,
        )?;
        for k in -6i64..=0 {
            let t = t0 + k as f64 / 60.0;
            render
                .scene()
                .warm_up_report(&cam, std::time::Duration::from_secs(120))?;
            if k < 0 {
                render.advance(&ctx, &cam, t, walker)?;
            } else {
                images.push(render.render(&ctx, &cam, t, walker)?);
                if i == 0 {
                    depth = render.read_depth(&ctx)?;
                }
            }
        }
    }
    let inv = cam.view_proj_relative(w as f32 / h as f32).inverse();
    let dist = ray_distances(&depth, w, h, inv);
    let e = flip_error_map(&rgb(&images[0]), &rgb(&images[1]))?;
    let mean = e.iter().map(|&v| f64::from(v)).sum::<f64>() / e.len() as f64;
    println!("{pathname} {w}x{h}: FLIP of the reduced levels against the full meshes {mean:.4}");
    for (a, b) in [
        (0.0, 25.0),
        (25.0, 60.0),
        (60.0, 150.0),
        (150.0, 300.0),
        (300.0, 1e9),
    ] {
        let mask = band_mask(&dist, a, b);
        let share = mask.iter().filter(|&&m| m).count() as f64 / mask.len() as f64;
        let flip = masked_mean(&e, &mask).map_or("-".into(), |v| format!("{v:.4}"));
        let lum = match (
            masked_luminance(&images[1], &mask),
            masked_luminance(&images[0], &mask),
        ) {
            (Some(r), Some(f)) if f > 0.0 => format!("{:.3}", r / f),
            _ => "-".into(),
        };
        println!(
            "  {a}-{b} m: share {share:.3}, FLIP {flip}, luminance over the full meshes' {lum}"
        );
    }
    Ok(())
}
