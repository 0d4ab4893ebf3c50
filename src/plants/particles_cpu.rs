//! CPU mirror of the particles' step (`shaders/particles.wgsl`, the GPU stage:
//! [`crate::plants::particles`]): the records the GPU keeps, a particle shed from a tree (a
//! leaf) or a flower (a petal), and one step of a particle in the wind; a test compares them with the GPU's on software Vulkan.

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
    /// A leaf: its tree's type (its index among the world's tree types); a petal: [`PETAL`]
    /// plus its flower's type (its index among the plants' layer's types).
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
    /// x: leaves in the air per tree near the camera (the rest of the pool waits); y: petals
    /// in the air per flower near the camera.
    pub shed: [f32; 4],
    /// The flowers petals are shed from: x: the plants' layer's types, y: instances a (type,
    /// level) region of its pool holds, z: a bit per type that sheds petals (a flower), w: the
    /// tickets a tree near the camera has in the draw against a flower's one (about
    /// `shed.x / shed.y`, at least 1).
    pub flowers: [u32; 4],
    /// Toward the sun.
    pub sun_dir: [f32; 4],
    /// The sun's colour.
    pub sun_color: [f32; 4],
    /// The sky's colour.
    pub sky_color: [f32; 4],
    /// The horizon's (fog's) colour.
    pub horizon_color: [f32; 4],
    /// Per tree type, its leaves' colour; then per type of the plants' layer, its petals'.
    pub colors: [[f32; 4]; 16],
}

const TAU: f32 = std::f32::consts::TAU;

/// A petal's kind is this plus its flower's type.
pub const PETAL: u32 = 8;

/// Buckets of the picks per class (trees, flowers): see [`Picks`].
pub const PICK_BUCKETS: u32 = 1024;

/// The most instances of a region the picks see (an index takes 24 bits of a pick).
pub const PICK_INDICES: u32 = 1 << 24;

/// The plants a frame's particles are shed from, whatever the order of the pools (their
/// placement's atomic appends differ from run to run): per class (0 trees, 1 flowers) and
/// bucket of [`PICK_BUCKETS`], the plant with the largest [`pick_key`] among those whose key
/// falls in the bucket, as its region << 24 | index, plus 1 (where keys tie, the largest); the
/// picked plants of each class are listed in the buckets' order, and a particle is shed from
/// the one its hash chooses. Mirrors the shader's `cs_pick_keys`, `cs_pick_plants` and
/// `cs_pick_list`.
#[derive(Clone, Debug, PartialEq)]
pub struct Picks {
    lists: [Vec<(u32, u32)>; 2],
}

/// A plant's key in the picks: a hash of its own hash, its position and the frame's `seed`,
/// never 0; nothing of where it lies in its pool.
pub fn pick_key(plant: &PlantInstance, seed: u32) -> u32 {
    hash3(
        plant.hash ^ seed,
        plant.pos[0].to_bits(),
        plant.pos[1].to_bits(),
    )
    .max(1)
}

impl Picks {
    /// The picks over the frame's trees (`trees`, `drawn` as in [`shed`]) and flowers.
    pub fn new(
        params: &ParticleParams,
        trees: &[PlantInstance],
        drawn: &[u32],
        flowers: Option<Flowers<'_>>,
    ) -> Self {
        let b = PICK_BUCKETS as usize;
        let (mut keys, mut plants) = (vec![0u32; 2 * b], vec![0u32; 2 * b]);
        let seed = params.counts[3];
        let mut bid = |class: usize, region: u32, i: u32, plant: &PlantInstance| {
            let key = pick_key(plant, seed);
            let slot = class * b + (key % PICK_BUCKETS) as usize;
            let packed = ((region << 24) | i) + 1;
            if key > keys[slot] || (key == keys[slot] && packed > plants[slot]) {
                keys[slot] = key;
                plants[slot] = packed;
            }
        };
        let cap = params.counts[2];
        for t in 0..params.counts[1] {
            for level in 0..2 {
                let region = t * 3 + level;
                for i in 0..drawn_in(drawn, cap, t, level).min(PICK_INDICES) {
                    bid(0, region, i, &trees[(region * cap + i) as usize]);
                }
            }
        }
        if let Some(f) = flowers {
            let [types, plant_cap, _, _] = params.flowers;
            for t in (0..types.min(8)).filter(|&t| sheds_petals(params, t)) {
                for level in 0..2 {
                    let region = t * 3 + level;
                    for i in 0..drawn_in(f.drawn, plant_cap, t, level).min(PICK_INDICES) {
                        bid(
                            1,
                            region,
                            i,
                            &f.instances[(region * plant_cap + i) as usize],
                        );
                    }
                }
            }
        }
        let list = |class: usize| {
            plants[class * b..(class + 1) * b]
                .iter()
                .filter(|&&p| p != 0)
                .map(|&p| ((p - 1) >> 24, (p - 1) & (PICK_INDICES - 1)))
                .collect()
        };
        Picks {
            lists: [list(0), list(1)],
        }
    }

