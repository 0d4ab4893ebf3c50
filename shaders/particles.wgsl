// Wind-carried leaves and petals (src/plants/particles.rs): a bounded pool of particles shed by
// the trees and the flowers, each stepped once a frame in the same wind field the grass and the
// plants bend in (a gust sends them flying, the helicopter's downwash scatters them), and drawn
// as small leaves turned to the camera. One compute pass steps every particle: one whose life is
// over, or that has fallen to the ground it was shed over, is shed again from a tree of the
// frame's instance pool (the nearest trees: full and reduced meshes), from a point in its crown,
// or from the head of a flower of the plants' pool (a petal); the rest move toward the wind plus
// their own flutter, sinking at their fall speed, with the exact solution of that drag over the
// frame's time. Positions are relative to the camera (moved by the camera's step each frame).
// The pools' order is their placement's atomic appends, which differs from run to run: so that a
// frame sheds the same particles whatever that order, three passes before the step pick, per
// bucket of PICK_BUCKETS, the tree and the flower with the largest key (a hash of the plant's
// own hash, its position and the frame's seed, never of its place in the pool), and list the
// picked ones in the buckets' order; a particle is shed from the plant of that list its hash
// chooses.
// CPU mirror: src/plants/particles_cpu.rs.

#include "shared/hash.wgsl"
#include "shared/output.wgsl"
#include "shared/wind_lookup.wgsl"
#include "shared/plant_instance.wgsl"

// Mirrors Particle in src/plants/particles_cpu.rs.
struct Particle {
    // Relative to the camera (m); age (s)
    pos: vec3<f32>,
    age: f32,
    // m/s; life (s; 0: not shed yet; below 0: waiting in the pool that long before it is
    // shed, drawn nowhere)
    vel: vec3<f32>,
    life: f32,
    // The ground under the tree it was shed from (camera-relative z, m); the tree's type; its
    // seed; its spin phase
    ground: f32,
    kind: u32,
    seed: u32,
    spin: f32,
}

// Mirrors ParticleParams in src/plants/particles_cpu.rs.
struct Params {
    view_proj: mat4x4<f32>,
    // xyz: how far the camera moved since the last step (m); w: the step's time (s)
    delta: vec4<f32>,
    // x: drag (1/s), y: fall speed (m/s), z: flutter (m/s), w: the leaf's size (m)
    motion: vec4<f32>,
    // x, y: life range (s); z: fog distance (m); w: 1 to shed every particle again (a teleport)
    life: vec4<f32>,
    // x: particles, y: tree types, z: instances a (type, level) region holds, w: the frame's seed
    counts: vec4<u32>,
    // x: leaves in the air per tree near the camera (the rest of the pool waits), y: petals in
    // the air per flower near the camera, zw: unused
    shed: vec4<f32>,
    // x: the plants' layer's types, y: instances a (type, level) region of its pool holds,
    // z: a bit per type that sheds petals, w: a tree's tickets in the draw to a flower's one
    flowers: vec4<u32>,
    sun_dir: vec4<f32>,
    sun_color: vec4<f32>,
    sky_color: vec4<f32>,
    horizon_color: vec4<f32>,
    // Per tree type, its leaves' colour; then per type of the plants' layer, its petals'.
    colors: array<vec4<f32>, 16>,
}

