// Derives child tiles from their parents in the tile atlas: Catmull-Rom upsampling of heights
// plus slope-scaled detail noise that fades to zero at tile edges; grass type from one of the
// nearest parent samples, density as their rounded mean. CPU mirror: src/stream/derive_child.rs.
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
    _pad: u32,
    // The child's identity in the atlas: [level, x, y, generation].
    identity: vec4<u32>,
    // What the parent's slot must hold; a parent slot holding anything else poisons the child.
    parent_identity: vec4<u32>,
}

struct Params {
    // x: tile cells, y: border, z: samples per side, w: seed
    grid: vec4<u32>,
    // x: detail amplitude, y: window cells
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

fn hash4(a: u32, b: u32, c: u32, d: u32) -> u32 {
    return hash_u32(a ^ hash_u32(b ^ hash_u32(c ^ hash_u32(d))));
}

fn unit(h: u32) -> f32 {
    return f32(h >> 8u) * (1.0 / 16777216.0) * 2.0 - 1.0;
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

    var rows: array<f32, 4>;
    for (var dy = 0; dy < 4; dy++) {
        let y = iy - 1 + dy;
        rows[dy] = ((wx.x * ph(ix - 1, y, layer) + wx.y * ph(ix, y, layer)) + wx.z * ph(ix + 1, y, layer))
            + wx.w * ph(ix + 2, y, layer);
    }
    var h = ((wy.x * rows[0] + wy.y * rows[1]) + wy.z * rows[2]) + wy.w * rows[3];

    let gx = (ph(ix + 1, iy, layer) - ph(ix - 1, iy, layer)) / (2.0 * job.cell_parent);
    let gy = (ph(ix, iy + 1, layer) - ph(ix, iy - 1, layer)) / (2.0 * job.cell_parent);
    let slope = min(sqrt(gx * gx + gy * gy), 1.5);

    let sx = i32(job.child_x) * n + i - b;
    let sy = i32(job.child_y) * n + j - b;
    // Euclidean remainder (the shader's % keeps the sign of the dividend).
    let mx = ((sx % n) + n) % n;
    let my = ((sy % n) + n) % n;
    let edge = f32(min(min(mx, n - mx), min(my, n - my)));
    let window = min(edge / params.detail.y, 1.0);
    let seed = params.grid.w;
    let noise = unit(hash4(u32(sx), u32(sy), job.child_level, seed));
    h += noise * (params.detail.x * job.cell_child * slope * window);

    let pick = hash4(u32(sx), u32(sy), job.child_level, seed ^ 0x9e3779b9u);
    let tx = ix + fx * i32(pick & 1u);
    let ty = iy + fy * i32((pick >> 1u) & 1u);
    let kind = textureLoad(parent_grass, clamp_texel(tx, ty), layer, 0).r;

    var sum = 0u;
    for (var a = 0; a <= fy; a++) {
        for (var c = 0; c <= fx; c++) {
            sum += textureLoad(parent_grass, clamp_texel(ix + c, iy + a), layer, 0).g;
        }
    }
    let count = u32((1 + fx) * (1 + fy));
    let d = (sum + count / 2u) / count;

    textureStore(out_heights, vec2<i32>(i, j), job.out_layer, vec4<f32>(h, 0.0, 0.0, 0.0));
    textureStore(out_grass, vec2<i32>(i, j), job.out_layer, vec4<u32>(kind, d, 0u, 0u));
}
