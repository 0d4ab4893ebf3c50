//! Unit tests of the baker's stages.

use glam::DVec2;

use super::paint::{Painted, fbm, paint_sample};
use super::*;

#[test]
fn nice_cell_sizes() {
    assert_eq!(nice_cell_size(24.585), 25.0);
    assert_eq!(nice_cell_size(30.888), 25.0);
    assert_eq!(nice_cell_size(10.2), 10.0);
    assert_eq!(nice_cell_size(0.95), 1.0);
    assert_eq!(nice_cell_size(4.4), 5.0);
}

#[test]
fn steep_ground_is_bare() {
    for slope in [36.0, 45.0, 80.0] {
        for k in 0..50 {
            let p = DVec2::new(k as f64 * 37.0, k as f64 * 91.0);
            assert_eq!(paint_sample(slope, 0.3, p, 7), (0, 0));
        }
    }
}

/// Every index the painter gives names one of the grass types a bake writes, and there are
/// no more of those than the renderer draws.
#[test]
fn painted_indices_name_the_types_written() {
    let types = default_grass_types().len();
    assert!(types <= crate::world::MAX_GRASS_TYPES);
    let mut seen = [false; 256];
    for seed in [1, 7, 12345] {
        for s in 0..=90 {
            for a in 0..=20 {
                for k in 0..20 {
                    let p = DVec2::new(k as f64 * 613.0, (s * 21 + a) as f64 * 97.0);
                    let (kind, _) = paint_sample(f64::from(s), f64::from(a) / 20.0, p, seed);
                    seen[usize::from(kind)] = true;
                }
            }
        }
    }
    let used: Vec<usize> = (0..256).filter(|&k| seen[k]).collect();
    assert_eq!(
        used,
        (0..types).collect::<Vec<_>>(),
        "every type, and no other"
    );
}

/// A painted index beyond the manifest's types is refused before anything is written.
#[test]
fn painted_indices_beyond_the_types_are_refused() {
    let grid = resample::Grid {
        width: 2,
        height: 2,
        origin: [0, 0],
        stride: 1,
        shape: resample::Shape {
            size: [2, 2],
            margin: 0,
            cell: 1.0,
            finest: 0,
            derived: 0,
        },
        heights: vec![0.0; 4],
    };
    let mut painted = Painted {
        grid,
        grass_type: vec![0, 1, 2, 3],
        density: vec![9; 4],
        material: Vec::new(),
        cancel: None,
    };
    let mut manifest = crate::world::Manifest::parse(
        include_str!("../../worlds/santa-cruz/world.toml"),
        Path::new("world.toml"),
    )
    .unwrap();
    assert!(check_painted_types(&painted, &manifest, Path::new("w/world.toml")).is_ok());
    painted.grass_type[2] = 4;
    let err = check_painted_types(&painted, &manifest, Path::new("w/world.toml")).unwrap_err();
    assert!(matches!(err, WorldError::BadTileData { .. }), "{err}");
    assert!(err.to_string().contains("grass type index 4"), "{err}");
    manifest.grass_types.truncate(2);
    painted.grass_type[2] = 2;
    assert!(check_painted_types(&painted, &manifest, Path::new("w/world.toml")).is_err());
}

/// Output paths resolve to a folder with a name and a parent, so that the staging folder
/// goes beside it.
#[test]
fn output_paths_resolve_without_dots() {
    let dir = tempfile::tempdir().unwrap();
    let base = dir.path().canonicalize().unwrap();
    std::fs::create_dir_all(base.join("w/sub")).unwrap();
    for (given, want) in [
        (base.join("w"), base.join("w")),
        (base.join("w/."), base.join("w")),
        (base.join("w/sub/.."), base.join("w")),
        (base.join("w/sub/../"), base.join("w")),
        (base.join("new/deeper/.."), base.join("new")),
        (base.join("w/sub/new/../.."), base.join("w")),
    ] {
        assert_eq!(resolve_out(&given).unwrap(), want, "{}", given.display());
    }
    for bad in ["/", "/..", ""] {
        let err = resolve_out(Path::new(bad)).unwrap_err();
        assert!(err.to_string().starts_with("--out"), "{err}");
    }
}

