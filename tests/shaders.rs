//! Every assembled shader stage parses and validates with naga (source spans in the error), and
//! the shared WGSL agrees with the Rust it mirrors.

use verdant::features::Feature;
use verdant::shaders::{STAGES, source};

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
        ("derive_child.wgsl", "fn hash_u32("),
        ("grass_generate.wgsl", "fn hash_u32("),
        ("wind_field.wgsl", "fn hash_u32("),
        ("grass_generate.wgsl", "struct Blade {"),
        ("grass_wind.wgsl", "struct Blade {"),
        ("grass_draw.wgsl", "struct Blade {"),
        ("grass_wind.wgsl", "struct WindLookup {"),
        ("composite.wgsl", "fn output_color("),
        ("terrain.wgsl", "struct Frame {"),
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
