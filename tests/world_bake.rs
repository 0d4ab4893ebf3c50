//! The baker on synthetic DEMs: heights match the analytic landscape, tiles meet without seams
//! at every level, cliffs stay bare, the bake is deterministic, and bad DEMs are refused with
//! errors that name the file.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use common::{Terrain, read_all_files, write_dem, write_sidecar};
use glam::DVec2;
use verdant::bake::{BakeOptions, BakeStage, bake};
use verdant::world::{Dem, TileId, WorldError};

/// The analytic landscape: rolling hills on a gentle slope, 118..=381 m.
fn hills(x: f64, y: f64) -> f64 {
    200.0 + 80.0 * (x / 300.0).sin() * (y / 400.0).cos() + 0.05 * x
}

/// A 300 m wall (79 degrees) between x = 800 m and x = 860 m, on gently rolling ground.
fn wall(x: f64, y: f64) -> f64 {
    let ground = 100.0 + 5.0 * (y / 200.0).sin();
    ground + 300.0 * ((x - 800.0) / 60.0).clamp(0.0, 1.0)
}

const DEM_SIZE: [u32; 2] = [200, 150];
const DEM_CELLS: [f64; 2] = [10.0, 13.0];
/// Heights are stored in centimetres.
const DEM_SCALE: [f64; 2] = [0.0, 0.01];

/// Largest difference allowed between baked heights and the analytic function: Catmull-Rom
/// interpolation of these hills (wavelength about 1.9 km, cells of 10 m x 13 m) is good to about
/// a centimetre, and the DEM rounds to half a centimetre.
const HEIGHT_TOLERANCE_M: f64 = 0.03;

fn small_bake(dir: &Path, dem: PathBuf, name: &str) -> PathBuf {
    let out = dir.join(name);
    let opts = BakeOptions {
        dem,
        out: out.clone(),
        name: Some(name.into()),
        cell_size_m: Some(20.0),
        tile_cells: 16,
        stored_levels: 2,
        seed: 7,
        ..Default::default()
    };
    bake(&opts, &mut |_, _, _| {}).unwrap();
    out
}

fn hills_world(dir: &Path) -> PathBuf {
    let dem = write_dem(dir, "hills", DEM_SIZE, DEM_CELLS, DEM_SCALE, hills);
    small_bake(dir, dem, "hills")
}

#[test]
fn baked_heights_match_the_analytic_function() {
    let dir = tempfile::tempdir().unwrap();
    let terrain = Terrain::load(&hills_world(dir.path()));
    let m = &terrain.world.manifest;
    assert_eq!(m.extent_m, [1990.0, 1937.0]);
    assert_eq!(m.pyramid.root_tile_size_m, 640.0);
    assert_eq!(m.pyramid.root_tiles, [4, 4]);
    assert_eq!(terrain.tiles.len(), 16 + 64);

    let mut checked = 0;
    let mut worst: f64 = 0.0;
    for (id, tile) in &terrain.tiles {
        for j in 0..tile.size {
            for i in 0..tile.size {
                let p = m.pyramid.sample_position(*id, i, j);
                if p.x < 0.0 || p.y < 0.0 || p.x > m.extent_m[0] || p.y > m.extent_m[1] {
                    continue;
                }
                let err = (f64::from(tile.height_at(i, j)) - hills(p.x, p.y)).abs();
                worst = worst.max(err);
                checked += 1;
            }
        }
    }
    assert!(checked > 10_000);
    assert!(
        worst <= HEIGHT_TOLERANCE_M,
        "worst height error {worst} m over {checked} samples"
    );
}

#[test]
fn beyond_the_dem_the_edge_is_repeated() {
    let dir = tempfile::tempdir().unwrap();
    let terrain = Terrain::load(&hills_world(dir.path()));
    let m = &terrain.world.manifest;
    // North of the data area (y > 1937 m), heights repeat the northern edge's: every sample
    // from the first one beyond the edge (y = 1940 m, with 20 m cells) holds the same height.
    let cell = m.pyramid.cell_size_m(1);
    let [ex, ey] = m.extent_m.map(|e| (e / cell).ceil() * cell);
    for x in [0.0, 300.0, 1000.0, 1980.0] {
        let edge = terrain.height(DVec2::new(x, ey));
        for y in [ey + 20.0, ey + 200.0, 2500.0] {
            assert_eq!(terrain.height(DVec2::new(x, y)), edge);
        }
    }
    let edge = terrain.height(DVec2::new(ex, 500.0));
    assert_eq!(terrain.height(DVec2::new(2400.0, 500.0)), edge);
}

/// Every pair of neighbours at every level shares its edge and border samples bit for bit, and
/// every coarse sample equals the fine sample at the same position.
#[test]
fn tiles_meet_without_seams() {
    let dir = tempfile::tempdir().unwrap();
    let terrain = Terrain::load(&hills_world(dir.path()));
    let p = &terrain.world.manifest.pyramid;
    let (size, cells, b) = (p.samples_per_side(), p.tile_cells, p.border);
    let same = |a: &verdant::world::TileData, ai, aj, c: &verdant::world::TileData, ci, cj| {
        let (ka, kc) = (a.index(ai, aj), c.index(ci, cj));
        assert_eq!(
            a.heights[ka].to_bits(),
            c.heights[kc].to_bits(),
            "{:?} ({ai},{aj}) vs {:?} ({ci},{cj})",
            a.id,
            c.id
        );
        assert_eq!(a.grass_type[ka], c.grass_type[kc]);
        assert_eq!(a.density[ka], c.density[kc]);
    };
    let mut pairs = 0;
    for (id, tile) in &terrain.tiles {
        let [_, east, _, north] = p.neighbours(*id);
        if let Some(e) = east {
            let other = &terrain.tiles[&e];
            for j in 0..size {
                for k in 0..=2 * b {
                    same(tile, cells + k, j, other, k, j);
                }
            }
            pairs += 1;
        }
        if let Some(n) = north {
            let other = &terrain.tiles[&n];
            for i in 0..size {
                for k in 0..=2 * b {
                    same(tile, i, cells + k, other, i, k);
                }
            }
            pairs += 1;
        }
        if id.level + 1 < p.stored_levels {
            for child in id.children() {
                let c = &terrain.tiles[&child];
                for j in 0..size {
                    for i in 0..size {
                        // Global sample index at the parent's level, doubled at the child's.
                        let gx = 2 * (i64::from(id.x * cells + i) - i64::from(b));
                        let gy = 2 * (i64::from(id.y * cells + j) - i64::from(b));
                        let ci = gx - i64::from(child.x * cells) + i64::from(b);
                        let cj = gy - i64::from(child.y * cells) + i64::from(b);
                        if (0..i64::from(size)).contains(&ci) && (0..i64::from(size)).contains(&cj)
                        {
                            same(tile, i, j, c, ci as u32, cj as u32);
                        }
                    }
                }
            }
        }
    }
    // 4x4 at level 0 and 8x8 at level 1: 2*4*3 + 2*8*7 neighbour pairs.
    assert_eq!(pairs, 24 + 112);
}

#[test]
fn cliffs_are_bare_and_flat_ground_is_grassy() {
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path(), "wall", DEM_SIZE, DEM_CELLS, DEM_SCALE, wall);
    let terrain = Terrain::load(&small_bake(dir.path(), dem, "wall"));
    let p = &terrain.world.manifest.pyramid;
    let (mut on_wall, mut grassy) = (0, 0);
    for (id, tile) in &terrain.tiles {
        for j in 0..tile.size {
            for i in 0..tile.size {
                let pos = p.sample_position(*id, i, j);
                let k = tile.index(i, j);
                if (810.0..=850.0).contains(&pos.x) {
                    assert_eq!(tile.grass_type[k], 0, "{id:?} ({i},{j}) at {pos}");
                    assert_eq!(tile.density[k], 0, "{id:?} ({i},{j}) at {pos}");
                    on_wall += 1;
                } else if pos.x < 700.0 && tile.grass_type[k] != 0 {
                    assert!(tile.density[k] > 0);
                    grassy += 1;
                }
            }
        }
    }
    assert!(on_wall > 100, "{on_wall} samples on the wall");
    assert!(grassy > 1000, "{grassy} grassy samples on flat ground");
}

#[test]
fn bake_is_deterministic_and_leaves_no_temporary_files() {
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path(), "hills", DEM_SIZE, DEM_CELLS, DEM_SCALE, hills);
    // An empty output folder is baked into.
    std::fs::create_dir_all(dir.path().join("a")).unwrap();
    let a = small_bake(dir.path(), dem.clone(), "a");
    let b = small_bake(dir.path(), dem, "b");
    let mut files_a = read_all_files(&a);
    let files_b = read_all_files(&b);
    // The manifests differ only in the name.
    let manifest_a = files_a.remove(Path::new("world.toml")).unwrap();
    let mut files_b = files_b;
    let manifest_b = files_b.remove(Path::new("world.toml")).unwrap();
    assert_eq!(
        String::from_utf8(manifest_a)
            .unwrap()
            .replacen("name = \"a\"", "name = \"b\"", 1),
        String::from_utf8(manifest_b).unwrap()
    );
    assert_eq!(files_a.len(), 3 * 80);
    assert!(
        files_a
            .keys()
            .all(|p| !p.to_string_lossy().contains(".tmp"))
    );
    assert!(files_a == files_b, "tile files differ between two bakes");
}

