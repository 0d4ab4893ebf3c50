//! Plants through the command line: a user's glTF plant in a world renders where its rule puts
//! it, trees of both recipes stand against the sky, and bad plant files are refused by name
//! before anything is drawn.

mod common;

use std::path::Path;

use common::{small_plant, world_with_plant};
use verdant::plants::{PlantImage, write_plant_gltf};

fn fly(world: &Path, dir: &Path) -> std::process::Output {
    fly_path(world, dir, "meadow", "160x90")
}

/// `verdant fly WORLD --path PATH --frames 1 --size SIZE --out o` in `dir`.
fn fly_path(world: &Path, dir: &Path, path: &str, size: &str) -> std::process::Output {
    common::verdant(
        &[
            "fly",
            world.to_str().unwrap(),
            "--path",
            path,
            "--frames",
            "1",
            "--size",
            size,
            "--out",
            "o",
        ],
        dir,
    )
}

fn report(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("o/report.json")).unwrap()).unwrap()
}

/// A copy of the default world whose only plant is a user's glTF marigold,
/// `plants/marigold.gltf` with its texture beside it.
fn marigold_world(dir: &Path) -> std::path::PathBuf {
    let w = world_with_plant(dir, "plants/marigold.gltf");
    std::fs::create_dir_all(w.join("plants")).unwrap();
    let texture = PlantImage {
        width: 4,
        height: 4,
        rgba: [255u8, 200, 40, 255].repeat(16),
    };
    write_plant_gltf(
        &w.join("plants/marigold.gltf"),
        &small_plant(),
        Some(&texture),
    )
    .unwrap();
    w
}

#[test]
fn a_gltf_plant_renders_where_its_rule_puts_it() {
    let tmp = tempfile::tempdir().unwrap();
    let w = marigold_world(tmp.path());
    let out = fly(&w, tmp.path());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "fly failed: {stderr}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(tmp.path().join("o/report.json")).unwrap())
            .unwrap();
    let plants = &report["frames"][0]["plants"];
    assert!(plants["drawn"].as_u64().unwrap() > 100, "{plants}");
    assert_eq!(plants["overflow"].as_u64().unwrap(), 0, "{plants}");

    // Without the plant on the grass types under the camera, none is drawn.
    let manifest = std::fs::read_to_string(w.join("world.toml")).unwrap();
    let none = manifest.replace(
        "density = { meadow = 1.5, \"tall grass\" = 1.5, \"dry grass\" = 1.5 }",
        "density = { bare = 1.5 }",
    );
    assert_ne!(manifest, none);
    std::fs::write(w.join("world.toml"), none).unwrap();
    let out = fly(&w, tmp.path());
    assert!(out.status.success());
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(tmp.path().join("o/report.json")).unwrap())
            .unwrap();
    assert_eq!(report["frames"][0]["plants"]["drawn"].as_u64(), Some(0));
}

#[test]
fn bad_plant_files_are_refused_naming_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    // (the file, how it is broken, what the error must name)
    type Case<'a> = (&'a str, &'a dyn Fn(&Path), &'a [&'a str]);
    let cases: [Case; 4] = [
        ("missing.gltf", &|_| {}, &["missing.gltf"]),
        (
            "notes.gltf",
            &|p| std::fs::write(p.join("notes.gltf"), "these are my notes").unwrap(),
            &["notes.gltf"],
        ),
        (
            "flat.glb",
            &|p| std::fs::write(p.join("flat.glb"), b"glTF\x02\x00\x00\x00").unwrap(),
            &["flat.glb"],
        ),
        (
            "broken_texture.gltf",
            &|p| {
                let img = PlantImage {
                    width: 2,
                    height: 2,
                    rgba: vec![255; 16],
                };
                write_plant_gltf(&p.join("broken_texture.gltf"), &small_plant(), Some(&img))
                    .unwrap();
                // Every PNG beside it garbled.
                for e in std::fs::read_dir(p).unwrap() {
                    let f = e.unwrap().path();
                    if f.extension().is_some_and(|x| x == "png") {
                        std::fs::write(&f, b"\x89PNG\r\n\x1a\nbroken").unwrap();
                    }
                }
            },
            &["broken_texture.gltf", "texture"],
        ),
    ];
    let w = world_with_plant(tmp.path(), "PLACEHOLDER");
    let manifest = std::fs::read_to_string(w.join("world.toml")).unwrap();
    for (file, make, needles) in cases {
        make(&w);
        std::fs::write(w.join("world.toml"), manifest.replace("PLACEHOLDER", file)).unwrap();
        let out = fly(&w, tmp.path());
        assert_refused(&out, file, needles.iter().copied(), tmp.path());
    }
}

#[test]
fn plant_files_that_would_draw_nothing_are_refused_naming_type_file_and_reason() {
    let tmp = tempfile::tempdir().unwrap();
    let w = world_with_plant(tmp.path(), "PLACEHOLDER");
    let manifest = std::fs::read_to_string(w.join("world.toml")).unwrap();
    for (file, mesh, reason) in common::undrawable_plants() {
        write_plant_gltf(&w.join(file), &mesh, None).unwrap();
        std::fs::write(w.join("world.toml"), manifest.replace("PLACEHOLDER", file)).unwrap();
        let out = fly_path(&w, tmp.path(), "meadow", "32x18");
        assert_refused(&out, file, [file, "\"marigold\"", reason], tmp.path());
    }
}

