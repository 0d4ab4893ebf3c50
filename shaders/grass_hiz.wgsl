// The Hi-Z pyramid of the terrain's depth (reverse-Z), in a storage buffer: level 0 copies the
// depth buffer, each further level keeps the smallest (farthest) depth of the 2x2 texels below
// it, 3 where the level below has an odd size. Levels lie one after another, rows top first.
// CPU mirror: src/grass/hiz_cpu.rs.

struct Level {
    src_offset: u32,
    src_width: u32,
    src_height: u32,
    dst_offset: u32,
    dst_width: u32,
    dst_height: u32,
}

@group(0) @binding(0) var src_depth: texture_depth_2d;
@group(0) @binding(1) var<storage, read_write> pyramid: array<f32>;
@group(0) @binding(2) var<uniform> level: Level;

@compute @workgroup_size(8, 8, 1)
fn copy_depth(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= level.dst_width || gid.y >= level.dst_height {
        return;
    }
    let d = textureLoad(src_depth, vec2<i32>(gid.xy), 0);
    pyramid[level.dst_offset + gid.y * level.dst_width + gid.x] = d;
}

@compute @workgroup_size(8, 8, 1)
fn reduce(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= level.dst_width || gid.y >= level.dst_height {
        return;
    }
    var xs = 2u;
    var ys = 2u;
    if gid.x == level.dst_width - 1u && level.src_width % 2u == 1u && level.src_width > 1u {
        xs = 3u;
    }
    if gid.y == level.dst_height - 1u && level.src_height % 2u == 1u && level.src_height > 1u {
        ys = 3u;
    }
    var m = 3.4028235e38;
    for (var dy = 0u; dy < ys; dy++) {
        for (var dx = 0u; dx < xs; dx++) {
            let x = min(2u * gid.x + dx, level.src_width - 1u);
            let y = min(2u * gid.y + dy, level.src_height - 1u);
            m = min(m, pyramid[level.src_offset + y * level.src_width + x]);
        }
    }
    pyramid[level.dst_offset + gid.y * level.dst_width + gid.x] = m;
}