/// Every file a bake writes carries its own name and the bake's id (the manifest's
/// `bake_id`), and the world reads back through those checks; a bake of other inputs (another
/// seed) has another id.
/// A DEM rewritten while the bake runs (read in windows, a bake of a large DEM reads it to the
/// end) is refused before anything is published, naming it: the world mixed its two versions
/// under the first one's id, and said nothing.
#[test]
fn a_dem_changed_during_the_bake_is_refused_and_nothing_is_published() {
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path(), "hills", DEM_SIZE, DEM_CELLS, DEM_SCALE, hills);
    let out = dir.path().join("w");
    let opts = BakeOptions {
        dem: dem.clone(),
        out: out.clone(),
        cell_size_m: Some(20.0),
        tile_cells: 16,
        stored_levels: 2,
        ..Default::default()
    };
    let mut touched = false;
    let err = bake(&opts, &mut |stage, _, _| {
        if stage == BakeStage::WriteTiles && !touched {
            touched = true;
            // Other heights, and a later time, as a writer leaves the file.
            write_dem(dir.path(), "hills", DEM_SIZE, DEM_CELLS, DEM_SCALE, wall);
            let f = std::fs::File::options().write(true).open(&dem).unwrap();
            f.set_modified(std::time::SystemTime::now() + std::time::Duration::from_secs(10))
                .unwrap();
        }
    })
    .unwrap_err();
    assert!(touched);
    let text = err.to_string();
    assert!(
        text.contains("hills.png") && text.contains("changed while the bake read it"),
        "{text}"
    );
    assert!(!out.exists(), "nothing is published");
    // Once it is still, it bakes.
    bake(&opts, &mut |_, _, _| {}).unwrap();
}

#[test]
fn a_bake_stamps_every_tile_file_with_its_name_and_its_bake() {
    use verdant::world::format::{read_stamp, stamp};
    use verdant::world::{TileFile, World};
    let dir = tempfile::tempdir().unwrap();
    let world = World::open(&hills_world(dir.path())).unwrap();
    let id = world
        .manifest
        .bake_id_value()
        .expect("a baked world has a bake_id");
    for tile in world.stored_tiles() {
        for kind in TileFile::ALL {
            let bytes = std::fs::read(world.tile_path(tile, kind)).unwrap();
            assert_eq!(read_stamp(&bytes, kind), Some(stamp(tile, kind, id)));
        }
        world.load_tile(tile).unwrap();
    }
    let dem = dir.path().join("hills.png");
    let other = BakeOptions {
        dem,
        out: dir.path().join("other"),
        cell_size_m: Some(20.0),
        tile_cells: 16,
        stored_levels: 2,
        seed: 8,
        ..Default::default()
    };
    bake(&other, &mut |_, _, _| {}).unwrap();
    let other = World::open(&dir.path().join("other")).unwrap();
    assert!(other.manifest.bake_id.is_some());
    assert_ne!(other.manifest.bake_id, world.manifest.bake_id);

    // The same DEM with its sidecar's height scale doubled: other heights, another id.
    common::write_sidecar(dir.path(), "hills", DEM_SIZE, DEM_CELLS, [0.0, 0.02]);
    let scaled = small_bake(dir.path(), dir.path().join("hills.png"), "scaled");
    let scaled = World::open(&scaled).unwrap();
    assert_ne!(
        scaled.manifest.height_range_m,
        world.manifest.height_range_m
    );
    assert_ne!(scaled.manifest.bake_id, world.manifest.bake_id);
}

/// DEMs the paths were not designed for: a strip three cells wide, a patch of two by two, and
/// lidar-fine cells (5 cm, where the search for the wind scenes' tall grass once grew with the
/// inverse fourth power of the cell and took hours). Each bakes, and every key of every path
/// lies over the data area.
#[test]
fn small_narrow_and_fine_dems_get_paths_over_their_own_ground() {
    let dir = tempfile::tempdir().unwrap();
    for (name, size, cell) in [
        ("strip", [3, 1000], [25.0, 25.0]),
        ("patch", [2, 2], [25.0, 25.0]),
        ("lidar", [100, 100], [0.05, 0.05]),
    ] {
        let dem = write_dem(dir.path(), name, size, cell, DEM_SCALE, |x, y| {
            200.0 + 3.0 * (x / 7.0).sin() * (y / 11.0).cos()
        });
        let out = dir.path().join(format!("w_{name}"));
        let report = bake(
            &BakeOptions {
                dem,
                out: out.clone(),
                ..Default::default()
            },
            &mut |_, _, _| {},
        )
        .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(report.tiles_written > 0, "{name}");
        let m = verdant::world::Manifest::from_path(&out.join("world.toml")).unwrap();
        let [ex, ey] = m.extent_m;
        assert!(m.paths.len() >= 7, "{name}");
        for p in &m.paths {
            // The bake states each path's length as its keys span it.
            assert_eq!(p.duration_s, p.length_s(), "{name}: path {}", p.name);
            for k in &p.keys {
                let [x, y, _] = k.position_m;
                assert!(
                    (0.0..=ex).contains(&x) && (0.0..=ey).contains(&y),
                    "{name}: path {} has a key at {x},{y} outside 0..{ex} x 0..{ey}",
                    p.name
                );
            }
        }
    }
}

#[test]
fn camera_paths_clear_the_terrain() {
    let dir = tempfile::tempdir().unwrap();
    let terrain = Terrain::load(&hills_world(dir.path()));
    let m = &terrain.world.manifest;
    assert_eq!(m.paths[0].name, "tour", "the tour is the default path");
    let overview = terrain.clearances(m.path("overview").unwrap(), 50);
    assert!(overview.iter().all(|&c| c >= 50.0), "{overview:?}");
    let low = terrain.clearances(m.path("low").unwrap(), 50);
    assert!(low.iter().all(|&c| (30.0..=80.0).contains(&c)), "{low:?}");
    let heli = terrain.clearances(m.path("helicopter").unwrap(), 50);
    assert!(heli.iter().all(|&c| c >= 15.0), "{heli:?}");
    let wind = terrain.clearances(m.path("wind-tour").unwrap(), 50);
    assert!(wind.iter().all(|&c| c >= 5.0), "{wind:?}");
    let walker = terrain.clearances(m.path("walker").unwrap(), 50);
    assert!(walker.iter().all(|&c| c >= 1.0), "{walker:?}");
    for name in ["tour", "meadow"] {
        let c = terrain.clearances(m.path(name).unwrap(), 50);
        assert!(c.iter().all(|&c| c >= 1.0), "{name}: {c:?}");
        assert!(
            *c.last().unwrap() < 5.0,
            "{name} ends low over the ground: {c:?}"
        );
    }
}

/// The paths clear the ground the renderer draws near the camera (the finest derived level),
/// not only the stored grid's bilinear surface: between the samples of coarse cells the two
/// part by metres (by 45 m at 10 km cells, where the meadow glide flew underground and drew no
/// grass). A dome baked at 400 m cells, whose drawn ground rises up to 20 m above the bilinear.
#[test]
fn camera_paths_clear_the_drawn_ground_of_coarse_cells() {
    let dir = tempfile::tempdir().unwrap();
    let dome = |x: f64, y: f64| 300.0 - ((x - 1000.0).powi(2) + (y - 975.0).powi(2)) / 4000.0;
    let dem = write_dem(dir.path(), "dome", DEM_SIZE, DEM_CELLS, DEM_SCALE, dome);
    let out = dir.path().join("coarse");
    let opts = BakeOptions {
        dem,
        out: out.clone(),
        cell_size_m: Some(400.0),
        tile_cells: 16,
        stored_levels: 2,
        seed: 7,
        ..Default::default()
    };
    bake(&opts, &mut |_, _, _| {}).unwrap();
    let terrain = Terrain::load(&out);
    let m = &terrain.world.manifest;
    let lowest: Vec<(&str, f64, f64)> = [
        ("overview", 200.0),
        ("low", 30.0),
        ("helicopter", 15.0),
        ("wind-tour", 5.0),
        ("walker", 1.0),
        ("tour", 1.0),
        ("meadow", 1.0),
    ]
    .into_iter()
    .map(|(name, least)| {
        let c = terrain.drawn_clearances(m.path(name).unwrap(), 10);
        (name, least, c.into_iter().fold(f64::INFINITY, f64::min))
    })
    .collect();
    assert!(
        lowest.iter().all(|&(_, least, c)| c >= least),
        "(path, least, lowest clearance): {lowest:?}"
    );
    // Clear of the ground, and still low over it.
    let meadow = terrain.drawn_clearances(m.path("meadow").unwrap(), 10);
    assert!(meadow.iter().all(|&c| c < 5.0), "{meadow:?}");
}

