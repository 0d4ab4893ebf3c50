//! CPU mirror of the particles' step (`shaders/particles.wgsl`, the GPU stage:
//! [`crate::plants::particles`]): the records the GPU keeps, a particle shed from a tree, and one
//! step of a particle in the wind; a test compares them with the GPU's on software Vulkan.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

use crate::hash::{hash_u32, hash3, rand01};
use crate::plants::place_cpu::PlantInstance;

/// One particle; mirrors `Particle` in the shader.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Particle {
    /// Position relative to the camera, metres.
    pub pos: [f32; 3],
    /// Seconds since it was shed.
    pub age: f32,
    /// Velocity, m/s.
    pub vel: [f32; 3],
    /// Seconds it lives (0: not shed yet; below 0: waiting in the pool that long before it is
    /// shed, drawn nowhere).
    pub life: f32,
    /// The camera-relative height of the ground under the tree it was shed from, metres.
    pub ground: f32,
    /// The tree's type (its index among the world's tree types).
    pub kind: u32,
    /// Its seed.
    pub seed: u32,
    /// Its spin's phase (turns).
    pub spin: f32,
}
const _: () = assert!(std::mem::size_of::<Particle>() == 48);

/// The stage's uniforms; mirrors `Params` in the shader.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct ParticleParams {
    /// Camera-relative view-projection.
    pub view_proj: [[f32; 4]; 4],
    /// xyz: how far the camera moved since the last step (m); w: the step's time (s).
    pub delta: [f32; 4],
    /// x: drag (1/s), y: fall speed (m/s), z: flutter (m/s), w: the leaf's size (m).
    pub motion: [f32; 4],
    /// x, y: life range (s); z: fog distance (m); w: 1 to shed every particle again.
    pub life: [f32; 4],
    /// x: particles, y: tree types, z: instances a (type, level) region holds, w: the
    /// frame's seed.
    pub counts: [u32; 4],
    /// x: leaves in the air per tree near the camera (the rest of the pool waits).
    pub shed: [f32; 4],
    /// Toward the sun.
    pub sun_dir: [f32; 4],
    /// The sun's colour.
    pub sun_color: [f32; 4],
    /// The sky's colour.
    pub sky_color: [f32; 4],
    /// The horizon's (fog's) colour.
    pub horizon_color: [f32; 4],
    /// Per tree type, its leaves' colour.
    pub colors: [[f32; 4]; 8],
}

const TAU: f32 = std::f32::consts::TAU;

/// Particle `i` shed from the trees of the frame: `trees` is the trees' instance pool (regions
/// of `params.counts[2]` instances, type * 3 + level) and `drawn[r]` the instances in region
/// `r`; a tree of a full or reduced mesh is picked by the particle's hash and the particle put
/// in its crown. So that about `params.shed[0]` leaves a tree are in the air, the particle is
/// shed only with the chance of that many over the pool's size, else (and with no such tree)
/// it waits in the pool for a life's time (a negative life).
pub fn shed(i: u32, params: &ParticleParams, trees: &[PlantInstance], drawn: &[u32]) -> Particle {
    let cap = params.counts[2];
    let count = |t: u32, level: u32| {
        drawn
            .get((t * 3 + level) as usize)
            .copied()
            .unwrap_or(0)
            .min(cap)
    };
    let h = hash3(i, params.counts[3], 0x1eaf);
    let types = params.counts[1];
    let total: u32 = (0..types).map(|t| count(t, 0) + count(t, 1)).sum();
    let mut p = Particle {
        seed: h,
        ..Default::default()
    };
    let life = params.life[0] + (params.life[1] - params.life[0]) * rand01(hash_u32(h ^ 5));
    let chance = (total as f32 * params.shed[0] / params.counts[0].max(1) as f32).min(1.0);
    if total == 0 || rand01(hash_u32(h ^ 7)) >= chance {
        p.life = -life;
        return p;
    }
    let mut k = hash_u32(h ^ 1) % total;
    let mut region = 0;
    'pick: for t in 0..types {
        for level in 0..2 {
            let n = count(t, level);
            if k < n {
                region = t * 3 + level;
                p.kind = t;
                break 'pick;
            }
            k -= n;
        }
    }
    let tree = &trees[(region * cap + k) as usize];
    let a = TAU * rand01(hash_u32(h ^ 2));
    let r = 0.35 * tree.scale * rand01(hash_u32(h ^ 3)).sqrt();
    let z = (0.5 + 0.4 * rand01(hash_u32(h ^ 4))) * tree.scale;
    p.pos = (Vec3::from(tree.pos) + Vec3::new(r * a.cos(), r * a.sin(), z)).to_array();
    p.ground = tree.pos[2];
    p.life = life;
    p.spin = rand01(hash_u32(h ^ 6));
    p
}

/// One step of `p` in the air over `dt` seconds in the wind `wind` at its position (xy, m/s):
/// its velocity relaxes toward the wind plus its flutter, less the fall speed, at the drag's
/// rate, solved exactly over the step (position as the integral of that velocity).
pub fn step(p: &Particle, dt: f32, params: &ParticleParams, wind: [f32; 2]) -> Particle {
    let [drag, fall, flutter_mps, _] = params.motion;
    let t = p.age + rand01(p.seed) * TAU;
    let flutter = Vec3::new((2.1 * t).cos(), (1.7 * t).sin(), 0.5 * (3.3 * t).sin()) * flutter_mps;
    let target = Vec3::new(wind[0], wind[1], 0.0) + flutter - Vec3::new(0.0, 0.0, fall);
    let k = 1.0 - (-drag * dt).exp();
    let v0 = Vec3::from(p.vel);
    let vel = target + (v0 - target) * (1.0 - k);
    let pos = Vec3::from(p.pos) + target * dt + (v0 - target) * (k / drag.max(1e-4));
    Particle {
        pos: pos.to_array(),
        vel: vel.to_array(),
        age: p.age + dt,
        ..*p
    }
}

