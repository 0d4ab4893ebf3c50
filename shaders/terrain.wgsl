// Terrain: one instanced draw of a regular grid per tile, heights fetched from the tile atlas.
// Positions are camera-relative: the CPU subtracts the camera position in f64 before anything
// reaches the GPU, so a world tens of kilometres wide does not jitter.

#include "shared/features.wgsl"
#include "shared/output.wgsl"

struct Frame {
    view_proj: mat4x4<f32>,
    inv_view_proj: mat4x4<f32>,
    // x: camera altitude (m), y: fog distance (m), z: skirt depth factor, w: unused
    camera: vec4<f32>,
    sun_dir: vec4<f32>,
    sun_color: vec4<f32>,
    sky_color: vec4<f32>,
    horizon_color: vec4<f32>,
    // x: tile cells, y: border samples, z: grass type count, w: feature bits (src/features.rs)
    grid: vec4<u32>,
    ground_colors: array<vec4<f32>, 16>,
    // The viewer's overlay: x: on (1) or off (0), y and z: radii of the high and low grass
    // rings (m), w: the grid cell of a level-0 tile's draw (m), from which a tile's level follows.
    overlay: vec4<f32>,
}

struct TileDraw {
    // Position of the drawn area's south-west corner relative to the camera, metres.
    origin: vec2<f32>,
    // Metres between grid vertices.
    cell_size: f32,
    // Atlas slot the heights come from.
    layer: u32,
    // Atlas texel of the drawn area's south-west corner (fractional when an ancestor stands in
    // for a tile that is not resident yet).
    tex_origin: vec2<f32>,
    // Atlas texels per grid cell: 1 for a tile's own data, 1/2^k for an ancestor k levels up.
    tex_step: f32,
    // Distance at which CDLOD morphing toward the next coarser grid starts (it ends at
    // 1.25 times this, where a coarser neighbour can begin).
    morph_start: f32,
}

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> tiles: array<TileDraw>;
@group(0) @binding(2) var heights: texture_2d_array<f32>;
@group(0) @binding(3) var grass: texture_2d_array<u32>;

struct VertexOut {
    // Invariant: the depth pre-pass and the colour pass must produce the same depths.
    @builtin(position) @invariant clip: vec4<f32>,
    @location(0) rel_pos: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) albedo: vec3<f32>,
    // The drawn tile's level (for the overlay).
    @location(3) @interpolate(flat) level: f32,
}

fn texel(t: vec2<i32>, layer: u32) -> f32 {
    let size = vec2<i32>(textureDimensions(heights));
    return textureLoad(heights, clamp(t, vec2<i32>(0), size - 1), layer, 0).r;
}

// Bilinear height at a fractional texel position (exact at whole texels).
fn height_at(p: vec2<f32>, layer: u32) -> f32 {
    let i = vec2<i32>(floor(p));
    let f = p - floor(p);
    let a = mix(texel(i, layer), texel(i + vec2<i32>(1, 0), layer), f.x);
    let b = mix(texel(i + vec2<i32>(0, 1), layer), texel(i + vec2<i32>(1, 1), layer), f.x);
    return mix(a, b, f.y);
}

@vertex
fn vs_terrain(@builtin(vertex_index) vi: u32, @builtin(instance_index) ii: u32) -> VertexOut {
    let tile = tiles[ii];
    let n = i32(frame.grid.x);
    // The grid has one extra ring of vertices on each side: the skirt, hanging below the edge
    // so that a coarser neighbour never shows a crack.
    let row = u32(n + 3);
    let g = vec2<i32>(i32(vi % row) - 1, i32(vi / row) - 1);
    let c = clamp(g, vec2<i32>(0), vec2<i32>(n));
    let skirt = any(g != c);

    // CDLOD: odd vertices slide onto the line between their even neighbours as the camera
    // recedes, so the grid has become the next coarser level's by the time one borders it.
    let flat_pos = tile.origin + vec2<f32>(c) * tile.cell_size;
    let h0 = height_at(tile.tex_origin + vec2<f32>(c) * tile.tex_step, tile.layer);
    let dist = length(vec3<f32>(flat_pos, h0 - frame.camera.x));
    let morph = clamp((dist - tile.morph_start) / (0.25 * tile.morph_start), 0.0, 1.0);
    let odd = vec2<f32>(c % vec2<i32>(2));
    let gm = vec2<f32>(c) - odd * morph;

    let tp = tile.tex_origin + gm * tile.tex_step;
    let h = height_at(tp, tile.layer);
    // Central differences one texel apart; the border samples make this seamless across tiles.
    let texel_m = tile.cell_size / tile.tex_step;
    let hl = height_at(tp - vec2<f32>(1.0, 0.0), tile.layer);
    let hr = height_at(tp + vec2<f32>(1.0, 0.0), tile.layer);
    let hd = height_at(tp - vec2<f32>(0.0, 1.0), tile.layer);
    let hu = height_at(tp + vec2<f32>(0.0, 1.0), tile.layer);
    let normal = normalize(vec3<f32>(hl - hr, hd - hu, 2.0 * texel_m));

    var z = h;
    if skirt {
        z -= frame.camera.z * texel_m;
    }
    let rel = vec3<f32>(tile.origin + gm * tile.cell_size, z - frame.camera.x);

    let gt = textureLoad(grass, vec2<i32>(round(tp)), tile.layer, 0);
    let kind = min(gt.r, frame.grid.z - 1u);
    let d = f32(gt.g) / 255.0;
    let rock = vec3<f32>(0.30, 0.28, 0.26);
    let soil = vec3<f32>(0.33, 0.27, 0.19);
    let grass_color = frame.ground_colors[kind].rgb;
    var albedo = mix(soil, grass_color, d);
    if kind == 0u {
        albedo = rock;
    } else if (frame.grid.w & GROUND_DARKENING) != 0u {
        // Ground darkening: dense grass shades the soil under it.
        albedo *= mix(1.0, 0.6, d);
    }

    var out: VertexOut;
    out.clip = frame.view_proj * vec4<f32>(rel, 1.0);
    out.rel_pos = rel;
    out.normal = normal;
    out.albedo = albedo;
    out.level = round(log2(frame.overlay.w / tile.cell_size));
    return out;
}