/// When a world cannot be moved into place, the one it was to replace is put back, and the
/// folder's other files are never touched.
#[test]
fn a_failed_publish_puts_the_previous_world_back() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().canonicalize().unwrap().join("w");
    std::fs::create_dir_all(out.join("tiles/L0")).unwrap();
    std::fs::write(out.join("tiles/L0/0_0.type.png"), "old tile").unwrap();
    std::fs::write(out.join("world.toml"), "[pyramid] # old manifest").unwrap();
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    let staging = Staging::begin(&out, &out, true).unwrap();
    let dir_of_staging = staging.dir.clone();
    assert_eq!(dir_of_staging.parent(), out.parent());
    // The new world lacks its manifest: the last move fails.
    std::fs::create_dir_all(staging.world().join("tiles/L0")).unwrap();
    std::fs::write(staging.world().join("tiles/L0/0_0.type.png"), "new tile").unwrap();
    let err = staging.publish(None).unwrap_err();
    assert!(err.to_string().contains("world.toml"), "{err}");
    assert_eq!(
        std::fs::read(out.join("world.toml")).unwrap(),
        b"[pyramid] # old manifest"
    );
    assert_eq!(
        std::fs::read(out.join("tiles/L0/0_0.type.png")).unwrap(),
        b"old tile"
    );
    assert_eq!(std::fs::read(out.join("notes.txt")).unwrap(), b"mine");
    assert!(!dir_of_staging.exists());

    // Into a new folder: nothing is left at all.
    let new = dir.path().canonicalize().unwrap().join("new");
    let staging = Staging::begin(&new, &new, false).unwrap();
    assert!(staging.publish(None).is_err());
    assert!(!new.exists());
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert_eq!(left.len(), 1, "{left:?}");
}

#[test]
fn noise_is_deterministic_and_bounded() {
    for k in 0..1000 {
        let p = DVec2::new(k as f64 * 0.37 - 100.0, k as f64 * 0.11);
        let v = fbm(p, 3, 3);
        assert!((0.0..=1.0).contains(&v));
        assert_eq!(v, fbm(p, 3, 3));
    }
    assert_ne!(
        fbm(DVec2::new(0.5, 0.5), 1, 3),
        fbm(DVec2::new(0.5, 0.5), 2, 3)
    );
}

/// A bake that chooses its levels keeps the level-0 tiles few enough to keep resident, and
/// small worlds at the three levels they always had.
#[test]
fn automatic_levels_keep_the_root_tiles_few() {
    // Santa Cruz: 25.6 km at 25 m.
    assert_eq!(auto_levels([25_575.0, 25_575.0], 25.0, 128), 3);
    // Sixteen 1-arc-second tiles: 356 x 445 km at 25 m: 980 root tiles at 3 levels, 63 at 5.
    assert_eq!(auto_levels([346_500.0, 444_000.0], 25.0, 128), 5);
    for extent in [1e3, 1e5, 1e6, 1e7] {
        let levels = auto_levels([extent, extent], 10.0, 128);
        let root = 10.0 * 128.0 * 2f64.powi(i32::from(levels) - 1);
        let n = (extent / root).ceil();
        assert!(
            n * n <= MAX_AUTO_ROOT_TILES as f64 || levels == 12,
            "{extent}: {levels}"
        );
    }
}

/// Six derived levels, or as many more as bring the finest tiles within 64 m, within 24
/// levels in all.
#[test]
fn coarse_dems_get_the_derived_levels_that_make_grass_sized_tiles() {
    use super::derived_levels_for;
    // SRTM at 30 m cells in 128-cell tiles: 3,840 m tiles, six levels make 60 m.
    assert_eq!(derived_levels_for(30.0 * 128.0, 3), 6);
    // Finer data keeps six.
    assert_eq!(derived_levels_for(1.0 * 128.0, 3), 6);
    // A 1 km global DEM: 128 km tiles, eleven levels make 62.5 m.
    assert_eq!(derived_levels_for(1000.0 * 128.0, 2), 11);
    // Lidar at 5 cm cells: 6.4 m tiles, three levels make 0.8 m (four would be 0.4 m).
    assert_eq!(derived_levels_for(0.05 * 128.0, 3), 3);
    assert_eq!(derived_levels_for(0.001 * 128.0, 3), 0);
    // Within 24 levels in all.
    assert_eq!(derived_levels_for(1.0e7, 20), 4);
    assert_eq!(derived_levels_for(1.0e7, 24), 0);
}

