// The terrain's shading, shared by the G-buffer pass (shaders/terrain_gbuffer.wgsl, which
// needs the frame and the heights) and the shading pass (shaders/terrain_shade.wgsl, which does
// all the per-pixel work): the frame's uniforms, the atlas, and every function of the terrain's
// and the sky's colour. CPU mirror of the far field: src/terrain/far_field.rs.

#include "shared/features.wgsl"
#include "shared/hash.wgsl"

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
    // The camera's world position, metres (x, y, z), in f32: exact to millimetres across a
    // world tens of kilometres wide, enough for shadow rays and noise; w: unused.
    camera_world: vec4<f32>,
    // x, y: the camera's world xy modulo 4096 m (the world-space colour noise of the grass's wind
    // pass); z: the start and w: the end of grass's dithered fade at its view distance (m), both
    // 0 without grass (the far-field shading is then everywhere).
    grass_view: vec4<f32>,
    // x, y: the camera's clump cell (floor of its xy over the clump cell), as i32 bits; z: the
    // grass seed; w: the clump cell (m) as f32 bits.
    clump: vec4<u32>,
    // x, y: the camera's xy minus its clump cell's south-west corner (m); z: 1 where the far
    // field lies under the blades too, 0 where only past their fade; w: metres toward the
    // grass's fade per metre the camera stands above (far_distance in
    // src/terrain/far_field.rs).
    clump_offset: vec4<f32>,
    // Per grass type: rgb the colour of blade base and tip, w of base: the growth blend.
    base_colors: array<vec4<f32>, 16>,
    tip_colors: array<vec4<f32>, 16>,
    // Level-0 tiles: x, y the root tile grid, z the cell size (m) as f32 bits, w: 1 when the
    // slots below hold every root tile (worlds of at most 64), else 0.
    roots: vec4<u32>,
    // Atlas slot of root tile (x, y) at index y * roots.x + x, four to a vector.
    root_slots: array<vec4<u32>, 16>,
    // Per band of altitude, per grass type, four to a vector ([band * 4 + kind / 4]): the depth
    // of the trees' canopy shade at full grass density (src/plants/shadow.rs, canopy_depth).
    tree_canopy: array<vec4<f32>, 32>,
    // x, y: where the canopy's shade fades in (the trees' shadow map fades out), m; z: 1 when
    // the world has tree shadows.
    tree_canopy_fade: vec4<f32>,
    // The altitude bands' edges, m, rising (unused ones huge): band i lies between edges i - 1
    // and i.
    tree_canopy_edges: array<vec4<f32>, 2>,
}

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(2) var heights: texture_2d_array<f32>;
@group(0) @binding(3) var grass: texture_2d_array<u32>;

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

fn fog_color(view_dir: vec3<f32>) -> vec3<f32> {
    let sun_amount = pow(max(dot(view_dir, frame.sun_dir.xyz), 0.0), 8.0);
    return mix(frame.horizon_color.rgb, frame.sun_color.rgb, 0.35 * sun_amount);
}

// ---- Terrain shading, per pixel (CPU mirror of the far field: src/terrain/far_field.rs) ----

// Rock and soil (CPU mirror: src/terrain/material.rs).
const ROCK: vec3<f32> = vec3<f32>(0.25, 0.23, 0.20);
// How much of the clump's tint the ground under grass takes.
const GROUND_TINT: f32 = 0.8;
const SOIL: vec3<f32> = vec3<f32>(0.33, 0.27, 0.19);

// Value noise in 0..1 (x) and its gradient (yz), per unit of p.
fn noise_grad(p: vec2<f32>) -> vec3<f32> {
    let fl = floor(p);
    let i = vec2<i32>(fl);
    let f = p - fl;
    let u = f * f * (3.0 - 2.0 * f);
    let du = 6.0 * f * (1.0 - f);
    let a = f32(hash2(i.x, i.y) >> 8u) / 16777216.0;
    let b = f32(hash2(i.x + 1, i.y) >> 8u) / 16777216.0;
    let c = f32(hash2(i.x, i.y + 1) >> 8u) / 16777216.0;
    let d = f32(hash2(i.x + 1, i.y + 1) >> 8u) / 16777216.0;
    let k = a - b - c + d;
    let v = a + (b - a) * u.x + (c - a) * u.y + k * u.x * u.y;
    return vec3<f32>(v, du.x * ((b - a) + k * u.y), du.y * ((c - a) + k * u.x));
}

