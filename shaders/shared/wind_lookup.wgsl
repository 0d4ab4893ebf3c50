// Reading the wind field (shaders/wind_field.wgsl) from another shader. Include this file
// (`#include "shared/wind_lookup.wgsl"`) and declare, there, with bindings of its choice:
//
//     @group(G) @binding(B0) var<uniform> wind_lookup: WindLookup;          // 32 bytes
//     @group(G) @binding(B1) var<storage, read> wind_cells: array<vec4<f32>>; // n * n * 16 bytes
//
// then call wind_at(position relative to the camera, metres) -> vec4: xy the wind (m/s, x east,
// y north), zw the trail's push (a bend of 0..1 along its direction). CPU mirror:
// src/wind/field_cpu.rs (wind_at).

struct WindLookup {
    // The camera's world cell; the field covers world cells origin - n/2 ..= origin + n/2 - 1.
    origin_cell: vec2<i32>,
    n: u32,
    cell_m: f32,
    // The camera's xy minus its cell's south-west corner, metres, in [0, cell_m).
    camera_offset: vec2<f32>,
    _pad: vec2<f32>,
}

// The cell rel_cell cells from the camera's cell, clamped to the field's edge.
fn wind_cell(rel_cell: vec2<i32>) -> vec4<f32> {
    let n = i32(wind_lookup.n);
    let half = n / 2;
    let r = clamp(rel_cell, vec2<i32>(-half, -half), vec2<i32>(half - 1, half - 1));
    let w = wind_lookup.origin_cell + r;
    let x = ((w.x % n) + n) % n;
    let y = ((w.y % n) + n) % n;
    return wind_cells[u32(y) * wind_lookup.n + u32(x)];
}

// The wind at rel_xy metres from the camera (x east, y north): bilinear between the four
// nearest cell centres.
fn wind_at(rel_xy: vec2<f32>) -> vec4<f32> {
    let p = (wind_lookup.camera_offset + rel_xy) / wind_lookup.cell_m - vec2<f32>(0.5, 0.5);
    let fl = floor(p);
    let f = p - fl;
    let c = vec2<i32>(fl);
    let v00 = wind_cell(c);
    let v10 = wind_cell(c + vec2<i32>(1, 0));
    let v01 = wind_cell(c + vec2<i32>(0, 1));
    let v11 = wind_cell(c + vec2<i32>(1, 1));
    let bottom = v00 + (v10 - v00) * f.x;
    let top = v01 + (v11 - v01) * f.x;
    return bottom + (top - bottom) * f.y;
}
