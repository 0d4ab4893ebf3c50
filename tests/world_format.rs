//! The manifest, the tile files and the committed default world: valid input round-trips, and
//! every kind of bad input gets its own error naming the file, without a panic.

mod common;

use std::path::{Path, PathBuf};

use common::{Rng, Terrain};
use verdant::world::{
    Manifest, Pyramid, ReadOptions, TileData, TileFile, TileId, World, WorldError, read_tile,
    read_tile_with, tile_path, write_tile, write_tile_with,
};

fn repo_world() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/santa-cruz")
}

const VALID: &str = r#"
name = "test"
description = "a small test world"
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

[[grass_types]]
name = "meadow"
ground_color = [0.1, 0.2, 0.05]
base_color = [0.05, 0.15, 0.02]
tip_color = [0.2, 0.5, 0.1]
height_m = [0.2, 0.4]
width_m = [0.01, 0.02]
stiffness = 0.5

[[paths]]
name = "overview"
duration_s = 10.0
keys = [
    { t_s = 0.0, position_m = [10.0, 10.0, 600.0], yaw_deg = 45.0, pitch_deg = -10.0 },
    { t_s = 10.0, position_m = [800.0, 900.0, 600.0], yaw_deg = 45.0, pitch_deg = -10.0 },
]
"#;

fn toml_path() -> &'static Path {
    Path::new("worlds/test/world.toml")
}

fn parse(text: &str) -> Result<Manifest, WorldError> {
    Manifest::parse(text, toml_path())
}

/// Parses VALID with `from` replaced by `to` (which must occur), expecting an error.
fn broken(from: &str, to: &str) -> WorldError {
    assert!(VALID.contains(from), "{from}");
    let err = parse(&VALID.replacen(from, to, 1)).expect_err(to);
    assert!(
        err.to_string().starts_with("worlds/test/world.toml: "),
        "message does not name the file: {err}"
    );
    err
}

#[test]
fn committed_world_manifest_parses_and_validates() {
    let m = Manifest::from_path(&repo_world().join("world.toml")).unwrap();
    assert_eq!(m.name, "santa-cruz");
    assert_eq!(m.pyramid.tile_cells, 128);
    assert_eq!(m.pyramid.stored_levels, 3);
    assert_eq!(m.pyramid.cell_size_m(2), 25.0);
    let names: Vec<&str> = m.grass_types.iter().map(|g| g.name.as_str()).collect();
    assert_eq!(names, ["bare", "meadow", "tall grass", "dry grass"]);
    let names: Vec<&str> = m.paths.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "tour",
            "overview",
            "low",
            "meadow",
            "helicopter",
            "wind-tour",
            "walker",
            "forest-edge"
        ]
    );
    // Its forests: three tree types, the oaks' and valley oaks' altitudes meeting at 90 m.
    let trees: Vec<&str> = m
        .plant_types
        .iter()
        .filter(|t| t.is_tree())
        .map(|t| t.name.as_str())
        .collect();
    assert_eq!(trees, ["oak", "fir", "valley oak"]);
    assert_eq!(
        m.plant_types[4].altitude_m[0],
        m.plant_types[6].altitude_m[1]
    );
    assert!(m.height_range_m[0] >= 0.0 && m.height_range_m[1] <= 1000.0);
    // The baker fitted the derived levels' detail: one amplitude per derived level.
    let fit = m.derive.as_ref().expect("a [derive] table");
    assert_eq!(fit.detail.len(), usize::from(m.pyramid.derived_levels));
    // Text written by `to_toml` reads back to the same manifest.
    assert_eq!(parse(&m.to_toml()).unwrap(), m);
}

#[test]
fn committed_world_tiles_all_load() {
    let world = World::open(&repo_world()).unwrap();
    let mut count = 0;
    for id in world.stored_tiles() {
        let tile = world.load_tile(id).unwrap();
        assert_eq!(tile.size, 133);
        count += 1;
    }
    assert_eq!(count, 6 + 24 + 96);
}

#[test]
fn committed_world_camera_paths_clear_the_terrain() {
    let terrain = Terrain::load(&repo_world());
    let m = &terrain.world.manifest;
    let overview = m.path("overview").unwrap();
    assert!((50.0..=70.0).contains(&overview.duration_s));
    let c = terrain.clearances(overview, 40);
    let min = c.iter().copied().fold(f64::INFINITY, f64::min);
    let mean = c.iter().sum::<f64>() / c.len() as f64;
    assert!(min >= 50.0, "overview dips to {min} m above the terrain");
    assert!(
        (250.0..=450.0).contains(&mean),
        "overview flies {mean} m up on average"
    );

    let c = terrain.clearances(m.path("low").unwrap(), 40);
    let min = c.iter().copied().fold(f64::INFINITY, f64::min);
    let max = c.iter().copied().fold(0.0, f64::max);
    assert!(
        min >= 30.0 && max <= 60.0,
        "low pass flies {min}..{max} m up"
    );

    // The tour descends from high above the hills to a glide over the meadow.
    let c = terrain.clearances(m.path("tour").unwrap(), 40);
    let min = c.iter().copied().fold(f64::INFINITY, f64::min);
    assert!(min >= 1.0, "the tour dips to {min} m above the terrain");
    assert!(
        c[0] > 150.0 && *c.last().unwrap() < 5.0,
        "tour clearances {c:?}"
    );

    // The helicopter hovers 15-20 m over the meadow, slowly.
    let heli = m.path("helicopter").unwrap();
    let c = terrain.clearances(heli, 40);
    let min = c.iter().copied().fold(f64::INFINITY, f64::min);
    let max = c.iter().copied().fold(0.0, f64::max);
    assert!(
        min >= 15.0 && max <= 20.0,
        "the helicopter flies {min}..{max} m up"
    );
    let (a, b) = (
        heli.keys[0].position_m,
        heli.keys.last().unwrap().position_m,
    );
    let speed = (b[0] - a[0]).hypot(b[1] - a[1]) / heli.duration_s;
    assert!(speed <= 8.0, "the helicopter passes at {speed} m/s");
}

#[test]
fn valid_manifest_parses() {
    let m = parse(VALID).unwrap();
    assert_eq!(m.name, "test");
    assert_eq!(m.pyramid.max_level(), 2);
    assert_eq!(m.paths[0].keys[1].position_m, [800.0, 900.0, 600.0]);
    // Wind and sky take their defaults: the sun in the south-west, 35 degrees up.
    assert_eq!(m.sky.sun_azimuth_deg, 225.0);
    assert_eq!(m.sky.sun_elevation_deg, 35.0);
    assert_eq!(m.sky.fog_distance_m, 12_000.0);
    assert!(m.wind.speed_mps > 0.0);
    assert_eq!(parse(&m.to_toml()).unwrap(), m);
}

const DERIVE: &str = r#"
[derive]
method = "fractal"
note = "fitted"
octaves = 4
hurst = 0.8
fit_rms_log2 = 0.05
residual_rms_m = 1.5
detail = [0.3]
"#;

#[test]
fn derive_calibration_is_optional_and_validated() {
    // Worlds baked before calibration: no table, the legacy amplitude at every level.
    let m = parse(VALID).unwrap();
    assert_eq!(m.derive, None);
    assert_eq!(
        verdant::stream::DeriveParams::for_manifest(&m),
        verdant::stream::DeriveParams::default()
    );
    let with = format!("{VALID}{DERIVE}");
    let m = parse(&with).unwrap();
    let table = m.derive.as_ref().unwrap();
    assert_eq!(table.method, verdant::world::DeriveMode::Fractal);
    assert_eq!(table.detail, vec![0.3]);
    assert_eq!(parse(&m.to_toml()).unwrap(), m);
    for (from, to, field) in [
        ("detail = [0.3]", "detail = [0.3, 0.2]", "derive.detail"),
        ("detail = [0.3]", "detail = [-0.3]", "derive.detail[0]"),
        ("detail = [0.3]", "detail = [1000.0]", "derive.detail[0]"),
        (
            "method = \"fractal\"",
            "method = \"bicubic\"",
            "derive.detail[0]",
        ),
        ("hurst = 0.8", "hurst = nan", "derive.hurst"),
    ] {
        let err = parse(&with.replacen(from, to, 1)).expect_err(to);
        let text = err.to_string();
        assert!(
            text.starts_with("worlds/test/world.toml: ") && text.contains(field),
            "{to}: {text}"
        );
    }
    let err = parse(&with.replacen("\"fractal\"", "\"spline\"", 1)).expect_err("spline");
    assert!(matches!(err, WorldError::ManifestSyntax { .. }), "{err}");
}

