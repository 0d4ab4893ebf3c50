//! CPU mirror of the plants' bending in the vertex stage (`bend` in
//! `shaders/plants_draw.wgsl`), and the per-type wind constants it reads.
//!
//! Detail bending (Crysis, GPU Gems 3 ch. 16) moves each vertex in the plant's own space by its
//! painted channels: a leaf or branch swings along the vertical by its freedom (the vertex
//! colour's b) and its edges flutter along the normal by r, from smoothed triangle waves at four
//! frequencies phased by the leaf (g) and the plant, as strongly as the wind felt now or, after
//! it drops, the wind the sway spring remembers ([`remembered_wind`]: leaf lag). Main bending then leans the whole plant
//! along the wind, the offset growing with height by Crysis' bend factor
//! `((z / h + 1)^2)^2 - (z / h + 1)^2` (divided by 12, its value at the top), and pulls each point back toward its distance from the
//! root (the type's stretch: 1 keeps the length exactly, so a bent plant does not grow). The lean
//! is the state of the type's sway spring in the wind cell at the plant's root (driven toward
//! the wind times the type's bend and main amplitude, less for a stiff plant: see
//! [`crate::wind::plant_lean_gain`]), plus the trail's push.

use bytemuck::{Pod, Zeroable};
use glam::{Vec2, Vec3, Vec4};

use crate::features::{Feature, Features};
use crate::plants::PlantVertex;
use crate::plants::place_cpu::PlantInstance;

/// A plant type's wind constants; mirrors `PlantWind` in the shader.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PlantWindGpu {
    /// x: movement scale, y: bend (plant heights per m/s), z: stretch, w: main amplitude.
    pub main: [f32; 4],
    /// x: detail amplitude, y: stiffness, zw: unused (the type's sway spring is the sway
    /// stage's: [`crate::wind::SwayConfig`]).
    pub detail: [f32; 4],
}

impl PlantWindGpu {
    /// From a manifest's plant wind.
    pub fn new(w: &crate::world::PlantWind) -> Self {
        Self {
            main: [w.movement_scale, w.bend, w.stretch, w.main_amplitude],
            detail: [w.detail_amplitude, w.stiffness, 0.0, 0.0],
        }
    }
}

/// The wind a plant still feels through its sway spring, m/s: the spring's lean over the lean
/// it takes per felt m/s at rest (its bend, less for a stiff plant, times its main amplitude;
/// the movement scale is the felt wind's). God of War's leaf lag: the detail bending follows the
/// larger of the wind felt now and this, so the leaves keep moving after a gust drops, for as
/// long as the spring still leans, fading with its damping; 0 for a plant that does not lean.
pub fn remembered_wind(sway_lean: Vec2, pw: &PlantWindGpu) -> f32 {
    let per_felt = pw.main[1] * (1.0 - 0.6 * pw.detail[1]) * pw.main[3];
    if per_felt > 1e-6 {
        sway_lean.length() / per_felt
    } else {
        0.0
    }
}

/// Lean of a plant on the axis of a fresh trail, plant heights.
pub const TRAIL_LEAN: f32 = 0.9;

/// WGSL's `fract`: `x - floor(x)` (Rust's `fract` keeps the sign).
fn fract(x: f32) -> f32 {
    x - x.floor()
}

/// Crysis' smoothed triangle wave in 0..1, period 1 (`shared/waves.wgsl`).
pub fn wave(x: f32) -> f32 {
    let t = (fract(x + 0.5) * 2.0 - 1.0).abs();
    t * t * (3.0 - 2.0 * t)
}