#[test]
fn bake_into_a_non_empty_folder_is_refused_unless_replaced_as_a_whole() {
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path(), "hills", DEM_SIZE, DEM_CELLS, DEM_SCALE, hills);
    let out = dir.path().join("w");
    std::fs::create_dir_all(out.join("tiles/L5")).unwrap();
    std::fs::write(out.join("tiles/L5/0_0.height.exr"), "stale").unwrap();
    // An old manifest that no longer validates, but is a world's (it has a [pyramid] table),
    // with a plant type that does not read.
    let old = b"[pyramid]\nold = true\n\n[[plant_types]]\nname = 3\n";
    std::fs::write(out.join("world.toml"), old).unwrap();
    std::fs::create_dir_all(out.join("source")).unwrap();
    std::fs::write(out.join("source/notes.txt"), "keep me").unwrap();
    let mut opts = BakeOptions {
        dem,
        out: out.clone(),
        cell_size_m: Some(20.0),
        tile_cells: 16,
        stored_levels: 2,
        ..Default::default()
    };
    let err = bake(&opts, &mut |_, _, _| {}).unwrap_err();
    assert!(matches!(err, WorldError::OutputNotEmpty { .. }), "{err}");
    assert!(err.to_string().contains("--replace"), "{err}");
    assert_eq!(std::fs::read(out.join("world.toml")).unwrap(), old);
    // A bake that fails after its checks leaves the old folder as it was and no temporary one.
    opts.replace = true;
    let good_dem = opts.dem.clone();
    opts.dem = dir.path().join("missing.png");
    bake(&opts, &mut |_, _, _| {}).unwrap_err();
    assert_eq!(std::fs::read(out.join("world.toml")).unwrap(), old);
    opts.dem = good_dem;
    // This manifest is not one a bake can keep plants and paths of: told to replace it, the
    // bake says so, and writes a fresh manifest when told to.
    let err = bake(&opts, &mut |_, _, _| {}).unwrap_err();
    assert!(matches!(err, WorldError::Carry { .. }), "{err}");
    assert!(err.to_string().contains("--fresh-manifest"), "{err}");
    assert_eq!(std::fs::read(out.join("world.toml")).unwrap(), old);
    opts.fresh_manifest = true;
    // Told to replace it, the bake replaces the folder as a whole: nothing stale stays.
    let mut written_into_out = false;
    bake(&opts, &mut |stage, _, _| {
        if stage == BakeStage::WriteTiles {
            written_into_out |= out.join("tiles/L0").exists();
        }
    })
    .unwrap();
    assert!(
        !written_into_out,
        "tiles were written into the output folder in place"
    );
    assert!(!out.join("tiles/L5").exists(), "a stale tile was kept");
    // Files beside the world (a README, the source DEM) are kept.
    assert_eq!(
        std::fs::read_to_string(out.join("source/notes.txt")).unwrap(),
        "keep me"
    );
    verdant::world::World::open(&out).unwrap();
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        names.iter().all(|n| !n.starts_with('.')),
        "temporary folders left: {names:?}"
    );
}

#[test]
fn progress_reaches_every_stage() {
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path(), "hills", DEM_SIZE, DEM_CELLS, DEM_SCALE, hills);
    let mut last: BTreeMap<String, (u64, u64)> = BTreeMap::new();
    let opts = BakeOptions {
        dem,
        out: dir.path().join("w"),
        cell_size_m: Some(20.0),
        tile_cells: 16,
        stored_levels: 2,
        ..Default::default()
    };
    let report = bake(&opts, &mut |stage, done, total| {
        assert!(done <= total);
        last.insert(format!("{stage:?}"), (done, total));
    })
    .unwrap();
    assert_eq!(report.tiles_written, 80);
    assert_eq!(report.levels, 2);
    assert_eq!(last["WriteTiles"], (80, 80));
    for stage in [
        BakeStage::LoadDem,
        BakeStage::Resample,
        BakeStage::Paint,
        BakeStage::Paths,
        BakeStage::WriteManifest,
    ] {
        let (done, total) = last[&format!("{stage:?}")];
        assert_eq!(done, total, "{stage:?}");
    }
    // The world is named after its directory by default.
    assert_eq!(
        verdant::world::World::open(&dir.path().join("w"))
            .unwrap()
            .manifest
            .name,
        "w"
    );
}

#[test]
fn absurd_bake_options_are_refused_before_writing() {
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path(), "hills", DEM_SIZE, DEM_CELLS, DEM_SCALE, hills);
    let out = dir.path().join("w");
    // Each is blamed on the option, not on the world.toml that does not exist yet.
    for (tile_cells, stored_levels, cell, option) in [
        (100, 2, 20.0, "--tile-cells 100"),
        (3, 2, 20.0, "--tile-cells 3"),
        (16, 13, 20.0, "--levels 13"),
        (16, 2, 0.001, "--cell-size 0.001"),
        (16, 2, 1e-6, "--cell-size 0.000001"),
        (16, 2, -5.0, "--cell-size -5"),
        // Written short, not as 300 zeros.
        (16, 2, 1e-300, "--cell-size 1e-300: must be at least"),
        (
            16,
            2,
            1e12,
            "--cell-size, --tile-cells and --levels 1.000e12 m, 16, 2",
        ),
        (
            8,
            12,
            20.0,
            "--cell-size, --tile-cells and --levels 20 m, 8, 12",
        ),
        // A root tile beyond f64's range.
        (
            16,
            2,
            1e307,
            "--cell-size, --tile-cells and --levels 1.000e307 m, 16, 2",
        ),
    ] {
        let opts = BakeOptions {
            dem: dem.clone(),
            out: out.clone(),
            cell_size_m: Some(cell),
            tile_cells,
            stored_levels,
            ..Default::default()
        };
        let err = bake(&opts, &mut |_, _, _| {}).unwrap_err();
        assert!(matches!(err, WorldError::BadOption { .. }), "{err}");
        assert!(err.to_string().starts_with(option), "{err}");
        assert!(!err.to_string().contains("world.toml"), "{err}");
        assert!(!out.exists());
    }
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        2,
        "nothing but the DEM and its sidecar"
    );
}

#[test]
fn implausible_dem_heights_and_cells_blame_the_sidecar() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("w");
    // Offset -1e30 m, scale 1e36 m (heights beyond f32), 1e33 m: a wrong sidecar.
    for (name, offset, scale) in [
        ("low", -1e30, 1.0),
        ("huge", 0.0, 1e36),
        ("high", 1e33, 1.0),
    ] {
        let png = write_dem(dir.path(), name, [20, 16], [5.0, 5.0], [0.0, 1.0], hills);
        write_sidecar(dir.path(), name, [20, 16], [5.0, 5.0], [offset, scale]);
        let opts = BakeOptions {
            dem: png,
            out: out.clone(),
            tile_cells: 8,
            stored_levels: 1,
            ..Default::default()
        };
        let err = bake(&opts, &mut |_, _, _| {}).unwrap_err();
        assert!(matches!(err, WorldError::ImplausibleHeight { .. }), "{err}");
        let text = err.to_string();
        assert!(
            text.starts_with(&format!(
                "{}",
                dir.path().join(format!("{name}.json")).display()
            )),
            "{text}"
        );
        assert!(
            text.contains("height_scale_m") && !text.contains("world.toml"),
            "{text}"
        );
        assert!(!out.exists());
    }
    // A DEM of 1 um cells: the sidecar's cell size is named.
    let png = write_dem(dir.path(), "tiny", [20, 16], [5.0, 5.0], [0.0, 1.0], hills);
    write_sidecar(dir.path(), "tiny", [20, 16], [1e-6, 1e-6], [0.0, 1.0]);
    let opts = BakeOptions {
        dem: png,
        out: out.clone(),
        tile_cells: 8,
        stored_levels: 1,
        ..Default::default()
    };
    let err = bake(&opts, &mut |_, _, _| {}).unwrap_err().to_string();
    assert!(
        err.contains("tiny.json") && err.contains("cell_size_m"),
        "{err}"
    );
    assert!(!err.contains("world.toml"), "{err}");
    // Cells of 1e308 m: the sidecar's field is named as it is read.
    let png = write_dem(dir.path(), "vast", [20, 16], [5.0, 5.0], [0.0, 1.0], hills);
    write_sidecar(dir.path(), "vast", [20, 16], [1e308, 10.0], [0.0, 1.0]);
    let err = bake(
        &BakeOptions {
            dem: png,
            out: out.clone(),
            tile_cells: 8,
            stored_levels: 1,
            ..Default::default()
        },
        &mut |_, _, _| {},
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("vast.json") && err.contains("cell_size_m.east_west") && err.contains("1e308"),
        "{err}"
    );
    assert!(!out.exists());
}

/// A DEM cell size too small for a bake that came from `--dem-cell-size` is blamed on the
/// option, not on the sidecar that said otherwise.
#[test]
fn a_too_small_dem_cell_size_option_is_named_not_the_sidecar() {
    let dir = tempfile::tempdir().unwrap();
    let png = write_dem(dir.path(), "hills", [20, 16], [5.0, 5.0], [0.0, 1.0], hills);
    let out = dir.path().join("w");
    let opts = BakeOptions {
        dem: png,
        dem_cell_size_m: Some([1e-4, 1e-4]),
        out: out.clone(),
        tile_cells: 8,
        stored_levels: 1,
        ..Default::default()
    };
    let err = bake(&opts, &mut |_, _, _| {}).unwrap_err();
    assert!(matches!(err, WorldError::BadOption { .. }), "{err}");
    let text = err.to_string();
    assert!(
        text.starts_with("--dem-cell-size 1.000e-4 x 1.000e-4: must be at least"),
        "{text}"
    );
    assert!(
        !text.contains("hills.json") && !text.contains("cell_size_m"),
        "{text}"
    );
    assert!(!out.exists());

    let run = verdant_cli(
        &[
            "bake",
            "--dem",
            "hills.png",
            "--out",
            "w",
            "--dem-cell-size",
            "0.0001",
        ],
        dir.path(),
    );
    common::assert_fails_naming(&run, &["--dem-cell-size"]);
    assert!(!String::from_utf8_lossy(&run.stderr).contains("hills.json"));
}