#[test]
fn manifest_syntax_errors() {
    let err = broken("stiffness = 0.5", "stiffness = 0.5\nshininess = 2.0");
    assert!(matches!(err, WorldError::ManifestSyntax { .. }), "{err}");
    assert!(err.to_string().contains("shininess"), "{err}");
    let err = broken("tile_cells = 16\n", "");
    assert!(matches!(err, WorldError::ManifestSyntax { .. }), "{err}");
    assert!(err.to_string().contains("tile_cells"), "{err}");
    let err = broken("name = \"test\"", "name = test");
    assert!(matches!(err, WorldError::ManifestSyntax { .. }), "{err}");
}

/// A syntax error quotes the offending line around the error's column, not the whole line: a
/// damaged manifest of one 10 MB line of NULs made an error of 60 MB.
#[test]
fn a_syntax_error_quotes_a_bounded_part_of_its_line() {
    let long = "\0".repeat(10_000_000);
    let err = Manifest::parse(&long, Path::new("w/world.toml")).unwrap_err();
    let text = err.to_string();
    assert!(matches!(err, WorldError::ManifestSyntax { .. }), "{text}");
    assert!(text.len() < 1000, "{} bytes: {}", text.len(), &text[..1000]);
    assert!(
        text.contains("line 1, column 10000001") && text.contains("| ...\\0\\0"),
        "{text}"
    );
    // A line's error far along it: the quote ends at the error, the column counted in full.
    let line = format!("name = \"{}\" x", "a".repeat(5000));
    let err = broken("name = \"test\"", &line);
    let text = err.to_string();
    assert!(text.len() < 1000, "{text}");
    assert!(
        text.contains(", column 5011") && text.contains("aaa\" x\n"),
        "{text}"
    );
    assert!(text.contains("...aaa"), "{text}");
}

#[test]
fn manifest_non_finite_numbers() {
    let err = broken("extent_m = [900.0, 1000.0]", "extent_m = [nan, 1000.0]");
    assert!(
        matches!(err, WorldError::NonFinite { ref field, .. } if field == "extent_m[0]"),
        "{err}"
    );
    let err = broken("[800.0, 900.0, 600.0]", "[800.0, inf, 600.0]");
    assert!(
        matches!(err, WorldError::NonFinite { ref field, .. } if field == "paths[0].keys[1].position_m[1]"),
        "{err}"
    );
    let err = broken(
        "height_range_m = [-10.0, 500.0]",
        "height_range_m = [-10.0, nan]",
    );
    assert!(matches!(err, WorldError::NonFinite { .. }), "{err}");
}

#[test]
fn manifest_non_positive_sizes() {
    let err = broken("extent_m = [900.0, 1000.0]", "extent_m = [900.0, -1.0]");
    assert!(
        matches!(err, WorldError::NonPositive { ref field, .. } if field == "extent_m[1]"),
        "{err}"
    );
    assert!(err.to_string().contains("extent_m[1] = -1"), "{err}");
    let err = broken("root_tile_size_m = 512.0", "root_tile_size_m = 0.0");
    assert!(matches!(err, WorldError::NonPositive { .. }), "{err}");
    let err = broken("root_tiles = [2, 2]", "root_tiles = [0, 2]");
    assert!(matches!(err, WorldError::NonPositive { .. }), "{err}");
    let err = broken("duration_s = 10.0", "duration_s = 0.0");
    assert!(matches!(err, WorldError::NonPositive { .. }), "{err}");
}

#[test]
fn manifest_absurd_sizes() {
    for (from, to, field) in [
        ("tile_cells = 16", "tile_cells = 100", "pyramid.tile_cells"),
        ("tile_cells = 16", "tile_cells = 4", "pyramid.tile_cells"),
        ("tile_cells = 16", "tile_cells = 2048", "pyramid.tile_cells"),
        ("border = 2", "border = 9", "pyramid.border"),
        (
            "stored_levels = 2",
            "stored_levels = 0",
            "pyramid.stored_levels",
        ),
        (
            "stored_levels = 2",
            "stored_levels = 13",
            "pyramid.stored_levels",
        ),
        (
            "derived_levels = 1",
            "derived_levels = 23",
            "pyramid.stored_levels + pyramid.derived_levels",
        ),
    ] {
        let err = broken(from, to);
        assert!(
            matches!(err, WorldError::OutOfRange { field: ref f, .. } if f == field),
            "{to}: {err}"
        );
    }
    let deep = VALID
        .replace("root_tiles = [2, 2]", "root_tiles = [4096, 1]")
        .replace("derived_levels = 1", "derived_levels = 20");
    let err = parse(&deep).unwrap_err();
    assert!(
        matches!(err, WorldError::OutOfRange { ref field, .. } if field == "pyramid.root_tiles[0]"),
        "{err}"
    );
    let err = broken("root_tiles = [2, 2]", "root_tiles = [100, 100]");
    assert!(
        matches!(err, WorldError::TooManyTiles { count: 10_000, .. }),
        "{err}"
    );
    let err = broken("stored_levels = 2", "stored_levels = 12");
    assert!(matches!(err, WorldError::TooManyTiles { .. }), "{err}");
    assert!(err.to_string().contains("1000000"), "{err}");
    let err = broken("extent_m = [900.0, 1000.0]", "extent_m = [1100.0, 1000.0]");
    assert!(
        matches!(err, WorldError::ExtentBeyondGrid { axis: 0, .. }),
        "{err}"
    );
    let err = broken(
        "extent_m = [900.0, 1000.0]\n",
        "extent_m = [2.0e7, 1000.0]\n",
    )
    .to_string();
    assert!(err.contains("extent_m[0]"), "{err}");
    let huge = VALID
        .replace("extent_m = [900.0, 1000.0]", "extent_m = [2.0e7, 1000.0]")
        .replace("root_tile_size_m = 512.0", "root_tile_size_m = 1.0e7");
    let err = parse(&huge).unwrap_err();
    assert!(
        matches!(err, WorldError::OutOfRange { ref field, .. } if field == "extent_m[0]"),
        "{err}"
    );
    // A value of hundreds of digits is shown in exponent form, not digit by digit.
    let err = parse(&VALID.replace("extent_m = [900.0, 1000.0]", "extent_m = [1e300, 1000.0]"))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("extent_m[0] = 1e300") && err.len() < 200,
        "{err}"
    );
}

#[test]
fn manifest_bad_height_range() {
    let err = broken(
        "height_range_m = [-10.0, 500.0]",
        "height_range_m = [500.0, -10.0]",
    );
    assert!(
        matches!(
            err,
            WorldError::BadHeightRange {
                min: 500.0,
                max: -10.0,
                ..
            }
        ),
        "{err}"
    );
    let err = broken(
        "height_range_m = [-10.0, 500.0]",
        "height_range_m = [5.0, 5.0]",
    );
    assert!(matches!(err, WorldError::BadHeightRange { .. }), "{err}");
}

