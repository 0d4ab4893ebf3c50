// Plants from the instance pool: one indexed indirect draw per (type, level of detail), the
// vertices read from the plant meshes' storage buffer by index, the instance from the region's
// slice of the pool (src/plants/place_cpu.rs has the records).
//
// Bending (Crysis, GPU Gems 3 ch. 16; God of War's parameters): detail bending first, in the
// plant's own space: leaves and branches swing along the vertical by their vertex colour's b
// (freedom) and their edges flutter along the normal by its r, from smoothed triangle waves at
// four frequencies phased by the leaf (g) and the plant, as strong as the wind felt or, when it
// has dropped, as the wind the sway spring still remembers (leaf lag); then main bending leans the whole
// plant by its type's sway spring in the wind cell at its root (God of War's sway spring and
// damping: the spring's state, advanced each frame by shaders/wind_sway.wgsl toward the lean
// the wind asks for, overshoots and swings back after a gust) and its trail's push, the offset
// growing with height as Crysis' bend factor, and the bent position pulled back to its length
// (the type's stretch). CPU mirror
// of the bending: src/plants/bend_cpu.rs (a test runs `probe_bend` below against it).
//
// Shading: two-sided (the back face's normal flipped), sun and sky light, light through thin
// leaves and petals (albedo alpha), ambient occlusion from the vertex colour's a, world-space
// colour variation per plant, alpha-tested cards, and a dither that cross-fades two levels of
// detail. The full meshes are lit per pixel (vs_plant, fs_plant); the reduced meshes and the
// cards, a few pixels each, per vertex (vs_plant_far, fs_plant_far), which on the H100 costs
// less: the rasteriser's share of the draw follows what each vertex hands on.

#include "shared/hash.wgsl"
#include "shared/features.wgsl"
#include "shared/output.wgsl"
#include "shared/wind_lookup.wgsl"
#include "shared/waves.wgsl"
#include "shared/sway_lookup.wgsl"
#include "shared/plant_instance.wgsl"

// Multisampled targets: the cards' alpha becomes coverage instead of a hard test.
override COVERAGE: bool = false;

struct PlantWind {
    // x: movement scale, y: bend (plant heights per m/s), z: stretch, w: main amplitude
    main: vec4<f32>,
    // x: detail amplitude, y: stiffness, zw: unused (the sway spring is wind_sway.wgsl's)
    detail: vec4<f32>,
}

struct PlantFrame {
    view_proj: mat4x4<f32>,
    // x: fog distance; y: time (s); zw: the camera's world xy modulo 4096 m
    misc: vec4<f32>,
    sun_dir: vec4<f32>,
    sun_color: vec4<f32>,
    sky_color: vec4<f32>,
    horizon_color: vec4<f32>,
    // x: feature bits, y: 1 where the cards are billboards (the trees' layer), z: 1 when drawing
    // a shadow map (billboards turned to the sun; view_proj is a cascade's)
    flags: vec4<u32>,
    wind: array<PlantWind, 8>,
    // Per type: x the texture layer of its meshes, y of its card, z its index among the
    // world's plant types (its sway spring's slot)
    layers: array<vec4<u32>, 8>,
}

struct PlantVertex {
    position: vec3<f32>,
    normal: vec3<f32>,
    // r: edge flutter, g: leaf phase, b: leaf/branch freedom, a: ambient occlusion
    wind: vec4<f32>,
    // rgb: albedo, a: thinness
    albedo: vec4<f32>,
    uv: vec2<f32>,
}

// Vertex `i` of the meshes: 16 packed floats (WGSL would pad a struct of vec3s).
fn load_vertex(i: u32) -> PlantVertex {
    let b = i * 16u;
    var v: PlantVertex;
    v.position = vec3<f32>(vertices[b], vertices[b + 1u], vertices[b + 2u]);
    v.normal = vec3<f32>(vertices[b + 3u], vertices[b + 4u], vertices[b + 5u]);
    v.wind = vec4<f32>(vertices[b + 6u], vertices[b + 7u], vertices[b + 8u], vertices[b + 9u]);
    v.albedo = vec4<f32>(vertices[b + 10u], vertices[b + 11u], vertices[b + 12u], vertices[b + 13u]);
    v.uv = vec2<f32>(vertices[b + 14u], vertices[b + 15u]);
    return v;
}