/// Every particle of `particles` after one frame's step, as the shader's `cs_step`: moved by
/// the camera's step, shed again when its life (or its wait) is over, when it has fallen below
/// its ground, or on a reset, else stepped in the wind `wind_at` gives at its (moved)
/// position, or, waiting, only aged.
pub fn advance(
    particles: &[Particle],
    params: &ParticleParams,
    trees: &[PlantInstance],
    drawn: &[u32],
    wind_at: &dyn Fn(glam::Vec2) -> [f32; 4],
) -> Vec<Particle> {
    let d = Vec3::new(params.delta[0], params.delta[1], params.delta[2]);
    particles
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let mut p = *p;
            p.pos = (Vec3::from(p.pos) - d).to_array();
            p.ground -= d.z;
            if params.life[3] > 0.5
                || p.age >= p.life.abs()
                || (p.life > 0.0 && p.pos[2] < p.ground)
            {
                shed(i as u32, params, trees, drawn)
            } else if p.life > 0.0 {
                let w = wind_at(glam::Vec2::new(p.pos[0], p.pos[1]));
                step(&p, params.delta[3], params, [w[0], w[1]])
            } else {
                Particle {
                    age: p.age + params.delta[3],
                    ..p
                }
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> ParticleParams {
        ParticleParams {
            motion: [2.0, 0.7, 0.3, 0.1],
            life: [3.0, 9.0, 3000.0, 0.0],
            counts: [16, 2, 4, 7],
            shed: [100.0, 0.0, 0.0, 0.0],
            ..Default::default()
        }
    }

    #[test]
    fn a_leaf_in_a_steady_wind_drifts_with_it_and_sinks_at_its_fall_speed() {
        let mut p = params();
        p.motion[2] = 0.0;
        let mut leaf = Particle {
            pos: [0.0, 0.0, 20.0],
            life: 100.0,
            ..Default::default()
        };
        for _ in 0..600 {
            leaf = step(&leaf, 1.0 / 60.0, &p, [5.0, -2.0]);
        }
        let v = Vec3::from(leaf.vel);
        assert!((v - Vec3::new(5.0, -2.0, -0.7)).length() < 1e-3, "{v}");
        // Ten seconds: the drift lags the wind by about 1/drag seconds.
        let x = leaf.pos[0];
        assert!((x - 5.0 * (10.0 - 0.5)).abs() < 0.1, "{x}");
        // The exact solution does not depend on how the time is cut.
        let mut coarse = Particle {
            pos: [0.0, 0.0, 20.0],
            life: 100.0,
            ..Default::default()
        };
        for _ in 0..10 {
            coarse = step(&coarse, 1.0, &p, [5.0, -2.0]);
        }
        assert!((Vec3::from(coarse.pos) - Vec3::from(leaf.pos)).length() < 1e-2);
    }

    #[test]
    fn a_shed_leaf_starts_in_a_crown_of_the_frames_trees() {
        let p = params();
        let tree = |x: f32, kind: u32| PlantInstance {
            pos: [x, 10.0, -3.0],
            yaw: 0.0,
            scale: 12.0,
            kind,
            hash: 0,
            fade: 1.0,
        };
        // Regions of 4: type 0 full meshes (2 drawn), type 1 reduced meshes (1 drawn).
        let mut trees = vec![tree(0.0, 99); 24];
        trees[0] = tree(30.0, 0);
        trees[1] = tree(-30.0, 0);
        trees[4 * 4] = tree(60.0, 1 | 1 << 8);
        let drawn = [2, 0, 0, 0, 1, 0];
        let mut kinds = [0; 2];
        for i in 0..200 {
            let leaf = shed(i, &p, &trees, &drawn);
            kinds[leaf.kind as usize] += 1;
            let from = [30.0f32, -30.0, 60.0]
                .into_iter()
                .find(|x| (leaf.pos[0] - x).abs() < 5.0)
                .expect("in a crown");
            let _ = from;
            assert!((leaf.pos[1] - 10.0).abs() <= 0.35 * 12.0 + 1e-4);
            assert!(leaf.pos[2] >= -3.0 + 6.0 - 1e-4 && leaf.pos[2] <= -3.0 + 10.8 + 1e-4);
            assert_eq!(leaf.ground, -3.0);
            assert!((3.0..=9.0).contains(&leaf.life));
        }
        assert!(kinds[0] > 100 && kinds[1] > 30, "{kinds:?}");
        assert!(shed(0, &p, &trees, &[0; 6]).life < 0.0, "no tree: waiting");
        // Two leaves a tree of three over a pool of 16: about 6 in 16 shed, the rest waiting.
        let few = ParticleParams {
            shed: [2.0, 0.0, 0.0, 0.0],
            counts: [16, 2, 4, 7],
            ..p
        };
        let flying = (0..1600)
            .filter(|&i| shed(i, &few, &trees, &drawn).life > 0.0)
            .count();
        assert!((500..700).contains(&flying), "{flying} of 1600 shed");
    }
}
