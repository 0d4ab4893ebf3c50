//! Terrain shadows against geometry: a wall of known height in a flat field, lit by the
//! manifest's sun, casts its shadow where a ray toward the sun says it falls (worked out on the
//! CPU for each pixel), and nowhere else.

mod common;

use std::sync::Arc;

use glam::{DVec2, DVec3, Vec4};
use verdant::RendererConfig;
use verdant::camera::Camera;
use verdant::terrain::sun_direction;
use verdant::tools::bench_blades::field_with_heights;
use verdant::tools::scene::Scene;

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
    let mut config = RendererConfig::for_world(&world);
    config.grass_rings = None;
    let (w, h) = (256u32, 144u32);
    let mut scene = Scene::with_source(&ctx, world.clone(), source, w, h, config).unwrap();
    // Looking straight down from 200 m over the wall's east side.
    let mut camera = Camera::new(DVec3::new(330.0, 300.0, 200.0), 0.0, -89.0);
    camera.fov_y_deg = 40.0;
    assert!(
        scene
            .warm_up(&ctx, &camera, std::time::Duration::from_secs(60))
            .unwrap()
    );
    scene.render(&ctx, &camera).unwrap();
    let image = scene.read_image(&ctx).unwrap();

    // The CPU's ray test: from a ground point east of the wall, the ray toward the sun meets
    // the wall's east face after (x - 310) / |sun.xy.x| metres of ground, at a height of that
    // times the sun's rise; in shadow when that is below the wall's top.
    let sun = sun_direction(&world.manifest.sky).as_dvec3();
    assert!(
        sun.x < 0.0,
        "the sun must stand to the west of the wall for this test"
    );
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
    assert!(
        shadowed_dark > 0.98,
        "only {shadowed_dark:.3} of the shadow is dark"
    );
    assert!(
        lit_dark < 0.03,
        "{lit_dark:.3} of the sunlit ground is dark"
    );
}

