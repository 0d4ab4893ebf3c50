// The sway springs' bend in the cell under a point. The includer declares, with bindings of its
// choice,
//     var<uniform> wind_lookup: WindLookup;              // shared/wind_lookup.wgsl
//     var<storage, read> sway: array<vec4<f32>>;          // per cell and slot: xy bend, zw velocity
// Mirrored by sway_at in src/wind/sway_cpu.rs.

#include "shared/sway_slots.wgsl"

// The bend of `slot` in the cell under the point `rel_xy` metres from the camera.
fn sway_at(rel_xy: vec2<f32>, slot: u32) -> vec2<f32> {
    return sway_state_at(rel_xy, slot).xy;
}

// The spring of `slot` in the cell under the point `rel_xy` metres from the camera: xy its
// bend, zw the bend's velocity (per second).
fn sway_state_at(rel_xy: vec2<f32>, slot: u32) -> vec4<f32> {
    let n = i32(wind_lookup.n);
    let half = n / 2;
    let c = vec2<i32>(floor((wind_lookup.camera_offset + rel_xy) / wind_lookup.cell_m));
    let r = clamp(c, vec2<i32>(-half, -half), vec2<i32>(half - 1, half - 1));
    let w = wind_lookup.origin_cell + r;
    let x = ((w.x % n) + n) % n;
    let y = ((w.y % n) + n) % n;
    return sway[(u32(y) * wind_lookup.n + u32(x)) * SWAY_SLOTS + slot];
}
