// The blade record of the instance pool, shared by grass_generate.wgsl, grass_wind.wgsl and
// grass_draw.wgsl (each includes it). Mirrors `Blade` in src/grass/blade.rs (96 bytes).
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
    // Fade at generation; after the wind pass, the gust highlight.
    fade: f32,
    // Written by the wind pass.
    lean_x: f32,
    lean_y: f32,
    sway: f32,
    flutter: f32,
    // Written by the wind pass: how much the lean (x, y), the sway and the flutter changed over
    // the last frame (the draw's motion vectors).
    moved_lean_x: f32,
    moved_lean_y: f32,
    moved_sway: f32,
    moved_flutter: f32,
}

// A blade's packed colour (8 bits a channel, red lowest) as linear RGB.
fn unpack_rgb(c: u32) -> vec3<f32> {
    return vec3<f32>(f32(c & 255u), f32((c >> 8u) & 255u), f32((c >> 16u) & 255u)) / 255.0;
}

// Linear RGB packed as a blade's colour (opaque alpha), the inverse of unpack_rgb.
fn pack_rgba8(c: vec3<f32>) -> u32 {
    let q = vec3<u32>(clamp(c, vec3<f32>(0.0), vec3<f32>(1.0)) * 255.0 + 0.5);
    return q.x | (q.y << 8u) | (q.z << 16u) | (255u << 24u);
}
