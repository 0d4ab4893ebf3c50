// Composite: the shaded terrain and sky (linear, shaders/terrain_shade.wgsl) written into the
// colour target, encoded as the target's format needs (shared/output.wgsl).

#include "shared/output.wgsl"
#include "shared/full_screen.wgsl"

@group(0) @binding(0) var shaded: texture_2d<f32>;

@fragment
fn fs_composite(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    return output_color(textureLoad(shaded, vec2<i32>(floor(pos.xy)), 0).rgb);
}