/// A `--name` holding a control character is refused before anything is read or written,
/// naming the option, and the escape never reaches the terminal raw.
#[test]
fn a_name_with_a_control_character_is_refused_before_writing() {
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path(), "hills", DEM_SIZE, DEM_CELLS, DEM_SCALE, hills);
    let out = dir.path().join("w");
    let opts = BakeOptions {
        dem,
        out: out.clone(),
        name: Some("a\x1bb".into()),
        cell_size_m: Some(20.0),
        tile_cells: 16,
        stored_levels: 2,
        ..Default::default()
    };
    let err = bake(&opts, &mut |_, _, _| {}).unwrap_err();
    assert!(matches!(err, WorldError::BadOption { .. }), "{err}");
    let text = err.to_string();
    assert!(
        text.starts_with("--name") && text.contains("U+001B") && !text.contains('\x1b'),
        "{text}"
    );
    assert!(!out.exists());

    let run = verdant_cli(
        &[
            "bake",
            "--dem",
            "hills.png",
            "--out",
            "w",
            "--name",
            "a\x1bb",
        ],
        dir.path(),
    );
    common::assert_fails_naming(&run, &["--name", "control character"]);
    assert!(!run.stderr.contains(&0x1b) && !run.stdout.contains(&0x1b));
    assert!(!out.exists());
    assert!(staging_folders(dir.path()).is_empty());

    // An empty name (or only blanks) is refused as the option, not as a world.toml that was
    // never written.
    for name in ["", "  "] {
        let err = bake(
            &BakeOptions {
                name: Some(name.into()),
                ..opts.clone()
            },
            &mut |_, _, _| {},
        )
        .unwrap_err();
        assert!(matches!(err, WorldError::BadOption { .. }), "{err}");
        let text = err.to_string();
        assert!(
            text.starts_with("--name") && text.contains("not empty"),
            "{text}"
        );
        assert!(!text.contains("world.toml"), "{text}");
        assert!(!out.exists());
    }
}

/// Control characters in a DEM's file name and its sidecar's texts are no fault of the user's:
/// the bake replaces them with U+FFFD in what the manifest records, and the world it writes
/// loads; nothing it prints holds them raw.
#[test]
fn control_characters_in_a_dem_name_and_sidecar_are_replaced() {
    let dir = tempfile::tempdir().unwrap();
    let name = "dem\x1b[31m";
    let png = write_dem(dir.path(), name, [20, 16], [5.0, 5.0], [0.0, 1.0], hills);
    let sidecar = dir.path().join(format!("{name}.json"));
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&sidecar).unwrap()).unwrap();
    json["place"] = "Ring\x07 hills".into();
    json["source"] = "Survey\x1b]0;title\x07.".into();
    std::fs::write(&sidecar, json.to_string()).unwrap();

    let out = dir.path().join("w");
    let opts = BakeOptions {
        dem: png.clone(),
        out: out.clone(),
        tile_cells: 8,
        stored_levels: 1,
        ..Default::default()
    };
    bake(&opts, &mut |_, _, _| {}).unwrap();
    let world = verdant::world::World::open(&out).unwrap();
    let m = &world.manifest;
    assert!(
        m.description
            .starts_with("Ring\u{FFFD} hills. Baked from dem\u{FFFD}[31m.png")
            && m.description.ends_with("Survey\u{FFFD}]0;title\u{FFFD}."),
        "{}",
        m.description
    );
    let source = m.source.as_ref().unwrap();
    assert_eq!(source.file, "dem\u{FFFD}[31m.png");

    let run = verdant_cli(
        &["bake", "--dem", png.to_str().unwrap(), "--out", "cli"],
        dir.path(),
    );
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(stdout.contains("dem\\u{1b}[31m.png"), "{stdout}");
    assert!(!run.stderr.contains(&0x1b) && !run.stdout.contains(&0x1b));
    verdant::world::World::open(&dir.path().join("cli")).unwrap();
}

/// Writes a flat 16-bit PNG DEM of `side` x `side` samples and its sidecar, row by row (a
/// constant image compresses to a small file, however many samples it holds).
fn write_flat_png(dir: &Path, name: &str, side: u32) -> PathBuf {
    use std::io::Write;
    let path = dir.join(format!("{name}.png"));
    let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
    let mut encoder = png::Encoder::new(file, side, side);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(png::BitDepth::Sixteen);
    encoder.set_compression(png::Compression::Fast);
    let mut writer = encoder.write_header().unwrap();
    let mut stream = writer.stream_writer().unwrap();
    let row = vec![0u8; side as usize * 2];
    for _ in 0..side {
        stream.write_all(&row).unwrap();
    }
    stream.finish().unwrap();
    write_sidecar(dir, name, [side, side], [1.0, 1.0], [100.0, 1.0]);
    path
}

/// A PNG DEM too large for `--memory-mib` is refused from its header, before a sample is
/// decoded (it was decoded whole first, past the limit), naming the option and what it needs.
#[test]
fn a_png_dem_over_the_memory_limit_is_refused_before_decoding() {
    let dir = tempfile::tempdir().unwrap();
    // 8192 x 8192 samples: 384 MiB of samples and heights while decoded, in a file of 1 MB.
    let png = write_flat_png(dir.path(), "flat", 8192);
    assert!(std::fs::metadata(&png).unwrap().len() < 4 << 20);
    let out = dir.path().join("w");
    let opts = BakeOptions {
        dem: png,
        out: out.clone(),
        memory_mib: 128,
        ..Default::default()
    };
    let start = std::time::Instant::now();
    let err = bake(&opts, &mut |_, _, _| {}).unwrap_err();
    let seconds = start.elapsed().as_secs_f64();
    assert!(matches!(err, WorldError::BadOption { .. }), "{err}");
    let text = err.to_string();
    assert!(
        text.starts_with("--memory-mib 128: must be at least 4")
            && text.contains("8192x8192 samples")
            && text.contains("decoded whole"),
        "{text}"
    );
    // Decoding 64 Mi samples takes seconds; reading a header, milliseconds.
    assert!(seconds < 0.5, "refused after {seconds} s: {text}");
    assert!(!out.exists());
}

#[test]
fn a_manifest_with_heights_beyond_a_planet_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let world = small_bake(
        dir.path(),
        write_dem(dir.path(), "hills", DEM_SIZE, DEM_CELLS, DEM_SCALE, hills),
        "w",
    );
    let file = world.join("world.toml");
    let text = std::fs::read_to_string(&file).unwrap();
    let line = text
        .lines()
        .find(|l| l.starts_with("height_range_m"))
        .unwrap()
        .to_owned();
    std::fs::write(&file, text.replace(&line, "height_range_m = [0.0, 1e33]")).unwrap();
    let err = verdant::world::World::open(&world).unwrap_err().to_string();
    assert!(
        err.contains("world.toml") && err.contains("height_range_m"),
        "{err}"
    );
}

#[test]
fn dem_loads_with_its_sidecar() {
    let dir = tempfile::tempdir().unwrap();
    let png = write_dem(dir.path(), "hills", DEM_SIZE, DEM_CELLS, DEM_SCALE, hills);
    let dem = Dem::load(&png).unwrap();
    assert_eq!((dem.width, dem.height), (200, 150));
    assert_eq!(dem.extent_m(), [1990.0, 1937.0]);
    // Row 0 is north: its first sample lies at (0, 1937).
    assert!((f64::from(dem.heights[0]) - hills(0.0, 1937.0)).abs() < 0.006);
    let last_row = 149 * 200;
    assert!((f64::from(dem.heights[last_row + 5]) - hills(50.0, 0.0)).abs() < 0.006);
    // Interpolation passes through the posts.
    assert!((dem.sample(50.0, 0.0) - f64::from(dem.heights[last_row + 5])).abs() < 1e-9);
}

#[test]
fn dem_sidecar_disagreeing_with_its_png_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let png = write_dem(dir.path(), "d", [20, 10], [5.0, 5.0], [0.0, 1.0], hills);
    write_sidecar(dir.path(), "d", [21, 10], [5.0, 5.0], [0.0, 1.0]);
    let err = Dem::load(&png).unwrap_err();
    assert!(
        matches!(
            err,
            WorldError::SidecarMismatch {
                field: "width",
                sidecar: 21,
                image: 20,
                ..
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("d.json"), "{err}");
}

#[test]
fn eight_bit_dem_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("d.png");
    image::GrayImage::new(20, 10).save(&png).unwrap();
    write_sidecar(dir.path(), "d", [20, 10], [5.0, 5.0], [0.0, 1.0]);
    let err = Dem::load(&png).unwrap_err();
    assert!(matches!(err, WorldError::WrongLayout { .. }), "{err}");
    let msg = err.to_string();
    assert!(
        msg.contains("d.png") && msg.contains("16-bit grayscale"),
        "{msg}"
    );
    assert!(msg.contains("8-bit"), "{msg}");
}

#[test]
fn dem_without_sidecar_or_with_a_bad_one_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let png = write_dem(dir.path(), "d", [20, 10], [5.0, 5.0], [0.0, 1.0], hills);
    let json = dir.path().join("d.json");

    std::fs::write(&json, "{ \"width\": 20, ").unwrap();
    let err = Dem::load(&png).unwrap_err();
    assert!(matches!(err, WorldError::BadSidecar { .. }), "{err}");
    assert!(err.to_string().contains("d.json"), "{err}");

    write_sidecar(dir.path(), "d", [20, 10], [0.0, 5.0], [0.0, 1.0]);
    let err = Dem::load(&png).unwrap_err();
    assert!(matches!(err, WorldError::NonPositive { .. }), "{err}");
    assert!(err.to_string().contains("cell_size_m.east_west"), "{err}");

    write_sidecar(dir.path(), "d", [20, 10], [5.0, 5.0], [0.0, -1.0]);
    let err = Dem::load(&png).unwrap_err();
    assert!(matches!(err, WorldError::NonPositive { .. }), "{err}");

    std::fs::remove_file(&json).unwrap();
    let err = Dem::load(&png).unwrap_err();
    assert!(matches!(err, WorldError::MissingSidecar { .. }), "{err}");
    assert!(err.to_string().contains("d.json"), "{err}");

    let err = Dem::load(&dir.path().join("absent.png")).unwrap_err();
    assert!(matches!(err, WorldError::MissingFile { .. }), "{err}");
    assert!(err.to_string().contains("absent.png"), "{err}");
}