#[test]
fn a_heavy_gltf_plant_is_drawn_reduced_within_a_triangle_budget() {
    use verdant::plants::set::{FILE_REDUCED_TRIANGLES, FULL_MESH_TRIANGLE_BUDGET};
    let tmp = tempfile::tempdir().unwrap();
    let w = world_with_plant(tmp.path(), "plants/heavy.gltf");
    std::fs::create_dir_all(w.join("plants")).unwrap();
    let heavy = common::heavy_plant();
    assert_eq!(heavy.triangles(), 130_050);
    write_plant_gltf(&w.join("plants/heavy.gltf"), &heavy, None).unwrap();
    let out = fly_path(&w, tmp.path(), "meadow", "32x18");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "fly failed: {stderr}");
    // The start-up says where the full mesh gives way.
    assert!(
        stderr.contains("\"marigold\"") && stderr.contains("switches to its reduced level"),
        "{stderr}"
    );
    let plants = &report(tmp.path())["frames"][0]["plants"];
    let drawn = plants["drawn"].as_u64().unwrap();
    let triangles = plants["triangles"].as_u64().unwrap();
    // Thousands of plants in view (about 5,000 in this frame), each of the file's 130,050
    // triangles, would make hundreds of millions; the full meshes near the camera stay within
    // the budget and the rest are reduced.
    assert!(drawn > 2_000, "{plants}");
    let bound = FULL_MESH_TRIANGLE_BUDGET as u64 + drawn * FILE_REDUCED_TRIANGLES as u64;
    assert!(
        triangles >= drawn && triangles <= bound,
        "{triangles} triangles for {drawn} plants, more than {bound}: {plants}"
    );
}

/// The frame's rows above the horizon: the top `share` of the image, as RGB.
fn top_rows(png: &Path, share: f64) -> Vec<[u8; 3]> {
    let img = image::open(png).unwrap().to_rgb8();
    let rows = (f64::from(img.height()) * share) as u32;
    (0..rows)
        .flat_map(|y| (0..img.width()).map(move |x| (x, y)))
        .map(|(x, y)| img.get_pixel(x, y).0)
        .collect()
}

#[test]
fn trees_of_both_recipes_stand_against_the_sky() {
    let tmp = tempfile::tempdir().unwrap();
    // The meadow with a broadleaf of 8-12 m at one plant to 500 m2 (and its usual plants gone).
    let w = world_with_plant(tmp.path(), "broadleaf");
    let manifest = std::fs::read_to_string(w.join("world.toml")).unwrap();
    let trees = manifest
        .replace("size_m = [0.4, 0.6]", "size_m = [8.0, 12.0]")
        .replace(
            "density = { meadow = 1.5, \"tall grass\" = 1.5, \"dry grass\" = 1.5 }",
            "density = { meadow = 0.002, \"tall grass\" = 0.002, \"dry grass\" = 0.002 }",
        );
    assert_ne!(manifest, trees);
    let bare = trees.replace(
        "density = { meadow = 0.002, \"tall grass\" = 0.002, \"dry grass\" = 0.002 }",
        "density = { bare = 0.002 }",
    );
    let mut skies = Vec::new();
    for (what, text) in [
        ("broadleaf", trees.clone()),
        (
            "conifer",
            trees.replace("mesh = \"broadleaf\"", "mesh = \"conifer\""),
        ),
        ("none", bare),
    ] {
        std::fs::write(w.join("world.toml"), &text).unwrap();
        let out = fly(&w, tmp.path());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "fly with {what} failed: {stderr}");
        let report = report(tmp.path());
        // Types this tall are trees: drawn by the trees' layer, none by the plants'.
        assert!(report["frames"][0]["plants"].is_null(), "{what}");
        let trees = &report["frames"][0]["trees"];
        if what == "none" {
            assert_eq!(trees["drawn"].as_u64(), Some(0), "{trees}");
        } else {
            assert!(trees["drawn"].as_u64().unwrap() > 5, "{what}: {trees}");
            assert_eq!(trees["overflow"].as_u64(), Some(0), "{what}: {trees}");
        }
        skies.push(top_rows(&tmp.path().join("o/frame_00000.png"), 0.4));
    }
    // Trees rise above the horizon: part of the sky is hidden by each kind, and the crowns
    // are darker than the sky they hide.
    for (k, what) in ["broadleaf", "conifer"].iter().enumerate() {
        let (with, without) = (&skies[k], &skies[2]);
        let hidden = with
            .iter()
            .zip(without)
            .filter(|(a, b)| {
                let sum = |p: &[u8; 3]| p.iter().map(|&c| u32::from(c)).sum::<u32>();
                sum(a) + 90 < sum(b)
            })
            .count();
        let share = hidden as f64 / with.len() as f64;
        assert!(
            (0.01..0.6).contains(&share),
            "{what}: {:.1}% of the sky hidden",
            share * 100.0
        );
    }
}

