// Grass generation and culling, one invocation per grid point of a tile (and, near the camera,
// the infill points of its cell), a batch of up to four jobs per dispatch (workgroup z is the
// job within the batch; a high-LOD tile within the near radius has a second job, LOD 2, for its
// blades there, drawn with more segments). Surviving blades are appended
// to the tile's slot of the instance pool; a second entry point turns the slot counters into
// indirect draw arguments, clamped to the slot capacity. CPU mirror: src/grass/generate_cpu.rs.
// The hashes and the blade record are included from shaders/shared/.

#include "shared/hash.wgsl"
#include "shared/blade.wgsl"
#include "shared/tile_texels.wgsl"
#include "shared/tile_job.wgsl"
#include "shared/hiz_cull.wgsl"

struct GrassType {
    height: vec2<f32>,
    width: vec2<f32>,
    growth_blend: f32,
    stiffness: f32,
    _pad: vec2<f32>,
}

struct Params {
    view_proj: mat4x4<f32>,
    planes: array<vec4<f32>, 6>,
    // x: camera altitude, y: near plane, z, w: Hi-Z size in texels
    camera: vec4<f32>,
    // x: grid points a tile edge, y: tile cells, z: border, w: seed
    grid: vec4<u32>,
    // x: spacing, y: tile edge, z: clump cell, w: short-grass height
    dims: vec4<f32>,
    // x, y: LOD fade band; z, w: dithered fade band ending at the view distance
    ranges: vec4<f32>,
    // Infill near the camera: x, y: fade band of the quarter-spacing points; z, w: of the
    // half-spacing points (w <= 0: no infill)
    infill: vec4<f32>,
    // x: horizontal radius of the near blades (job LOD 2, drawn with the most segments); y: the
    // low grid's widening (its blades this many times as wide in the low ring); z: metres toward
    // the view distance's fade per metre the camera stands above a blade (far_distance in
    // src/terrain/far_field.rs)
    near: vec4<f32>,
    // x: Hi-Z mips, y: slot capacity, z: grass types, w: blade segments, 8 bits each: near
    // blades, the rest of the high ring, the low ring
    limits: vec4<u32>,
    // Hi-Z levels: offset (floats), width, height
    hiz_levels: array<vec4<u32>, 16>,
    types: array<GrassType, 16>,
}

struct Batch {
    // Index of the batch's first job in `jobs`, and the number of jobs in it.
    first: u32,
    count: u32,
}