#[test]
fn corrupt_dem_png_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let png = write_dem(dir.path(), "d", [20, 10], [5.0, 5.0], [0.0, 1.0], hills);
    let bytes = std::fs::read(&png).unwrap();
    std::fs::write(&png, &bytes[..bytes.len() / 2]).unwrap();
    let err = Dem::load(&png).unwrap_err();
    assert!(matches!(err, WorldError::CorruptImage { .. }), "{err}");
    assert!(err.to_string().contains("d.png"), "{err}");
}

#[test]
fn tile_ids_of_a_baked_world_are_in_level_order() {
    let dir = tempfile::tempdir().unwrap();
    let world = verdant::world::World::open(&hills_world(dir.path())).unwrap();
    let ids: Vec<TileId> = world.stored_tiles().collect();
    assert_eq!(ids.len(), 80);
    assert!(ids.windows(2).all(|w| w[0].level <= w[1].level));
    assert_eq!(ids[0], TileId::new(0, 0, 0));
    assert_eq!(ids[79], TileId::new(1, 7, 7));
}

/// What a folder holds apart from a world (`world.toml`, `tiles/`): every file's bytes, every
/// folder, every symlink's target, by path.
fn unrelated_files(dir: &Path) -> BTreeMap<PathBuf, String> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            let rel = path.strip_prefix(dir).unwrap().to_path_buf();
            if rel == Path::new("world.toml") || rel == Path::new("tiles") {
                continue;
            }
            let meta = std::fs::symlink_metadata(&path).unwrap();
            let what = if meta.file_type().is_symlink() {
                format!("link to {}", std::fs::read_link(&path).unwrap().display())
            } else if meta.is_dir() {
                stack.push(path.clone());
                "folder".to_string()
            } else {
                format!("file {:?}", std::fs::read(&path).unwrap())
            };
            out.insert(rel, what);
        }
    }
    out
}

/// A folder holding a dozen files and folders that are not a world: notes, the DEM, a hidden
/// file, nested folders, an empty one, a symlink, and a file named like a staging folder.
fn busy_folder(dir: &Path) -> PathBuf {
    let w = dir.join("w");
    for sub in ["notes", "notes/deeper", "empty", "source"] {
        std::fs::create_dir_all(w.join(sub)).unwrap();
    }
    let files: [(&str, &[u8]); 9] = [
        ("README.md", b"# my world\n"),
        (".hidden", b"secret"),
        ("notes/a.txt", b"alpha"),
        ("notes/deeper/b.bin", &[0, 1, 2, 255, 254]),
        ("source/dem.json", b"{}"),
        ("world.toml.bak", b"an old manifest"),
        ("tiles.txt", b"not the tiles folder"),
        (".w.baking.notes", b"a file, not a staging folder"),
        ("big.bin", &[7; 5000]),
    ];
    for (name, bytes) in files {
        std::fs::write(w.join(name), bytes).unwrap();
    }
    #[cfg(unix)]
    std::os::unix::fs::symlink("README.md", w.join("readme-link")).unwrap();
    w
}

fn replace_opts(dem: PathBuf, out: PathBuf) -> BakeOptions {
    BakeOptions {
        dem,
        out,
        cell_size_m: Some(20.0),
        tile_cells: 16,
        stored_levels: 2,
        replace: true,
        ..Default::default()
    }
}

/// Staging folders (`.NAME.baking.*` folders) in `dir`.
fn staging_folders(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap())
        .filter(|e| e.file_type().unwrap().is_dir())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".baking."))
        .collect()
}

/// What a user adds to a baked manifest by hand: two plant types (one with a sub-table, both
/// with comments) and a camera path the bake does not write.
const HAND_MADE: &str = r#"
# Flowers on the meadow, added by hand.
[[plant_types]]
name = "poppy"
mesh = "flower"
color = [0.8, 0.1, 0.03]
size_m = [0.35, 0.65]
density = { meadow = 0.4 }
seed = 1

# A bush, its wind in a table of its own.
[[plant_types]]
name = "bush"
mesh = "bush"
color = [0.1, 0.24, 0.04]
size_m = [0.7, 1.4]
density = { "tall grass" = 0.05 }
seed = 4
[plant_types.wind]
bend = 0.012
stiffness = 0.75

# My own wind, and a flight in it.
[[wind_scenes]]
name = "gale"
[wind_scenes.ambient]
direction_deg = 90.0
speed_mps = 18.0
gustiness = 0.6

# My own flight.
[[paths]]
name = "my-flight"
duration_s = 10.0
wind = [{ t_s = 0.0, scene = "gale" }]
[[paths.keys]]
t_s = 0.0
position_m = [100.0, 100.0, 600.0]
yaw_deg = 45.0
pitch_deg = -10.0
[[paths.keys]]
t_s = 10.0
position_m = [900.0, 900.0, 600.0]
yaw_deg = 45.0
pitch_deg = -10.0
"#;

/// `--replace` keeps the replaced manifest's plant types and its camera paths of other names
/// than the bake's, as the user wrote them (comments too), and checks them against the new
/// world; `--fresh-manifest` drops them; parts that do not fit the new world are refused
/// before anything is replaced, naming the manifest, the field and the way out.
#[test]
fn replace_keeps_the_hand_made_plants_and_paths_of_the_manifest() {
    use verdant::world::Manifest;
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path(), "hills", DEM_SIZE, DEM_CELLS, DEM_SCALE, hills);
    let w = dir.path().join("w");
    bake(&replace_opts(dem.clone(), w.clone()), &mut |_, _, _| {}).unwrap();
    let toml = w.join("world.toml");
    let baked = Manifest::from_path(&toml).unwrap();
    assert!(baked.plant_types.is_empty());
    let mut text = std::fs::read_to_string(&toml).unwrap();
    text.push_str(HAND_MADE);
    std::fs::write(&toml, &text).unwrap();
    let edited = Manifest::from_path(&toml).unwrap();
    assert_eq!(edited.plant_types.len(), 2);

    // Re-baked with another seed: the bake's parts are new, the hand-made ones kept.
    let report = bake(
        &BakeOptions {
            seed: 5,
            ..replace_opts(dem.clone(), w.clone())
        },
        &mut |_, _, _| {},
    )
    .unwrap();
    assert_eq!(report.carried.plant_types, ["poppy", "bush"]);
    assert_eq!(report.carried.paths, ["my-flight"]);
    assert_eq!(report.carried.wind_scenes, ["gale"]);
    assert!(!report.carried.rewritten && report.carried.paths_outside.is_empty());
    // The seed moved the bake's meadow, and with it its paths: said, and the bake's kept.
    assert!(
        report
            .carried
            .replaced
            .iter()
            .any(|r| r == "path \"meadow\""),
        "{:?}",
        report.carried.replaced
    );
    let rebaked_text = std::fs::read_to_string(&toml).unwrap();
    let rebaked = Manifest::from_path(&toml).unwrap();
    assert_eq!(rebaked.plant_types, edited.plant_types);
    let names = |m: &Manifest| m.paths.iter().map(|p| p.name.clone()).collect::<Vec<_>>();
    assert_eq!(names(&rebaked), names(&edited));
    assert!(rebaked.path("my-flight") == edited.path("my-flight"));
    // The bake's own paths are the new bake's (the seed moved its meadow), not the old ones.
    assert!(rebaked.path("meadow") != edited.path("meadow"));
    assert!(rebaked.wind_scene("gale") == edited.wind_scene("gale"));
    for comment in [
        "# Flowers on the meadow",
        "# A bush, its wind",
        "# My own wind",
        "# My own flight.",
    ] {
        assert!(rebaked_text.contains(comment), "{comment:?} lost");
    }
    // Baked again, the hand-made parts are not doubled.
    bake(&replace_opts(dem.clone(), w.clone()), &mut |_, _, _| {}).unwrap();
    let again = Manifest::from_path(&toml).unwrap();
    assert_eq!(again.plant_types, edited.plant_types);
    assert_eq!(names(&again), names(&edited));
    assert!(
        again.paths == edited.paths,
        "the seed-7 bake's paths and my-flight"
    );

    // A plant on a grass type the world lacks: refused, the folder as it was.
    let mut bad = std::fs::read_to_string(&toml).unwrap();
    bad = bad.replace("density = { meadow = 0.4 }", "density = { moss = 0.4 }");
    std::fs::write(&toml, &bad).unwrap();
    let before = read_all_files(&w);
    let mut wrote_tiles = false;
    let e = bake(&replace_opts(dem.clone(), w.clone()), &mut |stage, _, _| {
        wrote_tiles |= stage == BakeStage::WriteTiles;
    })
    .unwrap_err();
    assert!(matches!(e, WorldError::Carry { .. }), "{e}");
    assert!(!wrote_tiles, "refused only after the tiles were baked");
    let msg = e.to_string();
    for needle in [
        toml.display().to_string(),
        "plant_types[0].density.moss".into(),
        "--fresh-manifest".into(),
    ] {
        assert!(msg.contains(&needle), "{needle:?} not in {msg:?}");
    }
    assert_eq!(read_all_files(&w), before);
    assert!(staging_folders(dir.path()).is_empty());
    // A kept path naming a wind scene nobody has: the error names the field.
    let bad = std::fs::read_to_string(&toml)
        .unwrap()
        .replace("density = { moss = 0.4 }", "density = { meadow = 0.4 }")
        .replace("scene = \"gale\" }", "scene = \"squall\" }");
    std::fs::write(&toml, &bad).unwrap();
    let msg = bake(&replace_opts(dem.clone(), w.clone()), &mut |_, _, _| {})
        .unwrap_err()
        .to_string();
    // The old manifest itself no longer reads: its own index is named.
    let at = format!("paths[{}].wind[0].scene", baked.paths.len());
    for needle in ["squall", at.as_str(), "--fresh-manifest"] {
        assert!(msg.contains(needle), "{needle:?} not in {msg:?}");
    }

    // --fresh-manifest writes the bake's manifest alone.
    let report = bake(
        &BakeOptions {
            fresh_manifest: true,
            ..replace_opts(dem, w.clone())
        },
        &mut |_, _, _| {},
    )
    .unwrap();
    assert!(report.carried.is_empty());
    let fresh = Manifest::from_path(&toml).unwrap();
    assert!(fresh.plant_types.is_empty());
    assert!(fresh.paths == baked.paths, "the bake's paths alone");
}