#[test]
fn manifest_bad_grass_types() {
    let no_grass: String = VALID.split("[[grass_types]]").next().unwrap().to_string()
        + "[[paths]]"
        + VALID.split("[[paths]]").nth(1).unwrap();
    let err = parse(&no_grass).unwrap_err();
    assert!(matches!(err, WorldError::NoGrassTypes { .. }), "{err}");
    assert!(err.to_string().contains("worlds/test/world.toml"), "{err}");

    let err = broken("height_m = [0.2, 0.4]", "height_m = [0.4, 0.2]");
    assert!(
        matches!(
            err,
            WorldError::BadGrassRange {
                index: 1,
                field: "height_m",
                ..
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("meadow"), "{err}");
    let err = broken("width_m = [0.01, 0.02]", "width_m = [-0.01, 0.02]");
    assert!(
        matches!(
            err,
            WorldError::BadGrassRange {
                field: "width_m",
                ..
            }
        ),
        "{err}"
    );
}

#[test]
fn manifest_bad_camera_paths() {
    let one_key = VALID.replace(
        "    { t_s = 10.0, position_m = [800.0, 900.0, 600.0], yaw_deg = 45.0, pitch_deg = -10.0 },\n",
        "",
    );
    let err = parse(&one_key).unwrap_err();
    assert!(
        matches!(err, WorldError::PathTooShort { keys: 1, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("\"overview\""), "{err}");
    assert!(err.to_string().contains("paths[0].keys has 1 key"), "{err}");

    let err = broken("{ t_s = 10.0,", "{ t_s = 0.0,");
    assert!(
        matches!(err, WorldError::PathKeysOutOfOrder { index: 1, .. }),
        "{err}"
    );
    assert!(
        err.to_string().contains("paths[0].keys[1].t_s = 0"),
        "{err}"
    );

    let paths = &VALID[VALID.find("[[paths]]").unwrap()..];
    let err = parse(&format!("{VALID}\n{paths}")).unwrap_err();
    assert!(
        matches!(err, WorldError::DuplicatePath { ref name, .. } if name == "overview"),
        "{err}"
    );
}

/// A camera path's length is the span of its keys' times, from the first key's `t_s` to the
/// last's: every tool flies that. A `duration_s` that says otherwise (by more than a thousandth
/// of a second) is refused naming the file, the path, the field and both values, not flown
/// over a part of the path or clamped to its last key.
#[test]
fn a_path_duration_that_disagrees_with_its_keys_is_refused() {
    for (to, shown) in [
        ("duration_s = 1000.0", "duration_s = 1000 "),
        ("duration_s = 4.0", "duration_s = 4 "),
        ("duration_s = 10.01", "duration_s = 10.01 "),
    ] {
        let err = broken("duration_s = 10.0", to);
        let text = err.to_string();
        for needle in [
            "camera path \"overview\"",
            "paths[0].duration_s",
            shown,
            "span 10 s",
            "t_s 0 to 10",
        ] {
            assert!(text.contains(needle), "{needle:?} not in: {text}");
        }
    }
    // Within the tolerance: accepted.
    parse(&VALID.replace("duration_s = 10.0", "duration_s = 10.0004")).unwrap();
    // Keys that start after 0: the span counts from the first key.
    let later = VALID
        .replace("{ t_s = 0.0,", "{ t_s = 5.0,")
        .replace("{ t_s = 10.0,", "{ t_s = 15.0,");
    parse(&later).unwrap();
    let err = parse(&later.replace("duration_s = 10.0", "duration_s = 15.0")).unwrap_err();
    assert!(err.to_string().contains("t_s 5 to 15"), "{err}");
}

/// Every world shipped under worlds/ (and so the bake that wrote them) states its paths'
/// lengths as their keys span them.
#[test]
fn every_shipped_world_manifest_validates() {
    let worlds = Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds");
    let mut seen = 0;
    for entry in std::fs::read_dir(&worlds).unwrap() {
        let toml = entry.unwrap().path().join("world.toml");
        if toml.is_file() {
            let m = Manifest::from_path(&toml).unwrap_or_else(|e| panic!("{e}"));
            assert!(!m.paths.is_empty(), "{}", toml.display());
            seen += 1;
        }
    }
    assert!(seen >= 2, "{seen} worlds");
}

/// A path's wind key that names a scene of a world without wind scenes says so, instead of
/// listing none.
#[test]
fn a_wind_key_in_a_world_without_wind_scenes_says_there_are_none() {
    let err = broken(
        "duration_s = 10.0\n",
        "duration_s = 10.0\nwind = [{ t_s = 0.0, scene = \"gale\" }]\n",
    );
    let text = err.to_string();
    assert!(text.contains("paths[0].wind[0].scene = \"gale\""), "{text}");
    assert!(text.contains("the world has no wind scenes"), "{text}");
    assert!(text.contains("[[wind_scenes]]"), "{text}");
    assert!(!text.contains("the world has: )"), "{text}");
}

/// Texts of a manifest are printed to terminals and window titles: a control character (an
/// escape sequence that would recolour the terminal or retitle it, from a world fetched over
/// HTTP say) is refused naming the field; tabs and line breaks in a description are fine.
#[test]
fn control_characters_in_a_manifests_texts_are_refused() {
    for (from, to, field, code) in [
        (
            "name = \"test\"",
            "name = \"a\\u001b[31mred\"",
            "name",
            "U+001B",
        ),
        (
            "name = \"overview\"",
            "name = \"over\\u0007view\"",
            "paths[0].name",
            "U+0007",
        ),
        (
            "name = \"meadow\"",
            "name = \"mea\\u009bdow\"",
            "grass_types[1].name",
            "U+009B",
        ),
        // A right-to-left override (and the other marks that reorder text) makes a name read
        // as another one.
        (
            "name = \"test\"",
            "name = \"san\\u202eta-cruz\"",
            "name",
            "U+202E",
        ),
        (
            "name = \"overview\"",
            "name = \"over\\u200fview\"",
            "paths[0].name",
            "U+200F",
        ),
        (
            "name = \"meadow\"",
            "name = \"mea\\u2067dow\"",
            "grass_types[1].name",
            "U+2067",
        ),
    ] {
        let e = broken(from, to).to_string();
        for needle in [field, code, "control character"] {
            assert!(e.contains(needle), "{needle:?} not in {e:?}");
        }
    }
    let ok = VALID.replacen(
        "description = \"a small test world\"",
        "description = \"two lines,\\n\\tindented\"",
        1,
    );
    assert!(parse(&ok).is_ok());

    // Validation checks it too, not only parsing: what a bake validates, its loader accepts.
    let mut m = parse(VALID).unwrap();
    m.source = Some(verdant::world::manifest::WorldSource {
        file: "dem.png".into(),
        format: verdant::world::DemFormat::PngSidecar,
        crs: String::new(),
        origin: None,
        samples: [2, 2],
        cell_size_m: [1.0, 1.0],
        nodata_filled: 0,
        land_cover: "cover.tif".into(),
        cover_table: "ESA\u{1b}[2J WorldCover".into(),
        density_map: String::new(),
        mask: String::new(),
    });
    let e = m.validate(toml_path()).unwrap_err().to_string();
    for needle in ["source.cover_table", "U+001B", "control character"] {
        assert!(e.contains(needle), "{needle:?} not in {e:?}");
    }
    assert_eq!(
        verdant::world::manifest::without_control_characters("a\u{1b}b\tc\n"),
        "a\u{FFFD}b\tc\n"
    );
}

/// A name of a million characters was accepted and printed whole in every line that names the
/// world: names are at most 256 characters, each refused naming the field; other texts (the
/// source's file names, which a bake of thousands of DEM files joins) are not limited.
#[test]
fn overlong_names_in_a_manifest_are_refused() {
    let long = |n: usize| "x".repeat(n);
    for (from, to, field, says) in [
        (
            "name = \"test\"".to_string(),
            format!("name = \"{}\"", long(1_000_000)),
            "name",
            "a name of 1000000 characters",
        ),
        (
            "name = \"overview\"".to_string(),
            format!("name = \"{}\"", long(257)),
            "paths[0].name",
            "at most 256 characters",
        ),
    ] {
        let e = broken(&from, &to).to_string();
        for needle in [field, says] {
            assert!(
                e.contains(needle),
                "{needle:?} not in {:?}",
                &e[..e.len().min(300)]
            );
        }
        assert!(
            e.len() < 1000,
            "the error repeats the text: {} bytes",
            e.len()
        );
    }
    // At the limit, and a long description, accepted.
    let ok = VALID
        .replacen("name = \"test\"", &format!("name = \"{}\"", long(256)), 1)
        .replacen(
            "description = \"a small test world\"",
            &format!("description = \"{}\"", long(100_000)),
            1,
        );
    assert!(parse(&ok).is_ok());
}

#[test]
fn missing_world_dir_and_manifest() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nowhere");
    let err = World::open(&missing).unwrap_err();
    assert!(matches!(err, WorldError::MissingWorldDir { .. }), "{err}");
    assert!(err.to_string().contains("nowhere"), "{err}");

    let err = World::open(dir.path()).unwrap_err();
    assert!(matches!(err, WorldError::MissingFile { .. }), "{err}");
    assert!(err.to_string().contains("world.toml"), "{err}");
}

fn pyramid() -> Pyramid {
    Pyramid {
        root_tile_size_m: 512.0,
        root_tiles: [2, 2],
        tile_cells: 16,
        border: 2,
        stored_levels: 2,
        derived_levels: 1,
    }
}

const RANGE: [f32; 2] = [-100.0, 1000.0];

fn random_tile(id: TileId, size: u32, seed: u64) -> TileData {
    let mut rng = Rng(seed);
    let n = (size * size) as usize;
    TileData {
        id,
        size,
        heights: (0..n)
            .map(|_| (RANGE[0] as f64 + rng.unit() * f64::from(RANGE[1] - RANGE[0])) as f32)
            .collect(),
        grass_type: (0..n).map(|_| (rng.next_u64() % 4) as u8).collect(),
        density: (0..n).map(|_| rng.next_u64() as u8).collect(),
        material: Vec::new(),
    }
}

#[test]
fn tiles_round_trip_bit_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let p = pyramid();
    for (k, id) in [
        TileId::new(0, 0, 0),
        TileId::new(0, 1, 1),
        TileId::new(1, 3, 2),
    ]
    .into_iter()
    .enumerate()
    {
        let mut tile = random_tile(id, p.samples_per_side(), 11 + k as u64);
        // Awkward values survive too.
        tile.heights[0] = -0.0;
        tile.heights[1] = f32::MIN_POSITIVE / 8.0;
        tile.heights[2] = 999.999_94;
        write_tile(dir.path(), &p, &tile).unwrap();
        let back = read_tile(dir.path(), &p, id, RANGE).unwrap();
        assert_eq!(back.id, id);
        assert_eq!(back.size, tile.size);
        let bits = |v: &[f32]| v.iter().map(|h| h.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&back.heights), bits(&tile.heights));
        assert_eq!(back.grass_type, tile.grass_type);
        assert_eq!(back.density, tile.density);
        assert_eq!(back.byte_size(), tile.byte_size());
    }
    assert!(
        tile_path(dir.path(), TileId::new(1, 3, 2), TileFile::Height)
            .ends_with("tiles/L1/3_2.height.exr")
    );
}

/// The files store the north edge first: the type PNG's first row is the tile's last (north) row.
#[test]
fn files_store_north_first() {
    let dir = tempfile::tempdir().unwrap();
    let p = pyramid();
    let id = TileId::new(0, 0, 0);
    let tile = random_tile(id, p.samples_per_side(), 5);
    write_tile(dir.path(), &p, &tile).unwrap();
    let png = image::open(tile_path(dir.path(), id, TileFile::Type))
        .unwrap()
        .into_luma8();
    let size = tile.size;
    for i in 0..size {
        assert_eq!(
            png.get_pixel(i, 0).0[0],
            tile.grass_type[tile.index(i, size - 1)]
        );
        assert_eq!(
            png.get_pixel(i, size - 1).0[0],
            tile.grass_type[tile.index(i, 0)]
        );
    }
}

/// A stamped world's tile files are checked against their stamps: a file copied over
/// another's (of another tile, or another map of the same tile) and a file of another bake are
/// refused naming both; an unstamped file (edited by hand) and a world without a `bake_id` are
/// read as they are.
#[test]
fn tile_files_are_checked_against_their_stamps() {
    let dir = tempfile::tempdir().unwrap();
    let p = pyramid();
    let ours = 0x0123_4567_89ab_cdef;
    let theirs = 0xfedc_ba98_7654_3210;
    let options = ReadOptions {
        height_range_m: RANGE,
        grass_type_count: 256,
        materials: false,
        bake_id: Some(ours),
    };
    let [a, b] = [TileId::new(1, 2, 1), TileId::new(1, 3, 1)];
    for (k, id) in [a, b].into_iter().enumerate() {
        let tile = random_tile(id, p.samples_per_side(), 20 + k as u64);
        write_tile_with(dir.path(), &p, &tile, Some(ours)).unwrap();
        assert_eq!(read_tile_with(dir.path(), &p, id, &options).unwrap(), tile);
    }
    let read = |options: &ReadOptions| read_tile_with(dir.path(), &p, a, options);
    let put_back = || {
        write_tile_with(
            dir.path(),
            &p,
            &random_tile(a, p.samples_per_side(), 20),
            Some(ours),
        )
        .unwrap()
    };

    // Another tile's height file copied over a's.
    std::fs::copy(
        tile_path(dir.path(), b, TileFile::Height),
        tile_path(dir.path(), a, TileFile::Height),
    )
    .unwrap();
    let err = read(&options).unwrap_err();
    assert!(matches!(err, WorldError::TileStamp { .. }), "{err}");
    assert_names(&err, "tiles/L1/2_1.height.exr");
    let msg = err.to_string();
    assert!(msg.contains("holds L1/3_1.height.exr"), "{msg}");
    assert!(msg.contains("not L1/2_1.height.exr"), "{msg}");
    // Without a bake_id nothing is checked: the copy reads as the other tile's heights.
    let unchecked = ReadOptions {
        bake_id: None,
        ..options
    };
    assert!(read(&unchecked).is_ok());
    put_back();

    // The density map copied over the type map of the same tile.
    std::fs::copy(
        tile_path(dir.path(), a, TileFile::Density),
        tile_path(dir.path(), a, TileFile::Type),
    )
    .unwrap();
    let err = read(&options).unwrap_err();
    assert!(matches!(err, WorldError::TileStamp { .. }), "{err}");
    assert!(
        err.to_string().contains("holds L1/2_1.density.png"),
        "{err}"
    );
    put_back();

    // A file of another bake of the same tile.
    let other = tempfile::tempdir().unwrap();
    write_tile_with(
        other.path(),
        &p,
        &random_tile(a, p.samples_per_side(), 30),
        Some(theirs),
    )
    .unwrap();
    std::fs::copy(
        tile_path(other.path(), a, TileFile::Density),
        tile_path(dir.path(), a, TileFile::Density),
    )
    .unwrap();
    let err = read(&options).unwrap_err();
    assert!(matches!(err, WorldError::TileStamp { .. }), "{err}");
    assert_names(&err, "tiles/L1/2_1.density.png");
    let msg = err.to_string();
    assert!(
        msg.contains("fedcba9876543210") && msg.contains("0123456789abcdef"),
        "{msg}"
    );
    put_back();
    assert!(read(&options).is_ok());

    // A map written without a stamp (as an image editor may save it, or a server's optimiser
    // strip it) is refused, saying how to record a change that was meant.
    let mut edited = random_tile(a, p.samples_per_side(), 20);
    edited.density.iter_mut().for_each(|d| *d = 255 - *d);
    let unstamped = tempfile::tempdir().unwrap();
    write_tile(unstamped.path(), &p, &edited).unwrap();
    std::fs::copy(
        tile_path(unstamped.path(), a, TileFile::Density),
        tile_path(dir.path(), a, TileFile::Density),
    )
    .unwrap();
    let err = read(&options).unwrap_err();
    assert!(matches!(err, WorldError::TileStamp { .. }), "{err}");
    let msg = err.to_string();
    assert!(msg.contains("carries no verdant-tile stamp"), "{msg}");
    assert!(msg.contains("verdant check WORLD --stamp"), "{msg}");
    assert_eq!(read(&unchecked).unwrap().density, edited.density);
    put_back();

    // Stamps the baker does not write: each refused, the stamp's text escaped in the message.
    let density_path = tile_path(dir.path(), a, TileFile::Density);
    let size = p.samples_per_side();
    for (stamps, says) in [
        (
            vec!["\u{1b}]0;title\u{7}\nL5/5_5: forged 0123456789abcdef".to_owned()],
            "is not \"L1/2_1.density.png 0123456789abcdef\" nor any stamp",
        ),
        (
            vec!["L1/2_1.density.png ".to_owned()],
            "nor any stamp the baker writes",
        ),
        (
            vec!["L1/2_1.density.png  0123456789abcdef".to_owned()],
            "nor any stamp",
        ),
        (vec!["x".repeat(5000)], "..."),
        (
            vec!["L1/2_1.density.png 0123456789abcdef".to_owned(); 2],
            "carries 2 verdant-tile stamps",
        ),
    ] {
        std::fs::write(&density_path, png_with_texts(size, &stamps)).unwrap();
        let err = read(&options).unwrap_err();
        let msg = err.to_string();
        assert!(matches!(err, WorldError::TileStamp { .. }), "{msg}");
        assert!(msg.contains(says), "{stamps:?}: {msg}");
        assert!(!msg.chars().any(|c| c.is_control()), "{msg:?}");
        assert!(msg.len() < 600, "{} bytes", msg.len());
    }
}

/// A grayscale PNG of `size` a side carrying `texts` as `verdant-tile` text chunks.
fn png_with_texts(size: u32, texts: &[String]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, size, size);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(png::BitDepth::Eight);
    for t in texts {
        encoder
            .add_text_chunk("verdant-tile".to_owned(), t.clone())
            .unwrap();
    }
    let mut writer = encoder.write_header().unwrap();
    writer
        .write_image_data(&vec![128; (size * size) as usize])
        .unwrap();
    writer.finish().unwrap();
    out
}

