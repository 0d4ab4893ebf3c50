// Grass blades from the instance pool: one indirect draw per generation job, a triangle strip
// per blade. SEGMENTS is set per pipeline: by default 9 (19 vertices) for the blades within the
// near radius, 3 (7 vertices) for the rest of the high ring and for the low ring. The shape
// is a cubic Bezier bent by the wind and scaled to keep its length (CPU mirror of the shape:
// src/grass/blade.rs). The blade record, the feature bits and the colour output are
// included from shaders/shared/. With the temporal anti-aliasing's blade motion on, the
// pipelines take vs_blade_motion and fs_blade_motion, which also write each blade's motion
// over the last frame into a second target (src/aa/taa.rs, MOTION_FORMAT).
//
// Bending (after Crysis): main bending leans the whole blade by its cell's sway (a damped spring
// per grass type, shaders/wind_sway.wgsl) plus the trail's push; detail bending adds whole-blade
// sway and edge flutter from smoothed triangle waves at four frequencies, phased by the blade's
// hash. Shading: front and back lighting with translucency, per-type gloss, ambient occlusion
// from root to tip, colour variation from world-space noise at the root, highlights that travel
// with the gusts, and normals that blend toward the terrain's with distance.

#include "shared/blade.wgsl"
#include "shared/features.wgsl"
#include "shared/output.wgsl"

override SEGMENTS: u32 = 9u;
// Multisampled targets with alpha to coverage: a blade narrower than a pixel is drawn a pixel
// wide, its true width becoming the share of the pixel's samples it covers (its alpha), so
// that it fades with distance instead of popping in and out of pixels.
override COVERAGE: bool = false;
// How far each vertex of the strip moves out of the curve, times its second derivative
// (across the curve) and the segment's parameter step squared: 3/4 of a chord's sag (k L^2 / 8),
// the shift that minimises the chords' mean distance from a parabolic arc. 0 keeps the
// vertices on the curve (src/grass/blade.rs, `strip_centre`).
const STRADDLE: f32 = 0.09375;

struct GrassFrame {
    view_proj: mat4x4<f32>,
    // x: fog distance; y, z: the target's height and width in pixels
    misc: vec4<f32>,
    sun_dir: vec4<f32>,
    sun_color: vec4<f32>,
    sky_color: vec4<f32>,
    horizon_color: vec4<f32>,
    // x: feature bits (src/features.rs)
    flags: vec4<u32>,
    // rgb colour; w: gloss exponent (base) and specular strength (tip)
    base_colors: array<vec4<f32>, 16>,
    tip_colors: array<vec4<f32>, 16>,
    // The motion vectors' (vs_blade_motion): this frame's view-projection unjittered, and the
    // last frame's, both from this frame's camera-relative positions.
    unjittered: mat4x4<f32>,
    last_view_proj: mat4x4<f32>,
}

@group(0) @binding(0) var<uniform> frame: GrassFrame;
@group(0) @binding(1) var<storage, read> blades: array<Blade>;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) rel_pos: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) color: vec3<f32>,
    // x: position along the blade 0..1, y: gust highlight 0..1, z: specular strength,
    // w: gloss exponent
    @location(3) misc: vec4<f32>,
    // The share of a pixel the blade's width covers (1 unless COVERAGE and the blade is
    // narrower than a pixel).
    @location(4) @interpolate(flat) coverage: f32,
}

// VertexOut with the blade's point in this frame's and the last frame's clip space
// (unjittered): the temporal anti-aliasing's motion vectors.
struct MotionVertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) rel_pos: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) color: vec3<f32>,
    @location(3) misc: vec4<f32>,
    @location(4) @interpolate(flat) coverage: f32,
    @location(5) now: vec4<f32>,
    @location(6) last: vec4<f32>,
}

struct MotionOut {
    @location(0) color: vec4<f32>,
    // xy: the pixels the blade's point moved since the last frame; z: its depth (the resolve
    // takes the motion only where the frame's depth is still the blade's); w: 1 (written).
    @location(1) motion: vec4<f32>,
}

// A vertex of a blade, and how far it moved since the last frame.
struct BladeVertex {
    out: VertexOut,
    moved: vec3<f32>,
}

