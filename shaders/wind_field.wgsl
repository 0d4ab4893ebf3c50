// The wind field around the camera: an N x N grid of cells addressed toroidally (world cell
// (i, j) lives at index (i mod N, j mod N)), updated once a frame. Per cell: ambient wind from
// multi-octave value noise sampled through two cross-faded scrolling windows, plus
// source-driven wind that follows the summed sources (fast attack, slow release), plus the
// walker's trail (a push that fades). CPU mirror: src/wind/field_cpu.rs. Uniform values are
// prepared in f64 on the CPU (src/wind/config.rs).

#include "shared/hash.wgsl"

struct Source {
    // Metres from the origin cell's south-west corner.
    center: vec2<f32>,
    radius: f32,
    // 0 directional, 1 omni, 2 vortex
    kind: u32,
    // directional: wind vector; omni: (outward speed, 0); vortex: (tangential speed, inflow)
    a: vec2<f32>,
    b: vec2<f32>,
}

struct Params {
    origin_cell: vec2<i32>,
    n: u32,
    cell_m: f32,
    // xy: unit direction, z: mean speed, w: gustiness
    ambient: vec4<f32>,
    // x: weight of the new noise window, y: of the old one
    blend: vec4<f32>,
    // x: attack factor, y: release factor, z: trail fade factor, w: trail radius (m)
    decay: vec4<f32>,
    // the walker's step: xy start, zw end (metres from the origin cell's corner)
    trail: vec4<f32>,
    // xy: push direction on the step's axis, z: cross-wind fraction, w: gust gain
    extra: vec4<f32>,
    // x: sources in use, y: flags (1 trail on, 2 stamp), z: lattice period, w: seed
    counts: vec4<u32>,
    octave_freq: vec4<f32>,
    octave_amp: vec4<f32>,
    // per octave: xy new window, zw old window (lattice position of the origin cell's corner)
    windows: array<vec4<f32>, 4>,
    sources: array<Source, 8>,
}

struct CellState {
    source: vec2<f32>,
    tag: vec2<i32>,
}

const SOURCE_CORE: f32 = 0.05;
const FLAG_TRAIL: u32 = 1u;
const FLAG_STAMP: u32 = 2u;

// A read-only storage buffer, not a uniform: Mesa's lavapipe (22.x) inlines uniform values that
// steer branches and loops into a freshly compiled shader at every dispatch and never frees it
// (about 0.4-0.5 MB a dispatch for this shader). Same layout, same results.
@group(0) @binding(0) var<storage, read> params: Params;
@group(0) @binding(1) var<storage, read_write> state: array<CellState>;
@group(0) @binding(2) var<storage, read_write> cells: array<vec4<f32>>;

fn wrap(x: i32, p: i32) -> u32 {
    return u32(((x % p) + p) % p);
}

// Lattice values of both channels (gust, cross) at a lattice point of an octave.
fn lattice(ix: i32, iy: i32, octave: u32) -> vec2<f32> {
    let p = i32(params.counts.z);
    let h = hash_u32(wrap(ix, p) ^ hash_u32(wrap(iy, p) ^ hash_u32(octave ^ params.counts.w)));
    return vec2<f32>(unit(h), unit(hash_u32(h ^ 0x68e31da4u)));
}

fn lerp2(a: vec2<f32>, b: vec2<f32>, t: f32) -> vec2<f32> {
    return a + (b - a) * t;
}

// Value noise of both channels at lattice position q, quintic fade.
fn lattice_noise(q: vec2<f32>, octave: u32) -> vec2<f32> {
    let fl = floor(q);
    let f = q - fl;
    let ix = i32(fl.x);
    let iy = i32(fl.y);
    let ux = f.x * f.x * f.x * (f.x * (f.x * 6.0 - 15.0) + 10.0);
    let uy = f.y * f.y * f.y * (f.y * (f.y * 6.0 - 15.0) + 10.0);
    let v00 = lattice(ix, iy, octave);
    let v10 = lattice(ix + 1, iy, octave);
    let v01 = lattice(ix, iy + 1, octave);
    let v11 = lattice(ix + 1, iy + 1, octave);
    return lerp2(lerp2(v00, v10, ux), lerp2(v01, v11, ux), uy);
}

