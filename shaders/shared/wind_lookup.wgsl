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

// The column or row of the field's ring buffer holding the world cell `w` (0..n).
fn wind_wrap(w: i32, n: i32) -> i32 {
    return ((w % n) + n) % n;
}

// The wind at rel_xy metres from the camera (x east, y north): bilinear between the four
// nearest cell centres, each clamped to the field's edge. One wrap per axis (the second cell
// is the next one, or the same at the edge): the draws call this per vertex.
fn wind_at(rel_xy: vec2<f32>) -> vec4<f32> {
    let p = (wind_lookup.camera_offset + rel_xy) / wind_lookup.cell_m - vec2<f32>(0.5, 0.5);
    let fl = floor(p);
    let f = p - fl;
    let c = vec2<i32>(fl);
    let n = i32(wind_lookup.n);
    let half = n / 2;
    let lo = vec2<i32>(-half, -half);
    let hi = vec2<i32>(half - 1, half - 1);
    let r0 = clamp(c, lo, hi);
    let step = clamp(c + vec2<i32>(1, 1), lo, hi) - r0;
    let w = wind_lookup.origin_cell + r0;
    let x0 = wind_wrap(w.x, n);
    let y0 = wind_wrap(w.y, n);
    var x1 = x0 + step.x;
    if x1 >= n {
        x1 -= n;
    }
    var y1 = y0 + step.y;
    if y1 >= n {
        y1 -= n;
    }
    let row0 = u32(y0) * wind_lookup.n;
    let row1 = u32(y1) * wind_lookup.n;
    let v00 = wind_cells[row0 + u32(x0)];
    let v10 = wind_cells[row0 + u32(x1)];
    let v01 = wind_cells[row1 + u32(x0)];
    let v11 = wind_cells[row1 + u32(x1)];
    let bottom = v00 + (v10 - v00) * f.x;
    let top = v01 + (v11 - v01) * f.x;
    return bottom + (top - bottom) * f.y;
}
