// The plant instance record the placement writes (shaders/plants_place.wgsl) and the draw reads
// (shaders/plants_draw.wgsl); mirrors `PlantInstance` in src/plants/place_cpu.rs.

struct PlantInstance {
    // The root, relative to the camera (m).
    pos: vec3<f32>,
    // Turn about the vertical (radians).
    yaw: f32,
    // Height (m): the unit mesh's scale.
    scale: f32,
    // Type, and level << 8.
    kind: u32,
    hash: u32,
    // The share of the plant's pixels drawn, for the cross-fade: f > 0 keeps pixels whose
    // dither is below f, f < 0 those at or above -f.
    fade: f32,
}
