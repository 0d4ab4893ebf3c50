//! Plants beyond grass: flowers, ferns and bushes, placed per grass tile on the GPU and bent by
//! the same wind as the blades.
//!
//! - [`mesh`]: the vertex record every plant mesh uses.

pub mod mesh;

pub use mesh::{PlantImage, PlantMesh, PlantVertex};