fn srgb_to_linear(c: u8) -> f32 {
    let c = f32::from(c) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// The contact shadows' pass (`shaders/terrain_contact_shadow.wgsl`) against its CPU mirror
/// (`src/terrain/contact_shadow.rs`): the same frame of a meadow drawn with and without
/// shadows, whose ratio is the pass's factor, against the factors the mirror finds in the
/// frame's depth.
#[test]
fn contact_shadows_match_their_cpu_mirror() {
    use verdant::features::Feature;
    use verdant::terrain::contact_shadow::ContactShadows;
    use verdant::tools::bench_blades::flat_field;

    let ctx = common::gpu();
    let (world, source) = flat_field(400.0).unwrap();
    let (w, h) = (192u32, 108u32);
    // Standing in the meadow, looking across the sun's direction so that the blades' shadows
    // fall beside them, in view.
    let camera = Camera::new(DVec3::new(200.0, 200.0, 1.7), 120.0, -25.0);
    let render = |features| {
        let mut config = RendererConfig::for_world(&world);
        config.features = features;
        // Each pixel against the mirror's shadow at its centre: one sample there.
        config.aa = verdant::aa::AntiAliasing::Off;
        let settings = config.grass_settings(&world).unwrap();
        config.grass.capacity = Some(settings.grid() * settings.grid());
        let mut scene =
            Scene::with_source(&ctx, world.clone(), source.clone(), w, h, config).unwrap();
        assert!(
            scene
                .warm_up(&ctx, &camera, std::time::Duration::from_secs(60))
                .unwrap()
        );
        scene.render_at(&ctx, &camera, 1.0).unwrap();
        (
            scene.read_image(&ctx).unwrap(),
            scene.read_depth(&ctx).unwrap(),
        )
    };
    let all = RendererConfig::for_world(&world).features;
    let (lit, depth) = render(all.without(Feature::Shadows));
    let (shaded, depth_shaded) = render(all);
    assert_eq!(depth, depth_shaded, "the two frames must be the same scene");

    let s = ContactShadows::default();
    let sun = sun_direction(&world.manifest.sky);
    let vp = camera.view_proj_relative(w as f32 / h as f32);
    let cpu = s.factors(&depth, w, h, vp, sun);
    let (mut agree, mut counted, mut shadowed) = (0usize, 0usize, 0usize);
    for (i, &f) in cpu.iter().enumerate() {
        let (a, b) = (
            &lit.as_raw()[i * 4..i * 4 + 3],
            &shaded.as_raw()[i * 4..i * 4 + 3],
        );
        let (la, lb) = (srgb_to_linear(a[1]), srgb_to_linear(b[1]));
        // Too dark to read a ratio from 8 bits.
        if la < 0.02 {
            continue;
        }
        counted += 1;
        let gpu = lb / la;
        if f < 0.999 {
            shadowed += 1;
        }
        if (gpu - f).abs() < 0.08 {
            agree += 1;
        }
    }
    let fraction = agree as f64 / counted.max(1) as f64;
    eprintln!(
        "{shadowed} of {counted} pixels in contact shadow; GPU and CPU agree on {fraction:.4}"
    );
    assert!(
        shadowed > counted / 50,
        "too few shadowed pixels to test: {shadowed}"
    );
    // Pixels where a step lands right at a depth edge can differ by the last bit of a depth.
    assert!(
        fraction > 0.98,
        "GPU and CPU agree on only {fraction:.4} of the pixels"
    );
}

/// The trees' shadow map (`src/plants/shadow.rs`, drawn by the trees' shadow casters, looked
/// up in `shaders/terrain_contact_shadow.wgsl`) against its CPU mirror
/// (`ShadowUniform::sun_seen`): a frame among trees drawn with and without tree shadows (the
/// contact shadows off in both), whose ratio is the lookup's factor, against the factors the
/// mirror finds in the frame's depth and the map read back. And against geometry: every
/// ground or leaf point the map shades has a caster toward the sun, within a tree's height of
/// it and a crown's reach of the tree's axis.
#[test]
fn tree_shadows_match_their_cpu_mirror_and_fall_from_the_trees() {
    use verdant::World;
    use verdant::features::Feature;
    use verdant::terrain::contact_shadow::ContactShadows;

    let ctx = common::gpu();
    let tmp = tempfile::tempdir().unwrap();
    let dir = common::world_with_trees(tmp.path(), "broadleaf", 0.003);
    let world = World::open(&dir).unwrap();
    let (w, h) = (192u32, 108u32);
    // Over the meadow at 25 m, looking down across the sun's direction at the trees.
    let path = world
        .manifest
        .paths
        .iter()
        .find(|p| p.name == "meadow")
        .unwrap();
    let mut camera = verdant::camera::sample_path(path, path.keys[0].t_s);
    camera.position.z += 25.0;
    camera.pitch_deg = -35.0;
    let render = |features: verdant::features::Features| {
        let mut config = RendererConfig::for_world(&world);
        config.features = features;
        // Each pixel against the mirror's shadow at its centre: one sample there.
        config.aa = verdant::aa::AntiAliasing::Off;
        let mut scene = Scene::new(&ctx, world.clone(), w, h, config).unwrap();
        assert!(
            scene
                .warm_up(&ctx, &camera, std::time::Duration::from_secs(60))
                .unwrap()
        );
        scene.render_at(&ctx, &camera, 1.0).unwrap();
        let image = scene.read_image(&ctx).unwrap();
        let depth = scene.read_depth(&ctx).unwrap();
        let r = scene.renderer();
        let maps = r
            .tree_shadow_map()
            .read_layers(&ctx.device, &ctx.queue)
            .unwrap();
        let uniform = *r.tree_shadow_map().uniform();
        let casters = r.read_shadow_casters();
        (image, depth, maps, uniform, casters)
    };
    // The wind-carried leaves included: each is shed from a tree picked whatever the order of
    // the frame's pool (the placement's atomic appends), so they fall alike in both frames.
    let all = RendererConfig::for_world(&world)
        .features
        .without(Feature::Shadows);
    let (lit, depth, _, off, _) = render(all.without(Feature::TreeShadows));
    assert_eq!(off.info[0], 0, "no cascades with tree shadows off");
    let (shaded, depth_shaded, maps, uniform, casters) = render(all);
    assert_eq!(depth, depth_shaded, "the two frames must be the same scene");
    assert_eq!(uniform.info[0], 2, "two cascades");
    assert!(casters.len() > 20, "{} casters", casters.len());

    let shade = ContactShadows::default().shade;
    let sun = sun_direction(&world.manifest.sky);
    let vp = camera.view_proj_relative(w as f32 / h as f32);
    let inv = vp.inverse();
    // A caster toward the sun from p: the ray within 1.5 heights meets the tree's crown
    // cylinder (0.7 of its height about its axis, root to top).
    let cast_on = |p: glam::Vec3| {
        casters.iter().any(|t| {
            let root = glam::Vec3::from(t.pos);
            (0..=60).any(|i| {
                let q = p + sun * (i as f32 / 40.0 * t.scale / sun.z.max(0.2));
                (q.truncate() - root.truncate()).length() < 0.7 * t.scale
                    && q.z >= root.z - 0.5
                    && q.z <= root.z + 1.05 * t.scale
            })
        })
    };
    let (mut agree, mut counted, mut shadowed, mut explained) = (0usize, 0usize, 0usize, 0usize);
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let d = depth[i];
            if d <= 0.0 {
                continue;
            }
            let ndc = glam::Vec2::new(
                (x as f32 + 0.5) / w as f32 * 2.0 - 1.0,
                1.0 - (y as f32 + 0.5) / h as f32 * 2.0,
            );
            let p = inv.project_point3(glam::Vec3::new(ndc.x, ndc.y, d));
            // Beyond the map's fade-out the terrain takes the canopy's shade instead (its own
            // test is in tests/far_field.rs).
            if p.length() >= uniform.fade[0] {
                continue;
            }
            let f = 1.0 + (shade - 1.0) * (1.0 - uniform.sun_seen(&maps, p));
            let (a, b) = (
                &lit.as_raw()[i * 4..i * 4 + 3],
                &shaded.as_raw()[i * 4..i * 4 + 3],
            );
            let (la, lb) = (srgb_to_linear(a[1]), srgb_to_linear(b[1]));
            if la < 0.02 {
                continue;
            }
            counted += 1;
            if (lb / la - f).abs() < 0.08 {
                agree += 1;
            }
            if f < 0.5 * (1.0 + shade) {
                shadowed += 1;
                if cast_on(p) {
                    explained += 1;
                }
            }
        }
    }
    let fraction = agree as f64 / counted.max(1) as f64;
    let cast = explained as f64 / shadowed.max(1) as f64;
    eprintln!(
        "{shadowed} of {counted} pixels in tree shadow, {cast:.4} of them under a caster; \
         GPU and CPU agree on {fraction:.4}"
    );
    assert!(
        shadowed > counted / 50,
        "too few shadowed pixels to test: {shadowed} of {counted}"
    );
    assert!(fraction > 0.98, "GPU and CPU agree on only {fraction:.4}");
    assert!(
        cast > 0.97,
        "only {cast:.4} of the shadow lies under a tree"
    );
}