/// A manifest's bake_id is 16 lowercase hexadecimal digits, as the baker writes it.
#[test]
fn a_bake_id_that_is_not_sixteen_hex_digits_is_refused() {
    let with =
        |id: &str| VALID.replacen("[pyramid]", &format!("bake_id = \"{id}\"\n\n[pyramid]"), 1);
    let m = Manifest::parse(&with("0123456789abcdef"), toml_path()).unwrap();
    assert_eq!(m.bake_id_value(), Some(0x0123_4567_89ab_cdef));
    for bad in [
        "0123456789ABCDEF",
        "0123",
        "0123456789abcdefa",
        "0123456789abcdeg",
        "",
    ] {
        let err = Manifest::parse(&with(bad), toml_path()).unwrap_err();
        assert!(
            matches!(err, WorldError::OutOfRange { ref field, .. } if field == "bake_id"),
            "{bad:?}: {err}"
        );
    }
}

fn written_tile(dir: &Path) -> (Pyramid, TileId) {
    let p = pyramid();
    let id = TileId::new(1, 2, 1);
    write_tile(dir, &p, &random_tile(id, p.samples_per_side(), 3)).unwrap();
    (p, id)
}

fn assert_names(err: &WorldError, file: &str) {
    let msg = err.to_string();
    assert!(msg.contains(file), "message does not name {file}: {msg}");
}