#[test]
fn trees_stand_on_the_tours_far_ridges() {
    // The tour's first frame looks down from 400 m and more over the ground: everything in it
    // lies beyond the plants' reach (twice the grass's view distance), where only the trees'
    // own layer draws.
    let tmp = tempfile::tempdir().unwrap();
    let w = common::world_with_trees(tmp.path(), "conifer", 0.01);
    let manifest = std::fs::read_to_string(w.join("world.toml")).unwrap();
    let mut frames = Vec::new();
    for (what, text) in [
        ("trees", manifest.clone()),
        (
            "none",
            manifest.replace(
                "density = { meadow = 0.01, \"tall grass\" = 0.01, \"dry grass\" = 0.01 }",
                "density = { bare = 0.01 }",
            ),
        ),
    ] {
        assert!(what == "trees" || text != manifest);
        std::fs::write(w.join("world.toml"), &text).unwrap();
        let out = fly_path(&w, tmp.path(), "tour", "640x360");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "fly with {what} failed: {stderr}");
        let report = report(tmp.path());
        let trees = report["frames"][0]["trees"].clone();
        let drawn = trees["drawn"].as_u64().unwrap();
        if what == "trees" {
            assert!(drawn > 5000, "{trees}");
            assert_eq!(trees["overflow"].as_u64(), Some(0), "{trees}");
        }
        frames.push((
            image::open(tmp.path().join("o/frame_00000.png"))
                .unwrap()
                .to_rgb8(),
            drawn,
        ));
    }
    // The bare ground's few trees: under one in twenty-five of the grassland's.
    assert!(
        frames[1].1 * 25 < frames[0].1,
        "only the bare ground's trees: {} against {}",
        frames[1].1,
        frames[0].1
    );
    // The trees cover a share of the ground, scattered over the slopes. Drawn at 640x360: with
    // none thinned or grown within 1,600 m, at 320x180 most trees are a pixel or less and
    // change the pixels they fall in by less than the threshold (0.8% of the frame changed;
    // 2.6% at 640x360).
    let (with, without) = (&frames[0].0, &frames[1].0);
    let sum = |p: &image::Rgb<u8>| p.0.iter().map(|&c| i32::from(c)).sum::<i32>();
    let changed = with
        .pixels()
        .zip(without.pixels())
        .filter(|(a, b)| (sum(a) - sum(b)).abs() > 30)
        .count();
    let share = changed as f64 / (with.width() * with.height()) as f64;
    assert!(
        (0.01..0.6).contains(&share),
        "{:.1}% of the frame changed by the trees",
        share * 100.0
    );
}

/// A world over HTTP fetches its glTF plants from its server like its tiles, the texture the
/// glTF file names beside it too, and draws what the world's folder draws.
#[test]
fn a_gltf_plant_over_http_renders_what_the_folder_renders() {
    let tmp = tempfile::tempdir().unwrap();
    let w = marigold_world(tmp.path());
    let server = verdant::tools::serve::WorldServer::start(&w, "127.0.0.1:0").unwrap();
    let local = fly(&w, tmp.path());
    assert!(
        local.status.success(),
        "{}",
        String::from_utf8_lossy(&local.stderr)
    );
    let frame = |dir: &str| image::open(tmp.path().join(dir).join("frame_00000.png")).unwrap();
    let local_frame = frame("o").to_rgb8();
    std::fs::remove_dir_all(tmp.path().join("o")).unwrap();
    let remote = fly(Path::new(&server.url()), tmp.path());
    assert!(
        remote.status.success(),
        "{}",
        String::from_utf8_lossy(&remote.stderr)
    );
    let flip = verdant::tools::metrics::flip_compare(&local_frame, &frame("o").to_rgb8()).unwrap();
    assert!(
        flip.mean < 1e-3,
        "FLIP {} between the folder's frame and HTTP's",
        flip.mean
    );

    // Without its texture on the server, the plant is refused, naming the texture's address.
    std::fs::remove_file(w.join("plants/marigold_base_color.png")).unwrap();
    let remote = fly(Path::new(&server.url()), tmp.path());
    let stderr = String::from_utf8_lossy(&remote.stderr);
    assert!(!remote.status.success());
    assert!(
        stderr.contains("marigold") && stderr.contains(&server.url()),
        "{stderr}"
    );
}

/// A run refused for the plant file `file`: status 1, no panic, every one of `needles` in its
/// stderr, and no report written into `dir/o`.
fn assert_refused<'a>(
    out: &std::process::Output,
    file: &str,
    needles: impl IntoIterator<Item = &'a str>,
    dir: &std::path::Path,
) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{file}: {stderr}");
    assert!(!stderr.contains("panicked"), "{file}: {stderr}");
    for n in needles {
        assert!(
            stderr.contains(n),
            "{file}: stderr should name {n:?}: {stderr}"
        );
    }
    assert!(
        !dir.join("o/report.json").exists(),
        "{file}: nothing is written"
    );
}
