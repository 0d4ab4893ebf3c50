//! The decoders under a deterministic mutation loop: tile files (EXR heights, PNG type and
//! density maps), the DEM with its sidecar, and `world.toml`. A decoder must refuse a mutated
//! input or return values inside the format's ranges (`verdant::world::fuzz`); nothing may
//! panic. The suite runs a few thousand inputs per target; `VERDANT_FUZZ_ITERATIONS=1000000`
//! runs a million.

mod common;

use verdant::world::fuzz::{Mutator, TileCheck, check_dem, check_manifest};
use verdant::world::{Pyramid, ReadOptions, TileData, TileFile, TileId, tile_path, write_tile};

fn iterations() -> usize {
    std::env::var("VERDANT_FUZZ_ITERATIONS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(3000)
}

/// Runs `check` on `iterations()` mutations of the seeds; returns how many were accepted.
fn fuzz(name: &str, seeds: &[Vec<u8>], mut check: impl FnMut(&[u8]) -> bool) -> usize {
    let mut m = Mutator::new(0x5eed ^ name.len() as u64);
    for s in seeds {
        assert!(check(s), "{name}: a valid seed was refused");
    }
    let n = iterations();
    let start = std::time::Instant::now();
    let mut accepted = 0;
    for i in 0..n {
        let seed = &seeds[i % seeds.len()];
        let other = &seeds[(i + 1) % seeds.len()];
        let input = m.mutate(seed, other);
        if check(&input) {
            accepted += 1;
        }
    }
    eprintln!(
        "{name}: {n} inputs, {accepted} accepted, {:.1} s",
        start.elapsed().as_secs_f64()
    );
    accepted
}

/// The three files of a small tile (13 samples a side) with heights in 0..=100 m and grass
/// types 0..=2.
fn tile_seeds() -> (TileCheck, [Vec<u8>; 3]) {
    let dir = tempfile::tempdir().unwrap();
    let pyramid = Pyramid {
        root_tile_size_m: 80.0,
        root_tiles: [1, 1],
        tile_cells: 8,
        border: 2,
        stored_levels: 1,
        derived_levels: 0,
    };
    let size = pyramid.samples_per_side();
    let n = (size * size) as usize;
    let id = TileId::new(0, 0, 0);
    let tile = TileData {
        id,
        size,
        heights: (0..n).map(|k| (k % 101) as f32).collect(),
        grass_type: (0..n).map(|k| (k % 3) as u8).collect(),
        density: (0..n).map(|k| (k * 7 % 256) as u8).collect(),
        material: Vec::new(),
    };
    write_tile(dir.path(), &pyramid, &tile).unwrap();
    let read = |kind| std::fs::read(tile_path(dir.path(), id, kind)).unwrap();
    let check = TileCheck {
        size,
        options: ReadOptions {
            height_range_m: [0.0, 100.0],
            grass_type_count: 3,
            materials: false,
            bake_id: None,
        },
    };
    (
        check,
        [
            read(TileFile::Height),
            read(TileFile::Type),
            read(TileFile::Density),
        ],
    )
}

#[test]
fn tile_height_exr_survives_mutation() {
    let (check, [heights, _, _]) = tile_seeds();
    // A second seed of other heights, for splices.
    fuzz("height.exr", &[heights.clone(), heights], |b| {
        check.heights(b)
    });
}

#[test]
fn tile_type_and_density_png_survive_mutation() {
    let (check, [_, types, density]) = tile_seeds();
    fuzz("type.png", std::slice::from_ref(&types), |b| {
        check.grass_types(b)
    });
    fuzz("density.png", &[density, types], |b| check.density(b));
}

/// A small DEM's PNG and sidecar, and a folder to write mutations into.
fn dem_seeds() -> (tempfile::TempDir, Vec<u8>, Vec<u8>) {
    let dir = tempfile::tempdir().unwrap();
    let png = common::write_dem(
        dir.path(),
        "seed",
        [9, 7],
        [10.0, 12.0],
        [-20.0, 0.5],
        |x, y| x * 0.3 + y * 0.1,
    );
    let png = std::fs::read(png).unwrap();
    let sidecar = std::fs::read(dir.path().join("seed.json")).unwrap();
    (dir, png, sidecar)
}

#[test]
fn dem_png_survives_mutation() {
    let (dir, png, sidecar) = dem_seeds();
    fuzz("DEM png", &[png], |b| check_dem(dir.path(), b, &sidecar));
}

#[test]
fn dem_sidecar_survives_mutation() {
    let (dir, png, sidecar) = dem_seeds();
    fuzz("DEM sidecar", &[sidecar], |b| {
        check_dem(dir.path(), &png, b)
    });
}

const MANIFEST: &str = r#"
name = "fuzz"
extent_m = [900.0, 1000.0]
height_range_m = [-10.0, 500.0]

[pyramid]
root_tile_size_m = 512.0
root_tiles = [2, 2]
tile_cells = 16
border = 2
stored_levels = 2
derived_levels = 1

[[grass_types]]
name = "bare"
ground_color = [0.3, 0.3, 0.3]
base_color = [0.3, 0.3, 0.3]
tip_color = [0.3, 0.3, 0.3]
height_m = [0.0, 0.0]
width_m = [0.0, 0.0]
stiffness = 1.0

[[paths]]
name = "overview"
duration_s = 10.0
keys = [
    { t_s = 0.0, position_m = [10.0, 10.0, 600.0], yaw_deg = 45.0, pitch_deg = -10.0 },
    { t_s = 10.0, position_m = [800.0, 900.0, 600.0], yaw_deg = 45.0, pitch_deg = -10.0 },
]

[[wind_scenes]]
name = "storm"
ambient = { direction_deg = 30.0, speed_mps = 14.0, gustiness = 0.6 }

[grass_peak]
window_m = 50.0
short_m = 0.3
density = 1.5
"#;

#[test]
fn world_toml_survives_mutation() {
    let seeds = [MANIFEST.as_bytes().to_vec()];
    fuzz("world.toml", &seeds, check_manifest);
}