#[test]
fn truncated_exr_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (p, id) = written_tile(dir.path());
    let path = tile_path(dir.path(), id, TileFile::Height);
    let bytes = std::fs::read(&path).unwrap();
    for len in [0, 10, 300, bytes.len() / 2, bytes.len() - 1] {
        std::fs::write(&path, &bytes[..len]).unwrap();
        let err = read_tile(dir.path(), &p, id, RANGE).unwrap_err();
        assert!(
            matches!(err, WorldError::CorruptImage { format: "EXR", .. }),
            "{len}: {err}"
        );
        assert_names(&err, "L1/2_1.height.exr");
    }
}

#[test]
fn random_bytes_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let (p, id) = written_tile(dir.path());
    let mut rng = Rng(99);
    for kind in TileFile::ALL {
        let path = tile_path(dir.path(), id, kind);
        let good = std::fs::read(&path).unwrap();
        for round in 0..40 {
            let mut bytes = good.clone();
            if round < 20 {
                // Flip bytes of a good file.
                for _ in 0..1 + round {
                    let k = (rng.next_u64() % bytes.len() as u64) as usize;
                    bytes[k] ^= (rng.next_u64() % 255 + 1) as u8;
                }
            } else {
                bytes = (0..rng.next_u64() % 2000)
                    .map(|_| rng.next_u64() as u8)
                    .collect();
            }
            std::fs::write(&path, &bytes).unwrap();
            // Any result but a panic will do; errors must name the file.
            if let Err(err) = read_tile(dir.path(), &p, id, RANGE) {
                assert!(err.to_string().contains(&*path.to_string_lossy()), "{err}");
            }
        }
        std::fs::write(&path, &good).unwrap();
    }
}

#[test]
fn corrupt_png_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (p, id) = written_tile(dir.path());
    let path = tile_path(dir.path(), id, TileFile::Type);
    let mut rng = Rng(7);
    let junk: Vec<u8> = (0..500).map(|_| rng.next_u64() as u8).collect();
    std::fs::write(&path, junk).unwrap();
    let err = read_tile(dir.path(), &p, id, RANGE).unwrap_err();
    assert!(
        matches!(err, WorldError::CorruptImage { format: "PNG", .. }),
        "{err}"
    );
    assert_names(&err, "L1/2_1.type.png");

    let path = tile_path(dir.path(), id, TileFile::Density);
    let good = std::fs::read(&path).unwrap();
    std::fs::write(&path, &good[..good.len() - 20]).unwrap();
    written_tile_type_fixed(dir.path(), &p, id);
    let err = read_tile(dir.path(), &p, id, RANGE).unwrap_err();
    assert!(
        matches!(err, WorldError::CorruptImage { format: "PNG", .. }),
        "{err}"
    );
    assert_names(&err, "L1/2_1.density.png");
}

/// Rewrites only the type map of `id` with a valid one.
fn written_tile_type_fixed(dir: &Path, p: &Pyramid, id: TileId) {
    let size = p.samples_per_side();
    image::GrayImage::new(size, size)
        .save(tile_path(dir, id, TileFile::Type))
        .unwrap();
}

#[test]
fn tile_of_the_wrong_size_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let small = Pyramid {
        tile_cells: 8,
        ..pyramid()
    };
    let id = TileId::new(0, 1, 0);
    write_tile(
        dir.path(),
        &small,
        &random_tile(id, small.samples_per_side(), 1),
    )
    .unwrap();
    let err = read_tile(dir.path(), &pyramid(), id, RANGE).unwrap_err();
    assert!(
        matches!(
            err,
            WorldError::WrongDimensions {
                expected: [21, 21],
                found: [13, 13],
                ..
            }
        ),
        "{err}"
    );
    assert!(
        err.to_string()
            .ends_with("L0/1_0.height.exr: expected 21x21 samples, found 13x13"),
        "{err}"
    );

    // A type map of the wrong size, beside a good height file.
    let p = pyramid();
    write_tile(dir.path(), &p, &random_tile(id, p.samples_per_side(), 1)).unwrap();
    image::GrayImage::new(21, 20)
        .save(tile_path(dir.path(), id, TileFile::Type))
        .unwrap();
    let err = read_tile(dir.path(), &p, id, RANGE).unwrap_err();
    assert!(
        matches!(
            err,
            WorldError::WrongDimensions {
                found: [21, 20],
                ..
            }
        ),
        "{err}"
    );
    assert_names(&err, "1_0.type.png");

    // Writing data that does not fit the pyramid is refused too.
    let err = write_tile(dir.path(), &p, &random_tile(id, 20, 1)).unwrap_err();
    assert!(matches!(err, WorldError::BadTileData { .. }), "{err}");
}

