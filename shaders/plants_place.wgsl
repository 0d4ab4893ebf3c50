// Plant placement and culling, one invocation per cell of a job's placement grid (cells of
// PLANT_CELL_M; workgroup z is the job). A job is a grass tile's worth of cells read from a tile
// in the atlas: the grass tile's own data (a near job), or beyond the grass a coarser terrain
// tile's (a far job). Each cell holds at most one plant: a hash of its world cell picks a type by
// the types' densities on the grass type and density under it (scaled by the type's clumps),
// then the slope and altitude limits, the hand-over at the view distance (a near job keeps a
// plant with a chance falling to 0 over the thinning band, by the plant's own number; a far job
// keeps exactly the others, thinned again toward the end of the cards' reach), the frustum and
// the terrain's Hi-Z cull it. A survivor goes to its type's
// level of detail by distance (a dithered cross-fade: within a band around each switch it goes
// to both levels, each drawing a complementary share of its pixels) and is appended to that
// (type, level)'s region of the instance pool, unless the region was crowded the frame before:
// then it thins from the distance that fills it to a little less than its capacity
// (crowd_distances in place_cpu.rs), each plant kept by its own number, the nearest all kept
// and the survivors grown to keep the cover (the same plants frame after frame, where a full
// region would drop whichever came last). A second entry point turns the counters into
// indexed indirect draws, clamped to the region's capacity, counts the overflow, and sets the
// distance from which each region thins in the next frame.
// CPU mirror: src/plants/place_cpu.rs.

#include "shared/hash.wgsl"
#include "shared/tile_texels.wgsl"
#include "shared/hiz_cull.wgsl"
#include "shared/plant_instance.wgsl"

// Mirrors PlantJob in src/plants/place_cpu.rs.
struct PlantJob {
    // The job's south-west corner relative to the camera (m).
    origin: vec2<f32>,
    // The job's corner in its data tile, in data cells from the tile's corner.
    texel: vec2<f32>,
    cell: f32,
    layer: u32,
    // The job's address at the grass level.
    tile_x: u32,
    tile_y: u32,
    // 0: a grass tile's job, 1: a far job.
    far: u32,
    // Cells along the job's edge (0: params.grid.x); its address counts jobs of this size.
    cells: u32,
    pad1: u32,
    pad2: u32,
}

fn job_cells(job: PlantJob) -> u32 {
    return select(job.cells, params.grid.x, job.cells == 0u);
}

struct PlantType {
    // x, y: height range (m); z: cosine of the steepest slope; w: clump cell (m)
    size: vec4<f32>,
    // x, y: altitude range (m); z: the share of the ground its clumps cover; w: bounding
    // radius over height (for the culling sphere)
    limits: vec4<f32>,
    // Plants per square metre on each of 16 grass types.
    density: array<vec4<f32>, 4>,
    // x: the type's own switch from level 0 to 1 (m; nearer than the settings' for a heavy
    // mesh read from a file): it switches at the nearer of this and params.lod.x
    lod: vec4<f32>,
}

struct Params {
    view_proj: mat4x4<f32>,
    planes: array<vec4<f32>, 6>,
    // x: camera altitude, y: near plane, z, w: Hi-Z size in texels
    camera: vec4<f32>,
    // x: cells along a tile edge, y: tile data cells, z: border, w: seed
    grid: vec4<u32>,
    // x: cell edge (m), y: tile edge (m), z: start of the thinning toward the view distance
    // (m), w: the view distance (m)
    dims: vec4<f32>,
    // x: switch from level 0 to 1 (m; a type switches at the nearer of this and its lod.x),
    // y: from level 1 to the card (m), z: width of each cross-fade band (m)
    lod: vec4<f32>,
    // Far jobs: x: start of their thinning (m), y: the end of the cards' reach (m); z: where
    // the plants start to thin out with distance, survivors grown to keep the cover (m); w: the
    // fewest of them that thinning keeps
    cards: vec4<f32>,
    // x: Hi-Z mips, y: instances a (type, level) region holds, z: plant types, w: grass types
    limits: vec4<u32>,
    hiz_levels: array<vec4<u32>, 16>,
    types: array<PlantType, 8>,
    // Per (type, level), type * 3 + level: index count, first index, base vertex.
    meshes: array<vec4<u32>, 24>,
}