// Ambient wind (m/s) at d metres from the origin cell's south-west corner.
fn ambient_wind(d: vec2<f32>) -> vec2<f32> {
    let w_new = params.blend.x;
    let w_old = params.blend.y;
    var n = vec2<f32>(0.0, 0.0);
    for (var o = 0u; o < 4u; o++) {
        let q = d * params.octave_freq[o];
        var v = vec2<f32>(0.0, 0.0);
        if w_new > 0.0 {
            v += lattice_noise(params.windows[o].xy + q, o) * w_new;
        }
        if w_old > 0.0 {
            v += lattice_noise(params.windows[o].zw + q, o) * w_old;
        }
        n += v * params.octave_amp[o];
    }
    let gain = params.extra.w;
    let gust = clamp(n.x * gain, -1.0, 1.0);
    let cross = clamp(n.y * gain, -1.0, 1.0);
    let dir = params.ambient.xy;
    let speed = params.ambient.z;
    let along = speed * (1.0 + params.ambient.w * gust);
    let side = speed * params.extra.z * cross;
    return dir * along + vec2<f32>(-dir.y, dir.x) * side;
}

// Falloff of omni and vortex sources: (1 - d/r)^2, ramping up from 0 within the core.
fn falloff(dist: f32, radius: f32) -> f32 {
    if dist >= radius {
        return 0.0;
    }
    let x = 1.0 - dist / radius;
    let core = min(dist / (SOURCE_CORE * radius), 1.0);
    return x * x * core;
}

// Sum of the sources' wind (m/s) at d.
fn source_wind(d: vec2<f32>) -> vec2<f32> {
    var sum = vec2<f32>(0.0, 0.0);
    for (var k = 0u; k < params.counts.x; k++) {
        let s = params.sources[k];
        if s.kind == 0u {
            sum += s.a;
            continue;
        }
        let off = d - s.center;
        let dist = length(off);
        let f = falloff(dist, s.radius);
        if f <= 0.0 {
            continue;
        }
        let out = off / dist;
        if s.kind == 1u {
            sum += out * (s.a.x * f);
        } else {
            let tangent = vec2<f32>(-out.y, out.x);
            sum += (tangent * s.a.x - out * s.a.y) * f;
        }
    }
    return sum;
}

// The walker's push at d, given the cell's faded push p: the larger of the two.
fn stamp(d: vec2<f32>, p: vec2<f32>) -> vec2<f32> {
    let a = params.trail.xy;
    let ab = params.trail.zw - a;
    let len2 = dot(ab, ab);
    var t = 0.0;
    if len2 > 0.0 {
        t = clamp(dot(d - a, ab) / len2, 0.0, 1.0);
    }
    let off = d - (a + ab * t);
    let dist = length(off);
    let radius = params.decay.w;
    if dist >= radius {
        return p;
    }
    let u = dist / radius;
    let m = 1.0 - u * u * (3.0 - 2.0 * u);
    var dir = params.extra.xy;
    if dist > 1e-4 {
        dir = off / dist;
    }
    if m * m > dot(p, p) {
        return dir * m;
    }
    return p;
}

@compute @workgroup_size(8, 8, 1)
fn update_wind(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = params.n;
    if gid.x >= n || gid.y >= n {
        return;
    }
    let ni = i32(n);
    let half = ni / 2;
    // The world cell this storage cell holds now: the one in [origin - n/2, origin + n/2)
    // congruent to its index.
    let lo = params.origin_cell - vec2<i32>(half, half);
    let wx = lo.x + i32(wrap(i32(gid.x) - lo.x, ni));
    let wy = lo.y + i32(wrap(i32(gid.y) - lo.y, ni));
    let world = vec2<i32>(wx, wy);
    let rel = world - params.origin_cell;
    let d = (vec2<f32>(rel) + vec2<f32>(0.5, 0.5)) * params.cell_m;
    let index = gid.y * n + gid.x;

    let ambient = ambient_wind(d);
    let target_wind = source_wind(d);

    let prev = state[index];
    let fresh = any(prev.tag != world);
    var s = prev.source;
    var push = cells[index].zw;
    if fresh {
        // A cell that scrolled in starts settled on its sources, with no trail.
        s = target_wind;
        push = vec2<f32>(0.0, 0.0);
    }
    var k = params.decay.y;
    if dot(target_wind, target_wind) > dot(s, s) {
        k = params.decay.x;
    }
    s = target_wind + (s - target_wind) * k;

    let flags = params.counts.y;
    if (flags & FLAG_TRAIL) != 0u {
        push = push * params.decay.z;
        if (flags & FLAG_STAMP) != 0u {
            push = stamp(d, push);
        }
    } else {
        push = vec2<f32>(0.0, 0.0);
    }

    state[index] = CellState(s, world);
    cells[index] = vec4<f32>(ambient + s, push);
}
