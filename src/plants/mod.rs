//! Plants beyond grass: flowers, ferns and bushes, placed per grass tile on the GPU and bent by
//! the same wind as the blades.
//!
//! - [`mesh`]: the vertex record every plant mesh uses.
//! - [`recipe`]: the procedural flowers, ferns and bushes, at two levels of detail.
//! - [`card`]: their far level, crossed cards with a picture rendered from the mesh.
//! - [`gltf`]: a user's plant read from a glTF 2.0 file (`.gltf` or `.glb`).
//! - [`set`]: a world's plant types made ready for the GPU (meshes of unit height, textures).
//! - [`reduce`]: the reduced level of a plant read from a file (vertex clustering to a budget).
//! - `place`: placement and culling per grass tile (`shaders/plants_place.wgsl`); mirror
//!   [`place_cpu`].
//! - `draw`: the indirect draws with the wind's bending and the shading
//!   (`shaders/plants_draw.wgsl`); the bending mirrored in [`bend_cpu`].
//! - [`particles`]: leaves shed by the trees and carried by the wind (mirror
//!   [`particles_cpu`]).
//! - [`shadow`]: the trees' cascaded shadow map (drawn by a caster instance of the stage).
//!
//! [`renderer`] holds the instance pool and records the stages after the grass.

pub mod bend_cpu;
pub mod card;
mod draw;
pub mod gltf;
pub mod mesh;
pub mod particles;
pub mod particles_cpu;
mod place;
pub mod place_cpu;
pub mod recipe;
pub mod reduce;
pub mod renderer;
pub mod set;
pub mod shadow;

pub use card::{crossed_cards, render_card};
pub use gltf::{
    LoadedPlant, MAX_PLANT_BUFFER_BYTES, MAX_PLANT_JSON_BYTES, MAX_PLANT_TRIANGLES,
    MAX_PLANT_VERTICES, MAX_TEXTURE_SIZE, PlantFileError, PlantFileReader, PlantTexture,
    load_plant, load_plant_from, read_plant_file, write_plant_gltf,
};
pub use mesh::{PlantImage, PlantMesh, PlantVertex};
pub use recipe::{PlantLods, Recipe, generate};
pub use renderer::{PlantLayer, PlantRenderer, PlantSettings, PlantStats};
pub use set::{PlantError, PlantSet};

/// The built-in recipes a plant type's `mesh` may name.
pub use crate::world::PLANT_RECIPES as RECIPES;

/// Edge of a cell of the placement grid, metres: each cell holds at most one plant.
pub const PLANT_CELL_M: f32 = 0.5;
