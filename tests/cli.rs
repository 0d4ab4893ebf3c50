//! The command line on bad input: a clear error naming the file and the problem, a non-zero
//! exit, no panic, and nothing lost.

mod common;

use std::path::Path;
use std::process::{Command, Output};

fn verdant(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("run verdant")
}

fn assert_fails_naming(out: &Output, needles: &[&str]) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "expected failure, stderr: {stderr}");
    assert_eq!(out.status.code(), Some(1), "stderr: {stderr}");
    assert!(!stderr.contains("panicked"), "panicked: {stderr}");
    for n in needles {
        assert!(stderr.contains(n), "stderr should mention {n:?}: {stderr}");
    }
}

fn world_copy(dir: &Path) -> std::path::PathBuf {
    let w = dir.join("world");
    std::fs::create_dir_all(&w).unwrap();
    std::fs::copy(
        common::default_world().join("world.toml"),
        w.join("world.toml"),
    )
    .unwrap();
    common::copy_dir(&common::default_world().join("tiles"), &w.join("tiles"));
    w
}

#[test]
fn fly_with_a_corrupt_tile_names_it() {
    let tmp = tempfile::tempdir().unwrap();
    let w = world_copy(tmp.path());
    let tile = w.join("tiles/L0/0_0.height.exr");
    let bytes = std::fs::read(&tile).unwrap();
    std::fs::write(&tile, &bytes[..bytes.len() / 3]).unwrap();
    let out = verdant(
        &["fly", w.to_str().unwrap(), "--frames", "1", "--out", "o"],
        tmp.path(),
    );
    assert_fails_naming(&out, &["0_0.height.exr"]);
}

#[test]
fn fly_with_an_absurd_manifest_names_the_field() {
    let tmp = tempfile::tempdir().unwrap();
    let w = world_copy(tmp.path());
    let manifest = std::fs::read_to_string(w.join("world.toml")).unwrap();
    let absurd = manifest.replace("tile_cells = 128", "tile_cells = 1048576");
    assert_ne!(manifest, absurd);
    std::fs::write(w.join("world.toml"), absurd).unwrap();
    let out = verdant(&["fly", w.to_str().unwrap(), "--frames", "1"], tmp.path());
    assert_fails_naming(&out, &["world.toml", "tile_cells"]);
}

#[test]
fn fly_without_a_world_says_so() {
    let tmp = tempfile::tempdir().unwrap();
    let out = verdant(&["fly", "no-such-world", "--frames", "1"], tmp.path());
    assert_fails_naming(&out, &["no-such-world"]);
}

#[test]
fn fly_rejects_a_bad_size() {
    let tmp = tempfile::tempdir().unwrap();
    let out = verdant(&["fly", "--size", "0x100"], tmp.path());
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("0x100"));
}

#[test]
fn bake_with_a_sidecar_that_disagrees_names_it_and_writes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let png = common::write_dem(
        tmp.path(),
        "dem",
        [64, 48],
        [10.0, 12.0],
        [0.0, 1.0],
        |x, y| x * 0.1 + y * 0.05,
    );
    common::write_sidecar(tmp.path(), "dem", [65, 48], [10.0, 12.0], [0.0, 1.0]);
    let out_dir = tmp.path().join("out");
    let out = verdant(
        &[
            "bake",
            "--dem",
            png.to_str().unwrap(),
            "--out",
            out_dir.to_str().unwrap(),
            "--tile-cells",
            "16",
            "--levels",
            "2",
        ],
        tmp.path(),
    );
    assert_fails_naming(&out, &["dem.json"]);
    assert!(
        !out_dir.join("world.toml").exists(),
        "a failed bake must not write a manifest"
    );
}

#[test]
fn bake_of_a_missing_dem_names_it() {
    let tmp = tempfile::tempdir().unwrap();
    let out = verdant(&["bake", "--dem", "missing.png", "--out", "w"], tmp.path());
    assert_fails_naming(&out, &["missing.png"]);
}