/// Vertex `v` of `inst` in the wind `w` (the wind field at its root: xy m/s, zw the trail's
/// push), leaning `sway_lean` (its type's sway spring at its root, plant heights: see
/// [`crate::wind::sway_at`]) at `time_s`, for a type of wind `pw`: its position relative to the
/// camera and its normal.
pub fn bend_vertex(
    v: &PlantVertex,
    inst: &PlantInstance,
    w: Vec4,
    sway_lean: Vec2,
    time_s: f32,
    pw: &PlantWindGpu,
    features: Features,
) -> (Vec3, Vec3) {
    let (s, c) = inst.yaw.sin_cos();
    let turn = |a: [f32; 3]| Vec3::new(c * a[0] - s * a[1], s * a[0] + c * a[1], a[2]);
    let scale = inst.scale;
    let phase = crate::hash::rand01(inst.hash);
    let mut p = turn(v.position) * scale;
    let n = turn(v.normal);
    let give = 1.0 - 0.6 * pw.detail[1];
    let felt = (Vec2::new(w.x, w.y) * pw.main[0]).length();
    let speed = felt.max(remembered_wind(sway_lean, pw));
    if features.has(Feature::DetailBending) {
        let [r, g, b, _] = v.wind;
        let branch_phase = g + phase;
        let vtx_phase = Vec3::from_array(v.position).dot(Vec3::splat(branch_phase));
        let (wx, wy) = (time_s + vtx_phase, time_s + branch_phase);
        let k = 1.0 + pw.detail[1];
        let waves = [
            wave(wx * 1.975 * k),
            wave(wx * 0.793 * k),
            wave(wy * 0.375 * k),
            wave(wy * 0.193 * k),
        ]
        .map(|x| x * 2.0 - 1.0);
        let sum = [waves[0] + waves[1], waves[2] + waves[3]];
        let amount = (speed / 5.0).min(1.5) * pw.detail[0] * give * scale;
        p += Vec3::new(
            n.x * r * 0.04 * sum[0],
            n.y * r * 0.04 * sum[0],
            b * 0.05 * sum[1],
        ) * amount;
    }
    let mut lean = sway_lean;
    if features.has(Feature::Interaction) {
        lean += Vec2::new(w.z, w.w) * TRAIL_LEAN;
    }
    let len = p.length();
    let mut bf = p.z / scale.max(1e-4) + 1.0;
    bf *= bf;
    bf = (bf * bf - bf) / 12.0;
    let mut q = p;
    q.x += lean.x * bf * scale;
    q.y += lean.y * bf * scale;
    let kept = (q + Vec3::new(0.0, 0.0, 1e-6)).normalize() * len;
    q = q.lerp(kept, pw.main[2]);
    let tilt = (lean * bf).extend(0.0);
    let n2 = (n - tilt * n.z).normalize();
    (Vec3::from_array(inst.pos) + q, n2)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vertex(z: f32) -> PlantVertex {
        PlantVertex {
            position: [0.05, 0.0, z],
            normal: [0.0, 1.0, 0.0],
            wind: [0.5, 0.3, z, 1.0],
            albedo: [0.2, 0.5, 0.1, 0.8],
            uv: [0.0, 0.0],
        }
    }

    fn instance() -> PlantInstance {
        PlantInstance {
            pos: [3.0, 4.0, -1.5],
            yaw: 0.7,
            scale: 0.8,
            kind: 0,
            hash: 12345,
            fade: 1.0,
        }
    }

    #[test]
    fn smooth_triangle_matches_wgsl_fract_for_negative_arguments() {
        for x in [-2.3f32, -0.75, -0.1, 0.0, 0.3, 1.6] {
            assert!((wave(x) - wave(x + 1.0)).abs() < 1e-5, "period 1 at {x}");
            assert!((0.0..=1.0).contains(&wave(x)));
        }
        assert_eq!(wave(0.0), 0.0);
        assert_eq!(wave(0.5), 1.0);
    }

    #[test]
    fn the_root_stays_put_and_a_bent_plant_keeps_its_length() {
        let pw = PlantWindGpu::new(&crate::world::PlantWind {
            bend: 0.08,
            ..Default::default()
        });
        let inst = instance();
        let root = Vec3::from_array(inst.pos);
        let wind = Vec4::new(8.0, 2.0, 0.0, 0.0);
        // The lean the type's spring settles at in this wind.
        let gain = crate::wind::plant_lean_gain(&crate::world::PlantWind {
            bend: 0.08,
            ..Default::default()
        });
        let lean = Vec2::new(wind.x, wind.y) * gain;
        let (at_root, _) = bend_vertex(&vertex(0.0), &inst, wind, lean, 1.0, &pw, Features::none());
        assert!(
            (at_root - root - Vec3::new(0.05 * 0.7f32.cos(), 0.05 * 0.7f32.sin(), 0.0) * 0.8)
                .length()
                < 1e-3
        );
        let top = vertex(1.0);
        let (still, _) = bend_vertex(
            &top,
            &inst,
            Vec4::ZERO,
            Vec2::ZERO,
            1.0,
            &pw,
            Features::none(),
        );
        let (bent, _) = bend_vertex(&top, &inst, wind, lean, 1.0, &pw, Features::none());
        // Leaned downwind, at the same distance from the root.
        let moved = (bent - still).truncate();
        assert!(
            moved.dot(Vec2::new(8.0, 2.0)) > 0.05,
            "leans downwind: {moved}"
        );
        assert!(((bent - root).length() - (still - root).length()).abs() < 1e-4);
        assert!(bent.z < still.z, "a leaning plant's top comes down");
    }

    #[test]
    fn detail_bending_moves_free_leaves_and_not_stiff_stems() {
        let pw = PlantWindGpu::new(&Default::default());
        let inst = instance();
        let wind = Vec4::new(6.0, 0.0, 0.0, 0.0);
        let mut free = vertex(0.6);
        let mut stiff = free;
        stiff.wind = [0.0, 0.3, 0.0, 1.0];
        free.wind = [1.0, 0.3, 1.0, 1.0];
        let moved = |v: &PlantVertex| {
            let lean = Vec2::new(0.2, 0.0);
            let (a, _) = bend_vertex(v, &inst, wind, lean, 2.0, &pw, Features::all());
            let (b, _) = bend_vertex(
                v,
                &inst,
                wind,
                lean,
                2.0,
                &pw,
                Features::none().with(Feature::Interaction),
            );
            (a - b).length()
        };
        assert_eq!(moved(&stiff), 0.0);
        assert!(moved(&free) > 1e-3, "{}", moved(&free));
    }

    #[test]
    fn leaves_keep_moving_after_the_wind_drops_while_the_spring_leans() {
        // A tree's wind: a slow, lightly damped sway spring.
        let wind = crate::world::PlantWind {
            bend: 0.004,
            stiffness: 0.8,
            sway_spring_hz: 0.3,
            sway_damping: 0.3,
            detail_amplitude: 0.12,
            ..Default::default()
        };
        let pw = PlantWindGpu::new(&wind);
        let gain = crate::wind::plant_lean_gain(&wind);
        let spring = crate::wind::SwaySpring::from_frequency(0.3, 0.3);
        let inst = PlantInstance {
            scale: 12.0,
            ..instance()
        };
        let mut leaf = vertex(0.8);
        leaf.wind = [1.0, 0.3, 1.0, 1.0];
        // The flutter of the leaf: its displacement by detail bending at a few times around
        // `t`, the largest.
        let flutter = |w: Vec4, lean: Vec2, t: f32| {
            (0..8)
                .map(|k| {
                    let at = t + k as f32 * 0.37;
                    let (a, _) = bend_vertex(&leaf, &inst, w, lean, at, &pw, Features::all());
                    let (b, _) = bend_vertex(
                        &leaf,
                        &inst,
                        w,
                        lean,
                        at,
                        &pw,
                        Features::none().with(Feature::Interaction),
                    );
                    (a - b).length()
                })
                .fold(0.0, f32::max)
        };
        // Settled in an 8 m/s wind, the spring leans as the wind asks: what it remembers is
        // the wind felt, so the flutter is the wind's own.
        let gust = Vec4::new(8.0, 0.0, 0.0, 0.0);
        let settled = Vec2::new(8.0 * gain, 0.0);
        assert!((remembered_wind(settled, &pw) - 8.0).abs() < 1e-3);
        let in_gust = flutter(gust, settled, 1.0);
        assert!(in_gust > 0.01, "{in_gust}");
        // The wind drops to nothing: the spring swings back over seconds, and the leaves keep
        // moving as long as it leans, less and less.
        let mut state = [
            crate::wind::SwayState {
                x: settled.x,
                v: 0.0,
            },
            crate::wind::SwayState::default(),
        ];
        let dt = 1.0 / 60.0;
        let mut after = Vec::new();
        for frame in 1..=600 {
            state = state.map(|s| crate::wind::RENDERER_INTEGRATOR.step(&spring, s, 0.0, dt));
            if frame % 60 == 0 {
                let lean = Vec2::new(state[0].x, 0.0);
                after.push((lean.length(), flutter(Vec4::ZERO, lean, frame as f32 * dt)));
            }
        }
        // In the three seconds after the drop (the spring swinging back through upright and
        // overshooting) the leaves still move, at most as much as in the gust.
        let early = after[..3].iter().map(|a| a.1).fold(0.0, f32::max);
        assert!(
            early > 0.2 * in_gust && early <= in_gust * 1.001,
            "{after:?}"
        );
        // Ten seconds after it, the spring has nearly settled and so have the leaves.
        let (lean, last) = after[after.len() - 1];
        assert!(lean < 0.05 * settled.x && last < 0.1 * early, "{after:?}");
        // No lean, no wind: no flutter (no lag without a state to carry it).
        assert_eq!(flutter(Vec4::ZERO, Vec2::ZERO, 3.0), 0.0);
        let rigid = PlantWindGpu::new(&crate::world::PlantWind { bend: 0.0, ..wind });
        assert_eq!(remembered_wind(Vec2::new(0.3, 0.0), &rigid), 0.0);
    }
}
