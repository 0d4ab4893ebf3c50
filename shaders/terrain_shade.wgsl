// Terrain shading: a compute pass over the whole target that does, per pixel, all the work of
// the terrain's and the sky's colour. It reads the depth of the terrain's G-buffer pass (the
// camera-relative position follows from it and the inverse view-projection) and its G-buffer
// (shaders/terrain_gbuffer.wgsl: where in the atlas the pixel's ground is), and writes linear
// colour into an internal texture that the composite pass (shaders/terrain_composite.wgsl)
// copies into the colour target.

#include "shared/terrain_shading.wgsl"

@group(0) @binding(4) var depth: texture_depth_2d;
@group(0) @binding(5) var gbuffer: texture_2d<u32>;
@group(0) @binding(6) var shaded: texture_storage_2d<rgba16float, write>;

@compute @workgroup_size(8, 8)
fn cs_shade(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(shaded);
    if any(id.xy >= size) {
        return;
    }
    let px = vec2<i32>(id.xy);
    let ndc = vec2<f32>(
        (f32(id.x) + 0.5) / f32(size.x) * 2.0 - 1.0,
        1.0 - (f32(id.y) + 0.5) / f32(size.y) * 2.0,
    );
    let d = textureLoad(depth, px, 0);
    var color: vec3<f32>;
    if d <= 0.0 {
        // Reverse-Z: depth 0 is infinitely far, the sky.
        let p = frame.inv_view_proj * vec4<f32>(ndc, 0.5, 1.0);
        color = sky_color(normalize(p.xyz / p.w));
    } else {
        let p = frame.inv_view_proj * vec4<f32>(ndc, d, 1.0);
        let rel = p.xyz / p.w;
        let g = textureLoad(gbuffer, px, 0).xy;
        let tex = vec2<f32>(f32(g.x & 0xffffu), f32(g.x >> 16u)) / 256.0;
        let layer = g.y & 0xfffu;
        let level = f32((g.y >> 12u) & 31u);
        let texel_m = unpack2x16float(g.y >> 17u).x;
        color = shade_terrain(rel, tex, layer, texel_m, level);
    }
    textureStore(shaded, px, vec4<f32>(color, 1.0));
}