struct DrawIndexedArgs {
    index_count: u32,
    instance_count: u32,
    first_index: u32,
    base_vertex: i32,
    first_instance: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read_write> particles: array<Particle>;
@group(0) @binding(2) var<uniform> wind_lookup: WindLookup;
@group(0) @binding(3) var<storage, read> wind_cells: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> trees: array<PlantInstance>;
@group(0) @binding(5) var<storage, read> tree_args: array<DrawIndexedArgs>;
// The plants' instance pool and draws, for the flowers' petals.
@group(0) @binding(6) var<storage, read> plants: array<PlantInstance>;
@group(0) @binding(7) var<storage, read> plant_args: array<DrawIndexedArgs>;
// Per pool (trees, then flowers) and bucket, the largest key of a plant in it (0: none); then
// the region << 24 | index, plus 1, of the plant that holds it (the largest where keys tie);
// then per pool the picked plants in the buckets' order; then per pool their number.
@group(0) @binding(8) var<storage, read_write> picks: array<atomic<u32>>;
// The pool again, read-only, for the draw (a vertex stage cannot see a writable buffer).
@group(1) @binding(0) var<storage, read> leaves: array<Particle>;

const TAU: f32 = 6.2831853;
// A petal's kind is this plus its flower's type.
const PETAL: u32 = 8u;
// Buckets of the picks per pool.
const PICK_BUCKETS: u32 = 1024u;
// The most instances of a region the picks see (an index takes 24 bits).
const PICK_INDICES: u32 = 16777216u;

// The trees of the frame a particle can be shed from: per type, its full and reduced meshes.
fn tree_count(t: u32, level: u32) -> u32 {
    return min(tree_args[t * 3u + level].instance_count, params.counts.z);
}

// The flowers of the frame a petal can be shed from: per type that sheds, its full and reduced
// meshes.
fn flower_count(t: u32, level: u32) -> u32 {
    if params.shed.y <= 0.0 || ((params.flowers.z >> t) & 1u) == 0u {
        return 0u;
    }
    return min(plant_args[t * 3u + level].instance_count, params.flowers.y);
}

// Shed particle `i` again, from a tree or a flower picked by its hash (a tree with
// params.flowers.w tickets to a flower's one; the plant from the picks), or, to keep about
// params.shed.x leaves in the air per tree and params.shed.y petals per flower near the camera,
// leave it waiting in the pool for a life's time (as shed in particles_cpu.rs).
fn shed(i: u32) -> Particle {
    var p: Particle;
    let h = hash3(i, params.counts.w, 0x1eafu);
    var tree_total = 0u;
    for (var t = 0u; t < params.counts.y; t++) {
        tree_total += tree_count(t, 0u) + tree_count(t, 1u);
    }
    let plant_types = min(params.flowers.x, 8u);
    var flower_total = 0u;
    for (var t = 0u; t < plant_types; t++) {
        flower_total += flower_count(t, 0u) + flower_count(t, 1u);
    }
    p.seed = h;
    p.age = 0.0;
    p.vel = vec3<f32>(0.0);
    p.pos = vec3<f32>(0.0);
    p.ground = 0.0;
    p.kind = 0u;
    p.spin = 0.0;
    let life = mix(params.life.x, params.life.y, rand01(hash_u32(h ^ 5u)));
    let expected = f32(tree_total) * params.shed.x + f32(flower_total) * params.shed.y;
    let chance = min(1.0, expected / f32(max(params.counts.x, 1u)));
    if tree_total + flower_total == 0u || rand01(hash_u32(h ^ 7u)) >= chance {
        // Waiting in the pool for a life's time, drawn nowhere.
        p.life = -life;
        return p;
    }
    let tickets = max(params.flowers.w, 1u);
    let tree_tickets = tree_total * tickets;
    let k = hash_u32(h ^ 1u) % (tree_tickets + flower_total);
    let a = TAU * rand01(hash_u32(h ^ 2u));
    let near = sqrt(rand01(hash_u32(h ^ 3u)));
    let spot = rand01(hash_u32(h ^ 4u));
    let pool = select(1u, 0u, k < tree_tickets);
    let picked = pick(pool, hash_u32(h ^ 8u));
    if picked == 0u {
        p.life = -life;
        return p;
    }
    let region = (picked - 1u) >> 24u;
    let index = (picked - 1u) & (PICK_INDICES - 1u);
    var source: PlantInstance;
    var r = 0.0;
    var z = 0.0;
    if pool == 0u {
        source = trees[region * params.counts.z + index];
        p.kind = region / 3u;
        // In the crown: within 0.35 of its height of the axis, from half to 0.9 of it up.
        r = 0.35 * near;
        z = 0.5 + 0.4 * spot;
    } else {
        source = plants[region * params.flowers.y + index];
        p.kind = PETAL + region / 3u;
        // At the flower head: within 0.15 of its height of the stem, 0.75 to 0.95 of it up.
        r = 0.15 * near;
        z = 0.75 + 0.2 * spot;
    }
    r = r * source.scale;
    z = z * source.scale;
    p.pos = source.pos + vec3<f32>(r * cos(a), r * sin(a), z);
    p.ground = source.pos.z;
    p.life = life;
    p.spin = rand01(hash_u32(h ^ 6u));
    return p;
}

// A plant's key in the picks: of its own hash, its position and the frame's seed, never 0 (as
// pick_key in particles_cpu.rs).
fn pick_key(plant: PlantInstance) -> u32 {
    let h = hash3(plant.hash ^ params.counts.w, bitcast<u32>(plant.pos.x), bitcast<u32>(plant.pos.y));
    return max(h, 1u);
}

// The plant at index `i` of `region` of pool `pool` (0 trees, 1 flowers) takes part in the
// picks: in the first pass its key bids for its bucket; in the second, the plant whose key won
// writes where it lies.
fn bid(pool: u32, region: u32, i: u32, plant: PlantInstance, second: bool) {
    let key = pick_key(plant);
    let slot = pool * PICK_BUCKETS + key % PICK_BUCKETS;
    if !second {
        atomicMax(&picks[slot], key);
    } else if atomicLoad(&picks[slot]) == key {
        atomicMax(&picks[2u * PICK_BUCKETS + slot], ((region << 24u) | i) + 1u);
    }
}

// Every tree and flower particles can be shed from, at index `i` of its region.
fn bid_all(i: u32, second: bool) {
    if i >= PICK_INDICES {
        return;
    }
    for (var t = 0u; t < params.counts.y; t++) {
        for (var level = 0u; level < 2u; level++) {
            if i < tree_count(t, level) {
                let region = t * 3u + level;
                bid(0u, region, i, trees[region * params.counts.z + i], second);
            }
        }
    }
    for (var t = 0u; t < min(params.flowers.x, 8u); t++) {
        for (var level = 0u; level < 2u; level++) {
            if i < flower_count(t, level) {
                let region = t * 3u + level;
                bid(1u, region, i, plants[region * params.flowers.y + i], second);
            }
        }
    }
}

@compute @workgroup_size(64)
fn cs_pick_keys(@builtin(global_invocation_id) id: vec3<u32>) {
    bid_all(id.x, false);
}

@compute @workgroup_size(64)
fn cs_pick_plants(@builtin(global_invocation_id) id: vec3<u32>) {
    bid_all(id.x, true);
}

var<workgroup> bucket_counts: array<u32, 64>;

// The picked plants of pool workgroup_id.x listed in the buckets' order: each of 64
// invocations counts the picks of 16 buckets, the first sums the counts before each, and each
// writes its own where they start.
@compute @workgroup_size(64)
fn cs_pick_list(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) l: u32) {
    let pool = wg.x;
    let per = PICK_BUCKETS / 64u;
    let start = 2u * PICK_BUCKETS + pool * PICK_BUCKETS + l * per;
    var n = 0u;
    for (var j = 0u; j < per; j++) {
        n += select(0u, 1u, atomicLoad(&picks[start + j]) != 0u);
    }
    bucket_counts[l] = n;
    workgroupBarrier();
    if l == 0u {
        var total = 0u;
        for (var j = 0u; j < 64u; j++) {
            let c = bucket_counts[j];
            bucket_counts[j] = total;
            total += c;
        }
        atomicStore(&picks[6u * PICK_BUCKETS + pool], total);
    }
    workgroupBarrier();
    var at = 4u * PICK_BUCKETS + pool * PICK_BUCKETS + bucket_counts[l];
    for (var j = 0u; j < per; j++) {
        let got = atomicLoad(&picks[start + j]);
        if got != 0u {
            atomicStore(&picks[at], got);
            at += 1u;
        }
    }
}

