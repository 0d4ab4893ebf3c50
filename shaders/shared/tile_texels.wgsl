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
