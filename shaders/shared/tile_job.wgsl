// One grass tile of the frame, as the grass's generation and the plants' placement read it;
// mirrors `TileJob` in src/grass/generate_cpu.rs.

struct TileJob {
    origin: vec2<f32>,
    cell: f32,
    layer: u32,
    tile_x: u32,
    tile_y: u32,
    lod: u32,
    slot: u32,
}
