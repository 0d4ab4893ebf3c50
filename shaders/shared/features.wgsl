// The grass model's switchable features, one bit each; mirrors `Feature::bit` in
// src/features.rs (a test compares the two).

const WIND_SOURCES: u32 = 1u;
const INTERACTION: u32 = 2u;
const DETAIL_BENDING: u32 = 4u;
const TRANSLUCENCY: u32 = 8u;
const SPECULAR: u32 = 16u;
const AMBIENT_OCCLUSION: u32 = 32u;
const COLOR_VARIATION: u32 = 64u;
const GROUND_DARKENING: u32 = 128u;
const FAR_FIELD: u32 = 256u;
const SHADOWS: u32 = 512u;
const PLANTS: u32 = 1024u;
const TREES: u32 = 2048u;
const TREE_SHADOWS: u32 = 4096u;
const PARTICLES: u32 = 8192u;

// Whether a pass's feature bits `flags` switch on `feature`.
fn has_feature(flags: u32, feature: u32) -> bool {
    return (flags & feature) != 0u;
}