// Value noise in 0..1 (noise_grad's value): the noise of the wind pass's colour variation
// (value_noise in shaders/grass_wind.wgsl), with its terms summed in another order.
fn noise_value(p: vec2<f32>) -> f32 {
    return noise_grad(p).x;
}

// A sample's grass type (x), density (y) and terrain material (z).
fn grass_texel(t: vec2<i32>, layer: u32) -> vec3<u32> {
    let size = vec2<i32>(textureDimensions(grass));
    return textureLoad(grass, clamp(t, vec2<i32>(0), size - 1), layer, 0).rgb;
}

// ---- Terrain materials (src/world/material.rs; CPU mirror: src/terrain/material.rs) ----

const MATERIAL_SOIL: u32 = 1u;
const MATERIAL_CROPS: u32 = 2u;
const MATERIAL_ROCK: u32 = 3u;
const MATERIAL_SAND: u32 = 4u;
const MATERIAL_WATER: u32 = 5u;
const MATERIAL_ROAD: u32 = 6u;
const MATERIAL_SNOW: u32 = 7u;
const CROP_SOIL: vec3<f32> = vec3<f32>(0.30, 0.23, 0.15);
const SAND: vec3<f32> = vec3<f32>(0.55, 0.47, 0.33);
const ROAD: vec3<f32> = vec3<f32>(0.11, 0.11, 0.115);
const SNOW: vec3<f32> = vec3<f32>(0.82, 0.86, 0.92);
// The bed seen through water, and how much of the light it sends back up.
const WATER_BODY: vec3<f32> = vec3<f32>(0.015, 0.035, 0.04);
const WATER_F0: f32 = 0.02;
// Furrow spacing of crops, metres (rows run north-south).
const CROP_ROW_M: f32 = 1.2;

// The albedo of material `m` (not the default, not water) at world xy, for a pixel footprint
// of `footprint` metres along the ground (stretched by the grazing view): crops' furrows fade
// out before they shrink below two pixels.
fn material_albedo(m: u32, world: vec2<f32>, footprint: f32) -> vec3<f32> {
    switch m {
        case MATERIAL_SOIL: {
            return SOIL;
        }
        case MATERIAL_CROPS: {
            let vis = clamp(CROP_ROW_M / (2.0 * footprint) - 1.0, 0.0, 1.0);
            let row = 0.5 + 0.5 * cos(6.2831853 * world.x / CROP_ROW_M);
            return CROP_SOIL * (1.0 + 0.35 * vis * (row - 0.5));
        }
        case MATERIAL_ROCK: {
            return ROCK;
        }
        case MATERIAL_SAND: {
            return SAND;
        }
        case MATERIAL_ROAD: {
            return ROAD;
        }
        case MATERIAL_SNOW: {
            return SNOW;
        }
        default: {
            return SOIL;
        }
    }
}

// Water seen along the unit direction `v` (from the camera), a flat surface: the sky mirrored
// by Schlick's Fresnel term (0.02 head-on), over a dark body lit by the sun (the fraction
// `sun_vis` of it) and the sky dome.
fn water_color(v: vec3<f32>, sun_vis: f32) -> vec3<f32> {
    let cos_v = clamp(-v.z, 0.0, 1.0);
    let fresnel = WATER_F0 + (1.0 - WATER_F0) * pow(1.0 - cos_v, 5.0);
    let mirrored = vec3<f32>(v.xy, abs(v.z));
    let dome = mix(frame.sky_color.rgb, frame.horizon_color.rgb, 0.5);
    let body = WATER_BODY * (frame.sun_color.rgb * max(frame.sun_dir.z, 0.0) * sun_vis + 0.45 * dome);
    return mix(body, sky_color(mirrored), fresnel);
}