// The plant picked for a particle of pool `pool` whose hash is `h`: of the pool's picked
// plants, the one at h modulo their number (region << 24 | index, plus 1; 0: none at all).
fn pick(pool: u32, h: u32) -> u32 {
    let n = atomicLoad(&picks[6u * PICK_BUCKETS + pool]);
    if n == 0u {
        return 0u;
    }
    return atomicLoad(&picks[4u * PICK_BUCKETS + pool * PICK_BUCKETS + h % n]);
}

// One step of a particle in the air over `dt` (as step in particles_cpu.rs): its velocity
// relaxes toward the wind plus its flutter, less its fall speed, at the drag's rate, exactly.
fn step(p_in: Particle, dt: f32) -> Particle {
    var p = p_in;
    let w = wind_at(p.pos.xy);
    let phase = rand01(p.seed) * TAU;
    let t = p.age + phase;
    let flutter = vec3<f32>(cos(2.1 * t), sin(1.7 * t), 0.5 * sin(3.3 * t)) * params.motion.z;
    let target_vel = vec3<f32>(w.xy, 0.0) + flutter - vec3<f32>(0.0, 0.0, params.motion.y);
    let k = 1.0 - exp(-params.motion.x * dt);
    let v0 = p.vel;
    p.vel = target_vel + (v0 - target_vel) * (1.0 - k);
    // The position over the step: the integral of the relaxing velocity.
    let drag = max(params.motion.x, 1e-4);
    p.pos += target_vel * dt + (v0 - target_vel) * (k / drag);
    p.age += dt;
    return p;
}

