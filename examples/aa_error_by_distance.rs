//! Where the error against the truth comes from, by distance from the camera.
//!
//! `cargo run --release --example aa_error_by_distance -- [WIDTH HEIGHT [PATH [OUT [WIDEN [PARTS [RUN_UP [WIND [TAA [REFS]]]]]]]]]`
//! (defaults 480 270 meadow out/error-by-distance): one view of the default world's path (the
//! meadow's first; 30% along any other), after six frames of the same wind for every render,
//! drawn as the 4x4 truth and as: the truth at 8x8 (the truth's own sampling error), with blades
//! out to one and two view distances, at one sample and at 2x2; the default frame's settings
//! supersampled 4x4 (a perfect anti-aliasing of the default frame); and the default frame with
//! each anti-aliasing method; WIDEN, a comma-separated list of the low ring's widenings
//! (`GrassConfig::lod_widen`), adds the default frame supersampled 4x4 with each (an empty
//! list, none); PARTS, a comma-separated list of `segments`, `rings`, `plants` and `trees`,
//! adds the default frame supersampled 4x4 with that part of the truth's settings (blades out
//! to one view distance): the blade segments, the grass rings (no LOD), every plant's full mesh
//! unthinned, every tree's; `truth` every setting of the truth's at its whole reach (with
//! `taa:`, the temporal method drawing the truth's content); `trees_meshes` the trees' meshes as
//! far as the truth's (thinned as the default's); and with values, the default frame with
//! those: `segments=NEAR/HIGH/LOW` blade segments, `trees_thin=METRES/KEEP` the trees'
//! thinning (`PlantSettings::thin_m`, `min_keep`), `trees_lod=NEAR/FAR` and
//! `plants_lod=NEAR/FAR` the switches, `plants_thin=METRES`, `view=SCALE` the grass's view
//! distance times SCALE (the far field standing in beyond it); `k=K` the default
//! frame supersampled K x K (at K other than 4, sampled elsewhere in the pixel than the truth's
//! sub-samples); parts joined by `+` (`segments=9/3/3+view=0.67`) make one frame with all of
//! them; a part prefixed `taa:` (`taa:segments=9/3/3+view=0.67`) is the default frame with
//! those settings drawn with the temporal method instead of supersampled. Prints each
//! one's mean FLIP against the truth over the frame and over bands of distance (from the
//! truth's depth) with the bands' share of the frame, each one's mean luminance over the
//! truth's in each band, and writes every image into OUT. RUN_UP (default 6) is the frames drawn
//! before the measured one (a temporal method's history fills over them); WIND names the
//! world's wind scene for every render (default: the renderer's); TAA, a comma-separated list
//! of `SIGMA/SAMPLES[/MOTION[/SPREAD[/PARALLAX[/MIN[/RECONSTRUCT[/SWAY]]]]]]`, adds the temporal
//! method with those settings (`TaaSettings::clip_sigma`, `max_samples`; MOTION 1 turns
//! `blade_motion` on; SPREAD is `pixel_spread`, PARALLAX `parallax_falloff`, MIN
//! `min_samples`, RECONSTRUCT `reconstruct_px`, SWAY `sway_falloff`; the fields left out keep the renderer's defaults,
//! `TaaSettings::default()`; before, PARALLAX, MIN and RECONSTRUCT left out were 0, 2 and 0).
//! REFS (default `all`) names the standard renders
//! drawn besides the truth, comma-separated, of `truth_k8`, `truth_reach1`, `truth_reach2`,
//! `truth_1x`, `truth_2x2`, `default_4x4`, `off`, `msaa` and `taa` (`none` for none):
//! `truth_k8` alone is 64 renders with blades to the truth's reach, and on a software renderer
//! the renders asked for are what a view's minutes are spent on. With `truth_k8`, every render
//! (the 4x4 truth among them) is also measured against the truth at 8x8.
use anyhow::Result;
use std::sync::Arc;
use verdant::RendererConfig;
use verdant::aa::AntiAliasing;
use verdant::camera::sample_path;
use verdant::gpu::GpuContext;
use verdant::tools::Scene;
use verdant::tools::metrics::{
    band_mask, flip_error_map, masked_luminance, masked_mean, ray_distances, rgb,
};
use verdant::tools::truth::{REACH_FACTOR, Truth, atlas_slots, truth_config_reaching};
use verdant::world::World;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let number = |i: usize, default: u32| -> Result<u32> {
        match args.get(i) {
            Some(s) => s
                .parse()
                .map_err(|e| anyhow::anyhow!("argument {i} ({s:?}) is not a size: {e}")),
            None => Ok(default),
        }
    };
    let (w, h) = (number(1, 480)?, number(2, 270)?);
    let pathname = args.get(3).cloned().unwrap_or("meadow".into());
    let out = std::path::PathBuf::from(
        args.get(4)
            .cloned()
            .unwrap_or("out/error-by-distance".into()),
    );
    std::fs::create_dir_all(&out)?;
    let wdir = std::path::PathBuf::from("worlds/santa-cruz");
    let world = World::open(&wdir)?;
    let path = verdant::tools::camera_path(&world, &wdir, Some(&pathname))?;
    let t0 = path.keys[0].t_s
        + 0.3
            * (path.keys[path.keys.len() - 1].t_s - path.keys[0].t_s)
            * if pathname == "meadow" { 0.0 } else { 1.0 };
    let cam = sample_path(&path, t0);
    let ctx = GpuContext::new()?;
    let slots = atlas_slots(&world, &ctx.device);
    let mut base = RendererConfig::for_world(&world);
    let run_up: i64 = match args.get(7).filter(|a| !a.is_empty()) {
        Some(n) => n
            .parse()
            .map_err(|e| anyhow::anyhow!("run-up {n:?} is not a count: {e}"))?,
        None => 6,
    };
    if let Some(scene) = args.get(8).filter(|a| !a.is_empty()) {
        base.wind_scene = Some(scene.clone());
    }
    let dt = 1.0 / 60.0;
    let walker = Some(cam.position.truncate());
    let mut truths: Vec<(String, Truth)> = Vec::new();
    let mk = |name: &str, cfg: RendererConfig, k: u32| -> Result<(String, Truth)> {
        Ok((
            name.to_string(),
            Truth::with_config(&ctx, world.clone(), Arc::new(world.clone()), (w, h), k, cfg)?,
        ))
    };
    const REFS: [&str; 9] = [
        "truth_k8",
        "truth_reach1",
        "truth_reach2",
        "truth_1x",
        "truth_2x2",
        "default_4x4",
        "off",
        "msaa",
        "taa",
    ];
    let refs: Vec<&str> = match args.get(10).map(String::as_str) {
        None | Some("all") => REFS.to_vec(),
        Some("none") => Vec::new(),
        Some(list) => {
            let v: Vec<&str> = list.split(',').collect();
            if let Some(bad) = v.iter().find(|r| !REFS.contains(r)) {
                anyhow::bail!("REFS: {bad:?} is not one of all, none, {}", REFS.join(", "));
            }
            v
        }
    };
    truths.push(mk(
        "truth",
        truth_config_reaching(&world, &base, slots, REACH_FACTOR),
        4,
    )?);
    for (name, reach, k) in [
        ("truth_k8", REACH_FACTOR, 8),
        ("truth_reach1", 1.0, 4),
        ("truth_reach2", 2.0, 4),
        ("truth_1x", REACH_FACTOR, 1),
        ("truth_2x2", REACH_FACTOR, 2),
    ] {
        if refs.contains(&name) {
            truths.push(mk(
                name,
                truth_config_reaching(&world, &base, slots, reach),
                k,
            )?);
        }
    }
    let mut d = base.clone();
    d.aa = AntiAliasing::Off;
    d.service.atlas_slots = d.service.atlas_slots.max(slots);
    if refs.contains(&"default_4x4") {
        truths.push(mk("default_4x4", d.clone(), 4)?);
    }
    // The parts drawn with the temporal method, made into scenes below.
    let mut taa_parts: Vec<(String, RendererConfig)> = Vec::new();
    if let Some(list) = args.get(5).filter(|l| !l.is_empty()) {
        for k in list.split(',') {
            let k: f32 = k
                .parse()
                .map_err(|e| anyhow::anyhow!("widening {k:?} is not a number: {e}"))?;
            let mut dk = d.clone();
            dk.grass.lod_widen = k;
            truths.push(mk(&format!("default_4x4_w{k}"), dk, 4)?);
        }
    }
    if let Some(list) = args.get(6).filter(|l| !l.is_empty()) {
        let t1 = truth_config_reaching(&world, &base, slots, 1.0);
        for part in list.split(',') {
            if let Some(k) = part.strip_prefix("k=") {
                // The default frame supersampled k x k: at k other than the truth's 4 its
                // sub-samples lie elsewhere in the pixel than the truth's.
                let k: u32 = k
                    .parse()
                    .map_err(|e| anyhow::anyhow!("part {part:?}: {e}"))?;
                truths.push(mk(&format!("default_{k}x{k}"), d.clone(), k)?);
                continue;
            }
            let (temporal, part) = match part.strip_prefix("taa:") {
                Some(p) => (true, p),
                None => (false, part),
            };
            let mut dp = d.clone();
            let usage = "truth, segments, segments=NEAR/HIGH/LOW, rings, plants, trees, \
                         trees_meshes, trees_thin=METRES/KEEP, trees_lod=NEAR/FAR, \
                         plants_lod=NEAR/FAR, plants_thin=METRES, view=SCALE, k=K";
            // Parts joined by `+` apply together to one frame.
            for part in part.split('+') {
                let trees = dp.tree_settings(&world);
                match part.split_once('=') {
                    None => match part {
                        // Every setting of the truth's, at its whole reach.
                        "truth" => dp = truth_config_reaching(&world, &base, slots, REACH_FACTOR),
                        "segments" => dp.grass.segments = t1.grass.segments,
                        "rings" => dp.grass_rings = t1.grass_rings,
                        "plants" => dp.plants = t1.plants,
                        "trees" => dp.trees = t1.trees,
                        "trees_meshes" => {
                            dp.trees = trees.map(|t| verdant::plants::PlantSettings {
                                lod_m: t1.trees.map_or(t.lod_m, |u| u.lod_m),
                                ..t
                            })
                        }
                        other => anyhow::bail!("part {other:?} is not one of {usage}"),
                    },
                    Some((name, values)) => {
                        let v: Vec<f32> = values
                            .split('/')
                            .map(|n| n.parse())
                            .collect::<Result<_, _>>()
                            .map_err(|e| anyhow::anyhow!("part {part:?}: {e}"))?;
                        let with = |f: &dyn Fn(&mut verdant::plants::PlantSettings)| {
                            trees.map(|mut t| {
                                f(&mut t);
                                t
                            })
                        };
                        match (name, &v[..]) {
                            ("segments", &[near, high, low]) => {
                                dp.grass.segments = [near, high, low].map(|n| n as u32)
                            }
                            ("trees_thin", &[m, k]) => {
                                dp.trees = with(&|t| {
                                    t.thin_m = m;
                                    t.min_keep = k;
                                })
                            }
                            ("trees_lod", &[a, b]) => dp.trees = with(&|t| t.lod_m = [a, b]),
                            ("plants_lod", &[a, b]) => dp.plants.lod_m = [a, b],
                            ("plants_thin", &[m]) => dp.plants.thin_m = m,
                            ("view", &[k]) if k > 0.0 => {
                                let r = dp.grass_rings.unwrap_or_else(|| {
                                    verdant::lod::RingSettings::for_pyramid(&world.manifest.pyramid)
                                });
                                dp.grass_rings = Some(verdant::lod::RingSettings {
                                    low_radius_m: r.low_radius_m * f64::from(k),
                                    ..r
                                });
                            }
                            _ => anyhow::bail!("part {part:?} is not one of {usage}"),
                        }
                    }
                }
            }
            let label = part.replace(['/', '=', '+'], "_");
            if temporal {
                dp.aa = AntiAliasing::Taa;
                taa_parts.push((format!("taa_{label}"), dp));
            } else {
                truths.push(mk(&format!("default_4x4_{label}"), dp, 4)?);
            }
        }
    }
    let mut scenes: Vec<(String, Scene)> = Vec::new();
    for m in [AntiAliasing::Off, AntiAliasing::Msaa, AntiAliasing::Taa] {
        if !refs.contains(&m.name()) {
            continue;
        }
        let mut c = base.clone();
        c.aa = m;
        scenes.push((
            m.name().to_string(),
            Scene::new(&ctx, world.clone(), w, h, c)?,
        ));
    }
    for (name, c) in taa_parts {
        scenes.push((name, Scene::new(&ctx, world.clone(), w, h, c)?));
    }
    for variant in args
        .get(9)
        .iter()
        .flat_map(|l| l.split(','))
        .filter(|v| !v.is_empty())
    {
        let v: Vec<f32> = variant
            .split('/')
            .map(|n| n.parse())
            .collect::<Result<_, _>>()
            .map_err(|e| anyhow::anyhow!("taa variant {variant:?}: {e}"))?;
        let mut c = base.clone();
        c.aa = AntiAliasing::Taa;
        match v[..] {
            [sigma, n, ..] if n >= 2.0 && v.len() <= 8 => {
                // The fields left out keep the renderer's defaults.
                let d = base.taa;
                c.taa.clip_sigma = sigma;
                c.taa.max_samples = n as u32;
                c.taa.blade_motion = v.get(2).map_or(d.blade_motion, |&m| m > 0.0);
                c.taa.pixel_spread = v.get(3).copied().unwrap_or(d.pixel_spread);
                c.taa.parallax_falloff = v.get(4).copied().unwrap_or(d.parallax_falloff);
                c.taa.min_samples = v.get(5).copied().unwrap_or(d.min_samples);
                c.taa.reconstruct_px = v.get(6).copied().unwrap_or(d.reconstruct_px);
                c.taa.sway_falloff = v.get(7).copied().unwrap_or(d.sway_falloff);
            }
            _ => anyhow::bail!(
                "taa variant {variant:?} is not SIGMA/SAMPLES[/MOTION[/SPREAD[/PARALLAX[/MIN[/RECONSTRUCT[/SWAY]]]]]]"
            ),
        }
        c.validate()
            .map_err(|e| anyhow::anyhow!("taa variant {variant:?}: {e}"))?;
        scenes.push((
            format!("taa_{}", variant.replace('/', "_")),
            Scene::new(&ctx, world.clone(), w, h, c)?,
        ));
    }
    let mut imgs: Vec<(String, image::RgbaImage)> = Vec::new();
    let mut depth = Vec::new();
    for i in -run_up..=0 {
        let t = t0 + i as f64 * dt;
        for (name, tr) in truths.iter_mut() {
            tr.scene()
                .warm_up_report(&cam, std::time::Duration::from_secs(60))?;
            if i < 0 {
                tr.advance(&ctx, &cam, t, walker)?;
            } else {
                let img = tr.render(&ctx, &cam, t, walker)?;
                if name == "truth" {
                    depth = tr.read_depth(&ctx)?;
                }
                imgs.push((name.clone(), img));
            }
        }
        for (name, sc) in scenes.iter_mut() {
            sc.warm_up_report(&cam, std::time::Duration::from_secs(60))?;
            sc.render_frame(&ctx, &cam, t, walker)?;
            if i == 0 {
                imgs.push((name.clone(), sc.read_image(&ctx)?));
            }
        }
    }
    let inv = cam.view_proj_relative(w as f32 / h as f32).inverse();
    let dist = ray_distances(&depth, w, h, inv);
    let bands = [
        (0.0, 10.0),
        (10.0, 25.0),
        (25.0, 60.0),
        (60.0, 150.0),
        (150.0, 600.0),
        (600.0, 1e9),
    ];
    let masks: Vec<Vec<bool>> = bands.iter().map(|&(a, b)| band_mask(&dist, a, b)).collect();
    let truth = imgs[0].1.clone();
    print!("{:14} {:>7}", "render", "FLIP");
    for (a, b) in bands {
        print!(" {:>9}", format!("{a}-{b}"));
    }
    println!();
    print!("{:14} {:>7}", "share", "");
    for m in &masks {
        print!(
            " {:>9.3}",
            m.iter().filter(|&&x| x).count() as f64 / m.len() as f64
        );
    }
    println!();
    // A render's row: its mean FLIP against `reference` over the frame and in each band.
    let row = |reference: &image::RgbaImage, name: &str, img: &image::RgbaImage| -> Result<()> {
        let e = flip_error_map(&rgb(reference), &rgb(img))?;
        let mean = e.iter().map(|&v| v as f64).sum::<f64>() / e.len() as f64;
        print!("{:14} {:>7.4}", name, mean);
        for m in &masks {
            print!(
                " {:>9}",
                masked_mean(&e, m).map_or("-".into(), |v| format!("{v:.4}"))
            );
        }
        println!();
        Ok(())
    };
    for (name, img) in &imgs {
        img.save(out.join(format!("{pathname}_{w}x{h}_{name}.png")))?;
        if name != "truth" {
            row(&truth, name, img)?;
        }
    }
    // With the truth at 8x8 drawn: every render against it too, the 4x4 truth among them (the
    // 4x4 truth's own sampling error: what an exact frame would err against the 4x4 truth).
    if let Some((_, k8)) = imgs.iter().find(|(n, _)| n == "truth_k8") {
        println!("against the truth at 8x8");
        for (name, img) in imgs.iter().filter(|(n, _)| n != "truth_k8") {
            row(k8, name, img)?;
        }
    }
    // Brightness by band: the mean linear luminance of each render over the truth's (a
    // systematic difference, not aliasing, moves it away from 1).
    println!("mean luminance over the truth's, by band");
    for (name, img) in &imgs {
        print!("{:14} {:>7}", name, "");
        for m in &masks {
            let v = match (masked_luminance(img, m), masked_luminance(&truth, m)) {
                (Some(a), Some(b)) if b > 0.0 => format!("{:.3}", a / b),
                _ => "-".into(),
            };
            print!(" {v:>9}");
        }
        println!();
    }
    Ok(())
}