    /// The picked plants of `class` (0 trees, 1 flowers) in the buckets' order, each as
    /// (region, index).
    pub fn list(&self, class: usize) -> &[(u32, u32)] {
        &self.lists[class]
    }

    /// The plant picked for a particle of `class` whose hash is `h`: of the class's list, the
    /// one at `h` modulo its length; `None` with none.
    pub fn pick(&self, class: usize, h: u32) -> Option<(u32, u32)> {
        let list = self.list(class);
        (!list.is_empty()).then(|| list[(h % list.len() as u32) as usize])
    }
}

/// Whether type `t` of the plants' layer sheds petals this frame (its bit in `params.flowers[2]`,
/// and petals asked for).
fn sheds_petals(params: &ParticleParams, t: u32) -> bool {
    params.shed[1] > 0.0 && (params.flowers[2] >> t) & 1 == 1
}

/// The flowers of the frame: the plants' instance pool (regions of `params.flowers[1]`
/// instances, type * 3 + level) and the instances drawn in each region.
#[derive(Clone, Copy, Debug)]
pub struct Flowers<'a> {
    /// The plants' instance pool.
    pub instances: &'a [PlantInstance],
    /// Instances drawn per region.
    pub drawn: &'a [u32],
}

/// The instances drawn in (`t`, `level`)'s region of a pool of `cap` a region.
fn drawn_in(drawn: &[u32], cap: u32, t: u32, level: u32) -> u32 {
    drawn
        .get((t * 3 + level) as usize)
        .copied()
        .unwrap_or(0)
        .min(cap)
}

/// Particle `i` shed from the trees of the frame, or from its flowers: `trees` is the trees'
/// instance pool (regions of `params.counts[2]` instances, type * 3 + level) and `drawn[r]` the
/// instances in region `r`; `flowers` the plants' (only the types with their bit in
/// `params.flowers[2]` shed). The particle's hash chooses between the trees and the flowers (a
/// tree with `params.flowers[3]` tickets to a flower's one) and a plant of that kind from the
/// frame's [`Picks`] (full or reduced meshes), and it is put in its crown (a leaf) or its
/// flower head (a petal). So that about `params.shed[0]` leaves a tree and `params.shed[1]`
/// petals a flower are in the air, the particle is shed only with the chance of that many over
/// the pool's size, else (and with no tree or flower) it waits in the pool for a life's time (a
/// negative life). (Builds the picks: [`shed_from`] takes them made once for many particles.)
pub fn shed(
    i: u32,
    params: &ParticleParams,
    trees: &[PlantInstance],
    drawn: &[u32],
    flowers: Option<Flowers<'_>>,
) -> Particle {
    let picks = Picks::new(params, trees, drawn, flowers);
    shed_from(i, params, &picks, trees, drawn, flowers)
}

