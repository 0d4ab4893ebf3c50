//! `verdant check`: every tile of a world read as the renderer reads it, on disk and over HTTP;
//! a tile file copied over another or left by another bake is listed by tile and file, with a
//! non-zero exit.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use verdant::bake::{BakeOptions, bake};
use verdant::tools::serve::WorldServer;
use verdant::world::{TileFile, TileId, tile_path};

/// A small world baked from rolling hills with `seed` into `dir/name`.
fn small_world(dir: &Path, name: &str, seed: u64) -> PathBuf {
    let dem = dir.join("hills.png");
    if !dem.is_file() {
        common::write_dem(
            dir,
            "hills",
            [120, 100],
            [10.0, 10.0],
            [0.0, 0.01],
            |x, y| 200.0 + 40.0 * (x / 200.0).sin() * (y / 300.0).cos(),
        );
    }
    let out = dir.join(name);
    let opts = BakeOptions {
        dem,
        out: out.clone(),
        cell_size_m: Some(20.0),
        tile_cells: 16,
        stored_levels: 2,
        seed,
        ..Default::default()
    };
    bake(&opts, &mut |_, _, _| {}).unwrap();
    out
}

fn check(world: &str) -> Output {
    Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(["check", world, "--threads", "2"])
        .output()
        .expect("run verdant check")
}

fn text(out: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn check_passes_a_whole_world_and_lists_copied_and_foreign_tile_files() {
    let dir = tempfile::tempdir().unwrap();
    let world = small_world(dir.path(), "hills", 7);
    let other = small_world(dir.path(), "other", 8);
    let shown = world.to_str().unwrap();

    let out = check(shown);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}{stderr}");
    assert!(stdout.contains("of hills read"), "{stdout}");
    assert!(stdout.contains("every tile is whole"), "{stdout}");
    assert!(
        stdout.contains("every file checked against its stamp"),
        "{stdout}"
    );

    // One tile's type map copied over another's, and a density map from the other bake.
    let [a, b, c] = [
        TileId::new(1, 0, 0),
        TileId::new(1, 1, 0),
        TileId::new(0, 0, 0),
    ];
    std::fs::copy(
        tile_path(&world, b, TileFile::Type),
        tile_path(&world, a, TileFile::Type),
    )
    .unwrap();
    std::fs::copy(
        tile_path(&other, c, TileFile::Density),
        tile_path(&world, c, TileFile::Density),
    )
    .unwrap();
    let out = check(shown);
    let (stdout, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(1), "{stdout}{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    let lines: Vec<&str> = stdout.lines().collect();
    // Coarsest level first.
    assert!(
        lines[0].starts_with("L0/0_0: ") && lines[0].contains("0_0.density.png"),
        "{stdout}"
    );
    assert!(lines[0].contains("another bake"), "{stdout}");
    assert!(
        lines[1].starts_with("L1/0_0: ") && lines[1].contains("holds L1/1_0.type.png"),
        "{stdout}"
    );
    assert!(
        stderr.contains("2 of ") && stderr.contains("tiles of hills cannot be read"),
        "{stderr}"
    );

    // The same world served over HTTP: the same two tiles.
    let server = WorldServer::start(&world, "127.0.0.1:0").unwrap();
    let out = check(&server.url());
    let (stdout, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(1), "{stdout}{stderr}");
    assert!(
        stdout.contains(&format!("{}tiles/L1/0_0.type.png", server.url())),
        "{stdout}"
    );
    assert_eq!(
        stdout.lines().filter(|l| l.starts_with('L')).count(),
        2,
        "{stdout}"
    );
}

/// A world without a bake_id (the committed default world, baked before stamps) is read whole,
/// and the check says that it had no stamps to check.
#[test]
fn check_of_a_world_without_stamps_says_so() {
    let out = check(common::default_world().to_str().unwrap());
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}{stderr}");
    assert!(stdout.contains("no stamps checked"), "{stdout}");
}