@group(0) @binding(0) var<uniform> frame: PlantFrame;
@group(0) @binding(1) var<storage, read> vertices: array<f32>;
@group(0) @binding(2) var<uniform> wind_lookup: WindLookup;
@group(0) @binding(3) var<storage, read> wind_cells: array<vec4<f32>>;
@group(0) @binding(4) var plant_textures: texture_2d_array<f32>;
@group(0) @binding(5) var plant_sampler: sampler;
// The same frame record read as a storage buffer, for the feature bits that branches test:
// lavapipe (Mesa 22.3) compiles a variant of a shader specialised on the values of the uniforms
// its branches test at every draw, and keeps each until the pipeline goes, so the process grew
// every frame; storage buffers are never specialised. The rest stays a uniform (the constant
// cache on GPUs). The README's Plants section has the figures.
@group(0) @binding(6) var<storage, read> frame_bits: PlantFrame;
// The sway springs' state (src/wind/sway.rs): per wind cell, the grass's slots then the plant
// types'.
@group(0) @binding(7) var<storage, read> sway: array<vec4<f32>>;
// A (type, level) region of the pool, chosen by a dynamic offset.
@group(1) @binding(0) var<storage, read> instances: array<PlantInstance>;

// Lean of a plant on the axis of a fresh trail, plant heights.
const TRAIL_LEAN: f32 = 0.9;


struct Bent {
    position: vec3<f32>,
    normal: vec3<f32>,
}

// Vertex `v` of an instance at `root` (relative to the camera), turned by `yaw`, of height
// `scale`, phase `phase` (0..1), in the wind `w` (wind_at at its root: xy m/s, zw the trail's
// push), leaning `sway_lean` (its type's sway spring at its root, plant heights), at `time`,
// with the type's wind `pw` and the frame's feature bits: its position relative to the camera
// and its normal. As bend_vertex in src/plants/bend_cpu.rs.
fn bend(v: PlantVertex, root: vec3<f32>, yaw: f32, scale: f32, phase: f32, w: vec4<f32>, sway_lean: vec2<f32>, time: f32, pw: PlantWind, flags: u32) -> Bent {
    let c = cos(yaw);
    let s = sin(yaw);
    var p = vec3<f32>(c * v.position.x - s * v.position.y, s * v.position.x + c * v.position.y, v.position.z) * scale;
    let n = vec3<f32>(c * v.normal.x - s * v.normal.y, s * v.normal.x + c * v.normal.y, v.normal.z);
    let give = 1.0 - 0.6 * pw.detail.y;
    // Leaf lag (God of War): the leaves answer the wind at once and keep moving after it drops,
    // for as long as the type's sway spring still leans: the spring's lean over the lean per
    // felt m/s is the wind the plant remembers, decaying with the spring's damping.
    let felt = length(w.xy * pw.main.x);
    let per_felt = pw.main.y * give * pw.main.w;
    var remembered = 0.0;
    if per_felt > 1e-6 {
        remembered = length(sway_lean) / per_felt;
    }
    let speed = max(felt, remembered);
    if has_feature(flags, DETAIL_BENDING) {
        // Crysis' detail bending: waves at four frequencies, phased per leaf and per plant.
        let branch_phase = v.wind.g + phase;
        let vtx_phase = dot(v.position, vec3<f32>(branch_phase));
        let waves_in = vec2<f32>(time + vtx_phase, time + branch_phase);
        let freq = vec4<f32>(1.975, 0.793, 0.375, 0.193) * (1.0 + pw.detail.y);
        let waves = vec4<f32>(
            smooth_triangle(waves_in.x * freq.x),
            smooth_triangle(waves_in.x * freq.y),
            smooth_triangle(waves_in.y * freq.z),
            smooth_triangle(waves_in.y * freq.w),
        ) * 2.0 - 1.0;
        let sum = waves.xz + waves.yw;
        let amount = min(speed / 5.0, 1.5) * pw.detail.x * give * scale;
        p += vec3<f32>(n.xy * (v.wind.r * 0.04 * sum.x), v.wind.b * 0.05 * sum.y) * amount;
    }
    // Main bending: the lean of the type's sway spring, the trail's push.
    var lean = sway_lean;
    if has_feature(flags, INTERACTION) {
        lean += w.zw * TRAIL_LEAN;
    }
    let len = length(p);
    // Crysis' bend factor of the height, scaled to 1 at the plant's top: the lean is in plant
    // heights there.
    var bf = p.z / max(scale, 1e-4) + 1.0;
    bf = bf * bf;
    bf = (bf * bf - bf) / 12.0;
    var q = p;
    q.x += lean.x * bf * scale;
    q.y += lean.y * bf * scale;
    let kept = normalize(q + vec3<f32>(0.0, 0.0, 1e-6)) * len;
    q = mix(q, kept, pw.main.z);
    // The normal follows the lean roughly: tilted by the bend at the top.
    let tilt = vec3<f32>(lean * bf, 0.0);
    let n2 = normalize(n - tilt * n.z);
    var out: Bent;
    out.position = root + q;
    out.normal = n2;
    return out;
}

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) rel_pos: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) albedo: vec4<f32>,
    @location(3) uv: vec2<f32>,
    // x: ambient occlusion, y: the cross-fade's fade
    @location(4) misc: vec2<f32>,
    @location(5) @interpolate(flat) layer: u32,
}