/// A `--replace` killed while moving its world in, after the old `world.toml` went aside and
/// before the new one came in, leaves the folder without a manifest: the next bake puts the
/// old world back first, says so, and keeps the hand-made parts of its manifest as ever.
#[test]
fn a_replace_killed_while_publishing_is_put_right_by_the_next_bake() {
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path(), "hills", DEM_SIZE, DEM_CELLS, DEM_SCALE, hills);
    let w = dir.path().join("w");
    bake(&replace_opts(dem.clone(), w.clone()), &mut |_, _, _| {}).unwrap();
    let toml = w.join("world.toml");
    let mut text = std::fs::read_to_string(&toml).unwrap();
    text.push_str(HAND_MADE);
    std::fs::write(&toml, &text).unwrap();
    std::fs::write(w.join("notes.txt"), "mine").unwrap();
    let before = read_all_files(&w);
    // The staging folder of the killed bake (whose lock nobody holds any more): its new world,
    // and the old manifest moved aside into previous/.
    let staging = dir.path().join(".w.baking.4242-0");
    common::copy_dir(&w.join("tiles"), &staging.join("world/tiles"));
    std::fs::write(staging.join("world/world.toml"), "[pyramid] # new").unwrap();
    std::fs::write(staging.join("lock"), "").unwrap();
    std::fs::create_dir_all(staging.join("previous")).unwrap();
    std::fs::rename(&toml, staging.join("previous/world.toml")).unwrap();
    let kept = staging.join("previous/world.toml");

    // Any bake into the folder puts it right first: this one is refused afterwards, the old
    // world back in place.
    let refused = verdant_cli(
        &[
            "bake",
            "--dem",
            "hills.png",
            "--out",
            "w",
            "--cell-size",
            "20",
        ],
        dir.path(),
    );
    common::assert_fails_naming(&refused, &["not empty"]);
    let said = String::from_utf8_lossy(&refused.stderr);
    assert!(said.contains("put the previous world.toml back"), "{said}");
    assert!(!kept.exists() && !staging.exists());
    assert_eq!(read_all_files(&w), before, "the folder as it was before");

    // Killed again at the same point: the next --replace keeps the hand-made parts.
    common::copy_dir(&w.join("tiles"), &staging.join("world/tiles"));
    std::fs::write(staging.join("world/world.toml"), "[pyramid] # new").unwrap();
    std::fs::write(staging.join("lock"), "").unwrap();
    std::fs::create_dir_all(staging.join("previous")).unwrap();
    std::fs::rename(&toml, staging.join("previous/world.toml")).unwrap();
    let report = bake(&replace_opts(dem, w.clone()), &mut |_, _, _| {}).unwrap();
    assert_eq!(report.carried.plant_types, ["poppy", "bush"]);
    assert_eq!(report.carried.paths, ["my-flight"]);
    assert_eq!(
        std::fs::read_to_string(w.join("notes.txt")).unwrap(),
        "mine"
    );
    assert!(staging_folders(dir.path()).is_empty());
}

/// A bake into a world's `tiles/` (or a folder inside it) is refused before anything is read,
/// naming the world, as the other tools refuse it: its files would be mixed with the tiles.
#[test]
fn bake_into_a_worlds_tiles_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let w = hills_world(dir.path());
    let dem = dir.path().join("hills.png");
    let before = read_all_files(&w);
    for out in [w.join("tiles"), w.join("tiles/L0"), w.join("tiles/new")] {
        for replace in [true, false] {
            let e = bake(
                &BakeOptions {
                    replace,
                    ..replace_opts(dem.clone(), out.clone())
                },
                &mut |_, _, _| {},
            )
            .unwrap_err()
            .to_string();
            assert!(
                e.starts_with("--out") && e.contains("tiles/") && e.contains(&*w.to_string_lossy()),
                "{}: {e}",
                out.display()
            );
        }
    }
    assert_eq!(read_all_files(&w), before);
    let run = verdant_cli(
        &[
            "bake",
            "--dem",
            "hills.png",
            "--out",
            "hills/tiles",
            "--replace",
        ],
        dir.path(),
    );
    common::assert_fails_naming(&run, &["--out", "hills/tiles", "tiles/"]);
    assert_eq!(read_all_files(&w), before);
}

/// A DEM whose cells span more cells of the bake's (its smaller cell, rounded) than a bake
/// makes is refused naming that: the extent and the cells across, not a cell too small.
#[test]
fn a_dem_spanning_too_many_bake_cells_is_refused_saying_so() {
    let dir = tempfile::tempdir().unwrap();
    let png = write_dem(
        dir.path(),
        "wide",
        [20, 16],
        // The widest cell a sidecar may give (1,000 km).
        [1e6, 20.0],
        [0.0, 1.0],
        |_, y| 100.0 + y / 100.0,
    );
    let opts = BakeOptions {
        dem: png.clone(),
        out: dir.path().join("w"),
        tile_cells: 8,
        ..Default::default()
    };
    let e = bake(&opts, &mut |_, _, _| {}).unwrap_err().to_string();
    for needle in [
        "wide.json",
        "cell_size_m",
        "1.900e7",
        "of the bake's cells a side",
        "950000 cells of 20 m",
        "--cell-size",
    ] {
        assert!(e.contains(needle), "{needle:?} not in {e}");
    }
    assert!(!e.contains("must be at least"), "{e}");
    // The same cells from --dem-cell-size: the option is named.
    let e = bake(
        &BakeOptions {
            dem_cell_size_m: Some([1e9, 20.0]),
            ..opts
        },
        &mut |_, _, _| {},
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.starts_with("--dem-cell-size") && e.contains("of the bake's cells a side"),
        "{e}"
    );
    assert!(!e.contains("must be at least"), "{e}");
}

/// `--replace` replaces the world (world.toml, tiles/) and nothing else, however the output
/// folder is spelled (`w/.`, `w/`, `w/notes/..`): every other file and folder stays where it
/// was, byte for byte, and no staging folder is left, inside or beside it.
#[test]
fn replace_keeps_every_unrelated_file_however_the_folder_is_spelled() {
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path(), "hills", DEM_SIZE, DEM_CELLS, DEM_SCALE, hills);
    let w = busy_folder(dir.path());
    std::fs::create_dir_all(w.join("tiles/L5")).unwrap();
    std::fs::write(w.join("tiles/L5/0_0.height.exr"), "stale").unwrap();
    let before = unrelated_files(&w);
    assert!(before.len() >= 12, "{before:?}");
    let spellings = [
        w.join("."),
        PathBuf::from(format!("{}/", w.display())),
        w.join("notes").join(".."),
        w.join("notes/deeper/../.."),
    ];
    for out in spellings {
        bake(&replace_opts(dem.clone(), out.clone()), &mut |_, _, _| {})
            .unwrap_or_else(|e| panic!("{}: {e}", out.display()));
        assert_eq!(unrelated_files(&w), before, "{}", out.display());
        let world = verdant::world::World::open(&w).unwrap();
        assert_eq!(world.manifest.name, "w", "{}", out.display());
        assert!(!w.join("tiles/L5").exists(), "a stale tile was kept");
        assert!(staging_folders(&w).is_empty(), "{}", out.display());
        assert!(staging_folders(dir.path()).is_empty(), "{}", out.display());
    }
}

