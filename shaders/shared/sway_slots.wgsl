// The sway springs' state per wind cell (src/wind/sway.rs, shaders/wind_sway.wgsl): the grass
// types' four slots, then the plant types' eight (SWAY_TYPES and GRASS_SWAY_TYPES in
// src/wind/sway.rs; tests/shaders.rs checks that they agree).

const SWAY_SLOTS: u32 = 12u;
const PLANT_SWAY_SLOT: u32 = 4u;
