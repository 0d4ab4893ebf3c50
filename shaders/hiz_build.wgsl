// The Hi-Z pyramid of the terrain's depth (reverse-Z): level 0 copies the depth buffer, each
// further level keeps the smallest (farthest) depth of the 2x2 texels below it, 3 where the
// level below has an odd size. CPU mirror: src/grass/hiz.rs.

@group(0) @binding(0) var src_depth: texture_depth_2d;
@group(0) @binding(1) var dst0: texture_storage_2d<r32float, write>;

@compute @workgroup_size(8, 8, 1)
fn copy_depth(@builtin(global_invocation_id) gid: vec3<u32>) {
    let size = textureDimensions(src_depth);
    if gid.x >= size.x || gid.y >= size.y {
        return;
    }
    let d = textureLoad(src_depth, vec2<i32>(gid.xy), 0);
    textureStore(dst0, vec2<i32>(gid.xy), vec4<f32>(d, 0.0, 0.0, 0.0));
}

@group(0) @binding(2) var src: texture_2d<f32>;
@group(0) @binding(3) var dst: texture_storage_2d<r32float, write>;

@compute @workgroup_size(8, 8, 1)
fn reduce(@builtin(global_invocation_id) gid: vec3<u32>) {
    let size = textureDimensions(dst);
    let prev = textureDimensions(src);
    if gid.x >= size.x || gid.y >= size.y {
        return;
    }
    var xs = 2u;
    var ys = 2u;
    if gid.x == size.x - 1u && prev.x % 2u == 1u && prev.x > 1u {
        xs = 3u;
    }
    if gid.y == size.y - 1u && prev.y % 2u == 1u && prev.y > 1u {
        ys = 3u;
    }
    var m = 3.4028235e38;
    for (var dy = 0u; dy < ys; dy++) {
        for (var dx = 0u; dx < xs; dx++) {
            let p = min(vec2<u32>(2u * gid.x + dx, 2u * gid.y + dy), prev - 1u);
            m = min(m, textureLoad(src, vec2<i32>(p), 0).r);
        }
    }
    textureStore(dst, vec2<i32>(gid.xy), vec4<f32>(m, 0.0, 0.0, 0.0));
}
