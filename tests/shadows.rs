//! Terrain shadows against geometry: a wall of known height in a flat field, lit by the
//! manifest's sun, casts its shadow where a ray toward the sun says it falls (worked out on the
//! CPU for each pixel), and nowhere else.

mod common;

use std::sync::Arc;

use glam::{DVec2, DVec3, Vec4};
use verdant::camera::Camera;
use verdant::terrain::sun_direction;
use verdant::tools::bench_blades::field_with_heights;
use verdant::tools::scene::{Scene, SceneConfig};

const WALL: (f64, f64) = (300.0, 310.0);
const WALL_M: f32 = 40.0;

fn luminance(px: &[u8]) -> f32 {
    0.2126 * f32::from(px[0]) + 0.7152 * f32::from(px[1]) + 0.0722 * f32::from(px[2])
}

#[test]
fn a_wall_casts_its_shadow_where_the_sun_ray_says() {
    let ctx = common::gpu();
    let height = Arc::new(|p: DVec2| {
        if (WALL.0..=WALL.1).contains(&p.x) {
            WALL_M
        } else {
            0.0
        }
    });
    let (world, source) = field_with_heights(800.0, Some(height), WALL_M).unwrap();
    let mut config = SceneConfig::for_world(&world);
    config.grass = None;
    let (w, h) = (256u32, 144u32);
    let mut scene = Scene::with_source(&ctx, world.clone(), source, w, h, config).unwrap();
    // Looking straight down from 200 m over the wall's east side.
    let mut camera = Camera::new(DVec3::new(330.0, 300.0, 200.0), 0.0, -89.0);
    camera.fov_y_deg = 40.0;
    assert!(scene
        .warm_up(&ctx, &camera, std::time::Duration::from_secs(60))
        .unwrap());
    scene.render(&ctx, &camera).unwrap();
    let image = scene.read_image(&ctx).unwrap();

    // The CPU's ray test: from a ground point east of the wall, the ray toward the sun meets
    // the wall's east face after (x - 310) / |sun.xy.x| metres of ground, at a height of that
    // times the sun's rise; in shadow when that is below the wall's top.
    let sun = sun_direction(&world.manifest.sky).as_dvec3();
    assert!(sun.x < 0.0, "the sun must stand to the west of the wall for this test");
    let rise = sun.z / sun.truncate().length();
    let in_shadow = |x: f64| {
        x > WALL.1 && (x - WALL.1) / (-sun.x / sun.truncate().length()) * rise < f64::from(WALL_M)
    };
    let edge = WALL.1 + f64::from(WALL_M) / rise * (-sun.x / sun.truncate().length());

    let inv = camera.view_proj_relative(w as f32 / h as f32).inverse();
    let (mut shadowed, mut lit) = (Vec::new(), Vec::new());
    for y in 0..h {
        for x in 0..w {
            let ndc = glam::Vec2::new(
                (x as f32 + 0.5) / w as f32 * 2.0 - 1.0,
                1.0 - (y as f32 + 0.5) / h as f32 * 2.0,
            );
            let p = inv * Vec4::new(ndc.x, ndc.y, 0.5, 1.0);
            let d = (p.truncate() / p.w).as_dvec3().normalize();
            let g = camera.position + d * (-camera.position.z / d.z);
            // Clear of the wall and of the shadow's edge (the heights' texels blur both).
            if (g.x - WALL.0).abs() < 4.0 || (g.x - WALL.1).abs() < 4.0 || (g.x - edge).abs() < 4.0
            {
                continue;
            }
            if (WALL.0..=WALL.1).contains(&g.x) {
                continue;
            }
            let i = ((y * w + x) * 4) as usize;
            let l = luminance(&image.as_raw()[i..i + 3]);
            if in_shadow(g.x) {
                shadowed.push(l);
            } else {
                lit.push(l);
            }
        }
    }
    assert!(
        shadowed.len() > 1000 && lit.len() > 1000,
        "{} shadowed and {} lit pixels in view",
        shadowed.len(),
        lit.len()
    );
    let mut sorted = lit.clone();
    sorted.sort_by(f32::total_cmp);
    let lit_median = sorted[sorted.len() / 2];
    let dark = |v: &[f32]| v.iter().filter(|&&l| l < 0.75 * lit_median).count() as f64;
    let shadowed_dark = dark(&shadowed) / shadowed.len() as f64;
    let lit_dark = dark(&lit) / lit.len() as f64;
    eprintln!(
        "shadow edge at x = {edge:.1} m; {:.3} of shadowed and {:.3} of lit pixels dark",
        shadowed_dark, lit_dark
    );
    // 0.993 seen on software Vulkan.
    assert!(shadowed_dark > 0.98, "only {shadowed_dark:.3} of the shadow is dark");
    assert!(lit_dark < 0.03, "{lit_dark:.3} of the sunlit ground is dark");
}