struct DrawArgs {
    vertex_count: u32,
    instance_count: u32,
    first_vertex: u32,
    first_instance: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> jobs: array<TileJob>;
@group(0) @binding(2) var<uniform> batch: Batch;
@group(0) @binding(3) var heights: texture_2d_array<f32>;
@group(0) @binding(4) var grass: texture_2d_array<u32>;
// The Hi-Z pyramid in a group of its own: it is rebuilt when the target is resized.
@group(1) @binding(0) var<storage, read> hiz: array<f32>;
@group(0) @binding(6) var<storage, read_write> blades: array<Blade>;
// Per slot of the half: blades wanted (may exceed the capacity).
@group(0) @binding(7) var<storage, read_write> counters: array<atomic<u32>, 4>;
// Per LOD: the counters of `counter` in generate_cpu.rs (8 each), then per slot: overflow.
@group(0) @binding(8) var<storage, read_write> stats: array<atomic<u32>, 16>;
@group(0) @binding(9) var<storage, read_write> args: array<DrawArgs, 4>;
// Workgroups of the wind pass that follows (shaders/grass_wind.wgsl): enough for the fullest slot.
@group(0) @binding(10) var<storage, read_write> wind_dispatch: array<u32, 3>;

var<workgroup> slot_blades: array<u32, 4>;

const CONSIDERED: u32 = 0u;
const EMPTY: u32 = 1u;
const DISTANCE: u32 = 2u;
const FRUSTUM: u32 = 3u;
const OCCLUSION: u32 = 4u;
const EMITTED: u32 = 5u;
// Metres (in the difference of the distances to the two nearest clump points) over which the
// grass types of two clumps mix.
const CLUMP_BLEND_M: f32 = 0.4;
const OVERFLOW: u32 = 6u;
const DRAWN: u32 = 7u;

var<workgroup> local_stats: array<atomic<u32>, 8>;


// The grass type of the map's texel nearest `local` (metres from the tile's corner).
fn kind_at(local: vec2<f32>, job: TileJob) -> u32 {
    let border = f32(params.grid.z);
    let t = floor(vec2<f32>(border, border) + local / job.cell + 0.5);
    return textureLoad(grass, tile_texel(i32(t.x), i32(t.y), job.layer), job.layer, 0).r;
}


fn emit(slot: u32, b: Blade) {
    let index = atomicAdd(&counters[slot], 1u);
    if index < params.limits.y {
        blades[slot * params.limits.y + index] = b;
    }
}

@compute @workgroup_size(8, 8, 1)
fn generate(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    if lid < 8u {
        atomicStore(&local_stats[lid], 0u);
    }
    workgroupBarrier();
    let in_batch = wid.z < batch.count;
    let job = jobs[batch.first + min(wid.z, 3u)];
    let g = params.grid.x;
    let lod = stats_lod(job.lod);
    let step = 1u + lod;
    let n = (g + step - 1u) / step;
    if in_batch && gid.x < n && gid.y < n {
        generate_point(job, gid.x * step, gid.y * step, lod);
    }
    workgroupBarrier();
    if lid < 8u && in_batch {
        let v = atomicLoad(&local_stats[lid]);
        if v > 0u {
            atomicAdd(&stats[lod * 8u + lid], v);
        }
    }
}

// How many times its own width a blade is drawn: 1 but for the blades the low grid keeps, which
// widen to params.near.y over the band in which the others fade out (params.ranges.xy) and are
// that wide in the low ring.
fn widening(lod: u32, kept: bool, dist: f32) -> f32 {
    if !kept {
        return 1.0;
    }
    var t = 1.0;
    if lod != 1u {
        t = clamp((dist - params.ranges.x) / max(params.ranges.y - params.ranges.x, 1e-3), 0.0, 1.0);
    }
    return 1.0 + (params.near.y - 1.0) * t;
}

// The statistics' LOD of a job's: near blades (LOD 2) count as high LOD (0).
fn stats_lod(lod: u32) -> u32 {
    return select(0u, 1u, lod == 1u);
}

fn count(c: u32) {
    atomicAdd(&local_stats[c], 1u);
}

// One point of the tile's grid, and near the camera the infill points of its cell: the cell's
// quarters (half the spacing) out to infill.w, its sixteenths (a quarter of the spacing) out to
// infill.y, each set shrinking away over its fade band. Blades seen at a grazing angle cover
// the ground between them; near the camera they are seen from above and must stand closer.
fn generate_point(job: TileJob, gx: u32, gy: u32, lod: u32) {
    let seed = params.grid.w;
    let spacing = params.dims.x;
    let g = params.grid.x;
    let gid_x = job.tile_x * g + gx;
    let gid_y = job.tile_y * g + gy;
    let h0 = hash3(gid_x, gid_y, seed);
    let jitter = vec2<f32>(
        (rand01(hash_u32(h0 ^ 1u)) - 0.5) * 0.9 * spacing,
        (rand01(hash_u32(h0 ^ 2u)) - 0.5) * 0.9 * spacing,
    );
    let cell = vec2<f32>(f32(gx), f32(gy));
    // Blades the low grid drops fade out before the ring switch.
    var band = vec2<f32>(0.0, 0.0);
    if job.lod != 1u && (gx % 2u == 1u || gy % 2u == 1u) {
        band = params.ranges.xy;
    }
    plant(job, (cell + 0.5) * spacing + jitter, h0, spacing, band, band.y <= 0.0);

    if job.lod == 1u || params.infill.w <= 0.0 {
        return;
    }
    // Horizontal distance of the cell's nearest point at most; the camera is at the origin.
    let reach = length(job.origin + (cell + 0.5) * spacing) - 0.75 * spacing;
    if reach >= params.infill.w {
        return;
    }
    let stride = select(2u, 1u, reach < params.infill.y);
    for (var j = 0u; j < 4u; j += stride) {
        for (var i = 0u; i < 4u; i += stride) {
            if i == 0u && j == 0u {
                continue;
            }
            let half = i % 2u == 0u && j % 2u == 0u;
            let sub = select(0.25, 0.5, half) * spacing;
            let h = hash3(gid_x * 4u + i, gid_y * 4u + j, seed ^ 0x1f111u);
            let offset = select(
                (vec2<f32>(f32(i), f32(j)) + 0.5) * 0.25,
                vec2<f32>(f32(i), f32(j)) * 0.25 + 0.25,
                half,
            );
            let jit = vec2<f32>(
                (rand01(hash_u32(h ^ 1u)) - 0.5) * 0.9 * sub,
                (rand01(hash_u32(h ^ 2u)) - 0.5) * 0.9 * sub,
            );
            plant(job, (cell + offset) * spacing + jit, h, sub, select(params.infill.xy, params.infill.zw, half), false);
        }
    }
}

// A blade at `local` (metres from the tile's corner) with its hash `h0`, of a grid of `spacing`,
// shrinking away over the distance band `band` (none where band.y <= 0). A blade of the low
// grid (`kept`) widens over the LOD fade band as the blades it stands for shrink, to
// params.near.y times its width at the ring switch and in the low ring: a quarter of the blades
// keeps the ground's cover.
fn plant(job: TileJob, local: vec2<f32>, h0: u32, spacing: f32, band: vec2<f32>, kept: bool) {
    // A high-LOD tile near the camera has two jobs: the near one (LOD 2) takes its blades within
    // params.near.x of the camera, the other (LOD 0) the rest.
    if job.lod != 1u && (length(job.origin + local) < params.near.x) != (job.lod == 2u) {
        return;
    }
    let seed = params.grid.w;
    let border = f32(params.grid.z);
    let tile_m = params.dims.y;
    let clump_m = params.dims.z;
    let short_m = params.dims.w;
    let type_count = max(params.limits.z, 1u);
    let clumps_per_tile = i32(max(round(tile_m / clump_m), 1.0));
    count(CONSIDERED);

    let tp = vec2<f32>(border + local.x / job.cell, border + local.y / job.cell);

    // Bilinear height and density, nearest grass type, normal by central differences.
    let hd = tile_height_density(tp, job.layer);
    let ground = hd.x;
    let density = hd.y;
    let normal = tile_normal(i32(floor(tp.x + 0.5)), i32(floor(tp.y + 0.5)), job.layer, job.cell);
    // Clump: the nearest of the hashed points of the 3x3 clump cells around, and the second
    // nearest. A clump has one grass type, the map's at its point: types meet along clump
    // borders, mixed over CLUMP_BLEND_M either side.
    let cx = i32(floor(local.x / clump_m));
    let cy = i32(floor(local.y / clump_m));
    var best = 3.4028235e38;
    var second = 3.4028235e38;
    var clump = 0u;
    var at_best = vec2<f32>(0.0);
    var at_second = vec2<f32>(0.0);
    for (var dy = -1; dy <= 1; dy++) {
        for (var dx = -1; dx <= 1; dx++) {
            let ccx = cx + dx;
            let ccy = cy + dy;
            let kx = u32(i32(job.tile_x) * clumps_per_tile + ccx);
            let ky = u32(i32(job.tile_y) * clumps_per_tile + ccy);
            let ch = hash3(kx, ky, seed ^ 0x00c10b55u);
            let px = (f32(ccx) + 0.5 + 0.8 * (rand01(ch) - 0.5)) * clump_m;
            let py = (f32(ccy) + 0.5 + 0.8 * (rand01(hash_u32(ch ^ 1u)) - 0.5)) * clump_m;
            let d2 = (px - local.x) * (px - local.x) + (py - local.y) * (py - local.y);
            if d2 < best {
                second = best;
                at_second = at_best;
                best = d2;
                clump = ch;
                at_best = vec2<f32>(px, py);
            } else if d2 < second {
                second = d2;
                at_second = vec2<f32>(px, py);
            }
        }
    }
    var kind = kind_at(at_best, job);
    let other = kind_at(at_second, job);
    let edge = sqrt(second) - sqrt(best);
    if other != kind && rand01(hash_u32(h0 ^ 15u)) < 0.5 * (1.0 - clamp(edge / CLUMP_BLEND_M, 0.0, 1.0)) {
        kind = other;
    }
    kind = min(kind, type_count - 1u);

    if kind == 0u || density <= 0.0 || rand01(hash_u32(h0 ^ 3u)) >= density {
        count(EMPTY);
        return;
    }
    let ty = params.types[kind];

    let clump_height = 0.7 + 0.6 * rand01(hash_u32(clump ^ 2u));
    let height = (ty.height.x + (ty.height.y - ty.height.x) * rand01(hash_u32(h0 ^ 4u)))
        * clump_height
        * (0.5 + 0.5 * density);
    if height <= 0.0 {
        count(EMPTY);
        return;
    }
    var width = ty.width.x + (ty.width.y - ty.width.x) * rand01(hash_u32(h0 ^ 9u));
    let up = vec3<f32>(0.0, 0.0, 1.0);
    let growth = normalize(up + (normal - up) * ty.growth_blend);
    let pos = vec3<f32>(job.origin.x + local.x, job.origin.y + local.y, ground - params.camera.x);

    let dist = length(pos);
    var fade = 1.0;
    if band.y > 0.0 {
        fade = clamp((band.y - dist) / (band.y - band.x), 0.0, 1.0);
    }
    // Seen from above, far blades are specks the far field shows better: each metre the
    // camera stands above a blade counts as params.near.z more metres toward the fade.
    let far_dist = dist + params.near.z * max(-pos.z, 0.0);
    let far = clamp((params.ranges.w - far_dist) / (params.ranges.w - params.ranges.z), 0.0, 1.0);
    if fade <= 0.0 || rand01(hash_u32(h0 ^ 11u)) >= far {
        count(DISTANCE);
        return;
    }
    width *= widening(job.lod, kept, dist);

    let center = pos + growth * (0.5 * height);
    let radius = 0.6 * height + width;
    var outside = false;
    for (var i = 0; i < 5; i++) {
        let plane = params.planes[i];
        if dot(plane.xyz, center) + plane.w < -radius {
            outside = true;
        }
    }
    if outside {
        count(FRUSTUM);
        return;
    }
    if occluded(center, radius) {
        count(OCCLUSION);
        return;
    }

    let facing = rand01(hash_u32(clump ^ 3u)) * 6.2831855 + (rand01(hash_u32(h0 ^ 5u)) - 0.5) * 1.9;
    let tint = vec3<f32>(
        0.85 + 0.3 * rand01(hash_u32(clump ^ 4u)),
        0.85 + 0.3 * rand01(hash_u32(clump ^ 5u)),
        0.85 + 0.3 * rand01(hash_u32(clump ^ 6u)),
    ) * 0.5;
    var b: Blade;
    b.pos_x = pos.x;
    b.pos_y = pos.y;
    b.pos_z = pos.z;
    b.facing = facing;
    b.growth_x = growth.x;
    b.growth_y = growth.y;
    b.height = height * fade;
    b.width = width * fade;
    b.tilt = 0.1 + 0.5 * rand01(hash_u32(h0 ^ 6u));
    b.bend = 0.2 + 0.7 * rand01(hash_u32(h0 ^ 7u));
    b.side_curve = 2.0 * rand01(hash_u32(h0 ^ 8u)) - 1.0;
    b.wind = (0.6 + 0.4 * rand01(hash_u32(h0 ^ 10u))) * (1.0 - 0.5 * ty.stiffness);
    b.hash = h0;
    b.kind = kind | (job.lod << 8u);
    b.color = pack_rgba8(tint);
    b.fade = fade;
    emit(job.slot, b);
    count(EMITTED);
    if height < short_m {
        b.pos_x += (rand01(hash_u32(h0 ^ 12u)) - 0.5) * 0.6 * spacing;
        b.pos_y += (rand01(hash_u32(h0 ^ 13u)) - 0.5) * 0.6 * spacing;
        b.facing += 1.5708;
        b.height *= 0.85;
        b.hash = hash_u32(h0 ^ 14u);
        emit(job.slot, b);
        count(EMITTED);
    }
}

// One invocation per slot of the half: indirect arguments from the counters, clamped to the
// slot's capacity; overflow and drawn blades go to the statistics.
@compute @workgroup_size(4, 1, 1)
fn finalize(@builtin(local_invocation_index) slot: u32) {
    let wanted = atomicLoad(&counters[slot]);
    let capacity = params.limits.y;
    let drawn = min(wanted, capacity);
    var vertices = 0u;
    if slot < batch.count {
        let job_lod = jobs[batch.first + slot].lod;
        let lod = stats_lod(job_lod);
        let shift = 8u * select(select(1u, 2u, job_lod == 1u), 0u, job_lod == 2u);
        let segments = (params.limits.w >> shift) & 0xffu;
        vertices = 2u * segments + 1u;
        atomicAdd(&stats[lod * 8u + OVERFLOW], wanted - drawn);
        atomicAdd(&stats[lod * 8u + DRAWN], drawn);
    }
    let in_use = select(0u, drawn, slot < batch.count);
    args[slot] = DrawArgs(vertices, in_use, 0u, 0u);
    slot_blades[slot] = in_use;
    workgroupBarrier();
    if slot == 0u {
        let most = max(max(slot_blades[0], slot_blades[1]), max(slot_blades[2], slot_blades[3]));
        wind_dispatch[0] = (most + 63u) / 64u;
        wind_dispatch[1] = 4u;
        wind_dispatch[2] = 1u;
    }
}
