//! The truth (`src/tools/truth.rs`): K x K jittered sub-samples averaged in linear light, with
//! the most accurate settings, on a flat field generated in memory (small sizes, K = 2, a coarse
//! blade spacing: software Vulkan draws it in seconds).

mod common;

use std::process::Command;

use glam::{DVec2, DVec3};
use verdant::RendererConfig;
use verdant::camera::Camera;
use verdant::tools::Scene;
use verdant::tools::bench_blades::flat_field;
use verdant::tools::truth::{self, Truth, truth_config};

const SIZE: (u32, u32) = (96, 64);
const TIME_S: f64 = 1.5;

/// The field, the truth's settings (blades every metre, so that 129-vertex blades stay cheap on
/// a software renderer), a camera at its edge looking across it, and its walker.
fn field(
    ctx: &verdant::gpu::GpuContext,
) -> (
    verdant::world::World,
    std::sync::Arc<dyn verdant::stream::TileSource>,
    RendererConfig,
    Camera,
    DVec2,
) {
    let (world, source) = flat_field(200.0).unwrap();
    let mut base = RendererConfig::for_world(&world);
    base.grass.spacing_m = 1.0;
    let g = base.grass_settings(&world).unwrap().grid();
    base.grass.capacity = Some(3 * g * g);
    let config = truth_config(&world, &base, truth::atlas_slots(&world, &ctx.device));
    let camera = Camera::new(DVec3::new(-5.0, -5.0, 4.0), 45.0, -12.0);
    let walker = camera.position.truncate();
    (world, source, config, camera, walker)
}

fn truth(ctx: &verdant::gpu::GpuContext, k: u32) -> (Truth, Camera, DVec2) {
    let (world, source, config, camera, walker) = field(ctx);
    let t = Truth::with_config(ctx, world, source, SIZE, k, config).unwrap();
    (t, camera, walker)
}