// Vertex `vi` of instance `ii`, bent, with what its shading needs.
fn plant_vertex(vi: u32, ii: u32) -> VertexOut {
    let inst = instances[ii];
    let v = load_vertex(vi);
    let t = inst.kind & 255u;
    let level = inst.kind >> 8u;
    var yaw = inst.yaw;
    var out: VertexOut;
    if level == 2u && frame.flags.y != 0u {
        // Billboards (the trees' cards): the first quad turned to face the camera, the second
        // dropped (its triangles collapse to a point and are culled): half the triangles and
        // none of the crossed quads' overdraw of each other.
        if v.normal.x > 0.5 {
            out.clip = vec4<f32>(0.0);
            return out;
        }
        // Toward the camera, or in a shadow map toward the sun (its silhouette is the shadow).
        let to_eye = select(-inst.pos.xy, frame.sun_dir.xy, frame.flags.z != 0u);
        if dot(to_eye, to_eye) > 1e-6 {
            let d = normalize(to_eye);
            yaw = atan2(d.x, -d.y);
        }
    }
    let phase = rand01(inst.hash);
    let w = wind_at(inst.pos.xy);
    let sway_lean = sway_at(inst.pos.xy, PLANT_SWAY_SLOT + frame.layers[t].z);
    let b = bend(v, inst.pos, yaw, inst.scale, phase, w, sway_lean, frame.misc.y, frame.wind[t], frame_bits.flags.x);
    var albedo = v.albedo;
    if has_feature(frame_bits.flags.x, COLOR_VARIATION) {
        // Per plant, from the noise of its root's world cell and its hash.
        let world = frame.misc.zw + inst.pos.xy;
        let cell = vec2<i32>(floor(world / 5.0));
        let nz = rand01(hash2(cell.x, cell.y));
        let own = rand01(hash_u32(inst.hash ^ 77u));
        albedo = vec4<f32>(albedo.rgb * (0.82 + 0.22 * nz + 0.14 * own), albedo.a);
    }
    out.clip = frame.view_proj * vec4<f32>(b.position, 1.0);
    out.rel_pos = b.position;
    out.normal = b.normal;
    out.albedo = albedo;
    out.uv = v.uv;
    out.misc = vec2<f32>(v.wind.a, inst.fade);
    out.layer = select(frame.layers[t].x, frame.layers[t].y, level == 2u);
    return out;
}