/// `--replace` deletes the replaced `tiles/` whole, so it refuses a `tiles/` that holds anything
/// a bake does not write there (the DEM being baked, someone's notes, a folder of photos), naming
/// the file, and leaves every file where it was; a `tiles/` of tile files alone is replaced.
#[test]
fn replace_refuses_a_tiles_folder_holding_files_that_are_not_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let w = dir.path().join("w");
    std::fs::create_dir_all(w.join("tiles")).unwrap();
    // The DEM being baked, inside the tiles folder it would replace.
    let dem = write_dem(
        &w.join("tiles"),
        "hills",
        DEM_SIZE,
        DEM_CELLS,
        DEM_SCALE,
        hills,
    );
    let before = read_all_files(&w);
    let err = bake(&replace_opts(dem.clone(), w.clone()), &mut |_, _, _| {}).unwrap_err();
    assert!(matches!(err, WorldError::ForeignInTiles { .. }), "{err}");
    assert!(err.to_string().contains("--replace would delete"), "{err}");
    assert_eq!(
        read_all_files(&w),
        before,
        "a refused bake changed the folder"
    );

    // A world.toml that is not a world's manifest (notes, a DEM named so) is not replaced.
    let notes = dir.path().join("notes");
    std::fs::create_dir_all(&notes).unwrap();
    std::fs::write(notes.join("world.toml"), "my notes about worlds\n").unwrap();
    let dem_elsewhere = write_dem(dir.path(), "hills", DEM_SIZE, DEM_CELLS, DEM_SCALE, hills);
    let err = bake(
        &replace_opts(dem_elsewhere, notes.clone()),
        &mut |_, _, _| {},
    )
    .unwrap_err();
    assert!(err.to_string().contains("not one: not TOML"), "{err}");
    assert_eq!(
        std::fs::read_to_string(notes.join("world.toml")).unwrap(),
        "my notes about worlds\n"
    );

    // Tile-named files in other places, a level that is a file, a tile that is a folder.
    let dem = write_dem(dir.path(), "hills", DEM_SIZE, DEM_CELLS, DEM_SCALE, hills);
    let cases: [(&str, bool); 6] = [
        ("tiles/kitchen/a.jpg", true),
        ("tiles/L0/notes.txt", true),
        ("tiles/0_0.height.exr", true),
        ("tiles/L0/0_0.height.exr.bak", true),
        ("tiles/L0/0_0.height.exr/x", true),
        ("tiles/L3/12_7.material.png", false),
    ];
    for (file, refused) in cases {
        let w = dir.path().join("case");
        let _ = std::fs::remove_dir_all(&w);
        std::fs::create_dir_all(w.join(file).parent().unwrap()).unwrap();
        std::fs::write(w.join(file), "mine").unwrap();
        let result = bake(&replace_opts(dem.clone(), w.clone()), &mut |_, _, _| {});
        match (result, refused) {
            (Err(WorldError::ForeignInTiles { path, .. }), true) => {
                assert!(w.join(file).exists(), "{file} was deleted");
                assert!(
                    w.join(file).starts_with(&path),
                    "{file}: blamed {}",
                    path.display()
                );
            }
            (Ok(_), false) => assert!(!w.join(file).exists(), "{file}: a stale tile was kept"),
            (r, _) => panic!("{file}: {:?}", r.map(|_| ())),
        }
    }
}

/// A bake that fails, before writing (a bad DEM) or while writing tiles (cancelled part-way),
/// leaves the folder exactly as it was: its world and every other file.
#[test]
fn a_failed_bake_leaves_the_folder_as_it_was() {
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path(), "hills", DEM_SIZE, DEM_CELLS, DEM_SCALE, hills);
    let w = busy_folder(dir.path());
    bake(&replace_opts(dem.clone(), w.clone()), &mut |_, _, _| {}).unwrap();
    let world_before = read_all_files(&w);
    let before = unrelated_files(&w);

    // A truncated DEM.
    let bad = dir.path().join("bad.png");
    let bytes = std::fs::read(&dem).unwrap();
    std::fs::write(&bad, &bytes[..bytes.len() / 2]).unwrap();
    std::fs::copy(dir.path().join("hills.json"), dir.path().join("bad.json")).unwrap();
    let err = bake(&replace_opts(bad, w.join(".")), &mut |_, _, _| {}).unwrap_err();
    assert!(matches!(err, WorldError::CorruptImage { .. }), "{err}");
    assert_eq!(read_all_files(&w), world_before);

    // Cancelled after a few tiles were written into the staging folder.
    let cancel = verdant::bake::CancelFlag::new();
    let opts = BakeOptions {
        cancel: Some(cancel.clone()),
        seed: 99,
        ..replace_opts(dem, w.join("notes/.."))
    };
    let mut tiles_seen = 0;
    let err = bake(&opts, &mut |stage, done, _| {
        if stage == BakeStage::WriteTiles && done >= 5 {
            tiles_seen = done;
            cancel.cancel();
        }
    })
    .unwrap_err();
    assert!(
        tiles_seen >= 5,
        "the bake was cancelled before writing tiles"
    );
    assert!(matches!(err, WorldError::Cancelled { .. }), "{err}");
    assert!(err.to_string().contains("cancelled"), "{err}");
    assert_eq!(read_all_files(&w), world_before);
    assert_eq!(unrelated_files(&w), before);
    assert!(staging_folders(dir.path()).is_empty());
}

/// A cancelled bake into a new folder creates nothing (nor the parents it lacked), and leaves
/// no staging folder.
#[test]
fn a_cancelled_bake_leaves_no_staging_folder() {
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path(), "hills", DEM_SIZE, DEM_CELLS, DEM_SCALE, hills);
    for stage in [
        BakeStage::Resample,
        BakeStage::Paint,
        BakeStage::Paths,
        BakeStage::WriteTiles,
    ] {
        let cancel = verdant::bake::CancelFlag::new();
        let out = dir.path().join("new");
        let opts = BakeOptions {
            cancel: Some(cancel.clone()),
            ..replace_opts(dem.clone(), out.clone())
        };
        let err = bake(&opts, &mut |s, _, _| {
            if s == stage {
                cancel.cancel();
            }
        })
        .unwrap_err();
        assert!(
            matches!(err, WorldError::Cancelled { .. }),
            "{stage:?}: {err}"
        );
        assert!(!out.exists(), "{stage:?}");
        assert!(staging_folders(dir.path()).is_empty(), "{stage:?}");
    }
    // Into a folder whose parents are missing too: none of them is left behind.
    let cancel = verdant::bake::CancelFlag::new();
    let opts = BakeOptions {
        cancel: Some(cancel.clone()),
        ..replace_opts(dem.clone(), dir.path().join("a/b/new"))
    };
    let err = bake(&opts, &mut |s, _, _| {
        // Once the staging folder, and the parents it needed, exist.
        if s == BakeStage::WriteTiles {
            cancel.cancel();
        }
    })
    .unwrap_err();
    assert!(matches!(err, WorldError::Cancelled { .. }), "{err}");
    assert!(!dir.path().join("a").exists());
    // A bake that succeeds keeps them.
    bake(
        &replace_opts(dem, dir.path().join("a/b/new")),
        &mut |_, _, _| {},
    )
    .unwrap();
    assert!(dir.path().join("a/b/new/world.toml").is_file());
}

/// The next bake beside an output folder removes the staging folders of killed bakes (their
/// lock is free; without a lock file, older than a minute) and leaves alone those of running
/// bakes (locked), young ones without a lock file, and anything not a staging folder of it.
#[test]
fn stale_staging_folders_are_removed_and_live_ones_kept() {
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path(), "hills", DEM_SIZE, DEM_CELLS, DEM_SCALE, hills);
    let staging = |name: &str, lock: bool| {
        let d = dir.path().join(name);
        std::fs::create_dir_all(d.join("world/tiles/L0")).unwrap();
        std::fs::write(d.join("world/tiles/L0/0_0.type.png"), [0u8; 100]).unwrap();
        if lock {
            std::fs::write(d.join("lock"), "").unwrap();
        }
        d
    };
    let killed = staging(".w.baking.4242-0", true);
    let running = staging(".w.baking.4243-0", true);
    let held = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(running.join("lock"))
        .unwrap();
    held.try_lock().unwrap();
    let old_version = staging(".w.baking.77.old", false);
    // An hour ago, as a folder left by an older version that took no lock.
    let hour_ago = std::time::SystemTime::now() - std::time::Duration::from_secs(3600);
    std::fs::File::open(&old_version)
        .unwrap()
        .set_modified(hour_ago)
        .unwrap();
    let starting = staging(".w.baking.4244-0", false);
    let other_world = staging(".v.baking.4245-0", true);

    bake(&replace_opts(dem, dir.path().join("w")), &mut |_, _, _| {}).unwrap();
    assert!(!killed.exists(), "the killed bake's staging folder is left");
    assert!(
        !old_version.exists(),
        "the old version's staging folder is left"
    );
    assert!(running.join("world/tiles/L0/0_0.type.png").exists());
    assert!(starting.exists());
    assert!(other_world.exists());
    drop(held);
    // Once its bake is gone, the next bake removes it.
    bake(
        &replace_opts(dir.path().join("hills.png"), dir.path().join("w")),
        &mut |_, _, _| {},
    )
    .unwrap();
    assert!(!running.exists());
}

fn verdant_cli(args: &[&str], cwd: &Path) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("run verdant")
}

/// `verdant bake --out . --replace` in a folder of other files bakes the world into it and
/// keeps every other file, byte for byte.
#[test]
fn cli_bake_into_the_current_folder_keeps_its_files() {
    let dir = tempfile::tempdir().unwrap();
    let w = busy_folder(dir.path());
    write_dem(&w, "hills", DEM_SIZE, DEM_CELLS, DEM_SCALE, hills);
    let before = unrelated_files(&w);
    for out in [".", "./", "../w", "notes/.."] {
        let run = verdant_cli(
            &[
                "bake",
                "--dem",
                "hills.png",
                "--out",
                out,
                "--replace",
                "--cell-size",
                "20",
                "--tile-cells",
                "16",
                "--levels",
                "2",
            ],
            &w,
        );
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(run.status.success(), "--out {out}: {stderr}");
        assert_eq!(unrelated_files(&w), before, "--out {out}");
        let world = verdant::world::World::open(&w).unwrap();
        assert_eq!(world.manifest.name, "w", "--out {out}");
        assert!(staging_folders(&w).is_empty() && staging_folders(dir.path()).is_empty());
    }
}

/// A child process killed when dropped, so that a failing test leaves no bake running.
struct Running(std::process::Child);

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// SIGTERM during a bake stops it: status 130, a message, no world and no staging folder left.
#[cfg(unix)]
#[test]
fn cli_sigterm_during_a_bake_cleans_up() {
    signalled_bake_cleans_up(&[("-TERM", 0)]);
}

