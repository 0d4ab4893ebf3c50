//! `verdant fly` along the wind tour: the wind scenes change along the path, the walker leaves
//! the trail, and `--wind`, `--disable` and `--enable` override the manifest.

mod common;

use std::path::Path;
use std::process::Command;

use verdant::camera::sample_path;
use verdant::world::Manifest;

fn fly(args: &[&str], cwd: &Path) -> serde_json::Value {
    let out = Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(["fly", common::default_world().to_str().unwrap()])
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("run verdant");
    assert!(
        out.status.success(),
        "fly failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report = cwd.join("fly/report.json");
    serde_json::from_str(&std::fs::read_to_string(report).unwrap()).unwrap()
}

#[test]
fn the_wind_tour_changes_scenes_and_its_walker_leaves_the_trail() {
    let tmp = tempfile::tempdir().unwrap();
    let base = [
        "--path",
        "wind-tour",
        "--frames",
        "5",
        "--size",
        "96x54",
        "--no-images",
        "--out",
        "fly",
    ];
    let report = fly(&base, tmp.path());
    let frames = report["frames"].as_array().unwrap();
    let scenes: Vec<&str> = frames
        .iter()
        .map(|f| f["wind_scene"].as_str().unwrap())
        .collect();
    // Frames at 0, 12.5, 25, 37.5 and 50 s.
    assert_eq!(
        scenes,
        ["calm", "breeze", "storm", "helicopter", "helicopter"]
    );
    let m = Manifest::from_path(&common::default_world().join("world.toml")).unwrap();
    let walker = m.path("walker").unwrap();
    for f in frames {
        let t = f["t_s"].as_f64().unwrap();
        let w: Vec<f64> = f["walker_m"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let want = sample_path(walker, t).position;
        assert!((w[0] - want.x).abs() < 1e-6 && (w[1] - want.y).abs() < 1e-6);
        let cam = f["camera_m"].as_array().unwrap();
        assert!(
            (cam[0].as_f64().unwrap() - w[0]).abs() > 1.0,
            "the walker is not the camera"
        );
    }

    // --wind holds one scene all along; --disable and --enable parse and combine.
    let mut args = base.to_vec();
    args.extend([
        "--wind",
        "storm",
        "--disable",
        "specular,translucency",
        "--enable",
        "shadows",
    ]);
    let report = fly(&args, tmp.path());
    for f in report["frames"].as_array().unwrap() {
        assert_eq!(f["wind_scene"].as_str(), Some("storm"));
    }

    let out = Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args([
            "fly",
            "--path",
            "wind-tour",
            "--enable",
            "sparkles",
            "--frames",
            "1",
        ])
        .current_dir(tmp.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("sparkles"));
}

/// `--wind SCENE` in a world without `[[wind_scenes]]` says that the world has none and what
/// the option needs, not an empty list of the scenes it has.
#[test]
fn fly_wind_in_a_world_without_wind_scenes_says_it_has_none() {
    let tmp = tempfile::tempdir().unwrap();
    let world = common::world_copy(tmp.path());
    let toml = world.join("world.toml");
    let mut m = Manifest::from_path(&toml).unwrap();
    m.wind_scenes.clear();
    for p in &mut m.paths {
        p.wind.clear();
    }
    std::fs::write(&toml, m.to_toml()).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(["fly", world.to_str().unwrap(), "--wind", "breeze"])
        .args([
            "--frames",
            "1",
            "--size",
            "32x18",
            "--no-images",
            "--out",
            "fly",
        ])
        .current_dir(tmp.path())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    common::assert_fails_naming(
        &out,
        &[
            "no wind scene called \"breeze\"",
            "the world has no wind scenes",
            "[[wind_scenes]]",
        ],
    );
    assert!(!stderr.contains("the world has: )"), "{stderr}");
}

#[test]
fn bench_features_charts_every_feature_in_the_wind_tour() {
    let tmp = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args([
            "bench",
            "features",
            common::default_world().to_str().unwrap(),
        ])
        .args([
            "--size",
            "128x72",
            "--warmup-frames",
            "0",
            "--timed-frames",
            "1",
            "--rounds",
            "1",
            "--truth",
            "1",
            "--truth-reach",
            "1",
            // One sample at each pixel's centre: at this size a falling leaf is a pixel or
            // less, and with the temporal method's jitter whether one covers a sample in the
            // measured frame is chance (the frames before it, while the tiles load, set the
            // jitter's phase).
            "--aa",
            "off",
        ])
        .args(["--out", "b"])
        .current_dir(tmp.path())
        .output()
        .expect("run verdant");
    assert!(
        out.status.success(),
        "bench failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let dir = tmp.path().join("b");
    let csv = std::fs::read_to_string(dir.join("features.csv")).unwrap();
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
    let names: Vec<&str> = rows.iter().map(|r| r[0]).collect();
    assert_eq!(
        names,
        [
            "all",
            "wind-sources",
            "interaction",
            "detail-bending",
            "translucency",
            "specular",
            "ambient-occlusion",
            "color-variation",
            "ground-darkening",
            "far-field",
            "shadows",
            "plants",
            "trees",
            "tree-shadows",
            "particles"
        ]
    );
    let contribution = |name: &str| -> f64 {
        rows.iter().find(|r| r[0] == name).unwrap()[col("contribution_flip")]
            .parse()
            .unwrap()
    };
    assert_eq!(contribution("all"), 0.0, "the full render against itself");
    // Every variant, the full render included, against the truth by both measures.
    for r in &rows {
        for c in [
            "flip_vs_truth",
            "coarse_flip_vs_truth",
            "contribution_coarse_flip",
        ] {
            let v: f64 = r[col(c)].parse().unwrap();
            assert!((0.0..1.0).contains(&v), "{c}: {csv}");
        }
        assert!(
            r[col("flip_vs_truth")].parse::<f64>().unwrap() > 0.0,
            "{csv}"
        );
    }
    // Every feature changes the image in these views, the walker's trail and the helicopter's
    // downwash included; but the falling leaves: at 128x72 a leaf is a pixel or less, and
    // whether one covers a pixel's centre in the measured frames is chance (it did with the
    // grass's view distance at 150 m, not at 100 m: which flowers and trees shed them follows
    // the plants' pool). `tests/particles.rs` checks that the leaves are drawn, at 192x108
    // among trees.
    for name in names[1..].iter().filter(|n| **n != "particles") {
        assert!(contribution(name) > 0.0, "{name} changes nothing: {csv}");
    }
    // Grass coverage of the captured views: grass covers part of the near terrain whatever
    // feature is off.
    for name in &names {
        let coverage: f64 = rows.iter().find(|r| r[0] == *name).unwrap()[col("coverage")]
            .parse()
            .unwrap();
        assert!(coverage > 0.0 && coverage <= 1.0, "{name}: {csv}");
    }
    for f in ["features.png", "features_coarse.png", "bench_features.json"] {
        assert!(dir.join(f).is_file(), "{f} missing");
    }
}
