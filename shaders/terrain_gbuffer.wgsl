// Terrain: one instanced draw of a regular grid per tile, heights fetched from the tile atlas.
// Positions are camera-relative: the CPU subtracts the camera position in f64 before anything
// reaches the GPU, so a world tens of kilometres wide does not jitter.
//
// One pass draws it, the G-buffer pass: it writes the depth, and its fragments record only
// where in the atlas each pixel's ground is. The shading, per pixel, is a compute pass
// (shaders/terrain_shade.wgsl); the functions of both are in shaders/shared/terrain_shading.wgsl.

#include "shared/terrain_shading.wgsl"

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

@group(0) @binding(1) var<storage, read> tiles: array<TileDraw>;

struct VertexOut {
    // Invariant: every pass that draws the terrain's mesh (the G-buffer pass, and any that
    // tests against its depth) must produce the same depths.
    @builtin(position) @invariant clip: vec4<f32>,
    // The atlas texel under the vertex (fractional), in the slot `layer`.
    @location(2) tex: vec2<f32>,
    // The drawn tile's level (for the overlay).
    @location(3) @interpolate(flat) level: f32,
    @location(4) @interpolate(flat) layer: u32,
    // Metres per atlas texel of the slot's data.
    @location(5) @interpolate(flat) texel_m: f32,
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
    // Metres per texel of the slot's data (the fragment's normals and maps are per texel).
    let texel_m = tile.cell_size / tile.tex_step;

    var z = h;
    if skirt {
        z -= frame.camera.z * texel_m;
    }
    let rel = vec3<f32>(tile.origin + gm * tile.cell_size, z - frame.camera.x);

    var out: VertexOut;
    out.clip = frame.view_proj * vec4<f32>(rel, 1.0);
    out.tex = tp;
    out.layer = tile.layer;
    out.texel_m = texel_m;
    out.level = round(log2(frame.overlay.w / tile.cell_size));
    return out;
}

// The G-buffer, two words: x the atlas texel under the pixel (x, y in 8.8 fixed point); y its
// slot (12 bits), the drawn tile's level (5 bits) and metres per texel (a half float without
// its sign, 15 bits). Read back by cs_shade in shaders/terrain_shade.wgsl.
@fragment
fn fs_gbuffer(in: VertexOut) -> @location(0) vec2<u32> {
    let t = vec2<u32>(clamp(round(in.tex * 256.0), vec2<f32>(0.0), vec2<f32>(65535.0)));
    let level = u32(clamp(in.level, 0.0, 31.0));
    let metres = pack2x16float(vec2<f32>(in.texel_m, 0.0)) & 0x7fffu;
    return vec2<u32>(t.x | (t.y << 16u), (in.layer & 0xfffu) | (level << 12u) | (metres << 17u));
}
