// The wind on each blade, once per blade (not per vertex): after a batch is generated, every
// blade in its slots gets its lean (the sway of its type in its wind cell, plus the trail's
// push), its detail bending (whole-blade sway and edge flutter from smoothed triangle waves at
// four frequencies, phased by its hash), its gust highlight and its colour variation (world-space
// noise at its root). The hashes, the blade record, the feature bits and the wind lookup are
// included from shaders/shared/.
// CPU mirror: src/grass/wind_cpu.rs.

#include "shared/hash.wgsl"
#include "shared/blade.wgsl"
#include "shared/features.wgsl"
#include "shared/wind_lookup.wgsl"
#include "shared/waves.wgsl"
#include "shared/sway_lookup.wgsl"

struct DrawArgs {
    vertex_count: u32,
    instance_count: u32,
    first_vertex: u32,
    first_instance: u32,
}

struct WindPass {
    // x: time (s), y: ambient wind speed (m/s), zw: the camera's world xy modulo 4096 m
    misc: vec4<f32>,
    // x: feature bits, y: slot capacity
    flags: vec4<u32>,
    // x: the frame's time step (s): the blades' motion over it
    motion: vec4<f32>,
}

@group(0) @binding(0) var<uniform> pass_params: WindPass;
@group(0) @binding(1) var<uniform> wind_lookup: WindLookup;
@group(0) @binding(2) var<storage, read> wind_cells: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> sway: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> blades: array<Blade>;
@group(0) @binding(5) var<storage, read> args: array<DrawArgs, 4>;

// Lean of a blade on the axis of a fresh trail, blade heights: trampled nearly flat.
const TRAIL_LEAN: f32 = 1.6;


fn value_noise(p: vec2<f32>) -> f32 {
    let fl = floor(p);
    let i = vec2<i32>(fl);
    let f = p - fl;
    let u = f * f * (3.0 - 2.0 * f);
    let a = f32(hash2(i.x, i.y) >> 8u) / 16777216.0;
    let b = f32(hash2(i.x + 1, i.y) >> 8u) / 16777216.0;
    let c = f32(hash2(i.x, i.y + 1) >> 8u) / 16777216.0;
    let d = f32(hash2(i.x + 1, i.y + 1) >> 8u) / 16777216.0;
    let ab = a + (b - a) * u.x;
    let cd = c + (d - c) * u.x;
    return ab + (cd - ab) * u.y;
}

// Detail bending at `time` of a blade of phase `phase`: its whole-blade sway and its edge
// flutter, before they are scaled by the wind's amount.
fn detail_bending(time: f32, phase: f32) -> vec2<f32> {
    return vec2<f32>(
        smooth_triangle(time * 0.193 + phase) + smooth_triangle(time * 0.375 + phase * 1.3) - 1.0,
        smooth_triangle(time * 1.975 + phase * 3.1) + smooth_triangle(time * 0.793 + phase * 2.7) - 1.0,
    );
}

// Workgroup y is the slot of the half; x runs over the slot's blades.
@compute @workgroup_size(64, 1, 1)
fn apply_wind(@builtin(global_invocation_id) gid: vec3<u32>) {
    let slot = gid.y;
    if gid.x >= args[slot].instance_count {
        return;
    }
    let index = slot * pass_params.flags.y + gid.x;
    var b = blades[index];
    let root = vec2<f32>(b.pos_x, b.pos_y);
    let kind = b.kind & 255u;
    let w = wind_at(root);
    let spring = sway_state_at(root, min(kind, 3u));
    let dt = pass_params.motion.x;
    var lean = spring.xy * b.wind;
    // The spring's bend a frame ago, from its velocity (the trail's push changes slowly).
    let moved_lean = spring.zw * (dt * b.wind);
    if has_feature(pass_params.flags.x, INTERACTION) {
        lean += w.zw * TRAIL_LEAN;
    }
    let speed = length(w.xy);
    var blade_sway = 0.0;
    var flutter = 0.0;
    var moved_detail = vec2<f32>(0.0);
    if has_feature(pass_params.flags.x, DETAIL_BENDING) {
        let phase = f32(b.hash & 1023u) / 1023.0;
        let time = pass_params.misc.x;
        let amount = min(speed / 5.0, 1.5) * b.wind;
        let now = detail_bending(time, phase);
        blade_sway = now.x * amount;
        flutter = now.y * amount;
        moved_detail = (now - detail_bending(time - dt, phase)) * amount;
    }
    if has_feature(pass_params.flags.x, COLOR_VARIATION) {
        let world = pass_params.misc.zw + root;
        let v = value_noise(world / 6.0) * 0.6 + value_noise(world / 1.7) * 0.4;
        let variation = vec3<f32>(0.78, 0.86, 0.7) + (vec3<f32>(1.15, 1.1, 0.95) - vec3<f32>(0.78, 0.86, 0.7)) * v;
        b.color = pack_rgba8(unpack_rgb(b.color) * variation);
    }
    b.lean_x = lean.x;
    b.lean_y = lean.y;
    b.sway = blade_sway;
    b.flutter = flutter;
    b.moved_lean_x = moved_lean.x;
    b.moved_lean_y = moved_lean.y;
    b.moved_sway = moved_detail.x;
    b.moved_flutter = moved_detail.y;
    b.fade = clamp(speed / max(pass_params.misc.y, 0.5) - 1.0, 0.0, 1.0);
    blades[index] = b;
}
