// Grass blades from the instance pool: one indirect draw per tile, a triangle strip per blade.
// The high-LOD pipeline has 7 segments (15 vertices), the low-LOD one 3 (7 vertices). The shape
// is a cubic Bezier scaled to keep its length (CPU mirror of the shape: src/grass/blade.rs).

override SEGMENTS: u32 = 7u;

struct GrassFrame {
    view_proj: mat4x4<f32>,
    // x: fog distance, y: time (s)
    misc: vec4<f32>,
    sun_dir: vec4<f32>,
    sun_color: vec4<f32>,
    sky_color: vec4<f32>,
    horizon_color: vec4<f32>,
    base_colors: array<vec4<f32>, 16>,
    tip_colors: array<vec4<f32>, 16>,
}

struct Blade {
    pos_x: f32, pos_y: f32, pos_z: f32,
    facing: f32,
    growth_x: f32, growth_y: f32,
    height: f32,
    width: f32,
    tilt: f32,
    bend: f32,
    side_curve: f32,
    wind: f32,
    hash: u32,
    kind: u32,
    color: u32,
    fade: f32,
}

@group(0) @binding(0) var<uniform> frame: GrassFrame;
@group(0) @binding(1) var<storage, read> blades: array<Blade>;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) rel_pos: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) color: vec3<f32>,
    // x: position along the blade 0..1
    @location(3) t: f32,
}

fn bezier(p0: vec3<f32>, p1: vec3<f32>, p2: vec3<f32>, p3: vec3<f32>, t: f32) -> vec3<f32> {
    let u = 1.0 - t;
    return p0 * (u * u * u) + p1 * (3.0 * u * u * t) + p2 * (3.0 * u * t * t) + p3 * (t * t * t);
}

fn bezier_tangent(p0: vec3<f32>, p1: vec3<f32>, p2: vec3<f32>, p3: vec3<f32>, t: f32) -> vec3<f32> {
    let u = 1.0 - t;
    return (p1 - p0) * (3.0 * u * u) + (p2 - p1) * (6.0 * u * t) + (p3 - p2) * (3.0 * t * t);
}

fn half_length(q0: vec3<f32>, q1: vec3<f32>, q2: vec3<f32>, q3: vec3<f32>) -> f32 {
    return 0.5 * (distance(q0, q3) + distance(q0, q1) + distance(q1, q2) + distance(q2, q3));
}

// Length of a cubic Bezier: split in the middle; per half, the mean of chord and polygon.
fn bezier_length(p0: vec3<f32>, p1: vec3<f32>, p2: vec3<f32>, p3: vec3<f32>) -> f32 {
    let p01 = (p0 + p1) * 0.5;
    let p12 = (p1 + p2) * 0.5;
    let p23 = (p2 + p3) * 0.5;
    let a = (p01 + p12) * 0.5;
    let b = (p12 + p23) * 0.5;
    let m = (a + b) * 0.5;
    return half_length(p0, p01, a, m) + half_length(m, b, p23, p3);
}

fn unpack_rgb(c: u32) -> vec3<f32> {
    return vec3<f32>(f32(c & 255u), f32((c >> 8u) & 255u), f32((c >> 16u) & 255u)) / 255.0;
}

@vertex
fn vs_blade(@builtin(vertex_index) vi: u32, @builtin(instance_index) ii: u32) -> VertexOut {
    let b = blades[ii];
    let root = vec3<f32>(b.pos_x, b.pos_y, b.pos_z);
    let up = vec3<f32>(b.growth_x, b.growth_y, sqrt(max(1.0 - b.growth_x * b.growth_x - b.growth_y * b.growth_y, 0.0)));
    let facing_dir = vec3<f32>(cos(b.facing), sin(b.facing), 0.0);
    let side = normalize(cross(up, facing_dir));
    let fwd = normalize(cross(side, up));
    let h = b.height;

    // Control points (as blade_curve in src/grass/blade.rs), then scaled to keep the length.
    let tip_angle = b.tilt + b.bend * 1.2;
    let p3 = (up * cos(b.tilt) + fwd * sin(b.tilt)) * h;
    let p1 = up * (h / 3.0) + side * (b.side_curve * 0.15 * h);
    let p2 = p3 - (up * cos(tip_angle) + fwd * sin(tip_angle)) * (h / 3.0) + side * (b.side_curve * 0.15 * h);
    let scale = h / max(bezier_length(vec3<f32>(0.0), p1, p2, p3), 1e-6);
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
    let p = root + bezier(vec3<f32>(0.0), c1, c2, c3, t);
    let tangent = normalize(bezier_tangent(vec3<f32>(0.0), c1, c2, c3, t) + up * 1e-4);
    var n = normalize(cross(side, tangent));

    // Seen edge-on, a blade turns a little toward the viewer so that it keeps some width.
    let view = normalize(p);
    let edge_on = 1.0 - abs(dot(n, view));
    let side_view = normalize(cross(view, tangent) + side * 1e-4);
    let width_dir = normalize(mix(side, side_view * sign(dot(side, side_view) + 1e-6), 0.4 * edge_on));
    let w = b.width * (1.0 - t);
    let pos = p + width_dir * (0.5 * w * side_sign);
    // Rounded cross-section: normals lean outward toward the edges.
    n = normalize(n + width_dir * (0.35 * side_sign));

    let kind = b.kind & 255u;
    let tint = unpack_rgb(b.color) * 2.0;
    let color = mix(frame.base_colors[kind].rgb, frame.tip_colors[kind].rgb, t) * tint;

    var out: VertexOut;
    out.clip = frame.view_proj * vec4<f32>(pos, 1.0);
    out.rel_pos = pos;
    out.normal = n;
    out.color = color;
    out.t = t;
    return out;
}

@fragment
fn fs_blade(in: VertexOut, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    var n = normalize(in.normal);
    if !front {
        n = -n;
    }
    let sun = frame.sun_dir.xyz;
    let diffuse = max(dot(n, sun), 0.0);
    // Light through the blade when the sun is behind it.
    let through = max(dot(-n, sun), 0.0) * 0.35;
    let ao = mix(0.35, 1.0, in.t);
    let ambient = frame.sky_color.rgb * (0.35 + 0.25 * n.z);
    let lit = in.color * (frame.sun_color.rgb * (diffuse + through) + ambient) * ao;
    let dist = length(in.rel_pos);
    let x = dist / frame.misc.x;
    let fog = 1.0 - exp(-3.0 * x * x);
    return vec4<f32>(mix(lit, frame.horizon_color.rgb, fog), 1.0);
}
