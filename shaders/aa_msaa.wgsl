// Multisampling of the grass: the terrain and sky are drawn and shaded once per pixel
// (deferred), then copied into every sample of the multisampled colour and depth targets
// (`fs_msaa_expand`); the blades are drawn into those with alpha to coverage
// (shaders/grass_draw.wgsl, COVERAGE); the colour is resolved by the render pass (the mean
// of the samples) and the depth by `fs_msaa_depth` (the nearest sample, for the passes after
// that read depth: the contact shadows). CPU mirror of the two per-pixel rules:
// src/aa/msaa_cpu.rs.

#include "shared/full_screen.wgsl"

@group(0) @binding(0) var scene: texture_2d<f32>;
@group(0) @binding(1) var depth: texture_depth_2d;
@group(0) @binding(2) var samples_depth: texture_depth_multisampled_2d;

struct Expanded {
    @location(0) color: vec4<f32>,
    @builtin(frag_depth) depth: f32,
}

@fragment
fn fs_msaa_expand(@builtin(position) pos: vec4<f32>) -> Expanded {
    let p = vec2<i32>(pos.xy);
    var out: Expanded;
    // Stored values pass through unchanged: an sRGB texture decodes on load and its
    // multisampled twin encodes on store; a plain unorm one holds them as they are.
    out.color = textureLoad(scene, p, 0);
    out.depth = textureLoad(depth, p, 0);
    return out;
}

@fragment
fn fs_msaa_depth(@builtin(position) pos: vec4<f32>) -> @builtin(frag_depth) f32 {
    let p = vec2<i32>(pos.xy);
    var nearest = 0.0;
    for (var i = 0; i < i32(textureNumSamples(samples_depth)); i++) {
        nearest = max(nearest, textureLoad(samples_depth, p, i));
    }
    return nearest;
}