fn bezier(p0: vec3<f32>, p1: vec3<f32>, p2: vec3<f32>, p3: vec3<f32>, t: f32) -> vec3<f32> {
    let u = 1.0 - t;
    return p0 * (u * u * u) + p1 * (3.0 * u * u * t) + p2 * (3.0 * u * t * t) + p3 * (t * t * t);
}

fn bezier_tangent(p0: vec3<f32>, p1: vec3<f32>, p2: vec3<f32>, p3: vec3<f32>, t: f32) -> vec3<f32> {
    let u = 1.0 - t;
    return (p1 - p0) * (3.0 * u * u) + (p2 - p1) * (6.0 * u * t) + (p3 - p2) * (3.0 * t * t);
}

// Second derivative of a cubic Bezier.
fn bezier_second(p0: vec3<f32>, p1: vec3<f32>, p2: vec3<f32>, p3: vec3<f32>, t: f32) -> vec3<f32> {
    return (p2 - 2.0 * p1 + p0) * (6.0 * (1.0 - t)) + (p3 - 2.0 * p2 + p1) * (6.0 * t);
}

// Mean of chord and control polygon of one piece of a curve.
fn piece_length(q0: vec3<f32>, q1: vec3<f32>, q2: vec3<f32>, q3: vec3<f32>) -> f32 {
    return 0.5 * (distance(q0, q3) + distance(q0, q1) + distance(q1, q2) + distance(q2, q3));
}

// Length of the half of a cubic Bezier: split once more, two pieces.
fn half_length(q0: vec3<f32>, q1: vec3<f32>, q2: vec3<f32>, q3: vec3<f32>) -> f32 {
    let q01 = (q0 + q1) * 0.5;
    let q12 = (q1 + q2) * 0.5;
    let q23 = (q2 + q3) * 0.5;
    let a = (q01 + q12) * 0.5;
    let b = (q12 + q23) * 0.5;
    let m = (a + b) * 0.5;
    return piece_length(q0, q01, a, m) + piece_length(m, b, q23, q3);
}

// Length of a cubic Bezier: split into quarters; per quarter, the mean of chord and polygon
// (as bezier_length_estimate in src/grass/blade.rs).
fn bezier_length(p0: vec3<f32>, p1: vec3<f32>, p2: vec3<f32>, p3: vec3<f32>) -> f32 {
    let p01 = (p0 + p1) * 0.5;
    let p12 = (p1 + p2) * 0.5;
    let p23 = (p2 + p3) * 0.5;
    let a = (p01 + p12) * 0.5;
    let b = (p12 + p23) * 0.5;
    let m = (a + b) * 0.5;
    return half_length(p0, p01, a, m) + half_length(m, b, p23, p3);
}

@vertex
fn vs_blade(@builtin(vertex_index) vi: u32, @builtin(instance_index) ii: u32) -> VertexOut {
    return blade_vertex(vi, ii).out;
}

@vertex
fn vs_blade_motion(@builtin(vertex_index) vi: u32, @builtin(instance_index) ii: u32) -> MotionVertexOut {
    let v = blade_vertex(vi, ii);
    var out: MotionVertexOut;
    out.clip = v.out.clip;
    out.rel_pos = v.out.rel_pos;
    out.normal = v.out.normal;
    out.color = v.out.color;
    out.misc = v.out.misc;
    out.coverage = v.out.coverage;
    out.now = frame.unjittered * vec4<f32>(v.out.rel_pos, 1.0);
    out.last = frame.last_view_proj * vec4<f32>(v.out.rel_pos - v.moved, 1.0);
    return out;
}

