//! `Renderer::new` refuses the settings that it and `prepare` rely on before building anything:
//! each of these was accepted and then panicked in `new` or `prepare`, or left frames that never
//! finished. No frame is drawn here: the error is all there is to see.

mod common;

use verdant::lod::MAX_GRASS_LEVELS_UP;
use verdant::world::World;
use verdant::{Renderer, RendererConfig, RendererError, RendererOptions};

fn world() -> World {
    World::open(&common::default_world()).unwrap()
}

/// `Renderer::new` for the default world with `tweak`ed settings (small targets).
fn new_with(tweak: impl FnOnce(&World, &mut RendererConfig)) -> Result<Renderer, RendererError> {
    let gpu = common::gpu();
    let world = world();
    let mut options = RendererOptions::new(
        &world,
        wgpu::TextureFormat::Rgba16Float,
        wgpu::TextureFormat::Depth32Float,
        64,
        36,
    );
    tweak(&world, &mut options.config);
    Renderer::new(&gpu.device, &gpu.queue, world, options)
}

/// `new` fails with a `ConfigError` naming `field`, whose text holds `range`.
fn assert_refused(result: Result<Renderer, RendererError>, field: &str, range: &str) {
    match result {
        Err(RendererError::Config(c)) => {
            assert_eq!(c.field, field, "{c}");
            let text = c.to_string();
            assert!(text.contains(range), "{text}");
        }
        Err(e) => panic!("another error than {field}'s range: {e}"),
        Ok(_) => panic!("{field} out of range was accepted"),
    }
}

#[test]
fn derives_a_frame_beyond_the_adapters_layers_make_a_renderer() {
    // Was: the derivation's staging texture of 2049 layers, past the adapter's limit, panicked.
    // A frame derives at most as many tiles as the atlas has slots: its textures have as many.
    for derives in [2049, u32::MAX] {
        new_with(|_, c| c.service.derives_per_frame = derives)
            .unwrap_or_else(|e| panic!("derives_per_frame {derives}: {e}"));
    }
}

#[test]
fn plant_and_tree_pools_beyond_what_a_pool_binds_are_refused() {
    // Was: an overflow rounding the regions' capacity up.
    let most = verdant::plants::renderer::max_capacity(1);
    let range = format!("in 1..={most} instances");
    assert_refused(
        new_with(|_, c| c.plants.capacity = u32::MAX),
        "plants.capacity",
        &range,
    );
    assert_refused(
        new_with(|w, c| {
            let mut t = c.tree_settings(w).unwrap();
            t.capacity = u32::MAX;
            c.trees = Some(t);
        }),
        "trees.capacity",
        &range,
    );
}

#[test]
fn grass_levels_the_world_has_not_or_far_too_coarse_are_refused() {
    // Was: level 200 panicked in the first frame's `prepare`, level 0 (12.8 km grass tiles)
    // left frames that never finished.
    for level in [200, 9, 0] {
        assert_refused(
            new_with(|_, c| c.grass_rings.as_mut().unwrap().level = level),
            "grass_rings.level",
            "in 6..=8",
        );
    }
}

#[test]
fn the_coarsest_grass_level_allowed_makes_a_renderer() {
    let r = new_with(|w, c| {
        c.grass_rings.as_mut().unwrap().level =
            w.manifest.pyramid.max_level() - MAX_GRASS_LEVELS_UP;
    });
    assert!(r.is_ok(), "{:?}", r.err());
}

#[test]
fn plant_cells_out_of_range_are_refused() {
    // Was: 0 a misleading error about the world's tiles, 1e-3 frames that never finished,
    // NaN accepted.
    for cell in [0.0, 1e-3, f32::NAN] {
        assert_refused(
            new_with(|_, c| c.plants.cell_m = cell),
            "plants.cell_m",
            "0.5 to 64 m",
        );
    }
}
