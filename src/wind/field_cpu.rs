//! CPU mirror of `shaders/wind_field.wgsl` (entry point `update_wind`) and of
//! `shaders/shared/wind_lookup.wgsl` (`wind_at`), written loop for loop like the shaders but on their
//! own, in f32: the tests feed both the same [`FieldParams`] and compare.
//!
//! [`WindFieldCpu`] runs the field on the CPU frame by frame, as [`super::WindField`] does on
//! the GPU; [`ambient_at`] is the ambient wind alone, anywhere, at any time.

use glam::{DVec2, DVec3, Vec2};

use super::config::{
    CellState, FLAG_STAMP, FLAG_TRAIL, FieldDriver, FieldParams, KIND_DIRECTIONAL, KIND_OMNI,
    OCTAVES, SOURCE_CORE, WindConfig, WindLookup, ambient_params,
};
use crate::hash::{hash_u32, unit};

/// Salt that turns a lattice hash into the cross-wind channel's.
const CROSS_SALT: u32 = 0x68e3_1da4;

/// Lattice values (gust, cross) of `octave` at lattice point (ix, iy), the lattice repeating
/// every `period` points.
fn lattice(p: &FieldParams, ix: i32, iy: i32, octave: u32) -> Vec2 {
    let period = p.counts[2] as i32;
    let x = ix.rem_euclid(period) as u32;
    let y = iy.rem_euclid(period) as u32;
    let h = hash_u32(x ^ hash_u32(y ^ hash_u32(octave ^ p.counts[3])));
    Vec2::new(unit(h), unit(hash_u32(h ^ CROSS_SALT)))
}

/// Value noise, two channels, quintic fade, at lattice position `q`.
fn value_noise(p: &FieldParams, q: Vec2, octave: u32) -> Vec2 {
    let (fx, fy) = (q.x.floor(), q.y.floor());
    let (tx, ty) = (q.x - fx, q.y - fy);
    let (ix, iy) = (fx as i32, fy as i32);
    let fade = |t: f32| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
    let (ux, uy) = (fade(tx), fade(ty));
    let lerp = |a: Vec2, b: Vec2, t: f32| a + (b - a) * t;
    let south = lerp(
        lattice(p, ix, iy, octave),
        lattice(p, ix + 1, iy, octave),
        ux,
    );
    let north = lerp(
        lattice(p, ix, iy + 1, octave),
        lattice(p, ix + 1, iy + 1, octave),
        ux,
    );
    lerp(south, north, uy)
}

/// The ambient wind (m/s) at `d` metres from the origin cell's south-west corner, for the
/// frame of `p`.
pub fn ambient_wind(p: &FieldParams, d: Vec2) -> Vec2 {
    let (w_new, w_old) = (p.blend[0], p.blend[1]);
    let mut sum = Vec2::ZERO;
    for o in 0..OCTAVES {
        let q = d * p.octave_freq[o];
        let win = p.windows[o];
        let mut v = Vec2::ZERO;
        if w_new > 0.0 {
            v += value_noise(p, Vec2::new(win[0], win[1]) + q, o as u32) * w_new;
        }
        if w_old > 0.0 {
            v += value_noise(p, Vec2::new(win[2], win[3]) + q, o as u32) * w_old;
        }
        sum += v * p.octave_amp[o];
    }
    let gain = p.extra[3];
    let gust = (sum.x * gain).clamp(-1.0, 1.0);
    let cross = (sum.y * gain).clamp(-1.0, 1.0);
    let dir = Vec2::new(p.ambient[0], p.ambient[1]);
    let speed = p.ambient[2];
    let along = speed * (1.0 + p.ambient[3] * gust);
    let side = speed * p.extra[2] * cross;
    dir * along + dir.perp() * side
}

