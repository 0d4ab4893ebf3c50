//! GPU tests of the terrain renderer on whatever adapter there is (lavapipe in CI).

mod common;

use std::time::Duration;

use verdant::RendererConfig;
use verdant::camera::sample_path;
use verdant::tools::Scene;
use verdant::world::World;

#[test]
fn default_world_matches_reference_image() {
    let ctx = common::gpu();
    let world = World::open(&common::default_world()).expect("open the default world");
    let path = world
        .manifest
        .path("overview")
        .expect("the default world has an overview path")
        .clone();
    let mut config = RendererConfig::for_world(&world);
    // The reference is the scene's shading, one sample at each pixel's centre (the temporal
    // method's own tests are in tests/aa.rs).
    config.aa = verdant::aa::AntiAliasing::Off;
    let mut scene = Scene::new(&ctx, world, 256, 144, config).expect("build the scene");
    let t = path.keys[0].t_s + 0.3 * (path.keys[path.keys.len() - 1].t_s - path.keys[0].t_s);
    let camera = sample_path(&path, t);
    assert!(
        scene
            .warm_up(&ctx, &camera, Duration::from_secs(60))
            .unwrap(),
        "tiles did not load"
    );
    let stats = scene.render(&ctx, &camera).unwrap();
    assert_eq!(stats.residency.resident, stats.residency.desired);
    assert!(stats.tiles_drawn > 0, "no terrain tiles drawn");
    let image = scene.read_image(&ctx).expect("read back the frame");
    // Bounds set on llvmpipe (Mesa 22.3, 2 cores), where repeated runs give the same image;
    // other adapters differ by rasterisation and float details well inside them.
    common::check_reference("terrain_overview", &image, 0.01, 0.10);
}

#[test]
fn frames_show_lit_terrain_below_a_sky() {
    let ctx = common::gpu();
    let world = World::open(&common::default_world()).expect("open the default world");
    let path = world
        .manifest
        .path("overview")
        .expect("the default world has an overview path")
        .clone();
    let config = RendererConfig::for_world(&world);
    let mut scene = Scene::new(&ctx, world, 160, 90, config).expect("build the scene");
    let camera = sample_path(&path, path.keys[0].t_s);
    scene
        .warm_up(&ctx, &camera, Duration::from_secs(60))
        .unwrap();
    scene.render(&ctx, &camera).unwrap();
    let image = scene.read_image(&ctx).unwrap();
    // The camera looks slightly down: the bottom row is terrain, which is darker and less blue
    // than the sky; and the terrain is not flat-coloured (it is lit by a directional sun).
    let bottom: Vec<[u8; 4]> = (0..160).map(|x| image.get_pixel(x, 89).0).collect();
    let distinct: std::collections::HashSet<[u8; 4]> = bottom.iter().copied().collect();
    assert!(
        distinct.len() > 10,
        "terrain looks flat: {} colours on the bottom row",
        distinct.len()
    );
    let mean_blue_minus_red = |px: &[[u8; 4]]| {
        px.iter()
            .map(|p| f64::from(p[2]) - f64::from(p[0]))
            .sum::<f64>()
            / px.len() as f64
    };
    let top: Vec<[u8; 4]> = (0..160).map(|x| image.get_pixel(x, 0).0).collect();
    assert!(
        mean_blue_minus_red(&top) > mean_blue_minus_red(&bottom) + 10.0,
        "expected a blue sky above the terrain"
    );
}

/// A source whose stored level-2 tiles take seconds to load.
struct SlowLevel2 {
    world: World,
    delay: Duration,
}

impl verdant::stream::TileSource for SlowLevel2 {
    fn load(
        &self,
        id: verdant::world::TileId,
    ) -> Result<verdant::world::TileData, verdant::world::WorldError> {
        if id.level == 2 {
            std::thread::sleep(self.delay);
        }
        self.world.load_tile(id)
    }
}

