// Occlusion of a bounding sphere by the terrain's Hi-Z pyramid (shaders/grass_hiz.wgsl). Include
// this file after declaring `hiz: array<f32>` (the pyramid's levels, farthest depth of each
// texel, reverse-Z) and a uniform `params` with the fields `view_proj` (camera-relative),
// `camera` (y: near plane; z, w: the pyramid's base size in texels), `limits` (x: its mips) and
// `hiz_levels` (per mip: offset, width, height). CPU mirror: sphere_occluded in
// src/grass/generate_cpu.rs.

fn hiz_load(mip: u32, x: i32, y: i32) -> f32 {
    let level = params.hiz_levels[mip];
    let cx = u32(clamp(x, 0, i32(level.y) - 1));
    let cy = u32(clamp(y, 0, i32(level.z) - 1));
    return hiz[level.x + cy * level.y + cx];
}

fn occluded(center: vec3<f32>, radius: f32) -> bool {
    let clip = params.view_proj * vec4<f32>(center, 1.0);
    let near = params.camera.y;
    if clip.w - radius <= near {
        return false;
    }
    let ndc = clip.xy / clip.w;
    let w = params.camera.z;
    let h = params.camera.w;
    let scale_y = max(abs(params.view_proj[1][1]), abs(params.view_proj[0][0]));
    let r_px = radius * scale_y / (clip.w - radius) * 0.5 * max(w, h);
    let sx = (ndc.x * 0.5 + 0.5) * w;
    let sy = (0.5 - ndc.y * 0.5) * h;
    let mips = max(params.limits.x, 1u);
    // The smallest level whose texels are at least as wide as the footprint (integer log2, so
    // that the CPU mirror picks the same level).
    let footprint = max(u32(ceil(2.0 * r_px)), 1u);
    let mip = min(select(firstLeadingBit(footprint - 1u) + 1u, 0u, footprint <= 1u), mips - 1u);
    let texel_px = f32(1u << mip);
    let x0 = i32(floor((sx - r_px) / texel_px));
    let y0 = i32(floor((sy - r_px) / texel_px));
    let x1 = i32(floor((sx + r_px) / texel_px));
    let y1 = i32(floor((sy + r_px) / texel_px));
    if x1 - x0 > 1 || y1 - y0 > 1 {
        return false;
    }
    let far = min(min(hiz_load(mip, x0, y0), hiz_load(mip, x1, y0)), min(hiz_load(mip, x0, y1), hiz_load(mip, x1, y1)));
    let nearest_depth = near / (clip.w - radius);
    return nearest_depth < far;
}
