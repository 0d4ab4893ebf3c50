// Composite: the shaded terrain and sky (linear, shaders/terrain_shade.wgsl) written into the
// colour target, encoded as the target's format needs (shared/output.wgsl).

#include "shared/output.wgsl"

@group(0) @binding(0) var shaded: texture_2d<f32>;

@vertex
fn vs_full(@builtin(vertex_index) vi: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2<f32>(f32((vi << 1u) & 2u), f32(vi & 2u));
    return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
}

@fragment
fn fs_composite(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    return output_color(textureLoad(shaded, vec2<i32>(floor(pos.xy)), 0).rgb);
}
