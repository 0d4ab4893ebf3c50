// Temporal anti-aliasing: each frame is drawn with its projection jittered within a pixel
// (a Halton sequence), and this stage folds it into a history that follows the surfaces on
// screen. Per pixel, the history is fetched where the pixel's surface was in the last frame:
// a grass blade's own motion where a blade is the pixel's surface (the draw evaluates each
// blade's wind a frame ago: its sway spring, sway and flutter), elsewhere the pixel
// reprojected through its depth (the camera's move; in grass the nearest depth of a
// neighbourhood is a blade's more often than not, and would drag the ground's history along
// with the blades),
// clipped toward the current frame's 3x3 neighbourhood (its mean and spread in YCoCg: what
// the neighbourhood cannot explain is a ghost and is dropped), and blended with the current
// sample with weight 1 / n, n the samples the history holds: at most MAX_SAMPLES, fewer the
// further the surface moved on screen (a history resampled frame after frame blurs): a still
// scene converges to the box-filtered average of the jittered samples, a moving one keeps a
// shorter history, and shorter still by its parallax (what it moved beyond the camera's turn:
// where the camera moves, blades at other depths slide past each other within a pixel and
// its history mixes blades that are no longer there; a turn moves every depth alike, and its
// history stays good), and, where a blade wrote its motion vector, by its own sway in the
// wind (`sway.x`: a swaying blade is never quite where its resampled history shows it).
// Beside the history, each pixel keeps its samples' own spread over time
// (an exponentially weighted variance per YCoCg channel, resampled from the nearest texel):
// with `clip.z` above 0, the clip's box also reaches the current sample plus and minus that
// many of the pixel's own standard deviations, so that a blade thinner than a pixel, which
// the current neighbourhood's samples missed but the pixel's past samples caught, is not
// clipped out of the history. A pixel whose history falls off
// screen, and every pixel after a cut, starts again from its current sample. Two passes: the
// resolve (compute) into the next history (linear colour, samples in alpha), then a
// full-screen pass that writes it into the colour target. CPU mirror: src/aa/taa_cpu.rs.

#include "shared/full_screen.wgsl"
#include "shared/output.wgsl"

// 1 when the current frame's texture holds sRGB-encoded values in a plain unorm format (the
// passes that drew it encoded them): decoded here.
override DECODE_SRGB: bool = false;

struct Params {
    // From the current frame's unjittered normalised coordinates and depth (reverse-Z) to the
    // last frame's unjittered clip space (the camera's move included).
    reproject: mat4x4<f32>,
    // x, y: target size (pixels); z: most samples a history holds; w: 1 to start every pixel
    // again (a cut, a teleport, the first frame).
    size: vec4<f32>,
    // x: the neighbourhood's spread, in standard deviations, that bounds the history; y: how
    // fast the most samples fall with the pixels moved (most / (1 + y * pixels), at least
    // hold.x);
    // z: the pixel's own spread over time, in standard deviations around the current sample,
    // that the box also reaches (0: the neighbourhood's box alone); w: how much faster the
    // most samples fall with the pixels of parallax (most / (1 + y * pixels + w * parallax)).
    clip: vec4<f32>,
    // x: the fewest samples a moving surface's history keeps (1: the current sample alone
    // where the history would only blur it); yz: the current frame's jitter (pixels, x right,
    // y down: its sample of a pixel shows the scene at the pixel's centre minus it); w: the
    // standard deviation (pixels) of the Gaussian that reconstructs the current frame at each
    // pixel's centre from its 3x3 samples (0: the pixel's own sample).
    hold: vec4<f32>,
    // x: how much faster the most samples fall with the pixels of a blade's own motion (its
    // motion vector beyond where its depth alone would have taken it: the wind's sway), most /
    // (1 + y * pixels + w * parallax + x * sway); yzw: unused.
    sway: vec4<f32>,
}

// Read-only storage, not uniform: software Vulkan (lavapipe) compiles and keeps a variant of a
// shader for every value of the uniforms its branches depend on, and these change every frame.
@group(0) @binding(0) var<storage, read> params: Params;
@group(0) @binding(1) var current: texture_2d<f32>;
@group(0) @binding(2) var depth: texture_depth_2d;
@group(0) @binding(3) var history: texture_2d<f32>;
@group(0) @binding(4) var history_out: texture_storage_2d<rgba16float, write>;
// The full-screen pass's input: the history just written.
@group(0) @binding(5) var resolved: texture_2d<f32>;
// The blades' motion vectors (shaders/grass_draw.wgsl, fs_blade_motion): xy the pixels the
// blade's point moved since the last frame, z its depth, w 1 where a blade wrote them, 2 where
// a falling leaf marked its pixel (shaders/particles.wgsl, fs_particle_mark).
@group(0) @binding(6) var motion: texture_2d<f32>;
// The pixels' own spread over time: the variance of their samples per YCoCg channel (xyz),
// read from the last frame's and written for the next.
@group(0) @binding(7) var spread: texture_2d<f32>;
@group(0) @binding(8) var spread_out: texture_storage_2d<rgba16float, write>;

