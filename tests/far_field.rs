//! The far field (terrain beyond the grass shaded with what the blades would show): its colour
//! where the blades end against the blades' own, and the GPU's against its CPU mirror
//! (`src/terrain/far_field.rs`), on a flat field generated in memory.

mod common;

use glam::{DVec2, DVec3, Vec3, Vec4};
use verdant::RendererConfig;
use verdant::camera::Camera;
use verdant::terrain::far_field::{self, Light};
use verdant::terrain::sun_direction;
use verdant::tools::bench_blades::flat_field;
use verdant::tools::scene::Scene;

fn srgb_to_linear(c: u8) -> f32 {
    let c = f32::from(c) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Where each pixel's ray meets the flat ground (z = 0), or None above the horizon.
fn ground_points(camera: &Camera, w: u32, h: u32) -> Vec<Option<DVec3>> {
    let inv = camera.view_proj_relative(w as f32 / h as f32).inverse();
    let mut out = Vec::with_capacity((w * h) as usize);
    for y in 0..h {
        for x in 0..w {
            let ndc = glam::Vec2::new(
                (x as f32 + 0.5) / w as f32 * 2.0 - 1.0,
                1.0 - (y as f32 + 0.5) / h as f32 * 2.0,
            );
            let p = inv * Vec4::new(ndc.x, ndc.y, 0.5, 1.0);
            let d = (p.truncate() / p.w).as_dvec3().normalize();
            out.push((d.z < -1e-6).then(|| camera.position + d * (-camera.position.z / d.z)));
        }
    }
    out
}

/// CIELAB (D65) of a linear sRGB colour.
fn lab(c: Vec3) -> Vec3 {
    let x = 0.4124 * c.x + 0.3576 * c.y + 0.1805 * c.z;
    let y = 0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z;
    let z = 0.0193 * c.x + 0.1192 * c.y + 0.9505 * c.z;
    let f = |t: f32| {
        if t > 0.008856 {
            t.cbrt()
        } else {
            7.787 * t + 16.0 / 116.0
        }
    };
    let (fx, fy, fz) = (f(x / 0.9505), f(y), f(z / 1.089));
    Vec3::new(116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz))
}

fn mean(v: &[Vec3]) -> Vec3 {
    v.iter().copied().sum::<Vec3>() / v.len().max(1) as f32
}