@compute @workgroup_size(64)
fn cs_step(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.counts.x {
        return;
    }
    var p = particles[i];
    p.pos -= params.delta.xyz;
    p.ground -= params.delta.z;
    if params.life.w > 0.5 || p.age >= abs(p.life) || (p.life > 0.0 && p.pos.z < p.ground) {
        particles[i] = shed(i);
    } else if p.life > 0.0 {
        particles[i] = step(p, params.delta.w);
    } else {
        p.age += params.delta.w;
        particles[i] = p;
    }
}

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
    @location(1) color: vec3<f32>,
    @location(2) fog: f32,
}

// A leaf: a quad turned to the camera, spinning as it falls, lit by the sun and the sky from
// both sides.
@vertex
fn vs_particle(@builtin(vertex_index) vi: u32, @builtin(instance_index) ii: u32) -> VertexOut {
    var out: VertexOut;
    let p = leaves[ii];
    if p.life <= 0.0 || p.age >= p.life {
        out.clip = vec4<f32>(0.0);
        return out;
    }
    let corner = vec2<f32>(f32(vi & 1u), f32(vi >> 1u)) * 2.0 - 1.0;
    let to_eye = normalize(-p.pos);
    var right = cross(vec3<f32>(0.0, 0.0, 1.0), to_eye);
    if dot(right, right) < 1e-6 {
        right = vec3<f32>(1.0, 0.0, 0.0);
    }
    right = normalize(right);
    let up = cross(to_eye, right);
    let a = TAU * (p.spin + 0.4 * p.age);
    let c = vec2<f32>(cos(a), sin(a));
    let r = vec2<f32>(corner.x * c.x - corner.y * c.y, corner.x * c.y + corner.y * c.x);
    // A petal is half a leaf's size.
    let size = select(params.motion.w, 0.5 * params.motion.w, p.kind >= PETAL);
    let world = p.pos + (right * r.x + up * r.y * 0.6) * size;
    out.clip = params.view_proj * vec4<f32>(world, 1.0);
    out.uv = corner;
    let albedo = params.colors[min(p.kind, 15u)].rgb;
    let light = params.sun_color.rgb * (0.35 + 0.4 * abs(params.sun_dir.z)) + params.sky_color.rgb * 0.4;
    out.color = albedo * light;
    let x = length(p.pos) / params.life.z;
    out.fog = 1.0 - exp(-3.0 * x * x);
    return out;
}

// Whether a fragment lies outside the leaf's outline, an ellipse pointed at both ends.
fn outside_leaf(in: VertexOut) -> bool {
    let q = vec2<f32>(in.uv.x, in.uv.y * (1.0 + 0.6 * abs(in.uv.x)));
    return dot(q, q) > 1.0;
}

@fragment
fn fs_particle(in: VertexOut) -> @location(0) vec4<f32> {
    if outside_leaf(in) {
        discard;
    }
    return output_color(mix(in.color, params.horizon_color.rgb, in.fog));
}

// With temporal anti-aliasing, a second draw of the leaves marks their pixels in the motion
// vectors' target (w = 2, at the leaf's depth) as ones whose history does not hold them. A
// leaf a pixel or two wide moves on its own and spins; reprojected through its depth, its
// pixel's history is the ground or the grass behind it, which the neighbourhood's clip keeps,
// and the leaf would show at 1 / n of its colour. The resolve (shaders/aa_taa.wgsl) takes a
// marked pixel's current sample alone.
@fragment
fn fs_particle_mark(in: VertexOut) -> @location(0) vec4<f32> {
    if outside_leaf(in) {
        discard;
    }
    return vec4<f32>(0.0, 0.0, in.clip.z, 2.0);
}