/// [`shed`] with the frame's `picks` (of the same pools) made beforehand.
pub fn shed_from(
    i: u32,
    params: &ParticleParams,
    picks: &Picks,
    trees: &[PlantInstance],
    drawn: &[u32],
    flowers: Option<Flowers<'_>>,
) -> Particle {
    let cap = params.counts[2];
    let h = hash3(i, params.counts[3], 0x1eaf);
    let types = params.counts[1];
    let tree_total: u32 = (0..types)
        .map(|t| drawn_in(drawn, cap, t, 0) + drawn_in(drawn, cap, t, 1))
        .sum();
    let [plant_types, plant_cap, _, tickets] = params.flowers;
    let flower_drawn = flowers.map_or(&[][..], |f| f.drawn);
    let flower_total: u32 = (0..plant_types.min(8))
        .filter(|&t| sheds_petals(params, t))
        .map(|t| drawn_in(flower_drawn, plant_cap, t, 0) + drawn_in(flower_drawn, plant_cap, t, 1))
        .sum();
    let mut p = Particle {
        seed: h,
        ..Default::default()
    };
    let life = params.life[0] + (params.life[1] - params.life[0]) * rand01(hash_u32(h ^ 5));
    let expected = tree_total as f32 * params.shed[0] + flower_total as f32 * params.shed[1];
    let chance = (expected / params.counts[0].max(1) as f32).min(1.0);
    if tree_total + flower_total == 0 || rand01(hash_u32(h ^ 7)) >= chance {
        p.life = -life;
        return p;
    }
    let tickets = tickets.max(1);
    let tree_tickets = tree_total * tickets;
    let k = hash_u32(h ^ 1) % (tree_tickets + flower_total);
    let a = TAU * rand01(hash_u32(h ^ 2));
    let (near, spot) = (rand01(hash_u32(h ^ 3)).sqrt(), rand01(hash_u32(h ^ 4)));
    let class = if k < tree_tickets { 0 } else { 1 };
    let Some((region, index)) = picks.pick(class, hash_u32(h ^ 8)) else {
        p.life = -life;
        return p;
    };
    let from = if class == 0 {
        p.kind = region / 3;
        let tree = &trees[(region * cap + index) as usize];
        // In the crown: within 0.35 of its height of the axis, from half to 0.9 of it up.
        (tree, 0.35 * near, 0.5 + 0.4 * spot)
    } else {
        p.kind = PETAL + region / 3;
        let flower = &flowers.expect("flowers were counted").instances
            [(region * plant_cap + index) as usize];
        // At the flower head: within 0.15 of its height of the stem, 0.75 to 0.95 of it up.
        (flower, 0.15 * near, 0.75 + 0.2 * spot)
    };
    let (plant, r, z) = from;
    let (r, z) = (r * plant.scale, z * plant.scale);
    p.pos = (Vec3::from(plant.pos) + Vec3::new(r * a.cos(), r * a.sin(), z)).to_array();
    p.ground = plant.pos[2];
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
    flowers: Option<Flowers<'_>>,
    wind_at: &dyn Fn(glam::Vec2) -> [f32; 4],
) -> Vec<Particle> {
    let d = Vec3::new(params.delta[0], params.delta[1], params.delta[2]);
    let picks = Picks::new(params, trees, drawn, flowers);
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
                shed_from(i as u32, params, &picks, trees, drawn, flowers)
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
            let leaf = shed(i, &p, &trees, &drawn, None);
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
        assert!(
            shed(0, &p, &trees, &[0; 6], None).life < 0.0,
            "no tree: waiting"
        );
        // Two leaves a tree of three over a pool of 16: about 6 in 16 shed, the rest waiting.
        let few = ParticleParams {
            shed: [2.0, 0.0, 0.0, 0.0],
            counts: [16, 2, 4, 7],
            ..p
        };
        let flying = (0..1600)
            .filter(|&i| shed(i, &few, &trees, &drawn, None).life > 0.0)
            .count();
        assert!((500..700).contains(&flying), "{flying} of 1600 shed");
    }

    #[test]
    fn the_sheds_do_not_depend_on_the_order_of_the_pools() {
        // Two types of 40 trees (full and reduced meshes) in regions of 64, and a flower type
        // of 30, each with its own hash and place; the same pools shuffled within each region.
        let plant = |x: f32, y: f32, scale: f32, kind: u32, hash: u32| PlantInstance {
            pos: [x, y, -2.0 + 0.01 * x],
            yaw: 0.0,
            scale,
            kind,
            hash,
            fade: 1.0,
        };
        let cap = 64u32;
        let mut trees = vec![plant(0.0, 0.0, 1.0, 99, 0); 6 * cap as usize];
        let drawn = [25, 15, 0, 30, 10, 0];
        for (r, &n) in drawn.iter().enumerate() {
            for i in 0..n {
                let x = (r * 100 + i as usize) as f32;
                trees[r * cap as usize + i as usize] =
                    plant(x, 0.5 * x, 10.0, (r / 3) as u32, hash_u32(x.to_bits()));
            }
        }
        let mut plants = vec![plant(0.0, 0.0, 0.5, 99, 0); 3 * cap as usize];
        let plant_drawn = [20, 10, 0];
        for (r, &n) in plant_drawn.iter().enumerate() {
            for i in 0..n {
                let x = -(r as f32 * 50.0 + i as f32) - 1.0;
                plants[r * cap as usize + i as usize] = plant(x, 3.0, 0.5, 0, i % 3);
            }
        }
        let p = ParticleParams {
            motion: [2.0, 0.7, 0.3, 0.1],
            life: [3.0, 9.0, 3000.0, 0.0],
            counts: [500, 2, cap, 12345],
            shed: [3.0, 1.0, 0.0, 0.0],
            flowers: [1, cap, 0b1, 3],
            ..Default::default()
        };
        let shuffled = |pool: &[PlantInstance], counts: &[u32], salt: u32| {
            let mut out = pool.to_vec();
            for (r, &n) in counts.iter().enumerate() {
                let region = &mut out[r * cap as usize..][..n as usize];
                region.sort_by_key(|q| hash_u32(q.hash ^ q.pos[0].to_bits() ^ salt));
            }
            out
        };
        let sheds = |trees: &[PlantInstance], plants: &[PlantInstance]| -> Vec<Particle> {
            let flowers = Flowers {
                instances: plants,
                drawn: &plant_drawn,
            };
            advance(
                &vec![Particle::default(); 500],
                &p,
                trees,
                &drawn,
                Some(flowers),
                &|_| [0.0; 4],
            )
        };
        let first = sheds(&trees, &plants);
        for salt in [1, 2, 3] {
            let again = sheds(
                &shuffled(&trees, &drawn, salt),
                &shuffled(&plants, &plant_drawn, salt),
            );
            assert_eq!(first, again, "shuffle {salt}");
        }
        // They come from many plants of both kinds (the picks keep nearly every plant at this
        // size), about in proportion: 3 tickets a tree, 1 a flower.
        let flying: Vec<&Particle> = first.iter().filter(|q| q.life > 0.0).collect();
        let petals = flying.iter().filter(|q| q.kind >= PETAL).count();
        let leaves = flying.len() - petals;
        assert!(flying.len() > 200, "{} flying", flying.len());
        let share = petals as f32 / flying.len() as f32;
        assert!(
            (0.06..0.16).contains(&share),
            "{petals} petals of {}",
            flying.len()
        );
        let sources: std::collections::HashSet<u32> =
            flying.iter().map(|q| q.ground.to_bits()).collect();
        assert!(
            sources.len() > 60,
            "{} plants shed {leaves} leaves and {petals} petals",
            sources.len()
        );
        // The frame's seed draws other picks.
        let picks = Picks::new(&p, &trees, &drawn, None);
        assert!(
            picks.list(0).len() >= 75 && picks.list(0).len() <= 80,
            "{}",
            picks.list(0).len()
        );
        let other = Picks::new(
            &ParticleParams {
                counts: [500, 2, cap, 777],
                ..p
            },
            &trees,
            &drawn,
            None,
        );
        assert_ne!(picks.list(0), other.list(0));
    }

    #[test]
    fn petals_come_from_the_flowers_heads_in_their_share() {
        let plant = |x: f32, scale: f32, kind: u32| PlantInstance {
            pos: [x, 10.0, -3.0],
            yaw: 0.0,
            scale,
            kind,
            hash: 0,
            fade: 1.0,
        };
        // One tree (type 0, full mesh); plant type 0 a fern (no petals), type 1 a flower:
        // regions of 4, the fern's 3 full meshes, the flower's 2 reduced ones.
        let mut trees = vec![plant(0.0, 12.0, 99); 24];
        trees[0] = plant(30.0, 12.0, 0);
        let drawn = [1, 0, 0, 0, 0, 0];
        let mut plants = vec![plant(0.0, 0.5, 99); 24];
        for (k, fern) in plants.iter_mut().take(3).enumerate() {
            *fern = plant(-50.0 - k as f32, 0.8, 0);
        }
        plants[4 * 4] = plant(70.0, 0.5, 1 | 1 << 8);
        plants[4 * 4 + 1] = plant(71.0, 0.5, 1 | 1 << 8);
        let plant_drawn = [3, 0, 0, 0, 2, 0];
        let flowers = Flowers {
            instances: &plants,
            drawn: &plant_drawn,
        };
        // A tree has 4 tickets to a flower's one: 4 of 6 particles are leaves, 2 petals.
        let p = ParticleParams {
            motion: [2.0, 0.7, 0.3, 0.1],
            life: [3.0, 9.0, 3000.0, 0.0],
            counts: [16, 1, 4, 7],
            shed: [100.0, 25.0, 0.0, 0.0],
            flowers: [2, 4, 0b10, 4],
            ..Default::default()
        };
        let (mut leaves, mut petals) = (0, 0);
        for i in 0..600 {
            let q = shed(i, &p, &trees, &drawn, Some(flowers));
            assert!(q.life > 0.0);
            if q.kind == 0 {
                leaves += 1;
                assert!((q.pos[0] - 30.0).abs() <= 0.35 * 12.0 + 1e-4);
            } else {
                petals += 1;
                assert_eq!(q.kind, PETAL + 1, "only the flower type sheds petals");
                assert!(q.pos[0] > 69.0 - 0.1 && q.pos[0] < 71.0 + 0.1, "{q:?}");
                let up = q.pos[2] + 3.0;
                assert!(
                    (0.75 * 0.5 - 1e-4..=0.95 * 0.5 + 1e-4).contains(&up),
                    "{q:?}"
                );
                assert_eq!(q.ground, -3.0);
            }
        }
        assert!(
            (150..250).contains(&petals) && leaves + petals == 600,
            "{petals} petals"
        );
        // Without petals asked for, every particle is a leaf.
        let none = ParticleParams {
            shed: [100.0, 0.0, 0.0, 0.0],
            ..p
        };
        assert!((0..200).all(|i| shed(i, &none, &trees, &drawn, Some(flowers)).kind == 0));
        // Flowers alone shed petals; nothing near, nothing shed.
        let no_tree = [0; 6];
        assert!((0..100).all(|i| shed(i, &p, &trees, &no_tree, Some(flowers)).kind == PETAL + 1));
        assert!(shed(0, &p, &trees, &no_tree, None).life < 0.0);
    }
}