@vertex
fn vs_plant(@builtin(vertex_index) vi: u32, @builtin(instance_index) ii: u32) -> VertexOut {
    return plant_vertex(vi, ii);
}

// A 4x4 ordered dither in 0..1: Bayer's matrix (0 8 2 10 / 12 4 14 6 / 3 11 1 9 / 15 7 13 5),
// its entry the bits of x ^ y and y interleaved and reversed, computed rather than looked up in
// a table (which would be indexed per pixel from memory).
fn dither(p: vec2<f32>) -> f32 {
    let x = u32(p.x) & 3u;
    let y = u32(p.y) & 3u;
    let a = x ^ y;
    let bayer = ((a & 1u) << 3u) | ((y & 1u) << 2u) | (a & 2u) | ((y & 2u) >> 1u);
    return (f32(bayer) + 0.5) / 16.0;
}

// Whether a pixel at `p` of a plant cross-faded by `fade` is drawn (as keeps_pixel in
// src/plants/place_cpu.rs).
fn keeps_pixel(fade: f32, p: vec2<f32>) -> bool {
    if fade >= 1.0 {
        return true;
    }
    let d = dither(p);
    return (fade >= 0.0 && d < fade) || (fade < 0.0 && d >= -fade);
}

// Sun and sky light on a plant's surface of `albedo` and thinness `thin` with the normal `n`
// (facing the viewer), ambient occlusion `ao`, at `rel_pos` from the camera: linear, before
// the fog and the texture.
fn shade(albedo: vec3<f32>, thin: f32, n: vec3<f32>, ao_in: f32, rel_pos: vec3<f32>) -> vec3<f32> {
    let sun = frame.sun_dir.xyz;
    let to_eye = -normalize(rel_pos);
    var light = frame.sun_color.rgb * max(dot(n, sun), 0.0);
    if has_feature(frame_bits.flags.x, TRANSLUCENCY) {
        // Light through the leaf from behind, stronger looking toward the sun; thin parts more.
        let back = max(dot(-n, sun), 0.0);
        let toward_sun = pow(max(dot(-to_eye, sun), 0.0), 4.0);
        light += frame.sun_color.rgb * back * thin * (0.3 + 0.7 * toward_sun) * vec3<f32>(1.0, 0.95, 0.6);
    }
    var ao = 1.0;
    if has_feature(frame_bits.flags.x, AMBIENT_OCCLUSION) {
        ao = ao_in;
    }
    let ambient = frame.sky_color.rgb * (0.35 + 0.25 * n.z) * ao;
    return albedo * (light * mix(0.6, 1.0, ao) + ambient);
}

// The fog's share of a colour at `rel_pos` from the camera.
fn fog_at(rel_pos: vec3<f32>) -> f32 {
    let x = length(rel_pos) / frame.misc.x;
    return 1.0 - exp(-3.0 * x * x);
}

// The texture at `uv` of `layer` for a pixel at `pixel` of a plant cross-faded by `fade`;
// the pixel is discarded where the cross-fade or (without coverage) the alpha test leaves it out.
fn cut_out(uv: vec2<f32>, layer: u32, fade: f32, pixel: vec2<f32>) -> vec4<f32> {
    if !keeps_pixel(fade, pixel) {
        discard;
    }
    let tex = textureSample(plant_textures, plant_sampler, uv, layer);
    if !COVERAGE && tex.a < 0.5 {
        discard;
    }
    return tex;
}

// The pixel's colour: `lit` with the fog's share `fog`, and `alpha` as coverage when
// multisampled.
fn finish(lit: vec3<f32>, fog: f32, alpha: f32) -> vec4<f32> {
    var color = output_color(mix(lit, frame.horizon_color.rgb, fog));
    if COVERAGE {
        color.a = alpha;
    }
    return color;
}