#[test]
fn slow_loads_never_stall_the_frame_loop_and_leave_no_hole() {
    let ctx = common::gpu();
    let world = World::open(&common::default_world()).expect("open the default world");
    let path = world
        .manifest
        .path("low")
        .expect("the default world has a low path")
        .clone();
    let source = std::sync::Arc::new(SlowLevel2 {
        world: world.clone(),
        delay: Duration::from_secs(20),
    });
    let config = RendererConfig::for_world(&world);
    let mut scene =
        Scene::with_source(&ctx, world, source, 96, 54, config).expect("build the scene");
    let camera = sample_path(&path, path.keys[0].t_s);
    let start = std::time::Instant::now();
    let mut frames = 0;
    let mut drawn_from_ancestors = 0;
    // While the first slow loads are still running (each takes 20 s), frames keep coming, fully
    // covered: five frames well inside the first load's time, however slow the machine.
    while start.elapsed() < Duration::from_secs(15) {
        let stats = scene.render(&ctx, &camera).unwrap();
        assert_eq!(stats.residency.holes, 0);
        assert!(stats.tiles_drawn > 0);
        drawn_from_ancestors = drawn_from_ancestors.max(stats.residency.from_ancestor);
        frames += 1;
        if frames >= 5 {
            break;
        }
    }
    assert!(
        frames >= 5,
        "only {frames} frames while the loads were pending: the frame loop waited"
    );
    assert!(start.elapsed() < Duration::from_secs(15));
    assert!(
        drawn_from_ancestors > 0,
        "tiles waiting for slow loads should be drawn from ancestors"
    );
    assert!(scene.service().stats().stream.in_flight > 0);
}

#[test]
fn grassy_meadow_matches_reference_image() {
    let ctx = common::gpu();
    let world = World::open(&common::default_world()).expect("open the default world");
    let path = world
        .manifest
        .path("meadow")
        .expect("the default world has a meadow path")
        .clone();
    let mut config = RendererConfig::for_world(&world);
    // The reference is the scene's shading, one sample at each pixel's centre (the temporal
    // method's own tests are in tests/aa.rs).
    config.aa = verdant::aa::AntiAliasing::Off;
    let mut scene = Scene::new(&ctx, world, 256, 144, config).expect("build the scene");
    let camera = sample_path(&path, path.keys[0].t_s + 0.4 * path.duration_s);
    assert!(
        scene
            .warm_up(&ctx, &camera, Duration::from_secs(60))
            .unwrap(),
        "tiles did not load"
    );
    let stats = scene.render(&ctx, &camera).unwrap();
    assert!(
        stats.grass.drawn[0] > 1000,
        "too few high-LOD blades: {:?}",
        stats.grass
    );
    // The low ring is the band from the high ring's 50 m to the view distance's 67 m: in this
    // view a strip of blades at twice the spacing before the far field.
    assert!(
        stats.grass.drawn[1] > 100,
        "too few low-LOD blades: {:?}",
        stats.grass
    );
    assert_eq!(stats.grass.overflow, [0, 0]);
    let image = scene.read_image(&ctx).expect("read back the frame");
    // Bounds set on llvmpipe (Mesa 22.3, 2 cores): repeated runs give the same image.
    common::check_reference("grass_meadow", &image, 0.01, 0.10);
}

fn meadow_in_wind(scene_name: &str) -> image::RgbaImage {
    let ctx = common::gpu();
    let world = World::open(&common::default_world()).expect("open the default world");
    let path = world
        .manifest
        .path("meadow")
        .expect("the default world has a meadow path")
        .clone();
    let mut config = RendererConfig::for_world(&world);
    config.wind_scene = Some(scene_name.to_owned());
    // One sample at each pixel's centre, as the references were drawn.
    config.aa = verdant::aa::AntiAliasing::Off;
    let mut scene = Scene::new(&ctx, world, 256, 144, config).expect("build the scene");
    let camera = sample_path(&path, path.keys[0].t_s + 0.6 * path.duration_s);
    assert!(
        scene
            .warm_up(&ctx, &camera, Duration::from_secs(60))
            .unwrap()
    );
    // A few frames of wind, so that the sway has moved from its start.
    for k in 0..4 {
        scene
            .render_at(&ctx, &camera, 12.0 + f64::from(k) / 30.0)
            .unwrap();
    }
    scene.read_image(&ctx).unwrap()
}

#[test]
fn calm_and_storm_match_reference_images_and_differ() {
    let calm = meadow_in_wind("calm");
    let storm = meadow_in_wind("storm");
    // Bounds set on llvmpipe (Mesa 22.3, 2 cores): repeated runs give the same image.
    common::check_reference("wind_calm", &calm, 0.01, 0.10);
    common::check_reference("wind_storm", &storm, 0.01, 0.10);
    let to_rgb = |i: &image::RgbaImage| image::DynamicImage::ImageRgba8(i.clone()).to_rgb8();
    let diff = verdant::tools::metrics::flip_compare(&to_rgb(&calm), &to_rgb(&storm)).unwrap();
    assert!(
        diff.mean > 0.02,
        "a storm should visibly bend the grass: FLIP {}",
        diff.mean
    );
}
