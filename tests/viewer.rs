//! The viewer in a window on a virtual X display (Xvfb, started by `xvfb-run`, which `.ci/run`
//! installs), the embedding example, and what a crate that embeds verdant compiles.

mod common;

use std::path::PathBuf;
use std::process::Command;
use std::time::Duration;

use verdant::RendererConfig;
use verdant::camera::sample_path;
use verdant::tools::Scene;
use verdant::tools::metrics::flip_compare;
use verdant::world::World;

const SIZE: (u32, u32) = (256, 144);
const FRAMES: u32 = 12;

fn verdant_bin() -> &'static str {
    env!("CARGO_BIN_EXE_verdant")
}

/// The headless render of the viewer's first camera (the `overview` path's start, standing
/// still) after the same frames at the viewer's fixed 1/60 s step.
fn headless_view() -> image::RgbaImage {
    let ctx = common::gpu();
    let world = World::open(&common::default_world()).unwrap();
    let path = world.manifest.path("overview").unwrap().clone();
    let camera = sample_path(&path, path.keys[0].t_s);
    let config = RendererConfig::for_world(&world);
    let mut scene = Scene::new(&ctx, world, SIZE.0, SIZE.1, config).unwrap();
    scene
        .warm_up(&ctx, &camera, Duration::from_secs(30))
        .unwrap();
    for i in 1..=FRAMES {
        scene.render_at(&ctx, &camera, f64::from(i) / 60.0).unwrap();
    }
    scene.read_image(&ctx).unwrap()
}

#[test]
fn the_viewer_on_a_virtual_display_shows_what_the_headless_renderer_does() {
    let dir = tempfile::tempdir().unwrap();
    let shot = dir.path().join("view.png");
    let out = Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 640x480x24", verdant_bin(), "view"])
        .arg(common::default_world())
        .args(["--path", "overview", "--size", "256x144", "--frames"])
        .arg(FRAMES.to_string())
        .arg("--screenshot")
        .arg(&shot)
        .output()
        .expect("xvfb-run is needed for the viewer's test (Debian package xvfb)");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "verdant view failed: {}\n{stdout}\n{stderr}",
        out.status
    );
    assert!(stdout.contains(&format!("{FRAMES} frames")), "{stdout}");
    assert!(!stderr.contains("no frame drew any terrain"), "{stderr}");
    let viewer = image::open(&shot).expect("the screenshot").to_rgb8();
    let headless = image::DynamicImage::ImageRgba8(headless_view()).to_rgb8();
    let r = flip_compare(&headless, &viewer).unwrap();
    eprintln!(
        "viewer vs headless: FLIP mean {:.4}, p99 {:.4}",
        r.mean, r.p99
    );
    // Same renderer, camera and frame times; the window's format (BGRA, sRGB encoded in the
    // shader or on store) rounds within a code value. Bounds set on llvmpipe.
    if r.mean > 0.01 || r.p99 > 0.1 {
        let failures = common::failure_dir();
        std::fs::create_dir_all(&failures).unwrap();
        viewer.save(failures.join("viewer-actual.png")).unwrap();
        headless.save(failures.join("viewer-headless.png")).unwrap();
        panic!(
            "viewer and headless render differ: FLIP mean {:.4}, p99 {:.4} (images in {})",
            r.mean,
            r.p99,
            failures.display()
        );
    }
}

/// A view of a camera path entirely outside the world (40 km out of it) draws sky alone, and
/// says so as `fly` does, instead of writing its sky-only screenshot in silence.
#[test]
fn the_viewer_warns_when_no_frame_drew_terrain() {
    let dir = tempfile::tempdir().unwrap();
    let world = common::world_with_a_path_away(dir.path());
    let shot = dir.path().join("v.png");
    let out = Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 640x480x24", verdant_bin(), "view"])
        .arg(&world)
        .args(["--path", "away", "--size", "32x18", "--frames", "2"])
        .arg("--screenshot")
        .arg(&shot)
        .output()
        .expect("xvfb-run is needed for the viewer's test (Debian package xvfb)");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "verdant view failed: {stderr}");
    assert!(shot.is_file());
    assert!(stderr.contains("no frame drew any terrain"), "{stderr}");
    assert!(stderr.contains("\"away\""), "{stderr}");
}

#[test]
fn the_viewer_without_a_display_says_so_and_suggests_fly() {
    let out = Command::new(verdant_bin())
        .arg("view")
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("no display") && stderr.contains("verdant fly"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
}

fn example_bin(name: &str) -> PathBuf {
    // Test binaries live in target/<profile>/deps, examples in target/<profile>/examples.
    let exe = std::env::current_exe().unwrap();
    let profile_dir = exe.parent().and_then(|d| d.parent()).unwrap();
    profile_dir.join("examples").join(name)
}

#[test]
fn the_embedding_example_renders_its_reference() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("embed.png");
    let bin = example_bin("embed");
    let out = Command::new(&bin)
        .arg(&png)
        .arg("256x144")
        .output()
        .unwrap_or_else(|e| panic!("cannot run {} ({e}): cargo test builds it", bin.display()));
    assert!(
        out.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let image = image::open(&png).unwrap().to_rgba8();
    // Bounds set on llvmpipe (Mesa 22.3): the blades' wind makes small differences only.
    common::check_reference("embed", &image, 0.02, 0.2);
}

#[test]
fn a_crate_without_default_features_compiles_no_tools() {
    let out = Command::new(env!("CARGO"))
        .current_dir(common::root())
        .args([
            "tree",
            "--offline",
            "--no-default-features",
            "--edges",
            "normal",
            "--prefix",
            "none",
            "--format",
            "{p}",
        ])
        .output()
        .expect("run cargo tree");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("wgpu v"), "{text}");
    for tool in [
        "clap",
        "indicatif",
        "plotters",
        "nv-flip",
        "winit",
        "anyhow",
        "env_logger",
        "httpdate",
    ] {
        assert!(
            !text.lines().any(|l| l.starts_with(&format!("{tool} v"))),
            "{tool} is compiled without the cli feature"
        );
    }
    // With the default features, the tools are there.
    let full = Command::new(env!("CARGO"))
        .current_dir(common::root())
        .args([
            "tree",
            "--offline",
            "--edges",
            "normal",
            "--prefix",
            "none",
            "--format",
            "{p}",
        ])
        .output()
        .unwrap();
    let full = String::from_utf8_lossy(&full.stdout);
    assert!(full.lines().any(|l| l.starts_with("clap v")), "{full}");
}