#[test]
fn bake_writes_a_world_that_flies() {
    let tmp = tempfile::tempdir().unwrap();
    let png = common::write_dem(
        tmp.path(),
        "hills",
        [96, 80],
        [20.0, 25.0],
        [0.0, 0.5],
        |x, y| 200.0 + 80.0 * (x / 300.0).sin() * (y / 400.0).cos(),
    );
    let world = tmp.path().join("hills");
    let out = verdant(
        &[
            "bake",
            "--dem",
            png.to_str().unwrap(),
            "--out",
            world.to_str().unwrap(),
            "--tile-cells",
            "16",
            "--levels",
            "2",
        ],
        tmp.path(),
    );
    assert!(
        out.status.success(),
        "bake failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = verdant(
        &[
            "fly",
            world.to_str().unwrap(),
            "--frames",
            "2",
            "--size",
            "64x36",
            "--out",
            "fly",
        ],
        tmp.path(),
    );
    assert!(
        out.status.success(),
        "fly failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(tmp.path().join("fly/report.json")).unwrap())
            .unwrap();
    assert_eq!(report["frames"].as_array().unwrap().len(), 2);
    assert!(report["summary"]["frame_ms"]["median"].as_f64().unwrap() > 0.0);
    assert!(tmp.path().join("fly/frame_00001.png").is_file());
}

#[test]
fn a_short_soak_holds_its_ceilings_and_its_memory() {
    let tmp = tempfile::tempdir().unwrap();
    // About 30 s of simulated flight at 50 m/s with teleports, small ceilings so that both the
    // cache and the atlas fill up and must evict. The streaming system alone (`--no-grass`),
    // which keeps this test short on software Vulkan; the grass passes' memory over many
    // frames has its own test (tests/memory.rs).
    let out = verdant(
        &[
            "soak",
            common::default_world().to_str().unwrap(),
            "--seconds",
            "30",
            "--speed",
            "50",
            "--seed",
            "3",
            "--size",
            "96x54",
            "--cache-mib",
            "3",
            "--atlas-slots",
            "96",
            "--no-grass",
            "--out",
            "soak",
        ],
        tmp.path(),
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "soak failed: {stderr}");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(tmp.path().join("soak/soak.json")).unwrap())
            .unwrap();
    assert_eq!(r["violations"].as_array().unwrap().len(), 0);
    assert_eq!(r["frames"], 300);
    assert!(r["cache_peak_bytes"].as_u64().unwrap() <= 3 << 20);
    assert!(r["atlas_peak_slots"].as_u64().unwrap() <= 96);
    assert!(
        r["evictions"].as_u64().unwrap() > 0,
        "the atlas should have had to evict"
    );
    assert!(r["teleports"].as_array().unwrap().len() >= 2);
    assert!(r["rss_peak_bytes"].as_u64().unwrap() > 0);
}

#[test]
fn a_soak_with_an_atlas_too_small_for_the_world_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    // An atlas too small for the world's always-resident level-0 tiles is refused up front.
    let out = verdant(
        &[
            "soak",
            common::default_world().to_str().unwrap(),
            "--seconds",
            "1",
            "--atlas-slots",
            "4",
            "--out",
            "soak",
        ],
        tmp.path(),
    );
    assert_fails_naming(&out, &["atlas", "4 slots"]);
}