/// The ambient wind (m/s) of `config` at `world_xy` at scene time `time_s`: the field's ambient
/// term, evaluated with the camera at `world_xy` (so in the same f32 arithmetic as a cell's).
pub fn ambient_at(config: &WindConfig, world_xy: DVec2, time_s: f64) -> Vec2 {
    let cell = config.world_cell(world_xy);
    let corner = DVec2::new(f64::from(cell[0]), f64::from(cell[1])) * f64::from(config.cell_m);
    let params = ambient_params(config, corner, time_s);
    ambient_wind(&params, (world_xy - corner).as_vec2())
}

/// `(1 - dist / radius)^2`, ramping linearly up from 0 over the inner [`SOURCE_CORE`] of the
/// radius; 0 beyond the radius.
fn falloff(dist: f32, radius: f32) -> f32 {
    if dist >= radius {
        return 0.0;
    }
    let x = 1.0 - dist / radius;
    let core = (dist / (SOURCE_CORE * radius)).min(1.0);
    x * x * core
}

/// The summed wind of the frame's sources (m/s) at `d` metres from the origin cell's corner.
pub fn source_wind(p: &FieldParams, d: Vec2) -> Vec2 {
    let mut sum = Vec2::ZERO;
    for s in &p.sources[..p.counts[0] as usize] {
        let a = Vec2::from_array(s.a);
        if s.kind == KIND_DIRECTIONAL {
            sum += a;
            continue;
        }
        let off = d - Vec2::from_array(s.center);
        let dist = off.length();
        let f = falloff(dist, s.radius);
        if f <= 0.0 {
            continue;
        }
        let out = off / dist;
        if s.kind == KIND_OMNI {
            sum += out * (a.x * f);
        } else {
            sum += (out.perp() * a.x - out * a.y) * f;
        }
    }
    sum
}

