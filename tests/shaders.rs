//! Every assembled shader stage parses and validates with naga (source spans in the error),
//! every WGSL function is written in one file only, and the shared WGSL agrees with the Rust it
//! mirrors.

use std::collections::BTreeMap;

use verdant::features::Feature;
use verdant::shaders::{STAGES, shared_pieces, source};

#[test]
fn every_assembled_stage_validates_with_naga() {
    for (name, _) in STAGES {
        let wgsl = source(name);
        let module = match naga::front::wgsl::parse_str(&wgsl) {
            Ok(m) => m,
            Err(e) => panic!("{name} does not parse:\n{}", e.emit_to_string(&wgsl)),
        };
        let mut validator = naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::all(),
        );
        if let Err(e) = validator.validate(&module) {
            panic!("{name} does not validate:\n{}", e.emit_to_string(&wgsl));
        }
        assert!(
            !wgsl.lines().any(|l| l.trim_start().starts_with("#include")),
            "{name} keeps an unresolved include"
        );
    }
}

#[test]
fn shared_pieces_are_defined_once_per_stage() {
    let defs = [
        "fn hash_u32(",
        "struct Blade {",
        "fn output_color(",
        "struct WindLookup {",
        "fn sun_visibility(",
    ];
    for (name, _) in STAGES {
        let wgsl = source(name);
        for def in defs {
            assert!(
                wgsl.matches(def).count() <= 1,
                "{name} defines {def:?} twice"
            );
        }
    }
    for (stage, def) in [
        ("stream_derive.wgsl", "fn hash_u32("),
        ("grass_generate.wgsl", "fn hash_u32("),
        ("wind_field.wgsl", "fn hash_u32("),
        ("grass_generate.wgsl", "struct Blade {"),
        ("grass_wind.wgsl", "struct Blade {"),
        ("grass_draw.wgsl", "struct Blade {"),
        ("grass_wind.wgsl", "struct WindLookup {"),
        ("terrain_composite.wgsl", "fn output_color("),
        ("terrain_gbuffer.wgsl", "struct Frame {"),
        ("terrain_shade.wgsl", "fn sun_visibility("),
        ("terrain_shade.wgsl", "fn sky_color("),
        ("grass_draw.wgsl", "fn output_color("),
    ] {
        assert_eq!(source(stage).matches(def).count(), 1, "{stage}: {def}");
    }
    // No stage file defines a shared piece itself: it includes it.
    for (name, text) in STAGES {
        for def in defs {
            assert!(
                !text.contains(def),
                "{name} defines {def:?} instead of including it"
            );
        }
    }
}

/// The names of the functions that `text` defines (`fn NAME(` at the start of a line).
fn function_names(text: &str) -> impl Iterator<Item = &str> {
    text.lines().filter_map(|line| {
        let rest = line.trim_start().strip_prefix("fn ")?;
        let name = &rest[..rest.find('(')?];
        Some(name.trim())
    })
}

#[test]
fn no_function_is_written_in_two_files() {
    let mut defined: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
    for (file, text) in STAGES.iter().chain(shared_pieces()) {
        for name in function_names(text) {
            defined.entry(name).or_default().push(file);
        }
    }
    assert!(defined.contains_key("hash_u32") && defined.contains_key("vs_full"));
    let twice: Vec<String> = defined
        .iter()
        .filter(|(_, files)| files.len() > 1)
        .map(|(name, files)| format!("{name}: {}", files.join(", ")))
        .collect();
    assert!(
        twice.is_empty(),
        "functions defined more than once (move each into shaders/shared/ or rename one):\n{}",
        twice.join("\n")
    );
}

#[test]
fn feature_bits_in_wgsl_match_the_rust_ones() {
    let text = verdant::shaders::shared("shared/features.wgsl").expect("features piece");
    for feature in Feature::ALL {
        let constant = feature.name().to_uppercase().replace('-', "_");
        let line = text
            .lines()
            .find(|l| l.starts_with(&format!("const {constant}: u32 = ")))
            .unwrap_or_else(|| panic!("shared/features.wgsl has no {constant}"));
        let value: u32 = line
            .trim_start_matches(&format!("const {constant}: u32 = "))
            .trim_end_matches("u;")
            .parse()
            .unwrap_or_else(|_| panic!("cannot read {line:?}"));
        assert_eq!(value, feature.bit(), "{constant}");
    }
}

#[test]
fn sway_slots_in_wgsl_match_the_rust_ones() {
    let text = verdant::shaders::shared("shared/sway_slots.wgsl").expect("sway slots piece");
    let constant = |name: &str| -> usize {
        let prefix = format!("const {name}: u32 = ");
        let line = text
            .lines()
            .find(|l| l.starts_with(&prefix))
            .unwrap_or_else(|| panic!("shared/sway_slots.wgsl has no {name}"));
        line.trim_start_matches(&prefix)
            .trim_end_matches("u;")
            .parse()
            .unwrap_or_else(|_| panic!("cannot read {line:?}"))
    };
    assert_eq!(constant("SWAY_SLOTS"), verdant::wind::SWAY_TYPES);
    assert_eq!(constant("PLANT_SWAY_SLOT"), verdant::wind::GRASS_SWAY_TYPES);
}
