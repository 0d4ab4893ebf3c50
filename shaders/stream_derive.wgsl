// Derives child tiles from their parents in the tile atlas: Catmull-Rom upsampling of the
// parent's smooth heights (the parent less its own detail, recomputed here) plus slope-scaled
// high-pass detail noise between the parent's samples, at the child level's amplitude (fitted per world;
// zero for stored levels), that fades to zero near tile edges; grass type and terrain material from one of the
// nearest parent samples, density as their rounded mean. CPU mirror: src/stream/derive_cpu.rs.
//
// One dispatch derives several tiles: workgroup z is the job index.

#include "shared/hash.wgsl"

struct Job {
    // Child tile address.
    child_x: u32,
    child_y: u32,
    child_level: u32,
    // Atlas slot of the parent.
    parent_layer: u32,
    // Layer of the staging textures to write.
    out_layer: u32,
    cell_parent: f32,
    cell_child: f32,
    // Detail amplitudes of the child's level and of the parent's (0 for a stored parent), in
    // cells per unit of slope. Per job rather than in the uniforms: lavapipe compiles a shader
    // variant per distinct uniform value that steers it.
    detail_child: f32,
    detail_parent: f32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
    // The child's identity in the atlas: [level, x, y, generation].
    identity: vec4<u32>,
    // What the parent's slot must hold; a parent slot holding anything else poisons the child.
    parent_identity: vec4<u32>,
}

