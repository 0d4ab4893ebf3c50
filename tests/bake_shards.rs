//! Sharded bakes: shards run in any order and a finish step make the world byte for byte as the
//! unsharded bake does; the world appears only after the finish; a killed shard is re-run
//! alone; a finished shard is not run again; a stopped finish keeps the shards' tiles; a finish
//! refuses shards whose tiles are missing; parts of another bake are refused.

use std::path::{Path, PathBuf};

use verdant::bake::{BakeOptions, BakeStage, CancelFlag, ShardStep, bake};

mod common;

use common::read_all_files;

fn dem(dir: &Path) -> PathBuf {
    common::write_dem(
        dir,
        "hills",
        [161, 161],
        [20.0, 20.0],
        [0.0, 0.1],
        |x, y| 200.0 + 60.0 * (x / 410.0).sin() * (y / 530.0).cos() + 0.01 * x,
    )
}

fn opts(dem: &Path, out: &Path, shard: Option<ShardStep>) -> BakeOptions {
    BakeOptions {
        dem: dem.to_path_buf(),
        out: out.to_path_buf(),
        name: Some("hills".into()),
        cell_size_m: Some(20.0),
        tile_cells: 16,
        stored_levels: 3,
        shard,
        ..Default::default()
    }
}

fn run(o: &BakeOptions) -> Result<verdant::bake::BakeReport, verdant::world::WorldError> {
    bake(o, &mut |_, _, _| {})
}

#[test]
fn shards_and_their_finish_make_the_unsharded_world_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    let dem = dem(dir.path());
    let whole = dir.path().join("whole");
    run(&opts(&dem, &whole, None)).unwrap();

    for count in [3, 2] {
        // Three shards: the root tiles (nine) are too few to deal out, so level 1 is; the roots
        // cross shards and are the finish's. Two shards: the roots are dealt out, nothing
        // crosses, and the finish publishes the shards' manifest without baking again.
        let out = dir.path().join(format!("sharded{count}"));
        let parts = verdant::bake::shard::parts_dir(&out);
        let mut written = 0;
        for index in (0..count).rev() {
            let r = run(&opts(&dem, &out, Some(ShardStep::Shard { index, count }))).unwrap();
            assert!(!r.already_done);
            assert!(r.tiles_written > 0, "shard {index} wrote nothing");
            written += r.tiles_written;
            // Nothing is published before the finish.
            assert!(!out.exists(), "the world appeared before the finish");
        }
        assert!(parts.is_dir());
        let r = run(&opts(&dem, &out, Some(ShardStep::Finish { count }))).unwrap();
        let all = r.tiles_written;
        if count == 3 {
            assert!(
                written < all,
                "the finish writes the tiles that cross shards"
            );
        } else {
            assert_eq!(written, all, "every tile is a shard's");
        }
        assert!(
            !parts.exists(),
            "the parts folder is removed once the world is out"
        );
        let (a, b) = (read_all_files(&whole), read_all_files(&out));
        assert_eq!(
            a.keys().collect::<Vec<_>>(),
            b.keys().collect::<Vec<_>>(),
            "the same files"
        );
        for (k, v) in &a {
            assert!(b[k] == *v, "{count} shards: {} differs", k.display());
        }
        assert!(a.len() as u64 >= 3 * all);
    }
}