#[test]
fn wrong_layouts_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (p, id) = written_tile(dir.path());
    // A 16-bit type map.
    image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::new(21, 21)
        .save(tile_path(dir.path(), id, TileFile::Type))
        .unwrap();
    let err = read_tile(dir.path(), &p, id, RANGE).unwrap_err();
    assert!(matches!(err, WorldError::WrongLayout { .. }), "{err}");
    let text = err.to_string();
    assert!(text.contains("expected 8-bit grayscale"), "{err}");
    assert!(text.ends_with("found 16-bit grayscale"), "{err}");

    // An RGB height file.
    write_exr(
        &tile_path(dir.path(), id, TileFile::Height),
        21,
        &["R", "G", "B"],
        |_| 1.0,
    );
    let err = read_tile(dir.path(), &p, id, RANGE).unwrap_err();
    assert!(matches!(err, WorldError::WrongLayout { .. }), "{err}");
    assert_names(&err, "2_1.height.exr");
}

/// Writes an f32 EXR with the given channels, every channel holding `f(sample index)`.
fn write_exr(path: &Path, size: usize, channels: &[&str], f: impl Fn(usize) -> f32) {
    use exr::prelude::*;
    let list: Vec<AnyChannel<FlatSamples>> = channels
        .iter()
        .map(|name| AnyChannel::new(*name, FlatSamples::F32((0..size * size).map(&f).collect())))
        .collect();
    let layer = Layer::new(
        (size, size),
        LayerAttributes::named("height"),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(SmallVec::from_vec(list)),
    );
    Image::from_layer(layer).write().to_file(path).unwrap();
}

#[test]
fn nan_heights_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (p, id) = written_tile(dir.path());
    let path = tile_path(dir.path(), id, TileFile::Height);
    // Sample 5 of the file's first row: i = 5 at the north edge, j = 20.
    write_exr(&path, 21, &["Y"], |k| if k == 5 { f32::NAN } else { 10.0 });
    let err = read_tile(dir.path(), &p, id, RANGE).unwrap_err();
    assert!(
        matches!(err, WorldError::NonFiniteHeight { i: 5, j: 20, .. }),
        "{err}"
    );
    assert_names(&err, "2_1.height.exr");

    write_exr(&path, 21, &["Y"], |k| {
        if k == 21 * 20 { f32::INFINITY } else { 10.0 }
    });
    let err = read_tile(dir.path(), &p, id, RANGE).unwrap_err();
    assert!(
        matches!(err, WorldError::NonFiniteHeight { i: 0, j: 0, .. }),
        "{err}"
    );

    // Writing NaN is refused before anything reaches the disk.
    let mut tile = random_tile(id, 21, 1);
    tile.heights[7] = f32::NAN;
    assert!(matches!(
        write_tile(dir.path(), &p, &tile),
        Err(WorldError::BadTileData { .. })
    ));
}

#[test]
fn heights_outside_the_range_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (p, id) = written_tile(dir.path());
    // Within 1 m + 1 % of the span: accepted.
    let ok = read_tile(dir.path(), &p, id, [-100.0, 990.0]);
    assert!(ok.is_ok());
    let err = read_tile(dir.path(), &p, id, [0.0, 500.0]).unwrap_err();
    assert!(matches!(err, WorldError::HeightOutOfRange { .. }), "{err}");
    assert_names(&err, "2_1.height.exr");
}

#[test]
fn grass_types_beyond_the_manifest_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (p, id) = written_tile(dir.path());
    let options = ReadOptions {
        height_range_m: RANGE,
        grass_type_count: 3,
        materials: false,
        bake_id: None,
    };
    let err = read_tile_with(dir.path(), &p, id, &options).unwrap_err();
    assert!(
        matches!(
            err,
            WorldError::GrassTypeOutOfRange {
                index: 3,
                count: 3,
                ..
            }
        ),
        "{err}"
    );
    assert_names(&err, "2_1.type.png");
    let options = ReadOptions {
        grass_type_count: 4,
        ..options
    };
    assert!(read_tile_with(dir.path(), &p, id, &options).is_ok());
}

#[test]
fn missing_tiles_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (p, id) = written_tile(dir.path());
    std::fs::remove_file(tile_path(dir.path(), id, TileFile::Density)).unwrap();
    let err = read_tile(dir.path(), &p, id, RANGE).unwrap_err();
    assert!(matches!(err, WorldError::MissingFile { .. }), "{err}");
    assert_names(&err, "2_1.density.png");

    let err = read_tile(dir.path(), &p, TileId::new(0, 0, 0), RANGE).unwrap_err();
    assert!(matches!(err, WorldError::MissingFile { .. }), "{err}");
    assert_names(&err, "L0/0_0.height.exr");

    // Outside the stored levels or the grid: not a stored tile at all.
    for id in [TileId::new(2, 0, 0), TileId::new(0, 2, 0)] {
        let err = read_tile(dir.path(), &p, id, RANGE).unwrap_err();
        assert!(matches!(err, WorldError::TileNotStored { .. }), "{err}");
    }
}

/// A grayscale PNG of `bits` (1, 2, 4 or 8) bits a sample, `size` square, holding `values`
/// (north row first), as an image editor saving a map at a low bit depth writes it.
fn gray_png(path: &Path, size: u32, bits: u8, values: &[u8]) {
    let depth = match bits {
        1 => png::BitDepth::One,
        2 => png::BitDepth::Two,
        4 => png::BitDepth::Four,
        _ => png::BitDepth::Eight,
    };
    let per_byte = 8 / usize::from(bits);
    let mut packed = Vec::new();
    for row in values.chunks(size as usize) {
        for group in row.chunks(per_byte) {
            let mut byte = 0u8;
            for (k, &v) in group.iter().enumerate() {
                assert!(u32::from(v) < 1 << bits, "{v} does not fit {bits} bits");
                byte |= v << (8 - usize::from(bits) * (k + 1));
            }
            packed.push(byte);
        }
    }
    let mut encoder = png::Encoder::new(std::fs::File::create(path).unwrap(), size, size);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(depth);
    let mut writer = encoder.write_header().unwrap();
    writer.write_image_data(&packed).unwrap();
}

/// Maps of 1, 2 and 4 bits read as their own values: a 4-bit type map holding 0..=3 is types
/// 0..=3 (not 0, 17, 34, 51, as the decoder scales them for display), and a 4-bit density map
/// holds densities 0..=15 of 255.
#[test]
fn low_bit_depth_maps_read_as_their_values() {
    let dir = tempfile::tempdir().unwrap();
    let (p, id) = written_tile(dir.path());
    let size = p.samples_per_side();
    let n = (size * size) as usize;
    for bits in [1u8, 2, 4] {
        let top = (1u16 << bits) as usize;
        let types: Vec<u8> = (0..n).map(|k| ((k * 7) % top.min(4)) as u8).collect();
        let density: Vec<u8> = (0..n).map(|k| ((k * 5) % top) as u8).collect();
        gray_png(
            &tile_path(dir.path(), id, TileFile::Type),
            size,
            bits,
            &types,
        );
        gray_png(
            &tile_path(dir.path(), id, TileFile::Density),
            size,
            bits,
            &density,
        );
        let options = ReadOptions {
            height_range_m: RANGE,
            grass_type_count: 4,
            materials: false,
            bake_id: None,
        };
        let tile = read_tile_with(dir.path(), &p, id, &options)
            .unwrap_or_else(|e| panic!("{bits}-bit maps: {e}"));
        // The files are north row first, the tile south row first.
        let south_first =
            |v: &[u8]| -> Vec<u8> { v.chunks(size as usize).rev().flatten().copied().collect() };
        assert_eq!(tile.grass_type, south_first(&types), "{bits}-bit type map");
        assert_eq!(
            tile.density,
            south_first(&density),
            "{bits}-bit density map"
        );
    }
}