#[test]
fn the_far_field_continues_the_blades_at_the_ring_and_matches_its_cpu_mirror() {
    let ctx = common::gpu();
    let (world, source) = flat_field(800.0).unwrap();
    let mut config = RendererConfig::for_world(&world);
    let settings = config.grass_settings(&world).unwrap();
    let (fade_start, view) = (
        f64::from(settings.view_distance_m - settings.far_fade_m),
        f64::from(settings.view_distance_m),
    );
    // Room in each pool slot for a whole tile of blades at full density.
    config.grass.capacity = Some(settings.grid() * settings.grid());
    let (w, h) = (320u32, 180u32);
    let mut scene = Scene::with_source(&ctx, world.clone(), source, w, h, config).unwrap();
    // Standing 6 m up in the field, looking over the ring's end through a narrow lens, so that
    // the bands before and after it are many pixels tall.
    let mut camera = Camera::new(DVec3::new(150.0, 150.0, 6.0), 45.0, -2.2);
    camera.fov_y_deg = 8.0;
    assert!(
        scene
            .warm_up(&ctx, &camera, std::time::Duration::from_secs(60))
            .unwrap()
    );
    scene.render(&ctx, &camera).unwrap();
    let image = scene.read_image(&ctx).unwrap();
    let points = ground_points(&camera, w, h);

    let sky = &world.manifest.sky;
    let light = Light {
        sun_dir: sun_direction(sky),
        sun_color: Vec3::from_array(sky.sun_color),
        sky_color: Vec3::from_array(sky.sky_color),
        ambient_occlusion: true,
        translucency: true,
        specular: true,
    };
    let meadow = &world.manifest.grass_types[1];
    let blade = Vec3::from_array(meadow.base_color)
        .lerp(Vec3::from_array(meadow.tip_color), far_field::FAR_T);
    let fog_at = |p: DVec3| {
        let rel = (p - camera.position).as_vec3();
        let dist = rel.length();
        let x = dist / sky.fog_distance_m;
        let fog = 1.0 - (-3.0 * x * x).exp();
        let v = rel / dist;
        let sun_amount = v.dot(light.sun_dir).max(0.0).powf(8.0);
        let fog_color = Vec3::from_array(sky.horizon_color)
            .lerp(Vec3::from_array(sky.sun_color), 0.35 * sun_amount);
        (fog, fog_color, dist)
    };

    let (mut blades, mut far_gpu, mut far_cpu) = (Vec::new(), Vec::new(), Vec::new());
    for (i, p) in points.iter().enumerate() {
        let Some(p) = *p else { continue };
        let px = image.as_raw()[i * 4..i * 4 + 3].to_vec();
        let gpu = Vec3::new(
            srgb_to_linear(px[0]),
            srgb_to_linear(px[1]),
            srgb_to_linear(px[2]),
        );
        let (fog, fog_color, dist) = fog_at(p);
        // The grass's fade goes by the distance plus the height the camera stands above.
        let faded_at = f64::from(far_field::far_distance(
            dist,
            (camera.position.z - p.z) as f32,
        ));
        let dist = f64::from(dist);
        // Blades at full density just before their fade; the far field past its end, where
        // the last blades (0.7 m at most, seen from 6 m) no longer stand in front of it.
        if (fade_start - 25.0..fade_start).contains(&faded_at) {
            blades.push(gpu);
        } else if (view + 25.0..view + 80.0).contains(&faded_at) {
            far_gpu.push(gpu);
            let xy = DVec2::new(p.x, p.y);
            let world_mod = DVec2::new(xy.x.rem_euclid(4096.0), xy.y.rem_euclid(4096.0));
            let clump = Vec3::ONE.lerp(
                far_field::clump_tint(xy, settings.clump_m, settings.seed),
                far_field::clump_visibility(dist as f32, settings.clump_m),
            );
            let albedo = blade * clump * far_field::color_variation(world_mod.as_vec2());
            let lit = far_field::light_far_grass(albedo, Vec3::Z, far_field::FAR_T, 1.0, &light);
            far_cpu.push(lit.lerp(fog_color, fog));
        }
    }
    assert!(
        blades.len() > 500 && far_gpu.len() > 500,
        "bands too thin: {} and {} pixels",
        blades.len(),
        far_gpu.len()
    );
    let (b, fg, fc) = (mean(&blades), mean(&far_gpu), mean(&far_cpu));
    eprintln!("blades {b}, far field {fg} (GPU), {fc} (CPU mirror)");
    // The GPU against its mirror: within 4% per channel (the mirror leaves out the ground's
    // detail noise, whose mean is zero, and the 8-bit target's rounding).
    let rel = ((fg - fc).abs() / fc).max_element();
    assert!(
        rel < 0.04,
        "far field GPU {fg} vs CPU mirror {fc}: {rel:.3}"
    );
    // The far field where the blades end against the blades before it: a colour difference
    // (CIE76 delta E of the mean colours) small enough that no line shows where they meet.
    let delta_e = (lab(fg) - lab(b)).length();
    eprintln!("delta E {delta_e:.2}");
    // 2.7 seen on software Vulkan; about 2.3 is the least difference the eye notices.
    assert!(
        delta_e < 3.5,
        "far field {fg} vs blades {b}: delta E {delta_e:.2}"
    );
}