fn blade_vertex(vi: u32, ii: u32) -> BladeVertex {
    let b = blades[ii];
    let root = vec3<f32>(b.pos_x, b.pos_y, b.pos_z);
    let up = vec3<f32>(b.growth_x, b.growth_y, sqrt(max(1.0 - b.growth_x * b.growth_x - b.growth_y * b.growth_y, 0.0)));
    let facing_dir = vec3<f32>(cos(b.facing), sin(b.facing), 0.0);
    let side = normalize(cross(up, facing_dir));
    let fwd = normalize(cross(side, up));
    let h = b.height;
    let kind = b.kind & 255u;

    // Wind, worked out once per blade by the wind pass (shaders/grass_wind.wgsl).
    let lean = vec2<f32>(b.lean_x, b.lean_y);
    let blade_sway = b.sway;
    let flutter = b.flutter;

    // Control points (as blade_curve in src/grass/blade.rs), bent, then scaled to keep the
    // length. The bend is horizontal: every control point stays above the root, so the curve
    // (inside their hull) never dips below the ground.
    let bend = vec3<f32>(lean, 0.0) + side * (0.06 * blade_sway);
    let tip_angle = b.tilt + b.bend * 1.2;
    let p3 = (up * cos(b.tilt) + fwd * sin(b.tilt)) * h + bend * h;
    let p1 = up * (h / 3.0) + side * (b.side_curve * 0.15 * h) + bend * (0.15 * h);
    let p2 = p3 - (up * cos(tip_angle) + fwd * sin(tip_angle)) * (h / 3.0) + side * (b.side_curve * 0.15 * h) - bend * (0.4 * h);
    let scale = h / max(bezier_length(vec3<f32>(0.0), p1, p2, p3), 1e-6);
    // The bend's change over the last frame (the wind pass's), moving the control points as
    // the bend does (linear in it; the length's rescaling kept).
    let moved_bend = (vec3<f32>(b.moved_lean_x, b.moved_lean_y, 0.0) + side * (0.06 * b.moved_sway)) * (h * scale);
    let c1 = p1 * scale;
    let c2 = p2 * scale;
    let c3 = p3 * scale;

    let last = 2u * SEGMENTS;
    let seg = min(vi / 2u, SEGMENTS);
    var t = f32(seg) / f32(SEGMENTS);
    var side_sign = select(-1.0, 1.0, (vi & 1u) == 1u);
    if vi >= last {
        t = 1.0;
        side_sign = 0.0;
    }
    let d1 = bezier_tangent(vec3<f32>(0.0), c1, c2, c3, t);
    let tangent = normalize(d1 + up * 1e-4);
    // The strip's chords cut inside the curve by up to its sag (a segment of length L on a
    // curve of curvature k sags k L^2 / 8, as much as a blade is wide near the camera): each
    // vertex between root and tip moves out by 3/4 of its segments' sag, so that the chords
    // straddle the curve, the blade's coverage halving its error.
    var bulge = vec3<f32>(0.0);
    if t > 0.0 && t < 1.0 {
        let d2 = bezier_second(vec3<f32>(0.0), c1, c2, c3, t);
        let dt = 1.0 / f32(SEGMENTS);
        bulge = -(d2 - tangent * dot(d2, tangent)) * (STRADDLE * dt * dt);
    }
    let p = root + bezier(vec3<f32>(0.0), c1, c2, c3, t) + bulge;
    var n = normalize(cross(side, tangent));

    // Seen edge-on, a blade turns a little toward the viewer so that it keeps some width.
    let view = normalize(p);
    let edge_on = 1.0 - abs(dot(n, view));
    let side_view = normalize(cross(view, tangent) + side * 1e-4);
    let width_dir = normalize(mix(side, side_view * sign(dot(side, side_view) + 1e-6), 0.4 * edge_on));
    var bw = b.width * (1.0 - t);
    var coverage = 1.0;
    if COVERAGE {
        // Pixels a metre at the root's distance: the projection's vertical scale (the length
        // of the view-projection's second row, the view being a rotation) over the depth.
        let clip_root = frame.view_proj * vec4<f32>(root, 1.0);
        let scale = length(vec3<f32>(frame.view_proj[0][1], frame.view_proj[1][1], frame.view_proj[2][1]));
        let px_per_m = 0.5 * frame.misc.y * scale / max(clip_root.w, 1e-3);
        let width_px = b.width * px_per_m;
        if width_px < 1.0 {
            coverage = max(width_px, 0.0);
            bw = bw / max(width_px, 1e-3);
        }
    }
    var pos = p + width_dir * (0.5 * bw * side_sign);
    // Edge flutter: the blade's edges move along its normal, more toward the tip.
    let flutter_step = n * (0.03 * h * t * abs(side_sign));
    pos += flutter_step * flutter;
    // Rounded cross-section: normals lean outward toward the edges; far away they blend toward
    // the ground's (the growth direction), as a field of blades reads from a distance.
    n = normalize(n + width_dir * (0.35 * side_sign));
    n = normalize(mix(n, up, smoothstep(15.0, 90.0, length(root))));

    // The clump's tint, with the colour variation of the blade's root folded in by the wind pass.
    let tint = unpack_rgb(b.color) * 2.0;
    let color = mix(frame.base_colors[kind].rgb, frame.tip_colors[kind].rgb, t) * tint;
    // Gust highlights: where the wind runs above the ambient speed, tips catch more light.
    let gust = b.fade;

    let moved = bezier(vec3<f32>(0.0), moved_bend * 0.15, moved_bend * 0.6, moved_bend, t)
        + flutter_step * b.moved_flutter;
    var out: VertexOut;
    out.clip = frame.view_proj * vec4<f32>(pos, 1.0);
    out.rel_pos = pos;
    out.normal = n;
    out.color = color;
    out.misc = vec4<f32>(t, gust * t, frame.tip_colors[kind].w, frame.base_colors[kind].w);
    out.coverage = coverage;
    return BladeVertex(out, moved);
}