/// A palette PNG is refused by name: whether it meant its indices or its colours cannot be told.
#[test]
fn palette_maps_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (p, id) = written_tile(dir.path());
    let size = p.samples_per_side();
    let path = tile_path(dir.path(), id, TileFile::Type);
    let mut encoder = png::Encoder::new(std::fs::File::create(&path).unwrap(), size, size);
    encoder.set_color(png::ColorType::Indexed);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_palette(vec![0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3]);
    let mut writer = encoder.write_header().unwrap();
    writer
        .write_image_data(&vec![1u8; (size * size) as usize])
        .unwrap();
    drop(writer);
    let err = read_tile(dir.path(), &p, id, RANGE).unwrap_err();
    assert!(matches!(err, WorldError::WrongLayout { .. }), "{err}");
    assert_names(&err, "2_1.type.png");
    assert!(
        err.to_string()
            .ends_with("found 8-bit palette (indexed-colour)"),
        "{err}"
    );
}

/// A world lists at most MAX_GRASS_TYPES (16) grass types: the renderer draws that many, and a
/// 17th would be drawn as the 16th.
#[test]
fn manifest_with_more_grass_types_than_the_renderer_draws_is_refused() {
    use verdant::world::manifest::MAX_GRASS_TYPES;
    assert_eq!(MAX_GRASS_TYPES, 16);
    let meadow = &VALID[VALID.rfind("[[grass_types]]").unwrap()..VALID.find("[[paths]]").unwrap()];
    let with_types = |count: usize| -> String {
        let extra: String = (2..count)
            .map(|i| meadow.replace("name = \"meadow\"", &format!("name = \"meadow {i}\"")))
            .collect();
        VALID.replacen("[[paths]]", &format!("{extra}[[paths]]"), 1)
    };
    let m = parse(&with_types(16)).unwrap();
    assert_eq!(m.grass_types.len(), 16);
    let err = parse(&with_types(17)).unwrap_err();
    assert!(
        matches!(err, WorldError::OutOfRange { ref field, .. } if field == "grass_types"),
        "{err}"
    );
    let text = err.to_string();
    assert!(
        text.starts_with("worlds/test/world.toml: grass_types = 17 types: must be at most 16"),
        "{text}"
    );
}

/// Every float of the manifest has a documented range: NaN, infinities and absurd magnitudes are
/// refused with the field and the range named.
#[test]
fn manifest_floats_beyond_their_ranges_are_refused_naming_field_and_range() {
    let sky = "\n[sky]\nsun_azimuth_deg = 225.0\nsun_elevation_deg = 35.0\n\
               sun_color = [1.0, 0.9, 0.8]\nsky_color = [0.3, 0.5, 0.8]\n\
               horizon_color = [0.7, 0.8, 0.9]\nfog_distance_m = 12000.0\n\n[[paths]]";
    let wind = "\n[wind]\ndirection_deg = 20.0\nspeed_mps = 4.0\ngustiness = 0.35\n";
    let text = VALID.replacen("\n[[paths]]", &format!("{wind}{sky}"), 1);
    parse(&text).unwrap();
    let cases: &[(&str, &str, &str, &str)] = &[
        (
            "speed_mps = 4.0",
            "speed_mps = 1e30",
            "wind.speed_mps",
            "at most 120 m/s",
        ),
        (
            "gustiness = 0.35",
            "gustiness = 3.0",
            "wind.gustiness",
            "in 0..=1",
        ),
        (
            "direction_deg = 20.0",
            "direction_deg = 1e30",
            "wind.direction_deg",
            "in -36000..=36000 degrees",
        ),
        (
            "sun_elevation_deg = 35.0",
            "sun_elevation_deg = 95.0",
            "sky.sun_elevation_deg",
            "in -90..=90 degrees",
        ),
        (
            "sun_azimuth_deg = 225.0",
            "sun_azimuth_deg = -1e20",
            "sky.sun_azimuth_deg",
            "in -36000..=36000 degrees",
        ),
        (
            "sun_color = [1.0, 0.9, 0.8]",
            "sun_color = [1.0, 1e30, 0.8]",
            "sky.sun_color[1]",
            "in 0..=100",
        ),
        (
            "sky_color = [0.3, 0.5, 0.8]",
            "sky_color = [0.3, -0.5, 0.8]",
            "sky.sky_color[1]",
            "in 0..=1",
        ),
        (
            "horizon_color = [0.7, 0.8, 0.9]",
            "horizon_color = [0.7, 0.8, 9.0]",
            "sky.horizon_color[2]",
            "in 0..=1",
        ),
        (
            "fog_distance_m = 12000.0",
            "fog_distance_m = 1e30",
            "sky.fog_distance_m",
            "at most 10000000 m",
        ),
        (
            "tip_color = [0.2, 0.5, 0.1]",
            "tip_color = [0.2, 5.0, 0.1]",
            "grass_types[1].tip_color[1]",
            "in 0..=1",
        ),
        (
            "stiffness = 0.5",
            "stiffness = 7.0",
            "grass_types[1].stiffness",
            "in 0..=1",
        ),
        (
            "height_m = [0.2, 0.4]",
            "height_m = [0.2, 1e30]",
            "grass_types[1].height_m[1]",
            "at most 10 m",
        ),
        (
            "width_m = [0.01, 0.02]",
            "width_m = [0.01, 2.0]",
            "grass_types[1].width_m[1]",
            "at most 1 m",
        ),
        (
            "root_tile_size_m = 512.0",
            "root_tile_size_m = 1e300",
            "pyramid.root_tile_size_m",
            "at most 100000000 m",
        ),
        (
            "duration_s = 10.0",
            "duration_s = 1e30",
            "paths[0].duration_s",
            "at most 1000000 s",
        ),
        (
            "{ t_s = 0.0,",
            "{ t_s = -1e30,",
            "paths[0].keys[0].t_s",
            "in -1000000..=1000000 s",
        ),
        (
            "[10.0, 10.0, 600.0]",
            "[10.0, 1e30, 600.0]",
            "paths[0].keys[0].position_m[1]",
            "in -20000000..=20000000 m",
        ),
        (
            "yaw_deg = 45.0",
            "yaw_deg = 1e30",
            "paths[0].keys[0].yaw_deg",
            "in -36000..=36000 degrees",
        ),
        (
            "pitch_deg = -10.0",
            "pitch_deg = -100.0",
            "paths[0].keys[0].pitch_deg",
            "in -90..=90 degrees",
        ),
    ];
    for &(from, to, field, range) in cases {
        assert!(text.contains(from), "{from}");
        let err = parse(&text.replacen(from, to, 1)).expect_err(to);
        assert!(
            matches!(err, WorldError::OutOfRange { field: ref f, .. } if f == field),
            "{to}: {err}"
        );
        let message = err.to_string();
        assert!(
            message.starts_with(&format!("worlds/test/world.toml: {field} = ")),
            "{message}"
        );
        assert!(message.ends_with(&format!("must be {range}")), "{message}");
    }
    // NaN and infinities are named as such.
    let err = parse(&text.replacen("speed_mps = 4.0", "speed_mps = nan", 1)).unwrap_err();
    assert!(
        matches!(err, WorldError::NonFinite { ref field, .. } if field == "wind.speed_mps"),
        "{err}"
    );
    let err = parse(&text.replacen("stiffness = 0.5", "stiffness = -inf", 1)).unwrap_err();
    assert!(
        matches!(err, WorldError::NonFinite { ref field, .. } if field == "grass_types[1].stiffness"),
        "{err}"
    );
}

