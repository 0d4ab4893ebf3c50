//! CPU mirror of `shaders/wind_sway.wgsl` (the GPU stage: [`crate::wind::sway`]), written loop
//! for loop like the shader but independently of it; the tests compare the two.

use glam::Vec2;

use super::config::WindLookup;
use super::sway::{SWAY_TYPES, SwayParams};

/// CPU mirror of the shader: advances `sway` (per cell and type: bend xy, velocity zw) and
/// `owners` by one frame, loop for loop.
pub fn update_sway(
    p: &SwayParams,
    wind_cells: &[[f32; 4]],
    sway: &mut [[f32; 4]],
    owners: &mut [[i32; 2]],
) {
    let n = p.n as i32;
    let base = [p.origin_cell[0] - n / 2, p.origin_cell[1] - n / 2];
    for y in 0..n {
        for x in 0..n {
            // The shader's `%` keeps the dividend's sign; base % n + n is then in 0..2n.
            let rel = [(x - base[0] % n + n) % n, (y - base[1] % n + n) % n];
            let world = [base[0] + rel[0], base[1] + rel[1]];
            let index = (y * n + x) as usize;
            let wind = [wind_cells[index][0], wind_cells[index][1]];
            let fresh = owners[index] != world;
            owners[index] = world;
            for t in 0..p.types as usize {
                let k = index * SWAY_TYPES + t;
                let g = p.gain[t];
                let mut target = [wind[0] * g[0], wind[1] * g[0]];
                let len = (target[0] * target[0] + target[1] * target[1]).sqrt();
                if len > g[1] {
                    let s = g[1] / len;
                    target = [target[0] * s, target[1] * s];
                }
                if fresh {
                    sway[k] = [target[0], target[1], 0.0, 0.0];
                    continue;
                }
                let s = sway[k];
                let d = [s[0] - target[0], s[1] - target[1]];
                let m = p.step[t];
                sway[k] = [
                    target[0] + m[0] * d[0] + m[1] * s[2],
                    target[1] + m[0] * d[1] + m[1] * s[3],
                    m[2] * d[0] + m[3] * s[2],
                    m[2] * d[1] + m[3] * s[3],
                ];
            }
        }
    }
}

/// The bend of `slot` in the cell under the point `rel` metres from the camera, from the sway
/// state `sway` of the field described by `lookup`: the mirror of `sway_at` in
/// `shaders/shared/sway_lookup.wgsl`.
pub fn sway_at(lookup: &WindLookup, sway: &[[f32; 4]], rel: Vec2, slot: u32) -> Vec2 {
    let s = sway_state_at(lookup, sway, rel, slot);
    Vec2::new(s[0], s[1])
}

/// The spring of `slot` in the cell under the point `rel` metres from the camera: its bend
/// (x, y) and the bend's velocity per second (z, w), as `sway_state_at` in
/// `shaders/shared/sway_lookup.wgsl`.
pub fn sway_state_at(lookup: &WindLookup, sway: &[[f32; 4]], rel: Vec2, slot: u32) -> [f32; 4] {
    let n = lookup.n as i32;
    let half = n / 2;
    let off = Vec2::from_array(lookup.camera_offset);
    let c = ((off + rel) / lookup.cell_m).floor();
    let (cx, cy) = (
        (c.x as i32).clamp(-half, half - 1),
        (c.y as i32).clamp(-half, half - 1),
    );
    let (wx, wy) = (lookup.origin_cell[0] + cx, lookup.origin_cell[1] + cy);
    let (x, y) = (wx.rem_euclid(n) as u32, wy.rem_euclid(n) as u32);
    sway[((y * lookup.n + x) * SWAY_TYPES as u32 + slot) as usize]
}
