//! Every stage's WGSL, assembled from `shaders/`.
//!
//! A stage's file may include shared pieces with a line `#include "shared/NAME.wgsl"`: the
//! integer hashes, the feature bits, the blade record of the instance pool, reading the wind
//! field, the colour output, the full-screen triangle and the terrain's shading. A piece may
//! include other pieces; each is written once in `shaders/shared/` and included at most once
//! per assembled shader, so every WGSL function is written in one file only. The sources are
//! compiled into the crate, so a shipped binary reads no shader files at run time;
//! `tests/shaders.rs` validates every assembled stage with naga and checks that no function
//! name is defined twice.

use std::borrow::Cow;

/// The shared pieces, by the path an `#include` names.
const SHARED: &[(&str, &str)] = &[
    (
        "shared/hash.wgsl",
        include_str!("../shaders/shared/hash.wgsl"),
    ),
    (
        "shared/features.wgsl",
        include_str!("../shaders/shared/features.wgsl"),
    ),
    (
        "shared/blade.wgsl",
        include_str!("../shaders/shared/blade.wgsl"),
    ),
    (
        "shared/wind_lookup.wgsl",
        include_str!("../shaders/shared/wind_lookup.wgsl"),
    ),
    (
        "shared/tile_texels.wgsl",
        include_str!("../shaders/shared/tile_texels.wgsl"),
    ),
    (
        "shared/hiz_cull.wgsl",
        include_str!("../shaders/shared/hiz_cull.wgsl"),
    ),
    (
        "shared/tile_job.wgsl",
        include_str!("../shaders/shared/tile_job.wgsl"),
    ),
    (
        "shared/plant_instance.wgsl",
        include_str!("../shaders/shared/plant_instance.wgsl"),
    ),
    (
        "shared/waves.wgsl",
        include_str!("../shaders/shared/waves.wgsl"),
    ),
    (
        "shared/sway_slots.wgsl",
        include_str!("../shaders/shared/sway_slots.wgsl"),
    ),
    (
        "shared/sway_lookup.wgsl",
        include_str!("../shaders/shared/sway_lookup.wgsl"),
    ),
    (
        "shared/output.wgsl",
        include_str!("../shaders/shared/output.wgsl"),
    ),
    (
        "shared/full_screen.wgsl",
        include_str!("../shaders/shared/full_screen.wgsl"),
    ),
    (
        "shared/terrain_shading.wgsl",
        include_str!("../shaders/shared/terrain_shading.wgsl"),
    ),
];

/// Every shared piece, by the path an `#include` names, with its source.
pub fn shared_pieces() -> &'static [(&'static str, &'static str)] {
    SHARED
}

/// One WGSL file per GPU stage, by file name.
pub const STAGES: &[(&str, &str)] = &[
    ("aa_taa.wgsl", include_str!("../shaders/aa_taa.wgsl")),
    ("aa_msaa.wgsl", include_str!("../shaders/aa_msaa.wgsl")),
    (
        "stream_derive.wgsl",
        include_str!("../shaders/stream_derive.wgsl"),
    ),
    (
        "terrain_gbuffer.wgsl",
        include_str!("../shaders/terrain_gbuffer.wgsl"),
    ),
    (
        "terrain_shade.wgsl",
        include_str!("../shaders/terrain_shade.wgsl"),
    ),
    (
        "terrain_composite.wgsl",
        include_str!("../shaders/terrain_composite.wgsl"),
    ),
    (
        "terrain_contact_shadow.wgsl",
        include_str!("../shaders/terrain_contact_shadow.wgsl"),
    ),
    ("grass_hiz.wgsl", include_str!("../shaders/grass_hiz.wgsl")),
    (
        "plants_place.wgsl",
        include_str!("../shaders/plants_place.wgsl"),
    ),
    (
        "plants_draw.wgsl",
        include_str!("../shaders/plants_draw.wgsl"),
    ),
    ("particles.wgsl", include_str!("../shaders/particles.wgsl")),
    (
        "renderer_hole_check.wgsl",
        include_str!("../shaders/renderer_hole_check.wgsl"),
    ),
    (
        "grass_generate.wgsl",
        include_str!("../shaders/grass_generate.wgsl"),
    ),
    (
        "grass_wind.wgsl",
        include_str!("../shaders/grass_wind.wgsl"),
    ),
    (
        "grass_draw.wgsl",
        include_str!("../shaders/grass_draw.wgsl"),
    ),
    (
        "wind_field.wgsl",
        include_str!("../shaders/wind_field.wgsl"),
    ),
    ("wind_sway.wgsl", include_str!("../shaders/wind_sway.wgsl")),
];

