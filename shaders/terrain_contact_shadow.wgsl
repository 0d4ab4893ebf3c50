// Contact shadows: the shadows of the grass (and of anything else in the depth buffer) within
// about 30 m of the camera, onto the ground and onto other blades. Each pixel's surface point
// marches toward the sun in screen space; where a step lands behind something nearer than it
// (and within a thickness of it), the pixel is in shadow and its colour is dimmed by
// multiplying the target (the sun's share of the light: the ambient stays). Two passes: the
// factors, per pixel in a compute pass over the target (1 where unshadowed, and beyond the
// fade distance without a march), then a full-screen pass that multiplies the colour target by
// them (blending). CPU mirror: src/terrain/contact_shadow_cpu.rs.
//
// The same factors take the trees' shadows from their cascaded shadow map (src/plants/shadow.rs,
// drawn by the trees' shadow casters): the pixel is as shaded as the larger of its contact
// shadow and its tree shadow. CPU mirror of that lookup: ShadowUniform::sun_seen.

#include "shared/full_screen.wgsl"

override ENCODE_SRGB: bool = false;

struct Params {
    // Camera-relative view-projection and its inverse (reverse-Z).
    view_proj: mat4x4<f32>,
    inv_view_proj: mat4x4<f32>,
    // xyz: unit vector toward the sun.
    sun_dir: vec4<f32>,
    // x, y: target size (pixels); z: distance where the shadows have faded out (m); w: where
    // they start to fade (m).
    size: vec4<f32>,
    // x: ray length (m); y: thickness of an occluder (m); z: the colour's factor in full
    // shadow; w: steps.
    march: vec4<f32>,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var depth: texture_depth_2d;
// The factors: written by the compute pass, read by the full-screen pass.
@group(0) @binding(2) var factors_out: texture_storage_2d<r32float, write>;
@group(0) @binding(3) var factors: texture_2d<f32>;

// Mirrors ShadowUniform in src/plants/shadow.rs.
struct TreeShadow {
    matrices: array<mat4x4<f32>, 4>,
    far: vec4<f32>,
    bias: vec4<f32>,
    // x: cascades (0: none this frame), y: the map's edge in texels
    info: vec4<u32>,
    // x: where the shadows start to fade (m), y: where they are gone
    fade: vec4<f32>,
}

@group(0) @binding(4) var tree_map: texture_depth_2d_array;
@group(0) @binding(5) var<uniform> tree_shadow: TreeShadow;

// The camera-relative point under pixel centre `px` at depth `d`.
fn unproject(px: vec2<f32>, d: f32) -> vec3<f32> {
    let ndc = vec2<f32>(px.x / params.size.x * 2.0 - 1.0, 1.0 - px.y / params.size.y * 2.0);
    let p = params.inv_view_proj * vec4<f32>(ndc, d, 1.0);
    return p.xyz / p.w;
}

// 1 in full sun, 0 in full contact shadow, for the surface point p (camera-relative) under
// pixel px. The ray's steps are interpolated in clip space (linear in the point), and depths
// are compared as view depths: with a reverse-Z projection to infinity a depth d at clip w
// means w * d is the same for every point, so the scene under a step lies at w * qd / sd.
fn sun_seen(px: vec2<i32>, p: vec3<f32>) -> f32 {
    let steps = i32(params.march.w);
    let c0 = params.view_proj * vec4<f32>(p, 1.0);
    let c1 = params.view_proj * vec4<f32>(p + params.sun_dir.xyz * params.march.x, 1.0);
    for (var i = 1; i <= steps; i++) {
        let c = mix(c0, c1, f32(i) / f32(steps));
        if c.w <= 0.0 {
            break;
        }
        let n = c.xyz / c.w;
        let spx = vec2<f32>((n.x * 0.5 + 0.5) * params.size.x, (0.5 - n.y * 0.5) * params.size.y);
        if any(spx < vec2<f32>(0.0)) || any(spx >= params.size.xy) {
            break;
        }
        let ipx = vec2<i32>(floor(spx));
        if all(ipx == px) {
            continue;
        }
        let sd = textureLoad(depth, ipx, 0);
        if sd <= 0.0 {
            continue;
        }
        let behind = c.w * (1.0 - n.z / sd);
        let bias = 0.02 + 0.004 * c.w;
        if behind > bias && behind < params.march.y {
            return 0.0;
        }
    }
    return 1.0;
}

// The sun's share at the camera-relative point p under the trees: 1 in full sun, 0 where every
// texel of the lookup (the tent of three bilinear taps: 4 x 4 texels weighted 1-f, 1, 1, f) in
// the cascade of its distance is nearer the sun. As ShadowUniform::sun_seen.
fn tree_sun_seen(p: vec3<f32>) -> f32 {
    let count = tree_shadow.info.x;
    if count == 0u {
        return 1.0;
    }
    let dist = length(p);
    if dist >= tree_shadow.fade.y {
        return 1.0;
    }
    var c = 0u;
    while c + 1u < count && dist >= tree_shadow.far[c] {
        c += 1u;
    }
    let s = tree_shadow.matrices[c] * vec4<f32>(p, 1.0);
    let size = i32(tree_shadow.info.y);
    let t = vec2<f32>((s.x * 0.5 + 0.5) * f32(size) - 0.5, (0.5 - s.y * 0.5) * f32(size) - 0.5);
    let reference = s.z + tree_shadow.bias[c];
    let i = floor(t);
    let f = t - i;
    let wx = array<f32, 4>(1.0 - f.x, 1.0, 1.0, f.x);
    let wy = array<f32, 4>(1.0 - f.y, 1.0, 1.0, f.y);
    var lit = 0.0;
    for (var j = 0; j < 4; j++) {
        for (var k = 0; k < 4; k++) {
            let x = i32(i.x) - 1 + k;
            let y = i32(i.y) - 1 + j;
            var texel = 0.0;
            if x >= 0 && y >= 0 && x < size && y < size {
                texel = textureLoad(tree_map, vec2<i32>(x, y), c, 0);
            }
            if reference >= texel {
                lit += wx[k] * wy[j];
            }
        }
    }
    lit /= 9.0;
    let fade = clamp((dist - tree_shadow.fade.x) / max(tree_shadow.fade.y - tree_shadow.fade.x, 1e-3), 0.0, 1.0);
    return lit + (1.0 - lit) * fade;
}

// The colour's factor at pixel px: 1 in full sun, the shade in full shadow (the larger of the
// contact shadow, with `params.march.w` steps, none at 0, and the trees' shadow).
fn factor_at(px: vec2<i32>) -> f32 {
    let d = textureLoad(depth, px, 0);
    if d <= 0.0 {
        return 1.0;
    }
    let p = unproject(vec2<f32>(px) + 0.5, d);
    let dist = length(p);
    var shadow = 0.0;
    if dist < params.size.z && params.march.w > 0.0 {
        let fade = 1.0 - smoothstep(params.size.w, params.size.z, dist);
        shadow = (1.0 - sun_seen(px, p)) * fade;
    }
    shadow = max(shadow, 1.0 - tree_sun_seen(p));
    return mix(1.0, params.march.z, shadow);
}

@compute @workgroup_size(8, 8)
fn cs_contact_shadow(@builtin(global_invocation_id) id: vec3<u32>) {
    if any(vec2<f32>(id.xy) >= params.size.xy) {
        return;
    }
    let px = vec2<i32>(id.xy);
    textureStore(factors_out, px, vec4<f32>(factor_at(px), 0.0, 0.0, 1.0));
}

@fragment
fn fs_contact_shadow(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    var f = textureLoad(factors, vec2<i32>(floor(pos.xy)), 0).r;
    if ENCODE_SRGB {
        // The target holds sRGB-encoded values: scale them so that the linear light scales by f.
        f = pow(f, 1.0 / 2.4);
    }
    return vec4<f32>(f, f, f, 1.0);
}
