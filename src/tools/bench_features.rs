//! `verdant bench features`: each grass feature's GPU cost against its contribution to the image,
//! and every variant's error against the truth.
//!
//! The contribution of a feature is the FLIP between the full render and the render with that
//! feature off. Every variant (the full render included) is also measured against the truth at
//! the same camera and time ([`crate::tools::truth`], all features on), by pixel FLIP and by the
//! coarse FLIP (see [`crate::tools::bench`]).

use anyhow::{Result, bail};
use serde::Serialize;

use crate::RendererConfig;
use crate::camera::sample_path;
use crate::gpu::GpuContext;
use crate::tools::bench::{Bench, BenchLodOptions, Measures, warm_up};
use crate::tools::fly::{OutDir, Outputs, write_text};
use crate::tools::metrics::{COVERAGE_DISTANCE_M, Chart, ChartPoint};
use crate::tools::stop::{Stop, caught, chart_title};
use crate::tools::timing::{FrameCounts, Timing, frame_ms, ramp_up, run_frames};
use crate::tools::{AdapterReport, write_json};
use crate::world::World;

/// One feature's cost and contribution.
#[derive(Clone, Debug, Serialize)]
pub struct FeatureResult {
    /// The feature (or "all" for the full render).
    pub feature: String,
    /// Median GPU time per frame with the feature off (all: everything on), milliseconds (wall
    /// time without timestamps).
    pub gpu_ms: f64,
    /// That time's quartiles and spread.
    pub timing: Timing,
    /// GPU time the feature costs: the full render's minus this one's, milliseconds.
    pub cost_ms: f64,
    /// Mean FLIP between the full render and the render without the feature: its contribution
    /// to the image.
    pub contribution: f64,
    /// The coarse FLIP between the same two (see [`crate::tools::metrics::coarse_flip`]).
    pub contribution_coarse: f64,
    /// Mean error of the render without the feature (all: the full render) against the truth
    /// over the views, by both measures.
    pub vs_truth: Measures,
    /// Grass coverage within [`COVERAGE_DISTANCE_M`] with the feature off (all: everything
    /// on), mean over the views, measured on the captured frames, not the timed ones.
    pub coverage: f64,
}

/// Everything `bench_features.json` holds.
#[derive(Clone, Debug, Serialize)]
pub struct BenchFeaturesReport {
    /// The adapter.
    pub adapter: AdapterReport,
    /// Image size.
    pub size: (u32, u32),
    /// Sub-samples a pixel side of the truth.
    pub truth_k: u32,
    /// The variants' anti-aliasing (`off`, `taa`, `msaa`).
    pub anti_aliasing: String,
    /// The full render first, then one row per feature switched off (of a run stopped early,
    /// the variants whose images were captured: their timings are of the rounds run, none
    /// where `timing.frames` is 0).
    pub features: Vec<FeatureResult>,
    /// Whether the run was stopped before its end (Ctrl-C; [`BenchLodOptions::stop`]): the
    /// report holds what was measured until then.
    pub interrupted: bool,
}

/// The files [`run_bench_features`] writes into its output folder.
const FILES: [&str; 4] = [
    "bench_features.json",
    "features.csv",
    "features.png",
    "features_coarse.png",
];