/// The source of a shared piece (`"shared/blade.wgsl"`), for a caller's own shader.
pub fn shared(path: &str) -> Option<&'static str> {
    SHARED.iter().find(|(p, _)| *p == path).map(|(_, s)| *s)
}

/// The assembled source of stage `name` (a file name of [`STAGES`]), its includes resolved.
///
/// # Panics
/// When `name` is not a stage or an include names no shared piece: both are fixed at compile
/// time and checked by the tests.
pub fn source(name: &str) -> String {
    let (_, text) = STAGES
        .iter()
        .find(|(n, _)| *n == name)
        .unwrap_or_else(|| panic!("no shader stage {name:?}"));
    assemble(text).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// Resolves the `#include "..."` lines of `text` (each piece once; pieces may include others).
pub fn assemble(text: &str) -> Result<String, String> {
    let mut out = String::with_capacity(text.len() * 2);
    let mut seen = Vec::new();
    append(text, &mut out, &mut seen)?;
    Ok(out)
}

fn append<'a>(text: &'a str, out: &mut String, seen: &mut Vec<&'a str>) -> Result<(), String> {
    for line in text.lines() {
        match include_of(line) {
            Some(path) => {
                if seen.contains(&path) {
                    continue;
                }
                let piece = shared(path).ok_or_else(|| format!("unknown include {path:?}"))?;
                seen.push(path);
                out.push_str(&format!("// ---- {path}\n"));
                append(piece, out, seen)?;
                out.push_str(&format!("// ---- end of {path}\n"));
            }
            None => {
                out.push_str(line);
                out.push('\n');
            }
        }
    }
    Ok(())
}

fn include_of(line: &str) -> Option<&str> {
    let rest = line.trim().strip_prefix("#include")?.trim();
    rest.strip_prefix('"')?.strip_suffix('"')
}

/// A shader module of stage `name`.
pub fn module(device: &wgpu::Device, name: &str) -> wgpu::ShaderModule {
    device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(name),
        source: wgpu::ShaderSource::Wgsl(Cow::Owned(source(name))),
    })
}

/// Whether a colour target of `format` needs the shader to encode sRGB itself (the
/// `ENCODE_SRGB` override of `shared/output.wgsl`): plain unorm targets do (8-bit RGBA and
/// BGRA, `Rgb10a2Unorm`, `Rgba16Unorm`); sRGB targets encode on store and the float targets
/// (`Rgba16Float`, `Rgba32Float`, `Rg11b10Ufloat`) hold linear values. `None` for formats the
/// renderer does not draw into.
pub fn encode_srgb_for(format: wgpu::TextureFormat) -> Option<bool> {
    use wgpu::TextureFormat as F;
    match format {
        F::Rgba8UnormSrgb | F::Bgra8UnormSrgb => Some(false),
        F::Rgba16Float | F::Rgba32Float | F::Rg11b10Ufloat => Some(false),
        F::Rgba8Unorm | F::Bgra8Unorm | F::Rgb10a2Unorm | F::Rgba16Unorm => Some(true),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn includes_resolve_once_and_unknown_ones_are_refused() {
        let s = assemble("#include \"shared/hash.wgsl\"\n#include \"shared/hash.wgsl\"\nfn f() {}")
            .unwrap();
        assert_eq!(s.matches("fn hash_u32").count(), 1);
        assert!(s.ends_with("fn f() {}\n"));
        assert!(assemble("#include \"shared/nope.wgsl\"").is_err());
    }
}