fn decode(c: u8) -> f64 {
    let c = f64::from(c) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

fn encode(v: f64) -> u8 {
    let v = v.clamp(0.0, 1.0);
    let s = if v <= 0.0031308 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

#[test]
fn with_one_sample_the_truth_is_a_plain_render_with_its_settings() {
    let ctx = common::gpu();
    let (world, source, config, camera, walker) = field(&ctx);
    let mut plain = Scene::with_source(
        &ctx,
        world.clone(),
        source.clone(),
        SIZE.0,
        SIZE.1,
        config.clone(),
    )
    .unwrap();
    assert!(
        plain
            .warm_up(&ctx, &camera, std::time::Duration::from_secs(60))
            .unwrap()
    );
    let stats = plain
        .render_frame(&ctx, &camera, TIME_S, Some(walker))
        .unwrap();
    assert!(stats.grass.drawn[0] > 0, "no blades drawn: {stats:?}");
    // Every tile high LOD.
    assert_eq!(stats.grass.drawn[1], 0, "{stats:?}");
    let expected = plain.read_image(&ctx).unwrap();
    drop(plain);
    let mut t = Truth::with_config(&ctx, world, source, SIZE, 1, config).unwrap();
    let got = t.render(&ctx, &camera, TIME_S, Some(walker)).unwrap();
    assert!(got == expected, "a 1x1 truth differs from the plain render");
}

#[test]
fn the_truth_is_the_linear_mean_of_jittered_sub_samples_and_steps_only_once_a_time() {
    let ctx = common::gpu();
    let (mut t, camera, walker) = truth(&ctx, 2);
    let samples = t
        .render_samples(&ctx, &camera, TIME_S, Some(walker))
        .unwrap();
    assert_eq!(samples.len(), 4);
    // The jitter moves the image: every sub-sample differs from the others.
    for i in 0..samples.len() {
        for j in i + 1..samples.len() {
            assert!(
                samples[i] != samples[j],
                "sub-samples {i} and {j} are the same"
            );
        }
    }
    // At the same time nothing advances: the truth drawn again is the mean of those very
    // sub-samples, taken independently here in linear light.
    let got = t.render(&ctx, &camera, TIME_S, Some(walker)).unwrap();
    let mut worst = 0i32;
    let mut srgb_mean_differs = 0;
    for (i, p) in got.pixels().enumerate() {
        for c in 0..3 {
            let values: Vec<u8> = samples.iter().map(|s| s.as_raw()[4 * i + c]).collect();
            let linear = values.iter().map(|&v| decode(v)).sum::<f64>() / 4.0;
            worst = worst.max((i32::from(p[c]) - i32::from(encode(linear))).abs());
            let naive = (values.iter().map(|&v| f64::from(v)).sum::<f64>() / 4.0).round() as u8;
            if naive.abs_diff(p[c]) > 2 {
                srgb_mean_differs += 1;
            }
        }
    }
    assert!(worst <= 1, "the truth is off the linear mean by {worst}");
    // ...and not the mean of the sRGB codes, which blade edges tell apart.
    assert!(srgb_mean_differs > 20, "{srgb_mean_differs} channels");
    assert!(
        t.render(&ctx, &camera, TIME_S, Some(walker)).unwrap() == got,
        "the truth at the same time changed"
    );
}

#[test]
fn a_half_covered_edge_averages_in_linear_light() {
    let black = image::RgbaImage::from_pixel(4, 4, image::Rgba([0, 0, 0, 255]));
    let white = image::RgbaImage::from_pixel(4, 4, image::Rgba([255, 255, 255, 255]));
    let mean = truth::mean_linear(&[black.clone(), white.clone(), black, white]).unwrap();
    assert!(
        mean.pixels().all(|p| p.0 == [188, 188, 188, 255]),
        "{mean:?}"
    );
}

#[test]
fn a_bad_factor_is_refused_naming_the_option_and_its_range() {
    let ctx = common::gpu();
    for k in [0, 9] {
        let (world, source, config, _, _) = field(&ctx);
        let e = match Truth::with_config(&ctx, world, source, SIZE, k, config) {
            Ok(_) => panic!("K = {k} accepted"),
            Err(e) => format!("{e:#}"),
        };
        assert!(
            e.contains(&format!("--truth {k}")) && e.contains("1..=8"),
            "{e}"
        );
    }
    let tmp = tempfile::tempdir().unwrap();
    for k in ["0", "9"] {
        let out = Command::new(env!("CARGO_BIN_EXE_verdant"))
            .args(["fly", "--truth", k, "--out", "t"])
            .current_dir(tmp.path())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success());
        assert!(err.contains("--truth") && err.contains("1..=8"), "{err}");
        assert!(!tmp.path().join("t").exists());
    }
    // Options the truth sets itself are refused with it, before anything runs.
    for extra in [
        &["--aa", "taa"][..],
        &["--taa-samples", "8"],
        &["--grass-segments", "1,1,1"],
        &["--grass-view-m", "20"],
        &["--tree-min-keep", "1"],
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_verdant"))
            .args(["fly", "--truth", "1", "--out", "t"])
            .args(extra)
            .current_dir(tmp.path())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{extra:?}: {err}");
        assert!(
            err.contains(&format!("{} does not apply to --truth", extra[0])),
            "{extra:?}: {err}"
        );
        assert!(!tmp.path().join("t").exists());
    }
}

#[test]
fn fly_writes_the_paths_frames_as_the_truth() {
    let tmp = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args([
            "fly",
            common::default_world().to_str().unwrap(),
            "--truth",
            "1",
            "--frames",
            "2",
            "--size",
            "48x32",
            "--grass-spacing-m",
            "1",
            "--out",
            "t",
        ])
        .current_dir(tmp.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "fly --truth failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let dir = tmp.path().join("t");
    for f in ["frame_00000.png", "frame_00001.png", "truth.json"] {
        assert!(dir.join(f).is_file(), "{f} missing");
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json")).unwrap()).unwrap();
    assert_eq!(report["k"], 1);
    assert_eq!(report["frames"].as_array().unwrap().len(), 2);
    assert_eq!(report["failed_loads"], 0);
    let img = image::open(dir.join("frame_00000.png")).unwrap();
    assert_eq!((img.width(), img.height()), (48, 32));
    // Standard error is no terminal here: the frames are logged as they are drawn.
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("truth: 2/2 frames"), "{stderr}");
}