@fragment
fn fs_blade(in: VertexOut, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    return shade_blade(in.rel_pos, in.normal, in.color, in.misc, in.coverage, front);
}

// The pixels a point moved on screen, from its unjittered clip positions now and then.
fn motion_px(now: vec4<f32>, last: vec4<f32>) -> vec2<f32> {
    let d = now.xy / now.w - last.xy / max(last.w, 1e-6);
    return vec2<f32>(0.5 * d.x * frame.misc.z, -0.5 * d.y * frame.misc.y);
}

@fragment
fn fs_blade_motion(in: MotionVertexOut, @builtin(front_facing) front: bool) -> MotionOut {
    var out: MotionOut;
    out.color = shade_blade(in.rel_pos, in.normal, in.color, in.misc, in.coverage, front);
    out.motion = vec4<f32>(motion_px(in.now, in.last), in.clip.z, 1.0);
    return out;
}

fn shade_blade(rel_pos: vec3<f32>, normal: vec3<f32>, base: vec3<f32>, misc: vec4<f32>, coverage: f32, front: bool) -> vec4<f32> {
    var n = normalize(normal);
    if !front {
        n = -n;
    }
    let t = misc.x;
    let sun = frame.sun_dir.xyz;
    let to_eye = -normalize(rel_pos);
    let diffuse = max(dot(n, sun), 0.0);
    var light = frame.sun_color.rgb * diffuse;
    if has_feature(frame.flags.x, TRANSLUCENCY) {
        // The back side lit through the blade, stronger when looking toward the sun.
        let back = max(dot(-n, sun), 0.0);
        let toward_sun = pow(max(dot(-to_eye, sun), 0.0), 4.0);
        light += frame.sun_color.rgb * back * (0.25 + 0.75 * toward_sun) * vec3<f32>(0.9, 1.0, 0.55);
    }
    var ao = 1.0;
    if has_feature(frame.flags.x, AMBIENT_OCCLUSION) {
        ao = mix(0.3, 1.0, t);
    }
    let ambient = frame.sky_color.rgb * (0.35 + 0.25 * n.z) * ao;
    var lit = base * (light * mix(0.6, 1.0, ao) + ambient) * (1.0 + 0.5 * misc.y);
    if has_feature(frame.flags.x, SPECULAR) {
        let half_dir = normalize(sun + to_eye);
        let spec = pow(max(dot(n, half_dir), 0.0), misc.w) * misc.z * (0.5 + t);
        lit += frame.sun_color.rgb * spec;
    }
    let dist = length(rel_pos);
    let x = dist / frame.misc.x;
    let fog = 1.0 - exp(-3.0 * x * x);
    var color = output_color(mix(lit, frame.horizon_color.rgb, fog));
    if COVERAGE {
        color.a = coverage;
    }
    return color;
}