@fragment
fn fs_plant(in: VertexOut, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    let tex = cut_out(in.uv, in.layer, in.misc.y, in.clip.xy);
    var n = normalize(in.normal);
    if !front {
        n = -n;
    }
    let lit = shade(in.albedo.rgb * tex.rgb, in.albedo.a, n, in.misc.x, in.rel_pos);
    return finish(lit, fog_at(in.rel_pos), tex.a);
}

// The reduced meshes and the cards, a few pixels each: lit per vertex (two-sided by the side
// the camera sees), so that a vertex hands the rasteriser a colour, not the shading's inputs.
struct FarOut {
    @builtin(position) clip: vec4<f32>,
    // Lit, linear, before the texture and the fog
    @location(0) color: vec3<f32>,
    @location(1) uv: vec2<f32>,
    // x: the cross-fade's fade, y: the fog's share
    @location(2) misc: vec2<f32>,
    @location(3) @interpolate(flat) layer: u32,
}

@vertex
fn vs_plant_far(@builtin(vertex_index) vi: u32, @builtin(instance_index) ii: u32) -> FarOut {
    let v = plant_vertex(vi, ii);
    var n = v.normal;
    if dot(n, v.rel_pos) > 0.0 {
        n = -n;
    }
    var out: FarOut;
    out.clip = v.clip;
    out.color = shade(v.albedo.rgb, v.albedo.a, n, v.misc.x, v.rel_pos);
    out.uv = v.uv;
    out.misc = vec2<f32>(v.misc.y, fog_at(v.rel_pos));
    out.layer = v.layer;
    return out;
}

@fragment
fn fs_plant_far(in: FarOut) -> @location(0) vec4<f32> {
    let tex = cut_out(in.uv, in.layer, in.misc.x, in.clip.xy);
    return finish(in.color * tex.rgb, in.misc.y, tex.a);
}

// The trees' depth in a shadow map's cascade (src/plants/shadow.rs): the same bent vertices,
// the same cut-out and cross-fade, no colour.
struct ShadowOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
    @location(1) fade: f32,
    @location(2) @interpolate(flat) layer: u32,
}

@vertex
fn vs_plant_shadow(@builtin(vertex_index) vi: u32, @builtin(instance_index) ii: u32) -> ShadowOut {
    let v = plant_vertex(vi, ii);
    var out: ShadowOut;
    out.clip = v.clip;
    out.uv = v.uv;
    out.fade = v.misc.y;
    out.layer = v.layer;
    return out;
}

@fragment
fn fs_plant_shadow(in: ShadowOut) {
    _ = cut_out(in.uv, in.layer, in.fade, in.clip.xy);
}

// The bending of test vertices, for the comparison with the CPU mirror: probe i bends vertex i
// of `vertices` as instance i in the wind i.
@group(1) @binding(1) var<storage, read> probe_instances: array<PlantInstance>;
@group(1) @binding(2) var<storage, read> probe_winds: array<vec4<f32>>;
@group(1) @binding(3) var<storage, read_write> probe_out: array<vec4<f32>>;
@group(1) @binding(4) var<storage, read> probe_leans: array<vec2<f32>>;

@compute @workgroup_size(64, 1, 1)
fn probe_bend(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= arrayLength(&probe_instances) {
        return;
    }
    let inst = probe_instances[gid.x];
    let t = inst.kind & 255u;
    let b = bend(load_vertex(gid.x), inst.pos, inst.yaw, inst.scale, rand01(inst.hash), probe_winds[gid.x], probe_leans[gid.x], frame.misc.y, frame.wind[t], frame_bits.flags.x);
    probe_out[gid.x * 2u] = vec4<f32>(b.position, 0.0);
    probe_out[gid.x * 2u + 1u] = vec4<f32>(b.normal, 0.0);
}