/// `verdant bench features`: each feature's GPU cost against its contribution to the image
/// (FLIP between the full render and the render with that feature off), charted one against
/// the other, and each variant's error against the truth (all features on; reached by the same
/// lead-in, so that its wind, sway and trail are those of the frames it judges). The views come from the world's first camera path with wind keys (the baked
/// `wind-tour`): one late in each of its wind scenes, each reached by two seconds of flight
/// along the path in as many frames as the untimed warm-up has (at least one; the sway's exact
/// step is stable at any frame time), so that the sway, the gusts, the sources and the walker's
/// trail are under way. The images are captured first; then the variants are timed in interleaved
/// rounds at each view's time (see [`crate::tools::timing`]). A world without such a path is viewed
/// along `meadow` (else its first path) in the storm. Writes `bench_features.json`, `features.csv`,
/// `features.png` and `features_coarse.png`. Stopped early ([`BenchLodOptions::stop`]), it
/// writes them with the variants measured so far, the report marked interrupted; stopped before
/// the first variant's images, it writes nothing.
pub fn run_bench_features(
    opts: &BenchLodOptions,
    progress: &mut dyn FnMut(&str, u64, u64),
) -> Result<BenchFeaturesReport> {
    use crate::features::{Feature, Features};
    const LEAD_S: f64 = 2.0;
    opts.validate_features()?;
    let world = World::open(&opts.world)?;
    let m = &world.manifest;
    let toured = m.paths.iter().find(|p| !p.wind.is_empty());
    let path = match toured.or(m.path("meadow")).or(m.paths.first()) {
        Some(p) => p.clone(),
        None => bail!("world {} has no camera paths", opts.world.display()),
    };
    let (t0, end) = (path.start_s(), path.end_s());
    // One view 70% of the way through each wind scene (at least LEAD_S into the path), or four
    // views along a path without wind keys.
    let times: Vec<f64> = if path.wind.is_empty() {
        [0.1, 0.35, 0.6, 0.85]
            .iter()
            .map(|&u| path.time_at(u))
            .collect()
    } else {
        path.wind
            .iter()
            .enumerate()
            .map(|(i, k)| {
                let next = path.wind.get(i + 1).map_or(end, |n| n.t_s);
                (k.t_s + 0.7 * (next - k.t_s)).clamp(t0 + LEAD_S, end)
            })
            .collect()
    };
    let scene_name =
        (path.wind.is_empty() && m.wind_scene("storm").is_some()).then(|| "storm".to_owned());
    let out_dir = OutDir::create_for(&opts.out, "bench features", &Outputs::named(&FILES))?;
    let ctx = GpuContext::new()?;
    let variants: Vec<(String, Features)> = std::iter::once(("all".to_owned(), Features::all()))
        .chain(
            Feature::ALL
                .iter()
                // A world without plants (or trees) has none to switch off.
                .filter(|f| match f {
                    Feature::Plants => m.plant_types.iter().any(|t| !t.is_tree()),
                    Feature::Trees | Feature::TreeShadows | Feature::Particles => {
                        m.plant_types.iter().any(|t| t.is_tree())
                    }
                    _ => true,
                })
                .map(|f| (f.name().to_owned(), Features::all().without(*f))),
        )
        .collect();
    let walker_at = |t: f64| crate::camera::walker_at(m, &path, t);
    let counts = FrameCounts::for_adapter(&ctx.info).with(
        opts.warmup_frames,
        opts.timed_frames,
        opts.rounds,
    );
    let lead_frames = counts.warmup.max(1);
    let stop = Stop::new(opts.stop.clone());
    let bench = Bench {
        ctx: &ctx,
        world: &world,
        size: opts.size,
        stop: &stop,
    };
    let variant_config = |features| {
        let mut config = RendererConfig::for_world(&world);
        config.features = features;
        config.wind_scene = scene_name.clone();
        config.wind_keys = path.wind.clone();
        if let Some(aa) = opts.aa {
            config.aa = aa;
        }
        config
    };
    let mut truths = Vec::new();
    let mut scenes = Vec::new();
    let mut all_images = Vec::new();
    // Timed frames hold each view's time: the same image every frame.
    let mut samples = vec![vec![Vec::new(); times.len()]; variants.len()];
    let total = variants.len() as u64;
    // Stopped (Ctrl-C) at a view or a variant, the variants whose images were all captured are
    // reported, with the rounds timed so far.
    let interrupted = caught((|| -> Result<()> {
        // The truth at each view, after the same lead-in as the variants (plain frames: only
        // the last frame, at the view's time, is supersampled).
        let mut truth = bench.truth(
            &variant_config(Features::all()),
            opts.truth_k,
            opts.truth_reach,
        )?;
        for (i, &t) in times.iter().enumerate() {
            stop.check()?;
            warm_up(truth.scene(), &sample_path(&path, t), &stop)?;
            for f in 0..lead_frames {
                let tf = t - LEAD_S * (1.0 - f64::from(f) / f64::from(lead_frames));
                truth.advance(&ctx, &sample_path(&path, tf), tf, Some(walker_at(tf)))?;
            }
            truths.push(truth.render(&ctx, &sample_path(&path, t), t, Some(walker_at(t)))?);
            progress("truth", i as u64 + 1, times.len() as u64);
        }
        drop(truth);
        for (k, (_, features)) in variants.iter().enumerate() {
            let mut scene = bench.scene(variant_config(*features))?;
            let (mut images, mut coverage) = (Vec::new(), Vec::new());
            scene.set_coverage_capture(true)?;
            for &t in &times {
                stop.check()?;
                warm_up(&mut scene, &sample_path(&path, t), &stop)?;
                // The lead-in: the camera and the walker along the path up to the view's time.
                for f in 0..=lead_frames {
                    let tf = t - LEAD_S * (1.0 - f64::from(f) / f64::from(lead_frames));
                    scene.render_frame(&ctx, &sample_path(&path, tf), tf, Some(walker_at(tf)))?;
                }
                images.push(scene.read_image(&ctx)?);
                coverage.push(scene.coverage(&ctx, COVERAGE_DISTANCE_M)?.fraction);
            }
            scene.set_coverage_capture(false)?;
            scenes.push(scene);
            all_images.push((images, coverage));
            progress("images", k as u64 + 1, total);
        }
        if let (Some(scene), Some(&t)) = (scenes.first_mut(), times.first()) {
            ramp_up(&ctx, scene, &sample_path(&path, t), t, Some(walker_at(t)))?;
        }
        for round in 0..counts.rounds {
            for (k, scene) in scenes.iter_mut().enumerate() {
                // A variant's views are timed together: a round stopped part-way leaves the
                // variants it reached with one round more than the others.
                stop.check()?;
                for (vi, &t) in times.iter().enumerate() {
                    let cam = sample_path(&path, t);
                    for (stats, wall) in run_frames(
                        &ctx,
                        scene,
                        &cam,
                        t,
                        Some(walker_at(t)),
                        counts.warmup,
                        counts.timed,
                    )? {
                        samples[k][vi].push(frame_ms(&stats, wall, ctx.timestamps));
                    }
                }
                progress(
                    "timing",
                    u64::from(round) * total + k as u64 + 1,
                    u64::from(counts.rounds) * total,
                );
            }
        }
        Ok(())
    })())?;
    drop(scenes);
    let mut report = BenchFeaturesReport {
        adapter: AdapterReport::of(&ctx),
        size: opts.size,
        truth_k: opts.truth_k,
        anti_aliasing: opts.aa.unwrap_or_default().name().to_owned(),
        features: Vec::new(),
        interrupted,
    };
    if all_images.is_empty() {
        // Stopped before any variant's images: nothing measured, nothing written (an earlier
        // run's files stay as they were).
        return Ok(report);
    }
    let rows: Vec<(String, Timing, Vec<image::RgbaImage>, f64)> = variants
        .iter()
        .zip(samples)
        .zip(all_images)
        .map(|(((name, _), views), (images, coverage))| {
            let t = Timing::over_views(&views.iter().map(|v| Timing::of(v)).collect::<Vec<_>>());
            let c = coverage.iter().sum::<f64>() / coverage.len().max(1) as f64;
            (name.clone(), t, images, c)
        })
        .collect();
    let full = rows[0].1;
    for (name, timing, images, coverage) in &rows {
        let (mut contributions, mut vs_truth) = (Vec::new(), Vec::new());
        for ((a, b), t) in rows[0].2.iter().zip(images).zip(&truths) {
            contributions.push(Measures::of(a, b)?);
            vs_truth.push(Measures::of(t, b)?);
        }
        let contribution = Measures::mean(&contributions);
        report.features.push(FeatureResult {
            feature: name.clone(),
            gpu_ms: timing.median_ms,
            timing: *timing,
            cost_ms: if full.measured() && timing.measured() {
                full.median_ms - timing.median_ms
            } else {
                0.0
            },
            contribution: contribution.flip,
            contribution_coarse: contribution.coarse,
            vs_truth: Measures::mean(&vs_truth),
            coverage: *coverage,
        });
    }
    let features = &report.features;
    use std::fmt::Write as _;
    let mut csv = String::from(
        "feature,gpu_ms_without,q1_ms,q3_ms,spread,noisy,frames,cost_ms,contribution_flip,\
         contribution_coarse_flip,flip_vs_truth,coarse_flip_vs_truth,coverage\n",
    );
    // Figures that a stopped run did not time are empty cells.
    for r in features {
        let t = &r.timing;
        let cost = if full.measured() && t.measured() {
            format!("{:.4}", r.cost_ms)
        } else {
            String::new()
        };
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{},{},{},{:.5},{:.5},{:.5},{:.5},{:.4}",
            r.feature,
            t.cell(r.gpu_ms, 4),
            t.cell(t.q1_ms, 4),
            t.cell(t.q3_ms, 4),
            t.cell(t.spread, 4),
            if t.measured() {
                t.noisy.to_string()
            } else {
                String::new()
            },
            t.frames,
            cost,
            r.contribution,
            r.contribution_coarse,
            r.vs_truth.flip,
            r.vs_truth.coarse,
            r.coverage
        );
    }
    write_text(&opts.out.join("features.csv"), &csv)?;
    let chart = |y_label: &str, y: &dyn Fn(&FeatureResult) -> f64| Chart {
        title: chart_title(
            "Grass features: GPU cost against contribution to the image",
            interrupted,
        ),
        x_label: "GPU cost (ms a frame, full render minus the render without it)".into(),
        y_label: y_label.into(),
        log_x: false,
        log_y: false,
        // A feature has a cost where both it and the full render were timed.
        points: features
            .iter()
            .skip(1)
            .filter(|r| full.measured() && r.timing.measured())
            .map(|r| ChartPoint {
                label: if r.timing.noisy {
                    format!("{} (noisy)", r.feature)
                } else {
                    r.feature.clone()
                },
                x: r.cost_ms,
                y: y(r),
                chosen: false,
            })
            .collect(),
    };
    chart("FLIP between the render with and without it", &|r| {
        r.contribution
    })
    .write_png_with_front(&opts.out.join("features.png"), 900, 600, |_| false)?;
    chart(
        "coarse FLIP (8x8 blocks) between the render with and without it",
        &|r| r.contribution_coarse,
    )
    .write_png_with_front(&opts.out.join("features_coarse.png"), 900, 600, |_| false)?;
    write_json(&opts.out.join("bench_features.json"), &report)?;
    out_dir.keep();
    Ok(report)
}