struct Params {
    // x: tile cells, y: border, z: samples per side, w: seed
    grid: vec4<u32>,
    // x: unused, y: window cells
    detail: vec4<f32>,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> jobs: array<Job>;
@group(0) @binding(2) var parent_heights: texture_2d_array<f32>;
@group(0) @binding(3) var parent_grass: texture_2d_array<u32>;
@group(0) @binding(4) var out_heights: texture_storage_2d_array<r32float, write>;
@group(0) @binding(5) var out_grass: texture_storage_2d_array<rgba8uint, write>;
// What each atlas slot holds (read: the parent's), and the identities of this batch's children.
@group(0) @binding(6) var<storage, read> atlas_identity: array<vec4<u32>>;
@group(0) @binding(7) var<storage, read_write> out_identity: array<vec4<u32>>;

// Weight k (0, 1, 2) of the high-pass filter [-1/2, 1, -1/2].
fn high_pass(k: i32) -> f32 {
    if k == 1 {
        return 1.0;
    }
    return -0.5;
}

// The detail noise at sample (x, y) of `level`: hashed values filtered by [-1/2, 1, -1/2]
// along x and then y, scaled by 2/3 (the variance of the hashed values).
fn detail_noise(x: i32, y: i32, level: u32, seed: u32) -> f32 {
    var sum = 0.0;
    for (var dy = 0; dy < 3; dy++) {
        var row = 0.0;
        for (var dx = 0; dx < 3; dx++) {
            row += high_pass(dx) * unit(hash4(u32(x + dx - 1), u32(y + dy - 1), level, seed));
        }
        sum += high_pass(dy) * row;
    }
    return sum * (2.0 / 3.0);
}

fn weights(f: i32) -> vec4<f32> {
    if f == 0 {
        return vec4<f32>(0.0, 1.0, 0.0, 0.0);
    }
    return vec4<f32>(-0.0625, 0.5625, 0.5625, -0.0625);
}

fn clamp_texel(x: i32, y: i32) -> vec2<i32> {
    let s = i32(params.grid.z);
    return vec2<i32>(clamp(x, 0, s - 1), clamp(y, 0, s - 1));
}

fn ph(x: i32, y: i32, layer: u32) -> f32 {
    return textureLoad(parent_heights, clamp_texel(x, y), layer, 0).r;
}

fn window_at(sx: i32, sy: i32) -> f32 {
    let n = i32(params.grid.x);
    let b = i32(params.grid.y);
    // Euclidean remainder (the shader's % keeps the sign of the dividend).
    let mx = ((sx % n) + n) % n;
    let my = ((sy % n) + n) % n;
    let edge = min(min(mx, n - mx), min(my, n - my)) - b;
    return clamp(f32(edge) / params.detail.y, 0.0, 1.0);
}

// The parent's smooth height at texel (x, y): its height less its own detail, which lies on
// the parent's new samples only, scaled by the grandparent's slope (read off the parent's
// other samples, which are the grandparent's).
fn smooth_height(x: i32, y: i32, job: Job) -> f32 {
    let n = i32(params.grid.x);
    let b = i32(params.grid.y);
    let gx = i32(job.child_x >> 1u) * n - b + x;
    let gy = i32(job.child_y >> 1u) * n - b + y;
    let ex = gx & 1;
    let ey = gy & 1;
    let new_sample = min(f32(ex | ey), 1.0);
    let cx = x - ex;
    let cy = y - ey;
    let layer = job.parent_layer;
    let cell_grandparent = 2.0 * job.cell_parent;
    let gpx = (ph(cx + 2, cy, layer) - ph(cx - 2, cy, layer)) / (2.0 * cell_grandparent);
    let gpy = (ph(cx, cy + 2, layer) - ph(cx, cy - 2, layer)) / (2.0 * cell_grandparent);
    let slope = min(sqrt(gpx * gpx + gpy * gpy), 1.5);
    let parent_level = job.child_level - 1u;
    let noise = detail_noise(gx, gy, parent_level, params.grid.w);
    let detail = noise * (job.detail_parent * job.cell_parent * slope * window_at(gx, gy) * new_sample);
    return ph(x, y, layer) - detail;
}

@compute @workgroup_size(8, 8, 1)
fn derive_child(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let s = i32(params.grid.z);
    let i = i32(gid.x);
    let j = i32(gid.y);
    if i >= s || j >= s {
        return;
    }
    let job = jobs[wid.z];
    if i == 0 && j == 0 {
        // A child derived from a slot that does not hold its parent is not the child.
        var identity = job.identity;
        if any(atlas_identity[job.parent_layer] != job.parent_identity) {
            identity.w = 0u;
        }
        out_identity[job.out_layer] = identity;
    }
    let n = i32(params.grid.x);
    let b = i32(params.grid.y);
    let qx = i32(job.child_x & 1u);
    let qy = i32(job.child_y & 1u);
    let layer = job.parent_layer;

    let px2 = b + qx * n + i;
    let py2 = b + qy * n + j;
    let ix = px2 >> 1u;
    let fx = px2 & 1;
    let iy = py2 >> 1u;
    let fy = py2 & 1;
    let wx = weights(fx);
    let wy = weights(fy);

    var taps: array<vec4<f32>, 4>;
    for (var dy = 0; dy < 4; dy++) {
        let y = iy - 1 + dy;
        taps[dy] = vec4<f32>(smooth_height(ix - 1, y, job), smooth_height(ix, y, job), smooth_height(ix + 1, y, job), smooth_height(ix + 2, y, job));
    }
    var rows: array<f32, 4>;
    for (var dy = 0; dy < 4; dy++) {
        let t = taps[dy];
        rows[dy] = ((wx.x * t.x + wx.y * t.y) + wx.z * t.z) + wx.w * t.w;
    }
    var h = ((wy.x * rows[0] + wy.y * rows[1]) + wy.z * rows[2]) + wy.w * rows[3];

    let gx = (taps[1].z - taps[1].x) / (2.0 * job.cell_parent);
    let gy = (taps[2].y - taps[0].y) / (2.0 * job.cell_parent);
    let slope = min(sqrt(gx * gx + gy * gy), 1.5);

    // Global sample coordinates at the child's level; detail only between the parent's samples.
    let sx = i32(job.child_x) * n + i - b;
    let sy = i32(job.child_y) * n + j - b;
    let new_sample = min(f32((sx | sy) & 1), 1.0);
    let seed = params.grid.w;
    let noise = detail_noise(sx, sy, job.child_level, seed);
    h += noise * (job.detail_child * job.cell_child * slope * window_at(sx, sy) * new_sample);

    let pick = hash4(u32(sx), u32(sy), job.child_level, seed ^ 0x9e3779b9u);
    let tx = ix + fx * i32(pick & 1u);
    let ty = iy + fy * i32((pick >> 1u) & 1u);
    // The grass type and the terrain material of one nearest parent sample.
    let picked = textureLoad(parent_grass, clamp_texel(tx, ty), layer, 0);

    var sum = 0u;
    for (var a = 0; a <= fy; a++) {
        for (var c = 0; c <= fx; c++) {
            sum += textureLoad(parent_grass, clamp_texel(ix + c, iy + a), layer, 0).g;
        }
    }
    let count = u32((1 + fx) * (1 + fy));
    let d = (sum + count / 2u) / count;

    textureStore(out_heights, vec2<i32>(i, j), job.out_layer, vec4<f32>(h, 0.0, 0.0, 0.0));
    textureStore(out_grass, vec2<i32>(i, j), job.out_layer, vec4<u32>(picked.r, d, picked.b, 0u));
}