#[test]
fn a_killed_shard_is_rerun_alone_and_a_finished_one_is_not_run_again() {
    let dir = tempfile::tempdir().unwrap();
    let dem = dem(dir.path());
    let out = dir.path().join("w");
    let count = 2;
    let shard = |index| Some(ShardStep::Shard { index, count });
    run(&opts(&dem, &out, shard(0))).unwrap();
    // Shard 1 is stopped after its first tile.
    let cancel = CancelFlag::new();
    let mut o = opts(&dem, &out, shard(1));
    o.cancel = Some(cancel.clone());
    let killed = bake(&o, &mut |stage, done, _| {
        if stage == BakeStage::WriteTiles && done >= 1 {
            cancel.cancel();
        }
    });
    assert!(killed.is_err());
    // The finish is refused, naming the shard that is not done; nothing is published.
    let e = run(&opts(&dem, &out, Some(ShardStep::Finish { count })))
        .unwrap_err()
        .to_string();
    assert!(e.contains("shard 1 of 2 not done"), "{e}");
    assert!(!out.exists());
    // Shard 0 again: already done, nothing written.
    let parts = verdant::bake::shard::parts_dir(&out);
    let before = read_all_files(&parts);
    let again = run(&opts(&dem, &out, shard(0))).unwrap();
    assert!(again.already_done);
    assert_eq!(read_all_files(&parts), before);
    // Shard 1 re-run alone, then the finish.
    run(&opts(&dem, &out, shard(1))).unwrap();
    run(&opts(&dem, &out, Some(ShardStep::Finish { count }))).unwrap();
    verdant::World::open(&out).unwrap();
}

/// Every tile file under `dir`'s `tiles/`, relative to `dir`.
fn tile_files(dir: &Path) -> Vec<PathBuf> {
    read_all_files(dir)
        .into_keys()
        .filter(|p| p.starts_with("tiles"))
        .collect()
}

/// A finish stopped after it wrote its own tiles, as it writes the manifest, leaves the
/// shards' tiles in the parts folder and publishes nothing; the next finish makes the whole
/// world.
#[test]
fn a_stopped_finish_keeps_the_shards_tiles_for_the_next() {
    let dir = tempfile::tempdir().unwrap();
    let dem = dem(dir.path());
    let whole = dir.path().join("whole");
    run(&opts(&dem, &whole, None)).unwrap();
    // Three shards: the roots cross shards, so the finish bakes them before it publishes.
    let count = 3;
    let out = dir.path().join("w");
    let parts = verdant::bake::shard::parts_dir(&out);
    for index in 0..count {
        run(&opts(&dem, &out, Some(ShardStep::Shard { index, count }))).unwrap();
    }
    let shards_tiles = tile_files(&parts);
    assert!(!shards_tiles.is_empty());
    let cancel = CancelFlag::new();
    let mut o = opts(&dem, &out, Some(ShardStep::Finish { count }));
    o.cancel = Some(cancel.clone());
    let stopped = bake(&o, &mut |stage, _, _| {
        if stage == BakeStage::WriteManifest {
            cancel.cancel();
        }
    });
    assert!(stopped.is_err(), "the finish was to be stopped");
    assert!(!out.exists(), "nothing is published");
    let kept = tile_files(&parts);
    for file in &shards_tiles {
        assert!(kept.contains(file), "{} lost", file.display());
    }
    let staging: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".w.") && n != ".w.shards")
        .collect();
    assert!(staging.is_empty(), "{staging:?}");

    run(&opts(&dem, &out, Some(ShardStep::Finish { count }))).unwrap();
    assert!(!parts.exists());
    assert!(
        read_all_files(&whole) == read_all_files(&out),
        "the world after a stopped finish differs from the unsharded one"
    );
}

/// A finish refuses to publish while a shard recorded done lacks any of its tile files,
/// naming the file and telling to run the shard again, which then bakes its tiles again.
/// How a shard's tile file is lost or damaged before the finish.
#[derive(Clone, Copy, Debug)]
enum Damage {
    Removed,
    /// Cut short, as a lost write leaves it.
    Truncated,
    /// Another tile's file copied over it (a part copied from elsewhere).
    Swapped,
}