/// The far field under trees (their canopy's shade beyond the shadow map, `canopy_depth` in
/// `src/plants/shadow.rs`): on a flat field with trees spread evenly, the ground's far field
/// against its CPU mirror lit with the sun's share the canopy leaves, and darker than the same
/// field's without tree shadows.
#[test]
fn the_far_field_darkens_under_a_forest_as_its_cpu_mirror_says() {
    use verdant::features::Feature;
    use verdant::plants::shadow::canopy_depth;

    let ctx = common::gpu();
    let (mut world, source) = flat_field(1200.0).unwrap();
    let tree: verdant::world::PlantType = toml::from_str(
        "name = \"oak\"\nmesh = \"broadleaf\"\nsize_m = [8.0, 12.0]\n\
         density = { meadow = 0.002 }\nclump_cover = 1.0\n",
    )
    .unwrap();
    world.manifest.plant_types.push(tree);
    let config = RendererConfig::for_world(&world);
    let settings = config.grass_settings(&world).unwrap();
    let shadows = config.tree_shadows.unwrap();
    let view = f64::from(settings.view_distance_m);
    let (w, h) = (320u32, 180u32);
    // 30 m over the field, looking at the ground 350-700 m away.
    let mut camera = Camera::new(DVec3::new(200.0, 200.0, 30.0), 45.0, -4.0);
    camera.fov_y_deg = 6.0;
    let render = |features: verdant::features::Features| {
        let mut config = RendererConfig::for_world(&world);
        config.features = features;
        let mut scene =
            Scene::with_source(&ctx, world.clone(), source.clone(), w, h, config).unwrap();
        assert!(
            scene
                .warm_up(&ctx, &camera, std::time::Duration::from_secs(60))
                .unwrap()
        );
        scene.render(&ctx, &camera).unwrap();
        (
            scene.read_image(&ctx).unwrap(),
            scene.read_depth(&ctx).unwrap(),
        )
    };
    let all = config.features;
    let (shaded, depth) = render(all);
    let (open, _) = render(all.without(Feature::TreeShadows));
    let points = ground_points(&camera, w, h);
    let vp = camera.view_proj_relative(w as f32 / h as f32);

    let sky = &world.manifest.sky;
    let light = Light {
        sun_dir: sun_direction(sky),
        sun_color: Vec3::from_array(sky.sun_color),
        sky_color: Vec3::from_array(sky.sky_color),
        ambient_occlusion: true,
        translucency: true,
        specular: true,
    };
    let set = verdant::plants::PlantSet::build(&world.manifest, &world.dir).unwrap();
    let trees = config.tree_settings(&world).unwrap();
    let tau = canopy_depth(&world.manifest, &set, trees.cell_m, light.sun_dir)[1];
    let meadow = &world.manifest.grass_types[1];
    let blade = Vec3::from_array(meadow.base_color)
        .lerp(Vec3::from_array(meadow.tip_color), far_field::FAR_T);
    let (mut gpu, mut cpu, mut bare) = (Vec::new(), Vec::new(), Vec::new());
    for (i, p) in points.iter().enumerate() {
        let Some(p) = *p else { continue };
        let rel = (p - camera.position).as_vec3();
        let dist = rel.length();
        let faded_at = f64::from(far_field::far_distance(
            dist,
            (camera.position.z - p.z) as f32,
        ));
        if faded_at < view + 25.0 {
            continue;
        }
        // The ground, not a tree in front of it: the depth is the ground's.
        let c = vp * rel.extend(1.0);
        if (depth[i] - c.z / c.w).abs() > 1e-3 * depth[i].max(1e-6) {
            continue;
        }
        let linear = |img: &image::RgbaImage| {
            let px = &img.as_raw()[i * 4..i * 4 + 3];
            Vec3::new(
                srgb_to_linear(px[0]),
                srgb_to_linear(px[1]),
                srgb_to_linear(px[2]),
            )
        };
        gpu.push(linear(&shaded));
        bare.push(linear(&open));
        let xy = DVec2::new(p.x, p.y);
        let world_mod = DVec2::new(xy.x.rem_euclid(4096.0), xy.y.rem_euclid(4096.0));
        let clump = Vec3::ONE.lerp(
            far_field::clump_tint(xy, settings.clump_m, settings.seed),
            far_field::clump_visibility(dist, settings.clump_m),
        );
        let albedo = blade * clump * far_field::color_variation(world_mod.as_vec2());
        let fade = [0.9 * shadows.distance_m, shadows.distance_m];
        let sun_vis = 1.0
            - far_field::tree_canopy_shade(tau, 1.0) * far_field::tree_canopy_fade_in(dist, fade);
        let lit = far_field::light_far_grass(albedo, Vec3::Z, far_field::FAR_T, sun_vis, &light);
        let x = dist / sky.fog_distance_m;
        let fog = 1.0 - (-3.0 * x * x).exp();
        let v = rel / dist;
        let fog_color = Vec3::from_array(sky.horizon_color).lerp(
            Vec3::from_array(sky.sun_color),
            0.35 * v.dot(light.sun_dir).max(0.0).powf(8.0),
        );
        cpu.push(lit.lerp(fog_color, fog));
    }
    assert!(gpu.len() > 2000, "{} far-field ground pixels", gpu.len());
    let (g, c, b) = (mean(&gpu), mean(&cpu), mean(&bare));
    let shade = far_field::tree_canopy_shade(tau, 1.0);
    eprintln!(
        "canopy shades {shade:.3} of the ground: far field {g} (GPU), {c} (CPU), {b} without"
    );
    assert!(shade > 0.2 && shade < 0.8, "a canopy to measure: {shade}");
    let rel = ((g - c).abs() / c).max_element();
    assert!(
        rel < 0.04,
        "far field under trees GPU {g} vs CPU mirror {c}: {rel:.3}"
    );
    assert!(
        g.y < 0.9 * b.y,
        "the canopy darkens the far field: {g} against {b} without"
    );
}