/// A plant type, and each way one can be out of range: refused naming the field.
#[test]
fn plant_types_are_read_and_bad_ones_named() {
    let plant = r#"
[[plant_types]]
name = "poppy"
mesh = "flower"
size_m = [0.3, 0.5]
density = { meadow = 0.4 }
wind = { bend = 0.05 }
"#;
    let with = |p: &str| format!("{VALID}{p}");
    let m = parse(&with(plant)).unwrap();
    assert_eq!(m.plant_types.len(), 1);
    assert_eq!(m.plant_types[0].density["meadow"], 0.4);
    assert_eq!(m.plant_types[0].wind.bend, 0.05);
    assert_eq!(m.plant_types[0].max_slope_deg, 35.0, "a default");
    for (from, to, field) in [
        (
            "mesh = \"flower\"",
            "mesh = \"tulip\"",
            "plant_types[0].mesh",
        ),
        (
            "mesh = \"flower\"",
            "mesh = \"tulip.obj\"",
            "plant_types[0].mesh",
        ),
        (
            "size_m = [0.3, 0.5]",
            "size_m = [0.5, 0.3]",
            "plant_types[0].size_m",
        ),
        (
            "size_m = [0.3, 0.5]",
            "size_m = [0.0, 0.3]",
            "plant_types[0].size_m",
        ),
        ("name = \"poppy\"", "name = \" \"", "plant_types[0].name"),
        (
            "size_m = [0.3, 0.5]",
            "size_m = [1e-30, 1e-30]",
            "plant_types[0].size_m",
        ),
        (
            "mesh = \"flower\"",
            "mesh = \"../../elsewhere/fern.glb\"",
            "plant_types[0].mesh",
        ),
        (
            "mesh = \"flower\"",
            "mesh = \"/srv/plants/fern.gltf\"",
            "plant_types[0].mesh",
        ),
        (
            "mesh = \"flower\"",
            "mesh = \"plants/../plants/fern.gltf\"",
            "plant_types[0].mesh",
        ),
        (
            "mesh = \"flower\"",
            "mesh = '..\\x.gltf'",
            "plant_types[0].mesh",
        ),
        ("meadow = 0.4", "lawn = 0.4", "plant_types[0].density.lawn"),
        (
            "meadow = 0.4",
            "meadow = 9.0",
            "plant_types[0].density.meadow",
        ),
        (
            "meadow = 0.4",
            "meadow = nan",
            "plant_types[0].density.meadow",
        ),
        ("bend = 0.05", "bend = 2.0", "plant_types[0].wind.bend"),
    ] {
        let text = with(&plant.replace(from, to));
        let err = parse(&text).expect_err(to).to_string();
        assert!(err.contains(field), "{to}: {err}");
        assert!(err.contains("world.toml"), "{to}: {err}");
    }
    // Two types whose densities add up past the grid's one plant a cell.
    let crowded = with(&format!(
        "{}{}",
        plant.replace("meadow = 0.4", "meadow = 0.45"),
        plant
            .replace("poppy", "daisy")
            .replace("meadow = 0.4", "meadow = 3.96")
    ));
    let err = parse(&crowded).expect_err("crowded").to_string();
    // The sum as the file's numbers add up (it printed 4.4100000113248825).
    assert!(
        err.contains("density.meadow = 4.41 plants per m2 in all"),
        "{err}"
    );
}

/// A 32-bit field's range is inclusive of its ends as the file writes them (0.01 reads as
/// 0.0099999998 in 32 bits, and was refused as below 0.01), and a refused value is printed as the
/// file holds it.
#[test]
fn a_32_bit_fields_range_ends_are_inclusive_and_its_value_printed_as_written() {
    let plant = r#"
[[plant_types]]
name = "poppy"
mesh = "flower"
size_m = [0.01, 0.01]
density = { meadow = 0.4 }
wind = { sway_damping = 0.01 }
"#;
    let m = parse(&format!("{VALID}{plant}")).unwrap();
    assert_eq!(m.plant_types[0].size_m, [0.01, 0.01]);
    assert_eq!(m.plant_types[0].wind.sway_damping, 0.01);
    for (from, to, shown) in [
        (
            "sway_damping = 0.01",
            "sway_damping = 0.0099",
            "sway_damping = 0.0099:",
        ),
        (
            "size_m = [0.01, 0.01]",
            "size_m = [0.0099, 0.01]",
            "size_m = [0.0099, 0.01]:",
        ),
        ("meadow = 0.4", "meadow = -0.45", "density.meadow = -0.45"),
    ] {
        let err = parse(&format!("{VALID}{}", plant.replace(from, to)))
            .expect_err(to)
            .to_string();
        assert!(err.contains(shown), "{to}: {err}");
    }
    let err = parse(&VALID.replacen(
        "tip_color = [0.2, 0.5, 0.1]",
        "tip_color = [-0.1, 0.5, 0.1]",
        1,
    ))
    .unwrap_err()
    .to_string();
    assert!(err.contains("tip_color[0] = -0.1:"), "{err}");
}

/// The finest tiles, where the grass grows, are 0.5 to 1024 m wide: a pyramid outside that is
/// refused naming `pyramid.derived_levels` and the counts that fit (tiles of kilometres made a
/// frame that never finished, tiles of centimetres an error about a renderer setting).
#[test]
fn the_finest_tiles_are_grass_sized() {
    // 512 m roots, two stored levels: the stored finest tiles are 256 m.
    for (to, fits) in [
        ("derived_levels = 10", "(they are 0.25 m): 0..=9"),
        (
            "derived_levels = 0\nroot_tile_size_m = 4096.0",
            "(they are 2048 m): 1..=12",
        ),
    ] {
        let text = VALID
            .replacen("derived_levels = 1", to.split('\n').next().unwrap(), 1)
            .replacen(
                "root_tile_size_m = 512.0",
                to.split('\n').nth(1).unwrap_or("root_tile_size_m = 512.0"),
                1,
            );
        let err = parse(&text).unwrap_err();
        let message = err.to_string();
        assert!(
            matches!(err, WorldError::OutOfRange { ref field, .. } if field == "pyramid.derived_levels"),
            "{to}: {message}"
        );
        assert!(
            message.contains("0.5 to 1024 m wide") && message.contains(fits),
            "{message}"
        );
    }
    for ok in ["derived_levels = 0", "derived_levels = 9"] {
        parse(&VALID.replacen("derived_levels = 1", ok, 1)).unwrap();
    }
}

/// A fixed-size array of another length is refused, naming the line (extra values, even of
/// the wrong type, were ignored).
#[test]
fn arrays_of_the_wrong_length_are_refused() {
    for (from, to, expected) in [
        (
            "extent_m = [900.0, 1000.0]",
            "extent_m = [900.0, 1000.0, 5.0]",
            "an array of 2 values",
        ),
        (
            "ground_color = [0.1, 0.2, 0.05]",
            "ground_color = [0.1, 0.2]",
            "an array of 3 values",
        ),
        (
            "root_tiles = [2, 2]",
            "root_tiles = [2, 2, 2]",
            "an array of 2 values",
        ),
        (
            "position_m = [10.0, 10.0, 600.0]",
            "position_m = [10.0, 10.0, 600.0, 1.0]",
            "an array of 3 values",
        ),
    ] {
        let message = broken(from, to).to_string();
        assert!(
            message.contains(expected) && message.contains(to),
            "{message}"
        );
    }
}

/// Grass types are named by plant types and cover tables: each name must be one and not empty;
/// the world's, its paths' and its wind scenes' names must not be empty either.
#[test]
fn names_are_not_empty_and_grass_types_differ() {
    for (from, to, field, expected) in [
        (
            "name = \"meadow\"",
            "name = \"bare\"",
            "grass_types[1].name",
            "no other grass type",
        ),
        (
            "name = \"meadow\"",
            "name = \" \"",
            "grass_types[1].name",
            "not empty",
        ),
        ("name = \"test\"", "name = \"\"", "name", "not empty"),
        (
            "name = \"overview\"",
            "name = \"\"",
            "paths[0].name",
            "not empty",
        ),
    ] {
        let err = broken(from, to);
        let message = err.to_string();
        assert!(
            matches!(err, WorldError::OutOfRange { field: ref f, .. } if f == field),
            "{to}: {message}"
        );
        assert!(message.contains(expected), "{message}");
    }
}