#[test]
fn a_finish_refuses_shards_whose_tiles_are_missing_or_damaged() {
    let dir = tempfile::tempdir().unwrap();
    let dem = dem(dir.path());
    let whole = dir.path().join("whole");
    run(&opts(&dem, &whole, None)).unwrap();
    // Two shards: the finish publishes the shards' manifest; three: it bakes the roots first.
    for (count, damage) in [
        (2, Damage::Removed),
        (3, Damage::Removed),
        (2, Damage::Truncated),
        (3, Damage::Swapped),
    ] {
        let out = dir.path().join(format!("w{count}{damage:?}"));
        let parts = verdant::bake::shard::parts_dir(&out);
        for index in 0..count {
            run(&opts(&dem, &out, Some(ShardStep::Shard { index, count }))).unwrap();
        }
        // The last tile file of the finest level is lost or damaged.
        let files: Vec<PathBuf> = tile_files(&parts)
            .into_iter()
            .filter(|p| p.starts_with("tiles/L2"))
            .collect();
        let gone = files.last().unwrap().clone();
        let at = parts.join(&gone);
        let why = match damage {
            Damage::Removed => {
                std::fs::remove_file(&at).unwrap();
                "missing"
            }
            Damage::Truncated => {
                let len = std::fs::metadata(&at).unwrap().len();
                let f = std::fs::OpenOptions::new().write(true).open(&at).unwrap();
                f.set_len(len / 2).unwrap();
                "cannot be read"
            }
            Damage::Swapped => {
                // The same kind of file of another tile.
                let kind = gone.extension().unwrap();
                let other = files
                    .iter()
                    .find(|p| {
                        *p != &gone && p.to_string_lossy().ends_with(&*kind.to_string_lossy())
                    })
                    .unwrap();
                std::fs::copy(parts.join(other), &at).unwrap();
                "cannot be read"
            }
        };
        let e = run(&opts(&dem, &out, Some(ShardStep::Finish { count })))
            .unwrap_err()
            .to_string();
        let name = gone.file_name().unwrap().to_string_lossy();
        assert!(
            e.contains(&*name) && e.contains(why) && e.contains(&format!("--shard I/{count}")),
            "{count} shards, {damage:?}: {e}"
        );
        assert!(
            !out.exists(),
            "{count} shards, {damage:?}: nothing is published"
        );
        // The shard that lost it is run again; the others are done.
        let rerun: Vec<u32> = (0..count)
            .filter(|&index| {
                !run(&opts(&dem, &out, Some(ShardStep::Shard { index, count })))
                    .unwrap()
                    .already_done
            })
            .collect();
        assert_eq!(rerun.len(), 1, "{count} shards: run again {rerun:?}");
        assert!(e.contains(&format!("shard {} of {count}", rerun[0])), "{e}");
        run(&opts(&dem, &out, Some(ShardStep::Finish { count }))).unwrap();
        assert!(
            read_all_files(&whole) == read_all_files(&out),
            "{count} shards: the world differs from the unsharded one"
        );
    }
}

