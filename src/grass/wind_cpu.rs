//! CPU mirror of `shaders/grass_wind.wgsl` (the GPU stage: `grass/wind.rs`): the wind on each
//! blade of a slot, once per blade. Written apart from the shader, statement for statement; a
//! test compares the two.

use bytemuck::{Pod, Zeroable};
use glam::Vec2;

use crate::grass::Blade;
use crate::grass::blade::pack_rgba8;
use crate::hash::value_noise;
use crate::wind::WindLookup;
use crate::wind::field_cpu::wind_at;

/// The pass's uniform; mirrors `WindPass` in the shader.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct WindPassParams {
    /// x: time (s), y: ambient wind speed (m/s), zw: camera world xy modulo 4096 m.
    pub misc: [f32; 4],
    /// x: feature bits, y: slot capacity.
    pub flags: [u32; 4],
    /// x: the frame's time step (s), over which the blades' motion is taken.
    pub motion: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<WindPassParams>() == 48);

/// Lean of a blade on the axis of a fresh trail, blade heights (trampled nearly flat); the
/// shader has the same constant.
pub const TRAIL_LEAN: f32 = 1.6;
const INTERACTION: u32 = 2;
const DETAIL_BENDING: u32 = 4;
const COLOR_VARIATION: u32 = 64;

fn smooth_triangle(x: f32) -> f32 {
    let f = x + 0.5;
    let t = ((f - f.floor()) * 2.0 - 1.0).abs();
    t * t * (3.0 - 2.0 * t)
}

fn unpack_rgb(c: u32) -> [f32; 3] {
    [
        (c & 255) as f32 / 255.0,
        ((c >> 8) & 255) as f32 / 255.0,
        ((c >> 16) & 255) as f32 / 255.0,
    ]
}

/// Applies the wind to `blades` (one slot's drawn blades), as the shader does.
pub fn apply_wind(
    p: &WindPassParams,
    lookup: &WindLookup,
    cells: &[[f32; 4]],
    sway: &[[f32; 4]],
    blades: &mut [Blade],
) {
    let has = |f: u32| p.flags[0] & f != 0;
    for b in blades.iter_mut() {
        let root = Vec2::new(b.pos[0], b.pos[1]);
        let kind = b.kind & 255;
        let w = wind_at(lookup, cells, root);
        let spring = crate::wind::sway_state_at(lookup, sway, root, kind.min(3));
        let dt = p.motion[0];
        let mut lean = Vec2::new(spring[0], spring[1]) * b.wind;
        // A frame ago the spring stood back by its velocity times the step.
        let moved_lean = Vec2::new(spring[2], spring[3]) * dt * b.wind;
        if has(INTERACTION) {
            lean += Vec2::new(w[2], w[3]) * TRAIL_LEAN;
        }
        let speed = Vec2::new(w[0], w[1]).length();
        let (mut blade_sway, mut flutter) = (0.0f32, 0.0f32);
        let mut moved_detail = [0.0f32; 2];
        if has(DETAIL_BENDING) {
            let phase = (b.hash & 1023) as f32 / 1023.0;
            let time = p.misc[0];
            let amount = (speed / 5.0).min(1.5) * b.wind;
            let sway_wave = |time: f32| {
                smooth_triangle(time * 0.193 + phase) + smooth_triangle(time * 0.375 + phase * 1.3)
                    - 1.0
            };
            let flutter_wave = |time: f32| {
                smooth_triangle(time * 1.975 + phase * 3.1)
                    + smooth_triangle(time * 0.793 + phase * 2.7)
                    - 1.0
            };
            let (sway_now, flutter_now) = (sway_wave(time), flutter_wave(time));
            blade_sway = sway_now * amount;
            flutter = flutter_now * amount;
            moved_detail = [
                (sway_now - sway_wave(time - dt)) * amount,
                (flutter_now - flutter_wave(time - dt)) * amount,
            ];
        }
        if has(COLOR_VARIATION) {
            let world = Vec2::new(p.misc[2], p.misc[3]) + root;
            let v = value_noise(world / 6.0) * 0.6 + value_noise(world / 1.7) * 0.4;
            let lo = [0.78, 0.86, 0.7];
            let hi = [1.15, 1.1, 0.95];
            let c = unpack_rgb(b.color);
            b.color = pack_rgba8([0, 1, 2].map(|i| c[i] * (lo[i] + (hi[i] - lo[i]) * v)));
        }
        b.lean = lean.to_array();
        b.sway = blade_sway;
        b.flutter = flutter;
        b.moved = [moved_lean.x, moved_lean.y, moved_detail[0], moved_detail[1]];
        b.fade = (speed / p.misc[1].max(0.5) - 1.0).clamp(0.0, 1.0);
    }
}