// The tint of the Voronoi clump around `rel_xy` (metres from the camera): the nearest of the
// jittered clump centres of the 3x3 cells around, as shaders/grass_generate.wgsl picks it for
// each blade, and its tint (mean 1).
fn clump_tint(rel_xy: vec2<f32>) -> vec3<f32> {
    let clump_m = bitcast<f32>(frame.clump.w);
    let local = rel_xy + frame.clump_offset.xy;
    let c = vec2<i32>(floor(local / clump_m));
    let base = vec2<i32>(bitcast<i32>(frame.clump.x), bitcast<i32>(frame.clump.y));
    var best = 3.4028235e38;
    var clump = 0u;
    for (var dy = -1; dy <= 1; dy++) {
        for (var dx = -1; dx <= 1; dx++) {
            let cc = c + vec2<i32>(dx, dy);
            let k = base + cc;
            let ch = hash3(u32(k.x), u32(k.y), frame.clump.z ^ 0x00c10b55u);
            let p = (vec2<f32>(cc) + 0.5 + 0.8 * (vec2<f32>(rand01(ch), rand01(hash_u32(ch ^ 1u))) - 0.5)) * clump_m;
            let d = p - local;
            let d2 = dot(d, d);
            if d2 < best {
                best = d2;
                clump = ch;
            }
        }
    }
    return vec3<f32>(
        0.85 + 0.3 * rand01(hash_u32(clump ^ 4u)),
        0.85 + 0.3 * rand01(hash_u32(clump ^ 5u)),
        0.85 + 0.3 * rand01(hash_u32(clump ^ 6u)),
    );
}

// The blades' colour variation at `rel_xy` (as the wind pass applies it to each blade's root).
fn color_variation(rel_xy: vec2<f32>) -> vec3<f32> {
    if (frame.grid.w & COLOR_VARIATION) == 0u {
        return vec3<f32>(1.0);
    }
    let world = frame.grass_view.xy + rel_xy;
    let v = noise_value(world / 6.0) * 0.6 + noise_value(world / 1.7) * 0.4;
    return vec3<f32>(0.78, 0.86, 0.7) + (vec3<f32>(1.15, 1.1, 0.95) - vec3<f32>(0.78, 0.86, 0.7)) * v;
}

// Grass seen from afar, lit as shaders/grass_draw.wgsl lights a blade at position t whose
// normal has turned to its growth direction `n` (as far blades' normals do): the mean of a
// blade's front (lit by the sun) and back (lit through the blade when translucency is on)
// over the part of the blades seen, whose colour is a0 and colour times position along the
// blade a1 (see visible_moments), plus the sheen of the blades' specular highlights on
// average (SHEEN of the sun, when specular is on).
const SHEEN: f32 = 0.005;

fn far_grass_light(a0: vec3<f32>, a1: vec3<f32>, n: vec3<f32>, sun_vis: f32) -> vec3<f32> {
    let sun = frame.sun_dir.xyz;
    let diffuse = max(dot(n, sun), 0.0) * sun_vis;
    var through = vec3<f32>(0.0);
    if (frame.grid.w & TRANSLUCENCY) != 0u {
        through = 0.25 * vec3<f32>(0.9, 1.0, 0.55);
    }
    let light = frame.sun_color.rgb * diffuse * 0.5 * (vec3<f32>(1.0) + through);
    let ambient = frame.sky_color.rgb * 0.35;
    var sheen = 0.0;
    if (frame.grid.w & SPECULAR) != 0u {
        sheen = SHEEN * diffuse;
    }
    // A blade's light at t: light (0.6 + 0.4 ao) + ambient ao, with ao rising from 0.3 at the
    // root to 1 at the tip: a flat part and a part rising with t.
    if (frame.grid.w & AMBIENT_OCCLUSION) != 0u {
        return a0 * (light * 0.72 + ambient * 0.3) + a1 * (light * 0.28 + ambient * 0.7) + frame.sun_color.rgb * sheen;
    }
    return a0 * (light + ambient) + frame.sun_color.rgb * sheen;
}

// The mean projection of a blade's area across the view per unit of its area (Ross's
// G-function), fitted against the truth's far blades (BLADE_PROJECTION in
// src/terrain/far_field.rs).
const BLADE_PROJECTION: f32 = 0.55;

// The optical depth of the grass layer along a view whose angle to the ground has the sine
// sin_e, for grass of blade area index `area` (one side of the blades per square metre of
// ground) at density d.
fn grass_depth(area: f32, d: f32, sin_e: f32) -> f32 {
    return BLADE_PROJECTION * area * d / max(sin_e, 1e-3);
}

// The error function, to 1.5e-7 (Abramowitz and Stegun 7.1.26), for x >= 0.
fn erf_pos(x: f32) -> f32 {
    let t = 1.0 / (1.0 + 0.3275911 * x);
    let poly = t * (0.2548296 + t * (-0.28449674 + t * (1.4214137 + t * (-1.4531521 + t * 1.0614054))));
    return 1.0 - poly * exp(-x * x);
}