struct DrawIndexedArgs {
    index_count: u32,
    instance_count: u32,
    first_index: u32,
    base_vertex: i32,
    first_instance: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> jobs: array<PlantJob>;
@group(0) @binding(2) var heights: texture_2d_array<f32>;
@group(0) @binding(3) var grass: texture_2d_array<u32>;
@group(0) @binding(4) var<storage, read> hiz: array<f32>;
@group(0) @binding(5) var<storage, read_write> instances: array<PlantInstance>;
// Per (type, level) region, `type * 3 + level`.
struct Counters {
    // Instances appended this frame (may exceed the capacity).
    appended: array<atomic<u32>, 24>,
    // Instances that passed every test but the thinning of crowded regions this frame, by
    // distance: region * CROWD_BINS + crowd_bin(distance).
    wanted: array<atomic<u32>, 1536>,
    // The distance from which the region thins its plants, from what it wanted the frame
    // before (crowd_distances in place_cpu.rs; written by finalize_draws; UNCROWDED when the
    // stage is made).
    crowded_from: array<f32, 24>,
}
@group(0) @binding(6) var<storage, read_write> counters: Counters;
// The counters of `counter` in place_cpu.rs.
@group(0) @binding(7) var<storage, read_write> stats: array<atomic<u32>, 9>;
@group(0) @binding(8) var<storage, read_write> args: array<DrawIndexedArgs, 24>;

const CONSIDERED: u32 = 0u;
const EMPTY: u32 = 1u;
const RULED_OUT: u32 = 2u;
const DISTANCE: u32 = 3u;
const FRUSTUM: u32 = 4u;
const OCCLUSION: u32 = 5u;
const OVERFLOW: u32 = 6u;
const DRAWN: u32 = 7u;
const CROWDED: u32 = 8u;
const STATS: u32 = 9u;

// As in place_cpu.rs.
const CROWD_FILL: f32 = 0.95;
const CROWD_BINS: u32 = 64u;
const CROWD_NEAR_M: f32 = 2.0;
const UNCROWDED: f32 = 3.40282347e38;
const CROWD_BISECTIONS: u32 = 40u;

// The distance bin of a plant `dist` metres away: a quarter of an octave each from
// CROWD_NEAR_M, the first holding everything nearer.
fn crowd_bin(dist: f32) -> u32 {
    let b = floor(4.0 * log2(max(dist, 1e-6) / CROWD_NEAR_M)) + 1.0;
    return u32(clamp(b, 0.0, f32(CROWD_BINS - 1u)));
}

// The near edge of distance bin b, metres (0 for the first).
fn crowd_bin_near(b: u32) -> f32 {
    if b == 0u {
        return 0.0;
    }
    return CROWD_NEAR_M * exp2(f32(b - 1u) * 0.25);
}

// The chance of keeping a plant `dist` metres away in a region crowded from `from_m`.
fn crowd_keep(dist: f32, from_m: f32) -> f32 {
    if dist <= from_m {
        return 1.0;
    }
    return (from_m / dist) * (from_m / dist);
}

// Salts of the placement's hashes (as in place_cpu.rs).
const SALT_CELL: u32 = 0x9e1a7u;
const SALT_CLUMP: u32 = 0x5c1f3u;

var<workgroup> local_stats: array<atomic<u32>, 9>;

fn tally(c: u32) {
    atomicAdd(&local_stats[c], 1u);
}



// Value noise in [0, 1) on a lattice of clump cells (integer world cells `c`, fraction `f`),
// salted per type.
fn clump_noise(c: vec2<i32>, f: vec2<f32>, salt: u32) -> f32 {
    let u = f * f * (3.0 - 2.0 * f);
    let a = rand01(hash3(u32(c.x), u32(c.y), salt));
    let b = rand01(hash3(u32(c.x + 1), u32(c.y), salt));
    let cc = rand01(hash3(u32(c.x), u32(c.y + 1), salt));
    let d = rand01(hash3(u32(c.x + 1), u32(c.y + 1), salt));
    let ab = a + (b - a) * u.x;
    let cd = cc + (d - cc) * u.x;
    return ab + (cd - ab) * u.y;
}

// How much denser than its mean a type grows at world cell `cell` (its clumps): 1 everywhere
// when it covers all the ground, else 0 outside its patches and 1 / cover inside, with a soft
// edge.
fn clump_factor(t: u32, cell: vec2<u32>) -> f32 {
    let cover = params.types[t].limits.z;
    if cover >= 1.0 {
        return 1.0;
    }
    let per = params.types[t].size.w / params.dims.x;
    let p = (vec2<f32>(cell) + 0.5) / per;
    let fl = floor(p);
    let n = clump_noise(vec2<i32>(fl), p - fl, params.grid.w ^ SALT_CLUMP ^ (t * 0x3779u));
    let edge = 1.0 - cover;
    return smoothstep(edge - 0.08, edge + 0.08, n) / cover;
}

fn emit_plant(t: u32, level: u32, inst: PlantInstance) {
    let region = t * 3u + level;
    let index = atomicAdd(&counters.appended[region], 1u);
    if index < params.limits.y {
        var i = inst;
        i.kind = t | (level << 8u);
        instances[region * params.limits.y + index] = i;
    }
}

@compute @workgroup_size(8, 8, 1)
fn place(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    if lid < STATS {
        atomicStore(&local_stats[lid], 0u);
    }
    workgroupBarrier();
    let job = jobs[wid.z];
    let n = job_cells(job);
    if gid.x < n && gid.y < n {
        place_cell(job, gid.x, gid.y);
    }
    workgroupBarrier();
    if lid < STATS {
        let v = atomicLoad(&local_stats[lid]);
        if v > 0u {
            atomicAdd(&stats[lid], v);
        }
    }
}

fn place_cell(job: PlantJob, gx: u32, gy: u32) {
    let n = job_cells(job);
    let cell_m = params.dims.x;
    let seed = params.grid.w;
    let world_cell = vec2<u32>(job.tile_x * n + gx, job.tile_y * n + gy);
    let h0 = hash3(world_cell.x, world_cell.y, seed ^ SALT_CELL);
    let local = (vec2<f32>(f32(gx), f32(gy)) + 0.5 + 0.9 * (vec2<f32>(rand01(hash_u32(h0 ^ 1u)), rand01(hash_u32(h0 ^ 2u))) - 0.5)) * cell_m;

    // Bilinear height and density, nearest grass type, normal by central differences (as the
    // grass's generation).
    let border = f32(params.grid.z);
    let tp = vec2<f32>(border, border) + job.texel + local / job.cell;
    let layer = job.layer;
    let hd = tile_height_density(tp, layer);
    let ground = hd.x;
    let density = hd.y;
    let pos = vec3<f32>(job.origin + local, ground - params.camera.x);
    let dist = length(pos);
    // The hand-over at the view distance: a far job leaves (uncounted) the near job's plants.
    let near = clamp((params.dims.w - dist) / max(params.dims.w - params.dims.z, 1e-3), 0.0, 1.0);
    let handed = rand01(hash_u32(h0 ^ 5u));
    if job.far != 0u && handed < near {
        return;
    }
    tally(CONSIDERED);
    let nx = i32(floor(tp.x + 0.5));
    let ny = i32(floor(tp.y + 0.5));
    let kind = min(textureLoad(grass, tile_texel(nx, ny, layer), layer, 0).r, 15u);

    // One plant at most: the types' chances add up along [0, 1).
    let u = rand01(hash_u32(h0 ^ 3u));
    var acc = 0.0;
    var chosen = 8u;
    let area = cell_m * cell_m;
    for (var t = 0u; t < params.limits.z; t++) {
        let d = params.types[t].density[kind / 4u][kind % 4u];
        if d <= 0.0 {
            continue;
        }
        acc += d * density * area * clump_factor(t, world_cell);
        if u < acc {
            chosen = t;
            break;
        }
    }
    if chosen == 8u {
        tally(EMPTY);
        return;
    }
    let ty = params.types[chosen];
    let normal = tile_normal(nx, ny, layer, job.cell);
    if normal.z < ty.size.z || ground < ty.limits.x || ground > ty.limits.y {
        tally(RULED_OUT);
        return;
    }
    var scale = ty.size.x + (ty.size.y - ty.size.x) * rand01(hash_u32(h0 ^ 4u));
    var kept = handed < near;
    if job.far != 0u {
        // Beyond the view distance: thinned out toward the end of the cards' reach.
        let reach = clamp((params.cards.y - dist) / max(params.cards.y - params.cards.x, 1e-3), 0.0, 1.0);
        kept = rand01(hash_u32(h0 ^ 7u)) < reach;
    }
    // Beyond params.cards.z the plants thin out as the square of the distance (at most
    // 1 - params.cards.w of them go), each survivor grown to keep the cover.
    let min_keep = params.cards.w;
    let keep = max(min(1.0, params.cards.z * params.cards.z / max(dist * dist, 1e-6)), min_keep);
    if !kept || rand01(hash_u32(h0 ^ 8u)) >= keep {
        tally(DISTANCE);
        return;
    }
    // The level by distance, cross-faded over a band centred on each switch.
    let half_band = 0.5 * params.lod.z;
    let to_1 = min(params.lod.x, ty.lod.x);
    var level = 2u;
    var t_band = -1.0;
    if dist < to_1 + half_band {
        level = 0u;
        t_band = (dist - (to_1 - half_band)) / max(params.lod.z, 1e-3);
    } else if dist < params.lod.y + half_band {
        level = 1u;
        t_band = (dist - (params.lod.y - half_band)) / max(params.lod.z, 1e-3);
    }
    let faded = level < 2u && t_band > 0.0;
    let region = chosen * 3u + level;
    // A region crowded the frame before thins from a distance, keeping a plant by its own
    // number (a plant in a cross-fade by the more crowded of its two regions); the survivors
    // grow to keep the cover as the thinning with distance grows them, together by no more
    // than that thinning alone may.
    var crowded_from = counters.crowded_from[region];
    if faded {
        crowded_from = min(crowded_from, counters.crowded_from[region + 1u]);
    }
    let crowd = crowd_keep(dist, crowded_from);
    let crowd_kept = rand01(hash_u32(h0 ^ 9u)) < crowd;
    let grown = scale / sqrt(max(keep * crowd, min_keep));
    // The culling sphere of a crowded region holds the plant however much it grows (so that
    // what the region wants does not follow how crowded it was, only whether it was).
    let reach = select(grown, scale / sqrt(min_keep), crowded_from < UNCROWDED);
    scale = grown;
    let radius = reach * max(ty.limits.w, 0.5);
    let center = pos + vec3<f32>(0.0, 0.0, 0.5 * reach);
    for (var i = 0; i < 5; i++) {
        let plane = params.planes[i];
        if dot(plane.xyz, center) + plane.w < -radius {
            tally(FRUSTUM);
            return;
        }
    }
    if occluded(center, radius) {
        tally(OCCLUSION);
        return;
    }
    let bin = crowd_bin(dist);
    atomicAdd(&counters.wanted[region * CROWD_BINS + bin], 1u);
    if faded {
        atomicAdd(&counters.wanted[(region + 1u) * CROWD_BINS + bin], 1u);
    }
    if !crowd_kept {
        tally(CROWDED);
        if faded {
            tally(CROWDED);
        }
        return;
    }
    var inst: PlantInstance;
    inst.pos = pos;
    inst.yaw = rand01(hash_u32(h0 ^ 6u)) * 6.2831855;
    inst.scale = scale;
    inst.hash = h0;
    inst.fade = 1.0;
    if faded {
        // Within the band: the nearer level keeps the pixels whose dither is below 1 - t,
        // the farther one the rest.
        inst.fade = 1.0 - t_band;
        emit_plant(chosen, level, inst);
        inst.fade = -(1.0 - t_band);
        emit_plant(chosen, level + 1u, inst);
    } else {
        emit_plant(chosen, level, inst);
    }
}

// One invocation per (type, level): the indexed indirect draw from its counter, clamped to the
// region's capacity; overflow and drawn instances go to the statistics; the distance from which
// the region thins its plants in the next frame from what it wanted in this one, by distance
// (crowd_distances in place_cpu.rs: the distance whose thinning keeps no more than the fill,
// each bin's plants counted at its near edge, by bisection).
@compute @workgroup_size(24, 1, 1)
fn finalize_draws(@builtin(local_invocation_index) region: u32) {
    let appended = atomicLoad(&counters.appended[region]);
    let drawn = min(appended, params.limits.y);
    let capacity = f32(params.limits.y);
    let fit = max(min(CROWD_FILL * capacity, capacity - 3.0 * sqrt(capacity)), 1.0);
    // The region's bins, read once, and their near edges.
    var wanted: array<f32, CROWD_BINS>;
    var near: array<f32, CROWD_BINS>;
    var total = 0.0;
    for (var b = 0u; b < CROWD_BINS; b++) {
        wanted[b] = f32(atomicLoad(&counters.wanted[region * CROWD_BINS + b]));
        near[b] = crowd_bin_near(b);
        total += wanted[b];
    }
    var thin_from = UNCROWDED;
    if total > fit {
        var lo = 0.0;
        var hi = near[CROWD_BINS - 1u] * 2.0;
        for (var i = 0u; i < CROWD_BISECTIONS; i++) {
            let mid = 0.5 * (lo + hi);
            var kept = 0.0;
            for (var b = 0u; b < CROWD_BINS; b++) {
                kept += wanted[b] * crowd_keep(near[b], mid);
            }
            if kept <= fit {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        thin_from = lo;
    }
    counters.crowded_from[region] = thin_from;
    let mesh = params.meshes[region];
    var count = 0u;
    if region / 3u < params.limits.z {
        count = drawn;
        atomicAdd(&stats[OVERFLOW], appended - drawn);
        atomicAdd(&stats[DRAWN], drawn);
    }
    args[region] = DrawIndexedArgs(mesh.x, count, mesh.y, i32(mesh.z), 0u);
}
