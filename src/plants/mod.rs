//! Plants beyond grass: flowers, ferns and bushes, placed per grass tile on the GPU and bent by
//! the same wind as the blades.
//!
//! - [`mesh`]: the vertex record every plant mesh uses.
//! - [`gltf`]: a user's plant read from a glTF 2.0 file, and a writer for tests and examples.

pub mod gltf;
pub mod mesh;

pub use gltf::{
    LoadedPlant, MAX_PLANT_TRIANGLES, MAX_PLANT_VERTICES, MAX_TEXTURE_SIZE, PlantFileError,
    PlantTexture, load_plant, write_plant_gltf,
};
pub use mesh::{PlantImage, PlantMesh, PlantVertex};