/// A stop sent twice at once (GNU `timeout -s INT`, which signals the bake and then its
/// process group) is one stop: the bake still cleans up, where it ended at once as for a
/// second Ctrl-C and left its staging folder to the next bake.
#[cfg(unix)]
#[test]
fn a_stop_signal_sent_twice_at_once_still_cleans_up() {
    signalled_bake_cleans_up(&[("-INT", 500), ("-INT", 20)]);
}

/// Starts a bake that writes tiles for many seconds, sends it `signals` once it is writing
/// tiles (each after its pause in milliseconds), and checks that it stopped cleanly: status
/// 130, a message, no world and no staging folder left.
#[cfg(unix)]
fn signalled_bake_cleans_up(signals: &[(&str, u64)]) {
    use std::time::{Duration, Instant};
    let dir = tempfile::tempdir().unwrap();
    let dem = common::root().join("tests/data/east_bay_768.png");
    // About 14,000 tiles of 8 cells: the bake is writing tiles for many seconds.
    let mut child = Running(
        std::process::Command::new(env!("CARGO_BIN_EXE_verdant"))
            .args(["bake", "--dem", dem.to_str().unwrap(), "--out", "w"])
            .args(["--tile-cells", "8", "--levels", "2"])
            .current_dir(dir.path())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let start = Instant::now();
    let staging = loop {
        if let Some(name) = staging_folders(dir.path()).pop() {
            let path = dir.path().join(name);
            if path.join("world/tiles").exists() {
                break path;
            }
        }
        if let Some(status) = child.0.try_wait().unwrap() {
            panic!("the bake ended ({status}) before it wrote tiles");
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no staging folder"
        );
        std::thread::sleep(Duration::from_millis(5));
    };
    // One shell sends them all with its own `kill`, so that signals meant to come close
    // together do, however loaded the machine (no process started between them).
    let script: Vec<String> = signals
        .iter()
        .map(|(signal, pause_ms)| {
            format!(
                "sleep {}; kill {signal} {}",
                *pause_ms as f64 / 1000.0,
                child.0.id()
            )
        })
        .collect();
    let kill = std::process::Command::new("sh")
        .args(["-c", &script.join("; ")])
        .status()
        .unwrap();
    assert!(kill.success());
    let deadline = Instant::now() + Duration::from_secs(30);
    let status = loop {
        if let Some(status) = child.0.try_wait().unwrap() {
            break status;
        }
        assert!(
            Instant::now() < deadline,
            "the bake did not stop on {signals:?}"
        );
        std::thread::sleep(Duration::from_millis(10));
    };
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut child.0.stderr.take().unwrap(), &mut stderr).unwrap();
    assert_eq!(status.code(), Some(130), "{stderr}");
    assert!(stderr.contains("bake cancelled"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(!staging.exists(), "{} is left", staging.display());
    assert!(!dir.path().join("w").exists());
}

/// An old manifest that a newer loader refuses outside the parts a bake keeps (a colour of four
/// values, a pyramid whose finest tiles are too small) is re-baked with `--replace` keeping its
/// plant types, paths and wind scenes: only they are read from it (it was refused whole, and
/// re-baking, the mend, needed `--fresh-manifest`, which drops them).
#[test]
fn replace_keeps_the_hand_made_parts_of_a_manifest_refused_elsewhere() {
    use verdant::world::Manifest;
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path(), "hills", DEM_SIZE, DEM_CELLS, DEM_SCALE, hills);
    let w = dir.path().join("w");
    bake(&replace_opts(dem.clone(), w.clone()), &mut |_, _, _| {}).unwrap();
    let toml = w.join("world.toml");
    let baked = std::fs::read_to_string(&toml).unwrap();
    let derived = Manifest::from_path(&toml).unwrap().pyramid.derived_levels;
    let old = baked
        .replacen("sun_color = [", "sun_color = [99.0, ", 1)
        .replacen(
            &format!("derived_levels = {derived}"),
            "derived_levels = 20",
            1,
        )
        + HAND_MADE;
    std::fs::write(&toml, &old).unwrap();
    assert!(Manifest::from_path(&toml).is_err());
    let report = bake(&replace_opts(dem, w.clone()), &mut |_, _, _| {}).unwrap();
    assert_eq!(report.carried.plant_types, ["poppy", "bush"]);
    assert_eq!(report.carried.paths, ["my-flight"]);
    assert_eq!(report.carried.wind_scenes, ["gale"]);
    let rebaked = Manifest::from_path(&toml).unwrap();
    assert_eq!(rebaked.pyramid.derived_levels, derived);
    assert_eq!(rebaked.plant_types.len(), 2);
}

/// A world folder whose bake was stopped while moving the world in (its staging folder beside
/// it holds the journal of that move) says so and how to put it right, not just "world.toml:
/// file not found".
#[test]
fn a_world_whose_bake_stopped_while_moving_it_in_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let w = dir.path().join("w");
    std::fs::create_dir_all(w.join("tiles")).unwrap();
    let staging = dir.path().join(".w.baking.4242-0");
    std::fs::create_dir_all(&staging).unwrap();
    std::fs::write(staging.join("publishing.json"), "{}").unwrap();
    let e = verdant::World::open(&w).unwrap_err().to_string();
    assert!(
        e.contains("no world.toml")
            && e.contains(".w.baking.4242-0")
            && e.contains("run the bake into it again"),
        "{e}"
    );
    std::fs::remove_dir_all(&w).unwrap();
    let e = verdant::World::open(&w).unwrap_err().to_string();
    assert!(
        e.contains("no such folder") && e.contains(".w.baking.4242-0"),
        "{e}"
    );
    // A staging folder that is not moving a world in (a bake under way) changes nothing.
    std::fs::remove_file(staging.join("publishing.json")).unwrap();
    let e = verdant::World::open(&w).unwrap_err().to_string();
    assert!(e.contains("world directory not found"), "{e}");
    std::fs::create_dir_all(&w).unwrap();
    let e = verdant::World::open(&w).unwrap_err().to_string();
    assert!(e.ends_with("world.toml: file not found"), "{e}");
}

/// An output folder where another file system is mounted (a volume, a USB disk) is refused
/// before anything is read or made: the world is staged beside it, on its parent's file system,
/// and the move in at the end failed ("Invalid cross-device link") after the whole bake.
/// `/proc` is a mount point on every Linux system.
#[cfg(target_os = "linux")]
#[test]
fn an_output_folder_that_is_a_mount_point_is_refused_before_the_bake() {
    let dem = common::root().join("tests/data/east_bay_768.png");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(["bake", "--dem", dem.to_str().unwrap(), "--out", "/proc"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{stderr}");
    for want in [
        "--out /proc",
        "another file system is mounted",
        "bake into a folder inside it, such as /proc/world",
    ] {
        assert!(stderr.contains(want), "{want:?} in {stderr}");
    }
    assert!(!stderr.contains("read "), "the DEM was read: {stderr}");
    let left: Vec<String> = staging_folders(Path::new("/"))
        .into_iter()
        .filter(|n| n.starts_with(".proc.baking."))
        .collect();
    assert!(left.is_empty(), "{left:?}");
}

/// Under an address-space limit (`ulimit -v`, a batch job's `vmem`) the default memory limit of
/// 2048 MiB let a large DEM's bake plan more than the process could map: it ended on a failed
/// allocation (status 134) or a panic starting its threads. The default now fits under the
/// limit, saying so, and a `--memory-mib` above it is warned of.
#[cfg(target_os = "linux")]
#[test]
fn the_default_memory_limit_fits_under_the_address_space_limit() {
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path(), "hills", DEM_SIZE, DEM_CELLS, DEM_SCALE, hills);
    let bake_under = |limit_kib: u64, more: &str, out: &str| {
        let script = format!(
            "ulimit -v {limit_kib} && exec \"$0\" bake --dem \"$1\" --out {out} --cell-size 20 \
             --tile-cells 16 --levels 2 {more}"
        );
        std::process::Command::new("sh")
            .args([
                "-c",
                &script,
                env!("CARGO_BIN_EXE_verdant"),
                dem.to_str().unwrap(),
            ])
            .current_dir(dir.path())
            .output()
            .unwrap()
    };
    // 1 GiB: three quarters of what is left after the process's own mappings.
    let run = bake_under(1 << 20, "", "a");
    let (stdout, stderr) = (
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr),
    );
    assert!(run.status.success(), "{stderr}");
    let note = "not the default 2048 MiB: the address-space limit (ulimit -v) of 1024 MiB leaves \
                this process";
    assert!(stderr.contains(note), "{note:?} in {stderr}");
    let limit: u64 = stderr
        .split("memory: limit ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("the limit in {stderr}"));
    assert!((600..=768).contains(&limit), "{limit} MiB of 1024");
    assert!(stdout.contains(&format!("(limit {limit} MiB")), "{stdout}");
    assert!(dir.path().join("a/world.toml").is_file());

    // A limit asked for above what the process can hold is kept, with a warning.
    let run = bake_under(1 << 20, "--memory-mib 2048", "b");
    let (stdout, stderr) = (
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr),
    );
    assert!(run.status.success(), "{stderr}");
    let warning = "warning: --memory-mib 2048 is more than this process can hold: the \
                   address-space limit (ulimit -v) of 1024 MiB";
    assert!(stderr.contains(warning), "{warning:?} in {stderr}");
    assert!(
        stderr.contains(&format!("(--memory-mib {limit} fits)")),
        "{stderr}"
    );
    assert!(stdout.contains("(limit 2048 MiB"), "{stdout}");

    // One that fits says nothing.
    let run = bake_under(1 << 20, "--memory-mib 256", "c");
    assert!(run.status.success());
    assert!(!String::from_utf8_lossy(&run.stderr).contains("memory"));
}