// The mean position along the blades (0 root, 1 tip) of what a view of optical depth `depth`
// sees of them (x) and its mean square (y): a blade is a triangle, hidden at 1 - t = s by the
// blades above in proportion to s^2, so the part seen at s is weighted by s exp(-depth s^2).
fn visible_moments(depth: f32) -> vec2<f32> {
    let u = clamp(depth, 0.05, 60.0);
    let e = exp(-u);
    let r = sqrt(u);
    let s1 = (0.88622693 * erf_pos(r) / r - e) / (1.0 - e);
    let s2 = 1.0 / u - e / (1.0 - e);
    return vec2<f32>(1.0 - s1, 1.0 - 2.0 * s1 + s2);
}

// Bilinear height of the root (level-0) tiles at world xy, or a very low height off the world.
fn root_height(world: vec2<f32>) -> f32 {
    let cell = bitcast<f32>(frame.roots.z);
    let size = i32(textureDimensions(heights).x);
    let border = f32(frame.grid.y);
    let cells = f32(size) - 2.0 * border;
    let tile_m = cell * cells;
    let r = vec2<i32>(floor(world / tile_m));
    if r.x < 0 || r.y < 0 || r.x >= i32(frame.roots.x) || r.y >= i32(frame.roots.y) {
        return -1e9;
    }
    let index = u32(r.y) * frame.roots.x + u32(r.x);
    let slot = frame.root_slots[index / 4u][index % 4u];
    let p = (world - vec2<f32>(r) * tile_m) / cell + border;
    return height_at(p, slot);
}

// The fraction of the sun seen from a surface point: rays marched over the heights of the
// pixel's own tile (short range, fine), then over the root tiles (long range, coarse), with a
// soft edge from the angle by which the ray clears the terrain.
fn sun_visibility(tex: vec2<f32>, layer: u32, texel_m: f32, world: vec3<f32>) -> f32 {
    let sun = frame.sun_dir.xyz;
    if sun.z <= 0.0 {
        return 0.0;
    }
    let flat_len = length(sun.xy);
    if flat_len < 1e-4 {
        return 1.0;
    }
    let dir = sun.xy / flat_len;
    let rise = sun.z / flat_len;
    let softness = 0.06;
    var vis = 1.0;
    // Fine: within the tile's own texels (its border included).
    let size = f32(textureDimensions(heights).x) - 1.0;
    let h0 = world.z + 0.05 * texel_m;
    var s = 1.5;
    for (var i = 0; i < 24; i++) {
        let q = tex + dir * s;
        if any(q < vec2<f32>(0.0)) || any(q > vec2<f32>(size)) {
            break;
        }
        let over = (h0 + s * texel_m * rise - height_at(q, layer)) / (s * texel_m);
        vis = min(vis, smoothstep(-softness, softness, over));
        s *= 1.2;
    }
    // Coarse: the root tiles, from where the fine march stopped up to 8 km. The ray starts
    // lifted to the root tiles' surface where that lies above the pixel's (their heights are
    // smoothed: a valley floor lies below them), so that they shade only what stands above.
    if frame.roots.w == 1u {
        let cell = bitcast<f32>(frame.roots.z);
        let lift = max(root_height(world.xy) - world.z, 0.0) + 0.02 * cell;
        var d = s * texel_m;
        for (var i = 0; i < 32; i++) {
            if d > 8000.0 {
                break;
            }
            let p = world.xy + dir * d;
            let over = (world.z + lift + d * rise - root_height(p)) / d;
            vis = min(vis, smoothstep(-softness, softness, over));
            d *= 1.2;
        }
    }
    return vis;
}

// The maps of one of the four grass samples around a pixel, added in with weight w.
// 0 within the trees' shadow map, rising to 1 over its fade-out (as canopy_fade_in in
// src/terrain/far_field.rs).
fn tree_canopy_fade_in(dist: f32) -> f32 {
    return clamp((dist - frame.tree_canopy_fade.x) / max(frame.tree_canopy_fade.y - frame.tree_canopy_fade.x, 1e-3), 0.0, 1.0);
}

// The share of the ground shaded by a canopy of depth `tau` (at full density) over grass of
// density `d` (as tree_canopy_shade in src/terrain/far_field.rs).
fn tree_canopy_shade(tau: f32, d: f32) -> f32 {
    return 1.0 - exp(-tau * d);
}