fn fog_color(view_dir: vec3<f32>) -> vec3<f32> {
    let sun_amount = pow(max(dot(view_dir, frame.sun_dir.xyz), 0.0), 8.0);
    return mix(frame.horizon_color.rgb, frame.sun_color.rgb, 0.35 * sun_amount);
}

@fragment
fn fs_terrain(in: VertexOut) -> @location(0) vec4<f32> {
    let n = normalize(in.normal);
    let sun = frame.sun_dir.xyz;
    let lambert = max(dot(n, sun), 0.0);
    // Hemisphere ambient: sky from above, warm bounce from the ground below.
    let bounce = vec3<f32>(0.20, 0.17, 0.12);
    let ambient = mix(bounce, frame.sky_color.rgb, 0.5 + 0.5 * n.z);
    let lit = in.albedo * (frame.sun_color.rgb * lambert + 0.45 * ambient);

    let dist = length(in.rel_pos);
    // Clear near the camera, 95% fog at the manifest's fog distance.
    let x = dist / frame.camera.y;
    let fog = 1.0 - exp(-3.0 * x * x);
    var color = mix(lit, fog_color(in.rel_pos / max(dist, 1e-3)), fog);
    if frame.overlay.x > 0.5 {
        color = with_overlay(color, in);
    }
    return output_color(color);
}

// Tile levels as hues, and the grass rings as lines around the camera.
fn with_overlay(color: vec3<f32>, in: VertexOut) -> vec3<f32> {
    let hues = array<vec3<f32>, 6>(
        vec3<f32>(0.9, 0.2, 0.2),
        vec3<f32>(0.9, 0.6, 0.1),
        vec3<f32>(0.8, 0.9, 0.1),
        vec3<f32>(0.2, 0.8, 0.3),
        vec3<f32>(0.2, 0.6, 0.9),
        vec3<f32>(0.6, 0.3, 0.9),
    );
    let level = u32(max(in.level, 0.0)) % 6u;
    var c = mix(color, hues[level], 0.35);
    let r = length(in.rel_pos.xy);
    let width = 0.3 + 0.004 * length(in.rel_pos);
    for (var k = 0; k < 2; k++) {
        let radius = select(frame.overlay.z, frame.overlay.y, k == 0);
        if radius > 0.0 && abs(r - radius) < width {
            c = select(vec3<f32>(0.1, 0.3, 1.0), vec3<f32>(1.0, 1.0, 1.0), k == 0);
        }
    }
    return c;
}

// Sky: drawn after the terrain, only where the depth buffer still holds the far plane.
struct SkyOut {
    @builtin(position) @invariant clip: vec4<f32>,
    @location(0) ndc: vec2<f32>,
}

@vertex
fn vs_sky(@builtin(vertex_index) vi: u32) -> SkyOut {
    let uv = vec2<f32>(f32((vi << 1u) & 2u), f32(vi & 2u));
    let ndc = uv * 2.0 - 1.0;
    var out: SkyOut;
    // Reverse-Z: depth 0 is infinitely far.
    out.clip = vec4<f32>(ndc, 0.0, 1.0);
    out.ndc = ndc;
    return out;
}

@fragment
fn fs_sky(in: SkyOut) -> @location(0) vec4<f32> {
    let p = frame.inv_view_proj * vec4<f32>(in.ndc, 0.5, 1.0);
    let dir = normalize(p.xyz / p.w);
    let up = clamp(dir.z, 0.0, 1.0);
    var color = mix(fog_color(dir), frame.sky_color.rgb, pow(up, 0.6));
    let sun = dot(dir, frame.sun_dir.xyz);
    color += frame.sun_color.rgb * smoothstep(0.9995, 0.9999, sun);
    return output_color(color);
}