// How far (relative) the frame's depth may lie from the depth a blade wrote with its motion
// (stored at half precision) for the motion to be the pixel's: beyond it, something drawn
// after the grass covers the blade, and the pixel is reprojected through its depth.
const MOTION_DEPTH_TOLERANCE: f32 = 2e-3;

// The pixels a surface may move in a frame and still reach for its own spread over time (the
// reach falls linearly to nothing there): past it, blades at other depths slide past each
// other within the pixel, and its past samples were of other blades.
const SPREAD_MOTION_PX: f32 = 0.5;

// Where the pixel at `px` (pixel position) with reverse-Z depth `d` was in the last frame, in
// pixels; negative where it lay behind the last camera.
fn reproject(px: vec2<f32>, d: f32) -> vec2<f32> {
    let ndc = vec2<f32>(px.x / params.size.x * 2.0 - 1.0, 1.0 - px.y / params.size.y * 2.0);
    let prev = params.reproject * vec4<f32>(ndc, d, 1.0);
    if prev.w <= 0.0 {
        return vec2<f32>(-1.0);
    }
    let pn = prev.xy / prev.w;
    return vec2<f32>((pn.x * 0.5 + 0.5) * params.size.x, (0.5 - pn.y * 0.5) * params.size.y);
}

fn srgb_to_linear(c: vec3<f32>) -> vec3<f32> {
    let lo = c / 12.92;
    let hi = pow((c + 0.055) / 1.055, vec3<f32>(2.4));
    return select(hi, lo, c <= vec3<f32>(0.04045));
}

fn load_current(p: vec2<i32>) -> vec3<f32> {
    let size = vec2<i32>(params.size.xy);
    let c = textureLoad(current, clamp(p, vec2<i32>(0), size - 1), 0).rgb;
    if DECODE_SRGB {
        return srgb_to_linear(c);
    }
    return c;
}

fn to_ycocg(c: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(
        0.25 * c.r + 0.5 * c.g + 0.25 * c.b,
        0.5 * c.r - 0.5 * c.b,
        -0.25 * c.r + 0.5 * c.g - 0.25 * c.b,
    );
}

fn from_ycocg(c: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(c.x + c.y - c.z, c.x + c.z, c.x - c.y - c.z);
}

// Catmull-Rom weights of the four texels around a sample at fraction `t` past the second.
fn catmull_rom(t: f32) -> vec4<f32> {
    let t2 = t * t;
    let t3 = t2 * t;
    return vec4<f32>(
        0.5 * (-t3 + 2.0 * t2 - t),
        0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
        0.5 * (-3.0 * t3 + 4.0 * t2 + t),
        0.5 * (t3 - t2),
    );
}

// The history at pixel position `pos` (pixel centres at +0.5), filtered by Catmull-Rom over
// the 4x4 nearest texels (sharper than bilinear, so that a moving view does not blur its
// history frame after frame); texels off screen count for nothing.
fn sample_history(pos: vec2<f32>) -> vec4<f32> {
    let size = vec2<i32>(params.size.xy);
    let f = pos - 0.5;
    let base = vec2<i32>(floor(f)) - 1;
    let wx = catmull_rom(f.x - floor(f.x));
    let wy = catmull_rom(f.y - floor(f.y));
    var sum = vec4<f32>(0.0);
    var weight = 0.0;
    for (var j = 0; j < 4; j++) {
        for (var i = 0; i < 4; i++) {
            let q = base + vec2<i32>(i, j);
            if all(q >= vec2<i32>(0)) && all(q < size) {
                let w = wx[i] * wy[j];
                sum += w * textureLoad(history, q, 0);
                weight += w;
            }
        }
    }
    if abs(weight) < 1e-4 {
        return vec4<f32>(0.0);
    }
    return max(sum / weight, vec4<f32>(0.0));
}

// Moves `h` toward the box's centre until it lies inside the box (clipping, not clamping:
// the colour keeps its hue as it is pulled in). Returns the point and how many times its
// offset from the centre was shortened (1 where it was inside).
fn clip_to_box(h: vec3<f32>, lo: vec3<f32>, hi: vec3<f32>) -> vec4<f32> {
    let center = 0.5 * (hi + lo);
    let extent = max(0.5 * (hi - lo), vec3<f32>(1e-5));
    let d = h - center;
    let m = max(max(abs(d.x) / extent.x, abs(d.y) / extent.y), abs(d.z) / extent.z);
    if m > 1.0 {
        return vec4<f32>(center + d / m, m);
    }
    return vec4<f32>(h, 1.0);
}