struct Maps {
    ground: vec3<f32>,
    // The grass's colour over the part of the blades seen, and that times the position along
    // the blade (see visible_moments), weighted by cover.
    grass_a0: vec3<f32>,
    grass_a1: vec3<f32>,
    cover: f32,
    growth_blend: f32,
    // The weight of the samples whose material is water.
    water: f32,
    // The share of the ground the trees' canopy shades.
    tree_canopy: f32,
}

fn add_corner(m: ptr<function, Maps>, g: vec3<u32>, w: f32, sin_e: f32, world: vec2<f32>, footprint: f32, band: u32) {
    let kind = min(g.x, frame.grid.z - 1u);
    let d = f32(g.y) / 255.0;
    var a = mix(SOIL, frame.ground_colors[kind].rgb, d);
    if g.z == MATERIAL_WATER {
        (*m).water += w;
        a = WATER_BODY;
    } else if g.z != 0u {
        a = material_albedo(g.z, world, footprint);
    } else if kind == 0u {
        a = ROCK;
    } else if (frame.grid.w & GROUND_DARKENING) != 0u {
        a *= mix(1.0, 0.6, d);
    }
    (*m).ground += w * a;
    if g.z != MATERIAL_WATER {
        (*m).tree_canopy += w * tree_canopy_shade(frame.tree_canopy[band * 4u + kind / 4u][kind % 4u], d);
    }
    if kind != 0u {
        // The tip colours' w: the type's blade area index at full density.
        let depth = grass_depth(frame.tip_colors[kind].w, d, sin_e);
        let c = (1.0 - exp(-depth)) * w;
        let mt = visible_moments(depth);
        let base = frame.base_colors[kind].rgb;
        let rise = frame.tip_colors[kind].rgb - base;
        (*m).grass_a0 += c * (base + rise * mt.x);
        (*m).grass_a1 += c * (base * mt.x + rise * mt.y);
        (*m).growth_blend += c * frame.base_colors[kind].w;
        (*m).cover += c;
    }
}

// One octave of detail noise of feature size `scale` (m) and amplitude `amp`, faded out as the
// pixel's footprint (m) nears the feature size: x the colour offset, yz the slope.
fn octave(p: vec2<f32>, scale: f32, amp: f32, footprint: f32) -> vec3<f32> {
    let vis = clamp(scale / footprint - 1.0, 0.0, 1.0);
    if vis <= 0.0 {
        return vec3<f32>(0.0);
    }
    let ng = noise_grad(p / scale);
    return vec3<f32>((ng.x - 0.5) * amp * 2.0, ng.yz * amp * 0.8) * vis;
}


