//! The far field (terrain beyond the grass shaded with what the blades would show): its colour
//! against real blades drawn past the view distance, the blades before it against real ones,
//! and the GPU's far field against its CPU mirror (`src/terrain/far_field.rs`), on a flat field
//! generated in memory.

mod common;

use glam::{DVec2, DVec3, Vec3, Vec4};
use verdant::RendererConfig;
use verdant::camera::Camera;
use verdant::terrain::far_field::{self, Light};
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
fn the_far_field_shows_what_real_blades_would_and_matches_its_cpu_mirror() {
    let ctx = common::gpu();
    let (world, source) = flat_field(800.0).unwrap();
    let mut config = RendererConfig::for_world(&world);
    // The blades end at two grass tiles (100 m), so that the band before their fade lies in the low
    // ring, past the high ring's thinning. With the default's 67 m that band lies on the high
    // ring's thinning (35-50 m), where the low grid's dropped blades fade out over the far field:
    // there the blades err a delta E of 2.5 against real ones, as much with the blades ending at 67
    // m as at 100 m (the same blades at those distances; docs/anti-aliasing.md, "Nine near segments
    // and a 67 m view as the default").
    let mut rings = config.grass_rings.unwrap();
    rings.low_radius_m = 2.0 * rings.high_radius_m;
    config.grass_rings = Some(rings);
    let settings = config.grass_settings(&world).unwrap();
    let (fade_start, view) = (
        f64::from(settings.view_distance_m - settings.far_fade_m),
        f64::from(settings.view_distance_m),
    );
    // Room in each pool slot for a whole tile of blades at full density.
    config.grass.capacity = Some(settings.grid() * settings.grid());
    let (w, h) = (320u32, 180u32);
    // Standing 6 m up in the field, looking over the ring's end through a narrow lens, so that
    // the bands before and after it are many pixels tall.
    let mut camera = Camera::new(DVec3::new(150.0, 150.0, 6.0), 45.0, -2.2);
    camera.fov_y_deg = 8.0;
    let render = |config: RendererConfig| {
        let mut scene =
            Scene::with_source(&ctx, world.clone(), source.clone(), w, h, config).unwrap();
        assert!(
            scene
                .warm_up(&ctx, &camera, std::time::Duration::from_secs(60))
                .unwrap()
        );
        scene.render(&ctx, &camera).unwrap();
        scene.read_image(&ctx).unwrap()
    };
    let image = render(config.clone());
    // The ground that the far field's grass covers: the same frame without it.
    let mut bare_config = config.clone();
    bare_config.features = config
        .features
        .without(verdant::features::Feature::FarField);
    let bare = render(bare_config);
    // What the far field stands for: real blades out to twice the view distance over bare
    // ground (the truth's settings, with the default's blade segments to keep it quick; the
    // truth's reach counts in the default's view distances).
    let slots = verdant::tools::truth::atlas_slots(&world, &ctx.device);
    let default_view =
        verdant::lod::RingSettings::for_pyramid(&world.manifest.pyramid).low_radius_m;
    let mut reach = verdant::tools::truth::truth_config_reaching(
        &world,
        &config,
        slots,
        2.0 * rings.low_radius_m / default_view,
    );
    reach.grass.segments = config.grass.segments;
    let real = render(reach);
    // The ground bare between the blades, as the truth keeps it: the far field only where the
    // blades fade out.
    let mut between_config = config.clone();
    between_config.grass.far_field_under_blades = false;
    let between = render(between_config);
    let points = ground_points(&camera, w, h);

    let sky = &world.manifest.sky;
    let light = Light::of_sky(sky);
    let meadow = &world.manifest.grass_types[1];
    let area = far_field::blade_area_index(
        meadow.width_m,
        meadow.height_m,
        settings.width_scale,
        settings.spacing_m,
    );
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
    let (mut near_real, mut far_real) = (Vec::new(), Vec::new());
    // Pixels before the blades' fade (where the bare-between frame should be the frame without
    // the far field) and past it (the frame with it), and those of them that differ.
    let (mut checked, mut differ) = ([0usize; 2], [0usize; 2]);
    for (i, p) in points.iter().enumerate() {
        let Some(p) = *p else { continue };
        let linear = |img: &image::RgbaImage| {
            let px = &img.as_raw()[i * 4..i * 4 + 3];
            Vec3::new(
                srgb_to_linear(px[0]),
                srgb_to_linear(px[1]),
                srgb_to_linear(px[2]),
            )
        };
        let gpu = linear(&image);
        let (fog, fog_color, dist) = fog_at(p);
        // The grass's fade goes by the distance plus the height the camera stands above.
        let faded_at = f64::from(far_field::far_distance(
            dist,
            (camera.position.z - p.z) as f32,
            settings.elevation_fade,
        ));
        let shown =
            far_field::under_blades_fade_in(faded_at as f32, [fade_start as f32, view as f32]);
        if shown == 0.0 || shown == 1.0 {
            let end = usize::from(shown == 1.0);
            let expected = if end == 1 { &image } else { &bare };
            let px = |img: &image::RgbaImage| img.as_raw()[i * 4..i * 4 + 3].to_vec();
            checked[end] += 1;
            if px(&between)
                .iter()
                .zip(px(expected))
                .any(|(a, b)| a.abs_diff(b) > 2)
            {
                differ[end] += 1;
            }
        }
        let dist = f64::from(dist);
        // Blades at full density just before their fade; the far field past its end, where
        // the last blades (0.7 m at most, seen from 6 m) no longer stand in front of it.
        if (fade_start - 25.0..fade_start).contains(&faded_at) {
            blades.push(gpu);
            near_real.push(linear(&real));
        } else if (view + 25.0..view + 80.0).contains(&faded_at) {
            far_gpu.push(gpu);
            far_real.push(linear(&real));
            let xy = DVec2::new(p.x, p.y);
            let world_mod = DVec2::new(xy.x.rem_euclid(4096.0), xy.y.rem_euclid(4096.0));
            let clump = Vec3::ONE.lerp(
                far_field::clump_tint(xy, settings.clump_m, settings.seed),
                far_field::clump_visibility(dist as f32, settings.clump_m),
            );
            let tint = clump * far_field::color_variation(world_mod.as_vec2());
            // Seen from 6 m over the ring's end, the grass hides most of the ground (the GPU's
            // frame without the far field), by the view's angle to it.
            let depth = far_field::optical_depth(area, 1.0, camera.position.z as f32 / dist as f32);
            let [a0, a1] = far_field::visible_albedo(
                Vec3::from_array(meadow.base_color),
                Vec3::from_array(meadow.tip_color),
                depth,
            );
            let lit = far_field::light_far_grass([a0 * tint, a1 * tint], Vec3::Z, 1.0, &light);
            far_cpu.push(linear(&bare).lerp(lit.lerp(fog_color, fog), far_field::cover(depth)));
        }
    }
    assert!(
        blades.len() > 500 && far_gpu.len() > 500,
        "bands too thin: {} and {} pixels",
        blades.len(),
        far_gpu.len()
    );
    // Kept bare between the blades, the frame is the one without the far field before their
    // fade and the one with it past the view distance (the mirror's fade-in at 0 and 1).
    assert!(checked[0] > 500 && checked[1] > 500, "{checked:?} pixels");
    assert!(
        differ == [0, 0],
        "bare between the blades: {} of {} pixels before their fade differ from the frame \
         without the far field, {} of {} past it from the frame with it",
        differ[0],
        checked[0],
        differ[1],
        checked[1]
    );
    let (b, fg, fc) = (mean(&blades), mean(&far_gpu), mean(&far_cpu));
    let (br, fr) = (mean(&near_real), mean(&far_real));
    eprintln!(
        "before the ring's end: blades {b} (real {br}); past it: far field {fg} (GPU), {fc} \
         (CPU mirror), real blades {fr}"
    );
    // The GPU against its mirror: within 4% per channel (the mirror leaves out the ground's
    // detail noise, whose mean is zero, and the 8-bit target's rounding).
    let rel = ((fg - fc).abs() / fc).max_element();
    assert!(
        rel < 0.04,
        "far field GPU {fg} vs CPU mirror {fc}: {rel:.3}"
    );
    // The far field against the real blades it stands for, in the same pixels, and the
    // blades before the ring's end against real ones there (the low ring's quarter of the
    // blades over the far field): colour differences (CIE76 delta E of the mean colours)
    // under what the eye notices, about 2.3.
    let far_e = (lab(fg) - lab(fr)).length();
    let near_e = (lab(b) - lab(br)).length();
    // Across the ring's end the colour changes as a field of real blades changes it (seen
    // from nearer and higher, more of the blades and the ground show): no more than that, so
    // that no line shows where the blades end.
    let step = lab(fg) - lab(b);
    let real_step = lab(fr) - lab(br);
    let seam_e = (step - real_step).length();
    eprintln!(
        "delta E: far field {far_e:.2} and blades {near_e:.2} from real blades; across the \
         ring's end {:.2} (real blades {:.2}), {seam_e:.2} apart",
        step.length(),
        real_step.length()
    );
    assert!(
        far_e < 2.3,
        "far field {fg} vs real blades {fr}: delta E {far_e:.2}"
    );
    assert!(
        near_e < 2.3,
        "blades before the ring's end {b} vs real blades {br}: delta E {near_e:.2}"
    );
    assert!(
        seam_e < 2.3,
        "the step across the ring's end {step} vs real blades' {real_step}: delta E {seam_e:.2}"
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
        // Each pixel against the mirror's shading of the ground at its centre: one sample there.
        config.aa = verdant::aa::AntiAliasing::Off;
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
    // The ground under the far field's grass, shaded by the canopy as the far field is.
    let (ground, _) = render(all.without(Feature::FarField));
    let points = ground_points(&camera, w, h);
    let vp = camera.view_proj_relative(w as f32 / h as f32);

    let sky = &world.manifest.sky;
    let light = Light::of_sky(sky);
    let set = verdant::plants::PlantSet::build(&world.manifest, &world.dir).unwrap();
    let trees = config.tree_settings(&world).unwrap();
    let tau = canopy_depth(&world.manifest, &set, trees.cell_m, light.sun_dir).at(1, 0.0);
    let meadow = &world.manifest.grass_types[1];
    let area = far_field::blade_area_index(
        meadow.width_m,
        meadow.height_m,
        settings.width_scale,
        settings.spacing_m,
    );
    let (mut gpu, mut cpu, mut bare) = (Vec::new(), Vec::new(), Vec::new());
    for (i, p) in points.iter().enumerate() {
        let Some(p) = *p else { continue };
        let rel = (p - camera.position).as_vec3();
        let dist = rel.length();
        let faded_at = f64::from(far_field::far_distance(
            dist,
            (camera.position.z - p.z) as f32,
            settings.elevation_fade,
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
        let under = linear(&ground);
        let xy = DVec2::new(p.x, p.y);
        let world_mod = DVec2::new(xy.x.rem_euclid(4096.0), xy.y.rem_euclid(4096.0));
        let clump = Vec3::ONE.lerp(
            far_field::clump_tint(xy, settings.clump_m, settings.seed),
            far_field::clump_visibility(dist, settings.clump_m),
        );
        let tint = clump * far_field::color_variation(world_mod.as_vec2());
        let fade = [0.9 * shadows.distance_m, shadows.distance_m];
        let sun_vis = 1.0
            - far_field::tree_canopy_shade(tau, 1.0) * far_field::tree_canopy_fade_in(dist, fade);
        // Seen from 30 m at 350-700 m, the grass hides most of the ground.
        let cover_depth =
            far_field::optical_depth(area, 1.0, (camera.position.z - p.z) as f32 / dist);
        let [a0, a1] = far_field::visible_albedo(
            Vec3::from_array(meadow.base_color),
            Vec3::from_array(meadow.tip_color),
            cover_depth,
        );
        let lit = far_field::light_far_grass([a0 * tint, a1 * tint], Vec3::Z, sun_vis, &light);
        let x = dist / sky.fog_distance_m;
        let fog = 1.0 - (-3.0 * x * x).exp();
        let v = rel / dist;
        let fog_color = Vec3::from_array(sky.horizon_color).lerp(
            Vec3::from_array(sky.sun_color),
            0.35 * v.dot(light.sun_dir).max(0.0).powf(8.0),
        );
        cpu.push(under.lerp(lit.lerp(fog_color, fog), far_field::cover(cover_depth)));
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
