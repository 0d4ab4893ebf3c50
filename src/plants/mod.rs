//! Plants beyond grass: flowers, ferns and bushes, placed per grass tile on the GPU and bent by
//! the same wind as the blades.
//!
//! - [`mesh`]: the vertex record every plant mesh uses.
//! - `draw`: the indirect draws with the wind's bending and the shading
//!   (`shaders/plants_draw.wgsl`); the bending mirrored in [`bend_cpu`].
//! - `place`: placement and culling per grass tile (`shaders/plants_place.wgsl`); mirror
//!   [`place_cpu`].

pub mod bend_cpu;
mod draw;
pub mod mesh;
mod place;
pub mod place_cpu;
pub mod renderer;
pub mod set;

pub use mesh::{PlantImage, PlantMesh, PlantVertex};
pub use renderer::{PlantRenderer, PlantSettings, PlantStats};
pub use set::{PlantError, PlantSet};

/// The built-in recipes a plant type's `mesh` may name.
pub const RECIPES: [&str; 3] = ["flower", "fern", "bush"];

/// Edge of a cell of the placement grid, metres: each cell holds at most one plant.
pub const PLANT_CELL_M: f32 = 0.5;