#[test]
fn eval_derive_writes_its_table_and_charts() {
    let tmp = tempfile::tempdir().unwrap();
    let png = common::write_dem(
        tmp.path(),
        "ridge",
        [129, 97],
        [20.0, 25.0],
        [0.0, 0.1],
        |x, y| {
            300.0
                + 120.0 * (x / 500.0).sin() * (y / 700.0).cos()
                + 8.0 * (x / 190.0).sin() * (y / 150.0).sin()
        },
    );
    let out = verdant(
        &[
            "eval",
            "derive",
            "--dem",
            png.to_str().unwrap(),
            "--factor",
            "4",
            "--out",
            "ev",
        ],
        tmp.path(),
    );
    assert!(
        out.status.success(),
        "eval failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let csv = std::fs::read_to_string(tmp.path().join("ev/derive.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert_eq!(rows.len(), 9, "{csv}");
    let rmse = |name: &str| -> f64 {
        rows.iter().find(|r| r[0] == name).unwrap()[2]
            .parse()
            .unwrap()
    };
    assert!(
        rmse("bicubic") < rmse("bilinear") && rmse("bilinear") < rmse("nearest"),
        "{csv}"
    );
    assert_eq!(
        rows.iter().filter(|r| r[9] == "true").count(),
        1,
        "exactly one runtime default: {csv}"
    );
    // The runtime's method is the calibrated one. A 33 x 25 coarse grid has too few octaves
    // to fit: it falls back to plain bicubic, and says so.
    let calibrated = rows.iter().find(|r| r[0] == "calibrated").unwrap();
    assert_eq!(
        (calibrated[9], calibrated[10]),
        ("true", "bicubic"),
        "{csv}"
    );
    assert_eq!(rmse("calibrated"), rmse("bicubic"), "{csv}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("too few levels"), "{stdout}");
    for chart in [
        "derive_height.png",
        "derive_slope.png",
        "derive_flattening.png",
        "derive_roughness.png",
    ] {
        let img = image::open(tmp.path().join("ev").join(chart)).unwrap();
        assert_eq!((img.width(), img.height()), (900, 600));
    }
}

#[test]
fn eval_derive_refuses_a_bad_factor() {
    let tmp = tempfile::tempdir().unwrap();
    let png = common::write_dem(
        tmp.path(),
        "d",
        [33, 33],
        [10.0, 10.0],
        [0.0, 1.0],
        |x, _| x,
    );
    let out = verdant(
        &[
            "eval",
            "derive",
            "--dem",
            png.to_str().unwrap(),
            "--factor",
            "3",
        ],
        tmp.path(),
    );
    assert_fails_naming(&out, &["--factor", "3"]);
}

#[test]
fn bench_lod_writes_its_tables_and_charts() {
    let tmp = tempfile::tempdir().unwrap();
    let out = verdant(
        &[
            "bench",
            "lod",
            common::default_world().to_str().unwrap(),
            "--size",
            "96x54",
            "--dolly-frames",
            "4",
            "--warmup-frames",
            "0",
            "--timed-frames",
            "1",
            "--rounds",
            "2",
            "--out",
            "b",
        ],
        tmp.path(),
    );
    assert!(
        out.status.success(),
        "bench failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let dir = tmp.path().join("b");
    let dolly = std::fs::read_to_string(dir.join("dolly.csv")).unwrap();
    assert_eq!(dolly.lines().count(), 5, "{dolly}");
    let settings = std::fs::read_to_string(dir.join("lod_settings.csv")).unwrap();
    let header: Vec<&str> = settings.lines().next().unwrap().split(',').collect();
    // The stated columns: each timing as a median with its quartiles and spread, flagged when
    // noisy, with the frames it took.
    for column in [
        "setting",
        "gpu_ms",
        "gpu_q1_ms",
        "gpu_q3_ms",
        "gpu_spread",
        "frame_ms",
        "frame_spread",
        "noisy",
        "frames",
        "flip_mean",
        "blades_drawn",
        "pareto",
    ] {
        assert!(header.contains(&column), "no column {column} in {header:?}");
    }
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let rows: Vec<Vec<&str>> = settings
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert_eq!(rows[0][0], "default");
    assert!(rows.len() >= 8);
    let value = |name: &str, column: &str| -> f64 {
        rows.iter().find(|r| r[0] == name).unwrap()[col(column)]
            .parse()
            .unwrap()
    };
    // More blades cost more: no LOD draws more than the default.
    assert!(value("no LOD", "blades_drawn") > value("default", "blades_drawn"));
    // Two rounds of one timed frame at each of the four views.
    assert_eq!(value("default", "frames"), 8.0);
    for r in &rows {
        let (q1, m, q3) = (
            r[col("gpu_q1_ms")].parse::<f64>().unwrap(),
            r[col("gpu_ms")].parse::<f64>().unwrap(),
            r[col("gpu_q3_ms")].parse::<f64>().unwrap(),
        );
        assert!(q1 <= m && m <= q3 && m > 0.0, "{r:?}");
        assert!(r[col("frame_ms")].parse::<f64>().unwrap() > 0.0, "{r:?}");
        assert!(["true", "false"].contains(&r[col("noisy")]), "{r:?}");
    }
    for f in ["dolly.png", "lod_settings.png", "bench_lod.json"] {
        assert!(dir.join(f).is_file(), "{f} missing");
    }
}

#[test]
fn bench_blades_accounts_for_every_blade_and_draws_the_floor_with_as_many_vertices() {
    let tmp = tempfile::tempdir().unwrap();
    let out = verdant(
        &[
            "bench",
            "blades",
            "--size",
            "96x54",
            "--counts",
            "5000,20000",
            "--warmup-frames",
            "0",
            "--timed-frames",
            "2",
            "--rounds",
            "1",
            "--out",
            "b",
        ],
        tmp.path(),
    );
    assert!(
        out.status.success(),
        "bench failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let dir = tmp.path().join("b");
    let csv = std::fs::read_to_string(dir.join("blades.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .unwrap_or_else(|| panic!("no column {name} in {header:?}"))
    };
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert_eq!(rows.len(), 2, "{csv}");
    let n = |r: &Vec<&str>, c: &str| -> f64 { r[col(c)].parse().unwrap() };
    for r in &rows {
        let drawn = n(r, "drawn_high") + n(r, "drawn_low");
        assert!(drawn > 0.0, "{csv}");
        // Every point considered is drawn, empty or culled (by a counted test).
        assert_eq!(
            n(r, "considered_high") + n(r, "considered_low") - n(r, "empty") - n(r, "culled"),
            drawn,
            "{csv}"
        );
        // 15-vertex strips near, 7 far, and the floor draws exactly as many.
        assert_eq!(
            n(r, "vertices"),
            15.0 * n(r, "drawn_high") + 7.0 * n(r, "drawn_low"),
            "{csv}"
        );
        assert_eq!(n(r, "floor_vertices"), n(r, "vertices"), "{csv}");
        for c in [
            "draw_ms",
            "floor_ms",
            "ns_per_blade",
            "ns_per_vertex",
            "ratio_to_floor",
        ] {
            assert!(n(r, c) > 0.0, "{c} in {csv}");
        }
        assert!(["true", "false"].contains(&r[col("noisy")]), "{csv}");
    }
    // Four times the blades: more drawn.
    assert!(n(&rows[1], "drawn_high") > n(&rows[0], "drawn_high"));
    for f in ["blades_time.png", "blades_ratio.png", "bench_blades.json"] {
        assert!(dir.join(f).is_file(), "{f} missing");
    }
    // A sweep without counts, or absurd ones, is refused before any GPU work.
    let bad = verdant(&["bench", "blades", "--counts", "10"], tmp.path());
    assert_eq!(bad.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("at least 1000"));
}