/// The walker's step stamped over a cell at `d` whose faded push is `push`: the stronger of
/// the two.
fn stamp(p: &FieldParams, d: Vec2, push: Vec2) -> Vec2 {
    let a = Vec2::new(p.trail[0], p.trail[1]);
    let ab = Vec2::new(p.trail[2], p.trail[3]) - a;
    let len2 = ab.dot(ab);
    let t = if len2 > 0.0 {
        ((d - a).dot(ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let off = d - (a + ab * t);
    let dist = off.length();
    let radius = p.decay[3];
    if dist >= radius {
        return push;
    }
    let u = dist / radius;
    let m = 1.0 - u * u * (3.0 - 2.0 * u);
    let dir = if dist > 1e-4 {
        off / dist
    } else {
        Vec2::new(p.extra[0], p.extra[1])
    };
    if m * m > push.dot(push) {
        dir * m
    } else {
        push
    }
}

/// One frame of the field: the mirror of the compute entry point `update_wind`. `state` and
/// `cells` hold `p.n * p.n` entries, row by row (index `y * n + x`).
pub fn update_wind(p: &FieldParams, state: &mut [CellState], cells: &mut [[f32; 4]]) {
    let n = p.n as i32;
    let half = n / 2;
    let lo = [p.origin_cell[0] - half, p.origin_cell[1] - half];
    for gy in 0..n {
        for gx in 0..n {
            let world = [
                lo[0] + (gx - lo[0]).rem_euclid(n),
                lo[1] + (gy - lo[1]).rem_euclid(n),
            ];
            let rel = [world[0] - p.origin_cell[0], world[1] - p.origin_cell[1]];
            let d = Vec2::new(
                (rel[0] as f32 + 0.5) * p.cell_m,
                (rel[1] as f32 + 0.5) * p.cell_m,
            );
            let index = (gy * n + gx) as usize;

            let ambient = ambient_wind(p, d);
            let target = source_wind(p, d);

            let prev = state[index];
            let mut s = Vec2::from_array(prev.source);
            let mut push = Vec2::new(cells[index][2], cells[index][3]);
            if prev.tag != world {
                s = target;
                push = Vec2::ZERO;
            }
            let k = if target.dot(target) > s.dot(s) {
                p.decay[0]
            } else {
                p.decay[1]
            };
            s = target + (s - target) * k;

            let flags = p.counts[1];
            if flags & FLAG_TRAIL != 0 {
                push *= p.decay[2];
                if flags & FLAG_STAMP != 0 {
                    push = stamp(p, d, push);
                }
            } else {
                push = Vec2::ZERO;
            }

            state[index] = CellState {
                source: s.to_array(),
                tag: world,
            };
            let wind = ambient + s;
            cells[index] = [wind.x, wind.y, push.x, push.y];
        }
    }
}

/// The mirror of `wind_at` in `shaders/shared/wind_lookup.wgsl`: the field `cells` read at `rel_xy`
/// metres from the camera, bilinear between the nearest cell centres.
pub fn wind_at(lookup: &WindLookup, cells: &[[f32; 4]], rel_xy: Vec2) -> [f32; 4] {
    let n = lookup.n as i32;
    let half = n / 2;
    let cell = |rx: i32, ry: i32| -> [f32; 4] {
        let rx = rx.clamp(-half, half - 1);
        let ry = ry.clamp(-half, half - 1);
        let x = (lookup.origin_cell[0] + rx).rem_euclid(n);
        let y = (lookup.origin_cell[1] + ry).rem_euclid(n);
        cells[(y * n + x) as usize]
    };
    let p = (Vec2::from_array(lookup.camera_offset) + rel_xy) / lookup.cell_m - Vec2::splat(0.5);
    let (fx, fy) = (p.x.floor(), p.y.floor());
    let (tx, ty) = (p.x - fx, p.y - fy);
    let (cx, cy) = (fx as i32, fy as i32);
    let (v00, v10) = (cell(cx, cy), cell(cx + 1, cy));
    let (v01, v11) = (cell(cx, cy + 1), cell(cx + 1, cy + 1));
    std::array::from_fn(|c| {
        let bottom = v00[c] + (v10[c] - v00[c]) * tx;
        let top = v01[c] + (v11[c] - v01[c]) * tx;
        bottom + (top - bottom) * ty
    })
}

/// The wind field run on the CPU, frame by frame, like [`super::WindField`].
#[derive(Clone, Debug)]
pub struct WindFieldCpu {
    driver: FieldDriver,
    state: Vec<CellState>,
    cells: Vec<[f32; 4]>,
    params: FieldParams,
    lookup: WindLookup,
}

impl WindFieldCpu {
    /// An empty field for `config` (every cell is filled on the first update).
    pub fn new(config: &WindConfig) -> Self {
        let count = config.cell_count();
        Self {
            driver: FieldDriver::new(config),
            state: vec![CellState::EMPTY; count],
            cells: vec![[0.0; 4]; count],
            params: bytemuck::Zeroable::zeroed(),
            lookup: WindLookup::default(),
        }
    }

    /// Steps the field to `time_s` (see [`super::WindField::update`]).
    pub fn update(
        &mut self,
        camera_world: DVec3,
        time_s: f64,
        dt_s: f32,
        walker_world: Option<DVec2>,
    ) {
        let (params, lookup) = self.driver.frame(camera_world, time_s, dt_s, walker_world);
        update_wind(&params, &mut self.state, &mut self.cells);
        self.params = params;
        self.lookup = lookup;
    }

    /// The cells: xy wind (m/s), zw trail push; index `(j mod n) * n + (i mod n)` for world
    /// cell (i, j).
    pub fn cells(&self) -> &[[f32; 4]] {
        &self.cells
    }

    /// The cells' state.
    pub fn state(&self) -> &[CellState] {
        &self.state
    }

    /// The last frame's compute uniform.
    pub fn params(&self) -> &FieldParams {
        &self.params
    }

    /// The last frame's lookup uniform.
    pub fn lookup(&self) -> &WindLookup {
        &self.lookup
    }

    /// The field at `rel_xy` metres from the camera, as `wind_at` reads it.
    pub fn wind_at(&self, rel_xy: Vec2) -> [f32; 4] {
        wind_at(&self.lookup, &self.cells, rel_xy)
    }
}