/// The height the camera paths are fitted to is the ground the renderer draws: the finest
/// derived level, as the derivation's CPU mirror makes it from the stored tile, at its samples
/// and between them, on relief that curves strongly from cell to cell (where the grid's
/// bilinear surface lies metres off it: 45 m below it at 10 km cells, the paths underground).
#[test]
fn path_heights_are_the_drawn_ground_of_the_finest_derived_level() {
    use crate::stream::{DeriveParams, derive_child};
    use crate::world::{TileData, TileId};
    let pyramid = Pyramid {
        root_tile_size_m: 80.0,
        root_tiles: [1, 1],
        tile_cells: 8,
        border: 2,
        stored_levels: 1,
        derived_levels: 3,
    };
    let shape = resample::Shape::of(&pyramid);
    let side = shape.size[0] as usize;
    let mut heights = Vec::with_capacity(side * side);
    for b in 0..side {
        for a in 0..side {
            let (x, y) = (a as f32, b as f32);
            let bumps = ((7 * a + 13 * b) % 5) as f32;
            heights.push(300.0 + 80.0 * (1.3 * x + 0.7 * y).sin() + 40.0 * bumps);
        }
    }
    let grid = resample::Grid {
        width: side,
        height: side,
        origin: [0, 0],
        stride: 1,
        shape,
        heights: heights.clone(),
    };
    // The stored tile's samples are the grid's: both start a border before the world.
    let root = TileId::new(0, 0, 0);
    let samples = side * side;
    let stored = TileData {
        id: root,
        size: pyramid.samples_per_side(),
        heights,
        grass_type: vec![0; samples],
        density: vec![0; samples],
        material: Vec::new(),
    };
    let params = DeriveParams::default().bicubic();
    let mut level = vec![stored];
    for _ in 0..pyramid.derived_levels {
        level = level
            .iter()
            .flat_map(|parent| {
                parent
                    .id
                    .children()
                    .map(|c| derive_child(&pyramid, parent, c, &params))
            })
            .collect();
    }
    // Away from the grid's edges (3 cells: the reach of the halvings), where the derivation
    // repeats its tiles' edge samples.
    let cell = pyramid.cell_size_m(0);
    let inside = |p: DVec2| p.min_element() >= cell && p.max_element() <= 7.0 * cell;
    let mut checked = 0;
    for tile in &level {
        let n = pyramid.tile_cells + pyramid.border;
        for j in pyramid.border..n {
            for i in pyramid.border..n {
                let p = pyramid.sample_position(tile.id, i, j);
                if !inside(p) {
                    continue;
                }
                let h = |i, j| f64::from(tile.height_at(i, j));
                // At the sample, and in the middle of its cell (drawn bilinearly).
                let mid = 0.25 * (h(i, j) + h(i + 1, j) + h(i, j + 1) + h(i + 1, j + 1));
                let half = DVec2::splat(0.5 * pyramid.cell_size_m(tile.id.level));
                for (q, drawn) in [(p, h(i, j)), (p + half, mid)] {
                    let fitted = grid.height(q);
                    assert!(
                        (fitted - drawn).abs() < 1e-3,
                        "at {q}: fitted {fitted} m, drawn {drawn} m"
                    );
                    checked += 1;
                }
            }
        }
    }
    assert!(checked > 1000, "{checked}");
}

/// A cell too small for the tile's cells (the finest tiles, where the grass grows, at least
/// 0.5 m wide) is refused in plain words, naming the option or the DEM's sidecar and the least
/// cell, before anything is written.
#[test]
fn cells_too_small_for_the_tiles_are_refused_naming_the_least() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("fine.png");
    image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(8, 8, |c, r| {
        image::Luma([(100 + r + c) as u16])
    })
    .save(&png)
    .unwrap();
    let write_sidecar = |cell: f64| {
        let json = serde_json::json!({
            "width": 8,
            "height": 8,
            "cell_size_m": { "east_west": cell, "north_south": cell },
        });
        std::fs::write(png.with_extension("json"), json.to_string()).unwrap();
    };
    write_sidecar(10.0);
    let out = dir.path().join("w");
    let refusal = |cell_size_m: Option<f64>, tile_cells: u32| {
        let opts = BakeOptions {
            dem: png.clone(),
            out: out.clone(),
            cell_size_m,
            tile_cells,
            ..Default::default()
        };
        let e = bake(&opts, &mut |_, _, _| {}).unwrap_err().to_string();
        assert!(!out.exists(), "{e}");
        assert!(
            !e.contains("derived_levels") && !e.contains("root tile"),
            "{e}"
        );
        e
    };
    let e = refusal(Some(0.002), 128);
    for want in [
        "--cell-size 0.002",
        "at least 0.00390625 m",
        "--tile-cells 128",
        "--tile-cells 256",
    ] {
        assert!(e.contains(want), "{e} lacks {want:?}");
    }
    // Below a millimetre no tile size helps.
    let e = refusal(Some(0.0005), 1024);
    assert!(
        e.contains("--cell-size 0.0005: must be at least 0.001 m"),
        "{e}"
    );
    // The DEM's own cell, where no --cell-size is given: its sidecar named.
    for cell in [0.001, 1e-30] {
        write_sidecar(cell);
        let e = refusal(None, 128);
        for want in [
            "fine.json",
            "cell_size_m",
            "at least 0.00390625 m",
            "--cell-size 0.00390625",
        ] {
            assert!(e.contains(want), "{cell}: {e} lacks {want:?}");
        }
    }
}