@compute @workgroup_size(8, 8)
fn cs_taa_resolve(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = vec2<i32>(params.size.xy);
    let p = vec2<i32>(id.xy);
    if any(p >= size) {
        return;
    }
    var cur = load_current(p);
    var m1 = vec3<f32>(0.0);
    var m2 = vec3<f32>(0.0);
    // The current frame at the pixel's centre: each sample shows the scene the jitter away
    // from its pixel's centre, weighted by a Gaussian of its distance from this one's.
    var rsum = vec3<f32>(0.0);
    var rweight = 0.0;
    let rs = params.hold.w;
    for (var dy = -1; dy <= 1; dy++) {
        for (var dx = -1; dx <= 1; dx++) {
            let s = load_current(p + vec2<i32>(dx, dy));
            let c = to_ycocg(s);
            m1 += c;
            m2 += c * c;
            if rs > 0.0 {
                let o = vec2<f32>(f32(dx), f32(dy)) - params.hold.yz;
                let w = exp(-dot(o, o) / (2.0 * rs * rs));
                rsum += w * s;
                rweight += w;
            }
        }
    }
    if rs > 0.0 && rweight > 0.0 {
        cur = rsum / rweight;
    }
    let d = textureLoad(depth, p, 0);
    let mean = m1 / 9.0;
    let sigma = sqrt(max(m2 / 9.0 - mean * mean, vec3<f32>(0.0)));

    var out = vec4<f32>(cur, 1.0);
    var var_out = vec3<f32>(0.0);
    // The pixel's motion vector, where what wrote it is still the pixel's surface: a blade's
    // own motion (w 1), or a mark that the surface's history does not hold it (w 2: a falling
    // leaf, shaders/particles.wgsl), which starts the pixel again from its current sample.
    let m = textureLoad(motion, p, 0);
    let own_motion = m.w > 0.5 && abs(m.z - d) <= MOTION_DEPTH_TOLERANCE * d;
    let reactive = own_motion && m.w > 1.5;
    if params.size.w < 0.5 && !reactive {
        let px = vec2<f32>(p) + 0.5;
        // Where the pixel's surface was: a blade's own motion where a blade is the pixel's
        // surface, else the pixel reprojected through its depth (the camera's move alone).
        var pp = reproject(px, d);
        // A blade's own motion beyond the camera's move (its sway in the wind), in pixels.
        var sway = 0.0;
        if own_motion {
            let still = pp;
            pp = px - m.xy;
            // (reproject's mark for a point behind the last camera: no sway to measure.)
            if any(still != vec2<f32>(-1.0)) {
                sway = length(pp - still);
            }
        }
        // Where a point at infinity behind the pixel was: the camera's turn alone. What the
        // surface moved beyond that is parallax (the camera's move against the depth) or the
        // blade's own motion: blades at other depths slid past each other within the pixel.
        let turned = reproject(px, 0.0);
        if all(pp >= vec2<f32>(0.0)) && all(pp < params.size.xy) {
            let h = sample_history(pp);
            if h.a >= 1.0 {
                let g = params.clip.x;
                var lo = mean - g * sigma;
                var hi = mean + g * sigma;
                let c = to_ycocg(cur);
                let q = clamp(vec2<i32>(floor(pp)), vec2<i32>(0), size - 1);
                let own = max(textureLoad(spread, q, 0).xyz, vec3<f32>(0.0));
                // Pixels the surface moved since the last frame.
                let moved = length(pp - px);
                let parallax = select(moved, length(pp - turned), turned.x >= 0.0);
                if params.clip.z > 0.0 {
                    // A moving surface's past samples were of other blades (its parallax
                    // uncovers others): the pixel's spread reaches less the further it moved,
                    // and not at all from SPREAD_MOTION_PX on.
                    let reach = params.clip.z * sqrt(own) * max(1.0 - moved / SPREAD_MOTION_PX, 0.0);
                    lo = min(lo, c - reach);
                    hi = max(hi, c + reach);
                }
                let clipped = clip_to_box(to_ycocg(h.rgb), lo, hi);
                let most = max(params.size.z / (1.0 + params.clip.y * moved + params.clip.w * parallax + params.sway.x * sway), params.hold.x);
                let n = min(h.a + 1.0, most);
                let a = 1.0 / n;
                out = vec4<f32>(mix(from_ycocg(clipped.xyz), cur, a), n);
                // The spread shrinks with the history's clipped offset, then takes in the
                // current sample (an exponentially weighted variance).
                let e = c - clipped.xyz;
                var_out = (1.0 - a) * (own / (clipped.w * clipped.w) + a * e * e);
            }
        }
    }
    textureStore(history_out, p, out);
    textureStore(spread_out, p, vec4<f32>(var_out, 0.0));
}

@fragment
fn fs_taa_output(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    return output_color(textureLoad(resolved, vec2<i32>(pos.xy), 0).rgb);
}