// The lit, fogged colour (linear) of the terrain at `rel` (metres from the camera), whose heights
// and maps are at atlas texel `tex` of slot `layer`, `texel_m` metres per texel, drawn from a
// tile of `level` (for the overlay).
fn shade_terrain(rel: vec3<f32>, tex: vec2<f32>, layer: u32, texel_m: f32, level: f32) -> vec3<f32> {
    let dist = length(rel);
    let world = frame.camera_world.xyz + rel;

    // Per-pixel normal from the height atlas (central differences one texel apart).
    let hl = height_at(tex - vec2<f32>(1.0, 0.0), layer);
    let hr = height_at(tex + vec2<f32>(1.0, 0.0), layer);
    let hd = height_at(tex - vec2<f32>(0.0, 1.0), layer);
    let hu = height_at(tex + vec2<f32>(0.0, 1.0), layer);
    let n_terrain = normalize(vec3<f32>(hl - hr, hd - hu, 2.0 * texel_m));

    // Maps: the four grass samples around the pixel, blended with weights whose border is
    // moved about by world-space noise (up to about half a texel), so that no texel edge shows.
    let warp_scale = max(texel_m, 0.5);
    let wn = 0.65 * noise_value(world.xy / (0.9 * warp_scale)) + 0.35 * noise_value(world.xy / (0.3 * warp_scale) + 31.7);
    let wn2 = 0.65 * noise_value(world.xy / (0.9 * warp_scale) + 57.3) + 0.35 * noise_value(world.xy / (0.3 * warp_scale) + 11.1);
    let cell = floor(tex);
    let f = tex - cell;
    let fw = clamp(f + (vec2<f32>(wn, wn2) - 0.5) * 0.9, vec2<f32>(0.0), vec2<f32>(1.0));
    let sw = smoothstep(vec2<f32>(0.3), vec2<f32>(0.7), fw);
    let ci = vec2<i32>(cell);
    // The sine of the view's angle to the ground.
    let sin_e = abs(dot(rel, n_terrain)) / max(dist, 1e-3);
    let footprint = 0.004 * dist + 1e-3;
    let ground_footprint = footprint / max(sin_e, 0.1);
    // The band of altitude whose trees shade the ground beyond their shadow map.
    var band = 0u;
    for (var i = 0u; i < 7u; i++) {
        if world.z >= frame.tree_canopy_edges[i / 4u][i % 4u] {
            band += 1u;
        }
    }
    var m = Maps();
    add_corner(&m, grass_texel(ci, layer), (1.0 - sw.x) * (1.0 - sw.y), sin_e, world.xy, ground_footprint, band);
    add_corner(&m, grass_texel(ci + vec2<i32>(1, 0), layer), sw.x * (1.0 - sw.y), sin_e, world.xy, ground_footprint, band);
    add_corner(&m, grass_texel(ci + vec2<i32>(0, 1), layer), (1.0 - sw.x) * sw.y, sin_e, world.xy, ground_footprint, band);
    add_corner(&m, grass_texel(ci + vec2<i32>(1, 1), layer), sw.x * sw.y, sin_e, world.xy, ground_footprint, band);
    var ground = m.ground;
    var grass_a0 = m.grass_a0;
    var grass_a1 = m.grass_a1;
    var cover = m.cover;
    var growth_blend = m.growth_blend;
    if cover > 0.0 {
        grass_a0 /= cover;
        grass_a1 /= cover;
        growth_blend /= cover;
    }
    // A renderer that keeps the ground bare between its blades shows the far field only
    // where they fade out (by the fade's distance: the distance plus clump_offset.w times
    // the height below the camera, as grass_generate.wgsl fades them).
    if frame.clump_offset.z < 0.5 {
        let far_dist = dist + frame.clump_offset.w * max(-rel.z, 0.0);
        cover *= clamp((far_dist - frame.grass_view.z) / max(frame.grass_view.w - frame.grass_view.z, 1e-3), 0.0, 1.0);
    }

    // Close-range detail: three octaves of world-space noise in the ground's colour and normal,
    // each faded out before its features shrink below a pixel.
    var detail = 0.0;
    var slope_noise = vec2<f32>(0.0);
    let o1 = octave(world.xy, 23.0, 0.10, footprint);
    let o2 = octave(world.xy + 19.1, 4.7, 0.08, footprint);
    let o3 = octave(world.xy + 38.2, 0.9, 0.07, footprint);
    detail = o1.x + o2.x + o3.x;
    slope_noise = o1.yz + o2.yz + o3.yz;
    let n = normalize(n_terrain - vec3<f32>(slope_noise, 0.0));

    // Materials: rock on steep slopes (the border moved by noise), soil where it is steep
    // enough to thin the grass; neither on water.
    let slope = 1.0 - n_terrain.z;
    let dry = 1.0 - min(m.water, 1.0);
    let rock_w = smoothstep(0.26, 0.40, slope + (wn - 0.5) * 0.12) * dry;
    let soil_w = smoothstep(0.10, 0.22, slope + (wn2 - 0.5) * 0.08) * 0.6 * dry;
    ground = mix(ground, SOIL * 0.9, soil_w * (1.0 - rock_w));
    ground = mix(ground, ROCK * (0.9 + 0.3 * wn2), rock_w);
    cover *= (1.0 - rock_w) * (1.0 - 0.5 * soil_w);
    ground *= 1.0 + detail;

    // The clump's tint (mean 1), faded out as its cells shrink below a few pixels (no sparkle
    // far away), and the blades' colour variation: on the far field's grass and, under grass,
    // on the ground between the blades, so that a meadow seen from above is mottled by its
    // clumps as its blades are.
    var tint = vec3<f32>(1.0);
    if (frame.grid.w & FAR_FIELD) != 0u && cover > 0.0 {
        let clump_vis = clamp(bitcast<f32>(frame.clump.w) / footprint - 1.0, 0.0, 1.0);
        if clump_vis > 0.0 {
            tint = mix(vec3<f32>(1.0), clump_tint(rel.xy), clump_vis);
        }
        tint *= color_variation(rel.xy);
        ground *= mix(vec3<f32>(1.0), tint, GROUND_TINT * (1.0 - rock_w));
    }

    // Terrain shadows, from the surface of the heights under the pixel (the rays march over
    // the same heights).
    var sun_vis = 1.0;
    if (frame.grid.w & SHADOWS) != 0u {
        let surface = vec3<f32>(world.xy, height_at(tex, layer));
        sun_vis = sun_visibility(tex, layer, texel_m, surface);
    }
    // Beyond the trees' shadow map, their canopy's shade as the share of the ground it covers.
    if frame.tree_canopy_fade.z > 0.0 && (frame.grid.w & (TREES | TREE_SHADOWS)) == (TREES | TREE_SHADOWS) {
        sun_vis *= 1.0 - m.tree_canopy * tree_canopy_fade_in(dist);
    }
    let sun = frame.sun_dir.xyz;
    let lambert = max(dot(n, sun), 0.0) * sun_vis;
    // Hemisphere ambient: the sky from above (its zenith and horizon averaged, as the dome a
    // point of ground sees), warm bounce from the ground below.
    let bounce = vec3<f32>(0.20, 0.17, 0.12);
    let dome = mix(frame.sky_color.rgb, frame.horizon_color.rgb, 0.5);
    let ambient = mix(bounce, dome, 0.5 + 0.5 * n.z);
    var lit = ground * (frame.sun_color.rgb * lambert + 0.45 * ambient);

    // The far field: the terrain shows what the blades would, under the blades drawn as beyond
    // them, so that the gaps between near blades read as grass and the blades' end, where
    // they thin out before the view distance, shows nothing new.
    if (frame.grid.w & FAR_FIELD) != 0u && cover > 0.0 {
        let up = vec3<f32>(0.0, 0.0, 1.0);
        let growth = normalize(up + (n_terrain - up) * growth_blend);
        let albedo_scale = tint * (1.0 + 0.5 * detail);
        let grass_lit = far_grass_light(grass_a0 * albedo_scale, grass_a1 * albedo_scale, growth, sun_vis);
        lit = mix(lit, grass_lit, min(cover, 1.0));
    }

    // Water: a flat mirror of the sky over a dark body, blended in by the same noisy weights
    // as the other maps (so shores are not straight texel edges).
    if m.water > 0.0 {
        lit = mix(lit, water_color(rel / max(dist, 1e-3), sun_vis), min(m.water, 1.0));
    }

    // Clear near the camera, 95% fog at the manifest's fog distance.
    let x = dist / frame.camera.y;
    let fog = 1.0 - exp(-3.0 * x * x);
    var color = mix(lit, fog_color(rel / max(dist, 1e-3)), fog);
    if frame.overlay.x > 0.5 {
        color = with_overlay(color, rel, level);
    }
    return color;
}