#[test]
fn parts_of_another_bake_and_bad_shards_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let dem = dem(dir.path());
    let out = dir.path().join("w");
    run(&opts(
        &dem,
        &out,
        Some(ShardStep::Shard { index: 0, count: 2 }),
    ))
    .unwrap();
    // Another seed is another bake: its shard is refused, naming the parts folder.
    let mut other = opts(&dem, &out, Some(ShardStep::Shard { index: 1, count: 2 }));
    other.seed = 7;
    let e = run(&other).unwrap_err().to_string();
    assert!(e.contains(".w.shards") && e.contains("another bake"), "{e}");
    assert!(
        e.contains("--shard 1/2") && e.contains("other options or input files"),
        "{e}"
    );
    // The same bake in another count of shards is refused naming the count to use (it was
    // "another bake's", naming --shard for a finish).
    let e = run(&opts(
        &dem,
        &out,
        Some(ShardStep::Shard { index: 1, count: 3 }),
    ))
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("--shard 1/3") && e.contains("sharded 2 ways there, not 3; run --shard 1/2"),
        "{e}"
    );
    let e = run(&opts(&dem, &out, Some(ShardStep::Finish { count: 3 })))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("--finish-shards 3") && e.contains("run --finish-shards 2"),
        "{e}"
    );
    let e = run(&opts(
        &dem,
        &out,
        Some(ShardStep::Shard { index: 2, count: 3 }),
    ))
    .unwrap_err()
    .to_string();
    assert!(e.contains("run --shard I/2 (I from 0 to 1)"), "{e}");
    // A folder of the parts' name that a bake did not make is never adopted (the finish
    // removes the parts folder): its files stay.
    let mine = dir.path().join("m");
    let theirs = verdant::bake::shard::parts_dir(&mine);
    std::fs::create_dir_all(&theirs).unwrap();
    std::fs::write(theirs.join("notes.txt"), "keep me").unwrap();
    let e = run(&opts(
        &dem,
        &mine,
        Some(ShardStep::Shard { index: 0, count: 2 }),
    ))
    .unwrap_err()
    .to_string();
    assert!(
        e.contains(".m.shards") && e.contains("not a sharded bake's"),
        "{e}"
    );
    assert_eq!(
        std::fs::read_to_string(theirs.join("notes.txt")).unwrap(),
        "keep me"
    );
    assert!(!theirs.join("fingerprint").exists());
    for (step, want) in [
        (ShardStep::Shard { index: 2, count: 2 }, "2/2"),
        (ShardStep::Shard { index: 0, count: 0 }, "1..=10000"),
        (
            ShardStep::Finish { count: 0 },
            "--finish-shards 0: must be a shard count",
        ),
        (
            ShardStep::Shard { index: 0, count: 0 },
            "--shard 0: must be a shard count",
        ),
    ] {
        let e = run(&opts(&dem, &dir.path().join("x"), Some(step)))
            .unwrap_err()
            .to_string();
        assert!(e.contains(want), "{e}");
    }
}

/// A shard refused for its input (here a DEM whose cells are too small for the tiles) leaves no
/// parts folder: it left one holding its fingerprint, and the same shard run again as the error
/// advised (with --cell-size) was refused as "another bake's".
#[test]
fn a_shard_refused_for_its_dem_leaves_no_parts_folder() {
    let dir = tempfile::tempdir().unwrap();
    let dem = common::write_dem(
        dir.path(),
        "tiny",
        [161, 161],
        [0.001, 0.001],
        [0.0, 0.1],
        |x, y| 1.0 + 0.1 * x + 0.05 * y,
    );
    let out = dir.path().join("w");
    let mut o = opts(&dem, &out, Some(ShardStep::Shard { index: 0, count: 2 }));
    o.cell_size_m = None;
    o.stored_levels = 0;
    let e = run(&o).unwrap_err().to_string();
    assert!(e.contains("pass --cell-size"), "{e}");
    let parts = verdant::bake::shard::parts_dir(&out);
    assert!(!parts.exists(), "{} was left behind", parts.display());
    assert!(!out.exists());
    o.cell_size_m = Some(0.05);
    let report = run(&o).unwrap();
    assert!(report.tiles_written > 0);
    assert!(parts.join("fingerprint").is_file());
}

#[test]
fn the_command_line_runs_shards_and_the_finish() {
    let dir = tempfile::tempdir().unwrap();
    let dem = dem(dir.path());
    let dem = dem.to_str().unwrap();
    let base = [
        "bake",
        "--dem",
        dem,
        "--out",
        "w",
        "--cell-size",
        "20",
        "--tile-cells",
        "16",
    ];
    for i in ["0/2", "1/2"] {
        let out = common::verdant(&[&base[..], &["--shard", i]].concat(), dir.path());
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(String::from_utf8_lossy(&out.stdout).contains("baked shard"));
    }
    let again = common::verdant(&[&base[..], &["--shard", "1/2"]].concat(), dir.path());
    assert!(String::from_utf8_lossy(&again.stdout).contains("already done"));
    let out = common::verdant(&[&base[..], &["--finish-shards", "2"]].concat(), dir.path());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    verdant::World::open(&dir.path().join("w")).unwrap();
    let bad = common::verdant(&[&base[..], &["--shard", "2/2"]].concat(), dir.path());
    common::assert_fails_naming(&bad, &["--shard", "2/2"]);
}
