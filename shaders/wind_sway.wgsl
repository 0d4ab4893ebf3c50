// The sway of the grass and the plants: per wind cell and slot (the grass types' four, then
// the plant types'), a damped spring (stiffness, damping per
// type) driven toward a bend proportional to the cell's wind, advanced by the exact solution of
// the spring over the frame's time step (stable at any step: see `verdant eval sway`). The step
// matrix of each type is computed on the CPU for the frame's dt. CPU mirror: update_sway in
// src/wind/sway_cpu.rs.

#include "shared/sway_slots.wgsl"

struct SwayParams {
    // The camera's world cell (as the wind field's lookup), and the field's size.
    origin_cell: vec2<i32>,
    n: u32,
    types: u32,
    // Per slot: the step matrix applied to (x - target, v), row-major.
    step: array<vec4<f32>, SWAY_SLOTS>,
    // Per slot: x = bend per m/s of wind, y = largest bend (blade or plant heights).
    gain: array<vec4<f32>, SWAY_SLOTS>,
}

// A read-only storage buffer, not a uniform: Mesa's lavapipe (22.x) inlines uniform values that
// steer branches and loops into a freshly compiled shader at every dispatch and never frees it.
// Same layout, same results.
@group(0) @binding(0) var<storage, read> params: SwayParams;
@group(0) @binding(1) var<storage, read> wind_cells: array<vec4<f32>>;
// Per cell and slot: xy bend (blade or plant heights), zw its velocity.
@group(0) @binding(2) var<storage, read_write> sway: array<vec4<f32>>;
// Per cell: the world cell the sway state belongs to.
@group(0) @binding(3) var<storage, read_write> owners: array<vec2<i32>>;

fn target_bend(wind: vec2<f32>, t: u32) -> vec2<f32> {
    let b = wind * params.gain[t].x;
    let len = length(b);
    if len > params.gain[t].y {
        return b * (params.gain[t].y / len);
    }
    return b;
}

@compute @workgroup_size(8, 8, 1)
fn update_sway(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = i32(params.n);
    if gid.x >= params.n || gid.y >= params.n {
        return;
    }
    // The world cell stored at this index: the one inside the window around the camera.
    let base = params.origin_cell - vec2<i32>(n / 2, n / 2);
    let rel = (vec2<i32>(gid.xy) - base % n + vec2<i32>(n, n)) % n;
    let world = base + rel;
    let index = gid.y * params.n + gid.x;
    let wind = wind_cells[index].xy;
    let fresh = any(owners[index] != world);
    owners[index] = world;
    for (var t = 0u; t < params.types; t++) {
        let k = index * SWAY_SLOTS + t;
        let goal = target_bend(wind, t);
        if fresh {
            sway[k] = vec4<f32>(goal, 0.0, 0.0);
            continue;
        }
        let s = sway[k];
        let d = s.xy - goal;
        let m = params.step[t];
        let x = goal + m.x * d + m.y * s.zw;
        let v = m.z * d + m.w * s.zw;
        sway[k] = vec4<f32>(x, v);
    }
}