// Tile levels as hues, and the grass rings as lines around the camera.
fn with_overlay(color: vec3<f32>, rel: vec3<f32>, level_f: f32) -> vec3<f32> {
    let hues = array<vec3<f32>, 6>(
        vec3<f32>(0.9, 0.2, 0.2),
        vec3<f32>(0.9, 0.6, 0.1),
        vec3<f32>(0.8, 0.9, 0.1),
        vec3<f32>(0.2, 0.8, 0.3),
        vec3<f32>(0.2, 0.6, 0.9),
        vec3<f32>(0.6, 0.3, 0.9),
    );
    let level = u32(max(level_f, 0.0)) % 6u;
    var c = mix(color, hues[level], 0.35);
    let r = length(rel.xy);
    let width = 0.3 + 0.004 * length(rel);
    for (var k = 0; k < 2; k++) {
        let radius = select(frame.overlay.z, frame.overlay.y, k == 0);
        if radius > 0.0 && abs(r - radius) < width {
            c = select(vec3<f32>(0.1, 0.3, 1.0), vec3<f32>(1.0, 1.0, 1.0), k == 0);
        }
    }
    return c;
}

// The sky's colour (linear) in the direction `dir` (unit, camera-relative).
fn sky_color(dir: vec3<f32>) -> vec3<f32> {
    let up = clamp(dir.z, 0.0, 1.0);
    var color = mix(fog_color(dir), frame.sky_color.rgb, pow(up, 0.6));
    let sun = dot(dir, frame.sun_dir.xyz);
    color += frame.sun_color.rgb * smoothstep(0.9995, 0.9999, sun);
    return color;
}
