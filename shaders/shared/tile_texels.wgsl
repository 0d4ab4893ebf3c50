// Reading a tile's data from the atlas (heights and grass maps, one layer per tile). Include
// this file after declaring, with bindings of the includer's choice:
//
//     var heights: texture_2d_array<f32>;   // metres
//     var grass: texture_2d_array<u32>;     // r: grass type, g: density 0..255
//
// Texel coordinates are clamped to the tile's samples (border included).

fn tile_texel(x: i32, y: i32, layer: u32) -> vec2<i32> {
    let s = i32(textureDimensions(heights).x);
    return vec2<i32>(clamp(x, 0, s - 1), clamp(y, 0, s - 1));
}

fn h_at(x: i32, y: i32, layer: u32) -> f32 {
    return textureLoad(heights, tile_texel(x, y, layer), layer, 0).r;
}

fn d_at(x: i32, y: i32, layer: u32) -> f32 {
    return f32(textureLoad(grass, tile_texel(x, y, layer), layer, 0).g) / 255.0;
}

// Bilinear height (x, metres) and grass density (y, 0..1) at texel position `tp` of `layer`.
fn tile_height_density(tp: vec2<f32>, layer: u32) -> vec2<f32> {
    let f0 = floor(tp);
    let ix = i32(f0.x);
    let iy = i32(f0.y);
    let fx = tp.x - f0.x;
    let fy = tp.y - f0.y;
    let ha = h_at(ix, iy, layer) + (h_at(ix + 1, iy, layer) - h_at(ix, iy, layer)) * fx;
    let hb = h_at(ix, iy + 1, layer) + (h_at(ix + 1, iy + 1, layer) - h_at(ix, iy + 1, layer)) * fx;
    let da = d_at(ix, iy, layer) + (d_at(ix + 1, iy, layer) - d_at(ix, iy, layer)) * fx;
    let db = d_at(ix, iy + 1, layer) + (d_at(ix + 1, iy + 1, layer) - d_at(ix, iy + 1, layer)) * fx;
    return vec2<f32>(ha + (hb - ha) * fy, da + (db - da) * fy);
}

// The ground's normal at texel (nx, ny) of `layer` by central differences, for texels `cell`
// metres apart.
fn tile_normal(nx: i32, ny: i32, layer: u32, cell: f32) -> vec3<f32> {
    let slope_x = h_at(nx - 1, ny, layer) - h_at(nx + 1, ny, layer);
    let slope_y = h_at(nx, ny - 1, layer) - h_at(nx, ny + 1, layer);
    return normalize(vec3<f32>(slope_x, slope_y, 2.0 * cell));
}
